"""The embedding store (:mod:`cgfem.embedding.store`): a stored embedding is the built one, bit
for bit, and is found exactly where the inputs that build it are the same."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from cgfem.case.model import Body, GridSpec, Material
from cgfem.embedding.quadrature import Embedding, embed, grid_for
from cgfem.embedding.store import EmbeddingStore, embedding_key
from cgfem.geometry.builders import build_solid
from cgfem.geometry.specs import BoxSpec, SphereSpec
from cgfem.run import embed_body

SPHERE = SphereSpec(center=(0.0, 0.0, 0.0), radius=0.01)
OFFSET = (0.13, 0.29, 0.41)


def _body(spec=SPHERE, h0: float = 0.008, offset=OFFSET) -> Body:
    return Body("ball", spec, Material("linear_elastic", 1.0e9, 0.3), GridSpec(h0, offset))


def _arrays(emb: Embedding) -> dict[str, np.ndarray]:
    """Every array of ``emb``, its reduced boundary rule's included."""
    out = {"status": emb.status, "fallback": emb.fallback}
    for part in ("volume", "surface", "boundary", "facets"):
        rule = getattr(emb, part)
        if rule is not None:
            out.update({f"{part}.{f.name}": getattr(rule, f.name) for f in dataclasses.fields(rule)})
    return out


def _assert_same(a: Embedding, b: Embedding) -> None:
    assert a.grid == b.grid and a.patch_names == b.patch_names and a.degree == b.degree
    x, y = _arrays(a), _arrays(b)
    assert x.keys() == y.keys()
    for name in x:
        assert x[name].dtype == y[name].dtype and x[name].shape == y[name].shape, name
        assert np.array_equal(x[name], y[name]), name     # bit for bit (no NaN in a rule)


@pytest.mark.parametrize("quadrature, degree", [("nurbs", 2), ("facets", 2), ("nurbs", 4)])
def test_a_stored_embedding_loads_as_built(tmp_path, quadrature, degree):
    solid = build_solid(SPHERE)
    grid = grid_for(solid, 0.008, 0, OFFSET)
    built = embed(solid, grid, quadrature, degree=degree)
    store = EmbeddingStore(tmp_path / "store")
    key = embedding_key(solid, grid, quadrature, degree)
    assert store.load(key, built.definition) is None
    store.save(key, built)
    loaded = store.load(key, "something else")
    assert loaded is not None and loaded.definition == "something else"
    _assert_same(loaded, built)
    assert (loaded.facets is None) == (quadrature == "nurbs")
    assert [p.name for p in (tmp_path / "store").iterdir()] == [f"{key}.npz"]   # no temporary left


def test_the_nurbs_definitions_share_an_embedding_and_nothing_else_does(tmp_path):
    body = _body()
    solid = build_solid(body.geometry)
    store = EmbeddingStore(tmp_path)
    first = embed_body(solid, body, 0, "nurbs_fe", store=store)
    assert store.loaded == 0 and first.definition == "nurbs_fe"
    second = embed_body(solid, body, 0, "nurbs_fit", store=store)
    assert store.loaded == 1 and second.definition == "nurbs_fit"
    _assert_same(second, embed_body(solid, body, 0, "nurbs_fit"))
    # another quadrature, level, degree, grid offset or geometry: built, not loaded
    embed_body(solid, body, 0, "facets", store=store)
    embed_body(solid, body, 1, "nurbs_fe", store=store)
    embed_body(solid, body, 0, "nurbs_fe", order=2, store=store)
    moved = _body(offset=(0.14, 0.29, 0.41))
    embed_body(solid, moved, 0, "nurbs_fe", store=store)
    bigger = _body(SphereSpec(center=(0.0, 0.0, 0.0), radius=0.0101))
    embed_body(build_solid(bigger.geometry), bigger, 0, "nurbs_fe", store=store)
    assert store.loaded == 1 and len(list(tmp_path.glob("*.npz"))) == 6


