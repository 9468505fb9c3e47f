"""Any object an artist marks (issue 19, items 3 and 4): every object type is imaged where it has
faces and otherwise skipped with a line in the report; nothing is dropped silently; one object's
trouble never touches the others' images. Runs on the pip bpy 4.2, 4.5 and 5.0.

Units: Blender units; the demo scene has r_s = 2 BU, the hole at the origin and the camera at
(40, 0, 0) looking along -x (20 r_s); odd objects are placed beside the hole, about 3-4 r_s from it.
"""
import math

import numpy as np
import pytest

import bpy  # noqa: E402

import grlens_addon  # noqa: E402
from grlens_addon.blender import gather, rebuild  # noqa: E402
from blender_session import empty_file, registered  # noqa: E402,F401  (autouse fixtures)


def _images():
    return {o.name: o for o in bpy.data.objects if o.grlens.order in (1, 2)}


def _positions(name):
    me = bpy.data.objects[name].data
    co = np.empty(3 * len(me.vertices), np.float32)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


class Demo:
    """The demo scene (160x90) with the sphere fixed at 90 degrees beside the hole, rebuilt once, and
    its images remembered, so that a test can check they stay intact beside an odd object."""

    def __init__(self):
        assert bpy.ops.grlens.demo_scene(r_s=2.0) == {"FINISHED"}
        self.scene = bpy.context.scene
        self.scene.render.resolution_x, self.scene.render.resolution_y = 160, 90
        self.g = self.scene.grlens
        self.g.auto_update = False  # the tests rebuild explicitly
        self.sphere = bpy.data.objects["OrbitingSphere"]
        self.sphere.animation_data_clear()
        self.sphere.parent = None
        self.sphere.location = (0.0, 6.0, 0.04)
        rep = rebuild.rebuild_scene(self.scene)
        assert isinstance(rep["objects"]["OrbitingSphere"], dict)
        self.before = {n: _positions(n) for n in ("OrbitingSphere.GR1", "OrbitingSphere.GR2")}
        assert all(len(p) for p in self.before.values())

    def link(self, obj, location=(0.0, -7.0, 1.0)):
        if obj.name not in self.scene.collection.objects:
            self.scene.collection.objects.link(obj)
        obj.location = location
        obj.grlens.enabled = True
        return obj

    def rebuild(self):
        rep = rebuild.rebuild_scene(self.scene)
        assert not rep["status"].startswith("grlens:"), rep["status"]
        assert self.g.report_lines == "\n".join(rep["warnings"])
        return rep

    def assert_sphere_intact(self, atol=0.0):
        """The sphere's images as first built (``atol`` BU: after a change of the lookup table)."""
        for name, pos in self.before.items():
            np.testing.assert_allclose(_positions(name), pos, rtol=0.0, atol=atol)


@pytest.fixture
def demo():
    return Demo()


def _assert_imaged(name, rep):
    imgs = _images()
    assert {f"{name}.GR1", f"{name}.GR2"} <= set(imgs), sorted(imgs)
    assert len(imgs[f"{name}.GR1"].data.polygons) > 0
    assert isinstance(rep["objects"][name], dict) or rep["objects"][name] == "unchanged"
    assert not any(w.startswith(f"{name}: skipped") or w.startswith(f"{name}: failed") for w in rep["warnings"]), \
        rep["warnings"]
    co = _positions(f"{name}.GR1")
    assert np.all(np.isfinite(co))


def _assert_skipped(name, rep, line):
    assert line in rep["warnings"], rep["warnings"]
    assert rep["objects"][name] == "skipped"
    assert not any(o.grlens.source and o.grlens.source.name == name and len(o.data.polygons)
                   for o in _images().values())


def _gn_tree(name, build):
    """A Geometry Nodes group with a geometry input and output; ``build(tree, group_in, group_out)``
    adds and links the nodes in between."""
    tree = bpy.data.node_groups.new(name, "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gi, go = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    build(tree, gi, go)
    return tree


def _cube_mesh(name, size=0.5):
    import bmesh

    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=size)
    bm.to_mesh(me)
    bm.free()
    return me


# -- meshes -------------------------------------------------------------------------------------


