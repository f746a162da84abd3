"""Lines blend into the joint moves before and after them unless the user asks for a stop (issue 11)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import planner
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
from planner.motion.line import line_deviation
from planner.motion.trajectory import LIMIT_TOLERANCE

from conftest import get_robot

# A joint move, a line down, a joint move away (al5c, metres).
TARGETS = [
    {"position": [0.15, 0.05, 0.10]},
    {"position": [0.18, 0.0, 0.06]},
    {"position": [0.18, 0.0, 0.01], "line": True},
    {"position": [0.12, -0.08, 0.08]},
]


def plan(robot, targets, **top):
    return plan_motion(robot, parse_motion_request({"targets": targets, **top}))


def assert_within_limits(traj):
    for peaks in (traj.peak_ratios(None), traj.peak_ratios(1000.0)):
        assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
        assert peaks["position"] <= 4 * LIMIT_TOLERANCE


def line_ends(p, k):
    """Velocity and acceleration just before, at and after the line's start and end (into waypoint k)."""
    t0, t1 = float(p.departure_times[k - 1]), float(p.waypoint_times[k])
    out = []
    for t in (t0, t1):
        s = p.trajectory.sample(np.array([t - 1e-7, t, t + 1e-7]))
        out.append((s.qd, s.qdd))
    return out


def assert_tip_on_line(robot, p, k, targets, tol=1e-4):
    t = np.arange(p.departure_times[k - 1], p.waypoint_times[k], 1e-3)
    a, b = (np.array(targets[i]["position"]) for i in (k - 1, k))
    assert line_deviation(robot, p.trajectory.sample(t).q, a, b) <= tol


def test_a_line_blends_into_the_moves_around_it_and_the_plan_is_shorter():
    robot = get_robot("al5c")
    rest = plan(robot, TARGETS, blend_lines=False)
    blended = plan(robot, TARGETS)
    assert blended.trajectory.duration < rest.trajectory.duration
    assert_within_limits(blended.trajectory)
    assert_tip_on_line(robot, blended, 2, TARGETS)
    assert blended.line_deviation[1] <= 1e-5
    direction = np.subtract(TARGETS[2]["position"], TARGETS[1]["position"])
    direction /= np.linalg.norm(direction)
    for (qd, qdd), q in zip(line_ends(blended, 2), blended.waypoints[1:3]):
        # Moving at both ends, continuously (velocity and acceleration), along the line.
        assert np.max(np.abs(qd[1]) / blended.limits.velocity) > 0.1
        np.testing.assert_allclose(qd[0], qd[2], atol=1e-5)
        np.testing.assert_allclose(qdd[0], qdd[2], atol=1e-3 * float(np.max(blended.limits.acceleration)))
        tip = robot.jacobian(q)[:3] @ qd[1]
        assert float(tip @ direction) > 0
        # Along the line within the end tangent's fit to the samples.
        np.testing.assert_allclose(tip, (tip @ direction) * direction, atol=1e-3 * np.linalg.norm(tip))
    for qd, _ in line_ends(rest, 2):
        np.testing.assert_allclose(qd[1], 0.0, atol=1e-12)


def test_stop_and_dwell_keep_a_line_end_at_rest():
    robot = get_robot("al5c")
    targets = [dict(t) for t in TARGETS]
    targets[1]["stop"] = True
    targets[2]["dwell"] = 0.2
    p = plan(robot, targets)
    (start, _), (end, _) = line_ends(p, 2)
    np.testing.assert_allclose(start[1], 0.0, atol=1e-12)
    np.testing.assert_allclose(end[1], 0.0, atol=1e-12)
    assert_within_limits(p.trajectory)
    targets[2].pop("dwell")
    p = plan(robot, targets)
    (start, _), _ = line_ends(p, 2)
    np.testing.assert_allclose(start[1], 0.0, atol=1e-12)
    # The end alone may blend; here that saves nothing, so the plan rests there too.
    assert p.trajectory.duration <= plan(robot, targets, blend_lines=False).trajectory.duration
    assert_within_limits(p.trajectory)


def test_two_lines_meeting_stop_where_they_meet():
    robot = get_robot("al5c")
    targets = [*TARGETS[:3], {"position": [0.18, 0.05, 0.01], "line": True}, TARGETS[3]]
    p = plan(robot, targets)
    (start, _), (corner, _) = line_ends(p, 2)
    assert np.max(np.abs(start[1])) > 0
    np.testing.assert_allclose(corner[1], 0.0, atol=1e-12)
    assert np.max(np.abs(line_ends(p, 3)[1][0][1])) > 0
    assert_within_limits(p.trajectory)
    for k in (2, 3):
        assert_tip_on_line(robot, p, k, targets)
    assert p.trajectory.duration < plan(robot, targets, blend_lines=False).trajectory.duration


def test_blend_lines_must_be_a_boolean():
    with pytest.raises(planner.PlannerError, match="blend_lines must be true or false, got 'yes'"):
        parse_motion_request({"targets": TARGETS, "blend_lines": "yes"})


@pytest.mark.parametrize("name", ["al5c", "three_joint"])
@settings(max_examples=5, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1))
def test_random_blended_lines_keep_every_limit_and_the_line(name, seed):
    robot = get_robot(name)
    rng = np.random.default_rng(seed)
    for _ in range(20):
        targets = [{"position": robot.position(q).tolist()} for q in robot.random_configurations(rng, 4)]
        targets[2]["line"] = True
        try:
            rest = plan(robot, targets, blend_lines=False)
        except planner.PlannerError:
            continue
        blended = plan(robot, targets)
        assert_within_limits(blended.trajectory)
        assert_tip_on_line(robot, blended, 2, targets)
        np.testing.assert_allclose(blended.trajectory.sample(blended.waypoint_times).q, blended.waypoints, atol=1e-12)
        assert blended.trajectory.duration <= rest.trajectory.duration  # else the plan rests at the line's ends
        return


