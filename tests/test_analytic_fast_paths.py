"""Property tests of the closed form's scalar fast paths (``YawPlanarIK.solve``).

On random arms of the yaw-planar family (base yaw, 2 or 3 parallel pitch joints with in-plane
and sideways offsets, flipped axes, an optional wrist roll about an in-plane axis, a tip off the
roll axis) and on the bundled arms: FK(IK(FK(q))) == FK(q) by Pinocchio for every branch, q
among the answers, and the answers equal those of the vectorised path (the reference: the
same closed form over arrays), also for targets moved off the reachable set.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from dh_arms import property_settings
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from planner import Robot, Target, load_robot, rotation_error
from planner.geometry.target import approach_pitch, pitch_error
from planner.ik.analytic import closed_form_solver
from planner.ik.analytic.yaw_planar.arrays import result_from_arrays, solve_arrays
from planner.ik.analytic.yaw_planar.corrected import real_tip_pose, solve_corrected_pose, solve_corrected_scalar
from planner.ik.analytic.yaw_planar.scalar_pose import pose_frame
from planner.model.catalog import example_robot_data_dir

from conftest import single_after

TOL_POS = 1e-9
TOL_ROT = 1e-9
TOL_Q = 1e-6

_FLOAT = {"allow_nan": False, "allow_infinity": False}


def _joint(name, parent, child, xyz, axis, lower, upper):
    return (
        f'<link name="{child}"/><joint name="{name}" type="revolute"><parent link="{parent}"/>'
        f'<child link="{child}"/><origin xyz="{xyz[0]!r} {xyz[1]!r} {xyz[2]!r}" rpy="0 0 0"/>'
        f'<axis xyz="{axis[0]!r} {axis[1]!r} {axis[2]!r}"/>'
        f'<limit lower="{lower!r}" upper="{upper!r}" effort="1" velocity="1"/></joint>'
    )


@st.composite
def yaw_planar_arms(draw, tilt: float = 0.0, n_pitch: int | None = None) -> Robot:
    """A random arm of the yaw-planar family, built from a URDF string.

    `tilt` [rad] turns every axis by about that much off the family's ideal direction.
    """
    length = st.floats(0.05, 0.3, **_FLOAT)
    offset = st.floats(-0.03, 0.03, **_FLOAT)
    sign = st.sampled_from([-1.0, 1.0])
    limit = st.floats(1.0, math.pi, **_FLOAT)
    n_pitch = n_pitch or draw(st.integers(2, 3))
    roll = draw(st.booleans())
    joints = [("yaw", (draw(offset), draw(offset), draw(length)), (0.0, 0.0, draw(sign)))]
    joints.append(("p0", (draw(offset), draw(offset), draw(offset)), (0.0, draw(sign), 0.0)))
    for k in range(1, n_pitch):
        joints.append((f"p{k}", (draw(length), draw(offset), draw(offset)), (0.0, draw(sign), 0.0)))
    if roll:
        slope = draw(st.floats(-0.5, 0.5, **_FLOAT))
        joints.append(("roll", (draw(length), draw(offset), draw(offset)), (math.cos(slope), 0.0, math.sin(slope))))
    if tilt:
        turned = []
        for name, xyz, axis in joints:
            off = np.array([draw(st.floats(0.5, 1.0, **_FLOAT)) * draw(sign) for _ in range(3)]) * tilt
            a = np.asarray(axis) + off
            turned.append((name, xyz, tuple((a / np.linalg.norm(a)).tolist())))
        joints = turned
    parts = ['<robot name="random_yaw_planar"><link name="base"/>']
    parent = "base"
    for k, (name, xyz, axis) in enumerate(joints):
        lim = draw(limit)
        parts.append(_joint(name, parent, f"l{k}", xyz, axis, -lim, lim))
        parent = f"l{k}"
    tip = (draw(length), draw(offset) if roll else 0.0, draw(offset) if roll else 0.0)
    parts.append(
        f'<link name="tip"/><joint name="tip_fixed" type="fixed"><parent link="{parent}"/><child link="tip"/>'
        f'<origin xyz="{tip[0]!r} {tip[1]!r} {tip[2]!r}"/></joint></robot>'
    )
    return Robot("".join(parts), tip="tip", approach_axis=(1.0, 0.0, 0.0))


@functools.cache
def so101() -> Robot:
    return load_robot("so101")


def configuration(data, robot: Robot) -> np.ndarray:
    return np.array([data.draw(st.floats(float(lo), float(hi), **_FLOAT)) for lo, hi in zip(robot.lower, robot.upper)])


def reference(solver, target: Target, q_current):
    """The vectorised path's answer for one target (a batch of one through the same closed form)."""
    arm = solver.arm
    qc = None if q_current is None else np.asarray(q_current, dtype=float)[None, :]
    pit = None if target.pitch is None else np.array([target.pitch])
    rot = None if target.rotation is None else target.rotation[None]
    arrays = solve_arrays(arm, target.position[None, :], pit, rot, qc)
    return result_from_arrays(arm, arrays, 0, target, None if q_current is None else list(q_current))


