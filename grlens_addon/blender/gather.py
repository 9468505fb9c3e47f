"""The geometry of a marked object, of any type, as one world-space source mesh (bpy side).

* Meshes, curves, text, surfaces and metaballs: their evaluated mesh (``Object.to_mesh()``: modifiers
  with the depsgraph's settings, render levels in renders and viewport levels in the viewport; the
  realized mesh of Geometry Nodes; curves and text with their
  bevel, extrusion and fill; a metaball family's surface belongs to its basis object, the one whose
  name has no ``.001`` suffix).
* Instances, through the evaluated depsgraph's ``object_instances`` (entries whose ``parent`` is the
  marked object: collection instances, vertex and face instancing, particle systems that render
  objects or collections, Geometry Nodes instances, nested instances included): the instanced meshes
  placed with each instance's ``matrix_world``, appended to the object's own faces (its own faces
  only if it shows its instancer in renders, ``show_instancer_for_render``). Geometry Nodes output of
  another kind (curves of a Geometry Nodes modifier on a curve object) comes the same way.
* Material slots of the combined mesh: the object's own slots first, as they are, then every other
  material the instanced meshes' faces use, in the order met (one slot per material); each face
  keeps its own material (an index past the slots uses the last, as in Blender).
* What has no faces is counted (loose vertices and edges, hair curves, point clouds, volumes,
  particles drawn as paths or halos) for the report: an object with no faces at all is skipped
  with a reason, one with faces is imaged and the rest named.

The depsgraph is the one the sources are evaluated in (a render's own for renders, the view
layer's for the viewport: see rebuild.source_depsgraphs); its instances are walked once per rebuild, and only when a marked
object may have instances. Units: Blender units, world space.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core import pipeline, triangulate

CONVERTED = ("MESH", "CURVE", "SURFACE", "FONT", "META")
"""Object types whose own surface ``Object.to_mesh()`` gives."""

NO_FACES = {"CURVES": "hair curves", "POINTCLOUD": "point cloud", "VOLUME": "volume"}
"""Object types without faces that render (in Cycles and Eevee) but cannot be imaged."""


def can_lens(obj) -> bool:
    """Whether ``obj`` can have images: object types that can produce geometry (meshes, curves, text,
    surfaces, metaballs; hair curves, point clouds and volumes through Geometry Nodes) and empties
    that instance a collection. The panel offers ``obj.grlens.enabled`` for these."""
    return obj.type in CONVERTED or obj.type in NO_FACES or (obj.type == "EMPTY" and obj.instance_type == "COLLECTION")


def may_have_instances(obj) -> bool:
    """Whether the depsgraph may hold instances made by ``obj`` (so its instances are gathered)."""
    return (obj.type == "EMPTY" or obj.is_instancer or len(obj.particle_systems) > 0
            or any(m.type == "NODES" and (m.show_viewport or m.show_render) for m in obj.modifiers))


@dataclass
class Part:
    """One evaluated mesh in its object's local space (BU): co (V, 3), tris (T, 3) vertex indices,
    corner_uv (T, 3, 2) or None (float32, as Blender stores them: the core carries them so, the upload
    writes them so), material (T,) slot indices, corner_normals (T, 3, 3) (local, not
    normalised; float32, as Blender stores them) or None, materials: its slots' materials (original data-blocks or None), and its
    loose vertices and edges (in no face)."""

    co: np.ndarray
    tris: np.ndarray
    corner_uv: np.ndarray | None
    material: np.ndarray
    corner_normals: np.ndarray | None
    materials: list = field(default_factory=list)
    loose_verts: int = 0
    loose_edges: int = 0


@dataclass
class Gathered:
    """What a marked object gives: ``mesh`` (world space; None when nothing can be imaged),
    ``materials`` the image's material slots (original data-blocks or None for an empty slot),
    ``skip`` the reason nothing can be imaged (else None), ``notes`` the parts of it that cannot be
    imaged (each a phrase for the report), ``instances`` the number of instances with faces."""

    mesh: pipeline.SourceMesh | None
    materials: list
    skip: str | None = None
    notes: list = field(default_factory=list)
    instances: int = 0


@dataclass
class Instances:
    """The instances of one marked object: ``parts`` {key: Part}, ``matrices`` {key: [(4, 4) world
    matrices]}, ``no_faces`` {kind: count} of instanced geometry without faces, ``entries`` all
    instance entries met."""

    parts: dict = field(default_factory=dict)
    matrices: dict = field(default_factory=dict)
    no_faces: dict = field(default_factory=dict)
    entries: int = 0


def _int_attr(me, name, n, fallback):
    """(n,) int32 values of the attribute ``name`` of ``me`` (``fallback()`` when absent)."""
    out = np.empty(n, dtype=np.int32)
    a = me.attributes.get(name)
    if a is None:
        return fallback()
    if n:
        a.data.foreach_get("value", out)
    return out


def _edge_verts(me) -> np.ndarray:
    ev = np.empty(2 * len(me.edges), dtype=np.int32)
    if len(ev):
        me.edges.foreach_get("vertices", ev)
    return ev


_KNOWN: list = []
_KNOWN_SIZE = 2
"""The arrays read from the last few meshes and what was derived from them (:func:`mesh_part`): a mesh
read again with equal arrays (an object that moves, or a frame that changes nothing of it) reuses
its triangles' corners, UVs and normals instead of deriving them again (comparing arrays is memory
speed; the quads' split and the corners' gathers are not)."""


def forget_all() -> None:
    """Drop the arrays kept for reuse (_KNOWN, _LAST_NORMALS: up to two meshes' arrays): a file being
    loaded or the add-on being disabled (rebuild.forget_all, registration.unregister) must not keep
    the last file's meshes alive."""
    _KNOWN.clear()
    _LAST_NORMALS.clear()


def _equal(a, b) -> bool:
    return a is not None and b is not None and a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b)


