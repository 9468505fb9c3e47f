"""The map stage: world-space points to their first- and second-order images, and the only way into
the table of connecting rays (a :class:`Mapper` per frame; every other stage asks it).

Units: positions in Blender units (BU); ``r_s`` is the Schwarzschild radius in BU; the LUT works in
units of r_s (lengths) and r_s/c (times), so a light travel time dt from the LUT is a distance of
dt * r_s BU (c = 1). Conventions (seed 000, eqs. 15 and 11): for a vertex p (relative to the hole) and
the camera c (relative to the hole), e1 = c/|c| is the observer's outward radial direction and e2 the
unit vector of p's component perpendicular to e1, so p has polar coordinates (r, phi) with
phi in [0, pi] in the plane (e1, e2). The observer sees the order-1 image in the direction
cos(xi) e1 + sin(xi) e2 and the order-2 image in cos(xi) e1 - sin(xi) e2, both in its static
orthonormal frame, which grlens identifies with Blender's Euclidean axes at the camera. Each image
is placed at its light-travel-time distance dt * r_s from the camera. That step from the table's
values to the world is observer_view.place_images.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .observer_view import any_perpendicular, lorentz_gamma, place_images, row_norm

# A vertex this close to the observer-hole axis (|p_perp| / |p|) has no unique plane: it is seen as
# an Einstein ring, which a mesh cannot show. Such vertices are flagged and their triangles culled.
AXIS_EPS = 1e-9

R_OBS_TOLERANCE = 1e-6
"""Largest relative difference between the LUT's observer radius and the camera's distance that is
accepted. Camera transforms are single precision in Blender, so an orbiting camera's distance
jitters by ~1e-7 from frame to frame; the add-on rounds the radius to 7 significant digits when it
builds tables (one table for the whole orbit). The resulting direction error is below 1e-6 rad."""


def round_radius(r_obs) -> float:
    """A camera or light radius (r_s) rounded to 7 significant digits: the radius tables are made for
    (single-precision transforms jitter by ~1e-7; the direction error of rounding is below 1e-6 rad,
    see R_OBS_TOLERANCE)."""
    return float(f"{float(r_obs):.7g}")


@dataclass
class Scene:
    """Camera and hole in world space (BU) and the Schwarzschild radius r_s (BU); ``beta`` (3,), when
    frames measure physical time: the camera's velocity in its local static frame (units of c, world
    axes; observer_view.static_frame_beta), which aberrates every image direction and shifts every
    image's light (assemble's 1 + z); None: a still, seen by the static observer (beta = 0 aberrates
    nothing but still gives every image its 1 + z). ``aberration`` False (for teaching): the directions
    are the static observer's though the camera moves (its light is still shifted)."""

    camera: np.ndarray  # (3,)
    hole: np.ndarray  # (3,)
    r_s: float
    beta: np.ndarray | None = None
    aberration: bool = True

    def __post_init__(self):
        self.camera = np.asarray(self.camera, dtype=np.float64).reshape(3)
        self.hole = np.asarray(self.hole, dtype=np.float64).reshape(3)
        self.r_s = float(self.r_s)
        if not (np.isfinite(self.r_s) and self.r_s > 0):
            raise ValueError(f"r_s must be a positive number of Blender units, got {self.r_s}")
        if not (np.all(np.isfinite(self.camera)) and np.all(np.isfinite(self.hole))):
            raise ValueError("camera and black hole positions must be finite")
        if not np.linalg.norm(self.camera - self.hole) > 0:
            raise ValueError("the camera is at the centre of the black hole")
        if self.beta is not None:
            self.beta = np.asarray(self.beta, dtype=np.float64).reshape(3)
            lorentz_gamma(self.beta)  # refuses |beta| >= 1

    @property
    def view_beta(self) -> np.ndarray | None:
        """The velocity that aberrates the camera's view (units of c): ``beta``, or None without one or
        with ``aberration`` off."""
        return self.beta if self.aberration else None

    @property
    def r_obs(self) -> float:
        """Camera distance from the hole in units of r_s."""
        return float(np.linalg.norm(self.camera - self.hole) / self.r_s)

    @property
    def e1(self) -> np.ndarray:
        """Unit vector from the hole to the camera (the observer's outward radial direction)."""
        d = self.camera - self.hole
        return d / np.linalg.norm(d)


