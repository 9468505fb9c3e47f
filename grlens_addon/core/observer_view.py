"""The observer's view: how the camera's static frame turns the table's values into directions in the
world, and the geometry of the view sphere and of the observer-hole axis that every stage measures by.

Units: positions in Blender units (BU); r_s (the Schwarzschild radius) in BU; the table's values in
units of r_s (lengths) and r_s/c (times), c = 1; angles in radians; directions are unit vectors
(dimensionless; chords on the unit view sphere likewise).

Conventions (seed 000). The observer is static at (r_obs, phi = 0), r_obs in units of r_s;
e1 = (camera - hole) / |camera - hole| is its outward radial direction. A point at plane coordinates
(r, phi) lies in the plane through the hole spanned by e1 and e2 (the unit vector of the point's
component perpendicular to e1). The table gives, per order, the angle ``xi`` of the connecting ray at
the observer, measured from e1 in the observer's static orthonormal frame (which grlens identifies
with Blender's Euclidean axes at the camera), and its travel time dt. The observer sees the order-1
image in the direction cos(xi) e1 + sin(xi) e2 and the order-2 image (which passes the hole on the
other side and sweeps 2 pi - phi) in cos(xi) e1 - sin(xi) e2 (:func:`view_directions`); each image
is placed at its light-travel-time distance c dt = dt r_s BU from the camera (:func:`place_images`).
:func:`ray_planes` is the inverse step: a world direction leaving the camera -> (xi, e2).

A moving observer: the table is the static observer's view. An observer at the same event moving
with the velocity beta (units of c) in the local static frame (:func:`static_frame_beta`, from a
coordinate velocity) sees every direction aberrated towards its motion (:func:`aberrate`, exact;
:func:`unaberrate` takes its directions back to the static frame) and every frequency multiplied by
gamma (1 + beta . d) for the static frame's apparent direction d (:func:`doppler_factor`);
:func:`frequency_ratio` is g = 1 / (1 + z) between an emitter and the observer, both possibly moving.

Axis geometry: coordinates (x, y, z) relative to the hole with z along the observer-hole axis
towards the camera and x, y across it (:func:`axis_coordinates`, a fixed perpendicular pair from
:func:`any_perpendicular`); where the axis crosses triangles, their distance from it, the azimuth
about it they cover. View-sphere geometry: chords and circumferences between unit directions, the
angle from the hole's direction, the sag of a piece's sides inside an Einstein ring.
"""
from __future__ import annotations

import numpy as np


