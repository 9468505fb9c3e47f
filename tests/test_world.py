"""The lensed world (grlens_addon/blender/world.py) on the pip bpy module: the user's world node tree
restored exactly (switched off, add-on disabled, save/reload), new nodes hooked, the per-frame
values following the camera, and renders checked per pixel against the exact escape directions of
lutgen.escape (Cycles: perspective, a 2-frame animation with a camera that changes its distance,
an equirectangular panorama, a procedural checker; Eevee: one smoke render in a subprocess).

Units: Blender units, r_s = 2 BU; the camera at about 20 r_s.
"""
import math
import os
import subprocess
import sys

import numpy as np
import pytest

if __name__ == "__main__":  # the Eevee smoke render's subprocess (see test_eevee_smoke)
    sys.path[:0] = [os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."),
                    os.path.dirname(os.path.abspath(__file__))]

import bpy  # noqa: E402

import grlens_addon  # noqa: E402
from blender_session import empty_file, registered  # noqa: E402,F401  (autouse fixtures)
from lutgen.escape import escape_angle, escape_limit, escape_table  # noqa: E402

R_S = 2.0


# ---------------------------------------------------------------------------------------------
# scene helpers
# ---------------------------------------------------------------------------------------------
def _world(scene):
    w = bpy.data.worlds.new("Sky")
    scene.world = w
    if bpy.app.version < (5, 0, 0):
        w.use_nodes = True
    w.cycles.sampling_method = "NONE"  # no importance map: tiny test renders stay fast
    return w


def _direction_world(scene):
    """Background colour 0.5 D + 0.5 from Texture Coordinate Generated (the world ray direction D)."""
    w = _world(scene)
    nt = w.node_tree
    tc = nt.nodes.new("ShaderNodeTexCoord")
    ma = nt.nodes.new("ShaderNodeVectorMath")
    ma.operation = "MULTIPLY_ADD"
    ma.inputs[1].default_value = (0.5, 0.5, 0.5)
    ma.inputs[2].default_value = (0.5, 0.5, 0.5)
    nt.links.new(tc.outputs["Generated"], ma.inputs[0])
    nt.links.new(ma.outputs[0], nt.nodes["Background"].inputs["Color"])
    return w


