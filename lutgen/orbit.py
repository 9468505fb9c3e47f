"""Closed-form light orbits in the Schwarzschild plane (units r_s = 1, c = 1).

A null geodesic in the plane theta = pi/2 obeys the orbit equation in the inverse radius u = r_s/r:

    (du/dphi)^2 = P(u) = u^3 - u^2 + 1/b^2 = (u - e1) * Q(u),

with impact parameter b (units of r_s). P always has exactly one negative root e1 < 0, and every orbit
is labelled by it; we use the well-conditioned label ``sigma = 1 + 3*e1`` in (-inf, 1):

* sigma < 0 (b < b_crit = 3*sqrt(3)/2): Q has the complex roots m +- i*n, the ray plunges.
* sigma > 0 (b > b_crit): Q has the real roots 0 < e2 < 2/3 < e3 and the ray turns at u = e2
  (its periapsis, r = 1/e2).
* sigma = 0: the critical orbit that winds onto the photon sphere u = 2/3 (r = 1.5 r_s).

The swept angle between two inverse radii of one monotone leg is a difference of the elliptic integral
of the first kind ``F(u) = integral_{e1}^{u} du'/sqrt(P(u'))``, evaluated with Carlson's symmetric
R_F (scipy.special.elliprf). Coordinate light travel time along a leg,
``dt = integral dphi / (b u^2 (1 - u))``, is integrated with Gauss-Legendre quadrature in a variable
that removes the square-root singularities of 1/sqrt(P) (turning points, near-double roots near
the photon sphere), on segments that are uniform in logit(u) (for the growth of 1/u^2 and points next
to the horizon) and in that variable (for rays that wind); the far part of a leg
(u < min(0.1, 0.5/b)) is r + ln r in closed form plus a smooth bounded remainder, so far points keep
full relative accuracy up to the largest double.

Everything here is vectorised over numpy arrays; nothing loops over elements in Python.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import elliprf, roots_legendre

B_CRIT = 1.5 * np.sqrt(3.0)
"""Critical impact parameter 3*sqrt(3)/2, in units of r_s (rays with smaller b fall in)."""

U_PHOTON = 2.0 / 3.0
"""Inverse radius of the photon sphere (r = 1.5 r_s)."""


@dataclass
class Orbit:
    """Root structure of P(u) for a batch of orbits (arrays of one shape).

    Attributes are the roots of P in units of 1/r_s. For plunging orbits (``real`` False) ``m, n`` are
    the real and imaginary parts of the complex pair; for turning orbits (``real`` True) ``e2 <= e3``
    are the real roots and ``delta = e3 - e2`` (computed without cancellation). Unused fields hold NaN.
    """

    e1: np.ndarray
    real: np.ndarray
    e2: np.ndarray
    e3: np.ndarray
    delta: np.ndarray
    m: np.ndarray
    n: np.ndarray

    @property
    def inv_b(self) -> np.ndarray:
        """1/b in units of 1/r_s (b = impact parameter)."""
        return -self.e1 * np.sqrt(1.0 - self.e1)

    def P(self, u):
        """P(u) = (du/dphi)^2 in factored form (accurate next to roots)."""
        u = np.asarray(u, dtype=float)
        with np.errstate(invalid="ignore"):
            p_real = (u - self.e1) * (self.e2 - u) * (self.e3 - u)
            p_cplx = (u - self.e1) * ((u - self.m) ** 2 + self.n**2)
        return np.where(self.real, p_real, p_cplx)

    def subset(self, mask) -> "Orbit":
        return Orbit(*(getattr(self, f)[mask] for f in ("e1", "real", "e2", "e3", "delta", "m", "n")))


def _from_sigma_e1(sigma, e1, delta=None, e2=None) -> Orbit:
    sigma = np.asarray(sigma, dtype=float)
    e1 = np.asarray(e1, dtype=float)
    real = sigma > 0
    one_m = 1.0 - e1
    with np.errstate(invalid="ignore", divide="ignore"):
        if delta is None:
            delta = np.where(real, np.sqrt(np.where(real, one_m * sigma, 0.0)), np.nan)
        if e2 is None:
            e2 = np.where(real, -2.0 * e1 * one_m / (one_m + delta), np.nan)
        e3 = np.where(real, e2 + delta, np.nan)
        m = np.where(real, np.nan, 0.5 * one_m)
        n = np.where(real, np.nan, 0.5 * np.sqrt(np.where(real, 0.0, -one_m * sigma)))
    return Orbit(e1=e1, real=real, e2=e2, e3=e3, delta=delta, m=m, n=n)


def orbit_from_b(b) -> Orbit:
    """Orbits with impact parameters ``b`` (units of r_s, b > 0).

    sigma = 1 + 3 e1 solves sigma (3 - sigma)^2 = y with y = 4 (b^2 - b_crit^2)/b^2 (a cubic whose
    trigonometric/hyperbolic solution is written so that it keeps full relative accuracy as
    b -> b_crit): sigma = 4 sin^2(asin(sqrt(y)/2)/3) for y >= 0, -4 sinh^2(asinh(sqrt(-y)/2)/3) else.
    """
    b = np.asarray(b, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        y = 4.0 * (b - B_CRIT) * (b + B_CRIT) / (b * b)
        sq = 0.5 * np.sqrt(np.abs(y))
        sigma = np.where(
            y >= 0.0,
            4.0 * np.sin(np.arcsin(np.minimum(sq, 1.0)) / 3.0) ** 2,
            -4.0 * np.sinh(np.arcsinh(sq) / 3.0) ** 2,
        )
    e1 = (sigma - 1.0) / 3.0
    # For large b the trigonometric form loses the relative accuracy of e1 ~ -1/b (asin near 1),
    # entirely for b >~ 1e8 (sigma rounds to 1, e1 to 0 or the wrong sign): polish e1 there with
    # Newton on e1^2 (1 - e1) = 1/b^2 (a simple root, so well conditioned), started for b > 1e3 from
    # the series e1 = -t + t^2/2 - 5 t^3/8 + O(t^4), t = 1/b (the other small root is +t + ...).
    big = sigma > 0.5
    if np.any(big):
        bb = b[big] if b.ndim else b
        c = 1.0 / (bb * bb)
        t = 1.0 / bb
        e = np.where(bb > 1e3, t * (-1.0 + t * (0.5 - 0.625 * t)), e1[big])
        for _ in range(3):
            e = e - (e * e * (1.0 - e) - c) / (e * (2.0 - 3.0 * e))
        e1 = np.where(big, 0.0, e1)
        e1[big] = e
        sigma = np.where(big, 1.0 + 3.0 * e1, sigma)
    return _from_sigma_e1(sigma, e1)


def orbit_from_turning_point(eps, e2=None) -> Orbit:
    """Turning orbits whose periapsis is u = e2 = 2/3 - eps (0 < eps < 2/3; units of 1/r_s).

    Parametrising by the distance ``eps`` of the periapsis from the photon sphere keeps
    e3 - e2 and sigma accurate for orbits that wind many times (eps -> 0). ``e2`` (optional): the
    periapsis itself, where it is known more accurately than 2/3 - eps (e.g. next to a given radius).
    """
    eps = np.asarray(eps, dtype=float)
    e2 = U_PHOTON - eps if e2 is None else np.asarray(e2, dtype=float)
    d2 = np.sqrt((1.0 - e2) * (1.0 + 3.0 * e2))
    e1 = -2.0 * e2 * (1.0 - e2) / ((1.0 - e2) + d2)
    delta = np.where(
        e2 > 1.0 / 3.0,
        6.0 * e2 * eps / (d2 + 3.0 * e2 - 1.0),
        0.5 * ((1.0 - 3.0 * e2) + d2),
    )
    sigma = delta**2 / (1.0 - e1)
    return _from_sigma_e1(sigma, e1, delta=delta, e2=e2)


def _legendre_F(s, c2, k2c_s2):
    """F(phi|k^2) = s R_F(c2, c2 + (1-k^2) s^2, 1) with s = sin(phi), c2 = cos^2(phi) (phi <= pi/2)."""
    return s * elliprf(c2, c2 + k2c_s2, 1.0)


def sweep(orb: Orbit, u) -> np.ndarray:
    """F(u) = integral from e1 to u of du'/sqrt(P(u')): the angle (radians) a ray sweeps from the
    (unphysical) root e1 to inverse radius u along a monotone leg. Differences of F give the angle
    swept between two radii. For turning orbits u must not exceed e2.
    """
    u, e1 = np.broadcast_arrays(np.asarray(u, dtype=float), orb.e1)
    out = np.empty(u.shape)
    real = np.broadcast_to(orb.real, u.shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        if real.any():
            # turning orbits: Legendre form, sin^2 = (u-e1)/(e2-e1), k^2 = (e2-e1)/(e3-e1)
            uu, a, e2, e3 = u[real], e1[real], _pick(orb.e2, real), _pick(orb.e3, real)
            e21, e31 = e2 - a, e3 - a
            s_r = np.sqrt(np.clip((uu - a) / e21, 0.0, 1.0))
            c2_r = np.clip((e2 - uu) / e21, 0.0, 1.0)
            out[real] = 2.0 / np.sqrt(e31) * s_r * elliprf(c2_r, (e3 - uu) / e31, 1.0)
        cplx = ~real
        if cplx.any():
            # plunging orbits: cos(phi) = (A - x)/(A + x), k^2 = (A + m - e1)/(2A)
            uu, a, m, n = u[cplx], e1[cplx], _pick(orb.m, cplx), _pick(orb.n, cplx)
            x = uu - a
            me1 = m - a
            A = np.sqrt(me1**2 + n**2)
            k2c = n**2 / (2.0 * A * (A + me1))  # 1 - k^2 without cancellation
            cphi = (A - x) / (A + x)
            sphi = 2.0 * np.sqrt(A * x) / (A + x)
            half = _legendre_F(sphi, cphi**2, k2c * sphi**2)
            neg = cphi < 0.0
            if neg.any():
                half[neg] = 2.0 * elliprf(0.0, k2c[neg], 1.0) - half[neg]
            out[cplx] = half / np.sqrt(A)
    return out


def _pick(a, mask):
    return np.broadcast_to(a, mask.shape)[mask]


def sweep_from_turning_point(orb: Orbit, u, sqrt_gap) -> np.ndarray:
    """F(e2) - F(u): the angle swept between inverse radius u and the periapsis e2 (turning orbits),
    given ``sqrt_gap`` = sqrt(e2 - u) (units of r_s^-1/2), which may be known more accurately than
    from e2 - u.

    Carlson's form of the integral from u to the root e2 (A = e2 - e1, B = e3 - e2, g = e2 - u):
    2 sqrt(g) R_F(A B, B (u - e1), A (B + g)). Unlike the difference of F it keeps full relative
    accuracy as u -> e2 (the angle ~ sqrt(g) there)."""
    u, sq = np.asarray(u, dtype=float), np.asarray(sqrt_gap, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = orb.e2 - orb.e1
        d = orb.delta
        out = 2.0 * sq * elliprf(a * d, d * (u - orb.e1), a * (d + sq * sq))
    return np.where(orb.real, out, np.nan)


def sweep_between(orb: Orbit, y, x, sqrt_gap_y, sqrt_gap_x) -> np.ndarray:
    """F(x) - F(y): the angle swept between inverse radii y < x <= e2 of a turning orbit, given
    sqrt(e2 - y) and sqrt(e2 - x) (see sweep_from_turning_point). Carlson's two-point form (DLMF
    19.29.4 with one linear factor constant), 2 (x - y) R_F(N12^2, N13^2, N14^2), has only positive
    terms: full relative accuracy for x - y -> 0 and next to the periapsis, where the difference of F
    (or of sweep_from_turning_point) cancels."""
    y, x = np.asarray(y, dtype=float), np.asarray(x, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        x1, y1 = np.sqrt(x - orb.e1), np.sqrt(y - orb.e1)
        x2, y2 = np.asarray(sqrt_gap_x, dtype=float), np.asarray(sqrt_gap_y, dtype=float)
        x3, y3 = np.sqrt(orb.delta + x2 * x2), np.sqrt(orb.delta + y2 * y2)
        n12 = x1 * x2 * y3 + y1 * y2 * x3
        n13 = x1 * x3 * y2 + y1 * y3 * x2
        n14 = x1 * y2 * y3 + y1 * x2 * x3
        out = 2.0 * (x - y) * elliprf(n12 * n12, n13 * n13, n14 * n14)
    return np.where(orb.real, out, np.nan)


def sweep_to_turning_point(orb: Orbit) -> np.ndarray:
    """F(e2): the angle swept from e1 to the periapsis e2 (turning orbits only; NaN otherwise)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        e31 = orb.e3 - orb.e1
        out = 2.0 / np.sqrt(e31) * elliprf(0.0, orb.delta / e31, 1.0)
    return np.where(orb.real, out, np.nan)


