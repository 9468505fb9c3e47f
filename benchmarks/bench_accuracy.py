"""Image-level accuracy and speed of the polygon method against the per-pixel reference ray tracer.

Scene (seed 000, section 4.2, as benchmarks/bench_frame.py): r_s = 1 BU, a UV sphere of radius
0.5 r_s (36 segments x 18 rings, 1224 triangles, spherical UVs) on the orbit r = 3 r_s (centre
(3 cos a, 3 sin a, 0.01)), observer at (20, 0, 0) r_s looking at the hole, vertical field of view
19 deg, 640x360 by default. For each orbit angle a: the reference image (grlens_addon.core.raytrace,
exact null geodesic per pixel), the polygon pipeline (pipeline.build_images, both orders, the
add-on's default table (--table every-distance: lutgen.LUTFamily's table for 20 r_s, interpolated;
--table fixed: the former 256x512 LUT over [1.05, 40] r_s), the add-on's default settings, frustum
culling as the add-on does;
time = best of --repeat) rasterized with grlens_addon.core.rasterize, and the metrics of
grlens_addon.core.image_metrics (coverage mismatch; screen error: how far from the pixel the texture
point drawn there truly appears, through the exact connecting geodesic; UV error in pixels through the
reference's UV gradient and in texels of a 1024^2 texture; relative light-travel-time error; per
order).

``--sweep`` adds a Pareto table (pipeline time vs error) over LUT sizes and tessellation settings
and the plot docs/accuracy_pareto.png; ``--write`` writes everything to docs/accuracy.md.

Usage: ./dev python benchmarks/bench_accuracy.py [--resolution 640x360] [--angles 0,45,90,135,170,180]
       [--repeat 5] [--sweep] [--orbit STEP] [--write]

``--orbit STEP`` adds every STEP degrees of the orbit (``--orbit 1``, the 360 frames of seed 000's
sphere sequence, takes about twenty more minutes; ``--orbit 5`` about four): which angles meet the
targets, the rows of those that do not, and the whole sequence's times.
"""
from __future__ import annotations

import argparse
import dataclasses
import hashlib
import math
import os
import platform
import sys
import time
import warnings

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

from bench_frame import uv_sphere  # noqa: E402
from provenance import code_version  # noqa: E402
from grlens_addon.core import budget, image_metrics, mapping, pipeline, rasterize, raytrace  # noqa: E402
from lutgen import LUTFamily, build_lut  # noqa: E402

R_S = 1.0
R_OBS = 20.0
ORBIT = 3.0
RADIUS = 0.5
FOV_DEG = 19.0
TEXTURE = 1024
DEFAULTS = dict(max_tess_level=64, tess_a=5.0, tess_b=0.75, cull_ratio=8.0)  # the add-on's defaults
LUT_DEFAULT = (256, 512)


def sphere_corner_uv(local, tris):
    """Spherical corner UVs (T, 3, 2) of a sphere's triangles: u = longitude / 2 pi (seam-corrected per
    triangle, so u may exceed 1 on the seam; it is periodic), v = colatitude / pi; pole corners take
    the mean u of their triangle's other corners. ``local``: vertex positions relative to the centre."""
    q = local[tris]
    q = q / np.linalg.norm(q, axis=2, keepdims=True)
    u = np.mod(np.arctan2(q[..., 1], q[..., 0]) / (2 * np.pi), 1.0)
    v = np.arccos(np.clip(q[..., 2], -1.0, 1.0)) / np.pi
    pole = np.abs(q[..., 2]) > 1.0 - 1e-12
    umax = np.where(pole, -1.0, u).max(axis=1, keepdims=True)
    u = np.where(~pole & (umax - u > 0.5), u + 1.0, u)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(np.where(pole, np.nan, u), axis=1, keepdims=True)
    u = np.where(pole, mean, u)
    return np.stack([u, v], axis=-1)


def sphere_scene(angle_deg, segments=36, rings=18):
    """(pipeline.SourceMesh, raytrace.TriangleScene) of the orbiting sphere at orbit angle (deg)."""
    local, tris = uv_sphere(segments, rings, RADIUS * R_S)
    a = math.radians(angle_deg)
    centre = np.array([ORBIT * math.cos(a), ORBIT * math.sin(a), 0.01]) * R_S
    uv = sphere_corner_uv(local, tris)
    pts = local + centre
    return pipeline.SourceMesh(pts, tris, uv), raytrace.TriangleScene(pts, tris, uv)


