"""One object, one frame: source triangles -> first- and second-order image meshes (numpy only).

Steps (seed 000, section 3): map the source vertices and edge midpoints (mapping), measure rho per
edge and choose crack-free subdivision levels (subdivision), subdivide in world space, map the new
vertices, drop degenerate / invalid / off-screen triangles (culling), interpolate corner attributes
(UVs, normals) and compute the GR irradiance (illumination). The Blender layer only extracts a
:class:`SourceMesh` and uploads the :class:`ImageMesh` results.

Units: positions in Blender units (BU); light travel time as a length c*dt in BU (c = 1).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, replace

import numpy as np

from . import axis_patch, culling, illumination, mapping, silhouette, subdivision, thin_disc


@dataclass
class SourceMesh:
    """Evaluated source geometry in world space.

    positions (N, 3) BU; tris (T, 3) vertex indices; corner_uv (T, 3, 2) or None; material (T,) slot
    indices; corner_normals (T, 3, 3) unit normals in world space or None.
    """

    positions: np.ndarray
    tris: np.ndarray
    corner_uv: np.ndarray | None = None
    material: np.ndarray | None = None
    corner_normals: np.ndarray | None = None


@dataclass
class Settings:
    """The numeric settings of scene.grlens (see the add-on's properties for their meaning)."""

    max_tess_level: int = 64
    tess_a: float = 5.0
    tess_b: float = 0.75
    cull_ratio: float = 4.0
    orders: tuple = (1, 2)
    pixel_angle: float | None = None  # radians per pixel on the view sphere (caps subdivision)
    max_error_px: float | None = 0.25  # screen-space tolerance of the curved edges, pixels (with pixel_angle)


@dataclass
class ImageMesh:
    """One lensed image mesh.

    positions (V, 3) BU; tris (F, 3); corner_uv (F, 3, 2) or None; material (F,);
    light_travel_time (V,) c*dt in BU; irradiance (F, 3) per corner or None; report: culling counts;
    source_tri (F,) the source triangle of each face; source_position (V, 3) BU: the undistorted
    world point each image vertex shows; with a :class:`DiscEmitter`: redshift (V,) 1 + z (0 where
    gas has no circular orbit: r <= 1.5 r_s or on the disc axis) and disc_colour (V, 3) linear RGB
    (black there), else None. source_tri indexes the caller's SourceMesh.tris.
    """

    order: int
    positions: np.ndarray
    tris: np.ndarray
    corner_uv: np.ndarray | None
    material: np.ndarray
    light_travel_time: np.ndarray
    irradiance: np.ndarray | None
    report: culling.CullReport
    source_tri: np.ndarray = field(repr=False, default=None)
    source_position: np.ndarray = field(repr=False, default=None)
    redshift: np.ndarray | None = field(repr=False, default=None)
    disc_colour: np.ndarray | None = field(repr=False, default=None)


@dataclass
class DiscEmitter:
    """A source that is a thin accretion disc of gas on circular geodesics (seed 002): its image
    vertices get the redshift factor 1 + z and a colour from the Page-Thorne flux F(r) / (1 + z)^4.

    axis: unit vector (world) of the disc's angular momentum (prograde gas turns counter-clockwise
    about it; retrograde with ``prograde`` False); mode: "bolometric" or "blackbody";
    r_in: inner edge in r_s (>= 3, the ISCO); t_peak: emitted temperature (K) at the flux maximum;
    exposure: scale of the colour (1: the emitted maximum flux gives 1).
    """

    axis: np.ndarray
    prograde: bool = True
    mode: str = "bolometric"
    r_in: float = 3.0
    t_peak: float = 1.0e4
    exposure: float = 1.0


@dataclass
class Light:
    """A point light for GR illumination: position (BU), intensity I0, and the LUT for its radius."""

    position: np.ndarray
    intensity: float
    lut: object


def clean_source(src: SourceMesh) -> tuple[SourceMesh, int]:
    """Drop triangles with out-of-range (negative or >= N) indices, non-finite or repeated vertices.
    Returns (cleaned, number dropped)."""
    cleaned, n_bad, _ = _clean(src)
    return cleaned, n_bad


def _clean(src: SourceMesh):
    """clean_source, and the indices (into src.tris) of the triangles kept."""
    tris = np.asarray(src.tris).reshape(-1, 3)
    if not np.issubdtype(tris.dtype, np.integer):
        raise ValueError(f"triangle indices must be integers, got {tris.dtype}")
    tris = tris.astype(np.int64, copy=False)
    pos = np.asarray(src.positions, dtype=np.float64).reshape(-1, 3)
    t0, t1, t2 = tris[:, 0], tris[:, 1], tris[:, 2]
    in_range = (np.minimum(np.minimum(t0, t1), t2) >= 0) & (np.maximum(np.maximum(t0, t1), t2) < len(pos))
    finite = np.isfinite(pos[:, 0]) & np.isfinite(pos[:, 1]) & np.isfinite(pos[:, 2])
    if len(tris) and len(pos):
        s0, s1, s2 = (np.where(in_range, t, 0) for t in (t0, t1, t2))
        ok = in_range & finite[s0] & finite[s1] & finite[s2]
    else:
        ok = np.zeros(len(tris), bool)
    ok &= (t0 != t1) & (t1 != t2) & (t2 != t0)

    all_ok = bool(ok.all())

    def sel(a):
        return None if a is None else (np.asarray(a) if all_ok else np.asarray(a)[ok])

    cleaned = SourceMesh(pos, sel(tris), _finite_or_zero(sel(src.corner_uv)),
                         sel(src.material) if src.material is not None else np.zeros(int(ok.sum()), np.int64),
                         _finite_or_zero(sel(src.corner_normals)))
    return cleaned, int((~ok).sum()), np.flatnonzero(ok)


def _finite_or_zero(a):
    """Corner attributes with their non-finite values set to 0 (a NaN UV or normal of the user's mesh
    must not reach an image mesh; a zero normal receives no GR irradiance). Copies only if needed."""
    if a is None:
        return None
    a = np.asarray(a, dtype=np.float64)
    bad = ~np.isfinite(a)
    if bad.any():
        a = np.where(bad, 0.0, a)
    return a


def build_images(src: SourceMesh, scene: mapping.Scene, lut, settings: Settings,
                 light: Light | None = None, frustum_planes=None,
                 disc: DiscEmitter | None = None, _presplit: bool = True) -> dict[int, ImageMesh]:
    """Image meshes of the requested orders for one source mesh (see the module docstring).

    ``frustum_planes`` (K, 4), rows (n, d) with n . x + d >= 0 inside (world space, BU): image
    triangles outside are dropped, and source triangles whose corners and edge midpoints all map
    outside one plane are dropped before they are subdivided. An image whose extent on the view sphere
    is below one pixel (``settings.pixel_angle``) is not built at all if it is a second-order image
    (reported as ``below_pixel``); first-order images are always built, so small objects stay visible.
    """
    src, n_bad, kept_source = _clean(src)
    out = {}
    if len(src.tris) == 0:
        for order in settings.orders:
            out[order] = _empty(order, n_bad)
        return out
    edges = _edges_of(src.tris)
    n_pts = len(src.positions)
    ev0, ev1 = edges.verts[:, 0], edges.verts[:, 1]
    plane_v = mapping.plane_coordinates(src.positions, scene)
    planes = None if frustum_planes is None or not len(frustum_planes) else np.asarray(frustum_planes, np.float64)
    ring_levels = bool(settings.pixel_angle and settings.max_error_px)
    images_v = mapping.map_vertices_orders(src.positions, scene, lut, settings.orders, plane_v)
    # per source triangle, the same for both orders: undistorted circumference (from its edges' chords
    # on the view sphere), and whether the observer-hole axis may pass through it
    src_circ = _circumference_from_edges(
        _chord_lengths(culling.unit_directions(src.positions, scene.camera), edges.verts), edges.of_tri)
    axis_xyz = culling.axis_coordinates(src.positions, scene.camera, scene.hole)  # shared by the steps below
    src_near_axis = culling.near_axis(src.positions, src.tris, scene.camera, scene.hole, axis_xyz=axis_xyz)
    # per order: the image circumferences of the source triangles
    img_chord_lens = {o: _chord_lengths(images_v[o].direction, edges.verts) for o in settings.orders}
    img_circs = {o: _circumference_from_edges(img_chord_lens[o], edges.of_tri) for o in settings.orders}
    patching = ring_levels and settings.max_tess_level > 1
    closed_memo = []
    leaving = _Leaving(src.positions, scene, lut, settings.orders)

    def seen_closed() -> bool:  # a closed, outward-wound surface seen from outside (computed once)
        if not closed_memo:
            closed_memo.append(is_closed_outward(src.positions, src.tris, edges)
                               and winding_number(src.positions, src.tris, scene.camera) < 0.5)
        return closed_memo[0]

    crossings = axis_patch.find_crossings(src.positions, src.tris, scene.camera, scene.hole,
                                          src_near_axis, axis_xyz) if patching else []
    hole_rs = {}

    def hole_r_of(order):  # the angles (radians) of the vertices' images from the hole's direction
        if order not in hole_rs:
            with np.errstate(invalid="ignore"):
                hole_rs[order] = culling.hole_angle(images_v[order].direction, scene.camera, scene.hole)
        return hole_rs[order]

    if _presplit and patching and not crossings:
        pre = _presplit_levels(src, edges, src_circ, img_circs, images_v, scene, settings,
                               hidden=lambda t: _turned_away(src, t, leaving, settings.orders)
                               if seen_closed() else np.zeros(len(t), bool), axis_xyz=axis_xyz, hole_r=hole_r_of)
        if pre is not None:
            sub = subdivision.subdivide(src.positions, src.tris, edges, pre)

            def carried(corner_values):
                if corner_values is None:
                    return None
                return sub.corner_values(corner_values)

            fine = SourceMesh(sub.positions, sub.tris, carried(src.corner_uv), src.material[sub.source_tri],
                              carried(src.corner_normals))
            out = build_images(fine, scene, lut, settings, light, frustum_planes, disc, _presplit=False)
            for img in out.values():
                img.source_tri = kept_source[sub.source_tri[img.source_tri]]
                img.report.extra["bad_source_triangles"] = n_bad
                img.report.presplit = len(sub.tris) - len(src.tris)
            return out
    patches = axis_patch.build_patches(src.positions, src.tris, edges.of_tri, len(edges.verts), scene, lut,
                                       settings.orders, settings.pixel_angle, settings.max_error_px,
                                       crossings=crossings, closed=seen_closed, leaving=leaving.at,
                                       axis_xyz=axis_xyz) if crossings else []
    xy_memo = []

    def axis_xy():  # (N, 2) axis coordinates x, y of the source vertices (stacked once, when needed)
        if not xy_memo:
            xy_memo.append(np.column_stack(axis_xyz[:2]))
        return xy_memo[0]

    # edge midpoints are mapped only where a level above 1 is possible: an edge whose image spans at
    # most one pixel keeps level 1 whatever its curvature (see subdivision.edge_levels); the orders'
    # edges are mapped together
    chords = {o: subdivision.angle_of_chord(img_chord_lens[o]) for o in settings.orders}
    probes = {o: np.flatnonzero(~(chords[o] <= settings.pixel_angle)) if settings.pixel_angle else np.arange(len(ev0))
              for o in settings.orders}
    probed = np.unique(np.concatenate([np.zeros(0, np.int64)] + list(probes.values())))
    mids = mapping.map_vertices_orders(0.5 * (src.positions.take(ev0[probed], axis=0)
                                              + src.positions.take(ev1[probed], axis=0)), scene, lut, settings.orders)
    for order in settings.orders:
        order_patches = [p for p in patches if order in p.orders]
        replaced = None
        if order_patches:
            replaced = np.zeros(len(src.tris), bool)
            for p in order_patches:
                replaced[p.replaced] = True
        img_v = images_v[order]
        img_circ = img_circs[order]
        chord = chords[order]
        probe = probes[order]
        p0, p1 = ev0[probe], ev1[probe]
        img_m = _subset(mids[order], np.searchsorted(probed, probe))
        if order == 2 and _below_pixel(img_v, img_m, settings.pixel_angle):
            out[order] = _empty(order, n_bad, below_pixel=len(src.tris))
            continue
        fit = settings  # the settings of this order's levels: a thin image's tighter tolerance (THIN_FACTOR)
        if ring_levels:  # the images' angles from the hole's direction (radians)
            hole_r = hole_r_of(order)
        if ring_levels and THIN_FACTOR != 1.0 and _thin_image(hole_r, settings.pixel_angle):
            fit = replace(settings, max_error_px=settings.max_error_px * THIN_FACTOR)
        rho = subdivision.rho(img_v.direction.take(p0, axis=0), img_v.direction.take(p1, axis=0), img_m.direction)
        levels = np.ones(len(ev0), dtype=np.int64)  # edges not probed keep level 1
        strip_tri = None
        levels[probe] = subdivision.edge_levels(rho, fit.max_tess_level, fit.tess_a, fit.tess_b,
                                                chord[probe], fit.pixel_angle, fit.max_error_px)
        if ring_levels:
            # silhouette edges (and the ring levels of silhouette triangles) aim at the tighter
            # tolerance; the silhouette is found only around the edges whose level that would change
            tight = subdivision.edge_levels(rho, fit.max_tess_level, fit.tess_a, fit.tess_b,
                                            chord[probe], fit.pixel_angle,
                                            fit.max_error_px * SILHOUETTE_FACTOR)
            raise_edges = tight != levels[probe]
            cap = (lambda t: _span_cap(order_patches, src.tris.take(t, axis=0), axis_xy())) if order_patches else None
            on_sheets = None
            if order_patches:  # the source triangles some patch draws a part of
                on_sheets = np.zeros(len(src.tris), bool)
                for p in order_patches:
                    on_sheets[p.face_src] = on_sheets[p.vertex_tri] = on_sheets[p.replaced] = True
            hidden = (lambda t: _turned_away(src, t, leaving, (order,)) if seen_closed() else np.zeros(len(t), bool))
            cand, want, sharp, gap_want, r_px = _ring_levels(src, src_circ, img_circ, scene, hole_r, order, fit,
                                                             replaced, cap, axis_xyz, on_sheets, hidden)
            want0 = want
            maybe = sharp != want
            if raise_edges.any() or maybe.any():
                sil_edge, sil_tri = _silhouette(src, edges, leaving, order, np.concatenate(
                    [probe[raise_edges], edges.of_tri[cand[maybe]].ravel()]))
                up = raise_edges & sil_edge[probe]
                levels[probe[up]] = tight[up]
                want = np.where(maybe & sil_tri[cand] & (sharp <= SILHOUETTE_RING_LEVEL_MAX), sharp, want)
            if order_patches and cand.size and (order in RING_EDGE_ORDERS
                                                or not all(p.complete for p in order_patches)):
                # next to a patch this order's ring is less than a pixel wide, or the patch stops
                # short of the surface's fold: the ring's edge there needs the silhouette's tolerance,
                # whatever the level (see RING_EDGE_REACH)
                reach = RING_EDGE_REACH * max(p.radius for p in order_patches)
                xy, cand_tris = axis_xy(), src.tris.take(cand, axis=0)
                near = culling.within_axis_distance(xy[:, 0], xy[:, 1], cand_tris, reach)
                raised = sharp
                if order not in RING_EDGE_ORDERS:  # only where an incomplete patch leaves a gap
                    gap = np.zeros(cand.size, bool)
                    for p in order_patches:
                        gap |= axis_patch.touches_gap(p, cand_tris, xy[:, 0], xy[:, 1])
                    near &= gap
                    raised = gap_want
                want = np.where(near, np.maximum(want, raised), want)
            strip = np.zeros(cand.size, bool)
            if STRIP_BAND_PX and cand.size:
                strip = _strip_candidates(src, cand, want, r_px, leaving, order, axis_xy(), scene, lut,
                                          settings.pixel_angle)
            if strip.any():
                # strips: each side gets the level of its own azimuth (see STRIP_BAND_PX)
                tight = (want > want0)[strip]  # raised to the silhouette's tolerance
                side = _side_levels(axis_xy(), src.tris.take(cand[strip], axis=0), r_px[strip],
                                    fit.max_error_px * np.where(tight, SILHOUETTE_FACTOR, STRIP_TOLERANCE), fit)
                np.maximum.at(levels, edges.of_tri[cand[strip]].ravel(), side.ravel())
                strip_tri = np.zeros(len(src.tris), bool)
                strip_tri[cand[strip]] = True
            np.maximum.at(levels, edges.of_tri[cand[~strip]].ravel(), np.repeat(want[~strip], 3))
        tri_sel, out_v = _inside_frustum(img_v, img_m, probe, src.tris, edges, planes)
        n_pre = len(src.tris) - len(tri_sel)
        if replaced is not None:  # drawn by the axis patches instead
            by_patch = replaced[tri_sel]
            n_replaced = int(by_patch.sum())
            tri_sel = tri_sel[~by_patch]
        n_back = 0
        lv = levels.take(edges.of_tri.take(tri_sel, axis=0))
        tri_level = np.maximum(np.maximum(lv[:, 0], lv[:, 1]), lv[:, 2])
        split = tri_sel[tri_level > 1]
        if split.size and int((tri_level[tri_level > 1] ** 2).sum()) >= max(BACK_FACE_MIN_PIECES, len(src.tris)) \
                and seen_closed():
            # hidden behind the object's own front: not subdivided (see BACK_FACE_MARGIN)
            away = split[_turned_away(src, split, leaving, (order,))]
            if away.size:
                drop = np.zeros(len(src.tris), bool)
                drop[away] = True
                tri_sel = tri_sel[~drop[tri_sel]]
                n_back = int(away.size)
        strips = None
        if strip_tri is not None:
            strips = (strip_tri[tri_sel], axis_xy())
        sub = subdivision.subdivide(src.positions, src.tris[tri_sel],
                                    subdivision.Edges(edges.verts, edges.of_tri[tri_sel]), levels, strips)
        img = _map_subdivided(sub, n_pts, img_v, scene, lut, order)
        face_src = tri_sel[sub.source_tri]  # each face's source triangle (index into src.tris)
        bits = None
        if out_v is not None:  # frustum bits of the subdivided vertices: the source corners' are known
            is_corner = sub.vertex_key < n_pts
            bits = np.empty(len(sub.vertex_key), dtype=np.int64)
            bits[is_corner] = out_v[sub.vertex_key[is_corner]]
            bits[~is_corner] = culling.outside_bits(img.position[~is_corner], planes)
        keep, report = culling.cull(
            sub.tris, img.direction, img.valid, sub.positions, scene.camera, settings.cull_ratio, planes,
            img.position, scene.hole, order, settings.pixel_angle, settings.max_error_px,
            source_circumference=_face_values(sub, face_src, src_circ, lambda t: culling.circumference(
                culling.unit_directions(sub.positions, scene.camera), t)),
            image_circumference=_face_values(sub, face_src, img_circ,
                                             lambda t: culling.circumference(img.direction, t)),
            image_outside_bits=bits, axis_candidates=src_near_axis[face_src])
        report.outside_frustum += n_pre
        report.back_face = n_back
        if order_patches and UNDER_PATCH_ERROR is not None:  # the patch draws these more exactly
            covered = _coarse_under_patches(order_patches, order, sub.tris, face_src, sub.positions, img, keep,
                                            scene, lut, settings, len(src.tris))
            report.patch_covered = int(covered.sum())
            if report.patch_covered:
                keep &= ~covered
                report.kept -= report.patch_covered
        report.extra["bad_source_triangles"] = n_bad
        everything = bool(keep.all())
        kept = None if everything else np.flatnonzero(keep)
        tris = sub.tris if everything else sub.tris.take(kept, axis=0)
        used = mapping.used_vertices(tris, len(sub.positions))
        if used.size == len(sub.positions):  # every vertex is used: indices stay as they are
            image_tris = tris
        else:
            remap = np.full(len(sub.positions), -1, dtype=np.int64)
            remap[used] = np.arange(used.size)
            image_tris = remap.take(tris)
        src_tri = face_src if everything else face_src.take(kept)
        # the faces' corners in their source triangles: None (whole source triangles src_tri) or rows
        # (row barycentrics, row source triangle, face corner rows, unit rows; see subdivision.Subdivided)
        rows = None
        if not sub.identity:
            rows = (sub.row_bary, tri_sel.take(sub.row_src),
                    sub.corner_row if everything else sub.corner_row.take(kept, axis=0), sub.n_unit_rows)
        v_pos, v_dir = img.position.take(used, axis=0), img.direction.take(used, axis=0)
        v_dist, v_src = img.distance[used], sub.positions.take(used, axis=0)
        patch_corners = None
        if order_patches:
            report.patch_replaced = n_replaced
            parts = _patch_parts(order_patches, order, planes, len(used))
            if parts is not None:
                p_tris, p_src, patch_corners, p_pos, p_dir, p_dist, p_spos = parts
                image_tris = np.concatenate([image_tris, p_tris])
                v_pos, v_dir = np.concatenate([v_pos, p_pos]), np.concatenate([v_dir, p_dir])
                v_dist, v_src = np.concatenate([v_dist, p_dist]), np.concatenate([v_src, p_spos])
                report.kept += len(p_tris)
                report.patch_faces = len(p_tris)

        def corner_values(values):  # (F, 3, K) per face corner, subdivided faces then patch faces
            own = _carry(values, src_tri, rows)
            if patch_corners is None:
                return own
            return np.concatenate([own, _patch_corner_values(values, p_src, *patch_corners)])

        corner_uv = None
        if src.corner_uv is not None:
            corner_uv = corner_values(src.corner_uv)
        irr = None
        if light is not None and src.corner_normals is not None:
            n = corner_values(src.corner_normals)
            n /= np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-300)
            pts = v_src.take(image_tris.ravel(), axis=0)
            e, _ = illumination.irradiance(pts, n.reshape(-1, 3), light.position, scene.hole, scene.r_s,
                                           light.lut, light.intensity)
            irr = e.reshape(-1, 3)
        if patch_corners is not None:
            src_tri = np.concatenate([src_tri, p_src])
        redshift = colour = None
        if disc is not None:
            pts = v_src
            redshift = thin_disc.vertex_redshift_from_direction(pts, scene.hole, scene.camera, scene.r_s,
                                                                disc.axis, v_dir, disc.prograde)
            r = np.linalg.norm(pts - scene.hole, axis=1) / scene.r_s
            colour = np.nan_to_num(thin_disc.disc_colour(r, redshift, disc.mode, r_in=disc.r_in,
                                                         t_peak=disc.t_peak, exposure=disc.exposure))
            redshift = np.nan_to_num(redshift, nan=0.0)  # 0: no circular orbit there (r <= 1.5 r_s, axis)
        out[order] = ImageMesh(order=order, positions=v_pos, tris=image_tris,
                               corner_uv=corner_uv, material=src.material[src_tri],
                               light_travel_time=v_dist, irradiance=irr, report=report,
                               source_tri=kept_source[src_tri], source_position=v_src,
                               redshift=redshift, disc_colour=colour)
    return out