# --------------------------------------------------------------------------------------------------
# Light travel time
# --------------------------------------------------------------------------------------------------
_GL_ORDER = 12
_GL_X, _GL_W = roots_legendre(_GL_ORDER)


def _logit(u):
    return np.log(u) - np.log1p(-u)


_U_FAR = 0.1
"""Far legs: the part of a leg with u < min(_U_FAR, 0.5/b) is timed by :func:`_far_time`."""
_HALVE_X = 2.4
"""Turning legs: a segment next to the periapsis closer than this (in half-widths) to the pole of the
integrand at u = 0 is halved (see :func:`_leg_time`)."""


def travel_time(orb: Orbit, u_a, u_b, *, r_a=None, r_b=None, sqrt_gap=None,
                logit_step: float = 0.75, v_step: float = 1.5) -> np.ndarray:
    """Coordinate light travel time (units of r_s/c) along one monotone leg between inverse radii
    ``u_a`` and ``u_b`` (either order; for turning orbits both must be <= e2, the periapsis).

    dt = integral |dphi| / (b u^2 (1-u)). The far part of the leg, u < u_far = min(0.1, 0.5/b), is
    (r_far - 1/u_far) + ln(u_far r_far) plus the integral of a smooth bounded remainder
    (:func:`_far_time`), so far points keep full relative accuracy up to r = 1.8e308. Legs much
    shorter than their distance from u = 0, the horizon and the roots of P are one Gauss-Legendre
    segment in u itself (short legs next to the periapsis too, given ``sqrt_gap``). On the rest
    the substitution u = e2 - delta sinh^2(v) (turning orbits, dphi = 2 dv/sqrt(u-e1)) or
    u = m + n sinh(v) (plunging, dphi = dv/sqrt(u-e1)) makes the integrand smooth even next to turning
    points and for rays that wind around the photon sphere. Quadrature: Gauss-Legendre (order 12) on
    the union of segments uniform in logit(u) (width at most ``logit_step``, for points next to the
    horizon) and segments uniform in v (width at most ``v_step``, for rays that wind near the photon
    sphere).

    ``r_a``, ``r_b`` (optional): the radii 1/u_a, 1/u_b themselves (pass them for far points: 1/u does
    not round back to r, and overflows, for r near the largest double). ``sqrt_gap`` (optional, turning
    orbits): a pair (sqrt(e2 - u_a), sqrt(e2 - u_b)), NaN where unknown, for legs next to the
    periapsis, where e2 - u can be far below the rounding of e2 (their time is ~ sqrt(e2 - u)).
    """
    u_a = np.asarray(u_a, dtype=float)
    u_b = np.asarray(u_b, dtype=float)
    shape = np.broadcast(u_a, u_b, orb.e1).shape
    lo = np.broadcast_to(np.minimum(u_a, u_b), shape).ravel()
    hi = np.broadcast_to(np.maximum(u_a, u_b), shape).ravel()
    out = np.zeros(lo.size)
    fields = {f: np.broadcast_to(getattr(orb, f), shape).ravel()
              for f in ("e1", "real", "e2", "e3", "delta", "m", "n")}
    todo = hi > lo
    gap_lo = gap_hi = None
    if sqrt_gap is not None:
        g_a, g_b = (np.broadcast_to(np.asarray(g, dtype=float), shape).ravel() for g in sqrt_gap)
        swap = np.broadcast_to(u_a > u_b, shape).ravel()
        gap_lo, gap_hi = np.where(swap, g_b, g_a), np.where(swap, g_a, g_b)
        with np.errstate(invalid="ignore"):
            todo |= gap_lo > gap_hi  # a leg next to the periapsis can be shorter than the rounding of e2
    # far part of the leg (u < u_far, where S = b sqrt(P) >= sqrt(3)/2)
    e1 = fields["e1"]
    with np.errstate(invalid="ignore"):
        u_far = np.minimum(_U_FAR, 0.5 * (-e1 * np.sqrt(1.0 - e1)))
        far = todo & (lo < u_far)
    sel = np.flatnonzero(far)
    if sel.size:
        with np.errstate(divide="ignore"):
            r_a = 1.0 / u_a if r_a is None else r_a
            r_b = 1.0 / u_b if r_b is None else r_b
            r_lo = np.broadcast_to(np.where(u_a <= u_b, r_a, r_b), shape).ravel()[sel]
            r_hi = np.broadcast_to(np.where(u_a <= u_b, r_b, r_a), shape).ravel()[sel]
            end = hi[sel] <= u_far[sel]
            r_hi = np.where(end, r_hi, 1.0 / u_far[sel])
        out[sel] = _far_time(lo[sel], np.where(end, hi[sel], u_far[sel]), r_lo, r_hi, e1[sel])
        lo = lo.copy()
        lo[sel] = np.minimum(hi[sel], u_far[sel])
        todo = hi > lo
        if gap_lo is not None:
            gap_lo[sel] = np.nan  # the near part of a far leg starts at u_far, not at the gap
            gap_hi = np.where(hi > lo, gap_hi, np.nan)
    # legs much shorter than their distance from u = 0, the horizon and the roots of P, where S is
    # not small (S^2 has slope <= 2 b^2 u): one Gauss-Legendre segment in u itself (the difference of
    # logit(u) or v at the ends would cancel)
    length = 40.0 * (hi - lo)
    sel = np.flatnonzero(todo & (length > 0.0) & (length <= np.minimum(lo, 1.0 - hi)))
    if sel.size:
        with np.errstate(invalid="ignore", divide="ignore"):
            b2 = 1.0 / (e1[sel] * e1[sel] * (1.0 - e1[sel]))
            l_s, h_s = lo[sel], hi[sel]
            s2_min = 1.0 - b2 * np.maximum(l_s * l_s * (1.0 - l_s), h_s * h_s * (1.0 - h_s))
            ok = (s2_min >= 1e-3) & (length[sel] * b2 * h_s <= s2_min)
        sel = sel[ok]
        out[sel] += _short_leg_time_s(lo[sel], hi[sel], b2[ok])
        todo = todo.copy()
        todo[sel] = False
    # Steep plunging rays (far from the critical orbit): integrate in logit(u) directly, where
    # dt = dlogit / (u sqrt(1 - b^2 u^2 (1-u))) is smooth, with no cancellation as b -> 0.
    steep = todo & ~fields["real"] & (fields["n"] >= 0.5)
    sel = np.flatnonzero(steep)
    if sel.size:
        out[sel] += _leg_time_steep(lo[sel], hi[sel], fields["e1"][sel], logit_step)
    if gap_hi is not None:
        # legs much shorter than their distance w = e2 - hi from the periapsis (next to the tangent ray
        # at hi): in v = asinh(sqrt((e2 - u)/delta)) both ends round alike, so integrate in u itself,
        # where 1/sqrt(P) is smooth (its singularity lies w away), with e2 - u = w + (hi - u) exact
        with np.errstate(invalid="ignore"):
            short = (todo & fields["real"] & np.isfinite(gap_lo) & (gap_hi > 0.0)
                     & (gap_hi * gap_hi >= 3.0 * (hi - lo)))
        sel = np.flatnonzero(short)
        if sel.size:
            out[sel] += _short_leg_time(lo[sel], hi[sel], gap_hi[sel], e1[sel], fields["delta"][sel])
            todo = todo & ~short
    for real in (True, False):
        sel = np.flatnonzero((fields["real"] == real) & todo & ~steep)
        if sel.size:
            gaps = None if gap_lo is None or not real else (gap_lo[sel], gap_hi[sel])
            out[sel] += _leg_time(real, lo[sel], hi[sel], *(fields[f][sel] for f in
                                  ("e1", "e2", "delta", "m", "n")), logit_step, v_step, sqrt_gap=gaps)
    return out.reshape(shape)


