"""Lookup tables: built on demand, cached by their parameters, optionally packed into the .blend.

Units: all radii in r_s. Three kinds, chosen by ``scene.grlens.lut_mode``:

* ``ONE_TABLE``: the one orbit table of :mod:`lutgen.rays` serves every camera and light radius from
  1.001 r_s (inside the photon sphere too) to 1e7 r_s: a moving camera costs no table build on any
  frame, the first pass as the second (each point's ray is solved from the table, so a frame costs
  more than with the family's tables: docs/tables.md). Observers closer than FAMILY_MIN get it in
  every mode.

* ``EVERY_DISTANCE`` (default): :class:`lutgen.LUTFamily` tables, which reach from ``lut_r_min`` to
  infinity and serve any camera (or light) radius by interpolating exact tables built at fixed radii
  (1 + exp(k/8) r_s), so a camera that moves needs no new table per frame; the exact tables are
  built the first time a radius near them is used (about a second each) and kept.
* ``FIXED_RANGE``: one :class:`lutgen.LUT` per camera radius over [lut_r_min, lut_r_max] with
  lut_n_r x lut_n_phi nodes, as grlens built before the family existed.

Tables are deterministic (the same parameters give the same table, whatever was built before), so
two render-farm processes get identical geometry; packing (``bpy.ops.grlens.pack_lut()``) only saves
the build time when the file is opened elsewhere. Packed tables live, exactly (float64), as hidden
custom-property arrays on the Text data-block "grlens LUTs" (fake user), one per table.

A disk cache, when the add-on preference "Table Cache Folder" or else the environment variable
``GRLENS_LUT_CACHE`` names a directory (preferences.lut_cache_folder): every table
built is also written there (``grlens-<sha1 of its name>.npz``, float64, exact; about 7 MB per
family table) and read back by later processes, so a farm machine or a shared directory builds each
table once, whatever the .blend holds. A file that cannot be read, is damaged, or holds another
table is ignored (the table is built and the file replaced). Unset (the default): nothing on disk.
Order of lookup: memory, the .blend, the disk cache, a build.
"""
import hashlib
import os
import tempfile
import zipfile
from collections import OrderedDict

import bpy
import numpy as np

from ..core.mapping import round_radius
from . import preferences

STORE = "grlens LUTs"
_CACHE = OrderedDict()
_MAX = 4
_FAMILIES: dict = {}
_WIDE = "_wide "
FAMILY_TABLES = 24
"""Exact tables a family keeps in memory (about 7 MB each): enough for a camera that sweeps its radius
by a factor of 20 (e.g. a fly-in from 60 to 4 r_s) to be scrubbed back and forth without rebuilding."""


FAMILY_MIN = 1.6
"""Observers (camera or light) closer than this (r_s) get the orbit table's rays in every mode: the
family's and fixed-range tables stop at the photon sphere (1.5 r_s), and the family interpolates only
from about 1.6 r_s (its exact tables at 1 + exp(k/8) r_s from 1.51 r_s, four around each radius)."""


CACHE_ENV = preferences.CACHE_ENV
"""Environment variable naming the directory of the disk cache (unset or empty: no disk cache), used
when the add-on preference "Table Cache Folder" is empty (preferences.lut_cache_folder)."""


def _disk_path(name):
    folder = preferences.lut_cache_folder()
    if not folder:
        return None
    return os.path.join(folder, "grlens-" + hashlib.sha1(name.encode()).hexdigest() + ".npz")


def _disk_load(name, shapes):
    """{array name: float64 array} of table ``name`` from the disk cache if it is there, whole and
    of the expected ``shapes`` ({array name: shape}); else None."""
    path = _disk_path(name)
    if path is None or not os.path.isfile(path):
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["name"]) != name:
                return None
            out = {k: np.array(z[k]) for k in shapes}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None
    if any(out[k].dtype != np.float64 or out[k].shape != tuple(shp) for k, shp in shapes.items()):
        return None
    return out


