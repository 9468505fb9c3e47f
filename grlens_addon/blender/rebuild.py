"""Per-frame rebuild: evaluated source meshes -> image objects ``<name>.GR1`` / ``<name>.GR2``.

Runs the numeric core (``grlens_addon.core.pipeline``) for every object with ``obj.grlens.enabled``
and uploads the results into mesh objects in the ``grlens`` collection. Source objects and their
meshes are never modified (only their camera visibility is switched off while they are lensed, and
restored when they are not: see _set_source_visibility). Units: Blender units; r_s from
``scene.grlens.r_s``.
"""
from __future__ import annotations

import math
import time
import uuid

import bpy
import numpy as np

from ..core import budget, culling, losses, mapping, observer_view, pipeline
from . import gather, lutcache, motion, shading, upload, world

COLLECTION = "grlens"


class RebuildError(Exception):
    """A scene-level problem that prevents any image (missing hole or camera, camera inside...)."""


class _WorldOnly(Exception):
    """No object is marked but the world is lensed: the rebuild's status is the world's."""


def _collection(scene):
    coll = bpy.data.collections.get(COLLECTION)
    if coll is None:
        coll = bpy.data.collections.new(COLLECTION)
    if coll.name not in scene.collection.children:
        scene.collection.children.link(coll)
    return coll


def is_image_object(obj) -> bool:
    return obj.grlens.order in (1, 2)


def sources(scene):
    """The objects of ``scene`` marked for lensing (``obj.grlens.enabled``), of any type: those that
    cannot be imaged are skipped with a reason by the rebuild (see gather.py)."""
    return [o for o in scene.objects if o.grlens.enabled and not is_image_object(o)]


def _extract(obj_eval, with_normals: bool = True) -> pipeline.SourceMesh:
    """World-space triangles, corner UVs, material indices and (only GR illumination uses them:
    ``with_normals``) corner normals of an evaluated object's own mesh: :func:`gather.extract`."""
    return gather.extract(obj_eval, with_normals)


def active_camera(scene):
    """The scene's active camera for its current frame: the camera of the timeline marker that binds
    one at or before the frame (the latest; the earliest marker's when none is before; cameras hidden
    for render skipped), as Blender switches cameras, else ``scene.camera``. (``scene.frame_set``
    switches ``scene.camera`` only after the frame handlers have run.)"""
    best, first = None, None
    f = scene.frame_current
    for m in scene.timeline_markers:
        cam = m.camera
        if cam is None or cam.hide_render:
            continue
        if m.frame <= f and (best is None or m.frame > best.frame):
            best = m
        if first is None or m.frame < first.frame:
            first = m
    m = best or first
    return m.camera if m is not None else scene.camera


def observer_camera(scene):
    """The camera whose view is lensed: ``scene.grlens.observer`` if set, else the active camera
    (:func:`active_camera`)."""
    obs = scene.grlens.observer
    return obs if obs is not None else active_camera(scene)


def half_tangents(scene, cam) -> tuple[float, float]:
    """(tan of the horizontal half angle, tan of the vertical half angle) of a perspective camera's
    actual frame for the scene's render settings (sensor fit and aspect ratio taken into account)."""
    frame = np.array([tuple(v) for v in cam.data.view_frame(scene=scene)])  # camera space, z < 0
    return (np.max(np.abs(frame[:, 0])) / np.max(np.abs(frame[:, 2])),
            np.max(np.abs(frame[:, 1])) / np.max(np.abs(frame[:, 2])))


def camera_rotation(cam) -> np.ndarray:
    """(3, 3) camera-to-world rotation of ``cam`` (its matrix_world without the object's scale)."""
    mw = np.array(cam.matrix_world, dtype=np.float64)
    return mw[:3, :3] / np.linalg.norm(mw[:3, :3], axis=0)


def _pixel_angle(scene, cam):
    """Radians per pixel on the view sphere for the observer camera and the render resolution: for a
    perspective camera its actual frame (sensor fit and aspect ratio taken into account); for Cycles'
    equirectangular and fisheye-equidistant panoramas their angular resolution (the reference
    tracer's camera of the same kind, raytrace.Camera.pixel_angle); otherwise a generous estimate."""
    r = scene.render
    px_x = max(r.resolution_x * r.resolution_percentage / 100.0, 1.0)
    px_y = max(r.resolution_y * r.resolution_percentage / 100.0, 1.0)
    if cam.type == "CAMERA" and cam.data.type == "PANO":
        from . import check  # (check uses this module's camera helpers)

        try:
            return check.check_camera(scene, cam, 100).pixel_angle
        except ValueError:  # another panorama type (or lens shift): the estimate below
            pass
    if cam.type != "CAMERA" or cam.data.type != "PERSP":
        return math.radians(60.0) / max(px_x, px_y)  # orthographic/other panoramas: a generous estimate
    half_x, half_y = half_tangents(scene, cam)
    return min(2.0 * math.atan(half_x) / px_x, 2.0 * math.atan(half_y) / px_y)


