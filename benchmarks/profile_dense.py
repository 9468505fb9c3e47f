"""Where the core's time goes on bench_dense's 1M-triangle UV sphere: per stage, and (``--cprofile``)
per function; ``--dump FILE`` writes every image mesh array of the builds (for before/after
comparisons of pipeline.build_images: ``--compare A B``).

The inputs of ``pipeline.build_images`` are captured once from Blender (benchmarks/bench_dense.py's
scene: ``bpy.ops.grlens.demo_scene``, 1920x1080, the sphere's frames, the render tolerance, or the
viewport's with ``--preview``) into an .npz (``--capture``, default /tmp/grlens_dense_<CAPTURE_VERSION>_<size>_<frames>.npz,
reused if present); the core then runs bpy-free on them, with the family's table for the camera's
radius (lutgen.LUTFamily, the add-on's default). Stage times come from the progress hook
(pipeline.Progress is called before every stage and inside long ones): time from one stage's call
to the next stage's, per stage and pass, and how far the progress fraction shown (from one call to
the next) strays from the fraction of the build's time gone.

Usage: ./dev python benchmarks/profile_dense.py [--size 1M] [--frames 30] [--repeat 3] [--preview]
       [--threads N] [--cprofile N] [--dump FILE] [--compare A B] [--write]
"""
import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)


CAPTURE_VERSION = "v2"
"""In the default capture's file name: captures of an earlier gather (float64 UVs and normals) are not
reused."""


def capture(path, size, frames, preview):
    """The inputs of build_images for each frame (bpy), into ``path``."""
    import bpy

    import grlens_addon
    from grlens_addon.blender import rebuild

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from bench_dense import dense_scene

    if not hasattr(bpy.types.Scene, "grlens"):
        grlens_addon.register()
    scene = dense_scene(size)[0]
    got = {}
    real = rebuild.pipeline.build_images

    def grab(src, geo, lut, settings, light=None, planes=None, disc=None, progress=None):
        got.update(positions=src.positions, tris=src.tris, corner_uv=src.corner_uv, material=src.material,
                   corner_normals=src.corner_normals, camera=geo.camera, hole=geo.hole, r_s=geo.r_s,
                   planes=planes, pixel_angle=settings.pixel_angle, max_error_px=settings.max_error_px,
                   r_obs=geo.r_obs)
        return real(src, geo, lut, settings, light, planes, disc, progress=progress)

    rebuild.pipeline.build_images = grab
    out = {}
    for f in frames:
        scene.frame_set(f)
        rebuild.rebuild_scene(scene, bpy.context.evaluated_depsgraph_get(), preview=preview)
        for k, v in got.items():
            if v is not None:
                out[f"{f}/{k}"] = np.asarray(v)
    rebuild.pipeline.build_images = real
    np.savez(path, frames=np.array(frames), **out)


def load(path):
    from grlens_addon.core import mapping, pipeline
    from grlens_addon.core.mapping import round_radius
    from lutgen import LUTFamily

    data = np.load(path)
    fam = LUTFamily(r_min=1.05)
    runs = []
    for f in data["frames"]:
        g = {k.split("/", 1)[1]: data[k] for k in data.files if k.startswith(f"{f}/")}
        src = pipeline.SourceMesh(g["positions"], g["tris"], g.get("corner_uv"), g.get("material"),
                                  g.get("corner_normals"))
        scene = mapping.Scene(g["camera"], g["hole"], float(g["r_s"]))
        settings = pipeline.Settings(pixel_angle=float(g["pixel_angle"]),
                                     max_error_px=float(g["max_error_px"]))
        lut = fam.at(round_radius(float(g["r_obs"])))
        runs.append((int(f), src, scene, lut, settings, g.get("planes")))
    return runs


