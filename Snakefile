# The replication pipeline: every example x level x surface definition is solved
# (results/runs/{case}/L{level}_{surface}/; the order-2 runs of examples.*.orders in
# results/runs/{case}/L{level}_{surface}_o2/), the planar runs are measured against a
# body-fitted reference, and every figure (paper_figures/) and the claims table
# (results/claims.md) are drawn from the result files.
#   snakemake --cores 2                                   # full run
#   snakemake --cores 2 --configfile config/smoke.yaml    # coarsest meshes, fewest steps


configfile: "config/config.yaml"


include: "workflow/rules/common.smk"


rule all:
    """Every final figure (PNG and PDF), the claims table, the checked cases and the
    kernels compiled in shares (first, side by side)."""
    input:
        expand("paper_figures/{name}.{ext}", name=FIGURES, ext=["png", "pdf"]),
        "results/claims.md",
        expand("results/check/{case}.json", case=EXAMPLES),
        expand(KERNELS, share=range(1, KERNEL_SHARES + 1), shares=KERNEL_SHARES),
    default_target: True


include: "workflow/rules/check.smk"
include: "workflow/rules/run.smk"
include: "workflow/rules/reference.smk"
include: "workflow/rules/analyse.smk"
include: "workflow/rules/figures.smk"
