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
  at 6 r_s looking at the thin disc and the sphere in front of the procedural star field) at frame 1,
  320x180, 16 samples (adaptive sampling off, here and above: every case takes all its samples), with
  the speed of light raised to 1e6 BU per frame so that the keyed camera moves at 1.6e-7 c (its images
  and sky the picture of a camera at rest, as in the worst case above): the render with the moving
  camera's sky (inverse aberration and colour shift linked in) against the same image meshes under the
  sky of a camera at rest (grlens' handlers detached so that the meshes stay; the world's aberration
  and shift unlinked), alternated, best of 5. (At the scene's own 0.32 c the two skies are other
  pictures: the shadow, where the world's own nodes are skipped, has another size.)

Times are CPU seconds of the Blender process (time.process_time: every render thread's time), the
cost that does not depend on what else the machine runs; wall-clock best times are printed beside
them. Ratios are of the best times.

``--profile`` prints instead what each node of the moving camera's sky costs per sample: the
nearly-all-sky render again with one node (or one group of nodes) taken out at a time (its consumers
fed from its input, or left at their defaults), alternated with the full one, best of 5, in ns per
sample (CPU time over 320 x 180 x 16 samples).

``--instructions`` (needs valgrind) counts instead of timing: each case and each cut of --profile
rendered once (1 sample per pixel, one thread) under callgrind in a process of its own, the
instructions collected in Cycles' kernels of a sample's path (KERNELS), and of those the world's
shading (ccl::integrator_shade_background), per sample: exact and the same on any machine with this
Blender, whatever else runs (a lookup's memory access or a logarithm counts as its instructions, not
its time). Cycles spends about the same on any node (decoding it, loading and storing its operands), so
these counts are what the shader's node count is chosen by. With --write as well, they go into the
section too.

Units: milliseconds and seconds as printed; r_s = 2 BU (the orbit scene: 1 BU).

Usage: ``./dev bench physical_time_sky [--write] [--instructions] | --profile``: with --write, the
figures replace the lensed world's section of docs/physical_time.md (between its markers;
bench_physical_time.py keeps it).
"""
import os
import shutil
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
    scene.cycles.use_adaptive_sampling = False  # every case takes all its samples (the pictures differ a little)
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
    # the same picture in both cases: the keyed camera at 1.6e-7 c (the images rebuilt for it), its
    # sky's shift and inverse aberration linked in or not
    scene.grlens.speed_of_light = 1.0e6
    scene.frame_set(1)
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = 320, 180, 100
    scene.cycles.samples = 16
    scene.cycles.use_adaptive_sampling = False  # the two skies differ: adaptive sampling would stop at other counts
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
    if "--one" in sys.argv:
        _one(sys.argv[sys.argv.index("--one") + 1])
        return
    if "--profile" in sys.argv:
        profile()
        return
    ins = None
    if "--instructions" in sys.argv:
        ins = instructions()
        _print_instructions(ins)
        if "--write" not in sys.argv:
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
        _write(up, t, th, tr, ins)


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
    raw = g["static direction"].inputs[0].links[0].from_socket  # D + k n, unnormalized
    d = g["D"].outputs["Vector"]
    out = [n for n in s if n.bl_idname == "NodeGroupOutput"][0]
    return {
        "the inverse aberration but its dot product (3 nodes and a float-to-vector conversion)": [(grp, sock, d) for sock in world._direction_inputs(grp)],
        "its normalization (1 vector node)": [(grp, sock, raw) for sock in world._direction_inputs(grp)],
        "the clip of negative channels (1 vector node)": [(shift, out.inputs["Color"], s["Combine XYZ"].outputs[0])],
        "row 2 (its lookup and dot product: Cycles folds a dot product with a zero vector)":
            [(shift, s["row 2"].inputs[0], None)],
        "rows 1 and 2 (two lookups and dot products)": [(shift, s["row 1"].inputs[0], None),
                                                       (shift, s["row 2"].inputs[0], None)],
    }


VARIANTS = ("rest", "aberration", "colours")
"""The render cases of the module docstring (sky at rest, inverse aberration, and the colour shift too)."""

KERNELS = "ccl::kernel_cpu_*integrator_*"
"""Cycles' CPU kernels of a sample's path, collected by --instructions (called one after the other, never
nested: callgrind toggles collection at each entry and exit): the camera ray (init_from_camera), and the
path traced and shaded (the megakernel; the world's shader in ccl::integrator_shade_background)."""


def _moving_scene(samples=16, threads=0):
    """bench_sky's nearly-all-sky scene with the camera keyed moving (1e-5 c at speed_of_light 1e6)."""
    scene, cam = bench_sky.scene_with_sky()
    scene.world.cycles.sampling_method = "NONE"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = False
    if threads:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = threads
    cam.animation_data_clear()
    cam.location = (40.0, 0.5, 0.5)
    cam.keyframe_insert("location", frame=1)
    cam.location = (40.0, 20.5, 0.5)
    cam.keyframe_insert("location", frame=3)
    return scene


def _set_case(scene, case):
    g = scene.grlens
    g.speed_of_light = 0.0 if case == "rest" else 1.0e6
    g.use_doppler_colour = g.use_beaming = g.use_gravitational_shift = case != "aberration"
    scene.frame_set(2)


def _one(variant):
    """Child of --instructions, run under callgrind: one render of ``variant`` (a case of VARIANTS or
    "cut:K", the K-th of :func:`_cuts`) at 1 sample per pixel, one thread, instrumented from just before
    it."""
    import subprocess

    from grlens_addon.blender import handlers, world

    scene = _moving_scene(samples=1, threads=1)
    _set_case(scene, variant if variant in VARIANTS else "colours")
    if variant.startswith("cut:"):
        node = world._group_node(scene.world.node_tree)
        grp = node.node_tree
        handlers.detach()
        cut = list(_cuts(grp, grp.nodes[world.SHIFT_HOLDER].node_tree).values())[int(variant[4:])]
        for tree, sock, src in cut:
            _feed(tree, sock, src)
    subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], capture_output=True, check=True)
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < 1.5:  # callgrind takes the request at its next check
        pass
    bpy.ops.render.render(write_still=False)


