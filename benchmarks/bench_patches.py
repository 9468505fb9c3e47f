"""Axis patches next to the limb: clipped to the source triangles (budget.CLIP_TO_TRIANGLES, the
default) against the plain grid, on the accuracy benchmark's sphere scene (640x360).

For each orbit angle the two are timed alternately in one process (core.pipeline.build_images, both
orders; N rounds, so that the machine's drift hits both alike) and the image triangles are counted.
Prints min and median ms per frame of each and the ratio of the medians. Accuracy of the default is
in benchmarks/bench_accuracy.py (--angles ...), of both in tests/test_raytrace.py.
Usage: ./dev python benchmarks/bench_patches.py [--angles 170.5,171,...] [--rounds N]
"""
import argparse
import os
import sys
import time
import warnings

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import bench_accuracy as BA  # noqa: E402
from grlens_addon.core import budget, mapping, pipeline  # noqa: E402
from lutgen import build_lut  # noqa: E402

LIMB = "170.5,171,172,173,174,186,187,188,189,189.5"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--angles", default=LIMB)
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    cam = BA.camera(640, 360)
    lut = build_lut(BA.R_OBS, 1.05, 40.0, *BA.LUT_DEFAULT)
    settings = BA.make_settings(cam)
    planes = cam.frustum_planes()
    scene = mapping.Scene(cam.position, np.zeros(3), BA.R_S)
    default = budget.CLIP_TO_TRIANGLES
    print(f"sphere scene of bench_accuracy, 640x360; {args.rounds} alternating rounds per angle\n")
    print("| angle [deg] | clipped: min / median [ms] | plain: min / median [ms] | median ratio | "
          "clipped / plain image triangles |")
    print("|---|---|---|---|---|")
    try:
        for a in (float(v) for v in args.angles.split(",")):
            src, _ = BA.sphere_scene(a)
            times = {True: [], False: []}
            tris = {}
            for _ in range(args.rounds + 1):
                for clip in (True, False):
                    budget.CLIP_TO_TRIANGLES = clip
                    t0 = time.perf_counter()
                    out = pipeline.build_images(src, scene, lut, settings, frustum_planes=planes)
                    times[clip].append(time.perf_counter() - t0)
                    tris[clip] = sum(len(m.tris) for m in out.values())
            c, p = (np.array(times[k][1:]) * 1e3 for k in (True, False))  # the first round warms up
            print(f"| {a:g} | {c.min():.1f} / {np.median(c):.1f} | {p.min():.1f} / {np.median(p):.1f} | "
                  f"{np.median(c) / np.median(p):.2f} | {tris[True]} / {tris[False]} |")
    finally:
        budget.CLIP_TO_TRIANGLES = default


if __name__ == "__main__":
    main()
