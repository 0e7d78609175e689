import pathlib
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def pytest_collection_modifyitems(config, items):
    """bpy tests skip, with the reason, where the headless Blender module is missing."""
    try:
        import bpy  # noqa: F401
    except ImportError:
        skip = pytest.mark.skip(reason="bpy (headless Blender 5.0.1) is not installed: run `make test`")
        for item in items:
            if "bpy" in item.keywords:
                item.add_marker(skip)


@pytest.fixture
def empty_blend():
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)


@pytest.fixture
def addon(empty_blend):
    """The add-on registered in an empty file, unregistered afterwards (the bpy tests' fixture)."""
    import addon as package

    package.register()
    yield package
    package.unregister()
