"""The contact surface definitions: what each one is, needs and supports, declared once.

A run names one definition (``cgfem run --surface``, paper Section 3):

- ``facets``: marching-cubes triangles whose vertices follow the FE field; the bodies'
  boundary conditions are integrated on the same triangles;
- ``nurbs_fe``: the exact NURBS surface moved by the FE field, ``X(xi) + u(X(xi))``;
- ``nurbs_fit``: NURBS surfaces fitted to the FE field (extra unknowns: the fitted controls
  and the fit's multipliers, :mod:`cgfem.contact.fitted`).

Everything that depends on the definition asks this registry (which boundary quadrature
the embedding builds, whether a rule that needs the exact surface can be used, whether the
system carries fitted unknowns), instead of comparing names.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SurfaceDefinition", "DEFINITIONS", "NAMES", "NURBS_DEFINITIONS", "surface_definition"]


@dataclass(frozen=True)
class SurfaceDefinition:
    """One contact surface definition.

    name : the name a case and the CLI use
    quadrature : the boundary quadrature the embedding builds for it (``nurbs``: on the
        exact surface; ``facets``: on the marching-cubes triangles), which the weak
        boundary conditions use too
    exact_surface : the contact surface is the exact NURBS geometry (moved or fitted): what
        the ``segmented`` slave rule and the exact surface rule need
    fitted : the contact surfaces move with fitted control displacements (extra unknowns)
    summary : one line for help texts
    """

    name: str
    quadrature: str
    exact_surface: bool
    fitted: bool
    summary: str


#: every definition, in the order figures and tables list them
DEFINITIONS: dict[str, SurfaceDefinition] = {d.name: d for d in (
    SurfaceDefinition("facets", "facets", False, False, "marching-cubes triangles"),
    SurfaceDefinition("nurbs_fe", "nurbs", True, False, "exact NURBS + FE displacement"),
    SurfaceDefinition("nurbs_fit", "nurbs", True, True, "fitted NURBS"),
)}
#: their names, in that order
NAMES: tuple[str, ...] = tuple(DEFINITIONS)
#: the names of the definitions on the exact NURBS surface
NURBS_DEFINITIONS: tuple[str, ...] = tuple(n for n, d in DEFINITIONS.items() if d.exact_surface)


def surface_definition(name: str) -> SurfaceDefinition:
    """The definition called ``name``; ``ValueError`` naming the known ones otherwise."""
    try:
        return DEFINITIONS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown surface definition {name!r} (known: {', '.join(NAMES)})") from None
