"""Cartesian targets: IK branch choice, and straight-line segments timed within the joint limits."""

from __future__ import annotations

import numpy as np
import pytest

from planner import InvalidArgumentError, Target, rotation_error
from planner.cartesian import TargetSolver, line_deviation, line_waypoints, time_line
from planner.trajectory import LIMIT_TOLERANCE, JointLimits
from planner.waypoints import parse_motion_request, plan_motion

from conftest import get_robot, needs_example_robot_data


def assert_within_limits(traj):
    peaks = traj.peak_ratios(1000.0)
    assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
    assert peaks["position"] <= LIMIT_TOLERANCE


def test_branch_nearest_the_previous_configuration():
    robot = get_robot("dh3")
    solver = TargetSolver(robot)
    target = Target([0.14, 0.0, -0.04])
    up = solver.choose(target, np.radians([0, 10, 50]))
    down = solver.choose(target, np.radians([0, -60, -50]))
    assert up.branch == "front/elbow-up" and down.branch == "front/elbow-down"
    for choice in (up, down):
        np.testing.assert_allclose(robot.position(choice.q), target.position, atol=1e-12)
        assert not choice.singular and choice.alternatives >= 1


def test_singular_solution_only_when_nothing_clear_exists():
    robot = get_robot("dh3")
    choice = TargetSolver(robot).choose(Target([0.17, 0.0, 0.03]), None)
    assert choice.singular and choice.inverse_condition == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(InvalidArgumentError, match="has no IK solution within the joint limits of dh3"):
        TargetSolver(robot).choose(Target([0.3, 0.0, 0.03]), None)


def test_line_segment_stays_on_the_line_within_limits():
    robot = get_robot("dh3")
    request = parse_motion_request(
        {"units": {"length": "cm"}, "targets": [{"position": [11, 0, 9]}, {"position": [0, 11, 9], "line": True}]}
    )
    plan = plan_motion(robot, request)
    assert plan.branches[1] == "line"
    assert plan.line_deviation[0] < 2e-4  # [m]
    traj = plan.trajectory
    assert_within_limits(traj)
    np.testing.assert_allclose(robot.position(plan.waypoints), [[0.11, 0, 0.09], [0, 0.11, 0.09]], atol=1e-9)
    # Every sample of the motion lies near the straight line.
    q = traj.sampled(500.0).q
    assert line_deviation(robot, q, np.array([0.11, 0, 0.09]), np.array([0, 0.11, 0.09])) < 2e-4


def test_line_slows_down_approaching_a_singularity():
    # The line ends where the arm is fully stretched: the elbow must turn ever faster per metre,
    # so the tip slows down instead of the joints exceeding their speed.
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    solver = TargetSolver(robot)
    start, end = Target([0.14, 0.0, -0.04]), Target([0.17, 0.0, 0.03])
    path = line_waypoints(solver, start, end, solver.choose(start, None).q)
    assert path.min_inverse_condition == pytest.approx(0.0, abs=1e-9)
    timing = time_line(path, limits)
    assert np.all(np.abs(timing.velocity) <= limits.velocity + 1e-12)
    # Tip speed along the line from the sample times: slow over the last millimetre.
    ds = np.linalg.norm(np.diff(path.points, axis=0), axis=1)
    speed = ds / np.maximum(np.diff(timing.t), 1e-15)
    s_mid = (path.s[:-1] + path.s[1:]) / 2
    near_end = speed[s_mid > 1 - 0.001 / np.linalg.norm(end.position - start.position)]
    assert near_end.max() < 0.3 * speed.max()
    request = parse_motion_request(
        {"targets": [{"position": [0.14, 0, -0.04]}, {"position": [0.17, 0, 0.03], "line": True}]}
    )
    plan = plan_motion(robot, request)
    assert_within_limits(plan.trajectory)
    assert plan.singular_waypoints == (1,)
    assert plan.line_deviation[0] < 2e-4


def test_line_leaving_the_workspace_is_an_error():
    robot = get_robot("dh3")
    request = parse_motion_request(
        {
            "targets": [
                {"position": [0.16, 0.0, 0.03]},
                {"position": [0.0, 0.16, 0.03]},
                {"position": [0.0, 0.15, 0.08], "line": True},
            ]
        }
    )
    plan_motion(robot, request)  # reachable along the line
    bad = parse_motion_request(
        {"targets": [{"position": [0.0, -0.16, 0.03]}, {"position": [0.0, 0.16, 0.03], "line": True}]}
    )
    with pytest.raises(InvalidArgumentError, match="straight line from .* leaves what dh3 can reach"):
        plan_motion(robot, bad)


def test_pitch_targets_on_al5c():
    robot = get_robot("al5c")
    request = parse_motion_request(
        {
            "units": {"angle": "deg"},
            "targets": [
                {"position": [0.2, 0.0, 0.1], "pitch": -90},
                {"position": [0.2, 0.1, 0.1], "pitch": -90, "line": True},
                {"position": [0.15, -0.1, 0.15], "pitch": 0},
            ],
        }
    )
    plan = plan_motion(robot, request)
    assert_within_limits(plan.trajectory)
    np.testing.assert_allclose(
        robot.position(plan.waypoints), [[0.2, 0, 0.1], [0.2, 0.1, 0.1], [0.15, -0.1, 0.15]], atol=1e-9
    )
    assert plan.branches[1] == "line" and plan.branches[0] is not None
    assert plan.line_deviation[0] < 2e-4


@needs_example_robot_data
def test_pose_targets_through_the_nlp_on_ur5():
    robot = get_robot("ur5")
    q = np.array([[0.1, -1.0, 1.2, -0.5, 0.3, 0.2], [0.5, -1.2, 1.0, -0.3, 0.6, 0.1], [0.9, -0.8, 1.4, -0.9, 0.2, 0.5]])
    poses = robot.fk(q)
    targets = [{"position": p[:3, 3].tolist(), "quaternion": _quaternion(p[:3, :3])} for p in poses]
    targets[2]["line"] = True
    plan = plan_motion(robot, parse_motion_request({"targets": targets, "start": {"q": q[0].tolist()}}))
    assert plan.branches == ("nlp", "nlp", "line")
    reached = robot.fk(plan.waypoints)
    np.testing.assert_allclose(reached[:, :3, 3], poses[:, :3, 3], atol=1e-6)
    assert np.all(rotation_error(reached[:, :3, :3], poses[:, :3, :3]) < 1e-6)
    assert_within_limits(plan.trajectory)
    assert plan.line_deviation[1] < 1e-3


def _quaternion(rot: np.ndarray) -> list[float]:
    """(x, y, z, w) of a rotation matrix (w > 0 branch is enough for these poses)."""
    w = np.sqrt(max(1.0 + np.trace(rot), 1e-12)) / 2.0
    return [(rot[2, 1] - rot[1, 2]) / (4 * w), (rot[0, 2] - rot[2, 0]) / (4 * w), (rot[1, 0] - rot[0, 1]) / (4 * w), w]
