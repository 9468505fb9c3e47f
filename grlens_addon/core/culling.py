"""Culling: which image triangles to drop, and why; the stage that owns every count of the report
(:func:`cull_pieces`), so the UI can say what happened to each triangle.

Seed 000, section 3.2: a triangle that straddles the observer-hole axis is mapped onto both sides of
the hole (its images belong to an Einstein ring, which a mesh cannot show); it is recognised by the
ratio of the circumference of its image to that of the undistorted triangle, both measured as
chords on the camera's unit view sphere (dimensionless, so independent of the camera's lens). Triangles with a
vertex without an image (outside the LUT's radial range, inside the horizon, non-finite, exactly on
the axis) are dropped, as are triangles entirely outside the camera frustum and triangles whose
source is degenerate (zero circumference).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import budget as B
from . import mapping, subdivision
from .mapping import any_perpendicular, row_norm, used_vertices


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


def chord_length(u, v):
    """(N,) distance between unit vectors ``u`` and ``v`` (N, 3): the chord on the view sphere."""
    w = u - v
    return np.sqrt(np.einsum("ij,ij->i", w, w))


def circumference(d, tris):
    """Perimeter of each triangle on the unit view sphere, as the sum of its corners' chord lengths
    (dimensionless; equal to the sum of the angles in radians to second order for small triangles)."""
    a, b, c = d.take(tris[:, 0], axis=0), d.take(tris[:, 1], axis=0), d.take(tris[:, 2], axis=0)
    return chord_length(a, b) + chord_length(b, c) + chord_length(c, a)


def unit_directions(points, camera):
    """Unit vectors from ``camera`` (3,) to ``points`` (N, 3) (BU); NaN for the camera itself."""
    v = np.asarray(points, dtype=np.float64) - camera
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / row_norm(v)[:, None]


def hole_angle(directions, camera, hole) -> np.ndarray:
    """Angle (radians) of unit ``directions`` (N, 3) from the camera's direction to the hole (BU)."""
    towards_hole = np.asarray(hole, np.float64) - np.asarray(camera, np.float64)
    towards_hole /= np.linalg.norm(towards_hole)
    return np.arccos(np.clip(directions @ towards_hole, -1.0, 1.0))


def ring_sagitta(radius, span):
    """How far (same unit as ``radius``) the straight sides of a piece covering the azimuth ``span``
    (radians about the observer-hole axis) fall inside a ring of angular radius ``radius`` around the
    hole's direction: radius (1 - cos(span / 2)). The mapping keeps a point's angle about the axis,
    so near an Einstein ring azimuth becomes position along the ring. :func:`max_ring_span` is its
    inverse."""
    return radius * (1.0 - np.cos(0.5 * np.minimum(span, np.pi)))


def max_ring_span(radius, sagitta):
    """The largest azimuth (radians) whose :func:`ring_sagitta` at ``radius`` stays within ``sagitta``:
    2 arccos(1 - sagitta / radius) (2 pi when any azimuth would do)."""
    return 2.0 * np.arccos(np.clip(1.0 - sagitta / radius, -1.0, 1.0))


def axis_coordinates(source_points, camera, hole):
    """Coordinates (x, y, z) of ``source_points`` (N, 3; BU) relative to the hole: z along the axis
    towards the camera, x and y across it (a fixed perpendicular pair)."""
    e1 = np.asarray(camera, np.float64) - hole
    e1 = e1 / np.linalg.norm(e1)
    u = any_perpendicular(e1)
    v = np.cross(e1, u)
    p = np.asarray(source_points, dtype=np.float64) - hole
    return p @ u, p @ v, p @ e1


def axis_crossing(x, y, z, tris):
    """Where the observer-hole axis meets the triangles ``tris`` (T, 3) of points with
    :func:`axis_coordinates` (x, y, z): (inside, crossed, along), each (T,). ``inside``: the origin lies
    in the triangle's projection onto the plane perpendicular to the axis (same sign of the three edge
    functions; touching counts); ``crossed``: inside and not edge-on, so there is a crossing point;
    ``along`` (BU): its coordinate along the axis (NaN where edge-on)."""
    xa, xb, xc = x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]]
    ya, yb, yc = y[tris[:, 0]], y[tris[:, 1]], y[tris[:, 2]]
    # twice the signed areas of (origin, b, c), (origin, c, a), (origin, a, b): barycentrics of the axis
    la, lb, lc = xb * yc - xc * yb, xc * ya - xa * yc, xa * yb - xb * ya
    with np.errstate(invalid="ignore", divide="ignore"):
        inside = ((la >= 0) & (lb >= 0) & (lc >= 0)) | ((la <= 0) & (lb <= 0) & (lc <= 0))
        total = la + lb + lc
        along = (la * z[tris[:, 0]] + lb * z[tris[:, 1]] + lc * z[tris[:, 2]]) / np.where(total != 0, total, np.nan)
    return inside, inside & (total != 0), along


