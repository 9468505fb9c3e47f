"""The emitter-observer problem: null geodesics that connect a static observer with a point.

Units: lengths in r_s (Schwarzschild radius), c = 1, so times are in r_s/c; angles in radians.
Conventions (seed 000, sections 2.2-2.5): the observer is static at (r_obs, phi = 0) in the plane
through the hole, the observer and the target; the target sits at (r, phi) with 0 <= phi <= pi.
The ray is traced backwards from the observer. ``xi`` in [0, pi] is the angle between the ray's
initial direction and the outward radial direction in the observer's static orthonormal frame
(eq. 11): xi = pi looks straight at the hole.

* order 1 sweeps the angle phi (the ray leaves towards the target's side of the axis, +e2);
* order 2 passes the hole on the other side and sweeps 2*pi - phi (it leaves towards -e2; xi is
  still the unsigned angle from the outward radial direction).

(ux, uy) is the ray's tangent at the target in the plane's pseudo-Cartesian axes (eq. 17; e1 points
from the hole to the observer, e2 towards the target's side), with the affine normalisation of
eq. (11) (u^t = -1/sqrt(1 - 1/r_obs) at the observer). It points away from the observer along the
ray, so -(ux, uy) is the direction in which light leaves the target towards the observer.

Connecting rays include the ones steeper than the critical angle: they reach points close to the hole,
inside the photon sphere too, before they fall in. For every target with r > 1 and each order there is
exactly one connecting ray: along the family of rays the angle swept on reaching radius r grows
monotonically from 0 to infinity. Each case is solved with a vectorised bracketing root finder
(Chandrupatla's method, scipy.optimize.elementwise.find_root) on closed-form swept angles: direct
rays by their impact parameter b, rays that pass a periapsis e2 (and direct rays close to the ray
tangent at the nearer of observer and target, u_turn) by a label of e2 that keeps both
e2 - u_turn and 2/3 - e2 to full relative accuracy (_periapsis), with Carlson's forms of the swept
angle, so targets next to the observer's own radius at angles down to 5e-324 are solved too.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.optimize import elementwise

from . import orbit as _orb

TWO_PI = 2.0 * np.pi
_B_TINY = 1e-20


class Connection(NamedTuple):
    """A connecting null geodesic (arrays broadcast from the inputs; NaN where no ray exists).

    xi: initial angle at the observer from the outward radial direction (radians, [0, pi]).
    dt: coordinate light travel time between observer and target (units of r_s/c).
    ux, uy: ray tangent at the target in the plane's pseudo-Cartesian axes (eq. 17).
    b: impact parameter (units of r_s).
    """

    xi: np.ndarray
    dt: np.ndarray
    ux: np.ndarray
    uy: np.ndarray
    b: np.ndarray


def shadow_half_angle(r_obs) -> np.ndarray:
    """Half opening angle of the black hole's shadow for a static observer at r_obs (units of r_s,
    r_obs > 1.5): the angle xi_crit of eq. (14), sin^2 xi_crit = 27/4 (1/r_obs^2)(1 - 1/r_obs).
    Rays with xi > pi - xi_crit fall into the hole. Radians."""
    r_obs = np.asarray(r_obs, dtype=float)
    s2 = 6.75 / r_obs**2 * (1.0 - 1.0 / r_obs)
    return np.arcsin(np.sqrt(np.clip(s2, 0.0, 1.0)))


def static_observer_radius(r_obs, need: str = "> 1 r_s") -> float:
    """A static observer's radius (units of r_s) as float; ValueError for what is not a finite number
    and for observers on or inside the horizon (no static observer exists there). ``need``: what the
    caller requires, for the message."""
    try:
        r = float(r_obs)
    except (TypeError, ValueError):
        raise ValueError(f"r_obs must be a number (units of r_s), got {r_obs!r}") from None
    if not np.isfinite(r):
        raise ValueError(f"r_obs must be finite, got {r}")
    if r <= 1.0:
        raise ValueError(f"observer at r_obs = {r:.6g} r_s is inside the event horizon (r_obs must be {need})")
    return r


def check_observer_radius(r_obs: float) -> float:
    """Validate a static observer radius (units of r_s) and return it as float.

    Raises ValueError for NaN/inf, for observers inside the horizon (no static observer exists there)
    and for observers inside the photon sphere (r_obs <= 1.5, not supported: the ray families differ).
    """
    r = static_observer_radius(r_obs, "> 1.5 r_s")
    if r <= 1.5:
        raise ValueError(
            f"observer at r_obs = {r} r_s is inside the photon sphere; only r_obs > 1.5 r_s is supported")
    return r


def _bracket_root(f, lo, hi, args, *, xatol, xrtol, maxiter=200):
    """Vectorised root of f(x, *args) on [lo, hi] (f(lo) and f(hi) of opposite signs)."""
    res = elementwise.find_root(
        f, (lo, hi), args=args,
        tolerances=dict(xatol=xatol, xrtol=xrtol, fatol=0.0, frtol=0.0),
        maxiter=maxiter,
    )
    return res.x


_B_SMALL = 0.5  # below this impact parameter _direct_sweep integrates b / S(u) directly


def _direct_sweep(b, u, uo):
    """Angle swept by a ray of impact parameter b between uo and u without a turning point."""
    b, u, uo = np.broadcast_arrays(np.asarray(b, dtype=float), u, uo)
    out = np.empty(b.shape)
    # b / S(u) is also smooth on legs much shorter than their distance from the nearest root of
    # S^2 = 1 - b^2 u^2 (1 - u) (estimated from its slope <= 2 b^2 u); there the difference of the
    # elliptic integrals cancels (it would need to resolve |u - uo| ~ 1e-17)
    with np.errstate(invalid="ignore"):
        b2, u_max = b * b, np.maximum(u, uo)
        s2_min = 1.0 - b2 * np.maximum(u * u * (1.0 - u), uo * uo * (1.0 - uo))
        short = (s2_min >= 1e-3) & (np.abs(u - uo) * 40.0 * b2 * u_max <= s2_min)
    small = (b <= _B_SMALL) | short
    if small.any():
        out[small] = _small_b_sweep(b[small], u[small], uo[small])
    big = ~small
    if big.any():
        orb = _orb.orbit_from_b(b[big])
        out[big] = np.abs(_orb.sweep(orb, u[big]) - _orb.sweep(orb, uo[big]))
    return out


def _small_b_sweep(b, u, uo):
    """Swept angle of a steep ray (b <= _B_SMALL, or a short leg, see _direct_sweep) between u and uo:
    b * integral du / S(u), S = sqrt(1 - b^2 u^2 (1 - u)) = b sqrt(P(u)), written as
    b (|u - uo| + integral (1/S - 1) du) with 1/S - 1 = x / (S (1 + S)), x = b^2 u^2 (1 - u) <= 4 b^2/27.

    The correction is smooth (S >= 0.98) and small, so 12-point Gauss-Legendre gives it to rounding;
    unlike the difference of the elliptic integrals F(u) - F(uo) (each ~ b^(1/3)) this keeps full
    relative accuracy for b -> 0 and for u -> uo, and stays finite down to b = 0 (linear in b below
    ~1e-8)."""
    lo, hi = np.minimum(u, uo), np.maximum(u, uo)
    half = 0.5 * (hi - lo)
    uu = (lo + half)[:, None] + half[:, None] * _orb._GL_X
    x = (b * b)[:, None] * uu * uu * (1.0 - uu)
    s = np.sqrt(1.0 - x)
    corr = np.einsum("ij,j->i", x / (s * (1.0 + s)), _orb._GL_W) * half
    return b * ((hi - lo) + corr)


_Z_MIN = -1500.0  # exp(_Z_MIN / 2) underflows to 0: the tangent ray at u_turn itself


def _periapsis(z, u_turn, span):
    """Turning orbits labelled by z in R: periapsis e2 = u_turn + w between u_turn (z -> -inf) and the
    photon sphere (z -> +inf), w = span / (1 + e^-z), eps = 2/3 - e2 = span / (1 + e^z), with
    span = 2/3 - u_turn. Returns (orbit, sqrt(w), eps); both w (down to ~1e-600 through sqrt(w)) and
    eps keep their relative accuracy, unlike e2 itself next to u_turn."""
    ez = np.exp(np.minimum(z, 700.0))
    sq_w = np.sqrt(span) * np.exp(0.5 * z) / np.sqrt(1.0 + ez)
    eps = span / (1.0 + ez)
    return _orb.orbit_from_turning_point(eps, e2=u_turn + sq_w * sq_w), sq_w, eps


def _turning_sweep(z, u_turn, span, du):
    """Angle swept by orbit z (see _periapsis) from inverse radius u_turn - du (the farther of observer
    and target) in to its periapsis and back out to u_turn."""
    orb, sq_w, _ = _periapsis(z, u_turn, span)
    return (_orb.sweep_from_turning_point(orb, u_turn, sq_w)
            + _orb.sweep_from_turning_point(orb, u_turn - du, np.hypot(sq_w, np.sqrt(du))))


def _near_tangent_sweep(z, u_turn, span, du):
    """Angle swept by orbit z (see _periapsis) directly from u_turn - du to u_turn (short of its
    periapsis): direct rays close to the tangent one, where F(u_turn) - F(u_turn - du) would need e2
    far below its rounding (and cancels for small du). Decreases from the tangent ray's sweep
    (z -> -inf) as z grows."""
    orb, sq_w, _ = _periapsis(z, u_turn, span)
    return _orb.sweep_between(orb, u_turn - du, u_turn, np.hypot(sq_w, np.sqrt(du)), sq_w)


def connect(r_obs, r, phi, order: int = 1) -> Connection:
    """Connecting null geodesic of the given order between a static observer at (r_obs, 0) and the
    points (r, phi), vectorised over ``r`` and ``phi`` (broadcast).

    Parameters: r_obs (scalar, units of r_s, >= 1.001; inside the photon sphere, r_obs <= 1.5, the rays
    come from lutgen.rays.connect_inside), r (units of r_s), phi (radians, [0, pi]),
    order 1 (sweeps phi) or 2 (sweeps 2*pi - phi). Points that no ray reaches (r <= 1, inside the
    horizon), or with NaN/inf/out-of-range input, come back as NaN in every field.
    See the module docstring for conventions; returns a :class:`Connection`.
    """
    inside = static_observer_radius(r_obs, ">= 1.001 r_s") <= 1.5
    if inside:
        from .rays import check_any_observer
        r_obs = check_any_observer(r_obs)
    else:
        r_obs = check_observer_radius(r_obs)
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order!r}")
    r, phi = np.broadcast_arrays(np.asarray(r, dtype=float), np.asarray(phi, dtype=float))
    shape = r.shape
    r = r.ravel()
    phi = phi.ravel()
    out = {k: np.full(r.shape, np.nan) for k in Connection._fields}
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & np.isfinite(phi) & (r > 1.0) & (phi >= 0.0) & (phi <= np.pi)
    idx = np.flatnonzero(ok)
    if idx.size:
        if inside:
            from .rays import connect_inside
            res = connect_inside(r_obs, r[idx], phi[idx], order)
        else:
            res = _solve(r_obs, r[idx], phi[idx], order)
        for k in Connection._fields:
            out[k][idx] = res[k]
    return Connection(**{k: v.reshape(shape) for k, v in out.items()})


def _solve(r_obs, r, phi, order):
    uo = 1.0 / r_obs
    u = 1.0 / r
    sweep = phi if order == 1 else TWO_PI - phi
    n = u.size
    b = np.zeros(n)
    eps = np.full(n, np.nan)
    sq_w = np.full(n, np.nan)
    branch = np.zeros(n, dtype=np.int8)  # 0 radial, 1 direct inbound, 2 direct outbound, 3 turning

    radial = sweep == 0.0
    inward = u > uo  # target closer to the hole than the observer
    # Largest impact parameter of the direct (turning-point-free) branch and the angle it sweeps.
    u_turn = np.where(inward, u, uo)
    can_turn = u_turn < _orb.U_PHOTON
    with np.errstate(divide="ignore", invalid="ignore"):
        b_turn = np.where(can_turn, 1.0 / (u_turn * np.sqrt(1.0 - u_turn)), _orb.B_CRIT)
        b_max = np.where(can_turn, b_turn, _orb.B_CRIT * (1.0 - 1e-15))
    span = _orb.U_PHOTON - u_turn
    du = np.abs(u - uo)
    sweep_turn = np.full(n, np.inf)
    ct = np.flatnonzero(can_turn & ~radial)
    if ct.size:
        # the tangent ray at u_turn: exactly the turning sweep of z = _Z_MIN, so the turning bracket
        # below always has its sign change
        sweep_turn[ct] = _turning_sweep(np.full(ct.size, _Z_MIN), u_turn[ct], span[ct], du[ct])

    direct = ~radial & (sweep <= sweep_turn)
    turning = ~radial & ~direct
    branch[direct & inward] = 1
    branch[direct & ~inward] = 2
    branch[turning] = 3

    d = np.flatnonzero(direct)
    # direct rays close to the tangent one (the orbit's periapsis just beyond u_turn): solved in the
    # periapsis label z in [_Z_MIN, 0] (f(_Z_MIN) = sweep_turn - phi >= 0 by construction)
    dc = d[can_turn[d]]
    if dc.size:
        z0 = np.zeros(dc.size)
        sweep_mid = _near_tangent_sweep(z0, u_turn[dc], span[dc], du[dc])
        b_max[dc] = 1.0 / _periapsis(z0, u_turn[dc], span[dc])[0].inv_b
        nt = dc[sweep[dc] > sweep_mid]
        if nt.size:
            f = lambda z, uu, sp, dd, target: _near_tangent_sweep(z, uu, sp, dd) - target  # noqa: E731
            z = _bracket_root(f, np.full(nt.size, _Z_MIN), np.zeros(nt.size),
                              (u_turn[nt], span[nt], du[nt], sweep[nt]), xatol=1e-15, xrtol=2.5e-16)
            orb, sq_w[nt], eps[nt] = _periapsis(z, u_turn[nt], span[nt])
            b[nt] = 1.0 / orb.inv_b
            d = np.setdiff1d(d, nt, assume_unique=True)
    if d.size:
        # Below b = _B_TINY the swept angle is linear in b (see _direct_sweep), so a target that needs
        # no more than the sweep of _B_TINY is solved exactly by proportion (the bracketing root finder
        # needs ~1.6 iterations per decade of b and ran out of them for phi <~ 1e-46).
        sweep_tiny = _direct_sweep(np.full(d.size, _B_TINY), u[d], uo)
        lin = sweep[d] <= sweep_tiny
        if lin.any():
            b[d[lin]] = _B_TINY * (sweep[d[lin]] / sweep_tiny[lin])
        d = d[~lin]
    if d.size:
        # the two forms of the swept angle at b_max agree only to rounding: a target between them
        # gets b_max (the root finder would see no sign change)
        edge = _direct_sweep(b_max[d], u[d], uo) <= sweep[d]
        b[d[edge]] = b_max[d[edge]]
        d = d[~edge]
    if d.size:
        f = lambda bb, uu, uuo, target: _direct_sweep(bb, uu, uuo) - target  # noqa: E731
        b[d] = _bracket_root(f, np.zeros(d.size), b_max[d], (u[d], uo * np.ones(d.size), sweep[d]),
                             xatol=1e-300, xrtol=4e-16)
    t = np.flatnonzero(turning)
    if t.size:
        # solve in z = log(w / eps) (see _periapsis): the swept angle grows like -log(eps) ~ z as the
        # periapsis approaches the photon sphere, and like sqrt(w) ~ e^(z/2) above the tangent ray's
        # (the periapsis next to u_turn: targets next to the observer's radius at tiny angles)
        f = lambda z, uu, sp, dd, target: _turning_sweep(z, uu, sp, dd) - target  # noqa: E731
        args = (u_turn[t], span[t], du[t], sweep[t])
        z_lo = np.full(t.size, -20.0)  # w ~ 2e-9 span: a shorter bracket where it is one
        z_lo[f(z_lo, *args) > 0.0] = _Z_MIN
        z_hi = np.log(span[t] / 1e-15)  # eps >= ~1e-15
        z = _bracket_root(f, z_lo, z_hi, args, xatol=1e-15, xrtol=2.5e-16)
        _, sq_w[t], eps[t] = _periapsis(z, u_turn[t], span[t])

    return _finish(r_obs, u, uo, phi, order, b, eps, branch, r=r, sq_w=sq_w)


def _labelled_orbits(b, eps, sq_w, u, uo):
    """Orbits labelled by their periapsis (eps = 2/3 - e2 and sq_w = sqrt(e2 - u_turn), u_turn =
    max(u, uo), see _periapsis) or, where eps is NaN, by b. Returns (orbit, b, sqrt(e2 - uo),
    sqrt(e2 - u)); the square roots come from the label (NaN for orbits labelled by b, NaN sq_w
    counts as 0): next to the tangent ray e2 - x is far below the rounding of e2."""
    by_b = np.isnan(eps)
    if by_b.all():  # (the grid solver's rays)
        orb = _orb.orbit_from_b(b)
        return orb, 1.0 / orb.inv_b, None, None
    w = np.where(by_b | np.isnan(sq_w), 0.0, sq_w)
    u_turn = np.maximum(u, uo)
    orb = _orb.orbit_from_turning_point(np.where(by_b, 0.1, eps), e2=np.where(by_b, 0.1, u_turn + w * w))
    if by_b.any():
        ob = _orb.orbit_from_b(b[by_b])
        for f in ("e1", "real", "e2", "e3", "delta", "m", "n"):
            getattr(orb, f)[by_b] = getattr(ob, f)
    with np.errstate(invalid="ignore"):
        sq_far = np.hypot(w, np.sqrt(np.abs(u - uo)))  # at the farther point, u_turn - |u - uo|
    sq_o = np.where(by_b, np.nan, np.where(u > uo, sq_far, w))
    sq_u = np.where(by_b, np.nan, np.where(u > uo, w, sq_far))
    return orb, 1.0 / orb.inv_b, sq_o, sq_u


def _sqrt_p(orb, x, sq):
    """sqrt(P(x)) = sqrt((x - e1)(e2 - x)(e3 - x)), with e2 - x = sq^2 where sq is known (not NaN)."""
    if sq is None:
        return np.sqrt(np.maximum(orb.P(x), 0.0))
    with np.errstate(invalid="ignore"):
        known = np.sqrt((x - orb.e1) * (orb.delta + sq * sq)) * sq
    return np.where(np.isnan(sq), np.sqrt(np.maximum(orb.P(x), 0.0)), known)


def _finish(r_obs, u, uo, phi, order, b, eps, branch, r=None, sq_w=None):
    """Initial angle, travel time and arrival direction from the solved orbits.

    ``r``: the targets' radii (default 1/u). Passing the exact input keeps r finite where 1/u
    would not round back to it (u = 1/r is subnormal for r >~ 4.5e307). ``sq_w`` (optional, with
    ``eps``): sqrt(e2 - max(u, uo)) of turning orbits labelled by their periapsis (see _periapsis).
    """
    n = u.size
    if r is None:
        with np.errstate(divide="ignore"):
            r = 1.0 / u
    if sq_w is None:
        sq_w = np.full(n, np.nan)
    xi = np.empty(n)
    dt = np.empty(n)
    u_r = np.empty(n)  # dr/dlambda at the target
    b_out = b.copy()
    k = np.sqrt(1.0 - uo)

    rad = branch == 0
    if rad.any():
        inward = u[rad] > uo
        # a point at the observer's own position gets the limit phi -> 0+ of its circle: tangential
        xi[rad] = np.where(inward, np.pi, np.where(u[rad] < uo, 0.0, 0.5 * np.pi))
        dt[rad] = _orb.radial_travel_time(uo, u[rad], r_a=r_obs, r_b=r[rad])
        u_r[rad] = np.where(inward, -k, k)

    dirm = (branch == 1) | (branch == 2)
    if dirm.any():
        # below _B_TINY the ray is radial to double precision (b sqrt(P) = 1); orbit_from_b itself
        # overflows for b <~ 1e-154
        orb, bb, sq_o, sq_u = _labelled_orbits(np.maximum(b[dirm], _B_TINY), eps[dirm], sq_w[dirm],
                                               u[dirm], uo)
        b_out[dirm] = np.where(np.isnan(eps[dirm]), b[dirm], bb)
        outward = branch[dirm] == 2
        cos_xi = np.where(outward, 1.0, -1.0) * bb * _sqrt_p(orb, uo, sq_o)
        xi[dirm] = np.arctan2(b_out[dirm] * k * uo, cos_xi)
        dt[dirm] = _orb.travel_time(orb, uo, u[dirm], r_a=r_obs, r_b=r[dirm],
                                    sqrt_gap=None if sq_o is None else (sq_o, sq_u))
        u_r[dirm] = np.where(outward, 1.0, -1.0) * k * bb * _sqrt_p(orb, u[dirm], sq_u)

    tm = branch == 3
    if tm.any():
        orb, bb, sq_o, sq_u = _labelled_orbits(b[tm], eps[tm], sq_w[tm], u[tm], uo)
        b_out[tm] = bb
        cos_xi = -bb * _sqrt_p(orb, uo, sq_o)
        xi[tm] = np.arctan2(bb * k * uo, cos_xi)
        if sq_o is None:
            gaps_o = gaps_u = None
        else:
            zero = np.where(np.isnan(sq_o), np.nan, 0.0)  # sqrt(e2 - e2)
            gaps_o, gaps_u = (sq_o, zero), (sq_u, zero)
        dt[tm] = (_orb.travel_time(orb, uo, orb.e2, r_a=r_obs, sqrt_gap=gaps_o)
                  + _orb.travel_time(orb, u[tm], orb.e2, r_a=r[tm], sqrt_gap=gaps_u))
        u_r[tm] = k * bb * _sqrt_p(orb, u[tm], sq_u)

    # r u^phi = h/r = k b u (u^phi negative for order 2, which sweeps towards -phi); formed without
    # u^2, which underflows for far targets
    r_u_phi = (1.0 if order == 1 else -1.0) * k * b_out * u
    c, s = np.cos(phi), np.sin(phi)
    ux = u_r * c - r_u_phi * s
    uy = u_r * s + r_u_phi * c
    return dict(xi=xi, dt=dt, ux=ux, uy=uy, b=b_out)


# --------------------------------------------------------------------------------------------------
# Grids: one observer, rows of constant r, many angles (the lookup table's shape)
# --------------------------------------------------------------------------------------------------
_N_SAMPLES = 768   # samples of the ray family per row
_Q_MAX = 36.0     # family parameter range, q in [0, _Q_MAX] (see _family)


def _family(uo, u, q):
    """The rays that reach inverse radius ``u`` (column vector), labelled by q >= 0 (broadcast).

    Along the family the swept angle grows monotonically from 0 (q = 0, radial ray) to infinity
    (q -> inf, the critical ray). For a target inside the observer's radius (u > uo) the label is the
    angle psi between the ray and the inward radial direction at the target, psi = p_max (1 - e^-q):
    psi < pi/2 arrives before the periapsis, psi > pi/2 after it. For a target outside it (u <= uo) the
    label is xi itself, xi = p_max (1 - e^-q): xi > pi/2 passes a periapsis first.
    Returns (b, turning): impact parameter (r_s) and whether the ray passes a periapsis first.
    """
    inward = u > uo
    g = np.where(inward, u * np.sqrt(1.0 - u), uo * np.sqrt(1.0 - uo))  # sin(angle) = b g
    s_c = np.minimum(_orb.B_CRIT * g, 1.0)
    p_max = np.where(inward & (u >= _orb.U_PHOTON), np.arcsin(s_c), np.pi - np.arcsin(s_c))
    p = p_max * -np.expm1(-q)
    return np.sin(p) / g, p > 0.5 * np.pi


def _family_sweep(uo, u, q):
    b, turning = _family(uo, u, q)
    b_eval = np.maximum(b, _B_TINY)
    orb = _orb.orbit_from_b(b_eval)
    f_u, f_o = _orb.sweep(orb, u), _orb.sweep(orb, uo)
    out = np.abs(f_u - f_o) * (b / b_eval)
    turning = np.broadcast_to(turning, out.shape)
    if turning.any():
        half = _orb.sweep_to_turning_point(orb.subset(turning))
        out[turning] = 2.0 * half - f_u[turning] - f_o[turning]
    return out


def connect_grid(r_obs, r, phi) -> tuple[Connection, Connection]:
    """Connecting rays of both orders for every pair of the radii ``r`` (1-D, r_s) and angles ``phi``
    (1-D, radians in [0, pi]): returns (order 1, order 2) Connections of shape (len(r), len(phi)).

    Same results as :func:`connect` (to its accuracy) but much faster on grids: for each radius the
    family of rays reaching it is sampled once, every target angle of both orders gets a guaranteed
    bracket and a cubic first guess from those samples, and a safeguarded secant iteration polishes
    it (about three evaluations of the swept angle per node instead of a dozen).
    """
    r_obs = check_observer_radius(r_obs)
    r = np.asarray(r, dtype=float).ravel()
    phi = np.asarray(phi, dtype=float).ravel()
    out = {1: {k: np.full((r.size, phi.size), np.nan) for k in Connection._fields},
           2: {k: np.full((r.size, phi.size), np.nan) for k in Connection._fields}}
    with np.errstate(invalid="ignore"):
        rows = np.flatnonzero(np.isfinite(r) & (r > 1.0))
        cols = np.flatnonzero(np.isfinite(phi) & (phi >= 0.0) & (phi <= np.pi))
    if rows.size and cols.size:
        uo = 1.0 / r_obs
        u = 1.0 / r[rows]
        ph = phi[cols]
        targets = np.concatenate([ph, TWO_PI - ph])  # order 1 then order 2 swept angles
        q = _solve_family(uo, u, targets)
        for order, sl in ((1, slice(0, ph.size)), (2, slice(ph.size, None))):
            qq = q[:, sl]
            uu = np.broadcast_to(u[:, None], qq.shape).ravel()
            b, turning = _family(uo, uu, qq.ravel())
            branch = np.where(turning, 3, np.where(uu > uo, 1, 2)).astype(np.int8)
            branch[qq.ravel() == 0.0] = 0
            b = np.where(branch == 0, 0.0, b)
            res = _finish(r_obs, uu, uo, np.broadcast_to(ph, qq.shape).ravel(), order, b,
                          np.full(uu.size, np.nan), branch,
                          r=np.broadcast_to(r[rows][:, None], qq.shape).ravel())
            for k in Connection._fields:
                out[order][k][np.ix_(rows, cols)] = res[k].reshape(qq.shape)
    return Connection(**out[1]), Connection(**out[2])


def _solve_family(uo, u, targets):
    """Family labels q (len(u), len(targets)) whose rays sweep ``targets`` (radians) on reaching u."""
    n_r, m = u.size, targets.size
    qs = np.linspace(0.0, _Q_MAX, _N_SAMPLES)
    samples = _family_sweep(uo, u[:, None], qs[None, :])  # (n_r, S), increasing along each row
    samples[:, 0] = 0.0
    samples = np.maximum.accumulate(np.nan_to_num(samples, nan=np.inf), axis=1)
    # bracket: samples[k] <= target < samples[k+1]
    k = np.empty((n_r, m), dtype=np.int64)
    for i in range(n_r):  # one searchsorted per row (n_r calls; vectorised over targets)
        k[i] = np.searchsorted(samples[i], targets, side="right") - 1
    k = np.clip(k, 0, _N_SAMPLES - 2)
    rows = np.arange(n_r)[:, None]
    lo, hi = qs[k], qs[k + 1]
    flo, fhi = samples[rows, k] - targets, samples[rows, k + 1] - targets
    # first guess: cubic (Catmull-Rom-like) inverse interpolation through 4 samples, clipped
    km = np.clip(k - 1, 0, _N_SAMPLES - 4)
    xs = qs[km[..., None] + np.arange(4)]
    ys = samples[rows[..., None], km[..., None] + np.arange(4)] - targets[None, :, None]
    guess, slope = _inverse_lagrange(xs, ys)
    bad = ~np.isfinite(guess) | (guess <= lo) | (guess >= hi)
    lin = lo - flo * (hi - lo) / np.where(fhi - flo > 0, fhi - flo, 1.0)
    guess = np.where(bad, lin, guess)
    exact0 = targets[None, :] == 0.0
    uu = np.broadcast_to(u[:, None], (n_r, m))
    tt = np.broadcast_to(targets[None, :], (n_r, m))
    q = _polish(lambda x, idx: _family_sweep(uo, uu.ravel()[idx], x) - tt.ravel()[idx],
                lo.ravel(), hi.ravel(), flo.ravel(), fhi.ravel(), guess.ravel(),
                slope0=np.where(bad, np.nan, slope).ravel())
    q = q.reshape(n_r, m)
    q[np.broadcast_to(exact0, q.shape)] = 0.0
    return q


def _inverse_lagrange(xs, ys):
    """Inverse cubic interpolation through 4 points (ys, xs) per element ((..., 4) inputs): the x where
    it passes y = 0, and its slope dx/dy there (NaN where it is undefined)."""
    x = np.zeros(xs.shape[:-1])
    dx = np.zeros(xs.shape[:-1])
    with np.errstate(divide="ignore", invalid="ignore"):
        for i in range(4):
            w = np.ones(xs.shape[:-1])
            dsum = np.zeros(xs.shape[:-1])
            for j in range(4):
                if i != j:
                    w = w * (0.0 - ys[..., j]) / (ys[..., i] - ys[..., j])
                    dsum = dsum + 1.0 / (0.0 - ys[..., j])
            x = x + w * xs[..., i]
            dx = dx + w * dsum * xs[..., i]
    return x, dx


def _polish(f, lo, hi, flo, fhi, x0, *, slope0=None, xtol=1e-13, ftol=1e-14, maxiter=100):
    """Safeguarded secant (regula falsi with bisection fallback) for increasing f on brackets.

    f(x, idx) evaluates the elements ``idx``; lo/hi bracket the roots with f(lo) <= 0 <= f(hi).
    ``slope0`` (optional): an estimate of dx/df at the root, used for the first (Newton-like) step.
    Stops when the step or the bracket is below ``xtol`` (relative to max(1, |x|)) or |f| <= ``ftol``
    (the swept angles, up to 2 pi, carry ~1e-14 rad of rounding, so closer is noise).
    """
    x = x0.copy()
    lo, hi, flo, fhi = lo.copy(), hi.copy(), flo.copy(), fhi.copy()
    idx = np.flatnonzero(hi > lo)
    x_prev = np.full(x.size, np.nan)
    f_prev = np.full(x.size, np.nan)
    for it in range(maxiter):
        if idx.size == 0:
            break
        fx = f(x[idx], idx)
        done = (np.abs(fx) <= ftol) | ~np.isfinite(fx)
        # shrink the bracket
        neg = fx < 0
        lo[idx[neg]], flo[idx[neg]] = x[idx[neg]], fx[neg]
        pos = fx > 0
        hi[idx[pos]], fhi[idx[pos]] = x[idx[pos]], fx[pos]
        # secant step from the previous iterate (or the nearer bracket end), else bisection
        xp = np.where(np.isfinite(x_prev[idx]), x_prev[idx], np.where(neg, hi[idx], lo[idx]))
        fp = np.where(np.isfinite(f_prev[idx]), f_prev[idx], np.where(neg, fhi[idx], flo[idx]))
        with np.errstate(divide="ignore", invalid="ignore"):
            xn = x[idx] - fx * (x[idx] - xp) / (fx - fp)
            if it == 0 and slope0 is not None:
                newton = x[idx] - fx * slope0[idx]
                xn = np.where(np.isfinite(newton), newton, xn)
        mid = 0.5 * (lo[idx] + hi[idx])
        outside = ~np.isfinite(xn) | (xn <= lo[idx]) | (xn >= hi[idx])
        if it >= 6:  # slow progress: alternate with bisection
            outside |= (it % 2 == 1)
        xn = np.where(outside, mid, xn)
        step = np.abs(xn - x[idx])
        x_prev[idx], f_prev[idx] = x[idx], fx
        x[idx] = np.where(done, x[idx], xn)
        conv = done | (step <= xtol * np.maximum(1.0, np.abs(x[idx]))) | (hi[idx] - lo[idx] <= xtol)
        idx = idx[~conv]
    return x


# --------------------------------------------------------------------------------------------------
# Refining a close guess (e.g. a lookup table's) to the exact connecting ray
# --------------------------------------------------------------------------------------------------
_REFINE_STEP = 1e-6  # the first secant's step in the family label q (the sweep's slope is smooth in q)
_REFINE_ITERATIONS = 12  # secant steps at most (guesses within 1e-5 rad need 1-4)


def refine_xi(r_obs, r, phi, order: int, xi) -> np.ndarray:
    """The exact initial angle xi (radians, see :func:`connect`) of the connecting ray of ``order``
    (1 or 2) from the static observer at ``r_obs`` (units of r_s) to the points (r, phi) (units of
    r_s, radians in [0, pi]; 1-D, broadcast), refined from close guesses ``xi`` (radians), e.g. a
    lookup table's interpolated values (errors up to about 1e-4 rad).

    Each point's guess is turned into the label q of the family of rays that reach its radius (the
    one :func:`connect_grid` solves in; along it the swept angle grows smoothly and monotonically, also
    through the periapsis), then one secant step on the closed-form swept angle corrects it: the
    error falls to about the guess's error squared times the sweep's curvature, and secant steps
    through the last two iterates take it to rounding, about 1e-12 rad (one more step for nearly
    every point of a table's guesses, a few next to the photon sphere). A target inside the observer's radius has two rays of the
    guess's impact parameter (arriving before and after a periapsis): the one whose swept angle is
    nearer the target is taken. Four or five closed-form swept angles per point (about a twentieth of
    :func:`connect`'s cost). Observers inside the photon sphere (r_obs <= 1.5), points whose
    guess is not finite and the few whose steps do not settle within _REFINE_ITERATIONS are solved
    by :func:`connect` itself. NaN where connect gives NaN."""
    r_obs = static_observer_radius(r_obs, ">= 1.001 r_s")
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order!r}")
    r, phi, xi = np.broadcast_arrays(np.asarray(r, dtype=float), np.asarray(phi, dtype=float),
                                     np.asarray(xi, dtype=float))
    shape = r.shape
    r, phi, xi = r.ravel(), phi.ravel(), xi.ravel()
    out = np.full(r.shape, np.nan)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(r) & np.isfinite(phi) & (r > 1.0) & (phi >= 0.0) & (phi <= np.pi)
        guess = ok & np.isfinite(xi) & (r_obs > 1.5)
    if guess.any():
        idx = np.flatnonzero(guess)
        out[idx] = _refine(r_obs, r[idx], phi[idx], order, xi[idx])
    with np.errstate(invalid="ignore"):
        rest = np.flatnonzero(ok & ~np.isfinite(out))
    if rest.size:
        out[rest] = connect(r_obs, r[rest], phi[rest], order).xi
    return out.reshape(shape)


def _label_limits(uo, u):
    """(inward, g, p_max) of _family: target inside the observer's radius, sin(label) = b g, the
    label's upper limit (the critical ray)."""
    inward = u > uo
    g = np.where(inward, u * np.sqrt(1.0 - u), uo * np.sqrt(1.0 - uo))
    s_c = np.minimum(_orb.B_CRIT * g, 1.0)
    p_max = np.where(inward & (u >= _orb.U_PHOTON), np.arcsin(s_c), np.pi - np.arcsin(s_c))
    return inward, g, p_max


def _label_of_angle(p, p_max):
    """The family label q >= 0 of the angle label p (clipped into [0, p_max))."""
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.clip(p / p_max, 0.0, 1.0 - 1e-16)
    return -np.log1p(-frac)


def _refine(r_obs, r, phi, order, xi):
    uo, u = 1.0 / r_obs, 1.0 / r
    k_o = np.sqrt(1.0 - uo)
    target = phi if order == 1 else TWO_PI - phi
    inward, g, p_max = _label_limits(uo, u)
    # the guess's label: xi itself outside the observer's radius; inside it the angle psi at the
    # target, sin(psi) = b g with b = sin(xi) / (k_o uo), before (psi < pi/2) or after a periapsis
    with np.errstate(invalid="ignore"):
        s_psi = np.clip(np.sin(xi) / (k_o * uo) * g, 0.0, 1.0)
    psi = np.arcsin(s_psi)
    q = _label_of_angle(np.where(inward, psi, xi), p_max)
    h = _REFINE_STEP * np.maximum(q, 1e-3)
    # one evaluation of the sweep (a few numpy calls whatever the size: small frames pay per call) at
    # the label, a step beside it, and for a target inside the observer's radius the same for the ray
    # after the periapsis, where the family has one: the nearer sweep wins
    two = np.flatnonzero(inward & (np.pi - psi < p_max))
    q_t = _label_of_angle(np.pi - psi[two], p_max[two])
    h_t = _REFINE_STEP * np.maximum(q_t, 1e-3)
    n, m = q.size, two.size
    sweeps = _family_sweep(uo, np.concatenate([u, u, u[two], u[two]]), np.concatenate([q, q + h, q_t, q_t + h_t]))
    f, f_h = sweeps[:n] - target, sweeps[n:2 * n] - target
    if m:
        f_t, f_th = sweeps[2 * n:2 * n + m] - target[two], sweeps[2 * n + m:] - target[two]
        better = np.abs(f_t) < np.abs(f[two])
        pick = two[better]
        q[pick], h[pick], f[pick], f_h[pick] = q_t[better], h_t[better], f_t[better], f_th[better]
    with np.errstate(divide="ignore", invalid="ignore"):
        q_new = np.maximum(q - f * h / (f_h - f), 0.0)
    q_new = np.where(np.isfinite(q_new), q_new, q)
    # secant steps through the last two iterates until a step is small: one more for nearly every
    # point (the table's guesses); next to the photon sphere (periapses at ~1.5 r_s) the sweep curves
    # strongly in q and needs a few
    todo = np.arange(q.size)
    q_prev, f_prev = q, f
    for _ in range(_REFINE_ITERATIONS):
        f_new = _family_sweep(uo, u[todo], q_new[todo]) - target[todo]
        with np.errstate(divide="ignore", invalid="ignore"):
            q_next = np.maximum(q_new[todo] - f_new * (q_new[todo] - q_prev) / (f_new - f_prev), 0.0)
        ok = np.isfinite(q_next) & (f_new != f_prev)
        q_next = np.where(ok, q_next, q_new[todo])
        # a secant step leaves an error of about the curvature times this step times the last one:
        # below 1e-9 (relative) that is far below rounding
        going = ok & (np.abs(q_next - q_new[todo]) > 1e-9 * np.maximum(q_next, 1e-3))
        # a step that stalls far from the target (a guess beyond the critical ray, clipped there) is
        # not converged: the last step left about its residual squared, so that must be small
        stalled = ~going & ~(np.abs(f_new) <= 1e-6)
        q_prev, f_prev = q_new[todo][going], f_new[going]
        q_new[todo] = np.where(stalled, np.nan, q_next)
        todo = todo[going]
        if not todo.size:
            break
    q_new[todo] = np.nan  # not converged (guesses far off next to the photon sphere): connect solves them
    q_new[target == 0.0] = 0.0
    p = p_max * -np.expm1(-q_new)
    with np.errstate(invalid="ignore"):
        s_xi = np.clip(np.sin(p) / g * k_o * uo, 0.0, 1.0)
    return np.where(inward, np.pi - np.arcsin(s_xi), p)
