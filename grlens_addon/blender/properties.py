"""Public scripting contract: ``scene.grlens`` and ``obj.grlens`` (keep names stable).

Units: ``r_s`` in Blender units (BU); LUT radii in units of r_s; light intensity I0 in BU^2 (so that
the irradiance attribute is I0 / (c dt)^2 with c dt in BU).
"""
import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty


def _changed(self, context):
    from . import handlers

    handlers.request_rebuild(context.scene if context else None)


def _r_s_changed(self, context):
    """r_s set: the hole of Add > Black Hole shows the new horizon and photon sphere, then rebuild."""
    from . import hole

    hole.sync(self.id_data)  # (the scene whose r_s this is)
    _changed(self, context)


def _hole_changed(self, context):
    """Black Hole chosen: a hole of Add > Black Hole shows the scene's r_s (it may have been made for
    another), then rebuild (a mesh as the hole gets its note in the panel and the report)."""
    from . import hole

    hole.sync(self.id_data)
    _changed(self, context)


def _gr_illumination_changed(self, context):
    """Switching GR illumination on creates its node group at once (for material set-up before any
    rebuild), then rebuilds like any setting."""
    if self.use_gr_illumination:
        from . import shading

        shading.ensure_node_group()
    _changed(self, context)


def _speed_changed(self, context):
    """Physical time switched on: the "grlens Shifted Colour" node group is created at once (for
    material set-up before any rebuild), then it rebuilds like any setting."""
    if self.speed_of_light > 0:
        from . import shading

        shading.ensure_shift_node_group()
    _changed(self, context)


def _switch_changed(self, context):
    """A colour switch of physical time: into the shifted-colour node group and the sky at once (no
    rebuild needed)."""
    from . import handlers, shading

    if context is not None and context.scene is not None:
        shading.set_shift_switches(context.scene)
        handlers.update_world(context.scene)  # the sky's switches


def _world_changed(self, context):
    """Lens World switched: lens or restore the world at once (whatever auto update says)."""
    from . import handlers

    handlers.update_world(context.scene if context else None)


def _is_camera(self, obj) -> bool:
    """Only cameras can be the observer (the field's list offers nothing else; a script that sets
    another object gets the rebuild's message)."""
    return obj.type == "CAMERA"


