"""lutgen.lut / lutgen.lutfile: table build, interpolation, OpenEXR round trip and bad files.

Units: radii in r_s, xi in radians, dt in r_s/c.
"""
import numpy as np
import pytest

from lutgen import LUT, LUTFileError, build_lut, connect, load_lut


@pytest.fixture(scope="module")
def lut():
    return build_lut(20.0, 1.25, 15.0, 96, 192)


def test_nodes_are_exact_connections(lut):
    """Every node holds connect()'s ray; rows uniform in x = 1/r, columns uniform in phi."""
    assert lut.x_nodes[0] == pytest.approx(1 / 15.0) and lut.x_nodes[-1] == pytest.approx(0.8)
    rng = np.random.default_rng(0)
    i, j = rng.integers(0, 96, 300), rng.integers(0, 192, 300)
    r, phi = 1.0 / lut.x_nodes[i], lut.phi_nodes[j]
    for o in (1, 2):
        c = connect(20.0, r, phi, o)
        np.testing.assert_allclose(lut.channel(o, "xi")[i, j], c.xi, rtol=0, atol=1e-11)
        np.testing.assert_allclose(lut.channel(o, "dt")[i, j], c.dt, rtol=1e-10)
        np.testing.assert_allclose(lut.channel(o, "ux")[i, j], c.ux, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(lut.channel(o, "uy")[i, j], c.uy, rtol=1e-9, atol=1e-10)
    assert lut.data32.dtype == np.float32 and lut.data32.shape == (2, 4, 96, 192)


def test_lookup_reproduces_nodes_and_converges(lut):
    """Lookup at a node returns the node; between nodes the error shrinks ~h^4 (cubic)."""
    np.testing.assert_allclose(lut.lookup(1 / lut.x_nodes[10], lut.phi_nodes[37], 2).xi,
                               lut.channel(2, "xi")[10, 37], rtol=0, atol=1e-13)
    rng = np.random.default_rng(3)
    x = rng.uniform(1 / 15, 0.8, 4000)
    phi = rng.uniform(0.05, np.pi - 0.05, 4000)
    exact = connect(20.0, 1 / x, phi, 1).xi
    fine = build_lut(20.0, 1.25, 15.0, 192, 384)
    e_coarse = np.percentile(np.abs(lut.lookup(1 / x, phi, 1).xi - exact), 99)
    e_fine = np.percentile(np.abs(fine.lookup(1 / x, phi, 1).xi - exact), 99)
    assert e_fine < e_coarse / 8  # fourth order would give 16


def test_lookup_outside_domain_is_nan(lut):
    out = lut.lookup(np.array([1.0, 1.2, 16.0, np.nan, 5.0, 5.0]), np.array([1, 1, 1, 1, -0.1, 3.2]))
    assert np.all(np.isnan(out.xi)) and np.all(np.isnan(out.dt))
    edge = lut.lookup(np.array([1.25, 15.0]), np.array([0.0, np.pi]))
    assert np.all(np.isfinite(edge.xi))


def test_exr_round_trip_is_exact(lut, tmp_path):
    path = tmp_path / "lut.exr"
    lut.save(path)
    back = load_lut(path)
    assert back.parameters == lut.parameters
    assert np.array_equal(back.data.view(np.uint64), lut.data.view(np.uint64))
    assert np.array_equal(back.data32, lut.data32)


def test_corrupt_truncated_and_foreign_files(lut, tmp_path):
    good = tmp_path / "good.exr"
    lut.save(good)
    raw = good.read_bytes()
    cases = {
        "missing.exr": None,
        "empty.exr": b"",
        "garbage.exr": bytes(np.random.default_rng(1).integers(0, 256, 4096, dtype=np.uint8)),
        "truncated.exr": raw[: len(raw) // 2],
    }
    for name, content in cases.items():
        p = tmp_path / name
        if content is not None:
            p.write_bytes(content)
        with pytest.raises(LUTFileError) as exc:
            load_lut(p)
        assert str(p) in str(exc.value)
    # a valid EXR that is not a grlens LUT
    from lutgen.exr_io import write_exr
    foreign = tmp_path / "foreign.exr"
    write_exr(str(foreign), {"R": np.zeros((4, 4), np.float32)}, {"something": 1})
    with pytest.raises(LUTFileError) as exc:
        load_lut(foreign)
    assert str(foreign) in str(exc.value)


def test_bad_parameters_raise():
    for args in [(1.2, 1.25, 15, 8, 8), (20, 0.9, 15, 8, 8), (20, 5, 4, 8, 8), (20, 1.25, 15, 2, 8),
                 (np.nan, 1.25, 15, 8, 8)]:
        with pytest.raises(ValueError):
            build_lut(*args)
    with pytest.raises(ValueError):
        LUT(r_obs=20, r_min=1.25, r_max=15, data=np.zeros((2, 3, 8, 8)))


def test_matches_and_progress():
    calls = []
    lut = build_lut(10.0, 1.5, 9.0, 16, 32, progress=lambda d, t: calls.append((d, t)))
    assert calls[-1][0] == calls[-1][1] and len(calls) >= 1
    assert lut.matches(10, 1.5, 9, 16, 32) and not lut.matches(10, 1.5, 9, 16, 33)


def test_lookup_of_some_quantities(lut):
    full = lut.lookup(np.array([2.0, 5.0]), np.array([0.3, 2.0]), 2)
    part = lut.lookup(np.array([2.0, 5.0]), np.array([0.3, 2.0]), 2, quantities=("dt", "uy"))
    assert part.xi is None and part.ux is None
    np.testing.assert_array_equal(part.dt, full.dt)
    np.testing.assert_array_equal(part.uy, full.uy)
    with pytest.raises(ValueError):
        lut.lookup(2.0, 0.3, 1, quantities=("zeta",))


def test_lookup_in_blocks_is_pointwise(lut):
    """lookup_orders works through its points in blocks (LOOKUP_BLOCK): every point's value is the
    one it gets alone, for any input shape (here 2-D, spanning three blocks, with points outside)."""
    from lutgen import lut as lut_module

    rng = np.random.default_rng(5)
    n = 2 * lut_module.LOOKUP_BLOCK + 17
    r = rng.uniform(1.0, 16.0, n).reshape(-1, 1) * np.ones((1, 1))
    phi = rng.uniform(-0.1, np.pi + 0.1, n).reshape(-1, 1)
    many = lut.lookup_orders(r, phi, (1, 2))
    pick = rng.integers(0, n, 40)
    for k in pick:
        one = lut.lookup_orders(r[k, 0], phi[k, 0], (1, 2))
        for o in (1, 2):
            assert many[o].xi.shape == (n, 1) and np.shape(one[o].xi) == ()
            for q in ("xi", "dt", "ux", "uy"):
                np.testing.assert_array_equal(getattr(many[o], q)[k, 0], getattr(one[o], q))
    assert np.isnan(many[1].xi).any() and np.isfinite(many[1].xi).any()
    empty = lut.lookup(np.zeros(0), np.zeros(0), 1)
    assert empty.xi.shape == (0,) and empty.dt.shape == (0,)


def test_build_is_bit_identical_for_any_number_of_threads():
    """Render-farm nodes differ in CPU count: the table must not depend on it."""
    a = build_lut(20.0, 1.05, 40.0, 64, 96, workers=1).data
    b = build_lut(20.0, 1.05, 40.0, 64, 96, workers=5).data
    assert np.array_equal(a, b, equal_nan=True)
