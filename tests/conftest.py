"""Shared fixtures: bundled robots loaded once per session."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import pytest

import planner
from planner.model.catalog import BUNDLED_ROBOTS, EXAMPLE_ROBOTS, example_robot_data_dir

BUNDLED = tuple(BUNDLED_ROBOTS)
EXAMPLES = tuple(EXAMPLE_ROBOTS)
HAVE_EXAMPLE_ROBOT_DATA = example_robot_data_dir() is not None
needs_example_robot_data = pytest.mark.skipif(
    not HAVE_EXAMPLE_ROBOT_DATA, reason="example-robot-data is not installed (pip install 'servo-arm-planner[bench]')"
)

_cache: dict[str, planner.Robot] = {}


def get_robot(name: str) -> planner.Robot:
    """A robot loaded once per test session (do not mutate it)."""
    if name not in _cache:
        _cache[name] = planner.load_robot(name)
    return _cache[name]


@pytest.fixture(params=BUNDLED)
def bundled_robot(request) -> planner.Robot:
    return get_robot(request.param)


def run_cli(*args: str, cwd: Path | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    """Run ``python -m planner ARGS`` in a scratch directory (so the installed package is used)."""
    env = dict(os.environ)
    return subprocess.run(
        [sys.executable, "-m", "planner", *args],
        capture_output=True,
        text=True,
        cwd=cwd or Path(__file__).parent,
        env=env,
        timeout=timeout,
    )


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_size(path: Path) -> tuple[int, int]:
    """Width and height of a PNG file, after checking its signature, header and end chunk."""
    data = Path(path).read_bytes()
    assert data[:8] == PNG_SIGNATURE, f"{path} is not a PNG"
    assert data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    assert data[-8:-4] == b"IEND"
    return width, height
