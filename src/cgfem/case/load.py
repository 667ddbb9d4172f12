"""Read a case file (YAML), validate it against ``schema.json`` and build a :class:`Case`.

Every defect raises :class:`~cgfem.errors.InputError` whose field is the dotted path of the
offending entry, with list indices (``boundary[4].value[1]``), and whose message is one line.
Order of checks: file and YAML, then the JSON schema (one error, the shallowest; an unknown
key is named itself), then the entries in file order (geometry, material, grid, body force;
boundary conditions; contact pairs; solver), then builder patch names.
"""

from __future__ import annotations

import functools
import importlib.resources
import json
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

import jsonschema
import yaml

from cgfem.case.expressions import as_expression, as_vector_expression
from cgfem.case.model import (
    DEFAULT_STEPS,
    Body,
    BoundaryCondition,
    Case,
    ContactPair,
    DisplacementBC,
    GridSpec,
    Material,
    SolverOptions,
    TractionBC,
    require_body,
)
from cgfem.errors import InputError
from cgfem.geometry.specs import BUILDERS, PATCH_NAMES, GeometrySpec

__all__ = ["case_schema", "check_patch_names", "load_case", "parse_case", "parse_yaml"]

T = TypeVar("T")
_SHOWN = 60  # characters of an offending value quoted in messages
_TYPE_NAMES = {
    "number": "a number",
    "integer": "an integer",
    "string": "a string",
    "array": "a list",
    "object": "a mapping",
    "boolean": "true or false",
    "null": "nothing",
}
# at equal depth, report an unknown key before what it may have caused (a missing key)
_PRIORITY = {"additionalProperties": 0, "propertyNames": 0, "required": 2}