TRIANGLE_FOV_DEG = 20.0
TRIANGLE_P2 = np.array([-5.0, 0.5, -0.5]) / 2.0
TRIANGLE_P1 = np.array([-5.0, 3.0, -0.5]) / 2.0
TRIANGLE_STEPS = (0.0, 0.25, 0.5, 0.75, 1.0)
"""Seed 000's triangle (section 4.1; sample_scenes ``triangle``) in units of r_s: the sample scene has
r_s = 2 BU, the camera at 20 r_s, a 20 deg vertical field of view, legs of 3 BU; here r_s = 1 BU.
Positions along its way from p2 (frame 1) to p1 (frame 150), as fractions of it."""


def triangle_scene(s):
    """(pipeline.SourceMesh, raytrace.TriangleScene) of the triangle at the fraction ``s`` of its way
    from p2 to p1: corners p, p + 1.5 y, p + 1.5 z (r_s), UVs (0, 0), (1, 0), (0, 1) as in the sample
    scene."""
    p = TRIANGLE_P2 + s * (TRIANGLE_P1 - TRIANGLE_P2)
    pts = p + np.array([[0.0, 0.0, 0.0], [0.0, 1.5, 0.0], [0.0, 0.0, 1.5]])
    tris = np.array([[0, 1, 2]])
    uv = np.array([[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]])
    return pipeline.SourceMesh(pts, tris, uv), raytrace.TriangleScene(pts, tris, uv)


def triangle_camera(width, height):
    return raytrace.Camera.look_at([R_OBS * R_S, 0.0, 0.0], [0.0, 0.0, 0.0], math.radians(TRIANGLE_FOV_DEG),
                                   width, height)


def triangle_pareto(width, height, repeat):
    """The Pareto sweep (:func:`sweep_settings`) on the triangle scene at TRIANGLE_STEPS: per setting the
    mean build_images time, the mismatch summed over the positions, the worst screen-error and
    light-travel-time p99, and the reference's mean time (markdown lines)."""
    cam = triangle_camera(width, height)
    frames = {s: triangle_scene(s) for s in TRIANGLE_STEPS}
    refs = {s: reference_image(frames[s][1], cam) for s in TRIANGLE_STEPS}
    t_ref = float(np.mean([t for _, t in refs.values()]))
    lines = ["| setting | build_images [ms] (mean) | mismatch | screen err p99 [px] | c*dt rel. err p99 | "
             "speed-up (mean times) |", "|---|---|---|---|---|---|"]
    luts = {}
    for label, size, over in sweep_settings():
        if size not in luts:
            luts[size] = build_lut(R_OBS, 1.05, 40.0, size[0], size[1])
        settings = make_settings(cam, **over)
        times, ms = [], []
        for s, (src, _) in frames.items():
            poly, t_poly, _, _ = polygon_image(src, cam, luts[size], settings, repeat)
            times.append(t_poly)
            ms.append(compare(refs[s][0], poly, cam, src, wrap_uv=(False, False)))
        mis, uv99, lt99 = aggregate(ms)
        t = float(np.mean(times))
        lines.append(f"| {label} | {1000 * t:.1f} | {_fmt_pct(mis)} | {uv99:.3f} | {lt99:.1e} | {t_ref / t:.0f}x |")
        print(lines[-1], flush=True)
    return lines, t_ref


def camera(width, height):
    return raytrace.Camera.look_at([R_OBS * R_S, 0.0, 0.0], [0.0, 0.0, 0.0], math.radians(FOV_DEG), width, height)


def make_settings(cam, **over):
    fields = {f.name for f in dataclasses.fields(pipeline.Settings)}
    kw = dict(DEFAULTS, pixel_angle=cam.pixel_angle)
    kw.update({k: v for k, v in over.items() if k in fields})
    return pipeline.Settings(**{k: v for k, v in kw.items() if k in fields})


def polygon_image(src, cam, lut, settings, repeat=1):
    """(buffers, best build_images time [s], rasterize time [s], triangle counts) of the polygon method."""
    scene = mapping.Scene(cam.position, np.zeros(3), R_S)
    planes = cam.frustum_planes()
    best = math.inf
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        images = pipeline.build_images(src, scene, lut, settings, frustum_planes=planes)
        best = min(best, time.perf_counter() - t0)
    t0 = time.perf_counter()
    buf = rasterize.rasterize(rasterize.from_images(images), cam)
    t_r = time.perf_counter() - t0
    return buf, best, t_r, {o: len(m.tris) for o, m in images.items()}


