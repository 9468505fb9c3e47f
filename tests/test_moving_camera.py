"""A camera that flies in, one new distance every frame, in an animation render (Workbench, pip bpy):
each frame's image vertices against lutgen.connect, and no new table per frame.

Units: Blender units with r_s = 2 BU; the camera goes from 12 to 6 r_s over five frames.
"""
import math

import numpy as np
import pytest

import bpy

from blender_session import empty_file, registered  # noqa: F401  (autouse fixtures)
from lutgen import connect

R_S = 2.0


def _fly_in_scene():
    scene = bpy.context.scene
    hole = bpy.data.objects.new("BlackHole", None)
    scene.collection.objects.link(hole)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens_unit, cam.data.angle = "FOV", math.radians(100.0)
    cam.rotation_euler = (math.pi / 2, 0.0, math.pi / 2)  # looks along -X, at the hole
    scene.collection.objects.link(cam)
    scene.camera = cam
    for frame, r in ((1, 12.0), (5, 6.0)):
        cam.location = (r * R_S, 0.0, 0.0)
        cam.keyframe_insert("location", frame=frame)
    # one small triangle behind the hole, off the axis (so both images are whole)
    corners = np.array([[-3.0, 1.5, 0.3], [-3.0, 2.0, 0.3], [-3.0, 1.5, 0.8]]) * R_S
    me = bpy.data.meshes.new("Tri")
    me.from_pydata([tuple(c) for c in corners], [], [(0, 1, 2)])
    tri = bpy.data.objects.new("Tri", me)
    scene.collection.objects.link(tri)
    tri.grlens.enabled = True
    g = scene.grlens
    g.black_hole, g.r_s = hole, R_S
    g.max_tess_level = 1  # no subdivision: the images' vertices are the corners' images
    g.use_gr_illumination = False
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.render.resolution_x, scene.render.resolution_y = 64, 36
    scene.frame_start, scene.frame_end = 1, 5
    return scene, corners


def test_a_camera_flying_in_gets_exact_images_every_frame(tmp_path):
    from grlens_addon.blender import lutcache

    scene, corners = _fly_in_scene()
    lutcache.clear()
    seen = []

    def record(sc, depsgraph=None):
        cam = np.array(sc.camera.evaluated_get(depsgraph).matrix_world.translation) if depsgraph else None
        imgs = {o: bpy.data.objects.get(f"Tri.GR{o}") for o in (1, 2)}
        seen.append((sc.frame_current, cam, {o: np.array([v.co[:] for v in ob.data.vertices]) if ob else None
                                             for o, ob in imgs.items()}))

    bpy.app.handlers.frame_change_post.append(record)  # after grlens' own handler
    try:
        scene.render.filepath = str(tmp_path / "fly_")
        bpy.ops.render.render(animation=True)
    finally:
        bpy.app.handlers.frame_change_post.remove(record)
    frames = {f: (cam, imgs) for f, cam, imgs in seen if cam is not None}
    assert sorted(frames) == [1, 2, 3, 4, 5]
    radii = [np.linalg.norm(frames[f][0]) / R_S for f in range(1, 6)]
    assert radii[0] == pytest.approx(12.0) and radii[-1] == pytest.approx(6.0) and len(set(radii)) == 5
    assert all((tmp_path / f"fly_{f:04d}.png").exists() for f in range(1, 6))
    for f in range(1, 6):
        cam, imgs = frames[f]
        r_obs = np.linalg.norm(cam) / R_S
        e1 = cam / np.linalg.norm(cam)
        for order in (1, 2):
            got = imgs[order]
            assert got is not None and len(got) >= 3, (f, order)
            for p in corners:
                perp = p - (p @ e1) * e1
                e2 = perp / np.linalg.norm(perp)
                c = connect(r_obs, np.linalg.norm(p) / R_S, math.atan2(np.linalg.norm(perp), p @ e1), order)
                sign = 1.0 if order == 1 else -1.0
                want = cam + float(c.dt) * R_S * (math.cos(c.xi) * e1 + sign * math.sin(c.xi) * e2)
                d = np.min(np.linalg.norm(got - want, axis=1))
                # float32 vertices; 1e-5 relative of the light travel distance is a 1e-5 rad direction error
                assert d < 1e-5 * float(c.dt) * R_S + 1e-4, (f, order, d)
    fam = lutcache.family(scene.grlens.lut_r_min)
    assert fam.built <= 11  # the exact tables at 1 + exp(k/8) r_s, k = 11 ... 21, each built once
