"""Luminet's thin disc: the polygon method (mesh images) against the analytic per-pixel image (seed 002).

Scene (sample_scenes/luminet.py, without bpy): r_s = 1 BU, hole at the origin, an annulus 3-15 r_s
(72 rings, denser near r_in as t^2, 256 segments, quads split into two triangles) in the local xy
plane, rotated by 90 - 84.5 = 5.5 deg about +y (its axis tilted from +z towards the camera: inclination
84.5 deg), prograde gas; a static camera at (120, 0, 0) r_s looking at the hole with +z up and a 6 deg
vertical field of view.

* polygon method: ``pipeline.build_images`` with ``DiscEmitter(mode="bolometric")`` (both orders, the
  add-on's default settings and frustum planes; LUT ``lutgen.build_lut(120, 1.05, 16, 256, 512)``,
  not counted per frame), rasterized per order with ``grlens_addon.core.rasterize`` (pixel centres;
  per-vertex 1 + z, disc colour and source position interpolated linearly, as Blender does);
* reference: ``lutgen.thin_disc.disc_crossings`` at the same pixel centres (each pixel's unit
  direction from ``raytrace.Camera.pixel_directions`` turned into (theta, alpha) in the sky basis
  e_o = hole -> camera, e_right, e_up = the camera's x, y axes);
* metrics per order: coverage mismatch (pixels where exactly one of them shows that order, over the
  reference's covered pixels), relative error of 1 + z, of the observed flux F / (1 + z)^4 (from the
  interpolated colour, and recomputed from the interpolated radius and 1 + z), radius error (r_s; the
  interpolated source point), all over the pixels both cover.

Usage: ./dev python benchmarks/bench_thin_disc.py [--resolutions 320x180,640x360] [--repeat 3] [--write]
"""
from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

from provenance import code_version  # noqa: E402
from grlens_addon.core import mapping, pipeline, rasterize, raytrace  # noqa: E402
from grlens_addon.core import thin_disc as core_disc  # noqa: E402
from lutgen import build_lut  # noqa: E402
from lutgen import thin_disc as ref_disc  # noqa: E402

R_S = 1.0  # BU
R_OBS = 120.0  # r_s
INCLINATION_DEG = 84.5
R_IN, R_OUT = 3.0, 15.0
RINGS, SEGMENTS = 72, 256
FOV_DEG = 6.0
LUT_ARGS = (R_OBS, 1.05, 16.0, 256, 512)  # r_obs, r_min, r_max, n_r, n_phi
DEFAULTS = dict(max_tess_level=64, tess_a=5.0, tess_b=0.75, cull_ratio=8.0)  # the add-on's defaults
DOC = os.path.join(ROOT, "docs", "thin_disc_accuracy.md")
PNG = os.path.join(ROOT, "docs", "images", "thin_disc_compare.png")


# --------------------------------------------------------------------------------------------------
# Scene
# --------------------------------------------------------------------------------------------------
def disc_rotation(inclination_deg=INCLINATION_DEG) -> np.ndarray:
    """Rotation (3, 3) of the disc object: about +y by 90 deg - inclination (Blender's rotation_euler
    (0, b, 0)), so the local +z axis tilts towards +x (the camera)."""
    b = math.radians(90.0 - inclination_deg)
    c, s = math.cos(b), math.sin(b)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def annulus(r_in=R_IN, r_out=R_OUT, rings=RINGS, segments=SEGMENTS, inclination_deg=INCLINATION_DEG):
    """(world positions (N, 3) BU, triangles (T, 3), disc axis (3,)) of sample_scenes/luminet.py's
    annulus: radii r_in + (r_out - r_in) (i / (rings - 1))^2, ``segments`` vertices per ring, each quad
    split into two triangles (counter-clockwise about the local +z)."""
    t = (np.arange(rings) / (rings - 1)) ** 2
    radii = (r_in + (r_out - r_in) * t) * R_S
    ang = 2.0 * np.pi * np.arange(segments) / segments
    local = np.stack([radii[:, None] * np.cos(ang)[None, :], radii[:, None] * np.sin(ang)[None, :],
                      np.zeros((rings, segments))], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(rings - 1), np.arange(segments), indexing="ij")
    i, j = i.ravel(), j.ravel()
    jn = (j + 1) % segments
    v00, v01, v11, v10 = i * segments + j, i * segments + jn, (i + 1) * segments + jn, (i + 1) * segments + j
    tris = np.concatenate([np.stack([v00, v01, v11], 1), np.stack([v00, v11, v10], 1)])
    rot = disc_rotation(inclination_deg)
    return local @ rot.T, tris, rot[:, 2]


