"""The extension zip: built by scripts/build_extension.py, installed into the pip `bpy` module.

Builds the linux-x64 zip once (needs PyPI for the scipy/OpenEXR wheels the first time and for the
lutgen wheel's build backend), then installs it in fresh Python processes with their own
BLENDER_USER_RESOURCES, so nothing registered there leaks into the other tests:

1. install + enable: the add-on `bl_ext.user_default.grlens` is enabled and registered, `lutgen`
   comes from the extension wheels and works;
2. a second process (= restarting Blender; a wheels folder created during a session is appended
   behind the site-packages, found at startup it goes ahead of them): scipy, OpenEXR and lutgen come
   from the extension's site-packages, numpy is still Blender's own 1.26; then disable and uninstall,
   which removes the package and its wheels.
"""
import json
import math
import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PLATFORM = "linux-x64"
MODULE = "bl_ext.user_default.grlens"
ALLOWED_TOP_LEVEL = {"blender_manifest.toml", "__init__.py", "grlens_addon", "wheels"}


def _manifest_wheels_for_linux():
    with open(ROOT / "blender_manifest.toml", "rb") as fh:
        wheels = [os.path.basename(w) for w in tomllib.load(fh)["wheels"]]
    return sorted(w for w in wheels if w.endswith("-any.whl") or "linux" in w)


@pytest.fixture(scope="module")
def zip_path(tmp_path_factory):
    out = tmp_path_factory.mktemp("dist")
    cmd = [sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--platform", PLATFORM,
           "--output-dir", str(out)]
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=900)
    if r.returncode != 0:
        pytest.fail("building the extension zip failed (the first build downloads wheels from PyPI: "
                    f"is it reachable?)\n$ {' '.join(cmd)}\n{r.stdout}\n{r.stderr}", pytrace=False)
    zips = sorted(out.glob("grlens-*-linux_x64.zip"))
    assert len(zips) == 1, (zips, r.stdout)
    return zips[0]


# Runs in a fresh interpreter; prints one line "RESULT <json>".
_CHILD = r'''
import json, math, os, sys
import bpy, addon_utils

phase, zip_path, mod = sys.argv[1], sys.argv[2], sys.argv[3]
res = {}
ext_dir = os.path.realpath(bpy.utils.user_resource("EXTENSIONS"))
site = os.path.join(ext_dir, ".local", "lib", "python{}.{}".format(*sys.version_info[:2]), "site-packages")

def where(m):
    return os.path.realpath(m.__file__)

def state():
    return {"enabled": mod in bpy.context.preferences.addons and all(addon_utils.check(mod)),
            "scene_prop": hasattr(bpy.types.Scene, "grlens")}

if phase == "install":
    res["install"] = sorted(bpy.ops.extensions.package_install_files(
        filepath=zip_path, repo="user_default", enable_on_install=True))
else:
    res["enabled_at_start"] = state()["enabled"]
    res["enable"] = sorted(bpy.ops.preferences.addon_enable(module=mod))
res["after_enable"] = state()
res["has_register"] = callable(getattr(sys.modules.get(mod), "register", None))
prefs = bpy.context.preferences.addons[mod].preferences if mod in bpy.context.preferences.addons else None
res["cache_pref"] = prefs is not None and "lut_cache_dir" in prefs.bl_rna.properties
res["add_menu"] = any(getattr(f, "__name__", "") == "menu_add" for f in bpy.types.VIEW3D_MT_add._dyn_ui_initialize())

import lutgen, numpy
res["lutgen_file"] = where(lutgen)
c = lutgen.connect(20, 3.3, 1.5707963, 1)
res["connect"] = [float(c.xi), float(c.dt), float(c.ux), float(c.uy)]
import scipy, OpenEXR
res["scipy"] = [scipy.__version__, where(scipy)]
res["openexr_file"] = where(OpenEXR)
res["numpy"] = [numpy.__version__, where(numpy)]
res["site"] = os.path.realpath(site)
res["site_listing"] = sorted(os.listdir(site))

if phase == "restart":
    repo = next(r for r in bpy.context.preferences.extensions.repos if r.module == "user_default")
    res["disable"] = sorted(bpy.ops.preferences.addon_disable(module=mod))
    res["after_disable"] = state()
    res["uninstall"] = sorted(bpy.ops.extensions.package_uninstall(
        repo_directory=repo.directory, pkg_id="grlens"))
    res["after_uninstall"] = state()
    res["package_dir_left"] = os.path.exists(os.path.join(repo.directory, "grlens"))
    res["site_listing_after"] = sorted(os.listdir(site)) if os.path.isdir(site) else []
print("RESULT " + json.dumps(res))
'''


