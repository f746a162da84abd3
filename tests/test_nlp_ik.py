"""Numerical IK (planner.ik.numeric.solver): round trips checked by Pinocchio FK, limits, restarts,
secondary objectives, the compile cache, and bad input with its messages."""

from __future__ import annotations

import dataclasses
import math
import os
import time

import numpy as np
import pytest
from test_casadi_kinematics import MIXED_URDF

from planner import InvalidArgumentError, InvalidConfigurationError, JointLimitError, PlannerError, Robot, Target
from planner.app.benchmark import make_target
from planner.core.rotations import rotation_error
from planner.geometry.joint_space import configurations_close, wrapped_distance
from planner.geometry.target import approach_direction, as_target, pitch_error, target_errors
from planner.ik.numeric.codegen import compile_function
from planner.ik.numeric.solver import ATTEMPT_KINDS, DISTINCT, NlpIK
from planner.ik.options import IKOptions
from planner.ik.result import IKResult
from planner.ik.status import IKStatus

from conftest import get_robot, needs_example_robot_data

_SOLVERS: dict[str, NlpIK] = {}


def solver(name: str) -> NlpIK:
    if name not in _SOLVERS:
        _SOLVERS[name] = NlpIK(get_robot(name))
    return _SOLVERS[name]


# Arms whose pitch plane contains the base z axis: a pitch fixes the approach direction.
IN_PLANE_ARMS = ("al5c", "three_joint")


def assert_reached(robot: Robot, target: Target, result: IKResult, tol: float = 1e-6) -> None:
    """Check a successful result independently: Pinocchio FK, limits, and the reported errors."""
    assert result.success, result.reason
    assert result.status == "solved"
    assert robot.within_limits(result.q)
    pose = robot.fk(result.q)
    position_error = np.linalg.norm(pose[:3, 3] - target.position)
    assert position_error <= tol
    assert result.position_error == pytest.approx(position_error, abs=1e-15)
    if target.rotation is not None:
        angle = rotation_error(pose[:3, :3], target.rotation)
        assert angle <= tol
        assert result.orientation_error == pytest.approx(angle, abs=1e-12)
    elif target.pitch is not None:
        approach = pose[:3, :3] @ robot.approach_axis
        # The convention: the elevation, the horizontal part on the outward side.
        assert abs(approach[2] - math.sin(target.pitch)) <= tol
        assert math.cos(target.pitch) * (approach[:2] @ target.position[:2]) >= -tol
        if robot.name in IN_PLANE_ARMS:
            # There it is the direction in the vertical plane through the base axis and the tip.
            wanted = approach_direction(pose[:3, 3], target.pitch)
            assert np.linalg.norm(approach - wanted) <= 2 * tol
        error = pitch_error(approach, target.position, target.pitch)
        assert error <= tol
        assert result.orientation_error == pytest.approx(error, abs=1e-12)
    else:
        assert result.orientation_error == 0.0


BUNDLED_CASES = [
    ("shelley", "position"),
    ("dh3", "position"),
    ("three_joint", "position"),
    ("three_joint", "pitch"),
    ("al5c", "position"),
    ("al5c", "pitch"),
]


@pytest.mark.parametrize(("name", "kind"), BUNDLED_CASES)
def test_round_trip_on_bundled_arms(name, kind):
    robot = get_robot(name)
    rng = np.random.default_rng(10)
    for q, seed in zip(robot.random_configurations(rng, 25), robot.random_configurations(rng, 25)):
        target = make_target(robot, kind, q)
        assert_reached(robot, target, solver(name).solve(target, seed))


@needs_example_robot_data
@pytest.mark.parametrize("name", ["ur5", "panda", "so101", "z1"])
def test_pose_round_trip_on_example_arms(name):
    # so101 has 5 joints: a 6-D pose from FK is reachable, so it must be solved too.
    robot = get_robot(name)
    rng = np.random.default_rng(11)
    for q, seed in zip(robot.random_configurations(rng, 40), robot.random_configurations(rng, 40)):
        target = make_target(robot, "pose", q)
        result = solver(name).solve(target, seed, IKOptions(time_budget=1.0))
        assert_reached(robot, target, result)
        assert result.attempt_kind in ("seed", "random")
        assert 0 <= result.attempt < result.attempts


