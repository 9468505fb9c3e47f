"""A camera that moves, seen for the first time, with one orbit table for every radius (lutgen.rays, the
add-on's lut_mode ONE_TABLE): no table is built per radius on any frame (counted, not timed: the time
per frame against a static camera is benchmarks/bench_moving.py's, docs/tables.md), and a frame
computed alone gives the same geometry, bit for bit, as in a run, whatever was computed before it.

Units: r_s = 1 BU; the paper's sphere (radius 0.5 r_s) on its 3 r_s orbit; the camera descends from 6 to
1.05 r_s (inside the photon sphere for the last frames).
"""
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))

from bench_frame import uv_sphere  # noqa: E402
from grlens_addon.core import mapping, pipeline  # noqa: E402
from lutgen import rays  # noqa: E402

SETTINGS = pipeline.Settings(max_tess_level=64, tess_a=5.0, tess_b=0.75, cull_ratio=8.0,
                             pixel_angle=math.radians(40.0) / 360)
RADII = np.linspace(6.0, 1.05, 6)


def _frame(i, r):
    pts, tris = uv_sphere(radius=0.5)
    a = math.radians(60.0 + 7.0 * i)
    src = pipeline.SourceMesh(pts + np.array([3 * math.cos(a), 3 * math.sin(a), 0.4]), tris)
    return src, mapping.Scene([float(r), 0.0, 0.3], [0.0, 0.0, 0.0], 1.0)


def _geometry(out):
    return {o: (m.positions.copy(), m.tris.copy()) for o, m in out.items()}


def test_no_table_per_radius_and_alone_equals_in_a_run(monkeypatch):
    table = rays.orbit_table()
    builds = []
    real = rays.build_kind
    monkeypatch.setattr(rays, "build_kind", lambda *a, **k: builds.append(a) or real(*a, **k))
    run = []
    for i, r in enumerate(RADII):
        src, scene = _frame(i, r)
        run.append(_geometry(pipeline.build_images(src, scene, rays.RayMap(scene.r_obs, table=table), SETTINGS)))
    assert builds == []  # every radius, inside the photon sphere too, from the one table
    assert sum(len(t) for g in run for _, t in g.values()) > 0
    for i in (len(RADII) - 1, 2):  # alone, in another order, after other radii
        src, scene = _frame(i, RADII[i])
        alone = _geometry(pipeline.build_images(src, scene, rays.RayMap(scene.r_obs, table=table), SETTINGS))
        assert alone.keys() == run[i].keys()
        for o in alone:
            assert np.array_equal(alone[o][0], run[i][o][0], equal_nan=True)
            assert np.array_equal(alone[o][1], run[i][o][1])


def test_a_new_radius_costs_one_dimensional_arrays():
    """What a new camera radius makes: the observer's phase on each ray (a few 1-D arrays of a few
    thousand numbers), not a table (the orbit table is shared by every radius)."""
    table = rays.orbit_table()
    m = rays.RayMap(2.345, table=table)
    own = m.node_theta.nbytes + m.node_j.nbytes + m.row_g.nbytes + m.row_d.nbytes + m.row_theta.nbytes + \
        m.row_b.nbytes + m.row_start.nbytes + m.row_length.nbytes + m.row_eps.nbytes
    assert own < 0.01 * table.nbytes
    assert m.table is table
