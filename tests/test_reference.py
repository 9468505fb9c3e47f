"""lutgen.reference: the independent numerical (DOP853 shooting) emitter-observer solver.

Units r_s = 1, c = 1 (times in r_s/c), angles in radians; observer static at (r_obs, phi = 0);
xi from the outward radial direction in the observer's static frame (seed 000, eq. 11). These
tests check the reference solver on its own, against facts that need neither it nor the
closed-form solver: conservation laws, the photon sphere, Euclidean geometry, exact radial
geodesics, and table 1 of seed 000.
"""
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from lutgen.reference import B_CRIT_REF, connect_numeric, null_constraint, shadow_xi_crit, shoot

DEG = math.pi / 180.0


def _conserved(s):
    """k = (1 - 1/r)|u^t| and h = r^2 |u^phi| at the end of a shot."""
    f = s.r_minus_1 / s.r
    return f * abs(s.ut), s.r * s.r * abs(s.uphi)


def _rays():
    """A mix of rays (r_obs, xi, side, shoot kwargs) for the conservation checks."""
    out = []
    for r_obs in (1.6, 20.0, 1000.0):
        edge = math.pi - shadow_xi_crit(r_obs)
        out += [
            (r_obs, 0.4, 1, {}),                                   # outwards, escapes
            (r_obs, 2.0, -1, {}),                                  # inwards, periapsis, escapes
            (r_obs, edge + 1e-3, 1, {}),                           # plunges to r - 1 = 1e-9
            (r_obs, edge - 1e-9, -1, {"phi_end": 4 * math.pi}),    # winds near r = 1.5
            (r_obs, math.pi, 1, {"r_end": 1.0 + 1e-6}),            # radial, to the horizon
        ]
    return out


@pytest.mark.parametrize("parametrisation", ["sundman", "affine"])
def test_null_constraint_and_constants_of_motion_conserved(parametrisation):
    """g(u, u) = 0 (eq. 4), k = (1 - 1/r)|u^t| and h = r^2|u^phi| (eq. 13) at the end of each ray."""
    for r_obs, xi, side, kw in _rays():
        s = shoot(r_obs, xi, side=side, parametrisation=parametrisation, **kw)
        assert s.status in ("escape", "horizon", "phi", "r")
        assert abs(s.null_rel) < 1e-10, (r_obs, xi, s)
        k, h = _conserved(s)
        assert abs(k / s.k - 1) < 1e-10, (r_obs, xi, s)
        if s.h > 1e-12:
            # escaped rays end at 1e4 r_obs, where u^phi ~ h/r^2 ~ 1e-12 and h drifts by up to
            # ~3e-10 (harmless: phi no longer changes there); within 100 r_obs it stays ~1e-12
            tol_h = 1e-9 if s.status == "escape" else 1e-10
            assert abs(h / s.h - 1) < tol_h, (r_obs, xi, s)
            assert math.copysign(1.0, s.uphi) == side
        # the initial data themselves are null (eq. 11)
        k0 = math.sqrt(1 - 1 / r_obs)
        v, _ = null_constraint(r_obs, -1 / k0, k0 * math.cos(xi), math.sin(xi) / r_obs)
        assert abs(v) < 1e-15


def test_sundman_and_affine_parametrisations_agree():
    """The default integration (d/dsigma = (r - 1) d/dlambda) gives the same orbit, tangent,
    travel time and affine parameter as integrating in lambda directly."""
    for r_obs, xi, kw in [(20.0, 2.9, {"phi_end": 2.5}), (3.0, 1.2, {"r_end": 50.0}),
                          (20.0, 3.1, {"r_end": 1.001, "r_direction": -1})]:
        a = shoot(r_obs, xi, parametrisation="sundman", **kw)
        b = shoot(r_obs, xi, parametrisation="affine", **kw)
        assert a.status == b.status != "max_lambda"
        for name in ("t", "r", "phi", "ut", "ur", "uphi", "lam"):
            x, y = getattr(a, name), getattr(b, name)
            assert abs(x - y) <= 1e-9 * max(1.0, abs(y)), (name, x, y)


@pytest.mark.parametrize("r_obs", [1.6, 20.0, 1000.0])
def test_radial_rays_match_the_exact_radial_geodesic(r_obs):
    """Radial null geodesics: t = r + ln(r - 1) + const exactly, down to r - 1 = 1e-6 (where the
    travel time is dominated by the logarithm). The bound is 1e-11: the integrator's rounding
    depends on the CPU's floating-point kernels (1.3e-12 at r = 1.8 seen on one machine)."""
    for r in (1.0 + 1e-6, 1.2, 1.5, 0.5 * r_obs + 1.0, 3.0 * r_obs):
        exact = abs(r - r_obs) + abs(math.log((r - 1.0) / (r_obs - 1.0)))
        if r < r_obs:
            xi, dt, ux, uy = connect_numeric(r_obs, r, 0.0, order=1)
            assert xi == math.pi and ux < 0
        else:
            xi, dt, ux, uy = connect_numeric(r_obs, r, 0.0, order=1)
            assert xi == 0.0 and ux > 0
        assert abs(dt / exact - 1) < 1e-11, (r, dt, exact)
        assert uy == 0.0 and abs(abs(ux) - math.sqrt(1 - 1 / r_obs)) < 1e-11  # u^r = -+k


