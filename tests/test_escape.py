"""lutgen.escape (where rays from a static observer go to infinity), checked against independent
methods: the DOP853 integrator of the geodesic equations (lutgen.reference), an integration of the
orbit equation u'' + u = 3/2 u^2 written here (observers inside the photon sphere, which the
reference does not take), the connecting rays of far targets (lutgen.connect), the flat limit, the
weak-field deflection series and the photon sphere's Lyapunov exponent.

Units: r_s = 1, angles in radians.
"""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import lutgen
from lutgen import escape
from lutgen.reference import shadow_xi_crit, shoot


def _shot_escape_angle(r_obs, xi, r_far=1e7):
    """phi_inf from the reference integrator: the ray shot to r_far, plus the rest of its sweep to
    infinity, integral_0^(1/r_far) du / sqrt(1/b^2 - u^2 + u^3) = asin(b/r_far) (1 + O(1/r_far))."""
    s = shoot(r_obs, xi, r_escape=r_far)
    if s.status != "escape":
        return s.status, math.nan
    return s.status, s.phi + math.asin(min(s.b / s.r, 1.0))


@pytest.mark.parametrize("r_obs", [1.6, 3.0, 20.0, 200.0])
def test_against_the_geodesic_integrator(r_obs):
    lim = escape.escape_limit(r_obs)
    assert lim == pytest.approx(math.pi - shadow_xi_crit(r_obs), abs=1e-14)
    xis = [0.0, 0.4, 1.2, 0.5 * math.pi - 1e-3, 0.5 * math.pi + 1e-3, 2.2, lim - 1e-2, lim - 1e-4, lim - 1e-6]
    xis = [x for x in xis if x < lim]
    phi = escape.escape_angle(r_obs, np.array(xis))
    for x, p in zip(xis, phi):
        status, ref = _shot_escape_angle(r_obs, x)
        assert status == "escape"
        # next to the limit the integrator's local errors (rtol 1e-12) grow as 1/(lim - xi) along the
        # ray's passes of the photon sphere (they shrink tenfold with rtol 1e-13)
        assert p == pytest.approx(ref, abs=1e-9 + 3e-13 / (lim - x)), (r_obs, x)
    # just beyond the limit the ray falls in (both methods)
    assert np.isnan(escape.escape_angle(r_obs, lim + 1e-6))
    assert shoot(r_obs, lim + 1e-6).status == "horizon"


def _binet_escape_angle(r_obs, xi):
    """phi_inf by integrating u'' = -u + 3/2 u^2 (u = 1/r, ' = d/dphi) from u = 1/r_obs with
    u' = -/+ u sqrt(1 - u) cot(xi) (out/in) to u = 0 (escape) or u = 1 (horizon): no elliptic
    functions and no closed form of the orbit."""
    uo = 1.0 / r_obs
    du0 = -uo * math.sqrt(1.0 - uo) * math.cos(xi) / math.sin(xi)

    def rhs(_phi, y):
        return [y[1], -y[0] + 1.5 * y[0] * y[0]]

    def out(_phi, y):
        return y[0]

    def horizon(_phi, y):
        return y[0] - 1.0

    out.terminal = horizon.terminal = True
    sol = solve_ivp(rhs, (0.0, 200.0), [uo, du0], method="DOP853", rtol=1e-12, atol=1e-14,
                    events=[out, horizon])
    if len(sol.t_events[0]):
        return sol.t_events[0][0]
    return math.nan


@pytest.mark.parametrize("r_obs", [1.05, 1.3, 1.45, 1.5, 2.5])
def test_inside_the_photon_sphere_against_the_orbit_equation(r_obs):
    lim = escape.escape_limit(r_obs)
    if r_obs <= 1.5:
        # only outward rays with b < b_crit escape: sin(lim) = b_crit sqrt(1 - 1/r) / r
        assert lim <= 0.5 * math.pi + 1e-15
        assert math.sin(lim) == pytest.approx(1.5 * math.sqrt(3.0) * math.sqrt(1 - 1 / r_obs) / r_obs, rel=1e-14)
    for frac in (0.1, 0.5, 0.9, 0.999, 1 + 1e-3):
        x = frac * lim
        if x >= math.pi:
            continue
        p = float(escape.escape_angle(r_obs, x))
        ref = _binet_escape_angle(r_obs, x)
        if frac > 1:
            assert math.isnan(p) and math.isnan(ref)
        else:
            assert p == pytest.approx(ref, abs=1e-9 + 3e-13 / (lim - x)), (r_obs, x)


@pytest.mark.parametrize("r_obs", [3.0, 20.0])
@pytest.mark.parametrize("order", [1, 2])
def test_far_targets_are_seen_in_their_direction(r_obs, order):
    """A target at very large R is seen along the ray that leaves towards it: the xi of
    lutgen.connect(r_obs, R, phi) has the escape angle phi (order 1) or 2 pi - phi (order 2), up to
    the parallax O(r_obs / R)."""
    phi = np.array([0.3, 1.0, 2.0, 3.0])
    for R in (1e6, 1e7, 1e8, 1e9):
        c = lutgen.connect(r_obs, R, phi, order=order)
        want = phi if order == 1 else 2 * np.pi - phi
        got = escape.escape_angle(r_obs, c.xi)
        assert np.all(np.abs(got - want) < 3 * r_obs / R + 1e-9), (R, got - want)


