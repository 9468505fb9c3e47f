"""Panoramic cameras (grlens_addon.core.raytrace.Camera kinds EQUIRECTANGULAR and FISHEYE_EQUIDISTANT)
in the reference tracer, the rasterizer and the frame check.

Units: BU (r_s = 1 BU where a hole matters); angles in radians; pixel coordinates with centres at
integer + 0.5, row 0 at the top. Independent checks: Cycles' own projection formulas
(intern/cycles/kernel/camera/projection.h: direction_to_equirectangular_range,
fisheye_equidistant_to_direction, direction_to_fisheye_equidistant, with the equirectangular range
of scene/camera.cpp and the panorama camera matrix of Cycles' Blender sync) transcribed literally,
brute-force straight rays against every triangle for every pixel, and the reference ray tracer with
a distant, tiny hole (flat space) or lutgen.connect (raytrace.image_pixels) for a real one.
"""
import math

import numpy as np
import pytest

from grlens_addon.core import frame_check, image_metrics, mapping, pipeline, rasterize, raytrace
from lutgen import build_lut

# Cycles' panorama frame (x forward, y left, z up) from Blender's camera axes (x right, y up, -z
# forward): the inverse of Cycles' blender_camera_matrix rows (0, -1, 0), (0, 0, 1), (-1, 0, 0)
_TO_CYCLES = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _cycles_equirect_uv(local, lon_min, lon_max, lat_min, lat_max):
    D = local @ _TO_CYCLES.T
    rng = (lon_min - lon_max, -lon_min, lat_min - lat_max, -lat_min + math.pi / 2)
    u = (np.arctan2(D[:, 1], D[:, 0]) - rng[1]) / rng[0]
    v = (np.arccos(D[:, 2] / np.linalg.norm(D, axis=1)) - rng[3]) / rng[2]
    return u, v


def _cycles_fisheye_uv(local, fov):
    D = local @ _TO_CYCLES.T
    r = np.arctan2(np.hypot(D[:, 1], D[:, 2]), D[:, 0]) / fov
    n = np.hypot(D[:, 1], D[:, 2])
    return 0.5 - r * D[:, 1] / n, r * D[:, 2] / n + 0.5


def _cycles_fisheye_dir(u, v, fov):
    u, v = (u - 0.5) * 2.0, (v - 0.5) * 2.0
    r = np.sqrt(u * u + v * v)
    theta = r * fov * 0.5
    phi = np.arccos(np.clip(np.where(r != 0, u / np.where(r != 0, r, 1), 0.0), -1, 1))
    phi = np.where(v < 0, -phi, phi)
    D = np.stack([np.cos(theta), -np.cos(phi) * np.sin(theta), np.sin(phi) * np.sin(theta)], -1)
    D[r > 1] = np.nan
    return D @ np.linalg.inv(_TO_CYCLES).T  # back to Blender's camera axes


def _rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


EQUI_FULL = dict(kind="EQUIRECTANGULAR")
EQUI_PART = dict(kind="EQUIRECTANGULAR", longitude_min=-2.0, longitude_max=1.0, latitude_min=-0.5, latitude_max=1.2)
FISH_180 = dict(kind="FISHEYE_EQUIDISTANT", fisheye_fov=math.pi)
FISH_250 = dict(kind="FISHEYE_EQUIDISTANT", fisheye_fov=math.radians(250))


