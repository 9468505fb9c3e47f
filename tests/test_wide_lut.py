"""Wide lookup tables (every radius out to infinity) and their family over the observer radius,
against the exact solver :func:`lutgen.connect`.

Units: r_s, radians, r_s/c.
"""
import math

import numpy as np
import pytest

import lutgen
from lutgen import wide_lut as W

R_OBS = 20.0


@pytest.fixture(scope="module")
def table():
    return W.build_wide_lut(R_OBS)


@pytest.fixture(scope="module")
def family():
    """A family of smaller tables (its interpolation in r_obs is what is tested; the default size's
    spatial accuracy is tested on ``table``)."""
    return W.LUTFamily(rows=SMALL[:3], n_phi=SMALL[3], max_slices=40)


SMALL = (24, 24, 96, 192)


def _beside(rng, r_obs, n, d_min, d_max):
    """(r, phi) of n points at distances d_min..d_max (units of r_obs, log-uniform) from the observer."""
    d = r_obs * 10 ** rng.uniform(np.log10(d_min), np.log10(d_max), n)
    a = rng.uniform(0, np.pi, n)
    x, y = r_obs + d * np.cos(a), d * np.sin(a)
    return np.hypot(x, y), np.arctan2(y, x)


REGIONS = {  # name: (points, bound on |xi error| in rad, bound on |dt/dt_exact - 1|)
    "next to the hole (1.05-3 r_s)": (lambda rng, r_obs: (rng.uniform(1.05, 3, 2000), rng.uniform(0, np.pi, 2000)),
                                      1e-8, 1e-6),
    "between (3 r_s - r_obs/2)": (lambda rng, r_obs: (rng.uniform(3, r_obs / 2, 2000), rng.uniform(0, np.pi, 2000)),
                                  1e-6, 1e-5),
    "far (2 r_obs - 1e4 r_s)": (lambda rng, r_obs: (10 ** rng.uniform(np.log10(2 * r_obs), 4, 2000),
                                                    rng.uniform(0, np.pi, 2000)), 1e-7, 1e-5),
    "very far (1e4 - 1e12 r_s)": (lambda rng, r_obs: (10 ** rng.uniform(4, 12, 2000), rng.uniform(0, np.pi, 2000)),
                                  1e-7, 1e-5),
    "beside the camera (1e-4 - 0.5 r_obs)": (lambda rng, r_obs: _beside(rng, r_obs, 3000, 1e-4, 0.5), 1e-6, 1e-5),
}


@pytest.mark.parametrize("region", sorted(REGIONS))
def test_table_matches_connect_everywhere(table, region):
    make, xi_tol, dt_tol = REGIONS[region]
    r, phi = make(np.random.default_rng(7), R_OBS)
    for order in (1, 2):
        exact = lutgen.connect(R_OBS, r, phi, order)
        got = table.lookup(r, phi, order)
        ok = np.isfinite(exact.xi)
        assert ok.mean() > 0.99
        assert np.array_equal(np.isfinite(got.xi), ok)
        assert np.max(np.abs(got.xi[ok] - exact.xi[ok])) < xi_tol, (region, order)
        assert np.max(np.abs(got.dt[ok] / exact.dt[ok] - 1)) < dt_tol, (region, order)
        for q in ("ux", "uy"):  # the tangents (illumination, back faces) to a looser bound
            assert np.max(np.abs(getattr(got, q)[ok] - getattr(exact, q)[ok])) < 1e-3, (region, order, q)


def test_infinity_and_outside(table):
    """r = infinity: the escape direction (that of a very distant point), dt infinite; below r_min, NaN
    input and phi outside [0, pi]: NaN."""
    got = table.lookup(np.array([np.inf, 1e15, 1.0, 1.04, np.nan, 10.0]),
                       np.array([1.0, 1.0, 1.0, 1.0, 1.0, 3.5]), 1)
    assert abs(got.xi[0] - lutgen.connect(R_OBS, 1e15, 1.0, 1).xi) < 1e-8
    assert got.dt[0] == np.inf and np.isfinite(got.dt[1])
    assert np.all(np.isnan(got.xi[2:]))


