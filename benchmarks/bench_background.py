"""Long viewport rebuilds beside the interface (grlens_addon/blender/background.py): how long the main
thread is blocked, how often it gets to run while the worker builds, how fast Esc stops a build, and
how well the progress fraction follows the time.

Scene: benchmarks/bench_dense.py's (``bpy.ops.grlens.demo_scene``, 1920x1080, a closed UV sphere of
radius 1 BU on the 3 r_s orbit, frame 30 of the orbit), rebuilt after a move to the viewport's
tolerance (an automatic viewport update). In the bpy module (background mode: no interface), so
background builds are allowed by background.FORCE and the timer is called by this script; the
interface is stood in for by a main-thread loop that does 1 ms of Python work (a panel's drawing)
60 times a second and measures how late its turns come while the worker builds.

Printed per size: the synchronous rebuild (the interface blocked for all of it); for the background
build the main thread's share (gathering the mesh before, uploading after), the longest and the 99th
percentile lateness of the stand-in's turns while the worker builds, the build's total time; the
time from cancel (Esc) to the worker stopped (cancelled at about a third of the build); the largest
difference between the progress fraction shown and the fraction of the build's time gone.
``--write``: replace this benchmark's section of docs/manual.md.

Usage: ./dev python benchmarks/bench_background.py [--sizes 200k,1M] [--write]
"""
import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_dense import dense_scene  # noqa: E402
from provenance import code_version  # noqa: E402

OUT = os.path.join(ROOT, "docs", "manual.md")
BEGIN, END = "<!-- bench_background: begin -->", "<!-- bench_background: end -->"


def _scene(size):
    scene, sphere, n_tris = dense_scene(size)
    scene.frame_set(30)
    return scene, sphere, n_tris


def _request(scene, background):
    from grlens_addon.blender import handlers, rebuild

    handlers._busy = True
    try:
        return rebuild.rebuild_scene(scene, preview=True, background=background)
    finally:
        handlers._busy = False


def _nudge(sphere, k):
    sphere.delta_location.z = 1e-3 * k  # (a move: every rebuild builds)


def _stand_in(job, work_s=1e-3, period_s=1 / 60):
    """The interface's stand-in: a turn of ``work_s`` Python work every ``period_s`` (a redraw at 60 Hz)
    until the worker is done; returns each turn's lateness against its schedule (s), (time, progress
    fraction) samples and the worker's time."""
    late, samples = [], []
    t0 = time.perf_counter()
    due = t0
    while not job.done:
        now = time.perf_counter()
        late.append(max(now - due, 0.0))
        samples.append((now - t0, job.progress.fraction))
        end = now + work_s
        x = 0
        while time.perf_counter() < end:
            x += 1
        due = now + period_s
        rest = due - time.perf_counter()
        if rest > 0:
            time.sleep(rest)
    return np.array(late), samples, time.perf_counter() - t0


def measure(size, rounds):
    from grlens_addon.blender import background

    scene, sphere, n_tris = _scene(size)
    k = 0
    _nudge(sphere, k)
    _request(scene, False)  # (one build first: tables, caches, the closedness of the mesh)
    sync = []
    for _ in range(rounds):
        k += 1
        _nudge(sphere, k)
        t0 = time.perf_counter()
        rep = _request(scene, False)
        sync.append(time.perf_counter() - t0)
        assert not rep["status"].startswith("grlens:"), rep["status"]
    out = {"tris": n_tris, "sync": np.median(sync), "plan": [], "finish": [], "gap_max": [], "gap_p99": [],
           "total": [], "cancel": [], "progress_off": [], "image_tris": 0}
    for _ in range(rounds):
        k += 1
        _nudge(sphere, k)
        t0 = time.perf_counter()
        rep = _request(scene, True)
        t_plan = time.perf_counter() - t0
        assert rep["status"] == "lensing in the background", rep["status"]
        job = background.current()
        gaps, samples, t_worker = _stand_in(job)
        t1 = time.perf_counter()
        background.tick()
        t_finish = time.perf_counter() - t1
        out["plan"].append(t_plan)
        out["finish"].append(t_finish)
        out["gap_max"].append(gaps.max() if len(gaps) else t_worker)
        out["gap_p99"].append(np.percentile(gaps, 99) if len(gaps) else t_worker)
        out["total"].append(time.perf_counter() - t0)
        out["progress_off"].append(max(abs(f - t / t_worker) for t, f in samples) if samples else 1.0)
    import bpy

    out["image_tris"] = sum(len(o.data.polygons) for o in bpy.data.objects if o.grlens.order in (1, 2))
    for _ in range(rounds):  # Esc at about a third of the build
        k += 1
        _nudge(sphere, k)
        _request(scene, True)
        job = background.current()
        while job.progress.fraction < 0.33 and not job.done:
            time.sleep(0.002)
        t0 = time.perf_counter()
        background.cancel(reason="Esc")
        out["cancel"].append(time.perf_counter() - t0)
        background.clear_cancelled()
    for key in ("plan", "finish", "gap_max", "gap_p99", "total", "cancel", "progress_off"):
        out[key] = float(np.median(out[key]))
    return out


def report(results, rounds):
    lines = [BEGIN, f"<!-- generated by benchmarks/bench_background.py on {code_version()} -->", "",
             f"From `./dev python benchmarks/bench_background.py --write` (medians of {rounds} rebuilds of a closed "
             "UV sphere beside the hole after a move, to the viewport's tolerance at 1920x1080, on a shared 2-core "
             "machine: compare figures within the table). The interface is stood in for by a loop on the main "
             "thread doing 1 ms of Python work 60 times a second (a redraw); late: how much later than due its "
             "turns came while the worker built. At once, the interface waits for the whole rebuild; beside it, "
             "for the main thread's parts: gathering the mesh before, the upload after.", "",
             "| source triangles | at once: interface blocked [s] | beside: main thread before / after [s] | "
             "turns late, at most [ms] | 99th percentile [ms] | whole build [s] | Esc to stopped [s] | progress "
             "vs time, largest difference |", "|---|---|---|---|---|---|---|---|"]
    for size, r in results.items():
        lines.append(f"| {r['tris']:,} | {r['sync']:.2f} | {r['plan']:.2f} / {r['finish']:.2f} | "
                     f"{1e3 * r['gap_max']:.0f} | {1e3 * r['gap_p99']:.0f} | {r['total']:.2f} | {r['cancel']:.2f} | "
                     f"{100 * r['progress_off']:.0f} % |")
    lines += ["", END]
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="200k,1M")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--write", action="store_true", help="replace this benchmark's section of docs/manual.md")
    args = ap.parse_args(argv)
    import bpy

    import grlens_addon
    from grlens_addon.blender import background

    if not hasattr(bpy.types.Scene, "grlens"):
        grlens_addon.register()
    background.FORCE = True
    background.BUDGET_SECONDS = 0.0
    results = {s: measure(s, args.rounds) for s in args.sizes.split(",")}
    text = report(results, args.rounds)
    print(text)
    if args.write:
        with open(OUT) as f:
            old = f.read()
        if BEGIN in old:
            new = old[:old.index(BEGIN)] + text + old[old.index(END) + len(END) + 1:]
        else:
            raise SystemExit(f"{OUT} has no {BEGIN} ... {END} section to replace")
        with open(OUT, "w") as f:
            f.write(new)
        print(f"wrote {os.path.relpath(OUT)}")
    sys.stdout.flush()
    os._exit(0)  # (the bpy module may hang in its static destructors at exit)


if __name__ == "__main__":
    main()
