"""Sample scenes built with grlens' public scripting API only (scene.grlens, obj.grlens, bpy.ops.grlens).

Units: Blender units (BU); each scene states its Schwarzschild radius r_s in BU. The seed-000 scenes
(Mueller, Schulz & Weiskopf 2021, section 4) use r_s = 2 BU with the static observer at 20 r_s = 40 BU
on the +x axis looking at the hole at the origin, so the paper's coordinates (given for r_s = 2) are
used unchanged in BU.

Every builder takes a fresh, empty scene and returns it; ``SCENES`` maps the scene names of
``render.py --scene`` to builders and ``DEFAULTS`` gives each its default frames, resolution and
samples. The lensed objects' source meshes are hidden from renders by grlens; what renders are their
images ``<name>.GR1`` / ``<name>.GR2`` in the ``grlens`` collection. Other (unlensed) objects are
visual aids: the grey disc or the black sphere that marks the hole's shadow.
"""
import functools
import math

import bpy

from sample_scenes import luminet as _luminet
from sample_scenes import starfield as _starfield
from sample_scenes import orbit as _orbit

# --------------------------------------------------------------------------------------------------
# helpers (plain bpy: materials, cameras, meshes)
# --------------------------------------------------------------------------------------------------


def _new_material(name):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):  # 5.0: always nodes, use_nodes deprecated
        mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    return mat, nt, out


def _emission_checker(name, color_a, color_b, scale=8.0):
    """A checkerboard emission material (needs no lights; UV-mapped)."""
    mat, nt, out = _new_material(name)
    tex = nt.nodes.new("ShaderNodeTexChecker")
    tex.inputs["Scale"].default_value = scale
    tex.inputs["Color1"].default_value = (*color_a, 1.0)
    tex.inputs["Color2"].default_value = (*color_b, 1.0)
    uv = nt.nodes.new("ShaderNodeTexCoord")
    nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
    em = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(tex.outputs["Color"], em.inputs["Color"])
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    mat.diffuse_color = (*color_a, 1.0)
    return mat


def _emission(name, color, strength=1.0):
    mat, nt, out = _new_material(name)
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (*color, 1.0)
    em.inputs["Strength"].default_value = strength
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    mat.diffuse_color = (*color, 1.0)
    return mat


def _principled(name, color, roughness=0.6, checker=None):
    """A diffuse-ish Principled BSDF (lit by Blender's lights); ``checker`` = (color_b, scale) puts a
    UV checkerboard of ``color`` and color_b into the base colour."""
    mat, nt, out = _new_material(name)
    bsdf = nt.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Roughness"].default_value = roughness
    if checker is not None:
        color_b, scale = checker
        tex = nt.nodes.new("ShaderNodeTexChecker")
        tex.inputs["Scale"].default_value = scale
        tex.inputs["Color1"].default_value = (*color, 1.0)
        tex.inputs["Color2"].default_value = (*color_b, 1.0)
        uv = nt.nodes.new("ShaderNodeTexCoord")
        nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
        nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    mat.diffuse_color = (*color, 1.0)
    return mat


def _world(scene, color=(0.0, 0.0, 0.0)):
    world = bpy.data.worlds.new("World")
    world.color = color
    if bpy.app.version < (5, 0, 0):  # 5.0: always nodes, use_nodes deprecated
        world.use_nodes = True
    for node in world.node_tree.nodes:
        if node.bl_idname == "ShaderNodeBackground":
            node.inputs["Color"].default_value = (*color, 1.0)
            node.inputs["Strength"].default_value = 1.0 if any(color) else 0.0
    scene.world = world


def _black_world(scene):
    _world(scene, (0.0, 0.0, 0.0))


def _look_at(obj, target):
    """Point a camera (its -Z axis) at ``target``, +Y of the camera towards +Z of the world."""
    from mathutils import Vector

    d = Vector(target) - obj.location
    obj.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()


def _camera(scene, name, location, target, angle_y_deg=None, angle_deg=None, active=True):
    cam = bpy.data.objects.new(name, bpy.data.cameras.new(name))
    if angle_y_deg is not None:
        cam.data.sensor_fit = "VERTICAL"
        cam.data.angle_y = math.radians(angle_y_deg)
    elif angle_deg is not None:
        cam.data.angle = math.radians(angle_deg)
    cam.data.clip_start, cam.data.clip_end = 0.05, 1000.0
    cam.location = location
    scene.collection.objects.link(cam)
    _look_at(cam, target)
    if active:
        scene.camera = cam
    return cam


def _hole(scene, r_s, location=(0.0, 0.0, 0.0)):
    hole = bpy.data.objects.new("BlackHole", None)
    hole.empty_display_type = "SPHERE"
    hole.empty_display_size = r_s
    hole.location = location
    scene.collection.objects.link(hole)
    return hole


def _mesh_object(scene, name, verts, faces, uvs=None, materials=(), face_materials=None, smooth=False):
    """A mesh object from vertex and face lists; ``uvs`` per face corner (list of lists of (u, v))."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(v) for v in verts], [], [tuple(f) for f in faces])
    if uvs is not None:
        layer = mesh.uv_layers.new(name="UVMap")
        flat = [uv for face in uvs for uv in face]
        for loop, uv in zip(layer.data, flat):
            loop.uv = uv
    for m in materials:
        mesh.materials.append(m)
    if face_materials is not None:
        mesh.polygons.foreach_set("material_index", list(face_materials))
    mesh.polygons.foreach_set("use_smooth", [smooth] * len(mesh.polygons))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(obj)
    return obj


def _shadow_half_angle(r_obs_rs):
    """Half opening angle of the hole's shadow for a static observer at r_obs (r_s): eq. 14 of seed 000."""
    return math.asin(math.sqrt(6.75 / r_obs_rs ** 2 * (1.0 - 1.0 / r_obs_rs)))


def _shadow_disc(scene, cam_location, hole_location, r_s, color=(0.03, 0.03, 0.03), distance=200.0):
    """A dark grey unlensed backdrop disc that exactly fills the observer's shadow cone, ``distance``
    BU from the camera beyond the hole (behind every image mesh, so that, like the semi-transparent
    grey disc of the paper's figure 8, it marks the shadow without hiding anything: in flat spacetime
    the triangle is drawn over it)."""
    from mathutils import Vector

    cam, hole = Vector(cam_location), Vector(hole_location)
    axis = (hole - cam).normalized()
    radius = distance * math.tan(_shadow_half_angle((hole - cam).length / r_s))
    n = 96
    verts = [(radius * math.cos(2 * math.pi * k / n), radius * math.sin(2 * math.pi * k / n), 0.0) for k in range(n)]
    obj = _mesh_object(scene, "ShadowDisc", verts, [list(range(n))], materials=[_emission("Shadow", color)])
    obj.location = cam + distance * axis
    obj.rotation_euler = (-axis).to_track_quat("Z", "Y").to_euler()
    return obj