def exact_pixels(cam):
    """image_metrics.compare's ``image_pixels`` for ``cam``: the exact image of world points (BU)."""
    return lambda points, order: raytrace.image_pixels(points, cam, np.zeros(3), R_S, order)


def compare(ref, poly, cam, src, wrap_uv=(True, False), **kw):
    """image_metrics.compare with this benchmark's texture, the exact screen error of the texture
    (``src``: the pipeline.SourceMesh whose UVs both images show) and U wrapped (the sphere's UVs; the
    triangle's: ``wrap_uv`` (False, False))."""
    return image_metrics.compare(ref, poly, texture_size=TEXTURE, wrap_uv=wrap_uv,
                                 image_pixels=exact_pixels(cam), uv_points=lambda uv: image_metrics.uv_surface_points(
                                     uv, src.positions, src.tris, src.corner_uv, wrap_uv), **kw)


REF_CACHE = None
"""A directory of stored reference images (``--ref-cache``), or None: references are traced anew."""


def _reference_key(scene, cam) -> str:
    """A digest of everything a reference image depends on: the triangles, UVs, object ids and the camera."""
    h = hashlib.blake2b(digest_size=16)
    for a in (scene.positions, scene.tris, scene.corner_uv, scene.object_id, cam.position, cam.rotation):
        if a is not None:
            h.update(np.ascontiguousarray(a).tobytes())
    h.update(repr((cam.fov_y, cam.width, cam.height, R_S)).encode())
    return h.hexdigest()


def reference_image(scene, cam):
    """(buffers, seconds) of the reference ray tracer; with REF_CACHE, read from there when stored
    (the seconds are those of the run that traced it), else traced and stored."""
    path = os.path.join(REF_CACHE, _reference_key(scene, cam) + ".npz") if REF_CACHE else None
    if path and os.path.exists(path):
        with np.load(path, allow_pickle=False) as z:
            fields = {f.name for f in dataclasses.fields(raytrace.PixelBuffers)} - {"info"}
            buf = raytrace.PixelBuffers(**{k: z[k] for k in z.files if k in fields})
            empty = raytrace.PixelBuffers.empty(buf.shape)
            for f in fields - set(z.files):  # a field added to PixelBuffers after the file was written
                setattr(buf, f, getattr(empty, f))
            return buf, float(z["_seconds"])
    t0 = time.perf_counter()
    buf = raytrace.trace(scene, cam, np.zeros(3), R_S)
    seconds = time.perf_counter() - t0
    if path:
        os.makedirs(REF_CACHE, exist_ok=True)
        arrays = {f.name: getattr(buf, f.name) for f in dataclasses.fields(buf) if f.name != "info"}
        tmp = path + ".tmp.npz"
        np.savez(tmp, _seconds=seconds, **arrays)
        os.replace(tmp, path)
    return buf, seconds


def _angle(text):
    """An orbit angle from the command line (degrees): an int when whole (171), else a float (170.5)."""
    v = float(text)
    return int(v) if v.is_integer() else v


def _fmt_pct(x):
    return "n/a" if not np.isfinite(x) else f"{100 * x:.2f}%"


def _radial_range(buf, order, cam):
    """(min, max) distance in pixels from the image centre (the hole's direction) of the pixel centres
    showing ``order``, or None."""
    shown = np.asarray(buf.order).reshape(cam.height, cam.width) == order
    if not shown.any():
        return None
    ys, xs = np.nonzero(shown)
    r = np.hypot(xs - (cam.width - 1) / 2, ys - (cam.height - 1) / 2)
    return float(r.min()), float(r.max())


