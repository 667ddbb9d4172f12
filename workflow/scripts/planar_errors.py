"""Energy-norm error of one planar run against the cached reference, as a CSV table."""
import sys

from _threads import limit_threads

limit_threads(snakemake.threads)  # before cgfem imports numba

from cgfem.embedding.store import EmbeddingStore
from cgfem.report.energy import energy_errors, reference_error, write_error_table

with open(snakemake.log[0], "w") as sys.stderr:
    error = reference_error(snakemake.input.reference)
    store = EmbeddingStore(snakemake.params.embeddings, lambda message: print(message, file=sys.stderr))
    write_error_table(energy_errors(snakemake.input.case, snakemake.input.summary, error, store),
                      snakemake.output[0])
