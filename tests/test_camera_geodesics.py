"""Cameras on timelike geodesics in coordinate time (grlens_addon/core/camera_geodesics.py), against
an independent DOP853 integration of the geodesic equations with t as the parameter, and the local
speeds that the static observers measure (observer_view.static_frame_beta)."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from grlens_addon.core import camera_geodesics as cg
from grlens_addon.core import observer_view


def _geodesic_in_t(t, y):
    """Equatorial timelike geodesics, r_s = 1, with coordinate time t as the parameter:
    r'' = -f f'/2 + (3 f' / (2 f)) r'^2 + r f phi'^2, phi'' = (f'/f - 2/r) r' phi' (f = 1 - 1/r,
    f' = 1/r^2), from the Christoffel symbols of the Schwarzschild metric and d/dtau = (dt/dtau) d/dt."""
    r, phi, dr, dphi = y
    f, fp = 1 - 1 / r, 1 / r**2
    return [dr, dphi, -f * fp / 2 + 1.5 * fp / f * dr**2 + r * f * dphi**2, (fp / f - 2 / r) * dr * dphi]


def _integrate(y0, t):
    """The integrated (r, phi, dr/dt, dphi/dt) at the times ``t`` (and the times reached), stopping
    at r = 1.001 (beyond which the parameter t stretches without bound)."""
    def near_horizon(_, y):
        return y[0] - 1.001
    near_horizon.terminal = True
    sol = solve_ivp(_geodesic_in_t, (0, t[-1]), y0, method="DOP853", t_eval=t, rtol=1e-13, atol=1e-15,
                    events=near_horizon)
    assert sol.status in (0, 1)
    return sol.y, sol.t


@pytest.mark.parametrize("r0", [4.0, 12.0, 60.0])
def test_fall_from_rest_matches_the_integrated_geodesic(r0):
    """From rest at r0: r(t) and dr/dt against the integrator started at (r0, dr/dt = 0), until close
    to the horizon; before the moment of rest the body rises (time symmetry)."""
    t = np.linspace(0, 3 * r0 ** 1.5, 400)[1:]  # past the slowing near the horizon
    y, t = _integrate([r0, 0.0, 0.0, 0.0], t)
    r, dr = cg.radial_fall(t, r0, r0)
    assert y[0].min() < 1.02
    np.testing.assert_allclose(r, y[0], rtol=1e-9)
    np.testing.assert_allclose(dr, y[2], rtol=1e-7, atol=1e-11)
    r_back, dr_back = cg.radial_fall(-t, r0, r0)
    np.testing.assert_array_equal(r_back, r)
    np.testing.assert_array_equal(dr_back, -dr)
    # started partway down: the same path shifted in time
    k = 150
    r_mid, dr_mid = cg.radial_fall(t[k:] - t[k], r[k], r0)
    np.testing.assert_allclose(r_mid, r[k:], rtol=1e-12)
    np.testing.assert_allclose(dr_mid, dr[k:], rtol=1e-9, atol=1e-14)


def test_fall_from_infinity_matches_the_integrated_geodesic_and_the_escape_speed():
    """From rest at infinity: against the integrator started at r = 30 with the escape velocity
    (E = 1: dr/dtau = -sqrt(1/r), dt/dtau = 1/f); the static observers see it pass at
    sqrt(r_s/r) c; a release far out approaches it."""
    r_start = 30.0
    t = np.linspace(0, 400, 300)[1:]
    f = 1 - 1 / r_start
    y, t = _integrate([r_start, 0.0, -f * np.sqrt(1 / r_start), 0.0], t)
    r, dr = cg.radial_fall(t, r_start)
    assert y[0].min() < 1.01
    np.testing.assert_allclose(r, y[0], rtol=1e-9)
    np.testing.assert_allclose(dr, y[2], rtol=1e-7, atol=1e-11)
    path = cg.fall_path(t, np.array([0.0, 3.0 * r_start, 0.0]), np.zeros(3), 3.0)
    beta = observer_view.static_frame_beta(path.position, path.velocity, np.zeros(3), 3.0, 1.0)
    np.testing.assert_allclose(np.linalg.norm(beta, axis=1), np.sqrt(1 / r), rtol=1e-12)
    np.testing.assert_allclose(beta[:, 1] / np.linalg.norm(beta, axis=1), -1.0)  # straight towards the hole
    r_far, _ = cg.radial_fall(t, r_start, 1e6)  # E^2 = 1 - 1e-6: speeds within r / (2 r0) relative
    np.testing.assert_allclose(r_far, r, rtol=1e-3)
    assert np.abs(r_far - r).max() > 1e-7  # (and not the same formula)
    # before t = 0 it came in from farther out
    r_before, dr_before = cg.radial_fall(np.array([-100.0, -1000.0]), r_start)
    assert r_start < r_before[0] < r_before[1] and (dr_before < 0).all()


def test_horizon_is_approached_in_coordinate_time():
    """Close to the horizon r - 1 shrinks like exp(-t) (dr/dt -> -(r - 1), e-folding time r_s/c): a
    fall seen in coordinate time slows and freezes there; r stays above 1 (until r - 1 drops below
    the rounding of r, about 1e-16)."""
    for r0 in (np.inf, 10.0):
        ts = np.linspace(0, 400, 40001)
        t0 = ts[np.argmax(cg.radial_fall(ts, 10.0, r0)[0] < 1.001)]
        t = t0 + np.array([0.0, 5.0, 10.0, 20.0])  # r - 1 from 1e-3 to ~2e-12
        r, dr = cg.radial_fall(t, 10.0, r0)
        assert np.all(r > 1) and np.all(np.diff(r) < 0)
        np.testing.assert_allclose(dr[1:] / (r[1:] - 1), -1.0, rtol=2e-2)
        np.testing.assert_allclose(np.diff(np.log(r[1:] - 1)) / np.diff(t[1:]), -1.0, rtol=2e-2)
        assert np.all(cg.radial_fall(t0 + np.array([100.0, 1e4]), 10.0, r0)[0] >= 1.0)


def test_circular_orbit_matches_the_integrated_geodesic_and_the_local_speed():
    """A circular orbit at r: the integrator started with d(phi)/dt = 1/sqrt(2 r^3) stays at r; the
    path's positions and velocities follow it; the static observers measure 1/sqrt(2 (r - 1)) c
    (seed 002, eq. 10); inside the ISCO the path is flagged unstable."""
    for r in (6.0, 3.0, 2.5):
        omega = 1 / np.sqrt(2 * r**3)
        t = np.linspace(0, 2 * np.pi / omega, 200)[1:]
        y, _ = _integrate([r, 0.0, 0.0, omega], t)
        np.testing.assert_allclose(y[0], r, rtol=1e-9 if r >= 3 else 1e-6)
        np.testing.assert_allclose(y[1], omega * t, rtol=1e-9)
        hole, r_s = np.array([1.0, 2.0, -1.0]), 0.5
        start = hole + r_s * r * np.array([0.6, 0.0, 0.8])
        axis = np.array([0.0, 1.0, 0.0]) + 0.7 * np.array([0.6, 0.0, 0.8])  # its part across the radius: +y
        path = cg.orbit_path(t, start, hole, r_s, axis=axis)
        assert path.stable == (r >= 3)
        rel = (path.position - hole) / r_s
        np.testing.assert_allclose(np.linalg.norm(rel, axis=1), r, rtol=1e-14)
        np.testing.assert_allclose(rel[:, 1], 0.0, atol=1e-12)  # in the plane perpendicular to the axis
        cos_phi = rel @ (start - hole) / (r_s * r) / r
        np.testing.assert_allclose(cos_phi, np.cos(omega * t), atol=1e-12)
        # counter-clockwise about +y: from (0.6, 0, 0.8) towards +y x (0.6, 0, 0.8) = (0.8, 0, -0.6)
        assert rel[0] @ [0.8, 0, -0.6] > 0
        np.testing.assert_allclose(np.gradient(rel, t, axis=0)[50:150], path.velocity[50:150], rtol=1e-3, atol=1e-6)
        beta = observer_view.static_frame_beta(path.position, path.velocity, hole, r_s, 1.0)
        np.testing.assert_allclose(np.linalg.norm(beta, axis=1), 1 / np.sqrt(2 * (r - 1)), rtol=1e-13)
    retro = cg.orbit_path([10.0], start, hole, r_s, axis=axis, prograde=False)
    assert (retro.position[0] - hole) @ [0.8, 0, -0.6] < 0


def test_bad_paths_are_refused():
    with pytest.raises(ValueError, match="horizon"):
        cg.radial_fall([1.0], 1.0)
    with pytest.raises(ValueError, match="radius of rest"):
        cg.radial_fall([1.0], 5.0, 4.0)
    with pytest.raises(ValueError, match="photon sphere"):
        cg.orbit_path([1.0], [1.5, 0, 0], np.zeros(3), 1.0, [0, 0, 1])
    with pytest.raises(ValueError, match="axis"):
        cg.orbit_path([1.0], [5.0, 0, 0], np.zeros(3), 1.0, [1, 0, 0])
