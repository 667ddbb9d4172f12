"""A torsional spring on a body's rigid spin about an axis: ``bodies.<name>.hold_spin``.

A body of revolution held by frictionless contact alone (chain3's middle link, a full torus)
can spin about its own axis: the exact problem is the same at every angle, so the angle is
free. Small strain represents that spin only by its linearization ``u = theta a x (X - c)``,
which moves every point along its tangent and so inflates the body by
``|theta a x d|^2 / (2 |d|)`` across a chord ``d``: under the kilonewtons a pulled link
carries, the contact forces do work on that inflation, so the spin lowers the energy (a
negative stiffness of about ``-2 F a`` for a link pulled by ``F`` with contacts ``a`` from
its axis) and the discrete equilibria are saddles in it. Holding the spin selects the member
of the family of equilibria with no spin, and takes the saddle away.

:class:`SpinSpring` measures the spin ``theta = g . u`` as the rigid-fit rotation
(:func:`~cgfem.solve.floating.rigid_fit_rows`) about the axis of ``SPIN_NODES`` nodes of the
body, the node farthest from the axis in each of as many equal sectors of angle about it
(among the nodes farther from it than ``SPIN_QUANTILE`` of them), and adds the energy
``k theta^2 / 2``: residual ``k theta g``, tangent ``k g g^T`` (exact: ``theta`` is linear
in ``u``). A rigid spin gives ``theta`` exactly; a translation or a turn about a
perpendicular axis gives 0. The stiffness ``k = s E h sum |r_perp|^2`` (N m/rad) is that of
a spring of ``s`` times the grid's nodal stiffness ``E h`` on each of those nodes (``s``: the
policy's ``spin_stiffness``), ``r_perp`` its distance to the axis: at the default ``s`` over a
hundred times the spin's spurious ``2 F a`` on chain3, and a hundredth of the bulk's entries,
so that the spin can still give a little where the discrete contact forces push it. The
spring's moment ``k theta`` is what holding the spin takes; on a surface of revolution about
the axis the contact forces have no moment about it, so the moment is what the
discretization breaks of that symmetry (reported per step in the summary).
"""

from __future__ import annotations

import numpy as np

from cgfem.geometry.builders import orthonormal_frame
from cgfem.solve.floating import rigid_fit_rows
from cgfem.solve.items import Couplings
from cgfem.solve.policy import DEFAULT_POLICY

#: the nodes the spin is measured on: one per sector of angle about the axis
SPIN_NODES = 48
#: of the nodes, only those farther from the axis than this fraction of them
SPIN_QUANTILE = 0.7


def spin_nodes(coordinates: np.ndarray, axis: np.ndarray, count: int = SPIN_NODES) -> np.ndarray:
    """Indices of the nodes ``coordinates`` (n, 3) (m) that measure a spin about ``axis`` (3,)
    through their centroid: in each of ``count`` equal sectors of angle about it, the node
    farthest from it (among those farther than the :data:`SPIN_QUANTILE` quantile; a sector
    with none is skipped). Sorted, deterministic."""
    X = np.asarray(coordinates, float)
    a = unit_axis(axis)
    r = X - X.mean(axis=0)
    perp = r - np.outer(r @ a, a)
    distance = np.linalg.norm(perp, axis=1)
    e1, e2, _ = orthonormal_frame(a)
    sector = np.floor((np.arctan2(perp @ e2, perp @ e1) + np.pi) / (2.0 * np.pi) * count).astype(np.int64)
    sector = np.minimum(sector, count - 1)
    far = distance > np.quantile(distance, SPIN_QUANTILE)
    chosen = []
    for k in range(count):
        candidates = np.flatnonzero(far & (sector == k))
        if candidates.size:
            chosen.append(candidates[np.argmax(distance[candidates])])
    return np.array(sorted(chosen), dtype=np.int64)


def unit_axis(axis) -> np.ndarray:
    """``axis`` (3,) scaled to length 1; ``ValueError`` if it has none."""
    a = np.asarray(axis, float).reshape(3)
    norm = float(np.linalg.norm(a))
    if not (np.isfinite(norm) and norm > 0.0):
        raise ValueError(f"a spin axis needs a nonzero length, got {a.tolist()}")
    return a / norm


class SpinSpring:
    """The spring on the spin about ``axis`` (3,) of the body whose dofs are
    ``start:start + 3 n``, its nodes at ``coordinates`` (n, 3) (m), Young's modulus ``E``
    (Pa), element size ``h`` (m) and ``stiffness`` ``s`` (the spring per node over ``E h``;
    module docstring). An item of the system (:mod:`cgfem.solve.items`): :meth:`add` adds its
    residual and returns its tangent's entries (constant: built once)."""

    def __init__(self, name: str, start: int, coordinates: np.ndarray, axis, E: float, h: float,
                 stiffness: float = DEFAULT_POLICY.spin_stiffness):
        self.name = name
        self.axis = unit_axis(axis)
        X = np.asarray(coordinates, float)
        nodes = spin_nodes(X, self.axis)
        if nodes.size < 3:
            raise ValueError(f"{name}: too few nodes away from the spin axis to measure a spin")
        rows = rigid_fit_rows(X[nodes])
        #: the spin's row on the chosen nodes' dofs: theta = g . u[dofs] (rad per m)
        self.g = self.axis @ rows[3:]
        self.dofs = (int(start) + 3 * nodes[:, None] + np.arange(3)).ravel()
        r = X[nodes] - X[nodes].mean(axis=0)
        perp = r - np.outer(r @ self.axis, self.axis)
        #: the spring's stiffness (N m/rad)
        self.stiffness = float(stiffness) * float(E) * float(h) * float((perp ** 2).sum())
        m = self.dofs.size
        self._tangent = Couplings(np.repeat(self.dofs, m), np.tile(self.dofs, m),
                                  self.stiffness * np.outer(self.g, self.g).ravel())

    def angle(self, u: np.ndarray) -> float:
        """The spin (rad) of the unknowns ``u``."""
        return float(self.g @ u[self.dofs])

    def moment(self, u: np.ndarray) -> float:
        """The spring's moment about the axis (N m) at the unknowns ``u``."""
        return self.stiffness * self.angle(u)

    def add(self, u: np.ndarray, t: float, r: np.ndarray, tangent: bool) -> Couplings | None:
        """Add ``k theta g`` to the residual ``r`` (n,) (N) at ``u`` (n,); the tangent's entries
        ``k g g^T`` (N/m) if ``tangent``. ``t`` is not used (the spring is not loaded)."""
        r[self.dofs] += self.moment(u) * self.g
        return self._tangent if tangent else None
