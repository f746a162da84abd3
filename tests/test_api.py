"""The public API: every name in __all__ resolves, and the package ships its type marker."""

from __future__ import annotations

from importlib import resources

import planner


def test_all_names_resolve():
    for name in planner.__all__:
        assert hasattr(planner, name), name
    assert len(set(planner.__all__)) == len(planner.__all__)


def test_version_and_py_typed():
    assert isinstance(planner.__version__, str) and planner.__version__.count(".") == 2
    assert resources.files("planner").joinpath("py.typed").is_file()


def test_bundled_models_are_package_data():
    for name in ("shelley", "al5c", "three_joint", "dh3"):
        assert resources.files("planner.urdf").joinpath(f"{name}.urdf").is_file()
