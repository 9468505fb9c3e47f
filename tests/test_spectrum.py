"""The colours of shifted light (grlens_addon/core/spectrum.py): the shift law against Planck's law
(a blackbody at T seen with g is a blackbody at g T), the LLSS model's identities and optimality, and
the 3x3 matrices against an independent finer quadrature."""
import numpy as np
import pytest

from grlens_addon.core import spectrum as S

C2 = 1.438776877e7  # h c / k_B, nm K


def _planck(lam, t):
    return lam ** -5 / np.expm1(C2 / (lam * t))


@pytest.mark.parametrize("t, g", [(3000.0, 1.3), (6500.0, 0.7), (12000.0, 1.05), (4500.0, 2.0)])
def test_the_shift_law_turns_a_blackbody_into_the_hotter_one(t, g):
    """g^5 B(g lambda; T) = B(lambda; g T) exactly, so shifted_rgb of a blackbody at T is the RGB of the
    blackbody at g T (sampled on a grid wide enough that the shift stays inside it)."""
    lam = np.arange(150.0, 3000.0, 0.25)
    got = S.shifted_rgb(_planck(lam, t), g, lam)
    want = _planck(lam, g * t) @ S.response(lam)
    np.testing.assert_allclose(got, want, rtol=2e-6)
    assert (got[2] / got[0] > (_planck(lam, t) @ S.response(lam))[2] / (_planck(lam, t) @ S.response(lam))[0]) == (g > 1)


def test_the_model_gives_back_each_colour_and_is_smoothest():
    """The basis spectra have the unit colours as their RGB; white is the flat spectrum; any change
    that keeps the colour (a direction orthogonal to the response) makes the spectrum more curved."""
    a = S.response(S.LAMBDA_NM)
    np.testing.assert_allclose(a.T @ S.basis(), np.eye(3), atol=1e-12)
    np.testing.assert_allclose(S.spectrum([1.0, 1.0, 1.0]), 1.0, atol=1e-10)
    rng = np.random.default_rng(2)
    rgb = rng.uniform(0, 1, 3)
    s = S.spectrum(rgb)
    q, _ = np.linalg.qr(a)
    for _ in range(20):
        w = rng.normal(size=len(s))
        w -= q @ (q.T @ w)  # keeps the colour
        np.testing.assert_allclose(a.T @ (s + 1e-3 * w), rgb, atol=1e-12)
        assert np.sum(np.diff(s + 1e-3 * w, n=2) ** 2) > np.sum(np.diff(s, n=2) ** 2)


def test_shift_matrices_against_a_finer_quadrature_and_their_identities():
    """M(g) rgb against the model's spectrum interpolated to 0.2 nm, shifted and integrated there; M(1)
    is the identity; white stays white, g^5 brighter; redder light when g < 1."""
    fine = np.arange(380.0, 780.0001, 0.2)
    rng = np.random.default_rng(3)
    for g in (0.6, 0.9, 1.0, 1.15, 1.7):
        m = S.shift_matrix(g)
        for rgb in rng.uniform(0, 1, (4, 3)):
            spec = np.interp(fine, S.LAMBDA_NM, S.spectrum(rgb))
            want = g ** 5 * np.interp(g * fine, fine, spec) @ S.response(fine)
            np.testing.assert_allclose(m @ rgb, want, rtol=2e-3, atol=2e-3 * g ** 5)
        np.testing.assert_allclose(m @ np.ones(3), g ** 5 * np.ones(3), rtol=1e-9)
    np.testing.assert_allclose(S.shift_matrix(1.0), np.eye(3), atol=1e-12)
    ln_g, table = S.shift_table(64)
    np.testing.assert_allclose(table[32] * np.exp(5 * ln_g[32]), S.shift_matrix(np.exp(ln_g[32])), rtol=1e-12)


def test_blackbody_colours_shift_towards_the_hotter_or_cooler_blackbody():
    """The model against the physics it stands in for: the colour of a blackbody at T (2500-20000 K),
    shifted by g = 0.9-1.1, turns bluer or redder as the colour of the blackbody at g T does, within
    0.25 in hue (channels over green) and 10% in brightness."""
    lam = np.arange(300.0, 1200.0, 0.5)
    a = S.response(lam)
    for t in (2500.0, 3000.0, 4000.0, 5000.0, 6500.0, 10000.0, 20000.0):
        rgb = _planck(lam, t) @ a
        for g in (0.9, 0.95, 1.05, 1.1):
            got, want = S.shift_matrix(g) @ rgb, _planck(lam, g * t) @ a
            assert np.sign(got[2] / got[0] - rgb[2] / rgb[0]) == np.sign(want[2] / want[0] - rgb[2] / rgb[0])
            assert np.abs(got / got[1] - want / want[1]).max() < 0.25
            assert abs(got[1] / want[1] - 1) < 0.1


def test_many_matrices_at_once_are_shift_matrix():
    """The vectorised quadrature behind the per-frame tables is shift_matrix's own, to rounding."""
    g = np.array([0.2, 0.25, 0.6, 1.0, 1.37, 4.0, 5.5])
    np.testing.assert_allclose(S._shift_matrices_direct(g), S.shift_matrix(g), rtol=1e-12, atol=1e-12 * g.max() ** 5)


def test_shifted_matrices_against_shift_matrix_over_the_range():
    """shifted_matrices (the cached table, interpolated) against shift_matrix over g = 1/4 .. 4: within
    2e-4 g^5 (a kink of M at each crossing of a 1 nm node limits linear interpolation), hue and
    brightness apart as g_bright^5 M(g_hue) / g_hue^5, rows summing to g_bright^5, the hue clipped to
    LN_G_RANGE (its ends) and the brightness not."""
    rng = np.random.default_rng(5)
    ln_g = np.concatenate([rng.uniform(*S.LN_G_RANGE, 400), list(S.LN_G_RANGE), [0.0]])
    g = np.exp(ln_g)
    got = S.shifted_matrices(ln_g, ln_g)
    want = S.shift_matrix(g)
    err = np.abs(got - want).max((1, 2)) / g ** 5
    assert err.max() < 2e-4, err.max()
    assert err.max() > 1e-6  # (an interpolation, not the quadrature itself)
    np.testing.assert_allclose(S.shifted_matrices(0.0, 0.0), np.eye(3), atol=2e-4)
    ln_b = rng.uniform(-2.0, 2.0, len(ln_g))
    both = S.shifted_matrices(ln_g, ln_b)
    np.testing.assert_allclose(both, got / (g ** 5)[:, None, None] * np.exp(5 * ln_b)[:, None, None], rtol=1e-12)
    np.testing.assert_allclose(both.sum(-1), np.repeat(np.exp(5 * ln_b)[:, None], 3, 1), rtol=1e-8)
    lo, hi = S.LN_G_RANGE
    np.testing.assert_allclose(S.shifted_matrices(hi + 0.7, 0.0), S.shift_matrix(4.0) / 4.0 ** 5, atol=1e-12)
    np.testing.assert_allclose(S.shifted_matrices(lo - 0.7, 0.0), S.shift_matrix(0.25) / 0.25 ** 5, atol=1e-12)
    assert S.shifted_matrices(np.zeros((2, 5)), np.zeros((2, 5))).shape == (2, 5, 3, 3)
