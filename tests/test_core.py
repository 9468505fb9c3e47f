"""Add-on numeric core (no bpy): mapping, subdivision, culling, illumination.

Units: world positions in Blender units (BU); r_s in BU; the LUT in r_s and r_s/c.
"""
import numpy as np
import pytest

from grlens_addon.core import culling, illumination, mapping, observer_view, subdivision
from lutgen import build_lut, connect
from meshes import uv_sphere

R_S = 2.0  # BU, as in seed 000's scenes
CAMERA = np.array([40.0, 0.0, 0.0])  # r_obs = 20 r_s
HOLE = np.zeros(3)


@pytest.fixture(scope="module")
def lut():
    return build_lut(20.0, 1.05, 40.0, 256, 512)


def random_points(n, rng, r_lo=2.5, r_hi=30.0):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    return d * rng.uniform(r_lo, r_hi, n)[:, None]


def test_mapping_matches_connect(lut):
    """Image direction and distance agree with lutgen.connect in each vertex's own plane."""
    rng = np.random.default_rng(0)
    pts = random_points(3000, rng)
    scene = mapping.Scene(CAMERA, HOLE, R_S)
    for order in (1, 2):
        img = mapping.map_vertices(pts, scene, lut, order)
        r = np.linalg.norm(pts, axis=1) / R_S
        e1 = CAMERA / np.linalg.norm(CAMERA)
        phi = np.arccos(np.clip(pts @ e1 / np.linalg.norm(pts, axis=1), -1, 1))
        c = connect(20.0, r, phi, order)
        look = lut.lookup(r, phi, order)
        assert np.all(img.valid)
        # exactly the LUT's values in the vertex's plane ...
        np.testing.assert_allclose(img.distance, look.dt * R_S, rtol=1e-12)
        ang = np.arccos(np.clip(img.direction @ e1, -1, 1))  # angle from the outward radial e1
        np.testing.assert_allclose(ang, look.xi, atol=1e-7)
        # ... which are the exact rays up to the table's interpolation error (this table spans
        # r_obs, where points pass close to the camera and the interpolation is at its worst)
        np.testing.assert_allclose(img.distance, c.dt * R_S, rtol=1e-4)
        np.testing.assert_allclose(ang, c.xi, atol=1e-4)
        # first-order images lie on the vertex's side of the axis, second-order on the other
        side = np.einsum("ij,ij->i", img.direction - (img.direction @ e1)[:, None] * e1, img.plane.e2)
        assert np.all(side > 0) if order == 1 else np.all(side < 0)
        np.testing.assert_allclose(np.linalg.norm(img.position - CAMERA, axis=1), img.distance, rtol=1e-12)


def test_flat_space_limit():
    """With a tiny hole (r_s -> 0 in BU) first-order images sit at the vertices themselves: here the
    camera is 1e5 r_s from the hole and the points 4e4..8e4 r_s, so the deflection (~2 r_s/b) is below
    1e-4 rad."""
    r_s = 1e-5
    cam = np.array([1e5 * r_s, 0, 0])
    far = build_lut(1e5, 3e4, 9e4, 128, 256)
    rng = np.random.default_rng(1)
    pts = random_points(500, rng, 4e4 * r_s, 8e4 * r_s)
    img = mapping.map_vertices(pts, mapping.Scene(cam, HOLE, r_s), far, 1)
    assert img.valid.all()
    err = np.linalg.norm(img.position - pts, axis=1) / np.linalg.norm(pts - cam, axis=1)
    assert np.percentile(err, 99) < 1e-3


def test_bad_vertices_are_invalid_not_errors(lut):
    scene = mapping.Scene(CAMERA, HOLE, R_S)
    pts = np.array([[np.nan, 0, 0], [np.inf, 1, 1], [1.0, 0.2, 0.1], [-10.0, 0.0, 0.0], [100.0, 0, 3]])
    img = mapping.map_vertices(pts, scene, lut, 1)
    # NaN, inf, inside the horizon (r = 0.5 r_s), on the axis behind the hole, outside the LUT
    assert not img.valid.any()
    assert np.all(np.isnan(img.position))


def test_lut_mismatch_and_bad_scene(lut):
    with pytest.raises(ValueError, match="rebuild"):
        mapping.map_vertices(np.zeros((1, 3)) + 5, mapping.Scene([30.0, 0, 0], HOLE, R_S), lut, 1)
    with pytest.raises(ValueError, match="rebuild"):  # beyond the tolerance
        mapping.map_vertices(np.zeros((1, 3)) + 5, mapping.Scene(CAMERA * (1 + 3e-6), HOLE, R_S), lut, 1)
    # float32 jitter of a camera transform (~1e-7) is accepted, with a negligible change of the image
    p = np.array([[-6.0, 3.0, 1.0]])
    exact = mapping.map_vertices(p, mapping.Scene(CAMERA, HOLE, R_S), lut, 1)
    jitter = mapping.map_vertices(p, mapping.Scene(CAMERA * (1 + 2e-7), HOLE, R_S), lut, 1)
    assert np.degrees(np.arccos(np.clip(exact.direction[0] @ jitter.direction[0], -1, 1))) < 1e-4
    with pytest.raises(ValueError):
        mapping.Scene(CAMERA, HOLE, 0.0)
    with pytest.raises(ValueError):
        mapping.Scene([np.nan, 0, 0], HOLE, 1.0)


