"""The budget inside the pieces: each drawn piece's error measured where the renderer interpolates.

A renderer draws an image triangle with its attributes interpolated perspective-correct, i.e. linearly
in space over the triangle (positions, UVs, the light-travel-time pass). The source point at the
barycentric coordinates b of a piece (source corners S_i, image corners Q_i with light travel times
c*dt_i) is therefore drawn

* on the screen in the direction of sum_i b_i Q_i from the camera, where its exact image is in the
  direction the map stage gives for sum_i b_i S_i: their angle, in pixels, is the error of the drawn
  surface and of its UVs (a UV is affine over its source triangle, so the point drawn with the
  interpolated UV is that source point);
* in the light-travel pass with sum_i b_i c*dt_i, where the exact value is its own c*dt: their
  difference relative to c*dt.

:func:`measure` samples every piece that can be off at all at its centroid and its three edge
midpoints and returns its error in units of the budget (budget.Budget.tolerance_px on
the screen, budget.LIGHT_TRAVEL_TOLERANCE relative for the pass): above 1, the piece breaks the
budget and the refine step (pipeline) cuts its source triangle further. A piece whose image spans at
most budget.SAMPLE_MIN_PX pixels and whose source extent is at most budget.SAMPLE_MIN_REACH of its
light travel distance is not sampled (an edge that short keeps level 1 in the level plan too, and its
light travel time bends by far less than the tolerance over it).

Units: positions in Blender units (BU), screen errors in pixels of the frame's camera, light travel
time as a length c*dt in BU.
"""
from __future__ import annotations

import numpy as np

from dataclasses import dataclass, field

from . import budget as B
from .mapping import row_norm

def measure(frame, positions, tris, images, order, faces=None):
    """(errors (F,), screen_px (F,), lt_rel (F,)) of the pieces ``tris`` (F, 3) with source corners
    ``positions`` (V, 3; BU) and images ``images`` (mapping.Images of those V points, order ``order``),
    only for the ``faces`` (indices; None: all): errors in units of the budget (the larger of
    screen_px / tolerance and lt_rel / LIGHT_TRAVEL_TOLERANCE; 0 where not sampled, NaN where a
    sample has no image), screen_px the largest screen error (pixels) and lt_rel the largest relative
    light-travel-time error at the samples: each piece's centroid and its edges' midpoints. Where the
    map is quadratic over a piece the edge midpoints bound the error everywhere inside (the deviation at
    b is sum_{i<j} 4 b_i b_j m_ij for the midpoint deviations m_ij); the centroid catches the larger
    pieces where it is not. Each edge's midpoint is mapped once, for both pieces beside it."""
    n = len(tris)
    err, scr, ltr = np.zeros(n), np.zeros(n), np.zeros(n)
    budget = frame.budget
    if not budget.active or n == 0:
        return err, scr, ltr
    f = np.arange(n) if faces is None else np.asarray(faces)
    t = tris.take(f, axis=0)
    q = images.position.take(t, axis=0)  # (K, 3, 3)
    dist = images.distance.take(t)  # (K, 3)
    s = positions.take(t, axis=0)
    # which pieces can be off at all (module docstring)
    with np.errstate(invalid="ignore"):
        d = images.direction.take(t, axis=0)
        side = np.maximum(np.maximum(row_norm(d[:, 1] - d[:, 0]), row_norm(d[:, 2] - d[:, 1])),
                          row_norm(d[:, 0] - d[:, 2]))
        reach = np.maximum(np.maximum(row_norm(s[:, 1] - s[:, 0]), row_norm(s[:, 2] - s[:, 1])),
                           row_norm(s[:, 0] - s[:, 2]))
        big = (side > B.SAMPLE_MIN_PX * budget.pixel_angle) | (reach > B.SAMPLE_REACH * dist.min(axis=1))
        big &= images.valid.take(t).all(axis=1)
    k = np.flatnonzero(big)
    if k.size == 0:
        return err, scr, ltr
    f, q, dist, s, t = f[k], q[k], dist[k], s[k], t[k]
    # the samples: each piece's centroid and each of its edges' midpoints, once per edge (shared)
    lo, hi = np.minimum(t, np.roll(t, -1, axis=1)), np.maximum(t, np.roll(t, -1, axis=1))
    _, first, side = np.unique((lo * len(positions) + hi).ravel(), return_index=True, return_inverse=True)
    ea, eb = lo.ravel().take(first), hi.ravel().take(first)
    pts = np.concatenate([s.mean(axis=1), 0.5 * (positions.take(ea, axis=0) + positions.take(eb, axis=0))])
    drawn = np.concatenate([q.mean(axis=1), 0.5 * (images.position.take(ea, axis=0) + images.position.take(eb, axis=0))])
    drawn_lt = np.concatenate([dist.mean(axis=1), 0.5 * (images.distance.take(ea) + images.distance.take(eb))])
    true = frame.map.images(pts, (order,))[order]
    cam = frame.scene.camera
    with np.errstate(invalid="ignore", divide="ignore"):
        v = drawn - cam
        v /= row_norm(v)[:, None]
        # the angle between unit vectors from the chord (accurate for small angles)
        chord = row_norm(v - true.direction)
        ang = 2.0 * np.arcsin(np.clip(0.5 * chord, 0.0, 1.0)) / budget.pixel_angle
        lt = np.abs(drawn_lt - true.distance) / true.distance
    ang = np.where(true.valid, ang, np.nan)
    lt = np.where(true.valid, lt, np.nan)
    n_c = len(f)
    side = side.reshape(-1, 3) + n_c
    scr[f] = np.maximum(ang[:n_c], ang.take(side).max(axis=1))
    ltr[f] = np.maximum(lt[:n_c], lt.take(side).max(axis=1))
    err[f] = np.maximum(scr[f] / budget.tolerance_px, ltr[f] / B.LIGHT_TRAVEL_TOLERANCE)
    return err, scr, ltr


