"""Test-suite configuration.

The tree says what a test proves: ``unit/`` checks kernels and layers against slow, obvious
references; ``physics/`` asserts mechanics and mathematics in numbers (patch tests, rates,
tangents against finite differences, equilibrium, Newton's order, Hertz); ``pipeline/`` the
command line, the result files, the Snakemake workflow and the README. Shared set-ups live in
the ``tests.support`` package.

Every test that solves a whole problem, or builds embeddings of several levels (over about
ten seconds), carries the ``slow`` marker: ``python3 -m pytest -q -m "not slow"`` runs the
rest in a few minutes. The acceptance runs of
several minutes each (order-2 rates over four levels, twenty grid offsets, the level-2 planar
runs, ...) also carry ``long``: the default command leaves them out (``addopts`` in
pyproject.toml), ``python3 -m pytest -q -n 2 --dist loadfile -m long`` runs them.
"""

from __future__ import annotations

import os

import pytest

# pytest-xdist's workers (the README's ``-n 2``) already fill the cores one each: a worker runs
# numba on one thread, and so does every ``cgfem`` process it starts, unless the environment
# says otherwise. Besides not oversubscribing the cores, the workers then call (and compile)
# the one-thread twins of the parallel kernels (cgfem._parallel) that the pipeline's jobs
# call too, instead of each compiling the parallel versions as well. Tests of the parallel
# kernels set the thread count of the processes they start themselves. numba reads the
# variable when it is first imported, after this file.
if "PYTEST_XDIST_WORKER" in os.environ:
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

from tests.support import schedule  # noqa: E402  (imports cgfem, and so numba: after the line above)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--record-file-seconds", action="store_true",
                     help=f"write each test file's seconds in this run to {schedule.SECONDS} (the order "
                          "pytest-xdist's workers take the files in: tests/support/schedule.py)")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # under pytest-xdist the files go to the workers longest first (tests/support/schedule.py)
    if "PYTEST_XDIST_WORKER" in os.environ:
        schedule.order_items(items, schedule.read_seconds())


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "slow: solves a whole problem or builds large embeddings (deselect with -m 'not slow')")
    config.addinivalue_line("markers", "long: an acceptance run of minutes, left out by default (run with -m long)")
    worker = os.environ.get("PYTEST_XDIST_WORKER")       # gw0, gw1, ...; None: the controller or alone
    if worker is None:
        # the queue of files keeps the workers' order (pytest-xdist would sort it by the number
        # of tests in a file)
        if hasattr(config.option, "loadscopereorder"):
            config.option.loadscopereorder = False
        if config.getoption("record_file_seconds"):
            config.pluginmanager.register(schedule.FileSeconds(schedule.SECONDS), "file-seconds")
        return
    # each worker first compiles its share of the kernels (cgfem.precompile): on a cold cache
    # the workers would otherwise each compile nearly all of them in their first tests; on a
    # warm one this loads the share from the cache
    from cgfem.precompile import compile_share

    compile_share(int(worker.removeprefix("gw")) + 1, int(os.environ["PYTEST_XDIST_WORKER_COUNT"]))
