"""Test-session hooks.

The pip ``bpy`` module can hang in its C++ static destructors when the interpreter exits (seen with
bpy 4.5 after failing tests, and bpy 4.2 always): once the session is over and pytest has printed its
summary, leave the process with the session's exit status directly, so a failing suite fails
instead of hanging CI.

The session's processes (this one and the Blender processes tests start) share one disk cache of
lookup tables (GRLENS_LUT_CACHE, a fresh temporary directory unless the variable is set), so each
table is built once per session; tests that check builds themselves clear it for their processes.

With a JUnit report, the number of tests collected is written into it (see _collected_count).
"""
import os
import shutil
import sys
import tempfile

import pytest

_status = {"code": 0}
_own_cache = []


@pytest.fixture(scope="session", autouse=True)
def _collected_count(request, record_testsuite_property):
    """The number of tests collected, as the suite property ``collected`` of pytest's JUnit report
    (--junitxml): .ci/check_report.py fails a run that reports fewer (it ended early)."""
    record_testsuite_property("collected", len(request.session.items))


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