def assert_same(got, want):
    assert got.status == want.status, (got, want)
    # Matched by branch: the order (by distance to q_current) may differ where a joint sits on
    # +-pi at a limit of +-pi, which round-off puts on either end.
    assert sorted(s.branch for s in got.solutions) == sorted(s.branch for s in want.solutions), (got, want)
    by_branch = {s.branch: s for s in want.solutions}
    for a in got.solutions:
        b = by_branch[a.branch]
        # Equal modulo 2 pi (an angle on a limit at +-pi may round either way).
        np.testing.assert_allclose(np.abs((a.q - b.q + np.pi) % (2 * np.pi) - np.pi), 0.0, atol=1e-9)
        assert a.within_limits == b.within_limits
        assert a.singular == b.singular
        assert not a.q.flags.writeable


def assert_covers(got, want):
    """The corrected path's answer against the vectorised path's: every branch it found, the same.

    Where the vectorised path starts branches apart next to the yaw axis it may miss a branch
    the corrected path (started at the ideal answer) finds: extra branches are allowed (the
    callers check every answer by Pinocchio's FK).
    """
    if want.ok:
        assert got.ok, (got, want)
    else:
        assert got.status == want.status or got.ok, (got, want)
    by_branch = {s.branch: s for s in got.solutions}
    for b in want.solutions:
        a = by_branch.get(b.branch)
        assert a is not None, (got, want)
        np.testing.assert_allclose(np.abs((a.q - b.q + np.pi) % (2 * np.pi) - np.pi), 0.0, atol=1e-9)
        assert a.within_limits == b.within_limits
        assert a.singular == b.singular
    for a in got.solutions:
        assert not a.q.flags.writeable


def assert_reproduces(robot, target, result):
    for sol in result.solutions:
        pose = robot.fk(sol.q)
        assert np.linalg.norm(pose[:3, 3] - target.position) < TOL_POS, sol
        assert sol.position_error < TOL_POS
        assert sol.within_limits == bool(robot.within_limits(sol.q))
        if target.rotation is not None:
            assert rotation_error(pose[:3, :3], target.rotation) < TOL_ROT, sol
            assert sol.orientation_error < TOL_ROT


def has(result, q) -> bool:
    return any(np.max(np.abs((s.q - q + np.pi) % (2 * np.pi) - np.pi)) < TOL_Q for s in result.solutions)


