"""Which table for every distance and a moving camera: the options' costs, and a dolly against a static camera.

Part 1 (the options, for an observer at 20 r_s): build time, memory, lookup time of 1e5 random points
(both orders, xi/dt/ux/uy) and the direction error |xi - xi_exact| (rad) against lutgen.connect in
four regions (next to the hole 1.05-3 r_s; 3-10 r_s; far 40-1e4 r_s; beside the camera, within
0.02-0.5 r_obs of it), for
  * the former default, a fixed-range LUT (256x512 over 1.05-40 r_s, built per camera radius);
  * a fixed-range LUT sized to reach 1e4 r_s (256x512 over 1.05-1e4 r_s);
  * the wide table (lutgen.wide_lut, default size) for this radius;
  * the family's interpolated table (LUTFamily.at) and what making it costs per radius;
  * exact lutgen.connect per point;
  * a table over the observer radius built for every radius at once (the family, all nodes);
  * one table for all radii keyed on (1/b, 1/r) with a 1-D root find per point (not built here: its
    lookup costs at least one table lookup per iteration; the row gives 12 lookups, measured).
Part 2 (images against the reference ray tracer, in the units of docs/accuracy.md): a floor from
150 r_s behind the hole to beside the camera, the same floor reaching 1e4 r_s, a wall beside the
camera and a floor under it (tests/meshes.grid; camera at 20 r_s, 640x360), rendered by the polygon
method with the family's table and by core.raytrace: coverage mismatch and screen error p99 (px).
Part 3 (the add-on's per-frame cost, numeric core): the paper's sphere (radius 0.5 r_s, 1224
triangles, orbit 3 r_s, 1 deg per frame) while the camera dollies from 30 to 6 r_s over --frames
frames, at 640x360 with a 19 deg field of view: per frame, the family's table for the new radius
plus build_images (moving) against build_images with the table of that radius already made (a
static camera there), alternated in one process; the exact tables the dolly needed, built once.

Usage: ./dev python benchmarks/bench_tables.py [--frames N] [--write]   (--write: docs/tables.md)
Units: r_s, radians, milliseconds / seconds as labelled.
"""
import argparse
import math
import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(__file__))

import lutgen  # noqa: E402
from bench_frame import uv_sphere  # noqa: E402
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
from grlens_addon.core import frame_check, mapping, pipeline, raytrace  # noqa: E402
from meshes import grid  # noqa: E402
from lutgen import wide_lut  # noqa: E402
from provenance import code_version  # noqa: E402

R_OBS = 20.0
OUT = os.path.join(os.path.dirname(__file__), "..", "docs", "tables.md")


def _regions(rng, n=4000):
    def beside(n):
        d = R_OBS * 10 ** rng.uniform(np.log10(0.02), np.log10(0.5), n)
        a = rng.uniform(0, np.pi, n)
        x, y = R_OBS + d * np.cos(a), d * np.sin(a)
        return np.hypot(x, y), np.arctan2(y, x)
    return {"1.05-3 r_s": (rng.uniform(1.05, 3, n), rng.uniform(0, np.pi, n)),
            "3-10 r_s": (rng.uniform(3, 10, n), rng.uniform(0, np.pi, n)),
            "40-1e4 r_s": (10 ** rng.uniform(np.log10(40), 4, n), rng.uniform(0, np.pi, n)),
            "beside the camera": beside(n)}


def _timed(f, repeat=3):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _errors(lookup_orders, regions, exact):
    row = {}
    for name, (r, p) in regions.items():
        worst = []
        got = lookup_orders(r, p)
        for o in (1, 2):
            ok = np.isfinite(exact[name][o].xi)
            g = got[o].xi[ok]
            missing = np.isnan(g).mean()
            if missing > 0.5:
                worst.append(None)
                continue
            worst.append(np.nanmax(np.abs(g - exact[name][o].xi[ok])))
        row[name] = None if None in worst else max(worst)
    return row


