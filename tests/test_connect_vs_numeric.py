"""Closed-form solver (lutgen.connect) against the independent DOP853 integrator
(lutgen.reference.connect_numeric) on random cases: r_obs from 1.6 to 1000 r_s, targets inside and
outside the observer's radius, next to the horizon (r = 1 + 1e-6 ...), near phi = 0 and phi = pi,
both orders. The default run checks 60 cases (120 rays); ``-m slow`` checks 1500 more.

Units: r_s = 1, c = 1; tolerances: xi 1e-9 rad, dt 1e-9 relative, (ux, uy) 1e-8 relative.
"""
import math

import numpy as np
import pytest

from lutgen import connect
from lutgen.reference import connect_numeric


def random_cases(n, seed):
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(n):
        r_obs = 10 ** rng.uniform(math.log10(1.6), 3.0)
        kind = rng.integers(5)
        if kind == 0:
            r = 1.0 + 10 ** rng.uniform(-6, -1)  # next to the horizon
        elif kind == 1:
            r = r_obs * rng.uniform(1.01, 3.0)  # beyond the observer
        elif kind == 2:
            r = 1.5 * (1 + rng.uniform(-0.05, 0.05))  # around the photon sphere
        else:
            r = 10 ** rng.uniform(0.005, math.log10(0.99 * r_obs))
        phi = [rng.uniform(0, np.pi), rng.uniform(0, 1e-3), np.pi - rng.uniform(0, 1e-3)][rng.integers(3)]
        cases.append((r_obs, r, phi))
    return cases


def check(cases):
    for r_obs, r, phi in cases:
        for order in (1, 2):
            c = connect(r_obs, r, phi, order)
            xi, dt, ux, uy = connect_numeric(r_obs, r, phi, order)
            ctx = (r_obs, r, phi, order)
            assert abs(float(c.xi) - xi) < 1e-9, ctx
            assert abs(float(c.dt) / dt - 1) < 1e-9, ctx
            scale = math.hypot(ux, uy)
            assert math.hypot(float(c.ux) - ux, float(c.uy) - uy) < 1e-8 * scale, ctx


def test_random_cases():
    check(random_cases(20, seed=11))  # test_many_random_cases (slow): 1500


@pytest.mark.slow
def test_many_random_cases():
    check(random_cases(1500, seed=12))
