"""The core's stages as a specification (issue 20): what each stage promises, checked on scenes of
several kinds (the benchmark sphere off and on the axis, a floor to 150 r_s, an open square behind
the hole), each stage run as build_images runs it. No private constant is changed here: these are
invariants of the shipped budget (grlens_addon/core/budget.py). Comparisons of a rule against its
absence are benchmarks (benchmarks/bench_budget.py), not tests."""
import math
import sys
import os

import numpy as np
import pytest

from grlens_addon.core import assemble, axis_patch, budget, culling, frame, interior, mapping, observer_view, pipeline, subdivision
from lutgen import LUTFamily, connect
from meshes import grid

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
import bench_accuracy as BA  # noqa: E402
import bench_budget as BB  # noqa: E402

R_OBS = 20.0
HOLE = np.zeros(3)
CAM = BA.camera(320, 180)
SCENE = mapping.Scene(CAM.position, HOLE, 1.0)


@pytest.fixture(scope="module")
def table():
    return LUTFamily().at(R_OBS)


def _square():
    pts = np.array([(-4, -0.7, -0.8), (-4, 1.3, -0.8), (-4, 1.3, 1.2), (-4, -0.7, 1.2)], float)
    return pipeline.SourceMesh(pts, np.array([[0, 1, 2], [0, 2, 3]]),
                               np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], float))


SCENES = {
    "sphere 45": lambda: BA.sphere_scene(45)[0],
    "sphere 170": lambda: BA.sphere_scene(170)[0],
    "sphere 180": lambda: BA.sphere_scene(180)[0],
    "sphere 0": lambda: BA.sphere_scene(0)[0],
    "floor": lambda: grid(-150, 30, -60, 60, 30, 20, "z", -2.0),
    "square": _square,
}


def _run(table, src, settings=None, planes="camera"):
    """Every stage as build_images runs them (pipeline.run_stages, then the assembly): per order a
    dict of the stage outputs."""
    settings = settings or BA.make_settings(CAM)
    fr = frame.frame_context(SCENE, table, settings, None, CAM.frustum_planes() if planes == "camera" else planes)
    st = pipeline.run_stages(fr, src)
    out = {}
    for order, s in st.orders.items():
        image = assemble.assemble(fr, st.source, s.pieces, s.keep, st.patches, s.patch_keep, s.report, order)
        out[order] = dict(frame=fr, source=st.source, coarse=st.coarse, plan=s.plan, pieces=s.pieces, keep=s.keep,
                          patches=[p for p in st.patches if order in p.orders], patch_keep=s.patch_keep,
                          report=s.report, image=image, probes=st.probes)
    return out


def test_frame_context_carries_a_table_for_the_cameras_radius(table):
    """The frame's map stage takes only a table built for the camera's radius (the family's table
    depends on it); a panorama's camera model has no frustum, so nothing is culled against one."""
    far = mapping.Scene(np.array([30.0, 0.0, 0.0]), HOLE, 1.0)
    with pytest.raises(ValueError, match="rebuild the LUT"):
        frame.frame_context(far, table, pipeline.Settings())
    with pytest.raises(ValueError, match="camera kind"):
        frame.CameraModel("ORTHO")
    fr = frame.frame_context(SCENE, table, pipeline.Settings(pixel_angle=2 * math.pi / 640), kind="EQUIRECTANGULAR")
    assert fr.planes is None and fr.camera.kind == "EQUIRECTANGULAR"
    src = BA.sphere_scene(90)[0]
    out = pipeline.build_images(src, SCENE, table, pipeline.Settings(pixel_angle=2 * math.pi / 640))
    assert all(img.report.outside_frustum == 0 and len(img.tris) > 0 for img in out.values())


def test_map_stage_is_the_connecting_rays(table):
    """Mapper.images puts a point's image where lutgen.connect says (direction at xi, distance c dt),
    and Mapper.extend reuses the source corners' images to the bit, looking up only new vertices."""
    rng = np.random.default_rng(3)
    pts = rng.uniform(-6, 6, (40, 3)) + np.array([-4.0, 0, 0])
    mp = frame.frame_context(SCENE, table, pipeline.Settings()).map
    img = mp.images(pts, (1, 2))
    plane = mapping.plane_coordinates(pts, SCENE)
    for order in (1, 2):
        c = connect(R_OBS, plane.r, plane.phi, order)
        ok = img[order].valid & np.isfinite(c.xi)
        assert ok.sum() > 30
        xi = np.arccos(np.clip(img[order].direction[ok] @ SCENE.e1, -1, 1))
        np.testing.assert_allclose(xi, c.xi[ok], atol=1e-6)
        np.testing.assert_allclose(img[order].distance[ok], c.dt[ok], rtol=1e-5)  # the table's accuracy
    keys = np.array([3, 7, 40 + 1, 40 + 5, 0])
    new_pts = np.vstack([pts[[3, 7]], pts[[1, 5]] + 0.1, pts[[0]]])
    ext = mp.extend(img[1], new_pts, keys, 40, 1)
    assert np.array_equal(ext.position[[0, 1, 4]], img[1].position[[3, 7, 0]])
    direct = mp.images(new_pts[2:4], (1,))[1]
    assert np.array_equal(ext.position[2:4], direct.position)
    # every new vertex among the known points: the table is not asked at all, the images are the same
    known = (np.array([41, 45]), mapping.take(direct, [0, 1]))
    calls = []
    lookup = mp.table.lookup_orders
    mp.table.lookup_orders = lambda *a, **k: calls.append(a) or lookup(*a, **k)
    try:
        reused = mp.extend(img[1], new_pts, keys, 40, 1, known=known)
    finally:
        del mp.table.lookup_orders
    assert calls == []
    for name in ("position", "direction", "distance", "valid", "xi", "dt"):
        assert np.array_equal(getattr(reused, name), getattr(ext, name), equal_nan=True), name


