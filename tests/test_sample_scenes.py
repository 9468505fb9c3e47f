"""sample_scenes/render.py end to end (fresh processes): every scene renders at a tiny resolution (PNG,
multilayer EXR with the grlens passes, .blend), and each shows its feature, checked from the pixels
or from the image meshes (tests/scripts/scene_stats.py prints them as JSON).

Geometry used by the pixel checks: every observer camera looks at the hole, so the hole's centre is
the image centre; with a vertical sensor fit the shadow's radius in pixels is
tan(xi_crit) / tan(fov_v / 2) * H / 2, xi_crit from eq. 14 of seed 000.
"""
import json
import math
import os
import subprocess
import sys

import numpy as np
import OpenEXR
import pytest
from PIL import Image, ImageDraw

HERE = os.path.dirname(__file__)
RENDER = os.path.join(HERE, "..", "sample_scenes", "render.py")
STATS = os.path.join(HERE, "scripts", "scene_stats.py")

SCENE_NAMES = sorted([
    "sphere", "triangle", "triangle_tess1", "triangle_tess4", "triangle_tess64", "triangle_flat",
    "disc", "disc_external", "disc_90", "disc_30", "disc_10", "disc_90_external", "disc_30_external",
    "disc_10_external", "shell", "room", "luminet", "luminet_blackbody", "flyin", "plunge", "starfield",
    "starfield_dome", "starfield_panorama", "orbit", "orbit_panorama", "orbit_still", "orbit_panorama_still"])

# how each scene is rendered here: (resolution, frames, samples); Cycles
TEST_RENDERS = {
    "sphere": ("96x54", "1", 2),
    "triangle": ("96x54", "1", 2),
    "triangle_tess1": ("96x54", "1", 1),
    "triangle_tess4": ("96x54", "1", 1),
    "triangle_tess64": ("192x108", "1", 2),
    "triangle_flat": ("192x108", "1,150", 4),
    "disc": ("80x72", "1,61,81", 4),
    "disc_90": ("80x72", "1", 4),
    "disc_30": ("80x72", "1", 4),
    "disc_10": ("80x72", "1", 4),
    "disc_external": ("96x54", "61", 2),
    "disc_90_external": ("96x54", "1", 2),
    "disc_30_external": ("96x54", "1", 2),
    "disc_10_external": ("96x54", "1", 2),
    "shell": ("192x108", "1", 4),
    "room": ("192x108", "1", 8),
    "luminet": ("96x54", "1", 2),
    "luminet_blackbody": ("96x54", "1", 2),
    "flyin": ("160x90", "120", 2),
    "plunge": ("160x90", "160,240", 2),
    "starfield": ("96x54", "1", 1),
    "starfield_dome": ("96x96", "1", 1),
    "starfield_panorama": ("192x96", "1", 1),
    "orbit": ("96x54", "1", 1),
    "orbit_panorama": ("192x96", "1", 1),
    "orbit_still": ("96x54", "1", 1),
    "orbit_panorama_still": ("192x96", "1", 1),
}