def _known(key: str, raw: tuple, make):
    """``make()``, or what it gave for equal ``raw`` arrays (a tuple) under ``key`` among the last
    meshes read (_KNOWN)."""
    for entry in _KNOWN:
        got = entry.get(key)
        if got is not None and len(got[0]) == len(raw) and all(_equal(a, b) for a, b in zip(got[0], raw)):
            _KNOWN[0][key] = got
            return got[1]
    value = make()
    _KNOWN[0][key] = (raw, value)
    return value


def mesh_part(me, materials=(), with_normals: bool = True) -> Part:
    """A :class:`Part` of the mesh ``me`` (as from ``to_mesh()``). Reads Blender's attribute arrays
    (memory speed) and derives the triangles' corners from them (core.triangulate); only meshes with
    n-gons use the slower per-triangle API. What is derived from arrays equal to those of a mesh read
    just before (the same mesh in the next frame) is reused (_KNOWN)."""
    n_v, n_l, n_p, n_e = len(me.vertices), len(me.loops), len(me.polygons), len(me.edges)
    if n_v == 0:
        return Part(np.zeros((0, 3)), np.zeros((0, 3), np.int64), None, np.zeros(0, np.int64), None, list(materials))
    co32 = np.empty(3 * n_v, dtype=np.float32)
    me.attributes["position"].data.foreach_get("vector", co32)
    co = co32.reshape(-1, 3).astype(np.float64)
    if n_p == 0:
        ev = _edge_verts(me)
        return Part(co, np.zeros((0, 3), np.int64), None, np.zeros(0, np.int64), None, list(materials),
                    loose_verts=n_v - int(np.count_nonzero(np.bincount(ev, minlength=n_v))) if n_e else n_v,
                    loose_edges=n_e)
    n_t = len(me.loop_triangle_polygons)
    tri_poly = np.empty(n_t, dtype=np.int32)
    me.loop_triangle_polygons.foreach_get("value", tri_poly)
    corner_vert = _int_attr(me, ".corner_vert", n_l, lambda: _loops(me, "vertex_index"))
    _KNOWN.insert(0, {})
    del _KNOWN[_KNOWN_SIZE + 1:]
    try:
        return _mesh_part(me, materials, with_normals, co32, co, tri_poly, corner_vert, (n_v, n_l, n_p, n_e))
    finally:
        if len(_KNOWN) > _KNOWN_SIZE:  # (the entry of this mesh replaces the oldest)
            _KNOWN.pop()


