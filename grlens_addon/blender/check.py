"""Check the current frame against the reference ray tracer (``bpy.ops.grlens.check_frame()``).

Renders the lensed sources of the scene twice at a fraction of the render resolution, with the exact
per-pixel ray tracer and with the polygon method the add-on uses (core.frame_check), compares them
and writes both renders' passes (light travel time, image order, object index, UV, the reference's
sky direction) and the mismatch to an OpenEXR file. When the scene's world is lensed
(``scene.grlens.lens_world``), the sky is checked too: the world's mapping
(``frame_check.lensed_world_sky``) against the reference's exact escape directions, with the
grlens sky direction and the sky error as passes. The observer camera may be perspective or one of
Cycles' panoramas equirectangular and fisheye equidistant (:func:`check_camera`). Geometry only:
materials, GR illumination and disc colours are not compared.
Units: Blender units; times in seconds; errors in pixels of the check's resolution.
"""
from __future__ import annotations

import os
import re

import bpy
import numpy as np

from ..core import frame_check, raytrace
from . import gather, lutcache, rebuild, world


PANORAMA_TYPES = ("EQUIRECTANGULAR", "FISHEYE_EQUIDISTANT")
"""Cycles' panorama types the check models (``cam.data.panorama_type``, Blender 4.x and 5.x)."""


def _at_bound(value, bound):
    """A camera angle (radians) read from a float32 property: +-``bound`` when it is that bound in
    float32 (Blender stores pi/2 as 1.5707963705..., just beyond pi/2, so a full panorama's range
    would read as out of range)."""
    v = float(value)
    return float(np.copysign(bound, v)) if abs(abs(v) - bound) <= 4e-7 * bound else v


def check_camera(scene, cam, percentage) -> raytrace.Camera:
    """The reference tracer's camera for the observer camera ``cam`` (evaluated) at ``percentage`` of
    the scene's render resolution; ValueError for what the tracer cannot model.

    Perspective cameras (sensor fit and aspect ratio from the camera's frame) and Cycles' panoramas
    of type equirectangular (``latitude_min/max``, ``longitude_min/max``) and fisheye equidistant
    (``fisheye_fov``), read from ``cam.data`` (where Blender 4.x and 5.x keep them) into
    ``raytrace.Camera`` kinds of the same names; Cycles' projection conventions (panoramas render
    in Cycles only). Orthographic cameras, the other panorama types, lens shift and non-square pixels
    are refused."""
    if cam.type != "CAMERA" or cam.data.type not in ("PERSP", "PANO"):
        raise ValueError("the check needs a perspective or panoramic (equirectangular, fisheye equidistant) "
                         "observer camera")
    data = cam.data
    if data.type == "PANO":
        ptype = getattr(data, "panorama_type", None)
        if ptype not in PANORAMA_TYPES:
            raise ValueError(f"the check models the panorama types equirectangular and fisheye equidistant, "
                             f"not {str(ptype).replace('_', ' ').lower()}")
    if data.shift_x or data.shift_y:
        raise ValueError("the check does not model lens shift (camera shift x/y must be 0)")
    r = scene.render
    if abs(r.pixel_aspect_x - r.pixel_aspect_y) > 1e-6 * max(r.pixel_aspect_x, r.pixel_aspect_y):
        raise ValueError("the check needs square pixels (pixel aspect x = y)")
    scale = r.resolution_percentage / 100.0 * percentage / 100.0
    width = max(1, round(r.resolution_x * scale))
    height = max(1, round(r.resolution_y * scale))
    position = np.array(cam.matrix_world.translation, dtype=np.float64)
    rotation = rebuild.camera_rotation(cam)
    if data.type == "PANO":
        half, full = 0.5 * np.pi, np.pi
        lens = dict(kind=data.panorama_type, fisheye_fov=_at_bound(data.fisheye_fov, 2.0 * full),
                    latitude_min=_at_bound(data.latitude_min, half),
                    latitude_max=_at_bound(data.latitude_max, half),
                    longitude_min=_at_bound(data.longitude_min, full),
                    longitude_max=_at_bound(data.longitude_max, full))
        return raytrace.Camera(position, rotation, 0.0, width, height, **lens)
    _, half_y = rebuild.half_tangents(scene, cam)
    return raytrace.Camera(position, rotation, 2.0 * np.arctan(half_y), width, height)


def output_path(filepath, frame) -> str:
    """``filepath`` with Blender's conventions: ``//`` relative to the .blend (to the temporary
    directory for an unsaved file) and a run of ``#`` replaced by the frame number, zero-padded."""
    if filepath.startswith("//") and not bpy.data.filepath:
        filepath = os.path.join(bpy.app.tempdir, filepath[2:])
    path = bpy.path.abspath(filepath)
    path = re.sub(r"#+", lambda m: f"{frame:0{len(m.group(0))}d}", path)
    return path


def check_scene(scene, depsgraph=None, percentage: int = 50, filepath: str = "") -> tuple:
    """(core.frame_check.FrameCheck, written path or "") for the current frame of ``scene``: its lensed
    sources (evaluated as the rebuild does), observer camera, hole and settings (render tolerance),
    at ``percentage`` of the render resolution. With ``filepath``, the passes are written there (see
    :func:`output_path`). Raises rebuild.RebuildError or ValueError with a message for the user."""
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    srcs = rebuild.sources(scene)
    if not srcs:
        raise rebuild.RebuildError("no object is marked for lensing (obj.grlens.enabled)")
    if not 1 <= percentage <= 100:
        raise ValueError(f"the check's resolution percentage must be 1-100, got {percentage}")
    geo, settings, cam = rebuild.scene_geometry(scene, depsgraph)
    camera = check_camera(scene, cam, percentage)
    g = scene.grlens
    lut = lutcache.get_table(g, geo.r_obs)
    src_dg = depsgraph.view_layer.depsgraph  # (the check runs from the viewport: its settings)
    found = gather.instances(srcs, src_dg, with_normals=False)
    meshes, names = [], []
    for s in srcs:  # as the rebuild gathers them; objects without faces are left out
        got = gather.gather(s, s.evaluated_get(src_dg), found.get(s.as_pointer()), with_normals=False)
        if got.mesh is not None and len(got.mesh.tris):
            meshes.append(got.mesh)
            names.append(s.name)
    if not meshes:
        raise rebuild.RebuildError("no marked object has faces")
    sky = None
    if world.wants_lensing(scene) and world.is_lensed(scene.world) and world.lensing_camera(scene) == cam.original:
        sky = frame_check.lensed_world_sky(geo.hole, geo.r_s, geo.beta)
    result = frame_check.check_frame(meshes, geo, lut, settings, camera, names=names, sky=sky)
    path = ""
    if filepath:
        path = output_path(filepath, scene.frame_current)
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        frame_check.write_passes(path, result)
    return result, path
