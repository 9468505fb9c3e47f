"""The artist's surface on the pip `bpy` module: the panels' draw functions (essentials open, knobs in
the closed Advanced panel, the Lens switch for every kind of object grlens can image), Add > Black
Hole, Lens / Unlens Selected on a mixed selection, Unlens All (Clear), the cache-folder preference.

The draw functions are called with a layout that records what they draw. Units: Blender units.
"""
import os
import re
from types import SimpleNamespace

import pytest

import bpy  # noqa: E402

from blender_session import empty_file, registered  # noqa: E402,F401  (autouse fixtures)
from grlens_addon.blender import gather, hole, lutcache, operators, panels, preferences  # noqa: E402


class Layout:
    """Records prop/operator/label calls of a draw function (all nested layouts share one log)."""

    def __init__(self, log=None):
        self.log = [] if log is None else log

    def _sub(self, *_a, **_k):
        return Layout(self.log)

    column = row = box = split = grid_flow = column_flow = _sub

    def prop(self, data, name, **kw):
        assert name in data.bl_rna.properties, f"no property {name} on {data}"
        self.log.append(("prop", data, name, kw.get("text")))

    def operator(self, idname, **kw):
        mod, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, mod), name), idname
        self.log.append(("operator", idname, kw.get("text")))
        return SimpleNamespace()

    def label(self, text="", **kw):
        self.log.append(("label", text, kw.get("icon")))

    def separator(self, **_k):
        pass

    def props(self, data=None):
        return [e[2] for e in self.log if e[0] == "prop" and (data is None or e[1] == data)]

    def operators(self):
        return [e[1] for e in self.log if e[0] == "operator"]

    def labels(self):
        return [e[1] for e in self.log if e[0] == "label"]


def draw(panel, obj=None, header=False):
    """The recording layout after ``panel``'s draw (or draw_header) for the current scene and ``obj``."""
    layout = Layout()
    ctx = SimpleNamespace(scene=bpy.context.scene, object=obj)
    (panel.draw_header if header else panel.draw)(SimpleNamespace(layout=layout), ctx)
    return layout


ESSENTIALS = {"black_hole", "r_s", "observer", "lens_world", "tess_max_error", "tess_max_error_viewport"}
KNOBS = {"lut_mode", "lut_r_min", "lut_r_max", "lut_n_r", "lut_n_phi", "max_tess_level", "tess_a", "tess_b",
         "cull_ratio", "max_triangles"}


def _scene():
    scene = bpy.context.scene
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.location = (40.0, 0.0, 0.0)
    cam.rotation_euler = (1.5707963, 0.0, 1.5707963)
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = 160, 90
    return scene


def test_essentials_are_open_and_the_knobs_in_the_closed_advanced_panel():
    scene = _scene()
    scene.grlens.lut_mode = "FIXED_RANGE"  # (all of the table's settings drawn)
    main = draw(panels.VIEW3D_PT_grlens)
    assert ESSENTIALS <= set(main.props(scene.grlens))
    assert not KNOBS & set(main.props()), KNOBS & set(main.props())
    assert "grlens.pack_lut" not in main.operators()
    assert "DEFAULT_CLOSED" not in getattr(panels.VIEW3D_PT_grlens, "bl_options", set())

    adv = draw(panels.VIEW3D_PT_grlens_advanced)
    assert set(adv.props(scene.grlens)) == KNOBS
    assert {"grlens.pack_lut", "grlens.unpack_luts"} <= set(adv.operators())
    for sub, props, ops in ((panels.VIEW3D_PT_grlens_advanced, KNOBS, ()),
                            (panels.VIEW3D_PT_grlens_illumination, {"light", "light_intensity"}, ()),
                            (panels.VIEW3D_PT_grlens_physical_time,
                             {"speed_of_light", "use_aberration", "use_doppler_colour", "use_beaming",
                              "use_gravitational_shift"}, ("grlens.set_speed_of_light", "grlens.camera_fall",
                                                              "grlens.camera_orbit")),
                            (panels.VIEW3D_PT_grlens_check, set(), ("grlens.check_frame",))):
        assert sub.bl_parent_id == "VIEW3D_PT_grlens" and "DEFAULT_CLOSED" in sub.bl_options, sub
        got = draw(sub)
        assert props <= set(got.props()) and set(ops) <= set(got.operators()), sub
        assert not set(got.props()) & ESSENTIALS
    assert draw(panels.VIEW3D_PT_grlens_illumination, header=True).props() == ["use_gr_illumination"]
    # the essentials panel has no knob under another name: every property of scene.grlens it draws is
    # an essential, an image-order switch or auto update (and beside it, whether long builds may run
    # beside the interface)
    assert set(main.props(scene.grlens)) <= ESSENTIALS | {"show_order_1", "show_order_2", "auto_update",
                                                          "build_in_background"}
    # every setting of scene.grlens is drawn somewhere (read-only report strings aside)
    drawn = set()
    for p in (panels.VIEW3D_PT_grlens, panels.VIEW3D_PT_grlens_advanced, panels.VIEW3D_PT_grlens_illumination,
              panels.VIEW3D_PT_grlens_physical_time):
        drawn |= set(draw(p).props(scene.grlens))
    drawn |= set(draw(panels.VIEW3D_PT_grlens_illumination, header=True).props())
    settings = {p.identifier for p in scene.grlens.bl_rna.properties if p.identifier not in ("rna_type", "name")}
    assert settings - drawn == {"status", "report_lines", "world_status", "check_summary"}