def _mesh_part(me, materials, with_normals, co32, co, tri_poly, corner_vert, counts) -> Part:
    n_v, n_l, n_p, n_e = counts
    n_t = len(tri_poly)
    sizes = np.array(counts)

    def corners():
        loops = triangulate.tri_corners(tri_poly, n_p, corner_vert, co)
        if loops is None:  # n-gons: Blender's own polygon fill
            loops = np.empty(3 * n_t, dtype=np.int32)
            me.loop_triangles.foreach_get("loops", loops)
        loops = loops.reshape(-1).astype(np.int64)
        return loops, corner_vert[loops].reshape(-1, 3).astype(np.int64)

    loops, tris = _known("corners", (sizes, tri_poly, corner_vert, co32), corners)
    mat = np.zeros(n_t, dtype=np.int64)
    mi = me.attributes.get("material_index")
    if mi is not None and mi.domain == "FACE":
        poly_mat = np.empty(n_p, dtype=np.int32)
        mi.data.foreach_get("value", poly_mat)
        mat = poly_mat[tri_poly].astype(np.int64)
    corner_uv = None
    if me.uv_layers.active is not None:
        uv = np.empty(2 * n_l, dtype=np.float32)
        me.uv_layers.active.uv.foreach_get("vector", uv)
        corner_uv = _known("uv", (loops, uv), lambda: uv.reshape(-1, 2).take(loops, axis=0).reshape(-1, 3, 2))
    normals = None
    if with_normals:
        cn = np.empty(3 * n_l, dtype=np.float32)
        me.corner_normals.foreach_get("vector", cn)
        normals = _known("normals", (loops, cn), lambda: cn.reshape(-1, 3).take(loops, axis=0).reshape(-1, 3, 3))
    # loose parts: edges in no face, vertices in no edge
    corner_edge = _int_attr(me, ".corner_edge", n_l, lambda: _loops(me, "edge_index"))

    def loose():
        loose_edges = n_e - int(np.count_nonzero(np.bincount(corner_edge, minlength=n_e)))
        free = n_v - int(np.count_nonzero(np.bincount(corner_vert, minlength=n_v)))  # vertices in no face
        if free and loose_edges:
            free = n_v - int(np.count_nonzero(np.bincount(_edge_verts(me), minlength=n_v)))
        return free, loose_edges

    free, loose_edges = _known("loose", (sizes, corner_vert, corner_edge), loose)
    return Part(co, tris, corner_uv, mat, normals, list(materials), loose_verts=free, loose_edges=loose_edges)


def _loops(me, prop):
    out = np.empty(len(me.loops), dtype=np.int32)
    if len(out):
        me.loops.foreach_get(prop, out)
    return out


def slot_materials(obj_eval) -> list:
    """The original materials (None: an empty slot) of the material slots of an evaluated object."""
    return [None if s.material is None else s.material.original for s in obj_eval.material_slots]


def part_of(obj_eval, with_normals: bool = True) -> Part:
    """:func:`mesh_part` of an evaluated object's ``to_mesh()`` (meshes, curves, text, surfaces,
    metaballs), with its material slots."""
    me = obj_eval.to_mesh()
    try:
        return mesh_part(me, slot_materials(obj_eval), with_normals)
    finally:
        obj_eval.to_mesh_clear()


def _inverse(lin):
    """Inverses of the (K, 3, 3) matrices ``lin``; zero for singular ones (an object scaled to zero:
    its triangles are degenerate, its normals 0, which receive no light)."""
    det = np.linalg.det(lin)
    ok = np.isfinite(det) & (det != 0)
    out = np.zeros_like(lin)
    if ok.any():
        out[ok] = np.linalg.inv(lin[ok])
    return out


def _unit_rows(n) -> np.ndarray:
    """``n`` (..., 3) with each row scaled to unit length (in place; zero rows stay zero)."""
    n /= np.maximum(np.sqrt(np.einsum("...k,...k->...", n, n)), 1e-300)[..., None]
    return n


_LAST_NORMALS: list = []
"""[(local corner normals, linear part of the matrix (bytes), world normals)] of the last objects
placed: an object that only moves (its matrix's linear part and its mesh's normals the same, the
normals' array reused by mesh_part) keeps its world normals."""


NORMAL_BLOCK = 1 << 16
"""Corners per block of :func:`_world_normals` (the float64 products stay in the cache)."""


