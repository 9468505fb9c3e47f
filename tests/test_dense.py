"""Dense meshes: the image mesh's edges from the source's topology (assemble.image_edges) against
every edge found from the faces alone, on scenes of every kind of piece (whole source triangles,
cut ones, strips, axis patches, refined pieces); the closed surface's volume from shared normals;
the upload of those edges into Blender (a valid mesh, as Blender would have found them)."""
import os
import sys

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
