"""Visibility: which parts of a source can be seen at all, decided before anything is subdivided.

* Silhouettes (silhouette.py): the edges along which the surface turns away from the camera along
  the rays of an order; they decide coverage, so the level plan gives them the coverage tolerance.
* Back faces: on a closed, outward-wound surface seen from outside, triangles turned away from the
  camera along the rays (budget.BACK_FACE_MARGIN) are hidden behind the surface's own front.
* The frustum: source triangles whose corners and edge midpoints all map outside one frustum plane.
* Sub-pixel images: a second-order image within one pixel is not built.

:func:`see` gives a :class:`Sight` for one source: the decisions that depend on rays are looked up
on demand (the leaving directions of the vertices, through the map stage, once per vertex) and kept
for the rest of the frame. Units: positions in Blender units (BU), angles in radians.
"""
from __future__ import annotations

import numpy as np

from . import budget as B
from . import culling, mapping, silhouette, subdivision
from .frame import Frame, Source


class Sight:
    """What can be seen of one source in one frame (see the module docstring)."""

    def __init__(self, frame: Frame, source: Source, coarse):
        self.frame, self.source, self.coarse = frame, source, coarse
        self._closed = None
        self._tangent = {}
        self._in_plane = {}
        self._away = {}
        self._six_volume = None
        self._trig = None

    def closed(self) -> bool:
        """True for a closed, outward-wound surface seen from outside (computed once)."""
        if self._closed is None:
            src = self.source
            cam = self.frame.scene.camera
            lo, hi = src.positions.min(axis=0), src.positions.max(axis=0)
            outside_box = bool(np.any(cam < lo) or np.any(cam > hi))  # a closed surface winds 0 times there
            self._closed = bool(is_closed_outward(src.positions, src.tris, src.edges, six_volume=self._volume)
                                and (outside_box or winding_number(src.positions, src.tris, cam) < 0.5))
        return self._closed

    def _volume(self) -> float:
        """Six times the volume the source's triangles enclose (BU^3; asked for a closed topology only),
        from the one pass over every triangle that also finds the back faces of the orders whose rays'
        tangents the map stage looked up (:func:`_whole_pass`)."""
        if self._six_volume is None:
            orders = [o for o in self.frame.orders if o not in self._away and self.coarse.images[o].ux is not None]
            self._six_volume, away = _whole_pass(self.source.positions, self.source.tris, self.frame.scene.e1,
                                                 self.source.plane.e2, {o: self.in_plane(o) for o in orders},
                                                 True, lambda q: self.frame.checkpoint())
            self._away.update(away)
        return self._six_volume

    def _tangents(self, order):
        """(ux, uy) (N,) the tangents of ``order``'s rays at every source vertex (the map stage's, or
        looked up once when it mapped without them)."""
        if order not in self._tangent:
            img = self.coarse.images[order]
            if img.ux is None:  # mapped without tangents (no screen-space budget): look them up now
                plane = self.source.plane
                look = self.frame.map.rays(plane.r, plane.phi, (order,), ("dt", "ux", "uy"))[order]
                self._tangent[order] = (look.ux, look.uy)
            else:
                self._tangent[order] = (img.ux, img.uy)
        return self._tangent[order]

    def in_plane(self, order):
        """(a, b), each (N,): the unit direction a e1 + b e2 in which light leaves each source vertex
        towards the camera along ``order``'s rays (e1: the hole-camera direction, e2: the vertex's
        plane's, source.plane.e2; mapping.leaving_in_plane divided by its length sqrt(a^2 + b^2): e1
        and e2 are orthonormal); NaN where there is no ray."""
        if order not in self._in_plane:
            if self._trig is None:  # (the same for every order)
                self._trig = mapping.plane_trig(self.source.plane)
            a, b = mapping.leaving_in_plane(self.source.plane, *self._tangents(order), self._trig)
            with np.errstate(invalid="ignore", divide="ignore"):
                h = np.sqrt(a * a + b * b)
                a /= h
                b /= h
            self._in_plane[order] = (a, b)
        return self._in_plane[order]

    def leaving(self, vertices, order) -> np.ndarray:
        """(len(vertices), 3) the unit directions in which light leaves the source vertices ``vertices``
        towards the camera along ``order``'s rays (mapping.leaving_direction of the rays' tangents the
        map stage looked up with the vertices' images, for those vertices only)."""
        vertices = np.asarray(vertices, dtype=np.int64)
        ux, uy = self._tangents(order)
        return mapping.leaving_direction(self.source.plane.take(vertices), self.frame.scene, ux.take(vertices),
                                         uy.take(vertices))

    def turned_away(self, tri_idx, orders) -> np.ndarray:
        """(len(tri_idx),) bool: the source triangles ``tri_idx`` turned away (BACK_FACE_MARGIN) along
        the rays of every order in ``orders``: n . d < -BACK_FACE_MARGIN at all three corners, n the
        triangle's unit geometric normal, d = a e1 + b e2 the corner's unit leaving direction
        (:meth:`in_plane`), as a n . e1 + b n . e2 (:func:`_away_rows`). Many triangles (a dense mesh's
        selection): every triangle once per order, in one pass over blocks (:func:`_whole_pass`), kept
        for the frame; else the triangles ``tri_idx`` alone (the same arithmetic per triangle)."""
        src = self.source
        tri_idx = np.asarray(tri_idx, dtype=np.int64)
        n_t = len(src.tris)
        if 2 * len(tri_idx) >= n_t or all(o in self._away for o in orders):
            missing = [o for o in orders if o not in self._away]
            if missing:
                _, away = _whole_pass(src.positions, src.tris, self.frame.scene.e1, src.plane.e2,
                                      {o: self.in_plane(o) for o in missing}, False, lambda q: self.frame.checkpoint())
                self._away.update(away)
            away = None
            for o in orders:
                a = self._away[o].take(tri_idx)
                away = a if away is None else away & a
            return away if away is not None else np.zeros(len(tri_idx), bool)
        tris = src.tris.take(tri_idx, axis=0)
        unit = silhouette.normals(src.positions, tris)
        with np.errstate(invalid="ignore", divide="ignore"):
            unit /= mapping.row_norm(unit)[:, None]
        away = _away_rows(unit, tris, self.frame.scene.e1, src.plane.e2, {o: self.in_plane(o) for o in orders})
        out = None
        for a in away.values():
            out = a if out is None else out & a
        return out if out is not None else np.zeros(len(tri_idx), bool)

    def hidden(self, tri_idx, orders) -> np.ndarray:
        """(len(tri_idx),) bool: back faces (:meth:`turned_away` on a closed surface; none otherwise)."""
        if not self.closed():
            return np.zeros(len(tri_idx), bool)
        return self.turned_away(tri_idx, orders)

    def silhouette(self, order, of_edges):
        """silhouette.silhouette of ``order`` as (edge mask (E,), triangle mask (T,)), right for the
        edges ``of_edges`` (indices) and for the triangles whose three edges are among them; only the
        corners of the triangles around those edges are looked up."""
        src = self.source
        mark = np.zeros(len(src.edges.verts), bool)
        mark[of_edges] = True
        near = np.flatnonzero(mark.take(src.edges.of_tri).any(axis=1))
        corners, pts, local = silhouette.compact(src.positions, src.tris.take(near, axis=0))
        edge, tri_near = silhouette.silhouette(pts, local, src.edges.of_tri.take(near, axis=0), len(src.edges.verts),
                                               self.leaving(corners, order))
        tri = np.zeros(len(src.tris), bool)
        tri[near] = tri_near
        return edge, tri

    def one_way(self, tri_idx, order) -> np.ndarray:
        """(len(tri_idx),) bool: triangles facing one way at all corners along ``order``'s rays (no fold
        of the silhouette inside them)."""
        corners, pts, local = silhouette.compact(self.source.positions, self.source.tris.take(tri_idx, axis=0))
        sign = silhouette.facing_signs(pts, local, self.leaving(corners, order))
        return (sign == sign[:, :1]).all(axis=1) & (sign[:, 0] != 0)

    def back_faces(self, selected, levels, order) -> np.ndarray:
        """(len(selected),) bool: the triangles among ``selected`` (source triangles; ``levels`` (E,): the
        plan's per-edge levels) hidden behind the surface's front in ``order``, looked for only when
        their pieces would be many (BACK_FACE_MIN_PIECES): among all of them on a mesh that has that
        many triangles itself (a dense mesh, whose back faces would otherwise all be drawn), or among
        the split ones (a triangle's level: its edges' largest)."""
        hidden = np.zeros(len(selected), bool)
        if len(selected) >= B.BACK_FACE_MIN_PIECES and self.closed():  # a dense mesh: every triangle
            return self.turned_away(selected, (order,))
        lv = levels.take(self.source.edges.of_tri.take(selected, axis=0))
        tri_level = np.maximum(np.maximum(lv[:, 0], lv[:, 1]), lv[:, 2])
        split = np.flatnonzero(tri_level > 1)
        n_tris = len(self.source.tris)
        if split.size and int((tri_level.take(split) ** 2).sum()) >= max(B.BACK_FACE_MIN_PIECES, n_tris) \
                and self.closed():
            hidden[split] = self.turned_away(selected.take(split), (order,))
        return hidden

    def below_pixel(self, order, vertex_images: mapping.Images, mid_images: mapping.Images) -> bool:
        """True when ``order`` is 2 and all valid image points (vertices and probed edge midpoints) lie
        within one pixel of each other: the image is too small to matter. First-order images are
        always built, so small objects stay visible."""
        return order == 2 and _below_pixel(vertex_images, mid_images, self.frame.camera.pixel_angle)

    def inside_frustum(self, vertex_images: mapping.Images, mid_images: mapping.Images, probe):
        """(selected, outside bits): the source triangles not having their three corners and three edge
        midpoints all mapped outside one frustum plane (all of them without a frustum), and the
        culling.outside_bits of the vertices' images (None without a frustum). Midpoints not probed
        (``probe``: the probed edges, sorted; the others span a pixel at most) are the mean of their
        end points' images; points without an image count as inside, so culling reports them under
        their own reason. Midpoints are tested only where the corners are all outside one plane."""
        planes = self.frame.planes
        src = self.source
        tris, edges = src.tris, src.edges
        if planes is None:
            return np.arange(len(tris)), None
        out_v = culling.outside_bits(vertex_images.position, planes)  # (N,) bit k: outside plane k
        e = edges.of_tri
        c = out_v.take(tris)  # (one gather of every corner)
        common = c[:, 0] & c[:, 1] & c[:, 2]
        cand = np.flatnonzero(common)
        if cand.size == 0:
            return np.arange(len(tris)), out_v
        cand_edges, slot = np.unique(e[cand], return_inverse=True)
        slot = slot.reshape(-1, 3)
        ev = edges.verts[cand_edges]
        mid = 0.5 * (vertex_images.position.take(ev[:, 0], axis=0) + vertex_images.position.take(ev[:, 1], axis=0))
        probe_row = np.searchsorted(probe, cand_edges)  # probe is sorted: where each candidate edge would be
        probed = probe_row < len(probe)
        probed[probed] = probe[probe_row[probed]] == cand_edges[probed]
        mid[probed] = mid_images.position[probe_row[probed]]
        out_m = culling.outside_bits(mid, planes)
        outside = common[cand] & out_m[slot[:, 0]] & out_m[slot[:, 1]] & out_m[slot[:, 2]]
        inside = np.ones(len(tris), dtype=bool)
        inside[cand[outside != 0]] = False
        return np.flatnonzero(inside), out_v


