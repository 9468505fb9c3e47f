"""The lensed world (sky): every direction in which the world is looked up is replaced by the
direction in which that ray, leaving the observer camera, goes to infinity; rays that fall into the
hole see black (the shadow). ``scene.grlens.lens_world``; design and limits in docs/sky.md.

How: the user's world node tree is modified IN PLACE and restorably. Two kinds of nodes are added,
each marked with the custom property ``grlens_own``:

* one node group instance (``grlens_own == "group"``) whose tree, per shading sample, takes the
  world ray direction D (the Geometry node's Incoming, negated: in Cycles' background and in Eevee's
  world shader Incoming = -D), computes xi = atan2(|D x e1|, D . e1) from the outward radial
  direction e1 (hole -> camera), the table coordinate s = ln(xi_lim / (xi_lim - xi)), the
  deflection phi_inf - xi from a float image of ``lutgen.escape_table`` (linear interpolation: one
  filtered lookup in Cycles, two texel lookups interpolated in math nodes for Eevee), and outputs
  ``Vector`` = cos(phi_inf) e1 + sin(phi_inf) e2, e2 = unit(D - (D . e1) e1) (D rotated about
  e1 x D by the deflection), and
  ``Escapes`` = (xi < xi_lim);
* one Mix Shader per World Output (``grlens_own == "shadow"``) between the output's Surface and
  the user's shader: Fac = Escapes, the first shader socket empty (black).

The group's Vector feeds every input of the user's tree that reads the view direction: the Vector
input of Environment, Sky and procedural textures when unlinked (their default coordinates), and
every link from a Texture Coordinate node's Generated or Object output. Each user node changed
records what it had in its custom property ``grlens_hooked`` ({input identifier: "" (unlinked) or
"<from node name>\\t<from output identifier>"}), so :func:`restore` puts the tree back exactly.
:func:`apply` is idempotent: nodes the user adds while lensing is on are hooked at the next update.

With physical time and a colour switch on, every Background colour of the user's tree is passed
through the world's own sky-shift group (:func:`_build_shift_group`, hooked by :func:`_hook_sky_shift`),
recorded and restored like the rest: per sample two lookups of a per-frame table of the shift's 3x3
matrix against c = D . n (the inverse aberration's own dot product; :func:`sky_shift_pixels`), the
motion, gravity, switches and brightness folded into the table.

Before all this, D is taken back to the camera's local static frame (exact inverse aberration in
four nodes, :func:`_static_direction`) when frames measure physical time and the camera moves (its velocity
from its own keyframes, as the images'); at rest the nodes give D itself.

Per frame only values change (never the tree): e1, xi_lim and the camera's velocity inside the
group, the sky-shift tables when the camera's speed or radius changes, and the table's pixels when
the camera's radius changes (r_obs rounded to 7 digits, as the
LUTs). Saving stores
the user's own world: the file is restored before it is written and lensed again after
(save_pre / save_post), so a .blend never holds grlens' nodes or its table.

Units: positions in Blender units, r_s in Blender units (scene.grlens.r_s); the table in units of
r_s and radians.
"""
from __future__ import annotations

import math
from collections import OrderedDict

import bpy
import numpy as np

OWN = "grlens_own"
HOOKED = "grlens_hooked"
R_OBS_KEY = "grlens_r_obs"
GROUP_PREFIX = "grlens Lensed Sky"
TABLE_PREFIX = "grlens Sky Table"
SHIFT_PREFIX = "grlens Sky Shift"
SHIFT_HOLDER = "sky shift group"
"""The lensed-sky group's unlinked group node that holds the world's sky-shift group."""
SHIFT_LOOKUPS = ("shift 0", "shift 1", "shift 2")
"""The sky-shift group's table lookups, one per row of the matrix (each with an unlinked "<name> spare"
beside it, and "<name> 0", "<name> 1" for Eevee)."""
SHIFT_SIZE = 1024
"""Texels of the sky-shift tables: the matrix at cos = -1 .. 1 (the ray's direction against the
camera's velocity, in the camera's frame), evenly."""

DIRECTION_TEXTURES = ("ShaderNodeTexEnvironment", "ShaderNodeTexSky", "ShaderNodeTexNoise",
                      "ShaderNodeTexVoronoi", "ShaderNodeTexWave", "ShaderNodeTexMagic",
                      "ShaderNodeTexGradient", "ShaderNodeTexChecker", "ShaderNodeTexBrick",
                      "ShaderNodeTexMusgrave", "ShaderNodeTexWhiteNoise", "ShaderNodeTexGabor")
"""Nodes whose unlinked Vector input means the world's view direction (their default coordinates)."""

TEXCOORD_OUTPUTS = ("Generated", "Object")
"""Texture Coordinate outputs that are the view direction in a world shader."""

_PIXELS: OrderedDict = OrderedDict()
PIXEL_CACHE = 256
"""Table images' pixels kept per radius (r_s, rounded): 16 KB each, so scrubbing or looping an
animation does not compute a frame's table again (a camera that flies in still does, once)."""

_written: dict = {}
"""as_pointer() of a table image -> the radius (r_s, rounded) whose table its pixels hold in this
session (generated images lose their pixels on reload; a load clears this)."""


class WorldError(Exception):
    """The world cannot be lensed for this frame (camera inside the horizon, ...)."""


def _math(nodes, op, x=0.0, label=None):
    n = nodes.new("ShaderNodeMath")
    n.operation = op
    n.location = (x, 0.0)
    if label:
        n.label = label
    return n


def _vmath(nodes, op, x=0.0):
    n = nodes.new("ShaderNodeVectorMath")
    n.operation = op
    n.location = (x, 0.0)
    return n


def _texel_and_weight(N, L, j, x, y):
    """Math nodes splitting the texel coordinate ``j`` (a socket) into its texel j0 = floor(j) and the
    weight j - j0 of the next texel, for the 'closest' lookups' linear interpolation; nodes at ``x``
    (the weight at x + 100) and height ``y``. Returns the nodes (j0, weight)."""
    j0 = _math(N, "FLOOR", x=x)
    j0.location.y = y
    L.new(j, j0.inputs[0])
    w = _math(N, "SUBTRACT", x=x + 100, label="weight")
    w.location.y = y
    L.new(j, w.inputs[0])
    L.new(j0.outputs[0], w.inputs[1])
    return j0, w


