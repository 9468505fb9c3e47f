"""Test-session hooks.

The pip ``bpy`` module can hang in its C++ static destructors when the interpreter exits (seen with
bpy 4.5 after failing tests, and bpy 4.2 always): once the session is over and pytest has printed its
summary, leave the process with the session's exit status directly, so a failing suite fails
instead of hanging CI.
"""
import os
import sys

_status = {"code": 0}


def pytest_sessionfinish(session, exitstatus):
    _status["code"] = int(exitstatus)


def pytest_unconfigure(config):
    if "bpy" in sys.modules:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_status["code"])
