"""Solids as NURBS JSON files (builder ``nurbs`` of a case file).

Format, version 1::

    {"format": "cgfem-nurbs",
     "version": 1,
     "patches": [
        {"name": "tube",
         "degree": [2, 2],
         "knots_u": [0.0, 0.0, 0.0, 0.5, 0.5, 1.0, 1.0, 1.0],
         "knots_v": [...],
         "control": [[[wx, wy, wz, w], ...], ...]}]}

- ``format`` is the string ``"cgfem-nurbs"``; ``version`` the integer 1.
- ``patches`` is a non-empty list; each patch has exactly the keys above (unknown keys are
  errors). ``name`` is a non-empty string without ``+`` or ``/`` (those separate names in
  result keys such as ``body/patch+patch``); several patches may share a name.
- ``degree`` is ``[p, q]``, integers >= 1. ``knots_u`` (``n_u + p + 1`` numbers) and
  ``knots_v`` (``n_v + q + 1``) are clamped, non-decreasing knot vectors.
- ``control`` is ``n_u`` lists of ``n_v`` homogeneous control points
  ``[w x, w y, w z, w]`` (weight last, ``w > 0``): ``control[i][j]`` multiplies
  ``N_i(u) M_j(v)``. Lengths in metres.
- The patches must form a closed, outward-oriented surface, ``S_u x S_v`` pointing out of
  the solid (checked by :func:`cgfem.geometry.watertight.check_watertight` on reading).

Floats are written with ``repr`` precision, so a write/read round trip is bit-exact. Every
problem found on reading raises :class:`~cgfem.errors.InputError` whose field is the path
inside the file (``patches[2].knots_u``); an unreadable file or a JSON syntax error has the
file path as its field.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from cgfem.atomic import write_text_atomic
from cgfem.errors import InputError
from cgfem.geometry.nurbs import NurbsSurface
from cgfem.geometry.solid import Patch, Solid
from cgfem.geometry.watertight import check_watertight

FORMAT = "cgfem-nurbs"
VERSION = 1
_TOP_KEYS = ("format", "version", "patches")
_PATCH_KEYS = ("name", "degree", "knots_u", "knots_v", "control")
_NAME_SEPARATORS = "+/"


# -- writing ------------------------------------------------------------------------------
def solid_to_dict(solid: Solid) -> dict:
    """The JSON-ready dictionary of ``solid`` (plain lists, ints and floats)."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "patches": [
            {
                "name": patch.name,
                "degree": [int(d) for d in patch.surface.degree],
                "knots_u": [float(k) for k in patch.surface.knots_u],
                "knots_v": [float(k) for k in patch.surface.knots_v],
                "control": patch.surface.control.tolist(),
            }
            for patch in solid.patches
        ],
    }


def _dumps(data: dict) -> str:
    """JSON text with one control row per line; numbers in ``repr`` precision."""
    def flat(value) -> str:
        return json.dumps(value, allow_nan=False)

    lines = ["{", f'  "format": {flat(data["format"])},', f'  "version": {flat(data["version"])},',
             '  "patches": [']
    for n, patch in enumerate(data["patches"]):
        rows = ",\n".join(f"        {flat(row)}" for row in patch["control"])
        lines += ["    {",
                  f'      "name": {flat(patch["name"])},',
                  f'      "degree": {flat(patch["degree"])},',
                  f'      "knots_u": {flat(patch["knots_u"])},',
                  f'      "knots_v": {flat(patch["knots_v"])},',
                  '      "control": [',
                  rows,
                  "      ]",
                  "    }" + ("," if n + 1 < len(data["patches"]) else "")]
    lines += ["  ]", "}"]
    return "\n".join(lines) + "\n"


def write_solid(solid: Solid, path) -> None:
    """Write ``solid`` to ``path`` atomically: a temporary file in the same folder is written,
    flushed to disk and renamed over ``path`` (readers never see a partial file)."""
    write_text_atomic(Path(path), _dumps(solid_to_dict(solid)))


# -- reading ------------------------------------------------------------------------------
def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _keys(field: str, data, expected: tuple[str, ...]) -> None:
    """``data`` is an object with exactly the ``expected`` keys."""
    prefix = f"{field}." if field else ""
    if not isinstance(data, dict):
        raise InputError(field, f"expected an object with keys {', '.join(expected)}, "
                                f"got {type(data).__name__}")
    for key in data:
        if key not in expected:
            raise InputError(f"{prefix}{key}", "unknown key")
    for key in expected:
        if key not in data:
            raise InputError(f"{prefix}{key}", "missing")