def _octahedron():
    P = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    T = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return P, T


def _directed_edge_counts(f):
    d = np.stack([f, np.roll(f, -1, 1)], 2).reshape(-1, 2)
    und = np.sort(d, axis=1)
    return np.unique(d, axis=0, return_counts=True)[1], np.unique(und, axis=0, return_counts=True)[1]


@pytest.mark.parametrize("seed", range(6))
def test_subdivision_is_watertight_for_any_levels(seed):
    """A closed source stays closed: every edge of the result has exactly two faces, in opposite
    directions (consistent winding), Euler characteristic 2, area unchanged."""
    P, T = _octahedron()
    E = subdivision.mesh_edges(T)
    levels = np.random.default_rng(seed).integers(1, 65, len(E.verts))
    S = subdivision.subdivide(P, T, E, levels)
    directed, undirected = _directed_edge_counts(S.tris)
    assert directed.max() == 1 and np.all(undirected == 2)
    n_e = len(undirected)
    assert len(S.positions) - n_e + len(S.tris) == 2
    cross = np.cross(S.positions[S.tris[:, 1]] - S.positions[S.tris[:, 0]],
                     S.positions[S.tris[:, 2]] - S.positions[S.tris[:, 0]])
    assert 0.5 * np.linalg.norm(cross, axis=1).sum() == pytest.approx(4 * np.sqrt(3), rel=1e-12)
    # barycentrics reproduce the positions
    src = P[T[S.source_tri]]
    corners = np.einsum("fck,fkx->fcx", S.bary, src)
    np.testing.assert_allclose(corners, S.positions[S.tris], atol=1e-12)
    # corner values (UVs, normals) carried through the shared rows: the positions again, as values
    np.testing.assert_allclose(S.corner_values(P[T]), S.positions[S.tris], atol=1e-12)
    assert len(S.row_bary) < 0.75 * 3 * len(S.tris)  # corners are shared: fewer rows than face corners


def test_corner_values_of_unsplit_triangles_are_taken_as_they_are():
    """Subdivided.n_unit_rows: the rows of the triangles left whole come first, with unit barycentrics;
    their corner values are the source's to the bit (no interpolation), the split ones' interpolated."""
    P, T = _octahedron()
    E = subdivision.mesh_edges(T)
    levels = np.ones(len(E.verts), np.int64)
    levels[E.of_tri[:2].ravel()] = 7  # triangles 0 and 1 split, those sharing no edge with them whole
    S = subdivision.subdivide(P, T, E, levels)
    whole = np.flatnonzero(levels[E.of_tri].max(axis=1) == 1)
    assert whole.size > 0 and S.n_unit_rows == 3 * whole.size
    np.testing.assert_array_equal(S.row_bary[:S.n_unit_rows], np.tile(np.eye(3), (whole.size, 1)))
    values = np.random.default_rng(2).normal(size=(len(T), 3, 2)) * 1e3
    got = S.corner_values(values)
    np.testing.assert_array_equal(got[:S.n_pass], values[S.source_tri[:S.n_pass]])
    expect = np.einsum("fck,fkx->fcx", S.bary, values[S.source_tri])
    np.testing.assert_allclose(got, expect, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("seed", range(6))
def test_subdivision_strips_are_watertight_and_linear_in_the_levels(seed):
    """Strips (subdivide(..., strips=)) on some triangles, the uniform grid on the others: still
    closed and consistently wound, area unchanged, barycentrics right, and a strip triangle with side
    levels l1, l2, l3 makes l1 + l2 + l3 - 2 faces with no interior vertex."""
    rng = np.random.default_rng(seed)
    P, T = _octahedron()
    P = P + rng.normal(0, 0.05, P.shape)
    E = subdivision.mesh_edges(T)
    levels = rng.integers(1, 20, len(E.verts)) if seed % 2 else rng.choice([1, 2, 3, 40], len(E.verts))
    mask = rng.random(len(T)) < 0.7
    xy = P[:, :2] + np.array([3.0, 0.5]) * (seed % 3 > 0)  # the origin inside some triangles' projections or beside all
    S = subdivision.subdivide(P, T, E, levels, strips=(mask, xy))
    directed, undirected = _directed_edge_counts(S.tris)
    assert directed.max() == 1 and np.all(undirected == 2)
    assert len(S.positions) - len(undirected) + len(S.tris) == 2
    def area(X, F):
        return 0.5 * np.linalg.norm(np.cross(X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]]), axis=1)

    np.testing.assert_allclose(np.bincount(S.source_tri, area(S.positions, S.tris), len(T)), area(P, T), rtol=1e-9)
    np.testing.assert_allclose(np.einsum("fck,fkx->fcx", S.bary, P[T[S.source_tri]]), S.positions[S.tris], atol=1e-12)
    np.testing.assert_allclose(S.corner_values(P[T]), S.positions[S.tris], atol=1e-12)
    side = levels[E.of_tri]
    counts = np.bincount(S.source_tri, minlength=len(T))
    _, a, _, b = subdivision._strip_corners(T, xy)
    strip = mask & (side[np.arange(len(T)), subdivision._slot(a, b)] > 1)
    np.testing.assert_array_equal(counts[strip], side[strip].sum(axis=1) - 2)
    # a face of a strip triangle has its corners on the triangle's sides
    f = np.flatnonzero(strip[S.source_tri])
    assert np.all((S.bary[f] < 1e-12).any(axis=2))
    uniform = S.source_tri[~strip[S.source_tri]]
    assert np.all(counts[np.unique(uniform)] >= 1)


