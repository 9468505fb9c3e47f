"""The per-frame core with a moving camera (mapping.Scene.beta): a camera moving at 0.4 c past a
static sphere, with radial and tangential parts. Its image directions against the static observer's
exact directions (lutgen.connect) aberrated exactly (a Lorentz matrix acting on the photons'
4-momenta), and each image vertex's 1 + z against the boosted photon's energy and the gravitational
shift. Without a velocity the images are those of a still, attributes included."""
import math
import os
import sys

import numpy as np
import pytest

from grlens_addon.core import assemble, frame, mapping, observer_view, pipeline, thin_disc
from lutgen import LUTFamily, connect

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
import bench_accuracy as BA  # noqa: E402

R_OBS = 20.0
CAM = BA.camera(320, 180)
BETA = 0.4 * np.array([0.6, 0.8 * math.cos(0.5), 0.8 * math.sin(0.5)])  # radial and tangential parts


@pytest.fixture(scope="module")
def table():
    return LUTFamily().at(R_OBS)


def _boost(beta):
    """4x4 Lorentz boost (t, x, y, z; c = 1) from the static frame to the frame moving with ``beta``."""
    g = 1 / math.sqrt(1 - beta @ beta)
    L = np.eye(4)
    L[0, 0] = g
    L[0, 1:] = L[1:, 0] = -g * beta
    L[1:, 1:] += (g - 1) * np.outer(beta, beta) / (beta @ beta)
    return L


def _exact(img, scene, order, beta):
    """(direction the moving camera sees, energy ratio nu_moving / nu_static) of each image vertex's
    source point, from lutgen.connect's exact xi and the Lorentz matrix."""
    plane = mapping.plane_coordinates(img.source_position, scene)
    conn = connect(R_OBS, plane.r, plane.phi, order)
    d_static = observer_view.view_directions(conn.xi, plane.e2, scene.e1, order)
    p = np.column_stack([np.ones(len(d_static)), -d_static]) @ _boost(beta).T
    return -p[:, 1:] / np.linalg.norm(p[:, 1:], axis=1, keepdims=True), p[:, 0], d_static


def _directions(img, scene):
    d = img.positions - scene.camera
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _angle(a, b):
    return np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1, 1))


@pytest.mark.parametrize("angle", [45, 170])
def test_a_moving_cameras_images_are_the_exactly_aberrated_static_images(table, angle):
    """Image directions within the static images' accuracy (times the aberration's largest angular
    magnification, (1 + beta) / sqrt(1 - beta^2)); 1 + z consistent with each vertex's own image
    direction to rounding, and with the exact direction to the table's accuracy."""
    src = BA.sphere_scene(angle)[0]
    still = mapping.Scene(CAM.position, np.zeros(3), 1.0)
    moving = mapping.Scene(CAM.position, np.zeros(3), 1.0, beta=BETA)
    settings = BA.make_settings(CAM)
    static_imgs = pipeline.build_images(src, still, table, settings)
    moving_imgs = pipeline.build_images(src, moving, table, settings)
    b = np.linalg.norm(BETA)
    for order in (1, 2):
        s_img, m_img = static_imgs[order], moving_imgs[order]
        assert len(m_img.tris) > 100 and s_img.redshift is None
        _, _, d_static = _exact(s_img, still, order, BETA)
        static_err = np.nanmax(_angle(_directions(s_img, still), d_static))
        assert static_err < 1e-6
        seen, e_moving, d_static = _exact(m_img, moving, order, BETA)
        err = _angle(_directions(m_img, moving), seen)
        assert np.nanmax(err) <= (1 + b) / math.sqrt(1 - b * b) * static_err + 1e-12
        # 1 + z = nu_emitted / nu_seen: the gravitational shift from the source point to the camera,
        # over the photon's energy in the moving frame (per unit energy in the static frame)
        r = np.linalg.norm(m_img.source_position, axis=1)
        exact = np.sqrt((1 - 1 / R_OBS) / (1 - 1 / r)) / e_moving
        np.testing.assert_allclose(m_img.redshift, exact, rtol=1e-6)
        # the same with the image's own direction (taken back to the static frame with the matrix)
        p = np.column_stack([np.ones(len(r)), -_directions(m_img, moving)]) @ _boost(-BETA).T  # static momenta
        np.testing.assert_allclose(m_img.redshift, np.sqrt((1 - 1 / R_OBS) / (1 - 1 / r)) * p[:, 0], rtol=1e-12)
        assert m_img.redshift.min() > 1  # deeper in the well than the camera, which moves away from it


