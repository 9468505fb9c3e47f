"""The observer's view (grlens_addon/core/observer_view.py): the one step from the table's values
(xi, dt, the plane's e2) to directions and image positions in the world, its inverse, and that the
map stage, the axis patches and the reference tracer all take that step there, to the bit."""
import numpy as np
import pytest

from grlens_addon.core import axis_patch, mapping, observer_view, raytrace
from lutgen import LUTFamily, connect

HOLE = np.array([0.3, -0.2, 0.1])
R_S = 1.7  # BU
CAMERA = HOLE + R_S * np.array([12.0, 5.0, 4.0])
SCENE = mapping.Scene(CAMERA, HOLE, R_S)


@pytest.fixture(scope="module")
def table():
    return LUTFamily().at(SCENE.r_obs)


def _points(n, seed=1):
    rng = np.random.default_rng(seed)
    return HOLE + R_S * rng.uniform(-12, 12, (n, 3))


def test_view_directions_are_the_angle_xi_from_e1_in_the_plane():
    """A direction from view_directions makes the angle xi with e1 (by arccos, an independent
    measure), lies in the plane of e1 and e2, on e2's side for order 1 and the other side for order 2."""
    rng = np.random.default_rng(3)
    e1 = SCENE.e1
    xi = rng.uniform(0, np.pi, 500)
    e2 = np.cross(e1, rng.normal(size=(500, 3)))
    e2 /= np.linalg.norm(e2, axis=1, keepdims=True)
    for order, side in ((1, 1.0), (2, -1.0)):
        d = observer_view.view_directions(xi, e2, e1, order)
        np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-15)
        np.testing.assert_allclose(np.arccos(np.clip(d @ e1, -1, 1)), xi, atol=3e-8)
        np.testing.assert_allclose(np.einsum("ij,ij->i", d, np.cross(e1, e2)), 0.0, atol=1e-15)
        assert np.all(side * np.einsum("ij,ij->i", d, e2) >= -1e-15)
    assert np.isnan(observer_view.view_directions(np.array([np.nan]), e2[:1], e1, 1)).all()


def test_ray_planes_inverts_view_directions():
    """ray_planes(view_directions(xi, e2)) gives back xi and e2 (order 1's side), for any length of
    the direction; a ray along the axis gets any_perpendicular(e1) as its e2."""
    rng = np.random.default_rng(4)
    e1 = SCENE.e1
    xi = rng.uniform(1e-6, np.pi - 1e-6, 400)
    e2 = np.cross(e1, rng.normal(size=(400, 3)))
    e2 /= np.linalg.norm(e2, axis=1, keepdims=True)
    d = observer_view.view_directions(xi, e2, e1, 1) * rng.uniform(0.1, 10, (400, 1))
    got_xi, cos_xi, sin_xi, got_e2 = observer_view.ray_planes(d, e1)
    np.testing.assert_allclose(got_xi, xi, atol=1e-13)
    np.testing.assert_allclose(got_e2, e2, atol=1e-9)
    np.testing.assert_allclose(cos_xi, np.cos(xi), atol=1e-15)
    np.testing.assert_allclose(sin_xi, np.sin(xi), atol=1e-15)
    np.testing.assert_allclose(observer_view.ray_planes(np.array([e1, -e1]), e1)[0], [0.0, np.pi], atol=1e-15)
    z = np.array([0.0, 0.0, 1.0])
    xi_ax, _, _, e2_ax = observer_view.ray_planes(np.array([z, -2 * z]), z)
    np.testing.assert_array_equal(xi_ax, [0.0, np.pi])
    np.testing.assert_array_equal(e2_ax, [observer_view.any_perpendicular(z)] * 2)


def _written_out(xi, dt, e2, order):
    """The step as the map stage, the axis patches and the tracer each wrote it before the seam."""
    sign = 1.0 if order == 1 else -1.0
    c, s = np.cos(xi), np.sin(xi)
    direction = c[:, None] * SCENE.e1 + (sign * s)[:, None] * e2
    distance = dt * SCENE.r_s
    return direction, distance, SCENE.camera + distance[:, None] * direction, np.isfinite(distance) & np.isfinite(c)


