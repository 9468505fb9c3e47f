"""The Blender layer on the pip `bpy` module (4.5 LTS): registration, rebuild, frame updates, bad input.

Units: Blender units; r_s = 2 BU in the demo scene (camera at 20 r_s).
"""
import math

import numpy as np
import pytest

import bpy  # noqa: E402  (pinned in requirements/dev.txt)

import grlens_addon  # noqa: E402
from blender_session import empty_file, registered  # noqa: E402,F401  (autouse fixtures)


def _image_objects():
    return {o.name: o for o in bpy.data.objects if o.grlens.order in (1, 2)}


def _small_demo(r_s=2.0):
    assert bpy.ops.grlens.demo_scene(r_s=r_s) == {"FINISHED"}
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 160, 90
    return scene, bpy.data.objects["OrbitingSphere"]


def _place(sphere, deg, r_s=2.0):
    """Sphere on the 3 r_s orbit at azimuth deg from the hole-camera axis (0 = in front of the hole)."""
    a = math.radians(deg)
    sphere.parent = None
    sphere.location = (3 * r_s * math.cos(a), 3 * r_s * math.sin(a), 0.02 * r_s)


def test_registration_round_trip():
    assert hasattr(bpy.types.Scene, "grlens") and hasattr(bpy.types.Object, "grlens")
    assert hasattr(bpy.ops.grlens, "rebuild")
    grlens_addon.unregister()
    assert not hasattr(bpy.types.Scene, "grlens")
    grlens_addon.register()
    assert bpy.context.scene.grlens.r_s == 1.0


def test_demo_scene_builds_both_orders_and_leaves_source_alone():
    scene, sphere = _small_demo()
    _place(sphere, 90)
    before = np.array([v.co[:] for v in sphere.data.vertices])
    n_poly = len(sphere.data.polygons)
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    imgs = _image_objects()
    assert set(imgs) == {"OrbitingSphere.GR1", "OrbitingSphere.GR2"}
    for o in imgs.values():
        assert len(o.data.polygons) > 0
        assert o.users_collection[0].name == "grlens"
        assert "light_travel_time" in o.data.attributes and "UVMap" in o.data.uv_layers
        ltt = np.empty(len(o.data.vertices), np.float32)
        o.data.attributes["light_travel_time"].data.foreach_get("value", ltt)
        assert np.all(np.isfinite(ltt)) and ltt.min() > 30  # c*dt > the 40 BU camera distance minus the orbit
    after = np.array([v.co[:] for v in sphere.data.vertices])
    assert np.array_equal(before, after) and len(sphere.data.polygons) == n_poly
    assert sphere.visible_camera is False and sphere.hide_render is True
    # disabling restores the source's visibility and removes its images
    sphere.grlens.enabled = False
    assert sphere.visible_camera is True and sphere.hide_render is False and not _image_objects()


def test_images_follow_the_frame():
    scene, sphere = _small_demo()
    sphere.animation_data_clear()
    _place(sphere, 90)
    sphere.keyframe_insert("location", frame=1)
    _place(sphere, 60)
    sphere.keyframe_insert("location", frame=2)
    scene.frame_set(1)
    a = np.array([v.co[:] for v in bpy.data.objects["OrbitingSphere.GR1"].data.vertices])
    scene.frame_set(2)
    b = np.array([v.co[:] for v in bpy.data.objects["OrbitingSphere.GR1"].data.vertices])
    scene.frame_set(1)
    c = np.array([v.co[:] for v in bpy.data.objects["OrbitingSphere.GR1"].data.vertices])
    assert a.shape != b.shape or not np.allclose(a, b)
    assert np.array_equal(a, c)  # deterministic: same frame, same geometry


def test_first_order_image_matches_lutgen():
    """Every vertex of the first-order image lies along the apparent direction lutgen gives for some
    point of the source surface: here, checked for the image's centroid direction against the
    sphere's centre seen through connect()."""
    from lutgen import connect

    scene, sphere = _small_demo()
    _place(sphere, 90)
    bpy.ops.grlens.rebuild()
    img = bpy.data.objects["OrbitingSphere.GR1"]
    pts = np.array([v.co[:] for v in img.data.vertices])
    cam = np.array(scene.camera.location)
    d = pts - cam
    d /= np.linalg.norm(d, axis=1)[:, None]
    centre_dir = d.mean(axis=0)
    centre_dir /= np.linalg.norm(centre_dir)
    c = connect(20.0, 3.0, math.pi / 2, 1)
    e1 = cam / np.linalg.norm(cam)
    assert abs(math.acos(centre_dir @ e1) - float(c.xi)) < math.radians(0.5)


@pytest.mark.parametrize("problem", ["no_hole", "no_camera", "camera_inside", "camera_in_horizon",
                                     "camera_in_photon_sphere", "nan_vertex",
                                     "inf_vertex", "empty_mesh", "r_s_tiny", "ngon_and_loose_edge",
                                     "object_inside_horizon", "zero_scale"])
