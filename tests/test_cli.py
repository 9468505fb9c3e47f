"""python -m lutgen: connect / build / plot / info, and clear errors."""
import json
import math
import subprocess
import sys

import pytest

from lutgen import connect


def run(*args, check=True):
    p = subprocess.run([sys.executable, "-m", "lutgen", *args], capture_output=True, text=True, timeout=300)
    if check:
        assert p.returncode == 0, p.stderr
    return p


def test_connect_prints_json():
    p = run("connect", "--r-obs", "20", "--r", "3.3", "--phi", "90", "--order", "1")
    out = json.loads(p.stdout)
    assert set(out) == {"xi_deg", "dt", "ux", "uy"}
    c = connect(20.0, 3.3, math.pi / 2, 1)
    assert out["xi_deg"] == pytest.approx(math.degrees(c.xi), abs=1e-12)
    assert out["dt"] == pytest.approx(float(c.dt), rel=1e-14)


def test_connect_inside_horizon_is_null():
    out = json.loads(run("connect", "--r-obs", "20", "--r", "0.5", "--phi", "10").stdout)
    assert out == {"xi_deg": None, "dt": None, "ux": None, "uy": None}


def test_bad_observer_is_a_clear_error():
    p = run("connect", "--r-obs", "1.0005", "--r", "3", "--phi", "10", check=False)
    assert p.returncode == 2 and "1.001" in p.stderr


def test_connect_inside_the_photon_sphere():
    out = json.loads(run("connect", "--r-obs", "1.2", "--r", "3", "--phi", "10").stdout)
    c = connect(1.2, 3.0, math.radians(10.0), 1)
    assert out["xi_deg"] == pytest.approx(math.degrees(float(c.xi)), rel=1e-12) and out["xi_deg"] < 90.0


def test_build_plot_info(tmp_path):
    exr, png = tmp_path / "t.exr", tmp_path / "t.png"
    run("build", "--r-obs", "20", "--r-min", "1.25", "--r-max", "15", "--size", "32x64", "-o", str(exr))
    info = json.loads(run("info", str(exr)).stdout)
    assert info == {"r_obs": 20.0, "r_min": 1.25, "r_max": 15.0, "n_r": 32, "n_phi": 64}
    p = run("build", "--r-obs", "20", "--size", "32x64", "-o", str(exr))
    assert "\r" not in p.stderr  # no progress bar when stderr is not a terminal
    run("plot", str(exr), "-o", str(png))
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_of_corrupt_file_is_a_clear_error(tmp_path):
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"not an exr at all")
    p = run("plot", str(bad), "-o", str(tmp_path / "x.png"), check=False)
    assert p.returncode == 2 and str(bad) in p.stderr


def test_bad_size_argument():
    p = run("build", "--r-obs", "20", "--size", "big", "-o", "x.exr", check=False)
    assert p.returncode == 2 and "256x512" in p.stderr
