"""Panels, essentials first (Blender's conventions: sub-panels, the rarely used closed by default).

3D Viewport > Sidebar (N) > grlens:

* grlens (open): the black hole and r_s, the observer, the lensed world, the pixel tolerance (render
  and viewport), the Lens switch of the active object, Lens / Unlens Selected, Rebuild, Unlens All,
  the status line (with grlens' time for the frame; while a long build runs beside the interface,
  its progress above it) and the report;
* GR Illumination, Frame Check (closed): each its own panel;
* Advanced (closed): the method's knobs, the tables (mode, range, size, packing), MaxTessLevel, a, b
  and the cull ratio.

Properties editor > Object > grlens: the object's own settings (Lens, the emitter, the thin disc),
or which object an image shows. Add > Black Hole is in operators.py (menu_add).
"""
import bpy

from .gather import can_lens


def panorama_note(scene) -> str:
    """A note for the panel when the observer camera is a panorama the render engine cannot draw:
    Cycles renders equirectangular and fisheye panoramas; Eevee and Workbench have no panoramic
    camera (they draw such a camera as a perspective one). Empty otherwise."""
    from .rebuild import observer_camera

    # (no grlens settings when the add-on's properties are not registered)
    cam = observer_camera(scene) if getattr(scene, "grlens", None) is not None else scene.camera
    if cam is None or cam.type != "CAMERA" or cam.data.type != "PANO" or scene.render.engine == "CYCLES":
        return ""
    return "Panoramic camera: only Cycles renders panoramas"


def shows_lens_switch(obj) -> bool:
    """Whether the panels offer Lens (``obj.grlens.enabled``) for ``obj``: every object grlens can
    image (gather.can_lens), and any object a script marked (so it can be switched off); never an
    image grlens made."""
    return obj is not None and obj.grlens.order == 0 and (can_lens(obj) or obj.grlens.enabled)


def _notes(col, lines, icon="ERROR"):
    for line in lines:
        col.label(text=line, icon=icon)


class VIEW3D_PT_grlens(bpy.types.Panel):
    """The essentials: what is lensed around which hole, seen by which camera, to which tolerance."""

    bl_label = "grlens"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "grlens"

    def draw(self, context):
        from .rebuild import hole_notes

        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        scene = context.scene
        g = scene.grlens
        col = layout.column()
        col.prop(g, "black_hole")
        if g.black_hole is None:
            row = col.row(align=True)
            row.operator("grlens.add_black_hole", text="Add Black Hole", icon="ADD")
            row.operator("grlens.demo_scene", icon="SPHERE")
        _notes(col, hole_notes(scene))
        col.prop(g, "r_s")
        col.prop(g, "observer")
        note = panorama_note(scene)
        if note:
            col.label(text=note, icon="INFO")
        col.prop(g, "lens_world")
        if g.world_status:
            col.label(text=g.world_status, icon="ERROR" if g.world_status.startswith("grlens:") else "WORLD")

        col = layout.column(heading="Pixel Tolerance", align=True)
        col.prop(g, "tess_max_error", text="Render")
        col.prop(g, "tess_max_error_viewport", text="Viewport")
        col = layout.column(heading="Images")
        row = col.row(align=True)
        row.prop(g, "show_order_1", text="Order 1", toggle=True)
        row.prop(g, "show_order_2", text="Order 2", toggle=True)

        obj = context.object
        col = layout.column()
        if shows_lens_switch(obj):
            col.prop(obj.grlens, "enabled", text=f"Lens '{obj.name}'")
        row = col.row(align=True)
        row.operator("grlens.lens_selected", icon="CHECKMARK")
        row.operator("grlens.unlens_selected", icon="PANEL_CLOSE")
        row = col.row(align=True)
        row.prop(g, "auto_update")
        row.prop(g, "build_in_background", text="In Background")
        row = col.row(align=True)
        row.operator("grlens.rebuild", text="Rebuild", icon="FILE_REFRESH")
        row.operator("grlens.clear", icon="X")
        from . import background

        building = background.status_line(scene)
        if building:
            layout.label(text=building, icon="TIME")
        if g.status:
            layout.label(text=g.status, icon="ERROR" if g.status.startswith("grlens:") else "INFO")
        lines = report_lines(g)
        if lines:
            col = layout.column(align=True)
            for line in lines:
                col.label(text=line, icon="BLANK1" if line.startswith("...") else "ERROR")


class _Sub:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "grlens"
    bl_parent_id = "VIEW3D_PT_grlens"
    bl_options = {"DEFAULT_CLOSED"}


