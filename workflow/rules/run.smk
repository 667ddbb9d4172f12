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
    conda:
        ENV
    log:
        "logs/runs/{case}/L{level}_{surface}.log",
    benchmark:
        "results/benchmarks/runs/{case}/L{level}_{surface}.tsv"
    threads: 1
    shell:
        "NUMBA_NUM_THREADS={threads} OMP_NUM_THREADS={threads} MKL_NUM_THREADS={threads} "
        "cgfem run {input.case} --level {wildcards.level} --surface {wildcards.surface} "
        "--out {params.out} 2> {log} || [ $? -eq 1 ] && [ -f {output.summary} ]"
