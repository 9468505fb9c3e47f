"""Thin disc (issue 4/5): Page-Thorne flux, redshift of circular-orbit gas, colours (add-on core), and
the analytic per-pixel disc reference (lutgen.thin_disc), against independent methods: quadrature of
the general Page-Thorne integral, DOP853 integration of the geodesic equations, straight lines in the
flat-space limit, the emitter-observer solver (isoradials), closed-form limits, and the add-on's
LUT mapping. Units: r_s, c = 1 (BU only where the add-on's per-vertex API takes them)."""
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import minimize_scalar

from grlens_addon.core import mapping
from grlens_addon.core import thin_disc as td
from lutgen import build_lut, connect
from lutgen import thin_disc as ref
from lutgen.reference import shoot

R_OBS = 120.0
INC = np.radians(84.5)


# --------------------------------------------------------------------------------------------------
# Page-Thorne flux
# --------------------------------------------------------------------------------------------------
def flux_by_quadrature(r, r_in):
    """General Page-Thorne formula, M = 1/2 (r_s = 1), integrated numerically:
    F = -(Mdot/(4 pi sqrt(-g))) Omega_,r / (E - Omega L)^2 int_{r_in}^r (E - Omega L) L_,r dr,
    sqrt(-g) = r, with E, L, Omega of circular geodesics; returned in units of
    F0 = 3 M Mdot / (8 pi r_s^3) = 3 Mdot / (16 pi)."""
    M = 0.5
    E = lambda x: (1 - 2 * M / x) / np.sqrt(1 - 3 * M / x)  # noqa: E731
    L = lambda x: np.sqrt(M * x) / np.sqrt(1 - 3 * M / x)  # noqa: E731
    Om = lambda x: np.sqrt(M / x**3)  # noqa: E731
    dL = lambda x: (L(x + 1e-30j) / 1e-30).imag  # complex-step derivative, exact to rounding  # noqa: E731
    integral = quad(lambda x: (E(x) - Om(x) * L(x)) * dL(x), r_in, r, epsabs=0, epsrel=1e-12, limit=200)[0]
    dOm = -1.5 * Om(r) / r
    f = -(1.0 / (4 * np.pi * r)) * dOm / (E(r) - Om(r) * L(r)) ** 2 * integral  # Mdot = 1
    return f / (3.0 / (16.0 * np.pi))


@pytest.mark.parametrize("r_in", [3.0, 4.5])
def test_page_thorne_closed_form_matches_quadrature(r_in):
    r = np.array([r_in * 1.001, r_in + 0.3, 4.7, 6.0, 10.0, 15.0, 40.0, 300.0])
    want = np.array([flux_by_quadrature(x, r_in) for x in r])
    for f in (td.page_thorne_flux, ref.page_thorne_flux):
        np.testing.assert_allclose(f(r, r_in), want, rtol=2e-8)


def test_page_thorne_edges_limits_and_peak():
    assert td.page_thorne_flux(3.0) == 0.0
    np.testing.assert_array_equal(td.page_thorne_flux([1.2, 2.0, 2.999999]), 0.0)
    assert np.isnan(td.page_thorne_flux(np.nan))
    assert td.page_thorne_flux(3.0 + 1e-9) >= 0.0
    with pytest.raises(ValueError):
        td.page_thorne_flux(5.0, r_in=2.0)
    # Newtonian far field: F -> 3 G M Mdot / (8 pi r^3), i.e. F/F0 -> R^-3
    big = np.array([1e4, 1e6, 1e8])
    far = td.page_thorne_flux(big) * big**3
    assert np.all(np.abs(far - 1) < 3.0 / np.sqrt(big)) and np.all(np.abs(far - 1) > 1.0 / np.sqrt(big))
    # maximum: independent bounded minimiser on the quadrature form
    res = minimize_scalar(lambda x: -flux_by_quadrature(x, 3.0), bounds=(3.5, 7.0), method="bounded",
                          options=dict(xatol=1e-7))
    r_pk, f_pk = td.page_thorne_peak()
    assert abs(r_pk - res.x) < 5e-5  # the quadrature's noise on a flat maximum
    assert abs(f_pk / -res.fun - 1) < 1e-9
    # seed 002: F_max/F0 ~ 9.167e-4 at R_max ~ 4.776 (i.e. 9.55 M, not 4.89 M)
    assert abs(r_pk - 4.776) < 1e-3 and abs(f_pk - 9.167e-4) < 1e-7
    assert td.page_thorne_peak(4.5)[0] > r_pk


