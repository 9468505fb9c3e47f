"""One table of light orbits for every observer radius, and the connecting rays read from it.

Units: lengths in r_s, c = 1 (times in r_s/c), angles in radians. Conventions as in
:mod:`lutgen.solver` (observer static at (r_obs, phi = 0); xi from the outward radial direction in the
observer's static frame; order 1 sweeps phi, order 2 sweeps 2*pi - phi).

Every light orbit in the plane obeys (du/dtheta)^2 = P(u) = e^2 - u^2 (1 - u), u = 1/r, e = 1/b, and
u'' = -u + 3/2 u^2 in the swept angle theta. An orbit is therefore one function u(theta) of one
parameter, whatever observer looks along it. :class:`OrbitTable` holds these functions, each from
the orbit's own reference point (the point nearest the photon sphere), in three kinds:

* ``T`` (b > b_crit, outside the photon sphere): from the periapsis (theta = 0) out to infinity
  (theta = H, the half sweep); rows labelled by rho = ln((b / b_crit)^2 - 1);
* ``P`` (b < b_crit, the rays that cross the photon sphere): from infinity (u = 0) through the photon
  sphere (theta = 0) to the horizon (u = 1); rows labelled by rho = ln((b_crit / b)^2 - 1) (so the
  nearly radial rays, whose theta range shrinks like b, are as finely sampled in ln b);
* ``I`` (b > b_crit, inside the photon sphere): from the apoapsis (theta = 0) down to the horizon;
  rows labelled as ``T``.

Near the critical orbit (rho -> -inf) the orbits wind about the photon sphere; rows are uniform in
rho (a fixed step in the logarithm of the distance from the critical impact parameter), so the
winding, an exponential in theta and rho, is smooth in the table's coordinates. Columns are uniform in
theta over the row's range. Each node holds u (times b for ``T``, where u ~ 1/b) and the
travel-time remainder J = integral dtheta / (e + |u'|) times e/L (L the row's theta range): along any
piece of orbit on which u is monotone the coordinate time is |r*(u_2) - r*(u_1)| + |J_2 - J_1|, with
the tortoise coordinate r* = r + ln(r - 1) (dt - |dr*| = dtheta / (e + |du/dtheta|) exactly), so the
growth of the time to infinity and its logarithm at the horizon are closed forms. The nodes are
integrated from each row's reference point (u'' = -u + 3/2 u^2 with RK4, started exactly at the
periapsis, apoapsis or the photon sphere crossing, where an orbit that winds is still determined to
full precision by its label).

:class:`RayMap` reads the connecting rays of one observer from the table. Along the observer's rays,
ordered by xi from 0 to pi in four segments (outward rays that cross the photon sphere, outward and
inward turning rays, inward rays that cross it; the turning rays are of kind ``T`` for an observer
outside the photon sphere and ``I`` inside it), the radius a ray has reached after sweeping the
target's angle, less the target's radius, changes sign exactly once: at the connecting ray (rays
that escaped before count as below, rays that fell in as above). A point's ray is bracketed between
two of the table's rows (1-D lookups along rows): four rows about the ray, in the segment a per-radius
seed index over the whole sky chooses, bracket it wherever f changes sign among them (a sign change
anywhere is the one); elsewhere the point's segment follows from the signs at the segments' ends and
a search over its rows (several per pass) brackets it. The ray is then found by a Newton step with
the slope of the rows' cubic, and secant steps where needed, in d = |xi - crit| with the bicubic
interpolation (:meth:`RayMap.solve`). No table depends on the observer: a camera at a new radius
costs a few 1-D arrays (its own phase on each ray, the seed index), not a table build. docs/inside.md
describes it with its figures.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import elliprf

from . import orbit as _orb
from .lut import QUANTITIES, Lookup, _cubic_stencil

B_C = _orb.B_CRIT
E_C2 = 4.0 / 27.0  # e_crit^2 = 1 / b_crit^2

RHO_MIN = -32.0
"""Rows start at rho = -32: |b^2 / b_crit^2 - 1| = 1.3e-14, orbits that wind about 16 rad on either side of
the photon sphere before they leave it (more than a ray of order 1 or 2 sweeps from an observer beyond
1.5001 r_s or inside 1.4999 r_s). Closer to the critical orbit the rounding of the start, amplified by
e^theta, reaches 1e-8."""

RHO_MAX_T = 32.0
"""Largest label of kind T (b = 2.3e7 r_s): observers out to about 1e7 r_s."""

RHO_MAX_P = 36.0
"""Largest label of kind P (b = 4e-8 r_s): rays within 4e-8 b_crit of the radial one, below the
double-precision resolution of any target's angle worth imaging."""

RHO_MAX_I = 5.0
"""Largest label of kind I (b = 32 r_s): observers down to r_obs = 1.001 r_s."""

R_OBS_MIN = 1.001
"""Innermost observer radius (r_s) the table serves."""

DEFAULT_STEP = 1.0 / 16.0
"""Row spacing in rho."""

DEFAULT_COLUMNS = 577
"""Columns (uniform in theta over a row's range)."""

SUBSTEPS = 6
"""RK4 steps per column interval when the table is built."""


# ------------------------------------------------------------------------------------------------
# The orbits of a row label
# ------------------------------------------------------------------------------------------------
def impact_parameter(kind: str, rho) -> np.ndarray:
    """b (r_s) of row labels ``rho`` of kind "T"/"I" (b > b_crit) or "P" (b < b_crit)."""
    rho = np.asarray(rho, dtype=float)
    if kind == "P":
        return B_C / np.sqrt(1.0 + np.exp(rho))
    return B_C * np.sqrt(1.0 + np.exp(rho))


def label_of_b(kind: str, b) -> np.ndarray:
    """The row label rho of impact parameters b (r_s); inverse of :func:`impact_parameter`."""
    q = (np.asarray(b, dtype=float) / B_C) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log(1.0 / q - 1.0) if kind == "P" else np.log(q - 1.0)


def _far_sigma_e1(b):
    """(sigma, e1) of lutgen.orbit.orbit_from_b for turning orbits with impact parameters b > b_crit
    (r_s): the same operations on the same numbers (the trigonometric form, e1 polished by Newton's
    method where sigma > 0.5), without the hyperbolic branch or the roots that follow from them."""
    with np.errstate(divide="ignore", invalid="ignore"):
        y = 4.0 * (b - B_C) * (b + B_C) / (b * b)
        sq = 0.5 * np.sqrt(np.abs(y))
        sigma = 4.0 * np.sin(np.arcsin(np.minimum(sq, 1.0)) / 3.0) ** 2
    e1 = (sigma - 1.0) / 3.0
    big = np.flatnonzero(sigma > 0.5)
    if big.size:
        bb = b.take(big)
        c = 1.0 / (bb * bb)
        t = 1.0 / bb
        e = np.where(bb > 1e3, t * (-1.0 + t * (0.5 - 0.625 * t)), e1.take(big))
        for _ in range(3):
            e = e - (e * e * (1.0 - e) - c) / (e * (2.0 - 3.0 * e))
        e1[big] = e
        sigma[big] = 1.0 + 3.0 * e
    return sigma, e1


def _turning_sigma_e1(rho):
    """(sigma, e1) of turning orbits (kinds T, I) with labels rho: from rho next to the critical orbit,
    as lutgen.orbit.orbit_from_b from b for rho > 0 (far orbits, whose e1 ~ -1/b it polishes)."""
    x = np.exp(rho)
    y = 4.0 * x / (1.0 + x)
    sigma = 4.0 * np.sin(np.arcsin(np.minimum(0.5 * np.sqrt(y), 1.0)) / 3.0) ** 2
    e1 = (sigma - 1.0) / 3.0
    far = np.flatnonzero(rho > 0.0)
    if far.size:
        sigma[far], e1[far] = _far_sigma_e1(B_C * np.sqrt(1.0 + x.take(far)))
    return sigma, e1


def _orbits(kind, rho) -> _orb.Orbit:
    """Roots of P(u) for labels rho, accurate next to the critical orbit (from rho, not from b)."""
    rho = np.asarray(rho, dtype=float)
    if kind == "P":  # y = 4 (b^2 - b_c^2) / b^2 = -4 e^rho
        sigma = -4.0 * np.sinh(np.arcsinh(np.sqrt(np.exp(rho))) / 3.0) ** 2
        return _orb._from_sigma_e1(sigma, (sigma - 1.0) / 3.0)
    return _orb._from_sigma_e1(*_turning_sigma_e1(rho))


def _reference_u(kind, rho) -> np.ndarray:
    """u at the reference point of turning orbits of kind "T" (the periapsis, e2) or "I" (the apoapsis,
    e3) with labels rho: the same numbers as :func:`_orbits`'s roots, only the one needed."""
    sigma, e1 = _turning_sigma_e1(np.asarray(rho, dtype=float))
    one_m = 1.0 - e1
    delta = np.sqrt(one_m * sigma)
    e2 = -2.0 * e1 * one_m / (one_m + delta)
    return e2 if kind == "T" else e2 + delta


_sweep_inner = _orb.sweep_inner


SINGLE_PHASE_RANGE = (1.1, 2.0)
"""Observers (r_s) at or inside the first or at or beyond the second radius get the crossing rays' phase
from one elliptic integral (:func:`_crossing_phase_single`); between them, next to the photon sphere,
from two (:func:`_crossing_phase_pair`), whose difference keeps full accuracy there."""


def _crossing_phase(orb, uo) -> np.ndarray:
    """The angle orbits of kind P (complex roots, ``orb`` from :func:`_orbits`) sweep from the photon
    sphere to inverse radius ``uo`` (radians): :func:`_crossing_phase_single` away from the photon
    sphere (SINGLE_PHASE_RANGE), :func:`_crossing_phase_pair` next to it."""
    lo, hi = SINGLE_PHASE_RANGE
    if 1.0 / lo <= uo or uo <= 1.0 / hi:
        return _crossing_phase_single(orb, uo)
    return _crossing_phase_pair(orb, uo)


def _crossing_phase_single(orb, uo) -> np.ndarray:
    """The angle orbits of kind P (complex roots, ``orb`` from :func:`_orbits`) sweep from the photon
    sphere to inverse radius ``uo`` (radians): lutgen.orbit.sweep(orb, uo) - sweep(orb, 2/3), as one
    elliptic integral. Both are F(phi|k^2) / sqrt(A) in Legendre's form (cos phi = (A - x)/(A + x),
    x = u - e1, amplitudes in [0, pi)); the addition theorem gives F(a) - F(c) = F(g) with
    sin g = (sin a cos c D_c - sin c cos a D_a) / E, cos g = (cos a cos c + sin a sin c D_a D_c) / E,
    D = sqrt(1 - k^2 sin^2), E = 1 - k^2 sin^2 a sin^2 c, and g in (-pi, pi) (F(a) - F(c) lies in
    (-2K, 2K)); F(g) by Carlson's R_F, 2K - F(pi - |g|) where cos g < 0, odd in g. One R_F per orbit
    (and R_F(0, 1 - k^2, 1) = K where cos g < 0) instead of two; 1 - k^2 is formed without
    cancellation and D^2 = cos^2 + (1 - k^2) sin^2. Next to the photon sphere both amplitudes approach
    pi/2 as k -> 1 and sin g cancels: used only beyond SINGLE_PHASE_RANGE (within 1e-12 rad of the
    pair there, tests/test_rays.py)."""
    a, me1, n = orb.e1, orb.m - orb.e1, orb.n
    big_a = np.sqrt(me1 ** 2 + n ** 2)
    k2c = n ** 2 / (2.0 * big_a * (big_a + me1))
    k2 = 1.0 - k2c
    x_o, x_c = uo - a, _orb.U_PHOTON - a
    c_o, c_c = (big_a - x_o) / (big_a + x_o), (big_a - x_c) / (big_a + x_c)
    s_o, s_c = 2.0 * np.sqrt(big_a * x_o) / (big_a + x_o), 2.0 * np.sqrt(big_a * x_c) / (big_a + x_c)
    so2, sc2 = s_o * s_o, s_c * s_c
    dd_o, dd_c = np.sqrt(c_o * c_o + k2c * so2), np.sqrt(c_c * c_c + k2c * sc2)
    den = 1.0 - k2 * so2 * sc2
    sg = (s_o * c_c * dd_c - s_c * c_o * dd_o) / den
    cg = (c_o * c_c + s_o * s_c * dd_o * dd_c) / den
    c2 = cg * cg
    s_abs = np.abs(sg)
    half = s_abs * elliprf(c2, c2 + k2c * s_abs * s_abs, 1.0)
    neg = np.flatnonzero(cg < 0.0)
    if neg.size:
        half[neg] = 2.0 * elliprf(0.0, k2c.take(neg), 1.0) - half.take(neg)
    return np.copysign(half, sg) / np.sqrt(big_a)


