rule check_case:
    """Validate a case and record the B-rep volume and patch areas of its bodies."""
    input:
        case_file,
    output:
        "results/check/{case}.json",
    conda:
        ENV
    log:
        "logs/check/{case}.log",
    # right after the kernels' compilation: every run of the case waits for it (the runs'
    # priorities do not pass on to the jobs they need)
    priority: FIRST - 1
    shell:
        "NUMBA_NUM_THREADS={threads} OMP_NUM_THREADS={threads} MKL_NUM_THREADS={threads} "
        "cgfem check {input} --json > {output}.tmp 2> {log} && mv {output}.tmp {output}"


rule check_embedding:
    """Embed every body of a case at one level: element counts and quadrature measures."""
    input:
        case_file,
    output:
        "results/embedding/{case}_L{level}_{surface}.json",
    conda:
        ENV
    log:
        "logs/embedding/{case}_L{level}_{surface}.log",
    shell:
        "NUMBA_NUM_THREADS={threads} OMP_NUM_THREADS={threads} MKL_NUM_THREADS={threads} "
        "cgfem check {input} --level {wildcards.level} --surface {wildcards.surface} --json "
        "> {output}.tmp 2> {log} && mv {output}.tmp {output}"


rule embeddings:
    """Every embedding of the configuration (not part of `all`: the runs embed again)."""
    input:
        [
            f"results/embedding/{case}_L{level}_{surface}.json"
            for case in EXAMPLES
            for level in EXAMPLES[case]["levels"]
            for surface in SURFACES
        ],