def main_table(angles, cam, lut, repeat, refs, png_dir=None):
    lines = ["| angle [deg] | reference [s] | build_images [ms] | speed-up | rasterize [s] | order-1 / order-2 triangles |",
             "|---|---|---|---|---|---|"]
    rows = []
    results = {}
    settings = make_settings(cam)
    for a in angles:
        src, sc = sphere_scene(a)
        ref, t_ref = refs[a]
        poly, t_poly, t_ras, ntri = polygon_image(src, cam, lut, settings, repeat)
        m = compare(ref, poly, cam, src, other_surface=OTHER_SURFACE)
        results[a] = m
        m["_t_poly"] = t_poly
        m["_radii"] = {o: (_radial_range(ref, o, cam), _radial_range(poly, o, cam)) for o in (1, 2)}
        lines.append(f"| {a} | {t_ref:.2f} | {1000 * t_poly:.1f} | {t_ref / t_poly:.0f}x | {t_ras:.2f} | "
                     f"{ntri.get(1, 0)} / {ntri.get(2, 0)} |")
        rows += image_metrics.markdown_rows(m, f"{a} deg")
        if png_dir:
            image_metrics.save_png(os.path.join(png_dir, f"accuracy_{a:05.1f}.png" if isinstance(a, float)
                                                else f"accuracy_{a:03d}.png"), {"reference": ref, "polygon": poly})
    targets = ["| angle [deg] | view | mismatch / covered (< 0.5%) | UV err p99 [px] (< 0.5): screen error | "
               "UV err via J p99 [px] | speed-up (>= 100x) |",
               "|---|---|---|---|---|---|"]
    for a in angles:
        m = results[a]["orders"]["all"]
        sp = refs[a][1] / results[a]["_t_poly"]

        def mark(ok):
            return "" if ok else " (missed)"

        targets.append(f"| {a} | {'Einstein ring' if is_ring(a) else 'off-axis'} | "
                       f"{_fmt_pct(m['mismatch_frac'])}{mark(m['mismatch_frac'] < 0.005)} | "
                       f"{m['screen_px']['p99']:.3f}{mark(m['screen_px']['p99'] < 0.5)} | {m['uv_px']['p99']:.3f} | "
                       f"{sp:.0f}x{mark(sp >= 100)} |")
    return lines, image_metrics.MARKDOWN_HEADER + rows, results, targets


OTHER_SURFACE = 0.25 * RADIUS
"""Pixels where both images show the sphere in the same order, but at world points more than this
(BU) apart, show another part of the sphere (e.g. its far side through a gap of the near side)."""


def other_surface_notes(angles, results):
    """Generated remark on the pixels that show another part of the sphere than the reference."""
    both = {a: results[a]["orders"]["all"] for a in angles}
    parts = [f"{a} deg: {both[a]['other_surface']} of {both[a]['matched']}" for a in angles if both[a]["other_surface"]]
    if not parts:
        return []
    return [f"Pixels showing the sphere in the right order but another part of it (seen points more than "
            f"{OTHER_SURFACE:g} r_s apart; the coverage mismatch cannot see these, the UV error does): "
            + "; ".join(parts) + ". Such pixels show the far side through a gap in the near side's image (where the ring "
            "culling drops pieces next to the axis), or lie on the edge of a second-order ring less than "
            "a pixel wide, where the two images cross over between the near and the far side.", ""]


def ring_notes(angles, results):
    """Generated remarks on the Einstein-ring views (coverage of each order, polygon vs reference)."""
    ring = [a for a in angles if is_ring(a)]
    if not ring:
        return []
    parts = []
    for a in ring:
        for o in (1, 2):
            m = results[a]["orders"][o]
            if m["covered_ref"]:
                part = (f"{a} deg order {o}: {m['covered_test']} px drawn vs {m['covered_ref']} px in the "
                        f"reference ({m['covered_test'] / m['covered_ref']:.2f}x), {m['mismatch']} mismatched")
                rr, rp = results[a]["_radii"][o]
                if o == 2 and rr and rp:
                    part += (f", pixel centres at {rr[0]:.1f}-{rr[1]:.1f} px from the hole's direction in the "
                             f"reference, {rp[0]:.1f}-{rp[1]:.1f} px in the polygon image")
                parts.append(part)
    return ["Einstein-ring views (the sphere straddles the camera-hole axis; see accuracy_NNN.png from "
            "`--png-dir` for pictures): " + "; ".join(parts) + ". The second-order rings are less than a "
            "pixel wide, so nearly all their pixels are edge pixels: a boundary that is off by a tenth of a "
            "pixel changes the coverage by tens of percent. The ring's edge at the Einstein radius is drawn "
            "by the axis patches (grlens_addon/core/axis_patch.py: chords sagging by max_error_px * "
            f"{budget.PATCH_EDGE_FACTOR * budget.COVERAGE_FACTOR:g} between points {budget.CHORD_OUTSET:.3g} of that sag outside the "
            "ring, so that they cross it); the other edge is the sphere's silhouette "
            f"along the rays, subdivided to max_error_px * {budget.COVERAGE_FACTOR:g} (core/budget.py); "
            "what is left is the straight sides of "
            "the pieces, within those tolerances of the curved edges, which the Pareto sweep below "
            "trades against time.", ""]


