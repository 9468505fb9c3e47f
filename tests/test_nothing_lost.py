"""Nothing lost: images come back after a frame that cannot be lensed, disabling the add-on leaves an
ordinary scene, image meshes carry their source's shading, renders evaluate the sources with render
settings, bad settings get clear words, background renders print each line once per frame.

Runs the add-on in the pip ``bpy`` module. Units: Blender units (BU); the demo scene has r_s = 2 BU and
its camera 40 BU (20 r_s) from the hole.
"""
import math

import numpy as np
import pytest

import bpy  # noqa: E402  (pinned in requirements/dev.txt)

import grlens_addon  # noqa: E402
from blender_session import empty_file, registered  # noqa: E402,F401  (autouse fixtures)


def _images():
    return {o.name: o for o in bpy.data.objects if o.grlens.order in (1, 2)}


def _polys():
    """Polygons of every image object, by name (an image that was removed counts 0)."""
    return {n: len(o.data.polygons) for n, o in _images().items()}


def _demo(r_s=2.0):
    assert bpy.ops.grlens.demo_scene(r_s=r_s) == {"FINISHED"}
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 160, 90
    sphere = bpy.data.objects["OrbitingSphere"]
    sphere.animation_data_clear()
    sphere.parent = None
    sphere.location = (0.0, 6.0, 0.04)  # on the 3 r_s orbit, 90 degrees from the hole-camera axis
    return scene, sphere


def _positions(obj):
    pts = np.empty(3 * len(obj.data.vertices), np.float32)
    obj.data.vertices.foreach_get("co", pts)
    return pts.reshape(-1, 3)


# --- faults for one frame, then fixed --------------------------------------------------------------

def _fault(scene, kind):
    """Break the scene as ``kind`` says; returns the function that mends it."""
    g = scene.grlens
    cam, hole = scene.camera, g.black_hole
    if kind == "no_hole":
        g.black_hole = None
        return lambda: setattr(g, "black_hole", hole)
    if kind == "nan_location":
        where = tuple(hole.location)
        hole.location = (float("nan"), 0.0, 0.0)
        return lambda: setattr(hole, "location", where)
    if kind == "camera_in_horizon":
        where = tuple(cam.location)
        cam.location = (0.5, 0.0, 0.0)  # 0.25 r_s from the hole
        return lambda: setattr(cam, "location", where)
    if kind == "hole_replaced":  # deleted: the pointer empties; a new empty at its place is set
        where = tuple(hole.location)
        bpy.data.objects.remove(hole, do_unlink=True)

        def mend():
            new = bpy.data.objects.new("NewHole", None)
            scene.collection.objects.link(new)
            new.location = where
            g.black_hole = new
        return mend
    raise ValueError(kind)


FAULTS = ["no_hole", "nan_location", "camera_in_horizon", "hole_replaced"]


@pytest.mark.parametrize("kind", FAULTS)
def test_images_come_back_by_frame_changes_after_a_bad_frame(kind):
    scene, sphere = _demo()
    scene.frame_set(1)
    ref = {n: _positions(o) for n, o in _images().items()}
    assert set(ref) == {"OrbitingSphere.GR1", "OrbitingSphere.GR2"} and all(len(p) for p in ref.values())
    mend = _fault(scene, kind)
    scene.frame_set(2)
    assert not any(_polys().values()), f"{kind}: a frame that cannot be lensed keeps stale images"
    assert scene.grlens.status.startswith("grlens:")
    mend()
    scene.frame_set(3)
    now = {n: _positions(o) for n, o in _images().items()}
    assert set(now) == set(ref)
    for n in ref:  # the very same images as before the fault (nothing in the scene moves)
        np.testing.assert_allclose(now[n], ref[n], atol=1e-5)
    assert not scene.grlens.status.startswith("grlens:")