def _build_group(name: str, image) -> bpy.types.NodeTree:
    """The node group of one world: outputs Vector (the escape direction) and Escapes (1/0).

    Per sample (Cycles' path, 11 nodes): D = -Incoming; xi = atan2(|e1 x D|, D . e1); the table
    coordinate u = (j + 0.5) / n, j = s (n - 1) / s_max, s = -ln(1 - xi / xi_lim); the deflection
    from the table image; D rotated by it about e1 x D, away from e1 (phi_inf = xi + deflection;
    the escape direction is cos(phi_inf) e1 + sin(phi_inf) e2). Beyond the limit,
    1 - xi / xi_lim <= 0, the Math node's logarithm gives 0 (u at the first texel) and Escapes is 0.
    Past the last node the lookups' EXTEND repeats the last texel.

    Two ways to read the table, one linked (:func:`_use_lookup`): "linear", one 'Linear' lookup
    (Cycles interpolates in float on the CPU), and "closest", linear interpolation between two
    texel-centre ('Closest') lookups done in math nodes, for Eevee: a GPU sampler picks a coarse
    mipmap level where u changes fast between neighbouring pixels (next to the shadow) and
    interpolates with 8-bit weights (errors of 0.1 in colour in 2 x 2 pixel blocks). The manual
    one would cost Cycles 7 more nodes per lookup."""
    from lutgen.escape import S_MAX, TABLE_SIZE

    ng = bpy.data.node_groups.new(name, "ShaderNodeTree")
    ng.interface.new_socket(name="Vector", in_out="OUTPUT", socket_type="NodeSocketVector")
    ng.interface.new_socket(name="Escapes", in_out="OUTPUT", socket_type="NodeSocketFloat")
    ng.interface.new_socket(name="Doppler cos", in_out="OUTPUT", socket_type="NodeSocketFloat")
    N, L = ng.nodes, ng.links
    geo = N.new("ShaderNodeNewGeometry")
    e1 = N.new("ShaderNodeCombineXYZ")
    e1.name = e1.label = "e1"
    e1.location = (0, -300)
    lim = N.new("ShaderNodeValue")
    lim.name = lim.label = "xi_lim"
    lim.location = (0, -500)
    d = _vmath(N, "SCALE", 200)  # D = -Incoming (unit in Cycles' background and Eevee's world)
    d.name = "D"
    d.inputs["Scale"].default_value = -1.0
    L.new(geo.outputs["Incoming"], d.inputs[0])
    _static_direction(N, L, d.outputs["Vector"])  # linked in for a moving camera only (_use_aberration)
    cos = _vmath(N, "DOT_PRODUCT", 400)
    cos.name = "cos xi"
    L.new(d.outputs["Vector"], cos.inputs[0])
    L.new(e1.outputs[0], cos.inputs[1])
    axis = _vmath(N, "CROSS_PRODUCT", 400)  # e1 x D: |.| = sin(xi), the axis of the deflection
    axis.name = "deflection axis"
    L.new(e1.outputs[0], axis.inputs[0])
    L.new(d.outputs["Vector"], axis.inputs[1])
    sin = _vmath(N, "LENGTH", 600)
    L.new(axis.outputs["Vector"], sin.inputs[0])
    xi = _math(N, "ARCTAN2", x=800, label="xi")  # accurate next to xi = pi, unlike acos
    L.new(sin.outputs["Value"], xi.inputs[0])
    L.new(cos.outputs["Value"], xi.inputs[1])
    inv = _math(N, "DIVIDE", x=800)  # -1 / xi_lim: constant per frame, folded by the compilers
    inv.inputs[0].default_value = -1.0
    L.new(lim.outputs[0], inv.inputs[1])
    y = _math(N, "MULTIPLY_ADD", x=1000)  # 1 - xi / xi_lim = exp(-s)
    L.new(xi.outputs[0], y.inputs[0])
    L.new(inv.outputs[0], y.inputs[1])
    y.inputs[2].default_value = 1.0
    ln = _math(N, "LOGARITHM", x=1200, label="-s")
    ln.inputs[1].default_value = math.e
    L.new(y.outputs[0], ln.inputs[0])
    # the 'linear' lookup: u = (j + 0.5) / n, j = -ln(y) (n - 1) / s_max
    u = _math(N, "MULTIPLY_ADD", x=1400)
    L.new(ln.outputs[0], u.inputs[0])
    u.inputs[1].default_value = -(TABLE_SIZE - 1) / (S_MAX * TABLE_SIZE)
    u.inputs[2].default_value = 0.5 / TABLE_SIZE
    linear = _table_lookup(N, "linear", image, "Linear", (1600, 0))
    L.new(u.outputs[0], linear.inputs["Vector"])
    sep = N.new("ShaderNodeSeparateColor")
    sep.name = "linear value"
    sep.location = (1800, 0)
    L.new(linear.outputs["Color"], sep.inputs[0])
    # the 'closest' lookups: a + w (b - a) between texels j0 and j0 + 1, j0 = floor(j)
    j = _math(N, "MULTIPLY", x=1400)
    j.location.y = -400
    L.new(ln.outputs[0], j.inputs[0])
    j.inputs[1].default_value = -(TABLE_SIZE - 1) / S_MAX
    j0, w = _texel_and_weight(N, L, j.outputs[0], 1500, -400)
    vals = []
    for k, tname in enumerate(("table", "table+1")):
        uk = _math(N, "MULTIPLY_ADD", x=1600)
        uk.location.y = -600 - 300 * k
        uk.inputs[1].default_value = 1.0 / TABLE_SIZE
        uk.inputs[2].default_value = (0.5 + k) / TABLE_SIZE
        L.new(j0.outputs[0], uk.inputs[0])
        tex = _table_lookup(N, tname, image, "Closest", (1800, -600 - 300 * k))
        L.new(uk.outputs[0], tex.inputs["Vector"])
        sk = N.new("ShaderNodeSeparateColor")
        sk.location = (2000, -600 - 300 * k)
        L.new(tex.outputs["Color"], sk.inputs[0])
        vals.append(sk.outputs[0])
    lerp = N.new("ShaderNodeMix")
    lerp.name = "closest value"
    lerp.data_type = "FLOAT"
    lerp.clamp_factor = False
    lerp.location = (2200, -600)
    L.new(w.outputs[0], lerp.inputs[0])
    L.new(vals[0], lerp.inputs[2])
    L.new(vals[1], lerp.inputs[3])
    # unlinked: holds the other table image (see write_table)
    _table_lookup(N, "spare", _new_table_image(image.name + " (spare)"), "Closest", (1800, -1300))
    # the escape direction: D rotated about e1 x D by the deflection (an empty axis, D along e1,
    # leaves D as it is: no deflection there)
    rot = N.new("ShaderNodeVectorRotate")
    rot.name = "rotate"
    rot.rotation_type = "AXIS_ANGLE"
    rot.location = (2400, 0)
    L.new(d.outputs["Vector"], rot.inputs["Vector"])
    L.new(axis.outputs["Vector"], rot.inputs["Axis"])
    esc = _math(N, "LESS_THAN", x=1000, label="escapes")
    esc.location.y = 300
    L.new(xi.outputs[0], esc.inputs[0])
    L.new(lim.outputs[0], esc.inputs[1])
    out = N.new("NodeGroupOutput")
    out.location = (2600, 0)
    L.new(rot.outputs["Vector"], out.inputs["Vector"])
    L.new(esc.outputs[0], out.inputs["Escapes"])
    L.new(N["doppler cos"].outputs["Value"], out.inputs["Doppler cos"])
    holder = N.new("ShaderNodeGroup")  # unlinked: keeps this world's sky-shift group (and finds it)
    holder.name = holder.label = SHIFT_HOLDER
    holder.location = (2400, -600)
    holder.node_tree = _build_shift_group(name.replace(GROUP_PREFIX, SHIFT_PREFIX, 1))
    return ng


