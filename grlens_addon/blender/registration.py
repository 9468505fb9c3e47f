"""register()/unregister(): idempotent (a second call does nothing), errors are raised, not printed."""
import bpy

from . import handlers, operators, panels, properties

_CLASSES = properties.CLASSES + operators.CLASSES + panels.CLASSES
_registered = False


def register():
    global _registered
    if _registered:
        return
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    properties.attach()
    handlers.attach()
    _registered = True


def unregister():
    global _registered
    if not _registered:
        return
    handlers.detach()
    from . import world

    world.restore_all()  # the user's worlds come back when the add-on is disabled
    properties.detach()
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
    _registered = False