TRI_BLOCK = 1 << 15
"""Triangles per block of the per-triangle passes below (their corners' rows stay in the cache; a
cancellation point between blocks)."""


def _whole_pass(points, tris, e1, e2, in_plane, volume=True, checkpoint=None):
    """(six_volume, {order: away}): one pass over the triangles ``tris`` of ``points`` (BU) in blocks of
    TRI_BLOCK (the corners gathered once per block): with ``volume``, six times the enclosed volume
    (BU^3, the sum of (p0 - q) . ((p1 - p0) x (p2 - p0)) about the first triangle's first corner q,
    as :func:`is_closed_outward`; else None), and for each order of ``in_plane`` ({order: (a, b)}:
    the vertices' unit leaving directions a e1 + b e2, ``e1`` (3,) and ``e2`` (N, 3) as
    Sight.in_plane) the mask (T,) of the triangles turned away at all three corners
    (:func:`_away_rows`). ``checkpoint``: None, or called between blocks with the fraction done."""
    n_t = len(tris)
    away = {o: np.empty(n_t, bool) for o in in_plane}
    six = 0.0
    q = points[tris[0, 0]] if n_t else None
    for s in range(0, n_t, TRI_BLOCK):
        if checkpoint is not None and s:
            checkpoint(s / n_t)
        e = min(s + TRI_BLOCK, n_t)
        t = tris[s:e]
        p0, p1, p2 = (points.take(t[:, k], axis=0) for k in range(3))
        p1 -= p0
        p2 -= p0
        raw = np.empty_like(p1)  # silhouette.normals' arithmetic
        raw[:, 0] = p1[:, 1] * p2[:, 2] - p1[:, 2] * p2[:, 1]
        raw[:, 1] = p1[:, 2] * p2[:, 0] - p1[:, 0] * p2[:, 2]
        raw[:, 2] = p1[:, 0] * p2[:, 1] - p1[:, 1] * p2[:, 0]
        if volume:
            p0 -= q
            six += float(np.einsum("ij,ij->", p0, raw))
        if in_plane:
            with np.errstate(invalid="ignore", divide="ignore"):
                raw /= mapping.row_norm(raw)[:, None]
            for o, a in _away_rows(raw, t, e1, e2, in_plane).items():
                away[o][s:e] = a
    return (six if volume else None), away


