"""Dense meshes: the image mesh's edges from the source's topology (assemble.image_edges) against
every edge found from the faces alone, on scenes of every kind of piece (whole source triangles,
cut ones, strips, axis patches, refined pieces); the closed surface's volume from shared normals;
the upload of those edges into Blender (a valid mesh, as Blender would have found them)."""
import os
import sys
import threading

import numpy as np
import pytest

from grlens_addon.core import assemble, mapping, pipeline, subdivision, visibility
from lutgen import LUTFamily
from meshes import grid

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
import bench_accuracy as BA  # noqa: E402
from bench_frame import uv_sphere  # noqa: E402

R_OBS = 20.0
CAM = BA.camera(320, 180)
SCENE = mapping.Scene(CAM.position, np.zeros(3), 1.0)


@pytest.fixture(scope="module")
def table():
    return LUTFamily().at(R_OBS)


def _dense_sphere(angle):
    """A UV sphere of 20k triangles (radius 0.5 r_s) on the orbit r = 3 r_s at ``angle`` degrees."""
    pts, tris = uv_sphere(144, 72, 0.5)
    a = np.radians(angle)
    return pipeline.SourceMesh(pts + [3 * np.cos(a), 3 * np.sin(a), 0.01], tris)


SCENES = {
    "sphere 45": lambda: BA.sphere_scene(45)[0],
    "sphere 180 (patches)": lambda: BA.sphere_scene(180)[0],
    "sphere 0": lambda: BA.sphere_scene(0)[0],
    "floor (cut, strips)": lambda: grid(-150, 30, -60, 60, 30, 20, "z", -2.0),
    "dense sphere 60": lambda: _dense_sphere(60),
    "dense sphere 175": lambda: _dense_sphere(175),
}


def _check_edges(img):
    verts, corner_edge = img.edges()
    assert img.edges()[0] is verts  # (found once: a worker thread's build finds them for the upload)
    tris = img.tris
    assert corner_edge.shape == tris.shape
    ends = verts[corner_edge]  # (F, 3, 2): each corner's edge joins that corner and the next
    a, b = tris, np.roll(tris, -1, axis=1)
    assert np.array_equal(np.minimum(ends[..., 0], ends[..., 1]), np.minimum(a, b))
    assert np.array_equal(np.maximum(ends[..., 0], ends[..., 1]), np.maximum(a, b))
    lo, hi = verts.min(axis=1), verts.max(axis=1)
    assert np.all(lo < hi) and np.all(lo >= 0) and np.all(hi < len(img.positions))
    assert len(np.unique(lo * len(img.positions) + hi)) == len(verts)  # unique
    assert len(verts) == len(subdivision.mesh_edges(tris).verts)  # every edge the faces have, no other
    return len(verts)


@pytest.mark.parametrize("name", list(SCENES))
def test_image_edges_are_the_faces_edges(table, name):
    """ImageMesh.edges (source edges for whole source triangles, the others sorted out) gives exactly
    the unique edges of the faces, each corner's edge joining it and the next corner."""
    src = SCENES[name]()
    settings = BA.make_settings(CAM)
    out = pipeline.build_images(src, SCENE, table, settings, frustum_planes=CAM.frustum_planes())
    n = 0
    for img in out.values():
        if len(img.tris):
            assert img.edge_basis is not None
            n += _check_edges(img)
    assert n > 0
    if name == "sphere 180 (patches)":
        assert any(img.report.patch_faces for img in out.values())


def test_image_edges_without_a_basis_are_found_from_the_faces():
    """An image mesh made elsewhere (no source to take edges from) finds them from its faces."""
    pts, tris = uv_sphere(8, 5, 1.0)
    img = assemble.ImageMesh(1, pts, tris, None, np.zeros(len(tris), np.int64), np.zeros(len(pts)), None, None)
    assert _check_edges(img) == len(subdivision.mesh_edges(tris).verts)
    empty = assemble.ImageMesh(1, np.zeros((0, 3)), np.zeros((0, 3), np.int64), None, np.zeros(0, np.int64),
                               np.zeros(0), None, None)
    v, c = empty.edges()
    assert v.shape == (0, 2) and c.shape == (0, 3)