def _far_time(lo, hi, r_lo, r_hi, e1):
    """Travel time between inverse radii lo < hi <= min(0.1, 0.5/b) (r_lo = 1/lo, r_hi = 1/hi, exact
    where they are the leg's ends).

    With S = b sqrt(P) = sqrt(1 - b^2 u^2 (1-u)) the integrand du / (u^2 (1-u) S) splits, by
    1/(u^2 (1-u)) = 1/u^2 + 1/u + 1/(1-u) and 1/S - 1 = b^2 u^2 (1-u) / (S (1+S)), into
    1/u^2 + 1/u (integrated exactly: r_lo - r_hi + ln(r_lo / r_hi)) plus the bounded remainder
    g(u) = b^2 (1 - u^2) / (S (1+S)) + 1 / ((1-u) S). On this range S >= sqrt(3)/2 and g is analytic
    (its nearest singularities, the roots of P, lie about 1/b away), so 12-point Gauss-Legendre
    gives it to rounding. No cancellation at any distance (u = e2 - delta sinh^2(v) of the near part
    loses ~1e-16 e2 r of relative accuracy far out, and u - e1 goes negative for r >~ 1e15)."""
    b2 = 1.0 / (e1 * e1 * (1.0 - e1))
    half = 0.5 * (hi - lo)
    u = (lo + half)[:, None] + half[:, None] * _GL_X
    s = np.sqrt(1.0 - b2[:, None] * u * u * (1.0 - u))
    g = b2[:, None] * (1.0 - u * u) / (s * (1.0 + s)) + 1.0 / ((1.0 - u) * s)
    dr = r_lo - r_hi
    return dr + np.log1p(dr / r_hi) + np.einsum("ij,j->i", g, _GL_W) * half


