"""Culling: which image triangles to drop, and why (counted, so the UI can report them).

Seed 000, section 3.2: a triangle that straddles the observer-hole axis is mapped onto both sides of
the hole (its images belong to an Einstein ring, which a mesh cannot show); it is recognised by the
ratio of the circumference of its image to that of the undistorted triangle, both measured as
chords on the camera's unit view sphere (dimensionless, so independent of the camera's lens). Triangles with a
vertex without an image (outside the LUT's radial range, inside the horizon, non-finite, exactly on
the axis) are dropped, as are triangles entirely outside the camera frustum and triangles whose
source is degenerate (zero circumference).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class CullReport:
    """Numbers of triangles dropped per reason (a triangle is counted under its first reason)."""

    invalid_vertex: int = 0
    degenerate_source: int = 0
    einstein_ring: int = 0
    outside_frustum: int = 0
    below_pixel: int = 0  # whole image smaller than a pixel: not built
    kept: int = 0
    extra: dict = field(default_factory=dict)

    def total_culled(self) -> int:
        return (self.invalid_vertex + self.degenerate_source + self.einstein_ring + self.outside_frustum
                + self.below_pixel)


def _circumference(d, tris):
    """Perimeter of each triangle on the unit view sphere, as the sum of its corners' chord lengths
    (dimensionless; equal to the sum of the angles in radians to second order for small triangles)."""
    a, b, c = d[tris[:, 0]], d[tris[:, 1]], d[tris[:, 2]]

    def chord(u, v):
        w = u - v
        return np.sqrt(np.einsum("ij,ij->i", w, w))

    return chord(a, b) + chord(b, c) + chord(c, a)


def unit_directions(points, camera):
    """Unit vectors from ``camera`` (3,) to ``points`` (N, 3) (BU); NaN for the camera itself."""
    v = np.asarray(points, dtype=np.float64) - camera
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / np.linalg.norm(v, axis=1)[:, None]


def cull(tris, image_dirs, valid, source_points, camera, cull_ratio, frustum_planes=None, image_points=None):
    """Mask of image triangles to keep, and a :class:`CullReport`.

    tris (F, 3) index the per-vertex arrays: image_dirs (V, 3) unit apparent directions of the images,
    valid (V,) bool, source_points (V, 3) the undistorted world positions (BU). ``cull_ratio``: drop a
    triangle whose image circumference exceeds cull_ratio times the undistorted one (seed 000 uses a
    customisable threshold; larger keeps more). ``frustum_planes`` (K, 4): rows (n, d) with
    n . x + d >= 0 inside, applied to ``image_points`` (V, 3).
    """
    tris = np.asarray(tris, dtype=np.int64)
    rep = CullReport()
    keep = np.ones(len(tris), dtype=bool)
    bad_v = ~valid[tris].all(axis=1)
    rep.invalid_vertex = int(bad_v.sum())
    keep &= ~bad_v
    src_c = _circumference(unit_directions(source_points, camera), tris)
    degenerate = keep & ~(src_c > 0)
    rep.degenerate_source = int(degenerate.sum())
    keep &= ~degenerate
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = _circumference(image_dirs, tris) / src_c
    ring = keep & ~(ratio <= cull_ratio)
    rep.einstein_ring = int(ring.sum())
    keep &= ~ring
    if frustum_planes is not None and image_points is not None and len(frustum_planes):
        pl = np.asarray(frustum_planes, dtype=np.float64)
        side = image_points @ pl[:, :3].T + pl[:, 3]  # (V, K)
        with np.errstate(invalid="ignore"):
            outside = (side[tris] < 0).all(axis=1).any(axis=1)  # all 3 corners behind one plane
        out = keep & outside
        rep.outside_frustum = int(out.sum())
        keep &= ~outside
    rep.kept = int(keep.sum())
    return keep, rep