def test_bad_input_gives_a_message_not_a_crash(problem):
    scene, sphere = _small_demo()
    _place(sphere, 90)
    if problem == "no_hole":
        scene.grlens.black_hole = None
    elif problem == "no_camera":
        scene.camera = None
    elif problem == "camera_inside":
        scene.camera.location = (2.001, 0, 0)  # 1.0005 r_s: closer to the horizon than the tables reach
    elif problem == "camera_in_photon_sphere":
        scene.camera.location = (2.5, 0, 0)  # 1.25 r_s: inside the photon sphere, imaged
    elif problem == "camera_in_horizon":
        scene.camera.location = (1.0, 0, 0)  # 0.5 r_s
    elif problem == "nan_vertex":
        sphere.data.vertices[5].co = (float("nan"), 0, 0)
    elif problem == "inf_vertex":
        sphere.data.vertices[7].co = (0, float("inf"), 0)
    elif problem == "ngon_and_loose_edge":
        import bmesh

        bm = bmesh.new()
        bm.from_mesh(sphere.data)
        ring = [bm.verts.new((0.3 * math.cos(a), 0.3 * math.sin(a), 1.5)) for a in np.linspace(0, 6, 7)]
        bm.faces.new(ring)  # a heptagon
        bm.edges.new((bm.verts.new((0, 0, 2.0)), bm.verts.new((0, 0.5, 2.0))))  # a loose edge
        bm.verts.new((0, 0, 2.5))  # a loose vertex
        bm.to_mesh(sphere.data)
        bm.free()
    elif problem == "object_inside_horizon":
        sphere.parent = None
        sphere.location = (0.2, 0.0, 0.0)  # within 1 r_s of the hole: no image at all
    elif problem == "zero_scale":
        sphere.scale = (0.0, 0.0, 0.0)
    elif problem == "empty_mesh":
        sphere.data.clear_geometry()
    elif problem == "r_s_tiny":
        scene.grlens.r_s = 1e-6  # camera at 4e7 r_s: far outside the LUT range, nothing to show
    before = np.array([v.co[:] for v in sphere.data.vertices])
    if problem in ("no_hole", "no_camera", "camera_inside", "camera_in_horizon"):
        # scripts get the operator's error report as an exception with the message
        with pytest.raises(RuntimeError, match="grlens: (no black hole|the scene has no camera|the camera is inside|"
                                               "the camera is too close to the horizon)"):
            bpy.ops.grlens.rebuild()
        assert scene.grlens.status.startswith("grlens:")
    else:
        assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    for o in _image_objects().values():
        pts = np.empty(3 * len(o.data.vertices), np.float32)
        o.data.vertices.foreach_get("co", pts)
        assert np.all(np.isfinite(pts))
    if problem == "ngon_and_loose_edge":
        assert len(bpy.data.objects["OrbitingSphere.GR1"].data.polygons) > 0
    if problem == "object_inside_horizon":
        assert all(len(o.data.polygons) == 0 for o in _image_objects().values())
    if problem == "camera_in_photon_sphere":  # (looking at the hole it sees only the shadow: nothing in view)
        assert scene.grlens.status.startswith("1 object(s) lensed")
    after = np.array([v.co[:] for v in sphere.data.vertices])
    np.testing.assert_array_equal(before, after)  # the source is never changed


def test_order_switch_and_clear():
    scene, sphere = _small_demo()
    _place(sphere, 90)
    scene.grlens.show_order_2 = False
    assert set(_image_objects()) == {"OrbitingSphere.GR1"}
    bpy.ops.grlens.clear()
    assert not _image_objects() and sphere.visible_camera and not sphere.grlens.enabled


def test_unchanged_objects_are_not_rebuilt():
    scene, sphere = _small_demo()
    scene.grlens.auto_update = False  # only the explicit calls below rebuild
    _place(sphere, 90)
    from grlens_addon.blender.rebuild import rebuild_scene

    first = rebuild_scene(scene)
    assert isinstance(first["objects"]["OrbitingSphere"], dict)
    again = rebuild_scene(scene)
    assert again["objects"]["OrbitingSphere"] == "unchanged"
    scene.grlens.tess_a = 4.0  # a setting changed: rebuilt
    assert isinstance(rebuild_scene(scene)["objects"]["OrbitingSphere"], dict)
    _place(sphere, 80)  # the object moved: rebuilt
    assert isinstance(rebuild_scene(scene)["objects"]["OrbitingSphere"], dict)


def test_gr_illumination_attribute_and_node_group():
    scene, sphere = _small_demo()
    _place(sphere, 90)
    light = bpy.data.objects.new("Lamp", None)
    light.location = (39.39, 0.0, 6.95)  # seed 000, section 4.3 (r = 20 r_s with r_s = 2)
    scene.collection.objects.link(light)
    g = scene.grlens
    g.light = light
    from grlens_addon.blender.shading import GROUP_NAME

    g.auto_update = False
    assert GROUP_NAME not in bpy.data.node_groups
    g.use_gr_illumination = True  # the node group exists at once, before any rebuild (material set-up)
    assert GROUP_NAME in bpy.data.node_groups
    g.auto_update = True
    bpy.ops.grlens.rebuild()
    mesh = bpy.data.objects["OrbitingSphere.GR1"].data
    a = mesh.attributes["grlens_irradiance"]
    assert a.domain == "CORNER"
    vals = np.empty(len(mesh.loops), np.float32)
    a.data.foreach_get("value", vals)
    assert np.all(np.isfinite(vals)) and vals.max() > 0 and vals.min() == 0  # lit side and dark side
    g.use_gr_illumination = False
    assert "grlens_irradiance" not in bpy.data.objects["OrbitingSphere.GR1"].data.attributes


