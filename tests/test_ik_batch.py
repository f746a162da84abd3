"""Batch numerical IK (planner.ik.numeric.batch through NlpIK.solve_batch): the same answers as
single calls, every answer checked by Pinocchio FK and the limits, bad input named, unreachable
targets as statuses."""

from __future__ import annotations

import math

import numpy as np
import pytest
from dh_arms import property_settings
from hypothesis import given
from hypothesis import strategies as st
from test_casadi_kinematics import MIXED_URDF

from planner import InvalidArgumentError, InvalidConfigurationError, JointLimitError, Robot, Target
from planner.app.benchmark import make_target
from planner.geometry.joint_space import angular_joints, wrapped_distance
from planner.geometry.target import target_errors
from planner.geometry.target_batch import BatchTargets
from planner.ik.numeric.batch_result import BatchIKResult
from planner.ik.numeric.solver import DISTINCT, NlpIK
from planner.ik.options import IKOptions
from planner.ik.result import IKResult
from planner.ik.status import IKStatus

from conftest import get_robot, needs_example_robot_data

_SOLVERS: dict[str, NlpIK] = {}


def solver(name: str) -> NlpIK:
    if name not in _SOLVERS:
        _SOLVERS[name] = NlpIK(get_robot(name))
    return _SOLVERS[name]


def check_batch(robot: Robot, targets: list[Target], batch: BatchIKResult, tol: float = 1e-6) -> None:
    """Every solved answer independently: Pinocchio FK within `tol`, within the limits, errors as reported."""
    assert len(batch) == len(targets)
    for target, result in zip(targets, batch):
        assert isinstance(result, IKResult)
        if not result.success:
            continue
        assert result.status == IKStatus.SOLVED
        assert robot.within_limits(result.q)
        position_error, orientation_error = target_errors(robot, target, result.q)
        assert position_error <= tol and orientation_error <= tol
        assert result.position_error == pytest.approx(position_error, abs=1e-12)
        assert result.orientation_error == pytest.approx(orientation_error, abs=1e-9)


def _apart(robot: Robot, kind: str, q: np.ndarray, task_distance: float) -> float:
    """How far apart [rad] two configurations of a non-redundant arm near q can be whose tip poses
    are `task_distance` apart (first order: over the task Jacobian's smallest singular value); 0 if redundant."""
    rows = {"pose": 6, "position": 3}.get(kind)
    if rows is None or rows != robot.dof:
        return 0.0
    jac = robot.jacobian(q)[:rows]
    return task_distance / np.linalg.svd(jac, compute_uv=False)[-1]


def compare_with_single_calls(name: str, kind: str, n: int, near: bool) -> None:
    """solve_batch and N single calls: every target solved by both; the same q where both answered from the seed."""
    robot = get_robot(name)
    ik = solver(name)
    rng = np.random.default_rng(7)
    q_true = robot.random_configurations(rng, n)
    if near:
        seeds = np.clip(q_true + rng.uniform(-0.2, 0.2, q_true.shape), robot.lower, robot.upper)
    else:
        seeds = robot.random_configurations(rng, n)
    targets = [make_target(robot, kind, q) for q in q_true]
    options = IKOptions(time_budget=0.5)
    batch = ik.solve_batch(targets, seeds, options)
    singles = [ik.solve(t, s, options) for t, s in zip(targets, seeds)]
    check_batch(robot, targets, batch)
    assert batch.success.all() and all(s.success for s in singles)
    angular = angular_joints(robot)
    both_seed = [i for i in range(n) if batch[i].attempt_kind == "seed" and singles[i].attempt_kind == "seed"]
    for i in both_seed:
        # One solution by the solver's own definition (DISTINCT), or near a singularity as far
        # apart as two poses within the tolerance of the target can be (a single call may stop
        # its seed's iteration earlier, within the tolerance); the angles taken nearest the seed
        # as a single call takes them: the same values, not only modulo 2 pi.
        bound = max(DISTINCT, _apart(robot, kind, batch.q[i], 4 * options.position_tolerance))
        assert wrapped_distance(batch.q[i], singles[i].q, angular) <= bound, i
        np.testing.assert_allclose(batch.q[i], singles[i].q, atol=bound)
    if near:
        assert len(both_seed) >= 0.9 * n
    else:
        assert len(both_seed) >= 0.2 * n


@pytest.mark.parametrize(("name", "kind"), [("al5c", "pitch"), ("dh3", "position"), ("three_joint", "pitch")])
@pytest.mark.parametrize("near", [True, False])
def test_batch_gives_the_single_call_answers_on_bundled_arms(name, kind, near):
    compare_with_single_calls(name, kind, 60, near)


@needs_example_robot_data
@pytest.mark.parametrize("near", [True, False])
def test_batch_gives_the_single_call_answers_on_ur5(near):
    compare_with_single_calls("ur5", "pose", 150, near)


