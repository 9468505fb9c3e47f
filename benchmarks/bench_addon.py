"""Per-frame cost of the add-on in Blender (bpy module, background): extract + map + subdivide +
cull + upload, and memory over a long animation.

Scenes (seed 000, section 4.2, built by ``bpy.ops.grlens.demo_scene``; r_s = 2 BU, camera at 20 r_s,
vertical fov 19 deg, MaxTessLevel 64, a = 5, b = 0.75, default tess_max_error):
* ``sphere``: the paper's sphere (36 x 18 UV sphere, 1224 triangles) over its 360-frame orbit;
* ``sphere100k``: the same orbit with a 320 x 160 UV sphere (101,760 triangles), every 10th frame;
* ``sphere, viewport preview``: the same orbit built as the viewport's automatic updates build it in
  the UI (``tess_max_error_viewport``, default 1 px; renders use the default ``tess_max_error``);
* ``memory``: the 1224-triangle orbit played for 1000 frames (frame_set, i.e. the persistent handler
  as during an animation render), resident memory and data-block counts sampled along the way.

Times are wall-clock per call of the rebuild (``grlens_addon.blender.rebuild.rebuild_scene``) after
the frame is set with auto-update off; "core" is the share spent in ``core.pipeline.build_images``.
Usage: ./dev python benchmarks/bench_addon.py [--resolution 640x360] [--skip-memory]
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import bpy  # noqa: E402

import grlens_addon  # noqa: E402
from grlens_addon.blender import rebuild  # noqa: E402
from grlens_addon.core import pipeline  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_dense import uv_sphere_mesh  # noqa: E402


def _rss_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _scene(resolution, segments=36, rings=18):
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.grlens.demo_scene(r_s=2.0)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = resolution
    if segments != 36:
        uv_sphere_mesh(bpy.data.objects["OrbitingSphere"].data, segments, rings)
    return scene


class _CoreTimer:
    """Wraps pipeline.build_images (as imported by the rebuild module) to add up its time."""

    def __init__(self):
        self.total = 0.0
        self._orig = rebuild.pipeline.build_images

    def __enter__(self):
        def timed(*a, **k):
            t0 = time.perf_counter()
            try:
                return self._orig(*a, **k)
            finally:
                self.total += time.perf_counter() - t0

        rebuild.pipeline.build_images = timed
        return self

    def __exit__(self, *exc):
        rebuild.pipeline.build_images = self._orig


def time_orbit(scene, frames, preview=False):
    scene.grlens.auto_update = False
    rows = []
    for f in frames:
        scene.frame_set(f)
        dg = bpy.context.evaluated_depsgraph_get()
        with _CoreTimer() as core:
            t0 = time.perf_counter()
            rep = rebuild.rebuild_scene(scene, dg, preview=preview)
            t = time.perf_counter() - t0
        n = rep["objects"].get("OrbitingSphere", {})
        tris = sum(v[1] for v in n.values()) if isinstance(n, dict) else 0
        rows.append((f, t, core.total, tris))
    return rows


def summarise(name, n_src, rows):
    t = np.array([r[1] for r in rows]) * 1e3
    c = np.array([r[2] for r in rows]) * 1e3
    tris = np.array([r[3] for r in rows])
    print(f"| {name} | {n_src} | {len(rows)} | {np.mean(t):.1f} | {np.median(t):.1f} | {np.percentile(t, 95):.1f} | "
          f"{t.max():.1f} | {np.mean(c):.1f} | {int(np.mean(tris))} | {tris.max()} |")
    return t


def memory(resolution, n_frames=1000):
    scene = _scene(resolution)
    scene.grlens.auto_update = True
    samples = []
    moved, last = 0, None
    for i in range(n_frames):
        scene.frame_set(1 + i % 360)
        img = bpy.data.objects["OrbitingSphere.GR1"].data
        first = tuple(img.vertices[0].co) if len(img.vertices) else None
        moved += first != last
        last = first
        if i in (9, 99, 249, 499, 749, n_frames - 1):
            samples.append((i + 1, _rss_mb(), len(bpy.data.meshes), len(bpy.data.objects),
                            len(bpy.data.materials)))
    print("\n| frames played | RSS [MB] | meshes | objects | materials |")
    print("|---|---|---|---|---|")
    for s in samples:
        print(f"| {s[0]} | {s[1]:.1f} | {s[2]} | {s[3]} | {s[4]} |")
    growth = samples[-1][1] - samples[1][1]
    print(f"\nRSS change from frame {samples[1][0]} to {samples[-1][0]}: {growth:+.1f} MB; data-blocks "
          f"{'unchanged' if samples[1][2:] == samples[-1][2:] else 'CHANGED'}; the image moved in {moved} of "
          f"{n_frames} frames (rebuilt by the frame handler)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", default="640x360")
    ap.add_argument("--skip-memory", action="store_true")
    args = ap.parse_args(argv)
    res = tuple(int(v) for v in args.resolution.lower().split("x"))
    grlens_addon.register()
    print(f"render resolution {res[0]}x{res[1]}; times in ms per frame (both orders, upload included)\n")
    print("| scene | source triangles | frames | mean | median | p95 | max | core mean | image triangles mean | max |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    scene = _scene(res)
    time_orbit(scene, [1])  # LUT build and first upload, not timed
    summarise("sphere", 1224, time_orbit(scene, range(1, 361)))
    # the same orbit as the viewport's automatic updates build it while scrubbing (UI only; renders
    # use the render tolerance above)
    time_orbit(scene, [1], preview=True)
    summarise(f"sphere, viewport preview ({scene.grlens.tess_max_error_viewport:g} px)", 1224,
              time_orbit(scene, range(1, 361), preview=True))
    scene = _scene(res, 320, 160)
    time_orbit(scene, [1])
    summarise("sphere100k", 320 * 158 * 2 + 2 * 320, time_orbit(scene, range(1, 361, 10)))
    if not args.skip_memory:
        memory(res)
    sys.stdout.flush()
    os._exit(0)  # bpy's interpreter exit is slow and not part of the benchmark


if __name__ == "__main__":
    main()