def options(rng):
    regions = _regions(rng)
    exact = {name: {o: lutgen.connect(R_OBS, r, p, o) for o in (1, 2)} for name, (r, p) in regions.items()}
    r_all = 10 ** rng.uniform(np.log10(1.06), 4, 100000)
    p_all = rng.uniform(0, np.pi, 100000)
    rows = []

    def add(name, build_s, mb, table, note=""):
        look_s, _ = _timed(lambda: table.lookup_orders(r_all, p_all))
        rows.append((name, build_s, mb, 1e3 * look_s, _errors(table.lookup_orders, regions, exact), note))

    t, lut = _timed(lambda: lutgen.build_lut(R_OBS, 1.05, 40.0, 256, 512), 1)
    add("fixed range 1.05-40 r_s, 256x512 (former default; per radius)", t, lut.data.nbytes / 2**20, lut,
        "nothing beyond 40 r_s")
    t, lut = _timed(lambda: lutgen.build_lut(R_OBS, 1.05, 1e4, 256, 512), 1)
    add("fixed range 1.05-1e4 r_s, 256x512 (per radius)", t, lut.data.nbytes / 2**20, lut)
    t, wide = _timed(lambda: wide_lut.build_wide_lut(R_OBS), 1)
    add(f"wide table {wide.rows} x {wide.n_phi}, 1.05 r_s to infinity (per radius)", t, wide.data.nbytes / 2**20,
        wide)
    fam = lutgen.LUTFamily()
    t_nodes, _ = _timed(lambda: fam.at(R_OBS), 1)  # builds its four exact tables
    t_at, interp = _timed(lambda: fam.at(R_OBS), 5)  # a new interpolated table on every call
    add("family: wide tables at 1 + exp(k/8) r_s, interpolated (any radius)", t_at, 4 * wide.data.nbytes / 2**20,
        interp, f"per new radius {1e3 * t_at:.2f} ms + rows made on first lookup; its 4 exact tables built once "
                f"({t_nodes:.1f} s)")
    n_nodes = fam.k_hi - fam.k_lo + 1
    rows.append((f"the family's {n_nodes} exact tables for 1.51-1e5 r_s built at once (a 3-D table)",
                 n_nodes * t_nodes / 4, n_nodes * wide.data.nbytes / 2**20, rows[-1][3], rows[-1][4],
                 "build and memory from the per-table figures above"))
    sub = slice(0, 2000)
    t_c, _ = _timed(lambda: [lutgen.connect(R_OBS, r_all[sub], p_all[sub], o) for o in (1, 2)], 1)
    rows.append(("exact lutgen.connect per point", 0.0, 0.0, 1e3 * t_c * 50,
                 {k: 0.0 for k in regions}, "time scaled from 2000 points"))
    small = lutgen.build_lut(R_OBS, 1.05, 40.0, 256, 512)
    t12, _ = _timed(lambda: [small.lookup_orders(r_all, p_all, (1,), ("xi",)) for _ in range(12)], 1)
    rows.append(("one table in (1/b, 1/r), 1-D root find per point (not built)", None, None, 1e3 * t12,
                 {k: None for k in regions}, "12 single-quantity lookups per point, measured on a 256x512 table"))
    return rows


IMAGE_SCENES = {  # name: (source, camera target (BU, r_s = 1), vertical field of view (deg))
    "floor from 150 r_s behind the hole to the camera": (lambda: grid(-150, 15, -40, 40, 66, 32, "z", -3.0),
                                                          (0, 0, 0), 60),
    "floor reaching 1e4 r_s (log-spaced rows)": (
        lambda: _log_floor(), (0, 0, -1.5), 40),
    "wall beside the camera (r 12-28 r_s)": (lambda: grid(12, 28, -4, 4, 32, 16, "y", 3.0), (17, 3, -0.5), 70),
    "floor under the camera (r 8-40 r_s)": (lambda: grid(8, 40, -12, 12, 32, 24, "z", -2.0), (15, 0, -2), 80),
}


def _log_floor():
    """A floor 3 r_s below the hole from x = 15 r_s to -1e4 r_s (rows spaced geometrically), 200 r_s wide."""
    src = grid(0.0, 1.0, -100, 100, 60, 20, "z", -3.0)
    x = src.positions[:, 0]
    src.positions[:, 0] = 15.0 - (np.expm1(x * np.log1p(1e4 + 15.0)))
    return src


def images(width=640, height=360):
    fam = lutgen.LUTFamily()
    rows = []
    for name, (make, target, fov) in IMAGE_SCENES.items():
        cam = raytrace.Camera.look_at([R_OBS, 0.0, 0.0], target, math.radians(fov), width, height)
        scene = mapping.Scene(cam.position, np.zeros(3), 1.0)
        check = frame_check.check_frame([make()], scene, fam.at(R_OBS), pipeline.Settings(64, 5.0, 0.75, 8.0), cam)
        m = check.metrics["orders"]["all"]
        rows.append((name, m["covered_ref"], m["mismatch_frac"], m["screen_px"]["p99"], check.reference_seconds,
                     check.polygon_seconds))
        print(name, check.summary(), flush=True)
    return rows