def sweep_settings():
    """(label, LUT size, settings overrides) of the Pareto sweep."""
    out = []
    for n in ((64, 128), (128, 256), (256, 512), (512, 1024)):
        out.append((f"LUT {n[0]}x{n[1]}", n, {}))
    for lvl in (4, 8, 16, 32):
        out.append((f"MaxTessLevel {lvl}", LUT_DEFAULT, dict(max_tess_level=lvl)))
    for a in (1.0, 2.0, 10.0):
        out.append((f"tess a {a:g}", LUT_DEFAULT, dict(tess_a=a)))
    if "max_error_px" in {f.name for f in dataclasses.fields(pipeline.Settings)}:
        for e in (0.05, 0.1, 0.5, 1.0, 2.0):
            out.append((f"max_error_px {e:g}", LUT_DEFAULT, dict(max_error_px=e)))
    for c in (4.0, 16.0):
        out.append((f"cull_ratio {c:g}", LUT_DEFAULT, dict(cull_ratio=c)))
    return out


def aggregate(ms):
    """Totals over angles: mismatch fraction (sum mismatch / sum covered, orders 1+2), max of p99s."""
    if not ms:
        return float("nan"), float("nan"), float("nan")
    mis = sum(m["orders"]["all"]["mismatch"] for m in ms)
    cov = sum(m["orders"]["all"]["covered_ref"] for m in ms)
    uv99 = np.nanmax([m["orders"]["all"]["screen_px"]["p99"] for m in ms])
    lt99 = np.nanmax([m["orders"]["all"]["lt_rel"]["p99"] for m in ms])
    return mis / cov if cov else float("nan"), uv99, lt99


def is_ring(angle_deg):
    """True if the sphere straddles the camera-hole axis at this orbit angle (Einstein rings)."""
    return abs(math.sin(math.radians(angle_deg))) * ORBIT < RADIUS


def orbit_table(step, cam, lut, repeat, refs=None):
    """Every ``step`` degrees of the orbit at default settings: a summary (how many angles meet each
    target) and the rows of the angles that miss one, worst first."""
    settings = make_settings(cam)
    rows = []
    for a in range(0, 360, step):
        src, sc = sphere_scene(a)
        ref, t_ref = refs[a] if refs and a in refs else reference_image(sc, cam)
        poly, t_poly, _, _ = polygon_image(src, cam, lut, settings, repeat)
        m = compare(ref, poly, cam, src)["orders"]["all"]
        rows.append((a, m["mismatch_frac"], m["screen_px"]["p99"], t_ref / t_poly, 1000 * t_poly))
        print(f"orbit {a} deg: mismatch {_fmt_pct(m['mismatch_frac'])}, screen p99 {m['screen_px']['p99']:.3f} px, "
              f"{t_ref / t_poly:.0f}x ({1000 * t_poly:.1f} ms)", flush=True)
    return orbit_summary(step, rows)


def orbit_summary(step, rows):
    """The orbit table's text from its ``rows`` (angle, mismatch fraction, screen p99 px, speed-up,
    build_images ms): how many angles meet each target, then the angles that miss one (worst
    mismatch first) or, when none does, the five closest to a target."""
    n = len(rows)
    ok = [(r[1] < 0.005, r[2] < 0.5, r[3] >= 100) for r in rows]
    missed = [r for r, o in zip(rows, ok) if not all(o)]
    if missed:
        shown, what = sorted(missed, key=lambda r: -r[1]), "The angles that miss one, by mismatch:"
    else:  # the closest to a target: the largest of mismatch / 0.5%, UV / 0.5 px and 100x / speed-up
        shown = sorted(rows, key=lambda r: -max(r[1] / 0.005, r[2] / 0.5, 100.0 / r[3]))[:5]
        what = ("No angle misses one. The five closest to a target (the largest of mismatch / 0.5%, "
                "UV / 0.5 px and 100x / speed-up):")
    out = [f"Every {step} degrees of the orbit ({n} angles) at default settings: the mismatch target is met at "
           f"{sum(o[0] for o in ok)}, the UV target at {sum(o[1] for o in ok)}, the speed-up target at "
           f"{sum(o[2] for o in ok)}, all three at {sum(all(o) for o in ok)}. {what}", "",
           "| angle [deg] | mismatch / covered | UV err p99 [px] (screen) | speed-up | build_images [ms] |",
           "|---|---|---|---|---|"]
    for a, mis, uv, sp, t in shown:
        out.append(f"| {a} | {_fmt_pct(mis)} | {uv:.3f} | {sp:.0f}x | {t:.1f} |")
    # the whole sequence, as seed 000's table 3 compares the two methods (render times of image sequences)
    t_ref = sum(r[3] * r[4] for r in rows) / 1000.0
    t_poly = sum(r[4] for r in rows) / 1000.0
    out += ["", f"The whole sequence ({n} frames): the reference took {t_ref:.0f} s, build_images {t_poly:.2f} s, "
                f"{t_ref / t_poly:.0f} times less (the paper's table 3 compares image sequences this way)."]
    return out


