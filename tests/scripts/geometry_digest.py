"""Print a digest of the image meshes of the demo scene at a given frame (fresh process).

Usage: python geometry_digest.py FILE.blend FRAME (FILE is created with the demo scene if missing).
Used by tests/test_render.py to check that two processes loading the same file (as render farm nodes
do) build identical geometry for the same frame.
"""
import hashlib
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", ".."))

import bpy  # noqa: E402

import grlens_addon  # noqa: E402

grlens_addon.register()
path, frame = sys.argv[1], int(sys.argv[2])
if not os.path.exists(path):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.grlens.demo_scene(r_s=2.0)
    bpy.context.scene.render.resolution_x, bpy.context.scene.render.resolution_y = 320, 180
    bpy.ops.wm.save_as_mainfile(filepath=path)
    print("GRLENS_SAVED")
    sys.stdout.flush()
    os._exit(0)
bpy.ops.wm.open_mainfile(filepath=path)
scene = bpy.context.scene
scene.frame_set(frame)
h = hashlib.blake2b(digest_size=16)
for name in ("OrbitingSphere.GR1", "OrbitingSphere.GR2"):
    me = bpy.data.objects[name].data
    co = np.empty(3 * len(me.vertices), np.float32)
    me.vertices.foreach_get("co", co)
    ltt = np.empty(len(me.vertices), np.float32)
    me.attributes["light_travel_time"].data.foreach_get("value", ltt)
    idx = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get("vertex_index", idx)
    for a in (co, ltt, idx):
        h.update(a.tobytes())
    print(name, len(me.vertices), len(me.polygons),
          *(hashlib.md5(a.tobytes()).hexdigest()[:8] for a in (co, ltt, idx)))
print("GRLENS_DIGEST", h.hexdigest())
sys.stdout.flush()
os._exit(0)
