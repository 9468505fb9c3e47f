"""lutgen.solver: the closed-form emitter-observer solver against independent facts.

Units r_s = 1, c = 1. Independent checks here: Euclidean geometry (flat-space limit), the shadow
angle of eq. (14), the photon sphere at 1.5 r_s and its Lyapunov exponent, direct numerical
quadrature of the orbit integrals, table 1 of seed 000, symmetries and continuity.
(The comparison with the numerical geodesic integrator is in test_connect_vs_numeric.py.)
"""
import math

import numpy as np
import pytest
from scipy.integrate import quad

from lutgen import connect, shadow_half_angle
from lutgen.orbit import B_CRIT


def test_seed_table_1():
    """Seed 000, table 1: observer at 20 r_s, thin disc edges at 3.3 and 8.25 r_s seen at phi = 90
    deg (the table uses r_s = 2, so its times are twice ours). Printed to 4 decimals."""
    c1 = connect(20.0, np.array([3.3, 8.25]), np.pi / 2, order=1)
    np.testing.assert_allclose(np.degrees(c1.xi), [169.0461, 155.4929], atol=1.5e-4)
    np.testing.assert_allclose(2 * c1.dt, [45.3345, 46.1738], atol=1.5e-4)
    c2 = connect(20.0, 3.3, np.pi / 2, order=2)
    np.testing.assert_allclose(np.degrees(c2.xi), 172.3350, atol=1.5e-4)
    np.testing.assert_allclose(2 * c2.dt, 66.1959, atol=1.5e-4)
    # Outer edge, order 2: the table prints xi = 171.9831 deg (we agree) and dt = 76.8531; we get
    # 76.8526, confirmed independently by the DOP853 integrator in test_connect_vs_numeric.py.
    c2o = connect(20.0, 8.25, np.pi / 2, order=2)
    np.testing.assert_allclose(np.degrees(c2o.xi), 171.9831, atol=1.5e-4)
    np.testing.assert_allclose(2 * c2o.dt, 76.8531, atol=1e-3)


@pytest.mark.parametrize("r_obs", [1.6, 3.0, 20.0, 1000.0])
def test_shadow_half_angle_formula(r_obs):
    """sin^2 xi_crit = 27/4 (1/r_obs^2)(1 - 1/r_obs), and it corresponds to b = b_crit."""
    xc = shadow_half_angle(r_obs)
    assert math.isclose(math.sin(xc) ** 2, 27 / 4 / r_obs**2 * (1 - 1 / r_obs), rel_tol=1e-14)
    assert math.isclose(r_obs * math.sin(xc) / math.sqrt(1 - 1 / r_obs), 1.5 * math.sqrt(3), rel_tol=1e-13)


def test_shadow_angle_seed_value():
    """Seed 000 section 4: xi_crit ~ 7.274 deg for r_obs = 20 r_s."""
    assert abs(math.degrees(shadow_half_angle(20.0)) - 7.274) < 5e-4


@pytest.mark.parametrize("r_obs", [1.6, 5.0, 20.0, 300.0])
def test_winding_rays_approach_the_critical_ray_and_photon_sphere(r_obs):
    """Rays that wind near the photon sphere (r = 1.5 r_s) approach the critical ray b_crit
    exponentially in the swept angle Phi (Lyapunov exponent 1 per radian): a ray that ends on the
    sphere winds in only (|b - b_crit| ~ n^2, n ~ exp(-Phi): ~ exp(-2 Phi)); a ray that passes a
    periapsis near the sphere winds in and out (~ exp(-Phi)). Compare Phi = 3pi/2 with Phi = 2pi."""
    on_a, on_b = connect(r_obs, 1.5, np.pi / 2, 2), connect(r_obs, 1.5, 0.0, 2)
    ratio = (B_CRIT - on_b.b) / (B_CRIT - on_a.b)
    assert 0.9 < ratio / math.exp(-np.pi) < 1.1
    assert on_b.b < B_CRIT  # the point on the sphere is reached by a plunging ray
    out_a, out_b = connect(r_obs, 2.0, np.pi / 2, 2), connect(r_obs, 2.0, 0.0, 2)
    ratio = (out_b.b - B_CRIT) / (out_a.b - B_CRIT)
    assert 0.9 < ratio / math.exp(-np.pi / 2) < 1.1
    # ... and both are seen close to the shadow edge, on either side of it
    edge = np.pi - shadow_half_angle(r_obs)
    assert 0 < on_b.xi - edge < 1e-3 and 0 < edge - out_b.xi < 1e-2