# -- YAML ------------------------------------------------------------------------------
class _CaseLoader(yaml.SafeLoader):
    """Safe YAML loader that rejects duplicate keys and reads ``2e11`` as a float
    (PyYAML's YAML 1.1 float needs a dot in the mantissa and a sign in the exponent, so it
    reads ``115.0e9`` as a string)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                duplicate = key in seen
                seen.add(key)
            except TypeError:  # unhashable: SafeLoader reports it
                continue
            if duplicate:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}", key_node.start_mark
                )
        return super().construct_mapping(node, deep=deep)


_CaseLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def _yaml_error(error: yaml.YAMLError) -> str:
    if isinstance(error, yaml.MarkedYAMLError) and error.problem_mark is not None:
        mark = error.problem_mark
        what = " ".join(str(error.problem or "").split())
        if error.context:
            what += f" ({' '.join(str(error.context).split())})"
        return f"invalid YAML at line {mark.line + 1}, column {mark.column + 1}: {what}"
    return "invalid YAML: " + " ".join(str(error).split())


def _kind(value: object) -> str:
    return {list: "a list", str: "a string", dict: "a mapping"}.get(type(value), type(value).__name__)


# -- schema ----------------------------------------------------------------------------
def case_schema() -> dict[str, Any]:
    """The JSON schema (draft 2020-12) of a case file, as shipped with the package."""
    text = importlib.resources.files("cgfem.case").joinpath("schema.json").read_text("utf-8")
    return json.loads(text)


@functools.lru_cache(maxsize=1)
def _validator() -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(case_schema())


def _field(parts: Sequence[object]) -> str:
    out = ""
    for part in parts:
        if isinstance(part, int) and not isinstance(part, bool):
            out += f"[{part}]"
        else:
            out = f"{out}.{part}" if out else str(part)
    return out


def _join(field: str, key: object) -> str:
    return f"{field}.{key}" if field else str(key)


def _show(value: object) -> str:
    text = repr(value)
    return text if len(text) <= _SHOWN else text[: _SHOWN - 3] + "..."


def _interval(schema: Mapping[str, Any]) -> str:
    low = ("[", schema["minimum"]) if "minimum" in schema else ("(", schema.get("exclusiveMinimum"))
    high = ("]", schema["maximum"]) if "maximum" in schema else (")", schema.get("exclusiveMaximum"))
    if low[1] is not None and high[1] is not None:
        return f"must be in {low[0]}{low[1]:g}, {high[1]:g}{high[0]}"
    if low[1] is not None:
        return f"must be {'>=' if low[0] == '[' else '>'} {low[1]:g}"
    return f"must be {'<=' if high[0] == ']' else '<'} {high[1]:g}"


def _schema_error(error: jsonschema.ValidationError) -> InputError:
    """One-line :class:`InputError` for a schema violation, naming the deepest useful field."""
    field = _field(list(error.absolute_path))
    kind, schema, inst = error.validator, error.schema, error.instance
    if "propertyNames" in error.absolute_schema_path:
        return InputError(
            _join(field, inst),
            "invalid name: must start with a letter or '_' and contain only letters, digits and '_'",
        )
    if kind == "additionalProperties" and isinstance(inst, dict):
        known = list(schema.get("properties", {}))
        extra = next(k for k in inst if k not in known)
        return InputError(_join(field, extra), f"unknown key (allowed: {', '.join(known)})")
    if kind == "required" and isinstance(inst, dict):
        missing = next(k for k in error.validator_value if k not in inst)
        return InputError(_join(field, missing), "missing required key")
    if kind == "type":
        types = error.validator_value if isinstance(error.validator_value, list) else [error.validator_value]
        if set(types) == {"number", "string"}:
            expected = "a number or an expression string"
        else:
            expected = " or ".join(_TYPE_NAMES.get(t, t) for t in types)
        return InputError(field, f"expected {expected}, got {_show(inst)}")
    if kind == "enum" and error.path and error.path[-1] == "builder":
        return InputError(field, f"unknown builder {_show(inst)} (known: {', '.join(BUILDERS)})")
    if kind == "enum":
        allowed = ", ".join(str(v) for v in error.validator_value)
        return InputError(field, f"must be one of {allowed}, got {_show(inst)}")
    if kind in ("minItems", "maxItems") and isinstance(inst, list):
        if schema.get("minItems") == schema.get("maxItems"):
            return InputError(field, f"expected {schema['minItems']} items, got {len(inst)}")
        return InputError(field, "must not be empty" if not inst else " ".join(error.message.split()))
    if kind == "minProperties":
        names = list(schema.get("properties", {}))
        if names:
            return InputError(field, f"must set at least one of {', '.join(names)}")
        empty = "must define at least one body" if field == "bodies" else "must not be empty"
        return InputError(field, empty)
    if kind == "minLength":
        return InputError(field, "must not be empty")
    if kind in ("minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum"):
        return InputError(field, f"{_interval(schema)}, got {_show(inst)}")
    return InputError(field, _show_text(" ".join(error.message.split())))


def _show_text(text: str, limit: int = 200) -> str:
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _validate(data: object) -> None:
    errors = list(_validator().iter_errors(data))
    if errors:
        # the shallowest error; at equal depth by _PRIORITY, then in the validator's order
        def rank(item: tuple[int, jsonschema.ValidationError]) -> tuple[int, int, int]:
            index, error = item
            return (len(error.absolute_path), _PRIORITY.get(str(error.validator), 1), index)

        raise _schema_error(min(enumerate(errors), key=rank)[1])


# -- entries ---------------------------------------------------------------------------
def _within(prefix: str, build: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """``build(*args, **kwargs)``, with the field of an :class:`InputError` prefixed."""
    try:
        return build(*args, **kwargs)
    except InputError as error:
        raise error.within(prefix) from None


def _number(value: Any, field: str) -> float:
    try:
        number = float(value)
    except OverflowError:
        raise InputError(field, f"number {_show(value)} is too large") from None
    if not math.isfinite(number):
        raise InputError(field, f"must be finite, got {value!r}")
    return number


def _numbers(value: Sequence[Any], field: str) -> tuple[float, ...]:
    return tuple(_number(v, f"{field}[{i}]") for i, v in enumerate(value))


def _geometry(raw: Mapping[str, Any], base_dir: Path, prefix: str) -> GeometrySpec:
    params: dict[str, Any] = {}
    for key, value in raw.items():
        if key == "builder":
            continue
        if key == "file":
            path = Path(value) if Path(value).is_absolute() else base_dir / value
            if not path.is_file():
                problem = "is a directory" if path.is_dir() else "no such file"
                raise InputError(f"{prefix}.file", f"{problem}: {path}")
            params[key] = path
        elif isinstance(value, list):
            params[key] = _numbers(value, f"{prefix}.{key}")
        else:
            params[key] = _number(value, f"{prefix}.{key}")
    return _within(prefix, BUILDERS[raw["builder"]], **params)


def _body(name: str, raw: Mapping[str, Any], base_dir: Path) -> Body:
    prefix = f"bodies.{name}"
    geometry = _geometry(raw["geometry"], base_dir, f"{prefix}.geometry")
    mat = raw["material"]
    material = _within(
        f"{prefix}.material", Material, mat["model"], _number(mat["E"], f"{prefix}.material.E"),
        _number(mat["nu"], f"{prefix}.material.nu"),
    )
    grid_raw = raw["grid"]
    offset = _numbers(grid_raw.get("offset", [0.0, 0.0, 0.0]), f"{prefix}.grid.offset")
    grid = _within(f"{prefix}.grid", GridSpec, _number(grid_raw["h0"], f"{prefix}.grid.h0"), offset)
    body_force = None
    if "body_force" in raw:
        body_force = as_vector_expression(raw["body_force"], f"{prefix}.body_force")
    hold_spin = _numbers(raw["hold_spin"], f"{prefix}.hold_spin") if "hold_spin" in raw else None
    return _within(prefix, Body, name, geometry, material, grid, body_force, hold_spin)


def _boundary(i: int, raw: Mapping[str, Any], names: tuple[str, ...]) -> BoundaryCondition:
    prefix = f"boundary[{i}]"
    require_body(names, raw["body"], f"{prefix}.body")
    patches = tuple(raw["patches"])
    if raw["type"] == "displacement":
        given = raw["components"]
        components = tuple(
            (k, as_expression(given[axis], f"{prefix}.components.{axis}"))
            for k, axis in enumerate("xyz")
            if axis in given
        )
        return _within(prefix, DisplacementBC, raw["body"], patches, components)
    value = as_vector_expression(raw["value"], f"{prefix}.value")
    return _within(prefix, TractionBC, raw["body"], patches, value)


def _contact(i: int, raw: Mapping[str, Any], names: tuple[str, ...]) -> ContactPair:
    prefix = f"contact[{i}]"
    require_body(names, raw["slave"], f"{prefix}.slave")
    require_body(names, raw["master"], f"{prefix}.master")
    kappa = _number(raw.get("kappa", ContactPair.kappa), f"{prefix}.kappa")
    patches = {key: tuple(raw[key]) for key in ("slave_patches", "master_patches") if key in raw}
    for key in ("fit", "rule"):
        if key in raw:
            patches[key] = raw[key]
    return _within(prefix, ContactPair, raw["slave"], raw["master"], kappa, **patches)


def _solver(raw: Mapping[str, Any]) -> SolverOptions:
    options: dict[str, Any] = dict(raw)
    for key in ("newton_tol", "outer_tol", "kappa_dirichlet", "ghost_penalty"):
        if key in options:
            options[key] = _number(options[key], f"solver.{key}")
    for key in ("max_newton", "outer_passes", "max_cutbacks"):
        if key in options:
            options[key] = int(options[key])  # the schema allows 30.0
    return _within("solver", SolverOptions, **options)


# -- public ----------------------------------------------------------------------------
def check_patch_names(case: Case, patches_by_body: Mapping[str, Sequence[str]]) -> None:
    """Check that every boundary entry on a body in ``patches_by_body`` names only that
    body's patches; bodies not in the mapping are skipped. Raises :class:`InputError` at
    ``boundary[i].patches[j]``. The loader checks the builder bodies; the CLI calls this
    again with the patch names of the ``nurbs`` bodies once their files are read."""
    entries = [(f"boundary[{i}].patches", bc.body, bc.patches) for i, bc in enumerate(case.boundary)]
    for i, pair in enumerate(case.contact):
        entries += [(f"contact[{i}].{side}_patches", body, patches)
                    for side, body, patches in (("slave", pair.slave, pair.slave_patches),
                                                ("master", pair.master, pair.master_patches))
                    if patches is not None]
    for field, body, patches in entries:
        known = patches_by_body.get(body)
        if known is None:
            continue
        for j, patch in enumerate(patches):
            if patch not in known:
                raise InputError(f"{field}[{j}]",
                                 f"unknown patch {patch!r} of body {body!r} (known: {', '.join(known)})")


def parse_case(data: object, base_dir: Path, source: Path | None = None) -> Case:
    """Validate ``data`` (a case file's YAML content) and build the :class:`Case`.

    Relative ``nurbs`` file names are resolved against ``base_dir``; ``source`` is recorded
    as :attr:`Case.source`.
    """
    if not isinstance(data, dict):
        raise InputError("", f"a case file must be a mapping of keys at the top level, got {_kind(data)}")
    _validate(data)
    base_dir = Path(base_dir)
    bodies = tuple(_body(name, raw, base_dir) for name, raw in data["bodies"].items())
    names = tuple(data["bodies"])
    boundary = tuple(_boundary(i, raw, names) for i, raw in enumerate(data["boundary"]))
    contact = tuple(_contact(i, raw, names) for i, raw in enumerate(data.get("contact", [])))
    solver = _solver(data.get("solver", {}))
    case = Case(
        name=data["name"],
        kinematics=data["kinematics"],
        steps=int(data.get("steps", DEFAULT_STEPS)),
        bodies=bodies,
        boundary=boundary,
        contact=contact,
        solver=solver,
        source=source,
    )
    check_patch_names(case, {b.name: PATCH_NAMES[b.builder] for b in bodies if b.builder in PATCH_NAMES})
    return case


def parse_yaml(text: str, field: str = "case") -> dict[str, Any]:
    """The top-level mapping of a case file's YAML ``text``; syntax errors, duplicate keys,
    an empty document or a top level that is not a mapping raise :class:`InputError` at
    ``field``. Unlike plain YAML 1.1, ``2e11`` and ``115.0e9`` are read as floats."""
    try:
        data = yaml.load(text, Loader=_CaseLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as error:
        raise InputError(field, _yaml_error(error)) from None
    if data is None:
        raise InputError(field, "empty case file")
    if not isinstance(data, dict):
        raise InputError(field, f"a case file must be a mapping of keys at the top level, got {_kind(data)}")
    return data


def load_case(path: str | os.PathLike[str]) -> Case:
    """Read, validate and build the case in the YAML file ``path``.

    File-level problems (missing, a directory, unreadable, YAML syntax, empty, not a
    mapping) raise :class:`InputError` whose field is ``str(path)``.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(str(path), "is a directory, not a case file")
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(str(path), "no such file") from None
    except UnicodeDecodeError:
        raise InputError(str(path), "is not UTF-8 text") from None
    except OSError as error:
        raise InputError(str(path), f"cannot read: {error.strerror or error}") from None
    data = parse_yaml(text, str(path))
    return parse_case(data, path.parent, source=path)
