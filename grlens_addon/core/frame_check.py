"""Check one frame of the polygon method against the per-pixel reference ray tracer (no bpy).

For the source meshes of a frame, the observer camera and the hole, :func:`check_frame` renders

* the reference: one exact null geodesic per pixel (``raytrace.trace``), and
* the polygon method: ``pipeline.build_images`` of every source (the images the add-on draws, built
  for this camera's pixel size), rasterized at pixel centres (``rasterize``),

and compares them per pixel (``image_metrics.compare``): coverage mismatch, UV error, light-travel-
time error, and the screen error (how far from each pixel the surface point drawn there truly
appears, through the exact connecting geodesic). :func:`passes` gives both renders' light travel
time and image order (the add-on's AOVs), object index and UV, and the mismatch as named 2-D arrays;
:func:`write_passes` stores them in one OpenEXR file with channels ``<layer>.<pass>.<channel>``
(layers ``Reference``, ``grlens``, ``Check``), as Blender names multilayer EXR channels.

Units: positions, r_s and light travel times c*dt in Blender units (BU); times in seconds; pixel
errors in pixels of the check's camera. Passes are (height, width) arrays, row 0 at the top.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from . import image_metrics, mapping, pipeline, rasterize, raytrace

@dataclass
class FrameCheck:
    """The result of :func:`check_frame`: ``reference`` and ``polygon`` (raytrace.PixelBuffers of the
    camera's shape), ``metrics`` (image_metrics.compare: per order 1, 2 and "all"), the time of the
    reference (``reference_seconds``) and of build_images for all sources (``polygon_seconds``),
    the sources' ``names`` (object index i is names[i]) and the camera's resolution."""

    reference: raytrace.PixelBuffers
    polygon: raytrace.PixelBuffers
    metrics: dict
    reference_seconds: float
    polygon_seconds: float
    names: list = field(default_factory=list)
    resolution: tuple = (0, 0)

    @property
    def speedup(self) -> float:
        return self.reference_seconds / self.polygon_seconds if self.polygon_seconds > 0 else float("inf")

    def summary(self) -> str:
        """One line: coverage mismatch, screen and UV errors (p99), light-travel-time error, times."""
        m = self.metrics["orders"]["all"]
        mis = m["mismatch_frac"]
        parts = [f"{self.resolution[0]}x{self.resolution[1]}: "
                 + (f"{100 * mis:.2f}% of the covered pixels differ ({m['mismatch']} of {m['covered_ref']})"
                    if np.isfinite(mis) else "nothing covered in the reference")]
        scr = m.get("screen_px", {}).get("p99", float("nan"))
        if np.isfinite(scr):
            parts.append(f"drawn points off by {scr:.3g} px (p99)")
        uv = m["uv_px"]["p99"]
        if np.isfinite(uv):
            parts.append(f"UV off by {uv:.3g} px (p99)")
        lt = m["lt_rel"]["p99"]
        if np.isfinite(lt):
            parts.append(f"light travel time within {lt:.2g} (p99, relative)")
        parts.append(f"reference {self.reference_seconds:.2f} s, grlens {1000 * self.polygon_seconds:.1f} ms "
                     f"({self.speedup:.0f}x)")
        return "; ".join(parts)


def check_frame(sources, scene: mapping.Scene, lut, settings: pipeline.Settings, camera: raytrace.Camera,
                names=None, light=None, discs=None) -> FrameCheck:
    """Reference and polygon renders of ``sources`` (pipeline.SourceMesh, world space, BU) seen by
    ``camera`` (whose position must be ``scene.camera``) and their comparison (see the module
    docstring). ``settings.pixel_angle`` is replaced by the camera's own, so the polygon images are
    built for the check's resolution; ``light`` (pipeline.Light) and ``discs`` (one
    pipeline.DiscEmitter or None per source) are passed to build_images as the add-on does."""
    sources = list(sources)
    if not sources:
        raise ValueError("nothing to check: no source mesh")
    if not np.allclose(camera.position, scene.camera, rtol=0.0, atol=1e-9 * max(1.0, float(np.abs(scene.camera).max()))):
        raise ValueError("the check's camera is not the scene's observer")
    names = list(names) if names is not None else [f"object {i}" for i in range(len(sources))]
    discs = list(discs) if discs is not None else [None] * len(sources)
    settings = dataclasses.replace(settings, pixel_angle=camera.pixel_angle)
    tri_scene = raytrace.TriangleScene.concatenate([(s.positions, s.tris, s.corner_uv) for s in sources])
    t0 = time.perf_counter()
    ref = raytrace.trace(tri_scene, camera, scene.hole, scene.r_s)
    t_ref = time.perf_counter() - t0
    planes = camera.frustum_planes()
    meshes, t_poly = [], 0.0
    for i, (src, disc) in enumerate(zip(sources, discs)):
        t0 = time.perf_counter()
        images = pipeline.build_images(src, scene, lut, settings, light, planes, disc)
        t_poly += time.perf_counter() - t0
        meshes += rasterize.from_images(images, object_id=i)
    poly = rasterize.rasterize(meshes, camera) if meshes else raytrace.PixelBuffers.empty((camera.height, camera.width))
    metrics = image_metrics.compare(
        ref, poly, image_pixels=lambda points, order: raytrace.image_pixels(points, camera, scene.hole, scene.r_s, order))
    return FrameCheck(ref, poly, metrics, t_ref, t_poly, names, (camera.width, camera.height))


def passes(check: FrameCheck) -> dict:
    """{channel name: (height, width) float32}: per render (layers ``Reference`` and ``grlens``) the
    light travel time (c*dt, BU; 0 where nothing is hit, as the add-on's AOV), the image order (0
    where nothing is hit), the object index (-1 where nothing is hit) and the UV (NaN where none);
    layer ``Check``: mismatch (1 where exactly one render shows an object in image order 1 or 2, the
    pixels the coverage mismatch counts)."""
    out = {}
    for layer, buf in (("Reference", check.reference), ("grlens", check.polygon)):
        hit = np.asarray(buf.hit, bool)
        out[f"{layer}.light_travel_time.V"] = np.where(hit, buf.light_time, 0.0).astype(np.float32)
        out[f"{layer}.image_order.V"] = np.where(hit, buf.order, 0).astype(np.float32)
        out[f"{layer}.object_index.V"] = np.where(hit, buf.object_id, -1).astype(np.float32)
        out[f"{layer}.UV.U"] = np.asarray(buf.uv[..., 0], np.float32)
        out[f"{layer}.UV.V"] = np.asarray(buf.uv[..., 1], np.float32)
    out["Check.mismatch.V"] = image_metrics.mismatch_mask(check.reference, check.polygon).astype(np.float32)
    return out


def write_passes(path, check: FrameCheck) -> None:
    """Write :func:`passes` and the check's figures (header attributes ``grlens:<key>``) to the
    OpenEXR file ``path`` (its directory must exist; replaced atomically)."""
    from lutgen.exr_io import write_exr

    m = check.metrics["orders"]["all"]
    meta = {"check": "grlens frame check against the reference ray tracer",
            "summary": check.summary(),
            "objects": ", ".join(f"{i}: {n}" for i, n in enumerate(check.names)),
            "mismatch_fraction": float(m["mismatch_frac"]),
            "screen_error_p99_px": float(m.get("screen_px", {}).get("p99", float("nan"))),
            "uv_error_p99_px": float(m["uv_px"]["p99"]),
            "light_travel_time_error_p99_rel": float(m["lt_rel"]["p99"]),
            "reference_seconds": float(check.reference_seconds),
            "grlens_seconds": float(check.polygon_seconds)}
    write_exr(path, passes(check), meta)