def _shadow_sphere(scene, cam_location, hole_location, r_s, color=(0.0, 0.0, 0.0)):
    """An unlensed sphere at the hole inscribed in the observer's shadow cone (radius d sin xi_crit):
    it fills the shadow in the observer's view and shows where the shadow is in external views."""
    import bmesh
    from mathutils import Vector

    d = (Vector(hole_location) - Vector(cam_location)).length
    radius = d * math.sin(_shadow_half_angle(d / r_s))
    mesh = bpy.data.meshes.new("ShadowSphere")
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=48, v_segments=24, radius=radius)
    bm.to_mesh(mesh)
    bm.free()
    mesh.polygons.foreach_set("use_smooth", [True] * len(mesh.polygons))
    mesh.materials.append(_principled("ShadowSphere", color, roughness=0.4))
    obj = bpy.data.objects.new("ShadowSphere", mesh)
    obj.location = hole_location
    scene.collection.objects.link(obj)
    return obj


def _lens(scene, hole, r_s, objects, **settings):
    """Mark ``objects`` for lensing around ``hole`` and apply scene.grlens ``settings`` (one rebuild at
    the end: auto_update is off while the settings change)."""
    g = scene.grlens
    g.auto_update = False
    g.black_hole, g.r_s = hole, r_s
    for key, value in settings.items():
        setattr(g, key, value)
    for obj in objects:
        obj.grlens.enabled = True
    g.auto_update = True


def _linear_keys(obj):
    """Linear interpolation for all keys of the object's action (Blender 4.x: action.fcurves; 5.0:
    the F-curves live in the channel bags of the action's layered strips)."""
    ad = obj.animation_data
    action = ad.action if ad is not None else None
    if action is None:
        return
    if hasattr(action, "layers") and len(action.layers):
        curves = [fc for layer in action.layers for strip in layer.strips
                  for bag in getattr(strip, "channelbags", []) for fc in bag.fcurves]
    else:
        curves = list(getattr(action, "fcurves", []))
    for fc in curves:
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"


# --------------------------------------------------------------------------------------------------
# seed 000, section 4.2: the orbiting sphere
# --------------------------------------------------------------------------------------------------


def sphere_orbit(scene):
    """Seed 000, section 4.2: a sphere of radius 0.5 r_s (36 x 18 UV sphere) on the last stable orbit
    r = 3 r_s, one orbit in 360 frames, camera at 20 r_s with a 19 degree vertical field of view,
    MaxTessLevel 64, a = 5, b = 0.75. r_s = 2 BU."""
    bpy.ops.grlens.demo_scene(r_s=2.0)
    sphere = bpy.data.objects["OrbitingSphere"]
    sphere.data.materials.clear()
    sphere.data.materials.append(_emission_checker("SphereChecker", (0.9, 0.5, 0.1), (0.1, 0.3, 0.9), 12.0))
    _black_world(scene)
    return scene


# --------------------------------------------------------------------------------------------------
# seed 000, section 4.1: one triangle behind the hole
# --------------------------------------------------------------------------------------------------

TRIANGLE_P1 = (-5.0, 3.0, -0.5)
TRIANGLE_P2 = (-5.0, 0.5, -0.5)


def _triangle(scene, tess_level=64, lensed=True, shadow_disc=False, paper_tess=False):
    """The triangle of seed 000, section 4.1 (see triangle_behind). ``tess_level``: MaxTessLevel;
    ``paper_tess``: eq. 19 alone (scene.grlens.tess_max_error = 0, no screen-space cap), as in the
    paper's figure 8; ``lensed=False``: flat spacetime (the triangle is rendered as it is);
    ``shadow_disc``: a dark grey unlensed disc filling the hole's shadow (figure 8's grey disc)."""
    r_s = 2.0
    hole = _hole(scene, r_s)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.sensor_fit = "VERTICAL"
    cam.data.angle_y = math.radians(20.0)
    cam.location = (20 * r_s, 0.0, 0.0)
    cam.rotation_euler = (math.radians(90.0), 0.0, math.radians(90.0))
    scene.collection.objects.link(cam)
    scene.camera = cam
    mesh = bpy.data.meshes.new("Triangle")
    mesh.from_pydata([(0, 0, 0), (0, 3, 0), (0, 0, 3)], [], [(0, 1, 2)])
    uv = mesh.uv_layers.new(name="UVMap")
    for loop, co in zip(uv.data, [(0, 0), (1, 0), (0, 1)]):
        loop.uv = co
    tri = bpy.data.objects.new("Triangle", mesh)
    scene.collection.objects.link(tri)
    mesh.materials.append(_emission_checker("TriangleChecker", (0.95, 0.95, 0.95), (0.2, 0.2, 0.2), 8.0))
    tri.location = TRIANGLE_P2
    tri.keyframe_insert("location", frame=1)
    tri.location = TRIANGLE_P1
    tri.keyframe_insert("location", frame=150)
    tri.location = TRIANGLE_P2
    tri.keyframe_insert("location", frame=300)
    scene.frame_start, scene.frame_end = 1, 300
    g = scene.grlens
    g.auto_update = False
    g.black_hole, g.r_s = hole, r_s
    g.max_tess_level, g.tess_a, g.tess_b = tess_level, 5.0, 0.75
    if paper_tess:
        g.tess_max_error = 0.0
    tri.grlens.enabled = lensed
    g.auto_update = lensed  # flat spacetime: grlens stays idle
    cam.data.clip_end = 1000.0
    if shadow_disc:
        _shadow_disc(scene, cam.location, hole.location, r_s)
    _black_world(scene)
    return scene


def triangle_behind(scene):
    """Seed 000, section 4.1: a checkerboard triangle behind the hole at p2 = (-5, 0.5, -0.5) with legs
    of 3 BU along y and z; r_s = 2 BU, observer at (40, 0, 0), vertical field of view 20 degrees;
    frames 1..300 move it from p2 to p1 = (-5, 3, -0.5) (frame 150) and back (the paper's 300-frame
    sequence). MaxTessLevel 64, a = 5, b = 0.75, screen-space cap on (tess_max_error 0.25 px)."""
    return _triangle(scene)


def triangle_tess(scene, level):
    """Seed 000, figure 8 (b)-(d): the triangle scene with MaxTessLevel = ``level`` (1: no
    subdivision, only the three corners are mapped; 4; 64) and eq. 19 alone (tess_max_error = 0, as in
    the paper), with the dark grey disc marking the shadow. Frame 1: p2, frame 150: p1."""
    return _triangle(scene, tess_level=level, shadow_disc=True, paper_tess=True)


def triangle_flat(scene):
    """Seed 000, figure 8 (a): the same triangle in flat spacetime (not lensed: rendered as it is), with
    the dark grey disc where the hole's shadow would be. Frame 1: p2, frame 150: p1."""
    return _triangle(scene, lensed=False, shadow_disc=True)


# --------------------------------------------------------------------------------------------------
# seed 000, section 4.3: the accretion disc
# --------------------------------------------------------------------------------------------------

DISC_R_S = 2.0
DISC_OBSERVER = (40.0, 0.0, 0.0)
DISC_LIGHT = (40.0 * math.sin(math.radians(80.0)), 0.0, 40.0 * math.cos(math.radians(80.0)))
"""(39.392, 0, 6.946) BU: the paper's point light (39.39, 0, 6.95), i.e. r = 20 r_s, theta = 80 deg with
r_s = 2 BU (its coordinates are in BU, not r_s: |(39.39, 0, 6.95)| = 40.0 = 20 r_s)."""
DISC_EXTERNAL = {90: (20.0, -36.0, 0.0), 30: (10.0, -40.0, 4.0), 10: (0.0, -40.0, 4.0)}
"""The paper's external cameras (figure 10 b, d, f), BU."""
DISC_EXTERNAL_TARGET = (-16.0, 0.0, 1.0)
"""Where the external cameras look (BU): about the middle of the image meshes, which lie 25..85 BU
from the observer (first order from x = 14 to -24, second order from -17 to -44)."""
DISC_FRAMES = {90: 1, 30: 61, 10: 81}
"""Frames of the ``disc`` sequence at the paper's inclinations (inclination = 91 - frame degrees)."""