def test_mapper_images_take_the_step_in_observer_view(table):
    """Mapper.images: directions, distances, positions and validity equal, to the bit, the step written
    out from the table's values, and the images agree with lutgen.connect (the exact solver)."""
    pts = _points(3000)
    out = mapping.Mapper(SCENE, table).images(pts)
    for order, img in out.items():
        direction, distance, position, finite = _written_out(img.xi, img.dt, img.plane.e2, order)
        valid = finite & ~img.plane.on_axis
        position[~valid] = np.nan
        np.testing.assert_array_equal(img.direction, direction)
        np.testing.assert_array_equal(img.distance, distance)
        np.testing.assert_array_equal(img.position, position)
        np.testing.assert_array_equal(img.valid, valid)
        ok = np.flatnonzero(img.valid)[:200]
        conn = connect(SCENE.r_obs, img.plane.r[ok], img.plane.phi[ok], order)
        exact = _written_out(conn.xi, conn.dt, img.plane.e2[ok], order)[0]
        assert np.nanmax(np.linalg.norm(exact - img.direction[ok], axis=1)) < 1e-4


def test_limit_images_take_the_step_in_observer_view(table):
    """axis_patch.limit_images (the Einstein ring's points) equal the step written out, to the bit."""
    crossing = axis_patch.Crossing(tri=0, point=HOLE - 3.0 * R_S * SCENE.e1, along=-3.0 * R_S)
    psi = np.linspace(0, 2 * np.pi, 17)
    mp = mapping.Mapper(SCENE, table)
    for order in (1, 2):
        img = axis_patch.limit_images(crossing, psi, mp, order)
        direction, distance, position, valid = _written_out(img.xi, img.dt, img.plane.e2, order)
        position[~valid] = np.nan
        np.testing.assert_array_equal(img.direction, direction)
        np.testing.assert_array_equal(img.position, position)
        np.testing.assert_array_equal(img.valid, valid)
        assert img.valid.all()


def test_reference_tracer_takes_the_step_in_observer_view():
    """raytrace: a ray's (xi, e2) come from ray_planes, and image_pixels' directions from
    view_directions: the pixel of an image is where the exact direction projects."""
    cam = raytrace.Camera.look_at(CAMERA, HOLE, np.radians(40), 64, 48)
    rays = raytrace.Rays(cam.position, cam.pixel_directions().reshape(-1, 3), HOLE, R_S)
    xi, cos_xi, sin_xi, e2 = observer_view.ray_planes(cam.pixel_directions().reshape(-1, 3), rays.e1)
    np.testing.assert_array_equal(rays.xi, xi)
    np.testing.assert_array_equal(rays.e2, e2)
    pts = _points(50, seed=7)
    plane = mapping.plane_coordinates(pts, SCENE)
    for order in (1, 2):
        col, row = raytrace.image_pixels(pts, cam, HOLE, R_S, order)
        conn = connect(SCENE.r_obs, plane.r, plane.phi, order)
        c2, r2, depth = cam.project(cam.position + _written_out(conn.xi, conn.dt, plane.e2, order)[0])
        ok = np.isfinite(col)
        assert ok.sum() > 5
        np.testing.assert_array_equal(col[ok], c2[ok])
        np.testing.assert_array_equal(row[ok], r2[ok])


# --------------------------------------------------------------------------------------------------
# A moving observer
# --------------------------------------------------------------------------------------------------
def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _boost(beta):
    """The 4x4 Lorentz boost (components (t, x, y, z), c = 1) from the static frame to the frame moving
    with velocity ``beta`` (3,): a matrix, built from its definition, not from the aberration formula."""
    b = np.asarray(beta, float)
    b2 = b @ b
    g = 1 / np.sqrt(1 - b2)
    L = np.eye(4)
    L[0, 0] = g
    L[0, 1:] = L[1:, 0] = -g * b
    L[1:, 1:] += (g - 1) * np.outer(b, b) / b2
    return L


BETAS = [np.array([0.4, 0.0, 0.0]), np.array([0.1, -0.3, 0.25]), np.array([-0.55, 0.6, -0.5]), np.array([0, 0, 0.97])]