def _world_normals(local, lin) -> np.ndarray:
    """Unit world corner normals (float32, as Blender stores normals: what the upload writes) of the
    ``local`` ones (T, 3, 3) under the linear part ``lin`` (3, 3) of an object's matrix (not
    mirroring): by the inverse transpose, in float64, normalised (one factor for a rotation and
    uniform scale), rounded to float32 once, in blocks of NORMAL_BLOCK corners; the last few results
    are kept (_LAST_NORMALS)."""
    key = np.ascontiguousarray(lin, dtype=np.float64).tobytes()
    for entry in _LAST_NORMALS:
        if entry[0] is local and entry[1] == key:
            return entry[2]
    inv = _inverse(lin[None])[0]
    gram = inv @ inv.T
    scale = np.trace(gram) / 3.0
    rows = np.ascontiguousarray(local).reshape(-1, 3)
    out = np.empty(rows.shape, np.float32)
    uniform = scale > 0 and np.allclose(gram, scale * np.eye(3), rtol=0.0, atol=1e-9 * scale)
    m = inv / np.sqrt(scale) if uniform else inv
    for s in range(0, len(rows), NORMAL_BLOCK):
        e = min(s + NORMAL_BLOCK, len(rows))
        block = rows[s:e].astype(np.float64) @ m  # (the inverse transpose, on rows)
        out[s:e] = block if uniform else _unit_rows(block)  # (rotation and uniform scale: unit stays unit)
    nrm = out.reshape(np.shape(local))
    _LAST_NORMALS.insert(0, (local, key, nrm))
    del _LAST_NORMALS[_KNOWN_SIZE:]
    return nrm


def _placed(part: Part, matrices: np.ndarray, with_normals: bool):
    """World positions (K V, 3), triangles (K T, 3), corner UVs, corner normals (unit) of ``part``
    placed by the (K, 4, 4) ``matrices``; triangles of mirroring matrices (negative determinant) are
    turned over, so that outward faces stay outward."""
    k, n_v = len(matrices), len(part.co)
    lin = matrices[:, :3, :3]
    if k == 1:  # the common case, one object: a plain matrix product
        m = matrices[0]
        pos = part.co @ m[:3, :3].T + m[:3, 3]
        if np.linalg.det(m[:3, :3]) >= 0:
            nrm = None
            if with_normals and part.corner_normals is not None:
                nrm = _world_normals(part.corner_normals, m[:3, :3])
            return pos, part.tris, part.corner_uv, nrm
    else:
        pos = (np.einsum("kij,vj->kvi", lin, part.co) + matrices[:, None, :3, 3]).reshape(-1, 3)
    tris = (part.tris[None] + (np.arange(k) * n_v)[:, None, None])
    flip = np.linalg.det(lin) < 0
    order = np.array([0, 2, 1])

    def corners(a):  # (T, 3, ...) per instance, corners 1 and 2 swapped where mirrored
        rep = np.repeat(a[None], k, axis=0)
        if flip.any():
            rep[flip] = rep[flip][:, :, order]
        return rep.reshape((-1,) + a.shape[1:])

    if flip.any():
        tris[flip] = tris[flip][:, :, order]
    uv = None if part.corner_uv is None else corners(part.corner_uv)
    nrm = None
    if with_normals and part.corner_normals is not None:
        inv_t = np.transpose(_inverse(lin), (0, 2, 1))  # normals transform by the inverse transpose
        n = np.einsum("kij,tcj->ktci", inv_t, part.corner_normals)
        if flip.any():
            n[flip] = n[flip][:, :, order]
        nrm = _unit_rows(n.reshape(-1, 3, 3)).astype(np.float32)  # (as _world_normals)
    return pos, tris.reshape(-1, 3), uv, nrm


