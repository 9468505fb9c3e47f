"""Operators of physical time: two put the observer camera on a timelike geodesic of the black hole
through its position, keyed every frame in Schwarzschild coordinate time (core.camera_geodesics),
looking at the hole or along its motion: ``bpy.ops.grlens.camera_fall()`` a radial free fall (from
rest at a chosen radius or at infinity), ``bpy.ops.grlens.camera_orbit()`` a circular orbit (a
warning inside the innermost stable one); ``bpy.ops.grlens.camera_geodesic()`` is either, by its
``path`` (the first form, kept for scripts); ``bpy.ops.grlens.set_speed_of_light()`` chooses the speed of light from the light
crossing time r_s/c in frames, or from the hole's size (or mass) and the frame rate.

Units: scene units (BU); r_s = ``scene.grlens.r_s``; frames measure coordinate time with
``scene.grlens.speed_of_light`` (BU per frame, > 0): one frame is c / r_s in units of r_s/c.
Keys are linear between frames; the rebuild reads the camera's velocity back from them
(blender/motion.py: a central difference, whose error is about (angle swept per frame)^2 / 6
relative for an orbit).
"""
import math

import bpy
import numpy as np
from mathutils import Vector

from ..core import camera_geodesics
from . import motion



class GRLENS_OT_camera_geodesic(bpy.types.Operator):
    """Put the observer camera on a geodesic of the black hole through its position, keyed every frame
    in coordinate time (needs a speed of light): a radial free fall or a circular orbit (the panel
    offers the two as Camera Falls and Camera Orbits)"""

    bl_idname = "grlens.camera_geodesic"
    bl_label = "Camera on a Geodesic"
    bl_options = {"REGISTER", "UNDO"}

    path: bpy.props.EnumProperty(
        name="Path", default="ORBIT",
        items=[("ORBIT", "Circular Orbit", "A circular orbit at the camera's distance (unstable inside 3 r_s, "
                                           "impossible inside 1.5 r_s)"),
               ("FALL", "Radial Fall", "A free fall straight towards the hole, from rest at the release radius")])
    release_radius: bpy.props.FloatProperty(
        name="Released at (r_s)", default=0.0, min=0.0,
        description="Fall only: the radius (units of r_s) where the camera was at rest, at least its distance "
                    "now; 0: at rest at infinity (it passes at the escape speed)")
    axis: bpy.props.FloatVectorProperty(
        name="Orbit Axis", default=(0.0, 0.0, 1.0), size=3,
        description="Orbit only: the camera turns counter-clockwise about this world direction (its part across "
                    "the line from the hole to the camera)")
    look: bpy.props.EnumProperty(
        name="Look", default="HOLE",
        items=[("HOLE", "At the Hole", "The camera looks at the hole, its up axis towards world +Z"),
               ("MOTION", "Along the Motion", "The camera looks where it goes, its up axis towards world +Z")])
    frame_start: bpy.props.IntProperty(name="First Frame", default=-1,
                                       description="Where the path starts at the camera's position; -1: the "
                                                   "scene's first frame")
    frame_end: bpy.props.IntProperty(name="Last Frame", default=-1,
                                     description="The last frame keyed; -1: the scene's last frame")

    def execute(self, context):
        return _run(self, context, self.path, self.release_radius, self.axis)


_LOOK_ITEMS = [("HOLE", "At the Hole", "The camera looks at the hole, its up axis towards world +Z"),
               ("MOTION", "Along the Motion", "The camera looks where it goes, its up axis towards world +Z")]


def _run(op, context, path, release_radius=0.0, axis=(0.0, 0.0, 1.0)):
    """Key the camera (key_geodesic) for an operator and report: the path's figures, its warning, or
    why not (CANCELLED)."""
    try:
        n, note = key_geodesic(context.scene, path, release_radius, tuple(axis), op.look, op.frame_start,
                               op.frame_end)
    except ValueError as exc:
        op.report({"ERROR"}, f"grlens: {exc}")
        return {"CANCELLED"}
    op.report({"WARNING"} if note.startswith("warning") else {"INFO"}, f"keyed {n} frames; {note}")
    return {"FINISHED"}


