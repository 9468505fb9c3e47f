"""Build sample scenes (sample_scenes.scenes) in a fresh bpy process and print their grlens image meshes
as JSON, one line per (scene, frame): ``SCENE_STATS {...}``.

Usage: python scene_stats.py WxH SCENE[:FRAME[,FRAME...]] [SCENE[:FRAMES] ...]

For each image object: order, vertex and triangle counts, world bounding box, light-travel-time
range, and the vertices' positions in the observer camera's normalised view (x, y in [0, 1] across the
frame, as bpy_extras.object_utils.world_to_camera_view) summarised as bounding box and mean; the same
view coordinates for the sources' own vertices (``sources``) and the hole's centre (``hole_view``).
"""
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", ".."))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import grlens_addon  # noqa: E402
from sample_scenes.scenes import SCENES  # noqa: E402


def view_coords(scene, cam, points):
    """(N, 3) world points -> (N, 3) normalised camera view coordinates (x, y in [0, 1], z depth)."""
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    return np.array([tuple(world_to_camera_view(scene, cam, Vector(p))) for p in points]).reshape(-1, 3)


def world_vertices(obj):
    me = obj.data
    co = np.empty(3 * len(me.vertices), dtype=np.float32)
    me.vertices.foreach_get("co", co)
    mw = np.array(obj.matrix_world)
    return co.reshape(-1, 3).astype(np.float64) @ mw[:3, :3].T + mw[:3, 3]


def summary(scene, cam, pts, hole):
    """View-space summary of world points; ``depth_inner``/``depth_outer``: mean depth of the tenth of
    the points nearest to / farthest from the hole's direction (angle on the view sphere)."""
    if len(pts) == 0:
        return None
    v = view_coords(scene, cam, pts)
    loc = np.array(cam.matrix_world.translation)
    d = pts - loc
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    h = (hole - loc) / np.linalg.norm(hole - loc)
    ang = np.arccos(np.clip(d @ h, -1.0, 1.0))
    order = np.argsort(ang)
    k = max(1, len(pts) // 10)
    return {"min": v.min(axis=0).tolist(), "max": v.max(axis=0).tolist(), "mean": v.mean(axis=0).tolist(),
            "angle_deg": [float(np.degrees(ang.min())), float(np.degrees(ang.max()))],
            "depth_inner": float(v[order[:k], 2].mean()), "depth_outer": float(v[order[-k:], 2].mean()),
            "view": v[:, :2].tolist() if len(v) <= 64 else None}


def stats(scene):
    g = scene.grlens
    cam = g.observer or scene.camera
    hole = np.array(g.black_hole.matrix_world.translation)
    out = {"status": g.status, "images": {}, "sources": {},
           "hole_view": view_coords(scene, cam, [tuple(g.black_hole.matrix_world.translation)])[0].tolist()}
    for obj in scene.objects:
        if obj.type != "MESH":
            continue
        if obj.grlens.order in (1, 2):
            pts = world_vertices(obj)
            me = obj.data
            ltt = np.empty(len(me.vertices), dtype=np.float32)
            if len(ltt):
                me.attributes["light_travel_time"].data.foreach_get("value", ltt)
            out["images"][obj.name] = {
                "order": obj.grlens.order, "source": obj.grlens.source.name, "n_verts": len(me.vertices),
                "n_tris": len(me.polygons),
                "bbox": [pts.min(axis=0).tolist(), pts.max(axis=0).tolist()] if len(pts) else None,
                "ltt": [float(ltt.min()), float(ltt.max())] if len(ltt) else None,
                "view": summary(scene, cam, pts, hole),
                "irradiance": me.attributes.get("grlens_irradiance") is not None}
        elif obj.grlens.enabled or obj.name == "Triangle":
            dg = bpy.context.evaluated_depsgraph_get()
            ev = obj.evaluated_get(dg)
            me = ev.to_mesh()
            co = np.empty(3 * len(me.vertices), dtype=np.float32)
            me.vertices.foreach_get("co", co)
            mw = np.array(ev.matrix_world)
            pts = co.reshape(-1, 3).astype(np.float64) @ mw[:3, :3].T + mw[:3, 3]
            ev.to_mesh_clear()
            out["sources"][obj.name] = {"n_verts": len(pts), "enabled": obj.grlens.enabled,
                                        "view": summary(scene, cam, pts, hole)}
    return out


def main(args):
    grlens_addon.register()
    w, h = (int(v) for v in args[0].lower().split("x"))
    for spec in args[1:]:
        name, _, frames = spec.partition(":")
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
        scene = bpy.context.scene
        scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = w, h, 100
        SCENES[name](scene)
        for f in [int(x) for x in frames.split(",")] if frames else [scene.frame_start]:
            scene.frame_set(f)
            print("SCENE_STATS " + json.dumps({"scene": name, "frame": f, **stats(scene)}), flush=True)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:])
    sys.stdout.flush()
    os._exit(0)