@pytest.mark.parametrize("scale", [1e3, 1e4, 1e5])
def test_flat_space_limit(scale):
    """Far from the hole (all distances scaled by L) xi and dt approach Euclidean geometry with
    errors O(r_s/L) (deflection ~ 2 r_s/b; Shapiro delay ~ r_s log L)."""
    rng = np.random.default_rng(1)
    r_obs = 2.0 * scale
    r = scale * rng.uniform(0.5, 3.0, 400)
    phi = rng.uniform(0.3, 2.8, 400)
    c = connect(r_obs, r, phi, order=1)
    # Euclidean: observer at (r_obs, 0), target at r (cos phi, sin phi)
    dx, dy = r * np.cos(phi) - r_obs, r * np.sin(phi)
    dist = np.hypot(dx, dy)
    xi_flat = np.arctan2(dy, dx)  # angle from +x (outward radial at the observer)
    b = np.abs(r_obs * r * np.sin(phi)) / dist  # impact parameter of the straight line
    assert np.all(np.abs(c.xi - xi_flat) < 8.0 / b)
    assert np.all(np.abs(c.dt - dist) < 4.0 * np.log(scale) + 10.0)
    # arrival direction: unit vector along the straight line (ux, uy normalised)
    n = np.hypot(c.ux, c.uy)
    cosang = (c.ux * dx + c.uy * dy) / (n * dist)
    assert np.all(np.arccos(np.clip(cosang, -1, 1)) < 8.0 / b)


def _orbit_integrals(r_obs, r, b, branch, log_pieces=False):
    """Swept angle and travel time by adaptive quadrature in r (independent of the elliptic forms):
    dphi/dr = b / (r^2 sqrt(1 - b^2 (1-1/r)/r^2)), dt/dr = 1 / ((1-1/r) sqrt(1 - b^2 (1-1/r)/r^2)).
    ``log_pieces``: integrate over pieces [x, 10 x] (for far targets, where one adaptive quadrature
    over many decades misses the angle swept close in)."""
    def s(rr):
        return 1.0 - b * b * (1 - 1 / rr) / rr**2

    dphi = lambda rr: b / (rr * rr * math.sqrt(max(s(rr), 0.0)))  # noqa: E731
    dtime = lambda rr: 1.0 / ((1 - 1 / rr) * math.sqrt(max(s(rr), 0.0)))  # noqa: E731
    lo, hi = sorted([r, r_obs])
    kw = dict(epsabs=1e-13, epsrel=1e-12, limit=500)

    def integral(f, a, z):
        if not log_pieces:
            return quad(f, a, z, **kw)[0]
        edges = [a]
        while edges[-1] * 10 < z:
            edges.append(edges[-1] * 10 if edges[-1] > 0 else min(1.0, z / 10))
        edges.append(z)
        return math.fsum(quad(f, x0, x1, **kw)[0] for x0, x1 in zip(edges[:-1], edges[1:]))

    if branch == "direct":
        return integral(dphi, lo, hi), integral(dtime, lo, hi)
    # turning: periapsis r_p solves s(r_p) = 0 (largest root below both radii)
    from scipy.optimize import brentq
    r_p = brentq(s, 1.5, lo * (1 - 1e-15), xtol=1e-15)
    # substitute r = r_p + w^2 to remove the square-root singularity at the periapsis
    out = []
    for f in (dphi, dtime):
        g = lambda w: 2 * w * f(r_p + w * w)  # noqa: E731
        out.append(integral(g, 0, math.sqrt(r_obs - r_p)) + integral(g, 0, math.sqrt(r - r_p)))
    return tuple(out)


@pytest.mark.parametrize("r_obs,r,phi,order", [
    (20.0, 3.3, 1.0, 1), (20.0, 8.25, 2.5, 1), (20.0, 5.0, 2.0, 2), (20.0, 40.0, 2.0, 1),
    (20.0, 40.0, 0.5, 2), (1.6, 10.0, 2.0, 1), (1000.0, 2.0, 3.0, 1), (5.0, 1.2, 1.0, 1),
])
def test_against_quadrature_in_r(r_obs, r, phi, order):
    """The solved ray's swept angle and travel time, integrated independently in r, match."""
    c = connect(r_obs, r, phi, order)
    sweep = phi if order == 1 else 2 * np.pi - phi
    cos_xi = math.cos(float(c.xi))
    inward_start = cos_xi < 0
    # turning if the ray starts inward but ends outward (radial velocity at target > 0 wrt e_r)
    ur = float(c.ux) * math.cos(phi) + float(c.uy) * math.sin(phi)
    branch = "turning" if (inward_start and ur > 0) else "direct"
    ang, dt = _orbit_integrals(r_obs, r, float(c.b), branch)
    assert abs(ang - sweep) < 1e-8
    assert abs(dt / float(c.dt) - 1) < 1e-9


