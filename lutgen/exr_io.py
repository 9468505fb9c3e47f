"""Named 2-D float arrays plus header metadata in one OpenEXR file (grlens lookup tables).

A thin, validating layer over the official OpenEXR 3.x Python bindings (``import OpenEXR``, the
``OpenEXR.File`` API; works with OpenEXR >= 3.3 and numpy >= 1.24). :func:`write_exr` stores
named 2-D ``float32`` / ``float64`` arrays and a flat metadata dict in a single-part scanline EXR;
:func:`read_exr` reads them back bit-exactly and raises :class:`LUTFileError` for anything wrong
with the file. This module knows nothing about what the arrays mean: callers (``lutgen.lutfile``)
choose channel names and metadata keys. The arrays' axis order is (rows, columns) -- in lutgen's
use (n_r, n_phi) -- and row 0 of the array is row 0 (the top scanline, y = 0) of the image; there
are no units or other conventions at this level.

Storage scheme (scheme version 1)
---------------------------------
* One part, ``scanlineimage``, ZIP compression (lossless), ``INCREASING_Y``; image height = number
  of rows, width = number of columns, data window origin (0, 0).
* A ``float32`` array ``name`` is one EXR channel ``name`` of pixel type FLOAT (32-bit IEEE);
  stored and read back bit for bit (NaN payloads, -0.0 and subnormals included).
* A ``float64`` array ``name`` is two EXR channels of pixel type UINT (32-bit unsigned):
  ``name.u64hi`` and ``name.u64lo``, the high and low 32 bits of the IEEE-754 binary64 bit pattern
  (``u = x.view(uint64); hi = u >> 32; lo = u & 0xFFFFFFFF``). EXR has no 64-bit pixel type and a
  float32 "hi + lo" split is not exact (hi + lo holds at most 48 mantissa bits, values beyond
  float32 range overflow and double subnormals underflow), whereas the bit split is exact for every
  double. Channel names ending in ``.u64hi`` / ``.u64lo`` are therefore reserved.
* Metadata ``{key: value}`` becomes header attribute ``grlens:<key>`` of the matching native EXR
  type, so that other EXR tools show it readably: ``str`` -> string attribute, ``float`` -> double
  attribute (64-bit, exact), ``int`` -> int attribute. The EXR int is only 32-bit signed, so an int
  outside [-2**31, 2**31 - 1] is stored as a string attribute holding its decimal digits and
  listed in the bookkeeping attribute below, which turns it back into an int on reading.
* Two bookkeeping attributes outside the ``grlens:`` namespace: ``_lutgen.exr_io:scheme`` (int, the
  storage scheme version, 1) and ``_lutgen.exr_io:crc32`` (string, JSON object): ``"channels"``, the
  CRC-32 of every stored channel's pixels (little-endian, C order); ``"metadata"``, a CRC-32 of the
  metadata; ``"str_ints"``, the keys of ints stored as strings. The EXR format has no checksum of
  its own, and the OpenEXR library silently decodes a flipped byte in ZIP-compressed data to wrong
  pixels; the CRCs turn such corruption into a :class:`LUTFileError`. (The library writes header
  attributes sorted by name; the leading ``_`` puts these two first, so that a corrupted length
  field of a ``grlens:`` string cannot swallow them and make the file look foreign.)

Files written by other tools ("foreign" files) are read too, as far as they fit the scheme: FLOAT
channels, ``.u64hi``/``.u64lo`` UINT pairs, and string/int/float/double ``grlens:`` attributes;
without the bookkeeping attributes no checksum is verified. Use ``required_channels`` and
``required_metadata`` to reject files that lack what the caller needs.

Writes are atomic: the file is written to a temporary file in the destination directory, flushed
to disk and renamed over the destination (``os.replace``), so a crash leaves either the old file or
the complete new one, never half a table.
"""
from __future__ import annotations

import contextlib
import io
import json
import os
import struct
import sys
import tempfile
import zlib
from collections.abc import Iterable, Mapping