def midpoint_errors(frame, qa, qb, la, lb, mid) -> tuple[np.ndarray, np.ndarray]:
    """(screen_px (E,), lt_units (E,)) of edges whose end points have images at ``qa``, ``qb`` (E, 3;
    BU) with light travel distances ``la``, ``lb`` (E,) and whose midpoints have the images ``mid``
    (mapping.Images): where the renderer draws the midpoint ((qa + qb) / 2 and (la + lb) / 2) against
    its exact image, in pixels and in units of LIGHT_TRAVEL_TOLERANCE. NaN without an image."""
    with np.errstate(invalid="ignore", divide="ignore"):
        v = qa + qb
        v -= 2.0 * frame.scene.camera
        v /= row_norm(v)[:, None]
        v -= mid.direction
        # the chord between the unit directions for their angle (short by angle^3 / 24: nothing at
        # the angles that matter, a fraction of a pixel)
        px = row_norm(v) / frame.budget.pixel_angle
        lt = np.abs(la + lb - 2.0 * mid.distance) / (2.0 * B.LIGHT_TRAVEL_TOLERANCE * mid.distance)
    return px, lt


def sampled_sources(frame, source) -> np.ndarray:
    """(T,) bool: the source triangles whose pieces are measured (budget.SAMPLE_REACH): those with an
    edge longer (BU) than SAMPLE_REACH times the distance of its nearer end from the camera or the
    hole. Per vertex and per edge, so that a dense mesh costs one pass over its edges."""
    pts, ev = source.positions, source.edges.verts
    scene = frame.scene
    scale = np.minimum(row_norm(pts - scene.camera), row_norm(pts - scene.hole))
    length = source.edge_length  # (frame.prepare_source)
    if length is None:
        length = row_norm(pts.take(ev[:, 1], axis=0) - pts.take(ev[:, 0], axis=0))
    if not length.max(initial=0.0) > B.SAMPLE_REACH * scale.min(initial=np.inf):
        return np.zeros(len(source.tris), bool)
    long = length > B.SAMPLE_REACH * np.minimum(scale.take(ev[:, 0]), scale.take(ev[:, 1]))
    return long.take(source.edges.of_tri).any(axis=1)


