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

from .mapping import Mapper, Scene, leaving_direction, leaving_in_plane  # noqa: F401 (the tangents' frame)


def irradiance(points, normals, light, hole, r_s, lut, intensity=1.0, orders=(1, 2)):
    """Irradiance at ``points`` (N, 3; BU) with unit ``normals`` (N, 3) from a point light at ``light``
    (3,; BU). ``lut`` must be built for r_obs = |light - hole| / r_s. Returns (N,) float64 with 0 where a
    point receives no light (or lies outside the LUT's range), and a dict of per-order arrays."""
    scene = Scene(camera=light, hole=hole, r_s=r_s)
    try:
        light_map = Mapper(scene, lut)
    except ValueError:
        raise ValueError(f"the light's LUT was built for r = {lut.r_obs:.9g} r_s, the light is at "
                         f"{scene.r_obs:.9g} r_s") from None
    normals = np.asarray(normals, dtype=np.float64)
    total = np.zeros(len(normals))
    parts = {}
    for order, (d, dt) in light_map.leaving(points, orders).items():
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
    camera's radius): mapping.Mapper.leaving. NaN where the point has no ray of that order."""
    return Mapper(scene, lut).leaving(points, orders)
