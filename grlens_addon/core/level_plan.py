"""The level plan: how finely each source edge is cut, so that every piece keeps its error within the
budget (budget.py), and which source triangles are cut at all.

Per order, in this sequence:

1. Curvature (seed 000, eqs. 18-19): each edge's level from rho of its image, capped by what the
   screen needs (subdivision.edge_levels): no more segments than pixels, no more than keep the
   chords within the tolerance. Edge midpoints are mapped only where a level above 1 is possible
   (:func:`probe_edges`), and become vertices of the cut where the level is even.
2. Silhouette: edges on the silhouette (visibility.Sight.silhouette) get the coverage tolerance.
3. Rings: strongly magnified triangles next to the observer-hole axis get levels that keep the
   azimuth each piece covers within the ring sagitta the tolerance allows (observer_view.max_ring_span):
   the same measure the culling applies. Next to axis patches, the ring's edge gets the coverage
   tolerance; triangles in a thin band around the ring are cut into strips instead (subdivision).
4. Selection: source triangles outside the frustum, replaced by an axis patch or hidden behind a
   closed surface's front are not cut; they are set aside and counted by the culling.

A mesh the axis does not cross whose magnified triangles pass close to it gets a coarse first split
(:func:`presplit`) before the plan is made on the smaller triangles.

Units: angles in radians, screen sizes in pixels of the frame's camera, positions in Blender units.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import axis_patch, culling, interior, mapping, observer_view, silhouette, subdivision
from . import budget as B
from .frame import Frame, Source, SourceImages, images_in_chunks


@dataclass
class Probes:
    """The edges whose midpoints were mapped, per order (``probe[order]``: sorted edge indices; the
    others span at most a pixel on screen), their images (``mids``: {order: mapping.Images} of the
    union ``probed``) and the edges' image sizes (``chord[order]`` (E,), radians)."""

    chord: dict
    probe: dict
    probed: np.ndarray
    mids: dict

    def mid_images(self, order) -> mapping.Images:
        """The images of ``order`` of the midpoints of probe[order]."""
        return mapping.take(self.mids[order], np.searchsorted(self.probed, self.probe[order]))


def probe_edges(frame: Frame, source: Source, coarse: SourceImages) -> Probes:
    """Map the midpoints of the edges that may need a level above 1 (an edge whose image spans at most
    one pixel keeps level 1 whatever its curvature), all orders together."""
    ev = source.edges.verts
    pixel_angle = frame.budget.pixel_angle
    chords = {o: subdivision.angle_of_chord(coarse.chord[o]) for o in frame.orders}
    probes = {o: np.flatnonzero(~(chords[o] <= pixel_angle)) if pixel_angle else np.arange(len(ev))
              for o in frame.orders}
    probed = np.unique(np.concatenate([np.zeros(0, np.int64)] + list(probes.values())))
    pts = source.positions
    mids = images_in_chunks(frame, 0.5 * (pts.take(ev[probed, 0], axis=0) + pts.take(ev[probed, 1], axis=0)))
    return Probes(chords, probes, probed, mids)


@dataclass
class LevelPlan:
    """One order's plan: ``levels`` (E,) per source edge; ``selected`` the source triangles to cut
    (indices); ``strips`` a mask over ``selected`` of those cut into strips (None: none); and what was
    set aside before cutting (``set_aside``: counts by culling.CullReport field), with the vertices'
    frustum bits (``outside_bits`` (N,), culling.outside_bits, or None without a frustum).
    ``below_pixel``: the whole image is within a pixel and is not built. ``known``: (keys (K,) sorted,
    mapping.Images) the images of the edge midpoints the plan mapped that are vertices of the cut at
    these levels, under their welding keys (subdivision.Subdivided)."""

    order: int
    levels: np.ndarray | None = None
    selected: np.ndarray | None = None
    strips: np.ndarray | None = None
    outside_bits: np.ndarray | None = None
    set_aside: dict = field(default_factory=dict)
    below_pixel: bool = False
    known: tuple | None = None