def test_image_materials_are_copies_with_aovs_and_the_users_material_is_untouched():
    scene, sphere = _small_demo()
    _place(sphere, 90)
    mat = bpy.data.materials.new("Mine")
    if bpy.app.version < (5, 0, 0):  # 5.0: always nodes, use_nodes deprecated
        mat.use_nodes = True
    sphere.data.materials.append(mat)
    n_nodes = len(mat.node_tree.nodes)
    bpy.ops.grlens.rebuild()
    img = bpy.data.objects["OrbitingSphere.GR1"]
    used = img.data.materials[0]
    assert used.name == "Mine (grlens)" and used != mat
    assert len(mat.node_tree.nodes) == n_nodes  # the user's material is not edited
    assert sum(n.bl_idname == "ShaderNodeOutputAOV" for n in used.node_tree.nodes) == 2
    assert {a.name for a in scene.view_layers[0].aovs} >= {"light_travel_time", "image_order"}
    assert "grlens_order" in img.data.attributes
    # editing the user's material refreshes the copy
    mat.node_tree.nodes.new("ShaderNodeTexChecker")
    bpy.ops.grlens.rebuild()
    used = bpy.data.objects["OrbitingSphere.GR1"].data.materials[0]
    assert any(n.bl_idname == "ShaderNodeTexChecker" for n in used.node_tree.nodes)


def test_save_and_reload_keep_settings_images_and_handlers(tmp_path):
    scene, sphere = _small_demo()
    _place(sphere, 90)
    bpy.ops.grlens.rebuild()
    n_before = len(bpy.data.objects["OrbitingSphere.GR1"].data.polygons)
    path = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    assert scene.grlens.black_hole.name == "BlackHole" and scene.grlens.r_s == 2.0
    sphere = bpy.data.objects["OrbitingSphere"]
    assert sphere.grlens.enabled and sphere.hide_render
    assert set(_image_objects()) == {"OrbitingSphere.GR1", "OrbitingSphere.GR2"}
    assert len(bpy.data.objects["OrbitingSphere.GR1"].data.polygons) == n_before
    # the persistent frame handler still runs after loading: moving the sphere and changing frame rebuilds
    before = np.array([v.co[:] for v in bpy.data.objects["OrbitingSphere.GR1"].data.vertices])
    _place(sphere, 60)
    scene.frame_set(scene.frame_current + 1)
    after = np.array([v.co[:] for v in bpy.data.objects["OrbitingSphere.GR1"].data.vertices])
    assert before.shape != after.shape or not np.allclose(before, after)


def test_no_data_block_growth_over_frames():
    """Image meshes and material copies are reused frame after frame: no orphan growth."""
    scene, sphere = _small_demo()
    scene.frame_set(2)
    counts = (len(bpy.data.meshes), len(bpy.data.materials), len(bpy.data.objects))
    for f in range(3, 40, 3):  # along the orbit, away from the ring configurations
        scene.frame_set(f)
        assert (len(bpy.data.meshes), len(bpy.data.materials), len(bpy.data.objects)) == counts


def test_viewport_preview_uses_its_own_tolerance_and_renders_the_render_one():
    """Automatic viewport updates are built to tess_max_error_viewport (the larger of the two), renders
    and explicit rebuilds to tess_max_error; switching between them rebuilds, and the render-quality
    images come back exactly."""
    from grlens_addon.blender import rebuild

    scene, sphere = _small_demo()
    scene.render.resolution_x, scene.render.resolution_y = 640, 360
    scene.grlens.auto_update = False
    _place(sphere, 180)  # the Einstein-ring frame: most of its pieces come from the tolerance
    g = scene.grlens
    assert (g.tess_max_error, g.tess_max_error_viewport) == (0.25, 1.0)

    def faces():
        return len(bpy.data.objects["OrbitingSphere.GR1"].data.polygons)

    def positions():
        me = bpy.data.objects["OrbitingSphere.GR1"].data
        co = np.empty(3 * len(me.vertices), np.float32)
        me.attributes["position"].data.foreach_get("vector", co)
        return co

    final = rebuild.rebuild_scene(scene)
    assert "preview" not in final["status"]
    n_final, co_final = faces(), positions()
    preview = rebuild.rebuild_scene(scene, preview=True)
    assert isinstance(preview["objects"]["OrbitingSphere"], dict)  # rebuilt, not "unchanged"
    assert "viewport preview: 1 px" in preview["status"] and scene.grlens.status == preview["status"]
    assert faces() < 0.7 * n_final
    again = rebuild.rebuild_scene(scene)  # a render after scrubbing: rebuilt at the render tolerance
    assert isinstance(again["objects"]["OrbitingSphere"], dict)
    assert faces() == n_final and np.array_equal(positions(), co_final)
    # the rule for the tolerance: the larger of the two; 0 for the viewport: the render's
    assert rebuild.max_error_px(g, preview=True) == 1.0 and rebuild.max_error_px(g) == 0.25
    g.tess_max_error = 2.0
    assert rebuild.max_error_px(g, preview=True) == 2.0
    g.tess_max_error = 0.0  # eq. 19 alone for renders; the viewport stays capped
    assert rebuild.max_error_px(g) is None and rebuild.max_error_px(g, preview=True) == 1.0
    g.tess_max_error, g.tess_max_error_viewport = 0.25, 0.0
    assert rebuild.max_error_px(g, preview=True) == 0.25
    rebuild.rebuild_scene(scene)
    assert rebuild.rebuild_scene(scene, preview=True)["objects"]["OrbitingSphere"] == "unchanged"


