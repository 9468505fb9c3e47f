"""Independent numerical reference solver of the Schwarzschild emitter-observer problem.

Test-only code: it exists to cross-check the closed-form (elliptic-function) solver. It uses no
elliptic functions and no closed form of the orbit equation: light rays are found by integrating
the geodesic equations (5)-(7) of seed paper 000 (Mueller, Schulz & Weiskopf 2021) as a 6-D
first-order system for (t, r, phi, u^t, u^r, u^phi) with ``scipy.integrate.solve_ivp`` (DOP853,
rtol 1e-12 and essentially relative error control, terminal events located on the dense
output), and connecting rays by shooting + ``scipy.optimize.brentq``. By default the system is
integrated in sigma, d lambda = (r - 1) d sigma (a Sundman time transformation: same orbits and
tangents, but no pole of u^t at the horizon and steps uniform in log r far out);
``shoot(..., parametrisation="affine")`` integrates in the affine parameter lambda itself. r is
carried as r - 1 so that it keeps its relative precision next to the horizon. The only
closed-form ingredient is the critical (shadow) angle of eq. (14), ``shadow_xi_crit``; the
constants of motion (eq. 13) appear only in diagnostics and in extrapolating rays that have
left the region of interest.

Units and conventions
---------------------
* r_s = 1 (lengths in Schwarzschild radii), c = 1 (times in r_s / c), angles in radians.
* Schwarzschild coordinates (t, r, phi) in the equatorial plane theta = pi/2.
* The static observer sits at (r_obs, phi = 0), r_obs > 1.5 (outside the photon sphere).
* A ray is traced past-directed from the observer (backwards, towards the emitting object). Its
  direction is the angle ``xi`` in [0, pi] from the OUTWARD radial direction in the observer's
  static orthonormal frame (eq. 8): frame components y^(t) = -1, y^(r) = cos xi,
  y^(phi) = side * sin xi. In coordinates (eq. 11)::

      u^t = -1/sqrt(1 - 1/r_obs),  u^r = sqrt(1 - 1/r_obs) cos xi,  u^phi = side * sin(xi)/r_obs

  so xi = pi points straight at the hole and xi = 0 straight away from it. ``side = +1`` sweeps
  increasing phi, ``side = -1`` decreasing phi (the mirror ray). Constants of motion (eq. 13):
  k = sqrt(1 - 1/r_obs) = (1 - 1/r) |u^t|, h = r_obs sin xi = r^2 |u^phi|, impact parameter
  b = h / k; rays with b < b_crit = 3 sqrt(3)/2 fall into the hole.
* Null constraint (eq. 4): g(u, u) = -(1 - 1/r) (u^t)^2 + (u^r)^2/(1 - 1/r) + r^2 (u^phi)^2 = 0.
* Target point (r, phi), 0 <= phi <= pi, in the plane through hole, observer and target.
  order = 1: the ray sweeping +phi (side = +1); order = 2: the ray passing the hole on the other
  side, sweeping -(2 pi - phi) (side = -1) and ending at coordinate angle phi - 2 pi (the same
  point). ``xi`` is reported unsigned in [0, pi] for both orders.
* Returned tangent at the target (eq. 17), with the affine normalisation of eq. (11) and the
  target's real angle phi: ux = u^r cos phi - u^phi r sin phi, uy = u^r sin phi + u^phi r cos phi
  (axes of the plane: e1 from the hole towards the observer, e2 towards the side of the target
  with y >= 0). -(ux, uy) is the direction in which light leaves the target towards the observer.
* dt is the light travel time, |t| accumulated along the ray (coordinate time, positive).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

__all__ = ["Shot", "shoot", "connect_numeric", "shadow_xi_crit", "null_constraint", "B_CRIT_REF",
           "HORIZON_EPS"]

#: critical impact parameter 3 sqrt(3)/2 (r_s = 1): b < B_CRIT_REF falls in, b > B_CRIT_REF escapes
B_CRIT_REF = 1.5 * math.sqrt(3.0)
#: a shot stops as 'horizon' when r < 1 + HORIZON_EPS
HORIZON_EPS = 1e-9

_RTOL = 1e-12
# Absolute tolerances per state component (t, r - 1, phi, u^t, u^r, u^phi, lambda). They are tiny
# on purpose: the components span many decades (u^phi ~ h/r^2 is ~1e-7 far out, r - 1 goes down
# to 1e-9 at the horizon, t and r reach 1e5), so the step control must be essentially relative
# (an atol of 1e-12 on u^phi alone would let phi drift by ~1e-9 on a long ray).
_ATOL = np.array([1e-15, 1e-18, 1e-15, 1e-15, 1e-15, 1e-20, 1e-15])
_SIGMA_MAX = 1e5  # Sundman-parameter budget (never reached in practice; lambda is the real budget)


def shadow_xi_crit(r_obs):
    """Critical angle xi_crit (radians) of eq. (14), r_s = 1: sin^2 xi_crit = 27/4 (1 - 1/r_obs)/r_obs^2.

    It is the half opening angle of the shadow: a ray leaving the observer (r_obs > 1.5) at
    xi > pi - xi_crit (impact parameter b < 3 sqrt(3)/2) falls into the hole, one with
    xi < pi - xi_crit escapes to infinity (it may first pass a periapsis > 1.5).
    The closed form is the one formula of the closed-form theory used here.
    """
    r_obs = _check_r_obs(r_obs)
    return math.asin(math.sqrt(27.0 / 4.0 * (1.0 - 1.0 / r_obs)) / r_obs)


def _check_r_obs(r_obs):
    r_obs = float(r_obs)
    if not (r_obs > 1.5 and math.isfinite(r_obs)):
        raise ValueError(f"r_obs must be finite and > 1.5 (outside the photon sphere), got {r_obs!r}")
    return r_obs


def null_constraint(r, ut, ur, uphi, r_minus_1=None):
    """g(u, u) of eq. (4) in the equatorial plane (r_s = c = 1): zero for a null tangent.

    Returns (value, relative value); the relative value divides by the spatial part
    (u^r)^2/(1 - 1/r) + r^2 (u^phi)^2 (which equals the temporal part for a null vector), so it
    stays meaningful close to the horizon where the individual terms diverge. Pass r_minus_1
    (= r - 1, exactly) near the horizon to avoid the cancellation in 1 - 1/r.
    """
    f = (r - 1.0 if r_minus_1 is None else r_minus_1) / r
    spatial = ur * ur / f + r * r * uphi * uphi
    value = -f * ut * ut + spatial
    return value, (value / spatial if spatial > 0 else value)


# The state is y = (t, x, phi, u^t, u^r, u^phi, lambda) with x = r - 1 (kept instead of r so that
# r - 1 keeps full relative precision next to the horizon, where eqs. (5)-(6) divide by it) and
# u^mu = dx^mu/dlambda the tangent in the affine normalisation of eq. (11). lambda is carried
# along so that both parametrisations below report it.

def _rhs_affine(lam, y):
    """Eqs. (5)-(7), r_s = c = 1, as a first-order system in the affine parameter lambda."""
    t, x, phi, ut, ur, up, _ = y
    r = 1.0 + x
    return (ut, ur, up,
            -ut * ur / (r * x),                                                      # (5)
            -x / (2.0 * r ** 3) * ut * ut + ur * ur / (2.0 * r * x) + x * up * up,  # (6)
            -2.0 * ur * up / r,                                                      # (7)
            1.0)


def _rhs_sundman(sigma, y):
    """The same system, multiplied by (r - 1): d/dsigma = (r - 1) d/dlambda (a Sundman time
    transformation, the orbit is unchanged). It removes the pole 1/(r - 1) of u^t at the horizon
    (t diverges only logarithmically) and makes the step size uniform in log r far out, so rays
    that plunge to r - 1 = 1e-9 or escape to 1e7 cost tens of steps instead of hundreds."""
    t, x, phi, ut, ur, up, _ = y
    r = 1.0 + x
    return (x * ut, x * ur, x * up,
            -ut * ur / r,
            -x * x / (2.0 * r ** 3) * ut * ut + ur * ur / (2.0 * r) + x * x * up * up,
            -2.0 * x * ur * up / r,
            x)


def _event(fun, direction):
    fun.terminal = True
    fun.direction = direction
    return fun


@dataclass(frozen=True)
class Shot:
    """End state of a ray shot by :func:`shoot` (units r_s = c = 1, angles in radians).

    status: 'phi' (|phi| reached phi_end), 'r' (r reached r_end), 'horizon' (r < 1 + 1e-9,
    fell in), 'escape' (r > r_escape, escaped), 'max_lambda' (affine-parameter budget used up).
    lam: affine parameter at the end. t, r, phi, ut, ur, uphi: final state (t <= 0 for the
    past-directed ray; phi is signed, with the sign of ``side``); r_minus_1 = r - 1 to full
    relative precision. null, null_rel: null constraint g(u, u) at the end, absolute and
    relative (see :func:`null_constraint`). k, h, b: constants of motion k = sqrt(1 - 1/r_obs),
    h = r_obs sin xi, b = h/k. nfev: right-hand-side calls.
    """
    status: str
    lam: float
    t: float
    r: float
    phi: float
    ut: float
    ur: float
    uphi: float
    r_minus_1: float
    null: float
    null_rel: float
    k: float
    h: float
    b: float
    nfev: int

    @property
    def dt(self) -> float:
        """Light travel time |t| (coordinate time, r_s/c)."""
        return abs(self.t)


def _direction(xi, supplement):
    """(cos xi, sin xi) of the angle xi, or of xi = pi - angle if ``supplement``."""
    if supplement:  # angle = pi - xi, resolved to full relative precision near xi = pi
        return -math.cos(xi), math.sin(xi)
    return math.cos(xi), (0.0 if xi == math.pi else math.sin(xi))  # sin(pi) = 1.2e-16 != 0


def _initial_state(r_obs, cos_xi, sin_xi, side):
    """Eq. (11) initial data (t, r - 1, phi, u^t, u^r, u^phi, lambda) and k = sqrt(1 - 1/r_obs)."""
    k = math.sqrt(1.0 - 1.0 / r_obs)
    return np.array([0.0, r_obs - 1.0, 0.0, -1.0 / k, k * cos_xi, side * sin_xi / r_obs, 0.0]), k


def shoot(r_obs, xi, *, side=+1, phi_end=None, r_end=None, max_lambda=None, r_escape=None,
          r_direction=0, rtol=_RTOL, atol=None, parametrisation="sundman", supplement=False):
    """Integrate the ray leaving the observer at (r_obs, phi = 0) at angle xi (radians) until an event.

    The geodesic equations (5)-(7) (r_s = c = 1) for (t, r, phi, u^t, u^r, u^phi) are integrated
    with solve_ivp(method="DOP853") from the eq. (11) initial data (past-directed, u^t < 0,
    u^phi = side * sin(xi)/r_obs; see the module docstring). r is carried as r - 1 for
    precision near the horizon. ``parametrisation="affine"`` integrates in the affine parameter
    lambda itself; the default ``"sundman"`` integrates the same equations in sigma with
    dlambda = (r - 1) dsigma (cheaper and better conditioned at the horizon and far out; the
    tangent u^mu = dx^mu/dlambda and lambda are reported in the affine normalisation either
    way). Radial turning points need no special treatment in either. Terminal events, first wins:

    * phi_end (>= 0, radians): |phi| reaches phi_end -> status 'phi';
    * r_end: r crosses r_end (in the direction ``r_direction``: 0 either way, -1 inwards,
      +1 outwards; a crossing at lambda = 0 does not count) -> status 'r';
    * r < 1 + 1e-9 -> status 'horizon';
    * r > r_escape (default 1e4 * max(r_obs, r_end, 10)) -> status 'escape';
    * lambda reaches max_lambda (default 100 * r_escape / k) -> status 'max_lambda'.

    rtol / atol go to solve_ivp (atol defaults to tiny per-component values so that the step
    control is essentially relative). With ``supplement=True`` the angle argument is pi - xi
    instead of xi (in [0, pi]): nearly inward-radial rays then keep the full relative precision
    of their small sin xi (xi itself resolves pi - xi only to 4.4e-16 absolute). Returns a
    :class:`Shot` with the final state, the null constraint there (it stays ~1e-13 relative)
    and the constants of motion. Any static observer (r_obs > 1) can shoot, inside the photon sphere
    too (the equations do not care; :func:`connect_numeric`'s bracketing does).
    """
    r_obs = float(r_obs)
    if not (r_obs > 1.0 and math.isfinite(r_obs)):
        raise ValueError(f"r_obs must be finite and > 1 (outside the horizon), got {r_obs!r}")
    xi = float(xi)
    if not 0.0 <= xi <= math.pi:
        raise ValueError(f"xi must be in [0, pi], got {xi!r}")
    if side not in (1, -1):
        raise ValueError("side must be +1 or -1")
    cos_xi, sin_xi = _direction(xi, supplement)
    y0, k = _initial_state(r_obs, cos_xi, sin_xi, side)
    if r_escape is None:
        r_escape = 1e4 * max(r_obs, r_end if r_end is not None else 0.0, 10.0)
    if max_lambda is None:
        max_lambda = 100.0 * r_escape / k
    events, names = [], []
    if phi_end is not None:
        phi_end = float(phi_end)
        events.append(_event(lambda s, y: side * y[2] - phi_end, 1))
        names.append("phi")
    if r_end is not None:
        x_end = float(r_end) - 1.0
        events.append(_event(lambda s, y: y[1] - x_end, r_direction))
        names.append("r")
    events.append(_event(lambda s, y: y[1] - HORIZON_EPS, -1))
    names.append("horizon")
    x_esc = float(r_escape) - 1.0
    events.append(_event(lambda s, y: y[1] - x_esc, 1))
    names.append("escape")
    if parametrisation == "sundman":
        fun, span = _rhs_sundman, _SIGMA_MAX
        max_lambda = float(max_lambda)
        events.append(_event(lambda s, y: y[6] - max_lambda, 1))
        names.append("max_lambda")
    elif parametrisation == "affine":
        fun, span = _rhs_affine, float(max_lambda)
    else:
        raise ValueError("parametrisation must be 'sundman' or 'affine'")
    sol = solve_ivp(fun, (0.0, span), y0, method="DOP853", rtol=rtol,
                    atol=_ATOL if atol is None else atol, events=events)
    status, y = "max_lambda", sol.y[:, -1]
    if sol.status == 1:
        # the terminal event that fired (the earliest if two fired in the same step)
        hits = [(te[0], i) for i, te in enumerate(sol.t_events) if len(te)]
        _, i = min(hits)
        status, y = names[i], sol.y_events[i][0]
    elif sol.status < 0:
        raise RuntimeError(f"solve_ivp failed at xi = {xi!r}: {sol.message}")
    t, x, phi, ut, ur, up, lam = (float(v) for v in y)
    r = 1.0 + x
    null, null_rel = null_constraint(r, ut, ur, up, r_minus_1=x)
    h = r_obs * sin_xi
    return Shot(status, lam, t, r, phi, ut, ur, up, x, null, null_rel, k, h, h / k, sol.nfev)


def _tangent_xy(r, phi, ur, uphi):
    """Eq. (17): (u^r, u^phi) at (r, phi) -> pseudo-Cartesian (ux, uy)."""
    c, s = math.cos(phi), math.sin(phi)
    return ur * c - uphi * r * s, ur * s + uphi * r * c


_NAN4 = (math.nan, math.nan, math.nan, math.nan)


def connect_numeric(r_obs, r, phi, order=1, *, rtol=_RTOL, xtol=1e-12):
    """Connecting ray from the observer at (r_obs, 0) to the target (r, phi), by shooting.

    Units r_s = c = 1, angles in radians; r_obs > 1.5, 0 <= phi <= pi; order 1 sweeps +phi,
    order 2 sweeps -(2 pi - phi) (see the module docstring). Returns floats (xi, dt, ux, uy): xi
    in [0, pi] the unsigned angle at the observer from the outward radial direction, dt the light
    travel time (coordinate time, > 0), (ux, uy) the ray tangent at the target by eq. (17) with
    the eq. (11) normalisation, in the plane's axes. All NaN for r <= 1 (no static target) and
    for the degenerate order-1 target at the observer itself.

    Method: with Phi the angle to sweep, the ray of the family xi in [0, pi] (fixed side) is
    integrated by :func:`shoot` until |phi| = Phi, and the residual F(xi) = 1/r - 1/r_at(xi),
    r_at the radius at which the ray sweeps Phi, is solved with brentq. F decreases
    monotonically in xi (the rays of one side do not cross), F(0) = 1/r + Phi > 0 (the outward
    radial ray sweeps nothing) and F(pi) = 1/r - 1 - Phi < 0 (the inward one falls straight in),
    so [0, pi] always brackets the root. F(pi/2) (the tangential ray) decides the half; the half
    (pi/2, pi] is searched in the variable pi - xi (``shoot(..., supplement=True)``) so that
    nearly radial rays on both sides keep full relative precision in sin xi. A shot stops early
    once the sign of F is certain, and rays that do not reach Phi are continued monotonically and
    continuously:

    * outbound past r_ceil = 2 max(r_obs, r) having swept Phi_c < Phi (outside r = 1.5 a null ray
      has no apoapsis, it never comes back): with Phi_tot = Phi_c + asin(b/r_ceil) (straight-line
      remainder), F = 1/r - sin(Phi_tot - Phi)/b (it reaches Phi at ~ b/sin(Phi_tot - Phi))
      if Phi <= Phi_tot, else F = 1/r + (Phi - Phi_tot) > 0 ("reaches Phi beyond infinity");
    * inbound below r_floor = 1 + (min(r, 1.5) - 1)/2 having swept Phi_f < Phi (inside the photon
      sphere an inbound ray cannot turn, it falls in): F = 1/r - 1/r_floor - (Phi - Phi_f) < 0
      ("reaches Phi below r_floor").

    brentq stops at the absolute tolerance xtol on the search angle; if the ray there misses r
    by more than 1e-6 (r - 1) (r_at extremely steep in the angle, e.g. next to the horizon at
    tiny phi), the tightest bracket seen is bisected on to adjacent floats. phi = 0 with
    order 1 is the radial ray (xi = 0 outwards or pi inwards), shot to r directly.

    The ray at the root (reused from the search) sweeps Phi at r_at, with r_at - r set by the
    rounding of the angle (up to ~1e-10 next to the horizon, ~1e-5 at r ~ 2000 behind the
    hole); its travel time and tangent are moved from r_at to r, see ``_finish``.
    """
    r_obs, r, phi = _check_r_obs(r_obs), float(r), float(phi)
    if order not in (1, 2):
        raise ValueError("order must be 1 or 2")
    if not 0.0 <= phi <= math.pi:
        raise ValueError(f"phi must be in [0, pi], got {phi!r}")
    if not (r > 1.0 and math.isfinite(r)):
        return _NAN4
    if order == 1 and phi == 0.0:  # radial ray
        if r == r_obs:
            return _NAN4
        xi = math.pi if r < r_obs else 0.0
        s = shoot(r_obs, xi, r_end=r, rtol=rtol)
        if s.status != "r":
            return _NAN4
        return xi, s.dt, s.ur, 0.0
    side = 1 if order == 1 else -1
    big_phi = phi if order == 1 else 2.0 * math.pi - phi
    inv_r = 1.0 / r
    # Shots of the root search stop early once their residual sign is certain: outbound past
    # r_ceil > max(r_obs, r) (a null ray outside r = 1.5 has no apoapsis, so it never comes back)
    # or inbound below r_floor < min(r, 1.5) (inside the photon sphere it cannot turn).
    r_ceil = 2.0 * max(r_obs, r)
    r_floor = 1.0 + 0.5 * (min(r, 1.5) - 1.0)
    inv_floor = 1.0 / r_floor

    def residual(a, supplement):
        """F at xi = a, or at xi = pi - a if supplement."""
        if a == 0.0:  # radial rays: outward sweeps nothing, inward falls straight in
            return inv_r - 1.0 - big_phi if supplement else inv_r + big_phi
        s = shoot(r_obs, a, side=side, phi_end=big_phi, r_end=r_floor, r_direction=-1,
                  r_escape=r_ceil, rtol=rtol, supplement=supplement)
        if s.status == "phi":
            reached[a] = s
            return inv_r - 1.0 / s.r
        if s.status == "r":  # plunging below the target: "reaches Phi below r_floor"
            return inv_r - inv_floor - (big_phi - abs(s.phi))
        if s.status == "escape":
            phi_tot = abs(s.phi) + math.asin(min(1.0, s.b / s.r))  # + straight-line remainder
            if big_phi <= phi_tot:  # would reach Phi beyond r_ceil, at ~ b / sin(Phi_tot - Phi)
                return inv_r - math.sin(phi_tot - big_phi) / s.b
            return inv_r + (big_phi - phi_tot)  # "reaches Phi beyond infinity"
        raise RuntimeError(f"unexpected shot status {s.status!r} at angle {a!r}")

    # Split the bracket at the tangential ray xi = pi/2 and search the inward half in pi - xi, so
    # that nearly radial rays on either side keep full relative precision in sin xi.
    reached = {}  # angle -> Shot that swept Phi (the last one is usually the root itself)
    half = 0.5 * math.pi
    f_half = residual(half, False)
    if f_half == 0.0:
        return _finish(reached[half], math.pi / 2, r, phi)
    supplement = f_half > 0.0  # F decreases in xi, so the root is in (pi/2, pi]
    sign = 1.0 if supplement else -1.0  # sign * F increases with the search angle
    seen = {0.0: -1.0, half: 1.0}  # angle -> sign of sign * F

    def g(a):
        v = f_half if a == half else residual(a, supplement)
        seen[a] = math.copysign(1.0, sign * v)
        return v

    eps4 = 4 * np.finfo(float).eps
    a = brentq(g, 0.0, half, xtol=xtol, rtol=eps4, maxiter=400)
    s = reached.get(a)
    if s is None or abs((r - 1.0) - s.r_minus_1) > 1e-6 * (r - 1.0):
        # r_at so steep in the angle that xtol is not enough: bisect on to adjacent floats
        lo = max(x for x, v in seen.items() if v < 0)
        hi = min(x for x, v in seen.items() if v > 0)
        a = brentq(g, lo, hi, xtol=1e-300, rtol=eps4, maxiter=400)
        s = reached.get(a)
    if s is None:
        s = shoot(r_obs, a, side=side, phi_end=big_phi, rtol=rtol, supplement=supplement)
        if s.status != "phi":
            return _NAN4
    return _finish(s, math.pi - a if supplement else a, r, phi)


def _finish(s, xi, r, phi):
    """(xi, dt, ux, uy) from the shot s that sweeps Phi at r_at close to the target radius r.

    r_at - r is set by the rounding of the search angle (up to ~1e-10 next to the horizon,
    ~1e-5 at r ~ 2000 behind the hole, where r_at is extremely steep in xi) and would otherwise
    dominate dt through dT/dr ~ 1/(r - 1) resp. ~ 1:

    * dt: first-order eikonal relation of the observer's past light cone t = -T(r, phi): its
      normal is u_mu, so dT = (u_r dr + u_phi dphi)/u_t with u_r = u^r/f, u_phi = r^2 u^phi,
      u_t = -f u^t, f = 1 - 1/r; here dphi = 0 and dr = r - r_at. (Transverse offsets do not
      change T to first order.)
    * tangent: where r_at - r matters, neighbouring rays of the family differ in h by a
      negligible amount, so the polar components at radius r are those of the same orbit moved
      from r_at to r with the shot's own constants of motion: u^phi r^2 = const and
      (u^r)^2 + (1 - 1/r) h^2/r^2 = const (eqs. 12-13, no orbit solution needed), keeping the
      sign of u^r. Then eq. (17) with the target's angle phi.
    """
    r_at, x_at = s.r, s.r_minus_1
    dr = (r - 1.0) - x_at
    f_at, f = x_at / r_at, (r - 1.0) / r
    dt = s.dt - s.ur * dr / (f_at * f_at * s.ut)
    h = r_at * r_at * s.uphi  # signed
    v_at, v = f_at * h * h / (r_at * r_at), f * h * h / (r * r)
    ur = math.copysign(math.sqrt(max(0.0, s.ur * s.ur + (v_at - v))), s.ur)
    ux, uy = _tangent_xy(r, phi, ur, h / (r * r))
    return xi, dt, ux, uy
