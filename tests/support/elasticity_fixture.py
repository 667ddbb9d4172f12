"""Linear-elasticity stiffness of a structured grid of H8 bricks (test and benchmark fixture).

Independent of the package's element kernels on purpose: the solver tests and
``benchmarks/bench_solvers.py`` need realistic elasticity matrices, not the FEM layer.
Nodes are numbered ``i + (nx+1) * (j + (ny+1) * k)``; dofs are interleaved,
``3 * node + component``.
"""

from __future__ import annotations

import itertools

import numpy as np
import scipy.sparse as sp

#: local coordinates of the 8 nodes of the reference cube
NODE_XI = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                    [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)


def isotropic_d(E: float, nu: float) -> np.ndarray:
    """6x6 Voigt elasticity matrix (xx, yy, zz, yz, xz, xy; engineering shear strains)."""
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[np.arange(3), np.arange(3)] += 2 * mu
    D[np.arange(3, 6), np.arange(3, 6)] = mu
    return D


def brick_stiffness(h: float = 1.0, E: float = 1.0, nu: float = 0.3) -> np.ndarray:
    """24x24 stiffness of a cube of side ``h`` (2x2x2 Gauss), dofs ``3 * node + component``."""
    g = np.array(list(itertools.product((-1, 1), repeat=3))) / np.sqrt(3.0)     # (8, 3) points
    factors = 1 + g[:, None, :] * NODE_XI[None, :, :]  # (8 points, 8 nodes, 3)
    dN = np.empty((8, 8, 3))
    for d in range(3):
        others = [e for e in range(3) if e != d]
        dN[:, :, d] = NODE_XI[None, :, d] * factors[:, :, others].prod(axis=2) / 8 * (2 / h)
    B = np.zeros((8, 6, 24))
    for d in range(3):
        B[:, d, d::3] = dN[:, :, d]
    for row, (a, b) in zip((3, 4, 5), ((1, 2), (0, 2), (0, 1))):   # yz, xz, xy
        B[:, row, a::3] = dN[:, :, b]
        B[:, row, b::3] = dN[:, :, a]
    return np.einsum("gia,ij,gjb->ab", B, isotropic_d(E, nu), B) * (h / 2) ** 3


def grid_coords(nx: int, ny: int, nz: int, h: float = 1.0) -> np.ndarray:
    """(n_nodes, 3) node coordinates of the grid."""
    k, j, i = np.meshgrid(np.arange(nz + 1), np.arange(ny + 1), np.arange(nx + 1), indexing="ij")
    return h * np.column_stack([i.ravel(), j.ravel(), k.ravel()]).astype(float)


def element_dofs(nx: int, ny: int, nz: int) -> np.ndarray:
    """(n_elements, 24) global dofs of every element."""
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    base = (i + (nx + 1) * (j + (ny + 1) * k)).ravel()
    up = (NODE_XI > 0).astype(np.int64)
    offsets = up[:, 0] + (nx + 1) * (up[:, 1] + (ny + 1) * up[:, 2])
    nodes = base[:, None] + offsets[None, :]
    return (3 * nodes[:, :, None] + np.arange(3)).reshape(len(base), 24)


def stiffness(nx: int, ny: int, nz: int, h: float = 1.0, nu: float = 0.3,
              element_scale: np.ndarray | None = None) -> sp.csr_matrix:
    """Unconstrained global stiffness (E = 1). ``element_scale`` multiplies each element's
    stiffness (e.g. a small volume fraction for cut cells)."""
    dofs = element_dofs(nx, ny, nz).astype(np.int32)
    n_el = dofs.shape[0]
    scale = np.ones(n_el) if element_scale is None else np.asarray(element_scale, float)
    data = (scale[:, None] * brick_stiffness(h, 1.0, nu).ravel()[None, :]).ravel()
    rows = np.repeat(dofs, 24, axis=1).ravel()
    cols = np.tile(dofs, (1, 24)).ravel()
    n = 3 * (nx + 1) * (ny + 1) * (nz + 1)
    K = sp.coo_matrix((data, (rows, cols)), shape=(n, n)).tocsr()
    K.sum_duplicates()
    return K


def clamped_cube(n: int, h: float = 1.0) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """``n^3`` cube, bottom face (z = 0) clamped by eliminating its dofs, unit downward
    load spread over the top face. Returns (K, f, free dofs)."""
    K = stiffness(n, n, n, h)
    coords = grid_coords(n, n, n, h)
    fixed = np.flatnonzero(np.repeat(coords[:, 2] == 0.0, 3))
    free = np.setdiff1d(np.arange(K.shape[0]), fixed)
    f = np.zeros(K.shape[0])
    top = np.flatnonzero(coords[:, 2] == coords[:, 2].max())
    f[3 * top + 2] = -1.0 / top.size
    return K[free][:, free].tocsr(), f[free], free


def penalty_cube(n: int, penalty: float = 1e3, cut_scale: float = 1e-4,
                 seed: int = 0) -> tuple[sp.csr_matrix, np.ndarray]:
    """A badly scaled cube: the bottom face is clamped by a penalty ``penalty`` times the
    largest stiffness diagonal, and a random tenth of the elements are "cut cells" with
    stiffness scaled by ``cut_scale``. Returns (K, f) over all dofs."""
    rng = np.random.default_rng(seed)
    scale = np.where(rng.random(n ** 3) < 0.1, cut_scale, 1.0)
    K = stiffness(n, n, n, element_scale=scale)
    coords = grid_coords(n, n, n)
    fixed = np.flatnonzero(np.repeat(coords[:, 2] == 0.0, 3))
    P = sp.csr_matrix((np.full(fixed.size, penalty * K.diagonal().max()), (fixed, fixed)),
                      shape=K.shape)
    f = np.zeros(K.shape[0])
    top = np.flatnonzero(coords[:, 2] == coords[:, 2].max())
    f[3 * top + 2] = -1.0 / top.size
    f[3 * top] = 0.3 / top.size
    return (K + P).tocsr(), f
