"""A contact pair repeats its last search only where nothing the search depends on changed
(:meth:`cgfem.contact.pair.ContactPair.search`): the same kinematic vectors, recorded
pairing, Verlet list, polishing and held pieces. Any of them changed, the search runs again
and gives what a pair without the memo gives."""
from __future__ import annotations

import numpy as np
import pytest

from cgfem.case import load_case
from cgfem.run import build_bodies, build_pairs
from tests.support.paths import CASES


@pytest.fixture()
def pair_and_state():
    """The planar example's pair at level 0 (``nurbs_fe``), its kinematic vectors pressing the
    lower block 1 um into the upper one, and a counter of the master surface's searches."""
    case = load_case(CASES / "planar.yaml")
    models, _, solids = build_bodies(case, 0, "nurbs_fe", lambda m: None)
    pair = build_pairs(case, models, solids, "nurbs_fe", lambda m: None)[0]
    u_s = np.zeros(models[pair.slave].n_dofs)
    u_s[2::3] = 1e-6
    u_m = np.zeros(models[pair.master].n_dofs)
    calls = []
    search = pair.surface.search

    def counted(*args, **kwargs):
        calls.append(1)
        return search(*args, **kwargs)
    pair.surface.search = counted
    pair.begin_pass(increment=True)     # the held pieces' counts exist, as in a solve
    return pair, u_s, u_m, calls


def _fresh(pair, u_s, u_m):
    """The search of ``pair`` at ``(u_s, u_m)`` without its memo (the memo put back after)."""
    memo, pair._memo = pair._memo, None
    try:
        return pair.search(u_s, u_m)
    finally:
        pair._memo = memo


def _assert_same_hits(a, b) -> None:
    for name in ("found", "piece", "theta", "g", "slot"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_the_same_search_is_not_repeated(pair_and_state):
    pair, u_s, u_m, calls = pair_and_state
    st, hits = pair.search(u_s, u_m)
    assert hits.found.sum() > 0 and len(calls) == 1
    # what the onset limit's gaps and then the residual at the same point ask for
    gaps = pair.gaps(u_s.copy(), u_m.copy())
    again = pair.search(u_s.copy(), u_m.copy())
    assert len(calls) == 1 and again[1] is hits and again[0] is st
    np.testing.assert_array_equal(gaps, np.where(hits.found, hits.g, np.nan))
    _assert_same_hits(_fresh(pair, u_s, u_m)[1], hits)


@pytest.mark.parametrize("change", ["u_s", "u_m", "pairing", "held", "polish"])
def test_a_changed_input_searches_again(pair_and_state, change):
    pair, u_s, u_m, calls = pair_and_state
    first = pair.search(u_s, u_m)[1]
    if change == "u_s":
        u_s = u_s.copy()
        u_s[2::3] += 1e-7
    elif change == "u_m":
        u_m = u_m.copy()
        u_m[0] += 1e-9
    elif change == "pairing":       # a Newton iterate records its pairing
        pair.assemble(u_s, u_m, False)
    elif change == "held":          # a piece held (its returns counted in place)
        pair.state.returns[np.flatnonzero(first.found)[0]] += 10 ** 6
    else:
        pair.surface.polish = True
    before = len(calls)
    st, hits = pair.search(u_s, u_m)
    assert len(calls) == before + 1 and hits is not first
    _assert_same_hits(_fresh(pair, u_s, u_m)[1], hits)