def test_subdivision_strips_fall_back_to_the_grid_without_finite_coordinates():
    """A strip triangle with a corner whose 2-D coordinates are not finite is split on the uniform grid,
    so the result is the same as without strips for it (and still closed)."""
    P, T = _octahedron()
    E = subdivision.mesh_edges(T)
    levels = np.full(len(E.verts), 5)
    xy = P[:, :2] + 3.0
    xy[4] = np.nan  # the top vertex: triangles 0-3
    S = subdivision.subdivide(P, T, E, levels, strips=(np.ones(len(T), bool), xy))
    directed, undirected = _directed_edge_counts(S.tris)
    assert directed.max() == 1 and np.all(undirected == 2)
    counts = np.bincount(S.source_tri, minlength=len(T))
    assert np.all(counts[:4] == 25) and np.all(counts[4:] == 13)  # grid 5^2; strips 5 + 5 + 5 - 2


def test_within_axis_distance_agrees_with_axis_distance():
    """The box-filtered test gives exactly axis_distance <= limit: random triangles around the axis,
    ones the axis passes through, ones beside it whose corners are all farther than the limit although
    an edge passes closer, and a corner with NaN coordinates (never excluded by the box)."""
    rng = np.random.default_rng(5)
    x, y = rng.uniform(-2, 2, 3000), rng.uniform(-2, 2, 3000)
    x[:3], y[:3] = [1.0, -1.0, 1.0], [0.2, 0.2, 5.0]  # edge (1, 0.2)-(-1, 0.2) passes at 0.2
    x[3] = np.nan
    tris = np.vstack([[0, 1, 2], [3, 4, 5], rng.integers(0, 3000, (4000, 3))])
    for limit in (0.1, 0.3, 1.0):
        with np.errstate(invalid="ignore"):
            expect = observer_view.axis_distance(x, y, tris) <= limit
        np.testing.assert_array_equal(observer_view.within_axis_distance(x, y, tris, limit), expect)
    assert observer_view.within_axis_distance(x, y, tris[:1], 0.3)[0]
    assert not observer_view.within_axis_distance(x, y, tris[:1], 0.1)[0]


def test_subdivision_levels_and_rho():
    lv = subdivision.edge_levels(np.array([0.0, 1e-4, 0.01, 0.05, 1.0, np.nan]), 64, 5.0, 0.75)
    assert list(lv) == [1, 1, 11, 34, 64, 1]  # ceil(64 * min(1, 5 rho^0.75)): 0.3, 10.1, 33.8, 320
    assert list(subdivision.edge_levels(np.array([1.0]), 200, 5.0, 0.75)) == [64]  # capped at 64
    # an edge spanning 3.5 pixels never gets more than 4 segments
    capped = subdivision.edge_levels(np.array([1.0, 1.0]), 64, 5.0, 0.75, chord=np.array([3.5e-3, 0.0]),
                                     pixel_angle=1e-3)
    assert list(capped) == [4, 1]
    # a straight mapping has rho = 0; a circle arc through 90 degrees has rho = (1 - cos45)/(2 sin45)
    a, b = np.array([[1.0, 0, 0]]), np.array([[0.0, 1, 0]])
    assert subdivision.rho(a, b, 0.5 * (a + b))[0] == 0
    m = np.array([[np.sqrt(0.5), np.sqrt(0.5), 0]])
    assert subdivision.rho(a, b, m)[0] == pytest.approx((1 - np.sqrt(0.5)) / np.sqrt(2))
    # uniform level-1 subdivision is the identity
    P, T = _octahedron()
    E = subdivision.mesh_edges(T)
    S = subdivision.subdivide(P, T, E, np.ones(len(E.verts), np.int64))
    assert len(S.tris) == 8 and len(S.positions) == 6