@pytest.mark.parametrize("kind", ["camera_in_horizon", "no_hole"])
def test_images_come_back_in_an_animation_render_after_a_bad_frame(kind, tmp_path):
    scene, sphere = _demo()
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.render.resolution_x, scene.render.resolution_y = 32, 18
    scene.render.filepath = str(tmp_path / "f_")
    scene.frame_start, scene.frame_end = 1, 3
    hole, cam = scene.grlens.black_hole, scene.camera
    if kind == "camera_in_horizon":  # keyed: good, inside the horizon, good (held, not interpolated)
        prefs = bpy.context.preferences.edit
        old = prefs.keyframe_new_interpolation_type
        prefs.keyframe_new_interpolation_type = "CONSTANT"
        try:
            where = tuple(cam.location)
            cam.keyframe_insert("location", frame=1)
            cam.location = (0.5, 0.0, 0.0)
            cam.keyframe_insert("location", frame=2)
            cam.location = where
            cam.keyframe_insert("location", frame=3)
        finally:
            prefs.keyframe_new_interpolation_type = old

        def script(sc, *_):
            pass
    else:  # a script unsets the hole for frame 2 only (before grlens' own frame handler runs)
        def script(sc, *_):
            sc.grlens.black_hole = None if sc.frame_current == 2 else hole
    seen = {}

    def record(sc, *_):
        seen[sc.frame_current] = sum(_polys().values())
    pre, post = bpy.app.handlers.frame_change_pre, bpy.app.handlers.render_post
    pre.insert(0, script)
    post.append(record)
    try:
        bpy.ops.render.render(animation=True)
    finally:
        pre.remove(script)
        post.remove(record)
    assert seen[1] > 0 and seen[2] == 0, seen
    assert seen[3] == seen[1], seen  # the images are back for every later frame


# --- disable and enable -----------------------------------------------------------------------------

def test_disable_leaves_an_ordinary_scene_and_enable_rebuilds_then_renders(tmp_path):
    scene, sphere = _demo()
    scene.frame_set(1)
    ref = _polys()
    assert sphere.hide_render and all(ref.values())
    grlens_addon.unregister()
    try:
        assert not [o for o in bpy.data.objects if o.name.startswith("OrbitingSphere.GR")]
        assert not sphere.hide_render and sphere.visible_camera  # the source renders again
    finally:
        grlens_addon.register()
    scene.frame_set(1)  # (the enable timer does not run in a script; a frame change rebuilds)
    assert _polys() == ref and sphere.hide_render
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.render.resolution_x, scene.render.resolution_y = 64, 36
    scene.render.filepath = str(tmp_path / "after_enable.png")
    bpy.ops.render.render(write_still=True)
    from PIL import Image

    img = np.asarray(Image.open(tmp_path / "after_enable.png").convert("L"), dtype=float)
    assert (img > 40).sum() > 4  # the lensed sphere is in the picture


# --- the source's shading ---------------------------------------------------------------------------

def _corner_normals(obj):
    dg = bpy.context.evaluated_depsgraph_get()
    me = obj.evaluated_get(dg).data
    n = np.empty(3 * len(me.loops), np.float32)
    me.corner_normals.foreach_get("vector", n)
    return n.reshape(-1, 3)


def test_custom_normals_are_transported_and_reversed_for_the_second_order():
    scene, _ = _demo()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=6, y_subdivisions=6, size=3.0, location=(-12.0, 2.0, 0.0))
    plane = bpy.context.active_object
    d = np.array([0.3, -0.5, 0.8])
    d /= np.linalg.norm(d)
    if bpy.app.version < (4, 1, 0):
        plane.data.use_auto_smooth = True
    plane.data.normals_split_custom_set([tuple(d)] * len(plane.data.loops))
    plane.grlens.enabled = True
    scene.frame_set(1)
    for order, sign in ((1, 1.0), (2, -1.0)):
        img = bpy.data.objects[f"{plane.name}.GR{order}"]
        assert len(img.data.polygons) > 0
        n = _corner_normals(img)
        assert np.abs(n - sign * d).max() < 2e-3, (order, np.abs(n - sign * d).max())
    # the source keeps its own normals
    assert np.abs(_corner_normals(plane) - d).max() < 2e-3