def _disc_mesh(scene, r_in, r_out, thickness, n_seg=128, n_rad=4, cells=(16, 4)):
    """A ring of rectangular cross-section in its local xy plane (normal +z): top and bottom faces of
    n_seg x n_rad quads, inner and outer edges of n_seg quads each: n_seg * (2 n_rad + 2) quads
    (2560 triangles for 128 x 4, as in the paper). Corner UVs: polar, scaled so that the unit
    checkerboard gives cells[0] sectors x cells[1] rings on the top and bottom; material slots 0 top
    (red checkerboard), 1 bottom (blue checkerboard), 2 edges (green)."""
    verts, faces, uvs, fmat = [], [], [], []
    h = 0.5 * thickness
    radii = [r_in + (r_out - r_in) * k / n_rad for k in range(n_rad + 1)]

    def vid(k, j, top):  # k: angle index (mod n_seg), j: radius index
        return ((1 if top else 0) * n_seg + (k % n_seg)) * (n_rad + 1) + j

    for top in (False, True):
        for k in range(n_seg):
            a = 2 * math.pi * k / n_seg
            for r in radii:
                verts.append((r * math.cos(a), r * math.sin(a), h if top else -h))
    su, sv = cells[0] / n_seg, cells[1] / n_rad
    for k in range(n_seg):
        for j in range(n_rad):
            # top: counter-clockwise seen from +z
            faces.append([vid(k, j, True), vid(k, j + 1, True), vid(k + 1, j + 1, True), vid(k + 1, j, True)])
            uvs.append([(k * su, j * sv), (k * su, (j + 1) * sv), ((k + 1) * su, (j + 1) * sv), ((k + 1) * su, j * sv)])
            fmat.append(0)
            faces.append([vid(k, j, False), vid(k + 1, j, False), vid(k + 1, j + 1, False), vid(k, j + 1, False)])
            uvs.append([(k * su, j * sv), ((k + 1) * su, j * sv), ((k + 1) * su, (j + 1) * sv), (k * su, (j + 1) * sv)])
            fmat.append(1)
        for j, outward in ((0, False), (n_rad, True)):  # inner and outer edge
            quad = [vid(k, j, False), vid(k + 1, j, False), vid(k + 1, j, True), vid(k, j, True)]
            faces.append(quad if outward else quad[::-1])
            uvs.append([(k * su, 0.0), ((k + 1) * su, 0.0), ((k + 1) * su, 1.0), (k * su, 1.0)]
                       if outward else [(k * su, 1.0), ((k + 1) * su, 1.0), ((k + 1) * su, 0.0), (k * su, 0.0)])
            fmat.append(2)
    materials = [_checker_colour("DiscTop", (0.9, 0.12, 0.05), (0.45, 0.03, 0.02)),
                 _checker_colour("DiscBottom", (0.08, 0.25, 0.95), (0.03, 0.08, 0.45)),
                 _checker_colour("DiscEdge", (0.1, 0.8, 0.15), None)]
    return _mesh_object(scene, "Disc", verts, faces, uvs, materials, fmat)


def _checker_colour(name, color_a, color_b):
    """Emission (node "Colour") of a UV checkerboard of unit cells in color_a / color_b, or of color_a
    alone; _use_gr_illumination later replaces the emission by GR illumination."""
    mat, nt, out = _new_material(name)
    em = nt.nodes.new("ShaderNodeEmission")
    em.name = "Colour"
    if color_b is None:
        em.inputs["Color"].default_value = (*color_a, 1.0)
    else:
        tex = nt.nodes.new("ShaderNodeTexChecker")
        tex.inputs["Scale"].default_value = 1.0
        tex.inputs["Color1"].default_value = (*color_a, 1.0)
        tex.inputs["Color2"].default_value = (*color_b, 1.0)
        uv = nt.nodes.new("ShaderNodeTexCoord")
        nt.links.new(uv.outputs["UV"], tex.inputs["Vector"])
        nt.links.new(tex.outputs["Color"], em.inputs["Color"])
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    mat.diffuse_color = (*color_a, 1.0)
    return mat


