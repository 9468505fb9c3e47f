"""Named 2-D channels and metadata in a single-part scanline OpenEXR file (OpenEXR 3.x bindings).

Channel arrays have axis order (rows, columns) = (image height, image width); row 0 is the first
scanline. Storage:

* float32 arrays as FLOAT channels (exact);
* float64 arrays bit-exactly as two UINT channels ``<name>.u64hi`` and ``<name>.u64lo`` holding the
  high and low 32 bits of each value's IEEE-754 pattern (EXR has no 64-bit pixel type);
* metadata as string header attributes ``grlens:<key>``, with a type tag so that ints, floats
  (written with ``repr``, hence exact; the bindings would store a Python float as a 32-bit float) and
  strings come back as they went in.

Files are written with lossless ZIP compression to a temporary file next to the target and renamed
into place, so a crash never leaves a half-written file. Every reading problem raises
:class:`LUTFileError` naming the file.
"""
from __future__ import annotations

import os
import tempfile

import numpy as np

_PREFIX = "grlens:"
_HI, _LO = ".u64hi", ".u64lo"


class LUTFileError(ValueError):
    """A grlens data file is missing, unreadable, corrupt, truncated, foreign or of another version."""


def _encode(value) -> str:
    if isinstance(value, bool):
        raise TypeError("booleans are not supported in metadata; use int")
    if isinstance(value, (int, np.integer)):
        return "i:" + str(int(value))
    if isinstance(value, (float, np.floating)):
        return "f:" + repr(float(value))
    if isinstance(value, str):
        return "s:" + value
    raise TypeError(f"unsupported metadata value {value!r}")


def _decode(text: str):
    tag, _, body = text.partition(":")
    if tag == "i":
        return int(body)
    if tag == "f":
        return float(body)
    if tag == "s":
        return body
    raise ValueError(f"unknown metadata encoding {text!r}")


def write_exr(path, channels: dict, metadata: dict) -> None:
    """Write 2-D arrays (all the same shape; float32 or float64) and metadata to ``path``."""
    import OpenEXR

    path = os.fspath(path)
    shapes = {np.shape(a) for a in channels.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 2:
        raise ValueError(f"channels must be 2-D arrays of one shape, got shapes {sorted(shapes)}")
    out = {}
    for name, a in channels.items():
        a = np.asarray(a)
        if a.dtype == np.float32:
            out[name] = np.ascontiguousarray(a)
        elif a.dtype == np.float64:
            bits = np.ascontiguousarray(a).view(np.uint64)
            out[name + _HI] = np.ascontiguousarray((bits >> np.uint64(32)).astype(np.uint32))
            out[name + _LO] = np.ascontiguousarray((bits & np.uint64(0xFFFFFFFF)).astype(np.uint32))
        else:
            raise ValueError(f"channel {name!r}: dtype {a.dtype} is not supported (float32 or float64)")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    header.update({_PREFIX + k: _encode(v) for k, v in metadata.items()})
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".grlens-", suffix=".exr", dir=directory)
    os.close(fd)
    try:
        OpenEXR.File(header, out).write(tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def read_exr(path, required_channels=None, required_metadata=None):
    """Read a file written by :func:`write_exr`: returns (channels, metadata) with float64 channels
    reassembled. ``required_channels`` / ``required_metadata``: names that must be present."""
    import OpenEXR

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise LUTFileError(f"{path}: no such file")
    try:
        f = OpenEXR.File(path)
        header = dict(f.header())
        raw = {name: np.asarray(ch.pixels) for name, ch in f.channels().items()}
    except Exception as exc:  # the bindings raise RuntimeError and others for bad files
        raise LUTFileError(f"{path}: not a readable OpenEXR file (corrupt or truncated?): {exc}") from exc
    metadata = {}
    for key, value in header.items():
        if isinstance(key, str) and key.startswith(_PREFIX):
            try:
                metadata[key[len(_PREFIX):]] = _decode(str(value))
            except ValueError as exc:
                raise LUTFileError(f"{path}: malformed header attribute {key}: {exc}") from None
    channels = {}
    for name, a in raw.items():
        if name.endswith(_HI) or name.endswith(_LO):
            base = name[: -len(_HI)]
            if base in channels:
                continue
            hi, lo = raw.get(base + _HI), raw.get(base + _LO)
            if hi is None or lo is None or hi.dtype != np.uint32 or lo.dtype != np.uint32:
                raise LUTFileError(f"{path}: channel {base!r} is missing half of its float64 data")
            bits = (hi.astype(np.uint64) << np.uint64(32)) | lo.astype(np.uint64)
            channels[base] = np.ascontiguousarray(bits.view(np.float64))
        else:
            channels[name] = np.ascontiguousarray(a)
    missing = [c for c in (required_channels or []) if c not in channels]
    if missing:
        raise LUTFileError(f"{path}: not a grlens LUT file: missing channel(s) {', '.join(missing)}")
    missing = [k for k in (required_metadata or []) if k not in metadata]
    if missing:
        raise LUTFileError(f"{path}: not a grlens LUT file: missing header attribute(s) "
                           + ", ".join(_PREFIX + k for k in missing))
    return channels, metadata
