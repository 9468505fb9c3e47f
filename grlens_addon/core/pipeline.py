"""One object, one frame: source triangles -> first- and second-order image meshes (numpy only).

The method's outline (seed 000, section 3), one stage a module:

==================  ======================  ==================================================
stage               module                  decides
==================  ======================  ==================================================
frame context       frame                   the frame's table, camera model and error budget
                                            (budget); the cleaned source and what stages share
map                 mapping                 where a point's images are (the only way into the
                                            table of connecting rays)
visibility          visibility              silhouettes, back faces, the frustum, sub-pixel images
axis patches        axis_patch              the surface around where the axis crosses it
level plan          level_plan              how finely each edge is cut, which triangles are cut
subdivide           subdivision             the pieces, and their vertices' images
cull                culling                 which pieces are dropped, and every count of it
assemble            assemble                the image mesh and its attributes (UVs, GR light,
                                            the disc's colour)
==================  ======================  ==================================================

The Blender layer only extracts a :class:`SourceMesh` and uploads the :class:`ImageMesh` results.
Units: positions in Blender units (BU); light travel time as a length c*dt in BU (c = 1).
"""
from __future__ import annotations

import concurrent.futures
import threading
from dataclasses import dataclass, field

import numpy as np

from . import axis_patch, culling, interior, level_plan, subdivision, visibility
from .assemble import ImageMesh, assemble, empty_image
from .frame import (DiscEmitter, Light, Settings, SourceMesh, Source, beside, clean_source,  # noqa: F401
                    frame_context, map_source, prepare_source, threads_for)
from .mapping import Scene
from .visibility import is_closed_outward, winding_number  # noqa: F401 (public names)

__all__ = ["SourceMesh", "Settings", "Light", "DiscEmitter", "ImageMesh", "clean_source", "build_images",
           "is_closed_outward", "winding_number", "Cancelled", "Progress", "STAGE_WEIGHTS"]


class Cancelled(Exception):
    """A build was stopped by its progress hook (:class:`Progress.cancel`), between two stages or at a
    checkpoint inside a long one (frame.Frame.checkpoint); it returns nothing, so no partial image
    exists."""


STAGE_WEIGHTS = {"prepare": 0.05, "map": 0.26, "visibility": 0.01, "patches": 0.005, "probes": 0.21,
                 "plan": 0.15, "cut": 0.005, "cull": 0.015, "refine": 0.005, "assemble": 0.06}
"""Share of a build's time each stage takes (per order for plan, cut, cull, refine and assemble), for
the progress fractions: the shares that keep the fraction shown closest to the time on closed UV
spheres of 200k and 1M triangles beside the hole at 1920x1080, both orders, to the viewport's
tolerance, the larger of the two differences made smallest (from the median shares
benchmarks/profile_dense.py --preview prints; the shares move with the view, the tolerance and
the mesh: probes take a quarter of the 200k sphere's build and 1 % of the 1M one's, assembly 4 % and
a quarter;
benchmarks/bench_background.py prints how far the fraction strays from the time). Only the
fractions' spacing depends on them; the first split beside the axis (when there is one) runs map and
visibility again within their shares."""


class Progress:
    """Progress and cancellation of one build, shared between the thread that runs it and the one that
    watches it (thread-safe: a lock-free read of two fields, a threading.Event).

    The core calls it between stages, ``progress(stage, fraction)`` with the stage about to run and
    the fraction of the build done (0 to 1, never decreasing), and inside long stages between the
    blocks of their passes (the stage running, the fraction within its share); it raises
    :class:`Cancelled` there once :meth:`cancel` was called. ``callback(stage, fraction)``, if given, is called at each step too (in
    the building thread)."""

    def __init__(self, callback=None):
        self._cancel = threading.Event()
        self.stage, self.fraction, self.callback = "", 0.0, callback

    def cancel(self) -> None:
        self._cancel.set()

    @property
    def cancelled(self) -> bool:
        return self._cancel.is_set()

    def __call__(self, stage: str, fraction: float) -> None:
        if self._cancel.is_set():
            raise Cancelled(stage)
        self.stage, self.fraction = stage, max(self.fraction, float(fraction))
        if self.callback is not None:
            self.callback(stage, self.fraction)


