"""Global sparse assembly and a Dirichlet-eliminated direct solve (scipy SuperLU)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla


def assemble_matrix(k_e: np.ndarray, dofs_e: np.ndarray, n_dofs: int) -> sp.csr_matrix:
    """Sum element matrices ``k_e`` (ne, m, m) at global DOFs ``dofs_e`` (ne, m) into CSR."""
    rows = np.broadcast_to(dofs_e[:, :, None], k_e.shape).ravel()
    cols = np.broadcast_to(dofs_e[:, None, :], k_e.shape).ravel()
    return sp.csr_matrix((k_e.ravel(), (rows, cols)), shape=(n_dofs, n_dofs))


def assemble_vector(f_e: np.ndarray, dofs_e: np.ndarray, n_dofs: int) -> np.ndarray:
    """Sum element vectors ``f_e`` (ne, m) at global DOFs ``dofs_e`` (ne, m): (n_dofs,)."""
    return np.bincount(dofs_e.ravel(), weights=f_e.ravel(), minlength=n_dofs)


def element_dofs(connectivity: np.ndarray, node_dofs: np.ndarray) -> np.ndarray:
    """Element DOFs (ne, 2·nodes) ordered ``2 k + c`` from node DOFs (n_nodes, 2)."""
    return node_dofs[connectivity].reshape(len(connectivity), -1)


def solve_dirichlet(
    K: sp.csr_matrix, f: np.ndarray, fixed: np.ndarray, values: np.ndarray
) -> np.ndarray:
    """Solve ``K u = f`` with ``u[fixed] = values`` by elimination.

    ``K``: (n, n) sparse, ``f``: (n,), ``fixed``: (m,) DOF ids, ``values``: (m,).
    Returns u (n,). Sparse LU (SuperLU in symmetric mode, minimum degree on Aᵀ + A) of the
    Jacobi-scaled free block, then one step of iterative refinement.
    """
    n = K.shape[0]
    u = np.zeros(n)
    u[fixed] = values
    free = np.setdiff1d(np.arange(n), fixed)
    K = K.tocsr()
    rhs = f[free] - K[free][:, fixed] @ values
    A = K[free][:, free]
    s = 1.0 / np.sqrt(A.diagonal())
    S = sp.diags(s)
    lu = spla.splu(
        (S @ A @ S).tocsc(),
        permc_spec="MMD_AT_PLUS_A",
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )
    x = s * lu.solve(s * rhs)
    x += s * lu.solve(s * (rhs - A @ x))
    u[free] = x
    return u


def element_energies(k_e: np.ndarray, u_e: np.ndarray) -> np.ndarray:
    """Strain energies ½ u_eᵀ k_e u_e (ne,) of element matrices (ne, m, m), values (ne, m)."""
    return 0.5 * np.einsum("ei,eij,ej->e", u_e, k_e, u_e)
