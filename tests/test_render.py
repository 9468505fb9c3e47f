"""Renders of small scenes with Cycles (CPU) and Workbench, each in a fresh process, checked for the
features the method must produce: two images of a triangle behind the hole (one on each side), and
an Einstein ring for a sphere directly behind it. Eevee renders through software GL here and is
slow: it gets one smoke test (the triangle).
"""
import os
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

SCRIPT = os.path.join(os.path.dirname(__file__), "scripts", "render_check.py")


def render(engine, scene, tmp_path):
    out = tmp_path / f"{engine}_{scene}.png"
    p = subprocess.run([sys.executable, SCRIPT, engine, scene, str(out)], capture_output=True, text=True,
                       timeout=600)
    assert out.exists(), p.stdout[-2000:] + p.stderr[-2000:]
    assert "GRLENS_STATUS 1 object(s) lensed" in p.stdout, p.stdout[-2000:]
    img = np.asarray(Image.open(out).convert("L"), dtype=np.float64) / 255.0
    return img > 0.15


def components(mask):
    """Number of 8-connected components of a boolean image after closing gaps of up to 4 pixels
    (the thin second-order arc is aliased into dashes at 160x90 by engines without anti-aliasing)."""
    from scipy import ndimage

    closed = ndimage.binary_dilation(mask, structure=np.ones((3, 3)), iterations=2)
    _, n = ndimage.label(closed, structure=np.ones((3, 3)))
    return n


@pytest.mark.parametrize("engine", ["CYCLES", "BLENDER_WORKBENCH",
                                    "EEVEE"])  # Eevee: the one smoke render (software GL, 10-30 s)
def test_triangle_behind_the_hole_has_two_images(engine, tmp_path):
    lit = render(engine, "triangle_behind", tmp_path)
    h, w = lit.shape
    assert components(lit) == 2
    # one image above the hole's centre row, one below (the triangle sits just above the axis)
    rows = np.flatnonzero(lit.any(axis=1))
    assert rows.min() < h / 2 < rows.max()
    from scipy import ndimage

    lab, _ = ndimage.label(ndimage.binary_dilation(lit, np.ones((3, 3)), iterations=2), structure=np.ones((3, 3)))
    centres = [np.mean(np.nonzero(lab == k)[0]) for k in (1, 2)]
    assert min(centres) < h / 2 < max(centres)


@pytest.mark.parametrize("engine", ["CYCLES", "BLENDER_WORKBENCH"])
def test_sphere_behind_the_hole_is_an_einstein_ring(engine, tmp_path):
    lit = render(engine, "sphere_behind", tmp_path)
    h, w = lit.shape
    ys, xs = np.nonzero(lit)
    cy, cx = (h - 1) / 2, (w - 1) / 2
    ang = np.arctan2(ys - cy, xs - cx)
    rad = np.hypot(ys - cy, xs - cx)
    sectors = np.unique(((ang + np.pi) / (2 * np.pi) * 16).astype(int) % 16)
    assert len(sectors) == 16  # light all around the hole
    assert not lit[int(cy) - 2:int(cy) + 3, int(cx) - 2:int(cx) + 3].any()  # dark centre (shadow)
    assert np.percentile(rad, 90) / np.percentile(rad, 10) < 2.0  # a ring, not a filled disc


def test_cycles_writes_light_travel_time_and_order_aovs(tmp_path):
    """Multilayer EXR from Cycles: the light_travel_time AOV holds c*dt of the image surfaces (for the
    sphere beside the hole, between the first-order image's ~40 BU and the second-order's ~60 BU),
    image_order holds 1 or 2, and the background holds 0."""
    import OpenEXR

    out = tmp_path / "side.exr"
    p = subprocess.run([sys.executable, SCRIPT, "CYCLES", "sphere_side", str(out)], capture_output=True,
                       text=True, timeout=600)
    assert out.exists(), p.stdout[-2000:] + p.stderr[-2000:]
    f = OpenEXR.File(str(out), separate_channels=True)
    chans = {}
    for part in f.parts:
        chans.update({name: np.asarray(ch.pixels) for name, ch in part.channels.items()})
    ltt = next(v for k, v in chans.items() if "light_travel_time" in k)
    order = next(v for k, v in chans.items() if "image_order" in k)
    from lutgen import connect

    lo = float(connect(20.0, 3.5, np.pi / 2, 1).dt) * 2.0 * 0.9  # nearest first-order point, r_s = 2
    hi = float(connect(20.0, 2.5, np.pi / 2, 2).dt) * 2.0 * 1.1  # farthest second-order point
    # AOVs are averaged over each pixel's samples, so edge pixels mix in the background's 0: check
    # pixels whose whole 3x3 neighbourhood lies inside one image
    from scipy import ndimage

    full = np.zeros(order.shape, bool)
    for k in (1.0, 2.0):
        inside = order == k
        full |= ndimage.binary_erosion(inside, structure=np.ones((3, 3)))
    assert full.sum() > 20
    assert lo < ltt[full].min() and ltt[full].max() < hi
    assert np.all((order >= 0) & (order <= 2))
    assert np.all(ltt[order == 0] == 0)


def test_animation_render_rebuilds_every_frame(tmp_path):
    """render(animation=True), the loop of `blender -b file.blend -a`: each frame shows that frame's
    images (the sphere moves 30 degrees along its orbit between the two frames)."""
    out = tmp_path / "anim"
    p = subprocess.run([sys.executable, SCRIPT, "BLENDER_WORKBENCH", "demo_animation", str(out)],
                       capture_output=True, text=True, timeout=600)
    frames = [tmp_path / f"anim_{f:04d}.png" for f in (1, 31)]
    assert all(f.exists() for f in frames), p.stdout[-2000:] + p.stderr[-2000:]
    a, b = (np.asarray(Image.open(f).convert("L"), dtype=np.float64) for f in frames)
    assert (np.abs(a - np.median(a)) > 40).sum() > 20 and (np.abs(b - np.median(b)) > 40).sum() > 20
    def centroid(img):  # of the pixels that stand out from the background (black, or grey in 4.2's Workbench)
        ys, xs = np.nonzero(np.abs(img - np.median(img)) > 40)
        return np.array([xs.mean(), ys.mean()])

    assert np.linalg.norm(centroid(a) - centroid(b)) > 2.0  # the images moved (pixels)


def test_same_frame_in_two_processes_gives_identical_geometry(tmp_path):
    """Render farms render frames of one .blend in separate processes: the image meshes of a frame
    (positions, light travel time, faces) must be bit-identical whatever process builds them, and
    differ between frames."""
    script = os.path.join(os.path.dirname(__file__), "scripts", "geometry_digest.py")
    blend = str(tmp_path / "farm.blend")

    env = {k: v for k, v in os.environ.items() if k != "GRLENS_LUT_CACHE"}  # each process builds its tables

    def run(*args):
        p = subprocess.run([sys.executable, script, blend, *map(str, args)], capture_output=True, text=True,
                           timeout=300, env=env)
        return p.stdout + p.stderr

    assert "GRLENS_SAVED" in run(1)

    def digest(frame):
        out = run(frame)
        lines = [ln for ln in out.splitlines() if ln.startswith("GRLENS_DIGEST")]
        assert lines, out[-2000:]
        return lines[0].split()[1]

    first = digest(170)
    assert digest(170) == first
    assert digest(20) != first