def test_flat_and_smooth_sources_shade_as_their_source():
    scene, _ = _demo()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=4, size=4.0, location=(-10.0, -3.0, -2.0),
                                    rotation=(0.4, 0.2, 0.0))
    flat = bpy.context.active_object
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=1.5, location=(-8.0, 4.0, 1.0))
    smooth = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    flat.grlens.enabled = smooth.grlens.enabled = True
    scene.frame_set(1)
    face_n = np.array(flat.matrix_world.to_3x3() @ flat.data.polygons[0].normal)
    n = _corner_normals(bpy.data.objects[f"{flat.name}.GR1"])
    assert np.abs(n - face_n).max() < 2e-3  # flat stays flat: one normal, the source's
    img = bpy.data.objects[f"{smooth.name}.GR1"]
    n = _corner_normals(img)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-3)
    # smooth: the normals spread over the half of the sphere the camera sees, like the source's
    spread = math.degrees(math.acos(np.clip((n @ n.mean(axis=0)) / np.linalg.norm(n.mean(axis=0)), -1, 1).min()))
    assert spread > 60


def _sun_floor_render(tmp_path, lensed):
    """Cycles, a sun lamp from above, a 200 BU floor of two triangles 3 BU under the hole (r_s = 1 BU),
    the camera 25 BU out and 3 BU above it; returns the floor's pixel values (eroded mask)."""
    scene = bpy.context.scene
    for o in list(bpy.data.objects):
        bpy.data.objects.remove(o, do_unlink=True)
    hole = bpy.data.objects.new("Hole", None)
    scene.collection.objects.link(hole)
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    scene.collection.objects.link(cam)
    cam.location = (0.0, -25.0, 3.0)
    cam.rotation_euler = (math.radians(90 - math.degrees(math.atan2(3.0, 25.0))), 0.0, 0.0)
    scene.camera = cam
    me = bpy.data.meshes.new("Floor")
    me.from_pydata([(-100, -100, -3), (100, -100, -3), (100, 100, -3), (-100, 100, -3)], [],
                   [(0, 1, 2), (0, 2, 3)])
    floor = bpy.data.objects.new("Floor", me)
    scene.collection.objects.link(floor)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.angle = 0.0
    sun.data.energy = 3.0
    sun.rotation_euler = (0.3, 0.0, 0.5)
    scene.collection.objects.link(sun)
    if scene.world is None:
        scene.world = bpy.data.worlds.new("W")
    scene.world.use_nodes = True
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    g = scene.grlens
    g.black_hole, g.r_s = hole, 1.0
    floor.grlens.enabled = lensed
    r = scene.render
    r.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 4
    scene.cycles.max_bounces = 0
    scene.cycles.use_denoising = False
    r.resolution_x, r.resolution_y = 160, 90
    scene.view_settings.view_transform = "Standard"
    r.filepath = str(tmp_path / f"floor_{lensed}.png")
    scene.frame_set(1)
    bpy.ops.render.render(write_still=True)
    from PIL import Image
    from scipy import ndimage

    img = np.asarray(Image.open(r.filepath).convert("L"), dtype=float)
    mask = ndimage.binary_erosion(img > 5, iterations=2)
    return img[mask]


def test_a_sun_lamp_lights_a_lensed_flat_floor_as_evenly_as_the_unlensed_one(tmp_path):
    plain = _sun_floor_render(tmp_path, False)
    lensed = _sun_floor_render(tmp_path, True)
    assert len(plain) > 1000 and len(lensed) > 1000
    med = np.median(plain)
    lo, hi = np.percentile(lensed, [1, 99])
    assert abs(np.median(lensed) - med) < 0.02 * med
    assert med * 0.95 <= lo and hi <= med * 1.05, (lo, hi, med)


# --- render settings in renders ---------------------------------------------------------------------

