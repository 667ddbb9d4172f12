"""Solids as closed sets of named NURBS patches (a boundary representation)."""

from __future__ import annotations

from dataclasses import dataclass

from cgfem.errors import InputError
from cgfem.geometry.nurbs import NurbsSurface


@dataclass(frozen=True)
class Patch:
    """A named NURBS patch of a solid's boundary, oriented so that ``S_u x S_v`` points
    out of the solid. Several patches may share a name (they form one named surface)."""

    name: str
    surface: NurbsSurface


@dataclass(frozen=True)
class Solid:
    """A closed, outward-oriented set of patches."""

    patches: tuple[Patch, ...]

    def __post_init__(self) -> None:
        if not self.patches:
            raise InputError("patches", "a solid needs at least one patch")
        object.__setattr__(self, "patches", tuple(self.patches))

    @property
    def patch_names(self) -> tuple[str, ...]:
        """Distinct patch names, in order of first appearance."""
        return tuple(dict.fromkeys(p.name for p in self.patches))

    def named(self, name: str) -> tuple[Patch, ...]:
        """All patches called ``name``."""
        found = tuple(p for p in self.patches if p.name == name)
        if not found:
            raise KeyError(f"no patch named {name!r} (have: {', '.join(self.patch_names)})")
        return found
