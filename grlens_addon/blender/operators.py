"""Operators (public scripting contract): ``bpy.ops.grlens.rebuild()``, ``bpy.ops.grlens.clear()``,
``bpy.ops.grlens.demo_scene()``, ``bpy.ops.grlens.pack_lut()``, ``bpy.ops.grlens.unpack_luts()``,
``bpy.ops.grlens.check_frame()``, ``bpy.ops.grlens.add_black_hole()`` (Add > Black Hole),
``bpy.ops.grlens.lens_selected()``, ``bpy.ops.grlens.unlens_selected()`` and
``bpy.ops.grlens.build_progress()`` (started for a build beside the interface: its progress, Esc).

Called from scripts (execute), Rebuild, Lens Selected and Unlens Selected build at once; from the
interface (invoke: buttons, menus, F3) a long build runs beside the interface (background.py)."""
import math

import bpy


class GRLENS_OT_rebuild(bpy.types.Operator):
    """Rebuild all lensed image meshes for the current frame"""

    bl_idname = "grlens.rebuild"
    bl_label = "Rebuild Lensed Images"
    bl_options = {"REGISTER", "UNDO"}

    def invoke(self, context, event):
        from . import background

        background.clear_cancelled()  # (an explicit rebuild: also the build cancelled last)
        return self._rebuild(context, background.allowed(context.scene))

    def execute(self, context):
        return self._rebuild(context, False)

    def _rebuild(self, context, in_background):
        from .rebuild import rebuild_scene

        report = rebuild_scene(context.scene, context.evaluated_depsgraph_get(), background=in_background)
        if report["status"] == "lensing in the background":
            self.report({"INFO"}, "grlens: lensing in the background (Esc cancels)")
            return {"FINISHED"}
        for w in report["warnings"]:
            self.report({"WARNING"}, w)
        if report["status"].startswith("grlens:"):
            self.report({"ERROR"}, report["status"])
            return {"CANCELLED"}
        self.report({"INFO"}, report["status"])
        return {"FINISHED"}


class GRLENS_OT_clear(bpy.types.Operator):
    """Switch Lens off on every object of the scene, remove every image object grlens made and show the
    source objects to the camera again (the black hole and all settings are kept)"""

    bl_idname = "grlens.clear"
    bl_label = "Unlens All"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from .rebuild import is_image_object, remove_image_object, _set_source_visibility

        removed = unmarked = 0
        for obj in list(bpy.data.objects):
            if is_image_object(obj):
                remove_image_object(obj)
                removed += 1
        for obj in context.scene.objects:
            if not is_image_object(obj):
                if obj.grlens.enabled:
                    obj.grlens.enabled = False
                    unmarked += 1
                _set_source_visibility(obj, False)
        self.report({"INFO"}, f"unlensed {_plural(unmarked, 'object')}, removed {_plural(removed, 'image object')}")
        return {"FINISHED"}


def _plural(n, word):
    return f"{n} {word}" + ("" if n == 1 else "s")


def _set_lens(scene, objs, on: bool, in_background: bool = False) -> int:
    """Switch Lens (``obj.grlens.enabled``) to ``on`` for ``objs``, then rebuild once (if auto update is
    on) instead of once per object; ``in_background``: a long build may run beside the interface.
    Returns how many objects changed."""
    g = scene.grlens
    auto, g.auto_update = g.auto_update, False
    n = 0
    try:
        for obj in objs:
            if obj.grlens.enabled != on:
                obj.grlens.enabled = on
                n += 1
    finally:
        g.auto_update = auto
    if n:
        from . import handlers

        handlers.request_rebuild(scene, background=in_background)
    return n


def lensable(obj, scene) -> bool:
    """Whether Lens Selected marks ``obj``: grlens can image it (any kind with geometry, or an empty
    instancing a collection), it is not an image grlens made, and it is not the black hole (or the
    photon sphere of Add > Black Hole)."""
    from .gather import can_lens
    from .hole import is_hole_marker

    return (can_lens(obj) and obj.grlens.order == 0 and obj != scene.grlens.black_hole
            and not is_hole_marker(obj))


