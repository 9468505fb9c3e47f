"""The reference ray tracer's moving camera (grlens_addon/core/raytrace.py, observer_view): a camera
moving at 0.4 c past a static sphere, with radial and tangential parts, against the static camera
at the same event looking along the exactly aberrated directions (computed here by boosting the
photons' 4-momenta with a Lorentz matrix), against the exact emitter-observer solver for where
each hit point appears, and g = 1 / (1 + z) of the hits and the sky against the photons' boosted
energies. Without a velocity (or with zero) the tracer is what it was."""
import math
import os
import sys

import numpy as np
import pytest

from grlens_addon.core import raytrace

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
import bench_accuracy as BA  # noqa: E402

HOLE = np.array([0.2, -0.1, 0.3])
R_S = 1.3  # BU
R_OBS = 12.0
CAM = raytrace.Camera.look_at(HOLE + R_S * np.array([R_OBS, 0.0, 0.0]), HOLE, math.radians(50), 72, 48)
E1 = np.array([1.0, 0.0, 0.0])
# 0.4 c: outwards (radial) and sideways (tangential) at once
BETA = 0.4 * np.array([0.6, 0.8 * math.cos(0.5), 0.8 * math.sin(0.5)])


def _scene():
    """A sphere of radius 2 r_s behind the hole and off the axis (first- and second-order hits), and
    a small one in front of it."""
    parts = []
    for centre, radius in (((-5.0, 2.5, 0.8), 2.0), ((4.0, -1.5, -0.8), 0.7)):
        local, tris = BA.uv_sphere(24, 12, radius * R_S)
        parts.append((local + HOLE + R_S * np.array(centre), tris, None))
    return raytrace.TriangleScene.concatenate(parts)


def _boost(beta):
    """4x4 Lorentz boost (t, x, y, z; c = 1) from the static frame to the frame moving with ``beta``."""
    b2 = beta @ beta
    g = 1 / math.sqrt(1 - b2)
    L = np.eye(4)
    L[0, 0] = g
    L[0, 1:] = L[1:, 0] = -g * beta
    L[1:, 1:] += (g - 1) * np.outer(beta, beta) / b2
    return L


def _static_photons(moving_dirs, beta):
    """The static frame's 4-momenta (E = 1 in the moving frame) of photons that the moving observer
    sees from ``moving_dirs`` (M, 3): boosted back with the inverse matrix."""
    p_moving = np.column_stack([np.ones(len(moving_dirs)), -moving_dirs])
    return p_moving @ _boost(-beta).T  # rows: (E_static, E_static k_static)


@pytest.fixture(scope="module")
def scene():
    return _scene()


@pytest.fixture(scope="module")
def static_trace(scene):
    return raytrace.trace(scene, CAM, HOLE, R_S)


def test_a_camera_at_rest_traces_as_before(scene, static_trace):
    """beta = 0 gives the static camera's buffers to the bit; the sky's light is blue-shifted by
    1 / sqrt(1 - r_s / r_obs), a hit's by sqrt((1 - r_s/r_hit) / (1 - r_s/r_obs)); elsewhere g is NaN."""
    still = raytrace.trace(scene, CAM, HOLE, R_S, beta=np.zeros(3))
    for name, *_ in raytrace._BUFFER_FIELDS:
        np.testing.assert_array_equal(getattr(still, name), getattr(static_trace, name), err_msg=name)
    buf = static_trace
    sky = np.isfinite(buf.sky[..., 0])
    assert sky.any() and buf.hit.any() and buf.fell.any() and (buf.order == 2).any()
    np.testing.assert_allclose(buf.g[sky], 1 / math.sqrt(1 - 1 / R_OBS), rtol=1e-15)
    r_hit = np.linalg.norm(buf.point[buf.hit] - HOLE, axis=1) / R_S
    np.testing.assert_allclose(buf.g[buf.hit], np.sqrt((1 - 1 / r_hit) / (1 - 1 / R_OBS)), rtol=1e-12)
    assert np.isnan(buf.g[buf.fell]).all()