def _static_direction(N, L, d):
    """Nodes taking the camera's ray direction ``d`` (a socket, unit) back to its local static frame,
    the exact inverse aberration of observer_view.unaberrate in four nodes: with n = -beta / |beta|
    (node "beta_dir"), gamma - 1 ("gamma_minus_1") and gamma |beta| ("gamma_beta") and c = D . n,
    D_static = ((c + b) / (1 + b c)) n + (D - c n) / (gamma (1 + b c)), which is the unit vector of
    D + ((gamma - 1) c + gamma b) n (times gamma (1 + b c) > 0). Per frame values only; left out of the
    path for a camera at rest (:func:`_use_aberration`). Returns the node whose output "Vector" is
    D_static."""
    n = N.new("ShaderNodeCombineXYZ")
    n.name = n.label = "beta_dir"
    n.location = (0, -800)
    gm1 = N.new("ShaderNodeValue")
    gm1.name = gm1.label = "gamma_minus_1"
    gm1.location = (0, -1000)
    gm1.outputs[0].default_value = 0.0
    gb = N.new("ShaderNodeValue")
    gb.name = gb.label = "gamma_beta"
    gb.location = (0, -1200)
    gb.outputs[0].default_value = 0.0
    c = _vmath(N, "DOT_PRODUCT", 250)
    c.name = "doppler cos"  # also the sky's Doppler factor: g = 1 / (gamma (1 + |beta| c))
    L.new(d, c.inputs[0])
    L.new(n.outputs[0], c.inputs[1])
    k = _math(N, "MULTIPLY_ADD", x=300)  # (gamma - 1) c + gamma b
    L.new(c.outputs["Value"], k.inputs[0])
    L.new(gm1.outputs[0], k.inputs[1])
    L.new(gb.outputs[0], k.inputs[2])
    v = _vmath(N, "MULTIPLY_ADD", 350)  # D + k n
    L.new(n.outputs[0], v.inputs[0])
    L.new(k.outputs[0], v.inputs[1])
    L.new(d, v.inputs[2])
    out = _vmath(N, "NORMALIZE", 400)
    out.name = "static direction"
    L.new(v.outputs["Vector"], out.inputs[0])
    return out


