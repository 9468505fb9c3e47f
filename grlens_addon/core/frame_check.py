"""Check one frame of the polygon method against the per-pixel reference ray tracer (no bpy).

For the source meshes of a frame, the observer camera and the hole, :func:`check_frame` renders

* the reference: one exact null geodesic per pixel (``raytrace.trace``), and
* the polygon method: ``pipeline.build_images`` of every source (the images the add-on draws, built
  for this camera's pixel size), rasterized at pixel centres (``rasterize``),

and compares them per pixel (``image_metrics.compare``): coverage mismatch, UV error, light-travel-
time error, and the screen error (how far from each pixel the surface point drawn there truly
appears, through the exact connecting geodesic). With a model of the lensed sky (``sky``: the
direction at infinity of the ray leaving the camera in each direction, as the add-on's lensed world
shows it) also the sky (``image_metrics.compare_sky``): its angular error per pixel against the
reference's ``PixelBuffers.sky``, the shadow (pixels where exactly one says the ray falls in) and the
checker edges of a checkered world. :func:`passes` gives both renders' light travel time and image
order (the add-on's AOVs), object index, UV and sky direction, and the mismatches as named 2-D
arrays; :func:`write_passes` stores them in one OpenEXR file with channels
``<layer>.<pass>.<channel>`` (layers ``Reference``, ``grlens``, ``Check``), as Blender names
multilayer EXR channels.

The camera may be perspective or panoramic (``raytrace.Camera.kind``: equirectangular, fisheye
equidistant); panoramas have no frustum, so build_images gets ``frustum_planes=None`` (nothing is
culled by the view).

Units: positions, r_s and light travel times c*dt in Blender units (BU); times in seconds; pixel
errors in pixels of the check's camera (angles divided by ``Camera.pixel_angle`` for the sky);
sky directions are unit world vectors. Passes are (height, width) arrays, row 0 at the top.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from . import image_metrics, mapping, observer_view, pipeline, rasterize, raytrace

@dataclass
class FrameCheck:
    """The result of :func:`check_frame`: ``reference`` and ``polygon`` (raytrace.PixelBuffers of the
    camera's shape), ``metrics`` (image_metrics.compare: per order 1, 2 and "all"; with a sky model
    also "sky": image_metrics.compare_sky), the time of the reference (``reference_seconds``) and of
    build_images for all sources (``polygon_seconds``), the sources' ``names`` (object index i is
    names[i]), the camera's resolution, the sky model's directions per pixel (``sky``, (height,
    width, 3), NaN where it says the ray falls in or the pixel has no ray; None without a model), its
    time (``sky_seconds``), the camera's ``pixel_angle`` (rad) and ``rays`` ((height, width) bool: the
    pixels that have a ray, all but a fisheye's outside its circle)."""

    reference: raytrace.PixelBuffers
    polygon: raytrace.PixelBuffers
    metrics: dict
    reference_seconds: float
    polygon_seconds: float
    names: list = field(default_factory=list)
    resolution: tuple = (0, 0)
    sky: np.ndarray | None = None
    sky_seconds: float = 0.0
    pixel_angle: float = float("nan")
    rays: np.ndarray | None = None

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
        sky = self.metrics.get("sky")
        if sky is not None:
            parts.append(f"sky off by {sky['sky_angle_px']['p99']:.3g} px (p99), shadow differs on "
                         f"{sky['shadow_mismatch']} px, checker edges off by {sky['checker_per_edge']:.3g} px")
        parts.append(f"reference {self.reference_seconds:.2f} s, grlens {1000 * self.polygon_seconds:.1f} ms "
                     f"({self.speedup:.0f}x)")
        return "; ".join(parts)


def lensed_world_sky(hole, r_s, beta=None):
    """The add-on's lensed world as a sky model for :func:`check_frame`: (directions (N, 3) unit
    world, camera position (3,) BU) -> escape directions (N, 3), the node group's mapping (the
    escape table of the camera's radius, rounded to 7 digits as the world update rounds it, read
    linearly in s; ``lutgen.EscapeTable.directions``) in float64. ``hole`` (3,) and ``r_s`` in BU;
    ``beta`` (3,; units of c): the camera's velocity in its local static frame, whose directions are
    taken back to that frame first (observer_view.unaberrate), as the node group does."""
    from lutgen.escape import escape_table

    hole = np.asarray(hole, dtype=float)
    tables = {}

    def sky(d, cam):
        e1 = np.asarray(cam, dtype=float) - hole
        key = mapping.round_radius(np.linalg.norm(e1) / r_s)
        if key not in tables:
            tables[key] = escape_table(key)
        if beta is not None:
            d = observer_view.unaberrate(np.asarray(d, dtype=float), beta)
        return tables[key].directions(d, e1 / np.linalg.norm(e1))

    return sky


