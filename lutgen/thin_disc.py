"""Analytic per-pixel image of an infinitely thin disc around the hole (seed 002's method).

A reference for the mesh-based disc of the add-on: for every pixel of a static observer the light
ray is followed backwards in closed form (the orbit of :mod:`lutgen.orbit`, inverted with Jacobi's
elliptic functions) to its first (order 1, direct image) and second (order 2, ghost image) crossing
of the disc plane; there the radius, the frequency shift 1 + z of gas on circular geodesics and the
observed Page-Thorne flux follow. Pure numpy/scipy, vectorised over pixels.

Units and conventions
---------------------
* Lengths in r_s, c = 1, G M = 1/2; angles in radians (``inclination`` and ``fov`` too). Hole at the
  origin. Sky basis (right-handed, orthonormal): e_o from the hole to the observer (which sits at
  r_obs e_o), e_right, e_up; vectors are given as components in (e_o, e_right, e_up). The camera
  looks at the hole (-e_o) with e_right to the right and e_up up in the picture.
* Disc: the plane through the hole with unit normal (axis) ``a = cos(i) e_o + sin(i) e_up``,
  i = inclination (0: face-on). Its near side is seen below the hole, the far side above.
  Prograde gas rotates counter-clockwise about ``a``: seen from the camera (i < 90 deg) the gas on
  the left of the hole approaches, on the right it recedes.
* A pixel is (theta, alpha): theta is the angle on the sky from the direction to the hole
  (theta = pi - xi, with xi of :mod:`lutgen.solver` measured from the outward radial direction),
  alpha the position angle from e_right towards e_up. The ray leaves the observer (traced backwards)
  along n = -cos(theta) e_o + sin(theta) s, s = cos(alpha) e_right + sin(alpha) e_up, in the plane
  (e_o, s), sweeping the polar angle Phi (from e_o towards s).
* The plane of the ray meets the disc plane in a line through the hole at Phi = phi_c and
  phi_c + pi, with phi_c in [0, pi). Crossing ``order`` k is at Phi = phi_c + (k - 1) pi. This is the
  add-on's image order: the disc point there has polar angle phi_c (order 1, plane vector e2 = s) or
  pi - phi_c (order 2, e2 = -s) in its own plane through hole and observer, and order 1 (2) is the
  LUT ray sweeping phi (2 pi - phi). (For an observer in the disc plane, i = 90 deg exactly,
  phi_c = 0 is the observer's own position: use an inclination just below 90 deg.)
* 1 + z is computed in the local static frame at the crossing (independently of the conserved-
  quantity formula of the add-on): special-relativistic Doppler factor gamma (1 - beta v.k) of the
  gas (local speed beta = 1/sqrt(2 (r - 1)) along a x q) against the photon's local direction of
  travel k, times the static-to-static gravitational factor sqrt((1 - 1/r_obs) / (1 - 1/r)).
* Flux: Page-Thorne flux in units of F0 = 3 G M Mdot / (8 pi r_s^3), observed F / (1 + z)^4.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.special import ellipj

from . import orbit as _orb
from .solver import check_observer_radius

R_ISCO = 3.0


class DiscCrossing(NamedTuple):
    """Per-pixel result for one order (arrays of the pixels' shape).

    r: radius (r_s) where the ray crosses the disc plane (NaN if it falls in or escapes first);
    hit: r_in <= r <= r_out; one_plus_z: 1 + z there (NaN without a crossing); flux: observed flux
    F / (1 + z)^4 in units of F0 where ``hit``, else 0; phi: swept polar angle of the crossing (rad);
    b: impact parameter (r_s).
    """

    r: np.ndarray
    hit: np.ndarray
    one_plus_z: np.ndarray
    flux: np.ndarray
    phi: np.ndarray
    b: np.ndarray


def page_thorne_flux(r, r_in: float = R_ISCO) -> np.ndarray:
    """Page-Thorne flux (units of F0 = 3 G M Mdot / (8 pi r_s^3)) at r (r_s), zero for r <= r_in.

    Written in M units (M = 1/2 r_s), rho = r/M = 2 r, x = sqrt(rho), h(x) = (x - sqrt3)/(x + sqrt3):
    F/F0 = 8 [x - x_in - (sqrt3/2) ln(h(x)/h(x_in))] / (rho^(5/2) (rho - 3)).
    """
    r = np.asarray(r, dtype=np.float64)
    rho = 2.0 * r
    rho_in = 2.0 * float(r_in)
    s3 = np.sqrt(3.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        x, x_in = np.sqrt(rho), np.sqrt(rho_in)
        integral = x - x_in - 0.5 * s3 * (np.log((x - s3) / (x + s3)) - np.log((x_in - s3) / (x_in + s3)))
        f = 8.0 * integral / (rho**2.5 * (rho - 3.0))
    return np.where(r > r_in, f, np.where(np.isnan(r), np.nan, 0.0))


def sky_vectors(inclination: float):
    """(e_o, e_right, e_up, axis) as components in the sky basis; axis = cos(i) e_o + sin(i) e_up."""
    i = float(inclination)
    e = np.eye(3)
    return e[0], e[1], e[2], np.array([np.cos(i), 0.0, np.sin(i)])


def pixel_angles(width: int, height: int, fov_v: float):
    """(theta, alpha) of the pixel centres (arrays (height, width), row 0 at the top) of a pinhole
    camera of vertical field of view ``fov_v`` (rad) looking at the hole: the pixel (ph, pv) looks
    along -e_o + x e_right + y e_up with x = aspect (2 (ph + 1/2)/width - 1) tan(fov_v/2),
    y = (1 - 2 (pv + 1/2)/height) tan(fov_v/2) (seed 002's eq. 4 in our axes)."""
    t = np.tan(0.5 * fov_v)
    x = (width / height) * (2.0 * (np.arange(width) + 0.5) / width - 1.0) * t
    y = (1.0 - 2.0 * (np.arange(height) + 0.5) / height) * t
    X, Y = np.meshgrid(x, y)
    return np.arctan(np.hypot(X, Y)), np.arctan2(Y, X)


def crossing_angle(inclination, alpha) -> np.ndarray:
    """phi_c in [0, pi): polar angle (from e_o towards s(alpha)) of the line where the ray plane of
    position angle alpha meets the disc plane. NaN if the two planes coincide."""
    A = np.cos(inclination)
    B = np.sin(alpha) * np.sin(inclination)
    # cos(phi) A + sin(phi) B = 0  ->  (cos, sin) along (-B, A)
    with np.errstate(invalid="ignore"):
        phi = np.mod(np.arctan2(A, -B), np.pi)
        return np.where((A == 0.0) & (B == 0.0), np.nan, np.where(phi >= np.pi, 0.0, phi))


def radius_at_sweep(r_obs, theta, sweep) -> np.ndarray:
    """Radius (r_s) reached by the ray leaving the observer at angle theta from the hole direction
    after sweeping the polar angle ``sweep`` (rad, >= 0), in closed form; NaN if the ray falls into
    the hole or escapes to infinity before sweeping that much. Arrays broadcast.

    With F(u) = :func:`lutgen.orbit.sweep` (the angle swept from the root e1 of the orbit's cubic), the
    ray is at F = F(u_obs) + sweep (inbound start, theta < pi/2) or F(u_obs) - sweep (outbound start).
    Turning orbits: u = e1 + (e2 - e1) sn^2(sqrt(e3 - e1) F / 2 | k^2), k^2 = (e2 - e1)/(e3 - e1), which
    passes the periapsis at F = F(e2) by itself; valid while F(0) <= F <= 2 F(e2) - F(0) (u >= 0).
    Plunging orbits: u = e1 + A (1 - cn)/(1 + cn), cn = cn(sqrt(A) F | k^2), valid for F(0) <= F <= F(1)
    (horizon). (The inversions of the Legendre forms used in :func:`lutgen.orbit.sweep`.)
    """
    r_obs = check_observer_radius(r_obs)
    theta, sweep = np.broadcast_arrays(np.asarray(theta, dtype=np.float64), np.asarray(sweep, dtype=np.float64))
    shape = theta.shape
    theta, sweep = theta.ravel(), sweep.ravel()
    uo = 1.0 / r_obs
    out = np.full(theta.size, np.nan)
    ok = np.isfinite(theta) & np.isfinite(sweep) & (theta > 0.0) & (theta <= np.pi) & (sweep >= 0.0)
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return out.reshape(shape)
    th, sw = theta[idx], sweep[idx]
    b = r_obs * np.sin(th) / np.sqrt(1.0 - uo)
    orb = _orb.orbit_from_b(b)
    inbound = th < 0.5 * np.pi
    with np.errstate(invalid="ignore", divide="ignore"):
        f_o = _orb.sweep(orb, uo)
        f = np.where(inbound, f_o + sw, f_o - sw)
        f_zero = _orb.sweep(orb, 0.0)
        u = np.full(idx.size, np.nan)
        valid = np.zeros(idx.size, dtype=bool)
        real = orb.real
        if real.any():
            e1, e2, e3 = orb.e1[real], orb.e2[real], orb.e3[real]
            fr = f[real]
            k2 = (e2 - e1) / (e3 - e1)
            sn = ellipj(0.5 * np.sqrt(e3 - e1) * fr, k2)[0]
            u[real] = e1 + (e2 - e1) * sn * sn
            f_peri = _orb.sweep_to_turning_point(orb.subset(real))
            valid[real] = (fr >= f_zero[real]) & (fr <= 2.0 * f_peri - f_zero[real])
        cplx = ~real
        if cplx.any():
            e1, m, n = orb.e1[cplx], orb.m[cplx], orb.n[cplx]
            fc = f[cplx]
            me1 = m - e1
            A = np.sqrt(me1 * me1 + n * n)
            k2c = n * n / (2.0 * A * (A + me1))
            cn = ellipj(np.sqrt(A) * fc, 1.0 - k2c)[1]
            u[cplx] = e1 + A * (1.0 - cn) / (1.0 + cn)
            f_hor = _orb.sweep(orb.subset(cplx), 1.0)
            valid[cplx] = (fc >= f_zero[cplx]) & (fc <= f_hor)
        u = np.where(valid & (u > 0.0), u, np.nan)
    out[idx] = 1.0 / u
    return out.reshape(shape)


def redshift_static_frame(r_obs, r, q_hat, k_dir, axis, prograde: bool = True) -> np.ndarray:
    """1 + z from the local static frame at the emitter (see the module docstring).

    r (N,) radius (r_s); q_hat (N, 3) unit position of the emitter; k_dir (N, 3) unit direction of
    travel of the photon in the emitter's static frame (towards the observer); axis (3,) disc axis.
    Gas speed beta = 1/sqrt(2 (r - 1)) along +-(axis x q_hat); 1 + z = gamma (1 - beta v.k)
    sqrt((1 - 1/r_obs) / (1 - 1/r)).
    """
    r = np.asarray(r, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        beta = 1.0 / np.sqrt(2.0 * (r - 1.0))
        gamma = 1.0 / np.sqrt(1.0 - beta * beta)
        v = np.cross(np.asarray(axis, dtype=np.float64), q_hat) * (1.0 if prograde else -1.0)
        v /= np.linalg.norm(v, axis=-1)[..., None]
        doppler = gamma * (1.0 - beta * np.einsum("...j,...j->...", v, k_dir))
        out = doppler * np.sqrt((1.0 - 1.0 / r_obs) / (1.0 - 1.0 / r))
    return np.where(r > 1.5, out, np.nan)


def disc_crossings(r_obs, inclination, theta, alpha, order: int = 1, *, r_in: float = R_ISCO,
                   r_out: float = 15.0, prograde: bool = True) -> DiscCrossing:
    """Crossing ``order`` (1 direct, 2 ghost) of the pixels (theta, alpha) (rad, broadcast) with the
    disc plane, for the static observer at r_obs (r_s) and the disc of inclination ``inclination``
    (rad) and radii [r_in, r_out] (r_s). See the module docstring for the axes. Returns a
    :class:`DiscCrossing`.
    """
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order!r}")
    r_obs = check_observer_radius(r_obs)
    theta, alpha = np.broadcast_arrays(np.asarray(theta, dtype=np.float64), np.asarray(alpha, dtype=np.float64))
    shape = theta.shape
    theta, alpha = theta.ravel(), alpha.ravel()
    e_o, e_right, e_up, axis = sky_vectors(inclination)
    phi = crossing_angle(inclination, alpha) + (order - 1) * np.pi
    r = radius_at_sweep(r_obs, theta, phi)
    b = r_obs * np.sin(theta) / np.sqrt(1.0 - 1.0 / r_obs)
    s = np.cos(alpha)[:, None] * e_right + np.sin(alpha)[:, None] * e_up
    c, sn = np.cos(phi)[:, None], np.sin(phi)[:, None]
    q_hat = c * e_o + sn * s
    e_phi = -sn * e_o + c * s  # direction of increasing Phi (the backward ray's sense)
    with np.errstate(invalid="ignore", divide="ignore"):
        # local static frame: the backward ray's tangential component is b sqrt(1 - 1/r)/r along
        # e_phi; the photon travels the other way. The radial part is orthogonal to the gas velocity
        # and does not enter the Doppler factor, so only the tangential part is needed (and then the
        # rest of k_dir along q_hat).
        st = np.clip(b * np.sqrt(1.0 - 1.0 / r) / r, 0.0, 1.0)
        k_dir = -st[:, None] * e_phi + np.sqrt(1.0 - st * st)[:, None] * q_hat
        one_plus_z = redshift_static_frame(r_obs, r, q_hat, k_dir, axis, prograde)
        hit = (r >= r_in) & (r <= r_out)
        flux = np.where(hit, page_thorne_flux(r, r_in) / one_plus_z**4, 0.0)
    rs = lambda a: a.reshape(shape)  # noqa: E731
    return DiscCrossing(r=rs(r), hit=rs(hit), one_plus_z=rs(one_plus_z), flux=rs(flux), phi=rs(phi), b=rs(b))


def disc_image(r_obs=120.0, inclination=np.radians(84.5), width=320, height=180, fov_v=np.radians(6.0),
               *, r_in: float = R_ISCO, r_out: float = 15.0, prograde: bool = True, orders=(1, 2)):
    """Bolometric image (height, width) of the disc (observed flux in units of F0, summed over
    ``orders``) and the per-order :class:`DiscCrossing` results, for a pinhole camera (seed 002's
    figure 4 defaults: r_obs = 120 r_s, i = 84.5 deg, fov_v = 6 deg, disc 3-15 r_s)."""
    theta, alpha = pixel_angles(width, height, fov_v)
    parts = {k: disc_crossings(r_obs, inclination, theta, alpha, k, r_in=r_in, r_out=r_out, prograde=prograde)
             for k in orders}
    image = sum(p.flux for p in parts.values())
    return image, parts