def _knots(field: str, value) -> np.ndarray:
    if not isinstance(value, list) or not all(_is_number(k) for k in value):
        raise InputError(field, "expected a list of numbers")
    return np.array(value, dtype=float)


def _degree(field: str, value) -> tuple[int, int]:
    if (not isinstance(value, list) or len(value) != 2
            or not all(isinstance(d, int) and not isinstance(d, bool) for d in value)):
        raise InputError(field, f"expected two integers [p, q], got {value!r}")
    if min(value) < 1:
        raise InputError(field, f"degrees must be >= 1, got {value!r}")
    return value[0], value[1]


def _control(field: str, value) -> np.ndarray:
    """``value`` as an (n_u, n_v, 4) array of homogeneous points with positive weights."""
    shape = "n_u lists of n_v points [wx, wy, wz, w]"
    if not isinstance(value, list) or not value:
        raise InputError(field, f"expected {shape}")
    n_v = None
    for i, row in enumerate(value):
        if not isinstance(row, list) or not row:
            raise InputError(field, f"row {i}: expected a non-empty list of points [wx, wy, wz, w]")
        if n_v is None:
            n_v = len(row)
        elif len(row) != n_v:
            raise InputError(field, f"row {i} has {len(row)} points, row 0 has {n_v}")
        for j, point in enumerate(row):
            if not isinstance(point, list) or len(point) != 4 or not all(_is_number(c) for c in point):
                raise InputError(field, f"point [{i}][{j}]: expected 4 numbers [wx, wy, wz, w], "
                                        f"got {point!r}")
            if not all(math.isfinite(c) for c in point):
                raise InputError(field, f"point [{i}][{j}]: must be finite, got {point!r}")
            if not point[3] > 0.0:
                raise InputError(field, f"point [{i}][{j}]: weights must be positive, got w = {point[3]!r}")
    return np.array(value, dtype=float)


def _name(field: str, value) -> str:
    if not isinstance(value, str) or not value.strip():
        raise InputError(field, "must be a non-empty string")
    bad = [c for c in _NAME_SEPARATORS if c in value]
    if bad:
        raise InputError(field, f"must not contain {' or '.join(map(repr, bad))} (got {value!r})")
    return value


def _patch(data) -> Patch:
    _keys("", data, _PATCH_KEYS)
    name = _name("name", data["name"])
    degree = _degree("degree", data["degree"])
    knots_u = _knots("knots_u", data["knots_u"])
    knots_v = _knots("knots_v", data["knots_v"])
    control = _control("control", data["control"])
    return Patch(name, NurbsSurface(degree, knots_u, knots_v, control))


def solid_from_dict(data) -> Solid:
    """The solid a parsed NURBS JSON document describes (structure and every patch validated;
    watertightness is not checked here, :func:`read_solid` does it)."""
    _keys("", data, _TOP_KEYS)
    if data["format"] != FORMAT:
        raise InputError("format", f"expected {FORMAT!r}, got {data['format']!r}")
    version = data["version"]
    if isinstance(version, bool) or not isinstance(version, int) or version != VERSION:
        raise InputError("version", f"unsupported version {version!r} (this reader knows {VERSION})")
    patches = data["patches"]
    if not isinstance(patches, list) or not patches:
        raise InputError("patches", "expected a non-empty list of patches")
    solid = []
    for i, entry in enumerate(patches):
        try:
            solid.append(_patch(entry))
        except InputError as err:
            raise err.within(f"patches[{i}]") from None
    return Solid(tuple(solid))


class _DuplicateKey(Exception):
    pass


def _no_duplicates(pairs: list[tuple[str, object]]) -> dict:
    out = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def read_solid(path) -> Solid:
    """Read a NURBS JSON file and check that it is a closed, outward-oriented solid."""
    path = Path(path)
    field = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(field, "no such file") from None
    except UnicodeDecodeError:
        raise InputError(field, "not a UTF-8 text file") from None
    except OSError as err:
        raise InputError(field, f"cannot read: {err.strerror or err}") from None
    try:
        data = json.loads(text, object_pairs_hook=_no_duplicates)
    except json.JSONDecodeError as err:
        raise InputError(field, f"invalid JSON at line {err.lineno}, column {err.colno}: {err.msg}") from None
    except _DuplicateKey as err:
        raise InputError(field, f"invalid JSON: key {err.args[0]!r} appears twice in one object") from None
    solid = solid_from_dict(data)
    check_watertight(solid)
    return solid