class GRLENS_OT_lens_selected(bpy.types.Operator):
    """Lens every selected object that grlens can image (meshes, curves, text, surfaces, metaballs,
    Geometry Nodes output, collection instances); cameras, lights, the black hole and grlens' own
    images are left alone"""

    bl_idname = "grlens.lens_selected"
    bl_label = "Lens Selected"
    bl_options = {"REGISTER", "UNDO"}

    def invoke(self, context, event):
        return self._lens(context, True)

    def execute(self, context):
        return self._lens(context, False)

    def _lens(self, context, in_background):
        scene = context.scene
        sel = list(context.selected_objects)
        objs = [o for o in sel if lensable(o, scene)]
        if not objs:
            self.report({"WARNING"}, "no selected object that grlens can image")
            return {"CANCELLED"}
        n = _set_lens(scene, objs, True, in_background)
        rest = len(sel) - len(objs)
        self.report({"INFO"}, f"lensed {_plural(n, 'object')}" + (f" ({rest} left alone: not imageable)" if rest
                                                                  else ""))
        return {"FINISHED"}


class GRLENS_OT_unlens_selected(bpy.types.Operator):
    """Switch Lens off on every selected object: their images are removed and they render again"""

    bl_idname = "grlens.unlens_selected"
    bl_label = "Unlens Selected"
    bl_options = {"REGISTER", "UNDO"}

    def invoke(self, context, event):
        return self._unlens(context, True)

    def execute(self, context):
        return self._unlens(context, False)

    def _unlens(self, context, in_background):
        objs = [o for o in context.selected_objects if o.grlens.enabled]
        if not objs:
            self.report({"WARNING"}, "no selected object is lensed")
            return {"CANCELLED"}
        n = _set_lens(context.scene, objs, False, in_background)
        self.report({"INFO"}, f"unlensed {_plural(n, 'object')}")
        return {"FINISHED"}


class GRLENS_OT_add_black_hole(bpy.types.Operator):
    """Add a black hole at the 3D cursor: an empty showing its event horizon (r_s) and photon sphere
    (1.5 r_s) at true size, which never renders, and make it the scene's black hole (a former one is
    kept, no longer used)"""

    bl_idname = "grlens.add_black_hole"
    bl_label = "Black Hole"
    bl_options = {"REGISTER", "UNDO"}

    lens_selected: bpy.props.BoolProperty(
        name="Lens Selected Objects", default=False,
        description="Also lens the objects selected before the hole is added (those grlens can image)")
    location: bpy.props.FloatVectorProperty(
        name="Location", subtype="TRANSLATION", size=3,
        description="Where the hole's centre goes (default: the 3D cursor)")

    @classmethod
    def poll(cls, context):
        return context.scene is not None and context.mode == "OBJECT"

    def execute(self, context):
        from . import hole

        scene = context.scene
        g = scene.grlens
        chosen = [o for o in context.selected_objects if lensable(o, scene)] if self.lens_selected else []
        collection = context.collection or scene.collection
        if collection.library is not None or collection.override_library is not None:
            collection = scene.collection
        auto, g.auto_update = g.auto_update, False  # (one rebuild at the end, not one per change)
        try:
            if not self.properties.is_property_set("location"):
                self.location = scene.cursor.location  # (then shown, and kept, in the redo panel)
            new, former = hole.add(scene, collection, tuple(self.location))
            lensed = 0
            for obj in chosen:
                if not obj.grlens.enabled:
                    obj.grlens.enabled = True
                    lensed += 1
        finally:
            g.auto_update = auto
        for o in context.selected_objects:
            o.select_set(False)
        if new.name in context.view_layer.objects:
            new.select_set(True)
            context.view_layer.objects.active = new
        if former is not None:
            self.report({"WARNING"}, hole.replaced_note(former))
        msg = f"added '{new.name}' as the black hole (r_s = {g.r_s:g})"
        if self.lens_selected:
            msg += f", lensed {_plural(lensed, 'object')}"
        self.report({"INFO"}, msg)
        from . import handlers

        handlers.request_rebuild(scene)  # (the images and the sky of the new hole)
        return {"FINISHED"}


