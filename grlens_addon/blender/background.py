"""Long viewport rebuilds beside the interface: the numeric core in a worker thread, with progress,
Esc to cancel, the latest request winning.

A rebuild has three steps (rebuild.RebuildPlan): gathering the marked objects (bpy, main thread),
the numeric core (numpy only: core.pipeline), and the upload (bpy, main thread). An automatic
update of the interactive viewport whose core is predicted to take longer than BUDGET_SECONDS runs
its core in a worker thread (numpy releases the GIL in its large array operations, and Python lets
the main thread run every few milliseconds, so Blender keeps drawing and answering); a timer
(bpy.app.timers, every POLL_SECONDS) shows the progress and uploads the images on the main thread
when the worker is done. Until then the former images stay.

Rules:

* Prediction: seconds per source triangle of the builds measured on this machine (the last
  builds of at least MIN_TRIANGLES, averaged: :func:`measured`; DEFAULT_SECONDS_PER_TRIANGLE before
  any) times the source triangles to build.
* Only automatic viewport updates and the panel's Lens / Rebuild buttons may go to the background;
  renders, background mode (``blender -b``, farms, scripts), animation playback and scripts calling
  the operators run the build at once, as before. ``scene.grlens.build_in_background`` off: always at
  once.
* A newer request supersedes the running build (it is cancelled; the new worker starts when the old
  one has stopped: one build at a time); a request for the very same build leaves it running.
* Esc (the modal operator ``grlens.build_progress``, started for the build) cancels it: the former
  images stay, the report says so, and the same build is not started again until something changes
  (or Rebuild is pressed).
* Renders: with Auto Update on, a render builds its own images for every frame, so a running build
  is cancelled at render_pre; with Auto Update off, the render waits for it (:func:`wait`). Its
  result is never uploaded during a render.
* Undo, redo and loading a file cancel the running build before the data changes under it (its
  objects are looked up again by name and pointer before anything is written in any case);
  unregister stops the worker and waits for it.

Tests run in background mode, where no timer runs: they set FORCE and call :func:`tick` themselves.
"""
from __future__ import annotations

import threading
import time

import bpy

from ..core import pipeline

BUDGET_SECONDS = 0.25
"""Responsiveness budget (seconds): a viewport rebuild whose core is predicted to take longer runs in
the background."""

POLL_SECONDS = 0.05
"""Interval of the timer that shows progress and uploads a finished build (seconds)."""

DEFAULT_SECONDS_PER_TRIANGLE = 2.0e-6
"""The prediction before any build was measured in this session (seconds per source triangle: a dense
closed mesh beside the hole at 1920x1080 on a 2-core machine, benchmarks/bench_dense.py)."""

MIN_TRIANGLES = 20_000
"""Builds of fewer source triangles are not measured (their time is mostly fixed costs)."""

FORCE = False
"""Tests: allow background builds in background mode (where Blender has no interface)."""

_rate = {"seconds_per_triangle": None}
_state = {"job": None, "cancelled": None, "watching": False, "shown": False, "last_thread": None}
_lock = threading.RLock()


class Job:
    """One rebuild's core running in a worker thread: its plan, its progress (pipeline.Progress: the
    fraction of the plan's source triangles built; cancel()), the object being built, and when it
    ended (done; cancelled or error)."""

    def __init__(self, plan, previous_thread=None):
        self.plan = plan
        self.progress = pipeline.Progress()
        self.items = plan.pending  # (the objects to build, in the order compute() builds them)
        self.total = max(sum(it.triangles for it in self.items), 1)
        self.name = self.items[0].name if self.items else ""
        self.index = 0
        self.done = False
        self.cancelled = False
        self.error = None
        self.started = time.perf_counter()
        self._previous = previous_thread
        self.thread = threading.Thread(target=self._run, name="grlens-build", daemon=True)

    def _hook(self, index, stage, fraction):
        pending = self.items
        before = sum(it.triangles for it in pending[:index])
        self.name, self.index = pending[index].name, index
        self.progress(stage, (before + fraction * pending[index].triangles) / self.total)

    def _run(self):
        from .rebuild import compute

        try:
            if self._previous is not None:
                self._previous.join()  # (the superseded build stops at its next stage)
            self.progress("start", 0.0)
            compute(self.plan, self._hook)
        except pipeline.Cancelled:
            self.cancelled = True
        except BaseException as exc:  # noqa: BLE001 (reported on the main thread)
            self.error = exc
        finally:
            self.done = True

    def text(self) -> str:
        """The status line while it runs, e.g. "grlens: lensing 'Scan' 40 % (Esc cancels)" (with several
        objects to build: "lensing 'Scan' (2 of 3) 70 %", the percentage over all of them)."""
        of = f" ({self.index + 1} of {len(self.items)})" if len(self.items) > 1 else ""
        return f"grlens: lensing '{self.name}'{of} {100 * self.progress.fraction:.0f} % (Esc cancels)"


