"""The fitted NURBS contact surface in the solver (``nurbs_fit``, paper eqs. 18-22), kept sparse.

The contact surfaces move as NURBS whose control displacements ``V = T Z`` fit the FE field
(:mod:`cgfem.contact.fit`: ``M Z = G u`` per patch). The paper eliminates the fit,
``Z = M^{-1} G u``, which couples every node of a surface with every other: the contact
tangent ``C^T K_c C`` (``C = M^{-1} G``) is dense. Here the fit stays a constraint. Every fitted
patch brings two blocks of unknowns, its free control displacements ``Z`` (n_free, 3) and a
multiplier ``mu`` (n_free, 3), and three sets of equations (``s`` = E / h of its body, so that
the constraint rows are of the size of the stiffness rows)::

    r_u  = f_int - f_ext - s G^T mu          (the body's rows, per component)
    r_Z  = f_c(Z) + s M mu                   (the contact residual acts on Z)
    r_mu = s (M Z - G u)

Eliminating ``mu`` and ``Z`` gives back the paper's ``f_int - f_ext + C^T f_c``. The tangent
``[[K, 0, -s G^T], [0, K_c, s M], [-s G, s M, 0]]`` is sparse (``G`` and ``M`` are banded
and fixed) and, in small strain, symmetric indefinite: the linear backends take it as a
saddle point (:func:`cgfem.solve.backends.choose_backend`, ``indefinite``).

:class:`FittedSurface` is the kinematic side: one body's fitted patches as a contact surface
whose "nodes" are the free controls ``Z`` of its patches (its vector of unknowns is theirs,
concatenated), in the local form of :mod:`cgfem.contact.kinematics`: a point at ``(s, t)``
on a patch moves with the controls of its knot span, ``x = S(s, t) (P + T Z)`` (eq. 21), and
its tangents and second derivatives are the basis derivatives (eq. 22). The master search is
the NURBS ray Newton of :mod:`cgfem.contact._ray_kernels` on the moved control net, with no FE
field on top (one grid element holding everything, zero displacement).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from cgfem.contact._fit_kernels import merge_controls
from cgfem.contact.fit import PatchFit, surface_basis
from cgfem.contact.kinematics import MasterPoints, SlaveFrames
from cgfem.contact.surfaces import RAY_TOL, RaySurface, locate_points, pack_patches
from cgfem.embedding.partition import SurfaceQuadrature

#: the search's single element reaches this many times the surface's size beyond its box
REACH = 100.0


@dataclass(frozen=True)
class FitBlock:
    """One fitted patch of one body among the system's unknowns: ``z`` and ``mu`` are the
    global indices (3 n_free,) of its control displacements and multipliers (node-major),
    ``scale`` the factor ``s`` of its equations."""

    body: int
    fit: PatchFit
    scale: float
    z: np.ndarray
    mu: np.ndarray


def _padded_map(T: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """``T`` (n_ctrl, n_free) as columns and values (n_ctrl, w) (w its largest row count;
    short rows padded with column 0 and value 0)."""
    T = sp.csr_matrix(T)
    counts = np.diff(T.indptr)
    w = int(counts.max(initial=1))
    cols, vals = np.zeros((T.shape[0], w), np.int64), np.zeros((T.shape[0], w))
    for i in range(T.shape[0]):
        a, b = T.indptr[i], T.indptr[i + 1]
        cols[i, :b - a], vals[i, :b - a] = T.indices[a:b], T.data[a:b]
    return cols, vals


def merge_columns(nodes: np.ndarray, coef: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per point, the distinct controls among ``nodes`` (n, W) where ``valid`` (n, W), with
    the coefficients ``coef`` (n, 6, W) of equal controls summed: (n, W') and (n, 6, W'), W'
    the largest count of distinct controls of a point; shorter rows are padded with their
    first control and coefficient 0 (:func:`cgfem.contact._fit_kernels.merge_controls`). A
    fitted point's (p+1)(q+1) controls each spread over the free controls tied to them (at
    double knots and seams): 36 entries with biquadratic patches, 9 distinct, and the
    tangent's blocks shrink by (36/9)^2."""
    return merge_controls(np.ascontiguousarray(nodes, dtype=np.int64), np.ascontiguousarray(coef, dtype=np.float64),
                          np.ascontiguousarray(valid, dtype=np.bool_))