def test_empty_mesh_is_skipped_with_a_line_and_never_raises(demo):
    empty = demo.link(bpy.data.objects.new("Blank", bpy.data.meshes.new("Blank")))
    rep = demo.rebuild()
    _assert_skipped("Blank", rep, "Blank: skipped: no faces (empty mesh)")
    assert rep["status"].startswith("1 object(s) lensed, 1 skipped, r_obs = 20")
    demo.assert_sphere_intact()
    # the traceback came from every rebuild, property change and frame change: none now
    demo.g.auto_update = True
    demo.g.tess_a = 4.5
    demo.scene.frame_set(3)
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    assert "Blank: skipped: no faces (empty mesh)" in demo.g.report_lines.split("\n")
    # an object that had images and loses its faces: its images are emptied, not left stale
    empty.data = _cube_mesh("Solid")
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    assert len(bpy.data.objects["Blank.GR1"].data.polygons) > 0
    empty.data.clear_geometry()
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    assert len(bpy.data.objects["Blank.GR1"].data.polygons) == 0


def test_loose_vertices_and_edges_only_are_skipped(demo):
    me = bpy.data.meshes.new("Wire")
    me.from_pydata([(0, 0, 0), (0.5, 0, 0), (0.5, 0.5, 0), (0, 0, 0.5), (0.3, 0.3, 0.3)], [(0, 1), (1, 2)], [])
    demo.link(bpy.data.objects.new("Wire", me))
    rep = demo.rebuild()
    _assert_skipped("Wire", rep, "Wire: skipped: no faces (2 loose vertices, 2 loose edges)")
    demo.assert_sphere_intact()


def test_mesh_with_faces_and_loose_parts_is_imaged_and_the_loose_parts_named(demo):
    import bmesh

    me = _cube_mesh("Rubble")
    bm = bmesh.new()
    bm.from_mesh(me)
    bm.verts.new((0.0, 0.0, 1.0))  # a loose vertex
    bm.edges.new((bm.verts.new((0.0, 0.0, 1.2)), bm.verts.new((0.0, 0.3, 1.2))))  # a loose edge
    bm.to_mesh(me)
    bm.free()
    demo.link(bpy.data.objects.new("Rubble", me))
    rep = demo.rebuild()
    _assert_imaged("Rubble", rep)
    assert "Rubble: not imaged: 1 loose vertex, 1 loose edge (no faces)" in rep["warnings"], rep["warnings"]
    assert rep["status"].startswith("2 object(s) lensed, r_obs")
    demo.assert_sphere_intact()


# -- curves, text, metaballs, surfaces ----------------------------------------------------------


def _bezier(name, bevel=0.0, extrude=0.0):
    cu = bpy.data.curves.new(name, "CURVE")
    cu.dimensions = "3D"
    sp = cu.splines.new("BEZIER")
    sp.bezier_points.add(1)
    for p, co in zip(sp.bezier_points, ((-1.0, 0.0, 0.0), (1.0, 0.0, 0.5))):
        p.co = co
        p.handle_left_type = p.handle_right_type = "AUTO"
    cu.bevel_depth, cu.extrude = bevel, extrude
    return bpy.data.objects.new(name, cu)


def test_bezier_curve_without_bevel_is_skipped(demo):
    demo.link(_bezier("Thread"))
    rep = demo.rebuild()
    line = next(w for w in rep["warnings"] if w.startswith("Thread: "))
    assert line.startswith("Thread: skipped: no faces (") and "loose edges" in line, line
    assert line.endswith("; a curve needs a bevel, an extrusion or a fill to have faces)"), line
    assert rep["objects"]["Thread"] == "skipped"
    demo.assert_sphere_intact()


@pytest.mark.parametrize("shape", ["bevel", "extrude"])
def test_bezier_curve_with_bevel_or_extrusion_is_imaged(demo, shape):
    obj = demo.link(_bezier("Tube", **({"bevel": 0.2} if shape == "bevel" else {"extrude": 0.3})))
    rep = demo.rebuild()
    _assert_imaged("Tube", rep)
    assert not [w for w in rep["warnings"] if w.startswith("Tube")], rep["warnings"]
    assert obj.hide_render  # the curve itself is hidden from renders like a mesh source
    demo.assert_sphere_intact()


