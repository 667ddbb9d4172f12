"""The Cartesian grid a body is embedded in.

Grid planes along axis ``a`` lie at ``x_a = origin[a] + i h``. A case gives ``h0`` and an
``offset`` in units of ``h0``: the planes of level ``L`` are ``x_a = (offset[a] + i / 2^L) h0``,
so every level contains the planes of the coarser ones and each element of level ``L`` is
split into 8 at level ``L + 1`` (the nested refinement of the paper's Fig. 8 and 12).
Elements and nodes are numbered over the whole box, ``id = (i * ny + j) * nz + k``; which of
them are active is decided by the embedding, not here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CartesianGrid:
    """A box of ``shape`` cubic elements of size ``h`` whose first node is at ``origin``."""

    h: float
    origin: tuple[float, float, float]
    shape: tuple[int, int, int]

    def __post_init__(self) -> None:
        if not (self.h > 0.0 and math.isfinite(self.h)):
            raise ValueError(f"h must be positive, got {self.h}")
        object.__setattr__(self, "origin", tuple(float(c) for c in self.origin))
        object.__setattr__(self, "shape", tuple(int(n) for n in self.shape))
        if min(self.shape) < 1:
            raise ValueError(f"shape must be positive, got {self.shape}")

    @classmethod
    def covering(cls, lo, hi, h0: float, level: int, offset=(0.0, 0.0, 0.0)) -> "CartesianGrid":
        """The smallest grid of level ``level`` that contains the box ``[lo, hi]``."""
        h = h0 / 2.0**level
        lo, hi, off = (np.asarray(v, float) for v in (lo, hi, offset))
        base = off * h0
        first = np.floor((lo - base) / h).astype(int)
        last = np.ceil((hi - base) / h).astype(int)
        last = np.maximum(last, first + 1)
        origin = base + first * h
        return cls(h, tuple(origin), tuple(last - first))

    # -- sizes -------------------------------------------------------------------------------
    @property
    def n_elements(self) -> int:
        nx, ny, nz = self.shape
        return nx * ny * nz

    @property
    def node_shape(self) -> tuple[int, int, int]:
        return tuple(n + 1 for n in self.shape)

    @property
    def n_nodes(self) -> int:
        nx, ny, nz = self.node_shape
        return nx * ny * nz

    def refined(self) -> "CartesianGrid":
        """The nested grid of half the element size (each element split into 8)."""
        return CartesianGrid(self.h / 2.0, self.origin, tuple(2 * n for n in self.shape))

    # -- geometry -----------------------------------------------------------------------------
    def plane(self, axis: int, index) -> np.ndarray:
        """Coordinate of grid plane(s) ``index`` along ``axis``."""
        return self.origin[axis] + np.asarray(index) * self.h

    def node_coordinates(self, ijk: np.ndarray) -> np.ndarray:
        """Coordinates of nodes ``ijk`` (n, 3) -> (n, 3)."""
        return np.asarray(self.origin) + np.asarray(ijk, float) * self.h

    def element_corner(self, ijk: np.ndarray) -> np.ndarray:
        """Lowest corner of elements ``ijk`` (n, 3) -> (n, 3)."""
        return self.node_coordinates(ijk)

    def element_center(self, ijk: np.ndarray) -> np.ndarray:
        """Centres of elements ``ijk`` (n, 3) -> (n, 3)."""
        return self.node_coordinates(np.asarray(ijk, float) + 0.5)

    def element_of_points(self, x: np.ndarray) -> np.ndarray:
        """Indices ``ijk`` (n, 3) of the elements containing points ``x`` (n, 3) (clipped to
        the box)."""
        ijk = np.floor((np.asarray(x, float) - np.asarray(self.origin)) / self.h).astype(np.int64)
        return np.clip(ijk, 0, np.asarray(self.shape) - 1)

    # -- numbering ------------------------------------------------------------------------------
    def element_id(self, ijk: np.ndarray) -> np.ndarray:
        """Linear element ids of ``ijk`` (n, 3)."""
        ijk = np.asarray(ijk, np.int64)
        _, ny, nz = self.shape
        return (ijk[..., 0] * ny + ijk[..., 1]) * nz + ijk[..., 2]

    def element_ijk(self, ids: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`element_id`."""
        _, ny, nz = self.shape
        ids = np.asarray(ids, np.int64)
        return np.stack([ids // (ny * nz), (ids // nz) % ny, ids % nz], axis=-1)

    def node_id(self, ijk: np.ndarray) -> np.ndarray:
        """Linear node ids of node indices ``ijk`` (n, 3)."""
        ijk = np.asarray(ijk, np.int64)
        _, ny, nz = self.node_shape
        return (ijk[..., 0] * ny + ijk[..., 1]) * nz + ijk[..., 2]

    def element_nodes(self, ids: np.ndarray) -> np.ndarray:
        """Node ids (n, 8) of elements ``ids`` in H8 order: (0,0,0) (1,0,0) (1,1,0) (0,1,0),
        then the same at k + 1."""
        ijk = self.element_ijk(ids)
        corners = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                            [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
        return self.node_id(ijk[:, None, :] + corners[None, :, :])
