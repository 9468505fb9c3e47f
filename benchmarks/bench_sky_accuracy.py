"""Accuracy of the lensed world against the reference ray tracer's exact escape directions (issue 21).

The sky model is what the world's node group computes per shading sample
(frame_check.lensed_world_sky: xi from the ray direction and e1, the 1-D table of lutgen.escape,
linear in s as the shader interpolates, the escape direction cos(phi_inf) e1 + sin(phi_inf) e2; NaN
(black) where the ray falls in). The
reference is grlens_addon.core.raytrace's own closed-form curve (PixelBuffers.sky). Compared by
frame_check.check_frame(sky=...) / image_metrics.compare_sky: the sky's angular error in pixels,
the shadow (pixels where exactly one says the ray falls in) and the edges of a checkered world (10
degree checks in longitude and latitude): mismatched pixels per edge pixel. Scene: the paper's
sphere beside the hole (90 deg of its orbit), camera at 20 r_s looking at the hole, r_s = 1 BU; a
90 degree perspective view (640x360), a full equirectangular panorama (720x360) and a 180 degree
fisheye dome (512x512). Target (issue 21): checker edges off by under 0.25 px on average, the
shadow black to the pixel.

Usage: ./dev python benchmarks/bench_sky_accuracy.py
"""
import math
import os
import sys
import time
import warnings

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import bench_accuracy as BA  # noqa: E402
from grlens_addon.core import frame_check, mapping, pipeline, raytrace  # noqa: E402
from lutgen import LUTFamily  # noqa: E402


def main():
    warnings.simplefilter("ignore", RuntimeWarning)
    hole = np.zeros(3)
    cam_pos = np.array([BA.R_OBS * BA.R_S, 0.0, 0.0])
    src, _ = BA.sphere_scene(90)
    scene = mapping.Scene(cam_pos, hole, BA.R_S)
    table = LUTFamily().at(BA.R_OBS)
    settings = pipeline.Settings(64, 5.0, 0.75, 8.0)
    cameras = {
        "perspective 90 deg, 640x360": raytrace.Camera.look_at(cam_pos, hole, math.radians(90.0), 640, 360),
        "equirectangular 360 deg, 720x360": raytrace.Camera.look_at(cam_pos, hole, math.radians(90.0), 720, 360,
                                                                    kind="EQUIRECTANGULAR"),
        "fisheye dome 180 deg, 512x512": raytrace.Camera.look_at(cam_pos, hole, math.radians(90.0), 512, 512,
                                                                 kind="FISHEYE_EQUIDISTANT", fisheye_fov=math.pi),
    }
    print("| camera | sky error p50 / p99 / max [px] | shadow: pixels differing (of the reference's) | "
          "checker edge pixels | mismatched per edge pixel [px] | reference [s] |")
    print("|---|---|---|---|---|---|")
    for name, cam in cameras.items():
        t0 = time.perf_counter()
        check = frame_check.check_frame([src], scene, table, settings, cam, sky=frame_check.lensed_world_sky(hole, BA.R_S))
        m = check.metrics["sky"]
        a = m["sky_angle_px"]
        print(f"| {name} | {a['p50']:.2g} / {a['p99']:.2g} / {a['max']:.2g} | {m['shadow_mismatch']} "
              f"({m['fell_ref']}) | {m['checker_edge']} | {m['checker_per_edge']:.2g} | "
              f"{time.perf_counter() - t0:.1f} |", flush=True)


if __name__ == "__main__":
    main()