def axis_distance(x, y, tris) -> np.ndarray:
    """(T,) distance (BU) from the observer-hole axis to the triangles ``tris`` (T, 3) projected along
    it (0 when the axis passes through the projection); x, y from :func:`axis_coordinates`."""
    inside, _, d = nearest_to_axis(x, y, tris)
    return np.where(inside, 0.0, d.min(axis=1))


def nearest_to_axis(x, y, tris):
    """(inside, t, d) for the triangles ``tris`` (T, 3) projected along the axis (x, y from
    :func:`axis_coordinates`): inside (T,) the axis passes through the projection (touching counts);
    per side k (corner k -> k + 1) the parameter t (T, 3) in [0, 1] of its point nearest to the axis
    and that point's distance d (T, 3) (BU)."""
    px, py = x[tris], y[tris]  # (T, 3)
    qx, qy = np.roll(px, -1, axis=1), np.roll(py, -1, axis=1)
    cross = px * qy - py * qx  # twice the signed areas of (origin, corner k, corner k+1)
    inside = (cross >= 0).all(axis=1) | (cross <= 0).all(axis=1)
    dx, dy = qx - px, qy - py
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.clip(-(px * dx + py * dy) / (dx * dx + dy * dy), 0.0, 1.0)
    t = np.nan_to_num(t)
    return inside, t, np.hypot(px + t * dx, py + t * dy)


def projected_area(x, y, tris) -> np.ndarray:
    """(T,) twice the signed area of the triangles ``tris`` (T, 3) projected along the axis (BU^2;
    positive: counter-clockwise seen from the camera's side); x, y from :func:`axis_coordinates`."""
    ax, bx, cx = x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]]
    ay, by, cy = y[tris[:, 0]], y[tris[:, 1]], y[tris[:, 2]]
    return (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)


def _beside_axis(x, y, tris, tol) -> np.ndarray:
    """(T,) bits, nonzero where all three corners of the triangles ``tris`` lie more than ``tol`` (a
    number, or one per point) to the same side of the axis along x or along y (bits 0-3: x > tol,
    x < -tol, y > tol, y < -tol), which puts the whole triangle farther than ``tol`` from it. NaN
    coordinates compare False: such a corner is on no side, so its triangle is never excluded."""
    with np.errstate(invalid="ignore"):
        side = ((x > tol).astype(np.uint8) | ((x < -tol).astype(np.uint8) << 1)
                | ((y > tol).astype(np.uint8) << 2) | ((y < -tol).astype(np.uint8) << 3))
    return side.take(tris[:, 0]) & side.take(tris[:, 1]) & side.take(tris[:, 2])


def within_axis_distance(x, y, tris, limit) -> np.ndarray:
    """(T,) bool: :func:`axis_distance` of the triangles ``tris`` (T, 3) <= ``limit`` (BU), computed only
    for those not excluded by their corners' box (all corners more than ``limit`` to one side of the
    axis along x or along y puts the whole triangle farther): the same answer, far cheaper on a large
    mesh of which a few triangles lie next to the axis."""
    maybe = _beside_axis(x, y, tris, limit) == 0
    out = np.zeros(len(tris), bool)
    t = np.flatnonzero(maybe)
    out[t] = axis_distance(x, y, tris.take(t, axis=0)) <= limit
    return out


def side_azimuths(x, y, tris) -> np.ndarray:
    """(T, 3) the angle (radians, <= pi) about the axis between the projected corners k and k + 1 of
    the triangles ``tris`` (T, 3): the azimuth side k covers (0 for a side with a corner on the axis,
    NaN with a corner without coordinates); x, y from :func:`axis_coordinates`."""
    tris = np.asarray(tris, dtype=np.int64)
    at = used_vertices(tris, len(x))
    psi = np.full(len(x), np.nan)
    psi[at] = np.arctan2(np.asarray(y).take(at), np.asarray(x).take(at))  # once per corner point
    psi[at[(np.asarray(x).take(at) == 0) & (np.asarray(y).take(at) == 0)]] = np.inf  # on the axis: no azimuth
    a = psi.take(tris)
    d = a[:, [1, 2, 0]] - a
    with np.errstate(invalid="ignore"):
        out = np.abs(np.mod(d + np.pi, 2.0 * np.pi) - np.pi)
    return np.where(np.isinf(a) | np.isinf(a[:, [1, 2, 0]]), 0.0, out)  # a side from the axis covers none


