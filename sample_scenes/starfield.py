"""A lensed star field (issue 21 item 5): Luminet's thin disc and the paper's orbiting sphere in front of
a procedural star field, seen by one observer through three cameras: a normal perspective view, a
180-degree fisheye dome master and a 360-degree equirectangular panorama. Built with grlens' public
scripting API only; no downloaded assets (the stars are made in the world's node tree).

Units: r_s = 1 BU, the hole at the origin. The observer is 20 r_s from the hole on the +x axis; every
camera sits there and looks at the hole, so the three views share one set of image meshes (the
active camera is grlens' observer; the dome and the panorama image everything, the normal view
culls by its frustum).

* The disc: Luminet's infinitely thin disc (sample_scenes/luminet.py: 3 to 15 r_s,
  ``obj.grlens.emitter = 'THIN_DISC'``, Page-Thorne flux / (1 + z)^4 in the colour of the
  observed blackbody temperature), at Luminet's inclination of 84.5 degrees (its axis tilted by 5.5
  degrees towards the camera: the observer is 5.5 degrees above the disc's plane).
* The sphere: the paper's (seed 000, section 4.2) sphere of radius 0.5 r_s (36 x 18 UV sphere, orange
  and blue emission checker) on the last stable orbit r = 3 r_s, one orbit in 360 frames, in an orbit
  plane tilted by 60 degrees from the world's xy plane about x, so it passes above and below the disc.
  Frame 1: up and to the right of the hole (its second-order image hugs the shadow's lower left).
* The sky: a procedural star field in the world (``_star_world``): two layers of Voronoi stars on the
  view direction (their Vector inputs unlinked: the default coordinates of a world texture are the
  view direction, which grlens' lensed world replaces by the escape direction of the camera ray), a
  sparse bright one and a dense faint one, each star a smooth spot of about 0.3 and 0.2 degrees
  (feature points near the unit sphere), brightness from the cell's random colour (most stars faint,
  a few bright), a faint warm or cool tint; plus a very faint bluish glow (a Noise texture). The
  world is lensed (``scene.grlens.lens_world``, on by default): black in the shadow, the stars
  behind the hole pulled into arcs and rings around it (the Einstein ring), and the sky's
  higher-order images squeezed at the shadow's edge. The world's importance map is off (the only
  lights are emissive; the map would be a fixed cost per frame).
"""
import math

import bpy

from sample_scenes import luminet as _luminet

R_S = 1.0  # BU
R_OBS = 20.0  # r_s
INCLINATION = 84.5  # degrees between the disc's axis and the line of sight (Luminet's)
SPHERE_ORBIT = 3.0  # r_s
SPHERE_RADIUS = 0.5  # r_s
ORBIT_TILT = 60.0  # degrees, the sphere's orbit plane about x
EXPOSURE = 0.34  # disc_exposure (as the luminet scene)
NORMAL_FOV = 50.0  # degrees, vertical, of the normal view (640 x 360: 79 degrees across)
VIEWS = ("normal", "dome", "panorama")

CAMERA_NAMES = {"normal": "CamNormal", "dome": "CamDome", "panorama": "CamPanorama"}

STAR_LAYERS = (  # (Voronoi scale, star radius in radians, brightest star, faintest star)
    (30.0, 5.0e-3, 6.0, 0.15),
    (70.0, 3.0e-3, 0.9, 0.06),
)
"""Voronoi F1 on the unit view direction: a feature point within the star radius of the unit sphere
makes a star (so each layer has about 8 pi scale^3 radius stars on the whole sky: 2700 bright, 26000
faint), its brightness falls smoothly to 0 at the radius; per cell, the brightness is
faintest + (brightest - faintest) u^6 with u uniform (the Voronoi cell colour), so most stars are faint."""


def _node(nt, kind, **inputs):
    node = nt.nodes.new(kind)
    for key, value in inputs.items():
        node.inputs[key].default_value = value
    return node


def _math(nt, op, a, b=None, clamp=False):
    node = nt.nodes.new("ShaderNodeMath")
    node.operation = op
    node.use_clamp = clamp
    for i, v in enumerate((a, b)):
        if v is None:
            continue
        if isinstance(v, bpy.types.NodeSocket):
            nt.links.new(v, node.inputs[i])
        else:
            node.inputs[i].default_value = v
    return node.outputs[0]


def _socket(sockets, identifier):
    return next(s for s in sockets if s.identifier == identifier)


