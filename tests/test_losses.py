"""core.losses: source triangles that cannot be imaged, sorted by reason (numpy only).

Units: BU with r_s = 2 BU; the hole at the origin, the camera at 20 r_s on +x.
"""
import numpy as np

import lutgen
from grlens_addon.core import losses, mapping

R_S = 2.0


def _setup():
    scene = mapping.Scene(np.array([20 * R_S, 0.0, 0.0]), np.zeros(3), R_S)
    lut = lutgen.build_lut(r_obs=20.0, r_min=1.25, r_max=15.0, n_r=32, n_phi=64)
    return scene, lut


def test_each_reason_and_the_first_one_counts():
    scene, lut = _setup()
    r = lambda x: (0.0, x * R_S, 0.3)  # noqa: E731  (beside the hole, about x r_s from it)
    pts = np.array([r(5), r(5.5), (0.0, 5 * R_S, 1.0),  # fine
                    r(0.5),  # inside the horizon
                    r(1.1),  # between the horizon and r_min = 1.25
                    r(30),  # beyond r_max = 15
                    (np.nan, 0.0, 0.0),  # non-finite
                    (-8.0 * R_S, 0.0, 0.0)])  # exactly on the axis behind the hole, in range
    tris = np.array([[0, 1, 2],  # imaged
                     [0, 1, 3],  # horizon
                     [0, 1, 4],  # below the table
                     [0, 1, 5],  # beyond
                     [6, 3, 5],  # non-finite first
                     [3, 5, 0],  # horizon before beyond
                     [0, 1, 7],  # on the axis: expected
                     [7, 5, 0]])  # beyond wins over the axis
    u = losses.unimaged_triangles(pts, tris, scene, lut)
    assert u.total == 8 and u.lost == 6 and u.on_axis == 1
    assert u.by_reason == {"non_finite": 1, "horizon": 2, "below_table": 1, "beyond_table": 2}
    text = losses.describe(u)
    assert text == ("1 with non-finite coordinates; 2 inside the horizon, r <= 1 r_s; 1 inside the lookup "
                    "table's inner radius, r < 1.25 r_s; 2 beyond the lookup table's range, r > 15 r_s")


def test_nothing_lost_and_empty_input():
    scene, lut = _setup()
    pts = np.array([(0.0, 8.0, 0.5), (0.0, 9.0, 0.5), (0.0, 8.0, 1.5)])
    u = losses.unimaged_triangles(pts, np.array([[0, 1, 2]]), scene, lut, orders=(1,))
    assert (u.total, u.lost, u.on_axis, u.by_reason) == (1, 0, 0, {})
    assert losses.unimaged_triangles(np.zeros((0, 3)), np.zeros((0, 3), int), scene, lut).total == 0
