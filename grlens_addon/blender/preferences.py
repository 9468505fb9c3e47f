"""Add-on preferences (Edit > Preferences > Add-ons > grlens): the folder of the tables' disk cache.

The folder where every lookup table built is kept and read back by later processes (lutcache.py):
the preference ``lut_cache_dir`` when it is set, else the environment variable ``GRLENS_LUT_CACHE``
(render farms that set it per job keep working); neither: no disk cache.
"""
import os
import threading

import bpy

CACHE_ENV = "GRLENS_LUT_CACHE"
"""Environment variable naming the disk cache's folder, used when the preference is empty."""


def _addon_name() -> str:
    """The add-on's module name, the key of its preferences: ``bl_ext.<repository>.grlens`` when
    installed as an extension (the package above ``grlens_addon``), ``grlens_addon`` when that
    package is enabled by itself (tests)."""
    pkg = __package__ or ""
    tail = ".grlens_addon.blender"
    return pkg[: -len(tail)] if pkg.endswith(tail) else pkg.split(".")[0]


ADDON = _addon_name()


class GRLENS_AddonPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON

    lut_cache_dir: bpy.props.StringProperty(
        name="Table Cache Folder", subtype="DIR_PATH", default="",
        description="Folder (local, or shared by a render farm's machines) where every lookup table built is "
                    "kept and read back by later processes instead of being built again (about 7 MB each). "
                    "Empty: the GRLENS_LUT_CACHE environment variable, if set; otherwise nothing is written")

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "lut_cache_dir")
        env = os.environ.get(CACHE_ENV, "")
        if self.lut_cache_dir:
            note = f"Used instead of {CACHE_ENV}" + (f" ({env})" if env else "")
        elif env:
            note = f"Empty: {CACHE_ENV} is used ({env})"
        else:
            note = f"Empty and {CACHE_ENV} unset: tables are kept in memory only"
        layout.label(text=note, icon="INFO")


def addon_preferences():
    """The add-on's preferences, or None (the add-on was registered without being enabled as an
    add-on, e.g. by a script that calls register(), or Blender is starting)."""
    try:
        addon = bpy.context.preferences.addons.get(ADDON)
    except AttributeError:
        return None
    return getattr(addon, "preferences", None) if addon is not None else None


_last_folder = {"pref": ""}  # the preference as last read on the main thread (see lut_cache_folder)


def lut_cache_folder() -> str:
    """The disk cache's folder (absolute; ``//`` relative to the open .blend): the preference if set,
    else ``GRLENS_LUT_CACHE``; "" for none. The preference is read on the main thread only (Blender's
    data is not thread-safe); another thread gets the value last read there."""
    if threading.current_thread() is threading.main_thread():
        prefs = addon_preferences()
        folder = getattr(prefs, "lut_cache_dir", "") if prefs is not None else ""
        _last_folder["pref"] = bpy.path.abspath(folder) if folder else ""
    return _last_folder["pref"] or os.environ.get(CACHE_ENV, "")


CLASSES = (GRLENS_AddonPreferences,)