def test_culling_reasons():
    cam = np.zeros(3)
    src = np.array([[10.0, -1, 0], [10, 1, 0], [10, 0, 1], [10, 0, 1], [10, 0, 1], [-10, 0, 0]])
    dirs = observer_view.unit_directions(src, cam)
    dirs_img = dirs.copy()
    dirs_img[4] = [0.0, 0.0, 1.0]  # this vertex's image jumped far away (axis straddling)
    valid = np.ones(6, bool)
    valid[5] = False
    tris = np.array([[0, 1, 2], [0, 1, 4], [0, 1, 5], [2, 3, 4 - 1]])
    keep, rep = culling.cull(tris, dirs_img, valid, src, cam, cull_ratio=3.0)
    assert list(keep) == [True, False, False, False]
    assert (rep.invalid_vertex, rep.einstein_ring, rep.degenerate_source, rep.kept) == (1, 1, 1, 1)
    planes = np.array([[-1.0, 0, 0, 5.0]])  # keep x <= 5: everything at x = 10 is outside
    keep, rep = culling.cull(tris[:1], dirs, valid, src, cam, 3.0, planes, src)
    assert not keep[0] and rep.outside_frustum == 1


def test_illumination_flat_limit_and_shadowing():
    """Far from a tiny hole, order-1 irradiance is I0 max(0, n.d)/|L - p|^2 with d towards the light."""
    r_s = 1e-5
    light = np.array([1e5 * r_s, 0.0, 0.0])
    lut_l = build_lut(1e5, 3e4, 9e4, 128, 256)
    rng = np.random.default_rng(4)
    pts = random_points(400, rng, 4e4 * r_s, 8e4 * r_s)
    normals = rng.normal(size=(400, 3))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    tot, parts = illumination.irradiance(pts, normals, light, HOLE, r_s, lut_l, intensity=2.0, orders=(1,))
    to_l = light - pts
    dist = np.linalg.norm(to_l, axis=1)
    expect = 2.0 * np.maximum(0, np.einsum("ij,ij->i", normals, to_l / dist[:, None])) / dist**2
    ok = expect > 1e-2 * expect.max()
    np.testing.assert_allclose(tot[ok], expect[ok], rtol=2e-3)
    assert np.all(tot[expect == 0] < 1e-3 * expect.max())


def test_leaving_in_plane_is_the_leaving_direction_unnormalised(lut):
    """illumination.leaving_in_plane's (a, b) point along leaving_direction: (a e1 + b e2) / |.| is it,
    for both orders, and NaN where the ray is (outside the LUT's range)."""
    rng = np.random.default_rng(7)
    pts = np.concatenate([random_points(300, rng, 2.5, 60.0), [[100.0, 0.0, 0.0]]])  # 1.25-30 r_s, 50 r_s
    scene = mapping.Scene(CAMERA, HOLE, R_S)
    plane = mapping.plane_coordinates(pts, scene)
    for o in (1, 2):
        look = lut.lookup(plane.r, plane.phi, o, quantities=("ux", "uy"))
        d = illumination.leaving_direction(plane, scene, look.ux, look.uy)
        a, b = illumination.leaving_in_plane(plane, look.ux, look.uy)
        v = a[:, None] * scene.e1 + b[:, None] * plane.e2
        ok = np.isfinite(d).all(axis=1)
        assert ok.sum() == len(pts) - 1 and np.isnan(a[~ok]).all() and np.isnan(b[~ok]).all()
        np.testing.assert_allclose(v[ok] / np.linalg.norm(v[ok], axis=1)[:, None], d[ok], atol=1e-12)


def test_illumination_back_side_gets_only_light_around_the_hole(lut):
    """A point behind the hole, facing away from the light, still receives second-order light."""
    light = CAMERA  # r = 20 r_s, same LUT
    p = np.array([[-8.0, 0.5, 0.0]])
    n = np.array([[1.0, 0.0, 0.0]])  # facing the hole/light side
    tot, parts = illumination.irradiance(p, n, light, HOLE, R_S, lut)
    assert parts[1][0] > 0 and parts[2][0] > 0 and parts[2][0] < parts[1][0]