def _disk_save(name, arrays) -> None:
    """Write table ``name`` into the disk cache (atomically: concurrent processes may write the same
    table, with the same contents). A cache that cannot be written is skipped."""
    path = _disk_path(name)
    if path is None:
        return
    tmp = None
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".grlens-", suffix=".tmp", dir=os.path.dirname(path))
        with os.fdopen(fd, "wb") as f:
            np.savez(f, name=np.array(name), **arrays)
        os.replace(tmp, path)
        tmp = None
    except OSError:
        pass
    finally:
        if tmp is not None and os.path.exists(tmp):
            os.remove(tmp)


def _key(r_obs, r_min, r_max, n_r, n_phi):
    """Cache key; r_obs rounded to 7 significant digits (see core.mapping.R_OBS_TOLERANCE), so a
    camera orbiting at a fixed distance (float32 jitter) keeps using one table."""
    return (round_radius(r_obs), float(r_min), float(r_max), int(n_r), int(n_phi))


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
    """The fixed-range LUT for these parameters: from the memory cache, else from the .blend, else built."""
    from lutgen import LUT, build_lut

    key = _key(r_obs, r_min, r_max, n_r, n_phi)

    def make():
        lut = _from_store(key)
        if lut is not None:
            return lut
        name = _prop_name(key)
        got = _disk_load(name, {"data": (2, 4, key[3], key[4])})
        if got is not None:
            return LUT(r_obs=key[0], r_min=key[1], r_max=key[2], data=got["data"])
        lut = build_lut(*key)
        _disk_save(name, {"data": lut.data})
        return lut

    return _cached(key, make)


def _cached(key, make):
    lut = _CACHE.get(key)
    if lut is None:
        lut = make()
        _CACHE[key] = lut
        while len(_CACHE) > _MAX:
            _CACHE.popitem(last=False)
    else:
        _CACHE.move_to_end(key)
    return lut


def _wide_name(r_obs, r_min, rows, n_phi):
    return _WIDE + " ".join(repr(v) for v in (float(r_obs), float(r_min), *map(int, rows), int(n_phi)))


def _wide_builder(r_obs, r_min, rows, n_phi):
    """A family's exact table: from the .blend if packed there (exact), else from the disk cache,
    else built (and written to the disk cache)."""
    from lutgen import WideLUT, build_wide_lut

    from lutgen.wide_lut import APEX_SIZE

    store = bpy.data.texts.get(STORE)
    name = _wide_name(r_obs, r_min, rows, n_phi)
    arr = store.get(name) if store is not None else None
    apex = store.get(name + " apex") if store is not None else None
    if arr is not None and apex is not None:
        data = np.frombuffer(memoryview(arr), dtype=np.float64)
        apex = np.frombuffer(memoryview(apex), dtype=np.float64)
        if data.size == 2 * 4 * sum(rows) * n_phi and apex.size == 4 * APEX_SIZE[0] * APEX_SIZE[1]:
            return WideLUT(r_obs=r_obs, r_min=r_min, rows=tuple(rows), data=data.reshape(2, 4, sum(rows), n_phi).copy(),
                           apex=apex.reshape(4, *APEX_SIZE).copy())
    got = _disk_load(name, {"data": (2, 4, sum(rows), n_phi), "apex": (4, *APEX_SIZE)})
    if got is not None:
        return WideLUT(r_obs=r_obs, r_min=r_min, rows=tuple(rows), data=got["data"], apex=got["apex"])
    lut = build_wide_lut(r_obs, r_min, rows, n_phi)  # not packed or cached, or damaged: built (the same table)
    _disk_save(name, {"data": lut.data, "apex": lut.apex})
    return lut


def family(r_min):
    """The table family for tables from ``r_min`` (r_s) to infinity (one per r_min, kept)."""
    from lutgen import LUTFamily

    r_min = round_radius(r_min)  # a float32 property: 1.05 reads as 1.0499999523...
    fam = _FAMILIES.get(r_min)
    if fam is None:
        fam = _FAMILIES[r_min] = LUTFamily(r_min=r_min, builder=_wide_builder, max_slices=FAMILY_TABLES)
    return fam


def orbit_map(r_obs, r_min):
    """The connecting rays of an observer at r_obs (r_s) read from the one orbit table of the process
    (:class:`lutgen.rays.RayMap`; the table is built on first use, about a second, or read from the
    disk cache); cached by radius like the other tables."""
    from lutgen import rays

    r, r_min = round_radius(r_obs), round_radius(r_min)  # (r_min may exceed r: targets below are not imaged)
    return _cached(("orbits", r, r_min), lambda: rays.RayMap(r, r_min=r_min, table=orbit_table()))


