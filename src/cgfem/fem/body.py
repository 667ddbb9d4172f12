"""One body of a case, discretized: its hexahedral space and every term acting on it.

A :class:`BodyModel` sums its terms (bulk elasticity, ghost penalty, weak Dirichlet
conditions, dead tractions and body forces) into a residual and a CSR tangent over its own
dofs, for a load factor ``t`` and a frozen recovered stress (the outer-loop state). Bodies
know nothing of each other; the solver stacks them and couples them by contact.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from cgfem.case.model import Body, Case, DisplacementBC, SolverOptions, TractionBC
from cgfem.embedding.quadrature import Embedding
from cgfem.fem import spr
from cgfem.fem._material_kernels import LINEAR_ELASTIC, NEO_HOOKEAN, cauchy_batch
from cgfem.fem.materials import model_id
from cgfem.fem.assembly import Pattern, build_pattern
from cgfem.fem.boundary import (BoundaryPoints, WeakDirichlet, body_force_load, surface_mask,
                                traction_load)
from cgfem.fem.elasticity import Elasticity
from cgfem.fem.element import HEX8, Hexahedron
from cgfem.fem.ghost import GhostFaces, ghost_penalty
from cgfem.fem.space import ElementPoints, Space


@dataclass
class BodyModel:
    name: str
    space: Space
    embedding: Embedding
    pattern: Pattern
    elasticity: Elasticity
    ghost: sp.csr_matrix             # (n_dofs, n_dofs) the ghost penalty of parameter gamma
    gamma: float                     # the ghost-penalty parameter it was built with
    kappa_dirichlet: float           # the weak-Dirichlet factor, beta = kappa_dirichlet E / h
    dirichlet: list[WeakDirichlet]
    load: np.ndarray                 # (n_dofs,) dead loads at load factor 1
    recovery: spr.Recovery
    ghost_positions: np.ndarray = field(repr=False)   # where ghost.data lies in the pattern's data
    _boundary: BoundaryPoints | None = field(default=None, repr=False)
    _samples: ElementPoints | None = field(default=None, repr=False)

    @classmethod
    def build(cls, body: Body, embedding: Embedding, boundary: list, options: SolverOptions,
              finite: bool, element: Hexahedron = HEX8) -> "BodyModel":
        """The model of ``body`` on ``embedding`` with ``element`` and the case's ``boundary``
        entries that name it (each a :class:`DisplacementBC` or :class:`TractionBC`);
        ``options`` gives the weak-Dirichlet and ghost-penalty parameters (the element's own
        ``kappa_dirichlet`` and ``gamma`` unless the options set them). In small strain
        every material is its linearization (linear elastic with the same E and nu). The
        embedding's rules must integrate the element's degree (``embedding.degree >=
        element.degree``), else ``ValueError``."""
        degree = getattr(embedding, "degree", 2)
        if degree < element.degree:
            raise ValueError(f"the embedding's rules are exact to degree {degree}, the order-"
                             f"{element.order} element needs {element.degree}")
        space = Space.from_embedding(embedding, element)
        lam, mu = body.material.lame()          # Lame(lam, mu)
        model = model_id(body.material.model) if finite else LINEAR_ELASTIC
        gamma = element.ghost_penalty if options.ghost_penalty is None else options.ghost_penalty
        faces = GhostFaces.of(space)
        pattern = build_pattern(space, faces.node_pairs(element) if gamma != 0.0 else None)
        G, ghost_positions = ghost_penalty(space, faces, pattern, gamma, lam + 2.0 * mu)
        volume = space.volume_points(embedding)
        elasticity = Elasticity(space, pattern, volume, model, mu, lam)
        kappa = element.kappa_dirichlet if options.kappa_dirichlet is None else options.kappa_dirichlet
        beta = kappa * body.material.E / space.h
        load = np.zeros(space.n_dofs)
        if body.body_force is not None:
            load += body_force_load(space, volume, body.body_force)
        dirichlet = []
        surface, names = embedding.boundary, embedding.patch_names
        for bc in boundary:
            points = BoundaryPoints.of(space, surface, surface_mask(surface, names, bc.patches))
            if isinstance(bc, DisplacementBC):
                label = f"{body.name}/{'+'.join(bc.patches)}"
                dirichlet.append(WeakDirichlet.build(label, space, pattern, points, bc.components, beta))
            elif isinstance(bc, TractionBC):
                load += traction_load(space, points, bc.value)
        return cls(body.name, space, embedding, pattern, elasticity, G, gamma, kappa, dirichlet, load,
                   spr.build_recovery(space), ghost_positions)

    @property
    def n_dofs(self) -> int:
        return self.space.n_dofs

    @property
    def definition(self) -> str:
        """The contact surface definition of the body's embedding: ``facets``, ``nurbs_fe``
        or ``nurbs_fit``."""
        return self.embedding.definition

    @property
    def finite(self) -> bool:
        return self.elasticity.model == NEO_HOOKEAN

    def assemble(self, u: np.ndarray, t: float, frozen_stress: np.ndarray | None,
                 tangent: bool = True) -> tuple[np.ndarray, sp.csr_matrix | None]:
        """Residual ``r(u) = f_int - f_ext`` (n_dofs,) and, if asked, its tangent (CSR), at
        load factor ``t`` with the recovered stress held at ``frozen_stress`` (n_nodes, 3, 3)
        (None: no recovery yet, the weak Dirichlet terms are pure penalties)."""
        r = -t * self.load
        data = self.pattern.zeros() if tangent else None
        self.elasticity.add(u, r, data)
        if self.ghost.nnz:
            r += self.ghost @ u
            if data is not None:
                data[self.ghost_positions] += self.ghost.data
        for term in self.dirichlet:
            term.add(u, t, frozen_stress, r, data)
        return r, (self.pattern.matrix(data) if data is not None else None)

    # -- recovered stress and outputs ------------------------------------------------------
    def recover(self, u: np.ndarray) -> np.ndarray:
        """Nodal recovered stress (n_nodes, 3, 3): SPR of ``P`` (Cauchy in small strain)."""
        return spr.recover(self.recovery, self.elasticity.stress(u, self.sampling_points()))

    def sampling_points(self) -> ElementPoints:
        """The SPR sampling points of the space (built once)."""
        if self._samples is None:
            self._samples = self.space.points_at(*spr.sampling_points(self.space))
        return self._samples

    @property
    def boundary_points(self) -> BoundaryPoints:
        """Every point of the boundary rule, grouped by element (built once)."""
        if self._boundary is None:
            surface = self.embedding.boundary
            self._boundary = BoundaryPoints.of(self.space, surface, np.ones(surface.w.size, bool))
        return self._boundary

    def reactions(self, u: np.ndarray, t: float, frozen_stress: np.ndarray | None
                  ) -> dict[str, np.ndarray]:
        """Force (3,) of every weak Dirichlet support on the body, by label, at ``u`` with
        the recovered stress the solve held frozen (``StepRecord.frozen_stress``)."""
        return {d.label: d.reaction(u, t, frozen_stress) for d in self.dirichlet}

    def cauchy(self, u: np.ndarray, points: ElementPoints | None = None) -> np.ndarray:
        """Cauchy stress (n, 3, 3) at ``points`` (default: the volume rule)."""
        el = self.elasticity
        return cauchy_batch(el.model, el.gradients(u, points), el.mu, el.lam)


def boundary_of(case: Case, body: str) -> list:
    """The boundary entries of ``case`` acting on ``body``, in file order."""
    return [bc for bc in case.boundary if bc.body == body]
