"""Lookup tables on disk: one OpenEXR file per table (format version 1).

Layout: a single-part scanline EXR of n_phi x n_r pixels (width = columns = phi, height = rows = x,
row 0 = x_min = 1/r_max). Channels, one per order and quantity:

* ``o1.xi``, ``o1.dt``, ``o1.ux``, ``o1.uy``, ``o2.xi``, ... float32 (what a renderer loads);
* the same with ``.f64`` appended: the float64 values stored bit-exactly (see :mod:`lutgen.exr_io`),
  so that saving and loading a table round-trips exactly.

Units as everywhere in lutgen: xi in radians, dt in r_s/c, radii in r_s. Header attributes (prefixed
``grlens:`` in the file): format_version, r_obs, r_min, r_max, n_r, n_phi, sampling, units,
lutgen_version.
"""
from __future__ import annotations

import os

import numpy as np

from .exr_io import LUTFileError, read_exr, write_exr
from .lut import FORMAT_VERSION, LUT, QUANTITIES, SAMPLING

UNITS = "lengths in r_s; c = 1; xi in radians; dt in r_s/c; ux, uy per eq. (17) of seed 000"
_META_KEYS = ("format_version", "r_obs", "r_min", "r_max", "n_r", "n_phi", "sampling")

__all__ = ["save_lut", "load_lut", "LUTFileError"]


def _channel_names():
    return [f"o{o}.{q}" for o in (1, 2) for q in QUANTITIES]


def save_lut(lut: LUT, path) -> None:
    """Write ``lut`` to ``path`` (OpenEXR, written atomically)."""
    from . import __version__

    channels = {}
    for o in (1, 2):
        for q in QUANTITIES:
            a = lut.channel(o, q)
            channels[f"o{o}.{q}"] = a.astype(np.float32)
            channels[f"o{o}.{q}.f64"] = np.ascontiguousarray(a, dtype=np.float64)
    meta = dict(format_version=FORMAT_VERSION, r_obs=lut.r_obs, r_min=lut.r_min, r_max=lut.r_max,
                n_r=lut.n_r, n_phi=lut.n_phi, sampling=SAMPLING, units=UNITS, lutgen_version=__version__)
    write_exr(os.fspath(path), channels, meta)


def load_lut(path) -> LUT:
    """Read a table written by :func:`save_lut`. Raises :class:`LUTFileError` (a ValueError) naming the
    file and the problem for missing, truncated, corrupt or foreign files and unsupported versions."""
    path = os.fspath(path)
    names = _channel_names()
    channels, meta = read_exr(path, required_channels=names + [n + ".f64" for n in names],
                              required_metadata=list(_META_KEYS))
    try:
        version = int(meta["format_version"])
    except (TypeError, ValueError):
        raise LUTFileError(f"{path}: malformed grlens:format_version {meta['format_version']!r}") from None
    if version != FORMAT_VERSION:
        raise LUTFileError(f"{path}: LUT format version {version} is not supported "
                           f"(this lutgen reads version {FORMAT_VERSION}); rebuild the table")
    try:
        r_obs, r_min, r_max = float(meta["r_obs"]), float(meta["r_min"]), float(meta["r_max"])
        n_r, n_phi = int(meta["n_r"]), int(meta["n_phi"])
    except (TypeError, ValueError) as exc:
        raise LUTFileError(f"{path}: malformed LUT parameters in the header ({exc})") from None
    if meta["sampling"] != SAMPLING:
        raise LUTFileError(f"{path}: unknown sampling {meta['sampling']!r}")
    data = np.empty((2, len(QUANTITIES), n_r, n_phi))
    for o in (1, 2):
        for k, q in enumerate(QUANTITIES):
            a = channels[f"o{o}.{q}.f64"]
            if a.shape != (n_r, n_phi):
                raise LUTFileError(f"{path}: channel o{o}.{q} has shape {a.shape}, header says {(n_r, n_phi)}")
            data[o - 1, k] = a
    try:
        return LUT(r_obs=r_obs, r_min=r_min, r_max=r_max, data=data)
    except ValueError as exc:
        raise LUTFileError(f"{path}: invalid LUT parameters ({exc})") from None
