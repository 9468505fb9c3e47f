"""Handlers: rebuild on frame changes (viewport, F12, animation renders, background mode) and after
interactive edits of lensed objects, the camera or the hole. Updates of the interactive viewport are
built to ``scene.grlens.tess_max_error_viewport`` (wants_preview); renders to ``tess_max_error``.
The lensed world (world.py) follows the camera on every frame change and edit even when auto update
is off (it costs a few milliseconds); files are saved with the user's own world (save_pre restores
it, save_post lenses it again) and lensed again on load.

Automatic updates of the interactive viewport whose build is predicted to be long run beside the
interface (background.py: progress, Esc, the latest request wins); renders and background mode
always build at once.

Thin and @persistent (they survive file loads); a re-entrancy flag (reset in finally) keeps our own
mesh updates from triggering another rebuild. Never calls bpy.ops.
"""
import bpy
from bpy.app.handlers import persistent

_busy = False
_rendering = False  # between render_pre and render_complete / render_cancel
_printed: list = []  # the report lines printed last by an interactive session (see _print)
_printed_frame: dict = {"key": None, "lines": set()}  # background: the lines printed for this frame


def wants_preview(depsgraph=None, background=None) -> bool:
    """Whether an automatic rebuild is for the interactive viewport (built to the viewport's
    tolerance): not in background mode (scripts, render farms) and not for a render's depsgraph
    (F12 and animation renders fire the frame handlers with it)."""
    background = bpy.app.background if background is None else background
    return not background and (depsgraph is None or depsgraph.mode != "RENDER")


def rendering() -> bool:
    """Whether a render is running (between render_pre and render_complete / render_cancel)."""
    return _rendering


def quiet(scene, status: str) -> bool:
    """Whether a failed rebuild's ``status`` is left unprinted: "no object is marked" in a scene that
    does not use grlens (no black hole set), so that renders of other scenes print nothing."""
    return "no object is marked" in status and scene.grlens.black_hole is None


def _print(scene, report) -> None:
    """Print a rebuild's error status and report lines. In background mode (renders, farms) each
    distinct line once per frame (a frame may be rebuilt several times: a render's frame handlers
    and the depsgraph's), per-object lines on every frame; interactively, the lines when they
    change."""
    lines = [f"grlens: {w}" for w in report["warnings"]]
    status = report["status"]
    if status.startswith("grlens:") and not quiet(scene, status):
        lines.insert(0, status.rsplit(" [", 1)[0])  # (without the time: one line per frame)
    global _printed
    if bpy.app.background:
        key = (scene.name, scene.frame_current, scene.frame_subframe)
        if _printed_frame["key"] != key:
            _printed_frame["key"], _printed_frame["lines"] = key, set()
        for line in lines:
            if line not in _printed_frame["lines"]:
                print(line)
                _printed_frame["lines"].add(line)
    elif lines != _printed:
        for line in lines:
            print(line)
        _printed = lines


def _run(scene, depsgraph=None, background=None):
    """Rebuild ``scene`` (auto update): an interactive viewport update may go to the background
    (background.allowed; ``background`` False: never)."""
    global _busy
    if _busy or scene is None or not hasattr(scene, "grlens"):
        return None
    _busy = True
    try:
        from . import background as bg
        from .rebuild import rebuild_scene

        preview = wants_preview(depsgraph)
        in_bg = preview and background is not False and bg.allowed(scene)
        report = rebuild_scene(scene, depsgraph, preview=preview, background=in_bg)
        if report["status"] != "lensing in the background" and not report["status"].startswith("cancelled"):
            _print(scene, report)
        return report
    finally:
        _busy = False


def finish_plan(plan):
    """Upload a rebuild whose core ran in the background (rebuild.finish) and print its lines, with
    the re-entrancy flag set like any rebuild here."""
    global _busy
    from .rebuild import finish

    was, _busy = _busy, True
    try:
        report = finish(plan)
        scene = plan.scene()
        if scene is not None:
            _print(scene, report)
        return report
    finally:
        _busy = was


def update_world(scene, depsgraph=None):
    """Bring the lensed world of ``scene`` up to date (world.refresh); errors are printed in
    background mode, like the rebuild's."""
    global _busy
    if _busy or scene is None or not hasattr(scene, "grlens"):
        return None
    _busy = True
    try:
        from . import world

        line, error = world.refresh(scene, depsgraph)
        if error:
            _print(scene, {"status": f"grlens: {error}", "warnings": []})
        return line, error
    finally:
        _busy = False


def request_rebuild(scene, background=None):
    """Called by property updates: rebuild now if auto update is on (the world in any case); a long
    build may run beside the interface (``background`` False: never)."""
    if scene is None:
        return
    if scene.grlens.auto_update:
        _run(scene, background=background)
    else:
        update_world(scene)


@persistent
def on_frame_change(scene, depsgraph=None):
    try:
        if scene is not None and hasattr(scene, "grlens"):
            from . import hole

            hole.sync(scene)  # (an animated r_s: the horizon and photon sphere shown follow it)
        if scene.grlens.auto_update:
            _run(scene, depsgraph)  # rebuild_scene updates the world too
        else:
            update_world(scene, depsgraph)
    finally:
        if depsgraph is not None and depsgraph.mode == "RENDER":
            from .rebuild import hide_sources

            hide_sources(scene)  # (shown to the render's depsgraph by on_render_pre: out of the picture again)