import numpy as np

__all__ = ["LUTFileError", "write_exr", "read_exr", "METADATA_PREFIX", "SCHEME_VERSION"]

METADATA_PREFIX = "grlens:"
"""Header attribute name prefix of the caller's metadata keys."""

SCHEME_VERSION = 1
"""Version of the storage scheme described in the module docstring."""

_SCHEME_ATTR = "_lutgen.exr_io:scheme"  # the leading "_" sorts the two bookkeeping attributes
_CRC_ATTR = "_lutgen.exr_io:crc32"  # before all others in the file header (see below)
_HI, _LO = ".u64hi", ".u64lo"
_MAGIC = b"\x76\x2f\x31\x01"  # first four bytes of every OpenEXR file
_MAX_NAME_BYTES = 255  # EXR limit for channel and attribute names; the bindings truncate longer ones
_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1
_LIB_PIXEL_WARNING = "Warning: Exception raised reading pixel data"


class LUTFileError(ValueError):
    """A lookup-table file cannot be used: missing, unreadable, not an OpenEXR file, truncated or
    corrupt, or lacking / malformed channels or header fields. The message names the file."""


# --------------------------------------------------------------------------------------------- write


def write_exr(path, channels: Mapping[str, np.ndarray], metadata: Mapping[str, str | int | float]) -> None:
    """Write ``channels`` and ``metadata`` to the OpenEXR file ``path``, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; replaced if it exists. Its directory must exist.
    channels : mapping of str to 2-D array
        Non-empty; all arrays 2-D with the same non-empty shape (rows, columns) -- (n_r, n_phi) in
        lutgen -- and floating dtype float32 or float64 (any memory layout or byte order). float32
        is stored as a FLOAT channel, float64 as a pair of UINT channels holding its 64 bits (see
        the module docstring); both round-trip bit-exactly. Names: non-empty, at most 255 UTF-8
        bytes including the ``.u64hi``/``.u64lo`` suffix of float64 channels, no NUL, and not
        ending in ``.u64hi``/``.u64lo``.
    metadata : mapping of str to str, int or float
        Stored as header attributes ``grlens:<key>`` (key: non-empty, no NUL, at most 248 UTF-8
        bytes); all three types round-trip exactly (ints of any size, floats as 64-bit doubles
        including nan/inf/-0.0). numpy integer / floating scalars are accepted and stored as int /
        float; bools are refused (they would read back as int).

    Raises
    ------
    TypeError, ValueError
        For arguments outside the rules above (nothing is written): TypeError for a wrong kind of
        argument (non-str name, unsupported metadata type), ValueError for a wrong shape or dtype
        or an invalid name.
    OSError
        If the file cannot be written (the destination is then left untouched).
    """
    import OpenEXR

    path = os.fspath(path)
    stored, _ = _encode_channels(channels)
    canonical = _canonical_metadata(metadata)
    attributes, str_ints = _encode_metadata(canonical)
    crcs = {"channels": {name: _crc32(a) for name, a in stored.items()},
            "metadata": _metadata_crc32(canonical), "str_ints": str_ints}
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        "lineOrder": OpenEXR.INCREASING_Y,
        _SCHEME_ATTR: SCHEME_VERSION,
        _CRC_ATTR: json.dumps(crcs, sort_keys=True),
    }
    header.update(attributes)

    directory = os.path.dirname(os.path.abspath(path))
    # hidden temporary file next to the target (same file system, so os.replace is atomic)
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path)[:100] + ".", suffix=".tmp", dir=directory)
    try:
        os.close(fd)
        try:
            # OpenEXR.File(header, ...) adds dataWindow/displayWindow to the dict it is given: pass
            # a fresh one. Writing by file name (not to a stream) keeps OpenEXR 3.3/3.4 supported.
            OpenEXR.File(dict(header), stored).write(tmp)
        except Exception as exc:
            raise OSError(f"{path}: could not write the OpenEXR file: {exc}") from exc
        with open(tmp, "r+b") as fh:  # the library closed it; make the bytes durable before renaming
            os.fsync(fh.fileno())
        os.chmod(tmp, _new_file_mode(path))
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_directory(directory)


