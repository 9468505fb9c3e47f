"""Per-frame cost of the add-on's numeric core on the paper's sphere scene (seed 000, section 4.2).

Sphere of radius 0.5 r_s (36 segments x 18 rings, 1224 triangles) on the orbit r = 3 r_s, observer at
20 r_s, MaxTessLevel 64, a = 5, b = 0.75, vertical fov 19 deg at 640x360 (pixel cap); both orders.
Prints, per orbit angle (0 = between hole and camera, 180 = behind the hole), the time of
core.pipeline.build_images (map + subdivide + cull + attributes; no Blender upload) and the
triangle counts, with the add-on's default table (lutgen.LUTFamily's for 20 r_s). ``--compare-tables``
instead times each angle with the former fixed-range table (256x512 over [1.05, 40] r_s) and the
default one, alternated in one process (best of --repeat each), and prints their ratio.
Usage: ./dev python benchmarks/bench_frame.py [--repeat N] [--compare-tables]
"""
import argparse
import math
import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from grlens_addon.core import mapping, pipeline  # noqa: E402
from lutgen import LUTFamily, build_lut  # noqa: E402


def uv_sphere(segments=36, rings=18, radius=1.0):
    """Blender-style UV sphere as triangles (quads split), poles as triangle fans."""
    th = np.linspace(0, np.pi, rings + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    ring_pts = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    pts = np.vstack([[0, 0, 1], ring_pts, [0, 0, -1]]) * radius
    idx = lambda i, j: 1 + i * segments + (j % segments)  # noqa: E731
    tris = [(0, idx(0, j), idx(0, j + 1)) for j in range(segments)]
    for i in range(rings - 2):
        for j in range(segments):
            a, b, c, d = idx(i, j), idx(i, j + 1), idx(i + 1, j), idx(i + 1, j + 1)
            tris += [(a, c, d), (a, d, b)]
    south = len(pts) - 1
    tris += [(south, idx(rings - 2, j + 1), idx(rings - 2, j)) for j in range(segments)]
    return pts, np.array(tris)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--compare-tables", action="store_true", help="the former fixed-range table against the default")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    r_s = 1.0
    pts, tris = uv_sphere(radius=0.5)
    fixed = build_lut(20.0, 1.05, 40.0, 256, 512)
    lut = LUTFamily().at(20.0)
    scene = mapping.Scene([20.0, 0, 0], [0, 0, 0], r_s)
    settings = pipeline.Settings(max_tess_level=64, tess_a=5.0, tess_b=0.75, cull_ratio=8.0,
                                 pixel_angle=math.radians(19.0) / 360)
    # one untimed frame first: the process's one-time set-up (imports, cached templates and tables)
    # is not part of a frame
    pipeline.build_images(pipeline.SourceMesh(pts + np.array([3.0, 0.0, 0.01]), tris), scene, lut, settings)
    if args.compare_tables:
        pipeline.build_images(pipeline.SourceMesh(pts + np.array([3.0, 0.0, 0.01]), tris), scene, fixed, settings)
        print(f"{len(tris)} source triangles; both orders; best of {args.repeat} each, alternated")
        print("| angle [deg] | fixed-range table [ms] | default (family) table [ms] | ratio |")
        print("|---|---|---|---|")
    else:
        print(f"{len(tris)} source triangles; both orders; best of {args.repeat} (after one untimed frame)")
        print("| angle [deg] | time [ms] | order-1 triangles | order-2 triangles | culled |")
        print("|---|---|---|---|---|")
    for deg in (0, 30, 60, 90, 120, 150, 180):
        a = math.radians(deg)
        centre = np.array([3 * math.cos(a), 3 * math.sin(a), 0.01])
        src = pipeline.SourceMesh(pts + centre, tris)
        times = {"fixed": [], "default": []}
        for _ in range(args.repeat):
            for name, table in ((("fixed", fixed),) if args.compare_tables else ()) + (("default", lut),):
                t0 = time.perf_counter()
                out = pipeline.build_images(src, scene, table, settings)
                times[name].append(time.perf_counter() - t0)
        if args.compare_tables:
            f, d = min(times["fixed"]), min(times["default"])
            print(f"| {deg} | {1000 * f:.1f} | {1000 * d:.1f} | {d / f:.2f} |")
            continue
        culled = sum(m.report.total_culled() for m in out.values())
        print(f"| {deg} | {1000 * min(times['default']):.1f} | {len(out[1].tris)} | {len(out[2].tris)} | {culled} |")


if __name__ == "__main__":
    main()
