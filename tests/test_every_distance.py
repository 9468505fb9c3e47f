"""Geometry at every distance against the reference ray tracer (core.raytrace), with the default
tables (a lutgen.LUTFamily reaching infinity): a floor to 150 r_s behind the hole, a wall beside the
camera, a floor under the camera, and a cube 75 r_s away (no bpy).

Units: BU with r_s = 1; camera at 20 r_s; 160x90 pixels. Targets as in docs/accuracy.md: coverage
mismatch under 0.5% of the covered pixels and screen error p99 under 0.5 px.
"""
import math

import numpy as np
import pytest

from grlens_addon.core import frame_check, mapping, pipeline, raytrace
from lutgen import LUTFamily, build_lut

R_OBS = 20.0


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
    return pipeline.SourceMesh(pts, tris, corner_uv=np.stack([u, v], -1).reshape(-1, 2)[tris])


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
    return pipeline.SourceMesh(np.vstack(pts), np.vstack(tris), corner_uv=np.vstack(uv))


SCENES = {  # name: (source, camera target (BU), vertical field of view (deg))
    "floor to 150 r_s behind the hole": (lambda: grid(-150, 15, -40, 40, 66, 32, "z", -3.0), (0, 0, 0), 60),
    "wall beside the camera": (lambda: grid(12, 28, -4, 4, 32, 16, "y", 3.0), (17, 3, -0.5), 70),
    "floor under the camera": (lambda: grid(8, 40, -12, 12, 32, 24, "z", -2.0), (15, 0, -2), 80),
    "cube 75 r_s away": (lambda: cube((-70, 20, 18), 6.0), "image", 15),  # seen 20 deg from where it is
}


@pytest.fixture(scope="module")
def family():
    return LUTFamily()


@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_distance_matches_the_reference(family, name):
    make, target, fov = SCENES[name]
    src = make()
    camera = np.array([R_OBS, 0.0, 0.0])
    scene = mapping.Scene(camera, np.zeros(3), 1.0)
    if target == "image":  # look where the source's first-order image is
        target = mapping.map_vertices(src.positions.mean(axis=0)[None], scene, family.at(R_OBS), 1).position[0]
    cam = raytrace.Camera.look_at(camera, target, math.radians(fov), 160, 90)
    check = frame_check.check_frame([src], scene, family.at(R_OBS), pipeline.Settings(64, 5.0, 0.75, 8.0), cam)
    m = check.metrics["orders"]["all"]
    assert m["covered_ref"] > 500, name
    assert m["mismatch_frac"] < 0.005, (name, check.summary())
    assert m["screen_px"]["p99"] < 0.5, (name, check.summary())


def test_the_former_fixed_range_table_drops_the_far_floor():
    """The reason for the family: with the former default table (r <= 40 r_s) most of the far floor
    is missing (so the test above can fail)."""
    make, target, fov = SCENES["floor to 150 r_s behind the hole"]
    cam = raytrace.Camera.look_at([R_OBS, 0.0, 0.0], target, math.radians(fov), 160, 90)
    scene = mapping.Scene(cam.position, np.zeros(3), 1.0)
    check = frame_check.check_frame([make()], scene, build_lut(R_OBS, 1.05, 40.0, 128, 256),
                                    pipeline.Settings(64, 5.0, 0.75, 8.0), cam)
    assert check.metrics["orders"]["all"]["mismatch_frac"] > 0.05
