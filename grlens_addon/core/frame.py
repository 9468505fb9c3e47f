"""The frame context and the prepared source: what every stage of the core reads, built once.

:func:`frame_context` gathers, once per frame: the scene (camera, hole, r_s), the map stage's table
(mapping.Mapper: the table may depend on the camera's radius, as the add-on's family of tables does),
the settings, the camera model (perspective, or a panorama without a frustum; its pixel size as an
angle), the light of GR illumination and the error budget (budget.Budget). :func:`prepare_source`
cleans one source mesh and computes what several stages need about it: its edges, its points'
plane and axis coordinates, its triangles' size on the view sphere and which of them the axis may
cross, and (on demand) whether it is a closed surface.

Units: positions in Blender units (BU), angles in radians; r in units of r_s.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from . import mapping, observer_view, subdivision
from .budget import Budget


@dataclass
class SourceMesh:
    """Evaluated source geometry in world space.

    positions (N, 3) BU; tris (T, 3) vertex indices; corner_uv (T, 3, 2) or None (float64, or float32 as
    Blender stores them: a whole source triangle's image keeps them as they are, interpolated ones
    are computed in float64); material (T,) slot indices; corner_normals (T, 3, 3) unit normals in world space or None.
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
    max_error_px: float | None = 0.25  # the error budget's tolerance, pixels (with pixel_angle; see budget.py)
    max_triangles: int = 1_000_000  # image triangles of one object (all orders) the refine step may make
    exact_redshift: bool = False  # 1 + z from exact connecting rays (to ~1e-12), not the table's (~1e-7 * beta)


@dataclass
class Light:
    """A point light for GR illumination: position (BU), intensity I0, and the LUT for its radius."""

    position: np.ndarray
    intensity: float
    lut: object


@dataclass
class DiscEmitter:
    """A source that is a thin accretion disc of gas on circular geodesics (seed 002): its image
    vertices get the redshift factor 1 + z and a colour from the Page-Thorne flux F(r) / (1 + z)^4.

    axis: unit vector (world) of the disc's angular momentum (prograde gas turns counter-clockwise
    about it; retrograde with ``prograde`` False); mode: "bolometric" or "blackbody";
    r_in: inner edge in r_s (>= 3, the ISCO); t_peak: emitted temperature (K) at the flux maximum;
    exposure: scale of the colour (1: the emitted maximum flux gives 1).
    """

    axis: np.ndarray
    prograde: bool = True
    mode: str = "bolometric"
    r_in: float = 3.0
    t_peak: float = 1.0e4
    exposure: float = 1.0


CAMERA_KINDS = ("PERSP", "EQUIRECTANGULAR", "FISHEYE_EQUIDISTANT")


@dataclass(frozen=True)
class CameraModel:
    """What the core needs of the observer camera: ``kind`` (one of CAMERA_KINDS), ``pixel_angle``
    (radians per pixel on the view sphere: a perspective camera's smaller field over its pixels, a
    panorama's angular resolution; None: no screen-space bounds) and ``frustum_planes`` (K, 4) rows
    (n, d), n . x + d >= 0 inside (world space, BU), or None (a panorama sees every direction)."""

    kind: str = "PERSP"
    pixel_angle: float | None = None
    frustum_planes: np.ndarray | None = None

    def __post_init__(self):
        if self.kind not in CAMERA_KINDS:
            raise ValueError(f"camera kind must be one of {CAMERA_KINDS}, got {self.kind!r}")


@dataclass
class Frame:
    """One frame's context (see the module docstring): ``scene``, ``map`` (mapping.Mapper),
    ``settings``, ``camera`` (CameraModel), ``budget`` (budget.Budget) and ``light`` (or None)."""

    scene: mapping.Scene
    map: mapping.Mapper
    settings: Settings
    camera: CameraModel
    budget: Budget
    light: Light | None = None
    check: object = field(default=None, repr=False)

    def checkpoint(self, part: float | None = None) -> None:
        """A cancellation point inside a stage: calls ``check`` (set by pipeline.build_images: the build's
        progress, which raises pipeline.Cancelled once the build was cancelled), if any, with ``part``
        (0 to 1: about how far through the stage its work is; None: not known)."""
        if self.check is not None:
            self.check(part)

    @property
    def orders(self) -> tuple:
        return tuple(self.settings.orders)

    @property
    def planes(self) -> np.ndarray | None:
        """The frustum planes, or None (no frustum: nothing is culled against one)."""
        return self.camera.frustum_planes