def _build_shift_group(name: str) -> bpy.types.NodeTree:
    """The node group that shifts one colour of the world (input ``Color``, linear RGB, as the user's
    tree gives it to a Background) by the sky's g (input ``Doppler cos``: c = D . n of the lensed-sky
    group, the camera's ray direction against n = -beta / |beta| in the camera's frame; 0 at rest),
    output ``Color``: max(T(c) Color, 0), T(c) the matrix of :func:`sky_shift_pixels` for this frame,
    every part of the shift (the camera's motion, gravity, the colour switches, the brightness) folded
    into it per frame.

    Per sample, nine nodes: u = 0.5 + c (n - 1) / (2 n) (one multiply-add: texel centres at
    c = -1 .. 1); three 'Linear' lookups at u of the tables "shift 0" .. "shift 2" (T's rows); three dot
    products of the rows with the colour; one Combine XYZ; one vector maximum with 0 (negative channels
    of out-of-gamut colours clipped, as "grlens Shift by g" does). Cycles spends about the same per node
    whatever it does (its per-node overhead dominates: ``./dev bench physical_time_sky --instructions``),
    so the count is what is kept small: two lookups and the row sums (each row sums to the brightness
    factor) would need the colour's channels apart and float-to-vector conversions, thirteen nodes. Eevee
    reads the tables by closest-texel pairs mixed in math nodes (:func:`_use_shift_lookup`)."""
    tree = bpy.data.node_groups.new(name, "ShaderNodeTree")
    tree.interface.new_socket(name="Color", in_out="INPUT", socket_type="NodeSocketColor").default_value = \
        (1.0, 1.0, 1.0, 1.0)
    tree.interface.new_socket(name="Doppler cos", in_out="INPUT", socket_type="NodeSocketFloat")
    tree.interface.new_socket(name="Color", in_out="OUTPUT", socket_type="NodeSocketColor")
    N, L = tree.nodes, tree.links
    gin, gout = N.new("NodeGroupInput"), N.new("NodeGroupOutput")
    gout.location = (1600, 0)
    u = _math(N, "MULTIPLY_ADD", x=200, label="u")
    L.new(gin.outputs["Doppler cos"], u.inputs[0])
    u.inputs[1].default_value = (SHIFT_SIZE - 1) / (2.0 * SHIFT_SIZE)
    u.inputs[2].default_value = 0.5
    # the 'closest' way (Eevee): texels j0 and j0 + 1, j = (c + 1) (n - 1) / 2, mixed by j - j0
    j = _math(N, "MULTIPLY_ADD", x=200)
    j.location.y = -1500
    L.new(gin.outputs["Doppler cos"], j.inputs[0])
    j.inputs[1].default_value = j.inputs[2].default_value = (SHIFT_SIZE - 1) / 2.0
    j0, w = _texel_and_weight(N, L, j.outputs[0], 250, -1500)
    uk = []
    for k in range(2):
        n = _math(N, "MULTIPLY_ADD", x=300)
        n.location.y = -1700 - 200 * k
        L.new(j0.outputs[0], n.inputs[0])
        n.inputs[1].default_value = 1.0 / SHIFT_SIZE
        n.inputs[2].default_value = (0.5 + k) / SHIFT_SIZE
        uk.append(n.outputs[0])
    comb = N.new("ShaderNodeCombineXYZ")
    comb.location = (1200, 0)
    for k, name_k in enumerate(SHIFT_LOOKUPS):
        image = _new_table_image(f"{name} {name_k[-1]}", SHIFT_SIZE)
        tex = _table_lookup(N, name_k, image, "Linear", (400, -300 * k))
        L.new(u.outputs[0], tex.inputs["Vector"])
        _table_lookup(N, name_k + " spare", _new_table_image(f"{name} {name_k[-1]} (spare)", SHIFT_SIZE), "Linear",
                      (400, -700 - 300 * k))
        pair = []
        for i in range(2):
            t = _table_lookup(N, f"{name_k} {i}", image, "Closest", (400 + 200 * i, -1500 - 300 * k))
            L.new(uk[i], t.inputs["Vector"])
            pair.append(t)
        mix = N.new("ShaderNodeMix")
        mix.name = name_k + " closest"
        mix.data_type = "RGBA"
        mix.clamp_factor = False
        mix.location = (800, -1500 - 300 * k)
        L.new(w.outputs[0], mix.inputs[0])
        L.new(pair[0].outputs["Color"], mix.inputs[6])
        L.new(pair[1].outputs["Color"], mix.inputs[7])
        dot = _vmath(N, "DOT_PRODUCT", 1000)
        dot.name = f"row {k}"
        dot.location.y = -300 * k
        L.new(tex.outputs["Color"], dot.inputs[0])
        L.new(gin.outputs["Color"], dot.inputs[1])
        L.new(dot.outputs["Value"], comb.inputs[k])
    clip = _vmath(N, "MAXIMUM", 1400)
    clip.name = "clip"
    L.new(comb.outputs[0], clip.inputs[0])
    clip.inputs[1].default_value = (0.0, 0.0, 0.0)
    L.new(clip.outputs["Vector"], gout.inputs["Color"])
    return tree


def _use_shift_lookup(tree, kind: str) -> bool:
    """Take the sky-shift group's rows from its 'linear' lookups (Cycles) or from its 'closest' pairs
    mixed in math nodes (Eevee: a GPU sampler's mipmaps average the table over many texels where c
    changes by several texels per pixel, and T's large entries of opposite sign turn that into errors
    of 0.5 in colour), as :func:`_use_lookup` for the escape table. Relinks only when that changes.
    Returns whether it relinked."""
    nodes, links = tree.nodes, tree.links
    changed = False
    for k, name in enumerate(SHIFT_LOOKUPS):
        sock = nodes[f"row {k}"].inputs[0]
        src = nodes[name].outputs["Color"] if kind == "linear" else nodes[name + " closest"].outputs[2]
        if sock.is_linked and sock.links[0].from_socket == src:
            continue
        for lk in list(sock.links):
            links.remove(lk)
        links.new(src, sock)
        changed = True
    return changed


def sky_shift_pixels(beta: float, r_obs: float, doppler_colour=True, beaming=True, gravity=True) -> np.ndarray:
    """(3, SHIFT_SIZE * 4) float32: the texels of the tables "shift 0" .. "shift 2" for a camera at
    ``r_obs`` (r_s) moving with speed ``beta`` (units of c, in its local static frame; 0: at rest) and the
    scene's colour switches. Entry j is for c_j = -1 + 2 j / (SHIFT_SIZE - 1), the camera-frame cosine of
    its ray direction D against n = -beta / |beta|: light from the sky (emitted at rest at infinity)
    reaches it with g = g_motion g_gravity, g_motion = 1 / (gamma (1 + |beta| c)) (the same as
    gamma (1 + beta . D_static)) and g_gravity = 1 / sqrt(1 - r_s / r_obs). The hue is shifted by
    g_hue = g_motion^[doppler_colour] g_gravity^[gravity], the brightness by g_bright (beaming in place of
    doppler_colour): T = core.spectrum.shifted_matrices(ln g_hue, ln g_bright). Table i holds row i of
    T in its colour channels (alpha 1)."""
    from ..core import spectrum

    c = np.linspace(-1.0, 1.0, SHIFT_SIZE)
    b = float(beta)
    gamma = 1.0 / math.sqrt(max(1.0 - b * b, 1e-300))
    ln_motion = -np.log(gamma * (1.0 + b * c))
    ln_grav = -0.5 * math.log(1.0 - 1.0 / r_obs) if gravity else 0.0
    ln_hue = ln_motion * float(doppler_colour) + ln_grav
    ln_bright = ln_motion * float(beaming) + ln_grav
    t = spectrum.shifted_matrices(ln_hue, ln_bright)
    px = np.ones((3, SHIFT_SIZE, 4), np.float32)
    px[:, :, :3] = np.swapaxes(t, 0, 1)
    return px.reshape(3, -1)