@dataclass
class Beyond:
    """One order's kept pieces against the budget inside (after the refine step's last round):
    ``sampled`` pieces measured, ``count`` of them beyond the budget, the largest screen error
    ``screen_px`` (pixels) and relative light-travel-time error ``lt_rel`` measured (0 when none was
    sampled)."""

    sampled: int = 0
    count: int = 0
    screen_px: float = 0.0
    lt_rel: float = 0.0


def refine(frame, source, pieces, keep, order, room, sampled=None):
    """The refine step of one order: the kept pieces of the source triangles that are sampled
    (:func:`sampled_sources`, or ``sampled`` (T,) bool when given) are measured (:func:`measure`);
    those beyond the budget are cut in four at their edges' midpoints, their neighbours in two
    across a cut edge (in four when two of their edges are cut), so that the mesh stays watertight,
    and the new pieces are measured again, at most budget.REFINE_ROUNDS times. The worst pieces are
    cut first, and no cut is made that would bring the kept pieces beyond ``room`` image triangles
    (Settings.max_triangles less the other orders'). Cut pieces stay in ``pieces`` (not kept); their
    parts are appended, each corner's values interpolated in its source triangle like the cut's.

    Returns (pieces, keep, Beyond, bound_reached, cut): the pieces and keep mask (new ones when
    something was cut; Pieces.cut marks the pieces replaced by their parts), the figures of the kept
    pieces after the last round, whether ``room`` stopped a cut, and the number of pieces cut."""
    beyond = Beyond()
    if not frame.budget.active or pieces is None or keep is None:
        return pieces, keep, beyond, False, 0
    if sampled is None:
        sampled = sampled_sources(frame, source)
    if not sampled.any():
        return pieces, keep, beyond, False, 0
    sub, img = pieces.sub, pieces.images
    cand = np.flatnonzero(keep & sampled.take(pieces.face_src))
    if cand.size == 0:
        return pieces, keep, beyond, False, 0
    err, scr, ltr = measure(frame, sub.positions, sub.tris, img, order, cand)
    over = cand[np.nan_to_num(err.take(cand)) > 1.0]
    bound = False
    added = 0
    if over.size:
        mesh = _Editable(sub, img, keep, pieces.selected)
        mesh.err, mesh.scr, mesh.ltr = err, scr, ltr
        for _ in range(B.REFINE_ROUNDS):
            if over.size == 0:
                break
            free = room - int(np.count_nonzero(mesh.keep))
            rank = over[np.argsort(-mesh.err.take(over), kind="stable")]
            fit = rank[:max(0, free // 6)]  # a piece cut in four (and its neighbours in two) adds about 3 + 3
            if fit.size < over.size:
                bound = True
            if fit.size == 0:
                break
            new = mesh.cut(fit, frame, order)
            e, sc, lt = measure(frame, mesh.positions, mesh.tris, mesh.images, order, new)
            mesh.set_figures(new, e, sc, lt)
            over = new[np.nan_to_num(e.take(new)) > 1.0]
        pieces, keep = mesh.result(pieces)
        added = int(pieces.cut.sum())
        err, scr, ltr = mesh.err, mesh.scr, mesh.ltr
    kept = np.flatnonzero(keep)
    m = kept[sampled.take(pieces.face_src.take(kept))]
    e = np.nan_to_num(err.take(m))
    beyond = Beyond(int(np.count_nonzero(e > 0)), int(np.count_nonzero(e > 1.0)),
                    float(np.nan_to_num(scr.take(m)).max(initial=0.0)), float(np.nan_to_num(ltr.take(m)).max(initial=0.0)))
    return pieces, keep, beyond, bound, added


class _Editable:
    """A cut (subdivision.Subdivided, its images and keep mask) that :meth:`cut` refines in place:
    faces are never removed (a cut one is no longer kept), parts and new vertices are appended."""

    def __init__(self, sub, img, keep, selected):
        n_f = len(sub.tris)
        if sub.identity:  # every corner its own row (barycentrics of the unit triangle)
            row_bary = np.tile(np.eye(3), (n_f, 1))
            row_src = np.repeat(np.arange(n_f), 3)
            corner_row = np.arange(3 * n_f).reshape(-1, 3)
            n_unit = 3 * n_f
        else:
            row_bary, row_src, corner_row, n_unit = sub.row_bary, sub.row_src, sub.corner_row, sub.n_unit_rows
        self.sub, self.n_unit, self.selected = sub, n_unit, selected
        self.positions, self.tris, self.source_tri = sub.positions, sub.tris, sub.source_tri
        self.row_bary, self.row_src, self.corner_row = row_bary, row_src, corner_row
        self.vertex_key = sub.vertex_key
        self.images = img
        self.keep = keep.copy()
        self.replaced = np.zeros(n_f, bool)
        self.err = self.scr = self.ltr = None

    @property
    def n_faces(self):
        return len(self.tris)

    def set_figures(self, faces, e, sc, lt):
        self.err[faces], self.scr[faces], self.ltr[faces] = e.take(faces), sc.take(faces), lt.take(faces)

    def cut(self, faces, frame, order) -> np.ndarray:
        """Cut the kept ``faces`` in four and their neighbours as needed (see :func:`refine`); returns
        the indices of the new faces."""
        tris, keep = self.tris, self.keep
        n_v = len(self.positions)
        red = np.zeros(len(tris), bool)
        red[faces] = True

        def keys(t):  # (K, 3) undirected edge keys of the faces ``t`` (corner k -> k + 1)
            a, b = tris.take(t, axis=0), np.roll(tris.take(t, axis=0), -1, axis=1)
            return np.minimum(a, b) * n_v + np.maximum(a, b)

        marked = np.unique(keys(faces))
        kept = np.flatnonzero(keep)
        while True:  # closure: a kept face with two cut edges is cut in four
            near = np.zeros(n_v, bool)
            near[np.unique(marked // n_v)] = True
            near[np.unique(marked % n_v)] = True
            around = kept[near.take(tris.take(kept, axis=0)).sum(axis=1) >= 2]
            around = around[~red.take(around)]
            hit = np.isin(keys(around), marked)
            two = around[hit.sum(axis=1) >= 2]
            if two.size == 0:
                break
            red[two] = True
            marked = np.union1d(marked, keys(two).ravel())
        reds = np.flatnonzero(red)
        green = around[hit.sum(axis=1) == 1]
        green_k = np.argmax(hit[hit.sum(axis=1) == 1], axis=1)
        # the new vertices: one per cut edge, at its midpoint (source space), mapped
        lo, hi = marked // n_v, marked % n_v
        mid = 0.5 * (self.positions.take(lo, axis=0) + self.positions.take(hi, axis=0))
        new_img = frame.map.images(mid, (order,))[order]
        vid = n_v + np.arange(marked.size)
        self.positions = np.concatenate([self.positions, mid])
        self.vertex_key = np.concatenate([self.vertex_key, self.vertex_key.max(initial=0) + 1 + np.arange(marked.size)])
        self.images = _append_images(self.images, new_img)

        def mid_of(t, k):  # (K,) vertex index of the midpoint of side k of faces t
            a, b = tris[t, k], tris[t, (k + 1) % 3]
            return vid.take(np.searchsorted(marked, np.minimum(a, b) * n_v + np.maximum(a, b)))

        def mid_row(t, k):  # (K, 3) barycentrics (in each face's source triangle) of that midpoint
            rows = self.corner_row
            return 0.5 * (self.row_bary.take(rows[t, k], axis=0) + self.row_bary.take(rows[t, (k + 1) % 3], axis=0))

        new_tris, new_src, new_rows, row_bary, row_src = [], [], [], [], []
        n_r = len(self.row_bary)
        # red: (c0, m01, m20), (m01, c1, m12), (m20, m12, c2), (m01, m12, m20)
        if reds.size:
            c = tris.take(reds, axis=0)
            r = self.corner_row.take(reds, axis=0)
            m = np.stack([mid_of(reds, k) for k in range(3)], axis=1)
            mr = n_r + np.arange(3 * reds.size).reshape(-1, 3)  # rows of m01, m12, m20
            row_bary.append(np.stack([mid_row(reds, k) for k in range(3)], axis=1).reshape(-1, 3))
            row_src.append(np.repeat(self.row_src.take(r[:, 0]), 3))
            n_r += 3 * reds.size
            for vs, rs in (((c[:, 0], m[:, 0], m[:, 2]), (r[:, 0], mr[:, 0], mr[:, 2])),
                           ((m[:, 0], c[:, 1], m[:, 1]), (mr[:, 0], r[:, 1], mr[:, 1])),
                           ((m[:, 2], m[:, 1], c[:, 2]), (mr[:, 2], mr[:, 1], r[:, 2])),
                           ((m[:, 0], m[:, 1], m[:, 2]), (mr[:, 0], mr[:, 1], mr[:, 2]))):
                new_tris.append(np.stack(vs, axis=1))
                new_rows.append(np.stack(rs, axis=1))
                new_src.append(self.source_tri.take(reds))
        # green: side k cut: (A, M, C), (M, B, C) with A, B, C corners k, k + 1, k + 2
        if green.size:
            k = green_k
            rows_g = np.arange(green.size)
            a = tris[green, k]
            b = tris[green, (k + 1) % 3]
            cc = tris[green, (k + 2) % 3]
            ra = self.corner_row[green, k]
            rb = self.corner_row[green, (k + 1) % 3]
            rc = self.corner_row[green, (k + 2) % 3]
            mg = mid_of(green, k)
            mrow = n_r + rows_g
            row_bary.append(mid_row(green, k))
            row_src.append(self.row_src.take(ra))
            n_r += green.size
            new_tris += [np.stack([a, mg, cc], axis=1), np.stack([mg, b, cc], axis=1)]
            new_rows += [np.stack([ra, mrow, rc], axis=1), np.stack([mrow, rb, rc], axis=1)]
            new_src += [self.source_tri.take(green)] * 2
        first = len(tris)
        self.tris = np.concatenate([tris] + new_tris)
        self.corner_row = np.concatenate([self.corner_row] + new_rows)
        self.source_tri = np.concatenate([self.source_tri] + new_src)
        self.row_bary = np.concatenate([self.row_bary] + row_bary)
        self.row_src = np.concatenate([self.row_src] + row_src)
        n_new = len(self.tris) - first
        self.keep = np.concatenate([self.keep, np.ones(n_new, bool)])
        self.keep[reds] = False
        self.keep[green] = False
        self.replaced = np.concatenate([self.replaced, np.zeros(n_new, bool)])
        self.replaced[reds] = self.replaced[green] = True
        for name in ("err", "scr", "ltr"):
            setattr(self, name, np.concatenate([getattr(self, name), np.zeros(n_new)]))
        return first + np.arange(n_new)

    def result(self, pieces):
        """(pieces, keep) of the refined cut."""
        from .subdivision import Pieces, Subdivided

        sub = Subdivided(self.positions, self.tris, self.source_tri, self.row_bary, self.row_src, self.corner_row,
                         self.vertex_key, identity=False, n_pass=self.sub.n_pass, n_unit_rows=self.n_unit)
        return Pieces(sub, self.selected.take(self.source_tri), self.selected, self.images, self.replaced), self.keep


def _append_images(a, b):
    """mapping.Images of the points of ``a`` then those of ``b`` (positions, directions, distances,
    validity, table values)."""
    from .mapping import Images

    return Images(position=np.concatenate([a.position, b.position]), direction=np.concatenate([a.direction, b.direction]),
                  distance=np.concatenate([a.distance, b.distance]), valid=np.concatenate([a.valid, b.valid]),
                  plane=None, xi=np.concatenate([a.xi, b.xi]), dt=np.concatenate([a.dt, b.dt]), ux=None, uy=None)