def menu_add(self, context):
    """Add > Black Hole in the 3D viewport's Add menu."""
    self.layout.separator()
    self.layout.operator_context = "INVOKE_REGION_WIN"
    self.layout.operator(GRLENS_OT_add_black_hole.bl_idname, text="Black Hole", icon="SHADING_SOLID")


class GRLENS_OT_demo_scene(bpy.types.Operator):
    """Set up the paper's demo: a sphere of radius 0.5 r_s on the last stable orbit (3 r_s) seen by a
    camera 20 r_s from a black hole (Mueller, Schulz & Weiskopf 2021, section 4.2)"""

    bl_idname = "grlens.demo_scene"
    bl_label = "Demo Scene"
    bl_options = {"REGISTER", "UNDO"}

    r_s: bpy.props.FloatProperty(name="r_s", default=2.0, min=0.001, description="Schwarzschild radius (scene units)")

    def execute(self, context):
        scene = context.scene
        r_s = self.r_s
        from . import hole as hole_marker

        g = scene.grlens
        g.auto_update = False
        g.r_s = r_s
        hole, _ = hole_marker.add(scene, scene.collection, name="BlackHole")  # (replaces a former hole)
        mesh = bpy.data.meshes.new("OrbitingSphere")
        sphere = bpy.data.objects.new("OrbitingSphere", mesh)
        scene.collection.objects.link(sphere)
        import bmesh

        bm = bmesh.new()
        bm.loops.layers.uv.new("UVMap")
        bmesh.ops.create_uvsphere(bm, u_segments=36, v_segments=18, radius=0.5 * r_s, calc_uvs=True)
        bm.to_mesh(mesh)
        bm.free()
        # one orbit over frames 1..361 (parented to a rotating empty), starting beside the hole;
        # a small z offset keeps the sphere's poles off the camera-hole axis (paper, section 4.2)
        orbit = bpy.data.objects.new("Orbit", None)
        scene.collection.objects.link(orbit)
        sphere.parent = orbit
        sphere.location = (0.0, 3 * r_s, 0.01 * r_s)
        orbit.rotation_euler = (0.0, 0.0, 0.0)
        orbit.keyframe_insert("rotation_euler", index=2, frame=1)
        orbit.rotation_euler = (0.0, 0.0, 2 * math.pi)
        orbit.keyframe_insert("rotation_euler", index=2, frame=361)
        for fc in _fcurves(orbit.animation_data.action):
            for kp in fc.keyframe_points:
                kp.interpolation = "LINEAR"
        scene.frame_start, scene.frame_end = 1, 360
        cam_data = bpy.data.cameras.new("Camera")
        cam_data.sensor_fit = "VERTICAL"
        cam_data.angle_y = math.radians(19.0)
        cam = bpy.data.objects.new("Camera", cam_data)
        cam.location = (20 * r_s, 0.0, 0.0)
        cam.rotation_euler = (math.radians(90.0), 0.0, math.radians(90.0))
        scene.collection.objects.link(cam)
        scene.camera = cam
        g.max_tess_level, g.tess_a, g.tess_b = 64, 5.0, 0.75
        sphere.grlens.enabled = True
        g.auto_update = True
        from .rebuild import rebuild_scene

        rebuild_scene(scene, context.evaluated_depsgraph_get())
        return {"FINISHED"}


def _fcurves(action):
    """The F-curves of an action: ``action.fcurves`` up to Blender 4.x, the channel bags of its
    layered (slotted) strips in 5.0, where ``Action.fcurves`` is gone."""
    if action is None:
        return []
    if hasattr(action, "layers") and len(action.layers):
        return [fc for layer in action.layers for strip in layer.strips
                for bag in getattr(strip, "channelbags", []) for fc in bag.fcurves]
    return list(getattr(action, "fcurves", []))


