"""Long viewport rebuilds beside the interface (grlens_addon/blender/background.py) and the core's
progress and cancel hook (core.pipeline.Progress).

The add-on runs in the pip ``bpy`` module in background mode, where Blender has no interface and no
timer runs: the tests allow background builds there (background.FORCE), force them with a budget of
0 s, wait for the worker thread and call the timer function (background.tick) themselves. Units:
Blender units; the demo scene has r_s = 2 BU and its camera 40 BU (20 r_s) from the hole.
"""
import math
import sys

import numpy as np
import pytest

import bpy  # noqa: E402

import grlens_addon  # noqa: E402
from blender_session import empty_file, registered  # noqa: E402,F401  (autouse fixtures)
from grlens_addon.blender import background, handlers, rebuild  # noqa: E402
from grlens_addon.core import mapping, pipeline  # noqa: E402

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from meshes import uv_sphere  # noqa: E402


# --- the core's hook ---------------------------------------------------------------------------------

def _core_case(segments=48, rings=24):
    from lutgen import LUTFamily

    pts, tris = uv_sphere([0.0, 6.0, 0.04], 1.0, segments, rings)
    scene = mapping.Scene([40.0, 0, 0], [0, 0, 0], 2.0)
    settings = pipeline.Settings(max_tess_level=64, tess_a=5.0, tess_b=0.75, cull_ratio=8.0,
                                 pixel_angle=math.radians(19.0) / 360, max_error_px=0.5)
    return pipeline.SourceMesh(pts, tris), scene, LUTFamily().at(20.0), settings


def test_the_progress_hook_reports_increasing_fractions_and_changes_nothing():
    src, scene, lut, settings = _core_case()
    plain = pipeline.build_images(src, scene, lut, settings)
    seen = []
    hooked = pipeline.build_images(src, scene, lut, settings, progress=pipeline.Progress(
        lambda stage, f: seen.append((stage, f))))
    stages = [s for s, _ in seen]
    fractions = [f for _, f in seen]
    assert stages[0] == "prepare" and stages[-1] == "done" and fractions[0] == 0.0 and fractions[-1] == 1.0
    assert all(b >= a for a, b in zip(fractions, fractions[1:])), fractions
    assert len(set(fractions)) >= 10  # (every stage moves it on)
    for s in ("map", "visibility", "patches", "probes", "plan", "cut", "cull", "refine", "assemble"):
        assert s in stages, s
    assert stages.count("assemble") == 2  # (one per order)
    for o in plain:  # the hook is only called: the images are the same
        np.testing.assert_array_equal(plain[o].positions, hooked[o].positions)
        np.testing.assert_array_equal(plain[o].tris, hooked[o].tris)


@pytest.mark.parametrize("at", [0, 3, 9, 14])  # (14: the last assemble; "done" stops it)
def test_a_cancelled_build_raises_between_stages_and_leaves_nothing(at):
    src, scene, lut, settings = _core_case()
    before = (src.positions.copy(), src.tris.copy())
    calls = []

    def hook(stage, f):
        calls.append(stage)
        if len(calls) == at + 1:
            prog.cancel()

    prog = pipeline.Progress(hook)
    out = "untouched"
    with pytest.raises(pipeline.Cancelled):
        out = pipeline.build_images(src, scene, lut, settings, progress=prog)
    assert out == "untouched"  # (nothing returned)
    assert len(calls) == at + 1  # stopped at the very next stage
    np.testing.assert_array_equal(src.positions, before[0])
    np.testing.assert_array_equal(src.tris, before[1])
    assert prog.cancelled