def test_a_moving_camera_sees_what_the_static_one_sees_along_the_aberrated_directions(scene):
    """Each pixel of the camera moving at 0.4 c shows what the static observer at the same event sees
    in the pixel's direction boosted back to the static frame: the same hits at the same points, the
    same sky."""
    moving = raytrace.trace(scene, CAM, HOLE, R_S, beta=BETA)
    p = _static_photons(CAM.pixel_directions().reshape(-1, 3), BETA)
    static_dirs = -p[:, 1:] / np.linalg.norm(p[:, 1:], axis=1, keepdims=True)
    along = raytrace.trace_rays(scene, CAM.position, static_dirs, HOLE, R_S).reshape(moving.shape)
    assert moving.hit.sum() > 150 and (moving.order == 2).sum() > 5
    np.testing.assert_array_equal(moving.hit, along.hit)
    np.testing.assert_array_equal(moving.face, along.face)
    np.testing.assert_array_equal(moving.order, along.order)
    np.testing.assert_array_equal(moving.fell, along.fell)
    np.testing.assert_allclose(moving.point[moving.hit], along.point[along.hit], atol=1e-9 * R_S)
    np.testing.assert_allclose(moving.light_time[moving.hit], along.light_time[along.hit], rtol=1e-10)
    sky = np.isfinite(moving.sky[..., 0])
    np.testing.assert_allclose(moving.sky[sky], along.sky[sky], atol=1e-9)
    np.testing.assert_allclose(raytrace.escape_directions(CAM.position, CAM.pixel_directions().reshape(-1, 3), HOLE,
                                                          R_S, beta=BETA).reshape(moving.sky.shape)[sky],
                               moving.sky[sky], atol=1e-15)


def test_a_moving_camera_images_each_hit_point_at_its_pixel(scene):
    """The exact emitter-observer solver (lutgen.connect, through image_pixels) with the static
    direction aberrated by beta puts each traced hit point of order 1 and 2 back at the centre of the
    pixel that saw it; without the aberration it would be pixels off."""
    moving = raytrace.trace(scene, CAM, HOLE, R_S, beta=BETA)
    rows, cols = np.nonzero(moving.hit & (moving.order <= 2))
    for order in (1, 2):
        sel = moving.order[rows, cols] == order
        pts = moving.point[rows[sel], cols[sel]]
        col, row = raytrace.image_pixels(pts, CAM, HOLE, R_S, order, beta=BETA)
        np.testing.assert_allclose(col, cols[sel] + 0.5, atol=1e-6)
        np.testing.assert_allclose(row, rows[sel] + 0.5, atol=1e-6)
        col0, row0 = raytrace.image_pixels(pts, CAM, HOLE, R_S, order)
        assert np.nanmax(np.hypot(col0 - cols[sel] - 0.5, row0 - rows[sel] - 0.5)) > 3


def test_a_moving_camera_measures_g_of_the_boosted_photons(scene):
    """g = 1 / (1 + z) of every hit and of the sky for the moving camera: the photon's energy in the
    moving frame (1) over its energy in the static frame (the boost), times the static observers'
    gravitational shift between the hit (or infinity) and the camera. The sky is bluer the closer a
    pixel looks towards the motion."""
    moving = raytrace.trace(scene, CAM, HOLE, R_S, beta=BETA)
    e_static = _static_photons(CAM.pixel_directions().reshape(-1, 3), BETA)[:, 0].reshape(moving.shape)
    hit, sky = moving.hit, np.isfinite(moving.sky[..., 0])
    r_hit = np.linalg.norm(moving.point[hit] - HOLE, axis=1) / R_S
    np.testing.assert_allclose(moving.g[hit], np.sqrt((1 - 1 / r_hit) / (1 - 1 / R_OBS)) / e_static[hit], rtol=1e-12)
    np.testing.assert_allclose(moving.g[sky], 1 / math.sqrt(1 - 1 / R_OBS) / e_static[sky], rtol=1e-12)
    assert np.isnan(moving.g[moving.fell]).all()
    towards = CAM.pixel_directions() @ BETA  # the pixels' directions along the motion
    ahead, behind = sky & (towards > np.median(towards[sky])), sky & (towards < np.median(towards[sky]))
    assert moving.g[ahead].min() > moving.g[behind].max()


def test_a_camera_at_the_speed_of_light_is_refused(scene):
    with pytest.raises(ValueError, match="speed of light"):
        raytrace.trace(scene, CAM, HOLE, R_S, beta=np.array([0.0, 1.0, 0.0]))
    with pytest.raises(ValueError, match="speed of light"):
        raytrace.image_pixels(np.ones((1, 3)), CAM, HOLE, R_S, 1, beta=np.array([0.8, 0.8, 0.0]))
