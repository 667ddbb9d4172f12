"""The planar reference solution as data: saved and loaded as npz, evaluated at points.

Evaluation maps 2D plane-strain fields in (y, z) to 3D tensors indexed (x, y, z):
ε_xx = ε_xy = ε_xz = 0, and σ_xx = ν (σ_yy + σ_zz).
"""

from __future__ import annotations

import io
import os
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from cgfem.atomic import write_bytes_atomic
from cgfem.reference.elements import physical_gradients, q9_basis
from cgfem.reference.mesh import RectMesh

BODIES = ("lower", "upper")
INTERFACE_Z = 0.01  # m
OUTSIDE_TOL = 1e-8  # m


def _check_inside(mesh: RectMesh, y: np.ndarray, z: np.ndarray, name: str) -> None:
    """ValueError if a point (y, z), each (n,), is farther than OUTSIDE_TOL outside ``mesh``."""
    out = np.maximum.reduce([mesh.y_breaks[0] - y, y - mesh.y_breaks[-1],
                             mesh.z_breaks[0] - z, z - mesh.z_breaks[-1]])
    if out.max(initial=0.0) > OUTSIDE_TOL:
        i = int(np.argmax(out))
        raise ValueError(f"x: point (y, z) = ({y[i]:.6g}, {z[i]:.6g}) lies outside body {name}")


@dataclass(frozen=True)
class PlanarReference:
    """Converged (or one level's) plane-strain solution of the planar example.

    Geometry in metres, displacements in metres, energies in J per metre of thickness.
    ``u_lower``: (n_nodes_lower, 2) and ``u_upper``: (n_nodes_upper, 2) nodal (u_y, u_z) on
    the Q9 node grids of ``RectMesh(y_breaks, z_breaks_lower)`` and
    ``RectMesh(y_breaks, z_breaks_upper)``. Per-level history: ``levels``, ``energies``,
    ``dofs``, ``seconds`` (wall time of the level), ``peak_rss_mb`` (process peak RSS after
    it), each (n_levels,). Interface (z = 0.01, nodes of the lower body's top, increasing y):
    ``interface_y`` (m,), ``interface_traction`` (m,) the normal traction σ_zz in Pa on the
    lower body (negative = compressive), ``tied`` (m,) whether u_z is continuous there.
    ``interface_force`` is the total contact force on the lower body (N/m, negative =
    downward) and ``lateral_force_z`` the resultant of t_z on its lateral faces (N/m).
    """

    E: float
    nu: float
    thickness: float
    level: int
    n_half: int
    beta: float
    y_breaks: np.ndarray
    z_breaks_lower: np.ndarray
    z_breaks_upper: np.ndarray
    u_lower: np.ndarray
    u_upper: np.ndarray
    strain_energy: float
    levels: np.ndarray
    energies: np.ndarray
    dofs: np.ndarray
    seconds: np.ndarray
    peak_rss_mb: np.ndarray
    interface_y: np.ndarray
    interface_traction: np.ndarray
    tied: np.ndarray
    interface_force: float
    lateral_force_z: float
    converged: bool = False

    def mesh(self, body: str) -> RectMesh:
        """The Q9 mesh of ``"lower"`` or ``"upper"``."""
        z = {"lower": self.z_breaks_lower, "upper": self.z_breaks_upper}[body]
        return RectMesh(self.y_breaks, z)

    def save(self, path: str | os.PathLike) -> Path:
        """Write an npz file atomically (temporary file in the same folder, then rename)."""
        buffer = io.BytesIO()
        np.savez(buffer, **{k: np.asarray(v) for k, v in asdict(self).items()})
        return write_bytes_atomic(Path(path), buffer.getvalue())

    @classmethod
    def load(cls, path: str | os.PathLike) -> "PlanarReference":
        """Read a file written by :meth:`save`."""
        with np.load(path) as data:
            values = {}
            for f in fields(cls):
                v = data[f.name]
                values[f.name] = v if v.ndim else v.item()
        return cls(**values)

    def _bodies(self, z: np.ndarray, body) -> np.ndarray:
        """Body index (n,) per point: 0 lower, 1 upper."""
        if body is None:
            return (z > INTERFACE_Z).astype(int)
        b = np.broadcast_to(np.asarray(body), z.shape)
        if b.dtype.kind in "US":
            if not np.all(np.isin(b, BODIES)):
                raise ValueError(f"body: must be 'lower' or 'upper' (got {np.unique(b)})")
            return (b == "upper").astype(int)
        if not np.all(np.isin(b, (0, 1))):
            raise ValueError(f"body: must be 0 (lower) or 1 (upper) (got {np.unique(b)})")
        return b.astype(int)

    def strain(self, y: np.ndarray, z: np.ndarray, body=None) -> np.ndarray:
        """3D small strain (n, 3, 3), axes (x, y, z), at points (y, z), each (n,).

        ``body``: None (the body containing the point; a point on the interface z = 0.01
        belongs to the lower body), or ``"lower"``/``"upper"``/0/1, scalar or (n,), to force
        it. Points up to ``OUTSIDE_TOL`` outside the body's rectangle are clipped onto it
        (quadrature points of a cut cell may sit a rounding error outside); farther ones are
        a ValueError.
        """
        y = np.atleast_1d(np.asarray(y, dtype=float))
        z = np.atleast_1d(np.asarray(z, dtype=float))
        b = self._bodies(z, body)
        eps = np.zeros((len(y), 3, 3))
        for index, name in enumerate(BODIES):
            sel = np.flatnonzero(b == index)
            if len(sel) == 0:
                continue
            mesh = self.mesh(name)
            u = self.u_lower if index == 0 else self.u_upper
            _check_inside(mesh, y[sel], z[sel], name)
            element, xi, eta = mesh.locate(y[sel], z[sel])
            conn = mesh.connectivity()[element]  # (n, 9)
            _, dxi, deta = q9_basis(xi, eta)
            dN_dy, dN_dz, _ = physical_gradients(
                mesh.node_coords()[conn], dxi[:, None, :], deta[:, None, :]
            )
            ue = u[conn]  # (n, 9, 2)
            grad = np.stack(
                [np.einsum("nk,nkc->nc", dN_dy[:, 0], ue), np.einsum("nk,nkc->nc", dN_dz[:, 0], ue)],
                axis=-1,
            )  # (n, c, d): du_c / dx_d over (y, z)
            eps[sel, 1:, 1:] = 0.5 * (grad + np.swapaxes(grad, 1, 2))
        return eps

    def stress(self, y: np.ndarray, z: np.ndarray, body=None) -> np.ndarray:
        """3D Cauchy stress (n, 3, 3) in Pa at points (y, z); see :meth:`strain`."""
        return hooke(self.strain(y, z, body), self.E, self.nu)