def test_text_is_imaged(demo):
    cu = bpy.data.curves.new("Sign", "FONT")
    cu.body = "GR"
    cu.size = 1.5
    obj = demo.link(bpy.data.objects.new("Sign", cu))
    obj.rotation_euler = (math.radians(90), 0.0, math.radians(90))  # facing the camera
    rep = demo.rebuild()
    _assert_imaged("Sign", rep)
    demo.assert_sphere_intact()


def test_metaballs_the_basis_is_imaged_an_element_is_skipped(demo):
    mb = bpy.data.metaballs.new("Blob")
    mb.elements.new().radius = 0.8
    basis = demo.link(bpy.data.objects.new("Blob", mb))
    mb2 = bpy.data.metaballs.new("Blob.001")
    mb2.elements.new().radius = 0.6
    demo.link(bpy.data.objects.new("Blob.001", mb2), location=(0.0, -7.0, 1.7))
    rep = demo.rebuild()
    _assert_imaged(basis.name, rep)
    _assert_skipped("Blob.001", rep, "Blob.001: skipped: no faces (a metaball element: its family's surface "
                                     "is built in the basis object 'Blob')")
    demo.assert_sphere_intact()


def test_nurbs_surface_is_imaged(demo):
    bpy.ops.surface.primitive_nurbs_surface_sphere_add(radius=0.8)
    obj = demo.link(bpy.context.object)
    obj.name = "Shell"
    rep = demo.rebuild()
    _assert_imaged("Shell", rep)
    demo.assert_sphere_intact()


# -- Geometry Nodes and instances ----------------------------------------------------------------


def test_geometry_nodes_mesh_primitive_is_imaged(demo):
    def build(tree, gi, go):
        ico = tree.nodes.new("GeometryNodeMeshIcoSphere")
        ico.inputs["Radius"].default_value = 0.7
        ico.inputs["Subdivisions"].default_value = 2
        tree.links.new(ico.outputs["Mesh"], go.inputs[0])

    obj = demo.link(bpy.data.objects.new("Made", bpy.data.meshes.new("Made")))  # no faces of its own
    obj.modifiers.new("GN", "NODES").node_group = _gn_tree("MakeIco", build)
    rep = demo.rebuild()
    _assert_imaged("Made", rep)
    demo.assert_sphere_intact()


def _gathered(obj):
    """gather.gather of a marked object as the rebuild does it (view layer depsgraph)."""
    dg = bpy.context.evaluated_depsgraph_get()
    found = gather.instances([obj], dg, with_normals=False)
    return gather.gather(obj, obj.evaluated_get(dg), found.get(obj.as_pointer()), with_normals=False)


def test_geometry_nodes_instance_on_points_is_imaged_with_every_instance(demo):
    red = bpy.data.materials.new("Red")

    def build(tree, gi, go):
        line = tree.nodes.new("GeometryNodeMeshLine")
        line.inputs["Count"].default_value = 4
        line.inputs["Offset"].default_value = (0.0, 0.0, 0.6)
        cube = tree.nodes.new("GeometryNodeMeshCube")
        cube.inputs["Size"].default_value = (0.3, 0.3, 0.3)
        mat = tree.nodes.new("GeometryNodeSetMaterial")
        mat.inputs["Material"].default_value = red
        iop = tree.nodes.new("GeometryNodeInstanceOnPoints")
        tree.links.new(cube.outputs["Mesh"], mat.inputs["Geometry"])
        tree.links.new(line.outputs["Mesh"], iop.inputs["Points"])
        tree.links.new(mat.outputs["Geometry"], iop.inputs["Instance"])
        tree.links.new(iop.outputs["Instances"], go.inputs[0])

    obj = demo.link(bpy.data.objects.new("Stack", bpy.data.meshes.new("Stack")))
    obj.modifiers.new("GN", "NODES").node_group = _gn_tree("Stack", build)
    got = _gathered(obj)
    assert got.skip is None and got.instances == 4 and len(got.mesh.tris) == 4 * 12
    z = got.mesh.positions[:, 2]
    assert z.max() - z.min() > 3 * 0.6  # the four cubes, stacked
    assert red in got.materials
    rep = demo.rebuild()
    _assert_imaged("Stack", rep)
    assert [m.name for m in bpy.data.objects["Stack.GR1"].data.materials] == ["Red (grlens)"]
    demo.assert_sphere_intact()


