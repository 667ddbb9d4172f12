rule planar_errors:
    """Relative energy-norm error of each body of one planar run against the reference."""
    input:
        summary="results/runs/planar/L{level}_{surface}/summary.json",
        case=EXAMPLES["planar"]["case"],
        reference="results/reference/planar.npz",
    output:
        "results/analysis/planar/errors_L{level}_{surface}.csv",
    params:
        embeddings=EMBEDDINGS,
    conda:
        ENV
    log:
        "logs/analysis/planar/errors_L{level}_{surface}.log",
    script:
        "../scripts/planar_errors.py"


rule claims:
    """The paper's four claims, reproduced or not, with the numbers behind each answer, and
    whether claims 3 and 4 still hold with the order-2 runs (``claims.order2``)."""
    input:
        errors=planar_error_tables(),
        chain2=summaries(config["claims"]["chain2"]),
        chain3=summaries("chain3"),
        references=reference_files([config["claims"]["chain2"], "chain3"]),
        order2=order_summaries(config["claims"]["chain2"]) + order_summaries("chain3"),
    output:
        "results/claims.md",
    params:
        claims=config["claims"],
        fig13=config["figures"]["fig13"]["options"],
    conda:
        ENV
    log:
        "logs/analysis/claims.log",
    script:
        "../scripts/claims.py"
