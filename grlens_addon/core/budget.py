"""The error budget of the per-frame core, and every parameter the core is tuned by, in one place.

The budget. Every drawn piece of an image is a flat triangle standing in for a curved one. Its
error is measured where the renderer interpolates it, perspective-correct over the image triangle:
how far, in pixels, a source point drawn with the interpolated position and UV lies from its exact
image, everywhere inside the piece, and how far the interpolated light travel time lies from the
exact c*dt, relative (LIGHT_TRAVEL_TOLERANCE; interior.py measures both at a piece's centroid and
edge midpoints, and the refine step cuts the pieces beyond).

* An edge mapped through the table bends: its midpoint, drawn halfway between its ends' images, is
  off its exact image (interior.midpoint_errors, subdivision.edge_levels).
* Next to an Einstein ring the mapping turns azimuth about the observer-hole axis into position
  along the ring, so a piece covering the azimuth D at R pixels from the hole's direction has sides
  R (1 - cos(D/2)) inside the ring (observer_view.ring_sagitta).
* An axis patch draws the ring's edge itself with chords of a circle (axis_patch.grid_shape).

The budget gives each piece a tolerance in pixels:

* ``tolerance``: Settings.max_error_px (pixels): every piece, whatever it draws, everywhere inside
  it. The level plan cuts pieces to it, the refine step cuts further the pieces still beyond it
  inside (interior.refine), and the culling drops a piece whose ring sagitta exceeds it: one measure for
  both (observer_view.ring_sagitta / observer_view.max_ring_span), so a piece the plan made is never culled for
  being too wide (RING_LEVEL_MARGIN leaves room for the unequal pieces of a triangle cut uniformly
  in space).
* ``coverage``: COVERAGE_FACTOR x tolerance: the edges that decide which pixels an image covers.
  Everywhere else a piece borders another piece of the same image, so where their shared edge lies
  does not change coverage; along the silhouette (silhouette.py), along a ring's edge and across an
  image that is nothing but edges (under THIN_PX pixels wide) it does. Those are: silhouette edges
  and the ring levels of silhouette triangles, strips (level_plan) and the second order's ring edge
  next to an axis patch. An image that is nothing but
  edges (THIN_PX) has its whole budget scaled by THIN_FACTOR.
* The patch's own ring edge: PATCH_EDGE_FACTOR x coverage (its chords are cheap, a patch has at
  most MAX_AZIMUTHS of them, and a second-order ring is under a pixel wide).

:class:`Budget` holds the frame's tolerances in pixels and in radians on the view sphere. The other
constants below are real parameters: each says what it trades. Units: pixels are those of the
frame's camera (Budget.pixel_angle radians each); distances in Blender units (BU) where stated.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# --- the budget's factors -------------------------------------------------------------------------

COVERAGE_FACTOR = 0.25
"""The edges that decide coverage are drawn to this fraction of Settings.max_error_px. Next to the
Einstein ring the second-order images are less than a pixel wide, so a tenth of a pixel there changes
the coverage by tens of percent; levels grow as the square root of the inverse tolerance, so this
costs twice the segments on those edges only. Trades image triangles on silhouettes, ring edges and
thin images for coverage mismatch (benchmarks/bench_budget.py measures it)."""

PATCH_EDGE_FACTOR = 0.25
"""An axis patch's ring edge is drawn with chords that sag by at most this times the coverage
tolerance (1/16 of Settings.max_error_px): the chords are a patch's azimuths, at most MAX_AZIMUTHS,
so the tight aim costs little, and a second-order ring is less than a pixel wide."""

PATCH_BAND_FACTOR = 1.0
"""The innermost circle of a patch lies where its image is within this times the coverage tolerance
of the Einstein ring; the band inside it is drawn by pieces that span the whole way to the ring,
refined in azimuth (axis_patch.band_shape) so that they stay within the tolerance."""

BAND_WIDE_FACTOR = 1.0
"""The same as PATCH_BAND_FACTOR for a wide band a patch tries first (where the sheet has no edge
near the axis; where its innermost circle does not go all round the sheet it takes the narrow
band). The refined band draws its points as exactly as the grid's circles, so a wide band would only
save circles (16: up to half a patch's faces next to a large ring), but its faces then reach over
many source triangles and carry their corner values (UVs) extrapolated from one of them: across the
benchmark sphere's UV seam next to the axis that drew textures 2-80 pixels off at 4-16
(benchmarks/bench_accuracy.py, 0 and 180 deg). 1.0: off, the band as narrow as PATCH_BAND_FACTOR."""

PATCH_AIM = 0.95
"""An axis patch's pieces (its grid's rows and its band's azimuth steps, axis_patch.grid_shape and
band_shape) keep their points' placement along the ring within this fraction of the tolerance:
the rest is left for the placement across it (the image's distance from the ring is not linear in
the distance from the axis, nor is the ring's chord its arc). Lower: more circles and band vertices;
at 1.0 points of the grid's outer rows were measured up to 0.4% beyond the tolerance
(tests/test_axis_band.py)."""

MAX_BAND_AZIMUTHS = 16384
"""At most this many limit vertices per turn in a patch's band next to the ring (about
pi ring_px / Settings.max_error_px are needed: 16384 keeps the tolerance up to a ring about 1300 px
in radius at 0.25 px; beyond, the band's pieces draw their points up to ring_px pi / 16384 pixels off
along the ring). Trades faces (about three per limit vertex) for the placement next to the ring."""

BAND_INNER_MAX = 0.9
"""The refined band's inner polygon lies at most this fraction of the way out to the innermost
circle (axis_patch.band_shape: usually nearer, as the tolerance requires); keeps its fan of pieces
from becoming slivers where the ring is small on screen."""

UNDER_PATCH_FACTOR = 1.0
"""Pieces that a complete axis patch draws over (inside its outer circle, on a source triangle it
draws in that order) are dropped when their centroid is drawn more than this times the tolerance
from its true image (None: never): inside its outer circle a complete patch draws the whole sheet,
so these pieces only compete with it for the same pixels. Trades a few map lookups per patch for
texture placement next to the axis (a square behind the hole crossed off its centre: 0.92 px ->
0.33 px, tests/test_stages.py)."""

LIGHT_TRAVEL_TOLERANCE = 0.01
"""The light-travel-time pass (c*dt, interpolated over a piece) stays within this fraction of the
exact c*dt everywhere inside a piece (interior.py): the pass's own budget, as relative as the
quantity it is used for (depth, time delay)."""

SAMPLE_REACH = 0.1
SAMPLE_MIN_PX = 1.0
"""Which pieces are measured inside (interior.py). The map bends on the scale of a point's distance
from the camera (perspective) and from the hole (lensing); over a source edge shorter than
SAMPLE_REACH times both (at its nearer end) it is quadratic to within that fraction, so the level
plan's midpoint rule judges it, and the insides of pieces of triangles with such edges follow from
their edges. Only the pieces of source triangles with a longer edge are sampled, and of those only the pieces whose image spans more than SAMPLE_MIN_PX pixels
(the level plan leaves such edges uncut too) or whose own extent exceeds SAMPLE_REACH times their light
travel distance (a distance bends by about reach^2 / 8 of itself over that reach: 0.00125, far inside
LIGHT_TRAVEL_TOLERANCE). Lower samples more pieces per frame; higher trusts the plan farther."""

REFINE_ROUNDS = 12
"""The refine step (interior.refine, run by pipeline.run_stages after the culling). A kept piece that
breaks the budget inside (error E > 1 in units of the budget, interior.measure) is cut in four at its
edges' midpoints (its neighbours in two across a cut edge, so that the mesh stays watertight), and
the new pieces are measured again, at most REFINE_ROUNDS times (each round halves a piece's size and
quarters its error where the map is smooth: 12 rounds reach 4096 times finer). Only the pieces that
break the budget are cut, so the cut is graded where the error is, and nothing caps it but this and
Settings.max_triangles (the image triangles of one object; the worst pieces are cut first)."""

# --- the level plan -----------------------------------------------------------------------------

RING_MAGNIFICATION = 2.0
"""Source triangles whose image circumference exceeds this many times their own are treated as lying
in a strongly lensed (Einstein-ring) region: the level plan gives them ring levels (azimuth about
the axis). Lower looks at more triangles per frame, higher misses magnified ones."""

RING_LEVEL_MARGIN = 0.75
"""The ring levels aim at this fraction of the largest azimuth per piece the tolerance allows:
pieces of a triangle subdivided uniformly in space cover unequal azimuths, and the culling tests the
same bound at the full tolerance, so it must not catch the widest of them. Higher: fewer pieces,
more of them culled (gaps)."""

SILHOUETTE_RING_LEVEL_MAX = 24
"""Ring levels of silhouette triangles aim at the coverage tolerance only up to this level. Beyond
it a triangle lies so close to the axis that doubling its level quadruples tens of thousands of
pieces, most of which the ring culling drops anyway (the benchmark sphere grazing the axis at 171
deg of its orbit: 38k -> 100k pieces per order). Trades pieces in grazing frames for the
second-order ring's coverage."""

