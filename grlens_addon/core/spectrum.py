"""The colours of shifted light: what an RGB colour becomes when its light reaches the camera with the
frequency ratio g = nu_seen / nu_emitted = 1 / (1 + z).

Physics. I_nu / nu^3 is invariant along a ray, so the specific intensity seen at frequency nu is
I_seen(nu) = g^3 I_emitted(nu / g); per unit wavelength, L_seen(lambda) = g^5 L_emitted(g lambda).
The colour seen is that spectrum through the RGB response, so the shift of hue and the change of
brightness (g^4 in total power) come from one integral, and no power of g is counted twice.

The spectrum model (an RGB colour has no spectrum of its own): the smoothest spectrum whose RGB is
the colour, in the sense of least squared curvature (sum of squared second differences of 1 nm
samples on 380-780 nm), continued flat beyond both ends: the least-curvature variant of Burns'
least-slope-squared reconstruction (S. A. Burns, "Numerical methods for smoothest reflectance
reconstruction", Color Research & Application 45, 2020). Least curvature rather than least slope:
for blackbody colours (2500-20000 K) shifted by g = 0.9-1.1 it moves every hue the way the exact
blackbody at g T lies (least slope got 10 of 28 such cases backwards), with a median hue error of
0.03 against 0.17. It is linear, so the shifted colour is M(g) rgb, a 3 x 3 matrix per g
(:func:`shift_matrix`); white (1, 1, 1) is the flat spectrum, which a shift leaves white (g^5
brighter per wavelength). Saturated colours have spectra with negative parts: their shifted colours
can leave the gamut (the node group clips negative channels). The RGB response: the CIE 1931 2-degree colour
matching functions (thin_disc.cie1931_cmf, the fit of Wyman, Sloan & Shirley 2013) through
XYZ -> linear Rec.709 (thin_disc.XYZ_TO_LINEAR_SRGB), each channel normalised so that the flat
spectrum is (1, 1, 1).

Units: wavelengths in nm; g dimensionless; colours linear Rec.709 (Blender's scene linear).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from .thin_disc import XYZ_TO_LINEAR_SRGB, cie1931_cmf

LAMBDA_NM = np.arange(380.0, 781.0, 1.0)
"""The model's wavelengths (nm)."""


def response(lam_nm) -> np.ndarray:
    """(N, 3) weights A of the RGB response at wavelengths ``lam_nm`` (N,; nm, evenly spaced): the RGB of
    a spectrum sampled there is A^T spectrum, normalised so that a flat spectrum gives (1, 1, 1)."""
    rgb_bar = cie1931_cmf(np.asarray(lam_nm, dtype=np.float64)) @ XYZ_TO_LINEAR_SRGB.T  # (N, 3)
    return rgb_bar / rgb_bar.sum(axis=0)


@lru_cache(maxsize=1)
def basis() -> np.ndarray:
    """(N, 3) the model's spectra of the unit colours (1, 0, 0), (0, 1, 0), (0, 0, 1) on LAMBDA_NM: the
    smoothest (least sum of squared second differences) spectra whose RGB are those colours (the KKT
    system of that constrained least squares, solved once)."""
    a = response(LAMBDA_NM)
    n = len(LAMBDA_NM)
    d = np.diff(np.eye(n), n=2, axis=0)  # (n - 2, n) second differences
    kkt = np.zeros((n + 3, n + 3))
    kkt[:n, :n] = 2.0 * d.T @ d
    kkt[:n, n:] = a
    kkt[n:, :n] = a.T
    rhs = np.zeros((n + 3, 3))
    rhs[n:] = np.eye(3)
    return np.linalg.solve(kkt, rhs)[:n]


def spectrum(rgb) -> np.ndarray:
    """(..., N) the model's spectrum (per unit wavelength, on LAMBDA_NM) of linear Rec.709 colours
    ``rgb`` (..., 3)."""
    return np.asarray(rgb, dtype=np.float64) @ basis().T


def shifted_rgb(spectra, g, lam_nm=LAMBDA_NM) -> np.ndarray:
    """(..., 3) the colour seen of light with the spectra ``spectra`` (..., N; per unit wavelength,
    sampled at ``lam_nm``, continued flat beyond its ends) arriving with the frequency ratio ``g``
    (broadcast against the leading axes): the RGB of g^5 L(g lambda)."""
    spectra = np.asarray(spectra, dtype=np.float64)
    g = np.asarray(g, dtype=np.float64)
    lam = np.asarray(lam_nm, dtype=np.float64)
    a = response(lam)
    lead = np.broadcast_shapes(spectra.shape[:-1], g.shape)
    s = np.broadcast_to(spectra, lead + spectra.shape[-1:]).reshape(-1, len(lam))
    gg = np.broadcast_to(g, lead).reshape(-1)
    out = np.empty((len(gg), 3))
    for i in range(len(gg)):
        out[i] = gg[i] ** 5 * (np.interp(gg[i] * lam, lam, s[i]) @ a)
    return out.reshape(lead + (3,))


