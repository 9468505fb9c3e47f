"""lutgen.exr_io: bit-exact channels and metadata in OpenEXR, atomic writes, errors naming the file."""
import json
import os
import stat
import struct

import numpy as np
import OpenEXR
import pytest

from lutgen import exr_io
from lutgen.exr_io import LUTFileError, read_exr, write_exr

SPECIAL64 = [np.nan, -np.nan, np.inf, -np.inf, 0.0, -0.0, 5e-324, -5e-324, 2.2250738585072009e-308,
             np.finfo(np.float64).tiny, np.finfo(np.float64).max, -np.finfo(np.float64).max,
             1e300, 1e-300, 1 / 3, 1 + 2**-52, 3.4028235677973366e38]  # the last one > float32 max


def _random_bits(rng, shape, dtype):
    """Uniformly random bit patterns: all NaN payloads, subnormals and magnitudes occur."""
    n = np.dtype(dtype).itemsize * 8
    u = rng.integers(0, 2**63, shape, dtype=np.uint64) * 2 + rng.integers(0, 2, shape, dtype=np.uint64)
    if n == 32:
        u = u >> np.uint64(32)
    return np.ascontiguousarray(u.astype(f"u{n // 8}")).view(dtype)


def _foreign_exr(path, channels, header=None):
    """A valid EXR written with the bindings directly (no lutgen bookkeeping)."""
    h = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    h.update(header or {})
    OpenEXR.File(h, channels).write(str(path))


# ----------------------------------------------------------------------------------- round trips


def test_float64_round_trip_is_bit_exact(tmp_path):
    rng = np.random.default_rng(1)
    x = _random_bits(rng, (3, 7), np.float64)
    x.flat[: len(SPECIAL64)] = SPECIAL64
    x.flat[0] = np.frombuffer(np.uint64(0x7FF0_0000_0000_0001).tobytes(), np.float64)[0]  # sNaN payload
    y = rng.normal(size=(3, 7)) * 10.0 ** rng.integers(-300, 300, (3, 7))
    p = tmp_path / "f64.exr"
    write_exr(p, {"x": x, "y": y}, {})
    ch, md = read_exr(p, required_channels=["x", "y"])
    assert set(ch) == {"x", "y"} and md == {}
    for name, a in (("x", x), ("y", y)):
        b = ch[name]
        assert b.dtype == np.float64 and b.shape == (3, 7)
        assert b.flags.c_contiguous and b.flags.writeable
        assert np.array_equal(b.view(np.uint64), a.view(np.uint64))


def test_float32_round_trip_is_bit_exact(tmp_path):
    rng = np.random.default_rng(2)
    x = _random_bits(rng, (7, 3), np.float32)
    x.flat[:10] = np.array([np.nan, np.inf, -np.inf, -0.0, 1e-45, -1e-45, 1.1754942e-38,
                            np.finfo(np.float32).max, 1e-30, 1e30], dtype=np.float32)
    p = tmp_path / "f32.exr"
    write_exr(p, {"x": x}, {})
    ch, _ = read_exr(p)
    assert ch["x"].dtype == np.float32 and ch["x"].shape == (7, 3) and ch["x"].flags.c_contiguous
    assert np.array_equal(ch["x"].view(np.uint32), x.view(np.uint32))


def test_row_order_and_non_square_shapes(tmp_path):
    a64 = np.arange(21, dtype=np.float64).reshape(3, 7)
    p = tmp_path / "rows.exr"
    write_exr(p, {"d": a64, "s": a64.astype(np.float32) + 100}, {})
    ch, _ = read_exr(p)
    assert np.array_equal(ch["d"], a64) and np.array_equal(ch["s"], a64 + 100)
    assert ch["d"][0, 0] == 0 and ch["d"][0, 6] == 6 and ch["d"][2, 0] == 14  # row 0 stays row 0
    with OpenEXR.File(str(p)) as f:  # and the image is 7 wide, 3 high
        assert f.parts[0].width() == 7 and f.parts[0].height() == 3
    for shape in [(1, 1), (1, 9), (9, 1), (5, 2)]:
        a = np.random.default_rng(0).normal(size=shape)
        write_exr(p, {"a": a}, {})
        assert np.array_equal(read_exr(p)[0]["a"], a)


