"""Numba helpers on the grid's faces and lines shared by the cut-element rules."""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def line_intervals(l_start, l_off, l_coord, node_shape, axis, i_other, lo, hi, out):
    """Material intervals within ``[lo, hi]`` of the grid line along ``axis`` through the
    nodes whose indices are ``i_other`` (3,) on the other axes -> count written to ``out``."""
    b = 1 if axis == 0 else 0
    c = 1 if axis == 2 else 2
    line = i_other[b] * node_shape[c] + i_other[c]
    start = l_off[l_start[axis] + line]
    stop = l_off[l_start[axis] + line + 1]
    n = 0
    for k in range(start, stop - 1, 2):
        a0 = max(l_coord[k], lo)
        a1 = min(l_coord[k + 1], hi)
        if a1 > a0 and n < out.shape[0]:
            out[n, 0] = a0
            out[n, 1] = a1
            n += 1
    return n


@njit(cache=True)
def face_key(ijk, a, sigma, shape):
    """Trim key of the face of element ``ijk`` on the ``sigma`` side along ``a``: ``a *
    n_elements +`` the element below the face; -1 (no trims) if that face is the grid's
    boundary."""
    below = ijk[a] - (1 if sigma < 0 else 0)
    if below < 0:
        return -1
    n_el = shape[0] * shape[1] * shape[2]
    i = ijk[0] if a != 0 else below
    j = ijk[1] if a != 1 else below
    k = ijk[2] if a != 2 else below
    return a * n_el + (i * shape[1] + j) * shape[2] + k