def is_closed_outward(points, tris, edges: subdivision.Edges | None = None) -> bool:
    """True if the triangles ``tris`` of ``points`` (BU) form closed surfaces with consistent winding
    (every edge used by exactly two triangles, once in each direction) that enclose a positive
    volume (normals from the winding point outwards)."""
    tris = np.asarray(tris, dtype=np.int64)
    if len(tris) == 0:
        return False
    edges = edges if edges is not None else subdivision.mesh_edges(tris)
    forward = np.where(tris < np.roll(tris, -1, axis=1), 1, -1)  # edge k: corner k -> k+1
    n_e = len(edges.verts)
    uses = np.bincount(edges.of_tri.ravel(), minlength=n_e)
    balance = np.bincount(edges.of_tri.ravel(), weights=forward.ravel(), minlength=n_e)
    if not (np.all(uses == 2) and np.all(balance == 0)):
        return False
    p = np.asarray(points, dtype=np.float64)
    p = p - p[tris[0, 0]]  # volume about a vertex: no cancellation far from the origin
    p0, p1, p2 = (p.take(tris[:, k], axis=0) for k in range(3))
    return bool(np.einsum("ij,ij->", p0, np.cross(p1, p2)) > 0)


def winding_number(points, tris, query) -> float:
    """How many times the triangles ``tris`` of ``points`` (BU) wind around the point ``query`` (3,; BU):
    1 inside a closed surface with outward winding, 0 outside (the sum of the solid angles the
    triangles subtend at ``query`` over 4 pi; Van Oosterom and Strackee's formula)."""
    tris = np.asarray(tris, dtype=np.int64)
    p = np.asarray(points, dtype=np.float64) - np.asarray(query, np.float64)
    a, b, c = (p.take(tris[:, k], axis=0) for k in range(3))
    la, lb, lc = (mapping.row_norm(v) for v in (a, b, c))
    num = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la
           + np.einsum("ij,ij->i", c, a) * lb)
    return float(np.nansum(2.0 * np.arctan2(num, den)) / (4.0 * np.pi))


