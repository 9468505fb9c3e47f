"""Einstein-ring patches (grlens_addon.core.axis_patch), the silhouette (core.silhouette) and the
closed-surface helpers of the pipeline, without Blender."""
import math

import numpy as np
import pytest

from grlens_addon.core import (axis_patch, budget, frame, illumination, mapping, observer_view, pipeline, rasterize,
                               raytrace, silhouette, subdivision, visibility)
from lutgen import build_lut, connect
from meshes import uv_sphere

R_S = 1.0
CAMERA = np.array([20.0, 0.0, 0.0])  # r_obs = 20 r_s, the axis is the x axis
HOLE = np.zeros(3)
SCENE = mapping.Scene(CAMERA, HOLE, R_S)
PIXEL = math.radians(19.0) / 360  # the accuracy benchmark's pixels (640x360, 19 deg vertical)
MAX_ERROR = 0.25


@pytest.fixture(scope="module")
def lut():
    return build_lut(20.0, 1.05, 40.0, 256, 512)


def _sphere(centre, radius=0.5, segments=36, rings=18):
    """A UV sphere with outward winding (poles on z)."""
    return uv_sphere(centre, radius, segments, rings)


def _grid(x, half, n, tilt=0.0, hole_radius=0.0):
    """A square grid of (2n)^2 quads (split in two) in the plane x = const (tilted by ``tilt`` radians
    about z), centred on the axis, optionally without the quads within ``hole_radius`` of it."""
    u = np.linspace(-half, half, 2 * n + 1)
    Y, Z = np.meshgrid(u, u, indexing="ij")
    pts = np.stack([x + Y * math.sin(tilt), Y * math.cos(tilt), Z], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(2 * n), np.arange(2 * n), indexing="ij")
    i, j = i.ravel(), j.ravel()
    m = 2 * n + 1
    a, b, c, d = i * m + j, (i + 1) * m + j, (i + 1) * m + j + 1, i * m + j + 1
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    if hole_radius:
        centre = pts[tris].mean(axis=1)
        tris = tris[np.hypot(centre[:, 1], centre[:, 2]) > hole_radius]
    return pts, tris


def _patches(pts, tris, lut, orders=(1, 2), closed=False, pixel=PIXEL):
    """axis_patch.build_patches of the mesh in a frame of SCENE (the stage as build_images calls it);
    ``closed``: whether the mesh counts as a closed surface seen from outside."""
    fr = frame.frame_context(SCENE, lut, pipeline.Settings(orders=tuple(orders), pixel_angle=pixel,
                                                          max_error_px=MAX_ERROR))
    source = frame.prepare_source(fr, pipeline.SourceMesh(pts, tris))
    sight = visibility.see(fr, source, frame.map_source(fr, source))
    sight._closed = bool(closed)
    return axis_patch.build_patches(fr, source, sight)


def _angle_from_hole(d):
    return np.arccos(np.clip(-(d @ SCENE.e1), -1.0, 1.0))


def test_crossings_of_a_sphere_on_the_axis():
    pts, tris = _sphere([-3.0, 0.0, 0.01])
    cr = axis_patch.find_crossings(pts, tris, CAMERA, HOLE)
    assert len(cr) == 2
    # on the sphere (the mesh's chords lie at most 0.5 (1 - cos 5 deg) inside it)
    along = sorted(c.along for c in cr)
    exact = -3.0 - math.sqrt(0.25 - 0.01 ** 2), -3.0 + math.sqrt(0.25 - 0.01 ** 2)
    np.testing.assert_allclose(along, exact, atol=0.5 * (1 - math.cos(math.radians(5))))
    for c in cr:  # on the axis, inside the triangle it names
        np.testing.assert_allclose(c.point[1:], 0.0, atol=1e-15)
    assert axis_patch.ring_orders(cr[0], (1, 2)) == (1, 2)
    # beside the axis: none; in front of the hole: order 2 only
    assert axis_patch.find_crossings(*_sphere([-3.0, 0.7, 0.0]), CAMERA, HOLE) == []
    front = axis_patch.find_crossings(*_sphere([5.0, 0.0, 0.01]), CAMERA, HOLE)
    assert len(front) == 2 and all(axis_patch.ring_orders(c, (1, 2)) == (2,) for c in front)


def test_a_crossing_through_a_shared_vertex_is_found_once():
    """A fan of triangles around a vertex on the axis: every triangle touches the axis there."""
    a = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    pts = np.vstack([[-4.0, 0, 0], np.stack([np.full(8, -4.2), np.cos(a), np.sin(a)], 1)])
    tris = np.array([(0, 1 + k, 1 + (k + 1) % 8) for k in range(8)])
    cr = axis_patch.find_crossings(pts, tris, CAMERA, HOLE)
    assert len(cr) == 1
    np.testing.assert_allclose(cr[0].point, [-4.0, 0, 0], atol=1e-12)


@pytest.mark.parametrize("x", [-3.0, -8.0, 5.0])
def test_limit_images_are_the_einstein_ring(lut, x):
    """The limit vertices of a crossing are the exact points of its Einstein ring: the angle of
    lutgen.connect at phi = pi (behind the hole) or 0 (order 2, in front), at position angle psi for
    order 1 and psi + pi for order 2; and points approaching the axis map onto them."""
    cr = axis_patch.Crossing(tri=0, point=np.array([x, 0.0, 0.0]), along=x)
    psi = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    u = observer_view.any_perpendicular(SCENE.e1)
    v = np.cross(SCENE.e1, u)
    for order in axis_patch.ring_orders(cr, (1, 2)):
        im = axis_patch.limit_images(cr, psi, mapping.Mapper(SCENE, lut), order)
        assert im.valid.all()
        exact = connect(20.0, abs(x), np.pi if x < 0 else 0.0, order)
        np.testing.assert_allclose(_angle_from_hole(im.direction), np.pi - exact.xi, atol=1e-9)
        np.testing.assert_allclose(im.distance, exact.dt * R_S, rtol=1e-6)  # the LUT's accuracy
        side = im.direction - (im.direction @ SCENE.e1)[:, None] * SCENE.e1
        pa = np.arctan2(side @ v, side @ u)
        want = psi if order == 1 else psi + np.pi
        np.testing.assert_allclose(np.angle(np.exp(1j * (pa - want))), 0.0, atol=1e-12)
        # continuity: a point 1e-7 from the axis at azimuth psi
        near = cr.point + 1e-7 * (np.cos(psi)[:, None] * u + np.sin(psi)[:, None] * v)
        img = mapping.map_vertices(near, SCENE, lut, order)
        assert np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", img.direction, im.direction), -1, 1))).max() < 1e-5