def test_flat_limit_and_weak_field_deflection():
    r_obs = 1e12
    xi = np.linspace(0.0, 3.0, 31)
    assert np.allclose(escape.escape_angle(r_obs, xi), xi, atol=1e-10, rtol=0)
    # the in- and outgoing rays of one impact parameter b together sweep pi + alpha(b), the
    # deflection of a ray from infinity to infinity (M = 1/2): alpha = 4M/b + 15 pi M^2 / (4 b^2)
    # + 128 M^3 / (3 b^3) + 3465 pi M^4 / (64 b^4) + ... (Keeton & Petters 2005)
    r_obs = 1e6
    for b in (50.0, 200.0, 1000.0):
        x_out = math.asin(b * math.sqrt(1 - 1 / r_obs) / r_obs)
        total = float(escape.escape_angle(r_obs, x_out) + escape.escape_angle(r_obs, math.pi - x_out))
        alpha = 2 / b + 15 * math.pi / (16 * b * b) + 16 / (3 * b**3)
        assert abs(total - math.pi - alpha) < 1.5 * 3465 * math.pi / (1024 * b**4) + 1e-12, b


@pytest.mark.parametrize("r_obs", [1.2, 1.5, 3.0, 50.0])
def test_rings_diverge_with_the_photon_sphere_lyapunov_exponent(r_obs):
    """Next to the limit the orbit lingers at the photon sphere, where u'' + u = 3/2 u^2 linearised
    at u = 2/3 gives perturbations growing as e^phi (Lyapunov exponent 1 per radian): passing it with
    P_min ~ (b - b_crit) sweeps -ln(b - b_crit) + const, whether the ray crosses it (from inside) or
    turns next to it (from outside), and b - b_crit ~ lim - xi (at r = 1.5 the observer sits on it:
    half the sweep, but b - b_crit ~ (lim - xi)^2). So d phi / d ln(lim - xi) -> -1."""
    slope = 1.0
    lim = escape.escape_limit(r_obs)
    d = np.array([1e-5, 1e-6])
    p = escape.escape_angle(r_obs, lim - d)
    assert (p[1] - p[0]) / math.log(10.0) == pytest.approx(slope, rel=2e-3)


@pytest.mark.parametrize("r_obs", [1.1, 1.45, 1.52, 2.0, 20.0, 1e3, 1e6])
def test_table_lookup_is_well_under_a_pixel(r_obs):
    """The table's linear interpolation (as the shader does it) against escape_angle, as an error of
    the apparent position: |phi error| / (d phi / d xi), below 6e-5 rad (a pixel of a 90 degree,
    640 px view is 2.5e-3 rad; the default 1024 nodes give at most 4.4e-5 rad, at r_obs ~ 1.5) for
    every ray down to 1e-6 rad from the shadow's edge (a float32 shader resolves ~2.4e-7 rad)."""
    t = escape.escape_table(r_obs)
    rng = np.random.default_rng(7)
    s = rng.uniform(0.0, math.log(t.xi_lim / 1e-6), 4000)
    xi = -t.xi_lim * np.expm1(-s)
    exact = escape.escape_angle(r_obs, xi)
    slope = (escape.escape_angle(r_obs, xi + 1e-9) - exact) / 1e-9
    assert np.all(np.isfinite(exact)) and np.all(slope > 0.5)
    err = np.abs(t.lookup(xi) - exact) / slope
    assert err.max() < 6e-5
    assert np.isnan(t.lookup(t.xi_lim)) and np.isnan(t.lookup(t.xi_lim + 0.1))


def test_table_directions_rotate_each_ray_in_its_own_plane():
    """EscapeTable.directions: for rays in any direction around an arbitrary e1, the direction at
    infinity is unit, lies in the plane of e1 and the ray, at the angle escape_angle from e1 on the
    ray's side (within the table's error); rays that fall in give NaN rows; a ray along e1 keeps its
    direction."""
    rng = np.random.default_rng(3)
    e1 = np.array([0.3, -0.5, 0.8])
    e1 /= np.linalg.norm(e1)
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    d = np.vstack([d, e1])
    t = escape.escape_table(6.0)
    out = t.directions(d, e1)
    xi = np.arccos(np.clip(d @ e1, -1.0, 1.0))
    fell = xi >= t.xi_lim
    assert fell.sum() > 10 and np.all(np.isnan(out[fell])) and np.all(np.isfinite(out[~fell]))
    ok = ~fell & (np.abs(xi - t.xi_lim) > 1e-3)
    o = out[ok]
    assert np.allclose(np.linalg.norm(o, axis=1), 1.0, atol=1e-12)
    normal = np.cross(e1, d[ok])
    assert np.allclose(np.einsum("ij,ij->i", o, normal), 0.0, atol=1e-12)  # in the ray's plane
    phi = escape.escape_angle(6.0, xi[ok])
    side = np.einsum("ij,ij->i", np.cross(e1, o), normal)  # turned the ray's way from e1, not back
    got = np.arctan2(np.linalg.norm(np.cross(e1, o), axis=1) * np.sign(side), o @ e1)
    assert np.all(np.abs(np.angle(np.exp(1j * (got - phi)))) < 1e-4)
    assert np.allclose(out[-1], e1)


def test_bad_observers_are_refused():
    for r in (1.0, 0.5, math.nan, math.inf):
        with pytest.raises(ValueError):
            escape.escape_angle(r, 0.1)
    with pytest.raises(ValueError, match="event horizon"):
        escape.escape_table(0.9)
    assert np.isnan(escape.escape_angle(20.0, [-0.1, math.pi, math.nan])).all()