@pytest.mark.parametrize("name", sorted(SCENES))
def test_culling_owns_every_count(table, name):
    """The report accounts for every piece the subdivision made and every source triangle set aside
    before it: pieces = no image + degenerate + ring + frustum (of the pieces) + under a patch + kept
    pieces + pieces the refine step cut further (replaced by their parts, which are among the kept);
    kept = the image's faces; patch faces are counted once, under kept."""
    for order, s in _run(table, SCENES[name]()).items():
        rep, image = s["report"], s["image"]
        assert rep.kept == len(image.tris)
        if s["plan"].below_pixel:
            assert rep.below_pixel == len(s["source"].tris) and len(image.tris) == 0
            continue
        n_pieces = len(s["pieces"].sub.tris)
        frustum_pieces = rep.outside_frustum - s["plan"].set_aside["outside_frustum"]
        assert n_pieces == (rep.invalid_vertex + rep.degenerate_source + rep.einstein_ring + frustum_pieces
                            + rep.patch_covered + rep.kept - rep.patch_faces + rep.refined)
        assert rep.patch_faces == sum(int(k.sum()) for k in s["patch_keep"] if k is not None)
        assert rep.back_face == s["plan"].set_aside["back_face"]
        assert len(s["source"].tris) == (s["plan"].set_aside["outside_frustum"] + rep.back_face
                                         + s["plan"].set_aside.get("patch_replaced", 0) + len(s["plan"].selected))


@pytest.mark.parametrize("name", ["sphere 45", "sphere 170", "floor"])
def test_subdivision_is_watertight(table, name):
    """The pieces of a closed surface (the sphere, every triangle selected) or of a grid share every
    inner edge with exactly one other piece, the same vertices on both sides (no T-junctions): each
    directed edge of the pieces appears once and its reverse once, except on the source's boundary
    and next to triangles the plan set aside."""
    for order, s in _run(table, SCENES[name](), planes=None).items():
        if s["pieces"] is None:
            continue
        sub, source = s["pieces"].sub, s["source"]
        t = sub.tris if s["pieces"].cut is None else sub.tris[~s["pieces"].cut]  # (cut pieces: their parts)
        fwd = np.stack([t, np.roll(t, -1, axis=1)], 2).reshape(-1, 2)
        n = len(sub.positions)
        key = fwd[:, 0] * n + fwd[:, 1]
        rev = fwd[:, 1] * n + fwd[:, 0]
        assert len(np.unique(key)) == len(key)  # consistent winding, no edge used twice one way
        unmatched = ~np.isin(key, rev)
        # every unmatched piece edge lies on a source edge used by one selected triangle
        selected = s["plan"].selected
        uses = np.bincount(source.edges.of_tri[selected].ravel(), minlength=len(source.edges.verts))
        open_src = np.flatnonzero(uses == 1)
        ends = source.positions[source.edges.verts[open_src]]
        p, q = sub.positions[fwd[unmatched, 0]], sub.positions[fwd[unmatched, 1]]
        on = np.zeros(len(p), bool)
        for a, b in ends:  # a handful of open edges per scene
            ab = b - a
            for x in (p, q):
                t_ = np.clip((x - a) @ ab / (ab @ ab), 0, 1)
                on_ab = np.linalg.norm(a + t_[:, None] * ab - x, axis=1) < 1e-9 * (1 + np.linalg.norm(ab))
                on |= on_ab if x is p else False
        assert on.all(), f"{name} order {order}: {int((~on).sum())} piece edges open inside the mesh"