def test_shadow_xi_crit_eq_14():
    """Eq. (14); it is the angle of b = b_crit = 3 sqrt(3)/2, and 7.274 deg at 20 r_s (sec. 4)."""
    for r_obs in (1.6, 3.0, 20.0, 1000.0):
        xc = shadow_xi_crit(r_obs)
        assert math.isclose(math.sin(xc) ** 2, 27 / 4 / r_obs**2 * (1 - 1 / r_obs), rel_tol=1e-14)
        assert math.isclose(r_obs * math.sin(xc) / math.sqrt(1 - 1 / r_obs), B_CRIT_REF, rel_tol=1e-13)
    assert abs(math.degrees(shadow_xi_crit(20.0)) - 7.274) < 5e-4
    with pytest.raises(ValueError):
        shadow_xi_crit(1.5)


@pytest.mark.parametrize("r_obs", [1.6, 20.0, 1000.0])
def test_critical_angle_separates_plunging_from_escaping_rays(r_obs):
    """xi just above pi - xi_crit falls in, just below escapes; close to it the ray winds around
    the photon sphere r = 1.5. Linearising the orbit equation u'' + u = 1.5 u^2 (u = 1/r) about
    u = 2/3 gives du'' = du, a Lyapunov exponent of exactly 1 per radian: the total swept angle
    grows by ln(1000) when the offset |b - b_crit| shrinks 1000-fold, on both sides."""
    edge = math.pi - shadow_xi_crit(r_obs)
    dxi_db = math.sqrt(1 - 1 / r_obs) / (r_obs * abs(math.cos(edge)))  # b = r_obs sin(xi)/k
    sweeps = {}
    for db in (1e-4, 1e-7, 1e-10):
        d = db * dxi_db
        out, down = shoot(r_obs, edge - d), shoot(r_obs, edge + d)
        assert out.status == "escape" and down.status == "horizon"
        sweeps[db] = (out.phi, down.phi)
    for i in (0, 1):  # escaping, plunging
        # (1e-10 is left out here: integration noise ~1e-12 b shifts it by ~1e-3 rad)
        step = sweeps[1e-7][i] - sweeps[1e-4][i]
        assert abs(step / math.log(1000.0) - 1) < 1e-4, (i, step)
    # 1e-10 from the edge, both rays stay within 1e-3 of r = 1.5 for more than 1.5 turns
    d = 1e-10 * dxi_db
    enter = shoot(r_obs, edge - d, r_end=1.501, r_direction=-1)
    leave = shoot(r_obs, edge - d, r_end=1.501, r_direction=+1)  # after the periapsis
    assert enter.status == leave.status == "r" and leave.phi - enter.phi > 3 * math.pi
    enter = shoot(r_obs, edge + d, r_end=1.501, r_direction=-1)
    below = shoot(r_obs, edge + d, r_end=1.499, r_direction=-1)
    assert enter.status == below.status == "r" and below.phi - enter.phi > 3 * math.pi
    assert min(sweeps[1e-10]) > 7 * math.pi
    # and a ray exactly at the computed edge winds at least as long as those
    assert shoot(r_obs, edge, phi_end=max(sweeps[1e-10])).status == "phi"


def test_seed_table_1():
    """Seed 000, table 1: observer at 20 r_s, an infinitely thin disc with edges at 3.3 and
    8.25 r_s seen at phi = 90 deg, orders 1 and 2. The table uses r_s = 2, so its times are
    twice ours. The paper's own numbers are only good to about one unit of the 4th decimal
    (e.g. (b) xi: ours 155.49296, printed 155.4929; (c) dt: ours 66.19598, printed 66.1959), so
    1e-4 is the tolerance. Entry (d)'s dt is the exception, see the next test."""
    rows = [  # (r, order, xi_deg, 2 dt)
        (3.3, 1, 169.0461, 45.3345),
        (8.25, 1, 155.4929, 46.1738),
        (3.3, 2, 172.3350, 66.1959),
        (8.25, 2, 171.9831, None),  # printed 76.8531, see below
    ]
    for r, order, xi_deg, dt2 in rows:
        xi, dt, ux, uy = connect_numeric(20.0, r, math.pi / 2, order)
        assert abs(math.degrees(xi) - xi_deg) < 1e-4, (r, order, math.degrees(xi))
        if dt2 is not None:
            assert abs(2 * dt - dt2) < 1e-4, (r, order, 2 * dt)
        else:
            assert abs(2 * dt - 76.85261) < 1e-5  # ours; 4.9e-4 below the printed 76.8531
    # Minkowski rows of the same table (observer at 40, targets 6.6 / 16.5 in its r_s = 2 units):
    # plain Euclidean geometry, which fixes how the table is to be read.
    for y, xi_deg, d in [(6.6, 170.6306, 40.5408), (16.5, 157.5839, 43.2695)]:
        assert abs(math.degrees(math.atan2(y, -40.0)) - xi_deg) < 1e-4
        assert abs(math.hypot(40.0, y) - d) < 1e-4