class GRLENS_OT_camera_fall(bpy.types.Operator):
    """Put the observer camera on a radial free fall towards the hole through its position, from rest at
    a chosen radius or at infinity, keyed every frame in coordinate time (needs a speed of light)"""

    bl_idname = "grlens.camera_fall"
    bl_label = "Camera Falls"
    bl_options = {"REGISTER", "UNDO"}

    release_radius: bpy.props.FloatProperty(
        name="Released at (r_s)", default=0.0, min=0.0,
        description="The radius (units of r_s) where the camera was at rest, at least its distance now; 0: at "
                    "rest at infinity (it passes at the escape speed)")
    look: bpy.props.EnumProperty(name="Look", default="HOLE", items=_LOOK_ITEMS)
    frame_start: bpy.props.IntProperty(name="First Frame", default=-1,
                                       description="Where the fall passes the camera's position; -1: the scene's "
                                                   "first frame")
    frame_end: bpy.props.IntProperty(name="Last Frame", default=-1,
                                     description="The last frame keyed (fewer if the camera reaches the innermost "
                                                 "radius imaged first); -1: the scene's last frame")

    def execute(self, context):
        return _run(self, context, "FALL", release_radius=self.release_radius)


class GRLENS_OT_camera_orbit(bpy.types.Operator):
    """Put the observer camera on the circular orbit at its distance from the hole, keyed every frame in
    coordinate time (needs a speed of light); inside 3 r_s (the innermost stable orbit) it warns"""

    bl_idname = "grlens.camera_orbit"
    bl_label = "Camera Orbits"
    bl_options = {"REGISTER", "UNDO"}

    axis: bpy.props.FloatVectorProperty(
        name="Orbit Axis", default=(0.0, 0.0, 1.0), size=3,
        description="The camera turns counter-clockwise about this world direction (its part across the line "
                    "from the hole to the camera)")
    look: bpy.props.EnumProperty(name="Look", default="HOLE", items=_LOOK_ITEMS)
    frame_start: bpy.props.IntProperty(name="First Frame", default=-1,
                                       description="Where the orbit starts at the camera's position; -1: the "
                                                   "scene's first frame")
    frame_end: bpy.props.IntProperty(name="Last Frame", default=-1,
                                     description="The last frame keyed; -1: the scene's last frame")

    def execute(self, context):
        return _run(self, context, "ORBIT", axis=self.axis)


