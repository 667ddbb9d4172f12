"""The body-fitted torus reference (cgfem.reference.tori_solve) on its coarsest meshes:
its own equilibrium, and a Hertz contact against the closed form.

Both solve a whole problem with NGSolve (tens of seconds on one core): marked slow.
"""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

pytest.importorskip("ngsolve")

from cgfem.case import DisplacementBC, Material, load_case  # noqa: E402
from cgfem.case.expressions import as_expression  # noqa: E402
from cgfem.reference.tori import PENALTY_FACTOR  # noqa: E402
from cgfem.reference.tori_geometry import MeshSpec, mesh_level  # noqa: E402
from cgfem.reference.tori_solve import ToriProblem, solve  # noqa: E402
from tests.support.paths import CASES  # noqa: E402

PULLED, CLAMPED = "link_b/cap_a+cap_b", "link_a/cap_a+cap_b"


@pytest.mark.slow
def test_chain3_on_the_coarsest_mesh_is_in_equilibrium():
    """chain3 (the middle link held by contact alone) on reference mesh 0: every link's
    support forces balance the contact forces on it to 1e-8 of the load, the chain is in
    tension, and the spring that held the middle link while contact closed is gone."""
    case = load_case(CASES / "chain3.yaml")
    # a tenth of the references' penalty: the balance is a property of any penalty, and
    # the softer one keeps the round-off of the residual (about 2e-9 here) further below 1e-8
    solution = solve(case, mesh_level(0), PENALTY_FACTOR / 10)
    assert solution.converged, solution.message
    step = solution.steps[-1]
    pulled, clamped = step.reactions[PULLED][1], step.reactions[CLAMPED][1]
    lower, upper = step.contact["link_c/link_a"], step.contact["link_b/link_c"]
    load = abs(pulled)
    assert pulled > 1e3 and clamped < -1e3                   # tension through the chain
    assert abs(pulled + upper["force"][1]) <= 1e-8 * load     # link_b: support + link_c on it
    assert abs(clamped + lower["on_master"][1]) <= 1e-8 * load  # link_a: support + link_c on it
    assert abs(lower["force"][1] + upper["on_master"][1]) <= 1e-8 * load  # link_c: a and b on it
    assert abs(pulled + clamped) <= 1e-8 * load
    assert step.equilibrium <= 1e-8
    # the spring that held link_c until contact closed would carry this much were it still
    # there: far above the 1e-8 the balance of link_c above allows, so the balance shows it gone
    assert step.spring_force["link_c"] > 1e-5 * load


def _hertz_case(displacement: float):
    """chain2_steel in small strain, linear elastic steel, one step of ``displacement``."""
    case = load_case(CASES / "chain2_steel.yaml")
    bodies = tuple(replace(b, material=Material("linear_elastic", b.material.E, b.material.nu))
                   for b in case.bodies)
    boundary = tuple(replace(bc, components=tuple((c, as_expression(displacement if c == 1 and bc.body == "link_b"
                                                                    else 0.0)) for c, _ in bc.components))
                     for bc in case.boundary)
    assert all(isinstance(bc, DisplacementBC) for bc in boundary)
    return replace(case, kinematics="small", steps=1, bodies=bodies, boundary=boundary)


@pytest.mark.slow
def test_crossed_tori_under_a_small_load_follow_hertz():
    """Two links pressed together a little: the tubes touch at their inner equators, where
    both surfaces have the principal curvatures 1/r and -1/(R - r) in crossed planes, so the
    contact is Hertz's circle with the equivalent radius R* = 1 / (1/r - 1/(R - r)) and
    E* = E / (2 (1 - nu^2)): a^3 = 3 F R* / (4 E*). The contact radius is measured from the
    second moment of the contact pressure (Hertz: <rho^2> = 2 a^2 / 5) and matches to 2 %;
    the reported extent of the contact zone lies between ``a`` and the refined radius."""
    import ngsolve as ng

    case = _hertz_case(4.0e-5)
    R, r = 0.02, 0.005
    E, nu = case.bodies[0].material.E, case.bodies[0].material.nu
    # a (about 0.47 mm) spans three contact elements; the pipeline's penalty factor
    problem = ToriProblem(case, MeshSpec(h=0.004, h_contact=1.5e-4, r_contact=8e-4), PENALTY_FACTOR)
    solution = problem.run()
    assert solution.converged, solution.message
    force = -problem.contact_work("link_b/link_a", ng.CF((0.0, 1.0, 0.0)))
    moment = -problem.contact_work("link_b/link_a", ng.CF((0.0, ng.x * ng.x + ng.z * ng.z, 0.0)))
    assert force == pytest.approx(solution.steps[-1].reactions[PULLED][1], rel=1e-8)
    a = math.sqrt(2.5 * moment / force)
    r_star, e_star = 1.0 / (1.0 / r - 1.0 / (R - r)), E / (2.0 * (1.0 - nu * nu))
    a_hertz = (3.0 * force * r_star / (4.0 * e_star)) ** (1.0 / 3.0)
    assert a / r < 0.15                                        # small against the tube: Hertz applies
    assert a == pytest.approx(a_hertz, rel=0.02)
    # the contact zone's reported extent holds Hertz's circle and lies in the refined ball
    extent = solution.steps[-1].contact_extent["link_b/link_a"]
    assert a_hertz <= extent <= problem.spec.r_contact
