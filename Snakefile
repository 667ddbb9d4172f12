# Regenerates the paper's figures. Today the pipeline validates every case and measures its
# exact geometry; solving and plotting join as the library grows.
from snakemake.utils import validate


configfile: "config/config.yaml"


validate(config, "workflow/schemas/config.schema.yaml")


include: "workflow/rules/check.smk"


rule all:
    input:
        expand("results/check/{case}.json", case=config["cases"]),