def test_error_cap_keeps_sub_edges_within_tolerance():
    """Circular arcs (radius R pixels, opening angle theta): the level chosen with max_error_px keeps
    each straight piece within the tolerance of the arc (up to the s/n^2 approximation), and is
    never above the paper's level (eq. 19) or the edge's pixel count."""
    pixel = 1e-3  # radians per pixel
    tol = 0.25
    for R_px in (20.0, 200.0, 2000.0):
        for theta in np.radians([5.0, 20.0, 60.0, 90.0]):
            chord_px = 2 * R_px * np.sin(theta / 2)
            sagitta_px = R_px * (1 - np.cos(theta / 2))
            rho = np.array([sagitta_px / chord_px])
            n = subdivision.edge_levels(rho, 64, 5.0, 0.75, np.array([chord_px * pixel]), pixel, tol)[0]
            paper = subdivision.edge_levels(rho, 64, 5.0, 0.75)[0]
            assert n <= paper and n <= np.ceil(chord_px)
            if n < paper:  # the cap was active: the pieces are within tolerance, one level less is not
                piece = R_px * (1 - np.cos(theta / (2 * n)))
                assert piece <= 1.25 * tol
                if n > 1:
                    assert R_px * (1 - np.cos(theta / (2 * (n - 1)))) > 0.75 * tol


def _sphere(centre, radius=0.5 * R_S, segments=24, rings=12):
    return uv_sphere(centre, radius, segments, rings)


def test_pipeline_images_are_the_exact_images_of_their_source_points(lut):
    """Every vertex of both image meshes (corners and the subdivision's new vertices, which reuse or
    redo the LUT lookup) shows its source point: direction and distance agree with lutgen.connect."""
    from grlens_addon.core import pipeline

    pts, tris = _sphere(np.array([-3.0 * R_S * np.cos(0.4), 3.0 * R_S * np.sin(0.4), 0.02]))
    scene = mapping.Scene(CAMERA, HOLE, R_S)
    settings = pipeline.Settings(pixel_angle=np.radians(19.0) / 1080)  # fine pixels: real subdivision
    out = pipeline.build_images(pipeline.SourceMesh(pts, tris), scene, lut, settings)
    e1 = scene.e1
    for order, img in out.items():
        assert len(img.tris) > len(tris)  # subdivided
        assert len(img.source_position) == len(img.positions) > len(pts)
        p = img.source_position
        r = np.linalg.norm(p, axis=1) / R_S
        phi = np.arccos(np.clip(p @ e1 / np.linalg.norm(p, axis=1), -1, 1))
        c = connect(20.0, r, phi, order)
        ang = np.arccos(np.clip((img.positions - CAMERA) @ e1 / img.light_travel_time, -1, 1))
        np.testing.assert_allclose(ang, c.xi, atol=2e-5)
        np.testing.assert_allclose(img.light_travel_time, c.dt * R_S, rtol=2e-5)


def test_pipeline_skips_off_screen_and_sub_pixel_work(lut):
    """Source triangles mapped wholly outside a frustum plane are not subdivided (counted as
    outside_frustum); a second-order image smaller than a pixel is not built (counted as below_pixel)."""
    from grlens_addon.core import pipeline

    pts, tris = _sphere(np.array([-3.0 * R_S, 1.0 * R_S, 0.02]))
    scene = mapping.Scene(CAMERA, HOLE, R_S)
    settings = pipeline.Settings(pixel_angle=np.radians(19.0) / 1080)
    full = pipeline.build_images(pipeline.SourceMesh(pts, tris), scene, lut, settings)
    # keep only what is seen at z >= 0 from the camera (a plane through the camera)
    planes = np.array([[0.0, 0.0, 1.0, 0.0]])
    half = pipeline.build_images(pipeline.SourceMesh(pts, tris), scene, lut, settings, frustum_planes=planes)
    for order in (1, 2):
        assert half[order].report.outside_frustum > 0
        assert 0 < len(half[order].tris) < len(full[order].tris)
        assert np.all(half[order].positions[half[order].tris][:, :, 2].max(axis=1) >= 0)
        # everything kept is exactly what the full build has there
        f = full[order]
        inside = (f.positions[f.tris][:, :, 2] >= 0).all(axis=1)
        assert inside.sum() <= len(half[order].tris)
    # a tiny far sphere at a coarse resolution: order 2 is below a pixel, order 1 is not
    tiny_pts, tiny_tris = _sphere(np.array([-15.0 * R_S, 6.0 * R_S, 0.0]), radius=0.01 * R_S)
    coarse = pipeline.Settings(pixel_angle=np.radians(19.0) / 120)
    out = pipeline.build_images(pipeline.SourceMesh(tiny_pts, tiny_tris), scene, lut, coarse)
    assert len(out[2].tris) == 0 and out[2].report.below_pixel == len(tiny_tris)
    assert out[1].report.below_pixel == 0 and len(out[1].tris) > 0  # order 1 always built


def test_axis_geometry_straddling_and_span():
    cam, hole = CAMERA, HOLE  # axis = x axis
    pts = np.array([[-5.0, -1, -1], [-5, 1, -1], [-5, 0, 1],  # behind the hole, around the axis
                    [5.0, -1, -1], [5, 1, -1], [5, 0, 1],  # in front of the hole, around the axis
                    [-5.0, 1, 0], [-5, 2, 0], [-5, 0, 1]])  # beside the axis: covers 90 degrees
    tris = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]])
    s1, span = observer_view.axis_geometry(pts, tris, cam, hole, 1)
    s2, _ = observer_view.axis_geometry(pts, tris, cam, hole, 2)
    assert list(s1) == [True, False, False] and list(s2) == [True, True, False]
    np.testing.assert_allclose(span, [np.pi, np.pi, np.pi / 2])


