"""The independent Q9 plane-strain reference: element, convergence, planar physics, error norm."""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.reference import planar
from cgfem.reference.assembly import (
    assemble_matrix,
    assemble_vector,
    element_dofs,
    solve_dirichlet,
)
from cgfem.reference.elements import (
    body_force,
    gauss_rule,
    lagrange_1d,
    physical_gradients,
    plane_strain_matrix,
    q9_basis,
    stiffness,
)
from cgfem.reference.field import PlanarReference, hooke, relative_energy_error
from cgfem.reference.mesh import RectMesh, graded_breakpoints

E, NU = 115.0e9, 0.3
LAM = E * NU / ((1 + NU) * (1 - 2 * NU))
MU = E / (2 * (1 + NU))


def _square(n: int, distortion: float = 0.0, seed: int = 0):
    """Unit-square Q9 mesh (n × n), interior nodes moved by up to ``distortion``·h."""
    mesh = RectMesh(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
    coords = mesh.node_coords()
    boundary = np.unique(np.concatenate([mesh.side_nodes(s) for s in ("ymin", "ymax", "zmin", "zmax")]))
    interior = np.setdiff1d(np.arange(mesh.n_nodes), boundary)
    rng = np.random.default_rng(seed)
    coords[interior] += distortion / (2 * n) * rng.uniform(-1, 1, (len(interior), 2))
    return mesh, coords, boundary


def _solve_square(mesh, coords, boundary, exact, force=None):
    """Dirichlet problem on the square: u = exact(y, z) (n, 2) on the boundary."""
    conn = mesh.connectivity()
    node_dofs = np.arange(2 * mesh.n_nodes).reshape(-1, 2)
    dofs = element_dofs(conn, node_dofs)
    K = assemble_matrix(stiffness(coords[conn], plane_strain_matrix(E, NU)), dofs, node_dofs.size)
    f = np.zeros(node_dofs.size)
    if force is not None:
        f = assemble_vector(body_force(coords[conn], force), dofs, node_dofs.size)
    fixed = node_dofs[boundary].ravel()
    u = solve_dirichlet(K, f, fixed, exact(*coords[boundary].T).ravel())
    return u.reshape(-1, 2)


def test_lagrange_partition_of_unity_and_derivative():
    t = np.linspace(-1, 1, 7)
    phi, dphi = lagrange_1d(t)
    np.testing.assert_allclose(phi.sum(axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(phi @ np.array([-1.0, 0.0, 1.0]), t, atol=1e-15)
    h = 1e-6
    fd = (lagrange_1d(t + h)[0] - lagrange_1d(t - h)[0]) / (2 * h)
    np.testing.assert_allclose(dphi, fd, atol=1e-9)


def test_patch_test_linear_field_reproduced_on_distorted_mesh():
    mesh, coords, boundary = _square(3, distortion=0.4, seed=3)

    def linear(y, z):
        return np.stack([1e-3 + 2e-3 * y - 1e-3 * z, -5e-4 + 7e-4 * y + 3e-3 * z], axis=-1)

    u = _solve_square(mesh, coords, boundary, linear)
    np.testing.assert_allclose(u, linear(*coords.T), rtol=0, atol=1e-12 * np.abs(u).max())
    xi, eta, _ = gauss_rule(3)
    _, dxi, deta = q9_basis(xi, eta)
    conn = mesh.connectivity()
    dN_dy, dN_dz, _ = physical_gradients(coords[conn], dxi, deta)
    ue = u[conn]
    np.testing.assert_allclose(np.einsum("eqk,ek->eq", dN_dy, ue[..., 0]), 2e-3, atol=1e-14)
    np.testing.assert_allclose(np.einsum("eqk,ek->eq", dN_dz, ue[..., 1]), 3e-3, atol=1e-14)


def test_energy_norm_error_converges_at_rate_two():
    """u = (sin πy sin πz, 0) with its body force: ||e||_E = O(h²) for Q9."""
    pi = np.pi

    def exact(y, z):
        return np.stack([np.sin(pi * y) * np.sin(pi * z), 0 * y], axis=-1)

    def force(y, z):
        return np.stack([(LAM + 3 * MU) * pi**2 * np.sin(pi * y) * np.sin(pi * z),
                         -(LAM + MU) * pi**2 * np.cos(pi * y) * np.cos(pi * z)], axis=-1)

    def exact_strain(y, z):  # Voigt [ε_yy, ε_zz, γ_yz]
        return np.stack([pi * np.cos(pi * y) * np.sin(pi * z), 0 * y,
                         pi * np.sin(pi * y) * np.cos(pi * z)], axis=-1)

    D = plane_strain_matrix(E, NU)
    xi, eta, w = gauss_rule(5)
    N, dxi, deta = q9_basis(xi, eta)
    hs, errors = [], []
    for n in (2, 4, 8, 16):
        mesh, coords, boundary = _square(n)
        u = _solve_square(mesh, coords, boundary, exact, force)
        conn = mesh.connectivity()
        dN_dy, dN_dz, det = physical_gradients(coords[conn], dxi, deta)
        ue = u[conn]
        strain_h = np.stack([np.einsum("eqk,ek->eq", dN_dy, ue[..., 0]),
                             np.einsum("eqk,ek->eq", dN_dz, ue[..., 1]),
                             np.einsum("eqk,ek->eq", dN_dz, ue[..., 0])
                             + np.einsum("eqk,ek->eq", dN_dy, ue[..., 1])], axis=-1)
        yq = np.einsum("qk,ek->eq", N, coords[conn][..., 0])
        zq = np.einsum("qk,ek->eq", N, coords[conn][..., 1])
        e = strain_h - exact_strain(yq, zq)
        errors.append(np.sqrt(np.sum(det * w * np.einsum("eqi,ij,eqj->eq", e, D, e))))
        hs.append(1.0 / n)
    rate = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert 1.9 < rate < 2.1, (rate, errors)


def test_graded_breakpoints_symmetric_and_refine_nested():
    b = graded_breakpoints(0.0, 0.01, 4, 3.0)
    np.testing.assert_allclose(b + b[::-1], 0.01, atol=1e-18)
    assert b[1] == pytest.approx(0.005 / 4**3)
    fine = graded_breakpoints(0.0, 0.01, 8, 3.0)
    np.testing.assert_allclose(fine[::2], b, atol=1e-18)  # every element split in two


@pytest.fixture(scope="module")
def level1() -> PlanarReference:
    return planar.solve(1)


@pytest.mark.slow
def test_planar_global_equilibrium(level1):
    exact = 2 * 10e11 * 0.01**3 / 6  # ∫ t_z over both lateral faces, N/m
    assert level1.lateral_force_z == pytest.approx(exact, rel=1e-13)
    # body 1 is held vertically by the contact only
    assert abs(level1.interface_force + level1.lateral_force_z) <= 1e-10 * exact


@pytest.mark.slow
def test_planar_contact_closed_and_compressive_everywhere(level1):
    assert level1.tied.all()
    # the quadratic traction field, sampled inside every interface edge too
    t = level1.interface_traction
    phi, _ = lagrange_1d(np.linspace(-1, 1, 9))
    edges = np.stack([t[0:-1:2], t[1::2], t[2::2]], axis=-1)
    assert (edges @ phi.T).max() < 0.0
    # it is the normal stress of either body there (within 3 % at level 1, 0.3 % at level 2)
    y = level1.interface_y
    z = np.full_like(y, 0.01)
    for body in ("lower", "upper"):
        sigma_zz = level1.stress(y, z, body)[:, 2, 2]
        np.testing.assert_allclose(sigma_zz, t, rtol=3e-2)
    # frictionless: u_z continuous, u_y free to jump, no shear on the interface
    top = level1.u_lower[level1.mesh("lower").side_nodes("zmax")]
    bottom = level1.u_upper[level1.mesh("upper").side_nodes("zmin")]
    np.testing.assert_array_equal(top[:, 1], bottom[:, 1])
    assert np.abs(top[:, 0] - bottom[:, 0]).max() > 0.1 * np.abs(top[:, 0]).max()
    np.testing.assert_allclose(level1.strain(y, z, "lower")[:, 1, 2], 0.0, atol=1e-2 * 4e-4)


@pytest.mark.slow
def test_planar_energy_converges(level1):
    energies = [planar.solve(level).strain_energy for level in (0, 2)]
    d01, d12 = abs(level1.strain_energy - energies[0]), abs(energies[1] - level1.strain_energy)
    assert d12 < d01 / 8  # graded Q9: about 12x per level


def _gauss_points(ref: PlanarReference):
    """3×3 Gauss points of the reference meshes in the 3D slab: x (n, 3), w (n,), body (n,)."""
    xi, eta, wq = gauss_rule(3)
    N, dxi, deta = q9_basis(xi, eta)
    xs, ws, bodies = [], [], []
    for name in ("lower", "upper"):
        ec = ref.mesh(name).element_coords()
        _, _, det = physical_gradients(ec, dxi, deta)
        yz = np.einsum("qk,ekc->eqc", N, ec).reshape(-1, 2)
        xs.append(np.column_stack([np.full(len(yz), 0.5 * ref.thickness), yz]))
        ws.append((det * wq).ravel() * ref.thickness)
        bodies.append(np.full(len(yz), name))
    return np.concatenate(xs), np.concatenate(ws), np.concatenate(bodies)


@pytest.mark.slow
def test_relative_energy_error_zero_and_known_perturbations(level1):
    x, w, body = _gauss_points(level1)
    eps = level1.strain(x[:, 1], x[:, 2], body)
    assert relative_energy_error(level1, x, w, eps, body) == pytest.approx(0.0, abs=1e-14)
    # 3x3 Gauss is exact on the rectangles: ε_h = 1.1 ε_ref is 10 % off in energy norm
    assert relative_energy_error(level1, x, w, 1.1 * eps, body) == pytest.approx(0.1, rel=1e-10)
    # a constant strain E0 added on the lower block only
    E0 = np.zeros((3, 3))
    E0[1, 2] = E0[2, 1] = 1e-4
    E0[0, 0] = 2e-5
    lower = body == "lower"
    eps_h = eps + lower[:, None, None] * E0
    expected = np.sqrt(np.sum(hooke(E0[None], E, NU) * E0) * 0.01 * 0.01 * level1.thickness
                       / (2 * level1.strain_energy * level1.thickness))
    assert relative_energy_error(level1, x, w, eps_h, np.where(lower, 0, 1)) == pytest.approx(
        expected, rel=1e-10)


@pytest.mark.slow
def test_strain_and_stress_plane_strain_and_body_choice(level1):
    y = np.array([0.003, 0.004, 0.007])
    z = np.array([0.002, 0.01, 0.015])
    eps = level1.strain(y, z)
    assert np.all(eps[:, 0, :] == 0.0) and np.all(eps[:, :, 0] == 0.0)
    np.testing.assert_array_equal(eps[1], level1.strain(y[1:2], z[1:2], "lower")[0])
    sigma = level1.stress(y, z)
    np.testing.assert_allclose(sigma[:, 0, 0], NU * (sigma[:, 1, 1] + sigma[:, 2, 2]), rtol=1e-12)
    with pytest.raises(ValueError, match="body"):
        level1.strain(y, z, "middle")
    with pytest.raises(ValueError, match="outside body lower"):
        level1.strain(y, z, "lower")  # z = 0.015 is in the upper block


@pytest.mark.slow
def test_save_load_round_trip(level1, tmp_path):
    path = level1.save(tmp_path / "planar.npz")
    loaded = PlanarReference.load(path)
    assert loaded.strain_energy == level1.strain_energy and loaded.level == 1
    y, z = np.array([0.001, 0.009]), np.array([0.004, 0.019])
    np.testing.assert_array_equal(loaded.strain(y, z), level1.strain(y, z))
    assert [p.name for p in tmp_path.iterdir()] == ["planar.npz"]


@pytest.mark.slow
def test_command_line_writes_converged_reference(tmp_path, capsys):
    out = tmp_path / "ref" / "planar.npz"
    assert planar.main(["--out", str(out), "--tol-digits", "2", "--max-level", "3"]) == 0
    ref = PlanarReference.load(out)
    assert ref.converged and list(ref.levels) == [0, 1]
    assert abs(ref.energies[1] - ref.energies[0]) <= 1e-2 * ref.energies[1]
    assert "level 1" in capsys.readouterr().err
    assert planar.main(["--out", str(out), "--max-level", "0"]) == 2


@pytest.mark.slow
def test_relative_energy_error_of_a_coarse_level_is_its_energy_gap(level1):
    """Nested meshes: ||u_1 − u_0||²_E = 2 (U_1 − U_0), exactly.

    Π(v) − Π(u_1) = ½ ||v − u_1||²_E for v = u_0 in the finer admissible space, and at a
    discrete solution Π(u_h) = R_h·d − U_h, where the top reaction R_h equals the lateral load
    resultant at every level (global equilibrium). Integrated on the finer mesh's Gauss points,
    which are exact for both fields.
    """
    coarse = planar.solve(0)
    x, w, body = _gauss_points(level1)
    error = relative_energy_error(level1, x, w, coarse.strain(x[:, 1], x[:, 2], body), body)
    gap = np.sqrt((level1.strain_energy - coarse.strain_energy) / level1.strain_energy)
    assert error == pytest.approx(gap, rel=1e-8)
