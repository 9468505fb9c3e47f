"""Einstein-ring patches: the source surface around each point where the observer-hole axis crosses
it, meshed on a log-polar grid about the axis.

Why. A source point on the observer-hole axis, behind the hole (both orders) or in front of it
(order 2, whose ray sweeps 2 pi), has a whole circle as its image: the Einstein ring, at an angle
theta_E from the hole's direction. Near such a point the mapping turns the azimuth psi about the
axis into position angle along the ring, so a piece of surface of size h at a distance delta from
the axis covers an azimuth of about h / delta on screen. No uniform subdivision (subdivision.py)
makes pieces that small as delta -> 0; the ring culling (culling.py) drops what is left, and the
ring's edge ends up as a polygon whose straight sides sag short of the true circle.

The patch. Around each crossing point P, the surface is sampled on a grid of circles about the axis,
delta_i = radius * q^(i - K) (i = 0 .. K, innermost first) and psi_j = 2 pi j / N, plus one ring of
*limit vertices* at delta = 0: the source point P itself, whose image in the direction psi_j is the
point of the Einstein ring (theta_E at position angle psi_j for order 1, psi_j + pi for order
2). Grid points are found on the surface by casting lines parallel to the axis through the triangles
connected to the crossing (nearest to P along the axis when several are hit). The patch's images are
quads (two triangles each) between consecutive circles, so:

* the ring's edge is drawn by chords between points of the circle theta_E, N per turn, chosen so
  they sag by at most budget.Budget.patch_edge_px pixels; the points are moved off the circle by
  B.CHORD_OUTSET of that sag, so that the chords cross it (limit_images);
* the ratio q keeps the tangential error of the linear interpolation inside a piece (a point of the
  surface is drawn at the azimuth of its corners' mean weighted by their distances from the axis, not
  its own) within B.PATCH_AIM of ``max_error_px`` (grid_shape);
* the innermost circle is where the image is within B.BAND_WIDE_FACTOR (as far as the sheet has no
  edge near the axis, else B.PATCH_BAND_FACTOR) times the coverage tolerance of theta_E;
* the band between it and the ring is refined in azimuth (band_shape, _refine_band): its faces touch
  the ring, where all their corners are the one point P, so they draw their points with the azimuth of
  their other corners: each spans at most 2 B.PATCH_AIM max_error_px / ring_px (about pi ring_px /
  (B.PATCH_AIM max_error_px) limit vertices per turn, three faces each), joined to the innermost
  circle by a fan.

The source triangles entirely inside the patch's drawn cells (connected to the crossed one, and
wound like it in projection, i.e. on the same sheet of the surface) are *replaced*: the pipeline does
not subdivide them. Triangles that reach beyond are kept as they are, so the patch overlaps them on
the same surface (no cracks; the two draw the same points).
Where the surface does not cover a whole circle (a mesh boundary, a hole, or the fold where a closed
surface turns parallel to the axis), the innermost circle must still be complete (the ring's edge
needs every azimuth), else there is no patch. If the fold comes close to the axis (B.CLIP_REACH), the
cells are cut along the source triangles under them (B.CLIP_TO_TRIANGLES): each face lies on one
source triangle, the patch reaches the sheet's edge, and it replaces every triangle of its sheet
inside its outer circle, the crossed ones included. Otherwise (the plain grid) the patch goes on with
the cells (between two circles and two azimuths) whose four corners are on the surface, and replaces
only the triangles that lie inside such cells; where the surface turns towards the axis' direction
(next to such a fold), circles are added between those where it is steep (B.STEEP_RATIO), so that
faces stay close to the surface.

Each vertex of a patch lies on one source triangle, whose corner values (UVs, normals) it takes
(the pipeline falls back to one triangle's values per face across a seam; a clipped patch's faces
carry their own triangle's values exactly). On a closed surface seen
from outside, faces turned away along the rays are not drawn, and a patch whose sheet is turned away
(the far side of an object behind the hole) gets no grid at all: neither when all of it is, nor when
the part that is not lies well away from the axis (B.HIDDEN_CORE), where kept pieces draw it.

Units: positions in Blender units (BU); delta in BU; angles in radians; pixel quantities in pixels
of ``pixel_angle`` radians. Axis coordinates: (x, y, z) relative to the hole, z along the axis
towards the camera (observer_view.axis_coordinates).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from . import budget as B
from . import mapping, silhouette
from .observer_view import (any_perpendicular, axis_coordinates, axis_crossing, axis_distance, hole_angle,
                            longest_side, magnification, max_ring_span, nearest_to_axis, place_images, projected_area,
                            row_norm, within_axis_distance)
from .ragged import group_offsets

@dataclass
class Crossing:
    """A point where the axis crosses the source surface: ``tri`` the crossed source triangle, ``point``
    (3,) BU, ``along`` (BU) its coordinate along the axis (negative: behind the hole)."""

    tri: int
    point: np.ndarray
    along: float


@dataclass
class Patch:
    """The log-polar patch about one crossing (see the module docstring).

    source_position (V, 3) BU: the surface point of each vertex (the first ``n_azimuths`` are the
    limit vertices, all at the crossing point); tris (F, 3), wound like the crossed source triangle;
    face_src (F,) the source triangle of each face (the one under its outer corner); bary (F, 3, 3) the
    barycentric coordinates of each face corner in that triangle (projected along the axis;
    extrapolated for corners in a neighbouring triangle); vertex_tri (V,) and vertex_bary (V, 3): the
    source triangle each vertex lies on and its barycentric coordinates there (the crossed triangle
    for the limit vertices); complete: every cell out to its outer circle is drawn (False where the
    surface folds over or ends inside it, so that kept triangles draw part of the ring near the axis);
    replaced: source triangles the patch stands
    in for; radius (BU): its outer circle's distance from the axis; orders: the image orders whose
    Einstein ring it is; images: {order: mapping.Images} of its vertices; facing: {order: (F,) bool}
    the faces to draw (all, unless back faces of a closed surface are left out, see
    :func:`build_patches`). limit_psi (V,): the azimuth (radians) of each limit vertex, NaN for the
    others; band: how many vertices the refined band (:func:`_refine_band`) appended at the end (its
    limit vertices between the grid's azimuths and its inner points); ring_chords: the number of
    equal chords per turn whose sag the limit vertices' outset is taken from (limit_images).
    """

    crossing: Crossing
    n_azimuths: int
    source_position: np.ndarray
    tris: np.ndarray
    face_src: np.ndarray
    bary: np.ndarray
    replaced: np.ndarray
    radius: float
    orders: tuple
    vertex_tri: np.ndarray = field(default=None, repr=False)
    vertex_bary: np.ndarray = field(default=None, repr=False)
    complete: bool = True
    images: dict = field(default_factory=dict, repr=False)
    facing: dict = field(default_factory=dict, repr=False)
    cell: np.ndarray = field(default=None, repr=False)
    ring_radii: np.ndarray = field(default=None, repr=False)
    limit_psi: np.ndarray = field(default=None, repr=False)
    band: int = 0
    ring_chords: int = 0

    @property
    def limit(self) -> np.ndarray:
        """(V,) bool: the limit vertices (at the crossing point; their images are points of the ring)."""
        if self.limit_psi is None:
            out = np.zeros(len(self.source_position), bool)
            out[:self.n_azimuths] = True
            return out
        return ~np.isnan(self.limit_psi)

    @property
    def grid_vertices(self) -> slice:
        """The vertices of the circles (grid points, clipped cells' other vertices): after the
        ``n_azimuths`` limit vertices, before the ``band`` vertices of the refined band."""
        return slice(self.n_azimuths, len(self.source_position) - self.band)


def find_crossings(points, tris, camera, hole, candidates=None, axis_xyz=None) -> list[Crossing]:
    """The points where the observer-hole axis crosses the triangles ``tris`` of ``points`` (BU), one
    per point (a crossing through a shared edge or vertex is found once). ``candidates``: indices or a
    mask of the triangles to test (e.g. observer_view.near_axis); default all. Ordered along the axis.
    ``axis_xyz``: observer_view.axis_coordinates of ``points``, when the caller has them."""
    tris = np.asarray(tris, dtype=np.int64)
    idx = np.arange(len(tris)) if candidates is None else np.arange(len(tris))[candidates]
    if idx.size == 0:
        return []
    x, y, z = axis_coordinates(points, camera, hole) if axis_xyz is None else axis_xyz
    t = tris[idx]
    _, crossed, along = axis_crossing(x, y, z, t)
    sel = np.flatnonzero(crossed & np.isfinite(along))
    if sel.size == 0:
        return []
    # one crossing per point: crossings closer along the axis than a millionth of their triangle's size
    # are the same point seen from the triangles around a shared edge or vertex
    size = longest_side(x, y, t)
    sel = sel[np.argsort(along[sel], kind="stable")]
    e1 = np.asarray(camera, np.float64) - hole
    e1 = e1 / np.linalg.norm(e1)
    out: list[Crossing] = []
    for k in sel:  # a handful per mesh
        if out and abs(along[k] - out[-1].along) <= 1e-6 * size[k]:
            continue
        out.append(Crossing(tri=int(idx[k]), point=np.asarray(hole, np.float64) + along[k] * e1, along=float(along[k])))
    return out


def ring_orders(crossing: Crossing, orders) -> tuple:
    """The orders among ``orders`` whose image of the crossing point is an Einstein ring: both behind
    the hole, order 2 only in front of it."""
    return tuple(o for o in orders if crossing.along < 0 or o == 2)


def limit_images(crossing: Crossing, psi, mp: mapping.Mapper, order, look=None,
                 chords: int | None = None) -> mapping.Images:
    """Images of order ``order`` of the crossing point approached from azimuth ``psi`` (K,) radians
    about the axis (measured in the frame of observer_view.axis_coordinates): the points of its Einstein
    ring, at the LUT's angle xi for phi = pi (behind the hole) or 0 (in front), at position angle psi
    (order 1) or psi + pi (order 2). ``look``: the LUT's (xi, dt) there (lutgen.Lookup of one point),
    when the caller has it (see :func:`_limit_look`).

    ``chords``: None (the exact points), or the number of equal azimuth steps per turn in which the
    ring is drawn as a polygon: then the points are moved off the ring by B.CHORD_OUTSET times the sag
    of the chords between them (chord_sag), away from the side the chords bow to, so that the chords
    cross the ring instead of all lying on one side of it (see B.CHORD_OUTSET)."""
    scene = mp.scene
    plane = _limit_plane(crossing, psi, scene)
    if look is None:  # one point: the same (r, phi) at every azimuth
        look = _limit_look(crossing, mp, (order,))[order]
    xi, dt = np.broadcast_to(look.xi, plane.r.shape), np.broadcast_to(look.dt, plane.r.shape)
    if chords:
        xi = xi - B.CHORD_OUTSET * chord_sag(xi, 2.0 * np.pi / chords)
    direction, distance, position, valid = place_images(xi, dt, plane.e2, scene, order)
    position[~valid] = np.nan
    return mapping.Images(position=position, direction=direction, distance=distance, valid=valid, plane=plane,
                          xi=xi.copy(), dt=dt.copy(), ux=None, uy=None)


def chord_sag(xi, step):
    """The angle (radians, signed) by which the great-circle chord between two directions at the
    same angle ``xi`` from scene.e1 and ``step`` radians apart in azimuth about it passes, at its
    middle, further from e1 than they do (negative: closer; straight edges on screen are such
    chords). Exact on the view sphere for any xi in [0, pi]."""
    return np.arctan2(np.sin(xi) * np.cos(0.5 * step), np.cos(xi)) - xi


def _limit_look(crossing: Crossing, mp: mapping.Mapper, orders) -> dict:
    """{order: lutgen.Lookup} of (xi, dt) of one point for the rays that reach the crossing point along
    the axis (the same at every azimuth)."""
    plane = _limit_plane(crossing, np.zeros(1), mp.scene)
    return mp.rays(plane.r, plane.phi, orders, ("xi", "dt"))


def _limit_plane(crossing: Crossing, psi, scene: mapping.Scene) -> mapping.PlaneCoordinates:
    """The plane coordinates of the crossing point approached from azimuths ``psi`` (K,) radians about
    the axis: its radius, phi = pi (behind the hole) or 0 (in front), and the planes through the axis
    at those azimuths (frame of observer_view.axis_coordinates)."""
    psi = np.asarray(psi, np.float64)
    u = any_perpendicular(scene.e1)
    v = np.cross(scene.e1, u)
    e2 = np.cos(psi)[:, None] * u + np.sin(psi)[:, None] * v
    r = np.full(psi.shape, np.linalg.norm(crossing.point - scene.hole) / scene.r_s)
    phi = np.full(psi.shape, np.pi if crossing.along < 0 else 0.0)
    return mapping.PlaneCoordinates(r=r, phi=phi, e2=e2, on_axis=np.ones(psi.shape, bool))


def _connected(seed, cand, of_tri, n_edges) -> np.ndarray:
    """Mask over ``cand`` (indices of triangles) of those connected to triangle ``seed`` through shared
    edges without leaving ``cand``."""
    cand = np.asarray(cand, np.int64)
    if cand.size == 0:
        return np.zeros(0, bool)
    # a graph with a node per candidate and per edge, joined where the triangle has that edge
    e = of_tri[cand].ravel()
    t = np.repeat(np.arange(cand.size), 3)
    graph = coo_matrix((np.ones(e.size, np.int8), (t, cand.size + e)), shape=(cand.size + n_edges,) * 2)
    _, label = connected_components(graph, directed=False)
    at = np.flatnonzero(cand == seed)
    if at.size == 0:
        return np.zeros(cand.size, bool)
    return label[:cand.size] == label[at[0]]


def _locate(radii, n_az, cand_tris, x, y, z, z_target):
    """For the grid points (radii[i] cos psi_j, radii[i] sin psi_j), psi_j = 2 pi j / n_az, in axis
    coordinates, the triangle among ``cand_tris`` (C, 3) whose projection along the axis contains each
    (nearest to ``z_target`` along the axis when several do): (index into cand_tris or -1, barycentrics
    (M, 3)), M = len(radii) * n_az, points ordered circle by circle. Only the pairs of a point and a
    triangle whose ranges of distance from the axis and of azimuth contain it are tested."""
    n_c = len(radii)
    m = n_c * n_az
    best = np.full(m, -1, np.int64)
    bary = np.full((m, 3), np.nan)
    if len(cand_tris) == 0 or m == 0:
        return best, bary
    d_lo, d_hi, a_lo, a_hi = _polar_box(cand_tris, x, y)
    step = 2.0 * np.pi / n_az
    j_lo = np.floor(a_lo / step).astype(np.int64)
    j_hi = np.ceil(a_hi / step).astype(np.int64)
    full = d_lo == 0.0  # the axis crosses the projection: every azimuth
    j_lo = np.where(full, 0, j_lo)
    j_hi = np.where(full, n_az - 1, j_hi)
    count = np.minimum(j_hi - j_lo + 1, n_az)
    # (circle, triangle) pairs whose distance ranges meet, then their azimuth indices
    ci, ti = np.nonzero((radii[:, None] >= d_lo[None, :] * (1 - 1e-12)) & (radii[:, None] <= d_hi[None, :] * (1 + 1e-12)))
    if ci.size == 0:
        return best, bary
    reps = count[ti]
    pc = np.repeat(ci, reps)
    pt = np.repeat(ti, reps)
    offs = group_offsets(reps)
    pj = (np.repeat(j_lo[ti], reps) + offs) % n_az
    psi = 2.0 * np.pi * pj / n_az  # as _grid_patch's azimuths, to the bit
    qx = radii[pc] * np.cos(psi)
    qy = radii[pc] * np.sin(psi)
    tr = cand_tris[pt]
    with np.errstate(invalid="ignore", divide="ignore"):
        lam = _projected_bary(qx, qy, tr, x, y)  # not finite for edge-on projections
    with np.errstate(invalid="ignore"):  # (NaN compares False; an infinite one makes the sum NaN or inf)
        inside = ((lam[:, 0] >= -1e-12) & (lam[:, 1] >= -1e-12) & (lam[:, 2] >= -1e-12)
                  & np.isfinite(lam[:, 0] + lam[:, 1] + lam[:, 2]))
    if not inside.any():
        return best, bary
    sel = np.flatnonzero(inside)
    point = pc[sel] * n_az + pj[sel]
    ls, zs = lam[sel], z[tr[sel]]
    gap = np.abs(ls[:, 0] * zs[:, 0] + ls[:, 1] * zs[:, 1] + ls[:, 2] * zs[:, 2] - z_target)
    first = _first_smallest(point, gap)
    pts = point[first]
    k = sel[first]
    best[pts] = pt[k]
    bary[pts] = lam[k]
    return best, bary


def _locate_points(qx, qy, cand_tris, x, y, z, z_target):
    """As :func:`_locate` for any points (qx, qy) (M,) in axis coordinates (BU): (index into
    ``cand_tris`` of the triangle whose projection along the axis contains each, nearest to
    ``z_target`` along the axis when several do, or -1; barycentrics (M, 3)). Only the triangles
    within the points' largest distance from the axis are tested, each against the points inside
    its box (the points sorted along x)."""
    m = len(qx)
    best = np.full(m, -1, np.int64)
    bary = np.full((m, 3), np.nan)
    if m == 0 or len(cand_tris) == 0:
        return best, bary
    reach = float(np.hypot(qx, qy).max())
    near = np.flatnonzero(within_axis_distance(x, y, cand_tris, reach))
    if near.size == 0:
        return best, bary
    tr = cand_tris[near]
    px, py = x[tr], y[tr]
    eps = 1e-12 * max(reach, 1e-300)
    order = np.argsort(qx, kind="stable")
    a = np.searchsorted(qx[order], px.min(axis=1) - eps, side="left")
    count = np.maximum(np.searchsorted(qx[order], px.max(axis=1) + eps, side="right") - a, 0)
    pt = np.repeat(np.arange(near.size), count)
    pp = order[np.repeat(a, count) + group_offsets(count)]
    ok = (qy[pp] >= py.min(axis=1)[pt] - eps) & (qy[pp] <= py.max(axis=1)[pt] + eps)
    pt, pp = pt[ok], pp[ok]
    with np.errstate(invalid="ignore", divide="ignore"):
        lam = _projected_bary(qx[pp], qy[pp], tr[pt], x, y)
    with np.errstate(invalid="ignore"):
        inside = (lam >= -1e-12).all(axis=1) & np.isfinite(lam.sum(axis=1))
    sel = np.flatnonzero(inside)
    if sel.size == 0:
        return best, bary
    gap = np.abs(np.einsum("mk,mk->m", lam[sel], z[tr[pt[sel]]]) - z_target)
    first = _first_smallest(pp[sel], gap)
    best[pp[sel][first]] = near[pt[sel][first]]
    bary[pp[sel][first]] = lam[sel][first]
    return best, bary


def _first_smallest(key, value) -> np.ndarray:
    """Indices of one element per distinct ``key`` (ints): the one of smallest ``value`` (the first in
    order among equals; NaN only where all of its key's values are NaN), in increasing key order. As
    np.lexsort((value, key)) and the first of each key, with one stable integer sort instead."""
    order = np.argsort(key, kind="stable")
    k, v = key[order], value[order]
    start = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    if start.size == len(k):  # every key once
        return order
    smallest = np.repeat(np.fmin.reduceat(v, start), np.diff(np.r_[start, len(k)]))
    candidate = (v == smallest) | np.isnan(smallest)
    at = np.flatnonzero(candidate)
    group = np.cumsum(np.r_[True, k[1:] != k[:-1]]) - 1
    keep = np.r_[True, group[at][1:] != group[at][:-1]]
    return order[at[keep]]


def _polar_box(tris, x, y):
    """(d_lo, d_hi, a_lo, a_hi), each (T,): the range of distance from the axis (BU; d_lo = 0 when the
    axis passes through the projection) and of azimuth (radians, a_lo <= a_hi, unwrapped from the
    first corner's) of the triangles ``tris`` (T, 3) projected along it; x, y from
    observer_view.axis_coordinates. When the axis passes through, every azimuth is in the box."""
    px, py = x[tris], y[tris]  # (T, 3)
    ang = np.arctan2(py, px)
    rel = np.angle(np.exp(1j * (ang - ang[:, :1])))  # corners' azimuths relative to corner 0, (-pi, pi]
    return (axis_distance(x, y, tris), np.hypot(px, py).max(axis=1),
            ang[:, 0] + rel.min(axis=1), ang[:, 0] + rel.max(axis=1))


def _inside_cells(cell, ring_radii, cand_tris, x, y) -> np.ndarray:
    """(C,) bool: the triangles ``cand_tris`` (C, 3) whose projection lies inside drawn cells only.
    ``cell`` (R - 1, N): drawn cells between rings of radii ``ring_radii`` (R,) (BU, increasing, the
    first 0) and azimuths 2 pi j / N. Tested on the triangle's box in distance from the axis and
    azimuth (its corners' range; all azimuths when the axis passes through it), which contains it."""
    n_rows = cell.shape[0]
    r0, r1, j0, count, d_hi = _cell_box(cell.shape, ring_radii, cand_tris, x, y)
    r1 = np.clip(r1, r0 + 1, n_rows)
    return (d_hi <= ring_radii[-1]) & (_cells_in(cell, r0, r1, j0, count) == (r1 - r0) * count)


def _cell_box(shape, ring_radii, tris, x, y):
    """The box of cells (rows between rings of ``ring_radii``, azimuths 2 pi j / N; ``shape`` (R - 1, N))
    that holds each of the triangles ``tris`` (T, 3) projected along the axis (:func:`_polar_box`):
    (r0, r1, j0, count, d_hi): rows r0 to r1 (exclusive, unclipped above), ``count`` azimuths from j0
    (all of them when the axis passes through the triangle), and its largest distance (BU)."""
    n_rows, n_az = shape
    d_lo, d_hi, a_lo, a_hi = _polar_box(tris, x, y)
    j0, count = _azimuth_span(d_lo, a_lo, a_hi, n_az)
    r0 = np.clip(np.searchsorted(ring_radii, d_lo, side="right") - 1, 0, n_rows)
    r1 = np.searchsorted(ring_radii, d_hi, side="left")
    return r0, r1, j0, count, d_hi


def _azimuth_span(d_lo, a_lo, a_hi, n_az):
    """(j0, count): the first of the azimuths 2 pi j / n_az (j0 in 0 .. n_az - 1) and how many of them
    hold each of :func:`_polar_box`'s boxes (all of them, from 0, when the axis passes through it)."""
    step = 2.0 * np.pi / n_az
    j0 = np.floor(a_lo / step).astype(np.int64)
    j1 = np.ceil(a_hi / step).astype(np.int64)  # exclusive
    full = d_lo == 0.0
    return np.where(full, 0, j0 % n_az), np.where(full, n_az, np.minimum(j1 - j0, n_az))


def _cells_in(mask, r0, r1, j0, count) -> np.ndarray:
    """How many cells of ``mask`` (R - 1, N) bool each box (rows r0 .. r1 - 1, ``count`` azimuths from
    j0, wrapping around) holds: by a 2-D prefix sum, the azimuths doubled for the wrap-around."""
    n_rows, n_az = mask.shape
    total = np.zeros((n_rows + 1, 2 * n_az + 1), np.int64)
    total[1:, 1:] = np.cumsum(np.cumsum(np.concatenate([mask, mask], axis=1), axis=0), axis=1)
    c1 = j0 + count
    return total[r1, c1] - total[r0, c1] - total[r1, j0] + total[r0, j0]


def open_distance(patch: Patch, tris, x, y) -> np.ndarray:
    """(T,) for the triangles ``tris`` (T, 3) (axis coordinates x, y of their vertices, BU): the
    smallest distance from the axis (BU) at which the patch may leave part of each undrawn, within
    the triangle's box of cells: the inner circle of the first row holding a cell it does not draw
    there, else its outer circle; inf for a triangle that does not reach inside the outer circle (or
    a patch without a grid)."""
    out = np.full(len(tris), np.inf)
    if patch.cell is None or len(tris) == 0:
        return out
    reach = np.flatnonzero(within_axis_distance(x, y, tris, patch.radius))  # the others stay inf
    if reach.size == 0:
        return out
    n_rows, n_az = patch.cell.shape
    r0, r1, j0, count, _ = _cell_box(patch.cell.shape, patch.ring_radii, np.asarray(tris)[reach], x, y)
    inside = r0 < n_rows  # reaches inside the outer circle
    gap = ~patch.cell
    if gap.any():
        per_row = np.zeros((n_rows, 2 * n_az + 1), np.int64)  # gap cells per row, by prefix sums
        per_row[:, 1:] = np.cumsum(np.concatenate([gap, gap], axis=1), axis=1)
        c1 = j0 + count
        rows = np.arange(n_rows)
        hit = (per_row[:, c1] - per_row[:, j0] > 0) & (rows[:, None] >= r0) & (rows[:, None] < r1)  # (R, T)
        first = np.where(hit.any(axis=0), hit.argmax(axis=0), n_rows)
    else:
        first = np.full(reach.size, n_rows)
    out[reach[inside]] = patch.ring_radii[first[inside]]  # first <= n_rows: the outer circle
    return out


def _projected_bary(qx, qy, tris, x, y) -> np.ndarray:
    """(M, 3) barycentrics of points (qx, qy) (M,) in the projections of triangles ``tris`` (M, 3)
    along the axis (extrapolated outside them)."""
    ax, bx, cx = x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]]
    ay, by, cy = y[tris[:, 0]], y[tris[:, 1]], y[tris[:, 2]]
    det = (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)
    l1 = ((qx - ax) * (cy - ay) - (cx - ax) * (qy - ay)) / det
    l2 = ((bx - ax) * (qy - ay) - (qx - ax) * (by - ay)) / det
    return np.column_stack([1.0 - l1 - l2, l1, l2])


def grid_shape(ring_radius_px, max_error_px) -> tuple[int, float]:
    """(N, q): the number of azimuths per turn and the ratio of consecutive circles of a patch whose
    Einstein ring is ``ring_radius_px`` pixels from the hole's direction (see the module docstring)."""
    s = float(max_ring_span(ring_radius_px, B.PATCH_EDGE_FACTOR * (B.COVERAGE_FACTOR * max_error_px)))
    n = int(np.clip(np.ceil(2.0 * np.pi / max(s, 1e-12)), 16, B.MAX_AZIMUTHS))
    s = 2.0 * np.pi / n
    # a piece spanning circles delta and q delta and one azimuth step draws its interior up to
    # R s (sqrt q - 1) / (sqrt q + 1) pixels along the ring from where it belongs (on its diagonal,
    # whose points the interpolation weights by their distance from the axis); q at most 3
    b = min(_Q3, B.PATCH_AIM * max_error_px / (ring_radius_px * s))
    return n, ((1.0 + b) / (1.0 - b)) ** 2


_Q3 = (np.sqrt(3.0) - 1.0) / (np.sqrt(3.0) + 1.0)  # grid_shape's bound at q = 3
_RING_PROBES = 64  # azimuths at which a moving camera's ring is probed (its scale varies smoothly about it)


def patching(frame) -> bool:
    """True when the frame builds axis patches: pieces are measured on screen and may be subdivided."""
    return frame.budget.active and frame.settings.max_tess_level > 1


def crossings_of(frame, source) -> list[Crossing]:
    """:func:`find_crossings` of a prepared source (frame.Source), found once and kept on it."""
    if source.crossings is None:
        scene = frame.scene
        source.crossings = find_crossings(source.positions, source.tris, scene.camera, scene.hole,
                                          source.near_axis, source.axis_xyz)
    return source.crossings


def build_patches(frame, source, sight) -> list[Patch]:
    """The axis patches of a prepared source (frame.Source) in ``frame``, with their images: one per
    point where the observer-hole axis crosses its surface (at most MAX_PATCHES), for the frame's
    orders whose image of that point is an Einstein ring. See the module docstring.

    ``sight`` (visibility.Sight): on a closed surface seen from outside, points whose connecting ray
    starts into the surface (n . d < 0, with n the geometric normal of the face's source triangle and
    d the direction the ray leaves it in) are hidden by the surface itself. Patch faces whose grid
    corners all face away are then left out (``Patch.facing``): on the side of a closed object turned
    away from the hole the whole patch is hidden and its images are not computed (``images`` lacks
    that order), but it still replaces its triangles (see HIDDEN_CORE for a sheet hidden but next to
    its rim)."""
    if not patching(frame) or source.empty:
        return []
    crossings = crossings_of(frame, source)
    if not crossings:
        return []
    points, tris = source.positions, source.tris
    x, y, z = source.axis_xyz
    closed = sight.closed()
    if len(crossings) > B.MAX_PATCHES:
        size = [np.ptp(x[tris[c.tri]]) + np.ptp(y[tris[c.tri]]) for c in crossings]
        keep = np.sort(np.argsort(size, kind="stable")[::-1][:B.MAX_PATCHES])
        crossings = [crossings[k] for k in keep]
    out = []
    pixel_angle, tolerance = frame.budget.pixel_angle, frame.budget.tolerance_px
    for cr in crossings:
        ords = ring_orders(cr, frame.orders)
        if ords:
            patch = _build_one(cr, ords, points, tris, source.edges.of_tri, len(source.edges.verts), x, y, z,
                               frame.map, pixel_angle, tolerance, closed, sight.leaving)
            if patch is not None:
                out.append(patch)
    return out


def _build_one(cr: Crossing, orders, points, tris, of_tri, n_edges, x, y, z, mp, pixel_angle, max_error_px,
               closed=False, leaving=None):
    scene = mp.scene
    t0 = tris[cr.tri]
    radius = B.PATCH_RADIUS_FACTOR * float(np.hypot(x[t0], y[t0]).max())
    if not np.isfinite(radius) or radius <= 0:
        return None
    cand, first_radius = None, radius
    if closed:
        cand = _sheet(cr, radius, tris, of_tri, n_edges, x, y)
        cone, away = _hidden_sheet(cr, cand, orders, points, tris, mp, leaving)
        if cone and (away.all() or np.all(axis_distance(x, y, tris[cand[~away]]) >= B.HIDDEN_CORE * radius)):
            # no grid: it would draw nothing, or only next to its rim, where kept pieces draw
            corner_d = np.hypot(x[tris[cand]], y[tris[cand]]).max(axis=1)
            return Patch(crossing=cr, n_azimuths=0, source_position=np.zeros((0, 3)),
                         tris=np.zeros((0, 3), np.int64), face_src=np.zeros(0, np.int64), bary=np.zeros((0, 3, 3)),
                         replaced=cand[(corner_d <= radius) & away], radius=radius, orders=tuple(orders),
                         vertex_tri=np.zeros(0, np.int64), vertex_bary=np.zeros((0, 3)),
                         facing={o: np.zeros(0, bool) for o in orders})
    # the ring's radius on screen, per order: a moving camera (scene.view_beta) sees it at the static
    # radius times the aberration's local scale, which varies about the ring: its largest at
    # _RING_PROBES azimuths sizes the grid, or the ring's length per radian of azimuth where that is
    # larger (the static sin(theta_E) times the local scale): how far along the ring an azimuth
    # error draws a point
    look = _limit_look(cr, mp, orders)
    beta = scene.view_beta
    psi_ring = np.zeros(1) if beta is None else 2.0 * np.pi * np.arange(_RING_PROBES) / _RING_PROBES
    ring = {o: limit_images(cr, psi_ring, mp, o, look[o]) for o in orders}
    if not all(bool(im.valid.all()) for im in ring.values()):
        return None
    seen = {o: hole_angle(im.direction, scene.camera, scene.hole, beta) for o, im in ring.items()}
    theta_e = {o: float(seen[o][0] / magnification(ring[o].direction[:1], beta)[0]) for o in orders}  # static
    rate = {o: magnification(im.direction, beta) * np.sin(np.asarray(look[o].xi, np.float64).ravel()[0])
            for o, im in ring.items()}
    ring_px = max(max(float(seen[o].max()), float(rate[o].max())) for o in orders) / pixel_angle
    n_az, q = grid_shape(ring_px, max_error_px)
    # the innermost circle: probe the image at B.PROBE_AZIMUTHS azimuths in the crossed triangle's plane
    k = np.arange(B.MAX_CIRCLES + 1)
    probe_delta = radius * q ** (-k.astype(np.float64))
    psi_p = 2.0 * np.pi * np.arange(B.PROBE_AZIMUTHS) / B.PROBE_AZIMUTHS
    qx = (probe_delta[:, None] * np.cos(psi_p)[None, :]).ravel()
    qy = (probe_delta[:, None] * np.sin(psi_p)[None, :]).ravel()
    lam = _projected_bary(qx, qy, np.repeat(t0[None], len(qx), axis=0), x, y)
    probe = lam @ points[t0]
    band = B.PATCH_BAND_FACTOR * (B.COVERAGE_FACTOR * max_error_px) * pixel_angle
    gap = np.zeros(len(qx))
    for o, img in mp.images(probe, orders).items():  # how far from the ring each probe is seen
        gap = np.maximum(gap, np.abs(hole_angle(img.direction, scene.camera, scene.hole, beta)
                                     - theta_e[o] * magnification(img.direction, beta)))  # NaN stays
    gap = gap.reshape(len(k), B.PROBE_AZIMUTHS).max(axis=1)
    # no image (outside the LUT, horizon) next to the axis: no patch; farther out: a smaller patch
    bad = np.flatnonzero(~np.isfinite(gap))
    if bad.size and bad[-1] == len(k) - 1:
        return None
    start = int(bad[-1]) + 1 if bad.size else 0
    radius = float(probe_delta[start])

    def circles(width, reach=np.inf):  # the circles out to the first within ``width`` (rad) of the
        # ring and ``reach`` (BU) of the axis
        first = np.flatnonzero((gap[start:] <= width) & (probe_delta[start:] <= reach))
        n_circles = int(first[0]) + 1 if first.size else len(k) - start  # circles radius q^-k, k = first .. 0
        n_circles = max(1, min(n_circles, B.MAX_GRID // n_az))
        return radius * q ** (-np.arange(n_circles - 1, -1, -1, dtype=np.float64))

    # the surface under the grid
    if cand is None or radius != first_radius:
        cand = _sheet(cr, radius, tris, of_tri, n_edges, x, y)
    # the wide band first (its faces are as exact as the grid's, and fewer circles are drawn) inside the
    # sheet's nearest edge to the axis (a mesh boundary, hole or fold: the grid's circles find those);
    # where its innermost circle does not go all round the sheet, the narrow one
    wide = circles(B.BAND_WIDE_FACTOR * band / B.PATCH_BAND_FACTOR, _open_reach(cand, tris, of_tri, n_edges, x, y))
    narrow = circles(band)
    for radii in ((wide, narrow) if len(wide) < len(narrow) else (narrow,)):
        patch = _grid_patch(radii, n_az, cand, projected_area(x, y, t0[None])[0] < 0, points, tris, x, y, z,
                            mp, orders, closed, cr, look, (ring_px, max_error_px))
        if patch is not None:
            return patch
    return None


def _open_reach(cand, tris, of_tri, n_edges, x, y) -> float:
    """The distance (BU) from the axis to the nearest edge of the sheet ``cand`` (triangles) that only
    one of its triangles has: the mesh's boundary, a hole, or a fold (the triangles beyond it wound
    the other way in projection are not on the sheet); inf where none. (The sheet's rim, where it
    meets triangles farther than its radius, lies beyond the radius.)"""
    if len(cand) == 0:
        return 0.0
    sides = of_tri[cand]
    once = np.bincount(sides.ravel(), minlength=n_edges)[sides] == 1
    if not once.any():
        return np.inf
    return float(nearest_to_axis(x, y, tris[cand])[2][once].min())


def _sheet(cr, radius, tris, of_tri, n_edges, x, y) -> np.ndarray:
    """Indices of the triangles connected to the crossed one whose projection along the axis meets the
    disc of ``radius`` (BU) and is wound the same way (a closed surface folds over where it turns
    parallel to the axis: the sheet beyond the fold projects with the opposite winding and belongs to
    another crossing)."""
    near = np.flatnonzero(within_axis_distance(x, y, tris, radius))
    near = near[projected_area(x, y, tris[near]) * projected_area(x, y, tris[cr.tri][None])[0] > 0]
    return near[_connected(cr.tri, near, of_tri, n_edges)]


def _hidden_sheet(cr, cand, orders, points, tris, mp, leaving=None):
    """How much of the sheet ``cand`` around the crossing ``cr`` of a closed surface seen from outside
    is turned away from the camera along the rays of every order: (cone, away). ``cone``: at the
    crossing point, for the rays arriving from B.HIDDEN_AZIMUTHS directions around the axis (the
    point's rays form a cone: its Einstein ring); ``away`` (C,) bool: the triangles turned away at
    every corner (silhouette.turned_away, margin 0). With both, the whole patch draws nothing (the
    far side of an object behind the hole)."""
    corners, pts, local = silhouette.compact(points, tris[cand])
    if leaving is None:
        looked = mp.leaving(pts, orders)
        leaving = lambda _, o: looked[o][0]  # noqa: E731
    t0 = tris[cr.tri]
    normal = silhouette.normals(points, t0[None])[0]
    normal = normal / np.linalg.norm(normal)
    scene = mp.scene
    plane = _limit_plane(cr, 2.0 * np.pi * np.arange(B.HIDDEN_AZIMUTHS) / B.HIDDEN_AZIMUTHS, scene)
    looks = mp.rays(plane.r[:1], plane.phi[:1], orders, ("ux", "uy"))  # alike at every azimuth
    away = np.ones(len(cand), bool)
    for o in orders:
        ux, uy = (np.broadcast_to(v, plane.r.shape) for v in (looks[o].ux, looks[o].uy))
        d = mapping.leaving_direction(plane, scene, ux, uy)
        with np.errstate(invalid="ignore"):
            if not (d @ normal < 0).all():
                return False, np.zeros(len(cand), bool)
        away &= silhouette.turned_away(pts, local, leaving(corners, o), 0.0)
    return True, away


def _refined_radii(radii, n_az, hit, lam, points, cand_tris) -> tuple[np.ndarray, np.ndarray]:
    """(radii, new): the circles ``radii`` (BU, increasing) with those B.STEEP_RATIO adds, and a mask of
    the added ones. ``hit``, ``lam``: :func:`_locate`'s result for ``radii`` on ``cand_tris``."""
    n_c = len(radii)
    if n_c < 2 or not B.STEEP_RATIO:
        return radii, np.zeros(n_c, bool)
    ok = hit >= 0
    pos = np.full((len(hit), 3), np.nan)
    pos[ok] = np.einsum("mk,mkx->mx", lam[ok], points[cand_tris[hit[ok]]])
    pos = pos.reshape(n_c, n_az, 3)
    with np.errstate(invalid="ignore"):
        ratio = row_norm((pos[1:] - pos[:-1]).reshape(-1, 3)).reshape(n_c - 1, n_az) / np.diff(radii)[:, None]
    worst = np.max(np.where(np.isfinite(ratio), ratio, 0.0), axis=1)
    parts = np.clip(np.ceil(worst / B.STEEP_RATIO), 1, B.STEEP_SPLIT_MAX).astype(np.int64)
    parts = np.where(np.cumsum(parts - 1) <= B.MAX_GRID // n_az - n_c, parts, 1)
    if parts.max() <= 1:
        return radii, np.zeros(n_c, bool)
    out, new = [radii[:1]], [np.zeros(1, bool)]
    for i, k in enumerate(parts):  # a few dozen intervals
        out.append(np.append(radii[i] * (radii[i + 1] / radii[i]) ** (np.arange(1, k) / k), radii[i + 1]))
        new.append(np.arange(1, k + 1) < k)
    return np.concatenate(out), np.concatenate(new)


_MAXV = 8  # vertices of a clipped cell: a quad cut by a triangle's three edges has at most 7


def _wedge_cells(tris, x, y, n_az, ring_radii):
    """(triangle, row, column) of the cells (between rings ``ring_radii``, BU, the first 0, and azimuths
    2 pi j / n_az) that each triangle ``tris`` (T, 3) projected along the axis may meet: per azimuth
    wedge of its range, the rows between its least and largest distance from the axis inside the
    wedge (from the wedge's two rays, its corners inside it and the feet of its sides' perpendiculars
    from the axis; all of them when it contains the axis)."""
    n_rows = len(ring_radii) - 1
    step = 2.0 * np.pi / n_az
    d_lo, _, a_lo, a_hi = _polar_box(tris, x, y)
    full = d_lo == 0.0
    j0, count = _azimuth_span(d_lo, a_lo, a_hi, n_az)
    t = np.repeat(np.arange(len(tris)), count)
    col = (np.repeat(j0, count) + group_offsets(count)) % n_az
    px, py = x[tris[t]], y[tris[t]]  # (W, 3) corners
    ex, ey = np.roll(px, -1, axis=1) - px, np.roll(py, -1, axis=1) - py  # side k: corner k -> k + 1
    sign = np.sign(ex[:, :1] * ey[:, 1:2] - ey[:, :1] * ex[:, 1:2])  # the triangle's winding
    lo = np.full(t.size, np.inf)
    hi = np.zeros(t.size)
    with np.errstate(invalid="ignore", divide="ignore"):
        for psi in (col * step, (col + 1) * step):  # the wedge's rays: t (cos psi, sin psi), t >= 0
            ux, uy = np.cos(psi)[:, None], np.sin(psi)[:, None]
            a = sign * (ex * uy - ey * ux)  # inside side k: a t >= b
            b = sign * (ex * py - ey * px)
            t_lo = np.max(np.where(a > 0, b / a, np.where((a == 0) & (b > 0), np.inf, -np.inf)), axis=1)
            t_hi = np.min(np.where(a < 0, b / a, np.inf), axis=1)
            t_lo = np.maximum(t_lo, 0.0)
            meet = t_lo <= t_hi
            lo = np.where(meet, np.minimum(lo, t_lo), lo)
            hi = np.where(meet, np.maximum(hi, t_hi), hi)
        base = col[:, None] * step
        in_wedge = lambda qx, qy: np.mod(np.arctan2(qy, qx) - base, 2.0 * np.pi) <= step  # noqa: E731
        d = np.hypot(px, py)
        inner = in_wedge(px, py)
        lo = np.minimum(lo, np.min(np.where(inner, d, np.inf), axis=1))
        hi = np.maximum(hi, np.max(np.where(inner, d, 0.0), axis=1))
        u = np.clip(-(px * ex + py * ey) / (ex * ex + ey * ey), 0.0, 1.0)  # feet of the perpendiculars
        fx, fy = px + u * ex, py + u * ey
        lo = np.minimum(lo, np.min(np.where(in_wedge(fx, fy), np.hypot(fx, fy), np.inf), axis=1))
    lo = np.where(full[t], 0.0, lo)
    keep = np.isfinite(lo) & (lo <= hi)
    t, col, lo, hi = t[keep], col[keep], lo[keep] * (1 - 1e-9), hi[keep] * (1 + 1e-9)
    r0 = np.clip(np.searchsorted(ring_radii, lo, side="right") - 1, 0, n_rows)
    r1 = np.minimum(np.searchsorted(ring_radii, hi, side="left"), n_rows)
    n = np.maximum(r1 - r0, 0)
    pt = np.repeat(t, n)
    prow = np.repeat(r0, n) + group_offsets(n)
    return pt, prow, np.repeat(col, n)


def _pack(emit, *columns):
    """The polygons' slots where ``emit`` (P, S) is True, moved to the front of each row in order: each
    of ``columns`` (P, S) as (P, _MAXV) (zero beyond the row's count), then the counts (P,)."""
    n_p = emit.shape[0]
    row, col = np.nonzero(emit)  # row by row, in order
    at = row * _MAXV + (np.cumsum(emit, axis=1) - 1)[row, col]
    out = []
    for c in columns:
        packed = np.zeros((n_p, _MAXV), c.dtype)
        packed.ravel()[at] = c[row, col]
        out.append(packed)
    return (*out, emit.sum(axis=1))


def _apex_to_limits(keys, vx, vy, cnt, apex, col, n_az):
    """Polygons of first-row cells (columns ``col``) with each run of vertices at the axis (``apex``)
    replaced by the cell's limit vertices d = col + 1 and a = col, in that order."""
    n_p, n_s = keys.shape
    slot = np.arange(n_s)[None, :]
    valid = slot < cnt[:, None]
    prev = np.take_along_axis(apex, (slot - 1) % np.maximum(cnt, 1)[:, None], axis=1)
    start = apex & ~prev & valid
    lone = apex.all(axis=1, where=valid)  # the whole polygon at the axis: nothing to draw
    start[:, 0] |= lone & apex[:, 0]
    d_key = np.broadcast_to(((col + 1) % n_az)[:, None], keys.shape)
    a_key = np.broadcast_to(col[:, None], keys.shape)
    out_k = np.stack([np.where(start, d_key, 0), np.where(start, a_key, keys)], axis=2).reshape(n_p, -1)
    out_x = np.stack([np.zeros(keys.shape), np.where(start, 0.0, vx)], axis=2).reshape(n_p, -1)
    out_y = np.stack([np.zeros(keys.shape), np.where(start, 0.0, vy)], axis=2).reshape(n_p, -1)
    emit = np.stack([start, start | (valid & ~apex)], axis=2).reshape(n_p, -1)
    keys, vx, vy, cnt = _pack(emit, out_k, out_x, out_y)
    return keys, vx, vy, np.minimum(cnt, n_s)


def _full_cells(hit, n_circles, n_az):
    """(on, cell): which grid points have the sheet under them ((R, N), vertex rings: 0 the limit
    vertices, r >= 1 circle r - 1), and which cells (between rings r and r + 1, azimuths j and j + 1)
    have it under their four corners ((R - 1, N)); ``hit``: :func:`_locate`'s triangle per point."""
    on = np.concatenate([np.ones((1, n_az), bool), (hit >= 0).reshape(n_circles, n_az)])
    cell = on[:-1] & on[1:]
    cell &= np.roll(cell, -1, axis=1)
    return on, cell


def _plain_reach(hit, radii, n_az) -> float:
    """How far out the plain grid's cells (four corners on the sheet) go all round, as a fraction of
    the last circle that has any (1: it draws its whole sheet inside that circle)."""
    _, cell = _full_cells(hit, len(radii), n_az)
    last = np.flatnonzero(cell.any(axis=1))
    if last.size == 0:
        return 0.0
    gap = np.flatnonzero(~cell[:last[-1] + 1].all(axis=1))
    return 1.0 if gap.size == 0 else float(np.concatenate([[0.0], radii])[gap[0]] / radii[last[-1]])


def _clipped_grid(radii, n_az, hit, lam, cand, points, tris, x, y, crossing):
    """The faces of a patch whose cells are cut along the source triangles ``cand`` under them (see
    B.CLIP_TO_TRIANGLES): cells whose four corners lie on one triangle stay quads (two faces); the others
    are clipped by the sides of each triangle that may meet them (:func:`_wedge_cells`; Sutherland-
    Hodgman, vectorised over (cell, triangle) pairs, only by the sides that cut the cell) and fanned.
    ``hit``, ``lam``: :func:`_locate`'s result for the circles ``radii`` (BU).

    Vertices are numbered by what they are, so that neighbouring cells and triangles share them: grid
    points (limit vertices first), source vertices, and crossings of a grid side with a source edge
    (found from the side's and the edge's end points, the same numbers in every cell). Returns None
    when the innermost circle is not complete, else a dict with faces (F, 3) (counter-clockwise in
    the axis projection), face_src (F,) (indices into tris), bary (F, 3, 3), vertex_tri (V,),
    vertex_bary (V, 3), position (V, 3) BU, ring_radii, replaced (indices into tris); False when there
    would be more than B.MAX_CLIP_PAIRS pairs to clip."""
    n_lim = n_az
    n_c = len(radii)
    on = (hit >= 0).reshape(n_c, n_az)
    if not on[0].all():  # the ring's edge needs every azimuth
        return None
    n_rings = int(np.flatnonzero(on.any(axis=1))[-1]) + 2  # the limit ring and the circles in use
    n_rows = n_rings - 1
    n_grid = n_rings * n_az
    m = n_grid - n_lim
    psi = 2.0 * np.pi * np.arange(n_az) / n_az
    gx = np.concatenate([np.zeros(n_lim), (radii[:n_rows, None] * np.cos(psi)[None, :]).ravel()])
    gy = np.concatenate([np.zeros(n_lim), (radii[:n_rows, None] * np.sin(psi)[None, :]).ravel()])
    ring_radii = np.concatenate([[0.0], radii[:n_rows]])
    ct = tris[cand]
    t_cross = np.flatnonzero(cand == crossing.tri)
    if t_cross.size == 0:  # the crossed triangle is not on the sheet (cannot happen for _sheet's)
        return None
    t_cross = int(t_cross[0])
    lim_bary = _projected_bary(np.zeros(1), np.zeros(1), tris[crossing.tri][None], x, y)[0]
    g_tri = np.concatenate([np.full(n_lim, t_cross), hit[:m]])  # index into cand, -1: off the sheet
    # the cells' corners a = (r, j), b = (r + 1, j), c = (r + 1, j + 1), d = (r, j + 1)
    r = np.arange(n_rows)[:, None]
    j = np.arange(n_az)[None, :]
    jn = (j + 1) % n_az
    ca, cb, cc, cd = r * n_az + j, (r + 1) * n_az + j, (r + 1) * n_az + jn, r * n_az + jn
    ta = g_tri[ca]
    whole = (ta >= 0) & (ta == g_tri[cb]) & (ta == g_tri[cc]) & (ta == g_tri[cd])
    wi = np.flatnonzero(whole.ravel())
    w_faces = np.concatenate([np.stack([ca.ravel()[wi], cb.ravel()[wi], cc.ravel()[wi]], -1),
                              np.stack([ca.ravel()[wi], cc.ravel()[wi], cd.ravel()[wi]], -1)])
    w_tri = np.tile(ta.ravel()[wi], 2)
    # (cell, triangle) pairs: the cells not whole that each triangle may meet
    pt, prow, pcol = _wedge_cells(ct, x, y, n_az, ring_radii)
    sel = ~whole[prow, pcol]
    pt, prow, pcol = pt[sel], prow[sel], pcol[sel]
    if len(pt) > B.MAX_CLIP_PAIRS:  # a mesh much finer than the cells: the plain grid instead
        return False
    # the source edges of the sheet's triangles (local numbering), per triangle side k (corner k -> k + 1)
    side = np.stack([ct[:, [0, 1]], ct[:, [1, 2]], ct[:, [2, 0]]], axis=1).reshape(-1, 2)
    e_verts, tri_edge = np.unique(np.sort(side, axis=1), axis=0, return_inverse=True)
    tri_edge = tri_edge.reshape(-1, 3)
    n_e = len(e_verts)
    key_v = n_grid  # source vertex v: key_v + v
    key_x = n_grid + len(points)  # grid side s crossing source edge e: key_x + s * n_e + e
    line_e = 2 * n_grid  # lines: grid sides 0 .. 2 n_grid - 1 (radial, then arcs), source edges from here
    # polygons: the cells' quads, each vertex with the line of the side that starts there
    n_p = len(pt)
    keys = np.zeros((n_p, _MAXV), np.int64)
    lines = np.zeros((n_p, _MAXV), np.int64)
    jq = (pcol + 1) % n_az
    keys[:, :4] = np.stack([prow * n_az + pcol, (prow + 1) * n_az + pcol, (prow + 1) * n_az + jq, prow * n_az + jq], -1)
    lines[:, :4] = np.stack([prow * n_az + pcol, n_grid + (prow + 1) * n_az + pcol, prow * n_az + jq,
                             n_grid + prow * n_az + pcol], -1)
    vx, vy = gx[keys], gy[keys]
    cnt = np.full(n_p, 4)
    sign = np.sign(projected_area(x, y, ct[:1]))[0]
    scale = max(float(ring_radii[-1]), 1e-300)
    slot = np.arange(_MAXV)[None, :]

    # the sides of the triangles as half-planes: inside where a x + b y >= c (with a tolerance)
    sx, sy = x[ct], y[ct]  # (C, 3) corners
    ex, ey = np.roll(sx, -1, axis=1) - sx, np.roll(sy, -1, axis=1) - sy  # side k: corner k -> k + 1
    ha, hb = -sign * ey, sign * ex
    hc = ha * sx + hb * sy - 1e-12 * scale * np.hypot(ex, ey)

    def inside_of(kk, px_, py_, pt):  # (P, K) bool: points on the inner side of side kk of each pair's triangle
        return ha[pt, kk][:, None] * px_ + hb[pt, kk][:, None] * py_ >= hc[pt, kk][:, None]

    # cells outside a side of the triangle meet nothing of it; cells inside all three are not cut
    ins = [inside_of(kk, vx[:, :4], vy[:, :4], pt) for kk in range(3)]
    apart = ~ins[0].any(axis=1) | ~ins[1].any(axis=1) | ~ins[2].any(axis=1)
    within = ins[0].all(axis=1) & ins[1].all(axis=1) & ins[2].all(axis=1)
    done = np.flatnonzero(within & ~apart)
    d_tri, d_keys = pt[done], keys[done, :4]
    cut = np.flatnonzero(~within & ~apart)
    pt, keys, lines, vx, vy, cnt = pt[cut], keys[cut], lines[cut], vx[cut], vy[cut], cnt[cut]
    pr, pc = prow[cut], pcol[cut]
    need = [~ins[kk].all(axis=1)[cut] for kk in range(3)]  # the sides that cut each cell

    def clip(kk, pt, keys, lines, vx, vy, cnt):  # the polygons clipped by side kk of their triangles
        n_p = len(pt)
        inside = inside_of(kk, vx, vy, pt)
        nxt = (slot + 1) % cnt[:, None]
        inside_n = np.take_along_axis(inside, nxt, axis=1)
        valid = slot < cnt[:, None]
        emit_x = valid & (inside != inside_n)
        emit_e = valid & inside_n
        # the crossing points' keys, coordinates and lines
        e_here = np.broadcast_to(tri_edge[pt, kk][:, None], keys.shape)
        on_grid = lines < line_e
        xk = np.where(on_grid, key_x + lines * n_e + e_here, 0)
        xx, xy_ = np.zeros(keys.shape), np.zeros(keys.shape)
        gsel = emit_x & on_grid
        if gsel.any():
            ls, es = lines[gsel], e_here[gsel]
            g0 = np.where(ls < n_grid, ls, ls - n_grid)
            g1 = np.where(ls < n_grid, g0 + n_az, (g0 // n_az) * n_az + (g0 % n_az + 1) % n_az)
            ax, ay = gx[g0], gy[g0]
            dx, dy = gx[g1] - ax, gy[g1] - ay
            m0, m1 = e_verts[es, 0], e_verts[es, 1]
            fx, fy = x[m1] - x[m0], y[m1] - y[m0]
            with np.errstate(invalid="ignore", divide="ignore"):
                t = np.clip(((x[m0] - ax) * fy - (y[m0] - ay) * fx) / (dx * fy - dy * fx), 0.0, 1.0)
            t = np.nan_to_num(t, nan=0.0)
            xx[gsel], xy_[gsel] = ax + t * dx, ay + t * dy
            with np.errstate(invalid="ignore", divide="ignore"):  # where along the source edge
                u = ((x[m0] - ax) * dy - (y[m0] - ay) * dx) / (dx * fy - dy * fx)
            # at an end of the source edge: that source vertex; at an end of the side (a grid point on
            # the source edge): that grid point
            v_end = np.where(np.abs(u) <= 1e-9, m0, np.where(np.abs(u - 1) <= 1e-9, m1, -1))
            snap = np.where(t <= 1e-9, g0, np.where(t >= 1 - 1e-9, g1, -1))
            on_v, at_end = (v_end >= 0) & (snap < 0), snap >= 0
            if on_v.any() or at_end.any():
                v, g = np.maximum(v_end, 0), np.maximum(snap, 0)
                xk[gsel] = np.where(at_end, snap, np.where(on_v, key_v + v_end, xk[gsel]))
                xx[gsel] = np.where(at_end, gx[g], np.where(on_v, x[v], xx[gsel]))
                xy_[gsel] = np.where(at_end, gy[g], np.where(on_v, y[v], xy_[gsel]))
        vsel = emit_x & ~on_grid
        if vsel.any():  # two sides of the triangle meet at its corner
            a_e, b_e = e_verts[lines[vsel] - line_e], e_verts[e_here[vsel]]
            v = np.where((a_e[:, 0] == b_e[:, 0]) | (a_e[:, 0] == b_e[:, 1]), a_e[:, 0], a_e[:, 1])
            xk[vsel] = key_v + v
            xx[vsel], xy_[vsel] = x[v], y[v]
        x_line = np.where(inside, line_e + e_here, lines)  # leaving the triangle: along its side
        # emitted in order: per side, its crossing then its end point
        out_k = np.stack([xk, np.take_along_axis(keys, nxt, axis=1)], axis=2).reshape(n_p, -1)
        out_l = np.stack([x_line, np.take_along_axis(lines, nxt, axis=1)], axis=2).reshape(n_p, -1)
        out_x = np.stack([xx, np.take_along_axis(vx, nxt, axis=1)], axis=2).reshape(n_p, -1)
        out_y = np.stack([xy_, np.take_along_axis(vy, nxt, axis=1)], axis=2).reshape(n_p, -1)
        emit = np.stack([emit_x, emit_e], axis=2).reshape(n_p, -1)
        return _pack(emit, out_k, out_l, out_x, out_y)

    for kk in range(3):
        sub = np.flatnonzero(need[kk])
        if sub.size:
            keys[sub], lines[sub], vx[sub], vy[sub], cnt[sub] = clip(kk, pt[sub], keys[sub], lines[sub], vx[sub],
                                                                      vy[sub], cnt[sub])
    keep = cnt >= 3
    if not keep.all():
        pt, keys, vx, vy, cnt, pr, pc = pt[keep], keys[keep], vx[keep], vy[keep], cnt[keep], pr[keep], pc[keep]
    n_p = len(pt)
    if n_p:  # a crossing at a grid point or source vertex already there: once
        valid = slot < cnt[:, None]
        prev = np.take_along_axis(keys, (slot - 1) % np.maximum(cnt, 1)[:, None], axis=1)
        dup = valid & (keys == prev)
        if dup.any():
            keys, vx, vy, cnt = _pack(valid & ~dup, keys, vx, vy)
    # a polygon vertex at the crossing point itself (a source vertex or edge on the axis) stands, in a
    # first-row cell, for the cell's two limit vertices, d then a (walking round the cell), whose
    # images are points of the Einstein ring
    if n_p:
        apex = (np.hypot(vx, vy) <= 1e-12 * scale) & (slot < cnt[:, None]) & (pr == 0)[:, None]
        if apex.any():
            keys, vx, vy, cnt = _apex_to_limits(keys, vx, vy, cnt, apex, pc, n_az)
    # fans of the clipped polygons
    fan = [np.flatnonzero(cnt > i + 1) for i in range(1, _MAXV - 1)]
    pf = np.concatenate(fan)
    ci = np.concatenate([np.full(f.size, i) for i, f in zip(range(1, _MAXV - 1), fan)])
    c_faces = np.stack([keys[pf, 0], keys[pf, ci], keys[pf, ci + 1]], -1)
    c_x = np.stack([vx[pf, 0], vx[pf, ci], vx[pf, ci + 1]], -1)
    c_y = np.stack([vy[pf, 0], vy[pf, ci], vy[pf, ci + 1]], -1)
    c_tri = pt[pf]
    if done.size:  # cells inside one triangle, with a corner on another's side (or a limit vertex)
        c_faces = np.concatenate([c_faces, d_keys[:, [0, 1, 2]], d_keys[:, [0, 2, 3]]])
        c_x = np.concatenate([c_x, gx[d_keys[:, [0, 1, 2]]], gx[d_keys[:, [0, 2, 3]]]])
        c_y = np.concatenate([c_y, gy[d_keys[:, [0, 1, 2]]], gy[d_keys[:, [0, 2, 3]]]])
        c_tri = np.concatenate([c_tri, d_tri, d_tri])
    # barycentrics of every corner in its face's triangle
    g_lam = np.concatenate([np.broadcast_to(lim_bary, (n_lim, 3)), lam[:m]])
    w_bary = g_lam[w_faces]
    c_bary = _projected_bary(c_x.ravel(), c_y.ravel(), np.repeat(ct[c_tri], 3, axis=0), x, y).reshape(-1, 3, 3)
    faces = np.concatenate([w_faces, c_faces])
    face_tri = np.concatenate([w_tri, c_tri])
    bary = np.concatenate([w_bary, c_bary])
    # the vertices: every limit vertex, then the others in use (grid points, source vertices,
    # crossings, in the order of their keys), each from one of its corners
    flat = faces.ravel()
    is_grid = flat < n_grid
    used = np.zeros(n_grid, bool)
    used[:n_lim] = True
    used[flat[is_grid]] = True
    index = np.cumsum(used) - 1
    n_used = int(index[-1]) + 1
    other, other_at = np.unique(flat[~is_grid], return_inverse=True)
    new_flat = np.empty_like(flat)
    new_flat[is_grid] = index[flat[is_grid]]
    new_flat[~is_grid] = n_used + other_at.ravel()
    faces = new_flat.reshape(-1, 3)
    n_v = n_used + len(other)
    fc = np.zeros(n_v, np.int64)
    fc[new_flat] = np.arange(len(new_flat))  # a corner of each vertex (the same one for the same input)
    vertex_tri = cand[face_tri[fc // 3]]
    vertex_bary = bary.reshape(-1, 3)[fc]
    vertex_tri[:n_lim] = crossing.tri
    vertex_bary[:n_lim] = lim_bary
    position = np.einsum("vk,vkx->vx", vertex_bary, points[tris[vertex_tri]])
    position[:n_lim] = crossing.point
    replaced = cand[np.hypot(x[ct], y[ct]).max(axis=1) <= ring_radii[-1]]
    return dict(faces=faces, face_src=cand[face_tri], bary=bary, vertex_tri=vertex_tri, vertex_bary=vertex_bary,
                position=position, ring_radii=ring_radii, replaced=replaced)


def _grid_patch(radii, n_az, cand, flip, points, tris, x, y, z, mp, orders, closed, crossing,
                limit_look=None, ring=None):
    """The patch of ``crossing``: a ring of limit vertices at the crossing point, then the grid of
    circles ``radii`` (BU, increasing) x ``n_az`` azimuths on the surface of the triangles ``cand``
    (one sheet: wound alike in projection; hits nearest the crossing along the axis), with faces wound
    counter-clockwise seen from the camera's side of the axis (clockwise with ``flip``), the band
    next to the ring refined (:func:`_refine_band`) for ``ring`` = (the ring's radius, the tolerance)
    in pixels (None: not refined). None when the innermost circle is not complete."""
    old_hit, old_lam = hit, lam = _locate(radii, n_az, tris[cand], x, y, z, crossing.along)

    def on_sheet(qx, qy):  # (triangle or -1, barycentrics, position) of points under (qx, qy)
        h, l = _locate_points(qx, qy, tris[cand], x, y, z, crossing.along)
        found = h >= 0
        tri = np.where(found, cand[np.maximum(h, 0)], -1)
        pos = np.full((len(qx), 3), np.nan)
        pos[found] = np.einsum("mk,mkx->mx", l[found], points[tris[tri[found]]])
        return tri, l, pos

    def in_triangles(qx, qy, tri):  # barycentrics of (qx, qy) in the projections of triangles tri
        return _projected_bary(qx, qy, tris[tri], x, y)

    if B.CLIP_TO_TRIANGLES and _plain_reach(hit, radii, n_az) < B.CLIP_REACH:
        cut = _clipped_grid(radii, n_az, hit, lam, cand, points, tris, x, y, crossing)
        if cut is None:
            return None
    else:
        cut = False
    if cut is not False:
        ring_radii = cut["ring_radii"]
        px, py, _ = axis_coordinates(cut["position"], mp.scene.camera, mp.scene.hole)
        mesh = dict(faces=cut["faces"], face_src=cut["face_src"], bary=cut["bary"], vertex_tri=cut["vertex_tri"],
                    vertex_bary=cut["vertex_bary"], position=cut["position"], xy=np.stack([px, py], -1))
        ring = None if ring is None else (*ring, on_sheet)  # each face on its sector's triangle
        return _finish(mesh, n_az, flip, crossing, orders, cut["replaced"], ring_radii,
                       np.ones((len(ring_radii) - 1, n_az), bool), ring, points, tris, mp, closed, limit_look)
    radii, new = _refined_radii(radii, n_az, hit, lam, points, tris[cand])
    if new.any():  # the added circles' points; the others' stay
        h, l = _locate(radii[new], n_az, tris[cand], x, y, z, crossing.along)
        at_new = np.repeat(new, n_az)
        hit, lam = np.empty(at_new.size, np.int64), np.empty((at_new.size, 3))
        hit[at_new], lam[at_new] = h, l
        hit[~at_new], lam[~at_new] = old_hit, old_lam
    n_circles = len(radii)
    n_lim = n_az  # the limit vertices
    psi = 2.0 * np.pi * np.arange(n_az) / n_az
    qx = (radii[:, None] * np.cos(psi)[None, :]).ravel()
    qy = (radii[:, None] * np.sin(psi)[None, :]).ravel()
    # vertex rings: 0 the limit vertices, r >= 1 circle r - 1; a cell (r, j) lies between rings r and
    # r + 1 and azimuths j and j + 1, and is drawn when the surface is under its four corners
    on, cell = _full_cells(hit, n_circles, n_az)
    ring_radii = np.concatenate([[0.0], radii])
    if not cell[0].all():  # the innermost circle must go all round: the ring's edge needs every azimuth
        return None
    rows = np.flatnonzero(cell.any(axis=1))
    n_rings = int(rows[-1]) + 2  # rings in use
    cell = cell[:n_rings - 1]
    ring_radii = ring_radii[:n_rings]
    m = n_rings * n_az - n_lim  # grid points in use
    hit, lam, qx, qy = hit[:m], lam[:m], qx[:m], qy[:m]
    # quads of the drawn cells (two faces each), counter-clockwise seen from the camera's side of the axis
    r_i, j_i = np.nonzero(cell)
    a = r_i * n_az + j_i
    b = (r_i + 1) * n_az + j_i
    c = (r_i + 1) * n_az + (j_i + 1) % n_az
    d = r_i * n_az + (j_i + 1) % n_az
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)])
    # only the grid points of drawn cells are vertices (limit vertices first, all used)
    used = np.zeros(n_rings * n_az, bool)
    used[faces.ravel()] = True
    used[:n_lim] = True
    faces = (np.cumsum(used) - 1)[faces]
    grid = np.flatnonzero(used[n_lim:])  # indices into hit / lam / qx / qy
    hit, lam = hit[grid], lam[grid]
    grid_pos = np.einsum("mk,mkx->mx", lam, points[tris[cand[hit]]])
    src_pos = np.concatenate([np.repeat(crossing.point[None], n_az, axis=0), grid_pos])
    vx = np.concatenate([np.zeros(n_az), qx[grid]])
    vy = np.concatenate([np.zeros(n_az), qy[grid]])
    # each face's source triangle: the one under its corner of largest index (on its outer circle;
    # faces are small, so their centroid lies in that triangle or next to it)
    where = hit[np.maximum(np.maximum(faces[:, 0], faces[:, 1]), faces[:, 2]) - n_lim]
    face_src = cand[where]
    replaced = cand[_inside_cells(cell, ring_radii, tris[cand], x, y)]
    lim_bary = _projected_bary(np.zeros(1), np.zeros(1), tris[crossing.tri][None], x, y)
    vertex_tri = np.concatenate([np.full(n_az, crossing.tri), cand[hit]]).astype(np.int64)
    vertex_bary = np.concatenate([np.repeat(lim_bary, n_az, axis=0), lam])
    # the corners' barycentrics in their face's source triangle: the vertex's own where that is the
    # triangle under it (the same numbers), computed for the others
    bary = vertex_bary[faces]  # (F, 3, 3)
    other = vertex_tri[faces] != face_src[:, None]
    if other.any():
        f_o, c_o = np.nonzero(other)
        v_o = faces[f_o, c_o]
        bary[f_o, c_o] = _projected_bary(vx[v_o], vy[v_o], tris[face_src[f_o]], x, y)
    mesh = dict(faces=faces.astype(np.int64), face_src=face_src, bary=bary, vertex_tri=vertex_tri,
                vertex_bary=vertex_bary, position=src_pos, xy=np.stack([vx, vy], -1))
    ring = None if ring is None else (*ring, on_sheet, in_triangles)  # faces as the grid's: see _refine_band
    return _finish(mesh, n_az, flip, crossing, orders, replaced, ring_radii, cell, ring, points, tris, mp, closed,
                   limit_look)


def _finish(mesh, n_az, flip, crossing, orders, replaced, ring_radii, cell, ring, points, tris, mp, closed,
            limit_look):
    """The Patch of a grid's ``mesh`` (dict: faces counter-clockwise in the axis projection, the first
    ``n_az`` vertices the limit vertices at azimuths 2 pi j / n_az; face_src, bary, vertex_tri,
    vertex_bary, position, xy: each vertex's axis coordinates x, y (BU)), its band refined for
    ``ring`` (see :func:`_grid_patch`), wound like the source (``flip``), with its images."""
    n_v = len(mesh["position"])
    limit_psi = np.full(n_v, np.nan)
    limit_psi[:n_az] = 2.0 * np.pi * np.arange(n_az) / n_az
    band, chords = 0, n_az
    refined = _refine_band(mesh, n_az, *ring) if ring is not None else None
    if refined is not None:
        mesh, band_psi, chords = refined
        band = len(mesh["position"]) - n_v
        limit_psi = np.concatenate([limit_psi, band_psi])
    faces, bary = mesh["faces"], mesh["bary"]
    if flip:  # to the source's winding
        faces, bary = faces[:, ::-1], bary[:, ::-1]
    patch = Patch(crossing=crossing, n_azimuths=n_az, source_position=mesh["position"],
                  tris=np.ascontiguousarray(faces), face_src=mesh["face_src"], bary=np.ascontiguousarray(bary),
                  replaced=replaced, radius=float(ring_radii[-1]), orders=tuple(orders),
                  vertex_tri=mesh["vertex_tri"], vertex_bary=mesh["vertex_bary"], complete=bool(cell.all()),
                  cell=cell, ring_radii=ring_radii, limit_psi=limit_psi, band=band, ring_chords=chords)
    return _shade(patch, points, tris, mp, orders, closed, limit_look)


def band_shape(ring_px, max_error_px, n_az) -> tuple[float, float, float] | None:
    """How the band between the Einstein ring and a patch's innermost circle is drawn (see
    :func:`_refine_band`), for a ring ``ring_px`` pixels from the hole's direction, the tolerance
    ``max_error_px`` (pixels) and ``n_az`` azimuths per circle: (step, t, q) or None when the plain
    band is within the tolerance already (its pieces span 2 pi / n_az of azimuth, drawn up to that
    times ring_px pixels along the ring). ``step`` (radians): the largest azimuth between two limit
    vertices (a piece touching the ring draws its points at most half of it off, along the ring);
    ``t``: the inner polygon is the outer one scaled by t towards the axis; ``q``: the largest ratio of
    distances from the axis of the corners of a piece between the two, which keeps the outer pieces
    within the tolerance too (a piece whose corners span the azimuth S at distances within a ratio q
    draws its points up to ring_px S (sqrt q - 1) / (sqrt q + 1) pixels along the ring from where they
    belong: the interpolation weights its corners' azimuths by their distance from the axis)."""
    s = 2.0 * np.pi / n_az
    aim = B.PATCH_AIM * max_error_px
    if not ring_px * s > aim:
        return None
    step = max(2.0 * aim / ring_px, 2.0 * np.pi / B.MAX_BAND_AZIMUTHS)
    b = aim / (ring_px * s)
    q = ((1.0 + b) / (1.0 - b)) ** 2
    # the inner polygon's points lie on the chords of the circle t delta: as near as t delta cos(s / 2)
    t = min(B.BAND_INNER_MAX, 1.0 / (q * np.cos(0.5 * s)))
    return step, t, q


def _refine_band(mesh, n_az, ring_px, max_error_px, on_sheet=None, in_triangles=None):
    """The band of a patch next to the Einstein ring redrawn so that every point of it lies within
    ``max_error_px`` of its image, for a ring ``ring_px`` pixels from the hole's direction (the
    largest about it): (mesh, limit azimuths of the appended vertices (NaN for the others), chords
    per turn of the ring's outset), or None where the plain band is within the tolerance
    (:func:`band_shape`). ``mesh``: see :func:`_finish` (faces counter-clockwise in projection).

    Why. A face with a limit vertex L (the crossing point P, drawn on the ring at its azimuth) and
    grid points X, Y draws its points near L with the azimuth of X and Y, whatever their position
    along the ring: a face whose corners span the azimuth S draws points up to ring_px S along the
    ring from where they belong, so every face touching the ring must span little azimuth. Faces with
    two limit vertices are one segment P X on the surface: all their points have X's azimuth.

    How. Each face (L, X, Y) with one limit vertex is a sector P X Y of the surface about the axis
    (faces with two or three limit vertices are segments or points of it, and are dropped). Its
    azimuth range, psi_X to psi_Y, is cut into equal steps of at most ``step`` (band_shape); it
    gets limit vertices at the steps (shared at psi_X and psi_Y with the neighbouring sectors: the
    grid's own limit vertices where psi_X is a grid azimuth), and an inner chain: t X, points on the
    segment t X - t Y at the steps' middle azimuths, t Y (t X = P + t (X - P), shared). Faces: (L_k,
    I_k+1, L_k+1) and (L_k, I_k, I_k+1) between the ring and the chain (their points within half a
    step of their azimuth), and a fan from X and Y to the chain (its points within the tolerance by
    the ratio q of distances, band_shape). Every new vertex is a combination of P, X and Y, so it
    lies on the face's source triangle (its barycentrics the same combination), and the edges X Y are
    left as they are: the band joins the grid's other faces as before. Its vertices off the axis are
    then put on the surface under them as the grid's are (``on_sheet``: (x, y) -> (triangle or -1,
    barycentrics, position), see :func:`_grid_patch`; where it finds none they stay on the face).
    With ``in_triangles`` ((x, y, triangles) -> barycentrics), each new face then takes, as the plain
    grid's faces do, the triangle under its corner farthest from the axis (its corners' barycentrics
    there, extrapolated); without, it keeps its sector's (a clipped grid's faces lie on it).
    About 3 ring_px pi / max_error_px faces per patch."""
    shape = band_shape(ring_px, max_error_px, n_az)
    if shape is None:
        return None
    step, t, _ = shape
    faces, bary, pos, xy = mesh["faces"], mesh["bary"], mesh["position"], mesh["xy"]
    n_v = len(pos)
    lim = faces < n_az
    n_l = lim.sum(axis=1)
    sec = np.flatnonzero(n_l == 1)
    if sec.size == 0:
        return None
    keep = np.flatnonzero(n_l == 0)
    # each sector's corners as (L, X, Y), counter-clockwise: psi_X to psi_Y is its range
    turn = (np.argmax(lim[sec], axis=1)[:, None] + np.arange(3)[None, :]) % 3
    f = np.take_along_axis(faces[sec], turn, axis=1)
    fb = np.take_along_axis(bary[sec], turn[:, :, None], axis=1)  # (S, 3, 3) corner barycentrics
    src = mesh["face_src"][sec]
    L, X, Y = f[:, 0], f[:, 1], f[:, 2]
    ax, ay, bx, by = xy[X, 0], xy[X, 1], xy[Y, 0], xy[Y, 1]
    psi_x = np.arctan2(ay, ax)
    span = np.maximum(np.arctan2(ax * by - ay * bx, ax * bx + ay * by), 0.0)  # psi_Y - psi_X in [0, pi]
    n_int = np.maximum(np.ceil(span / step * (1.0 - 1e-12)), 1).astype(np.int64)  # steps per sector
    n_s = len(sec)
    p_pos = pos[L]  # the crossing point (every limit vertex's position)
    # boundary vertices: each X / Y once, its limit vertex (the grid's where psi is a grid azimuth) and t X
    ends = np.concatenate([X, Y])
    ub, first = np.unique(ends, return_index=True)
    ub_psi = np.arctan2(xy[ub, 1], xy[ub, 0])
    j = np.rint(ub_psi * n_az / (2.0 * np.pi)).astype(np.int64)
    on_grid = np.abs(np.angle(np.exp(1j * (ub_psi - 2.0 * np.pi * j / n_az)))) <= 1e-9
    new_b = np.flatnonzero(~on_grid)
    b_lim = np.where(on_grid, j % n_az, 0)
    b_lim[new_b] = n_v + np.arange(new_b.size)
    base_t = n_v + new_b.size  # the t X points
    base_i = base_t + ub.size  # the limit vertices inside the sectors
    n_in = n_int - 1
    base_c = base_i + int(n_in.sum())  # the inner chains' middle points
    at = np.searchsorted(ub, ends)
    lim_x, lim_y = b_lim[at[:n_s]], b_lim[at[n_s:]]
    t_x, t_y = base_t + at[:n_s], base_t + at[n_s:]
    # the boundary points' data from a sector that has them (corner 1 for X, 2 for Y)
    fs, corner = first % n_s, np.where(first < n_s, 1, 2)
    pb = pos[ub]
    bb = fb[fs, corner]
    t_pos = (1.0 - t) * p_pos[fs] + t * pb
    t_bary = (1.0 - t) * fb[fs, 0] + t * bb
    # inside each sector: limit vertices at the steps, inner points at the steps' middles
    si = np.repeat(np.arange(n_s), n_in)
    ki = group_offsets(n_in) + 1.0
    in_psi = psi_x[si] + span[si] * ki / n_int[si]
    sc = np.repeat(np.arange(n_s), n_int)
    kc = group_offsets(n_int) + 0.5
    c_psi = psi_x[sc] + span[sc] * kc / n_int[sc]
    dx, dy = np.cos(c_psi), np.sin(c_psi)
    with np.errstate(invalid="ignore", divide="ignore"):  # where the ray at c_psi meets X + u (Y - X)
        u = (dx * ay[sc] - dy * ax[sc]) / (dx * (ay[sc] - by[sc]) - dy * (ax[sc] - bx[sc]))
    u = np.clip(np.nan_to_num(u, nan=0.5), 0.0, 1.0)[:, None]
    c_pos = (1.0 - t) * p_pos[sc] + t * ((1.0 - u) * pos[X[sc]] + u * pos[Y[sc]])
    c_bary = (1.0 - t) * fb[sc, 0] + t * ((1.0 - u) * fb[sc, 1] + u * fb[sc, 2])
    # the chains, flat: limit chain k = 0 .. n_int (L_0 at psi_X), inner chain k = 0 .. n_int + 1
    lc_len, ic_len = n_int + 1, n_int + 2
    lc_start, ic_start = np.cumsum(lc_len) - lc_len, np.cumsum(ic_len) - ic_len
    ls, lk = np.repeat(np.arange(n_s), lc_len), group_offsets(lc_len)
    lc = np.where(lk == 0, lim_x[ls], np.where(lk == n_int[ls], lim_y[ls], 0))
    inner_at = lk > 0
    inner_at &= lk < n_int[ls]
    lc[inner_at] = base_i + np.arange(int(n_in.sum()))
    cs, ck = np.repeat(np.arange(n_s), ic_len), group_offsets(ic_len)
    ic = np.where(ck == 0, t_x[cs], np.where(ck == n_int[cs] + 1, t_y[cs], 0))
    mid_at = (ck > 0) & (ck <= n_int[cs])
    ic[mid_at] = base_c + np.arange(int(n_int.sum()))
    ic_bary = np.empty((ic.size, 3))
    ic_bary[ck == 0] = (1.0 - t) * fb[:, 0] + t * fb[:, 1]
    ic_bary[ck == n_int[cs] + 1] = (1.0 - t) * fb[:, 0] + t * fb[:, 2]
    ic_bary[mid_at] = c_bary
    # faces: between the ring and the chain, then the fan from X and Y to the chain
    s1, k1 = np.repeat(np.arange(n_s), n_int), group_offsets(n_int)
    ring_faces = np.stack([lc[lc_start[s1] + k1], ic[ic_start[s1] + k1 + 1], lc[lc_start[s1] + k1 + 1]], -1)
    ring_bary = np.stack([fb[s1, 0], ic_bary[ic_start[s1] + k1 + 1], fb[s1, 0]], 1)
    s2, k2 = np.repeat(np.arange(n_s), n_int + 1), group_offsets(n_int + 1)
    chain_faces = np.stack([lc[lc_start[s2] + k2], ic[ic_start[s2] + k2], ic[ic_start[s2] + k2 + 1]], -1)
    chain_bary = np.stack([fb[s2, 0], ic_bary[ic_start[s2] + k2], ic_bary[ic_start[s2] + k2 + 1]], 1)
    half = (n_int + 1) // 2  # the inner point nearest the sector's middle azimuth
    to_y = k2 >= half[s2]
    apex = np.where(to_y, Y[s2], X[s2])
    apex_b = np.where(to_y[:, None], fb[s2, 2], fb[s2, 1])
    fan_faces = np.stack([ic[ic_start[s2] + k2], apex, ic[ic_start[s2] + k2 + 1]], -1)
    fan_bary = np.stack([ic_bary[ic_start[s2] + k2], apex_b, ic_bary[ic_start[s2] + k2 + 1]], 1)
    s3 = np.arange(n_s)
    mid_faces = np.stack([ic[ic_start + half], X, Y], -1)
    mid_bary = np.stack([ic_bary[ic_start + half], fb[:, 1], fb[:, 2]], 1)
    new_faces = np.concatenate([ring_faces, chain_faces, fan_faces, mid_faces])
    new_src = np.concatenate([src[s1], src[s2], src[s2], src[s3]])
    out = dict(
        faces=np.concatenate([faces[keep], new_faces]),
        face_src=np.concatenate([mesh["face_src"][keep], new_src]),
        bary=np.concatenate([bary[keep], ring_bary, chain_bary, fan_bary, mid_bary]),
        vertex_tri=np.concatenate([mesh["vertex_tri"], np.full(new_b.size, -1), src[fs], np.full(si.size, -1),
                                   src[sc]]),
        vertex_bary=np.concatenate([mesh["vertex_bary"], np.zeros((new_b.size, 3)), t_bary, np.zeros((si.size, 3)),
                                    c_bary]),
        position=np.concatenate([pos, np.repeat(p_pos[:1], new_b.size, axis=0), t_pos,
                                 np.repeat(p_pos[:1], si.size, axis=0), c_pos]),
        xy=np.concatenate([xy, np.zeros((new_b.size, 2)), t * xy[ub], np.zeros((si.size, 2)),
                           t * ((1.0 - u) * xy[X[sc]] + u * xy[Y[sc]])]))
    if on_sheet is not None:  # the points off the axis onto the surface under them
        rows = np.concatenate([base_t + np.arange(ub.size), base_c + np.arange(sc.size)])
        tri, lam, where = on_sheet(out["xy"][rows, 0], out["xy"][rows, 1])
        found = tri >= 0
        rows, tri, lam, where = rows[found], tri[found], lam[found], where[found]
        out["vertex_tri"][rows], out["vertex_bary"][rows], out["position"][rows] = tri, lam, where
    if on_sheet is not None and in_triangles is not None:  # each new face on the triangle under its outer corner
        nf = new_faces
        far = np.take_along_axis(nf, np.argmax(np.hypot(*out["xy"][nf].transpose(2, 0, 1)), axis=1)[:, None],
                                 axis=1)[:, 0]
        tri = out["vertex_tri"][far]
        tri = np.where(tri >= 0, tri, new_src)
        new_src = tri
        cxy = out["xy"][nf]  # (F, 3, 2)
        new_bary = in_triangles(cxy[..., 0].ravel(), cxy[..., 1].ravel(), np.repeat(tri, 3)).reshape(-1, 3, 3)
        out["face_src"][len(keep):] = new_src
        out["bary"][len(keep):] = new_bary
    # the new limit vertices: the crossing point, on the crossed triangle as the grid's are
    lim_rows = np.concatenate([n_v + np.arange(new_b.size), base_i + np.arange(si.size)])
    out["vertex_tri"][lim_rows] = mesh["vertex_tri"][0]
    out["vertex_bary"][lim_rows] = mesh["vertex_bary"][0]
    band_psi = np.full(len(out["position"]) - n_v, np.nan)
    band_psi[:new_b.size] = ub_psi[new_b]
    band_psi[base_i - n_v:base_i - n_v + si.size] = in_psi
    band_psi = np.mod(band_psi, 2.0 * np.pi)
    largest = float(np.max(span / n_int)) if n_s else 2.0 * np.pi / n_az
    chords = int(np.ceil(2.0 * np.pi / max(largest, 1e-300) * (1.0 - 1e-12)))
    return out, band_psi, max(chords, n_az)


def _shade(patch: Patch, points, tris, mp, orders, closed, limit_look=None) -> Patch:
    """Fill in the patch's ``facing`` (which faces to draw per order: on a closed surface those with a
    corner whose ray leaves the face's source triangle's front) and ``images`` (of the vertices of the
    faces drawn in some order; the limit vertices' are the Einstein ring's points)."""
    faces = patch.tris
    lim = patch.limit
    lim_at = np.flatnonzero(lim)
    grid_at = np.flatnonzero(~lim)
    grid_pos = patch.source_position[grid_at]
    psi = (patch.limit_psi[lim_at] if patch.limit_psi is not None
           else 2.0 * np.pi * np.arange(lim_at.size) / max(lim_at.size, 1))
    scene = mp.scene
    plane = mapping.plane_coordinates(grid_pos, scene)
    looked = None
    if closed:
        # which faces face the camera along each order's rays, from the rays' tangents; looked up
        # with the images (one interpolation stencil: most vertices of a patch are drawn)
        looked = mp.images(grid_pos, orders, plane, tangents=True)
        grid_corner = ~lim[faces]  # limit vertices have no direction of their own
        index = np.zeros(len(lim), np.int64)
        index[grid_at] = np.arange(grid_at.size)
        at = index[faces]  # each corner's grid vertex (0 for limit corners, not used)
        # n . d at each corner with the normal of the face's source triangle (the leaving direction
        # d = (a e1 + b e2) / |.|, so n . d has the sign of a n.e1 + b n.e2)
        src_tri, face_at = np.unique(patch.face_src, return_inverse=True)  # a patch lies on few triangles
        f_normal = silhouette.normals(points, tris[src_tri]).take(face_at.ravel(), axis=0)
        n1 = f_normal @ scene.e1
        n2 = np.einsum("fx,fcx->fc", f_normal, plane.e2[at])
        for o in orders:
            a, b = mapping.leaving_in_plane(plane, looked[o].ux, looked[o].uy)
            with np.errstate(invalid="ignore"):
                dots = a[at] * n1[:, None] + b[at] * n2
            away = np.where(grid_corner, dots < 0, True)  # NaN (no ray) counts as facing
            patch.facing[o] = ~(away[:, 0] & away[:, 1] & away[:, 2])
    shown = tuple(o for o in orders if o not in patch.facing or patch.facing[o].any())
    for o in orders:
        patch.facing.setdefault(o, np.ones(len(faces), bool))
    if not shown:
        return patch
    if looked is not None:
        regs = {o: looked[o] for o in shown}
    else:
        regs = mp.images(grid_pos, shown, plane)
    n_v = len(lim)
    for o, reg in regs.items():
        lm = limit_images(patch.crossing, psi, mp, o, limit_look and limit_look[o],
                          chords=patch.ring_chords or lim_at.size)
        parts = {}
        for name in ("position", "direction", "distance", "valid", "xi", "dt"):
            a, b = getattr(lm, name), getattr(reg, name)
            v = np.empty((n_v,) + a.shape[1:], a.dtype)
            v[lim_at], v[grid_at] = a, b
            parts[name] = v
        patch.images[o] = mapping.Images(plane=None, ux=None, uy=None, **parts)
    return patch
