"""grlens Blender extension entry point (the manifest lives at the repository root).

Blender imports this file as a package (``bl_ext.<repository>.grlens``). Tools that import it as a
plain module (pytest treats the repository root as a package and imports this file when the checkout's
folder name is not a Python identifier, e.g. ``grlens.git``) get a module without the add-on."""
if __package__:
    from .grlens_addon import register, unregister  # noqa: F401
