"""grlens Blender extension entry point (the manifest lives at the repository root)."""
from .grlens_addon import register, unregister  # noqa: F401