def write_shift_table(group, beta: float, r_obs: float, switches) -> bool:
    """Give the sky-shift group of the lensed-sky ``group`` the tables of :func:`sky_shift_pixels` (its
    arguments after ``group``; ``switches`` = (doppler_colour, beaming, gravity)) unless its images hold
    them already in this session (compared in float32, the radius rounded as the LUTs). Like
    :func:`write_table`, new texels go into the spare images, which then take the lookups' places.
    Returns whether it wrote."""
    from .lutcache import round_radius

    switches = tuple(bool(v) for v in switches)
    key = repr((float(np.float32(beta)), round_radius(r_obs) if switches[2] else 0.0, switches))
    tree = group.nodes[SHIFT_HOLDER].node_tree
    nodes = tree.nodes
    cur = [nodes[k].image for k in SHIFT_LOOKUPS]
    if all(im is not None and _written.get(im.as_pointer()) == key and im.get(R_OBS_KEY) == key for im in cur):
        return False
    px = sky_shift_pixels(beta, r_obs, *switches)
    for k, name in enumerate(SHIFT_LOOKUPS):
        spare = nodes[name + " spare"]
        image = spare.image
        image.pixels.foreach_set(px[k])
        image.update()
        image[R_OBS_KEY] = key
        image.update_tag()
        _written[image.as_pointer()] = key
        for k2 in (name, f"{name} 0", f"{name} 1"):
            nodes[k2].image = image
        spare.image = cur[k]
    return True


def _direction_inputs(group):
    """The inputs that take the ray's direction: xi's cosine, the deflection's axis, the rotated
    vector."""
    return (group.nodes["cos xi"].inputs[0], group.nodes["deflection axis"].inputs[1],
            group.nodes["rotate"].inputs["Vector"])


def _use_aberration(group, moving: bool) -> bool:
    """Feed the direction inputs from the inverse aberration (``moving``) or from D itself; relinks
    (and so recompiles the world's shader) only when that changes. Returns whether it relinked."""
    src = group.nodes["static direction" if moving else "D"].outputs["Vector"]
    changed = False
    for sock in _direction_inputs(group):
        if sock.is_linked and sock.links[0].from_socket == src:
            continue
        for lk in list(sock.links):
            group.links.remove(lk)
        group.links.new(src, sock)
        changed = True
    return changed


def _table_lookup(nodes, name, image, interpolation, location):
    tex = nodes.new("ShaderNodeTexImage")
    tex.name = tex.label = name
    tex.location = location
    tex.image = image
    tex.interpolation = interpolation
    tex.extension = "EXTEND"
    return tex


TABLE_LOOKUPS = ("table", "table+1", "linear")
"""The group's image nodes that read the table (the 'closest' pair and the 'linear' one)."""

LOOKUPS = {"linear": "linear value", "closest": "closest value"}
"""The group's two ways to read the table -> the node whose output is the deflection."""


def lookup_for(engine: str) -> str:
    """'linear' for Cycles (one filtered lookup, float interpolation on the CPU), 'closest' for
    every other engine (Eevee: GPU samplers, see :func:`_build_group`)."""
    return "linear" if engine == "CYCLES" else "closest"


def _use_lookup(group, kind: str) -> bool:
    """Link the deflection of lookup ``kind`` into the rotation's angle (only when it changes: a
    relink recompiles the world's shader). Returns whether it relinked."""
    angle = group.nodes["rotate"].inputs["Angle"]
    src = group.nodes[LOOKUPS[kind]]
    if angle.is_linked and angle.links[0].from_node == src:
        return False
    for lk in list(angle.links):
        group.links.remove(lk)
    group.links.new(src.outputs[0], angle)
    return True


def _new_table_image(name: str, size: int | None = None):
    """A 1-row float32 data image of ``size`` texels for a table of the group (default: the escape
    table, its value in the colour channels). Given a ``size`` (the sky-shift tables) its alpha is a
    fourth channel of data (CHANNEL_PACKED: never (un)premultiplied)."""
    from lutgen.escape import TABLE_SIZE

    img = bpy.data.images.new(name, width=size or TABLE_SIZE, height=1, alpha=size is not None, float_buffer=True,
                              is_data=True)
    img.use_half_precision = False  # Eevee would upload 16-bit floats (an error of ~1e-2 rad at phi ~ 20)
    img.colorspace_settings.name = "Non-Color"
    if size is not None:
        img.alpha_mode = "CHANNEL_PACKED"
    return img


def _own(tree, kind):
    return [n for n in tree.nodes if n.get(OWN) == kind]


GROUP_NODE_NAME = "grlens Lensed Sky"


def _group_node(tree):
    node = tree.nodes.get(GROUP_NODE_NAME)  # by name first (one lookup); renamed: by its mark
    if node is not None and node.get(OWN) == "group":
        return node
    found = _own(tree, "group")
    return found[0] if found else None


def is_lensed(world) -> bool:
    """Whether ``world``'s node tree holds grlens' nodes or records."""
    tree = getattr(world, "node_tree", None) if world is not None else None
    if tree is None:
        return False
    return any(n.get(OWN) or n.get(HOOKED) is not None for n in tree.nodes)


def _ensure_group_node(world):
    tree = world.node_tree
    node = _group_node(tree)
    if node is not None and _group_ok(node.node_tree):
        return node
    if node is not None:
        tree.nodes.remove(node)
    image = _new_table_image(f"{TABLE_PREFIX} ({world.name})")
    group = _build_group(f"{GROUP_PREFIX} ({world.name})", image)
    node = tree.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    node[OWN] = "group"
    node.name = GROUP_NODE_NAME
    node.label = "grlens: lensed sky (remove: switch Lens World off)"
    xs = [n.location.x for n in tree.nodes if n != node] or [0.0]
    node.location = (min(xs) - 300.0, 300.0)
    return node


def _record(node, ident, value):
    rec = node.get(HOOKED)
    if rec is None:
        node[HOOKED] = {}
        rec = node[HOOKED]
    if ident not in rec:
        rec[ident] = value


def _socket(sockets, ident):
    for s in sockets:
        if s.identifier == ident:
            return s
    return None


def _shift_ok(group) -> bool:
    holder = group.nodes.get(SHIFT_HOLDER)
    tree = holder.node_tree if holder is not None else None
    return tree is not None and all(k in tree.nodes for n in SHIFT_LOOKUPS
                                    for k in (n, n + " spare", n + " 0", n + " 1", n + " closest"))


def _group_ok(group) -> bool:
    return group is not None and _shift_ok(group) and all(k in group.nodes for k in (*TABLE_LOOKUPS, "spare", "e1", "xi_lim", "rotate",
                                                                 "beta_dir", "gamma_minus_1", "gamma_beta", "D",
                                                                 "static direction",
                                                                 "doppler cos", SHIFT_HOLDER,
                                                                 "cos xi", "deflection axis", *LOOKUPS.values()))


