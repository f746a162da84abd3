"""Property tests: random q within limits -> Pinocchio FK -> closed-form IK -> every solution
reproduces the target (1e-9 m, 1e-9 rad) and one of them is q (modulo 2 pi)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from planner import AnalyticIK, Robot, Target, load_robot, rotation_error
from planner.geometry.target import approach_direction, approach_pitch, pitch_error
from planner.ik.analytic import closed_form_solver
from planner.model.catalog import BUNDLED_ROBOTS, example_robot_data_dir

TOL_POS = 1e-9
TOL_ROT = 1e-9
TOL_Q = 1e-6

SETTINGS = settings(
    max_examples=100, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def offset_arm() -> Robot:
    """Yaw + 3 pitch (last one flipped) + roll, with in-plane and sideways offsets and a tip off
    the roll axis: the exact family's general case (SO-101-like, but without round-off)."""

    def joint(name, parent, child, xyz, axis):
        return (
            f'<link name="{child}"/><joint name="{name}" type="revolute"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz}" rpy="0 0 0"/><axis xyz="{axis}"/>'
            '<limit lower="-2.8" upper="2.8" effort="1" velocity="1"/></joint>'
        )

    urdf = (
        '<robot name="offset_arm"><link name="base"/>'
        + joint("yaw", "base", "l0", "0.01 -0.02 0.05", "0 0 1")
        + joint("shoulder", "l0", "l1", "0.02 0.03 0.06", "0 1 0")
        + joint("elbow", "l1", "l2", "0.15 -0.01 0.02", "0 1 0")
        + joint("wrist", "l2", "l3", "0.12 0.015 -0.01", "0 -1 0")
        + joint("roll", "l3", "l4", "0.03 0 0.005", "1 0 0")
        + '<link name="tip"/><joint name="tip_fixed" type="fixed"><parent link="l4"/><child link="tip"/>'
        '<origin xyz="0.06 0.004 -0.012"/></joint></robot>'
    )
    return Robot(urdf, tip="tip", approach_axis=(1.0, 0.0, 0.0))


ARMS = list(BUNDLED_ROBOTS) + ["offset_arm", "so101"]
_CACHE: dict[str, tuple[Robot, AnalyticIK]] = {}


def arm(name: str) -> tuple[Robot, AnalyticIK]:
    if name == "so101" and example_robot_data_dir() is None:
        pytest.skip("example-robot-data is not installed")
    if name not in _CACHE:
        robot = offset_arm() if name == "offset_arm" else load_robot(name)
        _CACHE[name] = (robot, closed_form_solver(robot))
    return _CACHE[name]


def configuration(data, robot: Robot) -> np.ndarray:
    return np.array(
        [
            data.draw(st.floats(float(lo), float(hi)), label=name)
            for name, lo, hi in zip(robot.joint_names, robot.lower, robot.upper)
        ]
    )


