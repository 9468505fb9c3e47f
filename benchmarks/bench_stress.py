"""Stress benchmark (issue 5, part 4): the full-size cases of tests/test_stress.py, as tables.

* lutgen: 10^6 adversarial points (on and within 1e-9 of the horizon, at the photon sphere +- 1e-12,
  at r_min / r_max +- 1e-12, far to 1e300 and the largest double, phi at and within 1e-15 of 0 and pi,
  NaN, inf, negative) per observer r_obs = 1.6, 2, 3, 20, 100, 1000 r_s: LUT.lookup of a 256x512 table
  (float64 and float32 input), and lutgen.connect on 10^6 points in all (both orders). Counted:
  finite, NaN by the documented rule, NaN where the rule says finite, inf.
* pipeline.build_images, each case in a fresh process (so ru_maxrss is the case's own peak): a
  10^6-triangle UV sphere behind the hole (Einstein ring, default settings at 640x360, frustum), a
  soup of 10^6 adversarial vertices, and random adversarial scenes (r_obs in [1.6, 1000] r_s, r_s in
  [1e-3, 1e3] BU, float32/float64, with and without frustum, point light) of 10^6 vertices. Per
  order: faces, culled triangles by reason, bad source triangles, the extra faces made by subdivision
  (F - S), whether the accounting identity kept + culled + bad = T + (F - S) and every finiteness check
  of tests/test_stress.check_images hold, time and peak RSS.

Memory over a 1000-frame animation is measured in Blender by benchmarks/bench_addon.py (its memory
section); it is not repeated here.

Usage: ./dev python benchmarks/bench_stress.py [--quick] [--skip-lutgen] [--skip-pipeline]
(--quick: 10^5 instead of 10^6.)

Last full run (2 CPUs, 2.5 minutes in all): lookups of 10^6 points take 1.2-2.6 s per observer,
with no NaN inside a table, nothing finite outside, no inf; connect needs 6 s (order 1) and 2-3 s
(order 2) per 1.7e5 points, and every non-finite result of a valid point has one of the known causes
('other' 0). build_images: the 10^6-triangle sphere behind the hole in 9 s at +1.1 GB peak RSS
(about 1.1 KB per source triangle), the 10^6-vertex soup in 13 s at +1.3 GB, the random scenes in
3.5-8 s at +0.6 to +0.9 GB; all checks and the accounting identity hold.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
import warnings

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from grlens_addon.core import pipeline  # noqa: E402
from lutgen import build_lut, connect  # noqa: E402
from tests import test_stress as ts  # noqa: E402


def _rss_mb():
    return ts.peak_rss_mb()


# ---------------------------------------------------------------------------------------------------
# lutgen
# ---------------------------------------------------------------------------------------------------
def lutgen_tables(n_points):
    rng = np.random.default_rng(7)
    print(f"\n## LUT.lookup, 256x512 tables (r_min = 1 + 1e-9, r_max = 2 r_obs + 10), {n_points} adversarial "
          "points per observer, both orders\n")
    print("| r_obs | input | build [s] | lookup [s] | inside (finite) | outside (NaN) | NaN inside | "
          "finite outside | inf |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r_obs in ts.R_OBS:
        t0 = time.perf_counter()
        lut = build_lut(r_obs, 1 + 1e-9, 2 * r_obs + 10, 256, 512)
        t_build = time.perf_counter() - t0
        r, phi = ts.adversarial_polar(n_points, rng, r_obs, lut.r_min, lut.r_max)
        for dtype in (np.float64, np.float32):
            with np.errstate(over="ignore"):
                rr, pp = r.astype(dtype), phi.astype(dtype)
            inside = ts._lookup_inside(lut, rr.astype(np.float64), pp.astype(np.float64))
            t0 = time.perf_counter()
            both = lut.lookup_orders(rr, pp, (1, 2))
            t_look = time.perf_counter() - t0
            nan_in = fin_out = inf = 0
            for look in both.values():
                for v in look:
                    nan_in += int((~np.isfinite(v[inside])).sum())
                    fin_out += int(np.isfinite(v[~inside]).sum())
                    inf += int(np.isinf(v).sum())
            print(f"| {r_obs:g} | {np.dtype(dtype).name} | {t_build:.2f} | {t_look:.2f} | {int(inside.sum())} | "
                  f"{int((~inside).sum())} | {nan_in} | {fin_out} | {inf} |")

    per = n_points // len(ts.R_OBS)
    print(f"\n## lutgen.connect, {per} adversarial points per observer ({per * len(ts.R_OBS)} in all)\n")
    print("Rule: NaN exactly where r <= 1 or the input is NaN/inf/outside [0, pi], finite elsewhere. Valid "
          "points whose result is not finite, by known cause (the xfail tests of tests/test_stress.py): "
          "order 1 with 0 < phi < 1e-30; order 1 within 1e-12 r_obs and 1e-6 rad of the observer; r within "
          "1e-15 of the horizon; r >= 1e14 r_s (and the radial ray to r > 1e307). 'other' must be 0.\n")
    print("| r_obs | order | time [s] | valid | finite | invalid -> NaN | invalid not NaN | tiny phi | "
          "at observer | r - 1 < 1e-15 | far | other | of which inf |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r_obs in ts.R_OBS:
        r, phi = ts.adversarial_polar(per, rng, r_obs, 1 + 1e-9, 2 * r_obs + 10)
        valid = ts._connect_rule(r, phi)
        with np.errstate(invalid="ignore"):
            tiny = (phi > 0) & (phi < 1e-30)
            at_obs = (np.abs(r / r_obs - 1.0) < 1e-12) & (np.abs(phi) < 1e-6)
            ulp = r < 1 + 1e-15
            far = r >= 1e14
        for order in (1, 2):
            t0 = time.perf_counter()
            c = connect(r_obs, r, phi, order)
            t = time.perf_counter() - t0
            fin = np.all([np.isfinite(v) for v in c], axis=0)
            nan_all = np.all([np.isnan(v) for v in c], axis=0)
            inf = np.any([np.isinf(v) for v in c], axis=0)
            bad = valid & ~fin
            causes = []
            left = bad.copy()
            for m in ((tiny if order == 1 else np.zeros_like(bad)), (at_obs if order == 1 else np.zeros_like(bad)),
                      ulp, far):
                causes.append(int((left & m).sum()))
                left &= ~m
            print(f"| {r_obs:g} | {order} | {t:.1f} | {int(valid.sum())} | {int((valid & fin).sum())} | "
                  f"{int((~valid & nan_all).sum())} | {int((~valid & ~nan_all).sum())} | "
                  + " | ".join(str(k) for k in causes) + f" | {int(left.sum())} | {int((valid & inf).sum())} |")


# ---------------------------------------------------------------------------------------------------
# pipeline (children)
# ---------------------------------------------------------------------------------------------------
def child_random(seed, n_tris):
    scene, lut, settings, frustum, src, light = ts.random_case(seed, n_tris, big_shells=True)
    settings.max_tess_level = min(settings.max_tess_level, 2)
    rss1 = _rss_mb()
    with ts.SubdivideSpy() as spy:
        t0 = time.perf_counter()
        out = pipeline.build_images(src, scene, lut, settings, light, frustum)
        t = time.perf_counter() - t0
    rss2 = _rss_mb()
    pos = np.asarray(src.positions)
    desc = (f"random seed {seed}: r_obs {scene.r_obs:.4g}, r_s {scene.r_s:.3g}, {pos.dtype.name}, "
            f"{'no frustum' if frustum is None or not len(frustum) else 'frustum'}"
            f"{', light' if light is not None else ''}, level <= {settings.max_tess_level}")
    return _result(desc, src, out, scene, settings, spy.calls, light, t, rss1, rss2)


def _result(desc, src, out, scene, settings, calls, light, t, rss1, rss2):
    try:
        orders = ts.check_images(out, src, scene, settings, list(calls), light)
        status = "ok"
    except AssertionError as exc:  # report, do not hide the case
        status = "FAIL: " + " ".join(str(exc).split())[:200]
        orders = {o: dict(faces=len(img.tris), kept=img.report.kept, invalid_vertex=img.report.invalid_vertex,
                          degenerate_source=img.report.degenerate_source, einstein_ring=img.report.einstein_ring,
                          outside_frustum=img.report.outside_frustum, below_pixel=img.report.below_pixel,
                          bad_source=img.report.extra.get("bad_source_triangles"), split_extra=None)
                  for o, img in out.items()}
    return dict(case=desc, source_triangles=len(src.tris), source_vertices=len(src.positions), orders=orders,
                time_build_s=t, rss_before_mb=rss1, rss_peak_mb=rss2, status=status)


def child_named(name, *args):
    if name == "random":
        return child_random(*args)
    res = getattr(ts, name)(*args)  # big_mesh_case / soup_case: check_images inside (raises on failure)
    res["status"] = "ok"
    return res


def run_child(*args, timeout=3600):
    proc = subprocess.run([sys.executable, os.path.abspath(__file__), "--child", json.dumps(args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode or not lines:
        tail = " ".join(proc.stderr.strip().splitlines()[-1:])
        return dict(case=f"{args}", status=f"CRASH: {tail[:200]}", orders={}, source_triangles=0, source_vertices=0,
                    time_build_s=float("nan"), rss_before_mb=float("nan"), rss_peak_mb=float("nan"))
    return json.loads(lines[-1][len("RESULT "):])


def pipeline_table(n):
    print(f"\n## pipeline.build_images (each case in its own process; times without the LUT build)\n")
    print("T: source triangles; per order: faces kept, culled by reason (invalid vertex / degenerate / "
          "Einstein ring / outside frustum / below pixel), bad source triangles (dropped before mapping), "
          "F - S (extra faces from subdivision); the accounting identity kept + culled + bad = T + (F - S) "
          "and every finiteness and topology check of tests/test_stress.check_images are 'ok'.\n")
    print("Peak RSS: the child's VmHWM (/proc/self/status; ru_maxrss of resource.getrusage carries the "
          "parent's peak across fork/exec on Linux, so it is only used where VmHWM is missing); growth: "
          "from after the set-up (mesh and LUT built) to the end of build_images.\n")
    print("| case | T | vertices | order | kept | invalid | degenerate | ring | frustum | below px | bad | F - S | "
          "time [s] | peak RSS [MB] (growth) | checks |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    cases = [("big_mesh_case", n), ("soup_case", n)] + [("random", seed, n // 3) for seed in (18, 19, 20, 21, 22, 23)]
    for args in cases:
        res = run_child(*args)
        grown = res["rss_peak_mb"] - res["rss_before_mb"]
        rows = sorted(res["orders"].items()) or [("-", {})]
        for k, (order, o) in enumerate(rows):
            head = (f"| {res['case']} | {res['source_triangles']} | {res['source_vertices']} |" if k == 0
                    else "| | | |")
            tail = (f" {res['time_build_s']:.2f} | {res['rss_peak_mb']:.0f} ({grown:+.0f}) | {res['status']} |"
                    if k == 0 else " | | |")
            cells = " | ".join(str(o.get(c, "")) for c in ("kept", "invalid_vertex", "degenerate_source",
                                                          "einstein_ring", "outside_frustum", "below_pixel",
                                                          "bad_source", "split_extra"))
            print(f"{head} {order} | {cells} |{tail}")
        sys.stdout.flush()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10^5 instead of 10^6 points / triangles")
    ap.add_argument("--skip-lutgen", action="store_true")
    ap.add_argument("--skip-pipeline", action="store_true")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    if args.child:
        name, *rest = json.loads(args.child)
        print("RESULT " + json.dumps(child_named(name, *rest)))
        return
    n = 10**5 if args.quick else 10**6
    print(f"grlens stress benchmark, {os.cpu_count()} CPUs, numpy {np.__version__}")
    if not args.skip_lutgen:
        lutgen_tables(n)
        sys.stdout.flush()
    if not args.skip_pipeline:
        pipeline_table(n)
    print("\nMemory over a 1000-frame animation (Blender, upload included): benchmarks/bench_addon.py, "
          "memory section.")


if __name__ == "__main__":
    main()
