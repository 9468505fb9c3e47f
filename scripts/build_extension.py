#!/usr/bin/env python3
"""Build the grlens Blender extension: one zip per platform in dist/, ready for "Install from Disk".

    ./dev python scripts/build_extension.py                        # all platforms of the manifest
    ./dev python scripts/build_extension.py --platform linux-x64   # just one (faster)

Steps:
1. builds the pure-Python `lutgen` wheel from this repository's pyproject.toml into wheels/;
2. downloads, per platform, the scipy and OpenEXR wheels pinned in requirements/dev.txt from PyPI
   (`pip download --only-binary=:all: --no-deps --python-version 3.11 --platform <tags>`), reusing
   wheels already in wheels/;
3. checks that these file names are exactly the `wheels` list of blender_manifest.toml (so the
   manifest cannot drift) and that numpy is never bundled (Blender ships its own);
4. runs Blender's own packer, `blender_ext.py build --source-dir . --output-dir dist
   --split-platforms`, from the pip `bpy` module with this plain Python (no Blender binary), and
   prints the zips written.
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MANIFEST = ROOT / "blender_manifest.toml"
WHEEL_DIR = ROOT / "wheels"
REQUIREMENTS = ROOT / "requirements" / "dev.txt"

PYTHON_VERSION = "3.11"  # Blender 4.2 - 5.0
# pip --platform tags per Blender platform. pip expands a macosx_X_Y tag to all older macOS versions
# but does not expand manylinux tags: scipy 1.15.3's Linux wheel is manylinux2014 (= manylinux_2_17),
# OpenEXR 3.5.3's is manylinux_2_28 only. macOS: Blender needs 11.2+; scipy 1.15.3 has no arm64 wheel
# older than macOS 12 (macosx_11_0_x86_64 picks scipy's 10_13 wheel, not the macOS 14 Accelerate one).
PLATFORM_TAGS = {
    "linux-x64": ["manylinux2014_x86_64", "manylinux_2_28_x86_64"],
    "windows-x64": ["win_amd64"],
    "macos-x64": ["macosx_11_0_x86_64"],
    "macos-arm64": ["macosx_12_0_arm64"],
}
DOWNLOADED = ["scipy", "OpenEXR"]  # versions come from requirements/dev.txt (the tested ones)
LOCAL_WHEEL = "lutgen"             # built from pyproject.toml
NEVER_BUNDLE = {"numpy"}           # all extensions share one site-packages ahead of Blender's own


class BuildError(Exception):
    pass


def log(msg):
    print(f"build_extension: {msg}", flush=True)


def norm(name):
    """Project name as it appears in wheel file names (PEP 427/503, compared in lower case)."""
    return re.sub(r"[-_.]+", "_", name).lower()


def wheel_project(filename):
    return norm(filename.split("-", 1)[0])


def pinned_versions():
    text = REQUIREMENTS.read_text()
    pins = {}
    for name in DOWNLOADED:
        m = re.search(rf"^{re.escape(name)}==([^\s#;]+)", text, re.MULTILINE | re.IGNORECASE)
        if not m:
            raise BuildError(f"{REQUIREMENTS.relative_to(ROOT)} has no '{name}==<version>' pin")
        pins[name] = m.group(1)
    return pins


def find_blender_ext():
    spec = importlib.util.find_spec("bpy")  # locates the package without importing it
    if spec is None or not spec.submodule_search_locations:
        raise BuildError("the pip 'bpy' module is not installed in this Python (use ./dev python ...)")
    found = []
    for loc in spec.submodule_search_locations:
        found += sorted(Path(loc).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        raise BuildError("blender_ext.py not found inside the bpy module")
    return found[-1]


def load_module(path, name="blender_ext"):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def read_manifest(blender_ext):
    with open(MANIFEST, "rb") as fh:
        data = tomllib.load(fh)
    errors = blender_ext.pkg_manifest_from_dict_and_validate_all_errros(data, from_repo=False, strict=True)
    if isinstance(errors, list):
        raise BuildError("blender_manifest.toml is invalid:\n  " + "\n  ".join(errors))
    wheels = data.get("wheels") or []
    platforms = data.get("platforms") or []
    for w in wheels:
        if not w.startswith("./wheels/") or "/" in w[len("./wheels/"):]:
            raise BuildError(f"manifest wheel {w!r}: expected './wheels/<file>.whl'")
        if wheel_project(os.path.basename(w)) in NEVER_BUNDLE:
            raise BuildError(f"manifest lists {w!r}: never bundle numpy (it would replace Blender's "
                             "numpy for every add-on)")
    unknown = [p for p in platforms if p not in PLATFORM_TAGS]
    if unknown:
        raise BuildError(f"manifest platforms {unknown} have no pip tags in PLATFORM_TAGS of {__file__}")
    return data, [os.path.basename(w) for w in wheels], platforms


def expected_wheels(blender_ext, manifest_wheels, platform, pins):
    """The downloaded wheels the manifest lists for this platform (by Blender's own platform filter)."""
    want = [w for w in manifest_wheels if wheel_project(w) != norm(LOCAL_WHEEL)
            and blender_ext.blender_platform_compatible_with_wheel_platform_from_filepath(platform, w)]
    for name, version in pins.items():
        hits = [w for w in want if w.lower().startswith(f"{norm(name)}-{version}-".lower())]
        if len(hits) != 1:
            raise BuildError(f"blender_manifest.toml must list exactly one {name} {version} wheel for "
                             f"{platform} (requirements/dev.txt pins {name}=={version}); it lists {hits}")
    extra = [w for w in want if wheel_project(w) not in {norm(n) for n in pins}]
    if extra:
        raise BuildError(f"blender_manifest.toml lists unexpected wheels for {platform}: {extra}")
    return sorted(want)


def run(cmd, **kw):
    return subprocess.run(cmd, text=True, capture_output=True, **kw)


def build_lutgen_wheel(expected):
    """`pip wheel . --no-deps` on a clean copy of the package sources (no build/ or egg-info left in
    the repository), then the wheel's name must be the manifest's."""
    with open(ROOT / "pyproject.toml", "rb") as fh:
        pyproject = tomllib.load(fh)
    packages = pyproject.get("tool", {}).get("setuptools", {}).get("packages", [LOCAL_WHEEL])
    with tempfile.TemporaryDirectory(prefix="grlens-lutgen-") as tmp:
        src, out = Path(tmp) / "src", Path(tmp) / "out"
        src.mkdir()
        for f in ROOT.iterdir():
            if f.is_file() and (f.name == "pyproject.toml" or f.name.upper().startswith(("README", "LICENSE", "COPYING"))):
                shutil.copy2(f, src / f.name)
        for pkg in packages:
            top = pkg.split(".")[0]
            if not (src / top).exists():
                shutil.copytree(ROOT / top, src / top, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        cmd = [sys.executable, "-m", "pip", "wheel", "--disable-pip-version-check", "--no-deps", "-q",
               "-w", str(out), str(src)]
        r = run(cmd)  # in an isolated build environment (setuptools from PyPI, like the downloads)
        if r.returncode != 0:
            raise BuildError(f"building the {LOCAL_WHEEL} wheel failed (pip fetches the build backend, "
                             f"setuptools, from PyPI: is it reachable?):\n  {' '.join(cmd)}\n"
                             + "\n".join((r.stdout + r.stderr).strip().splitlines()[-15:]))
        built = sorted(p.name for p in out.glob("*.whl"))
        if built != [expected]:
            raise BuildError(f"the {LOCAL_WHEEL} wheel built is {built}, blender_manifest.toml lists "
                             f"{expected!r}: update the manifest's wheels (or the version in pyproject.toml)")
        with zipfile.ZipFile(out / expected) as zf:
            names = zf.namelist()
        if f"{LOCAL_WHEEL}/__init__.py" not in names:
            raise BuildError(f"{expected} has no {LOCAL_WHEEL}/__init__.py")
        WHEEL_DIR.mkdir(exist_ok=True)
        tmp_dst = WHEEL_DIR / f".{expected}.part"
        shutil.copyfile(out / expected, tmp_dst)
        os.replace(tmp_dst, WHEEL_DIR / expected)
    log(f"built wheels/{expected}")


def fetch_platform_wheels(platform, expected, pins, refresh):
    if not refresh and all((WHEEL_DIR / w).is_file() for w in expected):
        log(f"{platform}: reusing wheels/ " + ", ".join(expected))
        return
    WHEEL_DIR.mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=f".download-{platform}-", dir=WHEEL_DIR) as tmp:
        cmd = [sys.executable, "-m", "pip", "download", "--disable-pip-version-check", "--progress-bar", "off",
               "--only-binary=:all:", "--no-deps", "--implementation", "cp", "--python-version", PYTHON_VERSION]
        for tag in PLATFORM_TAGS[platform]:
            cmd += ["--platform", tag]
        cmd += ["-d", tmp] + [f"{name}=={version}" for name, version in pins.items()]
        log(f"{platform}: downloading " + " ".join(f"{n}=={v}" for n, v in pins.items())
            + " (" + " ".join(PLATFORM_TAGS[platform]) + ")")
        r = run(cmd)
        if r.returncode != 0:
            raise BuildError(f"pip download for {platform} failed (is PyPI reachable?):\n  {' '.join(cmd)}\n"
                             + "\n".join((r.stdout + r.stderr).strip().splitlines()[-15:]))
        got = sorted(os.listdir(tmp))
        if got != expected:
            raise BuildError(
                f"{platform}: pip downloaded {got}\n  but blender_manifest.toml lists {expected}:\n"
                "  update the manifest's wheels = [...] (or the tags in PLATFORM_TAGS) so they agree")
        for w in got:
            os.replace(os.path.join(tmp, w), WHEEL_DIR / w)
    log(f"{platform}: downloaded " + ", ".join(expected))


# Runs blender_ext.py's `main` with its platform loop narrowed to the requested platforms (the packer
# has no option for that; each zip is otherwise exactly what the full build writes).
_SUBSET_RUNNER = r"""
import importlib.util, sys
path, wanted = sys.argv[1], sys.argv[2].split(",")
spec = importlib.util.spec_from_file_location("blender_ext", path)
mod = importlib.util.module_from_spec(spec)
sys.modules["blender_ext"] = mod
spec.loader.exec_module(mod)
full = mod.build_paths_filter_by_platform
def subset(build_paths, wheel_range, platforms):
    return full(build_paths, wheel_range, tuple(p for p in platforms if p in wanted))
mod.build_paths_filter_by_platform = subset
sys.exit(mod.main(sys.argv[3:]))
"""


def pack(blender_ext_path, blender_ext, data, platforms, all_platforms, output_dir):
    output_dir.mkdir(parents=True, exist_ok=True)
    args = ["build", "--source-dir", str(ROOT), "--output-dir", str(output_dir), "--split-platforms"]
    if platforms == all_platforms:
        cmd = [sys.executable, str(blender_ext_path), *args]
    else:
        if not hasattr(blender_ext, "build_paths_filter_by_platform"):
            raise BuildError("this blender_ext.py cannot build a subset of platforms: omit --platform")
        cmd = [sys.executable, "-c", _SUBSET_RUNNER, str(blender_ext_path), ",".join(platforms), *args]
    log("packing: blender_ext.py " + " ".join(args))
    r = run(cmd, cwd=ROOT)
    sys.stdout.write(r.stdout)
    sys.stderr.write(r.stderr)
    if r.returncode != 0:
        raise BuildError(f"blender_ext.py build failed (exit {r.returncode})")
    zips = [output_dir / f"{data['id']}-{data['version']}-{p.replace('-', '_')}.zip" for p in platforms]
    missing = [str(z) for z in zips if not z.is_file()]
    if missing:
        raise BuildError(f"blender_ext.py did not write {missing}")
    return zips


def check_zip(path, wheels):
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    in_zip = sorted(n.split("/", 1)[1] for n in names if n.startswith("wheels/"))
    if in_zip != sorted(wheels):
        raise BuildError(f"{path.name}: wheels {in_zip}, expected {sorted(wheels)}")
    if any(wheel_project(w) in NEVER_BUNDLE for w in in_zip):
        raise BuildError(f"{path.name} bundles numpy")
    if "__init__.py" not in names or "blender_manifest.toml" not in names:
        raise BuildError(f"{path.name} lacks __init__.py or blender_manifest.toml at its root")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--platform", action="append", choices=sorted(PLATFORM_TAGS),
                    help="build only this platform (repeatable); default: all platforms of the manifest")
    ap.add_argument("--output-dir", default=str(ROOT / "dist"), help="where the zips go (default: dist/)")
    ap.add_argument("--refresh", action="store_true", help="download the wheels again even if cached")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    try:
        blender_ext_path = find_blender_ext()
        blender_ext = load_module(blender_ext_path)
        data, manifest_wheels, all_platforms = read_manifest(blender_ext)
        platforms = [p for p in all_platforms if p in (args.platform or all_platforms)]
        absent = sorted(set(args.platform or []) - set(all_platforms))
        if absent:
            raise BuildError(f"--platform {absent}: not in the manifest's platforms {all_platforms}")
        pins = pinned_versions()

        local = [w for w in manifest_wheels if wheel_project(w) == norm(LOCAL_WHEEL)]
        if len(local) != 1:
            raise BuildError(f"blender_manifest.toml must list exactly one {LOCAL_WHEEL} wheel, found {local}")
        per_platform = {p: expected_wheels(blender_ext, manifest_wheels, p, pins) for p in all_platforms}
        accounted = set(local).union(*per_platform.values())
        stray = sorted(set(manifest_wheels) - accounted)
        if stray:
            raise BuildError(f"blender_manifest.toml lists wheels for no platform of the manifest: {stray}")

        build_lutgen_wheel(local[0])
        for p in platforms:
            fetch_platform_wheels(p, per_platform[p], pins, args.refresh)

        zips = pack(blender_ext_path, blender_ext, data, platforms, all_platforms, Path(args.output_dir))
        for p, z in zip(platforms, zips):
            check_zip(z, local + per_platform[p])
    except BuildError as ex:
        print(f"build_extension: error: {ex}", file=sys.stderr)
        return 1
    log(f"done in {time.perf_counter() - t0:.1f} s; wrote:")
    for z in zips:
        print(f"  {z}  ({z.stat().st_size / 1e6:.1f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