def _use_gr_illumination(mat, exposure=1.0):
    """Replace the material's emission node "Colour" by the "grlens GR Illumination" node group
    (which grlens creates at the first rebuild with GR illumination on): emission = colour x the
    irradiance of the point light along both geodesics (seed 000, eq. 21)."""
    group = bpy.data.node_groups.get("grlens GR Illumination")
    if group is None:
        raise RuntimeError("grlens made no 'grlens GR Illumination' node group (is use_gr_illumination on?)")
    nt = mat.node_tree
    em = nt.nodes["Colour"]
    node = nt.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    node.inputs["Exposure"].default_value = exposure
    src = em.inputs["Color"]
    if src.is_linked:
        nt.links.new(src.links[0].from_socket, node.inputs["Color"])
    else:
        node.inputs["Color"].default_value = src.default_value
    out = next(n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    nt.nodes.remove(em)
    nt.links.new(node.outputs["Shader"], out.inputs["Surface"])


def accretion_disc(scene, inclination=None, external=False):
    """Seed 000, section 4.3 and figure 10: a ring r_in = 3.3 r_s, r_out = 8.25 r_s, thickness 0.55 r_s
    (2560 triangles) with a polar checkerboard, red on top, blue below, green edges, around a hole of
    r_s = 2 BU; observer at (40, 0, 0) BU = 20 r_s (vertical field of view 50 degrees); a point light
    at r = 20 r_s, theta = 80 degrees, i.e. (39.39, 0, 6.95) BU (the paper's numbers are in BU with
    r_s = 2, not in r_s), lighting the disc along both geodesics with grlens' GR illumination
    (I0 = 1600 BU^2: irradiance about 1 at 40 BU).

    Inclination = angle between the line of sight and the disc plane: 90 degrees face-on (top towards
    the observer), 0 edge-on; the disc is tilted about the y axis. ``inclination=None``: the 180-frame
    sequence (the paper's table 3 gives 180 images for the disc but not what changes; here the
    inclination falls by one degree per frame, 90 at frame 1 to -89 at frame 180, so frames 1, 61 and
    81 are the paper's 90, 30 and 10 degrees, and the bottom turns towards the observer after frame 91).

    ``external``: render through an external camera at the paper's position for that inclination
    (20, -36, 0), (10, -40, 4) or (0, -40, 4) BU, with scene.grlens.observer = the observer camera:
    the image meshes are seen from outside, each vertex at its light-travel-time distance c dt from
    the observer; a black sphere inscribed in the observer's shadow cone marks the hole, against a dark blue
    background (not lensed: scene.grlens.lens_world is off; the view illustrates the image meshes in
    space, and its uniform background shows no lensing anyway)."""
    r_s = DISC_R_S
    hole = _hole(scene, r_s)
    observer = _camera(scene, "Observer", DISC_OBSERVER, (0.0, 0.0, 0.0), angle_y_deg=50.0)
    lamp = bpy.data.objects.new("PointLight", bpy.data.lights.new("PointLight", "POINT"))
    lamp.location = DISC_LIGHT
    scene.collection.objects.link(lamp)
    lamp.data.energy = 0.0  # not a Blender light: grlens' GR illumination uses its position only
    disc = _disc_mesh(scene, 3.3 * r_s, 8.25 * r_s, 0.55 * r_s)
    if inclination is None:
        disc.rotation_euler = (0.0, math.radians(90.0), 0.0)
        disc.keyframe_insert("rotation_euler", index=1, frame=1)
        disc.rotation_euler = (0.0, math.radians(-90.0), 0.0)
        disc.keyframe_insert("rotation_euler", index=1, frame=181)
        _linear_keys(disc)
        scene.frame_start, scene.frame_end = 1, 180
    else:
        disc.rotation_euler = (0.0, math.radians(inclination), 0.0)
        scene.frame_start, scene.frame_end = 1, 1
    # lens_world off for the external views: they illustrate the image meshes in space (the black
    # sphere marks the hole), and a uniform background shows no lensing (grlens would lens the sky
    # for the external camera that renders, docs/sky.md)
    _lens(scene, hole, r_s, [disc], max_tess_level=64, tess_a=5.0, tess_b=0.75, observer=observer,
          use_gr_illumination=True, light=lamp, light_intensity=1600.0, lens_world=not external)
    # the first rebuild with GR illumination creates the "grlens GR Illumination" node group, which
    # the disc's materials then use
    bpy.ops.grlens.rebuild()
    for mat in disc.data.materials:
        _use_gr_illumination(mat)
    if external:
        incl = 30 if inclination is None else inclination
        pos = DISC_EXTERNAL.get(incl) or DISC_EXTERNAL[min(DISC_EXTERNAL, key=lambda k: abs(k - incl))]
        _camera(scene, "ExternalCamera", pos, DISC_EXTERNAL_TARGET, angle_y_deg=62.0)
        _shadow_sphere(scene, observer.location, hole.location, r_s)
        _world(scene, (0.015, 0.02, 0.04))
    else:
        _black_world(scene)
    return scene


# --------------------------------------------------------------------------------------------------
# seed 004: the observer inside a gridded shell
# --------------------------------------------------------------------------------------------------

SHELL_R_S = 1.0
SHELL_RADIUS = 10.0  # r_s
SHELL_OBSERVER = 5.0  # r_s


def _lat_long_sphere(radius, n_lon, n_lat):
    """(vertices, faces, corner uvs) of a latitude/longitude sphere: u = longitude / 360 deg,
    v = (latitude + 90 deg) / 180 deg; poles as triangle fans."""
    verts = [(0.0, 0.0, -radius)]
    for i in range(1, n_lat):
        lat = -math.pi / 2 + math.pi * i / n_lat
        for k in range(n_lon):
            lon = 2 * math.pi * k / n_lon
            verts.append((radius * math.cos(lat) * math.cos(lon), radius * math.cos(lat) * math.sin(lon),
                          radius * math.sin(lat)))
    verts.append((0.0, 0.0, radius))
    top = len(verts) - 1

    def vid(i, k):  # ring i in 1..n_lat-1
        return 1 + (i - 1) * n_lon + (k % n_lon)

    faces, uvs = [], []
    for k in range(n_lon):
        u0, u1 = k / n_lon, (k + 1) / n_lon
        faces.append([0, vid(1, k + 1), vid(1, k)])
        uvs.append([(0.5 * (u0 + u1), 0.0), (u1, 1 / n_lat), (u0, 1 / n_lat)])
        for i in range(1, n_lat - 1):
            v0, v1 = i / n_lat, (i + 1) / n_lat
            faces.append([vid(i, k), vid(i, k + 1), vid(i + 1, k + 1), vid(i + 1, k)])
            uvs.append([(u0, v0), (u1, v0), (u1, v1), (u0, v1)])
        v0 = (n_lat - 1) / n_lat
        faces.append([vid(n_lat - 1, k), vid(n_lat - 1, k + 1), top])
        uvs.append([(u0, v0), (u1, v0), (0.5 * (u0 + u1), 1.0)])
    return verts, faces, uvs


def _grid_lines_material(name, step_deg=15.0, width_deg=0.6, line=(0.25, 0.6, 1.0), base=(0.02, 0.03, 0.06)):
    """Emission: ``line`` colour on the latitude and longitude lines every ``step_deg`` (UVs of
    _lat_long_sphere), a dim ``base`` colour between them (so that every part of the shell is visible)."""
    mat, nt, out = _new_material(name)
    uv = nt.nodes.new("ShaderNodeTexCoord")
    sep = nt.nodes.new("ShaderNodeSeparateXYZ")
    nt.links.new(uv.outputs["UV"], sep.inputs["Vector"])
    masks = []
    for axis, degrees in (("X", 360.0), ("Y", 180.0)):
        n_cells = degrees / step_deg
        half = 0.5 * width_deg / step_deg  # half line width in cell units
        mul = nt.nodes.new("ShaderNodeMath")
        mul.operation = "MULTIPLY_ADD"
        mul.inputs[1].default_value = n_cells
        mul.inputs[2].default_value = 0.5
        nt.links.new(sep.outputs[axis], mul.inputs[0])
        frac = nt.nodes.new("ShaderNodeMath")
        frac.operation = "FRACT"
        nt.links.new(mul.outputs["Value"], frac.inputs[0])
        dist = nt.nodes.new("ShaderNodeMath")  # |fract(c + 0.5) - 0.5|: distance to the nearest line
        dist.operation = "SUBTRACT"
        dist.inputs[1].default_value = 0.5
        nt.links.new(frac.outputs["Value"], dist.inputs[0])
        ab = nt.nodes.new("ShaderNodeMath")
        ab.operation = "ABSOLUTE"
        nt.links.new(dist.outputs["Value"], ab.inputs[0])
        lt = nt.nodes.new("ShaderNodeMath")
        lt.operation = "LESS_THAN"
        lt.inputs[1].default_value = half
        nt.links.new(ab.outputs["Value"], lt.inputs[0])
        masks.append(lt)
    both = nt.nodes.new("ShaderNodeMath")
    both.operation = "MAXIMUM"
    nt.links.new(masks[0].outputs["Value"], both.inputs[0])
    nt.links.new(masks[1].outputs["Value"], both.inputs[1])
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    nt.links.new(both.outputs["Value"], mix.inputs["Factor"])
    mix.inputs["A"].default_value = (*base, 1.0)
    mix.inputs["B"].default_value = (*line, 1.0)
    em = nt.nodes.new("ShaderNodeEmission")
    nt.links.new(mix.outputs["Result"], em.inputs["Color"])
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    mat.diffuse_color = (*line, 1.0)
    return mat


def gridded_shell(scene):
    """Seed 004: the observer inside a spherical shell with latitude/longitude lines every 15 degrees
    (emissive texture on a 96 x 48 latitude/longitude sphere; a dim blue between the lines), the hole
    at its centre. r_s = 1 BU; shell radius 10 r_s; camera at 5 r_s (outside the photon sphere,
    shadow half-angle 27.7 degrees) looking at the hole, vertical field of view 90 degrees; the
    shell's pole axis tilted (20 degrees about x, 25 about y) so that its grid is seen obliquely and
    no vertex lies on the observer-hole axis (the axis meets the shell at latitude 23.4 degrees,
    between two rings of vertices; a vertex on the axis would image to a ring).

    The LUT (a fixed-range one, lut_mode FIXED_RANGE) covers r = 8..12 r_s only: the shell lies
    farther out than the observer, which lutgen
    handles (1 < r_min < r_max is its only condition; order-1 rays to targets beyond the observer
    leave outwards), and a range that excludes the observer's own radius keeps the interpolation
    accurate (lookup errors at 10 r_s: 5e-10 rad in xi with [8, 12], 6e-8 rad with [1.05, 12]; a
    range containing r_obs is poor only right next to the camera, where nothing is here).
    Frames 1..120: the shell turns by one grid cell (15 degrees) about its pole axis, a seamless loop
    that moves the lensed grid past the shadow."""
    r_s = SHELL_R_S
    hole = _hole(scene, r_s)
    cam = _camera(scene, "Camera", (SHELL_OBSERVER * r_s, 0.0, 0.0), (0.0, 0.0, 0.0), angle_y_deg=90.0)
    verts, faces, uvs = _lat_long_sphere(SHELL_RADIUS * r_s, 96, 48)
    shell = _mesh_object(scene, "Shell", verts, faces, uvs, [_grid_lines_material("ShellGrid")])
    shell.rotation_mode = "ZXY"  # spin about its own pole axis (z), then tilt
    shell.rotation_euler = (math.radians(20.0), math.radians(25.0), 0.0)
    shell.keyframe_insert("rotation_euler", index=2, frame=1)
    shell.rotation_euler[2] += math.radians(15.0)
    shell.keyframe_insert("rotation_euler", index=2, frame=121)
    _linear_keys(shell)
    scene.frame_start, scene.frame_end = 1, 120
    _lens(scene, hole, r_s, [shell], lut_mode="FIXED_RANGE", lut_r_min=0.8 * SHELL_RADIUS,
          lut_r_max=1.2 * SHELL_RADIUS, max_tess_level=64, tess_a=5.0, tess_b=0.75, observer=cam)
    _black_world(scene)
    return scene


# --------------------------------------------------------------------------------------------------
# seed 003: everyday scale, a room with a small hole in the middle
# --------------------------------------------------------------------------------------------------

ROOM_R_S = 0.4
ROOM_HALF = 5.0
ROOM_CAMERA = (15.0, 0.0, 0.0)


def _grid_quad(n_u, n_v, corner, edge_u, edge_v):
    """(vertices, faces, uvs) of a planar n_u x n_v quad grid from ``corner`` along ``edge_u``/``edge_v``;
    UVs from 0 to 1 across it."""
    verts = []
    for j in range(n_v + 1):
        for i in range(n_u + 1):
            verts.append(tuple(corner[a] + edge_u[a] * i / n_u + edge_v[a] * j / n_v for a in range(3)))
    faces, uvs = [], []
    for j in range(n_v):
        for i in range(n_u):
            a = j * (n_u + 1) + i
            faces.append([a, a + 1, a + n_u + 2, a + n_u + 1])
            uvs.append([(i / n_u, j / n_v), ((i + 1) / n_u, j / n_v), ((i + 1) / n_u, (j + 1) / n_v),
                        (i / n_u, (j + 1) / n_v)])
    return verts, faces, uvs


def _primitive(scene, name, kind, material, location, rotation=(0.0, 0.0, 0.0), **size):
    """A bmesh primitive with split edges at sharp corners (the image meshes are smooth-shaded, so a
    cube needs separate vertices per face to keep its edges crisp), UVs, one material."""
    import bmesh

    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    if kind == "sphere":
        bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=size["radius"], calc_uvs=True)
    elif kind == "cube":
        bmesh.ops.create_cube(bm, size=size["size"], calc_uvs=True)
    elif kind == "cylinder":
        bmesh.ops.create_cone(bm, cap_ends=True, segments=32, radius1=size["radius"], radius2=size["radius"],
                              depth=size["depth"], calc_uvs=True)
    if kind != "sphere":
        sharp = [e for e in bm.edges if e.calc_face_angle(0.0) > math.radians(45.0)]
        bmesh.ops.split_edges(bm, edges=sharp)
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    mesh.polygons.foreach_set("use_smooth", [True] * len(mesh.polygons))
    mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    obj.rotation_euler = rotation
    scene.collection.objects.link(obj)
    return obj