def _short_leg_time_s(lo, hi, b2):
    """Travel time of a short leg [lo, hi] on which S = sqrt(1 - b^2 u^2 (1-u)) is not small:
    12-point Gauss-Legendre in u of 1/(u^2 (1-u) S)."""
    half = 0.5 * (hi - lo)
    u = (lo + half)[:, None] + half[:, None] * _GL_X
    integrand = 1.0 / (u * u * (1.0 - u) * np.sqrt(1.0 - b2[:, None] * u * u * (1.0 - u)))
    return np.einsum("ij,j->i", integrand, _GL_W) * half


def _short_leg_time(lo, hi, sqrt_gap_hi, e1, delta):
    """Travel time of a turning orbit's leg [lo, hi] with hi - lo <= (e2 - hi)/3 (e2 - hi =
    sqrt_gap_hi^2): 12-point Gauss-Legendre in u of 1/(b u^2 (1-u) sqrt(P)), P factored with
    e2 - u = (e2 - hi) + (hi - u)."""
    half = 0.5 * (hi - lo)
    t = (1.0 + _GL_X)[None, :] * half[:, None]  # u - lo
    u = lo[:, None] + t
    gap = (sqrt_gap_hi * sqrt_gap_hi)[:, None] + (2.0 * half[:, None] - t)
    p = (u - e1[:, None]) * gap * (delta[:, None] + gap)
    inv_b = -e1 * np.sqrt(1.0 - e1)
    integrand = 1.0 / (u * u * (1.0 - u) * np.sqrt(p))
    return inv_b * np.einsum("ij,j->i", integrand, _GL_W) * half