def same_configuration(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(np.max(np.abs((a - b + np.pi) % (2 * np.pi) - np.pi)) < TOL_Q)


def check(robot, solver, target, q, q_current=None, pitch=False):
    res = solver.solve(target, q_current=q_current)
    assert res.solutions, f"{robot.name}: no solution for FK({q.tolist()}): {res.status} {res.reason}"
    for sol in res.solutions:
        pose = robot.fk(sol.q)
        assert np.all(np.isfinite(sol.q))
        assert np.linalg.norm(pose[:3, 3] - target.position) < TOL_POS, sol
        assert sol.position_error < TOL_POS
        assert sol.within_limits == bool(robot.within_limits(sol.q))
        if target.rotation is not None:
            assert rotation_error(pose[:3, :3], target.rotation) < TOL_ROT, sol
        if pitch:
            # planner.geometry.target's convention: the elevation, the horizontal part pointing outward.
            a = pose[:3, :3] @ robot.approach_axis
            assert abs(a[2] - math.sin(target.pitch)) < TOL_ROT, sol
            assert math.cos(target.pitch) * (a[:2] @ target.position[:2]) >= -TOL_ROT, sol
            error = pitch_error(a, target.position, target.pitch)
            assert error < TOL_ROT, sol
            assert sol.orientation_error == pytest.approx(error, abs=TOL_ROT)
    if not any(same_configuration(s.q, q) for s in res.solutions):
        # Only a free joint (the yaw on the base axis) may differ: with q_current it is q's.
        assert res.singular, f"{robot.name}: q = {q.tolist()} not among {[s.q.tolist() for s in res.solutions]}"
        again = solver.solve(target, q_current=q)
        assert any(same_configuration(s.q, q) for s in again.solutions)
    assert any(s.within_limits for s in res.solutions) or q_current is None
    return res


@pytest.mark.parametrize("name", ARMS)
@SETTINGS
@given(data=st.data())
def test_pose_targets(name, data):
    robot, solver = arm(name)
    q = configuration(data, robot)
    check(robot, solver, Target.from_pose(robot.fk(q)), q)


@pytest.mark.parametrize("name", [n for n in ARMS if n != "shelley"])
@SETTINGS
@given(data=st.data())
def test_pitch_targets(name, data):
    robot, solver = arm(name)
    q = configuration(data, robot)
    pose = robot.fk(q)
    target = Target(pose[:3, 3], pitch=approach_pitch(robot, q))
    if solver.describe()["lateral_offset"] == pytest.approx(0.0, abs=1e-12):
        # Arms whose plane contains the base axis: exactly the planner.geometry.target convention.
        if np.hypot(*pose[:2, 3]) > 1e-6:
            want = pose[:3, :3] @ robot.approach_axis
            np.testing.assert_allclose(approach_direction(pose[:3, 3], target.pitch), want, atol=1e-9)
    # A free wrist roll takes q_current's value: give it q's.
    q_current = q if solver.has_roll else None
    check(robot, solver, target, q, q_current=q_current, pitch=True)


@pytest.mark.parametrize("name", ARMS)
@SETTINGS
@given(data=st.data())
def test_position_targets(name, data):
    robot, solver = arm(name)
    q = configuration(data, robot)
    target = Target(robot.fk(q)[:3, 3])
    redundant = getattr(solver, "n_pitch", 2) == 3
    # Redundant arms take q_current's approach pitch (and roll): with q's, q is among the answers.
    check(robot, solver, target, q, q_current=q if redundant else None)


@pytest.mark.parametrize("name", ["three_joint", "al5c", "offset_arm", "so101"])
@SETTINGS
@given(data=st.data())
def test_redundant_targets_within_limits_from_any_current_configuration(name, data):
    # FK(q) is reachable within the limits, so whatever approach pitch (and, where the wrist roll
    # moves the tip, roll) q_current has, the closed form finds a solution within them.
    robot, solver = arm(name)
    q = configuration(data, robot)
    q_current = configuration(data, robot)
    pose = robot.fk(q)
    targets = [Target(pose[:3, 3])]
    if solver.has_roll and not solver.describe()["tip_on_roll_axis"]:
        targets.append(Target(pose[:3, 3], pitch=approach_pitch(robot, q)))
    for target in targets:
        res = solver.solve(target, q_current=q_current)
        assert res.ok, f"{robot.name}: FK({q.tolist()}) from {q_current.tolist()}: {res.status} {res.reason}"
        for sol in res.solutions:
            got = robot.fk(sol.q)
            assert np.linalg.norm(got[:3, 3] - target.position) < TOL_POS, sol
            assert sol.within_limits == bool(robot.within_limits(sol.q))
            if target.pitch is not None:
                a = got[:3, :3] @ robot.approach_axis
                assert pitch_error(a, target.position, target.pitch) < TOL_ROT, sol


@pytest.mark.parametrize("name", ARMS)
def test_batch_reproduces_fk_targets(name):
    robot, solver = arm(name)
    q = robot.random_configurations(np.random.default_rng(21), 300)
    poses = robot.fk(q)
    batch = solver.solve_batch(poses[:, :3, 3], rotations=poses[:, :3, :3])
    assert np.all(batch.valid.any(axis=1))
    rows, cols = np.nonzero(batch.valid)
    got = robot.fk(batch.q[rows, cols])
    assert np.max(np.linalg.norm(got[:, :3, 3] - poses[rows, :3, 3], axis=1)) < TOL_POS
    assert np.max(rotation_error(got[:, :3, :3], poses[rows, :3, :3])) < TOL_ROT
    dq = np.abs((batch.q - q[:, None, :] + np.pi) % (2 * np.pi) - np.pi).max(axis=2)
    assert np.all(np.nanmin(dq, axis=1) < TOL_Q)
