"""Reference ray tracer, rasterizer and image metrics (grlens_addon.core.raytrace / rasterize /
image_metrics; numpy only).

Units: world positions, r_s and light travel times in Blender units (BU); lutgen in r_s and r_s/c.
Independent checks: an ordinary pinhole ray-triangle intersection (flat-space limit), eq. (14)
(shadow), lutgen.connect (the closed-form emitter-observer solver), lutgen.reference's DOP853
integration of the geodesic equations (the curve u(Phi), windings, travel time).
"""
import importlib.util
import math
import os

import numpy as np
import pytest

from grlens_addon.core import image_metrics, mapping, pipeline, rasterize, raytrace
from lutgen import build_lut, connect, shadow_half_angle
from lutgen import reference as numeric

HOLE = np.zeros(3)


def _moller_trumbore_all(o, dirs, pos, tris):
    """Brute force: nearest straight-ray hit (face, t, u, v) of every ray against every triangle."""
    a, b, c = pos[tris[:, 0]], pos[tris[:, 1]], pos[tris[:, 2]]
    e1, e2 = b - a, c - a
    p = np.cross(dirs[:, None, :], e2[None])
    det = np.einsum("ntk,tk->nt", p, e1)
    tv = o - a
    u = np.einsum("ntk,tk->nt", p, tv) / det
    q = np.cross(tv, e1)
    v = np.einsum("nk,tk->nt", dirs, q) / det
    t = np.einsum("tk,tk->t", e2, q)[None] / det
    t = np.where((u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0), t, np.inf)
    f = np.argmin(t, axis=1)
    rows = np.arange(len(dirs))
    return f, t[rows, f], u[rows, f], v[rows, f]


def _random_triangles(rng, n, spread=3.0, size=0.8):
    centres = rng.uniform(-spread, spread, (n, 3))
    pts = (centres[:, None, :] + rng.normal(size=(n, 3, 3)) * size).reshape(-1, 3)
    return pts, np.arange(3 * n).reshape(-1, 3)