def pareto(angles, cam, refs, repeat, plot_path=None):
    off = [a for a in angles if not is_ring(a)]
    ring = [a for a in angles if is_ring(a)]
    lines = ["| setting | build_images [ms] (mean) | mismatch, off-axis | screen err p99 [px], off-axis | "
             "c*dt rel. err p99, off-axis | mismatch, rings | screen err p99 [px], rings | LUT build [s] |",
             "|---|---|---|---|---|---|---|---|"]
    pts = []
    luts = {}
    for label, size, over in sweep_settings():
        if size not in luts:
            t0 = time.perf_counter()
            luts[size] = (build_lut(R_OBS, 1.05, 40.0, size[0], size[1]), time.perf_counter() - t0)
        lut, t_lut = luts[size]
        settings = make_settings(cam, **over)
        times, ms = [], {}
        for a in angles:
            src, _ = sphere_scene(a)
            poly, t_poly, _, _ = polygon_image(src, cam, lut, settings, repeat)
            times.append(t_poly)
            ms[a] = compare(refs[a][0], poly, cam, src)
        f_off, uv_off, lt_off = aggregate([ms[a] for a in off])
        f_ring, uv_ring, _ = aggregate([ms[a] for a in ring])
        t = float(np.mean(times))
        pts.append((label, t, f_off, uv_off, f_ring, uv_ring))
        lines.append(f"| {label} | {1000 * t:.1f} | {_fmt_pct(f_off)} | {uv_off:.3f} | {lt_off:.1e} | "
                     f"{_fmt_pct(f_ring)} | {uv_ring:.3f} | {t_lut:.2f} |")
        print(lines[-1], flush=True)
    if plot_path:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
        groups = ((2, 3, "off-axis " + ",".join(map(str, off)) + " deg", "o"),
                  (4, 5, "Einstein rings " + ",".join(map(str, ring)) + " deg", "s"))
        for i_f, i_uv, name, marker in groups:
            if not (off if i_f == 2 else ring):
                continue
            for ax, idx, scale in ((axes[0], i_f, 100.0), (axes[1], i_uv, 1.0)):
                xs = [1000 * p[1] for p in pts]
                ys = [max(scale * p[idx], 1e-4) for p in pts]
                ax.plot(xs, ys, marker, label=name, alpha=0.8)
                done = []  # label only points that are not next to an already labelled one
                for p, x, y in zip(pts, xs, ys):
                    if any(abs(x - x0) < 2.5 and abs(math.log10(y / y0)) < 0.08 for x0, y0 in done):
                        continue
                    done.append((x, y))
                    ax.annotate(p[0], (x, y), fontsize=6, xytext=(3, 2), textcoords="offset points")
        axes[0].set_ylabel("coverage mismatch [% of covered pixels]")
        axes[1].set_ylabel("screen error p99 [px] (worst angle of the group)")
        for ax in axes:
            ax.axhline(0.5, color="grey", lw=0.8, ls="--")
            ax.set_xlabel("build_images time per frame [ms] (both orders, mean over angles)")
            ax.set_yscale("log")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
        fig.suptitle(f"polygon method vs per-pixel reference: sphere scene at {cam.width}x{cam.height}; "
                     "one setting changed per point (dashed: targets)", fontsize=9)
        fig.tight_layout()
        fig.savefig(plot_path, dpi=110)
        plt.close(fig)
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", default="640x360")
    ap.add_argument("--angles", default="0,45,90,135,170,180")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--sweep", action="store_true", help="Pareto sweep of LUT size / tessellation settings")
    ap.add_argument("--sweep-angles", default=None, help="angles of the sweep (default: --angles)")
    ap.add_argument("--write", action="store_true", help="write docs/accuracy.md (and the plot with --sweep)")
    ap.add_argument("--png-dir", default=None, help="write debug pictures (reference / polygon / differences) here")
    ap.add_argument("--table", choices=("every-distance", "fixed"), default="every-distance",
                    help="the camera's table: the add-on's default (a LUTFamily table) or the former fixed-range LUT")
    ap.add_argument("--orbit", type=int, default=0, metavar="STEP",
                    help="also every STEP degrees of the orbit: which angles meet the targets")
    ap.add_argument("--ref-cache", default=None, metavar="DIR",
                    help="store reference images in DIR and reuse them (keyed by scene and camera; delete DIR "
                         "when the ray tracer changes)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    global REF_CACHE
    REF_CACHE = args.ref_cache
    w, h = (int(x) for x in args.resolution.lower().split("x"))
    angles = [_angle(a) for a in args.angles.split(",") if a.strip()]
    sweep_angles = [_angle(a) for a in args.sweep_angles.split(",")] if args.sweep_angles else angles
    cam = camera(w, h)
    if args.png_dir:
        os.makedirs(args.png_dir, exist_ok=True)
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    if args.table == "fixed":
        lut = build_lut(R_OBS, 1.05, 40.0, *LUT_DEFAULT)
        table_text = f"LUT {LUT_DEFAULT[0]}x{LUT_DEFAULT[1]} over [1.05, 40] r_s"
    else:
        lut = LUTFamily().at(R_OBS)
        table_text = (f"the add-on's default table, lutgen.LUTFamily's for {R_OBS:g} r_s (1.05 r_s to infinity, "
                      f"interpolated from its four exact {lut.rows} x {lut.n_phi} tables)")
    t_lut = time.perf_counter() - t0
    refs = {}
    for a in sorted(set(angles) | (set(sweep_angles) if args.sweep else set())):
        refs[a] = reference_image(sphere_scene(a)[1], cam)
        print(f"reference {a} deg: {refs[a][1]:.2f} s, {refs[a][0].info}", flush=True)
    timing, metric_rows, results, targets = main_table(angles, cam, lut, args.repeat, refs, args.png_dir)
    settings = make_settings(cam)
    out = [
        "# Accuracy of the polygon method against a per-pixel ray tracer",
        "",
        "Generated by `./dev python benchmarks/bench_accuracy.py"
        + (" --table fixed" if args.table == "fixed" else "") + (" --sweep" if args.sweep else "") + (f" --orbit {args.orbit}" if args.orbit else "") + " --write` "
        f"({platform.machine()}, {os.cpu_count()} CPUs, numpy {np.__version__}; {code_version()}; "
        f"load average {load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end: on a shared machine "
        "the times vary by tens of percent); do not edit by hand.",
        "",
        f"Scene: the paper's orbiting sphere (radius {RADIUS} r_s, 36x18 UV sphere, 1224 triangles, spherical "
        f"UVs) on the orbit r = {ORBIT} r_s, camera at {R_OBS} r_s looking at the hole, vertical field of view "
        f"{FOV_DEG} deg, {w}x{h} pixels (one sample per pixel centre), r_s = 1 BU. Orbit angle 0 puts the sphere "
        "between camera and hole, 180 behind the hole (Einstein rings in both cases; the centre is 0.01 r_s "
        "off the orbital plane).",
        "",
        "* reference: `grlens_addon.core.raytrace.trace`, the exact null geodesic through every pixel (closed-form "
        "orbits, exact intersections; single-threaded numpy);",
        f"* polygon method: `pipeline.build_images` (both orders; {table_text}, built in {t_lut:.2f} s, not "
        f"counted per frame; settings "
        f"`{dataclasses.asdict(settings)}`; frustum planes as the add-on passes them), best of {args.repeat}, "
        "rasterized by `grlens_addon.core.rasterize` (a numpy z-buffer sampling pixel centres; its time is not "
        "part of the per-frame cost, which a GPU renderer pays);",
        "* metrics (`grlens_addon.core.image_metrics.compare`): coverage mismatch = pixels where exactly one image "
        "shows a given (object, order), as a count and as a fraction of the reference's covered pixels; UV "
        "error on screen (\"screen err\") = the distance from the pixel's centre to where the texture point drawn "
        "there truly appears: the point of the sphere's mesh with that UV (`image_metrics.uv_surface_points`), "
        "imaged through the exact connecting geodesic (`raytrace.image_pixels`, lutgen.connect); UV error via J = "
        "|J^-1 duv| with J the "
        "reference's screen-space UV gradient from finite differences, the same quantity linearised, and in "
        f"texels of a {TEXTURE}^2 texture; light-travel-time error relative; p50 / p99 / max over the pixels "
        "where both show the same object in the same order. Orders 3 and higher (only the reference has them) "
        "are counted separately.",
        "",
        "The UV target is checked on the screen error. Where the image is not squeezed the two UV measures "
        "agree (45-135 deg below). Where it is squeezed to about a pixel across, beside the Einstein ring, the "
        "UV changes non-linearly within one pixel: J from finite differences is then wrong and nearly "
        "singular, and the linearised measure reads pixels (up to thousands) where the texture drawn is a "
        "fraction of a pixel from its true place; on rings one pixel wide it has no value at all (n/a). The "
        "reference's own UVs have a screen error below 1e-6 px (tests/test_raytrace.py), so the measure "
        "checks the ray tracer and lutgen.connect against each other as well.",
        "",
        "Accuracy targets (default settings, 640x360): coverage mismatch under 0.5% of the covered pixels, "
        "UV error p99 below 0.5 px (on screen, see above), polygon method at least 100x faster per frame than "
        "the reference.",
        "",
        "## Targets at default settings",
        "",
        *targets,
        "",
        "## Time per frame",
        "",
        *timing,
        "",
        "## Errors",
        "",
        *metric_rows,
        "",
        "Pixels with order 3+ in the reference: "
        + ", ".join(f"{a} deg: {results[a]['higher_ref']}" for a in angles) + ". "
        "UV errors via J need a reference UV gradient, i.e. neighbours of the same object and order: "
        "pixels measured (all orders) "
        + ", ".join(f"{a} deg: {results[a]['orders']['all']['uv_px_n']} of {results[a]['orders']['all']['matched']}"
                    for a in angles)
        + " (a ring one pixel wide has none, hence n/a).",
        "",
        *ring_notes(angles, results),
        *other_surface_notes(angles, results),
    ]
    print("\n".join(out[out.index("## Targets at default settings"):]), flush=True)
    if args.sweep:
        plot = os.path.join(ROOT, "docs", "accuracy_pareto.png") if args.write else None
        lines = pareto(sweep_angles, cam, refs, max(1, args.repeat // 2), plot)
        out += ["## Pareto sweep", "",
                "Each row changes one setting from the defaults above. Angles are grouped into off-axis "
                f"({', '.join(str(a) for a in sweep_angles if not is_ring(a))} deg) and Einstein-ring "
                f"({', '.join(str(a) for a in sweep_angles if is_ring(a))} deg) views; mismatch summed over a "
                "group's angles (orders 1 and 2), UV and light-travel-time p99 of its worst angle. "
                "Plot: [accuracy_pareto.png](accuracy_pareto.png).", "", *lines, ""]
    if args.sweep:
        tri_lines, tri_ref = triangle_pareto(w, h, max(1, args.repeat // 2))
        out += ["## Pareto sweep, triangle scene", "",
                "The paper's triangle behind the hole (section 4.1; sample scene `triangle`, in units of r_s: "
                f"camera at {R_OBS:g} r_s, {TRIANGLE_FOV_DEG:g} deg vertical field of view, {w}x{h}) at "
                f"{len(TRIANGLE_STEPS)} positions of its way from p2 to p1 (fractions "
                f"{', '.join(f'{t:g}' for t in TRIANGLE_STEPS)}); the same settings as above; mismatch summed "
                "over the positions, p99 of the worst one; speed-up = the reference's mean time "
                f"({tri_ref:.2f} s) over the mean build_images time.", "", *tri_lines, ""]
    if args.orbit:
        orbit = ["## Over the orbit", "", *orbit_table(args.orbit, cam, lut, max(1, args.repeat // 2), refs), ""]
        print("\n".join(orbit), flush=True)
        out += orbit
    if args.write:
        path = os.path.join(ROOT, "docs", "accuracy.md")
        with open(path, "w") as f:
            f.write("\n".join(out))
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
