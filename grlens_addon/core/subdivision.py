"""Adaptive, crack-free subdivision of triangle meshes by the screen-space curvature rho.

Seed 000, eqs. (18)-(19): for an edge with mapped end points q1, q2 and mapped midpoint q12,
rho = |q12 - (q1 + q2)/2| / |q2 - q1|, and the edge is split into
N = MaxTessLevel * clamp(a * rho^b, 0, 1) segments. Here q are apparent directions on the camera's
view sphere (unit vectors), which equals screen space for small fields of view and stays defined for
points beside or behind the camera.

Levels are capped by the edge's size on screen (see :func:`edge_levels`): an edge never gets more
segments than the pixels it spans, nor more than keep its straight pieces within a screen-space
tolerance of the curved image, so images smaller than a pixel are not subdivided at all.

Crack-free scheme: each edge has one level (1 .. 64), shared by both of its triangles. A triangle
is subdivided uniformly at its largest edge level L; the template vertices on an edge of level
l <= L are snapped along that edge to the nearest point of the edge's own l-grid (every l-grid
point is hit because L >= l), so both triangles of an edge put exactly the same vertices on it.
Vertices are then welded by integer keys (source corner / edge and l-grid index / triangle
interior), so the result is watertight whenever the source is; triangles that collapse under
snapping are dropped. All of this is vectorised over all split triangles at once (each on its own
level's template; the templates of all levels are laid end to end).

Strips (optional, per triangle): around an Einstein ring a triangle's image is long in azimuth and
can be a fraction of a pixel across. The uniform grid then makes L^2 pieces where about 2 L thin ones
do: the triangle is cut by joining the grid points of its sides in order of their angle about a
given centre (the observer-hole axis), so that only the sides' own points are used. That keeps the
shared-edge rule above (crack-free against uniform neighbours) and adds no interior vertex. The
pieces are straight across the triangle, so the caller uses strips only where the image is that
narrow (budget.STRIP_BAND_PX).

Units: positions in Blender units; barycentric coordinates are dimensionless.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .mapping import row_norm
from .ragged import group_offsets

GRID = 64  # largest level (GPU tessellators' usual maximum, as in seed 000)


def edge_levels(rho: np.ndarray, max_tess_level: int, a: float, b: float,
                chord: np.ndarray | None = None, pixel_angle: float | None = None,
                max_error_px: float | None = None, error_px: np.ndarray | None = None,
                lt_units: np.ndarray | None = None) -> np.ndarray:
    """Per-edge subdivision levels (integers 1 .. min(max_tess_level, 64), shape of ``rho``).

    The level is eq. (19), ceil(MaxTessLevel * clamp(a rho^b, 0, 1)), at least 1, and, when ``chord``
    (the edge's image size on the view sphere, radians) and ``pixel_angle`` (radians per pixel) are
    given, never more than needed on screen:

    * at most the number of pixels the edge spans (sub-edges are at least a pixel long), so images
      smaller than a pixel are not subdivided at all;
    * with ``max_error_px``: at most ceil(sqrt(e)), where e is the edge's error at its midpoint in
      units of the budget: ``error_px`` / ``max_error_px`` (pixels: how far from where the renderer
      draws the edge's midpoint its exact image lies, interior.midpoint_errors; without it the
      sagitta rho * chord in pixels), or ``lt_units`` (the light-travel pass's error there in units
      of its tolerance) if larger. A curve cut into n pieces deviates from its chords by about
      e / n^2, so this is the smallest level that keeps the pieces' edges within the budget.

    NaN rho (an end point without an image) gives level 1: such edges are culled later anyway.
    """
    top = int(np.clip(max_tess_level, 1, GRID))
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        r = np.maximum(rho, 0.0)
        n = top * np.clip(a * np.power(r, b), 0.0, 1.0)
        n = np.nan_to_num(np.ceil(n), nan=1.0)
        if chord is not None and pixel_angle:
            chord_px = chord / pixel_angle
            n = np.minimum(n, np.nan_to_num(np.ceil(chord_px), nan=1.0))
            if max_error_px:
                units = (r * chord_px if error_px is None else error_px) / max_error_px
                if lt_units is not None:
                    units = np.fmax(units, lt_units)
                n = np.minimum(n, np.nan_to_num(np.ceil(np.sqrt(units)), nan=1.0))
    return np.clip(n, 1, top).astype(np.int64)


def chord_angle(d_a: np.ndarray, d_b: np.ndarray) -> np.ndarray:
    """Angle (radians) between unit directions (E, 3): an edge's image size on the view sphere."""
    return angle_of_chord(row_norm(d_b - d_a))


def angle_of_chord(chord):
    """Angle (radians) subtended by a chord of the unit sphere of length ``chord``."""
    return 2.0 * np.arcsin(np.clip(0.5 * chord, 0.0, 1.0))


def rho(d_a: np.ndarray, d_b: np.ndarray, d_mid: np.ndarray) -> np.ndarray:
    """Eq. (18) on unit apparent directions (E, 3) of the end points and of the mapped midpoint."""
    chord = row_norm(d_b - d_a)
    dev = row_norm(d_mid - 0.5 * (d_a + d_b))
    with np.errstate(invalid="ignore", divide="ignore"):
        out = dev / chord
    return np.where(chord > 0, out, 0.0)


@dataclass
class Edges:
    """Unique undirected edges of a triangle mesh: ``verts`` (E, 2) with verts[:, 0] < verts[:, 1];
    ``of_tri`` (T, 3): edge k of triangle t joins corner k and corner (k+1) % 3."""

    verts: np.ndarray
    of_tri: np.ndarray
    closed: bool | None = None  # every edge used twice, once each way (visibility.is_closed_outward)
    n_points: int = 0  # more than the largest vertex index (the edges' keys lo * n_points + hi)
    keys: np.ndarray | None = None  # those keys (ascending), made when first needed (assemble.source_edge_keys)


def mesh_edges(tris: np.ndarray) -> Edges:
    tris = np.asarray(tris, dtype=np.int64)
    pairs = np.stack([tris, np.roll(tris, -1, axis=1)], axis=2).reshape(-1, 2)
    lo, hi = pairs.min(axis=1), pairs.max(axis=1)
    n_points = int(tris.max(initial=0)) + 1
    key = lo * n_points + hi
    uniq, inv = np.unique(key, return_inverse=True)
    verts = np.empty((uniq.size, 2), dtype=np.int64)
    verts[inv, 0], verts[inv, 1] = lo, hi
    return Edges(verts=verts, of_tri=inv.reshape(-1, 3), n_points=n_points, keys=uniq)


@lru_cache(maxsize=None)
def _template(level: int):
    """Uniform subdivision of the reference triangle: integer coordinates (i, j) of the vertices
    (barycentrics ((L-i-j), i, j)/L), the small triangles (index triples, counter-clockwise like the
    source), and for each vertex its edge (0, 1, 2 or -1) and parameter numerator along it."""
    L = level
    j = np.repeat(np.arange(L + 1), np.arange(L + 1, 0, -1))  # rows j = 0 .. L of L + 1 - j vertices
    i = group_offsets(np.arange(L + 1, 0, -1))
    ij = np.stack([i, j], axis=1)

    def index(i, j):  # of vertex (i, j)
        return j * (L + 1) - j * (j - 1) // 2 + i

    # per cell (i, j), i + j < L, row by row: the triangle pointing up, then (if any) the one pointing down
    ci, cj = i[i + j < L], j[i + j < L]
    a, b, c = index(ci, cj), index(ci + 1, cj), index(ci, cj + 1)
    up = np.stack([a, b, c], axis=1)
    down = np.stack([b, index(ci + 1, cj + 1), c], axis=1)
    tris = np.stack([up, down], axis=1).reshape(-1, 3)[np.stack([np.ones(ci.size, bool), ci + cj + 2 <= L], 1).ravel()]
    # edge 0: corner0 -> corner1 (j == 0, t = i/L); edge 1: corner1 -> corner2 (i + j == L, t = j/L);
    # edge 2: corner2 -> corner0 (i == 0, t = (L - j)/L). Corners belong to no edge here.
    edge = np.full(len(ij), -1)
    t = np.zeros(len(ij), dtype=np.int64)
    corner = np.full(len(ij), -1)
    corner[(i == 0) & (j == 0)] = 0
    corner[(i == L) & (j == 0)] = 1
    corner[(i == 0) & (j == L)] = 2
    inner = corner < 0
    m0 = inner & (j == 0)
    m1 = inner & (i + j == L)
    m2 = inner & (i == 0)
    edge[m0], t[m0] = 0, i[m0]
    edge[m1], t[m1] = 1, j[m1]
    edge[m2], t[m2] = 2, L - j[m2]
    return ij, tris.astype(np.int64), edge, t, corner


@dataclass(frozen=True)
class _Templates:
    """The templates of levels 1 .. GRID one after another (for all split triangles at once): per level
    L, vertices vert_start[L] .. + n_verts[L] of ij / edge / t / corner (as :func:`_template`) and
    triangles tri_start[L] .. + n_tris[L] of tris (template-local vertex indices)."""

    ij: np.ndarray
    edge: np.ndarray
    t: np.ndarray
    corner: np.ndarray
    tris: np.ndarray
    vert_start: np.ndarray
    n_verts: np.ndarray
    tri_start: np.ndarray
    n_tris: np.ndarray


@lru_cache(maxsize=None)
def _templates() -> _Templates:
    parts = [_template(L) for L in range(1, GRID + 1)]
    n_verts = np.array([0] + [len(p[0]) for p in parts], dtype=np.int64)  # index: the level
    n_tris = np.array([0] + [len(p[1]) for p in parts], dtype=np.int64)
    return _Templates(ij=np.concatenate([p[0] for p in parts]), edge=np.concatenate([p[2] for p in parts]),
                      t=np.concatenate([p[3] for p in parts]), corner=np.concatenate([p[4] for p in parts]),
                      tris=np.concatenate([p[1] for p in parts]), vert_start=np.cumsum(n_verts) - n_verts,
                      n_verts=n_verts, tri_start=np.cumsum(n_tris) - n_tris, n_tris=n_tris)


@dataclass
class Subdivided:
    """A subdivided mesh.

    positions: (V, 3) world positions (BU) of the welded vertices;
    tris: (F, 3) vertex indices, same winding as the source;
    source_tri: (F,) index of the source triangle each face comes from;
    row_bary (R, 3), row_src (R,), corner_row (F, 3): the barycentric coordinates of each face corner in
    its source triangle, stored once per (source triangle, template vertex) "row" (row_src: the
    row's source triangle) and indexed by corner_row, because the faces of a split triangle share
    their corners (R is about F / 2; see :attr:`bary` and :meth:`corner_values`); None when identity;
    vertex_key: (V,) the welding keys (stable for unchanged topology and levels);
    identity: True when nothing was split (all levels 1): positions and tris are the source's;
    n_pass: the first n_pass faces are source triangles passed through unsplit (level 1 on all edges),
    so their corners are source vertices and per-triangle values of the source apply to them;
    n_unit_rows: the first n_unit_rows rows are the corners of the unsplit triangles, in order
    (barycentrics (1, 0, 0), (0, 1, 0), (0, 0, 1) in turn).
    """

    positions: np.ndarray
    tris: np.ndarray
    source_tri: np.ndarray
    row_bary: np.ndarray | None
    row_src: np.ndarray | None
    corner_row: np.ndarray | None
    vertex_key: np.ndarray
    identity: bool = False
    n_pass: int = 0
    n_unit_rows: int = 0

    @property
    def bary(self) -> np.ndarray:
        """(F, 3, 3) barycentric coordinates of each face corner in its source triangle."""
        if self.identity:
            return np.broadcast_to(np.eye(3), (len(self.tris), 3, 3))
        return self.row_bary.take(self.corner_row, axis=0)

    def corner_values(self, values) -> np.ndarray:
        """Per face corner (F, 3, K) values interpolated from the source triangles' corner values
        ``values`` (T, 3, K) (UVs, normals; T indexes the triangles that were subdivided)."""
        values = np.asarray(values, dtype=np.float64)
        if self.identity:
            return values.take(self.source_tri, axis=0)
        return carry_rows(self.row_bary, self.row_src, self.corner_row, values, self.n_unit_rows)


def carry_rows(row_bary, row_src, corner_row, values, n_unit=0, unit=False) -> np.ndarray:
    """(F, 3, K) corner values of faces whose corners are rows ``corner_row`` (F, 3) of barycentric
    coordinates ``row_bary`` (R, 3) in the source triangles ``row_src`` (R,), from those triangles'
    corner values ``values`` (T, 3, K) (see :class:`Subdivided`). The first ``n_unit`` rows are the
    corners of whole source triangles (barycentrics (1, 0, 0), (0, 1, 0), (0, 0, 1) in turn, as
    Subdivided.n_unit_rows): their values are taken, not interpolated. ``unit``: the values are unit
    vectors (normals): the interpolated ones are normalised again (once per row)."""
    values = np.asarray(values)
    per_row = np.empty((len(row_bary), values.shape[2]))
    if n_unit:
        per_row[:n_unit] = values[row_src[:n_unit], np.arange(n_unit) % 3]
    mixed = np.einsum("rj,rjk->rk", row_bary[n_unit:], values.take(row_src[n_unit:], axis=0))
    if unit:
        mixed /= np.maximum(np.sqrt(np.einsum("rk,rk->r", mixed, mixed)), 1e-300)[:, None]
    per_row[n_unit:] = mixed
    return per_row.take(corner_row, axis=0)


def _strip_corners(src, xy):
    """For strips (see :func:`subdivide`): the angles (S, 3) of the corners of the triangles ``src``
    (S, 3) about the origin of the 2-D coordinates ``xy`` (N, 2), and the local indices (S,) of the
    first, middle and last corner in angle (a, c, b)."""
    ang = np.arctan2(xy.take(src, axis=0)[..., 1], xy.take(src, axis=0)[..., 0])
    rel = np.mod(ang - ang[:, :1] + np.pi, 2 * np.pi) - np.pi
    order = np.argsort(rel, axis=1, kind="stable")
    return ang, order[:, 0], order[:, 1], order[:, 2]


def _slot(i, j):
    """Edge slot (0, 1, 2) of the side joining local corners ``i`` and ``j`` (arrays): slot k joins
    corner k and corner (k + 1) % 3."""
    lo, hi = np.minimum(i, j), np.maximum(i, j)
    return np.where(hi - lo == 1, lo, 2)


def _chain(src, of_tri, verts, levels, n_pts, x, y, xy):
    """Interior points of the sides from local corner ``x`` to local corner ``y`` (S,) of the triangles
    ``src`` (S, 3): per point (in order along each side, triangles in order) its triangle (local index),
    key, barycentrics (P, 3) and the 2-D coordinates (P, 2) of ``xy`` interpolated there."""
    rows = np.arange(len(src))
    e = of_tri[rows, _slot(x, y)]
    lev = levels.take(e)
    count = lev - 1
    tri = np.repeat(rows, count)
    m = group_offsets(count) + 1  # 1 .. lev - 1 from corner x
    lev_p, e_p = lev.take(tri), e.take(tri)
    t = m / lev_p
    vx, vy = src[tri, x.take(tri)], src[tri, y.take(tri)]
    forward = vx == verts[e_p, 0]  # the edge's own grid runs from its lower vertex
    key = n_pts + e_p * (GRID + 1) + np.where(forward, m, lev_p - m)
    bary = np.zeros((tri.size, 3))
    bary[np.arange(tri.size), x.take(tri)] = 1.0 - t
    bary[np.arange(tri.size), y.take(tri)] = t
    p = (1.0 - t)[:, None] * xy.take(vx, axis=0) + t[:, None] * xy.take(vy, axis=0)
    return tri, key, bary, p


def _strip_faces(src, of_tri, verts, levels, n_pts, xy, corner_order):
    """Strip triangulation of the triangles ``src`` (S, 3) (see :func:`subdivide`, ``strips``), with
    ``corner_order`` their :func:`_strip_corners`.

    Returns (keys (P,), bary (P, 3), row_tri (P,), faces (F, 3) indexing the P points, face_tri (F,)):
    the points are the corners (3 per triangle, in corner order) and the sides' interior grid points;
    faces are wound like their source triangle."""
    S = len(src)
    ang, a, c, b = corner_order
    rows = np.arange(S)
    # chain 1: side a -> b; chain 2: sides a -> c, the corner c, c -> b
    t1, k1, b1, p1 = _chain(src, of_tri, verts, levels, n_pts, a, b, xy)
    ta, ka, ba, pa = _chain(src, of_tri, verts, levels, n_pts, a, c, xy)
    tb, kb, bb, pb = _chain(src, of_tri, verts, levels, n_pts, c, b, xy)
    bc = np.zeros((S, 3))
    bc[rows, c] = 1.0
    t2 = np.concatenate([ta, rows, tb])
    s2 = np.concatenate([np.zeros(ta.size), np.ones(S), np.full(tb.size, 2.0)])
    o2 = np.lexsort((s2, t2))  # per triangle: side a -> c, corner c, side c -> b
    t2, k2 = t2[o2], np.concatenate([ka, src[rows, c], kb])[o2]
    b2, p2 = np.concatenate([ba, bc, bb])[o2], np.concatenate([pa, xy.take(src[rows, c], axis=0), pb])[o2]
    n1, n2 = np.bincount(t1, minlength=S), np.bincount(t2, minlength=S)
    off1, off2 = np.cumsum(n1) - n1, np.cumsum(n2) - n2
    # angle of each point from corner a, made non-decreasing along each chain (the triangle's index
    # keeps the chains of different triangles apart)
    base = ang[rows, a]

    def along(t, p):
        r = np.mod(np.arctan2(p[:, 1], p[:, 0]) - base.take(t) + np.pi, 2 * np.pi) - np.pi
        return np.maximum.accumulate(4.0 * t + np.clip(r, 0.0, np.pi))

    s1, s2 = along(t1, p1), along(t2, p2)
    # merge the chains by angle; every interleaving triangulates the (convex) triangle
    merged = np.argsort(np.concatenate([s1, s2]), kind="stable")
    tri_m = np.concatenate([t1, t2])[merged]
    is2 = merged >= t1.size
    idx = np.where(is2, merged - t1.size, merged)  # index within its chain array
    local = idx - np.where(is2, off2.take(tri_m), off1.take(tri_m))  # position along its chain
    c1 = np.cumsum(~is2) - (~is2)  # chain-1 points before (global); per triangle below
    c2 = np.cumsum(is2) - is2
    c1 -= off1.take(tri_m)
    c2 -= off2.take(tri_m)
    # points: corners (3 per triangle), chain 1, chain 2
    n_c = 3 * S
    P1, P2 = n_c + off1, n_c + t1.size + off2  # first point of each triangle's chains
    corner_pt = 3 * rows[:, None] + np.arange(3)[None, :]
    ev = local > 0  # the first point of each chain starts the strip
    e1, e2 = ev & ~is2, ev & is2
    tm1, tm2 = tri_m[e1], tri_m[e2]
    f1 = np.stack([P1.take(tm1) + local[e1] - 1, P1.take(tm1) + local[e1],
                   P2.take(tm1) + np.maximum(c2[e1] - 1, 0)], axis=1)
    f2 = np.stack([P2.take(tm2) + local[e2], P2.take(tm2) + local[e2] - 1,
                   P1.take(tm2) + np.maximum(c1[e2] - 1, 0)], axis=1)
    first = np.stack([corner_pt[rows, a], P1, P2], axis=1)
    last = np.stack([P1 + n1 - 1, corner_pt[rows, b], P2 + n2 - 1], axis=1)
    faces = np.concatenate([first, f1, f2, last])
    face_tri = np.concatenate([rows, tm1, tri_m[e2], rows])
    # wound like the source: (a, b, c) is an even permutation of (0, 1, 2) when b follows a
    flip = (b != (a + 1) % 3).take(face_tri)
    faces[flip] = faces[flip][:, ::-1]
    keys = np.concatenate([src.ravel(), k1, k2])
    bary = np.concatenate([np.tile(np.eye(3), (S, 1)), b1, b2])
    row_tri = np.concatenate([np.repeat(rows, 3), t1, t2])
    return keys, bary, row_tri, faces, face_tri


def subdivide(points: np.ndarray, tris: np.ndarray, edges: Edges, levels: np.ndarray, strips=None,
              copy: bool = True) -> Subdivided:
    """Subdivide triangles ``tris`` (T, 3) of vertices ``points`` (N, 3) with per-edge ``levels``
    (integers 1 .. GRID, shape (E,)). See the module docstring for the scheme.

    ``strips``: None, or (mask (T,) bool, xy (N, 2)): the masked triangles are cut into strips instead
    of the uniform grid. Seen from the origin of the 2-D coordinates ``xy`` of the points, the side
    joining the first and the last corner in angle and the two sides through the middle corner are
    two chains of the sides' own grid points, and consecutive points in angle are joined across the
    triangle (a zipper): l1 + l2 + l3 - 2 faces for side levels l1, l2, l3 instead of about L^2, with
    no interior vertices. Meant for triangles whose image is long in that angle and narrow across it
    (around an Einstein ring, with xy the coordinates across the observer-hole axis). Triangles whose
    first-to-last side has level 1, or with a corner whose xy is not finite, get the uniform grid.

    ``copy`` False: when nothing is split, the result's tris are ``tris`` itself (a caller's array of
    its own), not a copy."""
    points = np.asarray(points, dtype=np.float64)
    tris = np.asarray(tris, dtype=np.int64)
    n_pts, n_edges = len(points), len(edges.verts)
    lev = levels.take(edges.of_tri)
    tri_level = np.maximum(np.maximum(lev[:, 0], lev[:, 1]), lev[:, 2])
    strip_sel = None
    if strips is not None and len(tris):
        xy = np.asarray(strips[1], dtype=np.float64)
        strip_sel = np.flatnonzero(strips[0] & (tri_level > 1))
        finite = np.isfinite(xy.take(tris.take(strip_sel, axis=0), axis=0))  # (S, 3, 2)
        strip_sel = strip_sel[finite.reshape(len(strip_sel), 6).all(axis=1)]
        if strip_sel.size:
            order = _strip_corners(tris[strip_sel], xy)
            ok = lev[strip_sel, _slot(order[1], order[3])] > 1
            strip_sel, order = strip_sel[ok], tuple(v[ok] for v in order)
        if strip_sel.size:
            tri_level = tri_level.copy()
            tri_level[strip_sel] = 0  # not in the uniform groups below
        else:
            strip_sel = None
    if len(tris) and tri_level.max() == 1 and strip_sel is None:  # nothing to split: the source itself
        return Subdivided(positions=points, tris=tris.copy() if copy else tris, source_tri=np.arange(len(tris)),
                          row_bary=None,
                          row_src=None, corner_row=None, vertex_key=np.arange(n_pts), identity=True, n_pass=len(tris))
    src_parts, other_key_parts, other_pos_parts, level_parts = [], [], [], []
    row_bary_parts, row_src_parts, corner_row_parts = [], [], []
    n_rows = 0
    unsplit_faces = None
    interior_base = n_pts + n_edges * (GRID + 1)
    unit = np.flatnonzero(tri_level == 1)
    if unit.size:  # unsplit triangles: their corners are source vertices, keyed by their indices
        unsplit_faces = tris[unit]
        src_parts.append(unit)
        row_bary_parts.append(np.tile(np.eye(3), (unit.size, 1)))
        row_src_parts.append(np.repeat(unit, 3))
        corner_row_parts.append(np.arange(3 * unit.size).reshape(-1, 3))
        n_rows += 3 * unit.size
    split = np.flatnonzero(tri_level > 1)
    if split.size:  # all split triangles at once, by level, then by index (each on its level's template)
        sel = split[np.argsort(tri_level[split], kind="stable")]
        level = tri_level[sel]  # (S,)
        src = tris[sel]  # (S, 3)
        tpl = _templates()
        nv = tpl.n_verts[level]
        row_start = np.cumsum(nv) - nv  # each triangle's first row (template vertex)
        vt = np.repeat(np.arange(sel.size), nv)  # the triangle of each row
        local = group_offsets(nv)  # the row's template vertex
        at = tpl.vert_start[level].take(vt) + local  # into the concatenated templates
        lv = level.take(vt)
        tedge, tcorner = tpl.edge.take(at), tpl.corner.take(at)
        # barycentrics of the template vertices, then snapped along low-level edges
        bary = np.empty((vt.size, 3))
        bary[:, 1] = tpl.ij[at, 0] / lv
        bary[:, 2] = tpl.ij[at, 1] / lv
        key = np.empty(vt.size, dtype=np.int64)
        corner = np.flatnonzero(tcorner >= 0)
        key[corner] = src[vt[corner], tcorner[corner]]
        # interior vertices: unique per triangle
        inner = np.flatnonzero((tcorner < 0) & (tedge < 0))
        key[inner] = interior_base + (sel[vt[inner]] * (GRID + 1) ** 2 + local[inner])
        on_edge = np.flatnonzero(tedge >= 0)
        t, k = vt[on_edge], tedge[on_edge]
        k1 = (k + 1) % 3
        e = edges.of_tri[sel[t], k]
        lev = levels[e]
        t_tri = tpl.t[at[on_edge]] / lv[on_edge]  # along corner k -> corner k+1
        t_snap = np.floor(t_tri * lev + 0.5) / lev
        forward = src[t, k] < src[t, k1]
        t_canon = np.where(forward, t_snap, 1.0 - t_snap)  # along the edge from its lower vertex
        num = np.rint(t_canon * lev).astype(np.int64)  # index on the edge's own grid
        key[on_edge] = np.where(num == 0, edges.verts[e, 0],
                                np.where(num == lev, edges.verts[e, 1], n_pts + e * (GRID + 1) + num))
        b = np.zeros((on_edge.size, 3))
        b[np.arange(on_edge.size), k] = 1.0 - t_snap
        b[np.arange(on_edge.size), k1] = t_snap
        bary[on_edge] = b
        bary[:, 0] = 1.0 - bary[:, 1] - bary[:, 2]
        # positions are needed only for the new vertices (corners are the source's own points)
        other = key >= n_pts
        other_key_parts.append(key[other])
        other_pos_parts.append((bary[other], src[vt[other]]))
        # the pieces: each triangle's template triangles, on its rows
        nt = tpl.n_tris[level]
        ft = np.repeat(np.arange(sel.size), nt)
        pieces = tpl.tris[tpl.tri_start[level].take(ft) + group_offsets(nt)] + row_start.take(ft)[:, None]
        level_parts.append((key[None, :], other[None, :], pieces))
        src_parts.append(sel.take(ft))
        row_bary_parts.append(bary)
        row_src_parts.append(sel.take(vt))
        corner_row_parts.append(n_rows + pieces)
        n_rows += vt.size
    if strip_sel is not None:
        keys, sbary, row_tri, sfaces, face_tri = _strip_faces(tris[strip_sel], edges.of_tri[strip_sel],
                                                              edges.verts, levels, n_pts, xy, order)
        other = keys >= n_pts
        other_key_parts.append(keys[other])
        other_pos_parts.append((sbary[other], tris[strip_sel[row_tri[other]]]))
        level_parts.append((keys[None, :], other[None, :], sfaces))
        src_parts.append(strip_sel[face_tri])
        row_bary_parts.append(sbary)
        row_src_parts.append(strip_sel[row_tri])
        corner_row_parts.append(n_rows + sfaces)
        n_rows += keys.size
    if not level_parts:
        return Subdivided(np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int64),
                          np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 3), np.int64), np.zeros(0, np.int64))
    # weld: corner keys (< n_pts) are source vertex indices (every corner of a source triangle is a
    # corner of one of its pieces); the others are merged by np.unique. Vertices come out sorted by
    # key (corners first), so equal inputs give equal meshes.
    used = np.zeros(n_pts, dtype=bool)
    used[tris.ravel()] = True
    corners = np.flatnonzero(used)
    index = np.full(n_pts, -1, dtype=np.int64)
    index[corners] = np.arange(corners.size)
    if other_key_parts:
        uniq, first, inverse = np.unique(np.concatenate(other_key_parts), return_index=True, return_inverse=True)
        b = np.concatenate([bp for bp, _ in other_pos_parts])[first]
        corner_idx = np.concatenate([cp for _, cp in other_pos_parts])[first]
        other_pos = np.einsum("mk,mkx->mx", b, points.take(corner_idx.ravel(), axis=0).reshape(-1, 3, 3))
    else:
        uniq, inverse, other_pos = np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3))
    face_parts = [index[unsplit_faces]] if unsplit_faces is not None else []
    offset = 0
    for key, other, ttris in level_parts:
        vid = np.empty(key.shape, dtype=np.int64)
        vid[~other] = index[key[~other]]
        n_other = int(np.count_nonzero(other))
        vid[other] = corners.size + inverse[offset:offset + n_other]
        offset += n_other
        face_parts.append(vid[:, ttris].reshape(-1, 3))
    faces = np.concatenate(face_parts)
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    n_unsplit = int(np.count_nonzero(tri_level == 1))  # the unsplit triangles come first
    n_pass = n_unsplit if keep[:n_unsplit].all() else 0
    source_tri, corner_row = np.concatenate(src_parts), np.concatenate(corner_row_parts)
    if not keep.all():
        k = np.flatnonzero(keep)  # (take is several times faster than boolean indexing)
        faces, source_tri, corner_row = faces.take(k, axis=0), source_tri.take(k), corner_row.take(k, axis=0)
    return Subdivided(positions=np.concatenate([points.take(corners, axis=0), other_pos]), tris=faces,
                      source_tri=source_tri, row_bary=np.concatenate(row_bary_parts),
                      row_src=np.concatenate(row_src_parts), corner_row=corner_row,
                      vertex_key=np.concatenate([corners, uniq]), n_pass=n_pass, n_unit_rows=3 * n_unsplit)