def frame_context(scene: mapping.Scene, table, settings: Settings, light: Light | None = None,
                  frustum_planes=None, kind: str = "PERSP") -> Frame:
    """The :class:`Frame` of ``scene`` seen through ``table`` (built for the camera's radius) with
    ``settings`` (their pixel_angle is the camera's pixel size) and ``frustum_planes`` (or None)."""
    planes = None if frustum_planes is None or not len(frustum_planes) else np.asarray(frustum_planes, np.float64)
    camera = CameraModel(kind, settings.pixel_angle, planes)
    return Frame(scene, mapping.Mapper(scene, table), settings, camera,
                 Budget(settings.pixel_angle, settings.max_error_px), light)


@dataclass
class Source:
    """A cleaned source mesh and what the stages share about it.

    mesh: the cleaned SourceMesh; origin (T,): each triangle's index into the caller's tris; n_bad:
    triangles dropped by the cleaning; presplit: triangles added by a first split (level_plan); edges
    (subdivision.Edges); plane (mapping.PlaneCoordinates) of the vertices; axis_xyz: their
    observer_view.axis_coordinates (BU); circumference (T,): the triangles' undistorted circumference on the
    view sphere; edge_length (E,): the edges' lengths (BU); near_axis (T,): those the axis may cross (observer_view.near_axis); crossings: where the axis
    crosses the surface (axis_patch.crossings_of, found when first needed)."""

    mesh: SourceMesh
    origin: np.ndarray
    n_bad: int
    edges: subdivision.Edges | None = None
    plane: mapping.PlaneCoordinates | None = None
    axis_xyz: tuple | None = None
    circumference: np.ndarray | None = None
    near_axis: np.ndarray | None = None
    presplit: int = 0
    edge_length: np.ndarray | None = field(default=None, repr=False)
    crossings: list | None = field(default=None, repr=False)  # axis_patch.crossings_of
    _xy: np.ndarray | None = field(default=None, repr=False)

    @property
    def positions(self) -> np.ndarray:
        return self.mesh.positions

    @property
    def tris(self) -> np.ndarray:
        return self.mesh.tris

    @property
    def empty(self) -> bool:
        return len(self.mesh.tris) == 0

    @property
    def xy(self) -> np.ndarray:
        """(N, 2) the axis coordinates x, y of the vertices (stacked once, when needed)."""
        if self._xy is None:
            self._xy = np.column_stack(self.axis_xyz[:2])
        return self._xy


def prepare_source(frame: Frame, src: SourceMesh, origin=None, n_bad: int = 0) -> Source:
    """The :class:`Source` of ``src``: cleaned (:func:`clean_source`), with its shared quantities.
    ``origin``/``n_bad``: for a mesh that is itself a split of the caller's (level_plan's first split),
    the caller's triangle of each of its triangles and the triangles the first cleaning dropped."""
    mesh, bad, kept = _clean(src)
    origin = kept if origin is None else np.asarray(origin)[kept]
    out = Source(mesh, origin, n_bad + bad)
    if out.empty:
        return out
    scene = frame.scene
    out.edges = _edges_of(mesh.tris)
    out.plane = mapping.plane_coordinates(mesh.positions, scene)
    out.axis_xyz = observer_view.axis_coordinates(mesh.positions, scene.camera, scene.hole)
    frame.checkpoint(0.5)
    # one pass over the edges for two measures: the chords of the undistorted view and the lengths (BU)
    chord, out.edge_length = edge_lengths(
        [observer_view.unit_directions(mesh.positions, scene.camera, scene.view_beta), mesh.positions],
        out.edges.verts, lambda q: frame.checkpoint(0.5 + 0.35 * q))
    out.circumference = circumference_from_edges(chord, out.edges.of_tri)
    out.near_axis = observer_view.near_axis(mesh.positions, mesh.tris, scene.camera, scene.hole, axis_xyz=out.axis_xyz)
    return out


def clean_source(src: SourceMesh) -> tuple[SourceMesh, int]:
    """Drop triangles with out-of-range (negative or >= N) indices, non-finite or repeated vertices.
    Returns (cleaned, number dropped)."""
    cleaned, n_bad, _ = _clean(src)
    return cleaned, n_bad


