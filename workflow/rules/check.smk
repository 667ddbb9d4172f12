wildcard_constraints:
    case=r"[A-Za-z0-9_]+",


rule check_case:
    """Validate a case and record the B-rep volume and patch areas of its bodies."""
    input:
        "config/cases/{case}.yaml",
    output:
        "results/check/{case}.json",
    log:
        "logs/check/{case}.log",
    shell:
        "cgfem check {input} --json > {output}.tmp 2> {log} && mv {output}.tmp {output}"
