"""Test-session hooks.

The pip ``bpy`` module can hang in its C++ static destructors when the interpreter exits (seen with
bpy 4.5 after failing tests, and bpy 4.2 always): once the session is over and pytest has printed its
summary, leave the process with the session's exit status directly, so a failing suite fails
instead of hanging CI.

The session's processes (this one and the Blender processes tests start) share one disk cache of
lookup tables (GRLENS_LUT_CACHE, a fresh temporary directory unless the variable is set), so each
table is built once per session; tests that check builds themselves clear it for their processes.
"""
import os
import shutil
import sys
import tempfile

_status = {"code": 0}
_own_cache = []


def pytest_configure(config):
    if not os.environ.get("GRLENS_LUT_CACHE"):
        folder = tempfile.mkdtemp(prefix="grlens-lut-cache-")
        os.environ["GRLENS_LUT_CACHE"] = folder
        _own_cache.append(folder)


def pytest_sessionfinish(session, exitstatus):
    _status["code"] = int(exitstatus)


def pytest_unconfigure(config):
    for folder in _own_cache:
        shutil.rmtree(folder, ignore_errors=True)
    if "bpy" in sys.modules:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_status["code"])
