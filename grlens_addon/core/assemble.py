"""Assembly: the kept pieces and patch faces of one order as one image mesh, with its attributes.

Vertices are compacted to those the kept faces use, the axis patches' faces are appended, and each
face corner gets its values (UVs, normals) from its source triangle: interpolated at the corner's
barycentric coordinates there (subdivision.carry_rows), or for a patch face from the source triangle
under each corner unless that crosses a seam (budget.PATCH_SEAM_JUMP). GR illumination (a point
light, illumination.irradiance) and a thin accretion disc's redshift and colour (thin_disc) are
computed per vertex or corner of the final mesh.

Units: positions in Blender units (BU); light travel time as a length c*dt in BU (c = 1).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import budget as B
from . import culling, illumination, observer_view, subdivision, thin_disc
from .frame import DiscEmitter, Frame, Source


@dataclass
class ImageMesh:
    """One lensed image mesh.

    positions (V, 3) BU; tris (F, 3); corner_uv (F, 3, 2) or None; material (F,);
    light_travel_time (V,) c*dt in BU; irradiance (F, 3) per corner or None; corner_normal (F, 3, 3)
    the source's unit shading normal (world space) at each corner's source point, or None when the
    source has no normals; report: culling counts;
    source_tri (F,) the source triangle of each face; source_position (V, 3) BU: the undistorted
    world point each image vertex shows; redshift (V,) 1 + z of the light each vertex shows
    (:func:`image_redshift`), with a :class:`DiscEmitter` or a scene with a velocity (physical time;
    0 where there is none: disc gas without a circular orbit, r <= 1.5 r_s or on the disc axis), else
    None; with a disc, disc_colour (V, 3) linear RGB (black there), else None; with physical time,
    redshift_gravity (V,) its gravitational part sqrt((1 - r_s/r_cam) / (1 - r_s/r)) (static emitter
    and camera), else None. source_tri indexes the caller's SourceMesh.tris.
    """

    order: int
    positions: np.ndarray
    tris: np.ndarray
    corner_uv: np.ndarray | None
    material: np.ndarray
    light_travel_time: np.ndarray
    irradiance: np.ndarray | None
    report: culling.CullReport
    source_tri: np.ndarray = field(repr=False, default=None)
    source_position: np.ndarray = field(repr=False, default=None)
    redshift: np.ndarray | None = field(repr=False, default=None)
    disc_colour: np.ndarray | None = field(repr=False, default=None)
    corner_normal: np.ndarray | None = field(repr=False, default=None)
    redshift_gravity: np.ndarray | None = field(repr=False, default=None)
    edge_basis: tuple | None = field(repr=False, default=None)
    """(vertex_source (V,): each vertex's index among the prepared source's vertices, -1 for a new one;
    face_source (F,): each face's prepared source triangle; the prepared source's tris (T, 3) and its
    subdivision.Edges), from which :meth:`edges` takes the edges of whole source triangles; None: the
    edges are found from the faces alone."""

    _edges: tuple | None = field(repr=False, default=None, compare=False)

    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """(verts (E, 2), corner_edge (F, 3)): the mesh's unique undirected edges (vertex indices) and
        for each face corner k the edge joining corners k and (k + 1) % 3, as Blender stores a mesh. A
        dense source's faces are mostly whole source triangles, whose edges are the source's (kept
        per topology): only the other faces' edges are sorted out (:func:`image_edges`). Found once
        (a build in a worker thread finds them there, before the upload reads them)."""
        if self._edges is None:
            if self.edge_basis is None:
                e = subdivision.mesh_edges(self.tris) if len(self.tris) else subdivision.Edges(
                    np.zeros((0, 2), np.int64), np.zeros((0, 3), np.int64))
                self._edges = (e.verts, e.of_tri)
            else:
                self._edges = image_edges(self.tris, *self.edge_basis)
        return self._edges


def image_edges(tris, vertex_source, face_source, source_tris, source_edges) -> tuple[np.ndarray, np.ndarray]:
    """(verts (E, 2), corner_edge (F, 3)) of the faces ``tris`` (F, 3) of a mesh whose vertices are
    source vertices ``vertex_source`` (V,; -1: a new vertex) and whose faces lie in the source
    triangles ``face_source`` (F,) of ``source_tris`` (T, 3) with edges ``source_edges``
    (subdivision.Edges): a face that is its source triangle (the same corners in the same order) has
    the source's edges; a side of another face joining two source vertices is a source edge if the
    source has one there (found among the source's sorted edge keys); the rest are new edges, made
    unique among themselves. The source edges used come first, in the source's order, then the new
    ones. Indices only (no units)."""
    tris = np.asarray(tris, dtype=np.int64)
    n_f, n_v = len(tris), len(vertex_source)
    if n_f == 0:
        return np.zeros((0, 2), np.int64), np.zeros((0, 3), np.int64)
    corner_src = vertex_source.take(tris)
    whole = (corner_src == source_tris.take(face_source, axis=0)).all(axis=1)
    edge_of = np.empty((n_f, 3), np.int64)  # >= 0: a source edge; < 0: -1 - (a new edge)
    rest = np.flatnonzero(~whole)
    if rest.size == 0:
        edge_of = source_edges.of_tri.take(face_source, axis=0)
    else:
        w = np.flatnonzero(whole)
        edge_of[w] = source_edges.of_tri.take(face_source.take(w), axis=0)
        a = tris.take(rest, axis=0)
        b = np.roll(a, -1, axis=1)
        ka = corner_src.take(rest, axis=0)
        kb = np.roll(ka, -1, axis=1)
        found = np.full(a.shape, -1, np.int64)
        both = (ka >= 0) & (kb >= 0)
        if both.any():
            keys = source_edge_keys(source_edges)
            m = np.int64(source_edges.n_points)
            q = np.minimum(ka[both], kb[both]) * m + np.maximum(ka[both], kb[both])
            at = np.minimum(np.searchsorted(keys, q), len(keys) - 1)
            found[both] = np.where(keys.take(at) == q, at, -1)
        new = found < 0
        lo, hi = np.minimum(a[new], b[new]), np.maximum(a[new], b[new])
        uniq, inv = np.unique(lo * n_v + hi, return_inverse=True)
        found[new] = -1 - inv
        edge_of[rest] = found
    n_src = len(source_edges.verts)
    is_src = edge_of >= 0
    used = np.zeros(n_src, bool)
    used[edge_of[is_src] if rest.size else edge_of.ravel()] = True
    src_used = np.flatnonzero(used)
    index = np.full(n_src, -1, np.int64)
    index[src_used] = np.arange(src_used.size)
    own = np.flatnonzero(vertex_source >= 0)
    n_pts = max(int(source_edges.n_points), int(vertex_source.max(initial=-1)) + 1)
    vertex_of = np.full(n_pts, -1, np.int64)  # source vertex -> this mesh's vertex
    vertex_of[vertex_source.take(own)] = own
    verts = vertex_of.take(source_edges.verts.take(src_used, axis=0))
    if rest.size == 0:
        return verts, index.take(edge_of)
    corner_edge = np.where(is_src, index.take(np.maximum(edge_of, 0)), src_used.size - 1 - edge_of)
    new_verts = np.stack([uniq // n_v, uniq % n_v], axis=1)
    return np.concatenate([verts, new_verts]), corner_edge


def source_edge_keys(edges) -> np.ndarray:
    """(E,) the keys lo * n_points + hi of subdivision.Edges ``edges`` (ascending: mesh_edges sorts its
    edges by them), made once per Edges (kept per topology with them)."""
    if edges.keys is None:
        edges.keys = edges.verts[:, 0] * np.int64(edges.n_points) + edges.verts[:, 1]
    return edges.keys


def empty_image(order, report: culling.CullReport) -> ImageMesh:
    """An image mesh without faces, with its ``report``."""
    return ImageMesh(order, np.zeros((0, 3)), np.zeros((0, 3), np.int64), None, np.zeros(0, np.int64),
                     np.zeros(0), None, report, np.zeros(0, np.int64), np.zeros((0, 3)))


def assemble(frame: Frame, source: Source, pieces, keep, patches, patch_keep, report, order,
             disc: DiscEmitter | None = None) -> ImageMesh:
    """The image mesh of ``order``: the ``pieces`` (subdivision.Pieces) that the culling ``keep``s, then
    the faces of this order's axis ``patches`` that ``patch_keep`` (culling.cull_pieces) marks, with
    corner values, irradiance (with frame.light) and disc values (with ``disc``)."""
    if keep is None:
        return empty_image(order, report)
    sub, img = pieces.sub, pieces.images
    everything = bool(keep.all())
    kept = None if everything else np.flatnonzero(keep)
    tris = sub.tris if everything else sub.tris.take(kept, axis=0)
    used = observer_view.used_vertices(tris, len(sub.positions))
    if used.size == len(sub.positions):  # every vertex is used: indices stay as they are
        image_tris = tris
    else:
        remap = np.full(len(sub.positions), -1, dtype=np.int64)
        remap[used] = np.arange(used.size)
        image_tris = remap.take(tris)
    src_tri = pieces.face_src if everything else pieces.face_src.take(kept)
    # the faces' corners in their source triangles: None (whole source triangles src_tri) or rows
    # (row barycentrics, row source triangle, face corner rows, unit rows; see subdivision.Subdivided)
    rows = None
    if not sub.identity:
        rows = (sub.row_bary, pieces.selected.take(sub.row_src),
                sub.corner_row if everything else sub.corner_row.take(kept, axis=0), sub.n_unit_rows)
    v_pos, v_dir = img.position.take(used, axis=0), img.direction.take(used, axis=0)
    v_dist, v_src = img.distance.take(used), sub.positions.take(used, axis=0)
    patch_corners = None
    order_patches = [p for p in patches if order in p.orders]
    parts = _patch_parts(order_patches, patch_keep, order, len(used)) if order_patches else None
    if parts is not None:
        p_tris, p_src, patch_corners, p_pos, p_dir, p_dist, p_spos = parts
        image_tris = np.concatenate([image_tris, p_tris])
        v_pos, v_dir = np.concatenate([v_pos, p_pos]), np.concatenate([v_dir, p_dir])
        v_dist, v_src = np.concatenate([v_dist, p_dist]), np.concatenate([v_src, p_spos])

    def corner_values(values, unit=False):  # (F, 3, K) per face corner, subdivided faces then patch faces
        own = _carry(values, src_tri, rows, unit)
        if patch_corners is None:
            return own
        patch = _patch_corner_values(values, p_src, *patch_corners)
        if unit:
            patch /= np.maximum(np.linalg.norm(patch, axis=2, keepdims=True), 1e-300)
        return np.concatenate([own, patch])

    mesh = source.mesh
    corner_uv = None
    if mesh.corner_uv is not None:
        corner_uv = corner_values(mesh.corner_uv)
    irr = n = None
    scene, light = frame.scene, frame.light
    if mesh.corner_normals is not None:  # interpolated like the UVs (a flat face's stay its normal)
        n = corner_values(mesh.corner_normals, unit=True)
    if light is not None and n is not None:
        pts = v_src.take(image_tris.ravel(), axis=0)
        e, _ = illumination.irradiance(pts, n.reshape(-1, 3), light.position, scene.hole, scene.r_s,
                                       light.lut, light.intensity)
        irr = e.reshape(-1, 3)
    # each vertex's source vertex (-1: a new one), for the image's edges (ImageMesh.edges)
    key = sub.vertex_key.take(used)
    vertex_source = np.where(key < len(source.positions), key, -1)
    if parts is not None:
        vertex_source = np.concatenate([vertex_source, np.full(len(v_pos) - used.size, -1, np.int64)])
    if patch_corners is not None:
        src_tri = np.concatenate([src_tri, p_src])
    redshift = colour = gravity = None
    if scene.beta is not None:  # physical time: the gravitational part too, for the colour's switches
        gravity = 1.0 / observer_view.frequency_ratio(np.linalg.norm(v_src - scene.hole, axis=1) / scene.r_s,
                                                       scene.r_obs, None)
    if disc is not None or scene.beta is not None:
        redshift = image_redshift(scene, v_src, v_dir, disc, gravity,
                                  exact_order=order if frame.settings.exact_redshift else None)
    if gravity is not None:
        gravity = np.where(np.isnan(gravity), 0.0, gravity)
    if disc is not None:
        r = np.linalg.norm(v_src - scene.hole, axis=1) / scene.r_s
        colour = np.nan_to_num(thin_disc.disc_colour(r, redshift, disc.mode, r_in=disc.r_in,
                                                     t_peak=disc.t_peak, exposure=disc.exposure))
    if redshift is not None:
        redshift = np.where(np.isnan(redshift), 0.0, redshift)  # 0: no circular orbit there (r <= 1.5 r_s, axis)
    return ImageMesh(order=order, positions=v_pos, tris=image_tris, corner_uv=corner_uv,
                     material=mesh.material.take(src_tri), light_travel_time=v_dist, irradiance=irr, report=report,
                     source_tri=source.origin.take(src_tri), source_position=v_src, redshift=redshift,
                     disc_colour=colour, corner_normal=n, redshift_gravity=gravity,
                     edge_basis=(vertex_source, src_tri, source.tris, source.edges))


def image_redshift(scene, points, directions, disc: DiscEmitter | None = None, gravity=None,
                   exact_order: int | None = None) -> np.ndarray:
    """(N,) 1 + z = nu_emitted / nu_seen of the light from the source ``points`` (N, 3; BU) that the
    camera of ``scene`` sees in the image ``directions`` (N, 3; its own frame: aberrated when the scene
    has a velocity ``beta``). Emitters at rest in their static frames (the gravitational shift and
    the camera's motion: observer_view.frequency_ratio), or a thin disc's gas on circular orbits
    (thin_disc, its shift for the static observer, divided by the camera's Doppler factor). NaN where
    there is none (r <= 1 r_s; disc gas at r <= 1.5 r_s or on the disc axis). ``gravity``: the
    gravitational part 1 / frequency_ratio(r, r_obs) of ``points`` when the caller has it (emitters
    at rest only). ``exact_order`` (1 or 2; Settings.exact_redshift): the directions are those of that
    order's images, and their angle from the camera-hole axis is made exact first
    (observer_view.exact_view_directions): 1 + z to about 1e-12 relative instead of the table's
    direction error times |beta| (a few 1e-8 at 0.4 c)."""
    view = scene.view_beta
    if exact_order is not None:
        static = directions if view is None else observer_view.unaberrate(directions, view)
        static = observer_view.exact_view_directions(static, points, scene, exact_order)
        directions = static if view is None else observer_view.aberrate(static, view)
    if disc is None and view is not None:  # the Doppler factor from the seen directions themselves
        if gravity is None:
            gravity = 1.0 / observer_view.frequency_ratio(np.linalg.norm(points - scene.hole, axis=1) / scene.r_s,
                                                           scene.r_obs, None)
        return gravity / observer_view.doppler_factor_seen(directions, view)
    static = directions if view is None else observer_view.unaberrate(directions, view)
    if disc is not None:
        z1 = thin_disc.vertex_redshift_from_direction(points, scene.hole, scene.camera, scene.r_s, disc.axis, static,
                                                      disc.prograde)
        return z1 if scene.beta is None else z1 / observer_view.doppler_factor(static, scene.beta)
    r = np.linalg.norm(points - scene.hole, axis=1) / scene.r_s
    return 1.0 / observer_view.frequency_ratio(r, scene.r_obs, -static, scene.beta)


def _patch_parts(patches, patch_keep, order, offset):
    """The kept faces of the axis ``patches`` (masks ``patch_keep``) of ``order`` as arrays to append to
    an image mesh whose vertex count is ``offset``: (tris, source triangle, corners, image positions,
    directions, c*dt, source positions), corners = (bary (F, 3, 3) in the face's source triangle, and
    the rows of subdivision.carry_rows: each appended vertex's own source triangle (V,) and
    barycentrics there (V, 3), and the faces' corners among them (F, 3)); None when no face is left."""
    out = [[] for _ in range(7)]
    first_offset = offset
    for p, ok in zip(patches, patch_keep):
        if ok is None:
            continue
        im = p.images[order]
        faces = p.tris[ok]
        if len(faces) == 0:
            continue
        used = observer_view.used_vertices(faces, len(p.source_position))
        remap = np.full(len(p.source_position), -1, dtype=np.int64)
        remap[used] = np.arange(used.size)
        out[0].append(remap.take(faces) + offset)
        out[1].append(p.face_src[ok])
        out[2].append((p.bary[ok], p.vertex_tri.take(used), p.vertex_bary.take(used, axis=0)))
        out[3].append(im.position.take(used, axis=0))
        out[4].append(im.direction.take(used, axis=0))
        out[5].append(im.distance.take(used))
        out[6].append(p.source_position.take(used, axis=0))
        offset += used.size
    if not out[0]:
        return None
    tris = np.concatenate(out[0])
    bary, vertex_tri, vertex_bary = (np.concatenate(a) for a in zip(*out[2]))
    corners = (bary, vertex_tri, vertex_bary, tris - first_offset)  # rows: the patch vertices appended
    return (tris, np.concatenate(out[1]), corners, *(np.concatenate(a) for a in out[3:]))


def _patch_corner_values(values, face_src, bary, vertex_tri, vertex_bary, corner_row) -> np.ndarray:
    """(F, 3, K) corner values of patch faces (see _patch_parts and PATCH_SEAM_JUMP) from the source
    triangles' corner values ``values`` (T, 3, K)."""
    values = np.asarray(values)  # (float32 UVs stay so: the arithmetic below is in float64)
    own = subdivision.carry_rows(vertex_bary, vertex_tri, corner_row, values)
    # only faces with a corner on another triangle than their own can be across a seam (where all
    # three lie on it, both ways interpolate in that triangle at the same point)
    other = np.flatnonzero((vertex_tri.take(corner_row) != face_src[:, None]).any(axis=1))
    if other.size:
        carried = np.matmul(bary[other], values.take(face_src[other], axis=0))  # the face's triangle, extrapolated
        seam = (np.abs(own[other] - carried) > B.PATCH_SEAM_JUMP).any(axis=(1, 2))
        own[other[seam]] = carried[seam]
    return own


def _carry(corner_values, src_tri, rows, unit=False):
    """Corner values (F, 3, K) of the image faces from the source triangles' corner values (T, 3, K):
    the faces' own source triangles' (``src_tri``) when ``rows`` is None, else interpolated at the
    rows (row_bary, row_src, corner_row, n_unit) of subdivision.carry_rows (``unit``: unit vectors,
    normalised again where interpolated; the source's own are unit already)."""
    corner_values = np.asarray(corner_values)  # (float32 UVs: taken as they are, interpolated in float64)
    if rows is None:
        return corner_values.take(src_tri, axis=0)
    row_bary, row_src, corner_row, n_unit = rows
    return subdivision.carry_rows(row_bary, row_src, corner_row, corner_values, n_unit, unit)
