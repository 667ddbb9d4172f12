# One rule per figure: the inputs are result files only; drawing is cgfem.report's.

rule fig09:
    """Fig. 9: relative energy-norm error vs DOFs, planar, every configured definition."""
    input:
        planar_error_tables(),
    output:
        png=report(
            "paper_figures/fig09.png", caption="../report/fig09.rst", category="Paper"
        ),
        pdf="paper_figures/fig09.pdf",
    params:
        name="fig09",
        options={},
    conda:
        ENV
    log:
        "logs/figures/fig09.log",
    script:
        "../scripts/figure.py"

rule fig10:
    """Fig. 10: u_z along a line across the top surface of the lower block, facets against
    nurbs_fit (nurbs_fe if nurbs_fit is not configured), with the fitted NURBS curve."""
    input:
        summaries("planar", surfaces=fig10_surfaces(), levels=[config["figures"]["fig10"]["level"]]),
    output:
        png=report(
            "paper_figures/fig10.png", caption="../report/fig10.rst", category="Paper"
        ),
        pdf="paper_figures/fig10.pdf",
    params:
        name="fig10",
        options=config["figures"]["fig10"]["options"],
    conda:
        ENV
    log:
        "logs/figures/fig10.log",
    script:
        "../scripts/figure.py"

rule fig13:
    """Fig. 13: reactions on the pulled and clamped caps vs load, chain2_steel."""
    input:
        summaries("chain2_steel"),
    output:
        png=report(
            "paper_figures/fig13.png", caption="../report/fig13.rst", category="Paper"
        ),
        pdf="paper_figures/fig13.pdf",
    params:
        name="fig13",
        options=config["figures"]["fig13"]["options"],
    conda:
        ENV
    log:
        "logs/figures/fig13.log",
    script:
        "../scripts/figure.py"

rule fig14:
    """Fig. 14: sigma_y maps at the final step, chain2_steel, one panel per run."""
    input:
        summaries("chain2_steel"),
    output:
        png=report(
            "paper_figures/fig14.png", caption="../report/fig14.rst", category="Paper"
        ),
        pdf="paper_figures/fig14.pdf",
    params:
        name="fig14",
        options={},
    conda:
        ENV
    log:
        "logs/figures/fig14.log",
    script:
        "../scripts/figure.py"

rule fig15:
    """Fig. 15: chain2_rubber deformed shapes coloured by |u|, active contact points."""
    input:
        fig15_summaries(),
    output:
        png=report(
            "paper_figures/fig15.png", caption="../report/fig15.rst", category="Paper"
        ),
        pdf="paper_figures/fig15.pdf",
    params:
        name="fig15",
        options={},
    conda:
        ENV
    log:
        "logs/figures/fig15.log",
    script:
        "../scripts/figure.py"

rule fig17:
    """Fig. 17: von Mises on the middle link of chain3, facets vs nurbs_fe."""
    input:
        summaries("chain3", surfaces=["facets", "nurbs_fe"], levels=config["figures"]["fig17"]["levels"]),
    output:
        png=report(
            "paper_figures/fig17.png", caption="../report/fig17.rst", category="Paper"
        ),
        pdf="paper_figures/fig17.pdf",
    params:
        name="fig17",
        options=config["figures"]["fig17"]["options"],
    conda:
        ENV
    log:
        "logs/figures/fig17.log",
    script:
        "../scripts/figure.py"

rule newton:
    """Newton residual histories of every run, one panel per example."""
    input:
        all_summaries(),
    output:
        png=report(
            "paper_figures/newton.png", caption="../report/newton.rst", category="Validation"
        ),
        pdf="paper_figures/newton.pdf",
    params:
        name="newton",
        options={},
    conda:
        ENV
    log:
        "logs/figures/newton.log",
    script:
        "../scripts/figure.py"

rule timings:
    """Seconds per stage (build, solve) vs DOFs."""
    input:
        all_summaries(),
    output:
        png=report(
            "paper_figures/timings.png", caption="../report/timings.rst", category="Validation"
        ),
        pdf="paper_figures/timings.pdf",
    params:
        name="timings",
        options={},
    conda:
        ENV
    log:
        "logs/figures/timings.log",
    script:
        "../scripts/figure.py"

rule geometry:
    """Volume and area error of the quadrature vs level per definition."""
    input:
        all_summaries(),
    output:
        png=report(
            "paper_figures/geometry.png", caption="../report/geometry.rst", category="Validation"
        ),
        pdf="paper_figures/geometry.pdf",
    params:
        name="geometry",
        options={},
    conda:
        ENV
    log:
        "logs/figures/geometry.log",
    script:
        "../scripts/figure.py"


rule validation:
    """Distance of every chain run to its example's body-fitted reference: pulled reaction
    per load step, final reaction (and chain3's peak von Mises) against DOFs."""
    input:
        reference_files(),
        [path for case in REFERENCE_CASES for path in summaries(case)],
    output:
        png=report(
            "paper_figures/validation.png", caption="../report/validation.rst", category="Validation"
        ),
        pdf="paper_figures/validation.pdf",
    params:
        name="validation",
        options={},
    conda:
        ENV
    log:
        "logs/figures/validation.log",
    script:
        "../scripts/figure.py"


rule accuracy:
    """Final pulled reaction of every chain run of both element orders against its DOFs and
    its wall time, with the best value at hand (body-fitted reference, or the finest order-2
    run) as a line."""
    input:
        [path for case in CHAINS for path in summaries(case) + order_summaries(case)],
        reference_files(),
    output:
        png=report(
            "paper_figures/accuracy.png", caption="../report/accuracy.rst", category="Validation"
        ),
        pdf="paper_figures/accuracy.pdf",
    params:
        name="accuracy",
        options={k: v for k, v in config["figures"]["fig13"]["options"].items() if k != "clamped"},
    conda:
        ENV
    log:
        "logs/figures/accuracy.log",
    script:
        "../scripts/figure.py"