_EDGE_CACHE: dict = {}
_EDGE_CACHE_SIZE = 8


def _edges_of(tris) -> subdivision.Edges:
    """subdivision.mesh_edges, remembered for the last few topologies (animated meshes usually keep
    theirs from frame to frame; the key is a digest of the index array)."""
    key = hashlib.blake2b(np.ascontiguousarray(tris).tobytes(), digest_size=16).digest() + bytes(str(tris.shape), "ascii")
    edges = _EDGE_CACHE.get(key)
    if edges is None:
        edges = subdivision.mesh_edges(tris)
        if len(_EDGE_CACHE) >= _EDGE_CACHE_SIZE:
            _EDGE_CACHE.pop(next(iter(_EDGE_CACHE)))
        _EDGE_CACHE[key] = edges
    return edges


def _chord_lengths(directions, edge_verts) -> np.ndarray:
    """(E,) chord length between the unit ``directions`` of each edge's end points (dimensionless)."""
    return culling.chord_length(directions.take(edge_verts[:, 1], axis=0),
                                directions.take(edge_verts[:, 0], axis=0))


def _circumference_from_edges(chord_lengths, of_tri) -> np.ndarray:
    """(T,) culling.circumference of the triangles, from the chord lengths of their edges."""
    return chord_lengths[of_tri[:, 0]] + chord_lengths[of_tri[:, 1]] + chord_lengths[of_tri[:, 2]]