@pytest.mark.parametrize("beta", BETAS)
def test_aberration_and_doppler_are_a_boost_of_the_photons_four_momentum(beta):
    """aberrate (closed form in the angle to beta) equals boosting the photon's 4-momentum (1, k),
    k = -d, with the Lorentz matrix and reading off -p'/|p'|; doppler_factor equals its energy p'^t."""
    L = _boost(beta)
    eta = np.diag([-1.0, 1, 1, 1])
    np.testing.assert_allclose(L.T @ eta @ L, eta, atol=1e-13)  # the test's matrix is a Lorentz transformation
    d = _unit(np.random.default_rng(5).normal(size=(2000, 3)))
    p = np.column_stack([np.ones(len(d)), -d]) @ L.T
    np.testing.assert_allclose(observer_view.aberrate(d, beta), -_unit(p[:, 1:]), atol=1e-13)
    np.testing.assert_allclose(observer_view.doppler_factor(d, beta), p[:, 0], rtol=1e-13)
    np.testing.assert_allclose(np.linalg.norm(observer_view.aberrate(d, beta), axis=1), 1.0, atol=1e-15)


@pytest.mark.parametrize("beta", BETAS)
def test_the_doppler_factor_and_hole_angle_from_the_moving_view_need_no_static_directions(beta):
    """doppler_factor_seen(d', beta), from the moving observer's directions d' = aberrate(d), is the
    boosted photon's energy of the static direction d; hole_angle with beta (two dot products of d')
    is the static angle from the hole times the aberration's local magnification, the reciprocal of
    that energy: 1 / (gamma (1 + beta . d))."""
    L = _boost(beta)
    d = _unit(np.random.default_rng(8).normal(size=(2000, 3)))
    p = np.column_stack([np.ones(len(d)), -d]) @ L.T
    seen = -_unit(p[:, 1:])
    np.testing.assert_allclose(observer_view.doppler_factor_seen(seen, beta), p[:, 0], rtol=1e-12)
    np.testing.assert_allclose(observer_view.magnification(seen, beta), 1.0 / p[:, 0], rtol=1e-12)
    np.testing.assert_array_equal(observer_view.magnification(seen, None), 1.0)
    camera, hole = SCENE.camera, SCENE.hole
    towards = (hole - camera) / np.linalg.norm(hole - camera)
    want = np.arccos(np.clip(d @ towards, -1, 1)) / p[:, 0]
    got = observer_view.hole_angle(seen, camera, hole, beta)
    far = np.abs(d @ towards) < 1 - 1e-6  # (arccos near 0 and pi magnifies rounding)
    np.testing.assert_allclose(got[far], want[far], rtol=1e-10)
    np.testing.assert_allclose(got, want, atol=1e-7)


@pytest.mark.parametrize("beta", BETAS)
def test_unaberrate_undoes_aberrate(beta):
    d = _unit(np.random.default_rng(6).normal(size=(2000, 3)))
    np.testing.assert_allclose(observer_view.unaberrate(observer_view.aberrate(d, beta), beta), d, atol=2e-13)
    np.testing.assert_allclose(observer_view.aberrate(observer_view.unaberrate(d, beta), beta), d, atol=2e-13)


def test_aberration_special_cases_and_bad_input():
    """Light from ahead stays ahead; light the static observer sees at right angles to the motion
    comes, for the moving observer, from cos theta' = beta (the headlight effect); beta = 0 changes
    nothing (the same array); |beta| >= 1 is refused."""
    beta = np.array([0.0, 0.6, 0.0])
    d = np.array([[0, 1.0, 0], [0, -1.0, 0], [1.0, 0, 0], [np.nan, 0, 0]])
    out = observer_view.aberrate(d, beta)
    np.testing.assert_allclose(out[:2], d[:2], atol=1e-16)
    np.testing.assert_allclose(out[2] @ [0, 1, 0], 0.6, atol=1e-15)
    assert np.isnan(out[3]).all()
    np.testing.assert_allclose(observer_view.doppler_factor(d[:3], beta), [2.0, 0.5, 1.25], rtol=1e-15)
    assert observer_view.aberrate(d, np.zeros(3)) is d
    np.testing.assert_array_equal(observer_view.doppler_factor(d[:3], np.zeros(3)), 1.0)
    for bad in ([1.0, 0, 0], [0.8, 0.7, 0], [np.nan, 0, 0]):
        with pytest.raises(ValueError, match="speed of light"):
            observer_view.aberrate(d, bad)


