"""The slave rule of a contact pair: where the contact work ``sum w lambda_N delta g_N`` is
integrated (case option ``contact[].rule``).

- ``boundary`` (default, the paper's Gauss-point-to-surface scheme): the slave body's
  boundary-rule points on the pair's slave patches, at most ``(degree + 1)^3`` per element
  and patch (:mod:`cgfem.embedding.reduce`; 27 for trilinear elements, 125 for triquadratic
  ones). Each integrates products of the *slave's* shape functions exactly, but the master's shape functions, seen from the slave, kink on the
  master's element faces, which these points straddle: on non-matching grids the contact
  forces on the master nodes carry a quadrature error and the patch test's pressure
  oscillates by a few per cent about the exact value (the total force stays exact).
- ``segmented``: the slave patches split by the planes of *both* grids (the exact partition
  of :func:`cgfem.embedding.partition.partition_surface` with the master's grid as a second
  cut), for ``nurbs_fit`` on the slave's fitting net (so its knot lines split the surface
  too); every part, one (slave element, master element, Bezier piece) cell, is recombined
  to at most ``(degree + 1)^3`` points that keep its moments of the tensor polynomials of
  degree <= ``degree`` per variable (:func:`cgfem.embedding.reduce.reduced_surface`; the
  element's degree, 2 for trilinear and 4 for triquadratic elements). On such a part both
  bodies' shape functions are polynomials of the element's order, so their products are
  integrated exactly and the
  homogeneous state of the contact patch test is the discrete solution on any two grids
  (tests/physics/test_contact_patch.py). The master's element faces are taken in the reference
  configuration, where the two surfaces meet: once the master slides along the slave, its
  faces move off the split and a quadrature error returns, growing with the slip.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.partition import SurfaceQuadrature, partition_surface
from cgfem.embedding.columns import DEFAULT_DEGREE
from cgfem.embedding.reduce import reduced_surface
from cgfem.geometry.nurbs import NurbsSurface
from cgfem.geometry.solid import Patch, Solid


def segmented_rule(solid: Solid, grid: CartesianGrid, master_grid: CartesianGrid, patch_ids: np.ndarray,
                   surfaces: Mapping[int, NurbsSurface] | None = None, degree: int = DEFAULT_DEGREE
                   ) -> SurfaceQuadrature:
    """The ``segmented`` slave rule (module docstring) of the patches ``patch_ids`` of
    ``solid``, embedded in ``grid``, split also by ``master_grid``'s planes; ``surfaces``
    (patch index -> surface): the same geometry on another net to split at its knot lines
    (``nurbs_fit``'s fitting space). ``piece`` of the result numbers the Bezier pieces of
    those nets. ``degree``: the degree per variable whose moments every part keeps (the
    slave body's element's :attr:`~cgfem.fem.element.Hexahedron.degree`)."""
    patches = list(solid.patches)
    for ip, surface in (surfaces or {}).items():
        patches[int(ip)] = Patch(patches[int(ip)].name, surface)
    exact = partition_surface(Solid(tuple(patches)), grid, cut_by=master_grid,
                              patches={int(i) for i in patch_ids}).surface
    master = master_grid.element_id(master_grid.element_of_points(exact.x))
    return reduced_surface(grid, exact, split=(master, exact.piece), degree=degree)
