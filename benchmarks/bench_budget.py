"""The error budget and the core's rules, measured: A/B comparisons in one process (issue 20).

Two modes; both alternate the variants round by round in one process, so that the machine's drift
hits them alike, and report per angle of the benchmark sphere's orbit (bench_accuracy's scene,
640x360 by default) the time of build_images (min / median of --rounds), the image triangles and,
against the reference ray tracer, the coverage mismatch and the screen error p99.

* ``--base REV``: this checkout's core against the core of git revision REV (its grlens_addon/core
  copied into a temporary package and imported beside this one). Prints the orbit's mean and median
  time per frame and mean triangles of each, and the same for the 100k-triangle sphere
  (bench_addon's sphere100k: 320 x 160 segments) every 10th angle.
* ``--rules``: each rule of the budget (budget.py) against the core without it (the constant set to
  its "off" value), at the angles where the rule acts. These are the comparisons that tests used to
  make by patching constants; tests/test_stages.py checks what the shipped budget promises.
* ``--errors``: what the single budget gives: per angle the pieces' measured edge error (the
  distance on screen between a piece edge's midpoint and the exact image of its source midpoint),
  p99 and max, and the share of pieces beyond the tolerance, split into pieces of magnified
  (Einstein-ring) triangles and the others.

* ``--base REV --pareto``: bench_accuracy's Pareto sweep of the triangle scene with both cores.

Usage: ./dev python benchmarks/bench_budget.py --base 2acf9ba [--step 10] [--rounds 5] [--ref-cache DIR]
       ./dev python benchmarks/bench_budget.py --rules [--ref-cache DIR]
       ./dev python benchmarks/bench_budget.py --errors [--step 15]
References are traced once per angle (slow: seconds each); --ref-cache DIR keeps them between runs.
"""
from __future__ import annotations

import argparse
import importlib
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
import warnings

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

import bench_accuracy as BA  # noqa: E402
from bench_frame import uv_sphere  # noqa: E402
from provenance import code_version  # noqa: E402
from grlens_addon.core import budget, frame, mapping, pipeline, rasterize, raytrace  # noqa: E402
from lutgen import LUTFamily  # noqa: E402


LINES: list = []


def emit(text=""):
    """Print ``text`` and keep it for --write."""
    print(text, flush=True)
    LINES.append(text)


def base_core(rev: str):
    """The ``pipeline`` module of git revision ``rev``'s grlens_addon/core, imported from a temporary
    package (its modules import each other relatively, and lutgen from this checkout)."""
    files = subprocess.run(["git", "-C", ROOT, "ls-tree", "--name-only", rev, "grlens_addon/core/"],
                           check=True, capture_output=True, text=True).stdout.split()
    name = "grlens_core_" + rev.replace("-", "_")[:12]
    root = tempfile.mkdtemp(prefix="grlens_base_")
    pkg = os.path.join(root, name)
    os.makedirs(pkg)
    for f in files:
        if f.endswith(".py"):
            text = subprocess.run(["git", "-C", ROOT, "show", f"{rev}:{f}"], check=True, capture_output=True,
                                  text=True).stdout
            with open(os.path.join(pkg, os.path.basename(f)), "w") as fh:
                fh.write(text)
    sys.path.insert(0, root)
    return importlib.import_module(name + ".pipeline")


def _measure(variants, src, scene, table, settings, planes, rounds):
    """{name: (times [s], image triangles, images)} of build_images per variant, alternated."""
    times = {k: [] for k in variants}
    out = {}
    for r in range(rounds + 1):
        for name, (build, make) in variants.items():
            s = make(src)
            t0 = time.perf_counter()
            images = build(s, scene, table, settings, frustum_planes=planes)
            dt = time.perf_counter() - t0
            if r:  # the first round warms up
                times[name].append(dt)
            out[name] = images
    return {k: (np.array(times[k]), sum(len(m.tris) for m in out[k].values()), out[k]) for k in variants}


def _accuracy(images, cam, src, ref):
    buf = rasterize.rasterize(rasterize.from_images(images), cam)
    m = BA.compare(ref, buf, cam, src)["orders"]["all"]
    return m["mismatch_frac"], m["screen_px"]["p99"]


def _same_src(src):
    return src


def _base_src(mod):
    return lambda s: mod.SourceMesh(s.positions, s.tris, s.corner_uv, s.material, s.corner_normals)