@needs_example_robot_data
def test_pitch_round_trip_on_so101():
    # Its arm plane passes beside the base z axis: the pitch is the elevation, outward.
    robot = get_robot("so101")
    rng = np.random.default_rng(13)
    for q, seed in zip(robot.random_configurations(rng, 40), robot.random_configurations(rng, 40)):
        target = make_target(robot, "pitch", q)
        assert_reached(robot, target, solver("so101").solve(target, seed, IKOptions(time_budget=1.0)))


@needs_example_robot_data
def test_position_target_on_a_redundant_arm():
    robot = get_robot("ur5")
    rng = np.random.default_rng(12)
    for q in robot.random_configurations(rng, 10):
        target = make_target(robot, "position", q)
        assert_reached(robot, target, solver("ur5").solve(target))


def test_pitch_target_on_the_base_axis_fixes_only_the_elevation():
    robot = get_robot("three_joint")
    # Straight above the base, pointing 30 deg up: any yaw will do.
    target = Target([0.0, 0.0, 5.0], pitch=math.radians(30))
    result = solver("three_joint").solve(target)
    assert result.success
    approach = robot.fk(result.q)[:3, :3] @ robot.approach_axis
    assert math.asin(approach[2]) == pytest.approx(math.radians(30), abs=1e-6)
    assert target_errors(robot, target, result.q)[1] <= 1e-6


def test_pitch_targets_straight_down_and_beyond_vertical():
    robot = get_robot("three_joint")
    # Straight down: the one direction -z (an elevation residual alone would converge slowly).
    q = np.array([0.3, 1.0, -0.5, -math.pi / 2 - 0.5])
    target = Target(robot.position(q), pitch=-math.pi / 2)
    result = solver("three_joint").solve(target, np.zeros(4))
    assert_reached(robot, target, result)
    np.testing.assert_allclose(robot.fk(result.q)[:3, :3] @ robot.approach_axis, [0.0, 0.0, -1.0], atol=1e-6)
    # Past vertical (|pitch| > 90 deg): the horizontal part points towards the base axis.
    q = np.array([-0.4, 0.5, 0.3, 1.2])
    target = make_target(robot, "pitch", q)
    assert abs(target.pitch) > math.pi / 2
    result = solver("three_joint").solve(target, np.zeros(4))
    assert_reached(robot, target, result)
    approach = robot.fk(result.q)[:3, :3] @ robot.approach_axis
    assert approach[:2] @ target.position[:2] < 0.0


def test_seed_at_a_solution_needs_no_iteration():
    robot = get_robot("al5c")
    q = np.array([0.3, 1.0, -1.2, 0.4, 0.2])
    target = make_target(robot, "pitch", q)
    result = solver("al5c").solve(target, q)
    assert result.success and result.attempt == 0 and result.attempt_kind == "seed"
    assert result.iterations == 0
    np.testing.assert_array_equal(result.q, q)


def test_extra_seeds_are_closed_form_attempts():
    robot = get_robot("dh3")
    q = np.array([0.4, 0.6, 0.9])
    target = make_target(robot, "position", q)
    result = solver("dh3").solve(target, extra_seeds=[q])
    assert result.attempt == 0 and result.attempt_kind == "closed_form"
    far_seed = np.array([-2.0, -2.0, -2.0])
    result = solver("dh3").solve(target, far_seed, extra_seeds=np.array([q]))
    assert result.success and result.attempt_kind in ("seed", "closed_form")


def test_unreachable_target_is_a_result_within_limits():
    robot = get_robot("shelley")
    target = Target([1.0, 0.0, 0.0])  # reach is 0.18 m
    result = solver("shelley").solve(target, options=IKOptions(max_attempts=16))
    assert not result.success
    assert result.status == "not_converged"
    assert "none of 16 attempts reached the target before the attempt cap" in result.reason
    assert result.attempts == 16 and result.attempt is None and result.attempt_kind is None
    assert robot.within_limits(result.q)
    # The best attempt stretches towards the target.
    assert result.position_error == pytest.approx(1.0 - np.linalg.norm(robot.position(np.zeros(2))), abs=1e-3)


def test_time_budget_stops_the_restarts():
    target = Target([1.0, 0.0, 0.0])
    start = time.perf_counter()
    result = solver("shelley").solve(target, options=IKOptions(time_budget=0.02))
    assert not result.success and "time budget" in result.reason
    assert time.perf_counter() - start < 1.0  # finishes the batch under way, starts no other