def test_collection_instance_is_imaged(demo):
    coll = bpy.data.collections.new("Props")
    for k, z in enumerate((0.0, 1.0)):
        o = bpy.data.objects.new(f"Prop{k}", _cube_mesh(f"Prop{k}", 0.5))
        o.location = (0.0, 0.0, z)
        coll.objects.link(o)  # not in the scene: only instanced
    empty = bpy.data.objects.new("PropsInstance", None)
    empty.instance_type = "COLLECTION"
    empty.instance_collection = coll
    assert gather.can_lens(empty)
    demo.link(empty)
    got = _gathered(empty)
    assert got.skip is None and got.instances == 2 and len(got.mesh.tris) == 24
    np.testing.assert_allclose(got.mesh.positions.mean(axis=0), (0.0, -7.0, 1.5), atol=1e-5)  # placed
    rep = demo.rebuild()
    _assert_imaged("PropsInstance", rep)
    assert empty.hide_render  # its instances render only through the images
    demo.assert_sphere_intact()


def test_particle_system_with_object_instances_is_imaged(demo):
    pebble = bpy.data.objects.new("Pebble", _cube_mesh("Pebble", 0.2))
    demo.scene.collection.objects.link(pebble)
    pebble.location = (0.0, 60.0, 0.0)  # the instanced object itself, out of the way (not marked)
    me = bpy.data.meshes.new("Ground")
    me.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
    emitter = demo.link(bpy.data.objects.new("Ground", me))
    emitter.rotation_euler = (0.0, math.radians(90), 0.0)  # facing the camera
    emitter.modifiers.new("Scatter", "PARTICLE_SYSTEM")
    st = emitter.particle_systems[0].settings
    st.count, st.frame_start, st.frame_end = 6, 1, 1
    st.physics_type, st.emit_from = "NO", "FACE"
    st.render_type, st.instance_object = "OBJECT", pebble
    got = _gathered(emitter)
    assert got.skip is None and got.instances == 6
    assert len(got.mesh.tris) == 2 + 6 * 12  # the emitter's own quad (shown) and the six pebbles
    rep = demo.rebuild()
    _assert_imaged("Ground", rep)
    assert not [w for w in rep["warnings"] if w.startswith("Ground")], rep["warnings"]
    # hair strands have no faces: named, the rest imaged
    emitter.modifiers.new("Fuzz", "PARTICLE_SYSTEM")
    emitter.particle_systems[-1].settings.type = "HAIR"
    emitter.particle_systems[-1].name = "Fuzz"
    rep = demo.rebuild()
    _assert_imaged("Ground", rep)
    assert "Ground: not imaged: hair of particle system 'Fuzz' (no faces)" in rep["warnings"], rep["warnings"]
    # the emitter hidden as an instancer ("Show Instancer" off for renders): the pebbles alone
    emitter.show_instancer_for_render = False
    assert len(_gathered(emitter).mesh.tris) == 6 * 12
    demo.assert_sphere_intact()


# -- types without faces -------------------------------------------------------------------------


