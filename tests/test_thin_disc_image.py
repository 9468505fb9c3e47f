"""Luminet's thin disc, image against image: the polygon method (pipeline.build_images with a
DiscEmitter, rasterized by grlens_addon.core.rasterize) against the analytic per-pixel reference
(lutgen.thin_disc, seed 002's method) at the same pixel centres. A small version of
benchmarks/bench_thin_disc.py (160x90, LUT 128x256; the full disc mesh of sample_scenes/luminet.py);
its full-size figures are in docs/thin_disc_accuracy.md.

Observed here (160x90): coverage mismatch 0.11% (order 1) and 1.3% (order 2, the ghost ring is one to
two pixels wide) of the reference's pixels; 1 + z relative error p99 4.2e-3 (order 1) and 8.8e-3
(order 2); per image vertex 1 + z agrees to 2e-5 and the radius to 2e-3 r_s. The bounds below leave a
factor of about 2-4.
"""
import math
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
import bench_thin_disc as btd  # noqa: E402

from grlens_addon.core import rasterize, raytrace  # noqa: E402
from lutgen import build_lut  # noqa: E402


@pytest.fixture(scope="module")
def case():
    lut = build_lut(btd.R_OBS, 1.05, 16.0, 128, 256)
    return btd.run_case(160, 90, lut, repeat=1)


def test_same_disc_orientation(case):
    """Both sides describe the same disc, turning the same way: at every image vertex the reference's
    crossing radius (in the vertex's apparent direction) is |source point|, and 1 + z agrees."""
    axis = btd.annulus(rings=2, segments=4)[2]
    theta, alpha, inc = btd.sky_geometry(case["cam"], axis)
    assert math.degrees(inc) == pytest.approx(btd.INCLINATION_DEG, abs=1e-9)
    for k in (1, 2):
        v = case["vertices"][k]
        assert v["n"] > 1000 and v["no_ref"] == 0
        assert v["r"]["max"] < 5e-3
        assert v["z"]["max"] < 1e-4
        # and per pixel, through the rasterizer's interpolated source point
        assert case["metrics"][k]["r"]["p50"] < 0.05


def test_coverage_mismatch_small(case):
    m1, m2 = case["metrics"][1], case["metrics"][2]
    assert m1["covered_ref"] > 4000 and m2["covered_ref"] > 800
    assert m1["mismatch_frac"] < 0.005  # observed 0.11%
    assert m2["mismatch_frac"] < 0.03  # observed 1.3%


def test_redshift_error_small(case):
    assert case["metrics"][1]["z"]["p99"] < 1e-2  # observed 4.2e-3
    assert case["metrics"][2]["z"]["p99"] < 2e-2  # observed 8.8e-3
    assert case["metrics"][1]["z"]["p50"] < 2e-4


def test_flux_agrees(case):
    for k in (1, 2):
        m = case["metrics"][k]
        assert m["flux_sum_ratio"] == pytest.approx(1.0, abs=0.01)
        assert m["flux_of_max"]["p99"] < 0.05


def test_approaching_side_brighter_in_both(case):
    """Prograde gas about the axis tilted towards the camera: the left half of the picture approaches."""
    cam = case["cam"]
    poly = case["poly"][1]["flux"] + case["poly"][2]["flux"]
    ref = case["ref"][1].flux + case["ref"][2].flux
    pl, pr = btd.side_brightness(poly, cam)
    rl, rr = btd.side_brightness(ref, cam)
    assert pl > 2.0 * pr and rl > 2.0 * rr
    assert pl / pr == pytest.approx(rl / rr, rel=0.01)
    # and it is blueshifted on the left in both
    for k in (1, 2):
        zp, zr = case["poly"][k]["one_plus_z"], case["ref"][k].one_plus_z
        half = cam.width // 2
        assert np.nanmedian(zp[:, :half]) < np.nanmedian(zp[:, half:])
        assert np.nanmedian(np.where(case["ref"][k].hit, zr, np.nan)[:, :half]) < \
            np.nanmedian(np.where(case["ref"][k].hit, zr, np.nan)[:, half:])


def test_ghost_present_in_both(case):
    """The order-2 image: a ring just outside the shadow, thick below the hole (the far side's ghost,
    about 1200 px here) and thin above it (12-18 px), in both images."""
    cam = case["cam"]
    H = cam.height
    for hit in (case["poly"][2]["hit"], case["ref"][2].hit):
        assert hit[: H // 2].sum() > 5 and hit[H // 2:].sum() > 800
    both = case["poly"][2]["hit"] & case["ref"][2].hit
    assert both.sum() > 0.95 * case["ref"][2].hit.sum()
    assert case["poly"][2]["flux"].sum() > 0.02 * case["poly"][1]["flux"].sum()


def test_rasterize_interpolates_vertex_attributes():
    """Extra per-vertex attributes are interpolated linearly (scalars and vectors); meshes without
    them leave NaN; the old fields are unchanged."""
    cam = raytrace.Camera.look_at([0.0, 0.0, 10.0], [0.0, 0.0, 0.0], math.radians(30.0), 16, 12, up=(0, 1, 0))
    pos = np.array([[-3.0, -3.0, 0.0], [3.0, -3.0, 0.0], [0.0, 3.0, 0.0]])
    f = lambda p: 1.0 + 0.1 * p[:, 0] - 0.2 * p[:, 1]  # noqa: E731  linear in the plane
    mesh = rasterize.RasterMesh(pos, np.array([[0, 1, 2]]), np.full(3, 10.0), 1, source_position=pos,
                                attributes={"s": f(pos), "v": np.stack([f(pos), 2 * f(pos)], axis=1)})
    other = rasterize.RasterMesh(pos + [0.0, 0.0, -1.0], np.array([[0, 1, 2]]), np.full(3, 11.0), 2)
    buf = rasterize.rasterize([mesh, other], cam)
    s, v = buf.info["attributes"]["s"], buf.info["attributes"]["v"]
    assert s.shape == (12, 16) and v.shape == (12, 16, 2)
    hit = buf.order == 1
    assert hit.sum() > 10
    np.testing.assert_allclose(s[hit], f(buf.point[hit]), atol=1e-12)
    np.testing.assert_allclose(v[hit, 1], 2 * s[hit], atol=1e-12)
    assert np.all(np.isnan(s[~hit]))
    assert "tests" in buf.info
    plain = rasterize.rasterize([other], cam)
    assert plain.info["attributes"] == {}
