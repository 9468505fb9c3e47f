"""The reference ray tracer's sky (grlens_addon.core.raytrace: ``Rays.phi_end``, ``escape_directions``,
``PixelBuffers.sky``): the direction in which each ray that neither hits anything nor falls in travels
at infinity.

Units: r_s and world positions in BU (r_s = 1 BU unless stated, so BU = r_s); angles in radians.
Conventions: observer static at r_obs, xi from the outward radial direction e1 = unit(camera - hole),
Phi the angle swept from the camera towards e2. Independent checks: weak-field light bending
(first order in r_s / b) for a distant hole, lutgen.reference's DOP853 integration of the geodesic
equations (plus the few-1e-13-rad tail beyond its escape radius by adaptive quadrature of the orbit
equation), the photon sphere's Lyapunov exponent (one e-fold of xi_crit - xi per radian of winding),
lutgen.connect (the emitter-observer solver) for targets at r = 1e7 r_s, eq. (14) (the shadow).
"""
import math

import numpy as np
import pytest
from scipy.integrate import quad

from grlens_addon.core import raytrace
from lutgen import connect, reference as numeric, shadow_half_angle

E1, E2 = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])


def _rays(xi, r_obs, side=1.0):
    """Rays at angles xi from e1 = +x in the x-y plane (towards +y for side = +1), hole at the origin,
    r_s = 1 BU, camera at (r_obs, 0, 0)."""
    xi = np.atleast_1d(np.asarray(xi, np.float64))
    d = np.cos(xi)[:, None] * E1 + side * np.sin(xi)[:, None] * E2
    return raytrace.Rays(r_obs * E1, d, np.zeros(3), 1.0), d


def _numeric_phi_inf(r_obs, xi):
    """Total swept angle to infinity by DOP853 (lutgen.reference.shoot to r = 1e6 r_s) plus the
    remaining sweep beyond, integral_0^(1/r) du / sqrt(1/b^2 - u^2 + u^3) (adaptive quadrature)."""
    s = numeric.shoot(r_obs, xi, r_escape=1e6)
    assert s.status == "escape", s.status
    tail = quad(lambda u: 1.0 / math.sqrt(1.0 / s.b ** 2 - u * u + u ** 3), 0.0, 1.0 / s.r,
                epsabs=1e-17, epsrel=1e-13)[0]
    return s.phi + tail


def _angle(a, b):
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.einsum("...k,...k->...", a, b))