FRUSTUM_MARGIN = 0.05
"""Extra field of view kept around the frustum (fraction of its half-angles), so that image
triangles whose curved edges bulge into the view are not culled by their straight edges."""


def frustum_planes(scene, cam):
    """(4, 4) world-space side planes (n, d), n . x + d >= 0 inside, of a perspective observer camera
    (widened by FRUSTUM_MARGIN), or None for other cameras (nothing is culled by the frustum then)."""
    if cam.type != "CAMERA" or cam.data.type != "PERSP":
        return None
    frame = [np.array(v) for v in cam.data.view_frame(scene=scene)]  # camera space, z = -distance
    corners = np.array([[v[0] * (1 + FRUSTUM_MARGIN), v[1] * (1 + FRUSTUM_MARGIN), v[2]] for v in frame])
    return culling.side_planes(np.array(cam.matrix_world.translation, dtype=np.float64),
                               corners @ camera_rotation(cam).T)


def max_error_px(g, preview: bool = False) -> float | None:
    """The screen-space tolerance (pixels; None: eq. 19 alone) of a rebuild: ``tess_max_error``, or for a
    viewport preview the larger of it and ``tess_max_error_viewport`` (when that is set)."""
    tol = g.tess_max_error
    if preview and g.tess_max_error_viewport > 0:
        tol = max(tol, g.tess_max_error_viewport) if tol > 0 else g.tess_max_error_viewport
    return tol or None


def check_settings(scene) -> None:
    """Refuse, with a RebuildError saying what to change, the scene settings no image can be built
    from: no camera, an observer that is not a camera, no black hole, r_s not a positive finite
    length. (Nothing is clamped: a wrong value is named.)"""
    g = scene.grlens
    cam = observer_camera(scene)
    if cam is None:
        raise RebuildError("the scene has no camera (set scene.camera or scene.grlens.observer)")
    if cam.type != "CAMERA":
        which = "scene.grlens.observer" if g.observer is not None else "the scene's camera"
        raise RebuildError(f"the observer '{cam.name}' ({which}) is a {cam.type.lower()}, not a camera")
    if g.black_hole is None:
        raise RebuildError("no black hole object is set (scene.grlens.black_hole)")
    if not (math.isfinite(g.r_s) and g.r_s > 0):
        raise RebuildError(f"the Schwarzschild radius must be a positive length (scene.grlens.r_s = {g.r_s:g})")
    if not (math.isfinite(g.speed_of_light) and g.speed_of_light >= 0):
        raise RebuildError(f"the speed of light must be positive, or 0 for stills (scene.grlens.speed_of_light = "
                           f"{g.speed_of_light:g})")


GEOMETRY_TYPES = ("MESH", "CURVE", "SURFACE", "FONT", "META", "CURVES", "POINTCLOUD", "VOLUME")
"""Object types that render geometry of their own (a black hole object of such a type shows)."""


def hole_notes(scene) -> list[str]:
    """Report lines about the black hole object: one that renders geometry of its own (a mesh used
    as the hole) shows as that geometry inside the shadow."""
    hole = scene.grlens.black_hole
    if hole is not None and hole.type in GEOMETRY_TYPES and not hole.hide_render:
        return [f"the black hole '{hole.name}' is a {hole.type.lower()} and renders inside the shadow: "
                "use Add > Black Hole (an empty that never renders), or hide it from renders"]
    return []


def scene_geometry(scene, depsgraph, preview: bool = False):
    """(mapping.Scene, core Settings, evaluated observer camera) or RebuildError; ``preview``: the
    viewport's tolerance (:func:`max_error_px`)."""
    check_settings(scene)
    g = scene.grlens
    cam = observer_camera(scene)
    cam_eval = cam.evaluated_get(depsgraph)
    hole_eval = g.black_hole.evaluated_get(depsgraph)
    cam_pos = np.array(cam_eval.matrix_world.translation)
    hole_pos = np.array(hole_eval.matrix_world.translation)
    for what, obj, pos in (("camera", cam, cam_pos), ("black hole", g.black_hole, hole_pos)):
        if not np.all(np.isfinite(pos)):
            raise RebuildError(f"the {what} '{obj.name}' has a location that is not a finite number")
    geo = mapping.Scene(cam_pos, hole_pos, g.r_s)
    r_obs = geo.r_obs
    if r_obs <= 1.0:
        raise RebuildError(f"the camera is inside the event horizon (r = {r_obs:.4g} r_s)")
    from lutgen.rays import R_OBS_MIN
    if r_obs < R_OBS_MIN:
        raise RebuildError(f"the camera is too close to the horizon (r = {r_obs:.6g} r_s): the images need "
                           f"r >= {R_OBS_MIN} r_s")
    if g.speed_of_light > 0:
        geo.beta = observer_beta(scene, cam, cam_eval, g.black_hole, hole_eval, geo)
        geo.aberration = bool(g.use_aberration)
    orders = tuple(o for o, on in ((1, g.show_order_1), (2, g.show_order_2)) if on)
    settings = pipeline.Settings(max_tess_level=g.max_tess_level, tess_a=g.tess_a, tess_b=g.tess_b,
                                 cull_ratio=g.cull_ratio, orders=orders,
                                 pixel_angle=_pixel_angle(scene, cam_eval),
                                 max_error_px=max_error_px(g, preview), max_triangles=g.max_triangles)
    return geo, settings, cam_eval