def test_hair_curves_point_cloud_volume_and_empty_are_skipped(demo):
    hair = bpy.data.hair_curves.new("Fur")
    hair.add_curves([3, 3])
    demo.link(bpy.data.objects.new("Fur", hair))
    demo.link(bpy.data.objects.new("Dust", bpy.data.pointclouds.new("Dust")))
    demo.link(bpy.data.objects.new("Fog", bpy.data.volumes.new("Fog")))
    demo.link(bpy.data.objects.new("Nothing", None))
    lamp = demo.link(bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT")))
    assert not gather.can_lens(lamp) and gather.can_lens(bpy.data.objects["Fur"])
    rep = demo.rebuild()
    _assert_skipped("Fur", rep, "Fur: skipped: no faces (hair curves: 2 curves)")
    _assert_skipped("Dust", rep, "Dust: skipped: no faces (no points)")
    _assert_skipped("Fog", rep, "Fog: skipped: no faces (a volume)")
    _assert_skipped("Nothing", rep, "Nothing: skipped: no faces (an empty without instances)")
    _assert_skipped("Lamp", rep, "Lamp: skipped: nothing to image (a light has no geometry)")
    assert rep["status"].startswith("1 object(s) lensed, 5 skipped")
    assert bpy.data.objects["Fur"].hide_render and not lamp.hide_render  # a light marked by a script still lights
    demo.assert_sphere_intact()
    # the panel shows at most 8 lines, the rest summed up
    from grlens_addon.blender.panels import report_lines

    assert report_lines(demo.g) == demo.g.report_lines.split("\n")
    demo.g.report_lines = "\n".join(f"line {k}" for k in range(12))
    assert report_lines(demo.g) == [f"line {k}" for k in range(7)] + ["... and 5 more"]


# -- failures and losses -------------------------------------------------------------------------


def test_an_exception_in_one_object_leaves_the_others_images(demo, monkeypatch):
    from grlens_addon.core import pipeline

    cube = demo.link(bpy.data.objects.new("Crate", _cube_mesh("Crate")))
    demo.rebuild()
    assert len(bpy.data.objects["Crate.GR1"].data.polygons) > 0
    real = pipeline.build_images

    def flaky(src, *args, **kwargs):  # fails for the crate (its vertices are at y < -6 BU)
        if np.asarray(src.positions)[:, 1].max() < -6.0:
            raise RuntimeError("boom")
        return real(src, *args, **kwargs)

    monkeypatch.setattr(pipeline, "build_images", flaky)
    demo.sphere.location = (0.0, 6.0, 0.3)  # the sphere moved: it is rebuilt in the same pass
    cube.location = (0.0, -7.0, 1.2)
    rep = demo.rebuild()
    assert "Crate: failed: boom" in rep["warnings"]
    assert rep["objects"]["Crate"] == "failed" and isinstance(rep["objects"]["OrbitingSphere"], dict)
    assert rep["status"].startswith("1 object(s) lensed, 1 failed")
    assert len(bpy.data.objects["Crate.GR1"].data.polygons) == 0  # emptied, not stale
    sphere_now = _positions("OrbitingSphere.GR1")
    assert len(sphere_now) and not np.array_equal(sphere_now, demo.before["OrbitingSphere.GR1"])
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}  # the operator reports, it does not raise
    monkeypatch.setattr(pipeline, "build_images", real)
    rep = demo.rebuild()  # fixed: the crate is built again
    assert rep["warnings"] == [] and len(bpy.data.objects["Crate.GR1"].data.polygons) > 0


def test_triangles_beyond_the_table_and_inside_the_horizon_are_reported(demo):
    demo.g.lut_mode, demo.g.lut_r_max = "FIXED_RANGE", 40.0  # a table of limited range, explicitly
    far = demo.link(bpy.data.objects.new("Far", _cube_mesh("Far", 2.0)), location=(-200.0, 5.0, 5.0))  # 100 r_s
    inner = demo.link(bpy.data.objects.new("Inner", _cube_mesh("Inner", 0.4)), location=(0.0, 0.0, 0.1))
    rep = demo.rebuild()
    assert "Far: 12 of 12 triangles not imaged (12 beyond the lookup table's range, r > 40 r_s)" \
        in rep["warnings"], rep["warnings"]
    assert "Inner: 12 of 12 triangles not imaged (12 inside the horizon, r <= 1 r_s)" in rep["warnings"]
    assert not any(w.startswith("OrbitingSphere") for w in rep["warnings"])
    # the pieces are in the stats, and the lines stay while nothing changes
    assert rep["stats"]["Far"][1]["invalid_vertex"] >= 12
    again = demo.rebuild()
    assert again["objects"]["Far"] == "unchanged" and again["warnings"] == rep["warnings"]
    assert again["stats"]["Far"] == rep["stats"]["Far"]
    # half of a cube beyond the range: only the triangles with a corner out there are counted
    far.location = (-80.0 + 1.0, 5.0, 0.0)  # x from -80 to -78: its far face's corners at r > 40 r_s
    inner.grlens.enabled = False
    rep = demo.rebuild()
    line = next(w for w in rep["warnings"] if w.startswith("Far: "))
    assert line.startswith("Far: ") and " of 12 triangles not imaged (" in line and "beyond" in line, line
    assert int(line.split()[1]) < 12
    demo.assert_sphere_intact(atol=1e-3)  # rebuilt with the fixed-range table: the same to far below a pixel
    # tables out to infinity (the default): the far cube is imaged, what is inside the horizon is not;
    # (its image lies near the Einstein ring, about 20 degrees from the hole: a wider view shows it)
    far.location = (-200.0, 5.0, 5.0)
    inner.grlens.enabled = True
    demo.g.lut_mode = "EVERY_DISTANCE"
    demo.scene.camera.data.angle_y = math.radians(60.0)
    rep = demo.rebuild()
    assert not [w for w in rep["warnings"] if w.startswith("Far")], rep["warnings"]
    assert len(bpy.data.objects["Far.GR1"].data.polygons) > 0
    assert "Inner: 12 of 12 triangles not imaged (12 inside the horizon, r <= 1 r_s)" in rep["warnings"]


