"""A moving camera (physical time): accuracy and per-frame cost of the images against a camera at rest.

Scenes: the paper's sphere (0.5 r_s on the 3 r_s orbit) at 45, 170 and 180 degrees of its orbit,
seen from 20 r_s through a 100 degree perspective view (480x270; wide, so that the aberrated
images stay in the frame), r_s = 1 BU. Cameras: at rest, and moving at 0.4 c in the local static
frame with radial and tangential parts, outwards ("out", beta = 0.4 (0.6 e_r + 0.8 e_t)) and
inwards ("in", radial part reversed).

* Images against the reference ray tracer for the same (moving) camera (frame_check.check_frame:
  raytrace.trace with beta, image_pixels with the exact solver's directions aberrated): coverage
  mismatch and screen error of the surface points (pixels, p99 and max).
* 1 + z of the image vertices against the exact value (lutgen.connect's direction at the camera,
  the gravitational shift and the Doppler factor): relative error p99 and max.
* Per-frame cost: pipeline.build_images, best of REPEATS runs (the three cameras in turn), moving over at
  rest; and per image triangle and per covered pixel (the reference's pixels of both orders), so
  that what a moving camera costs for being in motion shows apart from what it costs for showing
  more (a magnified view has more pixels, so more pieces).
* Exact 1 + z (pipeline Settings.exact_redshift: each kept vertex's direction refined to its exact
  connecting ray, lutgen.solver.refine_xi): its 1 + z error, and the frame's cost with it, over the
  same moving frame without it and over the camera at rest.

Usage: ./dev python benchmarks/bench_physical_time.py [output.md]   (default docs/physical_time.md)
"""
import dataclasses
import math
import os
import sys
import time
import warnings

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, HERE)

import bench_accuracy as BA  # noqa: E402
from provenance import code_version  # noqa: E402
from grlens_addon.core import (axis_patch, budget, frame, frame_check, mapping, observer_view, pipeline,  # noqa: E402
                               raytrace, spectrum, visibility)
from lutgen import LUTFamily, connect  # noqa: E402

R_OBS = 20.0
CAM = raytrace.Camera.look_at([R_OBS, 0.0, 0.0], [0.0, 0.0, 0.0], math.radians(100), 480, 270)
B = 0.4
CAMERAS = {"at rest": None,
           "out": B * np.array([0.6, 0.8 * math.cos(0.5), 0.8 * math.sin(0.5)]),
           "in": B * np.array([-0.6, 0.8 * math.cos(0.5), 0.8 * math.sin(0.5)])}


def _redshift_error(images, scene):
    """(p99, max) relative error of the image vertices' 1 + z against the exact value, off the axis, and
    the largest on it (the Einstein rings' vertices: drawn off the ring by the chord outset, see
    axis_patch.limit_images, and shifted as drawn)."""
    errs, ring = [], []
    for order, img in images.items():
        if img.redshift is None or not len(img.positions):
            continue
        plane = mapping.plane_coordinates(img.source_position, scene)
        # a point on the axis (an Einstein ring's limit vertex) is seen at every azimuth: the plane of
        # its image's own direction (taken back to the static frame)
        seen = img.positions - scene.camera
        seen = observer_view.unaberrate(seen / np.linalg.norm(seen, axis=1, keepdims=True), scene.beta)
        across = seen - (seen @ scene.e1)[:, None] * scene.e1
        own = (1.0 if order == 1 else -1.0) * across / np.linalg.norm(across, axis=1, keepdims=True)
        e2 = np.where(plane.on_axis[:, None], own, plane.e2)
        conn = connect(R_OBS, plane.r, plane.phi, order)
        d = observer_view.view_directions(conn.xi, e2, scene.e1, order)
        exact = 1.0 / observer_view.frequency_ratio(plane.r, R_OBS, -d, scene.beta)
        errs.append(np.abs(img.redshift / exact - 1.0))
        ring.append(plane.on_axis)
    if not errs:
        return float("nan"), float("nan"), float("nan")
    e, on = np.concatenate(errs), np.concatenate(ring)
    off = e[~on]
    return (float(np.nanpercentile(off, 99)), float(np.nanmax(off)),
            float(np.nanmax(e[on])) if on.any() else float("nan"))