def test_the_observers_own_radius_on_both_sides(table):
    """Points at the camera's radius (beside it), just beyond and just below it at phi = 0 (straight
    out and straight down): exact next to the corner, continuous across the observer's row."""
    phi = np.array([1e-6, 1e-3, 0.05, 0.5, 2.0])
    for r in (R_OBS, R_OBS * (1 + 1e-9), R_OBS * (1 - 1e-9)):
        got = table.lookup(np.full(phi.shape, r), phi, 1)
        exact = lutgen.connect(R_OBS, np.full(phi.shape, r), phi, 1)
        assert np.max(np.abs(got.xi - exact.xi)) < 1e-6
    down = table.lookup(np.array([R_OBS * 0.9, R_OBS * 1.1]), np.zeros(2), 1)
    assert down.xi[0] == pytest.approx(np.pi, abs=1e-9) and down.xi[1] == pytest.approx(0.0, abs=1e-9)


def test_the_polar_table_about_the_observer_is_used_where_it_reaches(table):
    """Order 1 within APEX_RADIUS * r_obs of the observer comes from the polar table (exact on its
    nodes), beyond it from the main table; both agree with connect on the boundary (1e-9, 2e-7 rad)."""
    s = W.APEX_RADIUS * R_OBS * np.array([0.5, 0.999, 1.001])
    theta = np.full(3, 1.0)
    r, phi = np.hypot(R_OBS + s * np.cos(theta), s * np.sin(theta)), np.arctan2(s * np.sin(theta), R_OBS + s * np.cos(theta))
    assert list(table.near_observer(r, phi)) == [True, True, False]
    got, exact = table.lookup(r, phi, 1), lutgen.connect(R_OBS, r, phi, 1)
    assert np.max(np.abs(got.xi - exact.xi)) < 1e-6


def test_singular_parts_are_the_flat_space_limit():
    """Far from any mass (r_obs = 1e8, targets within 1e3 r_s of the observer) light runs straight: the
    chord angle is xi and the chord length the travel time, to the bending of order 1/r_obs."""
    r_obs = 1e8
    rng = np.random.default_rng(3)
    r, phi = _beside(rng, r_obs, 200, 1e-7, 1e-5)
    xi_chord, dt_chord, _ = W.singular_parts(r, phi, r_obs)
    exact = lutgen.connect(r_obs, r, phi, 1)
    assert np.max(np.abs(xi_chord - exact.xi)) < 1e-7
    d = np.hypot(r * np.cos(phi) - r_obs, r * np.sin(phi))
    assert np.max(np.abs(dt_chord / d - 1)) < 1e-6
    assert np.max(np.abs(exact.dt / d - 1)) < 1e-6


@pytest.mark.parametrize("r_obs", [1.7, 3.1, 7.3, 29.0, 611.0])
def test_family_matches_the_exact_table_of_any_radius(family, r_obs):
    """The family's interpolated table (four exact tables at 1 + exp(k/8) r_s) against the exact table
    built for r_obs itself: the same lookups to 3e-6 rad (5e-6 rad next to the photon sphere)."""
    assert family.nodes_for(r_obs) is not None
    interp = family.at(r_obs)
    exact = W.build_wide_lut(r_obs, rows=SMALL[:3], n_phi=SMALL[3])
    assert interp.parameters["source"] == "family" and exact.parameters["source"] == "exact"
    rng = np.random.default_rng(11)
    r = np.concatenate([10 ** rng.uniform(np.log10(1.06), 6, 3000), _beside(rng, r_obs, 1000, 0.02, 0.5)[0]])
    phi = np.concatenate([rng.uniform(0, np.pi, 3000), _beside(rng, r_obs, 1000, 0.02, 0.5)[1]])
    tol = 5e-6 if r_obs < 2 else 3e-6
    for order in (1, 2):
        a, b = interp.lookup(r, phi, order), exact.lookup(r, phi, order)
        ok = np.isfinite(b.xi)
        assert np.array_equal(np.isfinite(a.xi), ok)
        assert np.max(np.abs(a.xi[ok] - b.xi[ok])) < tol, (r_obs, order)
        assert np.max(np.abs(a.dt[ok] / b.dt[ok] - 1)) < 1e-5  # depth: 0.01 r_s at 1000 r_s
    assert np.array_equal(interp.data.shape, exact.data.shape)