@dataclass
class PlaneCoordinates:
    """Per-vertex plane of (hole, camera, vertex): r (units of r_s), phi (rad), e2 (N, 3), on_axis."""

    r: np.ndarray
    phi: np.ndarray
    e2: np.ndarray
    on_axis: np.ndarray

    def take(self, rows) -> "PlaneCoordinates":
        """The coordinates of the points ``rows`` (indices)."""
        return PlaneCoordinates(r=self.r.take(rows), phi=self.phi.take(rows), e2=self.e2.take(rows, axis=0),
                                on_axis=self.on_axis.take(rows))


def plane_coordinates(points: np.ndarray, scene: Scene) -> PlaneCoordinates:
    """Polar coordinates of world-space ``points`` (N, 3; BU) in their planes through hole and camera.

    Non-finite points give NaN coordinates. Points on the observer-hole axis get an arbitrary but
    deterministic e2 (perpendicular to e1) and ``on_axis`` True.
    """
    e1 = scene.e1
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        p = (np.asarray(points, dtype=np.float64) - scene.hole) / scene.r_s
        along = p @ e1
        perp = p - along[:, None] * e1
        n_perp = row_norm(perp)
        r = row_norm(p)
        on_axis = n_perp <= AXIS_EPS * r
        fallback = any_perpendicular(e1)
        e2 = np.where(on_axis[:, None], fallback, perp / n_perp[:, None])
        phi = np.arctan2(n_perp, along)
    return PlaneCoordinates(r=r, phi=phi, e2=e2, on_axis=on_axis)


@dataclass
class Images:
    """Lensed images of N vertices for one order.

    position: (N, 3) image positions (BU), NaN where there is no image;
    direction: (N, 3) unit apparent direction from the camera;
    distance: (N,) light travel distance c*dt (BU) = camera-image distance;
    valid: (N,) bool, finite image that is not on the axis;
    plane: the PlaneCoordinates used; xi (rad), dt (r_s/c): the LUT values; ux, uy: the ray's tangent
    there (only from map_vertices_orders(..., tangents=True), else None).
    """

    position: np.ndarray
    direction: np.ndarray
    distance: np.ndarray
    valid: np.ndarray
    plane: PlaneCoordinates
    xi: np.ndarray
    dt: np.ndarray
    ux: np.ndarray
    uy: np.ndarray


