"""The solver's policy (its tuning constants) and the load stepping with cut-backs."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from cgfem.solve.policy import DEFAULT_POLICY, SolverPolicy, changed, fallback_policies, policy_with
from cgfem.solve.static import StepControl, predict


@pytest.mark.parametrize("change", [{"acceleration": "broyden"}, {"predictor": "quadratic"}, {"forcing": -0.1},
                                    {"floating_step": math.nan}, {"damping_max": 0.5}, {"krylov_refresh": True}])
def test_policy_refuses_values_that_mean_nothing(change):
    with pytest.raises(ValueError):
        replace(DEFAULT_POLICY, **change)


def test_policy_is_frozen_and_its_infinite_onset_turns_the_limit_off():
    policy = SolverPolicy(onset_penetration=math.inf)
    with pytest.raises(AttributeError):
        policy.forcing = 0.5
    assert policy.onset_penetration == math.inf and DEFAULT_POLICY.onset_penetration == 0.1


def test_policy_settings_are_read_as_their_constants_types():
    """``cgfem run --policy NAME=VALUE``: a float, an int (also written 1e5), a choice; the
    summary records exactly what differs from the defaults."""
    policy = policy_with(["floating_turn = 0.05", "krylov_min_dofs=1e5", "floating_search=energy"])
    assert policy.floating_turn == 0.05 and policy.krylov_min_dofs == 100_000
    assert isinstance(policy.krylov_min_dofs, int) and policy.floating_search == "energy"
    assert changed(policy) == {"floating_turn": 0.05, "krylov_min_dofs": 100_000, "floating_search": "energy"}
    assert changed(policy_with([])) == {} and policy_with([]) == DEFAULT_POLICY
    # a limit turned off is recorded as JSON can hold it (summary.json)
    off = changed(replace(DEFAULT_POLICY, floating_turn=math.inf))
    assert off == {"floating_turn": "inf"}
    json.dumps(off, allow_nan=False)
    assert policy_with(["floating_rotation=inf"]).floating_rotation == math.inf


@pytest.mark.parametrize("setting, says", [("floating_turn", "name=value"), ("floating_turn=", "name=value"),
                                           ("no_such=1", "no_such is not"), ("krylov_min_dofs=1.5", "an integer"),
                                           ("forcing=x", "a number"), ("forcing=-1", "forcing must be"),
                                           ("floating_search=fast", "floating_search must be")])
def test_policy_settings_that_mean_nothing_are_refused_by_name(setting, says):
    with pytest.raises(ValueError, match=says):
        policy_with([setting])


def test_fallbacks_are_groups_of_settings_tried_in_order():
    """Each group changes the run's own constants (not the groups before it); a group that
    changes nothing is no fallback, and without a floating body neither is one that changes
    only the floating bodies' constants (it would repeat the attempt that failed)."""
    policy = policy_with(["floating_turn=0.05", "fallbacks=floating_search=energy; "
                          "floating_turn=0.02, acceleration=anderson; floating_search=residual"])
    found = fallback_policies(policy)
    assert [n for n, _ in found] == [1, 2]
    own = replace(policy, fallbacks="none")
    assert changed(found[0][1], own) == {"floating_search": "energy"}
    assert changed(found[1][1], own) == {"floating_turn": 0.02, "acceleration": "anderson"}
    assert all(p.fallbacks == "none" for _, p in found)
    assert [n for n, _ in fallback_policies(policy, floating=False)] == [2]
    assert fallback_policies(replace(DEFAULT_POLICY, fallbacks="none")) == []
    # the default: the energy line search with the floating bodies' shift raised, without,
    # and with the shift raised further
    assert [changed(p, replace(DEFAULT_POLICY, fallbacks="none")) for _, p in fallback_policies(DEFAULT_POLICY)] \
        == [{"floating_search": "energy", "floating_shift": 1e-6}, {"floating_search": "energy"},
            {"floating_search": "energy", "floating_shift": 1e-5}]
    assert fallback_policies(DEFAULT_POLICY, floating=False) == []


@pytest.mark.parametrize("text, says", [("floating_turn=x", "floating_turn must be a number"),
                                        ("fallbacks=none", "cannot set fallbacks"),
                                        ("energy", "'energy' is not name=value"),
                                        ("floating_search=fast", "floating_search must be one of")])
def test_fallbacks_that_mean_nothing_are_refused_by_name(text, says):
    with pytest.raises(ValueError, match=f"^fallbacks: .*{says}"):
        replace(DEFAULT_POLICY, fallbacks=text)


def run_steps(steps: int, max_cutbacks: int, largest: float) -> tuple[list[float], bool]:
    """The load factors :class:`StepControl` reaches when every increment larger than
    ``largest`` fails; and whether it reached the end."""
    control, taken = StepControl(steps, max_cutbacks), []
    while (t := control.next()) is not None:
        if t - control.t > largest + 1e-12:
            if not control.cut_back():
                return taken, False
            continue
        control.accept(t)
        taken.append(t)
    return taken, True


def test_step_control_halves_a_failed_increment_and_keeps_the_size_that_succeeded():
    """Two steps of 0.5 where increments above 0.2 fail: each step is halved twice and then
    reached in sub-steps of 0.125 (not halved again after a success); the size starts again
    at the step's own in the second step. One cut-back is not enough: the run stops at once."""
    taken, done = run_steps(2, 2, 0.2)
    assert done and taken == pytest.approx([0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0])
    assert run_steps(2, 1, 0.2) == ([], False)
    assert run_steps(4, 0, 0.25) == (pytest.approx([0.25, 0.5, 0.75, 1.0]), True)


def test_step_control_restarts_a_step_from_its_start_at_full_size():
    """A fallback's attempt: the step again from where it started, at the step's own size,
    with every cut-back again; the step is reached only at its end."""
    control = StepControl(1, 2)
    assert control.next() == 1.0 and control.cut_back() and control.next() == 0.5
    control.accept(0.5)
    assert not control.step_reached()
    assert control.next() == 1.0 and control.cut_back() and control.next() == 0.75
    assert not control.cut_back()
    control.restart(0.0)
    assert control.next() == 1.0 and control.cut_back() and control.next() == 0.5
    assert control.cut_back() and control.next() == 0.25 and not control.cut_back()
    control.restart(0.0)
    control.accept(control.next())
    assert control.step_reached() and control.next() is None


def test_secant_predictor_is_exact_on_a_linear_path():
    u0, u1 = np.array([0.0, 1.0]), np.array([0.5, 2.0])      # u(t) = (t, 1 + 2 t) at 0, 0.5
    np.testing.assert_allclose(predict("secant", 0.5, u1, (0.0, u0), 0.75), [0.75, 2.5])
    assert predict("none", 0.5, u1, (0.0, u0), 0.75) is None
    assert predict("secant", 0.5, u1, None, 0.75) is None