def plan_levels(frame: Frame, source: Source, coarse: SourceImages, sight, patches, probes: Probes,
                order: int) -> LevelPlan:
    """The :class:`LevelPlan` of ``order`` (see the module docstring). ``sight``: visibility.Sight;
    ``patches``: the source's axis patches (axis_patch.Patch)."""
    plan = LevelPlan(order)
    edges, tris = source.edges, source.tris
    img_v = coarse.images[order]
    probe = probes.probe[order]
    img_m = probes.mid_images(order)
    if sight.below_pixel(order, img_v, img_m):
        plan.below_pixel = True
        return plan
    order_patches = [p for p in patches if order in p.orders]
    budget = frame.budget
    settings = frame.settings
    tol = budget.tolerance_px
    if budget.active and B.THIN_FACTOR != 1.0 and _thin_image(coarse.hole_angle(order), budget.pixel_angle):
        tol = tol * B.THIN_FACTOR  # an image that is all edges: the whole budget scaled (see THIN_FACTOR)
    cov = None if tol is None else B.COVERAGE_FACTOR * tol
    chord = probes.chord[order]
    d = img_v.direction
    rho = subdivision.rho(d.take(edges.verts[probe, 0], axis=0), d.take(edges.verts[probe, 1], axis=0),
                          img_m.direction)
    err_px = lt_units = None
    if budget.active:  # the edges' midpoints where the renderer draws them against their exact images
        ev = edges.verts.take(probe, axis=0)
        err_px, lt_units = interior.midpoint_errors(
            frame, img_v.position.take(ev[:, 0], axis=0), img_v.position.take(ev[:, 1], axis=0),
            img_v.distance.take(ev[:, 0]), img_v.distance.take(ev[:, 1]), img_m)
    levels = np.ones(len(edges.verts), dtype=np.int64)  # edges not probed keep level 1
    levels[probe] = subdivision.edge_levels(rho, settings.max_tess_level, settings.tess_a, settings.tess_b,
                                            chord[probe], budget.pixel_angle, tol, err_px, lt_units)
    strip_tri = None
    if budget.active:
        strip_tri = _ring_and_silhouette(frame, source, coarse, sight, order_patches, order, levels, rho, chord,
                                         probe, tol, cov, err_px, lt_units)
    # the selection: the frustum, the patches' triangles, back faces
    selected, plan.outside_bits = sight.inside_frustum(img_v, img_m, probe)
    plan.set_aside["outside_frustum"] = len(tris) - len(selected)
    if order_patches:
        replaced = np.zeros(len(tris), bool)
        for p in order_patches:
            replaced[p.replaced] = True
        by_patch = replaced[selected]
        plan.set_aside["patch_replaced"] = int(by_patch.sum())
        selected = selected[~by_patch]
    away = sight.back_faces(selected, levels, order)  # (a mask over selected)
    n_away = int(np.count_nonzero(away))
    plan.set_aside["back_face"] = n_away
    if n_away:
        selected = selected[~away]
    plan.levels, plan.selected = levels, selected
    plan.known = _known_points(len(source.positions), levels, probe, img_m)
    if strip_tri is not None:
        plan.strips = strip_tri[selected]
    return plan


