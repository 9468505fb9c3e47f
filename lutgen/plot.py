"""Pictures of a lookup table (like figure 4 of seed 000): one panel per order and quantity.

Axes: x = r_s/r (vertical, as stored: row 0 = 1/r_max at the bottom) and phi in degrees
(horizontal). Needs matplotlib (the ``plot`` extra); nothing else in lutgen does.
"""
from __future__ import annotations

import numpy as np

from .lut import LUT, QUANTITIES

_LABELS = {"xi": "xi [deg]", "dt": "dt [r_s/c]", "ux": "u^x", "uy": "u^y"}


def plot_lut(lut: LUT, path) -> None:
    """Write a PNG with the 2 x 4 channels of ``lut`` (grey maps with colour bars) to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 4, figsize=(16, 7.5), constrained_layout=True)
    extent = (0.0, 180.0, lut.x_min, lut.x_max)
    for o in (1, 2):
        for q, name in enumerate(QUANTITIES):
            ax = axes[o - 1, q]
            img = lut.channel(o, name)
            if name == "xi":
                img = np.degrees(img)
            im = ax.imshow(img, origin="lower", aspect="auto", extent=extent, cmap="gray",
                           interpolation="nearest")
            ax.set_title(f"order {o}: {_LABELS[name]}")
            ax.set_xlabel("phi [deg]")
            ax.set_ylabel("x = r_s / r")
            fig.colorbar(im, ax=ax, shrink=0.85)
    fig.suptitle(f"grlens LUT: r_obs = {lut.r_obs:g} r_s, r in [{lut.r_min:g}, {lut.r_max:g}] r_s, "
                 f"{lut.n_r} x {lut.n_phi}")
    fig.savefig(path, dpi=80)
    plt.close(fig)