def timed_build(run):
    """One build_images with the time of each stage (s) and the progress fraction's largest distance
    from the time's fraction."""
    from grlens_addon.core import pipeline

    f, src, scene, lut, settings, planes = run
    marks = []

    def hook(stage, fraction):
        marks.append((time.perf_counter(), stage, fraction))

    t0 = time.perf_counter()
    out = pipeline.build_images(src, scene, lut, settings, None, planes, progress=pipeline.Progress(hook))
    t1 = time.perf_counter()
    stages = {}  # stage -> s (all its passes: both orders' for the per-order stages)
    for (ta, name, _), (tb, _, _) in zip(marks, marks[1:]):
        stages[name] = stages.get(name, 0.0) + tb - ta
    # the fraction shown from one call to the next against the time's fraction (largest just before a
    # call, where the previous fraction has been shown longest)
    times = [(t - t0) / (t1 - t0) for t, _, _ in marks] + [1.0]
    shown = [0.0] + [fr for _, _, fr in marks]
    off = max(max(abs(a - tt), abs(b - tt)) for a, b, tt in zip(shown, shown[1:] + [1.0], times))
    return out, t1 - t0, stages, off


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="1M")
    ap.add_argument("--frames", default="30")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--preview", action="store_true", help="the viewport's tolerance")
    ap.add_argument("--capture", default=None, help="the captured inputs (.npz)")
    ap.add_argument("--threads", type=int, default=None, metavar="N",
                    help="grlens_addon.core.frame.THREADS for the builds (default: as the add-on has it)")
    ap.add_argument("--cprofile", type=int, default=0, metavar="N", help="print the N costliest functions")
    ap.add_argument("--dump", default=None, help="write the image meshes' arrays to this .npz")
    ap.add_argument("--compare", nargs=2, default=None, metavar=("A", "B"), help="compare two dumps")
    ap.add_argument("--write", action="store_true",
                    help="the first frame's stage table into docs/performance.md (section \"Dense meshes\")")
    args = ap.parse_args(argv)
    if args.compare:
        return compare(*args.compare)
    frames = [int(f) for f in args.frames.split(",")]
    path = args.capture or (f"/tmp/grlens_dense_{CAPTURE_VERSION}_{args.size}{'_preview' if args.preview else ''}_"
                            f"{'_'.join(map(str, frames))}.npz")
    if not os.path.exists(path):
        capture(path, args.size, frames, args.preview)
    runs = load(path)
    if args.threads is not None:
        from grlens_addon.core import frame

        frame.THREADS = args.threads
    for run in runs:
        timed_build(run)  # (tables and caches first)
    dump = {}
    for run in runs:
        rows = [timed_build(run) for _ in range(args.repeat)]
        best = min(rows, key=lambda r: r[1])
        out = best[0]
        tris = " / ".join(f"{len(out[o].tris):,}" for o in sorted(out))
        total = float(np.median([r[1] for r in rows]))
        print(f"frame {run[0]}: build_images median {total:.3f} s, best {best[1]:.3f} s; image triangles {tris}; "
              f"progress vs time, largest difference {100 * np.median([r[3] for r in rows]):.0f} % (median)")
        print("| stage | median [s] | share of the median build | STAGE_WEIGHTS share |")
        print("|---|---|---|---|")
        from grlens_addon.core import pipeline

        steps = pipeline._Steps(None, len(out))
        table = []
        for key in rows[0][2]:
            t = float(np.median([r[2].get(key, 0.0) for r in rows]))
            w = pipeline.STAGE_WEIGHTS.get(key, 0.0) * (len(out) if key in steps.PER_ORDER else 1) / steps.total
            table.append(f"| {key} | {t:.3f} | {100 * t / total:.1f} % | {100 * w:.1f} % |")
            print(table[-1])
        if args.write and run is runs[0]:
            write(table, run[0], total, tris, args)
        for o, img in out.items():
            for k, v in vars(img).items():
                if isinstance(v, np.ndarray):
                    dump[f"{run[0]}/{o}/{k}"] = v
    if args.dump:
        np.savez(args.dump, **dump)
        print(f"wrote {args.dump}")
    if args.cprofile:
        import cProfile
        import pstats

        pr = cProfile.Profile()
        pr.enable()
        timed_build(runs[0])
        pr.disable()
        pstats.Stats(pr).sort_stats("tottime").print_stats(args.cprofile)
        pstats.Stats(pr).sort_stats("cumulative").print_stats(args.cprofile)


OUT = os.path.join(ROOT, "docs", "performance.md")
BEGIN, END = "<!-- profile_dense: begin -->", "<!-- profile_dense: end -->"


def write(table, frame, total, tris, args):
    """The stage table between the markers of docs/performance.md, with where it came from."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from provenance import write_section

    from grlens_addon.core import frame as core_frame

    write_section(OUT, BEGIN, END, "benchmarks/profile_dense.py", [
        f"Where the core's time goes (`./dev python benchmarks/profile_dense.py --write`: bench_dense's "
        f"{args.size} sphere, frame {frame}, the {'viewport' if args.preview else 'render'} tolerance, "
        f"pipeline.build_images bpy-free on the inputs captured from Blender, {core_frame.THREADS} thread(s) "
        f"(frame.THREADS); medians of {args.repeat} builds, "
        f"{total:.2f} s, image triangles {tris}; per stage, the time from its progress call to the "
        "next stage's):", "",
        "| stage (both orders' passes) | median [s] | share of the median build | STAGE_WEIGHTS share |",
        "|---|---|---|---|", *table])
    print(f"wrote {os.path.relpath(OUT)}")


def compare(a, b):
    """Which arrays of two dumps differ, and by how much."""
    A, B = np.load(a), np.load(b)
    same = True
    for k in sorted(set(A.files) | set(B.files)):
        if k not in A.files or k not in B.files:
            print(f"{k}: only in {'A' if k in A.files else 'B'}")
            same = False
            continue
        x, y = A[k], B[k]
        if x.shape != y.shape:
            print(f"{k}: shapes {x.shape} / {y.shape}")
            same = False
        elif not np.array_equal(x, y, equal_nan=x.dtype.kind == "f"):
            d = np.abs(x.astype(np.float64) - y.astype(np.float64))
            print(f"{k}: differs, largest {np.nanmax(d):.3g}, {np.count_nonzero(d)} values")
            same = False
    print("identical" if same else "different")


if __name__ == "__main__":
    main()
    sys.stdout.flush()
    os._exit(0)