def test_flat_space_limit_and_weak_bending():
    """A hole 1e6 r_s away (r_s = 1e-3 BU, camera 1e3 BU from it): each ray's sky is its own direction,
    bent towards the hole (in the ray's plane, Phi_inf > xi) by the weak-field angle (1 - cos xi) r_s / b
    (b = r_obs sin xi / sqrt(1 - r_s/r_obs): 2 r_s / b for rays passing the hole, 0 straight outwards)
    to O((r_s / b)^2)."""
    rng = np.random.default_rng(3)
    r_s, hole = 1e-3, np.array([0.3, -0.2, 0.5])
    cam = hole + 1e3 * np.array([0.6, 0.0, 0.8])
    d = rng.normal(size=(400, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    e1 = (cam - hole) / np.linalg.norm(cam - hole)
    d[:5] = -e1 + np.array([[1e-4, 0, 0], [0, 1e-3, 0], [0, 0, 1e-2], [0.1, 0, 0], [0, 0.3, 0]])  # past the hole
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    sky = raytrace.escape_directions(cam, d, hole, r_s)
    np.testing.assert_allclose(np.linalg.norm(sky, axis=1), 1.0, atol=1e-14)
    r_obs = 1e6
    xi = np.arccos(np.clip(d @ e1, -1, 1))
    b = r_obs * np.sin(xi) / math.sqrt(1 - 1 / r_obs)
    bend = _angle(d, sky)
    expect = (1 - np.cos(xi)) / b
    assert np.all(np.abs(bend - expect) <= 5.0 / b ** 2 + 1e-12)
    assert np.all(np.abs(bend[:4] - 2 / b[:4]) < 0.02 * (2 / b[:4])) and bend[0] > 0.02  # 2 r_s / b
    # in the plane of e1 and d, towards the hole: sky = cos(Phi) e1 + sin(Phi) e2 with Phi >= xi
    normal = np.cross(e1, d)
    assert np.abs(np.einsum("nk,nk->n", sky, normal)).max() < 1e-13
    e2 = d - (d @ e1)[:, None] * e1
    e2 /= np.linalg.norm(e2, axis=1, keepdims=True)
    phi_inf = np.mod(np.arctan2(np.einsum("nk,nk->n", sky, e2), sky @ e1), 2 * np.pi)
    assert np.all(phi_inf >= xi - 1e-13) and phi_inf.max() > np.pi


@pytest.mark.parametrize("r_obs", [20.0, 3.0])
def test_escape_angle_matches_numeric_integration(r_obs):
    """Rays heading out, tangent, passing the periapsis, and near the critical angle winding more than
    once around the hole (Phi_inf > 2 pi): Rays.phi_end against DOP853, and the sky direction of
    trace_rays (which also sees a triangle: its pixel has no sky)."""
    xc = math.pi - float(shadow_half_angle(r_obs))
    xis = np.array([0.0, 0.3, 1.0, 0.5 * math.pi - 1e-3, 0.5 * math.pi + 1e-3, 2.0, min(2.8, xc - 0.05),
                    xc - 1e-2, xc - 1e-3, xc - 1e-4])
    rays, d = _rays(xis, r_obs)
    assert not rays.falls_in.any()
    phi = rays.phi_end
    num = np.array([_numeric_phi_inf(r_obs, x) if x > 0 else 0.0 for x in xis])
    np.testing.assert_allclose(phi, num, rtol=0, atol=2e-9)
    assert phi[-1] > 2 * math.pi and phi[-2] > 2 * math.pi  # these wind more than once
    # the sky of trace_rays: a triangle across +z (no ray of the x-y plane meets it)
    scene = raytrace.TriangleScene([[-99.0, -99, 50], [99, -99, 50], [0, 99, 50]], [[0, 1, 2]])
    up = np.array([[0.0, 0.0, 1.0]])
    buf = raytrace.trace_rays(scene, r_obs * E1, np.vstack([d, up]), np.zeros(3), 1.0)
    assert buf.hit.tolist() == [False] * len(xis) + [True]
    expect = np.cos(num)[:, None] * E1 + np.sin(num)[:, None] * E2
    assert _angle(buf.sky[:-1], expect).max() < 2e-9
    assert np.isnan(buf.sky[-1]).all() and not buf.fell.any()


def test_winding_follows_the_photon_sphere_lyapunov_exponent():
    """Close to the critical angle, each factor e in xi_crit - xi adds one radian of swept angle
    (perturbations of the photon orbit grow as exp(Phi)): Phi_inf(xc - d) - Phi_inf(xc - 10 d) -> ln 10."""
    r_obs = 20.0
    xc = math.pi - float(shadow_half_angle(r_obs))
    deltas = np.array([1e-7, 1e-8, 1e-9])
    rays, _ = _rays(xc - deltas, r_obs)
    phi = rays.phi_end
    assert phi[-1] > 6.5 * math.pi
    np.testing.assert_allclose(np.diff(phi), math.log(10.0), atol=1e-5)


@pytest.mark.parametrize("order", [1, 2])
def test_escape_angle_matches_connect_to_a_distant_target(order):
    """lutgen.connect(r_obs, R = 1e7, phi) gives the ray that reaches (R, phi); it escapes at
    Phi_inf = phi (order 2: 2 pi - phi, on the -e2 side) plus the sweep beyond R, asin(b / R) to
    O(b^3 / R^3): within 2e-9 rad of Rays.phi_end."""
    r_obs, R = 20.0, 1e7
    phis = np.array([0.05, 0.5, 1.0, 1.6, 2.5, 3.0, 3.1])
    c = connect(r_obs, np.full(len(phis), R), phis, order)
    assert np.all(np.isfinite(c.xi))
    rays, _ = _rays(c.xi, r_obs, side=1.0 if order == 1 else -1.0)
    b = r_obs * np.sin(c.xi) / math.sqrt(1 - 1 / r_obs)
    target = (phis if order == 1 else 2 * math.pi - phis) + np.arcsin(b / R)
    np.testing.assert_allclose(rays.phi_end, target, rtol=0, atol=2e-9)
    assert np.all(np.abs(rays.phi_end - target + np.arcsin(b / R)) < 2 * b / R)  # O(r_obs / R) without it
    sky = rays.escape_directions()
    side = 1.0 if order == 1 else -1.0
    expect = np.cos(target)[:, None] * E1 + side * np.sin(target)[:, None] * E2
    assert _angle(sky, expect).max() < 2e-9


@pytest.mark.parametrize("r_obs", [20.0, 2.0, 1e4])
def test_shadow_edge_is_eq14(r_obs):
    """Rays beyond the critical angle pi - xi_crit (eq. 14, lutgen.solver.shadow_half_angle) fall in:
    fell True and no sky; just inside it they escape (after many windings)."""
    xc = math.pi - float(shadow_half_angle(r_obs))
    eps = 1e-9 * max(1.0, float(shadow_half_angle(r_obs)))
    xis = np.array([xc - eps, xc + eps, math.pi, 0.5 * (xc + math.pi)])
    rays, d = _rays(xis, r_obs)
    assert rays.falls_in.tolist() == [False, True, True, True]
    sky = raytrace.escape_directions(r_obs * E1, d, np.zeros(3), 1.0)
    assert np.all(np.isfinite(sky[0])) and np.isnan(sky[1:]).all()
    buf = raytrace.trace_rays(raytrace.TriangleScene(np.zeros((0, 3)), np.zeros((0, 3))), r_obs * E1, d,
                              np.zeros(3), 1.0)
    assert buf.fell.tolist() == [False, True, True, True] and not buf.hit.any()
    assert np.all(np.isfinite(buf.sky[0])) and np.isnan(buf.sky[1:]).all()
    assert rays.phi_end[0] > 3 * math.pi


def test_pixel_buffers_keep_the_sky():
    """``sky`` is part of every PixelBuffers operation: empty (NaN), reshape, scatter, and a buffer
    built without it (stored before it existed) gets NaN."""
    buf = raytrace.PixelBuffers.empty((6,))
    assert buf.sky.shape == (6, 3) and np.isnan(buf.sky).all()
    buf.sky[2] = [0.0, 0.0, 1.0]
    assert buf.reshape((2, 3)).sky[0, 2].tolist() == [0.0, 0.0, 1.0]
    mask = np.array([[True, False, True, False], [True, True, True, True]])
    full = buf.scatter(mask)
    assert full.shape == (2, 4) and full.sky[1, 0].tolist() == [0.0, 0.0, 1.0]  # the third pixel of the mask
    assert np.isnan(full.sky[0, 1]).all() and full.object_id[0, 1] == -1
    fields = {k: getattr(buf, k) for k in ("hit", "object_id", "face", "bary", "uv", "order", "light_time",
                                           "fell", "point", "phi", "depth")}
    assert np.isnan(raytrace.PixelBuffers(**fields).sky).all()


@pytest.mark.parametrize("r_obs", [20.0, 2.5, 1e5])
def test_agrees_with_lutgen_escape(r_obs):
    """lutgen.escape.escape_angle (the add-on's lensed-world model: Carlson's form next to the turning
    point) against this module's phi_end (differences of the orbit integral along the curve), over
    xi from 0 to 1e-3 rad short of the shadow: within 5e-9 rad."""
    from lutgen import escape

    xc = math.pi - float(shadow_half_angle(r_obs))
    xi = np.linspace(0.0, xc - 1e-3, 2001)
    rays, _ = _rays(xi, r_obs)
    np.testing.assert_allclose(rays.phi_end, escape.escape_angle(r_obs, xi), rtol=0, atol=5e-9)