def row_norm(v) -> np.ndarray:
    """(N,) Euclidean lengths of the rows of ``v`` (N, 3): as np.linalg.norm(v, axis=1) to the last bit
    or so, several times faster on long arrays (one fused pass instead of a reduction per row)."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def used_vertices(tris, n_vertices) -> np.ndarray:
    """Sorted indices, among ``n_vertices`` points, of those the triangles ``tris`` (T, 3) use (like
    np.unique of their indices, without sorting)."""
    mask = np.zeros(n_vertices, dtype=bool)
    mask[np.asarray(tris).ravel()] = True
    return np.flatnonzero(mask)


def any_perpendicular(e1):
    """A unit vector perpendicular to the unit vector ``e1`` (3,), chosen deterministically (from the z
    axis, or the x axis when e1 is close to z)."""
    a = np.array([0.0, 0.0, 1.0]) if abs(e1[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    v = a - (a @ e1) * e1
    return v / np.linalg.norm(v)

# --------------------------------------------------------------------------------------------------
# The table's values -> directions in the world (and back)
# --------------------------------------------------------------------------------------------------
def view_directions(xi, e2, e1, order) -> np.ndarray:
    """(N, 3) unit world directions in which the static observer sees the images of ``order`` (1 or 2)
    whose connecting rays arrive at the angles ``xi`` (N,; radians from the outward radial direction
    ``e1`` (3,)) in the planes spanned by e1 and ``e2`` (N, 3): cos(xi) e1 + sin(xi) e2 for order 1,
    cos(xi) e1 - sin(xi) e2 for order 2. NaN where xi is NaN."""
    sign = 1.0 if order == 1 else -1.0
    c, s = np.cos(xi), np.sin(xi)
    return c[:, None] * e1 + (sign * s)[:, None] * e2


def place_images(xi, dt, e2, scene, order):
    """The images of ``order`` (1 or 2) of points whose table values are ``xi`` (N,; radians) and ``dt``
    (N,; r_s/c), in the planes of their unit vectors ``e2`` (N, 3), for the observer of ``scene``
    (anything with ``camera`` (3,; BU), ``e1`` (3,) and ``r_s`` (BU), and optionally ``view_beta``
    (3,; units of c), e.g. mapping.Scene): (direction (N, 3) unit, the static observer's
    :func:`view_directions` aberrated by view_beta if the scene has one (:func:`aberrate`), distance (N,)
    c dt in BU, position (N, 3) BU = camera + distance * direction, finite (N,) bool: xi and dt are
    finite). Positions are not masked here (the caller adds its own reasons, e.g. points on the axis)."""
    direction = view_directions(xi, e2, scene.e1, order)
    beta = getattr(scene, "view_beta", None)
    if beta is not None:
        direction = aberrate(direction, beta)
    distance = dt * scene.r_s
    position = scene.camera + distance[:, None] * direction
    finite = np.isfinite(distance) & np.isfinite(xi)
    return direction, distance, position, finite


def exact_view_directions(directions, points, scene, order) -> np.ndarray:
    """(N, 3) the static observer's unit ``directions`` (N, 3) of the images of ``order`` (1 or 2) of
    the source ``points`` (N, 3; BU) of ``scene`` (camera, hole (3,; BU), r_s (BU), e1, r_obs (r_s)),
    with their angle xi from e1 made exact: the table's interpolated xi (about 1e-7 rad off) refined to
    the connecting ray's own (lutgen.solver.refine_xi, to about 1e-12 rad); each direction keeps its
    azimuth about e1 (an Einstein ring's drawn vertices, set off the ring on purpose, go back onto it:
    the point's own image). NaN rows stay NaN."""
    d = np.asarray(directions, dtype=np.float64)
    rel = (np.asarray(points, dtype=np.float64) - scene.hole) / scene.r_s
    e1 = scene.e1
    along = rel @ e1
    r = row_norm(rel)
    phi = np.arctan2(row_norm(rel - along[:, None] * e1), along)
    xi_drawn, _, _, e2 = ray_planes(np.where(np.isfinite(d), d, e1), e1)
    from lutgen.solver import refine_xi
    xi = refine_xi(scene.r_obs, r, phi, order, xi_drawn)
    # ray_planes' e2 is on the drawn direction's side: cos(xi) e1 + sin(xi) e2 for either order
    out = np.cos(xi)[:, None] * e1 + np.sin(xi)[:, None] * e2
    out[~np.isfinite(d).all(axis=1)] = np.nan
    return out


def ray_planes(directions, e1):
    """The inverse of :func:`view_directions` for rays leaving the observer in world ``directions``
    (M, 3; any length, normalised here): (xi (M,) radians from ``e1`` (3,), cos xi, sin xi (M,), e2
    (M, 3) the unit vector of the direction's part perpendicular to e1; :func:`any_perpendicular` of e1
    for rays along the axis). A ray's plane through the hole is spanned by e1 and e2, and it travels
    towards +e2 (order 1's side)."""
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    cos_xi = np.clip(d @ e1, -1.0, 1.0)
    perp = d - cos_xi[:, None] * e1
    sin_xi = np.linalg.norm(perp, axis=1)
    fallback = any_perpendicular(e1)
    with np.errstate(invalid="ignore", divide="ignore"):
        e2 = np.where((sin_xi > 1e-300)[:, None], perp / sin_xi[:, None], fallback)
    return np.arctan2(sin_xi, cos_xi), cos_xi, sin_xi, e2

# --------------------------------------------------------------------------------------------------
# The view sphere
# --------------------------------------------------------------------------------------------------
def chord_length(u, v):
    """(N,) distance between unit vectors ``u`` and ``v`` (N, 3): the chord on the view sphere."""
    w = u - v
    return np.sqrt(np.einsum("ij,ij->i", w, w))


def circumference(d, tris):
    """Perimeter of each triangle on the unit view sphere, as the sum of its corners' chord lengths
    (dimensionless; equal to the sum of the angles in radians to second order for small triangles)."""
    a, b, c = d.take(tris[:, 0], axis=0), d.take(tris[:, 1], axis=0), d.take(tris[:, 2], axis=0)
    return chord_length(a, b) + chord_length(b, c) + chord_length(c, a)


def unit_directions(points, camera, beta=None):
    """Unit vectors from ``camera`` (3,) to ``points`` (N, 3) (BU): the undistorted view (flat space);
    NaN for the camera itself. With ``beta`` (3,; units of c), the view of an observer moving with it
    (:func:`aberrate`), whose images are to be measured against it."""
    v = np.asarray(points, dtype=np.float64) - camera
    with np.errstate(invalid="ignore", divide="ignore"):
        d = v / row_norm(v)[:, None]
    return d if beta is None else aberrate(d, beta)


def hole_angle(directions, camera, hole, beta=None) -> np.ndarray:
    """Angle (radians) of unit ``directions`` (N, 3) from the camera's direction to the hole (BU): the
    radius of the circle about the observer-hole axis through each direction, on which the lensing
    keeps a point's azimuth (Einstein rings are such circles). With ``beta`` (3,; units of c) the
    directions are those of an observer moving with it: aberration keeps circles circles, but not
    centred on the hole's direction, so the radius is measured in the static frame (:func:`unaberrate`)
    and scaled by the aberration's local magnification 1 / (gamma (1 + beta . d_static)) (it is
    conformal): the same circle's radius in the moving observer's angles there, which the error
    budget compares with its pixels."""
    towards_hole = np.asarray(hole, np.float64) - np.asarray(camera, np.float64)
    towards_hole /= np.linalg.norm(towards_hole)
    if beta is None:
        return np.arccos(np.clip(directions @ towards_hole, -1.0, 1.0))
    # from two dot products of the moving observer's directions d' (no (N, 3) temporaries): the static
    # direction is (d' / gamma - (1 - gamma / (gamma + 1) beta . d') beta) / (1 - beta . d') (aberrate
    # with -beta), and the local magnification 1 / (gamma (1 + beta . d_static)) = gamma (1 - beta . d')
    beta = np.asarray(beta, dtype=np.float64).reshape(3)
    gamma = lorentz_gamma(beta)
    k = directions @ beta
    cos_static = ((directions @ towards_hole) / gamma
                  - (1.0 - (gamma / (gamma + 1.0)) * k) * float(beta @ towards_hole)) / (1.0 - k)
    return np.arccos(np.clip(cos_static, -1.0, 1.0)) * (gamma * (1.0 - k))


def magnification(directions, beta) -> np.ndarray:
    """(N,) the aberration's local angular scale at the moving observer's unit ``directions`` (N, 3):
    small angles seen there by the observer moving with ``beta`` (3,; units of c) over the same angles
    seen by the static observer, gamma (1 - beta . d') = 1 / (gamma (1 + beta . d_static)) (aberration
    is conformal); ones for ``beta`` None. The reciprocal of :func:`doppler_factor_seen`."""
    d = np.asarray(directions, dtype=np.float64)
    if beta is None:
        return np.ones(d.shape[:-1])
    beta = np.asarray(beta, dtype=np.float64).reshape(3)
    return lorentz_gamma(beta) * (1.0 - d @ beta)


def doppler_factor_seen(directions, beta) -> np.ndarray:
    """:func:`doppler_factor` (nu_moving / nu_static, (N,)) from the *moving* observer's unit apparent
    ``directions`` (N, 3) (e.g. aberrated image directions) instead of the static ones:
    1 / (gamma (1 - beta . d')), the same value without taking d' back to the static frame (the
    Doppler factors of a direction and of its aberrated one are reciprocal: gamma (1 + beta . d)
    gamma (1 - beta . d') = 1): the reciprocal of :func:`magnification`. Raises ValueError for
    |beta| >= 1."""
    return 1.0 / magnification(directions, np.asarray(beta, dtype=np.float64))


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

# --------------------------------------------------------------------------------------------------
# The observer-hole axis
# --------------------------------------------------------------------------------------------------
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
    triangle), for ``culling.cull(..., axis_candidates=...)``. Non-finite corners make a candidate.
    ``axis_xyz``: :func:`axis_coordinates` of ``source_points``, when the caller has them."""
    tris = np.asarray(tris, dtype=np.int64)
    x, y, z = axis_coordinates(source_points, camera, hole) if axis_xyz is None else axis_xyz
    tol = margin * np.sqrt(x * x + y * y + z * z)  # margin times the distance from the hole (orthonormal axes)
    return _beside_axis(x, y, tris, tol) == 0


# --------------------------------------------------------------------------------------------------
# A moving observer: its velocity in the local static frame, aberration, the shift of frequencies
# --------------------------------------------------------------------------------------------------
def static_frame_beta(position, velocity, hole, r_s, speed_of_light) -> np.ndarray:
    """The velocity beta (N, 3; in units of c, world axes) that the local static observer measures for
    bodies at ``position`` (N, 3 or 3; BU) moving with the coordinate velocity ``velocity`` (same shape;
    BU per unit of coordinate time, e.g. BU per frame when frames measure Schwarzschild coordinate
    time t) about a hole at ``hole`` (3,; BU) of Schwarzschild radius ``r_s`` (BU), with the speed of
    light ``speed_of_light`` (BU per the same unit of time).

    Blender's Euclidean axes are Schwarzschild's: a point is at r = |x - hole| / r_s (units of r_s) in
    the direction n = (x - hole) / |x - hole|. With v_r = v . n and v_t = v - v_r n, proper radial
    length is dr / sqrt(1 - r_s/r) and proper time sqrt(1 - r_s/r) dt, so

        beta = (v_r / (1 - r_s/r) n + v_t / sqrt(1 - r_s/r)) / c.

    Raises ValueError for a position at or inside the horizon (r <= 1 r_s) or a speed of light that is
    not positive. |beta| >= 1 is returned as it is (:func:`lorentz_gamma` refuses it)."""
    c = float(speed_of_light)
    if not (np.isfinite(c) and c > 0):
        raise ValueError(f"the speed of light must be a positive number of Blender units per frame, got {c}")
    x = (np.asarray(position, dtype=np.float64) - np.asarray(hole, dtype=np.float64)) / float(r_s)
    x = np.atleast_2d(x)
    r = row_norm(x)
    if not np.all(r > 1.0):
        raise ValueError(f"a moving observer at r = {np.min(r):.6g} r_s is not outside the horizon (r > 1 r_s)")
    n = x / r[:, None]
    v = np.atleast_2d(np.asarray(velocity, dtype=np.float64)) / c
    f = 1.0 - 1.0 / r
    v_r = np.einsum("ij,ij->i", v, n)
    v_t = v - v_r[:, None] * n
    return (v_r / f)[:, None] * n + v_t / np.sqrt(f)[:, None]


def lorentz_gamma(beta) -> float:
    """gamma = 1 / sqrt(1 - |beta|^2) of one velocity ``beta`` (3,; units of c). Raises ValueError for
    |beta| >= 1 or a non-finite beta (no observer moves at or above the speed of light)."""
    beta = np.asarray(beta, dtype=np.float64).reshape(3)
    b2 = float(beta @ beta)
    if not (np.isfinite(b2) and b2 < 1.0):
        raise ValueError(f"the observer moves at {np.sqrt(b2):.6g} c in the local static frame; it must stay "
                         "below the speed of light (raise speed_of_light or slow the camera)")
    return 1.0 / np.sqrt(1.0 - b2)


def aberrate(directions, beta) -> np.ndarray:
    """(N, 3) unit directions in which an observer moving with ``beta`` (3,; units of c, world axes =
    the local static frame's) sees the light that the static observer at the same event sees from the
    unit ``directions`` (N, 3) (apparent directions, i.e. opposite to the photons' direction of travel).

    Special-relativistic aberration, exact: with theta the angle between a direction and beta,
    cos theta' = (cos theta + |beta|) / (1 + |beta| cos theta) and sin theta' = sin theta / (gamma
    (1 + |beta| cos theta)), in the same plane through beta: everything crowds towards the direction
    of motion. In vector form (one dot product per direction, no normalisation needed: the result is
    a unit vector to rounding),

        d' = (d / gamma + (1 + gamma / (gamma + 1) beta . d) beta) / (1 + beta . d).

    beta = 0 returns ``directions`` itself (the same array). Raises ValueError for |beta| >= 1. NaN
    directions stay NaN. :func:`unaberrate` is the inverse."""
    beta = np.asarray(beta, dtype=np.float64).reshape(3)
    gamma = lorentz_gamma(beta)
    if not beta.any():
        return directions
    d = np.asarray(directions, dtype=np.float64)
    k = d @ beta  # beta . d
    inv = 1.0 / (1.0 + k)  # (|beta| < 1: never 0 for unit d)
    along = (1.0 + (gamma / (gamma + 1.0)) * k) * inv
    out = d * (inv / gamma)[..., None]
    out += along[..., None] * beta
    return out


def unaberrate(directions, beta) -> np.ndarray:
    """The inverse of :func:`aberrate`: the static observer's apparent directions (N, 3) of light that
    the observer moving with ``beta`` (3,; units of c) sees from the unit ``directions`` (N, 3) (e.g.
    a moving camera's pixel rays, taken back to the static frame before the deflection)."""
    return aberrate(directions, -np.asarray(beta, dtype=np.float64).reshape(3))


def doppler_factor(directions, beta) -> np.ndarray:
    """(N,) nu_moving / nu_static: the ratio of the frequencies that the observer moving with ``beta``
    (3,; units of c) and the static observer at the same event measure for light they see from the
    unit apparent ``directions`` (N, 3) of the *static* frame: gamma (1 + beta . d) = gamma (1 - beta . k),
    k = -d the photon's direction of travel. Above 1 towards the direction of motion. Raises
    ValueError for |beta| >= 1."""
    beta = np.asarray(beta, dtype=np.float64).reshape(3)
    gamma = lorentz_gamma(beta)
    return gamma * (1.0 + np.asarray(directions, dtype=np.float64) @ beta)


def frequency_ratio(r_emit, r_obs, k_obs, beta_obs=None, k_emit=None, beta_emit=None) -> np.ndarray:
    """g = nu_observed / nu_emitted = 1 / (1 + z) of light from emitters at radii ``r_emit`` (N,; units
    of r_s; np.inf for the sky) received by the observer at ``r_obs`` (units of r_s):

        g = sqrt((1 - r_s/r_e) / (1 - r_s/r_o)) gamma_o (1 - beta_o . k_o) / (gamma_e (1 - beta_e . k_e)),

    ``k_obs`` (N, 3): the photon's unit direction of travel where it arrives, in the observer's local
    static frame (minus the static observer's apparent direction; not needed for an observer at
    rest); ``beta_obs`` (3,): the observer's velocity in that frame (units of c; None: at rest);
    ``k_emit`` (N, 3): the photon's unit direction
    of travel where it leaves the emitter, in the emitter's static frame, and ``beta_emit`` (N, 3 or 3)
    the emitter's velocity there (None: emitters at rest, and ``k_emit`` is not needed). An observer
    moving towards the source sees g > 1. NaN for emitters at or inside the horizon or moving at or
    above c; raises ValueError for r_obs <= 1 or |beta_obs| >= 1."""
    r_obs = float(r_obs)
    if not r_obs > 1.0:
        raise ValueError(f"the observer at r = {r_obs:.6g} r_s is not outside the horizon (r > 1 r_s)")
    r_e = np.asarray(r_emit, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        g = np.sqrt((1.0 - 1.0 / r_e) / (1.0 - 1.0 / r_obs))
        g = np.where(r_e > 1.0, g, np.nan)
        if beta_obs is not None:
            g = g * doppler_factor(-np.asarray(k_obs, dtype=np.float64), beta_obs)
        if beta_emit is not None:
            be = np.asarray(beta_emit, dtype=np.float64)
            b2 = np.einsum("...j,...j->...", be, be)
            gamma_e = np.where(b2 < 1.0, 1.0 / np.sqrt(1.0 - np.minimum(b2, 1.0)), np.nan)
            g = g / (gamma_e * (1.0 - np.einsum("...j,...j->...", be, np.asarray(k_emit, dtype=np.float64))))
    return g
