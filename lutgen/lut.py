"""The lookup table (LUT) of connecting null geodesics for one static observer.

Units: lengths in r_s, c = 1 (times in r_s/c), angles in radians. Conventions as in
:mod:`lutgen.solver` (observer static at (r_obs, phi = 0); xi from the outward radial direction;
order 1 sweeps phi, order 2 sweeps 2*pi - phi).

Sampling (seed 000, section 3.1): rows are uniform in the inverse radius x = r_s/r from
x_min = 1/r_max (row 0) to x_max = 1/r_min (last row), endpoints included; columns are uniform in
phi from 0 (column 0) to pi (last column), endpoints included. Every node holds, for each order, the
exact connecting ray (xi, dt, ux, uy) of :func:`lutgen.solver.connect` (computed by the grid solver
:func:`lutgen.solver.connect_grid`). ``data`` is float64 of shape
(2, 4, n_r, n_phi) = (order-1, quantity, row, column) with quantities in the order of ``QUANTITIES``;
``data32`` is the same in float32, the form a renderer uploads.

:meth:`LUT.lookup` interpolates with tensor-product cubic Lagrange (Catmull-Rom-like, 4x4 nodes,
one-sided at the edges), which is exact for cubics and so converges like h^4; outside the domain
(r outside [r_min, r_max], phi outside [0, pi], NaN input) it returns NaN.
"""
from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import numpy as np

from .solver import check_observer_radius, connect_grid

QUANTITIES = ("xi", "dt", "ux", "uy")
FORMAT_VERSION = 1
LOOKUP_BLOCK = 4096
"""Points interpolated together by :meth:`LUT.lookup_orders` (a block's stencils fit the CPU's cache)."""
SAMPLING = "rows uniform in x = r_s/r from 1/r_max to 1/r_min; columns uniform in phi from 0 to pi; endpoints included"


class Lookup(NamedTuple):
    """Interpolated LUT values: xi (rad), dt (r_s/c), ux, uy (eq. 17); NaN outside the domain."""

    xi: np.ndarray
    dt: np.ndarray
    ux: np.ndarray
    uy: np.ndarray


def check_lut_parameters(r_obs, r_min, r_max, n_r, n_phi):
    """Validate LUT parameters (radii in r_s) and return them as (float, float, float, int, int)."""
    r_obs = check_observer_radius(r_obs)
    r_min, r_max = float(r_min), float(r_max)
    if not (np.isfinite(r_min) and np.isfinite(r_max)):
        raise ValueError(f"r_min and r_max must be finite, got {r_min}, {r_max}")
    if not 1.0 < r_min < r_max:
        raise ValueError(f"need 1 < r_min < r_max (units of r_s), got r_min = {r_min}, r_max = {r_max}")
    n_r, n_phi = int(n_r), int(n_phi)
    if n_r < 4 or n_phi < 4:
        raise ValueError(f"the table needs at least 4x4 nodes, got {n_r}x{n_phi}")
    return r_obs, r_min, r_max, n_r, n_phi


