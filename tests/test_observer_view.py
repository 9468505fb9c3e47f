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