@needs_example_robot_data
def test_batch_of_pose_arrays_on_ur5_solves_every_target():
    robot = get_robot("ur5")
    rng = np.random.default_rng(3)
    q_true = robot.random_configurations(rng, 400)
    poses = np.stack([robot.fk(q) for q in q_true])
    seeds = robot.random_configurations(rng, 400)
    batch = solver("ur5").solve_batch(poses, seeds)
    assert batch.solve_rate == 1.0
    check_batch(robot, [Target.from_pose(p) for p in poses], batch)
    # Without seeds, the restart configurations alone.
    unseeded = solver("ur5").solve_batch(poses[:50])
    assert unseeded.success.all() and not unseeded.seeded
    assert {r.attempt_kind for r in unseeded} == {"random"}
    check_batch(robot, [Target.from_pose(p) for p in poses[:50]], unseeded)


def test_mixed_target_kinds_and_one_seed_for_all():
    robot = get_robot("al5c")
    rng = np.random.default_rng(4)
    q_true = robot.random_configurations(rng, 12)
    kinds = ["position", "pitch", "position", "pitch"] * 3
    targets = [make_target(robot, k, q) for k, q in zip(kinds, q_true)]
    home = np.clip(np.zeros(robot.dof), robot.lower, robot.upper)
    batch = solver("al5c").solve_batch(targets, home)
    assert batch.success.all()
    check_batch(robot, targets, batch)
    for result in batch:
        assert result.solutions[0].distance == pytest.approx(wrapped_distance(result.q, home, angular_joints(robot)))
    # Positions as an (N, 3) array are position targets.
    positions = np.array([t.position for t in targets])
    by_array = solver("al5c").solve_batch(positions, home)
    assert by_array.success.all()
    as_objects = np.empty(len(targets), dtype=object)
    as_objects[:] = targets
    np.testing.assert_array_equal(solver("al5c").solve_batch(as_objects, home).q, batch.q)
    check_batch(robot, [Target(p) for p in positions], by_array)


def test_continuous_joints_are_wrapped_or_nearest_the_seed():
    robot = Robot(MIXED_URDF, tip="tool")
    ik = NlpIK(robot)
    rng = np.random.default_rng(13)
    q_true = robot.random_configurations(rng, 20)
    targets = [make_target(robot, "position", q) for q in q_true]
    batch = ik.solve_batch(targets)
    assert batch.success.all()
    check_batch(robot, targets, batch)
    assert np.all((batch.q[:, 1] >= -math.pi) & (batch.q[:, 1] < math.pi))
    seeds = q_true.copy()
    seeds[:, 1] += 4 * math.pi  # a seed several turns away: the answer's angle follows it
    seeded = ik.solve_batch(targets, seeds)
    assert seeded.success.all()
    check_batch(robot, targets, seeded)
    assert np.all(np.abs(seeded.q[:, 1] - seeds[:, 1]) <= math.pi + 1e-9)


def test_unreachable_targets_are_statuses_with_reasons():
    robot = get_robot("dh3")
    ik = solver("dh3")
    reachable = make_target(robot, "position", np.array([0.4, 0.6, 0.9]))
    far = Target([50.0, 0.0, 0.0])
    batch = ik.solve_batch([reachable, far, reachable], options=IKOptions(max_attempts=5))
    assert batch.success.tolist() == [True, False, True]
    result = batch[1]
    assert result.status == IKStatus.NOT_CONVERGED and not result.success
    assert result.attempts == 5 and result.attempt is None and result.attempt_kind is None
    assert "none of 5 attempts reached the target before the attempt cap ran out" in result.reason
    assert result.position_error == pytest.approx(target_errors(robot, far, result.q)[0], abs=1e-12)
    assert robot.within_limits(result.q)
    assert result.solutions == ()
    assert batch[-1].success and batch[0].reason.startswith("reached by attempt")
    assert [r.success for r in batch[0:2]] == [True, False]
    with pytest.raises(IndexError):
        batch[3]


def test_empty_batch_and_the_secondary_objectives_path():
    ik = solver("al5c")
    empty = ik.solve_batch(np.zeros((0, 3)))
    assert len(empty) == 0 and list(empty) == [] and empty.solve_rate == 1.0
    robot = get_robot("al5c")
    rng = np.random.default_rng(5)
    q_true = robot.random_configurations(rng, 5)
    targets = [make_target(robot, "position", q) for q in q_true]
    near = ik.solve_batch(targets, q_true, IKOptions(near_seed=True, time_budget=0.5))
    singles = [ik.solve(t, q, IKOptions(near_seed=True, time_budget=0.5)) for t, q in zip(targets, q_true)]
    for b, s in zip(near, singles):
        np.testing.assert_allclose(b.q, s.q, atol=1e-9)
        assert b.reason == s.reason and len(b.solutions) == len(s.solutions)