def _bench_accuracy():
    path = os.path.join(os.path.dirname(__file__), "..", "benchmarks", "bench_accuracy.py")
    spec = importlib.util.spec_from_file_location("bench_accuracy", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_camera_conventions():
    """Pixel centres project back to (column + 0.5, row + 0.5); row 0 is the top (+Z up for look_at);
    a 4x4 matrix_world gives the same camera."""
    cam = raytrace.Camera.look_at([5.0, -2.0, 1.0], [0, 0, 0], math.radians(30), 8, 6)
    d = cam.pixel_directions()
    col, row, depth = cam.project(cam.position + 3.0 * d.reshape(-1, 3))
    np.testing.assert_allclose(col.reshape(6, 8), np.arange(8)[None, :] + 0.5 + np.zeros((6, 1)), atol=1e-12)
    np.testing.assert_allclose(row.reshape(6, 8), np.arange(6)[:, None] + 0.5 + np.zeros((1, 8)), atol=1e-12)
    assert np.all(depth > 0) and d[0, 4, 2] > d[-1, 4, 2]
    fwd = -cam.rotation[:, 2]
    np.testing.assert_allclose(fwd, -cam.position / np.linalg.norm(cam.position), atol=1e-12)
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = cam.rotation, cam.position
    same = raytrace.Camera.from_matrix_world(m, cam.fov_y, 8, 6)
    np.testing.assert_allclose(same.pixel_directions(), d, atol=1e-15)
    # the vertical field of view spans the image's height
    top, bottom = d[0, 4], d[-1, 4]
    assert math.acos(top @ bottom) == pytest.approx(cam.fov_y * 5 / 6, rel=0.02)


# --------------------------------------------------------------------------------------------------
# The curve itself
# --------------------------------------------------------------------------------------------------
def test_curve_matches_numeric_integration():
    """u(Phi) and the travel time of single rays (escaping, plunging, winding near the critical angle,
    leaving away from the hole) agree with the DOP853 integration of the geodesic equations."""
    r_obs = 20.0
    xi_c = math.pi - float(shadow_half_angle(r_obs))
    # near the photon sphere rays diverge like e^Phi, which amplifies the integrator's errors (rtol 1e-12)
    cases = [(0.4, 1.0, 1e-10), (1.6, 1.5, 1e-10), (2.9, 2.5, 1e-10), (xi_c - 1e-4, 9.0, 1e-8),
             (xi_c + 1e-4, 7.0, 1e-8), (3.1, 0.05, 1e-10)]
    for xi, phi, tol in cases:
        rays = raytrace.Rays([r_obs, 0, 0], [[math.cos(xi), math.sin(xi), 0.0]], HOLE, 1.0)
        phi = min(phi, 0.97 * float(rays.phi_end[0]))
        shot = numeric.shoot(r_obs, xi, phi_end=phi)
        assert shot.status == "phi"
        u, _ = rays.u(np.array([0]), np.array([phi]))
        t = rays.travel_time(np.array([0]), np.array([phi]), u)
        assert abs(u[0] * shot.r - 1.0) < tol, (xi, phi)
        assert abs(t[0] / abs(shot.t) - 1.0) < tol, (xi, phi)


def test_shadow_edge():
    """Rays closer to the hole's direction than shadow_half_angle (eq. 14) fall in, the others escape;
    along each ray u = r_s/r ends at 1 (horizon) or 0 (infinity)."""
    r_obs = 12.0
    cam = np.array([0.0, -r_obs * 2.0, 0.0])  # r_s = 2 BU
    crit = float(shadow_half_angle(r_obs))
    alpha = crit * np.array([0.2, 0.9, 1 - 1e-6, 1 + 1e-6, 1.1, 2.0])
    ang = np.linspace(0, 2 * np.pi, 7)[:-1]  # around the hole direction
    a, g = np.meshgrid(alpha, ang, indexing="ij")
    dirs = np.stack([np.sin(a) * np.cos(g), np.cos(a), np.sin(a) * np.sin(g)], axis=-1).reshape(-1, 3)
    empty = raytrace.TriangleScene(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    buf = raytrace.trace_rays(empty, cam, dirs, HOLE, 2.0)
    inside = (a < crit).ravel()
    assert np.array_equal(buf.fell, inside)
    assert not buf.hit.any()
    rays = raytrace.Rays(cam, dirs, HOLE, 2.0)
    u_end, _ = rays.u(np.arange(len(dirs)), rays.phi_end)
    np.testing.assert_allclose(u_end[inside], 1.0, atol=1e-9)
    np.testing.assert_allclose(u_end[~inside], 0.0, atol=1e-9)


# --------------------------------------------------------------------------------------------------
# Tracing
# --------------------------------------------------------------------------------------------------
def test_flat_space_limit():
    """With a tiny hole (r_s = 1e-6 BU, the camera ~1e7 r_s away) the reference is an ordinary pinhole
    ray caster: same pixels, faces, barycentric coordinates and distances."""
    rng = np.random.default_rng(3)
    pts, tris = _random_triangles(rng, 60)
    scene = raytrace.TriangleScene(pts, tris, object_id=np.arange(60) % 3)
    cam = raytrace.Camera.look_at([12.0, 1.0, 2.0], [0, 0, 0], math.radians(40), 64, 48)
    buf = raytrace.trace(scene, cam, np.array([-5.0, 7.0, 1.0]), 1e-6)
    dirs = cam.pixel_directions().reshape(-1, 3)
    f, t, u, v = _moller_trumbore_all(cam.position, dirs, pts, tris)
    hit = np.isfinite(t)
    assert hit.sum() > 500
    assert np.array_equal(buf.hit.ravel(), hit)
    assert np.array_equal(buf.face.ravel()[hit], f[hit])
    assert np.array_equal(buf.object_id.ravel()[hit], f[hit] % 3)
    assert np.all(buf.order.ravel()[hit] == 1)
    np.testing.assert_allclose(buf.bary.reshape(-1, 3)[hit][:, 1:], np.stack([u, v], 1)[hit], atol=1e-4)
    np.testing.assert_allclose(buf.light_time.ravel()[hit], t[hit], atol=1e-4)
    assert not buf.fell.any()


def test_triangle_behind_hole_two_images():
    """A triangle behind the hole, above the axis: an order-1 image above the hole and a smaller
    order-2 image below it, between the shadow's edge and the primary image's distance from the hole."""
    r_s = 2.0
    cam_pos = np.array([40.0, 0, 0])
    tri = np.array([[-12.0, -1.5, 2.0], [-12.0, 1.5, 2.0], [-12.0, 0.0, 5.0]])
    scene = raytrace.TriangleScene(tri, [[0, 1, 2]])
    cam = raytrace.Camera.look_at(cam_pos, HOLE, math.radians(30), 96, 96)
    buf = raytrace.trace(scene, cam, HOLE, r_s)
    rows = np.arange(cam.height)[:, None] * np.ones(cam.width)
    o1, o2 = buf.hit & (buf.order == 1), buf.hit & (buf.order == 2)
    assert o1.sum() > 20 and 0 < o2.sum() < o1.sum()
    centre = cam.height / 2
    assert np.all(rows[o1] < centre) and np.all(rows[o2] > centre)
    assert not (buf.hit & (buf.order >= 3)).any()
    # light bends towards the hole, so the primary image appears farther out than in flat space
    flat = raytrace.trace(scene, cam, np.array([0.0, 0.0, -100.0]), 1e-4)  # r_obs ~ 1e6
    assert flat.hit.any() and not (flat.order == 2).any()
    assert np.min(rows[o1]) < np.min(rows[flat.hit]) - 5
    # the secondary image hugs the shadow's edge (eq. 14)
    ang = np.arccos(np.clip(-cam.pixel_directions() @ (cam_pos / np.linalg.norm(cam_pos)), -1, 1))
    crit = float(shadow_half_angle(20.0))
    assert np.all((ang[o2] > crit) & (ang[o2] < 1.5 * crit))
    assert np.max(ang[o2]) < np.min(ang[o1])
    # light travel time: longer for the second-order image, and above the Euclidean distance
    assert np.nanmin(buf.light_time[o2]) > np.nanmax(buf.light_time[o1])
    assert np.nanmin(buf.light_time[o1]) > np.linalg.norm(tri.mean(0) - cam_pos) - 3.0


@pytest.mark.parametrize("order", [1, 2])
def test_consistent_with_connect(order):
    """Rays traced in the direction lutgen.connect finds for random points (orders 1 and 2, inside
    the photon sphere too, and beyond the camera) hit those points at lutgen's light travel time."""
    r_s = 1.5
    cam = np.array([0.0, 0.0, 15.0 * r_s])  # r_obs = 15
    r_obs = 15.0
    rng = np.random.default_rng(11 + order)
    n = 60
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    r = np.concatenate([rng.uniform(1.1, 1.5, 10), rng.uniform(1.5, 30.0, n - 10)])
    pts = d * (r * r_s)[:, None]
    e1 = cam / np.linalg.norm(cam)
    along = pts @ e1
    perp = pts - along[:, None] * e1
    e2 = perp / np.linalg.norm(perp, axis=1)[:, None]
    phi = np.arctan2(np.linalg.norm(perp, axis=1), along)
    c = connect(r_obs, r, phi, order)
    sign = 1.0 if order == 1 else -1.0
    dirs = np.cos(c.xi)[:, None] * e1 + (sign * np.sin(c.xi))[:, None] * e2
    # a tiny triangle around each point, facing the arriving ray
    t3 = c.ux[:, None] * e1 + c.uy[:, None] * e2
    t3 /= np.linalg.norm(t3, axis=1)[:, None]
    a = np.cross(t3, e1 + 0.3 * e2)
    a /= np.linalg.norm(a, axis=1)[:, None]
    b = np.cross(t3, a)
    s = 1e-3 * r_s
    corners = np.stack([pts + s * a, pts + s * (-0.5 * a + 0.866 * b), pts + s * (-0.5 * a - 0.866 * b)], axis=1)
    scene = raytrace.TriangleScene(corners.reshape(-1, 3), np.arange(3 * n).reshape(-1, 3))
    buf = raytrace.trace_rays(scene, cam, dirs, HOLE, r_s)
    assert np.all(buf.hit), np.flatnonzero(~buf.hit)
    assert np.array_equal(buf.face, np.arange(n))
    assert np.all(buf.order == order)
    np.testing.assert_allclose(buf.point, pts, atol=1e-8 * r_s)
    np.testing.assert_allclose(buf.light_time, c.dt * r_s, rtol=1e-9)
    np.testing.assert_allclose(buf.phi, phi if order == 1 else 2 * np.pi - phi, atol=1e-9)


def test_winding_ray_higher_order():
    """A ray 1e-6 rad outside the shadow winds around the photon sphere: a small triangle placed on it
    (by the DOP853 integrator) at swept angle 3.6 pi is hit there, as an order-4 image, at the
    integrator's light travel time."""
    r_obs = 20.0
    xi = math.pi - float(shadow_half_angle(r_obs)) - 1e-6
    phi = 3.6 * math.pi
    shot = numeric.shoot(r_obs, xi, phi_end=phi)
    p = shot.r * np.array([math.cos(phi), math.sin(phi), 0.0])
    a = np.array([0.0, 0.0, 1.0])
    b = np.array([-math.sin(phi), math.cos(phi), 0.0])  # tangential: the winding ray crosses it
    s = 0.02
    corners = np.array([p - s * a - s * b, p + s * a - s * b, p + 2 * s * b])
    scene = raytrace.TriangleScene(corners, [[0, 1, 2]])
    buf = raytrace.trace_rays(scene, [r_obs, 0, 0], [[math.cos(xi), math.sin(xi), 0.0]], HOLE, 1.0)
    assert buf.hit[0] and buf.order[0] == 4
    assert abs(buf.phi[0] - phi) < 1e-6
    assert np.linalg.norm(buf.point[0] - p) < 1e-6
    assert abs(buf.light_time[0] / abs(shot.t) - 1.0) < 1e-7


# --------------------------------------------------------------------------------------------------
# Rasterizer and metrics
# --------------------------------------------------------------------------------------------------
def test_rasterizer_matches_reference_in_flat_space():
    """The rasterizer of the source triangles themselves (flat space: images = sources) gives the
    reference's pixels, faces, UVs and (to the Shapiro delay) light travel times."""
    rng = np.random.default_rng(5)
    pts, tris = _random_triangles(rng, 40)
    uv = rng.uniform(0, 1, (len(tris), 3, 2))
    cam = raytrace.Camera.look_at([10.0, -3.0, 2.0], [0, 0, 0], math.radians(45), 80, 60)
    ref = raytrace.trace(raytrace.TriangleScene(pts, tris, uv), cam, np.array([-9.0, 4.0, 0.0]), 1e-6)
    mesh = rasterize.RasterMesh(pts, tris, np.linalg.norm(pts - cam.position, axis=1), order=1,
                                corner_uv=uv, source_position=pts)
    ras = rasterize.rasterize([mesh], cam)
    assert np.array_equal(ras.hit, ref.hit) and ref.hit.sum() > 500
    h = ref.hit
    assert np.array_equal(ras.face[h], ref.face[h])
    np.testing.assert_allclose(ras.uv[h], ref.uv[h], atol=1e-4)
    np.testing.assert_allclose(ras.depth[h], ref.light_time[h], atol=1e-4)
    np.testing.assert_allclose(ras.point[h], ref.point[h], atol=1e-4)
    # per-vertex distances interpolated linearly over a face are a chord of the true distance
    assert np.all(ras.light_time[h] >= ras.depth[h] - 1e-9)
    m = image_metrics.compare(ref, ras)
    assert m["orders"]["all"]["mismatch"] == 0
    assert m["orders"]["all"]["uv_px"]["max"] < 1e-2


def _synthetic(shift=0):
    """A 40x60 buffer with a rectangle (rows 10..19, columns 10..29, shifted right by ``shift``),
    uv = pixel centre / size, light time 10 + column of the unshifted content, point = (column + 0.5,
    row + 0.5, 0) of the unshifted content (its true pixel position under _identity_pixels)."""
    H, W = 40, 60
    b = raytrace.PixelBuffers.empty((H, W))
    rows, cols = np.mgrid[0:H, 0:W]
    src_col = cols - shift
    inside = (rows >= 10) & (rows < 20) & (src_col >= 10) & (src_col < 30)
    b.hit[inside] = True
    b.object_id[inside] = 3
    b.order[inside] = 1
    b.uv[inside] = np.stack([(src_col + 0.5) / W, (rows + 0.5) / H], -1)[inside]
    b.light_time[inside] = (10.0 + src_col)[inside]
    b.point[inside] = np.stack([src_col + 0.5, rows + 0.5, np.zeros((H, W))], -1)[inside]
    return b


def _identity_pixels(points, order):
    """image_pixels for _synthetic: a point (x, y, z) appears at column x, row y."""
    return points[:, 0], points[:, 1]


def test_metrics_screen_error():
    """screen_px: the distance from each matched pixel's centre to where the point the test pixel shows
    truly appears: 0 for the reference itself, exactly the shift for shifted content."""
    ref = _synthetic()
    m = image_metrics.compare(ref, _synthetic(), image_pixels=_identity_pixels)["orders"]
    assert m[1]["screen_px"]["max"] == 0 and m[1]["screen_px_n"] == 200 and m["all"]["screen_px_n"] == 200
    assert np.isnan(m[2]["screen_px"]["p50"]) and m[2]["screen_px_n"] == 0
    m = image_metrics.compare(ref, _synthetic(shift=2), image_pixels=_identity_pixels)["orders"]["all"]
    assert m["screen_px_n"] == m["matched"] == 180
    for k in ("p50", "p99", "max"):
        assert m["screen_px"][k] == pytest.approx(2.0, rel=1e-12)
    assert "screen_px" not in image_metrics.compare(ref, ref)["orders"][1]
    rows = image_metrics.markdown_rows(image_metrics.compare(ref, _synthetic(shift=2), image_pixels=_identity_pixels))
    assert len(rows) == 3 and rows[0].count("|") == image_metrics.MARKDOWN_HEADER[0].count("|")
    assert "| 2.000 | 2.000 | 2.00 |" in rows[0]
    # with uv_points the texture point drawn is imaged, not the surface point: here the geometry is
    # right (points of the reference) but the texture is shifted by 3 columns
    test = _synthetic()
    test.uv[test.hit] += [3.0 / 60, 0.0]
    uv_points = lambda uv: np.stack([uv[:, 0] * 60, uv[:, 1] * 40, np.zeros(len(uv))], -1)  # noqa: E731
    geo = image_metrics.compare(ref, test, image_pixels=_identity_pixels)["orders"]["all"]["screen_px"]
    tex = image_metrics.compare(ref, test, image_pixels=_identity_pixels, uv_points=uv_points)["orders"]["all"]
    assert geo["max"] == 0 and tex["screen_px"]["p50"] == pytest.approx(3.0, rel=1e-9)


def test_uv_surface_points():
    """image_metrics.uv_surface_points inverts the UV mapping of a mesh: points on its triangles come
    back from their UVs (also one period away in a wrapped coordinate); UVs on no triangle are NaN."""
    rng = np.random.default_rng(4)
    pts, tris = _random_triangles(rng, 20)
    corner_uv = np.zeros((20, 3, 2))  # each triangle its own UV triangle in a 5x4 atlas
    for k in range(20):
        o = np.array([k % 5, k // 5]) * [0.2, 0.25]
        corner_uv[k] = o + rng.uniform(0.01, 0.19, (3, 2)) * [1, 1.2]
    t = rng.integers(0, 20, 500)
    lam = rng.dirichlet([1, 1, 1], 500)
    uv = np.einsum("nk,nkx->nx", lam, corner_uv[t])
    want = np.einsum("nk,nkx->nx", lam, pts[tris[t]])
    np.testing.assert_allclose(image_metrics.uv_surface_points(uv, pts, tris, corner_uv, chunk=64), want, atol=1e-9)
    shifted = image_metrics.uv_surface_points(uv + [1.0, 0.0], pts, tris, corner_uv, wrap_uv=(True, False))
    np.testing.assert_allclose(shifted, want, atol=1e-9)
    assert np.isnan(image_metrics.uv_surface_points(uv + [1.0, 0.0], pts, tris, corner_uv)).all()
    assert np.isnan(image_metrics.uv_surface_points(np.array([[5.0, 5.0], [np.nan, 0.1]]), pts, tris, corner_uv)).all()


@pytest.mark.parametrize("angle", [135, 170])
def test_image_pixels_consistent_with_trace(angle):
    """raytrace.image_pixels (lutgen.connect) puts the world point that the ray tracer finds at each
    pixel back on that pixel's centre, to 1e-6 px, for both orders: the closed-form orbits of the
    tracer and the emitter-observer solver agree, also beside the Einstein ring (170 deg), where the
    second-order image of the sphere is squeezed to a pixel across."""
    bench = _bench_accuracy()
    cam = bench.camera(96, 54)
    _, scene = bench.sphere_scene(angle)
    ref = raytrace.trace(scene, cam, HOLE, 1.0)
    rows, cols = np.mgrid[0:54, 0:96]
    for order in (1, 2):
        m = ref.hit & (ref.order == order)
        assert m.sum() >= (5 if order == 2 else 50)
        col, row = raytrace.image_pixels(ref.point[m], cam, HOLE, 1.0, order)
        np.testing.assert_allclose(col, cols[m] + 0.5, atol=1e-6)
        np.testing.assert_allclose(row, rows[m] + 0.5, atol=1e-6)
        # the same through the UVs the tracer found (the sphere's spherical UVs, U wrapped)
        p = image_metrics.uv_surface_points(ref.uv[m], scene.positions, scene.tris, scene.corner_uv, (True, False))
        col, row = raytrace.image_pixels(p, cam, HOLE, 1.0, order)
        np.testing.assert_allclose(col, cols[m] + 0.5, atol=1e-6)
        np.testing.assert_allclose(row, rows[m] + 0.5, atol=1e-6)
    # no image on the axis, none behind the camera
    col, row = raytrace.image_pixels(np.array([[-5.0, 0, 0], [40.0, 0, 1.0], [0, 0, 0.5], [0, 0, 2.0]]),
                                     cam, HOLE, 1.0, 1)
    assert np.isnan(col[:3]).all() and np.isnan(row[:3]).all()  # axis, behind the camera, horizon
    assert np.isfinite(col[3]) and np.isfinite(row[3])


def test_metrics_identical_and_shifted():
    ref = _synthetic()
    same = image_metrics.compare(ref, _synthetic(), texture_size=512)
    for o in (1, "all"):
        m = same["orders"][o]
        assert m["mismatch"] == 0 and m["covered_ref"] == 200 and m["matched"] == 200
        assert m["uv_px"]["max"] == 0 and m["uv_texel"]["max"] == 0 and m["lt_rel"]["max"] == 0
    assert same["orders"][2]["covered_ref"] == 0
    m = image_metrics.compare(ref, _synthetic(shift=1), texture_size=512)["orders"][1]
    assert m["mismatch"] == 20 and m["mismatch_frac"] == pytest.approx(0.1)
    assert m["matched"] == 190
    for k in ("p50", "p99", "max"):
        assert m["uv_px"][k] == pytest.approx(1.0, rel=1e-9)
        assert m["uv_texel"][k] == pytest.approx(512 / 60, rel=1e-9)
    lt = np.repeat(1.0 / (10.0 + np.arange(11, 30)), 10)  # matched columns 11..29, ref time 10 + col
    assert m["lt_rel"]["p50"] == pytest.approx(np.percentile(lt, 50))
    assert m["lt_rel"]["max"] == pytest.approx(1.0 / 21.0)
    # a different object in the same place counts as a mismatch of every pixel
    other = _synthetic()
    other.object_id[other.hit] = 4
    assert image_metrics.compare(ref, other)["orders"][1]["mismatch"] == 200


def test_metrics_other_surface():
    """Matched pixels whose world points lie farther apart than ``other_surface`` (BU) are counted:
    the same object in the same order, but another part of it."""
    ref, test = _synthetic(), _synthetic()
    ref.point[ref.hit] = (0.0, 0.0, 0.0)
    test.point[test.hit] = (0.0, 0.0, 0.0)
    far = test.hit & (np.arange(60)[None, :] < 15)  # columns 10..14 of the rectangle: 50 pixels
    test.point[far] = (0.0, 0.0, 0.3)
    m = image_metrics.compare(ref, test, other_surface=0.2)
    assert m["orders"][1]["other_surface"] == m["orders"]["all"]["other_surface"] == 50
    assert image_metrics.compare(ref, test, other_surface=0.5)["orders"][1]["other_surface"] == 0
    assert "other_surface" not in image_metrics.compare(ref, test)["orders"][1]


def test_debug_png(tmp_path):
    ref, test = _synthetic(), _synthetic(shift=2)
    path = tmp_path / "dbg.png"
    image_metrics.save_png(path, {"ref": ref, "test": test})
    assert path.stat().st_size > 1000


# --------------------------------------------------------------------------------------------------
# The polygon method against the reference
# --------------------------------------------------------------------------------------------------
def _exact_pixels(cam):
    return lambda points, order: raytrace.image_pixels(points, cam, HOLE, 1.0, order)


def _uv_points(src):
    return lambda uv: image_metrics.uv_surface_points(uv, src.positions, src.tris, src.corner_uv, (True, False))


@pytest.fixture(scope="module")
def lut():
    return build_lut(20.0, 1.05, 40.0, 256, 512)


@pytest.mark.parametrize("angle", [45, 90, 135])
def test_sphere_polygon_method_vs_reference(lut, angle):
    """The paper's sphere (radius 0.5 r_s on r = 3 r_s, observer at 20 r_s, fov 19 deg) at 96x54: the
    rasterized image meshes of pipeline.build_images agree with the reference ray tracer."""
    bench = _bench_accuracy()
    cam = bench.camera(96, 54)
    src, scene = bench.sphere_scene(angle)
    ref = raytrace.trace(scene, cam, HOLE, 1.0)
    settings = bench.make_settings(cam)
    images = pipeline.build_images(src, mapping.Scene(cam.position, HOLE, 1.0), lut, settings,
                                   frustum_planes=cam.frustum_planes())
    poly = rasterize.rasterize(rasterize.from_images(images), cam)
    m = image_metrics.compare(ref, poly, wrap_uv=(True, False), image_pixels=_exact_pixels(cam),
                              uv_points=_uv_points(src))
    a = m["orders"]["all"]
    print(f"\nsphere {angle} deg 96x54: covered {a['covered_ref']} / {a['covered_test']}, mismatch "
          f"{a['mismatch']} ({100 * a['mismatch_frac']:.2f}%), UV p99 {a['uv_px']['p99']:.3f} px, "
          f"max {a['uv_px']['max']:.3f} px, c*dt p99 {a['lt_rel']['p99']:.1e}; order 2: "
          f"{m['orders'][2]['covered_ref']} px, mismatch {m['orders'][2]['mismatch']}")
    assert a["covered_ref"] > 50 and m["orders"][2]["covered_ref"] > 0
    assert a["mismatch_frac"] < 0.03
    assert a["uv_px"]["p99"] < 0.5 and a["screen_px"]["p99"] < 0.5
    assert a["lt_rel"]["p99"] < 2e-3


def _ring_view(lut, angle, size=(320, 180)):
    """The benchmark sphere at ``angle`` deg of its orbit seen at ``size`` pixels: (camera, source
    mesh, reference buffers, render) with render() rasterizing the pipeline's images as the add-on
    builds them (called again after a test changes a setting)."""
    bench = _bench_accuracy()
    cam = bench.camera(*size)
    src, scene = bench.sphere_scene(angle)
    ref = raytrace.trace(scene, cam, HOLE, 1.0)

    def render():
        images = pipeline.build_images(src, mapping.Scene(cam.position, HOLE, 1.0), lut, bench.make_settings(cam),
                                       frustum_planes=cam.frustum_planes())
        return rasterize.rasterize(rasterize.from_images(images), cam)

    return cam, src, ref, render


def test_orbit_summary_lists_the_misses_or_the_closest():
    """bench_accuracy.orbit_summary: the counts per target, the angles that miss one (worst mismatch
    first), or, when none does, the five closest to a target; the whole sequence's times."""
    bench = _bench_accuracy()
    rows = [(a, 0.001, 0.1, 200.0, 5.0) for a in range(0, 360, 30)]
    rows[3] = (90, 0.006, 0.1, 200.0, 5.0)
    rows[5] = (150, 0.002, 0.1, 90.0, 30.0)
    text = "\n".join(bench.orbit_summary(30, rows))
    assert "the mismatch target is met at 11, the UV target at 12, the speed-up target at 11, all three at 10" in text
    assert text.index("| 90 |") < text.index("| 150 |") and text.count("\n| ") == 3  # header + 2 rows
    rows[3], rows[5] = (90, 0.004, 0.1, 200.0, 5.0), (150, 0.002, 0.45, 105.0, 30.0)
    text = "\n".join(bench.orbit_summary(30, rows))
    assert "all three at 12" in text and "No angle misses one" in text and text.count("\n| ") == 6
    assert text.index("| 150 |") < text.index("| 90 |")  # 0.45 px is closer to its target than 0.4%
    # the whole sequence: 11 frames of 5 ms at 200x (1 s each) and one of 30 ms at 105x (3.15 s)
    assert "The whole sequence (12 frames): the reference took 14 s, build_images 0.09 s, 166 times less" in text


def test_benchmark_triangle_is_the_sample_scene_s_in_units_of_r_s():
    """bench_accuracy.triangle_scene: the sample scene's triangle (r_s = 2 BU, legs of 3 BU from p2 to
    p1) scaled to r_s = 1, with its UVs; the camera at the same 20 r_s and field of view."""
    bench = _bench_accuracy()
    src, tri_scene = bench.triangle_scene(0.0)
    legs = np.array([[0.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 3.0]])
    assert np.allclose(2.0 * src.positions, np.array([-5.0, 0.5, -0.5]) + legs)
    assert np.allclose(2.0 * bench.triangle_scene(1.0)[0].positions, np.array([-5.0, 3.0, -0.5]) + legs)
    assert np.array_equal(src.corner_uv[0], [[0, 0], [1, 0], [0, 1]]) and np.array_equal(tri_scene.tris, src.tris)
    cam = bench.triangle_camera(64, 36)
    assert np.allclose(cam.position, [20.0, 0.0, 0.0]) and np.isclose(cam.fov_y, math.radians(20.0))


@pytest.mark.parametrize("angle, bound", [(0, 0.05), (170, 0.008), (180, 0.006)])
def test_sphere_ring_views_vs_reference(lut, angle, bound):
    """The paper's sphere next to and on the observer-hole axis at 320x180, where the second-order
    rings are a third of a pixel wide: coverage mismatch within ``bound`` of the covered pixels
    (before the Einstein-ring patches and the silhouette tolerance: 8.0%, 1.1%, 1.6%). Beside the
    axis (170 deg) the near side has no gaps the far side shows through: under 1% of the pixels
    show a point of the sphere more than a quarter of its radius from the reference's (6.7% before
    the first split next to the axis, pipeline._presplit_levels)."""
    cam, src, ref, render = _ring_view(lut, angle)
    a = image_metrics.compare(ref, render(), wrap_uv=(True, False), other_surface=0.125,
                              image_pixels=_exact_pixels(cam), uv_points=_uv_points(src))["orders"]["all"]
    print(f"\nsphere {angle} deg 320x180: mismatch {a['mismatch']} of {a['covered_ref']} "
          f"({100 * a['mismatch_frac']:.2f}%), other surface {a['other_surface']} of {a['matched']}, "
          f"screen error p99 {a['screen_px']['p99']:.3f} px (via J {a['uv_px']['p99']:.3f})")
    assert a["covered_ref"] > 500
    assert a["mismatch_frac"] < bound
    assert a["screen_px"]["p99"] < 0.5
    if angle == 170:
        assert a["other_surface"] < 0.01 * a["matched"]


@pytest.mark.parametrize("angle", [355, 5])
def test_second_order_ring_edge_next_to_a_patch(lut, angle):
    """The sphere grazing the axis in front of the hole, at 320x180: its second-order ring, less than a
    pixel wide, is a thin image (its whole budget scaled by budget.THIN_FACTOR) and its edge next to
    the axis patch gets the coverage tolerance (budget.RING_EDGE_REACH): at most 0.2% of the covered
    pixels differ. (Without those rules 0.57% and 0.69%: benchmarks/bench_budget.py --rules.)"""
    _, _, ref, render = _ring_view(lut, angle)
    assert image_metrics.compare(ref, render())["orders"]["all"]["mismatch_frac"] < 0.002


@pytest.mark.parametrize("angle", [170.5, pytest.param(172.0, marks=pytest.mark.slow)])
def test_patches_next_to_the_limb(lut, angle):
    """The sphere with the axis next to its limb, at 640x360: the patches, clipped to the source
    triangles under them (budget.CLIP_TO_TRIANGLES), draw their sheets up to the fold: under 0.35% of
    the covered pixels differ and the texture is within 0.3 px (p99 of the screen error). (The plain
    grid: 0.46% / 0.43 px at 170.5 deg with three times the triangles; bench_budget.py --rules.)"""
    bench = _bench_accuracy()
    cam, src, ref, render = _ring_view(lut, angle, (640, 360))
    m = bench.compare(ref, render(), cam, src, other_surface=bench.OTHER_SURFACE)["orders"]["all"]
    assert m["mismatch_frac"] < 0.0035 and m["screen_px"]["p99"] < 0.3


def _annulus(r_in, r_out, n_r, n_a, z=0.0):
    r = np.linspace(r_in, r_out, n_r + 1)
    a = np.linspace(0, 2 * np.pi, n_a, endpoint=False)
    R, A = np.meshgrid(r, a, indexing="ij")
    pts = np.stack([R * np.cos(A), R * np.sin(A), np.full(R.shape, z)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_r), np.arange(n_a), indexing="ij")
    i, j = i.ravel(), j.ravel()
    v00, v10 = i * n_a + j, (i + 1) * n_a + j
    v11, v01 = (i + 1) * n_a + (j + 1) % n_a, i * n_a + (j + 1) % n_a
    tris = np.concatenate([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)])
    return pts, tris


def test_equatorial_disc():
    """A disc in a plane through the hole is cut radially by every ray plane (the special case of the
    tracer): its hits agree with lutgen.connect, and with a disc lifted by 1e-7 r_s (general case)."""
    r_s = 1.0
    cam_pos = 18.0 * np.array([0.0, -math.sin(math.radians(80)), math.cos(math.radians(80))])
    cam = raytrace.Camera.look_at(cam_pos, HOLE, math.radians(50), 64, 36)
    pts, tris = _annulus(3.0, 12.0, 8, 48)
    buf = raytrace.trace(raytrace.TriangleScene(pts, tris), cam, HOLE, r_s)
    assert buf.info.get("radial_segments", 0) > 0
    h = buf.hit
    assert h.sum() > 600
    p = buf.point[h]
    np.testing.assert_allclose(p[:, 2], 0.0, atol=1e-9)
    e1 = cam_pos / np.linalg.norm(cam_pos)
    r = np.linalg.norm(p, axis=1)
    phi = np.arccos(np.clip(p @ e1 / r, -1, 1))
    xi_pix = np.arccos(np.clip(cam.pixel_directions()[h] @ e1, -1, 1))
    for o in (1, 2):  # (the order-2 ring is thinner than these pixels: it may be missing)
        k = buf.order[h] == o
        c = connect(18.0, r[k] / r_s, phi[k], o)
        np.testing.assert_allclose(c.xi, xi_pix[k], atol=1e-9)
        np.testing.assert_allclose(c.dt * r_s, buf.light_time[h][k], rtol=1e-9)
    lifted = raytrace.trace(raytrace.TriangleScene(pts + [0, 0, 1e-7], tris), cam, HOLE, r_s)
    assert lifted.info.get("radial_segments", 0) == 0
    assert (lifted.hit != buf.hit).sum() <= 2
    same = lifted.hit & buf.hit
    np.testing.assert_allclose(lifted.point[same], buf.point[same], atol=1e-5)
    assert np.array_equal(lifted.order[same], buf.order[same])


@pytest.mark.parametrize("angle", [4, pytest.param(356, marks=pytest.mark.slow)])  # 356: the mirror image
def test_second_order_ring_edge_crosses_the_ring(lut, angle):
    """The sphere grazing the axis in front of the hole, at the benchmark's 640x360: the second-order
    ring is under a pixel wide, and its edge at the Einstein radius is the patch's polygon. With its
    points on the ring its chords all lie inside it and add pixel centres along the whole ring: 0.50%
    of the covered pixels differed at 4 and 356 deg, the accuracy target missed; with the points
    moved out by budget.CHORD_OUTSET of the chords' sag, 0.06% (bench_budget.py --rules)."""
    _, _, ref, render = _ring_view(lut, angle, (640, 360))

    def mismatch():
        return image_metrics.compare(ref, render())["orders"]["all"]["mismatch_frac"]

    assert mismatch() < 0.002
