"""DH tables and joint lists turned into URDF; the bundled arms are generated from their own tables."""

from __future__ import annotations

import math
from importlib import resources

import numpy as np
import pytest

import planner
from planner.model.catalog import BUNDLED_ROBOTS
from planner.model.description import dh_transform

from conftest import run_cli


@pytest.mark.parametrize("name", BUNDLED_ROBOTS)
def test_bundled_urdf_is_what_its_description_generates(name):
    folder = resources.files("planner.urdf")
    generated = planner.urdf_from_dh(folder.joinpath(f"{name}.yaml"))
    assert generated == folder.joinpath(f"{name}.urdf").read_text()


@pytest.mark.parametrize("name", BUNDLED_ROBOTS)
def test_bundled_arms_have_limits_speeds_and_a_tip(name):
    robot = planner.load_robot(name)
    assert robot.tip == BUNDLED_ROBOTS[name].tip
    assert np.all(np.isfinite(robot.lower)) and np.all(robot.lower < robot.upper)
    np.testing.assert_allclose(robot.velocity_limit, math.radians(60) / 0.20)  # "0.20 s per 60 deg"


def random_dh_table(rng: np.random.Generator, n: int) -> list[dict]:
    return [
        {
            "theta": float(rng.uniform(-1, 1)),
            "d": float(rng.uniform(-0.2, 0.2)),
            "a": float(rng.uniform(0, 0.3)),
            "alpha": float(rng.choice([0, math.pi / 2, -math.pi / 2, math.pi, rng.uniform(-3, 3)])),
            "lower": -3.0,
            "upper": 3.0,
        }
        for _ in range(n)
    ]


def test_generated_urdf_fk_equals_the_product_of_dh_matrices():
    rng = np.random.default_rng(5)
    for trial in range(10):
        rows = random_dh_table(rng, int(rng.integers(1, 7)))
        robot = planner.Robot(planner.urdf_from_dh({"name": f"arm{trial}", "velocity": 2.0, "dh": rows}))
        for q in robot.random_configurations(rng, 5):
            expected = np.eye(4)
            for row, qi in zip(rows, q):
                expected = expected @ dh_transform(qi + row["theta"], row["d"], row["a"], row["alpha"])
            np.testing.assert_allclose(robot.fk(q), expected, atol=1e-12)


def test_dh_transform_matches_the_seed_general_matrix():
    theta, d, a, alpha = 0.3, 0.02, 0.11, math.pi / 2
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    expected = [[ct, -ca * st, sa * st, a * ct], [st, ca * ct, -sa * ct, a * st], [0, sa, ca, d], [0, 0, 0, 1]]
    np.testing.assert_allclose(dh_transform(theta, d, a, alpha), expected)


def test_joint_list_description_prismatic_and_tool():
    desc = {
        "name": "gantry",
        "units": {"length": "mm", "angle": "deg"},
        "servo_seconds_per_60deg": 0.2,
        "joints": [
            {"name": "slide", "type": "prismatic", "axis": [1, 0, 0], "lower": 0, "upper": 500, "velocity": 100},
            {"name": "turn", "xyz": [0, 0, 50], "axis": [0, 0, 1], "lower": -90, "upper": 90},
        ],
        "tool": {"name": "pen", "xyz": [30, 0, 0]},
    }
    robot = planner.Robot(planner.urdf_from_dh(desc))
    assert robot.joint_kinds == ("prismatic", "revolute") and robot.tip == "pen"
    np.testing.assert_allclose(robot.upper, [0.5, math.pi / 2])
    np.testing.assert_allclose(robot.velocity_limit, [0.1, math.radians(60) / 0.2])
    np.testing.assert_allclose(robot.position([0.2, math.pi / 2]), [0.2, 0.03, 0.05], atol=1e-15)


