"""Coarse meshes against the per-pixel reference ray tracer: a ground plane and a wall of one quad each,
and the same as 20x20 grids (the meshes artists make first), and the budget inside their pieces.

Scenes (r_s = 1 BU, the hole at the origin, the camera at (25, 0, 0) r_s looking at the hole, vertical
field of view 30 deg):

* ``plane``: a square 200 BU across in z = -3 BU (3 BU under the camera and the hole), two triangles;
  ``plane 20x20``: the same as a grid of 20x20 quads (800 triangles);
* ``wall``: a rectangle in y = 4 BU beside the camera, x from -80 to 40 BU (it passes the camera),
  z from -20 to 20 BU, two triangles; ``wall 20x20``: the same as a grid.

UVs run from 0 to 1 across each mesh; the texture measure draws a checker of 50 x 50 cells from
them (image_metrics.checker_torn). Per scene and resolution: build_images (both orders, the add-on's
default settings and table; best of --repeat), the image triangles per order, what the refine step
did (pieces cut further, pieces beyond the budget after it), the reference (raytrace.trace), and
the metrics of docs/accuracy.md (coverage mismatch, screen error of the texture, light travel time)
plus the checker's wrong and torn pixels, the kept pieces' own errors measured inside
(interior.measure over every kept piece, sampled or not: p99 and max in pixels and relative c*dt),
and (this checkout) the GR irradiance of a point light 20 r_s above the hole as the renderer
interpolates it over a piece against its exact value at the piece's centroid (it does not drive the
cutting).

``--base REV`` adds the same for git revision REV's core (bench_budget.base_core), alternated in one
process. ``--write`` writes docs/coarse.md. Times vary by tens of percent on the shared machine:
compare within one run.

Usage: ./dev python benchmarks/bench_coarse.py [--resolutions 480x270,1920x1080] [--repeat 3]
       [--base REV] [--scenes plane,...] [--ref-cache DIR] [--write]
"""
from __future__ import annotations

import argparse
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

import bench_accuracy as BA  # noqa: E402
from provenance import code_version  # noqa: E402
from grlens_addon.core import frame, illumination, image_metrics, interior, mapping, pipeline, rasterize, raytrace  # noqa: E402
from lutgen import LUTFamily  # noqa: E402

R_OBS = 25.0
FOV_DEG = 30.0
CELLS = 50
CAMERA = np.array([R_OBS, 0.0, 0.0])


def grid_mesh(corner, du, dv, n):
    """(positions, tris, corner_uv) of a parallelogram from ``corner`` (3,) spanned by ``du``, ``dv``
    (3,) (BU) as n x n quads, two triangles each, UVs from 0 to 1 along du and dv."""
    g = np.linspace(0.0, 1.0, n + 1)
    u, v = np.meshgrid(g, g, indexing="ij")
    pts = corner + u.reshape(-1, 1) * du + v.reshape(-1, 1) * dv
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    uv = np.stack([u.ravel(), v.ravel()], 1)
    return pts, tris, uv[tris]


def scenes():
    """{name: (positions, tris, corner_uv)} of the benchmark's meshes (see the module docstring)."""
    plane = (np.array([-100.0, -100.0, -3.0]), np.array([200.0, 0.0, 0.0]), np.array([0.0, 200.0, 0.0]))
    wall = (np.array([-80.0, 4.0, -20.0]), np.array([120.0, 0.0, 0.0]), np.array([0.0, 0.0, 40.0]))
    return {"plane": grid_mesh(*plane, 1), "plane 20x20": grid_mesh(*plane, 20),
            "wall": grid_mesh(*wall, 1), "wall 20x20": grid_mesh(*wall, 20)}


def camera(width, height):
    return raytrace.Camera.look_at(CAMERA, [0.0, 0.0, 0.0], math.radians(FOV_DEG), width, height)


