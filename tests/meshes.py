"""Test meshes shared by several test modules (pytest puts this folder on sys.path)."""
import numpy as np


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