def _best(fn, n=5):
    """Best of ``n`` timings of ``fn()`` (s)."""
    out = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return min(out)


ANGLES = (45, 170, 179, 180)
REPEATS = 15  # timings per camera, best taken (the machine is shared: a busy moment slows one run)


SATURATED = {"red (1, 0, 0)": (1.0, 0.0, 0.0), "green (0, 1, 0)": (0.0, 1.0, 0.0), "blue (0, 0, 1)": (0.0, 0.0, 1.0),
             "orange (1, 0.4, 0.05)": (1.0, 0.4, 0.05), "grey (0.5, 0.5, 0.5)": (0.5, 0.5, 0.5)}
LUMA = np.array([0.2126, 0.7152, 0.0722])  # linear Rec.709 luminance weights


def _clipping():
    """Rows: saturated colours shifted by g (core.spectrum.shift_matrix, as "grlens Shift by g" draws
    them), their most negative channel before the clip (relative to the shifted colour's largest
    channel), and the luminance the clip adds (relative to the emitted colour's)."""
    rows = []
    for name, rgb in SATURATED.items():
        cells = []
        for g in (0.8, 1.25):
            out = spectrum.shift_matrix(g) @ np.array(rgb)
            low = min(0.0, float(out.min())) / float(out.max())
            added = float(LUMA @ (np.maximum(out, 0.0) - out)) / float(LUMA @ np.array(rgb))
            cells += [f"{low:.3f}", f"{added:.3f}"]
        rows.append(f"| {name} | " + " | ".join(cells) + " |")
    return rows


def _plain_band(table, settings):
    """Rows of the near-ring angles, per camera (at rest / out / in), with the patch's band refined
    (the add-on) and plain (axis_patch.band_shape made to answer None and the narrow band only: the
    band's faces span the grid's azimuth steps, as before the refinement): largest screen error of both
    orders (px), the
    patches' limit vertices and band faces (faces touching the ring or the refined band's vertices,
    one patch per camera here) and image triangles of both orders, refined / plain, and the per-frame
    CPU time (best of REPEATS, the variants in turn, ms) refined / plain; and those figures per angle
    and variant."""
    def patch_counts(src, scene):
        fr = frame.frame_context(scene, table, dataclasses.replace(settings, pixel_angle=CAM.pixel_angle),
                                 CAM.frustum_planes())
        source = frame.prepare_source(fr, src)
        sight = visibility.see(fr, source, frame.map_source(fr, source))
        lim = band = 0
        for p in axis_patch.build_patches(fr, source, sight):
            if len(p.tris):
                extra = np.zeros(len(p.source_position), bool)
                extra[len(p.source_position) - p.band:] = True
                lim += int(p.limit[np.unique(p.tris)].sum())
                band += int((p.limit | extra)[p.tris].any(axis=1).sum())
        return lim, band

    rows, summary, keep, wide = [], {}, axis_patch.band_shape, budget.BAND_WIDE_FACTOR

    def variant(name):  # the band refined (the add-on's), or plain and narrow as before the refinement
        axis_patch.band_shape = keep if name == "refined" else (lambda *a, **k: None)
        budget.BAND_WIDE_FACTOR = wide if name == "refined" else budget.PATCH_BAND_FACTOR

    for angle in (179, 180):
        src = BA.sphere_scene(angle)[0]
        scenes = {n: mapping.Scene(CAM.position, np.zeros(3), BA.R_S, beta=b) for n, b in CAMERAS.items()}
        cells = {}
        runs = {(v, n): [] for v in ("refined", "plain") for n in scenes}
        try:
            for name in ("refined", "plain"):
                variant(name)
                scr = {n: max(frame_check.check_frame([src], sc, table, settings, CAM).metrics["orders"][o]
                              .get("screen_px", {}).get("max", 0.0) for o in (1, 2)) for n, sc in scenes.items()}
                counts = {n: patch_counts(src, sc) for n, sc in scenes.items()}
                tris = {n: sum(len(i.tris) for i in pipeline.build_images(src, sc, table, settings, None,
                                                                          CAM.frustum_planes()).values())
                        for n, sc in scenes.items()}
                cells[name] = dict(scr=scr, lim={n: c[0] for n, c in counts.items()},
                                   band={n: c[1] for n, c in counts.items()}, tris=tris)
            for _ in range(REPEATS):  # both variants in turn (CPU time: the machine is shared)
                for name in ("refined", "plain"):
                    variant(name)
                    for n, sc in scenes.items():
                        t0 = time.process_time()
                        pipeline.build_images(src, sc, table, settings, None, CAM.frustum_planes())
                        runs[(name, n)].append(time.process_time() - t0)
        finally:
            variant("refined")
        for name in cells:
            cells[name]["t"] = {n: min(runs[(name, n)]) for n in scenes}
        r, pl = cells["refined"], cells["plain"]
        row = [f"{angle}"]
        for key, fmt in (("scr", "{:.2f}"), ("lim", "{}"), ("band", "{}"), ("tris", "{}")):
            row.append(" / ".join(fmt.format(r[key][n]) for n in scenes) + " (" + " / ".join(
                fmt.format(pl[key][n]) for n in scenes) + ")")
        row.append(" / ".join(f"{1e3 * r['t'][n]:.1f}" for n in scenes) + " (" + " / ".join(
            f"{1e3 * pl['t'][n]:.1f}" for n in scenes) + ")")
        rows.append("| " + " | ".join(row) + " |")
        print(rows[-1], flush=True)
        summary[angle] = cells
    return rows, summary


