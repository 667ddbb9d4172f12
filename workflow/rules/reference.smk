rule planar_reference:
    """Body-fitted plane-strain overkill solution of the planar example (cgfem.reference)."""
    output:
        "results/reference/planar.npz",
    conda:
        ENV
    log:
        "logs/reference/planar.log",
    shell:
        "python3 -m cgfem.reference.planar --out {output} > {log} 2>&1"