def test_side_azimuths_are_the_angles_between_the_corners_about_the_axis():
    """observer_view.side_azimuths (from each corner point's azimuth, once): the unsigned angle about the
    axis between consecutive corners, as atan2(|a x b|, a . b) of the projected corners gives it, also
    across the -pi / pi cut; NaN for a corner without coordinates."""
    rng = np.random.default_rng(5)
    x, y = rng.normal(size=(2, 200))
    tris = rng.integers(0, 200, (500, 3))
    got = observer_view.side_azimuths(x, y, tris)
    px, py = x[tris], y[tris]
    qx, qy = px[:, [1, 2, 0]], py[:, [1, 2, 0]]
    np.testing.assert_allclose(got, np.abs(np.arctan2(px * qy - py * qx, px * qx + py * qy)), atol=1e-12)
    across = observer_view.side_azimuths(np.array([-1.0, -1.0, 1.0]), np.array([0.1, -0.1, 0.0]), np.array([[0, 1, 2]]))
    np.testing.assert_allclose(across[0, 0], 2 * np.arctan(0.1), rtol=1e-12)
    x[3] = np.nan
    assert np.isnan(observer_view.side_azimuths(x, y, np.array([[3, 4, 5]]))[0, [0, 2]]).all()
    x[3] = y[3] = 0.0  # a corner on the axis
    np.testing.assert_array_equal(observer_view.side_azimuths(x, y, np.array([[3, 4, 5]]))[0, [0, 2]], 0.0)


def test_fine_mesh_behind_the_hole_keeps_its_ring(lut):
    """Behind the hole a fine mesh is magnified everywhere: the triangles at the axis are replaced by
    the axis patch (axis_patch.py), few or none are culled, the ring stays closed, and no kept triangle
    spans a wide arc (its straight sides would cut into the ring: culling allows
    the tolerance, 0.25 px, about 6.4 degrees at this size)."""
    from grlens_addon.core import pipeline

    scene = mapping.Scene(CAMERA, HOLE, R_S)
    settings = pipeline.Settings(pixel_angle=np.radians(19.0) / 360)
    for segments, rings in ((24, 12), (96, 48)):
        pts, tris = _sphere(np.array([-3.0 * R_S, 0.0, 0.01 * R_S]), segments=segments, rings=rings)
        out = pipeline.build_images(pipeline.SourceMesh(pts, tris), scene, lut, settings)
        for order, img in out.items():
            assert img.report.einstein_ring < 0.01 * len(img.tris)
            assert img.report.patch_faces > 0 and img.report.patch_replaced > 0
            d = img.positions - CAMERA
            az = np.arctan2(d[:, 2], d[:, 1])  # position angle around the hole's direction (-x)
            assert len(np.unique(((az + np.pi) / (2 * np.pi) * 32).astype(int) % 32)) == 32
            a = az[img.tris]
            diff = np.abs(np.angle(np.exp(1j * (a[:, :, None] - a[:, None, :])))).max(axis=(1, 2))
            assert diff.max() < np.radians(8.0)


def test_pipeline_thin_disc_emitter(lut):
    """With a DiscEmitter each image vertex carries 1 + z of circular-orbit gas seen along its own
    geodesic (core.thin_disc, itself tested against the analytic reference) and the flux colour;
    without it both are None."""
    from grlens_addon.core import pipeline, thin_disc

    ang = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    rr = np.array([3.5, 5.0, 7.0]) * R_S
    pts = np.array([[r * np.cos(a), r * np.sin(a), 0.0] for r in rr for a in ang])
    idx = lambda i, j: i * 64 + j % 64  # noqa: E731
    tris = np.array([t for i in range(2) for j in range(64)
                     for t in ((idx(i, j), idx(i, j + 1), idx(i + 1, j + 1)), (idx(i, j), idx(i + 1, j + 1), idx(i + 1, j)))])
    tilt = np.radians(10.0)
    rot = np.array([[np.cos(tilt), 0, np.sin(tilt)], [0, 1, 0], [-np.sin(tilt), 0, np.cos(tilt)]])
    pts = pts @ rot.T
    axis = rot @ np.array([0.0, 0, 1])
    scene = mapping.Scene(CAMERA, HOLE, R_S)
    settings = pipeline.Settings(pixel_angle=np.radians(19.0) / 360)
    plain = pipeline.build_images(pipeline.SourceMesh(pts, tris), scene, lut, settings)
    assert plain[1].redshift is None and plain[1].disc_colour is None
    disc = pipeline.DiscEmitter(axis=axis, mode="blackbody")
    out = pipeline.build_images(pipeline.SourceMesh(pts, tris), scene, lut, settings, disc=disc)
    for order, img in out.items():
        d = (img.positions - CAMERA) / img.light_travel_time[:, None]
        expect = thin_disc.vertex_redshift_from_direction(img.source_position, HOLE, CAMERA, R_S, axis, d)
        np.testing.assert_allclose(img.redshift, expect, rtol=1e-9)
        assert img.disc_colour.shape == (len(img.positions), 3) and np.all(img.disc_colour >= 0)
        assert img.redshift.min() < 1.0 < img.redshift.max()


