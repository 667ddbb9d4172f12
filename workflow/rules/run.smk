rule compile_kernels:
    """Compile one of KERNEL_SHARES shares of the numba kernels (``cgfem warmup --share``)
    before the runs: the shares run side by side as the first jobs, where the first runs
    would each compile every kernel at once. With a warm cache they only load them."""
    output:
        KERNELS,
    conda:
        ENV
    log:
        "logs/kernels/share_{share}_of_{shares}.log",
    threads: 1
    # ahead of every other job: the runs then find their kernels compiled
    priority: FIRST
    shell:
        "NUMBA_NUM_THREADS={threads} OMP_NUM_THREADS={threads} MKL_NUM_THREADS={threads} "
        "cgfem warmup --share {wildcards.share}/{wildcards.shares} > {output}.tmp 2> {log} "
        "&& mv {output}.tmp {output}"


rule run_case:
    """Solve one example at one level with one surface definition. A run that fails to
    converge (exit 1, summary.json written with status "failed", or "outer_not_converged"
    when every step solved but an outer loop hit its cap) is a result; bad input (exit 2) or
    a crash is an error of the pipeline."""
    input:
        case=case_file,
        check="results/check/{case}.json",
    output:
        summary=f"{RUN}/summary.json",
    params:
        out=run_folder,
        embeddings=EMBEDDINGS,
    conda:
        ENV
    log:
        "logs/runs/{case}/L{level}_{surface}.log",
    benchmark:
        "results/benchmarks/runs/{case}/L{level}_{surface}.tsv"
    threads: 1
    resources:
        mem_mb=run_memory_mb,
    # the longest first
    priority: run_priority
    shell:
        "NUMBA_NUM_THREADS={threads} OMP_NUM_THREADS={threads} MKL_NUM_THREADS={threads} "
        "cgfem run {input.case} --level {wildcards.level} --surface {wildcards.surface} "
        "--out {params.out} --embedding-cache {params.embeddings} 2> {log} "
        "|| [ $? -eq 1 ] && [ -f {output.summary} ]"


rule run_case_order:
    """As run_case (order 1, the paper's trilinear elements) with elements of a higher order
    (``examples.*.orders``, ``cgfem run --order``), into a folder of its own (``_o{order}``)."""
    input:
        case=case_file,
        check="results/check/{case}.json",
    output:
        summary=f"{RUN_ORDER}/summary.json",
    params:
        out=lambda wildcards: RUN_ORDER.format(**wildcards),
        embeddings=EMBEDDINGS,
    conda:
        ENV
    log:
        "logs/runs/{case}/L{level}_{surface}_o{order}.log",
    benchmark:
        "results/benchmarks/runs/{case}/L{level}_{surface}_o{order}.tsv"
    threads: 1
    resources:
        mem_mb=run_memory_mb,
    # the longest first
    priority: run_priority
    shell:
        "NUMBA_NUM_THREADS={threads} OMP_NUM_THREADS={threads} MKL_NUM_THREADS={threads} "
        "cgfem run {input.case} --level {wildcards.level} --surface {wildcards.surface} "
        "--order {wildcards.order} --out {params.out} --embedding-cache {params.embeddings} 2> {log} "
        "|| [ $? -eq 1 ] && [ -f {output.summary} ]"
