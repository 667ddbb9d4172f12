"""The item protocol: what the Newton driver sums.

A system's residual and tangent are sums over *items*, each owning its state and a part of
the unknowns:

- a body (:class:`BodyItem`): its bulk, loads and weak conditions, on its own dofs, with the
  recovered stress the current outer pass holds frozen;
- a contact pair (:class:`cgfem.contact.assembly.PairItem`): the pair's residual on the
  kinematic vectors of its two sides and its tangent couplings between them, with the
  pair's frozen ``p_N``, active set and pairing;
- the fit constraints of ``nurbs_fit`` (:class:`cgfem.contact.assembly.FitConstraintItem`),
  on the bodies' dofs and the contact set's own unknowns.

Every item has ``add(u, t, r, tangent)``: it adds its residual at the unknowns ``u`` (n,) and
load factor ``t`` to ``r`` (n,) in place and returns, if ``tangent``, its part of the tangent:
a :class:`Block` (a square block on a contiguous range of unknowns, the bodies') or
:class:`Couplings` (triplets on global unknowns). Forces are in N, displacements in m,
stiffnesses in N/m. The system (:class:`cgfem.solve.system.System`) stacks the blocks on
the diagonal and adds the couplings; an item returns None when asked for no tangent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class Block:
    """A tangent block ``K`` (m, m) on the unknowns ``start:start + m``."""

    start: int
    K: sp.spmatrix


@dataclass(frozen=True)
class Couplings:
    """Tangent entries on global unknowns: ``values[k]`` at ``(rows[k], cols[k])``, duplicates
    summed."""

    rows: np.ndarray
    cols: np.ndarray
    values: np.ndarray


class Item(Protocol):
    """Anything whose residual and tangent the Newton driver sums (module docstring)."""

    def add(self, u: np.ndarray, t: float, r: np.ndarray, tangent: bool) -> Block | Couplings | None:
        ...


class BodyItem:
    """One body (:class:`~cgfem.fem.body.BodyModel`) on the unknowns ``start:start + n_dofs``.

    State: :attr:`frozen`, the nodal recovered stress (n_nodes, 3, 3) (Pa) the current outer
    pass holds fixed in the weak conditions, None before any recovery."""

    def __init__(self, model, start: int):
        self.model, self.start = model, int(start)
        self.stop = self.start + int(model.n_dofs)
        self.frozen: np.ndarray | None = None

    def dofs(self, u: np.ndarray) -> np.ndarray:
        """The body's slice of the unknowns (a view)."""
        return u[self.start:self.stop]

    def residual_and_tangent(self, u: np.ndarray, t: float, tangent: bool):
        """The body's residual (n_dofs,) and, if ``tangent``, its tangent (n_dofs, n_dofs)."""
        return self.model.assemble(self.dofs(u), t, self.frozen, tangent)

    def add(self, u: np.ndarray, t: float, r: np.ndarray, tangent: bool) -> Block | None:
        r_body, K = self.residual_and_tangent(u, t, tangent)
        r[self.start:self.stop] += r_body
        return Block(self.start, K) if tangent else None

    def recover(self, u: np.ndarray) -> np.ndarray:
        """The nodal recovered stress (n_nodes, 3, 3) (Pa) of the body's displacement in ``u``."""
        return self.model.recover(self.dofs(u))

    def internal_force(self, u: np.ndarray) -> np.ndarray:
        """``f_int(u)`` (n_dofs,) of the bulk alone (N): the forces the body carries."""
        f = np.zeros(self.model.n_dofs)
        self.model.elasticity.add(self.dofs(u), f, None)
        return f
