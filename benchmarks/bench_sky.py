"""Lensed world (sky) benchmark, in the pip bpy of the dev environment: ``./dev bench sky``.

Prints
* the escape table's build time (lutgen.escape_table, default size), best of 20;
* the per-frame cost of the world update for a camera that moves and changes its distance every
  frame (grlens_addon.blender.world.update: values and a new table each frame), of an update with
  the camera at the same distance (nothing to write), of a frame change to frames seen before
  (scrubbing: their tables are kept), and the extra
  time of a whole frame change (scene.frame_set) with lens_world on against off, medians over
  100 frames;
* the same update for a world of about 125 nodes (the pass over the user's tree);
* the Cycles render time of one scene with and without the lensed world, alternated in one process
  (CPU, 320x180, 16 samples, a diffuse sphere lit by a procedural world, or by an HDRI made here),
  best of 3 each: with the
  world's importance sampling map at its default resolution (1024), at 256, and off (so the
  per-sample cost of the world shader is seen apart from the map's bake, a fixed cost per frame);
* the same for the sample scenes ``starfield`` (normal view) and ``starfield_panorama`` at their
  own settings (resolution, 16 samples, no importance map), frame 1, best of 5 and medians: a
  lensed disc and sphere in front of a procedural star field, the render a user of the sample gets
  (this machine's render times vary by about 10% from run to run).

Units: milliseconds and seconds as printed; the scene in Blender units with r_s = 2 BU.
"""
import math
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

import grlens_addon  # noqa: E402
from lutgen.escape import TABLE_SIZE, escape_table  # noqa: E402