def test_any_memory_layout_and_byte_order(tmp_path):
    base = np.random.default_rng(3).normal(size=(6, 8))
    cases = {"fortran": np.asfortranarray(base), "transposed": base.T, "strided": base[::2, ::3],
             "bigendian64": base.astype(">f8"), "bigendian32": base.astype(">f4")}
    p = tmp_path / "layout.exr"
    for name, a in cases.items():
        write_exr(p, {name: a}, {})
        b = read_exr(p)[0][name]
        assert b.shape == a.shape and b.dtype == np.dtype(a.dtype.kind + str(a.dtype.itemsize))
        assert np.array_equal(b, a), name


def test_float32_hi_lo_split_would_not_be_exact():
    """Why float64 is stored as its 64 bits and not as float32 hi + float32 lo."""
    x = np.array([1 / 3, 1e300, 5e-324, np.pi * 1e-40])
    with np.errstate(over="ignore", invalid="ignore"):
        hi = x.astype(np.float32)
        lo = (x - hi.astype(np.float64)).astype(np.float32)
        back = hi.astype(np.float64) + lo.astype(np.float64)
    assert not np.any(back == x)  # 48 mantissa bits at most; overflow; underflow


def test_metadata_round_trip_is_exact(tmp_path):
    meta = {"format_version": 1, "zero": 0, "neg": -5, "i32max": 2**31 - 1, "i32min": -(2**31),
            "past_i32": 2**31, "big": -(2**40), "huge": 10**30, "third": 1 / 3, "tiny": 5e-324,
            "negzero": -0.0, "inf": float("inf"), "nan": float("nan"), "max": 1.7976931348623157e308,
            "text": "lengths in r_s; c = 1: colons, semicolons", "empty": "", "unicode": "φ ∈ [0, π] ✓",
            "i:looks_tagged": "f:1.5", "np_int": np.int64(7), "np_float": np.float32(0.1)}
    p = tmp_path / "meta.exr"
    write_exr(p, {"a": np.zeros((2, 2))}, meta)
    _, md = read_exr(p, required_metadata=list(meta))
    assert set(md) == set(meta)
    for k, v in meta.items():
        if isinstance(v, str):
            assert type(md[k]) is str and md[k] == v, k
        elif isinstance(v, (int, np.integer)):
            assert type(md[k]) is int and md[k] == v, k
        else:  # bit-exact, also for nan and -0.0
            assert type(md[k]) is float and struct.pack("<d", md[k]) == struct.pack("<d", v), k
    assert md["np_float"] == float(np.float32(0.1)) and md["huge"] == 10**30 and md["big"] == -(2**40)


def test_file_layout_uses_native_attribute_and_pixel_types(tmp_path):
    p = tmp_path / "layout.exr"
    write_exr(p, {"o1.xi": np.ones((3, 4), np.float32), "o1.xi.f64": np.ones((3, 4))},
              {"n": 3, "r": 2.5, "s": "x", "big": 2**40})
    f = OpenEXR.File(str(p), separate_channels=True)  # no "with": __exit__ empties these dicts
    h, ch = f.header(), f.channels()
    assert len(f.parts) == 1
    assert h["compression"] == OpenEXR.ZIP_COMPRESSION and h["type"] == OpenEXR.scanlineimage
    assert sorted(ch) == ["o1.xi", "o1.xi.f64.u64hi", "o1.xi.f64.u64lo"]
    assert ch["o1.xi"].type() == OpenEXR.FLOAT and ch["o1.xi.f64.u64hi"].type() == OpenEXR.UINT
    assert ch["o1.xi.f64.u64hi"].pixels.dtype == np.uint32
    assert h["grlens:n"] == 3 and type(h["grlens:n"]) is int
    assert isinstance(h["grlens:r"], np.ndarray) and h["grlens:r"].dtype == np.float64  # a double
    assert h["grlens:s"] == "x" and h["grlens:big"] == str(2**40)
    assert h["_lutgen.exr_io:scheme"] == exr_io.SCHEME_VERSION
    assert json.loads(h["_lutgen.exr_io:crc32"])["str_ints"] == ["big"]


# ----------------------------------------------------------------------------------------- errors


def _assert_lut_error(path, match=None, **kwargs):
    with pytest.raises(LUTFileError, match=match) as exc:
        read_exr(path, **kwargs)
    assert str(path) in str(exc.value)
    assert isinstance(exc.value, ValueError)
    return exc.value


