"""Frictionless contact between the bodies of a case (paper sections "Contact kinematics" to
"Linearization of kinematic variables"): surface definitions in the current configuration
(:mod:`~cgfem.contact.surfaces`), the ray-traced gap and its exact derivatives
(:mod:`~cgfem.contact.kinematics`), and one slave/master pair's residual and consistent
tangent with the stabilized multiplier (:mod:`~cgfem.contact.pair`). The formulation and
the reasons for each of its rules: docs/methods/contact.md."""
