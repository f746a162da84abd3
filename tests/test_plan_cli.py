"""Plan files, `plan_motion` and the `planner plan` command, with Sumadsad's (2020) pick and place."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from planner import InvalidArgumentError, JointLimitError, PlannerError
from planner.app.cli import main
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import load_motion_request, parse_motion_request
from planner.motion.trajectory import LIMIT_TOLERANCE

from conftest import get_robot, run_cli

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "dh3_pick_and_place.yaml"
SEED_STATES_CM = [
    (17, 0, 3),
    (14, 0, -4),
    (14, 0, -4),
    (11, 0, 9),
    (7.7, 7.7, 9),
    (0, 11, 9),
    (0, 17, 3),
    (0, 14, -4),
    (0, 14, -4),
    (17, 0, 3),
]


@pytest.fixture(scope="module")
def pick_and_place():
    robot = get_robot("dh3")
    return robot, plan_motion(robot, load_motion_request(EXAMPLE))


def test_004_pick_and_place_plans_with_stretched_states_flagged(pick_and_place):
    robot, plan = pick_and_place
    # (17, 0, 3) (start and return) and (0, 17, 3): the arm fully stretched, 6 + 11 cm.
    assert plan.singular_waypoints == (0, 6, 9)
    assert plan.singularity.min_inverse_condition == pytest.approx(0.0, abs=1e-9)
    targets = np.array(SEED_STATES_CM) / 100.0
    np.testing.assert_allclose(robot.position(plan.waypoints), targets, atol=1e-9)
    traj = plan.trajectory
    np.testing.assert_allclose(traj.sample(plan.waypoint_times).q, plan.waypoints, atol=1e-12)
    peaks = traj.peak_ratios(1000.0)
    assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
    assert peaks["position"] <= LIMIT_TOLERANCE
    # The seed's own check: state 5 is base 45 deg; the elbow-up branch is kept throughout.
    assert math.degrees(plan.waypoints[4][0]) == pytest.approx(45.0)
    assert all(b == "front/elbow-up" for b in plan.branches)
    # The claw states hold still for their dwell.
    t2 = plan.waypoint_times[2]
    np.testing.assert_allclose(
        traj.sample(np.linspace(t2, t2 + 0.5, 6)).q, plan.waypoints[2][None].repeat(6, 0), atol=1e-12
    )
    # It does not stop at the swing waypoints 4 and 5.
    v = traj.sample(plan.waypoint_times[[4, 5]]).qd
    assert np.all(np.linalg.norm(v, axis=1) > 0.1)


def test_cli_json_summary(capsys):
    assert main(["plan", "dh3", str(EXAMPLE), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    for key in (
        "duration",
        "waypoint_times",
        "max_velocity_ratio",
        "max_acceleration_ratio",
        "max_jerk_ratio",
        "min_manipulability",
        "singular_waypoints",
    ):
        assert key in summary
    assert summary["singular_waypoints"] == [0, 6, 9]
    assert summary["min_manipulability"] == pytest.approx(0.0, abs=1e-12)
    assert summary["duration"] == pytest.approx(summary["waypoint_times"][-1])
    assert 0.5 < summary["max_acceleration_ratio"] <= 1 + LIMIT_TOLERANCE
    assert summary["max_jerk_ratio"] <= 1 + LIMIT_TOLERANCE


def test_cli_out_writes_csv_and_servo_files(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["plan", "dh3", str(EXAMPLE), "--out", str(out), "--rate", "200"]) == 0
    text = capsys.readouterr().out
    assert "SINGULAR" in text and "duration" in text
    header = (out / "trajectory.csv").read_text().splitlines()[0]
    assert header.startswith("t,q_base_yaw,q_shoulder,q_elbow,qd_base_yaw")
    rows = (out / "trajectory.csv").read_text().splitlines()
    summary = json.loads((out / "summary.json").read_text())
    t = np.array([float(r.split(",")[0]) for r in rows[1:]])
    assert t[0] == 0.0 and t[-1] == pytest.approx(summary["duration"], abs=1e-12)
    assert np.all(np.diff(t) <= 1 / 200 + 1e-12)
    commands = (out / "ssc32.txt").read_bytes().decode().split("\r")
    assert commands[-1] == ""
    assert all(re.fullmatch(r"#0P\d+#1P\d+#2P\d+T20", c) for c in commands[:-1])
    pulses = (out / "servo_pulses.csv").read_text().splitlines()
    assert pulses[0] == "t,ch0_base_yaw,ch1_shoulder,ch2_elbow"


def test_cli_subprocess_smoke(tmp_path):
    path = tmp_path / "w.json"
    path.write_text(json.dumps({"waypoints": [[0, 0.5, 1.0], [0.5, 0.8, 1.2], [1.0, 0.5, 0.9]]}))
    proc = run_cli("plan", "dh3", str(path), "--json")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["singular_waypoints"] == []


def test_cli_errors_are_one_line(tmp_path, capsys):
    path = tmp_path / "w.yaml"
    path.write_text("waypoints:\n  - [0, 0, 0]\n  - [0, 3.0, 0]\n")
    assert main(["plan", "dh3", str(path)]) == 1
    err = capsys.readouterr().err.strip()
    assert err == "planner plan: error: waypoint 1: joint 'shoulder' value 3 is outside its range [-2.35619, 2.35619]"
    assert main(["plan", "dh3", str(tmp_path / "missing.yaml")]) == 1
    assert "cannot read plan file" in capsys.readouterr().err


def test_joint_waypoints_in_degrees_with_limits_and_dwell():
    robot = get_robot("dh3")
    request = parse_motion_request(
        {
            "units": {"angle": "deg"},
            "waypoints": [[0, 30, 60], {"q": [45, 60, 90], "dwell": 0.25, "label": "grasp"}, [90, 30, 45]],
            "limits": {"velocity": 90, "acceleration": [180, 180, 360]},
        }
    )
    plan = plan_motion(robot, request)
    np.testing.assert_allclose(plan.limits.velocity, math.radians(90))
    np.testing.assert_allclose(plan.limits.acceleration, np.radians([180, 180, 360]))
    np.testing.assert_allclose(plan.limits.jerk, 10 * np.radians([180, 180, 360]))
    np.testing.assert_allclose(plan.waypoints[1], np.radians([45, 60, 90]))
    assert plan.trajectory.dwell[1] == 0.25
    assert plan.branches == (None, None, None)


def test_servo_speed_limit_key():
    robot = get_robot("dh3")
    request = parse_motion_request(
        {"waypoints": [[0, 0.5, 1], [1, 0.5, 1]], "limits": {"servo_seconds_per_60deg": 0.5}}
    )
    plan = plan_motion(robot, request)
    np.testing.assert_allclose(plan.limits.velocity, math.radians(60) / 0.5)


@pytest.mark.parametrize(
    ("data", "error", "message"),
    [
        ({"waypoints": [[0, 0, 0]]}, InvalidArgumentError, r"at least two waypoints, got 1"),
        ({"waypoints": [[0, 0, 0], [0, 0]]}, InvalidArgumentError, r"waypoints have different lengths: \[3, 2\]"),
        (
            {"waypoints": [[0, 0], [0, 0.1]]},
            InvalidArgumentError,
            r"waypoints have 2 values; dh3 has 3 joints \(base_yaw, shoulder, elbow\)",
        ),
        ({"waypoints": [[0, 0, 0], [0, float("nan"), 0]]}, InvalidArgumentError, r"waypoints\[1\]\[1\] must be finite"),
        (
            {"waypoints": [[0, 0, 0], [0, 0, 2.5]]},
            JointLimitError,
            r"waypoint 1: joint 'elbow' value 2.5 is outside its range",
        ),
        (
            {"waypoints": [[0, 0, 0], [0, 0, 1]], "limits": {"velocity": 0}},
            PlannerError,
            r"velocity limit of joint 'base_yaw' must be positive and finite",
        ),
        (
            {"waypoints": [[0, 0, 0], [0, 0, 1]], "limits": {"jerk": -5}},
            PlannerError,
            r"jerk limit of joint 'base_yaw' must be positive and finite",
        ),
        (
            {"waypoints": [[0, 0, 0], [0, 0, 1]], "limits": {"velocity": [1, 1]}},
            PlannerError,
            r"velocity limit has 2 values; give one number or 3",
        ),
        (
            {"waypoints": [[0, 0, 0], [0, 0, 1]], "limits": {"acceleration": float("nan")}},
            PlannerError,
            r"limits.acceleration is NaN",
        ),
        ({"waypoints": [[0, 0, 0], [0, 0, 1]], "targets": []}, InvalidArgumentError, r"give either 'waypoints'"),
        (
            {"waypoints": [[0, 0, 0], [0, 0, 1]], "speed": 3},
            InvalidArgumentError,
            r"unknown key 'speed' in the plan; valid keys: units",
        ),
        (
            {"targets": [{"position": [0.1, 0, 0.05], "line": True}, {"position": [0.1, 0.02, 0.05]}]},
            InvalidArgumentError,
            r"the first target has no previous target",
        ),
        (
            {"targets": [{"position": [0.1, 0, 0.05], "pitch": 0, "rpy": [0, 0, 0]}, {"position": [0.1, 0, 0]}]},
            InvalidArgumentError,
            r"give at most one of pitch, rpy, quaternion",
        ),
        (
            {"targets": [{"position": [0.1, 0]}, {"position": [0.1, 0, 0]}]},
            InvalidArgumentError,
            r"targets\[0\].position must have 3 numbers",
        ),
        (
            {"targets": [{"position": [0.1, 0, 0.05]}, {"position": [0.5, 0, 0]}]},
            InvalidArgumentError,
            r"target 1 at position \[0.5, 0.0, 0.0\] m has no IK solution within the joint limits of dh3",
        ),
        (
            {"waypoints": [[0, 0, 0], [0, 0, 1]], "units": {"angle": "grad"}},
            InvalidArgumentError,
            r"unknown angle unit 'grad'; valid units: rad, deg",
        ),
    ],
)
def test_bad_plan_files(data, error, message):
    robot = get_robot("dh3")
    with pytest.raises(error, match=message):
        plan_motion(robot, parse_motion_request(data))


def test_summary_lists_plots_and_departures_without_negative_zero(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["plan", "dh3", str(EXAMPLE), "--out", str(out), "--plot"]) == 0
    capsys.readouterr()
    text = (out / "summary.json").read_text()
    summary = json.loads(text)
    names = sorted(Path(f).name for f in summary["files"])
    assert names == sorted(p.name for p in out.iterdir())
    assert {"joints.png", "singularity.png", "arm.png"} <= set(names)
    # The example dwells 0.5 s where the claw acts (waypoints 2 and 8): the arm leaves later.
    arrive, leave = np.array(summary["waypoint_times"]), np.array(summary["departure_times"])
    np.testing.assert_allclose(leave - arrive, [0, 0, 0.5, 0, 0, 0, 0, 0, 0.5, 0], atol=1e-12)
    assert not re.search(r"-0\.0\b|-0\b", text)


def test_to_json_writes_plain_numbers():
    from planner.core.text import to_json

    assert to_json({"a": np.float64(-0.0), "b": [np.int64(3), -0.0, (1.5,)], "c": np.array([-0.0, 2.0])}) == (
        '{\n  "a": 0.0,\n  "b": [\n    3,\n    0.0,\n    [\n      1.5\n    ]\n  ],\n  "c": [\n    0.0,\n    2.0\n  ]\n}'
    )
    with pytest.raises(ValueError):
        to_json({"x": float("nan")})


def test_ssc32_line_endings(tmp_path, capsys):
    from planner.export.formats.ssc32 import Ssc32

    cr, crlf = tmp_path / "cr", tmp_path / "crlf"
    assert main(["plan", "dh3", str(EXAMPLE), "--out", str(cr)]) == 0
    assert main(["plan", "dh3", str(EXAMPLE), "--out", str(crlf), "--line-ending", "crlf"]) == 0
    capsys.readouterr()
    a, b = (cr / "ssc32.txt").read_bytes(), (crlf / "ssc32.txt").read_bytes()
    assert b"\n" not in a and a.endswith(b"T20\r")
    assert b == a.replace(b"\r", b"\r\n")
    with pytest.raises(InvalidArgumentError, match="unknown line ending 'lf'; valid line endings: cr, crlf"):
        Ssc32("lf")
    with pytest.raises(SystemExit):
        main(["plan", "dh3", str(EXAMPLE), "--line-ending", "lf"])
    assert "invalid choice: 'lf'" in capsys.readouterr().err


def test_plan_table_speaks_the_plan_files_units_and_labels(tmp_path, capsys):
    path = tmp_path / "deg.yaml"
    path.write_text(
        "units: {angle: deg}\nwaypoints:\n  - {q: [0, 30, 60], label: home}\n"
        "  - {q: [45, 40, 70], dwell: 0.25}\n  - {q: [-30, 20, 50], label: drop}\n"
    )
    assert main(["plan", "dh3", str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert re.match(r"#\s+label\s+t \[s\]\s+leaves \[s\]\s+q \[deg\]\s+branch", lines[1])
    assert re.match(r"0\s+home\s+0\.0000\s+0\.0000\s+\+0\.0000 \+30\.0000 \+60\.0000\s+-", lines[3])
    assert re.match(r"1\s+\d\.\d{4}\s+\d\.\d{4}\s+\+45\.0000 \+40\.0000 \+70\.0000", lines[4])
    assert lines[5].split()[:2] == ["2", "drop"] and "-30.0000 +20.0000 +50.0000" in lines[5]
    assert main(["plan", "dh3", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["labels"] == ["home", None, "drop"]