def _crossing_phase_pair(orb, uo) -> np.ndarray:
    """The angle orbits of kind P (complex roots, ``orb`` from :func:`_orbits`) sweep from the photon
    sphere to inverse radius ``uo``: lutgen.orbit.sweep(orb, uo) - sweep(orb, 2/3) with the same
    operations on the same numbers (Legendre's form of Carlson's R_F), the terms that do not depend
    on u formed once and no masks (every P orbit has complex roots)."""
    a, me1, n = orb.e1, orb.m - orb.e1, orb.n
    big_a = np.sqrt(me1 ** 2 + n ** 2)
    k2c = n ** 2 / (2.0 * big_a * (big_a + me1))
    x = np.array([[uo], [_orb.U_PHOTON]]) - a  # (2, N): the observer, the photon sphere
    cphi = (big_a - x) / (big_a + x)
    sphi = 2.0 * np.sqrt(big_a * x) / (big_a + x)
    c2 = cphi ** 2
    half = sphi * elliprf(c2, c2 + k2c * sphi ** 2, 1.0)
    neg = np.flatnonzero(cphi.reshape(-1) < 0.0)
    if neg.size:
        k_neg = np.broadcast_to(k2c, cphi.shape).reshape(-1).take(neg)
        half.reshape(-1)[neg] = 2.0 * elliprf(0.0, k_neg, 1.0) - half.reshape(-1).take(neg)
    out = half / np.sqrt(big_a)
    return out[0] - out[1]


def row_ranges(kind, rho):
    """(theta_start, L, e, u0): the theta range [theta_start, theta_start + L] of rows ``rho`` (the
    reference point at theta = 0), e = 1/b and the reference point's u."""
    rho = np.asarray(rho, dtype=float)
    orb = _orbits(kind, rho)
    e = orb.inv_b
    if kind == "T":
        h = _orb.sweep_from_turning_point(orb, np.zeros(rho.shape), np.sqrt(orb.e2))
        return np.zeros(rho.shape), h, e, orb.e2
    if kind == "I":
        return np.zeros(rho.shape), _sweep_inner(orb, np.ones(rho.shape)), e, orb.e3
    f0 = _orb.sweep(orb, np.zeros(rho.shape))
    fc = _orb.sweep(orb, np.full(rho.shape, _orb.U_PHOTON))
    f1 = _orb.sweep(orb, np.ones(rho.shape))
    return -(fc - f0), f1 - f0, e, np.full(rho.shape, _orb.U_PHOTON)


# ------------------------------------------------------------------------------------------------
# The table
# ------------------------------------------------------------------------------------------------
def _rk4(u, w, j, h, e, sign):
    """One RK4 step of (u, w = du/dtheta, J) over theta-steps h (arrays), J' = 1/(e + sign * w)."""
    def f(u, w):
        return w, u * (1.5 * u - 1.0), 1.0 / (e + sign * w)
    k1 = f(u, w)
    k2 = f(u + 0.5 * h * k1[0], w + 0.5 * h * k1[1])
    k3 = f(u + 0.5 * h * k2[0], w + 0.5 * h * k2[1])
    k4 = f(u + h * k3[0], w + h * k3[1])
    c = h / 6.0
    return (u + c * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]),
            w + c * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]),
            j + c * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2]))


def _integrate(u, w, h_col, n_steps, e, sign, record, start_col, direction, first_h):
    """Integrate rows from their reference point through ``n_steps`` column intervals, the first of
    length ``first_h`` (theta), the rest ``h_col``; ``record(cols, rows, u, w, j)`` gets each column.
    Rows whose columns run out get zero steps (they stop)."""
    n_rows = u.size
    j = np.zeros(n_rows)
    col = start_col.copy()
    rows = np.arange(n_rows)
    for s in range(n_steps):
        active = (col >= 0) & (col < record.n_cols)
        if not active.any():
            break
        h = np.where(active, first_h if s == 0 else h_col, 0.0) * direction
        for _ in range(SUBSTEPS):
            u, w, j = _rk4(u, w, j, h / SUBSTEPS, e, sign)
        record(col[active], rows[active], u[active], w[active], j[active])
        col = col + direction


class _Record:
    def __init__(self, n_rows, n_cols):
        self.n_cols = n_cols
        self.u = np.full((n_rows, n_cols), np.nan)
        self.w = np.full((n_rows, n_cols), np.nan)
        self.j = np.full((n_rows, n_cols), np.nan)

    def __call__(self, cols, rows, u, w, j):
        self.u[rows, cols], self.w[rows, cols], self.j[rows, cols] = u, w, j


def _range_scale(kind, b):
    """The factor the stored theta ranges of kind ``kind`` are divided by (so that they are smooth in rho):
    T 1, P b (start and length ~ b as b -> 0), I 1/b (length ~ 2/b as b -> inf)."""
    if kind == "T":
        return np.ones_like(b)
    return b if kind == "P" else 1.0 / b


def _stencil(g, n):
    """As :func:`lutgen.lut._cubic_stencil` (first node (N,), cubic Lagrange weights (4, N) for fractional
    grid coordinates g in [0, n - 1]), with fewer array passes (shared products)."""
    i0 = np.minimum(np.maximum(g.astype(np.int64) - 1, 0), n - 4)  # g >= 0: truncation is floor
    t = g - i0
    t1, t2, t3 = t - 1.0, t - 2.0, t - 3.0
    a, c = t1 * t2, t * t3
    w = np.empty((4, g.size))
    np.multiply(a, t3, out=w[0])
    w[0] *= -1.0 / 6.0
    np.multiply(c, t2, out=w[1])
    w[1] *= 0.5
    np.multiply(c, t1, out=w[2])
    w[2] *= -0.5
    np.multiply(a, t, out=w[3])
    w[3] *= 1.0 / 6.0
    return i0, w


def _clip(x, lo, hi):
    return np.minimum(np.maximum(x, lo), hi)


def _derivative_weights(g, n):
    """d/dg of the cubic Lagrange weights of :func:`lutgen.lut._cubic_stencil` (4, N)."""
    i0 = np.clip(np.floor(g).astype(np.int64) - 1, 0, n - 4)
    t = g - i0
    d = np.empty((4, g.size))
    d[0] = -((t - 2.0) * (t - 3.0) + (t - 1.0) * (t - 3.0) + (t - 1.0) * (t - 2.0)) / 6.0
    d[1] = ((t - 2.0) * (t - 3.0) + t * (t - 3.0) + t * (t - 2.0)) / 2.0
    d[2] = -((t - 1.0) * (t - 3.0) + t * (t - 3.0) + t * (t - 1.0)) / 2.0
    d[3] = ((t - 1.0) * (t - 2.0) + t * (t - 2.0) + t * (t - 1.0)) / 6.0
    return d


@dataclass(eq=False)
class Kind:
    """One kind of orbit (T, P or I): rows uniform in rho from ``rho0`` with step ``step``, columns
    uniform in theta over each row's range [start, start + length] (stored divided by
    :func:`_range_scale`). ``u``: u (T: u b) at the nodes; ``j``: J e / L (see the module docstring);
    both (n_rows, n_cols) float64."""

    name: str
    rho0: float
    step: float
    start: np.ndarray
    length: np.ndarray
    u: np.ndarray
    j: np.ndarray

    @property
    def n_rows(self) -> int:
        return self.u.shape[0]

    @property
    def n_cols(self) -> int:
        return self.u.shape[1]

    @property
    def rho_max(self) -> float:
        return self.rho0 + self.step * (self.n_rows - 1)

    @property
    def rho(self) -> np.ndarray:
        """The rows' labels."""
        return self.rho0 + self.step * np.arange(self.n_rows)

    def evaluate(self, rho, theta, want_j=False):
        """u and, with ``want_j``, J (r_s/c) on the orbits of labels ``rho`` at angles ``theta`` from
        their reference points (arrays). Beyond a row's theta range the values continue linearly (an
        orbit that escaped is below u = 0, one that fell in above 1)."""
        n_r, n_c = self.n_rows, self.n_cols
        g = np.clip((rho - self.rho0) / self.step, 0.0, n_r - 1)
        i0, wr = _cubic_stencil(g, n_r)
        b = impact_parameter(self.name, rho)
        sc = _range_scale(self.name, b)
        ridx = i0[None, :] + np.arange(4)[:, None]
        st = (wr * self.start.take(ridx)).sum(0) * sc
        ln = (wr * self.length.take(ridx)).sum(0) * sc
        c = (theta - st) / ln * (n_c - 1)
        u = self._bicubic(self.u, i0, wr, c)
        if self.name == "T":
            u = u / b
        if not want_j:
            return u, None
        return u, self._bicubic(self.j, i0, wr, c) * ln * b

    def _bicubic(self, data, i0, wr, c):
        n_c = self.n_cols
        cc = np.clip(c, 0.0, n_c - 1)
        j0, wc = _cubic_stencil(cc, n_c)
        flat = data.reshape(-1)
        base = i0 * n_c + j0
        return _linear_tail(flat, base, n_c, c, cc, wr, _gather(flat, base, wr, wc, n_c))


def build_kind(name, rho_max, step=DEFAULT_STEP, n_cols=DEFAULT_COLUMNS, rho_min=RHO_MIN) -> Kind:
    """Integrate the orbits of one kind on its grid (see the module docstring)."""
    n_rows = int(round((rho_max - rho_min) / step)) + 1
    rho = rho_min + step * np.arange(n_rows)
    start, length, e, u0 = row_ranges(name, rho)
    rec = _Record(n_rows, n_cols)
    h_col = length / (n_cols - 1)
    if name in ("T", "I"):
        rec(np.zeros(n_rows, dtype=int), np.arange(n_rows), u0, np.zeros(n_rows), np.zeros(n_rows))
        sign = -1.0 if name == "T" else 1.0  # T: u falls as theta grows (w <= 0); I: u rises
        _integrate(u0.copy(), np.zeros(n_rows), h_col, n_cols - 1, e, sign, rec, np.ones(n_rows, dtype=int), 1,
                   h_col)
    else:
        w0 = np.sqrt(E_C2 * np.exp(rho))  # sqrt(e^2 - 4/27) at u = 2/3
        t_ref = -start / h_col  # the reference point's fractional column
        up = np.floor(t_ref).astype(int) + 1  # first column beyond it
        _integrate(u0.copy(), w0.copy(), h_col, n_cols, e, 1.0, rec, up, 1, (up - t_ref) * h_col)
        down = up - 1
        _integrate(u0.copy(), w0.copy(), h_col, n_cols, e, 1.0, rec, down, -1, (t_ref - down) * h_col)
    if name == "T":
        b = 1.0 / e
        rec.u *= b[:, None]
    rec.j *= (e / length)[:, None]
    sc = _range_scale(name, 1.0 / e)
    return Kind(name, float(rho_min), float(step), start / sc, length / sc, rec.u, rec.j)


TABLE_VERSION = 1
"""Bumped whenever the table's contents change (disk caches key on it)."""

_RHO_MAX = {"T": RHO_MAX_T, "P": RHO_MAX_P, "I": RHO_MAX_I}


class OrbitTable:
    """The three kinds of orbits (see the module docstring); built once, for every observer (about a
    second; ``nbytes`` about 26 MB). Deterministic: the same size gives a bit-identical table."""

    def __init__(self, step=DEFAULT_STEP, n_cols=DEFAULT_COLUMNS, kinds=None):
        self.step, self.n_cols = float(step), int(n_cols)
        self.kinds = kinds if kinds is not None else {
            k: build_kind(k, _RHO_MAX[k], step, n_cols) for k in ("T", "P", "I")}

    @staticmethod
    def shapes(step=DEFAULT_STEP, n_cols=DEFAULT_COLUMNS) -> dict:
        """{array name: shape} of :meth:`arrays` for a table of this size."""
        out = {}
        for k, mx in _RHO_MAX.items():
            n = int(round((mx - RHO_MIN) / step)) + 1
            out.update({f"{k}_start": (n,), f"{k}_length": (n,), f"{k}_u": (n, n_cols), f"{k}_j": (n, n_cols)})
        return out

    def arrays(self) -> dict:
        """The table as float64 arrays (for a disk cache); :meth:`from_arrays` reads them back exactly."""
        out = {}
        for k, kind in self.kinds.items():
            out.update({f"{k}_start": kind.start, f"{k}_length": kind.length, f"{k}_u": kind.u, f"{k}_j": kind.j})
        return out

    @classmethod
    def from_arrays(cls, arrays, step=DEFAULT_STEP, n_cols=DEFAULT_COLUMNS) -> "OrbitTable":
        kinds = {k: Kind(k, RHO_MIN, float(step), *(np.asarray(arrays[f"{k}_{a}"], dtype=np.float64)
                                                     for a in ("start", "length", "u", "j")))
                 for k in ("T", "P", "I")}
        return cls(step, n_cols, kinds)

    @property
    def nbytes(self) -> int:
        return sum(k.u.nbytes + k.j.nbytes for k in self.kinds.values())

    @property
    def parameters(self) -> dict:
        return dict(kind="orbits", step=self.step, n_cols=self.n_cols)


