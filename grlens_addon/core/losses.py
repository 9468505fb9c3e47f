"""Which source triangles cannot be imaged, and why (for the add-on's report; numpy only).

The pipeline drops an image triangle whose vertex has no image (``CullReport.invalid_vertex``) and a
source triangle with non-finite corners (``extra["bad_source_triangles"]``), counting pieces of the
subdivided mesh. The user thinks in source triangles and wants the reason: this module sorts the
source triangles with a corner that cannot be mapped by the first reason that applies,

    non_finite   a corner coordinate is NaN or infinite
    horizon      a corner inside the event horizon (r <= 1 r_s)
    below_table  a corner between the horizon and the lookup table's inner radius (1 < r < r_min)
    beyond_table a corner beyond the lookup table's outer radius (r > r_max)
    no_ray       a corner in the table's range without an image of some order (should not happen)

using the mapping the pipeline uses (:func:`mapping.map_vertices_orders`: whatever it can map counts
as imaged). A corner exactly on the observer-hole axis has no image either, but that is expected (its
image is the Einstein ring, drawn by the axis patches or culled like the ring): such triangles are
counted apart, in ``on_axis``. Of a source triangle that is subdivided, the pieces away from its
unmappable corner may still be imaged; the counts are of source triangles with such a corner.

Units: positions in Blender units (BU), radii in r_s.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import mapping

REASONS = ("non_finite", "horizon", "below_table", "beyond_table", "no_ray")
"""Reasons a source triangle is not imaged, in the order they are tested (the first one counts)."""


@dataclass
class Unimaged:
    """Source triangles not imaged: ``total`` triangles, ``lost`` of them with a corner that cannot
    be mapped, ``by_reason`` {reason: count} (keys of REASONS, only those that occur), ``on_axis``
    triangles with a corner on the observer-hole axis (expected, not in ``lost``), and the radial
    range of the table used (r_s)."""

    total: int
    lost: int = 0
    by_reason: dict = field(default_factory=dict)
    on_axis: int = 0
    r_min: float = float("nan")
    r_max: float = float("nan")


def unimaged_triangles(positions, tris, scene: mapping.Scene, lut, orders=(1, 2)) -> Unimaged:
    """Sort the triangles ``tris`` (T, 3) of the world-space points ``positions`` (N, 3; BU) by why
    they cannot be imaged for the ``orders`` seen from ``scene.camera`` with ``lut`` (see the module
    docstring)."""
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    tris = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    r_min, r_max = float(getattr(lut, "r_min", np.nan)), float(getattr(lut, "r_max", np.nan))
    out = Unimaged(total=len(tris), r_min=r_min, r_max=r_max)
    if not len(tris) or not len(pos):
        return out
    images = mapping.map_vertices_orders(pos, scene, lut, tuple(orders))
    plane = next(iter(images.values())).plane
    valid = np.logical_and.reduce([im.valid for im in images.values()])
    finite = np.isfinite(pos).all(axis=1)
    r = plane.r
    bad = ~valid
    # vertex classes: 0 imaged, 1..5 the REASONS in order, 6 on the axis (and in the table's range)
    cls = np.zeros(len(pos), dtype=np.int8)
    with np.errstate(invalid="ignore"):
        cls[bad] = 5
        cls[bad & plane.on_axis] = 6
        cls[bad & (r > r_max)] = 4
        cls[bad & (r < r_min)] = 3
        cls[bad & (r <= 1.0)] = 2
    cls[~finite] = 1
    corner = cls.take(tris)
    first = np.where(corner == 0, 127, corner).min(axis=1)  # the first reason among the corners
    counts = np.bincount(first[first < 127], minlength=7)
    out.by_reason = {REASONS[k - 1]: int(counts[k]) for k in range(1, 6) if counts[k]}
    out.lost = int(counts[1:6].sum())
    out.on_axis = int(counts[6])
    return out


def describe(u: Unimaged) -> str:
    """The reasons of :func:`unimaged_triangles` in words, e.g. "12 beyond the lookup table's range,
    r > 40 r_s; 2 inside the horizon, r <= 1 r_s"."""
    words = {
        "non_finite": "with non-finite coordinates",
        "horizon": "inside the horizon, r <= 1 r_s",
        "below_table": f"inside the lookup table's inner radius, r < {u.r_min:.4g} r_s",
        "beyond_table": f"beyond the lookup table's range, r > {u.r_max:.4g} r_s",
        "no_ray": "without a connecting ray",
    }
    return "; ".join(f"{n} {words[k]}" for k, n in u.by_reason.items())