def _clean(src: SourceMesh):
    """clean_source, and the indices (into src.tris) of the triangles kept."""
    tris = np.asarray(src.tris).reshape(-1, 3)
    if not np.issubdtype(tris.dtype, np.integer):
        raise ValueError(f"triangle indices must be integers, got {tris.dtype}")
    tris = tris.astype(np.int64, copy=False)
    pos = np.asarray(src.positions, dtype=np.float64).reshape(-1, 3)
    t0, t1, t2 = tris[:, 0], tris[:, 1], tris[:, 2]
    if len(tris) and len(pos) and tris.min() >= 0 and tris.max() < len(pos):  # (the usual case: two reductions)
        ok = None
    else:
        ok = (np.minimum(np.minimum(t0, t1), t2) >= 0) & (np.maximum(np.maximum(t0, t1), t2) < len(pos))
    if not len(tris) or not len(pos):
        ok = np.zeros(len(tris), bool)
    elif not np.isfinite(np.add.reduce(pos, axis=None)):  # some coordinate is not finite (or the sum overflows)
        finite = np.isfinite(pos[:, 0]) & np.isfinite(pos[:, 1]) & np.isfinite(pos[:, 2])
        if ok is None:
            ok = finite[t0] & finite[t1] & finite[t2]
        else:
            s0, s1, s2 = (np.where(ok, t, 0) for t in (t0, t1, t2))
            ok &= finite[s0] & finite[s1] & finite[s2]
    distinct = (t0 != t1) & (t1 != t2) & (t2 != t0)
    ok = distinct if ok is None else ok & distinct

    all_ok = bool(ok.all())

    def sel(a):
        return None if a is None else (np.asarray(a) if all_ok else np.asarray(a)[ok])

    cleaned = SourceMesh(pos, sel(tris), _finite_or_zero(sel(src.corner_uv)),
                         sel(src.material) if src.material is not None else np.zeros(int(ok.sum()), np.int64),
                         _finite_or_zero(sel(src.corner_normals)))
    return cleaned, int((~ok).sum()), np.flatnonzero(ok)


def _finite_or_zero(a):
    """Corner attributes with their non-finite values set to 0 (a NaN UV or normal of the user's mesh
    must not reach an image mesh; a zero normal receives no GR irradiance). Copies only if needed."""
    if a is None:
        return None
    a = np.asarray(a)
    if a.dtype != np.float32:  # (float32 UVs, as Blender stores them, stay so: exact in float64 arithmetic)
        a = np.asarray(a, dtype=np.float64)
    if np.isfinite(np.add.reduce(a, axis=None)):  # (one reduction: a NaN or infinity anywhere makes it so)
        return a
    bad = ~np.isfinite(a)
    if bad.any():
        a = np.where(bad, 0.0, a)
    return a


_EDGE_CACHE: list = []
_EDGE_CACHE_SIZE = 8


def _edges_of(tris) -> subdivision.Edges:
    """subdivision.mesh_edges, remembered for the last few topologies (animated meshes usually keep
    theirs from frame to frame): a copy of each index array is kept and compared with the new one
    (a comparison is several times cheaper than a digest of the array)."""
    for i, (known, edges) in enumerate(_EDGE_CACHE):
        if known.shape == tris.shape and np.array_equal(known, tris):
            if i:  # the most recent first
                _EDGE_CACHE.insert(0, _EDGE_CACHE.pop(i))
            return edges
    edges = subdivision.mesh_edges(tris)
    _EDGE_CACHE.insert(0, (np.array(tris, copy=True), edges))
    del _EDGE_CACHE[_EDGE_CACHE_SIZE:]
    return edges


def chord_lengths(directions, edge_verts) -> np.ndarray:
    """(E,) chord length between the unit ``directions`` of each edge's end points (dimensionless)."""
    return observer_view.chord_length(directions.take(edge_verts[:, 1], axis=0),
                                directions.take(edge_verts[:, 0], axis=0))


THREADS = 2
"""Threads a build of a dense mesh uses (1: the calling thread alone): the map's chunks are looked up
two at a time (one in a worker thread, each chunk's values its own: :func:`images_in_chunks`), both
orders' image meshes assembled at once (pipeline.build_images). numpy releases the GIL inside its
large operations, so the two run side by side on two free cores; the results do not depend on how
they are scheduled (every piece writes arrays of its own). Only with tables whose lookups are safe
from two threads (:func:`threads_for`)."""