def _spherical(x):
    """r, theta, phi and the unit vectors r_hat, theta_hat, phi_hat of points x (N, 3)."""
    r = np.linalg.norm(x, axis=1)
    th = np.arccos(x[:, 2] / r)
    ph = np.arctan2(x[:, 1], x[:, 0])
    r_hat = x / r[:, None]
    th_hat = np.column_stack([np.cos(th) * np.cos(ph), np.cos(th) * np.sin(ph), -np.sin(th)])
    ph_hat = np.column_stack([-np.sin(ph), np.cos(ph), np.zeros_like(ph)])
    return r, th, r_hat, th_hat, ph_hat


def test_static_frame_beta_is_the_static_tetrads_view_of_the_four_velocity():
    """static_frame_beta against the 4-velocity in Schwarzschild coordinates (t, r, theta, phi),
    u = u^t (1, dr/dt, dtheta/dt, dphi/dt) normalised with the metric, projected on the static
    observer's orthonormal tetrad: gamma = -g(u, e_t), gamma beta^i = g(u, e_i)."""
    rng = np.random.default_rng(8)
    hole, r_s, c = np.array([1.0, -2.0, 0.5]), 1.7, 2.3  # BU, BU, BU per frame
    x = rng.normal(size=(500, 3))
    x *= (rng.uniform(1.05, 30, 500) / np.linalg.norm(x, axis=1))[:, None]  # r_s units, outside the horizon
    r, th, r_hat, th_hat, ph_hat = _spherical(x)
    f = 1 - 1 / r
    # coordinate velocities (units of c) with a static-frame speed below 1
    w = rng.normal(size=(500, 3)) * 0.3
    w *= np.minimum(1, 0.95 / np.linalg.norm(w, axis=1))[:, None]
    dr, r_dth, r_s_dph = w[:, 0] * f, w[:, 1] * np.sqrt(f), w[:, 2] * np.sqrt(f)
    v_world = dr[:, None] * r_hat + r_dth[:, None] * th_hat + r_s_dph[:, None] * ph_hat  # dx/dt, units of c
    ut = 1 / np.sqrt(f - dr**2 / f - r_dth**2 - r_s_dph**2)
    u = np.column_stack([ut, ut * dr, ut * r_dth / r, ut * r_s_dph / (r * np.sin(th))])
    metric = np.stack([-f, 1 / f, r**2, (r * np.sin(th)) ** 2], axis=1)
    tetrad = [np.zeros((len(r), 4)) for _ in range(4)]  # the static observer's orthonormal tetrad
    for k, e in enumerate((1 / np.sqrt(f), np.sqrt(f), 1 / r, 1 / (r * np.sin(th)))):
        tetrad[k][:, k] = e
    proj = [np.einsum("ij,ij,ij->i", metric, u, e) for e in tetrad]
    gamma = -proj[0]
    expect = (proj[1][:, None] * r_hat + proj[2][:, None] * th_hat + proj[3][:, None] * ph_hat) / gamma[:, None]
    got = observer_view.static_frame_beta(hole + r_s * x, c * v_world, hole, r_s, c)
    np.testing.assert_allclose(got, expect, atol=1e-12)
    np.testing.assert_allclose(1 / np.sqrt(1 - np.einsum("ij,ij->i", got, got)), gamma, rtol=1e-12)
    # one position as a (3,) vector
    np.testing.assert_allclose(observer_view.static_frame_beta(hole + r_s * x[0], c * v_world[0], hole, r_s, c),
                               expect[:1], atol=1e-12)
    with pytest.raises(ValueError, match="horizon"):
        observer_view.static_frame_beta(hole + [0.9 * r_s, 0, 0], [0, 0, 0], hole, r_s, c)
    for bad_c in (0.0, -1.0, np.nan):
        with pytest.raises(ValueError, match="speed of light"):
            observer_view.static_frame_beta(hole + r_s * x, v_world, hole, r_s, bad_c)