class GRLENS_SceneSettings(bpy.types.PropertyGroup):
    black_hole: PointerProperty(
        name="Black Hole", type=bpy.types.Object, update=_hole_changed,
        description="Object whose location is the centre of the black hole (usually an empty)")
    observer: PointerProperty(
        name="Observer", type=bpy.types.Object, update=_changed, poll=_is_camera,
        description="Camera whose view is lensed (the static observer); empty: the scene's active camera. "
                    "Render through another camera to see the image meshes from outside")
    r_s: FloatProperty(
        name="Schwarzschild Radius", default=1.0, soft_min=1e-6, soft_max=100.0, unit="LENGTH", update=_r_s_changed,
        description="Schwarzschild radius r_s of the black hole, in scene length units (a positive length; "
                    "zero or a negative value is refused with a message, never clamped)")
    speed_of_light: FloatProperty(
        name="Speed of Light", default=0.0, soft_min=0.0, soft_max=100.0, precision=4, update=_speed_changed,
        description="Speed of light c in scene length units per frame. 0: infinite, every frame a still seen by "
                    "a camera at rest (as without it). Above 0, frames measure Schwarzschild coordinate time (the "
                    "clock of a distant observer at rest; a fall seen in this time slows near the horizon): the "
                    "camera's motion, read from its animation, aberrates the images and shifts their light "
                    "(point attribute grlens_redshift = 1 + z; node group 'grlens Shifted Colour'), and the black "
                    "hole must stay at rest. A negative value is refused with a message")
    use_aberration: BoolProperty(
        name="Aberration", default=True, update=_changed,
        description="Physical time: the camera's motion aberrates its view (images and sky). Off, for teaching: "
                    "the directions of a camera at rest, the light still shifted")
    use_doppler_colour: BoolProperty(
        name="Doppler Colour", default=True, update=_switch_changed,
        description="Physical time: the motions' shift changes the hue (node group 'grlens Shifted Colour')")
    use_beaming: BoolProperty(
        name="Beaming", default=True, update=_switch_changed,
        description="Physical time: the motions' shift changes the brightness (node group 'grlens Shifted Colour')")
    use_gravitational_shift: BoolProperty(
        name="Gravitational Shift", default=True, update=_switch_changed,
        description="Physical time: the gravitational shift between the surface and the camera changes hue and "
                    "brightness (node group 'grlens Shifted Colour')")
    lut_mode: EnumProperty(
        name="Lookup Table", default="EVERY_DISTANCE", update=_changed,
        items=[("EVERY_DISTANCE", "Every Distance",
                "Tables from LUT r min out to infinity for any camera distance: a camera or light that moves "
                "needs no new table per frame (exact tables at fixed distances, interpolated)"),
               ("ONE_TABLE", "One Table",
                "One table of light orbits for every camera distance (inside the photon sphere too): a camera "
                "that moves never waits for a table; each frame solves its points' rays from it (slower per "
                "frame than Every Distance once its tables exist)"),
               ("FIXED_RANGE", "Fixed Range",
                "One table over [LUT r min, LUT r max] with LUT rows x LUT columns nodes, built for the camera's "
                "distance (a new one whenever it changes); geometry outside the range is not imaged")],
        description="Which lookup tables of connecting rays grlens uses")
    lut_r_min: FloatProperty(
        name="LUT r min", default=1.05, min=1.000001, soft_max=10.0, update=_changed,
        description="Smallest radius covered by the lookup table, in units of r_s (> 1: outside the horizon)")
    lut_r_max: FloatProperty(
        name="LUT r max", default=40.0, min=1.1, soft_max=1000.0, update=_changed,
        description="Fixed Range tables only: largest radius covered, in units of r_s; parts farther out are "
                    "not imaged")
    lut_n_r: IntProperty(
        name="LUT rows", default=256, min=16, max=4096, update=_changed,
        description="Fixed Range tables only: rows (uniform in r_s/r)")
    lut_n_phi: IntProperty(
        name="LUT columns", default=512, min=16, max=8192, update=_changed,
        description="Fixed Range tables only: columns (uniform in the angle phi from 0 to 180 degrees)")
    max_tess_level: IntProperty(
        name="Max Tess Level", default=64, min=1, max=64, update=_changed,
        description="Largest number of segments an edge is split into (eq. 19 of Mueller et al. 2021)")
    tess_a: FloatProperty(
        name="Tess a", default=5.0, min=0.0, soft_max=50.0, update=_changed,
        description="Factor a of the tessellation heuristic N = MaxTessLevel * clamp(a rho^b, 0, 1)")
    tess_b: FloatProperty(
        name="Tess b", default=0.75, min=0.01, soft_max=4.0, update=_changed,
        description="Exponent b of the tessellation heuristic N = MaxTessLevel * clamp(a rho^b, 0, 1)")
    tess_max_error: FloatProperty(
        name="Tess Max Error", default=0.25, min=0.0, soft_min=0.01, soft_max=4.0, update=_changed,
        description="Screen-space tolerance in pixels: edges are split no more than needed to keep their straight "
                    "pieces this close to the curved image (0: eq. 19 alone, capped only by the edge's pixel length)")
    tess_max_error_viewport: FloatProperty(
        name="Viewport Max Error", default=1.0, min=0.0, soft_max=8.0, update=_changed,
        description="Screen-space tolerance in pixels of the automatic updates in the viewport (frame changes, "
                    "edits), for fast scrubbing; the larger of this and Tess Max Error is used. Renders and the "
                    "Rebuild operator always use Tess Max Error. 0: the viewport uses Tess Max Error too")
    max_triangles: IntProperty(
        name="Max Triangles", default=1_000_000, min=1000, soft_max=10_000_000, update=_changed,
        description="Most image triangles one object may get (both orders) from the cutting that keeps every "
                    "piece within Tess Max Error inside; when this stops it, the report names the object "
                    "and how far off its pieces are")
    cull_ratio: FloatProperty(
        name="Cull Ratio", default=8.0, min=1.0, soft_max=100.0, update=_changed,
        description="Drop image triangles whose circumference exceeds this many times the undistorted one "
                    "(triangles straddling the observer-hole axis, which belong to an Einstein ring)")
    show_order_1: BoolProperty(name="First-order Images", default=True, update=_changed,
                               description="Show the images seen along the direct ray")
    show_order_2: BoolProperty(name="Second-order Images", default=True, update=_changed,
                               description="Show the images seen along the ray around the other side of the hole")
    use_gr_illumination: BoolProperty(
        name="GR Illumination", default=False, update=_gr_illumination_changed,
        description="Compute the irradiance of a point light along both connecting geodesics into the "
                    "'grlens_irradiance' attribute (use the 'grlens GR Illumination' node group)")
    light: PointerProperty(name="Light", type=bpy.types.Object, update=_changed,
                           description="Point light (any object; its location is used) for GR illumination")
    light_intensity: FloatProperty(name="Light Intensity", default=1000.0, min=0.0, update=_changed,
                                   description="I0 of eq. 21: irradiance = I0 max(0, n.d) / (c dt)^2, c dt in scene units")
    lens_world: BoolProperty(
        name="Lens World", default=True, update=_world_changed,
        description="While a black hole is set, show the world (sky) as the observer camera sees it past the hole: "
                    "every world direction replaced by the direction its ray leaves in, black where rays fall in. "
                    "Changes the world's node tree in place (restored exactly when switched off; saved files "
                    "hold the original world)")
    world_status: StringProperty(name="World Status", default="", options={"SKIP_SAVE"},
                                 description="Outcome of the last world update (read only)")
    auto_update: BoolProperty(name="Auto Update", default=True,
                              description="Rebuild the images on frame changes and edits")
    build_in_background: BoolProperty(
        name="Build in Background", default=True,
        description="In the viewport, automatic updates and the panel's buttons whose build is predicted to take "
                    "longer than a quarter of a second run beside the interface: progress in the status bar and the "
                    "panel, Esc cancels, the former images stay until the new ones are ready. Renders, background "
                    "mode and scripts calling the operators always build at once. Off: every build at once")
    status: StringProperty(name="Status", default="", options={"SKIP_SAVE"},
                           description="Outcome of the last rebuild (read only)")
    report_lines: StringProperty(
        name="Report", default="", options={"SKIP_SAVE"},
        description="What the last rebuild could not image, one line each (read only): marked objects skipped "
                    "(no faces) or failed, parts without faces, triangles that could not be mapped and why")
    check_summary: StringProperty(
        name="Last Check", default="",
        description="Outcome of the last bpy.ops.grlens.check_frame(): coverage mismatch, errors and times "
                    "against the reference ray tracer (read only)")