def _subsurf_render(tmp_path, viewport, render, tag):
    """A Workbench render of the demo scene with only a cube lensed ("Block"), with a Subdivision
    Surface modifier of the given levels (None: no modifier); returns the picture (grey, 0-255)."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene, sphere = _demo()
    bpy.ops.mesh.primitive_cube_add(size=2.5, location=(-12.0, 0.0, 1.5))
    cube = bpy.context.active_object
    cube.name = "Block"
    if viewport is not None:
        m = cube.modifiers.new("Subdivision", "SUBSURF")
        m.levels, m.render_levels = viewport, render
    sphere.grlens.enabled = False
    cube.grlens.enabled = True
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.render.resolution_x, scene.render.resolution_y = 160, 90
    scene.render.filepath = str(tmp_path / f"{tag}.png")
    scene.frame_set(1)
    bpy.ops.render.render(write_still=True)
    from PIL import Image

    return np.asarray(Image.open(scene.render.filepath).convert("L"), dtype=float)


def test_renders_use_the_modifiers_render_levels(tmp_path):
    low_view = _subsurf_render(tmp_path, 0, 2, "view0_render2")
    smooth = _subsurf_render(tmp_path, 2, 2, "view2_render2")
    cube = _subsurf_render(tmp_path, None, None, "plain")
    assert np.abs(cube - smooth).max() > 50  # a cube and its subdivided ball differ
    assert np.abs(low_view - smooth).mean() < 0.02 * np.abs(cube - smooth).mean() + 0.05


def test_sources_are_hidden_from_renders_again_after_a_render(tmp_path):
    _subsurf_render(tmp_path, 0, 2, "after")
    block = bpy.data.objects["Block"]
    assert block.hide_render  # shown to the render's depsgraph only while it evaluated the sources
    img = bpy.data.objects["Block.GR1"]
    scene = bpy.context.scene
    scene.frame_set(1)
    after = _positions(img)
    block.modifiers[0].levels = 2  # the viewport follows the viewport levels, before and after renders
    scene.frame_set(1)
    assert _positions(img).shape != after.shape
    block.modifiers[0].levels = 0
    scene.frame_set(1)
    np.testing.assert_array_equal(_positions(img), after)  # the render's levels left nothing behind


# --- clear words for bad settings -------------------------------------------------------------------

@pytest.mark.parametrize("case, message", [
    ("r_s_zero", "Schwarzschild radius must be a positive length"),
    ("r_s_negative", "Schwarzschild radius must be a positive length"),
    ("light_observer", "is a light, not a camera"),
    ("nan_hole", "has a location that is not a finite number"),
    ("nan_camera", "has a location that is not a finite number"),
])
def test_bad_settings_are_named_not_clamped(case, message):
    scene, _ = _demo()
    g = scene.grlens
    if case == "r_s_zero":
        g.r_s = 0.0
        assert g.r_s == 0.0  # not silently clamped
    elif case == "r_s_negative":
        g.r_s = -2.0
        assert g.r_s == -2.0
    elif case == "light_observer":
        lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
        scene.collection.objects.link(lamp)
        g.observer = lamp
    elif case == "nan_hole":
        g.black_hole.location = (0.0, float("nan"), 0.0)
    elif case == "nan_camera":
        scene.camera.location = (float("nan"), 0.0, 0.0)  # (inf is stored as the largest float)
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.grlens.rebuild()
    assert message in g.status
    assert not any(_polys().values())


def test_a_mesh_as_the_black_hole_gets_a_note():
    scene, sphere = _demo()
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0)
    g = scene.grlens
    g.black_hole = bpy.context.active_object
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    assert "renders inside the shadow" in g.report_lines


# --- background renders print each line once per frame ----------------------------------------------

def test_background_render_prints_each_line_once_per_frame(tmp_path, capfd):
    scene, sphere = _demo()
    sphere.grlens.enabled = False  # a hole, nothing marked: "no object is marked"
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.render.resolution_x, scene.render.resolution_y = 16, 9
    scene.render.filepath = str(tmp_path / "f_")
    scene.frame_start, scene.frame_end = 1, 3
    capfd.readouterr()
    bpy.ops.render.render(animation=True)
    out = capfd.readouterr().out
    assert out.count("no object is marked") == 3, out
    # a scene that does not use grlens (no hole) prints nothing about it
    scene.grlens.black_hole = None
    bpy.ops.render.render(animation=True)
    assert "grlens" not in capfd.readouterr().out
