"""The ``segmented`` slave rule (:mod:`cgfem.contact.rule`) on a curved surface: every part
lies in one element of each grid, so a field that is trilinear inside every master element
and jumps across the master's planes is integrated as the unreduced exact partition
integrates it, which the slave's boundary rule (split at its own planes only) cannot do."""

from __future__ import annotations

import numpy as np

from cgfem.geometry.specs import SphereSpec
from cgfem.contact.rule import segmented_rule
from cgfem.embedding.partition import partition_surface
from cgfem.embedding.quadrature import embed, grid_for
from cgfem.geometry.builders import sphere

SOLID = sphere(SphereSpec(center=(0.01, -0.02, 0.03), radius=1.0))
GRID = grid_for(SOLID, 0.7, 0, (0.13, 0.29, 0.41))
MASTER = grid_for(SOLID, 0.55, 0, (0.61, 0.77, 0.57))


def _field(x: np.ndarray) -> np.ndarray:
    """Trilinear in every master element (the local coordinates there), discontinuous across
    the master's planes, times ``1 + x y``: degree <= 2 in each variable on every part."""
    local = (x - np.asarray(MASTER.origin)) / MASTER.h
    local -= np.floor(local)
    return np.prod(local + 0.5, axis=1) * (1.0 + x[:, 0] * x[:, 1])


def test_segmented_rule_integrates_master_piecewise_fields():
    exact = partition_surface(SOLID, GRID, 1e-12, cut_by=MASTER).surface
    reference = float(exact.w @ _field(exact.x))
    rule = segmented_rule(SOLID, GRID, MASTER, np.array([0]))
    assert abs(rule.w.sum() / (4.0 * np.pi) - 1.0) < 1e-9          # the sphere's area
    assert abs(float(rule.w @ _field(rule.x)) / reference - 1.0) < 1e-8
    # at most 27 points per (slave element, master element, piece) part, all on the sphere
    parts = np.unique(np.column_stack([rule.element, MASTER.element_id(MASTER.element_of_points(rule.x)),
                                       rule.piece]), axis=0, return_counts=True)[1]
    assert parts.max() <= 27
    np.testing.assert_allclose(np.linalg.norm(rule.x - (0.01, -0.02, 0.03), axis=1), 1.0, atol=1e-12)
    # the slave's boundary rule straddles the master's planes
    boundary = embed(SOLID, GRID).boundary
    assert abs(float(boundary.w @ _field(boundary.x)) / reference - 1.0) > 1e-4
