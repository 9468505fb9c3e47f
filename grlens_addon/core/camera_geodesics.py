"""Cameras on timelike geodesics, as functions of Schwarzschild coordinate time t (the clock of a
distant static observer, which grlens' frames measure when the speed of light is finite): a radial
free fall and a circular orbit, positions and coordinate velocities.

Units: lengths in r_s (Schwarzschild radii), c = 1, so times are in r_s/c and velocities dr/dt in
units of c; G M = r_s/2 (M = 1/2 in these units). World positions are in Blender units (BU) where a
function takes ``hole`` and ``r_s`` (BU); velocities stay in units of c (dx/dt with x in BU and t in
BU/c: multiply by the speed of light in BU per frame for BU per frame). f = 1 - r_s/r.

* Radial free fall from rest at r0 (energy per unit mass E = sqrt(1 - 1/r0)), in the cycloid
  parameter eta (MTW eq. 31.10, with 2 M = 1): r = r0 / (1 + x^2), x = tan(eta / 2) in [0, a),
  a = sqrt(r0 - 1), and

      t = ln((a + x) / (a - x)) + a (eta + (r0 / 2) (eta + sin eta)),   t = 0 at rest;

  dr/dt = -f sqrt(1/r - 1/r0) / E. The fall is time-symmetric about the moment of rest (before it,
  the body rises). t -> infinity at the horizon (x -> a), where r - 1 shrinks like exp(-t): a fall
  seen in coordinate time slows and freezes there (r reaches 1 to rounding some 37 r_s/c after it
  passes 2 r_s). It is solved in w = a - x, which keeps r - 1 accurate until then.
* Radial free fall from rest at infinity (E = 1): with y = sqrt(r),
  t = F(r_start) - F(r), F(r) = (2/3) y^3 + 2 y + ln((y - 1) / (y + 1)), and dr/dt = -f sqrt(1/r).
* Circular orbit at r > 1.5 (the photon sphere): angular velocity d(phi)/dt = sqrt(M / r^3)
  = 1 / sqrt(2 r^3); stable only from the innermost stable circular orbit, r >= 3 (``R_ISCO``).
  The local static observer sees it move at 1 / sqrt(2 (r - 1)) c.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .thin_disc import R_ISCO, circular_orbit

_BISECTIONS = 110  # halvings of a bracket that is at most ~(t + 760) wide in ln w: below 1e-16 relative


def radial_fall(t, r_start, r_release=np.inf):
    """(r, dr/dt), each shaped like ``t``: the radius (r_s) and coordinate velocity (units of c) of a body
    falling radially, ``t`` (r_s/c) after it was at ``r_start`` (r_s, > 1), having been at rest at
    ``r_release`` (r_s, >= r_start; np.inf: at rest at infinity, i.e. falling at the escape speed).
    With a finite r_release the motion before the moment of rest is the time-reversed fall (rising).
    Raises ValueError for r_start <= 1 or r_release < r_start."""
    t = np.asarray(t, dtype=np.float64)
    r_start, r0 = float(r_start), float(r_release)
    if not (np.isfinite(r_start) and r_start > 1.0):
        raise ValueError(f"a fall must start outside the horizon (r > 1 r_s), got r = {r_start:.6g} r_s")
    if not r0 >= r_start:
        raise ValueError(f"the radius of rest ({r0:.6g} r_s) must be at least the starting radius "
                         f"({r_start:.6g} r_s)")
    if np.isinf(r0):
        return _fall_from_infinity(t, r_start)
    a = np.sqrt(r0 - 1.0)
    w_start = a - np.sqrt(max(r0 / r_start - 1.0, 0.0))
    since_rest = _fall_time(np.asarray(w_start), a, r0) + t
    w = _solve_w(np.abs(since_rest), a, r0)
    x = a - w
    r = 1.0 + w * (2.0 * a - w) / (1.0 + x * x)
    f = 1.0 - 1.0 / r
    with np.errstate(invalid="ignore"):
        speed = f * np.sqrt(np.maximum(1.0 / r - 1.0 / r0, 0.0)) / np.sqrt(1.0 - 1.0 / r0)
    return r, np.where(since_rest >= 0, -speed, speed)


def _fall_time(w, a, r0):
    """Coordinate time (r_s/c) since rest at r0 = 1 + a^2 of the fall at x = a - w (w in (0, a])."""
    x = a - w
    eta = 2.0 * np.arctan(x)
    with np.errstate(divide="ignore", over="ignore"):
        return np.log((2.0 * a - w) / w) + a * (eta + 0.5 * r0 * (eta + 2.0 * x / (1.0 + x * x)))


def _solve_w(t, a, r0):
    """w = a - tan(eta/2) at which the fall from rest at r0 has taken the time ``t`` >= 0 (bisection in
    ln w: the time decreases with w, from infinity at w = 0 to 0 at w = a)."""
    hi = np.full(t.shape, np.log(a))
    lo = np.log(2.0 * a) - t - 1.0  # there the time exceeds t (its log term alone does)
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        later = _fall_time(np.exp(mid), a, r0) > t
        lo = np.where(later, mid, lo)
        hi = np.where(later, hi, mid)
    return np.exp(0.5 * (lo + hi))


def _f_infinity(v):
    """F(r) = (2/3) y^3 + 2 y + ln((y - 1)/(y + 1)) with y = sqrt(r) = 1 + e^v."""
    y = 1.0 + np.exp(v)
    return (2.0 / 3.0) * y**3 + 2.0 * y + v - np.log(y + 1.0)


def _fall_from_infinity(t, r_start):
    """radial_fall with the body at rest at infinity."""
    target = float(_f_infinity(np.log(np.sqrt(r_start) - 1.0))) - t
    lo = np.minimum(target, 0.0) - 10.0  # F <= v + 8.6 for y <= 2
    hi = np.maximum(np.log(np.abs(target) + 1.0), 1.0) + 1.0
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        above = _f_infinity(mid) > target
        hi = np.where(above, mid, hi)
        lo = np.where(above, lo, mid)
    e = np.exp(0.5 * (lo + hi))
    r = 1.0 + e * (2.0 + e)  # (1 + e)^2, keeping r - 1 exact
    return r, -(1.0 - 1.0 / r) * np.sqrt(1.0 / r)


@dataclass
class Path:
    """A camera's path sampled at coordinate times: ``position`` (N, 3) BU, ``velocity`` (N, 3) the
    coordinate velocity dx/dt in units of c, ``r`` (N,) r_s; ``stable``: False for a circular orbit
    inside the innermost stable one (R_ISCO = 3 r_s), which a small push turns into a fall or an
    escape."""

    position: np.ndarray
    velocity: np.ndarray
    r: np.ndarray
    stable: bool = True


def fall_path(t, start, hole, r_s, r_release=np.inf) -> Path:
    """The radial free fall (:func:`radial_fall`) of a camera that is at ``start`` (3,; BU) at t = 0, on
    the line from ``hole`` (3,; BU) through it; ``t`` (N,) r_s/c; ``r_s`` BU; ``r_release`` (r_s): the
    radius where it was at rest (np.inf: at rest at infinity)."""
    hole = np.asarray(hole, dtype=np.float64).reshape(3)
    rel = np.asarray(start, dtype=np.float64).reshape(3) - hole
    n = rel / np.linalg.norm(rel)
    r, dr = radial_fall(np.atleast_1d(t), np.linalg.norm(rel) / float(r_s), r_release)
    return Path(hole + (float(r_s) * r)[:, None] * n, dr[:, None] * n, r)


def orbit_path(t, start, hole, r_s, axis, prograde: bool = True) -> Path:
    """The circular geodesic through ``start`` (3,; BU) about ``hole`` (3,; BU) in the plane
    perpendicular to ``axis`` (3,; its part perpendicular to start - hole; counter-clockwise about it
    when ``prograde``), at the camera's radius r = |start - hole| / r_s; ``t`` (N,) r_s/c after the
    camera was at ``start``. Angular velocity 1 / sqrt(2 r^3) (c/r_s). Raises ValueError at or
    inside the photon sphere (r <= 1.5 r_s: no circular timelike orbit) and for an axis along the
    radius; ``stable`` is False inside R_ISCO."""
    hole = np.asarray(hole, dtype=np.float64).reshape(3)
    rel = np.asarray(start, dtype=np.float64).reshape(3) - hole
    r = float(np.linalg.norm(rel)) / float(r_s)
    if not r > 1.5:
        raise ValueError(f"no circular orbit at r = {r:.6g} r_s: it must lie outside the photon sphere (1.5 r_s)")
    a = rel / np.linalg.norm(rel)
    axis = np.asarray(axis, dtype=np.float64).reshape(3)
    normal = axis - (axis @ a) * a
    if not np.linalg.norm(normal) > 1e-9 * np.linalg.norm(axis):
        raise ValueError("the orbit's axis must not point along the line from the hole to the camera")
    normal /= np.linalg.norm(normal)
    b = np.cross(normal, a)
    omega = float(circular_orbit(r, prograde)[0])
    phi = omega * np.atleast_1d(np.asarray(t, dtype=np.float64))
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    return Path(hole + float(r_s) * r * (c * a + s * b), r * omega * (c * b - s * a), np.full(phi.shape, r),
                stable=r >= R_ISCO)