def instructions():
    """Instructions per sample of each variant (VARIANTS, then the cuts of :func:`_cuts`) by callgrind:
    {variant: (all of the sample's kernels, the world's shading alone)}; exact, the same on any machine
    with the same Blender (not a time: a lookup's memory access or a logarithm counts as its
    instructions)."""
    import subprocess
    import tempfile

    if not shutil.which("valgrind"):
        raise SystemExit("--instructions needs valgrind (callgrind)")
    cuts = _cut_labels()
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for k, variant in enumerate(list(VARIANTS) + [f"cut:{i}" for i in range(len(cuts))]):
            f = os.path.join(tmp, f"cg.{k}")
            cmd = ["valgrind", "--tool=callgrind", "--instr-atstart=no", f"--callgrind-out-file={f}"]
            cmd.append(f"--toggle-collect={KERNELS}")
            subprocess.run(cmd + [sys.executable, os.path.abspath(__file__), "--one", variant], check=True,
                           capture_output=True)
            total = int(next(ln for ln in open(f) if ln.startswith(("summary:", "totals:"))).split()[1])
            ann = subprocess.run(["callgrind_annotate", "--inclusive=yes", "--threshold=100", f], check=True,
                                 capture_output=True, text=True).stdout
            world_ir = max(int(ln.split()[0].replace(",", "")) for ln in ann.splitlines()
                           if "integrator_shade_background" in ln and ln.split()[0].replace(",", "").isdigit())
            if total == 0:
                raise RuntimeError(f"callgrind collected nothing for {variant}")
            n = 320 * 180
            out[cuts[k - len(VARIANTS)] if k >= len(VARIANTS) else variant] = (total / n, world_ir / n)
    return out


def _cut_labels():
    """The labels of :func:`_cuts` (built on a scene of their own)."""
    from grlens_addon.blender import world

    scene = _moving_scene(samples=1)
    _set_case(scene, "colours")
    grp = world._group_node(scene.world.node_tree).node_tree
    return list(_cuts(grp, grp.nodes[world.SHIFT_HOLDER].node_tree))


def profile(repeats=5):
    """Per-sample costs of the moving camera's sky, node by node, in CPU time (module docstring): prints
    them."""
    from grlens_addon.blender import handlers, world

    scene = _moving_scene()
    _set_case(scene, "colours")
    node = world._group_node(scene.world.node_tree)
    grp = node.node_tree
    shift = grp.nodes[world.SHIFT_HOLDER].node_tree
    handlers.detach()  # the cuts stay as made (no update relinks them)
    cases = {"full": [], **_cuts(grp, shift)}
    times = {}
    try:
        for k in range(repeats + 1):
            for label, cut in list(cases.items()) + [("the colour shift (unhooked)", None),
                                                     ("everything of physical time (the sky at rest)", None)]:
                if cut is None:
                    world._hook_sky_shift(scene.world, node, False)
                    if label.startswith("everything"):
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


def _print_instructions(ins):
    rest = ins["rest"]
    print("instructions per sample (callgrind; all of a sample's kernels / the world's shading alone):")
    for label, (total, sky) in ins.items():
        print(f"  {label}: {total:.0f} ({total / rest[0]:.3f}x) / {sky:.0f} ({sky / rest[1]:.3f}x)")
    full = ins["colours"]
    for label, (total, sky) in ins.items():
        if label not in VARIANTS:
            print(f"  colours without {label}: saves {full[0] - total:.0f} per sample")


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


def _verdict(real, worst, target):
    """The section's sentence on the target (a render within ``target`` times the one without physical
    time) from the realistic and the worst-case ratios."""
    head = "The target of a render within 10 % of the same render without physical time is "
    why = (": where a cheap sky is most of each sample's work, the inverse aberration (four nodes and a "
           "conversion) and the shift (nine nodes) cost more per sample than a tenth of it.")
    if real <= target and worst <= target:
        return head + f"met in the realistic scene ({real:.2f}x) and in the worst case ({worst:.2f}x)."
    if real <= target:
        return head + f"met in the realistic scene ({real:.2f}x) but not in the worst case ({worst:.2f}x)" + why
    if worst <= target:
        return head + f"met in the worst case ({worst:.2f}x) but not in the realistic scene ({real:.2f}x)."
    return (head + f"not met: {real:.2f}x in the realistic scene, {worst:.2f}x in the worst case" + why
            + " Scenes where surfaces take more of each sample pay less in proportion.")