def run(*args, script=RENDER):
    p = subprocess.run([sys.executable, script, *args], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    return p.stdout


def shadow_radius_px(r_obs_rs, fov_v_deg, height):
    xi = math.asin(math.sqrt(6.75 / r_obs_rs ** 2 * (1.0 - 1.0 / r_obs_rs)))
    return math.tan(xi) / math.tan(math.radians(fov_v_deg) / 2) * height / 2


def radius_map(img):
    h, w = img.shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    return np.hypot(x + 0.5 - w / 2, y + 0.5 - h / 2), x + 0.5 - w / 2, h / 2 - (y + 0.5)


def red(img):
    r, g, b = (img[..., i].astype(float) for i in range(3))
    return (r > 30) & (r > 1.5 * g) & (r > 1.5 * b)


class Renders:
    """Each scene rendered once per session (render.py in a fresh process), PNGs loaded as RGB arrays."""

    def __init__(self, root):
        self.root = root
        self.done = {}

    def get(self, name):
        if name not in self.done:
            res, frames, samples = TEST_RENDERS[name]
            out = self.root / name
            stdout = run("--scene", name, "--frames", frames, "--engine", "cycles", "--resolution", res,
                         "--samples", str(samples), "--output", str(out))
            imgs = {int(f): np.asarray(Image.open(out / f"{name}_{int(f):04d}.png").convert("RGB"))
                    for f in frames.split(",")}
            self.done[name] = (out, stdout, imgs)
        return self.done[name]


@pytest.fixture(scope="module")
def renders(tmp_path_factory):
    return Renders(tmp_path_factory.mktemp("scenes"))


@pytest.fixture(scope="module")
def stats():
    """Image-mesh statistics of several scenes (one process), keyed by (scene, frame)."""
    out = run("96x54", "triangle_tess1:1,150", "triangle_tess4:1,150", "triangle_tess64:1,150",
              "triangle_flat:1", "disc_90", "disc_10", "disc_90_external", "shell", "room", script=STATS)
    res = {}
    for line in out.splitlines():
        if line.startswith("SCENE_STATS "):
            d = json.loads(line.split(" ", 1)[1])
            res[(d["scene"], d["frame"])] = d
    return res


# --------------------------------------------------------------------------------------------------
# all scenes
# --------------------------------------------------------------------------------------------------


def test_list_names_every_scene_with_defaults():
    out = run("--list")
    names = sorted(line.split()[0] for line in out.splitlines() if line.strip())
    assert names == SCENE_NAMES == sorted(TEST_RENDERS)


SLOW_RENDERS = ("disc_90_external", "disc_10_external")
"""Scenes whose render repeats another's code path (disc_30_external and disc_external show the
external camera): rendered only with -m slow, to keep the default suite short."""


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW_RENDERS else n
                                  for n in SCENE_NAMES])
def test_every_scene_renders(renders, name):
    out_dir, stdout, imgs = renders.get(name)
    frames = TEST_RENDERS[name][1].split(",")
    assert f"frame {frames[0]} (1/{len(frames)})" in stdout and "s per frame" in stdout
    assert "grlens:" not in stdout.replace("grlens: no object is marked", "")  # no rebuild errors
    for f, img in imgs.items():
        assert img.shape[:2] == tuple(int(v) for v in TEST_RENDERS[name][0].split("x"))[::-1]
        assert (img.max(axis=2) > 60).sum() > 10, f"frame {f} is (nearly) empty"
        exr = OpenEXR.File(str(out_dir / f"{name}_{f:04d}.exr"), separate_channels=True)
        channels = [n for part in exr.parts for n in part.channels]
        if name == "triangle_flat":  # nothing lensed: grlens adds no passes
            continue
        assert any("light_travel_time" in n for n in channels) and any("image_order" in n for n in channels)
    assert (out_dir / f"{name}.blend").exists()


def test_sphere_scene_cycles_png_and_exr(tmp_path):
    out = run("--scene", "sphere", "--frames", "1", "--engine", "cycles", "--resolution", "96x54",
              "--samples", "2", "--output", str(tmp_path))
    assert "frame 1" in out and "s per frame" in out
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


# --------------------------------------------------------------------------------------------------
# triangle (seed 000, 4.1, figure 8)
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("frame", [1, 150])
def test_triangle_two_images_on_opposite_sides_of_the_hole(stats, frame):
    for level in (1, 4, 64):
        d = stats[(f"triangle_tess{level}", frame)]
        hx, hy = d["hole_view"][:2]
        one, two = d["images"]["Triangle.GR1"], d["images"]["Triangle.GR2"]
        assert one["n_tris"] > 0 and two["n_tris"] > 0
        a = np.subtract(one["view"]["mean"][:2], (hx, hy))
        b = np.subtract(two["view"]["mean"][:2], (hx, hy))
        assert a @ b < -0.5 * np.linalg.norm(a) * np.linalg.norm(b)  # roughly opposite directions
        assert a[0] > 0 > b[0]  # the triangle is at +y (right): order 1 right, order 2 left
        # every image point lies outside the shadow (7.274 deg at 20 r_s); the second-order image is
        # a thin sliver just outside it, the first-order one farther out
        assert one["view"]["angle_deg"][0] > 7.274 and two["view"]["angle_deg"][0] > 7.274
        assert two["view"]["angle_deg"][1] < one["view"]["angle_deg"][1]
        # the second image is farther away (longer light travel time)
        assert two["ltt"][1] > one["ltt"][1]


