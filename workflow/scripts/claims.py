"""The claims table of the paper, from the planar error tables, the chain runs and the
body-fitted references of the chains (when the configuration has them), and the order-2
line from the order-2 runs of the chains."""
import sys

from _threads import limit_threads

limit_threads(snakemake.threads)  # before cgfem imports numba

from cgfem.report.claims import claims, write_claims
from cgfem.report.curves import AXES

with open(snakemake.log[0], "w") as sys.stderr:
    c, f = snakemake.params.claims, snakemake.params.fig13
    write_claims(snakemake.output[0], claims(
        snakemake.input.errors, snakemake.input.chain2, snakemake.input.chain3,
        rate_tolerance=c["rate_tolerance"], reaction_level=c["reaction_level"],
        pulled=f["pulled"], component=AXES[f.get("component", "y")],
        von_mises_levels=c["von_mises_levels"], von_mises_body=c["von_mises_body"],
        references=list(getattr(snakemake.input, "references", [])),
        order2=c.get("order2"), order2_summaries=list(getattr(snakemake.input, "order2", []))))