def _incoming(tree) -> dict:
    """{input socket's as_pointer(): its link} of ``tree``, in one pass over the tree's links
    (``socket.links`` scans every link of the tree, so asking each socket is quadratic in the size
    of the user's tree). Shader sockets take one link each."""
    return {lk.to_socket.as_pointer(): lk for lk in tree.links}


def _survey(tree):
    """One pass over ``tree``'s nodes: (the user's nodes with records, the user's direction textures,
    the user's World Outputs)."""
    recorded, textures, outputs = [], [], []
    for node in tree.nodes:
        if node.get(OWN):
            continue
        if node.get(HOOKED) is not None:
            recorded.append(node)
        kind = node.bl_idname
        if kind in DIRECTION_TEXTURES:
            textures.append(node)
        elif kind == "ShaderNodeOutputWorld":
            outputs.append(node)
    return recorded, textures, outputs


def _damaged(tree, recorded, incoming) -> bool:
    """Whether grlens' nodes were deleted by hand while inputs are recorded as hooked: the group node
    (or its table) is gone, or a World Output recorded as hooked no longer gets its Surface from a
    shadow mix."""
    if not recorded:
        return False
    grp = _group_node(tree)
    if grp is None or not _group_ok(grp.node_tree):
        return True
    for n in recorded:
        if n.bl_idname == "ShaderNodeOutputWorld" and "Surface" in n[HOOKED].keys():
            lk = incoming.get(n.inputs["Surface"].as_pointer())
            if lk is None or lk.from_node.get(OWN) != "shadow":
                return True
    return False


def apply(world) -> bool:
    """Hook ``world``'s node tree up to the lensed sky (idempotent). Returns whether it changed
    anything. Worlds without a node tree are left alone. Linear in the size of the tree: a pass over
    its nodes and one over its links (twice when grlens' nodes were deleted by hand)."""
    tree = world.node_tree if world is not None else None
    if tree is None:
        return False
    recorded, textures, outputs = _survey(tree)
    incoming = _incoming(tree)
    if _damaged(tree, recorded, incoming):
        restore(world)  # the user deleted grlens' nodes: back to the user's tree, then hook afresh
        recorded, textures, outputs = _survey(tree)
        incoming = _incoming(tree)
    changed = _group_node(tree) is None
    grp = _ensure_group_node(world)
    vec, esc = grp.outputs["Vector"], grp.outputs["Escapes"]
    links = tree.links
    # inputs the user relinked by hand since they were hooked: the user's link wins (forget the record)
    for node in recorded:
        rec = node[HOOKED]
        for ident in list(rec.keys()):
            sock = _socket(node.inputs, ident)
            lk = incoming.get(sock.as_pointer()) if sock is not None else None
            if sock is None or (lk is not None and lk.from_node.get(OWN) is None):
                del rec[ident]
        if not rec.keys():
            del node[HOOKED]
    for node in textures:  # their default coordinates (an unlinked Vector) are the view direction
        sock = node.inputs.get("Vector")
        if sock is not None and sock.enabled and not sock.is_linked:
            _record(node, sock.identifier, "")
            links.new(vec, sock)
            changed = True
    for lk in list(links):  # the user's Texture Coordinate Generated / Object links
        fn, to = lk.from_node, lk.to_node
        if (fn.bl_idname == "ShaderNodeTexCoord" and lk.from_socket.identifier in TEXCOORD_OUTPUTS
                and not to.get(OWN)):
            sock = lk.to_socket
            _record(to, sock.identifier, f"{fn.name}\t{lk.from_socket.identifier}")
            links.remove(lk)
            links.new(vec, sock)
            changed = True
    for node in outputs:
        surf = node.inputs["Surface"]
        lk = incoming.get(surf.as_pointer())
        if lk is not None and lk.from_node.get(OWN) != "shadow":
            src = lk.from_socket
            _record(node, surf.identifier, f"{lk.from_node.name}\t{src.identifier}")
            links.remove(lk)
            mix = tree.nodes.new("ShaderNodeMixShader")
            mix[OWN] = "shadow"
            mix.name = "grlens Shadow"
            mix.label = "grlens: shadow (black where rays fall in)"
            mix.location = (node.location.x - 200.0, node.location.y - 200.0)
            links.new(esc, mix.inputs[0])
            links.new(src, mix.inputs[2])
            links.new(mix.outputs[0], surf)
            changed = True
    return changed


def unhooked(world) -> list:
    """Names of the user's direction textures that cannot be lensed because Blender disables their
    Vector input (the Nishita Sky Texture with Sun Disc on)."""
    tree = world.node_tree if world is not None else None
    if tree is None:
        return []
    # (inputs["Vector"] does not find a disabled socket: look it up by identifier)
    return [n.name for n in tree.nodes if n.bl_idname in DIRECTION_TEXTURES
            and getattr(_socket(n.inputs, "Vector"), "enabled", True) is False]


def restore(world) -> None:
    """Put ``world``'s node tree back as it was before :func:`apply` (every recorded input relinked
    as it was, grlens' nodes, node group and table image removed)."""
    tree = world.node_tree if world is not None else None
    if tree is None:
        return
    links = tree.links
    incoming = _incoming(tree)
    for node in tree.nodes:
        rec = node.get(HOOKED)
        if rec is None:
            continue
        for ident, was in rec.items():
            sock = _socket(node.inputs, ident)
            if sock is None:
                continue
            lk = incoming.get(sock.as_pointer())
            if lk is not None and lk.from_node.get(OWN):
                links.remove(lk)
            if was and not sock.is_linked:
                from_name, from_ident = was.split("\t")
                fn = tree.nodes.get(from_name)
                out = _socket(fn.outputs, from_ident) if fn is not None else None
                if out is not None:
                    links.new(out, sock)
        del node[HOOKED]
    groups, images = [], []
    for node in list(tree.nodes):
        if node.get(OWN):
            if node.bl_idname == "ShaderNodeGroup" and node.node_tree is not None:
                groups.append(node.node_tree)
            tree.nodes.remove(node)
    holders = [g for g in groups if SHIFT_HOLDER in g.nodes]  # lensed-sky groups hold the sky-shift group
    ordered = []
    for g in holders + groups + [h.nodes[SHIFT_HOLDER].node_tree for h in holders]:
        if g is not None and g not in ordered:
            ordered.append(g)
    for g in ordered:  # holders first: the group they hold loses that user when they go
        for k in (*TABLE_LOOKUPS, "spare", *SHIFT_LOOKUPS, *(n + " spare" for n in SHIFT_LOOKUPS)):
            tex = g.nodes.get(k)
            if tex is not None and tex.image is not None and tex.image not in images:
                images.append(tex.image)
        if g.users == 0:
            bpy.data.node_groups.remove(g)
    for img in images:
        if img.users == 0:
            _written.pop(img.as_pointer(), None)
            bpy.data.images.remove(img)