def camera(width, height, r_obs=R_OBS):
    return raytrace.Camera.look_at([r_obs * R_S, 0.0, 0.0], [0.0, 0.0, 0.0], math.radians(FOV_DEG), width, height)


def make_settings(cam, **over):
    return pipeline.Settings(**dict(DEFAULTS, pixel_angle=cam.pixel_angle, **over))


# --------------------------------------------------------------------------------------------------
# The two images
# --------------------------------------------------------------------------------------------------
def sky_geometry(cam, axis, hole=np.zeros(3)):
    """(theta, alpha) (H, W) of the camera's pixel centres and the inclination (rad) of the disc axis,
    in lutgen.thin_disc's sky basis: e_o from the hole to the camera, e_right and e_up the camera's
    x and y axes (the camera must look at the hole). theta = angle from the hole's direction (-e_o),
    alpha = position angle from e_right towards e_up. The axis must lie in the (e_o, e_up) plane with
    a positive e_up component (then it is cos(i) e_o + sin(i) e_up)."""
    e_o = cam.position - hole
    e_o = e_o / np.linalg.norm(e_o)
    e_right, e_up = cam.rotation[:, 0], cam.rotation[:, 1]
    if abs(e_right @ e_o) > 1e-12 or abs(e_up @ e_o) > 1e-12:
        raise ValueError("the camera must look at the hole")
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    if abs(a @ e_right) > 1e-12 or not a @ e_up > 0:
        raise ValueError("the disc axis must lie in the (e_o, e_up) half plane above the hole")
    d = cam.pixel_directions()
    theta = np.arccos(np.clip(-(d @ e_o), -1.0, 1.0))
    alpha = np.arctan2(d @ e_up, d @ e_right)
    return theta, alpha, math.atan2(a @ e_up, a @ e_o)


def reference_image(cam, axis, r_in=R_IN, r_out=R_OUT, orders=(1, 2)):
    """({order: lutgen.thin_disc.DiscCrossing}, seconds) at the camera's pixel centres."""
    t0 = time.perf_counter()
    theta, alpha, inc = sky_geometry(cam, axis)
    r_obs = float(np.linalg.norm(cam.position)) / R_S
    parts = {k: ref_disc.disc_crossings(r_obs, inc, theta, alpha, k, r_in=r_in, r_out=r_out) for k in orders}
    return parts, time.perf_counter() - t0


def polygon_images(positions, tris, axis, cam, lut, settings, repeat=1):
    """(images {order: ImageMesh}, best build_images seconds)."""
    scene = mapping.Scene(cam.position, np.zeros(3), R_S)
    src = pipeline.SourceMesh(positions, tris)
    disc = pipeline.DiscEmitter(axis=np.asarray(axis), mode="bolometric", r_in=R_IN)
    planes = cam.frustum_planes()
    best, images = math.inf, None
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        images = pipeline.build_images(src, scene, lut, settings, frustum_planes=planes, disc=disc)
        best = min(best, time.perf_counter() - t0)
    return images, best


def rasterize_orders(images, cam):
    """{order: dict(hit, r, one_plus_z, flux, flux_rz, point)} per-order rasterization (each order on its
    own: the reference sees through the transparent disc, so orders are compared separately).
    flux: the interpolated disc colour (bolometric grey, exposure 1) times F_peak (units of F0);
    flux_rz: F(r) / (1 + z)^4 from the interpolated radius and 1 + z."""
    _, f_peak = core_disc.page_thorne_peak(R_IN)
    out = {}
    for order, img in sorted(images.items()):
        H, W = cam.height, cam.width
        if not len(img.tris):
            nan = np.full((H, W), np.nan)
            out[order] = dict(hit=np.zeros((H, W), bool), r=nan, one_plus_z=nan, flux=np.zeros((H, W)),
                              flux_rz=np.zeros((H, W)), point=np.full((H, W, 3), np.nan), tris=0)
            continue
        buf = rasterize.rasterize([rasterize.RasterMesh.from_image_mesh(img)], cam)
        attrs = buf.info["attributes"]
        r = np.linalg.norm(buf.point, axis=-1) / R_S
        z = attrs["redshift"]
        with np.errstate(invalid="ignore", divide="ignore"):
            flux_rz = core_disc.observed_flux(r, z, R_IN)
        out[order] = dict(hit=buf.hit, r=r, one_plus_z=z, flux=np.where(buf.hit, attrs["disc_colour"][..., 0] * f_peak, 0.0),
                          flux_rz=np.where(buf.hit, flux_rz, 0.0), point=buf.point, tris=len(img.tris))
    return out


