"""The main job, end to end: `planner demo` plans both seed scenarios and writes its files."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import planner
from planner.app.demo import AL5C_READING, AL5C_SENSOR_POSE, DEMO_ANIMATION, DH3_STATES_CM, run_demo

from conftest import assert_animation, png_size, run_cli

pytest.importorskip("matplotlib")

FILES = (
    "trajectory.csv",
    "servo_pulses.csv",
    "ssc32.txt",
    "summary.json",
    "joints.png",
    "singularity.png",
    "arm.png",
    "animation.gif",
)


@pytest.fixture(scope="module")
def report():
    return run_demo(None, plots=False, log=None)


def test_cli_demo_writes_every_file(tmp_path):
    out = tmp_path / "demo"
    result = run_cli("demo", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert "state 7: reach out" in result.stdout and "peak v/limit" in result.stdout
    for arm in ("dh3", "al5c"):
        for name in FILES:
            path = out / arm / name
            assert path.is_file() and path.stat().st_size > 0, path
            if name.endswith(".png"):
                width, height = png_size(path)
                assert width >= 600 and height >= 300
    for arm in ("dh3", "al5c"):
        duration = json.loads((out / arm / "summary.json").read_text())["duration"]
        fps, speed, size = DEMO_ANIMATION["fps"], 1.0, DEMO_ANIMATION["size"]
        assert_animation(out / arm / "animation.gif", duration, fps, speed, tuple(size))
    commands = (out / "al5c" / "ssc32.txt").read_bytes().decode("ascii").split("\r")
    assert commands[0].startswith("#0P") and commands[0].endswith("T20")
    summary = json.loads((out / "dh3" / "summary.json").read_text())
    assert summary["singular_waypoints"] == [0, 6, 9]


def test_dh3_states_are_reached_and_stretched_ones_flagged(report):
    plan = report.plans["dh3"]
    robot = planner.load_robot("dh3")
    positions = np.array([p for p, _ in DH3_STATES_CM]) / 100
    np.testing.assert_allclose(robot.position(plan.waypoints), positions, atol=1e-9)
    # States 1 and 7 (and the return to 1) are the arm fully stretched: 6 + 11 cm at shoulder height.
    assert plan.singular_waypoints == (0, 6, 9)
    sample = plan.trajectory.sample(plan.waypoint_times)
    np.testing.assert_allclose(sample.q, plan.waypoints, atol=1e-9)


def test_every_move_is_checked_and_within_limits(report):
    assert len(report.moves) == 9 + 5
    for move in report.moves:
        assert "NLP agrees" in move.ik_method, move
        assert move.ik_position_error < 1e-9
        assert move.peak_velocity_ratio <= 1 + 1e-9
    for plan in report.plans.values():
        peaks = plan.trajectory.peak_ratios(1000.0)
        assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + 1e-9
        assert peaks["position"] <= 1e-9


def test_al5c_approaches_the_seen_object_from_above(report):
    seen = planner.range_bearing_to_base(*AL5C_READING, AL5C_SENSOR_POSE)
    np.testing.assert_allclose(report.object_position, seen)
    plan = report.plans["al5c"]
    robot = planner.load_robot("al5c")
    grasp = robot.fk(plan.waypoints[1])
    np.testing.assert_allclose(grasp[:2, 3], seen[:2], atol=1e-9)
    # Straight down: the gripper's approach axis points along -z at every target.
    for q in plan.waypoints:
        approach = robot.fk(q)[:3, :3] @ robot.approach_axis
        np.testing.assert_allclose(approach, [0, 0, -1], atol=1e-9)
    assert plan.branches[1] == "line" and plan.branches[3] != "line"
    deviation = plan.line_deviation
    assert deviation[2] is None and all(deviation[k] < 1e-3 for k in (0, 1, 3, 4))
    assert math.isclose(plan.trajectory.dwell.max(), 0.5)
