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