def _encode_channels(channels):
    """Validate the caller's arrays; return ({stored EXR channel name: C-contiguous array}, shape)."""
    if not isinstance(channels, Mapping) or not channels:
        raise ValueError("channels must be a non-empty mapping of name -> 2-D array")
    stored, shape = {}, None
    for name, array in channels.items():
        if not isinstance(name, str):
            raise TypeError(f"channel name {name!r} is not a str")
        _check_name(name, "channel name")
        if name.endswith((_HI, _LO)):
            raise ValueError(f"channel name {name!r}: the suffixes {_HI!r} and {_LO!r} are reserved "
                             "for the two halves of float64 channels")
        a = np.asarray(array)
        if a.ndim != 2 or 0 in a.shape:
            raise ValueError(f"channel {name!r}: expected a non-empty 2-D array, got shape {a.shape}")
        if shape is None:
            shape = a.shape
        elif a.shape != shape:
            raise ValueError(f"channel {name!r} has shape {a.shape}, other channels {shape}; "
                             "all channels must have the same shape")
        if a.dtype.kind == "f" and a.dtype.itemsize == 4:
            stored[name] = np.ascontiguousarray(a, dtype=np.float32)
        elif a.dtype.kind == "f" and a.dtype.itemsize == 8:
            for suffix in (_HI, _LO):
                _check_name(name + suffix, "channel name (with float64 suffix)")
            bits = np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)
            stored[name + _HI] = (bits >> np.uint64(32)).astype(np.uint32)
            stored[name + _LO] = (bits & np.uint64(0xFFFFFFFF)).astype(np.uint32)
        else:
            raise ValueError(f"channel {name!r}: dtype {a.dtype} is not supported (use float32 or float64)")
    return stored, shape


def _canonical_metadata(metadata):
    """Validate the metadata; return {key: python str | int | float} (numpy scalars converted)."""
    if not isinstance(metadata, Mapping):
        raise TypeError("metadata must be a mapping of str -> str | int | float")
    out = {}
    for key, value in metadata.items():
        if not isinstance(key, str):
            raise TypeError(f"metadata key {key!r} is not a str")
        _check_name(METADATA_PREFIX + key, "metadata key (with prefix)")
        if not key:
            raise ValueError("metadata keys must be non-empty")
        if isinstance(value, (bool, np.bool_)):
            raise TypeError(f"metadata {key!r}: bool is not supported (store an int or a str)")
        if isinstance(value, str):
            out[key] = str(value)
        elif isinstance(value, (int, np.integer)):
            out[key] = int(value)
        elif isinstance(value, (float, np.floating)):
            out[key] = float(value)
        else:
            raise TypeError(f"metadata {key!r}: type {type(value).__name__} is not supported "
                            "(use str, int or float)")
    return out


def _encode_metadata(canonical):
    """{key: value} -> ({header attribute name: object the bindings store as the intended type},
    sorted keys of the ints stored as decimal strings)."""
    attributes, str_ints = {}, []
    for key, value in canonical.items():
        if isinstance(value, float):
            # A python float becomes a 32-bit FloatAttribute in the bindings; a 1-element float64
            # array becomes a 64-bit DoubleAttribute (and reads back as such an array).
            value = np.array([value], dtype=np.float64)
        elif isinstance(value, int) and not _INT32_MIN <= value <= _INT32_MAX:
            # The bindings silently wrap a python int to the 32-bit IntAttribute.
            value = str(value)
            str_ints.append(key)
        attributes[METADATA_PREFIX + key] = value
    return attributes, sorted(str_ints)


# ---------------------------------------------------------------------------------------------- read


