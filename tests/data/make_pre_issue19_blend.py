"""Write tests/data/pre_issue19.blend: the demo scene as saved by the add-on before issue 19.

Made with commit c406bd2de37fd5d0756c44c3ed05e7c4f991dc23 (the add-on before issue 19's items 3 and 4:
any object type marked, report lines). Do not regenerate: the file stands for .blend files users
saved with that version; tests/test_blend_compat.py opens, rebuilds and renders it with the current
add-on.

What it holds: ``bpy.ops.grlens.demo_scene(r_s=2.0)`` (r_s = 2 BU, camera at 20 r_s), render
resolution 160x90, one rebuild at frame 1 (images OrbitingSphere.GR1/.GR2 in the ``grlens``
collection), no packed LUT; saved compressed.

Usage (from the repository root, on that commit): ./dev python tests/data/make_pre_issue19_blend.py
"""
import os
import sys

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(here, "..", ".."))

import bpy  # noqa: E402

import grlens_addon  # noqa: E402


def main(path=os.path.join(here, "pre_issue19.blend")):
    grlens_addon.register()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    assert bpy.ops.grlens.demo_scene(r_s=2.0) == {"FINISHED"}
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 160, 90, 100
    scene.frame_set(1)
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    for name in ("OrbitingSphere.GR1", "OrbitingSphere.GR2"):
        assert len(bpy.data.objects[name].data.polygons) > 0, name
    from grlens_addon.blender import lutcache

    assert lutcache.STORE not in bpy.data.texts  # no packed LUT
    bpy.ops.wm.save_as_mainfile(filepath=path, compress=True)
    print("GRLENS_SAVED", path, os.path.getsize(path), "bytes;", scene.grlens.status)


if __name__ == "__main__":
    main()
    sys.stdout.flush()
    os._exit(0)  # the pip bpy module can hang at interpreter exit