def combine(placed_parts, with_normals: bool) -> tuple[pipeline.SourceMesh, list]:
    """One world-space SourceMesh and its material slots from ``placed_parts`` [(Part, (K, 4, 4)
    matrices)], the first being the object's own (its slots kept as they are; see the module
    docstring for the slots of the others)."""
    slots, index = [], {}

    def slot_of(m):
        key = 0 if m is None else m.as_pointer()
        if key not in index:
            index[key] = len(slots)
            slots.append(m)
        return index[key]

    pos, tris, uv, nrm, mat = [], [], [], [], []
    offset = 0
    any_uv = any(p.corner_uv is not None and len(p.tris) for p, _ in placed_parts)
    for i, (part, matrices) in enumerate(placed_parts):
        if i == 0:  # the object's own slots, as they are
            slots.extend(part.materials)
            for j, m in enumerate(part.materials):
                index.setdefault(0 if m is None else m.as_pointer(), j)
        if not len(part.tris):
            continue
        local = np.clip(part.material, 0, max(len(part.materials) - 1, 0))
        if part.materials:  # slots for the materials its faces use (all of the object's own)
            used = range(len(part.materials)) if i == 0 else np.unique(local)
            lookup = np.zeros(len(part.materials), dtype=np.int64)
            for j in used:
                lookup[j] = slot_of(part.materials[j])
        else:
            lookup = np.array([slot_of(None)], dtype=np.int64)
        p, t, u, n = _placed(part, matrices, with_normals)
        pos.append(p)
        tris.append(t + offset if offset else t)
        offset += len(p)
        if any_uv:
            uv.append(u if u is not None else np.zeros((len(t), 3, 2)))
        if with_normals:
            nrm.append(n if n is not None else np.zeros((len(t), 3, 3), np.float32))
        mat.append(np.tile(lookup[local], len(matrices)))
    if not tris:
        return pipeline.SourceMesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64), None, np.zeros(0, np.int64),
                                   None), slots
    mesh = pipeline.SourceMesh(_joined(pos), _joined(tris), _joined(uv) if any_uv else None, _joined(mat),
                               _joined(nrm) if with_normals else None)
    return mesh, slots


def _joined(arrays):
    """The arrays one after another: the one array itself when there is one (a plain mesh without
    instances: no copy of its million-triangle arrays)."""
    return arrays[0] if len(arrays) == 1 else np.concatenate(arrays)


def extract(obj_eval, with_normals: bool = True) -> pipeline.SourceMesh:
    """World-space triangles, corner UVs, material (slot) indices and, with ``with_normals``, unit
    corner normals of an evaluated object's own mesh (``to_mesh()``; instances not included)."""
    part = part_of(obj_eval, with_normals)
    mw = np.array(obj_eval.matrix_world, dtype=np.float64)[None]
    if not len(part.tris):
        return pipeline.SourceMesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64), None, np.zeros(0, np.int64), None)
    pos, tris, uv, nrm = _placed(part, mw, with_normals)
    return pipeline.SourceMesh(pos, tris, uv, part.material.copy(), nrm)


def instances(srcs, depsgraph, with_normals: bool = True) -> dict:
    """{``src.as_pointer()``: :class:`Instances`} for the marked objects ``srcs`` (originals) that
    :func:`may_have_instances`, from one walk over ``depsgraph.object_instances``. Each instanced mesh
    is read once (keyed by its evaluated data and material slots). grlens' own image objects are
    never taken (an instanced collection may hold them)."""
    wanted = {s.as_pointer(): Instances() for s in srcs if may_have_instances(s)}
    if not wanted:
        return {}
    cache = {}
    for inst in depsgraph.object_instances:
        if not inst.is_instance or inst.parent is None:
            continue
        bucket = wanted.get(inst.parent.original.as_pointer())
        if bucket is None:
            continue
        ob = inst.object
        orig = ob.original
        if orig is not None and orig.grlens.order in (1, 2):
            continue
        bucket.entries += 1
        data = ob.data
        if isinstance(data, bpy.types.Mesh):
            mats = slot_materials(ob)
            key = (data.as_pointer(), tuple(0 if m is None else m.as_pointer() for m in mats))
            if key not in cache:
                cache[key] = part_of(ob, with_normals)
            bucket.parts[key] = cache[key]
            bucket.matrices.setdefault(key, []).append(np.array(inst.matrix_world, dtype=np.float64))
        elif ob.type in NO_FACES:
            bucket.no_faces[ob.type] = bucket.no_faces.get(ob.type, 0) + 1
    return wanted


def _plural(n, word, words=None):
    return f"{n} {word if n == 1 else (words or word + 's')}"


def _metaball_basis(name):
    """The basis object's name of the metaball family of the object ``name`` (Blender groups metaball
    objects by their name without a trailing ``.NNN``)."""
    return re.sub(r"\.\d+$", "", name)


