"""Where the body-fitted torus reference refines its meshes (cgfem.reference.tori_geometry):
the cap edges and the touch points, checked against the exact tori (no mesh is built)."""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.case import load_case
from cgfem.geometry.specs import HalfTorusSpec, TorusSpec
from cgfem.reference.tori_geometry import cap_edge_points, touch_points
from tests.support.paths import CASES


def _distance_to_tube(spec: TorusSpec, x: np.ndarray) -> np.ndarray:
    """Distance of the points ``x`` (m, 3) from the centre circle of ``spec``."""
    a = np.asarray(spec.axis)
    d = x - np.asarray(spec.center)
    height = d @ a
    radial = np.linalg.norm(d - height[:, None] * a, axis=1)
    return np.hypot(radial - spec.major_radius, height)


@pytest.mark.parametrize("case", ["chain2_rubber", "chain3"])
def test_cap_edge_points_lie_on_the_cap_edge_in_the_quarter(case):
    """Every point lies on the tube (distance r from the centre circle) and in the cut plane;
    the quarter ``x, z >= 0`` holds half of one cap edge, sampled at the requested step."""
    step = 5e-4
    for body in load_case(CASES / f"{case}.yaml").bodies:
        spec = body.geometry
        x = cap_edge_points(spec, step)
        if not isinstance(spec, HalfTorusSpec):
            assert x.shape == (0, 3)
            continue
        r = spec.minor_radius
        assert np.abs(_distance_to_tube(spec, x) - r).max() < 1e-12 * spec.major_radius
        assert np.abs((x - spec.center) @ np.asarray(spec.keep)).max() < 1e-15
        assert x[:, 0].min() >= -1e-12 and x[:, 2].min() >= -1e-12
        # the quarter holds half of one cap's edge: a half circle about one cap centre
        centres = [np.asarray(spec.center) + sign * spec.major_radius
                   * np.cross(spec.axis, spec.keep) for sign in (1.0, -1.0)]
        near = [np.abs(np.linalg.norm(x - c, axis=1) - r).max() < 1e-12 for c in centres]
        assert sum(near) == 1
        n_circle = int(np.ceil(2.0 * np.pi * r / step))
        assert abs(len(x) - n_circle / 2) <= 1
        d = np.linalg.norm(x[:, None] - x[None], axis=-1) + np.eye(len(x))
        assert np.allclose(d.min(axis=1), 2.0 * r * np.sin(np.pi / n_circle), rtol=1e-9)

def test_touch_points_lie_on_both_tubes_of_each_pair():
    """chain3's two pairs touch with zero initial gap: each touch point lies on the slave's
    and on the master's tube to the search's angular resolution."""
    case = load_case(CASES / "chain3.yaml")
    specs = {b.name: b.geometry for b in case.bodies}
    points = touch_points(case)
    assert len(points) == len(case.contact)
    for pair, p in zip(case.contact, points):
        for name in (pair.slave, pair.master):
            spec = specs[name]
            assert abs(_distance_to_tube(spec, p[None])[0] - spec.minor_radius) < 1e-9
