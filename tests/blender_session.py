"""Fixtures of the tests that run the add-on in the pip ``bpy`` module: import them into a test module
(``from blender_session import empty_file, registered  # noqa: F401``) and they apply to all its tests."""
import pytest

import bpy

import grlens_addon


@pytest.fixture(scope="module", autouse=True)
def registered():
    """The add-on registered for the module's tests (twice: registering is idempotent)."""
    grlens_addon.register()
    grlens_addon.register()
    yield
    grlens_addon.unregister()


@pytest.fixture(autouse=True)
def empty_file():
    """Every test starts and ends with an empty factory-settings file."""
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    yield
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