class VIEW3D_PT_grlens_illumination(_Sub, bpy.types.Panel):
    """GR illumination: a point light's irradiance along both connecting geodesics."""

    bl_label = "GR Illumination"

    def draw_header(self, context):
        self.layout.prop(context.scene.grlens, "use_gr_illumination", text="")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        g = context.scene.grlens
        col = layout.column()
        col.active = g.use_gr_illumination
        col.prop(g, "light")
        col.prop(g, "light_intensity")


class VIEW3D_PT_grlens_physical_time(_Sub, bpy.types.Panel):
    """Physical time: frames as Schwarzschild coordinate time, a moving camera's aberration and the
    colours of light (speed_of_light in scene units per frame; 0: every frame a still)."""

    bl_label = "Physical Time"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        g = context.scene.grlens
        col = layout.column()
        row = col.row(align=True)
        row.prop(g, "speed_of_light")
        row.operator("grlens.set_speed_of_light", text="", icon="TIME")
        row = col.row(align=True)
        row.operator("grlens.camera_fall")
        row.operator("grlens.camera_orbit")
        sub = col.column()
        sub.active = g.speed_of_light > 0
        if g.speed_of_light > 0:
            sub.label(text=f"r_s/c = {g.r_s / g.speed_of_light:.4g} frames (coordinate time)")
        for prop in ("use_aberration", "use_doppler_colour", "use_beaming", "use_gravitational_shift"):
            sub.prop(g, prop)


class VIEW3D_PT_grlens_check(_Sub, bpy.types.Panel):
    """The current frame against the exact per-pixel ray tracer."""

    bl_label = "Frame Check"

    def draw(self, context):
        layout = self.layout
        g = context.scene.grlens
        layout.operator("grlens.check_frame", icon="VIEWZOOM")
        if g.check_summary:
            layout.label(text=g.check_summary, icon="INFO")


class VIEW3D_PT_grlens_advanced(_Sub, bpy.types.Panel):
    """The method's knobs: lookup tables, subdivision and culling."""

    bl_label = "Advanced"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        g = context.scene.grlens
        col = layout.column()
        col.label(text="Lookup Tables (radii in r_s)")
        col.prop(g, "lut_mode")
        col.prop(g, "lut_r_min")
        if g.lut_mode == "FIXED_RANGE":
            col.prop(g, "lut_r_max")
            col.prop(g, "lut_n_r")
            col.prop(g, "lut_n_phi")
        row = col.row(align=True)
        row.operator("grlens.pack_lut", icon="PACKAGE")
        row.operator("grlens.unpack_luts", icon="UGLYPACKAGE", text="")
        col = layout.column()
        col.label(text="Subdivision and Culling")
        col.prop(g, "max_tess_level")
        col.prop(g, "tess_a")
        col.prop(g, "tess_b")
        col.prop(g, "cull_ratio")
        col.prop(g, "max_triangles")


class OBJECT_PT_grlens(bpy.types.Panel):
    """Properties editor > Object > grlens: the active object's own grlens settings."""

    bl_label = "grlens"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "object"

    @classmethod
    def poll(cls, context):
        obj = context.object
        return obj is not None and hasattr(obj, "grlens") and (shows_lens_switch(obj) or obj.grlens.order in (1, 2))

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        obj = context.object
        og = obj.grlens
        if og.order in (1, 2):
            src = og.source.name if og.source is not None else "?"
            layout.label(text=f"Order-{og.order} image of '{src}', made by grlens", icon="INFO")
            return
        layout.prop(og, "enabled", text="Lens")
        col = layout.column()
        col.active = og.enabled
        col.prop(og, "emitter")
        if og.emitter == "THIN_DISC":
            col.prop(og, "disc_mode")
            col.prop(og, "disc_r_in")
            col.prop(og, "disc_prograde")
            col.prop(og, "disc_t_peak")
            col.prop(og, "disc_exposure")


def report_lines(g, limit=None) -> list:
    """The lines of ``g.report_lines`` the panel shows: at most ``limit`` (default
    rebuild.MAX_PANEL_LINES), the rest summed up as "... and N more"."""
    from .rebuild import MAX_PANEL_LINES

    limit = MAX_PANEL_LINES if limit is None else limit
    lines = [ln for ln in g.report_lines.split("\n") if ln]
    if len(lines) > limit:
        return lines[:limit - 1] + [f"... and {len(lines) - limit + 1} more"]
    return lines


CLASSES = (VIEW3D_PT_grlens, VIEW3D_PT_grlens_illumination, VIEW3D_PT_grlens_physical_time, VIEW3D_PT_grlens_check, VIEW3D_PT_grlens_advanced,
           OBJECT_PT_grlens)
