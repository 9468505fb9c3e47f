"""Culling: which image triangles to drop, and why; the stage that owns every count of the report
(:func:`cull_pieces`), so the UI can say what happened to each triangle.

Seed 000, section 3.2: a triangle that straddles the observer-hole axis is mapped onto both sides of
the hole (its images belong to an Einstein ring, which a mesh cannot show); it is recognised by the
ratio of the circumference of its image to that of the undistorted triangle, both measured as
chords on the camera's unit view sphere (dimensionless, so independent of the camera's lens). Triangles with a
vertex without an image (outside the LUT's radial range, inside the horizon, non-finite, exactly on
the axis) are dropped, as are triangles entirely outside the camera frustum and triangles whose
source is degenerate (zero circumference). The view-sphere and axis geometry these tests measure by
is in observer_view.py.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import budget as B
from . import subdivision
from .observer_view import (axis_coordinates, axis_geometry, chord_length, circumference, hole_angle,
                            ring_sagitta, row_norm, unit_directions, used_vertices)


@dataclass
class CullReport:
    """Numbers of triangles dropped per reason (a triangle is counted under its first reason)."""

    invalid_vertex: int = 0
    degenerate_source: int = 0
    einstein_ring: int = 0
    outside_frustum: int = 0
    below_pixel: int = 0  # whole image smaller than a pixel: not built
    kept: int = 0
    patch_replaced: int = 0  # source triangles drawn by an Einstein-ring patch instead (not culled)
    patch_faces: int = 0  # of the kept faces, those of Einstein-ring patches (axis_patch.py)
    presplit: int = 0  # source triangles added by the level plan's first split next to the axis (counted above)
    back_face: int = 0  # source triangles hidden behind the front of a closed surface (budget.BACK_FACE_MARGIN)
    patch_covered: int = 0  # pieces that a complete patch draws more exactly (budget.UNDER_PATCH_FACTOR)
    refined: int = 0  # pieces the refine step cut further (interior.refine: replaced by their parts, in ``kept``)
    over_budget: object = None  # interior.Beyond: the kept pieces measured inside after the refine step
    triangle_bound: bool = False  # the refine step stopped at Settings.max_triangles
    extra: dict = field(default_factory=dict)

    def total_culled(self) -> int:
        return (self.invalid_vertex + self.degenerate_source + self.einstein_ring + self.outside_frustum
                + self.below_pixel + self.back_face + self.patch_covered)


def side_planes(origin, corner_directions) -> np.ndarray:
    """(4, 4) planes (n, d), n . x + d >= 0 inside, through ``origin`` (3,; BU) and consecutive pairs of
    the four ``corner_directions`` (4, 3) of a pyramid (a camera frustum without near and far
    planes), with unit normals pointing into it."""
    origin = np.asarray(origin, dtype=np.float64)
    corners = np.asarray(corner_directions, dtype=np.float64)
    centre = corners.mean(axis=0)
    n = np.cross(corners, np.roll(corners, -1, axis=0))
    n *= np.where(n @ centre < 0, -1.0, 1.0)[:, None]
    n /= row_norm(n)[:, None]
    return np.column_stack([n, -(n @ origin)])


def outside_bits(points, planes) -> np.ndarray:
    """Per point (N,) an integer whose bit k is set when the point is outside plane k (rows (n, d) of
    ``planes``, n . x + d >= 0 inside; at most 63 planes). Points with NaN coordinates are inside of
    every plane (0), so they are never culled by the frustum. A triangle is wholly outside one plane
    exactly when the bitwise AND of its corners' values is nonzero."""
    planes = np.asarray(planes, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    bits = np.zeros(len(points), dtype=np.int64)
    with np.errstate(invalid="ignore"):
        for k, (n, d) in enumerate(zip(planes[:, :3], planes[:, 3])):
            bits |= (points @ n + d < 0).astype(np.int64) << k  # NaN -> False (inside)
    return bits


def cull(tris, image_dirs, valid, source_points, camera, cull_ratio, frustum_planes=None, image_points=None,
         hole=None, order=None, pixel_angle=None, max_error_px=None, *, source_circumference=None,
         image_circumference=None, image_outside_bits=None, axis_candidates=None, beta=None):
    """Mask of image triangles to keep, and a :class:`CullReport`.

    tris (F, 3) index the per-vertex arrays: image_dirs (V, 3) unit apparent directions of the images,
    valid (V,) bool, source_points (V, 3) the undistorted world positions (BU). ``cull_ratio``: drop a
    triangle whose image circumference exceeds cull_ratio times the undistorted one (seed 000 uses a
    customisable threshold; larger keeps more). With ``hole`` (BU) and ``order`` given, triangles the
    axis passes through are always dropped, and the ratio drops only triangles that also cover more
    than budget.AZIMUTH_SPAN_MAX around the axis (see :func:`axis_geometry`): near the Einstein ring regular
    triangles are magnified by large factors too (a fine mesh behind the hole would lose its whole
    ring to the ratio alone), but only wide or straddling ones have a wrong image. With
    ``pixel_angle`` (radians per pixel) and ``max_error_px`` given, "wide" is measured on screen: the
    mapping keeps a point's angle about the axis, so near the ring an image triangle covering an
    azimuth D at an angular radius R from the hole's direction has straight sides that fall
    R (1 - cos(D/2)) inside the ring; such magnified triangles are culled when that exceeds
    ``max_error_px`` pixels, the level plan's measure (else when D > budget.AZIMUTH_SPAN_MAX).
    ``frustum_planes`` (K, 4): rows (n, d) with n . x + d >= 0 inside, applied to ``image_points`` (V, 3).

    Values the caller already has can be passed instead of being computed here (the result is the
    same): ``source_circumference`` and ``image_circumference`` (F,), :func:`circumference` of the
    undistorted and image directions; ``image_outside_bits`` (V,), :func:`outside_bits` of
    ``image_points``; ``axis_candidates`` (F,) bool, a superset of the triangles the axis may pass
    through (e.g. from :func:`near_axis` of their source triangles; others are not tested). ``beta``
    (3,; units of c): the camera's velocity (mapping.Scene.beta), whose view ``image_dirs`` are; the
    undistorted view and the ring measure are then the moving camera's (observer_view.unit_directions,
    observer_view.hole_angle).
    """
    tris = np.asarray(tris, dtype=np.int64)
    rep = CullReport()
    keep = np.ones(len(tris), dtype=bool)
    ok_v = valid.take(tris)  # (one gather of every corner)
    bad_v = ~(ok_v[:, 0] & ok_v[:, 1] & ok_v[:, 2])
    rep.invalid_vertex = int(bad_v.sum())
    keep &= ~bad_v
    src_c = source_circumference
    if src_c is None:
        src_c = circumference(unit_directions(source_points, camera, beta), tris)
    degenerate = keep & ~(src_c > 0)
    rep.degenerate_source = int(degenerate.sum())
    keep &= ~degenerate
    img_c = circumference(image_dirs, tris) if image_circumference is None else image_circumference
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = img_c / src_c
    ring = keep & ~(ratio <= cull_ratio)
    if hole is not None and order is not None:
        # the axis test and the azimuth span only where they can matter: candidates and ring triangles
        sel = np.arange(len(tris)) if axis_candidates is None else np.flatnonzero(ring | axis_candidates)
        straddles = np.zeros(len(tris), dtype=bool)
        span = np.full(len(tris), np.nan)
        t_sel = tris.take(sel, axis=0)
        straddles[sel], span[sel] = axis_geometry(source_points, t_sel, np.asarray(camera, np.float64),
                                                  np.asarray(hole, np.float64), order,
                                                  span_of=np.flatnonzero(ring[sel]))
        wide = np.zeros(len(tris), dtype=bool)
        with np.errstate(invalid="ignore"):
            if pixel_angle and max_error_px:
                at = used_vertices(t_sel, len(image_dirs))  # once per corner point
                angle = np.full(len(image_dirs), np.nan)
                angle[at] = hole_angle(image_dirs.take(at, axis=0), camera, hole, beta)
                r_px = angle.take(t_sel)
                r_px = np.maximum(np.maximum(r_px[:, 0], r_px[:, 1]), r_px[:, 2]) / pixel_angle
                wide[sel] = ring_sagitta(r_px, span[sel]) > max_error_px
            else:
                wide[sel] = span[sel] > B.AZIMUTH_SPAN_MAX
            ring = keep & (straddles | (ring & wide))
    rep.einstein_ring = int(ring.sum())
    keep &= ~ring
    if frustum_planes is not None and image_points is not None and len(frustum_planes):
        bits = outside_bits(image_points, frustum_planes) if image_outside_bits is None else image_outside_bits
        b = bits.take(tris)
        outside = (b[:, 0] & b[:, 1] & b[:, 2]) != 0  # all 3 behind one plane
        out = keep & outside
        rep.outside_frustum = int(out.sum())
        keep &= ~outside
    rep.kept = int(keep.sum())
    return keep, rep


def cull_pieces(frame, source, coarse, plan, pieces, patches, order):
    """The cull stage of one order: (keep, patch_keep, report). ``keep`` (F,) bool over the pieces'
    faces (None when the level plan built nothing: the image is below a pixel); ``patch_keep``: per
    axis patch of this order, a mask of its faces to draw (None: the patch draws nothing in it);
    ``report``: every count of the image (:class:`CullReport`), including what the level plan set
    aside before cutting (outside the frustum, replaced by patches, back faces) and the source's
    cleaning (extra["bad_source_triangles"]).

    Pieces are culled by :func:`cull` (no image, degenerate, on an Einstein ring by the level plan's
    measure, outside the frustum) and under complete patches (:func:`_under_patches`); patch faces
    with a corner without an image or wholly outside one frustum plane are not drawn."""
    report = CullReport()
    report.extra["bad_source_triangles"] = source.n_bad
    report.presplit = source.presplit
    if plan.below_pixel:
        report.below_pixel = len(source.tris)
        return None, [], report
    scene, settings, budget, planes = frame.scene, frame.settings, frame.budget, frame.planes
    sub, img, face_src = pieces.sub, pieces.images, pieces.face_src
    n_pts = len(source.positions)
    bits = None
    if plan.outside_bits is not None:  # frustum bits of the pieces' vertices: the source corners' are known
        is_corner = sub.vertex_key < n_pts
        bits = np.empty(len(sub.vertex_key), dtype=np.int64)
        bits[is_corner] = plan.outside_bits[sub.vertex_key[is_corner]]
        bits[~is_corner] = outside_bits(img.position[~is_corner], planes)
    keep, rep = cull(
        sub.tris, img.direction, img.valid, sub.positions, scene.camera, settings.cull_ratio, planes,
        img.position, scene.hole, order, budget.pixel_angle, budget.tolerance_px,
        source_circumference=_face_values(sub, face_src, source.circumference, lambda t: circumference(
            unit_directions(sub.positions, scene.camera, scene.view_beta), t)),
        image_circumference=_face_values(sub, face_src, coarse.circumference[order],
                                         lambda t: circumference(img.direction, t)),
        image_outside_bits=bits, axis_candidates=source.near_axis[face_src], beta=scene.view_beta)
    rep.extra, rep.presplit = report.extra, report.presplit
    rep.outside_frustum += plan.set_aside.get("outside_frustum", 0)
    rep.back_face = plan.set_aside.get("back_face", 0)
    order_patches = [p for p in patches if order in p.orders]
    if order_patches and B.UNDER_PATCH_FACTOR is not None:  # the patch draws these more exactly
        covered = _under_patches(frame, order_patches, order, sub.tris, face_src, sub.positions, img, keep,
                                 len(source.tris))
        rep.patch_covered = int(covered.sum())
        if rep.patch_covered:
            keep &= ~covered
            rep.kept -= rep.patch_covered
    patch_keep = []
    if order_patches:
        rep.patch_replaced = plan.set_aside.get("patch_replaced", 0)
        for p in order_patches:
            ok = _patch_faces_kept(p, order, planes)
            patch_keep.append(ok)
            if ok is not None:
                rep.patch_faces += int(ok.sum())
        rep.kept += rep.patch_faces
    return keep, patch_keep, rep


def _patch_faces_kept(patch, order, planes):
    """(F,) bool: the faces of ``patch`` drawn in ``order``: facing (not hidden), every corner with an
    image, not wholly outside one frustum plane; None when the patch has no image of that order."""
    im = patch.images.get(order)
    if im is None:  # hidden (back faces of a closed surface)
        return None
    faces = patch.tris
    ok = im.valid.take(faces).all(axis=1) & patch.facing[order]
    if planes is not None:
        bits = outside_bits(np.where(im.valid[:, None], im.position, 0.0), planes)
        fb = bits.take(faces)
        ok &= (fb[:, 0] & fb[:, 1] & fb[:, 2]) == 0
    return ok


def _face_values(sub, face_src, per_source, compute) -> np.ndarray:
    """(F,) a per-triangle quantity for the faces of ``sub`` (subdivision.Subdivided): taken from
    ``per_source`` (indexed by ``face_src``) for the faces passed through unsplit, ``compute(tris)``
    for the split ones."""
    n = sub.n_pass
    if n == len(sub.tris):
        return per_source[face_src]
    out = np.empty(len(sub.tris))
    out[:n] = per_source[face_src[:n]]
    out[n:] = compute(sub.tris[n:])
    return out


def _under_patches(frame, patches, order, tris, face_src, points, img, keep, n_src) -> np.ndarray:
    """(F,) bool: the pieces ``tris`` (F, 3) (vertices ``points`` (V, 3) BU, their ``order`` images
    ``img``, source triangles ``face_src``) among ``keep`` that a complete patch draws over (wholly
    inside its outer circle, on a source triangle it draws in that order) and whose centroid is drawn
    more than UNDER_PATCH_FACTOR times the tolerance from its true image; ``n_src``: the number of
    source triangles."""
    scene = frame.scene
    out = np.zeros(len(tris), bool)
    dist = None
    for p in patches:
        if not p.complete:
            continue
        drawn = np.zeros(n_src, bool)
        drawn[p.face_src[p.facing[order]]] = True
        cand = np.flatnonzero(drawn[face_src] & keep & ~out)
        if not cand.size:
            continue
        if dist is None:  # the vertices' distances from the axis (BU)
            x, y, _ = axis_coordinates(points, scene.camera, scene.hole)
            dist = np.hypot(x, y)
        cand = cand[(dist.take(tris.take(cand, axis=0)) < p.radius).all(axis=1)]
        if not cand.size:
            continue
        t = tris.take(cand, axis=0)
        true = frame.map.images(points.take(t, axis=0).mean(axis=1), (order,))[order]
        drawn_dir = img.direction.take(t, axis=0).sum(axis=1)
        drawn_dir /= np.maximum(row_norm(drawn_dir), 1e-300)[:, None]
        err = subdivision.angle_of_chord(chord_length(true.direction, drawn_dir))  # radians
        budget = frame.budget
        out[cand[err > B.UNDER_PATCH_FACTOR * budget.tolerance_px * budget.pixel_angle]] = True
    return out