def _run_child(phase, zip_path, user_resources):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["BLENDER_USER_RESOURCES"] = str(user_resources)
    script = user_resources.parent / "child.py"
    script.write_text(_CHILD)
    # cwd and the script's folder are outside the repository: `lutgen` must come from the wheels.
    r = subprocess.run([sys.executable, str(script), phase, str(zip_path), MODULE], cwd=user_resources.parent,
                       env=env, capture_output=True, text=True, timeout=300)
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("RESULT ")]
    assert r.returncode == 0 and lines, f"{phase} failed (rc {r.returncode}):\n{r.stdout}\n{r.stderr}"
    return json.loads(lines[-1][len("RESULT "):])


def _check_common(res):
    site = res["site"] + os.sep
    assert res["after_enable"] == {"enabled": True, "scene_prop": True}, res
    assert res["has_register"], res
    assert res["cache_pref"], res  # Edit > Preferences > Add-ons > grlens: the tables' cache folder
    assert res["add_menu"], res    # Add > Black Hole
    assert res["lutgen_file"].startswith(site), res["lutgen_file"]
    assert all(math.isfinite(v) for v in res["connect"]), res["connect"]
    assert 0 < res["connect"][0] < math.pi and res["connect"][1] > 0, res["connect"]
    version, numpy_file = res["numpy"]
    assert version.startswith("1.26."), version            # Blender 4.5's numpy, not replaced
    assert not numpy_file.startswith(site), numpy_file
    assert not any(n.lower().startswith("numpy") for n in res["site_listing"]), res["site_listing"]
    assert {"lutgen", "scipy"} <= set(res["site_listing"]), res["site_listing"]


def test_zip_contents(zip_path):
    with zipfile.ZipFile(zip_path) as zf:
        names = zf.namelist()
        manifest = tomllib.loads(zf.read("blender_manifest.toml").decode())
    top = {n.split("/", 1)[0] for n in names}
    assert top == ALLOWED_TOP_LEVEL, (
        f"unexpected top-level entries {sorted(top - ALLOWED_TOP_LEVEL)} (exclude them in "
        f"[build] paths_exclude_pattern of blender_manifest.toml, or allow them here); missing "
        f"{sorted(ALLOWED_TOP_LEVEL - top)}")
    assert not [n for n in names if "__pycache__" in n or n.endswith((".pyc", ".pyo"))]
    wheels = sorted(n.split("/", 1)[1] for n in names if n.startswith("wheels/"))
    assert wheels == _manifest_wheels_for_linux(), wheels
    assert [w.split("-")[0].lower() for w in wheels] == ["lutgen", "openexr", "scipy"], wheels
    assert not [w for w in wheels if w.lower().startswith("numpy")]
    assert manifest["id"] == "grlens" and manifest["build"]["generated"]["platforms"] == [PLATFORM]
    assert "grlens_addon/__init__.py" in names and "__init__.py" in names


def test_install_enable_uninstall(zip_path, tmp_path):
    user = tmp_path / "user_resources"
    user.mkdir()

    first = _run_child("install", zip_path, user)
    assert first["install"] == ["FINISHED"], first
    _check_common(first)

    again = _run_child("restart", zip_path, user)
    assert again["enable"] == ["FINISHED"], again
    _check_common(again)
    site = again["site"] + os.sep
    version, scipy_file = again["scipy"]
    assert version == "1.15.3" and scipy_file.startswith(site), again["scipy"]
    assert again["openexr_file"].startswith(site), again["openexr_file"]

    assert again["disable"] == ["FINISHED"] and again["after_disable"] == {"enabled": False, "scene_prop": False}
    assert again["uninstall"] == ["FINISHED"], again
    assert again["after_uninstall"]["enabled"] is False
    assert not again["package_dir_left"]
    assert not {"lutgen", "scipy"} & set(again["site_listing_after"]), again["site_listing_after"]


def test_root_init_imports_as_a_plain_module():
    """pytest imports the repository's root __init__.py as a top-level module when the checkout's folder
    name is not an identifier (e.g. a CI checkout in ``grlens.git``): that must not fail."""
    import importlib.util
    import os

    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "__init__.py")
    spec = importlib.util.spec_from_file_location("__init__", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert not hasattr(module, "register")