def _away_rows(unit_normals, tris, e1, e2, in_plane) -> dict:
    """{order: (T,) bool}: the triangles ``tris`` (T, 3) with unit normals ``unit_normals`` (T, 3)
    turned away at all three corners along each order's rays: n . d < -BACK_FACE_MARGIN with d the
    corner's unit leaving direction a e1 + b e2 (``in_plane`` {order: (a, b)} per vertex, ``e1`` (3,)
    the hole-camera direction, ``e2`` (N, 3) the vertices' planes' second axes), computed as
    a (n . e1) + b (n . e2) (n . e2 once per corner for every order). NaN (no ray): not turned away."""
    out = {}
    with np.errstate(invalid="ignore"):
        n_e1 = unit_normals @ e1
        for k in range(3):
            c = tris[:, k]
            n_e2 = np.einsum("fx,fx->f", unit_normals, e2.take(c, axis=0))
            for o, (a, b) in in_plane.items():
                dot = a.take(c) * n_e1
                dot += b.take(c) * n_e2
                hit = dot < -B.BACK_FACE_MARGIN
                out[o] = hit if k == 0 else out[o] & hit
    return out


def see(frame: Frame, source: Source, coarse) -> Sight:
    """The :class:`Sight` of ``source`` in ``frame``; ``coarse``: the map stage's images of its vertices
    (frame.SourceImages)."""
    return Sight(frame, source, coarse)


