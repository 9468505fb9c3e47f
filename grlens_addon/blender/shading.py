"""Ready-made shading for grlens images: node groups ("grlens GR Illumination" and others below).

The group reads the corner attribute ``grlens_irradiance`` written by the rebuild when
scene.grlens.use_gr_illumination is on (I0 max(0, n.d) / (c dt)^2 summed over both geodesics, c dt
in scene units) and emits ``Color * Irradiance * Exposure``: the seed paper's illumination model,
independent of Blender's lights. Put it in the materials used by lensed objects (Add > Group).
Blender's own lighting keeps working on the image meshes as an alternative.

With physical time, "grlens Shifted Colour" turns a material's colour into the colour of its light
shifted by g = 1 / (1 + z) (point attribute ``grlens_redshift``; core.spectrum); "grlens Thin Disc
Emission" emits a thin disc's colour.
"""
import math

import bpy

GROUP_NAME = "grlens GR Illumination"
ATTRIBUTE = "grlens_irradiance"


def _socket(tree, in_out, name, socket_type, default=None):
    sock = tree.interface.new_socket(name=name, in_out=in_out, socket_type=socket_type)
    if default is not None:
        sock.default_value = default
    return sock


def ensure_node_group():
    """Get or create the node group (never duplicated)."""
    tree = bpy.data.node_groups.get(GROUP_NAME)
    if tree is not None and tree.bl_idname == "ShaderNodeTree":
        return tree
    tree = bpy.data.node_groups.new(GROUP_NAME, "ShaderNodeTree")
    _socket(tree, "INPUT", "Color", "NodeSocketColor", (1.0, 1.0, 1.0, 1.0))
    _socket(tree, "INPUT", "Exposure", "NodeSocketFloat", 1.0)
    _socket(tree, "OUTPUT", "Shader", "NodeSocketShader")
    _socket(tree, "OUTPUT", "Irradiance", "NodeSocketFloat")
    n = tree.nodes
    gin, gout = n.new("NodeGroupInput"), n.new("NodeGroupOutput")
    attr = n.new("ShaderNodeAttribute")
    attr.attribute_type = "GEOMETRY"
    attr.attribute_name = ATTRIBUTE
    scale = n.new("ShaderNodeMath")
    scale.operation = "MULTIPLY"
    emit = n.new("ShaderNodeEmission")
    links = tree.links
    links.new(attr.outputs["Fac"], scale.inputs[0])
    links.new(gin.outputs["Exposure"], scale.inputs[1])
    links.new(gin.outputs["Color"], emit.inputs["Color"])
    links.new(scale.outputs["Value"], emit.inputs["Strength"])
    links.new(emit.outputs["Emission"], gout.inputs["Shader"])
    links.new(attr.outputs["Fac"], gout.inputs["Irradiance"])
    for i, node in enumerate((gin, attr, scale, emit, gout)):
        node.location = (200 * i, 0)
    return tree


SHIFT_GROUP_NAME = "grlens Shifted Colour"
SHIFT_CURVE_POINTS = 255
"""Points per curve of the group's table of M(g) / g^5 (core.spectrum.shift_table), evenly in ln g
from 1/4 to 4; Blender's smooth curves through them are within 2e-3 of the table's entries (which
reach about 3)."""


REDSHIFT_GRAVITY = "grlens_redshift_gravity"
"""Point float attribute of image meshes with physical time: the gravitational part of 1 + z."""

SWITCHES = {"use_gravitational_shift": "gravitational shift", "use_doppler_colour": "Doppler colour",
            "use_beaming": "beaming"}
"""scene.grlens switch -> the shifted-colour group's Value node that carries it (1 on, 0 off)."""


def set_shift_switches(scene) -> None:
    """Write the scene's colour switches into the shifted-colour group, if there is one (only values
    that change: every write updates the node tree)."""
    tree = bpy.data.node_groups.get(SHIFT_GROUP_NAME)
    if tree is None:
        return
    for prop, name in SWITCHES.items():
        node = tree.nodes.get(name)
        value = 1.0 if getattr(scene.grlens, prop) else 0.0
        if node is not None and node.outputs[0].default_value != value:
            node.outputs[0].default_value = value


def _builders(tree):
    """(math node, vector math node) helpers linking into ``tree``: each returns the node's output."""
    n, links = tree.nodes, tree.links

    def fn(op, a=None, b=None, c=None, clamp=False):
        node = n.new("ShaderNodeMath")
        node.operation = op
        node.use_clamp = clamp
        for i, v in enumerate((a, b, c)):
            if v is None:
                continue
            if isinstance(v, (int, float)):
                node.inputs[i].default_value = v
            else:
                links.new(v, node.inputs[i])
        return node.outputs[0]

    def vmath(op, a, b, scale=None):
        node = n.new("ShaderNodeVectorMath")
        node.operation = op
        links.new(a, node.inputs[0])
        if scale is not None:
            links.new(scale, node.inputs["Scale"])
        elif isinstance(b, tuple):
            node.inputs[1].default_value = b
        else:
            links.new(b, node.inputs[1])
        return node.outputs["Vector"]

    return fn, vmath