def key_geodesic(scene, path, release_radius=0.0, axis=(0.0, 0.0, 1.0), look="HOLE", frame_start=-1,
                 frame_end=-1):
    """Key the observer camera of ``scene`` on the geodesic (see the operator); returns (frames keyed,
    a note: the path's figures, or a warning starting with "warning"). Raises ValueError with a
    message for what cannot be done."""
    from .rebuild import observer_camera

    g = scene.grlens
    cam = observer_camera(scene)
    if cam is None or cam.type != "CAMERA":
        raise ValueError("the scene has no observer camera")
    if g.black_hole is None:
        raise ValueError("no black hole object is set (scene.grlens.black_hole)")
    if not (g.speed_of_light > 0 and math.isfinite(g.speed_of_light)):
        raise ValueError("set scene.grlens.speed_of_light first (scene units per frame): the path is keyed in "
                         "coordinate time")
    if not (g.r_s > 0 and math.isfinite(g.r_s)):
        raise ValueError(f"the Schwarzschild radius must be a positive length (r_s = {g.r_s:g})")
    if cam.parent is not None:
        raise ValueError(f"the camera '{cam.name}' has a parent: unparent it first (its keys are world positions)")
    f0 = scene.frame_start if frame_start < 0 else frame_start
    f1 = scene.frame_end if frame_end < 0 else frame_end
    if f1 < f0:
        raise ValueError(f"the last frame ({f1}) is before the first ({f0})")
    hole = np.array(g.black_hole.matrix_world.translation, dtype=np.float64)
    start = np.array(cam.location, dtype=np.float64) + np.array(cam.delta_location, dtype=np.float64)  # (no parent)
    r_s, c = float(g.r_s), float(g.speed_of_light)
    r0 = float(np.linalg.norm(start - hole)) / r_s
    frames = np.arange(f0, f1 + 1)
    t = (frames - f0) * c / r_s  # coordinate time, r_s / c
    note = ""
    if path == "ORBIT":
        p = camera_geodesics.orbit_path(t, start, hole, r_s, np.array(axis, dtype=np.float64))
        period = 2.0 * math.pi * math.sqrt(2.0 * r0 ** 3) * r_s / c
        note = f"circular orbit at r = {r0:.4g} r_s, one turn in {period:.4g} frames"
        if not p.stable:
            note = (f"warning: the orbit at r = {r0:.4g} r_s is inside the innermost stable one (3 r_s): a real "
                    f"camera there falls or escapes at the slightest push; {note}")
    elif path == "FALL":
        release = math.inf if release_radius == 0 else float(release_radius)
        if release < r0 * (1.0 - 1e-9):
            raise ValueError(f"the release radius ({release:.4g} r_s) is inside the camera's distance ({r0:.4g} r_s)")
        from lutgen.rays import R_OBS_MIN  # the innermost camera grlens images for

        p = camera_geodesics.fall_path(t, start, hole, r_s, max(release, r0))
        outside = np.flatnonzero(p.r >= R_OBS_MIN)
        n_out = int(outside[-1]) + 1 if outside.size else 0
        note = ("radial fall from rest " + ("at infinity" if math.isinf(release) else f"at {release:.4g} r_s")
                + f", from {r0:.4g} r_s to {p.r[max(n_out - 1, 0)]:.6g} r_s")
        if n_out < len(frames):
            note += (f"; it comes within {R_OBS_MIN} r_s of the hole's centre after frame "
                     f"{frames[n_out - 1] if n_out else f0}: keyed up to there")
        frames, p = frames[:n_out], camera_geodesics.Path(p.position[:n_out], p.velocity[:n_out], p.r[:n_out])
    else:
        raise ValueError(f"unknown path {path!r} (ORBIT or FALL)")
    if not len(frames):
        raise ValueError("no frame to key: the camera is too close to the horizon")
    _key(cam, frames, p, hole, look)
    return len(frames), note


def _key(cam, frames, p, hole, look):
    """Replace the camera's location and rotation keys by ``p`` at ``frames`` (linear between them)."""
    ad = cam.animation_data
    if ad is not None and ad.action is not None:
        curves = motion._fcurves(cam)
        for fc in [fc for fc in curves if fc.data_path in ("location", "rotation_euler", "rotation_quaternion",
                                                           "rotation_axis_angle")]:
            curves.remove(fc)
    cam.rotation_mode = "QUATERNION"
    delta = Vector(cam.delta_location)
    prev = None
    for f, pos, vel in zip(frames, p.position, p.velocity):
        towards = Vector(hole - pos) if look == "HOLE" else Vector(vel)
        if towards.length == 0:  # (a fall's first frame from rest: look at the hole)
            towards = Vector(hole - pos)
        q = towards.to_track_quat("-Z", "Y")
        if prev is not None and q.dot(prev) < 0:  # the same turn, not the way round
            q.negate()
        prev = q
        cam.location = Vector(pos) - delta
        cam.rotation_quaternion = q
        cam.keyframe_insert("location", frame=int(f))
        cam.keyframe_insert("rotation_quaternion", frame=int(f))
    for fc in motion._fcurves(cam):
        if fc.data_path in ("location", "rotation_quaternion"):
            for kp in fc.keyframe_points:
                kp.interpolation = "LINEAR"


