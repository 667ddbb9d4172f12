"""NURBS JSON files: bit-exact round trips, atomic writes, and every malformed file rejected
with the field of the offending entry."""

from __future__ import annotations

import copy
import json
import os

import numpy as np
import pytest

from cgfem import atomic
from cgfem.errors import InputError
from cgfem.geometry.builders import build_solid
from cgfem.geometry.io import read_solid, solid_from_dict, solid_to_dict, write_solid
from cgfem.geometry.solid import Solid
from cgfem.geometry.specs import (BoxSpec, CylinderSpec, HalfTorusSpec, NurbsFileSpec, SphereSpec,
                                  TorusSpec)

AXIS = tuple(np.array([0.2, 0.9, -0.4]) / np.linalg.norm([0.2, 0.9, -0.4]))
KEEP = tuple(np.cross(AXIS, (0.0, 0.0, 1.0)) / np.linalg.norm(np.cross(AXIS, (0.0, 0.0, 1.0))))
SPECS = {
    "box": BoxSpec((0.1, -0.2, 0.3), (1.0 / 3.0, 2.0, 3.7)),
    "sphere": SphereSpec((1.0, 2.0, 3.0), 0.1),
    "cylinder": CylinderSpec((0.0, 0.0, 0.0), AXIS, 1.0 / 7.0, 2.0),
    "torus": TorusSpec((1.0, 1.0, -1.0), AXIS, 1.0, 0.3),
    "half_torus": HalfTorusSpec((0.0, 3.0, 0.0), AXIS, 1.5, 0.2, KEEP),
}


def assert_identical(a: Solid, b: Solid) -> None:
    assert len(a.patches) == len(b.patches)
    for pa, pb in zip(a.patches, b.patches):
        assert pa.name == pb.name
        assert pa.surface.degree == pb.surface.degree
        for attr in ("knots_u", "knots_v", "control"):
            x, y = getattr(pa.surface, attr), getattr(pb.surface, attr)
            assert x.shape == y.shape
            assert x.tobytes() == y.tobytes()  # bit-exact, signed zeros included


@pytest.mark.parametrize("name", list(SPECS))
def test_round_trip_is_bit_exact(name, tmp_path):
    solid = build_solid(SPECS[name])
    path = tmp_path / f"{name}.json"
    write_solid(solid, path)
    back = read_solid(path)
    assert_identical(solid, back)
    again = tmp_path / "again.json"
    write_solid(back, again)
    assert again.read_bytes() == path.read_bytes()
    assert_identical(build_solid(NurbsFileSpec(path)), solid)  # the `nurbs` builder


def test_written_file_is_the_documented_format(tmp_path):
    path = tmp_path / "cyl.json"
    write_solid(build_solid(SPECS["cylinder"]), path)
    data = json.loads(path.read_text())
    assert data["format"] == "cgfem-nurbs" and data["version"] == 1
    side = data["patches"][0]
    assert set(side) == {"name", "degree", "knots_u", "knots_v", "control"}
    assert side["name"] == "side" and side["degree"] == [2, 1]
    assert np.array(side["control"]).shape == (9, 2, 4)
    assert data == solid_to_dict(solid_from_dict(data))


