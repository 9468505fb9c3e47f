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


@dataclass
class ImageMesh:
    """One lensed image mesh.

    positions (V, 3) BU; tris (F, 3); corner_uv (F, 3, 2) or None; material (F,);
    light_travel_time (V,) c*dt in BU; irradiance (F, 3) per corner or None; report: culling counts.
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
    """Image meshes of the requested orders for one source mesh (see the module docstring)."""
    src, n_bad = clean_source(src)
    out = {}
    if len(src.tris) == 0:
        for order in settings.orders:
            out[order] = _empty(order, n_bad)
        return out
    edges = subdivision.mesh_edges(src.tris)
    plane_v = mapping.plane_coordinates(src.positions, scene)
    mids = 0.5 * (src.positions[edges.verts[:, 0]] + src.positions[edges.verts[:, 1]])
    plane_m = mapping.plane_coordinates(mids, scene)
    for order in settings.orders:
        img_v = mapping.map_vertices(src.positions, scene, lut, order, plane_v)
        img_m = mapping.map_vertices(mids, scene, lut, order, plane_m)
        d_a, d_b = img_v.direction[edges.verts[:, 0]], img_v.direction[edges.verts[:, 1]]
        rho = subdivision.rho(d_a, d_b, img_m.direction)
        levels = subdivision.edge_levels(rho, settings.max_tess_level, settings.tess_a, settings.tess_b,
                                         subdivision.chord_angle(d_a, d_b), settings.pixel_angle)
        sub = subdivision.subdivide(src.positions, src.tris, edges, levels)
        img = mapping.map_vertices(sub.positions, scene, lut, order)
        keep, report = culling.cull(sub.tris, img.direction, img.valid, sub.positions, scene.camera,
                                    settings.cull_ratio, frustum_planes, img.position)
        report.extra["bad_source_triangles"] = n_bad
        tris = sub.tris[keep]
        used = np.unique(tris)
        remap = np.full(len(sub.positions), -1, dtype=np.int64)
        remap[used] = np.arange(used.size)
        src_tri = sub.source_tri[keep]
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
                               source_tri=src_tri)
    return out


def _empty(order, n_bad):
    rep = culling.CullReport()
    rep.extra["bad_source_triangles"] = n_bad
    return ImageMesh(order, np.zeros((0, 3)), np.zeros((0, 3), np.int64), None, np.zeros(0, np.int64),
                     np.zeros(0), None, rep, np.zeros(0, np.int64))
