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
        self._d = {}
        self._normals = None
        self._raw = None
        self._away = {}

    def closed(self) -> bool:
        """True for a closed, outward-wound surface seen from outside (computed once)."""
        if self._closed is None:
            src = self.source
            cam = self.frame.scene.camera
            lo, hi = src.positions.min(axis=0), src.positions.max(axis=0)
            outside_box = bool(np.any(cam < lo) or np.any(cam > hi))  # a closed surface winds 0 times there
            self._closed = bool(is_closed_outward(src.positions, src.tris, src.edges, normals=self._raw_normals)
                                and (outside_box or winding_number(src.positions, src.tris, cam) < 0.5))
        return self._closed

    def _raw_normals(self) -> np.ndarray:
        """(T, 3) the geometric normals (p1 - p0) x (p2 - p0) of every source triangle (BU^2, from the
        winding; silhouette.normals), once: the closed surface's volume and the back faces share them."""
        if self._raw is None:
            self._raw, self._normals = _normals_in_blocks(self.source.positions, self.source.tris,
                                                          lambda q: self.frame.checkpoint())
        return self._raw

    def leaving(self, vertices, order) -> np.ndarray:
        """(len(vertices), 3) the unit directions in which light leaves the source vertices ``vertices``
        towards the camera along ``order``'s rays (mapping.leaving_direction of the rays' tangents the
        map stage looked up with the vertices' images)."""
        if order not in self._d:
            img = self.coarse.images[order]
            if img.ux is None:  # mapped without tangents (no screen-space budget): look them up now
                self._d[order] = self.frame.map.leaving(self.source.positions, (order,))[order][0]
            else:
                self._d[order] = mapping.leaving_direction(self.source.plane, self.frame.scene, img.ux, img.uy)
        return self._d[order].take(vertices, axis=0)

    def turned_away(self, tri_idx, orders) -> np.ndarray:
        """(len(tri_idx),) bool: the source triangles ``tri_idx`` turned away (BACK_FACE_MARGIN) along
        the rays of every order in ``orders`` (silhouette.turned_away, corner by corner: only the
        triangles turned away at the corners before are looked at the next; the normals and corners
        of ``tri_idx`` are gathered once, none when ``tri_idx`` is every triangle in order)."""
        src = self.source
        self._raw_normals()  # (unit geometric normals of every triangle, once, with the raw ones)
        tri_idx = np.asarray(tri_idx, dtype=np.int64)
        n_t = len(src.tris)
        if 2 * len(tri_idx) >= n_t or all(o in self._away for o in orders):
            # many triangles (a dense mesh's selection): every triangle once per order, in blocks
            # (the same arithmetic per triangle), kept for the frame
            away = None
            for o in orders:
                if o not in self._away:
                    self.leaving(np.zeros(0, np.int64), o)
                    self._away[o] = _away_in_blocks(self._normals, src.tris, self._d[o],
                                                    lambda q: self.frame.checkpoint())
                a = self._away[o].take(tri_idx)
                away = a if away is None else away & a
            return away if away is not None else np.zeros(len(tri_idx), bool)
        every = len(tri_idx) == n_t and (n_t == 0 or (tri_idx[0] == 0 and tri_idx[-1] == n_t - 1
                                                       and bool(np.all(np.diff(tri_idx) == 1))))
        normals = self._normals if every else self._normals.take(tri_idx, axis=0)
        tris = src.tris if every else src.tris.take(tri_idx, axis=0)
        rows = None  # (the rows of tri_idx still turned away; None: all of them)
        for o in orders:
            self.leaving(np.zeros(0, np.int64), o)  # (every vertex's, once per order)
            d = self._d[o]
            for k in range(3):
                if rows is None:
                    n_k, corner = normals, tris[:, k]
                else:
                    n_k, corner = normals.take(rows, axis=0), tris[:, k].take(rows)
                with np.errstate(invalid="ignore"):
                    dots = np.einsum("fx,fx->f", n_k, d.take(corner, axis=0))
                hit = np.flatnonzero(dots < -B.BACK_FACE_MARGIN)  # NaN (no ray): not turned away
                rows = hit if rows is None else rows.take(hit)
        away = np.zeros(len(tri_idx), bool)
        if rows is not None:
            away[rows] = True
        return away

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

    def back_faces(self, selected, tri_level, order) -> np.ndarray:
        """The indices among ``selected`` (source triangles, with their levels ``tri_level``) hidden
        behind the surface's front in ``order``, looked for only when their pieces would be many
        (BACK_FACE_MIN_PIECES): among the split ones, or among all of them on a mesh that has that many
        triangles itself (a dense mesh, whose back faces would otherwise all be drawn)."""
        split = selected[tri_level > 1]
        n_tris = len(self.source.tris)
        if len(selected) >= B.BACK_FACE_MIN_PIECES and self.closed():  # a dense mesh: every triangle
            return selected[self.turned_away(selected, (order,))]
        if split.size and int((tri_level[tri_level > 1] ** 2).sum()) >= max(B.BACK_FACE_MIN_PIECES, n_tris) \
                and self.closed():
            return split[self.turned_away(split, (order,))]
        return np.zeros(0, np.int64)

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
        common = out_v[tris[:, 0]] & out_v[tris[:, 1]] & out_v[tris[:, 2]]
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