def test_patch_on_a_tilted_plane(lut):
    """Grid points lie on the surface at their circle's distance from the axis and their azimuth; faces
    are wound like the source; the triangles inside the patch are replaced, the ones reaching out are
    not; the ring's edge is drawn by chords sagging by at most budget.Budget.patch_edge_px, between
    points moved CHORD_OUTSET of that sag off the exact ring (lutgen.connect), so that they cross it."""
    pts, tris = _grid(-4.0, 1.0, 10, tilt=0.5)
    (p,) = _patches(pts, tris, lut)
    assert p.complete
    n = p.n_azimuths
    grid = p.source_position[p.grid_vertices]
    x, y, z = observer_view.axis_coordinates(grid, CAMERA, HOLE)
    # on the plane through (-4, 0, 0) with normal (cos 0.5, -sin 0.5, 0)
    np.testing.assert_allclose((grid - [-4.0, 0, 0]) @ [math.cos(0.5), -math.sin(0.5), 0.0], 0.0, atol=1e-12)
    delta = np.hypot(x, y).reshape(-1, n)
    np.testing.assert_allclose(delta, delta[:, :1] * np.ones((1, n)), rtol=1e-9)
    assert np.all(np.diff(delta[:, 0]) > 0) and delta[-1, 0] == pytest.approx(p.radius)
    np.testing.assert_allclose(p.source_position[:n], p.crossing.point[None].repeat(n, 0))
    # winding: the faces' normals (where not degenerate) point like the source triangles'
    src_n = np.cross(pts[tris[:, 1]] - pts[tris[:, 0]], pts[tris[:, 2]] - pts[tris[:, 0]])[0]
    f = p.source_position[p.tris]
    fn = np.cross(f[:, 1] - f[:, 0], f[:, 2] - f[:, 0])
    big = np.linalg.norm(fn, axis=1) > 1e-12
    assert big.sum() > len(fn) // 2 and np.all(fn[big] @ src_n > 0)
    # barycentrics reproduce the corners (in the plane, projected along the axis: exact)
    rebuilt = np.einsum("fck,fkx->fcx", p.bary, pts[tris[p.face_src]])
    np.testing.assert_allclose(rebuilt, f, atol=1e-12)
    # replaced: all corners inside the outer circle
    cd = np.hypot(*observer_view.axis_coordinates(pts, CAMERA, HOLE)[:2])
    assert len(p.replaced) > 0 and np.all(cd[tris[p.replaced]].max(axis=1) <= p.radius)
    rest = np.setdiff1d(np.arange(len(tris)), p.replaced)
    assert np.all(cd[tris[rest]].max(axis=1) > p.radius)
    # the ring's edge: the limit vertices (the grid's n, and the refined band's between them) in
    # azimuth order, each a point of the crossing (the same source point)
    lim = np.flatnonzero(p.limit)
    assert np.all(p.limit[:n]) and len(lim) > n and not p.limit[p.grid_vertices].any()
    np.testing.assert_allclose(p.source_position[lim], p.crossing.point[None].repeat(len(lim), 0))
    ring_order = lim[np.argsort(p.limit_psi[lim])]
    step = np.diff(np.append(p.limit_psi[ring_order], p.limit_psi[ring_order[0]] + 2 * np.pi))
    assert step.max() <= 2 * np.pi / p.ring_chords * (1 + 1e-9)
    for order in p.orders:
        im = p.images[order]
        assert im.valid.all()
        ring = im.direction[ring_order]
        theta = _angle_from_hole(ring)
        np.testing.assert_allclose(theta, theta[0], rtol=1e-12)
        chord_mid = 0.5 * (ring + np.roll(ring, -1, axis=0))
        mid = _angle_from_hole(chord_mid / np.linalg.norm(chord_mid, axis=1)[:, None])
        sag = (theta - mid) / PIXEL
        assert 0 < sag.max() <= budget.PATCH_EDGE_FACTOR * budget.COVERAGE_FACTOR * MAX_ERROR * 1.0001
        exact = np.pi - connect(20.0, np.linalg.norm(p.crossing.point), np.pi, order).xi
        # the outset is CHORD_OUTSET of the longest chord's sag: the chords cross the ring
        np.testing.assert_allclose((theta - exact) / PIXEL, budget.CHORD_OUTSET * sag.max(), rtol=1e-3, atol=1e-6)
        np.testing.assert_allclose((mid - exact) / PIXEL, budget.CHORD_OUTSET * sag.max() - sag, rtol=1e-3, atol=1e-6)
        assert np.all(mid < exact)
        # the innermost circle is within the band (the wide one where the plane has no edge near the
        # axis: BAND_WIDE_FACTOR of the coverage tolerance) of the ring
        inner = _angle_from_hole(im.direction[p.grid_vertices][:n])
        wide = budget.BAND_WIDE_FACTOR * budget.COVERAGE_FACTOR * MAX_ERROR
        assert np.abs(inner - theta[0]).max() / PIXEL <= wide * 1.5