def room(scene):
    """Seed 003 (everyday scale): a Cornell-like room 10 x 10 x 10 BU, open towards the camera, with a
    checkered back wall, red left and green right walls, white floor and ceiling, a sphere, a cube and
    a cylinder, and a small black hole (r_s = 0.4 BU) floating in the middle of the room. Every wall
    and object is a lensed mesh; they use ordinary Principled BSDF materials lit by a Blender area
    light under the ceiling (Cycles), not grlens' GR illumination. Camera at (15, 0, 0) BU = 37.5 r_s,
    outside the room, vertical field of view 40 degrees; LUT r = 1.05..22 r_s (the room's corners
    reach 21.7 r_s; the camera lies outside that range). Frames 1..120: the hole drifts from the room's
    centre 1.5 BU to the left and back, so the lensing moves over the back wall (the camera's distance to
    the hole changes, so every frame of the drift builds its own LUT, about 1 s)."""
    r_s = ROOM_R_S
    hole = _hole(scene, r_s)
    hole.keyframe_insert("location", frame=1)
    hole.location = (0.0, -1.5, 0.0)
    hole.keyframe_insert("location", frame=61)
    hole.location = (0.0, 0.0, 0.0)
    hole.keyframe_insert("location", frame=121)
    scene.frame_start, scene.frame_end = 1, 120
    cam = _camera(scene, "Camera", ROOM_CAMERA, (0.0, 0.0, 0.0), angle_y_deg=40.0)
    h = ROOM_HALF
    white = _principled("Wall White", (0.75, 0.75, 0.72))
    red = _principled("Wall Red", (0.7, 0.08, 0.06))
    green = _principled("Wall Green", (0.1, 0.55, 0.12))
    checker = _principled("Back Wall", (0.8, 0.8, 0.78), checker=((0.08, 0.08, 0.1), 10.0))
    # (name, corner, edge_u, edge_v, cells, material); faces towards the room's inside. The back wall's
    # odd cell count keeps its vertices off the observer-hole axis (a point on the axis images to a
    # ring, seed 000 section 3.2), and its fine grid keeps the Einstein-ring gap (the culled cell) thin.
    walls = [("BackWall", (-h, -h, -h), (0, 2 * h, 0), (0, 0, 2 * h), (41, 41), checker),
             ("Floor", (-h, -h, -h), (2 * h, 0, 0), (0, 2 * h, 0), (20, 20), white),
             ("Ceiling", (-h, -h, h), (0, 2 * h, 0), (2 * h, 0, 0), (20, 20), white),
             ("LeftWall", (-h, -h, -h), (0, 0, 2 * h), (2 * h, 0, 0), (20, 20), red),
             ("RightWall", (-h, h, -h), (2 * h, 0, 0), (0, 0, 2 * h), (20, 20), green)]
    lensed = []
    for name, corner, eu, ev, (nu, nv), mat in walls:
        verts, faces, uvs = _grid_quad(nu, nv, corner, eu, ev)
        lensed.append(_mesh_object(scene, name, verts, faces, uvs, [mat]))
    lensed.append(_primitive(scene, "Sphere", "sphere", _principled("Sphere", (0.85, 0.6, 0.15), 0.3),
                             (-2.0, -2.6, -h + 1.3), radius=1.3))
    lensed.append(_primitive(scene, "Cube", "cube", _principled("Cube", (0.2, 0.35, 0.85), 0.5),
                             (-2.2, 2.4, -h + 1.1), (0.0, 0.0, math.radians(25.0)), size=2.2))
    lensed.append(_primitive(scene, "Cylinder", "cylinder", _principled("Cylinder", (0.8, 0.8, 0.8), 0.25),
                             (-3.0, 0.4, -h + 2.0), radius=0.7, depth=4.0))
    lamp = bpy.data.objects.new("CeilingLight", bpy.data.lights.new("CeilingLight", "AREA"))
    lamp.data.size = 3.0
    lamp.data.energy = 1500.0
    lamp.location = (0.0, 0.0, h - 0.6)
    scene.collection.objects.link(lamp)
    _lens(scene, hole, r_s, lensed, lut_r_min=1.05, lut_r_max=22.0, max_tess_level=32, tess_a=5.0,
          tess_b=0.75, observer=cam)
    _black_world(scene)
    return scene