@dataclass(eq=False)
class LUT:
    """Lookup table for an observer at ``r_obs`` over r in [r_min, r_max] (units of r_s).

    Build it with :func:`build_lut`, read it with :func:`lutgen.load_lut`.
    """

    r_obs: float
    r_min: float
    r_max: float
    data: np.ndarray  # float64, (2, 4, n_r, n_phi)
    _data32: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self):
        self.r_obs, self.r_min, self.r_max, _, _ = check_lut_parameters(
            self.r_obs, self.r_min, self.r_max, self.data.shape[2], self.data.shape[3])
        if self.data.shape[:2] != (2, len(QUANTITIES)):
            raise ValueError(f"LUT data must have shape (2, 4, n_r, n_phi), got {self.data.shape}")
        self.data = np.ascontiguousarray(self.data, dtype=np.float64)

    # -- geometry of the grid ------------------------------------------------------------------
    @property
    def n_r(self) -> int:
        return self.data.shape[2]

    @property
    def n_phi(self) -> int:
        return self.data.shape[3]

    @property
    def x_min(self) -> float:
        """Smallest inverse radius r_s/r_max (row 0)."""
        return 1.0 / self.r_max

    @property
    def x_max(self) -> float:
        """Largest inverse radius r_s/r_min (last row)."""
        return 1.0 / self.r_min

    @property
    def x_nodes(self) -> np.ndarray:
        """Inverse radii r_s/r of the rows (float64)."""
        return np.linspace(self.x_min, self.x_max, self.n_r)

    @property
    def phi_nodes(self) -> np.ndarray:
        """Angles of the columns in radians (float64)."""
        return np.linspace(0.0, np.pi, self.n_phi)

    @property
    def data32(self) -> np.ndarray:
        """The table in float32, (2, 4, n_r, n_phi), C-contiguous (for rendering/upload)."""
        if self._data32 is None:
            self._data32 = self.data.astype(np.float32)
        return self._data32

    def channel(self, order: int, quantity: str) -> np.ndarray:
        """One channel (n_r, n_phi) in float64, e.g. ``lut.channel(1, "xi")``."""
        return self.data[_order_index(order), QUANTITIES.index(quantity)]

    @property
    def parameters(self) -> dict:
        return dict(r_obs=self.r_obs, r_min=self.r_min, r_max=self.r_max, n_r=self.n_r, n_phi=self.n_phi)

    def matches(self, r_obs, r_min, r_max, n_r, n_phi) -> bool:
        """True if this table was built for exactly these parameters."""
        return self.parameters == dict(r_obs=float(r_obs), r_min=float(r_min), r_max=float(r_max),
                                       n_r=int(n_r), n_phi=int(n_phi))

    # -- interpolation --------------------------------------------------------------------------
    def lookup(self, r, phi, order: int = 1, quantities=QUANTITIES) -> Lookup:
        """Interpolated (xi, dt, ux, uy) at points (r, phi) (broadcast arrays; r in r_s, phi in
        radians in [0, pi]) for the given order. NaN outside the table's domain. Only the
        ``quantities`` asked for are interpolated; the others come back as None."""
        return self.lookup_orders(r, phi, (order,), quantities)[order]

    def lookup_orders(self, r, phi, orders=(1, 2), quantities=QUANTITIES) -> dict:
        """Like :meth:`lookup` for several orders at once: {order: Lookup}. The interpolation stencil
        (which depends on (r, phi) only) is computed once and shared by the orders."""
        shape, _, out = lookup_in_blocks(self, r, phi, orders, quantities)
        return {order: Lookup(*(got[q].reshape(shape) if q in got else None for q in QUANTITIES))
                for order, got in out.items()}

    def _lookup_block(self, r, p, ks, quantities, dest):
        """lookup_orders for 1-d ``r``, ``p`` (one block), written into ``dest`` {order: {quantity: (n,)}}."""
        qi = [QUANTITIES.index(q) for q in quantities]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = 1.0 / r
        gx = (x - self.x_min) / (self.x_max - self.x_min) * (self.n_r - 1)
        gp = p / np.pi * (self.n_phi - 1)
        tol = 1e-9
        inside = (gx >= -tol) & (gx <= self.n_r - 1 + tol) & (gp >= -tol) & (gp <= self.n_phi - 1 + tol)
        gx = np.where(inside, np.clip(gx, 0.0, self.n_r - 1), 0.0)
        gp = np.where(inside, np.clip(gp, 0.0, self.n_phi - 1), 0.0)
        idx, w = stencil_2d(*_cubic_stencil(gx, self.n_r), *_cubic_stencil(gp, self.n_phi), self.n_phi)
        outside = ~inside
        for order, k in ks.items():
            for q, i in zip(quantities, qi):
                v = dest[order][q]
                np.einsum("nij,nij->n", self.data[k, i].reshape(-1).take(idx), w, out=v)  # data: a view
                v[outside] = np.nan

    def save(self, path) -> None:
        """Write the table to an OpenEXR file (see :mod:`lutgen.lutfile`)."""
        from .lutfile import save_lut

        save_lut(self, path)


def stencil_2d(ix, wx, ip, wp, n_cols):
    """(N, 4, 4) flat indices into a row-major channel of ``n_cols`` columns and the (N, 4, 4) weights
    of tensor-product cubic stencils, from the first rows ``ix`` and columns ``ip`` (N,) and the
    weights ``wx``, ``wp`` (4, N) of :func:`_cubic_stencil` (built along N: numpy is slow on short
    inner axes)."""
    offsets = (np.arange(4)[:, None] * n_cols + np.arange(4)[None, :]).ravel()
    idx = ((ix * n_cols + ip)[:, None] + offsets).reshape(-1, 4, 4)
    w = np.ascontiguousarray((wx[:, None, :] * wp[None, :, :]).transpose(2, 0, 1))
    return idx, w