def _write(up, t, th, tr, ins=None):
    """The lensed world's section of docs/physical_time.md from this run's figures (``ins``: those of
    --instructions, when run with it)."""
    from provenance import code_version

    from bench_physical_time import SKY_BEGIN, SKY_END

    worst, hdri, real = _ratio(t, "colours"), _ratio(th, "colours"), _ratio(tr, "moving")
    target = 1.10
    text = [
        "From `./dev bench physical_time_sky --write` (see its docstring; times are CPU seconds of the Blender "
        "process, which do not depend on what else this shared machine runs; wall-clock times beside them). "
        "The world's update per frame for a camera flying in from 20 to 4 r_s (a new deflection table each "
        f"frame), medians: at rest {1e3 * statistics.median(up[0.0]):.2f} ms, moving with the colour shift "
        f"{1e3 * statistics.median(up[2.0]):.2f} ms (new sky-shift tables each frame too).",
        "",
        "A Cycles render that is nearly all sky of a cheap procedural world (the worst case: 320x180, 16 samples, "
        f"no importance map, best of {len(t['rest'])}): at rest {_pair(t, 'rest')}; moving at 1e-5 c (the same "
        f"picture) with the inverse aberration {_pair(t, 'aberration')} ({_ratio(t, 'aberration'):.2f}x); with "
        f"the sky's colour shift too {_pair(t, 'colours')} ({worst:.2f}x). The same with a 2048 x 1024 image "
        f"as the sky and Blender's default importance map (best of {len(th['rest'])}): at rest {_pair(th, 'rest')}, "
        f"the inverse aberration {_ratio(th, 'aberration'):.2f}x, the colour shift too {hdri:.2f}x. A realistic "
        f"scene, the `orbit` sample scene at frame 1 (320x180, 16 samples, best of {len(tr['rest'])}; the camera "
        "on its orbit in front of the thin disc, the sphere and the procedural star field, at 1.6e-7 c for the "
        "same picture), the same image meshes under the sky of a camera at rest "
        f"{_pair(tr, 'rest')} and under the moving camera's sky {_pair(tr, 'moving')}: {real:.2f}x.",
    ]
    if ins is not None:
        r, c = ins["rest"], ins["colours"]
        a = ins["aberration"]
        text += ["", "Instructions per sample, counted by callgrind in Cycles' kernels of a sample's path "
                 "(`--instructions`: exact, whatever the machine's load; the worst-case scene at 1 sample per "
                 f"pixel): at rest {r[0]:.0f}, of which the world's shading {r[1]:.0f}; the inverse aberration "
                 f"{a[0]:.0f} ({a[0] / r[0]:.2f}x); the colour shift too {c[0]:.0f} ({c[0] / r[0]:.2f}x; the "
                 f"world's shading {c[1] / r[1]:.2f}x). What single nodes save of that (the render with each "
                 "taken out, their consumers fed from their input or left at their defaults): "
                 + "; ".join(f"{label} {c[0] - v[0]:.0f}" for label, v in ins.items() if label not in VARIANTS)
                 + "."]
    text += ["", "How the shift is made cheap: per frame (it depends on the camera's speed and distance and the "
             "colour switches only) a table of the 3x3 matrix against c, the cosine of the ray's direction "
             "against the velocity in the camera's frame, which the inverse aberration computes anyway "
             "(g = 1 / (gamma (1 + |beta| c)) needs no other node), with the brightness, gravity and the "
             "switches folded in; per sample three lookups of its rows, three dot products with the colour, "
             "a Combine XYZ and a maximum (Cycles spends about the same on any node, see the counts above) "
             "(`world.sky_shift_pixels`, `_build_shift_group`; it replaced five nodes for ln g and "
             "\"grlens Shift by g\", three curve lookups, vector sums and an exponential, which surfaces keep). "
             "The importance map is built by Cycles from the same shader: its bake evaluates the world with the "
             "path flags PATH_RAY_EMISSION | PATH_RAY_IMPORTANCE_BAKE and the Light Path node's bounce outputs "
             "masked (kernel/bake/bake.h, kernel_background_evaluate), and the Light Path node reports no flag "
             "that only the bake has (kernel/svm/light_path.h), so a shader cannot leave the shift out of the map "
             "alone; leaving it out of every ray but the camera's (Is Camera Ray) would keep the sampling "
             "unbiased (the map is only a distribution of directions) but would also light and reflect the "
             "scene with the unshifted sky: a change of the picture, not made here.",
             "",
             _verdict(real, worst, target)]
    lines = [SKY_BEGIN, f"<!-- generated by benchmarks/bench_physical_time_sky.py on {code_version()} -->", "",
             "## The lensed world of a moving camera", "", *text, "", SKY_END]
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