class Mapper:
    """The table of connecting rays for one frame's observer (``scene.camera``), and every question the
    core asks it. ``table``: a lutgen.LUT / WideLUT / LUTFamily table (anything with ``r_obs`` and
    ``lookup_orders``) built for r_obs = scene.r_obs (to R_OBS_TOLERANCE relative); the family's
    tables depend on the camera's radius, so a moving camera gets a new Mapper per frame."""

    def __init__(self, scene: Scene, table):
        if abs(table.r_obs / scene.r_obs - 1.0) > R_OBS_TOLERANCE:
            raise ValueError(f"the LUT was built for r_obs = {table.r_obs:.9g} r_s but the camera is at "
                             f"{scene.r_obs:.9g} r_s from the hole; rebuild the LUT")
        self.scene, self.table = scene, table

    def images(self, points, orders=(1, 2), plane: PlaneCoordinates | None = None, tangents: bool = False) -> dict:
        """{order: :class:`Images`} of world-space ``points`` (N, 3; BU): see :func:`map_vertices_orders`."""
        for order in orders:
            if order not in (1, 2):
                raise ValueError(f"order must be 1 or 2, got {order!r}")
        scene = self.scene
        plane = plane if plane is not None else plane_coordinates(points, scene)
        looks = self.rays(plane.r, plane.phi, orders, ("xi", "dt", "ux", "uy") if tangents else ("xi", "dt"))
        out = {}
        for order in orders:
            look = looks[order]
            direction, distance, position, finite = place_images(look.xi, look.dt, plane.e2, scene, order)
            valid = finite & ~plane.on_axis
            position[~valid] = np.nan
            out[order] = Images(position=position, direction=direction, distance=distance, valid=valid, plane=plane,
                                xi=look.xi, dt=look.dt, ux=look.ux, uy=look.uy)
        return out

    def rays(self, r, phi, orders, quantities=("xi", "dt")) -> dict:
        """{order: lutgen.Lookup} of the table's values at plane coordinates (``r`` in r_s, ``phi`` in
        radians): the raw rays, for points given by their coordinates (an Einstein ring's limit)."""
        return self.table.lookup_orders(r, phi, tuple(orders), quantities=tuple(quantities))

    def leaving(self, points, orders=(1, 2)) -> dict:
        """{order: (d, dt)}: the unit direction d (N, 3; world axes) in which the connecting ray leaves
        each of ``points`` (N, 3; BU) towards the observer, in the point's static frame, and its travel
        time dt (N,; r_s / c). A surface with unit normal n faces the observer along that ray when
        n . d > 0. NaN where the point has no ray of that order."""
        plane = plane_coordinates(points, self.scene)
        looks = self.rays(plane.r, plane.phi, orders, ("dt", "ux", "uy"))
        return {o: (leaving_direction(plane, self.scene, looks[o].ux, looks[o].uy), looks[o].dt) for o in orders}

    def extend(self, coarse: Images, positions, vertex_key, n_pts, order, known=None) -> Images:
        """Images of order ``order`` of subdivided vertices ``positions`` (V, 3; BU) whose welding keys
        ``vertex_key`` (V,) below ``n_pts`` are source vertices: those reuse ``coarse`` (the source
        vertices' images); ``known``: (keys (K,) sorted, Images) of points mapped already under their
        keys (the level plan's probes), reused too; only the others are looked up."""
        is_corner = vertex_key < n_pts
        if is_corner.all():
            return take(coarse, vertex_key)
        rest = np.flatnonzero(~is_corner)
        reuse = None
        if known is not None:
            keys, known_img = known
            at = np.minimum(np.searchsorted(keys, vertex_key[rest]), len(keys) - 1)
            hit = keys[at] == vertex_key[rest]
            if hit.any():
                reuse = (rest[hit], at[hit])
                rest = rest[~hit]
        # every new vertex known already: no lookup (a table call costs ~0.1-1 ms even without points)
        new = self.images(positions[rest], (order,))[order] if rest.size else None
        n = len(positions)
        out = Images(position=np.empty((n, 3)), direction=np.empty((n, 3)), distance=np.empty(n),
                     valid=np.empty(n, dtype=bool), plane=None, xi=np.empty(n), dt=np.empty(n), ux=None, uy=None)
        idx = vertex_key[is_corner]
        for name in ("position", "direction", "distance", "valid", "xi", "dt"):
            dst = getattr(out, name)
            dst[is_corner] = getattr(coarse, name)[idx]
            if new is not None:
                dst[rest] = getattr(new, name)
            if reuse is not None:
                dst[reuse[0]] = getattr(known_img, name)[reuse[1]]
        return out


def take(img: Images, rows) -> Images:
    """The images ``rows`` (indices) of ``img`` (positions, directions, distances, validity, table values)."""
    return Images(position=img.position.take(rows, axis=0), direction=img.direction.take(rows, axis=0),
                  distance=img.distance.take(rows), valid=img.valid.take(rows), plane=None,
                  xi=img.xi.take(rows), dt=img.dt.take(rows), ux=None, uy=None)


