"""core.frame_check: one frame of the polygon method against the reference ray tracer, its passes and
their OpenEXR file (no bpy). Units: BU with r_s = 1; the paper's sphere at 160x90."""
import dataclasses
import math

import numpy as np
import pytest

from grlens_addon.core import frame_check, mapping, pipeline, raytrace
from lutgen import build_lut
from lutgen.exr_io import read_exr
from meshes import uv_sphere

R_S, R_OBS = 1.0, 20.0


@pytest.fixture(scope="module")
def lut():
    return build_lut(R_OBS, 1.05, 40.0, 128, 256)


def _frame(deg, width=160, height=90):
    a = math.radians(deg)
    pts, tris = uv_sphere(np.array([3 * math.cos(a), 3 * math.sin(a), 0.01]), 0.5, 36, 18)
    src = pipeline.SourceMesh(pts, tris,
                              corner_uv=np.random.default_rng(0).random((len(tris), 3, 2)))
    cam = raytrace.Camera.look_at([R_OBS, 0.0, 0.0], [0.0, 0.0, 0.0], math.radians(19.0), width, height)
    scene = mapping.Scene(cam.position, np.zeros(3), R_S)
    settings = pipeline.Settings(64, 5.0, 0.75, 8.0)  # pixel_angle: the check's camera's
    return src, scene, settings, cam


def test_frame_check_off_axis_matches_and_writes_its_passes(lut, tmp_path):
    src, scene, settings, cam = _frame(90)
    check = frame_check.check_frame([src], scene, lut, settings, cam, names=["Sphere"])
    m = check.metrics["orders"]["all"]
    assert m["covered_ref"] > 100 and m["mismatch_frac"] < 0.01
    assert m["screen_px"]["p99"] < 0.5 and m["lt_rel"]["p99"] < 1e-3
    assert check.reference_seconds > 0 and check.polygon_seconds > 0 and check.resolution == (160, 90)
    assert "of the covered pixels differ" in check.summary() and "x)" in check.summary()
    passes = frame_check.passes(check)
    assert all(v.shape == (90, 160) and v.dtype == np.float32 for v in passes.values())
    both = (passes["Reference.object_index.V"] == 0) & (passes["grlens.object_index.V"] == 0)
    assert both.sum() > 100
    lt_r, lt_p = passes["Reference.light_travel_time.V"][both], passes["grlens.light_travel_time.V"][both]
    assert np.all(np.abs(lt_p - lt_r) <= 1e-3 * lt_r)
    assert np.array_equal(passes["Reference.image_order.V"][both], passes["grlens.image_order.V"][both])
    none = passes["Reference.object_index.V"] < 0
    assert np.all(passes["Reference.light_travel_time.V"][none] == 0) and np.all(passes["Reference.image_order.V"][none] == 0)
    assert passes["Check.mismatch.V"].sum() == m["mismatch"]
    path = tmp_path / "check.exr"
    frame_check.write_passes(path, check)
    channels, meta = read_exr(path)
    assert set(channels) == set(passes)
    assert np.array_equal(channels["grlens.image_order.V"], passes["grlens.image_order.V"], equal_nan=True)
    assert meta["mismatch_fraction"] == m["mismatch_frac"] and meta["objects"] == "0: Sphere"


def test_frame_check_sees_the_polygon_method_s_error_at_the_ring(lut):
    """Behind the hole (Einstein ring) the polygon method is approximate: the check reports a small,
    nonzero mismatch, and the first-order ring in both renders."""
    src, scene, settings, cam = _frame(180)
    check = frame_check.check_frame([src], scene, lut, settings, cam)
    m = check.metrics["orders"]["all"]
    assert 0 < m["mismatch"] and m["mismatch_frac"] < 0.02
    assert frame_check.passes(check)["Check.mismatch.V"].sum() == m["mismatch"]
    assert check.metrics["orders"][1]["covered_ref"] > 500 and check.metrics["orders"][1]["covered_test"] > 500


def test_frame_check_refuses_bad_input(lut):
    src, scene, settings, cam = _frame(90)
    with pytest.raises(ValueError, match="no source"):
        frame_check.check_frame([], scene, lut, settings, cam)
    other = raytrace.Camera.look_at([R_OBS, 1.0, 0.0], [0.0, 0.0, 0.0], math.radians(19.0), 160, 90)
    with pytest.raises(ValueError, match="not the scene's observer"):
        frame_check.check_frame([src], scene, lut, settings, other)


