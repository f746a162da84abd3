"""Lines that go straight on from one another pass their junction without stopping (issue 11).

Unless the user asks for a stop there (``stop``, a ``dwell``, ``blend_lines: false``), or the
second line changes direction or the rate of the orientation along the line.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import planner
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
from planner.geometry.target import Target
from planner.motion.line import continues_line, line_deviation
from planner.motion.trajectory import LIMIT_TOLERANCE

from conftest import get_robot

# A joint move, two lines straight down one after the other, a joint move away (al5c, metres).
TARGETS = [
    {"position": [0.15, 0.05, 0.10]},
    {"position": [0.18, 0.0, 0.08]},
    {"position": [0.18, 0.0, 0.05], "line": True},
    {"position": [0.18, 0.0, 0.02], "line": True},
    {"position": [0.12, -0.08, 0.08]},
]


def plan(robot, targets, **top):
    return plan_motion(robot, parse_motion_request({"targets": targets, **top}))


def assert_within_limits(traj):
    for peaks in (traj.peak_ratios(None), traj.peak_ratios(1000.0)):
        assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
        assert peaks["position"] <= 4 * LIMIT_TOLERANCE


def assert_tip_on_lines(robot, p, targets, tol=1e-4):
    """Pinocchio FK of the 1 kHz samples of every line within tol [m] of it."""
    for k in range(1, len(targets)):
        if targets[k].get("line"):
            t = np.arange(p.departure_times[k - 1], p.waypoint_times[k], 1e-3)
            a, b = (np.array(targets[i]["position"]) for i in (k - 1, k))
            assert line_deviation(robot, p.trajectory.sample(t).q, a, b) <= tol


def speed_at(p, k):
    """Largest joint speed over its limit when passing user waypoint k."""
    return float(np.max(np.abs(p.trajectory.sample(np.array([p.waypoint_times[k]])).qd[0]) / p.limits.velocity))


def test_collinear_lines_pass_their_junction_moving_and_the_plan_is_shorter():
    robot = get_robot("al5c")
    through = plan(robot, TARGETS)
    stopped = [dict(t) for t in TARGETS]
    stopped[2]["stop"] = True
    rest = plan(robot, stopped)
    assert speed_at(through, 2) > 0.1
    assert speed_at(rest, 2) <= 1e-9
    assert through.trajectory.duration < rest.trajectory.duration
    traj = through.trajectory
    assert_within_limits(traj)
    assert_tip_on_lines(robot, through, TARGETS)
    np.testing.assert_allclose(traj.sample(through.waypoint_times).q, through.waypoints, atol=1e-12)
    # Velocity and acceleration continuous through the junction.
    t = float(through.waypoint_times[2])
    s = traj.sample(np.array([t - 1e-7, t + 1e-7]))
    np.testing.assert_allclose(s.qd[0], s.qd[1], atol=1e-5)
    np.testing.assert_allclose(s.qdd[0], s.qdd[1], atol=1e-3 * float(np.max(through.limits.acceleration)))
    # The two lines are one smooth motion: no more jerk sign changes than the S-curve between their ends.
    t0, t1 = float(through.departure_times[1]), float(through.waypoint_times[3])
    scurve = planner.plan_trajectory(traj.sample(np.array([t0, t1])).q, through.limits, strategy="stop")
    assert np.all(traj.jerk_sign_changes(t0, t1) <= scurve.jerk_sign_changes())


@pytest.mark.parametrize("change", ["dwell", "blend_lines", "turn"])
def test_a_junction_rests_where_asked_or_where_the_line_turns(change):
    robot = get_robot("al5c")
    targets = [dict(t) for t in TARGETS]
    top = {}
    if change == "dwell":
        targets[2]["dwell"] = 0.1
    elif change == "blend_lines":
        top["blend_lines"] = False
    else:
        targets[3]["position"] = [0.19, 0.0, 0.02]
    p = plan(robot, targets, **top)
    assert speed_at(p, 2) <= 1e-9
    assert_within_limits(p.trajectory)
    assert_tip_on_lines(robot, p, targets)


def test_continues_line_needs_the_same_direction_and_orientation_rate():
    a, b, c = (np.array(x) for x in ([0.1, 0.0, 0.1], [0.2, 0.0, 0.1], [0.4, 0.0, 0.1]))
    assert continues_line(Target(a), Target(b), Target(c))
    assert not continues_line(Target(a), Target(b), Target(a))  # back the same way
    assert not continues_line(Target(a), Target(b), Target(c + [0, 0.01, 0]))
    assert not continues_line(Target(a), Target(a), Target(c))  # no length
    # Pitch: 0.1 rad over the first 0.1 m, then 0.2 rad over 0.2 m: the same rate.
    assert continues_line(Target(a, pitch=0.0), Target(b, pitch=0.1), Target(c, pitch=0.3))
    assert not continues_line(Target(a, pitch=0.0), Target(b, pitch=0.1), Target(c, pitch=0.1))
    assert not continues_line(Target(a, pitch=0.0), Target(b), Target(c))

    def rz(angle):
        cs, sn = math.cos(angle), math.sin(angle)
        return np.array([[cs, -sn, 0.0], [sn, cs, 0.0], [0.0, 0.0, 1.0]])

    assert continues_line(Target(a, rotation=rz(0.0)), Target(b, rotation=rz(0.1)), Target(c, rotation=rz(0.3)))
    assert not continues_line(Target(a, rotation=rz(0.0)), Target(b, rotation=rz(0.1)), Target(c, rotation=rz(0.1)))


@pytest.mark.parametrize("name", ["al5c", "three_joint"])
@settings(max_examples=4, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), split=st.floats(0.2, 0.8))
def test_random_collinear_lines_keep_every_limit_and_the_line(name, seed, split):
    robot = get_robot(name)
    rng = np.random.default_rng(seed)
    for _ in range(20):
        q = robot.random_configurations(rng, 2)
        a, c = robot.position(q)
        b = a + split * (c - a)
        targets = [{"position": a.tolist()}, {"position": b.tolist(), "line": True}]
        targets.append({"position": c.tolist(), "line": True})
        stopped = [dict(t) for t in targets]
        stopped[1]["stop"] = True
        try:
            rest = plan(robot, stopped)
        except planner.PlannerError:
            continue
        p = plan(robot, targets)
        assert_within_limits(p.trajectory)
        assert_tip_on_lines(robot, p, targets)
        np.testing.assert_allclose(p.trajectory.sample(p.waypoint_times).q, p.waypoints, atol=1e-12)
        assert p.trajectory.duration <= rest.trajectory.duration * (1 + 1e-9)
        return