# --------------------------------------------------------------------------------------------------
# issue 19: a fly-in over a checkered floor (tables for every camera distance)
# --------------------------------------------------------------------------------------------------

FLYIN_R_S = 2.0
FLYIN_FRAMES = 240
FLYIN_DISTANCE = (80.0, 4.5)
"""Camera distance from the hole at the first and the last frame (r_s)."""
FLYIN_ELEVATION = (8.0, 16.0)
"""Camera elevation above the hole's equatorial plane at the first and the last frame (degrees)."""
FLYIN_AZIMUTH = (-90.0, 20.0)
"""Camera azimuth about the hole's z axis, from +x, at the first and the last frame (degrees). The
sphere starts at +90 degrees, so at frame 1 it is right behind the hole."""
FLYIN_FOV = (25.0, 100.0)
"""Vertical field of view at the first and the last frame (degrees)."""
FLOOR_DEPTH = 2.0
"""The floor lies this far below the hole's equatorial plane (r_s)."""
FLOOR_RADIUS = 300.0
"""Radius of the floor disc about the point under the hole (r_s)."""
FLOOR_CELL = 2.0
"""Side of the floor's checker squares (r_s)."""


def flyin_ease(frame):
    """The fly-in's progress at ``frame``: 0 at frame 1, 1 at FLYIN_FRAMES, smoothstep in between (the
    camera starts and stops gently)."""
    s = min(max((frame - 1.0) / (FLYIN_FRAMES - 1.0), 0.0), 1.0)
    return s * s * (3.0 - 2.0 * s)


def flyin_camera(frame):
    """(distance in r_s, elevation in degrees, azimuth in degrees, vertical field of view in degrees) of
    the fly-in's camera at ``frame``: the distance falls geometrically (log-linear in the eased progress,
    so the view grows at an even rate), elevation, azimuth and field of view change linearly with it."""
    e = flyin_ease(frame)
    d = FLYIN_DISTANCE[0] * (FLYIN_DISTANCE[1] / FLYIN_DISTANCE[0]) ** e

    def lerp(pair):
        return pair[0] + (pair[1] - pair[0]) * e

    return d, lerp(FLYIN_ELEVATION), lerp(FLYIN_AZIMUTH), lerp(FLYIN_FOV)


def _polar_floor(scene, name, r_s, depth, radius, cell, material, n_az=96, n_rings=48, r_first=0.2):
    """A flat disc ``depth`` r_s below the origin, of ``radius`` r_s, as a polar grid: a fan about the
    centre, then rings at radii growing geometrically from ``r_first`` r_s to ``radius`` (fine under the
    hole, coarse far out: n_az x (n_rings - 1) quads + n_az triangles). Its spokes are turned by an odd
    angle so that no vertex is on a line through the centre at a round azimuth. UVs are the planar
    coordinates in units of ``cell`` r_s, so a checker texture of scale 1 draws squares of ``cell`` r_s,
    exact on every face (affine in position). Faces point up (+z)."""
    radii = [r_first * (radius / r_first) ** (k / (n_rings - 1)) for k in range(n_rings)]
    turn = 0.37 * 2 * math.pi / n_az
    z = -depth * r_s
    verts = [(0.0, 0.0, z)]
    for r in radii:
        for k in range(n_az):
            a = turn + 2 * math.pi * k / n_az
            verts.append((r * r_s * math.cos(a), r * r_s * math.sin(a), z))

    def vid(ring, k):
        return 1 + ring * n_az + (k % n_az)

    def uv(i):
        return (verts[i][0] / (cell * r_s), verts[i][1] / (cell * r_s))

    faces = [[0, vid(0, k), vid(0, k + 1)] for k in range(n_az)]
    for ring in range(n_rings - 1):
        faces += [[vid(ring, k), vid(ring + 1, k), vid(ring + 1, k + 1), vid(ring, k + 1)] for k in range(n_az)]
    uvs = [[uv(i) for i in f] for f in faces]
    return _mesh_object(scene, name, verts, faces, uvs, [material])


def _floor_and_sphere(scene, clip_start):
    """The set-up the fly-in and the plunge share: the demo scene (hole, orbiting sphere, camera;
    r_s = FLYIN_R_S BU) with an emissive checker on the sphere, the checkered polar floor, and the
    camera fitted vertically with its near clip at ``clip_start`` BU. Automatic updates stay off until
    everything is in place (_lens switches them on). Returns (r_s, scene.grlens, hole, sphere,
    camera, floor)."""
    r_s = FLYIN_R_S
    bpy.ops.grlens.demo_scene(r_s=r_s)  # hole, orbiting sphere, camera; builds its images once
    g = scene.grlens
    g.auto_update = False
    hole, sphere, cam = (bpy.data.objects[n] for n in ("BlackHole", "OrbitingSphere", "Camera"))
    sphere.data.materials.clear()
    sphere.data.materials.append(_emission_checker("SphereChecker", (0.9, 0.35, 0.03), (0.03, 0.2, 0.9), 6.0))
    floor_mat = _emission_checker("FloorChecker", (0.62, 0.6, 0.52), (0.035, 0.04, 0.06), 1.0)
    floor = _polar_floor(scene, "Floor", r_s, FLOOR_DEPTH, FLOOR_RADIUS, FLOOR_CELL, floor_mat)
    cam.data.sensor_fit = "VERTICAL"
    cam.data.clip_start, cam.data.clip_end = clip_start, 1.0e4
    return r_s, g, hole, sphere, cam, floor