def test_near_axis_is_a_superset_of_the_crossed_triangles():
    """observer_view.near_axis never misses a triangle (or a sub-triangle of one) that the axis crosses, and
    excludes triangles away from the axis; non-finite corners count as candidates."""
    rng = np.random.default_rng(5)
    cam, hole = CAMERA, np.array([0.3, -0.2, 0.1])
    axis = (cam - hole) / np.linalg.norm(cam - hole)
    # small triangles scattered around the axis, some touching it exactly
    centres = hole + axis * rng.uniform(-20, 20, 4000)[:, None] + rng.normal(scale=0.3, size=(4000, 3))
    pts = (centres[:, None, :] + rng.normal(scale=0.3, size=(4000, 3, 3))).reshape(-1, 3)
    pts[:30] = hole + axis * rng.uniform(-20, 20, 30)[:, None]  # corners exactly on the axis
    tris = np.arange(len(pts)).reshape(-1, 3)
    cand = observer_view.near_axis(pts, tris, cam, hole)
    for order in (1, 2):
        crossed, _ = observer_view.axis_geometry(pts, tris, cam, hole, order)
        assert crossed.sum() > 100 and not np.any(crossed & ~cand)
    assert 0.2 < cand.mean() < 0.9  # it does exclude the ones beside the axis
    # sub-triangles of an unsplit-then-split mesh
    E = subdivision.mesh_edges(tris)
    S = subdivision.subdivide(pts, tris, E, rng.integers(1, 9, len(E.verts)))
    sub_crossed, _ = observer_view.axis_geometry(S.positions, S.tris, cam, hole, 2)
    assert sub_crossed.any() and not np.any(sub_crossed & ~cand[S.source_tri])
    bad = pts.copy()
    bad[0] = np.nan
    assert observer_view.near_axis(bad, tris, cam, hole)[0]


def test_cull_with_precomputed_values_is_the_same(lut):
    """culling.cull gives the same mask and counts whether the circumferences, frustum bits and axis
    candidates are passed in or computed by itself (a sphere behind the hole: ring, straddling and
    frustum culling all happen)."""
    scene = mapping.Scene(CAMERA, HOLE, R_S)
    pts, tris = _sphere(np.array([-3.0 * R_S, 0.1, 0.02 * R_S]), segments=48, rings=24)
    planes = np.array([[0.0, 0.0, 1.0, 0.0]])  # z >= 0
    pix = np.radians(19.0) / 360
    for order in (1, 2):
        img = mapping.map_vertices(pts, scene, lut, order)
        args = (tris, img.direction, img.valid, pts, CAMERA, 4.0, planes, img.position, HOLE, order, pix, 0.25)
        keep, rep = culling.cull(*args)
        fast_keep, fast_rep = culling.cull(
            *args, source_circumference=observer_view.circumference(observer_view.unit_directions(pts, CAMERA), tris),
            image_circumference=observer_view.circumference(img.direction, tris),
            image_outside_bits=culling.outside_bits(img.position, planes),
            axis_candidates=observer_view.near_axis(pts, tris, CAMERA, HOLE))
        assert rep.einstein_ring > 0 and rep.outside_frustum > 0 and rep.kept > 0
        assert np.array_equal(keep, fast_keep) and rep == fast_rep


