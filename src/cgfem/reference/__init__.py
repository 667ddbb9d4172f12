"""Independent reference solutions (own numpy/scipy Q9 solver, no cgFEM code paths).

:mod:`cgfem.reference.planar` is the body-fitted plane-strain overkill solution of the
planar example and the relative energy-norm error of a cgFEM strain field against it.
"""