HOLE_AT_REST = 1e-7
"""Largest speed of the black hole (r_s per frame) that counts as at rest when frames measure
physical time (float32 keyframes of a hole that does not move differ by less)."""


def observer_beta(scene, cam, cam_eval, hole, hole_eval, geo) -> np.ndarray:
    """(3,) the observer camera's velocity (units of c, world axes) in its local static frame, from its
    own animation (motion.velocity: no frame change; the camera of a timeline marker by its own
    motion, so a cut starts from the new camera's motion) and ``scene.grlens.speed_of_light`` (BU per
    frame, > 0): observer_view.static_frame_beta. RebuildError when the hole moves, when either's
    motion cannot be read from its keyframes, or when the camera moves at or above the speed of light
    in the static frame."""
    g = scene.grlens
    try:
        v_hole = motion.velocity(scene, hole, hole_eval)
        v_cam = motion.velocity(scene, cam, cam_eval)
    except motion.MotionError as exc:
        raise RebuildError(f"physical time needs the camera's and the black hole's motion from their keyframes: "
                           f"{exc}") from None
    if np.linalg.norm(v_hole) > HOLE_AT_REST * g.r_s:
        raise RebuildError(f"the black hole '{hole.name}' moves ({np.linalg.norm(v_hole):.4g} BU per frame): with "
                           "physical time (speed_of_light > 0) it must stay at rest")
    beta = observer_view.static_frame_beta(geo.camera, v_cam, geo.hole, g.r_s, g.speed_of_light)[0]
    speed = float(np.linalg.norm(beta))
    if not speed < 1.0:
        raise RebuildError(f"the camera '{cam.name}' moves at {speed:.4g} c in the local static frame (at "
                           f"r = {geo.r_obs:.4g} r_s): raise speed_of_light or slow the camera")
    return beta


def _image_object(scene, src, order):
    name = f"{src.name}.GR{order}"
    obj = bpy.data.objects.get(name)
    if obj is not None and (obj.type != "MESH" or obj.grlens.source != src or obj.grlens.order != order):
        obj = None  # a user's object of that name: leave it alone
        name = f"{src.name}.GR{order}.grlens"
        obj = bpy.data.objects.get(name)
    if obj is None:
        mesh = bpy.data.meshes.new(name)
        obj = bpy.data.objects.new(name, mesh)
        obj.grlens.source = src
        obj.grlens.order = order
        _collection(scene).objects.link(obj)
    elif obj.name not in _collection(scene).objects:
        _collection(scene).objects.link(obj)
    return obj


def remove_image_object(obj):
    mesh = obj.data
    _INPUTS.pop(obj.get("grlens_input"), None)
    if mesh is not None:
        upload.forget(mesh)
    bpy.data.objects.remove(obj, do_unlink=True)
    if mesh is not None and mesh.users == 0:
        bpy.data.meshes.remove(mesh)


def remove_all_images() -> None:
    """Remove every image object grlens made and give every source its own visibility back (the
    add-on is being disabled, or Clear). The objects' marks are kept."""
    for obj in list(bpy.data.objects):
        if is_image_object(obj):
            remove_image_object(obj)
    for obj in bpy.data.objects:
        _set_source_visibility(obj, False)
    coll = bpy.data.collections.get(COLLECTION)
    if coll is not None and not coll.objects and not coll.children:
        bpy.data.collections.remove(coll)
    forget_all()


def _set_source_visibility(src, lensed: bool):
    """Hide a lensed source from renders (hide_render: every engine, Workbench included, which has no
    per-object camera visibility) and from the camera; restore the user's settings when it is not."""
    if lensed and src.get("grlens_hidden") is None:
        src.grlens.saved_visible_camera = src.visible_camera
        src.grlens.saved_hide_render = src.hide_render
        src["grlens_hidden"] = 1
        src.visible_camera = False
        src.hide_render = True
    elif not lensed and src.get("grlens_hidden") is not None:
        src.visible_camera = src.grlens.saved_visible_camera
        src.hide_render = src.grlens.saved_hide_render
        del src["grlens_hidden"]


def _present(src, depsgraph) -> bool:
    """Whether the render ``depsgraph`` evaluates ``src`` (objects hidden from renders are not in it)."""
    return not src.hide_render