@persistent
def on_render_pre(scene, *_args):
    """Before a render frame's depsgraph is built: the lensed sources are shown to it, so that their
    images are built from their render settings (rebuild.expose_sources); the frame handler hides
    them again after the rebuild, and the render re-evaluates without them."""
    global _rendering
    from . import background

    if background.running():  # renders wait for a build beside the interface, or build their own
        if scene is not None and hasattr(scene, "grlens") and scene.grlens.auto_update:
            background.cancel(quiet=True)
        else:
            background.wait()
    _rendering = True
    if scene is not None and hasattr(scene, "grlens"):
        from .rebuild import expose_sources

        expose_sources(scene)


@persistent
def on_render_end(scene, *_args):
    """A render finished or was cancelled: every lensed source hidden from renders again."""
    global _rendering
    _rendering = False
    from .rebuild import hide_sources

    hide_sources()


def _original(idb):
    """The original data-block of an evaluated copy (depsgraph updates carry evaluated copies)."""
    return getattr(idb, "original", None) or idb


def _relevant(scene, update):
    """Whether a depsgraph update can change an image: a marked object (an instancer is updated with
    what it instances), the camera, hole or light, a mesh."""
    idb = update.id
    if isinstance(idb, bpy.types.Object):
        if idb.grlens.order in (1, 2):
            return False
        g = scene.grlens
        # (updates carry the evaluated copies: compare their originals)
        return idb.grlens.enabled or _original(idb) in (scene.camera, g.observer, g.black_hole, g.light)
    return isinstance(idb, bpy.types.Mesh) and not idb.get("grlens_topology")


def _world_relevant(scene, update):
    """Whether a depsgraph update can change the lensed world: the camera or hole moved, the
    world's node tree was edited (new nodes are hooked; our own value writes find nothing to do), or
    the scene itself (its render engine decides how the table is read)."""
    idb = update.id
    g = scene.grlens
    orig = _original(idb)
    if isinstance(idb, bpy.types.Object):
        from .world import lensing_camera

        return orig in (scene.camera, lensing_camera(scene), g.observer, g.black_hole)
    if isinstance(idb, bpy.types.Scene):
        return orig == scene
    w = scene.world
    if w is None:
        return False
    return (isinstance(idb, bpy.types.World) and orig == w) or (isinstance(idb, bpy.types.NodeTree)
                                                                 and orig == w.node_tree)


@persistent
def on_depsgraph_update(scene, depsgraph):
    if _busy or _rendering or depsgraph.mode == "RENDER":
        return
    ups = list(depsgraph.updates)
    hole_obj = scene.grlens.black_hole
    if hole_obj is not None and any(_original(u.id) == hole_obj for u in ups):
        from . import hole

        hole.sync(scene)  # (the hole scaled: its horizon is still shown at r_s)
    if scene.grlens.auto_update and any(_relevant(scene, u) for u in ups):
        _run(scene, depsgraph)
    elif scene.grlens.lens_world and any(_world_relevant(scene, u) for u in ups):
        update_world(scene, depsgraph)


@persistent
def on_load_pre(*_args):
    from . import background, world
    from .rebuild import forget_all

    background.forget()  # (a build beside the interface is for the file being closed)
    forget_all()
    world.forget_all()


@persistent
def on_load_post(*_args):
    """Lens the worlds of the loaded file (their tables are written again)."""
    for scene in bpy.data.scenes:
        if scene.grlens.lens_world and scene.grlens.black_hole is not None:
            update_world(scene)


@persistent
def on_undo_pre(*_args):
    """Undo or redo replaces data-blocks: a build running beside the interface is cancelled first (the
    images and the scene come back together; the next change rebuilds)."""
    from . import background

    background.forget()


@persistent
def on_undo_post(*_args):
    """Undo may bring back a table image whose pixels are not the ones written: write them again."""
    from . import world

    world.forget_all()
    on_load_post()


@persistent
def on_save_pre(*_args):
    """Save the user's own worlds: grlens' nodes, node groups and tables are removed first."""
    from . import world

    world.restore_all()


@persistent
def on_save_post(*_args):
    on_load_post()


HANDLERS = ((bpy.app.handlers.frame_change_post, on_frame_change),
            (bpy.app.handlers.depsgraph_update_post, on_depsgraph_update),
            (bpy.app.handlers.load_pre, on_load_pre),
            (bpy.app.handlers.load_post, on_load_post),
            (bpy.app.handlers.save_pre, on_save_pre),
            (bpy.app.handlers.save_post, on_save_post),
            (bpy.app.handlers.undo_pre, on_undo_pre),
            (bpy.app.handlers.redo_pre, on_undo_pre),
            (bpy.app.handlers.undo_post, on_undo_post),
            (bpy.app.handlers.redo_post, on_undo_post),
            (bpy.app.handlers.render_pre, on_render_pre),
            (bpy.app.handlers.render_complete, on_render_end),
            (bpy.app.handlers.render_cancel, on_render_end))


def attach():
    for lst, fn in HANDLERS:
        if fn not in lst:
            lst.append(fn)


def detach():
    for lst, fn in HANDLERS:
        while fn in lst:
            lst.remove(fn)