def _own_kind(src, src_eval, own: Part | None, inst: Instances | None) -> str | None:
    """The object's own geometry in words when it cannot have faces (None when it can)."""
    t = src.type
    if t == "CURVES":
        n = len(src_eval.data.curves)
        return f"hair curves: {_plural(n, 'curve')}" if n else None
    if t == "POINTCLOUD":
        n = len(src_eval.data.points)
        return f"a point cloud: {_plural(n, 'point')}" if n else None
    if t == "VOLUME":
        return "a volume"
    if t == "EMPTY":
        return None if inst is not None and inst.entries else "an empty without instances"
    if t == "META" and own is not None and len(own.co) == 0:
        basis = _metaball_basis(src.name)
        if basis != src.name:
            return f"a metaball element: its family's surface is built in the basis object '{basis}'"
    if t not in CONVERTED:
        return f"a {t.lower().replace('_', ' ')} has no geometry"
    return None


_EMPTY_WORDS = {"MESH": "empty mesh", "CURVE": "empty curve", "FONT": "empty text", "SURFACE": "empty surface",
                "META": "the metaball family has no surface", "EMPTY": "its instances have no faces",
                "CURVES": "no hair curves", "POINTCLOUD": "no points"}


def gather(src, src_eval, inst: Instances | None, with_normals: bool = True) -> Gathered:
    """The :class:`Gathered` geometry of the marked object ``src`` (evaluated: ``src_eval``) with its
    :class:`Instances` ``inst`` (None: it has none; see :func:`instances`)."""
    placed = []
    own = None
    instancer = inst is not None and (src.is_instancer or len(src.particle_systems) > 0 or inst.entries > 0)
    own_shown = not instancer or src.show_instancer_for_render
    if src.type == "MESH" or (src.type in CONVERTED and inst is None):
        own = part_of(src_eval, with_normals)
        placed.append((own if own_shown else Part(own.co[:0], own.tris[:0], None, own.material[:0], None,
                                                   own.materials), np.array(src_eval.matrix_world, np.float64)[None]))
    else:  # the object's own slots still come first
        placed.append((Part(np.zeros((0, 3)), np.zeros((0, 3), np.int64), None, np.zeros(0, np.int64), None,
                            slot_materials(src_eval)), np.eye(4)[None]))
    n_inst = 0
    no_faces = {}
    if inst is not None:
        for key, part in inst.parts.items():
            mats = np.array(inst.matrices[key])
            placed.append((part, mats))
            if len(part.tris):
                n_inst += len(mats)
            elif not len(part.co):  # (loose vertices and edges of an instanced mesh are counted as such)
                no_faces["empty mesh instance"] = no_faces.get("empty mesh instance", 0) + len(mats)
        for kind, n in inst.no_faces.items():
            no_faces[f"{NO_FACES[kind]} instance"] = n
    loose_v = sum(p.loose_verts * len(m) for p, m in placed)
    loose_e = sum(p.loose_edges * len(m) for p, m in placed)
    mesh, slots = combine(placed, with_normals)
    # what of it has no faces, in words
    phrases = []
    own_kind = _own_kind(src, src_eval, own, inst)
    if own_kind:
        phrases.append(own_kind)
    if loose_v:
        phrases.append(_plural(loose_v, "loose vertex", "loose vertices"))
    if loose_e:
        phrases.append(_plural(loose_e, "loose edge"))
    phrases += [_plural(n, kind) for kind, n in no_faces.items()]
    phrases += [f"hair of particle system '{ps.name}'" if ps.settings.type == "HAIR" else
                f"particle system '{ps.name}' drawn as {ps.settings.render_type.lower()}s"
                for ps in src.particle_systems if ps.settings.render_type in ("PATH", "HALO", "LINE")]
    if not len(mesh.tris):
        words = ", ".join(phrases) or _EMPTY_WORDS.get(src.type, "nothing to image")
        if src.type == "CURVE" and loose_e:
            words += "; a curve needs a bevel, an extrusion or a fill to have faces"
        head = "no faces" if src.type in CONVERTED or src.type in NO_FACES or src.type == "EMPTY" else "nothing to image"
        return Gathered(None, slots, skip=f"{head} ({words})", instances=n_inst)
    notes = [f"not imaged: {', '.join(phrases)} (no faces)"] if phrases else []
    return Gathered(mesh, slots, notes=notes, instances=n_inst)
