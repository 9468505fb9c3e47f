"""Mesh upload: numpy image meshes into Blender mesh data-blocks (fast foreach_set paths).

Units: positions in Blender units, written in world space (image objects have identity transforms).
Attributes written: UV map ``UVMap`` (corner), ``light_travel_time`` (point, float: c*dt in scene
length units), ``grlens_order`` (point, float: 1 or 2), ``grlens_irradiance`` (corner, float; only
with GR illumination), ``grlens_redshift`` (point, float: 1 + z; thin discs, and everything with
physical time), ``grlens_redshift_gravity`` (point, float: its gravitational part; physical time) and
``grlens_disc_colour`` (point, colour: linear RGB) for thin-disc sources, material indices, and the source's shading normals as the
image's custom normals (:func:`set_normals`).
"""
import uuid

import bpy
import numpy as np

FREE_NORMALS = bpy.app.version >= (4, 5, 0)
"""Custom normals can be written as a plain float vector attribute ``custom_normal`` on the corners
(Blender 4.5 and later: about 4 ms for 200k triangles); before, through
``Mesh.normals_split_custom_set`` (about 1 s for 200k triangles)."""

_TOPOLOGY: dict = {}
"""Token (the mesh's ``grlens_topology`` property) -> the triangle array last uploaded with it.
Comparing arrays is cheaper than hashing them every frame; a token not found here (after a reload,
or an undo step that brought back an older mesh) means a full upload."""


def _attr(mesh, name, type_, domain):
    a = mesh.attributes.get(name)
    if a is None or a.data_type != type_ or a.domain != domain:
        if a is not None:
            mesh.attributes.remove(a)
        a = mesh.attributes.new(name, type_, domain)
    return a


def same_topology(mesh, img) -> bool:
    """True if ``mesh`` holds exactly the vertices count and triangles of ``img`` (as last uploaded)."""
    if len(mesh.vertices) != len(img.positions) or len(mesh.polygons) != len(img.tris):
        return False
    last = _TOPOLOGY.get(mesh.get("grlens_topology"))
    return last is not None and np.array_equal(last, img.tris)


def forget(mesh) -> None:
    """Drop what is remembered of ``mesh`` (before it is removed)."""
    _TOPOLOGY.pop(mesh.get("grlens_topology"), None)


def forget_all() -> None:
    """Drop every remembered topology (a new file is being loaded)."""
    _TOPOLOGY.clear()


def _remember_topology(mesh, img) -> None:
    old = mesh.get("grlens_topology")
    _TOPOLOGY.pop(old, None)
    token = uuid.uuid4().hex
    _TOPOLOGY[token] = np.array(img.tris, copy=True)
    mesh["grlens_topology"] = token


def _set_edges(mesh, img) -> None:
    """The image's edges and corner edges (ImageMesh.edges: a dense source's own, kept per topology)
    written as Blender stores them, so that ``mesh.update()`` need not find them (Blender's search
    for the edges of a mesh without any is most of a large upload's time)."""
    if not len(img.tris):
        return
    verts, corner_edge = img.edges()
    mesh.edges.add(len(verts))
    ev = mesh.attributes.get(".edge_verts")
    if ev is not None and ev.data_type == "INT32_2D" and ev.domain == "EDGE":
        ev.data.foreach_set("value", np.ascontiguousarray(verts, dtype=np.int32).ravel())
    else:
        mesh.edges.foreach_set("vertices", np.ascontiguousarray(verts, dtype=np.int32).ravel())
    _attr(mesh, ".corner_edge", "INT", "CORNER").data.foreach_set(
        "value", np.ascontiguousarray(corner_edge, dtype=np.int32).ravel())


