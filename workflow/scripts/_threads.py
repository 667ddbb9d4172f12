"""The threads of a script job, set before anything imports numba, MKL or OpenMP."""
import os

#: the variables the run jobs' shell commands set too (workflow/rules/run.smk)
THREAD_VARIABLES = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def limit_threads(threads: int) -> None:
    """Run this job's numba kernels, MKL and OpenMP on ``threads`` threads (the rule's
    ``threads``), as a run job does: a job then keeps to its own core beside the other
    jobs, and on one thread it calls the serial twins of the parallel kernels
    (``cgfem._parallel``), which the runs have compiled already, instead of compiling the
    parallel ones."""
    for name in THREAD_VARIABLES:
        os.environ[name] = str(int(threads))