def settings_for(cam, mod=pipeline):
    return mod.Settings(max_tess_level=64, tess_a=5.0, tess_b=0.75, cull_ratio=8.0, pixel_angle=cam.pixel_angle)


def piece_errors(images, cam, table, settings):
    """(screen px p99, max; lt rel p99, max) of every kept piece of ``images`` ({order: ImageMesh})
    measured inside (interior.measure: centroid and edge midpoints; patch faces included)."""
    scene = mapping.Scene(cam.position, np.zeros(3), 1.0)
    fr = frame.frame_context(scene, table, settings)
    scr, lt = [], []
    for order, m in images.items():
        if not len(m.tris):
            continue
        img = fr.map.images(m.source_position, (order,))[order]
        img.position, img.distance = m.positions, m.light_travel_time  # what is drawn
        _, s, l_ = interior.measure(fr, m.source_position, m.tris, img, order)
        scr.append(s)
        lt.append(l_)
    s, l_ = np.concatenate(scr), np.concatenate(lt)
    q = lambda a, p: float(np.nanpercentile(a, p)) if np.isfinite(a).any() else float("nan")  # noqa: E731
    return q(s, 99), q(s, 100), q(l_, 99), q(l_, 100)


LIGHT = np.array([0.0, 0.0, 20.0])
"""A point light 20 r_s above the hole for the GR irradiance column (illumination.irradiance)."""


