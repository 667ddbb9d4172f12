"""Body-fitted plane-strain overkill reference of the planar example (docs/validation.md,
"The planar example and its reference").

Independent of cgFEM: our own Q9 elements (:mod:`cgfem.reference.elements`) on tensor
meshes of both blocks (:mod:`cgfem.reference.mesh`) with the same y edges, so the interface
nodes match. Every mesh is radically graded toward all four corners of each block (edges at
``(k / n)^BETA`` of each half side): the two top corners of the upper block (clamped next to a
free side) and the interface corners, where the solution is singular, and the bottom corners
of the lower block. Level L has ``n = N_HALF_0 · 2^L`` elements per half side, i.e.
``(2 n)²`` elements per block: every level splits each element's parameter interval in two.

Frictionless contact on z = 0.01: u_z is tied node by node (the upper body's interface u_z
DOF is the lower body's), u_y of the two bodies stays independent (no shear coupling). The
normal traction on the lower body's top is recovered from its reaction (nodal forces
K₁u₁ − f₁ there, turned into a quadratic traction field with the interface mass matrix) and
must be compressive; where it is not, an active set releases those nodes (and re-ties a
released node that would penetrate) until both conditions hold.

Command line: ``python3 -m cgfem.reference.planar --out results/reference/planar.npz``.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

from cgfem.reference.assembly import (
    assemble_matrix,
    assemble_vector,
    element_dofs,
    element_energies,
    solve_dirichlet,
)
from cgfem.reference.elements import edge_load, edge_mass, plane_strain_matrix, stiffness
from cgfem.reference.field import PlanarReference, relative_energy_error
from cgfem.reference.mesh import RectMesh, graded_breakpoints

__all__ = ["PlanarReference", "relative_energy_error", "solve", "converged", "main"]

E = 115.0e9  # Pa
NU = 0.3
THICKNESS = 0.0025  # m, of the 3D slab
WIDTH = 0.01  # m, y extent of both blocks
HEIGHT = 0.01  # m, z extent of each block
D_TOP = -1.6e-6  # m, u_z on the top of the upper block
N_HALF_0 = 2
BETA = 3.0
MAX_ACTIVE_SET_PASSES = 20


def lateral_traction(side: str) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """Traction (t_y, t_z) in Pa on the lower block's ``ymin`` or ``ymax`` face: (n, 2)."""
    sign = 1.0 if side == "ymin" else -1.0

    def traction(y: np.ndarray, z: np.ndarray) -> np.ndarray:
        q = (HEIGHT - z) * z
        return np.stack([sign * 4e11 * q, 10e11 * q], axis=-1)

    return traction


def meshes(level: int, n_half0: int = N_HALF_0, beta: float = BETA) -> tuple[RectMesh, RectMesh]:
    """The (lower, upper) meshes of a level."""
    n = n_half0 * 2**level
    y = graded_breakpoints(0.0, WIDTH, n, beta)
    return (
        RectMesh(y, graded_breakpoints(0.0, HEIGHT, n, beta)),
        RectMesh(y, graded_breakpoints(HEIGHT, 2 * HEIGHT, n, beta)),
    )


def _node_dofs(
    lower: RectMesh, upper: RectMesh, tied: np.ndarray
) -> tuple[np.ndarray, np.ndarray, int]:
    """Global DOFs (n_nodes, 2) of each body, u_z shared at ``tied`` (m,) interface nodes."""
    d1 = np.arange(2 * lower.n_nodes).reshape(-1, 2)
    d2 = 2 * lower.n_nodes + np.arange(2 * upper.n_nodes).reshape(-1, 2)
    d2[upper.side_nodes("zmin")[tied], 1] = d1[lower.side_nodes("zmax")[tied], 1]
    _, inverse = np.unique(np.concatenate([d1.ravel(), d2.ravel()]), return_inverse=True)
    n = int(inverse.max()) + 1
    return inverse[: d1.size].reshape(d1.shape), inverse[d1.size :].reshape(d2.shape), n


