rule planar_reference:
    """Body-fitted plane-strain overkill solution of the planar example (cgfem.reference)."""
    output:
        "results/reference/planar.npz",
    conda:
        ENV
    log:
        "logs/reference/planar.log",
    # early, with the cases' checks: every planar error table waits for it
    priority: FIRST - 1
    shell:
        "NUMBA_NUM_THREADS={threads} OMP_NUM_THREADS={threads} MKL_NUM_THREADS={threads} "
        "python3 -m cgfem.reference.planar --out {output} > {log} 2>&1"


# Body-fitted references of the chain examples (cgfem.reference.tori, NGSolve). Their mesh
# and penalty studies take 6-31 min each on one thread and need NGSolve, so each is a gold
# file in config/reference/ holding the command that regenerates it; the rule checks that
# the gold file was made by the current reference code (its script version) for the current
# case file, and copies it (exit 1 naming the command if not).


rule reference_chain2_steel:
    """Body-fitted reference of chain2_steel, from its checked gold file."""
    input:
        gold="config/reference/chain2_steel.json",
        case=REFERENCE_CASES["chain2_steel"],
    output:
        "results/reference/chain2_steel.json",
    conda:
        ENV
    log:
        "logs/reference/chain2_steel.log",
    shell:
        "NUMBA_NUM_THREADS={threads} OMP_NUM_THREADS={threads} MKL_NUM_THREADS={threads} "
        "python3 -m cgfem.reference.tori --case {input.case} --from-gold {input.gold} "
        "--out {output} > {log} 2>&1"


rule reference_chain2_rubber:
    """Body-fitted reference of chain2_rubber, from its checked gold file."""
    input:
        gold="config/reference/chain2_rubber.json",
        case=REFERENCE_CASES["chain2_rubber"],
    output:
        "results/reference/chain2_rubber.json",
    conda:
        ENV
    log:
        "logs/reference/chain2_rubber.log",
    shell:
        "NUMBA_NUM_THREADS={threads} OMP_NUM_THREADS={threads} MKL_NUM_THREADS={threads} "
        "python3 -m cgfem.reference.tori --case {input.case} --from-gold {input.gold} "
        "--out {output} > {log} 2>&1"


rule reference_chain3:
    """Body-fitted reference of chain3, from its checked gold file."""
    input:
        gold="config/reference/chain3.json",
        case=REFERENCE_CASES["chain3"],
    output:
        "results/reference/chain3.json",
    conda:
        ENV
    log:
        "logs/reference/chain3.log",
    shell:
        "NUMBA_NUM_THREADS={threads} OMP_NUM_THREADS={threads} MKL_NUM_THREADS={threads} "
        "python3 -m cgfem.reference.tori --case {input.case} --from-gold {input.gold} "
        "--out {output} > {log} 2>&1"