def test_mismatch_pass_counts_what_the_metric_counts():
    """image_metrics.mismatch_mask (the Check.mismatch pass): a pixel differs where exactly one render
    shows an (object, order) of orders 1-2; a third-order pixel of the reference alone is not counted,
    as in compare's coverage mismatch."""
    from grlens_addon.core import image_metrics

    ref, test = raytrace.PixelBuffers.empty((1, 5)), raytrace.PixelBuffers.empty((1, 5))
    for buf, orders, objs in ((ref, [1, 2, 3, 1, 0], [0, 0, 0, 0, -1]), (test, [1, 1, 0, 0, 2], [0, 0, -1, -1, 0])):
        buf.order[0] = orders
        buf.object_id[0] = objs
        buf.hit[0] = np.array(orders) > 0
    assert image_metrics.mismatch_mask(ref, test).tolist() == [[False, True, False, True, True]]
    assert image_metrics.compare(ref, test)["orders"]["all"]["mismatch"] == 3


def test_plane_across_the_axis_matches_the_reference(lut):
    """A square of two triangles behind the hole, perpendicular to the axis, which crosses their shared
    edge: its images are two rings. Its triangles' corners all lie at one distance from the axis, so
    their images lie in a band under a pixel wide, but their edge passes through the axis: they must
    not be cut into strips (found by this check: strips across the ring's inside, 256% of the covered
    pixels differed at 320x180)."""
    pts = np.array([(-4, -1, -1), (-4, 1, -1), (-4, 1, 1), (-4, -1, 1)], float)
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], float)
    cam = raytrace.Camera.look_at([R_OBS, 0.0, 0.0], [0.0, 0.0, 0.0], math.radians(19.0), 240, 135)
    scene = mapping.Scene(cam.position, np.zeros(3), R_S)
    check = frame_check.check_frame([pipeline.SourceMesh(pts, tris, uv)], scene, lut,
                                    pipeline.Settings(64, 5.0, 0.75, 8.0), cam)
    o = check.metrics["orders"]
    assert o[1]["covered_ref"] > 1000 and o[2]["covered_ref"] > 500
    assert o["all"]["mismatch_frac"] < 0.01 and o["all"]["screen_px"]["p99"] < 0.5


def test_box_beside_the_crossed_face_leaves_no_gap_in_the_ring(lut):
    """A cube behind the hole whose front face the axis crosses off its centre: its side face next to
    the axis (parallel to it, on no axis patch's sheet) passes 0.4 r_s beside the axis. Its pieces
    there cover far more azimuth than its average; without levels for that they were culled and a
    piece of the Einstein ring was missing (4.4% of the covered pixels at 320x180)."""
    c, h = np.array([-4.0, 0.2, 0.1]), 0.6
    v = np.array([[x, y, z] for x in (-h, h) for y in (-h, h) for z in (-h, h)]) + c
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = np.array([t for a, b, cc, d in quads for t in ((a, b, cc), (a, cc, d))])
    cam = raytrace.Camera.look_at([R_OBS, 0.0, 0.0], [0.0, 0.0, 0.0], math.radians(19.0), 240, 135)
    scene = mapping.Scene(cam.position, np.zeros(3), R_S)
    check = frame_check.check_frame([pipeline.SourceMesh(v, tris)], scene, lut, pipeline.Settings(64, 5.0, 0.75, 8.0), cam)
    o = check.metrics["orders"]
    assert o[1]["covered_ref"] > 2000
    assert o["all"]["mismatch_frac"] < 0.01 and o["all"]["screen_px"]["p99"] < 0.5