def read_exr(path, required_channels: Iterable[str] | None = None,
             required_metadata: Iterable[str] | None = None) -> tuple[dict[str, np.ndarray], dict]:
    """Read a file written by :func:`write_exr` (or a compatible foreign EXR).

    Parameters
    ----------
    path : str or os.PathLike
    required_channels : iterable of str, optional
        Channel names (as given to :func:`write_exr`, e.g. ``"o1.xi.f64"``) that must be present.
    required_metadata : iterable of str, optional
        Metadata keys (without the ``grlens:`` prefix) that must be present.

    Returns
    -------
    channels : dict of str to numpy.ndarray
        Every channel, as a C-contiguous, writable array of shape (rows, columns) -- (n_r, n_phi)
        in lutgen -- with row 0 = row 0 written; dtype float32 for FLOAT channels and float64 for
        ``.u64hi``/``.u64lo`` pairs (reassembled, bit-exact).
    metadata : dict of str to str, int or float
        Every ``grlens:`` header attribute, prefix removed. Doubles (and 32-bit floats of foreign
        files) come back as float, ints as int, strings as str.

    Raises
    ------
    LUTFileError
        Naming ``path`` and the problem: missing / unreadable file, not an OpenEXR file, truncated
        or corrupt (including checksum mismatch), multi-part or deep image, unsupported pixel type,
        unpaired or inconsistent channels, missing required channel or metadata, malformed header
        field, unsupported storage scheme version.
    """
    import OpenEXR

    path = os.fspath(path)
    required_channels = _name_list(required_channels, "required_channels")
    required_metadata = _name_list(required_metadata, "required_metadata")

    def fail(what):
        return LUTFileError(f"{path}: {what}")

    _check_magic(path, fail)
    captured = io.StringIO()
    try:
        # OpenEXR >= 3.5 reports a pixel-data failure by printing a warning to sys.stdout and
        # dropping the part (older versions raise): capture it and turn it into the error message.
        # separate_channels=True: otherwise R, G, B, A channels are merged into one 3-D "RGBA" array.
        with contextlib.redirect_stdout(captured):
            exr = OpenEXR.File(path, separate_channels=True)
            parts = list(exr.parts)
            header = exr.header() if parts else None
            raw = exr.channels() if parts else None
    except Exception as exc:
        raise fail(f"corrupt or truncated OpenEXR file ({_one_line(exc)})") from exc
    finally:
        warnings = _replay_other_output(captured.getvalue())
    if warnings:
        raise fail(f"corrupt or truncated OpenEXR file ({_one_line(' '.join(warnings))})")
    if len(parts) != 1:
        if not parts:
            raise fail("corrupt or truncated OpenEXR file (no readable image part)")
        raise fail(f"multi-part OpenEXR file ({len(parts)} parts); expected a single part")

    stored = _stored_arrays(raw, fail)
    metadata = _decode_metadata(header, fail)
    _verify_scheme(header, stored, metadata, fail)  # also turns ints stored as strings back into ints
    channels = _decode_channels(stored, fail)

    missing = [n for n in required_channels if n not in channels]
    if missing:
        raise fail(f"missing channel(s) {', '.join(map(repr, missing))} (file has "
                   f"{', '.join(map(repr, sorted(channels))) or 'none'}); not a grlens lookup table?")
    missing = [k for k in required_metadata if k not in metadata]
    if missing:
        raise fail(f"missing header field(s) {', '.join(METADATA_PREFIX + k for k in missing)}; "
                   "not a grlens lookup table?")
    return channels, metadata


def _check_magic(path, fail):
    try:
        with open(path, "rb") as fh:
            magic = fh.read(4)
    except FileNotFoundError:
        raise fail("no such file") from None
    except IsADirectoryError:
        raise fail("is a directory, not a file") from None
    except PermissionError:
        raise fail("permission denied") from None
    except OSError as exc:
        raise fail(f"cannot open the file ({exc.strerror or exc})") from exc
    if not magic:
        raise fail("file is empty (0 bytes); not an OpenEXR file")
    if magic != _MAGIC:
        raise fail("not an OpenEXR file (wrong magic number)")