@pytest.mark.parametrize("theta_deg", [0.5, 8.0, 60.0, 120.0, 175.0])
def test_chord_sag_and_outset(theta_deg):
    """chord_sag is the angle of the great-circle arc's midpoint (slerp) from the ring's angle, for
    rings on either side of the equator; limit points moved off by CHORD_OUTSET of it make a polygon
    whose area on the view sphere equals the ring's cap (its chords cross the ring evenly), where the
    exact points leave a sliver along the whole ring (inside it below the equator, outside beyond)."""
    theta, n = math.radians(theta_deg), 64
    xi = np.pi - theta  # the ring at theta from the hole's direction -e1 (e1 towards the camera)
    step = 2 * np.pi / n
    e1, u, v = np.eye(3)

    def points(x, psi):
        return np.cos(x) * e1 + np.sin(x) * (np.cos(psi)[:, None] * u + np.sin(psi)[:, None] * v)

    a, b = points(xi, np.zeros(1))[0], points(xi, np.full(1, step))[0]
    w = math.acos(float(a @ b))
    mid = (math.sin(0.5 * w) * (a + b)) / math.sin(w)  # slerp at 1/2
    np.testing.assert_allclose(float(axis_patch.chord_sag(xi, step)), math.acos(mid @ e1) - xi, atol=1e-14)

    def cap_error(x):  # (polygon area - cap area) on the unit sphere, the polygon about -e1
        p = points(x, step * np.arange(n))
        centre = -e1
        area = 0.0
        for i in range(n):  # spherical triangles (centre, p_i, p_i+1), Van Oosterom-Strackee
            q, r = p[i], p[(i + 1) % n]
            num = abs(centre @ np.cross(q, r))
            den = 1 + centre @ q + q @ r + r @ centre
            area += 2 * math.atan2(num, den)
        return area - 2 * np.pi * (1 - math.cos(theta))

    exact = cap_error(xi)
    moved = cap_error(xi - budget.CHORD_OUTSET * axis_patch.chord_sag(xi, step))
    assert np.sign(exact) == (-1 if theta_deg < 90 else 1)  # the chords bow towards the nearer pole
    assert abs(moved) < 0.01 * abs(exact)


@pytest.mark.parametrize("tilt_deg", [0.0, 50.0, 70.0, 80.0])
def test_patch_circles_on_a_steep_plane(lut, monkeypatch, tilt_deg):
    """On a plane at ``tilt`` to the axis' normal plane, a step across the axis is 1 / cos(tilt) times
    longer on the surface: the patch's intervals between circles are each cut into
    ceil(1 / (cos(tilt) STEEP_RATIO)) (1, 1, 2, 3 for 0, 50, 70, 80 deg), and the circles keep
    their geometric spacing within each interval."""
    tilt = math.radians(tilt_deg)
    pts, tris = _grid(-4.0, 3.0, 30, tilt=tilt)  # 0.5 across the axis at 80 deg: the patch is complete

    def circles(p):
        n = p.n_azimuths
        d = np.hypot(*observer_view.axis_coordinates(p.source_position[p.grid_vertices], CAMERA, HOLE)[:2])
        return d.reshape(-1, n)[:, 0]

    (p,) = _patches(pts, tris, lut)
    monkeypatch.setattr(budget, "STEEP_RATIO", 0.0)
    (plain,) = _patches(pts, tris, lut)
    parts = math.ceil(1.0 / (math.cos(tilt) * 2.0) - 1e-9)
    assert budget.STEEP_RATIO == 0.0 and p.complete and plain.complete
    fine, coarse = circles(p), circles(plain)
    assert len(fine) == parts * (len(coarse) - 1) + 1
    np.testing.assert_allclose(fine[::parts], coarse, rtol=1e-9)
    if parts > 1:
        ratio = fine[1:] / fine[:-1]
        np.testing.assert_allclose(ratio.reshape(-1, parts), ratio.reshape(-1, parts)[:, :1] * np.ones((1, parts)),
                                   rtol=1e-9)