@property_settings(150)
@given(robot=yaw_planar_arms(), data=st.data())
def test_pose_targets_on_random_arms(robot, data):
    solver = closed_form_solver(robot)
    q = configuration(data, robot)
    pose = robot.fk(q)
    q_current = configuration(data, robot) if data.draw(st.booleans()) else None
    target = Target(pose[:3, 3], rotation=pose[:3, :3])
    result = solver.solve(target, q_current=q_current)
    assert_same(result, reference(solver, target, q_current))
    assert_reproduces(robot, target, result)
    assert result.solutions
    assert has(result, q) or result.singular
    # The same rotation elsewhere: mostly not achievable; the same answer as the reference.
    shift = np.array([data.draw(st.floats(-0.2, 0.2, **_FLOAT)) for _ in range(3)])
    moved = Target(pose[:3, 3] + shift, rotation=pose[:3, :3])
    result = solver.solve(moved, q_current=q_current)
    assert_same(result, reference(solver, moved, q_current))
    assert_reproduces(robot, moved, result)


@functools.cache
def _bundled_solver(name: str):
    """One closed-form solver per bundled arm for this module: its solve kernel (CasADi,
    0.1-0.3 s to build) built once, not once per example."""
    return closed_form_solver(load_robot(name))


@pytest.mark.parametrize("name", ["dh3", "three_joint", "al5c"])
@property_settings(100)
@given(data=st.data())
def test_pose_targets_on_bundled_arms(name, data):
    solver = _bundled_solver(name)
    robot = solver.robot
    q = configuration(data, robot)
    pose = robot.fk(q)
    target = Target(pose[:3, 3], rotation=pose[:3, :3])
    # Never compiled to C: every example takes a fresh solver's first-call path (the VM kernel).
    result = single_after(10**12, lambda: solver.solve(target))
    assert not any(kernel.compiled for kernel in solver._scalar_plan.compiled._built.values() if kernel)
    assert_same(result, reference(solver, target, None))
    assert_reproduces(robot, target, result)
    assert has(result, q) or result.singular


@st.composite
def inexact_arms(draw) -> Robot:
    """A random 3-pitch arm whose axes deviate from the family's by micro-radians (as SO-101's)."""
    return draw(yaw_planar_arms(tilt=draw(st.floats(1e-7, 2e-5, **_FLOAT)), n_pitch=3))


def check_corrected(robot, solver, target, q_current):
    """The corrected scalar path (when it answers) against the vectorised path and Pinocchio FK."""
    fast = solve_corrected_scalar(solver.arm, real_tip_pose(robot), target, list(q_current))
    if fast is None:  # declined: the solver takes the vectorised path (tested elsewhere)
        return None
    assert_covers(fast, reference(solver, target, q_current))
    for sol in fast.solutions:
        pose = robot.fk(sol.q)
        assert np.linalg.norm(pose[:3, 3] - target.position) < TOL_POS, sol
        if target.pitch is not None:
            a = pose[:3, :3] @ robot.approach_axis
            assert pitch_error(a, target.position, target.pitch) < TOL_ROT, sol
    return fast


@settings(parent=property_settings(100), suppress_health_check=list(HealthCheck))
@given(robot=inexact_arms(), data=st.data())
def test_corrected_path_on_random_inexact_arms(robot, data):
    solver = closed_form_solver(robot)
    assert not solver.exact
    q = configuration(data, robot)
    pose = robot.fk(q)
    for target in (Target(pose[:3, 3]), Target(pose[:3, 3], pitch=approach_pitch(robot, q))):
        if target.pitch is not None and not solver.arm.pitch_supported:
            continue
        result = check_corrected(robot, solver, target, q)
        if result is not None:
            assert result.ok
            # q among the answers wherever the vectorised path finds it (at a stretched elbow or a
            # joint limit, both may take the default approach pitch instead of q_current's).
            assert has(result, q) or result.singular or not has(reference(solver, target, q), q)
    target = Target(pose[:3, 3], rotation=pose[:3, :3])
    fast = solve_corrected_pose(solver.arm, pose_frame(solver.arm), real_tip_pose(robot), target, None)
    if fast is not None:
        assert_covers(fast, reference(solver, target, None))
        assert_reproduces(robot, target, fast)


