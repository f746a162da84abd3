"""Shared fixtures: bundled robots loaded once per session."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
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


def gif_frames(path: Path) -> tuple[tuple[int, int], list[np.ndarray]]:
    """The size and every frame (RGB) of a GIF, after checking its signature."""
    assert Path(path).read_bytes()[:6] in (b"GIF89a", b"GIF87a"), f"{path} is not a GIF"
    from PIL import Image

    with Image.open(path) as image:
        frames = []
        for k in range(image.n_frames):
            image.seek(k)
            frames.append(np.asarray(image.convert("RGB"), dtype=np.int16))
        return image.size, frames


def assert_animation(path: Path, duration: float, fps: float, speed: float, size: tuple[int, int]) -> None:
    """A GIF of the given size with one frame per frame time, and frames that differ."""
    from planner.app.animation import frame_times

    got_size, frames = gif_frames(path)
    assert got_size == size
    assert len(frames) == len(frame_times(duration, fps, speed))
    # The arm moves: the first, middle and last frames all differ from each other.
    first, middle, last = frames[0], frames[len(frames) // 2], frames[-1]
    for a, b in ((first, middle), (middle, last), (first, last)):
        assert np.count_nonzero(np.any(a != b, axis=-1)) > 50


def single_after(calls: int, call):
    """``call()`` with the analytic solvers' SINGLE_AFTER set to `calls` (1: the compiled kernel
    from the first call; huge: never)."""
    import planner.ik.analytic.base as analytic_base

    old = analytic_base.SINGLE_AFTER
    analytic_base.SINGLE_AFTER = calls
    try:
        return call()
    finally:
        analytic_base.SINGLE_AFTER = old