def _normals_in_blocks(points, tris, checkpoint=None):
    """((T, 3) geometric normals (p1 - p0) x (p2 - p0) (BU^2; silhouette.normals), (T, 3) the same
    normalised (NaN for a degenerate triangle)) of the triangles ``tris`` of ``points``, in one pass
    over blocks of TRI_BLOCK triangles (the corners gathered once per block). ``checkpoint``: None, or
    called between blocks with the fraction of the triangles done."""
    n_t = len(tris)
    raw, unit = np.empty((n_t, 3)), np.empty((n_t, 3))
    for s in range(0, n_t, TRI_BLOCK):
        if checkpoint is not None and s:
            checkpoint(s / n_t)
        e = min(s + TRI_BLOCK, n_t)
        raw[s:e] = silhouette.normals(points, tris[s:e])
        with np.errstate(invalid="ignore", divide="ignore"):
            np.divide(raw[s:e], mapping.row_norm(raw[s:e])[:, None], out=unit[s:e])
    return raw, unit


def _away_in_blocks(unit_normals, tris, directions, checkpoint=None) -> np.ndarray:
    """(T,) bool: the triangles ``tris`` whose unit normals ``unit_normals`` (T, 3) are turned away
    from the unit leaving ``directions`` (N, 3) of all three corners by more than BACK_FACE_MARGIN
    (n . d < -margin; NaN, no ray: not turned away), in blocks of TRI_BLOCK triangles. ``checkpoint``:
    None, or called between blocks with the fraction of the triangles done."""
    n_t = len(tris)
    away = np.empty(n_t, bool)
    for s in range(0, n_t, TRI_BLOCK):
        if checkpoint is not None and s:
            checkpoint(s / n_t)
        e = min(s + TRI_BLOCK, n_t)
        n, t = unit_normals[s:e], tris[s:e]
        with np.errstate(invalid="ignore"):
            a = np.einsum("fx,fx->f", n, directions.take(t[:, 0], axis=0)) < -B.BACK_FACE_MARGIN
            for k in (1, 2):
                a &= np.einsum("fx,fx->f", n, directions.take(t[:, k], axis=0)) < -B.BACK_FACE_MARGIN
        away[s:e] = a
    return away


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


def is_closed_outward(points, tris, edges: subdivision.Edges | None = None, normals=None) -> bool:
    """True if the triangles ``tris`` of ``points`` (BU) form closed surfaces with consistent winding
    (every edge used by exactly two triangles, once in each direction) that enclose a positive
    volume (normals from the winding point outwards). ``normals``: optionally a callable giving the
    triangles' geometric normals (p1 - p0) x (p2 - p0) (T, 3), asked only for a closed topology."""
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
