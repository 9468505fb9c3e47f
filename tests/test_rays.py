"""The orbit table (one table for every observer radius) and the connecting rays read from it
(:mod:`lutgen.rays`), against the closed-form solver :func:`lutgen.connect` outside the photon sphere
and the DOP853 integrator of the geodesic equations (:func:`lutgen.reference.shoot`) inside it.

Units: r_s, radians, r_s/c.
"""
import math

import numpy as np
import pytest

import lutgen
import lutgen.wide_lut
from lutgen import orbit as O
from lutgen import rays, reference


@pytest.fixture(scope="module")
def table():
    return rays.orbit_table()


def test_table_nodes_against_closed_forms(table):
    """u on each kind's orbits at the closed-form angle of random radii, by the table's interpolation."""
    rng = np.random.default_rng(0)
    for name, lo, hi in (("T", -24.0, rays.RHO_MAX_T), ("P", -24.0, rays.RHO_MAX_P), ("I", -24.0, rays.RHO_MAX_I)):
        kind = table.kinds[name]
        rho = rng.uniform(lo, hi, 3000)
        orb = rays._orbits(name, rho)
        if name == "T":
            u = orb.e2 * rng.uniform(0, 1, rho.size)
            th = O.sweep_from_turning_point(orb, u, np.sqrt(orb.e2 - u))
            scale = orb.e2
        elif name == "P":
            u = rng.uniform(0, 1, rho.size)
            th = O.sweep(orb, u) - O.sweep(orb, np.full(u.size, O.U_PHOTON))
            scale = 1.0
        else:
            u = orb.e3 + (1 - orb.e3) * rng.uniform(0, 1, rho.size)
            th = rays._sweep_inner(orb, u)
            scale = 1.0
        got, _ = kind.evaluate(rho, th)
        assert np.max(np.abs(got - u) / scale) < 3e-7, name


def _spy_row_residual(monkeypatch, measure):
    """Wrap RayMap._row_residual (the rows' residuals, one call per search pass) so that each call
    appends ``measure(row)`` (e.g. np.size: the rows evaluated) to the returned list."""
    record = []
    real = rays.RayMap._row_residual

    def counting(self, row, *a, **k):
        record.append(measure(row))
        return real(self, row, *a, **k)

    monkeypatch.setattr(rays.RayMap, "_row_residual", counting)
    return record