def compare_revisions(rev, angles, rounds, cam, table, accuracy=True):
    base = base_core(rev)
    variants = {"base": (base.build_images, _base_src(base)), "this": (pipeline.build_images, _same_src)}
    scene = mapping.Scene(cam.position, np.zeros(3), BA.R_S)
    settings = BA.make_settings(cam)
    planes = cam.frustum_planes()
    rows = []
    emit(f"| angle [deg] | base: min / median [ms] | this: min / median [ms] | median ratio | triangles base / this"
          + (" | mismatch base / this | screen p99 [px] base / this" if accuracy else "") + " |")
    emit("|---|---|---|---|---|" + ("---|---|" if accuracy else ""))
    for a in angles:
        src, tri_scene = BA.sphere_scene(a)
        res = _measure(variants, src, scene, table, settings, planes, rounds)
        (tb, nb, ib), (tt, nt, it) = res["base"], res["this"]
        line = (f"| {a:g} | {1e3 * tb.min():.1f} / {1e3 * np.median(tb):.1f} | {1e3 * tt.min():.1f} / "
                f"{1e3 * np.median(tt):.1f} | {np.median(tt) / np.median(tb):.2f} | {nb} / {nt}")
        acc = None
        if accuracy:
            ref, _ = BA.reference_image(tri_scene, cam)
            acc = (_accuracy(ib, cam, src, ref), _accuracy(it, cam, src, ref))
            line += (f" | {100 * acc[0][0]:.2f}% / {100 * acc[1][0]:.2f}% | {acc[0][1]:.3f} / {acc[1][1]:.3f}")
        emit(line + " |")
        rows.append((a, np.median(tb), np.median(tt), nb, nt, acc))
    mb, mt = np.mean([r[1] for r in rows]), np.mean([r[2] for r in rows])
    emit(f"\nsphere orbit ({len(rows)} angles): mean of the median times base {1e3 * mb:.2f} ms, this "
          f"{1e3 * mt:.2f} ms (ratio {mt / mb:.3f}); median frame base {1e3 * np.median([r[1] for r in rows]):.2f} ms, "
          f"this {1e3 * np.median([r[2] for r in rows]):.2f} ms; mean triangles base "
          f"{np.mean([r[3] for r in rows]):.0f}, this {np.mean([r[4] for r in rows]):.0f}")
    if accuracy:
        worst = [max(r[5][k][0] for r in rows) for k in (0, 1)]
        worst_p = [max(r[5][k][1] for r in rows) for k in (0, 1)]
        emit(f"worst mismatch base {100 * worst[0]:.2f}%, this {100 * worst[1]:.2f}%; worst screen p99 base "
              f"{worst_p[0]:.3f} px, this {worst_p[1]:.3f} px")
    # the 100k-triangle sphere (bench_addon's sphere100k), every 10th angle of its orbit
    local, tris = uv_sphere(320, 160, BA.RADIUS)
    big = []
    for a in angles[::max(1, len(angles) // 36)]:
        r = math.radians(a)
        src = pipeline.SourceMesh(local + np.array([BA.ORBIT * math.cos(r), BA.ORBIT * math.sin(r), 0.01]), tris)
        res = _measure(variants, src, scene, table, settings, planes, max(1, rounds // 2))
        big.append((np.median(res["base"][0]), np.median(res["this"][0]), res["base"][1], res["this"][1]))
    b, t = np.mean([x[0] for x in big]), np.mean([x[1] for x in big])
    emit(f"100k-triangle sphere ({len(big)} angles): mean base {1e3 * b:.1f} ms, this {1e3 * t:.1f} ms "
          f"(ratio {t / b:.3f}); mean triangles base {np.mean([x[2] for x in big]):.0f}, "
          f"this {np.mean([x[3] for x in big]):.0f}")


RULES = [
    # (name, attribute of budget, its "off" value, angles where the rule acts, other attributes set for both)
    ("strips (STRIP_BAND_PX)", "STRIP_BAND_PX", 0.0, (170, 180, 0), {}),
    ("second-order ring edge next to a patch (RING_EDGE_ORDERS)", "RING_EDGE_ORDERS", (), (355, 5), {}),
    ("thin images (THIN_FACTOR)", "THIN_FACTOR", 1.0, (350, 355, 5, 10), {}),
    ("patches clipped to the triangles (CLIP_TO_TRIANGLES)", "CLIP_TO_TRIANGLES", False, (170.5, 172, 188), {}),
    ("steep circles of plain patches (STEEP_RATIO)", "STEEP_RATIO", 0.0, (170.5, 171),
     {"CLIP_TO_TRIANGLES": False}),
    ("ring edge chords crossing the ring (CHORD_OUTSET)", "CHORD_OUTSET", 0.0, (4, 356), {}),
    ("pieces under complete patches (UNDER_PATCH_FACTOR)", "UNDER_PATCH_FACTOR", None, (176, 180, 184), {}),
    ("back faces (BACK_FACE_MIN_PIECES)", "BACK_FACE_MIN_PIECES", 10 ** 12, (170, 180), {}),
    ("hidden patch sheets (HIDDEN_CORE)", "HIDDEN_CORE", np.inf, (175, 185), {}),
    ("first split beside the axis (PRESPLIT_MIN)", "PRESPLIT_MIN", np.inf, (165, 170, 190), {}),
    ("silhouette ring levels up to (SILHOUETTE_RING_LEVEL_MAX)", "SILHOUETTE_RING_LEVEL_MAX", 0, (171, 180), {}),
]


def compare_rules(rounds, cam, table, only=None):
    """Each rule of RULES with and without it (its budget constant set to the "off" value), alternated
    round by round, at the angles where it acts."""
    scene = mapping.Scene(cam.position, np.zeros(3), BA.R_S)
    settings = BA.make_settings(cam)
    planes = cam.frustum_planes()
    emit("| rule | angle [deg] | with: median [ms] / triangles / mismatch / screen p99 [px] | "
          "without: median [ms] / triangles / mismatch / screen p99 [px] |")
    emit("|---|---|---|---|")
    for name, attr, off, angles, fixed in RULES:
        if only and only not in name:
            continue
        saved = {k: getattr(budget, k) for k in [attr, *fixed]}
        on = saved[attr]

        def variant(value):
            def build(*a, **k):
                for key, v in fixed.items():
                    setattr(budget, key, v)
                setattr(budget, attr, value)
                try:
                    return pipeline.build_images(*a, **k)
                finally:
                    for key, v in saved.items():
                        setattr(budget, key, v)
            return build, _same_src

        for a in angles:
            src, tri_scene = BA.sphere_scene(a)
            ref, _ = BA.reference_image(tri_scene, cam)
            res = _measure({"with": variant(on), "without": variant(off)}, src, scene, table, settings, planes, rounds)
            cells = []
            for k in ("with", "without"):
                times, n, images = res[k]
                mis, p99 = _accuracy(images, cam, src, ref)
                cells.append(f"{1e3 * np.median(times):.1f} / {n} / {100 * mis:.2f}% / {p99:.3f}")
            emit(f"| {name} | {a:g} | {cells[0]} | {cells[1]} |")


def sagitta_px(d_a, d_b, d_mid, pixel_angle):
    """(E,) pixels: how far the exact image ``d_mid`` (unit directions) of an edge's source midpoint lies
    off the straight edge between the images ``d_a``, ``d_b`` of its ends (the great circle through
    them on the view sphere): the sagitta the budget bounds. (Its offset along the edge is a texture
    placement error, measured on screen by bench_accuracy.)"""
    n = np.cross(d_a, d_b)
    with np.errstate(invalid="ignore", divide="ignore"):
        n /= np.linalg.norm(n, axis=1)[:, None]
        return np.arcsin(np.clip(np.abs(np.einsum("ij,ij->i", d_mid, n)), 0.0, 1.0)) / pixel_angle


def compare_pareto(rev, width, height, repeat):
    """bench_accuracy's Pareto sweep of the triangle scene (seed 000's triangle behind the hole at five
    positions; every setting of the sweep) with REV's core and with this checkout's."""
    base = base_core(rev)
    for name, mod in (("base " + rev, base), ("this checkout", pipeline)):
        BA.pipeline = mod
        try:
            emit(f"\nTriangle scene, {name}:\n")
            lines, _ = BA.triangle_pareto(width, height, repeat)
        finally:
            BA.pipeline = pipeline
        for line in lines:
            emit(line)


def _floors():
    """(label, source mesh, camera) of two floors seen at grazing angles: a floor 2 r_s below the hole
    from 30 r_s in front of it to 150 r_s behind (tests/test_stages.py's, 320x180), and bench_tables'
    floor reaching 1e4 r_s behind the hole (640x360, bench_tables' camera for it)."""
    sys.path.insert(0, os.path.join(ROOT, "tests"))
    import bench_tables as BT
    from meshes import grid

    make, target, fov = BT.IMAGE_SCENES[next(k for k in BT.IMAGE_SCENES if "1e4" in k)]
    far_cam = raytrace.Camera.look_at([BA.R_OBS, 0.0, 0.0], target, math.radians(fov), 640, 360)
    return [("floor to 150 r_s", grid(-150, 30, -60, 60, 30, 20, "z", -2.0), BA.camera(320, 180)),
            ("floor to 1e4 r_s", make(), far_cam)]


def piece_errors(angles, cam, table):
    """What the budget gives: the measured sagitta of the kept pieces per orbit angle, and on two floors
    seen at grazing angles."""
    tol = BA.make_settings(cam).max_error_px
    emit(f"Tolerance {tol} px. Per kept piece the largest sagitta of its three edges: how far the exact image "
         "of the edge's source midpoint lies off the straight edge on screen (sagitta_px). Plain: pieces of "
         "triangles the lensing magnifies less than budget.RING_MAGNIFICATION; magnified: the others (next "
         "to the Einstein ring). Beyond: the share of pieces whose sagitta exceeds the tolerance.\n")
    emit("| scene | order | pieces (plain / magnified) | plain: p99 / max [px] / beyond | "
         "magnified: p99 / max [px] / beyond |")
    emit("|---|---|---|---|---|")
    scenes = [(f"sphere at {a:g} deg", BA.sphere_scene(a)[0], cam) for a in angles] + _floors()
    for label, src, c in scenes:
        scene = mapping.Scene(c.position, np.zeros(3), BA.R_S)
        settings = BA.make_settings(c)
        fr = frame.frame_context(scene, table, settings, None, c.frustum_planes())
        st = pipeline.run_stages(fr, src)
        source, coarse = st.source, st.coarse
        for order, s in st.orders.items():
            if s.pieces is None:
                continue
            pieces, keep = s.pieces, s.keep
            sub, img, fs = pieces.sub, pieces.images, pieces.face_src
            mag = (coarse.circumference[order][fs] > budget.RING_MAGNIFICATION * source.circumference[fs])[keep]
            t = sub.tris[keep]
            i, j = t.ravel(), np.roll(t, -1, axis=1).ravel()
            mid = fr.map.images(0.5 * (sub.positions[i] + sub.positions[j]), (order,))[order]
            err = sagitta_px(img.direction[i], img.direction[j], mid.direction, settings.pixel_angle)
            err = np.nan_to_num(err).reshape(-1, 3).max(axis=1)
            cells = []
            for sel in (~mag, mag):
                e = err[sel]
                cells.append("-" if not len(e) else
                             f"{np.percentile(e, 99):.3f} / {e.max():.3f} / {100 * (e > tol).mean():.1f}%")
            emit(f"| {label} | {order} | {int((~mag).sum())} / {int(mag.sum())} | {cells[0]} | {cells[1]} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", default=None, metavar="REV", help="compare this checkout's core with REV's")
    ap.add_argument("--rules", action="store_true", help="each rule of the budget with and without it")
    ap.add_argument("--only", default=None, help="with --rules: only rules whose name contains this")
    ap.add_argument("--errors", action="store_true", help="the kept pieces' measured edge errors")
    ap.add_argument("--pareto", action="store_true", help="with --base: the triangle scene's Pareto sweep of both")
    ap.add_argument("--angles", default=None, help="orbit angles (deg), comma-separated (default: every --step)")
    ap.add_argument("--step", type=float, default=10.0)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--no-accuracy", action="store_true", help="with --base: times and triangles only")
    ap.add_argument("--resolution", default="640x360")
    ap.add_argument("--ref-cache", default=None, metavar="DIR", help="as bench_accuracy's --ref-cache")
    ap.add_argument("--write", default=None, metavar="SECTION",
                    help="write the output into docs/budget.md under the heading SECTION (replacing it)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    BA.REF_CACHE = args.ref_cache
    w, h = (int(x) for x in args.resolution.lower().split("x"))
    cam = BA.camera(w, h)
    table = LUTFamily().at(BA.R_OBS)
    angles = ([BA._angle(a) for a in args.angles.split(",")] if args.angles
              else [BA._angle(a) for a in np.arange(0.0, 360.0, args.step)])
    load0 = os.getloadavg()[0]
    emit(f"`./dev python benchmarks/bench_budget.py {' '.join(argv if argv is not None else sys.argv[1:])}` "
         f"({platform.machine()}, {os.cpu_count()} CPUs; {code_version()}; {w}x{h}, {args.rounds} rounds; load "
         f"average {load0:.1f} at the start)\n")
    if args.base and args.pareto:
        compare_pareto(args.base, w, h, max(1, args.rounds // 2))
    elif args.base:
        compare_revisions(args.base, angles, args.rounds, cam, table, accuracy=not args.no_accuracy)
    if args.rules:
        compare_rules(args.rounds, cam, table, args.only)
    if args.errors:
        piece_errors(angles, cam, table)
    if args.write:
        _write_section(args.write, LINES)


def _write_section(title, lines):
    """Replace (or append) the section ``## title`` of docs/budget.md with ``lines``; the rest stays."""
    path = os.path.join(ROOT, "docs", "budget.md")
    old = open(path).read().split("\n") if os.path.exists(path) else ["# The error budget, measured", ""]
    sections, current = [[]], None
    for line in old:
        if line.startswith("## "):
            sections.append([])
        sections[-1].append(line)
    head = f"## {title}"
    new = [head, "", *lines, ""]
    for k, sec in enumerate(sections):
        if sec and sec[0] == head:
            sections[k] = new
            break
    else:
        sections.append(new)
    with open(path, "w") as f:
        f.write("\n".join(line for sec in sections for line in sec).rstrip("\n") + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