def test_write_is_atomic(tmp_path, monkeypatch):
    path = tmp_path / "solid.json"
    write_solid(build_solid(SPECS["box"]), path)
    before = path.read_bytes()

    def broken(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(atomic.os, "replace", broken)
    with pytest.raises(OSError, match="disk full"):
        write_solid(build_solid(SPECS["sphere"]), path)
    assert path.read_bytes() == before  # the old file is untouched
    assert os.listdir(tmp_path) == ["solid.json"]  # and no temporary file is left behind


# -- malformed files ----------------------------------------------------------------------
def sphere_doc() -> dict:
    return solid_to_dict(build_solid(SPECS["sphere"]))


def half_torus_doc() -> dict:
    return solid_to_dict(build_solid(SPECS["half_torus"]))


def edit(doc, change):
    doc = copy.deepcopy(doc)
    change(doc)
    return doc


def _set(path, value):
    def change(doc):
        target = doc
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
    return change


def _delete(path):
    def change(doc):
        target = doc
        for key in path[:-1]:
            target = target[key]
        del target[path[-1]]
    return change


def _negative_weight(doc):
    doc["patches"][0]["control"][3][2][3] = -0.5


def _gap(doc):
    # move one control row of the tube: its end u = 0 no longer meets cap_a
    for point in doc["patches"][0]["control"][0]:
        point[2] += 1e-3 * point[3]


BAD = {
    # case: (parsed document, expected field)
    "unknown key": (edit(sphere_doc(), _set(("patches", 0, "colour"), "red")), "patches[0].colour"),
    "unknown top key": (edit(sphere_doc(), _set(("units",), "m")), "units"),
    "missing control": (edit(sphere_doc(), _delete(("patches", 0, "control"))), "patches[0].control"),
    "missing patches": (edit(sphere_doc(), _delete(("patches",))), "patches"),
    "wrong knot count": (edit(sphere_doc(), lambda d: d["patches"][0]["knots_u"].insert(4, 0.3)),
                         "patches[0].knots_u"),
    "unclamped knots": (edit(sphere_doc(), _set(("patches", 0, "knots_v", 0), -0.1)), "patches[0].knots_v"),
    "knot not a number": (edit(sphere_doc(), _set(("patches", 0, "knots_v", 3), "0.5")),
                          "patches[0].knots_v"),
    "negative weight": (edit(sphere_doc(), _negative_weight), "patches[0].control"),
    "ragged control": (edit(sphere_doc(), lambda d: d["patches"][0]["control"][4].pop()),
                       "patches[0].control"),
    "point of 3": (edit(sphere_doc(), lambda d: d["patches"][0]["control"][1][1].pop()),
                   "patches[0].control"),
    "degree 0": (edit(sphere_doc(), _set(("patches", 0, "degree"), [0, 2])), "patches[0].degree"),
    "degree not integer": (edit(sphere_doc(), _set(("patches", 0, "degree"), [2.0, 2])), "patches[0].degree"),
    "name not a string": (edit(half_torus_doc(), _set(("patches", 1, "name"), 7)), "patches[1].name"),
    "empty name": (edit(half_torus_doc(), _set(("patches", 2, "name"), " ")), "patches[2].name"),
    "name with separator": (edit(half_torus_doc(), _set(("patches", 2, "name"), "cap+b")), "patches[2].name"),
    "patch not an object": (edit(half_torus_doc(), _set(("patches", 1), [1, 2])), "patches[1]"),
    "format wrong": (edit(sphere_doc(), _set(("format",), "nurbs")), "format"),
    "version wrong": (edit(sphere_doc(), _set(("version",), 2)), "version"),
    "version bool": (edit(sphere_doc(), _set(("version",), True)), "version"),
    "no patches": (edit(sphere_doc(), _set(("patches",), [])), "patches"),
    "top not an object": ([1, 2, 3], ""),
    "not watertight": (edit(half_torus_doc(), _gap), "patches[0]"),
    "open (cap removed)": (edit(half_torus_doc(), lambda d: d["patches"].pop(2)), "patches[0]"),
    "inward": (edit(sphere_doc(), lambda d: d["patches"][0]["control"].reverse()), "patches"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_malformed_file(case, tmp_path):
    doc, field = BAD[case]
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError) as info:
        read_solid(path)
    assert info.value.field == field, str(info.value)
    assert info.value.message


def test_unknown_key_message(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(BAD["unknown key"][0]))
    with pytest.raises(InputError, match=r"^patches\[0\]\.colour: unknown key$"):
        read_solid(path)


def test_name_message(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(BAD["name not a string"][0]))
    with pytest.raises(InputError, match=r"^patches\[1\]\.name: must be a non-empty string$"):
        read_solid(path)


def test_bad_json_names_line_and_column(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text('{"format": "cgfem-nurbs",\n "version": 1,\n "patches": [}\n')
    with pytest.raises(InputError) as info:
        read_solid(path)
    assert info.value.field == str(path)
    assert "line 3, column 14" in info.value.message
    assert "\n" not in str(info.value)


def test_duplicate_key(tmp_path):
    path = tmp_path / "dup.json"
    path.write_text('{"format": "cgfem-nurbs", "version": 1, "version": 1, "patches": []}')
    with pytest.raises(InputError, match="'version' appears twice") as info:
        read_solid(path)
    assert info.value.field == str(path)


def test_missing_file(tmp_path):
    path = tmp_path / "nowhere.json"
    with pytest.raises(InputError) as info:
        read_solid(path)
    assert info.value.field == str(path)
    assert info.value.message == "no such file"


def test_errors_nest_under_the_case_path(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(BAD["wrong knot count"][0]))
    with pytest.raises(InputError) as info:
        build_solid(NurbsFileSpec(path))
    assert info.value.within("bodies.a.geometry").field == "bodies.a.geometry.patches[0].knots_u"
