"""Servo files for any arm: default calibrations fit the plan's travel, and a servo-file problem
keeps the trajectory's files."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from planner import InvalidArgumentError, ServoCalibration, default_calibrations, load_robot
from planner.app.cli import main
from planner.export.calibration import SSC32_US_PER_RAD
from planner.model.catalog import example_robot_data_dir

from conftest import get_robot, needs_example_robot_data

# A two-joint arm whose first joint turns without end.
CONTINUOUS_URDF = """<?xml version="1.0"?>
<robot name="spinner">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="tip"/>
  <joint name="spin" type="continuous"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit effort="1" velocity="2"/></joint>
  <joint name="lift" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 1 0"/><limit lower="-1.5" upper="1.5" effort="1" velocity="2"/></joint>
  <joint name="tool" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.2 0 0"/></joint>
</robot>
"""


@pytest.fixture
def spinner(tmp_path):
    path = tmp_path / "spinner.urdf"
    path.write_text(CONTINUOUS_URDF)
    return path


def test_default_calibrations_fit_a_continuous_joint_travel(spinner):
    robot = load_robot(spinner)
    assert not np.isfinite(robot.lower[0])
    # Without a travel, a continuous joint gets the SSC-32 scale (+-90 deg).
    assert default_calibrations(robot)[0].us_per_rad == pytest.approx(SSC32_US_PER_RAD)
    cals = default_calibrations(robot, travel=(np.array([-0.5, -9.0]), np.array([4.0, 9.0])))
    # The continuous joint covers its travel; the revolute joint keeps fitting its range.
    assert cals[0].pulse(4.0) == pytest.approx(2500.0) and 500.0 < cals[0].pulse(-0.5) < 1500.0
    assert cals[1] == default_calibrations(robot)[1]
    with pytest.raises(InvalidArgumentError, match="travel needs two arrays of 2 angles"):
        default_calibrations(robot, travel=(np.zeros(3), np.zeros(3)))


def test_plan_of_a_continuous_joint_beyond_90_deg_writes_every_file(spinner, tmp_path, capsys):
    plan = tmp_path / "p.yaml"
    plan.write_text("units: {angle: deg}\nwaypoints:\n  - [0, 0]\n  - [200, 30]\n  - [-120, -40]\n")
    out = tmp_path / "out"
    assert main(["plan", str(spinner), str(plan), "--out", str(out)]) == 0, capsys.readouterr().err
    names = {p.name for p in out.iterdir()}
    assert {"trajectory.csv", "servo_pulses.csv", "ssc32.txt", "summary.json"} <= names
    rows = [c for c in (out / "ssc32.txt").read_bytes().decode().split("\r") if c]
    pulses = np.array([[int(x) for x in re.findall(r"P(\d+)", c)] for c in rows])
    assert pulses.min() >= 500 and pulses.max() <= 2500
    # The spin joint's 200 deg reach the top of the pulse range (within the 1 mrad margin).
    assert pulses[:, 0].max() >= 2499


def test_a_servo_file_problem_keeps_the_trajectory_files(tmp_path, capsys):
    plan = tmp_path / "p.yaml"
    plan.write_text(
        "waypoints:\n  - [0, 0.5, 1.0]\n  - [1.0, 0.8, 1.2]\n"
        "servos:\n  - {channel: 0, min_pulse: 1400, max_pulse: 1600}\n  - {channel: 1}\n  - {channel: 2}\n"
    )
    out = tmp_path / "out"
    assert main(["plan", "dh3", str(plan), "--out", str(out), "--json"]) == 1
    captured = capsys.readouterr()
    err = captured.err
    assert err.startswith("planner plan: error: servo files not written")
    assert "joint 'base_yaw' (channel 0)" in err and "servos:" in err
    assert {p.name for p in out.iterdir()} == {"trajectory.csv", "summary.json"}
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["servo_file_errors"]) == {"servo_pulses.csv", "ssc32.txt"}
    assert sorted(summary["files"]) == sorted(str(out / n) for n in ("summary.json", "trajectory.csv"))
    assert json.loads(captured.out)["servo_file_errors"] == summary["servo_file_errors"]


def test_bundled_arms_keep_their_range_fitted_calibrations():
    robot = get_robot("dh3")
    cals = default_calibrations(robot, travel=(robot.lower / 2, robot.upper / 2))
    assert cals == default_calibrations(robot)
    assert all(isinstance(c, ServoCalibration) for c in cals)


@needs_example_robot_data
def test_kinova_plan_writes_all_its_files(tmp_path, capsys):
    urdf = example_robot_data_dir() / "kinova_description" / "robots" / "kinova.urdf"
    plan = tmp_path / "p.yaml"
    plan.write_text(
        "units: {angle: deg}\nwaypoints:\n  - [0, 180, 180, 0, 180, 0]\n"
        "  - [120, 150, 100, -150, 200, 170]\n  - [-100, 200, 150, 100, 160, -120]\n"
    )
    out = tmp_path / "out"
    assert main(["plan", str(urdf), str(plan), "--out", str(out)]) == 0, capsys.readouterr().err
    assert {"trajectory.csv", "servo_pulses.csv", "ssc32.txt", "summary.json"} <= {p.name for p in out.iterdir()}
    assert "servo_file_errors" not in json.loads((out / "summary.json").read_text())
