"""The band of an axis patch next to the Einstein ring (grlens_addon.core.axis_patch.band_shape,
_refine_band): every point the patch draws lies within the tolerance of its exact image (lutgen.connect,
the closed-form solver, not the table), for cameras looking nearly through the hole, at rest and
moving at 0.4 c; per pixel against the reference ray tracer (frame_check.check_frame), and at points
sampled all over the patch's faces (so that no pixel grid decides which points are looked at)."""
import math

import numpy as np
import pytest

from grlens_addon.core import (axis_patch, budget, frame, frame_check, mapping, observer_view, pipeline, raytrace,
                               visibility)
from lutgen import build_lut, connect
from meshes import uv_sphere

R_OBS = 20.0
CAMERA = np.array([R_OBS, 0.0, 0.0])
HOLE = np.zeros(3)
MAX_ERROR = 0.25
# the physical-time benchmark's view (benchmarks/bench_physical_time.py): 100 deg, 480x270
WIDE = raytrace.Camera.look_at(CAMERA, HOLE, math.radians(100), 480, 270)
BETA = 0.4
CAMERAS = {"at rest": None,
           "out": BETA * np.array([0.6, 0.8 * math.cos(0.5), 0.8 * math.sin(0.5)]),
           "in": BETA * np.array([-0.6, 0.8 * math.cos(0.5), 0.8 * math.sin(0.5)])}


@pytest.fixture(scope="module")
def lut():
    return build_lut(R_OBS, 1.05, 40.0, 256, 512)


def _sphere(angle_deg):
    """The benchmarks' sphere: 0.5 r_s on the 3 r_s orbit at ``angle_deg`` (behind the hole at 180)."""
    a = math.radians(angle_deg)
    return uv_sphere([3.0 * math.cos(a), 3.0 * math.sin(a), 0.01], 0.5, 36, 18)


def _plane(tilt=0.5, half=1.0, n=10):
    """A tilted square behind the hole, crossed by the axis off its vertices."""
    u = np.linspace(-half, half, 2 * n + 1) + 0.013
    Y, Z = np.meshgrid(u, u, indexing="ij")
    pts = np.stack([-4.0 + Y * math.sin(tilt), Y * math.cos(tilt), Z], -1).reshape(-1, 3)
    i, j = (k.ravel() for k in np.meshgrid(np.arange(2 * n), np.arange(2 * n), indexing="ij"))
    m = 2 * n + 1
    a, b, c, d = i * m + j, (i + 1) * m + j, (i + 1) * m + j + 1, i * m + j + 1
    return pts, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _settings(pixel_angle):
    return pipeline.Settings(pixel_angle=pixel_angle, max_error_px=MAX_ERROR)


def _patches(pts, tris, scene, lut, pixel_angle):
    """The source's axis patches as the pipeline builds them (frame, prepared source, its sight)."""
    fr = frame.frame_context(scene, lut, _settings(pixel_angle))
    source = frame.prepare_source(fr, pipeline.SourceMesh(pts, tris))
    sight = visibility.see(fr, source, frame.map_source(fr, source))
    return axis_patch.build_patches(fr, source, sight)


