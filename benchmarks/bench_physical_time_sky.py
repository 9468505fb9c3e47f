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


def renders(repeats=5):
    scene, cam = bench_sky.scene_with_sky()
    scene.world.cycles.sampling_method = "NONE"
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


if __name__ == "__main__":
    main()
    sys.stdout.flush()
    os._exit(0)
