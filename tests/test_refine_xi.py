"""lutgen.solver.refine_xi: a close guess of a connecting ray's angle (e.g. a lookup table's) made
exact, against lutgen.connect (closed-form root finding) and the independent numerical integrator
(lutgen.reference.connect_numeric, DOP853 shooting); and the core's exact 1 + z built on it
(Settings.exact_redshift) against the exact aberration of the static observer's exact directions."""
import math

import numpy as np
import pytest

from lutgen import connect, reference, solver


def _targets(rng, n, r_obs):
    r = np.exp(rng.uniform(np.log(1.02), np.log(300.0), n))
    phi = rng.uniform(0.0, np.pi, n)
    r[:8] = r_obs  # the observer's own radius (periapsis label next to the tangent ray)
    phi[8:16] = np.pi  # behind the hole: both orders sweep pi
    phi[16:24] = 1e-9  # next to the axis in front
    r[24:40] = rng.uniform(1.49, 1.52, 16)  # periapses next to the photon sphere
    return r, phi


@pytest.mark.parametrize("r_obs", [1.6, 2.0, 6.0, 20.0, 1e3])
@pytest.mark.parametrize("order", [1, 2])
def test_guesses_off_by_up_to_1e_5_rad_become_the_exact_ray(r_obs, order):
    rng = np.random.default_rng(int(r_obs * 10) + order)
    r, phi = _targets(rng, 4000, r_obs)
    exact = connect(r_obs, r, phi, order).xi
    for scale in (1e-7, 1e-5):
        guess = exact + rng.normal(0.0, scale, exact.size)
        got = solver.refine_xi(r_obs, r, phi, order, guess)
        assert np.isfinite(got).all()
        err = np.abs(got - exact)
        assert err.max() < (1e-10 if scale == 1e-7 else 1e-8), (scale, r[err.argmax()], phi[err.argmax()])
        assert np.percentile(err, 99) < 1e-11


def test_against_the_numerical_integrator():
    """An independent method: DOP853 shooting, accurate to about 1e-10 rad here."""
    rng = np.random.default_rng(7)
    cases = [(20.0, 3.0, 2.5, 1), (20.0, 3.0, 2.5, 2), (6.0, 1.7, 1.0, 1), (6.0, 40.0, 0.3, 2),
             (2.0, 2.0, 0.7, 1), (20.0, 1.55, 3.0, 2)]
    for r_obs, r, phi, order in cases:
        ref = reference.connect_numeric(r_obs, r, phi, order)[0]
        guess = ref + rng.normal(0.0, 3e-7)
        got = solver.refine_xi(r_obs, np.array([r]), np.array([phi]), order, np.array([guess]))[0]
        assert abs(got - ref) < 1e-9, (r_obs, r, phi, order, got - ref)


def test_inside_the_photon_sphere_and_without_a_guess_the_exact_solver_answers():
    r, phi = np.array([1.3, 4.0, 2.0, 0.5, 3.0]), np.array([1.0, 2.0, np.nan, 1.0, 0.4])
    guess = np.array([2.0, 2.5, 1.0, 1.0, np.nan])
    got = solver.refine_xi(1.3, r, phi, 1, guess)
    exact = connect(1.3, r, phi, 1).xi
    np.testing.assert_array_equal(np.isnan(got), np.isnan(exact))
    np.testing.assert_allclose(got[[0, 1, 4]], exact[[0, 1, 4]], rtol=0, atol=1e-12)
    got = solver.refine_xi(20.0, r, phi, 2, guess)  # NaN guess: solved from scratch; r <= 1: NaN
    exact = connect(20.0, r, phi, 2).xi
    assert np.isnan(got[[2, 3]]).all()
    assert abs(got[4] - exact[4]) < 1e-12


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="order"):
        solver.refine_xi(20.0, [3.0], [1.0], 3, [1.0])
    with pytest.raises(ValueError, match="horizon"):
        solver.refine_xi(0.9, [3.0], [1.0], 1, [1.0])