def _lateral_loads(lower: RectMesh) -> tuple[np.ndarray, np.ndarray]:
    """Lower block's lateral loads: element vectors (ns, 6) and their nodes (ns, 3)."""
    coords = lower.node_coords()
    loads, nodes = [], []
    for side in ("ymin", "ymax"):
        edges = lower.side_edges(side)
        loads.append(edge_load(coords[edges], lateral_traction(side)))
        nodes.append(edges)
    return np.concatenate(loads), np.concatenate(nodes)


def _solve_tied(lower: RectMesh, upper: RectMesh, tied: np.ndarray, k1, k2, loads, load_nodes):
    """Solve with u_z tied at ``tied`` (m,) interface nodes: (u_lower, u_upper, n_dofs)."""
    d1, d2, n = _node_dofs(lower, upper, tied)
    dofs1 = element_dofs(lower.connectivity(), d1)
    dofs2 = element_dofs(upper.connectivity(), d2)
    K = assemble_matrix(np.concatenate([k1, k2]), np.concatenate([dofs1, dofs2]), n)
    f = assemble_vector(loads, element_dofs(load_nodes, d1), n)
    top = upper.side_nodes("zmax")
    fixed = np.concatenate([d2[top, 0], d2[top, 1], d1[lower.side_nodes("zmin"), 0]])
    values = np.concatenate([np.zeros(len(top)), np.full(len(top), D_TOP),
                             np.zeros(lower.side_nodes("zmin").size)])
    u = solve_dirichlet(K, f, fixed, values)
    return u[d1], u[d2], n


def _interface(lower: RectMesh, u1: np.ndarray, k1, loads, load_nodes):
    """Contact on the lower body's top: nodal forces (m,) and traction σ_zz (m,), in N/m, Pa."""
    d1 = np.arange(2 * lower.n_nodes).reshape(-1, 2)
    conn = lower.connectivity()
    internal = assemble_vector(
        np.einsum("eij,ej->ei", k1, u1[conn].reshape(len(conn), -1)),
        element_dofs(conn, d1), d1.size,
    )
    external = assemble_vector(loads, element_dofs(load_nodes, d1), d1.size)
    top = lower.side_nodes("zmax")
    force = (internal - external)[d1[top, 1]]
    edges = lower.side_edges("zmax")
    m = edge_mass(lower.node_coords()[edges])
    index = np.searchsorted(top, edges)  # edge nodes as interface positions (top is sorted)
    M = assemble_matrix(m, index, len(top)).toarray()  # a few hundred nodes: dense is fine
    traction = np.linalg.solve(M, force)
    return force, traction


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def solve(level: int, n_half0: int = N_HALF_0, beta: float = BETA) -> PlanarReference:
    """Solve the planar example on the meshes of ``level`` (≥ 0).

    The contact starts closed everywhere; nodes with a tensile normal traction are released
    and released nodes that penetrate are re-tied until neither happens (RuntimeError after
    ``MAX_ACTIVE_SET_PASSES``). The returned history holds this level only.
    """
    if level < 0:
        raise ValueError(f"level: must be >= 0 (got {level})")
    start = time.perf_counter()
    lower, upper = meshes(level, n_half0, beta)
    D = plane_strain_matrix(E, NU)
    k1, k2 = stiffness(lower.element_coords(), D), stiffness(upper.element_coords(), D)
    loads, load_nodes = _lateral_loads(lower)
    top, bottom = lower.side_nodes("zmax"), upper.side_nodes("zmin")
    tied = np.ones(len(top), dtype=bool)
    for _ in range(MAX_ACTIVE_SET_PASSES):
        u1, u2, n = _solve_tied(lower, upper, tied, k1, k2, loads, load_nodes)
        force, traction = _interface(lower, u1, k1, loads, load_nodes)
        gap = u2[bottom, 1] - u1[top, 1]
        release = tied & (traction > 0.0)
        close = ~tied & (gap < 0.0)
        if not (release.any() or close.any()):
            break
        tied = (tied & ~release) | close
    else:
        raise RuntimeError(f"contact active set did not settle in {MAX_ACTIVE_SET_PASSES} passes")
    energy = float(
        element_energies(k1, u1[lower.connectivity()].reshape(lower.n_elements, -1)).sum()
        + element_energies(k2, u2[upper.connectivity()].reshape(upper.n_elements, -1)).sum()
    )
    seconds = time.perf_counter() - start
    return PlanarReference(
        E=E, nu=NU, thickness=THICKNESS, level=level, n_half=n_half0 * 2**level, beta=beta,
        y_breaks=lower.y_breaks, z_breaks_lower=lower.z_breaks, z_breaks_upper=upper.z_breaks,
        u_lower=u1, u_upper=u2, strain_energy=energy,
        levels=np.array([level]), energies=np.array([energy]), dofs=np.array([n]),
        seconds=np.array([seconds]), peak_rss_mb=np.array([_peak_rss_mb()]),
        interface_y=lower.node_coords()[top, 0], interface_traction=traction, tied=tied,
        interface_force=float(force.sum()), lateral_force_z=float(loads[:, 1::2].sum()),
    )