def test_results_are_frozen_and_reproducible():
    robot = get_robot("three_joint")
    target = make_target(robot, "pitch", np.array([0.5, 1.0, -0.5, 0.3]))
    a = solver("three_joint").solve(target)
    b = solver("three_joint").solve(target)
    np.testing.assert_array_equal(a.q, b.q)
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.success = False  # type: ignore[misc]
    with pytest.raises(ValueError):
        a.q[0] = 1.0
    d = a.as_dict()
    assert d["method"] == "nlp" and d["time_ms"] == pytest.approx(a.wall_time * 1e3)
    assert set(d) >= {"q", "success", "status", "position_error", "orientation_error", "iterations", "attempts"}


def test_explicit_rng_draws_other_restarts():
    robot = get_robot("dh3")
    target = make_target(robot, "position", np.array([0.4, 0.6, 0.9]))
    a = solver("dh3").solve(target, options=IKOptions(rng=np.random.default_rng(1)))
    b = solver("dh3").solve(target, options=IKOptions(rng=np.random.default_rng(1)))
    np.testing.assert_array_equal(a.q, b.q)
    assert a.success
    # An int seed is a new generator from that seed on every call.
    c = solver("dh3").solve(target, options=IKOptions(rng=1))
    np.testing.assert_array_equal(c.q, a.q)


def test_continuous_and_prismatic_joints():
    robot = Robot(MIXED_URDF, tip="tool")
    ik = NlpIK(robot)
    rng = np.random.default_rng(13)
    for q in robot.random_configurations(rng, 10):
        target = make_target(robot, "position", q)
        result = ik.solve(target, options=IKOptions(time_budget=0.5))
        assert_reached(robot, target, result)
        assert -math.pi <= result.q[1] < math.pi  # the continuous joint is wrapped


@needs_example_robot_data
def test_near_seed_on_a_redundant_arm_is_nearer_than_the_plain_answer():
    robot = get_robot("panda")
    rng = np.random.default_rng(14)
    middle = (robot.lower + robot.upper) / 2  # keeps every joint clear of its limits
    q_target = middle + rng.uniform(-0.4, 0.4, robot.dof)
    seed = q_target + rng.uniform(-0.6, 0.6, robot.dof)
    target = make_target(robot, "pose", q_target)
    plain = solver("panda").solve(target, seed, IKOptions(time_budget=1.0))
    near = solver("panda").solve(target, seed, IKOptions(near_seed=True, time_budget=1.0))
    assert_reached(robot, target, near)
    assert np.linalg.norm(near.q - seed) <= np.linalg.norm(plain.q - seed) + 1e-7
    # Stationary on the solution set: moving along the redundancy gets no nearer the seed.
    jac = robot.jacobian(near.q)
    null = np.linalg.svd(jac)[2][-1]
    assert abs(null @ (near.q - seed)) <= 1e-4 * max(1.0, np.linalg.norm(near.q - seed))


def test_near_seed_on_a_non_redundant_target_picks_the_nearest_branch():
    robot = get_robot("dh3")
    seed = np.array([0.3, 0.2, 0.5])
    target = make_target(robot, "position", np.array([0.35, 0.3, 0.4]))
    near = solver("dh3").solve(target, seed, IKOptions(near_seed=True))
    assert_reached(robot, target, near)
    np.testing.assert_allclose(near.q, [0.35, 0.3, 0.4], atol=1e-6)


@needs_example_robot_data
def test_near_seed_takes_angles_a_whole_turn_nearer_the_seed():
    robot = get_robot("ur5")  # ranges of +-2 pi except the elbow's +-pi
    rng = np.random.default_rng(15)
    for q, seed in zip(robot.random_configurations(rng, 10), robot.random_configurations(rng, 10)):
        target = make_target(robot, "pose", q)
        result = solver("ur5").solve(target, seed, IKOptions(near_seed=True))
        assert_reached(robot, target, result)
        for j in range(robot.dof):  # no whole turn within the limits brings a joint nearer
            for shifted in (result.q[j] - 2 * math.pi, result.q[j] + 2 * math.pi):
                if robot.lower[j] <= shifted <= robot.upper[j]:
                    assert abs(shifted - seed[j]) >= abs(result.q[j] - seed[j])


