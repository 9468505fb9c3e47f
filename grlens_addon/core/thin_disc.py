"""Thin accretion disc (Luminet style, seed 002): Page-Thorne flux, redshift of gas on circular
geodesics, observed flux and blackbody colour, per vertex of a lensed disc mesh. Plain numpy, no bpy.

Units and conventions
---------------------
* Lengths in r_s (Schwarzschild radii) unless a parameter says Blender units (BU); c = 1, G M = r_s/2
  (so M = 1/2 in these units). Angular velocities in c/r_s, temperatures in kelvin.
* Disc gas: particles on circular timelike geodesics (r > 1.5 r_s; stable for r >= 3 r_s = ISCO) in
  the plane through the hole perpendicular to the disc axis ``axis`` (a unit vector). Prograde gas
  rotates counter-clockwise about ``axis`` (its angular momentum points along +axis), retrograde gas
  the other way. Omega = d(phi)/dt = +-sqrt(M/r^3) = +-1/sqrt(2 r^3), u^t = 1/sqrt(1 - 3M/r)
  = 1/sqrt(1 - 3/(2 r)).
* Photon: future-directed, from the emitting point to the camera, with conserved energy E = -p_t and
  angular momentum vector L (per unit E): L = (x cross direction of travel), |L| = b, the impact
  parameter. l_z = L . axis is the component conjugate to the rotation angle of the gas.
* Observer (camera): static at r_obs. It measures E_obs = E / sqrt(1 - 1/r_obs); the gas measures
  E_em = -p.u = u^t (E - Omega L_z). Hence

      1 + z = E_em / E_obs = u^t (1 - Omega l_z) sqrt(1 - 1/r_obs)          (l_z = L_z / E).

  1 + z < 1 is a blueshift (approaching gas), > 1 a redshift. Face-on (l_z = 0):
  1 + z = sqrt(1 - 1/r_obs) / sqrt(1 - 3/(2r)).
* Per vertex (add-on, :mod:`grlens_addon.core.mapping` conventions): e1 = (camera - hole)/|.|, e2 the
  unit vector of the vertex's component perpendicular to e1, and the LUT's xi (rad, from the outward
  radial direction at the camera) for order 1 or 2. The impact parameter is
  b = r_obs sin(xi) / sqrt(1 - 1/r_obs). The plane (e1, e2) has normal n = e1 x e2 and polar angle
  phi increasing from e1 towards e2. Order 1 light travels from phi (the vertex) back to phi = 0 (the
  camera), i.e. with dphi/dt < 0: L = -b n. Order 2 light passes the hole on the other side and
  travels from phi - 2 pi up to 0, dphi/dt > 0: L = +b n. Both amount to L = r_obs e1 x (-d) /
  sqrt(1 - 1/r_obs) with d the apparent (image) direction at the camera, L evaluated where the
  photon arrives (:func:`vertex_redshift_from_direction`).
* Page-Thorne flux F(r) in units of F0 = 3 G M Mdot / (8 pi r_s^3) (the seed's normalisation; Mdot
  the accretion rate): zero at and inside the inner edge r_in (zero-torque boundary, default the ISCO
  3 r_s). With the ISCO edge the maximum is F = 9.1666e-4 F0 at r = 4.7745 r_s (9.549 M).
  Observed (bolometric) flux: F_obs = F / (1 + z)^4.
* Colours: linear Rec.709 / sRGB primaries (D65 white), the colour space Blender renders in.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

R_ISCO = 3.0
"""Innermost stable circular orbit of the Schwarzschild spacetime (units of r_s)."""

MODES = ("bolometric", "blackbody")


# --------------------------------------------------------------------------------------------------
# Page-Thorne flux
# --------------------------------------------------------------------------------------------------
def page_thorne_flux(r, r_in: float = R_ISCO) -> np.ndarray:
    """Page-Thorne (Novikov-Thorne, Schwarzschild) flux emitted by one face of the disc at radius r.

    r in units of r_s (array); r_in (r_s, >= 3, the ISCO) is the zero-torque inner edge. Returns F in
    units of F0 = 3 G M Mdot / (8 pi r_s^3): with R = r / r_s,

        F / F0 = [sqrt(R) - sqrt(R_in) - (sqrt(3/2)/2) ln(g(R) / g(R_in))] / ((R - 3/2) R^(5/2)),
        g(R) = (sqrt(R) - sqrt(3/2)) / (sqrt(R) + sqrt(3/2)),

    which is the general Page-Thorne integral for circular geodesics (E, L, Omega of Schwarzschild)
    done in closed form. Zero for r <= r_in; NaN for NaN input.
    """
    r_in = _check_r_in(r_in)
    r = np.asarray(r, dtype=np.float64)
    h = np.sqrt(1.5)
    with np.errstate(invalid="ignore", divide="ignore"):
        x = np.sqrt(r)
        x_in = np.sqrt(r_in)
        log_term = np.log((x - h) / (x + h)) - np.log((x_in - h) / (x_in + h))
        f = (x - x_in - 0.5 * h * log_term) / ((r - 1.5) * r**2.5)
    return np.where(r > r_in, f, np.where(np.isnan(r), np.nan, 0.0))


def _check_r_in(r_in):
    r_in = float(r_in)
    if not (np.isfinite(r_in) and r_in >= R_ISCO * (1.0 - 1e-12)):
        raise ValueError(f"r_in must be at least the ISCO (3 r_s), got {r_in}")
    return max(r_in, R_ISCO)


@lru_cache(maxsize=32)
def page_thorne_peak(r_in: float = R_ISCO) -> tuple[float, float]:
    """(r_peak, F_peak): radius (r_s) and value (units of F0) of the maximum of :func:`page_thorne_flux`.

    Golden-section search (F is unimodal: 0 at r_in, decaying like r^-3 far out) to ~1e-12 relative.
    For r_in = 3 r_s: r_peak = 4.7745 r_s (= 9.549 M), F_peak = 9.1666e-4 F0.
    """
    r_in = _check_r_in(r_in)
    a, b = r_in, 20.0 * r_in
    g = 0.5 * (np.sqrt(5.0) - 1.0)
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = float(page_thorne_flux(c, r_in)), float(page_thorne_flux(d, r_in))
    while b - a > 1e-12 * b:
        if fc > fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = float(page_thorne_flux(c, r_in))
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = float(page_thorne_flux(d, r_in))
    r = 0.5 * (a + b)
    return r, float(page_thorne_flux(r, r_in))


# --------------------------------------------------------------------------------------------------
# Redshift
# --------------------------------------------------------------------------------------------------
def circular_orbit(r, prograde: bool = True):
    """(Omega, u^t) of circular geodesics at r (r_s): Omega = +-1/sqrt(2 r^3) (c/r_s; sign + for
    prograde), u^t = 1/sqrt(1 - 3/(2 r)). NaN at and inside the photon sphere r <= 1.5."""
    r = np.asarray(r, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = r > 1.5
        omega = np.where(ok, (1.0 if prograde else -1.0) / np.sqrt(2.0 * r**3), np.nan)
        ut = np.where(ok, 1.0 / np.sqrt(1.0 - 1.5 / r), np.nan)
    return omega, ut


def redshift_factor(r, l_z, r_obs, prograde: bool = True) -> np.ndarray:
    """1 + z of light emitted by disc gas on a circular geodesic at radius r (r_s) and received by the
    static observer at r_obs (r_s): 1 + z = u^t (1 - Omega l_z) sqrt(1 - 1/r_obs).

    l_z (r_s): the photon's angular momentum per unit energy about the disc axis (future-directed
    photon, see the module docstring); prograde gas has Omega > 0 about that axis. Arrays broadcast.
    """
    r_obs = float(r_obs)
    if not r_obs > 1.0:
        raise ValueError(f"the static observer must be outside the horizon, got r_obs = {r_obs}")
    omega, ut = circular_orbit(r, prograde)
    return ut * (1.0 - omega * np.asarray(l_z, dtype=np.float64)) * np.sqrt(1.0 - 1.0 / r_obs)


def impact_parameter(xi, r_obs) -> np.ndarray:
    """Impact parameter b (r_s) of a ray leaving the static observer at r_obs (r_s) at angle xi (rad,
    from the outward radial direction): b = r_obs sin(xi) / sqrt(1 - 1/r_obs)."""
    return r_obs * np.sin(np.asarray(xi, dtype=np.float64)) / np.sqrt(1.0 - 1.0 / r_obs)


def photon_angular_momentum(e1, e2, xi, r_obs, order: int) -> np.ndarray:
    """Angular momentum vector per unit energy (N, 3; r_s) of the order-1 or order-2 photon that
    travels from a vertex to the camera: L = s b (e1 x e2), s = -1 for order 1, +1 for order 2.

    e1 (3,) unit vector hole -> camera; e2 (N, 3) the vertex's plane vector (mapping.plane_coordinates);
    xi (N,) the LUT angle (rad) of that order; r_obs (r_s)."""
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order!r}")
    n = np.cross(np.asarray(e1, dtype=np.float64), np.asarray(e2, dtype=np.float64))
    s = -1.0 if order == 1 else 1.0
    return (s * impact_parameter(xi, r_obs))[..., None] * n


def _gas_frame(points, hole, camera, r_s, axis):
    """(r (N,) in r_s, orbit normal (N, 3), e1 (3,), r_obs in r_s) for vertices (BU): the unit normal of
    the circular orbit through each vertex (the axis' component perpendicular to the vertex direction,
    normalised; ``axis`` itself for vertices in the disc plane)."""
    points = np.asarray(points, dtype=np.float64)
    hole = np.asarray(hole, dtype=np.float64).reshape(3)
    camera = np.asarray(camera, dtype=np.float64).reshape(3)
    r_s = float(r_s)
    axis = np.asarray(axis, dtype=np.float64).reshape(3)
    axis = axis / np.linalg.norm(axis)
    d = camera - hole
    r_obs = np.linalg.norm(d) / r_s
    e1 = d / np.linalg.norm(d)
    p = (points - hole) / r_s
    r = np.linalg.norm(p, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        p_hat = p / r[:, None]
        normal = axis - (p_hat @ axis)[:, None] * p_hat
        normal /= np.linalg.norm(normal, axis=1)[:, None]
    return r, normal, e1, r_obs


def vertex_redshift(points, hole, camera, r_s, axis, xi, e2, order: int, prograde: bool = True):
    """Per-vertex 1 + z of disc gas seen along the order-1 or order-2 geodesic.

    points (N, 3), hole (3,), camera (3,), r_s: Blender units (BU). axis (3,): disc axis (normalised
    here). xi (N,): LUT angle (rad) of that order at the vertex (mapping.Images.xi); e2 (N, 3): the
    vertex's plane vector (mapping.Images.plane.e2). Returns (N,) 1 + z, NaN where xi is NaN or
    r <= 1.5 r_s.

    Vertices off the disc plane (a disc mesh with thickness) are given the circular geodesic through
    the vertex in the plane that contains the hole and the axis' component perpendicular to the vertex
    direction as normal (for vertices in the disc plane this is ``axis`` itself).
    """
    r, normal, e1, r_obs = _gas_frame(points, hole, camera, r_s, axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        L = photon_angular_momentum(e1, e2, xi, r_obs, order)
        l_z = np.einsum("ij,ij->i", L, normal)
    return redshift_factor(r, l_z, r_obs, prograde)


def vertex_redshift_from_direction(points, hole, camera, r_s, axis, direction, prograde: bool = True):
    """Per-vertex 1 + z from the image's apparent direction alone (mapping.Images.direction), any order.

    The photon's angular momentum is conserved, so it can be read off where it arrives: at the camera
    (position r_obs e1 from the hole, r_s units) it travels along -direction in the static frame, so
    L = r_obs e1 x (-direction) / sqrt(1 - 1/r_obs) (per unit conserved energy). This equals
    :func:`vertex_redshift` (direction = cos(xi) e1 +- sin(xi) e2 for order 1 / 2) and needs neither
    xi nor e2. Arguments as there; ``direction`` (N, 3) unit vectors; NaN directions give NaN.
    """
    r, normal, e1, r_obs = _gas_frame(points, hole, camera, r_s, axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        L = -(r_obs / np.sqrt(1.0 - 1.0 / r_obs)) * np.cross(e1, np.asarray(direction, dtype=np.float64))
        l_z = np.einsum("ij,ij->i", L, normal)
    return redshift_factor(r, l_z, r_obs, prograde)


def observed_flux(r, one_plus_z, r_in: float = R_ISCO) -> np.ndarray:
    """Observed bolometric flux F(r) / (1 + z)^4 in units of F0 (r in r_s). NaN 1 + z gives NaN."""
    return page_thorne_flux(r, r_in) / np.asarray(one_plus_z, dtype=np.float64) ** 4


# --------------------------------------------------------------------------------------------------
# Temperature and colour
# --------------------------------------------------------------------------------------------------
def disc_temperature(r, t_peak: float = 1.0e4, r_in: float = R_ISCO) -> np.ndarray:
    """Effective (emitted) temperature in K at r (r_s): sigma T^4 = F, scaled so that the temperature
    at the flux maximum is ``t_peak``: T = t_peak (F / F_peak)^(1/4). Zero inside r_in."""
    _, f_peak = page_thorne_peak(r_in)
    return t_peak * np.maximum(page_thorne_flux(r, r_in) / f_peak, 0.0) ** 0.25


def observed_temperature(r, one_plus_z, t_peak: float = 1.0e4, r_in: float = R_ISCO) -> np.ndarray:
    """Observed temperature T / (1 + z) in K (a blackbody stays a blackbody of that temperature)."""
    return disc_temperature(r, t_peak, r_in) / np.asarray(one_plus_z, dtype=np.float64)


def _lobe(lam, mu, s_lo, s_hi):
    s = np.where(lam < mu, s_lo, s_hi)
    return np.exp(-0.5 * ((lam - mu) / s) ** 2)


def cie1931_cmf(lam_nm) -> np.ndarray:
    """CIE 1931 2-degree colour matching functions (x-bar, y-bar, z-bar), shape (..., 3), at
    wavelengths in nm, from the multi-lobe piecewise-Gaussian fit of Wyman, Sloan & Shirley (2013)."""
    lam = np.asarray(lam_nm, dtype=np.float64)
    x = (1.056 * _lobe(lam, 599.8, 37.9, 31.0) + 0.362 * _lobe(lam, 442.0, 16.0, 26.7)
         - 0.065 * _lobe(lam, 501.1, 20.4, 26.2))
    y = 0.821 * _lobe(lam, 568.8, 46.9, 40.5) + 0.286 * _lobe(lam, 530.9, 16.3, 31.1)
    z = 1.217 * _lobe(lam, 437.0, 11.8, 36.0) + 0.681 * _lobe(lam, 459.0, 26.0, 13.8)
    return np.stack([x, y, z], axis=-1)


XYZ_TO_LINEAR_SRGB = np.array([
    [3.2404542, -1.5371385, -0.4985314],
    [-0.9692660, 1.8760108, 0.0415560],
    [0.0556434, -0.2040259, 1.0572252],
])
"""XYZ -> linear Rec.709/sRGB (D65 white)."""

_C2_NM_K = 1.438776877e7  # second radiation constant h c / k_B in nm K
_LAMBDA_NM = np.arange(360.0, 831.0, 1.0)
_T_TABLE_RANGE = (300.0, 1.0e6)
_T_TABLE_N = 2048


def blackbody_xyz(t_kelvin) -> np.ndarray:
    """Chromaticity of a blackbody as XYZ with Y = 1, shape (..., 3), by direct quadrature of Planck's
    law against :func:`cie1931_cmf` (360-830 nm, 1 nm steps). Temperatures in K (> 0)."""
    t = np.asarray(t_kelvin, dtype=np.float64)
    flat = t.reshape(-1)
    cmf = cie1931_cmf(_LAMBDA_NM)  # (L, 3)
    out = np.empty((flat.size, 3))
    for a in range(0, flat.size, 4096):  # chunks bound the (chunk, L) temporary
        tt = flat[a:a + 4096, None]
        with np.errstate(over="ignore"):
            # Planck's law up to a constant; exp overflow -> spectrum 0 (only where T is tiny)
            spec = _LAMBDA_NM**-5 / np.expm1(_C2_NM_K / (_LAMBDA_NM * tt))
        xyz = spec @ cmf
        out[a:a + 4096] = xyz / xyz[:, 1:2]
    return out.reshape(t.shape + (3,))


@lru_cache(maxsize=1)
def _rgb_table():
    log_t = np.linspace(np.log(_T_TABLE_RANGE[0]), np.log(_T_TABLE_RANGE[1]), _T_TABLE_N)
    rgb = blackbody_xyz(np.exp(log_t)) @ XYZ_TO_LINEAR_SRGB.T
    return log_t, rgb


def blackbody_rgb(t_kelvin, normalise: str = "luminance") -> np.ndarray:
    """Colour of a blackbody of temperature T (K) in linear Rec.709/sRGB, shape (..., 3).

    ``normalise="luminance"``: luminance Y = 1 (so a brightness factor multiplies it directly);
    ``"max"``: largest component 1. Out-of-gamut components (negative; e.g. blue below ~1900 K) are
    clipped to 0 after normalising. Interpolated linearly in log T from a table of direct quadratures
    (300 K to 1e6 K, 2048 nodes, error < 1e-5); temperatures outside that range take the end colour
    (above 1e6 K the chromaticity is already at its Rayleigh-Jeans limit). NaN or T <= 0 give NaN.
    """
    if normalise not in ("luminance", "max"):
        raise ValueError(f"normalise must be 'luminance' or 'max', got {normalise!r}")
    t = np.asarray(t_kelvin, dtype=np.float64)
    log_t, table = _rgb_table()
    with np.errstate(invalid="ignore", divide="ignore"):
        lt = np.log(t.reshape(-1))
    rgb = np.stack([np.interp(lt, log_t, table[:, k]) for k in range(3)], axis=-1)
    bad = ~(t.reshape(-1) > 0)
    rgb[bad] = np.nan
    rgb = np.maximum(rgb, 0.0)  # NaN stays NaN
    if normalise == "max":
        rgb = rgb / np.max(rgb, axis=-1, keepdims=True)
    return rgb.reshape(t.shape + (3,))


def disc_colour(r, one_plus_z, mode: str = "bolometric", *, r_in: float = R_ISCO, t_peak: float = 1.0e4,
                exposure: float = 1.0) -> np.ndarray:
    """Linear RGB (..., 3) of disc gas at radius r (r_s) observed with redshift factor 1 + z.

    * ``"bolometric"``: grey = exposure * F_obs / F_peak (F_obs = F / (1 + z)^4; F_peak the emitted
      maximum of :func:`page_thorne_peak`, so the fixed scale keeps frames comparable; Doppler
      boosting makes values > 1 on the approaching side);
    * ``"blackbody"``: the colour of the observed temperature T_obs = T / (1 + z)
      (:func:`blackbody_rgb`, luminance 1) times exposure * F_obs / F_peak.

    Inside r_in the colour is black; NaN 1 + z (no image) gives NaN.
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    one_plus_z = np.asarray(one_plus_z, dtype=np.float64)
    _, f_peak = page_thorne_peak(r_in)
    level = exposure * observed_flux(r, one_plus_z, r_in) / f_peak
    if mode == "bolometric":
        return np.repeat(level[..., None], 3, axis=-1)
    t_obs = observed_temperature(r, one_plus_z, t_peak, r_in)
    rgb = blackbody_rgb(np.where(t_obs > 0, t_obs, 1.0))  # colour irrelevant where the flux is 0
    return rgb * level[..., None]
