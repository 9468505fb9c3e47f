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

:func:`measure` samples every piece that can be off at all at the points SAMPLES (the centroid and
the three edge midpoints) and returns its error in units of the budget (budget.Budget.tolerance_px on
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

SAMPLES = np.array([[1 / 3, 1 / 3, 1 / 3], [0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5]])
"""Barycentric sample points of a piece: its centroid and its edge midpoints. Where the map is
quadratic over a piece the edge midpoints bound the error everywhere inside (the deviation at b is
sum_{i<j} 4 b_i b_j m_ij for midpoint deviations m_ij); the centroid catches the larger pieces where
it is not."""


def measure(frame, positions, tris, images, order, faces=None):
    """(errors (F,), screen_px (F,), lt_rel (F,)) of the pieces ``tris`` (F, 3) with source corners
    ``positions`` (V, 3; BU) and images ``images`` (mapping.Images of those V points, order ``order``),
    only for the ``faces`` (indices; None: all): errors in units of the budget (the larger of
    screen_px / tolerance and lt_rel / LIGHT_TRAVEL_TOLERANCE; 0 where not sampled, NaN where a
    sample has no image), screen_px the largest screen error (pixels) and lt_rel the largest relative
    light-travel-time error at the SAMPLES."""
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
    f, q, dist, s = f[k], q[k], dist[k], s[k]
    m = len(SAMPLES)
    pts = np.einsum("mi,kix->kmx", SAMPLES, s).reshape(-1, 3)
    drawn = np.einsum("mi,kix->kmx", SAMPLES, q).reshape(-1, 3)
    drawn_lt = np.einsum("mi,ki->km", SAMPLES, dist).reshape(-1)
    true = frame.map.images(pts, (order,))[order]
    cam = frame.scene.camera
    with np.errstate(invalid="ignore", divide="ignore"):
        v = drawn - cam
        v /= row_norm(v)[:, None]
        # the angle between unit vectors from the chord (accurate for small angles)
        chord = row_norm(v - true.direction)
        ang = 2.0 * np.arcsin(np.clip(0.5 * chord, 0.0, 1.0)) / budget.pixel_angle
        lt = np.abs(drawn_lt - true.distance) / true.distance
    ang = np.where(true.valid, ang, np.nan).reshape(-1, m)
    lt = np.where(true.valid, lt, np.nan).reshape(-1, m)
    scr[f] = ang.max(axis=1)
    ltr[f] = lt.max(axis=1)
    err[f] = np.maximum(scr[f] / budget.tolerance_px, ltr[f] / B.LIGHT_TRAVEL_TOLERANCE)
    return err, scr, ltr


def midpoint_errors(frame, qa, qb, la, lb, mid) -> tuple[np.ndarray, np.ndarray]:
    """(screen_px (E,), lt_units (E,)) of edges whose end points have images at ``qa``, ``qb`` (E, 3;
    BU) with light travel distances ``la``, ``lb`` (E,) and whose midpoints have the images ``mid``
    (mapping.Images): where the renderer draws the midpoint ((qa + qb) / 2 and (la + lb) / 2) against
    its exact image, in pixels and in units of LIGHT_TRAVEL_TOLERANCE. NaN without an image."""
    with np.errstate(invalid="ignore", divide="ignore"):
        v = 0.5 * (qa + qb) - frame.scene.camera
        v /= row_norm(v)[:, None]
        chord = row_norm(v - mid.direction)
        px = 2.0 * np.arcsin(np.clip(0.5 * chord, 0.0, 1.0)) / frame.budget.pixel_angle
        lt = np.abs(0.5 * (la + lb) - mid.distance) / (mid.distance * B.LIGHT_TRAVEL_TOLERANCE)
    return px, lt


def sampled_sources(frame, source) -> np.ndarray:
    """(T,) bool: the source triangles whose pieces are measured (budget.SAMPLE_REACH): those with an
    edge longer (BU) than SAMPLE_REACH times the distance of its nearer end from the camera or the
    hole. Per vertex and per edge, so that a dense mesh costs one pass over its edges."""
    pts, ev = source.positions, source.edges.verts
    scene = frame.scene
    scale = np.minimum(row_norm(pts - scene.camera), row_norm(pts - scene.hole))
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


@dataclass
class Verdict:
    """:func:`judge`'s answer: ``split_levels`` (E,) per source edge for the next round (None: no
    round), ``per_order`` {order: Beyond} and ``bound_reached`` (a split was left out for
    Settings.max_triangles); for :meth:`carry`, ``memo``: per order the measured figures per source
    triangle (pieces sampled, pieces beyond, largest screen px, largest lt rel; (4, T)) and the
    source's ``of_tri``."""

    split_levels: np.ndarray | None
    per_order: dict = field(default_factory=dict)
    bound_reached: bool = False
    memo: dict = field(default_factory=dict, repr=False)
    of_tri: np.ndarray | None = field(default=None, repr=False)

    def carry(self, parent) -> dict:
        """The figures of the next round's source triangles, whose triangles of this round are
        ``parent`` (T',), that are known already: those of the triangles that were not split (all
        three edges at level 1: the same triangle with the same edges, so the same pieces); NaN
        for the others."""
        whole = (self.split_levels.take(self.of_tri).max(axis=1) == 1).take(parent)
        out = {}
        for order, m in self.memo.items():
            carried = np.full((4, len(parent)), np.nan)
            carried[:, whole] = m[:, parent[whole]]
            out[order] = carried
        return out


def judge(frame, st, memo=None, last: bool = False) -> Verdict:
    """Measure the kept pieces of every order of the stages ``st`` (pipeline.Stages) and decide the
    refine step's next split (budget.REFINE_ROUNDS): the source triangles with a piece beyond the
    budget (error E > 1), each split in four, the worst first, as many as keep the estimated image
    triangles (each split triangle's pieces times E) within Settings.max_triangles. ``memo``: the
    figures carried from the previous round (Verdict.carry: the triangles measured already are not
    measured again); ``last``: measure only."""
    source = st.source
    n_src = len(source.tris)
    verdict = Verdict(None, of_tri=None if source.edges is None else source.edges.of_tri)
    if not frame.budget.active or n_src == 0 or not st.orders:
        return verdict
    sampled = sampled_sources(frame, source)
    if not sampled.any():
        verdict.per_order = {o: Beyond() for o, s in st.orders.items() if s.keep is not None}
        return verdict
    tol, lt_tol = frame.budget.tolerance_px, B.LIGHT_TRAVEL_TOLERANCE
    worst = np.zeros(n_src)
    pieces = np.zeros(n_src)
    total = 0
    for order, s in st.orders.items():
        if s.keep is None:
            continue
        kept = np.flatnonzero(s.keep)
        total += kept.size + s.report.patch_faces
        face_src = s.pieces.face_src
        kept_src = face_src.take(kept)
        pieces += np.bincount(kept_src, minlength=n_src)
        known = memo.get(order) if memo else None
        m = np.zeros((4, n_src))  # sampled, beyond, screen px, lt rel per source triangle
        todo = sampled.copy()
        if known is not None:
            have = ~np.isnan(known[0])
            m[:, have] = known[:, have]
            todo &= ~have
        cand = kept[todo.take(kept_src)] if todo.any() else kept[:0]
        if cand.size:
            sub = s.pieces.sub
            err, scr, ltr = measure(frame, sub.positions, sub.tris, s.pieces.images, order, cand)
            fs = face_src.take(cand)
            e = np.nan_to_num(err.take(cand))
            m[0] += np.bincount(fs, weights=(e > 0), minlength=n_src)
            m[1] += np.bincount(fs, weights=(e > 1.0), minlength=n_src)
            np.fmax.at(m[2], fs, np.nan_to_num(scr.take(cand)))
            np.fmax.at(m[3], fs, np.nan_to_num(ltr.take(cand)))
        verdict.memo[order] = m
        verdict.per_order[order] = Beyond(int(m[0].sum()), int(m[1].sum()), float(m[2].max(initial=0.0)),
                                          float(m[3].max(initial=0.0)))
        worst = np.maximum(worst, np.where(m[1] > 0, np.maximum(m[2] / tol, m[3] / lt_tol), 0.0))
    bad = np.flatnonzero(worst > 1.0)
    if bad.size == 0 or last:
        return verdict
    e = worst.take(bad)
    grow = np.maximum(pieces.take(bad) * e, 4.0)  # estimated image triangles after the split
    rank = np.argsort(-e, kind="stable")
    fits = np.cumsum(grow.take(rank) - pieces.take(bad).take(rank)) <= frame.settings.max_triangles - total
    take = bad.take(rank[:int(np.count_nonzero(fits))])  # the growth is positive, so ``fits`` is a prefix
    verdict.bound_reached = take.size < bad.size
    if take.size == 0:
        return verdict
    levels = np.ones(len(source.edges.verts), np.int64)
    levels[source.edges.of_tri.take(take, axis=0).ravel()] = 2
    verdict.split_levels = levels
    return verdict
