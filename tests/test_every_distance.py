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
from meshes import cube, grid

R_OBS = 20.0


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