def _four_velocity(beta, r, phi):
    """Coordinate components (t, r, theta, phi) at (r, theta = pi/2, phi) of the observer moving with
    ``beta`` (N, 3) (world axes; the plane of the geodesic is the x-y plane) in the local static frame."""
    f = 1 - 1 / r
    r_hat = np.column_stack([np.cos(phi), np.sin(phi), 0 * phi])
    ph_hat = np.column_stack([-np.sin(phi), np.cos(phi), 0 * phi])
    g = 1 / np.sqrt(1 - np.einsum("ij,ij->i", beta, beta))
    b_r, b_ph, b_th = np.einsum("ij,ij->i", beta, r_hat), np.einsum("ij,ij->i", beta, ph_hat), -beta[:, 2]
    return np.column_stack([g / np.sqrt(f), g * b_r * np.sqrt(f), g * b_th / r, g * b_ph / r])


def _minus_p_dot_u(p, u, r):
    """-g(p, u) with the Schwarzschild metric at (r, theta = pi/2)."""
    f = 1 - 1 / r
    return f * p[:, 0] * u[:, 0] - p[:, 1] * u[:, 1] / f - r**2 * (p[:, 2] * u[:, 2] + p[:, 3] * u[:, 3])


@pytest.mark.parametrize("order", [1, 2])
def test_frequency_ratio_is_the_ratio_of_the_invariants_minus_p_dot_u(order):
    """g by the static-frame formula against (-p.u_observer) / (-p.u_emitter) with the Schwarzschild
    metric in coordinates, for real connecting photons (lutgen.connect: its xi at the observer and
    its tangent at the emitter give the photon's coordinate momentum at both ends) and observers
    and emitters moving every way at up to 0.7 c."""
    rng = np.random.default_rng(9 + order)
    n, r_o = 300, 8.0
    r_e = rng.uniform(1.2, 15, n)
    phi = rng.uniform(0.05, np.pi - 0.05, n)
    conn = connect(r_o, r_e, phi, order)
    ok = np.isfinite(conn.xi)
    r_e, phi, xi, ux, uy = r_e[ok], phi[ok], conn.xi[ok], conn.ux[ok], conn.uy[ok]
    m = len(r_e)
    assert m > 200
    f_o, f_e = 1 - 1 / r_o, 1 - 1 / r_e
    side = 1.0 if order == 1 else -1.0
    # future-directed photon momenta (the table's rays are traced backwards from the observer)
    p_o = np.column_stack([np.full(m, 1 / np.sqrt(f_o)), -np.sqrt(f_o) * np.cos(xi), 0 * xi, -side * np.sin(xi) / r_o])
    p_e = np.column_stack([np.sqrt(f_o) / f_e, -(ux * np.cos(phi) + uy * np.sin(phi)), 0 * xi,
                           -(-ux * np.sin(phi) + uy * np.cos(phi)) / r_e])
    beta_o = np.array([0.3, -0.5, 0.35])
    beta_e = rng.normal(size=(m, 3)) * 0.35
    beta_e *= np.minimum(1, 0.7 / np.linalg.norm(beta_e, axis=1))[:, None]
    expect = (_minus_p_dot_u(p_o, _four_velocity(np.tile(beta_o, (m, 1)), np.full(m, r_o), 0 * xi), np.full(m, r_o))
              / _minus_p_dot_u(p_e, _four_velocity(beta_e, r_e, phi), r_e))
    e1, e2 = np.array([1.0, 0, 0]), np.tile([0, 1.0, 0], (m, 1))
    k_o = -observer_view.view_directions(xi, e2, e1, order)
    scene = mapping.Scene(np.array([r_o, 0, 0]), np.zeros(3), 1.0)
    plane = mapping.PlaneCoordinates(r=r_e, phi=phi, e2=e2, on_axis=np.zeros(m, bool))
    k_e = mapping.leaving_direction(plane, scene, ux, uy)
    got = observer_view.frequency_ratio(r_e, r_o, k_o, beta_o, k_e, beta_e)
    np.testing.assert_allclose(got, expect, rtol=1e-10)
    # emitters at rest: only the gravitational shift and the observer's motion
    rest = _minus_p_dot_u(p_o, _four_velocity(np.tile(beta_o, (m, 1)), np.full(m, r_o), 0 * xi), np.full(m, r_o)) \
        / _minus_p_dot_u(p_e, _four_velocity(np.zeros((m, 3)), r_e, phi), r_e)
    np.testing.assert_allclose(observer_view.frequency_ratio(r_e, r_o, k_o, beta_o), rest, rtol=1e-10)


