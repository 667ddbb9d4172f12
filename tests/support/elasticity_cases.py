"""Small case files for the elasticity tests, built as dicts and parsed like YAML ones."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cgfem.case.load import parse_case
from cgfem.case.model import Case


def _num(v: float) -> str:
    return repr(float(v))


def linear_field(G: np.ndarray, i: int) -> str:
    """Expression of ``u_i = G[i, j] x_j``."""
    return f"{_num(G[i, 0])}*x + {_num(G[i, 1])}*y + {_num(G[i, 2])}*z"


def box_case(boundary: list, *, material: dict, kinematics: str = "small", steps: int = 1,
             h0: float = 0.3, offset=(0.13, 0.29, 0.41), size=(1.0, 1.0, 1.0),
             solver: dict | None = None) -> Case:
    data = {"name": "box", "kinematics": kinematics, "steps": steps,
            "bodies": {"b": {"geometry": {"builder": "box", "min": [0, 0, 0], "max": list(size)},
                             "material": material,
                             "grid": {"h0": h0, "offset": [float(o) for o in offset]}}},
            "boundary": [{"body": "b", **bc} for bc in boundary],
            "solver": {"outer_passes": 40, "outer_tol": 1e-12, "linear": "superlu", **(solver or {})}}
    return parse_case(data, Path("."))


def uniform_stress_case(sigma: np.ndarray, E: float, nu: float, offset,
                        solver: dict | None = None) -> tuple[Case, np.ndarray]:
    """Unit box with u = eps x on the three low faces and sigma . n on the three high ones
    (``solver``: options over :func:`box_case`'s); returns the case and the strain ``eps``."""
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    eps = (sigma - lam / (3 * lam + 2 * mu) * np.trace(sigma) * np.eye(3)) / (2 * mu)
    fixed = {"patches": ["xmin", "ymin", "zmin"], "type": "displacement",
             "components": {c: linear_field(eps, i) for i, c in enumerate("xyz")}}
    loads = [{"patches": [p], "type": "traction", "value": [_num(v) for v in sigma[:, a]]}
             for a, p in enumerate(("xmax", "ymax", "zmax"))]
    case = box_case([fixed, *loads], material={"model": "linear_elastic", "E": E, "nu": nu},
                    offset=offset, solver=solver)
    return case, eps
