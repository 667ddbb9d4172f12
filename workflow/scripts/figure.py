"""Draw one figure of cgfem.report from its input files and save it as PNG and PDF."""
import sys

from _threads import limit_threads

limit_threads(snakemake.threads)  # before cgfem imports numba

from cgfem.report import figure
from cgfem.report.style import save_figure

with open(snakemake.log[0], "w") as sys.stderr:
    save_figure(figure(snakemake.params.name, snakemake.input, **snakemake.params.options),
                snakemake.output.png, snakemake.output.pdf)
