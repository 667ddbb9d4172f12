"""The contact-onset limit of a Newton solve's first step.

The first Newton step of a solve has no contact stiffness at points still open, so where an
imposed motion closes a contact it carries the slave through the master by all of it
(chain2_steel's first step at level 2 pushed 1085 points in by up to 0.8 h, and the active set
then swung by hundreds of points per iteration). :class:`OnsetLimit` scales that step so that no
slave point goes deeper into its master than ``onset_penetration`` of the slave's element size
beyond where it already was. Measurements: ``docs/methods/contact.md``, "Contact onset".
"""

from __future__ import annotations

import numpy as np

from cgfem.solve.policy import DEFAULT_POLICY, SolverPolicy


class OnsetLimit:
    """The onset limit on a contact set (:class:`~cgfem.contact.assembly.ContactSet`, whose
    ``gaps(u)`` gives every pair's slave-point gaps (m), NaN where no master is hit).

    Not applied while a body is held by contact alone (``floating()`` true): its first step
    is bounded already by the floating-body step limit, and on chain3 the onset limit made
    convergence worse (``docs/methods/contact.md``)."""

    def __init__(self, contact, floating, policy: SolverPolicy = DEFAULT_POLICY):
        self.contact, self.floating, self.policy = contact, floating, policy

    def limit(self, u: np.ndarray, du: np.ndarray) -> np.ndarray:
        """The first Newton step ``du`` (n,) of a solve from ``u`` (n,), scaled by the
        largest factor for which no slave point goes deeper into its master than
        ``onset_penetration * h_slave`` beyond where it already is, the gap taken linear
        along the step (gaps at ``u + du``, and at ``u`` only when some point would end
        deeper than the allowance); ``du`` itself if none does."""
        allowance = self.policy.onset_penetration
        if not self.contact or self.floating() or not np.isfinite(allowance):
            return du
        allowed = [allowance * pair.slave_space.h for pair in self.contact.pairs]
        after = self.contact.gaps(u + du)
        if all(np.nan_to_num(-g, nan=0.0).max(initial=0.0) <= a for g, a in zip(after, allowed)):
            return du
        factor = 1.0
        for before, end, a in zip(self.contact.gaps(u), after, allowed):
            seen = np.isfinite(end)
            deeper = np.minimum(np.nan_to_num(before[seen], nan=0.0), 0.0) - end[seen]
            depth = float(deeper.max(initial=0.0))
            if depth > a:
                factor = min(factor, a / depth)
        return du if factor == 1.0 else factor * du
