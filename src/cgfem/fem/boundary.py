"""Boundary terms on the embedded surface: weak Dirichlet conditions and dead loads.

Weak Dirichlet (stabilized Lagrange multiplier with recovered stress, Tur et al. 2015): on
the constrained components ``c`` of a patch the multiplier (the support's traction on the
body) is taken as

    lambda_c = (P* . N)_c + beta (t u_bar - u)_c,      beta = kappa E / h,

with ``P*`` the recovered stress (SPR; Cauchy in small strain, first Piola-Kirchhoff in
finite strain, reference normal ``N``), frozen during a Newton solve and refreshed by the
outer loop. The residual gets ``- int lambda_c v_c dA`` and the tangent ``beta M_c``. At
convergence of the outer loop ``P* ~ P(u)`` and the method is consistent; unlike Nitsche's
method it needs no estimate of an inverse inequality, since ``P*`` is a smooth field.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cgfem.case.expressions import Expression, VectorExpression
from cgfem.embedding.partition import SurfaceQuadrature
from cgfem.fem import _element_kernels as kern
from cgfem.fem.assembly import Pattern
from cgfem.fem.space import ElementPoints, Space


@dataclass(frozen=True)
class BoundaryPoints:
    """Surface quadrature points of some patches, grouped by active element.

    points : positions, weights and local coordinates, grouped
    normal : (n, 3) outward unit normals (reference configuration)
    slots : (n,) active element of each point
    patch : (n,) patch of each point (index in ``Embedding.patch_names``)
    uv : (n, 2) the point's NURBS parameters ``(xi, eta)`` on its patch, or for facets its
        barycentric coordinates ``(l1, l2)`` in its triangle
    piece : (n,) Bezier piece of the patch (NURBS) or triangle id (facets,
        a row of ``Embedding.facets.triangles``); see
        :class:`cgfem.embedding.partition.SurfaceQuadrature`
    """

    points: ElementPoints
    normal: np.ndarray
    slots: np.ndarray
    patch: np.ndarray
    uv: np.ndarray
    piece: np.ndarray

    @classmethod
    def of(cls, space: Space, surface: SurfaceQuadrature, mask: np.ndarray) -> "BoundaryPoints":
        """The rows ``mask`` of the boundary rule ``surface``, grouped by element (every
        per-point field permuted alike)."""
        rows = surface.select(mask)
        points, order, slots = space.group(rows.x, rows.w, rows.element)
        return cls(points, rows.normal[order], slots, rows.patch[order], rows.uv[order], rows.piece[order])

    def interpolate(self, space: Space, nodal: np.ndarray) -> np.ndarray:
        """Values (n, ...) at the points of a nodal field (n_nodes, ...)."""
        nodal = np.asarray(nodal, float)
        flat = np.ascontiguousarray(nodal.reshape(nodal.shape[0], -1))
        p = self.points
        out = kern.point_values(*space.kernel_element, space.connectivity, flat, p.xi, p.offsets, space.h)
        return out.reshape((-1,) + nodal.shape[1:])

    def values(self, space: Space, u: np.ndarray) -> np.ndarray:
        """Displacement (n, 3) at the points."""
        return self.interpolate(space, u.reshape(-1, 3))

    def traction_of(self, space: Space, nodal_stress: np.ndarray) -> np.ndarray:
        """``sigma* . n`` (n, 3) of a nodal stress field (n_nodes, 3, 3)."""
        s = self.interpolate(space, nodal_stress)
        n = self.normal
        return s[:, :, 0] * n[:, 0:1] + s[:, :, 1] * n[:, 1:2] + s[:, :, 2] * n[:, 2:3]

    def integrate(self, space: Space, values: np.ndarray, r: np.ndarray) -> None:
        """``r += int N_a values_i dA``."""
        p = self.points
        kern.integrate_load(*space.kernel_element, space.connectivity, np.ascontiguousarray(values),
                            p.xi, p.w, p.offsets, space.h, r)


def surface_mask(surface: SurfaceQuadrature, patch_names: tuple[str, ...],
                 names: tuple[str, ...]) -> np.ndarray:
    """Rows of ``surface`` on the named patches (names may repeat over several patches)."""
    ids = [i for i, n in enumerate(patch_names) if n in names]
    return np.isin(surface.patch, ids)


@dataclass
class WeakDirichlet:
    """Prescribed components ``u_c = t * u_bar_c(x)`` on a set of surface points."""

    label: str
    space: Space
    pattern: Pattern
    boundary: BoundaryPoints
    components: np.ndarray          # (3,) bool
    target: np.ndarray              # (n, 3) u_bar at load factor 1 (0 where free)
    beta: float
    _penalty: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)

    @classmethod
    def build(cls, label: str, space: Space, pattern: Pattern, boundary: BoundaryPoints,
              components: tuple[tuple[int, Expression], ...], beta: float) -> "WeakDirichlet":
        mask = np.zeros(3, bool)
        target = np.zeros((boundary.points.x.shape[0], 3))
        x = boundary.points.x
        for i, expr in components:
            mask[i] = True
            target[:, i] = expr(x[:, 0], x[:, 1], x[:, 2])
        return cls(label, space, pattern, boundary, mask, target, beta)

    def multiplier(self, u: np.ndarray, t: float, frozen_stress: np.ndarray | None) -> np.ndarray:
        """``lambda`` (n, 3) at the points (zero on free components), with ``P*`` the frozen
        recovered stress ``frozen_stress`` (n_nodes, 3, 3; None: penalty only)."""
        lam = self.beta * (t * self.target - self.boundary.values(self.space, u))
        if frozen_stress is not None:
            lam += self.boundary.traction_of(self.space, frozen_stress)
        return lam * self.components

    def add(self, u: np.ndarray, t: float, frozen_stress: np.ndarray | None, r: np.ndarray,
            data: np.ndarray | None) -> None:
        """``r -= int lambda . v dA`` and, if ``data`` is given, the tangent ``beta M_c``."""
        self.boundary.integrate(self.space, -self.multiplier(u, t, frozen_stress), r)
        if data is not None:
            pos, val = self._penalty_entries()
            data[pos] += val

    def reaction(self, u: np.ndarray, t: float, frozen_stress: np.ndarray | None) -> np.ndarray:
        """Force (3,) the support exerts on the body: ``int lambda dA``."""
        return self.boundary.points.w @ self.multiplier(u, t, frozen_stress)

    def _penalty_entries(self) -> tuple[np.ndarray, np.ndarray]:
        if self._penalty is None:
            data = self.pattern.zeros()
            p = self.boundary.points
            elements = np.flatnonzero(np.diff(p.offsets) > 0)
            kern.integrate_mass(*self.space.kernel_element, p.xi, p.w, p.offsets, self.space.h,
                                self.components, elements, self.pattern.scatter, data)
            pos = np.flatnonzero(data)
            self._penalty = (pos, self.beta * data[pos])
        return self._penalty


def traction_load(space: Space, boundary: BoundaryPoints, value: VectorExpression) -> np.ndarray:
    """``f_a = int N_a t(x) dA`` (n_dofs,) of a dead traction on the reference surface."""
    x = boundary.points.x
    f = np.zeros(space.n_dofs)
    boundary.integrate(space, value(x[:, 0], x[:, 1], x[:, 2]), f)
    return f


def body_force_load(space: Space, points: ElementPoints, value: VectorExpression) -> np.ndarray:
    """``f_a = int N_a b(x) dV`` (n_dofs,) of a dead body force (N/m^3)."""
    x = points.x
    f = np.zeros(space.n_dofs)
    kern.integrate_load(*space.kernel_element, space.connectivity,
                        np.ascontiguousarray(value(x[:, 0], x[:, 1], x[:, 2])), points.xi, points.w,
                        points.offsets, space.h, f)
    return f
