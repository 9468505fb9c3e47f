"""A camera that moves, seen for the first time: the orbit table (one table for every radius) against the
family of exact tables, per frame, against a static camera; and the orbit table's costs and errors.

Part 1 (the options, in the units of docs/tables.md): the orbit table of lutgen.rays (built once per
process): build time, memory, the per-radius setup of a RayMap (and with the segments it makes when a
point first needs them), the lookup time of 1e5 random points
(both orders, xi/dt/ux/uy; the family's table for the same radius measured in the same run), the
fixed cost of a lookup call (one point, both orders; the family's too) and the
largest |xi - xi_exact| against lutgen.connect in docs/tables.md's four regions, observer at 20 r_s.
Inside the photon sphere (1.05, 1.2, 1.4 r_s) no closed-form solver exists: each ray the table gives
is shot with the DOP853 integrator (lutgen.reference.shoot) until it has swept the target's angle;
the table prints the largest miss in u = r_s/r and in the travel time.

Part 3 (images and sky against the reference ray tracer inside the photon sphere, in the units of
docs/accuracy.md): the floor of tests/meshes.grid (60 x 60 r_s, 2 r_s below the hole) and the paper's
sphere at 3 r_s, seen from 1.6, 1.4, 1.2 and 1.05 r_s at elevation 25 degrees, looking away from the
hole and down (90 degrees, 320x180): coverage mismatch, screen error p99, the lensed sky's direction
error p99 and the pixels where grlens' shadow differs from the reference's.

Part 2 (per frame, numeric core, the paper's sphere of radius 0.5 r_s on its 3 r_s orbit, 640x360, 19
degrees): a dolly from 30 to 6 r_s and a descent from 6 to 1.05 r_s, 12 frames each, as a first
pass (nothing built or cached before: a fresh family, a fresh RayMap per frame; the orbit table itself
is built once per process, before, and reported in part 1), a second pass (the same frames again, the
tables in memory) and a static camera at each frame's radius (its table made before; below 1.6 r_s,
where the add-on uses the orbit table in every mode, the orbit table's RayMap). Modes as the add-on's
``lut_mode``: EVERY_DISTANCE (the family; the orbit table below 1.6 r_s) and ONE_TABLE (the orbit
table for every radius). All figures of one run; the ratios are frame by frame (first pass / static).
The static camera and ONE_TABLE are timed best of 5 (BEST_OF) (ONE_TABLE's first pass with a new RayMap each
time, so both are first passes); EVERY_DISTANCE's first pass once (the second time its tables exist). Frames
are timed in the process's CPU time (the VM is shared: time waiting for a core is not counted), except
EVERY_DISTANCE's first pass, in wall time (its table builds use every core).

Usage: ./dev python benchmarks/bench_moving.py [--frames N] [--write]   (--write: its section of
docs/tables.md, between the markers, replaced)
Units: ms (frames, setup), s (builds), MB, ms per 1e5 points, radians.
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
from bench_tables import _errors, _regions, _timed  # noqa: E402
from grlens_addon.core import mapping, pipeline  # noqa: E402
from lutgen import rays, reference  # noqa: E402
from provenance import code_version  # noqa: E402

OUT = os.path.join(os.path.dirname(__file__), "..", "docs", "tables.md")
BEGIN, END = "<!-- bench_moving: begin -->", "<!-- bench_moving: end -->"
FAMILY_MIN = 1.6  # as grlens_addon.blender.lutcache.FAMILY_MIN (the add-on is not imported here: bpy)
BEST_OF = 5  # the static camera's and ONE_TABLE's frames: the best of this many (the VM is shared)


def cpu():
    """The process's CPU time (s): the frames' clock, so that time spent waiting for a core of the shared
    VM is not counted (the frames are single-threaded)."""
    return time.process_time()


def options(rng):
    t0 = time.perf_counter()
    table = rays.OrbitTable()
    t_build = time.perf_counter() - t0
    rays._TABLES[(rays.DEFAULT_STEP, rays.DEFAULT_COLUMNS)] = table
    setup, setup_all = [], []
    for r in np.geomspace(1.02, 1e4, 25):
        t0 = cpu()
        m = rays.RayMap(float(r), table=table)
        setup.append(1e3 * (cpu() - t0))
        for i in np.flatnonzero(~m._built):  # the segments made when a point first needs them
            if m._twins()[i] == i:
                m._build(i)
        setup_all.append(1e3 * (cpu() - t0))
    regions = _regions(rng)
    exact = {name: {o: lutgen.connect(20.0, r, p, o) for o in (1, 2)} for name, (r, p) in regions.items()}
    rm = rays.RayMap(20.0, table=table)
    r_all = 10 ** rng.uniform(np.log10(1.06), 4, 100000)
    p_all = rng.uniform(0, np.pi, 100000)
    look, _ = _timed(lambda: rm.lookup_orders(r_all, p_all))
    fam_table = lutgen.LUTFamily().at(20.0)
    fam_table.lookup_orders(r_all, p_all)
    fam_look, _ = _timed(lambda: fam_table.lookup_orders(r_all, p_all))
    # the fixed cost of one lookup call (both orders, one point): what a frame's few calls pay besides
    # the per-point cost
    one_r, one_p = np.array([7.0]), np.array([1.0])
    call, _ = _timed(lambda: rm.lookup_orders(one_r, one_p), repeat=20)
    fam_call, _ = _timed(lambda: fam_table.lookup_orders(one_r, one_p), repeat=20)
    err = _errors(rm.lookup_orders, regions, exact)
    inside = {}
    for r_obs in (1.05, 1.2, 1.4):
        m = rays.RayMap(r_obs, r_min=1.02, table=table)
        r = 10 ** rng.uniform(np.log10(1.03), 2, 40)
        p = rng.uniform(0.02, np.pi - 0.02, r.size)
        got = m.lookup_orders(r, p)
        du = dt = 0.0
        for o in (1, 2):
            for i in range(r.size):
                sweep = p[i] if o == 1 else 2 * np.pi - p[i]
                shot = reference.shoot(r_obs, got[o].xi[i], side=1 if o == 1 else -1, phi_end=sweep, r_escape=1e6)
                du = max(du, abs(1.0 / shot.r - 1.0 / r[i]))
                slack = abs(lutgen.wide_lut.tortoise(shot.r) - lutgen.wide_lut.tortoise(r[i]))
                dt = max(dt, max(0.0, abs(shot.dt - got[o].dt[i]) - slack) / got[o].dt[i])
        inside[r_obs] = (du, dt)
    return dict(t_build=t_build, mb=table.nbytes / 2**20, setup=np.array(setup), setup_all=np.array(setup_all),
                look=1e3 * look,
                fam_look=1e3 * fam_look, call=1e3 * call, fam_call=1e3 * fam_call, err=err, inside=inside)


def inside_accuracy(width=320, height=180):
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests"))
    from meshes import grid

    from grlens_addon.core import frame_check, raytrace

    pts, tris = uv_sphere(radius=0.5)
    rows = []
    for r_obs in (1.6, 1.4, 1.2, 1.05):
        el = math.radians(25.0)
        pos = np.array([r_obs * math.cos(el), 0.0, r_obs * math.sin(el)])
        cam = raytrace.Camera.look_at(pos, 3.0 * pos + np.array([0.0, 0.0, -2.5]), math.radians(90.0), width, height)
        sphere = pipeline.SourceMesh(pts + np.array([3.0 * math.cos(0.3), 3.0 * math.sin(0.3), 0.0]), tris)
        floor = grid(-30, 30, -30, 30, 40, 40, "z", -2.0)
        check = frame_check.check_frame([floor, sphere], mapping.Scene(cam.position, np.zeros(3), 1.0),
                                        rays.RayMap(r_obs, r_min=1.02), pipeline.Settings(64, 5.0, 0.75, 8.0), cam,
                                        sky=frame_check.lensed_world_sky(np.zeros(3), 1.0))
        m, sky = check.metrics["orders"]["all"], check.metrics["sky"]
        rows.append((r_obs, m["covered_ref"], m["mismatch_frac"], m["screen_px"]["p99"], sky["sky_angle_px"]["p99"],
                     sky["shadow_mismatch"], sky["fell_ref"], check.reference_seconds, check.polygon_seconds))
        print(r_obs, check.summary(), flush=True)
    return rows


def _frames(r0, r1, frames):
    pts, tris = uv_sphere(radius=0.5)
    out = []
    for i, r in enumerate(np.linspace(r0, r1, frames)):
        a = math.radians(60.0 + 3.0 * i)
        out.append((float(r), pipeline.SourceMesh(pts + np.array([3 * math.cos(a), 3 * math.sin(a), 0.01]), tris)))
    return out


def shot(r0, r1, frames):
    """Per frame [ms]: static, and first and second pass of each mode."""
    settings = pipeline.Settings(max_tess_level=64, tess_a=5.0, tess_b=0.75, cull_ratio=8.0,
                                 pixel_angle=math.radians(19.0) / 360)
    todo = _frames(r0, r1, frames)
    table = rays.orbit_table()

    def every_distance():
        fam, maps = lutgen.LUTFamily(max_slices=1000), {}

        def get(r):
            if r < FAMILY_MIN:
                return maps.setdefault(r, rays.RayMap(r, table=table))
            return maps.setdefault(r, fam.at(r))
        return get, fam

    def one_table():
        maps = {}
        return lambda r: maps.setdefault(r, rays.RayMap(r, table=table)), None

    out = {}
    # the static camera: its table made before (a separate family), timed best of BEST_OF beside every frame
    static_get, _ = every_distance()
    for r, _src in todo:
        static_get(r)
    ed_get, ed_fam = every_distance()
    ot_get, _ = one_table()
    solved = windowed = 0  # ONE_TABLE's points, and those its seed window bracketed
    for label in ("first", "second"):  # interleaved frame by frame: the VM's speed drifts
        st, ed, ot = [], [], []
        for r, src in todo:
            scene = mapping.Scene([r, 0, 0], [0, 0, 0], 1.0)
            ts = []
            for _ in range(BEST_OF):
                t0 = cpu()
                pipeline.build_images(src, scene, static_get(r), settings)
                ts.append(1e3 * (cpu() - t0))
            st.append(min(ts))
            if label == "first":  # best of BEST_OF as the static camera's: each a fresh RayMap (nothing kept)
                ts = []
                for _ in range(BEST_OF):
                    t0 = cpu()
                    rm = rays.RayMap(r, table=table)
                    pipeline.build_images(src, scene, rm, settings)
                    ts.append(1e3 * (cpu() - t0))
                ot.append(min(ts))
                solved += rm.solved
                windowed += rm.windowed
                ot_get(r)  # the second pass's, made outside the timing
            else:
                ts = []
                for _ in range(BEST_OF):
                    t0 = cpu()
                    pipeline.build_images(src, scene, ot_get(r), settings)
                    ts.append(1e3 * (cpu() - t0))
                ot.append(min(ts))
            # the family last: its first pass builds tables (threads, much memory) that would disturb
            # the timings after it (that pass in wall time: its builds use every core)
            clock = time.perf_counter if label == "first" else cpu
            t0 = clock()
            pipeline.build_images(src, scene, ed_get(r), settings)
            ed.append(1e3 * (clock() - t0))
        out["static", label] = np.array(st)
        out["EVERY_DISTANCE", label] = np.array(ed)
        out["ONE_TABLE", label] = np.array(ot)
    out["EVERY_DISTANCE", "built"] = ed_fam.built
    out["ONE_TABLE", "built"] = 0
    out["window"] = windowed / max(solved, 1)
    out["static"] = out["static", "first"]
    return out


def report(opt, shots, frames, acc):
    regions = ["1.05-3 r_s", "3-10 r_s", "40-1e4 r_s", "beside the camera"]
    e = opt["err"]
    lines = [BEGIN, f"<!-- generated by benchmarks/bench_moving.py on {code_version()} -->", "",
             "## One table for every radius: the orbit table", "",
             "From `./dev python benchmarks/bench_moving.py --write` (the figures of one run; compare them within "
             "it: this 2-core VM's speed varies by up to 2x from day to day, and the runs share it). The orbit "
             "table (`lutgen.rays`, `scene.grlens.lut_mode = \"ONE_TABLE\"`) holds every light orbit once, keyed by "
             "its impact parameter, and each point's ray is solved from it (docs/inside.md).", "",
             "| option | build [s] | memory [MB] | lookup [ms / 1e5] | 1.05-3 r_s | 3-10 r_s | 40-1e4 r_s "
             "| beside the camera | note |", "|---|---|---|---|---|---|---|---|---|",
             f"| orbit table, every radius from 1.001 to 1e7 r_s, a 1-D solve per point | {opt['t_build']:.2f} "
             f"(once) | {opt['mb']:.0f} | {opt['look']:.0f} | "
             + " | ".join(f"{e[k]:.1e}" for k in regions)
             + f" | per new radius {np.median(opt['setup']):.1f} ms (max {opt['setup'].max():.1f}), "
               f"{np.median(opt['setup_all']):.1f} ms with every segment's nodes (some are made when a point "
               f"first needs them); the family's "
               f"table for 20 r_s looks the same points up in {opt['fam_look']:.0f} ms in this run; one call "
               f"with one point {opt['call']:.2f} ms (the family's table {opt['fam_call']:.2f} ms) |", "",
             "Inside the photon sphere, the table's rays shot with the DOP853 integrator to the target's swept "
             "angle (40 targets, both orders): largest miss in u = r_s/r, and in the travel time (relative, "
             "beyond the distance between the shot's end and the target along the ray):", "",
             "| observer [r_s] | miss in u | travel time |", "|---|---|---|"]
    for r_obs, (du, dt) in opt["inside"].items():
        lines.append(f"| {r_obs} | {du:.1e} | {dt:.1e} |")
    lines += ["", "### Images and sky inside the photon sphere against the reference ray tracer (320x180)", "",
              "The floor (60 x 60 r_s, 2 r_s below the hole) and the paper's sphere on its 3 r_s orbit, seen from "
              "elevation 25 degrees, looking away from the hole and down (90 degrees); the units and targets of "
              "docs/accuracy.md (mismatch under 0.5% of the covered pixels, screen error p99 under 0.5 px). The "
              "reference tracer's curves are closed forms on the inner branch too (checked against the DOP853 "
              "integrator), and the exact image positions come from lutgen.connect, which solves inside the "
              "photon sphere too.", "",
              "| observer [r_s] | covered px | mismatch | screen error p99 [px] | sky p99 [px] | shadow differs "
              "[px] | shadow [px] | reference [s] | grlens [ms] |", "|---|---|---|---|---|---|---|---|---|"]
    for r_obs, cov, mis, scr, sky, shm, fell, t_ref, t_poly in acc:
        lines.append(f"| {r_obs} | {cov} | {100 * mis:.2f}% | {scr:.3f} | {sky:.1e} | {shm} | {fell} | {t_ref:.1f} | "
                     f"{1e3 * t_poly:.0f} |")
    lines += ["", f"### A camera that moves, seen for the first time ({frames} frames per shot, 640x360, the "
                  "paper's sphere)", "",
              "Per frame, numeric core (table for the frame's radius + build_images). Static: the camera at that "
              "radius with its table already made (the family's; below 1.6 r_s the orbit table's). First pass: "
              "nothing built or cached before (the orbit table itself is built once per process, part of no "
              "frame here: its build is the row above). Ratios frame by frame against the static camera, timed "
              f"beside each frame (best of {BEST_OF}; ONE_TABLE's first pass too, each time with a new RayMap, its "
              "second pass with the one made before; EVERY_DISTANCE's first pass once: its tables are then built), "
              "in the process's CPU time (the VM is shared: time waiting for a core is not counted), except "
              "EVERY_DISTANCE's first pass, in wall time (its table builds use every core).", "",
              "| shot | mode | first pass median [ms] | max [ms] | first / static: median | max | second / static: "
              "median | max | exact tables built |", "|---|---|---|---|---|---|---|---|---|"]
    for name, d in shots.items():
        st = d["static"]
        lines.append(f"| {name} | static camera | {np.median(st):.1f} | {st.max():.1f} | 1 | 1 | 1 | 1 | |")
        for mode in ("EVERY_DISTANCE", "ONE_TABLE"):
            f, s = d[mode, "first"], d[mode, "second"]
            rf, rs = f / st, s / d["static", "second"]
            lines.append(f"| {name} | {mode} | {np.median(f):.1f} | {f.max():.1f} | {np.median(rf):.2f} | "
                         f"{rf.max():.2f} | {np.median(rs):.2f} | {rs.max():.2f} | {d[mode, 'built']} |")
    lines += ["", "Per frame of the descent, first pass / static (EVERY_DISTANCE, ONE_TABLE): "
              + ", ".join(f"{r:.2f} r_s {a:.1f}/{b:.1f}" for r, a, b in zip(
                  np.linspace(6.0, 1.05, frames), shots["descent 6 to 1.05 r_s"]["EVERY_DISTANCE", "first"]
                  / shots["descent 6 to 1.05 r_s"]["static"],
                  shots["descent 6 to 1.05 r_s"]["ONE_TABLE", "first"] / shots["descent 6 to 1.05 r_s"]["static"])),
              "", "ONE_TABLE's seed index (one per radius, over the whole sky): its window of four rows bracketed "
              + " and ".join(f"{100 * d['window']:.1f}% of the points solved in the {name}"
                             for name, d in shots.items())
              + " (the others: the segments' ends, then a search over the rows).",
              "", END]
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--write", action="store_true", help="replace this benchmark's section of docs/tables.md")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    rng = np.random.default_rng(0)
    opt = options(rng)
    acc = inside_accuracy()
    shots = {"dolly 30 to 6 r_s": shot(30.0, 6.0, args.frames), "descent 6 to 1.05 r_s": shot(6.0, 1.05, args.frames)}
    text = report(opt, shots, args.frames, acc)
    print(text)
    if args.write:
        with open(OUT) as f:
            old = f.read()
        if BEGIN in old:
            old = old[:old.index(BEGIN)] + old[old.index(END) + len(END) + 1:]
        with open(OUT, "w") as f:
            f.write(old.rstrip("\n") + "\n\n" + text)
        print(f"wrote {os.path.relpath(OUT)}")


if __name__ == "__main__":
    main()