def orbit_table():
    """The process's orbit table (lutgen.rays): from the disk cache when ``GRLENS_LUT_CACHE`` is set and
    holds it, else built (and written there)."""
    from lutgen import rays

    key = (rays.DEFAULT_STEP, rays.DEFAULT_COLUMNS)
    if key in rays._TABLES:
        return rays._TABLES[key]
    name = "_orbits " + " ".join(repr(v) for v in key) + f" v{rays.TABLE_VERSION}"
    probe = rays.OrbitTable.shapes()
    got = _disk_load(name, probe)
    if got is not None:
        table = rays.OrbitTable.from_arrays(got)
    else:
        table = rays.OrbitTable()
        _disk_save(name, table.arrays())
    rays._TABLES[key] = table
    return table


def get_table(g, r_obs):
    """The table for an observer (the camera, or the light of GR illumination) at r_obs (r_s) under the
    scene settings ``g`` (scene.grlens): the orbit table's rays (``lut_mode`` ONE_TABLE, and for any
    observer inside the photon sphere or next to it, below FAMILY_MIN r_s, whatever the mode), a
    family's table (EVERY_DISTANCE) or a fixed-range LUT. Which one depends on the radius and the
    settings only, so every process computes the same geometry. Raises ValueError for bad settings or
    radii."""
    if g.lut_mode == "ONE_TABLE" or round_radius(r_obs) < FAMILY_MIN:
        return orbit_map(r_obs, g.lut_r_min)
    if g.lut_mode == "FIXED_RANGE":
        return get_lut(r_obs, g.lut_r_min, g.lut_r_max, g.lut_n_r, g.lut_n_phi)
    r = round_radius(r_obs)
    fam = family(g.lut_r_min)
    if not fam.r_min < r:
        raise ValueError(f"the lookup table's innermost radius (LUT r min = {fam.r_min:.4g} r_s) must be below "
                         f"the distance of the camera or light ({r:.4g} r_s)")
    return _cached(("wide", r, fam.r_min), lambda: fam.at(r))


def pack(lut) -> str:
    """Store ``lut`` in the .blend (exact): a fixed-range LUT itself; for a family's table, the exact
    tables it is interpolated from (or itself, if exact). Returns a description of what was packed."""
    store = bpy.data.texts.get(STORE) or bpy.data.texts.new(STORE)
    store.use_fake_user = True
    p = lut.parameters
    if p.get("kind") == "orbits":
        return ("nothing: the orbit table serves every radius and is the same in every process (built once "
                "per process, or read from the disk cache)")
    if p.get("kind") != "wide":
        key = _key(*(p[k] for k in ("r_obs", "r_min", "r_max", "n_r", "n_phi")))
        store[_prop_name(key)] = lut.data.ravel()
        return f"the {p['n_r']}x{p['n_phi']} LUT for r_obs = {p['r_obs']:.6g} r_s"
    fam = family(p["r_min"])
    ks = fam.nodes_for(p["r_obs"])
    tables = [fam.exact(fam.node_radius(k)) for k in ks] if ks else [fam.exact(p["r_obs"])]
    size = 0
    for t in tables:
        name = _wide_name(t.r_obs, t.r_min, t.rows, t.n_phi)
        store[name] = t.data.ravel()
        store[name + " apex"] = t.apex.ravel()
        size += t.data.nbytes + t.apex.nbytes
    return (f"{len(tables)} exact table(s) for r_obs = {', '.join(f'{t.r_obs:.5g}' for t in tables)} r_s "
            f"({size / 2**20:.0f} MB)")


def unpack_all() -> int:
    """Remove every packed table from the .blend; returns how many there were."""
    store = bpy.data.texts.get(STORE)
    if store is None:
        return 0
    n = sum(1 for k in store.keys() if k.startswith("_lut ") or (k.startswith(_WIDE) and not k.endswith(" apex")))
    bpy.data.texts.remove(store)
    return n


def clear():
    """Forget the memory caches (packed tables stay in the file; the orbit table, the same for every
    scene, stays built)."""
    _CACHE.clear()
    _FAMILIES.clear()