def hooke(eps: np.ndarray, E: float, nu: float) -> np.ndarray:
    """Isotropic stress σ = λ tr(ε) I + 2 μ ε for strains (n, 3, 3)."""
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    tr = np.trace(eps, axis1=1, axis2=2)
    return lam * tr[:, None, None] * np.eye(3) + 2.0 * mu * eps


def relative_energy_error(
    reference: PlanarReference,
    x: np.ndarray,
    w: np.ndarray,
    strain_h: np.ndarray,
    body,
    thickness: float | None = None,
) -> float:
    """Relative energy-norm error ||e||_E / ||u_ref||_E of a 3D strain field.

    ``x``: (n, 3) quadrature points (the x coordinate is ignored: plane strain), ``w``:
    (n,) their weights in m³ (a volume rule of both bodies over the 3D slab),
    ``strain_h``: (n, 3, 3) the approximate small strain there, ``body``: (n,) or scalar,
    ``"lower"``/``"upper"`` or 0/1, the body each point belongs to.

    Numerator: ||e||²_E = Σ w (ε_h − ε_ref):C:(ε_h − ε_ref), with C the 3D isotropic
    elasticity of the reference (E, ν), i.e. twice the error's strain energy in the slab.
    Denominator: ||u_ref||²_E = 2 U_ref · t, twice the reference strain energy per metre
    (``reference.strain_energy``, integrated exactly on the reference mesh) times the slab
    thickness ``t`` (``reference.thickness``, 0.0025 m, unless given). Returns
    sqrt(numerator / denominator).
    """
    x = np.asarray(x, dtype=float)
    w = np.asarray(w, dtype=float)
    strain_h = np.asarray(strain_h, dtype=float)
    n = len(w)
    if x.shape != (n, 3) or strain_h.shape != (n, 3, 3):
        raise ValueError(
            f"x, strain_h: shapes must be ({n}, 3) and ({n}, 3, 3) "
            f"(got {x.shape} and {strain_h.shape})"
        )
    t = reference.thickness if thickness is None else thickness
    e = strain_h - reference.strain(x[:, 1], x[:, 2], body)
    error2 = float(np.sum(w * np.einsum("nij,nij->n", hooke(e, reference.E, reference.nu), e)))
    return float(np.sqrt(error2 / (2.0 * reference.strain_energy * t)))
