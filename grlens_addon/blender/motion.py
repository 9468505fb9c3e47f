"""An object's velocity from its own animation, without changing the scene's frame.

Frame handlers must not call ``scene.frame_set`` (Blender's API documentation warns against altering
data from them), and the depsgraph is evaluated for the current frame only. So the object's world
matrix at a neighbouring time is rebuilt from its F-curves: each animated transform channel
(location, rotation in any mode, scale and their deltas) evaluated there, the others as they are,
composed as Blender composes them (matrix_basis = T(location + delta) R(delta rotation) R(rotation)
S(scale * delta scale)), and carried through its parents (parent_type OBJECT, with
``matrix_parent_inverse``). The rebuilt matrix at the current frame is checked against the evaluated
one (its translation, when the object itself has constraints that only turn it, such as Track To):
constraints that move it or its parents, drivers, NLA strips or other parent types make them differ,
and the velocity is then refused with a message saying why, not guessed.

Units: Blender units (BU) per frame; the central difference over +-``STEP`` frames about the
current frame and subframe, one-sided (second order) at the first and last keys, where the
F-curves hold their end values.
"""
from __future__ import annotations

import numpy as np
from mathutils import Euler, Matrix, Quaternion, Vector

STEP = 0.5
"""Half-width (frames) of the central difference: within the Bezier segments on either side of a key
on a whole frame; a path keyed every frame moves little enough in half a frame for an O(STEP^2)
error."""

MATCH = 1e-5
"""Largest difference (relative to the matrix's scale, and to 1 BU for its translation) between the
rebuilt and the evaluated world matrix at the current frame that is accepted."""

_CHANNELS = ("location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle", "scale",
             "delta_location", "delta_rotation_euler", "delta_rotation_quaternion", "delta_scale")


TURNING_CONSTRAINTS = ("TRACK_TO", "DAMPED_TRACK", "LOCKED_TRACK", "COPY_ROTATION", "LIMIT_ROTATION")
"""Constraints that only turn an object about its origin: they leave its velocity alone."""


class MotionError(Exception):
    """The object's velocity cannot be read from its animation (said why)."""


def _fcurves(obj):
    """The F-curves of the object's active action (its slot's, on Blender 4.4 and later), or ()."""
    ad = obj.animation_data
    if ad is None or ad.action is None:
        return ()
    slot = getattr(ad, "action_slot", None)
    if slot is not None:  # slotted actions (4.4+; the only API from 5.0)
        from bpy_extras import anim_utils

        bag = anim_utils.action_get_channelbag_for_slot(ad.action, slot)
        return () if bag is None else bag.fcurves
    return getattr(ad.action, "fcurves", ())


def _channels_at(obj, frame) -> dict:
    """The object's transform channels at ``frame`` (float): F-curve values where animated."""
    out = {name: list(getattr(obj, name)) for name in _CHANNELS}
    for fc in _fcurves(obj):
        if fc.data_path in out and not fc.mute and 0 <= fc.array_index < len(out[fc.data_path]):
            out[fc.data_path][fc.array_index] = fc.evaluate(frame)
    return out


def _rotation(mode, euler, quat, axis_angle) -> Matrix:
    if mode == "QUATERNION":
        return Quaternion(quat).normalized().to_matrix()
    if mode == "AXIS_ANGLE":
        return Matrix.Rotation(axis_angle[0], 3, Vector(axis_angle[1:]).normalized())
    return Euler(euler, mode).to_matrix()


def _basis(obj, frame) -> Matrix:
    """matrix_basis of ``obj`` at ``frame`` from its channels."""
    c = _channels_at(obj, frame)
    mode = obj.rotation_mode
    rot = _rotation(mode, c["rotation_euler"], c["rotation_quaternion"], c["rotation_axis_angle"])
    drot = Matrix.Identity(3) if mode == "AXIS_ANGLE" else _rotation(mode, c["delta_rotation_euler"],
                                                                      c["delta_rotation_quaternion"], None)
    scale = Vector(c["scale"]) * 1.0
    for i, d in enumerate(c["delta_scale"]):
        scale[i] *= d
    m = (drot @ rot).to_4x4() @ Matrix.Diagonal(scale.to_4d())
    m.translation = Vector(c["location"]) + Vector(c["delta_location"])
    return m


def world_matrix_at(obj, frame) -> Matrix:
    """The world matrix of ``obj`` at ``frame`` (float) rebuilt from its and its parents' F-curves."""
    m = _basis(obj, frame)
    while obj.parent is not None:
        if obj.parent_type != "OBJECT":
            raise MotionError(f"'{obj.name}' has a {obj.parent_type.lower()} parent")
        m = obj.matrix_parent_inverse @ m
        obj = obj.parent
        m = _basis(obj, frame) @ m
    return m


def velocity(scene, obj, obj_eval=None) -> np.ndarray:
    """(3,) world velocity (BU per frame) of ``obj``'s origin at the scene's current frame and subframe,
    from its own animation (central difference over +-STEP frames; zero for an object without
    animation). ``obj_eval``: its evaluated copy, whose world matrix the rebuilt one must match.
    Raises MotionError when the animation cannot be followed this way (constraints, drivers, NLA
    strips, a parent that is not an object)."""
    frame = scene.frame_current + scene.frame_subframe
    turned = False
    for o in _chain(obj):
        for con in o.constraints:
            if con.mute or (hasattr(con, "enabled") and not con.enabled):
                continue
            if o is obj and con.type in TURNING_CONSTRAINTS:
                turned = True
                continue
            raise MotionError(f"'{o.name}' has a {con.type.replace('_', ' ').lower()} constraint")
    now = world_matrix_at(obj, frame)
    actual = (obj_eval or obj).matrix_world
    tol = MATCH * max(1.0, max(abs(x) for row in actual for x in row))
    rows = range(3) if not turned else ()
    if (any(abs(now[i][3] - actual[i][3]) > tol for i in range(3))
            or any(abs(now[i][j] - actual[i][j]) > tol for i in rows for j in range(3))):
        raise MotionError(f"the motion of '{obj.name}' does not follow from its keyframes alone "
                          "(drivers, NLA strips or other animation)")
    lo, hi = _keyed_range(obj)
    at = [np.array(world_matrix_at(obj, frame + k * STEP).translation, dtype=np.float64) for k in (-2, -1, 1, 2)]
    if frame - STEP < lo <= frame + STEP < hi:  # the first key: held before it, so one-sided (second order)
        now_t = np.array(now.translation, dtype=np.float64)
        return (-3.0 * now_t + 4.0 * at[2] - at[3]) / (2.0 * STEP)
    if lo < frame - STEP <= hi < frame + STEP:  # the last key
        now_t = np.array(now.translation, dtype=np.float64)
        return (3.0 * now_t - 4.0 * at[1] + at[0]) / (2.0 * STEP)
    return (at[2] - at[1]) / (2.0 * STEP)


def _keyed_range(obj):
    """(first, last) frame over the keys of the transform F-curves of ``obj`` and its parents that hold
    their end values beyond their keys (constant extrapolation); (-inf, inf) without any."""
    lo, hi = -np.inf, np.inf
    for o in _chain(obj):
        for fc in _fcurves(o):
            if fc.data_path in _CHANNELS and fc.extrapolation == "CONSTANT" and len(fc.keyframe_points) > 1 \
                    and not fc.modifiers:
                a, b = fc.range()
                lo, hi = (a, b) if not np.isfinite(lo) else (min(lo, a), max(hi, b))
    return lo, hi


def _chain(obj):
    while obj is not None:
        yield obj
        obj = obj.parent