def _objects_of_every_kind(scene):
    """{type: object} of every kind grlens can image, and of some it cannot."""
    make = {
        "MESH": lambda: bpy.data.meshes.new("m"),
        "CURVE": lambda: bpy.data.curves.new("c", "CURVE"),
        "SURFACE": lambda: bpy.data.curves.new("s", "SURFACE"),
        "FONT": lambda: bpy.data.curves.new("f", "FONT"),
        "META": lambda: bpy.data.metaballs.new("mb"),
        "CURVES": lambda: bpy.data.hair_curves.new("h"),
        "POINTCLOUD": lambda: bpy.data.pointclouds.new("p"),
        "VOLUME": lambda: bpy.data.volumes.new("v"),
        "CAMERA": lambda: bpy.data.cameras.new("cam"),
        "LIGHT": lambda: bpy.data.lights.new("l", "POINT"),
        "EMPTY": lambda: None,
    }
    out = {}
    for kind, data in make.items():
        obj = bpy.data.objects.new(f"obj_{kind}", data())
        scene.collection.objects.link(obj)
        assert obj.type == kind
        out[kind] = obj
    coll = bpy.data.collections.new("Instanced")
    coll.objects.link(bpy.data.objects.new("in_coll", bpy.data.meshes.new("ic")))
    inst = bpy.data.objects.new("collection_instance", None)
    inst.instance_type, inst.instance_collection = "COLLECTION", coll
    scene.collection.objects.link(inst)
    out["COLLECTION_INSTANCE"] = inst
    return out


IMAGEABLE = {"MESH", "CURVE", "SURFACE", "FONT", "META", "CURVES", "POINTCLOUD", "VOLUME", "COLLECTION_INSTANCE"}


def test_every_kind_grlens_can_image_gets_the_lens_switch():
    scene = _scene()
    objs = _objects_of_every_kind(scene)
    assert {k for k, o in objs.items() if gather.can_lens(o)} == IMAGEABLE
    for kind, obj in objs.items():
        side = draw(panels.VIEW3D_PT_grlens, obj)
        has_side = "enabled" in side.props(obj.grlens)
        ctx = SimpleNamespace(scene=scene, object=obj)
        in_props = panels.OBJECT_PT_grlens.poll(ctx)
        assert has_side == in_props == (kind in IMAGEABLE), kind
        if in_props:
            got = draw(panels.OBJECT_PT_grlens, obj)
            assert got.props(obj.grlens)[:2] == ["enabled", "emitter"], kind
    # the thin disc's settings in Object properties; a light a script marked can be switched off
    disc = objs["MESH"]
    disc.grlens.emitter = "THIN_DISC"
    assert {"disc_mode", "disc_r_in", "disc_prograde", "disc_t_peak", "disc_exposure"} <= set(
        draw(panels.OBJECT_PT_grlens, disc).props(disc.grlens))
    lamp = objs["LIGHT"]
    scene.grlens.auto_update = False
    lamp.grlens.enabled = True
    assert "enabled" in draw(panels.VIEW3D_PT_grlens, lamp).props(lamp.grlens)


def _demo():
    assert bpy.ops.grlens.demo_scene(r_s=2.0) == {"FINISHED"}
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 160, 90
    return scene, bpy.data.objects["OrbitingSphere"]


def test_status_line_shows_grlens_time_and_images_say_what_they_show():
    scene, sphere = _demo()
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    labels = draw(panels.VIEW3D_PT_grlens, sphere).labels()
    assert any(re.search(r"object\(s\) lensed.*\[\d+ ms\]", t) for t in labels), labels
    image = bpy.data.objects["OrbitingSphere.GR2"]
    ctx = SimpleNamespace(scene=scene, object=image)
    assert panels.OBJECT_PT_grlens.poll(ctx)
    got = draw(panels.OBJECT_PT_grlens, image)
    assert got.props() == [] and any("Order-2 image of 'OrbitingSphere'" in t for t in got.labels())
    assert "enabled" not in draw(panels.VIEW3D_PT_grlens, image).props()