def _log_level(ref: PlanarReference, log: Callable[[str], None]) -> None:
    log(
        f"planar reference level {ref.level}: {ref.dofs[-1]} dofs, "
        f"strain energy {ref.strain_energy:.12e} J/m, {ref.seconds[-1]:.1f} s, "
        f"peak RSS {ref.peak_rss_mb[-1]:.0f} MB, min pressure "
        f"{-ref.interface_traction.max():.4e} Pa, {int((~ref.tied).sum())} released nodes"
    )


def _stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def converged(
    tol_digits: int = 7,
    max_level: int = 5,
    start_level: int = 0,
    log: Callable[[str], None] = _stderr,
) -> PlanarReference:
    """Refine from ``start_level`` until the strain energy is stable to ``tol_digits``.

    Stable: |U_L − U_(L−1)| ≤ 10^(−tol_digits) |U_L|. Returns the last level's solution
    with the history of every level solved; ``converged`` is False if ``max_level`` was
    reached first (logged).
    """
    if start_level < 0 or max_level <= start_level or tol_digits < 1:
        raise ValueError(
            f"levels: need 0 <= start_level < max_level and tol_digits >= 1 "
            f"(got {start_level}, {max_level}, {tol_digits})"
        )
    history: list[PlanarReference] = []
    for level in range(start_level, max_level + 1):
        ref = solve(level)
        history.append(ref)
        _log_level(ref, log)
        done = len(history) > 1 and abs(ref.strain_energy - history[-2].strain_energy) <= (
            10.0**-tol_digits * abs(ref.strain_energy)
        )
        if done or level == max_level:
            break
    if not done:
        log(f"planar reference: energy not stable to {tol_digits} digits by level {max_level}")
    stacked = {
        name: np.concatenate([getattr(h, name) for h in history])
        for name in ("levels", "energies", "dofs", "seconds", "peak_rss_mb")
    }
    return replace(ref, **stacked, converged=bool(done))


def main(argv: list[str] | None = None) -> int:
    """``python3 -m cgfem.reference.planar --out FILE.npz``: compute and cache the reference."""
    parser = argparse.ArgumentParser(prog="python3 -m cgfem.reference.planar",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="npz file to write")
    parser.add_argument("--tol-digits", type=int, default=7)
    parser.add_argument("--max-level", type=int, default=5)
    parser.add_argument("--start-level", type=int, default=0)
    args = parser.parse_args(argv)
    if args.start_level < 0 or args.max_level <= args.start_level or args.tol_digits < 1:
        print(f"--max-level: must exceed --start-level >= 0, and --tol-digits be >= 1 (got "
              f"{args.max_level}, {args.start_level}, {args.tol_digits})", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    ref = converged(args.tol_digits, args.max_level, args.start_level)
    ref.save(out)
    _stderr(f"planar reference: U = {ref.strain_energy:.12e} J/m "
            f"({'converged' if ref.converged else 'NOT converged'}), written to {out}")
    return 0 if ref.converged else 1


if __name__ == "__main__":
    sys.exit(main())