def test_triangle_higher_tess_level_more_triangles(stats):
    for frame in (1, 150):
        n = [stats[(f"triangle_tess{level}", frame)]["images"]["Triangle.GR1"]["n_tris"] for level in (1, 4, 64)]
        assert n[0] == 1  # tessLevel 1: only the three corners are mapped
        assert 1 < n[1] <= 16 < n[2]


def test_triangle_flat_is_undistorted(renders, stats):
    """Flat spacetime: nothing is lensed and the render shows the triangle exactly where its own
    perspective projection is; the lensed render (tess 64) is elsewhere."""
    d = stats[("triangle_flat", 1)]
    assert d["images"] == {} and not d["sources"]["Triangle"]["enabled"]
    _, _, imgs = renders.get("triangle_flat")
    _, _, lensed = renders.get("triangle_tess64")
    for frame, img in imgs.items():
        h, w = img.shape[:2]
        # the source's corners at this frame: p + (0, 0, 0), (0, 3, 0), (0, 0, 3) seen from (40, 0, 0)
        p = (-5.0, 0.5, -0.5) if frame == 1 else (-5.0, 3.0, -0.5)
        corners = [(p[0], p[1], p[2]), (p[0], p[1] + 3, p[2]), (p[0], p[1], p[2] + 3)]
        f = (h / 2) / math.tan(math.radians(10.0))
        poly = [(w / 2 + f * y / (40.0 - x), h / 2 - f * z / (40.0 - x)) for x, y, z in corners]
        mask_img = Image.new("L", (w, h), 0)
        ImageDraw.Draw(mask_img).polygon(poly, fill=1)
        expected = np.asarray(mask_img, dtype=bool)
        seen = img.max(axis=2) > 90  # checker 0.95 / 0.2 (sRGB 250 / 124); the grey disc is sRGB 48
        iou = (expected & seen).sum() / (expected | seen).sum()
        assert iou > 0.75, (frame, iou)
        if frame == 1:
            seen_lensed = lensed[1].max(axis=2) > 90
            assert (expected & seen_lensed).sum() / (expected | seen_lensed).sum() < 0.2
            # the lensed images lie right and left of the hole, outside the shadow
            r, x, _ = radius_map(lensed[1])
            big_r = shadow_radius_px(20.0, 20.0, h)
            assert (seen_lensed & (x > 0) & (r > big_r)).sum() > 20
            assert (seen_lensed & (x < 0) & (r > big_r)).sum() > 0
            assert not (seen_lensed & (r < 0.9 * big_r)).any()


# --------------------------------------------------------------------------------------------------
# accretion disc (seed 000, 4.3, figure 10)
# --------------------------------------------------------------------------------------------------

DISC_FOV = 50.0


@pytest.mark.parametrize("name", ["disc_30", "disc_10"])
def test_disc_far_side_seen_above_the_shadow(renders, name):
    """Low inclinations: the far side of the disc, which in flat space would hide behind the hole (at
    10 degrees its top face would appear at most 4.1 deg above the centre, inside the 7.3 deg shadow),
    is lifted by lensing into an arch right above the shadow."""
    _, _, imgs = renders.get(name)
    img = imgs[1]
    h = img.shape[0]
    r, x, y = radius_map(img)
    big_r = shadow_radius_px(20.0, DISC_FOV, h)
    # the upper half of the shadow is empty (the near side of the disc crosses its lower half)
    assert img[(r < 0.8 * big_r) & (y > 0.3 * big_r)].max() < 30
    lit = img.max(axis=2) > 30
    band = (np.abs(x) < 3) & (y > 1.05 * big_r) & (y < 1.6 * big_r)
    assert lit[band].sum() >= 3, "no disc pixels right above the shadow"  # far side's inner edge, top face
    column = (np.abs(x) < 3) & (y > 1.05 * big_r) & (y < 2.5 * big_r)
    assert red(img)[column].sum() >= 2, "no red top face above the shadow"
    # the near side passes in front of the hole, across the lower half of the shadow
    assert red(img)[(r < big_r) & (y < 0)].sum() >= 3


