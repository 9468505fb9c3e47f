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
  rest; and per image triangle and per covered pixel (the reference's pixels of both orders), so
  that what a moving camera costs for being in motion shows apart from what it costs for showing
  more (a magnified view has more pixels, so more pieces).
* An exactness step for 1 + z (the direction solved exactly for the final image vertices): the cost
  of lutgen.connect (the exact solver) on the moving camera's image vertices, and of one evaluation
  of the closed-form swept angle for as many rays (lutgen.orbit.orbit_from_b and sweep at both ends),
  against the frame: a Newton step on xi needs at least the branch test, the angle and its
  derivative, i.e. three or more such evaluations.

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
from provenance import code_version  # noqa: E402
from grlens_addon.core import frame_check, mapping, observer_view, pipeline, raytrace  # noqa: E402
from lutgen import LUTFamily, connect  # noqa: E402
from lutgen import orbit as lut_orbit  # noqa: E402

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


def _best(fn, n=5):
    """Best of ``n`` timings of ``fn()`` (s)."""
    out = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return min(out)


def _exactness_cost(images, scene):
    """(vertices, s for lutgen.connect on the image vertices, s for one closed-form swept angle per
    vertex's ray: orbit_from_b and the sweep at the observer's and the vertex's radius)."""
    planes = {o: mapping.plane_coordinates(img.source_position, scene) for o, img in images.items()}
    n = sum(len(p.r) for p in planes.values())
    t_connect = _best(lambda: [connect(R_OBS, p.r, p.phi, o) for o, p in planes.items()], 3)
    b = np.concatenate([connect(R_OBS, p.r, p.phi, o).b for o, p in planes.items()])
    u = 1.0 / np.concatenate([p.r for p in planes.values()])
    ok = np.isfinite(b) & (b > 0)
    b, u = b[ok], u[ok]

    def one_sweep():
        orb = lut_orbit.orbit_from_b(b)
        return lut_orbit.sweep(orb, u) - lut_orbit.sweep(orb, np.full(len(u), 1.0 / R_OBS))

    return n, t_connect, _best(one_sweep) * n / max(len(b), 1)


READING = "(set below)"
SKY_BEGIN, SKY_END = "<!-- bench_physical_time_sky: begin -->", "<!-- bench_physical_time_sky: end -->"


def main(out_path):
    warnings.simplefilter("ignore", RuntimeWarning)
    table = LUTFamily().at(R_OBS)
    settings = BA.make_settings(CAM)
    rows, cost, exact = [], [], []
    for angle in (45, 170, 180):
        src = BA.sphere_scene(angle)[0]
        scenes = {name: mapping.Scene(CAM.position, np.zeros(3), BA.R_S, beta=beta) for name, beta in CAMERAS.items()}
        tris, pixels = {}, {}
        for name, beta in CAMERAS.items():
            scene = scenes[name]
            chk = frame_check.check_frame([src], scene, table, settings, CAM)
            images = pipeline.build_images(src, scene, table, settings, None, CAM.frustum_planes())
            tris[name] = sum(len(img.tris) for img in images.values())
            pixels[name] = sum(chk.metrics["orders"][o]["covered_ref"] for o in (1, 2))
            if name == "out":
                out_images = images
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
        per_tri = {n: times[n] / tris[n] for n in times}
        per_px = {n: times[n] / pixels[n] for n in times}
        cost.append(f"| {angle} | {1e3 * times['at rest']:.1f} | {1e3 * times['out']:.1f} | {1e3 * times['in']:.1f} | "
                    f"{max(times['out'], times['in']) / times['at rest']:.2f} | "
                    f"{tris['at rest']} / {tris['out']} / {tris['in']} | "
                    f"{max(per_tri['out'], per_tri['in']) / per_tri['at rest']:.2f} | "
                    f"{pixels['at rest']} / {pixels['out']} / {pixels['in']} | "
                    f"{max(per_px['out'], per_px['in']) / per_px['at rest']:.2f} |")
        n, t_conn, t_sweep = _exactness_cost(out_images, scenes["out"])
        exact.append(f"| {angle} | {n} | {1e3 * times['out']:.1f} | {1e3 * t_conn:.1f} ({t_conn / times['out']:.2f}x) | "
                     f"{1e3 * t_sweep:.2f} ({t_sweep / times['out']:.2f}x) |")
        print(rows[-3:], cost[-1], exact[-1], flush=True)
    text = "\n".join([
        "# A moving camera: accuracy and cost", "",
        f"<!-- generated by benchmarks/bench_physical_time.py on {code_version()} -->", "",
        "From `benchmarks/bench_physical_time.py` (see its docstring): the paper's sphere seen from 20 r_s through a "
        "100 degree view (480x270), the camera at rest or moving at 0.4 c in its local static frame (radial "
        "and tangential parts; `out`: away from the hole, `in`: towards it). Images against the reference ray "
        "tracer for the same camera: pixels covered (reference), coverage mismatch, screen error of the surface "
        "points (pixels); 1 + z of the image vertices against the exact value (relative).", "",
        "| orbit angle (deg) | camera | o1 covered | o1 mismatch | o1 screen p99 | o1 screen max | o2 covered | "
        "o2 mismatch | o2 screen p99 | o2 screen max | 1+z p99 | 1+z max |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|", *rows, "",
        "Per-frame cost of the core (`pipeline.build_images`, best of 9 taken in turn, ms), the larger moving "
        "one over the camera at rest per frame, and per image triangle and per covered pixel (triangles of both "
        "image meshes and the reference's pixels of both orders, at rest / out / in; the ratio of the moving "
        "camera with the larger cost per triangle, or per pixel, over the camera at rest):", "",
        "| orbit angle (deg) | at rest | out | in | ratio per frame | image triangles | ratio per triangle | "
        "covered pixels | ratio per pixel |", "|---|---|---|---|---|---|---|---|---|", *cost, "",
        "An exactness step for 1 + z, for the `out` camera's image vertices (ms, and over its frame): the exact "
        "solver `lutgen.connect`, and one evaluation of the closed-form swept angle per vertex's ray (a Newton "
        "step on xi needs the branch test, the angle and its derivative: three or more of these):", "",
        "| orbit angle (deg) | image vertices | frame (ms) | lutgen.connect | one swept angle |",
        "|---|---|---|---|---|", *exact, "",
        READING, ""])
    sky = ""
    if os.path.exists(out_path):  # the lensed world's section (bench_physical_time_sky.py) stays
        old = open(out_path).read()
        if SKY_BEGIN in old and SKY_END in old:
            sky = old[old.index(SKY_BEGIN):old.index(SKY_END) + len(SKY_END)] + "\n"
    with open(out_path, "w") as f:
        f.write(text + ("\n" + sky if sky else ""))
    print(text)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else os.path.join(HERE, "..", "docs", "physical_time.md"))
