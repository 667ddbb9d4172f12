"""Small cut cells: the ghost penalty keeps the stiffness well conditioned.

A box whose corner pokes a tiny cube of material (volume fraction ``delta``) into the next
grid elements: without the ghost penalty the condition number of the (unscaled) stiffness
grows like ``1 / delta``; with it, it stays bounded. Jacobi scaling alone also bounds it
for trilinear elements in these configurations (measured, not relied upon).
"""

from __future__ import annotations

import numpy as np
import pytest

from cgfem.fem.ghost import face_matrix, face_pairs
from cgfem.run import build_models
from tests.support.elasticity_cases import box_case


def _stiffness(delta: float, gamma: float):
    corner = 0.25 * delta ** (1.0 / 3.0)   # a corner cube of volume delta h^3 in the last elements
    size = (0.75 + 0.13 * 0.25 + corner, 0.75 + 0.29 * 0.25 + corner, 0.75 + 0.41 * 0.25 + corner)
    case = box_case([{"patches": ["xmin", "ymin", "zmin"], "type": "displacement",
                      "components": {"x": "0", "y": "0", "z": "0"}}],
                    material={"model": "linear_elastic", "E": 1.0, "nu": 0.3}, h0=0.25,
                    offset=(0.13, 0.29, 0.41), size=size, solver={"ghost_penalty": gamma})
    model = build_models(case, 0, "nurbs_fe", lambda m: None)[0][0]
    return model, model.assemble(np.zeros(model.n_dofs), 0.0, None)[1]


def _condition(K, scaled: bool) -> float:
    A = K.toarray()
    if scaled:
        d = 1.0 / np.sqrt(np.diag(A))
        A = A * d[:, None] * d[None, :]
    ev = np.linalg.eigvalsh(A)
    return ev[-1] / ev[0]


def test_ghost_penalty_bounds_condition_number_of_small_cut_cells():
    deltas = (1e-1, 1e-3, 1e-5)
    plain = [_condition(_stiffness(d, 0.0)[1], False) for d in deltas]
    ghost = [_condition(_stiffness(d, 0.05)[1], False) for d in deltas]
    # without: grows like 1/delta; with: bounded, independent of the cut
    assert plain[-1] / plain[0] > 1e3
    assert max(ghost) < 1e4 and max(ghost) / min(ghost) < 3.0
    jacobi = [_condition(_stiffness(d, 0.0)[1], True) for d in deltas]
    assert max(jacobi) < 100                        # measured 57


def test_smallest_cut_fraction_is_what_the_test_claims():
    model, _ = _stiffness(1e-5, 0.05)
    emb = model.embedding
    per_element = np.bincount(emb.volume.element, emb.volume.w, minlength=emb.grid.n_elements)
    fractions = per_element[model.space.elements] / model.space.h ** 3
    assert fractions.min() == pytest.approx(1e-5, rel=1e-6)


def test_face_matrix_vanishes_on_linear_fields_and_sees_kinks():
    h = 0.3
    m = face_matrix(2, h)
    from cgfem.fem.space import NODE_XI
    x = np.concatenate([0.5 * h * NODE_XI, 0.5 * h * NODE_XI + [0, 0, h]])   # lower, upper element
    linear = 0.7 * x[:, 0] - 1.1 * x[:, 1] + 0.4 * x[:, 2] + 2.0
    assert abs(linear @ m @ linear) < 1e-14
    kink = np.maximum(x[:, 2] - 0.5 * h, 0.0)   # slope 0 below the face z = h/2, 1 above
    assert kink @ m @ kink == pytest.approx(h * h * 1.0, rel=1e-12)   # int_F 1^2 dF = h^2


def test_face_pairs_touch_cut_elements_only():
    model, _ = _stiffness(1e-1, 0.05)
    pairs, axes = face_pairs(model.space)
    cut = model.space.cut
    assert np.all(cut[pairs[:, 0]] | cut[pairs[:, 1]])
    ijk = model.space.grid.element_ijk(model.space.elements)
    step = ijk[pairs[:, 1]] - ijk[pairs[:, 0]]
    assert np.array_equal(step, np.eye(3, dtype=int)[axes])