def scene_with_sky(resolution=(320, 180), samples=16, sky="noise"):
    """The benchmark scene; ``sky``: 'noise' (a cloudy procedural sky) or 'hdri' (an Environment
    Texture of a 2048 x 1024 float image made here, as an HDRI would be used)."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    w = bpy.data.worlds.new("Sky")
    scene.world = w
    if bpy.app.version < (5, 0, 0):
        w.use_nodes = True
    nt = w.node_tree
    if sky == "hdri":
        img = bpy.data.images.new("HDRI", 2048, 1024, alpha=False, float_buffer=True)
        y, x = np.mgrid[0:1024, 0:2048] / 1024.0
        val = 0.5 + 0.4 * np.sin(9.0 * x) * np.cos(7.0 * y) + 0.1 * np.random.default_rng(1).random((1024, 2048))
        px = np.ones((1024, 2048, 4), np.float32)
        px[..., :3] = val[..., None] * np.array([1.0, 0.9, 0.8])
        img.pixels.foreach_set(px.ravel())
        env = nt.nodes.new("ShaderNodeTexEnvironment")  # default coordinates: the view direction
        env.image = img
        nt.links.new(env.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    else:
        noise = nt.nodes.new("ShaderNodeTexNoise")  # a cloudy sky from the world's default coordinates
        noise.inputs["Scale"].default_value = 4.0
        ramp = nt.nodes.new("ShaderNodeValToRGB")
        nt.links.new(noise.outputs["Fac"], ramp.inputs["Fac"])
        nt.links.new(ramp.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    hole = bpy.data.objects.new("BlackHole", None)
    scene.collection.objects.link(hole)
    mesh = bpy.data.meshes.new("Ball")
    import bmesh

    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=2.0)
    bm.to_mesh(mesh)
    bm.free()
    ball = bpy.data.objects.new("Ball", mesh)
    ball.location = (10.0, 8.0, 0.0)
    scene.collection.objects.link(ball)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (40.0, 0.5, 0.5)
    cam.rotation_euler = (math.radians(90), 0.0, math.radians(100))
    cam.data.angle = math.radians(70)
    scene.collection.objects.link(cam)
    scene.camera = cam
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = resolution[0], resolution[1], 100
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.cycles.device = "CPU"
    g = scene.grlens
    g.r_s = 2.0
    g.black_hole = hole
    return scene, cam


def per_frame(n=100):
    from grlens_addon.blender import world

    scene, cam = scene_with_sky()
    cam.animation_data_clear()
    cam.location = (40.0, 0.5, 0.5)
    cam.keyframe_insert("location", frame=1)
    cam.location = (8.0, 0.5, 0.5)  # 20 -> 4 r_s: a new radius (and table) every frame
    cam.keyframe_insert("location", frame=n)
    out = {}
    for on in (True, False, True, False):
        scene.grlens.lens_world = on
        world._PIXELS.clear()  # every frame's table computed, as for a camera flying in the first time
        times = []
        for f in range(1, n + 1):
            t0 = time.perf_counter()
            scene.frame_set(f)
            times.append(time.perf_counter() - t0)
        out.setdefault(on, []).extend(times)
    scene.grlens.lens_world = True
    for f in range(1, n + 1):  # once through: every frame's table made
        scene.frame_set(f)
    looped = []
    for f in range(1, n + 1):  # the same frames again (scrubbing, a looping playback): tables kept
        t0 = time.perf_counter()
        scene.frame_set(f)
        looped.append(time.perf_counter() - t0)
    dg = bpy.context.evaluated_depsgraph_get()
    upd = []
    # world.update alone: grlens' depsgraph handler would update the world as soon as the moved
    # camera is evaluated, so it is detached while the camera moves
    from grlens_addon.blender import handlers

    bpy.app.handlers.depsgraph_update_post.remove(handlers.on_depsgraph_update)
    try:
        for f in range(1, n + 1):
            scene.frame_set(f)
            cam.location.x += 1e-3  # a new radius for the update below
            dg.update()
            t0 = time.perf_counter()
            world.update(scene, dg)
            upd.append(time.perf_counter() - t0)
    finally:
        bpy.app.handlers.depsgraph_update_post.append(handlers.on_depsgraph_update)
    same = []
    for _ in range(n):  # the camera keeps its distance: values only, no new table
        t0 = time.perf_counter()
        world.update(scene, dg)
        same.append(time.perf_counter() - t0)
    return out, upd, same, looped


def big_world_update(n_layers=60, n=50):
    """world.update with the camera at the same distance (nothing to write) for a world of
    3 + 2 n_layers nodes (n_layers Noise textures mixed in a chain): the hooking pass over the user's
    tree, linear in its size."""
    from grlens_addon.blender import world

    scene, cam = scene_with_sky()
    nt = scene.world.node_tree
    prev = nt.nodes["Background"].inputs["Color"].links[0].from_socket
    for _ in range(n_layers):
        tex = nt.nodes.new("ShaderNodeTexNoise")
        mix = nt.nodes.new("ShaderNodeMix")
        mix.data_type = "RGBA"
        nt.links.new(prev, mix.inputs[6])
        nt.links.new(tex.outputs["Color"], mix.inputs[7])
        prev = mix.outputs[2]
    nt.links.new(prev, nt.nodes["Background"].inputs["Color"])
    dg = bpy.context.evaluated_depsgraph_get()
    world.update(scene, dg)
    nodes = len(nt.nodes)
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        world.update(scene, dg)
        times.append(time.perf_counter() - t0)
    return nodes, statistics.median(times)


def render_times(repeats=3, method="AUTOMATIC", map_resolution=1024, sky="noise"):
    scene, cam = scene_with_sky(sky=sky)
    scene.world.cycles.sampling_method = "MANUAL" if method == "AUTOMATIC" and map_resolution != 1024 else method
    scene.world.cycles.sample_map_resolution = map_resolution
    path = os.path.join(bpy.app.tempdir or "/tmp", "bench_sky.png")
    scene.render.filepath = path
    times = {True: [], False: []}
    for on in (False, True):  # warm-up (kernel, first shader compile), not counted
        scene.grlens.lens_world = on
        bpy.ops.render.render(write_still=False)
    for _ in range(repeats):
        for on in (False, True):
            scene.grlens.lens_world = on
            t0 = time.perf_counter()
            bpy.ops.render.render(write_still=False)
            times[on].append(time.perf_counter() - t0)
    return times


def sample_scene_times(name, repeats=3):
    from sample_scenes.scenes import DEFAULTS, SCENES

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    SCENES[name](scene)
    d = DEFAULTS[name]
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y = d["resolution"]
    r.resolution_percentage = 100
    scene.cycles.samples = d["samples"]
    scene.cycles.use_denoising = False
    scene.cycles.device = "CPU"
    times = {True: [], False: []}
    for k in range(repeats + 1):  # the first round warms up (kernel, shader compile): not counted
        for on in (False, True):
            scene.grlens.lens_world = on
            t0 = time.perf_counter()
            bpy.ops.render.render(write_still=False)
            if k:
                times[on].append(time.perf_counter() - t0)
    return times, d


def main():
    grlens_addon.register()
    t = []
    for _ in range(20):
        t0 = time.perf_counter()
        escape_table(20.0 + 1e-3 * len(t))
        t.append(time.perf_counter() - t0)
    print(f"escape table ({TABLE_SIZE} nodes): {min(t) * 1e3:.2f} ms best of 20, median {statistics.median(t) * 1e3:.2f} ms")
    frames, upd, same, looped = per_frame()
    on, off = statistics.median(frames[True]), statistics.median(frames[False])
    print(f"world.update per frame, new radius each frame: median {statistics.median(upd) * 1e3:.2f} ms, "
          f"p90 {np.percentile(upd, 90) * 1e3:.2f} ms, max {max(upd) * 1e3:.2f} ms")
    print(f"world.update, camera at the same distance: median {statistics.median(same) * 1e3:.2f} ms")
    print(f"frame_set, the same moving-camera frames again (tables kept): median "
          f"{statistics.median(looped) * 1e3:.2f} ms")
    nodes, t_big = big_world_update()
    print(f"world.update, camera at the same distance, a world of {nodes} nodes (incl. grlens' 2): "
          f"median {t_big * 1e3:.2f} ms")
    print(f"frame_set, moving camera (no marked object): lens_world on {on * 1e3:.2f} ms, off {off * 1e3:.2f} ms "
          f"(medians of 200 frames each): +{(on - off) * 1e3:.2f} ms per frame")
    for sky, method, res, what in (("noise", "AUTOMATIC", 1024, "importance map 1024 (default)"),
                                   ("noise", "AUTOMATIC", 256, "importance map 256"),
                                   ("noise", "NONE", 1024, "no importance map"),
                                   ("hdri", "AUTOMATIC", 1024, "HDRI world, importance map 1024 (default)"),
                                   ("hdri", "NONE", 1024, "HDRI world, no importance map")):
        rt = render_times(method=method, map_resolution=res, sky=sky)
        a, b = min(rt[False]), min(rt[True])
        print(f"Cycles 320x180, 16 samples, CPU, {what}: without lensed world {a:.2f} s, with {b:.2f} s "
              f"(best of 3, alternated): ratio {b / a:.2f}")
    for name in ("starfield", "starfield_panorama"):
        rt, d = sample_scene_times(name, repeats=5)
        a, b = min(rt[False]), min(rt[True])
        ma, mb = statistics.median(rt[False]), statistics.median(rt[True])
        print(f"Cycles sample scene {name}, {d['resolution'][0]}x{d['resolution'][1]}, {d['samples']} samples, CPU: "
              f"without lensed world {a:.2f} s, with {b:.2f} s (best of 5, alternated): ratio {b / a:.2f}; "
              f"medians {ma:.2f} s and {mb:.2f} s: ratio {mb / ma:.2f}")
    print(f"bpy {bpy.app.version_string}, {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
    sys.stdout.flush()
    os._exit(0)
