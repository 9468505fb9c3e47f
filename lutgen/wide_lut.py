"""Lookup tables that reach infinity, for one observer radius or for any (interpolated over a family).

Units: lengths in r_s, c = 1 (times in r_s/c), angles in radians. Conventions as in
:mod:`lutgen.solver` (observer static at (r_obs, phi = 0); xi from the outward radial direction;
order 1 sweeps phi, order 2 sweeps 2*pi - phi).

A :class:`WideLUT` covers every target radius from ``r_min`` (just outside the horizon) to infinity.
Its rows are uniform in the inverse radius x = r_s/r within each of three blocks; the first two meet
at the observer's own radius x_o = 1/r_obs:

* the outer block, ``n_out`` rows from x = 0 (r = infinity; the row holds the rays to R_FAR) to x_o;
* the middle block, ``n_mid`` rows from x_o to x_m = x_o + (x_max - x_o) x_o / (x_o + x_max) (about
  2 x_o for distant observers, half way to x_max for close ones; smooth in r_obs), as fine relative
  to r_obs as the outer one, so that the cells around the observer are alike on both sides;
* the inner block, ``n_in`` rows from x_m to x_max = 1/r_min (the hole's neighbourhood).

The point where a table of connecting rays is singular, the observer itself (x_o, phi = 0), where
xi jumps from 0 (targets beyond it) to pi (targets below it), is then a corner of the outer and the
middle block, never inside an interpolation stencil. Order-1 lookups within APEX_RADIUS * r_obs of
the observer read a small polar table about it instead (``apex``: rows uniform in the distance s
from the observer, columns in the angle theta of the chord from the outward radial), where what
remains of xi after the chord's angle is subtracted is smooth (about s times a function of theta).

Closed-form parts are subtracted before storing (:func:`singular_parts`): from order 1's xi the
static-frame angle of the straight chord to the target, and from the travel times a closed-form
travel time built on the tortoise coordinate r* = r + ln(r - 1), which removes the growth to
infinity (r + ln r), the logarithm at the horizon and (order 1) the cone at the observer, so that
what is interpolated is smooth.

Because the blocks are scale-free near the observer (uniform in r_obs/r), the tables of different
observers agree node by node up to the slow change of the light bending with r_obs: :class:`LUTFamily` holds exact tables at the fixed radii 1 + exp(k * step) and interpolates
them (cubic Lagrange in ln(r_obs - 1), node by node: like ln r_obs far out, denser towards the photon
sphere, where the tables change fastest) to give the table of any camera radius in milliseconds;
a camera that moves every frame therefore needs no new table per frame.
"""
from __future__ import annotations

import math
import os
import threading
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from .lut import QUANTITIES, Lookup, _cubic_stencil, lookup_in_blocks, stencil_2d
from .solver import check_observer_radius, connect, connect_grid

R_MIN = 1.05
"""Default innermost radius (r_s) of a wide table: the horizon is at 1; below about 1.05 the
first-order image of a surface is a sliver under the photon ring that no camera resolves."""

R_FAR = 1e9
"""The outer block's first row (x = 0) holds the rays to r = R_FAR r_s: their directions differ from
those to infinity by about r_obs / R_FAR rad (2e-8 at r_obs = 20), and the travel time less its
closed form (:func:`singular_parts`) is still exact there to about 1e-7 r_s/c in float64."""

APEX_RADIUS = 0.3
"""Order-1 points closer to the observer than this many times r_obs are looked up in the polar table
about the observer: there xi is mostly a function of the direction from the camera, which the main
table's rows and columns do not follow (there its errors are 2e-7 rad at this distance, growing
towards the camera; the polar table's stay below 1e-8 rad)."""

APEX_SIZE = (32, 128)
"""(rows in s, columns in theta) of the polar table about the observer."""

DEFAULT_SIZE = (48, 48, 192, 384)
"""(n_out, n_mid, n_in, n_phi) of the add-on's wide tables (see docs/tables.md for the trade)."""

FAMILY_STEP = 0.125
"""Spacing of a family's observer radii in ln(r_obs - 1) (8 per factor e, about 6 per doubling far
out)."""

FAMILY_R_OBS = (1.51, 1.0e5)
"""Observer radii (r_s) a family interpolates; outside them a table is built for the radius itself."""


