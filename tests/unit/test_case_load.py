"""Case files: the DESIGN.md example loads with the right values; malformed files are
rejected with a one-line InputError naming the exact field."""

from __future__ import annotations

import copy
import pickle
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from cgfem.case import (
    Case,
    ContactPair,
    DisplacementBC,
    GridSpec,
    Material,
    SolverOptions,
    TractionBC,
    case_schema,
    check_patch_names,
    load_case,
    parse_case,
    parse_yaml,
)
from cgfem.errors import InputError
from cgfem.fem.element import HEX8, HEX27
from cgfem.geometry.specs import BoxSpec, CylinderSpec, HalfTorusSpec, NurbsFileSpec, SphereSpec, TorusSpec

from tests.support.cases import PLANAR



def write(tmp_path: Path, text: str, name: str = "case.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def planar_data() -> dict:
    return parse_yaml(PLANAR)


def test_planar_example_loads_with_its_values(tmp_path: Path) -> None:
    path = write(tmp_path, PLANAR)
    case = load_case(path)
    assert isinstance(case, Case)
    assert (case.name, case.kinematics, case.steps, case.source) == ("planar", "small", 1, path)
    assert case.body_names == ("lower", "upper")
    lower, upper = case.bodies
    assert lower.geometry == BoxSpec(min=(0.0, 0.0, 0.0), max=(0.0025, 0.01, 0.01))
    assert upper.geometry.min == (0.0, 0.0, 0.01)
    assert lower.builder == "box"
    assert lower.material == Material("linear_elastic", 115.0e9, 0.3)
    assert lower.grid.offset == (0.13, 0.29, 0.41)
    assert upper.grid.offset == (0.37, 0.71, 0.23)
    assert lower.grid.h(2) == 0.0025 / 4
    assert lower.body_force is None
    assert case.body("upper") is upper

    first = case.boundary[0]
    assert isinstance(first, DisplacementBC)
    assert (first.body, first.patches) == ("upper", ("zmax",))
    assert [(i, e.constant_value) for i, e in first.components] == [(1, 0.0), (2, -1.6e-6)]
    assert [i for i, _ in case.boundary[2].components] == [0]
    assert case.boundary[2].patches == ("xmin", "xmax")

    traction = case.boundary[4]
    assert isinstance(traction, TractionBC)
    assert traction.patches == ("ymin",)
    point = (0.001, 0.0, 0.003)
    z = point[2]
    np.testing.assert_allclose(
        traction.value(*point), [0.0, 4e11 * (0.01 - z) * z, 10e11 * (0.01 - z) * z], rtol=1e-15
    )
    np.testing.assert_allclose(case.boundary[5].value(*point)[1], -4e11 * (0.01 - z) * z, rtol=1e-15)

    assert case.contact == (ContactPair("lower", "upper", 10.0),)
    assert case.solver == SolverOptions(1e-9, 30, 4, "auto")


def test_case_round_trips_through_pickle(tmp_path: Path) -> None:
    case = load_case(write(tmp_path, PLANAR))
    again = pickle.loads(pickle.dumps(case))
    assert again == case
    assert again.boundary[4].value(0.0, 0.0, 0.005)[2] == pytest.approx(10e11 * 0.005 * 0.005)


def test_defaults_are_filled(tmp_path: Path) -> None:
    data = planar_data()
    for key in ("steps", "solver"):
        del data[key]
    del data["bodies"]["lower"]["grid"]["offset"]
    del data["contact"][0]["kappa"]
    case = parse_case(data, tmp_path)
    assert case.steps == 1
    assert case.solver == SolverOptions(newton_tol=1e-9, max_newton=30, outer_passes=50, linear="auto")
    assert case.body("lower").grid.offset == (0.0, 0.0, 0.0)
    assert case.contact[0].kappa == 10.0
    del data["contact"]
    assert parse_case(data, tmp_path).contact == ()
    assert parse_case({**data, "contact": []}, tmp_path).contact == ()


def test_schema_is_valid_and_its_defaults_match_the_dataclasses() -> None:
    schema = case_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    solver = schema["$defs"]["solver"]["properties"]
    defaults = SolverOptions()
    names = ("newton_tol", "max_newton", "outer_passes", "linear", "outer_tol", "max_cutbacks")
    per_element = ("ghost_penalty", "kappa_dirichlet")
    assert {k: v["default"] for k, v in solver.items() if k not in per_element} == \
        {n: getattr(defaults, n) for n in names}
    # the ghost penalty's and the weak-Dirichlet factor's defaults are the element's, named in
    # the descriptions
    for name in per_element:
        assert "default" not in solver[name] and getattr(defaults, name) is None
        assert f"{getattr(HEX8, name):g} at order 1" in solver[name]["description"]
        assert f"{getattr(HEX27, name):g} at order 2" in solver[name]["description"]
    assert schema["$defs"]["contactPair"]["properties"]["kappa"]["default"] == ContactPair.kappa
    assert tuple(schema["$defs"]["grid"]["properties"]["offset"]["default"]) == GridSpec.offset
    assert schema["properties"]["steps"]["default"] == 1


def test_material_lame_parameters() -> None:
    lam, mu = Material("neo_hookean", 1.0e9, 0.3).lame()
    assert lam == pytest.approx(1.0e9 * 0.3 / (1.3 * 0.4), rel=1e-15)
    assert mu == pytest.approx(1.0e9 / 2.6, rel=1e-15)
    assert Material("neo_hookean", 1.0e9, 0.3).lame() == (lam, mu)
    assert Material("neo_hookean", 1.0e9, 0.3).lame().mu == mu


def test_all_builders_and_their_patches(tmp_path: Path) -> None:
    (tmp_path / "shapes").mkdir()
    (tmp_path / "shapes" / "link.json").write_text("{}")
    material = {"model": "neo_hookean", "E": 2e11, "nu": 0.3}
    grid = {"h0": 0.1}
    bodies = {
        "ball": {"builder": "sphere", "center": [0, 0, 0], "radius": 1},
        "can": {"builder": "cylinder", "center": [0, 0, 0], "axis": [0, 0, 1], "radius": 1, "height": 2},
        "ring": {"builder": "torus", "center": [0, 0, 0], "axis": [0, 1, 0], "major_radius": 2,
                 "minor_radius": 0.5},
        "arch": {"builder": "half_torus", "center": [0, 0, 0], "axis": [0, 0, 1], "major_radius": 2,
                 "minor_radius": 0.5, "keep": [0, 1, 0]},
        "link": {"builder": "nurbs", "file": "shapes/link.json"},
    }
    data = {
        "name": "shapes",
        "kinematics": "finite",
        "steps": 3,
        "bodies": {n: {"geometry": g, "material": material, "grid": grid} for n, g in bodies.items()},
        "boundary": [
            {"body": "ball", "patches": ["surface"], "type": "displacement", "components": {"z": "0.1*x"}},
            {"body": "can", "patches": ["bottom", "top", "side"], "type": "traction", "value": [0, 0, 1e6]},
            {"body": "arch", "patches": ["cap_a", "cap_b"], "type": "displacement", "components": {"x": 0}},
            {"body": "link", "patches": ["anything"], "type": "displacement", "components": {"x": 0}},
        ],
        "contact": [{"slave": "ball", "master": "can"}],
    }
    case = parse_case(data, tmp_path)
    kinds = [type(b.geometry) for b in case.bodies]
    assert kinds == [SphereSpec, CylinderSpec, TorusSpec, HalfTorusSpec, NurbsFileSpec]
    assert case.body("arch").geometry.keep == (0.0, 1.0, 0.0)
    assert case.body("link").geometry.file == tmp_path / "shapes" / "link.json"
    assert case.body("ball").material.E == 2e11
    assert case.steps == 3
    # nurbs patch names are only known once the file is read: the CLI checks them then
    check_patch_names(case, {"link": ["anything", "other"]})
    with pytest.raises(InputError) as info:
        check_patch_names(case, {"link": ["hole", "rim"]})
    assert info.value.field == "boundary[3].patches[0]"
    assert "hole, rim" in info.value.message


def test_scientific_numbers_without_a_dot_are_floats(tmp_path: Path) -> None:
    text = PLANAR.replace("E: 115.0e9, nu: 0.3}   # or", "E: 2e11, nu: 0.3}   # or")
    case = load_case(write(tmp_path, text))
    assert case.body("lower").material.E == 2e11
    assert case.body("upper").material.E == 115.0e9


def _set(data: dict, path: str, value: object) -> None:
    """Set a dotted path (list indices as numbers) in ``data``; ``...`` deletes."""
    keys = [int(k) if k.isdigit() else k for k in path.split(".")]
    node = data
    for key in keys[:-1]:
        node = node[key]
    if value is ...:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value


TORUS = {"builder": "torus", "center": [0, 0, 0], "axis": [0, 0, 1], "major_radius": 1.0, "minor_radius": 0.2}
CYLINDER = {"builder": "cylinder", "center": [0, 0, 0], "axis": [0, 0, 1], "radius": 1.0, "height": 1.0}
HALF = {**TORUS, "builder": "half_torus", "keep": [1, 0, 0]}

# (id, dotted path to change, new value (... deletes), expected field, words in the message)
MALFORMED = [
    ("unknown top key", "colour", "red", "colour", "unknown key"),
    ("unknown grid key", "bodies.lower.grid.colour", 1, "bodies.lower.grid.colour", "unknown key"),
    ("unknown geometry key", "bodies.lower.geometry.radius", 1.0, "bodies.lower.geometry.radius",
     "unknown key (allowed: builder, min, max)"),
    ("unknown material key", "bodies.upper.material.G", 1.0, "bodies.upper.material.G", "unknown key"),
    ("unknown boundary key", "boundary.0.value", [0, 0, 0], "boundary[0].value", "unknown key"),
    ("unknown component", "boundary.1.components.w", 0.0, "boundary[1].components.w", "unknown key"),
    ("unknown solver key", "solver.tolerance", 1e-6, "solver.tolerance", "unknown key"),
    ("finite linear", "kinematics", "finite", "bodies.lower.material.model", "need neo_hookean"),
    ("negative ghost penalty", "solver.ghost_penalty", -1.0, "solver.ghost_penalty", ">= 0"),
    ("negative cut-backs", "solver.max_cutbacks", -1, "solver.max_cutbacks", ""),
    ("unknown contact key", "contact.0.penalty", 1.0, "contact[0].penalty", "unknown key"),
    ("E as string", "bodies.lower.material.E", "stiff", "bodies.lower.material.E", "expected a number"),
    ("E as expression", "bodies.lower.material.E", "1e9*2", "bodies.lower.material.E", "expected a number"),
    ("E as bool", "bodies.lower.material.E", True, "bodies.lower.material.E", "expected a number"),
    ("huge E", "bodies.lower.material.E", 10**400, "bodies.lower.material.E", "too large"),
    ("steps string", "steps", "two", "steps", "expected an integer"),
    ("steps zero", "steps", 0, "steps", "must be >= 1, got 0"),
    ("patches string", "boundary.0.patches", "zmax", "boundary[0].patches", "expected a list"),
    ("patches empty", "boundary.0.patches", [], "boundary[0].patches", "must not be empty"),
    ("value two items", "boundary.4.value", ["0", "1"], "boundary[4].value", "expected 3 items, got 2"),
    ("value dict", "boundary.4.value", {"x": 1}, "boundary[4].value", "expected a list"),
    ("components empty", "boundary.1.components", {}, "boundary[1].components", "at least one of x, y, z"),
    ("bad bc type", "boundary.1.type", "pressure", "boundary[1].type", "must be one of displacement, traction"),
    ("missing grid", "bodies.lower.grid", ..., "bodies.lower.grid", "missing required key"),
    ("missing name", "name", ..., "name", "missing required key"),
    ("missing builder", "bodies.lower.geometry.builder", ..., "bodies.lower.geometry.builder", "missing"),
    ("box missing max", "bodies.lower.geometry.max", ..., "bodies.lower.geometry.max", "missing"),
    ("body name", "bodies.2nd", {}, "bodies.2nd", "invalid name"),
    ("no bodies", "bodies", {}, "bodies", "must define at least one body"),
    ("r >= R", "bodies.lower.geometry", {**TORUS, "minor_radius": 1.0}, "bodies.lower.geometry.minor_radius",
     "smaller than major_radius"),
    ("zero-size box", "bodies.lower.geometry.max", [0.0, 0.01, 0.01], "bodies.lower.geometry.max", "along x"),
    ("non-unit axis", "bodies.upper.geometry", {**CYLINDER, "axis": [0, 0, 2]}, "bodies.upper.geometry.axis",
     "unit vector"),
    ("zero axis", "bodies.upper.geometry", {**CYLINDER, "axis": [0, 0, 0]}, "bodies.upper.geometry.axis",
     "zero vector"),
    ("axis two items", "bodies.upper.geometry", {**CYLINDER, "axis": [0, 1]}, "bodies.upper.geometry.axis",
     "expected 3 items"),
    ("keep not perpendicular", "bodies.lower.geometry", {**HALF, "keep": [0, 0, 1]},
     "bodies.lower.geometry.keep", "perpendicular"),
    ("half torus without keep", "bodies.lower.geometry", TORUS | {"builder": "half_torus"},
     "bodies.lower.geometry.keep", "missing"),
    ("unknown builder", "bodies.lower.geometry", {"builder": "cone", "radius": 1},
     "bodies.lower.geometry.builder", "unknown builder 'cone' (known: box, sphere, cylinder, torus, half_torus"),
    ("negative radius", "bodies.lower.geometry", {"builder": "sphere", "center": [0, 0, 0], "radius": -1},
     "bodies.lower.geometry.radius", "must be > 0"),
    ("unknown patch", "boundary.2.patches", ["xmin", "top"], "boundary[2].patches[1]",
     "unknown patch 'top' of body 'lower' (known: xmin, xmax, ymin, ymax, zmin, zmax)"),
    ("duplicate patch", "boundary.2.patches", ["xmin", "xmin"], "boundary[2].patches[1]", "duplicate"),
    ("unknown body", "boundary.1.body", "middle", "boundary[1].body", "unknown body 'middle' (known: lower, upper)"),
    ("unknown slave", "contact.0.slave", "middle", "contact[0].slave", "unknown body"),
    ("slave == master", "contact.0.master", "lower", "contact[0].master", "must differ from slave"),
    ("kappa zero", "contact.0.kappa", 0, "contact[0].kappa", "must be > 0"),
    ("nu 0.5", "bodies.lower.material.nu", 0.5, "bodies.lower.material.nu", "must be in (-1, 0.5), got 0.5"),
    ("nu nan", "bodies.lower.material.nu", float("nan"), "bodies.lower.material.nu", "finite"),
    ("bad material model", "bodies.lower.material.model", "plastic", "bodies.lower.material.model",
     "must be one of linear_elastic, neo_hookean"),
    ("negative h0", "bodies.upper.grid.h0", -0.001, "bodies.upper.grid.h0", "must be > 0"),
    ("offset 1.0", "bodies.upper.grid.offset", [0.5, 1.0, 0.0], "bodies.upper.grid.offset[1]",
     "must be in [0, 1), got 1.0"),
    ("kinematics", "kinematics", "big", "kinematics", "must be one of small, finite, got 'big'"),
    ("linear solver", "solver.linear", "mumps", "solver.linear", "must be one of auto"),
    ("max_newton zero", "solver.max_newton", 0, "solver.max_newton", ">= 1"),
    ("__import__", "boundary.4.value.1", '__import__("os")', "boundary[4].value[1]", "unknown name '__import__'"),
    ("attribute access", "boundary.0.components.z", "x.real", "boundary[0].components.z", "attribute access"),
    ("unlisted function", "bodies.lower.body_force", ["0", "0", "log(z)"], "bodies.lower.body_force[2]",
     "unknown name 'log'"),
    ("huge exponent", "boundary.5.value.2", "z**1000", "boundary[5].value[2]", "exceeds 64"),
    ("huge constant power", "boundary.5.value.0", "10**64*1e300", "boundary[5].value[0]", "overflows"),
    ("inf component", "boundary.0.components.y", float("inf"), "boundary[0].components.y", "finite"),
    ("expression list", "boundary.0.components.y", [1], "boundary[0].components.y",
     "expected a number or an expression string"),
    ("zero spin axis", "bodies.lower.hold_spin", [0, 0, 0], "bodies.lower.hold_spin", "not all 0"),
    ("spin axis two items", "bodies.lower.hold_spin", [1, 0], "bodies.lower.hold_spin", "expected 3 items"),
    ("spin axis string", "bodies.lower.hold_spin", ["x", 0, 0], "bodies.lower.hold_spin[0]", "expected a number"),
]


@pytest.mark.parametrize("path, value, field, words", [m[1:] for m in MALFORMED], ids=[m[0] for m in MALFORMED])
def test_malformed_cases_name_the_field(tmp_path: Path, path: str, value: object, field: str, words: str) -> None:
    data = planar_data()
    _set(data, path, copy.deepcopy(value))
    with pytest.raises(InputError) as info:
        parse_case(data, tmp_path)
    error = info.value
    assert error.field == field, str(error)
    assert words in error.message, str(error)
    assert "\n" not in str(error)
    assert str(error) == f"{field}: {error.message}"


def test_exact_messages(tmp_path: Path) -> None:
    cases = [
        ("bodies.lower.material.nu", 0.7, "bodies.lower.material.nu: must be in (-1, 0.5), got 0.7"),
        ("kinematics", "big", "kinematics: must be one of small, finite, got 'big'"),
    ]
    for path, value, expected in cases:
        data = planar_data()
        _set(data, path, value)
        with pytest.raises(InputError) as info:
            parse_case(data, tmp_path)
        assert str(info.value) == expected


def test_unknown_key_is_reported_before_the_missing_key_it_replaces(tmp_path: Path) -> None:
    data = planar_data()
    data["kinematic"] = data.pop("kinematics")
    with pytest.raises(InputError) as info:
        parse_case(data, tmp_path)
    assert info.value.field == "kinematic"


def test_missing_nurbs_file_is_resolved_next_to_the_case(tmp_path: Path) -> None:
    text = PLANAR.replace("{builder: box, min: [0, 0, 0], max: [0.0025, 0.01, 0.01]}",
                          "{builder: nurbs, file: geometry/lower.json}")
    (tmp_path / "cases").mkdir()
    path = write(tmp_path / "cases", text)
    with pytest.raises(InputError) as info:
        load_case(path)
    assert info.value.field == "bodies.lower.geometry.file"
    assert str(tmp_path / "cases" / "geometry" / "lower.json") in info.value.message
    (tmp_path / "cases" / "geometry" / "lower.json").mkdir(parents=True)
    with pytest.raises(InputError) as info:
        load_case(path)
    assert info.value.field == "bodies.lower.geometry.file"
    assert "is a directory" in info.value.message
    (tmp_path / "cases" / "geometry" / "lower.json").rmdir()
    (tmp_path / "cases" / "geometry" / "lower.json").write_text("{}")
    case = load_case(path)
    assert case.body("lower").geometry.file == tmp_path / "cases" / "geometry" / "lower.json"


FILE_ERRORS = [
    ("yaml syntax", "name: [planar\nkinematics: small\n", "line 2, column"),
    ("empty file", "", "empty case file"),
    ("only a comment", "# nothing here\n", "empty case file"),
    ("top level list", "- name: planar\n- kinematics: small\n", "mapping of keys at the top level, got a list"),
    ("top level scalar", "planar\n", "got a string"),
    ("duplicate key", PLANAR.replace("components: {y: 0.0}}", "components: {y: 0.0, y: 1.0}}"), "duplicate key 'y'"),
    ("two documents", PLANAR + "---\nname: again\n", "single document"),
]


@pytest.mark.parametrize("text, words", [f[1:] for f in FILE_ERRORS], ids=[f[0] for f in FILE_ERRORS])
def test_file_level_errors_name_the_file(tmp_path: Path, text: str, words: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(InputError) as info:
        load_case(path)
    assert info.value.field == str(path)
    assert words in info.value.message, str(info.value)
    assert "\n" not in str(info.value)


def test_missing_file_and_directory(tmp_path: Path) -> None:
    with pytest.raises(InputError) as info:
        load_case(tmp_path / "nope.yaml")
    assert (info.value.field, info.value.message) == (str(tmp_path / "nope.yaml"), "no such file")
    with pytest.raises(InputError) as info:
        load_case(tmp_path)
    assert info.value.field == str(tmp_path)
    assert "directory" in info.value.message


def test_parse_case_rejects_a_non_mapping(tmp_path: Path) -> None:
    with pytest.raises(InputError) as info:
        parse_case(["name"], tmp_path)
    assert info.value.field == ""
    assert "got a list" in str(info.value)


def test_case_checks_references_when_built_directly(tmp_path: Path) -> None:
    case = load_case(write(tmp_path, PLANAR))
    with pytest.raises(InputError) as info:
        Case("c", "small", 1, case.bodies, case.boundary, (ContactPair("lower", "ghost"),), SolverOptions())
    assert info.value.field == "contact[0].master"
    with pytest.raises(InputError) as info:
        Case("c", "small", 1, case.bodies + case.bodies[:1], (), (), SolverOptions())
    assert info.value.field == "bodies.lower"
    with pytest.raises(KeyError):
        case.body("ghost")
