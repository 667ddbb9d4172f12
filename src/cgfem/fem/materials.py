"""Constitutive laws at material points: Lamé parameters, model ids, batched stress
evaluation and the closed-form uniaxial Neo-Hookean reference.

The laws themselves are the numba kernels of :mod:`cgfem.fem._material_kernels`
(:func:`~cgfem.fem._material_kernels.stress_tangent` is what the element kernels call);
this module validates and shapes the inputs of the batched versions.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from cgfem.case.model import Lame, Material
from cgfem.errors import InputError
from cgfem.fem import _material_kernels as _k
from cgfem.fem._material_kernels import LINEAR_ELASTIC, NEO_HOOKEAN, stress_tangent

__all__ = [
    "LINEAR_ELASTIC",
    "NEO_HOOKEAN",
    "Lame",
    "MODEL_IDS",
    "lame",
    "model_id",
    "stress",
    "cauchy",
    "stress_tangent_at",
    "von_mises",
    "uniaxial_stretch_neo_hookean",
]

#: Model name (as in the case file) -> kernel id.
MODEL_IDS: dict[str, int] = {"linear_elastic": LINEAR_ELASTIC, "neo_hookean": NEO_HOOKEAN}


def lame(E: float, nu: float) -> Lame:
    """Lamé parameters ``Lame(lam, mu)`` of ``E`` and ``nu`` (the order of
    :meth:`cgfem.case.model.Material.lame`, validated like a case file's material). The
    kernels below take ``mu, lam``: pass them by name."""
    return Material("linear_elastic", E, nu).lame()


def model_id(name: str) -> int:
    """Kernel id of the material model ``name`` (``"linear_elastic"`` or ``"neo_hookean"``)."""
    try:
        return MODEL_IDS[name]
    except (KeyError, TypeError):
        raise InputError(
            "model", f"unknown material model {name!r}; known: {', '.join(MODEL_IDS)}"
        ) from None


def _gradients(H: np.ndarray) -> tuple[np.ndarray, tuple[int, ...]]:
    H = np.ascontiguousarray(H, dtype=np.float64)
    if H.ndim < 2 or H.shape[-2:] != (3, 3):
        raise ValueError(f"displacement gradients must have shape (..., 3, 3), got {H.shape}")
    lead = H.shape[:-2]
    return H.reshape(-1, 3, 3), lead


def _check_model(model: int) -> int:
    model = int(model)
    if model not in MODEL_IDS.values():
        raise ValueError(f"unknown material model id {model}")
    return model


def stress_tangent_at(model: int, H: np.ndarray, mu: float, lam: float
                      ) -> tuple[float, np.ndarray, np.ndarray]:
    """Energy density ``W``, stress ``P`` (3, 3) and tangent ``A = dP/dH`` (3, 3, 3, 3) at one
    displacement gradient ``H`` (3, 3); ``W = inf`` and NaN ``P``, ``A`` if ``det F <= 0``."""
    Hq, lead = _gradients(H)
    if lead != ():
        raise ValueError(f"H must have shape (3, 3), got {np.shape(H)}")
    P = np.empty((3, 3))
    A = np.empty((3, 3, 3, 3))
    W = stress_tangent(_check_model(model), Hq[0], float(mu), float(lam), P, A)
    return float(W), P, A


def stress(model: int, H: np.ndarray, mu: float, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """Energy density ``W`` (...) and stress ``P`` (..., 3, 3) at the displacement gradients
    ``H`` (..., 3, 3): first Piola-Kirchhoff for Neo-Hookean, Cauchy for linear elastic."""
    Hq, lead = _gradients(H)
    W, P = _k.stress_batch(_check_model(model), Hq, float(mu), float(lam))
    return W.reshape(lead), P.reshape(lead + (3, 3))


def cauchy(model: int, H: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """Cauchy stress (..., 3, 3) at the displacement gradients ``H`` (..., 3, 3)."""
    Hq, lead = _gradients(H)
    sigma = _k.cauchy_batch(_check_model(model), Hq, float(mu), float(lam))
    return sigma.reshape(lead + (3, 3))


def von_mises(sigma: np.ndarray) -> np.ndarray:
    """Von Mises stress ``sqrt(3/2 s : s)`` (n,) of the stresses ``sigma`` (n, 3, 3)
    (any leading shape is kept)."""
    s = np.ascontiguousarray(sigma, dtype=np.float64)
    if s.ndim < 2 or s.shape[-2:] != (3, 3):
        raise ValueError(f"stresses must have shape (..., 3, 3), got {s.shape}")
    lead = s.shape[:-2]
    return _k.von_mises_batch(s.reshape(-1, 3, 3)).reshape(lead)


def uniaxial_stretch_neo_hookean(stretch: float, E: float, nu: float) -> tuple[float, float]:
    """Uniaxial tension/compression of the compressible Neo-Hookean law along ``x`` with
    free lateral faces: ``F = diag(s, t, t)``, ``P22 = P33 = 0``.

    ``P22 = 0`` reads ``mu (t^2 - 1) + lam ln(s t^2) = 0`` (multiplied by ``t > 0``), which
    is solved for ``t`` with Brent's method to machine precision. Returns the lateral
    stretch ``t`` and the nominal (first Piola-Kirchhoff) stress
    ``P11 = mu (s - 1/s) + lam ln(s t^2) / s``. For ``nu < 0`` (``lam < 0``) and strong
    compression there may be no such ``t`` on the branch ``t^2 > -lam/mu``, where the
    equation is monotone: :class:`~cgfem.errors.InputError` is raised.
    """
    s = float(stretch)
    if not (math.isfinite(s) and s > 0.0):
        raise InputError("stretch", f"must be a finite number > 0, got {stretch!r}")
    lam, mu = lame(E, nu)
    if s == 1.0:
        return 1.0, 0.0
    ln_s = math.log(s)

    def lateral(t: float) -> float:
        return mu * (t * t - 1.0) + lam * (ln_s + 2.0 * math.log(t))

    # d lateral / dt = 2 (mu t^2 + lam) / t: increasing for t > t_min = sqrt(max(0, -lam/mu))
    # (lam < 0 only for nu < 0, where the branch t < t_min is the unphysical one). Bracket
    # the root on the increasing branch by doubling / halving from t = 1.
    f1 = lateral(1.0)
    if f1 == 0.0:
        t = 1.0
    else:
        t_min = math.sqrt(max(0.0, -lam / mu))
        lo = hi = 1.0
        if f1 > 0.0:
            if t_min > 0.0:
                lo = t_min
                if lateral(lo) > 0.0:
                    raise InputError("stretch", f"no laterally stress-free state at stretch {s!r}")
            else:
                while lateral(lo) > 0.0:
                    lo *= 0.5
        else:
            while lateral(hi) < 0.0:
                hi *= 2.0
        eps = np.finfo(np.float64).eps
        t = brentq(lateral, lo, hi, xtol=1e-300, rtol=4.0 * eps, maxiter=500)
    P11 = mu * (s - 1.0 / s) + lam * (ln_s + 2.0 * math.log(t)) / s
    return float(t), float(P11)