def tortoise(r):
    """The tortoise coordinate r* = r + ln(r - 1) (units of r_s; c = 1): radial null rays have
    dt = |dr*|. Infinite at r = infinity, -infinity at the horizon."""
    r = np.asarray(r, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return r + np.log(r - 1.0)


def singular_parts(r, phi, r_obs):
    """Closed-form parts that a wide table subtracts before storing and adds back after interpolating
    (arrays broadcast from r (r_s), phi (rad); r_obs in r_s): (xi_chord, dt_chord, dt_radial).

    * xi_chord: the angle, in the observer's static frame, of the straight chord from the observer to
      the target (radial component scaled by 1/sqrt(1 - 1/r_obs)): order 1's xi tends to it next to
      the observer, where xi is a function of the direction alone. Subtracted from order 1's xi.
    * dt_chord = sqrt((r* - r*_obs)^2 + 2 r r_obs (1 - cos phi) / (1 - 1/r_obs)): the light travel
      time next to the observer to first order, r + ln r + const far away, -ln(r - 1) + const at the
      horizon. Subtracted from order 1's dt.
    * dt_radial = |r* - r*_obs| (radial light). Subtracted from order 2's dt (its rays are not
      singular at the observer; each block is one side of r = r_obs, where this is smooth).
    """
    r, phi = np.broadcast_arrays(np.asarray(r, dtype=np.float64), np.asarray(phi, dtype=np.float64))
    k = 1.0 - 1.0 / r_obs
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        h = np.sin(0.5 * phi)
        h2 = h * h  # (1 - cos phi) / 2, without cancellation at small phi
        # the chord (r cos phi - r_obs, r sin phi) divided by r (finite at r = infinity)
        xi_chord = np.arctan2(np.sqrt(k) * np.sin(phi), (1.0 - r_obs / r) - 2.0 * h2)
        radial = tortoise(r) - tortoise(r_obs)
        dt_chord = np.sqrt(radial * radial + 4.0 * r * r_obs * h2 / k)
    return xi_chord, dt_chord, np.abs(radial)


def apex_coordinates(r, phi, r_obs):
    """(s, theta): distance (r_s) of points (r, phi) from the observer at (r_obs, 0) in their plane,
    and the angle (rad, [0, pi]) of the chord to them from the observer's outward radial direction."""
    r, phi = np.broadcast_arrays(np.asarray(r, dtype=np.float64), np.asarray(phi, dtype=np.float64))
    with np.errstate(invalid="ignore", over="ignore"):
        h = np.sin(0.5 * phi)
        x = (r - r_obs) - 2.0 * r * h * h  # r cos(phi) - r_obs without cancellation
        y = r * np.sin(phi)
        return np.hypot(x, y), np.arctan2(y, x)


def build_apex(r_obs, size=APEX_SIZE) -> np.ndarray:
    """The polar table about an observer at r_obs (r_s): (4, n_s, n_theta) order-1 (xi, dt, ux, uy)
    of :func:`lutgen.solver.connect` at distances s = APEX_RADIUS * r_obs * i / (n_s - 1) and chord
    angles theta = pi * j / (n_theta - 1), less the chord's angle (xi) and the closed-form travel time
    (dt) of :func:`singular_parts`. The s = 0 row holds the limits (solved at s = 1e-9 r_obs)."""
    n_s, n_t = int(size[0]), int(size[1])
    s = APEX_RADIUS * r_obs * np.linspace(0.0, 1.0, n_s)
    s[0] = 1e-9 * r_obs
    theta = np.linspace(0.0, np.pi, n_t)
    S, T = np.meshgrid(s, theta, indexing="ij")
    x, y = r_obs + S * np.cos(T), S * np.sin(T)
    r, phi = np.hypot(x, y), np.arctan2(y, x)
    c = connect(r_obs, r.ravel(), phi.ravel(), 1)
    xi_chord, dt_chord, _ = singular_parts(r.ravel(), phi.ravel(), r_obs)
    out = np.stack([c.xi - xi_chord, c.dt - dt_chord, c.ux, c.uy]).reshape(4, n_s, n_t)
    out[:2, 0] = 0.0  # the limits at the observer: xi is the chord's angle, dt vanishes with s
    return out


def check_wide_parameters(r_obs, r_min, rows, n_phi):
    """Validate a wide table's parameters (radii in r_s; ``rows`` = (n_out, n_mid, n_in)); returns
    them as (float, float, (int, int, int), int)."""
    r_obs = check_observer_radius(r_obs)
    r_min = float(r_min)
    if not (np.isfinite(r_min) and 1.0 < r_min < r_obs):
        raise ValueError(f"need 1 < r_min < r_obs (units of r_s), got r_min = {r_min}, r_obs = {r_obs}")
    rows, n_phi = tuple(int(n) for n in rows), int(n_phi)
    if len(rows) != 3 or min(rows + (n_phi,)) < 4:
        raise ValueError(f"each of the three blocks needs at least 4x4 nodes, got rows = {rows}, n_phi = {n_phi}")
    return r_obs, r_min, rows, n_phi


def block_edges(r_obs, r_min) -> tuple[float, float, float, float]:
    """Inverse radii (r_s/r) at which the outer, middle and inner blocks start and end: (0, x_o, x_m,
    x_max)."""
    x_o, x_max = 1.0 / r_obs, 1.0 / r_min
    return 0.0, x_o, x_o + (x_max - x_o) * x_o / (x_o + x_max), x_max


def row_radii(r_obs, r_min, rows) -> np.ndarray:
    """(sum(rows),) target radii (r_s) of the rows: the outer block from R_FAR to r_obs, the middle
    one from r_obs inwards, the inner one down to r_min (each uniform in 1/r). The observer's row
    ends the outer block and starts the middle one; the middle block's last row starts the inner."""
    e = block_edges(r_obs, r_min)
    x = np.concatenate([np.linspace(e[i], e[i + 1], n) for i, n in enumerate(rows)])
    with np.errstate(divide="ignore"):
        r = 1.0 / x
    r[0] = R_FAR
    r[rows[0] - 1] = r_obs  # exactly, whatever the rounding of 1/x_o
    r[rows[0]] = r_obs
    return r


@dataclass(eq=False)
class WideLUT:
    """Table of connecting rays for an observer at ``r_obs`` and targets at every r >= r_min (r_s).

    ``data``: float64 (2, 4, sum(rows), n_phi) = (order - 1, quantity, row, column), quantities
    in the order of ``QUANTITIES``, less the closed-form parts of :func:`singular_parts` (order 1: xi
    and dt; order 2: dt); ``rows`` = (n_out, n_mid, n_in), the blocks' row counts; ``apex``: the
    polar table about the observer (:func:`build_apex`).
    Build it with :func:`build_wide_lut` or take it from a :class:`LUTFamily`.
    """

    r_obs: float
    r_min: float
    rows: tuple
    data: np.ndarray
    apex: np.ndarray
    source: str = "exact"

    def __post_init__(self):
        self.data = self._checked(np.ascontiguousarray(self.data, dtype=np.float64))
        self.apex = np.ascontiguousarray(self.apex, dtype=np.float64)
        if self.apex.ndim != 3 or self.apex.shape[0] != len(QUANTITIES) or min(self.apex.shape[1:]) < 4:
            raise ValueError(f"the polar table about the observer must have shape (4, n_s, n_theta), got {self.apex.shape}")

    def _checked(self, data) -> np.ndarray:
        if data.ndim != 4 or data.shape[:2] != (2, len(QUANTITIES)) or data.shape[2] != sum(self.rows):
            raise ValueError(f"wide table data must have shape (2, 4, {sum(self.rows)}, n_phi), got {data.shape}")
        self.r_obs, self.r_min, self.rows, _ = check_wide_parameters(self.r_obs, self.r_min, self.rows, data.shape[3])
        self._edges = np.array(block_edges(self.r_obs, self.r_min))
        self._starts = np.array([0, self.rows[0], self.rows[0] + self.rows[1]])
        self._counts = np.array(self.rows)
        self._n_phi = data.shape[3]
        return data

    r_max = math.inf

    @property
    def n_phi(self) -> int:
        return self._n_phi

    @property
    def parameters(self) -> dict:
        """What the table is, for caches and change detection (``source``: "exact" or "family")."""
        return dict(kind="wide", r_obs=self.r_obs, r_min=self.r_min, rows=self.rows, n_phi=self.n_phi,
                    source=self.source)

    def lookup(self, r, phi, order: int = 1, quantities=QUANTITIES) -> Lookup:
        """Interpolated (xi, dt, ux, uy) at points (r, phi) (broadcast arrays; r in r_s, any r >= r_min
        including infinity, phi in radians in [0, pi]); NaN outside. As :meth:`lutgen.LUT.lookup`."""
        return self.lookup_orders(r, phi, (order,), quantities)[order]

    def lookup_orders(self, r, phi, orders=(1, 2), quantities=QUANTITIES) -> dict:
        """:meth:`lookup` for several orders at once: {order: Lookup} (one stencil per point)."""
        shape, (r, p), out = lookup_in_blocks(self, r, phi, orders, quantities)
        if 1 in out:  # next to the observer: the polar table about it
            near = np.flatnonzero(self.near_observer(r, p))
            if near.size:
                got = self._apex_lookup(r[near], p[near], quantities)
                for q in quantities:
                    out[1][q][near] = got[q]
        return {order: Lookup(*(got[q].reshape(shape) if q in got else None for q in QUANTITIES))
                for order, got in out.items()}

    def grid_coordinates(self, r, p):
        """Where points (r, p) fall in the table: (block (0 outer, 1 middle, 2 inner), fractional row
        within the block, fractional column, inside-the-table mask)."""
        e = self._edges
        with np.errstate(divide="ignore", invalid="ignore"):
            x = 1.0 / r
            block = (x > e[1]).astype(np.int64) + (x > e[2])
            lo, hi = e.take(block), e.take(block + 1)
            g = (x - lo) / (hi - lo) * (self._counts.take(block) - 1)
            gp = p / np.pi * (self.n_phi - 1)
        tol = 1e-9
        inside = (x >= 0.0) & (x <= e[3] * (1 + tol)) & (gp >= -tol) & (gp <= self.n_phi - 1 + tol)
        return block, g, gp, inside

    def near_observer(self, r, p) -> np.ndarray:
        """Mask of the points (r, p) closer to the observer than APEX_RADIUS * r_obs (and inside the
        table), whose order-1 rays come from the polar table about the observer."""
        reach = APEX_RADIUS * self.r_obs
        with np.errstate(invalid="ignore"):
            # only points within the reach in r and in phi (sin(phi) <= s / r_obs) can be that close
            near = (np.abs(r - self.r_obs) < reach) & (p >= 0.0) & (p < math.asin(APEX_RADIUS) + 1e-9) & (r >= self.r_min)
        at = np.flatnonzero(near)
        if at.size:
            near[at] = apex_coordinates(r[at], p[at], self.r_obs)[0] < reach
        return near

    def _apex_lookup(self, r, p, quantities) -> dict:
        """Order-1 {quantity: values} of points next to the observer from the polar table ``apex``."""
        s, theta = apex_coordinates(r, p, self.r_obs)
        n_s, n_t = self.apex.shape[1:]
        gs = np.clip(s / (APEX_RADIUS * self.r_obs) * (n_s - 1), 0.0, n_s - 1)
        gt = np.clip(theta / np.pi * (n_t - 1), 0.0, n_t - 1)
        idx, w = stencil_2d(*_cubic_stencil(gs, n_s), *_cubic_stencil(gt, n_t), n_t)
        xi_chord, dt_chord, _ = singular_parts(r, p, self.r_obs)
        out = {}
        for q in quantities:
            v = np.einsum("nij,nij->n", self.apex[QUANTITIES.index(q)].reshape(-1).take(idx), w)
            out[q] = v + (xi_chord if q == "xi" else dt_chord if q == "dt" else 0.0)
        return out

    def _rows_ready(self, first_rows) -> np.ndarray:
        """The array the stencils whose first rows are ``first_rows`` (and the three after each) read:
        ``data`` here; tables whose rows are made on demand (:meth:`LUTFamily.at`) make them first."""
        return self.data

    def _lookup_block(self, r, p, ks, quantities, dest):
        block, g, gp, inside = self.grid_coordinates(r, p)
        block = np.where(inside, block, 0)
        n = self._counts.take(block)
        gl = np.where(inside, np.clip(g, 0.0, n - 1), 0.0)
        gp = np.where(inside, np.clip(gp, 0.0, self.n_phi - 1), 0.0)
        ix, wx = _cubic_stencil(gl, n)
        ix = ix + self._starts.take(block)
        table = self._rows_ready(ix)
        idx, w = stencil_2d(ix, wx, *_cubic_stencil(gp, self.n_phi), self.n_phi)
        outside = ~inside
        parts = {}
        if "dt" in quantities or ("xi" in quantities and 1 in ks):
            xi_chord, dt_chord, dt_radial = singular_parts(r, p, self.r_obs)
            parts = {(1, "xi"): xi_chord, (1, "dt"): dt_chord, (2, "dt"): dt_radial}
        for order, k in ks.items():
            for q in quantities:
                v = dest[order][q]
                np.einsum("nij,nij->n", table[k, QUANTITIES.index(q)].reshape(-1).take(idx), w, out=v)
                if (order, q) in parts:
                    v += parts[order, q]
                v[outside] = np.nan


class _InterpolatedLUT(WideLUT):
    """A family's table for a radius between its nodes: rows are interpolated from the node tables in
    bands of BAND_ROWS rows, when a lookup first needs them (a frame reads a fraction of the table).
    Thread-safe: a band is made by one thread at a time, and is read only once it is whole (the
    add-on's worker thread and the main thread may look up the same table)."""

    BAND_ROWS = 8

    def __init__(self, r_obs, r_min, rows, weights, tables, apexes):
        self._weights, self._tables = weights, tables
        self.apex = sum(wk * a for wk, a in zip(weights, apexes))
        self._made = np.zeros(-(-sum(rows) // self.BAND_ROWS), dtype=bool)
        self._partial = np.empty(tables[0].shape)
        self._lock = threading.Lock()
        self.r_obs, self.r_min, self.rows, self.source = r_obs, r_min, rows, "family"
        self._checked(self._partial)

    @property
    def data(self) -> np.ndarray:
        """The whole interpolated table (float64, as :class:`WideLUT`'s; every band is made)."""
        with self._lock:
            self._make_bands(np.flatnonzero(~self._made))
        return self._partial

    def _make_bands(self, bands):
        for band in bands:
            rows = slice(band * self.BAND_ROWS, (band + 1) * self.BAND_ROWS)
            out = self._partial[:, :, rows]
            np.multiply(self._tables[0][:, :, rows], self._weights[0], out=out)
            for wk, t in zip(self._weights[1:], self._tables[1:]):
                out += wk * t[:, :, rows]
        self._made[bands] = True

    def _rows_ready(self, first_rows) -> np.ndarray:
        need = np.zeros(self._made.size, dtype=bool)
        need[first_rows // self.BAND_ROWS] = True
        need[(first_rows + 3) // self.BAND_ROWS] = True
        if (need & ~self._made).any():
            with self._lock:  # checked again under the lock: another thread may have made them meanwhile
                missing = np.flatnonzero(need & ~self._made)
                if missing.size:
                    self._make_bands(missing)
        return self._partial


def build_wide_lut(r_obs, r_min=R_MIN, rows=DEFAULT_SIZE[:3], n_phi=DEFAULT_SIZE[3], *,
                   workers: int | None = None) -> WideLUT:
    """The exact wide table for an observer at r_obs (r_s): every node solved by
    :func:`lutgen.solver.connect_grid`. Deterministic: the rows are solved in blocks that depend on the
    table's size only, so every process (any number of CPUs) builds a bit-identical table."""
    r_obs, r_min, rows, n_phi = check_wide_parameters(r_obs, r_min, rows, n_phi)
    r = row_radii(r_obs, r_min, rows)
    # the observer's corner: each block gets its own one-sided limit (targets just beyond the
    # observer, xi = 0, and just below it, xi = pi), so the solve uses radii a hair away from r_obs
    solve_r = r.copy()
    solve_r[rows[0] - 1] = r_obs * (1.0 + 1e-12)
    solve_r[rows[0]] = r_obs * (1.0 - 1e-12)
    phi = np.linspace(0.0, np.pi, n_phi)
    data = np.empty((2, len(QUANTITIES), r.size, n_phi))
    rows_per_block = int(np.clip(r.size // 32, 1, max(1, 131072 // n_phi)))
    blocks = [(a, min(a + rows_per_block, r.size)) for a in range(0, r.size, rows_per_block)]
    xi_chord, dt_chord, dt_radial = singular_parts(solve_r[:, None], phi[None, :], r_obs)
    less = {(1, "xi"): xi_chord, (1, "dt"): dt_chord, (2, "dt"): dt_radial}

    def work(block):
        a, b = block
        for order, c in enumerate(connect_grid(r_obs, solve_r[a:b], phi), start=1):
            for q, name in enumerate(QUANTITIES):
                v = getattr(c, name)
                data[order - 1, q, a:b] = v - less[order, name][a:b] if (order, name) in less else v

    workers = max(1, workers or os.cpu_count() or 1)
    with ThreadPoolExecutor(max_workers=workers) as pool:
        list(pool.map(work, blocks))
    return WideLUT(r_obs=r_obs, r_min=r_min, rows=rows, data=data, apex=build_apex(r_obs))


class LUTFamily:
    """Exact wide tables at the observer radii 1 + exp(k * step) (r_s), built when first needed and kept
    (the last ``max_slices``), and the table of any radius between them by interpolation.

    :meth:`at` interpolates the four nearest exact tables node by node with cubic Lagrange weights
    in ln(r_obs - 1) (the blocks are scale-free near the observer, so each node is a smooth function of
    the observer's radius); radii outside ``r_obs_range`` (or closer than one step to its ends) get an exact table
    of their own. Deterministic: a radius always gives the same table, whatever was built before.
    """

    def __init__(self, r_min=R_MIN, rows=DEFAULT_SIZE[:3], n_phi=DEFAULT_SIZE[3], step=FAMILY_STEP,
                 r_obs_range=FAMILY_R_OBS, max_slices=12, builder=build_wide_lut):
        self.r_min, self.rows, self.n_phi = float(r_min), tuple(int(n) for n in rows), int(n_phi)
        self.step = float(step)
        self.k_lo = math.ceil(math.log(r_obs_range[0] - 1.0) / self.step)
        self.k_hi = math.floor(math.log(r_obs_range[1] - 1.0) / self.step)
        self.max_slices = int(max_slices)
        self._builder = builder
        self._slices: OrderedDict = OrderedDict()
        self._lock = threading.RLock()  # exact(): one thread builds a table, the others wait for it
        self.built = 0  # exact tables built so far (for benchmarks and tests)

    @property
    def parameters(self) -> dict:
        return dict(r_min=self.r_min, rows=self.rows, n_phi=self.n_phi, step=self.step)

    def node_radius(self, k: int) -> float:
        return 1.0 + math.exp(k * self.step)

    def exact(self, r_obs) -> WideLUT:
        """The exact table at one radius (cached with the family's node tables)."""
        key = float(r_obs)
        with self._lock:
            lut = self._slices.get(key)
            if lut is None:
                lut = self._builder(key, self.r_min, self.rows, self.n_phi)
                self.built += 1
                self._slices[key] = lut
                while len(self._slices) > self.max_slices:
                    self._slices.popitem(last=False)
            else:
                self._slices.move_to_end(key)
        return lut

    def nodes_for(self, r_obs) -> list[int] | None:
        """The four node indices whose tables give r_obs by interpolation, or None (exact table)."""
        t = math.log(float(r_obs) - 1.0) / self.step
        k0 = math.floor(t) - 1
        if k0 < self.k_lo or k0 + 3 > self.k_hi or self.r_min >= self.node_radius(k0):
            return None
        return [k0, k0 + 1, k0 + 2, k0 + 3]

    def at(self, r_obs) -> WideLUT:
        """The table for an observer at r_obs (r_s): interpolated from the family, or exact."""
        r_obs = check_observer_radius(r_obs)
        ks = self.nodes_for(r_obs)
        if ks is None:
            return self.exact(r_obs)
        t = math.log(r_obs - 1.0) / self.step - ks[0]  # in [1, 2): between the middle two nodes
        w = [float(v) for v in _cubic_stencil(np.array([t]), 4)[1][:, 0]]
        exact = [self.exact(self.node_radius(k)) for k in ks]
        return _InterpolatedLUT(r_obs, self.r_min, self.rows, w, [t.data for t in exact], [t.apex for t in exact])