R_S_SUN_KM = 2.0 * 6.6743e-11 * 1.98841e30 / 299792458.0 ** 2 / 1e3
"""Schwarzschild radius of one solar mass, km (2 G M_sun / c^2 = 2.953 km)."""

C_KM_S = 299792.458
"""The speed of light, km/s."""


def frames_per_crossing(mode, frames=10.0, r_s_km=0.0, mass=0.0, fps=24.0, slow_motion=1.0) -> float:
    """The light crossing time r_s/c in frames: ``frames`` itself (mode "FRAMES"), or (mode
    "PHYSICAL") r_s / c in seconds for a hole of Schwarzschild radius ``r_s_km`` (km; 0: from ``mass``
    in solar masses, r_s = 2.953 km per solar mass) times the frame rate ``fps``, times ``slow_motion``
    (seconds of the film per second of the hole's time). Raises ValueError for what is not positive."""
    if mode == "FRAMES":
        n = float(frames)
    elif mode == "PHYSICAL":
        km = float(r_s_km) if r_s_km > 0 else float(mass) * R_S_SUN_KM
        n = km / C_KM_S * float(fps) * float(slow_motion)
    else:
        raise ValueError(f"unknown mode {mode!r} (FRAMES or PHYSICAL)")
    if not (math.isfinite(n) and n > 0):
        raise ValueError("the light crossing time must be positive: give frames, or a size or mass, a frame rate "
                         "and a slow-motion factor above 0")
    return n


class GRLENS_OT_set_speed_of_light(bpy.types.Operator):
    """Set the speed of light (scene units per frame) from the light crossing time r_s/c in frames, or
    from the hole's size or mass and the scene's frame rate"""

    bl_idname = "grlens.set_speed_of_light"
    bl_label = "Set Speed of Light"
    bl_options = {"REGISTER", "UNDO"}

    mode: bpy.props.EnumProperty(
        name="From", default="FRAMES",
        items=[("FRAMES", "Crossing Time", "Light crosses r_s in this many frames"),
               ("PHYSICAL", "Size and Frame Rate", "A real hole of this size or mass, filmed at the scene's "
                                                  "frame rate (slowed down by the slow-motion factor)")])
    frames: bpy.props.FloatProperty(name="r_s/c (frames)", default=10.0, min=1e-6,
                                    description="Frames light takes to cross one Schwarzschild radius")
    r_s_km: bpy.props.FloatProperty(name="r_s (km)", default=0.0, min=0.0,
                                    description="The hole's Schwarzschild radius in km (0: from its mass)")
    mass: bpy.props.FloatProperty(name="Mass (suns)", default=10.0, min=0.0,
                                  description="The hole's mass in solar masses (r_s = 2.953 km each)")
    slow_motion: bpy.props.FloatProperty(name="Slow Motion", default=1.0, min=1e-12,
                                         description="Seconds of film per second of the hole's coordinate time")

    def execute(self, context):
        scene = context.scene
        fps = scene.render.fps / scene.render.fps_base
        try:
            n = frames_per_crossing(self.mode, self.frames, self.r_s_km, self.mass, fps, self.slow_motion)
        except ValueError as exc:
            self.report({"ERROR"}, f"grlens: {exc}")
            return {"CANCELLED"}
        scene.grlens.speed_of_light = scene.grlens.r_s / n
        self.report({"INFO"}, f"speed of light {scene.grlens.speed_of_light:.6g} scene units per frame "
                              f"(r_s/c = {n:.6g} frames)")
        return {"FINISHED"}


CLASSES = (GRLENS_OT_camera_geodesic, GRLENS_OT_camera_fall, GRLENS_OT_camera_orbit, GRLENS_OT_set_speed_of_light)
