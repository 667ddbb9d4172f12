"""Body-fitted NGSolve solution of a chain case on the symmetric quarter (one mesh, one penalty).

Discretization (:mod:`cgfem.reference.tori_geometry` for the geometry):

- ``VectorH1`` of order ``p >= 2`` on the curved tetrahedral mesh of all bodies (one space,
  the bodies share no vertex), ``u_x = 0`` on ``sym_x``, ``u_z = 0`` on ``sym_z``, and the
  case's prescribed displacement, times the load factor, on each ``{body}_cap``.
- Bulk energy per body, total Lagrangian: ``finite`` kinematics the project's Neo-Hookean
  ``W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2`` with ``F = I + grad u``; ``small``
  kinematics linear elasticity ``W = mu eps:eps + lam/2 (tr eps)^2``, ``eps = sym grad u``.
- Frictionless contact by penalty, for every pair of the case, with NGSolve's
  ``ContactBoundary``: at the quadrature points of the slave tube (reference area ``dA``)
  the gap ``g = (x_s - x_m) . n_s`` to the closest point ``x_m`` of the master tube, both
  in the current configuration (``x = X + u``), ``n_s`` the current outward normal of the
  slave; the energy is ``eps_c/2 <g>_+^2 dA`` with ``eps_c = penalty_factor E_slave /
  r_slave`` (N/m^3). In either kinematics the contact is on current positions (as cgFEM's).
- Newton per load step: before every iteration the closest points and ``n_s`` are searched
  again at the current state and held for that iteration (its tangent omits their
  variation), a sparse Cholesky solve, a backtracking line search on the energy. A step
  converges when the free residual is below ``tol`` times the norm of the residual on the
  prescribed dofs (the support forces), and else halves its increment (``max_cutbacks``).
- A body without supports (chain3's middle link) is held by a spring
  ``k/2 |u|^2 dV`` (``k = SPRING_FACTOR E / r^2``) until Newton converges; then the
  spring is removed and Newton continues to the spring-free equilibrium (it only removes
  the translation along y that the symmetry planes leave free, so it changes nothing
  once contact holds the body).

Reported per step (the whole chain, from the quarter by symmetry: y components times 4, x
and z components zero): the reaction (N) of every support entry, keyed like cgFEM's
``body/patch+patch`` (force of the support on the body), the contact force of every pair
(force of the master on the slave) and on the master, the equilibrium of every body
(largest resultant of its support and contact forces relative to the largest support
force), the peak von Mises stress (Pa, Cauchy) of every body on a lattice of points per
element and where it is (reference coordinates, in the quarter), also on either side of
the body's centre plane ``y = c_y``; and the extent of every pair's contact zone (m: the
largest distance, in the reference configuration, from the pair's touch point to a tube
vertex carrying contact), which tells whether the mesh's refined ball holds the zone.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from cgfem.case import Case
from cgfem.reference.tori_geometry import SYM_X, SYM_Z, MeshSpec, build_mesh, cap, touch_points, tube

__all__ = ["SYMMETRY_FACTOR", "Solution", "StepResult", "ToriProblem", "solve"]

#: the quarter carries a quarter of every force of the chain
SYMMETRY_FACTOR = 4.0
#: spring of a body without supports, k = SPRING_FACTOR E / r^2 (N/m^4), until it is held
SPRING_FACTOR = 1e-4
#: closest points are searched up to SEARCH_MAX minor radii from a slave point at the first
#: iteration of a solve; then up to SEARCH_STEP times the largest displacement change of the
#: last iteration, at least SEARCH_MIN minor radii; a converged state is confirmed, and its
#: forces evaluated, with SEARCH_FINAL minor radii (the search costs about the square of
#: its radius; converged penetrations are micrometres)
SEARCH_MAX, SEARCH_MIN, SEARCH_FINAL, SEARCH_STEP = 0.2, 0.02, 0.05, 4.0
#: contact quadrature order on the slave's surface elements: CONTACT_ORDER_PER_P * p (chain2_steel
#: at level 2: orders 4 and 6 give final reactions 2e-5 apart, order 4 in three quarters the time)
CONTACT_ORDER_PER_P = 2
#: line search: smallest step fraction, and the energy rise (relative) still accepted
MIN_STEP, ENERGY_SLACK = 2.0 ** -12, 1e-13
#: a Newton solve that stops decreasing below STALL_FACTOR times its tolerance has converged
#: to round-off
STALL_FACTOR = 1e3
#: the penalty check's Newton (a continuation to a stiffer penalty, whose tangent omits the
#: variation of the closest points) gets this many times the iterations of a load step's: it
#: converges linearly (chain2_rubber at level 2, last step: a factor 0.75 per iteration,
#: 3.7e-8 of the support forces after 40)
CHECK_ITERATIONS_FACTOR = 2
#: a tube vertex carries contact when its nodal contact force exceeds this fraction of the
#: pair's largest one (penalty pressures fade continuously to zero at the zone's edge)
CONTACT_CUTOFF = 1e-6


@dataclass
class StepResult:
    """Values of one converged load step (the whole chain; forces in N, stresses in Pa)."""

    load_factor: float
    reactions: dict[str, list[float]]
    contact: dict[str, dict]
    max_von_mises: dict[str, float]
    max_von_mises_at: dict[str, list[float]]
    max_von_mises_sides: dict[str, dict[str, list[float]]]
    equilibrium: float
    newton_iterations: int
    residual: float
    residual_reference: float
    cutbacks: int
    seconds: float
    contact_extent: dict[str, float] = field(default_factory=dict)
    spring_force: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Solution:
    """One solve: mesh numbers, penalties and the steps."""

    mesh: dict
    penalty_factor: float
    penalties: dict[str, float]
    steps: list[StepResult]
    seconds: dict[str, float]
    converged: bool
    message: str = ""
    #: the same steps with the penalty times ``check_factor``, each from this solution's
    #: converged state of the step (None unless asked for)
    check: "Solution | None" = None

    def as_dict(self) -> dict:
        return {"mesh": self.mesh, "penalty_factor": self.penalty_factor,
                "penalties": self.penalties, "seconds": self.seconds,
                "converged": self.converged, "message": self.message,
                "steps": [s.as_dict() for s in self.steps]}


def _entry_key(bc) -> str:
    return f"{bc.body}/{'+'.join(bc.patches)}"


class ToriProblem:
    """The discrete quarter problem of ``case`` on the mesh ``spec`` (see the module)."""

    def __init__(self, case: Case, spec: MeshSpec, penalty_factor: float,
                 contact_order: int | None = None):
        import ngsolve as ng

        self.ng, self.case, self.spec = ng, case, spec
        self.penalty_factor = float(penalty_factor)
        self.mesh = mesh = build_mesh(case, spec)
        self.contact_order = contact_order or CONTACT_ORDER_PER_P * spec.order
        dirichlet = {0: [SYM_X], 1: [], 2: [SYM_Z]}
        for bc in case.boundary:
            for c, _ in bc.components:
                dirichlet[c].append(cap(bc.body))
        names = {0: "dirichletx", 1: "dirichlety", 2: "dirichletz"}
        flags = {names[c]: "|".join(sorted(set(r))) for c, r in dirichlet.items() if r}
        self.fes = fes = ng.VectorH1(mesh, order=spec.order, **flags)
        self.free = np.array(fes.FreeDofs(), bool)
        self.u = ng.GridFunction(fes)
        self.n_block = fes.ndof // 3
        trial = fes.TrialFunction()
        self.bodies = {b.name: b for b in case.bodies}
        self.floating = [n for n in self.bodies if not any(bc.body == n for bc in case.boundary)]
        bulk = None
        for name in self.bodies:
            term = self._energy(trial, name).Compile() * ng.dx(definedon=mesh.Materials(name))
            bulk = term if bulk is None else bulk + term
        self.a = ng.BilinearForm(fes, symmetric=True)
        self.a += ng.Variation(bulk)
        self.a_spring = None
        if self.floating:
            self.a_spring = ng.BilinearForm(fes, symmetric=True)
            spring = bulk
            for name in self.floating:
                m = self.bodies[name].material
                k = SPRING_FACTOR * m.E / self.bodies[name].geometry.minor_radius ** 2
                spring = spring + k / 2 * ng.InnerProduct(trial, trial) * ng.dx(definedon=mesh.Materials(name))
            self.a_spring += ng.Variation(spring)
        self.penalties, self.pairs = {}, []
        self.penalty_scale = ng.Parameter(1.0)
        for pair in case.contact:
            slave = self.bodies[pair.slave]
            eps = self.penalty_factor * slave.material.E / slave.geometry.minor_radius
            key = f"{pair.slave}/{pair.master}"
            self.penalties[key] = eps
            self.pairs.append((key, pair, self._contact(trial, pair, eps), self._contact(trial, pair, eps),
                               ng.BilinearForm(fes, symmetric=True)))
        self._supports = [(bc, _entry_key(bc)) for bc in case.boundary]
        self._touch = dict(zip((key for key, *_ in self.pairs), touch_points(case)))
        self._vertex_dofs = np.array([fes.GetDofNrs(ng.NodeId(ng.VERTEX, i)) for i in range(mesh.nv)], int)
        self._vertices = np.array([v.point for v in mesh.vertices], float)
        self._prescribed = self._prescribed_vectors()

    # -- forms ------------------------------------------------------------------------------
    def _energy(self, u, name: str):
        ng = self.ng
        lam, mu = self.bodies[name].material.lame()
        if self.case.kinematics == "finite":
            F = ng.Id(3) + ng.Grad(u)
            J = ng.Det(F)
            return mu / 2 * (ng.Trace(F.trans * F) - 3) - mu * ng.log(J) + lam / 2 * ng.log(J) ** 2
        eps = ng.Sym(ng.Grad(u))
        return mu * ng.InnerProduct(eps, eps) + lam / 2 * ng.Trace(eps) ** 2

    def _contact(self, u, pair, eps: float):
        ng = self.ng
        cb = ng.ContactBoundary(self.mesh.Boundaries(tube(pair.slave)),
                                self.mesh.Boundaries(tube(pair.master)))
        X = ng.CF((ng.x, ng.y, ng.z))
        g = (X + u - (X.Other() + u.Other())) * cb.normal
        cb.AddEnergy(ng.IfPos(g, eps * self.penalty_scale / 2 * g * g, 0))
        return cb

    def stress(self, name: str, u=None):
        """Cauchy stress (3x3 CoefficientFunction, Pa) of body ``name`` at ``u`` (the solution)."""
        ng = self.ng
        u = self.u if u is None else u
        lam, mu = self.bodies[name].material.lame()
        I = ng.Id(3)
        if self.case.kinematics == "finite":
            F = I + ng.Grad(u)
            J = ng.Det(F)
            b = F * F.trans
            return (mu * (b - I) + lam * ng.log(J) * I) / J
        eps = ng.Sym(ng.Grad(u))
        return 2 * mu * eps + lam * ng.Trace(eps) * I

    # -- prescribed values and test vectors -------------------------------------------------
    def _component_mask(self, region, component: int) -> np.ndarray:
        dofs = np.array(self.fes.GetDofs(region), bool)
        mask = np.zeros_like(dofs)
        block = slice(component * self.n_block, (component + 1) * self.n_block)
        mask[block] = dofs[block]
        return mask

    def _unit(self, region, component: int) -> np.ndarray:
        """Coefficients of the unit vector field ``e_component`` set on ``region`` (zero
        elsewhere): the virtual displacement whose work on a residual is the force."""
        ng = self.ng
        e = [0.0, 0.0, 0.0]
        e[component] = 1.0
        gf = ng.GridFunction(self.fes)
        gf.Set(ng.CF(tuple(e)), definedon=region)
        return gf.vec.FV().NumPy().copy()

    def _prescribed_vectors(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(mask, values at load factor 1) of every prescribed component on a cap."""
        out = []
        for bc in self.case.boundary:
            region = self.mesh.Boundaries(cap(bc.body))
            for c, expr in bc.components:
                mask = self._component_mask(region, c)
                out.append((mask, expr.constant_value * self._unit(region, c)[mask]))
        return out

    def set_load(self, u: np.ndarray, load_factor: float) -> None:
        for mask, values in self._prescribed:
            u[mask] = load_factor * values

    # -- Newton -----------------------------------------------------------------------------
    def _update_pairs(self, form, keep: bool = False, search: float | None = None,
                      final: bool = False) -> None:
        """Search the closest points of every pair at the current ``u`` (up to ``search``
        m, default SEARCH_MAX minor radii, or SEARCH_FINAL with ``final``) and add them
        to ``form``."""
        for _, pair, cb, _, _ in self.pairs:
            r = self.bodies[pair.slave].geometry.minor_radius
            if final:
                reach = SEARCH_FINAL * r
            elif search is None:
                reach = SEARCH_MAX * r
            else:
                reach = min(max(search, SEARCH_MIN * r), SEARCH_MAX * r)
            cb.Update(self.u, form, self.contact_order, reach, keep_pairs=keep)

    def _residual(self, form) -> np.ndarray:
        res = self.u.vec.CreateVector()
        form.Apply(self.u.vec, res)
        return res.FV().NumPy().copy()

    def newton(self, form, tol: float, max_iterations: int, log: Callable[[str], None]
               ) -> tuple[bool, int, float, float]:
        """Newton on ``form`` from the current ``u``; returns (converged, iterations, final
        free residual norm, the reference it was measured against: the norm of the
        residual on the prescribed dofs, i.e. of the support forces)."""
        vec = self.u.vec
        du = vec.CreateVector()
        history, search, confirmed = [], None, False
        for it in range(max_iterations + 1):
            self._update_pairs(form, search=search)
            form.AssembleLinearization(vec)
            res = self._residual(form)
            rn = float(np.linalg.norm(res[self.free]))
            reference = float(np.linalg.norm(res[~self.free]))
            if not np.isfinite(rn):
                return False, it, rn, reference
            history.append(rn)
            stalled = (len(history) > 6 and rn > 0.5 * min(history[-6:-1])
                       and rn < STALL_FACTOR * tol * reference)
            if rn <= tol * reference or stalled:
                if search is None or confirmed:
                    return True, it, rn, reference
                # confirm with the final search radius: no deep point was left unpaired
                self._update_pairs(form, final=True)
                res = self._residual(form)
                rn = float(np.linalg.norm(res[self.free]))
                if rn <= (STALL_FACTOR * tol if stalled else tol) * reference:
                    return True, it, rn, reference
                search, confirmed = None, True
                form.AssembleLinearization(vec)
            if it == max_iterations:
                break
            inverse = form.mat.Inverse(self.fes.FreeDofs(), inverse="sparsecholesky")
            r = vec.CreateVector()
            r.FV().NumPy()[:] = np.where(self.free, res, 0.0)
            du.data = inverse * r
            e0, step = form.Energy(vec), 1.0
            while True:
                vec.data -= step * du
                e1 = form.Energy(vec)
                if np.isfinite(e1) and e1 <= e0 + ENERGY_SLACK * abs(e0):
                    break
                vec.data += step * du
                step *= 0.5
                if step < MIN_STEP:
                    vec.data -= step * du
                    break
            if not confirmed:
                search = SEARCH_STEP * step * float(np.abs(du.FV().NumPy()).max())
            log(f"    iteration {it}: residual {rn:.3e} N ({rn / max(reference, 1e-300):.1e} of the "
                f"support forces), step {step:g}")
        return False, max_iterations, history[-1], reference

    # -- one load step ----------------------------------------------------------------------
    def solve_step(self, start: float, target: float, previous: np.ndarray, tol: float,
                   max_iterations: int, max_cutbacks: int, log: Callable[[str], None]
                   ) -> tuple[bool, int, int, float, float]:
        """Move from the converged state at load factor ``start`` to ``target``, halving
        the increment on failure. ``previous`` is ``[u, load factor]`` of the converged
        state before (``[None, None]`` at the first step; updated here): the predictor
        extrapolates linearly from it. Returns (converged, iterations, cutbacks, residual,
        reference residual)."""
        u = self.u.vec.FV().NumPy()
        cutbacks, total, reached = 0, 0, start
        increment = target - start
        while reached < target - 1e-12 * abs(target):
            goal = min(target, reached + increment)
            saved = u.copy()
            scale = (goal - reached) / max(reached - previous[1], 1e-300) if previous[1] is not None else 0.0
            if previous[0] is not None and 0.0 < scale <= 2.0:
                u[self.free] += scale * (u - previous[0])[self.free]
            self.set_load(u, goal)
            forms = [self.a_spring, self.a] if self.a_spring is not None else [self.a]
            ok, rn, ref = True, 0.0, 0.0
            for form in forms:
                ok, its, rn, ref = self.newton(form, tol, max_iterations, log)
                total += its
                if not ok:
                    break
            if ok:
                previous[0], previous[1] = saved, reached
                reached = goal
                continue
            u[:] = saved
            cutbacks += 1
            if cutbacks > max_cutbacks:
                return False, total, cutbacks, rn, ref
            increment /= 2.0
            log(f"  cut back: increment {increment:g} of the load factor")
        return True, total, cutbacks, rn, ref

    # -- results ----------------------------------------------------------------------------
    def reactions(self) -> dict[str, list[float]]:
        self._update_pairs(self.a, final=True)
        res = self._residual(self.a)
        out = {}
        for bc, key in self._supports:
            region = self.mesh.Boundaries(cap(bc.body))
            fy = SYMMETRY_FACTOR * float(res @ self._unit(region, 1))
            out[key] = [0.0, fy, 0.0]
        return out

    def contact_forces(self) -> tuple[dict[str, dict], dict[str, float]]:
        """Per pair: the y contact forces on the slave and on the master, and the contact
        zone's extent (m): the largest distance, in the reference configuration, from the
        pair's touch point (:func:`touch_points`) to a vertex of either tube whose nodal
        contact force exceeds ``CONTACT_CUTOFF`` of the largest. The nodal forces reach one
        element beyond the zone, so the zone lies within the extent."""
        out, extent = {}, {}
        self._update_pairs(self.a, keep=True, final=True)
        for key, pair, cb, cb_alone, form in self.pairs:
            cb_alone.Update(self.u, form, self.contact_order, other=cb)
            res = self._residual(form)
            on = {}
            for body in (pair.slave, pair.master):
                on[body] = -SYMMETRY_FACTOR * float(res @ self._unit(self.mesh.Materials(body), 1))
            out[key] = {"force": [0.0, on[pair.slave], 0.0], "on_master": [0.0, on[pair.master], 0.0]}
            nodal = np.linalg.norm(res[self._vertex_dofs], axis=1)
            loaded = nodal > CONTACT_CUTOFF * nodal.max() if nodal.max() > 0.0 else nodal > 0.0
            distance = np.linalg.norm(self._vertices[loaded] - self._touch[key], axis=1)
            extent[key] = float(distance.max()) if distance.size else 0.0
        return out, extent

    def spring_forces(self) -> dict[str, float]:
        """y force (N, whole chain) the springs of the floating bodies would carry at ``u``."""
        out = {}
        for name in self.floating:
            m = self.bodies[name]
            k = SPRING_FACTOR * m.material.E / m.geometry.minor_radius ** 2
            uy = self.ng.Integrate(self.u[1], self.mesh, definedon=self.mesh.Materials(name))
            out[name] = SYMMETRY_FACTOR * k * float(uy)
        return out

    def peak_von_mises(self, lattice: int | None = None) -> tuple[dict, dict, dict]:
        """Peak von Mises stress (Pa) of every body on the lattice points ``(i, j, k) / n``
        of every element (``n = 2 p``, vertices included), its reference position, and
        ``[peak, x, y, z]`` on each side of the body's centre plane ``y = c_y`` that holds
        material (``below``, ``above``: the two contacts of a middle link)."""
        ng = self.ng
        from ngsolve.fem import IntegrationRule

        n = lattice or 2 * self.spec.order
        pts = [(i / n, j / n, k / n) for i in range(n + 1) for j in range(n + 1 - i)
               for k in range(n + 1 - i - j)]
        rule = IntegrationRule(pts, [0.0] * len(pts))
        peak, where, sides = {}, {}, {}
        for name in self.bodies:
            s = self.stress(name)
            dev = s - ng.Trace(s) / 3 * ng.Id(3)
            vm = ng.sqrt(1.5 * ng.InnerProduct(dev, dev))
            points = self.mesh.MapToAllElements(rule, self.mesh.Materials(name))
            values = np.asarray(vm(points)).ravel()
            x = np.asarray(ng.CF((ng.x, ng.y, ng.z))(points)).reshape(-1, 3)
            i = int(np.argmax(values))
            peak[name], where[name] = float(values[i]), [float(v) for v in x[i]]
            cy = self.bodies[name].geometry.center[1]
            sides[name] = {}
            for side, mask in (("below", x[:, 1] < cy), ("above", x[:, 1] > cy)):
                if mask.sum():
                    j = np.flatnonzero(mask)[int(np.argmax(values[mask]))]
                    sides[name][side] = [float(values[j]), *(float(v) for v in x[j])]
        return peak, where, sides

    def equilibrium(self, reactions: dict, contact: dict) -> float:
        """Largest resultant (y) of the support and contact forces on one body, relative to
        the largest support force: zero at equilibrium."""
        total = {name: 0.0 for name in self.bodies}
        for bc, key in self._supports:
            total[bc.body] += reactions[key][1]
        for key, pair, *_ in self.pairs:
            total[pair.slave] += contact[key]["force"][1]
            total[pair.master] += contact[key]["on_master"][1]
        scale = max(abs(v[1]) for v in reactions.values())
        return max(abs(v) for v in total.values()) / scale

    def run(self, *, steps: int | None = None, tol: float = 1e-11, max_iterations: int = 40,
            max_cutbacks: int = 6, check_factor: float | None = None,
            log: Callable[[str], None] = lambda s: None, t_build: float = 0.0) -> Solution:
        """Solve through the load steps (``steps`` of them if given, else the case's; load
        factor ``k / steps``) from the rest state; stops at the first step that fails.
        With ``check_factor``, every converged step is solved again with the penalty times
        ``check_factor``, starting from its converged state (a continuation in the penalty:
        the stiffer penalty only closes the penetration; at most ``CHECK_ITERATIONS_FACTOR *
        max_iterations`` Newton iterations), into ``Solution.check``; the next step goes on
        from the nominal state."""
        t0 = time.perf_counter()
        numbers = self.mesh_numbers()
        log(f"  mesh: {numbers['elements']} elements, {numbers['dofs']} dofs (order {self.spec.order})")
        n_steps = steps or self.case.steps
        results, previous, converged, message = [], [None, None], True, ""
        checked, check_ok, check_message, t_check = [], check_factor is not None, "", 0.0
        for k in range(1, n_steps + 1):
            ts = time.perf_counter()
            ok, its, cuts, rn, ref = self.solve_step((k - 1) / n_steps, k / n_steps, previous, tol,
                                                     max_iterations, max_cutbacks, log)
            if not ok:
                converged, message = False, f"step {k} failed after {cuts} cut-backs"
                log(f"  {message}")
                break
            results.append(self._record(k / n_steps, its, rn, ref, cuts, time.perf_counter() - ts))
            log("  step {}/{}: {} ({} iterations, {:.1f} s)".format(
                k, n_steps, ", ".join(f"{key} F_y = {v[1]:.6e} N"
                                      for key, v in results[-1].reactions.items()), its,
                results[-1].seconds))
            if check_ok:
                tc = time.perf_counter()
                u = self.u.vec.FV().NumPy()
                saved = u.copy()
                self.penalty_scale.Set(check_factor)
                check_ok, its, rn, ref = self.newton(self.a, tol, CHECK_ITERATIONS_FACTOR * max_iterations,
                                                     log)
                if check_ok:
                    checked.append(self._record(k / n_steps, its, rn, ref, 0, time.perf_counter() - tc))
                    log(f"  step {k}/{n_steps} with the penalty times {check_factor:g}: "
                        + ", ".join(f"{key} F_y = {v[1]:.6e} N" for key, v in checked[-1].reactions.items()))
                else:
                    check_message = f"step {k} failed with the penalty times {check_factor:g}"
                    log(f"  {check_message}")
                self.penalty_scale.Set(1.0)
                u[:] = saved
                t_check += time.perf_counter() - tc
        seconds = {"build": t_build, "solve": time.perf_counter() - t0 - t_check,
                   "total": t_build + time.perf_counter() - t0 - t_check}
        check = None
        if check_factor is not None:
            check = Solution(numbers, self.penalty_factor * check_factor,
                             {k: v * check_factor for k, v in self.penalties.items()}, checked,
                             {"check": t_check}, check_ok and converged, check_message)
        return Solution(numbers, self.penalty_factor, self.penalties, results, seconds, converged,
                        message, check)

    def _record(self, load_factor: float, its: int, rn: float, ref: float, cuts: int,
                seconds: float) -> StepResult:
        """The values of the converged state at ``load_factor``."""
        peak, where, sides = self.peak_von_mises()
        reactions = self.reactions()
        contact, extent = self.contact_forces()
        return StepResult(load_factor, reactions, contact, peak, where, sides,
                          self.equilibrium(reactions, contact), its, rn, ref, cuts, seconds,
                          extent, self.spring_forces())

    def contact_work(self, key: str, field) -> float:
        """Work (J, whole chain) of the contact traction of pair ``key`` (``slave/master``) on
        the slave for the virtual displacement ``field`` (a 3-vector CoefficientFunction)
        set on the slave's tube: ``4 int_tube t . field dA``, ``t`` the force per reference
        area the master exerts on the slave. ``field = (0, 1, 0)`` gives the y contact force."""
        for name, pair, cb, cb_alone, form in self.pairs:
            if name == key:
                self._update_pairs(self.a, keep=True, final=True)
                cb_alone.Update(self.u, form, self.contact_order, other=cb)
                gf = self.ng.GridFunction(self.fes)
                gf.Set(field, definedon=self.mesh.Boundaries(tube(pair.slave)))
                return -SYMMETRY_FACTOR * float(self._residual(form) @ gf.vec.FV().NumPy())
        raise KeyError(key)

    def mesh_numbers(self) -> dict:
        return {**self.spec.as_dict(), "elements": int(self.mesh.ne), "vertices": int(self.mesh.nv),
                "dofs": int(self.fes.ndof), "free_dofs": int(self.free.sum()),
                "contact_order": self.contact_order}


def solve(case: Case, spec: MeshSpec, penalty_factor: float, *, tol: float = 1e-11,
          max_iterations: int = 40, max_cutbacks: int = 6, steps: int | None = None,
          contact_order: int | None = None, check_factor: float | None = None,
          log: Callable[[str], None] = lambda s: None) -> Solution:
    """Solve ``case`` on the quarter mesh ``spec`` with penalty ``penalty_factor`` through
    its load steps (``steps`` of them if given, else the case's; load factor ``k / steps``),
    the contact integrated with a rule of order ``contact_order`` on the slave's surface
    elements (default ``CONTACT_ORDER_PER_P p``); with ``check_factor`` also every step with
    the penalty times it (:meth:`ToriProblem.run`)."""
    t0 = time.perf_counter()
    problem = ToriProblem(case, spec, penalty_factor, contact_order)
    return problem.run(steps=steps, tol=tol, max_iterations=max_iterations,
                       max_cutbacks=max_cutbacks, check_factor=check_factor, log=log,
                       t_build=time.perf_counter() - t0)
