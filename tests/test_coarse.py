"""Coarse meshes within the error budget, per pixel against the reference ray tracer: a ground plane
and a wall of one quad each (benchmarks/bench_coarse.py's scenes, smaller), and the triangle bound of
the refine step (core/interior.py), reached and reported."""
import os
import sys

import numpy as np
import pytest

from grlens_addon.core import budget, frame_check, image_metrics, mapping, pipeline, raytrace

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
import bench_coarse as BC  # noqa: E402

from lutgen import LUTFamily, connect  # noqa: E402


@pytest.fixture(scope="module")
def table():
    return LUTFamily().at(BC.R_OBS)


def _check(table, name, width=320, height=180, **settings):
    pts, tris, uv = BC.scenes()[name]
    cam = BC.camera(width, height)
    scene = mapping.Scene(cam.position, np.zeros(3), 1.0)
    s = pipeline.Settings(max_tess_level=64, tess_a=5.0, tess_b=0.75, cull_ratio=8.0, **settings)
    return frame_check.check_frame([pipeline.SourceMesh(pts, tris, uv)], scene, table, s, cam), (pts, tris, uv)


@pytest.mark.parametrize("name", ["plane", "wall"])
def test_one_quad_matches_the_reference(table, name):
    """A plane 200 BU across under the hole and a wall beside the camera, two triangles each: the
    texture drawn where it truly is (screen error p99 within 0.5 px, the accuracy target), no checker
    pixel wrong away from its cell's edges (torn), the same coverage (0.5%) and the light-travel pass
    within 1% (p99) of the exact c*dt of the point drawn at each pixel. Without the refine step the
    plane is torn (the texture 22 px off at p99)."""
    check, (pts, tris, uv) = _check(table, name)
    m = check.metrics["orders"]["all"]
    assert m["covered_ref"] > 10000
    assert m["mismatch_frac"] < 0.005
    assert m["screen_px"]["p99"] < 0.5
    # the light-travel pass where the image is drawn: the value at a pixel against the exact c*dt of
    # the surface point drawn there (lutgen.connect), on a sample of the pixels
    poly = check.polygon
    shown = np.flatnonzero((poly.hit & (poly.order >= 1) & (poly.order <= 2)).ravel())
    pick = np.random.default_rng(1).choice(shown, 3000, replace=False)
    pts, order = poly.point.reshape(-1, 3)[pick], poly.order.ravel()[pick]
    plane = mapping.plane_coordinates(pts, mapping.Scene(BC.CAMERA, np.zeros(3), 1.0))
    exact = np.full(len(pick), np.nan)
    for o in (1, 2):
        k = order == o
        exact[k] = connect(BC.R_OBS, plane.r[k], plane.phi[k], order=o).dt
    rel = np.abs(poly.light_time.ravel()[pick] - exact) / exact
    assert np.percentile(rel[np.isfinite(rel)], 99) < budget.LIGHT_TRAVEL_TOLERANCE
    tex = image_metrics.checker_torn(check.reference, check.polygon, BC.CELLS)
    assert tex["matched"] > 10000 and tex["torn"] == 0, tex


def test_checker_torn_sees_a_torn_texture():
    """The torn-pixel measure itself: a texture shifted by a fraction of a cell is wrong in the middle
    of cells; shifted by a fraction of a pixel it is wrong only along edges."""
    h, w = 60, 80
    rows, cols = np.mgrid[0:h, 0:w]
    ref = raytrace.PixelBuffers.empty((h, w))
    ref.hit[:] = True
    ref.object_id[:] = 0
    ref.order[:] = 1
    ref.uv = np.stack([(cols + 0.5) / w, (rows + 0.5) / h], -1)
    cells = 8  # 10 px per cell along u

    def shifted(du):
        test = raytrace.PixelBuffers.empty((h, w))
        test.hit[:], test.object_id[:], test.order[:] = True, 0, 1
        test.uv = ref.uv + np.array([du, 0.0])
        return image_metrics.checker_torn(ref, test, cells)

    small, large = shifted(0.6 / w), shifted(4.0 / w)
    assert small["wrong"] > 0 and small["torn"] == 0
    assert large["torn"] > 0


def test_triangle_bound_stops_the_cutting_and_is_reported(table):
    """With a small Settings.max_triangles the refine step stops before the budget holds: the report
    says so (CullReport.triangle_bound, over_budget with how far off), the image stays near the bound,
    and the add-on's report line names the object with its error."""
    pts, tris, uv = BC.scenes()["plane"]
    cam = BC.camera(320, 180)
    scene = mapping.Scene(cam.position, np.zeros(3), 1.0)
    kw = dict(max_tess_level=64, tess_a=5.0, tess_b=0.75, cull_ratio=8.0, pixel_angle=cam.pixel_angle)
    src = pipeline.SourceMesh(pts, tris, uv)
    free = pipeline.build_images(src, scene, table, pipeline.Settings(**kw), frustum_planes=cam.frustum_planes())
    n_free = sum(len(m.tris) for m in free.values())
    assert not any(m.report.triangle_bound for m in free.values())
    bound = n_free // 4
    held = pipeline.build_images(src, scene, table, pipeline.Settings(max_triangles=bound, **kw),
                                 frustum_planes=cam.frustum_planes())
    reps = [m.report for m in held.values()]
    assert any(r.triangle_bound for r in reps)
    assert sum(r.over_budget.count for r in reps) > 0
    worst = max(r.over_budget.screen_px for r in reps)
    assert worst > 0.25
    assert sum(len(m.tris) for m in held.values()) <= 1.25 * bound
    from grlens_addon.blender import rebuild

    line = rebuild.over_budget_line("Ground", held, pipeline.Settings(max_triangles=bound, **kw))
    assert line.startswith("Ground: ") and "Max Triangles" in line and f"{worst:.2g} px" in line
    assert rebuild.over_budget_line("Ground", free, pipeline.Settings(**kw)) is None or \
        "last round" in rebuild.over_budget_line("Ground", free, pipeline.Settings(**kw))
