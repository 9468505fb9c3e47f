"""The Luminet thin-disc sample scene (sample_scenes/luminet.py) on the pip bpy module: the images
carry the expected physics (seed 002): the far side of the disc is seen above the shadow, the
approaching side is blueshifted and brighter, the ghost (order-2) image hugs the shadow."""
import math
import os
import sys

import numpy as np
import pytest

import bpy

import grlens_addon
from lutgen.solver import shadow_half_angle

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "sample_scenes"))
import luminet  # noqa: E402


@pytest.fixture(scope="module", autouse=True)
def registered():
    grlens_addon.register()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    yield
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)


def _read(obj):
    me = obj.data
    n = len(me.vertices)
    pos = np.empty(3 * n, np.float32)
    me.vertices.foreach_get("co", pos)
    z = np.empty(n, np.float32)
    me.attributes["grlens_redshift"].data.foreach_get("value", z)
    col = np.empty(4 * n, np.float32)
    me.attributes["grlens_disc_colour"].data.foreach_get("color", col)
    return pos.reshape(-1, 3), z, col.reshape(-1, 4)[:, :3]


def test_luminet_disc_images():
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 320, 180
    luminet.luminet_disc(scene)
    cam = np.array(scene.camera.location)
    shadow = float(shadow_half_angle(luminet.R_OBS))
    for order in (1, 2):
        pos, z, col = _read(bpy.data.objects[f"ThinDisc.GR{order}"])
        d = pos - cam
        d /= np.linalg.norm(d, axis=1)[:, None]
        theta = np.arccos(-d[:, 0])  # apparent angle from the hole's direction
        assert np.all(np.isfinite(z))
        approaching = d[:, 1] < 0  # prograde about the tilted +z axis: the gas at -y comes towards +x
        assert np.median(z[approaching]) < np.median(z[~approaching])
        assert np.median(col[approaching, 0]) > np.median(col[~approaching, 0])
        if order == 1:
            assert z.min() < 1.0 < z.max()
            # the disc's far side, lensed over the hole: images straight above the shadow
            above = (np.abs(d[:, 1]) < 0.1 * shadow) & (d[:, 2] > 0)
            assert above.any() and theta[above].min() < 3 * shadow
        else:  # the ghost image is a thin ring just outside the shadow's edge
            assert theta.min() > shadow and theta.max() < 2.5 * shadow and np.median(theta) < 1.2 * shadow


def test_luminet_blackbody_mode_is_coloured():
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 320, 180
    luminet.luminet_disc_blackbody(scene)
    pos, z, col = _read(bpy.data.objects["ThinDisc.GR1"])
    bright = col.sum(axis=1) > 0.1 * col.sum(axis=1).max()
    chroma = col[bright] / col[bright].sum(axis=1)[:, None]
    assert np.ptp(chroma[:, 2]) > 0.02  # blue and red sides differ in colour, not only in brightness
    assert not math.isclose(float(np.median(chroma[:, 0])), 1 / 3, abs_tol=1e-3)
