"""Point evaluation of the H8 field at arbitrary points of a body (the seam contact uses):
``Space.locate`` finds the active element of each point, ``Space.evaluate`` the field and
its gradient there."""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.embedding.quadrature import embed, grid_for
from cgfem.fem.space import Space
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import TorusSpec

R, r = 0.02, 0.005
CENTRE = np.array([0.001, -0.002, 0.0015])


@pytest.fixture(scope="module")
def torus_space() -> Space:
    """A torus (axis z) embedded at level 1 (h = 2.5 mm, about four elements across the tube)."""
    solid = build_solid(TorusSpec(tuple(CENTRE), (0.0, 0.0, 1.0), R, r))
    return Space.from_embedding(embed(solid, grid_for(solid, 0.005, 1, (0.31, 0.62, 0.17))))


def _points_in_torus(n: int, seed: int) -> np.ndarray:
    """``n`` uniform random points (n, 3) inside the torus, in no particular order."""
    rng = np.random.default_rng(seed)
    out = []
    while sum(len(o) for o in out) < n:
        x = rng.uniform(-(R + r), R + r, (2 * n, 3)) * [1, 1, r / (R + r)]
        rho = np.hypot(x[:, 0], x[:, 1])
        out.append(x[(rho - R) ** 2 + x[:, 2] ** 2 < r * r])
    return np.concatenate(out)[:n] + CENTRE


def _trilinear(x: np.ndarray, coeff: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A field trilinear in x, y, z (n, 3) and its gradient (n, 3, 3) at ``x`` (n, 3);
    ``coeff`` (3, 8) multiplies 1, X, Y, Z, XY, YZ, ZX, XYZ with X = (x - CENTRE) / R."""
    X, Y, Z = ((x - CENTRE) / R).T
    one, zero = np.ones_like(X), np.zeros_like(X)
    monomials = np.stack([one, X, Y, Z, X * Y, Y * Z, Z * X, X * Y * Z], axis=1)
    d = [np.stack([zero, one, zero, zero, Y, zero, Z, Y * Z], axis=1),
         np.stack([zero, zero, one, zero, X, Z, zero, Z * X], axis=1),
         np.stack([zero, zero, zero, one, zero, Y, X, X * Y], axis=1)]
    grad = np.stack([m @ coeff.T for m in d], axis=2) / R
    return monomials @ coeff.T, grad


def test_interpolates_a_trilinear_field_exactly(torus_space):
    space = torus_space
    coeff = np.random.default_rng(7).uniform(-1.0, 1.0, (3, 8))
    u = _trilinear(space.coordinates, coeff)[0].reshape(-1)
    x = _points_in_torus(100_000, seed=11)
    slots, xi = space.locate(x)
    assert np.all(slots >= 0)                                   # every point of the body is found
    assert np.abs(xi).max() <= 1.0 + 1e-9
    centres = space.centres()[slots]
    assert np.abs(centres + 0.5 * space.h * xi - x).max() < 1e-15
    values, gradients = space.evaluate(u, slots, xi)
    exact, exact_grad = _trilinear(x, coeff)
    assert np.abs(values - exact).max() <= 1e-13 * np.abs(exact).max()
    assert np.abs(gradients - exact_grad).max() <= 1e-12 * np.abs(exact_grad).max()
    # any order of the points: the same numbers, permuted
    perm = np.random.default_rng(3).permutation(x.shape[0])
    s2, xi2 = space.locate(x[perm])
    v2, g2 = space.evaluate(u, s2, xi2)
    assert np.array_equal(s2, slots[perm]) and np.array_equal(v2, values[perm])
    assert np.array_equal(g2, gradients[perm])


def test_gradient_matches_central_differences(torus_space):
    """A random (not trilinear) field: du_i/dX_J against central differences of the
    evaluated field, the points moved by +-delta along X_J and located again."""
    space = torus_space
    u = np.random.default_rng(5).normal(size=space.n_dofs)
    x = _points_in_torus(2000, seed=13)
    slots, xi = space.locate(x)
    keep = np.all(np.abs(xi) < 0.98, axis=1)                    # differences stay in the element
    x, slots, xi = x[keep], slots[keep], xi[keep]
    _, gradients = space.evaluate(u, slots, xi)
    delta = 1e-4 * space.h
    for J in range(3):
        e = np.zeros(3)
        e[J] = delta
        plus = space.evaluate(u, *space.locate(x + e))[0]
        minus = space.evaluate(u, *space.locate(x - e))[0]
        fd = (plus - minus) / (2 * delta)
        assert np.abs(fd - gradients[:, :, J]).max() <= 1e-8 * np.abs(gradients).max()


def test_points_on_faces_and_outside(torus_space):
    space = torus_space
    grid = space.grid
    h = space.h
    ijk = grid.element_ijk(space.elements)
    # a face between two active elements along x: the element above (whose lower face it is)
    upper = space.slot(grid.element_id(ijk + [1, 0, 0]))
    shared = np.flatnonzero(upper >= 0)[0]
    on_face = grid.element_center(ijk[shared])[None] + [[0.5 * h, 0.1 * h, -0.2 * h]]
    nudged = on_face + [[-1e-12 * h, 0, 0], [0, 0, 0], [1e-12 * h, 0, 0]]  # round-off either side
    slots, xi = space.locate(nudged)
    assert np.all(slots == upper[shared]) and np.abs(xi[:, 0] + 1.0).max() < 1e-9
    slots, xi = slots[1:2], xi[1:2]
    # continuity: the lower element's value at the same point is the same (C0 field)
    u = np.random.default_rng(1).normal(size=space.n_dofs)
    below = space.evaluate(u, [shared], xi + [2.0, 0.0, 0.0])[0]
    assert np.abs(space.evaluate(u, slots, xi)[0] - below).max() < 1e-12
    # a face whose element above is inactive: the active one below gets the point
    last = np.flatnonzero(upper < 0)
    last = last[ijk[last, 0] < grid.shape[0] - 1][0]
    point = grid.element_center(ijk[last])[None] + [[0.5 * h, 0.3 * h, 0.1 * h]]
    slots, xi = space.locate(point)
    assert slots[0] == last and abs(xi[0, 0] - 1.0) < 1e-9
    # outside: the hole of the torus, far away, NaN input
    away = np.array([CENTRE, CENTRE + 10.0, [np.nan, 0.0, 0.0]])
    slots, xi = space.locate(away)
    assert np.all(slots == -1) and np.all(np.isnan(xi))
    values, gradients = space.evaluate(u, slots, xi)
    assert np.all(np.isnan(values)) and np.all(np.isnan(gradients))
    with pytest.raises(ValueError, match="dofs"):
        space.evaluate(u[:-1], slots, xi)
