"""Image-level error of the polygon method: metrics between two per-pixel buffers (numpy only, no bpy).

Both inputs are ``raytrace.PixelBuffers`` of one camera: the reference (``raytrace.trace``) and a
test image (usually ``rasterize.rasterize`` of the pipeline's image meshes). Units: light travel time
in Blender units (BU, c = 1), UVs in texture coordinates, screen distances in pixels.

Per image order o (1, 2, and "all" = orders 1 and 2 together) the comparison reports

* coverage: ``covered_ref`` / ``covered_test`` pixels showing some object in order o;
  ``mismatch``: pixels where exactly one of the two shows a given (object, order o) (a pixel where
  both show order o but of different objects counts once); ``mismatch_frac`` = mismatch /
  covered_ref (the fraction of the reference's covered pixels);
* on the ``matched`` pixels (both show the same object in the same order):

  - ``uv_texel``: |uv_test - uv_ref| times ``texture_size`` (texels of a square texture);
  - ``uv_px``: the same UV difference in screen pixels, |J^-1 (uv_test - uv_ref)|, where
    J = d(uv)/d(column, row) is the reference's UV gradient at that pixel (finite differences
    between neighbours showing the same object and order; one-sided next to silhouettes, pixels
    with neither neighbour in a direction are left out, see ``uv_px_n``). It is how far one would
    have to move on the reference image to see the texture point the test pixel shows: a texture
    lands that many pixels off;
  - ``screen_px`` (with ``image_pixels`` and ``uv_points``): the distance in pixels from the pixel's
    centre to where the texture point drawn there truly appears: the surface point with the test
    pixel's UV (``uv_points``, e.g. :func:`uv_surface_points` on the source mesh), imaged in that
    order through the exact connecting geodesic (``image_pixels``). This is what ``uv_px``
    estimates, without the linearisation: J from finite differences is wrong where the image is
    squeezed to a pixel or less across (beside the Einstein ring the UV changes non-linearly within
    one pixel, J is nearly singular and ``uv_px`` reads hundreds of pixels where the texture is a
    fraction of a pixel off), and ``uv_px`` has no value at all on rings one pixel wide. Where the
    image is not squeezed the two agree (benchmarks/bench_accuracy.py). Without ``uv_points`` the
    surface point the test pixel shows (``test.point``) is imaged instead: the error of the geometry
    alone, blind to corner values interpolated across several source triangles;
  - ``lt_rel``: |lt_test - lt_ref| / lt_ref, the relative light-travel-time error;

  each as p50 / p99 / max (NaN if there is nothing to measure).

A texture (:func:`checker_torn`): checker cells from the UVs (``cells`` per unit of U and of V),
compared per pixel where both show the same object in the same order: ``wrong`` pixels show the
other cell's colour; ``torn`` are the wrong ones whose 3x3 neighbourhood in the reference is all in
one cell of the same object and order, i.e. wrong more than a pixel away from every checker edge (a
texture drawn within the budget is wrong only next to its edges; a torn one is wrong in the middle of
its cells; where cells are under a pixel there is no inside to be torn).

The sky (:func:`compare_sky`): on the pixels whose ray meets no object in the reference, a model of
the lensed world (the direction each ray travels at infinity, NaN for rays that fall in) against the
reference's ``PixelBuffers.sky``: ``sky_angle_px`` (angle between the two directions, in pixels of the
camera's ``pixel_angle``), ``shadow_mismatch`` (pixels where exactly one says the ray falls in) and,
for the checkered world :func:`checker` (checks of 10 degrees in longitude and latitude about the world
z axis), ``checker_per_edge``: mismatched checker pixels per pixel along the reference's checker
edges, about how many pixels the edges are off on average.

Pixels where the reference sees an image of order 3 or more are counted separately
(``higher_ref``; the polygon method builds orders 1 and 2 only) and enter the order keys only through
the test buffer. UV coordinates listed in ``wrap_uv`` are periodic (differences taken modulo 1, e.g.
the longitude of a UV sphere, whose seam otherwise reads as a jump of 1).
"""
from __future__ import annotations

import numpy as np

_STATS = (("p50", 50.0), ("p99", 99.0), ("max", 100.0))


def _stats(x) -> dict:
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    if not x.size:
        return {k: float("nan") for k, _ in _STATS}
    return {k: float(np.percentile(x, q)) for k, q in _STATS}


