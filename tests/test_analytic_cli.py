"""`planner ik`: JSON output, statuses as results, bad input as one-line errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from planner import load_robot
from planner.app.cli import main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_ik_json_best_solution(capsys):
    robot = load_robot("dh3")
    q = np.radians([45.0, 90.0, 90.0])
    x, y, z = robot.fk(q)[:3, 3].tolist()
    code, out, err = run(
        capsys, "ik", "dh3", repr(x), repr(y), repr(z), "--json", "--current", "40", "80", "80", "--deg"
    )
    assert code == 0 and err == ""
    data = json.loads(out)
    assert data["status"] == "solved" and data["method"] == "analytic" and data["success"]
    assert len(data["solutions"]) == 1 and data["best"] == 0  # without --all: the chosen one
    sol = data["solutions"][0]
    assert set(sol) >= {"q", "position_error", "orientation_error", "label", "within_limits", "singular", "distance"}
    assert sol["within_limits"] and sol["q"] == data["q"]
    np.testing.assert_allclose(sol["q"], q, atol=1e-12)
    assert np.linalg.norm(robot.fk(sol["q"])[:3, 3] - [x, y, z]) < 1e-9


def test_ik_all_with_pitch_in_degrees(capsys):
    code, out, _ = run(capsys, "ik", "al5c", "0.25", "0.05", "0.12", "--pitch", "-60", "--deg", "--all", "--json")
    assert code == 0
    data = json.loads(out)
    assert data["target"]["pitch"] == pytest.approx(math.radians(-60))
    assert len(data["solutions"]) == 4
    robot = load_robot("al5c")
    for sol in data["solutions"]:
        assert np.linalg.norm(robot.fk(sol["q"])[:3, 3] - [0.25, 0.05, 0.12]) < 1e-9
        assert sum(sol["q"][1:4]) == pytest.approx(math.radians(-60)) or sol["label"].startswith("back")


def test_ik_rpy_target(capsys):
    robot = load_robot("three_joint")
    q = [0.2, 0.7, -0.9, 0.4]
    pose = robot.fk(q)
    r = pose[:3, :3]
    rpy = [
        math.atan2(r[2, 1], r[2, 2]),
        math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0])),
        math.atan2(r[1, 0], r[0, 0]),
    ]
    x, y, z = pose[:3, 3].tolist()
    code, out, _ = run(capsys, "ik", "three_joint", repr(x), repr(y), repr(z), "--rpy", *map(repr, rpy), "--json")
    data = json.loads(out)
    assert code == 0 and data["status"] == "solved"
    np.testing.assert_allclose(data["solutions"][0]["q"], q, atol=1e-9)
    assert data["solutions"][0]["orientation_error"] < 1e-9


def test_ik_unreachable_is_a_result(capsys):
    code, out, err = run(capsys, "ik", "three_joint", "20", "0", "0", "--json")
    assert code == 0 and err == ""
    data = json.loads(out)
    assert data["status"] == "beyond_max_reach" and data["solutions"] == []
    assert "beyond the 10 m" in data["reason"]


def test_ik_outside_limits_prints_none_without_all(capsys):
    code, out, _ = run(capsys, "ik", "shelley", "-0.15", "0", "0", "--json")
    data = json.loads(out)
    assert code == 0 and data["status"] == "outside_joint_limits" and data["solutions"] == []
    code, out, _ = run(capsys, "ik", "shelley", "-0.15", "0", "0", "--json", "--all")
    assert [s["within_limits"] for s in json.loads(out)["solutions"]] == [False, False]


def test_ik_current_orders_the_solutions(capsys):
    code, out, _ = run(capsys, "ik", "shelley", "0.15", "0", "0", "--all", "--json", "--current", "-30", "60", "--deg")
    sols = json.loads(out)["solutions"]
    assert sols[0]["label"] == "elbow-right"


def test_ik_text_output(capsys):
    code, out, _ = run(capsys, "ik", "dh3", "0.11", "0", "0.09", "--deg", "--all")
    assert code == 0
    assert "dh3 analytic IK" in out and ": solved" in out
    assert "front/elbow-up" in out and "q [deg]" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["ik", "al5c", "0.2", "0", "0.1", "--pitch", "0", "--rpy", "0", "0", "0"], "either --pitch or --rpy"),
        (["ik", "al5c", "0.2", "nan", "0.1"], "must be finite"),
        (["ik", "al5c", "0.2", "0", "0.1", "--current", "0", "0"], "expects (5,)"),
        (["ik", "nosuch", "0.2", "0", "0.1"], "unknown robot 'nosuch'"),
    ],
)
def test_ik_bad_input_exits_1(capsys, argv, message):
    code, out, err = run(capsys, *argv)
    assert code == 1 and out == ""
    assert err.count("\n") == 1 and err.startswith("planner ik: error: ") and message in err


def test_ik_outside_the_family_exits_1(capsys):
    from planner.model.catalog import example_robot_data_dir

    if example_robot_data_dir() is None:
        pytest.skip("example-robot-data is not installed")
    code, _, err = run(capsys, "ik", "ur5", "0.3", "0.1", "0.2", "--method", "analytic")
    assert code == 1 and "wrist_3_joint" in err and "use the method 'nlp'" in err
    code, out, err = run(capsys, "ik", "ur5", "0.3", "0.1", "0.2", "--json")  # the default, auto: the NLP
    assert code == 0 and err == "" and json.loads(out)["method"] == "nlp"