def test_seed_table_1_entry_d_travel_time_discrepancy():
    """Table 1 (d), order 2 to the outer edge: the paper prints dt = 76.8531 (r_s = 2 units); we
    get 76.85261 (the closed-form solver agrees to 1e-12). The difference, 4.9e-4, is what the
    paper's bisection tolerance allows: dt is very sensitive to xi here (d(2 dt)/d xi =
    -58.6 per degree), so the printed time belongs to a ray only 8e-6 deg (far below the printed
    1e-4 deg) from the exact one, which sweeps 3 pi/2 at 8.25 + 2e-4 r_s instead of 8.25 r_s.
    This test pins that explanation down instead of loosening the tolerance above."""
    xi, dt, _, _ = connect_numeric(20.0, 8.25, math.pi / 2, order=2)

    def shot(x):
        return shoot(20.0, x, side=-1, phi_end=1.5 * math.pi)

    xi_paper = brentq(lambda x: 2 * shot(x).dt - 76.8531, xi - 1e-6, xi + 1e-6, xtol=1e-14)
    s = shot(xi_paper)
    assert abs(math.degrees(xi_paper) - 171.9831) < 5e-5  # the printed xi still rounds right
    assert 1e-6 < math.degrees(xi - xi_paper) < 2e-5
    assert 0 < s.r - 8.25 < 5e-4  # the paper's ray ends ~2e-4 r_s off the disc edge


@pytest.mark.parametrize("scale", [1e4, 1e5])
def test_flat_space_limit(scale):
    """Targets and observer at distances ~ L = scale from the hole: deflection is tiny, so xi and
    dt must approach Euclidean geometry in the (r, phi) plane. Reasoning for the bounds: a ray
    with impact parameter b is deflected by at most the full weak-field angle 2 r_s/b, towards
    the hole, so the image is seen *away* from the hole: -2/b < xi - xi_flat < 0 (the frame and
    coordinate effects at the observer are O(r_s/L) too and keep the sign here). The travel time
    exceeds the Euclidean distance D by the Shapiro delay ln((r_o + r + D)/(r_o + r - D)) (r_s = 1)
    up to O(r_s) terms from using Schwarzschild coordinates as Euclidean ones, so the remainder is
    bounded by a few r_s independently of L. Both residuals must be scale-free: b (xi - xi_flat)
    and dt - D - Shapiro are the same for L = 1e4 and 1e5 to O(r_s/L)."""
    rng = np.random.default_rng(1)
    r_obs = 2.0 * scale
    for _ in range(5):
        u, phi = rng.uniform(0.5, 3.0), rng.uniform(0.3, 2.8)
        r = scale * u
        xi, dt, ux, uy = connect_numeric(r_obs, r, phi, order=1)
        dx, dy = r * math.cos(phi) - r_obs, r * math.sin(phi)
        dist = math.hypot(dx, dy)
        xi_flat = math.atan2(dy, dx)
        b = r_obs * r * math.sin(phi) / dist
        assert -2.0 / b < xi - xi_flat < 0.0
        shapiro = math.log((r_obs + r + dist) / (r_obs + r - dist))
        assert abs(dt - dist - shapiro) < 1.5
        # the ray arrives at the target along the Euclidean chord direction (to O(1/b))
        turn = math.atan2(-uy, -ux) - math.atan2(-dy, -dx)
        assert abs(math.remainder(turn, 2 * math.pi)) < 2.0 / b
        # scale-free residuals: compare with the same geometry scaled down 10x
        if scale > 1e4:
            xs, ds, _, _ = connect_numeric(r_obs / 10, r / 10, phi, order=1)
            dist_s, b_s = dist / 10, b / 10
            sh_s = math.log((r_obs + r + dist) / (r_obs + r - dist))
            xi_flat_s = xi_flat
            assert abs(b * (xi - xi_flat) - b_s * (xs - xi_flat_s)) < 2e-3
            assert abs((dt - dist - shapiro) - (ds - dist_s - sh_s)) < 2e-3