def _ring_and_silhouette(frame, source, coarse, sight, order_patches, order, levels, rho, chord, probe, tol, cov,
                         err_px=None, lt_units=None):
    """Steps 2-3 of the plan (see the module docstring), raising ``levels`` in place; returns the mask
    (T,) of the triangles cut into strips, or None."""
    settings, edges, tris = frame.settings, source.edges, source.tris
    pixel_angle = frame.budget.pixel_angle
    # silhouette edges (and the ring levels of silhouette triangles) aim at the coverage tolerance;
    # the silhouette is found only around the edges whose level that would change
    tight = subdivision.edge_levels(rho, settings.max_tess_level, settings.tess_a, settings.tess_b,
                                    chord[probe], pixel_angle, cov, err_px, lt_units)
    raise_edges = tight != levels[probe]
    replaced = cap = on_sheets = None
    if order_patches:
        replaced = np.zeros(len(tris), bool)
        on_sheets = np.zeros(len(tris), bool)  # the source triangles some patch draws a part of
        for p in order_patches:
            replaced[p.replaced] = True
            on_sheets[p.face_src] = on_sheets[p.vertex_tri] = on_sheets[p.replaced] = True
        cap = lambda t: _span_cap(order_patches, tris.take(t, axis=0), source.xy)  # noqa: E731
    hole_r = coarse.hole_angle(order)
    cand, want, sharp, r_px = _ring_levels(
        frame, source, coarse.circumference[order], hole_r, order, tol, cov, replaced, cap, on_sheets,
        lambda t: sight.hidden(t, (order,)))
    maybe = sharp != want
    if raise_edges.any() or maybe.any():
        sil_edge, sil_tri = sight.silhouette(order, np.concatenate([probe[raise_edges],
                                                                    edges.of_tri[cand[maybe]].ravel()]))
        up = raise_edges & sil_edge[probe]
        levels[probe[up]] = tight[up]
        want = np.where(maybe & sil_tri[cand] & (sharp <= B.SILHOUETTE_RING_LEVEL_MAX), sharp, want)
    if order_patches and cand.size and order in B.RING_EDGE_ORDERS:
        # next to a patch this order's ring is less than a pixel wide: the ring's edge there decides
        # coverage, whatever the level
        reach = B.RING_EDGE_REACH * max(p.radius for p in order_patches)
        xy = source.xy
        near = observer_view.within_axis_distance(xy[:, 0], xy[:, 1], tris.take(cand, axis=0), reach)
        want = np.where(near, np.maximum(want, sharp), want)
    strip = np.zeros(cand.size, bool)
    if B.STRIP_BAND_PX and cand.size:
        strip = _strip_candidates(frame, source, sight, cand, want, r_px, order)
    strip_tri = None
    if strip.any():
        # strips: each side gets the level of its own azimuth, for the coverage tolerance
        side = _side_levels(source.xy, tris.take(cand[strip], axis=0), r_px[strip], cov, settings)
        np.maximum.at(levels, edges.of_tri[cand[strip]].ravel(), side.ravel())
        strip_tri = np.zeros(len(tris), bool)
        strip_tri[cand[strip]] = True
    np.maximum.at(levels, edges.of_tri[cand[~strip]].ravel(), np.repeat(want[~strip], 3))
    return strip_tri


def _known_points(n_pts, levels, probe, mids):
    """(keys, images) of the probed midpoints that are vertices of the cut (those of edges cut at an even
    level; keys as subdivision.subdivide welds them: n_pts + edge (GRID + 1) + index on the edge's own
    grid from its lower vertex), so they are not looked up again; None when there are none."""
    lev = levels.take(probe)
    even = np.flatnonzero(lev % 2 == 0)
    if even.size == 0:
        return None
    return n_pts + probe[even] * (subdivision.GRID + 1) + lev[even] // 2, mapping.take(mids, even)