def allowed(scene) -> bool:
    """Whether an automatic update of ``scene`` may go to the background: the interface runs (not
    background mode, unless FORCE), no render is running, no animation plays, and
    ``scene.grlens.build_in_background`` is on."""
    from . import handlers

    if (bpy.app.background and not FORCE) or handlers.rendering() or not scene.grlens.build_in_background:
        return False
    wm = getattr(bpy.context, "window_manager", None)
    for win in (wm.windows if wm is not None else ()):
        screen = win.screen
        if screen is not None and screen.is_animation_playing:
            return False
    return True


def seconds_per_triangle() -> float:
    rate = _rate["seconds_per_triangle"]
    return DEFAULT_SECONDS_PER_TRIANGLE if rate is None else rate


def predicted_seconds(plan) -> float:
    """The predicted time of the plan's core: seconds per source triangle (:func:`seconds_per_triangle`)
    times the source triangles to build."""
    return seconds_per_triangle() * sum(it.triangles for it in plan.pending)


def wants_background(plan) -> bool:
    return predicted_seconds(plan) > BUDGET_SECONDS


def measured(plan) -> None:
    """Learn from a finished build: its core's seconds per source triangle (builds of at least
    MIN_TRIANGLES; the mean of the former estimate and this one, so one odd build moves it halfway)."""
    n = sum(it.triangles for it in plan.items if it.outcome == "built")
    if n < MIN_TRIANGLES or plan.compute_seconds <= 0:
        return
    rate = plan.compute_seconds / n
    old = _rate["seconds_per_triangle"]
    _rate["seconds_per_triangle"] = rate if old is None else 0.5 * (old + rate)


def current():
    """The running Job, or None."""
    return _state["job"]


def running() -> bool:
    return _state["job"] is not None


def status_line(scene=None) -> str:
    """The running build's status line for the panel ("" when none runs, or it is another scene's)."""
    job = _state["job"]
    if job is None or (scene is not None and job.plan.scene_ptr != scene.as_pointer()):
        return ""
    return job.text()


def provisional_report(plan) -> dict:
    """The report of a rebuild that runs in the background: status "lensing in the background", the
    objects being built "pending", the others as the last build left them."""
    return {"status": "lensing in the background", "warnings": [], "stats": {}, "seconds": 0.0,
            "objects": {it.name: "pending" for it in plan.pending}}


def cancelled_report(plan) -> dict:
    out = provisional_report(plan)
    out["status"] = "cancelled (Esc): the same build waits for a change"
    out["objects"] = {it.name: "cancelled" for it in plan.pending}
    return out


def was_cancelled(plan) -> bool:
    """Whether ``plan`` is the very build cancelled last (Esc): it waits for a change."""
    last = _state["cancelled"]
    return last is not None and last.same_work(plan)


def start(plan) -> dict:
    """Run the core of ``plan`` in a worker thread (a running build is cancelled: the new one starts
    when it has stopped); the timer shows progress and finishes it. Returns the provisional report."""
    with _lock:
        old = _state["job"]
        previous = None
        if old is not None:
            old.progress.cancel()
            previous = old.thread
        elif _state["last_thread"] is not None and _state["last_thread"].is_alive():
            previous = _state["last_thread"]
        job = Job(plan, previous)
        _state["job"], _state["cancelled"], _state["last_thread"] = job, None, job.thread
        job.thread.start()
    if not bpy.app.timers.is_registered(tick):
        bpy.app.timers.register(tick, first_interval=POLL_SECONDS)
    if not bpy.app.background and not _state["watching"] and not bpy.app.timers.is_registered(_start_watch):
        bpy.app.timers.register(_start_watch, first_interval=0.0)
    return provisional_report(plan)  # (the timer shows the progress: nothing drawn from a handler)


