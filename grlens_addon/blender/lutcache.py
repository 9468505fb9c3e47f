"""Lookup tables: built on demand, cached by their parameters, optionally packed into the .blend.

Units: all radii in r_s. Tables are deterministic (the same parameters give the same table), so two
render-farm processes get identical geometry; packing a table (``bpy.ops.grlens.pack_lut()``) saves
the build time when the file is opened elsewhere. Packed tables live, exactly (float64), as hidden
custom-property arrays on the Text data-block "grlens LUTs" (fake user), one per parameter set.
"""
from collections import OrderedDict

import bpy
import numpy as np

STORE = "grlens LUTs"
_CACHE = OrderedDict()
_MAX = 4


def _key(r_obs, r_min, r_max, n_r, n_phi):
    """Cache key; r_obs rounded to 7 significant digits (see core.mapping.R_OBS_TOLERANCE), so a
    camera orbiting at a fixed distance (float32 jitter) keeps using one table."""
    return (float(f"{float(r_obs):.7g}"), float(r_min), float(r_max), int(n_r), int(n_phi))


def _prop_name(key):
    return "_lut " + " ".join(repr(v) for v in key)


def _from_store(key):
    from lutgen import LUT

    store = bpy.data.texts.get(STORE)
    if store is None:
        return None
    arr = store.get(_prop_name(key))
    if arr is None:
        return None
    data = np.frombuffer(memoryview(arr), dtype=np.float64)
    n_r, n_phi = key[3], key[4]
    if data.size != 2 * 4 * n_r * n_phi:
        return None  # damaged or foreign entry: rebuild instead
    return LUT(r_obs=key[0], r_min=key[1], r_max=key[2], data=data.reshape(2, 4, n_r, n_phi).copy())


def get_lut(r_obs, r_min, r_max, n_r, n_phi):
    """The LUT for these parameters: from the memory cache, else from the .blend, else built."""
    from lutgen import build_lut

    key = _key(r_obs, r_min, r_max, n_r, n_phi)
    lut = _CACHE.get(key)
    if lut is None:
        lut = _from_store(key) or build_lut(*key)
        _CACHE[key] = lut
        while len(_CACHE) > _MAX:
            _CACHE.popitem(last=False)
    else:
        _CACHE.move_to_end(key)
    return lut


def pack(lut) -> str:
    """Store ``lut`` in the .blend (exact). Returns the entry's name."""
    store = bpy.data.texts.get(STORE) or bpy.data.texts.new(STORE)
    store.use_fake_user = True
    key = _key(*(lut.parameters[k] for k in ("r_obs", "r_min", "r_max", "n_r", "n_phi")))
    name = _prop_name(key)
    store[name] = lut.data.ravel()
    return name


def unpack_all() -> int:
    """Remove every packed table from the .blend; returns how many there were."""
    store = bpy.data.texts.get(STORE)
    if store is None:
        return 0
    n = sum(1 for k in store.keys() if k.startswith("_lut "))
    bpy.data.texts.remove(store)
    return n


def clear():
    """Forget the memory cache (packed tables stay in the file)."""
    _CACHE.clear()