def test_equirectangular_is_cycles():
    """Pixel directions and projection of the equirectangular camera against Cycles' formulas, full and
    partial ranges; the image centre looks along -Z, longitude grows towards +X (right), the top row
    is the highest latitude, the seam is behind the camera."""
    rng = np.random.default_rng(1)
    for lens in (EQUI_FULL, EQUI_PART):
        cam = raytrace.Camera(rng.normal(size=3), _rotation(rng), 0.0, 24, 12, **lens)
        loc = cam.local_directions().reshape(-1, 3)
        u, v = _cycles_equirect_uv(loc, cam.longitude_min, cam.longitude_max, cam.latitude_min, cam.latitude_max)
        cols, rows = np.meshgrid(np.arange(24) + 0.5, np.arange(12) + 0.5)
        np.testing.assert_allclose(u * 24, cols.ravel(), atol=1e-9)
        np.testing.assert_allclose((1 - v) * 12, rows.ravel(), atol=1e-9)
        # project: world points along random directions, at random distances
        d = rng.normal(size=(200, 3))
        col, row, depth = cam.project(cam.position + d * 3.0)
        u, v = _cycles_equirect_uv(d @ cam.rotation, cam.longitude_min, cam.longitude_max, cam.latitude_min,
                                   cam.latitude_max)
        np.testing.assert_allclose(col, u * 24, atol=1e-9)
        np.testing.assert_allclose(row, (1 - v) * 12, atol=1e-9)
        np.testing.assert_allclose(depth, 3.0 * np.linalg.norm(d, axis=1), rtol=1e-12)
        dirs = cam.pixel_directions().reshape(-1, 3)
        col, row, _ = cam.project(cam.position + 2.0 * dirs)
        np.testing.assert_allclose(col, cols.ravel(), atol=1e-9)
        np.testing.assert_allclose(row, rows.ravel(), atol=1e-9)
        assert cam.frustum_planes() is None and cam.panoramic
    cam = raytrace.Camera(np.zeros(3), np.eye(3), 0.0, 360, 180, **EQUI_FULL)
    col, row, _ = cam.project(np.array([[0, 0, -1.0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, 0, 1], [0, -1e-9, 1]]))
    np.testing.assert_allclose(col[:4], [180, 270, col[2], 90], atol=1e-6)
    np.testing.assert_allclose(row[[0, 1, 3]], 90, atol=1e-6)
    assert row[2] == pytest.approx(0.0) and abs(col[4] - 360) < 1e-6 and abs(col[5] - 360) < 1e-6
    assert cam.pixel_angle == pytest.approx(2 * math.pi / 360)
    part = raytrace.Camera(np.zeros(3), np.eye(3), 0.0, 30, 17, **EQUI_PART)
    assert part.pixel_angle == pytest.approx(min(3.0 / 30, 1.7 / 17))
    with pytest.raises(ValueError, match="latitude"):
        raytrace.Camera(np.zeros(3), np.eye(3), 0.0, 30, 17, kind="EQUIRECTANGULAR", latitude_min=0.3,
                        latitude_max=0.2)
    with pytest.raises(ValueError, match="unknown camera kind"):
        raytrace.Camera(np.zeros(3), np.eye(3), 0.0, 30, 17, kind="MIRRORBALL")