def test_frustum_pre_cull_matches_brute_force(lut):
    """visibility.Sight.inside_frustum (corners first, midpoints only where the corners agree) keeps
    exactly the source triangles a brute-force test of all corners and edge midpoints keeps."""
    from grlens_addon.core import frame, pipeline, visibility

    rng = np.random.default_rng(9)
    scene = mapping.Scene(CAMERA, HOLE, R_S)
    pts, tris = _sphere(np.array([-3.0 * R_S, 1.0 * R_S, 0.02]), segments=40, rings=20)
    edges = subdivision.mesh_edges(tris)
    img_v = mapping.map_vertices(pts, scene, lut, 1)
    probe = np.sort(rng.choice(len(edges.verts), len(edges.verts) // 2, replace=False))
    mids = 0.5 * (pts[edges.verts[probe, 0]] + pts[edges.verts[probe, 1]])
    img_m = mapping.map_vertices(mids, scene, lut, 1)
    planes = np.array([[0.0, 0.0, 1.0, -0.05], [0.0, 1.0, 0.0, -1.0]])
    fr = frame.frame_context(scene, lut, pipeline.Settings(), frustum_planes=planes)
    source = frame.prepare_source(fr, pipeline.SourceMesh(pts, tris))
    sight = visibility.see(fr, source, frame.map_source(fr, source))
    sel, out_v = sight.inside_frustum(img_v, img_m, probe)
    mid = 0.5 * (img_v.position[edges.verts[:, 0]] + img_v.position[edges.verts[:, 1]])
    mid[probe] = img_m.position
    pts_of = np.concatenate([img_v.position[tris], mid[edges.of_tri]], axis=1)  # (T, 6, 3)
    out = (np.einsum("tpx,kx->tpk", pts_of, planes[:, :3]) + planes[:, 3] < 0).all(axis=1).any(axis=1)
    assert 0 < out.sum() < len(tris)
    assert np.array_equal(sel, np.flatnonzero(~out))
    assert np.array_equal(out_v, culling.outside_bits(img_v.position, planes))


def test_triangulate_tris_quads_and_ngons():
    """core.triangulate: triangles are their corners, a flat convex quad splits on 0-2, a quad folded
    over its 0-2 diagonal splits on 1-3, and a mesh with an n-gon is left to Blender (None)."""
    from grlens_addon.core import triangulate

    pos = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],  # convex quad 0-3
                    [0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0.8, 0.2, 0],  # quad 4-7: reflex at 7
                    [5.0, 5, 5], [6, 5, 5], [5, 6, 5]])  # triangle 8-10
    corner_vert = np.arange(11)
    tri_poly = np.array([0, 0, 1, 1, 2])
    out = triangulate.tri_corners(tri_poly, 3, corner_vert, pos)
    assert out.tolist() == [[0, 1, 2], [0, 2, 3], [4, 5, 7], [5, 6, 7], [8, 9, 10]]
    # the split keeps the concave quad's area (no triangle outside it)
    tri_area = lambda t: 0.5 * abs(np.cross(pos[t[1]] - pos[t[0]], pos[t[2]] - pos[t[0]])[2])  # noqa: E731
    assert tri_area(out[2]) + tri_area(out[3]) == pytest.approx(0.5 - 0.3)
    # a pentagon (3 triangles for one polygon): Blender's own fill is needed
    assert triangulate.tri_corners(np.array([0, 0, 0]), 1, np.arange(5), np.zeros((5, 3))) is None
    # an empty mesh
    assert triangulate.tri_corners(np.zeros(0, np.int64), 0, np.zeros(0, np.int64), np.zeros((0, 3))).shape == (0, 3)


def test_non_finite_corner_attributes_never_reach_an_image(lut):
    """NaN or inf UVs and normals of the user's mesh come out as 0 (UV) and a zero normal (no GR
    irradiance); the geometry is unaffected."""
    from grlens_addon.core import pipeline

    pts, tris = _sphere(np.array([-3.0 * R_S * np.cos(0.4), 3.0 * R_S * np.sin(0.4), 0.02]))
    rng = np.random.default_rng(2)
    uv = rng.random((len(tris), 3, 2))
    nrm = rng.normal(size=(len(tris), 3, 3))
    uv[::7, 1, 0] = np.nan
    uv[::11, 2, 1] = np.inf
    nrm[::5, 0, :] = np.nan
    scene = mapping.Scene(CAMERA, HOLE, R_S)
    light = pipeline.Light(np.array([0.0, 0.0, 30.0]), 1.0, build_lut(15.0, 1.05, 40.0, 64, 128))
    settings = pipeline.Settings(pixel_angle=np.radians(19.0) / 1080)
    out = pipeline.build_images(pipeline.SourceMesh(pts, tris, uv, None, nrm), scene, lut, settings, light)
    clean = pipeline.build_images(pipeline.SourceMesh(pts, tris), scene, lut, settings)
    for order, img in out.items():
        assert np.isfinite(img.corner_uv).all() and np.isfinite(img.irradiance).all()
        assert np.array_equal(img.positions, clean[order].positions)
        bad = np.isin(img.source_tri, np.arange(0, len(tris), 5))  # faces of triangles with a NaN normal
        assert bad.any() and img.report.kept == len(img.tris)


def test_group_offsets_number_each_group_from_zero():
    from grlens_addon.core.ragged import group_offsets

    rng = np.random.default_rng(3)
    counts = rng.integers(0, 5, 40)
    expected = [k for c in counts for k in range(c)]
    assert group_offsets(counts).tolist() == expected
    assert group_offsets([2, 0, 3]).tolist() == [0, 1, 0, 1, 2]
    assert group_offsets(np.zeros(3, np.int64)).size == 0