@pytest.mark.parametrize(
    ("change", "error", "message"),
    [
        (
            {"dh": [{"d": 0, "a": 1, "alpha": 0, "lower": 1, "upper": -1}]},
            planner.InvalidLimitsError,
            r"joint 'joint1' has lower limit 1 > upper limit -1",
        ),
        (
            {"dh": [{"d": 0, "a": 1, "alpha": 0, "lower": -1, "upper": 1, "velocity": -3}]},
            planner.InvalidLimitsError,
            r"joint 'joint1' velocity must be positive, got -3",
        ),
        (
            {"dh": [{"d": 0, "a": 1, "lower": -1, "upper": 1}]},
            planner.InvalidArgumentError,
            r"DH row 1 \('joint1'\) is missing 'alpha'",
        ),
        (
            {"dh": [{"d": 0, "a": 1, "alpha": 0, "lower": -1, "upper": 1, "type": "ball"}]},
            planner.InvalidArgumentError,
            r"unknown type 'ball'; valid types: revolute, prismatic, continuous",
        ),
        (
            {"units": {"length": "furlong"}},
            planner.InvalidArgumentError,
            r"unknown length unit 'furlong'; valid units: m, cm, mm, in",
        ),
        (
            {"dh": [{"d": "x", "a": 1, "alpha": 0, "lower": -1, "upper": 1}]},
            planner.InvalidArgumentError,
            r"joint 'joint1' d must be a number, got 'x'",
        ),
        ({"dh": []}, planner.InvalidArgumentError, r"must be a non-empty list"),
        ({"tool": {"xyz": [0, 0]}}, planner.InvalidArgumentError, r"tool xyz must have 3 numbers, got 2"),
        ({"base": {"rpy": [0, "x", 0]}}, planner.InvalidArgumentError, r"base rpy\[1\] must be a number, got 'x'"),
        ({"tool": {"name": "joint1_link"}}, planner.InvalidArgumentError, r"link names must be unique"),
    ],
)
def test_bad_descriptions(change, error, message):
    desc = {"name": "x", "velocity": 1.0, "dh": [{"d": 0, "a": 1, "alpha": 0, "lower": -1, "upper": 1}]}
    desc.update(change)
    with pytest.raises(error, match=message):
        planner.urdf_from_dh(desc)


def test_missing_speed_is_an_error():
    with pytest.raises(planner.InvalidArgumentError, match=r"joint 'joint1' has no speed"):
        planner.urdf_from_dh({"dh": [{"d": 0, "a": 1, "alpha": 0, "lower": -1, "upper": 1}]})


def test_servo_speed_to_velocity():
    assert planner.servo_speed_to_velocity(0.20) == pytest.approx(math.radians(60) / 0.2)
    assert planner.servo_speed_to_velocity(0.5, 90) == pytest.approx(math.pi)
    with pytest.raises(planner.InvalidLimitsError, match=r"servo speed time must be positive and finite, got -0.1 s"):
        planner.servo_speed_to_velocity(-0.1)


def test_cli_urdf_from_dh_writes_a_loadable_urdf(tmp_path):
    table = tmp_path / "arm.yaml"
    table.write_text(
        "name: mine\nunits: {length: cm, angle: deg}\nservo_seconds_per_60deg: 0.2\n"
        "dh:\n  - {theta: 0, d: 3, a: 0, alpha: 90, lower: -90, upper: 90}\n"
        "  - {theta: 0, d: 0, a: 10, alpha: 0, lower: -90, upper: 90}\n"
    )
    result = run_cli("urdf-from-dh", str(table))
    assert result.returncode == 0, result.stderr
    robot = planner.Robot(result.stdout)
    np.testing.assert_allclose(robot.position([0, 0]), [0.1, 0, 0.03], atol=1e-15)


def test_cli_urdf_from_dh_bad_file(tmp_path):
    result = run_cli("urdf-from-dh", str(tmp_path / "none.yaml"))
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1 and "cannot read arm description" in result.stderr
    assert "Traceback" not in result.stderr
