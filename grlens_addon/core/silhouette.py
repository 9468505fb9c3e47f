"""The silhouette of a lensed image: the source edges along which the surface turns from facing the
camera to facing away, seen along the connecting rays of one order.

The outline of an image on screen is made of the images of these edges and of the mesh's boundary
edges: everywhere else a triangle's image borders another's, so where their shared edge is drawn
does not change which pixels are covered. Coverage therefore follows the silhouette's straight
pieces, and the pipeline subdivides these edges to a tighter screen-space tolerance
(budget.COVERAGE_FACTOR).

A source triangle with geometric normal n (from its winding) faces the camera at a corner when
n . d > 0, with d the direction in which that corner's connecting ray leaves it
(illumination.leaving_direction). Lensing bends d, so the silhouette of order 2 differs from the
one a straight line of sight would give. Units: positions in Blender units; d is a unit vector.
"""
from __future__ import annotations

import numpy as np

from .observer_view import row_norm, used_vertices


def compact(points, tris):
    """(corners, corner points, local tris): the vertex indices that the triangles ``tris`` (T, 3) use
    (sorted), their ``points``, and ``tris`` re-indexed into them, so that the functions below (and the
    rays they need) run on those corners only."""
    tris = np.asarray(tris, dtype=np.int64)
    corners = used_vertices(tris, len(points))  # (a mask, not a sort: dense meshes pass every triangle)
    index = np.empty(len(points), np.int64)
    index[corners] = np.arange(corners.size)
    return corners, points.take(corners, axis=0), index.take(tris)


def normals(points, tris) -> np.ndarray:
    """(T, 3) geometric normals (p1 - p0) x (p2 - p0) of the triangles ``tris`` (T, 3) of ``points``
    (BU^2, not normalised; right-handed with the winding)."""
    tris = np.asarray(tris, dtype=np.int64)
    p0, p1, p2 = (points.take(tris[:, k], axis=0) for k in range(3))
    a, b = p1 - p0, p2 - p0
    out = np.empty_like(a)  # the cross product, by components (np.cross is several times slower)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def facing_signs(points, tris, directions) -> np.ndarray:
    """(T, 3) sign of n . d at each corner of the triangles ``tris`` (T, 3) of ``points`` (N, 3; BU),
    with ``directions`` (N, 3) the vertices' leaving directions d: +1 facing, -1 facing away, 0 on the
    silhouette or without a ray (NaN)."""
    tris = np.asarray(tris, dtype=np.int64)
    n = normals(points, tris)
    with np.errstate(invalid="ignore"):
        dots = np.einsum("fx,fcx->fc", n, directions.take(tris, axis=0))
    return np.sign(np.nan_to_num(dots, nan=0.0))


def turned_away(points, tris, directions, margin: float) -> np.ndarray:
    """(T,) bool: triangles ``tris`` of ``points`` (BU) turned away from the camera along the rays by
    more than ``margin``: n . d < -margin at all three corners, with n the unit geometric normal and
    ``directions`` (N, 3) the vertices' unit leaving directions d (so n . d is the cosine of the angle
    between them). A corner without a ray (NaN) is not turned away."""
    tris = np.asarray(tris, dtype=np.int64)
    n = normals(points, tris)
    with np.errstate(invalid="ignore", divide="ignore"):
        n /= row_norm(n)[:, None]
        dots = np.einsum("fx,fcx->fc", n, directions.take(tris, axis=0))
        return (dots < -margin).all(axis=1)


def silhouette(points, tris, of_tri, n_edges, directions) -> tuple[np.ndarray, np.ndarray]:
    """(edge mask (E,), triangle mask (T,)) of the silhouette.

    An edge is on it when its triangles do not all face the same way (one facing, one facing away),
    when it borders a triangle that is itself split (corners of both signs, or a corner on the
    silhouette), or when it is a boundary edge (one triangle). A triangle is on it when one of its
    edges is. ``of_tri`` (T, 3): the edge index of each triangle side (subdivision.Edges.of_tri);
    ``directions``: see :func:`facing_signs`."""
    of_tri = np.asarray(of_tri, dtype=np.int64)
    sign = facing_signs(points, tris, directions)
    split = (sign != sign[:, :1]).any(axis=1) | (sign[:, 0] == 0)
    face = np.where(split, 0, sign[:, 0]).astype(np.int8)
    e = of_tri.ravel()
    f = np.repeat(face, 3)
    lo = np.full(n_edges, 2, np.int8)
    hi = np.full(n_edges, -2, np.int8)
    np.minimum.at(lo, e, f)
    np.maximum.at(hi, e, f)
    uses = np.bincount(e, minlength=n_edges)
    edge = (lo != hi) | (lo == 0) | (uses == 1)
    return edge, edge.take(of_tri).any(axis=1)
