"""Internal force and tangent of the elastic bulk over the cut-cell volume rule.

Small strain (linear elastic) and finite strain (total Lagrangian, compressible Neo-Hookean)
share one path: the displacement gradient ``H`` at the volume points, the constitutive kernel
gives the stress ``P`` (Cauchy for small strain, first Piola-Kirchhoff for finite) and the
tangent ``A = dP/dH``, and the element kernels integrate ``int P : grad v`` and
``int grad v : A : grad du``. In the linear case the stiffness is computed once, and the
inside elements of the uniform grid all get one reference matrix (their tensor Gauss rule
is the same up to translation), so only cut elements are integrated point by point.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cgfem.fem import _element_kernels as kern
from cgfem.fem._material_kernels import LINEAR_ELASTIC, stress_batch, tangent_batch
from cgfem.fem.assembly import Pattern
from cgfem.fem.element import HEX8, Hexahedron
from cgfem.fem.space import ElementPoints, Space
from cgfem.quadrature_rules import tensor_gauss

#: elements whose tangent tensors are held at once in finite strain
CHUNK_ELEMENTS = 4096



@dataclass
class Elasticity:
    """The bulk term of one body.

    model : material kernel id (:data:`LINEAR_ELASTIC` or ``NEO_HOOKEAN``)
    mu, lam : Lamé constants (Pa)
    points : the volume rule grouped by active element
    """

    space: Space
    pattern: Pattern
    points: ElementPoints
    model: int
    mu: float
    lam: float
    _linear_data: np.ndarray | None = field(default=None, repr=False)

    @property
    def linear(self) -> bool:
        return self.model == LINEAR_ELASTIC

    def gradients(self, u: np.ndarray, points: ElementPoints | None = None) -> np.ndarray:
        """Displacement gradient (n, 3, 3) at ``points`` (default: the volume rule)."""
        pts = self.points if points is None else points
        return kern.point_gradients(*self.space.kernel_element, self.space.connectivity, u, pts.xi,
                                    pts.offsets, self.space.h)

    def stress(self, u: np.ndarray, points: ElementPoints | None = None) -> np.ndarray:
        """Stress ``P`` (n, 3, 3) at ``points``: Cauchy (small strain) or first Piola-Kirchhoff."""
        return stress_batch(self.model, self.gradients(u, points), self.mu, self.lam)[1]

    def add(self, u: np.ndarray, r: np.ndarray, data: np.ndarray | None) -> None:
        """Add the internal force to ``r`` and, if ``data`` is given, the tangent to it."""
        if self.linear:
            K = self.pattern.matrix(self._stiffness())
            r += K @ u
            if data is not None:
                data += self._linear_data
            return
        pts, h = self.points, self.space.h
        H = self.gradients(u)
        P = stress_batch(self.model, H, self.mu, self.lam)[1]
        element = self.space.kernel_element
        kern.integrate_force(*element, self.space.connectivity, P, pts.xi, pts.w, pts.offsets, h, r)
        if data is None:
            return
        # the tangent tensors of a chunk of elements at a time (81 numbers per point)
        for e0 in range(0, self.space.n_elements, CHUNK_ELEMENTS):
            e1 = min(e0 + CHUNK_ELEMENTS, self.space.n_elements)
            p0, p1 = pts.offsets[e0], pts.offsets[e1]
            A = tangent_batch(self.model, H[p0:p1], self.mu, self.lam)[2]
            for elements in self.pattern.colours:
                chunk = elements[(elements >= e0) & (elements < e1)]
                kern.integrate_tangent(*element, A, p0, pts.xi, pts.w, pts.offsets, h, chunk,
                                       self.pattern.scatter, data)

    def _stiffness(self) -> np.ndarray:
        if self._linear_data is None:
            self._linear_data = self.linear_stiffness_data()
        return self._linear_data

    def linear_stiffness_data(self) -> np.ndarray:
        """CSR data of the small-strain stiffness: one reference matrix for every inside
        element, the volume rule for cut ones."""
        space, pts, pat, h = self.space, self.points, self.pattern, self.space.h
        data = pat.zeros()
        zero = np.zeros((1, 3, 3))
        A = tangent_batch(self.model, zero, self.mu, self.lam)[2]
        ke = reference_matrix(A[0], h, space.element)
        cut = space.cut
        for elements in pat.colours:
            inner = elements[~cut[elements]]
            kern.scatter_reference(ke, inner, pat.scatter, data)
            kern.integrate_tangent(*space.kernel_element, A, -1, pts.xi, pts.w, pts.offsets, h,
                                   elements[cut[elements]], pat.scatter, data)
        return data


def reference_matrix(A: np.ndarray, h: float, element: Hexahedron = HEX8) -> np.ndarray:
    """Stiffness (nd, nd) of ``element`` on a whole cube of size ``h`` with the constant
    tangent ``A`` (3, 3, 3, 3), by the tensor Gauss rule of ``element.gauss_points`` points per
    direction (exact: the integrand has degree ``2 order`` per variable)."""
    xi, w = tensor_gauss(element.gauss_points, 3)
    w = w * (0.5 * h) ** 3
    nd = element.n_dofs
    offsets = np.array([0, xi.shape[0]], np.int64)
    # int32 as the bodies' scatter maps (:func:`cgfem.fem.assembly.build_pattern`): one compiled
    # version of the kernel serves both
    scatter = np.arange(nd * nd, dtype=np.int32).reshape(1, nd * nd)
    data = np.zeros(nd * nd)
    kern.integrate_tangent(element.node_ijk, element.order, A[None], -1, xi, w, offsets, h,
                           np.array([0], np.int64), scatter, data)
    return data.reshape(nd, nd)
