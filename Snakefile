# Regenerates the paper's figures. Today the pipeline validates every case, measures its exact
# geometry and embeds every body at each level and surface definition; solving and plotting
# join as the library grows.
from snakemake.utils import validate


configfile: "config/config.yaml"


validate(config, "workflow/schemas/config.schema.yaml")


include: "workflow/rules/check.smk"


rule all:
    input:
        expand("results/check/{case}.json", case=config["cases"]),
        expand(
            "results/embedding/{case}_L{level}_{surface}.json",
            case=config["cases"],
            level=config["levels"],
            surface=config["surfaces"],
        ),