def _replay_other_output(text):
    """Return the library's pixel-read warnings in ``text``; print any other captured line (e.g.
    from another thread) to the real stdout so nothing is lost."""
    warnings, others = [], []
    for line in text.splitlines(keepends=True):
        (warnings if line.startswith(_LIB_PIXEL_WARNING) else others).append(line)
    if others:
        with contextlib.suppress(Exception):  # sys.stdout may be None (e.g. pythonw)
            sys.stdout.write("".join(others))
    return [w.strip() for w in warnings]


def _stored_arrays(raw, fail):
    """{EXR channel name: pixel array}, checking pixel types and a common 2-D shape."""
    stored, shape = {}, None
    for name, channel in raw.items():
        px = channel.pixels
        if not isinstance(px, np.ndarray) or px.ndim != 2 or px.dtype.kind == "O":
            raise fail(f"channel {name!r} is not a flat 2-D pixel array (deep or subsampled image?)")
        if px.dtype == np.float16:
            raise fail(f"channel {name!r} has pixel type HALF; only FLOAT (float32) and UINT pairs "
                       "(float64) are supported")
        if px.dtype not in (np.float32, np.uint32):
            raise fail(f"channel {name!r} has unsupported pixel dtype {px.dtype}")
        if shape is None:
            shape = px.shape
        elif px.shape != shape:
            raise fail(f"channel {name!r} has shape {px.shape}, other channels {shape}")
        stored[name] = px
    if not stored:
        raise fail("the image has no channels")
    return stored


def _decode_channels(stored, fail):
    channels = {}
    for name, px in stored.items():
        if name.endswith((_HI, _LO)):
            continue
        if px.dtype != np.float32:
            raise fail(f"channel {name!r} has pixel type UINT; only FLOAT channels and "
                       f"{_HI!r}/{_LO!r} UINT pairs are supported")
        channels[name] = np.ascontiguousarray(px, dtype=np.float32)
    for name in sorted({n[: -len(_HI)] for n in stored if n.endswith((_HI, _LO))}):
        hi, lo = stored.get(name + _HI), stored.get(name + _LO)
        if hi is None or lo is None:
            raise fail(f"float64 channel {name!r} is incomplete: one of {name + _HI!r} / "
                       f"{name + _LO!r} is missing")
        if hi.dtype != np.uint32 or lo.dtype != np.uint32:
            raise fail(f"float64 channel {name!r}: {name + _HI!r} and {name + _LO!r} must have pixel "
                       f"type UINT, found {hi.dtype} / {lo.dtype}")
        if name in channels:
            raise fail(f"channel {name!r} is stored both as float32 and as float64")
        bits = (hi.astype(np.uint64) << np.uint64(32)) | lo.astype(np.uint64)
        channels[name] = np.ascontiguousarray(bits.view(np.float64))
    return channels


def _decode_metadata(header, fail):
    metadata = {}
    for attr, value in header.items():
        if not attr.startswith(METADATA_PREFIX):
            continue
        key = attr[len(METADATA_PREFIX):]
        if isinstance(value, str):
            metadata[key] = value
        elif isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
            metadata[key] = int(value)
        elif isinstance(value, (float, np.floating)):  # a 32-bit float attribute (foreign file)
            metadata[key] = float(value)
        elif isinstance(value, np.ndarray) and value.dtype == np.float64 and value.size == 1:
            metadata[key] = float(value.reshape(-1)[0])  # double attribute
        else:
            raise fail(f"malformed header field {attr}: unsupported value {value!r} "
                       f"(type {type(value).__name__}); expected a string, int, float or double")
    return metadata