# --------------------------------------------------------------------------------------------------
# Metrics
# --------------------------------------------------------------------------------------------------
def _stats(x):
    x = np.asarray(x, np.float64)
    x = x[np.isfinite(x)]
    if not x.size:
        return dict(p50=np.nan, p99=np.nan, max=np.nan, n=0)
    return dict(p50=float(np.percentile(x, 50)), p99=float(np.percentile(x, 99)), max=float(x.max()), n=int(x.size))


def compare_order(poly: dict, ref: ref_disc.DiscCrossing) -> dict:
    """Metrics of one order (see the module docstring)."""
    ref_hit = np.asarray(ref.hit, bool)
    hit = poly["hit"]
    both = hit & ref_hit
    mism = hit ^ ref_hit
    with np.errstate(invalid="ignore", divide="ignore"):
        z_err = np.abs(poly["one_plus_z"] / ref.one_plus_z - 1.0)[both]
        f_err = np.abs(poly["flux"] / ref.flux - 1.0)[both]
        frz_err = np.abs(poly["flux_rz"] / ref.flux - 1.0)[both]
        fmax = float(ref.flux[ref_hit].max()) if ref_hit.any() else np.nan
        f_abs = (np.abs(poly["flux"] - ref.flux) / fmax)[both]
        r_err = np.abs(poly["r"] - ref.r)[both]
    return dict(covered_ref=int(ref_hit.sum()), covered_poly=int(hit.sum()), mismatch=int(mism.sum()),
                only_poly=int((hit & ~ref_hit).sum()), only_ref=int((~hit & ref_hit).sum()),
                mismatch_frac=mism.sum() / max(int(ref_hit.sum()), 1), both=int(both.sum()),
                z=_stats(z_err), flux=_stats(f_err), flux_rz=_stats(frz_err), flux_of_max=_stats(f_abs),
                r=_stats(r_err), flux_sum_ratio=float(poly["flux"].sum() / ref.flux.sum()) if ref_hit.any() else np.nan)


