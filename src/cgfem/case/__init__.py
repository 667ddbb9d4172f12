"""Case files: YAML validated against the shipped JSON schema, loaded into frozen dataclasses.

>>> case = load_case("config/cases/planar.yaml")          # doctest: +SKIP
>>> case.body("lower").grid.h(2)                          # doctest: +SKIP
0.000625
"""

from cgfem.case.expressions import (
    Expression,
    VectorExpression,
    as_expression,
    as_vector_expression,
    parse_expression,
)
from cgfem.case.load import case_schema, check_patch_names, load_case, parse_case, parse_yaml
from cgfem.case.model import (
    Body,
    BoundaryCondition,
    Case,
    ContactPair,
    DisplacementBC,
    GridSpec,
    Material,
    SolverOptions,
    TractionBC,
)

__all__ = [
    "Body",
    "BoundaryCondition",
    "Case",
    "ContactPair",
    "DisplacementBC",
    "Expression",
    "GridSpec",
    "Material",
    "SolverOptions",
    "TractionBC",
    "VectorExpression",
    "as_expression",
    "as_vector_expression",
    "case_schema",
    "check_patch_names",
    "load_case",
    "parse_case",
    "parse_expression",
    "parse_yaml",
]