def test_patch_faces_take_their_corners_values_from_the_triangles_under_them(lut):
    """Corner UVs of patch faces: at each corner, the source's piecewise-linear UV at that point (the
    value in the triangle under it, not one face's triangle extrapolated), except across a seam (here
    a UV island shifted by 5), where a face takes one triangle's values for all its corners, so no
    face interpolates across the jump."""
    pts, tris = _grid(-4.0, 1.0, 10)
    g = np.stack([pts[:, 1] ** 2 + 0.3 * pts[:, 2], np.sin(3 * pts[:, 2])], -1)  # not affine
    uv = g[tris]
    island = pts[tris].mean(axis=1)[:, 1] > 0.05
    uv[island, :, 0] += 5.0
    src = pipeline.SourceMesh(pts, tris, corner_uv=uv)
    out = pipeline.build_images(src, SCENE, lut, pipeline.Settings(pixel_angle=PIXEL))
    img = out[1]
    n_p = img.report.patch_faces
    assert n_p > 100
    corner_uv = img.corner_uv[-n_p:]
    corner_pts = img.source_position[img.tris[-n_p:]]
    # the piecewise-linear UV of the source at each corner (its triangle, found by barycentrics)
    q = corner_pts.reshape(-1, 3)[:, 1:]
    a, b, c = (pts[tris[:, k]][:, 1:] for k in range(3))
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    l1 = ((q[:, None, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (q[:, None, 1] - a[:, 1])) / det
    l2 = ((b[:, 0] - a[:, 0]) * (q[:, None, 1] - a[:, 1]) - (q[:, None, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
    inside = np.minimum(np.minimum(1 - l1 - l2, l1), l2)
    t = np.argmax(inside, axis=1)
    r = np.arange(len(q))
    lam = np.stack([1 - l1[r, t] - l2[r, t], l1[r, t], l2[r, t]], 1)
    pl = np.einsum("nk,nkx->nx", lam, uv[t]).reshape(-1, 3, 2)
    # no face spans the jump
    assert np.ptp(corner_uv[:, :, 0], axis=1).max() < 1.0
    # away from the seam, every corner has the source's own value
    side = island[t].reshape(-1, 3)
    crosses = side.any(axis=1) & ~side.all(axis=1)
    assert (~crosses).sum() > 0.9 * n_p
    np.testing.assert_allclose(corner_uv[~crosses], pl[~crosses], atol=1e-9)


def test_patch_stops_at_the_mesh(lut, monkeypatch):
    """A small plane, with the plain grid (CLIP_TO_TRIANGLES off): the patch's cells stay on the plane
    (full circles inside it, then the cells whose four corners are on it, into its corners); it
    replaces only triangles inside drawn cells. A plane with a hole around the axis (nothing crosses
    it) and a plane whose hole reaches the crossing's circles give no patch."""
    monkeypatch.setattr(budget, "CLIP_TO_TRIANGLES", False)
    pts, tris = _grid(-4.0, 0.04, 2)
    (p,) = _patches(pts, tris, lut)
    assert 0.04 < p.radius <= 0.04 * math.sqrt(2) and not p.complete
    _, y, z = p.source_position.T
    assert np.abs(y).max() <= 0.04 + 1e-12 and np.abs(z).max() <= 0.04 + 1e-12
    n = p.n_azimuths
    grid = p.source_position[p.grid_vertices]
    delta = np.hypot(*observer_view.axis_coordinates(grid, CAMERA, HOLE)[:2])
    assert np.unique(np.round(delta, 9)).size > 1 and len(grid) < n * np.unique(np.round(delta, 9)).size
    cd = np.hypot(*observer_view.axis_coordinates(pts, CAMERA, HOLE)[:2])
    assert 0 < len(p.replaced) < len(tris) and np.all(cd[tris[p.replaced]].max(axis=1) <= p.radius)
    assert _patches(*_grid(-4.0, 1.0, 10, hole_radius=0.15), lut) == []
    # crossed, but the triangles next to the crossed one are missing
    pts, tris = _grid(-4.0, 1.0, 10)
    centre = pts[tris].mean(axis=1)
    d = np.hypot(centre[:, 1], centre[:, 2])
    keep = (d < 0.06) | (d > 0.3)
    assert _patches(pts, tris[keep], lut) == []


def _clip_check(p, pts, tris):
    """Faces of a clipped patch: each inside its source triangle (projected along the axis), and the
    patch's own edges used twice, except on its outer circle and the sheet's edge (no cracks)."""
    x, y, _ = observer_view.axis_coordinates(pts, CAMERA, HOLE)
    n = p.n_azimuths
    assert np.all(p.bary.sum(axis=2) == pytest.approx(1.0)) and p.bary.min() > -1e-9
    # the corners' positions are their barycentrics in the face's source triangle
    corner = np.einsum("fck,fkx->fcx", p.bary, pts[tris[p.face_src]])
    np.testing.assert_allclose(corner.reshape(-1, 3), p.source_position[p.tris.ravel()], atol=1e-12)
    e = np.sort(np.concatenate([p.tris[:, [0, 1]], p.tris[:, [1, 2]], p.tris[:, [2, 0]]]), axis=1)
    e = e[~p.limit[e].any(axis=1)]  # the limit vertices are one point with a turn of images: the ring
    key, count = np.unique(e, axis=0, return_counts=True)
    assert count.max() == 2
    px, py, _ = observer_view.axis_coordinates(p.source_position, CAMERA, HOLE)
    once = key[count == 1]
    outer = (np.hypot(px, py)[once] >= p.radius * math.cos(math.pi / n) * (1 - 1e-12)).all(axis=1)
    return once[~outer], px, py, x, y


def test_clipped_patch_covers_the_mesh_up_to_its_edge(lut, monkeypatch):
    """A small plane with the patch clipped to its triangles (CLIP_TO_TRIANGLES; CLIP_REACH raised so
    that a plain grid reaching 87% of the way out is clipped too): the patch is complete, every face
    lies on one source triangle with that triangle's barycentrics, the faces' projected area is the
    plane's inside the outer circle (its corners beyond it), its inner edges are shared by two faces
    (the only edges used once lie on the outer circle or the plane's border), and it replaces the
    triangles inside the outer circle. The crossing is a vertex of the plane, so edges of it run
    through the limit vertices."""
    assert budget.CLIP_TO_TRIANGLES
    monkeypatch.setattr(budget, "CLIP_REACH", 1.0)
    pts, tris = _grid(-4.0, 0.04, 2)
    (p,) = _patches(pts, tris, lut)
    assert p.complete
    rim, px, py, x, y = _clip_check(p, pts, tris)
    assert len(rim) > 0
    on_x = np.isclose(np.abs(px[rim]), 0.04, rtol=0, atol=1e-12).all(axis=1)  # both ends on one side
    on_y = np.isclose(np.abs(py[rim]), 0.04, rtol=0, atol=1e-12).all(axis=1)
    assert (on_x | on_y).all()
    # the area of the square inside the outer circle (chords of it, N per turn), against Monte Carlo
    area = np.abs(observer_view.projected_area(px, py, p.tris)).sum() / 2
    rng = np.random.default_rng(1)
    q = rng.uniform(-0.04, 0.04, (400000, 2))
    inside = np.hypot(q[:, 0], q[:, 1]) <= p.radius * math.cos(math.pi / p.n_azimuths)
    assert area == pytest.approx(0.08 ** 2 * inside.mean(), rel=0.01)
    d_hi = np.hypot(x, y)[tris].max(axis=1)
    np.testing.assert_array_equal(np.sort(p.replaced), np.flatnonzero(d_hi <= p.radius))


def test_clipped_patch_leaves_out_a_hole_in_the_mesh(lut, monkeypatch):
    """A plane with a hole (two triangles missing) beside the axis, inside the patch: the clipped patch
    covers the plane but not the hole (its projected area is the plane's inside the outer circle less
    the hole's), and its edges used once lie on the outer circle, the plane's border or the hole's."""
    monkeypatch.setattr(budget, "CLIP_TO_TRIANGLES", True)
    monkeypatch.setattr(budget, "CLIP_REACH", 1.0)
    pts, tris = _grid(-4.0, 0.04, 4)  # 0.01 quads
    centre = pts[tris].mean(axis=1)
    hole = (np.abs(centre[:, 1] - 0.015) < 0.005) & (np.abs(centre[:, 2] - 0.005) < 0.005)
    assert hole.sum() == 2  # the quad [0.01, 0.02] x [0, 0.01]
    (p,) = _patches(pts, tris[~hole], lut)
    assert p.complete and p.radius > math.hypot(0.02, 0.01)
    rim, px, py, x, y = _clip_check(p, pts, tris[~hole])
    on_border = (np.isclose(np.abs(px[rim]), 0.04, rtol=0, atol=1e-12).all(axis=1)
                 | np.isclose(np.abs(py[rim]), 0.04, rtol=0, atol=1e-12).all(axis=1))
    hxy = np.stack(observer_view.axis_coordinates(pts[tris[hole]].reshape(-1, 3), CAMERA, HOLE)[:2], -1)
    h_centre = 0.5 * (hxy.min(axis=0) + hxy.max(axis=0))  # the hole's square, half-side 0.005
    hx, hy = px[rim] - h_centre[0], py[rim] - h_centre[1]
    on_hole = ((np.abs(hx) <= 0.005 + 1e-12) & (np.abs(hy) <= 0.005 + 1e-12)
               & np.isclose(np.maximum(np.abs(hx), np.abs(hy)), 0.005, rtol=0, atol=1e-12)).all(axis=1)
    assert (on_border | on_hole).all() and on_hole.sum() >= 4
    area = np.abs(observer_view.projected_area(px, py, p.tris)).sum() / 2
    rng = np.random.default_rng(2)
    q = rng.uniform(-0.04, 0.04, (400000, 2))
    inside = np.hypot(q[:, 0], q[:, 1]) <= p.radius * math.cos(math.pi / p.n_azimuths)
    in_hole = (np.abs(q[:, 0] - h_centre[0]) < 0.005) & (np.abs(q[:, 1] - h_centre[1]) < 0.005)
    assert area == pytest.approx(0.08 ** 2 * (inside & ~in_hole).mean(), rel=0.01)


def test_clipped_patch_on_a_sphere_next_to_its_limb(lut, monkeypatch):
    """The benchmark's sphere with the axis just inside its limb (170.5 deg of its orbit): the clipped
    patches are complete, inside their source triangles and crack-free, and replace the crossed
    triangles, which the plain grid left to be cut at ring levels. With more (cell, triangle) pairs
    to clip than MAX_CLIP_PAIRS, the plain grid is built instead."""
    a = math.radians(170.5)
    pts, tris = _sphere([3 * math.cos(a), 3 * math.sin(a), 0.01])
    with monkeypatch.context() as m:
        m.setattr(budget, "MAX_CLIP_PAIRS", 10)
        plain = [p for p in _patches(pts, tris, lut, closed=True) if len(p.tris)]
    assert plain and not any(p.complete for p in plain)
    assert not any(p.crossing.tri in p.replaced for p in plain)
    patches = _patches(pts, tris, lut, closed=True)
    grids = [p for p in patches if len(p.tris)]
    assert grids and all(p.complete for p in grids)
    for p in grids:
        assert p.crossing.tri in p.replaced
        rim, px, py, x, y = _clip_check(p, pts, tris)
        # edges used once off the outer circle lie on the sheet's edge: the fold, between triangles of
        # opposite winding in projection
        assert len(rim) > 0
        # the fold: edges between triangles wound oppositely in projection
        e = subdivision.mesh_edges(tris)
        sign = np.sign(observer_view.projected_area(x, y, tris))
        pos, neg = (np.bincount(e.of_tri.ravel(), weights=np.repeat(sign == k, 3), minlength=len(e.verts))
                    for k in (1, -1))
        fold = e.verts[(pos > 0) & (neg > 0)]
        ax_, ay_ = x[fold[:, 0]], y[fold[:, 0]]
        fx, fy = x[fold[:, 1]] - ax_, y[fold[:, 1]] - ay_
        for v in np.unique(rim):  # every vertex of the patch's other edge lies on the fold
            t = np.clip(((px[v] - ax_) * fx + (py[v] - ay_) * fy) / (fx * fx + fy * fy), 0, 1)
            assert np.hypot(ax_ + t * fx - px[v], ay_ + t * fy - py[v]).min() < 1e-12


def test_open_distance_is_where_a_patch_stops_drawing(lut, monkeypatch):
    """axis_patch.open_distance: on a complete patch, the outer circle for the triangles reaching
    inside it and inf for the others; on an incomplete one (the plain grid on a small plane), the
    inner circle of the first row with an undrawn cell in the triangle's box (never beyond the outer
    circle)."""
    monkeypatch.setattr(budget, "CLIP_TO_TRIANGLES", False)
    pts, tris = _grid(-4.0, 1.0, 10)
    (p,) = _patches(pts, tris, lut)
    x, y, _ = observer_view.axis_coordinates(pts, CAMERA, HOLE)
    got = axis_patch.open_distance(p, tris, x, y)
    reach_in = observer_view.axis_distance(x, y, tris) < p.radius
    assert p.complete and reach_in.any() and (~reach_in).any()
    np.testing.assert_array_equal(got[reach_in], p.radius)
    assert np.isinf(got[~reach_in]).all()
    pts, tris = _grid(-4.0, 0.04, 2)
    (p,) = _patches(pts, tris, lut)
    x, y, _ = observer_view.axis_coordinates(pts, CAMERA, HOLE)
    got = axis_patch.open_distance(p, tris, x, y)
    first_gap = p.ring_radii[np.flatnonzero(~p.cell.all(axis=1))[0]]
    gap_near = np.hypot(x, y)[tris].max(axis=1) > first_gap  # reaching beyond the largest full circle
    assert not p.complete and gap_near.any()
    assert np.all(got[gap_near] >= first_gap) and np.all(got[gap_near] <= p.radius)
    assert np.all(got[gap_near] < p.radius) and np.all(np.isin(got[gap_near], p.ring_radii))


def test_first_smallest_is_lexsorts_first_of_each_key():
    """axis_patch._first_smallest picks, per key, the element np.lexsort((value, key)) puts first: the
    smallest value, the earliest among equal ones, NaN last (ties, NaN and all-NaN keys included)."""
    rng = np.random.default_rng(3)
    for _ in range(500):
        n = int(rng.integers(1, 60))
        key = rng.integers(0, int(rng.integers(1, 30)), n)
        value = rng.integers(0, 4, n).astype(float)
        value[rng.random(n) < 0.2] = np.nan
        order = np.lexsort((value, key))
        want = order[np.r_[True, key[order][1:] != key[order][:-1]]]
        np.testing.assert_array_equal(axis_patch._first_smallest(key, value), want)


def test_connected_stays_inside_the_candidates():
    """axis_patch._connected: the triangles reachable from the seed through shared edges without
    leaving the candidates; a seed that is not a candidate reaches nothing."""
    pts, tris = _grid(-4.0, 1.0, 3)  # 6x6 quads, 72 triangles
    edges = subdivision.mesh_edges(tris)
    centre = pts[tris].mean(axis=1)
    left, right = np.flatnonzero(centre[:, 1] < -0.2), np.flatnonzero(centre[:, 1] > 0.2)
    cand = np.concatenate([left, right])  # two strips with a gap between them
    got = axis_patch._connected(int(left[0]), cand, edges.of_tri, len(edges.verts))
    np.testing.assert_array_equal(got, np.isin(cand, left))
    every = axis_patch._connected(0, np.arange(len(tris)), edges.of_tri, len(edges.verts))
    assert every.all()
    middle = np.setdiff1d(np.arange(len(tris)), cand)[0]
    assert not axis_patch._connected(int(middle), cand, edges.of_tri, len(edges.verts)).any()


def test_patch_limits(lut, monkeypatch):
    """Many crossings (a stack of planes): at most MAX_PATCHES patches; a grid never exceeds
    MAX_GRID points."""
    parts = [_grid(-2.5 - 0.3 * k, 0.3, 2) for k in range(12)]
    pts = np.concatenate([p for p, _ in parts])
    tris = np.concatenate([t + 25 * k for k, (_, t) in enumerate(parts)])
    patches = _patches(pts, tris, lut)
    assert len(patches) == budget.MAX_PATCHES
    monkeypatch.setattr(budget, "MAX_GRID", 2000)
    for p in _patches(*_grid(-4.0, 1.0, 10), lut, pixel=PIXEL / 8):
        assert len(p.source_position[p.grid_vertices]) <= 2000
        # the refined band: at most MAX_BAND_AZIMUTHS limit vertices per turn (one more per sector)
        assert 0 < p.limit.sum() <= budget.MAX_BAND_AZIMUTHS + 2 * p.n_azimuths


def test_back_faces_of_a_closed_sphere(lut):
    """Behind the hole the axis crosses the sphere twice. With ``closed`` the far crossing's patch is
    hidden (its rays start into the sphere), except perhaps for order 1 in its outer part: the rays
    arrive inclined by the bending, so nearer the limb they reach the far side too. It still replaces
    its triangles; the near one is drawn."""
    pts, tris = _sphere([-3.0, 0.0, 0.01])
    patches = sorted(_patches(pts, tris, lut, closed=True), key=lambda p: p.crossing.along)
    assert len(patches) == 2
    far, near = patches
    assert set(far.images) <= {1} and not far.facing[2].any() and len(far.replaced)
    face_delta = np.hypot(*observer_view.axis_coordinates(far.source_position, CAMERA, HOLE)[:2])[far.tris].max(axis=1)
    assert far.facing[1].sum() <= 0.25 * len(far.tris) and np.all(face_delta[far.facing[1]] > 0.5 * far.radius)
    assert set(near.images) == {1, 2} and near.facing[1].all() and near.facing[2].mean() > 0.5
    both = _patches(pts, tris, lut, closed=False)
    assert all(set(p.images) == {1, 2} for p in both)


def test_patch_images_and_facing_from_one_lookup(lut):
    """On a closed surface a patch's faces are tested for facing from the rays' tangents, looked up
    with the vertices' images (one interpolation stencil); the images are map_vertices' to the bit. The
    sphere is where the benchmark orbit's 174 deg frame puts it: the far crossing's patch shows a fifth
    of its faces in order 1 and a few in order 2."""
    a = math.radians(174.0)
    pts, tris = _sphere([3.0 * math.cos(a), 3.0 * math.sin(a), 0.01])
    far, near = sorted(_patches(pts, tris, lut, closed=True), key=lambda p: p.crossing.along)
    assert 0 < far.facing[1].sum() < 0.3 * len(far.tris) and far.facing[2].sum() < 0.01 * len(far.tris)
    for p in (far, near):
        off = ~p.limit  # the vertices off the axis (the limit vertices' images are the ring's points)
        for o, im in p.images.items():
            want = mapping.map_vertices(p.source_position[off], SCENE, lut, o)
            np.testing.assert_array_equal(im.position[off], want.position)
            np.testing.assert_array_equal(im.distance[off], want.distance)
    open_patches = _patches(pts, tris, lut, closed=False)
    for p in open_patches:
        for o, im in p.images.items():
            np.testing.assert_array_equal(im.position[~p.limit],
                                          mapping.map_vertices(p.source_position[~p.limit], SCENE, lut, o).position)


def test_hidden_patches_are_not_built(lut, monkeypatch):
    """A crossing whose sheet is turned away along every order's rays (the far side of the sphere behind
    the hole) gets no grid at all, only its replaced triangles; the image meshes are the same as when
    its grid is built and every face found hidden."""
    pts, tris = _sphere([-3.0, 0.0, 0.01])
    far, near = sorted(_patches(pts, tris, lut, closed=True), key=lambda p: p.crossing.along)
    assert len(far.tris) == 0 and far.images == {} and len(far.replaced) > 0
    assert len(near.tris) > 0 and set(near.images) == {1, 2}
    src = pipeline.SourceMesh(pts, tris, corner_uv=np.zeros((len(tris), 3, 2)))
    settings = pipeline.Settings(pixel_angle=PIXEL)
    fast = pipeline.build_images(src, SCENE, lut, settings)
    monkeypatch.setattr(axis_patch, "_hidden_sheet", lambda cr, cand, *a: (False, np.zeros(len(cand), bool)))
    slow = pipeline.build_images(src, SCENE, lut, settings)
    for o in (1, 2):
        np.testing.assert_array_equal(fast[o].tris, slow[o].tris)
        np.testing.assert_array_equal(fast[o].positions, slow[o].positions)


def test_patch_hidden_but_at_its_rim_gets_no_grid(lut, monkeypatch):
    """The sphere at 175 deg of the benchmark orbit: the far crossing's rays arrive from behind its sheet
    (the cone at the crossing point is hidden), and the triangles not turned away at every corner lie
    beyond HIDDEN_CORE of the patch's radius from the axis. Its grid would draw only faces next to its
    rim, which the kept triangles' pieces draw as well, so there is none: it replaces only the
    triangles turned away. Where such triangles reach the axis (174 deg) the grid is built."""
    a = math.radians(175.0)
    pts, tris = _sphere([3.0 * math.cos(a), 3.0 * math.sin(a), 0.01])
    far, near = sorted(_patches(pts, tris, lut, closed=True), key=lambda p: p.crossing.along)
    assert len(far.tris) == 0 and far.images == {} and len(near.tris) > 0
    x, y, _ = observer_view.axis_coordinates(pts, CAMERA, HOLE)
    sheet = axis_patch._sheet(far.crossing, far.radius, tris, subdivision.mesh_edges(tris).of_tri,
                              len(subdivision.mesh_edges(tris).verts), x, y)
    kept = np.setdiff1d(sheet, far.replaced)
    assert 0 < len(far.replaced) < len(sheet) and len(kept) > 0
    assert np.all(observer_view.axis_distance(x, y, tris[kept]) >= budget.HIDDEN_CORE * far.radius)
    monkeypatch.setattr(budget, "HIDDEN_CORE", np.inf)
    far_grid, _ = sorted(_patches(pts, tris, lut, closed=True), key=lambda p: p.crossing.along)
    assert len(far_grid.tris) > 0 and 0 < far_grid.facing[1].sum() < 0.2 * len(far_grid.tris)
    b = math.radians(174.0)
    pts, tris = _sphere([3.0 * math.cos(b), 3.0 * math.sin(b), 0.01])
    monkeypatch.setattr(budget, "HIDDEN_CORE", 0.25)
    far174, _ = sorted(_patches(pts, tris, lut, closed=True), key=lambda p: p.crossing.along)
    assert len(far174.tris) > 0


def test_winding_number_and_closed_surfaces():
    pts, tris = _sphere([-3.0, 0.0, 0.0])
    assert pipeline.is_closed_outward(pts, tris)
    assert not pipeline.is_closed_outward(pts, tris[:, ::-1])
    assert not pipeline.is_closed_outward(pts, tris[1:])
    assert pipeline.winding_number(pts, tris, [-3.0, 0.1, 0.2]) == pytest.approx(1.0, abs=1e-9)
    assert pipeline.winding_number(pts, tris, CAMERA) == pytest.approx(0.0, abs=1e-9)
    assert pipeline.winding_number(pts, tris[:, ::-1], [-3.0, 0, 0]) == pytest.approx(-1.0, abs=1e-9)


def test_camera_inside_a_closed_shell_still_sees_the_patch(lut):
    """A closed shell around camera and hole is seen from inside (its back faces): the pipeline draws
    the patch where the axis crosses it behind the hole."""
    pts, tris = _sphere([0.0, 0.0, 0.0], radius=30.0, segments=48, rings=24)
    lut40 = build_lut(20.0, 1.05, 40.0, 128, 256)
    settings = pipeline.Settings(pixel_angle=PIXEL)
    out = pipeline.build_images(pipeline.SourceMesh(pts, tris), SCENE, lut40, settings)
    assert out[1].report.patch_faces > 0


def test_silhouette_of_a_sphere_is_its_limb(lut):
    """With straight lines of sight (d towards the camera) the silhouette of a sphere is its limb:
    the edges whose midpoints see the camera at 90 degrees from the normal, to within the mesh's
    angular step. Along the lensed order-1 rays it is a band of similar size, shifted by the bending."""
    centre = np.array([-2.0, 9.0, 1.0])
    pts, tris = _sphere(centre, radius=0.5)
    edges = subdivision.mesh_edges(tris)
    straight = (CAMERA - pts) / np.linalg.norm(CAMERA - pts, axis=1)[:, None]
    e_flat, t_flat = silhouette.silhouette(pts, tris, edges.of_tri, len(edges.verts), straight)
    mid = 0.5 * (pts[edges.verts[e_flat, 0]] + pts[edges.verts[e_flat, 1]])
    n = (mid - centre) / np.linalg.norm(mid - centre, axis=1)[:, None]
    view = (CAMERA - mid) / np.linalg.norm(CAMERA - mid, axis=1)[:, None]
    assert np.degrees(np.abs(np.arcsin(np.einsum("ij,ij->i", n, view)))).max() < 10.0
    assert 36 <= e_flat.sum() < 0.2 * len(e_flat)
    # the limb is a closed loop: every silhouette edge's triangles are silhouette triangles
    assert np.all(t_flat[np.flatnonzero(e_flat.take(edges.of_tri).any(axis=1))])
    d, _ = illumination.towards_observer(pts, SCENE, lut, (1,))[1]
    e_lens, t_lens = silhouette.silhouette(pts, tris, edges.of_tri, len(edges.verts), d)
    assert 0.5 * e_flat.sum() < e_lens.sum() < 2 * e_flat.sum()
    sign = silhouette.facing_signs(pts, tris, d)
    assert np.all(t_lens[(sign != sign[:, :1]).any(axis=1)])  # split triangles are on it


def test_turned_away_needs_all_corners_beyond_the_margin():
    """silhouette.turned_away: n . d < -margin at all three corners (n the unit normal from the winding);
    a corner without a ray (NaN) or a degenerate triangle is never turned away."""
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 2, 0], [3, 3, 0]])  # normal +z
    tris = np.array([[0, 1, 2], [0, 1, 2], [0, 1, 2], [0, 3, 4]])
    down = np.array([0.0, 0.6, -0.8])  # n . d = -0.8
    d = np.tile(down, (5, 1))
    np.testing.assert_array_equal(silhouette.turned_away(pts, tris[:1], d, 0.5), [True])
    np.testing.assert_array_equal(silhouette.turned_away(pts, tris[:1], d, 0.85), [False])
    np.testing.assert_array_equal(silhouette.turned_away(pts, tris[:1, ::-1], d, 0.5), [False])  # normal -z
    d[2] = [0.0, 0.0, 1.0]
    assert not silhouette.turned_away(pts, tris[:1], d, 0.0).any()
    d[2] = np.nan
    assert not silhouette.turned_away(pts, tris[:1], d, 0.0).any()
    assert not silhouette.turned_away(pts, tris[3:], np.tile(down, (5, 1)), 0.0).any()  # collinear


def _ring_view(lut, pts, tris, **settings):
    cam = raytrace_camera(320, 180)
    src = pipeline.SourceMesh(pts, tris, corner_uv=np.zeros((len(tris), 3, 2)))
    out = pipeline.build_images(src, SCENE, lut, pipeline.Settings(pixel_angle=cam.pixel_angle, **settings),
                                frustum_planes=cam.frustum_planes())
    return out, rasterize.rasterize(rasterize.from_images(out), cam)


def raytrace_camera(width, height):
    return raytrace.Camera.look_at(CAMERA, HOLE, math.radians(19.0), width, height)


@pytest.mark.parametrize("angle", [170.0, 180.0])
def test_back_faces_are_skipped_without_changing_the_image(lut, monkeypatch, angle):
    """A closed sphere next to the axis behind the hole, seen along lensed rays: its triangles turned
    away from the camera (by more than BACK_FACE_MARGIN) are not subdivided. That removes a large
    share of the pieces, and the rasterized image shows the same (order, point) at all but a few
    edge pixels as with every triangle kept."""
    a = math.radians(angle)
    pts, tris = _sphere([3 * math.cos(a), 3 * math.sin(a), 0.01])
    out, img = _ring_view(lut, pts, tris)
    monkeypatch.setattr(budget, "BACK_FACE_MIN_PIECES", 10**12)
    full, img_full = _ring_view(lut, pts, tris)
    skipped = {o: out[o].report.back_face for o in out}
    assert all(full[o].report.back_face == 0 for o in full)
    busiest = max(out, key=lambda o: skipped[o])
    assert skipped[busiest] > 200
    assert len(out[busiest].tris) < 0.8 * len(full[busiest].tris)
    covered = img_full.hit.sum()
    assert covered > 1000
    differ = (img.hit != img_full.hit) | (img.hit & img_full.hit & (img.order != img_full.order))
    assert differ.sum() <= 0.002 * covered
    both = img.hit & img_full.hit & (img.order == img_full.order)
    far = np.linalg.norm(img.point[both] - img_full.point[both], axis=1) > 0.05
    assert far.sum() <= 0.002 * covered


def test_back_faces_are_kept_on_open_meshes_and_from_inside(lut):
    """Without a closed, outward-wound surface seen from outside there is no hidden side: a sphere with
    one triangle missing, and a sphere around the camera, keep every triangle."""
    a = math.radians(170.0)
    pts, tris = _sphere([3 * math.cos(a), 3 * math.sin(a), 0.01])
    open_out, _ = _ring_view(lut, pts, tris[1:])
    assert all(img.report.back_face == 0 for img in open_out.values())
    assert max(len(img.tris) for img in open_out.values()) > budget.BACK_FACE_MIN_PIECES
    inside_pts, inside_tris = _sphere([0.0, 0.0, 0.0], radius=30.0, segments=48, rings=24)
    lut40 = build_lut(20.0, 1.05, 40.0, 128, 256)
    out = pipeline.build_images(pipeline.SourceMesh(inside_pts, inside_tris), SCENE, lut40,
                                pipeline.Settings(pixel_angle=PIXEL))
    assert all(img.report.back_face == 0 for img in out.values())


def test_silhouette_of_an_open_disc_is_its_boundary(lut):
    pts, tris = _grid(-4.0, 1.0, 4, tilt=0.3)
    pts = pts + [0.0, 3.0, 0.0]  # off the axis
    edges = subdivision.mesh_edges(tris)
    d, _ = illumination.towards_observer(pts, SCENE, lut, (1,))[1]
    e, _ = silhouette.silhouette(pts, tris, edges.of_tri, len(edges.verts), d)
    boundary = np.bincount(edges.of_tri.ravel(), minlength=len(edges.verts)) == 1
    np.testing.assert_array_equal(e, boundary)


def test_pipeline_ring_reaches_the_einstein_radius(lut):
    """Behind the hole, the order-1 image of the sphere starts at the Einstein ring of the crossing
    point, all round (no culled gap), and order 2 ends there (the same ring: phi = pi either way);
    the ring's points lie CHORD_OUTSET of their chords' sag outside it (the refined band's chords,
    far shorter than the patch-edge tolerance allows)."""
    pts, tris = _sphere([-3.0, 0.0, 0.01])
    settings = pipeline.Settings(pixel_angle=PIXEL, max_error_px=MAX_ERROR)
    out = pipeline.build_images(pipeline.SourceMesh(pts, tris), SCENE, lut, settings)
    near = max(axis_patch.find_crossings(pts, tris, CAMERA, HOLE), key=lambda c: c.along)
    theta_e = np.pi - connect(20.0, abs(near.along), np.pi, 1).xi
    patch = max(_patches(pts, tris, lut, closed=True), key=lambda p: p.crossing.along)
    assert patch.band > 0 and patch.ring_chords > 4 * patch.n_azimuths
    sag = abs(float(axis_patch.chord_sag(np.pi - theta_e, 2 * np.pi / patch.ring_chords)))
    most = budget.CHORD_OUTSET * budget.PATCH_EDGE_FACTOR * budget.COVERAGE_FACTOR * settings.max_error_px * PIXEL
    assert budget.CHORD_OUTSET * sag < 0.1 * most
    outset = None
    for order in (1, 2):
        img = out[order]
        assert img.report.patch_faces > 0 and img.report.einstein_ring <= 10
        d = img.positions - CAMERA
        d /= np.linalg.norm(d, axis=1)[:, None]
        theta = _angle_from_hole(d)
        if order == 1:  # nothing of order 1 lies inside the ring (order 2 also shows the far side)
            outset = theta.min() - theta_e
            assert outset == pytest.approx(budget.CHORD_OUTSET * sag, rel=1e-2)
        at_ring = np.abs(theta - theta_e - outset) < 1e-7
        pa = np.arctan2(d[at_ring, 2], d[at_ring, 1])
        assert len(np.unique(((pa + np.pi) / (2 * np.pi) * 64).astype(int) % 64)) == 64