# --------------------------------------------------------------------------------------------------
# Redshift: conserved-quantity form (core) vs local static frame (lutgen.thin_disc), limits
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("prograde", [True, False])
def test_redshift_conserved_vs_static_frame(prograde):
    rng = np.random.default_rng(1)
    n = 400
    axis = np.array([0.3, -0.2, 0.9])
    axis /= np.linalg.norm(axis)
    r = rng.uniform(1.6, 50.0, n)
    # emitter positions in the disc plane, photon directions arbitrary (local static frame)
    d = rng.normal(size=(n, 3))
    q = d - (d @ axis)[:, None] * axis
    q /= np.linalg.norm(q, axis=1)[:, None]
    k = rng.normal(size=(n, 3))
    k /= np.linalg.norm(k, axis=1)[:, None]
    # conserved angular momentum per unit energy: r (q x k) / sqrt(1 - 1/r)
    L = r[:, None] * np.cross(q, k) / np.sqrt(1 - 1 / r)[:, None]
    for r_obs in (5.0, 120.0):
        a = td.redshift_factor(r, L @ axis, r_obs, prograde)
        b = ref.redshift_static_frame(r_obs, r, q, k, axis, prograde)
        np.testing.assert_allclose(a, b, rtol=1e-12)


def scene_vectors(seed=3):
    """A random world orientation of the sky basis, a hole off the origin and the camera at R_OBS."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    Q *= np.sign(np.linalg.det(Q))  # proper rotation: columns = world e_o, e_right, e_up
    r_s = 2.0
    hole = np.array([1.0, -2.0, 0.5])
    camera = hole + R_OBS * r_s * Q[:, 0]
    return Q, r_s, hole, camera


def disc_points(Q, r_s, hole, inc, r, psi):
    """World points (BU) of the disc of inclination inc at radii r (r_s) and disc angles psi: psi = 0
    towards e_right, psi = pi/2 towards the near side."""
    _, e_right, e_up, axis = ref.sky_vectors(inc)
    near = np.cross(axis, e_right)  # in the disc plane, towards the observer for inc < 90 deg
    sky = np.cos(psi)[:, None] * e_right + np.sin(psi)[:, None] * near
    return hole + r_s * r[:, None] * (sky @ Q.T), Q @ axis


def test_face_on_and_line_of_sight_known_values():
    """Face-on: no Doppler shift, 1 + z = sqrt(1 - 1/r_obs)/sqrt(1 - 3/(2r)) for every vertex, xi and
    order. Any inclination: gas moving across the line of sight (photon with l_z = 0, the points
    in front of and behind the hole) shows the gravitational + transverse Doppler shift only."""
    Q, r_s, hole, camera = scene_vectors()
    rng = np.random.default_rng(4)
    r = rng.uniform(3.0, 15.0, 50)
    psi = rng.uniform(0, 2 * np.pi, 50)
    want = np.sqrt(1 - 1 / R_OBS) / np.sqrt(1 - 1.5 / r)
    pts, axis = disc_points(Q, r_s, hole, 0.0, r, psi)
    plane = mapping.plane_coordinates(pts, mapping.Scene(camera, hole, r_s))
    xi = rng.uniform(0, np.pi, 50)  # whatever the ray, L is perpendicular to the axis
    for order in (1, 2):
        got = td.vertex_redshift(pts, hole, camera, r_s, axis, xi, plane.e2, order)
        np.testing.assert_allclose(got, want, rtol=1e-13)
    # per-pixel reference, face-on: independent of the position angle, no Doppler shift
    th = np.full(16, 0.03)
    al = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    c = ref.disc_crossings(R_OBS, 0.0, th, al, 1)
    np.testing.assert_allclose(c.r, c.r[0], rtol=1e-12)
    np.testing.assert_allclose(c.one_plus_z, np.sqrt(1 - 1 / R_OBS) / np.sqrt(1 - 1.5 / c.r), rtol=1e-12)
    # inclined disc, points straight in front of / behind the hole (psi = +-pi/2)
    pts, axis = disc_points(Q, r_s, hole, INC, r, np.where(psi < np.pi, 0.5, 1.5) * np.pi)
    plane = mapping.plane_coordinates(pts, mapping.Scene(camera, hole, r_s))
    for order in (1, 2):
        got = td.vertex_redshift(pts, hole, camera, r_s, axis, xi, plane.e2, order)
        np.testing.assert_allclose(got, want, rtol=1e-12)
    # the transverse-Doppler + gravitational factor is u^t sqrt(1 - 1/r_obs): a redshift
    assert np.all(want > 1)


# --------------------------------------------------------------------------------------------------
# Per-pixel reference vs DOP853, flat space, isoradials
# --------------------------------------------------------------------------------------------------
def redshift_from_shot(s, phi, alpha, inc, prograde=True):
    """1 + z from the integrated tangent at the crossing: the observer's frame energy is 1 by the
    initial data, the gas measures -p.u_gas in the local static frame."""
    e_o, e_right, e_up, axis = ref.sky_vectors(inc)
    sv = np.cos(alpha) * e_right + np.sin(alpha) * e_up
    q = np.cos(phi) * e_o + np.sin(phi) * sv
    e_phi = -np.sin(phi) * e_o + np.cos(phi) * sv
    f = s.r_minus_1 / s.r
    # future-directed photon p = -u (u is the backward-traced tangent)
    p_t, p_r, p_ph = -np.sqrt(f) * s.ut, -s.ur / np.sqrt(f), -s.r * s.uphi
    beta = 1 / np.sqrt(2 * (s.r - 1))
    gamma = 1 / np.sqrt(1 - beta**2)
    v = np.cross(axis, q) * (1 if prograde else -1)
    return gamma * (p_t - beta * (p_r * q + p_ph * e_phi) @ v)


def test_reference_matches_numerical_integration():
    rng = np.random.default_rng(5)
    th_c = float(np.arcsin(np.sqrt(6.75 * (1 - 1 / R_OBS)) / R_OBS))  # shadow half angle (eq. 14)
    n = 24
    checked = {1: 0, 2: 0}
    for order, lo, hi in ((1, 0.3, 4.0), (2, 1.0, 1.6)):
        theta = th_c * rng.uniform(lo, hi, n)
        alpha = rng.uniform(0, 2 * np.pi, n)
        for prograde in (True, False):
            c = ref.disc_crossings(R_OBS, INC, theta, alpha, order, prograde=prograde)
            for k in range(n):
                s = shoot(R_OBS, np.pi - theta[k], phi_end=c.phi[k])
                if np.isnan(c.r[k]):
                    assert s.status in ("horizon", "escape"), (order, k, s.status)
                    continue
                assert s.status == "phi"
                assert abs(s.r / c.r[k] - 1) < 1e-9, (order, theta[k], alpha[k], s.r, c.r[k])
                z_num = redshift_from_shot(s, c.phi[k], alpha[k], INC, prograde)
                assert abs(z_num / c.one_plus_z[k] - 1) < 1e-9
                checked[order] += 1
    assert checked[1] > 30 and checked[2] > 15
    # and rays that go outwards (looking away from the hole): direct crossings only
    theta = rng.uniform(0.6, 1.4, 6) + 0.5 * np.pi * rng.integers(0, 2, 6)
    alpha = rng.uniform(0, 2 * np.pi, 6)
    c = ref.disc_crossings(6.0, np.radians(60), theta, alpha, 1, r_out=1e9)
    for k in range(6):
        s = shoot(6.0, np.pi - theta[k], phi_end=c.phi[k])
        if np.isnan(c.r[k]):
            assert s.status in ("horizon", "escape")
        else:
            assert s.status == "phi" and abs(s.r / c.r[k] - 1) < 1e-9


def test_reference_flat_space_limit():
    """Far from the hole (all lengths scaled by lam) the crossing is the straight-line intersection and
    the shift the special-relativistic Doppler factor along the straight line; deviations ~ 1/lam."""
    rng = np.random.default_rng(6)
    theta = rng.uniform(0.002, 0.05, 200)
    alpha = rng.uniform(0, 2 * np.pi, 200)
    e_o, e_right, e_up, axis = ref.sky_vectors(INC)
    errs = []
    for lam in (1e4, 1e5, 1e6):
        r_obs = R_OBS * lam
        n = (-np.cos(theta)[:, None] * e_o + np.sin(theta)[:, None] * (
            np.cos(alpha)[:, None] * e_right + np.sin(alpha)[:, None] * e_up))
        t = -(r_obs * e_o @ axis) / (n @ axis)
        P = r_obs * e_o + t[:, None] * n
        r_line = np.linalg.norm(P, axis=1)
        c = ref.disc_crossings(r_obs, INC, theta, alpha, 1, r_out=np.inf)
        ok = np.isfinite(c.r)
        assert ok.mean() > 0.95 and np.all(ok == (t > 0))
        q = P / r_line[:, None]
        beta = 1 / np.sqrt(2 * (r_line - 1))
        v = np.cross(axis, q)
        z_line = (1 / np.sqrt(1 - beta**2) * (1 + beta * np.einsum("ij,ij->i", v, n))
                  * np.sqrt((1 - 1 / r_obs) / (1 - 1 / r_line)))
        e_r = np.max(np.abs(c.r[ok] / r_line[ok] - 1))
        e_z = np.max(np.abs(c.one_plus_z[ok] / z_line[ok] - 1) / beta[ok])  # relative to the effect
        assert e_r < 50 / lam and e_z < 50 / lam, (lam, e_r, e_z)
        errs.append(e_r)
    assert errs[2] < 0.2 * errs[0]  # converges


def test_reference_isoradials():
    """For rings r = const the emitter-observer solver gives each ring point's apparent angle; the
    per-pixel reference must cross the disc at that ring (both orders, two inclinations)."""
    rng = np.random.default_rng(7)
    alpha = rng.uniform(0, 2 * np.pi, 200)
    for inc in (INC, np.radians(30)):
        phi_c = ref.crossing_angle(inc, alpha)
        # geometry of the crossing line: the point at phi_c in the plane (e_o, s) lies in the disc
        e_o, e_right, e_up, axis = ref.sky_vectors(inc)
        sv = np.cos(alpha)[:, None] * e_right + np.sin(alpha)[:, None] * e_up
        assert np.max(np.abs((np.cos(phi_c)[:, None] * e_o + np.sin(phi_c)[:, None] * sv) @ axis)) < 1e-15
        for r in (3.01, 6.0, 14.0):
            for order, phi_pt in ((1, phi_c), (2, np.pi - phi_c)):
                xi = connect(R_OBS, r, phi_pt, order).xi
                c = ref.disc_crossings(R_OBS, inc, np.pi - xi, alpha, order)
                np.testing.assert_allclose(c.r, r, rtol=1e-9)
                assert np.all(c.hit)


# --------------------------------------------------------------------------------------------------
# Add-on per-vertex redshift vs per-pixel reference through the LUT mapping
# --------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def lut120():
    return build_lut(R_OBS, 2.9, 16.0, 256, 512)


@pytest.mark.parametrize("prograde", [True, False])
def test_vertex_redshift_matches_reference(lut120, prograde):
    Q, r_s, hole, camera = scene_vectors()
    rng = np.random.default_rng(8)
    n = 3000
    r = rng.uniform(3.0, 15.0, n)
    psi = rng.uniform(0, 2 * np.pi, n)
    pts, axis = disc_points(Q, r_s, hole, INC, r, psi)
    scene = mapping.Scene(camera, hole, r_s)
    for order in (1, 2):
        img = mapping.map_vertices(pts, scene, lut120, order)
        assert np.all(img.valid)
        z_vertex = td.vertex_redshift(pts, hole, camera, r_s, axis, img.xi, img.plane.e2, order, prograde)
        z_dir = td.vertex_redshift_from_direction(pts, hole, camera, r_s, axis, img.direction, prograde)
        np.testing.assert_allclose(z_dir, z_vertex, rtol=1e-12)
        n_sky = img.direction @ Q  # components along (e_o, e_right, e_up)
        theta = np.arccos(np.clip(-n_sky[:, 0], -1, 1))
        alpha = np.arctan2(n_sky[:, 2], n_sky[:, 1])
        c = ref.disc_crossings(R_OBS, INC, theta, alpha, order, prograde=prograde)
        np.testing.assert_allclose(c.r, r, rtol=2e-5)  # LUT interpolation of xi, amplified by dr/dxi
        np.testing.assert_allclose(z_vertex, c.one_plus_z, rtol=1e-6)
        f_vertex = td.observed_flux(r, z_vertex)
        np.testing.assert_allclose(f_vertex, c.flux, rtol=1e-4, atol=1e-12)
        # Doppler: the approaching side (left on the sky for prograde gas) is blueshifted and brighter
        left = alpha % (2 * np.pi)
        left = (left > 0.6 * np.pi) & (left < 1.4 * np.pi)
        right = (np.abs(np.angle(np.exp(1j * alpha))) < 0.4 * np.pi)
        blue, red = (left, right) if prograde else (right, left)
        assert np.median(z_vertex[blue]) < np.median(z_vertex[red]) - 0.15
        if order == 1:
            assert np.median(z_vertex[blue]) < 0.9 and np.median(z_vertex[red]) > 1.25
        # the ghost image is mirrored: its left side shows the right (near) side of the disc
        side = np.sign(np.cos(psi))
        assert np.mean(side[left] == (-1 if order == 1 else 1)) > 0.95


def test_vertex_redshift_invalid_inputs():
    Q, r_s, hole, camera = scene_vectors()
    pts, axis = disc_points(Q, r_s, hole, INC, np.array([5.0, 1.2]), np.array([0.3, 0.3]))
    e2 = mapping.plane_coordinates(pts, mapping.Scene(camera, hole, r_s)).e2
    z = td.vertex_redshift(pts, hole, camera, r_s, axis, np.array([np.nan, 3.0]), e2, 1)
    assert np.all(np.isnan(z))  # no image; inside the photon sphere no circular orbit
    with pytest.raises(ValueError):
        td.vertex_redshift(pts, hole, camera, r_s, axis, np.array([3.0, 3.0]), e2, 3)


# --------------------------------------------------------------------------------------------------
# Colours
# --------------------------------------------------------------------------------------------------
def planckian_kim(T):
    """Planckian locus (CIE 1931 xy), cubic-spline fit of Kim et al. (2002), 1667-25000 K."""
    T = np.asarray(T, float)
    x = np.where(T <= 4000, -0.2661239e9 / T**3 - 0.2343589e6 / T**2 + 0.8776956e3 / T + 0.179910,
                 -3.0258469e9 / T**3 + 2.1070379e6 / T**2 + 0.2226347e3 / T + 0.240390)
    y = np.where(T <= 2222, -1.1063814 * x**3 - 1.34811020 * x**2 + 2.18555832 * x - 0.20219683,
                 np.where(T <= 4000, -0.9549476 * x**3 - 1.37418593 * x**2 + 2.09137015 * x - 0.16748867,
                          3.0817580 * x**3 - 5.87338670 * x**2 + 3.75112997 * x - 0.37001483))
    return x, y


def test_blackbody_chromaticity_and_rgb():
    T = np.geomspace(1667, 25000, 40)
    xyz = td.blackbody_xyz(T)
    x, y = (xyz[:, :2] / xyz.sum(axis=1)[:, None]).T
    kx, ky = planckian_kim(T)
    tol = np.where(T < 4000, 4e-3, 1.5e-3)  # the CMF fit is least accurate in the red
    assert np.all(np.abs(x - kx) < tol) and np.all(np.abs(y - ky) < tol)
    # illuminant A (2856 K, CIE: x = 0.44757, y = 0.40745)
    a = td.blackbody_xyz(2856.0)
    assert abs(a[0] / a.sum() - 0.44757) < 2e-3 and abs(a[1] / a.sum() - 0.40745) < 2e-3
    # D65 white maps to R = G = B
    w = np.array([0.3127 / 0.3290, 1.0, (1 - 0.3127 - 0.3290) / 0.3290])
    np.testing.assert_allclose(td.XYZ_TO_LINEAR_SRGB @ w, 1.0, atol=5e-4)
    # table vs direct quadrature; luminance 1 where in gamut; hotter is bluer
    Tr = np.exp(np.random.default_rng(9).uniform(np.log(2500), np.log(9e5), 300))
    direct = td.blackbody_xyz(Tr) @ td.XYZ_TO_LINEAR_SRGB.T
    rgb = td.blackbody_rgb(Tr)
    np.testing.assert_allclose(rgb, direct, atol=2e-5)
    lum = rgb @ np.array([0.2126729, 0.7151522, 0.0721750])
    np.testing.assert_allclose(lum, 1.0, atol=1e-4)
    s = np.sort(Tr)
    ratio = td.blackbody_rgb(s)[:, 2] / td.blackbody_rgb(s)[:, 0]
    assert np.all(np.diff(ratio) > 0)
    assert np.all(td.blackbody_rgb(800.0) >= 0) and td.blackbody_rgb(800.0)[2] == 0.0
    np.testing.assert_allclose(td.blackbody_rgb(5000.0, "max").max(), 1.0)
    assert np.all(np.isnan(td.blackbody_rgb([np.nan, 0.0, -5.0])))


def test_disc_colour_modes():
    r = np.array([2.5, 3.0, 4.0, 4.7754641, 8.0, 15.0, 9.0])
    z = np.array([0.9, 1.0, 0.7, 1.1, 1.3, 1.0, np.nan])
    f_obs = td.observed_flux(r, z)
    _, f_pk = td.page_thorne_peak()
    grey = td.disc_colour(r, z, "bolometric", exposure=2.0)
    np.testing.assert_allclose(grey[:, 0], 2.0 * f_obs / f_pk)
    assert np.all(grey[:, 0] == grey[:, 2]) or np.isnan(grey[-1, 0])
    # Stefan-Boltzmann: (T_obs / t_peak)^4 = F_obs / F_peak
    t_obs = td.observed_temperature(r, z, t_peak=8000.0)
    np.testing.assert_allclose((t_obs[:-1] / 8000.0) ** 4, f_obs[:-1] / f_pk, rtol=1e-12)
    assert abs(td.disc_temperature(td.page_thorne_peak()[0], 8000.0) - 8000.0) < 1e-6
    bb = td.disc_colour(r, z, "blackbody", t_peak=2e4)
    lum = bb @ np.array([0.2126729, 0.7151522, 0.0721750])
    np.testing.assert_allclose(lum[2:6], f_obs[2:6] / f_pk, rtol=1e-4)
    np.testing.assert_array_equal(bb[:2], 0.0)  # inside the ISCO: black
    assert np.all(np.isnan(bb[-1])) and np.all(np.isnan(grey[-1]))
    with pytest.raises(ValueError):
        td.disc_colour(r, z, "false")


def test_disc_image_smoke():
    """Seed 002's figure 4 set-up, small: the direct image is brighter on the approaching (left)
    side, the ghost image is there, and nothing is inside the shadow."""
    img, parts = ref.disc_image(width=96, height=80)
    assert img.shape == (80, 96) and np.all(img >= 0)
    assert img[:, :48].sum() > 1.5 * img[:, 48:].sum()
    assert parts[2].hit.sum() > 20
    theta, _ = ref.pixel_angles(96, 80, np.radians(6.0))
    th_c = np.arcsin(np.sqrt(6.75 * (1 - 1 / R_OBS)) / R_OBS)
    _, alpha = ref.pixel_angles(96, 80, np.radians(6.0))
    upper = (theta < 0.95 * th_c) & (alpha > 0.25 * np.pi) & (alpha < 0.75 * np.pi)
    assert upper.sum() > 10 and np.all(img[upper] == 0)  # the near side covers the lower half
