"""Physical time in the Blender layer (pip `bpy` 4.5): scene.grlens.speed_of_light, the observer's
velocity read from its own animation without changing the frame (blender/motion.py), the images of a
moving camera and their grlens_redshift attribute, and the messages for what physical time refuses.

Units: Blender units (BU); r_s = 2 BU in the demo scene (camera at 20 r_s = 40 BU); speeds in BU per
frame."""
import math

import numpy as np
import pytest

import bpy  # noqa: E402
import mathutils  # noqa: E402

from blender_session import empty_file, registered  # noqa: E402,F401  (autouse fixtures)
from grlens_addon.blender import motion, rebuild
from grlens_addon.core import mapping, observer_view, pipeline

R_S = 2.0


def _demo():
    assert bpy.ops.grlens.demo_scene(r_s=R_S) == {"FINISHED"}
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 160, 90
    sphere = bpy.data.objects["OrbitingSphere"]
    sphere.animation_data_clear()
    sphere.parent = None
    sphere.location = (0.0, 3 * R_S, 0.02 * R_S)
    return scene, scene.camera, sphere


def _key_linear(obj, path, frames_values):
    for f, v in frames_values:
        setattr(obj, path, v)
        obj.keyframe_insert(path, frame=f)
    for fc in motion._fcurves(obj):
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"


def _attr(obj, name):
    a = obj.data.attributes.get(name)
    if a is None:
        return None
    out = np.empty(len(obj.data.vertices), np.float32)
    a.data.foreach_get("value", out)
    return out


@pytest.mark.parametrize("mode", ["XYZ", "ZXY", "QUATERNION", "AXIS_ANGLE"])
def test_world_matrices_from_keyframes_match_blenders(mode):
    """motion.world_matrix_at (keyframes evaluated at any frame, composed with the deltas and the
    parent's animated matrix) equals the matrix Blender evaluates at that frame; the velocity equals
    the difference of Blender's own matrices half a frame either side."""
    scene = bpy.context.scene
    parent = bpy.data.objects.new("Parent", None)
    child = bpy.data.objects.new("Child", None)
    for o in (parent, child):
        scene.collection.objects.link(o)
    child.parent = parent
    child.matrix_parent_inverse = mathutils.Matrix(((1, 0, 0, 0.5), (0, 0.8, -0.6, 0), (0, 0.6, 0.8, -1), (0, 0, 0, 1)))
    child.rotation_mode = mode
    child.delta_location = (0.1, -0.2, 0.3)
    child.delta_scale = (1.0, 1.5, 1.0)
    if mode == "QUATERNION":
        child.delta_rotation_quaternion = (0.9, 0.1, 0.3, 0.0)
    elif mode != "AXIS_ANGLE":
        child.delta_rotation_euler = (0.2, -0.1, 0.4)
    rot_path = {"QUATERNION": "rotation_quaternion", "AXIS_ANGLE": "rotation_axis_angle"}.get(mode, "rotation_euler")
    rot_vals = {"rotation_quaternion": [(1, 0, 0, 0), (0.7, 0.3, -0.2, 0.6), (0.2, 0.9, 0.1, -0.3)],
                "rotation_axis_angle": [(0.1, 0, 0, 1), (1.2, 0.3, 0.4, 0.8), (2.0, -0.6, 0.2, 0.7)],
                "rotation_euler": [(0, 0, 0), (0.4, 1.1, -0.3), (1.5, -0.2, 0.9)]}[rot_path]
    keys = zip((1, 6, 15), ((0, 0, 0), (3, 1, -2), (5, -4, 1)), rot_vals, ((1, 1, 1), (2, 1, 1), (1, 1, 3)))
    for f, loc, rot, sc in keys:
        child.location, child.scale = loc, sc
        setattr(child, rot_path, rot)
        for p in ("location", rot_path, "scale"):
            child.keyframe_insert(p, frame=f)
        parent.location = (f * 0.3, -f * 0.1, 2.0)
        parent.rotation_euler = (0.0, 0.05 * f, 0.1 * f)
        parent.keyframe_insert("location", frame=f)
        parent.keyframe_insert("rotation_euler", frame=f)
    for f in (3, 7.25, 12):
        scene.frame_set(int(f), subframe=f - int(f))
        got = np.array(motion.world_matrix_at(child, f))
        np.testing.assert_allclose(got, np.array(child.matrix_world), atol=2e-5)
        v = motion.velocity(scene, child, child.evaluated_get(bpy.context.evaluated_depsgraph_get()))
        ends = []
        for g in (f + motion.STEP, f - motion.STEP):
            scene.frame_set(int(math.floor(g)), subframe=g - math.floor(g))
            ends.append(np.array(child.matrix_world.translation))
        np.testing.assert_allclose(v, (ends[0] - ends[1]) / (2 * motion.STEP), atol=5e-5)
        assert np.linalg.norm(v) > 0.1