def _gauss_nodes(breaks):
    """Gauss-Legendre nodes and half-widths on the segments between consecutive columns of breaks."""
    a = breaks[:, :-1]
    h = 0.5 * (breaks[:, 1:] - a)
    return (a + h)[:, :, None] + h[:, :, None] * _GL_X, h


def _logit_breaks(lo, hi, logit_step):
    with np.errstate(invalid="ignore", divide="ignore"):
        l_lo, l_hi = _logit(lo), _logit(hi)
    span = np.nan_to_num(l_hi - l_lo, nan=0.0, posinf=0.0, neginf=0.0)
    n_logit = int(np.clip(np.ceil(np.max(span, initial=0.0) / logit_step), 1, 128))
    t = np.linspace(0.0, 1.0, n_logit + 1)
    return l_lo[:, None] + (l_hi - l_lo)[:, None] * t[None, :]


def _leg_time_steep(lo, hi, e1, logit_step):
    lam, h = _gauss_nodes(_logit_breaks(lo, hi, logit_step))
    u = 1.0 / (1.0 + np.exp(-lam))
    b2 = 1.0 / (e1 * e1 * (1.0 - e1))[:, None, None]
    integrand = 1.0 / (u * np.sqrt(1.0 - b2 * u * u * (1.0 - u)))
    return np.einsum("ijk,k,ij->i", integrand, _GL_W, h)