@property_settings(150)
@given(data=st.data())
def test_corrected_path_on_so101(data):
    if example_robot_data_dir() is None:
        pytest.skip("example-robot-data is not installed")
    robot = so101()
    solver = closed_form_solver(robot)
    q = configuration(data, robot)
    q_current = q if data.draw(st.booleans()) else configuration(data, robot)
    pose = robot.fk(q)
    for target in (Target(pose[:3, 3]), Target(pose[:3, 3], pitch=approach_pitch(robot, q))):
        result = check_corrected(robot, solver, target, q_current)
        if result is not None:
            assert result.ok
            assert has(result, q) or q_current is not q
    # Full poses: the corrected pose path.
    target = Target(pose[:3, 3], rotation=pose[:3, :3])
    fast = solve_corrected_pose(solver.arm, pose_frame(solver.arm), real_tip_pose(robot), target, None)
    if fast is not None:
        assert_covers(fast, reference(solver, target, None))
        assert_reproduces(robot, target, fast)
        assert has(fast, q)
    # Through the public solver too.
    result = solver.solve(Target(pose[:3, 3], pitch=approach_pitch(robot, q)), q_current=q)
    assert_reproduces(robot, Target(pose[:3, 3]), result)
    assert has(result, q)


def test_so101_pitch_target_next_to_the_yaw_axis_keeps_every_branch():
    # Regression (bench_analytic, seed 1, target 702): the tip 0.44 mm outside the cylinder the
    # arm's sideways offset leaves around the yaw axis, at a nearly stretched arm. The vectorised
    # path starts the yaws apart there (1.8 mm), which put the front branches' wrist beyond the
    # reach: only the back ones were found, not q. The corrected path starts at the ideal
    # yaws and finds all four.
    if example_robot_data_dir() is None:
        pytest.skip("example-robot-data is not installed")
    robot = so101()
    solver = closed_form_solver(robot)
    q = np.array([1.9179531878237697, 0.2174011516632317, -1.3235712848998065, -1.5122802494870973, 1.4456039673221133])
    target = Target(robot.fk(q)[:3, 3], pitch=approach_pitch(robot, q))
    fast = check_corrected(robot, solver, target, q)
    assert fast is not None and fast.ok
    assert has(fast, q)
    assert len(fast.solutions) == 4
    assert all(s.singular for s in fast.solutions)  # the yaw is ill-conditioned there
    result = solver.solve(target, q_current=q)
    assert_reproduces(robot, target, result)
    assert has(result, q)


def test_pose_next_to_the_yaw_axis_is_left_to_the_vectorised_path():
    # Regression (found by test_corrected_path_on_random_inexact_arms): the roll centre 5.9 mm
    # (in the arm's plane) from the yaw axis, within the distance where the vectorised path
    # starts the yaws apart (11 mm on this arm, whose axes are up to 33 micro-radians off). The
    # corrected pose path took the solution as back/elbow-up, the vectorised path as
    # front/elbow-down: now the solver answers there by the vectorised path, and both name it alike.
    tilt = -1.1706732937714155e-05
    parts = ['<robot name="near_axis"><link name="base"/>']
    joints = [
        ("yaw", "base", "l0", (0.0, 0.0, 0.25), (tilt, tilt, -0.9999999998629523), 1.0),
        ("p0", "l0", "l1", (0.0, 0.0, 0.0), (tilt, -0.9999999998629523, tilt), 1.0),
        (
            "p1",
            "l1",
            "l2",
            (0.203125, 0.0, 0.0),
            (-1.1707007039323937e-05, 0.9999999998629461, -1.1707007039323937e-05),
            2.0,
        ),
        (
            "p2",
            "l2",
            "l3",
            (0.28125, 0.0, 0.0),
            (-1.1707007039323937e-05, 0.9999999998629461, -1.1707007039323937e-05),
            1.0,
        ),
        (
            "roll",
            "l3",
            "l4",
            (0.25, 0.015625, 0.0234375),
            (0.9921989333205955, -1.1707023057375941e-05, 0.12466465650062247),
            1.0,
        ),
    ]
    for name, parent, child, xyz, axis, limit in joints:
        parts.append(_joint(name, parent, child, xyz, axis, -limit, limit))
    parts.append(
        '<link name="tip"/><joint name="tip_fixed" type="fixed"><parent link="l4"/><child link="tip"/>'
        '<origin xyz="0.25 0.0 0.0"/></joint></robot>'
    )
    robot = Robot("".join(parts), tip="tip", approach_axis=(1.0, 0.0, 0.0))
    solver = closed_form_solver(robot)
    q = np.array([0.0, 0.46875, -1.859375, 0.875, 0.0])
    pose = robot.fk(q)
    target = Target(pose[:3, 3], rotation=pose[:3, :3])
    assert solve_corrected_pose(solver.arm, pose_frame(solver.arm), real_tip_pose(robot), target, None) is None
    result = solver.solve(target)
    assert_same(result, reference(solver, target, None))
    assert_reproduces(robot, target, result)
    assert has(result, q)