def test_family_is_deterministic_and_builds_each_node_once():
    """The same radius gives bit-identical lookups whatever the family built before (farm renders);
    a dolly through one interval builds no new table."""
    calls = []

    def builder(r_obs, *args):
        calls.append(r_obs)
        return W.build_wide_lut(r_obs, *args)

    rng = np.random.default_rng(5)
    r, phi = 10 ** rng.uniform(0.1, 3, 2000), rng.uniform(0, np.pi, 2000)
    fam1, fam2 = (W.LUTFamily(rows=SMALL[:3], n_phi=SMALL[3], builder=builder) for _ in range(2))
    k = fam1.nodes_for(10.0)[1]
    inside = [1 + (fam1.node_radius(k) - 1) * math.exp(t * fam1.step) for t in (0.1, 0.4, 0.7, 0.95)]
    for r_obs in inside:
        fam1.at(r_obs)
    assert len(calls) == 4
    fam2.at(3.0)  # other tables first
    for r_obs in inside:
        a, b = fam1.at(r_obs).lookup_orders(r, phi), fam2.at(r_obs).lookup_orders(r, phi)
        for o in (1, 2):
            assert all(np.array_equal(getattr(a[o], q), getattr(b[o], q), equal_nan=True) for q in lutgen.lut.QUANTITIES)


def test_family_outside_its_range_builds_the_radius_itself():
    fam = W.LUTFamily(rows=SMALL[:3], n_phi=SMALL[3], max_slices=2)
    assert fam.nodes_for(1.51) is None and fam.nodes_for(2e5) is None
    lut = fam.at(1.51)
    assert lut.parameters["source"] == "exact" and lut.r_obs == 1.51


@pytest.mark.parametrize("bad", [dict(r_obs=1.2), dict(r_obs=float("nan")), dict(r_min=0.9), dict(r_min=30.0),
                                 dict(rows=(3, 48, 192)), dict(rows=(48, 48)), dict(n_phi=2)])
def test_bad_parameters_raise(bad):
    kw = dict(r_obs=20.0, r_min=1.05, rows=(48, 48, 192), n_phi=384) | bad
    with pytest.raises(ValueError):
        W.check_wide_parameters(**kw)


def test_build_is_bit_identical_whatever_the_threads():
    """Render-farm processes with any number of CPUs build the same table (rows solved in blocks that
    depend on the table's size only)."""
    a = W.build_wide_lut(7.0, rows=(8, 8, 16), n_phi=32, workers=1)
    b = W.build_wide_lut(7.0, rows=(8, 8, 16), n_phi=32, workers=3)
    assert np.array_equal(a.data, b.data) and np.array_equal(a.apex, b.apex)


def test_a_table_looked_up_from_two_threads_at_once_gives_the_single_thread_values(family):
    """The add-on's worker thread and the main thread may look up one family table at the same time:
    its rows, made on first lookup, must be made once and read only when whole. The node tables are
    read slowly here, so that without the table's lock both threads make the same bands at once."""
    import threading
    import time

    rng = np.random.default_rng(11)
    r, phi = 10 ** rng.uniform(0.1, 3, 3000), rng.uniform(0, np.pi, 3000)
    r_obs = 12.3
    want = family.at(r_obs).lookup_orders(r, phi)

    class Slow:
        def __init__(self, data):
            self.data, self.shape = data, data.shape

        def __getitem__(self, index):
            time.sleep(0.002)
            return self.data[index]

    lut = family.at(r_obs)
    lut._tables = [Slow(t) for t in lut._tables]
    start, got = threading.Barrier(2), [None, None]

    def look(i):
        start.wait()
        got[i] = lut.lookup_orders(r, phi)

    threads = [threading.Thread(target=look, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for res in got:
        for o in (1, 2):
            for q in lutgen.lut.QUANTITIES:
                assert np.array_equal(getattr(res[o], q), getattr(want[o], q), equal_nan=True), (o, q)