def _cursor_at(*xyz):
    bpy.context.scene.cursor.location = xyz


def test_add_black_hole_shows_horizon_and_photon_sphere_and_follows_r_s():
    scene = _scene()
    scene.grlens.r_s = 2.0
    _cursor_at(1.0, 2.0, 3.0)
    assert "grlens.add_black_hole" in draw(panels.VIEW3D_PT_grlens).operators()  # offered while there is none
    assert bpy.ops.grlens.add_black_hole("INVOKE_DEFAULT") == {"FINISHED"}
    h = scene.grlens.black_hole
    assert h is not None and h.type == "EMPTY" and h.empty_display_type == "SPHERE"
    assert tuple(h.location) == (1.0, 2.0, 3.0)
    ps = hole.photon_sphere_of(h)
    assert ps is not None and ps.parent == h and ps.empty_display_type == "SPHERE"
    assert h.empty_display_size == pytest.approx(2.0) and ps.empty_display_size == pytest.approx(3.0)
    assert h.hide_render and ps.hide_render and ps.hide_select  # never renders; clicks select the hole
    assert bpy.context.view_layer.objects.active == h and h.select_get()
    assert "grlens.add_black_hole" not in draw(panels.VIEW3D_PT_grlens).operators()
    assert not [t for t in draw(panels.VIEW3D_PT_grlens).labels() if "renders inside the shadow" in t]

    scene.grlens.r_s = 3.0  # set: followed at once
    assert h.empty_display_size == pytest.approx(3.0) and ps.empty_display_size == pytest.approx(4.5)
    scene.grlens.keyframe_insert("r_s", frame=1)
    scene.grlens.keyframe_insert("r_s", frame=11)
    (fc,) = operators._fcurves(scene.animation_data.action)  # (setting r_s = 5 at frame 1 would be undone
    fc.keyframe_points[1].co[1] = 5.0                      # by the animation: the key is edited instead)
    scene.frame_set(11)  # animated: followed on frame changes
    assert h.empty_display_size == pytest.approx(5.0) and ps.empty_display_size == pytest.approx(7.5)
    scene.frame_set(1)
    assert h.empty_display_size == pytest.approx(3.0) and ps.empty_display_size == pytest.approx(4.5)
    h.scale = (2.0, 2.0, 2.0)  # scaled: still shown at true size
    scene.frame_set(1)
    assert h.empty_display_size == pytest.approx(1.5) and ps.empty_display_size == pytest.approx(2.25)
    # a hole made for another r_s follows this scene's when it is chosen again
    scene.grlens.black_hole = None
    scene.animation_data_clear()
    scene.grlens.r_s = 1.0
    h.scale = (1.0, 1.0, 1.0)
    bpy.context.view_layer.update()  # (the new scale reaches matrix_world)
    scene.grlens.black_hole = h
    assert h.empty_display_size == pytest.approx(1.0) and ps.empty_display_size == pytest.approx(1.5)
    # the demo scene's hole is one too
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene, _ = _demo()
    assert hole.is_hole_marker(scene.grlens.black_hole) and scene.grlens.black_hole.empty_display_size == 2.0


def test_add_black_hole_replaces_the_scene_s_hole_with_a_note(capfd):
    scene = _scene()
    old = bpy.data.objects.new("MyHole", None)
    scene.collection.objects.link(old)
    scene.grlens.black_hole = old
    assert bpy.ops.grlens.add_black_hole(location=(0.0, 0.0, 0.0)) == {"FINISHED"}
    new = scene.grlens.black_hole
    assert new != old and hole.is_hole_marker(new) and "MyHole" in bpy.data.objects  # kept, not used
    out = capfd.readouterr()
    assert "replaces 'MyHole' as the scene's black hole" in out.out + out.err
    assert "replaces 'MyHole'" in hole.replaced_note(old)


def test_a_mesh_chosen_as_the_hole_gets_a_note():
    scene = _scene()
    ball = bpy.data.objects.new("Ball", bpy.data.meshes.new("Ball"))
    scene.collection.objects.link(ball)
    scene.grlens.black_hole = ball
    notes = [t for t in draw(panels.VIEW3D_PT_grlens).labels() if "renders inside the shadow" in t]
    assert len(notes) == 1 and "'Ball' is a mesh" in notes[0] and "Add > Black Hole" in notes[0]
    ball.hide_render = True
    assert not [t for t in draw(panels.VIEW3D_PT_grlens).labels() if "renders inside the shadow" in t]


def test_add_menu_has_black_hole():
    funcs = bpy.types.VIEW3D_MT_add._dyn_ui_initialize()
    assert operators.menu_add in funcs
    layout = Layout()
    operators.menu_add(SimpleNamespace(layout=layout), bpy.context)
    assert layout.operators() == ["grlens.add_black_hole"]


