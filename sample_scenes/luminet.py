"""Luminet's thin accretion disc (seed 002), built with grlens' public scripting API only.

A geometrically thin disc from r_in = 3 r_s (the innermost stable circular orbit) to 15 r_s around a
hole of r_s = 1 BU, seen by a static observer at 120 r_s at an inclination of 84.5 degrees (angle
between the disc's axis and the line of sight) through a 6 degree vertical field of view. The disc
object has ``obj.grlens.emitter = 'THIN_DISC'``: every image vertex gets its redshift factor 1 + z
(gas on prograde circular geodesics, seen along that image's own geodesic) and the Page-Thorne flux
F(r) / (1 + z)^4 as a colour, grey (bolometric) or the blackbody colour of the observed temperature.
The material emits the ``grlens_disc_colour`` attribute, so the picture is the observed flux itself.
"""
import math

import bpy

R_S = 1.0  # BU
R_OBS = 120.0  # r_s
INCLINATION = 84.5  # degrees
R_IN, R_OUT = 3.0, 15.0  # r_s
EXPOSURE = 0.34  # the Doppler-boosted maximum of F/(1+z)^4 is about 2.9 times the emitted peak here


def _annulus(name, r_in, r_out, rings=72, segments=256):
    """Annulus in the local xy plane (BU), rings denser near r_in where the flux rises steeply,
    with UVs (u: angle, v: radius)."""
    import bmesh

    me = bpy.data.meshes.new(name)
    bm = bmesh.new()
    uv = bm.loops.layers.uv.new("UVMap")
    t = [(i / (rings - 1)) ** 2 for i in range(rings)]
    radii = [r_in + (r_out - r_in) * x for x in t]
    verts = [[bm.verts.new((r * math.cos(2 * math.pi * j / segments), r * math.sin(2 * math.pi * j / segments), 0.0))
              for j in range(segments)] for r in radii]
    for i in range(rings - 1):
        for j in range(segments):
            f = bm.faces.new((verts[i][j], verts[i][(j + 1) % segments], verts[i + 1][(j + 1) % segments],
                              verts[i + 1][j]))
            for loop, (a, b) in zip(f.loops, ((j, i), (j + 1, i), (j + 1, i + 1), (j, i + 1))):
                loop[uv].uv = (a / segments, b / (rings - 1))
    bm.to_mesh(me)
    bm.free()
    return me


def _disc_material():
    mat = bpy.data.materials.new("DiscFlux")
    if bpy.app.version < (5, 0, 0):  # 5.0: always nodes, use_nodes deprecated
        mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    attr = nt.nodes.new("ShaderNodeAttribute")
    attr.attribute_type = "GEOMETRY"
    attr.attribute_name = "grlens_disc_colour"  # written by grlens on the disc's image meshes
    em = nt.nodes.new("ShaderNodeEmission")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(attr.outputs["Color"], em.inputs["Color"])
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    return mat


def luminet_disc(scene, mode="BOLOMETRIC"):
    """Build the scene into ``scene`` (mode: 'BOLOMETRIC' or 'BLACKBODY'). Returns the disc object."""
    hole = bpy.data.objects.new("BlackHole", None)
    hole.empty_display_type = "SPHERE"
    hole.empty_display_size = R_S
    scene.collection.objects.link(hole)
    disc = bpy.data.objects.new("ThinDisc", _annulus("ThinDisc", R_IN * R_S, R_OUT * R_S))
    scene.collection.objects.link(disc)
    disc.data.materials.append(_disc_material())
    # the disc's axis is tilted by 90 - 84.5 degrees from +z towards the camera (+x): inclination 84.5
    disc.rotation_euler = (0.0, math.radians(90.0 - INCLINATION), 0.0)
    cam_data = bpy.data.cameras.new("Observer")
    cam_data.sensor_fit = "VERTICAL"
    cam_data.angle_y = math.radians(6.0)
    cam_data.clip_start, cam_data.clip_end = 1.0, 10.0 * R_OBS * R_S  # images sit at c dt > 100 BU
    cam = bpy.data.objects.new("Observer", cam_data)
    cam.location = (R_OBS * R_S, 0.0, 0.0)
    cam.rotation_euler = (math.radians(90.0), 0.0, math.radians(90.0))  # looking along -x at the hole
    scene.collection.objects.link(cam)
    scene.camera = cam
    world = bpy.data.worlds.new("Black")
    world.color = (0.0, 0.0, 0.0)
    scene.world = world
    scene.view_settings.view_transform = "Standard"  # show the flux linearly
    g = scene.grlens
    g.auto_update = False
    g.black_hole = hole
    g.r_s = R_S
    g.lut_r_min, g.lut_r_max = 1.05, R_OUT + 1.0
    disc.grlens.enabled = True
    disc.grlens.emitter = "THIN_DISC"
    disc.grlens.disc_mode = mode
    disc.grlens.disc_r_in = R_IN
    disc.grlens.disc_exposure = EXPOSURE
    scene.frame_start = scene.frame_end = 1
    g.auto_update = True
    bpy.ops.grlens.rebuild()
    return disc


def luminet_disc_blackbody(scene):
    return luminet_disc(scene, "BLACKBODY")