def test_a_build_is_cancelled_inside_its_long_stages_and_reports_fractions_within_them(monkeypatch):
    """Frame.checkpoint between the blocks of the dense passes (frame.edge_lengths, the back faces in
    visibility): the hook is called inside prepare, map and plan with fractions between the stage's
    own and the next stage's, never decreasing; cancelled at such a point the build raises there,
    before the stage ends; the images with checkpoints are the same as without."""
    from grlens_addon.core import frame as F
    from grlens_addon.core import visibility

    monkeypatch.setattr(F, "EDGE_BLOCK", 1000)
    monkeypatch.setattr(visibility, "TRI_BLOCK", 1000)
    monkeypatch.setattr(visibility.B, "BACK_FACE_MIN_PIECES", 1000)  # (the sphere's back faces: the dense way)
    src, scene, lut, settings = _core_case(96, 48)
    plain = pipeline.build_images(src, scene, lut, settings)
    seen = []
    hooked = pipeline.build_images(src, scene, lut, settings, progress=pipeline.Progress(
        lambda stage, f: seen.append((stage, f))))
    fractions = [f for _, f in seen]
    assert all(b >= a for a, b in zip(fractions, fractions[1:])), fractions
    firsts = {}  # each stage's first fraction, and the repeated calls inside it
    inside = []
    for i, (stage, f) in enumerate(seen):
        if i and seen[i - 1][0] == stage:
            inside.append((stage, f, i))
        else:
            firsts.setdefault(stage, f)
    assert {s for s, _, _ in inside} >= {"prepare", "map", "plan"}, inside
    for stage, f, i in inside:
        nxt = next(g for s, g in seen[i:] if s != stage)
        assert seen[i - 1][1] <= f <= nxt
    for o in plain:
        np.testing.assert_array_equal(plain[o].positions, hooked[o].positions)
        np.testing.assert_array_equal(plain[o].tris, hooked[o].tris)
    for stage, _, i in inside[::3]:  # cancelled inside the stage: raised at the very next call
        calls = []

        def hook(s, f, at=i):
            calls.append(s)
            if len(calls) == at:
                prog.cancel()

        prog = pipeline.Progress(hook)
        with pytest.raises(pipeline.Cancelled) as err:
            pipeline.build_images(src, scene, lut, settings, progress=prog)
        assert str(err.value) == stage and calls[-1] == stage and len(calls) == i


# --- the add-on ----------------------------------------------------------------------------------------

@pytest.fixture
def forced(monkeypatch):
    """Background builds allowed in background mode, every build predicted too long (budget 0 s)."""
    monkeypatch.setattr(background, "FORCE", True)
    monkeypatch.setattr(background, "BUDGET_SECONDS", 0.0)
    yield
    background.stop()


def _dense_scene(segments=96, rings=48):
    """The demo scene at 320x180, its sphere (radius 1 BU) replaced by a denser UV sphere at rest."""
    import bmesh

    assert bpy.ops.grlens.demo_scene(r_s=2.0) == {"FINISHED"}
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 320, 180
    sphere = bpy.data.objects["OrbitingSphere"]
    sphere.animation_data_clear()
    sphere.parent = None
    sphere.location = (0.0, 6.0, 0.04)
    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=1.0, calc_uvs=True)
    bm.to_mesh(sphere.data)
    bm.free()
    scene.grlens.auto_update = False  # (the tests request every build themselves: _lens)
    _lens(scene, False)
    return scene, sphere


def _lens(scene, in_background=True, preview=True):
    """A rebuild as the handlers run it (their re-entrancy flag set: the depsgraph's evaluation does
    not start another)."""
    handlers._busy = True
    try:
        return rebuild.rebuild_scene(scene, preview=preview, background=in_background)
    finally:
        handlers._busy = False


def _positions(name="OrbitingSphere.GR1"):
    obj = bpy.data.objects[name]
    pts = np.empty(3 * len(obj.data.vertices), np.float32)
    obj.data.vertices.foreach_get("co", pts)
    return pts.reshape(-1, 3)


def _images():
    return {n: _positions(n) for n in ("OrbitingSphere.GR1", "OrbitingSphere.GR2")}


def _sync_images(scene, preview=True):
    """The images a synchronous build makes now (everything remembered forgotten first)."""
    rebuild.forget_all()
    report = _lens(scene, False, preview)
    assert report["objects"]["OrbitingSphere"] not in ("unchanged", "pending")
    return _images()


def _move(sphere, y):
    sphere.location.y = y


def _finish_in_timer():
    """What Blender's timer does: wait for the worker, then the timer function uploads."""
    job = background.current()
    assert job is not None
    job.thread.join(60)
    assert job.done
    assert background.tick() is None  # (done: the timer is not run again)
    assert not background.running()


