"""lutgen.exr_io: bit-exact channels and metadata in OpenEXR, atomic writes, clear errors."""
import os

import numpy as np
import pytest

from lutgen.exr_io import LUTFileError, read_exr, write_exr


def test_round_trip_is_bit_exact(tmp_path):
    rng = np.random.default_rng(0)
    f64 = rng.normal(size=(3, 7)) * 10.0 ** rng.integers(-300, 300, (3, 7))
    f64.flat[:6] = [np.nan, np.inf, -np.inf, -0.0, 5e-324, np.finfo(float).max]
    f32 = rng.normal(size=(3, 7)).astype(np.float32)
    f32.flat[:3] = [np.nan, -0.0, np.float32(1e-45)]
    meta = {"a": 3, "b": 1 / 3, "c": "text with spaces: and colons", "d": -2**40, "e": 1e-300}
    p = tmp_path / "x.exr"
    write_exr(p, {"d": f64, "s": f32}, meta)
    ch, md = read_exr(p, required_channels=["d", "s"], required_metadata=list(meta))
    assert np.array_equal(ch["d"].view(np.uint64), f64.view(np.uint64))
    assert np.array_equal(ch["s"].view(np.uint32), f32.view(np.uint32))
    assert ch["d"].shape == (3, 7) and ch["d"].flags.c_contiguous
    assert md == meta and type(md["a"]) is int and type(md["b"]) is float
    assert [n for n in os.listdir(tmp_path)] == ["x.exr"]  # no temporary file left behind


def test_errors_name_the_file(tmp_path):
    good = tmp_path / "good.exr"
    write_exr(good, {"R": np.zeros((4, 5), np.float32)}, {"k": 1})
    with pytest.raises(LUTFileError, match="missing channel"):
        read_exr(good, required_channels=["G"])
    with pytest.raises(LUTFileError, match="missing header"):
        read_exr(good, required_metadata=["other"])
    for name, content in [("none.exr", None), ("empty.exr", b""), ("junk.exr", b"\x76\x2f\x31\x01" + b"x" * 100),
                          ("half.exr", good.read_bytes()[: good.stat().st_size // 2])]:
        p = tmp_path / name
        if content is not None:
            p.write_bytes(content)
        with pytest.raises(LUTFileError) as exc:
            read_exr(p)
        assert str(p) in str(exc.value)


def test_write_rejects_bad_input(tmp_path):
    with pytest.raises(ValueError):
        write_exr(tmp_path / "a.exr", {"a": np.zeros((2, 2)), "b": np.zeros((3, 2))}, {})
    with pytest.raises(ValueError):
        write_exr(tmp_path / "a.exr", {"a": np.zeros((2, 2), np.int32)}, {})
    with pytest.raises(TypeError):
        write_exr(tmp_path / "a.exr", {"a": np.zeros((2, 2))}, {"x": [1, 2]})
    assert os.listdir(tmp_path) == []
