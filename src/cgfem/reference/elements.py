"""Biquadratic Lagrange quadrilateral (Q9) for 2D plane-strain elasticity in the y–z plane.

Independent of cgFEM's element code: plain numpy, vectorized over elements.

Reference square (ξ, η) ∈ [-1, 1]²; ξ runs along y, η along z. Local node ``3 a + b``
(a, b ∈ {0, 1, 2}) sits at (ξ, η) = (a − 1, b − 1), i.e. the element's nodes are the
tensor product of the 1D quadratic Lagrange nodes {-1, 0, 1}. Element DOF ``2 k + c``
is component c (0: u_y, 1: u_z) of local node k.

Strains are in Voigt form ``[ε_yy, ε_zz, γ_yz]`` (γ_yz = 2 ε_yz); the plane-strain
matrix D maps them to ``[σ_yy, σ_zz, σ_yz]``.
"""

from __future__ import annotations

import numpy as np

N_NODES = 9
N_DOFS = 18


def lagrange_1d(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quadratic Lagrange basis on {-1, 0, 1} and its derivative.

    ``t``: (n,) points in [-1, 1]. Returns ``(phi, dphi)``, each (n, 3).
    """
    t = np.asarray(t, dtype=float)
    phi = np.stack([0.5 * t * (t - 1.0), 1.0 - t * t, 0.5 * t * (t + 1.0)], axis=-1)
    dphi = np.stack([t - 0.5, -2.0 * t, t + 0.5], axis=-1)
    return phi, dphi


def q9_basis(xi: np.ndarray, eta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Q9 shape functions at reference points.

    ``xi``, ``eta``: (n,). Returns ``(N, dN_dxi, dN_deta)``, each (n, 9).
    """
    px, dpx = lagrange_1d(xi)
    pe, dpe = lagrange_1d(eta)
    n = px.shape[0]
    shape = (n, N_NODES)
    return (
        (px[:, :, None] * pe[:, None, :]).reshape(shape),
        (dpx[:, :, None] * pe[:, None, :]).reshape(shape),
        (px[:, :, None] * dpe[:, None, :]).reshape(shape),
    )


def gauss_rule(n_points: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tensor Gauss–Legendre rule on [-1, 1]²: ``(xi, eta, w)``, each (n_points²,)."""
    t, w = np.polynomial.legendre.leggauss(n_points)
    xi, eta = np.meshgrid(t, t, indexing="ij")
    return xi.ravel(), eta.ravel(), np.outer(w, w).ravel()


def plane_strain_matrix(E: float, nu: float) -> np.ndarray:
    """Plane-strain constitutive matrix (3, 3) on ``[ε_yy, ε_zz, γ_yz]``."""
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    return np.array([[lam + 2 * mu, lam, 0.0], [lam, lam + 2 * mu, 0.0], [0.0, 0.0, mu]])


def physical_gradients(
    coords: np.ndarray, dN_dxi: np.ndarray, dN_deta: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shape-function gradients in (y, z) through the isoparametric map.

    ``coords``: (ne, 9, 2) node positions; ``dN_dxi``, ``dN_deta``: (nq, 9) or (ne, nq, 9).
    Returns ``(dN_dy, dN_dz, detJ)``: (ne, nq, 9), (ne, nq, 9), (ne, nq).
    """
    y, z = coords[..., 0], coords[..., 1]
    sub = "eqk,ek->eq" if dN_dxi.ndim == 3 else "qk,ek->eq"
    j11 = np.einsum(sub, dN_dxi, y)  # dy/dξ
    j12 = np.einsum(sub, dN_dxi, z)  # dz/dξ
    j21 = np.einsum(sub, dN_deta, y)  # dy/dη
    j22 = np.einsum(sub, dN_deta, z)  # dz/dη
    det = j11 * j22 - j12 * j21
    if np.any(det <= 0.0):
        raise ValueError("element with a non-positive Jacobian")
    dxi = dN_dxi if dN_dxi.ndim == 3 else dN_dxi[None]
    deta = dN_deta if dN_deta.ndim == 3 else dN_deta[None]
    dN_dy = (j22[..., None] * dxi - j12[..., None] * deta) / det[..., None]
    dN_dz = (-j21[..., None] * dxi + j11[..., None] * deta) / det[..., None]
    return dN_dy, dN_dz, det


def strain_matrix(dN_dy: np.ndarray, dN_dz: np.ndarray) -> np.ndarray:
    """Voigt strain–displacement matrices B: (..., 3, 18) from gradients (..., 9)."""
    B = np.zeros(dN_dy.shape[:-1] + (3, N_DOFS))
    B[..., 0, 0::2] = dN_dy
    B[..., 1, 1::2] = dN_dz
    B[..., 2, 0::2] = dN_dz
    B[..., 2, 1::2] = dN_dy
    return B


def stiffness(coords: np.ndarray, D: np.ndarray, n_gauss: int = 3) -> np.ndarray:
    """Element stiffness matrices (ne, 18, 18) per metre of thickness.

    ``coords``: (ne, 9, 2); ``D``: (3, 3). A 3×3 Gauss rule is exact on affine
    (rectangular) elements.
    """
    xi, eta, w = gauss_rule(n_gauss)
    _, dxi, deta = q9_basis(xi, eta)
    dN_dy, dN_dz, det = physical_gradients(coords, dxi, deta)
    B = strain_matrix(dN_dy, dN_dz)  # (ne, nq, 3, 18)
    DB = np.einsum("ij,eqjk->eqik", D, B)
    return np.einsum("eq,eqij,eqik->ejk", det * w[None, :], B, DB)


def body_force(coords: np.ndarray, force, n_gauss: int = 4) -> np.ndarray:
    """Element load vectors (ne, 18) of a body force ``force(y, z) -> (n, 2)`` in N/m³."""
    xi, eta, w = gauss_rule(n_gauss)
    N, dxi, deta = q9_basis(xi, eta)
    _, _, det = physical_gradients(coords, dxi, deta)
    yq = np.einsum("qk,ek->eq", N, coords[..., 0])
    zq = np.einsum("qk,ek->eq", N, coords[..., 1])
    f = np.asarray(force(yq.ravel(), zq.ravel()), dtype=float).reshape(yq.shape + (2,))
    fe = np.einsum("eq,qk,eqc->ekc", det * w[None, :], N, f)
    return fe.reshape(len(coords), N_DOFS)


def _edge_map(nodes: np.ndarray, phi: np.ndarray, dphi: np.ndarray):
    """Points (ns, nq, 2) and length Jacobians (ns, nq) of quadratic edges (ns, 3, 2)."""
    x = np.einsum("qk,skc->sqc", phi, nodes)
    jac = np.linalg.norm(np.einsum("qk,skc->sqc", dphi, nodes), axis=-1)
    return x, jac


def edge_mass(nodes: np.ndarray, n_gauss: int = 3) -> np.ndarray:
    """Scalar mass matrices (ns, 3, 3) ∫ φ_i φ_j ds of quadratic edges (ns, 3, 2)."""
    t, w = np.polynomial.legendre.leggauss(n_gauss)
    phi, dphi = lagrange_1d(t)
    _, jac = _edge_map(nodes, phi, dphi)
    return np.einsum("sq,qi,qj->sij", jac * w[None, :], phi, phi)


def edge_load(nodes: np.ndarray, traction, n_gauss: int = 4) -> np.ndarray:
    """Load vectors (ns, 6) of a traction on quadratic edges.

    ``nodes``: (ns, 3, 2) edge nodes (end, middle, end) in (y, z); ``traction(y, z) -> (n, 2)``
    in Pa. Entry ``2 k + c`` is component c at edge node k.
    """
    t, w = np.polynomial.legendre.leggauss(n_gauss)
    phi, dphi = lagrange_1d(t)
    x, jac = _edge_map(nodes, phi, dphi)
    tr = np.asarray(traction(x[..., 0].ravel(), x[..., 1].ravel()), dtype=float)
    tr = tr.reshape(x.shape)
    fe = np.einsum("sq,qk,sqc->skc", jac * w[None, :], phi, tr)
    return fe.reshape(len(nodes), 6)