def test_the_operator_reports_each_line(demo, capfd):
    demo.link(bpy.data.objects.new("Blank", bpy.data.meshes.new("Blank")))
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    out = capfd.readouterr()
    assert "Blank: skipped: no faces (empty mesh)" in out.out + out.err
    assert demo.g.status.startswith("1 object(s) lensed, 1 skipped")


def test_editing_an_instanced_object_updates_the_instancers_images(demo):
    """With auto update, moving an object that a marked collection instance shows (the object itself
    is not marked) rebuilds the instancer's images: the depsgraph updates the instancer with what it
    instances, so the handler sees a marked object change."""
    coll = bpy.data.collections.new("Props")
    demo.scene.collection.children.link(coll)  # in the view layer, so that it can be edited
    prop = bpy.data.objects.new("Prop", _cube_mesh("Prop", 0.5))
    coll.objects.link(prop)
    prop.location = (0.0, 0.0, 40.0)  # the original far above the camera's view
    empty = bpy.data.objects.new("PropsInstance", None)
    empty.instance_type, empty.instance_collection = "COLLECTION", coll
    coll.instance_offset = (0.0, 0.0, 40.0)
    demo.link(empty)
    demo.g.auto_update = True
    bpy.context.view_layer.update()
    a = _positions("PropsInstance.GR1")
    prop.location = (0.0, 0.5, 40.5)
    bpy.context.view_layer.update()
    b = _positions("PropsInstance.GR1")
    assert len(a) and len(b) and (a.shape != b.shape or not np.allclose(a, b))


def test_combined_instances_keep_outward_winding_and_own_slots_first():
    """gather.combine: instances placed by mirroring matrices are turned over (their faces stay
    outward: the geometric normal agrees with the carried corner normal); the object's own slots come
    first as they are, an instanced mesh adds only the materials its faces use; a matrix of scale 0
    gives zero normals, not an error."""
    a, b, c = (bpy.data.materials.new(n) for n in "ABC")
    tri = gather.Part(co=np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), tris=np.array([[0, 1, 2]]),
                      corner_uv=None, material=np.array([1]), corner_normals=np.tile([0.0, 0, 1], (1, 3, 1)),
                      materials=[b, c])
    own = gather.Part(co=tri.co, tris=tri.tris, corner_uv=np.zeros((1, 3, 2)), material=np.array([0]),
                      corner_normals=tri.corner_normals, materials=[a, None])
    mirror = np.diag([1.0, 1.0, -1.0, 1.0])
    mats = np.stack([np.eye(4), mirror, np.diag([0.0, 0.0, 0.0, 1.0])])
    mesh, slots = gather.combine([(own, np.eye(4)[None]), (tri, mats)], with_normals=True)
    assert slots == [a, None, c]  # B is unused by the instanced faces
    assert mesh.material.tolist() == [0, 2, 2, 2]
    assert mesh.corner_uv.shape == (4, 3, 2)
    p = mesh.positions[mesh.tris]
    geometric = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    for k in (0, 1, 2):  # own, instance, mirrored instance
        assert geometric[k] @ mesh.corner_normals[k, 0] > 0
    assert np.all(mesh.corner_normals[3] == 0)