def test_a_camera_at_rest_with_physical_time_shifts_light_by_gravity_alone(table):
    """beta = 0: the same images as a still to the bit, and every vertex's 1 + z is
    sqrt((1 - r_s/r_obs) / (1 - r_s/r))."""
    src = BA.sphere_scene(45)[0]
    settings = BA.make_settings(CAM)
    still = pipeline.build_images(src, mapping.Scene(CAM.position, np.zeros(3), 1.0), table, settings)
    rest = pipeline.build_images(src, mapping.Scene(CAM.position, np.zeros(3), 1.0, beta=np.zeros(3)), table, settings)
    for order in (1, 2):
        for name in ("positions", "tris", "corner_uv", "light_travel_time", "source_position"):
            np.testing.assert_array_equal(getattr(rest[order], name), getattr(still[order], name))
        r = np.linalg.norm(rest[order].source_position, axis=1)
        np.testing.assert_allclose(rest[order].redshift, np.sqrt((1 - 1 / R_OBS) / (1 - 1 / r)), rtol=1e-14)
        assert rest[order].redshift.min() > 1  # light climbing from deeper in the well than the camera


def test_the_discs_1_plus_z_includes_the_cameras_motion(table):
    """A thin disc seen by the moving camera: 1 + z is the static observer's (thin_disc, from the
    exact static direction) over the camera's Doppler factor (the photon's boosted energy)."""
    disc = frame.DiscEmitter(axis=np.array([0.0, 0.1, 1.0]))
    pts = []
    for rr in np.linspace(3.2, 12, 12):
        a = np.linspace(0, 2 * np.pi, 48, endpoint=False)
        pts.append(np.column_stack([rr * np.cos(a), rr * np.sin(a), -0.1 * rr * np.sin(a)]))
    pts = np.concatenate(pts)
    moving = mapping.Scene(CAM.position, np.zeros(3), 1.0, beta=BETA)
    mp = mapping.Mapper(moving, table)
    for order in (1, 2):
        img = mp.images(pts, (order,))[order]
        ok = img.valid
        got = assemble.image_redshift(moving, pts[ok], img.direction[ok], disc)
        conn = connect(R_OBS, img.plane.r[ok], img.plane.phi[ok], order)
        d_static = observer_view.view_directions(conn.xi, img.plane.e2[ok], moving.e1, order)
        static_z = thin_disc.vertex_redshift_from_direction(pts[ok], np.zeros(3), CAM.position, 1.0, disc.axis,
                                                            d_static, disc.prograde)
        e_moving = (np.column_stack([np.ones(ok.sum()), -d_static]) @ _boost(BETA).T)[:, 0]
        np.testing.assert_allclose(got, static_z / e_moving, rtol=1e-6)


def test_a_camera_at_or_above_the_speed_of_light_is_refused():
    for bad in ([1.0, 0, 0], [0.9, 0.5, 0.0], [np.nan, 0, 0]):
        with pytest.raises(ValueError, match="speed of light"):
            mapping.Scene(CAM.position, np.zeros(3), 1.0, beta=bad)


def test_with_aberration_off_a_moving_camera_sees_the_static_directions_and_shifted_light(table):
    """Scene.aberration False (for teaching): the images are the still's, to the bit; 1 + z is the
    moving camera's for those (static) directions; the gravitational part is written beside it."""
    src = BA.sphere_scene(170)[0]
    settings = BA.make_settings(CAM)
    still = pipeline.build_images(src, mapping.Scene(CAM.position, np.zeros(3), 1.0), table, settings)
    off = pipeline.build_images(src, mapping.Scene(CAM.position, np.zeros(3), 1.0, beta=BETA, aberration=False),
                                table, settings)
    for order in (1, 2):
        np.testing.assert_array_equal(off[order].positions, still[order].positions)
        d = _directions(off[order], mapping.Scene(CAM.position, np.zeros(3), 1.0))
        r = np.linalg.norm(off[order].source_position, axis=1)
        grav = np.sqrt((1 - 1 / R_OBS) / (1 - 1 / r))
        e_moving = (np.column_stack([np.ones(len(d)), -d]) @ _boost(BETA).T)[:, 0]
        np.testing.assert_allclose(off[order].redshift, grav / e_moving, rtol=1e-12)
        np.testing.assert_allclose(off[order].redshift_gravity, grav, rtol=1e-14)
        assert still[order].redshift_gravity is None