def flyin(scene):
    """Issue 19: a fly-in, the camera from 80 r_s to 4.5 r_s, over a checkered floor that reaches the
    horizon, with the paper's sphere on its orbit. Units: r_s = 2 BU (as the demo); the hole at the
    origin, its equatorial plane z = 0.

    * The paper's orbiting sphere (bpy.ops.grlens.demo_scene: radius 0.5 r_s, 36 x 18 UV sphere, on the
      last stable orbit r = 3 r_s in the equatorial plane, one orbit in 360 frames starting at +y),
      orange/blue checker (6 cells per unit of UV, coarser than the ``sphere`` scene's 12, so that it
      reads at a distance).
    * The floor: a disc of radius 300 r_s, 2 r_s below the equatorial plane (its nearest point to the
      hole is the one right under it, 2 r_s away), a polar grid (96 spokes x 48 rings, 4608 faces,
      rings from 0.2 r_s growing geometrically), light and dark emissive checker squares of 2 r_s
      (Checker Texture on its UVs, which are its planar coordinates).
    * The camera flies in over frames 1..240 while looking at the hole (``flyin_camera``): its
      distance falls from 80 to 4.5 r_s (geometrically in the eased progress: slow start and stop), its
      elevation above the equatorial plane grows from 8 to 16 degrees (13.1 r_s above the floor at the
      start, 3.2 r_s at the end), it turns about the hole from azimuth -90 degrees (the sphere right
      behind the hole) to +20 degrees, and its vertical field of view widens from 25 to 100 degrees
      as the shadow grows (1.9 to 30.6 degrees in radius). Keyed every frame (location, rotation, lens;
      linear in between); it stays outside the sphere's orbit (at least 4.3 r_s from the axis).
    * grlens' default tables for every camera distance (lut_mode EVERY_DISTANCE, from 1.05 r_s to
      infinity, lutgen.LUTFamily): an exact table is built once for each of the family's fixed node
      radii the camera comes near (a second or two each), and every frame interpolates four of them.
    * A dark blue-black world, lensed (scene.grlens.lens_world, on by default: black in the shadow);
      the Standard view transform, so that the emission colours show as they are.

    The camera is placed at frame 1; the images are built by the first frame change (render.py)."""
    r_s, g, hole, sphere, cam, floor = _floor_and_sphere(scene, clip_start=0.05)
    from mathutils import Vector

    previous = None
    for f in range(1, FLYIN_FRAMES + 1):
        d, el, az, fov = flyin_camera(f)
        el, az = math.radians(el), math.radians(az)
        cam.location = (d * r_s * math.cos(el) * math.cos(az), d * r_s * math.cos(el) * math.sin(az),
                        d * r_s * math.sin(el))
        quat = (Vector(hole.location) - cam.location).to_track_quat("-Z", "Y")
        cam.rotation_euler = quat.to_euler("XYZ", previous) if previous is not None else quat.to_euler("XYZ")
        previous = cam.rotation_euler.copy()
        cam.data.angle_y = math.radians(fov)
        cam.keyframe_insert("location", frame=f)
        cam.keyframe_insert("rotation_euler", frame=f)
        cam.data.keyframe_insert("lens", frame=f)
    _linear_keys(cam)
    _linear_keys(cam.data)
    scene.frame_start, scene.frame_end = 1, FLYIN_FRAMES
    scene.frame_set(1)  # the camera at its first key (no rebuild: auto_update is off)
    _lens(scene, hole, r_s, [sphere, floor], lut_mode="EVERY_DISTANCE", lut_r_min=1.05, max_tess_level=64,
          tess_a=5.0, tess_b=0.75)
    _world(scene, (0.002, 0.003, 0.008))
    scene.view_settings.view_transform = "Standard"
    return scene


PLUNGE_FRAMES = 240
PLUNGE_HOVER = 48
"""The plunge's camera hovers at PLUNGE_DISTANCE[0] over frames 1..PLUNGE_HOVER, then descends."""
PLUNGE_DISTANCE = (6.0, 1.05)  # r_s
PLUNGE_ELEVATION = 25.0  # degrees above the equatorial plane, fixed (the camera falls radially)
PLUNGE_AZIMUTH = -100.0  # degrees
PLUNGE_FOV = (70.0, 100.0)  # degrees, vertical
PLUNGE_LOOK = (0.0, 0.95)
"""How far the view has turned from the hole (0) towards straight up (1, radially outwards, through the
tangent towards the floor at 0.5) at the start and the end of the descent."""


def plunge_camera(frame):
    """(distance in r_s, view turn, vertical field of view in degrees) of the plunge's camera at
    ``frame``: still until PLUNGE_HOVER, then r - 1 falls geometrically (smoothstep in time) from
    PLUNGE_DISTANCE[0] - 1 to PLUNGE_DISTANCE[1] - 1, so the approach to the horizon slows as it would
    for a camera lowered on a rope; the view turns from the hole towards the sky overhead (which
    shrinks into a disc of radius asin(b_crit sqrt(1 - 1/r) / r): 33 degrees at 1.05 r_s) and widens."""
    s = min(max((frame - PLUNGE_HOVER) / (PLUNGE_FRAMES - PLUNGE_HOVER), 0.0), 1.0)
    e = s * s * (3.0 - 2.0 * s)
    a, b = PLUNGE_DISTANCE
    d = 1.0 + (a - 1.0) * ((b - 1.0) / (a - 1.0)) ** e
    turn = PLUNGE_LOOK[0] + (PLUNGE_LOOK[1] - PLUNGE_LOOK[0]) * e
    return d, turn, PLUNGE_FOV[0] + (PLUNGE_FOV[1] - PLUNGE_FOV[0]) * e


def plunge(scene):
    """A camera that hovers at 6 r_s, then descends to 1.05 r_s, deep inside the photon sphere, over a
    checkered floor and the paper's orbiting sphere, under the lensed star field. Units: r_s = 2 BU;
    the hole at the origin, its equatorial plane z = 0.

    * Each frame is a static observer at the camera's radius (the descent is a sequence of hovering
      cameras; a falling camera's aberration is not applied here).
    * The orbiting sphere (bpy.ops.grlens.demo_scene, radius 0.5 r_s on the 3 r_s orbit) and the floor
      of the fly-in (a disc of 300 r_s, 2 r_s below the equatorial plane, checker squares of 2 r_s).
    * The camera (``plunge_camera``) at elevation 25 degrees, azimuth -100 degrees, hovers at 6 r_s for
      48 frames, then falls radially to 1.05 r_s by frame 240, its view turning from the hole to the
      sky overhead. Below 1.5 r_s only rays leaving within the escape cone reach anything outside the
      photon sphere: the floor, the sphere and the stars crowd into a disc overhead, the shadow fills
      the rest of the sky, and rays that turn back show the floor again at its edge.
    * lut_mode ONE_TABLE: the orbit table serves every radius of the descent, so no frame waits for a
      table (lutgen.rays; lut_r_min 1.02 r_s).
    * The star field of the ``starfield`` scene as the world, lensed (scene.grlens.lens_world)."""
    r_s, g, hole, sphere, cam, floor = _floor_and_sphere(scene, clip_start=0.01)
    from mathutils import Vector

    el, az = math.radians(PLUNGE_ELEVATION), math.radians(PLUNGE_AZIMUTH)
    radial = Vector((math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)))
    down = Vector((0.0, 0.0, -1.0))
    down = (down - down.dot(radial) * radial).normalized()  # the tangent towards the floor
    previous = None
    for f in range(1, PLUNGE_FRAMES + 1):
        d, turn, fov = plunge_camera(f)
        cam.location = radial * (d * r_s)
        a = math.pi * turn  # the view turns from the hole through the floor's side to straight up
        view = -radial * math.cos(a) + down * math.sin(a)
        quat = view.to_track_quat("-Z", "Z")
        cam.rotation_euler = quat.to_euler("XYZ", previous) if previous is not None else quat.to_euler("XYZ")
        previous = cam.rotation_euler.copy()
        cam.data.angle_y = math.radians(fov)
        cam.keyframe_insert("location", frame=f)
        cam.keyframe_insert("rotation_euler", frame=f)
        cam.data.keyframe_insert("lens", frame=f)
    _linear_keys(cam)
    _linear_keys(cam.data)
    scene.frame_start, scene.frame_end = 1, PLUNGE_FRAMES
    scene.frame_set(1)
    _lens(scene, hole, r_s, [sphere, floor], lut_mode="ONE_TABLE", lut_r_min=1.02, max_tess_level=64,
          tess_a=5.0, tess_b=0.75)
    _starfield._star_world(scene)
    scene.view_settings.view_transform = "Standard"
    return scene