def source_depsgraphs(srcs, depsgraph):
    """{``src.as_pointer()``: the depsgraph that evaluates ``src``} for the marked objects ``srcs``:
    for a render (``depsgraph.mode == 'RENDER'``) the render depsgraph itself, so that sources are
    evaluated with their render settings (modifier render levels, render visibility of what they
    instance); the handlers show lensed sources to it for the frame (:func:`expose_sources`). A source
    the render depsgraph does not hold (hidden from renders by the user, or a render the handlers did
    not prepare) and every source of a viewport update are evaluated in the view layer's depsgraph
    (viewport settings), updated first for a render."""
    out, view_dg = {}, None
    for src in srcs:
        if depsgraph.mode == "RENDER" and _present(src, depsgraph):
            out[src.as_pointer()] = depsgraph
            continue
        if view_dg is None:
            view_dg = depsgraph.view_layer.depsgraph
            if depsgraph.mode == "RENDER":
                view_dg.update()
        out[src.as_pointer()] = view_dg
    return out


def expose_sources(scene) -> int:
    """Before a render builds its depsgraph (render_pre): show the lensed sources of ``scene`` to it
    (``hide_render`` off), so that it evaluates them with render settings; :func:`hide_sources` hides
    them again once their images are built (the render then re-evaluates without them). Sources the
    user hides from renders stay hidden. Returns the number of sources shown."""
    n = 0
    if not scene.grlens.auto_update:
        return 0  # no rebuild in the render: nothing needs the sources
    for src in scene.objects:
        if (src.get("grlens_hidden") is not None and src.grlens.enabled and not src.grlens.saved_hide_render
                and src.hide_render):
            src.hide_render = False
            n += 1
    return n


def hide_sources(scene=None) -> None:
    """Hide every lensed source (of ``scene``, or of every scene) from renders again (after its images
    were built for a render frame, or after a render that was cancelled)."""
    for src in (scene.objects if scene is not None else bpy.data.objects):
        if src.get("grlens_hidden") is not None and not src.hide_render:
            src.hide_render = True


def _disc_emitter(obj_eval):
    """core DiscEmitter for an object with obj.grlens.emitter == 'THIN_DISC' (axis: its local Z in
    world space), else None."""
    g = obj_eval.original.grlens if obj_eval.original is not None else obj_eval.grlens
    if g.emitter != "THIN_DISC":
        return None
    m = np.array(obj_eval.matrix_world, dtype=np.float64)[:3, :3]
    axis = m @ np.array([0.0, 0.0, 1.0])
    norm = np.linalg.norm(axis)
    if not norm > 0:
        raise ValueError(f"{obj_eval.name}: the disc's local Z axis has zero length (scale 0)")
    shading.ensure_disc_node_group()
    return pipeline.DiscEmitter(axis=axis / norm, prograde=g.disc_prograde, mode=g.disc_mode.lower(),
                                r_in=g.disc_r_in, t_peak=g.disc_t_peak, exposure=g.disc_exposure)


_INPUTS: dict = {}
"""Token (the image objects' ``grlens_input`` property) -> the inputs their images were built from.
Comparing the new inputs with these is cheaper than hashing them every frame (an animated mesh
differs in its positions, found in one pass); a token not found (after a reload, or an undo step
that brought back older images) means a rebuild."""


def _inputs(mesh, geo, settings, lut, light, mats, planes, disc=None):
    """Everything an image depends on: world-space geometry and attributes, camera, hole, r_s,
    settings, LUT parameters, light and material slots. Equal inputs give identical images."""
    arrays = (mesh.positions, mesh.tris, mesh.corner_uv, mesh.material, mesh.corner_normals,
              geo.camera, geo.hole, planes, geo.beta)
    disc_key = None if disc is None else (tuple(disc.axis), disc.prograde, disc.mode, disc.r_in, disc.t_peak,
                                          disc.exposure)
    rest = repr((geo.r_s, geo.aberration, settings, disc_key,
                 tuple(sorted(lut.parameters.items())), [m.name if m else None for m in mats],
                 None if light is None else (tuple(light.position), light.intensity,
                                             tuple(sorted(light.lut.parameters.items())))))
    return arrays, rest


def forget_all() -> None:
    """Drop every remembered input and topology (a new file is being loaded: its images are rebuilt
    on their first update)."""
    _INPUTS.clear()
    upload.forget_all()
    gather.forget_all()


def _equal_inputs(a, b) -> bool:
    """Whether two builds' inputs (arrays, other values), as made by _inputs, are equal; None (no
    inputs) equals only None."""
    if a is None or b is None:
        return a is b
    if a[1] != b[1]:
        return False
    for x, y in zip(a[0], b[0]):
        if (x is None) != (y is None):
            return False
        if x is not None and not (np.shape(x) == np.shape(y) and np.array_equal(x, y)):
            return False
    return True


def _same_inputs(token, inputs) -> bool:
    """Whether ``inputs`` equal those remembered under ``token`` (the last build's)."""
    old = _INPUTS.get(token)
    return old is not None and _equal_inputs(old, inputs)


def _remember_inputs(objs, inputs, lines=(), stats=None) -> str:
    """Store ``inputs`` (and the report ``lines`` and ``stats`` of that build, repeated while they are
    unchanged) under a new token and drop the old tokens of the image objects ``objs``."""
    for o in objs:
        _INPUTS.pop(o.get("grlens_input"), None)
    token = uuid.uuid4().hex
    _INPUTS[token] = (inputs[0], inputs[1], list(lines), stats)
    return token


