"""Triangle corners of a polygon mesh from Blender's fast arrays, without its slow per-triangle API.

Blender triangulates a mesh into loop triangles; reading their corners (``loop_triangles.foreach_get
("loops")``) costs about 70 ns per triangle, while the triangle-to-polygon map
(``Mesh.loop_triangle_polygons``) and the corner-to-vertex map (the ``.corner_vert`` attribute) read
at memory speed. Loop triangles are stored polygon by polygon, n - 2 per polygon of n corners, so for
meshes of triangles and quads the corners follow from these two arrays: a triangle is its own
corners, a quad is split on its 0-2 diagonal, or on the 1-3 diagonal when it is folded over the 0-2
one (as Blender does). Meshes with n-gons (more than four corners) need Blender's own polygon fill:
:func:`tri_corners` returns None for them and the caller falls back to the slow API.

Indices only; no units.
"""
from __future__ import annotations

import numpy as np


def tri_corners(tri_poly, n_polys, corner_vert, positions):
    """Corner (loop) indices (T, 3) of the loop triangles, or None if some polygon has more than four
    corners.

    tri_poly (T,): the polygon of each loop triangle (non-decreasing, n - 2 per polygon of n corners);
    n_polys: number of polygons; corner_vert (L,): the vertex of each corner; positions (V, 3): vertex
    positions in any consistent frame (only to decide how quads are split)."""
    tri_poly = np.asarray(tri_poly, dtype=np.int64)
    n_t = len(tri_poly)
    per_poly = np.bincount(tri_poly, minlength=n_polys) if n_t else np.zeros(n_polys, np.int64)
    if n_t and per_poly.max() > 2:
        return None
    sizes = per_poly + 2  # corners per polygon (every polygon has at least one triangle)
    loop_start = np.zeros(n_polys, dtype=np.int64)
    np.cumsum(sizes[:-1], out=loop_start[1:])
    if n_polys and loop_start[-1] + sizes[-1] != len(corner_vert):
        return None  # not the layout assumed above: let Blender say
    start = loop_start[tri_poly]
    k = np.arange(n_t) - (start - 2 * tri_poly)  # 0 for the first triangle of a polygon, 1 for the second
    out = np.stack([start, start + k + 1, start + k + 2], axis=1)
    quads = np.flatnonzero(sizes == 4)
    if quads.size:
        s = loop_start[quads]
        p = np.asarray(positions, dtype=np.float64)
        v0, v1, v2, v3 = (p[corner_vert[s + i]] for i in range(4))
        # folded over the 0-2 diagonal: the two halves face opposite ways
        d, a, b = v2 - v0, v1 - v0, v3 - v0
        flip = _dot_of_crosses(a, d, d, b) < 0
        if flip.any():
            first = s[flip] - 2 * quads[flip]  # index of the quad's first triangle
            q = s[flip]
            out[first] = np.stack([q, q + 1, q + 3], axis=1)
            out[first + 1] = np.stack([q + 1, q + 2, q + 3], axis=1)
    return out


def _dot_of_crosses(a, b, c, d) -> np.ndarray:
    """(N,) (a x b) . (c x d) of rows (N, 3), by components (np.cross is several times slower on long
    arrays); the Binet-Cauchy identity would cancel more, so the crosses are formed as they are."""
    def cross(u, v):
        return (u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1], u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2],
                u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    x0, x1, x2 = cross(a, b)
    y0, y1, y2 = cross(c, d)
    return x0 * y0 + x1 * y1 + x2 * y2