def side_brightness(flux, cam):
    """(mean observed flux on the camera's left half, on its right half) of an image (H, W)."""
    W = cam.width
    return float(flux[:, : W // 2].sum()), float(flux[:, W - W // 2:].sum())


def orientation_check(poly, ref, n=8, seed=1):
    """Rows (order, row, col, reference r, |source point| of the polygon image) at ``n`` random pixels
    both cover, per order: the two must describe the same disc point."""
    rng = np.random.default_rng(seed)
    rows = []
    for k in sorted(ref):
        both = np.argwhere(poly[k]["hit"] & ref[k].hit)
        for j, i in both[rng.choice(len(both), size=min(n, len(both)), replace=False)] if len(both) else []:
            rows.append((k, int(j), int(i), float(ref[k].r[j, i]), float(poly[k]["r"][j, i]),
                         float(ref[k].one_plus_z[j, i]), float(poly[k]["one_plus_z"][j, i])))
    return rows


def vertex_check(images, cam, axis):
    """{order: dict(n, r=stats, z=stats)}: every image vertex against the reference evaluated in its own
    apparent direction (no interpolation): |r_reference - |source point|| (r_s) and the relative
    difference of 1 + z. This isolates the LUT and the per-vertex physics from the rasterization."""
    e_o = cam.position / np.linalg.norm(cam.position)
    e_right, e_up = cam.rotation[:, 0], cam.rotation[:, 1]
    _, _, inc = sky_geometry(cam, axis)
    out = {}
    for k, img in sorted(images.items()):
        if not len(img.positions):
            continue
        d = img.positions - cam.position
        d /= np.linalg.norm(d, axis=1)[:, None]
        theta = np.arccos(np.clip(-(d @ e_o), -1.0, 1.0))
        alpha = np.arctan2(d @ e_up, d @ e_right)
        c = ref_disc.disc_crossings(np.linalg.norm(cam.position) / R_S, inc, theta, alpha, k, r_in=R_IN,
                                    r_out=R_OUT)
        r = np.linalg.norm(img.source_position, axis=1) / R_S
        with np.errstate(invalid="ignore"):
            out[k] = dict(n=len(r), no_ref=int(np.sum(~np.isfinite(c.r))), r=_stats(np.abs(c.r - r)),
                          z=_stats(np.abs(img.redshift / c.one_plus_z - 1.0)))
    return out


def run_case(width, height, lut, repeat=3, rings=RINGS, segments=SEGMENTS, **settings_over):
    cam = camera(width, height)
    positions, tris, axis = annulus(rings=rings, segments=segments)
    settings = make_settings(cam, **settings_over)
    images, t_poly = polygon_images(positions, tris, axis, cam, lut, settings, repeat)
    t0 = time.perf_counter()
    poly = rasterize_orders(images, cam)
    t_ras = time.perf_counter() - t0
    t_ref = math.inf
    for _ in range(max(1, repeat)):
        ref, t = reference_image(cam, axis)
        t_ref = min(t_ref, t)
    metrics = {k: compare_order(poly[k], ref[k]) for k in (1, 2)}
    return dict(cam=cam, poly=poly, ref=ref, metrics=metrics, t_poly=t_poly, t_ref=t_ref, t_ras=t_ras,
                n_src=len(tris), images=images, vertices=vertex_check(images, cam, axis))


# --------------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------------
def _g(x, fmt=".1e"):
    return "nan" if not np.isfinite(x) else format(x, fmt)


def tables(cases) -> list[str]:
    lines = ["## Time per frame", "",
             "| resolution | source triangles | order-1 / order-2 image triangles | build_images [ms] | "
             "analytic reference [ms] | rasterize [s] | culled as Einstein ring (order 1 / 2) |",
             "|---|---|---|---|---|---|---|"]
    for (w, h), c in cases.items():
        ring = [c["images"][k].report.einstein_ring for k in (1, 2)]
        lines.append(f"| {w}x{h} | {c['n_src']} | {c['poly'][1]['tris']} / {c['poly'][2]['tris']} | "
                     f"{1000 * c['t_poly']:.0f} | {1000 * c['t_ref']:.0f} | {c['t_ras']:.2f} | {ring[0]} / {ring[1]} |")
    lines += ["", "## Coverage", "",
              "| resolution | order | covered (reference) | covered (polygon) | both | only polygon | only reference | "
              "mismatch / covered | sum of flux polygon / reference |", "|---|---|---|---|---|---|---|---|---|"]
    for (w, h), c in cases.items():
        for k in (1, 2):
            m = c["metrics"][k]
            lines.append(f"| {w}x{h} | {k} | {m['covered_ref']} | {m['covered_poly']} | {m['both']} | {m['only_poly']} | "
                         f"{m['only_ref']} | {100 * m['mismatch_frac']:.2f}% | {m['flux_sum_ratio']:.4f} |")
    lines += ["", "## Errors over the pixels both cover (p50 / p99 / max)", "",
              "| resolution | order | 1+z rel. | flux rel. (colour) | flux rel. (F(r)/(1+z)^4) | "
              "flux error / max flux | radius [r_s] |", "|---|---|---|---|---|---|---|"]
    for (w, h), c in cases.items():
        for k in (1, 2):
            m = c["metrics"][k]

            def t(s, fmt=".1e"):
                return f"{_g(s['p50'], fmt)} / {_g(s['p99'], fmt)} / {_g(s['max'], fmt)}"

            lines.append(f"| {w}x{h} | {k} | {t(m['z'])} | {t(m['flux'])} | {t(m['flux_rz'])} | {t(m['flux_of_max'])} | "
                         f"{t(m['r'], '.4f')} |")
    return lines


def brightness_lines(cases) -> list[str]:
    lines = ["## Approaching side", "",
             "Summed observed flux (both orders) on the left half (approaching gas) over the right half "
             "(receding gas):", "", "| resolution | polygon | reference |", "|---|---|---|"]
    for (w, h), c in cases.items():
        pl, pr = side_brightness(c["poly"][1]["flux"] + c["poly"][2]["flux"], c["cam"])
        rl, rr = side_brightness(c["ref"][1].flux + c["ref"][2].flux, c["cam"])
        lines.append(f"| {w}x{h} | {pl / pr:.3f} | {rl / rr:.3f} |")
    return lines


def check_lines(case) -> list[str]:
    lines = ["## Same disc on both sides", "",
             "Every image vertex against the reference evaluated in the vertex's own apparent direction (no "
             "interpolation: the LUT and the per-vertex 1 + z alone), p50 / p99 / max:", "",
             "| order | image vertices | radius [r_s] | 1+z rel. |", "|---|---|---|---|"]
    for k, v in case["vertices"].items():
        lines.append(f"| {k} | {v['n']} | {_g(v['r']['p50'])} / {_g(v['r']['p99'])} / {_g(v['r']['max'])} | "
                     f"{_g(v['z']['p50'])} / {_g(v['z']['p99'])} / {_g(v['z']['max'])} |")
    lines += ["",
             "Random pixels both cover: the reference's crossing radius and the radius of the source point the "
             "polygon image shows there (interpolated), and 1 + z of both:", "",
             "| order | row | column | r reference [r_s] | r polygon [r_s] | 1+z reference | 1+z polygon |",
             "|---|---|---|---|---|---|---|"]
    for k, j, i, rr, rp, zr, zp in orientation_check(case["poly"], case["ref"], n=4):
        lines.append(f"| {k} | {j} | {i} | {rr:.4f} | {rp:.4f} | {zr:.5f} | {zp:.5f} |")
    return lines


def worst_lines(case, n=8) -> list[str]:
    """The pixels with the largest difference of the observed flux (both orders summed)."""
    poly = case["poly"][1]["flux"] + case["poly"][2]["flux"]
    ref = case["ref"][1].flux + case["ref"][2].flux
    d = np.abs(poly - ref)
    fmax = float(ref.max())
    W = case["cam"].width
    lines = [f"## Largest flux differences ({W}x{case['cam'].height})", "",
             "| row | column | abs. difference / max flux | order: drawn by polygon / reference, r polygon / reference "
             "[r_s], 1+z polygon / reference |", "|---|---|---|---|"]
    for f in np.argsort(d.ravel())[::-1][:n]:
        j, i = divmod(int(f), W)
        parts = []
        for k in (1, 2):
            p, r = case["poly"][k], case["ref"][k]
            if p["hit"][j, i] or r.hit[j, i]:
                parts.append(f"{k}: {int(p['hit'][j, i])}/{int(r.hit[j, i])}, {p['r'][j, i]:.3f}/{r.r[j, i]:.3f}, "
                             f"{p['one_plus_z'][j, i]:.4f}/{r.one_plus_z[j, i]:.4f}")
        lines.append(f"| {j} | {i} | {d[j, i] / fmax:.3f} | {'; '.join(parts)} |")
    return lines


def save_png(path, case):
    """polygon | reference | |difference| of the observed flux (both orders summed: a transparent disc)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    poly = case["poly"][1]["flux"] + case["poly"][2]["flux"]
    ref = case["ref"][1].flux + case["ref"][2].flux
    diff = np.abs(poly - ref)
    vmax = float(np.percentile(ref[ref > 0], 99.9))
    h, w = ref.shape
    fig, axes = plt.subplots(1, 3, figsize=(3 * w / 100 * 0.75, h / 100 * 0.75 + 0.45), dpi=100)
    for ax, img, title, vm, cmap in ((axes[0], poly, "polygon method (build_images + rasterize)", vmax, "inferno"),
                                     (axes[1], ref, "analytic reference (lutgen.thin_disc)", vmax, "inferno"),
                                     (axes[2], diff, f"|difference| (x10 scale: white = {vmax / 10:.1e} F0)",
                                      vmax / 10, "gray")):
        ax.imshow(img, cmap=cmap, vmin=0.0, vmax=vm, interpolation="nearest")
        ax.set_title(title, fontsize=8)
        ax.set_axis_off()
    fig.tight_layout(pad=0.2)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--resolutions", default="320x180,640x360")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--write", action="store_true", help=f"write {os.path.relpath(DOC, ROOT)} and the PNG")
    args = ap.parse_args(argv)
    res = [tuple(int(v) for v in s.split("x")) for s in args.resolutions.split(",")]
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    lut = build_lut(*LUT_ARGS)
    t_lut = time.perf_counter() - t0
    cases = {r: run_case(r[0], r[1], lut, args.repeat) for r in res}
    load1 = os.getloadavg()[0]
    biggest = cases[max(cases, key=lambda r: r[0] * r[1])]
    head = [
        "# Thin disc: polygon method against the analytic per-pixel image", "",
        f"Generated by `./dev python benchmarks/bench_thin_disc.py --write` ({platform.machine()}, {os.cpu_count()} CPUs, "
        f"numpy {np.__version__}; {code_version()}; load average {load0:.1f} at the start, {load1:.1f} at the end: "
        "on a shared machine the times vary by tens of percent); do not edit by hand.", "",
        f"Scene: Luminet's disc of `sample_scenes/luminet.py` without Blender: r_s = 1 BU, annulus {R_IN:g}-{R_OUT:g} r_s "
        f"({RINGS} rings denser near r_in, {SEGMENTS} segments, {2 * (RINGS - 1) * SEGMENTS} triangles), axis tilted "
        f"{90 - INCLINATION_DEG:g} deg from +z towards the camera (inclination {INCLINATION_DEG:g} deg), prograde gas, "
        f"static camera at {R_OBS:g} r_s on +x looking at the hole, +z up, vertical field of view {FOV_DEG:g} deg, "
        "one sample per pixel centre.", "",
        f"* polygon method: `pipeline.build_images(..., disc=DiscEmitter(axis, mode=\"bolometric\"))`, both orders, "
        f"settings {DEFAULTS} with the camera's pixel angle and the add-on's frustum planes; LUT "
        f"`build_lut{LUT_ARGS}` built in {t_lut:.2f} s (not counted per frame); best of {args.repeat}. Each order "
        "is rasterized on its own by `grlens_addon.core.rasterize` (per-vertex `redshift`, `disc_colour` and source "
        "position interpolated linearly, as Blender interpolates attributes);",
        "* reference: `lutgen.thin_disc.disc_crossings` at the same pixel centres (closed-form crossing radius "
        "with Jacobi's elliptic functions, 1 + z in the local static frame, Page-Thorne flux); each pixel's "
        "direction from `raytrace.Camera` becomes (theta, alpha) in the sky basis e_o = hole -> camera, e_right, "
        "e_up = the camera's x and y axes; the disc axis is cos(i) e_o + sin(i) e_up;",
        "* metrics per order: coverage mismatch = pixels where exactly one of them shows the disc in that order, "
        "over the reference's covered pixels; relative errors of 1 + z and of the observed flux F / (1 + z)^4 "
        "(from the interpolated grey colour, i.e. what the render shows, and recomputed from the interpolated radius "
        "and 1 + z), the flux error over the image's maximum flux, and the radius error |r_polygon - r_reference| "
        "(r_s; r_polygon = |interpolated source point|), over the pixels both cover. The relative flux error "
        "is large only where the flux itself vanishes (next to r_in, where F -> 0).", ""]
    body = (tables(cases) + [""] + brightness_lines(cases) + [""] + check_lines(biggest) + [""]
            + worst_lines(biggest))
    text = "\n".join(head + body) + "\n"
    print(text)
    if args.write:
        with open(DOC, "w") as f:
            f.write(text + "\n![polygon | reference | difference](images/thin_disc_compare.png)\n\n"
                    "`images/thin_disc_compare.png`: observed flux of both orders summed (the reference's "
                    "transparent disc), polygon method | analytic reference | absolute difference, "
                    f"{biggest['cam'].width}x{biggest['cam'].height}.\n")
        save_png(PNG, biggest)
        print(f"wrote {DOC} and {PNG} ({os.path.getsize(PNG) / 1024:.0f} KB)")


if __name__ == "__main__":
    main()
