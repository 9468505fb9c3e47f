"""The tables' disk cache (GRLENS_LUT_CACHE, grlens_addon/blender/lutcache.py): a table built in one
process is written there and read back, exactly, by a later one instead of being built; damaged,
foreign or unwritable cache files are ignored (the table is built); unset, nothing is written."""
import os

import numpy as np
import pytest

pytest.importorskip("bpy")

from grlens_addon.blender import lutcache  # noqa: E402

ROWS, N_PHI = (6, 6, 6), 24  # a small family table (seconds to build are not the point here)
FIXED = (12.0, 1.5, 15.0, 16, 24)  # r_obs, r_min, r_max, n_r, n_phi of a small fixed-range LUT


@pytest.fixture()
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(lutcache.CACHE_ENV, str(tmp_path / "luts"))
    monkeypatch.setattr(lutcache, "_CACHE", lutcache.OrderedDict())
    return tmp_path / "luts"


def _forbid_builds(monkeypatch):
    import lutgen

    def refuse(*_a, **_k):
        raise AssertionError("built although cached")

    monkeypatch.setattr(lutgen, "build_wide_lut", refuse)
    monkeypatch.setattr(lutgen, "build_lut", refuse)


def test_a_family_table_is_written_once_and_read_back_exactly(cache, monkeypatch):
    built = lutcache._wide_builder(9.0, 1.5, ROWS, N_PHI)
    files = list(cache.glob("grlens-*.npz"))
    assert len(files) == 1
    _forbid_builds(monkeypatch)
    again = lutcache._wide_builder(9.0, 1.5, ROWS, N_PHI)
    assert np.array_equal(again.data, built.data) and np.array_equal(again.apex, built.apex)
    assert again.rows == built.rows and again.r_obs == built.r_obs


def test_a_fixed_range_lut_is_cached_too(cache, monkeypatch):
    built = lutcache.get_lut(*FIXED)
    monkeypatch.setattr(lutcache, "_CACHE", lutcache.OrderedDict())  # a new process: memory empty
    _forbid_builds(monkeypatch)
    again = lutcache.get_lut(*FIXED)
    assert again is not built and np.array_equal(again.data, built.data)


@pytest.mark.parametrize("damage", ["truncated", "garbage", "other table", "wrong shape"])
def test_a_damaged_or_foreign_file_is_rebuilt(cache, damage):
    built = lutcache._wide_builder(9.0, 1.5, ROWS, N_PHI)
    (path,) = cache.glob("grlens-*.npz")
    if damage == "truncated":
        path.write_bytes(path.read_bytes()[:1000])
    elif damage == "garbage":
        path.write_bytes(os.urandom(5000))
    elif damage == "other table":
        np.savez(path, name=np.array("another table"), data=built.data, apex=built.apex)
    else:
        np.savez(path, name=np.array(lutcache._wide_name(9.0, 1.5, ROWS, N_PHI)), data=built.data[:, :, :-1],
                 apex=built.apex)
    again = lutcache._wide_builder(9.0, 1.5, ROWS, N_PHI)
    assert np.array_equal(again.data, built.data)
    # the file was replaced by the rebuilt table: read back without a build
    assert lutcache._disk_load(lutcache._wide_name(9.0, 1.5, ROWS, N_PHI),
                               {"data": built.data.shape, "apex": built.apex.shape}) is not None


def test_no_cache_when_unset_and_an_unwritable_cache_is_skipped(tmp_path, monkeypatch):
    monkeypatch.delenv(lutcache.CACHE_ENV, raising=False)
    monkeypatch.chdir(tmp_path)
    lutcache._wide_builder(9.0, 1.5, ROWS, N_PHI)
    assert not list(tmp_path.rglob("*.npz"))
    blocker = tmp_path / "a file"
    blocker.write_text("not a directory")
    monkeypatch.setenv(lutcache.CACHE_ENV, str(blocker / "luts"))
    assert lutcache._wide_builder(9.0, 1.5, ROWS, N_PHI).data.shape[2] == sum(ROWS)


def test_the_orbit_table_is_cached_too(cache, monkeypatch):
    """The one orbit table (lutgen.rays, the same for every scene) is written once and read back exactly
    by a later process instead of being built."""
    from lutgen import rays

    monkeypatch.setattr(rays, "_TABLES", {})
    built = lutcache.orbit_table()
    assert len(list(cache.glob("grlens-*.npz"))) == 1
    monkeypatch.setattr(rays, "_TABLES", {})  # a new process

    def refuse(*_a, **_k):
        raise AssertionError("built although cached")

    monkeypatch.setattr(rays, "build_kind", refuse)
    again = lutcache.orbit_table()
    assert again is not built
    for k in ("T", "P", "I"):
        assert np.array_equal(again.kinds[k].u, built.kinds[k].u) and np.array_equal(again.kinds[k].j, built.kinds[k].j)