RING_EDGE_REACH = 2.0
RING_EDGE_ORDERS = (2,)
"""Magnified triangles within RING_EDGE_REACH patch radii of the axis draw the ring's edge next to a
patch; in the orders RING_EDGE_ORDERS (the second order, whose ring is less than a pixel wide) they
get the coverage tolerance. A first-order ring is wide: there the rule would only add pieces (next
to incomplete patches, where kept pieces draw part of it, the coverage tolerance and half the
tolerance were measured: the same mismatch at 171-175 and 185-189 deg, 5-21% more triangles;
benchmarks/bench_budget.py)."""

EDGE_ON_RATIO = 0.1
"""Magnified triangles on no patch's sheet whose projection along the axis has under this fraction
of their area (a face of a box parallel to the axis, beside the face the axis crosses) get levels for
the azimuth they cover next to the axis, which is far more than their average."""

THIN_PX = 2.0
THIN_FACTOR = 0.5
"""An order whose whole image lies within a band of THIN_PX pixels in radius about the hole's
direction (the second-order image of an object in front of the hole, around the Einstein ring) is
about a pixel wide: every one of its pixels is an edge pixel, so its whole budget (tolerance and
coverage alike) is scaled by THIN_FACTOR. Planning such an image for the coverage tolerance instead
(every edge a coverage edge, silhouettes no tighter) saves a tenth of its pieces but misses the
mismatch target next to the axis in front of the hole (9, 12 and 351 deg of the benchmark orbit:
0.51-0.54% of the pixels differ; benchmarks/bench_budget.py). 1.0 turns this off."""

