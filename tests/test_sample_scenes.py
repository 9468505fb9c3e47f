"""sample_scenes/render.py end to end (fresh process): PNG and multilayer EXR with the grlens passes."""
import os
import subprocess
import sys

import numpy as np
import OpenEXR
from PIL import Image

RENDER = os.path.join(os.path.dirname(__file__), "..", "sample_scenes", "render.py")


def run(*args):
    p = subprocess.run([sys.executable, RENDER, *args], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    return p.stdout


def test_sphere_scene_cycles_png_and_exr(tmp_path):
    out = run("--scene", "sphere", "--frames", "1", "--engine", "cycles", "--resolution", "96x54",
              "--samples", "2", "--output", str(tmp_path))
    assert "frame 1:" in out and "s per frame" in out
    png = np.asarray(Image.open(tmp_path / "sphere_0001.png").convert("L"))
    assert (png > 40).sum() > 10
    f = OpenEXR.File(str(tmp_path / "sphere_0001.exr"), separate_channels=True)
    names = [n for part in f.parts for n in part.channels]
    assert any("light_travel_time" in n for n in names) and any("image_order" in n for n in names)
    assert (tmp_path / "sphere.blend").exists()


def test_triangle_scene_workbench(tmp_path):
    run("--scene", "triangle", "--frames", "1,150", "--engine", "workbench", "--resolution", "96x54",
        "--output", str(tmp_path))
    a = np.asarray(Image.open(tmp_path / "triangle_0001.png").convert("L"), dtype=float)
    b = np.asarray(Image.open(tmp_path / "triangle_0150.png").convert("L"), dtype=float)
    assert (a > 40).sum() > 5 and (b > 40).sum() > 5 and np.abs(a - b).mean() > 0.5