def test_square_off_the_axis_shows_the_patch_not_coarse_pieces(lut):
    """A square of two triangles (2 r_s) behind the hole, crossed by the axis off its centre: the
    complete axis patch draws the surface around the crossing, and the kept triangles' pieces under
    it that are too wide (drawn beyond the tolerance at their centroid) are dropped
    (budget.UNDER_PATCH_FACTOR) or cut finer by the refine step (core/interior.py), else they would
    show through the patch on the same plane, the texture up to 1.7 px off (found by this check:
    screen p99 0.92 px at 320x180)."""
    pts = np.array([(-4, -0.7, -0.8), (-4, 1.3, -0.8), (-4, 1.3, 1.2), (-4, -0.7, 1.2)], float)
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], float)
    cam = raytrace.Camera.look_at([R_OBS, 0.0, 0.0], [0.0, 0.0, 0.0], math.radians(19.0), 320, 180)
    scene = mapping.Scene(cam.position, np.zeros(3), R_S)

    def screen_p99():
        check = frame_check.check_frame([pipeline.SourceMesh(pts, tris, uv)], scene, lut,
                                        pipeline.Settings(64, 5.0, 0.75, 8.0), cam)
        o = check.metrics["orders"]
        assert o[1]["covered_ref"] > 3000 and o["all"]["mismatch_frac"] < 0.005
        return o["all"]["screen_px"]["p99"]

    assert screen_p99() < 0.4
    settings = pipeline.Settings(64, 5.0, 0.75, 8.0, pixel_angle=cam.pixel_angle)
    img = pipeline.build_images(pipeline.SourceMesh(pts, tris, uv), scene, lut, settings,
                                frustum_planes=cam.frustum_planes())[1]
    rep = img.report  # the dropped pieces are counted (culling.CullReport.patch_covered), not kept
    assert (rep.patch_covered > 0 or rep.refined > 0) and rep.kept == len(img.tris)


def _rotate_towards_z(d, angle):
    """Each unit direction d (N, 3) turned by ``angle`` (rad) about unit(d x z): exactly that far."""
    axis = np.cross(d, [0.0, 0.0, 1.0])
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    return d * math.cos(angle) + np.cross(axis, d) * math.sin(angle)


def test_frame_check_of_the_sky(lut, tmp_path):
    """check_frame(sky=...): a sky model equal to the reference's own curve (raytrace.escape_directions)
    has no error; one turned by 0.7 px on every pixel reads 0.7 px and moves the checker edges; one
    whose shadow is 2 px too wide differs on exactly the pixels of that ring (counted here from the
    pixel directions and eq. 14). The sky directions go into the passes and the EXR file."""
    from grlens_addon.core import image_metrics
    from lutgen import shadow_half_angle
    from lutgen.exr_io import read_exr

    src, scene, settings, cam = _frame(90)
    exact = lambda d, p: raytrace.escape_directions(p, d, scene.hole, scene.r_s)  # noqa: E731
    check = frame_check.check_frame([src], scene, lut, settings, cam, sky=exact)
    sky = check.metrics["sky"]
    assert sky["fell_ref"] > 1000 and sky["compared"] > 10000 and sky["sky_angle_n"] > 8000
    assert sky["sky_angle_px"]["max"] == 0 and sky["shadow_mismatch"] == 0 and sky["checker_mismatch"] == 0
    assert sky["checker_edge"] > 300 and sky["checker_per_edge"] == 0
    assert "sky off by 0 px" in check.summary() and check.sky.shape == (90, 160, 3)
    ref = check.reference
    esc = ~ref.hit & ~ref.fell
    np.testing.assert_allclose(np.linalg.norm(ref.sky[esc], axis=-1), 1.0, atol=1e-13)
    assert np.isnan(ref.sky[~esc]).all()

    # off by a known angle
    pa = cam.pixel_angle
    off = np.full_like(check.sky, np.nan)
    ok = np.all(np.isfinite(check.sky), axis=-1)
    off[ok] = _rotate_towards_z(check.sky[ok], 0.7 * pa)
    m = image_metrics.compare_sky(ref, off, pa)
    for k in ("p50", "p99", "max"):
        assert m["sky_angle_px"][k] == pytest.approx(0.7, rel=1e-6)
    assert m["checker_per_edge"] > 0.01 and m["shadow_mismatch"] == 0  # edges move less where the sky is squeezed

    # a shadow 2 px too wide: NaN where the ray's angle from e1 is above pi - xi_crit - 2 px
    e1 = (scene.camera - scene.hole) / np.linalg.norm(scene.camera - scene.hole)
    xi = np.arccos(np.clip(cam.pixel_directions() @ e1, -1, 1))
    lim = math.pi - float(shadow_half_angle(scene.r_obs))
    wide = np.where((xi > lim - 2 * pa)[..., None], np.nan, check.sky)
    m = image_metrics.compare_sky(ref, wide, pa)
    ring = ~ref.hit & (xi > lim - 2 * pa) & (xi <= lim)
    assert m["shadow_mismatch"] == ring.sum() > 50 and m["fell_test"] == m["fell_ref"] + ring.sum()

    # passes and file
    bad = dataclasses.replace(check, sky=off, metrics=dict(check.metrics, sky=image_metrics.compare_sky(ref, off, pa)))
    p = frame_check.passes(bad)
    for layer in ("Reference", "grlens"):
        assert {f"{layer}.sky_direction.{a}" for a in "XYZ"} <= set(p)
    np.testing.assert_array_equal(p["Reference.sky_direction.Y"], ref.sky[..., 1].astype(np.float32))
    err = p["Check.sky_error.V"]
    assert np.nanmax(np.abs(err - 0.7)) < 1e-4 and np.isfinite(err).sum() == bad.metrics["sky"]["sky_angle_n"]
    assert p["Check.shadow_mismatch.V"].sum() == 0
    assert frame_check.passes(dataclasses.replace(check, sky=wide))["Check.shadow_mismatch.V"].sum() == ring.sum()
    path = tmp_path / "sky.exr"
    frame_check.write_passes(path, bad)
    channels, meta = read_exr(path)
    assert set(channels) == set(p) and meta["sky_error_p99_px"] == pytest.approx(0.7, rel=1e-6)
    assert "Reference.sky_direction.X" in frame_check.passes(dataclasses.replace(check, sky=None))
    assert "grlens.sky_direction.X" not in frame_check.passes(dataclasses.replace(check, sky=None))