def test_velocity_of_linear_keys_and_what_it_refuses():
    """Linear keys: the exact speed; no animation: at rest; a turning constraint (Track To) is
    allowed; a constraint that moves the object, or a driver, is refused with the reason."""
    scene = bpy.context.scene
    obj = bpy.data.objects.new("Mover", None)
    target = bpy.data.objects.new("Target", None)
    for o in (obj, target):
        scene.collection.objects.link(o)
    _key_linear(obj, "location", [(1, (0.0, 0.0, 0.0)), (11, (2.0, -1.0, 0.5))])
    scene.frame_set(4)
    np.testing.assert_allclose(motion.velocity(scene, obj), [0.2, -0.1, 0.05], atol=1e-7)
    np.testing.assert_array_equal(motion.velocity(scene, target), 0.0)
    con = obj.constraints.new("TRACK_TO")
    con.target = target
    scene.frame_set(5)
    dg = bpy.context.evaluated_depsgraph_get()
    np.testing.assert_allclose(motion.velocity(scene, obj, obj.evaluated_get(dg)), [0.2, -0.1, 0.05], atol=1e-7)
    obj.constraints.new("COPY_LOCATION").target = target
    with pytest.raises(motion.MotionError, match="copy location constraint"):
        motion.velocity(scene, obj, obj.evaluated_get(dg))
    obj.constraints.clear()
    drv = obj.driver_add("location", 2).driver
    drv.expression = "frame * 0.1"
    scene.frame_set(6)
    with pytest.raises(motion.MotionError, match="keyframes alone"):
        motion.velocity(scene, obj, obj.evaluated_get(bpy.context.evaluated_depsgraph_get()))


def test_a_moving_camera_aberrates_the_images_and_writes_their_1_plus_z():
    """With speed_of_light > 0 the camera's keyed motion gives beta (static frame), the images are the
    core's for that beta, every image vertex carries grlens_redshift = 1 + z (as the core computes
    it, to float32), and the status says the camera's speed; back to 0, the images are the stills'
    again, without the attribute."""
    scene, cam, sphere = _demo()
    x0 = np.array(cam.location)
    _key_linear(cam, "location", [(1, tuple(x0)), (21, tuple(x0 + np.array([-4.0, 6.0, 1.0])))])
    scene.frame_set(11)
    still = {o: np.array([v.co[:] for v in bpy.data.objects[f"OrbitingSphere.GR{o}"].data.vertices]) for o in (1, 2)}
    assert _attr(bpy.data.objects["OrbitingSphere.GR1"], "grlens_redshift") is None
    c = 1.5  # BU per frame
    scene.grlens.speed_of_light = c
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    v = np.array([-4.0, 6.0, 1.0]) / 20
    pos = np.array(cam.matrix_world.translation)
    beta = observer_view.static_frame_beta(pos, v, np.zeros(3), R_S, c)[0]
    assert f"camera at {np.linalg.norm(beta):.3g} c" in scene.grlens.status, scene.grlens.status
    geo = mapping.Scene(pos, np.zeros(3), R_S, beta=beta)
    dg = bpy.context.evaluated_depsgraph_get()
    src = rebuild._extract(sphere.evaluated_get(dg))
    settings = rebuild.scene_geometry(scene, dg)[1]
    from grlens_addon.blender import lutcache

    expect = pipeline.build_images(src, geo, lutcache.get_table(scene.grlens, geo.r_obs), settings, None,
                                   rebuild.frustum_planes(scene, cam))
    for order in (1, 2):
        obj = bpy.data.objects[f"OrbitingSphere.GR{order}"]
        got = np.array([vv.co[:] for vv in obj.data.vertices])
        assert got.shape == expect[order].positions.shape
        np.testing.assert_allclose(got, expect[order].positions, atol=1e-5 * 40)
        z = _attr(obj, "grlens_redshift")
        np.testing.assert_allclose(z, expect[order].redshift, rtol=1e-5)  # the keys' float32 velocity
        assert got.shape != still[order].shape or not np.allclose(got, still[order], atol=1e-3)
    scene.grlens.speed_of_light = 0.0
    assert bpy.ops.grlens.rebuild() == {"FINISHED"}
    for order in (1, 2):
        obj = bpy.data.objects[f"OrbitingSphere.GR{order}"]
        np.testing.assert_array_equal(np.array([vv.co[:] for vv in obj.data.vertices]), still[order])
        assert _attr(obj, "grlens_redshift") is None


