"""Add-on numeric core (no bpy): mapping, subdivision, culling, illumination.

Units: world positions in Blender units (BU); r_s in BU; the LUT in r_s and r_s/c.
"""
import numpy as np
import pytest

from grlens_addon.core import culling, illumination, mapping, subdivision
from lutgen import build_lut, connect

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
    dirs = culling.unit_directions(src, cam)
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


def test_illumination_back_side_gets_only_light_around_the_hole(lut):
    """A point behind the hole, facing away from the light, still receives second-order light."""
    light = CAMERA  # r = 20 r_s, same LUT
    p = np.array([[-8.0, 0.5, 0.0]])
    n = np.array([[1.0, 0.0, 0.0]])  # facing the hole/light side
    tot, parts = illumination.irradiance(p, n, light, HOLE, R_S, lut)
    assert parts[1][0] > 0 and parts[2][0] > 0 and parts[2][0] < parts[1][0]
