"""The NURBS surface fitted to the FE displacement (``nurbs_fit``, paper eqs. 18-22).

Per contact patch the control-point displacements ``V`` (n_ctrl, 3) are the least-squares
fit of the FE displacement ``N u`` on the patch (eq. 18)::

    M V = G u,   M_ij = int R_i R_j dA,   G_ia = int R_i N_a dA        (eqs. 19-20)

integrated with the body's exact surface rule (its points on that patch), so the fitted
surface is ``x = S(s, t) (P + V)`` (eq. 21). ``R_i`` are the rational basis functions of the
*fitting space* of the patch (:func:`fit_space`): the paper's net refined by knot insertion
(and degree elevation to 2) so that its spans are about one element size h long, because
the original net of a torus cannot follow a fine grid's field. Refinement keeps the geometry
and the parametrisation, so a rule point's ``(s, t)`` on the original patch is its ``(s, t)``
on the fitting surface.

Control functions are numbered u-major, ``k = i n_v + j`` (``i`` along u); ``V[k]`` moves
control point ``P[k]``. The FE side acts per component: ``V[:, c] = M^{-1} G u[:, c]`` with
``u`` (n_dofs,) node-major (``u.reshape(-1, 3)``).

``M`` is banded (bandwidth ``p n_v + q`` in this numbering, or ``q n_u + p`` in the
transposed one) and factorized once by a banded Cholesky (:class:`BandedCholesky`), which
also proves it positive definite. A patch that closes on itself (a full torus: both
directions) couples its first and last rows, so neither numbering is banded; reverse
Cuthill-McKee then folds the rings (chain3's middle link at level 2: bandwidth 173 instead
of 2975, :func:`band_order`). The fitting space, the
ties and why the fit stays a constraint in the solver: docs/methods/contact.md.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import meshio
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee

from cgfem.contact import _fit_kernels as _k
from cgfem.contact.surfaces import locate_points
from cgfem.embedding.export import write_vtu_files
from cgfem.embedding.partition import SurfaceQuadrature
from cgfem.errors import InputError
from cgfem.fem.space import Space
from cgfem.geometry.io import solid_from_dict, write_solid
from cgfem.geometry.nurbs import NurbsSurface
from cgfem.geometry.refine import elevate_degree, refine_knots
from cgfem.geometry.solid import Patch, Solid

#: default refinement of the fitting space: spans of about h (see :func:`fit_space`)
DEFAULT_REFINE = "auto"
#: ``auto`` raises each direction to at least this degree (a C1 fitted surface)
AUTO_MIN_DEGREE = 2
#: chords per knot span (and iso-lines per span of the other direction) measuring arc lengths
ARC_SAMPLES = 8
#: between the body's and the patch's name of a fitted patch in the result files
#: NURBS JSON (``body::patch``; patch names may not contain '/')
FIT_NAME_SEPARATOR = "::"
#: rows of :attr:`SurfaceBasis.values`: R, R_s, R_t, R_ss, R_st, R_tt
ORDERS = _k.ORDERS


# -- the fitting space ------------------------------------------------------------------
def span_lengths(surface: NurbsSurface, direction: int) -> tuple[np.ndarray, np.ndarray]:
    """Distinct knots ``breaks`` (m + 1,) of ``direction`` (0: u, 1: v) and the physical length
    (m,) of each of its m spans: the longest arc length of the span along that direction
    over iso-lines of the other direction (:data:`ARC_SAMPLES` chords per span, iso-lines at
    the other direction's breaks and :data:`ARC_SAMPLES` per span between them)."""
    breaks = surface.breaks()
    along, across = breaks[direction], breaks[1 - direction]
    s = np.linspace(0.0, 1.0, ARC_SAMPLES + 1)
    a = (along[:-1, None] + s[None, :] * np.diff(along)[:, None]).ravel()          # (m (S+1),)
    b = np.unique((across[:-1, None] + s[None, :] * np.diff(across)[:, None]).ravel())
    grid = np.stack(np.meshgrid(a, b, indexing="ij"), axis=-1).reshape(-1, 2)
    if direction == 1:
        grid = grid[:, ::-1]
    x = surface.evaluate(np.ascontiguousarray(grid)).reshape(along.size - 1, ARC_SAMPLES + 1, b.size, 3)
    chords = np.linalg.norm(np.diff(x, axis=1), axis=-1).sum(axis=1)                  # (m, lines)
    return along, chords.max(axis=1)


def _check_refine(refine) -> str | int:
    if refine is None or refine == "none":
        return "none"
    if refine == "auto":
        return "auto"
    if isinstance(refine, (int, np.integer)) and not isinstance(refine, bool) and refine >= 0:
        return int(refine)
    raise InputError("fit", f"expected 'auto', 'none' or a number of knots per span >= 0, got {refine!r}")


def fit_space(surface: NurbsSurface, h: float, refine: str | int | None = DEFAULT_REFINE) -> NurbsSurface:
    """The fitting space of one patch: the same geometry on a refined net.

    ``refine``: ``"auto"`` (default) raises every degree to at least
    :data:`AUTO_MIN_DEGREE` and splits every knot span into ``max(1, round(L / h))`` equal
    parametric spans, L its physical length (:func:`span_lengths`), so the control net is
    about h fine (a finer grid gets a finer fit); ``"none"`` or None: the original net (the
    paper's); an int n: n uniformly spaced knots inserted in every span (no elevation).
    """
    mode = _check_refine(refine)
    if mode == "none":
        return surface
    if mode == "auto" and not h > 0.0:
        raise InputError("h", f"must be positive, got {h!r}")
    fitted = surface
    for direction in (0, 1):
        if mode == "auto":
            raise_by = AUTO_MIN_DEGREE - fitted.degree[direction]
            if raise_by > 0:
                fitted = elevate_degree(fitted, direction, raise_by)
            breaks, length = span_lengths(fitted, direction)
            counts = np.maximum(1, np.round(length / h)).astype(np.int64)
        else:
            breaks = fitted.breaks()[direction]
            counts = np.full(breaks.size - 1, mode + 1, np.int64)
        new = [a + (b - a) * np.arange(1, n) / n for a, b, n in zip(breaks[:-1], breaks[1:], counts)]
        new = np.concatenate(new) if new else np.zeros(0)
        if new.size:
            fitted = refine_knots(fitted, direction, new)
    return fitted


# -- basis functions at points ----------------------------------------------------------
@dataclass(frozen=True)
class SurfaceBasis:
    """The non-vanishing rational basis functions of a surface at n points.

    index : (n, k) int64 flat control index ``i n_v + j`` of each function, k = (p+1)(q+1)
    values : (n, 6, k) ``R``, ``R_s``, ``R_t``, ``R_ss``, ``R_st``, ``R_tt`` (:data:`ORDERS`)
    n_ctrl : number of control points of the surface
    """

    index: np.ndarray
    values: np.ndarray
    n_ctrl: int

    def matrix(self, row: int = 0) -> sp.csr_matrix:
        """(n, n_ctrl) sparse matrix of derivative ``row`` of :data:`ORDERS` (0: the values)."""
        n, k = self.index.shape
        indptr = np.arange(0, n * k + 1, k)
        return sp.csr_matrix((self.values[:, row].ravel(), self.index.ravel(), indptr), shape=(n, self.n_ctrl))

    def apply(self, control: np.ndarray) -> np.ndarray:
        """``sum_i d R_i * control[i]`` for every row of :data:`ORDERS`: (n, 6, 3) from
        ``control`` (n_ctrl, 3), e.g. ``x, x_s, x_t, x_ss, x_st, x_tt`` from ``P + V``."""
        return np.einsum("prk,pkc->prc", self.values, np.asarray(control, float)[self.index])


def surface_basis(surface: NurbsSurface, uv: np.ndarray) -> SurfaceBasis:
    """Rational basis of ``surface`` and its derivatives to order 2 at ``uv`` (n, 2),
    clipped to the parameter domain."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    (u0, u1), (v0, v1) = surface.domain
    uv = np.ascontiguousarray(np.column_stack([np.clip(uv[:, 0], u0, u1), np.clip(uv[:, 1], v0, v1)]))
    p, q = surface.degree
    k = (p + 1) * (q + 1)
    index = np.empty((uv.shape[0], k), np.int64)
    values = np.empty((uv.shape[0], len(ORDERS), k))
    _k.rational_basis_batch(p, q, surface.knots_u, surface.knots_v, np.ascontiguousarray(surface.weights),
                            uv, index, values)
    return SurfaceBasis(index, values, int(surface.weights.size))


def fe_shape_matrix(space: Space, x: np.ndarray) -> sp.csr_matrix:
    """(n, n_nodes) shape functions of ``space``'s element at points ``x`` (n, 3) (located
    in their active elements); a point in no active element is a ValueError."""
    slots, xi = locate_points(space, x)
    N = space.element.tabulate(xi, space.h)[0]
    n, k = N.shape
    return sp.csr_matrix((N.ravel(), space.connectivity[slots].ravel(), np.arange(0, k * n + 1, k)),
                         shape=(n, space.n_nodes))


# -- C1 across the rational circles' double knots ---------------------------------------
def _tie(surface: NurbsSurface, direction: int, i: int) -> float | None:
    """The coefficient ``a`` of the C1 condition ``V_i = a V_{i-1} + (1 - a) V_{i+1}`` (every
    line of the other direction) across the interior knot of full multiplicity p whose
    interpolating control row is ``i`` along ``direction``::

        a = (w_{i-1} / D_l) / (w_{i-1} / D_l + w_{i+1} / D_r)

    (D the spans either side): with it the fitted displacement ``sum R V`` is C1 across the
    knot line. None unless the weight ratios ``w_{i+-1} / w_i`` are the same on every line
    (then ``a`` is too) and the geometry itself satisfies the condition (no crease)."""
    p = surface.degree[direction]
    knots = surface.knots_u if direction == 0 else surface.knots_v
    net = surface.control if direction == 0 else surface.control.transpose(1, 0, 2)
    w = net[..., 3]
    d_l, d_r = knots[i + p] - knots[i], knots[i + p + 1] - knots[i + 1]    # knots i+1..i+p: the joint
    ratio_l, ratio_r = w[i - 1] / w[i], w[i + 1] / w[i]
    if not (d_l > 0.0 and d_r > 0.0) or np.ptp(ratio_l) > 1e-12 * ratio_l.max() \
            or np.ptp(ratio_r) > 1e-12 * ratio_r.max():
        return None
    a = float((ratio_l[0] / d_l) / (ratio_l[0] / d_l + ratio_r[0] / d_r))
    pts = net[..., :3] / w[..., None]
    crease = np.abs(pts[i] - a * pts[i - 1] - (1.0 - a) * pts[i + 1]).max()
    return a if crease <= 1e-12 * float(np.abs(pts).max()) else None


def _seam_tie(surface: NurbsSurface, direction: int) -> float | None:
    """The coefficient ``a`` of the seam of a direction along which the patch closes on itself
    (its first and last control rows coincide, as a revolved turn's do): the two rows are one
    point, tied as an interior joint (:func:`_tie`) between row ``n - 2`` (before the seam) and
    row 1 (after it), ``V_0 = V_{n-1} = a V_{n-2} + (1 - a) V_1``. None if the direction is
    open, has fewer than 4 rows, or the condition does not hold for the geometry."""
    p = surface.degree[direction]
    knots = surface.knots_u if direction == 0 else surface.knots_v
    net = surface.control if direction == 0 else surface.control.transpose(1, 0, 2)
    n = net.shape[0]
    if n < 4:
        return None
    w = net[..., 3]
    pts = net[..., :3] / w[..., None]
    scale = float(np.abs(pts).max())
    if np.abs(pts[0] - pts[-1]).max() > 1e-12 * scale or np.ptp(w[0] / w[-1]) > 1e-12:
        return None
    d_l, d_r = knots[n - 1 + p] - knots[n - 1], knots[p + 1] - knots[1]
    ratio_l, ratio_r = w[n - 2] / w[n - 1], w[1] / w[0]
    if not (d_l > 0.0 and d_r > 0.0) or np.ptp(ratio_l) > 1e-12 * ratio_l.max() \
            or np.ptp(ratio_r) > 1e-12 * ratio_r.max():
        return None
    a = float((ratio_l[0] / d_l) / (ratio_l[0] / d_l + ratio_r[0] / d_r))
    crease = np.abs(pts[0] - a * pts[n - 2] - (1.0 - a) * pts[1]).max()
    return a if crease <= 1e-12 * scale else None


def c1_extraction(surface: NurbsSurface) -> tuple[sp.csr_matrix, tuple[int, int]]:
    """``T`` (n_ctrl, n_free) with ``V = T Z`` and the free net's shape ``(n_u', n_v')``: the
    control rows at interior knots of full multiplicity (the joints of rational circles) are
    tied to their neighbours so that the fitted displacement is C1 there (:func:`_tie`), and
    along a direction in which the patch closes on itself the two seam rows are one,
    tied the same way (:func:`_seam_tie`: the fitted surface stays closed); free controls
    keep their u-major order. The identity where there are no such knots or seams."""
    shape = surface.control.shape[:2]
    T = sp.identity(shape[0] * shape[1], format="csr")
    free = list(shape)
    for direction in (0, 1):
        p = surface.degree[direction]
        n = shape[direction]
        knots = surface.knots_u if direction == 0 else surface.knots_v
        values, counts = np.unique(knots[p + 1: knots.size - p - 1], return_counts=True)
        rows = [int(np.searchsorted(knots, v, side="right")) - p - 1 for v, c in zip(values, counts) if c == p]
        tied = {i: (i - 1, i + 1, a) for i in rows if (a := _tie(surface, direction, i)) is not None}
        seam = _seam_tie(surface, direction)
        if seam is not None and not {0, 1, n - 2, n - 1} & set(tied):
            tied[0] = tied[n - 1] = (n - 2, 1, seam)
        if not tied:
            continue
        keep = np.array([i for i in range(n) if i not in tied])
        col = np.full(n, -1)
        col[keep] = np.arange(keep.size)
        r, c, v = list(keep), list(col[keep]), [1.0] * keep.size       # 1D map (n, n_keep)
        for i, (left, right, a) in tied.items():
            r += [i, i]
            c += [col[left], col[right]]
            v += [a, 1.0 - a]
        step = sp.csr_matrix((v, (r, c)), shape=(n, keep.size))
        other = sp.identity(free[1 - direction], format="csr")
        T = (T @ (sp.kron(step, other) if direction == 0 else sp.kron(other, step))).tocsr()
        free[direction] = keep.size
    return T, (free[0], free[1])


# -- the factorization of M -------------------------------------------------------------
@dataclass(frozen=True)
class BandedCholesky:
    """Cholesky factor of a banded SPD matrix in a permuted order (numba kernels of
    :mod:`cgfem.contact._fit_kernels`: no BLAS threads, whose start-up dominated LAPACK's
    banded routine on these small bands on a busy machine).

    perm : (n,) the original index of every row of the permuted matrix
    factor : (n, bandwidth + 1) lower band of L by columns, ``factor[j, d] = L[j + d, j]``
    """

    perm: np.ndarray
    factor: np.ndarray

    @classmethod
    def of(cls, M: sp.spmatrix, perm: np.ndarray) -> "BandedCholesky":
        """Factorize ``M`` (n, n) symmetric; raises :class:`numpy.linalg.LinAlgError` if it
        is not positive definite."""
        A = sp.tril(sp.csr_matrix(M)[perm][:, perm]).tocoo()
        bandwidth = int((A.row - A.col).max()) if A.nnz else 0
        lb = np.zeros((M.shape[0], bandwidth + 1))
        lb[A.col, A.row - A.col] = A.data
        failed = _k.banded_cholesky(lb)
        if failed >= 0:
            raise np.linalg.LinAlgError(f"not positive definite (pivot {failed})")
        return cls(np.asarray(perm, np.int64), lb)

    @property
    def bandwidth(self) -> int:
        return int(self.factor.shape[1] - 1)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``M^{-1} b`` for ``b`` (n,) or (n, m)."""
        b = np.asarray(b, float)
        y = np.ascontiguousarray(b[self.perm].reshape(b.shape[0], -1))
        _k.banded_cholesky_solve(self.factor, y)
        x = np.empty_like(y)
        x[self.perm] = y
        return x.reshape(b.shape)


def band_order(n_u: int, n_v: int, degree: tuple[int, int], M: sp.spmatrix | None = None) -> np.ndarray:
    """Permutation (n_u n_v,) of the u-major control numbering that minimises the bandwidth
    of M: u-major (bandwidth ``p n_v + q``) or v-major (``q n_u + p``); given ``M`` (its
    pattern), the one of those and reverse Cuthill-McKee's whose bandwidth in ``M`` is
    smallest, the natural ones first on a tie (a closed direction's seam couples its first
    and last rows, which only the latter folds)."""
    p, q = degree
    natural = np.arange(n_u * n_v)
    transposed = natural.reshape(n_u, n_v).T.ravel()
    if M is None:
        return natural if p * n_v + q <= q * n_u + p else transposed
    A = sp.coo_matrix(M)
    candidates = (natural, transposed,
                  reverse_cuthill_mckee(sp.csr_matrix(M), symmetric_mode=True).astype(np.int64))
    return min(candidates, key=lambda perm: bandwidth(A, perm))


def bandwidth(M: sp.spmatrix, perm: np.ndarray) -> int:
    """Largest ``|i - j|`` over the entries of ``M[perm][:, perm]``."""
    A = sp.coo_matrix(M)
    rank = np.empty(perm.size, np.int64)
    rank[perm] = np.arange(perm.size)
    return int(np.abs(rank[A.row] - rank[A.col]).max()) if A.nnz else 0


# -- the fit of one patch ---------------------------------------------------------------
@dataclass(frozen=True)
class PatchFit:
    """Least-squares fit of the FE displacement on one patch (eqs. 18-20).

    name, patch : the patch's name and index in its solid
    surface : the fitting surface (geometry of the patch, refined net), n_ctrl control points
    space : the body's FE space (n_nodes nodes)
    T : (n_ctrl, n_free) csr, ``V = T Z``: the free control displacements Z of a fitted
        surface that is C1 across the rational circles' double knots (:func:`c1_extraction`;
        the identity for ``smooth=False`` or without such knots)
    M : (n_free, n_free) csr, ``T^T [int R_i R_j dA] T``; factor : its :class:`BandedCholesky`
    G : (n_free, n_nodes) csr, ``T^T [int R_i N_a dA]``: the fit is ``M Z = G u``, ``V = T Z``
    uv, x, w : (n_q, 2), (n_q, 3), (n_q,) the rule points' parameters, positions and weights

    The point matrices R (n_q, n_ctrl) and N (n_q, n_nodes) are rebuilt on demand
    (:meth:`rule_matrices`), not kept: they take a few hundred bytes per rule point
    (docs/methods/contact.md).
    """

    name: str
    patch: int
    surface: NurbsSurface
    space: Space
    T: sp.csr_matrix
    M: sp.csr_matrix
    factor: BandedCholesky
    G: sp.csr_matrix
    uv: np.ndarray
    x: np.ndarray
    w: np.ndarray

    @property
    def n_ctrl(self) -> int:
        """Control points of the fitting surface (rows of V)."""
        return int(self.T.shape[0])

    @property
    def n_free(self) -> int:
        """Free control displacements (rows of Z, of M and of G)."""
        return int(self.T.shape[1])

    @property
    def control_points(self) -> np.ndarray:
        """(n_ctrl, 3) reference control points P, u-major."""
        return self.surface.points.reshape(-1, 3)

    @property
    def area(self) -> float:
        """Area of the patch by its rule (m^2)."""
        return float(self.w.sum())

    def rule_matrices(self) -> tuple[sp.csr_matrix, sp.csr_matrix]:
        """R (n_q, n_ctrl): the fitting basis, and N (n_q, n_nodes): the FE shape functions,
        at the rule points (``M = R^T W R``, ``G = R^T W N``, W the weights)."""
        return surface_basis(self.surface, self.uv).matrix(), fe_shape_matrix(self.space, self.x)

    def displacements(self, u: np.ndarray) -> np.ndarray:
        """Control-point displacements V (n_ctrl, 3) fitted to ``u`` (n_dofs,): ``T M^{-1} G u``."""
        return self.T @ self.factor.solve(self.G @ _nodal(u, self.space))

    def misfit(self, u: np.ndarray, V: np.ndarray | None = None) -> tuple[float, float]:
        """``sqrt(int |S V - N u|^2 dA)`` and ``sqrt(int |N u|^2 dA)`` by the rule (units: a
        displacement times the square root of an area, m^2); ``V`` defaults to the fit of ``u``."""
        U = _nodal(u, self.space)
        V = self.displacements(u) if V is None else V
        R, N = self.rule_matrices()
        fe = N @ U
        err = R @ V - fe
        return (float(np.sqrt(self.w @ np.einsum("pc,pc->p", err, err))),
                float(np.sqrt(self.w @ np.einsum("pc,pc->p", fe, fe))))

    def l2_error(self, u: np.ndarray, V: np.ndarray | None = None) -> float:
        """``sqrt(int |S V - N u|^2 dA)``, the L2 distance of the fit to the FE field."""
        return self.misfit(u, V)[0]

    def relative_l2_error(self, u: np.ndarray, V: np.ndarray | None = None) -> float:
        """:meth:`l2_error` over ``sqrt(int |N u|^2 dA)`` (0 for a zero field)."""
        err, norm = self.misfit(u, V)
        return err / norm if norm > 0.0 else 0.0

    # -- the fitted surface (eqs. 21-22) ------------------------------------------------
    def basis(self, uv: np.ndarray) -> SurfaceBasis:
        """Basis of the fitting surface and its derivatives at ``uv`` (n, 2)."""
        return surface_basis(self.surface, uv)

    def derivatives(self, V: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """(n, 6, 3): ``x, x_s, x_t, x_ss, x_st, x_tt`` of ``x = S(s, t)(P + V)`` at ``uv``."""
        return self.basis(uv).apply(self.control_points + V)

    def position(self, V: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """(n, 3) points ``S(s, t)(P + V)`` at ``uv`` (n, 2)."""
        return self.derivatives(V, uv)[:, 0]

    def fe_displacement(self, u: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """(n, 3) FE displacement ``N u`` at the reference points ``S(s, t) P`` of ``uv``."""
        X = self.position(np.zeros((self.n_ctrl, 3)), uv)
        return fe_shape_matrix(self.space, X) @ _nodal(u, self.space)

    def moved(self, V: np.ndarray) -> NurbsSurface:
        """The fitted surface as a NURBS with control points ``P + V`` (same weights and knots)."""
        s = self.surface
        pts = (self.control_points + V).reshape(s.control.shape[:2] + (3,))
        return NurbsSurface.from_points(s.degree, s.knots_u, s.knots_v, pts, s.weights)


def _nodal(u: np.ndarray, space: Space) -> np.ndarray:
    u = np.asarray(u, float).reshape(-1)
    if u.size != space.n_dofs:
        raise ValueError(f"u has {u.size} entries, the space {space.n_dofs} dofs")
    return u.reshape(-1, 3)


def build_fit(surface: NurbsSurface, uv: np.ndarray, w: np.ndarray, space: Space,
              refine: str | int | None = DEFAULT_REFINE, name: str = "", patch: int = -1,
              smooth: bool = True) -> PatchFit:
    """The fit of the patch ``surface`` from its surface-rule points ``uv`` (n, 2) and area
    weights ``w`` (n,) (points of zero weight are dropped), the body's ``space`` (its h sets
    the ``auto`` refinement, :func:`fit_space`). ``name``/``patch`` label the patch in errors.
    ``smooth``: tie the controls at double knots so the fitted displacement is C1 there
    (:func:`c1_extraction`); without it the fitted surface has kinks along the joints of the
    rational circles.

    Raises ValueError if M is singular: a control function without rule points in its
    support, or rule points too few to tell the functions apart.
    """
    label = f"patch {name!r} (#{patch})"
    uv, w = np.asarray(uv, float).reshape(-1, 2), np.asarray(w, float).reshape(-1)
    keep = w > 0.0
    uv, w = np.ascontiguousarray(uv[keep]), w[keep]
    fitting = fit_space(surface, space.h, refine)
    x = surface.evaluate(uv)
    R = surface_basis(fitting, uv).matrix()
    N = fe_shape_matrix(space, x)
    if smooth:
        T, free = c1_extraction(fitting)
    else:
        T, free = sp.identity(fitting.weights.size, format="csr"), fitting.control.shape[:2]
    RtW = (T.T @ R.T @ sp.diags(w)).tocsr()
    M = (RtW @ R @ T).tocsr()
    G = (RtW @ N).tocsr()
    empty = np.flatnonzero(M.diagonal() <= 0.0)
    if empty.size:
        raise ValueError(f"{label}: {empty.size} control functions have no surface-rule point in their "
                         f"support (first: free control ({empty[0] // free[1]}, {empty[0] % free[1]})); "
                         f"use a coarser fit or a finer rule")
    try:
        factor = BandedCholesky.of(M, band_order(*free, fitting.degree, M))
    except np.linalg.LinAlgError:
        raise ValueError(f"{label}: the fit matrix M ({M.shape[0]} control points) is not positive definite: "
                         f"the surface rule cannot tell its basis functions apart; use a coarser fit") from None
    return PatchFit(name, int(patch), fitting, space, T, M, factor, G, uv, x, w)


def build_fits(solid: Solid, rule: SurfaceQuadrature, space: Space, patches: Sequence[int],
               refine: str | int | None = DEFAULT_REFINE, smooth: bool = True) -> tuple[PatchFit, ...]:
    """One :class:`PatchFit` per patch index of ``patches`` of ``solid``, from the body's
    exact surface rule ``rule`` (``Embedding.surface``) and FE ``space``."""
    fits = []
    for ip in patches:
        rows = rule.patch == ip
        patch = solid.patches[int(ip)]
        fits.append(build_fit(patch.surface, rule.uv[rows], rule.w[rows], space, refine, patch.name, int(ip),
                              smooth))
    return tuple(fits)


# -- output ------------------------------------------------------------------------------
def write_fit_json(path, fits: Sequence[PatchFit], displacements: Sequence[np.ndarray],
                   names: Sequence[str] | None = None) -> Path:
    """Write the fitted surfaces (control points ``P + V``, weights, knots and degrees of
    every patch, :meth:`PatchFit.moved`) as a NURBS JSON file (:mod:`cgfem.geometry.io`
    format), atomically. ``displacements``: V (n_ctrl, 3) per fit; ``names``: the patches'
    names in the file (default: the fits' patch names)."""
    if len(fits) != len(displacements):
        raise ValueError(f"{len(fits)} fits but {len(displacements)} displacement sets")
    names = [f.name or "fit" for f in fits] if names is None else list(names)
    path = Path(path)
    write_solid(Solid(tuple(Patch(n, f.moved(V)) for n, f, V in zip(names, fits, displacements))), path)
    return path


def read_fit_json(path) -> tuple[Patch, ...]:
    """The patches of a file of :func:`write_fit_json` (a set of patches, not a closed solid:
    watertightness is not checked)."""
    return solid_from_dict(json.loads(Path(path).read_text(encoding="utf-8"))).patches


def fit_mesh(fits: Sequence[PatchFit], displacements: Sequence[np.ndarray], fe_fields: Sequence[np.ndarray],
             samples: int = 16) -> meshio.Mesh:
    """The fitted surfaces sampled on a regular ``(samples + 1)^2`` lattice of every patch's
    parameter domain, as quads at the current points ``S(P + V)``.

    Point data: ``displacement`` (S V), ``fe_displacement`` (N u at the same reference points
    ``S P``, ``fe_fields[k]`` the displacement (n_dofs,) of the body of ``fits[k]``), ``patch``
    (index of the fit in ``fits``) and ``reference`` (the reference points ``S P``): the data of
    the paper's Fig. 10.
    """
    if not len(fits) == len(displacements) == len(fe_fields):
        raise ValueError("fits, displacements and fe_fields must have one entry per fit")
    if not fits:
        raise ValueError("no fits to sample")
    if samples < 1:
        raise ValueError(f"samples must be >= 1, got {samples}")
    m = samples + 1
    s = np.linspace(0.0, 1.0, m)
    cell = np.array([0, m, m + 1, 1])                                  # lattice (i, j) -> i m + j
    base = (np.arange(samples)[:, None] * m + np.arange(samples)[None, :]).ravel()
    points, quads, data = [], [], {"displacement": [], "fe_displacement": [], "patch": [], "reference": []}
    shift = 0
    for k, (fit, V, u) in enumerate(zip(fits, displacements, fe_fields)):
        (u0, u1), (v0, v1) = fit.surface.domain
        uv = np.stack(np.meshgrid(u0 + s * (u1 - u0), v0 + s * (v1 - v0), indexing="ij"), -1).reshape(-1, 2)
        B = fit.basis(uv)
        X = B.apply(fit.control_points)[:, 0]
        moved = B.apply(V)[:, 0]
        points.append(X + moved)
        quads.append(base[:, None] + cell[None, :] + shift)
        data["displacement"].append(moved)
        data["fe_displacement"].append(fe_shape_matrix(fit.space, X) @ _nodal(u, fit.space))
        data["patch"].append(np.full(uv.shape[0], k, np.int32))
        data["reference"].append(X)
        shift += uv.shape[0]
    return meshio.Mesh(np.concatenate(points), [("quad", np.concatenate(quads))],
                       point_data={key: np.concatenate(v) for key, v in data.items()})


def write_fit_vtu(path, mesh: meshio.Mesh) -> Path:
    """Write a :func:`fit_mesh` as VTU, atomically."""
    return write_vtu_files({Path(path): mesh})[0]
