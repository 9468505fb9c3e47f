"""Command line interface: ``python -m lutgen {connect,build,plot,info}``.

Units: radii in r_s (Schwarzschild radii), angles in degrees on the command line, times in r_s/c.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time


def _size(text: str) -> tuple[int, int]:
    try:
        a, b = text.lower().split("x")
        return int(a), int(b)
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 256x512 (n_r x n_phi), got {text!r}") from None


class _Progress:
    """A one-line progress bar on stderr when it is a terminal; silent otherwise."""

    def __init__(self, label: str, stream=None):
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty()
        self.label = label
        self.t0 = time.perf_counter()

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled:
            return
        width = 30
        filled = int(width * done / max(total, 1))
        bar = "#" * filled + "-" * (width - filled)
        self.stream.write(f"\r{self.label} [{bar}] {done}/{total} {time.perf_counter() - self.t0:5.1f} s")
        if done >= total:
            self.stream.write("\n")
        self.stream.flush()


def _cmd_connect(args) -> int:
    from .solver import connect

    c = connect(args.r_obs, args.r, math.radians(args.phi), args.order)
    out = {"xi_deg": math.degrees(float(c.xi)), "dt": float(c.dt), "ux": float(c.ux), "uy": float(c.uy)}
    # JSON has no NaN: points no ray of this order reaches are reported as null.
    print(json.dumps({k: (None if math.isnan(v) else v) for k, v in out.items()}))
    return 0


def _cmd_build(args) -> int:
    from .lut import build_lut

    n_r, n_phi = args.size
    t0 = time.perf_counter()
    lut = build_lut(args.r_obs, args.r_min, args.r_max, n_r, n_phi,
                    progress=_Progress(f"building {n_r}x{n_phi} LUT"), workers=args.workers)
    t_build = time.perf_counter() - t0
    lut.save(args.output)
    print(f"wrote {args.output}: r_obs = {lut.r_obs} r_s, r in [{lut.r_min}, {lut.r_max}] r_s, "
          f"{n_r}x{n_phi}, built in {t_build:.2f} s", file=sys.stderr)
    return 0


def _cmd_plot(args) -> int:
    from .lutfile import load_lut
    from .plot import plot_lut

    plot_lut(load_lut(args.lut), args.output)
    print(f"wrote {args.output}", file=sys.stderr)
    return 0


def _cmd_info(args) -> int:
    from .lutfile import load_lut

    lut = load_lut(args.lut)
    print(json.dumps(lut.parameters))
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lutgen", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    c = sub.add_parser("connect", help="print the connecting ray between observer and one point as JSON")
    c.add_argument("--r-obs", type=float, required=True, help="observer radius (r_s), > 1.5")
    c.add_argument("--r", type=float, required=True, help="target radius (r_s)")
    c.add_argument("--phi", type=float, required=True, help="target angle (degrees, 0..180)")
    c.add_argument("--order", type=int, default=1, choices=(1, 2), help="image order (default 1)")
    c.set_defaults(func=_cmd_connect)

    b = sub.add_parser("build", help="build a lookup table and write it as OpenEXR")
    b.add_argument("--r-obs", type=float, required=True, help="observer radius (r_s), > 1.5")
    b.add_argument("--r-min", type=float, default=1.25, help="smallest radius (r_s), default 1.25")
    b.add_argument("--r-max", type=float, default=15.0, help="largest radius (r_s), default 15")
    b.add_argument("--size", type=_size, default=(256, 512), help="n_r x n_phi, default 256x512")
    b.add_argument("--workers", type=int, default=None, help="threads (default: all CPUs)")
    b.add_argument("-o", "--output", required=True, help="output .exr path")
    b.set_defaults(func=_cmd_build)

    pl = sub.add_parser("plot", help="draw the channels of a lookup table to a PNG")
    pl.add_argument("lut", help="input .exr written by 'lutgen build'")
    pl.add_argument("-o", "--output", required=True, help="output .png path")
    pl.set_defaults(func=_cmd_plot)

    i = sub.add_parser("info", help="print a lookup table's parameters as JSON")
    i.add_argument("lut")
    i.set_defaults(func=_cmd_info)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, OSError) as exc:  # bad parameters, unreadable/corrupt files: one clear line
        print(f"lutgen {args.command}: error: {exc}", file=sys.stderr)
        return 2
