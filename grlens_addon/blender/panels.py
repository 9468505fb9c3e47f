"""Sidebar panel (3D viewport > N panel > grlens)."""
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


class VIEW3D_PT_grlens(bpy.types.Panel):
    bl_label = "grlens"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "grlens"

    def draw(self, context):
        layout = self.layout
        g = context.scene.grlens
        col = layout.column()
        col.prop(g, "black_hole")
        col.prop(g, "r_s")
        row = col.row(align=True)
        row.prop(g, "speed_of_light")
        row.operator("grlens.set_speed_of_light", text="", icon="TIME")
        if g.speed_of_light > 0:
            col.label(text=f"r_s/c = {g.r_s / g.speed_of_light:.4g} frames (coordinate time)")
            col.operator("grlens.camera_geodesic")
            row = col.row(align=True)
            for prop in ("use_aberration", "use_doppler_colour", "use_beaming", "use_gravitational_shift"):
                row.prop(g, prop, toggle=True)
        col.prop(g, "observer")
        note = panorama_note(context.scene)
        if note:
            col.label(text=note, icon="INFO")
        obj = context.object
        if obj is not None and obj.grlens.order == 0 and (can_lens(obj) or obj.grlens.enabled):
            col.prop(obj.grlens, "enabled", text=f"Lens '{obj.name}'")
            if obj.grlens.enabled:
                col.prop(obj.grlens, "emitter")
                if obj.grlens.emitter == "THIN_DISC":
                    sub = col.box()
                    sub.prop(obj.grlens, "disc_mode")
                    row = sub.row(align=True)
                    row.prop(obj.grlens, "disc_r_in")
                    row.prop(obj.grlens, "disc_prograde")
                    sub.prop(obj.grlens, "disc_t_peak")
                    sub.prop(obj.grlens, "disc_exposure")
        col.separator()
        col.prop(g, "show_order_1")
        col.prop(g, "show_order_2")
        box = layout.box()
        box.label(text="Subdivision and culling")
        box.prop(g, "max_tess_level")
        row = box.row(align=True)
        row.prop(g, "tess_a")
        row.prop(g, "tess_b")
        box.prop(g, "tess_max_error")
        box.prop(g, "tess_max_error_viewport")
        box.prop(g, "cull_ratio")
        box = layout.box()
        box.label(text="Lookup table (radii in r_s)")
        box.prop(g, "lut_mode", text="")
        if g.lut_mode == "FIXED_RANGE":
            row = box.row(align=True)
            row.prop(g, "lut_r_min")
            row.prop(g, "lut_r_max")
            row = box.row(align=True)
            row.prop(g, "lut_n_r")
            row.prop(g, "lut_n_phi")
        else:
            box.prop(g, "lut_r_min")
        row = box.row(align=True)
        row.operator("grlens.pack_lut", icon="PACKAGE")
        row.operator("grlens.unpack_luts", icon="UGLYPACKAGE", text="")
        box = layout.box()
        box.prop(g, "use_gr_illumination")
        sub = box.column()
        sub.enabled = g.use_gr_illumination
        sub.prop(g, "light")
        sub.prop(g, "light_intensity")
        layout.prop(g, "lens_world")
        if g.world_status:
            layout.label(text=g.world_status, icon="ERROR" if g.world_status.startswith("grlens:") else "WORLD")
        layout.prop(g, "auto_update")
        row = layout.row(align=True)
        row.operator("grlens.rebuild", icon="FILE_REFRESH")
        row.operator("grlens.clear", icon="X")
        layout.operator("grlens.demo_scene", icon="SPHERE")
        layout.operator("grlens.check_frame", icon="VIEWZOOM")
        if g.check_summary:
            layout.label(text=g.check_summary, icon="INFO")
        if g.status:
            layout.label(text=g.status, icon="ERROR" if g.status.startswith("grlens:") else "INFO")
        lines = report_lines(g)
        if lines:
            col = layout.column(align=True)
            for line in lines:
                col.label(text=line, icon="BLANK1" if line.startswith("...") else "ERROR")


def report_lines(g, limit=None) -> list:
    """The lines of ``g.report_lines`` the panel shows: at most ``limit`` (default
    rebuild.MAX_PANEL_LINES), the rest summed up as "... and N more"."""
    from .rebuild import MAX_PANEL_LINES

    limit = MAX_PANEL_LINES if limit is None else limit
    lines = [ln for ln in g.report_lines.split("\n") if ln]
    if len(lines) > limit:
        return lines[:limit - 1] + [f"... and {len(lines) - limit + 1} more"]
    return lines


CLASSES = (VIEW3D_PT_grlens,)