STRIP_BAND_PX = 1.0
STRIP_MIN_LEVEL = 3
"""Ring triangles whose image lies within a band of STRIP_BAND_PX pixels in radius about the hole's
direction, that face one way at all corners and whose level is at least STRIP_MIN_LEVEL are cut into
strips across the ring (subdivision.subdivide, ``strips``) instead of the uniform grid, each side at
the level of its own azimuth for the coverage tolerance: about 2 L pieces instead of L^2. Wider
bands put the texture off (2 px: 0.6 px at 180 deg); 0 turns strips off."""

PRESPLIT_MIN = 12
PRESPLIT_EXP = 0.35
"""A magnified source triangle beside the axis (on a mesh the axis does not cross) whose pieces would
need more than level PRESPLIT_MIN next to it is first split at level need ** PRESPLIT_EXP, and the
level plan runs again on the smaller triangles, which refines mostly those next to the axis. Lower
exponents leave fewer triangles to the second pass but too coarse a first split (0.25: the sphere's
mismatch 0.21% -> 0.36% at 170 deg; 0.5 is 10% slower there)."""

# --- visibility -----------------------------------------------------------------------------------

BACK_FACE_MARGIN = 0.1
"""On a closed, outward-wound surface seen from outside, a triangle turned away from the camera along
the rays of an order by more than this at all three corners (the cosine between its normal and the
direction in which light leaves the corner towards the camera below -BACK_FACE_MARGIN) is hidden
behind the surface's own front: it is not subdivided and its image is not built. Back faces closer
to the silhouette are kept: where the front's straight pieces fall short of the curved outline, the
fold behind it fills in (margin 0: the sphere's mismatch at 170 deg 0.21% -> 0.34%)."""

BACK_FACE_MIN_PIECES = 4096
"""Back faces are looked for only when the subdivided triangles of an order would make at least this
many pieces (and at least as many as the mesh has triangles), or, on a dense mesh, when this many of
its triangles are in view (then among all of them, split or not: half of a dense closed mesh is
hidden behind its front, and its images, corner values and upload cost more than the test): the
test looks up the rays of their corners and checks that the mesh is closed, which costs more than
it saves on a mesh that is hardly subdivided."""

# --- axis patches ---------------------------------------------------------------------------------

PATCH_RADIUS_FACTOR = 2.0
"""A patch reaches this many times the largest distance from the axis of the crossed triangle's
corners. Larger patches replace more magnified triangles, but a patch face spans several source
triangles there and its corner values (UVs, normals) are interpolated across them (texture up to 2
px off at 6, 0.2 px at 2)."""

