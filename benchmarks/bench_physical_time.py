"""A moving camera (physical time): accuracy and per-frame cost of the images against a camera at rest.

Scenes: the paper's sphere (0.5 r_s on the 3 r_s orbit) at 45, 170 and 180 degrees of its orbit,
seen from 20 r_s through a 100 degree perspective view (480x270; wide, so that the aberrated
images stay in the frame), r_s = 1 BU. Cameras: at rest, and moving at 0.4 c in the local static
frame with radial and tangential parts, outwards ("out", beta = 0.4 (0.6 e_r + 0.8 e_t)) and
inwards ("in", radial part reversed).

* Images against the reference ray tracer for the same (moving) camera (frame_check.check_frame:
  raytrace.trace with beta, image_pixels with the exact solver's directions aberrated): coverage
  mismatch and screen error of the surface points (pixels, p99 and max).
* 1 + z of the image vertices against the exact value (lutgen.connect's direction at the camera,
  the gravitational shift and the Doppler factor): relative error p99 and max.
* Per-frame cost: pipeline.build_images, best of 9 runs (the three cameras in turn), moving over at
  rest.

Usage: ./dev python benchmarks/bench_physical_time.py [output.md]   (default docs/physical_time.md)
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
from grlens_addon.core import frame_check, mapping, observer_view, pipeline, raytrace  # noqa: E402
from lutgen import LUTFamily, connect  # noqa: E402

R_OBS = 20.0
CAM = raytrace.Camera.look_at([R_OBS, 0.0, 0.0], [0.0, 0.0, 0.0], math.radians(100), 480, 270)
B = 0.4
CAMERAS = {"at rest": None,
           "out": B * np.array([0.6, 0.8 * math.cos(0.5), 0.8 * math.sin(0.5)]),
           "in": B * np.array([-0.6, 0.8 * math.cos(0.5), 0.8 * math.sin(0.5)])}


def _redshift_error(images, scene):
    """(p99, max) relative error of the image vertices' 1 + z against the exact value."""
    errs = []
    for order, img in images.items():
        if img.redshift is None or not len(img.positions):
            continue
        plane = mapping.plane_coordinates(img.source_position, scene)
        # a point on the axis (an Einstein ring's limit vertex) is seen at every azimuth: the plane of
        # its image's own direction (taken back to the static frame)
        seen = img.positions - scene.camera
        seen = observer_view.unaberrate(seen / np.linalg.norm(seen, axis=1, keepdims=True), scene.beta)
        across = seen - (seen @ scene.e1)[:, None] * scene.e1
        own = (1.0 if order == 1 else -1.0) * across / np.linalg.norm(across, axis=1, keepdims=True)
        e2 = np.where(plane.on_axis[:, None], own, plane.e2)
        conn = connect(R_OBS, plane.r, plane.phi, order)
        d = observer_view.view_directions(conn.xi, e2, scene.e1, order)
        exact = 1.0 / observer_view.frequency_ratio(plane.r, R_OBS, -d, scene.beta)
        errs.append(np.abs(img.redshift / exact - 1.0))
    if not errs:
        return float("nan"), float("nan")
    e = np.concatenate(errs)
    return float(np.nanpercentile(e, 99)), float(np.nanmax(e))


def main(out_path):
    warnings.simplefilter("ignore", RuntimeWarning)
    table = LUTFamily().at(R_OBS)
    settings = BA.make_settings(CAM)
    rows, cost = [], []
    for angle in (45, 170, 180):
        src = BA.sphere_scene(angle)[0]
        scenes = {name: mapping.Scene(CAM.position, np.zeros(3), BA.R_S, beta=beta) for name, beta in CAMERAS.items()}
        for name, beta in CAMERAS.items():
            scene = scenes[name]
            chk = frame_check.check_frame([src], scene, table, settings, CAM)
            images = pipeline.build_images(src, scene, table, settings, None, CAM.frustum_planes())
            z99, zmax = _redshift_error(images, scene) if beta is not None else (float("nan"), float("nan"))
            cells = []
            for order in (1, 2):
                m = chk.metrics["orders"][order]
                sp = m.get("screen_px", {})
                cells += [f"{m['covered_ref']}", f"{m['mismatch']}", f"{sp.get('p99', float('nan')):.3f}",
                          f"{sp.get('max', float('nan')):.3f}"]
            rows.append(f"| {angle} | {name} | " + " | ".join(cells) + f" | {z99:.1e} | {zmax:.1e} |")
        runs = {name: [] for name in CAMERAS}
        for _ in range(9):  # the three cameras in turn, so that a busy moment of the machine hits all
            for name, scene in scenes.items():
                t0 = time.perf_counter()
                pipeline.build_images(src, scene, table, settings, None, CAM.frustum_planes())
                runs[name].append(time.perf_counter() - t0)
        times = {name: float(np.min(r)) for name, r in runs.items()}
        cost.append(f"| {angle} | {1e3 * times['at rest']:.1f} | {1e3 * times['out']:.1f} | {1e3 * times['in']:.1f} | "
                    f"{max(times['out'], times['in']) / times['at rest']:.2f} |")
        print(rows[-3:], cost[-1], flush=True)
    text = "\n".join([
        "# A moving camera: accuracy and cost", "",
        "From `benchmarks/bench_physical_time.py` (see its docstring): the paper's sphere seen from 20 r_s through a "
        "100 degree view (480x270), the camera at rest or moving at 0.4 c in its local static frame (radial "
        "and tangential parts; `out`: away from the hole, `in`: towards it). Images against the reference ray "
        "tracer for the same camera: pixels covered (reference), coverage mismatch, screen error of the surface "
        "points (pixels); 1 + z of the image vertices against the exact value (relative).", "",
        "| orbit angle (deg) | camera | o1 covered | o1 mismatch | o1 screen p99 | o1 screen max | o2 covered | "
        "o2 mismatch | o2 screen p99 | o2 screen max | 1+z p99 | 1+z max |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|", *rows, "",
        "Per-frame cost of the core (`pipeline.build_images`, best of 9 taken in turn, ms) and the larger moving "
        "one over the camera at rest (the moving images are larger or smaller on screen: `out` sees the hole's "
        "side magnified, `in` shrunk):", "",
        "| orbit angle (deg) | at rest | out | in | ratio |", "|---|---|---|---|---|", *cost, "",
        "Reading. The moving camera's images are as accurate as the resting camera's: the same coverage "
        "mismatch (a few pixels) and screen errors of the same size, against a reference that traces the moving "
        "camera's own pixel rays. 1 + z is within about 1e-7 of the exact value: the table's direction error "
        "(about 1.6e-7 rad here) times beta; given a direction, the formula is exact to rounding "
        "(tests/test_moving_observer.py). The cost follows the images' size on screen: the camera moving away "
        "from the hole's side (`out`) sees that side magnified (about 1.75 times the pixels at 180 degrees, "
        "the Einstein ring wider), so its images have more pieces and its axis patch more azimuths; moving "
        "towards it (`in`) the images shrink. The error budget measures the moving camera's own view (the "
        "ring radius about the axis in the static frame times the aberration's local magnification): measured "
        "about the unaberrated hole direction instead, the same frames cost 1.3 to 2.5 times as much.", ""])
    with open(out_path, "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else os.path.join(HERE, "..", "docs", "physical_time.md"))