MAX_PANEL_LINES = 8
"""Report lines the panel shows (the rest as "... and N more")."""


def _plural(n, word, words=None):
    return f"{n} {word if n == 1 else (words or word + 's')}"


def not_imaged_line(name, mesh, images, geo, lut, orders) -> str | None:
    """The report line of the source triangles of ``mesh`` (a SourceMesh) that ``images`` (the
    pipeline's {order: ImageMesh}) could not show because a corner could not be mapped, with the
    reasons (core.losses), or None when there are none. Counted only when the pipeline reports such
    pieces, so an object without losses costs nothing here. Expected culling (frustum, back faces,
    Einstein ring, sub-pixel images, the axis) is in the report's stats, not here."""
    reps = [img.report for img in images.values()]
    invalid = max((r.invalid_vertex for r in reps), default=0)
    bad = max((r.extra.get("bad_source_triangles", 0) for r in reps), default=0)
    if not invalid and not bad:
        return None
    u = losses.unimaged_triangles(mesh.positions, mesh.tris, geo, lut, orders)
    if u.lost:
        return f"{name}: {u.lost} of {_plural(u.total, 'triangle')} not imaged ({losses.describe(u)})"
    if invalid and not u.on_axis:  # pieces between mappable corners (an edge passing the horizon)
        return (f"{name}: {_plural(invalid, 'piece')} of subdivided triangles not imaged (points between their "
                f"corners inside the lookup table's inner radius or beyond its range)")
    return None


def over_budget_line(name, images, settings) -> str | None:
    """The report line of an object whose kept pieces are not all within the error budget inside
    (core.interior: the refine step stopped at ``settings.max_triangles``, or after its last round),
    saying how far off they are, or None when they all are."""
    reps = [img.report for img in images.values()]
    over = [r.over_budget for r in reps if r.over_budget is not None and r.over_budget.count]
    if not over:
        return None
    count = sum(b.count for b in over)
    px = max(b.screen_px for b in over)
    lt = max(b.lt_rel for b in over)
    why = (f"the triangle bound (Max Triangles {settings.max_triangles:,}) stopped the cutting"
           if any(r.triangle_bound for r in reps) else "the cutting stopped after its last round")
    return (f"{name}: {_plural(count, 'piece')} beyond the error budget ({why}): drawn up to {px:.2g} px off "
            f"(tolerance {settings.max_error_px:.2g} px), light travel time up to {100 * lt:.2g}% off (tolerance "
            f"{100 * budget.LIGHT_TRAVEL_TOLERANCE:.2g}%)")


def _stats(images) -> dict:
    """{order: {reason: count}} of the pieces each image dropped (core CullReport; pieces of the
    subdivided mesh), for the report's stats."""
    out = {}
    for order, img in images.items():
        r = img.report
        out[order] = {"kept": r.kept, "invalid_vertex": r.invalid_vertex, "degenerate_source": r.degenerate_source,
                      "einstein_ring": r.einstein_ring, "outside_frustum": r.outside_frustum,
                      "below_pixel": r.below_pixel, "back_face": r.back_face, "patch_covered": r.patch_covered,
                      "patch_replaced": r.patch_replaced, "patch_faces": r.patch_faces,
                      "bad_source_triangles": int(r.extra.get("bad_source_triangles", 0)),
                      "refined": r.refined, "triangle_bound": r.triangle_bound,
                      "over_budget": 0 if r.over_budget is None else r.over_budget.count}
    return out


def clear_image(obj) -> None:
    """Empty the image object ``obj`` and forget the inputs it was built from, so that the next
    rebuild builds it whatever its inputs are (a frame that could not be lensed never leaves an
    image empty at a later good frame)."""
    _INPUTS.pop(obj.get("grlens_input"), None)
    if "grlens_input" in obj:
        del obj["grlens_input"]
    if obj.data is not None and len(obj.data.vertices):
        upload.forget(obj.data)
        obj.data.clear_geometry()


def _empty_images(scene, src, orders, wanted):
    """Empty the existing image objects of ``src`` (none are created) and forget their inputs, so the
    next rebuild builds them; they are kept (``wanted``)."""
    for order in orders:
        for name in (f"{src.name}.GR{order}", f"{src.name}.GR{order}.grlens"):
            obj = bpy.data.objects.get(name)
            if obj is not None and is_image_object(obj) and obj.grlens.source == src:
                clear_image(obj)
                wanted.add(obj.name)


class _Item:
    """One marked object in a rebuild: its name and pointer (looked up again before its images are
    written, so a build finished later never touches an object that is gone), its report lines in
    order, and its outcome: "pending" (gathered, to be built), "unchanged", "skipped", "failed" or
    "built" (images computed, to be uploaded)."""

    def __init__(self, src):
        self.name, self.ptr = src.name, src.as_pointer()
        self.lines: list = []
        self.outcome = "pending"
        self.mesh = self.inputs = self.disc = self.images = self.stats = None
        self.mats: list = []  # names of the image materials
        self.built_lines: list = []

    @property
    def triangles(self) -> int:
        return 0 if self.mesh is None else len(self.mesh.tris)


