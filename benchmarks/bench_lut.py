"""LUT benchmark: build time and interpolation error against the exact solver.

For table sizes 64x128 ... 1024x2048 and observers at r_obs in {10, 20, 30} r_s (radial range
[1.25, 15] r_s, as in seed 000 table 2) it prints the build time (best of --repeat runs, all CPUs)
and the lookup error of xi (radians) and dt (relative) against lutgen.connect at --points random
points (uniform in x = r_s/r and in phi, excluding 1e-3 rad next to phi = 0 and phi = pi), both
orders together: max, p99 and median. It also checks table nodes against the independent
numerical integrator (lutgen.reference) at --nodes random nodes of the 256x512 table.

Writes a markdown table (--markdown) and a run-time-vs-error plot (--plot), used in docs/LUT.md.
Usage: ./dev bench [--quick] [--markdown docs/lut_benchmark.md] [--plot docs/lut_benchmark.png]
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from lutgen import build_lut, connect  # noqa: E402

SIZES = [(64, 128), (128, 256), (256, 512), (512, 1024), (1024, 2048)]
R_OBS = [10.0, 20.0, 30.0]
R_MIN, R_MAX = 1.25, 15.0


def lookup_errors(lut, r, phi, exact):
    e_xi, e_dt = [], []
    for o in (1, 2):
        got = lut.lookup(r, phi, o)
        e_xi.append(np.abs(got.xi - exact[o].xi))
        e_dt.append(np.abs(got.dt / exact[o].dt - 1.0))
    e_xi, e_dt = np.concatenate(e_xi), np.concatenate(e_dt)
    return {"xi": (e_xi.max(), np.percentile(e_xi, 99), np.median(e_xi)),
            "dt": (e_dt.max(), np.percentile(e_dt, 99), np.median(e_dt))}


def node_accuracy(r_obs, n_nodes, rng):
    """Max |xi - xi_ref| and |dt/dt_ref - 1| over random nodes of a 256x512 table, against the
    DOP853 integrator (independent of the closed form)."""
    from lutgen.reference import connect_numeric

    lut = build_lut(r_obs, R_MIN, R_MAX, 256, 512)
    ix = rng.integers(0, lut.n_r, n_nodes)
    ip = rng.integers(1, lut.n_phi - 1, n_nodes)
    worst_xi = worst_dt = 0.0
    for i, j in zip(ix, ip):
        r, phi = 1.0 / lut.x_nodes[i], lut.phi_nodes[j]
        for o in (1, 2):
            xi, dt, _, _ = connect_numeric(r_obs, r, phi, o)
            worst_xi = max(worst_xi, abs(lut.channel(o, "xi")[i, j] - xi))
            worst_dt = max(worst_dt, abs(lut.channel(o, "dt")[i, j] / dt - 1.0))
    return worst_xi, worst_dt


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="sizes up to 256x512 only, 2e4 points")
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--nodes", type=int, default=40, help="nodes checked against the integrator (0: skip)")
    ap.add_argument("--markdown", default=None)
    ap.add_argument("--plot", default=None)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", RuntimeWarning)
    sizes = SIZES[:3] if args.quick else SIZES
    n_pts = 20_000 if args.quick else args.points
    rng = np.random.default_rng(2026)

    lines = [f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs; "
             f"numpy {np.__version__}; radial range [{R_MIN}, {R_MAX}] r_s; {n_pts} random points",
             "",
             "| r_obs | size | build [s] | xi err max | xi err p99 | xi err median | dt rel max | dt rel p99 | dt rel median |",
             "|---|---|---|---|---|---|---|---|---|"]
    print("\n".join(lines), flush=True)
    rows = []
    for r_obs in R_OBS:
        x = rng.uniform(1.0 / R_MAX, 1.0 / R_MIN, n_pts)
        r = 1.0 / x
        phi = rng.uniform(1e-3, np.pi - 1e-3, n_pts)
        exact = {o: connect(r_obs, r, phi, o) for o in (1, 2)}
        for n_r, n_phi in sizes:
            times = []
            for _ in range(args.repeat if n_r <= 512 else 1):
                t0 = time.perf_counter()
                lut = build_lut(r_obs, R_MIN, R_MAX, n_r, n_phi)
                times.append(time.perf_counter() - t0)
            err = lookup_errors(lut, r, phi, exact)
            row = (r_obs, f"{n_r}x{n_phi}", min(times), *err["xi"], *err["dt"])
            rows.append(row)
            line = (f"| {r_obs:g} | {row[1]} | {row[2]:.3f} | " +
                    " | ".join(f"{v:.2e}" for v in row[3:]) + " |")
            lines.append(line)
            print(line, flush=True)
    if args.nodes:
        lines.append("")
        for r_obs in R_OBS:
            wx, wd = node_accuracy(r_obs, args.nodes, rng)
            line = (f"nodes of the 256x512 table at r_obs = {r_obs:g} vs the DOP853 integrator "
                    f"({args.nodes} nodes, both orders): max |xi err| = {wx:.1e} rad, max |dt rel err| = {wd:.1e}")
            lines.append(line)
            print(line, flush=True)
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write("\n".join(lines) + "\n")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
        for r_obs in R_OBS:
            rr = [row for row in rows if row[0] == r_obs]
            ax.loglog([row[2] for row in rr], [row[4] for row in rr], "o-", label=f"xi p99, r_obs = {r_obs:g}")
            ax.loglog([row[2] for row in rr], [row[3] for row in rr], "x--", alpha=0.6,
                      label=f"xi max, r_obs = {r_obs:g}")
            for row in rr:
                ax.annotate(row[1], (row[2], row[4]), fontsize=7)
        ax.axhline(1.6e-5, color="k", lw=0.8, ls=":")
        ax.text(ax.get_xlim()[0], 1.9e-5, " 0.05 px at 1920x1080, 20 deg fov", fontsize=8)
        ax.set_xlabel("LUT build time [s]")
        ax.set_ylabel("lookup error in xi [rad]")
        ax.legend(fontsize=7)
        fig.savefig(args.plot, dpi=100)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