def test_near_seed_keeps_continuous_joints_near_the_seed():
    robot = Robot(MIXED_URDF, tip="tool")
    q = np.array([0.3, 7.5, 0.1, -0.1, 1.0])
    result = NlpIK(robot).solve(make_target(robot, "pose", q), q + 0.05, IKOptions(near_seed=True, time_budget=0.5))
    assert result.success and abs(result.q[1] - 7.5) <= math.pi
    # Without near_seed too, every angle is the equivalent nearest the seed (no needless turn)...
    plain = NlpIK(robot).solve(make_target(robot, "pose", q), q + 0.05, IKOptions(time_budget=0.5))
    assert plain.success and abs(plain.q[1] - 7.55) <= math.pi
    # ... and without a seed, continuous joints come back in [-pi, pi).
    unseeded = NlpIK(robot).solve(make_target(robot, "pose", q), None, IKOptions(time_budget=0.5))
    assert unseeded.success and -math.pi <= unseeded.q[1] < math.pi


def test_manipulability_floor():
    robot = get_robot("three_joint")
    q = np.array([0.2, 0.8, -1.0, 0.5])
    target = make_target(robot, "position", q)  # 4 joints for 3 coordinates: redundant
    floor = 1.1 * float(robot.manipulability(q))  # the best on this target is about 1.18 times
    result = solver("three_joint").solve(target, q, IKOptions(manipulability_floor=floor))
    assert_reached(robot, target, result)
    assert robot.manipulability(result.q) >= floor
    impossible = solver("three_joint").solve(target, q, IKOptions(manipulability_floor=1e6, max_attempts=8))
    assert not impossible.success and impossible.status == "below_manipulability_floor"
    assert "none with manipulability >= 1e+06 (position task)" in impossible.reason
    assert impossible.position_error <= 1e-6 and robot.within_limits(impossible.q)


def test_jit_off_gives_the_same_answers():
    robot = get_robot("al5c")
    plain = NlpIK(robot, jit=False)
    assert not plain.compiled("pitch")
    target = make_target(robot, "pitch", np.array([0.3, 1.0, -1.2, 0.4, 0.2]))
    seed = np.array([-0.5, 0.5, -0.8, -0.2, 0.0])
    a, b = plain.solve(target, seed), solver("al5c").solve(target, seed)
    assert a.success and b.success and a.attempt == b.attempt
    np.testing.assert_allclose(a.q, b.q, atol=1e-9)


def test_compile_cache(tmp_path, monkeypatch):
    import casadi as ca

    monkeypatch.setenv("PLANNER_CACHE_DIR", str(tmp_path))
    x = ca.SX.sym("x", 2)
    f = ca.Function("square_sum", [x], [ca.sumsqr(x)])
    compiled = compile_function(f)
    libraries = list((tmp_path / "casadi").glob("*.so"))
    assert len(libraries) == 1 and float(compiled([1.0, 2.0])) == 5.0
    stamp = libraries[0].stat().st_mtime_ns
    again = compile_function(f)  # loaded from the cache, not rebuilt
    assert libraries[0].stat().st_mtime_ns == stamp and float(again([3.0, 4.0])) == 25.0
    monkeypatch.setenv("CC", "false")  # a "compiler" that always fails
    other = ca.Function("other", [x], [x[0] * x[1]])
    with pytest.warns(RuntimeWarning, match="cannot compile CasADi function 'other'"):
        fallback = compile_function(other)
    assert fallback is other and float(fallback([2.0, 3.0])) == 6.0
    monkeypatch.setenv("CC", "no-such-compiler-here")
    assert compile_function(other) is other
    monkeypatch.setenv("PLANNER_JIT", "0")
    assert compile_function(f) is f


