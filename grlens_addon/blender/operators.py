"""Operators (public scripting contract): ``bpy.ops.grlens.rebuild()``, ``bpy.ops.grlens.clear()``,
``bpy.ops.grlens.demo_scene()``, ``bpy.ops.grlens.pack_lut()``, ``bpy.ops.grlens.unpack_luts()``,
``bpy.ops.grlens.check_frame()``."""
import math

import bpy


class GRLENS_OT_rebuild(bpy.types.Operator):
    """Rebuild all lensed image meshes for the current frame"""

    bl_idname = "grlens.rebuild"
    bl_label = "Rebuild Lensed Images"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from .rebuild import rebuild_scene

        report = rebuild_scene(context.scene, context.evaluated_depsgraph_get())
        for w in report["warnings"]:
            self.report({"WARNING"}, w)
        if report["status"].startswith("grlens:"):
            self.report({"ERROR"}, report["status"])
            return {"CANCELLED"}
        self.report({"INFO"}, report["status"])
        return {"FINISHED"}


class GRLENS_OT_clear(bpy.types.Operator):
    """Remove all image objects made by grlens and show the source objects to the camera again"""

    bl_idname = "grlens.clear"
    bl_label = "Remove Lensed Images"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from .rebuild import is_image_object, remove_image_object, _set_source_visibility

        for obj in list(bpy.data.objects):
            if is_image_object(obj):
                remove_image_object(obj)
        for obj in context.scene.objects:
            if not is_image_object(obj):
                if obj.grlens.enabled:
                    obj.grlens.enabled = False
                _set_source_visibility(obj, False)
        return {"FINISHED"}


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
        hole = bpy.data.objects.new("BlackHole", None)
        hole.empty_display_type = "SPHERE"
        hole.empty_display_size = r_s
        scene.collection.objects.link(hole)
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
        g = scene.grlens
        g.auto_update = False
        g.black_hole = hole
        g.r_s = r_s
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


CLASSES = (GRLENS_OT_rebuild, GRLENS_OT_clear, GRLENS_OT_demo_scene, GRLENS_OT_pack_lut, GRLENS_OT_unpack_luts,
           GRLENS_OT_check_frame)