def test_a_long_viewport_build_runs_in_the_worker_and_gives_the_synchronous_images(forced):
    scene, sphere = _dense_scene()
    old = _images()
    _move(sphere, 6.5)
    report = _lens(scene)
    assert report["status"] == "lensing in the background"
    assert report["objects"] == {"OrbitingSphere": "pending"}
    job = background.current()
    assert job is not None and job.thread is not None
    assert "lensing 'OrbitingSphere'" in background.status_line(scene) and "Esc cancels" in job.text()
    for n, p in _images().items():  # the former images stay while it runs
        np.testing.assert_array_equal(p, old[n])
    fractions = []
    job.progress.callback = lambda stage, f: fractions.append(f)
    job.thread.join(60)
    # the images' edges were found in the worker (rebuild.compute), not by the upload on the main thread
    assert all(img._edges is not None for item in job.plan.pending for img in item.images.values())
    _finish_in_timer()
    assert all(b >= a for a, b in zip(fractions, fractions[1:]))
    assert scene.grlens.status.startswith("1 object(s) lensed") and "viewport preview" in scene.grlens.status
    built = _images()
    assert any(len(p) != len(old[n]) or not np.array_equal(p, old[n]) for n, p in built.items())
    ref = _sync_images(scene)
    for n in ref:  # identical to the synchronous build
        np.testing.assert_array_equal(built[n], ref[n])


def test_the_handlers_send_long_viewport_updates_to_the_worker_and_short_ones_not(forced, monkeypatch):
    scene, sphere = _dense_scene()
    monkeypatch.setattr(handlers, "wants_preview", lambda *a, **k: True)  # (as in the interface)
    _move(sphere, 6.5)
    report = handlers._run(scene, bpy.context.evaluated_depsgraph_get())
    assert report["status"] == "lensing in the background" and background.running()
    _finish_in_timer()
    # predicted under the budget: built at once, as before
    monkeypatch.setattr(background, "BUDGET_SECONDS", 1e9)
    _move(sphere, 6.0)
    report = handlers._run(scene, bpy.context.evaluated_depsgraph_get())
    assert report["status"].startswith("1 object(s) lensed") and not background.running()
    # switched off by the user: at once too
    monkeypatch.setattr(background, "BUDGET_SECONDS", 0.0)
    scene.grlens.build_in_background = False
    _move(sphere, 6.5)
    assert not background.allowed(scene)
    report = handlers._run(scene, bpy.context.evaluated_depsgraph_get())
    assert report["status"].startswith("1 object(s) lensed") and not background.running()


def test_background_mode_and_renders_never_build_in_the_background(monkeypatch):
    scene, sphere = _dense_scene(48, 24)
    monkeypatch.setattr(background, "BUDGET_SECONDS", 0.0)
    assert bpy.app.background and not background.allowed(scene)  # (farms, scripts: FORCE is off)
    scene.grlens.auto_update = True
    old = _images()
    _move(sphere, 6.5)
    scene.frame_set(5)  # a scripted frame change builds at once
    assert not background.running()
    assert any(len(p) != len(old[n]) or not np.array_equal(p, old[n]) for n, p in _images().items())
    monkeypatch.setattr(background, "FORCE", True)
    assert background.allowed(scene)
    monkeypatch.setattr(handlers, "_rendering", True)
    assert not background.allowed(scene)


def test_cancel_keeps_the_former_images_and_the_same_build_waits_for_a_change(forced):
    scene, sphere = _dense_scene()
    old = _images()
    status = scene.grlens.status
    _move(sphere, 6.5)
    _lens(scene)
    job = background.current()
    assert background.cancel(reason="Esc")
    assert not background.running() and not job.thread.is_alive()
    assert background.tick() is None
    for n, p in _images().items():
        np.testing.assert_array_equal(p, old[n])
    assert scene.grlens.report_lines.startswith("rebuild cancelled (Esc)")
    assert scene.grlens.status == status
    # the same request again (an update that changes nothing): not started again
    report = _lens(scene)
    assert report["status"].startswith("cancelled") and not background.running()
    # a change: built again
    _move(sphere, 6.6)
    report = _lens(scene)
    assert report["status"] == "lensing in the background"
    _finish_in_timer()
    assert not scene.grlens.report_lines.startswith("rebuild cancelled")
    ref = _sync_images(scene)
    for n, p in _images().items():
        np.testing.assert_array_equal(p, ref[n])


def test_an_explicit_rebuild_builds_the_cancelled_build():
    scene, sphere = _dense_scene(48, 24)
    _move(sphere, 6.5)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(background, "FORCE", True)
        mp.setattr(background, "BUDGET_SECONDS", 0.0)
        _lens(scene)
        background.cancel(reason="Esc")
        assert bpy.ops.grlens.rebuild() == {"FINISHED"}  # (a script: at once, whatever was cancelled)
        assert not background.running()
        assert bpy.ops.grlens.rebuild("INVOKE_DEFAULT") == {"FINISHED"}  # (the button: may go beside)
        if background.running():
            _finish_in_timer()
    background.stop()
    assert scene.grlens.status.startswith("1 object(s) lensed")


