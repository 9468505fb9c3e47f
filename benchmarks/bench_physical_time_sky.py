"""The lensed world of a moving camera (physical time), in the pip bpy of the dev environment:
``./dev bench physical_time_sky``.

Prints
* the world update per frame (grlens_addon.blender.world.update, grlens' depsgraph handler
  detached) for a camera flying in from 20 to 4 r_s over 100 frames, at rest in each frame
  (speed_of_light 0) and moving (speed_of_light 2 BU per frame: its velocity read from its keys,
  beta written into the group's inverse aberration), medians;
* the Cycles render time of bench_sky's scene (a diffuse sphere under a procedural sky, 320x180,
  16 samples, the world's importance map off so that the shader's per-sample cost shows) with the
  camera at rest (nothing of physical time in the sky's shader) and moving at 1e-5 c (the same
  picture), with the inverse aberration alone (colour switches off) and with the sky's colour shift
  too, alternated, best of 5: the shader's own costs. (A fast camera's picture is another picture:
  more or less sky, shadow and objects.)

Units: milliseconds and seconds as printed; r_s = 2 BU.

Usage: ``./dev bench physical_time_sky [--write]``: with --write, the figures replace the lensed
world's section of docs/physical_time.md (between its markers; bench_physical_time.py keeps it).
"""
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import bpy  # noqa: E402

import bench_sky  # noqa: E402


def updates(n=100):
    from grlens_addon.blender import handlers, motion, world

    scene, cam = bench_sky.scene_with_sky()
    cam.animation_data_clear()
    cam.location = (40.0, 0.5, 0.5)
    cam.keyframe_insert("location", frame=1)
    cam.location = (8.0, 0.5, 0.5)
    cam.keyframe_insert("location", frame=n)
    for fc in motion._fcurves(cam):
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"
    out = {}
    bpy.app.handlers.depsgraph_update_post.remove(handlers.on_depsgraph_update)
    try:
        for c in (0.0, 2.0, 0.0, 2.0):
            scene.grlens.speed_of_light = c
            dg = bpy.context.evaluated_depsgraph_get()
            for f in range(2, n):
                scene.frame_set(f)
                t0 = time.perf_counter()
                line = world.update(scene, dg)
                out.setdefault(c, []).append(time.perf_counter() - t0)
            assert (c > 0) == ("camera at" in line), line
    finally:
        bpy.app.handlers.depsgraph_update_post.append(handlers.on_depsgraph_update)
    return out


def renders(repeats=5, sky="noise", sampling="NONE"):
    """Render times per case (see the module docstring); ``sky`` as bench_sky.scene_with_sky,
    ``sampling`` the world's importance sampling ('NONE': the shader's cost shows; 'AUTOMATIC':
    Blender's default, its map evaluates the world shader too)."""
    scene, cam = bench_sky.scene_with_sky(sky=sky)
    scene.world.cycles.sampling_method = sampling
    cam.animation_data_clear()
    cam.location = (40.0, 0.5, 0.5)
    cam.keyframe_insert("location", frame=1)
    cam.location = (40.0, 20.5, 0.5)  # 10 BU per frame sideways
    cam.keyframe_insert("location", frame=3)
    scene.frame_set(2)
    times = {}
    g = scene.grlens
    for k in range(repeats + 1):  # the first round warms up (kernel, shader compile): not counted
        # at rest; moving at 1e-5 c (the same picture) with the inverse aberration only (colour
        # switches off), and with the sky's colour shift too
        for case, c, colours in (("rest", 0.0, True), ("aberration", 1.0e6, False), ("colours", 1.0e6, True)):
            g.speed_of_light = c
            g.use_doppler_colour = g.use_beaming = g.use_gravitational_shift = colours
            scene.frame_set(2)
            t0 = time.perf_counter()
            bpy.ops.render.render(write_still=False)
            if k:
                times.setdefault(case, []).append(time.perf_counter() - t0)
    return times, scene.grlens.world_status


