"""Test-suite configuration.

The tree says what a test proves: ``unit/`` checks kernels and layers against slow, obvious
references; ``physics/`` asserts mechanics and mathematics in numbers (patch tests, rates,
tangents against finite differences, equilibrium, Newton's order, Hertz); ``pipeline/`` the
command line, the result files, the Snakemake workflow and the README. Shared set-ups live in
the ``tests.support`` package.

Every test that solves a whole problem carries the ``slow`` marker:
``python3 -m pytest -q -m "not slow"`` runs the rest in a few minutes.
"""

from __future__ import annotations

import pytest


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "slow: solves a whole problem (deselect with -m 'not slow')")
