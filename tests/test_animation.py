"""Animations of plans: valid GIFs with the expected frames and size, frames that differ."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import planner
from planner.app.animation import animate_plan, frame_times

from conftest import assert_animation, get_robot, run_cli

pytest.importorskip("matplotlib")
pytest.importorskip("PIL.Image")

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "dh3_pick_and_place.yaml"


@pytest.fixture(scope="module")
def dh3_plan():
    request = planner.parse_motion_request(
        {
            "units": {"length": "cm"},
            "targets": [
                {"position": [14, 0, -4], "label": "pick"},
                {"position": [11, 0, 9], "label": "lift"},
                {"position": [0, 14, -4], "label": "place"},
            ],
        }
    )
    return planner.plan_motion(get_robot("dh3"), request), request.labels


def test_frame_times_run_at_real_speed_and_end_at_the_end():
    t = frame_times(5.0, 15.0)
    assert len(t) == 76 and t[0] == 0.0 and t[-1] == 5.0
    np.testing.assert_allclose(np.diff(t), 1 / 15)
    assert len(frame_times(5.0, 15.0, speed=2.0)) == 39
    assert frame_times(0.01, 15.0).tolist() == [0.0, 0.01]


@pytest.mark.parametrize("view", ["side-top", "3d"])
def test_animation_is_a_gif_of_the_arm_moving(dh3_plan, tmp_path, view):
    plan, labels = dh3_plan
    path = animate_plan(
        tmp_path / "a.gif", get_robot("dh3"), plan, labels=labels, fps=10, speed=1.5, size=(320, 200), view=view
    )
    assert_animation(path, plan.trajectory.duration, 10, 1.5, (320, 200))


@pytest.mark.parametrize("view", ["side-top", "3d"])
def test_animation_of_a_plan_around_an_obstacle(tmp_path, view):
    example = EXAMPLE.parent / "al5c_around_a_block.yaml"
    plan = planner.plan_motion(get_robot("al5c"), planner.load_motion_request(example))
    assert plan.scene is not None and plan.scene.obstacles
    path = animate_plan(tmp_path / "block.gif", get_robot("al5c"), plan, fps=8, size=(320, 240), view=view)
    assert_animation(path, plan.trajectory.duration, 8, 1.0, (320, 240))


def test_plan_animate_writes_the_gif_at_real_speed(tmp_path):
    out = tmp_path / "plan.gif"
    result = run_cli("plan", "dh3", str(EXAMPLE), "--animate", str(out), "--json")
    assert result.returncode == 0, result.stderr
    duration = planner.plan_motion(get_robot("dh3"), planner.load_motion_request(EXAMPLE)).trajectory.duration
    assert_animation(out, duration, 15.0, 1.0, (640, 400))


def test_plan_animate_flags(tmp_path):
    out = tmp_path / "fast.gif"
    args = ("--animate", str(out), "--speed", "2", "--fps", "8", "--size", "300", "200", "--animate-view", "3d")
    result = run_cli("plan", "dh3", str(EXAMPLE), *args)
    assert result.returncode == 0, result.stderr
    assert str(out) in result.stdout
    duration = planner.plan_motion(get_robot("dh3"), planner.load_motion_request(EXAMPLE)).trajectory.duration
    assert_animation(out, duration, 8.0, 2.0, (300, 200))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"path": "a.png"}, "the file name must end in .gif"),
        ({"fps": 0}, "fps must be in [0.01, 60] frames per second, got 0"),
        ({"fps": float("nan")}, "fps must be in [0.01, 60]"),
        ({"speed": -1.0}, "speed must be a positive number (plan seconds per second), got -1.0"),
        ({"size": (10, 400)}, "size must be between 64 and 4096 pixels each way, got 10x400"),
        ({"size": "big"}, "size must be (width, height) in pixels"),
        ({"view": "front"}, "unknown view 'front'; valid: side-top, 3d"),
        ({"fps": 60, "speed": 0.001}, "frames for a"),
    ],
)
def test_bad_animation_settings_are_refused(dh3_plan, tmp_path, kwargs, message):
    plan, _ = dh3_plan
    kwargs = dict(kwargs)
    path = tmp_path / kwargs.pop("path", "a.gif")
    with pytest.raises(planner.InvalidArgumentError) as info:
        animate_plan(path, get_robot("dh3"), plan, **kwargs)
    assert message in str(info.value)
    assert not path.exists()


def test_animation_of_a_plan_for_another_arm_is_refused(dh3_plan, tmp_path):
    plan, _ = dh3_plan
    with pytest.raises(planner.InvalidArgumentError, match="the plan has 3 joints; al5c has 5"):
        animate_plan(tmp_path / "a.gif", get_robot("al5c"), plan)


def test_plan_animate_bad_flag_is_one_line_error(tmp_path):
    result = run_cli("plan", "dh3", str(EXAMPLE), "--animate", str(tmp_path / "a.gif"), "--fps", "-3")
    assert result.returncode == 1
    assert result.stderr.strip() == "planner plan: error: fps must be in [0.01, 60] frames per second, got -3.0"
