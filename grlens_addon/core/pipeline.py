"""One object, one frame: source triangles -> first- and second-order image meshes (numpy only).

Steps (seed 000, section 3): map the source vertices and edge midpoints (mapping), measure rho per
edge and choose crack-free subdivision levels (subdivision), subdivide in world space, map the new
vertices, drop degenerate / invalid / off-screen triangles (culling), interpolate corner attributes
(UVs, normals) and compute the GR irradiance (illumination). The Blender layer only extracts a
:class:`SourceMesh` and uploads the :class:`ImageMesh` results.

Units: positions in Blender units (BU); light travel time as a length c*dt in BU (c = 1).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import culling, illumination, mapping, subdivision


@dataclass
class SourceMesh:
    """Evaluated source geometry in world space.

    positions (N, 3) BU; tris (T, 3) vertex indices; corner_uv (T, 3, 2) or None; material (T,) slot
    indices; corner_normals (T, 3, 3) unit normals in world space or None.
    """

    positions: np.ndarray
    tris: np.ndarray
    corner_uv: np.ndarray | None = None
    material: np.ndarray | None = None
    corner_normals: np.ndarray | None = None


@dataclass
class Settings:
    """The numeric settings of scene.grlens (see the add-on's properties for their meaning)."""

    max_tess_level: int = 64
    tess_a: float = 5.0
    tess_b: float = 0.75
    cull_ratio: float = 4.0
    orders: tuple = (1, 2)
    pixel_angle: float | None = None  # radians per pixel on the view sphere (caps subdivision)
    max_error_px: float | None = 0.25  # screen-space tolerance of the curved edges, pixels (with pixel_angle)


@dataclass
class ImageMesh:
    """One lensed image mesh.

    positions (V, 3) BU; tris (F, 3); corner_uv (F, 3, 2) or None; material (F,);
    light_travel_time (V,) c*dt in BU; irradiance (F, 3) per corner or None; report: culling counts;
    source_tri (F,) the source triangle of each face; source_position (V, 3) BU: the undistorted
    world point each image vertex shows.
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


@dataclass
class Light:
    """A point light for GR illumination: position (BU), intensity I0, and the LUT for its radius."""

    position: np.ndarray
    intensity: float
    lut: object


def clean_source(src: SourceMesh) -> tuple[SourceMesh, int]:
    """Drop triangles with non-finite or repeated vertices. Returns (cleaned, number dropped)."""
    tris = np.asarray(src.tris, dtype=np.int64).reshape(-1, 3)
    pos = np.asarray(src.positions, dtype=np.float64).reshape(-1, 3)
    finite = np.all(np.isfinite(pos), axis=1)
    ok = finite[tris].all(axis=1) if len(tris) else np.zeros(0, bool)
    ok &= (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 2] != tris[:, 0])

    def sel(a):
        return None if a is None else np.asarray(a)[ok]

    cleaned = SourceMesh(pos, tris[ok], sel(src.corner_uv),
                         sel(src.material) if src.material is not None else np.zeros(int(ok.sum()), np.int64),
                         sel(src.corner_normals))
    return cleaned, int((~ok).sum())


def build_images(src: SourceMesh, scene: mapping.Scene, lut, settings: Settings,
                 light: Light | None = None, frustum_planes=None) -> dict[int, ImageMesh]:
    """Image meshes of the requested orders for one source mesh (see the module docstring).

    ``frustum_planes`` (K, 4), rows (n, d) with n . x + d >= 0 inside (world space, BU): image
    triangles outside are dropped, and source triangles whose corners and edge midpoints all map
    outside one plane are dropped before they are subdivided. An image whose extent on the view sphere
    is below one pixel (``settings.pixel_angle``) is not built at all if it is a second-order image
    (reported as ``below_pixel``); first-order images are always built, so small objects stay visible.
    """
    src, n_bad = clean_source(src)
    out = {}
    if len(src.tris) == 0:
        for order in settings.orders:
            out[order] = _empty(order, n_bad)
        return out
    edges = subdivision.mesh_edges(src.tris)
    n_pts = len(src.positions)
    ev0, ev1 = edges.verts[:, 0], edges.verts[:, 1]
    # source vertices and edge midpoints share one plane computation and one LUT lookup per order
    coarse_pts = np.concatenate([src.positions, 0.5 * (src.positions[ev0] + src.positions[ev1])])
    coarse_plane = mapping.plane_coordinates(coarse_pts, scene)
    planes = None if frustum_planes is None or not len(frustum_planes) else np.asarray(frustum_planes, np.float64)
    for order in settings.orders:
        coarse = mapping.map_vertices(coarse_pts, scene, lut, order, coarse_plane)
        if order == 2 and _below_pixel(coarse, settings.pixel_angle):
            out[order] = _empty(order, n_bad, below_pixel=len(src.tris))
            continue
        d = coarse.direction
        d_a, d_b = d[ev0], d[ev1]
        rho = subdivision.rho(d_a, d_b, d[n_pts:])
        levels = subdivision.edge_levels(rho, settings.max_tess_level, settings.tess_a, settings.tess_b,
                                         subdivision.chord_angle(d_a, d_b), settings.pixel_angle,
                                         settings.max_error_px)
        tri_sel = _inside_frustum(coarse, src.tris, edges, n_pts, planes)
        n_pre = len(src.tris) - len(tri_sel)
        sub = subdivision.subdivide(src.positions, src.tris[tri_sel],
                                    subdivision.Edges(edges.verts, edges.of_tri[tri_sel]), levels)
        img = _map_subdivided(sub, n_pts, coarse, scene, lut, order)
        keep, report = culling.cull(sub.tris, img.direction, img.valid, sub.positions, scene.camera,
                                    settings.cull_ratio, planes, img.position)
        report.outside_frustum += n_pre
        report.extra["bad_source_triangles"] = n_bad
        tris = sub.tris[keep]
        used = np.unique(tris)
        remap = np.full(len(sub.positions), -1, dtype=np.int64)
        remap[used] = np.arange(used.size)
        src_tri = tri_sel[sub.source_tri[keep]]
        bary = sub.bary[keep]
        corner_uv = None
        if src.corner_uv is not None:
            corner_uv = np.einsum("fck,fkx->fcx", bary, src.corner_uv[src_tri])
        irr = None
        if light is not None and src.corner_normals is not None:
            n = np.einsum("fck,fkx->fcx", bary, src.corner_normals[src_tri])
            n /= np.maximum(np.linalg.norm(n, axis=2, keepdims=True), 1e-300)
            pts = sub.positions[tris].reshape(-1, 3)
            e, _ = illumination.irradiance(pts, n.reshape(-1, 3), light.position, scene.hole, scene.r_s,
                                           light.lut, light.intensity)
            irr = e.reshape(-1, 3)
        out[order] = ImageMesh(order=order, positions=img.position[used], tris=remap[tris],
                               corner_uv=corner_uv, material=src.material[src_tri],
                               light_travel_time=img.distance[used], irradiance=irr, report=report,
                               source_tri=src_tri, source_position=sub.positions[used])
    return out


def _below_pixel(coarse: mapping.Images, pixel_angle) -> bool:
    """True if all valid image points lie within one pixel (radians on the view sphere) of each other:
    the image is too small to matter (checked on the source vertices and edge midpoints)."""
    if not pixel_angle:
        return False
    d = coarse.direction[coarse.valid]
    if len(d) == 0:
        return False  # nothing valid: culling reports why
    centre = d.mean(axis=0)
    centre /= max(np.linalg.norm(centre), 1e-300)
    return bool(np.max(subdivision.chord_angle(d, np.broadcast_to(centre, d.shape))) * 2.0 < pixel_angle)


def _inside_frustum(coarse: mapping.Images, tris, edges, n_pts, planes) -> np.ndarray:
    """Indices of the source triangles to subdivide: all of them, or without a frustum those whose
    three corners and three edge midpoints all map outside one frustum plane (invalid points count as
    inside, so culling reports them under their own reason)."""
    if planes is None:
        return np.arange(len(tris))
    with np.errstate(invalid="ignore"):
        side = coarse.position @ planes[:, :3].T + planes[:, 3]  # (N + E, K)
    out = side < 0  # NaN (no image) -> False
    six = np.concatenate([tris, n_pts + edges.of_tri], axis=1)  # (T, 6)
    return np.flatnonzero(~out[six].all(axis=1).any(axis=1))


def _map_subdivided(sub, n_pts, coarse: mapping.Images, scene, lut, order) -> mapping.Images:
    """Images of the subdivided vertices; source corners (welding keys < n_pts) reuse the coarse
    mapping, only the new vertices are looked up."""
    is_corner = sub.vertex_key < n_pts
    if is_corner.all():
        idx = sub.vertex_key
        return mapping.Images(position=coarse.position[idx], direction=coarse.direction[idx],
                              distance=coarse.distance[idx], valid=coarse.valid[idx], plane=None,
                              xi=coarse.xi[idx], dt=coarse.dt[idx], ux=None, uy=None)
    new = mapping.map_vertices(sub.positions[~is_corner], scene, lut, order)
    n = len(sub.positions)
    position = np.empty((n, 3))
    direction = np.empty((n, 3))
    distance = np.empty(n)
    valid = np.empty(n, dtype=bool)
    xi = np.empty(n)
    dt = np.empty(n)
    idx = sub.vertex_key[is_corner]
    for dst, a, b in ((position, coarse.position, new.position), (direction, coarse.direction, new.direction),
                      (distance, coarse.distance, new.distance), (valid, coarse.valid, new.valid),
                      (xi, coarse.xi, new.xi), (dt, coarse.dt, new.dt)):
        dst[is_corner] = a[idx]
        dst[~is_corner] = b
    return mapping.Images(position=position, direction=direction, distance=distance, valid=valid, plane=None,
                          xi=xi, dt=dt, ux=None, uy=None)


def _empty(order, n_bad, below_pixel=0):
    rep = culling.CullReport()
    rep.extra["bad_source_triangles"] = n_bad
    rep.below_pixel = below_pixel
    return ImageMesh(order, np.zeros((0, 3)), np.zeros((0, 3), np.int64), None, np.zeros(0, np.int64),
                     np.zeros(0), None, rep, np.zeros(0, np.int64), np.zeros((0, 3)))
