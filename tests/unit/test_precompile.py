"""cgfem.precompile: the manifest of the package's kernels, its shares and their compilation,
and ``cgfem warmup --share`` / ``--record`` at the command line."""

from __future__ import annotations

import json

import numba
import numpy as np
import pytest
from numba.core import types

from cgfem.cli import main
from cgfem.precompile import (Entry, callees, compile_share, depths, format_types, package_kernels,
                              parallel_versions, parse_types, read_manifest, resolve, share, write_manifest)

RECORD = "cgfem warmup --record src/cgfem/kernels.tsv"


@numba.njit
def _twice(x):
    return 2.0 * x


def test_the_manifest_lists_every_kernel_of_the_package_and_no_other():
    kernels = package_kernels()
    listed = {e.kernel for e in read_manifest()}
    assert len(kernels) > 100
    assert not set(kernels) - listed, f"kernels missing from the manifest: run `{RECORD}`"
    assert not listed - set(kernels), f"the manifest names kernels that do not exist: run `{RECORD}`"
    assert all(resolve(name) is kernels[name] for name in kernels)


def test_the_manifest_types_read_back_and_the_recorded_seconds_add_up():
    entries = read_manifest()
    typed = [e for e in entries if e.argtypes]
    assert len(typed) > 100
    for entry in typed:
        assert format_types(parse_types(entry.argtypes)) == entry.argtypes
    # the warm-up compiles for one to a few minutes, on one thread: of a parallel kernel
    # (cgfem._parallel) the serial twin only
    assert 20.0 < sum(e.seconds for e in typed) < 600.0
    assert all(e.seconds >= 0.0 for e in entries)
    names = {e.kernel for e in typed}
    assert any(name.endswith("_serial") for name in names)
    assert not {name for name in names if f"{name}_serial" in names}


def test_types_of_every_kind_the_kernels_take_read_back():
    from cgfem.geometry.bvh import BvhArrays

    frozen = np.zeros((2, 3))
    frozen.setflags(write=False)
    args = (numba.typeof(BvhArrays(*[frozen] * len(BvhArrays._fields))), types.Array(types.int32, 1, "F"),
            types.int64, types.float64, types.boolean, types.UniTuple(types.float64, 3),
            numba.typeof((np.zeros(3), 1.0)), types.none)
    assert parse_types(format_types(args)) == args
    with pytest.raises(TypeError, match="no manifest form"):
        format_types((types.unicode_type,))
    with pytest.raises(ValueError, match="not a tuple"):
        parse_types("float64")


def test_a_kernel_lies_deeper_in_the_call_graph_than_its_callees():
    kernels = package_kernels()
    depth = depths(sorted(kernels))
    # by a global name, and as an attribute of an imported module
    assert callees(kernels["cgfem.embedding._column_kernels:column_rules_serial"]) >= {
        "cgfem.embedding._column_kernels:recombine_checked", "cgfem.embedding._cone_kernels:cone_rule"}
    called = [(name, c) for name in kernels for c in callees(kernels[name])]
    assert len(called) > 50
    assert all(depth[name] > depth[c] for name, c in called)
    assert min(depth.values()) == 0 and max(depth.values()) >= 4


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_the_shares_partition_the_typed_entries_by_depth_and_balance_them(n):
    entries = read_manifest()
    typed = [e for e in entries if e.argtypes]
    depth = depths(sorted({e.kernel for e in typed}))
    shares = [share(entries, k, n) for k in range(1, n + 1)]
    assert sorted((typed.index(e) for s in shares for e in s)) == list(range(len(typed)))
    for s in shares:           # by depth, then in the manifest's order
        assert [(depth[e.kernel], typed.index(e)) for e in s] == sorted((depth[e.kernel], typed.index(e)) for e in s)
    # list scheduling: no share exceeds the mean by more than the largest entry
    loads = [sum(e.seconds for e in s) for s in shares]
    assert max(loads) <= sum(loads) / n + max(e.seconds for e in typed) + 1e-9
    with pytest.raises(ValueError, match="1 <= k <= n"):
        share(entries, n + 1, n)


def test_a_share_compiles_its_versions_and_skips_stale_entries():
    name = f"{__name__}:_twice"
    entries = [Entry(name, "(float64, )", 1.0), Entry(f"{__name__}:_gone", "(float64, )", 1.0),
               Entry(name, "(Array(float64, 1, 'C', False), Array(float64, 1, 'C', False), )", 1.0),
               Entry(name, "", 0.0)]
    assert resolve(name) is _twice and _twice.signatures == []
    report = compile_share(1, 1, entries)
    assert report.compiled == 1 and _twice.signatures == [(types.float64,)]
    assert [s.split(":")[1] for s in report.skipped] == ["_gone", "_twice"]
    assert "no such kernel" in report.skipped[0] and "Signature mismatch" in report.skipped[1]
    # the second of two shares gets the entries the first did not
    assert [e.kernel for e in share(entries, 2, 2)] == [f"{__name__}:_gone"]


def test_the_parallel_versions_are_the_twins_kernels_with_the_twins_types():
    entries = read_manifest()
    twins = {e.kernel: e for e in entries if e.argtypes and e.kernel.endswith("_serial")}
    versions = parallel_versions(entries)
    assert len(versions) == len(twins) > 5
    for entry in versions:
        twin = twins[f"{entry.kernel}_serial"]
        assert (entry.argtypes, entry.seconds) == (twin.argtypes, twin.seconds)
        parallel, serial = resolve(entry.kernel), resolve(twin.kernel)
        assert parallel.targetoptions.get("parallel") and not serial.targetoptions.get("parallel")
        assert parallel.py_func.__code__ is serial.py_func.__code__


def test_the_manifest_file_round_trips(tmp_path):
    entries = [Entry("a.b:c", "(int64, )", 1.25), Entry("a.b:d")]
    write_manifest(entries, tmp_path / "m.tsv")
    assert read_manifest(tmp_path / "m.tsv") == entries


@pytest.mark.parametrize("argv", [["--share", "0/2"], ["--share", "3/2"], ["--share", "two"], ["--share", "1/"],
                                  ["--share", "1/2", "--record", "x.tsv"], ["--record", "."]])
def test_bad_share_or_record_is_a_one_line_error(argv, capsys):
    assert main(["warmup", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("cgfem: error: --")


def test_warmup_share_prints_what_it_compiled(capsys):
    assert main(["warmup", "--share", "4/4"]) == 0
    out = capsys.readouterr().out
    report = json.loads(out)
    assert report["share"] == 4 and report["shares"] == 4 and report["skipped"] == []
    assert report["compiled"] == len(share(read_manifest(), 4, 4)) > 10