class _Steps:
    """The progress fractions of one build's stages (STAGE_WEIGHTS over the stages this build runs)."""

    PER_ORDER = ("plan", "cut", "cull", "refine", "assemble")

    def __init__(self, progress, n_orders: int):
        self.progress = progress
        w = STAGE_WEIGHTS
        self.total = sum(v for k, v in w.items() if k not in self.PER_ORDER) + n_orders * sum(
            w[k] for k in self.PER_ORDER)
        self.done = self.start = 0.0
        self.stage = ""

    def __call__(self, stage: str) -> None:
        """Before ``stage``: report the fraction done and check for cancellation; count its share."""
        if self.progress is None:
            return
        self.stage, self.start = stage, self.done
        self.progress(stage, min(self.done / self.total, 1.0))
        self.done += STAGE_WEIGHTS.get(stage, 0.0)

    def inside(self, part: float | None = None) -> None:
        """A cancellation point inside the stage running (Frame.checkpoint: between the blocks or
        passes of a long stage), reporting the fraction at the stage's start, or ``part`` (0 to 1) of
        the way through its share."""
        if self.progress is not None:
            part = 0.0 if part is None else min(max(float(part), 0.0), 1.0)
            self.progress(self.stage, min((self.start + part * (self.done - self.start)) / self.total, 1.0))

    def check(self, stage: str) -> None:
        """A cancellation point inside a stage's share (the fraction stays)."""
        if self.progress is not None:
            self.progress(stage, min(self.done / self.total, 1.0))

    def finish(self) -> None:
        if self.progress is not None:
            self.progress("done", 1.0)


def build_images(src: SourceMesh, scene: Scene, lut, settings: Settings, light: Light | None = None,
                 frustum_planes=None, disc: DiscEmitter | None = None, progress=None) -> dict[int, ImageMesh]:
    """Image meshes {order: ImageMesh} of the requested orders for one source mesh.

    ``lut``: the table of connecting rays for the camera's radius (lutgen.LUT, WideLUT or a
    LUTFamily's table); ``frustum_planes`` (K, 4), rows (n, d) with n . x + d >= 0 inside (world
    space, BU), or None for a camera without one (a panorama): image triangles outside are dropped,
    and source triangles whose corners and edge midpoints all map outside one plane are not cut. An
    image whose extent on the view sphere is below one pixel (``settings.pixel_angle``) is not built
    if it is a second-order image (reported as ``below_pixel``); first-order images are always built,
    so small objects stay visible. ``light``: GR illumination; ``disc``: the source is a thin disc.

    ``progress``: None, or a callable ``progress(stage, fraction)`` (e.g. a :class:`Progress`) called
    before every stage with its name and the fraction of the build done (non-decreasing, 0 to 1;
    ("done", 1.0) last), and again inside long stages (the same name, a fraction within the stage's
    share: Frame.checkpoint); it may raise (:class:`Cancelled`) to stop the build there: nothing is
    returned then, and nothing the caller holds has changed (the stages build new arrays)."""
    frame = frame_context(scene, lut, settings, light, frustum_planes)
    steps = _Steps(progress, len(frame.orders))
    if progress is not None:
        frame.check = steps.inside  # cancellation inside long stages too (Frame.checkpoint)
    st = run_stages(frame, src, steps)
    if st.source.empty:
        steps.finish()
        return {o: empty_image(o, _report_of_nothing(st.source)) for o in frame.orders}
    out = {}
    orders = list(st.orders.items())
    order_keys = [o for o, _ in orders]
    # both orders at once when a dense mesh makes it worth a thread (frame.THREADS; each order's image
    # its own arrays: the same result however the two are scheduled)
    pool = _assembly_pool(frame, st)
    later = None
    if pool is not None and len(orders) == 2:
        o, s = orders.pop()
        later = (o, pool.submit(assemble, frame, st.source, s.pieces, s.keep, st.patches, s.patch_keep, s.report,
                                o, disc))
    done_here = False
    try:
        for o, s in orders:
            steps("assemble")
            out[o] = assemble(frame, st.source, s.pieces, s.keep, st.patches, s.patch_keep, s.report, o, disc)
        done_here = True
    finally:
        if later is not None:  # waited for even when this thread's order failed or was cancelled; then
            if done_here:      # this thread's exception is the one raised (the worker's is dropped)
                got = later[1].result()
            else:
                concurrent.futures.wait([later[1]])
    if later is not None:
        steps("assemble")
        out[later[0]] = got
    steps.finish()
    return {o: out[o] for o in order_keys}


ASSEMBLE_THREADS_MIN = 1 << 16
"""Source triangles from which both orders' image meshes are assembled at once (frame.THREADS)."""


def _assembly_pool(frame, st):
    """The worker thread (frame.beside) for one order's assembly, or None: a small mesh, or a light
    whose table is not safe from two threads (frame.threads_for)."""
    if len(st.source.tris) < ASSEMBLE_THREADS_MIN:
        return None
    if frame.light is not None and not threads_for(frame.light.lut):
        return None
    return beside()