#: points whose basis :meth:`FittedSurface._basis` evaluates at once
BASIS_CHUNK = 16384


class FittedSurface(RaySurface):
    """The fitted patches of one body as a contact surface (module docstring)."""

    definition = "nurbs_fit"
    #: no point moves further than its controls' largest move (NURBS weights are non-negative)
    lebesgue = 1.0

    def __init__(self, body: int, fits: Sequence[PatchFit], seeds: SurfaceQuadrature, scale: float):
        """``fits``: the body's fitted patches that may touch; ``seeds``: a dense exact surface
        rule of the body (search seeds, on every patch); ``scale``: ``s`` of its equations."""
        if not fits:
            raise ValueError("a fitted surface needs at least one patch")
        self.body, self.fits, self.scale = body, tuple(fits), float(scale)
        self.space = self.fits[0].space
        self.h = self.space.h
        self.local = {f.patch: k for k, f in enumerate(self.fits)}
        sizes = [f.n_free for f in self.fits]
        #: first node (free control) of every fit in the surface's vector of unknowns
        self.node_offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self._maps = [_padded_map(f.T) for f in self.fits]
        #: entries of a point's basis before equal controls are merged (:func:`merge_columns`)
        self._spread = max(((f.surface.degree[0] + 1) * (f.surface.degree[1] + 1)) * m[0].shape[1]
                           for f, m in zip(self.fits, self._maps))
        self._layout, self._knots, self._control = pack_patches([f.surface for f in self.fits])
        keep = np.isin(seeds.patch, list(self.local))
        self.seed_piece = np.array([self.local[int(p)] for p in seeds.patch[keep]], np.int64)
        self.seed_theta = np.ascontiguousarray(seeds.uv[keep])
        ref, coef, nodes = self._basis(self.seed_piece, self.seed_theta)
        self._seed_X = ref[:, 0].copy()
        n, w = nodes.shape
        #: controls a point moves with (at the seeds; a point elsewhere may have a few more)
        self.width = w
        self._seed_coef = np.ascontiguousarray(coef[:, 0])
        self._seed_nodes = np.ascontiguousarray(nodes, dtype=np.int64)
        self.spacing = (float(cKDTree(self._seed_X).query(self._seed_X, k=2)[0][:, 1].max())
                        if n > 1 else self.h)
        points = np.concatenate([f.control_points for f in self.fits])
        lo, hi = points.min(axis=0), points.max(axis=0)
        size = float(np.max(hi - lo))
        pad = REACH * size
        self._origin, self._box = lo - pad, size + 2.0 * pad

    @property
    def n_nodes(self) -> int:
        """Free controls of all the surface's patches (its unknowns are 3 per control)."""
        return int(self.node_offsets[-1])

    def displacements(self, z: np.ndarray) -> list[np.ndarray]:
        """Control displacements ``V = T Z`` (n_ctrl, 3) of every fit from the surface's
        unknowns ``z`` (3 n_nodes,)."""
        Z = np.asarray(z, float).reshape(-1, 3)
        return [f.T @ Z[a:b] for f, a, b in zip(self.fits, self.node_offsets[:-1], self.node_offsets[1:])]

    # -- the basis at points -----------------------------------------------------------
    def _basis(self, piece: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At points ``(piece, theta)`` ((n,), (n, 2); ``piece`` a fit's index): the reference
        geometry ``x, x_s, x_t, x_ss, x_st, x_tt`` (n, 6, 3), the coefficients of the same on
        the free controls (n, 6, W) and those controls (n, W), as surface nodes; rows with
        fewer controls padded with their first control and coefficient 0
        (:func:`merge_columns`). Evaluated :data:`BASIS_CHUNK` points at a time: a point's
        basis before its equal controls are merged is several times wider (the seeds of
        chain2_steel at order 2, level 1 held 2.7 GB of it at once)."""
        if piece.size <= BASIS_CHUNK:
            return self._basis_chunk(piece, theta)
        parts = [self._basis_chunk(piece[k:k + BASIS_CHUNK], theta[k:k + BASIS_CHUNK])
                 for k in range(0, piece.size, BASIS_CHUNK)]
        width = max(nodes.shape[1] for _, _, nodes in parts)
        coef = np.concatenate([np.pad(c, ((0, 0), (0, 0), (0, width - c.shape[2]))) for _, c, _ in parts])
        nodes = np.concatenate([np.concatenate([n] + [n[:, :1]] * (width - n.shape[1]), axis=1)
                                for _, _, n in parts])
        return np.concatenate([ref for ref, _, _ in parts]), coef, nodes

    def _basis_chunk(self, piece: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_basis` of points all at once."""
        n = piece.size
        ref = np.zeros((n, 6, 3))
        coef = np.zeros((n, 6, self._spread))
        nodes = np.zeros((n, self._spread), np.int64)
        valid = np.zeros((n, self._spread), bool)
        for k in np.unique(piece):
            rows = np.flatnonzero(piece == k)
            fit = self.fits[k]
            b = surface_basis(fit.surface, theta[rows])
            ref[rows] = b.apply(fit.control_points)
            cols, vals = self._maps[k]
            c = cols[b.index]                                                   # (m, kk, w)
            v = b.values[:, :, :, None] * vals[b.index][:, None]                # (m, 6, kk, w)
            width = c.shape[1] * c.shape[2]
            nodes[rows, :width] = c.reshape(rows.size, width) + self.node_offsets[k]
            coef[rows, :, :width] = v.reshape(rows.size, 6, width)
            valid[rows, :width] = (vals[b.index] != 0.0).reshape(rows.size, width)
        nodes, coef = merge_columns(nodes, coef, valid)
        return ref, coef, nodes

    # -- slave side ----------------------------------------------------------------------
    def slave_frames(self, rule: SurfaceQuadrature) -> SlaveFrames:
        """Slave data of the points of ``rule`` (exact surface points on the fitted patches)."""
        piece = np.array([self.local[int(p)] for p in rule.patch], np.int64)
        ref, coef, nodes = self._basis(piece, rule.uv)
        slots = locate_points(self.space, rule.x)[0]
        return SlaveFrames(slots, nodes, rule.x.copy(), ref[:, 1], ref[:, 2], coef[:, 0], coef[:, 1], coef[:, 2],
                           rule.w.copy())

    # -- master side ---------------------------------------------------------------------
    def evaluate(self, z: np.ndarray, piece: np.ndarray, theta: np.ndarray, second: bool = True,
                 slot: np.ndarray | None = None) -> MasterPoints:
        """The current fitted surface at ``(piece, theta)`` (n,), (n, 2) (eqs. 21-22); ``slot``
        is ignored (no grid element: -1 in the result)."""
        ref, coef, nodes = self._basis(piece, theta)
        U = np.asarray(z, float).reshape(-1, 3)[nodes]                          # (n, W, 3)
        d = ref + np.einsum("pra,pak->prk", coef, U)                            # (n, 6, 3)
        t = d[:, 1:3]
        s = np.zeros((piece.size, 2, 2, 3))
        if second:
            s[:, 0, 0], s[:, 0, 1], s[:, 1, 0], s[:, 1, 1] = d[:, 3], d[:, 4], d[:, 4], d[:, 5]
        m2 = np.cross(t[:, 0], t[:, 1])
        normal = m2 / np.linalg.norm(m2, axis=1)[:, None]
        return MasterPoints(d[:, 0], t, s, coef[:, 0], coef[:, 1:3], np.full(piece.size, -1, np.int64),
                            normal, nodes)

    def _may_hit(self, z: np.ndarray, x1: np.ndarray, max_gap: float, n1: np.ndarray) -> np.ndarray:
        """Every ray is tried (a ray no seed lies near gets no start)."""
        return np.ones(x1.shape[0], bool)

    def _kernel_data(self, z: np.ndarray) -> tuple:
        """The moved control nets (homogeneous) and one grid element holding every point,
        with zero displacement: the ray Newton on the fitted NURBS alone. Its tolerance is
        the surface's ``RAY_TOL h`` in absolute terms."""
        parts = []
        for fit, V in zip(self.fits, self.displacements(z)):
            w = fit.surface.weights.reshape(-1, 1)
            parts.append(np.hstack([(fit.control_points + V) * w, w]).ravel())
        control = np.ascontiguousarray(np.concatenate(parts))
        control.setflags(write=False)       # as the packed nets (:func:`pack_patches`): one compiled trace
        box = self._box
        return (control, self._origin, float(box), np.ones(3, np.int64), np.zeros(1, np.int64),
                np.arange(8, dtype=np.int64)[None], np.zeros((8, 3)), RAY_TOL * self.h / box)