def test_uncompiled_kernel_gives_the_same_answers():
    robot = get_robot("dh3")
    rng = np.random.default_rng(6)
    q_true = robot.random_configurations(rng, 10)
    targets = [make_target(robot, "position", q) for q in q_true]
    seeds = robot.random_configurations(rng, 10)
    compiled = solver("dh3").solve_batch(targets, seeds)
    plain = NlpIK(robot, jit=False).solve_batch(targets, seeds)
    np.testing.assert_allclose(plain.q, compiled.q, atol=1e-9)
    assert plain.success.tolist() == compiled.success.tolist()


def test_bad_input_names_the_target_or_seed():
    ik = solver("dh3")
    robot = get_robot("dh3")
    positions = np.array([[0.3, 0.1, 0.5], [np.nan, 0.0, 0.0]])
    with pytest.raises(InvalidArgumentError, match=r"target 1 holds NaN or infinite values"):
        ik.solve_batch(positions)
    with pytest.raises(InvalidArgumentError, match=r"target 1: target position must be finite"):
        ik.solve_batch([positions[0], positions[1]])
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[2, :3, :3] *= 2.0
    with pytest.raises(InvalidArgumentError, match=r"target 2: rotation is not a proper orthonormal matrix"):
        ik.solve_batch(poses)
    with pytest.raises(InvalidArgumentError, match=r"targets must have shape \(N, 3\)"):
        ik.solve_batch(np.zeros((4, 2)))
    with pytest.raises(InvalidArgumentError, match=r"targets must be an array"):
        ik.solve_batch(3.0)  # type: ignore[arg-type]
    with pytest.raises(InvalidConfigurationError, match=r"got 2 targets but 3 seeds"):
        ik.solve_batch(positions[:1].repeat(2, axis=0), np.zeros((3, robot.dof)))
    with pytest.raises(InvalidConfigurationError, match=r"expects"):
        ik.solve_batch(positions[:1], np.zeros((1, robot.dof + 1)))
    outside = np.zeros((2, robot.dof))
    outside[1, 0] = robot.upper[0] + 1.0
    with pytest.raises(JointLimitError, match=r"seed of target 1"):
        ik.solve_batch(positions[:1].repeat(2, axis=0), outside)
    eye = np.eye(3)[None]
    with pytest.raises(InvalidArgumentError, match=r"target 0: unknown kind 'orbit'; valid: position, pose, pitch"):
        BatchTargets(np.zeros((1, 3)), eye, np.zeros(1), ["orbit"])
    with pytest.raises(InvalidArgumentError, match=r"rotations must have shape \(1, 3, 3\), got \(3, 3\)"):
        BatchTargets(np.zeros((1, 3)), np.eye(3), np.zeros(1), ["pose"])
    with pytest.raises(InvalidArgumentError, match=r"target 0 holds NaN or infinite values"):
        BatchTargets(np.zeros((1, 3)), eye, np.array([np.inf]), ["pitch"])
    with pytest.raises(InvalidArgumentError, match=r"options must be a planner.IKOptions"):
        ik.solve_batch(positions[:1], options={"time_budget": 1})  # type: ignore[arg-type]


@given(data=st.data())
@property_settings(15)
def test_random_reachable_batches_are_solved_and_verified(data):
    name = data.draw(st.sampled_from(["al5c", "dh3", "three_joint", "shelley"]))
    robot = get_robot(name)
    kind = "pitch" if name in ("al5c", "three_joint") and data.draw(st.booleans()) else "position"
    n = data.draw(st.integers(1, 20))
    seed = data.draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    q_true = robot.random_configurations(rng, n)
    targets = [make_target(robot, kind, q) for q in q_true]
    seeds = robot.random_configurations(rng, n) if data.draw(st.booleans()) else None
    batch = solver(name).solve_batch(targets, seeds, IKOptions(time_budget=0.5))
    assert batch.success.all(), [batch.reason(i) for i in np.flatnonzero(~batch.success)]
    check_batch(robot, targets, batch)


def test_restarts_from_an_rng_are_reproducible_and_the_time_budget_ends_restarts():
    robot = get_robot("dh3")
    ik = solver("dh3")
    rng = np.random.default_rng(8)
    q_true = robot.random_configurations(rng, 30)
    targets = [make_target(robot, "position", q) for q in q_true]
    a = ik.solve_batch(targets, options=IKOptions(rng=5))
    b = ik.solve_batch(targets, options=IKOptions(rng=np.random.default_rng(5)))
    np.testing.assert_array_equal(a.q, b.q)
    assert a.success.all()
    check_batch(robot, targets, a)
    far = Target([50.0, 0.0, 0.0])
    out = ik.solve_batch([far], options=IKOptions(time_budget=1e-9))
    assert out.attempts.tolist() == [1]
    assert "before the time budget ran out" in out[0].reason