def _verify_scheme(header, stored, metadata, fail):
    """Check the storage scheme version and the CRCs of files that carry them; convert the ints
    stored as strings (``str_ints``) back to int in ``metadata``."""
    if _SCHEME_ATTR not in header:
        if _CRC_ATTR in header:
            raise fail(f"malformed header: {_CRC_ATTR} without {_SCHEME_ATTR}")
        return  # foreign file: nothing to verify
    version = header[_SCHEME_ATTR]
    if not isinstance(version, int) or isinstance(version, bool):
        raise fail(f"malformed header field {_SCHEME_ATTR}: {version!r}")
    if version != SCHEME_VERSION:
        raise fail(f"unsupported lutgen.exr_io storage scheme version {version} (this lutgen "
                   f"reads version {SCHEME_VERSION})")
    try:
        crcs = json.loads(header[_CRC_ATTR])
        channel_crcs = {str(k): int(v) for k, v in crcs["channels"].items()}
        metadata_crc = int(crcs["metadata"])
        str_ints = [str(k) for k in crcs["str_ints"]]
    except Exception as exc:
        raise fail(f"missing or malformed header field {_CRC_ATTR}") from exc
    for key in str_ints:
        text = metadata.get(key)
        try:
            if not isinstance(text, str) or text != text.strip():
                raise ValueError
            metadata[key] = int(text)
        except ValueError:
            raise fail(f"malformed header field {METADATA_PREFIX}{key}: expected an integer written "
                       f"as a string, found {text!r}") from None
    if set(channel_crcs) != set(stored):
        raise fail(f"corrupt file: the stored channels {sorted(stored)} differ from those listed "
                   f"in {_CRC_ATTR} {sorted(channel_crcs)}")
    for name, px in stored.items():
        if _crc32(px) != channel_crcs[name]:
            raise fail(f"corrupt file: checksum mismatch in the pixels of channel {name!r}")
    if _metadata_crc32(metadata) != metadata_crc:
        raise fail("corrupt file: checksum mismatch in the grlens: header fields")


# ------------------------------------------------------------------------------------------- helpers


def _crc32(array):
    """CRC-32 of an array's elements as little-endian bytes in C order."""
    a = np.ascontiguousarray(array, dtype=array.dtype.newbyteorder("<"))
    return zlib.crc32(a.tobytes())


def _metadata_crc32(metadata):
    """CRC-32 of a canonical, exact serialisation of {key: str | int | float}."""
    items = []
    for key in sorted(metadata):
        value = metadata[key]
        if isinstance(value, float):
            items.append([key, "f", struct.pack("<d", value).hex()])
        elif isinstance(value, int):
            items.append([key, "i", str(value)])
        else:
            items.append([key, "s", value])
    return zlib.crc32(json.dumps(items).encode("utf-8"))


def _check_name(name, what):
    if not name:
        raise ValueError(f"{what} must be non-empty")
    if "\0" in name:
        raise ValueError(f"{what} {name!r} contains a NUL character")
    if len(name.encode("utf-8")) > _MAX_NAME_BYTES:
        raise ValueError(f"{what} {name!r} is longer than {_MAX_NAME_BYTES} UTF-8 bytes (EXR limit)")


def _name_list(names, what):
    if names is None:
        return []
    if isinstance(names, str):
        raise TypeError(f"{what} must be an iterable of names, not a single str")
    return list(names)


def _one_line(obj):
    return " ".join(str(obj).split())


def _new_file_mode(path):
    """Permission bits for the new file: those of the file being replaced, else 0o666 & ~umask."""
    try:
        return os.stat(path).st_mode & 0o7777
    except OSError:
        pass
    umask = None
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/self/status") as fh:  # Linux: read the umask without changing it
            for line in fh:
                if line.startswith("Umask:"):
                    umask = int(line.split()[1], 8)
    if umask is None:
        umask = os.umask(0o022)
        os.umask(umask)
    return 0o666 & ~umask


def _fsync_directory(directory):
    """Make the rename durable (POSIX); a no-op where directories cannot be opened."""
    if os.name != "posix":
        return
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