def test_only_interactive_viewport_updates_are_previews():
    """handlers.wants_preview: the viewport's depsgraph in the UI is a preview; a render's depsgraph (F12
    and animation renders fire the frame handlers with it) and background mode never are. In this
    (background) process the frame handler rebuilds at the render tolerance."""
    from types import SimpleNamespace

    from grlens_addon.blender import handlers

    viewport = bpy.context.evaluated_depsgraph_get()
    assert viewport.mode == "VIEWPORT"
    assert handlers.wants_preview(viewport, background=False)
    assert handlers.wants_preview(None, background=False)  # property updates from the UI
    assert not handlers.wants_preview(SimpleNamespace(mode="RENDER"), background=False)
    assert not handlers.wants_preview(viewport, background=True)
    assert bpy.app.background and not handlers.wants_preview(viewport)
    scene, sphere = _small_demo()
    scene.frame_set(2)
    assert "preview" not in scene.grlens.status and "lensed" in scene.grlens.status


def test_remembered_inputs_and_topologies_stay_bounded():
    """The rebuild-skip and topology-reuse checks keep one entry per image mesh: none accumulate over
    frames or when images are removed, and loading a file forgets them; the skip still works."""
    from grlens_addon.blender import rebuild, upload

    scene, sphere = _small_demo()
    scene.grlens.auto_update = False
    for deg in (90, 60, 90, 120):
        _place(sphere, deg)
        rebuild.rebuild_scene(scene)
    assert len(rebuild._INPUTS) == 1 and len(upload._TOPOLOGY) <= 2
    assert rebuild.rebuild_scene(scene)["objects"]["OrbitingSphere"] == "unchanged"
    scene.grlens.show_order_2 = False  # the order-2 image is removed
    rebuild.rebuild_scene(scene)
    assert len(rebuild._INPUTS) == 1 and len(upload._TOPOLOGY) <= 1
    sphere.grlens.enabled = False
    rebuild.rebuild_scene(scene)
    assert len(rebuild._INPUTS) == 0 and len(upload._TOPOLOGY) == 0
    sphere.grlens.enabled = True
    rebuild.rebuild_scene(scene)
    assert len(rebuild._INPUTS) == 1
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    assert len(rebuild._INPUTS) == 0 and len(upload._TOPOLOGY) == 0


