"""The one IK entry point: one result type for every method, solutions, options, the solver cache."""

from __future__ import annotations

import gc
import weakref

import numpy as np
import pytest

import planner
from planner import IKOptions, IKResult, IKSolution, IKStatus, Target, approach_pitch, load_robot, solve_ik
from planner.ik.result import LazySolutions
from planner.ik.solvers import IKSolvers


@pytest.fixture(scope="module")
def al5c():
    return load_robot("al5c")


@pytest.mark.parametrize("method", ["auto", "analytic", "nlp"])
def test_every_method_answers_with_one_result_type(al5c, method):
    q = np.array([0.3, 1.0, -1.2, -0.4, 0.2])
    target = Target(al5c.position(q), pitch=planner.approach_pitch(al5c, q))
    seed = (al5c.lower + al5c.upper) / 2
    result = solve_ik(al5c, target, seed, method=method)
    assert type(result) is IKResult and isinstance(result.status, IKStatus)
    assert result.success and result.status == "solved" and str(result.status) == "solved"
    assert result.method == ("nlp" if method == "nlp" else "analytic")
    assert all(type(s) is IKSolution for s in result.solutions)
    assert any(np.array_equal(s.q, result.q) for s in result.solutions)
    # Nearest the seed first, each marked within limits, errors by Pinocchio FK.
    distances = [s.distance for s in result.solutions]
    assert distances == sorted(distances)
    for s in result.solutions:
        assert s.within_limits == bool(al5c.within_limits(s.q))
        pe, oe = planner.geometry.target.target_errors(al5c, target, s.q)
        assert s.position_error == pytest.approx(pe, abs=1e-15) and s.orientation_error == pytest.approx(oe, abs=1e-15)
    assert result.as_dict()["status"] == "solved" and len(result.as_dict()["solutions"]) == len(result.solutions)


def test_closed_form_lists_every_branch_including_those_outside_the_limits():
    robot = load_robot("shelley")
    result = solve_ik(robot, Target([-0.15, 0.0, 0.0]), method="analytic")
    assert not result.success and result.status == IKStatus.OUTSIDE_JOINT_LIMITS
    assert [s.label for s in result.solutions] == ["elbow-left", "elbow-right"]
    assert not any(s.within_limits for s in result.solutions) and result.within_limits == ()
    assert all(s.position_error < 1e-12 for s in result.solutions)  # they reach it, outside the limits


def test_solutions_are_checked_when_first_read(al5c):
    result = solve_ik(al5c, al5c.position(np.array([0.1, 1.2, -1.0, -0.3, 0.0])), method="nlp")
    assert isinstance(result.solutions, LazySolutions)
    assert "not yet read" in repr(result.solutions)
    first = tuple(result.solutions)
    assert result.solutions == first and len(result.solutions) == len(first) and result.solutions[0] == first[0]
    assert result.solutions + () == first


def test_options_are_one_frozen_object():
    options = IKOptions(time_budget=0.01, rng=3)
    with pytest.raises(AttributeError):
        options.time_budget = 1.0  # type: ignore[misc]
    with pytest.raises(planner.InvalidArgumentError, match="options must be a planner.IKOptions, got dict"):
        solve_ik(load_robot("dh3"), [0.1, 0.0, 0.1], options={"time_budget": 0.01})  # type: ignore[arg-type]
    with pytest.raises(planner.InvalidArgumentError, match="rng must be an int seed"):
        IKOptions(rng="seed")  # type: ignore[arg-type]


def test_one_solver_cache_per_robot_freed_with_it():
    robot = planner.Robot(load_robot("al5c").urdf, tip="gripper")
    for method in ("auto", "analytic", "nlp"):
        solve_ik(robot, robot.position(np.zeros(robot.dof)), method=method)
    assert IKSolvers in robot.derived and IKSolvers.of(robot) is IKSolvers.of(robot)
    ref = weakref.ref(robot)
    del robot
    gc.collect()
    assert ref() is None


def _wide_arm():
    """dh3's geometry with every joint free over +-350 deg: whole turns fit within the limits."""
    description = {
        "name": "wide",
        "units": {"length": "cm", "angle": "deg"},
        "servo_seconds_per_60deg": 0.2,
        "dh": [
            {"name": "yaw", "theta": 0, "d": 3, "a": 0, "alpha": 90, "lower": -350, "upper": 350},
            {"name": "shoulder", "theta": 0, "d": 0, "a": 6, "alpha": 180, "lower": -350, "upper": 350},
            {"name": "elbow", "theta": 0, "d": 0, "a": 11, "alpha": 0, "lower": -350, "upper": 350},
        ],
        "tool": {"name": "hand"},
    }
    return planner.Robot(planner.urdf_from_dh(description), tip="hand")


@pytest.mark.parametrize(
    ("name", "method", "count"),
    [("wide", "auto", 60), ("wide", "nlp", 60), ("ur5", "nlp", 200), ("ur5", "auto", 200), ("panda", "auto", 200)],
)
def test_answers_take_no_needless_whole_turn(name, method, count):
    if name == "wide":
        robot = _wide_arm()
    else:
        from planner.model.catalog import example_robot_data_dir

        if example_robot_data_dir() is None:
            pytest.skip("example-robot-data is not installed")
        robot = load_robot(name)
    rng = np.random.default_rng(7)
    options = IKOptions(closed_form_seeds=False)  # the NLP on its own: random restarts too
    for _ in range(count):
        q, seed = robot.random_configurations(rng, 2)
        target = robot.position(q) if robot.dof < 6 else robot.fk(q)
        result = solve_ik(robot, target, seed, method=method, options=options)
        assert result.success
        for answer in (result.q, *(s.q for s in result.solutions)):
            for j in range(robot.dof):
                for turn in (-2 * np.pi, 2 * np.pi):
                    shifted = answer[j] + turn
                    nearer = abs(shifted - seed[j]) < abs(answer[j] - seed[j])
                    assert not (nearer and robot.lower[j] <= shifted <= robot.upper[j]), (method, answer, seed)


def test_a_joint_the_target_leaves_free_keeps_the_seed_value():
    # al5c's wrist roll turns about the gripper's own axis: neither a position nor an approach
    # pitch fixes it, so every method must leave it where the seed has it.
    robot = load_robot("al5c")
    rng = np.random.default_rng(17)
    for _ in range(40):
        q, seed = rng.uniform(robot.lower, robot.upper), rng.uniform(robot.lower, robot.upper)
        position = robot.fk(q)[:3, 3]
        for target in (Target(position=position), Target(position=position, pitch=approach_pitch(robot, q))):
            for method in ("auto", "analytic", "nlp"):
                result = solve_ik(robot, target, seed, method=method)
                assert result.success, (method, target)
                assert result.q[4] == pytest.approx(seed[4], abs=1e-9), (method, target)
