"""Independent reference solutions (no cgFEM code paths).

:mod:`cgfem.reference.planar` is the body-fitted plane-strain overkill solution of the
planar example (own numpy/scipy Q9 solver) and the relative energy-norm error of a cgFEM
strain field against it. :mod:`cgfem.reference.tori` is the body-fitted solution of the
chain examples with NGSolve (curved high-order tetrahedra on the exact tori, penalty
contact; needs the ``reference`` extra), with its mesh and penalty uncertainty.
"""