def test_the_spline_meets_given_end_velocities_and_accelerations():
    from planner.motion.line_smoothing import rest_to_rest_spline

    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.01, 0.05, 12))
    q = rng.normal(size=(12, 2))
    v0, v1, a0, a1 = rng.normal(size=(4, 2))
    knots, p, v, a, j = rest_to_rest_spline(t, q, v0, v1, a0, a1)
    h = np.diff(np.append(knots, t[-1]))[:, None]
    end_p = p + v * h + a * h**2 / 2 + j * h**3 / 6
    end_v = v + a * h + j * h**2 / 2
    end_a = a + j * h
    np.testing.assert_allclose(end_p[:-1], p[1:], atol=1e-9)
    np.testing.assert_allclose(end_v[:-1], v[1:], atol=1e-8)
    np.testing.assert_allclose(end_a[:-1], a[1:], atol=1e-6)
    np.testing.assert_allclose([v[0], a[0], end_v[-1], end_a[-1]], [v0, a0, v1, a1], atol=1e-8)
    np.testing.assert_allclose(p[np.isin(knots, t)], q[:-1], atol=1e-9)
    np.testing.assert_allclose(end_p[-1], q[-1], atol=1e-9)


def test_last_waypoint_time_within_the_duration_after_a_line():
    """A line that ends the plan (here a point to itself after a pose) is spliced in: its last
    waypoint time and the duration agree, not one rounding apart (found by fuzzing plan files)."""
    pose = {
        "position": [23.4153511805605, -4.8600859643141e-15, -5.156881337873559],
        "stop": True,
        "rpy": [179.99999999999997, -32.70422048691766, 8.16884270217236e-15],
    }
    line = {"position": pose["position"], "stop": True, "line": True}
    data = {"units": {"length": "cm", "angle": "deg"}, "targets": [pose, line], "singularity": {"detours": False}}
    result = plan_motion(get_robot("al5c"), parse_motion_request(data))
    times = np.asarray(result.waypoint_times)
    assert times[-1] <= result.trajectory.duration
    assert np.all(np.asarray(result.trajectory.waypoint_times) <= result.trajectory.duration)
    np.testing.assert_allclose(result.trajectory.sample(times).q, result.waypoints, rtol=0.0, atol=1e-7)


def test_waypoint_times_never_go_back_after_a_spliced_line():
    """What follows a spliced line starts from its new end time, so a zero-length move after it
    is not one rounding earlier (two zero-length lines after a pose; found by the CI's fuzz)."""
    at = [9.389303155443883, 28.257762035328508, 28.510529926675186]
    data = {
        "units": {"length": "cm", "angle": "deg"},
        "targets": [
            {"position": at, "stop": True, "rpy": [0.0, -18.380275608647096, -108.38027560864711]},
            {"position": at, "stop": True, "line": True},
            {"position": at, "stop": True, "line": True},
            {"position": [36.62361517720418, 5.084119199237515e-16, 19.020683733119327], "stop": True},
        ],
        "singularity": {"detours": False},
    }
    result = plan_motion(get_robot("al5c"), parse_motion_request(data))
    assert np.all(np.diff(result.waypoint_times) >= 0.0)
    assert np.all(np.diff(result.trajectory.waypoint_times) >= 0.0)
    assert np.all(np.diff(result.trajectory.knots) >= 0.0)
    np.testing.assert_allclose(result.trajectory.sample(result.waypoint_times).q, result.waypoints, rtol=0.0, atol=1e-7)


def dipping_user_segments(robot, p):
    """Requested segments dipping below the threshold between two trajectory waypoints above it,
    measured again on the returned trajectory."""
    from planner.motion.singularity import measure_singularities

    thr = p.singularity.threshold
    report, t, _, inv = measure_singularities(robot, p.trajectory, thr, robot.resolve_task(None), p.singularity.rate)
    w_t, w_inv = p.trajectory.waypoint_times, report.waypoint_inverse_condition
    dips = set()
    for j in range(len(w_t) - 1):
        if w_inv[j] < thr or w_inv[j + 1] < thr:
            continue
        inside = (t >= w_t[j]) & (t <= w_t[j + 1])
        if inside.any() and inv[inside].min() < thr:
            dips.add(int(np.searchsorted(p.waypoint_times, w_t[j], side="right") - 1))
    return dips


@pytest.mark.parametrize(("name", "seed"), [("dh3", 1), ("al5c", 2)])
def test_unresolved_segments_are_those_of_the_smoothed_motion(name, seed):
    # A smoothed line changes the motion: its unresolved segments are found on what is returned.
    robot = get_robot(name)
    rng = np.random.default_rng(seed)
    targets = [
        # dh3: the joint move before the line dipped only before smoothing (reported unresolved).
        [
            [-0.00014242, -0.12668564, 0.03276036],
            [0.00122092, 0.01254747, 0.18803164],
            [-0.00477667, -0.1676918, 0.01507928],
        ]
    ]
    targets += [
        [robot.position(q).tolist() for q in rng.uniform(robot.lower, robot.upper, (3, robot.dof))] for _ in range(12)
    ]
    planned = 0
    for points in targets:
        try:
            p = plan(robot, [{"position": points[0]}, {"position": points[1], "line": True}, {"position": points[2]}])
        except planner.PlannerError:
            continue
        planned += 1
        if not p.detours:
            assert set(p.unresolved) == dipping_user_segments(robot, p)
    assert planned >= 4