def _targets(rng, r_obs, n):
    r = 10 ** rng.uniform(np.log10(1.06), 3, n)
    p = rng.uniform(0, np.pi, n)
    d = r_obs * 10 ** rng.uniform(-3, np.log10(0.5), n // 4)  # beside the camera
    a = rng.uniform(0, np.pi, d.size)
    x, y = r_obs + d * np.cos(a), d * np.sin(a)
    return np.concatenate([r, np.hypot(x, y), [1e9, 1e6]]), np.concatenate([p, np.arctan2(y, x), [1.0, 2.0]])


@pytest.mark.parametrize("r_obs", [1e7, 1e6, 1e5, 1e4, 20.0, 6.0, 2.0, 1.6, 1.51])
def test_connecting_rays_outside_photon_sphere(r_obs):
    rng = np.random.default_rng(int(r_obs * 10))
    r, p = _targets(rng, r_obs, 3000)
    ok = r >= 1.05
    r, p = r[ok], p[ok]
    got = rays.RayMap(r_obs).lookup_orders(r, p)
    for o in (1, 2):
        ex = lutgen.connect(r_obs, r, p, o)
        assert np.nanmax(np.abs(got[o].xi - ex.xi)) < 2e-6, o
        assert np.nanmax(np.abs(got[o].dt / ex.dt - 1.0)) < 5e-6, o
        assert np.nanmax(np.abs(got[o].ux - ex.ux)) < 1e-4, o
        assert np.nanmax(np.abs(got[o].uy - ex.uy)) < 1e-4, o
        assert not np.isnan(got[o].xi).any()


@pytest.mark.parametrize("r_obs", [1.45, 1.2, 1.05, 1.01])
def test_connecting_rays_inside_photon_sphere_against_dop853(r_obs):
    """Shoot the table's ray (xi, on the target's side for order 1, the other for order 2) with the
    DOP853 integrator until it has swept the target's angle: it is at the target's radius, after the
    table's travel time."""
    rng = np.random.default_rng(int(r_obs * 100))
    n = 40
    r = np.concatenate([10 ** rng.uniform(np.log10(1.05), 2, n), [r_obs * 1.02, r_obs * 0.999, 1e4]])
    r = np.maximum(r, 1.01)
    p = rng.uniform(0.02, np.pi - 0.02, r.size)
    got = rays.RayMap(r_obs, r_min=1.01).lookup_orders(r, p)
    for o in (1, 2):
        for i in range(r.size):
            xi, dt = got[o].xi[i], got[o].dt[i]
            assert np.isfinite(xi) and np.isfinite(dt)
            sweep = p[i] if o == 1 else 2 * np.pi - p[i]
            shot = reference.shoot(r_obs, xi, side=1 if o == 1 else -1, phi_end=sweep, r_escape=1e6)
            assert shot.status == "phi", (o, r[i], p[i], shot.status)
            assert abs(1.0 / shot.r - 1.0 / r[i]) < 2e-6 * max(1.0, abs(shot.phi)), (o, r[i], p[i], shot.r)
            # the shot ends where it has swept the angle, a hair from the target along the ray
            slack = abs(lutgen.wide_lut.tortoise(shot.r) - lutgen.wide_lut.tortoise(r[i]))
            assert abs(shot.dt - dt) < 2e-5 * dt + 1.01 * slack, (o, r[i], p[i], shot.dt, dt)


def test_inside_photon_sphere_families():
    """From inside the photon sphere: outward rays within the escape limit reach far targets; the
    rays that turn back (apoapsis) reach targets below the observer at large angles; rays to targets
    between the observer and the photon sphere exist for every angle."""
    r_obs = 1.3
    m = rays.RayMap(r_obs)
    lim = lutgen.escape_limit(r_obs)
    far = m.lookup(np.array([1e6]), np.array([0.5]), 1)
    assert far.xi[0] < lim
    assert abs(far.xi[0] - _escape_xi(r_obs, 0.5)) < 1e-6
    below = m.lookup(np.array([1.1, 1.1]), np.array([2.5, 3.0]), 1)
    assert np.all(below.xi < 0.5 * np.pi) and np.all(below.xi > lim)  # out, turn back, fall in
    between = m.lookup(np.full(5, 1.45), np.linspace(0.1, 3.0, 5), 1)
    assert np.all(np.isfinite(between.xi))


def _escape_xi(r_obs, phi_inf):
    """xi whose ray reaches infinity at phi_inf (lutgen.escape, inverted by bisection)."""
    lo, hi = 0.0, lutgen.escape_limit(r_obs) * (1 - 1e-12)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if lutgen.escape_angle(r_obs, mid) < phi_inf:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def test_batch_independence_and_determinism():
    """A point's ray does not depend on the other points looked up with it, nor on what was looked up
    or built before (the same RayMap radius gives bit-identical values)."""
    rng = np.random.default_rng(5)
    r, p = _targets(rng, 7.0, 2000)
    a = rays.RayMap(7.0).lookup_orders(r, p)
    rays.RayMap(3.3).lookup_orders(r, p)
    sub = slice(100, 160)
    b = rays.RayMap(7.0).lookup_orders(r[sub], p[sub])
    for o in (1, 2):
        for q in ("xi", "dt", "ux", "uy"):
            assert np.array_equal(getattr(a[o], q)[sub], getattr(b[o], q)), (o, q)


@pytest.mark.parametrize("r_obs", [20.0, 2.5, 1.2])
def test_segments_made_on_first_need(r_obs):
    """Some segments (outside the photon sphere those of the rays that cross it, inside it those of the
    turning rays) get their nodes (the observer's phase and J there) when a point's solve first needs
    them: a point's ray is the same bit for bit whether the segments were made before it (by other
    points, or all at once) or for it."""
    rng = np.random.default_rng(9)
    r, p = _targets(rng, r_obs, 3000)
    fresh = rays.RayMap(r_obs)
    assert not fresh._built.all()  # a segment waits for a point
    every = rays.RayMap(r_obs)
    for i in np.flatnonzero(~every._built):
        if every._twins()[i] == i:
            every._build(i)
    ref = every.lookup_orders(r, p)
    for sub in (slice(0, 40), slice(1000, 1300), slice(2900, 3000)):
        alone = rays.RayMap(r_obs).lookup_orders(r[sub], p[sub])
        for o in (1, 2):
            for q in ("xi", "dt", "ux", "uy"):
                assert np.array_equal(getattr(ref[o], q)[sub], getattr(alone[o], q), equal_nan=True), (o, q)


def _no_seed(self, u, sweep):
    """The seed index disabled: every point's window at the first segment's first rows."""
    return np.zeros(u.size, dtype=np.int64), np.zeros(u.size)


@pytest.mark.parametrize("r_obs", [1e4, 20.0, 2.0, 1.2])
def test_seed_index_chooses_only_where_the_search_starts(r_obs, monkeypatch):
    """The per-radius seed index puts most points' roots inside its window of four rows (so the rows
    looked up per point stay few: no segment tests for those), and the rays are those of the segment
    tests and the full search over the rows (index disabled: the window at the first segment's first
    rows, which brackets almost nothing)."""
    rng = np.random.default_rng(int(r_obs) + 3)
    r, p = _targets(rng, r_obs, 4000)
    ok = r >= 1.05
    r, p = r[ok], p[ok]
    evaluated = _spy_row_residual(monkeypatch, np.size)
    m = rays.RayMap(r_obs)
    evaluated.clear()
    got = m.lookup_orders(r, p)
    with_index = sum(evaluated) / (2 * r.size)
    monkeypatch.setattr(rays.RayMap, "_seed", _no_seed)
    evaluated.clear()
    full = m.lookup_orders(r, p)
    without = sum(evaluated) / (2 * r.size)
    # the window (4), and for the few points it does not bracket the segments' ends (up to 3) and a search;
    # next to the ray tangent at the observer the last three rows for the cubic's start where unknown
    assert with_index < 6.5 < without
    for o in (1, 2):
        assert np.nanmax(np.abs(got[o].xi - full[o].xi)) < 1e-8, o
        assert np.nanmax(np.abs(got[o].dt / full[o].dt - 1.0)) < 1e-8, o
        assert np.array_equal(np.isnan(got[o].xi), np.isnan(full[o].xi))


@pytest.mark.parametrize("r_obs", [1e7, 1e5, 3e3, 20.0, 1.51, 1.4999, 1.2, 1.001])
def test_turning_ray_of_label_inverts_the_label(r_obs):
    """RayMap._d_of_rho for turning rays (a row label's ray, d = |xi - critical angle|: Newton's method
    from a start that holds for far observers too, where d >> the critical angle) against RayMap._rho,
    the label of a ray (closed form), over the turning segments' labels."""
    m = rays.RayMap(r_obs)
    for i in range(m.n_seg):
        if m.s_kind[i] == 1:
            continue
        rho = m.row_rho[m.r_first[i]:m.r_first[i] + m.r_count[i]]
        rho = np.concatenate([rho, np.linspace(rho[0], rho[-1], 5001)])
        seg = np.full(rho.size, i)
        with np.errstate(divide="ignore", invalid="ignore"):
            back = m._rho(seg, m._d_of_rho(seg, rho))
        assert np.max(np.abs(back - rho)) < 1e-9, (i, np.max(np.abs(back - rho)))


def test_stencil_weights():
    """rays._stencil (shared products) against lutgen.lut._cubic_stencil."""
    from lutgen.lut import _cubic_stencil
    g = np.concatenate([np.linspace(0.0, 576.0, 5001), [0.0, 1.0, 575.0, 576.0]])
    i_a, w_a = rays._stencil(g, 577)
    i_b, w_b = _cubic_stencil(g, 577)
    assert np.array_equal(i_a, i_b)
    assert np.max(np.abs(w_a - w_b)) < 1e-12
    assert np.allclose(w_a.sum(0), 1.0, atol=1e-12)
    # the few-points path (up to _STENCIL_SMALL points) gives the same weights bit for bit
    for k in range(0, g.size, rays._STENCIL_SMALL):
        i_s, w_s = rays._stencil(g[k:k + rays._STENCIL_SMALL], 577)
        assert np.array_equal(i_s, i_a[k:k + rays._STENCIL_SMALL])
        assert np.array_equal(w_s, w_a[:, k:k + rays._STENCIL_SMALL])


def test_node_sums_one_take():
    """rays._sum4 and rays._gather (the nodes from one take) against the sums node by node, in order,
    bit for bit (real and complex tables, a column tail beyond the row's range)."""
    rng = np.random.default_rng(3)
    n_c = 37
    for flat in (rng.normal(size=20 * n_c), rays._complex(rng.normal(size=20 * n_c), rng.normal(size=20 * n_c))):
        base = rng.integers(0, 16 * n_c, 300)
        wr, wc = rng.normal(size=(4, 300)), rng.normal(size=(4, 300))
        want4 = wc[0] * flat[base] + wc[1] * flat[base + 1] + wc[2] * flat[base + 2] + wc[3] * flat[base + 3]
        assert np.array_equal(rays._sum4(wc, flat, base), want4)
        want = None
        for i in range(4):
            b = base + i * n_c
            t = wr[i] * (wc[0] * flat[b] + wc[1] * flat[b + 1] + wc[2] * flat[b + 2] + wc[3] * flat[b + 3])
            want = t if want is None else want + t
        assert np.array_equal(rays._gather(flat, base, wr, wc, n_c), want)
        # the linear tail: beyond the columns [0, n_c - 1] the slope there times the excess
        c = np.concatenate([rng.uniform(-3.0, 0.0, 150), rng.uniform(n_c - 1.0, n_c + 2.0, 150)])
        cc = np.clip(c, 0.0, n_c - 1.0)
        dw = rays._derivative_weights(cc, n_c)
        slope = np.zeros(300, dtype=flat.dtype)
        for i in range(4):
            for j in range(4):
                slope += wr[i] * dw[j] * flat[base + (i * n_c + j)]
        got = rays._linear_tail(flat, base, n_c, c, cc, wr, want.copy())
        assert np.array_equal(got, want + slope * (c - cc))


def test_observer_range():
    with pytest.raises(ValueError):
        rays.RayMap(1.0)
    with pytest.raises(ValueError):
        rays.RayMap(1.0005)
    assert math.isfinite(rays.RayMap(1.001).lookup(np.array([2.0]), np.array([1.0])).xi[0])


@pytest.mark.parametrize("r_obs", [1.45, 1.2, 1.05, 1.01])
def test_exact_connect_inside_photon_sphere_against_dop853(r_obs):
    """lutgen.connect inside the photon sphere (the table's ray polished on the closed-form swept angle):
    the DOP853 integrator, shot at its xi, sweeps the target's angle at the target's radius after its
    travel time, to the integrator's own accuracy; the table agrees to within its 1e-6 rad."""
    rng = np.random.default_rng(int(r_obs * 1000))
    r = np.concatenate([10 ** rng.uniform(np.log10(1.02), 2, 25), [r_obs * 1.01, r_obs * 0.995]])
    p = rng.uniform(0.02, np.pi - 0.02, r.size)
    for o in (1, 2):
        c = lutgen.connect(r_obs, r, p, o)
        assert not np.isnan(c.xi).any()
        table = rays.RayMap(r_obs, r_min=1.001).lookup(r, p, o)
        assert np.max(np.abs(table.xi - c.xi)) < 1e-6
        for i in range(r.size):
            sweep = p[i] if o == 1 else 2 * np.pi - p[i]
            shot = reference.shoot(r_obs, c.xi[i], side=1 if o == 1 else -1, phi_end=sweep, r_escape=1e6)
            assert shot.status == "phi"
            assert abs(1.0 / shot.r - 1.0 / r[i]) < 1e-9
            assert abs(shot.dt / c.dt[i] - 1.0) < 1e-8


@pytest.mark.parametrize("r_obs", [20.0, 1.2])
def test_row_search_passes_give_the_bisections_bracket(r_obs, monkeypatch):
    """The search over a segment's rows (points outside the seed index's window) takes up to
    SEARCH_MAX_K rows per point and pass (the first pass PROBE_STEPS beyond the window where it lay
    on one side of the root); it ends at the same bracket as bisection (SEARCH_BUDGET = 1), so the
    rays are bit-identical, and it takes fewer passes."""
    rng = np.random.default_rng(11)
    r, p = _targets(rng, r_obs, 300)
    ok = r >= 1.05
    r, p = r[ok], p[ok]
    # the index disabled: every point goes through the search
    monkeypatch.setattr(rays.RayMap, "_seed", _no_seed)
    calls = _spy_row_residual(monkeypatch, np.size)
    m = rays.RayMap(r_obs)
    m.lookup_orders(r, p)  # the segments' nodes and the table's error at the observer made (first use)
    calls.clear()
    got = m.lookup_orders(r, p)
    passes = len(calls)
    monkeypatch.setattr(rays, "SEARCH_BUDGET", 1)
    calls.clear()
    bisect = m.lookup_orders(r, p)
    assert len(calls) > passes + 3
    for o in (1, 2):
        for q in ("xi", "dt", "ux", "uy"):
            assert np.array_equal(getattr(got[o], q), getattr(bisect[o], q), equal_nan=True), (o, q)


@pytest.mark.parametrize("r_obs", [20.0, 2.0])
def test_row_search_probes_from_a_window_off_the_root(r_obs, monkeypatch):
    """Windows moved off the root by 2 to 600 rows either way (in the seed's segment): the first pass
    probes rows PROBE_STEPS beyond the window's side, the next a K-section of the bracket found; the
    rays are bit-identical to bisection's (SEARCH_BUDGET = 1), in fewer passes than plain K-sections."""
    rng = np.random.default_rng(5)
    r, p = _targets(rng, r_obs, 400)
    ok = r >= 1.05
    r, p = r[ok], p[ok]
    real_seed = rays.RayMap._seed
    shift = rng.choice([-600, -40, -7, -2, 2, 5, 13, 90, 600], r.size * 2)

    def moved(self, u, sweep):
        seg, row = real_seed(self, u, sweep)
        return seg, np.clip(row + shift[:row.size], 0.0, self.r_count.take(seg) - 1.0)

    monkeypatch.setattr(rays.RayMap, "_seed", moved)
    calls = _spy_row_residual(monkeypatch, np.shape)
    m = rays.RayMap(r_obs)
    m.lookup_orders(r, p)  # the segments' nodes and the table's error at the observer made (first use)
    calls.clear()
    m.solved = m.windowed = 0
    got = m.lookup_orders(r, p)
    assert m.windowed < 0.5 * m.solved
    assert any(len(c) == 2 and c[0] == len(rays.PROBE_STEPS) for c in calls)  # a probe pass
    probed = len(calls)
    monkeypatch.setattr(rays, "PROBE_STEPS", np.array([1]))  # a probe of one row, then K-sections
    calls.clear()
    plain = m.lookup_orders(r, p)
    assert len(calls) >= probed
    monkeypatch.setattr(rays, "SEARCH_BUDGET", 1)
    bisect = m.lookup_orders(r, p)
    for o in (1, 2):
        for q in ("xi", "dt", "ux", "uy"):
            assert np.array_equal(getattr(got[o], q), getattr(bisect[o], q), equal_nan=True), (o, q)
            assert np.array_equal(getattr(plain[o], q), getattr(bisect[o], q), equal_nan=True), (o, q)


def test_no_valid_point():
    """Empty input and points that are all outside the range give empty / NaN results (no solve)."""
    m = rays.RayMap(6.0)
    got = m.lookup_orders(np.empty(0), np.empty(0))
    assert got[1].xi.shape == (0,) and got[2].dt.shape == (0,)
    got = m.lookup_orders(np.array([[0.5, np.nan]]), np.array([[0.3, 0.3]]), orders=(2,))
    assert got[2].xi.shape == (1, 2) and np.isnan(got[2].xi).all() and np.isnan(got[2].uy).all()


@pytest.mark.parametrize("r_obs", [20.0, 4.0])
def test_rays_past_the_periapsis_next_to_the_observer(r_obs):
    """Points beside the observer (order 1, within rays.NEAR r_obs) whose connecting ray passes its
    periapsis on the way (about the observer's radius, a little off its direction): finite travel times
    that agree with lutgen.connect (the near-observer difference of J serves only rays that did not pass
    it; these take the plain sum of both legs), and the tangents and xi as elsewhere. Fails with NaN
    travel times where the two were mixed up."""
    rng = np.random.default_rng(17)
    r = r_obs * rng.uniform(0.97, 1.05, 200)
    p = rng.uniform(0.02, 0.25, r.size)
    got = rays.RayMap(r_obs).lookup(r, p, 1)
    c = lutgen.connect(r_obs, r, p, 1)
    inward = c.xi > 0.5 * np.pi  # rays that start inwards: those beyond the periapsis's radius pass it
    assert 0.25 * r.size < inward.sum() < 0.75 * r.size
    assert np.isfinite(got.dt).all()
    assert np.max(np.abs(got.xi - c.xi)) < 2e-6
    assert np.max(np.abs(got.dt / c.dt - 1.0)) < 5e-6
    assert np.max(np.abs(got.ux - c.ux)) < 1e-4 and np.max(np.abs(got.uy - c.uy)) < 1e-4


def test_quantities_asked_for():
    """Without ux, uy asked for, the solve skips the tangents: xi and dt bit-identical to a full lookup's,
    the tangents absent; every point valid or not, the values where they belong."""
    rng = np.random.default_rng(23)
    r, p = _targets(rng, 9.0, 500)
    r = np.concatenate([r, [0.5, np.nan]])  # two invalid points (inside r_min, NaN)
    p = np.concatenate([p, [1.0, 1.0]])
    m = rays.RayMap(9.0)
    full = m.lookup_orders(r, p)
    some = m.lookup_orders(r, p, quantities=("xi", "dt"))
    for o in (1, 2):
        assert some[o].ux is None and some[o].uy is None
        for q in ("xi", "dt"):
            assert np.array_equal(getattr(full[o], q), getattr(some[o], q), equal_nan=True), (o, q)
        assert np.isnan(full[o].xi[-2:]).all() and np.isfinite(full[o].xi[:-2]).all()
    valid = m.lookup_orders(r[:-2], p[:-2], quantities=("dt",))  # every point valid: the solve's arrays
    assert np.array_equal(valid[2].dt, full[2].dt[:-2])


def test_per_radius_shortcuts_equal_the_general_forms():
    """The set-up's and the solve's shortcuts give the general closed forms' numbers: the crossing rays'
    phase at the observer next to the photon sphere bit for bit (lutgen.orbit.sweep at the observer
    less at the photon sphere, both sides of the photon sphere and beyond pi/2 in Legendre's
    amplitude), away from it (one integral by the addition theorem) within 2e-12 rad; and the turning
    orbits' reference points (the roots of _orbits) bit for bit."""
    rho = np.linspace(rays.RHO_MIN, rays.RHO_MAX_P, 2000)
    orb = rays._orbits("P", rho)
    lo, hi = rays.SINGLE_PHASE_RANGE
    for r_obs in (1.001, 1.05, lo, lo * 1.001, 1.2, 1.5, hi * 0.999, hi, 3.0, 1e4, 1e7):
        uo = 1.0 / r_obs
        with np.errstate(invalid="ignore", divide="ignore"):
            ends = O.sweep(orb, np.array([[uo], [O.U_PHOTON]]) * np.ones(rho.size))
            got = rays._crossing_phase(orb, uo)
            if lo < r_obs < hi:
                assert np.array_equal(got, ends[0] - ends[1], equal_nan=True), r_obs
            else:
                assert np.max(np.abs(got - (ends[0] - ends[1]))) < 2e-12, r_obs
    for kind, mx in (("T", rays.RHO_MAX_T), ("I", rays.RHO_MAX_I)):
        rho = np.linspace(rays.RHO_MIN, mx, 2000)
        o = rays._orbits(kind, rho)
        assert np.array_equal(rays._reference_u(kind, rho), o.e2 if kind == "T" else o.e3), kind
        # far orbits (rho > 0): lutgen.orbit.orbit_from_b's roots from b, bit for bit
        far = rho > 0.0
        ob = O.orbit_from_b(rays.impact_parameter(kind, rho[far]))
        for f in ("e1", "e2", "e3", "delta"):
            assert np.array_equal(getattr(o, f)[far], getattr(ob, f)), (kind, f)


def test_crossing_phase_against_quadrature():
    """The crossing rays' phase at the observer, both forms (one integral by the addition theorem, and
    the difference of two), against scipy's adaptive quadrature of dtheta = du / sqrt(e^2 - u^2 (1 - u))
    from the photon sphere to the observer: with u = 2/3 + w, e^2 - u^2 (1 - u) = eps + w^2 + w^3 exactly
    (eps = e^2 - 4/27 = 4/27 e^rho for these labels), and w = sqrt(eps) sinh(v) takes the near double
    root of orbits that wind out of the integrand, 1 / sqrt(1 + w^3 / (eps cosh^2 v)) dv."""
    from scipy.integrate import quad
    rho = np.array([-20.0, -8.0, -2.0, 0.0, 3.0, 12.0])
    orb = rays._orbits("P", rho)
    for r_obs in (1.01, 1.05, 2.0, 3.0, 30.0, 1e4):
        uo = 1.0 / r_obs
        single, pair = rays._crossing_phase_single(orb, uo), rays._crossing_phase_pair(orb, uo)
        for i in range(rho.size):
            eps = 4.0 / 27.0 * math.exp(rho[i])
            sq = math.sqrt(eps)

            def f(v):
                w = sq * math.sinh(v)
                return 1.0 / math.sqrt(1.0 + w ** 3 / (eps * math.cosh(v) ** 2))
            exact = quad(f, 0.0, math.asinh((uo - O.U_PHOTON) / sq), epsabs=0.0, epsrel=1e-13, limit=200)[0]
            tol = 1e-12 + 1e-11 * abs(exact)
            assert abs(single[i] - exact) < tol, (r_obs, rho[i], single[i], exact)
            assert abs(pair[i] - exact) < tol, (r_obs, rho[i], pair[i], exact)


def test_cubic_root_through_uneven_nodes():
    """rays._cubic_root_nodes (the start next to the ray tangent at the observer): the root and slope
    of the cubic through four uneven nodes, against numpy's polynomial fit and roots."""
    rng = np.random.default_rng(2)
    dn = np.sort(rng.uniform(0.1, 1.0, (4, 50)), axis=0)
    roots = rng.uniform(dn[1], dn[2])
    fn = (dn - roots) * (1.0 + 0.3 * (dn - roots) + 0.2 * (dn - roots) ** 2)
    x, dp = rays._cubic_root_nodes(dn, fn, 0.5 * (dn[1] + dn[2]), dn[1], dn[2], steps=8)
    x3, _ = rays._cubic_root_nodes(dn, fn, 0.5 * (dn[1] + dn[2]), dn[1], dn[2])
    assert np.abs(x3 - roots).max() < 1e-6  # the default three Newton steps from the middle
    for i in range(50):
        c = np.polyfit(dn[:, i], fn[:, i], 3)
        assert abs(x[i] - roots[i]) < 1e-12
        assert abs(dp[i] - np.polyval(np.polyder(c), x[i])) < 1e-9