@pytest.mark.parametrize("mode, builder", [("EVERY_DISTANCE", "build_wide_lut"), ("FIXED_RANGE", "build_lut")])
def test_packed_tables_are_saved_and_used_exactly(tmp_path, mode, builder):
    """pack_lut stores the camera's tables (Every Distance, the default: the exact tables its table is
    interpolated from; Fixed Range: the LUT itself); after a reload nothing is built and the table is
    the same to the bit; unpack_luts removes them."""
    import lutgen
    from grlens_addon.blender import lutcache

    scene, sphere = _small_demo()
    scene.grlens.lut_mode = mode
    assert bpy.ops.grlens.pack_lut() == {"FINISHED"}
    built = lutcache.get_table(scene.grlens, 20.0)
    path = str(tmp_path / "packed.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    lutcache.clear()
    calls = []
    real = getattr(lutgen, builder)
    setattr(lutgen, builder, lambda *a, **k: calls.append(a) or real(*a, **k))
    try:
        loaded = lutcache.get_table(bpy.context.scene.grlens, 20.0)
    finally:
        setattr(lutgen, builder, real)
    assert not calls  # read from the file, not built
    assert np.array_equal(loaded.data, built.data)
    assert bpy.ops.grlens.unpack_luts() == {"FINISHED"}
    assert lutcache.STORE not in bpy.data.texts


def test_observer_camera_and_frustum():
    """scene.grlens.observer lenses that camera's view, whichever camera renders; images are culled
    against the observer's frustum; tess_max_error = 0 subdivides at least as much as the default."""
    scene, sphere = _small_demo()
    _place(sphere, 150)
    bpy.ops.grlens.rebuild()
    n_default = len(bpy.data.objects["OrbitingSphere.GR1"].data.polygons)
    scene.grlens.tess_max_error = 0.0
    bpy.ops.grlens.rebuild()
    assert len(bpy.data.objects["OrbitingSphere.GR1"].data.polygons) >= n_default
    scene.grlens.tess_max_error = 0.25
    observer = scene.camera
    # an external camera becomes the render camera; the images stay those seen by the observer
    ext_data = bpy.data.cameras.new("External")
    ext = bpy.data.objects.new("External", ext_data)
    scene.collection.objects.link(ext)
    ext.location = (0.0, -60.0, 20.0)
    scene.grlens.observer = observer
    scene.camera = ext
    bpy.ops.grlens.rebuild()
    pts = np.array([v.co[:] for v in bpy.data.objects["OrbitingSphere.GR1"].data.vertices])
    ltt = np.empty(len(pts), np.float32)
    bpy.data.objects["OrbitingSphere.GR1"].data.attributes["light_travel_time"].data.foreach_get("value", ltt)
    np.testing.assert_allclose(np.linalg.norm(pts - np.array(observer.location), axis=1), ltt, rtol=1e-5)
    # turn the observer away from the sphere: its images leave the frustum and are culled
    scene.grlens.observer = None
    scene.camera = observer
    observer.rotation_euler = (math.radians(90), 0.0, math.radians(-90))  # looking along +x, away
    bpy.ops.grlens.rebuild()
    assert len(bpy.data.objects["OrbitingSphere.GR1"].data.polygons) == 0
    assert len(bpy.data.objects["OrbitingSphere.GR2"].data.polygons) == 0


def test_thin_disc_emitter_writes_redshift_and_colour():
    """obj.grlens.emitter = 'THIN_DISC': image vertices carry 1 + z and the Page-Thorne colour; the
    approaching side (prograde about +z, seen from +x: the gas at -y moves towards the camera) is
    blueshifted and brighter, and reversing the rotation swaps the sides."""

    scene, sphere = _small_demo()
    sphere.grlens.enabled = False
    bpy.ops.mesh.primitive_circle_add(vertices=96, radius=12.0, fill_type="NOTHING")
    disc = bpy.context.object
    # an annulus 3.5..6 r_s (r_s = 2 BU) in the xy plane, tilted 10 degrees: seen at 80 degrees inclination
    bm_me = disc.data
    bm_me.clear_geometry()
    import bmesh

    bm = bmesh.new()
    rings = [7.0, 8.0, 9.5, 12.0]
    verts = [[bm.verts.new((r * math.cos(a), r * math.sin(a), 0.0)) for a in np.linspace(0, 2 * np.pi, 96, endpoint=False)]
             for r in rings]
    for i in range(len(rings) - 1):
        for j in range(96):
            bm.faces.new((verts[i][j], verts[i][(j + 1) % 96], verts[i + 1][(j + 1) % 96], verts[i + 1][j]))
    bm.to_mesh(bm_me)
    bm.free()
    disc.rotation_euler = (0.0, math.radians(10.0), 0.0)
    disc.grlens.enabled = True
    disc.grlens.emitter = "THIN_DISC"
    bpy.ops.grlens.rebuild()
    img = bpy.data.objects[disc.name + ".GR1"]
    me = img.data
    n = len(me.vertices)
    assert n > 0 and "grlens_redshift" in me.attributes and "grlens_disc_colour" in me.attributes
    z = np.empty(n, np.float32)
    me.attributes["grlens_redshift"].data.foreach_get("value", z)
    col = np.empty(4 * n, np.float32)
    me.attributes["grlens_disc_colour"].data.foreach_get("color", col)
    col = col.reshape(-1, 4)
    pos = np.array([v.co[:] for v in me.vertices])
    assert np.all(np.isfinite(z)) and z.min() < 1.0 < z.max()  # blue- and redshifted sides
    # gas turning counter-clockwise about the tilted axis: at +y it moves towards -x (away from the camera)
    assert np.median(z[pos[:, 1] > 2]) > np.median(z[pos[:, 1] < -2])
    assert np.median(col[pos[:, 1] < -2, 0]) > np.median(col[pos[:, 1] > 2, 0])  # Doppler-brighter side
    assert bpy.data.node_groups.get("grlens Thin Disc Emission") is not None
    disc.grlens.disc_prograde = False
    bpy.ops.grlens.rebuild()
    me.attributes["grlens_redshift"].data.foreach_get("value", z)
    pos = np.array([v.co[:] for v in me.vertices])
    assert np.median(z[pos[:, 1] > 2]) < np.median(z[pos[:, 1] < -2])


def _verts(name):
    me = bpy.data.objects[name].data
    co = np.empty(3 * len(me.vertices), np.float32)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def test_undo_and_redo_keep_images_consistent_with_their_sources():
    scene, sphere = _small_demo()
    sphere.animation_data_clear()
    _place(sphere, 90)
    bpy.ops.grlens.rebuild()
    bpy.ops.ed.undo_push(message="sphere at 90")
    a = _verts("OrbitingSphere.GR1")
    sphere = bpy.data.objects["OrbitingSphere"]
    _place(sphere, 60)
    bpy.ops.grlens.rebuild()
    bpy.ops.ed.undo_push(message="sphere at 60")
    b = _verts("OrbitingSphere.GR1")
    assert a.shape != b.shape or not np.allclose(a, b)
    assert bpy.ops.ed.undo() == {"FINISHED"}
    sphere = bpy.data.objects["OrbitingSphere"]
    assert math.isclose(sphere.location.y, 3 * 2.0 * math.sin(math.radians(90)), abs_tol=1e-6)
    np.testing.assert_array_equal(_verts("OrbitingSphere.GR1"), a)
    bpy.ops.grlens.rebuild()  # a rebuild of the restored state gives the restored images
    np.testing.assert_allclose(_verts("OrbitingSphere.GR1"), a, atol=1e-5)
    assert sorted(_image_objects()) == ["OrbitingSphere.GR1", "OrbitingSphere.GR2"]
    assert sphere.hide_render and not sphere.visible_camera
    assert bpy.ops.ed.redo() == {"FINISHED"}
    np.testing.assert_array_equal(_verts("OrbitingSphere.GR1"), b)


def test_interactive_edit_rebuilds_through_the_depsgraph_handler():
    """Moving a lensed object (no frame change, no operator) updates its images once the depsgraph
    is evaluated, as after an edit in the viewport."""
    scene, sphere = _small_demo()
    sphere.animation_data_clear()
    _place(sphere, 90)
    bpy.context.view_layer.update()
    a = _verts("OrbitingSphere.GR1")
    _place(sphere, 120)
    bpy.context.view_layer.update()
    b = _verts("OrbitingSphere.GR1")
    assert a.shape != b.shape or not np.allclose(a, b)
    scene.grlens.auto_update = False  # switched off: edits leave the images alone
    _place(sphere, 60)
    bpy.context.view_layer.update()
    np.testing.assert_array_equal(_verts("OrbitingSphere.GR1"), b)


def test_depsgraph_updates_of_the_camera_hole_and_light_are_seen():
    """The depsgraph handler's filters get the updates' evaluated copies: the camera, the observer,
    the hole and the light count (regression: they were compared with the original objects, so a
    camera or hole moved by hand in the viewport was seen only through other updates)."""
    import types

    from grlens_addon.blender import handlers

    scene, sphere = _small_demo()
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    scene.collection.objects.link(lamp)
    scene.grlens.light = lamp
    other = bpy.data.objects.new("Other", None)
    scene.collection.objects.link(other)
    dg = bpy.context.evaluated_depsgraph_get()

    def upd(obj):
        ev = obj.evaluated_get(dg)
        assert ev.original == obj and ev is not obj
        return types.SimpleNamespace(id=ev)

    for obj in (scene.camera, scene.grlens.black_hole, lamp, sphere):
        assert handlers._relevant(scene, upd(obj)), obj.name
    for obj in (scene.camera, scene.grlens.black_hole):
        assert handlers._world_relevant(scene, upd(obj)), obj.name
    assert not handlers._relevant(scene, upd(other)) and not handlers._world_relevant(scene, upd(other))


def test_material_slots_and_indices_carry_over():
    """Faces of the images use the material slot of their source face (regression: clearing the
    image mesh's materials reset every face to slot 0)."""
    scene, sphere = _small_demo()
    _place(sphere, 90)
    a, b = bpy.data.materials.new("Upper"), bpy.data.materials.new("Lower")
    sphere.data.materials.clear()
    sphere.data.materials.append(a)
    sphere.data.materials.append(b)
    for p in sphere.data.polygons:
        p.material_index = 1 if p.center.z < 0 else 0
    for frame in (1, 2):
        scene.frame_set(frame)
        bpy.ops.grlens.rebuild()
        for order in (1, 2):
            me = bpy.data.objects[f"OrbitingSphere.GR{order}"].data
            assert [m.name for m in me.materials] == ["Upper (grlens)", "Lower (grlens)"]
            mi = np.empty(len(me.polygons), np.int32)
            me.polygons.foreach_get("material_index", mi)
            counts = np.bincount(mi, minlength=2)
            assert counts[0] > 0 and counts[1] > 0 and abs(int(counts[0]) - int(counts[1])) < 0.2 * len(mi)


def test_orbiting_camera_reuses_one_lut():
    """A camera circling the hole at a fixed distance (float32 transforms jitter by ~1e-7) builds its
    lookup table once, not every frame."""
    from grlens_addon.blender import lutcache

    scene, sphere = _small_demo()
    lutcache.clear()
    pivot = bpy.data.objects.new("CameraPivot", None)
    scene.collection.objects.link(pivot)
    scene.camera.parent = pivot
    pivot.rotation_euler = (0.0, 0.0, 0.0)
    pivot.keyframe_insert("rotation_euler", index=2, frame=1)
    pivot.rotation_euler = (0.0, 0.0, math.radians(90.0))
    pivot.keyframe_insert("rotation_euler", index=2, frame=9)
    for mode in ("FIXED_RANGE", "EVERY_DISTANCE"):
        scene.grlens.lut_mode = mode
        lutcache.clear()
        keys = set()
        for f in range(1, 10):
            scene.frame_set(f)
            keys |= set(lutcache._CACHE)
        assert len(keys) == 1, mode
    assert lutcache.family(scene.grlens.lut_r_min).built == 4  # the exact tables around 20 r_s


def test_demo_orbit_is_uniform():
    """The demo sphere moves one degree per frame (linear keys on Blender 4.x and 5.0 actions alike)."""
    scene, sphere = _small_demo()
    for frame, deg in ((1, 0.0), (31, 30.0), (91, 90.0)):
        scene.frame_set(frame)
        p = sphere.matrix_world.translation
        assert math.isclose(math.degrees(math.atan2(-p.x, p.y)), deg, abs_tol=1e-3)


def _loop_triangle_reference(obj):
    """World positions, triangles (vertex indices), corner UVs and material indices through Blender's
    own loop_triangles API (the slow path _extract avoids)."""
    me = obj.data
    me.calc_loop_triangles()
    n_t = len(me.loop_triangles)
    tris = np.empty(3 * n_t, np.int32)
    me.loop_triangles.foreach_get("vertices", tris)
    loops = np.empty(3 * n_t, np.int32)
    me.loop_triangles.foreach_get("loops", loops)
    mat = np.empty(n_t, np.int32)
    me.loop_triangles.foreach_get("material_index", mat)
    uv = np.empty(2 * len(me.loops), np.float32)
    me.uv_layers.active.uv.foreach_get("vector", uv)
    return tris.reshape(-1, 3), uv.reshape(-1, 2)[loops].reshape(-1, 3, 2), mat


@pytest.mark.parametrize("kind", ["uv_sphere", "folded_quads", "ngons", "mixed_materials"])
def test_extract_matches_blenders_loop_triangles(kind):
    """rebuild._extract derives the triangles' corners from the attribute arrays (core.triangulate);
    they are Blender's own loop triangles, for triangles, quads (folded ones split on the other
    diagonal, as Blender does) and, through the fallback, n-gons; UVs and material indices follow."""
    import bmesh

    from grlens_addon.blender import rebuild

    me = bpy.data.meshes.new(kind)
    bm = bmesh.new()
    uv_layer = bm.loops.layers.uv.new("UVMap")
    if kind in ("uv_sphere", "mixed_materials"):
        bmesh.ops.create_uvsphere(bm, u_segments=24, v_segments=12, radius=1.0, calc_uvs=True)
    elif kind == "folded_quads":
        rng = np.random.default_rng(3)
        bmesh.ops.create_grid(bm, x_segments=12, y_segments=12, size=1.0, calc_uvs=True)
        for v in bm.verts:  # strong random displacement: many quads fold over a diagonal
            v.co.x += rng.normal(scale=0.12)
            v.co.y += rng.normal(scale=0.12)
            v.co.z += rng.normal(scale=0.3)
    else:
        bmesh.ops.create_circle(bm, cap_ends=True, segments=9, radius=1.0, calc_uvs=True)
        bmesh.ops.create_cone(bm, cap_ends=True, segments=7, radius1=1.0, radius2=0.5, depth=1.0,
                              calc_uvs=True)
    for i, f in enumerate(bm.faces):
        for loop in f.loops:
            loop[uv_layer].uv = (0.01 * i + 0.1 * loop.vert.index % 1.0, 0.5 * (i % 3))
        if kind == "mixed_materials":
            f.material_index = i % 3
    bm.to_mesh(me)
    bm.free()
    obj = bpy.data.objects.new(kind, me)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = (1.0, 2.0, 3.0)
    obj.rotation_euler = (0.3, 0.2, 0.1)
    obj.scale = (1.0, 2.0, 0.5)
    dg = bpy.context.evaluated_depsgraph_get()
    mesh = rebuild._extract(obj.evaluated_get(dg), with_normals=True)
    tris, uv, mat = _loop_triangle_reference(obj)
    assert np.array_equal(mesh.tris, tris)
    assert np.array_equal(mesh.corner_uv, uv.astype(np.float64))
    assert np.array_equal(mesh.material, mat)
    local = np.array([v.co[:] for v in me.vertices])
    world = local @ np.array(obj.matrix_world)[:3, :3].T + np.array(obj.matrix_world)[:3, 3]
    np.testing.assert_allclose(mesh.positions, world, atol=1e-5)
    assert mesh.corner_normals.shape == (len(tris), 3, 3)
    if kind == "mixed_materials":
        assert set(np.unique(mat)) == {0, 1, 2}
    if kind == "folded_quads":  # the test does cover folded quads
        from grlens_addon.core import triangulate

        fan = triangulate.tri_corners(np.repeat(np.arange(len(me.polygons)), 2), len(me.polygons),
                                      np.arange(4 * len(me.polygons)), np.zeros((4 * len(me.polygons), 3)))
        me.calc_loop_triangles()
        loops = np.empty(3 * len(me.loop_triangles), np.int32)
        me.loop_triangles.foreach_get("loops", loops)
        assert (loops.reshape(-1, 3) != fan).any(axis=1).sum() > 5


def test_check_frame_against_ray_tracing(tmp_path):
    """bpy.ops.grlens.check_frame: both renders of the current frame at a fraction of the render
    resolution, their comparison in scene.grlens.check_summary and their passes in an OpenEXR file
    named after the frame; the source is not modified."""
    from lutgen.exr_io import read_exr

    scene, sphere = _small_demo()  # 160x90
    _place(sphere, 90)
    before = np.array([v.co[:] for v in sphere.data.vertices])
    scene.frame_set(7)
    out = str(tmp_path / "sub" / "check_###.exr")
    assert bpy.ops.grlens.check_frame(percentage=100, filepath=out) == {"FINISHED"}
    path = tmp_path / "sub" / "check_007.exr"
    assert path.exists()
    summary = scene.grlens.check_summary
    assert summary.startswith("frame 7, 160x90: ") and str(path) in summary
    channels, meta = read_exr(path)
    assert {"Reference.light_travel_time.V", "Reference.image_order.V", "grlens.light_travel_time.V",
            "grlens.image_order.V", "Check.mismatch.V"} <= set(channels)
    assert channels["Reference.image_order.V"].shape == (90, 160)
    assert meta["mismatch_fraction"] < 0.02 and meta["objects"] == "0: OrbitingSphere"
    both = (channels["Reference.image_order.V"] == 1) & (channels["grlens.image_order.V"] == 1)
    assert both.sum() > 50
    lt_r, lt_p = channels["Reference.light_travel_time.V"][both], channels["grlens.light_travel_time.V"][both]
    assert np.all(np.abs(lt_p - lt_r) <= 1e-3 * lt_r)  # c*dt in BU in both (r_s = 2 BU here)
    assert np.array_equal(before, np.array([v.co[:] for v in sphere.data.vertices]))
    # a lower resolution, no file
    assert bpy.ops.grlens.check_frame(percentage=50, filepath="") == {"FINISHED"}
    assert scene.grlens.check_summary.startswith("frame 7, 80x45: ") and "passes in" not in scene.grlens.check_summary


def test_check_frame_checks_the_lensed_world(tmp_path):
    """With a lensed world, check_frame also compares the world's mapping (its escape table) with the
    reference's exact escape directions: sky metrics in the summary and the EXR; without lensing, no
    sky check."""
    from lutgen.exr_io import read_exr

    scene, sphere = _small_demo()
    _place(sphere, 90)
    w = bpy.data.worlds.new("Sky")
    if bpy.app.version < (5, 0, 0):
        w.use_nodes = True
    w.node_tree.nodes.new("ShaderNodeTexNoise")  # a direction texture, hooked to the lensed sky
    scene.world = w
    scene.frame_set(1)
    out = str(tmp_path / "check_#.exr")
    assert bpy.ops.grlens.check_frame(percentage=100, filepath=out) == {"FINISHED"}
    assert "sky off by" in scene.grlens.check_summary
    channels, meta = read_exr(tmp_path / "check_1.exr")
    ref, got = channels["Reference.sky_direction.X"], channels["grlens.sky_direction.X"]
    assert np.array_equal(np.isnan(ref), np.isnan(channels["Check.sky_error.V"]))
    assert np.isfinite(ref).sum() > 1000 and np.isnan(ref).sum() > 20  # sky and shadow (and the sphere)
    assert meta["sky_error_max_px"] < 0.05 and meta["shadow_mismatch_pixels"] == 0
    assert np.all(np.isfinite(got[np.isfinite(ref)]))
    scene.grlens.lens_world = False
    assert bpy.ops.grlens.check_frame(percentage=50, filepath="") == {"FINISHED"}
    assert "sky off by" not in scene.grlens.check_summary


def test_timeline_markers_switch_the_observer_camera():
    """Camera cuts by timeline markers: each frame's images are built for the camera the marker binds
    to that frame, also from a script's frame_set (which switches scene.camera only after the frame
    handlers); an explicit scene.grlens.observer wins over the markers."""
    scene, sphere = _small_demo()
    near = scene.camera
    far = bpy.data.objects.new("FarCamera", near.data.copy())
    far.matrix_world = near.matrix_world
    far.location = (30 * 2.0, 0.0, 0.0)  # 30 r_s (r_s = 2 BU); the demo's camera is at 20 r_s
    scene.collection.objects.link(far)
    scene.timeline_markers.new("far", frame=3).camera = far
    scene.timeline_markers.new("near", frame=6).camera = near
    for f, r_obs in ((4, "30"), (7, "20"), (2, "30"), (8, "20")):  # before the first marker: its camera
        scene.frame_set(f)
        assert f"r_obs = {r_obs} r_s" in scene.grlens.status, (f, scene.grlens.status)
    scene.grlens.observer = near
    scene.frame_set(4)
    assert "r_obs = 20 r_s" in scene.grlens.status


def test_check_frame_refuses_what_it_cannot_check():
    from grlens_addon.blender import check

    scene, sphere = _small_demo()
    scene.camera.data.type = "ORTHO"
    with pytest.raises(ValueError, match="perspective"):
        check.check_scene(scene, percentage=10)
    with pytest.raises(RuntimeError, match="perspective"):  # the operator's error report
        bpy.ops.grlens.check_frame(percentage=10, filepath="")
    scene.camera.data.type = "PERSP"
    scene.camera.data.shift_x = 0.1
    with pytest.raises(ValueError, match="lens shift"):
        check.check_scene(scene, percentage=10)
    scene.camera.data.shift_x = 0.0
    sphere.grlens.enabled = False
    with pytest.raises(RuntimeError, match="no object is marked"):
        bpy.ops.grlens.check_frame(percentage=10, filepath="")