def test_frequency_ratio_limits_and_bad_input():
    """The sky seen by a static observer is blue-shifted by 1 / sqrt(1 - r_s/r); far from the hole g is
    special relativity's Doppler factor (receding: sqrt((1 - beta) / (1 + beta)); co-moving: 1; light
    arriving across the motion: gamma); an
    observer moving towards the source sees g > 1; emitters inside the horizon or at c give NaN."""
    k = np.array([[1.0, 0, 0]])
    for r in (1.01, 3.0, 20.0):
        np.testing.assert_allclose(observer_view.frequency_ratio(np.array([np.inf]), r, k), 1 / np.sqrt(1 - 1 / r),
                                   rtol=1e-15)
    far, b = 1e12, 0.6
    away = observer_view.frequency_ratio(np.array([far]), far, k, [b, 0, 0])
    np.testing.assert_allclose(away, np.sqrt((1 - b) / (1 + b)), rtol=1e-11)
    np.testing.assert_allclose(observer_view.frequency_ratio(np.array([far]), far, k, [-b, 0, 0]),
                               np.sqrt((1 + b) / (1 - b)), rtol=1e-11)
    np.testing.assert_allclose(observer_view.frequency_ratio(np.array([far]), far, k, [b, 0.2, 0], k, [b, 0.2, 0]), 1.0,
                               rtol=1e-11)
    # light arriving at right angles to the motion (in the static frame): time dilation alone, gamma
    np.testing.assert_allclose(observer_view.frequency_ratio(np.array([far]), far, k, [0, 0.5, 0]), 1 / np.sqrt(0.75),
                               rtol=1e-11)
    out = observer_view.frequency_ratio(np.array([0.9, 5.0]), 10.0, np.tile(k, (2, 1)), None, np.tile(k, (2, 1)),
                                        np.array([[0, 0, 0], [1.0, 0, 0]]))
    assert np.isnan(out).all()
    with pytest.raises(ValueError, match="horizon"):
        observer_view.frequency_ratio(np.array([5.0]), 1.0, k)
    with pytest.raises(ValueError, match="speed of light"):
        observer_view.frequency_ratio(np.array([5.0]), 4.0, k, [0, 1.0, 0])


@pytest.mark.parametrize("beta", BETAS[:3])
def test_ring_measure_of_a_moving_observer_is_the_sag_it_sees(beta):
    """hole_angle with beta: the static radius of the circle about the axis through a direction times
    the aberration's local scale. A piece of such a circle (radius R about the hole's direction in the
    static frame, spanning the azimuth D), seen by the moving observer, sags from its chord by
    ring_sagitta(hole_angle(., beta), D) (checked by aberrating the arc's ends and middle and
    measuring the angle between the chord's middle and the arc's), and unit_directions with beta is
    the aberrated undistorted view."""
    camera, hole = SCENE.camera, SCENE.hole
    towards = -SCENE.e1
    u = observer_view.any_perpendicular(towards)
    v = np.cross(towards, u)
    for radius in (0.003, 0.01):
        for psi in np.linspace(0, 2 * np.pi, 7)[:-1]:
            step = 0.3

            def at(a):
                return np.cos(radius) * towards + np.sin(radius) * (np.cos(a) * u + np.sin(a) * v)

            ends = observer_view.aberrate(np.array([at(psi), at(psi + step)]), beta)
            mid = observer_view.aberrate(at(psi + step / 2)[None], beta)[0]
            chord_mid = ends.sum(axis=0) / np.linalg.norm(ends.sum(axis=0))
            seen_sag = np.arccos(np.clip(chord_mid @ mid, -1, 1))
            r_moving = observer_view.hole_angle(mid[None], camera, hole, beta)[0]
            np.testing.assert_allclose(seen_sag, observer_view.ring_sagitta(r_moving, step), rtol=0.05)
            if np.linalg.norm(beta) > 0.5:  # the static radius would not do
                assert abs(seen_sag / observer_view.ring_sagitta(radius, step) - 1) > 0.2
    np.testing.assert_allclose(observer_view.hole_angle(SCENE.e1[None], camera, hole), [np.pi], atol=1e-7)
    pts = _points(20)
    np.testing.assert_allclose(observer_view.unit_directions(pts, camera, beta),
                               observer_view.aberrate(observer_view.unit_directions(pts, camera), beta), atol=0)