def test_a_moving_cameras_axis_patch_is_sized_by_the_ring_it_sees(table):
    """The sphere right behind the hole (180 degrees): the axis patch's grid follows the Einstein ring as
    the moving camera sees it, the static radius times the aberration's local scale (which varies
    about the ring), not one azimuth's value: a camera moving towards the hole's side sees the ring
    shrunk (scale below 1) and needs no more patch faces than at rest, one moving away at most
    scale^2 times as many (the scale at the hole's direction, with 20 % for its variation about the
    ring); with a negligible speed, the same patch as at rest. Every patch vertex's image is still
    the exactly aberrated static one."""
    src = BA.sphere_scene(180)[0]
    settings = BA.make_settings(CAM)
    hole_dir = -np.asarray(CAM.position) / np.linalg.norm(CAM.position)

    def faces(beta):
        scene = mapping.Scene(CAM.position, np.zeros(3), 1.0, beta=beta)
        fr = pipeline.frame_context(scene, table, settings, None, CAM.frustum_planes())
        st = pipeline.run_stages(fr, src)
        return sum(len(p.tris) for p in st.patches)

    rest = faces(None)
    assert rest > 100
    assert faces(1e-9 * BETA / np.linalg.norm(BETA)) == rest
    for sign in (1.0, -1.0):
        beta = BETA * np.array([sign, 1.0, 1.0])
        scale = observer_view.magnification(observer_view.aberrate(hole_dir[None], beta), beta)[0]
        n = faces(beta)
        assert (scale < 1) == (sign < 0)
        assert n <= rest * max(1.0, 1.2 * scale) ** 2, (sign, n, rest, scale)


@pytest.mark.parametrize("angle", [45, 170, 180])
def test_exact_redshift_gives_1_plus_z_to_1e_9_with_exact_velocities(table, angle):
    """Settings.exact_redshift: each image vertex's 1 + z from its exact connecting ray
    (lutgen.solver.refine_xi) within 1e-9 relative of the exact value (the Lorentz matrix acting on
    lutgen.connect's direction), Einstein-ring vertices included (180 degrees: their 1 + z is the
    source point's own); the geometry is the same as without it. Without it the table's direction
    error (about 1e-7 rad, times beta) shows."""
    src = BA.sphere_scene(angle)[0]
    moving = mapping.Scene(CAM.position, np.zeros(3), 1.0, beta=BETA)
    settings = BA.make_settings(CAM)
    plain = pipeline.build_images(src, moving, table, settings)
    settings.exact_redshift = True
    exact_imgs = pipeline.build_images(src, moving, table, settings)
    worst_plain = 0.0
    for order in (1, 2):
        img = exact_imgs[order]
        np.testing.assert_array_equal(img.positions, plain[order].positions)
        np.testing.assert_array_equal(img.tris, plain[order].tris)
        plane = mapping.plane_coordinates(img.source_position, moving)
        # a point on the axis has a ring of images: a drawn ring vertex keeps its drawn azimuth
        drawn = observer_view.unaberrate(_directions(img, moving), BETA)
        e2_drawn = observer_view.ray_planes(drawn, moving.e1)[3] * (1.0 if order == 1 else -1.0)
        on_axis = plane.r * np.sin(plane.phi) < 1e-6
        e2 = np.where(on_axis[:, None], e2_drawn, plane.e2)
        d_static = observer_view.view_directions(connect(R_OBS, plane.r, plane.phi, order).xi, e2, moving.e1,
                                                 order)
        e_moving = (np.column_stack([np.ones(len(d_static)), -d_static]) @ _boost(BETA).T)[:, 0]
        r = np.linalg.norm(img.source_position, axis=1)
        exact = np.sqrt((1 - 1 / R_OBS) / (1 - 1 / r)) / e_moving
        np.testing.assert_allclose(img.redshift, exact, rtol=1e-9)
        if angle == 180:
            assert on_axis.sum() > 50  # the rings' vertices are checked too
        worst_plain = max(worst_plain, np.max(np.abs(plain[order].redshift / exact - 1)))
    assert worst_plain > 1e-9


def test_exact_redshift_of_a_thin_disc_seen_by_a_moving_camera(table):
    disc = frame.DiscEmitter(axis=np.array([0.0, 0.1, 1.0]))
    a = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    pts = np.concatenate([np.column_stack([rr * np.cos(a), rr * np.sin(a), -0.1 * rr * np.sin(a)])
                          for rr in np.linspace(3.2, 12, 12)])
    moving = mapping.Scene(CAM.position, np.zeros(3), 1.0, beta=BETA)
    mp = mapping.Mapper(moving, table)
    for order in (1, 2):
        img = mp.images(pts, (order,))[order]
        ok = img.valid
        got = assemble.image_redshift(moving, pts[ok], img.direction[ok], disc, exact_order=order)
        conn = connect(R_OBS, img.plane.r[ok], img.plane.phi[ok], order)
        d_static = observer_view.view_directions(conn.xi, img.plane.e2[ok], moving.e1, order)
        static_z = thin_disc.vertex_redshift_from_direction(pts[ok], np.zeros(3), CAM.position, 1.0, disc.axis,
                                                            d_static, disc.prograde)
        e_moving = (np.column_stack([np.ones(ok.sum()), -d_static]) @ _boost(BETA).T)[:, 0]
        np.testing.assert_allclose(got, static_z / e_moving, rtol=1e-9)