_TABLES: dict = {}


def orbit_table(step=DEFAULT_STEP, n_cols=DEFAULT_COLUMNS) -> OrbitTable:
    """The process's :class:`OrbitTable` of this size (built on first use, then kept)."""
    key = (float(step), int(n_cols))
    if key not in _TABLES:
        _TABLES[key] = OrbitTable(step, n_cols)
    return _TABLES[key]


# ------------------------------------------------------------------------------------------------
# One observer's connecting rays
# ------------------------------------------------------------------------------------------------
SEGMENT_NODES = 769
"""Nodes of an observer's 1-D arrays per segment (its phase on each orbit, uniform in z)."""

FAR_GAP_T = 1e-9
"""The segments of turning rays end this far (rad) from xi = pi/2 (the ray tangent at the observer)."""

R_MIN = 1.05
"""Default innermost target radius (r_s), as the wide tables'."""

NEAR = 0.3
"""Order-1 targets closer to the observer than this many times r_obs subtract the table's own error
at the observer (its value there less uo, from the same row stencil): next to the observer the
target's offset in u and the swept angle are both small."""

SECANT_DONE = 1e-6
"""A secant step shorter than this relative to d ends the iteration (the error left is of order its
square times the curvature: below 1e-11 relative)."""

CUBIC_STEPS = 2
"""Newton steps on the cubic through four rows (from the linear interpolation; quadratic convergence):
two leave its root far closer than the cubic itself is to the bicubic interpolation, which the Newton
step that follows corrects (with three, the same rays to 1e-12 on the bench's frames)."""

NEWTON_DONE = 1e-6
"""A first (Newton) step, with the slope of the cubic through four rows, shorter than this relative to d
ends the iteration: the error left is the step times the slope's relative error (below 1e-9 relative;
the figures of tests/test_rays.py and docs/tables.md are those of the full secant iteration)."""

TOL_D = 1e-12
"""Iterations stop when their step in d = |xi - crit| is below this relative to d."""

SEARCH_BUDGET = 4096
"""The search over a segment's rows (points the seed index's window does not bracket) evaluates up to
this many rows per pass over all its points: K = SEARCH_BUDGET / points rows each (at most
SEARCH_MAX_K, at least 1: bisection), so that a few points take two or three passes instead of ten
(each pass costs a fixed numpy overhead); the bracket found is the same (f changes sign once)."""

SEARCH_MAX_K = 63
"""The most rows per point in one pass of that search."""

PROBE_STEPS = np.array([1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512, 768, 1024, 1536])
"""The first pass of that search for points whose window lay on one side of the root (in the right
segment): rows this many rows beyond the window's last row towards the root (growing by at most 3/2,
so the second pass, a K-section of the bracket found, ends it). Most roots lie a row or two beyond
the window: one pass."""

INDEX_SWEEPS = 33
"""Angles of the seed index (uniform over [0, 2 pi], see :meth:`RayMap._setup_index`): each costs set-up
time per radius; fewer leave more points outside the window of four rows (to the segment tests and
the search)."""

INDEX_ROW_STEP = 8
"""The seed index holds every this-many-th row of a segment (and its last)."""

INDEX_SHIFT = 4.0
"""The seed index's angles follow one another in one sorted array, each shifted by this much more than
the one before (its values, u clipped to [-1, 2], span less)."""

_KINDS = ("T", "P", "I")


def check_any_observer(r_obs) -> float:
    """A static observer radius (r_s) the orbit table serves: R_OBS_MIN <= r_obs <= 1e7; ValueError else."""
    from .solver import static_observer_radius
    r = static_observer_radius(r_obs, f">= {R_OBS_MIN} r_s")
    if r < R_OBS_MIN or r > 1e7:
        raise ValueError(f"observer at r_obs = {r:.6g} r_s: the orbit table serves {R_OBS_MIN} <= r_obs <= 1e7 r_s")
    return r


class _Flat:
    """The orbit table's three kinds as one array of rows (same columns), for lookups that mix kinds:
    per kind its first row, label origin and count. ``uj``: each node's u (the stored u) and J as one
    complex number u + i J (row-major, flat), so that one ``take`` reads both (the interpolation
    weights are real: the sums' real and imaginary parts are those of u and of J, bit for bit)."""

    def __init__(self, table: OrbitTable):
        ks = [table.kinds[k] for k in _KINDS]
        self.n_cols = ks[0].n_cols
        self.uj = _complex(np.concatenate([k.u.reshape(-1) for k in ks]), np.concatenate([k.j.reshape(-1) for k in ks]))
        self.start = np.concatenate([k.start for k in ks])
        self.length = np.concatenate([k.length for k in ks])
        self.sl = _complex(self.start, self.length)  # both from one take per row
        self.offset = np.cumsum([0] + [k.n_rows for k in ks])[:-1]
        self.rho0 = np.array([k.rho0 for k in ks])
        self.step = ks[0].step
        self.n_rows = np.array([k.n_rows for k in ks])


def _complex(re, im) -> np.ndarray:
    """re + i im as one complex array (parts copied as they are: no arithmetic, NaN and infinities kept
    apart), so that one ``take`` reads two quantities; real weights times it give each part's sum."""
    out = np.empty(np.shape(re), dtype=np.complex128)
    out.real, out.imag = re, im
    return out


def _b_of(kind, rho):
    """b of labels rho of kind codes ``kind`` (0 T, 1 P, 2 I)."""
    q = np.sqrt(1.0 + np.exp(rho))
    return np.where(kind == 1, B_C / q, B_C * q)


def _scale(kind, b):
    """The factor of the stored theta ranges (see :func:`_range_scale`) for kind codes."""
    return np.where(kind == 0, 1.0, np.where(kind == 1, b, 1.0 / b))


def _gather(flat, base, wr, wc, n_c):
    """Bicubic sum of the 4 x 4 nodes of a row-major table (``flat``, ``n_c`` columns; real or complex)
    from the flat indices ``base`` (N,), with row and column weights wr, wc (4, N)."""
    v = None
    for i in range(4):
        b = base + i * n_c
        t = wr[i] * (wc[0] * flat.take(b) + wc[1] * flat.take(b + 1) + wc[2] * flat.take(b + 2)
                     + wc[3] * flat.take(b + 3))
        v = t if v is None else v + t
    return v


def _linear_tail(flat, base, n_c, c, cc, wr, v):
    """``v`` (N,; the interpolated values, changed in place and returned) plus the linear continuation
    beyond a row's range where c (the fractional column) was clipped to cc: slope (per column) times
    the excess. ``wr``: the rows' weights (4, N), or None for one row."""
    out = np.flatnonzero(c != cc)
    if out.size:
        dw = _derivative_weights(cc[out], n_c)
        slope = np.zeros(out.size, dtype=flat.dtype)
        for i in range(1 if wr is None else wr.shape[0]):
            for j in range(4):
                slope += (1.0 if wr is None else wr[i, out]) * dw[j] * flat.take(base[out] + (i * n_c + j))
        v[out] += slope * (c[out] - cc[out])
    return v