@pytest.mark.parametrize("problem", ["negative", "moving_hole", "too_fast", "constrained"])
def test_physical_time_refuses_bad_input_with_a_message(problem):
    scene, cam, sphere = _demo()
    g = scene.grlens
    g.speed_of_light = 2.0
    if problem == "negative":
        g.speed_of_light = -1.0
        expect = "speed of light must be positive"
    elif problem == "moving_hole":
        _key_linear(g.black_hole, "location", [(1, (0.0, 0.0, 0.0)), (11, (0.0, 1.0, 0.0))])
        expect = "black hole 'BlackHole' moves"
    elif problem == "too_fast":
        _key_linear(cam, "location", [(1, (40.0, 0.0, 0.0)), (3, (40.0, 4.0, 0.0))])
        expect = "raise speed_of_light or slow the camera"
    else:
        cam.constraints.new("FOLLOW_PATH")
        expect = "follow path constraint"
    scene.frame_set(2)
    rebuild.rebuild_scene(scene)
    assert g.status.startswith("grlens:") and expect in g.status, g.status
    g.speed_of_light = 0.0
    rebuild.rebuild_scene(scene)
    assert not g.status.startswith("grlens:"), g.status


def test_a_marker_cut_starts_from_the_new_cameras_own_motion():
    """At a timeline marker that switches to a camera moving on its own, beta is that camera's (not a
    difference across the cut)."""
    scene, cam, sphere = _demo()
    cam_b = bpy.data.objects.new("CameraB", cam.data)
    scene.collection.objects.link(cam_b)
    cam_b.rotation_euler = cam.rotation_euler
    _key_linear(cam_b, "location", [(1, (0.0, 40.0, 0.0)), (21, (0.0, 40.0, 4.0))])
    scene.timeline_markers.new("A", frame=1).camera = cam
    scene.timeline_markers.new("B", frame=10).camera = cam_b
    scene.grlens.speed_of_light = 1.0
    for frame, v in ((9, np.zeros(3)), (10, np.array([0.0, 0.0, 0.2]))):
        scene.frame_set(frame)
        assert bpy.ops.grlens.rebuild() == {"FINISHED"}
        pos = np.array(rebuild.observer_camera(scene).matrix_world.translation)
        beta = observer_view.static_frame_beta(pos, v, np.zeros(3), R_S, 1.0)[0]
        assert f"camera at {np.linalg.norm(beta):.3g} c" in scene.grlens.status, scene.grlens.status


def _cam_at(scene, cam, frame):
    scene.frame_set(frame)
    return np.array(cam.matrix_world.translation), -np.array(cam.matrix_world.to_3x3().col[2])


