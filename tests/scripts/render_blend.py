"""Open a .blend with the grlens add-on registered, rebuild and render one frame (fresh process).

Usage: python render_blend.py FILE.blend ENGINE OUT.png WIDTHxHEIGHT
ENGINE: BLENDER_WORKBENCH or CYCLES. Prints ``GRLENS_STATUS <status>`` and one ``GRLENS_IMAGE <name>
<faces>`` line per image object. The .blend is opened read-only (never saved).
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", ".."))

import bpy  # noqa: E402

import grlens_addon  # noqa: E402


def main(path, engine, out, size):
    grlens_addon.register()
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    r = scene.render
    r.resolution_x, r.resolution_y = (int(v) for v in size.lower().split("x"))
    r.resolution_percentage = 100
    r.engine = engine
    if engine == "CYCLES":
        scene.cycles.device = "CPU"
        scene.cycles.samples = 4
    bpy.ops.grlens.rebuild()
    for obj in bpy.data.objects:
        if obj.grlens.order in (1, 2):
            print("GRLENS_IMAGE", obj.name, len(obj.data.polygons))
    r.filepath = out
    bpy.ops.render.render(write_still=True)
    print("GRLENS_STATUS", scene.grlens.status)


if __name__ == "__main__":
    main(*sys.argv[-4:])
    sys.stdout.flush()
    os._exit(0)  # the bpy module can hang or crash at exit after a GPU-engine render