def irradiance_error(pts, tris, uv, cam, table, light_table):
    """(p99, max) of the relative error of the GR irradiance as the renderer interpolates it (the mean
    of a piece's corner values) against its exact value at the piece's centroid (faces lit by more
    than 1% of the brightest), with the meshes' flat normals (towards the camera's side)."""
    n = np.cross(pts[tris[:, 1]] - pts[tris[:, 0]], pts[tris[:, 2]] - pts[tris[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(((CAMERA - pts[tris[:, 0]]) * n).sum(axis=1, keepdims=True) < 0, -n, n)
    src = pipeline.SourceMesh(pts, tris, uv, corner_normals=np.repeat(n[:, None], 3, axis=1))
    scene = mapping.Scene(cam.position, np.zeros(3), 1.0)
    light = pipeline.Light(LIGHT, 1000.0, light_table)
    images = pipeline.build_images(src, scene, table, settings_for(cam), light, cam.frustum_planes())
    rel = []
    for m in images.values():
        if not len(m.tris):
            continue
        centre = m.source_position.take(m.tris, axis=0).mean(axis=1)
        normal = m.corner_normal.mean(axis=1)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        exact, _ = illumination.irradiance(centre, normal, LIGHT, np.zeros(3), 1.0, light_table, 1000.0)
        drawn = m.irradiance.mean(axis=1)
        lit = exact > 0.01 * exact.max(initial=0.0)
        rel.append(np.abs(drawn[lit] - exact[lit]) / exact[lit])
    rel = np.concatenate(rel) if rel else np.zeros(0)
    return (float(np.percentile(rel, 99)), float(rel.max())) if rel.size else (float("nan"), float("nan"))


def run(name, mesh, cam, table, variants, repeat, light_table=None):
    """One scene at one resolution: a markdown row per variant."""
    pts, tris, uv = mesh
    ref, t_ref = BA.reference_image(raytrace.TriangleScene(pts, tris, uv), cam)
    scene = mapping.Scene(cam.position, np.zeros(3), 1.0)
    rows = []
    for label, mod in variants:
        settings = settings_for(cam, mod)
        src = mod.SourceMesh(pts, tris, uv)
        best = math.inf
        for _ in range(max(1, repeat)):
            t0 = time.perf_counter()
            images = mod.build_images(src, scene, table, settings, frustum_planes=cam.frustum_planes())
            best = min(best, time.perf_counter() - t0)
        poly = rasterize.rasterize(rasterize.from_images(images), cam)
        m = image_metrics.compare(ref, poly, image_pixels=BA.exact_pixels(cam),
                                  uv_points=lambda q: image_metrics.uv_surface_points(q, pts, tris, uv))
        a = m["orders"]["all"]
        tex = image_metrics.checker_torn(ref, poly, CELLS)
        pe = piece_errors(images, cam, table, settings_for(cam))
        rep = images[1].report
        over = [im.report.over_budget for im in images.values() if getattr(im.report, "over_budget", None)]
        beyond = (f"{sum(b.count for b in over)} ({max(b.screen_px for b in over):.2f} px)" if over else "-")
        irr = (irradiance_error(pts, tris, uv, cam, table, light_table)
               if light_table is not None and mod is pipeline else None)
        irr_cell = "-" if irr is None else f"{irr[0]:.1e} / {irr[1]:.1e}"
        rows.append(
            f"| {name} | {cam.width}x{cam.height} | {label} | {1e3 * best:.0f} | "
            f"{' / '.join(str(len(im.tris)) for im in images.values())} | {getattr(rep, 'refined', '-')} | {beyond} | "
            f"{100 * a['mismatch_frac']:.2f}% | {a['screen_px']['p50']:.3f} / {a['screen_px']['p99']:.3f} / "
            f"{a['screen_px']['max']:.2f} | {a['lt_rel']['p99']:.1e} / {a['lt_rel']['max']:.1e} | "
            f"{tex['wrong']} / {tex['torn']} | {pe[0]:.3f} / {pe[1]:.2f} | {pe[2]:.1e} / {pe[3]:.1e} | {irr_cell} | "
            f"{t_ref:.1f} |")
        print(rows[-1], flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolutions", default="480x270,1920x1080")
    ap.add_argument("--scenes", default=None, help="comma-separated names (default: all)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--base", default=None, metavar="REV", help="also git revision REV's core")
    ap.add_argument("--ref-cache", default=None, metavar="DIR", help="as bench_accuracy's --ref-cache")
    ap.add_argument("--write", action="store_true", help="write docs/coarse.md")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    BA.REF_CACHE = args.ref_cache
    if args.ref_cache:
        os.makedirs(args.ref_cache, exist_ok=True)
    table = LUTFamily().at(R_OBS)
    light_table = LUTFamily().at(float(np.linalg.norm(LIGHT)))
    variants = [("this", pipeline)]
    if args.base:
        import bench_budget

        variants.insert(0, (f"base {args.base}", bench_budget.base_core(args.base)))
    meshes = scenes()
    names = args.scenes.split(",") if args.scenes else list(meshes)
    load0 = os.getloadavg()[0]
    lines = [f"Generated by `./dev python benchmarks/bench_coarse.py {' '.join(argv if argv is not None else sys.argv[1:])}` "
             f"({platform.machine()}, {os.cpu_count()} CPUs; {code_version()}; load average {load0:.1f} at the start: "
             "on this shared machine times vary by tens of percent, compare within a run); do not edit by hand.", "",
             "| scene | resolution | core | build_images [ms] (best) | image triangles (order 1 / 2) | "
             "pieces the refine step cut | pieces beyond the budget after it (worst) | mismatch / covered | "
             "screen err p50 / p99 / max [px] | c*dt rel. err p99 / max | checker pixels wrong / torn | "
             "pieces inside: screen p99 / max [px] | pieces inside: c*dt rel. p99 / max | "
             "GR irradiance interpolated, rel. err p99 / max | reference [s] |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    print("\n".join(lines), flush=True)
    for res in args.resolutions.split(","):
        w, h = (int(v) for v in res.lower().split("x"))
        cam = camera(w, h)
        for name in names:
            lines += run(name, meshes[name], cam, table, variants, args.repeat, light_table)
    if args.write:
        path = os.path.join(ROOT, "docs", "coarse.md")
        head = ["# Coarse meshes against the per-pixel reference", "", *__doc__.split("\n\n")[1:4], ""]
        with open(path, "w") as f:
            f.write("\n".join(head + lines) + "\n")
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