def _face_values(sub: subdivision.Subdivided, face_src, per_source, compute) -> np.ndarray:
    """(F,) a per-triangle quantity for the faces of ``sub``: taken from ``per_source`` (indexed by
    ``face_src``) for the faces passed through unsplit, ``compute(tris)`` for the split ones."""
    n = sub.n_pass
    if n == len(sub.tris):
        return per_source[face_src]
    out = np.empty(len(sub.tris))
    out[:n] = per_source[face_src[:n]]
    out[n:] = compute(sub.tris[n:])
    return out


PATCH_SEAM_JUMP = 0.1
"""A patch face takes its corners' values (UVs, normals) from the source triangle under each corner,
unless they differ by more than this from the values of the face's own source triangle carried to
the corner (a seam: a UV island's edge, a sharp normal), where it takes those for all three."""


def _patch_corner_values(values, face_src, bary, vertex_tri, vertex_bary, corner_row) -> np.ndarray:
    """(F, 3, K) corner values of patch faces (see _patch_parts and PATCH_SEAM_JUMP) from the source
    triangles' corner values ``values`` (T, 3, K)."""
    values = np.asarray(values, dtype=np.float64)
    own = subdivision.carry_rows(vertex_bary, vertex_tri, corner_row, values)
    # only faces with a corner on another triangle than their own can be across a seam (where all
    # three lie on it, both ways interpolate in that triangle at the same point)
    other = np.flatnonzero((vertex_tri.take(corner_row) != face_src[:, None]).any(axis=1))
    if other.size:
        carried = np.matmul(bary[other], values.take(face_src[other], axis=0))  # the face's triangle, extrapolated
        seam = (np.abs(own[other] - carried) > PATCH_SEAM_JUMP).any(axis=(1, 2))
        own[other[seam]] = carried[seam]
    return own


def _carry(corner_values, src_tri, rows):
    """Corner values (F, 3, K) of the image faces from the source triangles' corner values (T, 3, K):
    the faces' own source triangles' (``src_tri``) when ``rows`` is None, else interpolated at the
    rows (row_bary, row_src, corner_row, n_unit) of subdivision.carry_rows."""
    corner_values = np.asarray(corner_values, dtype=np.float64)
    if rows is None:
        return corner_values.take(src_tri, axis=0)
    row_bary, row_src, corner_row, n_unit = rows
    return subdivision.carry_rows(row_bary, row_src, corner_row, corner_values, n_unit)


RING_MAGNIFICATION = 2.0
"""Source triangles whose image circumference exceeds this many times their own are treated as
lying in a strongly lensed (Einstein-ring) region by :func:`_ring_levels`."""


SILHOUETTE_FACTOR = 0.25
"""Silhouette edges (silhouette.py) are subdivided to this fraction of ``max_error_px``: they alone
decide which pixels an image covers, and next to the Einstein ring the second-order images are less
than a pixel wide, so a tenth of a pixel there changes the coverage by tens of percent. Levels grow
as the square root of the inverse tolerance, so this costs twice the segments on those edges only."""


SILHOUETTE_RING_LEVEL_MAX = 24
"""Ring levels (_ring_levels) of silhouette triangles aim at the silhouette's tolerance only up to this
level. Beyond it a triangle lies so close to the axis that doubling its level quadruples tens of
thousands of pieces, most of which the ring culling drops anyway (the sphere grazing the axis at 171
degrees of its orbit went from 38k to 100k pieces per order); up to it the tighter tolerance is what
brings the 180-degree view's second-order ring to the target (benchmarks/bench_accuracy.py)."""


