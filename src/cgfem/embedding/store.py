"""A folder of embeddings already built, so that runs on the same geometry and grid share one.

:func:`embed` is deterministic: the same solid, grid, boundary quadrature and degree give the
same rules, bit for bit, whatever the contact surface definition that asks (``nurbs_fe`` and
``nurbs_fit`` share the NURBS quadrature) and however many threads build them. An
:class:`EmbeddingStore` keeps each embedding it builds in a file named by a digest of those
inputs and of the source of the code that builds it (:func:`embedding_key`), together with
its reduced boundary rule (:attr:`~cgfem.embedding.quadrature.Embedding.boundary`), and a
later run with the same inputs loads it instead: the embedding is the most expensive part of
a NURBS run's set-up (several seconds per body at the finer levels and with triquadratic
elements), and a study that varies anything but the geometry and grid (the surface
definition, the loads, the solver) repeats it identically.

Files are written as :mod:`cgfem.atomic` writes (a temporary name, flushed, renamed), so a
reader sees a whole file or none, and processes that build the same embedding at once each
write the same bytes. A file that does not load (truncated, another format) is built again
and replaced. A change of any module the embedding depends on changes the key, so a stale
file is never read; old files are not removed (delete the folder to reclaim the space).
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import zipfile
from pathlib import Path
from typing import Any, Callable

import numpy as np

from cgfem._numba_cache import source_digest
from cgfem.atomic import fsync, new_temporary
from cgfem.embedding.facets import FacetSurface
from cgfem.embedding.grid import CartesianGrid
from cgfem.embedding.moments import VolumeRule
from cgfem.embedding.partition import SurfaceQuadrature
from cgfem.embedding.quadrature import Embedding
from cgfem.geometry.solid import Solid

#: the file layout's version (part of every key)
FORMAT = 1
#: the modules whose source, with everything they import from the package, builds an embedding
BUILDERS = ("cgfem.embedding.quadrature", "cgfem.embedding.reduce")
_ARRAY_RULES = {"volume": VolumeRule, "surface": SurfaceQuadrature, "boundary": SurfaceQuadrature,
                "facets": FacetSurface}


def embedding_key(solid: Solid, grid: CartesianGrid, quadrature: str, degree: int) -> str:
    """The hex digest that names the embedding of ``solid`` (its patches' names, degrees,
    knots and control points) in ``grid`` (``h``, ``origin``, ``shape``) with the boundary
    ``quadrature`` (``nurbs`` or ``facets``) and rules exact to ``degree``, built by the
    current source of :data:`BUILDERS`."""
    h = hashlib.sha256()
    h.update(repr((FORMAT, quadrature, int(degree), grid.h, grid.origin, grid.shape)).encode())
    for name in BUILDERS:
        h.update(source_digest(name).encode())
    for patch in solid.patches:
        s = patch.surface
        h.update(repr((patch.name, tuple(s.degree))).encode())
        for array in (s.knots_u, s.knots_v, s.control):
            a = np.ascontiguousarray(array, dtype=np.float64)
            h.update(repr(a.shape).encode())
            h.update(a.tobytes())
    return h.hexdigest()


def _pack(emb: Embedding) -> dict[str, np.ndarray]:
    """The arrays of ``emb`` and of its reduced boundary rule, by ``part.field`` name."""
    out: dict[str, np.ndarray] = {
        "status": emb.status, "fallback": emb.fallback, "degree": np.asarray(emb.degree),
        "patch_names": np.asarray(emb.patch_names, dtype=str),
        "grid": np.asarray([emb.grid.h, *emb.grid.origin, *emb.grid.shape], dtype=np.float64)}
    for part in _ARRAY_RULES:
        rule = getattr(emb, part)          # ``boundary`` is built here if it was not yet
        if rule is not None:
            out.update({f"{part}.{f.name}": getattr(rule, f.name) for f in dataclasses.fields(rule)})
    return out


def _unpack(arrays: Any, definition: str) -> Embedding:
    """The embedding :func:`_pack` stored, for the surface ``definition``."""
    g = arrays["grid"]
    grid = CartesianGrid(float(g[0]), tuple(g[1:4]), tuple(int(n) for n in g[4:7]))
    rules = {}
    for part, cls in _ARRAY_RULES.items():
        names = [f.name for f in dataclasses.fields(cls)]
        if f"{part}.{names[0]}" in arrays:
            rules[part] = cls(**{n: arrays[f"{part}.{n}"] for n in names})
    emb = Embedding(grid, arrays["status"], rules["volume"], rules["surface"],
                    tuple(str(n) for n in arrays["patch_names"]), arrays["fallback"], rules.get("facets"),
                    definition, int(arrays["degree"]))
    emb.__dict__["boundary"] = rules["boundary"]     # the cached property, as built
    return emb


class EmbeddingStore:
    """Embeddings kept in ``folder`` (created on the first write), one ``.npz`` per key;
    ``log`` hears of a file that could not be written."""

    def __init__(self, folder: str | os.PathLike[str], log: Callable[[str], None] = lambda m: None) -> None:
        self.folder = Path(folder)
        #: where a file that cannot be written is reported (the run goes on without it)
        self.log = log
        #: embeddings :meth:`get` loaded instead of building them
        self.loaded = 0

    def path(self, key: str) -> Path:
        return self.folder / f"{key}.npz"

    def load(self, key: str, definition: str) -> Embedding | None:
        """The stored embedding of ``key`` for ``definition``, or None if there is none or its
        file does not load."""
        try:
            with np.load(self.path(key), allow_pickle=False) as arrays:
                return _unpack({k: arrays[k] for k in arrays.files}, definition)
        except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile, EOFError):
            return None         # none (FileNotFoundError), or truncated, or of another layout

    def save(self, key: str, emb: Embedding) -> None:
        """Store ``emb`` (its reduced boundary rule built first) under ``key``, atomically."""
        arrays = _pack(emb)
        self.folder.mkdir(parents=True, exist_ok=True)
        target = self.path(key)
        tmp = new_temporary(target)
        try:
            with open(tmp, "wb") as f:
                np.savez(f, **arrays)
            fsync(tmp)
            os.replace(tmp, target)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise

    def get(self, key: str, definition: str, build: Callable[[], Embedding]) -> Embedding:
        """The embedding of ``key`` for ``definition``: loaded (counted in :attr:`loaded`), or
        ``build()`` and stored."""
        emb = self.load(key, definition)
        if emb is not None:
            self.loaded += 1
            return emb
        emb = build()
        try:
            self.save(key, emb)
        except OSError as err:
            self.log(f"warning: embedding not kept in {self.folder}: {err.strerror or err}")
        return emb