# ------------------------------------------------------------------------------ bad input
def test_bad_targets_raise_with_clear_messages():
    ik = solver("dh3")
    with pytest.raises(InvalidArgumentError, match=r"target position must be finite, got \[nan, 0.0, 0.0\]"):
        ik.solve([math.nan, 0.0, 0.0])
    with pytest.raises(InvalidArgumentError, match=r"target position must be finite, got \[0.0, inf, 0.0\]"):
        ik.solve(np.array([0.0, math.inf, 0.0]))
    skewed = np.eye(4)
    skewed[0, 1] = 0.1
    with pytest.raises(InvalidArgumentError, match="rotation is not a proper orthonormal matrix"):
        ik.solve(skewed)
    with pytest.raises(InvalidArgumentError, match=r"quaternion \(x, y, z, w\) has zero norm"):
        ik.solve(Target.from_quaternion([0.1, 0.0, 0.1], [0.0, 0.0, 0.0, 0.0]))
    with pytest.raises(InvalidArgumentError, match=r"target must be a planner.Target, a position \(3,\) or a pose"):
        ik.solve([1.0, 2.0])
    with pytest.raises(InvalidArgumentError, match="pitch must be finite"):
        ik.solve(Target([0.1, 0.0, 0.1], pitch=math.inf))
    assert isinstance(as_target([0.1, 0.2, 0.3]), Target)


def test_bad_seeds_raise_with_clear_messages():
    ik = solver("dh3")
    target = Target([0.1, 0.0, 0.1])
    with pytest.raises(InvalidConfigurationError, match=r"q has shape \(2,\); dh3 expects \(3,\) for joints"):
        ik.solve(target, [0.0, 0.0])
    with pytest.raises(InvalidConfigurationError, match="q holds nan for joint 'shoulder'"):
        ik.solve(target, [0.0, math.nan, 0.0])
    with pytest.raises(
        JointLimitError, match=r"seed: joint 'elbow' value 3 is outside its range \[-2.35619, 2.35619\]"
    ):
        ik.solve(target, [0.0, 0.0, 3.0])
    with pytest.raises(InvalidConfigurationError, match=r"extra_seeds must have shape \(M, 3\)"):
        ik.solve(target, extra_seeds=[0.0, 0.0, 0.0])


@pytest.mark.parametrize("budget", [0.0, -1.0, math.nan, math.inf])
def test_time_budget_must_be_positive(budget):
    with pytest.raises(InvalidArgumentError, match=r"time_budget must be a positive finite number \[s\], got"):
        IKOptions(time_budget=budget)


def test_other_bad_options():
    ik = solver("dh3")
    target = Target([0.1, 0.0, 0.1])
    with pytest.raises(InvalidArgumentError, match="position_tolerance must be a positive finite number"):
        IKOptions(position_tolerance=0.0)
    with pytest.raises(InvalidArgumentError, match="max_attempts must be a positive integer or None, got 0"):
        IKOptions(max_attempts=0)
    with pytest.raises(InvalidArgumentError, match="near_seed=True needs a q_seed"):
        ik.solve(target, options=IKOptions(near_seed=True))
    with pytest.raises(InvalidArgumentError, match="unknown manipulability_task 'twist'; valid: position, pose"):
        IKOptions(manipulability_floor=0.1, manipulability_task="twist")  # type: ignore[arg-type]
    with pytest.raises(
        InvalidArgumentError, match="rng must be an int seed, a numpy.random.Generator or None, got str"
    ):
        IKOptions(rng="3")  # type: ignore[arg-type]
    with pytest.raises(InvalidArgumentError, match="options must be a planner.IKOptions or None, got dict"):
        ik.solve(target, options={"time_budget": 1.0})  # type: ignore[arg-type]
    with pytest.raises(InvalidArgumentError, match="batch_size must be a positive integer, got 0"):
        NlpIK(get_robot("dh3"), batch_size=0)
    with pytest.raises(InvalidArgumentError, match="NlpIK needs a planner.Robot, got str"):
        NlpIK("dh3")  # type: ignore[arg-type]
    assert issubclass(InvalidArgumentError, PlannerError)


def test_environment_is_untouched():
    # Solving must not change the caller's arrays.
    seed = np.array([0.3, 0.2, 0.5])
    before = seed.copy()
    solver("dh3").solve(Target([0.1, 0.0, 0.1]), seed)
    np.testing.assert_array_equal(seed, before)
    assert os.environ.get("PLANNER_JIT") in (None, "1", "0")