def test_fisheye_equidistant_is_cycles():
    """The fisheye's pixel directions and projection against Cycles' formulas; pixels outside the
    circle have no direction, points outside the field no pixel; the dome master (180 deg) sees the
    half space in front, its rim at 90 deg from the view axis."""
    rng = np.random.default_rng(2)
    for lens, (w, h) in ((FISH_180, (20, 20)), (FISH_250, (24, 16))):
        cam = raytrace.Camera(rng.normal(size=3), _rotation(rng), 0.0, w, h, **lens)
        u = (np.arange(w) + 0.5) / w
        v = 1 - (np.arange(h) + 0.5) / h
        uu, vv = np.meshgrid(u, v)
        expect = _cycles_fisheye_dir(uu.ravel(), vv.ravel(), cam.fisheye_fov)
        loc = cam.local_directions().reshape(-1, 3)
        assert np.array_equal(np.isnan(loc), np.isnan(expect)) and np.isnan(loc).any()
        ok = ~np.isnan(loc[:, 0])
        np.testing.assert_allclose(loc[ok], expect[ok], atol=1e-12)
        d = rng.normal(size=(300, 3))
        col, row, depth = cam.project(cam.position + d)
        cu, cv = _cycles_fisheye_uv(d @ cam.rotation, cam.fisheye_fov)
        angle = np.arccos(np.clip(-(d @ cam.rotation)[:, 2] / np.linalg.norm(d, axis=1), -1, 1))
        inside = angle <= cam.fisheye_fov / 2
        assert np.isnan(col[~inside]).all() and np.isnan(row[~inside]).all() and inside.sum() > 50
        np.testing.assert_allclose(col[inside], cu[inside] * w, atol=1e-9)
        np.testing.assert_allclose(row[inside], (1 - cv[inside]) * h, atol=1e-9)
        assert np.all(depth > 0) and cam.frustum_planes() is None
        assert cam.pixel_angle == pytest.approx(cam.fisheye_fov / max(w, h))
    cam = raytrace.Camera(np.zeros(3), np.eye(3), 0.0, 100, 100, **FISH_180)
    col, row, _ = cam.project(np.array([[0, 0, -1.0], [1, 0, -1e-12], [0, 1, -1e-12], [0, 0, 1.0]]))
    np.testing.assert_allclose([col[0], row[0]], [50, 50], atol=1e-9)
    np.testing.assert_allclose([col[1], row[1], col[2], row[2]], [100, 50, 50, 0], atol=1e-6)
    assert np.isnan(col[3])
    with pytest.raises(ValueError, match="fisheye_fov"):
        raytrace.Camera(np.zeros(3), np.eye(3), 0.0, 10, 10, kind="FISHEYE_EQUIDISTANT", fisheye_fov=7.0)


def _brute_force(cam, pos, tris):
    """Straight pixel rays against every triangle: (T, H, W) whether each triangle is hit, and (H, W)
    the nearest face (or -1)."""
    dirs = cam.pixel_directions().reshape(-1, 3)
    a, b, c = pos[tris[:, 0]], pos[tris[:, 1]], pos[tris[:, 2]]
    P = len(dirs)
    best = np.full(P, -1)
    best_t = np.full(P, np.inf)
    hits = np.zeros((len(tris), P), bool)
    for f in range(len(tris)):
        t, u, v, ok = rasterize._moller_trumbore(cam.position, dirs, np.broadcast_to(a[f], (P, 3)),
                                                 np.broadcast_to(b[f], (P, 3)), np.broadcast_to(c[f], (P, 3)))
        hits[f] = ok
        better = ok & (t < best_t)
        best[better], best_t[better] = f, t[better]
    return hits.reshape(len(tris), cam.height, cam.width), best.reshape(cam.height, cam.width)


def _awkward_triangles(rng, cam):
    """Triangles around a camera: small and large ones all around, across the equirectangular seam
    (behind the camera), over the poles (straight up and down), around and right next to the camera."""
    o = cam.position
    R = cam.rotation
    tris = []
    for _ in range(40):
        centre = rng.normal(size=3)
        centre *= rng.uniform(2, 6) / np.linalg.norm(centre)
        tris.append(centre + rng.normal(size=(3, 3)) * rng.choice([0.1, 0.8, 3.0]))
    behind = R[:, 2] * 3.0
    tris.append(behind + np.array([R[:, 0] * -1.0, R[:, 0] * 1.2 + R[:, 1] * 0.3, R[:, 1] * -0.8]))  # across the seam
    tris.append(R[:, 1] * 2.0 + np.array([R[:, 0], R[:, 2] * 0.9, -R[:, 0] - R[:, 2]]) * 1.5)  # over the top pole
    tris.append(-R[:, 1] * 2.0 + np.array([R[:, 0], R[:, 2], -R[:, 0] - R[:, 2] * 0.7]) * 0.5)  # under the bottom
    tris.append(np.array([[5.0, -5, -1], [-5, -5, -1], [0, 8, -1]]))  # under the camera, wider than a hemisphere
    tris.append(np.array([[1e-3, 0, 0], [0, 1e-3, 0.0], [0, 0, 1e-3]]) + 0.0)  # tiny, right next to the camera
    pos = np.concatenate(tris) + o
    return pos, np.arange(len(pos)).reshape(-1, 3)


