"""Ready-made shading for grlens images: the "grlens GR Illumination" node group.

The group reads the corner attribute ``grlens_irradiance`` written by the rebuild when
scene.grlens.use_gr_illumination is on (I0 max(0, n.d) / (c dt)^2 summed over both geodesics, c dt
in scene units) and emits ``Color * Irradiance * Exposure``: the seed paper's illumination model,
independent of Blender's lights. Put it in the materials used by lensed objects (Add > Group).
Blender's own lighting keeps working on the image meshes as an alternative.
"""
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