def _reading(st, tol, band=None):
    """The reading of the tables, its figures from this run (``st``: per angle, see main; ``band``: per
    angle, _plain_band's figures)."""
    def span(values, fmt="{:.2f}"):
        values = [v for v in values if np.isfinite(v)]
        lo, hi = min(values), max(values)
        return fmt.format(lo) if fmt.format(lo) == fmt.format(hi) else f"{fmt.format(lo)}-{fmt.format(hi)}"

    same = [a for a, v in st.items() if len(set(v["tris"].values())) == 1]
    text = (f"Reading. Per frame the larger of the two moving cameras costs {span([v['ratio'] for v in st.values()])} "
            f"times the camera at rest. ")
    if same:
        text += (f"Where it shows the very same images ({', '.join(map(str, same))} degrees: the same image triangles) "
                 f"that is the moving observer's own overhead, {span([st[a]['ratio'] for a in same])} times: its image "
                 "directions aberrated once, as their points are mapped; the budget's measures in its own view (the "
                 "ring radius from two dot products of the seen direction, without taking it back to the static "
                 "frame); 1 + z of the kept vertices only, its Doppler factor from the drawn directions and its "
                 "gravitational part computed once. ")
    text += (f"Elsewhere the moving cameras show more or less than the camera at rest (`out` sees the hole's side "
             f"magnified, `in` shrunk), and per image triangle they cost "
             f"{span([x for v in st.values() for x in v['per_tri']])} times as much. Their axis patches are sized "
             "by the Einstein ring as they see it (its static radius times the aberration's local scale, which "
             "varies about the ring), by the same rule as the camera at rest's. "
             f"1 + z is within {span([v['zoff'] for v in st.values()], '{:.1e}')} of the exact value off the axis: "
             "the table's direction error (about 1.6e-7 rad here) times beta; given a direction the formula is exact "
             "to rounding (tests/test_moving_observer.py). On the Einstein rings' vertices it is within "
             f"{span([v['zon'] for v in st.values()], '{:.1e}')}: they are drawn off the ring by the chord outset "
             "that makes the ring's polygon cross it, and shifted as drawn. With `Settings.exact_redshift` (the core's "
             "option; the add-on leaves it off: Blender stores the attribute in float32, whose rounding, 6e-8, is "
             "that error's size) every kept vertex's direction is first refined to its exact connecting ray (a secant "
             "iteration on the closed-form swept angle from the table's guess, two to three evaluations per vertex), "
             f"and 1 + z is within {span([v['zexact'] for v in st.values()], '{:.1e}')} "
             f"(on the rings {span([v['zexact_ring'] for v in st.values()], '{:.1e}')}: each drawn ring vertex keeps "
             "its azimuth and goes back onto the ring), for "
             f"{span([v['exact_over_out'] for v in st.values()])} times the moving frame without it "
             f"({span([v['exact_over_rest'] for v in st.values()])} times the camera at rest's).")
    if band is not None:
        def each(key, variant, fmt="{}"):
            return span([v[variant][key][n] for v in band.values() for n in CAMERAS], fmt)

        extra = [v["refined"]["tris"][n] - v["plain"]["tris"][n] for v in band.values() for n in CAMERAS]
        cost = [v["refined"]["t"][n] / v["plain"]["t"][n] for v in band.values() for n in CAMERAS]
        near = {a: max(v["screen"].values()) for a, v in st.items() if a in band}
        within = ("every pixel is placed within" if max(near.values()) <= tol
                  else "single pixels are still placed beyond")
        text += (f" Next to the Einstein ring {within} the {tol:g} px tolerance ("
                 + "; ".join(f"{a} degrees: {e:.2f} px" for a, e in near.items()) + "). The axis patch's band "
                 "next to the ring is drawn by faces with corners on it, which are all one source point, the axis "
                 "crossing: such a face draws its points with the azimuth of its other corners, so each spans at most "
                 "2 PATCH_AIM tol / R of azimuth (R: the ring's radius as seen, in pixels), joined to the grid by a fan "
                 "(axis_patch.band_shape). Without that (the table below) single pixels there were up to "
                 f"{each('scr', 'plain', '{:.2f}')} px off. Per patch it takes {each('lim', 'refined')} limit vertices "
                 f"and {each('band', 'refined')} band faces instead of {each('lim', 'plain')} and "
                 f"{each('band', 'plain')} ({span(extra, '{}')} more image triangles per frame, "
                 f"{span(cost)} times the frame's cost).")
    return text