def test_closed_volume_from_shared_normals():
    """is_closed_outward with the triangles' normals given is the tetrahedra's volume sum as before:
    a sphere is closed outwards, turned inside out it is not, with or without a hole in it."""
    pts, tris = uv_sphere(24, 12, 1.0)
    pts = pts + [1e4, 0, 0]  # far from the origin: the volume is taken about a vertex
    for t, want in ((tris, True), (tris[:, ::-1], False), (tris[1:], False)):
        e = subdivision.mesh_edges(t)
        given = visibility.is_closed_outward(pts, t, e, normals=lambda: visibility.silhouette.normals(pts, t))
        assert visibility.is_closed_outward(pts, t) is want and given is want


def test_block_passes_are_the_plain_arithmetic_to_the_bit(monkeypatch):
    """The dense passes in blocks (frame.edge_lengths, visibility's pass over the triangles) give
    exactly what the plain whole-array arithmetic gives (observer_view.chord_length; the back-face
    masks of visibility._away_rows), NaN and degenerate triangles included, whatever the block size,
    the closed surface's volume that sum to rounding, and the back-face masks those of the unit
    leaving directions dotted with the unit normals (but within 1e-12 of the margin); their
    checkpoint is called between blocks."""
    from grlens_addon.core import frame as F
    from grlens_addon.core import observer_view

    rng = np.random.default_rng(5)
    pts = rng.normal(size=(3000, 3)) * 4.0
    pts[7] = np.nan
    tris = rng.integers(0, len(pts), (9000, 3))
    tris[:5, 1] = tris[:5, 0]  # degenerate
    d = rng.normal(size=(len(pts), 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    d[11] = np.nan
    ev = rng.integers(0, len(pts), (7000, 2))
    # the back-face test's inputs: an orthonormal pair e1, e2 per vertex and unit in-plane directions
    e1 = np.array([0.6, 0.0, 0.8])
    e2 = rng.normal(size=(len(pts), 3))
    e2 -= np.multiply.outer(e2 @ e1, e1)
    e2 /= np.linalg.norm(e2, axis=1)[:, None]
    ang = rng.uniform(0, 2 * np.pi, (2, len(pts)))
    in_plane = {1: (np.cos(ang[0]), np.sin(ang[0])), 2: (np.cos(ang[1]), np.sin(ang[1]))}
    in_plane[2][0][11] = np.nan
    ok = np.isfinite(pts).all(axis=1)[tris].all(axis=1)
    for block in (1000, 1 << 15):
        monkeypatch.setattr(F, "EDGE_BLOCK", block)
        monkeypatch.setattr(visibility, "TRI_BLOCK", block)
        calls = []
        chord, length = F.edge_lengths([d, pts], ev, lambda q: calls.append(q))
        assert len(calls) == (len(ev) - 1) // block
        np.testing.assert_array_equal(chord, observer_view.chord_length(d[ev[:, 1]], d[ev[:, 0]]))
        assert np.array_equal(length, observer_view.row_norm(pts[ev[:, 1]] - pts[ev[:, 0]]), equal_nan=True)
        n_calls = len(calls)
        six, away = visibility._whole_pass(pts, tris, e1, e2, in_plane, True, lambda q: calls.append(q))
        assert len(calls) - n_calls == (len(tris) - 1) // block
        want = visibility.silhouette.normals(pts, tris)
        p0 = pts[tris[:, 0]] - pts[tris[0, 0]]
        whole = np.einsum("ij,ij->", p0[ok], want[ok])  # (the triangles without a NaN corner)
        clean = visibility._whole_pass(pts, tris[ok], e1, e2, {}, True)[0]
        assert abs(clean - whole) <= 1e-12 * np.abs(np.einsum("ij,ij->i", p0[ok], want[ok])).sum()
        assert np.isnan(six)  # (a NaN corner)
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = want / observer_view.row_norm(want)[:, None]
        assert set(away) == {1, 2}
        for o in (1, 2):
            # the same arithmetic on whole arrays, to the bit
            np.testing.assert_array_equal(away[o], visibility._away_rows(unit, tris, e1, e2, in_plane)[o])
            # against the unit directions d = (a e1 + b e2) / |a e1 + b e2| dotted with n
            a, b = in_plane[o]
            u = np.multiply.outer(a, e1) + b[:, None] * e2
            with np.errstate(invalid="ignore", divide="ignore"):
                u /= observer_view.row_norm(u)[:, None]
                dots = np.stack([np.einsum("fx,fx->f", unit, u[tris[:, k]]) for k in range(3)], axis=1)
            near = (np.abs(dots + visibility.B.BACK_FACE_MARGIN) < 1e-12).any(axis=1)
            np.testing.assert_array_equal(away[o][~near], (dots < -visibility.B.BACK_FACE_MARGIN).all(axis=1)[~near])
            assert 0 < away[o].sum() < len(tris)


@pytest.mark.parametrize("threads", [1, 2])
def test_the_map_in_chunks_is_one_call_to_the_bit(table, monkeypatch, threads):
    """frame.images_in_chunks (a dense mesh's vertices and edge midpoints in calls of MAP_CHUNK points,
    a checkpoint between calls, or between pairs of calls run in two threads) gives exactly the
    values of one call, tangents and plane included."""
    from grlens_addon.core import frame as F

    monkeypatch.setattr(F, "THREADS", threads)
    assert F.threads_for(table)

    src = _dense_sphere(60)
    fr = F.frame_context(SCENE, table, BA.make_settings(CAM), None, CAM.frustum_planes())
    plane = mapping.plane_coordinates(src.positions, SCENE)
    whole = fr.map.images(src.positions, fr.orders, plane, tangents=True)
    calls = []
    fr.check = calls.append
    monkeypatch.setattr(F, "MAP_CHUNK", 3000)
    for given in (plane, None):
        calls.clear()
        parts = F.images_in_chunks(fr, src.positions, given, True, (0.0, 0.5))
        n_calls = -(-len(src.positions) // 3000)
        assert len(calls) == (n_calls - 1) // threads and all(0 < c < 0.5 for c in calls)
        for o in fr.orders:
            for name in ("position", "direction", "distance", "valid", "xi", "dt", "ux", "uy"):
                assert np.array_equal(getattr(parts[o], name), getattr(whole[o], name), equal_nan=True), name
            for name in ("r", "phi", "e2", "on_axis"):
                assert np.array_equal(getattr(parts[o].plane, name), getattr(plane, name)), name


@pytest.mark.parametrize("name", ["sphere 180 (patches)", "dense sphere 60"])
def test_two_threads_build_the_images_of_one(table, monkeypatch, name):
    """build_images with frame.THREADS = 2 (the map's chunks two at a time, both orders assembled at
    once) gives exactly the images of the calling thread alone, a light's irradiance included."""
    from grlens_addon.core import frame as F

    src = SCENES[name]()
    rng = np.random.default_rng(6)
    src.corner_normals = rng.normal(size=(len(src.tris), 3, 3)).astype(np.float32)
    monkeypatch.setattr(pipeline, "ASSEMBLE_THREADS_MIN", 0)
    monkeypatch.setattr(F, "MAP_CHUNK", 3000)
    light = pipeline.Light(np.array([0.0, 0.0, 30.0]), 1.0, LUTFamily().at(30.0))
    got = {}
    for threads in (1, 2):
        monkeypatch.setattr(F, "THREADS", threads)
        got[threads] = pipeline.build_images(src, SCENE, table, BA.make_settings(CAM), light, CAM.frustum_planes())
    assert list(got[1]) == list(got[2]) == [1, 2]
    for o in got[1]:
        for k, v in vars(got[1][o]).items():
            if isinstance(v, np.ndarray):
                assert np.array_equal(v, getattr(got[2][o], k), equal_nan=True), k
        assert len(got[1][o].tris) > 0 and got[1][o].irradiance is not None


def test_cleaning_shortcuts_keep_what_the_full_tests_keep():
    """frame.clean_source's shortcuts (every index in range, every coordinate finite: two reductions)
    drop exactly the triangles the full per-corner tests drop, and the edges kept per topology are
    found again for an equal index array only."""
    from grlens_addon.core import frame as F

    pts, tris = uv_sphere(24, 12, 1.0)
    for bad_pts, bad_tris, n_bad in ((None, None, 0), ({3: np.inf}, None, 6), (None, {(4, 1): -1}, 1),
                                     (None, {(5, 2): len(pts)}, 1), ({0: np.nan}, {(6, 0): len(pts) + 3}, 25)):
        p, t = pts.copy(), tris.copy()
        for i, v in (bad_pts or {}).items():
            p[i, 0] = v
        for (i, k), v in (bad_tris or {}).items():
            t[i, k] = v
        cleaned, dropped = F.clean_source(pipeline.SourceMesh(p, t, np.zeros((len(t), 3, 2))))
        ok = np.array([all(0 <= v < len(p) for v in row) and len(set(row)) == 3
                       and all(np.isfinite(p[v]).all() for v in row) for row in t])
        assert dropped == int((~ok).sum()) and (dropped > 0) == (n_bad > 0), (bad_pts, bad_tris)
        np.testing.assert_array_equal(cleaned.tris, t[ok])
    uv = np.zeros((len(tris), 3, 2))
    uv[2, 1, 0] = np.nan
    cleaned, _ = F.clean_source(pipeline.SourceMesh(pts, tris, uv))
    assert np.isfinite(cleaned.corner_uv).all() and cleaned.corner_uv[2, 1, 0] == 0.0
    a = F._edges_of(tris)
    assert F._edges_of(tris.copy()) is a
    other = tris.copy()
    other[0] = other[0, ::-1]
    assert F._edges_of(other) is not a


@pytest.mark.parametrize("name", ["sphere 180 (patches)", "floor (cut, strips)", "sphere 45"])
def test_float32_uvs_give_the_same_image_uvs(table, name):
    """UVs given in float32 (as Blender stores them and the gather passes them on) give the same image
    UVs as the same values in float64: taken as they are for whole source triangles, interpolated in
    float64 for cut pieces and patch faces."""
    src = SCENES[name]()
    if src.corner_uv is None:
        rng = np.random.default_rng(3)
        src.corner_uv = rng.random((len(src.tris), 3, 2))
    uv32 = np.asarray(src.corner_uv, np.float32)
    settings = BA.make_settings(CAM)
    a = pipeline.build_images(pipeline.SourceMesh(src.positions, src.tris, uv32.astype(np.float64)), SCENE, table,
                              settings, frustum_planes=CAM.frustum_planes())
    b = pipeline.build_images(pipeline.SourceMesh(src.positions, src.tris, uv32), SCENE, table, settings,
                              frustum_planes=CAM.frustum_planes())
    for o in a:
        np.testing.assert_array_equal(a[o].tris, b[o].tris)
        np.testing.assert_array_equal(a[o].corner_uv, b[o].corner_uv)
        assert b[o].corner_uv.dtype in (np.float32, np.float64)


@pytest.mark.parametrize("name", ["sphere 180 (patches)", "floor (cut, strips)", "sphere 45"])
def test_float32_normals_give_the_float32_of_the_image_normals(table, name):
    """Corner normals given in float32 (as the gather passes them on) give, for whole source
    triangles, the float32 of the image normals the same values in float64 give (what the upload
    wrote before), and for cut pieces and patch faces normals interpolated in float64 from the same
    values (equal to rounding); the GR irradiance from them is equal to 1e-6 relative."""
    src = SCENES[name]()
    rng = np.random.default_rng(4)
    n = rng.normal(size=(len(src.tris), 3, 3))
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    n32 = n.astype(np.float32)
    settings = BA.make_settings(CAM)
    light = pipeline.Light(np.array([0.0, 0.0, 30.0]), 1.0, LUTFamily().at(30.0))
    a = pipeline.build_images(pipeline.SourceMesh(src.positions, src.tris, None, None, n32.astype(np.float64)),
                              SCENE, table, settings, light, CAM.frustum_planes())
    b = pipeline.build_images(pipeline.SourceMesh(src.positions, src.tris, None, None, n32), SCENE, table,
                              settings, light, CAM.frustum_planes())
    for o in a:
        np.testing.assert_array_equal(a[o].tris, b[o].tris)
        assert a[o].corner_normal.shape == b[o].corner_normal.shape
        np.testing.assert_array_equal(np.asarray(a[o].corner_normal, np.float32),
                                      np.asarray(b[o].corner_normal, np.float32))
        np.testing.assert_allclose(b[o].irradiance, a[o].irradiance, rtol=1e-6, atol=0)


def test_image_edges_upload_into_a_valid_blender_mesh(table):
    """The edges written by upload.upload are a valid mesh for Blender (validate() changes nothing)
    and the ones Blender finds itself."""
    bpy = pytest.importorskip("bpy")
    from grlens_addon.blender import upload

    out = pipeline.build_images(SCENES["floor (cut, strips)"](), SCENE, table, BA.make_settings(CAM),
                                frustum_planes=CAM.frustum_planes())
    img = out[1]
    me = bpy.data.meshes.new("edges test")
    try:
        upload.upload(me, img, [])
        assert len(me.edges) == len(img.edges()[0]) and len(me.polygons) == len(img.tris)
        assert all(p.use_smooth for p in me.polygons[:50])
        cv = np.empty(len(me.loops), np.int32)
        me.attributes[".corner_vert"].data.foreach_get("value", cv)
        assert np.array_equal(cv.reshape(-1, 3), img.tris)
        copy = me.copy()
        assert not copy.validate(verbose=False)  # nothing to fix
        theirs = bpy.data.meshes.new("blender's edges")  # Blender's own search for them
        theirs.vertices.add(len(img.positions))
        theirs.loops.add(3 * len(img.tris))
        theirs.polygons.add(len(img.tris))
        theirs.attributes[".corner_vert"].data.foreach_set("value", img.tris.astype(np.int32).ravel())
        theirs.polygons.foreach_set("loop_start", np.arange(0, 3 * len(img.tris), 3, dtype=np.int32))
        theirs.update()
        ev = np.empty(2 * len(me.edges), np.int32)
        me.edges.foreach_get("vertices", ev)
        tv = np.empty(2 * len(theirs.edges), np.int32)
        theirs.edges.foreach_get("vertices", tv)
        mine = {tuple(sorted(p)) for p in ev.reshape(-1, 2)}
        assert mine == {tuple(sorted(p)) for p in tv.reshape(-1, 2)}
        bpy.data.meshes.remove(copy)
        bpy.data.meshes.remove(theirs)
    finally:
        bpy.data.meshes.remove(me)


def _uv_sphere(bpy, name, segments, rings):
    """A new Blender mesh ``name``: a UV sphere of radius 1 BU, ``segments`` x ``rings``, UVs in "UVMap"."""
    import bmesh

    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=1.0, calc_uvs=True)
    bm.to_mesh(me)
    bm.free()
    return me


def test_gather_reuses_what_it_derived_from_equal_arrays_only():
    """gather.mesh_part reuses the triangle corners, UVs and normals it derived from a mesh whose
    arrays are equal to those read just before (an object that only moves), and derives them again
    (the same as a first read) as soon as positions, UVs or the topology differ; the world normals are
    reused for the same local normals and the same linear part of the matrix only."""
    bpy = pytest.importorskip("bpy")

    from grlens_addon.blender import gather

    me = _uv_sphere(bpy, "gather reuse", 16, 8)
    try:
        def fresh():
            gather._KNOWN.clear()
            return gather.mesh_part(me)

        first = fresh()
        again = gather.mesh_part(me)
        assert again.tris is first.tris and again.corner_uv is first.corner_uv
        assert again.corner_normals is first.corner_normals
        me.vertices[20].co.x += 0.3  # a quad folded or not: the corners are derived again
        moved = gather.mesh_part(me)
        assert moved.tris is not first.tris
        want = fresh()
        np.testing.assert_array_equal(moved.tris, want.tris)
        np.testing.assert_array_equal(moved.corner_normals, want.corner_normals)
        me.uv_layers.active.uv[5].vector = (0.25, 0.75)
        changed = gather.mesh_part(me)
        assert changed.corner_uv is not want.corner_uv
        np.testing.assert_array_equal(changed.corner_uv, fresh().corner_uv)
        assert (changed.corner_uv == [0.25, 0.75]).all(axis=-1).any()
        rot = np.array([[0.0, -2.0, 0.0], [2.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
        n1 = gather._world_normals(first.corner_normals, rot)
        assert gather._world_normals(first.corner_normals, rot.copy()) is n1
        n2 = gather._world_normals(first.corner_normals, np.diag([1.0, 2.0, 3.0]))
        assert n2 is not n1
        inv_t = np.linalg.inv(np.diag([1.0, 2.0, 3.0])).T
        direct = first.corner_normals @ inv_t.T
        direct /= np.linalg.norm(direct, axis=-1, keepdims=True)
        # float32, as Blender stores normals: the float64 transform rounded once
        assert n1.dtype == n2.dtype == first.corner_normals.dtype == np.float32
        np.testing.assert_allclose(n2, direct, rtol=0, atol=6e-8)
        np.testing.assert_allclose(np.linalg.norm(n1.astype(np.float64), axis=-1), 1.0, atol=2e-7)
        rot_t = np.linalg.inv(rot).T
        want = first.corner_normals.astype(np.float64) @ rot_t.T
        want /= np.linalg.norm(want, axis=-1, keepdims=True)
        np.testing.assert_allclose(n1, want, rtol=0, atol=2e-7)  # (Blender's own normals unit to float32)
    finally:
        bpy.data.meshes.remove(me)
        gather._KNOWN.clear()
        gather._LAST_NORMALS.clear()


def test_gather_reuse_is_dropped_on_file_load_and_unregister():
    """The gather's reuse (gather._KNOWN, _LAST_NORMALS: up to two meshes' arrays) is dropped when a
    file is loaded (the load_pre handler) and when the add-on is unregistered: the last file's meshes
    are not kept alive."""
    bpy = pytest.importorskip("bpy")

    import grlens_addon
    from grlens_addon.blender import gather, handlers

    grlens_addon.register()

    def fill():
        me = _uv_sphere(bpy, "gather forget", 8, 4)
        part = gather.mesh_part(me)
        gather._world_normals(part.corner_normals, np.eye(3))
        bpy.data.meshes.remove(me)
        assert gather._KNOWN and any(gather._KNOWN) and gather._LAST_NORMALS

    try:
        fill()
        assert handlers.on_load_pre in bpy.app.handlers.load_pre
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)  # (load_pre runs)
        assert not any(gather._KNOWN) and not gather._LAST_NORMALS
        fill()
        grlens_addon.unregister()
        assert not any(gather._KNOWN) and not gather._LAST_NORMALS
    finally:
        grlens_addon.register()
        gather.forget_all()


def test_unregister_stops_the_cores_worker_thread():
    """Disabling the add-on shuts the core's worker thread for dense meshes down (frame.stop_threads):
    no thread of grlens' is left running, and the next dense build makes a new one."""
    pytest.importorskip("bpy")
    import threading

    import grlens_addon
    from grlens_addon.core import frame

    def workers():
        return [t for t in threading.enumerate() if t.name.startswith("grlens-core") and t.is_alive()]

    grlens_addon.register()
    try:
        pool = frame.beside()
        assert pool is not None and pool.submit(lambda: 1).result() == 1
        assert workers()
        grlens_addon.unregister()
        assert not workers() and not frame._POOL
    finally:
        grlens_addon.register()
    assert frame.beside() is not pool


def test_a_failed_order_raises_its_own_error_not_the_workers(table, monkeypatch):
    """When both orders are assembled at once and both fail, the calling thread's error is raised (the
    worker's order is waited for, its error dropped); when only the worker's order fails, its error is
    raised."""
    from grlens_addon.core import frame as F

    src = SCENES["sphere 180 (patches)"]()
    monkeypatch.setattr(pipeline, "ASSEMBLE_THREADS_MIN", 0)
    monkeypatch.setattr(F, "THREADS", 2)
    real = pipeline.assemble
    main = threading.get_ident()

    class Here(Exception):
        pass

    class Worker(Exception):
        pass

    for fail_here in (True, False):
        def failing(*args, **kw):
            if threading.get_ident() != main:
                raise Worker()
            if fail_here:
                raise Here()
            return real(*args, **kw)

        monkeypatch.setattr(pipeline, "assemble", failing)
        with pytest.raises(Here if fail_here else Worker):
            pipeline.build_images(src, SCENE, table, BA.make_settings(CAM), None, CAM.frustum_planes())