def test_the_orbit_operator_keys_the_circular_geodesic_in_coordinate_time():
    """bpy.ops.grlens.camera_geodesic(path="ORBIT"): the camera's keys are the circular orbit at its
    distance in coordinate time (one frame = c / r_s), it looks at the hole, and the rebuild reads
    back the orbital speed 1/sqrt(2 (r - 1)) c (seed 002, eq. 10) from the keys."""
    from grlens_addon.core import camera_geodesics

    scene, cam, sphere = _demo()
    g = scene.grlens
    g.speed_of_light = 2.0  # BU per frame: one frame is 1 r_s / c
    start = np.array(cam.matrix_world.translation)
    assert bpy.ops.grlens.camera_geodesic(path="ORBIT", axis=(0.0, 0.0, 1.0), look="HOLE", frame_start=1,
                                          frame_end=40) == {"FINISHED"}
    expect = camera_geodesics.orbit_path(np.arange(40.0), start, np.zeros(3), R_S, np.array([0.0, 0.0, 1.0]))
    for f in (1, 17, 40):
        pos, view = _cam_at(scene, cam, f)
        np.testing.assert_allclose(pos, expect.position[f - 1], atol=2e-5)
        np.testing.assert_allclose(view, -pos / np.linalg.norm(pos), atol=1e-5)
    scene.frame_set(20)
    rebuild.rebuild_scene(scene)
    speed = 1 / math.sqrt(2 * (20 - 1))
    assert f"camera at {speed:.3g} c" in g.status, g.status
    beta = rebuild.observer_beta(scene, cam, cam, g.black_hole, g.black_hole, mapping.Scene(
        np.array(cam.matrix_world.translation), np.zeros(3), R_S))
    np.testing.assert_allclose(np.linalg.norm(beta), speed, rtol=1e-4)


