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
  more or less sky, shadow and objects.) The same with a 2048 x 1024 image as the sky and Blender's
  default importance map (whose bake evaluates the world shader once per map texel), best of 3;
* a realistic scene: the ``orbit`` sample scene (sample_scenes/orbit.py: a camera on the circular orbit
  at 6 r_s, 0.32 c, looking at the thin disc and the sphere in front of the procedural star field) at
  frame 1, 320x180, 16 samples: the render with the sky as the moving camera sees it (inverse
  aberration and colour shift) against the same image meshes under the sky of a camera at rest
  (grlens' handlers detached so that the meshes stay; the world's aberration and shift unlinked),
  alternated, best of 5.

Times are CPU seconds of the Blender process (time.process_time: every render thread's time), the
cost that does not depend on what else the machine runs; wall-clock best times are printed beside
them. Ratios are of the best times.

``--profile`` prints instead what each node of the moving camera's sky costs per sample: the
nearly-all-sky render again with one node (or one group of nodes) taken out at a time (its consumers
fed from its input, or left at their defaults), alternated with the full one, best of 5, in ns per
sample (CPU time over 320 x 180 x 16 samples).

Units: milliseconds and seconds as printed; r_s = 2 BU (the orbit scene: 1 BU).

Usage: ``./dev bench physical_time_sky [--write | --profile]``: with --write, the figures replace the
lensed world's section of docs/physical_time.md (between its markers; bench_physical_time.py keeps it).
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


def _render():
    """One still render: (CPU seconds of the process, wall seconds)."""
    c0, t0 = time.process_time(), time.perf_counter()
    bpy.ops.render.render(write_still=False)
    return time.process_time() - c0, time.perf_counter() - t0


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
            t = _render()
            if k:
                times.setdefault(case, []).append(t)
    return times, scene.grlens.world_status


def realistic(repeats=5):
    """The orbit sample scene at frame 1 (see the module docstring): {'moving': [...], 'rest': [...]}
    of (CPU, wall) seconds, and the world status."""
    from grlens_addon.blender import handlers, world

    from sample_scenes import orbit

    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    orbit.orbit(scene, "normal", physical=True)
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = 320, 180, 100
    scene.cycles.samples = 16
    scene.cycles.use_denoising = False
    scene.cycles.device = "CPU"
    status = scene.grlens.world_status
    assert "camera at" in status, status
    node = world._group_node(scene.world.node_tree)
    grp = node.node_tree
    handlers.detach()
    times = {}
    try:
        for k in range(repeats + 1):
            for case in ("moving", "rest"):
                world._use_aberration(grp, case == "moving")
                world._hook_sky_shift(scene.world, node, case == "moving")
                t = _render()
                if k:
                    times.setdefault(case, []).append(t)
    finally:
        handlers.attach()
    return times, status


def main():
    import grlens_addon

    grlens_addon.register()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    if "--profile" in sys.argv:
        profile()
        return
    up = updates()
    print(f"world update per frame, camera flying in (a new table each frame): at rest "
          f"{1e3 * statistics.median(up[0.0]):.2f} ms, moving {1e3 * statistics.median(up[2.0]):.2f} ms (medians)")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    t, status = renders()
    print(f"Cycles 320x180, 16 samples, no importance map, best of {len(t['rest'])}: " + _line(t) + f"; {status}")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    th, _ = renders(repeats=3, sky="hdri", sampling="AUTOMATIC")
    print(f"Cycles 320x180, 16 samples, a 2048x1024 image sky with Blender's default importance map, best of "
          f"{len(th['rest'])}: " + _line(th))
    tr, status = realistic()
    print(f"orbit sample scene, frame 1, Cycles 320x180, 16 samples, best of {len(tr['rest'])}: the sky at rest "
          + _pair(tr, "rest") + ", as the moving camera sees it " + _pair(tr, "moving")
          + f" ({_ratio(tr, 'moving'):.3f}x); {status}")
    if "--write" in sys.argv:
        _write(up, t, th, tr)


def _feed(tree, sock, src):
    """Link ``src`` into ``sock`` (None: unlink it, its default value then used); returns the former source."""
    old = sock.links[0].from_socket if sock.is_linked else None
    for lk in list(sock.links):
        tree.links.remove(lk)
    if src is not None:
        tree.links.new(src, sock)
    return old


def _cuts(grp, shift):
    """{label: [(tree, input socket, new source or None)]}: the moving camera's sky with one node or
    group of nodes taken out (see the module docstring)."""
    from grlens_addon.blender import world

    g, s = grp.nodes, shift.nodes
    static = g["static direction"]
    raw = static.inputs[0].links[0].from_socket  # D + k n, unnormalized
    d = g["D"].outputs["Vector"]
    combine = [n for n in s if n.bl_idname == "ShaderNodeCombineColor"][0]
    return {
        "the inverse aberration but its dot product (3 nodes)": [(grp, sock, d) for sock in world._direction_inputs(grp)],
        "its normalization (1 vector node)": [(grp, sock, raw) for sock in world._direction_inputs(grp)],
        "the clip of negative channels (3 float nodes)":
            [(shift, combine.inputs[i], combine.inputs[i].links[0].from_node.inputs[0].links[0].from_socket)
             for i in range(3)],
        "lookup B (1 image node)": [(shift, s["shift B entries"].inputs[0], None)],
        "lookup A (1 image node)": [(shift, s["shift A entries"].inputs[0], None),
                                    (shift, s["row 1 inner"].inputs[0], None)],
        "both lookups and u (3 nodes)": [(shift, s["shift A entries"].inputs[0], None),
                                         (shift, s["row 1 inner"].inputs[0], None),
                                         (shift, s["shift B entries"].inputs[0], None)],
    }


def profile(repeats=5):
    """Per-sample costs of the moving camera's sky, node by node (module docstring): prints them."""
    from grlens_addon.blender import world

    scene, cam = bench_sky.scene_with_sky()
    scene.world.cycles.sampling_method = "NONE"
    cam.animation_data_clear()
    cam.location = (40.0, 0.5, 0.5)
    cam.keyframe_insert("location", frame=1)
    cam.location = (40.0, 20.5, 0.5)
    cam.keyframe_insert("location", frame=3)
    g = scene.grlens
    g.speed_of_light = 1.0e6
    scene.frame_set(2)
    node = world._group_node(scene.world.node_tree)
    grp = node.node_tree
    shift = grp.nodes[world.SHIFT_HOLDER].node_tree
    from grlens_addon.blender import handlers

    handlers.detach()  # the cuts stay as made (no update relinks them)
    cases = {"full": [], **_cuts(grp, shift)}
    times = {}
    try:
        for k in range(repeats + 1):
            for label, cut in list(cases.items()) + [("the colour shift (unhooked)", None),
                                                     ("the sky at rest (nothing of physical time)", None)]:
                if label.startswith("the colour shift"):
                    world._hook_sky_shift(scene.world, node, False)
                elif label.startswith("the sky at rest"):
                    world._hook_sky_shift(scene.world, node, False)
                    world._use_aberration(grp, False)
                old = [(tree, sock, _feed(tree, sock, src)) for tree, sock, src in cut or []]
                t = _render()
                for tree, sock, src in reversed(old):
                    _feed(tree, sock, src)
                world._hook_sky_shift(scene.world, node, True)
                world._use_aberration(grp, True)
                if k:
                    times.setdefault(label, []).append(t)
    finally:
        handlers.attach()
    n = scene.render.resolution_x * scene.render.resolution_y * scene.cycles.samples
    full = min(v[0] for v in times["full"])
    print(f"the moving camera's sky with the colour shift, Cycles 320x180, 16 samples, best of {repeats}: "
          f"{full:.3f} s CPU, {1e9 * full / n:.0f} ns per sample")
    for label, v in times.items():
        if label != "full":
            best = min(x[0] for x in v)
            print(f"  without {label}: {best:.3f} s CPU, saves {1e9 * (full - best) / n:.1f} ns per sample "
                  f"({(full - best) / full:.1%})")


def _best(t, case, k=0):
    return min(v[k] for v in t[case])


def _ratio(t, case, base="rest"):
    return _best(t, case) / _best(t, base)


def _pair(t, case):
    return f"{_best(t, case):.3f} s CPU ({_best(t, case, 1):.3f} s wall)"


def _line(t):
    return (f"at rest {_pair(t, 'rest')}, moving with the inverse aberration {_pair(t, 'aberration')} "
            f"({_ratio(t, 'aberration'):.3f}x), and the sky's colour shift {_pair(t, 'colours')} "
            f"({_ratio(t, 'colours'):.3f}x)")


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