def lookup_in_blocks(table, r, phi, orders, quantities):
    """The shared frame of the tables' ``lookup_orders``: checks ``orders`` and ``quantities``,
    broadcasts (r, phi) and fills {order: {quantity: (N,)}} block by block with
    ``table._lookup_block(r, p, ks, quantities, dest)``. Returns (shape, (r, p) flattened, out)."""
    ks = {order: _order_index(order) for order in orders}
    unknown = set(quantities) - set(QUANTITIES)
    if unknown:
        raise ValueError(f"unknown quantities {sorted(unknown)}; choose from {QUANTITIES}")
    r, phi = np.broadcast_arrays(np.asarray(r, dtype=np.float64), np.asarray(phi, dtype=np.float64))
    shape = r.shape
    r, p = r.ravel(), phi.ravel()
    out = {order: {q: np.empty(r.size) for q in quantities} for order in ks}
    # in blocks: the (n, 4, 4) stencils of a block stay in the CPU's cache (several times faster
    # than one pass over 10^4-10^5 points); every point's value is computed the same way
    for a in range(0, r.size, LOOKUP_BLOCK):
        b = min(a + LOOKUP_BLOCK, r.size)
        table._lookup_block(r[a:b], p[a:b], ks, quantities, {o: {q: v[a:b] for q, v in got.items()}
                                                             for o, got in out.items()})
    return shape, (r, p), out


def _order_index(order) -> int:
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order!r}")
    return int(order) - 1


def _cubic_stencil(g, n):
    """First node (N,) and cubic Lagrange weights (4, N) of the nodes first .. first + 3, for fractional
    grid coordinates g (N,) in [0, n-1].

    The 4-node stencil is shifted inwards at the edges (one-sided), so no node outside the table is
    ever used and the weights reproduce cubics exactly everywhere.
    """
    i0 = np.clip(np.floor(g).astype(np.int64) - 1, 0, n - 4)
    t = g - i0  # position inside the stencil, nodes at 0, 1, 2, 3
    w = np.empty((4, g.size))
    w[0] = -(t - 1.0) * (t - 2.0) * (t - 3.0) / 6.0
    w[1] = t * (t - 2.0) * (t - 3.0) / 2.0
    w[2] = -t * (t - 1.0) * (t - 3.0) / 2.0
    w[3] = t * (t - 1.0) * (t - 2.0) / 6.0
    return i0, w


def build_lut(r_obs, r_min, r_max, n_r, n_phi, *, progress: Callable[[int, int], None] | None = None,
              workers: int | None = None) -> LUT:
    """Build the table for a static observer at r_obs over r in [r_min, r_max] (units of r_s) with
    n_r rows (uniform in x = r_s/r) and n_phi columns (uniform in phi over [0, pi]).

    ``progress(done, total)`` is called after each block of rows; ``workers`` threads share the rows
    (default: the number of CPUs; the elliptic-function kernels release the GIL).
    """
    r_obs, r_min, r_max, n_r, n_phi = check_lut_parameters(r_obs, r_min, r_max, n_r, n_phi)
    x = np.linspace(1.0 / r_max, 1.0 / r_min, n_r)
    phi = np.linspace(0.0, np.pi, n_phi)
    data = np.empty((2, len(QUANTITIES), n_r, n_phi))
    workers = max(1, workers or os.cpu_count() or 1)
    # blocks of rows: small enough for a lively progress bar and to share between threads. The rows of
    # a block are solved together (vectorised quadrature shares its segmentation within a batch), so
    # the partition must not depend on the machine: it depends on the table's size only, and every
    # process (render-farm nodes with any number of CPUs) builds a bit-identical table.
    rows_per_block = int(np.clip(n_r // 32, 1, max(1, 131072 // n_phi)))
    blocks = [(a, min(a + rows_per_block, n_r)) for a in range(0, n_r, rows_per_block)]

    def work(block):
        a, b = block
        for order, c in enumerate(connect_grid(r_obs, 1.0 / x[a:b], phi), start=1):
            for q, name in enumerate(QUANTITIES):
                data[order - 1, q, a:b] = getattr(c, name)

    done = 0
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for _ in pool.map(work, blocks):
            done += 1
            if progress:
                progress(done, len(blocks))
    return LUT(r_obs=r_obs, r_min=r_min, r_max=r_max, data=data)
