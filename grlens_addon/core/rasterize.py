"""A small numpy z-buffer "rasterizer" of the add-on's image meshes (no bpy), for image-level comparison
of the polygon method with the reference tracer (``raytrace``) without Blender.

Units: positions and light travel times in Blender units (BU), c = 1. The camera is a
:class:`raytrace.Camera` (Blender's axes): perspective, or Cycles' equirectangular or fisheye
equidistant panorama. Every pixel is sampled once, at its centre, like the reference: for each
triangle a set of candidate pixels is tested with an exact ray-triangle intersection
(Moeller-Trumbore) of the straight pixel ray, which is what a rasterizer's perspective-correct
interpolation computes. Perspective: the candidates are the pixels of the triangle's screen bounding
box; triangles that reach behind the camera's near distance are tested against every pixel instead of
being clipped. Panoramas, where a triangle's image has curved edges and may wrap around the
equirectangular seam: the triangle's image on the view sphere (the spherical triangle of its corners'
directions) lies inside the cap about their normalised mean through the farthest corner direction;
the candidates are the pixels whose centres can lie in that cap (its latitude range and longitude
half-width asin(sin radius / cos latitude), split into two boxes across the seam, every longitude
around a pole; for the fisheye the annular sector of angles from the view axis and azimuths), and
triangles whose cap is not narrower than a hemisphere are tested against every pixel. The
intersection test is the same, so the result is exact whatever the projection (tested against brute
force). Depth is the distance from the camera
along the pixel ray (the image meshes sit at distance c*dt along their apparent directions, so this is
the order in which a renderer's z-buffer keeps them). Attributes (UV, light travel time, source
position) are interpolated with the hit's barycentric coordinates, as Blender interpolates corner and
point attributes; extra per-vertex attributes (``RasterMesh.attributes``, e.g. a thin disc's ``redshift``
and ``disc_colour``) are interpolated linearly the same way into ``PixelBuffers.info["attributes"]``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .ragged import group_offsets
from .raytrace import Camera, PixelBuffers


@dataclass
class RasterMesh:
    """One mesh to rasterize.

    positions (V, 3) BU; tris (F, 3); light_travel_time (V,) c*dt in BU; order: image order (int);
    object_id: int; corner_uv (F, 3, 2) or None; face_id (F,) reported per pixel (default: the image
    mesh's source triangle, else the face index); source_position (V, 3) BU or None: the world point
    each vertex shows (interpolated into ``PixelBuffers.point``); attributes: optional dict
    {name: (V,) or (V, K) array} of further per-vertex values, interpolated linearly into
    ``PixelBuffers.info["attributes"][name]`` ((H, W) or (H, W, K), NaN where no triangle of a mesh with
    that attribute is seen).
    """

    positions: np.ndarray
    tris: np.ndarray
    light_travel_time: np.ndarray
    order: int
    object_id: int = 0
    corner_uv: np.ndarray | None = None
    face_id: np.ndarray | None = None
    source_position: np.ndarray | None = None
    attributes: dict | None = None

    @classmethod
    def from_image_mesh(cls, img, object_id: int = 0) -> "RasterMesh":
        """From a ``pipeline.ImageMesh`` (its order, UVs, per-vertex light travel time, source
        triangles and source positions; a disc image's per-vertex ``redshift`` and ``disc_colour`` as
        attributes of those names)."""
        face = getattr(img, "source_tri", None)
        if face is not None and len(face) != len(img.tris):
            face = None
        attrs = {}
        for name in ("redshift", "disc_colour"):
            val = getattr(img, name, None)
            if val is not None and len(val) == len(img.positions):
                attrs[name] = np.asarray(val, np.float64)
        return cls(np.asarray(img.positions, np.float64), np.asarray(img.tris, np.int64),
                   np.asarray(img.light_travel_time, np.float64), int(img.order), int(object_id),
                   img.corner_uv, face, getattr(img, "source_position", None), attrs or None)


def from_images(images, object_id: int = 0) -> list[RasterMesh]:
    """RasterMeshes of the dict {order: ImageMesh} returned by ``pipeline.build_images``."""
    return [RasterMesh.from_image_mesh(img, object_id) for _, img in sorted(images.items()) if len(img.tris)]


def rasterize(meshes, camera: Camera, *, near: float = 1e-6, chunk: int = 1_000_000) -> PixelBuffers:
    """Per-pixel buffers (shape (camera.height, camera.width)) of the nearest triangle of ``meshes``
    (a sequence of :class:`RasterMesh`) along each straight pixel ray; ``near`` (BU) is the view depth
    below which a triangle corner counts as behind a perspective camera (panoramas have no behind). ``info`` holds the number of
    (triangle, pixel) tests ("tests") and the interpolated extra attributes ("attributes", a dict,
    empty if no mesh has any). See the module docstring."""
    H, W = camera.height, camera.width
    dirs = camera.pixel_directions().reshape(-1, 3)
    n_pix = H * W
    best_t = np.full(n_pix, np.inf)
    best_mesh = np.full(n_pix, -1, np.int64)
    best_face = np.full(n_pix, -1, np.int64)
    best_uv = np.zeros((n_pix, 2))  # barycentric (u, v) of corners 1 and 2
    tests = 0
    o = camera.position
    for mi, mesh in enumerate(meshes):
        tris = np.asarray(mesh.tris, np.int64).reshape(-1, 3)
        if not len(tris):
            continue
        pos = np.asarray(mesh.positions, np.float64)
        a, b, c = pos[tris[:, 0]], pos[tris[:, 1]], pos[tris[:, 2]]
        if camera.panoramic:
            box_tri, c0, c1, r0, r1 = _panorama_boxes(camera, pos, tris)
        else:
            box_tri = np.arange(len(tris))
            c0, c1, r0, r1 = _perspective_boxes(camera, pos, tris, near)
        nx = np.maximum(c1 - c0 + 1, 0)
        ny = np.maximum(r1 - r0 + 1, 0)
        count = nx * ny
        sel = np.flatnonzero(count)
        if not sel.size:
            continue
        cum = np.cumsum(count[sel])
        i0 = 0
        while i0 < sel.size:
            base = cum[i0 - 1] if i0 else 0
            i1 = max(int(np.searchsorted(cum, base + chunk, side="right")), i0 + 1)
            f = sel[i0:i1]
            cnt = count[f]
            tot = int(cnt.sum())
            tests += tot
            fb = np.repeat(f, cnt)
            k = group_offsets(cnt)
            px = c0[fb] + k % nx[fb]
            py = r0[fb] + k // nx[fb]
            pix = py * W + px
            fi = box_tri[fb]
            t, u, v, ok = _moller_trumbore(o, dirs[pix], a[fi], b[fi], c[fi])
            ok &= t < best_t[pix]
            if ok.any():
                pix, t, u, v, face = pix[ok], t[ok], u[ok], v[ok], fi[ok]
                order = np.lexsort((t, pix))
                pix, t, u, v, face = pix[order], t[order], u[order], v[order], face[order]
                first = np.ones(len(pix), bool)
                first[1:] = pix[1:] != pix[:-1]
                pix, t, u, v, face = pix[first], t[first], u[first], v[first], face[first]
                better = t < best_t[pix]
                p = pix[better]
                best_t[p] = t[better]
                best_mesh[p] = mi
                best_face[p] = face[better]
                best_uv[p, 0], best_uv[p, 1] = u[better], v[better]
            i0 = i1
    out = PixelBuffers.empty((n_pix,))
    attributes = {}
    for mesh in meshes:
        for name, val in (mesh.attributes or {}).items():
            if name not in attributes:
                attributes[name] = np.full((n_pix,) + np.shape(val)[1:], np.nan)
    hit = best_mesh >= 0
    out.hit[:] = hit
    out.depth[hit] = best_t[hit]
    for mi, mesh in enumerate(meshes):
        pix = np.flatnonzero(best_mesh == mi)
        if not pix.size:
            continue
        face = best_face[pix]
        bary = np.stack([1.0 - best_uv[pix, 0] - best_uv[pix, 1], best_uv[pix, 0], best_uv[pix, 1]], axis=1)
        tri = np.asarray(mesh.tris, np.int64)[face]
        out.bary[pix] = bary
        out.object_id[pix] = mesh.object_id
        out.order[pix] = mesh.order
        out.face[pix] = face if mesh.face_id is None else np.asarray(mesh.face_id)[face]
        out.light_time[pix] = np.einsum("pk,pk->p", bary, np.asarray(mesh.light_travel_time)[tri])
        if mesh.corner_uv is not None:
            out.uv[pix] = np.einsum("pk,pkx->px", bary, np.asarray(mesh.corner_uv)[face])
        if mesh.source_position is not None:
            out.point[pix] = np.einsum("pk,pkx->px", bary, np.asarray(mesh.source_position)[tri])
        for name, val in (mesh.attributes or {}).items():
            val = np.asarray(val, np.float64)
            if val.ndim == 1:
                attributes[name][pix] = np.einsum("pk,pk->p", bary, val[tri])
            else:
                attributes[name][pix] = np.einsum("pk,pkx->px", bary, val[tri].reshape(len(pix), 3, -1))
    out.info = dict(tests=tests, attributes={k: v.reshape((H, W) + v.shape[1:]) for k, v in attributes.items()})
    return out.reshape((H, W))


def _perspective_boxes(camera: Camera, pos, tris, near):
    """(c0, c1, r0, r1) per triangle, inclusive pixel ranges to test for a perspective camera: the
    screen bounding box of the projected corners, or every pixel for a triangle reaching behind the
    camera's ``near`` distance (and none for one entirely behind it or with non-finite corners)."""
    W, H = camera.width, camera.height
    col, row, depth = camera.project(pos)
    front = np.all(depth[tris] > near, axis=1)
    with np.errstate(invalid="ignore"):
        c0 = np.floor(np.nanmin(col[tris], axis=1) - 0.5)
        c1 = np.ceil(np.nanmax(col[tris], axis=1) - 0.5)
        r0 = np.floor(np.nanmin(row[tris], axis=1) - 0.5)
        r1 = np.ceil(np.nanmax(row[tris], axis=1) - 0.5)
    finite = np.all(np.isfinite(pos[tris]), axis=(1, 2))
    c0 = np.where(front, np.clip(c0, 0, W - 1), 0).astype(np.int64)
    c1 = np.where(front, np.clip(c1, -1, W - 1), W - 1).astype(np.int64)
    r0 = np.where(front, np.clip(r0, 0, H - 1), 0).astype(np.int64)
    r1 = np.where(front, np.clip(r1, -1, H - 1), H - 1).astype(np.int64)
    # triangles behind the camera entirely (all corners at depth <= near) are invisible
    behind = np.all(depth[tris] <= near, axis=1)
    drop = ~(finite & ~behind)
    return c0, np.where(drop, c0 - 1, c1), r0, r1


CAP_PAD = 1e-9
"""Relative widening (plus as many radians) of a triangle's bounding cap in a panorama."""


def _panorama_boxes(camera: Camera, pos, tris):
    """(triangle index, c0, c1, r0, r1): inclusive pixel ranges to test for a panoramic camera, one or
    more per triangle. A triangle's image on the view sphere (the directions of its points seen from
    the camera) is the spherical triangle of its corners' directions; it lies inside the cap about the
    normalised mean of those directions through the farthest of them (a cap narrower than a
    hemisphere is convex, so it holds every positive combination of the corners). The cap's pixels
    are bounded by ``Camera.cap_pixel_boxes`` (longitude and latitude ranges, split at the
    equirectangular seam; an annular sector of the fisheye image). Triangles whose cap is not
    narrower than a hemisphere (e.g. around or next to the camera) test every pixel."""
    W, H = camera.width, camera.height
    n = len(tris)
    finite = np.all(np.isfinite(pos[tris]), axis=(1, 2))
    rel = pos - camera.position
    with np.errstate(invalid="ignore", divide="ignore"):
        u = rel / np.linalg.norm(rel, axis=1, keepdims=True)
        ut = u[tris]                        # (T, 3, 3) unit corner directions
        m = ut.sum(axis=1)
        m_len = np.linalg.norm(m, axis=1)
        centre = m / m_len[:, None]
        cos_c = np.einsum("tk,tjk->tj", centre, ut)
        sin_c = np.linalg.norm(np.cross(centre[:, None, :], ut), axis=2)
        radius = np.max(np.arctan2(sin_c, cos_c), axis=1) * (1.0 + CAP_PAD) + CAP_PAD
    capped = finite & np.isfinite(radius) & (radius < 0.5 * np.pi - 1e-3) & (m_len > 1e-6)
    whole = np.flatnonzero(finite & ~capped)
    sel = np.flatnonzero(capped)
    idx, c0, c1, r0, r1 = camera.cap_pixel_boxes(centre[sel], radius[sel])
    tri = np.concatenate([sel[idx], whole])
    z = np.zeros(len(whole), np.int64)
    return (tri, np.concatenate([c0, z]), np.concatenate([c1, z + W - 1]),
            np.concatenate([r0, z]), np.concatenate([r1, z + H - 1]))


def _moller_trumbore(o, d, a, b, c):
    """Ray (origin o (3,), unit directions d (P, 3)) against triangles (a, b, c) (P, 3): distance t
    along the ray (BU), barycentric coordinates (u, v) of b and c, and whether it is a hit (t > 0,
    inside the triangle including its edges)."""
    e1, e2 = b - a, c - a
    pv = np.cross(d, e2)
    det = np.einsum("pi,pi->p", e1, pv)
    tv = o - a
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        u = np.einsum("pi,pi->p", tv, pv) * inv
        qv = np.cross(tv, e1)
        v = np.einsum("pi,pi->p", d, qv) * inv
        t = np.einsum("pi,pi->p", e2, qv) * inv
        ok = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & np.isfinite(t)
    return t, u, v, ok
