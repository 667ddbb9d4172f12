"""Normal gap of a slave point, its first and second derivatives (paper eqs. 2-10, 28-30).

Every surface definition is reduced here to one local form, per slave point ``p``:

- the **slave point** moves with the ``3 A`` dofs ``U1`` of its ``A`` nodes (node-major; the
  nodes of its grid element for NURBS+FE and facets (8 or 27, :mod:`cgfem.fem.element`), the control points of the fitted
  surface's span for ``nurbs_fit``): ``x1 = X1 + U1^T phi1`` and its two tangent vectors ``a = A + U1^T ca``,
  ``b = B + U1^T cb`` (``A x B`` points out of the slave body). The current normal is
  ``n = m / |m|`` with ``m = a x b`` (eq. 3). For NURBS+FE ``A, B = Q_xi, Q_eta``,
  ``phi1 = N(zeta)``, ``ca = grad N . Q_xi`` (eq. 16); for facets ``A, B`` are two edges of the
  triangle and ``phi1, ca, cb`` mix the shape values at its vertices (eq. 11 on the
  displaced triangle); for ``nurbs_fit`` ``phi1, ca, cb`` are the fitting basis and its
  derivatives (eq. 21).
- the **master point** at convective coordinates ``theta = (xi, eta)`` moves with the ``3 B``
  dofs ``U2`` of its ``B`` nodes (the master element holding it, or the fitted span):
  ``x2(theta) = Q(theta) + U2^T phi2(theta)`` with tangents ``t_alpha = x2_{,alpha}``, second
  derivatives ``s_{alpha beta}`` and ``d t_alpha / d U2 = psi_alpha`` (eqs. 16-17, 22).

The ray-tracing pairing ``x2(theta) = x1 + g n`` (eq. 2) defines ``theta`` and the gap
``g`` implicitly as functions of the ``3 (A + B)`` local dofs ``v = (U1, U2)``. With
``F(theta, g; v) = x2(theta) - x1 - g n`` and ``J = [t_xi, t_eta, -n]`` the implicit
function theorem gives ``(theta, g)_{,v} = -J^{-1} F_{,v}`` (the system of eqs. 5 and 9,
solved in one piece), and differentiating once more (eqs. 28-30)

    g_{,ij} = -q . [ s_{ab} th^a_i th^b_j + t_{a,j} th^a_i + t_{a,i} th^a_j
                     - n_{,j} g_{,i} - n_{,i} g_{,j} - g n_{,ij} ],

with ``q = J^{-T} e_3 = -m2 / (m2 . n)`` (``m2 = t_xi x t_eta``), so that ``g_{,v} = -q . F_{,v}``:
exactly the variations of eq. (5), ``dg = (dx2 - dx1) . n`` with the convective terms.
All quantities are exact: the tangent built from them is the consistent one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_E = np.eye(3)
#: Levi-Civita products e_k x e_l, (3, 3, 3)
_CROSS = np.cross(_E[:, None, :], _E[None, :, :])


@dataclass(frozen=True)
class SlaveFrames:
    """Reference data of slave points (n of them).

    slot : (n,) active element of the slave's FE space holding each point (where its recovered
        stress and deformation gradient are read)
    nodes : (n, A) the nodes the point moves with, indices into the slave surface's vector of
        unknowns viewed as (n_nodes, 3) (the element's nodes; the fitted span's controls,
        padded with zero coefficients)
    X : (n, 3) reference positions; A, B : (n, 3) reference tangents, ``A x B`` outward
    phi, ca, cb : (n, A) coefficients of ``x1``, ``a`` and ``b`` on the nodal values
    w : (n,) reference area weights
    """

    slot: np.ndarray
    nodes: np.ndarray
    X: np.ndarray
    A: np.ndarray
    B: np.ndarray
    phi: np.ndarray
    ca: np.ndarray
    cb: np.ndarray
    w: np.ndarray

    @property
    def size(self) -> int:
        return int(self.slot.size)

    def select(self, rows: np.ndarray) -> "SlaveFrames":
        return SlaveFrames(*(getattr(self, f)[rows] for f in
                             ("slot", "nodes", "X", "A", "B", "phi", "ca", "cb", "w")))


@dataclass(frozen=True)
class SlaveState:
    """Current slave geometry: position ``x`` (n, 3), tangents ``a, b`` (n, 3), ``m = a x b``,
    unit normal ``n`` (n, 3) and ``|m|`` (n,)."""

    x: np.ndarray
    a: np.ndarray
    b: np.ndarray
    m: np.ndarray
    n: np.ndarray
    norm_m: np.ndarray


def state_of(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> SlaveState:
    """The slave geometry of points at ``x`` with current tangents ``a``, ``b`` (n, 3 each)."""
    m = np.cross(a, b)
    r = np.linalg.norm(m, axis=1)
    return SlaveState(x, a, b, m, m / r[:, None], r)


@dataclass(frozen=True)
class MasterPoints:
    """The master surface at the paired points (n of them), current configuration.

    x : (n, 3) position; t : (n, 2, 3) tangents ``x_{,xi}``, ``x_{,eta}``;
    s : (n, 2, 2, 3) second derivatives; phi : (n, B) ``dx/dU2``; psi : (n, 2, B)
    ``dt_alpha/dU2``; slot : (n,) master element (-1 for a fitted surface); normal : (n, 3)
    outward unit normal; nodes : (n, B) the nodes of ``U2`` (as :attr:`SlaveFrames.nodes`)
    """

    x: np.ndarray
    t: np.ndarray
    s: np.ndarray
    phi: np.ndarray
    psi: np.ndarray
    slot: np.ndarray
    normal: np.ndarray
    nodes: np.ndarray


@dataclass(frozen=True)
class GapDerivatives:
    """``g`` (n,), ``g_{,v}`` (n, D) and the current area weight ``w`` (n,) with its
    derivative ``w_{,v}`` (n, D) on ``v = (U1, U2)`` (``D = 3 (A + B)``, the slave's ``3 A``
    dofs first), and ``g_{,vv}`` in factors::

        g_{,vv} = sum_r u_r v_r^T  +  [[sum_r s_r t_r^T, 0], [0, 0]]

    ``u``, ``v`` (n, 6, D) and, on the slave's dofs only, ``s``, ``t`` (n, 9, 3 A) (the second
    derivative of the slave normal). Every term of the second derivative (module docstring)
    is of rank one or two per point, so the factors are exact; a tangent assembled from them
    costs ``2 (6 D^2 + 9 (3 A)^2)`` flops per point in matrix products, instead of forming
    a dozen (D, D) temporaries. Without the second derivative the factors have no rows."""

    g: np.ndarray
    dg: np.ndarray
    w: np.ndarray
    dw: np.ndarray
    u: np.ndarray
    v: np.ndarray
    s: np.ndarray
    t: np.ndarray

    def d2g(self) -> np.ndarray:
        """``g_{,vv}`` (n, D, D), formed from the factors."""
        out = np.einsum("pri,prj->pij", self.u, self.v)
        s1 = self.s.shape[2]
        out[:, :s1, :s1] += np.einsum("pri,prj->pij", self.s, self.t)
        return out


def area_weight(frames: SlaveFrames, norm_m: np.ndarray, current_area: bool) -> np.ndarray:
    """Area weight (n,) of the slave points: the current area ``w0 |a x b| / |A x B|``
    (``norm_m = |a x b|``) in finite strain, the reference ``w0`` otherwise."""
    if not current_area:
        return frames.w.copy()
    return frames.w * norm_m / np.linalg.norm(np.cross(frames.A, frames.B), axis=1)


def gap_gradient_direction(t: np.ndarray, n: np.ndarray) -> np.ndarray:
    """``q = dg/dx1`` (n, 3) of the ray pairing with master tangents ``t`` (n, 2, 3) and slave
    normal ``n`` (n, 3): ``-m2 / (m2 . n)``, ``m2 = t_xi x t_eta`` (``J^{-T} e_3``)."""
    m2 = np.cross(t[:, 0], t[:, 1])
    return -m2 / np.einsum("pk,pk->p", m2, n)[:, None]


def gap_derivatives(frames: SlaveFrames, slave: SlaveState, master: MasterPoints, g: np.ndarray,
                    current_area: bool, second: bool = True) -> GapDerivatives:
    """Derivatives of the ray-traced gap ``g`` (module docstring) at ``n`` paired points.

    ``current_area``: the weight is the current area ``w0 |a x b| / |A x B|`` (finite
    strain) instead of the reference one."""
    n_pts = g.size
    s1, s2 = 3 * frames.phi.shape[1], 3 * master.phi.shape[1]    # slave and master dofs per point
    d = s1 + s2
    n, m, r = slave.n, slave.m, slave.norm_m
    # dm/dU1[a, k] = ca_a (e_k x b) + cb_a (a x e_k)       (n, A, 3, 3): [p, node, k, vector]
    ek_x_b = np.cross(_E[None, :, :], slave.b[:, None, :])          # (n, 3, 3)
    a_x_ek = np.cross(slave.a[:, None, :], _E[None, :, :])
    dm = (frames.ca[:, :, None, None] * ek_x_b[:, None] + frames.cb[:, :, None, None] * a_x_ek[:, None])
    dm = dm.reshape(n_pts, s1, 3)
    m_dm = np.einsum("pk,pik->pi", m, dm)                           # m . m_i
    dn = dm / r[:, None, None] - m[:, None, :] * (m_dm / r[:, None] ** 3)[:, :, None]
    # F_v (3, D): dF/dU1 = -phi1 e_k - g n_i ; dF/dU2 = phi2 e_k
    Fv = np.zeros((n_pts, 3, d))
    Fv[:, :, :s1] = -np.einsum("pa,kc->pcak", frames.phi, _E).reshape(n_pts, 3, s1) \
        - g[:, None, None] * dn.transpose(0, 2, 1)
    Fv[:, :, s1:] = np.einsum("pa,kc->pcak", master.phi, _E).reshape(n_pts, 3, s2)
    J = np.stack([master.t[:, 0], master.t[:, 1], -n], axis=2)     # columns
    theta = -np.linalg.solve(J, Fv)                                 # (n, 3, D)
    q = gap_gradient_direction(master.t, n)
    dg = theta[:, 2]
    w = area_weight(frames, r, current_area)
    dw = np.zeros((n_pts, d))
    if current_area:     # w = w0 |m| / R: dw = (w / |m|) n . dm
        dw[:, :s1] = (w / r)[:, None] * np.einsum("pk,pik->pi", n, dm)
    s1_rows = np.zeros((n_pts, 0, s1))
    if not second:
        return GapDerivatives(g, dg, w, dw, np.zeros((n_pts, 0, d)), np.zeros((n_pts, 0, d)), s1_rows, s1_rows)
    # - (th^T qs th + th^T qt + qt^T th - dg qdn^T - qdn dg^T): six rank-one terms
    th = theta[:, :2]                                               # (n, 2, D)
    qs = np.einsum("pk,pabk->pab", q, master.s)
    qt = np.zeros((n_pts, 2, d))                                    # q . dt_alpha/dv: U2 dofs only
    qt[:, :, s1:] = np.einsum("pca,pk->pcak", master.psi, q).reshape(n_pts, 2, s2)
    qdn = np.zeros((n_pts, d))
    qdn[:, :s1] = np.einsum("pk,pik->pi", q, dn)
    qs_th = np.einsum("pab,pbi->pai", qs, th)
    u = np.concatenate([th, qt, dg[:, None], qdn[:, None]], axis=1)
    v = np.concatenate([-qs_th - qt, -th, qdn[:, None], dg[:, None]], axis=1)
    # + g q . n_ij on the slave block, n_ij the second derivative of the normal:
    # v . m_ij - (q_dm m_dm^T + m_dm q_dm^T) / r^3 - (q . m) dm dm^T / r^3
    # + 3 (q . m) / r^5 m_dm m_dm^T, with m_ij = d2m/dU1_i dU1_j = c_ac (e_k x e_l) for
    # i = (a, k), j = (c, l), c_ac = ca_a cb_c - cb_a ca_c, and v = q / r - (q . m) m / r^3.
    # With p a unit vector normal to v and o = v x p, v . (e_k x e_l) = p_k o_l - o_k p_l,
    # so v . m_ij = (ca x p)(cb x o)^T - (ca x o)(cb x p)^T - (cb x p)(ca x o)^T
    # + (cb x o)(ca x p)^T with (x y)_(a, k) = x_a y_k
    qm = np.einsum("pk,pk->p", q, m)
    q_dm = np.einsum("pk,pik->pi", q, dm)
    r3 = r ** 3
    vv = q / r[:, None] - (qm / r3)[:, None] * m
    p = _unit_normal_to(vv)
    o = np.cross(vv, p)

    def kron(x, y):                                                 # (n, A), (n, 3) -> (n, 3 A)
        return (x[:, :, None] * y[:, None, :]).reshape(n_pts, s1)

    ca_p, ca_o, cb_p, cb_o = kron(frames.ca, p), kron(frames.ca, o), kron(frames.cb, p), kron(frames.cb, o)
    gl = g[:, None]
    srows = [q_dm, m_dm, *(dm[:, :, c] for c in range(3)), ca_p, ca_o, cb_p, cb_o]
    trows = [-gl * m_dm / r3[:, None], gl * (-q_dm / r3[:, None] + (3.0 * qm / r ** 5)[:, None] * m_dm),
             *(-(g * qm / r3)[:, None] * dm[:, :, c] for c in range(3)),
             gl * cb_o, -gl * cb_p, -gl * ca_o, gl * ca_p]
    return GapDerivatives(g, dg, w, dw, u, v, np.stack(srows, axis=1), np.stack(trows, axis=1))


def _unit_normal_to(v: np.ndarray) -> np.ndarray:
    """A unit vector (n, 3) normal to each ``v`` (n, 3) (any, for ``v = 0``): the cross
    product with the axis ``v`` is least aligned with, normalized."""
    axis = np.eye(3)[np.argmin(np.abs(v), axis=1)]
    p = np.cross(v, axis)
    size = np.linalg.norm(p, axis=1)
    return np.where(size[:, None] > 0.0, p / np.where(size > 0.0, size, 1.0)[:, None], axis)
