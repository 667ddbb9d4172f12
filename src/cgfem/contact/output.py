"""``contact_NNN.vtu``: one vertex per slave point of every pair (README "Result files").

Point data: ``gap`` (m, signed, NaN where the ray found no master), ``pressure`` (lambda_N,
Pa, negative in compression, 0 where inactive), ``p_N`` (the frozen stabilizing stress),
``active`` (0/1), ``normal`` (current unit slave normal), ``weight`` (area weight, m^2: the
current area in finite strain, so ``sum pressure * weight * normal`` is the contact force on
the slave when the surfaces are parallel), ``force`` (the exact point force on the slave, N,
summing to the pair's contact force), ``displacement`` (m, from the point's reference
position: ParaView's Warp By Vector with factor -1 shows the reference configuration) and
``pair`` (index of the pair in the case's ``contact`` list). Points sit at their current
positions.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from cgfem.contact.pair import ContactPoints
from cgfem.embedding.export import write_vtu_files


def contact_mesh(points: list[ContactPoints]) -> meshio.Mesh:
    """The vertex cloud of every pair's slave points."""
    x = np.concatenate([p.x for p in points]) if points else np.zeros((0, 3))
    data = {
        "gap": np.concatenate([p.gap for p in points]) if points else np.zeros(0),
        "pressure": np.concatenate([p.pressure for p in points]) if points else np.zeros(0),
        "p_N": np.concatenate([p.p_N for p in points]) if points else np.zeros(0),
        "active": np.concatenate([p.active for p in points]).astype(np.int32) if points else np.zeros(0, np.int32),
        "normal": np.concatenate([p.normal for p in points]) if points else np.zeros((0, 3)),
        "weight": np.concatenate([p.weight for p in points]) if points else np.zeros(0),
        "force": np.concatenate([p.point_force for p in points]) if points else np.zeros((0, 3)),
        "displacement": np.concatenate([p.displacement for p in points]) if points else np.zeros((0, 3)),
        "pair": np.concatenate([np.full(p.x.shape[0], i, np.int32) for i, p in enumerate(points)])
        if points else np.zeros(0, np.int32),
    }
    cells = [("vertex", np.arange(x.shape[0], dtype=np.int64).reshape(-1, 1))]
    return meshio.Mesh(x, cells, point_data=data)


def write_contact(folder: Path, number: int, points: list[ContactPoints]) -> Path:
    target = Path(folder) / f"contact_{number:03d}.vtu"
    write_vtu_files({target: contact_mesh(points)})
    return target