def _wrap(d, wrap_uv):
    d = np.array(d, dtype=np.float64, copy=True)
    for i, w in enumerate(wrap_uv):
        if w:
            d[..., i] -= np.round(d[..., i])
    return d


def pixel_keys(buf, orders):
    """Per pixel an integer (object, order) key, -1 for no hit or an order not in ``orders``; a pixel is
    a mismatch where the two renders' keys differ and one of them is not -1 (:func:`mismatch_mask`)."""
    ok = buf.hit & np.isin(buf.order, orders)
    return np.where(ok, buf.object_id * 1024 + buf.order, -1)


def mismatch_mask(ref, test, orders=(1, 2)) -> np.ndarray:
    """(S,) bool: pixels where exactly one of the buffers shows a given (object, order), orders among
    ``orders`` (the coverage mismatch of :func:`compare`)."""
    return _differ(pixel_keys(ref, orders), pixel_keys(test, orders))


def _differ(kr, kt):
    return (kr != kt) & ((kr >= 0) | (kt >= 0))


def uv_surface_points(uv, points, tris, corner_uv, wrap_uv=(False, False), chunk: int = 1024) -> np.ndarray:
    """(M, 3) the surface points (BU) of a mesh (``points`` (N, 3), ``tris`` (T, 3), ``corner_uv``
    (T, 3, 2)) whose texture coordinates are ``uv`` (M, 2): in the triangle whose UV triangle contains
    the query (the one it is deepest inside where UV islands overlap or touch), at the same
    barycentric coordinates. Coordinates in ``wrap_uv`` are periodic (the query is also tried one
    period to either side). NaN for a query outside every UV triangle by more than 1e-6 (in
    barycentric terms) and for non-finite queries. Brute force over ``chunk`` queries at a time
    (meant for checks and benchmarks, not per frame)."""
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    points = np.asarray(points, np.float64)
    tris = np.asarray(tris, np.int64)
    t_uv = np.asarray(corner_uv, np.float64)
    a, b, c = t_uv[:, 0], t_uv[:, 1], t_uv[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    good = np.abs(det) > 0
    a, b, c, det, t_ok = a[good], b[good], c[good], det[good], np.flatnonzero(good)
    shifts = [(du, dv) for du in ((-1.0, 0.0, 1.0) if wrap_uv[0] else (0.0,))
              for dv in ((-1.0, 0.0, 1.0) if wrap_uv[1] else (0.0,))]
    out = np.full((len(uv), 3), np.nan)
    for s in range(0, len(uv), chunk):
        q = uv[s:s + chunk]
        best = np.full(len(q), -np.inf)
        pick = np.zeros(len(q), np.int64)
        lam = np.zeros((len(q), 3))
        rows = np.arange(len(q))
        for du, dv in shifts:
            qu, qv = (q[:, 0] + du)[:, None], (q[:, 1] + dv)[:, None]
            with np.errstate(invalid="ignore"):
                l1 = ((qu - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (qv - a[:, 1])) / det
                l2 = ((b[:, 0] - a[:, 0]) * (qv - a[:, 1]) - (qu - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
                depth = np.nan_to_num(np.minimum(np.minimum(1.0 - l1 - l2, l1), l2), nan=-np.inf)
            k = np.argmax(depth, axis=1)
            better = depth[rows, k] > best
            best = np.where(better, depth[rows, k], best)
            pick = np.where(better, k, pick)
            here = np.stack([1.0 - l1[rows, k] - l2[rows, k], l1[rows, k], l2[rows, k]], 1)
            lam = np.where(better[:, None], here, lam)
        found = best >= -1e-6
        p = np.einsum("mk,mkx->mx", lam, points[tris[t_ok[pick]]])
        out[s:s + chunk][found] = p[found]
    return out


def uv_gradient(buf, wrap_uv=(False, False), seam: float = 0.25) -> np.ndarray:
    """(H, W, 2, 2) UV gradient J[..., i, j] = d uv_i / d (column, row)_j of a buffer, from
    neighbours showing the same object in the same order (central differences where both are there,
    one-sided otherwise, NaN with neither); differences above ``seam`` (UV units) are treated as a
    seam and not used."""
    uv = buf.uv
    key = np.where(buf.hit, buf.object_id * 1024 + buf.order, -1)
    out = np.full(uv.shape[:2] + (2, 2), np.nan)
    for j, axis in enumerate((1, 0)):  # column (x), row (y)
        n = uv.shape[axis]
        idx = np.arange(n)
        nxt = np.take(uv, np.minimum(idx + 1, n - 1), axis=axis)
        prv = np.take(uv, np.maximum(idx - 1, 0), axis=axis)
        k_n = np.take(key, np.minimum(idx + 1, n - 1), axis=axis)
        k_p = np.take(key, np.maximum(idx - 1, 0), axis=axis)
        edge_n = (idx == n - 1).reshape((1, -1) if axis == 1 else (-1, 1))
        edge_p = (idx == 0).reshape((1, -1) if axis == 1 else (-1, 1))
        fwd = _wrap(nxt - uv, wrap_uv)
        bwd = _wrap(uv - prv, wrap_uv)
        with np.errstate(invalid="ignore"):
            ok_f = (key >= 0) & (k_n == key) & ~edge_n & np.all(np.abs(fwd) < seam, axis=-1)
            ok_b = (key >= 0) & (k_p == key) & ~edge_p & np.all(np.abs(bwd) < seam, axis=-1)
        d = np.where((ok_f & ok_b)[..., None], 0.5 * (fwd + bwd),
                     np.where(ok_f[..., None], fwd, np.where(ok_b[..., None], bwd, np.nan)))
        out[..., :, j] = d
    return out


def compare(ref, test, *, texture_size: int = 1024, orders=(1, 2), wrap_uv=(False, False),
            other_surface: float | None = None, image_pixels=None, uv_points=None,
            column_period: float | None = None) -> dict:
    """Metrics between the reference buffers ``ref`` and ``test`` (see the module docstring).

    Returns {"orders": {1: {...}, 2: {...}, "all": {...}}, "higher_ref": int, "higher_test": int,
    "pixels": int}; each order's dict holds covered_ref, covered_test, mismatch, mismatch_frac,
    matched, uv_texel / uv_px / lt_rel (dicts p50, p99, max) and uv_px_n. With ``other_surface`` (a
    distance in BU) also other_surface: the matched pixels (same object, same order) whose world
    points (``point`` buffers) are farther apart than that, i.e. that show another part of the object
    (such as its far side through a gap in the near side), which the coverage mismatch cannot see.
    With ``image_pixels``, a function (points (M, 3) BU, order) -> (column, row) giving where the
    image of that order of each point truly appears (e.g. raytrace.image_pixels for the buffers'
    camera), also screen_px (p50, p99, max) and screen_px_n, of the texture points when
    ``uv_points`` (a function (uv (M, 2)) -> points (M, 3) BU, NaN where no surface point has that
    UV) is given, else of the surface points: see the module docstring. ``column_period`` (pixels,
    e.g. ``Camera.column_period`` of an equirectangular panorama): column differences of the screen
    error are taken modulo it (an image across the seam is next to its pixel, not a width away).
    """
    if ref.shape != test.shape:
        raise ValueError(f"buffers of different shapes: {ref.shape} vs {test.shape}")
    grad = uv_gradient(ref, wrap_uv) if ref.uv.ndim == 3 else None
    out = {"orders": {}, "pixels": int(np.prod(ref.shape)),
           "higher_ref": int((ref.hit & (ref.order >= 3)).sum()),
           "higher_test": int((test.hit & (test.order >= 3)).sum())}
    screen = {}
    if image_pixels is not None:
        rows, cols = np.mgrid[0:ref.shape[0], 0:ref.shape[1]]
        for o in orders:
            m = ref.hit & test.hit & (ref.order == o) & (test.order == o) & (ref.object_id == test.object_id)
            shown = uv_points(test.uv[m]) if uv_points is not None else test.point[m]
            col, row = image_pixels(shown, o)
            dc = np.asarray(col) - (cols[m] + 0.5)
            if column_period:
                dc = dc - column_period * np.round(dc / column_period)
            screen[o] = np.hypot(dc, np.asarray(row) - (rows[m] + 0.5))
    for o in list(orders) + ["all"]:
        sel = list(orders) if o == "all" else [o]
        kr, kt = pixel_keys(ref, sel), pixel_keys(test, sel)
        mismatch = int(_differ(kr, kt).sum())
        covered = int((kr >= 0).sum())
        matched = (kr >= 0) & (kr == kt)
        d_uv = _wrap(test.uv[matched] - ref.uv[matched], wrap_uv)
        res = dict(covered_ref=covered, covered_test=int((kt >= 0).sum()), mismatch=mismatch,
                   mismatch_frac=mismatch / covered if covered else float("nan"), matched=int(matched.sum()))
        res["uv_texel"] = _stats(np.linalg.norm(d_uv, axis=-1) * texture_size)
        if grad is not None:
            J = grad[matched]
            good = np.all(np.isfinite(J), axis=(1, 2)) & np.all(np.isfinite(d_uv), axis=1)
            det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
            good &= np.abs(det) > 0
            px = np.full(len(J), np.nan)
            if good.any():
                px[good] = np.linalg.norm(np.linalg.solve(J[good], d_uv[good][..., None])[..., 0], axis=1)
            res["uv_px"] = _stats(px)
            res["uv_px_n"] = int(np.isfinite(px).sum())
        else:
            res["uv_px"], res["uv_px_n"] = _stats([]), 0
        with np.errstate(invalid="ignore", divide="ignore"):
            lt = np.abs(test.light_time[matched] - ref.light_time[matched]) / ref.light_time[matched]
        res["lt_rel"] = _stats(lt)
        if image_pixels is not None:
            err = np.concatenate([screen[k] for k in sel])
            res["screen_px"] = _stats(err)
            res["screen_px_n"] = int(np.isfinite(err).sum())
        if other_surface is not None:
            far = np.linalg.norm(test.point[matched] - ref.point[matched], axis=-1) > other_surface
            res["other_surface"] = int(np.count_nonzero(far))
        out["orders"][o] = res
    return out


CHECKER_SIZE = np.radians(10.0)
"""Size of the checks of :func:`checker` (rad): 10 degrees in longitude and latitude."""


def checker(directions, size: float = CHECKER_SIZE) -> np.ndarray:
    """The checkered world: (N,) int, 0 or 1 per unit world direction (N, 3), the parity of
    floor(longitude / size) + floor(latitude / size), longitude atan2(y, x) and latitude asin(z) about
    the world z axis (rad); -1 for non-finite directions (no sky)."""
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    ok = np.all(np.isfinite(d), axis=1)
    with np.errstate(invalid="ignore"):
        lon = np.arctan2(d[:, 1], d[:, 0])
        lat = np.arcsin(np.clip(d[:, 2] / np.linalg.norm(d, axis=1), -1.0, 1.0))
        k = np.floor(lon / size) + np.floor(lat / size)
    return np.where(ok, np.mod(np.nan_to_num(k), 2), -1).astype(np.int64)


def angle_between(a, b) -> np.ndarray:
    """Angle (rad) between direction vectors a and b (..., 3) (atan2 of |a x b| and a . b: accurate
    for tiny angles); NaN where either is NaN."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.einsum("...k,...k->...", a, b))


def checker_parity(uv, cells: int) -> np.ndarray:
    """(S,) int: the checker cell's colour (0 or 1) of the UVs ``uv`` (S, 2) with ``cells`` cells per
    unit of U and of V; -1 where the UV is not finite."""
    with np.errstate(invalid="ignore"):
        c = np.floor(np.asarray(uv, np.float64) * cells)
        ok = np.isfinite(c).all(axis=-1)
        return np.where(ok, np.mod(np.nan_to_num(c[..., 0]) + np.nan_to_num(c[..., 1]), 2), -1).astype(np.int64)


def checker_torn(ref, test, cells: int, orders=(1, 2)) -> dict:
    """The checker texture measure of the module docstring between ``ref`` and ``test`` (buffers of
    shape (height, width)): {"matched": pixels both show the same object in the same order, "wrong":
    those of the other checker colour, "torn": those wrong more than a pixel from every checker edge
    and silhouette of the reference}."""
    kr, kt = pixel_keys(ref, orders), pixel_keys(test, orders)
    pr, pt = checker_parity(ref.uv, cells), checker_parity(test.uv, cells)
    both = (kr == kt) & (kr >= 0) & (pr >= 0) & (pt >= 0)
    wrong = both & (pr != pt)
    h, w = kr.shape
    with np.errstate(invalid="ignore"):  # the reference's cell (not only its colour: cells under a pixel)
        cell = np.nan_to_num(np.floor(np.asarray(ref.uv, np.float64) * cells), nan=-1.0)
    kp = np.pad(kr, 1, constant_values=-2)
    cp = np.pad(cell, ((1, 1), (1, 1), (0, 0)), constant_values=-2.0)
    inside = np.ones((h, w), bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            win = (slice(1 + dy, 1 + dy + h), slice(1 + dx, 1 + dx + w))
            inside &= (kp[win] == kr) & (cp[win] == cell).all(axis=-1)
    return {"matched": int(both.sum()), "wrong": int(wrong.sum()), "torn": int((wrong & inside).sum())}


def compare_sky(ref, sky, pixel_angle: float, rays=None, checker_size: float = CHECKER_SIZE) -> dict:
    """A lensed-sky model against the reference's sky (see the module docstring).

    ref: the reference :class:`raytrace.PixelBuffers` (shape S); sky: (S, 3) the model's unit world
    directions at infinity per pixel (NaN: the model says the ray falls in); pixel_angle: rad per pixel
    (``Camera.pixel_angle``); rays: (S,) bool, the pixels that have a ray (default all; a fisheye's
    pixels outside its circle have none). Compared are the pixels with a ray that meets no object in
    the reference (``compared``). Returns sky_angle_px (p50, p99, max) and sky_angle_n over the pixels
    where both say the ray escapes; shadow_mismatch (pixels where exactly one says it falls in),
    fell_ref, fell_test; checker_mismatch (escaping pixels whose :func:`checker` values differ),
    checker_edge (reference pixels with a right or lower neighbour, both escaping, of the other
    checker value: the length of the checker edges in pixels) and checker_per_edge (their ratio, NaN
    without edges)."""
    sky = np.asarray(sky, np.float64).reshape(ref.shape + (3,))
    rays = np.ones(ref.shape, bool) if rays is None else np.asarray(rays, bool)
    cmp_ = rays & ~ref.hit
    fell_ref = cmp_ & ref.fell
    fell_test = cmp_ & ~np.all(np.isfinite(sky), axis=-1)
    both = cmp_ & ~fell_ref & ~fell_test
    ang = angle_between(ref.sky[both], sky[both]) / pixel_angle
    out = {"compared": int(cmp_.sum()), "sky_angle_px": _stats(ang), "sky_angle_n": int(np.isfinite(ang).sum()),
           "shadow_mismatch": int((fell_ref != fell_test).sum()), "fell_ref": int(fell_ref.sum()),
           "fell_test": int(fell_test.sum())}
    esc_ref = cmp_ & ~fell_ref
    c_ref = np.where(esc_ref, checker(ref.sky.reshape(-1, 3), checker_size).reshape(ref.shape), -1)
    c_test = np.where(both, checker(sky.reshape(-1, 3), checker_size).reshape(ref.shape), -1)
    out["checker_mismatch"] = int((both & (c_ref != c_test)).sum())
    edge = np.zeros(ref.shape, bool)
    if len(ref.shape) == 2:
        edge[:, :-1] |= (c_ref[:, :-1] >= 0) & (c_ref[:, 1:] >= 0) & (c_ref[:, :-1] != c_ref[:, 1:])
        edge[:-1, :] |= (c_ref[:-1, :] >= 0) & (c_ref[1:, :] >= 0) & (c_ref[:-1, :] != c_ref[1:, :])
    out["checker_edge"] = int(edge.sum())
    out["checker_per_edge"] = out["checker_mismatch"] / out["checker_edge"] if out["checker_edge"] else float("nan")
    return out


def sky_error_px(ref, sky, pixel_angle: float) -> np.ndarray:
    """(S,) per pixel the angle (pixels of ``pixel_angle``) between the reference's sky and the model's
    ``sky`` (S, 3), NaN where either has none (hit, fell in, no ray)."""
    sky = np.asarray(sky, np.float64).reshape(ref.shape + (3,))
    return angle_between(ref.sky, sky) / pixel_angle


def markdown_rows(metrics: dict, label: str = "") -> list[str]:
    """Markdown table rows (one per order) of :func:`compare`'s result; header in
    :data:`MARKDOWN_HEADER`."""
    rows = []
    for o, m in metrics["orders"].items():
        sc = m.get("screen_px", _stats([]))
        rows.append(
            f"| {label} | {o} | {m['covered_ref']} | {m['covered_test']} | {m['mismatch']} | "
            f"{100 * m['mismatch_frac']:.2f}% | {sc['p50']:.3f} | {sc['p99']:.3f} | {sc['max']:.2f} | "
            f"{m['uv_px']['p50']:.3f} | {m['uv_px']['p99']:.3f} | "
            f"{m['uv_px']['max']:.2f} | {m['uv_texel']['p99']:.2f} | {m['lt_rel']['p50']:.1e} | "
            f"{m['lt_rel']['p99']:.1e} | {m['lt_rel']['max']:.1e} |")
    return rows


MARKDOWN_HEADER = [
    "| case | order | covered (ref) | covered (test) | mismatch | mismatch / covered | screen err p50 [px] | "
    "p99 | max | UV err via J p50 [px] | p99 | max | UV err p99 [texel] | c*dt rel. err p50 | p99 | max |",
    "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
]
"""Columns of :func:`markdown_rows`: screen err is ``screen_px`` (nan without ``image_pixels``), UV err
via J is ``uv_px``."""


# --------------------------------------------------------------------------------------------------
# Debug pictures
# --------------------------------------------------------------------------------------------------
def to_rgb(buf, field: str) -> np.ndarray:
    """(H, W, 3) float image in [0, 1] of one buffer field: "order" (1 blue-ish, 2 orange, 3+ red,
    fell-in black, background dark grey), "uv" (u red, v green), "light_time" (normalised grey),
    "object_id" (a colour per object)."""
    H, W = buf.shape
    img = np.full((H, W, 3), 0.15)
    if field == "order":
        cols = {1: (0.3, 0.6, 1.0), 2: (1.0, 0.6, 0.1)}
        for o, c in cols.items():
            img[buf.hit & (buf.order == o)] = c
        img[buf.hit & (buf.order >= 3)] = (1.0, 0.1, 0.1)
        img[buf.fell] = 0.0
    elif field == "uv":
        uv = np.nan_to_num(buf.uv, nan=0.0) % 1.0
        img[buf.hit] = np.stack([uv[..., 0], uv[..., 1], np.full(uv.shape[:2], 0.3)], -1)[buf.hit]
    elif field == "light_time":
        lt = buf.light_time
        if np.isfinite(lt).any():
            lo, hi = np.nanmin(lt), np.nanmax(lt)
            g = (lt - lo) / (hi - lo if hi > lo else 1.0)
            img[buf.hit] = np.stack([g, g, g], -1)[buf.hit] * 0.8 + 0.2
    elif field == "object_id":
        rng = np.random.default_rng(7)
        pal = rng.uniform(0.3, 1.0, (64, 3))
        img[buf.hit] = pal[buf.object_id[buf.hit] % 64]
    else:
        raise ValueError(f"unknown field {field!r}")
    return img


def save_png(path, buffers: dict, fields=("order", "uv", "light_time")) -> None:
    """A grid of pictures (rows: the named buffers of ``buffers`` {name: PixelBuffers}, columns:
    ``fields``), plus a column of coverage differences to the first buffer, written to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(buffers)
    ref = buffers[names[0]]
    ncol = len(fields) + (1 if len(names) > 1 else 0)
    H, W = ref.shape
    fig, axes = plt.subplots(len(names), ncol, figsize=(3.2 * ncol * W / max(H, 1) / 1.6, 2.2 * len(names)),
                             squeeze=False)
    for i, n in enumerate(names):
        b = buffers[n]
        for j, f in enumerate(fields):
            axes[i, j].imshow(to_rgb(b, f), interpolation="nearest")
            axes[i, j].set_title(f"{n}: {f}", fontsize=8)
        if ncol > len(fields):
            axes[i, -1].imshow(diff_rgb(ref, b), interpolation="nearest")
            axes[i, -1].set_title(f"{n} vs {names[0]}", fontsize=8)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def diff_rgb(ref, test) -> np.ndarray:
    """(H, W, 3) picture of coverage differences: grey where both agree on (object, order), red where
    only the reference shows it, green where only the test does, yellow where they show different
    (object, order)s."""
    kr, kt = pixel_keys(ref, [1, 2, 3, 4, 5, 6, 7, 8]), pixel_keys(test, [1, 2, 3, 4, 5, 6, 7, 8])
    img = np.full(ref.shape + (3,), 0.1)
    img[(kr >= 0) & (kr == kt)] = 0.45
    img[(kr >= 0) & (kt < 0)] = (1.0, 0.1, 0.1)
    img[(kr < 0) & (kt >= 0)] = (0.1, 1.0, 0.1)
    img[(kr >= 0) & (kt >= 0) & (kr != kt)] = (1.0, 1.0, 0.1)
    return img