PROBE_AZIMUTHS = 8
"""Azimuths at which the crossed triangle's plane is probed for a patch's innermost circle."""

MAX_PATCHES = 8
"""At most this many patches per mesh (the crossings with the largest triangles): a closed surface
crosses the axis a few times; a triangle soup may cross it thousands of times, and there the ring
culling does the work."""

MAX_AZIMUTHS = 1024
MAX_CIRCLES = 64
MAX_GRID = 32768
"""Bounds of one patch's grid: azimuths per turn, circles, and their product. Beyond them the ring's
edge gets coarser chords or a wider innermost band."""

CHORD_OUTSET = 2.0 / 3.0
"""A patch's ring-edge vertices lie this fraction of their chords' sag off the Einstein ring, on the
side away from the chords' bow, so that the chords cross the ring and the polygon covers it on
average (the sliver's signed area is zero): the pixels drawn wrongly along the edge drop to about
0.38 of those of exact vertices, the largest deviation to 2/3 of the sag."""

HIDDEN_AZIMUTHS = 16
"""Azimuths at which the rays arriving at a crossing point are sampled to see whether the whole sheet
around it is turned away (axis_patch)."""

HIDDEN_CORE = 0.25
"""On a closed surface, a crossing whose rays all arrive from behind the sheet, and whose sheet's
triangles not turned away at every corner all lie at least HIDDEN_CORE patch radii from the axis,
gets no grid: it would only draw faces next to its rim, which kept pieces draw. Trades a few
milliseconds in frames with the far side of an object behind the hole for a little coverage."""

STEEP_RATIO = 2.0
STEEP_SPLIT_MAX = 4
"""Where the surface under a plain patch grid turns towards the axis' direction, an interval between
circles whose grid points lie more than STEEP_RATIO times farther apart on the surface than across
the axis is cut into ceil(ratio / STEEP_RATIO) intervals (at most STEEP_SPLIT_MAX), so that faces
stay close to the surface. 0 turns this off."""

CLIP_TO_TRIANGLES = True
CLIP_REACH = 0.6
"""A patch whose plain grid would stop short of the surface's fold within CLIP_REACH of its outer
circle has its cells cut along the source triangles under them: every face lies on one triangle,
carries its exact corner values and the patch draws its whole sheet (the benchmark sphere at 170.5
deg: 43k image triangles instead of 135k, 0.31% of the pixels differ instead of 0.46%). Farther out a
plain grid that goes all round is cheaper and as accurate. CLIP_TO_TRIANGLES False: always the plain
grid."""

MAX_CLIP_PAIRS = 4 * MAX_GRID
"""At most this many (cell, triangle) pairs are clipped per patch; beyond, the plain grid is used."""

# --- culling and assembly -------------------------------------------------------------------------

AZIMUTH_SPAN_MAX = np.radians(30.0)
"""Without a pixel size (no screen to measure on), the largest azimuth about the axis (radians) a
magnified triangle may cover before it is culled as part of an Einstein ring."""

PATCH_SEAM_JUMP = 0.1
"""A patch face takes its corners' values (UVs, normals) from the source triangle under each corner,
unless they differ by more than this from its own triangle's values carried there (a seam: a UV
island's edge, a sharp normal); then it takes those for all three."""


@dataclass(frozen=True)
class Budget:
    """The frame's error budget (see the module docstring). ``pixel_angle``: radians per pixel on the
    view sphere (None: no screen, so no screen-space bounds); ``tolerance_px``: Settings.max_error_px
    (None: no screen-space tolerance)."""

    pixel_angle: float | None
    tolerance_px: float | None

    @property
    def active(self) -> bool:
        """True when pieces are measured on screen (a pixel size and a tolerance are set)."""
        return bool(self.pixel_angle and self.tolerance_px)

    @property
    def coverage_px(self) -> float | None:
        """The tolerance (pixels) of the edges that decide coverage."""
        return None if self.tolerance_px is None else COVERAGE_FACTOR * self.tolerance_px

    @property
    def patch_edge_px(self) -> float:
        """The sag (pixels) allowed to the chords of an axis patch's ring edge."""
        return PATCH_EDGE_FACTOR * self.coverage_px

    @property
    def patch_band_px(self) -> float:
        """How close (pixels) to the Einstein ring a patch's innermost circle must be."""
        return PATCH_BAND_FACTOR * self.coverage_px

    def radians(self, px) -> float:
        """``px`` pixels as an angle (radians) on the view sphere."""
        return px * self.pixel_angle