_POOL: list = []


def beside():
    """The one worker thread the builds share (a concurrent.futures pool made on first use), or None
    when THREADS is 1."""
    if THREADS < 2:
        return None
    if not _POOL:
        import concurrent.futures

        _POOL.append(concurrent.futures.ThreadPoolExecutor(max_workers=THREADS - 1,
                                                           thread_name_prefix="grlens-core"))
    return _POOL[0]


def stop_threads() -> None:
    """Shut the worker thread down (waiting for work it runs); the next dense build makes a new one.
    For the add-on's unregister, so that disabling or reloading it leaves no thread of its own behind."""
    while _POOL:
        _POOL.pop().shutdown(wait=True)


def threads_for(table) -> bool:
    """Whether lookups in ``table`` may run in two threads at once: lutgen's LUT and WideLUT (a
    family's tables make their rows under a lock); not the orbit table's RayMap (it counts its
    solves)."""
    from lutgen import LUT
    from lutgen.wide_lut import WideLUT

    return isinstance(table, (LUT, WideLUT))


MAP_CHUNK = 1 << 16
"""Points per call of the table for a dense mesh's vertices and edge midpoints (:func:`images_in_chunks`:
a cancellation point and the progress between calls; each point's values do not depend on the
others)."""


def images_in_chunks(frame: Frame, points, plane=None, tangents: bool = False, part=(0.0, 1.0)) -> dict:
    """frame.map.images of ``points`` (N, 3; BU) for every order of the frame (``plane``: their
    mapping.PlaneCoordinates, or None; ``tangents``: the rays' tangents too), in calls of MAP_CHUNK
    points with frame.checkpoint between them, reporting the way through the stage from part[0] to
    part[1] (the same values as one call: the map is per point)."""
    n = len(points)
    if n <= MAP_CHUNK:
        return frame.map.images(points, frame.orders, plane, tangents=tangents)
    def chunk(s):
        e = min(s + MAP_CHUNK, n)
        sub = None if plane is None else mapping.PlaneCoordinates(
            r=plane.r[s:e], phi=plane.phi[s:e], e2=plane.e2[s:e], on_axis=plane.on_axis[s:e])
        return frame.map.images(points[s:e], frame.orders, sub, tangents=tangents)

    pool = beside() if threads_for(frame.map.table) else None
    starts = list(range(0, n, MAP_CHUNK))
    out = None  # {order: mapping.Images} of all the points, made at the first chunk, filled chunk by chunk
    step = 2 if pool is not None else 1
    for i in range(0, len(starts), step):
        if i:
            frame.checkpoint(part[0] + (part[1] - part[0]) * starts[i] / n)
        later = pool.submit(chunk, starts[i + 1]) if step == 2 and i + 1 < len(starts) else None
        try:
            done = [(starts[i], chunk(starts[i]))]
        finally:
            if later is not None:  # (waited for even when this thread's chunk failed)
                done.append((starts[i + 1], later.result()))
        for s, got in done:
            if out is None:  # (each chunk copied in as it comes: its own arrays are freed for the next
                # chunk's, not all kept until a concatenation)
                out = {o: _empty_like_images(img, n, plane) for o, img in got.items()}
                if plane is None:  # (one PlaneCoordinates for every order)
                    for o in out:
                        out[o].plane = out[frame.orders[0]].plane
            for o, img in got.items():
                _copy_images(out[o], img, s, min(s + MAP_CHUNK, n), with_plane=plane is None and o == frame.orders[0])
    return out


_PLANE_FIELDS = ("r", "phi", "e2", "on_axis")


def _empty_like_images(img, n, plane):
    """mapping.Images of ``n`` points with uninitialised arrays shaped and typed like ``img``'s (None
    where ``img`` has None), and ``plane`` (or new arrays like ``img.plane``'s when None)."""
    def like(a):
        return None if a is None else np.empty((n,) + a.shape[1:], a.dtype)

    values = {f.name: like(getattr(img, f.name)) for f in dataclasses.fields(mapping.Images) if f.name != "plane"}
    values["plane"] = plane if plane is not None else mapping.PlaneCoordinates(
        *(like(getattr(img.plane, k)) for k in _PLANE_FIELDS))
    return mapping.Images(**values)