RING_EDGE_REACH = 2.0
RING_EDGE_ORDERS = (2,)
GAP_FACTOR = 0.5
"""Magnified source triangles within RING_EDGE_REACH patch radii of the axis (axis_patch.Patch.radius)
get the ring levels of the silhouette's tolerance (SILHOUETTE_FACTOR), without the cap of
SILHOUETTE_RING_LEVEL_MAX, in the orders RING_EDGE_ORDERS; in the other orders those that may meet
a cell that an incomplete patch (Patch.complete False) does not draw (axis_patch.touches_gap) get
the levels of GAP_FACTOR times the tolerance (0.25 instead of 0.5 adds a third of the first-order
pieces at 171 and 189 deg for 0.41 / 0.37% instead of 0.44 / 0.41% of the pixels differing).
- Second order: its pieces draw the ring next to the patch, which is less than a pixel wide, so the
  straight sides of a piece that fall a quarter of a pixel inside it flip a pixel at its edge. With
  the sphere grazing the axis in front of the hole, 1-2% of the pixels differed (355 and 5 deg of its
  orbit), 0.3-0.5% with the rule, at twice the second-order pieces
  (benchmarks/bench_accuracy.py --orbit 5).
- First order: its ring is wide where the patch is complete, and the rule would only double its
  pieces (180 deg: 26k -> 53k). Where the axis crosses the surface near its fold and the patch is
  not clipped to it (axis_patch.CLIP_REACH; with the plain grid at 171-172 and 188 deg), the patch
  stops short and kept pieces draw the ring's edge: with the plain grid 0.70% -> 0.44% of the pixels
  differ at 171 deg (2.0% -> 0.4% before the patch's circles followed the steep surface there,
  axis_patch.STEEP_RATIO), at a quarter more time in those frames."""

RING_LEVEL_MARGIN = 0.75
"""Fraction of the largest allowed azimuth per piece that :func:`_ring_levels` aims at: pieces
of a triangle subdivided uniformly in space cover unequal azimuths, and the culling test of the same
bound (culling.cull) must not catch the widest of them."""


BACK_FACE_MARGIN = 0.1
"""On a closed, outward-wound surface seen from outside (is_closed_outward, winding_number), a
triangle turned away from the camera along the rays of an order by more than this at all three
corners (silhouette.turned_away: the cosine between its normal and the direction in which light
leaves the corner towards the camera below -BACK_FACE_MARGIN) is hidden behind the surface's own
front, so it is not subdivided and its image is not built (CullReport.back_face). Near the
Einstein ring most of the pieces of a ring frame are such back faces (the sphere at 170 deg: 60% of
the first-order pieces, at 180 deg 40% of the second-order ones). Back faces closer to the
silhouette are kept: where the front's straight pieces fall short of the curved outline, the fold
behind it fills in. Measured on the benchmark sphere (benchmarks/bench_accuracy.py), coverage
mismatch at 170 / 180 deg: 0.34% / 0.47% with margin 0, 0.21% / 0.37% with 0.05, 0.21% / 0.33%
with 0.1 and 0.2 (0.1 is 3-6% faster in those frames than 0.2)."""

BACK_FACE_MIN_PIECES = 4096
"""Back faces are looked for only when the subdivided triangles of an order would make at least
this many pieces (and at least as many as the mesh has triangles): the test looks up the rays of
their corners and checks that the mesh is closed, which costs more than it saves on a mesh that is
hardly subdivided."""


class _Leaving:
    """The unit directions (illumination.towards_observer) in which light leaves the source vertices
    towards the camera, per order: looked up on demand, for all the build's orders at once, and kept
    for the rest of the build (the silhouette and the back faces need them at the same corners)."""

    def __init__(self, points, scene, lut, orders):
        self.points, self.scene, self.lut, self.orders = points, scene, lut, tuple(orders)
        self.known = np.zeros(len(points), bool)
        self.d = {o: np.full((len(points), 3), np.nan) for o in self.orders}

    def at(self, vertices, order) -> np.ndarray:
        """(len(vertices), 3) the directions of ``order`` at the source vertices ``vertices``."""
        new = vertices[~self.known[vertices]]
        if new.size:
            new = np.unique(new)
            for o, (d, _) in illumination.towards_observer(self.points.take(new, axis=0), self.scene, self.lut,
                                                           self.orders).items():
                self.d[o][new] = d
            self.known[new] = True
        return self.d[order].take(vertices, axis=0)


def _turned_away(src, tri_idx, leaving: _Leaving, orders) -> np.ndarray:
    """(len(tri_idx),) bool: the source triangles ``tri_idx`` turned away (BACK_FACE_MARGIN) along the
    rays of every order in ``orders``; only their corners are looked up."""
    corners, pts, local = silhouette.compact(src.positions, src.tris.take(tri_idx, axis=0))
    away = np.ones(len(tri_idx), bool)
    for o in orders:
        away &= silhouette.turned_away(pts, local, leaving.at(corners, o), BACK_FACE_MARGIN)
    return away


def _silhouette(src, edges, leaving: _Leaving, order, of_edges):
    """silhouette.silhouette of ``order`` as (edge mask (E,), triangle mask (T,)), right for the edges
    ``of_edges`` (indices) and for the triangles whose three edges are among them; only the corners of
    the triangles around those edges are looked up."""
    mark = np.zeros(len(edges.verts), bool)
    mark[of_edges] = True
    near = np.flatnonzero(mark.take(edges.of_tri).any(axis=1))
    corners, pts, local = silhouette.compact(src.positions, src.tris.take(near, axis=0))
    edge, tri_near = silhouette.silhouette(pts, local, edges.of_tri.take(near, axis=0), len(edges.verts),
                                           leaving.at(corners, order))
    tri = np.zeros(len(src.tris), bool)
    tri[near] = tri_near
    return edge, tri


