"""A manufactured small-strain solution: a cubic polynomial displacement, its stress and the
body force that balances it, with exact derivatives (no symbolic package needed)."""

from __future__ import annotations

import itertools

import numpy as np

from cgfem.case.model import Body, GridSpec, Material, SolverOptions
from cgfem.embedding.quadrature import embed, grid_for
from cgfem.fem import spr
from cgfem.fem.body import BodyModel
from cgfem.fem.boundary import BoundaryPoints, WeakDirichlet, body_force_load
from cgfem.geometry.specs import SphereSpec
from cgfem.solve.static import System, solve_static

#: exponents (a, b, c) of x^a y^b z^c with a + b + c <= 3
MONOMIALS = [m for m in itertools.product(range(4), repeat=3) if sum(m) <= 3]


class CubicField:
    """``u_i = sum_m C[i, m] x^a y^b z^c`` over :data:`MONOMIALS`."""

    def __init__(self, coefficients: np.ndarray):
        self.C = np.asarray(coefficients, float)

    @classmethod
    def random(cls, seed: int, scale: float = 0.1) -> "CubicField":
        return cls(np.random.default_rng(seed).uniform(-scale, scale, (3, len(MONOMIALS))))

    def _eval(self, x: np.ndarray, d: tuple[int, int, int]) -> np.ndarray:
        """Derivative ``d`` (orders along x, y, z) of every component at points (n, 3) -> (n, 3)."""
        out = np.zeros((x.shape[0], 3))
        for k, m in enumerate(MONOMIALS):
            if any(mi < di for mi, di in zip(m, d)):
                continue
            factor, term = 1.0, np.ones(x.shape[0])
            for axis in range(3):
                for j in range(d[axis]):
                    factor *= m[axis] - j
                term = term * x[:, axis] ** (m[axis] - d[axis])
            out += factor * term[:, None] * self.C[:, k][None, :]
        return out

    def value(self, x: np.ndarray) -> np.ndarray:
        return self._eval(x, (0, 0, 0))

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """(n, 3, 3): ``[p, i, j] = du_i / dx_j``."""
        return np.stack([self._eval(x, tuple(np.eye(3, dtype=int)[j])) for j in range(3)], axis=-1)

    def stress(self, x: np.ndarray, mu: float, lam: float) -> np.ndarray:
        H = self.gradient(x)
        eps = 0.5 * (H + np.swapaxes(H, 1, 2))
        return lam * np.trace(eps, axis1=1, axis2=2)[:, None, None] * np.eye(3) + 2 * mu * eps

    def body_force(self, x: np.ndarray, mu: float, lam: float) -> np.ndarray:
        """``b = -div sigma = -((lam + mu) grad div u + mu laplacian u)`` (n, 3)."""
        second = {}
        for j in range(3):
            for k in range(j, 3):
                d = np.zeros(3, int)
                d[j] += 1
                d[k] += 1
                second[j, k] = second[k, j] = self._eval(x, tuple(d))
        grad_div = np.stack([sum(second[i, j][:, j] for j in range(3)) for i in range(3)], axis=-1)
        laplacian = sum(second[j, j] for j in range(3))
        return -((lam + mu) * grad_div + mu * laplacian)


def solve_manufactured(solid, field: CubicField, h0: float, level: int, offset, E=1.0, nu=0.3,
                       gamma=0.05, linear="auto", surface="nurbs") -> dict:
    """Weak Dirichlet ``u = field`` on the whole surface, the balancing body force; returns
    relative energy and L2 errors, the ZZ estimate and the model size."""
    emb = embed(solid, grid_for(solid, h0, level, offset), surface)
    body = Body("b", SphereSpec(center=(0.0, 0.0, 0.0), radius=1.0), Material("linear_elastic", E, nu),
                GridSpec(h0))   # geometry here is unused: the embedding is given
    options = SolverOptions(ghost_penalty=gamma, outer_passes=40, outer_tol=1e-8, linear=linear)
    model = BodyModel.build(body, emb, [], options, finite=False)
    el, space = model.elasticity, model.space
    mu, lam = el.mu, el.lam
    model.load[:] = body_force_load(space, el.points, lambda x, y, z: field.body_force(np.stack([x, y, z], -1), mu, lam))
    surface = BoundaryPoints.of(space, emb.surface, np.ones(emb.surface.w.size, bool))
    comps = tuple((i, (lambda i: lambda x, y, z: field.value(np.stack([x, y, z], -1))[:, i])(i)) for i in range(3))
    model.dirichlet.append(WeakDirichlet.build("all", space, model.pattern, surface, comps,
                                               10.0 * E / space.h))
    result = solve_static(System([model]), 1, options)
    assert result.status == "converged", result.message
    step = result.steps[-1]
    u = step.u[0]
    pts = el.points
    sigma_h, sigma = el.stress(u), field.stress(pts.x, mu, lam)
    error = spr.energy_norm(pts, sigma_h - sigma, mu, lam)
    uh = space.interpolate(u.reshape(-1, 3), pts.element, pts.xi)
    ue = field.value(pts.x)
    l2 = np.sqrt(np.sum(pts.w * np.sum((uh - ue) ** 2, 1)) / np.sum(pts.w * np.sum(ue ** 2, 1)))
    eta, _ = spr.zz_estimate(space, pts, sigma_h, spr.recovered_at(space, step.recovered[0], pts.element, pts.xi),
                             mu, lam)
    return {"h": space.h, "energy": error / spr.energy_norm(pts, sigma, mu, lam), "l2": l2,
            "effectivity": eta / error, "dofs": model.n_dofs, "passes": step.outer_passes,
            "finite": bool(np.all(np.isfinite(u)))}