def _mix_colour(nt, fac, a, b):
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    nt.links.new(fac, _socket(mix.inputs, "Factor_Float"))
    for ident, v in (("A_Color", a), ("B_Color", b)):
        if isinstance(v, bpy.types.NodeSocket):
            nt.links.new(v, _socket(mix.inputs, ident))
        else:
            _socket(mix.inputs, ident).default_value = (*v, 1.0)
    return _socket(mix.outputs, "Result_Color")


def _star_layer(nt, scale, radius, brightest, faintest):
    """Colour output of one layer of stars (see STAR_LAYERS)."""
    vor = nt.nodes.new("ShaderNodeTexVoronoi")  # Vector unlinked: the view direction (lensed by grlens)
    vor.voronoi_dimensions = "3D"
    vor.feature = "F1"
    vor.distance = "EUCLIDEAN"
    vor.inputs["Scale"].default_value = scale
    vor.inputs["Randomness"].default_value = 1.0
    # spot: 1 at the feature point, 0 at ``radius`` (in cell units: radius * scale), smooth
    spot = nt.nodes.new("ShaderNodeMapRange")
    spot.interpolation_type = "SMOOTHSTEP"
    nt.links.new(vor.outputs["Distance"], spot.inputs["Value"])
    spot.inputs["From Min"].default_value = radius * scale
    spot.inputs["From Max"].default_value = 0.0
    rnd = nt.nodes.new("ShaderNodeSeparateColor")
    nt.links.new(vor.outputs["Color"], rnd.inputs["Color"])
    u6 = _math(nt, "POWER", rnd.outputs["Red"], 6.0)
    bright = _math(nt, "MULTIPLY_ADD", u6, brightest - faintest)
    bright.node.inputs[2].default_value = faintest
    value = _math(nt, "MULTIPLY", spot.outputs["Result"], bright)
    tint = _mix_colour(nt, rnd.outputs["Green"], (1.0, 0.78, 0.55), (0.72, 0.84, 1.0))
    white = _mix_colour(nt, rnd.outputs["Blue"], tint, (1.0, 1.0, 1.0))  # some stars whiter than others
    out = nt.nodes.new("ShaderNodeVectorMath")
    out.operation = "SCALE"
    nt.links.new(white, out.inputs[0])
    nt.links.new(value, _socket(out.inputs, "Scale"))
    return out.outputs["Vector"]


def _star_world(scene):
    """A new world with the procedural star field (see the module's docstring) for ``scene``."""
    world = bpy.data.worlds.new("Starfield")
    world.color = (0.0, 0.0, 0.0)
    if bpy.app.version < (5, 0, 0):  # 5.0: always nodes, use_nodes deprecated
        world.use_nodes = True
    nt = world.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputWorld")
    bg = nt.nodes.new("ShaderNodeBackground")
    bg.inputs["Strength"].default_value = 1.0
    total = None
    for layer in STAR_LAYERS:
        sock = _star_layer(nt, *layer)
        if total is None:
            total = sock
        else:
            add = nt.nodes.new("ShaderNodeVectorMath")
            add.operation = "ADD"
            nt.links.new(total, add.inputs[0])
            nt.links.new(sock, add.inputs[1])
            total = add.outputs["Vector"]
    glow = nt.nodes.new("ShaderNodeTexNoise")  # Vector unlinked: lensed as well
    glow.inputs["Scale"].default_value = 1.5
    glow.inputs["Detail"].default_value = 6.0
    haze = _math(nt, "POWER", glow.outputs["Fac"], 4.0)
    haze_col = nt.nodes.new("ShaderNodeVectorMath")
    haze_col.operation = "SCALE"
    haze_col.inputs[0].default_value = (0.05, 0.06, 0.12)
    nt.links.new(haze, _socket(haze_col.inputs, "Scale"))
    add = nt.nodes.new("ShaderNodeVectorMath")
    add.operation = "ADD"
    nt.links.new(total, add.inputs[0])
    nt.links.new(haze_col.outputs["Vector"], add.inputs[1])
    nt.links.new(add.outputs["Vector"], bg.inputs["Color"])
    nt.links.new(bg.outputs["Background"], out.inputs["Surface"])
    if hasattr(world, "cycles") and hasattr(world.cycles, "sampling_method"):
        world.cycles.sampling_method = "NONE"  # emissive scene: no importance map (a fixed cost per frame)
    scene.world = world
    return world