@pytest.mark.parametrize("kind", ["position", "pitch", "pose"])
def test_so101_batch_agrees_with_single_calls(kind):
    # The batch corrects every branch by the same compiled Newton steps (refine) as the single
    # calls (corrected): each branch the batch finds, a single call finds with the same q (the
    # single call may find more next to the yaw axis, where the batch starts the yaws apart).
    if example_robot_data_dir() is None:
        pytest.skip("example-robot-data is not installed")
    robot = so101()
    solver = closed_form_solver(robot)
    q = robot.random_configurations(np.random.default_rng(12), 150)
    poses = robot.fk(q)
    pos, rot = poses[:, :3, 3], poses[:, :3, :3]
    pitch = np.array([approach_pitch(robot, qi) for qi in q]) if kind == "pitch" else None
    current = None if kind == "pose" else q
    batch = solver.solve_batch(pos, pitch=pitch, rotations=rot if kind == "pose" else None, q_current=current)
    for i in range(len(q)):
        target = Target(
            pos[i], pitch=None if pitch is None else float(pitch[i]), rotation=rot[i] if kind == "pose" else None
        )
        single = solver.solve(target, q_current=None if current is None else current[i])
        assert_reproduces(robot, target, single)
        assert single.ok and batch.status[i] == 0
        by_branch = {s.branch: s for s in single.solutions}
        for slot in np.nonzero(batch.valid[i])[0]:
            s = by_branch[batch.branches[slot]]
            np.testing.assert_allclose(np.abs((s.q - batch.q[i, slot] + np.pi) % (2 * np.pi) - np.pi), 0.0, atol=1e-9)
            assert s.within_limits == batch.within_limits[i, slot]
        assert has(single, q[i])


@pytest.mark.parametrize("elbow", [2.3125, 2.356, 0.0])
def test_a_straight_elbow_has_one_name_on_every_path(elbow):
    """dh3 with its elbow stretched, a full-pose target: the one solution is elbow-up on the
    scalar, compiled and batch paths alike (round-off once put the sign of the elbow angle, and
    so the name, either way: back/elbow-down on one path, back/elbow-up on another)."""
    robot = load_robot("dh3")
    q = np.array([0.0, elbow, 0.0])
    pose = robot.fk(q)
    target = Target(pose[:3, 3], rotation=pose[:3, :3])
    fresh = closed_form_solver(load_robot("dh3"))
    interpreted = single_after(10**12, lambda: fresh.solve(target))
    compiled = closed_form_solver(robot)
    last = single_after(1, lambda: compiled.solve(target))  # the compiled kernel from the first call
    batch = reference(compiled, target, None)
    for result in (interpreted, last, batch):
        assert result.ok and result.singular
        assert all(s.branch.endswith("elbow-up") for s in result.solutions), result
        assert_same(result, batch)
        assert_reproduces(robot, target, result)