class GRLENS_OT_pack_lut(bpy.types.Operator):
    """Store the lookup tables for the current camera distance and settings in the .blend file, so that
    other processes (render farms) load them instead of building them"""

    bl_idname = "grlens.pack_lut"
    bl_label = "Pack LUT into .blend"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from . import lutcache
        from .rebuild import RebuildError, scene_geometry

        scene = context.scene
        g = scene.grlens
        try:
            geo, _, _ = scene_geometry(scene, context.evaluated_depsgraph_get())
        except (RebuildError, ValueError) as exc:
            self.report({"ERROR"}, f"grlens: {exc}")
            return {"CANCELLED"}
        try:
            what = lutcache.pack(lutcache.get_table(g, geo.r_obs))
        except ValueError as exc:
            self.report({"ERROR"}, f"grlens: {exc}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"packed {what}")
        return {"FINISHED"}


class GRLENS_OT_unpack_luts(bpy.types.Operator):
    """Remove all lookup tables packed into the .blend file"""

    bl_idname = "grlens.unpack_luts"
    bl_label = "Remove Packed LUTs"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from . import lutcache

        n = lutcache.unpack_all()
        self.report({"INFO"}, f"removed {n} packed LUT(s)")
        return {"FINISHED"}


class GRLENS_OT_check_frame(bpy.types.Operator):
    """Render the current frame with the exact per-pixel ray tracer and with grlens' image meshes (at a
    fraction of the render resolution), compare them and write both renders' passes to an OpenEXR
    file (takes seconds: the ray tracer is slow)"""

    bl_idname = "grlens.check_frame"
    bl_label = "Check Frame Against Ray Tracing"
    bl_options = {"REGISTER"}

    percentage: bpy.props.IntProperty(
        name="Resolution %", default=50, min=1, max=100, subtype="PERCENTAGE",
        description="Resolution of the check, in percent of the render resolution (the ray tracer is slow: "
                    "seconds per frame at 640x360, the most where an object surrounds the hole's direction)")
    filepath: bpy.props.StringProperty(
        name="Output", default="//grlens_check_####.exr", subtype="FILE_PATH",
        description="OpenEXR file for the passes of both renders and the mismatch (# -> frame number; "
                    "// -> next to the .blend, or the temporary directory for an unsaved file); empty: none")

    def execute(self, context):
        from .check import check_scene
        from .rebuild import RebuildError

        scene = context.scene
        try:
            result, path = check_scene(scene, context.evaluated_depsgraph_get(), self.percentage, self.filepath)
        except (RebuildError, ValueError, OSError) as exc:
            self.report({"ERROR"}, f"grlens: {exc}")
            return {"CANCELLED"}
        text = f"frame {scene.frame_current}, {result.summary()}" + (f"; passes in {path}" if path else "")
        scene.grlens.check_summary = text
        self.report({"INFO"}, text)
        if bpy.app.background:
            print(f"grlens check: {text}")
        return {"FINISHED"}


class GRLENS_OT_build_progress(bpy.types.Operator):
    """Show the progress of the images being built beside the interface; Esc cancels the build (the
    former images stay). Started by grlens for such a build; ends with it"""

    bl_idname = "grlens.build_progress"
    bl_label = "grlens Build Progress"
    bl_options = {"INTERNAL"}

    def invoke(self, context, event):
        from . import background

        if not background.running() or context.window is None:
            return {"CANCELLED"}
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        background.set_watching(True)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        return {"CANCELLED"}  # (only meaningful while a build runs, from invoke)

    def modal(self, context, event):
        from . import background

        if not background.running():
            self._end(context)
            return {"FINISHED"}
        if event.type == "ESC" and event.value == "PRESS":
            background.cancel(reason="Esc")
            self._end(context)
            self.report({"INFO"}, "grlens: build cancelled; the former images stay")
            return {"CANCELLED"}
        return {"PASS_THROUGH"}

    def cancel(self, context):
        self._end(context)

    def _end(self, context):
        from . import background

        timer, self._timer = getattr(self, "_timer", None), None
        if timer is not None:
            context.window_manager.event_timer_remove(timer)
        background.set_watching(False)


CLASSES = (GRLENS_OT_rebuild, GRLENS_OT_build_progress, GRLENS_OT_clear, GRLENS_OT_demo_scene, GRLENS_OT_pack_lut, GRLENS_OT_unpack_luts,
           GRLENS_OT_check_frame, GRLENS_OT_lens_selected, GRLENS_OT_unlens_selected, GRLENS_OT_add_black_hole)