class RayMap:
    """The connecting rays of a static observer at ``r_obs`` (r_s, R_OBS_MIN to 1e7) to points at
    r >= ``r_min``, read from the process's :class:`OrbitTable` (see the module docstring). Offers the
    interface of the wide tables (``lookup``, ``lookup_orders``, ``r_obs``, ``r_min``, ``r_max``,
    ``parameters``), so the add-on's map stage uses it as it would a table of one radius. Making one
    costs its observer's phase on each orbit (1-D arrays, about a millisecond)."""

    r_max = math.inf
    source = "orbits"

    def __init__(self, r_obs, r_min=R_MIN, table: OrbitTable | None = None):
        self.r_obs = check_any_observer(r_obs)
        self.r_min = float(r_min)
        if not (np.isfinite(self.r_min) and self.r_min > 1.0):
            raise ValueError(f"r_min must be a number > 1 (r_s), got {r_min}")
        self.table = table if table is not None else orbit_table()
        if not hasattr(self.table, "_flat"):
            self.table._flat = _Flat(self.table)
        self.flat = self.table._flat
        uo = self.uo = 1.0 / self.r_obs
        self.k = math.sqrt(1.0 - uo)
        sin_c = min(B_C * math.sqrt(uo * uo * (1.0 - uo)), 1.0)
        self.xi_c = xi_c = math.asin(sin_c)
        t_code = 0 if uo < _orb.U_PHOTON else 2
        # per segment: kind code, direction of theta along the traced ray, critical angle, side, far
        specs = [(1, -1.0, xi_c, -1.0, xi_c)]
        if xi_c < 0.5 * math.pi - 1e-9:
            d_out = 1.0 if t_code == 0 else -1.0
            specs += [(t_code, d_out, xi_c, 1.0, 0.5 * math.pi - xi_c),
                      (t_code, -d_out, math.pi - xi_c, -1.0, 0.5 * math.pi - xi_c)]
        specs += [(1, 1.0, math.pi - xi_c, 1.0, xi_c)]
        n_seg = len(specs)
        self.n_seg = n_seg
        self.s_kind = np.array([sp[0] for sp in specs])
        self.s_dir = np.array([sp[1] for sp in specs])
        self.s_crit = np.array([sp[2] for sp in specs])
        self.s_side = np.array([sp[3] for sp in specs])
        self.s_far = np.array([sp[4] for sp in specs])
        self.c2, self.sin2c = 2.0 * xi_c, sin_c * sin_c
        self.solved = self.windowed = 0  # points solved, and of those bracketed by the seed's window
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # one for all set-up steps
            self._setup_rows()
            self._setup_nodes()
            # the segments most points of a camera need made now (outside the photon sphere the turning
            # rays', inside it those that cross it), the others when a point first needs them
            outside = uo < _orb.U_PHOTON
            for i in range(n_seg):
                if self._twins()[i] == i and (self.s_kind[i] != 1) == outside:
                    self._build(i)
            self._setup_index()

    # ---- per segment 1-D arrays -------------------------------------------------------------------
    def _rho(self, seg, d):
        """Labels of the rays d = |xi - crit| of segments ``seg`` (arrays)."""
        kind = self.s_kind.take(seg)
        c2 = self.c2
        # T, I: (b/b_c)^2 - 1 = sin(d) sin(2 xi_c + d) / sin^2 xi_c;
        # P: (b_c/b)^2 - 1 = sin(d) sin(2 xi_c - d) / sin^2(xi_c - d)
        turning = kind != 1
        s2 = np.sin(np.where(turning, c2 + d, c2 - d))
        den = np.where(turning, self.sin2c, np.sin(0.5 * c2 - d) ** 2)
        return np.log(np.sin(d) * s2 / den)

    def _d_of_rho(self, seg, rho):
        """Inverse of :meth:`_rho` (each kind's closed form on its own points only)."""
        kind = self.s_kind.take(seg)
        rho = np.asarray(rho, dtype=float)
        out = np.empty(rho.shape)
        c = self.xi_c
        p = kind == 1
        if p.any():
            # P: sin d = sin c e^rho / ((sqrt(cos^2 c + e^rho) + cos c) sqrt(1 + e^rho))
            x = np.exp(rho[p])
            sd = math.sin(c) * x / ((np.sqrt(math.cos(c) ** 2 + x) + math.cos(c)) * np.sqrt(1.0 + x))
            out[p] = np.arcsin(np.minimum(sd, 1.0))
        if not p.all():
            # T, I: sin d sin(2c + d) = X, X = e^rho sin^2 c: cos(2c + 2d) = cos 2c - 2 X; where X is small,
            # d (sin 2c + d cos 2c) = X to second order in d (a start that holds for small c too, far
            # observers, where d >> c); Newton's method then
            xx = np.exp(rho[~p]) * self.sin2c
            s2c, c2c = math.sin(self.c2), math.cos(self.c2)
            d_t = np.where(xx > 1e-6,
                           0.5 * (np.arccos(np.clip(c2c - 2.0 * xx, -1.0, 1.0)) - self.c2),
                           2.0 * xx / (s2c + np.sqrt(np.maximum(s2c * s2c + 4.0 * xx * c2c, 0.0))))
            for _ in range(3):
                s_d, s_cd = np.sin(d_t), np.sin(self.c2 + d_t)
                d_t = d_t - (s_d * s_cd - xx) / (np.cos(d_t) * s_cd + s_d * np.cos(self.c2 + d_t))
            out[~p] = d_t
        return out

    def _twins(self):
        """For each segment, the first segment of the same rays (same kind and d-range; the outward and
        inward halves of the observer's sky: segments 0 and 3, 1 and 2)."""
        if self.n_seg == 4:
            return [0, 1, 1, 0]
        return list(range(self.n_seg))

    def _setup_nodes(self):
        """Per segment, nodes uniform in z = logit(d / far) from the label RHO_MIN + 0.5 to the far end
        (their range; the observer's phase theta_o and J there are made per segment when first needed,
        :meth:`_build`)."""
        n = SEGMENT_NODES
        self.n_z = n
        self.s_zlo, self.s_zhi = np.empty(self.n_seg), np.empty(self.n_seg)
        # every segment's ends in d: its first row's (the label RHO_MIN + 0.5) and, for kind P, its last
        # row's (RHO_MAX_P)
        for i in range(self.n_seg):
            d_lo = self.row_d[self.r_first[i]]
            d_hi = self.row_d[self.r_first[i] + self.r_count[i] - 1] if self.s_kind[i] == 1 else \
                self.s_far[i] - FAR_GAP_T
            far = self.s_far[i]
            self.s_zlo[i], self.s_zhi[i] = math.log(d_lo / (far - d_lo)), math.log(d_hi / (far - d_hi))
        twin = self._twins()
        for i in range(self.n_seg):  # a twin: the same rays as an earlier segment, the same nodes
            self.s_zlo[i], self.s_zhi[i] = self.s_zlo[twin[i]], self.s_zhi[twin[i]]
        self.s_dz = (self.s_zhi - self.s_zlo) / (n - 1)
        self.node_theta = np.full(self.n_seg * n, np.nan)
        self.node_j = np.full(self.n_seg * n, np.nan)
        self.node_tj = _complex(self.node_theta, self.node_j)  # both from one take (see _nodes)
        self._built = np.zeros(self.n_seg, dtype=bool)  # per segment that is its own twin

    def _phase(self, i, d, rho):
        """The observer's phase (closed forms: the swept angle from the orbit's reference point to the
        observer, radians) on the rays d, labels rho of segment ``i`` (one that is its own twin)."""
        uo = self.uo
        name = _KINDS[self.s_kind[i]]
        orb = _orbits(name, rho)
        if name == "P":
            return _crossing_phase(orb, uo)  # the swept angle from the photon sphere to the observer
        x = self.s_crit[i] + self.s_side[i] * d
        p_uo = uo * uo * (1.0 - uo) * (np.cos(x) / np.sin(x)) ** 2  # P(uo), no cancellation
        if name == "T":
            return _orb.sweep_from_turning_point(orb, uo, np.sqrt(p_uo / ((uo - orb.e1) * (orb.e3 - uo))))
        return _sweep_inner(orb, uo, p_uo / ((uo - orb.e1) * (uo - orb.e2)))

    def _build(self, i):
        """Segment ``i``'s (one that is its own twin) and its twin's nodes: the observer's phase and J
        there (closed forms; J from the table); then its rows' phase and J, cubic from the nodes. Made
        when a point's solve first needs the segment: they depend on the observer and the segment
        only, so a point's ray does not depend on what was looked up before."""
        n = self.n_z
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            z = np.linspace(self.s_zlo[i], self.s_zhi[i], n)
            d = self.s_far[i] / (1.0 + np.exp(-z))
            rho = self._rho(np.full(n, i), d)
            theta = self._phase(i, d, rho)
            j = self._evaluate(np.full(n, self.s_kind[i]), rho, theta, want_j=True, want_u=False)[1]
            for k in np.flatnonzero(np.array(self._twins()) == i):
                sl = slice(k * n, (k + 1) * n)
                self.node_theta[sl], self.node_j[sl] = theta, j
                self.node_tj.real[sl], self.node_tj.imag[sl] = theta, j
            self._built[i] = True
            rows = slice(self.r_first[i], self.r_first[i] + self.r_count[i])
            d_r = self.row_d[rows]
            z_r = np.log(d_r) - np.log(self.s_far[i] - d_r)
            self.row_theta[rows], self.row_jo[rows] = self._nodes(np.full(d_r.size, i), z_r, None, both=True)

    def _ensure(self, seg):
        """Build the segments (:meth:`_build`) of the points' segments ``seg`` not built yet."""
        if self._built.all():
            return
        used = np.bincount(seg, minlength=self.n_seg) > 0
        twin = self._twins()
        for i in np.flatnonzero(used):
            if not self._built[twin[i]]:
                self._build(twin[i])

    def _nodes(self, seg, z, values, both=False):
        """``values`` (per segment on its nodes, see :meth:`_setup_nodes`) at z, cubic; with ``both``
        the observer's phase and J there ((theta_o, J_o); ``values`` unused), from one stencil and one
        complex take per node (``node_tj``)."""
        n = self.n_z
        g = _clip((z - self.s_zlo.take(seg)) / self.s_dz.take(seg), 0.0, n - 1)
        i0, w = _stencil(g, n)
        base = i0 + seg * n
        v = self.node_tj if both else values
        out = w[0] * v.take(base) + w[1] * v.take(base + 1) + w[2] * v.take(base + 2) + w[3] * v.take(base + 3)
        return (out.real, out.imag) if both else out

    def _setup_rows(self):
        """Per segment, the table's rows inside it (from the label RHO_MIN + 0.5, the critical end, to the
        far end): global row index, d, the observer's phase, b, theta start and length. Concatenated;
        ``r_first``, ``r_count`` per segment."""
        fl = self.flat
        rows, rhos, segs = [], [], []
        self.r_first, self.r_count = np.empty(self.n_seg, dtype=np.int64), np.empty(self.n_seg, dtype=np.int64)
        total = 0
        twin = self._twins()
        for i in range(self.n_seg):
            if twin[i] < i:  # the same rows as an earlier segment
                self.r_first[i], self.r_count[i] = self.r_first[twin[i]], self.r_count[twin[i]]
                continue
            kc = self.s_kind[i]
            k_lo = int(round((RHO_MIN + 0.5 - fl.rho0[kc]) / fl.step))
            if kc == 1:
                k_hi = fl.n_rows[kc] - 1
            else:
                rho_far = self._rho(np.array([i]), np.array([self.s_far[i] - FAR_GAP_T]))[0]
                k_hi = min(int(math.floor((rho_far - fl.rho0[kc]) / fl.step - 1e-9)), fl.n_rows[kc] - 1)
            k = np.arange(k_lo, k_hi + 1)
            rows.append(k + fl.offset[kc])
            rhos.append(fl.rho0[kc] + fl.step * k)
            segs.append(np.full(k.size, i))
            self.r_first[i], self.r_count[i] = total, k.size
            total += k.size
        # every segment's rows at once: d, b, theta start and length
        seg, rho, g = np.concatenate(segs), np.concatenate(rhos), np.concatenate(rows)
        kind = self.s_kind.take(seg)
        b = _b_of(kind, rho)
        sc = _scale(kind, b)
        self.row_g, self.row_d, self.row_rho = g, self._d_of_rho(seg, rho), rho
        # the observer's phase and J there per row: made with the segment's nodes (_build)
        self.row_theta, self.row_jo = np.full(total, np.nan), np.full(total, np.nan)
        self.row_b, self.row_start, self.row_length = b, fl.start[g] * sc, fl.length[g] * sc
        self.row_ld = np.log(self.row_d)
        # the cubic through ln d on rows k..k+3 (Newton form, as _cubic_at): (f0 + i a, c + i e) per k
        ld = np.concatenate([self.row_ld, np.full(3, np.nan)])
        f0, f1, f2, f3 = ld[:-3], ld[1:-2], ld[2:-1], ld[3:]
        self.row_ld_fa = _complex(f0, f1 - f0)
        self.row_ld_ce = _complex(0.5 * (f2 - 2.0 * f1 + f0), (f3 - 3.0 * f2 + 3.0 * f1 - f0) * (1.0 / 6.0))
        # per row: the factor from the stored J to J (r_s/c)
        self.row_jscale = self.row_length * self.row_b
        # per row: columns per radian, and the factor from the stored u (u b for T) to u
        self.row_cscale = (fl.n_cols - 1) / self.row_length
        self.row_uscale = np.where(kind == 0, 1.0 / self.row_b, 1.0)
        # made when first needed (points outside the seed's window; next to the observer): the ray
        # tangent at the observer as a row, the table's error at the observer on each row (per segment)
        self._tan = None
        self._eps = np.full(total, np.nan)
        self._eps_done = np.zeros(self.n_seg, dtype=bool)
        self._end_eps = {}

    @property
    def tan(self):
        """The ray tangent at the observer (pi/2, the far end of the turning segments) as a row (a dict;
        None with two segments); made on first use."""
        if self._tan is None and self.n_seg == 4:
            fl = self.flat
            i = 1
            if not self._built[i]:
                self._build(i)
            d_far = self.s_far[i] - FAR_GAP_T
            with np.errstate(divide="ignore", invalid="ignore"):
                rho_t = self._rho(np.array([i]), np.array([d_far]))
            kc = self.s_kind[i]
            n_c = fl.n_cols
            b = _b_of(np.array([kc]), rho_t)[0]
            g = np.clip((rho_t[0] - fl.rho0[kc]) / fl.step, 0.0, fl.n_rows[kc] - 1)
            i0, w = _cubic_stencil(np.array([g]), fl.n_rows[kc])
            rows_t = i0[0] + fl.offset[kc] + np.arange(4)
            w = w[:, 0]
            sc = _scale(np.array([kc]), np.array([b]))[0]
            st = float(w @ fl.start[rows_t]) * sc
            ln = float(w @ fl.length[rows_t]) * sc
            u_rows = np.ascontiguousarray(fl.uj.reshape(-1, n_c)[rows_t].real)
            self._tan = dict(u=w @ u_rows, b=b, start=st, length=ln, kind=kc,
                             theta=self.node_theta[(i + 1) * self.n_z - 1])
        return self._tan

    @property
    def row_eps(self) -> np.ndarray:
        """The table's error at the observer on each row (u on the row at the observer's phase, less
        uo): subtracted next to the observer; made on first use."""
        for i in np.flatnonzero(self._built & ~self._eps_done):  # the built segments' rows
            rows = np.arange(self.r_first[i], self.r_first[i] + self.r_count[i])
            self._eps_done[i] = True
            with np.errstate(divide="ignore", invalid="ignore"):
                self._eps[rows] = self._row_residual(rows, np.full(rows.size, self.uo), np.zeros(rows.size),
                                                     np.full(rows.size, i))
        return self._eps

    def _setup_index(self):
        """The seed index: the table's u along every INDEX_ROW_STEP-th row of every segment (and each
        segment's last), in the order of the rays' xi over the whole sky (a segment whose rows run
        towards smaller xi reversed), at INDEX_SWEEPS angles uniform over [0, 2 pi] (the swept angle of
        either order). Along xi the radius a ray has reached grows (f changes sign once), so each
        angle's sequence is made monotone (a running maximum) and stored shifted by INDEX_SHIFT per
        angle, all angles in one sorted array: a point's place in it is one ``np.searchsorted``
        (:meth:`_seed`). The index only chooses where the solve looks first (its segment and four
        rows): the bracket it yields is the one the full search finds (f changes sign once along the
        rays), so the rays are the same as without it. About INDEX_SWEEPS * (rows / INDEX_ROW_STEP)
        1-D lookups, linear along each row."""
        n_s = INDEX_SWEEPS
        segs, locs = [], []
        for i in range(self.n_seg):
            count = int(self.r_count[i])
            p = np.arange(0, count, INDEX_ROW_STEP)
            if p[-1] != count - 1:
                p = np.append(p, count - 1)
            if self.s_side[i] < 0:  # rows towards smaller xi: reversed
                p = p[::-1]
            segs.append(np.full(p.size, i))
            locs.append(p)
        seg, loc = np.concatenate(segs), np.concatenate(locs)
        rows = self.r_first.take(seg) + loc
        n_c, uj = self.flat.n_cols, self.flat.uj
        sweeps = np.linspace(0.0, 2.0 * math.pi, n_s)
        # the observer's phase on these rows: the rows' own in the segments built now, else by the
        # closed forms (those segments' nodes are made when a point first needs them); and on each
        # segment's first row (the segment tests of _solve)
        twin = np.array(self._twins())
        own = twin.take(seg)
        theta = self.row_theta.take(rows)
        self.first_theta = np.empty(self.n_seg)
        for i in np.unique(own):
            at = np.flatnonzero(own == i)
            if not self._built[i]:
                r_i = rows.take(at)
                theta[at] = self._phase(i, self.row_d.take(r_i), self.row_rho.take(r_i))
            self.first_theta[i] = theta[at[np.flatnonzero(loc.take(at) == 0)[0]]]
        self.first_theta = self.first_theta.take(twin)
        # u along each row, linear between its columns (and beyond them): a seed needs no more
        th = theta[None, :] + self.s_dir.take(seg)[None, :] * sweeps[:, None]
        th = np.where((self.s_kind.take(seg) != 1)[None, :], np.abs(th), th)
        c = (th - self.row_start.take(rows)) * self.row_cscale.take(rows)
        j = _clip(np.floor(c), 0.0, n_c - 2.0).astype(np.int64)
        t = c - j
        base = self.row_g.take(rows) * n_c + j
        f = (uj.take(base).real * (1.0 - t) + uj.take(base + 1).real * t) * self.row_uscale.take(rows)
        # (n_s, q): monotone along xi, each value the least of those after it (rays that escaped,
        # below every target, may wind up and down below zero: a running minimum from the side of
        # the rays that fell in keeps the values next to every target's root)
        f = np.fmax(np.fmin(f, 2.0), -1.0)  # clipped to [-1, 2], NaN (no value) as 2
        f = np.minimum.accumulate(f[:, ::-1], axis=1)[:, ::-1]
        self.ix_n = seg.size
        self.ix_val = f  # per angle, the coarse rows' u
        self.ix_flat = (f + INDEX_SHIFT * np.arange(n_s)[:, None]).reshape(-1)
        self.ix_seg, self.ix_loc = seg, loc.astype(float)

    def _seed(self, u, sweep):
        """(segment, fractional local row) of the points' roots from the seed index (see
        :meth:`_setup_index`): the place of u among the coarse rows at the point's angle, the index's
        values interpolated linearly between its two angles about it, and linearly between two coarse
        rows. That place lies between the places at the two angles (each one ``np.searchsorted``): a
        bisection between them, which most points skip (both places the same)."""
        n_s, q = INDEX_SWEEPS, self.ix_n
        x = sweep * ((n_s - 1) / (2.0 * math.pi))
        j = _clip(x.astype(np.int64), 0, n_s - 2)  # x >= 0: truncation is floor
        w = x - j
        w0 = 1.0 - w
        y = _clip(u, -1.0, 2.0)
        c0 = j * q  # the first coarse row of angle j in the flat arrays; angle j + 1's: c0 + q
        key = y + INDEX_SHIFT * j
        a0 = np.searchsorted(self.ix_flat, key) - c0  # the first coarse row >= u at angle j
        a1 = np.searchsorted(self.ix_flat, key + INDEX_SHIFT) - (c0 + q)
        # the interpolated values' first coarse row >= u, in [lo, hi]
        lo, hi = np.minimum(a0, a1), np.maximum(a0, a1)
        val = self.ix_val.reshape(-1)
        o = np.flatnonzero(hi > lo)
        while o.size:
            lo_o, hi_o = lo.take(o), hi.take(o)
            mid = (lo_o + hi_o) >> 1
            at = c0.take(o) + mid
            below = w0.take(o) * val.take(at) + w.take(o) * val.take(at + q) < y.take(o)
            lo[o] = np.where(below, mid + 1, lo_o)
            hi[o] = np.where(below, hi_o, mid)
            o = o[hi.take(o) > lo.take(o)]
        a = _clip(lo - 1, 0, q - 2)  # the coarse interval [a, a + 1]
        at = c0 + a
        v_a = w0 * val.take(at) + w * val.take(at + q)
        v_b = w0 * val.take(at + 1) + w * val.take(at + q + 1)
        t = _clip((y - v_a) / (v_b - v_a), 0.0, 1.0)
        t = np.where(np.isfinite(t), t, 0.5)
        s_a, s_b = self.ix_seg.take(a), self.ix_seg.take(a + 1)
        l_a, l_b = self.ix_loc.take(a), self.ix_loc.take(a + 1)
        same = s_a == s_b  # else between two segments' ends: the nearer one's
        seg = np.where(same | (t < 0.5), s_a, s_b)
        row = np.where(same, l_a + t * (l_b - l_a), np.where(t < 0.5, l_a, l_b))
        return seg, row

    # ---- table lookups ----------------------------------------------------------------------------
    def _evaluate(self, kind, rho, theta, want_j=False, ref=None, want_u=True):
        """(u, J (r_s/c), J's difference, b) on orbits of kind codes ``kind`` and labels ``rho`` at angles
        ``theta`` from their reference points, bicubic, continued linearly beyond a row's range; b the
        orbits' impact parameters (r_s). With ``ref`` = (indices k, the observer's phase theta_ref at
        them): at those points u(theta) - u(theta_ref) + uo, and J(theta) - J(theta_ref) as the third
        value (at k, NaN elsewhere), from the same row stencil, so that the table's own small error
        cancels next to the observer. Without ``want_u`` (J only) u is None; without ``want_j`` J and
        its difference are None."""
        fl = self.flat
        n_c = fl.n_cols
        nr = fl.n_rows.take(kind)
        g = _clip((rho - fl.rho0.take(kind)) * (1.0 / fl.step), 0.0, nr - 1)
        i0, wr = _stencil(g, nr)
        i0 = i0 + fl.offset.take(kind)
        b = _b_of(kind, rho)
        sc = _scale(kind, b)
        sl = fl.sl  # start + i length: both from one take per row
        v = (wr[0] * sl.take(i0) + wr[1] * sl.take(i0 + 1) + wr[2] * sl.take(i0 + 2) + wr[3] * sl.take(i0 + 3)) * sc
        st, ln = v.real, v.imag
        u, j = self._columns(i0, wr, (theta - st) / ln * (n_c - 1), want_j, want_u)
        j_diff = None
        if ref is not None:
            k, theta_ref = ref
            lk = ln.take(k)
            u0, j0 = self._columns(i0.take(k), wr[:, k], (theta_ref - st.take(k)) / lk * (n_c - 1), want_j,
                                   want_u)
            if u is not None:
                u[k] -= u0
            if j is not None:
                j_diff = np.full(j.size, np.nan)
                j_diff[k] = (j.take(k) - j0) * lk * b.take(k)
        if u is not None:
            u = np.where(kind == 0, u / b, u)
            if ref is not None:
                u[ref[0]] += self.uo
        return u, (None if j is None else j * ln * b), j_diff, b

    def _columns(self, i0, wr, c, want_j, want_u=True):
        fl = self.flat
        n_c = fl.n_cols
        cc = _clip(c, 0.0, n_c - 1)
        j0, wc = _stencil(cc, n_c)
        base = i0 * n_c + j0
        v = _linear_tail(fl.uj, base, n_c, c, cc, wr, _gather(fl.uj, base, wr, wc, n_c))  # u + i J
        return (v.real if want_u else None), (v.imag if want_j else None)

    def _residual(self, seg, d, u, sweep, want=False, near=None, want_f=True):
        """f = u_ray - u on the rays d of segments ``seg`` for targets (u, sweep); ``near`` (mask):
        targets next to the observer, whose f is formed as u_ray - u_ray(theta_o) + uo - u. With
        ``want``: (f, the rays' values for :meth:`_finish`); without ``want_f`` f is None."""
        far = self.s_far.take(seg)
        z = np.log(d) - np.log(far - d)
        kind = self.s_kind.take(seg)
        rho = self._rho(seg, d)
        j_o = None
        if want:  # the observer's phase and J there
            th_o, j_o = self._nodes(seg, z, None, both=True)
        else:
            th_o = self._nodes(seg, z, self.node_theta)
        th = th_o + self.s_dir.take(seg) * sweep
        turning = kind != 1
        th_row = np.where(turning, np.abs(th), th)
        ref = None
        if near is not None:
            k = np.flatnonzero(near)
            if k.size:
                ref = (k, th_o.take(k))
        u_ray, j, j_diff, b = self._evaluate(kind, rho, th_row, want, ref=ref, want_u=want_f)
        if want:
            return (u_ray - u if want_f else None), dict(z=z, rho=rho, theta=th, theta_o=th_o, j=j, j_diff=j_diff,
                                                         b=b, j_o=j_o)
        return u_ray - u

    def _end_residual(self, i, u, sweep, near):
        """f on segment ``i``'s first row (the segment tests of :meth:`_solve`), with the observer's phase
        there by the closed forms (``first_theta``) and, for targets next to the observer, the table's
        error there from it: the tests do not depend on which segments are built."""
        row, seg = np.full(u.size, self.r_first[i]), np.full(u.size, i)
        f = self._row_residual(row, u, sweep, seg, theta=np.full(u.size, self.first_theta[i]))
        if not near.any():
            return f
        if i not in self._end_eps:
            self._end_eps[i] = self._row_residual(row[:1], np.array([self.uo]), np.zeros(1), seg[:1],
                                                  theta=self.first_theta[i:i + 1])[0]
        return f - np.where(near, self._end_eps[i], 0.0)

    def _row_residual(self, row, u, sweep, seg, near=None, want_q=False, theta=None):
        """f on the concatenated rows ``row`` (1-D cubic along each row); ``near``: targets next to the
        observer, from whose f the table's error at the observer is subtracted. ``row`` may be (k, N)
        with the targets' arrays (N,): k rows per target (the per-target parts formed once). With
        ``want_q``: (f, q), q the travel-time remainder from the observer to the target along each row,
        J(theta) signed as theta (turning rays: negative past the periapsis / apoapsis) less J at the
        observer's phase (r_s/c; the quantity whose modulus :meth:`_finish` adds to the radial part),
        from the same column stencil. ``theta``: the observer's phase on the rows where given (else the
        rows' own, ``row_theta``)."""
        fl = self.flat
        n_c = fl.n_cols
        th = (self.row_theta.take(row) if theta is None else theta) + self.s_dir.take(seg) * sweep
        past = None
        if self.n_seg > 2:  # turning rays: the angle from the periapsis / apoapsis
            turning = self.s_kind.take(seg) != 1
            if want_q:
                past = turning & (th < 0.0)
            th = np.where(turning, np.abs(th), th)
        c = ((th - self.row_start.take(row)) * self.row_cscale.take(row)).reshape(-1)
        cc = _clip(c, 0.0, n_c - 1)
        j0, wc = _stencil(cc, n_c)
        base = self.row_g.take(row).reshape(-1) * n_c + j0
        t = fl.uj
        v = wc[0] * t.take(base) + wc[1] * t.take(base + 1) + wc[2] * t.take(base + 2) + wc[3] * t.take(base + 3)
        v = _linear_tail(t, base, n_c, c, cc, None, v).reshape(np.shape(row))  # u + i J
        f = v.real * self.row_uscale.take(row) - u
        if near is not None and near.any():
            f = f - np.where(near, self.row_eps.take(row), 0.0)
        if not want_q:
            return f
        vj = v.imag * self.row_jscale.take(row)
        if past is not None:
            vj = np.where(past, -vj, vj)
        return f, vj - self.row_jo.take(row)

    def _tangent_residual(self, u, sweep, direction):
        """f on the ray tangent at the observer (1-D cubic along its interpolated row)."""
        t = self.tan
        n_c = self.flat.n_cols
        th = np.abs(t["theta"] + direction * sweep)
        c = (th - t["start"]) / t["length"] * (n_c - 1)
        cc = np.clip(c, 0.0, n_c - 1)
        j0, wc = _cubic_stencil(cc, n_c)
        row = t["u"]
        v = wc[0] * row.take(j0) + wc[1] * row.take(j0 + 1) + wc[2] * row.take(j0 + 2) + wc[3] * row.take(j0 + 3)
        out = np.flatnonzero(c != cc)
        if out.size:
            dw = _derivative_weights(cc[out], n_c)
            jo = j0[out]
            v[out] += (dw[0] * row.take(jo) + dw[1] * row.take(jo + 1) + dw[2] * row.take(jo + 2)
                       + dw[3] * row.take(jo + 3)) * (c[out] - cc[out])
        return (v / t["b"] if t["kind"] == 0 else v) - u

    # ---- the solve --------------------------------------------------------------------------------
    @property
    def parameters(self) -> dict:
        return dict(kind="orbits", r_obs=self.r_obs, r_min=self.r_min, source=self.source,
                    step=self.table.step, n_cols=self.table.n_cols)

    def lookup(self, r, phi, order: int = 1, quantities=QUANTITIES) -> Lookup:
        return self.lookup_orders(r, phi, (order,), quantities)[order]

    def lookup_orders(self, r, phi, orders=(1, 2), quantities=QUANTITIES) -> dict:
        """{order: Lookup} of the connecting rays to points (r, phi) (broadcast; r in r_s, r >= r_min
        including infinity, phi in [0, pi]); NaN outside. As :meth:`lutgen.WideLUT.lookup_orders`."""
        orders = tuple(orders)
        for order in orders:
            if order not in (1, 2):
                raise ValueError(f"order must be 1 or 2, got {order!r}")
        unknown = set(quantities) - set(QUANTITIES)
        if unknown:
            raise ValueError(f"unknown quantities {sorted(unknown)}; choose from {QUANTITIES}")
        r, phi = np.broadcast_arrays(np.asarray(r, dtype=np.float64), np.asarray(phi, dtype=np.float64))
        shape = r.shape
        r, p = r.ravel(), phi.ravel()
        with np.errstate(invalid="ignore"):
            ok = (r >= self.r_min * (1.0 - 1e-12)) & (p >= 0.0) & (p <= math.pi) & ~np.isnan(r)
        idx = np.flatnonzero(ok)
        m = idx.size
        if m:
            rr = np.tile(r[idx], len(orders))
            pp = np.tile(p[idx], len(orders))
            oo = np.repeat(np.array(orders), m)
            res = self.solve(rr, pp, oo, quantities)
        else:  # nothing to solve (no valid point): the solve's fixed cost saved
            res = {q: np.empty(0) for q in QUANTITIES}
        out = {}
        for i, order in enumerate(orders):
            got = {}
            for q in quantities:
                if m == r.size:  # every point valid: the solve's values as they are
                    got[q] = res[q][i * m:(i + 1) * m].reshape(shape)
                    continue
                v = np.full(r.size, np.nan)
                v[idx] = res[q][i * m:(i + 1) * m]
                got[q] = v.reshape(shape)
            out[order] = Lookup(*(got.get(q) for q in QUANTITIES))
        return out

    def solve(self, r, phi, order, quantities=QUANTITIES) -> dict:
        """{xi, dt, ux, uy} of the connecting rays of orders ``order`` (array of 1 and 2) to points
        (r, phi) (1-D, valid; ux, uy only where ``quantities`` asks for either): see :meth:`_solve`
        (under one np.errstate: the steps divide by zero and meet NaN by design, e.g. at rows' ends and
        for rays that escaped)."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return self._solve(r, phi, order, "ux" in quantities or "uy" in quantities)

    def _solve(self, r, phi, order, tangents=True) -> dict:
        """{xi, dt, ux, uy} of the connecting rays of orders ``order`` (array of 1 and 2) to points
        (r, phi) (1-D, valid). Every point goes through the same vectorised steps:

        1. the four rows about the root in the segment that the seed index gives (:meth:`_seed`;
           1-D lookups along each row) bracket it between neighbouring rows where f changes sign among
           them (f changes sign once along the rays ordered by xi, over all segments: such a change
           is the root's);
        2. elsewhere its segment (the first whose end towards larger xi has f >= 0), then a search
           over the segment's rows (K-section, SEARCH_BUDGET; when the seed's segment was that one, a
           first pass of rows PROBE_STEPS beyond the window's side), or the last row and the far end,
           pi/2, bracket it;
        3. between two rows, the cubic through f on four rows gives a start and a slope; a Newton step
           with them and the bicubic interpolation ends where it is shorter than NEWTON_DONE, else
           secant steps converge (d = |xi - crit| to TOL_D); in the end intervals next to the ray
           tangent at the observer the start and slope come from the cubic in d through f on the
           segment's last three rows and on that ray (:func:`_cubic_root_nodes`); where the secant
           steps do not converge, the Anderson-Bjorck variant of regula falsi in d does."""
        n = r.size
        u = 1.0 / r
        sweep = np.where(order == 1, phi, 2.0 * math.pi - phi)
        h = np.sin(0.5 * phi)
        gap = np.hypot(r - self.r_obs, 2.0 * np.sqrt(r * self.r_obs) * h)  # distance from the observer
        near = (gap < NEAR * self.r_obs) & (order == 1)
        ns = self.n_seg
        # 1. the seed index's segment and window of four rows about the root: where f changes sign inside
        # it (f changes sign once along the rays ordered by xi), the bracket and the cubic's four values
        # are known
        seg, k_row = self._seed(u, sweep)
        self._ensure(seg)
        first, count = self.r_first.take(seg), self.r_count.take(seg)
        orient = self.s_side.take(seg)  # f grows along the rows when side > 0
        k0 = _clip(k_row.astype(np.int64) - 1, 0, count - 4)  # k_row >= 0: truncation is floor
        fw, qw = self._row_residual(first + k0 + np.arange(4)[:, None], u, sweep, seg, near, want_q=True)  # (4, n)
        bw = orient * fw < 0.0
        # f changes sign between rows k0 + j and k0 + j + 1 (the first such j); elsewhere lo, hi span the
        # segment, f_lo NaN (node 0's value: computed below where the search never moved lo)
        cand = bw[:3] & ~bw[1:]
        window = cand[0] | cand[1] | cand[2]
        js = cand.argmax(0)
        at_lo = js * n + np.arange(n)
        lo = np.where(window, k0 + js, 0)
        hi = np.where(window, lo + 1, count)
        fw_flat = fw.reshape(-1)
        f_lo = np.where(window, fw_flat.take(at_lo), np.nan)
        f_hi = np.where(window, fw_flat.take(at_lo + n), orient * np.inf)
        rest = np.flatnonzero(~window)
        moved = np.zeros(n, dtype=bool)  # points whose segment is not the seed's (their window is not theirs)
        self.solved += n
        self.windowed += n - rest.size
        if rest.size:
            # 2. elsewhere the segment from the signs at the segments' ends (the first whose end towards
            # larger xi has f >= 0); in the seed's segment the search over its rows starts from what the
            # window showed, in another one from all its rows
            ur, sr, nr = u.take(rest), sweep.take(rest), near.take(rest)
            s_rest = np.full(rest.size, ns - 1)
            if ns == 4:  # the ray tangent at the observer first, then one end on its side: two tests
                f_tan = np.full(n, np.nan)  # kept for the end intervals of segment 1 (same direction)
                f_tan[rest] = self._tangent_residual(ur, sr, self.s_dir[1])
                low = f_tan.take(rest) >= 0.0
                for i, side in ((0, low), (2, ~low)):
                    at = np.flatnonzero(side)
                    if not at.size:  # no point on this side: no call (its fixed cost saved)
                        continue
                    f = self._end_residual(i, ur[at], sr[at], nr[at])
                    s_rest[at] = np.where(f >= 0.0, i, i + 1)
            else:  # two segments (an observer next to the photon sphere): the first's end
                f = self._end_residual(0, ur, sr, nr)
                s_rest[f >= 0.0] = 0
            same = s_rest == seg.take(rest)
            rs, ro = rest[same], rest[~same]
            last = rs[bw[3, rs]]  # below on all four: the root is beyond them
            lo[last], f_lo[last] = k0[last] + 3, fw[3, last]
            start = rs[~bw[0, rs]]  # above on all four: before them (at the critical end if k0 = 0)
            hi[start], f_hi[start] = k0[start], fw[0, start]
            at_first = start[k0[start] == 0]
            hi[at_first], f_lo[at_first] = 1, fw[0, at_first]
            f_hi[at_first] = fw[1, at_first]
            # the first pass of the search probes rows at growing distances from the window's side
            # (the root is most often a row or two beyond it)
            side = np.zeros(n, dtype=np.int8)
            side[last], side[start] = 1, -1
            if ro.size:  # another segment: all its rows
                moved[ro] = True
                seg[ro] = s_rest[~same]
                self._ensure(seg[ro])
                first[ro], count[ro], orient[ro] = (self.r_first.take(seg[ro]), self.r_count.take(seg[ro]),
                                                    self.s_side.take(seg[ro]))
                hi[ro], f_hi[ro] = count[ro], orient[ro] * np.inf
        probe = rest.size > 0 and SEARCH_BUDGET > 1
        while True:  # a K-section search: K rows per point and pass, as many as SEARCH_BUDGET allows
            o = np.flatnonzero(hi - lo > 1)
            if not o.size:
                break
            lo_o, hi_o = lo.take(o), hi.take(o)
            gap = hi_o - lo_o
            # no more rows per point than the widest bracket holds inside (a pass over few points
            # would otherwise repeat rows)
            n_k = int(min(max(SEARCH_BUDGET // o.size, 1), SEARCH_MAX_K, gap.max() - 1))
            sd = side.take(o) if probe else None
            probe = False
            if sd is not None and sd.any():  # the first pass: PROBE_STEPS.size rows per point
                n_k = PROBE_STEPS.size
            # rows lo + (hi - lo) j / (K + 1), j = 1..K, inside (lo, hi) (bisection for K = 1)
            mid = lo_o + (gap[None, :] * np.arange(1, n_k + 1)[:, None]) // (n_k + 1)
            if sd is not None and sd.any():  # from the window's side: rows PROBE_STEPS beyond it
                cols = np.flatnonzero(sd)
                steps = PROBE_STEPS[:, None]
                mid[:, cols] = np.where(sd.take(cols) > 0, lo_o.take(cols) + steps, hi_o.take(cols) - steps[::-1])
            mid = np.minimum(np.maximum(mid, lo_o + 1), hi_o - 1)
            f = self._row_residual(first.take(o) + mid, u.take(o), sweep.take(o), seg.take(o), near.take(o))
            below = orient.take(o) * f < 0.0  # true on a prefix of the K rows (f changes sign once)
            n_below = below.sum(0)
            ob = np.flatnonzero(n_below > 0)  # the last row below: the new lo
            lo[o[ob]], f_lo[o[ob]] = mid[n_below[ob] - 1, ob], f[n_below[ob] - 1, ob]
            oa = np.flatnonzero(n_below < n_k)  # the first row above: the new hi
            hi[o[oa]], f_hi[o[oa]] = mid[n_below[oa], oa], f[n_below[oa], oa]
        at0 = np.flatnonzero((lo == 0) & np.isnan(f_lo))
        if at0.size:
            f_lo[at0] = self._row_residual(first[at0], u[at0], sweep[at0], seg[at0], near[at0])
        d = np.empty(n)
        carried = None  # the rays whose values the Newton step's read gave (see below)
        none = orient * f_lo >= 0.0  # a root at the critical end (within rounding)
        d[none] = self.row_d.take(first[none])
        # the end intervals: the far end (pi/2) and the two rows before it
        turning = self.s_kind.take(seg) != 1
        inner = ~none & ~(turning & (hi >= count - 2)) & (hi < count)
        i = np.flatnonzero(inner)
        if i.size:
            # the points' arrays at i (all of them, most often: no copies then)
            pick = (lambda a: a) if i.size == n else (lambda a: a.take(i, axis=-1))
            wi, lo_i, fst_i = pick(window), pick(lo), pick(first)
            if wi.all():
                kc, fs, qs = pick(k0), pick(fw), pick(qw)
            else:
                qs = np.where(wi, pick(qw), np.nan)  # outside the window: no rows' q (values read at the end)
                kc = np.where(wi, pick(k0), _clip(lo_i - 1, 0, pick(count) - 4))
                fs = np.where(wi, pick(fw), np.nan)
                m_all = np.flatnonzero(~wi)
                need_j, need_m = [], []
                for j in range(4):  # outside the window: the bracket's two rows are known from the search
                    im = i[m_all]
                    kj = kc[m_all] + j
                    known_lo, known_hi = kj == lo[im], kj == hi[im]
                    fs[j, m_all[known_lo]], fs[j, m_all[known_hi]] = f_lo[im[known_lo]], f_hi[im[known_hi]]
                    m = m_all[~known_lo & ~known_hi]
                    need_j.append(np.full(m.size, j))
                    need_m.append(m)
                nj, nm = np.concatenate(need_j), np.concatenate(need_m)
                if nm.size:  # the other two rows of every such point in one call
                    im = i[nm]
                    fs[nj, nm] = self._row_residual(first[im] + kc[nm] + nj, u[im], sweep[im], seg[im], near[im])
            t, dp = _cubic_root(fs, (lo_i - kc).astype(float), slope=True)
            # the ray at t: ln d is smooth in the row index (rows uniform in rho, ln d ~ rho next to
            # the critical angle), so the cubic through the four rows' ln d gives d and dd/dt
            r0 = fst_i + kc
            fa, ce = self.row_ld_fa.take(r0), self.row_ld_ce.take(r0)
            p, dp_ld = _cubic_at_coefficients(fa.real, fa.imag, ce.real, ce.imag, t)
            d0 = np.exp(p)
            dd_dt = d0 * dp_ld
            d_a, d_b = self.row_d.take(fst_i + lo_i), self.row_d.take(fst_i + pick(hi))
            d0 = np.clip(d0, np.minimum(d_a, d_b), np.maximum(d_a, d_b))
            # the cubic's slope as df/dd: the first step is Newton's with it
            slope = dp / dd_dt
            seg_i, near_i = pick(seg), pick(near)
            f0, got0 = self._residual(seg_i, d0, pick(u), pick(sweep), want=True, near=near_i)
            d_i, ok, (x_rd, th_rd, q_rd) = self._secant(seg_i, pick(u), pick(sweep), d0, d_a, d_b, near_i,
                                                        slope=slope, f0=f0,
                                                        read0=(got0["theta"], self._remainder(seg_i, got0, near_i)))
            d[i] = d_i
            inner[i[~ok]] = False
            # the ray's values come from the iteration's reads: where the Newton step ended it, from its
            # read at d0, the travel-time remainder carried to the ray by its derivative along the four
            # rows (the step is below NEWTON_DONE of d: what is left is the step times that derivative's
            # error); where a secant step did, as the secant carried it (x_rd is then the ray's d)
            q_x = np.where(x_rd == d_i, q_rd, q_rd + (d_i - x_rd) * (_cubic_at(qs, t)[1] / dd_dt))
            q_x = np.where(np.isnan(qs[0]), np.nan, q_x)  # outside the window: read at the end
            c_at = np.flatnonzero(ok & np.isfinite(q_x))
            if c_at.size:
                carried = (i.take(c_at), th_rd.take(c_at), q_x.take(c_at))
        e = np.flatnonzero(~none & ~inner)
        if e.size:
            far_d = self.s_far.take(seg[e]) - FAR_GAP_T
            d_a = self.row_d.take(first[e] + np.minimum(lo[e], count[e] - 1))
            d_b = np.where(hi[e] >= count[e], far_d, self.row_d.take(first[e] + np.minimum(hi[e], count[e] - 1)))
            f_a, f_b = f_lo[e], f_hi[e]
            tan = np.flatnonzero((hi[e] >= count[e]) & (self.s_kind.take(seg[e]) != 1))
            if tan.size and self.tan is not None:  # the far end is the ray tangent at the observer: its f
                # (segment 1's points have it from the segment test, same direction; the others' is made)
                et = e[tan]
                known = seg.take(et) == 1
                f_b[tan[known]] = f_tan.take(et[known])
                todo = ~known
                if todo.any():
                    f_b[tan[todo]] = self._tangent_residual(u[et[todo]], sweep[et[todo]],
                                                            self.s_dir.take(seg[et[todo]]))
            # in these intervals f is smooth in d: regula falsi for a start, then secant steps
            d0 = d_a - f_a * (d_b - d_a) / (f_b - f_a)
            lo_d, hi_d = np.minimum(d_a, d_b), np.maximum(d_a, d_b)
            d0 = np.where(np.isfinite(d0) & (d0 > lo_d) & (d0 < hi_d), d0, 0.5 * (d_a + d_b))
            slope = None
            end = np.flatnonzero((hi[e] >= count[e] - 2) & turning.take(e) & (count[e] >= 4))
            if end.size and self.tan is not None:
                # next to the ray tangent at the observer: the cubic in d through f on the segment's last
                # three rows and on that ray gives a start and a slope (Newton's step, as between rows)
                ee = e[end]
                f_t = np.where(hi[ee] >= count[ee], f_b.take(end), np.nan)
                miss = np.flatnonzero(np.isnan(f_t))
                if miss.size:
                    em = ee[miss]
                    f_t[miss] = self._tangent_residual(u[em], sweep[em], self.s_dir.take(seg[em]))
                last3 = first[ee] + count[ee] - 3 + np.arange(3)[:, None]
                fn = np.full((4, end.size), np.nan)
                fn[3] = f_t
                # the rows' f where known: the window's (in the seed's segment), the bracket's ends
                loc = count[ee] - 3 + np.arange(3)[:, None]  # (3, m) local rows
                jw = loc - k0[ee]
                inw = ~moved[ee] & (jw >= 0) & (jw <= 3)
                fn[:3][inw] = fw[jw[inw], np.broadcast_to(ee, loc.shape)[inw]]
                for f_known, at in ((f_lo, lo), (f_hi, hi)):
                    hit = np.isnan(fn[:3]) & (loc == at[ee])
                    fn[:3][hit] = np.broadcast_to(f_known[ee], loc.shape)[hit]
                jm, om = np.nonzero(np.isnan(fn[:3]))
                if om.size:
                    eo = ee[om]
                    fn[jm, om] = self._row_residual(last3[jm, om], u[eo], sweep[eo], seg[eo], near[eo])
                dn = np.concatenate([self.row_d.take(last3), far_d.take(end)[None]])
                x, dp = _cubic_root_nodes(dn, fn, d0.take(end), lo_d.take(end), hi_d.take(end))
                good = np.isfinite(x) & np.isfinite(dp) & (dp != 0.0)
                d0[end[good]] = x[good]
                slope = np.full(e.size, np.nan)  # no slope: the plain secant start (see _secant)
                slope[end[good]] = dp[good]
            d_e, ok, (x_rd, th_rd, q_rd) = self._secant(seg[e], u[e], sweep[e], d0, d_a, d_b, near[e], steps=6,
                                                        slope=slope, carry=True)
            d[e] = d_e
            # where secant steps ended the iteration, the rays' values as they carried them
            c_at = np.flatnonzero(ok & (x_rd == d_e) & np.isfinite(q_rd))
            if c_at.size:
                more = (e.take(c_at), th_rd.take(c_at), q_rd.take(c_at))
                carried = more if carried is None else tuple(np.concatenate(p) for p in zip(carried, more))
            rest = np.flatnonzero(~ok)
            if rest.size:
                er = e[rest]
                d[er] = self._regula_falsi(seg[er], u[er], sweep[er], d_a[rest], d_b[rest], f_a[rest], f_b[rest],
                                           near[er])
        return self._finish(seg, d, u, r, phi, sweep, order, near, tangents, carried)

    def _secant(self, seg, u, sweep, d0, d_a, d_b, near, steps=4, slope=None, f0=None, read0=None, carry=False):
        """Secant steps in d from d0 (inside the bracket [d_a, d_b], next to the root) with the bicubic
        interpolation; returns (d, converged). With ``slope`` (an estimate of df/dd at d0) the second
        point is Newton's step from d0 with it (where it falls inside the bracket), else d0 plus 1e-7 of
        the bracket; ``f0``: f at d0 where known (with ``slope``). With ``carry`` or ``read0`` (theta and
        the travel-time remainder of :meth:`_remainder` at d0, with ``f0``) the steps read the rays'
        values too and a third value is returned, meaningful where converged: per ray a point x, and
        theta and the remainder there. Where the Newton step ended the iteration x is d0 (its read);
        where a secant step did, x is the converged d, the remainder carried from the last point read
        by the secant through the last two reads (the step is below SECANT_DONE of d, the secant's
        slope exact to the distance between those reads)."""
        lo, hi = np.minimum(d_a, d_b), np.maximum(d_a, d_b)
        carry = carry or read0 is not None
        q_prev = None
        if slope is None:
            x_prev = d0 + 1e-7 * (hi - lo)
            if carry:
                f_prev, got = self._residual(seg, x_prev, u, sweep, want=True, near=near)
                q_prev = self._remainder(seg, got, near)
            else:
                f_prev = self._residual(seg, x_prev, u, sweep, near=near)
            x = d0
        else:  # (a NaN slope: no Newton step, the second point as without a slope)
            x_prev = d0
            if f0 is not None:
                f_prev = f0
            elif carry:
                f_prev, got = self._residual(seg, d0, u, sweep, want=True, near=near)
                read0 = (got["theta"], self._remainder(seg, got, near))
            else:
                f_prev = self._residual(seg, d0, u, sweep, near=near)
            x = d0 - f_prev / slope
            newton = np.isfinite(x) & (x >= lo) & (x <= hi) & (x != d0)
            x = np.where(newton, x, d0 + 1e-7 * (hi - lo))
        out = d0.copy()
        ok = np.zeros(u.size, dtype=bool)
        act = np.arange(u.size)
        if carry:  # per ray a point read, theta and the remainder there
            if read0 is not None:
                x_rd, th_rd, q_rd = d0.copy(), read0[0].copy(), read0[1].copy()
                q_prev = read0[1]
            else:
                x_rd, th_rd, q_rd = np.full(u.size, np.nan), np.full(u.size, np.nan), np.full(u.size, np.nan)
        if slope is not None:  # a Newton step this short leaves its length times the slope's error
            done = newton & (np.abs(x - d0) <= NEWTON_DONE * x)
            out[done], ok[done] = x[done], True
            keep = ~done
            act, x_prev, f_prev, x = act[keep], x_prev[keep], f_prev[keep], x[keep]
            if carry:
                q_prev = q_prev[keep]
        for _ in range(steps):
            if not act.size:
                break
            sa, na = seg.take(act), near.take(act)
            if carry:
                f, got = self._residual(sa, x, u.take(act), sweep.take(act), want=True, near=na)
                q = self._remainder(sa, got, na)
            else:
                f = self._residual(sa, x, u.take(act), sweep.take(act), near=na)
            x_new = x - f * (x - x_prev) / (f - f_prev)
            x_new = np.where(f == 0.0, x, x_new)
            good = np.isfinite(x_new) & (x_new >= lo.take(act)) & (x_new <= hi.take(act))
            # a step this short leaves an error of order its square: converged
            done = good & (np.abs(x_new - x) <= SECANT_DONE * x)
            out[act[done]] = x_new[done]
            ok[act[done]] = True
            keep = good & ~done
            if carry:
                ad = act[done]
                x_rd[ad], th_rd[ad] = x_new[done], got["theta"][done]
                q_rd[ad] = q[done] + (x_new[done] - x[done]) * ((q[done] - q_prev[done]) / (x[done] - x_prev[done]))
                q_prev = q[keep]
            act, x_prev, f_prev, x = act[keep], x[keep], f[keep], x_new[keep]
        if carry:
            return out, ok, (x_rd, th_rd, q_rd)
        return out, ok

    def _regula_falsi(self, seg, u, sweep, a, b, f_a, f_b, near):
        """d of the roots bracketed by [a, b] (f values f_a, f_b, possibly infinite): the
        Anderson-Bjorck variant of regula falsi."""
        out = np.empty(u.size)
        act = np.arange(u.size)
        for _ in range(100):
            if not act.size:
                break
            c = b - f_b * (b - a) / (f_b - f_a)
            lo_d, hi_d = np.minimum(a, b), np.maximum(a, b)
            c = np.where(np.isfinite(c) & (c > lo_d) & (c < hi_d), c, 0.5 * (a + b))
            f_c = self._residual(seg.take(act), c, u.take(act), sweep.take(act), near=near.take(act))
            flip = (f_c < 0) != (f_b < 0)
            mm = 1.0 - f_c / f_b
            mm = np.where(mm > 0.0, mm, 0.5)
            a, f_a = np.where(flip, b, a), np.where(flip, f_b, f_a * mm)
            tol = TOL_D * c
            done = (np.abs(c - b) <= tol) | (f_c == 0.0) | (np.abs(c - a) <= tol)
            b, f_b = c, f_c
            out[act[done]] = c[done]
            keep = ~done
            act, a, b, f_a, f_b = act[keep], a[keep], b[keep], f_a[keep], f_b[keep]
        out[act] = b
        return out

    def _remainder(self, seg, got, near):
        """The travel-time remainder (r_s/c) of rays read by :meth:`_residual` (``got``): J at the target
        signed as theta (turning rays: negative past the periapsis / apoapsis) less J at the observer;
        next to the observer J's difference from one stencil. :meth:`_finish` adds its modulus to the
        radial part."""
        th = got["theta"]
        turning = self.s_kind.take(seg) != 1
        dj = np.where(turning, np.sign(th), 1.0) * got["j"] - got["j_o"]
        if got["j_diff"] is not None:  # next to the observer: J(theta) - J(theta_o) from one stencil
            same = near & ((th >= 0.0) | ~turning)
            dj = np.where(same, got["j_diff"], dj)
        return dj

    def _finish(self, seg, d, u, r, phi, sweep, order, near, tangents=True, carried=None) -> dict:
        """xi, dt and (with ``tangents``) ux, uy of the rays d of segments ``seg``. ``carried``: (indices,
        theta, remainder) of rays whose values are known (see :meth:`_solve`); the others' are read."""
        k = self.k
        kind = self.s_kind.take(seg)
        turning = kind != 1
        xi = self.s_crit.take(seg) + self.s_side.take(seg) * d
        n = d.size
        if carried is None or not carried[0].size:
            _, got = self._residual(seg, d, u, sweep, want=True, near=near, want_f=False)
            rho, th, b = got["rho"], got["theta"], got["b"]
            dj = self._remainder(seg, got, near)
        elif carried[0].size == n:  # every ray known
            ci = carried[0]
            th, dj = np.empty(n), np.empty(n)
            th[ci], dj[ci] = carried[1], carried[2]
            rho = b = None  # (b from xi below; rho only where needed)
        else:
            ci = carried[0]
            th, dj = np.empty(n), np.empty(n)
            th[ci], dj[ci] = carried[1], carried[2]
            rho = b = None
            rest = np.ones(n, dtype=bool)
            rest[ci] = False
            rest = np.flatnonzero(rest)
            sr = seg.take(rest)
            _, got = self._residual(sr, d.take(rest), u.take(rest), sweep.take(rest), want=True,
                                    near=near.take(rest), want_f=False)
            th[rest] = got["theta"]
            dj[rest] = self._remainder(sr, got, near.take(rest))
        rs_o = self.r_obs + math.log(self.r_obs - 1.0)
        rs_t = r + np.log(r - 1.0)
        radial = np.abs(rs_t - rs_o)
        tt = np.flatnonzero(turning & (th < 0.0))  # the ray passed its periapsis / apoapsis
        if tt.size:
            rho_tt = self._rho(seg.take(tt), d.take(tt)) if rho is None else rho.take(tt)
            r_ref = 1.0 / _reference_u("T" if kind[tt[0]] == 0 else "I", rho_tt)
            rs_ref = r_ref + np.log(r_ref - 1.0)
            radial[tt] = np.abs(rs_t[tt] - rs_ref) + np.abs(rs_o - rs_ref)
        dt = radial + np.abs(dj)
        dt = np.where(np.isinf(r), np.inf, dt)
        if not tangents:
            return dict(xi=xi, dt=dt)
        if b is None:  # the impact parameter of the ray leaving the static observer at xi
            b = np.sin(xi) * (self.r_obs / k)
        direction = self.s_dir.take(seg)
        outward = np.where(turning, (np.sign(th) * direction > 0) == (kind == 0), direction < 0)
        s2 = np.maximum(1.0 - b * b * u * u * (1.0 - u), 0.0)
        u_r = np.where(outward, 1.0, -1.0) * k * np.sqrt(s2)
        r_u_phi = np.where(order == 1, 1.0, -1.0) * k * b * u
        c, s = np.cos(phi), np.sin(phi)
        return dict(xi=xi, dt=dt, ux=u_r * c - r_u_phi * s, uy=u_r * s + r_u_phi * c)


def _cubic_at(fs, t):
    """(p(t), p'(t)) of the cubic through (j, fs[j]), j = 0..3 (fs (4, N)), in Newton form."""
    f0, f1, f2, f3 = fs
    a = f1 - f0
    c = 0.5 * (f2 - 2.0 * f1 + f0)
    e = (f3 - 3.0 * f2 + 3.0 * f1 - f0) * (1.0 / 6.0)
    return _cubic_at_coefficients(f0, a, c, e, t)


def _cubic_at_coefficients(f0, a, c, e, t):
    """(p(t), p'(t)) of the cubic p(t) = f0 + t (a + (t - 1) (c + (t - 2) e)) (Newton form through
    nodes 0..3, as :func:`_cubic_at`)."""
    t1 = t - 1.0
    q = c + (t - 2.0) * e
    return f0 + t * (a + t1 * q), a + (2.0 * t - 1.0) * c + (3.0 * t * t - 6.0 * t + 2.0) * e


def _cubic_root_nodes(dn, fn, x0, lo, hi, steps=3):
    """(root, slope there) of the cubic through (dn[j], fn[j]), j = 0..3 (arrays (4, N), distinct
    nodes in any order): Newton from x0, kept inside [lo, hi]. Divided differences, Newton form."""
    d0, d1, d2, d3 = dn
    f0, f1, f2, f3 = fn
    c01, c12, c23 = (f1 - f0) / (d1 - d0), (f2 - f1) / (d2 - d1), (f3 - f2) / (d3 - d2)
    c012, c123 = (c12 - c01) / (d2 - d0), (c23 - c12) / (d3 - d1)
    c3 = (c123 - c012) / (d3 - d0)
    x = x0
    for i in range(steps + 1):
        a, b, c = x - d0, x - d1, x - d2
        q = c012 + c * c3
        p = f0 + a * (c01 + b * q)
        dp = c01 + b * q + a * (q + b * c3)
        if i == steps:
            break
        x_new = x - p / dp
        x = np.where(np.isfinite(x_new), np.clip(x_new, lo, hi), x)
    return x, dp


def _cubic_root(fs, t0, slope=False):
    """Root in [t0, t0 + 1] of the cubic through (j, fs[j]), j = 0..3 (fs (4, N); f changes sign
    between nodes t0 and t0 + 1): Newton on the cubic from the linear interpolation, kept inside."""
    f0, f1, f2, f3 = fs
    # Newton form of the interpolating cubic: p(t) = f0 + t (a + (t - 1) (c + (t - 2) e))
    a = f1 - f0
    c = 0.5 * (f2 - 2.0 * f1 + f0)
    e = (f3 - 3.0 * f2 + 3.0 * f1 - f0) / 6.0
    n = t0.size
    at = t0.astype(np.int64) * n + np.arange(n)  # the bracket's nodes t0, t0 + 1
    flat = fs.reshape(-1) if fs.flags.c_contiguous else np.ascontiguousarray(fs).reshape(-1)
    fa, fb = flat.take(at), flat.take(at + n)
    t = t0 + np.where(fb != fa, fa / (fa - fb), 0.5)
    for _ in range(CUBIC_STEPS):
        p = f0 + t * (a + (t - 1.0) * (c + (t - 2.0) * e))
        dp = a + (2.0 * t - 1.0) * c + (3.0 * t * t - 6.0 * t + 2.0) * e
        t_new = t - p / dp
        t = np.where(np.isfinite(t_new), np.clip(t_new, t0, t0 + 1.0), t)
    if slope:  # and the cubic's derivative there
        return t, a + (2.0 * t - 1.0) * c + (3.0 * t * t - 6.0 * t + 2.0) * e
    return t


# ------------------------------------------------------------------------------------------------
# Exact connecting rays of an observer inside the photon sphere
# ------------------------------------------------------------------------------------------------
def connect_inside(r_obs, r, phi, order):
    """Connecting rays of ``order`` for a static observer inside the photon sphere (R_OBS_MIN <= r_obs
    <= 1.5 r_s) to points (r, phi) (1-D arrays, r > 1, phi in [0, pi]): dict of xi, dt, ux, uy, b, in
    lutgen.solver's conventions, exact to rounding. The orbit table's ray (:class:`RayMap`) is the
    start; secant steps in the orbit's label rho on the closed-form swept angle (Carlson's forms:
    lutgen.orbit.sweep for the rays that cross the photon sphere, sweep_inner on the inner branch)
    polish it; travel times are lutgen.orbit.travel_time and travel_time_inner."""
    r_obs = float(r_obs)
    r, phi = np.asarray(r, dtype=float), np.asarray(phi, dtype=float)
    n = r.size
    u = 1.0 / r
    uo = 1.0 / r_obs
    sweep = phi if order == 1 else 2.0 * math.pi - phi
    m = RayMap(r_obs, r_min=min(float(r.min()), r_obs) * (1 - 1e-12) if n else 1.01)
    xi0 = m.lookup(r, phi, order).xi
    v_o = uo * uo * (1.0 - uo)
    sin_c = B_C * math.sqrt(v_o)
    outward = xi0 < 0.5 * math.pi
    s = np.sin(xi0)
    plunging = s < sin_c
    kind = np.where(plunging, "P", "I")
    with np.errstate(divide="ignore", invalid="ignore"):
        # (b/b_c)^2 - 1 = (sin^2 xi - sin^2 xi_c) / sin^2 xi_c, (b_c/b)^2 - 1 = its negative over (b/b_c)^2
        xi_c = math.asin(min(sin_c, 1.0))
        x = np.where(outward, xi0, math.pi - xi0)
        num = np.sin(x - xi_c) * np.sin(x + xi_c)
        rho = np.where(plunging, np.log(-num / np.sin(x) ** 2), np.log(num / sin_c ** 2))
    out = {k: np.full(n, np.nan) for k in ("xi", "dt", "ux", "uy", "b")}
    radial = (s < 1e-12) | ~np.isfinite(rho)
    for kname in ("P", "I"):
        sel = np.flatnonzero((kind == kname) & ~radial & np.isfinite(xi0))
        if not sel.size:
            continue
        ou, uu, sw = outward[sel], u[sel], sweep[sel]

        def sweeps(rh):
            orb = _orbits(kname, rh)
            if kname == "P":
                fo, fu = _orb.sweep(orb, np.full(rh.size, uo)), _orb.sweep(orb, uu)
                return np.where(ou, fo - fu, fu - fo), orb, None
            go, gu = _orb.sweep_inner(orb, np.full(rh.size, uo)), _orb.sweep_inner(orb, uu)
            before, after = go - gu, go + gu
            past = ou & (np.abs(after - sw) < np.abs(before - sw))  # past the apoapsis
            return np.where(ou, np.where(past, after, before), gu - go), orb, past

        x0 = rho[sel]
        f0 = sweeps(x0)[0] - sw
        x1 = x0 + 1e-7 * np.maximum(1.0, np.abs(x0))
        f1 = sweeps(x1)[0] - sw
        for _ in range(6):
            with np.errstate(divide="ignore", invalid="ignore"):
                x2 = x1 - f1 * (x1 - x0) / (f1 - f0)
            x2 = np.where(np.isfinite(x2) & (f1 != f0), x2, x1)
            x0, f0 = x1, f1
            x1 = x2
            f1 = sweeps(x1)[0] - sw
            if np.all(np.abs(x1 - x0) <= 1e-14 * np.maximum(1.0, np.abs(x1))):
                break
        _, orb, past = sweeps(x1)
        b = impact_parameter(kname, x1)
        xi = np.arcsin(np.minimum(b * math.sqrt(v_o), 1.0))
        xi = np.where(ou, xi, math.pi - xi)
        if kname == "P":
            dt = _orb.travel_time(orb, np.full(sel.size, uo), uu, r_a=np.full(sel.size, r_obs), r_b=r[sel])
            going_out = ou
        else:
            to, tu = _orb.travel_time_inner(orb, np.full(sel.size, uo)), _orb.travel_time_inner(orb, uu)
            dt = np.where(ou, np.where(past, to + tu, to - tu), tu - to)
            going_out = ou & ~past
        k = math.sqrt(1.0 - uo)
        s2 = np.maximum(1.0 - b * b * uu * uu * (1.0 - uu), 0.0)
        u_r = np.where(going_out, 1.0, -1.0) * k * np.sqrt(s2)
        r_u_phi = (1.0 if order == 1 else -1.0) * k * b * uu
        c, sn = np.cos(phi[sel]), np.sin(phi[sel])
        out["xi"][sel], out["dt"][sel], out["b"][sel] = xi, dt, b
        out["ux"][sel], out["uy"][sel] = u_r * c - r_u_phi * sn, u_r * sn + r_u_phi * c
    rad = np.flatnonzero(radial & np.isfinite(xi0))
    if rad.size:  # the radial rays (phi = 0 or pi on the axis)
        inward = u[rad] > uo
        out["xi"][rad] = np.where(inward, math.pi, 0.0)
        out["dt"][rad] = _orb.radial_travel_time(uo, u[rad], r_a=r_obs, r_b=r[rad])
        k = math.sqrt(1.0 - uo)
        u_r = np.where(inward, -k, k)
        out["ux"][rad], out["uy"][rad] = u_r * np.cos(phi[rad]), u_r * np.sin(phi[rad])
        out["b"][rad] = 0.0
    return out
