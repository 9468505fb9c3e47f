"""register()/unregister(): idempotent (a second call does nothing), errors are raised, not printed.

Disabling the add-on leaves an ordinary scene: grlens' image objects are removed, the lensed sources
render again and the worlds are restored. Enabling it again rebuilds the images of every scene with
marked objects (at once where the data can be reached, and on the next frame change in any case);
the marks and settings are kept in the file meanwhile.
"""
import bpy

from . import geodesic_camera, handlers, operators, panels, preferences, properties

_CLASSES = properties.CLASSES + preferences.CLASSES + operators.CLASSES + geodesic_camera.CLASSES + panels.CLASSES
_registered = False


def register():
    global _registered
    if _registered:
        return
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    properties.attach()
    handlers.attach()
    bpy.types.VIEW3D_MT_add.append(operators.menu_add)
    _registered = True
    if not bpy.app.timers.is_registered(_rebuild_after_enable):
        bpy.app.timers.register(_rebuild_after_enable, first_interval=0.0)


def unregister():
    global _registered
    if not _registered:
        return
    from . import background

    background.stop()  # (a build beside the interface: cancelled, its worker waited for)
    from ..core import frame

    frame.stop_threads()  # (the core's worker thread for dense meshes, idle after background.stop)
    handlers.detach()
    bpy.types.VIEW3D_MT_add.remove(operators.menu_add)
    if bpy.app.timers.is_registered(_rebuild_after_enable):
        bpy.app.timers.unregister(_rebuild_after_enable)
    from . import rebuild, world

    world.restore_all()  # the user's worlds come back when the add-on is disabled
    if isinstance(bpy.data, bpy.types.BlendData):  # (not while Blender starts or quits)
        rebuild.remove_all_images()  # no frozen images; the sources render again
    rebuild.forget_all()  # (nothing of the last builds kept: inputs, topologies, the gather's arrays)
    properties.detach()
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
    _registered = False


def _rebuild_after_enable():
    """Timer run once after register(): rebuild the current scene if it has marked objects (the images
    were removed when the add-on was disabled). Returns None (not run again)."""
    from . import handlers

    scene = getattr(bpy.context, "scene", None)
    if scene is not None and hasattr(scene, "grlens") and scene.grlens.auto_update \
            and any(o.grlens.enabled for o in scene.objects):
        handlers.request_rebuild(scene)  # (other scenes: when they are shown or rendered)
    return None
