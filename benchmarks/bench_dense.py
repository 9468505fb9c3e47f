"""Rebuild time of dense meshes in Blender (bpy module, background): a UV sphere of 16k, 200k and 1M
triangles beside the hole, rebuilt after each move.

Scene: ``bpy.ops.grlens.demo_scene`` (r_s = 2 BU, camera at 20 r_s, vertical fov 19 deg) at 1920x1080,
its orbiting sphere (radius 1 BU on the orbit r = 3 r_s) replaced by a UV sphere of the given size
(bmesh, with UVs; the image meshes carry UVs and shading normals). Frames 10, 20, ... of its orbit
(30-150 degrees: beside the hole), one rebuild each (``rebuild.rebuild_scene``, the render
tolerance, auto-update off), each frame a move. Printed per size: the median and best time of a
rebuild and its parts (gather: the evaluated mesh to a source; core: build_images; the rest: upload
and bookkeeping), the image triangles. ``--addon DIR``: import grlens_addon from another checkout
(e.g. ``git archive main | tar -x -C DIR``) to compare.

``--write``: the table into docs/performance.md (section "Dense meshes", between its markers).

Usage: ./dev python benchmarks/bench_dense.py [--sizes 16k,200k,1M] [--frames 10,20,30,40,50]
       [--addon DIR] [--write]
"""
import argparse
import os
import sys
import time

import numpy as np

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "docs", "performance.md")
BEGIN, END = "<!-- bench_dense: begin -->", "<!-- bench_dense: end -->"
SIZES = {"16k": (128, 64), "200k": (448, 224), "1M": (1200, 416)}
"""UV sphere segments x rings per size: closed meshes (some of bmesh's UV spheres of about a million
triangles have open edges next to their poles, e.g. 1000 x 500: an open mesh has no back faces culled)."""


def dense_scene(size, resolution=(1920, 1080)):
    """(scene, sphere, source triangles) in Blender (bpy module): ``bpy.ops.grlens.demo_scene`` (r_s = 2 BU)
    at ``resolution`` (pixels), auto-update off, its orbiting sphere's mesh replaced by the UV sphere of
    SIZES[size] (bmesh, radius 1 BU, with UVs). Shared by the dense-mesh benchmarks (bench_background,
    profile_dense)."""
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.grlens.demo_scene(r_s=2.0)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = resolution
    scene.grlens.auto_update = False
    sphere = bpy.data.objects["OrbitingSphere"]
    uv_sphere_mesh(sphere.data, *SIZES[size])
    return scene, sphere, sum(len(p.vertices) - 2 for p in sphere.data.polygons)


def uv_sphere_mesh(mesh, segments, rings):
    """Replace the Blender ``mesh``'s geometry by a UV sphere of radius 1 BU with ``segments`` x ``rings``
    (bmesh, UVs in the layer "UVMap")."""
    import bmesh

    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=1.0, calc_uvs=True)
    bm.to_mesh(mesh)
    bm.free()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="16k,200k,1M")
    ap.add_argument("--frames", default="10,20,30,40,50")
    ap.add_argument("--resolution", default="1920x1080")
    ap.add_argument("--addon", default=None, metavar="DIR", help="import grlens_addon from DIR")
    ap.add_argument("--write", action="store_true", help="write the table into docs/performance.md")
    args = ap.parse_args(argv)
    root = args.addon or os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    sys.path.insert(0, os.path.abspath(root))
    sys.path.insert(1, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))  # lutgen
    import bpy

    import grlens_addon  # noqa: F401
    from grlens_addon.blender import gather, rebuild

    if not hasattr(bpy.types.Scene, "grlens"):
        grlens_addon.register()
    w, h = (int(v) for v in args.resolution.lower().split("x"))
    frames = [int(f) for f in args.frames.split(",")]
    timers = {"core": 0.0, "gather": 0.0}

    def timed(name, fn):
        def wrapper(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                timers[name] += time.perf_counter() - t0
        return wrapper

    rebuild.pipeline.build_images = timed("core", rebuild.pipeline.build_images)
    gather.gather = timed("gather", gather.gather)
    rebuild.gather.gather = gather.gather
    print(f"grlens_addon from {os.path.abspath(root)}; {w}x{h}; frames {frames}")
    table = ["| source triangles | rebuild median / best [s] | gather [s] | core [s] | upload and the rest [s] | "
             "image triangles (order 1 / 2) |", "|---|---|---|---|---|---|"]
    print("\n".join(table))
    for size in args.sizes.split(","):
        scene, sphere, n_tris = dense_scene(size, (w, h))
        scene.frame_set(frames[0] - 1)
        rebuild.rebuild_scene(scene, bpy.context.evaluated_depsgraph_get())  # one untimed (tables, caches)
        rows = []
        for f in frames:
            scene.frame_set(f)
            timers["core"] = timers["gather"] = 0.0
            t0 = time.perf_counter()
            rebuild.rebuild_scene(scene, bpy.context.evaluated_depsgraph_get())
            total = time.perf_counter() - t0
            rows.append((total, timers["gather"], timers["core"]))
        rows = np.array(rows)
        med = np.median(rows, axis=0)
        tri = [len(o.data.polygons) for o in (bpy.data.objects.get("OrbitingSphere.GR1"),
                                              bpy.data.objects.get("OrbitingSphere.GR2")) if o is not None]
        table.append(f"| {n_tris:,} | {med[0]:.2f} / {rows[:, 0].min():.2f} | {med[1]:.2f} | {med[2]:.2f} | "
                     f"{med[0] - med[1] - med[2]:.2f} | {' / '.join(f'{t:,}' for t in tri)} |")
        print(table[-1], flush=True)
    if args.write:
        write(table, w, h, frames)


def write(table, w, h, frames):
    """The table between the markers of docs/performance.md, with where it came from."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from provenance import write_section

    write_section(OUT, BEGIN, END, "benchmarks/bench_dense.py", [
        f"{w}x{h}, frames {', '.join(map(str, frames))} (median and best of a rebuild after each move; the "
        "parts are medians, the rest is the median rebuild less the medians of the gather and the core):", "",
        *table])


if __name__ == "__main__":
    main()
    sys.stdout.flush()
    os._exit(0)