def test_a_newer_request_supersedes_the_running_build(forced):
    scene, sphere = _dense_scene()
    _move(sphere, 6.5)
    _lens(scene)
    first = background.current()
    # the very same request leaves it running
    again = _lens(scene)
    assert again["status"] == "lensing in the background" and background.current() is first
    _move(sphere, 7.0)
    _lens(scene)
    second = background.current()
    assert second is not first and first.progress.cancelled
    first.thread.join(60)
    assert first.done and (first.cancelled or first.progress.fraction == 1.0)
    assert background.tick() in (None, background.POLL_SECONDS)  # (the first one is never uploaded)
    _finish_in_timer()
    built = _images()
    ref = _sync_images(scene)  # the latest request's images
    for n in ref:
        np.testing.assert_array_equal(built[n], ref[n])


def test_a_synchronous_build_supersedes_the_running_one(forced):
    scene, sphere = _dense_scene()
    _move(sphere, 6.5)
    _lens(scene)
    job = background.current()
    _move(sphere, 7.0)
    report = _lens(scene, False)  # (e.g. a script's rebuild)
    assert report["status"].startswith("1 object(s) lensed")
    assert not background.running() and not job.thread.is_alive() and job.progress.cancelled
    assert background.tick() is None
    built = _images()
    ref = _sync_images(scene)
    for n in ref:
        np.testing.assert_array_equal(built[n], ref[n])


def _render_counts(scene, tmp_path):
    """Render the current frame (Workbench, tiny) and return what the image meshes held when the
    render drew them, and whether a background build was running then."""
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.render.resolution_x, scene.render.resolution_y = 32, 18
    scene.render.filepath = str(tmp_path / "r")
    seen = {}

    def record(sc, *_):
        seen["positions"] = _images()
        seen["running"] = background.running()
    bpy.app.handlers.render_post.append(record)
    try:
        bpy.ops.render.render(write_still=False)
    finally:
        bpy.app.handlers.render_post.remove(record)
    return seen


def test_a_render_builds_its_own_images_synchronously(forced, tmp_path):
    scene, sphere = _dense_scene(48, 24)
    scene.grlens.auto_update = True
    _move(sphere, 6.5)
    _lens(scene)
    job = background.current()
    seen = _render_counts(scene, tmp_path)
    assert not seen["running"] and job.progress.cancelled  # auto update on: cancelled, the render builds
    assert not job.thread.is_alive()
    # the render's images are the render tolerance's, built for this frame
    ref = _sync_images(scene, preview=False)
    for n in ref:
        np.testing.assert_array_equal(seen["positions"][n], ref[n])


def test_a_render_waits_for_a_build_when_auto_update_is_off(forced, tmp_path):
    scene, sphere = _dense_scene(48, 24)
    scene.grlens.auto_update = False
    _move(sphere, 6.5)
    _lens(scene)
    assert background.running()
    seen = _render_counts(scene, tmp_path)
    assert not seen["running"]
    built = seen["positions"]
    ref = _sync_images(scene)  # the build that ran, finished before the render drew
    for n in ref:
        np.testing.assert_array_equal(built[n], ref[n])


def test_unregister_during_a_build_stops_its_worker(forced):
    scene, sphere = _dense_scene()
    _move(sphere, 6.5)
    _lens(scene)
    job = background.current()
    grlens_addon.unregister()
    try:
        assert not job.thread.is_alive() and not background.running()
        assert not bpy.app.timers.is_registered(background.tick)
        assert not [o for o in bpy.data.objects if o.name.startswith("OrbitingSphere.GR")]
    finally:
        grlens_addon.register()


def test_an_object_removed_during_a_build_is_left_out(forced):
    scene, sphere = _dense_scene()
    _move(sphere, 6.5)
    _lens(scene)
    job = background.current()
    bpy.data.objects.remove(sphere, do_unlink=True)
    job.thread.join(60)
    background.tick()
    assert not background.running()
    assert "OrbitingSphere" not in job.plan.report["objects"]


def test_loading_a_file_cancels_the_build(forced):
    scene, sphere = _dense_scene()
    _move(sphere, 6.5)
    _lens(scene)
    job = background.current()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    assert not background.running() and not job.thread.is_alive()
    assert background.tick() is None


