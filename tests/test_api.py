"""The public API: every name in __all__ resolves, and the package ships its type marker."""

from __future__ import annotations

import re
from importlib import metadata, resources
from pathlib import Path

import pytest

import planner
from planner.core.version import DISTRIBUTION


def test_all_names_resolve():
    for name in planner.__all__:
        assert hasattr(planner, name), name
    assert len(set(planner.__all__)) == len(planner.__all__)


def test_version_and_py_typed():
    assert isinstance(planner.__version__, str) and planner.__version__.count(".") == 2
    # One place: pyproject.toml's version, read through the installed distribution's metadata.
    pyproject = (Path(__file__).resolve().parents[1] / "pyproject.toml").read_text()
    assert re.search(r'^name = "servo-arm-planner"$', pyproject, re.MULTILINE)
    assert f'\nversion = "{planner.__version__}"\n' in pyproject
    assert metadata.version(DISTRIBUTION) == planner.__version__
    assert resources.files("planner").joinpath("py.typed").is_file()


def test_bundled_models_are_package_data():
    for name in ("shelley", "al5c", "three_joint", "dh3"):
        assert resources.files("planner.urdf").joinpath(f"{name}.urdf").is_file()


def test_import_is_lazy_and_the_lazy_table_matches_the_imports():
    import ast
    import subprocess
    import sys

    code = (
        "import sys, planner; before = set(sys.modules); planner.load_robot('al5c'); "
        "print(sorted(m for m in ('pinocchio', 'casadi', 'yourdfpy', 'trimesh', 'ruckig') if m in before), "
        "sorted(m for m in ('casadi', 'yourdfpy', 'trimesh', 'ruckig') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[] []"
    # The TYPE_CHECKING imports (for type checkers and readers) and the lazy table agree.
    tree = ast.parse(Path(planner.__file__).read_text())
    block = next(n for n in tree.body if isinstance(n, ast.If) and getattr(n.test, "id", "") == "TYPE_CHECKING")
    imported = {(node.module, a.name) for node in block.body for a in node.names}
    assert imported == {(module, name) for module, names in planner._LAZY.items() for name in names}
    assert set(planner.__all__) == {n for _, n in imported} | {
        n
        for n in planner.__all__
        if isinstance(getattr(planner, n), type) and issubclass(getattr(planner, n), Exception)
    }
    assert planner.ik.solve.solve_ik is planner.solve_ik
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        planner.nope  # noqa: B018