@pytest.mark.parametrize("lens", [EQUI_FULL, EQUI_PART, FISH_180, FISH_250], ids=["equi", "equi-part", "fish180",
                                                                                  "fish250"])
def test_panorama_rasterizer_finds_every_pixel(lens):
    """The rasterizer's candidate pixels (bounding caps of the triangles' spherical images, split at
    the seam) miss nothing: its nearest faces equal brute-force straight rays against every triangle."""
    rng = np.random.default_rng(5)
    cam = raytrace.Camera.look_at([0.2, -0.1, 0.3], [3.0, 1.0, 0.5], 0.0, 72, 36 if lens["kind"] == "EQUIRECTANGULAR"
                                  else 40, **lens)
    pos, tris = _awkward_triangles(rng, cam)
    buf = rasterize.rasterize([rasterize.RasterMesh(pos, tris, np.ones(len(pos)), 1)], cam)
    hits, expect = _brute_force(cam, pos, tris)
    assert np.array_equal(buf.face, expect)
    assert (expect >= 0).mean() > 0.3 and len(np.unique(expect)) > 10
    assert buf.info["tests"] < 0.5 * len(tris) * cam.width * cam.height  # the boxes do select
    for f in range(len(tris)):  # each triangle alone: every pixel it covers
        one = rasterize.rasterize([rasterize.RasterMesh(pos, tris[f:f + 1], np.ones(len(pos)), 1)], cam)
        assert np.array_equal(one.hit, hits[f]), f
    assert (hits.sum(axis=(1, 2)) > 0).sum() > 15
    assert np.isnan(buf.sky).all()


@pytest.mark.parametrize("lens", [EQUI_FULL, FISH_180], ids=["equi", "fish180"])
def test_panorama_flat_triangles_match_the_reference(lens):
    """With a tiny, distant hole (1e6 r_s away: flat space to ~1e-6 rad) the reference ray tracer and
    the rasterizer see the same pixels of triangles across the seam and near the fisheye's rim;
    the fisheye's pixels outside the circle have no ray (no hit, not fallen, no sky)."""
    r_s = 1e-5
    cam = raytrace.Camera.look_at([0.0, 0.0, 0.0], [0.0, -1.0, 0.0], 0.0, 96, 48 if lens is EQUI_FULL else 64, **lens)
    R = cam.rotation
    pos = np.concatenate([
        R[:, 2] * 4.0 + np.array([R[:, 0] * -1.5, R[:, 0] * 1.7 + R[:, 1] * 0.5, R[:, 1] * -1.2]),  # behind: the seam
        -R[:, 2] * 2.0 + np.array([R[:, 0] * 2.5, R[:, 0] * 2.5 + R[:, 1], R[:, 0] * 0.5 - R[:, 2] * 0.2]),  # right, rim
        -R[:, 2] * 5.0 + np.array([[0.3, 0.2, 0.0], [-0.4, 0.1, 0.5], [0.1, -0.6, 0.2]])])
    tris = np.arange(9).reshape(3, 3)
    hole = -10.0 * R[:, 1]  # 1e6 r_s below the camera
    ref = raytrace.trace(raytrace.TriangleScene(pos, tris), cam, hole, r_s)
    ras = rasterize.rasterize([rasterize.RasterMesh(pos, tris, np.ones(9), 1)], cam)
    assert ref.hit.sum() > 40
    assert np.count_nonzero(ref.hit != ras.hit) <= 2 and np.count_nonzero(ref.face != ras.face) <= 2
    assert np.all(np.isfinite(ref.sky[~ref.hit & ~ref.fell]).any(axis=-1) | np.isnan(cam.pixel_directions()[~ref.hit][:, 0]))
    if lens is FISH_180:
        outside = np.isnan(cam.pixel_directions()[..., 0])
        assert outside.sum() > 500 and not ref.hit[outside].any() and not ref.fell[outside].any()
        assert np.isnan(ref.sky[outside]).all() and np.isfinite(ref.sky[~outside & ~ref.hit]).all()
    else:
        seam = ref.hit & ((np.arange(cam.width) < 3) | (np.arange(cam.width) >= cam.width - 3))[None, :]
        assert seam.sum() > 10  # the first triangle does cross the seam