def _leg_time(real, lo, hi, e1, e2, delta, m, n, logit_step, v_step, sqrt_gap=None):
    """Travel time of regularised legs, elements grouped by how many segments they need.
    ``sqrt_gap`` (turning orbits, optional, NaN where unknown): sqrt(e2 - lo), sqrt(e2 - hi), see
    travel_time."""
    if real:
        def v_of_u(u, k):
            return np.arcsinh(np.sqrt(np.maximum(e2[k, None] - u, 0.0) / delta[k, None]))
    else:
        def v_of_u(u, k):
            return np.arcsinh((u - m[k, None]) / n[k, None])
    every = np.arange(lo.size)
    with np.errstate(invalid="ignore", divide="ignore"):
        l_span = np.nan_to_num(_logit(hi) - _logit(lo), nan=0.0, posinf=0.0, neginf=0.0)
        ends = v_of_u(np.stack([lo, hi], axis=1), every)
        if sqrt_gap is not None:
            for j, g in enumerate(sqrt_gap):
                ends[:, j] = np.where(np.isnan(g), ends[:, j], np.arcsinh(g / np.sqrt(delta)))
    v_span = np.nan_to_num(np.abs(ends[:, 1] - ends[:, 0]), nan=0.0, posinf=0.0)
    n_l = np.clip(np.ceil(l_span / logit_step), 1, 128).astype(np.int64)
    n_v = np.clip(np.ceil(v_span / v_step), 1, 64).astype(np.int64)
    halve = np.zeros(lo.size, dtype=bool)
    if real:
        # v ~ sqrt(e2 - u) stretches the segment next to the periapsis side (smallest v, at u = hi):
        # one reaching from near e2 down to ~e2/2 ends ~0.7 of the way to the pole of 1/u^2 at u = 0
        # (v0), where 12-point Gauss-Legendre loses up to ~1e-10 relative. Such segments (centre c,
        # half-width w with v0 - c < _HALVE_X w) are halved in logit(u).
        with np.errstate(invalid="ignore", divide="ignore"):
            u_1 = 1.0 / (1.0 + np.exp(-(_logit(hi) - l_span / n_l)))
            v_a = ends[:, 1]
            v_b = np.minimum(v_of_u(u_1[:, None], every)[:, 0], v_a + v_span / n_v)
            v_0 = np.arcsinh(np.sqrt(e2 / delta))
            halve = (v_0 - 0.5 * (v_a + v_b)) < _HALVE_X * 0.5 * (v_b - v_a)
    group = (n_l + halve) * 1000 + n_v
    out = np.empty(lo.size)
    inv_b = -e1 * np.sqrt(1.0 - e1)
    for g in np.unique(group):
        k = np.flatnonzero(group == g)
        nl, nv = int(g // 1000), int(g % 1000)
        t = np.linspace(0.0, 1.0, nl + 1)[None, :]
        if nl > 1 and halve[k].any():
            # nl - 1 uniform segments, the last (next to hi) halved
            t_h = np.append(np.linspace(0.0, 1.0, nl)[:-1], [(nl - 1.5) / (nl - 1), 1.0])
            t = np.where(halve[k, None], t_h[None, :], t)
        lam = _logit(lo[k])[:, None] + l_span[k, None] * t
        u_break = 1.0 / (1.0 + np.exp(-lam))
        u_break[:, 0], u_break[:, -1] = lo[k], hi[k]
        v_logit = v_of_u(u_break, k)
        v_logit[:, 0], v_logit[:, -1] = ends[k, 0], ends[k, 1]
        if nv > 1:
            v_lo, v_hi = v_logit[:, :1], v_logit[:, -1:]
            tv = np.linspace(0.0, 1.0, nv + 1)[1:-1]
            v_logit = np.sort(np.concatenate([v_logit, v_lo + (v_hi - v_lo) * tv[None, :]], axis=1), axis=1)
        v, h = _gauss_nodes(v_logit)
        sh = np.sinh(v)
        if real:
            # (0 < u <= e2 < 2/3 on these legs: a node a hair outside the leg is harmless)
            u = e2[k, None, None] - delta[k, None, None] * sh * sh
        else:
            u = m[k, None, None] + n[k, None, None] * sh
            # rounding can put a node a hair outside the leg, e.g. onto u = 1 for a target one ulp off
            # the horizon, where the integrand is infinite
            u = np.minimum(np.maximum(u, lo[k, None, None]), hi[k, None, None])
        integrand = 1.0 / (u * u * (1.0 - u) * np.sqrt(u - e1[k, None, None]))
        out[k] = (2.0 if real else 1.0) * inv_b[k] * np.einsum("ijk,k,ij->i", integrand, _GL_W, np.abs(h))
    return out


def radial_travel_time(u_a, u_b, *, r_a=None, r_b=None) -> np.ndarray:
    """Light travel time (units of r_s/c) of a radial ray between inverse radii u_a and u_b:
    |Delta r + ln((r_b - 1)/(r_a - 1))|, r = 1/u.

    ``r_a``, ``r_b`` (optional): the radii themselves, used instead of 1/u (pass them for far points:
    1/u overflows to inf for a subnormal u = 1/r, i.e. r near the largest double)."""
    with np.errstate(divide="ignore"):
        r_a = 1.0 / np.asarray(u_a, dtype=float) if r_a is None else np.asarray(r_a, dtype=float)
        r_b = 1.0 / np.asarray(u_b, dtype=float) if r_b is None else np.asarray(r_b, dtype=float)
        dr = r_b - r_a
        # ln((r_b - 1)/(r_a - 1)): as a difference of logs (no overflow of the ratio), or as
        # log1p(dr / (r_a - 1)) for r_b next to r_a (no cancellation)
        near = np.abs(dr) < 0.5 * (r_a - 1.0)
        log_ratio = np.where(near, np.log1p(np.where(near, dr, 0.0) / (r_a - 1.0)),
                             np.log(r_b - 1.0) - np.log(r_a - 1.0))
        return np.abs(dr + log_ratio)


# --------------------------------------------------------------------------------------------------
# The inner branch (u >= e3 of turning orbits: rays of an observer inside the photon sphere that climb
# to an apoapsis and fall in)
# --------------------------------------------------------------------------------------------------
def sweep_inner(orb: Orbit, u, gap=None) -> np.ndarray:
    """Angle swept from the apoapsis e3 of turning orbits down to inverse radius u >= e3: Carlson's
    two-point form of integral_{e3}^{u} du / sqrt((u - e1)(u - e2)(u - e3)) (DLMF 19.29.4 with the lower
    limit at a root and a fourth factor 1), all terms positive. ``gap``: u - e3 where it is known more
    accurately than from the difference."""
    u = np.asarray(u, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        x3 = np.sqrt(np.maximum(u - orb.e3 if gap is None else gap, 0.0))
        y1, y2 = np.sqrt(orb.e3 - orb.e1), np.sqrt(orb.delta)
        x1, x2 = np.sqrt(u - orb.e1), np.sqrt(u - orb.e2)
        out = 2.0 * x3 * elliprf((y1 * y2) ** 2, (x1 * y2) ** 2, (y1 * x2) ** 2)
    return np.where(x3 > 0.0, out, 0.0)


_GL32 = np.polynomial.legendre.leggauss(32)


def travel_time_inner(orb: Orbit, u) -> np.ndarray:
    """Coordinate time (r_s/c) from the apoapsis e3 of inner-branch orbits to inverse radius u >= e3
    (< 1): integral e dx / (x^2 (1 - x) sqrt(P(x))), with x = e3 + delta sinh^2(v), delta = e3 - e2,
    which removes the root at e3 and the near double root e2 of orbits that wind:
    dt = 2 e dv / (x^2 (1 - x) sqrt(x - e1)). Gauss-Legendre, 32 nodes on each of up to 64 segments of
    at most 0.5 in v."""
    u = np.asarray(u, dtype=float)
    e = orb.inv_b
    delta = orb.delta
    with np.errstate(invalid="ignore", divide="ignore"):
        v_end = np.arcsinh(np.sqrt(np.maximum(u - orb.e3, 0.0) / delta))
    n_seg = np.clip(np.ceil(v_end / 0.5), 1, 64).astype(int)
    x_gl, w_gl = _GL32
    out = np.zeros(u.size)
    for k in range(int(n_seg.max()) if n_seg.size else 0):
        a = v_end * k / n_seg
        b = v_end * (k + 1) / n_seg
        half = np.where(k < n_seg, 0.5 * (b - a), 0.0)
        v = (0.5 * (a + b))[:, None] + half[:, None] * x_gl[None, :]
        x = orb.e3[:, None] + delta[:, None] * np.sinh(v) ** 2
        f = 2.0 * e[:, None] / (x * x * (1.0 - x) * np.sqrt(x - orb.e1[:, None]))
        out += half * (f @ w_gl)
    return out
