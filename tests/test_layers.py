"""The layers import only downwards: core, model, geometry, collision, ik, motion, export, hardware, view, app."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "planner"
LAYERS = ("core", "model", "geometry", "collision", "ik", "motion", "export", "hardware", "view", "app")

pytestmark = pytest.mark.skipif(not (PACKAGE / "app").is_dir(), reason="the source tree is not next to the tests")


def _layer(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] != "planner" or len(parts) < 2:
        return None
    return parts[1] if parts[1] in LAYERS else None


@pytest.mark.parametrize("layer", LAYERS)
def test_imports_go_down_only(layer):
    rank = LAYERS.index(layer)
    upward = []
    for path in sorted((PACKAGE / layer).rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            for name in names:
                target = _layer(name)
                if target is not None and LAYERS.index(target) > rank:
                    upward.append(f"{path.relative_to(PACKAGE.parent)} imports {name}")
    assert upward == []