def _checker_world(scene):
    """A Checker texture with its Vector unlinked (the world's default coordinates)."""
    w = _world(scene)
    nt = w.node_tree
    ch = nt.nodes.new("ShaderNodeTexChecker")
    ch.inputs["Scale"].default_value = 3.0
    ch.inputs["Color1"].default_value = (1.0, 1.0, 1.0, 1.0)
    ch.inputs["Color2"].default_value = (0.25, 0.25, 0.25, 1.0)
    nt.links.new(ch.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    return w


def _busy_world(scene):
    """Every kind of hook: Environment and Sky textures and a Noise unlinked, Generated -> Mapping ->
    Voronoi, Object -> Checker, Normal -> Wave (not a view direction: left alone), two World Outputs
    (Cycles and Eevee targets), plus a node group of the user's."""
    w = _world(scene)
    nt = w.node_tree
    bg = nt.nodes["Background"]
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    sky = nt.nodes.new("ShaderNodeTexSky")
    sky.sun_disc = False  # with the sun disc Blender disables the Vector input (see the test below)
    noise = nt.nodes.new("ShaderNodeTexNoise")
    tc = nt.nodes.new("ShaderNodeTexCoord")
    tc.name = "My Coordinates"
    mp = nt.nodes.new("ShaderNodeMapping")
    mp.inputs["Scale"].default_value = (2.0, 1.0, 0.5)
    vor = nt.nodes.new("ShaderNodeTexVoronoi")
    chk = nt.nodes.new("ShaderNodeTexChecker")
    wave = nt.nodes.new("ShaderNodeTexWave")
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    nt.links.new(tc.outputs["Generated"], mp.inputs["Vector"])
    nt.links.new(mp.outputs["Vector"], vor.inputs["Vector"])
    nt.links.new(tc.outputs["Object"], chk.inputs["Vector"])
    nt.links.new(tc.outputs["Normal"], wave.inputs["Vector"])
    nt.links.new(env.outputs["Color"], mix.inputs[6])
    nt.links.new(sky.outputs["Color"], mix.inputs[7])
    nt.links.new(noise.outputs["Fac"], mix.inputs[0])
    nt.links.new(mix.outputs[2], bg.inputs["Color"])
    nt.links.new(vor.outputs["Distance"], bg.inputs["Strength"])
    out2 = nt.nodes.new("ShaderNodeOutputWorld")
    out2.target = "EEVEE"
    nt.nodes["World Output"].target = "CYCLES"
    em = nt.nodes.new("ShaderNodeBackground")
    nt.links.new(chk.outputs["Color"], em.inputs["Color"])
    nt.links.new(wave.outputs["Fac"], em.inputs["Strength"])
    nt.links.new(em.outputs[0], out2.inputs["Surface"])
    grp = bpy.data.node_groups.new("User Group", "ShaderNodeTree")
    gn = nt.nodes.new("ShaderNodeGroup")
    gn.node_tree = grp
    return w


def _scene(location=(40.0, 3.0, 1.0), rotation_deg=(90.0, 0.0, 95.0), fov_deg=90.0, size=(48, 32)):
    scene = bpy.context.scene
    hole = bpy.data.objects.new("BlackHole", None)
    scene.collection.objects.link(hole)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    scene.camera = cam
    cam.location = location
    cam.rotation_euler = [math.radians(a) for a in rotation_deg]
    cam.data.angle = math.radians(fov_deg)
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = size[0], size[1], 100
    r.engine = "CYCLES"
    r.filter_size = 0.01  # samples at the pixel centres (to 0.005 px)
    scene.cycles.samples = 1
    scene.cycles.use_denoising = False
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    g = scene.grlens
    g.r_s = R_S
    g.black_hole = hole
    return scene, cam, hole


def _snapshot(tree):
    """Everything a user can see of a node tree: every node's RNA properties (data-blocks by name,
    nested structs such as texture_mapping by their own properties), input default values, custom
    properties, and the set of links. Plain Python values only (bpy objects go stale on reload)."""
    skip = ("rna_type", "inputs", "outputs", "internal_links", "dimensions", "interface", "select")

    def val(v, depth=0):
        if isinstance(v, bpy.types.ID):
            return ("ID", v.name)
        if isinstance(v, bpy.types.bpy_struct):
            if isinstance(v, bpy.types.Node):
                return ("Node", v.name)
            if depth > 2:
                return ("struct", type(v).__name__)
            return tuple((p.identifier, val(getattr(v, p.identifier), depth + 1)) for p in v.bl_rna.properties
                         if p.identifier not in skip and p.type != "COLLECTION")
        if isinstance(v, (str, int, float, bool)) or v is None:
            return v
        try:
            return tuple(val(x, depth) for x in v)
        except TypeError:
            return repr(v)

    nodes = {}
    for n in tree.nodes:
        props = {p.identifier: val(getattr(n, p.identifier)) for p in n.bl_rna.properties
                 if p.identifier not in skip and p.type != "COLLECTION"}
        ins = {s.identifier: val(getattr(s, "default_value", None)) for s in n.inputs}
        custom = {k: val(n[k].to_dict() if hasattr(n[k], "to_dict") else n[k]) for k in n.keys()}
        nodes[n.name] = (props, ins, custom)
    links = {(lk.from_node.name, lk.from_socket.identifier, lk.to_node.name, lk.to_socket.identifier,
              lk.is_muted) for lk in tree.links}
    return nodes, links


def _own_nodes(tree):
    return [n for n in tree.nodes if n.get("grlens_own")]


def _render(scene, path):
    import OpenEXR

    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    f = OpenEXR.File(str(path), separate_channels=True)
    ch = f.parts[0].channels
    return np.stack([np.asarray(ch[c].pixels, dtype=np.float64) for c in ("R", "G", "B")], -1)


def _pixel_dirs(scene, cam, du=0.0, dv=0.0):
    """(H, W, 3) world directions of a perspective camera's pixels (row 0 at the top) through the
    points (du, dv) pixels off their centres."""
    tr, br, bl, tl = (np.array(v) for v in cam.data.view_frame(scene=scene))
    w, h = scene.render.resolution_x, scene.render.resolution_y
    u = (np.arange(w) + 0.5 + du) / w
    v = (np.arange(h) + 0.5 + dv) / h
    top = tl[None, :] + u[:, None] * (tr - tl)[None, :]
    bot = bl[None, :] + u[:, None] * (br - bl)[None, :]
    p = top[None] + v[:, None, None] * (bot - top)[None]
    d = p @ np.array(cam.matrix_world.to_3x3()).T
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _equirect_dirs(scene, cam, du=0.0, dv=0.0):
    """(H, W, 3) world directions of a full equirectangular panorama's pixels, Cycles' convention:
    longitude from -pi (left) to pi, latitude from pi/2 (top) to -pi/2, direction
    (cos lat sin lon, sin lat, -cos lat cos lon) in the camera's axes."""
    w, h = scene.render.resolution_x, scene.render.resolution_y
    lon = -np.pi + (np.arange(w) + 0.5 + du) / w * 2 * np.pi
    lat = 0.5 * np.pi - (np.arange(h) + 0.5 + dv) / h * np.pi
    local = np.stack([np.cos(lat)[:, None] * np.sin(lon)[None, :],
                      np.sin(lat)[:, None] + 0 * lon[None, :],
                      -np.cos(lat)[:, None] * np.cos(lon)[None, :]], -1)
    return local @ np.array(cam.matrix_world.to_3x3()).T


def escape_directions(d, cam_pos, hole_pos, r_s):
    """Exact directions (H, W, 3) in which the camera rays d leave to infinity (lutgen.escape), NaN
    where they fall in."""
    rel = np.asarray(cam_pos, float) - np.asarray(hole_pos, float)
    r_obs = np.linalg.norm(rel) / r_s
    e1 = rel / np.linalg.norm(rel)
    c = d @ e1
    xi = np.arctan2(np.linalg.norm(np.cross(d, e1), axis=-1), c)
    phi = escape_angle(r_obs, xi)
    e2 = d - c[..., None] * e1
    e2 /= np.linalg.norm(e2, axis=-1, keepdims=True)
    return np.cos(phi)[..., None] * e1 + np.sin(phi)[..., None] * e2


def _direction_colours(out):
    return np.where(np.isnan(out), 0.0, 0.5 * out + 0.5)


def _check_per_pixel(img, want_at, tol=2e-4):
    """Rendered colours against ``want_at(du, dv)`` (the exact colours through points du, dv px off
    the pixel centres): the error may exceed ``tol`` only by what the colour changes within the
    samples' 0.01 px footprint. Returns the fraction of pixels whose error is below ``tol``."""
    want = want_at(0.0, 0.0)
    spread = np.zeros(want.shape[:2])
    for du, dv in ((0.01, 0), (-0.01, 0), (0, 0.01), (0, -0.01)):
        spread = np.maximum(spread, np.abs(want_at(du, dv) - want).max(-1))
    err = np.abs(img - want).max(-1)
    bad = err > tol + spread
    assert not bad.any(), (np.argwhere(bad)[:10].tolist(), err[bad][:10], spread[bad][:10])
    return float(np.mean(err <= tol))


# ---------------------------------------------------------------------------------------------
# the node tree
# ---------------------------------------------------------------------------------------------
def test_switching_off_restores_the_world_exactly():
    scene = bpy.context.scene
    w = _busy_world(scene)
    before = _snapshot(w.node_tree)
    n_groups, n_images = len(bpy.data.node_groups), len(bpy.data.images)
    _scene()
    nt = w.node_tree
    assert scene.grlens.world_status.startswith("sky lensed, r_obs = 20.")
    own = _own_nodes(nt)
    assert sorted(n.get("grlens_own") for n in own) == ["group", "shadow", "shadow"]
    grp = next(n for n in own if n.get("grlens_own") == "group")
    hooked = {(lk.to_node.name, lk.to_socket.name) for lk in nt.links if lk.from_node == grp
              and lk.from_socket.name == "Vector"}
    assert hooked == {("Environment Texture", "Vector"), ("Sky Texture", "Vector"), ("Noise Texture", "Vector"),
                      ("Mapping", "Vector"), ("Checker Texture", "Vector")}
    assert nt.nodes["Wave Texture"].inputs["Vector"].links[0].from_socket.name == "Normal"
    for out in [n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputWorld"]:
        assert out.inputs["Surface"].links[0].from_node.get("grlens_own") == "shadow"
    assert grlens_addon.blender.world.apply(w) is False  # idempotent
    scene.grlens.lens_world = False
    assert _snapshot(nt) == before
    assert (len(bpy.data.node_groups), len(bpy.data.images)) == (n_groups, n_images)
    scene.grlens.lens_world = True
    assert len(_own_nodes(nt)) == 3
    scene.grlens.black_hole = None  # no hole, no lensing
    assert _snapshot(nt) == before and scene.grlens.world_status == ""


def test_a_sky_texture_with_sun_disc_is_named_as_not_lensed():
    scene = bpy.context.scene
    w = _world(scene)
    sky = w.node_tree.nodes.new("ShaderNodeTexSky")
    sky.sun_disc = True
    nt = w.node_tree
    nt.links.new(sky.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    _scene()
    vec = next(s for s in sky.inputs if s.identifier == "Vector")  # inputs["Vector"] skips a disabled one
    if vec.enabled:  # a Blender that keeps the input: it is hooked
        assert vec.links[0].from_node.get("grlens_own") == "group"
    else:
        assert "not lensed" in scene.grlens.world_status and "Sky Texture" in scene.grlens.world_status
        sky.sun_disc = False
        scene.frame_set(2)
        assert sky.inputs["Vector"].links[0].from_node.get("grlens_own") == "group"
        assert "not lensed" not in scene.grlens.world_status


def test_new_nodes_are_hooked_at_the_next_update_and_the_users_links_win():
    scene = bpy.context.scene
    w = _world(scene)
    _scene()
    nt = w.node_tree
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env_name = env.name
    scene.frame_set(2)
    grp = next(n for n in _own_nodes(nt) if n.get("grlens_own") == "group")
    assert nt.nodes[env_name].inputs["Vector"].links[0].from_node == grp
    # the user links their own coordinates into a hooked input: theirs stays, and stays on restore
    tc = nt.nodes.new("ShaderNodeTexCoord")
    nt.links.new(tc.outputs["Window"], nt.nodes[env_name].inputs["Vector"])
    scene.frame_set(3)
    assert nt.nodes[env_name].inputs["Vector"].links[0].from_socket.name == "Window"
    scene.grlens.lens_world = False
    assert nt.nodes[env_name].inputs["Vector"].links[0].from_socket.name == "Window"
    assert not _own_nodes(nt) and "grlens_hooked" not in nt.nodes[env_name].keys()
    assert {n.name for n in nt.nodes} == {"Background", "World Output", env_name, tc.name}


def test_a_swapped_world_gets_its_tree_back_and_the_new_one_is_lensed():
    scene = bpy.context.scene
    w = _busy_world(scene)
    before = _snapshot(w.node_tree)
    _scene()
    other = bpy.data.worlds.new("Other")
    if bpy.app.version < (5, 0, 0):
        other.use_nodes = True
    scene.world = other
    scene.frame_set(2)
    assert _snapshot(w.node_tree) == before
    assert len(_own_nodes(other.node_tree)) == 2  # the group and the shadow mix
    assert scene.grlens.world_status.startswith("sky lensed")
    scene.world = None  # no world: nothing to lens, no message
    scene.frame_set(3)
    assert not _own_nodes(other.node_tree) and scene.grlens.world_status == ""


def test_deleting_grlens_nodes_by_hand_is_repaired_at_the_next_update():
    scene = bpy.context.scene
    w = _busy_world(scene)
    before = _snapshot(w.node_tree)
    _scene()
    nt = w.node_tree
    for n in _own_nodes(nt):
        nt.nodes.remove(n)
    scene.frame_set(2)
    assert sorted(n.get("grlens_own") for n in _own_nodes(nt)) == ["group", "shadow", "shadow"]
    assert nt.nodes["Mapping"].inputs["Vector"].links[0].from_node.get("grlens_own") == "group"
    scene.grlens.lens_world = False
    assert _snapshot(nt) == before


def test_disabling_the_add_on_restores_the_world():
    scene = bpy.context.scene
    w = _busy_world(scene)
    before = _snapshot(w.node_tree)
    _scene()
    assert _own_nodes(w.node_tree)
    grlens_addon.unregister()
    try:
        assert _snapshot(w.node_tree) == before
        assert not any(g.name.startswith("grlens") for g in bpy.data.node_groups)
        assert not any(i.name.startswith("grlens") for i in bpy.data.images)
    finally:
        grlens_addon.register()


def test_saved_files_hold_the_users_world_and_reload_lenses_it(tmp_path):
    scene = bpy.context.scene
    w = _busy_world(scene)
    before = _snapshot(w.node_tree)
    _, cam, _ = _scene()
    r_obs = float(f"{np.linalg.norm(cam.location) / R_S:.7g}")
    assert _own_nodes(w.node_tree)
    path = str(tmp_path / "sky.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    assert _own_nodes(bpy.data.worlds["Sky"].node_tree)  # lensed again after saving
    # the file itself, opened without the add-on: the user's world, no grlens data-blocks
    grlens_addon.unregister()
    try:
        bpy.ops.wm.open_mainfile(filepath=path)
        assert _snapshot(bpy.data.worlds["Sky"].node_tree) == before
        assert not any(g.name.startswith("grlens") for g in bpy.data.node_groups)
        assert not any(i.name.startswith("grlens") for i in bpy.data.images)
    finally:
        grlens_addon.register()
    # with the add-on: lensed on load (table written), and switching off gives the user's world
    bpy.ops.wm.open_mainfile(filepath=path)
    nt = bpy.data.worlds["Sky"].node_tree
    assert len(_own_nodes(nt)) == 3
    grp = next(n for n in _own_nodes(nt) if n.get("grlens_own") == "group").node_tree
    px = np.empty(4 * grp.nodes["table"].image.size[0], np.float32)
    grp.nodes["table"].image.pixels.foreach_get(px)
    assert np.allclose(px[0::4], escape_table(r_obs).deflection, atol=1e-6, rtol=1e-6)
    bpy.context.scene.grlens.lens_world = False
    assert _snapshot(nt) == before


# ---------------------------------------------------------------------------------------------
# per-frame values
# ---------------------------------------------------------------------------------------------
def test_values_and_table_follow_the_camera_every_frame():
    import time

    scene = bpy.context.scene
    w = _direction_world(scene)
    scene_, cam, hole = _scene()
    cam.animation_data_clear()
    for f, x in ((1, 40.0), (2, 10.0), (3, 2.6)):  # 20, 5 and 1.3 r_s (inside the photon sphere)
        cam.location = (x, 1.0, 0.5)
        cam.keyframe_insert("location", frame=f)
    grp = next(n for n in _own_nodes(w.node_tree) if n.get("grlens_own") == "group").node_tree
    times = []
    for f in (1, 2, 3, 2, 1):
        t0 = time.perf_counter()
        scene.frame_set(f)
        times.append(time.perf_counter() - t0)
        p = np.array(cam.matrix_world.translation)
        r_obs = np.linalg.norm(p) / R_S
        e1 = [grp.nodes["e1"].inputs[k].default_value for k in range(3)]
        assert np.allclose(e1, p / np.linalg.norm(p), atol=1e-7)
        assert grp.nodes["xi_lim"].outputs[0].default_value == pytest.approx(escape_limit(r_obs), abs=1e-6)
        assert grp.nodes["table"].image == grp.nodes["table+1"].image != grp.nodes["spare"].image
        px = np.empty(4 * grp.nodes["table"].image.size[0], np.float32)
        grp.nodes["table"].image.pixels.foreach_get(px)
        want = escape_table(float(f"{r_obs:.7g}")).deflection
        assert np.allclose(px[0::4], want, atol=2e-6, rtol=1e-6), f
    assert "r_obs = 1.3" in scene.grlens.world_status or "r_obs = 20" in scene.grlens.world_status
    assert min(times) < 0.05  # a frame change with a new table (benchmarks/bench_sky.py: a few ms)


def test_the_table_is_read_the_way_the_engine_reads_it_best():
    """Cycles reads the table with one filtered lookup; Eevee (GPU samplers) with two texel lookups
    interpolated in math nodes. A change of engine relinks the group at the next update."""
    scene = bpy.context.scene
    w = _direction_world(scene)
    _scene()
    grp = next(n for n in _own_nodes(w.node_tree) if n.get("grlens_own") == "group").node_tree
    eevee = "BLENDER_EEVEE" if bpy.app.version >= (5, 0, 0) else "BLENDER_EEVEE_NEXT"
    for engine, source in (("CYCLES", "linear value"), (eevee, "closest value"), ("CYCLES", "linear value")):
        scene.render.engine = engine
        bpy.context.evaluated_depsgraph_get().update()  # the depsgraph handler (an engine picked in the UI)
        links = grp.nodes["rotate"].inputs["Angle"].links
        assert len(links) == 1 and links[0].from_node.name == source, engine
        assert grp.nodes["linear"].image == grp.nodes["table"].image  # one table for both


def test_the_sky_is_lensed_for_the_camera_that_renders():
    """scene.grlens.observer may name another camera than the one that renders (an outside view of
    the image meshes): the sky follows the render camera, so its own sky is exact; markers that switch
    the active camera switch the lensed sky with it."""
    scene = bpy.context.scene
    w = _direction_world(scene)
    _, cam, hole = _scene()
    outside = bpy.data.objects.new("Outside", bpy.data.cameras.new("Outside"))
    scene.collection.objects.link(outside)
    outside.location = (0.0, -60.0, 10.0)
    scene.grlens.observer = cam
    grp = next(n for n in _own_nodes(w.node_tree) if n.get("grlens_own") == "group").node_tree

    def e1():
        return np.array([grp.nodes["e1"].inputs[k].default_value for k in range(3)])

    for active in (outside, cam):
        scene.camera = active
        scene.frame_set(scene.frame_current)
        p = np.array(active.location)
        assert np.allclose(e1(), p / np.linalg.norm(p), atol=1e-7), active.name
        r_obs = np.linalg.norm(p) / R_S
        assert grp.nodes["xi_lim"].outputs[0].default_value == pytest.approx(escape_limit(r_obs), abs=1e-6)
    scene.timeline_markers.new("outside", frame=5).camera = outside
    scene.timeline_markers.new("observer", frame=9).camera = cam
    for f, active in ((6, outside), (10, cam)):
        scene.frame_set(f)
        p = np.array(active.location)
        assert np.allclose(e1(), p / np.linalg.norm(p), atol=1e-7), f


@pytest.mark.parametrize("auto_update", [True, False])
def test_moving_the_camera_by_hand_updates_the_sky(auto_update):
    """A camera moved in the viewport (no frame change): the depsgraph handler updates the sky."""
    scene = bpy.context.scene
    w = _direction_world(scene)
    _, cam, _ = _scene()
    scene.grlens.auto_update = auto_update
    grp = next(n for n in _own_nodes(w.node_tree) if n.get("grlens_own") == "group").node_tree
    cam.location = (10.0, 10.0, 0.5)
    bpy.context.view_layer.update()
    e1 = np.array([grp.nodes["e1"].inputs[k].default_value for k in range(3)])
    p = np.array(cam.location)
    assert np.allclose(e1, p / np.linalg.norm(p), atol=1e-7)
    assert scene.grlens.world_status.startswith(f"sky lensed, r_obs = {np.linalg.norm(p) / R_S:.4g} r_s")


def test_rebuild_without_marked_objects_lenses_the_world():
    scene = bpy.context.scene
    w = _world(scene)
    _, cam, _ = _scene()
    scene.grlens.lens_world = False
    assert not _own_nodes(w.node_tree)
    with pytest.raises(RuntimeError, match="no object is marked"):
        bpy.ops.grlens.rebuild()
    scene.grlens.lens_world = True
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    assert scene.grlens.status.startswith("no object marked; sky lensed, r_obs = 20.")
    cam.location = (1.0, 0.5, 0.0)  # inside the horizon (r = 0.56 r_s)
    with pytest.raises(RuntimeError, match="inside the event horizon"):
        bpy.ops.grlens.rebuild()
    assert scene.grlens.world_status.startswith("grlens: the camera is inside the event horizon")
    grp = next(n for n in _own_nodes(w.node_tree) if n.get("grlens_own") == "group").node_tree
    assert grp.nodes["xi_lim"].outputs[0].default_value == 0.0  # every ray falls in: black


# ---------------------------------------------------------------------------------------------
# renders
# ---------------------------------------------------------------------------------------------
def test_cycles_render_matches_the_exact_escape_directions(tmp_path):
    scene = bpy.context.scene
    _direction_world(scene)
    _, cam, hole = _scene()
    scene.grlens.lens_world = False
    plain = _render(scene, tmp_path / "plain.exr")
    # the conventions first: unlensed, the colour is 0.5 D + 0.5 of the pixel's own ray
    assert np.abs(plain - (0.5 * _pixel_dirs(scene, cam) + 0.5)).max() < 1e-4
    scene.grlens.lens_world = True
    img = _render(scene, tmp_path / "lensed.exr")

    def want(du, dv):
        d = _pixel_dirs(scene, cam, du, dv)
        return _direction_colours(escape_directions(d, cam.location, hole.location, R_S))

    assert _check_per_pixel(img, want) > 0.98
    dark = np.isnan(escape_directions(_pixel_dirs(scene, cam), cam.location, hole.location, R_S)).any(-1)
    assert 10 < dark.sum() < 60 and np.all(img[dark] == 0.0)  # the shadow, black


@pytest.mark.parametrize("persistent", [False, True])
def test_cycles_animation_follows_the_camera_and_its_distance(tmp_path, persistent):
    """A render of three frames (the `blender -b -a` loop) with the camera moving from 20 to 8 and 5
    r_s: each frame's sky is the exact one of that frame's camera (the table written in the frame
    handler is the one rendered), also with Persistent Data (Cycles keeps its scene between frames)."""
    import OpenEXR

    scene = bpy.context.scene
    _direction_world(scene)
    _, cam, hole = _scene(size=(32, 24))
    cam.animation_data_clear()
    cam.location = (40.0, 3.0, 1.0)
    cam.keyframe_insert("location", frame=1)
    cam.location = (16.0, 1.0, 0.5)
    cam.keyframe_insert("location", frame=2)
    cam.location = (10.0, 1.0, 0.5)
    cam.keyframe_insert("location", frame=3)
    scene.frame_start, scene.frame_end = 1, 3
    scene.render.use_persistent_data = persistent
    scene.render.filepath = str(tmp_path / "anim_")
    bpy.ops.render.render(animation=True)
    for f in (1, 2, 3):
        scene.frame_set(f)
        ch = OpenEXR.File(str(tmp_path / f"anim_{f:04d}.exr"), separate_channels=True).parts[0].channels
        img = np.stack([np.asarray(ch[c].pixels, dtype=np.float64) for c in ("R", "G", "B")], -1)
        pos = np.array(cam.matrix_world.translation)

        def want(du, dv, pos=pos):
            d = _pixel_dirs(scene, cam, du, dv)
            return _direction_colours(escape_directions(d, pos, hole.location, R_S))

        assert _check_per_pixel(img, want) > 0.9, f  # (at 5 r_s more pixels lie by the shadow)


def test_cycles_equirectangular_panorama(tmp_path):
    """The node group works from the ray direction, so panoramic cameras are lensed too."""
    scene = bpy.context.scene
    _direction_world(scene)
    _, cam, hole = _scene(size=(48, 24))
    cam.data.type = "PANO"
    if hasattr(cam.data, "panorama_type"):
        cam.data.panorama_type = "EQUIRECTANGULAR"
    else:  # Blender < 4.0 kept it in Cycles' settings
        cam.data.cycles.panorama_type = "EQUIRECTANGULAR"
    scene.grlens.lens_world = False
    plain = _render(scene, tmp_path / "plain.exr")
    assert np.abs(plain - (0.5 * _equirect_dirs(scene, cam) + 0.5)).max() < 1e-4
    scene.grlens.lens_world = True
    img = _render(scene, tmp_path / "pano.exr")

    def want(du, dv):
        return _direction_colours(escape_directions(_equirect_dirs(scene, cam, du, dv), cam.location,
                                                    hole.location, R_S))

    assert _check_per_pixel(img, want) > 0.95


def _fisheye_dirs(cam, size, fov, du=0.0, dv=0.0):
    """(H, W, 3) world directions of a square equidistant fisheye's pixels through points du, dv px
    off their centres (row 0 at the top); NaN outside its circle, where Cycles has no ray."""
    n = size
    x = (2.0 * (np.arange(n) + 0.5 + du) / n - 1.0)[None, :] + np.zeros((n, 1))
    y = (1.0 - 2.0 * (np.arange(n) + 0.5 + dv) / n)[:, None] + np.zeros((1, n))
    rho = np.hypot(x, y)
    theta = 0.5 * fov * rho
    sr = np.sin(theta) / np.maximum(rho, 1e-300)
    local = np.stack([x * sr, y * sr, -np.cos(theta)], -1)
    local[rho > 1.0] = np.nan
    return local @ np.array(cam.matrix_world.to_3x3()).T


def test_cycles_fisheye_dome_master(tmp_path):
    """A 180 degree equidistant fisheye (a dome master) looking past the hole: the lensed world per
    pixel, black in the shadow and outside the circle."""
    from grlens_addon.blender.check import check_camera

    scene = bpy.context.scene
    _direction_world(scene)
    _, cam, hole = _scene(size=(32, 32), rotation_deg=(90.0, 0.0, 110.0))
    cam.data.type = "PANO"
    cam.data.panorama_type = "FISHEYE_EQUIDISTANT"
    cam.data.fisheye_fov = math.pi
    ref = check_camera(scene, cam, 100).pixel_directions()  # the reference's model (test_panorama: Cycles')
    mine = _fisheye_dirs(cam, 32, math.pi)
    assert np.array_equal(np.isnan(ref), np.isnan(mine))
    assert np.allclose(ref[~np.isnan(ref)], mine[~np.isnan(mine)], atol=1e-6)
    scene.grlens.lens_world = True
    img = _render(scene, tmp_path / "dome.exr")

    def want(du, dv):
        d = _fisheye_dirs(cam, 32, math.pi, du, dv)
        out = np.full(d.shape, np.nan)
        ok = np.all(np.isfinite(d), -1)
        out[ok] = escape_directions(d[ok], cam.location, hole.location, R_S)
        return _direction_colours(out)

    assert _check_per_pixel(img, want) > 0.9
    d = _fisheye_dirs(cam, 32, math.pi)
    ok = np.all(np.isfinite(d), -1)
    fell = np.zeros(ok.shape, bool)
    fell[ok] = np.isnan(escape_directions(d[ok], cam.location, hole.location, R_S)).any(-1)
    assert fell.sum() >= 1 and np.all(img[fell] == 0.0) and np.all(img[~ok] == 0.0)


def _checker(p, scale=3.0):
    """Cycles' checker texture (svm_checker): colour 1 or 2 of the point p * scale."""
    p = (p * scale + 0.000001) * 0.999999
    i = np.abs(np.floor(p)).astype(np.int64) % 2
    return np.where(((i[..., 0] == i[..., 1]) == (i[..., 2] == 1))[..., None] & True, 1.0, 0.25)


def test_cycles_procedural_checker_world(tmp_path):
    """A procedural texture with its default coordinates is lensed: each pixel shows the checker
    colour of its exact escape direction (black in the shadow), but where the 0.01 px footprint of
    its samples crosses a checker edge."""
    scene = bpy.context.scene
    _checker_world(scene)
    _, cam, hole = _scene()
    img = _render(scene, tmp_path / "checker.exr")

    def want(du, dv):
        out = escape_directions(_pixel_dirs(scene, cam, du, dv), cam.location, hole.location, R_S)
        col = _checker(np.nan_to_num(out))
        return np.where(np.isnan(out).any(-1, keepdims=True), 0.0, np.repeat(col, 3, -1))

    assert _check_per_pixel(img, want, tol=1e-5) > 0.95


# ---------------------------------------------------------------------------------------------
# a moving camera (physical time): its sky aberrated by its own velocity
# ---------------------------------------------------------------------------------------------
def _moving(scene, cam, velocity=(-3.0, 4.0, 1.0), c=10.0, shift_colours=False):
    """Key the camera moving linearly (BU per frame) through its position at frame 2, set the speed
    of light (BU per frame) and the colour switches (off: the sky's directions alone); returns beta in
    the local static frame at frame 2 (units of c)."""
    from grlens_addon.core import observer_view

    pos = np.array(cam.location)
    v = np.array(velocity)
    cam.animation_data_clear()
    for f in (1, 3):
        cam.location = tuple(pos + (f - 2) * v)
        cam.keyframe_insert("location", frame=f)
    from grlens_addon.blender import motion

    for fc in motion._fcurves(cam):
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"
    scene.grlens.speed_of_light = c
    g = scene.grlens
    g.use_doppler_colour = g.use_beaming = g.use_gravitational_shift = shift_colours
    scene.frame_set(2)
    return observer_view.static_frame_beta(pos, v, np.zeros(3), R_S, c)[0]


def _boosted_back(d, beta):
    """The static frame's directions of the light a camera moving with ``beta`` sees from ``d``
    (H, W, 3): the photons' 4-momenta (1, -d) boosted back with the Lorentz matrix."""
    b2 = beta @ beta
    g = 1 / np.sqrt(1 - b2)
    L = np.eye(4)
    L[0, 0] = g
    L[0, 1:] = L[1:, 0] = g * beta  # the boost by -beta
    L[1:, 1:] += (g - 1) * np.outer(beta, beta) / b2
    p = np.concatenate([np.ones(d.shape[:-1] + (1,)), -d], -1) @ L.T
    return -p[..., 1:] / np.linalg.norm(p[..., 1:], axis=-1, keepdims=True)


@pytest.mark.parametrize("panorama", [False, True])
def test_cycles_render_of_a_moving_cameras_sky_matches_the_exact_aberrated_escape_directions(tmp_path, panorama):
    """With speed_of_light > 0 the camera's keyed motion aberrates its sky: each pixel shows the escape
    direction of its ray taken back to the static frame (a Lorentz matrix here), per pixel, in a
    perspective view and a full equirectangular panorama; the world status names the speed."""
    scene = bpy.context.scene
    _direction_world(scene)
    _, cam, hole = _scene(size=(48, 24) if panorama else (48, 32))
    if panorama:
        cam.data.type = "PANO"
        cam.data.panorama_type = "EQUIRECTANGULAR"
    beta = _moving(scene, cam)
    assert 0.3 < np.linalg.norm(beta) < 0.9
    assert f"camera at {np.linalg.norm(beta):.3g} c" in scene.grlens.world_status, scene.grlens.world_status
    img = _render(scene, tmp_path / "moving.exr")
    pos = np.array(cam.matrix_world.translation)
    dirs = _equirect_dirs if panorama else _pixel_dirs

    def want(du, dv):
        d = _boosted_back(dirs(scene, cam, du, dv), beta)
        return _direction_colours(escape_directions(d, pos, hole.location, R_S))

    assert _check_per_pixel(img, want) > 0.9
    static = _direction_colours(escape_directions(dirs(scene, cam), pos, hole.location, R_S))
    assert np.abs(img - static).max() > 0.1  # (the aberration shows)


def test_a_camera_at_rest_keeps_the_aberration_out_of_the_sky_shader():
    """The inverse aberration is linked into the group only while the camera moves (a camera at rest
    pays nothing for it); switching back relinks D itself."""
    from grlens_addon.blender import world

    scene = bpy.context.scene
    _direction_world(scene)
    _, cam, hole = _scene()
    world.update(scene)
    grp = world._group_node(scene.world.node_tree).node_tree

    def source():
        return {s.links[0].from_node.name for s in world._direction_inputs(grp)}

    assert source() == {"D"}
    _moving(scene, cam)
    world.update(scene)
    assert source() == {"static direction"}
    assert grp.nodes["gamma_beta"].outputs[0].default_value > 0.3
    scene.grlens.use_aberration = False  # for teaching: the sky of a camera at rest
    world.update(scene)
    assert source() == {"D"} and "aberration off" in scene.grlens.world_status
    scene.grlens.use_aberration = True
    scene.grlens.speed_of_light = 0.0
    world.update(scene)
    assert source() == {"D"} and grp.nodes["gamma_beta"].outputs[0].default_value == 0.0


@pytest.mark.parametrize("velocity", [(-3.0, 4.0, 1.0), (0.0, 0.0, 0.0)])
def test_cycles_render_of_the_skys_colours_shifted_for_the_moving_camera(tmp_path, velocity):
    """With physical time and the colour switches on, the sky's light (emitted at rest at infinity)
    reaches the camera with g = gamma (1 + beta . D_static) / sqrt(1 - r_s/r): each pixel shows the
    colour of its escape direction shifted by that g (core.spectrum), per pixel; a camera at rest
    sees the whole sky blue-shifted by 1 / sqrt(1 - r_s/r)."""
    from grlens_addon.core import spectrum

    scene = bpy.context.scene
    _direction_world(scene)
    _, cam, hole = _scene(size=(40, 24))
    beta = _moving(scene, cam, velocity=velocity, shift_colours=True)
    img = _render(scene, tmp_path / "shifted.exr")
    pos = np.array(cam.matrix_world.translation)
    r = np.linalg.norm(pos - np.array(hole.location)) / R_S

    def want(du, dv):
        d = _pixel_dirs(scene, cam, du, dv)
        ds = _boosted_back(d, beta) if np.any(beta) else d
        colour = _direction_colours(escape_directions(ds, pos, hole.location, R_S))
        gamma = 1 / np.sqrt(1 - beta @ beta)
        g = gamma * (1 + ds @ beta) / np.sqrt(1 - 1 / r)
        m = spectrum.shift_matrix(g.ravel()).reshape(g.shape + (3, 3))
        return np.maximum(np.einsum("hwij,hwj->hwi", m, colour), 0.0)

    assert _check_per_pixel(img, want, tol=2e-2) > 0.9
    if not np.any(beta):
        assert 1.02 < 1 / np.sqrt(1 - 1 / r) < 1.03  # (20 r_s)


def test_the_skys_colour_shift_is_hooked_restorably():
    """The sky's colour shift hooks every Background colour through a grlens node: switching the speed
    of light off takes it out again, lens_world off gives back the user's tree exactly, and a
    Background with an unlinked colour keeps its own colour in the shift node."""
    from grlens_addon.blender import world

    scene = bpy.context.scene
    w = _direction_world(scene)
    plain_bg = w.node_tree.nodes.new("ShaderNodeBackground")  # a second, unlinked one
    plain_bg.inputs["Color"].default_value = (0.2, 0.3, 0.4, 1.0)
    _, cam, hole = _scene()
    scene.grlens.lens_world = False
    before = _snapshot(w.node_tree)
    scene.grlens.lens_world = True
    lensed = _snapshot(w.node_tree)
    _moving(scene, cam, shift_colours=True)
    world.update(scene)
    shifts = [n for n in w.node_tree.nodes if n.get("grlens_own") == "sky shift"]
    assert len(shifts) == 2
    for bg in (w.node_tree.nodes["Background"], plain_bg):
        assert bg.inputs["Color"].links[0].from_node.get("grlens_own") == "sky shift"
    plain_shift = plain_bg.inputs["Color"].links[0].from_node
    assert tuple(plain_shift.inputs["Color"].default_value) == pytest.approx((0.2, 0.3, 0.4, 1.0))
    scene.grlens.speed_of_light = 0.0
    world.update(scene)
    assert not [n for n in w.node_tree.nodes if n.get("grlens_own") == "sky shift"]
    assert _snapshot(w.node_tree) == lensed
    scene.grlens.speed_of_light = 10.0
    world.update(scene)
    scene.grlens.lens_world = False
    assert _snapshot(w.node_tree) == before


def _shift_reference(c, beta, r_obs, colour=True, beaming=True, gravity=True):
    """The sky's shift matrices at camera-frame cosines ``c`` by core.spectrum.shift_matrix: hue shifted
    by g_hue (clipped to 1/4 .. 4), brightness by g_bright^5."""
    from grlens_addon.core import spectrum

    gamma = 1 / math.sqrt(1 - beta * beta)
    ln_m = -np.log(gamma * (1 + beta * c))
    ln_grav = -0.5 * math.log(1 - 1 / r_obs) if gravity else 0.0
    g_hue = np.exp(np.clip(ln_m * colour + ln_grav, *spectrum.LN_G_RANGE))
    g_bright = np.exp(ln_m * beaming + ln_grav)
    return spectrum.shift_matrix(g_hue) / (g_hue ** 5)[:, None, None] * (g_bright ** 5)[:, None, None], g_bright


def _matrices_of(px):
    """(n, 3, 3) the matrices that the sky-shift group applies, from its texels ``px`` (3, n, 4): one
    row per table."""
    assert np.all(px[:, :, 3] == 1)
    return np.swapaxes(px[:, :, :3], 0, 1)


@pytest.mark.parametrize("beta, tol", [(0.0, 3e-4), (0.3, 3e-4), (0.7, 3e-4), (0.9, 4e-3)])
def test_the_sky_shift_tables_against_the_exact_shift(beta, tol):
    """world.sky_shift_pixels: the matrices the sky-shift group makes of its texels (two entries per row
    and the row sum) against core.spectrum.shift_matrix at each texel's cosine (within 2e-4 g^5, the
    cached table's interpolation), and halfway between texels, where the group interpolates linearly in
    c (the error grows where g changes fast: next to the direction of motion of a fast camera), for
    every switch setting; the group's u puts c_j at texel j's centre."""
    from grlens_addon.blender import world

    n = world.SHIFT_SIZE
    c = np.linspace(-1, 1, n)
    for switches in ((True, True, True), (True, False, True), (False, True, True), (True, True, False)):
        px = world.sky_shift_pixels(beta, 20.0, *switches).reshape(3, n, 4).astype(np.float64)
        want, g_b = _shift_reference(c, beta, 20.0, *switches)
        err = np.abs(_matrices_of(px) - want).max((1, 2)) / g_b ** 5
        assert err.max() < 2e-4, (switches, err.max())
        mid = 0.5 * (c[1:] + c[:-1])
        want, g_b = _shift_reference(mid, beta, 20.0, *switches)
        err = np.abs(_matrices_of(0.5 * (px[:, 1:] + px[:, :-1])) - want).max((1, 2)) / g_b ** 5
        assert err.max() < tol, (switches, err.max())
    grp = world._build_shift_group("test shift")
    u = grp.nodes["Math"]
    assert u.label == "u"
    for j in (0, 17, n - 1):
        assert c[j] * u.inputs[1].default_value + u.inputs[2].default_value == pytest.approx((j + 0.5) / n, abs=1e-9)


def test_the_sky_shift_tables_are_written_when_the_camera_changes_and_read_per_engine():
    """The tables are written (into the spare images, which take the lookups' place) only when the
    camera's speed, radius or a switch changes; Cycles reads them with one filtered lookup each, Eevee
    with texel pairs mixed in math nodes."""
    from grlens_addon.blender import world

    scene = bpy.context.scene
    w = _direction_world(scene)
    _, cam, hole = _scene()
    _moving(scene, cam, shift_colours=True)
    grp = world._group_node(w.node_tree).node_tree
    shift = grp.nodes[world.SHIFT_HOLDER].node_tree
    before = shift.nodes["shift 0"].image
    world.set_sky_shift(grp, scene, 20.0, 0.5)
    assert not world.set_sky_shift(grp, scene, 20.0, 0.5)
    assert world.set_sky_shift(grp, scene, 20.0, 0.6)
    scene.grlens.use_beaming = False
    assert world.set_sky_shift(grp, scene, 20.0, 0.6)
    a = shift.nodes["shift 0"].image
    assert a == shift.nodes["shift 0 0"].image == shift.nodes["shift 0 1"].image != shift.nodes["shift 0 spare"].image
    px = np.empty(4 * world.SHIFT_SIZE, np.float32)
    a.pixels.foreach_get(px)
    np.testing.assert_array_equal(px, world.sky_shift_pixels(0.6, 20.0, True, False, True)[0])
    assert before is not None
    eevee = "BLENDER_EEVEE" if bpy.app.version >= (5, 0, 0) else "BLENDER_EEVEE_NEXT"
    for engine, source in (("CYCLES", "shift 1"), (eevee, "shift 1 closest"), ("CYCLES", "shift 1")):
        scene.render.engine = engine
        world.update(scene)
        assert shift.nodes["row 1"].inputs[0].links[0].from_node.name == source, engine


def test_check_frame_of_a_moving_camera_checks_its_aberrated_sky(tmp_path):
    """bpy.ops.grlens.check_frame with a moving camera: the reference traces the camera's own pixel
    rays and the sky model takes them back to the static frame as the node group does: they agree."""
    scene = bpy.context.scene
    _direction_world(scene)
    _, cam, hole = _scene(size=(64, 40))
    sphere = bpy.data.objects.new("Ball", bpy.data.meshes.new("Ball"))
    import bmesh

    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=16, v_segments=8, radius=2.0)
    bm.to_mesh(sphere.data)
    bm.free()
    sphere.location = (-12.0, 6.0, 1.0)
    scene.collection.objects.link(sphere)
    sphere.grlens.enabled = True
    _moving(scene, cam, velocity=(-2.0, 3.0, 0.5))
    assert bpy.ops.grlens.check_frame(percentage=100, filepath="") == {"FINISHED"}
    summary = scene.grlens.check_summary
    assert "sky" in summary, summary
    from grlens_addon.blender import check
    from grlens_addon.blender.rebuild import scene_geometry

    result, _ = check.check_scene(scene, bpy.context.evaluated_depsgraph_get(), 100, "")
    sky = result.metrics["sky"]
    assert sky["compared"] > 1000 and sky["sky_angle_px"]["p99"] < 0.05 and sky["shadow_mismatch"] <= 3, sky
    assert np.linalg.norm(scene_geometry(scene, bpy.context.evaluated_depsgraph_get())[0].beta) > 0.1


# ---------------------------------------------------------------------------------------------
# Eevee: one smoke render in a subprocess (bpy 4.2 may crash at exit after a GPU-engine render)
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", ["eevee", "eevee_moving", "eevee_shifted"])
def test_eevee_smoke(tmp_path, mode):
    """Eevee renders the lensed sky, of a camera at rest, of one moving (aberrated), and of one moving
    with the sky's colour shift."""
    out = tmp_path / "eevee.exr"
    p = subprocess.run([sys.executable, __file__, mode, str(out)], capture_output=True, text=True, timeout=600,
                       cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    assert "GRLENS_EEVEE_ERR" in p.stdout, p.stdout[-3000:] + p.stderr[-3000:]
    line = next(ln for ln in p.stdout.splitlines() if ln.startswith("GRLENS_EEVEE_ERR"))
    p99, frac = (float(v) for v in line.split()[1:3])
    # Eevee samples across the pixel (no filter control): the 99th percentile of the colour error
    # against the exact directions, and the shadow's pixels black
    assert p99 < 3e-3 and frac > 0.95, line


def _eevee_main(out, moving=False, shifted=False):
    grlens_addon.register()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    _direction_world(scene)
    _, cam, hole = _scene(size=(48, 32))
    scene.render.engine = "BLENDER_EEVEE" if bpy.app.version >= (5, 0, 0) else "BLENDER_EEVEE_NEXT"
    scene.eevee.taa_render_samples = 1
    scene.view_settings.view_transform = "Standard"
    beta = _moving(scene, cam, shift_colours=shifted) if moving else None
    img = _render(scene, out)
    d = _pixel_dirs(scene, cam)
    if beta is not None:
        d = _boosted_back(d, beta)
    pos = np.array(cam.matrix_world.translation)
    exact = escape_directions(d, pos, hole.location, R_S)
    want = _direction_colours(exact)
    if shifted:
        from grlens_addon.core import spectrum

        r = np.linalg.norm(pos - np.array(hole.location)) / R_S
        g = (d @ beta + 1) / np.sqrt(1 - beta @ beta) / np.sqrt(1 - 1 / r)
        m = spectrum.shift_matrix(g.ravel()).reshape(g.shape + (3, 3))
        want = np.maximum(np.einsum("hwij,hwj->hwi", m, want), 0.0)
    err = np.abs(img - want).max(-1)
    dark = np.isnan(exact).any(-1)
    print("GRLENS_EEVEE_ERR", np.percentile(err, 99), np.mean(err < 2e-3), int(dark.sum()),
          float(np.abs(img[dark]).max()) if dark.any() else 0.0, flush=True)


if __name__ == "__main__" and len(sys.argv) == 3 and sys.argv[1] in ("eevee", "eevee_moving", "eevee_shifted"):
    _eevee_main(sys.argv[2], moving=sys.argv[1] != "eevee", shifted=sys.argv[1] == "eevee_shifted")
    sys.stdout.flush()
    os._exit(0)
