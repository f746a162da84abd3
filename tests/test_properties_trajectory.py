"""Property tests of `planner.plan_trajectory` through the public API, with generated inputs.

Random waypoints within the joint ranges of the bundled arms and of arms built from random DH
tables, random per-joint velocity, acceleration and jerk limits (or the URDF's, or a servo
rating), every via strategy, random stops and dwells. The input is valid, so planning must
succeed (its documented errors are all about bad input), and then:

- the trajectory is at every waypoint at its time (atol 1e-7), starting at rest at time 0
  and ending at rest at its duration, at rest at every stop;
- positions stay within the joint ranges; velocities, accelerations and jerks stay within
  their limits, both by the trajectory's own sampled derivatives and by finite differences
  of densely sampled positions (see `trajectory_checks`).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from dh_arms import arm, arm_specs, bundled_robot, configurations, property_settings
from hypothesis import given, note
from hypothesis import strategies as st
from trajectory_checks import assert_passes_waypoints, assert_within_limits

import planner

_FLOAT = {"allow_nan": False, "allow_infinity": False, "allow_subnormal": False}


@st.composite
def joint_limits(draw, robot: planner.Robot) -> planner.JointLimits:
    """Motion limits for the robot's joints: the URDF's speeds, a servo rating, or random ones."""
    source = draw(st.sampled_from(["urdf", "servo", "random"]))
    if source == "urdf":
        return planner.JointLimits.from_robot(robot)
    if source == "servo":
        return planner.JointLimits.from_robot(robot, servo_seconds_per_60deg=draw(st.floats(0.05, 1.0, **_FLOAT)))
    velocity = [draw(st.floats(0.05, 10.0, **_FLOAT)) for _ in range(robot.dof)]
    acceleration = [v * draw(st.floats(0.1, 50.0, **_FLOAT)) for v in velocity]
    jerk = [a * draw(st.floats(0.5, 200.0, **_FLOAT)) for a in acceleration]
    return planner.JointLimits.from_robot(robot, velocity=velocity, acceleration=acceleration, jerk=jerk)


@st.composite
def waypoint_lists(draw, robot: planner.Robot) -> np.ndarray:
    """2-11 configurations within the joint ranges: random ones, repeats (a zero-length
    segment), tiny steps (down to rounding level) from the previous one or onto a range end, and
    steps onto range ends.
    """
    lower, upper = np.asarray(robot.lower), np.asarray(robot.upper)
    rows = [draw(configurations(robot))]
    for _ in range(draw(st.integers(1, 5))):
        kind = draw(st.sampled_from(["random", "random", "repeat", "tiny", "to_end"]))
        previous = rows[-1]
        if kind == "random":
            rows.append(draw(configurations(robot)))
        elif kind == "repeat":
            rows.append(previous.copy())
        elif kind == "tiny":  # from the previous one, or from just inside a range end onto it
            scale = 10.0 ** draw(st.integers(-13, -3))
            step = np.array([draw(st.floats(-1.0, 1.0, **_FLOAT)) for _ in range(robot.dof)]) * scale
            if draw(st.booleans()):
                rows.append(np.clip(previous + step, lower, upper))
            else:
                ends = np.where(step > 0, lower, upper)
                rows += [np.clip(ends + step, lower, upper), ends]
        else:
            ends = np.where([draw(st.booleans()) for _ in range(robot.dof)], lower, upper)
            moved = np.array([draw(st.booleans()) for _ in range(robot.dof)])
            rows.append(np.where(moved, ends, previous))
    return np.array(rows)


@st.composite
def problems(draw):
    spec = draw(arm_specs())
    robot = arm(spec)
    limits = draw(joint_limits(robot))
    waypoints = draw(waypoint_lists(robot))
    n = len(waypoints)
    options = {"strategy": draw(st.sampled_from(["optimized", "heuristic", "stop"]))}
    if draw(st.booleans()):
        options["stops"] = sorted(draw(st.sets(st.integers(0, n - 1))))
    dwell = draw(st.sampled_from(["none", "one", "each"]))
    if dwell == "one":
        options["dwell"] = draw(st.floats(0.0, 0.5, **_FLOAT))
    elif dwell == "each":
        options["dwell"] = [draw(st.one_of(st.just(0.0), st.floats(0.0, 0.5, **_FLOAT))) for _ in range(n)]
    return spec, limits, waypoints, options


def check_trajectory(spec: str | dict, limits: planner.JointLimits, waypoints: np.ndarray, options: dict) -> None:
    robot = arm(spec)
    note(f"robot {robot.name}: lower {robot.lower.tolist()}, upper {robot.upper.tolist()}")
    note(f"velocity {limits.velocity.tolist()}, acceleration {limits.acceleration.tolist()}")
    note(f"jerk {limits.jerk.tolist()}")
    note(f"waypoints = {waypoints.tolist()}, options = {options}")
    traj = planner.plan_trajectory(waypoints, limits, **options)
    note(f"{traj!r}")
    assert isinstance(traj, planner.JointTrajectory)
    n = len(waypoints)
    times = np.asarray(traj.waypoint_times)
    assert times.shape == (n,) and times[0] == 0.0
    dwell = np.broadcast_to(np.asarray(options.get("dwell", 0.0), dtype=float), (n,))
    assert times[-1] + dwell[-1] == pytest.approx(traj.duration, rel=1e-12, abs=1e-12)
    assert_passes_waypoints(traj, times, waypoints)

    rest = 1e-9 * np.asarray(limits.velocity)
    stops = range(n) if options["strategy"] == "stop" else options.get("stops", ())
    for k in sorted({0, n - 1, *stops, *np.flatnonzero(dwell > 0)}):
        # At rest on arrival and through the dwell.
        span = np.linspace(times[k], min(times[k] + dwell[k], traj.duration), 5)
        state = traj.sample(span)
        assert np.all(np.abs(state.qd) <= rest), f"moving at stop {k}: {state.qd.tolist()}"
        np.testing.assert_allclose(state.q, np.broadcast_to(waypoints[k], state.q.shape), rtol=0, atol=1e-7)
    end = traj.sample(traj.duration)
    np.testing.assert_allclose(end.q, waypoints[-1], rtol=0, atol=1e-7)

    assert_within_limits(traj, limits.velocity, limits.acceleration, limits.jerk, robot.lower, robot.upper)


def _trajectory_test(examples: int):
    @property_settings(examples)
    @given(problem=problems())
    def test(problem):
        check_trajectory(*problem)

    return test


test_plan_trajectory_on_arm_limits = _trajectory_test(100)
test_plan_trajectory_on_arm_limits_many = pytest.mark.slow(_trajectory_test(600))


def test_finite_differences_see_a_jump():
    # The checker itself: a trajectory whose samples jump must fail the finite-difference view.
    robot = bundled_robot("dh3")
    limits = planner.JointLimits.from_robot(robot)
    traj = planner.plan_trajectory([[0.0, 0.0, 0.0], [0.5, 0.5, 0.5]], limits)

    class Jumping:
        duration, knots = traj.duration, traj.knots

        @staticmethod
        def sample(t):
            s = traj.sample(t)
            q = np.where(np.asarray(t)[..., None] > traj.duration / 2, s.q + 1e-2, s.q)
            return type(s)(s.t, q, s.qd, s.qdd, s.qddd)

    assert_within_limits(traj, limits.velocity, limits.acceleration, limits.jerk, robot.lower, robot.upper)
    with pytest.raises(AssertionError, match="finite-difference order 1"):
        assert_within_limits(Jumping, limits.velocity, limits.acceleration, limits.jerk, robot.lower, robot.upper)
    assert math.isfinite(traj.duration)