class GRLENS_ObjectSettings(bpy.types.PropertyGroup):
    enabled: BoolProperty(name="Lens This Object", default=False, update=_changed,
                          description="Replace what the camera sees of this object by its lensed images (meshes, "
                                      "curves, text, surfaces, metaballs, Geometry Nodes output and instances; what "
                                      "has no faces is skipped and named in the report)")
    emitter: EnumProperty(
        name="Emitter", default="SURFACE", update=_changed,
        items=(("SURFACE", "Surface", "Shaded by its own materials (and GR illumination if on)"),
               ("THIN_DISC", "Thin Disc", "A thin accretion disc of gas on circular orbits about the object's local Z "
                                          "axis: image vertices get 1 + z ('grlens_redshift') and the Page-Thorne flux "
                                          "/ (1 + z)^4 as a colour ('grlens_disc_colour'; node group "
                                          "'grlens Thin Disc Emission')")),
        description="What the object's images show")
    disc_mode: EnumProperty(
        name="Disc Colour", default="BOLOMETRIC", update=_changed,
        items=(("BOLOMETRIC", "Bolometric", "Grey: observed flux F / (1 + z)^4 relative to the emitted maximum"),
               ("BLACKBODY", "Blackbody", "Colour of the observed temperature T / (1 + z), scaled by the observed flux")),
        description="How the thin disc's observed flux becomes a colour")
    disc_prograde: BoolProperty(name="Prograde", default=True, update=_changed,
                                description="Gas turns counter-clockwise about the object's local Z axis (else clockwise)")
    disc_r_in: FloatProperty(name="Inner Radius", default=3.0, min=3.0, soft_max=20.0, update=_changed,
                             description="Inner edge of the emitting disc in units of r_s (3: the innermost stable orbit)")
    disc_t_peak: FloatProperty(name="Peak Temperature", default=10000.0, min=100.0, soft_max=1e6, update=_changed,
                               description="Emitted temperature in kelvin where the flux is largest (blackbody colour)")
    disc_exposure: FloatProperty(name="Disc Exposure", default=1.0, min=0.0, soft_max=100.0, update=_changed,
                                 description="Colour scale: 1 maps the largest emitted flux to 1")
    source: PointerProperty(type=bpy.types.Object, name="Source",
                            description="For image objects made by grlens: the object they show (read only)")
    order: IntProperty(name="Image Order", default=0, min=0, max=2,
                       description="For image objects made by grlens: 1 or 2 (read only)")
    saved_visible_camera: BoolProperty(default=True, options={"HIDDEN"},
                                       description="The source's own camera visibility, restored when disabled")
    saved_hide_render: BoolProperty(default=False, options={"HIDDEN"},
                                    description="The source's own render visibility, restored when disabled")


CLASSES = (GRLENS_SceneSettings, GRLENS_ObjectSettings)


def attach():
    bpy.types.Scene.grlens = PointerProperty(type=GRLENS_SceneSettings)
    bpy.types.Object.grlens = PointerProperty(type=GRLENS_ObjectSettings)


def detach():
    for owner in (bpy.types.Scene, bpy.types.Object):
        if hasattr(owner, "grlens"):
            del owner.grlens
