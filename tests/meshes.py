"""Test meshes shared by several test modules (pytest puts this folder on sys.path)."""
import numpy as np

from grlens_addon.core.pipeline import SourceMesh


def uv_sphere(centre, radius, segments, rings):
    """A UV sphere (poles on z) with outward winding: (points (N, 3), triangles (T, 3))."""
    th = np.linspace(0, np.pi, rings + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    ring = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    pts = np.vstack([[0, 0, 1], ring, [0, 0, -1]]) * radius + np.asarray(centre, float)
    idx = lambda i, j: 1 + i * segments + (j % segments)  # noqa: E731
    tris = [(0, idx(0, j), idx(0, j + 1)) for j in range(segments)]
    for i in range(rings - 2):
        for j in range(segments):
            tris += [(idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)), (idx(i, j), idx(i + 1, j + 1), idx(i, j + 1))]
    tris += [(len(pts) - 1, idx(rings - 2, j + 1), idx(rings - 2, j)) for j in range(segments)]
    return pts, np.array(tris)


def grid(a0, a1, b0, b1, na, nb, normal="z", c=0.0):
    """A plane of na x nb quads (two triangles each) spanning [a0, a1] x [b0, b1] at ``normal`` = c
    (BU), with UVs over [0, 1]^2."""
    u, v = np.meshgrid(np.linspace(0, 1, na + 1), np.linspace(0, 1, nb + 1), indexing="ij")
    a, b = a0 + (a1 - a0) * u, b0 + (b1 - b0) * v
    cols = {"z": (a, b, np.full_like(a, c)), "y": (a, np.full_like(a, c), b), "x": (np.full_like(a, c), a, b)}
    pts = np.stack(cols[normal], -1).reshape(-1, 3)
    i, j = (m.ravel() for m in np.meshgrid(np.arange(na), np.arange(nb), indexing="ij"))
    k = lambda i, j: i * (nb + 1) + j  # noqa: E731
    tris = np.concatenate([np.stack([k(i, j), k(i + 1, j), k(i + 1, j + 1)], 1),
                           np.stack([k(i, j), k(i + 1, j + 1), k(i, j + 1)], 1)])
    return SourceMesh(pts, tris, corner_uv=np.stack([u, v], -1).reshape(-1, 2)[tris])


def cube(centre, size):
    """A cube of edge ``size`` (BU) at ``centre``: six faces of 4 x 4 quads."""
    c, h = np.asarray(centre, float), size / 2
    faces = []
    for axis in "xyz":
        for s in (-1, 1):
            o = {"x": 0, "y": 1, "z": 2}[axis]
            rest = [i for i in range(3) if i != o]
            g = grid(c[rest[0]] - h, c[rest[0]] + h, c[rest[1]] - h, c[rest[1]] + h, 4, 4, axis, c[o] + s * h)
            faces.append(g)
    n = 0
    pts, tris, uv = [], [], []
    for f in faces:
        pts.append(f.positions), tris.append(f.tris + n), uv.append(f.corner_uv)
        n += len(f.positions)
    return SourceMesh(np.vstack(pts), np.vstack(tris), corner_uv=np.vstack(uv))
