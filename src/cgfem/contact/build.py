"""Contact pairs of a case, built on the discretized bodies.

Slave points are the slave body's boundary-rule points (the reduced rule of the weak form:
exact NURBS points for ``nurbs_fe``, points on the facet triangles for ``facets``) on the
pair's ``slave_patches``; the master surface is the master body's ``master_patches`` in the
same surface definition. ``max_gap`` (the farthest a ray looks) is
:data:`~cgfem.contact.pair.MAX_GAP_H` times the larger element size of the two bodies.

With ``rule: segmented`` (:mod:`cgfem.contact.rule`) the slave points are instead the exact
slave patches split by both grids' planes, at most ``(degree + 1)^3`` points per part (NURBS definitions
only: a facets pair so configured is refused).

Every surface works with the element of its body's space (:mod:`cgfem.fem.element`):
the slave points and master points move with that element's field, of order 1 or 2.

``nurbs_fit``: both sides are fitted surfaces (:class:`~cgfem.contact.fitted.FittedSurface`)
of the pair's patches, fitted on each body's exact surface rule in the fitting space the
pair's ``fit`` option names; the slave points are the same exact points as ``nurbs_fe``'s.
"""

from __future__ import annotations

import numpy as np

from cgfem.case.model import ContactPair as ContactSpec
from cgfem.contact.fit import build_fits
from cgfem.contact.fitted import FittedSurface
from cgfem.contact.pair import MAX_GAP_H, ContactPair, slave_gradients
from cgfem.contact.rule import segmented_rule
from cgfem.contact.surfaces import FacetSurface, NurbsFeSurface
from cgfem.embedding.partition import SurfaceQuadrature
from cgfem.definitions import NURBS_DEFINITIONS, surface_definition
from cgfem.errors import InputError
from cgfem.geometry.solid import Solid


def patch_ids(solid_names: tuple[str, ...], wanted: tuple[str, ...] | None) -> np.ndarray:
    """Indices of the patches (of a body whose patches are named ``solid_names``) named in
    ``wanted`` (None: all)."""
    return np.array([i for i, name in enumerate(solid_names) if wanted is None or name in wanted], np.int64)


def _slave_rule(spec: ContactSpec, solid: Solid, emb, master_emb, ids: np.ndarray, fits=()) -> SurfaceQuadrature:
    """The slave points of the pair ``spec`` (:mod:`cgfem.contact.rule`) on the patches
    ``ids`` of the slave ``solid`` embedded as ``emb``; ``fits``: the slave's fitted patches
    (``nurbs_fit``), whose knot lines the segmented rule also splits at."""
    if spec.rule == "segmented":
        return segmented_rule(solid, emb.grid, master_emb.grid, ids, {f.patch: f.surface for f in fits},
                              degree=emb.degree)
    return emb.boundary.select(np.isin(emb.boundary.patch, ids) & (emb.boundary.w > 0.0))


def build_pair(name: str, spec: ContactSpec, index: dict[str, int], models: list, solids: dict[str, Solid],
               definition: str, finite: bool, E: float, E_master: float | None = None) -> ContactPair:
    """The pair ``spec`` between ``models[index[spec.slave]]`` and the master's model;
    ``E``: Young's modulus of the slave (Pa), for the penalty ``kappa E / h``; ``E_master``
    (default ``E``): the master's, which scales its fit constraint (``nurbs_fit``)."""
    kind = surface_definition(definition)
    s_model, m_model = models[index[spec.slave]], models[index[spec.master]]
    s_solid, m_solid = solids[spec.slave], solids[spec.master]
    s_emb, m_emb = s_model.embedding, m_model.embedding
    s_ids = patch_ids(tuple(p.name for p in s_solid.patches), spec.slave_patches)
    m_ids = patch_ids(tuple(p.name for p in m_solid.patches), spec.master_patches)
    if spec.rule == "segmented" and not kind.exact_surface:
        raise InputError("rule", f"'segmented' needs a NURBS surface definition ({', '.join(NURBS_DEFINITIONS)}), "
                                 f"not {definition}")

    slave_surface = None
    if kind.exact_surface and not kind.fitted:          # nurbs_fe
        rule = _slave_rule(spec, s_solid, s_emb, m_emb, s_ids)
        frames = NurbsFeSurface(s_solid, s_model.space, rule, s_ids).slave_frames(rule)
        master = NurbsFeSurface(m_solid, m_model.space, m_emb.surface, m_ids)
    elif kind.fitted:                                   # nurbs_fit
        E_m = E if E_master is None else E_master
        s_fits = build_fits(s_solid, s_emb.surface, s_model.space, s_ids, spec.fit)
        slave_surface = FittedSurface(index[spec.slave], s_fits, s_emb.surface, E / s_model.space.h)
        frames = slave_surface.slave_frames(_slave_rule(spec, s_solid, s_emb, m_emb, s_ids, s_fits))
        master = FittedSurface(index[spec.master], build_fits(m_solid, m_emb.surface, m_model.space, m_ids, spec.fit),
                               m_emb.surface, E_m / m_model.space.h)
    else:
        s_fac, m_fac = s_emb.facets, m_emb.facets
        slave_srf = FacetSurface(s_model.space, s_fac.triangles, s_fac.element, np.isin(s_fac.patch, s_ids))
        rule = _slave_rule(spec, s_solid, s_emb, m_emb, s_ids)
        frames = slave_srf.slave_frames(rule.piece, rule.uv, rule.w)
        master = FacetSurface(m_model.space, m_fac.triangles, m_fac.element, np.isin(m_fac.patch, m_ids))
    h = s_model.space.h
    max_gap = MAX_GAP_H * max(h, m_model.space.h)
    return ContactPair(name, index[spec.slave], index[spec.master], s_model.space, m_model.space, frames,
                       slave_gradients(s_model.space, frames), master, spec.kappa * E / h, finite, max_gap,
                       slave_surface)