# --------------------------------------------------------------------------------------------------
# registry: scene name -> builder, and render defaults
# --------------------------------------------------------------------------------------------------

SCENES = {
    "sphere": sphere_orbit,
    "triangle": triangle_behind,
    "triangle_tess1": functools.partial(triangle_tess, level=1),
    "triangle_tess4": functools.partial(triangle_tess, level=4),
    "triangle_tess64": functools.partial(triangle_tess, level=64),
    "triangle_flat": triangle_flat,
    "disc": accretion_disc,
    "disc_external": functools.partial(accretion_disc, external=True),
    "shell": gridded_shell,
    "room": room,
    "flyin": flyin,
    "plunge": plunge,
}
SCENES["luminet"] = _luminet.luminet_disc
SCENES["luminet_blackbody"] = _luminet.luminet_disc_blackbody
SCENES["starfield"] = _starfield.starfield
SCENES["starfield_dome"] = functools.partial(_starfield.starfield, view="dome")
SCENES["starfield_panorama"] = functools.partial(_starfield.starfield, view="panorama")
SCENES["orbit"] = _orbit.orbit
SCENES["orbit_panorama"] = functools.partial(_orbit.orbit, view="panorama")
SCENES["orbit_still"] = functools.partial(_orbit.orbit, physical=False)
SCENES["orbit_panorama_still"] = functools.partial(_orbit.orbit, view="panorama", physical=False)
for _incl in (90, 30, 10):
    SCENES[f"disc_{_incl}"] = functools.partial(accretion_disc, inclination=_incl)
    SCENES[f"disc_{_incl}_external"] = functools.partial(accretion_disc, inclination=_incl, external=True)

_TRI = dict(frames=[1, 150], resolution=(320, 180), samples=16)
_DISC = dict(frames=[1], resolution=(400, 360), samples=16)
_DISC_EXT = dict(frames=[1], resolution=(480, 270), samples=16)
DEFAULTS = {
    "sphere": dict(frames=[1, 46, 91], resolution=(320, 180), samples=16,
                   what="seed 000 4.2: sphere on the last stable orbit, one orbit in 360 frames"),
    "triangle": dict(_TRI, what="seed 000 4.1: checkered triangle behind the hole, p2 -> p1 -> p2 in 300 frames"),
    "triangle_tess1": dict(_TRI, what="figure 8(b): the triangle, MaxTessLevel 1 (only its corners are mapped)"),
    "triangle_tess4": dict(_TRI, what="figure 8(c): the triangle, MaxTessLevel 4"),
    "triangle_tess64": dict(_TRI, what="figure 8(d): the triangle, MaxTessLevel 64"),
    "triangle_flat": dict(_TRI, what="figure 8(a): the triangle in flat spacetime (not lensed), grey = shadow"),
    "disc": dict(_DISC, frames=[1, 61, 81],
                 what="seed 000 4.3: accretion disc, inclination 90 -> -89 deg in 180 frames (61: 30, 81: 10)"),
    "disc_external": dict(_DISC_EXT, frames=[1, 61, 81],
                          what="the disc sequence seen by the external camera (10, -40, 4) BU"),
    "shell": dict(frames=[1], resolution=(480, 270), samples=16,
                  what="seed 004: observer at 5 r_s inside a lat/long gridded shell of 10 r_s, 120 frames"),
    "luminet": dict(frames=[1], resolution=(640, 360), samples=16,
                    what="seed 002: thin disc 3-15 r_s at 84.5 deg from 120 r_s, fov 6 deg, Page-Thorne flux / (1+z)^4"),
    "luminet_blackbody": dict(frames=[1], resolution=(640, 360), samples=16,
                              what="seed 002: the thin disc in blackbody colours of the observed temperature"),
    "room": dict(frames=[1], resolution=(480, 270), samples=64,
                 what="seed 003: Cornell-like room, sphere, cube, cylinder, hole of r_s = 0.4 BU in the middle"),
    "flyin": dict(frames=[1, 120, 180, 240], resolution=(480, 270), samples=16,
                  what="issue 19: camera flies in from 80 to 4.5 r_s over a checkered floor, orbiting sphere, 240 frames"),
    "plunge": dict(frames=[1, 150, 200, 240], resolution=(480, 270), samples=16,
                   what="camera hovers at 6 r_s, then descends to 1.05 r_s inside the photon sphere: floor, "
                        "orbiting sphere, lensed star field, 240 frames"),
    "starfield": dict(frames=[1], resolution=(640, 360), samples=16,
                      what="issue 21: lensed star field, Luminet's thin disc, orbiting sphere; normal view from 20 r_s"),
    "starfield_dome": dict(frames=[1], resolution=(512, 512), samples=16,
                           what="the star field through a 180-degree fisheye dome master (fisheye equidistant)"),
    "starfield_panorama": dict(frames=[1], resolution=(1024, 512), samples=16,
                               what="the star field as a 360-degree equirectangular panorama"),
    "orbit": dict(frames=[1], resolution=(640, 360), samples=16,
                  what="physical time: the star field's scene from a camera on the circular orbit at 6 r_s (0.316 c)"),
    "orbit_panorama": dict(frames=[1], resolution=(1024, 512), samples=16,
                           what="the orbiting camera's 360-degree equirectangular panorama"),
    "orbit_still": dict(frames=[1], resolution=(640, 360), samples=16,
                        what="the same frame with speed_of_light 0: a camera at rest at the same place"),
    "orbit_panorama_still": dict(frames=[1], resolution=(1024, 512), samples=16,
                                 what="the still's 360-degree equirectangular panorama"),
}
for _incl, _letters in ((90, "a, b"), (30, "c, d"), (10, "e, f")):
    _obs, _ext = _letters.split(", ")
    DEFAULTS[f"disc_{_incl}"] = dict(
        _DISC, what=f"figure 10({_obs}): the disc at inclination {_incl} deg, observer view")
    DEFAULTS[f"disc_{_incl}_external"] = dict(
        _DISC_EXT, what=f"figure 10({_ext}): inclination {_incl} deg, external camera {DISC_EXTERNAL[_incl]} BU")
assert set(DEFAULTS) == set(SCENES)


def describe(name) -> str:
    """One line on what the scene shows."""
    return DEFAULTS[name]["what"]