def check_frame(sources, scene: mapping.Scene, lut, settings: pipeline.Settings, camera: raytrace.Camera,
                names=None, light=None, discs=None, sky=None) -> FrameCheck:
    """Reference and polygon renders of ``sources`` (pipeline.SourceMesh, world space, BU) seen by
    ``camera`` (perspective or panoramic; its position must be ``scene.camera``) and their comparison
    (see the module docstring). ``settings.pixel_angle`` is replaced by the camera's own, so the
    polygon images are built for the check's resolution; ``light`` (pipeline.Light) and ``discs`` (one
    pipeline.DiscEmitter or None per source) are passed to build_images as the add-on does, with the
    camera's frustum planes (None for a panorama). ``sky``: optional model of the lensed world, a
    function (directions (N, 3) unit world, camera position (3,) BU) -> (N, 3) unit world directions at
    infinity, NaN rows for rays that fall in; it is asked for every pixel that has a ray and compared
    with the reference's sky (``metrics["sky"]``). A moving observer (``scene.view_beta``) is checked as
    such: the reference traces its aberrated pixel rays (raytrace.trace)."""
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
    ref = raytrace.trace(tri_scene, camera, scene.hole, scene.r_s, beta=scene.view_beta)
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
        ref, poly, image_pixels=lambda points, order: raytrace.image_pixels(points, camera, scene.hole, scene.r_s, order,
                                                                            beta=scene.view_beta),
        column_period=camera.column_period)
    model, t_sky = None, 0.0
    dirs = camera.pixel_directions()
    rays = np.all(np.isfinite(dirs), axis=-1)
    if sky is not None:
        model = np.full(dirs.shape, np.nan)
        t0 = time.perf_counter()
        got = np.asarray(sky(dirs[rays], camera.position.copy()), np.float64)
        t_sky = time.perf_counter() - t0
        if got.shape != (int(rays.sum()), 3):
            raise ValueError(f"the sky model returned shape {got.shape}, expected {(int(rays.sum()), 3)}")
        model[rays] = got
        metrics["sky"] = image_metrics.compare_sky(ref, model, camera.pixel_angle, rays)
    return FrameCheck(ref, poly, metrics, t_ref, t_poly, names, (camera.width, camera.height), model, t_sky,
                      camera.pixel_angle, rays)


def passes(check: FrameCheck) -> dict:
    """{channel name: (height, width) float32}: per render (layers ``Reference`` and ``grlens``) the
    light travel time (c*dt, BU; 0 where nothing is hit, as the add-on's AOV), the image order (0
    where nothing is hit), the object index (-1 where nothing is hit) and the UV (NaN where none);
    ``Reference.sky_direction.X/Y/Z``: the unit world direction at infinity of the reference's rays
    that meet nothing and escape (NaN elsewhere), ``grlens.sky_direction.X/Y/Z`` the sky model's (with
    one; NaN where it says the ray falls in; on every pixel with a ray, objects or not); layer
    ``Check``: mismatch (1 where exactly one render shows an object in image order 1 or 2, the pixels
    the coverage mismatch counts) and, with a sky model, sky_error (the angle between the two sky
    directions in pixels, NaN where either has none) and shadow_mismatch (1 where exactly one says a
    ray that meets nothing falls in)."""
    out = {}
    for layer, buf in (("Reference", check.reference), ("grlens", check.polygon)):
        hit = np.asarray(buf.hit, bool)
        out[f"{layer}.light_travel_time.V"] = np.where(hit, buf.light_time, 0.0).astype(np.float32)
        out[f"{layer}.image_order.V"] = np.where(hit, buf.order, 0).astype(np.float32)
        out[f"{layer}.object_index.V"] = np.where(hit, buf.object_id, -1).astype(np.float32)
        out[f"{layer}.UV.U"] = np.asarray(buf.uv[..., 0], np.float32)
        out[f"{layer}.UV.V"] = np.asarray(buf.uv[..., 1], np.float32)
    for layer, sky in (("Reference", check.reference.sky), ("grlens", check.sky)):
        if sky is not None:
            for i, ax in enumerate("XYZ"):
                out[f"{layer}.sky_direction.{ax}"] = np.asarray(sky[..., i], np.float32)
    out["Check.mismatch.V"] = image_metrics.mismatch_mask(check.reference, check.polygon).astype(np.float32)
    if check.sky is not None:
        ref = check.reference
        model_fell = ~np.all(np.isfinite(check.sky), axis=-1)
        has_ray = check.rays if check.rays is not None else np.ones(ref.shape, bool)
        out["Check.sky_error.V"] = image_metrics.sky_error_px(ref, check.sky, check.pixel_angle).astype(np.float32)
        out["Check.shadow_mismatch.V"] = (has_ray & ~ref.hit & (ref.fell != model_fell)).astype(np.float32)
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
    sky = check.metrics.get("sky")
    if sky is not None:
        meta.update({"sky_error_p50_px": float(sky["sky_angle_px"]["p50"]),
                     "sky_error_p99_px": float(sky["sky_angle_px"]["p99"]),
                     "sky_error_max_px": float(sky["sky_angle_px"]["max"]),
                     "shadow_mismatch_pixels": int(sky["shadow_mismatch"]),
                     "checker_mismatch_per_edge_pixel": float(sky["checker_per_edge"]),
                     "sky_seconds": float(check.sky_seconds)})
    write_exr(path, passes(check), meta)