def test_the_fall_operator_keys_the_radial_fall_down_to_the_innermost_camera():
    """path="FALL" from rest at infinity: the keys follow core.camera_geodesics.fall_path down to the
    innermost camera grlens images for (lutgen.rays.R_OBS_MIN, inside the photon sphere); looking along
    the motion, the camera faces the hole; the rebuild reads the escape speed sqrt(r_s / r) c."""
    from lutgen.rays import R_OBS_MIN
    from grlens_addon.core import camera_geodesics

    scene, cam, sphere = _demo()
    g = scene.grlens
    g.speed_of_light = 4.0  # one frame is 2 r_s / c
    start = np.array(cam.matrix_world.translation)
    assert bpy.ops.grlens.camera_geodesic(path="FALL", release_radius=0.0, look="MOTION", frame_start=1,
                                          frame_end=300) == {"FINISHED"}
    t = np.arange(300.0) * 2.0
    expect = camera_geodesics.fall_path(t, start, np.zeros(3), R_S)
    last = int(np.flatnonzero(expect.r >= R_OBS_MIN)[-1]) + 1
    fc = [f for f in motion._fcurves(cam) if f.data_path == "location"][0]
    assert len(fc.keyframe_points) == last < 300
    for f in (1, last // 2, last):
        pos, view = _cam_at(scene, cam, f)
        np.testing.assert_allclose(pos, expect.position[f - 1], atol=2e-5)
        np.testing.assert_allclose(view, -pos / np.linalg.norm(pos), atol=1e-5)
    f = last // 2
    scene.frame_set(f)
    rebuild.rebuild_scene(scene)
    beta = rebuild.observer_beta(scene, cam, cam, g.black_hole, g.black_hole, mapping.Scene(
        np.array(cam.matrix_world.translation), np.zeros(3), R_S))
    np.testing.assert_allclose(np.linalg.norm(beta), np.sqrt(1 / expect.r[f - 1]), rtol=2e-3)


def test_the_geodesic_operator_warns_inside_the_isco_and_refuses_what_it_cannot_key():
    from grlens_addon.blender import geodesic_camera

    scene, cam, sphere = _demo()
    g = scene.grlens
    with pytest.raises(ValueError, match="speed_of_light first"):
        geodesic_camera.key_geodesic(scene, "ORBIT")
    g.speed_of_light = 1.0
    cam.location = (5.0, 0.0, 0.0)  # 2.5 r_s
    n, note = geodesic_camera.key_geodesic(scene, "ORBIT", frame_start=1, frame_end=10)
    assert n == 10 and note.startswith("warning") and "innermost stable" in note
    cam.animation_data_clear()
    cam.location = (2.8, 0.0, 0.0)  # 1.4 r_s
    scene.frame_set(1)
    with pytest.raises(ValueError, match="photon sphere"):
        geodesic_camera.key_geodesic(scene, "ORBIT")
    cam.location = (40.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="release radius"):
        geodesic_camera.key_geodesic(scene, "FALL", release_radius=10.0)
    assert "Camera" == cam.name and bpy.ops.grlens.camera_geodesic.idname() == "GRLENS_OT_camera_geodesic"


class _Op:
    """Stands in for an operator's self: its properties, and the reports it makes."""

    def __init__(self, **props):
        self.__dict__.update(props)
        self.reports = []

    def report(self, kind, text):
        self.reports.append((set(kind), text))


def test_the_two_geodesic_operators_have_only_their_own_options():
    ops = bpy.ops.grlens
    fall = {p.identifier for p in ops.camera_fall.get_rna_type().properties} - {"rna_type"}
    orbit = {p.identifier for p in ops.camera_orbit.get_rna_type().properties} - {"rna_type"}
    assert fall == {"release_radius", "look", "frame_start", "frame_end"}, fall
    assert orbit == {"axis", "look", "frame_start", "frame_end"}, orbit


@pytest.mark.parametrize("look", ["HOLE", "MOTION"])
def test_camera_orbit_keys_the_circular_orbit_looking_where_asked(look):
    """bpy.ops.grlens.camera_orbit: keys on core.camera_geodesics.orbit_path (one frame = 1 r_s/c here),
    about the given axis; looking at the hole, or along the velocity (the orbit's tangent)."""
    from grlens_addon.core import camera_geodesics

    scene, cam, sphere = _demo()
    scene.grlens.speed_of_light = 2.0
    start = np.array(cam.matrix_world.translation)
    axis = np.array([0.0, 0.3, 1.0])
    assert bpy.ops.grlens.camera_orbit(axis=axis, look=look, frame_start=1, frame_end=30) == {"FINISHED"}
    expect = camera_geodesics.orbit_path(np.arange(30.0), start, np.zeros(3), R_S, axis)
    assert expect.stable
    for f in (1, 12, 30):
        pos, view = _cam_at(scene, cam, f)
        np.testing.assert_allclose(pos, expect.position[f - 1], atol=2e-5)
        want = -pos if look == "HOLE" else expect.velocity[f - 1]
        np.testing.assert_allclose(view, want / np.linalg.norm(want), atol=1e-5)
    if look == "MOTION":  # along the motion is across the line of sight to the hole on a circle
        assert abs(float(view @ pos)) < 1e-4 * np.linalg.norm(pos)


def test_camera_orbit_warns_inside_the_isco_and_not_outside():
    """The operator's execute: inside 3 r_s a WARNING naming the innermost stable orbit (and the keys
    still made), outside an INFO with the period; without a speed of light an ERROR, nothing keyed."""
    from grlens_addon.blender import geodesic_camera

    scene, cam, sphere = _demo()
    op = _Op(axis=(0.0, 0.0, 1.0), look="HOLE", frame_start=1, frame_end=5)
    assert geodesic_camera.GRLENS_OT_camera_orbit.execute(op, bpy.context) == {"CANCELLED"}
    assert op.reports[-1][0] == {"ERROR"} and cam.animation_data is None
    scene.grlens.speed_of_light = 1.0
    for r, kind in ((2.5, "WARNING"), (3.2, "INFO")):
        cam.animation_data_clear()
        cam.location = (r * R_S, 0.0, 0.0)
        scene.frame_set(1)
        assert geodesic_camera.GRLENS_OT_camera_orbit.execute(op, bpy.context) == {"FINISHED"}
        got, text = op.reports[-1]
        assert got == {kind}, text
        assert ("innermost stable" in text) == (kind == "WARNING"), text
        assert text.startswith("keyed 5 frames")
        np.testing.assert_allclose(_cam_at(scene, cam, 5)[0], _kepler_orbit(r, 4.0 * 1.0 / R_S),
                                   atol=2e-5)


def _kepler_orbit(r, t):
    """The circular orbit at r (r_s) through (r R_S, 0, 0) about +z at coordinate time t (r_s/c), by
    Kepler's law in coordinate time (Omega = sqrt(1 / (2 r^3)) c / r_s): an independent closed form."""
    w = math.sqrt(1.0 / (2.0 * r ** 3))
    return np.array([r * R_S * math.cos(w * t), r * R_S * math.sin(w * t), 0.0])


@pytest.mark.parametrize("release", [0.0, 30.0])
def test_camera_fall_keys_the_radial_fall_from_rest_where_asked(release):
    """bpy.ops.grlens.camera_fall from rest at infinity or at 30 r_s (the camera at 20 r_s): keys on
    core.camera_geodesics.fall_path; the speed read back by the rebuild is the fall's local speed
    sqrt((1/r - 1/r0) / (1 - 1/r0)) c (seed 002); looking at the hole (the default)."""
    from grlens_addon.core import camera_geodesics

    scene, cam, sphere = _demo()
    g = scene.grlens
    g.speed_of_light = 4.0  # one frame is 2 r_s / c
    start = np.array(cam.matrix_world.translation)
    assert bpy.ops.grlens.camera_fall(release_radius=release, frame_start=1, frame_end=20) == {"FINISHED"}
    r0 = math.inf if release == 0 else release
    expect = camera_geodesics.fall_path(np.arange(20.0) * 2.0, start, np.zeros(3), R_S, r0)
    for f in (1, 10, 20):
        pos, view = _cam_at(scene, cam, f)
        np.testing.assert_allclose(pos, expect.position[f - 1], atol=2e-5)
        np.testing.assert_allclose(view, -pos / np.linalg.norm(pos), atol=1e-5)
    scene.frame_set(10)
    rebuild.rebuild_scene(scene)
    beta = rebuild.observer_beta(scene, cam, cam, g.black_hole, g.black_hole, mapping.Scene(
        np.array(cam.matrix_world.translation), np.zeros(3), R_S))
    r = expect.r[9]
    local = math.sqrt((1 / r - 1 / r0) / (1 - 1 / r0))
    np.testing.assert_allclose(np.linalg.norm(beta), local, rtol=2e-3)
    with pytest.raises(RuntimeError, match="release radius"):  # inside the camera's 20 r_s: its error report
        bpy.ops.grlens.camera_fall(release_radius=10.0)


def test_the_speed_of_light_from_a_crossing_time_or_a_real_hole():
    """set_speed_of_light: r_s/c = 10 frames gives c = r_s / 10; Sagittarius A* (4.3 million suns,
    r_s = 1.27e7 km, r_s/c = 42.4 s) at 24 frames per second, 1017 frames; bad input is refused."""
    from grlens_addon.blender import geodesic_camera

    scene = bpy.context.scene
    scene.grlens.r_s = 2.0
    assert bpy.ops.grlens.set_speed_of_light(mode="FRAMES", frames=10.0) == {"FINISHED"}
    assert scene.grlens.speed_of_light == pytest.approx(0.2)
    scene.render.fps, scene.render.fps_base = 24, 1.0
    assert bpy.ops.grlens.set_speed_of_light(mode="PHYSICAL", mass=4.3e6) == {"FINISHED"}
    n = 4.3e6 * 2 * 6.6743e-11 * 1.98841e30 / 299792458.0 ** 3 * 24  # G M / c^3 in seconds, times 2 and fps
    assert 1010 < n < 1025
    assert scene.grlens.speed_of_light == pytest.approx(2.0 / n, rel=1e-6)
    assert geodesic_camera.frames_per_crossing("PHYSICAL", r_s_km=299792.458, fps=30) == pytest.approx(30)
    with pytest.raises(ValueError, match="positive"):
        geodesic_camera.frames_per_crossing("PHYSICAL", mass=0.0)


class _Layout:
    """Stands in for a UILayout: records every prop/operator/label drawn."""

    def __init__(self, drawn):
        self.drawn = drawn

    def __getattr__(self, name):
        if name in ("column", "row", "box", "split"):
            return lambda *a, **k: self
        if name in ("prop", "operator", "label", "separator", "prop_search", "template_list"):
            return lambda *a, **k: self.drawn.append((name, a, k))
        raise AttributeError(name)


def test_the_panel_draws_physical_time():
    """The Physical Time panel shows the speed of light with its helper and the geodesic operator, and
    while a speed of light is set, r_s/c in frames."""
    from grlens_addon.blender import panels

    scene, cam, sphere = _demo()
    for c in (0.0, 0.5):
        scene.grlens.speed_of_light = c
        drawn = []
        fake = type("P", (), {"layout": _Layout(drawn)})()
        panels.VIEW3D_PT_grlens_physical_time.draw(fake, bpy.context)
        ops = [a[0] for kind, a, k in drawn if kind == "operator"]
        labels = [k.get("text", a[0] if a else "") for kind, a, k in drawn if kind == "label"]
        assert "grlens.set_speed_of_light" in ops
        assert "grlens.camera_fall" in ops and "grlens.camera_orbit" in ops
        assert any("r_s/c = 4 frames" in t for t in labels) == (c > 0), labels


def _shift_quads(tmp_path, z, z_grav, rgb):
    """Quads (one per entry of ``z``) with grlens_redshift = z and grlens_redshift_gravity = z_grav, in
    an emission material through "grlens Shifted Colour" of colour ``rgb``, under an orthographic
    camera; returns (render(strength) -> (len(z), 3) colours at the quads' middles, group node)."""
    import OpenEXR

    from grlens_addon.blender import shading

    scene = bpy.context.scene
    verts, faces = [], []
    for i in range(len(z)):
        x0 = 2.0 * i
        verts += [(x0, 0, 0), (x0 + 1.6, 0, 0), (x0 + 1.6, 1.6, 0), (x0, 1.6, 0)]
        faces.append((4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3))
    me = bpy.data.meshes.new("Quads")
    me.from_pydata(verts, [], faces)
    for name, values in (("grlens_redshift", z), ("grlens_redshift_gravity", z_grav)):
        if values is not None:
            a = me.attributes.new(name, "FLOAT", "POINT")
            a.data.foreach_set("value", np.repeat(np.array(values, np.float32), 4))
    obj = bpy.data.objects.new("Quads", me)
    scene.collection.objects.link(obj)
    mat = bpy.data.materials.new("Shifted")
    mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    grp = nt.nodes.new("ShaderNodeGroup")
    grp.node_tree = shading.ensure_shift_node_group()
    assert shading.ensure_shift_node_group() is grp.node_tree  # never duplicated
    grp.inputs["Color"].default_value = (*rgb, 1.0)
    emit = nt.nodes.new("ShaderNodeEmission")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(grp.outputs["Color"], emit.inputs["Color"])
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    me.materials.append(mat)
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 2.0 * len(z)
    cam.location = (len(z) - 0.2, 0.8, 5.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x, r.resolution_y, r.resolution_percentage = 20 * len(z), 20, 100
    r.filter_size = 0.01
    scene.cycles.samples = 1
    scene.cycles.use_denoising = False
    scene.view_settings.view_transform = "Standard"
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"

    def render(strength):
        grp.inputs["Strength"].default_value = strength
        r.filepath = str(tmp_path / f"q{strength}.exr")
        bpy.ops.render.render(write_still=True)
        ch = OpenEXR.File(r.filepath, separate_channels=True).parts[0].channels
        img = np.stack([np.asarray(ch[c].pixels, dtype=np.float64) for c in ("R", "G", "B")], -1)
        return img[10, [10 * (2 * i) + 8 for i in range(len(z))]]  # each quad's middle (0.1 BU per pixel)

    return render, grp


def _expected_shift(rgb, z, z_grav, strength=1.0, gravity=True, colour=True, beaming=True):
    """The group's colour by its formula, from core.spectrum."""
    from grlens_addon.core import spectrum

    ln_total = -np.log(z) if z > 0 else 0.0
    ln_grav = -np.log(z_grav) if z_grav and z_grav > 0 else 0.0
    motion, grav = ln_total - ln_grav, ln_grav * gravity
    ln_hue, ln_bright = strength * (motion * colour + grav), strength * (motion * beaming + grav)
    g = np.exp(ln_hue)
    return np.maximum(spectrum.shift_matrix(g) @ rgb / g ** 5 * np.exp(5 * ln_bright), 0.0)


def test_the_shifted_colour_group_renders_the_shifted_spectrum(tmp_path):
    """The "grlens Shifted Colour" node group in an emission material, rendered by Cycles on quads
    whose grlens_redshift is 1 + z = 0.8, 1, 1.25, 1.6 and 0 (none): each shows max(M(g) rgb, 0) of
    core.spectrum with g = 1 / (1 + z) (to the curves' accuracy), and at Strength 0 the colour itself."""
    z = [0.8, 1.0, 1.25, 1.6, 0.0]
    rgb = np.array([0.8, 0.5, 0.2])
    render, _ = _shift_quads(tmp_path, z, None, rgb)
    got = render(1.0)
    for i, zi in enumerate(z):
        want = _expected_shift(rgb, zi, None)
        np.testing.assert_allclose(got[i], want, rtol=5e-3, atol=5e-3 * max(1.0, want.max()), err_msg=str(zi))
    np.testing.assert_allclose(render(0.0), np.tile(rgb, (len(z), 1)), atol=1e-5)


@pytest.mark.parametrize("switches", [(True, True, False), (True, False, True), (False, True, True),
                                      (False, False, False)])
def test_the_teaching_switches_take_parts_of_the_shift_out(tmp_path, switches):
    """scene.grlens.use_gravitational_shift / use_doppler_colour / use_beaming: the group leaves the
    gravitational part (grlens_redshift_gravity) out of the shift, or the motions' part out of the
    hue or the brightness, as its formula says; Strength 0.5 halves every ln g."""
    grav_on, colour_on, beaming_on = switches
    z, zg = [0.8, 1.3, 1.1], [1.2, 1.2, 0.9]
    rgb = np.array([0.3, 0.6, 0.9])
    scene = bpy.context.scene
    render, grp = _shift_quads(tmp_path, z, zg, rgb)
    g = scene.grlens
    g.use_gravitational_shift, g.use_doppler_colour, g.use_beaming = grav_on, colour_on, beaming_on
    from grlens_addon.blender import shading

    assert grp.node_tree.nodes[shading.SWITCHES["use_beaming"]].outputs[0].default_value == float(beaming_on)
    for strength in (1.0, 0.5):
        got = render(strength)
        for i in range(len(z)):
            want = _expected_shift(rgb, z[i], zg[i], strength, grav_on, colour_on, beaming_on)
            np.testing.assert_allclose(got[i], want, rtol=5e-3, atol=5e-3 * max(1.0, want.max()),
                                       err_msg=f"{switches} {strength} {z[i]}")


def test_setting_a_speed_of_light_creates_the_shifted_colour_group():
    from grlens_addon.blender import shading

    assert bpy.data.node_groups.get(shading.SHIFT_GROUP_NAME) is None
    bpy.context.scene.grlens.speed_of_light = 0.5
    assert bpy.data.node_groups.get(shading.SHIFT_GROUP_NAME) is not None


def test_aberration_off_keeps_the_stills_images_and_shifts_their_light():
    """use_aberration off (teaching): a moving camera's images are the still's, with grlens_redshift
    (its motion's shift) and grlens_redshift_gravity on every vertex."""
    scene, cam, sphere = _demo()
    x0 = np.array(cam.location)
    _key_linear(cam, "location", [(1, tuple(x0)), (21, tuple(x0 + np.array([-4.0, 6.0, 1.0])))])
    scene.frame_set(11)
    still = np.array([v.co[:] for v in bpy.data.objects["OrbitingSphere.GR1"].data.vertices])
    scene.grlens.speed_of_light = 1.5
    scene.grlens.use_aberration = False
    rebuild.rebuild_scene(scene)
    obj = bpy.data.objects["OrbitingSphere.GR1"]
    np.testing.assert_array_equal(np.array([v.co[:] for v in obj.data.vertices]), still)
    z, zg = _attr(obj, "grlens_redshift"), _attr(obj, "grlens_redshift_gravity")
    assert z is not None and zg is not None and np.all(zg > 1) and not np.allclose(z, zg, rtol=1e-3)


def test_velocity_at_the_first_and_last_keys_is_not_halved():
    """At the first and last keys (held beyond them) the velocity is one-sided, not half the slope."""
    scene = bpy.context.scene
    obj = bpy.data.objects.new("Mover", None)
    scene.collection.objects.link(obj)
    _key_linear(obj, "location", [(1, (0.0, 0.0, 0.0)), (11, (2.0, -1.0, 0.5))])
    for f in (1, 6, 11):
        scene.frame_set(f)
        np.testing.assert_allclose(motion.velocity(scene, obj), [0.2, -0.1, 0.05], atol=1e-6)
    scene.frame_set(15)
    np.testing.assert_allclose(motion.velocity(scene, obj), 0.0, atol=1e-9)  # held after the last key