def _sphere(scene):
    """The paper's sphere on its orbit (as bpy.ops.grlens.demo_scene builds it, r_s = 1 BU), the orbit
    plane tilted by ORBIT_TILT about x."""
    import bmesh

    from sample_scenes.scenes import _emission_checker, _linear_keys

    tilt = bpy.data.objects.new("OrbitTilt", None)
    tilt.rotation_euler = (math.radians(ORBIT_TILT), 0.0, 0.0)
    scene.collection.objects.link(tilt)
    orbit = bpy.data.objects.new("Orbit", None)
    orbit.parent = tilt
    scene.collection.objects.link(orbit)
    mesh = bpy.data.meshes.new("OrbitingSphere")
    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    bmesh.ops.create_uvsphere(bm, u_segments=36, v_segments=18, radius=SPHERE_RADIUS * R_S, calc_uvs=True)
    bm.to_mesh(mesh)
    bm.free()
    mesh.materials.append(_emission_checker("SphereChecker", (0.9, 0.35, 0.03), (0.03, 0.2, 0.9), 8.0))
    sphere = bpy.data.objects.new("OrbitingSphere", mesh)
    sphere.parent = orbit
    sphere.location = (0.0, SPHERE_ORBIT * R_S, 0.01 * R_S)  # poles off the camera-hole axis
    scene.collection.objects.link(sphere)
    orbit.keyframe_insert("rotation_euler", index=2, frame=1)
    orbit.rotation_euler = (0.0, 0.0, 2 * math.pi)
    orbit.keyframe_insert("rotation_euler", index=2, frame=361)
    _linear_keys(orbit)
    return sphere


def _cameras(scene):
    """The three cameras at the observer's place, looking at the hole: {view: camera object}."""
    cams = {}
    for view in VIEWS:
        data = bpy.data.cameras.new(CAMERA_NAMES[view])
        data.clip_start, data.clip_end = 0.05, 1.0e4  # image meshes sit at c dt, up to a few 10 r_s
        if view == "normal":
            data.type = "PERSP"
            data.sensor_fit = "VERTICAL"
            data.angle_y = math.radians(NORMAL_FOV)
        else:
            data.type = "PANO"
            if view == "dome":  # 180-degree fisheye dome master (square frame)
                data.panorama_type = "FISHEYE_EQUIDISTANT"
                data.fisheye_fov = math.pi
            else:  # full equirectangular panorama (2:1 frame)
                data.panorama_type = "EQUIRECTANGULAR"
                data.latitude_min, data.latitude_max = -math.pi / 2, math.pi / 2
                data.longitude_min, data.longitude_max = -math.pi, math.pi
        cam = bpy.data.objects.new(CAMERA_NAMES[view], data)
        cam.location = (R_OBS * R_S, 0.0, 0.0)
        cam.rotation_euler = (math.radians(90.0), 0.0, math.radians(90.0))  # along -x at the hole, +z up
        scene.collection.objects.link(cam)
        cams[view] = cam
    return cams


def starfield(scene, view="normal"):
    """Build the star-field scene into ``scene`` with the ``view`` camera ('normal', 'dome' or
    'panorama') active (the other two are in the scene too). Returns the scene."""
    if view not in VIEWS:
        raise ValueError(f"view must be one of {VIEWS}")
    hole = bpy.data.objects.new("BlackHole", None)
    hole.empty_display_type = "SPHERE"
    hole.empty_display_size = R_S
    scene.collection.objects.link(hole)
    disc = bpy.data.objects.new("ThinDisc", _luminet._annulus("ThinDisc", _luminet.R_IN * R_S,
                                                               _luminet.R_OUT * R_S))
    scene.collection.objects.link(disc)
    disc.data.materials.append(_luminet._disc_material())
    disc.rotation_euler = (0.0, math.radians(90.0 - INCLINATION), 0.0)  # axis tilted towards the camera (+x)
    sphere = _sphere(scene)
    cams = _cameras(scene)
    scene.camera = cams[view]
    _star_world(scene)
    scene.view_settings.view_transform = "Standard"  # the disc's flux and the stars as they are
    scene.frame_start, scene.frame_end = 1, 360
    scene.frame_set(1)
    g = scene.grlens
    g.auto_update = False
    g.black_hole, g.r_s = hole, R_S
    g.lut_mode = "FIXED_RANGE"  # a static observer: one table for r = 1.05 .. 16 r_s
    g.lut_r_min, g.lut_r_max = 1.05, _luminet.R_OUT + 1.0
    g.max_tess_level, g.tess_a, g.tess_b = 64, 5.0, 0.75
    g.lens_world = True  # the default; stated here because the scene is about it
    disc.grlens.enabled = True
    disc.grlens.emitter = "THIN_DISC"
    disc.grlens.disc_mode = "BLACKBODY"
    disc.grlens.disc_r_in = _luminet.R_IN
    disc.grlens.disc_exposure = EXPOSURE
    sphere.grlens.enabled = True
    g.auto_update = True
    bpy.ops.grlens.rebuild()
    return scene