@dataclass
class Pieces:
    """One order's source cut into pieces: ``sub`` (:class:`Subdivided`, over the selected source
    triangles), ``face_src`` (F,) each face's source triangle (index into the prepared source's tris),
    ``selected`` (the level plan's selection: sub's triangle t is source triangle selected[t]) and
    ``images`` (mapping.Images of sub's vertices, in the plan's order); ``cut`` (F,) bool: the faces the
    refine step replaced by their parts (interior.refine; None: none)."""

    sub: Subdivided
    face_src: np.ndarray
    selected: np.ndarray
    images: object
    cut: np.ndarray | None = None


def cut(frame, source, plan, coarse_images) -> Pieces:
    """The subdivide stage: the selected source triangles of a level plan (level_plan.LevelPlan) cut at
    its levels (strips where it says so), and the new vertices mapped (frame.map; the source's own
    corners keep ``coarse_images``, their images of the plan's order, and the edge midpoints the plan
    mapped keep theirs, LevelPlan.known)."""
    sel = plan.selected
    edges = source.edges
    strips = None if plan.strips is None else (plan.strips, source.xy)
    sub = subdivide(source.positions, source.tris.take(sel, axis=0),
                    Edges(edges.verts, edges.of_tri.take(sel, axis=0)), plan.levels, strips,
                    copy=False)  # (the selection's tris are this call's own)
    if sub.identity:  # the source's own vertices, in order
        images = coarse_images
    else:
        images = frame.map.extend(coarse_images, sub.positions, sub.vertex_key, len(source.positions), plan.order,
                                  plan.known)
    return Pieces(sub, sel.take(sub.source_tri), sel, images)
