wildcard_constraints:
    case=r"[A-Za-z0-9_]+",
    level=r"\d+",
    surface=r"facets|nurbs_fe|nurbs_fit",


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


rule check_embedding:
    """Embed every body of a case at one level: element counts and quadrature measures."""
    input:
        "config/cases/{case}.yaml",
    output:
        "results/embedding/{case}_L{level}_{surface}.json",
    log:
        "logs/embedding/{case}_L{level}_{surface}.log",
    shell:
        "cgfem check {input} --level {wildcards.level} --surface {wildcards.surface} --json "
        "> {output}.tmp 2> {log} && mv {output}.tmp {output}"