def test_connecting_rays_reach_the_target_with_eq_11_normalisation():
    """At the target, (ux, uy) -> (u^r, r u^phi) by inverting eq. (17) must satisfy the null
    condition with k = sqrt(1 - 1/r_obs) (eq. 11 normalisation): (u^r)^2 + (1 - 1/r)(r u^phi)^2
    = k^2, and angular momentum r (r u^phi) = +h (order 1) or -h (order 2), h = r_obs sin xi.
    And the ray shot at the returned xi, stopped by radius instead of angle, crosses r at the
    target's swept angle (phi, or 2 pi - phi for order 2) with the returned travel time."""
    cases = [(20.0, 3.3, 1.0), (20.0, 1.2, 2.5), (3.0, 40.0, 0.5), (1.6, 1.0 + 1e-6, 2.0),
             (1000.0, 1.7, 3.0), (1000.0, 2000.0, 0.3)]
    for r_obs, r, phi in cases:
        for order in (1, 2):
            xi, dt, ux, uy = connect_numeric(r_obs, r, phi, order)
            assert 0.0 <= xi <= math.pi and dt > 0
            ur = ux * math.cos(phi) + uy * math.sin(phi)
            rup = -ux * math.sin(phi) + uy * math.cos(phi)
            f = 1 - 1 / r
            assert math.isclose(ur * ur + f * rup * rup, 1 - 1 / r_obs, rel_tol=1e-10)
            h = r_obs * math.sin(xi)
            assert math.isclose(r * rup, h if order == 1 else -h, rel_tol=1e-10, abs_tol=1e-12)
            if r > 1000:
                continue  # far behind the hole r(xi) is too steep for this check in float64
            side = 1 if order == 1 else -1
            swept = phi if order == 1 else 2 * math.pi - phi
            crossings = [shoot(r_obs, xi, side=side, r_end=r, r_direction=d) for d in (-1, 1)]
            hit = [c for c in crossings if c.status == "r" and abs(abs(c.phi) - swept) < 1e-7]
            assert len(hit) == 1, (r_obs, r, phi, order, crossings)
            assert abs(hit[0].dt / dt - 1) < 1e-7


def test_connecting_ray_regimes():
    """Where the connecting rays start: straight-line-like (r > r_obs, small phi: outwards), behind
    the hole (order 2 at phi = 0: near the shadow edge), inside the photon sphere (plunging rays,
    xi > pi - xi_crit), and the mirror symmetry of orders 1 and 2 at phi = pi."""
    r_obs = 20.0
    edge = math.pi - shadow_xi_crit(r_obs)
    xi, dt, _, _ = connect_numeric(r_obs, 60.0, 0.2, 1)
    assert xi < math.pi / 2 and dt > 40.0
    xi, _, _, _ = connect_numeric(r_obs, 10.0, 0.0, 2)  # Einstein-ring ray: just outside the edge
    assert 0 < edge - xi < 0.01
    for r in (1.0 + 1e-6, 1.1, 1.4):  # inside the photon sphere: only plunging rays get there
        for order in (1, 2):
            xi, dt, _, _ = connect_numeric(r_obs, r, 2.0, order)
            assert xi > edge and dt > 20.0
    a = connect_numeric(r_obs, 5.0, math.pi, 1)
    b = connect_numeric(r_obs, 5.0, math.pi, 2)
    assert abs(a[0] - b[0]) < 1e-11 and abs(a[1] / b[1] - 1) < 1e-11
    assert abs(a[2] - b[2]) < 1e-10 and abs(a[3] + b[3]) < 1e-10
    # continuity at phi -> 0 with the radial special case, next to the horizon too
    for r in (5.0, 1.0 + 1e-6):
        rad, near = connect_numeric(r_obs, r, 0.0, 1), connect_numeric(r_obs, r, 1e-7, 1)
        assert abs(rad[0] - near[0]) < 1e-5 and abs(near[1] / rad[1] - 1) < 1e-9


def test_invalid_inputs():
    assert all(math.isnan(v) for v in connect_numeric(20.0, 1.0, 1.0))
    assert all(math.isnan(v) for v in connect_numeric(20.0, 0.5, 1.0, 2))
    assert all(math.isnan(v) for v in connect_numeric(20.0, 20.0, 0.0, 1))  # the observer itself
    with pytest.raises(ValueError):
        connect_numeric(1.5, 3.0, 1.0)
    with pytest.raises(ValueError):
        connect_numeric(20.0, 3.0, 4.0)
    with pytest.raises(ValueError):
        connect_numeric(20.0, 3.0, 1.0, order=3)
    with pytest.raises(ValueError):
        shoot(20.0, 4.0)