def test_unreadable_files_raise_naming_the_path(tmp_path, capsys):
    good = tmp_path / "good.exr"
    write_exr(good, {"a": np.random.default_rng(4).normal(size=(40, 50))}, {"k": 1})
    raw = good.read_bytes()
    rng = np.random.default_rng(5)
    cases = {
        "missing.exr": (None, "no such file"),
        "empty.exr": (b"", "empty"),
        "random.exr": (rng.integers(0, 256, 4096, dtype=np.uint8).tobytes(), "not an OpenEXR file"),
        "short.exr": (b"\x76\x2f", "not an OpenEXR file"),
        "magic_then_junk.exr": (raw[:4] + rng.integers(0, 256, 500, dtype=np.uint8).tobytes(), "corrupt"),
        "half.exr": (raw[: len(raw) // 2], "corrupt or truncated"),
        "minus_one_byte.exr": (raw[:-1], "corrupt or truncated"),
        "header_only.exr": (raw[:300], "corrupt or truncated"),
    }
    for name, (content, match) in cases.items():
        p = tmp_path / name
        if content is not None:
            p.write_bytes(content)
        _assert_lut_error(p, match)
    (tmp_path / "adir.exr").mkdir()
    _assert_lut_error(tmp_path / "adir.exr", "directory")
    assert capsys.readouterr().out == ""  # the bindings' "Warning: ..." print is captured


def test_corrupted_pixel_data_is_detected(tmp_path):
    p = tmp_path / "good.exr"
    a = np.random.default_rng(6).normal(size=(30, 20))
    write_exr(p, {"a": a, "b": a.astype(np.float32)}, {"k": "v"})
    raw = p.read_bytes()
    for offset in range(len(raw) // 4, len(raw), len(raw) // 25):  # flips inside compressed pixel data
        bad = bytearray(raw)
        bad[offset] ^= 0x10
        q = tmp_path / f"flip{offset}.exr"
        q.write_bytes(bytes(bad))
        _assert_lut_error(q, "corrupt")


def test_corrupted_metadata_is_detected(tmp_path):
    p = tmp_path / "meta.exr"
    write_exr(p, {"a": np.zeros((2, 2))}, {"comment": "value-AAAA"})
    raw = p.read_bytes()
    assert raw.count(b"value-AAAA") == 1
    q = tmp_path / "meta_flipped.exr"
    q.write_bytes(raw.replace(b"value-AAAA", b"value-AAAB"))
    _assert_lut_error(q, "checksum mismatch in the grlens: header")


def test_foreign_exr_is_rejected_by_requirements(tmp_path):
    foreign = tmp_path / "foreign.exr"
    rgb = {c: np.full((4, 6), i, np.float32) for i, c in enumerate("RGB")}
    _foreign_exr(foreign, rgb, {"owner": "someone"})
    ch, md = read_exr(foreign)  # readable: R, G, B stay separate channels, no grlens metadata
    assert sorted(ch) == ["B", "G", "R"] and ch["G"].shape == (4, 6) and np.all(ch["G"] == 1) and md == {}
    _assert_lut_error(foreign, "missing channel", required_channels=["o1.xi"])
    _assert_lut_error(foreign, "missing header field", required_metadata=["format_version"])
    # written by write_exr, but with other channels / metadata than required
    other = tmp_path / "other.exr"
    write_exr(other, {"R": np.zeros((4, 4), np.float32)}, {"something": 1})
    _assert_lut_error(other, "missing channel.*'o1.xi.f64'", required_channels=["R", "o1.xi.f64"])
    _assert_lut_error(other, "grlens:format_version", required_metadata=["something", "format_version"])


def test_foreign_exr_with_unsupported_content(tmp_path):
    z = np.zeros((3, 4), np.float32)
    cases = {
        "half.exr": ({"h": z.astype(np.float16)}, {}, "HALF"),
        "uint.exr": ({"u": z.astype(np.uint32)}, {}, "UINT"),
        "unpaired.exr": ({"x.u64hi": z.astype(np.uint32)}, {}, "incomplete"),
        "badpair.exr": ({"x.u64hi": z.astype(np.uint32), "x.u64lo": z}, {}, "UINT"),
        "clash.exr": ({"x": z, "x.u64hi": z.astype(np.uint32), "x.u64lo": z.astype(np.uint32)}, {}, "both"),
        "badattr.exr": ({"a": z}, {"grlens:v": (1.0, 2.0)}, "malformed header field grlens:v"),
        "scheme2.exr": ({"a": z}, {"_lutgen.exr_io:scheme": 2}, "unsupported .*version 2"),
        "nocrc.exr": ({"a": z}, {"_lutgen.exr_io:scheme": 1}, "_lutgen.exr_io:crc32"),
        "badcrc.exr": ({"a": z}, {"_lutgen.exr_io:scheme": 1, "_lutgen.exr_io:crc32": "{"}, "malformed"),
    }
    for name, (channels, header, match) in cases.items():
        p = tmp_path / name
        _foreign_exr(p, channels, header)
        _assert_lut_error(p, match)
    multi = tmp_path / "multipart.exr"
    OpenEXR.File([OpenEXR.Part({}, {"a": z}), OpenEXR.Part({}, {"a": z})]).write(str(multi))
    _assert_lut_error(multi, "multi-part")
    # a foreign 32-bit float attribute is still a float
    p = tmp_path / "float_attr.exr"
    _foreign_exr(p, {"a": z}, {"grlens:f": 0.5, "grlens:i": 3})
    assert read_exr(p)[1] == {"f": 0.5, "i": 3}


def test_required_names_must_be_a_list(tmp_path):
    p = tmp_path / "a.exr"
    write_exr(p, {"a": np.zeros((2, 2))}, {})
    with pytest.raises(TypeError):
        read_exr(p, required_channels="a")


# ------------------------------------------------------------------------------------------ writes


def test_write_rejects_bad_input_and_writes_nothing(tmp_path):
    p = tmp_path / "a.exr"
    z = np.zeros((2, 3))
    bad_channels = [
        {}, {"a": np.zeros(3)}, {"a": np.zeros((2, 3, 1))}, {"a": np.zeros((0, 3))},
        {"a": z, "b": np.zeros((3, 2))}, {"a": z.astype(np.int32)}, {"a": z.astype(np.float16)},
        {"a": z.astype(np.complex128)}, {"a.u64hi": z}, {"a.u64lo": z.astype(np.float32)}, {"": z},
        {"x" * 250: z}, {"nul\0": z},
    ]
    for channels in bad_channels:
        with pytest.raises(ValueError):
            write_exr(p, channels, {})
    with pytest.raises(TypeError):
        write_exr(p, {1: z}, {})
    for meta, exc in [({"x": [1, 2]}, TypeError), ({"x": True}, TypeError), ({"x": None}, TypeError),
                      ({1: 1}, TypeError), ({"": 1}, ValueError), ({"k" * 250: 1}, ValueError)]:
        with pytest.raises(exc):
            write_exr(p, {"a": z}, meta)
    assert os.listdir(tmp_path) == []


def test_atomic_write_leaves_no_temp_files_and_keeps_old_file_on_failure(tmp_path, monkeypatch):
    p = tmp_path / "lut.exr"
    write_exr(p, {"a": np.ones((2, 2))}, {"v": 1})
    assert os.listdir(tmp_path) == ["lut.exr"]
    write_exr(p, {"a": np.full((3, 3), 2.0)}, {"v": 2})  # overwrite in place
    assert os.listdir(tmp_path) == ["lut.exr"]
    ch, md = read_exr(p)
    assert md == {"v": 2} and ch["a"].shape == (3, 3)
    before = p.read_bytes()

    class CrashingFile:
        """Writes half a file, then fails, like a crash or a full disk in the middle of a write."""

        def __init__(self, header, channels):
            pass

        def write(self, filename):
            with open(filename, "wb") as fh:
                fh.write(before[: len(before) // 2])
            raise RuntimeError("disk full")

    monkeypatch.setattr(OpenEXR, "File", CrashingFile)
    with pytest.raises(OSError, match="disk full"):
        write_exr(p, {"a": np.zeros((3, 3))}, {"v": 3})
    monkeypatch.undo()
    assert os.listdir(tmp_path) == ["lut.exr"] and p.read_bytes() == before
    with pytest.raises(FileNotFoundError):
        write_exr(tmp_path / "no_such_dir" / "x.exr", {"a": np.zeros((2, 2))}, {})


@pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
def test_written_file_has_normal_permissions(tmp_path):
    p = tmp_path / "perm.exr"
    umask = os.umask(0o022)
    try:
        write_exr(p, {"a": np.zeros((2, 2))}, {})
        assert stat.S_IMODE(p.stat().st_mode) == 0o644  # not mkstemp's 0o600
        p.chmod(0o640)
        write_exr(p, {"a": np.zeros((2, 2))}, {})
        assert stat.S_IMODE(p.stat().st_mode) == 0o640  # an overwritten file keeps its mode
    finally:
        os.umask(umask)
