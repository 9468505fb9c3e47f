"""GR illumination by a point light along both connecting geodesics (seed 000, eqs. 20-21).

For a surface point p with unit normal n and a point light at L (both world space, BU), the light
reaches p along the order-1 and order-2 null geodesics from L. With the LUT of an observer at the
light's radius (the light plays the observer's role), each ray's tangent at p, (ux, uy) in the plane
(e1 = light direction from the hole, e2), gives the direction back towards the light,
d = -(u^(r) e_r + u^(phi) e_phi) / |.| in p's static orthonormal frame (the local-frame version of
eq. 20, i.e. the dot product with respect to the Schwarzschild metric), and

    I = I0 * sum over orders of max(0, n . d) / (c dt)^2,    c dt in BU,

with the light travel time dt from the LUT (r_s/c) times r_s (BU). Units: I0 in (BU^2 x the unit of
the result); the irradiance is in I0 / BU^2.
"""
from __future__ import annotations

import numpy as np

from .mapping import R_OBS_TOLERANCE, Scene, plane_coordinates, row_norm


def irradiance(points, normals, light, hole, r_s, lut, intensity=1.0, orders=(1, 2)):
    """Irradiance at ``points`` (N, 3; BU) with unit ``normals`` (N, 3) from a point light at ``light``
    (3,; BU). ``lut`` must be built for r_obs = |light - hole| / r_s. Returns (N,) float64 with 0 where a
    point receives no light (or lies outside the LUT's range), and a dict of per-order arrays."""
    scene = Scene(camera=light, hole=hole, r_s=r_s)
    if abs(lut.r_obs / scene.r_obs - 1.0) > R_OBS_TOLERANCE:
        raise ValueError(f"the light's LUT was built for r = {lut.r_obs:.9g} r_s, the light is at "
                         f"{scene.r_obs:.9g} r_s")
    normals = np.asarray(normals, dtype=np.float64)
    total = np.zeros(len(normals))
    parts = {}
    for order, (d, dt) in towards_observer(points, scene, lut, orders).items():
        with np.errstate(invalid="ignore", divide="ignore"):
            dist = dt * r_s
            part = intensity * np.maximum(0.0, np.einsum("ij,ij->i", normals, d)) / dist**2
        part = np.nan_to_num(part, nan=0.0, posinf=0.0)
        parts[order] = part
        total += part
    return total, parts


def towards_observer(points, scene: Scene, lut, orders=(1, 2)) -> dict:
    """For each order, (d, dt): the unit direction d (N, 3; world axes) in which the connecting ray
    leaves (or, for a light, reaches) each of ``points`` (N, 3; BU) towards ``scene.camera``, measured
    in the point's static frame, and the travel time dt (N,; r_s / c) from the LUT (built for the
    camera's radius). A surface with unit normal n at the point faces the observer along that ray
    when n . d > 0. NaN where the point has no ray of that order (outside the LUT, on the axis)."""
    plane = plane_coordinates(points, scene)
    looks = lut.lookup_orders(plane.r, plane.phi, tuple(orders), quantities=("dt", "ux", "uy"))
    return {order: (leaving_direction(plane, scene, looks[order].ux, looks[order].uy), looks[order].dt)
            for order in orders}


def leaving_direction(plane, scene: Scene, ux, uy) -> np.ndarray:
    """(N, 3) unit direction, in the static frame of points with plane coordinates ``plane``
    (mapping.PlaneCoordinates), opposite to the tangent (ux, uy) of their connecting rays from the
    LUT (components along e1 and e2 of the plane, see lutgen): the way the light leaves the point
    towards the observer. NaN where the ray is undefined."""
    e1 = scene.e1
    c, s, f_r, r_uphi = _static_frame(plane, ux, uy)
    e_r = c[:, None] * e1 + s[:, None] * plane.e2
    e_phi = -s[:, None] * e1 + c[:, None] * plane.e2
    with np.errstate(invalid="ignore", divide="ignore"):
        d = -(f_r[:, None] * e_r + r_uphi[:, None] * e_phi)
        d /= row_norm(d)[:, None]
    return d


def leaving_in_plane(plane, ux, uy):
    """(a, b), each (N,): :func:`leaving_direction` = (a e1 + b e2) / |(a, b)|, without the
    normalisation (a positive factor per point: enough for the sign of n . d). NaN where the ray is
    undefined."""
    c, s, f_r, r_uphi = _static_frame(plane, ux, uy)
    with np.errstate(invalid="ignore"):
        return -(f_r * c - r_uphi * s), -(f_r * s + r_uphi * c)


def _static_frame(plane, ux, uy):
    """cos phi, sin phi and the ray's tangent in the points' static frame: its components along e_r
    and e_phi (f_r, r_uphi), from the LUT's (ux, uy) (along e1 and e2)."""
    c, s = np.cos(plane.phi), np.sin(plane.phi)
    u_r = ux * c + uy * s  # dr/dlambda
    r_uphi = -ux * s + uy * c  # r dphi/dlambda
    with np.errstate(invalid="ignore", divide="ignore"):
        f_r = u_r / np.sqrt(1.0 - 1.0 / plane.r)  # local static frame components
    return c, s, f_r, r_uphi
