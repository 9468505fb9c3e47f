"""Lookup tables built on demand and cached by their parameters (r_obs, r_min, r_max, sizes).

Units: all radii in r_s. The cache is a process-level memo of deterministic results: the same
parameters always give the same table, so two render-farm processes get identical geometry.
"""
from collections import OrderedDict

_CACHE = OrderedDict()
_MAX = 4


def get_lut(r_obs, r_min, r_max, n_r, n_phi):
    """The LUT for these parameters (built once, then reused; the 4 most recent are kept)."""
    from lutgen import build_lut

    key = (float(r_obs), float(r_min), float(r_max), int(n_r), int(n_phi))
    lut = _CACHE.get(key)
    if lut is None:
        lut = build_lut(*key)
        _CACHE[key] = lut
        while len(_CACHE) > _MAX:
            _CACHE.popitem(last=False)
    else:
        _CACHE.move_to_end(key)
    return lut


def clear():
    _CACHE.clear()
