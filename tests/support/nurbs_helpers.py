"""Helpers shared by the NURBS tests."""

from __future__ import annotations

from cgfem.geometry.nurbs import NurbsSurface


def geomdl_surface(S: NurbsSurface):
    """The same surface as a geomdl NURBS surface (the independent cross-check)."""
    from geomdl import NURBS

    g = NURBS.Surface(normalize_kv=False)
    g.degree_u, g.degree_v = S.degree
    g.set_ctrlpts(S.control.reshape(-1, 4).tolist(), *S.control.shape[:2])
    g.knotvector_u = S.knots_u.tolist()
    g.knotvector_v = S.knots_v.tolist()
    return g