def upload(mesh, img, materials) -> None:
    """Write ``img`` (a core.pipeline.ImageMesh) into ``mesh``. If the topology is unchanged only the
    vertex positions and per-vertex/corner values are rewritten."""
    pos = np.ascontiguousarray(img.positions, dtype=np.float32).ravel()
    same = same_topology(mesh, img)
    if not same:
        mesh.clear_geometry()
        n_v, n_f = len(img.positions), len(img.tris)
        mesh.vertices.add(n_v)
        mesh.loops.add(3 * n_f)
        mesh.polygons.add(n_f)
        mesh.attributes["position"].data.foreach_set("vector", pos)
        mesh.attributes[".corner_vert"].data.foreach_set(
            "value", np.ascontiguousarray(img.tris, dtype=np.int32).ravel())
        mesh.polygons.foreach_set("loop_start", np.arange(0, 3 * n_f, 3, dtype=np.int32))
        _set_edges(mesh, img)
        sharp = mesh.attributes.get("sharp_face")  # smooth faces: no sharp_face attribute (clear_geometry
        if sharp is not None:  # drops it; polygons.foreach_set("use_smooth") would go face by face)
            mesh.attributes.remove(sharp)
        _remember_topology(mesh, img)
        mesh.update()
    else:
        mesh.attributes["position"].data.foreach_set("vector", pos)
        mesh.update_tag()
    if img.corner_uv is not None:
        uv = mesh.uv_layers.get("UVMap") or mesh.uv_layers.new(name="UVMap")
        uv.uv.foreach_set("vector", np.ascontiguousarray(img.corner_uv, dtype=np.float32).ravel())
    _attr(mesh, "light_travel_time", "FLOAT", "POINT").data.foreach_set(
        "value", np.ascontiguousarray(img.light_travel_time, dtype=np.float32))
    if img.irradiance is not None:
        _attr(mesh, "grlens_irradiance", "FLOAT", "CORNER").data.foreach_set(
            "value", np.ascontiguousarray(img.irradiance, dtype=np.float32).ravel())
    elif mesh.attributes.get("grlens_irradiance") is not None:
        mesh.attributes.remove(mesh.attributes["grlens_irradiance"])
    for name, values, type_ in (("grlens_redshift", img.redshift, "FLOAT"),
                                ("grlens_redshift_gravity", img.redshift_gravity, "FLOAT"),
                                ("grlens_disc_colour", img.disc_colour, "FLOAT_COLOR")):
        if values is not None:
            a = _attr(mesh, name, type_, "POINT")
            if type_ == "FLOAT_COLOR":
                rgba = np.ones((len(values), 4), dtype=np.float32)
                rgba[:, :3] = values
                a.data.foreach_set("color", rgba.ravel())
            else:
                a.data.foreach_set("value", np.ascontiguousarray(values, dtype=np.float32))
        elif mesh.attributes.get(name) is not None:
            mesh.attributes.remove(mesh.attributes[name])
    if list(mesh.materials) != list(materials):
        mesh.materials.clear()  # (this also resets the faces' material indices: written below)
        for m in materials:
            mesh.materials.append(m)
    if len(img.tris):  # the face attribute (memory speed; polygons.foreach_set goes item by item)
        _attr(mesh, "material_index", "INT", "FACE").data.foreach_set(
            "value", np.ascontiguousarray(img.material, dtype=np.int32))


def set_normals(mesh, img) -> None:
    """The image's shading normals: at every corner the source's own shading normal (world space, flat
    or smooth or custom, as the source shades) at the corner's source point (``img.corner_normal``),
    so that a lamp lights the image as it lights the source. Second-order images are mirror images
    (their rays cross the axis behind the hole), so their faces are wound the other way round
    relative to the side of the source that is seen: their normals are written reversed. The
    renderer turns a normal round on a face seen from behind, so every image is lit on the side of
    the source that its ray leaves from, never from behind. Without normals (an empty image or a
    source without them) Blender's own are used."""
    n = img.corner_normal
    have = FREE_NORMALS and mesh.attributes.get("custom_normal") is not None
    if n is None or not len(img.tris):
        if have:
            mesh.attributes.remove(mesh.attributes["custom_normal"])
        return
    vals = np.ascontiguousarray(n, dtype=np.float32).reshape(-1, 3)
    if img.order == 2:
        # (exact: no float64 copy of -n first; a new array when vals is the image's own float32 normals)
        vals = np.negative(vals, out=None if np.may_share_memory(vals, n) else vals)
    if FREE_NORMALS:
        a = mesh.attributes.get("custom_normal")
        if a is None or a.data_type != "FLOAT_VECTOR" or a.domain != "CORNER":
            if a is not None:
                mesh.attributes.remove(a)
            a = mesh.attributes.new("custom_normal", "FLOAT_VECTOR", "CORNER")
        a.data.foreach_set("vector", vals.ravel())
    else:  # every edge sharp: each corner keeps its own normal (no averaging over smooth fans)
        _attr(mesh, "sharp_edge", "BOOLEAN", "EDGE").data.foreach_set("value", np.ones(len(mesh.edges), dtype=bool))
        mesh.normals_split_custom_set(vals)
    mesh.update_tag()


def set_order(mesh, order: int) -> None:
    """Point attribute ``grlens_order`` (1.0 or 2.0) for the image-order AOV."""
    a = _attr(mesh, "grlens_order", "FLOAT", "POINT")
    a.data.foreach_set("value", np.full(len(mesh.vertices), float(order), dtype=np.float32))
