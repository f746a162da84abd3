"""Position lines on yaw-planar arms: the free approach pitch chosen to keep joints off their range ends.

Tracking a position line keeps the free end angle near the previous sample's and can drive a
joint into a range end, where the joint path turns a corner and the arm stops (issue 11).
:func:`planner.motion.line.line_waypoints` then tries the line with the approach pitch going
linearly along it; where it takes that, the joint path has no range-end corner, the tip stays on
the line (Pinocchio FK) and every limit holds.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from line_cases import random_position_line

import planner
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
from planner.geometry.target import approach_pitch
from planner.motion.line import on_range_end
from planner.motion.trajectory import LIMIT_TOLERANCE

from conftest import get_robot


def pinocchio_tips(robot: planner.Robot, q: np.ndarray) -> np.ndarray:
    """Tip positions of configurations q (M, dof) by Pinocchio's FK directly [m]."""
    data = robot.model.createData()
    out = []
    for row in q:
        pin.framesForwardKinematics(robot.model, data, row)
        out.append(data.oMf[robot.tip_frame_id].translation.copy())
    return np.array(out)


def distance_to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = b - a
    s = np.clip((p - a) @ d / float(d @ d), 0.0, 1.0)
    return np.linalg.norm(p - (a + s[:, None] * d), axis=1)


def pitch_line_taken(robot: planner.Robot, s: np.ndarray, q: np.ndarray) -> bool:
    """Whether the approach pitch along the samples changes linearly with s (the free pitch chosen)."""
    pitch = np.unwrap(np.asarray(approach_pitch(robot, q)))
    linear = pitch[0] + s * (pitch[-1] - pitch[0])
    return bool(np.max(np.abs(pitch - linear)) <= 1e-6) and len(q) > 2


def check_pitch_line(robot: planner.Robot, data: dict, path) -> None:
    a, b = (np.array(x["position"]) for x in data["targets"])
    ends = on_range_end(robot, np.asarray(path.q))
    # A joint may leave a range end at the start or arrive at one at the end, not in between.
    assert not np.any(ends[1:-1]), "a range-end corner on the chosen pitch line"
    assert np.all(path.q >= np.asarray(robot.lower) - 1e-12) and np.all(path.q <= np.asarray(robot.upper) + 1e-12)
    assert np.max(distance_to_segment(pinocchio_tips(robot, np.asarray(path.q)), a, b)) <= 1e-6
    plan = plan_motion(robot, parse_motion_request(data))
    traj = plan.trajectory
    for peaks in (traj.peak_ratios(None), traj.peak_ratios(1000.0)):
        assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
        assert peaks["position"] <= 4 * LIMIT_TOLERANCE
    t0, t1 = float(plan.departure_times[0]), float(plan.waypoint_times[1])
    q = traj.sample(np.arange(t0, t1, 1e-3)).q
    assert np.max(distance_to_segment(pinocchio_tips(robot, q), a, b)) <= 1e-4  # [m], at 1 kHz
    # The plan follows this path: no rest inside the line (no corner to stop at).
    np.testing.assert_allclose(plan.waypoints[-1], path.q[-1], atol=1e-9)
    inside = traj.waypoint_times[(traj.waypoint_times > t0 + 1e-9) & (traj.waypoint_times < t1 - 1e-9)]
    speed = np.abs(traj.sample(inside).qd) / plan.limits.velocity
    assert not np.any(np.all(speed <= 1e-9, axis=1))


@pytest.mark.parametrize("name", ["al5c", "three_joint"])
@settings(max_examples=5, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1))
def test_random_position_lines_with_the_pitch_chosen_have_no_range_end_corner(name, seed):
    robot = get_robot(name)
    found = random_position_line(robot, np.random.default_rng(seed))
    if found is None:
        return
    data, path = found
    a, b = (np.array(x["position"]) for x in data["targets"])
    # Whichever way the line is sampled, the tip is on it and the limits hold.
    assert np.max(distance_to_segment(pinocchio_tips(robot, np.asarray(path.q)), a, b)) <= 1e-6
    assert np.all(path.q >= np.asarray(robot.lower) - 1e-12) and np.all(path.q <= np.asarray(robot.upper) + 1e-12)
    if pitch_line_taken(robot, np.asarray(path.s), np.asarray(path.q)):
        check_pitch_line(robot, data, path)


def test_the_benchmark_seed_has_lines_that_take_the_pitch_line():
    # Among the first al5c lines of benchmarks/bench_lines.py's seed, tracking drives a joint
    # into a range end on some; the pitch line keeps them off it.
    rng = np.random.default_rng(5)
    robot = get_robot("al5c")
    taken = 0
    for _ in range(8):
        found = random_position_line(robot, rng)
        assert found is not None
        data, path = found
        if pitch_line_taken(robot, np.asarray(path.s), np.asarray(path.q)):
            check_pitch_line(robot, data, path)
            taken += 1
    assert taken >= 1


def test_a_pitch_line_ends_off_a_range_end_so_it_blends_into_the_next_move():
    # Joint move, line, joint move on al5c (a plan of benchmarks/bench_lines.py's blending
    # table, rng seed 11): the pitch line nearest the tracked end's pitch ends with the shoulder
    # arriving at its range end, so the move after it cannot keep the line's end velocity; the
    # next pitch tried ends off it, and the line blends into both moves.
    tips = [
        [0.17873889948215654, -0.1382685860975172, 0.2481221063594746],
        [0.3437322710349819, 0.01986719621959437, 0.11204936010822522],
        [0.029182707365703536, 0.004538697133893144, -0.14255980751043315],
        [0.06335952948677974, 0.02908045570922897, 0.40937798347549886],
    ]
    robot = get_robot("al5c")
    targets = [{"position": p} for p in tips]
    targets[2]["line"] = True
    plans = {b: plan_motion(robot, parse_motion_request({"targets": targets, "blend_lines": b})) for b in (False, True)}
    plan = plans[True]
    traj = plan.trajectory
    t0, t1 = float(plan.departure_times[1]), float(plan.waypoint_times[2])
    q = traj.sample(np.arange(t0, t1, 1e-3)).q
    assert np.max(distance_to_segment(pinocchio_tips(robot, q), np.array(tips[1]), np.array(tips[2]))) <= 1e-4
    times = np.asarray(traj.waypoint_times)
    line_q = np.asarray(traj.waypoints)[(times >= t0 - 1e-9) & (times <= t1 + 1e-9)]
    np.testing.assert_allclose(line_q[-1], plan.waypoints[2], atol=1e-9)
    assert not np.any(on_range_end(robot, line_q[-1:]) & ~on_range_end(robot, line_q[-2:-1]))
    ends = np.abs(traj.sample(np.array([t0, t1])).qd) / plan.limits.velocity
    assert np.all(ends.max(axis=1) > 1e-6), "a line end not passed moving"
    assert traj.duration < plans[False].trajectory.duration
    for peaks in (traj.peak_ratios(None), traj.peak_ratios(1000.0)):
        assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
        assert peaks["position"] <= 4 * LIMIT_TOLERANCE