@pytest.mark.parametrize("name", sorted(SCENES))
def test_level_plan_meets_the_tolerance(table, name):
    """Every probed edge gets at least the level that keeps it within the budget where the renderer
    draws it (its midpoint's error shrinks as 1/n^2: interior.midpoint_errors), unless it is capped
    by MaxTessLevel or spans fewer pixels; and every kept piece is within the budget inside, where the
    renderer interpolates it (interior.measure, its centroid and edge midpoints: the refine step
    splits the source triangles of those beyond), or reported beyond it (CullReport.over_budget):
    the pieces of the triangles the refine step samples (budget.SAMPLE_REACH; the others' pieces
    are measured by benchmarks/bench_coarse.py)."""
    for order, s in _run(table, SCENES[name]()).items():
        if s["pieces"] is None:
            continue
        fr, plan, probes = s["frame"], s["plan"], s["probes"]
        probe = probes.probe[order]
        img_v = s["coarse"].images[order]
        d = img_v.direction
        ev = s["source"].edges.verts[probe]
        mids = probes.mid_images(order)
        rho = subdivision.rho(d[ev[:, 0]], d[ev[:, 1]], mids.direction)
        chord_px = probes.chord[order][probe] / fr.budget.pixel_angle
        err_px, lt_units = interior.midpoint_errors(fr, img_v.position[ev[:, 0]], img_v.position[ev[:, 1]],
                                                    img_v.distance[ev[:, 0]], img_v.distance[ev[:, 1]], mids)
        need = np.ceil(np.sqrt(np.fmax(err_px / fr.budget.tolerance_px, lt_units)))
        curv = np.ceil(fr.settings.max_tess_level * np.clip(fr.settings.tess_a * rho ** fr.settings.tess_b, 0, 1))
        floor = np.minimum(np.minimum(need, np.ceil(chord_px)), curv)
        ok = np.isfinite(floor)
        assert np.all(plan.levels[probe][ok] >= np.minimum(floor[ok], fr.settings.max_tess_level))
        sub, img = s["pieces"].sub, s["pieces"].images
        sampled = interior.sampled_sources(fr, s["source"])[s["pieces"].face_src]
        plain = np.flatnonzero(s["keep"] & sampled)
        if plain.size == 0:
            continue
        err, scr, lt = interior.measure(fr, sub.positions, sub.tris, img, order, plain)
        beyond = s["report"].over_budget
        assert np.nanmax(err[plain]) <= 1.0 or beyond.count > 0, (name, order)
        assert np.nanmax(scr[plain]) <= max(fr.budget.tolerance_px, beyond.screen_px) * (1 + 1e-9), (name, order)


@pytest.mark.parametrize("name", ["sphere 170", "sphere 180", "sphere 0", "square"])
def test_kept_ring_pieces_are_within_the_ring_sagitta(table, name):
    """The culling and the level plan measure pieces next to the Einstein ring one way: a kept piece
    covering the azimuth D about the axis at R pixels from the hole's direction has straight sides
    that fall R (1 - cos(D/2)) inside the ring, and that never exceeds the tolerance."""
    for order, s in _run(table, SCENES[name]()).items():
        if s["pieces"] is None:
            continue
        fr, sub, img = s["frame"], s["pieces"].sub, s["pieces"].images
        t = sub.tris[s["keep"]]
        x, y, z = observer_view.axis_coordinates(sub.positions, SCENE.camera, HOLE)
        src_c = observer_view.circumference(observer_view.unit_directions(sub.positions, SCENE.camera), t)
        img_c = observer_view.circumference(img.direction, t)
        ring = img_c > fr.settings.cull_ratio * src_c
        if not ring.any():
            continue
        _, span = observer_view.axis_geometry(sub.positions, t[ring], SCENE.camera, HOLE, order, axis_xyz=(x, y, z))
        r_px = observer_view.hole_angle(img.direction, SCENE.camera, HOLE)[t[ring]].max(axis=1) / fr.budget.pixel_angle
        assert np.all(observer_view.ring_sagitta(r_px, span) <= fr.budget.tolerance_px * (1 + 1e-12))


@pytest.mark.parametrize("angle", [180, 0, 4])
def test_patches_cross_the_ring(table, angle):
    """An axis patch draws the Einstein ring's edge with chords whose sag is within the patch-edge
    tolerance (budget.Budget.patch_edge_px), its points CHORD_OUTSET of that sag outside the ring, so
    that the chords cross it (the points outside, the chords' middles inside); its innermost circle
    is within the band of the ring."""
    runs = _run(table, BA.sphere_scene(angle)[0])
    seen = 0
    for order, s in runs.items():
        fr = s["frame"]
        for p in s["patches"]:
            if order not in p.images:
                continue
            seen += 1
            look = axis_patch._limit_look(p.crossing, fr.map, (order,))[order]
            lim = p.images[order]
            n = p.n_azimuths
            theta = observer_view.hole_angle(lim.direction[:n], SCENE.camera, HOLE)
            exact = float(observer_view.hole_angle(axis_patch.limit_images(p.crossing, np.zeros(1), fr.map, order,
                                                                     look).direction, SCENE.camera, HOLE)[0])
            sag = abs(axis_patch.chord_sag(look.xi[0], 2 * np.pi / n)) / fr.budget.pixel_angle
            assert sag <= fr.budget.patch_edge_px * (1 + 1e-9)
            mids = lim.direction[:n] + np.roll(lim.direction[:n], -1, axis=0)
            mids /= np.linalg.norm(mids, axis=1)[:, None]
            mid_theta = observer_view.hole_angle(mids, SCENE.camera, HOLE)
            outside = np.sign(theta - exact)
            inside = np.sign(mid_theta - exact)
            assert np.all(outside == outside[0]) and np.all(inside == -outside[0])
    assert seen > 0