def test_disc_face_on_ring_and_sequence(renders):
    """Inclination 90: the first-order image is a red ring (inner edge at 10.9 deg, outer at 24.7 deg
    from the centre) around the shadow; the 180-frame sequence passes through the paper's views at
    frames 1, 61, 81 (90, 30, 10 degrees)."""
    _, _, imgs = renders.get("disc_90")
    img = imgs[1]
    r, _, _ = radius_map(img)
    big_r = shadow_radius_px(20.0, DISC_FOV, img.shape[0])
    assert img[r < 0.8 * big_r].max() < 30
    ring = (r > 1.8 * big_r) & (r < 3.0 * big_r)
    assert red(img)[ring].mean() > 0.9
    _, _, seq = renders.get("disc")
    for frame, single in ((1, "disc_90"), (61, "disc_30"), (81, "disc_10")):
        ref = renders.get(single)[2][1].astype(float)
        assert np.abs(seq[frame].astype(float) - ref).mean() < 2.0, frame
    assert np.abs(seq[1].astype(float) - seq[81].astype(float)).mean() > 5


def test_disc_gr_illumination_and_light_travel_time_geometry(stats):
    """GR illumination writes the irradiance; the external view's meshes are the observer's image
    meshes, each vertex at c dt: the second-order image lies beyond the first, and (figure 10b) the
    inner part of the face-on first-order image is farther away than its outer part, much more so
    than the source disc's own depth spread (time dilation near the hole)."""
    d = stats[("disc_90", 1)]
    one, two = d["images"]["Disc.GR1"], d["images"]["Disc.GR2"]
    assert one["irradiance"] and two["irradiance"]
    assert two["ltt"][0] > one["ltt"][1]
    # paper's table 1 (thin disc, BU): inner edge 45.33, outer 46.17; ours has a thickness of 1.1 BU
    assert 43.0 < one["ltt"][0] < 46.0 and 45.5 < one["ltt"][1] < 48.0
    src = d["sources"]["Disc"]["view"]
    assert one["view"]["depth_inner"] - one["view"]["depth_outer"] > src["depth_inner"] - src["depth_outer"] + 1.0
    ext = stats[("disc_90_external", 1)]
    assert ext["images"]["Disc.GR1"]["n_tris"] == one["n_tris"]  # same meshes, whatever camera renders


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW_RENDERS else n
                                  for n in ("disc_90_external", "disc_30_external", "disc_10_external")])