def longest_side(x, y, tris) -> np.ndarray:
    """(T,) the longest side (BU) of the triangles ``tris`` (T, 3) projected along the axis; x, y from
    :func:`axis_coordinates`."""
    px, py = x.take(tris), y.take(tris)
    return np.maximum(np.maximum(np.hypot(px[:, 1] - px[:, 0], py[:, 1] - py[:, 0]),
                                 np.hypot(px[:, 2] - px[:, 1], py[:, 2] - py[:, 1])),
                      np.hypot(px[:, 0] - px[:, 2], py[:, 0] - py[:, 2]))


def axis_geometry(source_points, tris, camera, hole, order, span_of=None, axis_xyz=None):
    """Per triangle: (straddles, span).

    ``straddles`` (F,) bool: the observer-hole axis passes through the triangle on a half where that
    order's images form an Einstein ring, so no mesh can show it. The axis is the line through
    ``hole`` and ``camera`` (BU); a triangle is crossed when the origin lies inside the projection of
    its corners onto the plane perpendicular to the axis (same sign of the three edge functions;
    touching counts). The crossing point's coordinate along the axis decides the half: behind the
    hole (phi = pi) both orders are rings; in front of the hole (phi = 0) only order 2 is (its ray
    sweeps 2 pi), the order-1 image there is regular.

    ``span`` (F,) radians: the angle around the axis the triangle covers (pi for triangles containing
    the axis in projection); with ``span_of`` (a boolean mask or index array) only for those
    triangles, the others get NaN. ``axis_xyz``: :func:`axis_coordinates` of ``source_points``, when the
    caller has them (the same numbers).
    """
    tris = np.asarray(tris, dtype=np.int64)
    x, y, z = axis_coordinates(source_points, camera, hole) if axis_xyz is None else axis_xyz
    inside, crossed, along = axis_crossing(x, y, z, tris)
    span = np.full(len(tris), np.nan)
    sel = slice(None) if span_of is None else span_of
    sides = side_azimuths(x, y, tris[sel])
    span[sel] = np.maximum(np.maximum(sides[:, 0], sides[:, 1]), sides[:, 2])
    span = np.where(inside, np.pi, span)
    straddles = crossed & (along < 0) if order == 1 else crossed
    return straddles, span


def near_axis(source_points, tris, camera, hole, margin=1e-9, axis_xyz=None) -> np.ndarray:
    """(F,) bool: triangles that may be crossed by the observer-hole axis: False only for those whose
    corners all lie, by more than ``margin`` times their distance from the hole, on one side of one of
    two perpendicular planes through the axis. A superset of the triangles :func:`axis_geometry`
    finds crossed, and of every sub-triangle of theirs (sub-triangles lie inside their source
    triangle), for ``cull(..., axis_candidates=...)``. Non-finite corners make a candidate.
    ``axis_xyz``: :func:`axis_coordinates` of ``source_points``, when the caller has them."""
    tris = np.asarray(tris, dtype=np.int64)
    x, y, z = axis_coordinates(source_points, camera, hole) if axis_xyz is None else axis_xyz
    tol = margin * np.sqrt(x * x + y * y + z * z)  # margin times the distance from the hole (orthonormal axes)
    return _beside_axis(x, y, tris, tol) == 0


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
         image_circumference=None, image_outside_bits=None, axis_candidates=None):
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
    through (e.g. from :func:`near_axis` of their source triangles; others are not tested).
    """
    tris = np.asarray(tris, dtype=np.int64)
    rep = CullReport()
    keep = np.ones(len(tris), dtype=bool)
    bad_v = ~(valid[tris[:, 0]] & valid[tris[:, 1]] & valid[tris[:, 2]])
    rep.invalid_vertex = int(bad_v.sum())
    keep &= ~bad_v
    src_c = source_circumference
    if src_c is None:
        src_c = circumference(unit_directions(source_points, camera), tris)
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
                angle[at] = hole_angle(image_dirs.take(at, axis=0), camera, hole)
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
        outside = (bits[tris[:, 0]] & bits[tris[:, 1]] & bits[tris[:, 2]]) != 0  # all 3 behind one plane
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
            unit_directions(sub.positions, scene.camera), t)),
        image_circumference=_face_values(sub, face_src, coarse.circumference[order],
                                         lambda t: circumference(img.direction, t)),
        image_outside_bits=bits, axis_candidates=source.near_axis[face_src])
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
        drawn_dir /= np.maximum(mapping.row_norm(drawn_dir), 1e-300)[:, None]
        err = subdivision.angle_of_chord(chord_length(true.direction, drawn_dir))  # radians
        budget = frame.budget
        out[cand[err > B.UNDER_PATCH_FACTOR * budget.tolerance_px * budget.pixel_angle]] = True
    return out
