"""Newton's order measured on the error: every converged full-Newton solve of the static
solver is continued with exact steps to round-off (``u*``), and the order of Newton's map is
taken along the direction of the last measurable iterate (see
``tests/physics/test_newton_order.py`` for why the error, not the residual)."""

from __future__ import annotations

import numpy as np

import cgfem.solve.outer as outer

#: errors below this fraction of the first are round-off of the converged state
FLOOR = 1e-11
#: the two distances from ``u*`` along an iterate's direction are its error and this fraction
SHRINK = 3.0


def record_errors(monkeypatch) -> list[dict]:
    """Wrap the static solver's Newton: every converged full-Newton solve is continued with
    exact steps to round-off, and the list returned gets, per solve, its iterates' errors
    against that ``u*`` (``errors``), its ``residuals``, ``tail`` (the norms of the extra
    steps), ``order``: the order of Newton's map along the direction of its last iterate
    whose next error is above ``FLOOR`` (see the module's docstring), ``probes``: the two
    new errors that order is read from, and ``constant``: that iterate's ``e_k+1 / e_k^2``,
    the errors taken relative to the first."""
    solves: list[dict] = []
    newton = outer.newton

    def wrapped(assemble, u0, solve, **kwargs):
        iterates: list[tuple[np.ndarray, float]] = []

        def recording(u, tangent):
            r, K = assemble(u, tangent)
            iterates.append((u.copy(), float(np.linalg.norm(r))))
            return r, K
        result = newton(recording, u0, solve, **kwargs)
        if kwargs.get("fixed_tangent") or not result.converged:
            return result
        # the accepted iterates are the trials whose residual norms the solve kept
        accepted = [next(u for u, n in iterates if n == norm) for norm in result.residuals]

        def step(u: np.ndarray) -> np.ndarray:
            r, K = assemble(u, True)
            return u + solve(K, -r)
        u, tail = result.u.copy(), []
        for _ in range(3):
            v = step(u)
            tail.append(float(np.linalg.norm(v - u)))
            u = v
        errors = [float(np.linalg.norm(v - u)) for v in accepted]
        # the order of Newton's map along the direction of the last iterate whose image is
        # measurable: its next error is above FLOOR (round-off is ~1e-15 of the first error)
        # (none: a solve that ends in one step; its order and constant are NaN, and fail)
        k = max((k for k in range(len(errors) - 1) if errors[k + 1] > FLOOR * errors[0]), default=None)
        order = constant = float("nan")
        new = [float("nan")] * 2
        if k is not None:
            d = (accepted[k] - u) / errors[k]
            new = [float(np.linalg.norm(step(u + eps * d) - u)) for eps in (errors[k], errors[k] / SHRINK)]
            order = float(np.log(new[0] / new[1]) / np.log(SHRINK))
            constant = errors[k + 1] / errors[k] ** 2 * errors[0]
        solves.append({"errors": errors, "residuals": list(result.residuals), "tail": tail,
                       "order": order, "probes": new, "constant": constant})
        return result
    monkeypatch.setattr(outer, "newton", wrapped)
    return solves
