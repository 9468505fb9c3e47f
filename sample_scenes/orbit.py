"""A camera on the circular orbit at 6 r_s (physical time): the star field's scene (sample_scenes/
starfield.py: Luminet's thin disc from 3 to 15 r_s, the paper's sphere on its tilted 3 r_s orbit, a
procedural star field, the lensed world) seen from a camera that orbits the hole at 6 r_s, 30
degrees above the disc's plane at frame 0 and going the way the gas goes, looking at the hole.
Built with grlens' public scripting API only.

Units: r_s = 1 BU, the hole at the origin; the speed of light 0.5 BU per frame (r_s/c = 2 frames: one
orbit of the camera in 261 frames). The local static observer sees the camera move at
1 / sqrt(2 (6 - 1)) = 0.316 c, towards the right of the picture: the sky and the images are
aberrated towards that side, and the light from there is blue-shifted and brighter, from the left
red-shifted and dimmer. The disc's colours (the blackbody of the observed temperature) include the
camera's motion through their 1 + z; the sphere's checker goes through the node group
"grlens Shifted Colour". With ``physical=False`` the same frame is a still (speed of light 0): the
camera at rest at the same place.

The camera's orbit crosses the disc's plane a quarter of a turn after frame 1 (an orbit about the
hole always does, and 6 r_s lies on the disc): frames there are not meant to be rendered.
"""
import math

import bpy
from mathutils import Vector

from sample_scenes import starfield as _starfield

R_CAM = 6.0  # r_s
ELEVATION = 30.0  # degrees above the disc's plane at frame 0 (the top of the camera's orbit)
FRAMES_PER_CROSSING = 2.0  # r_s / c in frames
DISC_EXPOSURE = 0.12  # the disc fills much of the view from 6 r_s (the star field's is 0.34 from 20 r_s)
VIEWS = ("normal", "panorama")


def _shifted_checker(name, color_a, color_b, scale=8.0):
    """The sphere's emission checker with its colour through "grlens Shifted Colour"."""
    from sample_scenes.scenes import _new_material

    mat, nt, out = _new_material(name)
    tex = nt.nodes.new("ShaderNodeTexChecker")
    tex.inputs["Scale"].default_value = scale
    tex.inputs["Color1"].default_value = (*color_a, 1.0)
    tex.inputs["Color2"].default_value = (*color_b, 1.0)
    uv = nt.nodes.new("ShaderNodeTexCoord")
    nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
    from grlens_addon.blender import shading

    shift = nt.nodes.new("ShaderNodeGroup")
    shift.node_tree = shading.ensure_shift_node_group()
    nt.links.new(tex.outputs["Color"], shift.inputs["Color"])
    em = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(shift.outputs["Color"], em.inputs["Color"])
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    mat.diffuse_color = (*color_a, 1.0)
    return mat


def orbit(scene, view="normal", physical=True):
    """Build the scene into ``scene`` with the ``view`` camera ('normal' or 'panorama') active: the
    star field's scene, the camera moved to 6 r_s and keyed on the circular orbit
    (bpy.ops.grlens.camera_geodesic) when ``physical``. Returns the scene."""
    if view not in VIEWS:
        raise ValueError(f"view must be one of {VIEWS}")
    _starfield.starfield(scene, view)
    g = scene.grlens
    g.auto_update = False
    bpy.data.objects["ThinDisc"].grlens.disc_exposure = DISC_EXPOSURE
    sphere = bpy.data.objects["OrbitingSphere"]
    sphere.data.materials[0] = _shifted_checker("SphereCheckerShifted", (0.9, 0.35, 0.03), (0.03, 0.2, 0.9), 8.0)
    incl = math.radians(90.0 - _starfield.INCLINATION)  # the disc's axis, tilted towards +x about y
    axis = (math.sin(incl), 0.0, math.cos(incl))
    in_plane = (math.cos(incl), 0.0, -math.sin(incl))
    e = math.radians(ELEVATION)
    start = [R_CAM * _starfield.R_S * (math.cos(e) * p + math.sin(e) * a) for p, a in zip(in_plane, axis)]
    orbit_axis = [math.cos(e) * a - math.sin(e) * p for p, a in zip(in_plane, axis)]  # start is its top
    cam = scene.camera
    for c in bpy.data.objects:
        if c.type == "CAMERA":
            c.location = start
            c.data.clip_start = 0.01
    g.lut_mode = "EVERY_DISTANCE"
    if physical:
        bpy.ops.grlens.set_speed_of_light(mode="FRAMES", frames=FRAMES_PER_CROSSING)
        # keyed from frame 0, so that frame 1 is between keys (its velocity a central difference)
        bpy.ops.grlens.camera_geodesic(path="ORBIT", axis=orbit_axis, look="HOLE", frame_start=0, frame_end=361)
    else:  # at rest at the same place, looking at the hole
        cam.rotation_mode = "QUATERNION"
        cam.rotation_quaternion = Vector([-x for x in start]).to_track_quat("-Z", "Y")
    scene.frame_set(1)
    g.auto_update = True
    bpy.ops.grlens.rebuild()
    return scene