def _select(objs):
    bpy.context.view_layer.update()
    for o in bpy.context.scene.objects:
        o.select_set(o in objs)


def test_lens_and_unlens_act_on_every_kind_in_a_mixed_selection():
    scene, sphere = _demo()
    sphere.grlens.enabled = False
    objs = _objects_of_every_kind(scene)
    chosen = list(objs.values()) + [sphere, scene.grlens.black_hole, scene.camera]
    _select(chosen)
    assert set(bpy.context.selected_objects) == set(chosen)
    assert bpy.ops.grlens.lens_selected() == {"FINISHED"}
    marked = {o.name for o in scene.objects if o.grlens.enabled}
    assert marked == {o.name for k, o in objs.items() if k in IMAGEABLE} | {"OrbitingSphere"}
    assert "OrbitingSphere.GR1" in bpy.data.objects  # rebuilt (auto update)
    _select([sphere, objs["MESH"], objs["LIGHT"]])
    assert bpy.ops.grlens.unlens_selected() == {"FINISHED"}
    assert not sphere.grlens.enabled and not objs["MESH"].grlens.enabled and objs["FONT"].grlens.enabled
    assert "OrbitingSphere.GR1" not in bpy.data.objects and sphere.visible_camera and not sphere.hide_render
    _select([objs["LIGHT"], scene.camera])
    assert bpy.ops.grlens.lens_selected() == {"CANCELLED"}  # nothing imageable: said, nothing marked
    assert bpy.ops.grlens.unlens_selected() == {"CANCELLED"}


def test_add_black_hole_can_lens_the_selection():
    scene = _scene()
    ball = bpy.data.objects.new("Ball", bpy.data.meshes.new("Ball"))
    scene.collection.objects.link(ball)
    _select([ball, scene.camera])
    assert bpy.ops.grlens.add_black_hole(lens_selected=True) == {"FINISHED"}
    assert ball.grlens.enabled and not scene.camera.grlens.enabled
    assert not scene.grlens.black_hole.grlens.enabled


def test_unlens_all_says_what_it_does_and_does_it():
    scene, sphere = _demo()
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    rna = bpy.ops.grlens.clear.get_rna_type()
    assert "Lens off on every object" in rna.description and "remove every image object" in rna.description
    assert rna.name == "Unlens All"
    hole_obj, r_s = scene.grlens.black_hole, scene.grlens.r_s
    assert bpy.ops.grlens.clear() == {"FINISHED"}
    assert not [o for o in bpy.data.objects if o.grlens.order in (1, 2)]
    assert not sphere.grlens.enabled and sphere.visible_camera and not sphere.hide_render
    assert scene.grlens.black_hole == hole_obj and scene.grlens.r_s == r_s  # the rest is kept


@pytest.fixture()
def addon_prefs():
    """The add-on enabled in the preferences under its module name (as Blender does for an enabled
    add-on), so that its AddonPreferences exist."""
    prefs = bpy.context.preferences
    addon = prefs.addons.get(preferences.ADDON)
    made = addon is None
    if made:
        addon = prefs.addons.new()
        addon.module = preferences.ADDON
    yield addon.preferences
    if made:
        prefs.addons.remove(addon)


def test_the_cache_folder_preference_wins_over_the_environment(addon_prefs, tmp_path, monkeypatch):
    assert preferences.ADDON == "grlens_addon"
    monkeypatch.setenv(lutcache.CACHE_ENV, str(tmp_path / "from_env"))
    addon_prefs.lut_cache_dir = ""
    assert lutcache._disk_path("t").startswith(str(tmp_path / "from_env") + os.sep)
    addon_prefs.lut_cache_dir = str(tmp_path / "from_prefs")
    assert lutcache._disk_path("t").startswith(str(tmp_path / "from_prefs") + os.sep)
    monkeypatch.delenv(lutcache.CACHE_ENV)
    assert lutcache._disk_path("t").startswith(str(tmp_path / "from_prefs") + os.sep)
    import threading

    seen = []
    worker = threading.Thread(target=lambda: seen.append(lutcache._disk_path("t")))  # (a build thread)
    worker.start()
    worker.join()
    assert seen[0].startswith(str(tmp_path / "from_prefs") + os.sep)
    addon_prefs.lut_cache_dir = ""
    assert lutcache._disk_path("t") is None
    layout = Layout()

    class Prefs:  # the preferences with a recording layout
        def __getattr__(self, name):
            return layout if name == "layout" else getattr(addon_prefs, name)

    preferences.GRLENS_AddonPreferences.draw(Prefs(), bpy.context)
    assert layout.props() == ["lut_cache_dir"] and "unset" in layout.labels()[0]