class RebuildPlan:
    """A rebuild of one scene in three steps: :func:`plan_rebuild` (main thread: the scene's settings,
    the table, every marked object gathered and compared with its last build), :func:`compute` (the
    numeric core of the objects whose inputs changed: bpy-free, so it may run in a worker thread,
    background.py) and :func:`finish` (main thread: upload, report, status). ``rebuild_scene`` runs
    the three at once."""

    def __init__(self, scene, preview):
        self.scene_name, self.scene_ptr = scene.name, scene.as_pointer()
        self.preview = preview
        self.t0 = time.perf_counter()
        self.report = {"status": "", "objects": {}, "stats": {}, "warnings": [], "seconds": 0.0}
        self.warn: list = []  # lines before the objects' own (sky, hole, light)
        self.items: list = []
        self.wanted: set = set()
        self.srcs = False
        self.world_line = None
        self.geo = self.settings = self.lut = self.light = self.planes = None
        self.compute_seconds = 0.0

    @property
    def pending(self) -> list:
        return [it for it in self.items if it.outcome == "pending"]

    def same_work(self, other) -> bool:
        """Whether ``other`` (a later plan of the same scene) asks for the very same builds: the same
        objects pending with equal inputs (its outcome would be this plan's)."""
        if other is None or other.scene_ptr != self.scene_ptr or other.preview != self.preview:
            return False
        a = [(it.ptr, it.outcome) for it in self.items]
        b = [(it.ptr, it.outcome) for it in other.items]
        if a != b or self.report["status"] != other.report["status"]:
            return False
        return all(_equal_inputs(x.inputs, y.inputs) for x, y in zip(self.pending, other.pending))

    def scene(self):
        """The plan's scene, or None when it is gone."""
        sc = bpy.data.scenes.get(self.scene_name)
        return sc if sc is not None and sc.as_pointer() == self.scene_ptr else None


def rebuild_scene(scene, depsgraph=None, preview: bool = False, background: bool = False) -> dict:
    """Rebuild every image object of ``scene`` for its current frame. Returns a report dict
    {"status": str, "objects": {name: {order: (vertices, faces, culled)} | "unchanged" | "skipped" |
    "failed"}, "stats": {name: {order: {reason: pieces}}}, "warnings": [str]}; the warnings (also in
    ``scene.grlens.report_lines``, one per line) name every marked object that is skipped or failed
    and what of an object is not imaged, and why. ``preview``: an automatic update of the interactive
    viewport, built to the viewport's tolerance (see :func:`max_error_px`; renders and explicit
    rebuilds use the render tolerance).

    ``background``: the build may run beside the interface (background.py) when it is predicted to
    take longer than background.BUDGET_SECONDS: the report returned then has the status "lensing in
    the background" and the objects to build as "pending"; the images, the status line and the report
    lines change when the build finishes. Otherwise (and always in renders and background mode) the
    build runs here; a background build still running is stopped first (the latest request wins)."""
    from . import background as bg

    plan = plan_rebuild(scene, depsgraph, preview)
    running = bg.current()
    if running is not None and running.plan.same_work(plan):
        if background:
            return bg.provisional_report(running.plan)  # (the running build is this very build)
    if background and plan.pending and bg.wants_background(plan):
        if bg.was_cancelled(plan):
            return bg.cancelled_report(plan)  # (Esc: the same build again waits for a change)
        return bg.start(plan)
    bg.cancel(quiet=True)  # (superseded; joined: one build at a time)
    compute(plan)
    return finish(plan)