SKY_BEGIN, SKY_END = "<!-- bench_physical_time_sky: begin -->", "<!-- bench_physical_time_sky: end -->"


def main(out_path):
    warnings.simplefilter("ignore", RuntimeWarning)
    table = LUTFamily().at(R_OBS)
    settings = BA.make_settings(CAM)
    exact_settings = dataclasses.replace(settings, exact_redshift=True)
    rows, cost, exact, st = [], [], [], {}
    for angle in ANGLES:
        src = BA.sphere_scene(angle)[0]
        scenes = {name: mapping.Scene(CAM.position, np.zeros(3), BA.R_S, beta=beta) for name, beta in CAMERAS.items()}
        tris, pixels, screen, zoff, zon = {}, {}, {}, [], []
        for name, beta in CAMERAS.items():
            scene = scenes[name]
            chk = frame_check.check_frame([src], scene, table, settings, CAM)
            images = pipeline.build_images(src, scene, table, settings, None, CAM.frustum_planes())
            tris[name] = sum(len(img.tris) for img in images.values())
            pixels[name] = sum(chk.metrics["orders"][o]["covered_ref"] for o in (1, 2))
            if name == "out":
                out_images = images
            z99, zmax, zring = _redshift_error(images, scene) if beta is not None else (float("nan"),) * 3
            zoff.append(zmax)
            zon.append(zring)
            cells = []
            screen[name] = max(chk.metrics["orders"][o].get("screen_px", {}).get("max", 0.0) for o in (1, 2))
            for order in (1, 2):
                m = chk.metrics["orders"][order]
                sp = m.get("screen_px", {})
                cells += [f"{m['covered_ref']}", f"{m['mismatch']}", f"{sp.get('p99', float('nan')):.3f}",
                          f"{sp.get('max', float('nan')):.3f}"]
            rows.append(f"| {angle} | {name} | " + " | ".join(cells) + f" | {z99:.1e} | {zmax:.1e} | {zring:.1e} |")
        exact_z = [_redshift_error(pipeline.build_images(src, scenes[n], table, exact_settings, None,
                                                         CAM.frustum_planes()), scenes[n]) for n in ("out", "in")]
        runs = {name: [] for name in (*CAMERAS, "out exact")}
        for _ in range(REPEATS):  # the cameras in turn, so that a busy moment of the machine hits all
            for name, scene in (*scenes.items(), ("out exact", scenes["out"])):
                t0 = time.perf_counter()
                pipeline.build_images(src, scene, table, exact_settings if name == "out exact" else settings, None,
                                      CAM.frustum_planes())
                runs[name].append(time.perf_counter() - t0)
        times = {name: float(np.min(r)) for name, r in runs.items()}
        per_tri = {n: times[n] / tris[n] for n in CAMERAS}
        per_px = {n: times[n] / pixels[n] for n in CAMERAS}
        cost.append(f"| {angle} | {1e3 * times['at rest']:.1f} | {1e3 * times['out']:.1f} | {1e3 * times['in']:.1f} | "
                    f"{max(times['out'], times['in']) / times['at rest']:.2f} | "
                    f"{tris['at rest']} / {tris['out']} / {tris['in']} | "
                    f"{per_tri['out'] / per_tri['at rest']:.2f} / {per_tri['in'] / per_tri['at rest']:.2f} | "
                    f"{pixels['at rest']} / {pixels['out']} / {pixels['in']} | "
                    f"{per_px['out'] / per_px['at rest']:.2f} / {per_px['in'] / per_px['at rest']:.2f} |")
        n = sum(len(img.positions) for img in out_images.values())
        t_ex = times["out exact"]
        exact.append(f"| {angle} | {n} | {1e3 * times['out']:.1f} | {1e3 * t_ex:.1f} | {t_ex / times['out']:.2f} | "
                     f"{t_ex / times['at rest']:.2f} | {max(z[1] for z in exact_z):.1e} | "
                     f"{np.nanmax([z[2] for z in exact_z]):.1e} |")
        st[angle] = dict(ratio=max(times["out"], times["in"]) / times["at rest"], tris=tris,
                         per_tri=(per_tri["out"] / per_tri["at rest"], per_tri["in"] / per_tri["at rest"]),
                         zoff=np.nanmax(zoff), zon=np.nanmax(zon), exact_over_out=t_ex / times["out"],
                         exact_over_rest=t_ex / times["at rest"], zexact=max(z[1] for z in exact_z),
                         zexact_ring=np.nanmax([z[2] for z in exact_z]), screen=screen)
        print(rows[-3:], cost[-1], exact[-1], flush=True)
    band, band_figures = _plain_band(table, settings)
    text = "\n".join([
        "# A moving camera: accuracy and cost", "",
        f"<!-- generated by benchmarks/bench_physical_time.py on {code_version()} -->", "",
        "From `benchmarks/bench_physical_time.py` (see its docstring): the paper's sphere seen from 20 r_s through a "
        "100 degree view (480x270), the camera at rest or moving at 0.4 c in its local static frame (radial "
        "and tangential parts; `out`: away from the hole, `in`: towards it). Images against the reference ray "
        "tracer for the same camera: pixels covered (reference), coverage mismatch, screen error of the surface "
        "points (pixels); 1 + z of the image vertices against the exact value (relative; off the axis, and on "
        "the Einstein rings).", "",
        "| orbit angle (deg) | camera | o1 covered | o1 mismatch | o1 screen p99 | o1 screen max | o2 covered | "
        "o2 mismatch | o2 screen p99 | o2 screen max | 1+z p99 | 1+z max | 1+z max on the ring |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|", *rows, "",
        f"Per-frame cost of the core (`pipeline.build_images`, best of {REPEATS} taken in turn, ms), the larger moving "
        "one over the camera at rest per frame, and per image triangle and per covered pixel (triangles of both "
        "image meshes and the reference's pixels of both orders, at rest / out / in; each moving camera's cost per "
        "triangle, or per pixel, over the camera at rest's, out / in):", "",
        "| orbit angle (deg) | at rest | out | in | ratio per frame | image triangles | ratio per triangle | "
        "covered pixels | ratio per pixel |", "|---|---|---|---|---|---|---|---|---|", *cost, "",
        "Exact 1 + z (`Settings.exact_redshift`: the kept vertices' directions refined to their exact connecting "
        "rays, `lutgen.solver.refine_xi`), for the `out` camera: image vertices, its frame without and with it "
        "(ms, best of the same runs), with it over without it and over the camera at rest, and the largest "
        "relative error of 1 + z of both moving cameras with it, off the axis and on the Einstein rings:", "",
        "| orbit angle (deg) | image vertices | frame (ms) | with exact 1 + z (ms) | over without | over at rest | "
        "1+z max | 1+z max on the ring |", "|---|---|---|---|---|---|---|---|", *exact, "",
        _reading(st, settings.max_error_px, band_figures), "",
        "The same next to the ring with the band refined (the add-on) and, in brackets, plain (narrow, each of its "
        "faces spanning one of the grid's azimuth steps; axis_patch.band_shape answering None), at rest / out / in: "
        "largest screen error of both orders (px), the patch's limit vertices and band faces (those touching the "
        "ring or the refined band's vertices), image triangles of both orders, and the per-frame CPU time (best "
        f"of {REPEATS}, the two in turn, ms):", "",
        "| orbit angle (deg) | screen max | limit vertices | band faces | image triangles | frame (ms) |",
        "|---|---|---|---|---|---|", *band, "",
        "## Saturated colours", "",
        "A shifted colour is M(g) rgb (core.spectrum): the colour of the smoothest spectrum of rgb, shifted. A "
        "saturated colour's smoothest spectrum dips below zero, so its shift can leave the gamut: a channel "
        "becomes negative. \"grlens Shift by g\" (surfaces) and the sky's shift group clip negative channels to 0 and leave "
        "the others as they are; channels above 1 are kept (scene-linear light, for the view transform). The "
        "choice: a renderer cannot emit negative light, and clipping one channel keeps the hue of the others, "
        "where pulling the colour towards grey at equal luminance would wash every channel out; the price is "
        "light added: little for most colours, but a pure primary's smoothest spectrum has deep negative lobes, "
        "so a shifted pure green is mostly clipped (blue-shifted, the clip adds several times its luminance): "
        "such colours are better kept a little inside the gamut when physical time colours them. The most "
        "negative channel (over the largest) and the luminance the clip adds (over "
        "the emitted colour's), at g = 0.8 (red-shifted) and 1.25 (blue-shifted):", "",
        "| colour | g = 0.8: negative | luminance added | g = 1.25: negative | luminance added |",
        "|---|---|---|---|---|", *_clipping(), ""])
    sky = ""
    if os.path.exists(out_path):  # the lensed world's section (bench_physical_time_sky.py) stays
        old = open(out_path).read()
        if SKY_BEGIN in old and SKY_END in old:
            sky = old[old.index(SKY_BEGIN):old.index(SKY_END) + len(SKY_END)] + "\n"
    with open(out_path, "w") as f:
        f.write(text + ("\n" + sky if sky else ""))
    print(text)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else os.path.join(HERE, "..", "docs", "physical_time.md"))
