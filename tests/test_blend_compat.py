"""Round trip: a .blend saved by the add-on before issue 19 (tests/data/pre_issue19.blend, made by
tests/data/make_pre_issue19_blend.py at commit c406bd2) opens with the current add-on, rebuilds both
image orders and renders (Workbench, in a fresh process).

Units: Blender units; the file's demo scene has r_s = 2 BU and the camera at 20 r_s.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

import bpy  # noqa: E402

from blender_session import empty_file, registered  # noqa: E402,F401  (autouse fixtures)

HERE = os.path.dirname(os.path.abspath(__file__))
BLEND = os.path.join(HERE, "data", "pre_issue19.blend")


def _images():
    return {o.name: o for o in bpy.data.objects if o.grlens.order in (1, 2)}


def test_the_file_is_small_and_has_no_packed_lut():
    from grlens_addon.blender import lutcache

    assert os.path.getsize(BLEND) < 1_000_000
    bpy.ops.wm.open_mainfile(filepath=BLEND)
    assert lutcache.STORE not in bpy.data.texts


def test_pre_issue19_file_opens_and_rebuilds_both_orders():
    bpy.ops.wm.open_mainfile(filepath=BLEND)
    scene = bpy.context.scene
    g = scene.grlens
    assert g.black_hole.name == "BlackHole" and g.r_s == 2.0
    sphere = bpy.data.objects["OrbitingSphere"]
    assert sphere.grlens.enabled and sphere.hide_render
    assert set(_images()) == {"OrbitingSphere.GR1", "OrbitingSphere.GR2"}  # saved with the file
    scene.frame_set(5)  # the frame handler rebuilds (the sphere moved 4 degrees)
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    assert g.status.startswith("1 object(s) lensed")
    assert g.report_lines == ""  # nothing skipped or lost
    imgs = _images()
    assert set(imgs) == {"OrbitingSphere.GR1", "OrbitingSphere.GR2"}
    for o in imgs.values():
        me = o.data
        assert len(me.polygons) > 0
        co = np.empty(3 * len(me.vertices), np.float32)
        me.vertices.foreach_get("co", co)
        assert np.all(np.isfinite(co))
    # clear and rebuild from nothing: the old file's settings are all there is
    bpy.ops.grlens.clear()
    assert not _images() and not sphere.grlens.enabled
    sphere.grlens.enabled = True
    assert all(len(o.data.polygons) > 0 for o in _images().values()) and len(_images()) == 2


def test_pre_issue19_file_renders_with_workbench(tmp_path):
    from PIL import Image

    out = tmp_path / "compat.png"
    script = os.path.join(HERE, "scripts", "render_blend.py")
    p = subprocess.run([sys.executable, script, BLEND, "BLENDER_WORKBENCH", str(out), "80x45"],
                       capture_output=True, text=True, timeout=600)
    log = p.stdout[-2000:] + p.stderr[-2000:]
    assert out.exists(), log
    assert "GRLENS_STATUS 1 object(s) lensed" in p.stdout, log
    faces = {ln.split()[1]: int(ln.split()[2]) for ln in p.stdout.splitlines() if ln.startswith("GRLENS_IMAGE")}
    assert set(faces) == {"OrbitingSphere.GR1", "OrbitingSphere.GR2"} and min(faces.values()) > 0, log
    img = np.asarray(Image.open(out).convert("L"), dtype=np.float64)
    assert img.shape == (45, 80)
    assert (np.abs(img - np.median(img)) > 20).sum() >= 3  # the sphere's image stands out from the world