# ------------------------------------------------------------------------------ all solutions
def check_solutions(robot: Robot, target: Target, result: IKResult, seed: np.ndarray | None) -> None:
    """Every listed solution reaches the target by Pinocchio FK, lies within the limits, is distinct."""
    assert result.solutions, "a solved call lists at least its answer"
    angular = [k != "prismatic" for k in robot.joint_kinds]
    for sol in result.solutions:
        assert sol.within_limits and robot.within_limits(sol.q)
        assert sol.label in ATTEMPT_KINDS and sol.singular is None
        assert (sol.position_error, sol.orientation_error) == pytest.approx(
            target_errors(robot, target, sol.q), abs=1e-15
        )
        assert sol.position_error <= 1e-6 and sol.orientation_error <= 1e-6
        assert not sol.q.flags.writeable
        if seed is None:
            assert sol.distance is None
        else:
            assert sol.distance == pytest.approx(wrapped_distance(sol.q, seed, angular), abs=1e-12)
    for i, a in enumerate(result.solutions):
        for b in result.solutions[i + 1 :]:
            assert wrapped_distance(a.q, b.q, angular) > DISTINCT
    # The answer is one of them (or a near-duplicate of one).
    assert min(wrapped_distance(result.q, s.q, angular) for s in result.solutions) <= DISTINCT
    if seed is not None:
        distances = [s.distance for s in result.solutions]
        assert distances == sorted(distances)


@pytest.mark.parametrize(("name", "kind"), [("dh3", "position"), ("al5c", "pitch"), ("shelley", "position")])
def test_solutions_list_the_distinct_answers_nearest_the_seed_first(name, kind):
    robot = get_robot(name)
    rng = np.random.default_rng(21)
    several = 0
    for q, seed in zip(robot.random_configurations(rng, 15), robot.random_configurations(rng, 15)):
        target = make_target(robot, kind, q)
        result = solver(name).solve(target, seed)
        assert result.status is IKStatus.SOLVED
        check_solutions(robot, target, result, seed)
        several += len(result.solutions) > 1
    assert several > 0  # the random rows of a batch find other branches


def test_solutions_without_a_seed_are_sorted_by_error():
    robot = get_robot("dh3")
    target = make_target(robot, "position", np.array([0.4, 0.6, 0.9]))
    result = solver("dh3").solve(target)
    check_solutions(robot, target, result, None)
    merits = [s.position_error + 0.25 * solver("dh3").length * s.orientation_error for s in result.solutions]
    assert merits == sorted(merits)


def test_solutions_with_secondary_objectives_and_below_the_floor():
    robot = get_robot("three_joint")
    q = np.array([0.2, 0.8, -1.0, 0.5])
    target = make_target(robot, "position", q)
    near = solver("three_joint").solve(target, q + 0.1, IKOptions(near_seed=True))
    assert near.status is IKStatus.SOLVED
    check_solutions(robot, target, near, q + 0.1)
    impossible = solver("three_joint").solve(target, q, IKOptions(manipulability_floor=1e6, max_attempts=8))
    assert impossible.status is IKStatus.BELOW_MANIPULABILITY_FLOOR and not impossible.success
    check_solutions(robot, target, impossible, q)


def test_not_converged_lists_no_solution_and_reports_its_own_errors():
    robot = get_robot("shelley")
    target = Target([1.0, 0.3, 0.2])  # out of reach
    result = solver("shelley").solve(target, options=IKOptions(max_attempts=64))
    assert result.status is IKStatus.NOT_CONVERGED and result.solutions == ()
    # The best attempt is kept as it was, not overwritten by later batches.
    assert (result.position_error, result.orientation_error) == pytest.approx(
        target_errors(robot, target, result.q), abs=1e-15
    )


def test_joint_distance_takes_angles_modulo_two_pi():
    angular = [True, False]
    assert wrapped_distance([0.1, 0.2], [0.1 + 2 * math.pi, 0.2], angular) == pytest.approx(0.0, abs=1e-12)
    assert wrapped_distance([0.0, 0.2], [0.0, 0.2 + 2 * math.pi], angular) == pytest.approx(2 * math.pi)
    assert wrapped_distance(np.array([3.1, 0.0]), np.array([-3.1, 0.0]), angular) == pytest.approx(2 * math.pi - 6.2)
    assert configurations_close([math.pi - 1e-6, 0.0], [-math.pi + 1e-6, 0.0], angular, 1e-4)
    assert not configurations_close([0.0, 0.0], [0.0, 2e-4], angular, 1e-4)


