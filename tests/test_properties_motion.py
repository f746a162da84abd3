"""Property tests of `planner.plan_motion(robot, planner.parse_motion_request(data))` with generated plans.

Plan data as a user writes it (planner/app/motion_plan.py documents the format): joint
waypoints, or Cartesian targets reachable by construction (FK of random q within the limits:
positions, approach pitches, rpy, quaternions; some joined by straight lines), in random units,
with random limits, strategies, dwells and stops, on the bundled arms and on arms from random DH
tables. Only `PlannerError` may escape (a line may leave the workspace, a plan may be refused
with a reason); joint waypoints in radians, which need no conversion, must always plan. On
success:

- every requested waypoint is planned where asked: joint waypoints as given (converted to SI),
  targets reached by Pinocchio FK within the IK tolerances (1e-6 m, 1e-6 rad);
- the trajectory is at each waypoint at its reported time, and at rest through each dwell;
- the limits planned with are the requested ones in SI (or the documented defaults), and the
  trajectory honours them and the joint ranges (see `trajectory_checks`).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from dh_arms import (
    ANGLE_SCALE,
    LENGTH_SCALE,
    arm,
    arm_specs,
    configurations,
    property_settings,
    tip_errors,
    uncompiled_nlp,
)
from hypothesis import event, given, note
from hypothesis import strategies as st
from trajectory_checks import assert_passes_waypoints, assert_within_limits

import planner

_FLOAT = {"allow_nan": False, "allow_infinity": False, "allow_subnormal": False}
# The IK tolerances plan_motion's waypoints are solved to [m], [rad], plus recomputation rounding.
POSITION_TOLERANCE = 1e-6 + 1e-12
ORIENTATION_TOLERANCE = 1e-6 + 1e-12


@st.composite
def limit_entries(draw, dof: int, angle: float) -> dict:
    """The plan's `limits` mapping, in the file's angle unit, and the SI limits it asks for."""
    limits, si = {}, {}
    speed = draw(st.sampled_from(["urdf", "velocity", "velocities", "servo"]))
    if speed == "velocity":
        v = draw(st.floats(0.1, 8.0, **_FLOAT))
        limits["velocity"], si["velocity"] = v / angle, np.full(dof, v)
    elif speed == "velocities":
        v = [draw(st.floats(0.1, 8.0, **_FLOAT)) for _ in range(dof)]
        limits["velocity"], si["velocity"] = [x / angle for x in v], np.array(v)
    elif speed == "servo":
        s = draw(st.floats(0.05, 1.0, **_FLOAT))
        limits["servo_seconds_per_60deg"], si["velocity"] = s, np.full(dof, (math.pi / 3) / s)
    if draw(st.booleans()):
        a = draw(st.floats(0.2, 40.0, **_FLOAT))
        limits["acceleration"], si["acceleration"] = a / angle, np.full(dof, a)
    if draw(st.booleans()):
        j = [draw(st.floats(1.0, 400.0, **_FLOAT)) for _ in range(dof)]
        limits["jerk"], si["jerk"] = [x / angle for x in j], np.array(j)
    return limits, si


@st.composite
def plans(draw):
    """(arm spec, plan data, expected): the data as a user writes it; expected holds SI values."""
    spec = draw(arm_specs())
    robot = arm(spec)
    length_unit = draw(st.sampled_from(sorted(LENGTH_SCALE)))
    angle_unit = draw(st.sampled_from(sorted(ANGLE_SCALE)))
    length, angle = LENGTH_SCALE[length_unit], ANGLE_SCALE[angle_unit]
    n = draw(st.integers(2, 5))
    qs = [draw(configurations(robot)) for _ in range(n)]
    mode = draw(st.sampled_from(["waypoints", "targets"]))
    items, goals, dwell = [], [], []
    for k, q in enumerate(qs):
        extras = {}
        if draw(st.integers(0, 2)) == 0:
            extras["dwell"] = draw(st.floats(0.0, 0.3, **_FLOAT))
        if draw(st.integers(0, 3)) == 0:
            extras["stop"] = True
        dwell.append(extras.get("dwell", 0.0))
        if mode == "waypoints":
            q_file = [float(x) / angle for x in q]
            items.append({"q": q_file, **extras} if extras or draw(st.booleans()) else q_file)
            goals.append(np.array(q_file) * angle)
            continue
        pose = robot.fk(q)
        item = {"position": [float(x) / length for x in pose[:3, 3]], **extras}
        kind = draw(st.sampled_from(["position", "pitch", "rpy", "quaternion"]))
        if kind == "pitch":
            pitch = float(planner.approach_pitch(robot, q))
            item["pitch"] = pitch / angle
            goals.append(planner.Target(pose[:3, 3], pitch=pitch))
        elif kind == "rpy":
            item["rpy"] = [float(x) / angle for x in pin.rpy.matrixToRpy(pose[:3, :3])]
            goals.append(planner.Target(pose[:3, 3], rotation=pose[:3, :3]))
        elif kind == "quaternion":
            item["quaternion"] = [float(x) for x in pin.Quaternion(pose[:3, :3]).coeffs()]  # x, y, z, w
            goals.append(planner.Target(pose[:3, 3], rotation=pose[:3, :3]))
        else:
            goals.append(planner.Target(pose[:3, 3]))
        if k > 0 and draw(st.integers(0, 3)) == 0:
            item["line"] = True
        items.append(item)
    limits, si = draw(limit_entries(robot.dof, angle))
    data = {"units": {"length": length_unit, "angle": angle_unit}, mode: items}
    if limits:
        data["limits"] = limits
    if draw(st.booleans()):
        data["strategy"] = draw(st.sampled_from(["optimized", "heuristic", "stop"]))
    if draw(st.integers(0, 3)) == 0:
        data["singularity"] = {"detours": draw(st.booleans())}
    return spec, data, {"goals": goals, "dwell": np.array(dwell), "limits": si, "mode": mode}


def expected_limits(robot: planner.Robot, si: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The SI limits a plan asks for, with the documented defaults (URDF speed, 2 x, 10 x)."""
    velocity = si.get("velocity", np.asarray(robot.velocity_limit, dtype=float))
    acceleration = si.get("acceleration", 2.0 * velocity)
    jerk = si.get("jerk", 10.0 * acceleration)
    return velocity, acceleration, jerk


