"""Sample scenes built with grlens' public scripting API only (scene.grlens, obj.grlens, bpy.ops.grlens).

Units: Blender units; each scene states its r_s. Scenes follow seed 000 (Mueller, Schulz & Weiskopf
2021): the camera is the static observer at 20 r_s on the +x axis looking at the hole at the origin.
"""
import math

import bpy


def _emission_checker(name, color_a, color_b, scale=8.0):
    """A checkerboard emission material (needs no lights; UV-mapped)."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    tex = nt.nodes.new("ShaderNodeTexChecker")
    tex.inputs["Scale"].default_value = scale
    tex.inputs["Color1"].default_value = (*color_a, 1.0)
    tex.inputs["Color2"].default_value = (*color_b, 1.0)
    uv = nt.nodes.new("ShaderNodeTexCoord")
    nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
    em = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(tex.outputs["Color"], em.inputs["Color"])
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    mat.diffuse_color = (*color_a, 1.0)
    return mat


def _black_world(scene):
    world = bpy.data.worlds.new("Black")
    world.color = (0.0, 0.0, 0.0)
    world.use_nodes = True
    for node in world.node_tree.nodes:
        if node.bl_idname == "ShaderNodeBackground":
            node.inputs["Strength"].default_value = 0.0
    scene.world = world


def sphere_orbit(scene):
    """Seed 000, section 4.2: a sphere of radius 0.5 r_s (36 x 18 UV sphere) on the last stable orbit
    r = 3 r_s, one orbit in 360 frames, camera at 20 r_s with a 19 degree vertical field of view,
    MaxTessLevel 64, a = 5, b = 0.75. r_s = 2 BU."""
    bpy.ops.grlens.demo_scene(r_s=2.0)
    sphere = bpy.data.objects["OrbitingSphere"]
    sphere.data.materials.clear()
    sphere.data.materials.append(_emission_checker("SphereChecker", (0.9, 0.5, 0.1), (0.1, 0.3, 0.9), 12.0))
    _black_world(scene)
    return scene


def triangle_behind(scene):
    """Seed 000, section 4.1: a checkerboard triangle behind the hole at p2 = (-5, 0.5, -0.5) with legs
    of 3 BU along y and z; r_s = 2 BU, observer at (40, 0, 0), vertical field of view 20 degrees;
    frames 1..300 move it from p2 to p1 = (-5, 3, -0.5) and back."""
    r_s = 2.0
    hole = bpy.data.objects.new("BlackHole", None)
    scene.collection.objects.link(hole)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.sensor_fit = "VERTICAL"
    cam.data.angle_y = math.radians(20.0)
    cam.location = (20 * r_s, 0.0, 0.0)
    cam.rotation_euler = (math.radians(90.0), 0.0, math.radians(90.0))
    scene.collection.objects.link(cam)
    scene.camera = cam
    mesh = bpy.data.meshes.new("Triangle")
    mesh.from_pydata([(0, 0, 0), (0, 3, 0), (0, 0, 3)], [], [(0, 1, 2)])
    uv = mesh.uv_layers.new(name="UVMap")
    for loop, co in zip(uv.data, [(0, 0), (1, 0), (0, 1)]):
        loop.uv = co
    tri = bpy.data.objects.new("Triangle", mesh)
    scene.collection.objects.link(tri)
    mesh.materials.append(_emission_checker("TriangleChecker", (0.95, 0.95, 0.95), (0.2, 0.2, 0.2), 8.0))
    tri.location = (-5.0, 0.5, -0.5)
    tri.keyframe_insert("location", frame=1)
    tri.location = (-5.0, 3.0, -0.5)
    tri.keyframe_insert("location", frame=150)
    tri.location = (-5.0, 0.5, -0.5)
    tri.keyframe_insert("location", frame=300)
    scene.frame_start, scene.frame_end = 1, 300
    g = scene.grlens
    g.auto_update = False
    g.black_hole, g.r_s = hole, r_s
    g.max_tess_level, g.tess_a, g.tess_b = 64, 5.0, 0.75
    tri.grlens.enabled = True
    g.auto_update = True
    _black_world(scene)
    return scene


SCENES = {"sphere": sphere_orbit, "triangle": triangle_behind}