SHIFT_BY_G_NAME = "grlens Shift by g"


def ensure_shift_by_g_group():
    """Get or create the node group "grlens Shift by g" (never duplicated): ``Color`` (linear RGB, as
    emitted) -> the colour seen when its light's hue is shifted by g_hue and its brightness by
    g_bright (inputs ``ln g hue``, ``ln g bright``, natural logarithms): M(g_hue) / g_hue^5 Color
    times g_bright^5 (core.spectrum; negative channels of out-of-gamut colours clipped to 0). Used by
    "grlens Shifted Colour" (surfaces) and by the lensed world (the sky).

    Nodes: u = (ln g_hue - ln(1/4)) / ln(16), clamped -> three RGB Curves nodes (one per basis colour,
    each channel's curve M(g)_kc / g^5 over u) -> the input's channels times those columns, summed ->
    times exp(5 ln g_bright)."""
    from ..core import spectrum

    tree = bpy.data.node_groups.get(SHIFT_BY_G_NAME)
    if tree is not None and tree.bl_idname == "ShaderNodeTree":
        return tree
    tree = bpy.data.node_groups.new(SHIFT_BY_G_NAME, "ShaderNodeTree")
    _socket(tree, "INPUT", "Color", "NodeSocketColor", (1.0, 1.0, 1.0, 1.0))
    _socket(tree, "INPUT", "ln g hue", "NodeSocketFloat", 0.0)
    _socket(tree, "INPUT", "ln g bright", "NodeSocketFloat", 0.0)
    _socket(tree, "OUTPUT", "Color", "NodeSocketColor")
    n, links = tree.nodes, tree.links
    fn, vmath = _builders(tree)
    gin, gout = n.new("NodeGroupInput"), n.new("NodeGroupOutput")
    lo, hi = spectrum.LN_G_RANGE
    u = fn("MULTIPLY_ADD", gin.outputs["ln g hue"], 1.0 / (hi - lo), -lo / (hi - lo), clamp=True)
    uu = n.new("ShaderNodeCombineColor")
    for k in range(3):
        links.new(u, uu.inputs[k])
    ln_tab, table = spectrum.shift_table(SHIFT_CURVE_POINTS)
    x = (ln_tab - lo) / (hi - lo)
    sep = n.new("ShaderNodeSeparateColor")
    links.new(gin.outputs["Color"], sep.inputs[0])
    total = None
    for c in range(3):  # the colour seen of the unit colour c: column c of M(g) / g^5
        cur = n.new("ShaderNodeRGBCurve")
        cur.name = cur.label = f"M column {c}"
        m = cur.mapping
        m.use_clip = False
        for k in range(3):
            pts = m.curves[k].points
            pts[0].location = (0.0, float(table[0, k, c]))
            pts[1].location = (1.0, float(table[-1, k, c]))
            for xi, yi in zip(x[1:-1], table[1:-1, k, c]):
                pts.new(float(xi), float(yi))
        m.update()
        links.new(uu.outputs[0], cur.inputs["Color"])
        part = vmath("SCALE", cur.outputs["Color"], None, scale=sep.outputs[c])
        total = part if total is None else vmath("ADD", total, part)
    shifted = vmath("SCALE", total, None, scale=fn("EXPONENT", fn("MULTIPLY", gin.outputs["ln g bright"], 5.0)))
    links.new(vmath("MAXIMUM", shifted, (0.0, 0.0, 0.0)), gout.inputs["Color"])
    for i, node in enumerate(tree.nodes):
        node.location = (150 * (i % 12), -200 * (i // 12))
    return tree


def ensure_shift_node_group():
    """Get or create the node group "grlens Shifted Colour" (never duplicated): the colour a surface of
    colour ``Color`` (linear RGB, as emitted) shows when its light reaches the camera with
    g = 1 / (1 + z), 1 + z from the point attribute ``grlens_redshift`` of the image meshes (written
    with physical time; 0 or missing: no shift). ``Strength`` runs from 0 (no shift) to 1 (physical:
    the colour of the shifted spectrum, brightness and hue together, core.spectrum); in between the
    shift g^Strength. Outputs ``Color`` (negative channels of out-of-gamut colours clipped to 0) and
    ``Redshift`` (1 + z). For teaching, the scene's switches (:data:`SWITCHES`, set into the group by
    :func:`set_shift_switches`) leave out the gravitational part of the shift
    (``grlens_redshift_gravity``), or the motions' part (the rest) from the hue (Doppler colour) or
    from the brightness (beaming): the hue is that of g_hue, the brightness scaled by
    g_bright^5 / g_hue^5. Use it in front of a shader's colour (Add > Group); the image meshes'
    materials are copies of the sources', so putting it in the source's material is enough.

    Nodes: ln g_hue, ln g_bright (Strength times the parts switched on) -> "grlens Shift by g"."""
    tree = bpy.data.node_groups.get(SHIFT_GROUP_NAME)
    if tree is not None and tree.bl_idname == "ShaderNodeTree":
        return tree
    inner = ensure_shift_by_g_group()
    tree = bpy.data.node_groups.new(SHIFT_GROUP_NAME, "ShaderNodeTree")
    _socket(tree, "INPUT", "Color", "NodeSocketColor", (1.0, 1.0, 1.0, 1.0))
    s_in = _socket(tree, "INPUT", "Strength", "NodeSocketFloat", 1.0)
    s_in.min_value, s_in.max_value = 0.0, 1.0
    _socket(tree, "OUTPUT", "Color", "NodeSocketColor")
    _socket(tree, "OUTPUT", "Redshift", "NodeSocketFloat")
    n, links = tree.nodes, tree.links
    fn, _ = _builders(tree)
    gin, gout = n.new("NodeGroupInput"), n.new("NodeGroupOutput")

    def ln_g_of(name):  # ln g = -ln(1 + z) of a point attribute; 0 where it is 0 or missing
        attr = n.new("ShaderNodeAttribute")
        attr.attribute_type = "GEOMETRY"
        attr.attribute_name = name
        z1 = attr.outputs["Fac"]
        valid = fn("GREATER_THAN", z1, 0.0)
        z1 = fn("MULTIPLY_ADD", fn("SUBTRACT", z1, 1.0), valid, 1.0)
        return fn("MULTIPLY", fn("LOGARITHM", z1, math.e), -1.0), attr

    def switch(name):
        node = n.new("ShaderNodeValue")
        node.name = node.label = name
        node.outputs[0].default_value = 1.0
        return node.outputs[0]

    ln_total, attr = ln_g_of(REDSHIFT)
    ln_grav, _ = ln_g_of(REDSHIFT_GRAVITY)
    ln_motion = fn("SUBTRACT", ln_total, ln_grav)  # the motions' part (camera, disc gas)
    grav = fn("MULTIPLY", ln_grav, switch(SWITCHES["use_gravitational_shift"]))
    strength = gin.outputs["Strength"]
    shift = n.new("ShaderNodeGroup")
    shift.node_tree = inner
    links.new(fn("MULTIPLY", fn("MULTIPLY_ADD", ln_motion, switch(SWITCHES["use_doppler_colour"]), grav), strength),
              shift.inputs["ln g hue"])
    links.new(fn("MULTIPLY", fn("MULTIPLY_ADD", ln_motion, switch(SWITCHES["use_beaming"]), grav), strength),
              shift.inputs["ln g bright"])
    links.new(gin.outputs["Color"], shift.inputs["Color"])
    links.new(shift.outputs["Color"], gout.inputs["Color"])
    links.new(attr.outputs["Fac"], gout.inputs["Redshift"])
    for i, node in enumerate(tree.nodes):
        node.location = (150 * (i % 12), -200 * (i // 12))
    return tree


DISC_GROUP_NAME = "grlens Thin Disc Emission"
DISC_COLOUR = "grlens_disc_colour"
"""Point colour attribute (linear RGB) of thin-disc images: Page-Thorne flux / (1 + z)^4, see core.thin_disc."""
REDSHIFT = "grlens_redshift"
"""Point float attribute of thin-disc images: the redshift factor 1 + z."""


def ensure_disc_node_group():
    """Get or create the node group that emits the ``grlens_disc_colour`` attribute (Strength input
    scales it); never duplicated."""
    tree = bpy.data.node_groups.get(DISC_GROUP_NAME)
    if tree is not None and tree.bl_idname == "ShaderNodeTree":
        return tree
    tree = bpy.data.node_groups.new(DISC_GROUP_NAME, "ShaderNodeTree")
    _socket(tree, "INPUT", "Strength", "NodeSocketFloat", 1.0)
    _socket(tree, "OUTPUT", "Shader", "NodeSocketShader")
    _socket(tree, "OUTPUT", "Color", "NodeSocketColor")
    _socket(tree, "OUTPUT", "Redshift", "NodeSocketFloat")
    n = tree.nodes
    gin, gout = n.new("NodeGroupInput"), n.new("NodeGroupOutput")
    colour = n.new("ShaderNodeAttribute")
    colour.attribute_type = "GEOMETRY"
    colour.attribute_name = DISC_COLOUR
    z = n.new("ShaderNodeAttribute")
    z.attribute_type = "GEOMETRY"
    z.attribute_name = REDSHIFT
    emit = n.new("ShaderNodeEmission")
    links = tree.links
    links.new(colour.outputs["Color"], emit.inputs["Color"])
    links.new(gin.outputs["Strength"], emit.inputs["Strength"])
    links.new(emit.outputs["Emission"], gout.inputs["Shader"])
    links.new(colour.outputs["Color"], gout.inputs["Color"])
    links.new(z.outputs["Fac"], gout.inputs["Redshift"])
    for i, node in enumerate((gin, colour, emit, gout)):
        node.location = (200 * i, 0)
    z.location = (200, -200)
    return tree


# --------------------------------------------------------------------------------------------------
# Render passes: light travel time and image order as AOVs
# --------------------------------------------------------------------------------------------------
AOVS = (("light_travel_time", "light_travel_time"), ("image_order", "grlens_order"))
"""(AOV name, mesh attribute) pairs written by image materials."""

COPY_SUFFIX = " (grlens)"


def ensure_view_layer_aovs(scene):
    """Value AOVs ``light_travel_time`` and ``image_order`` on every view layer of ``scene``
    (Cycles and Eevee write them; Workbench writes no AOV)."""
    for vl in scene.view_layers:
        names = {a.name for a in vl.aovs}
        for aov, _ in AOVS:
            if aov not in names:
                a = vl.aovs.add()
                a.name = aov
                a.type = "VALUE"


_NODES_ALWAYS = bpy.app.version >= (5, 0, 0)
"""From Blender 5.0 every material has a node tree and Material.use_nodes is deprecated (to be removed in
6.0): it is neither read nor set there."""


def _uses_nodes(mat) -> bool:
    return mat.node_tree is not None and (_NODES_ALWAYS or mat.use_nodes)


def _use_nodes(mat) -> None:
    if not _NODES_ALWAYS:
        mat.use_nodes = True


def _digest(mat) -> str:
    """A cheap fingerprint of a material's node tree (node types, names, links, input defaults)."""
    if mat is None or not _uses_nodes(mat):
        return repr((getattr(mat, "name", None), tuple(getattr(mat, "diffuse_color", ()))))
    parts = []
    for n in mat.node_tree.nodes:
        vals = []
        for i in n.inputs:
            v = getattr(i, "default_value", None)
            try:
                v = tuple(v)
            except TypeError:
                pass
            vals.append((i.identifier, v))
        parts.append((n.bl_idname, n.name, tuple(vals)))
    links = [(l.from_node.name, l.from_socket.identifier, l.to_node.name, l.to_socket.identifier)
             for l in mat.node_tree.links]
    return repr((sorted(parts, key=repr), sorted(links)))


def _add_aov_nodes(tree):
    for aov, attribute in AOVS:
        a = tree.nodes.new("ShaderNodeAttribute")
        a.attribute_type = "GEOMETRY"
        a.attribute_name = attribute
        a.label = f"grlens {attribute}"
        out = tree.nodes.new("ShaderNodeOutputAOV")
        if hasattr(out, "aov_name"):
            out.aov_name = aov
        else:
            out.name = aov
        out.label = f"grlens AOV {aov}"
        tree.links.new(a.outputs["Fac"], out.inputs["Value"])


def _plain_surface(tree, colour) -> None:
    """Make ``tree`` the surface Cycles gives an empty material slot or a material without nodes: a
    Diffuse BSDF of ``colour`` (linear RGBA; 0.8 grey for an empty slot). A new material's default
    Principled BSDF would add a specular lobe, and the images would shade unlike their source."""
    tree.nodes.clear()
    bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = colour
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    out.location = (300, 0)
    tree.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])


def image_material(mat):
    """The material image objects use in place of ``mat`` (None: an empty slot): a copy of it with
    the grlens AOV outputs added. The user's material is never edited; the copy is refreshed when
    the original changes."""
    key = "(none)" if mat is None else mat.name
    name = f"{key}{COPY_SUFFIX}"
    digest = _digest(mat)
    old = bpy.data.materials.get(name)
    if old is not None and old.get("grlens_digest") == digest:
        return old
    copy = bpy.data.materials.new(name + ".new") if mat is None else mat.copy()
    plain = mat is None or not _uses_nodes(mat)
    _use_nodes(copy)
    if plain:
        _plain_surface(copy.node_tree, (0.8, 0.8, 0.8, 1.0) if mat is None else tuple(mat.diffuse_color))
    _add_aov_nodes(copy.node_tree)
    copy["grlens_digest"] = digest
    copy["grlens_material_copy"] = 1
    if old is not None:  # the original changed: every image mesh switches to the fresh copy
        old.user_remap(copy)
        bpy.data.materials.remove(old)
    copy.name = name
    return copy