def shift_matrix(g) -> np.ndarray:
    """(..., 3, 3) M(g): the colour seen is M(g) rgb for the emitted colour rgb (linear Rec.709) whose
    light arrives with the frequency ratio ``g`` (...,); M(1) is the identity, M(g) (1, 1, 1) =
    g^5 (1, 1, 1)."""
    g = np.asarray(g, dtype=np.float64)
    cols = shifted_rgb(basis().T, g[..., None])  # (..., 3 basis colours, 3 channels)
    return np.swapaxes(cols, -1, -2)


LN_G_RANGE = (-np.log(4.0), np.log(4.0))
"""The range of ln g the node group's table covers (g from 1/4 to 4; beyond, its ends, which the
model's flat continuation makes a plain brightening or dimming anyway)."""


def shift_table(n: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """(ln g (n,), M(g) / g^5 (n, 3, 3)) on LN_G_RANGE, evenly in ln g: the node group's curves (the
    factor g^5 is applied in its math nodes, so the curves stay of order 1)."""
    ln_g = np.linspace(*LN_G_RANGE, n)
    g = np.exp(ln_g)
    return ln_g, shift_matrix(g) / (g**5)[:, None, None]


def _shift_matrices_direct(g) -> np.ndarray:
    """(len(g), 3, 3) M(g) of :func:`shift_matrix` for many g at once (g (n,) > 0): the same
    quadrature (the 1 nm spectra interpolated linearly at g lambda, flat beyond both ends), its
    interpolation done by index arithmetic on the evenly spaced wavelengths instead of np.interp per g."""
    g = np.asarray(g, dtype=np.float64).reshape(-1)
    lam = LAMBDA_NM
    a = response(lam)  # (N, 3)
    spectra = basis().T  # (3 basis colours, N)
    p = np.clip(g[:, None] * lam[None, :], lam[0], lam[-1]) - lam[0]  # (n, N), 1 nm steps
    i = np.minimum(np.floor(p).astype(np.intp), len(lam) - 2)
    w = p - i
    out = np.empty((len(g), 3, 3))
    for b in range(3):  # rows of M are channels, columns the basis colours
        s = spectra[b]
        out[:, :, b] = (s[i] * (1.0 - w) + s[i + 1] * w) @ a
    return out * (g**5)[:, None, None]


FINE_POINTS = 1025
"""Nodes of the cached table behind :func:`shifted_matrices`, evenly in ln g over LN_G_RANGE (steps of
2.7e-3; built once, about 0.03 s). M(g) has a small kink wherever g lambda crosses a node of the 1 nm
spectra, so linear interpolation converges only as the first power of the step: within 1.6e-4 here,
7e-5 with 2049 nodes."""


@lru_cache(maxsize=1)
def _fine_table() -> tuple[np.ndarray, np.ndarray]:
    ln_g = np.linspace(*LN_G_RANGE, FINE_POINTS)
    return ln_g, _shift_matrices_direct(np.exp(ln_g)) / np.exp(5.0 * ln_g)[:, None, None]


def shifted_matrices(ln_g_hue, ln_g_bright) -> np.ndarray:
    """(..., 3, 3) the matrices of light whose hue is shifted by g_hue and brightness by g_bright
    (natural logarithms ``ln_g_hue``, ``ln_g_bright``, broadcast together): M(g_hue) / g_hue^5 times
    g_bright^5, the colour seen of the emitted colour rgb being that matrix times rgb. ln g_hue is
    clipped to LN_G_RANGE, as in the node group "grlens Shift by g" (beyond, the flat continuation makes
    the shift a plain change of brightness anyway); the brightness is not. With g_hue = g_bright = g
    inside the range it is M(g) (:func:`shift_matrix`), here from a cached table of FINE_POINTS nodes
    interpolated linearly (within 2e-4 g_bright^5 of shift_matrix, tests/test_spectrum.py), fast enough
    for a table per frame (1024 matrices in 0.2 ms). Each row sums to g_bright^5 (white stays white)."""
    hue, bright = np.broadcast_arrays(np.asarray(ln_g_hue, dtype=np.float64),
                                      np.asarray(ln_g_bright, dtype=np.float64))
    ln_tab, tab = _fine_table()
    x = (np.clip(hue, *LN_G_RANGE) - ln_tab[0]) / (ln_tab[1] - ln_tab[0])
    i = np.minimum(np.floor(x).astype(np.intp), len(ln_tab) - 2)
    w = (x - i)[..., None, None]
    m = tab[i] * (1.0 - w) + tab[i + 1] * w
    return m * np.exp(5.0 * bright)[..., None, None]