def concatenate(parts) -> Images:
    """The images of several point sets one after another (positions, directions, distances,
    validity, table values)."""
    return Images(position=np.concatenate([p.position for p in parts]),
                  direction=np.concatenate([p.direction for p in parts]),
                  distance=np.concatenate([p.distance for p in parts]), valid=np.concatenate([p.valid for p in parts]),
                  plane=None, xi=np.concatenate([p.xi for p in parts]), dt=np.concatenate([p.dt for p in parts]),
                  ux=None, uy=None)


def leaving_direction(plane, scene: Scene, ux, uy) -> np.ndarray:
    """(N, 3) unit direction, in the static frame of points with plane coordinates ``plane``, opposite
    to the tangent (ux, uy) of their connecting rays from the table (components along e1 and e2 of the
    plane, see lutgen): the way the light leaves the point towards the observer. NaN where the ray is
    undefined."""
    a, b = leaving_in_plane(plane, ux, uy)  # (along e1 and e2: -(f_r e_r + r_uphi e_phi) in the plane)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.multiply.outer(a, scene.e1)
        d += b[:, None] * plane.e2
        d /= row_norm(d)[:, None]
    return d


def leaving_in_plane(plane, ux, uy, trig=None):
    """(a, b), each (N,): :func:`leaving_direction` = (a e1 + b e2) / |(a, b)|, without the
    normalisation (a positive factor per point: enough for the sign of n . d). NaN where the ray is
    undefined. ``trig``: :func:`plane_trig` of ``plane`` when the caller has it (several orders' rays
    at the same points)."""
    c, s, f_r, r_uphi = _static_frame(plane, ux, uy, trig)
    with np.errstate(invalid="ignore"):
        return -(f_r * c - r_uphi * s), -(f_r * s + r_uphi * c)


def plane_trig(plane):
    """(cos phi, sin phi, sqrt(1 - 1/r)), each (N,), of points with plane coordinates ``plane`` (r in
    r_s): what the static frame's components of their rays' tangents need (:func:`_static_frame`)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.cos(plane.phi), np.sin(plane.phi), np.sqrt(1.0 - 1.0 / plane.r)


def _static_frame(plane, ux, uy, trig=None):
    """cos phi, sin phi and the ray's tangent in the points' static frame: its components along e_r
    and e_phi (f_r, r_uphi), from the table's (ux, uy) (along e1 and e2); ``trig``: plane_trig(plane)
    or None."""
    c, s, root = trig if trig is not None else plane_trig(plane)
    u_r = ux * c + uy * s  # dr/dlambda
    r_uphi = -ux * s + uy * c  # r dphi/dlambda
    with np.errstate(invalid="ignore", divide="ignore"):
        f_r = u_r / root  # local static frame components
    return c, s, f_r, r_uphi


def map_vertices(points: np.ndarray, scene: Scene, lut, order: int, plane: PlaneCoordinates | None = None) -> Images:
    """Images of order 1 or 2 of world-space ``points`` (N, 3; BU) seen from ``scene.camera``.

    ``lut`` is a :class:`lutgen.LUT` built for r_obs = scene.r_obs (to R_OBS_TOLERANCE relative); points
    outside its radial range, inside the horizon, non-finite or on the axis come back invalid (NaN).
    """
    return map_vertices_orders(points, scene, lut, (order,), plane)[order]


def map_vertices_orders(points: np.ndarray, scene: Scene, lut, orders=(1, 2),
                        plane: PlaneCoordinates | None = None, tangents: bool = False) -> dict:
    """:func:`map_vertices` for several orders at once ({order: Images}); the plane coordinates and
    the LUT's interpolation stencil are computed once. With ``tangents`` the rays' tangents ux, uy at
    the points are looked up too (for illumination.leaving_direction)."""
    return Mapper(scene, lut).images(points, orders, plane, tangents)