# ------------------------------------------------------------------------------ the first stage
@needs_example_robot_data
@pytest.mark.parametrize("name", ["ur5", "panda", "so101", "z1"])
def test_pose_targets_from_random_seeds_are_all_reached_and_verified(name):
    # The benchmark's setting in small: random reachable poses, random seeds, default options.
    robot = get_robot(name)
    rng = np.random.default_rng(31)
    for q, seed in zip(robot.random_configurations(rng, 25), robot.random_configurations(rng, 25)):
        target = make_target(robot, "pose", q)
        result = solver(name).solve(target, seed)
        assert_reached(robot, target, result)
        assert result.attempt_kind in ("seed", "random") and result.attempts >= 1


def test_first_stage_answer_is_the_whole_turn_nearest_the_seed():
    # Continuous, revolute and prismatic joints: no angle of the answer can move a whole turn
    # nearer the seed within the limits (the turn is taken in the compiled first stage).
    robot = Robot(MIXED_URDF, tip="tool")
    nlp = NlpIK(robot)
    rng = np.random.default_rng(8)
    for q, seed in zip(robot.random_configurations(rng, 20), robot.random_configurations(rng, 20)):
        target = make_target(robot, "position", q)
        result = nlp.solve(target, seed)
        assert_reached(robot, target, result)
        for j, kind in enumerate(robot.joint_kinds):
            if kind == "prismatic":
                continue
            for turn in (-2 * np.pi, 2 * np.pi):
                shifted = result.q[j] + turn
                nearer = abs(shifted - seed[j]) < abs(result.q[j] - seed[j]) - 1e-12
                assert not (nearer and robot.lower[j] <= shifted <= robot.upper[j]), (result.q, seed)


def test_deferred_extra_seeds_are_computed_only_when_needed():
    robot = get_robot("dh3")
    calls = []

    def branches():
        calls.append(1)
        return [q]

    q = np.array([0.4, 0.6, 0.9])
    target = make_target(robot, "position", q)
    result = solver("dh3").solve(target, q, extra_seeds=branches)
    assert result.success and result.attempt_kind == "seed" and calls == []
    assert len(result.solutions) >= 1 and calls == [1]  # reading the solutions runs one batch
    # Without a seed they are the first starts, computed at once.
    result = solver("dh3").solve(target, extra_seeds=branches)
    assert result.success and result.attempt_kind == "closed_form" and calls == [1, 1]


def test_attempt_cap_below_the_first_stage_is_kept():
    target = Target([5.0, 0.0, 0.0])  # out of reach of shelley
    result = solver("shelley").solve(target, np.zeros(2), IKOptions(max_attempts=3))
    assert result.status is IKStatus.NOT_CONVERGED and result.attempts == 3
    assert "none of 3 attempts reached the target before the attempt cap" in result.reason
    assert get_robot("shelley").within_limits(result.q)


def test_random_starts_from_a_generator_are_reproducible():
    robot = get_robot("al5c")
    rng = np.random.default_rng(12)
    q, seed = robot.random_configurations(rng, 2)
    target = make_target(robot, "pitch", q)
    first = solver("al5c").solve(target, seed, IKOptions(rng=5))
    again = solver("al5c").solve(target, seed, IKOptions(rng=5))
    assert first.success and np.array_equal(first.q, again.q) and first.attempts == again.attempts


def _fields(result: IKResult) -> dict:
    return {f.name: getattr(result, f.name) for f in dataclasses.fields(IKResult)}


def test_solver_results_equal_the_constructors():
    # The first stage builds its result without the dataclass constructor: the same object.
    robot = get_robot("three_joint")
    ik = solver("three_joint")
    rng = np.random.default_rng(12)
    for q_target, q_seed in zip(robot.random_configurations(rng, 20), robot.random_configurations(rng, 20)):
        target = make_target(robot, "pitch", q_target)
        result = ik.solve(target, q_seed)
        assert result.attempt_kind is not None  # answered by the first stage
        assert_reached(robot, target, result)
        rebuilt = IKResult(**_fields(result))
        for name, value in _fields(result).items():
            if name == "q":
                np.testing.assert_array_equal(value, rebuilt.q)
                assert value.dtype == float and value.shape == (robot.dof,)
            else:
                assert value == getattr(rebuilt, name), name
                assert type(value) is type(getattr(rebuilt, name)), name
        assert result.status is IKStatus.SOLVED
        assert not result.q.flags.writeable and result.q.base is None
        with pytest.raises(dataclasses.FrozenInstanceError):
            result.reason = "x"  # type: ignore[misc]
        assert result.as_dict() == {**rebuilt.as_dict(), "solutions": result.as_dict()["solutions"]}
        assert dataclasses.replace(result, wall_time=1.0).wall_time == 1.0
    # A later call does not change an earlier result (no view of the solver's buffers).
    kept = result.q.copy()
    ik.solve(make_target(robot, "pitch", np.array([0.2, 0.4, -0.3, 0.1])), np.zeros(robot.dof))
    np.testing.assert_array_equal(result.q, kept)