def _copy_images(dst, src, s, e, with_plane=False):
    """``src``'s arrays (mapping.Images of points s to e) into rows s:e of ``dst``'s (and its plane's)."""
    for f in dataclasses.fields(mapping.Images):
        a = getattr(src, f.name)
        if isinstance(a, np.ndarray):
            getattr(dst, f.name)[s:e] = a
    if with_plane:
        for k in _PLANE_FIELDS:
            getattr(dst.plane, k)[s:e] = getattr(src.plane, k)


EDGE_BLOCK = 1 << 15
"""Edges per block of :func:`edge_lengths` (their end points' rows stay in the cache between the
gather and the arithmetic; a cancellation point between blocks)."""


def edge_lengths(columns, edge_verts, checkpoint=None) -> list:
    """[(E,) per array of ``columns``]: for each (N, 3) array of per-vertex vectors (unit directions
    on the view sphere: the chord; positions in BU: the edge's length), the distance between the rows
    of each edge's end points (``edge_verts`` (E, 2)), as :func:`chord_lengths` (the same arithmetic:
    |v[b] - v[a]| by observer_view.chord_length), for all arrays in one pass over the edges: the end
    points' rows of every array are gathered together, in blocks of EDGE_BLOCK edges. ``checkpoint``:
    None, or called between blocks with the fraction of the edges done (it may raise to stop)."""
    k = len(columns)
    stacked = np.concatenate([np.asarray(c, np.float64).reshape(-1, 3) for c in columns], axis=1) if k > 1 else \
        np.asarray(columns[0], np.float64).reshape(-1, 3)
    n_e = len(edge_verts)
    out = np.empty((n_e, k))
    a_idx, b_idx = edge_verts[:, 0], edge_verts[:, 1]
    for s in range(0, n_e, EDGE_BLOCK):
        if checkpoint is not None and s:
            checkpoint(s / n_e)
        e = min(s + EDGE_BLOCK, n_e)
        w = stacked.take(b_idx[s:e], axis=0)
        w -= stacked.take(a_idx[s:e], axis=0)
        w = w.reshape(e - s, k, 3)
        np.sqrt(np.einsum("ijk,ijk->ij", w, w), out=out[s:e])
    return [np.ascontiguousarray(out[:, j]) for j in range(k)]


def circumference_from_edges(chords, of_tri) -> np.ndarray:
    """(T,) observer_view.circumference of triangles from the chord lengths (E,) of their edges."""
    return chords[of_tri[:, 0]] + chords[of_tri[:, 1]] + chords[of_tri[:, 2]]


@dataclass
class SourceImages:
    """The map stage's images of a prepared source's vertices: ``images`` {order: mapping.Images},
    per order the chord lengths (E,) of its edges' images and the circumferences (T,) of its
    triangles' images on the view sphere, and on demand the images' angles from the hole's direction
    (:meth:`hole_angle`, radians)."""

    images: dict
    chord: dict
    circumference: dict
    scene: mapping.Scene = field(repr=False, default=None)
    _hole: dict = field(default_factory=dict, repr=False)

    def hole_angle(self, order) -> np.ndarray:
        """(N,) radians: the angle of each vertex's ``order`` image from the hole's direction."""
        if order not in self._hole:
            with np.errstate(invalid="ignore"):
                self._hole[order] = observer_view.hole_angle(self.images[order].direction, self.scene.camera,
                                                             self.scene.hole, self.scene.view_beta)
        return self._hole[order]


def map_source(frame: Frame, source: Source) -> SourceImages:
    """The map stage for the source's vertices: their images of every order of the frame, with the rays'
    tangents when pieces are measured on screen (visibility needs the directions in which the rays
    leave the vertices: one lookup for both)."""
    images = images_in_chunks(frame, source.positions, source.plane, frame.budget.active, (0.0, 0.75))
    frame.checkpoint(0.75)  # (the table's lookups are about three quarters of the stage)
    chord = dict(zip(frame.orders, edge_lengths([images[o].direction for o in frame.orders], source.edges.verts,
                                                 lambda q: frame.checkpoint(0.75 + 0.2 * q))))
    circ = {o: circumference_from_edges(chord[o], source.edges.of_tri) for o in frame.orders}
    return SourceImages(images, chord, circ, frame.scene)