@pytest.mark.parametrize("r_obs,r,phi,order", [
    (20.0, 1e6, 1.0, 1), (20.0, 1e8, 2.5, 2), (1.6, 1e7, 0.3, 1), (1000.0, 1e9, 3.0, 1),
    (3.0, 1e10, 1.5, 2), (20.0, 1e12, 0.5, 1), (1.6, 1e12, 3.0, 2), (1000.0, 3e4, 1.0, 2),
])
def test_far_targets_against_quadrature_in_r(r_obs, r, phi, order):
    """Far targets (r up to 1e12 r_s): swept angle and travel time integrated in r, decade by decade,
    match to ~1e-13. (The travel time used to lose ~1e-16 r of its relative accuracy: 1e-8 at
    r = 1e8, 1e-4 at 1e12.)"""
    c = connect(r_obs, r, phi, order)
    sweep = phi if order == 1 else 2 * np.pi - phi
    ur = float(c.ux) * math.cos(phi) + float(c.uy) * math.sin(phi)
    branch = "turning" if (math.cos(float(c.xi)) < 0 and ur > 0) else "direct"
    ang, dt = _orbit_integrals(r_obs, r, float(c.b), branch, log_pieces=True)
    assert abs(ang - sweep) < 1e-8
    assert abs(dt / float(c.dt) - 1) < 1e-13


