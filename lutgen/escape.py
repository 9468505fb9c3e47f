"""Escape directions: where a ray leaving a static observer goes to infinity (the lensed sky).

Units: lengths in r_s (Schwarzschild radius), c = 1, angles in radians. Conventions as in the rest
of lutgen: the observer is static at (r_obs, phi = 0); ``xi`` in [0, pi] is the angle of the ray at
the observer from the OUTWARD radial direction e1 (hole -> observer) in the observer's static frame
(xi = pi looks straight at the hole). The ray moves in the plane spanned by e1 and
e2 = unit(d - (d.e1) e1) (d: its direction at the observer) and sweeps the position angle phi
from 0 towards e2.

``escape_angle(r_obs, xi)`` is the position angle phi_inf at which the ray reaches infinity, so it
leaves in the direction cos(phi_inf) e1 + sin(phi_inf) e2 (the sky it shows is the sky in that
direction; flat space: phi_inf = xi). Rays that fall into the hole give NaN (the shadow).

With u = r_s/r, uo = 1/r_obs and impact parameter b = r_obs sin(xi) / sqrt(1 - uo), and the orbit
integral F(u) of :func:`lutgen.orbit.sweep`:

* rays heading out (cos xi >= 0) sweep phi_inf = F(uo) - F(0) on their way to infinity; from
  inside the photon sphere (r_obs <= 1.5) only those with b < b_crit = 3 sqrt(3)/2 escape (the
  others turn at an apoapsis inside the photon sphere and fall back);
* rays heading in (cos xi < 0) escape iff b > b_crit (r_obs > 1.5 only): they pass the periapsis
  e2 and go out, phi_inf = (F(e2) - F(uo)) + (F(e2) - F(0)), both terms in Carlson's form next to
  the turning point (:func:`lutgen.orbit.sweep_from_turning_point`), with e2 - uo from P(uo)
  without cancellation.

So a ray escapes iff xi < :func:`escape_limit` (r_obs): pi - the shadow's half angle (eq. 14) for
r_obs > 1.5, asin(b_crit sqrt(1 - uo) uo) <= pi/2 for 1 < r_obs <= 1.5. phi_inf grows without bound
(logarithmically) as xi approaches that limit: the sky's higher-order rings.

``escape_table`` samples the deflection phi_inf - xi in the table coordinate
s = ln(xi_lim / (xi_lim - xi)) (0 at xi = 0, log-spaced towards the limit, so the rings are resolved
at a uniform step), for the shader of the add-on's lensed world, which adds xi back (the deflection
is smooth where xi(s) is curved, next to s = 0); ``EscapeTable.lookup`` is that shader's linear
interpolation in numpy.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import orbit as _orb
from .solver import static_observer_radius

S_MAX = 24.0
"""Largest table coordinate s: xi_lim - xi = xi_lim e^-24 ~ 1e-10 xi_lim, below the float32
resolution of an angle in a shader (~2.4e-7 rad at pi); beyond it the table is held constant."""

TABLE_SIZE = 1024
"""Default number of table nodes (uniform in s over [0, S_MAX])."""


def check_escape_radius(r_obs) -> float:
    """Validate an observer radius (units of r_s) for escape directions; returns it as float.
    Raises ValueError for NaN/inf and for observers on or inside the horizon (no static observer
    exists there). Observers inside the photon sphere (1 < r_obs <= 1.5) are allowed."""
    return static_observer_radius(r_obs)


def escape_limit(r_obs) -> float:
    """The largest angle xi (radians) of a ray that escapes to infinity from a static observer at
    r_obs (units of r_s, > 1): pi - shadow half angle (eq. 14) for r_obs > 1.5, else
    asin(b_crit sqrt(1 - 1/r_obs) / r_obs) (outward rays only; pi/2 at r_obs = 1.5)."""
    r = check_escape_radius(r_obs)
    s = np.sqrt(6.75 * (1.0 - 1.0 / r)) / r  # sin of the critical angle, <= 1 with equality at 1.5
    a = float(np.arcsin(min(s, 1.0)))
    return np.pi - a if r > 1.5 else a


def escape_angle(r_obs, xi) -> np.ndarray:
    """Position angle phi_inf (radians, >= 0) at which the ray leaving a static observer at r_obs
    (units of r_s, > 1) at angle xi (radians, [0, pi], from the outward radial direction) reaches
    infinity; NaN where it falls into the hole (xi >= escape_limit(r_obs)) or for bad xi.
    Vectorised over xi. See the module docstring for the formulas."""
    r = check_escape_radius(r_obs)
    xi = np.asarray(xi, dtype=float)
    shape = xi.shape
    xi = xi.ravel()
    out = np.full(xi.shape, np.nan)
    uo = 1.0 / r
    lim = escape_limit(r)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(xi) & (xi >= 0.0) & (xi < lim)
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return out.reshape(shape)
    x = xi[idx]
    sin_x, cos_x = np.sin(x), np.cos(x)
    b = r * sin_x / np.sqrt(1.0 - uo)
    res = np.empty(x.shape)
    tiny = b < 1e-12  # radial ray outwards: phi_inf = 0 (the orbit of b = 0 is degenerate)
    res[tiny] = 0.0
    out_m = ~tiny & (cos_x >= 0.0)
    if out_m.any():
        orb = _orb.orbit_from_b(b[out_m])
        f_o = _orb.sweep(orb, np.full(orb.e1.shape, uo))
        f_0 = _orb.sweep(orb, np.zeros(orb.e1.shape))
        res[out_m] = f_o - f_0
    in_m = ~tiny & (cos_x < 0.0)
    if in_m.any():
        orb = _orb.orbit_from_b(b[in_m])
        # e2 - uo = P(uo) / ((uo - e1)(e3 - uo)) with P(uo) = uo^2 (1 - uo) cot^2(xi): no cancellation
        cot = cos_x[in_m] / sin_x[in_m]
        gap = uo * uo * (1.0 - uo) * cot * cot / ((uo - orb.e1) * (orb.e3 - uo))
        res[in_m] = (_orb.sweep_from_turning_point(orb, uo, np.sqrt(gap))
                     + _orb.sweep_from_turning_point(orb, 0.0, np.sqrt(orb.e2)))
    out[idx] = res
    return out.reshape(shape)


def table_coordinate(xi, xi_lim) -> np.ndarray:
    """s = ln(xi_lim / (xi_lim - xi)) (dimensionless): 0 at xi = 0, +inf at the escape limit."""
    xi = np.asarray(xi, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(xi_lim / (xi_lim - xi))


@dataclass(frozen=True)
class EscapeTable:
    """The deflection phi_inf - xi (radians) at ``size`` nodes uniform in
    s = ln(xi_lim / (xi_lim - xi)) over [0, s_max], for one observer radius r_obs (units of r_s).
    ``deflection[j]`` belongs to s_j = j s_max / (size - 1), xi_j = xi_lim (1 - e^-s_j)."""

    r_obs: float
    xi_lim: float
    s_max: float
    deflection: np.ndarray

    @property
    def size(self) -> int:
        return int(self.deflection.size)

    def lookup(self, xi) -> np.ndarray:
        """phi_inf = xi + the deflection interpolated linearly in s (held constant beyond s_max):
        what the shader's image texture lookup computes; NaN where the ray falls in
        (xi >= xi_lim)."""
        xi = np.asarray(xi, dtype=float)
        s = table_coordinate(xi, self.xi_lim)
        j = np.clip(s / self.s_max * (self.size - 1), 0.0, self.size - 1)
        with np.errstate(invalid="ignore"):
            res = xi + np.interp(j, np.arange(self.size), self.deflection)
            return np.where((xi >= 0.0) & (xi < self.xi_lim), res, np.nan)

    def directions(self, d, e1) -> np.ndarray:
        """Escape directions (N, 3) of rays leaving the observer in the directions ``d`` ((N, 3),
        unit) for the outward radial unit vector ``e1`` (3,) (hole -> observer): cos(phi_inf) e1 +
        sin(phi_inf) e2, e2 = unit(d - (d.e1) e1), phi_inf from :meth:`lookup` (the lensed world's
        shader, in float64); NaN rows where the ray falls in. A ray along e1 keeps its direction."""
        d = np.asarray(d, dtype=float).reshape(-1, 3)
        e1 = np.asarray(e1, dtype=float)
        along = d @ e1
        perp = d - along[:, None] * e1
        n_perp = np.linalg.norm(perp, axis=1)
        phi = self.lookup(np.arctan2(n_perp, along))
        with np.errstate(invalid="ignore", divide="ignore"):
            e2 = perp / n_perp[:, None]
        e2[n_perp == 0] = 0.0
        return np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2


def escape_table(r_obs, size: int = TABLE_SIZE, s_max: float = S_MAX) -> EscapeTable:
    """The escape-angle table of an observer at r_obs (units of r_s, > 1): ``size`` nodes uniform in
    s over [0, s_max] (see :class:`EscapeTable`). xi at node j is xi_lim (1 - e^-s_j), with
    xi_lim - xi = xi_lim e^-s_j exact."""
    r = check_escape_radius(r_obs)
    if size < 2:
        raise ValueError(f"size must be >= 2, got {size}")
    lim = escape_limit(r)
    s = np.linspace(0.0, float(s_max), int(size))
    xi = -lim * np.expm1(-s)
    # the node at s = 0 is xi = 0 (radial outwards); nodes are < lim by construction
    xi = np.minimum(xi, np.nextafter(lim, 0.0))
    return EscapeTable(r_obs=r, xi_lim=lim, s_max=float(s_max), deflection=escape_angle(r, xi) - xi)
