"""The reduced iterative solver of nurbs_fit's saddle points equals a direct solve."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import elasticity_fixture as fx
from cgfem.solve.linear import available_backends
from cgfem.solve.saddle import FitConstraint, reduced_saddle


def _system(symmetric: bool, seed: int = 0):
    K, f, free = fx.clamped_cube(5, 0.2)
    n_u = K.shape[0]
    rng = np.random.default_rng(seed)
    m, n_nodes = 12, n_u // 3
    M = sp.diags([np.full(m - 1, 0.1), np.full(m, 0.5), np.full(m - 1, 0.1)], [-1, 0, 1], format="csr") * 1e-2
    G = sp.random(m, n_nodes, density=0.1, random_state=rng, format="csr") * 1e-2
    scale = float(K.diagonal().mean() / M.diagonal().mean())
    A_dense = M.toarray()
    c = FitConstraint(np.arange(n_u, n_u + 3 * m), np.arange(n_u + 3 * m, n_u + 6 * m), np.arange(n_u), M, G,
                      lambda Y: np.linalg.solve(A_dense, Y), scale)
    R = rng.standard_normal((3 * m, 3 * m))
    Kc = (R @ R.T) * K.diagonal().mean() / (3 * m)
    if not symmetric:
        Kc = Kc + 0.05 * K.diagonal().mean() * rng.standard_normal((3 * m, 3 * m))
    I3 = sp.identity(3)
    G3, M3 = sp.kron(G, I3), sp.kron(M, I3)
    A = sp.bmat([[K, None, -scale * G3.T], [None, sp.csr_matrix(Kc), scale * M3],
                 [-scale * G3, scale * M3, None]], format="csr")
    b = rng.standard_normal(A.shape[0])
    return A, b, n_u, c


PRECONDITIONERS = ["amg", "superlu"] + (["pardiso"] if "pardiso" in available_backends() else [])


@pytest.mark.parametrize("preconditioner", PRECONDITIONERS)
@pytest.mark.parametrize("symmetric", [True, False])
def test_reduced_solve_equals_direct(symmetric, preconditioner):
    A, b, n_u, c = _system(symmetric)
    solver = reduced_saddle(A, n_u, [c], symmetric, preconditioner=preconditioner)
    x = solver.solve(b)
    exact = np.linalg.solve(A.toarray(), b)
    assert np.linalg.norm(A @ x - b) <= 1e-8 * np.linalg.norm(b)
    assert np.linalg.norm(x - exact) <= 1e-7 * np.linalg.norm(exact)
    # a random G is no fit (its lumped form is a poor stand-in): 145 CG iterations measured
    # with AMG; the factorized reduced matrix leaves fewer
    assert solver.info["iterations"][-1] < 400
    if preconditioner != "amg":
        amg = reduced_saddle(A, n_u, [c], symmetric)
        amg.solve(b)
        assert solver.info["iterations"][-1] < amg.info["iterations"][-1]


def test_auto_reduces_symmetric_saddle_points_above_the_direct_limit(monkeypatch):
    from cgfem.solve import linear
    A, b, n_u, c = _system(True)
    monkeypatch.setattr(linear, "SADDLE_MAX_DOFS", 100)
    solver = linear.factorize(A, symmetric=True, indefinite=True, saddle=(n_u, [c]))
    assert solver.backend == "saddle-amg"
    assert np.linalg.norm(A @ solver.solve(b) - b) <= 1e-8 * np.linalg.norm(b)