def plan_rebuild(scene, depsgraph=None, preview: bool = False) -> RebuildPlan:
    """The first step of a rebuild (main thread): the world refreshed, the scene's settings checked,
    the table, and every marked object gathered and compared with its last build. Scene-level
    problems end the plan here (its status starts with "grlens:" and it has no objects)."""
    plan = RebuildPlan(scene, preview)
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    warn = plan.warn
    srcs = sources(scene)
    plan.srcs = bool(srcs)
    world_line, world_error = world.refresh(scene, depsgraph)
    plan.world_line = world_line
    if world_error and srcs:
        warn.append(f"sky: {world_error}")
    report = plan.report
    try:
        if not srcs:
            if world_error:
                raise RebuildError(world_error)
            if world_line is None:
                raise RebuildError("no object is marked for lensing (obj.grlens.enabled)")
            raise _WorldOnly(f"no object marked; {world_line}")
        geo, settings, cam = scene_geometry(scene, depsgraph, preview)
        warn.extend(hole_notes(scene))
        if geo.beta is not None:
            shading.set_shift_switches(scene)  # (a file saved with other switches: its group follows)
        planes = frustum_planes(scene, cam)
        g = scene.grlens
        lut = lutcache.get_table(g, geo.r_obs)
        light = None
        if g.use_gr_illumination:
            shading.ensure_node_group()
            if g.light is None:
                warn.append("GR illumination is on but no light object is set")
            else:
                lpos = np.array(g.light.evaluated_get(depsgraph).matrix_world.translation)
                r_light = float(np.linalg.norm(lpos - geo.hole) / geo.r_s)
                from lutgen.rays import R_OBS_MIN
                if r_light < R_OBS_MIN:
                    warn.append(f"the light is too close to the horizon (r = {r_light:.6g} r_s, needs "
                                f">= {R_OBS_MIN} r_s)")
                else:
                    light = pipeline.Light(lpos, g.light_intensity,
                                           lutcache.get_table(g, r_light))
        plan.geo, plan.settings, plan.lut, plan.light, plan.planes = geo, settings, lut, light, planes
        src_dgs = source_depsgraphs(srcs, depsgraph)
        shading.ensure_view_layer_aovs(scene)
        found, walk_error = {}, None
        for dg in {id(d): d for d in src_dgs.values()}.values():
            try:
                found.update(gather.instances([s for s in srcs if src_dgs[s.as_pointer()] is dg], dg))
            except Exception as exc:  # noqa: BLE001 (reported per object below)
                walk_error = exc
        for src in srcs:
            item = _Item(src)
            plan.items.append(item)
            try:
                if walk_error is not None and gather.may_have_instances(src):
                    raise walk_error
                _plan_source(scene, src, src_dgs[src.as_pointer()], found.get(src.as_pointer()), plan, item)
            except Exception as exc:  # noqa: BLE001 (one object's failure must not stop the others)
                _fail(item, exc)
    except _WorldOnly as exc:
        report["status"] = str(exc)
    except RebuildError as exc:
        report["status"] = f"grlens: {exc}"
    except ValueError as exc:  # bad numbers from the scene (r_s, NaN transforms, LUT parameters)
        report["status"] = f"grlens: {exc}"
    return plan


def _fail(item, exc) -> None:
    item.lines.append(f"{item.name}: failed: {type(exc).__name__}: {exc}" if not str(exc) else
                      f"{item.name}: failed: {exc}")
    item.outcome = "failed"


def compute(plan: RebuildPlan, progress=None) -> None:
    """The second step (bpy-free: may run in a worker thread): the images of every pending object
    (pipeline.build_images) and their report lines and stats. ``progress``: None, or a callable
    ``progress(item_index, stage, fraction)`` passed on to the core for each pending object, which
    may raise pipeline.Cancelled (then nothing of the plan is written). An object's failure is its
    report line; the others are built."""
    t0 = time.perf_counter()
    for i, item in enumerate(plan.pending):
        hook = None if progress is None else (lambda stage, f, i=i: progress(i, stage, f))
        try:
            images = pipeline.build_images(item.mesh, plan.geo, plan.lut, plan.settings, plan.light, plan.planes,
                                           item.disc, progress=hook)
            lines = []
            for line in (not_imaged_line(item.name, item.mesh, images, plan.geo, plan.lut, plan.settings.orders),
                         over_budget_line(item.name, images, plan.settings)):
                if line:
                    lines.append(line)
            item.images, item.built_lines, item.stats = images, lines, _stats(images)
            item.outcome = "built"
            if progress is not None:  # (a build beside the interface: the images' edges found here, off
                # the main thread, which uploads them; ImageMesh.edges keeps them)
                for img in images.values():
                    img.edges()
        except pipeline.Cancelled:
            raise
        except Exception as exc:  # noqa: BLE001 (one object's failure must not stop the others)
            _fail(item, exc)
    plan.compute_seconds = time.perf_counter() - t0