def _below_pixel(img_v: mapping.Images, img_m: mapping.Images, pixel_angle) -> bool:
    """True if all valid image points lie within one pixel (radians) of each other."""
    if not pixel_angle:
        return False
    d = np.concatenate([img_v.direction[img_v.valid], img_m.direction[img_m.valid]])
    if len(d) == 0:
        return False  # nothing valid: culling reports why
    centre = d.mean(axis=0)
    centre /= max(np.linalg.norm(centre), 1e-300)
    return bool(np.max(subdivision.chord_angle(d, np.broadcast_to(centre, d.shape))) * 2.0 < pixel_angle)


def is_closed_outward(points, tris, edges: subdivision.Edges | None = None, normals=None, six_volume=None) -> bool:
    """True if the triangles ``tris`` of ``points`` (BU) form closed surfaces with consistent winding
    (every edge used by exactly two triangles, once in each direction) that enclose a positive
    volume (normals from the winding point outwards). ``normals``: optionally a callable giving the
    triangles' geometric normals (p1 - p0) x (p2 - p0) (T, 3), asked only for a closed topology;
    ``six_volume``: optionally a callable giving six times the enclosed volume itself (BU^3, the
    sum below; Sight's pass over the triangles), asked only for a closed topology."""
    tris = np.asarray(tris, dtype=np.int64)
    if len(tris) == 0:
        return False
    edges = edges if edges is not None else subdivision.mesh_edges(tris)
    if edges.closed is None:  # topology only: kept with the edges (frame._edges_of keeps those per topology)
        forward = np.where(tris < np.roll(tris, -1, axis=1), 1, -1)  # edge k: corner k -> k+1
        n_e = len(edges.verts)
        uses = np.bincount(edges.of_tri.ravel(), minlength=n_e)
        balance = np.bincount(edges.of_tri.ravel(), weights=forward.ravel(), minlength=n_e)
        edges.closed = bool(np.all(uses == 2) and np.all(balance == 0))
    if not edges.closed:
        return False
    # six times the volume: the sum over triangles of (p0 - q) . ((p1 - p0) x (p2 - p0)), about a
    # vertex q (no cancellation far from the origin); (p0 - q) . ((p1 - p0) x (p2 - p0)) equals
    # (p0 - q) . ((p1 - q) x (p2 - q)), the signed volume of the tetrahedron (q, p0, p1, p2)
    if six_volume is not None:
        return bool(six_volume() > 0)
    p = np.asarray(points, dtype=np.float64)
    n = normals() if normals is not None else silhouette.normals(p, tris)
    q = p[tris[0, 0]]
    p0 = p.take(tris[:, 0], axis=0)
    p0 -= q
    return bool(np.einsum("ij,ij->", p0, n) > 0)


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