def test_the_key_follows_the_source_of_the_code_that_builds(monkeypatch):
    import cgfem.embedding.store as store_module

    solid = build_solid(SPHERE)
    grid = grid_for(solid, 0.008, 0, OFFSET)
    key = embedding_key(solid, grid, "nurbs", 2)
    assert embedding_key(solid, grid, "nurbs", 2) == key
    real = store_module.source_digest
    monkeypatch.setattr(store_module, "source_digest",
                        lambda name: real(name) + ("x" if name == "cgfem.embedding.reduce" else ""))
    assert embedding_key(solid, grid, "nurbs", 2) != key


def test_a_file_that_does_not_load_is_built_again(tmp_path):
    body = _body(BoxSpec(min=(0.0, 0.0, 0.0), max=(0.01, 0.01, 0.01)))
    solid = build_solid(body.geometry)
    store = EmbeddingStore(tmp_path)
    built = embed_body(solid, body, 0, "nurbs_fe", store=store)
    (path,) = tmp_path.glob("*.npz")
    path.write_bytes(path.read_bytes()[:100])          # a truncated file
    again = embed_body(solid, body, 0, "nurbs_fe", store=store)
    assert store.loaded == 0
    _assert_same(again, built)
    assert store.load(path.stem, "nurbs_fe") is not None     # replaced by a whole one


def test_a_folder_that_cannot_be_written_costs_the_store_not_the_run(tmp_path):
    body = _body(BoxSpec(min=(0.0, 0.0, 0.0), max=(0.01, 0.01, 0.01)))
    (tmp_path / "file").write_text("not a folder")
    said: list[str] = []
    store = EmbeddingStore(tmp_path / "file" / "store", said.append)
    emb = embed_body(build_solid(body.geometry), body, 0, "nurbs_fe", store=store)
    assert emb.volume.w.size > 0
    assert len(said) == 1 and said[0].startswith("warning: embedding not kept in ")


@pytest.mark.slow
def test_a_run_with_the_store_writes_what_a_run_without_it_writes(tmp_path):
    """Two runs of a small contact case with the two NURBS definitions through the CLI: the
    second loads both bodies' embeddings, and its summary (less the timings) and every result
    file are those of the same run without the store."""
    from cgfem.cli import main
    from tests.support.paths import CASES

    case = str(CASES / "planar.yaml")
    store = tmp_path / "store"
    common = [case, "--level", "0", "--quiet"]
    assert main(["run", *common, "--surface", "nurbs_fe", "--out", str(tmp_path / "fe"),
                 "--embedding-cache", str(store)]) == 0
    assert main(["run", *common, "--surface", "nurbs_fit", "--out", str(tmp_path / "cached"),
                 "--embedding-cache", str(store)]) == 0
    assert main(["run", *common, "--surface", "nurbs_fit", "--out", str(tmp_path / "plain")]) == 0
    assert len(list(store.glob("*.npz"))) == 2      # the two blocks, shared by both runs
    cached, plain = tmp_path / "cached", tmp_path / "plain"
    assert sorted(p.name for p in cached.iterdir()) == sorted(p.name for p in plain.iterdir())
    for path in plain.iterdir():
        if path.name != "summary.json":
            assert path.read_bytes() == (cached / path.name).read_bytes(), path.name
    a, b = (json.loads((d / "summary.json").read_text()) for d in (cached, plain))
    for s in (a, b):
        for key in ("timings", "versions", "threads"):
            s.pop(key)
        for step in s["steps"]:
            step.pop("seconds")
    assert a == b


def test_a_store_that_is_a_file_is_bad_input(tmp_path, capsys):
    from cgfem.cli import main
    from tests.support.paths import CASES

    (tmp_path / "store").write_text("")
    code = main(["run", str(CASES / "planar.yaml"), "--level", "0", "--surface", "nurbs_fe",
                 "--out", str(tmp_path / "out"), "--embedding-cache", str(tmp_path / "store")])
    assert code == 2 and not (tmp_path / "out").exists()
    err = capsys.readouterr().err.strip()
    assert err.startswith("cgfem: error: --embedding-cache") and "\n" not in err