def main():
    import grlens_addon

    grlens_addon.register()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    up = updates()
    print(f"world update per frame, camera flying in (a new table each frame): at rest "
          f"{1e3 * statistics.median(up[0.0]):.2f} ms, moving {1e3 * statistics.median(up[2.0]):.2f} ms (medians)")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    t, status = renders()
    rest, ab, col = min(t["rest"]), min(t["aberration"]), min(t["colours"])
    print(f"Cycles 320x180, 16 samples, no importance map, best of {len(t['rest'])}: at rest {rest:.3f} s, moving "
          f"with the inverse aberration {ab:.3f} s ({ab / rest:.3f}x), and the sky's colour shift {col:.3f} s "
          f"({col / rest:.3f}x); {status}")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    th, _ = renders(repeats=3, sky="hdri", sampling="AUTOMATIC")
    rest, ab, col = min(th["rest"]), min(th["aberration"]), min(th["colours"])
    print(f"Cycles 320x180, 16 samples, a 2048x1024 image sky with Blender's default importance map, best of "
          f"{len(th['rest'])}: at rest {rest:.3f} s, inverse aberration {ab:.3f} s ({ab / rest:.3f}x), colour shift "
          f"{col:.3f} s ({col / rest:.3f}x)")
    if "--write" in sys.argv:
        _write(up, t, th)


def _write(up, t, th):
    """The lensed world's section of docs/physical_time.md from this run's figures."""
    from provenance import code_version

    from bench_physical_time import SKY_BEGIN, SKY_END

    rest, ab, col = min(t["rest"]), min(t["aberration"]), min(t["colours"])
    h_rest, h_ab, h_col = min(th["rest"]), min(th["aberration"]), min(th["colours"])
    lines = [SKY_BEGIN, f"<!-- generated by benchmarks/bench_physical_time_sky.py on {code_version()} -->", "",
             "## The lensed world of a moving camera", "",
             "From `./dev bench physical_time_sky --write` (see its docstring). The world's update per frame for a "
             "camera flying in from 20 to 4 r_s (a new deflection table each frame), medians: at rest "
             f"{1e3 * statistics.median(up[0.0]):.2f} ms, moving {1e3 * statistics.median(up[2.0]):.2f} ms. A Cycles "
             f"render that is nearly all sky of a cheap procedural world (320x180, 16 samples, best of {len(t['rest'])}"
             f"): at rest {rest:.3f} s; moving at 1e-5 c (the same picture) with the inverse aberration "
             f"{ab:.3f} s ({ab / rest:.2f}x); with the sky's colour shift too {col:.3f} s ({col / rest:.2f}x). The "
             "shift is linked in only with physical time and a colour switch on, the inverse aberration only "
             "while the camera moves; the shift's cost per sample is that of the node group \"grlens Shift by g\" "
             "(three curve lookups for the 3x3 matrix of g, a sum of three scaled columns and the brightness), "
             "which a cheap sky makes large in proportion. The same with a 2048 x 1024 image as the sky and "
             f"Blender's default importance map (which evaluates the world shader too; best of {len(th['rest'])}): "
             f"at rest {h_rest:.3f} s, the inverse aberration {h_ab / h_rest:.2f}x, the colour shift too "
             f"{h_col / h_rest:.2f}x. The target of a render within 10 % of the same render without physical time "
             "is not met: the shift's 3x3 matrix of g costs per sample about as much as the lensed sky's own "
             "escape lookup. Renders where surfaces, not the sky, take most of the time pay less in proportion.", "",
             SKY_END]
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "docs", "physical_time.md")
    old = open(path).read()
    if SKY_BEGIN in old:
        old = old[:old.index(SKY_BEGIN)] + old[old.index(SKY_END) + len(SKY_END):].lstrip("\n")
    with open(path, "w") as f:
        f.write(old.rstrip("\n") + "\n\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
    sys.stdout.flush()
    os._exit(0)