def test_the_prediction_learns_seconds_per_triangle(forced, monkeypatch):
    monkeypatch.setitem(background._rate, "seconds_per_triangle", None)
    monkeypatch.setattr(background, "MIN_TRIANGLES", 1000)
    scene, sphere = _dense_scene()  # (a synchronous build, measured)
    rate = background.seconds_per_triangle()
    assert rate != background.DEFAULT_SECONDS_PER_TRIANGLE and 1e-9 < rate < 1e-3
    _move(sphere, 6.5)
    handlers._busy = True
    try:
        plan = rebuild.plan_rebuild(scene, preview=True)
    finally:
        handlers._busy = False
    n = sum(it.triangles for it in plan.pending)
    assert n == 96 * 48 * 2 - 2 * 96  # (the sphere's triangles)
    assert background.predicted_seconds(plan) == pytest.approx(rate * n)


def test_the_progress_operator_cancels_on_esc_and_passes_other_events_on(forced):
    """The modal operator's event handling (Blender cannot invoke operators headless: its methods are
    called with stand-ins for the operator, context and events)."""
    from types import SimpleNamespace

    from grlens_addon.blender.operators import GRLENS_OT_build_progress as Op

    scene, sphere = _dense_scene()
    old = _images()
    _move(sphere, 6.5)
    _lens(scene)
    ended, reports = [], []
    op = SimpleNamespace(_end=lambda ctx: ended.append(1), report=lambda kind, text: reports.append(text))
    ctx = SimpleNamespace(window_manager=bpy.context.window_manager)
    for kind, value in (("TIMER", "NOTHING"), ("MOUSEMOVE", "NOTHING"), ("ESC", "RELEASE"), ("A", "PRESS")):
        assert Op.modal(op, ctx, SimpleNamespace(type=kind, value=value)) == {"PASS_THROUGH"}
        assert background.running() and not ended
    assert Op.modal(op, ctx, SimpleNamespace(type="ESC", value="PRESS")) == {"CANCELLED"}
    assert not background.running() and ended and "cancelled" in reports[0]
    assert scene.grlens.report_lines.startswith("rebuild cancelled (Esc)")
    for n, p in _images().items():
        np.testing.assert_array_equal(p, old[n])
    # the build finished (or gone): the operator ends
    assert Op.modal(op, ctx, SimpleNamespace(type="TIMER", value="NOTHING")) == {"FINISHED"}
    background._start_watch()  # (headless: no window can run it; nothing breaks)
    assert bpy.ops.grlens.build_progress() == {"CANCELLED"}  # (from a script: nothing to watch)


def test_several_objects_progress_over_all_of_them(forced):
    scene, sphere = _dense_scene(64, 32)
    other = sphere.copy()
    other.data = sphere.data.copy()
    other.name = "Second"
    scene.collection.objects.link(other)
    other.location = (0.0, -6.0, 0.04)
    _move(sphere, 6.5)
    _lens(scene)
    job = background.current()
    assert [it.name for it in job.items] == ["OrbitingSphere", "Second"]
    seen = []
    job.progress.callback = lambda stage, f: seen.append((job.index, f))
    assert "(1 of 2)" in job.text() or "(2 of 2)" in job.text()
    _finish_in_timer()
    fractions = [f for _, f in seen]
    assert all(b >= a for a, b in zip(fractions, fractions[1:])) and fractions[-1] == 1.0
    if seen and seen[0][0] == 0:  # (the callback was set before the first object was done)
        assert {i for i, _ in seen} == {0, 1}
        assert max(f for i, f in seen if i == 0) <= min(f for i, f in seen if i == 1) + 1e-12
    assert scene.grlens.status.startswith("2 object(s) lensed")
    assert {"Second.GR1", "OrbitingSphere.GR1"} <= set(bpy.data.objects.keys())


def test_undo_cancels_the_build_before_the_data_changes(forced):
    scene, sphere = _dense_scene(64, 32)
    _move(sphere, 6.5)
    _lens(scene)
    job = background.current()
    assert handlers.on_undo_pre in bpy.app.handlers.undo_pre and handlers.on_undo_pre in bpy.app.handlers.redo_pre
    handlers.on_undo_pre()  # (what Blender calls before it steps back)
    assert not background.running() and not job.thread.is_alive() and job.progress.cancelled
    assert background.tick() is None
    # nothing is remembered of it: the same build starts again on the next request
    assert _lens(scene)["status"] == "lensing in the background"
    _finish_in_timer()