def test_image_pixels_in_a_panorama():
    """raytrace.image_pixels (lutgen.connect) puts the point each pixel of the reference shows back at
    that pixel's centre, in an equirectangular panorama around a real hole (both orders, the seam
    included: columns compared modulo the width) and in a fisheye."""
    for lens, size in ((EQUI_FULL, (120, 60)), (FISH_250, (60, 60))):
        cam = raytrace.Camera.look_at([20.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.0, *size, **lens)
        pos = np.array([[-3.0, -4.0, -3.0], [-3.0, 4.0, -2.0], [-3.0, 0.0, 4.0], [30.0, -3, -3], [30.0, 3, -3],
                        [30.0, 0, 4]])
        ref = raytrace.trace(raytrace.TriangleScene(pos, [[0, 1, 2], [3, 4, 5]]), cam, np.zeros(3), 1.0)
        rows, cols = np.mgrid[0:size[1], 0:size[0]]
        for order in (1, 2):
            m = ref.hit & (ref.order == order)
            assert m.sum() > (10 if order == 1 else 3)
            col, row = raytrace.image_pixels(ref.point[m], cam, np.zeros(3), 1.0, order)
            dc = col - (cols[m] + 0.5)
            if lens is EQUI_FULL:
                dc -= cam.width * np.round(dc / cam.width)
            assert np.abs(dc).max() < 1e-5 and np.abs(row - (rows[m] + 0.5)).max() < 1e-5
        if lens is EQUI_FULL:  # the object behind the camera straddles the seam
            assert ref.hit[:, 0].any() and ref.hit[:, -1].any()


@pytest.fixture(scope="module")
def lut():
    return build_lut(20.0, 1.05, 40.0, 128, 256)


@pytest.mark.parametrize("lens", [dict(kind="EQUIRECTANGULAR", longitude_min=-0.35, longitude_max=0.35,
                                       latitude_min=-0.175, latitude_max=0.175),
                                  dict(kind="FISHEYE_EQUIDISTANT", fisheye_fov=math.radians(25))],
                         ids=["equi-part", "fish25"])
def test_frame_check_in_a_panorama(lut, lens):
    """check_frame with panoramic cameras: build_images without frustum planes, rasterized in the
    panorama; the polygon method's images agree with the reference as in the perspective check."""
    from meshes import uv_sphere

    a = math.radians(90)
    pts, tris = uv_sphere(np.array([3 * math.cos(a), 3 * math.sin(a), 0.01]), 0.5, 36, 18)
    src = pipeline.SourceMesh(pts, tris, corner_uv=np.random.default_rng(0).random((len(tris), 3, 2)))
    size = (160, 80) if lens["kind"] == "EQUIRECTANGULAR" else (128, 128)
    cam = raytrace.Camera.look_at([20.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.0, *size, **lens)
    scene = mapping.Scene(cam.position, np.zeros(3), 1.0)
    check = frame_check.check_frame([src], scene, lut, pipeline.Settings(64, 5.0, 0.75, 8.0), cam)
    m = check.metrics["orders"]["all"]
    assert m["covered_ref"] > 100
    assert m["mismatch_frac"] < 0.05 and m["screen_px"]["p99"] < 0.5
    assert check.metrics["orders"][2]["covered_ref"] > 0


def test_blender_panoramic_cameras_become_reference_cameras():
    """blender.check.check_camera (bpy): a PANO camera of type equirectangular or fisheye equidistant
    becomes the raytrace.Camera of that kind with the camera's ranges / field of view and position,
    looking along the object's -Z; other panorama types and orthographic cameras are refused."""
    bpy = pytest.importorskip("bpy")
    from grlens_addon.blender import check

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    try:
        scene = bpy.context.scene
        scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 400, 200, 50
        data = bpy.data.cameras.new("Pano")
        obj = bpy.data.objects.new("Pano", data)
        scene.collection.objects.link(obj)
        obj.location = (3.0, -2.0, 1.0)
        obj.rotation_euler = (1.2, 0.1, 0.7)
        bpy.context.view_layer.update()
        data.type = "PANO"
        data.panorama_type = "EQUIRECTANGULAR"
        data.latitude_min, data.latitude_max = -1.0, 1.2
        data.longitude_min, data.longitude_max = -2.5, 2.0
        cam = check.check_camera(scene, obj, 50)
        assert (cam.kind, cam.width, cam.height) == ("EQUIRECTANGULAR", 100, 50)
        assert (cam.latitude_min, cam.latitude_max, cam.longitude_min, cam.longitude_max) == pytest.approx((-1, 1.2, -2.5, 2))
        mw = np.array(obj.matrix_world)
        np.testing.assert_allclose(cam.position, mw[:3, 3], atol=1e-6)
        # the direction at longitude 0, latitude 0 is the object's -Z
        col, row, _ = cam.project(cam.position[None] - mw[:3, 2][None])
        assert col[0] == pytest.approx(2.5 / 4.5 * 100, abs=1e-4) and row[0] == pytest.approx(1.2 / 2.2 * 50, abs=1e-4)
        # the rebuild's pixel size is the panorama's angular resolution, and it has no frustum
        from grlens_addon.blender import rebuild

        assert rebuild._pixel_angle(scene, obj) == pytest.approx(min(4.5 / 200, 2.2 / 100))  # the render: 200x100
        assert rebuild.frustum_planes(scene, obj) is None
        # Blender's full panorama (its float32 properties hold +-pi/2 and +-pi just beyond them)
        data.latitude_min, data.latitude_max = -math.pi / 2, math.pi / 2
        data.longitude_min, data.longitude_max = -math.pi, math.pi
        assert data.latitude_max > math.pi / 2 and data.longitude_max > math.pi  # as float64
        cam = check.check_camera(scene, obj, 50)
        assert (cam.latitude_min, cam.latitude_max) == (-math.pi / 2, math.pi / 2)
        assert (cam.longitude_min, cam.longitude_max) == (-math.pi, math.pi)
        assert rebuild._pixel_angle(scene, obj) == pytest.approx(2 * math.pi / 200)
        data.panorama_type = "FISHEYE_EQUIDISTANT"
        data.fisheye_fov = 2 * math.pi  # a full-sphere fisheye
        assert check.check_camera(scene, obj, 50).fisheye_fov == 2 * math.pi
        data.fisheye_fov = math.radians(200)
        assert rebuild._pixel_angle(scene, obj) == pytest.approx(math.radians(200) / 200)
        cam = check.check_camera(scene, obj, 50)
        assert cam.kind == "FISHEYE_EQUIDISTANT" and cam.fisheye_fov == pytest.approx(math.radians(200))
        np.testing.assert_allclose(cam.pixel_directions()[25, 50], -mw[:3, 2] / np.linalg.norm(mw[:3, 2]), atol=0.05)
        for other in ("MIRRORBALL", "FISHEYE_EQUISOLID"):
            data.panorama_type = other
            with pytest.raises(ValueError, match="equirectangular and fisheye equidistant, not " + other.replace("_", " ").lower()):
                check.check_camera(scene, obj, 50)
        # the panel says that only Cycles renders panoramas
        from grlens_addon.blender import panels

        scene.camera = obj
        scene.render.engine = "CYCLES"
        assert panels.panorama_note(scene) == ""
        scene.render.engine = "BLENDER_WORKBENCH"
        assert "only Cycles" in panels.panorama_note(scene)
        data.type = "ORTHO"
        assert panels.panorama_note(scene) == ""
        with pytest.raises(ValueError, match="perspective or panoramic"):
            check.check_camera(scene, obj, 50)
    finally:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
