"""Reference renderer: one exact null geodesic per pixel against a triangle scene (numpy only, no bpy).

This is the ground truth the polygon method (mapping + subdivision, see ``pipeline``) is measured
against; it is slow (seconds per frame): tests, benchmarks and the add-on's frame check
(``frame_check``, ``bpy.ops.grlens.check_frame``) use it, the per-frame rebuild does not.

Units and conventions
---------------------
World positions, r_s, distances and light travel times c*dt are in Blender units (BU); internally
lengths are in units of r_s (as in ``lutgen``), c = 1. The camera is a static observer at
r_obs = |camera - hole| / r_s (> 1; inside the photon sphere too).
``e1 = (camera - hole)/|camera - hole|`` is its outward radial
direction; a ray leaving the camera in the world direction ``d`` makes the angle ``xi`` with e1 (in
the observer's static orthonormal frame, which grlens identifies with Blender's Euclidean axes at the
camera) and lies in the plane through the hole spanned by e1 and ``e2 = unit(d - (d.e1) e1)``. In
that plane the ray is the exact curve u(Phi) = r_s/r of the orbit with impact parameter
b = sin(xi) / (u_obs sqrt(1 - u_obs)), where Phi >= 0 is the angle swept from the camera around the
hole towards +e2 (Phi grows monotonically along the ray). A point reached at swept angle Phi is an
image of order 1 if Phi <= pi (lutgen's order 1 with phi = Phi), of order 2 if pi < Phi <= 2 pi
(lutgen's order 2 with phi = 2 pi - Phi, measured on the other side of the axis) and of order
ceil(Phi / pi) beyond.

The curve in closed form (lutgen.orbit's roots e1 < e2 <= e3 or e1, m +- i n): with
w = w_obs + s c Phi (s = +1 for rays that leave towards the hole, cos xi < 0, else -1),

* turning orbits (b > b_crit): u = e1 + (e2 - e1) sn^2(w | k^2), k^2 = (e2-e1)/(e3-e1),
  c = sqrt(e3 - e1)/2; the periapsis u = e2 is at w = K(k^2), after which u decreases again;
* plunging orbits (b < b_crit): u = e1 + A (1 - cn(w|k^2)) / (1 + cn(w|k^2)), A = |m + i n - e1|,
  k^2 = (A + m - e1)/(2A), c = sqrt(A);

both the inverse of lutgen.orbit.sweep (``w / c`` is the F(u) of that module). For an observer inside
the photon sphere (r_obs <= 1.5) the turning rays lie on the inner branch u >= e3 (they climb to an
apoapsis and fall in): u = (e3 - e2 sn^2(w | k^2)) / cn^2(w | k^2), same k^2 and c, w = 0 at the
apoapsis, the inverse of the angle swept from it (lutgen.rays._sweep_inner, Carlson's form). The swept
angle is therefore exact, however often a ray near the critical impact parameter winds around the hole.

Intersections
-------------
Every ray plane contains the axis hole-camera, so a triangle can only be met by rays whose plane
azimuth about that axis lies in the triangle's azimuth range (all rays if the triangle surrounds the
axis); rays are sorted by azimuth and paired with triangles by ``searchsorted``. Each object gets a
radial shell [R_lo, R_hi] around the hole; the swept-angle intervals in which a ray is inside it
(at most one inbound and one outbound leg) are exact (lutgen.orbit.sweep). For each (ray, triangle)
pair the triangle is cut by the ray's plane into a segment that subtends an angular sector
[phi_a, phi_a + width] (width < pi) seen from the hole; candidate intervals are the sector shifted by
2 pi k and clipped to the shell intervals. On each interval the curve meets the segment where

    g(Phi) = u_ray(Phi) - u_line(Phi) = 0,   u_line(Phi) = (m . (cos Phi, sin Phi)) / p

(the segment's line {x : m.x = p}, p > 0). Since u_ray'' + u_ray = 3/2 u_ray^2 and
u_line'' + u_line = 0, g'' + g >= 0: on intervals shorter than pi, g has at most two zeros, a sign
change brackets exactly one, equal negative signs exclude any, and g(a + t) >= g(a) cos t + g'(a) sin t
(the ray stays on the hole's side of its tangent) gives a rigorous exclusion test for equal positive
signs. Undecided intervals are bisected; bracketed roots are polished with safeguarded Newton steps
to ~1e-14 rad. The first root along the ray (smallest Phi) is the pixel's hit. Nothing is sampled, so
there is no step-size error; the answers are exact up to rounding (tested against lutgen.connect
and, for the curve itself, against lutgen.reference's DOP853 integrator).

Light travel time: lutgen.orbit.travel_time from u_obs to u_hit, or, for a hit after the periapsis,
from u_obs to the periapsis plus from there to u_hit (as lutgen.solver._finish does); on the inner
branch a Gauss-Legendre quadrature in v, u = e3 + (e3 - e2) sinh^2(v) (lutgen.orbit.travel_time_inner).

Sky
---
A ray that hits nothing and does not fall in (b > b_crit or leaving outwards, i.e. xi below
pi - the shadow's half angle of eq. 14) reaches r = infinity at the swept angle Phi_inf = ``phi_end``,
where the closed-form curve has u(Phi) = 0: F(u_obs) - F(0) for rays leaving outwards,
2 F(e2) - F(u_obs) - F(0) for rays passing the periapsis (F = lutgen.orbit.sweep; flat limit
Phi_inf = xi). There its direction is parallel to its position, so it travels in the world direction
cos(Phi_inf) e1 + sin(Phi_inf) e2: the sky it shows (``PixelBuffers.sky``, :func:`escape_directions`;
no lutgen table and no emitter-observer solver involved). Accurate to ~1e-13 rad, except near
xi = pi/2 (a turning point next to the camera: ~1e-9 rad) and next to the critical angle, where
Phi_inf grows like -ln(xi_crit - xi) and the rounding of xi (4e-16 rad) is amplified accordingly.

Moving cameras
--------------
Everything above is the static observer's view. A camera moving with the velocity ``beta`` (units
of c, world axes) in its local static frame (observer_view.static_frame_beta) sees through each
pixel the light that the static observer at the same event sees from the pixel's direction taken
back to the static frame (observer_view.unaberrate, exact Lorentz aberration): the tracer traces
those static directions. Light from a hit reaches the camera with the frequency ratio
g = nu_seen / nu_emitted = 1 / (1 + z) of observer_view.frequency_ratio (the hit at rest, the
camera moving with beta; ``PixelBuffers.g``), the sky's light (emitted at rest at infinity) with
g = gamma (1 + beta . d) / sqrt(1 - r_s/r_obs), d the static direction. Without beta (or beta = 0)
the camera is static and every other buffer is what it was.

Cameras
-------
:class:`Camera` is Blender's perspective camera or one of Cycles' panoramas, equirectangular (the
full sphere or a longitude / latitude range) and fisheye equidistant (``Camera.kind``); the tracer
only needs its pixel directions (a fisheye's pixels outside its circle have no ray: no hit, not
fallen, no sky), the rasterizer and the metrics its projection.

Cuts whose line passes through the hole (to 1e-10 of their length; every cut of a planar mesh whose
plane contains the hole, such as an equatorial disc) are radial: the ray meets them where Phi equals
their polar angle (+ 2 pi k), if r(Phi) lies within the cut.

Cost: single-threaded numpy, about 1-6 s for the paper's sphere at 640x360 (more when an object
surrounds the camera-hole axis, since its triangles pair with many ray planes); memory is bounded by
``pair_chunk``. Limitations: grazing (tangential) hits can be missed; everything at r <= r_s
(inside the horizon) is invisible; the camera must be within 1e8 r_s of the hole.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.special import ellipj

from lutgen import orbit as _orb
from lutgen.orbit import sweep_inner as _sweep_inner
from lutgen.solver import connect, static_observer_radius
from .culling import side_planes
from .mapping import Scene, plane_coordinates
from .observer_view import aberrate, any_perpendicular, frequency_ratio, ray_planes, unaberrate, view_directions
from .ragged import group_offsets

TWO_PI = 2.0 * np.pi
_B_MIN = 1e-12  # impact parameters (r_s) below this are clamped (the ray is radial to rounding)
_RADIAL_TOL = 1e-10  # a cut whose line passes within this fraction of its length from the hole is radial
_R_OBS_MAX = 1e8  # r_s; impact parameters above ~1e9 r_s break lutgen.orbit.orbit_from_b
_AZ_PAD = 1e-7  # rad, widening of the triangles' azimuth ranges (pairing is only a pre-selection)


# --------------------------------------------------------------------------------------------------
# Camera and buffers
# --------------------------------------------------------------------------------------------------
CAMERA_KINDS = ("PERSP", "EQUIRECTANGULAR", "FISHEYE_EQUIDISTANT")
"""The camera models of :class:`Camera`: Blender's perspective camera and two of Cycles' panoramas."""


@dataclass
class Camera:
    """A camera in Blender's convention: it looks along its local -Z, local +Y is up, +X right.

    position: (3,) BU; rotation: (3, 3) camera-to-world rotation (columns: the camera's x, y, z axes in
    world space, e.g. ``matrix_world.to_3x3()``); fov_y: full vertical field of view (rad; perspective
    only, ignored by panoramas); width, height: resolution in pixels. Pixel (row j, column i) looks
    through its centre; row 0 is the top of the image, so buffers are (height, width) arrays in image
    order. (A Blender camera with sensor fit AUTO and width >= height has the horizontal angle
    ``cam.data.angle``: then fov_y = 2 atan(tan(angle / 2) * height / width).)

    ``kind`` selects the projection (:data:`CAMERA_KINDS`); the panoramas follow Cycles
    (intern/cycles/kernel/camera/projection.h and the camera matrix of Cycles' Blender sync, which
    turns Cycles' panorama frame, +x forward, +y left, +z up, into Blender's camera axes). With
    u = (i + 0.5) / width from the left and v = 1 - (j + 0.5) / height from the bottom (Cycles' raster
    y runs upwards):

    * ``"PERSP"``: the pinhole camera above;
    * ``"EQUIRECTANGULAR"``: longitude lon = longitude_min + u (longitude_max - longitude_min),
      latitude lat = latitude_min + v (latitude_max - latitude_min) (rad; Blender's camera settings
      ``longitude_min/max``, ``latitude_min/max``, default the full 360 x 180 degrees), the direction
      (cos lat sin lon, sin lat, -cos lat cos lon) in camera axes: the image centre looks along -Z,
      longitude grows to the right (towards +X), latitude upwards (+Y). With the full range the
      left and right edges meet behind the camera (the seam, at lon = +-pi);
    * ``"FISHEYE_EQUIDISTANT"``: x = 2u - 1, y = 2v - 1, rho = hypot(x, y); the angle from the view
      axis (-Z) is theta = rho * fisheye_fov / 2 (rad), towards (x, y) / rho in the camera's (X, Y)
      plane. Pixels with rho > 1 see nothing (their directions are NaN). As in Cycles, u and v span
      the frame's width and height: a square frame holds the circular image (fisheye_fov = pi is a
      180 degree dome master), another aspect ratio stretches it into an ellipse. fisheye_fov is
      limited to (0, 2 pi] (beyond, a direction would appear on several rings).
    """

    position: np.ndarray
    rotation: np.ndarray
    fov_y: float
    width: int
    height: int
    kind: str = "PERSP"
    fisheye_fov: float = np.pi
    latitude_min: float = -0.5 * np.pi
    latitude_max: float = 0.5 * np.pi
    longitude_min: float = -np.pi
    longitude_max: float = np.pi

    def __post_init__(self):
        self.position = np.asarray(self.position, dtype=np.float64).reshape(3)
        self.rotation = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        self.fov_y = float(self.fov_y)
        self.width, self.height = int(self.width), int(self.height)
        self.kind = str(self.kind).upper()
        if self.kind not in CAMERA_KINDS:
            raise ValueError(f"unknown camera kind {self.kind!r}; expected one of {', '.join(CAMERA_KINDS)}")
        for k in ("fisheye_fov", "latitude_min", "latitude_max", "longitude_min", "longitude_max"):
            setattr(self, k, float(getattr(self, k)))
        if self.kind == "FISHEYE_EQUIDISTANT" and not 0.0 < self.fisheye_fov <= TWO_PI:
            raise ValueError(f"fisheye_fov must be in (0, 2 pi], got {self.fisheye_fov!r}")
        if self.kind == "EQUIRECTANGULAR":
            if not -0.5 * np.pi <= self.latitude_min < self.latitude_max <= 0.5 * np.pi:
                raise ValueError("the latitude range must satisfy -pi/2 <= latitude_min < latitude_max <= pi/2")
            if not -np.pi <= self.longitude_min < self.longitude_max <= np.pi:
                raise ValueError("the longitude range must satisfy -pi <= longitude_min < longitude_max <= pi")

    @property
    def panoramic(self) -> bool:
        """True for the panoramic kinds (no perspective frustum, nothing 'behind' the camera)."""
        return self.kind != "PERSP"

    @property
    def column_period(self) -> float | None:
        """Equirectangular: the number of columns per full turn of longitude, 2 pi width /
        (longitude_max - longitude_min) (the width for the full panorama; column differences are
        periodic in it); None for the other kinds."""
        if self.kind != "EQUIRECTANGULAR":
            return None
        return TWO_PI * self.width / (self.longitude_max - self.longitude_min)

    @classmethod
    def look_at(cls, position, target, fov_y, width, height, up=(0.0, 0.0, 1.0), **lens) -> "Camera":
        """Camera at ``position`` looking at ``target`` (BU) with the image's up close to ``up``;
        ``lens``: further fields (kind, fisheye_fov, latitude_min, ...)."""
        position = np.asarray(position, dtype=np.float64)
        fwd = np.asarray(target, dtype=np.float64) - position
        fwd /= np.linalg.norm(fwd)
        up = np.asarray(up, dtype=np.float64)
        if abs(fwd @ up) > 0.999999 * np.linalg.norm(up):
            up = np.array([0.0, 1.0, 0.0]) if abs(fwd[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        x = np.cross(fwd, up)
        x /= np.linalg.norm(x)
        y = np.cross(x, fwd)
        return cls(position, np.stack([x, y, -fwd], axis=1), fov_y, width, height, **lens)

    @classmethod
    def from_matrix_world(cls, matrix_world, fov_y, width, height, **lens) -> "Camera":
        """From a 4x4 (or 3x4) camera-to-world matrix such as Blender's ``camera.matrix_world`` (its
        rotation part must be orthonormal: no scale); ``lens``: further fields (kind, ...)."""
        m = np.asarray(matrix_world, dtype=np.float64)
        return cls(m[:3, 3], m[:3, :3], fov_y, width, height, **lens)

    @property
    def tan_half(self) -> tuple[float, float]:
        """(tan of the horizontal half angle, tan of the vertical half angle) (perspective only)."""
        ty = np.tan(0.5 * self.fov_y)
        return ty * self.width / self.height, ty

    @property
    def pixel_angle(self) -> float:
        """Radians per pixel on the view sphere as the add-on computes it for ``Settings.pixel_angle``.

        Perspective: the smaller of the horizontal and vertical fields of view divided by their pixel
        counts. Equirectangular: the smaller of (longitude_max - longitude_min) / width and
        (latitude_max - latitude_min) / height (2 pi / width for the full 2:1 panorama: the spacing
        along the horizon and along every meridian; rows closer to the poles are closer together in
        longitude). Fisheye: fisheye_fov / max(width, height), the radial spacing of the pixels (the
        spacing across the rays of the larger image axis; both axes for the square dome master)."""
        if self.kind == "EQUIRECTANGULAR":
            return min((self.longitude_max - self.longitude_min) / self.width,
                       (self.latitude_max - self.latitude_min) / self.height)
        if self.kind == "FISHEYE_EQUIDISTANT":
            return self.fisheye_fov / max(self.width, self.height)
        tx, ty = self.tan_half
        return min(2.0 * np.arctan(tx) / self.width, 2.0 * np.arctan(ty) / self.height)

    def _uv(self):
        """Per column u (from the left) and per row v (from the bottom) of the pixel centres, in [0, 1]."""
        u = (np.arange(self.width) + 0.5) / self.width
        v = 1.0 - (np.arange(self.height) + 0.5) / self.height
        return u, v

    def local_directions(self) -> np.ndarray:
        """(height, width, 3) unit directions through the pixel centres in camera axes (NaN for a
        fisheye's pixels outside its circle)."""
        local = np.empty((self.height, self.width, 3))
        if self.kind == "PERSP":
            tx, ty = self.tan_half
            xs = (2.0 * (np.arange(self.width) + 0.5) / self.width - 1.0) * tx
            ys = (1.0 - 2.0 * (np.arange(self.height) + 0.5) / self.height) * ty
            local[..., 0] = xs[None, :]
            local[..., 1] = ys[:, None]
            local[..., 2] = -1.0
            local /= np.linalg.norm(local, axis=2, keepdims=True)
            return local
        u, v = self._uv()
        if self.kind == "EQUIRECTANGULAR":
            lon = self.longitude_min + u * (self.longitude_max - self.longitude_min)
            lat = self.latitude_min + v * (self.latitude_max - self.latitude_min)
            cl = np.cos(lat)[:, None]
            local[..., 0] = cl * np.sin(lon)[None, :]
            local[..., 1] = np.sin(lat)[:, None]
            local[..., 2] = -cl * np.cos(lon)[None, :]
            return local
        x = (2.0 * u - 1.0)[None, :] + np.zeros((self.height, 1))
        y = (2.0 * v - 1.0)[:, None] + np.zeros((1, self.width))
        rho = np.hypot(x, y)
        theta = 0.5 * self.fisheye_fov * rho
        with np.errstate(invalid="ignore", divide="ignore"):
            s = np.where(rho > 0, np.sin(theta) / rho, 0.0)
        local[..., 0] = x * s
        local[..., 1] = y * s
        local[..., 2] = -np.cos(theta)
        local[rho > 1.0] = np.nan
        return local

    def pixel_directions(self) -> np.ndarray:
        """(height, width, 3) unit world-space directions through the pixel centres (NaN for a
        fisheye's pixels outside its circle: they see nothing)."""
        return self.local_directions() @ self.rotation.T

    def project(self, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World points (N, 3; BU) -> (column, row, depth): continuous pixel coordinates (pixel centres
        at integer + 0.5, row 0 at the top) and a depth (BU).

        Perspective: depth is the view depth along the camera's -Z (<= 0 behind the camera, where the
        coordinates mean nothing). Panoramas have no 'behind': depth is the distance from the camera
        (> 0 except at the camera itself). Equirectangular: longitude and latitude as in the class
        docstring (longitude in [-pi, pi], the seam behind the camera); points outside the longitude /
        latitude range get coordinates outside [0, width] x [0, height]. Fisheye: NaN coordinates for
        points outside its field (angle from the view axis above fisheye_fov / 2)."""
        local = (np.asarray(points, dtype=np.float64) - self.position) @ self.rotation
        if self.kind == "PERSP":
            depth = -local[:, 2]
            tx, ty = self.tan_half
            with np.errstate(divide="ignore", invalid="ignore"):
                col = (local[:, 0] / depth / tx + 1.0) * 0.5 * self.width
                row = (1.0 - local[:, 1] / depth / ty) * 0.5 * self.height
            return col, row, depth
        x, y, z = local[:, 0], local[:, 1], local[:, 2]
        depth = np.sqrt(x * x + y * y + z * z)
        if self.kind == "EQUIRECTANGULAR":
            lon = np.arctan2(x, -z)
            lat = np.arctan2(y, np.hypot(x, z))
            col = (lon - self.longitude_min) / (self.longitude_max - self.longitude_min) * self.width
            row = (1.0 - (lat - self.latitude_min) / (self.latitude_max - self.latitude_min)) * self.height
            return col, row, depth
        rxy = np.hypot(x, y)
        theta = np.arctan2(rxy, -z)
        rho = theta / (0.5 * self.fisheye_fov)
        with np.errstate(divide="ignore", invalid="ignore"):
            cx = np.where(rxy > 0, x / rxy, 0.0)
            cy = np.where(rxy > 0, y / rxy, 0.0)
        col = 0.5 * (1.0 + rho * cx) * self.width
        row = 0.5 * (1.0 - rho * cy) * self.height
        out = ~(rho <= 1.0)
        return np.where(out, np.nan, col), np.where(out, np.nan, row), depth

    def frustum_planes(self, margin: float = 0.05) -> np.ndarray | None:
        """(4, 4) world-space side planes (n, d), n . x + d >= 0 inside, widened by ``margin`` (a
        fraction of the half-angles' tangents), as the add-on passes to pipeline.build_images; None
        for the panoramas (no perspective frustum: nothing is culled)."""
        if self.panoramic:
            return None
        tx, ty = self.tan_half
        tx, ty = tx * (1 + margin), ty * (1 + margin)
        corners = np.array([[-tx, -ty, -1.0], [tx, -ty, -1.0], [tx, ty, -1.0], [-tx, ty, -1.0]]) @ self.rotation.T
        return side_planes(self.position, corners)

    def cap_pixel_boxes(self, centre, radius) -> tuple[np.ndarray, ...]:
        """Pixel boxes that hold every pixel centre whose direction lies within the angle ``radius``
        (K,; rad, < pi/2) of the unit world directions ``centre`` (K, 3), panoramas only: (index into
        the caps, column start, column end, row start, row end), ends inclusive, one or two boxes per
        cap (two where an equirectangular cap crosses the seam). Used by the rasterizer to find the
        pixels a triangle may cover: its spherical image lies inside the cap through its corners'
        directions. Conservative by half a pixel plus one pixel."""
        c = np.asarray(centre, np.float64).reshape(-1, 3) @ self.rotation  # camera axes
        rad = np.asarray(radius, np.float64).reshape(-1)
        k = np.arange(len(c))
        W, H = self.width, self.height
        if self.kind == "EQUIRECTANGULAR":
            lat_c = np.arcsin(np.clip(c[:, 1], -1.0, 1.0))
            lon_c = np.arctan2(c[:, 0], -c[:, 2])
            lat0, lat1 = lat_c - rad, lat_c + rad
            full = (lat1 >= 0.5 * np.pi) | (lat0 <= -0.5 * np.pi)  # around a pole: every longitude
            with np.errstate(invalid="ignore", divide="ignore"):
                half = np.arcsin(np.clip(np.sin(rad) / np.cos(lat_c), -1.0, 1.0))
            dlon = (self.longitude_max - self.longitude_min) / W
            dlat = (self.latitude_max - self.latitude_min) / H
            r0 = np.floor((self.latitude_max - lat1) / dlat - 0.5) - 1
            r1 = np.ceil((self.latitude_max - lat0) / dlat - 0.5) + 1
            # continuous column of a longitude: (lon - longitude_min) / dlon - 0.5; the cap's longitudes
            # [lon_c - half, lon_c + half] lie in [-2 pi, 2 pi]: with the shifts by a full turn
            # (2 pi / dlon columns) every column whose longitude lies in the cap is in one of the boxes
            a = np.where(full, -np.pi, lon_c - half)
            b = np.where(full, np.pi, lon_c + half)
            q0 = np.floor((a - self.longitude_min) / dlon - 0.5) - 1
            q1 = np.ceil((b - self.longitude_min) / dlon - 0.5) + 1
            turn = TWO_PI / dlon
            boxes = [(k, q0, q1, r0, r1)]
            for shift in (-turn, turn):
                s_ = ~full & (q0 + shift <= W - 1) & (q1 + shift >= 0)
                boxes.append((k[s_], np.floor(q0[s_] + shift), np.ceil(q1[s_] + shift), r0[s_], r1[s_]))
        else:  # fisheye: the cap's angles from the axis and azimuths, an annular sector of the image
            th_c = np.arctan2(np.hypot(c[:, 0], c[:, 1]), -c[:, 2])
            az_c = np.arctan2(c[:, 1], c[:, 0])
            t0, t1 = np.maximum(th_c - rad, 0.0), th_c + rad
            around = (th_c <= rad) | (th_c + rad >= np.pi)  # the cap holds the view axis or its opposite
            with np.errstate(invalid="ignore", divide="ignore"):
                half = np.where(around, np.pi, np.arcsin(np.clip(np.sin(rad) / np.sin(th_c), -1.0, 1.0)))
            s = 2.0 / self.fisheye_fov
            rho0 = np.where(around, 0.0, t0 * s)
            rho1 = np.minimum(t1 * s, 1.0)
            # bounding box of {rho (cos a, sin a): rho0 <= rho <= rho1, |a - az_c| <= half}
            angs = [az_c - half, az_c + half]
            xs = [rho * np.cos(a_) for rho in (rho0, rho1) for a_ in angs]
            ys = [rho * np.sin(a_) for rho in (rho0, rho1) for a_ in angs]
            x0, x1 = np.minimum.reduce(xs), np.maximum.reduce(xs)
            y0, y1 = np.minimum.reduce(ys), np.maximum.reduce(ys)
            for ax in (0.0, 0.5 * np.pi, np.pi, 1.5 * np.pi):  # axis directions inside the sector
                inside = around | (np.abs(np.mod(ax - az_c + np.pi, TWO_PI) - np.pi) <= half)
                x0 = np.where(inside, np.minimum(x0, rho1 * np.cos(ax)), x0)
                x1 = np.where(inside, np.maximum(x1, rho1 * np.cos(ax)), x1)
                y0 = np.where(inside, np.minimum(y0, rho1 * np.sin(ax)), y0)
                y1 = np.where(inside, np.maximum(y1, rho1 * np.sin(ax)), y1)
            c0 = np.floor(0.5 * (1.0 + x0) * W - 0.5) - 1
            c1 = np.ceil(0.5 * (1.0 + x1) * W - 0.5) + 1
            r0 = np.floor(0.5 * (1.0 - y1) * H - 0.5) - 1
            r1 = np.ceil(0.5 * (1.0 - y0) * H - 0.5) + 1
            keep = t0 * s <= 1.0  # caps entirely outside the field hold no pixel
            boxes = [(k[keep], c0[keep], c1[keep], r0[keep], r1[keep])]
        out = [np.concatenate(x) for x in zip(*boxes)]
        idx = out[0]
        c0 = np.clip(out[1], 0, W - 1).astype(np.int64)
        c1 = np.clip(out[2], -1, W - 1).astype(np.int64)
        r0 = np.clip(out[3], 0, H - 1).astype(np.int64)
        r1 = np.clip(out[4], -1, H - 1).astype(np.int64)
        return idx, c0, c1, r0, r1


_BUFFER_FIELDS = (  # name, dtype, fill value, trailing shape
    ("hit", bool, False, ()), ("object_id", np.int64, -1, ()), ("face", np.int64, -1, ()),
    ("bary", np.float64, np.nan, (3,)), ("uv", np.float64, np.nan, (2,)), ("order", np.int64, 0, ()),
    ("light_time", np.float64, np.nan, ()), ("fell", bool, False, ()), ("point", np.float64, np.nan, (3,)),
    ("phi", np.float64, np.nan, ()), ("depth", np.float64, np.nan, ()), ("sky", np.float64, np.nan, (3,)),
    ("g", np.float64, np.nan, ()))


@dataclass
class PixelBuffers:
    """Per-pixel results of the reference tracer (:func:`trace`) or the rasterizer (``rasterize``).

    Arrays have the image shape S = (height, width) (or (M,) for :func:`trace_rays`):

    hit (S) bool; object_id (S) int, -1 where nothing is hit; face (S) int, the world triangle
    (raytracer) or the image face's source triangle (rasterizer), -1 if none; bary (S, 3): barycentric
    coordinates of the hit in that triangle (rasterizer: in the rasterized image face); uv (S, 2) the
    interpolated corner UVs (NaN without UVs or hit); order (S) int: image order, 0 where nothing is
    hit (1: swept angle <= pi, 2: in (pi, 2 pi], 3+ higher); light_time (S): light travel time c*dt from
    the camera to the hit (BU; coordinate time as in lutgen); fell (S) bool: no hit and the ray falls
    into the hole (always False from the rasterizer); point (S, 3): the world point seen (BU; rasterizer:
    the interpolated source position); phi (S): swept angle of the hit (rad; raytracer only, else NaN);
    depth (S): distance camera-hit along the straight pixel ray (rasterizer only, BU; NaN otherwise);
    sky (S, 3): where the ray neither hits anything nor falls in, the unit world direction in which it
    travels at infinity (the direction of the sky it sees; raytracer: :func:`escape_directions`), NaN
    elsewhere (and everywhere in the rasterizer's buffers). A fisheye's pixels outside its circle have
    no ray: no hit, not fallen, no sky. g (S): the frequency ratio nu_seen / nu_emitted = 1 / (1 + z)
    of the light of the hit, or of the sky (raytracer; see the module docstring), NaN elsewhere (and
    everywhere in the rasterizer's buffers). ``sky`` and ``g`` may be left out (None) when
    constructing: they are then NaN everywhere (buffers stored before they existed).
    """

    hit: np.ndarray
    object_id: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    uv: np.ndarray
    order: np.ndarray
    light_time: np.ndarray
    fell: np.ndarray
    point: np.ndarray
    phi: np.ndarray
    depth: np.ndarray
    sky: np.ndarray | None = None
    g: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.sky is None:
            self.sky = np.full(np.shape(self.hit) + (3,), np.nan)
        if self.g is None:
            self.g = np.full(np.shape(self.hit), np.nan)

    @classmethod
    def empty(cls, shape) -> "PixelBuffers":
        shape = tuple(shape)
        return cls(**{k: np.full(shape + tail, fill, dt) for k, dt, fill, tail in _BUFFER_FIELDS})

    @property
    def shape(self):
        return self.hit.shape

    def reshape(self, shape) -> "PixelBuffers":
        shape = tuple(shape)
        return PixelBuffers(**{k: getattr(self, k).reshape(shape + tail) for k, _, _, tail in _BUFFER_FIELDS},
                            info=self.info)

    def scatter(self, mask) -> "PixelBuffers":
        """Buffers of ``mask``'s shape holding these (flat, one entry per True of ``mask``) where
        ``mask`` is True and the empty values elsewhere; ``info`` is shared."""
        mask = np.asarray(mask, bool)
        out = PixelBuffers.empty(mask.shape)
        for k, _, _, tail in _BUFFER_FIELDS:
            getattr(out, k)[mask] = getattr(self, k).reshape((-1,) + tail)
        out.info = self.info
        return out


@dataclass
class TriangleScene:
    """World-space triangles: positions (N, 3) BU, tris (T, 3) indices, corner_uv (T, 3, 2) or None,
    object_id (T,) int (default 0)."""

    positions: np.ndarray
    tris: np.ndarray
    corner_uv: np.ndarray | None = None
    object_id: np.ndarray | None = None

    def __post_init__(self):
        self.positions = np.asarray(self.positions, dtype=np.float64).reshape(-1, 3)
        self.tris = np.asarray(self.tris, dtype=np.int64).reshape(-1, 3)
        if self.corner_uv is not None:
            self.corner_uv = np.asarray(self.corner_uv, dtype=np.float64).reshape(-1, 3, 2)
        if self.object_id is None:
            self.object_id = np.zeros(len(self.tris), np.int64)
        self.object_id = np.asarray(self.object_id, dtype=np.int64).reshape(-1)

    @classmethod
    def concatenate(cls, parts) -> "TriangleScene":
        """One scene from several (positions, tris, corner_uv or None) meshes; object ids 0, 1, ..."""
        pos, tris, uvs, ids, off = [], [], [], [], 0
        any_uv = any(p[2] is not None for p in parts)
        for i, (p, t, uv) in enumerate(parts):
            p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
            t = np.asarray(t, dtype=np.int64).reshape(-1, 3)
            pos.append(p)
            tris.append(t + off)
            off += len(p)
            ids.append(np.full(len(t), i, np.int64))
            if any_uv:
                uvs.append(np.zeros((len(t), 3, 2)) if uv is None else np.asarray(uv, np.float64).reshape(-1, 3, 2))
        return cls(np.concatenate(pos), np.concatenate(tris), np.concatenate(uvs) if any_uv else None,
                   np.concatenate(ids))


# --------------------------------------------------------------------------------------------------
# The rays: exact curves u(Phi)
# --------------------------------------------------------------------------------------------------
class Rays:
    """Exact null geodesics leaving a static observer (units of r_s inside; see the module docstring).

    origin (3,) and hole (3,) in BU, directions (M, 3) world-space (normalised here), r_s in BU.
    Attributes per ray: xi (rad), b (r_s), e2 (M, 3) in-plane unit vector, normal (M, 3) plane normal,
    turning (bool, b > b_crit), inward (bool, leaves towards the hole), the closed-form parameters,
    and ``phi_peri`` (swept angle of the periapsis; NaN if the ray reaches none) and ``phi_end``
    (swept angle at which it crosses the horizon or reaches infinity).
    """

    def __init__(self, origin, directions, hole, r_s):
        self.origin = np.asarray(origin, dtype=np.float64).reshape(3)
        self.hole = np.asarray(hole, dtype=np.float64).reshape(3)
        self.r_s = float(r_s)
        rel = (self.origin - self.hole) / self.r_s
        self.r_obs = static_observer_radius(np.linalg.norm(rel))
        if self.r_obs > _R_OBS_MAX:
            raise ValueError(f"the camera is {self.r_obs:.3g} r_s from the hole; above {_R_OBS_MAX:.0e} r_s "
                             "lutgen's orbit roots lose their precision (use a larger r_s for a flat-space limit)")
        self.e1 = rel / self.r_obs
        self.uo = 1.0 / self.r_obs
        self.xi, cos_xi, sin_xi, self.e2 = ray_planes(directions, self.e1)
        self.normal = np.cross(self.e1, self.e2)
        k = np.sqrt(1.0 - self.uo)
        self.b = np.maximum(sin_xi / (self.uo * k), _B_MIN)
        self.inward = cos_xi < 0.0
        orb = _orb.orbit_from_b(self.b)
        self.orbit = orb
        self.turning = np.asarray(orb.real, dtype=bool)
        n = len(self.xi)
        self.amp = np.empty(n)   # e2 - e1 (turning) or A (plunging)
        self.mk = np.empty(n)    # elliptic parameter k^2
        self.c = np.empty(n)     # dw / dPhi
        t, p = self.turning, ~self.turning
        e31 = orb.e3[t] - orb.e1[t]
        self.amp[t] = orb.e2[t] - orb.e1[t]
        self.mk[t] = self.amp[t] / e31
        self.c[t] = 0.5 * np.sqrt(e31)
        me1 = orb.m[p] - orb.e1[p]
        A = np.sqrt(me1 ** 2 + orb.n[p] ** 2)
        self.amp[p] = A
        self.mk[p] = 1.0 - orb.n[p] ** 2 / (2.0 * A * (A + me1))
        self.c[p] = np.sqrt(A)
        self.e1r = orb.e1  # the orbit's negative root (not the unit vector e1)
        self.f_obs = _orb.sweep(orb, np.full(n, self.uo))
        self.w0 = self.c * self.f_obs
        self.s = np.where(self.inward, 1.0, -1.0)
        # an observer inside the photon sphere: its turning rays are on the inner branch u >= e3, from the
        # apoapsis u = e3 (w = 0): u = (e3 - e2 sn^2(w)) / cn^2(w), w = c G, G the angle swept from the
        # apoapsis (lutgen.rays._sweep_inner), c = sqrt(e3 - e1)/2, the same k^2
        self.inner = self.turning & (self.uo >= _orb.U_PHOTON)
        self.g_obs = np.full(n, np.nan)
        if self.inner.any():
            i = self.inner
            oi = orb.subset(i)
            p_uo = self.uo * self.uo * (1.0 - self.uo) * (cos_xi[i] / sin_xi[i]) ** 2  # P(uo), no cancellation
            gap = p_uo / ((self.uo - oi.e1) * (self.uo - oi.e2))
            self.g_obs[i] = _sweep_inner(oi, np.full(int(i.sum()), self.uo), gap)
            self.w0[i] = self.c[i] * self.g_obs[i]
        with np.errstate(invalid="ignore"):
            f_peri = _orb.sweep_to_turning_point(orb)
        self.f_peri = f_peri
        self.phi_peri = np.where(self.turning & self.inward, f_peri - self.f_obs, np.nan)
        f0 = _orb.sweep(orb, np.zeros(n))
        f1 = np.full(n, np.nan)
        if p.any():
            f1[p] = _orb.sweep(orb.subset(p), np.ones(int(p.sum())))
        self.phi_end = np.where(~self.inward, self.f_obs - f0,
                                np.where(self.turning, 2.0 * f_peri - self.f_obs - f0, f1 - self.f_obs))
        if self.inner.any():  # to the horizon: out to the apoapsis and back, or straight in
            i = self.inner
            g1 = _sweep_inner(orb.subset(i), np.ones(int(i.sum())))
            self.phi_end[i] = np.where(self.inward[i], g1 - self.g_obs[i], g1 + self.g_obs[i])
            self.phi_peri[i] = np.nan

    def __len__(self):
        return len(self.b)

    @property
    def falls_in(self) -> np.ndarray:
        """Rays that cross the horizon (inward and b < b_crit; inside the photon sphere also every ray with
        b > b_crit)."""
        return (self.inward & ~self.turning) | self.inner

    def u(self, idx, phi):
        """u = r_s/r and du/dPhi of rays ``idx`` at swept angles ``phi`` (arrays of one shape)."""
        w = self.w0[idx] + self.s[idx] * self.c[idx] * phi
        sn, cn, dn, _ = ellipj(w, self.mk[idx])
        amp = self.amp[idx]
        turn = self.turning[idx]
        dw = self.s[idx] * self.c[idx]
        with np.errstate(divide="ignore", invalid="ignore"):
            one_p = 1.0 + cn
            u = self.e1r[idx] + amp * np.where(turn, sn * sn, (1.0 - cn) / one_p)
            du = dw * amp * 2.0 * sn * dn * np.where(turn, cn, 1.0 / (one_p * one_p))
            inner = self.inner[idx]
            if inner.any():
                o = self.orbit
                e2, e3 = o.e2[idx][inner], o.e3[idx][inner]
                s_, c_, d_ = sn[inner], cn[inner], dn[inner]
                u[inner] = (e3 - e2 * s_ * s_) / (c_ * c_)
                du[inner] = dw[inner] * 2.0 * s_ * d_ * (e3 - e2) / (c_ * c_ * c_)
        return u, du

    def shell_intervals(self, r_lo: float, r_hi: float, pad: float = 1e-9) -> np.ndarray:
        """(M, 2, 2): for each ray its inbound and outbound swept-angle intervals [Phi_0, Phi_1] (rad) in
        which r_lo <= r <= r_hi (units of r_s; r_hi may be inf) and r > 1 (outside the horizon); NaN rows
        where a leg does not enter the shell. Intervals are widened by ``pad`` rad."""
        n = len(self)
        out = np.full((n, 2, 2), np.nan)
        u_a = 0.0 if not np.isfinite(r_hi) else 1.0 / r_hi
        u_b = 1.0 if r_lo <= 1.0 else 1.0 / r_lo
        if u_a >= u_b:
            return out
        orb, fo = self.orbit, self.f_obs
        e2 = np.where(self.turning, orb.e2, np.inf)
        uo = self.uo

        def F(u):
            return _orb.sweep(orb, u)

        with np.errstate(invalid="ignore"):
            # inbound leg (rays leaving towards the hole): u from uo up to e2 (turning) or 1 (plunging)
            lo = np.maximum(uo, u_a)
            hi = np.minimum(np.minimum(e2, u_b), 1.0)
            ok = self.inward & (lo <= hi)
            lo_c, hi_c = np.where(ok, lo, uo), np.where(ok, hi, uo)
            a, b = F(lo_c) - fo, F(hi_c) - fo
            out[ok, 0, 0], out[ok, 0, 1] = a[ok], b[ok]
            # outbound leg after the periapsis: u from e2 down to 0
            lo2 = np.full(n, u_a)
            hi2 = np.minimum(e2, u_b)
            ok2 = self.inward & self.turning & (lo2 <= hi2)
            lo_c, hi_c = np.where(ok2, lo2, 0.5 * uo), np.where(ok2, hi2, 0.5 * uo)
            base = 2.0 * self.f_peri - fo
            a, b = base - F(hi_c), base - F(lo_c)
            out[ok2, 1, 0], out[ok2, 1, 1] = a[ok2], b[ok2]
            # rays leaving away from the hole: u from uo down to 0 (one leg)
            hi3 = np.minimum(uo, u_b)
            ok3 = ~self.inward & (u_a <= hi3)
            lo_c, hi_c = np.where(ok3, u_a, 0.5 * uo), np.where(ok3, hi3, 0.5 * uo)
            a, b = fo - F(hi_c), fo - F(lo_c)
            out[ok3, 0, 0], out[ok3, 0, 1] = a[ok3], b[ok3]
        if self.inner.any():  # inside the photon sphere: the turning rays' legs on the inner branch
            i = np.flatnonzero(self.inner)
            out[i] = np.nan
            oi = orb.subset(i)
            g_o = self.g_obs[i]
            e3 = oi.e3

            def G(u):
                return _sweep_inner(oi, u)

            with np.errstate(invalid="ignore"):
                inw = self.inward[i]
                # inward: u from uo up to 1; outward: from uo down to e3, then (after the apoapsis) up to 1
                lo, hi = np.maximum(np.where(inw, uo, e3), u_a), np.minimum(np.where(inw, 1.0, uo), u_b)
                ok = lo <= hi
                lo_c, hi_c = np.where(ok, lo, e3), np.where(ok, hi, e3)
                a = np.where(inw, G(lo_c) - g_o, g_o - G(hi_c))
                b = np.where(inw, G(hi_c) - g_o, g_o - G(lo_c))
                out[i[ok], 0, 0], out[i[ok], 0, 1] = a[ok], b[ok]
                lo2, hi2 = np.maximum(e3, u_a), np.minimum(1.0, u_b)
                ok2 = ~inw & (lo2 <= hi2)
                lo_c, hi_c = np.where(ok2, lo2, e3), np.where(ok2, hi2, e3)
                out[i[ok2], 1, 0], out[i[ok2], 1, 1] = (g_o + G(lo_c))[ok2], (g_o + G(hi_c))[ok2]
        out[..., 0] = np.maximum(out[..., 0] - pad, 0.0)
        out[..., 1] += pad
        return out

    def travel_time(self, idx, phi, u):
        """Light travel time (units of r_s/c) from the observer to the points at swept angle ``phi``
        (inverse radius ``u``) of rays ``idx``."""
        inner = self.inner[idx]
        if inner.any():
            out = np.empty(len(idx))
            i = idx[inner]
            oi = self.orbit.subset(i)
            t_o = _orb.travel_time_inner(oi, np.full(len(i), self.uo))
            t_u = _orb.travel_time_inner(oi, u[inner])
            after = ~self.inward[i] & (phi[inner] > self.g_obs[i])
            out[inner] = np.where(self.inward[i], t_u - t_o, np.where(after, t_o + t_u, t_o - t_u))
            rest = ~inner
            if rest.any():
                out[rest] = self.travel_time(idx[rest], phi[rest], u[rest])
            return out
        orb = self.orbit.subset(idx)
        after = self.turning[idx] & self.inward[idx] & (phi > self.phi_peri[idx])
        uo = np.full(len(idx), self.uo)
        u = np.where(self.turning[idx], np.minimum(u, np.where(self.turning[idx], orb.e2, 1.0)), u)
        out = _orb.travel_time(orb, uo, u)
        if after.any():
            oa = orb.subset(after)
            out[after] = _orb.travel_time(oa, uo[after], oa.e2) + _orb.travel_time(oa, u[after], oa.e2)
        return out

    def escape_directions(self) -> np.ndarray:
        """(M, 3) unit world directions in which the rays travel at infinity: cos(phi_end) e1 +
        sin(phi_end) e2, phi_end the total swept angle from the camera to u = 0 (the ray's asymptote is
        parallel to its position there); NaN rows for rays that fall in."""
        out = self.e2 * np.sin(self.phi_end)[:, None] + np.cos(self.phi_end)[:, None] * self.e1
        out[self.falls_in] = np.nan
        return out

    def points(self, idx, phi, u=None):
        """World positions (BU) of the rays ``idx`` at swept angles ``phi``."""
        if u is None:
            u, _ = self.u(idx, phi)
        r = self.r_s / u
        return self.hole + r[:, None] * (np.cos(phi)[:, None] * self.e1 + np.sin(phi)[:, None] * self.e2[idx])


# --------------------------------------------------------------------------------------------------
# Tracing
# --------------------------------------------------------------------------------------------------
def trace(scene: TriangleScene, camera: Camera, hole, r_s, *, beta=None, pair_chunk: int = 400_000) -> PixelBuffers:
    """Reference image: the first triangle hit by the exact null geodesic through each pixel centre.

    scene: world triangles (BU); camera: :class:`Camera` (at rest in its local static frame, or moving
    with ``beta`` (3,; units of c, world axes) there: see the module docstring); hole: (3,) BU; r_s:
    Schwarzschild radius in BU. Returns :class:`PixelBuffers` of shape (camera.height, camera.width);
    ``info`` holds counts (pairs, candidates, roots, seconds).
    """
    dirs = camera.pixel_directions()
    ray = np.all(np.isfinite(dirs), axis=2)
    if ray.all():
        out = trace_rays(scene, camera.position, dirs.reshape(-1, 3), hole, r_s, beta=beta, pair_chunk=pair_chunk)
        return out.reshape((camera.height, camera.width))
    # a fisheye's pixels outside its circle: no ray
    return trace_rays(scene, camera.position, dirs[ray], hole, r_s, beta=beta, pair_chunk=pair_chunk).scatter(ray)


def escape_directions(origin, directions, hole, r_s, beta=None) -> np.ndarray:
    """(M, 3) the unit world directions in which the null geodesics leaving the static observer at
    ``origin`` (BU) in the world ``directions`` (M, 3) travel at infinity (where they reach r = inf,
    u(Phi) = 0 on this module's closed-form curve: swept angle ``Rays.phi_end``, = xi in flat space),
    NaN rows for rays that fall into the hole (xi beyond the shadow's edge); objects are ignored. The
    lensed sky each direction sees. hole: (3,) BU; r_s: BU; ``beta`` (3,; units of c): the observer's
    velocity in its local static frame, whose ``directions`` they then are (taken back to the static
    frame first)."""
    return Rays(origin, _static_directions(directions, beta), hole, r_s).escape_directions()


def _static_directions(directions, beta):
    """The moving observer's ``directions`` (M, 3) taken back to its local static frame
    (observer_view.unaberrate); unchanged (the same array) without ``beta``."""
    return directions if beta is None else unaberrate(np.asarray(directions, dtype=np.float64).reshape(-1, 3), beta)


def image_pixels(points, camera: Camera, hole, r_s, order: int, beta=None) -> tuple[np.ndarray, np.ndarray]:
    """Where the image of ``order`` (1 or 2) of each world point (N, 3; BU) appears: continuous pixel
    coordinates (column, row) of ``camera`` (pixel centres at integer + 0.5, as :meth:`Camera.project`),
    moving with ``beta`` (3,; units of c) in its local static frame if given (the static observer's
    direction, aberrated exactly: observer_view.aberrate).

    The direction comes from the exact connecting geodesic (lutgen.connect, the closed-form
    emitter-observer solver), not from a LUT and not from this module's ray tracing, so it is an
    independent check of both (inside the photon sphere lutgen.connect polishes lutgen.rays' ray on
    the closed-form swept angle: exact to rounding there too). NaN where the point has no image of
    that order (inside the horizon, on the camera-hole axis, non-finite) or the image lies behind the
    camera. hole: (3,) BU; r_s: BU.
    """
    scene = Scene(camera.position, hole, r_s)
    plane = plane_coordinates(np.asarray(points, dtype=np.float64).reshape(-1, 3), scene)
    conn = connect(scene.r_obs, plane.r, plane.phi, order)
    direction = view_directions(conn.xi, plane.e2, scene.e1, order)
    if beta is not None:
        direction = aberrate(direction, beta)
    col, row, depth = camera.project(camera.position + direction)
    with np.errstate(invalid="ignore"):
        bad = plane.on_axis | ~(depth > 0)
    return np.where(bad, np.nan, col), np.where(bad, np.nan, row)


def _object_shells(V, tri_obj, n_obj):
    """Per object [R_lo, R_hi] (units of r_s) around the hole: R_lo is a lower bound of the distance
    of its triangles from the hole (nearest vertex minus longest edge / sqrt 3), R_hi the farthest
    vertex."""
    d = np.linalg.norm(V, axis=2)
    edge = np.max(np.linalg.norm(V - np.roll(V, 1, axis=1), axis=2), axis=1)
    lo_t = np.maximum(d.min(axis=1) - edge / np.sqrt(3.0), 0.0)
    hi_t = d.max(axis=1)
    lo = np.full(n_obj, np.inf)
    hi = np.full(n_obj, -np.inf)
    np.minimum.at(lo, tri_obj, lo_t)
    np.maximum.at(hi, tri_obj, hi_t)
    return lo, hi


def _triangle_azimuths(V, f1, f2):
    """Azimuth range [lo, hi] (rad, hi - lo < pi) of each triangle about the hole-camera axis, and
    a mask of triangles that surround the axis (seen by rays of every azimuth)."""
    q = np.stack([V @ f1, V @ f2], axis=-1)  # (T, 3, 2)
    a = np.arctan2(q[..., 1], q[..., 0])
    cr = [q[:, i, 0] * q[:, (i + 1) % 3, 1] - q[:, i, 1] * q[:, (i + 1) % 3, 0] for i in range(3)]
    cr = np.stack(cr, axis=1)  # orientation of (origin, q_i, q_i+1)
    scale = np.max(np.linalg.norm(q, axis=2), axis=1) ** 2
    tol = 1e-12 * scale
    surround = np.all(cr >= -tol[:, None], axis=1) | np.all(cr <= tol[:, None], axis=1)
    surround |= np.min(np.linalg.norm(q, axis=2), axis=1) <= 1e-9 * np.sqrt(scale)
    d1 = np.angle(np.exp(1j * (a[:, 1] - a[:, 0])))
    d2 = np.angle(np.exp(1j * (a[:, 2] - a[:, 0])))
    lo = a[:, 0] + np.minimum(0.0, np.minimum(d1, d2)) - _AZ_PAD
    hi = a[:, 0] + np.maximum(0.0, np.maximum(d1, d2)) + _AZ_PAD
    surround |= (hi - lo) >= np.pi
    return lo, hi, surround


def _pairs(order_beta, beta_sorted, lo, hi, surround, tri_ids, chunk):
    """Yield (ray, tri) index arrays of rays whose plane (line azimuth beta in [0, pi)) meets the
    triangles' azimuth ranges [lo, hi] (taken mod pi), in chunks of about ``chunk`` pairs."""
    n = len(beta_sorted)
    lo_m = np.mod(lo, np.pi)
    hi_m = lo_m + (hi - lo)
    # up to two index ranges per triangle: [lo_m, min(hi_m, pi)) and [0, hi_m - pi]
    s1 = np.searchsorted(beta_sorted, lo_m, side="left")
    e1 = np.searchsorted(beta_sorted, np.minimum(hi_m, np.pi), side="right")
    s2 = np.zeros_like(s1)
    e2 = np.where(hi_m > np.pi, np.searchsorted(beta_sorted, hi_m - np.pi, side="right"), 0)
    s1 = np.where(surround, 0, s1)
    e1 = np.where(surround, n, e1)
    e2 = np.where(surround, 0, e2)
    starts = np.concatenate([s1, s2])
    counts = np.maximum(np.concatenate([e1 - s1, e2 - s2]), 0)
    tris = np.concatenate([tri_ids, tri_ids])
    keep = counts > 0
    starts, counts, tris = starts[keep], counts[keep], tris[keep]
    if not len(counts):
        return
    cum = np.cumsum(counts)
    i0 = 0
    while i0 < len(counts):
        base = cum[i0 - 1] if i0 else 0
        i1 = int(np.searchsorted(cum, base + chunk, side="right"))
        i1 = max(i1, i0 + 1)
        c = counts[i0:i1]
        pos = group_offsets(c) + np.repeat(starts[i0:i1], c)
        yield order_beta[pos], np.repeat(tris[i0:i1], c)
        i0 = i1


def _segments(ct, st, X, Q1, Q2, ray, tri):
    """The cut of triangles ``tri`` by the planes of rays ``ray``: for the pairs that are cut,
    (keep mask, phi_a, width, mx, my, p): the sector [phi_a, phi_a + width] (phi_a in [0, 2 pi),
    width in [0, pi)) seen from the hole and the segment's line {x : mx x + my y = p} in the plane
    coordinates (e1, e2 of the ray; units of r_s).

    ct, st: per ray, cos and sin of the plane azimuth (e2 = ct f1 + st f2, normal = ct f2 - st f1);
    X, Q1, Q2: per triangle (T, 3), its corners' coordinates along e1, f1, f2 (relative to the hole)."""
    c = ct[ray][:, None]
    s_ = st[ray][:, None]
    q1, q2, x = Q1[tri], Q2[tri], X[tri]
    y = c * q1 + s_ * q2   # along the ray's e2
    s = c * q2 - s_ * q1   # signed distance from the ray's plane
    pos = s > 0.0
    c0 = pos[:, 0] != pos[:, 1]
    c1 = pos[:, 1] != pos[:, 2]
    c2 = pos[:, 2] != pos[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        def edge(i, j):
            t = s[:, i] / (s[:, i] - s[:, j])
            return x[:, i] + t * (x[:, j] - x[:, i]), y[:, i] + t * (y[:, j] - y[:, i])

        x01, y01 = edge(0, 1)
        x12, y12 = edge(1, 2)
        x20, y20 = edge(2, 0)
        xp, yp = np.where(c0, x01, x12), np.where(c0, y01, y12)
        xq, yq = np.where(c2, x20, x12), np.where(c2, y20, y12)
        dx, dy = xq - xp, yq - yp
        ln = np.hypot(dx, dy)
        mx, my = dy / ln, -dx / ln
        p = mx * xp + my * yp
    flip = p < 0
    mx, my, p = np.where(flip, -mx, mx), np.where(flip, -my, my), np.abs(p)
    ap = np.arctan2(yp, xp)
    aq = np.arctan2(yq, xq)
    delta = np.mod(aq - ap + np.pi, TWO_PI) - np.pi
    phi_a = np.mod(np.where(delta >= 0, ap, aq), TWO_PI)
    width = np.abs(delta)
    rp, rq = np.hypot(xp, yp), np.hypot(xq, yq)
    cut = c0 | c1
    with np.errstate(invalid="ignore"):
        # the segment's line passes (to _RADIAL_TOL relative) through the hole: e.g. every cut of a
        # planar mesh whose plane contains the hole (an equatorial disc) is radial in every ray plane
        radial = cut & ~(p > _RADIAL_TOL * np.maximum(rp, rq))
        keep = cut & ~radial & (ln > 0)
    return keep, phi_a, width, mx, my, p, radial, np.mod(ap, TWO_PI), np.mod(aq, TWO_PI), rp, rq


def _radial_roots(rays: Rays, shells, ray, pair_ids, width, ap, aq, rp, rq):
    """Hits of radial segments (lines through the hole): a segment on one side of the hole, at polar
    angle ap ~ aq, is met where Phi = ap + 2 pi k with r(Phi) between rp and rq; one through the hole
    (width ~ pi) is two such pieces, [0, rp] at ap and [0, rq] at aq. Returns (pair index, Phi)."""
    through = width > 0.5 * np.pi
    ang = np.concatenate([ap, aq[through]])
    lo = np.concatenate([np.where(through, 0.0, np.minimum(rp, rq)), np.zeros(int(through.sum()))])
    hi = np.concatenate([np.where(through, rp, np.maximum(rp, rq)), rq[through]])
    pid = np.concatenate([pair_ids, pair_ids[through]])
    sh = np.concatenate([shells, shells[through]])
    out_p, out_x = [], []
    for leg in (0, 1):
        s0, s1 = sh[:, leg, 0], sh[:, leg, 1]
        with np.errstate(invalid="ignore"):
            kmin = np.ceil((s0 - ang) / TWO_PI)
            kmax = np.floor((s1 - ang) / TWO_PI)
        idx, k = _expand_turns(np.isfinite(s0), kmin, kmax)
        if not idx.size:
            continue
        x = ang[idx] + TWO_PI * k
        u, _ = rays.u(ray[pid[idx]], x)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = 1.0 / u
        ok = (u > 0) & (r >= lo[idx] * (1 - 1e-12)) & (r <= hi[idx] * (1 + 1e-12))
        out_p.append(pid[idx[ok]])
        out_x.append(x[ok])
    if not out_p:
        return np.zeros(0, np.int64), np.zeros(0)
    return np.concatenate(out_p), np.concatenate(out_x)


def _expand_turns(ok, kmin, kmax):
    """Every (row, turn) with kmin <= turn <= kmax for the rows where ``ok``: (row indices, turns k as
    floats), rows repeated once per turn (NaN or empty ranges give none)."""
    with np.errstate(invalid="ignore"):
        nk = np.where(ok, kmax - kmin + 1, 0)
    nk = np.maximum(np.nan_to_num(nk, nan=0.0), 0).astype(np.int64)
    sel = np.flatnonzero(nk)
    c = nk[sel]
    idx = np.repeat(sel, c)
    k = np.repeat(kmin[sel], c) + group_offsets(c)
    return idx, k


def _candidates(shells, phi_a, width, pair_ids):
    """Swept-angle intervals (pair index, a, b): the sectors shifted by 2 pi k and clipped to the
    rays' shell intervals ``shells`` (P, 2, 2)."""
    out_p, out_a, out_b = [], [], []
    for leg in (0, 1):
        s0, s1 = shells[:, leg, 0], shells[:, leg, 1]
        ok = np.isfinite(s0)
        with np.errstate(invalid="ignore"):
            kmin = np.ceil((s0 - phi_a - width) / TWO_PI)
            kmax = np.floor((s1 - phi_a) / TWO_PI)
        idx, k = _expand_turns(ok, kmin, kmax)
        if not idx.size:
            continue
        a = np.maximum(phi_a[idx] + TWO_PI * k, s0[idx])
        b = np.minimum(phi_a[idx] + width[idx] + TWO_PI * k, s1[idx])
        good = a <= b
        out_p.append(pair_ids[idx[good]])
        out_a.append(a[good])
        out_b.append(b[good])
    if not out_p:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
    return np.concatenate(out_p), np.concatenate(out_a), np.concatenate(out_b)


def _g(rays: Rays, ray, phi, mx, my, p):
    """g = u_ray - u_line and dg/dPhi (units of 1/r_s)."""
    u, du = rays.u(ray, phi)
    c, s = np.cos(phi), np.sin(phi)
    return u - (mx * c + my * s) / p, du - (my * c - mx * s) / p


def _roots(rays: Rays, ray, a, b, mx, my, p, max_depth=48, newton_iter=60):
    """Roots of g on the intervals [a, b] (each shorter than pi): returns (candidate index, Phi) of
    every root (all of them; there are at most two per interval)."""
    n = len(a)
    cand = np.arange(n)
    ga, gpa = _g(rays, ray, a, mx, my, p)
    gb, gpb = _g(rays, ray, b, mx, my, p)
    iso_c, iso_a, iso_b, iso_ga, iso_gb = [], [], [], [], []
    for _ in range(max_depth):
        if not cand.size:
            break
        with np.errstate(invalid="ignore"):
            bracket = (ga <= 0) & (gb >= 0) | (ga >= 0) & (gb <= 0)
            both_pos = (ga > 0) & (gb > 0)
            w = b - a
            cw, sw = np.cos(w), np.sin(w)
            excluded = both_pos & ((ga * cw + gpa * sw > 0) | (gb * cw - gpb * sw > 0))
        iso_c.append(cand[bracket])
        iso_a.append(a[bracket])
        iso_b.append(b[bracket])
        iso_ga.append(ga[bracket])
        iso_gb.append(gb[bracket])
        split = both_pos & ~excluded & ~bracket & (w > 1e-13)
        if not split.any():
            break
        cand, a, b = cand[split], a[split], b[split]
        ga, gpa, gb, gpb = ga[split], gpa[split], gb[split], gpb[split]
        m = 0.5 * (a + b)
        gm, gpm = _g(rays, ray[cand], m, mx[cand], my[cand], p[cand])
        cand = np.concatenate([cand, cand])
        a, b = np.concatenate([a, m]), np.concatenate([m, b])
        ga, gb = np.concatenate([ga, gm]), np.concatenate([gm, gb])
        gpa, gpb = np.concatenate([gpa, gpm]), np.concatenate([gpm, gpb])
    c = np.concatenate(iso_c) if iso_c else np.zeros(0, np.int64)
    if not c.size:
        return c, np.zeros(0)
    lo, hi = np.concatenate(iso_a), np.concatenate(iso_b)
    glo, ghi = np.concatenate(iso_ga), np.concatenate(iso_gb)
    # orient the brackets so that g(lo) <= 0 <= g(hi)
    swap = glo > 0
    lo, hi = np.where(swap, hi, lo), np.where(swap, lo, hi)
    glo, ghi = np.where(swap, ghi, glo), np.where(swap, glo, ghi)
    x = np.where(glo == 0, lo, np.where(ghi == 0, hi, lo - glo * (hi - lo) / np.where(ghi != glo, ghi - glo, 1.0)))
    active = np.flatnonzero((glo != 0) & (ghi != 0))
    for _ in range(newton_iter):
        if not active.size:
            break
        k = active
        g, gp = _g(rays, ray[c[k]], x[k], mx[c[k]], my[c[k]], p[c[k]])
        neg = g < 0
        lo[k] = np.where(neg, x[k], lo[k])
        hi[k] = np.where(neg, hi[k], x[k])
        with np.errstate(invalid="ignore", divide="ignore"):
            xn = x[k] - g / gp
        inside = np.isfinite(xn) & (xn >= np.minimum(lo[k], hi[k])) & (xn <= np.maximum(lo[k], hi[k]))
        xn = np.where(inside, xn, 0.5 * (lo[k] + hi[k]))
        exact = g == 0
        step = np.where(exact, 0.0, np.abs(xn - x[k]))
        x[k] = np.where(exact, x[k], xn)
        tol = 1e-15 * np.maximum(1.0, np.abs(x[k]))
        done = exact | (step <= tol) | (np.abs(hi[k] - lo[k]) <= 2 * tol)
        active = k[~done]
    return c, x


def trace_rays(scene: TriangleScene, origin, directions, hole, r_s, *, beta=None,
               pair_chunk: int = 400_000) -> PixelBuffers:
    """First hits of the exact null geodesics leaving the observer at ``origin`` (BU) in the world
    ``directions`` (M, 3), for a hole at ``hole`` (BU) with Schwarzschild radius ``r_s`` (BU); the
    observer is static, or moving with ``beta`` (3,; units of c, world axes) in its local static
    frame, whose directions they then are. Returns flat :class:`PixelBuffers` of shape (M,). See the
    module docstring for the method."""
    t0 = time.perf_counter()
    rays = Rays(origin, _static_directions(directions, beta), hole, r_s)
    m = len(rays)
    out = PixelBuffers.empty((m,))
    info = dict(pairs=0, candidates=0, roots=0)
    V = (scene.positions[scene.tris] - rays.hole) / rays.r_s  # (T, 3, 3) r_s, relative to the hole
    best_phi = np.full(m, np.inf)
    best_tri = np.full(m, -1, np.int64)
    if len(V):
        f1 = any_perpendicular(rays.e1)
        f2 = np.cross(rays.e1, f1)
        ct, st = rays.e2 @ f1, rays.e2 @ f2
        plane_azimuth = np.mod(np.arctan2(st, ct), np.pi)
        X, Q1, Q2 = V @ rays.e1, V @ f1, V @ f2
        az_lo, az_hi, surround = _triangle_azimuths(V, f1, f2)
        objs = np.unique(scene.object_id)
        lo_r, hi_r = _object_shells(V, np.searchsorted(objs, scene.object_id), len(objs))
        for oi, obj in enumerate(objs):
            shells = rays.shell_intervals(lo_r[oi], hi_r[oi])
            active = np.flatnonzero(np.isfinite(shells[:, :, 0]).any(axis=1))
            if not active.size:
                continue
            order_b = active[np.argsort(plane_azimuth[active], kind="stable")]
            beta_sorted = plane_azimuth[order_b]
            tri_ids = np.flatnonzero(scene.object_id == obj)
            for ray, tri in _pairs(order_b, beta_sorted, az_lo[tri_ids], az_hi[tri_ids], surround[tri_ids],
                                   tri_ids, pair_chunk):
                info["pairs"] += len(ray)
                keep, phi_a, width, mx, my, p, radial, ap, aq, rp, rq = _segments(ct, st, X, Q1, Q2, ray, tri)
                sel = np.flatnonzero(keep)
                cid, a, b = _candidates(shells[ray[sel]], phi_a[sel], width[sel], sel)
                info["candidates"] += len(cid)
                ci, x = _roots(rays, ray[cid], a, b, mx[cid], my[cid], p[cid])
                hit_pair = cid[ci]
                rad = np.flatnonzero(radial)
                if rad.size:
                    info["radial_segments"] = info.get("radial_segments", 0) + len(rad)
                    rp_, rx = _radial_roots(rays, shells[ray[rad]], ray, rad, width[rad], ap[rad], aq[rad],
                                            rp[rad], rq[rad])
                    hit_pair, x = np.concatenate([hit_pair, rp_]), np.concatenate([x, rx])
                info["roots"] += len(hit_pair)
                if not hit_pair.size:
                    continue
                r_hit, t_hit = ray[hit_pair], tri[hit_pair]
                # keep the smallest swept angle per ray
                o = np.lexsort((x, r_hit))
                r_hit, t_hit, x = r_hit[o], t_hit[o], x[o]
                first = np.ones(len(o), bool)
                first[1:] = r_hit[1:] != r_hit[:-1]
                r_hit, t_hit, x = r_hit[first], t_hit[first], x[first]
                better = x < best_phi[r_hit]
                best_phi[r_hit[better]] = x[better]
                best_tri[r_hit[better]] = t_hit[better]
    hit = best_tri >= 0
    idx = np.flatnonzero(hit)
    out.hit[:] = hit
    out.fell[:] = ~hit & rays.falls_in
    if m:
        out.sky[:] = np.where(hit[:, None], np.nan, rays.escape_directions())
        arriving = -view_directions(rays.xi, rays.e2, rays.e1, 1)  # photons' direction of travel (static frame)
        sky = np.flatnonzero(np.isfinite(out.sky[:, 0]))
        out.g[sky] = frequency_ratio(np.full(len(sky), np.inf), rays.r_obs, arriving[sky], beta)
    if idx.size:
        phi = best_phi[idx]
        tri = best_tri[idx]
        u, _ = rays.u(idx, phi)
        pts = rays.points(idx, phi, u)
        bary = _barycentric(pts, scene.positions[scene.tris[tri]])
        out.phi[idx] = phi
        out.point[idx] = pts
        out.face[idx] = tri
        out.object_id[idx] = scene.object_id[tri]
        out.bary[idx] = bary
        if scene.corner_uv is not None:
            out.uv[idx] = np.einsum("pk,pkx->px", bary, scene.corner_uv[tri])
        out.order[idx] = np.maximum(1, np.ceil(phi / np.pi - 1e-15)).astype(np.int64)
        out.light_time[idx] = rays.travel_time(idx, phi, u) * rays.r_s
        out.g[idx] = frequency_ratio(1.0 / u, rays.r_obs, arriving[idx], beta)
    info["seconds"] = time.perf_counter() - t0
    info["higher_order_pixels"] = int((out.order >= 3).sum())
    out.info = info
    return out


def _barycentric(points, tri_pts):
    """Barycentric coordinates (P, 3) of ``points`` (P, 3) projected onto the triangles (P, 3, 3),
    clipped to [0, 1] and renormalised (the points lie on the triangles up to rounding)."""
    a, b, c = tri_pts[:, 0], tri_pts[:, 1], tri_pts[:, 2]
    v0, v1, v2 = b - a, c - a, points - a
    d00 = np.einsum("pi,pi->p", v0, v0)
    d01 = np.einsum("pi,pi->p", v0, v1)
    d11 = np.einsum("pi,pi->p", v1, v1)
    d20 = np.einsum("pi,pi->p", v2, v0)
    d21 = np.einsum("pi,pi->p", v2, v1)
    den = d00 * d11 - d01 * d01
    with np.errstate(invalid="ignore", divide="ignore"):
        v = (d11 * d20 - d01 * d21) / den
        w = (d00 * d21 - d01 * d20) / den
    bary = np.stack([1.0 - v - w, v, w], axis=1)
    bary = np.clip(bary, 0.0, 1.0)
    return bary / np.maximum(bary.sum(axis=1, keepdims=True), 1e-300)