def test_symmetry_at_phi_pi():
    """At phi = pi the first- and second-order rays are mirror images (Einstein ring point)."""
    r = np.array([1.01, 1.3, 2.0, 3.0, 8.0, 15.0, 30.0])
    a = connect(20.0, r, np.pi, order=1)
    b = connect(20.0, r, np.pi, order=2)
    np.testing.assert_allclose(a.xi, b.xi, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.dt, b.dt, rtol=1e-12)
    np.testing.assert_allclose(a.ux, b.ux, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(a.uy, -b.uy, rtol=1e-10, atol=1e-12)


def test_radial_rays():
    """phi = 0, order 1: radial rays, xi = pi (inward) or 0 (outward), dt = |dr + ln((r-1)/(r_o-1))|."""
    r = np.array([1.000001, 2.0, 10.0, 30.0])
    c = connect(20.0, r, 0.0, order=1)
    np.testing.assert_array_equal(c.xi, [np.pi, np.pi, np.pi, 0.0])
    np.testing.assert_allclose(c.dt, np.abs(r - 20 + np.log((r - 1) / 19)), rtol=1e-14)


def _max_jump(f, grid_fn, n):
    return np.max(np.abs(np.diff(f(grid_fn(n)))))


@pytest.mark.parametrize("r_obs", [1.6, 20.0, 1000.0])
@pytest.mark.parametrize("order", [1, 2])
def test_continuity_in_phi_and_r(r_obs, order):
    """xi and dt are continuous (no jump at the switch between rays with and without a periapsis,
    or between plunging and turning rays): halving the grid step halves the largest step-to-step
    change, which a jump would not do."""
    for r in (1.000001, 1.2, 1.49, 1.5, 1.51, 3.0, 0.9 * r_obs, r_obs, 1.1 * r_obs, 3 * r_obs):
        for q in ("xi", "dt"):
            f = lambda p: getattr(connect(r_obs, r, p, order), q)  # noqa: E731
            grid = lambda n: np.linspace(0.0, np.pi, n)  # noqa: E731
            j1, j2 = _max_jump(f, grid, 2001), _max_jump(f, grid, 4001)
            assert np.isfinite(j1) and j2 < 0.6 * j1, (r, q, j1, j2)
    # along r (crossing r_obs at phi > 0; at phi -> 0 the point would pass through the observer)
    for p, r_far in ((1e-3, max(0.5 * r_obs, 1.3)), (0.5, 3 * r_obs), (1.5, 3 * r_obs), (3.0, 3 * r_obs), (np.pi, 3 * r_obs)):
        f = lambda r: connect(r_obs, r, p, order).xi  # noqa: E731
        grid = lambda n: 1.0 / np.linspace(1 / r_far, 1 / 1.000001, n)  # noqa: E731
        j1, j2 = _max_jump(f, grid, 2001), _max_jump(f, grid, 4001)
        assert np.isfinite(j1) and j2 < 0.6 * j1, (p, j1, j2)


def test_xi_monotone_in_phi_for_fixed_r():
    """For a fixed radius, xi is monotone in phi for each order, and second-order images lie just
    outside the shadow edge for points outside the photon sphere, inside it for points within."""
    phi = np.linspace(0, np.pi, 2001)
    edge = np.pi - shadow_half_angle(20.0)
    for r in (1.1, 1.4, 2.0, 5.0, 15.0):
        for order in (1, 2):
            x = connect(20.0, r, phi, order).xi
            d = np.diff(x)
            if order == 1 and r > 1.5:
                # unimodal: xi falls while the ray meets r before its periapsis, then rises again;
                # the turn is the ray that grazes r (b = r/sqrt(1-1/r)).
                k = int(np.argmin(x))
                assert np.all(d[:k] <= 1e-14) and np.all(d[k:] >= -1e-14), (r, order)
                b_graze = r / math.sqrt(1 - 1 / r)
                xi_graze = np.pi - math.asin(b_graze * math.sqrt(1 - 1 / 20.0) / 20.0)
                assert abs(x[k] - xi_graze) < 1e-5
            else:
                assert np.all(d <= 1e-14) or np.all(d >= -1e-14), (r, order)
        x2 = connect(20.0, r, phi, 2).xi
        assert np.all(x2 > edge) if r < 1.5 else np.all(x2 < edge)


def test_invalid_points_are_nan_and_bad_observers_raise():
    c = connect(20.0, np.array([0.5, 1.0, np.nan, np.inf, 3.0, 3.0, 3.0]),
                np.array([1.0, 1.0, 1.0, 1.0, -0.1, 4.0, np.nan]))
    for f in c:
        assert np.all(np.isnan(f))
    for bad in (0.5, 1.0, 1.0005, np.nan, np.inf, "x"):  # (inside the photon sphere: see test_rays)
        with pytest.raises(ValueError):
            connect(bad, 3.0, 1.0)
    with pytest.raises(ValueError):
        connect(20.0, 3.0, 1.0, order=3)


def test_broadcasting_and_shapes():
    c = connect(20.0, np.array([[2.0], [3.0]]), np.array([0.1, 0.2, 0.3]))
    assert c.xi.shape == (2, 3)
    s = connect(20.0, 3.0, 1.0)
    assert np.ndim(s.xi) == 0 and np.isfinite(s.xi)


def test_orbit_roots_for_huge_impact_parameters():
    """lutgen.orbit.orbit_from_b keeps the roots of u^3 - u^2 + 1/b^2 = 0 (e1 < 0 < e2 < e3) to full
    relative accuracy up to b = 1e15 r_s: against the series e1 = -t + t^2/2 - 5 t^3/8, e2 = t + t^2/2
    + 5 t^3/8 (t = 1/b), Vieta's sum e1 + e2 + e3 = 1 and the cubic's residual; and it agrees with the
    trigonometric solution where that is accurate."""
    from lutgen.orbit import orbit_from_b

    b = np.geomspace(1e3, 1e15, 49)
    t = 1.0 / b
    orb = orbit_from_b(b)
    assert np.all(orb.real)
    far = b >= 1e5  # the series' next term, O(t^3) relative, is below 1e-15 there
    assert np.allclose(orb.e1[far] / t[far], -1.0 + t[far] * (0.5 - 0.625 * t[far]), rtol=2e-15, atol=0)
    assert np.allclose(orb.e2[far] / t[far], 1.0 + t[far] * (0.5 + 0.625 * t[far]), rtol=2e-15, atol=0)
    assert np.allclose(orb.e1 + orb.e2 + orb.e3, 1.0, rtol=0, atol=1e-15)
    for e in (orb.e1, orb.e2):
        assert np.allclose(e * e * (1.0 - e) * b * b, 1.0, rtol=1e-13, atol=0)
    mid = orbit_from_b(np.array([3.0, 10.0, 100.0]))  # the series' start is not used here
    ref = [np.sort(np.roots([1.0, -1.0, 0.0, 1.0 / bb ** 2]).real) for bb in (3.0, 10.0, 100.0)]
    assert np.allclose(mid.e1, [r[0] for r in ref], rtol=1e-12)