def _ring_candidates(src_circ, img_circ) -> np.ndarray:
    """Indices of the source triangles magnified more than RING_MAGNIFICATION."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.flatnonzero(img_circ > B.RING_MAGNIFICATION * src_circ)


def _ring_levels(frame, source, img_circ, hole_r, order, tol, cov, skip=None, cap=None, on_sheets=None, hidden=None):
    """The levels that strongly magnified source triangles near the axis need so that their pieces are
    narrow enough on screen (observer_view.ring_sagitta: a piece covering an azimuth d at an angular radius R
    from the hole's direction has straight sides R (1 - cos(d/2)) inside the ring): a triangle
    covering D gets ceil(D / (RING_LEVEL_MARGIN d_max)), d_max = observer_view.max_ring_span(R_px, tolerance),
    on all its edges (levels are per edge, so neighbours stay crack-free), capped at max_tess_level.

    ``img_circ``: the triangles' image circumferences of this order; ``hole_r`` (N,): the angles
    (radians) of the vertices' images from the hole's direction; ``tol``, ``cov``: the tolerance and
    the coverage tolerance (pixels);
    ``skip`` (T,) bool: triangles left alone (replaced by an axis patch); ``cap``: None, or a function
    of the candidates' indices giving the most azimuth (radians) each must be cut into pieces narrow in
    (:func:`_span_cap`); ``on_sheets`` (T,) bool: the triangles axis patches draw parts of. A candidate
    on none of them that passes beside the axis at d_min (e.g. a face of a box parallel to the axis)
    covers the azimuth h / d_min per length h next to the axis, far more than its average: its level
    counts that (EDGE_ON_RATIO); ``hidden``: a function of triangle indices giving those hidden in
    this order (back faces), which do not need it.

    Returns (cand, want, sharp, corner_px): the candidates (indices), their levels for ``tol`` and for
    ``cov``, and the angular radii (pixels) of their corners' images (len(cand), 3)."""
    settings = frame.settings
    top = int(np.clip(settings.max_tess_level, 1, subdivision.GRID))
    tris = source.tris
    cand = _ring_candidates(source.circumference, img_circ)
    if skip is not None:
        cand = cand[~skip[cand]]
    if cand.size == 0:
        return cand, np.ones(0, np.int64), np.ones(0, np.int64), np.zeros((0, 3))
    scene = frame.scene
    _, span = observer_view.axis_geometry(source.positions, tris[cand], scene.camera, scene.hole, order,
                                    axis_xyz=source.axis_xyz)
    if cap is not None:
        span = np.fmin(span, cap(cand))
    off = np.flatnonzero(~on_sheets[cand]) if on_sheets is not None else np.zeros(0, np.int64)
    if off.size and hidden is not None:
        off = off[~hidden(cand[off])]
    x, y, _ = source.axis_xyz
    if off.size:
        t_off = tris.take(cand[off], axis=0)
        # only triangles nearly parallel to the axis (projected area under EDGE_ON_RATIO of their own):
        # the others' pieces spread their azimuth evenly enough for the level of the azimuth they span
        proj = np.abs(observer_view.projected_area(x, y, t_off))
        own = observer_view.row_norm(silhouette.normals(source.positions, t_off))
        keep = proj < B.EDGE_ON_RATIO * own
        off, t_off = off[keep], t_off[keep]
    if off.size:
        d_min = observer_view.axis_distance(x, y, t_off)
        with np.errstate(invalid="ignore", divide="ignore"):
            near = np.where(d_min > 0, observer_view.longest_side(x, y, t_off) / d_min, np.nan)
        span[off] = np.fmax(span[off], near)
    with np.errstate(invalid="ignore", divide="ignore"):
        radius = hole_r / frame.budget.pixel_angle  # px
        corner_px = radius.take(tris.take(cand, axis=0))
        r_px = np.maximum(np.maximum(corner_px[:, 0], corner_px[:, 1]), corner_px[:, 2])
        out = [_azimuth_levels(span, observer_view.max_ring_span(r_px, t), top) for t in (tol, cov)]
    return cand, out[0], out[1], corner_px


def _azimuth_levels(span, d_max, top) -> np.ndarray:
    """Levels (integers 1 .. ``top``) that cut an azimuth ``span`` (radians) about the axis into pieces
    of at most RING_LEVEL_MARGIN * ``d_max`` each (the subdivision is uniform in space, not in
    azimuth, so it aims below the bound); 1 where either is NaN."""
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.ceil(span / (B.RING_LEVEL_MARGIN * d_max))
    return np.clip(np.nan_to_num(n, nan=1.0), 1, top).astype(np.int64)


def _span_cap(patches, tris, xy) -> np.ndarray:
    """(T,) radians: how much azimuth about the axis the pieces of the triangles ``tris`` (T, 3) (source
    vertices' axis coordinates ``xy`` (N, 2), BU) need to be narrow in, at most, next to the axis
    ``patches``: h / delta, h the triangle's longest side across the axis and delta the distance from
    the axis beyond which a patch may leave part of it undrawn (axis_patch.open_distance); inf where
    no patch draws any of it. Nearer the axis the patch draws the surface, so the ring levels need
    only make the pieces narrow enough from delta outwards."""
    x, y = xy[:, 0], xy[:, 1]
    out = np.full(len(tris), np.inf)
    near = np.flatnonzero(observer_view.within_axis_distance(x, y, tris, max(p.radius for p in patches)))
    if near.size == 0:
        return out
    t = tris.take(near, axis=0)
    delta = np.full(len(t), np.inf)
    for p in patches:
        delta = np.minimum(delta, axis_patch.open_distance(p, t, x, y))
    with np.errstate(divide="ignore", invalid="ignore"):
        out[near] = np.where(np.isfinite(delta), observer_view.longest_side(x, y, t) / delta, np.inf)
    return out


def _thin_image(hole_r, pixel_angle) -> bool:
    """True when the images of the source vertices, at the angles ``hole_r`` (radians) from the hole's
    direction, lie within THIN_PX pixels of radius about it."""
    r = hole_r[np.isfinite(hole_r)]
    return bool(r.size) and float(r.max() - r.min()) < B.THIN_PX * pixel_angle


def _strip_candidates(frame, source, sight, cand, want, corner_px, order) -> np.ndarray:
    """(len(cand),) bool: the ring triangles ``cand`` to cut into strips (see STRIP_BAND_PX). Their
    image must lie in the band all over, not only at the corners: also the image of the triangle's
    point nearest to the axis is checked (an edge passing close to the axis comes close to the
    Einstein ring in between; a triangle containing the axis covers the whole ring)."""
    c0, c1, c2 = corner_px[:, 0], corner_px[:, 1], corner_px[:, 2]
    band = np.maximum(np.maximum(c0, c1), c2) - np.minimum(np.minimum(c0, c1), c2)
    ok = (band < B.STRIP_BAND_PX) & (want >= B.STRIP_MIN_LEVEL)
    if ok.any():
        at = np.flatnonzero(ok)
        near_px = _nearest_point_radius(frame, source, cand[at], order)
        lo = np.minimum(np.minimum(np.minimum(c0[at], c1[at]), c2[at]), near_px)
        hi = np.maximum(np.maximum(np.maximum(c0[at], c1[at]), c2[at]), near_px)
        ok[at] = hi - lo < B.STRIP_BAND_PX  # NaN (no image there, or the axis itself): not a strip
    if ok.any():
        ok[ok] = sight.one_way(cand[ok], order)
    return ok


def _nearest_point_radius(frame, source, tris_idx, order) -> np.ndarray:
    """(K,) pixels: the angle from the hole's direction of the ``order`` image of each source triangle's
    point nearest to the axis in projection (on its boundary; NaN when the axis passes through it)."""
    xy = source.xy
    t3 = source.tris.take(tris_idx, axis=0)
    inside, t, d = observer_view.nearest_to_axis(xy[:, 0], xy[:, 1], t3)
    k = np.argmin(d, axis=1)  # the side with the nearest point
    rows = np.arange(len(t3))
    a = source.positions.take(t3[rows, k], axis=0)
    b = source.positions.take(t3[rows, (k + 1) % 3], axis=0)
    point = a + t[rows, k][:, None] * (b - a)  # the projection along the axis is affine
    img = frame.map.images(point, (order,))[order]
    scene = frame.scene
    with np.errstate(invalid="ignore"):
        r = observer_view.hole_angle(img.direction, scene.camera, scene.hole, scene.view_beta) / frame.budget.pixel_angle
    return np.where(inside | ~img.valid, np.nan, r)


def _side_levels(xy, tris, corner_px, tolerance, settings) -> np.ndarray:
    """(S, 3) ring levels of the sides of the triangles ``tris`` (S, 3) of the source vertices with axis
    coordinates ``xy`` (N, 2), cut into strips: side k (corner k -> k + 1) covering the azimuth D_k
    about the axis gets ceil(D_k / (RING_LEVEL_MARGIN d_max)) as in :func:`_ring_levels`, with d_max
    from the triangle's largest corner radius ``corner_px`` and ``tolerance`` (pixels)."""
    top = int(np.clip(settings.max_tess_level, 1, subdivision.GRID))
    span = observer_view.side_azimuths(xy[:, 0], xy[:, 1], tris)
    with np.errstate(invalid="ignore", divide="ignore"):
        d_max = observer_view.max_ring_span(corner_px.max(axis=1), tolerance)
    return _azimuth_levels(span, np.reshape(d_max, (-1, 1)), top)


def presplit(frame: Frame, source: Source, coarse: SourceImages, sight) -> np.ndarray | None:
    """Per-edge levels (E,) of a first, coarse split of the source, or None when none is needed.

    A strongly magnified triangle of projected size h whose closest point lies at d_min from the axis
    needs pieces of size RING_LEVEL_MARGIN * d_max * d_min next to that point (d_max: the azimuth the
    tolerance allows at its ring radius), i.e. a level need = h / (RING_LEVEL_MARGIN d_max d_min). The
    ring levels look at the azimuth its corners span, which for a triangle passing close to the axis
    is much less: its pieces next to the axis would stay too wide and be culled. A uniform split at
    ``need`` would cost need^2 pieces; instead, triangles with need > PRESPLIT_MIN are first split at
    need ** PRESPLIT_EXP, and the plan is made again on the smaller triangles. Only meshes the axis
    does not cross (axis patches handle the crossings); back faces (hidden in every order) are not
    split."""
    if not axis_patch.patching(frame) or axis_patch.crossings_of(frame, source):
        return None
    budget = frame.budget
    need = np.ones(len(source.tris))
    x = y = None
    for order in frame.orders:
        cand = _ring_candidates(source.circumference, coarse.circumference[order])
        if cand.size == 0:
            continue
        x, y, _ = source.axis_xyz
        t = source.tris[cand]
        px, py = x[t], y[t]
        h = np.hypot(px - np.roll(px, -1, axis=1), py - np.roll(py, -1, axis=1)).max(axis=1)
        dmin = observer_view.axis_distance(x, y, t)
        with np.errstate(invalid="ignore", divide="ignore"):
            radius = coarse.hole_angle(order) / budget.pixel_angle
            d_max = observer_view.max_ring_span(radius[t].max(axis=1), budget.tolerance_px)
            n = np.where(dmin > 0, h / (B.RING_LEVEL_MARGIN * d_max * dmin), 1.0)
        need[cand] = np.maximum(need[cand], np.nan_to_num(n, nan=1.0, posinf=1.0))
    split = need > B.PRESPLIT_MIN
    if split.any():
        idx = np.flatnonzero(split)
        split[idx[sight.hidden(idx, frame.orders)]] = False
    if not split.any():
        return None
    k = np.clip(np.ceil(need ** B.PRESPLIT_EXP), 1, subdivision.GRID).astype(np.int64)
    k[~split] = 1
    levels = np.ones(len(source.edges.verts), np.int64)
    np.maximum.at(levels, source.edges.of_tri.ravel(), np.repeat(k, 3))
    return levels