def restore_all() -> None:
    """Restore every world in the file (add-on disabled, file about to be saved)."""
    for w in bpy.data.worlds:
        if is_lensed(w):
            restore(w)


def wants_lensing(scene) -> bool:
    """lens_world is on and a black hole is set."""
    g = scene.grlens
    return bool(g.lens_world) and g.black_hole is not None


def lensing_camera(scene):
    """The camera the sky is lensed for: the one that renders (``scene.camera``, or the camera a
    timeline marker binds to the frame: rebuild.active_camera), so its sky is exact
    even when ``scene.grlens.observer`` names another camera (whose view the image meshes are built
    for: the render then shows them from outside); the observer when the scene has no active camera."""
    from .rebuild import active_camera, observer_camera

    return active_camera(scene) or observer_camera(scene)


def _set(sock_owner, value: float):
    """Write a (float32) socket default value only when it differs after rounding to float32 (every
    write propagates a node tree update, ~0.2 ms, and tags the world for the depsgraph)."""
    value = float(np.float32(value))
    if sock_owner.default_value != value:
        sock_owner.default_value = value


def write_table(group, r_obs: float) -> bool:
    """Give the group's two table lookups lutgen.escape_table(r_obs) (the deflection in every colour
    channel) unless their image holds that radius's table already in this session. Returns whether
    it wrote. The table goes into the group's spare image, which then takes the lookups' place (the
    former one becomes the spare): Cycles keeps an image it has loaded while the same image is in
    use (with Persistent Data, between the frames of an animation, and in the viewport), so new
    pixels must come in a different image."""
    from lutgen.escape import escape_table

    from .lutcache import round_radius

    key = round_radius(r_obs)
    cur = group.nodes["table"].image
    if cur is not None and _written.get(cur.as_pointer()) == key and cur.get(R_OBS_KEY) == key:
        return False
    spare = group.nodes["spare"]
    image = spare.image
    px = _PIXELS.get(key)
    if px is None:
        t = escape_table(key)
        px = np.zeros((t.size, 4), np.float32)
        px[:, :3] = t.deflection[:, None]
        px[:, 3] = 1.0
        px = _PIXELS[key] = px.ravel()
        while len(_PIXELS) > PIXEL_CACHE:
            _PIXELS.popitem(last=False)
    else:
        _PIXELS.move_to_end(key)
    image.pixels.foreach_set(px)
    image.update()
    image[R_OBS_KEY] = key
    image.update_tag()
    _written[image.as_pointer()] = key
    for k in TABLE_LOOKUPS:
        group.nodes[k].image = image
    spare.image = cur
    return True


def update(scene, depsgraph=None) -> str | None:
    """Bring the lensed world of ``scene`` up to date for its current frame: hook the world's nodes
    (idempotent), set the camera's e1 and escape limit and, when its radius changed, the table.
    Restores the world when lensing is off. Returns a status line ("sky lensed, r_obs = ...") or
    None when the world is not lensed; raises WorldError for a scene that cannot be lensed (the
    world is then black)."""
    world = scene.world
    # worlds no longer shown by a lensing scene (the scene's world was swapped) get theirs back
    keep = {s.world for s in bpy.data.scenes if s.world is not None and wants_lensing(s)}
    for w in bpy.data.worlds:
        if w not in keep and is_lensed(w):
            restore(w)
    if not wants_lensing(scene):
        return None
    if world is None:
        return None  # no world: the background is black, lensed or not
    if world.node_tree is None or (bpy.app.version < (5, 0, 0) and not world.use_nodes):
        return f"sky not lensed: the world '{world.name}' uses no nodes (a plain colour; switch Use Nodes on)"
    g = scene.grlens
    cam = lensing_camera(scene)
    if cam is None:
        raise WorldError("the scene has no camera (set scene.camera or scene.grlens.observer)")
    if depsgraph is None and bpy.context.scene == scene:
        depsgraph = bpy.context.evaluated_depsgraph_get()  # (after a load, matrix_world is not evaluated yet)
    if depsgraph is not None:
        cam, hole = cam.evaluated_get(depsgraph), g.black_hole.evaluated_get(depsgraph)
    else:
        hole = g.black_hole
    p_cam = np.array(cam.matrix_world.translation, dtype=np.float64)
    p_hole = np.array(hole.matrix_world.translation, dtype=np.float64)
    if not (g.r_s > 0 and np.all(np.isfinite(p_cam)) and np.all(np.isfinite(p_hole))):
        raise WorldError("bad camera or hole position, or r_s")
    d = p_cam - p_hole
    r_obs = float(np.linalg.norm(d) / g.r_s)
    apply(world)
    grp = _group_node(world.node_tree).node_tree
    lim_sock = grp.nodes["xi_lim"].outputs[0]
    if r_obs <= 1.0:
        _set(lim_sock, 0.0)  # every ray falls in: the world is black
        raise WorldError(f"the camera is inside the event horizon (r = {r_obs:.4g} r_s): the sky is black")
    from lutgen.escape import escape_limit

    from .lutcache import round_radius

    e1 = d / np.linalg.norm(d)
    write_table(grp, r_obs)
    _use_lookup(grp, lookup_for(scene.render.engine))
    e1_node = grp.nodes["e1"]
    for k in range(3):
        _set(e1_node.inputs[k], float(e1[k]))
    _set(lim_sock, float(escape_limit(round_radius(r_obs))))
    line = f"sky lensed, r_obs = {r_obs:.4g} r_s"
    beta = np.zeros(3)
    if g.speed_of_light > 0:  # physical time: the camera's own motion aberrates its sky
        from ..core import mapping
        from .rebuild import RebuildError, observer_beta

        try:
            beta = observer_beta(scene, lensing_camera(scene), cam, g.black_hole, hole,
                                 mapping.Scene(p_cam, p_hole, g.r_s))
        except RebuildError as exc:
            raise WorldError(str(exc)) from None
        line += f", camera at {np.linalg.norm(beta):.3g} c"
        if not g.use_aberration:
            line += " (aberration off)"
            beta = np.zeros(3)
    set_velocity(grp, beta)
    _use_aberration(grp, bool(np.any(beta != 0)))
    shifted = g.speed_of_light > 0 and any(getattr(g, prop) for prop in SKY_SWITCHES)
    if shifted:
        set_sky_shift(grp, scene, r_obs, float(np.linalg.norm(beta)))
        _use_shift_lookup(grp.nodes[SHIFT_HOLDER].node_tree, lookup_for(scene.render.engine))
    _hook_sky_shift(world, _group_node(world.node_tree), shifted)
    skipped = unhooked(world)
    if skipped:
        line += f"; not lensed (no Vector input, e.g. a Sky Texture with Sun Disc on): {', '.join(skipped)}"
    return line


