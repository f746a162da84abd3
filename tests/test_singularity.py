"""Singularity checks along trajectories and detours around avoidable ones."""

from __future__ import annotations

import numpy as np
import pytest

from planner import InvalidArgumentError
from planner.motion.detours import SingularityOptions, plan_clear_of_singularities
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory
from planner.motion.request import TrajectoryRequest
from planner.motion.singularity import check_singularities
from planner.motion.trajectory import LIMIT_TOLERANCE

from conftest import get_robot

THRESHOLD = 1.0 / 30.0


def test_conditioning_matches_the_robot():
    rng = np.random.default_rng(3)
    for name in ("dh3", "al5c", "three_joint", "shelley"):
        robot = get_robot(name)
        q = robot.random_configurations(rng, 20)
        inv, man = robot.conditioning(q)
        np.testing.assert_allclose(inv, robot.inverse_condition_number(q), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(man, robot.manipulability(q), rtol=1e-12, atol=1e-15)


def test_segment_through_a_singularity_gets_a_detour():
    # three_joint's planar part (shoulder, elbow, wrist) is stretched when elbow = wrist = 0:
    # a straight joint move from (+0.5, +0.5) to (-0.5, -0.5) passes right through it, while
    # both ends are well conditioned. The arm is redundant for positions, so a detour exists.
    robot = get_robot("three_joint")
    limits = JointLimits.from_robot(robot)
    q = np.array([[0.0, 1.0, 0.5, 0.5], [0.0, 1.0, -0.5, -0.5]])
    direct = check_singularities(robot, plan_trajectory(q, limits))
    assert direct.singular_waypoints == ()
    assert direct.min_inverse_condition < 1e-3
    assert direct.below_threshold

    plan = plan_clear_of_singularities(robot, TrajectoryRequest(q, limits))
    assert len(plan.detours) >= 1
    assert all(d.segment == 0 and d.inverse_condition >= THRESHOLD for d in plan.detours)
    assert plan.report.clear and plan.report.min_inverse_condition >= THRESHOLD
    assert plan.unresolved == ()
    traj = plan.trajectory
    np.testing.assert_allclose(traj.sample(plan.waypoint_times).q, q, atol=1e-12)
    assert len(traj.waypoints) == 2 + len(plan.detours)
    peaks = traj.peak_ratios(1000.0)
    assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
    assert peaks["position"] <= LIMIT_TOLERANCE


def test_singular_waypoint_is_kept_and_flagged():
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    q = np.array([[0.0, 0.0, 0.0], [0.5, 0.6, 1.2], [1.0, 0.5, 1.0]])  # the first is fully stretched
    plan = plan_clear_of_singularities(robot, TrajectoryRequest(q, limits))
    assert plan.singular_waypoints == (0,)
    assert plan.report.singular_waypoints == (0,)
    assert plan.report.waypoint_inverse_condition[0] == pytest.approx(0.0, abs=1e-12)
    assert plan.detours == ()
    assert plan.report.min_inverse_condition == pytest.approx(0.0, abs=1e-12)
    assert plan.report.time_of_minimum == 0.0
    np.testing.assert_allclose(plan.trajectory.sample(plan.waypoint_times).q, q, atol=1e-12)


def test_crossing_between_sign_changed_ends_is_reported_not_detoured():
    # dh3 is not redundant: elbow-up and elbow-down lie on either side of the stretched
    # configurations (det J changes sign), so every path between them crosses a singularity.
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    q = np.array([[0.0, 0.3, 0.6], [0.0, 0.6, -0.6]])
    inv_ends = robot.conditioning(q)[0]
    assert np.all(inv_ends > THRESHOLD)
    plan = plan_clear_of_singularities(robot, TrajectoryRequest(q, limits))
    assert plan.detours == ()
    assert plan.unresolved == (0,)
    assert plan.report.min_inverse_condition < THRESHOLD


def test_report_intervals_and_rate():
    robot = get_robot("three_joint")
    limits = JointLimits.from_robot(robot)
    traj = plan_trajectory([[0.0, 1.0, 0.5, 0.5], [0.0, 1.0, -0.5, -0.5]], limits)
    report = check_singularities(robot, traj, rate=200.0)
    assert len(report.below_threshold) == 1
    start, end = report.below_threshold[0]
    assert 0 < start < report.time_of_minimum < end < traj.duration
    assert report.rate == 200.0 and report.task == "position"


@pytest.mark.parametrize("threshold", [-0.1, 1.0, float("nan")])
def test_bad_threshold(threshold):
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    traj = plan_trajectory([[0, 0.5, 1], [0.5, 0.5, 1]], limits)
    with pytest.raises(InvalidArgumentError, match=r"threshold is an inverse condition number in \[0, 1\)"):
        check_singularities(robot, traj, threshold=threshold)


def test_mismatched_robot():
    limits = JointLimits.from_robot(get_robot("dh3"))
    traj = plan_trajectory([[0, 0.5, 1], [0.5, 0.5, 1]], limits)
    with pytest.raises(InvalidArgumentError, match="the trajectory has 3 joints; three_joint has 4"):
        check_singularities(get_robot("three_joint"), traj)
    with pytest.raises(InvalidArgumentError, match="the limits are for 3 joints; three_joint has 4"):
        plan_clear_of_singularities(get_robot("three_joint"), TrajectoryRequest([[0, 0.5, 1], [0.5, 0.5, 1]], limits))


def test_options_and_kept_segments():
    with pytest.raises(InvalidArgumentError, match="max_detours must be a non-negative integer, got -1"):
        SingularityOptions(max_detours=-1)
    with pytest.raises(InvalidArgumentError, match="margin must be >= 1, got 0.5"):
        SingularityOptions(margin=0.5)
    with pytest.raises(InvalidArgumentError, match=r"threshold is an inverse condition number in \[0, 1\)"):
        SingularityOptions(threshold=1.5)
    assert SingularityOptions().threshold == pytest.approx(THRESHOLD)
    robot = get_robot("three_joint")
    request = TrajectoryRequest([[0.0, 1.0, 0.5, 0.5], [0.0, 1.0, -0.5, -0.5]], JointLimits.from_robot(robot))
    # A kept segment (say, samples of a Cartesian line) gets no detour and is reported.
    kept = plan_clear_of_singularities(robot, request, keep_segments=[0])
    assert kept.detours == () and kept.unresolved == (0,)
    none = plan_clear_of_singularities(robot, request, SingularityOptions(max_detours=0))
    assert none.detours == () and none.trajectory.duration == kept.trajectory.duration


@pytest.mark.parametrize("count", [8, pytest.param(100, marks=pytest.mark.slow)])
def test_no_plan_is_slower_than_resting_at_every_waypoint_for_detours_that_clear_nothing(count):
    from planner.motion.detours import SingularityOptions, plan_clear_of_singularities
    from planner.motion.limits import JointLimits
    from planner.motion.plan import plan_trajectory
    from planner.motion.request import TrajectoryRequest

    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(11)
    for _ in range(count):
        q = robot.random_configurations(rng, 5)
        q[:, 2] = np.abs(q[:, 2]) * np.array([1, -1, 1, -1, 1])  # every segment crosses the stretched elbow
        plan = plan_clear_of_singularities(robot, TrajectoryRequest(q, limits), SingularityOptions())
        rest = plan_trajectory(q, limits, strategy="stop")
        assert not {d.segment for d in plan.detours} & set(plan.unresolved)
        if plan.trajectory.duration > rest.duration * (1 + 1e-9):
            assert plan.detours and not plan.unresolved