def test_checker_edges_moved_by_a_known_angle():
    """In flat space (hole 1e6 r_s away), a sky model turned by 0.7 px in longitude and in latitude
    moves every checker edge by 0.7 px across itself (a 30 deg view of the horizon: pixels within 7%
    of pixel_angle): image_metrics.compare_sky's checker_per_edge reads about 0.7, sky_angle about
    0.7 sqrt 2."""
    from grlens_addon.core import image_metrics

    cam = raytrace.Camera.look_at([0.0, 0.0, 0.0], [1.0, 0.3, 0.05], math.radians(30.0), 320, 180)
    ref = raytrace.trace(raytrace.TriangleScene(np.zeros((0, 3)), np.zeros((0, 3))), cam, [0, 0, -10.0], 1e-5)
    pa = cam.pixel_angle
    d = ref.sky.reshape(-1, 3)
    lon = np.arctan2(d[:, 1], d[:, 0]) + 0.7 * pa / np.sqrt(1 - d[:, 2] ** 2)
    lat = np.arcsin(d[:, 2]) + 0.7 * pa
    turned = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], 1)
    m = image_metrics.compare_sky(ref, turned.reshape(ref.sky.shape), pa)
    assert m["checker_edge"] > 1000 and m["shadow_mismatch"] == 0 and m["fell_ref"] == 0
    assert 0.6 < m["checker_per_edge"] < 0.8
    assert m["sky_angle_px"]["p50"] == pytest.approx(0.7 * math.sqrt(2), rel=0.01)
    exact = image_metrics.compare_sky(ref, ref.sky, pa)
    assert exact["checker_per_edge"] == 0 and exact["sky_angle_px"]["max"] == 0


def test_checker_world():
    """image_metrics.checker: 10-degree checks in longitude (about world z) and latitude."""
    from grlens_addon.core import image_metrics

    lon = np.radians([5.0, 15.0, 5.0, 15.0, -5.0, 175.0, -175.0])
    lat = np.radians([5.0, 5.0, 15.0, 15.0, 5.0, -85.0, 85.0])
    d = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], 1)
    assert image_metrics.checker(d).tolist() == [0, 1, 1, 0, 1, (17 - 9) % 2, (-18 + 8) % 2]
    assert image_metrics.checker(np.full((2, 3), np.nan)).tolist() == [-1, -1]