def set_velocity(group, beta) -> None:
    """The group's inverse aberration for a camera moving with ``beta`` (3,; units of c, world axes;
    zero: at rest) in its local static frame (see _static_direction)."""
    beta = np.asarray(beta, dtype=np.float64).reshape(3)
    b = float(np.linalg.norm(beta))
    n = -beta / b if b > 0 else np.zeros(3)
    gamma = 1.0 / math.sqrt(max(1.0 - b * b, 1e-300))
    node = group.nodes["beta_dir"]
    for k in range(3):
        _set(node.inputs[k], float(n[k]))
    _set(group.nodes["gamma_minus_1"].outputs[0], gamma - 1.0)
    _set(group.nodes["gamma_beta"].outputs[0], gamma * b)


SKY_SWITCHES = ("use_doppler_colour", "use_beaming", "use_gravitational_shift")
"""scene.grlens' colour switches, in the order of :func:`sky_shift_pixels`' arguments."""


def _hook_sky_shift(world, group_node, on: bool) -> None:
    """With ``on`` (physical time, a colour switch on), every Background node of the user's tree takes
    its colour through a group node of the world's sky-shift group (:func:`_build_shift_group`, marked
    ``grlens_own == "sky shift"``) fed by the lensed-sky group's ``Doppler cos``, its Color input recorded as the lensed world records inputs (so
    :func:`restore` puts it back); without, those nodes are taken out again and the colours relinked.
    An unlinked colour is copied into the shift node (again whenever it changes)."""
    tree = world.node_tree
    links = tree.links
    incoming = _incoming(tree)
    for node in _own(tree, "sky shift"):  # left over (the user linked the Background's colour anew)
        if not node.outputs["Color"].is_linked:
            tree.nodes.remove(node)
    backgrounds = [n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground" and not n.get(OWN)]
    for bg in backgrounds:
        sock = bg.inputs["Color"]
        lk = incoming.get(sock.as_pointer())
        hooked = lk is not None and lk.from_node.get(OWN) == "sky shift"
        if on:
            if hooked:
                shift = lk.from_node
            else:
                shift = tree.nodes.new("ShaderNodeGroup")
                shift.node_tree = group_node.node_tree.nodes[SHIFT_HOLDER].node_tree
                shift[OWN] = "sky shift"
                shift.label = "grlens: the sky's colour shift (physical time)"
                shift.location = (bg.location.x - 250.0, bg.location.y - 200.0)
                rec = bg.get(HOOKED)
                was = rec.get(sock.identifier) if rec is not None else None
                if lk is not None:
                    src = lk.from_socket
                    _record(bg, sock.identifier, f"{lk.from_node.name}\t{src.identifier}")
                    links.remove(lk)
                    links.new(src, shift.inputs["Color"])
                elif was:  # hooked before and our node deleted by hand: the recorded source again
                    fn = tree.nodes.get(was.split("\t")[0])
                    out = _socket(fn.outputs, was.split("\t")[1]) if fn is not None else None
                    if out is not None:
                        links.new(out, shift.inputs["Color"])
                else:
                    _record(bg, sock.identifier, "")
                links.new(shift.outputs["Color"], sock)
                links.new(group_node.outputs["Doppler cos"], shift.inputs["Doppler cos"])
            if not shift.inputs["Color"].is_linked and tuple(shift.inputs["Color"].default_value) != \
                    tuple(sock.default_value):
                shift.inputs["Color"].default_value = tuple(sock.default_value)
        elif hooked or (bg.get(HOOKED) is not None and sock.identifier in bg[HOOKED].keys()):
            if hooked:
                shift = lk.from_node
                src = shift.inputs["Color"].links[0].from_socket if shift.inputs["Color"].is_linked else None
                links.remove(lk)
                if src is not None:
                    links.new(src, sock)
            rec = bg[HOOKED]
            if sock.identifier in rec.keys():
                del rec[sock.identifier]
            if not rec.keys():
                del bg[HOOKED]
    if not on:
        for node in _own(tree, "sky shift"):
            tree.nodes.remove(node)


def set_sky_shift(group, scene, r_obs: float, beta: float = 0.0) -> bool:
    """The sky's shift for the camera at ``r_obs`` (r_s; light from infinity is blue-shifted by
    1 / sqrt(1 - r_s/r_obs)) moving at ``beta`` (c; the speed the group's inverse aberration uses) with
    the scene's colour switches: the tables of the group's sky-shift group (:func:`write_shift_table`).
    Returns whether they were written."""
    return write_shift_table(group, beta, r_obs, [getattr(scene.grlens, prop) for prop in SKY_SWITCHES])


def refresh(scene, depsgraph=None):
    """:func:`update` with its outcome in ``scene.grlens.world_status`` (written only when it
    changes). Returns (status line or None, error message or None)."""
    line = error = None
    try:
        line = update(scene, depsgraph)
    except WorldError as exc:
        error = str(exc)
    except ValueError as exc:  # bad numbers from the scene
        error = str(exc)
    text = f"grlens: {error}" if error else (line or "")
    g = scene.grlens
    if g.world_status != text:
        g.world_status = text
    return line, error


def forget_all() -> None:
    """A new file is being loaded: its table images must be written again."""
    _written.clear()
