"""Render a grlens sample scene in background mode (the pip `bpy` module; no Blender binary needed).

    ./dev python sample_scenes/render.py --scene sphere --frames 1,46,91 --engine cycles \
        --resolution 320x180 --samples 16 --output out/sphere

builds the scene in a fresh file with grlens' public API, saves it as <output>/<scene>.blend, and
renders each frame to <output>/<scene>_NNNN.png and a multilayer OpenEXR <output>/<scene>_NNNN.exr
(with the light_travel_time and image_order passes; Workbench writes no passes). One progress line per
frame (time for the grlens rebuild and for the render), then a summary of the time per frame.
``--list`` prints the scenes with their defaults: sphere (seed 000, 4.2), triangle and its variants
(4.1, figure 8), disc and its views (4.3, figure 10), shell (seed 004), room (seed 003), luminet
(seed 002), flyin (issue 19: the camera flies in from 80 to 4.5 r_s over a checkered floor), plunge
(the camera descends from 6 to 1.05 r_s, inside the photon sphere, over the same floor), and the
lensed star field (issue 21) in three cameras, one scene each: starfield (normal perspective view,
640x360), starfield_dome (180-degree fisheye dome master, Cycles fisheye equidistant, 512x512) and
starfield_panorama (360-degree equirectangular panorama, 1024x512); panoramas render in Cycles only.
Frames, resolution and samples default to the scene's own defaults (sample_scenes.scenes.DEFAULTS).
"""
import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import bpy  # noqa: E402

import grlens_addon  # noqa: E402
from sample_scenes.scenes import DEFAULTS, SCENES, describe  # noqa: E402

ENGINES = {"cycles": "CYCLES", "workbench": "BLENDER_WORKBENCH", "eevee": None}


def frames(text):
    out = []
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            out.extend(range(int(a), int(b) + 1))
        else:
            out.append(int(part))
    return out


def resolution(text):
    w, h = text.lower().split("x")
    return int(w), int(h)


def set_exr(settings, multilayer: bool):
    if bpy.app.version >= (5, 0, 0):
        settings.media_type = "MULTI_LAYER_IMAGE" if multilayer else "IMAGE"
    if multilayer:
        settings.file_format = "OPEN_EXR_MULTILAYER"
        settings.color_depth = "32"
    else:
        settings.file_format = "PNG"
        settings.color_depth = "8"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", choices=sorted(SCENES), default="sphere",
                    help="the scene (--list describes each); the star field's cameras are the scenes starfield "
                         "(normal view), starfield_dome (180-degree fisheye) and starfield_panorama (360-degree "
                         "equirectangular)")
    ap.add_argument("--frames", type=frames, default=None, help="e.g. 1,46,91 or 1-10 (default: the scene's)")
    ap.add_argument("--engine", choices=sorted(ENGINES), default="cycles")
    ap.add_argument("--resolution", type=resolution, default=None, help="WxH (default: the scene's)")
    ap.add_argument("--samples", type=int, default=None, help="Cycles/Eevee samples (default: the scene's)")
    ap.add_argument("--output", default="out", help="output folder")
    ap.add_argument("--list", action="store_true", help="list the scenes and their defaults, then exit")
    args = ap.parse_args(argv)
    if args.list:
        for name in sorted(SCENES):
            d = DEFAULTS[name]
            frames_text = ",".join(str(f) for f in d["frames"])
            print(f"{name:22s} frames {frames_text:10s} {d['resolution'][0]}x{d['resolution'][1]:<4d} "
                  f"samples {d['samples']:<3d} {describe(name)}")
        return 0
    d = DEFAULTS[args.scene]
    args.frames = args.frames or list(d["frames"])
    args.resolution = args.resolution or tuple(d["resolution"])
    args.samples = args.samples or d["samples"]
    os.makedirs(args.output, exist_ok=True)

    grlens_addon.register()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    r = scene.render
    # resolution first: grlens' subdivision is capped by the pixel size of the observer camera
    r.resolution_x, r.resolution_y = args.resolution
    r.resolution_percentage = 100
    t_build = time.perf_counter()
    SCENES[args.scene](scene)
    t_build = time.perf_counter() - t_build
    engine = ENGINES[args.engine] or ("BLENDER_EEVEE" if bpy.app.version >= (5, 0, 0) else "BLENDER_EEVEE_NEXT")
    r.engine = engine
    if engine == "CYCLES":
        scene.cycles.device = "CPU"
        scene.cycles.samples = args.samples
    elif engine.startswith("BLENDER_EEVEE"):
        scene.eevee.taa_render_samples = args.samples
    blend = os.path.abspath(os.path.join(args.output, f"{args.scene}.blend"))
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    print(f"{args.scene}: scene built in {t_build:.2f} s (with any LUT builds and rebuilds it triggered, so the "
          f"first frame's images may be ready already); {len(args.frames)} frame(s), {engine}, "
          f"{args.resolution[0]}x{args.resolution[1]}", flush=True)
    times, rebuilds = [], []
    for i, f in enumerate(args.frames):
        t0 = time.perf_counter()
        scene.frame_set(f)  # the grlens frame handler rebuilds the images
        t1 = time.perf_counter()
        bpy.ops.render.render()
        result = bpy.data.images["Render Result"]
        stem = os.path.abspath(os.path.join(args.output, f"{args.scene}_{f:04d}"))
        set_exr(r.image_settings, multilayer=False)
        result.save_render(stem + ".png", scene=scene)
        if engine != "BLENDER_WORKBENCH":
            set_exr(r.image_settings, multilayer=True)
            result.save_render(stem + ".exr", scene=scene)
        dt = time.perf_counter() - t0
        times.append(dt)
        rebuilds.append(t1 - t0)
        print(f"frame {f} ({i + 1}/{len(args.frames)}): {dt:.2f} s (grlens {t1 - t0:.2f} s, render+save "
              f"{dt - (t1 - t0):.2f} s)  {scene.grlens.status}  -> {stem}.png", flush=True)
    n = len(times)
    print(f"{args.scene}: {n} frame(s), {sum(times) / n:.2f} s per frame (min {min(times):.2f}, max "
          f"{max(times):.2f}; grlens {sum(rebuilds) / n:.2f} s per frame), total {sum(times):.1f} s "
          f"({engine}, {args.resolution[0]}x{args.resolution[1]}); scene saved as {blend}", flush=True)
    return 0


if __name__ == "__main__":
    rc = main()
    sys.stdout.flush()
    os._exit(rc)  # skip interpreter teardown (bpy can crash there after GPU renders)
