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

import pytest


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "slow: solves a whole problem or builds large embeddings (deselect with -m 'not slow')")
    config.addinivalue_line("markers", "long: an acceptance run of minutes, left out by default (run with -m long)")
