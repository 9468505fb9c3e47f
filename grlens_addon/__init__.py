"""grlens Blender add-on: gravitationally lensed image meshes of marked objects.

``core/`` is plain numpy (tested without Blender); ``blender/`` is the thin bpy layer (properties,
operators, panel, handlers, mesh upload). Heavy modules are imported inside ``register()`` so that
importing this package never needs bpy.
"""


def register():
    from .blender import registration

    registration.register()


def unregister():
    from .blender import registration

    registration.unregister()