def test_from_solver_equals_the_constructor():
    q = np.array([0.1, 0.2, 0.3])
    args = (True, IKStatus.SOLVED, "r", 1e-9, 2e-9, 3, 1, 0, "seed", 1e-5, "nlp", ())
    a, b = IKResult.from_solver(q.copy(), *args), IKResult(q, *args)
    np.testing.assert_array_equal(a.q, b.q)
    assert {k: v for k, v in _fields(a).items() if k != "q"} == {k: v for k, v in _fields(b).items() if k != "q"}
    assert not a.q.flags.writeable and a.as_dict() == b.as_dict()


def test_options_objects_each_give_their_own_answer():
    # The solver works out what an options object needs once and keeps it: a call with other
    # options (more of them than it keeps, and new objects at reused addresses) is never
    # answered with another's tolerances.
    robot = get_robot("three_joint")
    ik, fresh = solver("three_joint"), NlpIK(robot)
    rng = np.random.default_rng(13)
    q_targets, q_seeds = robot.random_configurations(rng, 80), robot.random_configurations(rng, 80)
    for i, (q_target, q_seed) in enumerate(zip(q_targets, q_seeds)):
        tolerance = 10.0 ** -(1 + i % 7)
        options = IKOptions(position_tolerance=tolerance, orientation_tolerance=tolerance)
        target = make_target(robot, "pitch", q_target)
        a = ik.solve(target, q_seed, options)
        b = fresh.solve(target, q_seed, IKOptions(position_tolerance=tolerance, orientation_tolerance=tolerance))
        np.testing.assert_array_equal(a.q, b.q)
        assert (a.iterations, a.attempts, a.status) == (b.iterations, b.attempts, b.status)
        assert a.success and a.position_error <= tolerance and a.orientation_error <= tolerance
        if i % 5 == 0:  # the defaults in between
            np.testing.assert_array_equal(ik.solve(target, q_seed).q, fresh.solve(target, q_seed, IKOptions()).q)


def test_seeds_at_the_limits_pass_and_infinite_seeds_raise():
    ik = solver("dh3")
    robot = ik.robot
    target = Target([0.1, 0.0, 0.1])
    for seed in (robot.lower, robot.upper):
        np.testing.assert_array_equal(ik.check_seed(list(seed)), seed)
    with pytest.raises(InvalidConfigurationError, match="q holds inf for joint 'shoulder'"):
        ik.solve(target, [0.0, math.inf, 0.0])


def test_calls_of_other_kinds_in_between_change_no_answer():
    # The first stage keeps its starts' set-up between calls; calls with a generator or extra
    # seeds in between must not leak into a plain call, nor the other way round.
    robot = get_robot("three_joint")
    shared = NlpIK(robot)
    alone = {kind: NlpIK(robot) for kind in ("plain", "rng", "extra")}
    rng = np.random.default_rng(14)
    q_targets, q_seeds = robot.random_configurations(rng, 60), robot.random_configurations(rng, 60)
    far = robot.random_configurations(rng, 2)
    calls = {
        "plain": lambda ik, target, seed: ik.solve(target, seed),
        "rng": lambda ik, target, seed: ik.solve(target, seed, IKOptions(rng=3)),
        "extra": lambda ik, target, seed: ik.solve(target, seed, extra_seeds=far),
    }
    for i, (q_target, q_seed) in enumerate(zip(q_targets, q_seeds)):
        kind = ("plain", "rng", "plain", "extra")[i % 4]
        target = make_target(robot, "pitch", q_target)
        a, b = calls[kind](shared, target, q_seed), calls[kind](alone[kind], target, q_seed)
        np.testing.assert_array_equal(a.q, b.q)
        assert (a.iterations, a.attempts, a.attempt_kind, a.reason) == (
            b.iterations,
            b.attempts,
            b.attempt_kind,
            b.reason,
        )