def test_disc_external_views(renders, name):
    _, _, imgs = renders.get(name)
    img = imgs[min(imgs)]
    assert red(img).mean() > 0.03  # the image meshes
    assert (img.max(axis=2) < 8).sum() > 5  # the black shadow sphere against the dark blue background
    # ... and nothing else black: the world is not lensed for the external camera (a world lensed as the
    # observer sees it showed the observer's shadow cone as a black patch on the left)
    assert img[:, : img.shape[1] // 5].max(axis=2).min() > 20
    if name == "disc_30_external":
        seq = renders.get("disc_external")[2][61]
        assert np.abs(seq.astype(float) - img.astype(float)).mean() < 2.0


# --------------------------------------------------------------------------------------------------
# observer inside a gridded shell (seed 004)
# --------------------------------------------------------------------------------------------------


def test_shell_seen_all_around_the_hole(renders, stats):
    _, _, imgs = renders.get("shell")
    img = imgs[1]
    r, x, y = radius_map(img)
    big_r = shadow_radius_px(5.0, 90.0, img.shape[0])
    peak = img.max(axis=2)
    assert peak[r < 0.85 * big_r].max() < 20  # the shadow in the middle
    outside = r > 1.5 * big_r
    assert (peak[outside] > 25).mean() > 0.98  # the shell everywhere else (dim blue between the lines)
    lines = img[..., 2] > 120
    ang = np.degrees(np.arctan2(y, x))
    for k in range(8):  # grid lines in every direction around the hole
        sector = outside & (ang >= -180 + 45 * k) & (ang < -135 + 45 * k)
        assert lines[sector].sum() >= 3, k
    assert (peak[(r > 1.05 * big_r) & (r < 1.4 * big_r)] > 25).mean() > 0.5  # second-order image
    d = stats[("shell", 1)]
    one, two = d["images"]["Shell.GR1"], d["images"]["Shell.GR2"]
    # order 1 outside the Einstein ring of the point behind the hole, order 2 between it and the shadow
    shadow_deg = math.degrees(math.asin(math.sqrt(6.75 / 25 * 0.8)))
    assert two["view"]["angle_deg"][0] > shadow_deg
    assert abs(one["view"]["angle_deg"][0] - two["view"]["angle_deg"][1]) < 1.0


# --------------------------------------------------------------------------------------------------
# room at everyday scale (seed 003)
# --------------------------------------------------------------------------------------------------


def test_room_with_hole_shadow_and_distortion(renders, stats):
    _, _, imgs = renders.get("room")
    img = imgs[1].astype(float)
    h, w = img.shape[:2]
    r, _, _ = radius_map(img)
    big_r = shadow_radius_px(37.5, 40.0, h)
    assert img[r < 0.7 * big_r].max() < 25  # the shadow in the middle of the room
    assert img[(r > 1.5 * big_r) & (r < 3 * big_r)].mean() > 40  # the lit back wall around it
    left, right = img[:, : w // 6].reshape(-1, 3).mean(axis=0), img[:, -w // 6:].reshape(-1, 3).mean(axis=0)
    assert left[0] > 1.2 * left[1] and right[1] > 1.2 * right[0]  # red and green walls lit by the lamp
    d = stats[("room", 1)]
    assert d["status"].startswith("8 object(s) lensed")
    shadow_deg = math.degrees(math.asin(math.sqrt(6.75 / 37.5 ** 2 * (1 - 1 / 37.5))))
    wall, src = d["images"]["BackWall.GR1"], d["sources"]["BackWall"]
    # the back wall behind the hole (from 0.5 deg off its centre) is pushed out of the shadow, into an
    # Einstein ring, and subdivided where it bends
    assert src["view"]["angle_deg"][0] < 1.0 < shadow_deg < wall["view"]["angle_deg"][0]
    assert wall["n_tris"] > 2 * 41 * 41
    for name in ("BackWall", "Floor", "Ceiling", "LeftWall", "RightWall", "Sphere", "Cube", "Cylinder"):
        assert d["images"][f"{name}.GR2"]["n_tris"] > 0  # second-order images around the shadow


# --------------------------------------------------------------------------------------------------
# fly-in over a checkered floor (issue 19: tables for every camera distance)
# --------------------------------------------------------------------------------------------------

FLYIN_SCRIPT = r"""
import json, os, sys
sys.path.insert(0, sys.argv[1])
import bpy
import numpy as np
import grlens_addon
from sample_scenes.scenes import SCENES

grlens_addon.register()
bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
scene = bpy.context.scene
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 160, 90, 100
SCENES["flyin"](scene)
g = scene.grlens
r_s = g.r_s
hole = np.array(g.black_hole.matrix_world.translation)
out = {"frames": [scene.frame_start, scene.frame_end], "lut_mode": g.lut_mode, "camera": []}
g.auto_update = False  # the camera's path alone: no rebuilds
for f in range(scene.frame_start, scene.frame_end + 1):
    scene.frame_set(f)
    cam = scene.camera.evaluated_get(bpy.context.evaluated_depsgraph_get())
    m = np.array(cam.matrix_world)
    to_hole = hole - m[:3, 3]
    look = -m[:3, 2] / np.linalg.norm(m[:3, 2])
    aim = float(np.degrees(np.arccos(np.clip(look @ to_hole / np.linalg.norm(to_hole), -1, 1))))
    out["camera"].append([f, float(np.linalg.norm(to_hole)) / r_s, float(m[2, 3] - hole[2]) / r_s, aim,
                          float(np.degrees(cam.data.angle_y))])
floor = bpy.data.objects["Floor"]
me = floor.data
co = np.empty(3 * len(me.vertices))
me.vertices.foreach_get("co", co)
mw = np.array(floor.matrix_world)
co = (co.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3] - hole) / r_s
out["floor"] = {"faces": len(me.polygons), "z": [float(co[:, 2].min()), float(co[:, 2].max())],
                "reach": float(np.hypot(co[:, 0], co[:, 1]).max()),
                "extent": [float(co[:, 0].min()), float(co[:, 0].max()), float(co[:, 1].min()),
                           float(co[:, 1].max())],
                "nearest_under_hole": float(np.hypot(co[:, 0], co[:, 1]).min())}
g.auto_update = True
scene.frame_set(120)
bpy.ops.grlens.rebuild()
out["status"], out["report"] = g.status, g.report_lines
out["images"] = {o.name: len(o.data.polygons) for o in scene.objects if o.type == "MESH" and o.grlens.order in (1, 2)}
print("FLYIN " + json.dumps(out), flush=True)
os._exit(0)
"""


@pytest.fixture(scope="module")
def flyin():
    out = run(FLYIN_SCRIPT, os.path.join(HERE, ".."), script="-c")
    return json.loads(next(line for line in out.splitlines() if line.startswith("FLYIN "))[6:])


def test_flyin_camera_path(flyin):
    """The camera flies in from 80 r_s to 4.5 r_s over frames 1-240, smoothly (its distance falls every
    frame, geometrically at an eased rate), always looking at the hole, above the floor and well
    outside the photon sphere; its field of view widens with the shadow."""
    cam = np.array(flyin["camera"])
    assert flyin["frames"] == [1, 240] and cam[0, 0] == 1 and cam[-1, 0] == 240
    dist, height, aim, fov = cam[:, 1], cam[:, 2], cam[:, 3], cam[:, 4]
    assert dist[0] == pytest.approx(80.0, rel=1e-4) and dist[-1] == pytest.approx(4.5, rel=1e-4)
    assert dist.min() == dist[-1] > 1.5 and np.all(np.diff(dist) < 0)
    step = np.diff(np.log(dist))  # per-frame change of ln(distance): eased in and out, no jumps
    assert abs(step[0]) < 1e-3 and abs(step[-1]) < 1e-3 and np.abs(np.diff(step)).max() < 1e-3
    assert aim.max() < 0.01  # degrees off the hole
    assert height.min() - flyin["floor"]["z"][1] > 3.0  # at least 3 r_s above the floor
    assert fov[0] == pytest.approx(25.0, abs=0.01) and fov[-1] == pytest.approx(100.0, abs=0.01)
    assert flyin["lut_mode"] == "EVERY_DISTANCE"


def test_flyin_floor_reaches_far_and_passes_under_the_hole(flyin):
    fl = flyin["floor"]
    assert fl["reach"] >= 100.0
    assert min(-fl["extent"][0], fl["extent"][1], -fl["extent"][2], fl["extent"][3]) >= 100.0  # all around
    assert -3.0 <= fl["z"][0] <= fl["z"][1] <= -1.0 and fl["z"][1] - fl["z"][0] < 1e-6  # flat, 1-3 r_s below
    assert fl["nearest_under_hole"] < 0.25  # a vertex right under the hole: no hole in the floor there
    assert 2000 <= fl["faces"] <= 20000


def test_flyin_middle_frame_images(flyin):
    """At frame 120 (camera at 19 r_s) the floor and the sphere are imaged, both orders of the floor,
    and nothing is lost (the tables reach the horizon and infinity; the floor stays 2 r_s from the hole)."""
    im = flyin["images"]
    assert flyin["status"].startswith("2 object(s) lensed")
    assert flyin["report"] == ""
    assert im["Floor.GR1"] > flyin["floor"]["faces"] and im["Floor.GR2"] > 0 and im["OrbitingSphere.GR1"] > 0


def test_flyin_render_shadow_and_lensed_horizon(renders):
    """Frame 120: the shadow in the middle (its upper half is empty: the floor passes in front of the
    lower half), floor all around it, and the floor behind the hole lifted above its own horizon: in
    flat space the horizon is a straight horizontal line (no camera roll), here it rises over the hole."""
    _, _, imgs = renders.get("flyin")
    img = imgs[120]
    h, w = img.shape[:2]
    r, x, y = radius_map(img)
    big_r = shadow_radius_px(19.15, 25.0 + 75.0 * 0.4969, h)  # flyin_camera(120): 19.15 r_s, 62.3 deg
    peak = img.max(axis=2)
    assert peak[(r < 0.8 * big_r) & (y > 0.2 * big_r)].max() < 35  # dark sky colour (sRGB 22-25)
    ring = (r > 1.3 * big_r) & (r < 2.5 * big_r)
    assert (peak[ring] > 40).mean() > 0.8  # the floor all around the shadow (dark squares: sRGB 52+)
    floor = peak > 40
    top = [int(np.argmax(floor[:, c])) for c in range(w)]  # topmost floor row per column
    side = min(np.median(top[: w // 8]), np.median(top[-w // 8:]))
    centre = min(top[w // 2 - 3: w // 2 + 3])
    assert centre < side - 8, (centre, side)  # 160x90: 9 against 26 rows from the top


# --------------------------------------------------------------------------------------------------
# lensed star field (issue 21 item 5): normal view, fisheye dome master, equirectangular panorama
# --------------------------------------------------------------------------------------------------

STARFIELD_SCRIPT = r"""
import json, math, os, sys
sys.path.insert(0, sys.argv[1])
import bpy
import grlens_addon
from grlens_addon.blender import world as gw
from sample_scenes.scenes import SCENES

grlens_addon.register()
bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
scene = bpy.context.scene
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 64, 36, 100
SCENES["starfield"](scene)
g = scene.grlens
tree = scene.world.node_tree
groups = [n for n in tree.nodes if n.bl_idname == "ShaderNodeGroup" and n.node_tree is not None
          and n.node_tree.name.startswith(gw.GROUP_PREFIX)]
textures = [n for n in tree.nodes if n.bl_idname in ("ShaderNodeTexVoronoi", "ShaderNodeTexNoise")]
out = {"lens_world": g.lens_world, "is_lensed": gw.is_lensed(scene.world), "world_status": g.world_status,
       "groups": len(groups), "textures": len(textures),
       "hooked": sum(1 for n in textures if n.inputs["Vector"].is_linked
                     and n.inputs["Vector"].links[0].from_node in groups),
       "cameras": {}, "views": {}}
for name in ("CamNormal", "CamDome", "CamPanorama"):
    d = bpy.data.objects[name].data
    out["cameras"][name] = {"type": d.type, "panorama_type": getattr(d, "panorama_type", None),
                            "fisheye_fov": d.fisheye_fov, "lat": [d.latitude_min, d.latitude_max],
                            "lon": [d.longitude_min, d.longitude_max],
                            "location": list(bpy.data.objects[name].location)}
for name, res in (("CamNormal", (64, 36)), ("CamDome", (256, 256)), ("CamPanorama", (512, 256))):
    scene.camera = bpy.data.objects[name]
    scene.render.resolution_x, scene.render.resolution_y = res
    bpy.ops.grlens.rebuild()
    out["views"][name] = {"status": g.status, "report": g.report_lines, "lensed": gw.is_lensed(scene.world),
                          "images": {o.name: len(o.data.polygons) for o in scene.objects
                                     if o.type == "MESH" and o.grlens.order in (1, 2)}}
print("STARFIELD " + json.dumps(out), flush=True)
os._exit(0)
"""


@pytest.fixture(scope="module")
def starfield():
    out = run(STARFIELD_SCRIPT, os.path.join(HERE, ".."), script="-c")
    return json.loads(next(line for line in out.splitlines() if line.startswith("STARFIELD "))[10:])


def test_starfield_world_lensed_cameras_and_images(starfield):
    """The star field's world is lensed (grlens' node group feeds every star and haze texture's Vector,
    the view direction), its three cameras are a perspective view, a 180-degree fisheye equidistant
    dome master and a full equirectangular panorama at the same place, and each, as the observer,
    gets first- and second-order images of the disc and the sphere."""
    sf = starfield
    assert sf["lens_world"] and sf["is_lensed"] and sf["groups"] == 1
    assert sf["textures"] == 3 and sf["hooked"] == 3, sf
    assert "not lensed" not in sf["world_status"]
    cams = sf["cameras"]
    assert cams["CamNormal"]["type"] == "PERSP"
    dome, pano = cams["CamDome"], cams["CamPanorama"]
    assert dome["type"] == "PANO" and dome["panorama_type"] == "FISHEYE_EQUIDISTANT"
    assert dome["fisheye_fov"] == pytest.approx(math.pi)
    assert pano["type"] == "PANO" and pano["panorama_type"] == "EQUIRECTANGULAR"
    assert pano["lat"] == pytest.approx([-math.pi / 2, math.pi / 2])
    assert pano["lon"] == pytest.approx([-math.pi, math.pi])
    assert cams["CamNormal"]["location"] == dome["location"] == pano["location"]
    for name, view in sf["views"].items():
        assert view["status"].startswith("2 object(s) lensed") and "sky lensed" in view["status"], (name, view)
        assert view["lensed"] and view["report"] == "", (name, view)
        im = view["images"]
        assert im["ThinDisc.GR1"] > 1000 and im["ThinDisc.GR2"] > 0 and im["OrbitingSphere.GR1"] > 0, (name, im)
        if name != "CamNormal":  # panoramas image everything (no frustum; 256 px across 180 degrees:
            assert im["OrbitingSphere.GR2"] > 0, (name, im)  # the sphere's thin image is over a pixel)


def test_starfield_renders_black_shadow_and_round_dome(renders):
    """Tiny Cycles renders (render.py, 1 sample): the upper half of the shadow (the disc's near side
    crosses its lower half) is black in every view, the dome master is a disc (its corners, outside the
    180-degree circle, are black) with stars and the disc inside it, and the panorama has sky all
    around, behind the camera too."""
    shadow_deg = math.degrees(math.asin(math.sqrt(6.75 / 400 * 0.95)))  # 7.27 degrees at 20 r_s
    radius = {"starfield": shadow_radius_px(20.0, 50.0, 54), "starfield_dome": shadow_deg / 90.0 * 48,
              "starfield_panorama": shadow_deg / 360.0 * 192}
    for name, big_r in radius.items():
        img = renders.get(name)[2][1].astype(float)
        h, w = img.shape[:2]
        peak = img.max(axis=2)
        r, x, y = radius_map(img)
        upper = (r < big_r - 1.0) & (y > 0.3 * big_r) & (np.abs(x) < 0.5 * big_r)
        assert upper.sum() >= 1 and peak[upper].max() < 12, (name, big_r, peak[upper])
        assert (peak > 60).sum() > 5, name
    dome = renders.get("starfield_dome")[2][1].astype(float).max(axis=2)
    r, _, _ = radius_map(dome)
    assert dome[r > 49.5].max() < 5  # outside the fisheye circle
    assert (dome[(r < 45) & (r > 18)] > 40).sum() > 10  # stars and the disc inside it
    pano = renders.get("starfield_panorama")[2][1].astype(float).max(axis=2)
    assert (pano[:, :24] > 15).sum() > 3 and (pano[:, -24:] > 15).sum() > 3


def test_plunge_inside_the_photon_sphere(renders):
    """The camera descends from 6 to 1.05 r_s: at 1.28 r_s (frame 160) the floor fills the lower part of
    the view (seen along rays that turn back or cross the photon sphere); at 1.05 r_s (frame 240) the
    outside world crowds into a bright disc overhead and the shadow fills the rest: most of the frame is
    black, the lit part one blob within the escape cone (33 degrees in radius)."""
    out_dir, stdout, imgs = renders.get("plunge")
    assert "2 object(s) lensed, r_obs = 1.283 r_s" in stdout and "2 object(s) lensed, r_obs = 1.05 r_s" in stdout
    lit = {f: img.max(axis=2) > 60 for f, img in imgs.items()}
    h = lit[160].shape[0]
    assert lit[160][h // 2:].mean() > 0.4 and lit[160][: h // 4].mean() < 0.05  # floor below, black above
    assert 0.02 < lit[240].mean() < 0.45
    ys, xs = np.nonzero(lit[240])
    w = lit[240].shape[1]
    assert xs.min() > 0.1 * w and xs.max() < 0.9 * w  # one disc, away from the frame's sides


def test_orbit_camera_moves_and_its_view_is_aberrated(renders):
    """The orbit scene: the camera on the circular orbit at 6 r_s moves at 1/sqrt(10) = 0.316 c in the
    static frame (the rebuild's status), to the right of the picture; its view crowds towards the
    motion: the shadow (the darkest pixels off the top and bottom rows) lies farther right and is no
    larger (1/gamma across the motion) than from the camera at rest at the same place, in the normal
    view and in the panorama."""
    for moving, still in (("orbit", "orbit_still"), ("orbit_panorama", "orbit_panorama_still")):
        out_m, stdout_m, imgs_m = renders.get(moving)
        _, stdout_s, imgs_s = renders.get(still)
        assert "camera at 0.316 c" in stdout_m and "camera at" not in stdout_s

        def shadow(img):
            peak = img.astype(float).max(axis=2)
            h, w = peak.shape
            dark = peak < 6
            dark[: h // 5] = dark[-h // 5:] = False  # (the sky's dark gaps at the top and bottom)
            ys, xs = np.nonzero(dark)
            return xs.mean() / w, dark.sum()

        (xm, nm), (xs_, ns) = shadow(imgs_m[1]), shadow(imgs_s[1])
        assert xm > xs_ + 0.03 and nm <= ns, (moving, xm, xs_, nm, ns)  # (18 degrees in the panorama)
