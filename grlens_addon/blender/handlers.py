"""Handlers: rebuild on frame changes (viewport, F12, animation renders, background mode) and after
interactive edits of lensed objects, the camera or the hole. Updates of the interactive viewport are
built to ``scene.grlens.tess_max_error_viewport`` (wants_preview); renders to ``tess_max_error``.

Thin and @persistent (they survive file loads); a re-entrancy flag (reset in finally) keeps our own
mesh updates from triggering another rebuild. Never calls bpy.ops.
"""
import bpy
from bpy.app.handlers import persistent

_busy = False
_printed: list = []  # the report lines printed last (see _run)


def wants_preview(depsgraph=None, background=None) -> bool:
    """Whether an automatic rebuild is for the interactive viewport (built to the viewport's
    tolerance): not in background mode (scripts, render farms) and not for a render's depsgraph
    (F12 and animation renders fire the frame handlers with it)."""
    background = bpy.app.background if background is None else background
    return not background and (depsgraph is None or depsgraph.mode != "RENDER")


def _run(scene, depsgraph=None):
    global _busy
    if _busy or scene is None or not hasattr(scene, "grlens"):
        return None
    _busy = True
    try:
        from .rebuild import rebuild_scene

        report = rebuild_scene(scene, depsgraph, preview=wants_preview(depsgraph))
        if report["status"].startswith("grlens:") and bpy.app.background:
            print(report["status"])
        global _printed
        if report["warnings"] != _printed:  # the same lines frame after frame are printed once
            for w in report["warnings"]:
                print(f"grlens: {w}")
            _printed = list(report["warnings"])
        return report
    finally:
        _busy = False


def request_rebuild(scene):
    """Called by property updates: rebuild now if auto update is on."""
    if scene is not None and scene.grlens.auto_update:
        _run(scene)


@persistent
def on_frame_change(scene, depsgraph=None):
    if scene.grlens.auto_update:
        _run(scene, depsgraph)


def _relevant(scene, update):
    """Whether a depsgraph update can change an image: a marked object (an instancer is updated with
    what it instances), the camera, hole or light, a mesh."""
    idb = update.id
    if isinstance(idb, bpy.types.Object):
        if idb.grlens.order in (1, 2):
            return False
        g = scene.grlens
        return idb.grlens.enabled or idb in (scene.camera, g.observer, g.black_hole, g.light)
    return isinstance(idb, bpy.types.Mesh) and not idb.get("grlens_topology")


@persistent
def on_depsgraph_update(scene, depsgraph):
    if _busy or not scene.grlens.auto_update or depsgraph.mode == "RENDER":
        return
    if any(_relevant(scene, u) for u in depsgraph.updates):
        _run(scene, depsgraph)


@persistent
def on_load_pre(*_args):
    from .rebuild import forget_all

    forget_all()


HANDLERS = ((bpy.app.handlers.frame_change_post, on_frame_change),
            (bpy.app.handlers.depsgraph_update_post, on_depsgraph_update),
            (bpy.app.handlers.load_pre, on_load_pre))


def attach():
    for lst, fn in HANDLERS:
        if fn not in lst:
            lst.append(fn)


def detach():
    for lst, fn in HANDLERS:
        while fn in lst:
            lst.remove(fn)