def _sampled_errors(patch, order, scene, pixel_angle, samples=48, seed=0):
    """(faces, error) for the faces ``patch`` draws in ``order``: the largest distance (pixels of
    ``pixel_angle``) between where a point of the face is drawn and its exact image, over ``samples``
    points inside each face. A face is flat in the image (positions at c*dt): a point of it with
    barycentrics w is drawn in the direction of sum(w_i image_i) and shows the source point
    sum(w_i source_i) (as the renderer interpolates, perspective-correct); its exact image is
    lutgen.connect's ray of that point, aberrated for a moving camera."""
    rng = np.random.default_rng(seed)
    w = np.vstack([rng.dirichlet([1.0, 1.0, 1.0], samples // 2), rng.dirichlet([0.2, 0.2, 0.2], samples // 2)])
    im = patch.images[order]
    faces = patch.tris[patch.facing[order]]
    drawn = np.einsum("sk,fkx->fsx", w, im.position[faces]).reshape(-1, 3) - scene.camera
    drawn /= np.linalg.norm(drawn, axis=1)[:, None]
    shown = np.einsum("sk,fkx->fsx", w, patch.source_position[faces]).reshape(-1, 3)
    plane = mapping.plane_coordinates(shown, scene)
    exact = observer_view.view_directions(connect(scene.r_obs, plane.r, plane.phi, order).xi, plane.e2, scene.e1, order)
    if scene.view_beta is not None:
        exact = observer_view.aberrate(exact, scene.view_beta)
    err = np.arccos(np.clip(np.einsum("ij,ij->i", exact, drawn), -1.0, 1.0)) / pixel_angle
    err[plane.on_axis] = 0.0  # the crossing point itself (a weight of a ring corner within ~1e-9 of 1)
    return faces, err.reshape(len(faces), -1).max(axis=1)


def _band_faces(patch, faces):
    """(F,) bool: the faces between the ring and the innermost circle (a limit vertex or a vertex of
    the refined band)."""
    band = np.zeros(len(patch.source_position), bool)
    band[len(patch.source_position) - patch.band:] = True
    return (patch.limit | band)[faces].any(axis=1)


@pytest.mark.parametrize("angle", [179.0, 180.0])
@pytest.mark.parametrize("name", list(CAMERAS))
def test_pixels_next_to_the_ring_are_placed_within_the_tolerance(lut, angle, name):
    """The sphere just behind the hole seen through a wide view (the physical-time benchmark's):
    every pixel whose shown point lies inside the axis patch's innermost circle (its band next to the
    ring) and every pixel inside the patch shows a point whose exact image is within the tolerance
    of the pixel (the reference tracer's own camera, moving alike). Before the band was refined the
    moving cameras had single pixels there 0.4-0.8 px off."""
    pts, tris = _sphere(angle)
    scene = mapping.Scene(CAMERA, HOLE, 1.0, beta=CAMERAS[name])
    src = pipeline.SourceMesh(pts, tris)
    chk = frame_check.check_frame([src], scene, lut, _settings(WIDE.pixel_angle), WIDE)
    patches = [p for p in _patches(pts, tris, scene, lut, WIDE.pixel_angle) if len(p.tris)]
    assert patches and all(p.band > 0 for p in patches)
    inner = max(p.ring_radii[1] for p in patches)  # the innermost circles
    outer = max(p.radius for p in patches)
    ref, poly = chk.reference, chk.polygon
    rows, cols = np.mgrid[0:ref.shape[0], 0:ref.shape[1]]
    in_band = in_patch = 0
    for order in (1, 2):
        m = ref.hit & poly.hit & (ref.order == order) & (poly.order == order)
        col, row = raytrace.image_pixels(poly.point[m], WIDE, HOLE, 1.0, order, beta=scene.view_beta)
        err = np.hypot(col - (cols[m] + 0.5), row - (rows[m] + 0.5))
        x, y, _ = observer_view.axis_coordinates(poly.point[m], CAMERA, HOLE)
        delta = np.hypot(x, y)
        band, near = delta < inner, delta < outer
        in_band += int(band.sum())
        in_patch += int(near.sum())
        assert np.all(err[near] <= MAX_ERROR), (order, float(np.nanmax(err[near])))
    assert in_patch >= 20 and in_band >= 0  # (the band is thin: few pixel centres fall in it)


@pytest.mark.parametrize("angle", [170.5, 179.0, 180.0])
@pytest.mark.parametrize("name", list(CAMERAS))
def test_every_point_of_a_patch_is_placed_within_the_tolerance(lut, angle, name):
    """Points all over the patches' faces (clipped patches next to the sphere's limb at 170.5 deg):
    each drawn within the tolerance of its exact image, the band's faces (next to the ring) too,
    and the band's limit vertices close enough in azimuth for it (band_shape's step)."""
    pts, tris = _sphere(angle)
    scene = mapping.Scene(CAMERA, HOLE, 1.0, beta=CAMERAS[name])
    patches = [p for p in _patches(pts, tris, scene, lut, WIDE.pixel_angle) if len(p.tris)]
    assert patches
    for p in patches:
        for order in p.images:
            faces, err = _sampled_errors(p, order, scene, WIDE.pixel_angle)
            band = _band_faces(p, faces)
            assert band.sum() > 3 * p.n_azimuths
            assert err.max() <= MAX_ERROR, (order, float(err.max()), float(err[band].max()))


@pytest.mark.parametrize("beta", [None, CAMERAS["out"]])
def test_a_large_ring_on_a_plane(lut, beta):
    """A tilted plane behind the hole through a narrow view (19 deg, 640x360: the ring some 240 px
    in radius; the plain grid): every sampled point of its patch within the tolerance; the band has
    about pi ring_px / (PATCH_AIM max_error_px) limit vertices per turn (ring_px: its largest radius
    as seen, a moving camera's within 1%) and three faces for each."""
    pixel = math.radians(19.0) / 360
    pts, tris = _plane()
    scene = mapping.Scene(CAMERA, HOLE, 1.0, beta=beta)
    (p,) = _patches(pts, tris, scene, lut, pixel)
    assert p.complete and p.band > 0
    ring = p.images[1].direction[p.limit]
    ring_px = observer_view.hole_angle(ring, CAMERA, HOLE, scene.view_beta).max() / pixel
    assert ring_px > 150
    n_lim = int(p.limit.sum())
    want = math.pi * ring_px / (budget.PATCH_AIM * MAX_ERROR)
    assert 0.99 * want <= n_lim <= 1.01 * want + 2 * p.n_azimuths, (n_lim, want)
    band = _band_faces(p, p.tris)
    assert 3 * n_lim <= band.sum() <= 3 * n_lim + 6 * p.n_azimuths
    for order in p.images:
        faces, err = _sampled_errors(p, order, scene, pixel, samples=12)
        assert err.max() <= MAX_ERROR, (order, float(err.max()))


def test_band_faces_tile_the_band(lut):
    """The refined band is watertight: every edge of it off the ring is shared by two faces (the
    ring's chords, between limit vertices, once; the innermost circle's edges, once in the band and
    once in the grid's next row); its faces have positive area in the image, wound like the grid's;
    its limit vertices go round the ring in steps of at most band_shape's."""
    pts, tris = _plane()
    scene = mapping.Scene(CAMERA, HOLE, 1.0)
    (p,) = _patches(pts, tris, scene, lut, WIDE.pixel_angle)
    assert p.band > 0
    e = np.sort(np.concatenate([p.tris[:, [0, 1]], p.tris[:, [1, 2]], p.tris[:, [2, 0]]]), axis=1)
    key, count = np.unique(e, axis=0, return_counts=True)
    chord = p.limit[key].all(axis=1)
    assert np.all(count[chord] == 1) and count.max() == 2
    rim = np.hypot(*observer_view.axis_coordinates(p.source_position, CAMERA, HOLE)[:2])
    once = key[(count == 1) & ~chord]
    assert np.all(rim[once] >= p.radius * math.cos(math.pi / p.n_azimuths) * (1 - 1e-9))  # the outer circle only
    # the image's winding: the grid's faces and the band's faces touching the ring alike (seen from the
    # camera); the fan between the band's inner chain and the innermost circle may fold where the
    # circle's image lies within about twice the ring's chord sag of the chain (slivers under 0.02 px)
    d = p.images[1].direction[p.tris]
    normal = np.einsum("fx,fx->f", np.cross(d[:, 1] - d[:, 0], d[:, 2] - d[:, 0]), d.mean(axis=1))
    sign = np.sign(normal[~_band_faces(p, p.tris)])
    assert np.all(sign == sign[0])
    assert np.all(np.sign(normal[p.limit[p.tris].any(axis=1)]) == sign[0])
    ring_px = observer_view.hole_angle(p.images[1].direction[p.limit], CAMERA, HOLE).max() / WIDE.pixel_angle
    step, t, q = axis_patch.band_shape(ring_px, MAX_ERROR, p.n_azimuths)
    psi = np.sort(p.limit_psi[p.limit])
    assert np.diff(np.append(psi, psi[0] + 2 * np.pi)).max() <= step * (1 + 1e-9)
    assert 0 < t < 1 and q > 1


@pytest.mark.parametrize("q", [1.01, 1.3, 2.0, 3.0, 10.0, 1e6])
def test_interpolation_bound_of_a_piece(q):
    """band_shape's and grid_shape's bound: a piece whose corners lie at distances delta and q delta
    from the axis, at azimuths psi_0 and psi_1, draws a point with weights w at the azimuth
    sum(w delta psi) / sum(w delta) of the surface point it shows but at sum(w psi) on screen; the
    largest difference along an edge is |psi_1 - psi_0| (sqrt q - 1) / (sqrt q + 1) (by brute force
    over the weights)."""
    w = np.concatenate([np.linspace(0.0, 1.0, 200_001), np.geomspace(1e-12, 1.0, 2_000_001)])
    shown = w * q / ((1.0 - w) + w * q)
    worst = np.max(np.abs(w - shown))
    assert worst == pytest.approx((math.sqrt(q) - 1) / (math.sqrt(q) + 1), rel=1e-8)
    n, ratio = axis_patch.grid_shape(100.0, MAX_ERROR)
    s = 2 * math.pi / n
    sq = math.sqrt(ratio)
    assert 100.0 * s * (sq - 1) / (sq + 1) <= budget.PATCH_AIM * MAX_ERROR * (1 + 1e-12)