def cancel(quiet: bool = False, reason: str = "") -> bool:
    """Cancel the running build (the worker stops at its next stage and is waited for) and keep the
    former images. ``quiet``: superseded by another request (nothing is reported); else (Esc, undo,
    loading) the report lines get "rebuild cancelled (<reason>)" and the same build is not started
    again until something changes. Returns whether a build was running."""
    with _lock:
        job = _state["job"]
        if job is None:
            return False
        job.progress.cancel()
        _state["job"] = None
        if not quiet:
            _state["cancelled"] = job.plan
    job.thread.join()
    _hide()
    if not quiet:
        scene = job.plan.scene()
        if scene is not None:
            line = (f"rebuild cancelled{f' ({reason})' if reason else ''}: the images shown are those of the last "
                    "finished build; the next change rebuilds")
            old = scene.grlens.report_lines
            scene.grlens.report_lines = line + ("\n" + old if old else "")
            _redraw()
    return True


def clear_cancelled() -> None:
    """An explicit Rebuild: the build cancelled last may start again."""
    _state["cancelled"] = None


def forget() -> None:
    """Undo, redo or a file being loaded: the running build is cancelled (its objects may be replaced)
    and nothing is remembered of cancelled builds."""
    cancel(quiet=True)
    _state["cancelled"] = None


def wait():
    """Finish the running build now: wait for the worker and upload its images (renders with Auto
    Update off; scripts). Returns its report, or None when none runs."""
    job = _state["job"]
    if job is None:
        return None
    job.thread.join()
    return _complete(job)


def tick():
    """The timer (bpy.app.timers; tests call it): progress shown while the build runs, its images
    uploaded when it is done. Returns the next interval, or None when no build runs."""
    job = _state["job"]
    if job is None:
        _hide()
        return None
    from . import handlers

    if handlers.rendering():
        return POLL_SECONDS  # (never written during a render)
    if not job.done:
        _show(job)
        return POLL_SECONDS
    _complete(job)
    return None


def _complete(job):
    """Upload a finished build on the main thread (rebuild.finish), print its lines like a handler's
    rebuild, end the progress."""
    from . import handlers
    from .rebuild import finish

    with _lock:
        if _state["job"] is not job:
            return None
        _state["job"] = None
    _hide()
    if job.cancelled:
        return None
    scene = job.plan.scene()
    if job.error is not None:
        if scene is not None:
            scene.grlens.status = f"grlens: the build failed: {type(job.error).__name__}: {job.error}"
        return None
    report = handlers.finish_plan(job.plan)
    _redraw()
    return report


def stop() -> None:
    """unregister(): cancel the running build, wait for its worker, remove the timers."""
    cancel(quiet=True)
    t = _state["last_thread"]
    if t is not None and t.is_alive():
        t.join()
    for fn in (tick, _start_watch):
        if bpy.app.timers.is_registered(fn):
            bpy.app.timers.unregister(fn)
    _state.update(cancelled=None, last_thread=None)
    _hide()


def _windows():
    wm = getattr(bpy.context, "window_manager", None)
    return list(wm.windows) if wm is not None else []


def _start_watch():
    """Timer: start the modal operator that shows progress and catches Esc (operators cannot be called
    from a handler) in a window with a 3D view, else the first window."""
    if not running() or _state["watching"]:
        return None
    wins = _windows()
    wins.sort(key=lambda w: not any(a.type == "VIEW_3D" for a in w.screen.areas) if w.screen else True)
    for win in wins:
        try:
            with bpy.context.temp_override(window=win):
                bpy.ops.grlens.build_progress("INVOKE_DEFAULT")
            break
        except (RuntimeError, TypeError, AttributeError):
            continue
    return None


def _show(job) -> None:
    """The progress in the interface: the window manager's progress, the status bar's text, the panel."""
    if bpy.app.background:
        return
    wm = bpy.context.window_manager
    try:
        if not _state["shown"]:
            wm.progress_begin(0.0, 100.0)
            _state["shown"] = True
        wm.progress_update(100.0 * job.progress.fraction)
        for win in _windows():
            if win.workspace is not None:
                with bpy.context.temp_override(window=win):
                    win.workspace.status_text_set(job.text())
    except (RuntimeError, AttributeError, TypeError):
        pass
    _redraw()


def _hide() -> None:
    shown, _state["shown"] = _state["shown"], False
    if not shown or bpy.app.background:
        return
    try:
        bpy.context.window_manager.progress_end()
        for win in _windows():
            if win.workspace is not None:
                with bpy.context.temp_override(window=win):
                    win.workspace.status_text_set(None)
    except (RuntimeError, AttributeError, TypeError):
        pass
    _redraw()


def _redraw() -> None:
    """The panel (3D views) and the status bar drawn again."""
    for win in _windows():
        if win.screen is None:
            continue
        for area in win.screen.areas:
            if area.type in ("VIEW_3D", "STATUSBAR"):
                area.tag_redraw()


def set_watching(on: bool) -> None:
    _state["watching"] = on