def dolly(frames, rng):
    pts, tris = uv_sphere(radius=0.5)
    settings = pipeline.Settings(max_tess_level=64, tess_a=5.0, tess_b=0.75, cull_ratio=8.0,
                                 pixel_angle=math.radians(19.0) / 360)
    fam = lutgen.LUTFamily(max_slices=1000)  # keep every table the shot needs (steady state: scrubbing)
    radii = np.linspace(30.0, 6.0, frames)
    t0 = time.perf_counter()
    for r in radii:  # the exact tables the dolly needs, built once (a first pass through the shot)
        fam.at(float(r))
    t_build = time.perf_counter() - t0
    built = fam.built
    static_tables = {}
    moving, static, n_tris = [], [], []
    warm = pipeline.SourceMesh(pts + np.array([3.0, 0.0, 0.01]), tris)
    pipeline.build_images(warm, mapping.Scene([20.0, 0, 0], [0, 0, 0], 1.0), fam.at(20.0), settings)
    for i, r in enumerate(radii):
        a = math.radians(60.0 + i)
        src = pipeline.SourceMesh(pts + np.array([3 * math.cos(a), 3 * math.sin(a), 0.01]), tris)
        scene = mapping.Scene([float(r), 0, 0], [0, 0, 0], 1.0)
        static_tables[i] = fam.at(float(r))
        pipeline.build_images(src, scene, static_tables[i], settings)  # the static camera's table is made
        for first in (("moving", "static") if i % 2 else ("static", "moving")):
            if first == "moving":
                t0 = time.perf_counter()
                out = pipeline.build_images(src, scene, fam.at(float(r)), settings)
                moving.append(time.perf_counter() - t0)
            else:
                t0 = time.perf_counter()
                out = pipeline.build_images(src, scene, static_tables[i], settings)
                static.append(time.perf_counter() - t0)
        n_tris.append(sum(len(m.tris) for m in out.values()))
        static_tables.pop(i)
    assert fam.built == built, "the dolly built a table while timed"
    m, s = 1e3 * np.array(moving), 1e3 * np.array(static)
    fixed = []
    for r in radii[:: max(1, frames // 4)][:4]:  # the former mode: a new table every frame
        t0 = time.perf_counter()
        lut = lutgen.build_lut(float(r), 1.05, 40.0, 256, 512)
        a = math.radians(60.0)
        pipeline.build_images(pipeline.SourceMesh(pts + np.array([3 * math.cos(a), 3 * math.sin(a), 0.01]), tris),
                              mapping.Scene([float(r), 0, 0], [0, 0, 0], 1.0), lut, settings)
        fixed.append(time.perf_counter() - t0)
    return dict(frames=frames, built=built, t_build=t_build, moving=m, static=s, ratio=m / s, tris=np.array(n_tris),
                fixed=1e3 * np.array(fixed))


def _fmt(v, spec):
    return "n/a" if v is None else format(v, spec)


def report(rows, img, d):
    lines = [f"<!-- generated by benchmarks/bench_tables.py on {code_version()} -->",
             "# Tables for every distance and a moving camera", "",
             "From `./dev python benchmarks/bench_tables.py --write` (the figures below are that run's; this "
             "2-core VM's speed varies by up to 2x from day to day). Units: seconds (build), MB (float64 "
             "tables), ms per 1e5 points (both orders, all four quantities), radians (largest |xi - xi_exact| "
             "against `lutgen.connect`, both orders; n/a: the table does not reach there).", "",
             "## The options (observer at 20 r_s)", "",
             "| option | build [s] | memory [MB] | lookup [ms / 1e5] | 1.05-3 r_s | 3-10 r_s | 40-1e4 r_s "
             "| beside the camera | note |", "|---|---|---|---|---|---|---|---|---|"]
    regions = ["1.05-3 r_s", "3-10 r_s", "40-1e4 r_s", "beside the camera"]
    for name, b, mb, look, err, note in rows:
        lines.append(f"| {name} | {_fmt(b, '.3g')} | {_fmt(mb, '.3g')} | {_fmt(look, '.0f')} | "
                     + " | ".join(_fmt(err[k], '.1e') for k in regions) + f" | {note} |")
    lines += ["", "1 px of docs/accuracy.md's 640x360 view (19 deg) is 9.2e-4 rad; of a 1920x1080 view with a 20 deg "
              "field of view, 1.6e-5 rad.", "",
              "## Images against the reference ray tracer (640x360, camera at 20 r_s)", "",
              "The family's table for 20 r_s; the units and targets of docs/accuracy.md (coverage mismatch under "
              "0.5% of the covered pixels, screen error p99 under 0.5 px).", "",
              "| scene | covered px | mismatch | screen error p99 [px] | reference [s] | grlens [ms] |",
              "|---|---|---|---|---|---|"]
    for name, cov, mis, scr, t_ref, t_poly in img:
        lines.append(f"| {name} | {cov} | {100 * mis:.2f}% | {scr:.3f} | {t_ref:.1f} | {1e3 * t_poly:.0f} |")
    lines += ["", f"## A dolly from 30 to 6 r_s over the paper's sphere ({d['frames']} frames, 640x360)", "",
              f"Exact tables the shot needs: {d['built']}, built once in {d['t_build']:.1f} s (a table "
              "is built when the camera first comes within two steps of its radius; pack them with "
              "`bpy.ops.grlens.pack_lut()` per radius or let each process build its own: they are identical).", "",
              "| per frame [ms] | median | mean | p95 | max |", "|---|---|---|---|---|"]
    for label, v in (("static camera (table of that radius already made)", d["static"]),
                     ("moving camera (family table for the new radius + build_images)", d["moving"])):
        lines.append(f"| {label} | {np.median(v):.1f} | {v.mean():.1f} | {np.percentile(v, 95):.1f} | {v.max():.1f} |")
    r = d["ratio"]
    lines += ["", f"Moving / static, frame by frame: median {np.median(r):.2f}, mean {r.mean():.2f}, "
                  f"p95 {np.percentile(r, 95):.2f}, max {r.max():.2f}; mean of all moving frames over mean of all "
                  f"static frames {d['moving'].mean() / d['static'].mean():.2f}. Image triangles per frame "
                  f"{d['tris'].min()}-{d['tris'].max()}.",
              "", f"The former mode (a new fixed-range 256x512 table every frame, then build_images): "
                  f"{', '.join(f'{v:.0f}' for v in d['fixed'])} ms on {len(d['fixed'])} frames of the dolly.",
              "", "## The choice", "",
              "The add-on's default (`scene.grlens.lut_mode = \"EVERY_DISTANCE\"`) is the family, for these "
              "reasons, all from the tables above:",
              "",
              "* Every distance: a fixed-range table either stops at r_max (the former default drops everything "
              "beyond 40 r_s) or, stretched to 1e4 r_s, loses accuracy far out; both are off by order 1 rad "
              "beside the camera when their range contains its radius. The wide table reaches infinity and "
              "is as accurate beside the camera as elsewhere (a polar table about the observer, in which what "
              "remains after the chord's angle is subtracted is smooth).",
              "* A moving camera: any table made per radius costs its build every frame (the former mode's "
              "figures at the end of the dolly section). Exact `connect` per point costs about 50-100x the lookups, every frame. A table in "
              "(1/b, 1/r) would serve every radius with one table, but its root find per point costs at "
              "least a dozen lookups per point and iteration counts that depend on the point: several times "
              "the present mapping, with no error advantage. A table over the observer radius built at once "
              "costs minutes and hundreds of MB (its row above). The family builds that 3-D table lazily: only the exact tables "
              "near the radii the camera visits, once each, kept in memory; per frame it costs a few "
              "microseconds plus interpolating the table rows a frame's points touch.",
              "* Farms: the family's tables depend only on their radius, so every process computes the same "
              "geometry for the same frame, whether a table was packed, cached or built. Packing stores the "
              "four exact tables one frame needs (float64, exact); a shot's worth is not packed by default "
              "(about 7 MB per table).",
              "",
              "The cost: the first pass of a moving camera through a range of distances builds one exact "
              "table per 1/8 of ln(r_obs - 1) (about six per doubling of the distance far out), each about "
              "as long as one former table; lookups in the wide table take somewhat longer than in the "
              "former one (its stencils add the chord's angle and travel time)."]
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--write", action="store_true", help="write docs/tables.md")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    rng = np.random.default_rng(0)
    text = report(options(rng), images(), dolly(args.frames, rng))
    print(text)
    if args.write:
        kept = ""  # the section of benchmarks/bench_moving.py stays
        if os.path.exists(OUT):
            with open(OUT) as f:
                old = f.read()
            begin, end = "<!-- bench_moving: begin -->", "<!-- bench_moving: end -->"
            if begin in old and end in old:
                kept = "\n" + old[old.index(begin):old.index(end) + len(end)] + "\n"
        with open(OUT, "w") as f:
            f.write(text + kept)
        print(f"wrote {os.path.relpath(OUT)}")


if __name__ == "__main__":
    main()