def _ring_candidates(src_circ, img_circ) -> np.ndarray:
    """Indices of the source triangles magnified more than RING_MAGNIFICATION (see _ring_levels)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.flatnonzero(img_circ > RING_MAGNIFICATION * src_circ)


EDGE_ON_RATIO = 0.1
"""See :func:`_ring_levels` (``on_sheets``): triangles off the patches' sheets whose projection along
the axis has under this fraction of their area get levels for the azimuth next to the axis."""


def _ring_levels(src, src_circ, img_circ, scene, hole_r, order, settings: Settings, skip=None, cap=None,
                 axis_xyz=None, on_sheets=None, hidden=None):
    """The levels that strongly magnified source triangles near the axis need so that their
    sub-triangles are narrow enough on screen (see culling.ring_sagitta: a piece covering an azimuth d
    at an angular radius R from the hole's direction has straight sides R (1 - cos(d/2)) inside the
    ring): a triangle covering D gets level ceil(D / (RING_LEVEL_MARGIN d_max)),
    d_max = culling.max_ring_span(R_px, tolerance), on all its edges (levels are per edge, so
    neighbours stay crack-free), capped at max_tess_level. ``src_circ``, ``img_circ``: the source
    triangles' circumferences (culling.circumference) undistorted and of this order's image;
    ``hole_r`` (N,): the angles (radians) of the source vertices' images of this order from the hole's
    direction (culling.hole_angle); ``skip`` (T,) bool: triangles left alone (replaced by an axis patch);
    ``cap``: None, or a function of the candidates' indices giving the most azimuth (radians) each
    must be cut into pieces narrow in (:func:`_span_cap`), where that is less than the azimuth it covers;
    ``axis_xyz``: culling.axis_coordinates of the source positions, when the caller has them;
    ``on_sheets`` (T,) bool: the triangles axis patches draw parts of (when the mesh has patches). A
    candidate on none of them that passes beside the axis at d_min (e.g. a face of a box parallel to
    the axis, next to the face the axis crosses) covers the azimuth h / d_min per length h next to the
    axis, far more than its average: its level counts that (as _presplit_levels does for meshes
    without patches), else its pieces there are culled and leave a gap in the ring; ``hidden``: a
    function of triangle indices giving those hidden in this order (back faces), which do not need it.

    Returns (cand, want, sharp, gap, corner_px): the candidate triangles (indices), their levels for
    ``max_error_px``, for SILHOUETTE_FACTOR * max_error_px (the silhouette's tolerance) and for
    GAP_FACTOR * max_error_px (see RING_EDGE_REACH), and the angular radii (pixels) of their corners'
    images (len(cand), 3)."""
    top = int(np.clip(settings.max_tess_level, 1, subdivision.GRID))
    tris = src.tris
    cand = _ring_candidates(src_circ, img_circ)
    if skip is not None:
        cand = cand[~skip[cand]]
    if cand.size == 0:
        return cand, np.ones(0, np.int64), np.ones(0, np.int64), np.ones(0, np.int64), np.zeros((0, 3))
    _, span = culling.axis_geometry(src.positions, tris[cand], scene.camera, scene.hole, order, axis_xyz=axis_xyz)
    if cap is not None:
        span = np.fmin(span, cap(cand))
    off = np.flatnonzero(~on_sheets[cand]) if on_sheets is not None else np.zeros(0, np.int64)
    if off.size and hidden is not None:
        off = off[~hidden(cand[off])]
    if off.size:
        x, y, _ = culling.axis_coordinates(src.positions, scene.camera, scene.hole) if axis_xyz is None else axis_xyz
        t_off = tris.take(cand[off], axis=0)
        # only triangles nearly parallel to the axis (projected area under EDGE_ON_RATIO of their own):
        # the others' pieces spread their azimuth evenly enough for the level of the azimuth they span
        proj = np.abs(culling.projected_area(x, y, t_off))
        own = mapping.row_norm(silhouette.normals(src.positions, t_off))
        keep = proj < EDGE_ON_RATIO * own
        off, t_off = off[keep], t_off[keep]
    if off.size:
        d_min = culling.axis_distance(x, y, t_off)
        with np.errstate(invalid="ignore", divide="ignore"):
            near = np.where(d_min > 0, culling.longest_side(x, y, t_off) / d_min, np.nan)
        span[off] = np.fmax(span[off], near)
    with np.errstate(invalid="ignore", divide="ignore"):
        radius = hole_r / settings.pixel_angle  # px
        corner_px = radius.take(tris.take(cand, axis=0))
        r_px = np.maximum(np.maximum(corner_px[:, 0], corner_px[:, 1]), corner_px[:, 2])
        out = []
        out = [_azimuth_levels(span, culling.max_ring_span(r_px, tol), top)
               for tol in (settings.max_error_px, settings.max_error_px * SILHOUETTE_FACTOR,
                           settings.max_error_px * GAP_FACTOR)]
    return cand, out[0], out[1], out[2], corner_px


def _azimuth_levels(span, d_max, top) -> np.ndarray:
    """Levels (integers 1 .. ``top``) that cut an azimuth ``span`` (radians) about the axis into pieces
    of at most RING_LEVEL_MARGIN * ``d_max`` each (the subdivision is uniform in space, not in
    azimuth, so it aims below the bound); 1 where either is NaN."""
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.ceil(span / (RING_LEVEL_MARGIN * d_max))
    return np.clip(np.nan_to_num(n, nan=1.0), 1, top).astype(np.int64)


def _span_cap(patches, tris, xy) -> np.ndarray:
    """(T,) radians: how much azimuth about the axis the pieces of the triangles ``tris`` (T, 3) (source
    vertices' axis coordinates ``xy`` (N, 2), BU) need to be narrow in, at most, next to the axis
    ``patches``: h / delta, h the triangle's longest side across the axis and delta the distance
    from the axis beyond which a patch may leave part of it undrawn (axis_patch.open_distance); inf
    where no patch draws any of it. Nearer the axis the patch draws the surface, and a piece there
    that covers too wide an azimuth is culled (culling.cull, the ring's sagitta), so the ring levels
    (_ring_levels) need only make the pieces narrow enough from delta outwards, not around the whole
    turn that a triangle containing the axis covers (the crossed triangles of a patch that stops
    short of the surface's fold: the sphere at 172 deg, 129k -> 100k pieces)."""
    x, y = xy[:, 0], xy[:, 1]
    out = np.full(len(tris), np.inf)
    near = np.flatnonzero(culling.within_axis_distance(x, y, tris, max(p.radius for p in patches)))
    if near.size == 0:
        return out
    t = tris.take(near, axis=0)
    delta = np.full(len(t), np.inf)
    for p in patches:
        delta = np.minimum(delta, axis_patch.open_distance(p, t, x, y))
    with np.errstate(divide="ignore", invalid="ignore"):
        out[near] = np.where(np.isfinite(delta), culling.longest_side(x, y, t) / delta, np.inf)
    return out


THIN_PX = 2.0
THIN_FACTOR = 0.5
"""An order whose whole image lies within a band of THIN_PX pixels in radius about the hole's
direction (the second-order image of an object in front of the hole, around the Einstein ring) gets
its levels for THIN_FACTOR times ``max_error_px``: such an image is about a pixel wide, so every one
of its pixels is an edge pixel and a fraction of a pixel flips it. The benchmark sphere grazing the
axis in front of the hole (benchmarks/bench_accuracy.py, 640x360, with strips): coverage mismatch
at 340 / 350 / 355 / 10 deg 0.51 / 0.53 / 0.45 / 0.37% -> 0.10 / 0.25 / 0.34 / 0.22%, for 1.4-1.8x
the second-order pieces of those frames. The culling keeps ``max_error_px``."""


def _thin_image(hole_r, pixel_angle) -> bool:
    """True when the images of the source vertices, at the angles ``hole_r`` (radians) from the hole's
    direction, lie within THIN_PX pixels of radius about it (see THIN_PX)."""
    r = hole_r[np.isfinite(hole_r)]
    return bool(r.size) and float(r.max() - r.min()) < THIN_PX * pixel_angle


STRIP_BAND_PX = 1.0
STRIP_MIN_LEVEL = 3
STRIP_TOLERANCE = 0.25
"""Ring triangles (_ring_levels) whose image lies within a band of STRIP_BAND_PX pixels in radius
about the hole's direction (their corners' and that of their point nearest to the axis), that face one way at all corners (no fold inside) and
whose level is at least STRIP_MIN_LEVEL are cut into strips across the ring (subdivision.subdivide,
``strips``) instead of the uniform grid: the ring's straight-side bound concerns the pieces' extent
in azimuth only, and across a band that narrow straight strips stay within the tolerance. Each side
gets the level of its own azimuth (_side_levels) for STRIP_TOLERANCE times ``max_error_px`` (the
silhouette's tolerance where the triangle's level was raised to it): pieces grow with the level,
not its square, so the tighter aim costs little. 0 turns strips off.

Measured on the benchmark sphere (benchmarks/bench_accuracy.py, 640x360), second-order pieces at
170 / 180 / 0 deg: 19.7k / 17.6k / 25.0k -> 11.7k / 8.5k / 13.4k (with THIN_FACTOR at 0 deg),
coverage mismatch 0.21 / 0.33% -> 0.19 / 0.36% at 170 / 180 deg. A band of 2 px put the texture
0.6 px off at 180 deg (screen error p99); 1.5 px gained ~1 ms."""


def _strip_candidates(src, cand, want, corner_px, leaving: _Leaving, order, xy, scene, lut, pixel_angle) -> np.ndarray:
    """(len(cand),) bool: the ring triangles ``cand`` to cut into strips (see STRIP_BAND_PX). Their image
    must lie in the band all over, not only at the corners: also the image of the triangle's point
    nearest to the axis (an edge passing close to the axis comes close to the Einstein ring in
    between; a triangle containing the axis covers the whole ring) is checked; ``xy`` (N, 2): the
    source vertices' axis coordinates."""
    c0, c1, c2 = corner_px[:, 0], corner_px[:, 1], corner_px[:, 2]
    band = np.maximum(np.maximum(c0, c1), c2) - np.minimum(np.minimum(c0, c1), c2)
    ok = (band < STRIP_BAND_PX) & (want >= STRIP_MIN_LEVEL)
    if ok.any():
        at = np.flatnonzero(ok)
        near_px = _nearest_point_radius(src, cand[at], xy, scene, lut, order, pixel_angle)
        lo = np.minimum(np.minimum(np.minimum(c0[at], c1[at]), c2[at]), near_px)
        hi = np.maximum(np.maximum(np.maximum(c0[at], c1[at]), c2[at]), near_px)
        ok[at] = hi - lo < STRIP_BAND_PX  # NaN (no image there, or the axis itself): not a strip
    if ok.any():
        corners, pts, local = silhouette.compact(src.positions, src.tris.take(cand[ok], axis=0))
        sign = silhouette.facing_signs(pts, local, leaving.at(corners, order))
        ok[ok] = (sign == sign[:, :1]).all(axis=1) & (sign[:, 0] != 0)
    return ok


def _nearest_point_radius(src, tris_idx, xy, scene, lut, order, pixel_angle) -> np.ndarray:
    """(K,) pixels: the angle from the hole's direction of the ``order`` image of each source triangle's
    point nearest to the axis in projection (on its boundary; NaN when the axis passes through it)."""
    t3 = src.tris.take(tris_idx, axis=0)
    inside, t, d = culling.nearest_to_axis(xy[:, 0], xy[:, 1], t3)
    k = np.argmin(d, axis=1)  # the side with the nearest point
    rows = np.arange(len(t3))
    a = src.positions.take(t3[rows, k], axis=0)
    b = src.positions.take(t3[rows, (k + 1) % 3], axis=0)
    point = a + t[rows, k][:, None] * (b - a)  # the projection along the axis is affine
    img = mapping.map_vertices_orders(point, scene, lut, (order,))[order]
    with np.errstate(invalid="ignore"):
        r = culling.hole_angle(img.direction, scene.camera, scene.hole) / pixel_angle
    return np.where(inside | ~img.valid, np.nan, r)


def _side_levels(xy, tris, corner_px, tolerance, settings) -> np.ndarray:
    """(S, 3) ring levels of the sides of the triangles ``tris`` (S, 3) of the source vertices with axis
    coordinates ``xy`` (N, 2) (culling.axis_coordinates' x, y), cut into strips: side k
    (corner k -> k + 1) covering the azimuth D_k about the axis gets ceil(D_k / (RING_LEVEL_MARGIN d_max))
    as in :func:`_ring_levels`, with d_max from the triangle's largest corner radius ``corner_px``
    and ``tolerance`` (S,) pixels."""
    top = int(np.clip(settings.max_tess_level, 1, subdivision.GRID))
    span = culling.side_azimuths(xy[:, 0], xy[:, 1], tris)
    with np.errstate(invalid="ignore", divide="ignore"):
        d_max = culling.max_ring_span(corner_px.max(axis=1), tolerance)
    return _azimuth_levels(span, d_max[:, None], top)


PRESPLIT_MIN = 12
"""A magnified source triangle beside the axis whose pieces would need more than this level is split
first (see :func:`_presplit_levels`)."""

PRESPLIT_EXP = 0.35
"""The first split cuts such a triangle at level need ** PRESPLIT_EXP. The second pass's ring levels
then refine the pieces next to the axis, so a coarse first split is enough, and it leaves fewer
triangles to that pass. The benchmark sphere at 170 deg: 25.5 ms at 0.5 (the square root), 22.9 ms
at 0.35, with the same coverage. At 0.25 the mismatch rises from 0.21% to 0.36%
(benchmarks/bench_accuracy.py)."""


def _presplit_levels(src, edges, src_circ, img_circs, images_v, scene, settings, hidden=None, axis_xyz=None,
                     hole_r=None):
    """Per-edge levels of a first, coarse split of the source mesh, or None when none is needed.

    A strongly magnified triangle (RING_MAGNIFICATION) of projected size h whose closest point lies at
    d_min from the axis needs pieces of size RING_LEVEL_MARGIN * d_max * d_min next to that point
    (d_max: the azimuth allowed at its ring radius, culling.max_ring_span), i.e. a level
    need = h / (RING_LEVEL_MARGIN d_max d_min). The ring levels (_ring_levels) look at the azimuth
    its corners span, which for a triangle passing close to the axis is much less: its pieces next
    to the axis stay too wide, are culled, and the far side of the object shows through the gaps.
    A uniform split at ``need`` would cost need^2 pieces; instead, triangles with need > PRESPLIT_MIN
    are first split at need ** PRESPLIT_EXP, so that the ring levels of the smaller triangles, computed
    again, refine mostly those next to the axis. Only meshes the axis does not cross (axis patches
    handle the crossings). ``img_circs``: {order: image circumferences of the source triangles};
    ``hidden``: a function of triangle indices giving a mask of those hidden in every order (back
    faces, see BACK_FACE_MARGIN), which are not split. ``axis_xyz``: culling.axis_coordinates of the
    source positions; ``hole_r``: a function of the order giving culling.hole_angle of that order's
    vertex images (both computed here when not given)."""
    need = np.ones(len(src.tris))
    x = y = None
    for order, img_v in images_v.items():
        cand = _ring_candidates(src_circ, img_circs[order])
        if cand.size == 0:
            continue
        if x is None:
            x, y, _ = culling.axis_coordinates(src.positions, scene.camera, scene.hole) if axis_xyz is None else axis_xyz
        t = src.tris[cand]
        px, py = x[t], y[t]
        h = np.hypot(px - np.roll(px, -1, axis=1), py - np.roll(py, -1, axis=1)).max(axis=1)
        dmin = culling.axis_distance(x, y, t)
        with np.errstate(invalid="ignore", divide="ignore"):
            angle = culling.hole_angle(img_v.direction, scene.camera, scene.hole) if hole_r is None else hole_r(order)
            radius = angle / settings.pixel_angle
            d_max = culling.max_ring_span(radius[t].max(axis=1), settings.max_error_px)
            n = np.where(dmin > 0, h / (RING_LEVEL_MARGIN * d_max * dmin), 1.0)
        need[cand] = np.maximum(need[cand], np.nan_to_num(n, nan=1.0, posinf=1.0))
    split = need > PRESPLIT_MIN
    if split.any() and hidden is not None:
        idx = np.flatnonzero(split)
        split[idx[hidden(idx)]] = False
    if not split.any():
        return None
    k = np.clip(np.ceil(need ** PRESPLIT_EXP), 1, subdivision.GRID).astype(np.int64)
    k[~split] = 1
    levels = np.ones(len(edges.verts), np.int64)
    np.maximum.at(levels, edges.of_tri.ravel(), np.repeat(k, 3))
    return levels


def _patch_parts(patches, order, planes, offset):
    """The faces of the axis patches (axis_patch.Patch) of ``order`` as arrays to append to an image
    mesh whose vertex count is ``offset``: (tris, source triangle, corners, image positions,
    directions, c*dt, source positions), corners = (bary (F, 3, 3) in the face's source triangle, and
    the rows of subdivision.carry_rows: each appended vertex's own source triangle (V,) and
    barycentrics there (V, 3), and the faces' corners among them (F, 3)), without faces that have a
    corner without an image or lie outside one frustum plane; None when no face is left."""
    out = [[] for _ in range(7)]
    first_offset = offset
    for p in patches:
        im = p.images.get(order)
        if im is None:  # hidden (back faces of a closed surface)
            continue
        faces = p.tris
        ok = im.valid.take(faces).all(axis=1) & p.facing[order]
        if planes is not None:
            bits = culling.outside_bits(np.where(im.valid[:, None], im.position, 0.0), planes)
            fb = bits.take(faces)
            ok &= (fb[:, 0] & fb[:, 1] & fb[:, 2]) == 0
        faces = faces[ok]
        if len(faces) == 0:
            continue
        used = mapping.used_vertices(faces, len(p.source_position))
        remap = np.full(len(p.source_position), -1, dtype=np.int64)
        remap[used] = np.arange(used.size)
        out[0].append(remap.take(faces) + offset)
        out[1].append(p.face_src[ok])
        out[2].append((p.bary[ok], p.vertex_tri.take(used), p.vertex_bary.take(used, axis=0)))
        out[3].append(im.position.take(used, axis=0))
        out[4].append(im.direction.take(used, axis=0))
        out[5].append(im.distance.take(used))
        out[6].append(p.source_position.take(used, axis=0))
        offset += used.size
    if not out[0]:
        return None
    tris = np.concatenate(out[0])
    bary, vertex_tri, vertex_bary = (np.concatenate(a) for a in zip(*out[2]))
    corners = (bary, vertex_tri, vertex_bary, tris - first_offset)  # rows: the patch vertices appended
    return (tris, np.concatenate(out[1]), corners, *(np.concatenate(a) for a in out[3:]))


UNDER_PATCH_ERROR = 1.0
"""Pieces that a complete axis patch draws over (wholly inside its outer circle, on a source
triangle it draws in that order) are dropped when their centroid is drawn more than
UNDER_PATCH_ERROR * max_error_px from its true image (None: never). Inside its outer circle a
complete patch draws the whole sheet, so these pieces only compete with it for the same pixels. On a
plane both lie on one surface and either may show; the ring levels of triangles under a patch are
capped (_span_cap) and culling drops only pieces whose chords sag too far (culling.cull), so large
triangles near the axis leave pieces that pass both and are still too wide: a point inside one is
drawn at the azimuth of its corners' mean, not its own. A square of two triangles (2 r_s) 4 r_s
behind the hole, crossed by the axis off its centre, showed texture 0.92 px off (p99 of the drawn
points, 320x180), 0.33 px with the rule (0.24 px when every such piece is dropped; but on the
benchmark sphere, whose pieces lie on the curved surface in front of the patch's flat faces and are
the more exact there, that raised the screen error next to the limb from 0.23-0.34 to 0.32-0.42 px:
at 1.0 the sphere's errors are unchanged or slightly lower, at 0.5 mixed)."""


def _coarse_under_patches(patches, order, tris, face_src, points, img: mapping.Images, keep, scene, lut,
                          settings: Settings, n_src) -> np.ndarray:
    """(F,) bool: the pieces ``tris`` (F, 3) of the subdivided mesh (vertices ``points`` (V, 3) BU,
    their ``order`` images ``img``, source triangles ``face_src``) among ``keep`` to drop under the
    complete ``patches`` (see UNDER_PATCH_ERROR); ``n_src``: the number of source triangles."""
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
            x, y, _ = culling.axis_coordinates(points, scene.camera, scene.hole)
            dist = np.hypot(x, y)
        cand = cand[(dist.take(tris.take(cand, axis=0)) < p.radius).all(axis=1)]
        if not cand.size:
            continue
        t = tris.take(cand, axis=0)
        true = mapping.map_vertices_orders(points.take(t, axis=0).mean(axis=1), scene, lut, (order,))[order]
        drawn_dir = img.direction.take(t, axis=0).sum(axis=1)
        drawn_dir /= np.maximum(mapping.row_norm(drawn_dir), 1e-300)[:, None]
        err = subdivision.angle_of_chord(culling.chord_length(true.direction, drawn_dir))  # radians
        out[cand[err > UNDER_PATCH_ERROR * settings.max_error_px * settings.pixel_angle]] = True
    return out


def _subset(img: mapping.Images, rows) -> mapping.Images:
    """The images ``rows`` (indices) of ``img`` (positions, directions, distances, validity, LUT values)."""
    return mapping.Images(position=img.position.take(rows, axis=0), direction=img.direction.take(rows, axis=0),
                          distance=img.distance.take(rows), valid=img.valid.take(rows), plane=None,
                          xi=img.xi.take(rows), dt=img.dt.take(rows), ux=None, uy=None)


def _below_pixel(img_v: mapping.Images, img_m: mapping.Images, pixel_angle) -> bool:
    """True if all valid image points (source vertices and probed edge midpoints) lie within one
    pixel (radians on the view sphere) of each other: the image is too small to matter."""
    if not pixel_angle:
        return False
    d = np.concatenate([img_v.direction[img_v.valid], img_m.direction[img_m.valid]])
    if len(d) == 0:
        return False  # nothing valid: culling reports why
    centre = d.mean(axis=0)
    centre /= max(np.linalg.norm(centre), 1e-300)
    return bool(np.max(subdivision.chord_angle(d, np.broadcast_to(centre, d.shape))) * 2.0 < pixel_angle)


def _inside_frustum(img_v: mapping.Images, img_m: mapping.Images, probe, tris, edges, planes):
    """Indices of the source triangles to subdivide: all of them, or with a frustum those not having
    their three corners and three edge midpoints all mapped outside one frustum plane; and the
    culling.outside_bits of the source vertices' images (None without a frustum). Midpoints not
    probed (edges within a pixel) are taken as the mean of their end points' images; points without
    an image count as inside, so culling reports them under their own reason. Midpoints are tested
    only for triangles whose corners are all outside one plane."""
    if planes is None:
        return np.arange(len(tris)), None
    out_v = culling.outside_bits(img_v.position, planes)  # (N,) bit k: outside plane k
    t, e = tris, edges.of_tri
    common = out_v[t[:, 0]] & out_v[t[:, 1]] & out_v[t[:, 2]]
    cand = np.flatnonzero(common)
    if cand.size == 0:
        return np.arange(len(tris)), out_v
    cand_edges, slot = np.unique(e[cand], return_inverse=True)
    slot = slot.reshape(-1, 3)
    ev = edges.verts[cand_edges]
    mid = 0.5 * (img_v.position.take(ev[:, 0], axis=0) + img_v.position.take(ev[:, 1], axis=0))
    probe_row = np.searchsorted(probe, cand_edges)  # probe is sorted: where each candidate edge would be
    probed = probe_row < len(probe)
    probed[probed] = probe[probe_row[probed]] == cand_edges[probed]
    mid[probed] = img_m.position[probe_row[probed]]
    out_m = culling.outside_bits(mid, planes)
    outside = common[cand] & out_m[slot[:, 0]] & out_m[slot[:, 1]] & out_m[slot[:, 2]]
    inside = np.ones(len(tris), dtype=bool)
    inside[cand[outside != 0]] = False
    return np.flatnonzero(inside), out_v


def _map_subdivided(sub, n_pts, coarse: mapping.Images, scene, lut, order) -> mapping.Images:
    """Images of the subdivided vertices; source corners (welding keys < n_pts) reuse ``coarse``, the
    images of the source vertices; only the new vertices are looked up."""
    if sub.identity:  # the source's own vertices, in order
        return coarse
    is_corner = sub.vertex_key < n_pts
    if is_corner.all():
        return _subset(coarse, sub.vertex_key)
    new = mapping.map_vertices(sub.positions[~is_corner], scene, lut, order)
    n = len(sub.positions)
    position = np.empty((n, 3))
    direction = np.empty((n, 3))
    distance = np.empty(n)
    valid = np.empty(n, dtype=bool)
    xi = np.empty(n)
    dt = np.empty(n)
    idx = sub.vertex_key[is_corner]
    for dst, a, b in ((position, coarse.position, new.position), (direction, coarse.direction, new.direction),
                      (distance, coarse.distance, new.distance), (valid, coarse.valid, new.valid),
                      (xi, coarse.xi, new.xi), (dt, coarse.dt, new.dt)):
        dst[is_corner] = a[idx]
        dst[~is_corner] = b
    return mapping.Images(position=position, direction=direction, distance=distance, valid=valid, plane=None,
                          xi=xi, dt=dt, ux=None, uy=None)


def _empty(order, n_bad, below_pixel=0):
    rep = culling.CullReport()
    rep.extra["bad_source_triangles"] = n_bad
    rep.below_pixel = below_pixel
    return ImageMesh(order, np.zeros((0, 3)), np.zeros((0, 3), np.int64), None, np.zeros(0, np.int64),
                     np.zeros(0), None, rep, np.zeros(0, np.int64), np.zeros((0, 3)))
