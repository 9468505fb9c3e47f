"""Render a small grlens test scene in a fresh Blender (pip bpy) process and write a PNG.

Usage: python render_check.py ENGINE SCENE OUT.png
ENGINE: CYCLES | BLENDER_WORKBENCH | EEVEE (the engine id differs between 4.2/4.5 and 5.0).
SCENE: triangle_behind (seed 000, section 4.1, at p2 = (-5, 0.5, -0.5), r_s = 2, camera at 40 BU)
       sphere_behind (section 4.2: sphere of radius 0.5 r_s at 3 r_s directly behind the hole)
       sphere_side (the same sphere at 90 degrees from the axis)
       demo_animation (grlens.demo_scene, frames 1 and 31 rendered as an animation)
An OUT path ending in .exr writes a multilayer OpenEXR with the grlens AOVs.
Both use an emission material so that no light is needed; the world is black. The image is 160x90
(vertical field of view 20 deg, matching the paper's camera); the hole's centre projects to the
image centre.
"""
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", ".."))

import bpy  # noqa: E402

import grlens_addon  # noqa: E402


def emission_material():
    mat = bpy.data.materials.new("Emit")
    if bpy.app.version < (5, 0, 0):  # 5.0: always nodes, use_nodes deprecated
        mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (1, 1, 1, 1)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    mat.diffuse_color = (1, 1, 1, 1)
    return mat


def render_demo_animation(engine, out):
    """The demo scene's orbit, frames 1 and 31, rendered as an animation (the `blender -b -a` loop):
    the frame handler must rebuild the images for each frame. Writes OUT_0001.png, OUT_0031.png."""
    bpy.ops.grlens.demo_scene(r_s=2.0)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end, scene.frame_step = 1, 31, 30
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = 160, 90, 100
    r.engine = engine
    r.filepath = out + "_"
    bpy.ops.render.render(animation=True)
    print("GRLENS_STATUS", scene.grlens.status)


def main(engine, which, out):
    grlens_addon.register()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    if which == "demo_animation":
        return render_demo_animation(engine, out)
    scene = bpy.context.scene
    r_s = 2.0
    hole = bpy.data.objects.new("BlackHole", None)
    scene.collection.objects.link(hole)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.sensor_fit = "VERTICAL"
    cam.data.angle_y = math.radians(20.0)
    cam.location = (20 * r_s, 0, 0)
    cam.rotation_euler = (math.radians(90), 0, math.radians(90))
    scene.collection.objects.link(cam)
    scene.camera = cam
    mesh = bpy.data.meshes.new("Thing")
    if which == "triangle_behind":
        p = (-5.0, 0.5, -0.5)
        verts = [p, (p[0], p[1] + 3.0, p[2]), (p[0], p[1], p[2] + 3.0)]
        mesh.from_pydata(verts, [], [(0, 1, 2)])
    elif which in ("sphere_behind", "sphere_side"):
        import bmesh

        bm = bmesh.new()
        bmesh.ops.create_uvsphere(bm, u_segments=36, v_segments=18, radius=0.5 * r_s)
        where = (-3 * r_s, 0.0, 0.01 * r_s) if which == "sphere_behind" else (0.0, 3 * r_s, 0.01 * r_s)
        bmesh.ops.translate(bm, verts=bm.verts, vec=where)
        bm.to_mesh(mesh)
        bm.free()
    else:
        raise SystemExit(f"unknown scene {which}")
    obj = bpy.data.objects.new("Thing", mesh)
    scene.collection.objects.link(obj)
    mesh.materials.append(emission_material())
    g = scene.grlens
    g.auto_update = False
    g.black_hole, g.r_s = hole, r_s
    g.max_tess_level = 16
    obj.grlens.enabled = True
    world = bpy.data.worlds.new("Black")
    world.color = (0, 0, 0)
    if bpy.app.version < (5, 0, 0):  # 5.0: always nodes, use_nodes deprecated
        world.use_nodes = True
    for node in world.node_tree.nodes:
        if node.bl_idname == "ShaderNodeBackground":
            node.inputs["Strength"].default_value = 0.0
    scene.world = world
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = 160, 90, 100
    if engine == "EEVEE":
        engine = "BLENDER_EEVEE" if bpy.app.version >= (5, 0, 0) else "BLENDER_EEVEE_NEXT"
    r.engine = engine
    if engine == "CYCLES":
        scene.cycles.device = "CPU"
        scene.cycles.samples = 4
    elif engine == "BLENDER_WORKBENCH":
        scene.display.shading.light = "FLAT"
        scene.display.shading.color_type = "SINGLE"
        scene.display.shading.single_color = (1, 1, 1)
    g.auto_update = True
    bpy.ops.grlens.rebuild()
    if out.endswith(".exr"):  # multilayer EXR with the grlens AOVs
        fmt = r.image_settings
        if bpy.app.version >= (5, 0, 0):
            fmt.media_type = "MULTI_LAYER_IMAGE"
            fmt.use_exr_interleave = True
        fmt.file_format = "OPEN_EXR_MULTILAYER"
        fmt.color_depth = "32"
    r.filepath = out
    bpy.ops.render.render(write_still=True)
    print("GRLENS_STATUS", g.status)


if __name__ == "__main__":
    main(*sys.argv[-3:])
    sys.stdout.flush()
    # skip interpreter teardown: after a GPU-engine render the bpy module can hang or crash at exit
    # (all output is written by now)
    os._exit(0)