def check_plan(spec: str | dict, data: dict, expected: dict) -> None:
    robot = arm(spec)
    note(f"robot {robot.name}: lower {robot.lower.tolist()}, upper {robot.upper.tolist()}")
    note(f"plan data = {data!r}")
    must_plan = expected["mode"] == "waypoints" and data["units"]["angle"] == "rad"
    try:
        request = planner.parse_motion_request(data, source="generated")
        plan = planner.plan_motion(robot, request)
    except planner.PlannerError as exc:
        event(f"refused: {type(exc).__name__}")
        note(f"refused: {exc!r}")
        if must_plan:
            raise  # joint waypoints within the limits, no unit conversion: nothing to refuse
        return
    event("planned")
    n = len(expected["goals"])
    q = np.asarray(plan.waypoints)
    assert q.shape == (n, robot.dof)
    assert np.all(q >= robot.lower) and np.all(q <= robot.upper), f"waypoints outside the joint limits: {q.tolist()}"
    if expected["mode"] == "waypoints":
        np.testing.assert_allclose(q, np.array(expected["goals"]), rtol=0, atol=1e-12)
    else:
        for k, goal in enumerate(expected["goals"]):
            position_error, orientation_error, elevation_error = tip_errors(robot, goal, q[k])
            assert position_error <= POSITION_TOLERANCE, f"target {k} missed by {position_error:.3g} m"
            assert orientation_error <= ORIENTATION_TOLERANCE, f"target {k} missed by {orientation_error:.3g} rad"
            assert elevation_error <= ORIENTATION_TOLERANCE, f"target {k} pitch missed by {elevation_error:.3g} rad"

    traj = plan.trajectory
    times = np.asarray(plan.waypoint_times)
    assert times.shape == (n,) and times[0] == 0.0
    assert_passes_waypoints(traj, times, q)
    rest = 1e-9 * np.asarray(plan.limits.velocity)
    for k in np.flatnonzero(expected["dwell"] > 0):
        span = np.linspace(times[k], times[k] + expected["dwell"][k], 5)
        state = traj.sample(span)
        np.testing.assert_allclose(state.q, np.broadcast_to(q[k], state.q.shape), rtol=0, atol=1e-7)
        assert np.all(np.abs(state.qd) <= rest), f"moving during the dwell at waypoint {k}"

    velocity, acceleration, jerk = expected_limits(robot, expected["limits"])
    np.testing.assert_allclose(plan.limits.velocity, velocity, rtol=1e-12)
    np.testing.assert_allclose(plan.limits.acceleration, acceleration, rtol=1e-12)
    np.testing.assert_allclose(plan.limits.jerk, jerk, rtol=1e-12)
    assert_within_limits(traj, velocity, acceleration, jerk, robot.lower, robot.upper)


def _motion_test(examples: int):
    @property_settings(examples)
    @given(case=plans())
    def test(case):
        if isinstance(case[0], str):
            check_plan(*case)
        else:
            with uncompiled_nlp():  # a generated arm: see dh_arms.uncompiled_nlp
                check_plan(*case)

    return test


test_plan_motion_from_generated_plans = _motion_test(40)
test_plan_motion_from_generated_plans_many = pytest.mark.slow(_motion_test(400))