def finish(plan: RebuildPlan) -> dict:
    """The last step (main thread): upload the built images, empty those of skipped and failed
    objects, remove the images no longer wanted, and write the status and report lines. Objects gone
    since the plan was made are left out (the next change rebuilds)."""
    from . import background as bg

    scene = plan.scene()
    report, warn = plan.report, plan.report["warnings"]
    if scene is None:
        report["status"] = "grlens: the scene is gone"
        return report
    warn.extend(plan.warn)
    counts = {"lensed": 0, "skipped": 0, "failed": 0}
    wanted = plan.wanted
    for item in plan.items:
        src = bpy.data.objects.get(item.name)
        if src is None or src.as_pointer() != item.ptr:
            continue  # (gone, or renamed, since the plan was made)
        try:
            outcome = _finish_source(scene, src, plan, item)
        except Exception as exc:  # noqa: BLE001 (one object's failure must not stop the others)
            _fail(item, exc)
            outcome = "failed"
        if outcome == "failed":
            report["objects"][item.name] = "failed"
            _set_source_visibility(src, _hides(src))
            _empty_images(scene, src, plan.settings.orders, wanted)
        warn.extend(item.lines)
        counts[outcome] += 1
    if plan.items:
        geo, settings, g = plan.geo, plan.settings, scene.grlens
        report["status"] = f"{counts['lensed']} object(s) lensed"
        for key in ("skipped", "failed"):
            if counts[key]:
                report["status"] += f", {counts[key]} {key}"
        report["status"] += f", r_obs = {geo.r_obs:.4g} r_s"
        if geo.beta is not None:
            report["status"] += f", camera at {np.linalg.norm(geo.beta):.3g} c"
        if settings.max_error_px != max_error_px(g):
            report["status"] += f" (viewport preview: {settings.max_error_px:.3g} px)"
        if plan.world_line and plan.world_line.startswith("sky lensed"):
            report["status"] += "; sky lensed"
    world_line, srcs = plan.world_line, plan.srcs
    if report["status"].startswith("grlens:") and srcs:
        # the images are not built; say what the world does, so the two never seem to disagree
        report["status"] += "; no images" + (f" ({world_line})" if world_line and world_line.startswith("sky lensed")
                                             else "")
    # image objects not rebuilt now: keep (empty) those of enabled sources while the scene is invalid,
    # remove those of sources that are gone or disabled and of orders switched off
    invalid = report["status"].startswith("grlens:")
    for obj in list(bpy.data.objects):
        if is_image_object(obj) and obj.name not in wanted:
            src = obj.grlens.source
            if invalid and src is not None and src.grlens.enabled:
                clear_image(obj)
            else:
                remove_image_object(obj)
    for o in scene.objects:
        if not is_image_object(o) and not o.grlens.enabled:
            _set_source_visibility(o, False)
    report["seconds"] = time.perf_counter() - plan.t0
    if not report["status"].startswith("grlens:") or srcs:
        report["status"] += f" [{1000 * report['seconds']:.0f} ms]"
    scene.grlens.status = report["status"]
    scene.grlens.report_lines = "\n".join(warn)
    bg.measured(plan)
    return report


def _hides(src) -> bool:
    """Whether a marked object is hidden from renders (its images stand in for it, or stay empty when
    it is skipped): every object that can have geometry; a light or camera marked by a script is
    left alone."""
    return gather.can_lens(src) or src.type == "EMPTY"


def _plan_source(scene, src, src_dg, inst, plan, item) -> None:
    """Gather one marked object and compare it with its last build: ``item`` becomes "skipped",
    "unchanged" (its report lines repeated) or "pending" (with its source mesh and inputs); the
    names of its image objects go into ``plan.wanted``."""
    settings = plan.settings
    src_eval = src.evaluated_get(src_dg)
    _set_source_visibility(src, _hides(src))
    got = gather.gather(src, src_eval, inst)
    if got.skip is not None:
        item.lines.append(f"{src.name}: skipped: {got.skip}")
        item.outcome = "skipped"
        return
    item.lines.extend(f"{src.name}: {note}" for note in got.notes)
    mesh = got.mesh
    mats = [shading.image_material(m) for m in got.materials] or [shading.image_material(None)]
    disc = _disc_emitter(src_eval)
    inputs = _inputs(mesh, plan.geo, settings, plan.lut, plan.light, mats, plan.planes, disc)
    objs = {order: _image_object(scene, src, order) for order in settings.orders}
    plan.wanted.update(o.name for o in objs.values())
    tokens = {o.get("grlens_input") for o in objs.values()}
    if len(tokens) == 1 and _same_inputs(next(iter(tokens)), inputs):
        item.outcome = "unchanged"  # same geometry, camera and settings: skip
        _, _, lines, stats = _INPUTS[next(iter(tokens))]
        item.lines.extend(lines)
        item.stats = stats
        return
    item.mesh, item.inputs, item.disc, item.mats = mesh, inputs, disc, [m.name for m in mats]


def _finish_source(scene, src, plan, item) -> str:
    """Write one object's outcome (main thread); returns "lensed", "skipped" or "failed"."""
    report, settings = plan.report, plan.settings
    if item.outcome == "skipped":
        report["objects"][src.name] = "skipped"
        _empty_images(scene, src, settings.orders, plan.wanted)
        return "skipped"
    if item.outcome == "failed":
        return "failed"
    if item.outcome == "unchanged":
        report["objects"][src.name] = "unchanged"
        if item.stats is not None:
            report["stats"][src.name] = item.stats
        return "lensed"
    if item.outcome != "built":
        raise RuntimeError(f"not built ({item.outcome})")
    mats = [bpy.data.materials.get(n) for n in item.mats]
    if any(m is None for m in mats):
        raise RuntimeError("an image material was removed while the images were built")
    objs = {order: _image_object(scene, src, order) for order in settings.orders}
    plan.wanted.update(o.name for o in objs.values())
    key = _remember_inputs(objs.values(), item.inputs, item.built_lines, item.stats)
    entry = {}
    for order, img in item.images.items():
        obj = objs[order]
        upload.upload(obj.data, img, mats)
        upload.set_normals(obj.data, img)
        upload.set_order(obj.data, order)
        obj["grlens_input"] = key
        entry[order] = (len(img.positions), len(img.tris), img.report.total_culled())
    report["objects"][src.name] = entry
    report["stats"][src.name] = item.stats
    item.lines.extend(item.built_lines)
    return "lensed"