@dataclass
class OrderStages:
    """One order's stage outputs: the level plan, the pieces (None below a pixel), the culling's keep
    mask (None below a pixel), its patch-face masks and its report."""

    plan: level_plan.LevelPlan
    pieces: subdivision.Pieces | None
    keep: np.ndarray | None
    patch_keep: list
    report: culling.CullReport


@dataclass
class Stages:
    """The outputs of the stages before assembly for one source in one frame: the prepared source
    (after the first split, if any), the map stage's images of its vertices, its visibility, its
    axis patches, the probed edge midpoints and {order: OrderStages} (empty for an empty source)."""

    source: Source
    coarse: object = None
    sight: object = None
    patches: list = field(default_factory=list)
    probes: object = None
    orders: dict = field(default_factory=dict)


def run_stages(frame, src: SourceMesh, steps=None) -> Stages:
    """The method's stages for ``src`` in ``frame``, in order, up to the culling (build_images then
    assembles the images; tests and benchmarks read the stages' outputs).

    Refine (interior.refine): the kept pieces are measured where the renderer interpolates them, and
    those beyond the budget are cut further, within Settings.max_triangles image triangles (each
    order's report says what is left: CullReport.over_budget, refined, triangle_bound).

    ``steps``: the build's progress (build_images' _Steps), or None."""
    steps = steps or _Steps(None, 0)
    steps("prepare")
    source = prepare_source(frame, src)
    if source.empty:
        return Stages(source)
    steps("map")
    coarse = map_source(frame, source)
    steps("visibility")
    sight = visibility.see(frame, source, coarse)
    levels = level_plan.presplit(frame, source, coarse, sight)
    if levels is not None:  # a first split next to the axis; the stages run again on the smaller triangles
        steps.check("presplit")
        source = _split(frame, source, levels)
        steps.check("map")
        coarse = map_source(frame, source)
        steps.check("visibility")
        sight = visibility.see(frame, source, coarse)
    st = _stages(frame, source, coarse, sight, steps)
    # refine: pieces beyond the budget inside are cut further (interior.refine), within max_triangles
    sampled = interior.sampled_sources(frame, source) if frame.budget.active else None
    counts = {o: 0 if s.keep is None else int(np.count_nonzero(s.keep)) for o, s in st.orders.items()}
    for order, s in st.orders.items():
        steps("refine")
        room = frame.settings.max_triangles - sum(n for o, n in counts.items() if o != order)
        s.pieces, s.keep, beyond, bound, added = interior.refine(frame, source, s.pieces, s.keep, order, room, sampled)
        if s.keep is not None:
            kept = int(np.count_nonzero(s.keep))
            s.report.kept += kept - counts[order]
            counts[order] = kept
        s.report.refined, s.report.over_budget, s.report.triangle_bound = added, beyond, bound
    return st


def _stages(frame, source, coarse, sight, steps=None) -> Stages:
    """One pass of the stages after the map stage: patches, level plan, cut and cull per order."""
    steps = steps or _Steps(None, 0)
    steps("patches")
    patches = axis_patch.build_patches(frame, source, sight)
    steps("probes")
    probes = level_plan.probe_edges(frame, source, coarse)
    st = Stages(source, coarse, sight, patches, probes)
    for order in frame.orders:
        steps("plan")
        plan = level_plan.plan_levels(frame, source, coarse, sight, patches, probes, order)
        steps("cut")
        pieces = None if plan.below_pixel else subdivision.cut(frame, source, plan, coarse.images[order])
        steps("cull")
        keep, patch_keep, report = culling.cull_pieces(frame, source, coarse, plan, pieces, patches, order)
        st.orders[order] = OrderStages(plan, pieces, keep, patch_keep, report)
    return st


def _split(frame, source: Source, levels) -> Source:
    """The prepared source cut at the per-edge ``levels`` (level_plan.presplit), its
    triangles traced back to the caller's."""
    sub = subdivision.subdivide(source.positions, source.tris, source.edges, levels)
    mesh = source.mesh

    def carried(corner_values):
        return None if corner_values is None else sub.corner_values(corner_values)

    fine = SourceMesh(sub.positions, sub.tris, carried(mesh.corner_uv), mesh.material[sub.source_tri],
                      carried(mesh.corner_normals))
    out = prepare_source(frame, fine, origin=source.origin[sub.source_tri], n_bad=source.n_bad)
    out.presplit = len(sub.tris) - len(source.tris)
    return out


def _report_of_nothing(source: Source) -> culling.CullReport:
    """The report of a source without a valid triangle."""
    rep = culling.CullReport()
    rep.extra["bad_source_triangles"] = source.n_bad
    return rep
