"""Joint trajectories through waypoints: limits, exact passage, continuous motion, range repair."""

from __future__ import annotations

import copy
import csv
import math
import pickle
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from ruckig import InputParameter, Ruckig
from ruckig import Trajectory as RuckigTrajectory

from planner import InvalidArgumentError, InvalidConfigurationError, InvalidLimitsError, JointLimitError
from planner.motion.checks import check_waypoints, waypoint_rows_within
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory, plan_trajectory_request
from planner.motion.request import TrajectoryRequest
from planner.motion.segments import rest_to_rest_segments, rest_to_rest_trajectory
from planner.motion.trajectory import LIMIT_TOLERANCE
from planner.motion.vias import VIA_STRATEGIES, HeuristicStrategy, OptimizedStrategy, StopStrategy, ViaStrategy
from planner.motion.vias.optimized import golden_minimum, golden_points, spline_via_states

from conftest import get_robot, needs_example_robot_data

# Sampled peaks may exceed a limit by this relative amount (floating-point rounding only).
TOL = LIMIT_TOLERANCE

SETTINGS = settings(max_examples=100, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


def assert_within_limits(traj, rate=1000.0):
    lim = traj.limits
    for peaks in (traj.peak_ratios(rate), traj.peak_ratios(None)):
        assert peaks["velocity"] <= 1 + TOL
        assert peaks["acceleration"] <= 1 + TOL
        assert peaks["jerk"] <= 1 + TOL
    s = traj.sampled(rate)
    slack = TOL * np.maximum(1.0, np.abs(np.nan_to_num(lim.upper)))
    assert np.all(s.q <= lim.upper + slack)
    assert np.all(s.q >= lim.lower - slack)


def assert_passes_waypoints(traj, q):
    s = traj.sample(traj.waypoint_times)
    np.testing.assert_allclose(s.q, q, rtol=0, atol=1e-12)


@st.composite
def problems(draw, max_dof=6, max_points=6):
    dof = draw(st.integers(1, max_dof))
    n = draw(st.integers(2, max_points))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    lower = rng.uniform(-3.0, 0.0, dof)
    upper = lower + rng.uniform(0.1, 4.0, dof)
    v = rng.uniform(0.2, 6.0, dof)
    a = v * rng.uniform(0.5, 10.0, dof)
    j = a * rng.uniform(2.0, 40.0, dof)
    limits = JointLimits(v, a, j, lower, upper)
    style = draw(st.sampled_from(["uniform", "ends", "monotone"]))
    if style == "uniform":
        q = rng.uniform(lower, upper, (n, dof))
    elif style == "ends":  # many waypoints on or next to a range end
        q = lower + (upper - lower) * rng.choice([0.0, 0.01, 0.5, 0.99, 1.0], (n, dof))
    else:  # running monotonically into the upper end
        q = np.sort(rng.uniform(lower, upper, (n, dof)), axis=0)
        q[-1] = upper
    return q, limits


@SETTINGS
@given(problems())
def test_limits_never_exceeded_and_waypoints_exact(problem):
    q, limits = problem
    traj = plan_trajectory(q, limits)
    assert_within_limits(traj)
    assert_passes_waypoints(traj, q)
    assert traj.waypoint_times[0] == 0.0 and traj.waypoint_times[-1] == pytest.approx(traj.duration)
    assert np.all(np.diff(traj.waypoint_times) >= 0)
    end = traj.sample(traj.duration)
    np.testing.assert_array_equal(end.qd, 0.0)


@SETTINGS
@given(problems(max_points=5))
def test_faster_than_stopping_when_a_via_lies_between_its_neighbours(problem):
    q, limits = problem
    between = any(np.any((q[i] - q[i - 1]) * (q[i + 1] - q[i]) > 0) for i in range(1, len(q) - 1))
    optimized = plan_trajectory(q, limits)
    stop = plan_trajectory(q, limits, strategy="stop")
    assert_within_limits(stop)
    np.testing.assert_array_equal(stop.via_velocities, 0.0)
    if between:
        assert optimized.duration < stop.duration
    else:
        assert optimized.duration <= stop.duration * (1 + 1e-12)


def test_continuous_motion_through_vias_on_dh3():
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    q = np.array([[-1.0, -0.5, 0.2], [-0.5, 0.0, 0.6], [0.0, 0.5, 1.0], [0.5, 1.0, 1.4]])
    traj = plan_trajectory(q, limits)
    stop = plan_trajectory(q, limits, strategy="stop")
    assert traj.duration < 0.8 * stop.duration
    assert np.all(np.abs(traj.via_velocities[1:-1]) > 0)  # it does not stop at the vias
    assert_within_limits(traj)


@pytest.mark.parametrize("segments", [2, 3, 6])
def test_spline_via_states_are_those_of_the_c2_cubic_spline(segments):
    # The cubic through each segment from its end positions and velocities (Hermite) must have
    # the same acceleration on both sides of every inner knot: that is the C2 spline.
    rng = np.random.default_rng(segments)
    q = rng.uniform(-1, 1, (segments + 1, 3))
    h = rng.uniform(0.2, 2.0, segments)
    v_start, v_end = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)
    v, acc = spline_via_states(q, h, v_start, v_end)
    vel = np.vstack([v_start, v, v_end])
    dq, hh = np.diff(q, axis=0), h[:, None]
    acc_start = 6 * dq / hh**2 - (4 * vel[:-1] + 2 * vel[1:]) / hh
    acc_end = -6 * dq / hh**2 + (2 * vel[:-1] + 4 * vel[1:]) / hh
    np.testing.assert_allclose(acc_end[:-1], acc_start[1:], atol=1e-9)
    np.testing.assert_allclose(acc, acc_start[1:], atol=1e-9)


@given(
    st.floats(-5.0, 5.0),
    st.floats(1e-3, 10.0),
    st.integers(2, 6),
    st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6),
)
def test_golden_points_hold_every_point_the_golden_section_evaluates(lo, width, evals, values):
    # The line search makes the candidate states of these points in one batch: the search
    # itself must not ask for any other (bit for bit), whichever way its comparisons go.
    seen = []

    def f(x):
        seen.append(x)
        return values[len(seen) - 1]

    golden_minimum(f, lo, lo + width, evals)
    assert set(seen) <= golden_points(lo, lo + width, evals)


def test_spline_via_states_scale_with_the_durations():
    # The spline search evaluates every time scale s from one spline: via velocities scale by
    # 1/s and accelerations by 1/s^2, the parts due to the end velocities by 1 and 1/s.
    rng = np.random.default_rng(7)
    q = rng.uniform(-1, 1, (5, 3))
    h = rng.uniform(0.2, 2.0, 4)
    v_start, v_end = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)
    v_q, acc_q = spline_via_states(q, h, 0 * v_start, 0 * v_end)
    v_1, acc_1 = spline_via_states(q, h, v_start, v_end)
    for s in (0.5, 0.9, 1.3):
        v, acc = spline_via_states(q, s * h, v_start, v_end)
        np.testing.assert_allclose(v, v_q / s + (v_1 - v_q), atol=1e-12)
        np.testing.assert_allclose(acc, acc_q / s**2 + (acc_1 - acc_q) / s, atol=1e-12)


def test_position_overshoot_is_detected_and_repaired():
    # A fast run up to a waypoint just below the upper end: the via speed of the slope blend
    # alone would carry the joint past the end before it could stop.
    limits = JointLimits([2.0], [4.0], [40.0], [-3.0], [1.0])
    q = np.array([[-3.0], [0.95], [0.999], [-2.0]])
    for strategy in ("heuristic", "optimized"):
        traj = plan_trajectory(q, limits, strategy=strategy)
        assert traj.sampled(1000.0).q.max() <= 1.0 + TOL
        assert traj.peak_ratios(None)["position"] <= TOL
        assert traj.via_velocities[1, 0] > 0  # the joint still passes the first via moving
        assert_passes_waypoints(traj, q)
        if strategy == "heuristic":
            assert traj.repaired[1:3].any()  # the blended via state was lowered


def test_ruckig_extrema_miss_a_constant_acceleration_turn_and_ours_do_not():
    # Community Ruckig's position_extrema only looks for turning points in phases with non-zero
    # jerk; this segment turns round inside a constant-acceleration phase.
    inp = InputParameter(1)
    inp.current_position, inp.current_velocity = [1.0367966341996353], [3.2466170303544835]
    inp.target_position, inp.target_velocity = [1.1100512913641813], [0.2757926180550544]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [5.235987755982988], [10.47197551196598], [104.7197551196598]
    inp.minimum_duration = 0.9353783171878454
    traj = RuckigTrajectory(1)
    Ruckig(1).calculate(inp, traj)
    sampled = max(traj.at_time(t)[0][0] for t in np.linspace(0, traj.duration, 4001))
    assert traj.position_extrema[0].max < sampled - 0.05  # Ruckig's figure is too low
    limits = JointLimits([5.235987755982988], [10.47197551196598], [104.7197551196598], [-2.0], [1.614])
    q = np.array([[0.0], [1.0367966341996353], [1.1100512913641813], [0.0]])
    ours = plan_trajectory(q, limits, strategy="heuristic")
    assert ours.sampled(1000.0).q.max() <= 1.614 + TOL


def test_pieces_match_ruckig_at_time():
    limits = JointLimits([1.0, 2.0], [3.0, 2.0], [30.0, 10.0], [-5, -5], [5, 5])
    q = np.array([[0.0, 0.0], [1.0, -0.5]])
    traj = plan_trajectory(q, limits, start_velocity=[0.5, -0.3], start_acceleration=[1.0, 0.0])
    inp = InputParameter(2)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0, 0], [0.5, -0.3], [1.0, 0.0]
    inp.target_position = [1.0, -0.5]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [1, 2], [3, 2], [30, 10]
    ref = RuckigTrajectory(2)
    Ruckig(2).calculate(inp, ref)
    assert traj.duration == pytest.approx(ref.duration, abs=1e-12)
    for t in np.linspace(0, ref.duration, 57):
        p, v, a = ref.at_time(t)
        s = traj.sample(t)
        np.testing.assert_allclose(s.q, p, atol=1e-10)
        np.testing.assert_allclose(s.qd, v, atol=1e-9)
        np.testing.assert_allclose(s.qdd, a, atol=1e-8)


def test_start_state_is_honoured():
    limits = JointLimits([1.0, 1.0], [2.0, 2.0], [20.0, 20.0], [-2, -2], [2, 2])
    q = np.array([[0.0, 0.0], [1.0, 0.5], [0.0, 1.0]])
    traj = plan_trajectory(q, limits, start_velocity=[0.8, -0.2], start_acceleration=[0.5, 0.0])
    s = traj.sample(0.0)
    np.testing.assert_allclose(s.qd, [0.8, -0.2])
    np.testing.assert_allclose(s.qdd, [0.5, 0.0])
    assert_within_limits(traj)
    assert_passes_waypoints(traj, q)


def test_start_state_braking_first_when_a_stretched_profile_would_leave_the_range():
    # Joint 1 is fast towards its upper end; joint 0 has far to go, so a synchronised first
    # segment would stretch joint 1's profile and carry it out of range. It brakes first.
    limits = JointLimits([1.0, 2.0], [2.0, 4.0], [20.0, 40.0], [-3.0, -1.0], [3.0, 1.0])
    q = np.array([[-3.0, 0.5], [3.0, 0.6], [0.0, 0.0]])
    traj = plan_trajectory(q, limits, start_velocity=[0.0, 1.5])
    assert_within_limits(traj)
    assert_passes_waypoints(traj, q)


def test_start_state_that_cannot_stop_in_range_is_an_error():
    limits = JointLimits([2.0], [1.0], [10.0], [-1.0], [1.0])
    with pytest.raises(InvalidArgumentError, match=r"start state carries joint 'joint0' to .* outside its range"):
        plan_trajectory([[0.99], [0.0]], limits, start_velocity=[1.9])


def test_dwell_holds_the_waypoint():
    limits = JointLimits([1.0], [2.0], [20.0], [-2], [2])
    traj = plan_trajectory([[0.0], [1.0], [0.0]], limits, dwell=[0.0, 0.4, 0.0])
    t1 = traj.waypoint_times[1]
    s = traj.sample(np.linspace(t1, t1 + 0.4, 9))
    np.testing.assert_array_equal(s.q, 1.0)
    np.testing.assert_array_equal(s.qd, 0.0)


def test_duplicate_waypoints_stop_there():
    limits = JointLimits([1.0, 1.0], [2.0, 2.0], [20.0, 20.0], [-2, -2], [2, 2])
    q = [[0, 0], [1, 1], [1, 1], [0, 1]]
    traj = plan_trajectory(q, limits)
    assert traj.waypoint_times[1] == traj.waypoint_times[2]
    np.testing.assert_array_equal(traj.via_velocities[1:3], 0.0)
    assert_within_limits(traj)


def test_sample_shapes_and_csv(tmp_path):
    limits = JointLimits([1.0, 1.0], [2.0, 2.0], [20.0, 20.0], [-2, -2], [2, 2], ("a", "b"))
    traj = plan_trajectory([[0, 0], [1, 0.5], [0.5, 1]], limits)
    s = traj.sample(0.3)
    assert s.q.shape == (2,) and s.t.shape == ()
    s = traj.sample(np.array([[0.1, 0.2], [0.3, 0.4]]))
    assert s.q.shape == (2, 2, 2)
    times = traj.times(1000.0)
    assert times[0] == 0.0 and times[-1] == traj.duration
    assert np.all(np.diff(times) <= 1e-3 + 1e-15)
    path = traj.to_csv(tmp_path / "traj.csv", rate=100.0)
    with path.open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "q_a", "q_b", "qd_a", "qd_b", "qdd_a", "qdd_b", "qddd_a", "qddd_b"]
    assert len(rows) - 1 == len(traj.times(100.0))
    row = np.array(rows[5], dtype=float)
    s = traj.sample(row[0])
    np.testing.assert_allclose(row[1:3], s.q)
    with pytest.raises(InvalidArgumentError, match=r"outside the trajectory .* \(clamp=True holds the end states\)"):
        traj.sample(traj.duration + 1.0)
    # clamp=True holds the end states and keeps the times asked for.
    held = traj.sample([-1.0, 0.0, traj.duration, traj.duration + 1.0], clamp=True)
    np.testing.assert_array_equal(held.t, [-1.0, 0.0, traj.duration, traj.duration + 1.0])
    np.testing.assert_array_equal(held.q[0], held.q[1])
    np.testing.assert_array_equal(held.qd[0], held.qd[1])
    np.testing.assert_array_equal(held.q[3], traj.waypoints[-1])
    assert not np.any(held.qd[2:]) and not np.any(held.qdd[2:]) and not np.any(held.qddd[2:])
    assert traj.sample(5.0 + traj.duration, clamp=True).q.shape == (2,)
    with pytest.raises(InvalidArgumentError, match="time nan s is not a finite number"):
        traj.sample([0.0, float("nan")], clamp=True)
    with pytest.raises(InvalidArgumentError, match="rate must be positive"):
        traj.times(0.0)


@given(seed=st.integers(0, 2**32 - 1), clamp=st.booleans())
@settings(max_examples=25, deadline=None)
def test_positions_are_the_sampled_positions(seed, clamp):
    # positions() computes q as sample() does, bit for bit, with the same checks and shapes.
    rng = np.random.default_rng(seed)
    limits = JointLimits([1.0, 2.0, 1.5], [2.0, 3.0, 2.5], [20.0, 30.0, 25.0], [-2, -2, -2], [2, 2, 2])
    traj = plan_trajectory(rng.uniform(-2, 2, (int(rng.integers(2, 5)), 3)), limits)
    lo, hi = (-0.5, traj.duration + 0.5) if clamp else (0.0, traj.duration)
    t = np.concatenate([rng.uniform(lo, hi, 40), traj.waypoint_times, [traj.duration]])
    assert np.array_equal(traj.positions(t, clamp=clamp), traj.sample(t, clamp=clamp).q)
    assert np.array_equal(traj.positions(t[3], clamp=clamp), traj.sample(t[3], clamp=clamp).q)
    grid = t[:40].reshape(4, 10)
    assert np.array_equal(traj.positions(grid, clamp=clamp), traj.sample(grid, clamp=clamp).q)
    with pytest.raises(InvalidArgumentError, match="outside the trajectory"):
        traj.positions(traj.duration + 1.0)
    with pytest.raises(InvalidArgumentError, match="not a finite number"):
        traj.positions([0.0, float("nan")], clamp=clamp)


@given(seed=st.integers(0, 2**32 - 1), points=st.integers(2, 5))
@settings(max_examples=25, deadline=None)
def test_compiled_positions_equal_the_numpy_ones_bit_for_bit(seed, points):
    # Many times at once go through one compiled loop (as the singularity measure samples at 1 kHz):
    # the same values as the NumPy path (taken without the compiled library, as with PLANNER_JIT=0),
    # at the knots themselves (the interval that starts there), between them and at the end.
    import planner.motion.trajectory as trajectory_module
    from planner.core.certificates import grams

    rng = np.random.default_rng(seed)
    dof = int(rng.integers(1, 8))
    limits = JointLimits(
        rng.uniform(0.5, 3, dof), rng.uniform(1, 10, dof), rng.uniform(5, 50, dof), [-3] * dof, [3] * dof
    )
    traj = plan_trajectory(rng.uniform(-2, 2, (points, dof)), limits)
    t = np.concatenate([traj.times(1000.0), traj.knots, traj.waypoint_times, rng.uniform(0, traj.duration, 50)])
    compiled = traj.positions(t)
    if grams(np.zeros((1, 1, 1))) is not None:  # a compiler: the compiled loop runs
        assert traj._compiled_positions(t) is not None
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(trajectory_module, "load_functions", lambda *args: None)
        assert traj._compiled_positions(t) is None
        written_out = traj.positions(t)
    assert compiled.tobytes() == written_out.tobytes()
    assert compiled.tobytes() == traj.sample(t).q.tobytes()
    np.testing.assert_array_equal(traj.positions(traj.waypoint_times), traj.waypoints)


def test_limits_from_robot_defaults_and_servo_speed():
    robot = get_robot("dh3")
    lim = JointLimits.from_robot(robot)
    np.testing.assert_allclose(lim.velocity, robot.velocity_limit)
    np.testing.assert_allclose(lim.acceleration, 2 * robot.velocity_limit)
    np.testing.assert_allclose(lim.jerk, 20 * robot.velocity_limit)
    lim = JointLimits.from_robot(robot, servo_seconds_per_60deg=0.1, acceleration=5.0, jerk=[50, 60, 70])
    np.testing.assert_allclose(lim.velocity, math.radians(60) / 0.1)
    np.testing.assert_allclose(lim.acceleration, 5.0)
    np.testing.assert_allclose(lim.jerk, [50, 60, 70])
    assert not lim.velocity.flags.writeable


# ---------------------------------------------------------------------------- bad input
LIM = JointLimits([1.0, 1.0], [2.0, 2.0], [20.0, 20.0], [-1.0, -2.0], [1.0, 2.0], ("shoulder", "elbow"))


def test_waypoint_outside_range_names_joint_and_value():
    with pytest.raises(JointLimitError, match=r"waypoint 1: joint 'elbow' value 2.5 is outside its range \[-2, 2\]"):
        plan_trajectory([[0, 0], [0.5, 2.5]], LIM)


@pytest.mark.parametrize("value", [0.0, -1.0, float("nan")])
def test_zero_negative_or_nan_limits(value):
    with pytest.raises(InvalidLimitsError, match=r"velocity limit of joint 'joint1' must be positive and finite"):
        JointLimits([1.0, value], [1.0, 1.0], [1.0, 1.0], [-1, -1], [1, 1])
    with pytest.raises(InvalidLimitsError, match=r"jerk limit of joint 'joint0' must be positive and finite"):
        JointLimits([1.0, 1.0], [1.0, 1.0], [value, 1.0], [-1, -1], [1, 1])
    robot = get_robot("dh3")
    with pytest.raises(InvalidLimitsError, match=r"acceleration limit of joint 'base_yaw' must be positive"):
        JointLimits.from_robot(robot, acceleration=value)


def test_limit_lengths_and_ranges():
    with pytest.raises(InvalidLimitsError, match=r"velocity limit has 3 values; give one number or 2"):
        JointLimits([1.0, 1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [-1, -1], [1, 1])
    with pytest.raises(InvalidLimitsError, match=r"joint 'joint0' has lower limit 1 > upper limit -1"):
        JointLimits([1.0], [1.0], [1.0], [1.0], [-1.0])


def test_nan_waypoint():
    with pytest.raises(InvalidConfigurationError, match=r"waypoint 1 holds nan for joint 'elbow'"):
        plan_trajectory([[0, 0], [0, float("nan")]], LIM)


def test_infinite_waypoint_of_a_joint_without_range():
    # A continuous joint (infinite range) still needs finite waypoints.
    limits = JointLimits(1.0, 2.0, 20.0, lower=[-1.0, -math.inf], upper=[1.0, math.inf], joint_names=("a", "b"))
    with pytest.raises(InvalidConfigurationError, match=r"waypoint 1 holds inf for joint 'b'"):
        plan_trajectory(np.array([[0.0, 0.0], [0.0, math.inf]]), limits)
    assert plan_trajectory(np.array([[0.0, 0.0], [0.5, 10.0]]), limits).duration > 0.0


def test_fewer_than_two_waypoints():
    with pytest.raises(InvalidArgumentError, match="at least two waypoints, got 1"):
        plan_trajectory([[0, 0]], LIM)
    with pytest.raises(InvalidArgumentError, match="at least two waypoints, got 0"):
        plan_trajectory([], LIM)


def test_mismatched_dof():
    with pytest.raises(
        InvalidConfigurationError, match=r"waypoint 1 has 3 values; expected 2, one per joint \(shoulder, elbow\)"
    ):
        plan_trajectory([[0, 0], [0, 0, 0]], LIM)


def test_bad_start_state_strategy_and_dwell():
    with pytest.raises(InvalidArgumentError, match=r"start velocity of joint 'elbow' is 3, beyond its limit \+-1"):
        plan_trajectory([[0, 0], [0.5, 0.5]], LIM, start_velocity=[0, 3])
    unknown = "unknown strategy 'fast'; valid: optimized, heuristic, stop, refined"
    with pytest.raises(InvalidArgumentError, match=unknown):
        plan_trajectory([[0, 0], [0.5, 0.5]], LIM, strategy="fast")
    with pytest.raises(InvalidArgumentError, match=r"dwell at waypoint 1 must be >= 0"):
        plan_trajectory([[0, 0], [0.5, 0.5]], LIM, dwell=[0, -1])
    with pytest.raises(InvalidArgumentError, match=r"stop index 5 is not a waypoint index"):
        plan_trajectory([[0, 0], [0.5, 0.5]], LIM, stops=[5])


def test_stops_as_an_array_and_bad_stops():
    q = [[0, 0], [0.5, 0.5], [0.2, 0.9], [0.0, 0.3]]
    as_list = plan_trajectory(q, LIM, stops=[1, 2])
    as_array = plan_trajectory(q, LIM, stops=np.array([1, 2]))
    assert as_array.duration == as_list.duration
    np.testing.assert_array_equal(as_array.waypoint_times, as_list.waypoint_times)
    for bad in (3, "1", [[1, 2]], {"a": 1}):
        with pytest.raises(InvalidArgumentError, match=r"stop"):
            plan_trajectory(q, LIM, stops=bad)


@pytest.mark.slow
@settings(max_examples=1500, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(problems(), st.integers(0, 2**32 - 1), st.sampled_from(["optimized", "heuristic", "stop"]))
def test_many_problems_with_start_states_and_dwell(problem, seed, strategy):
    q, limits = problem
    rng = np.random.default_rng(seed)
    kwargs = {"dwell": rng.uniform(0, 0.3, len(q)) * (rng.random(len(q)) < 0.3)}
    if strategy != "stop" and rng.random() < 0.5:
        kwargs = {"start_velocity": rng.uniform(-0.5, 0.5, q.shape[1]) * limits.velocity}
    try:
        traj = plan_trajectory(q, limits, strategy=strategy, **kwargs)
    except InvalidArgumentError as exc:  # a start state that cannot stop within the range
        assert "even braking at once" in str(exc)
        return
    assert_within_limits(traj)
    assert_passes_waypoints(traj, q)


def test_request_plans_as_the_keywords_do():
    robot = get_robot("al5c")
    limits = JointLimits.from_robot(robot)
    q = robot.random_configurations(np.random.default_rng(11), 5)
    kwargs = {"stops": [2], "dwell": [0, 0.1, 0, 0, 0], "strategy": "heuristic"}
    request = TrajectoryRequest(q, limits, **kwargs)
    a, b = plan_trajectory(q, limits, **kwargs), plan_trajectory_request(request)
    assert a.duration == b.duration and b.strategy == "heuristic"
    np.testing.assert_array_equal(a.sampled(200.0).q, b.sampled(200.0).q)
    # Normalised and read-only: derived requests are validated again.
    assert request.stops == (2,) and request.dwell.shape == (5,) and not request.waypoints.flags.writeable
    assert np.all(np.isnan(request.via_velocities)) and request.min_durations.shape == (4,)
    unknown = "unknown strategy 'fast'; valid: optimized, heuristic, stop, refined"
    with pytest.raises(InvalidArgumentError, match=unknown):
        replace(request, strategy="fast")
    with pytest.raises(InvalidArgumentError, match="waypoint 0 is a stop, but a non-zero start state was given"):
        TrajectoryRequest(q, limits, stops=[0], start_velocity=0.1 * limits.velocity)
    with pytest.raises(InvalidArgumentError, match="request must be a TrajectoryRequest, got list"):
        plan_trajectory_request([q, limits])


def test_via_strategies_are_registered_objects():
    assert list(VIA_STRATEGIES) == ["optimized", "heuristic", "stop", "refined"]
    for name, cls in VIA_STRATEGIES.items():
        assert issubclass(cls, ViaStrategy) and cls.name == name

    class Halfway(HeuristicStrategy):
        """The slope blend at half speed: a plug-in needs no registry entry to be passed."""

        name = "halfway"

        def choose(self, chain):
            super().choose(chain)
            free = ~chain.fixed
            chain.v[free] *= 0.5
            chain.acc[free] *= 0.25

    q = [[0.0, 0.0], [0.5, 0.4], [1.0, 0.1], [0.2, 0.3]]
    traj = plan_trajectory(q, LIM, strategy=Halfway())
    assert traj.strategy == "halfway"
    assert_within_limits(traj)
    assert_passes_waypoints(traj, np.array(q))


# ------------------------------------------------------------------ regressions found by fuzzing
AL5C_RUCKIG_ERROR_CASE = np.array(
    [
        [-0.9130776931532878, 1.8381956651777496, -1.6030045689591623, 0.45822408396590575, -1.0018930426017902],
        [0.7157392185800953, 1.0249813358251911, -0.8958922087909214, -0.6340588046435863, -1.2413118691828933],
        [-0.45422529643051, 1.687326161978938, -1.2283348912702614, 0.8741352809277316, -0.7274680640109338],
        [0.23599635464154312, 0.46023278213059526, -2.196517217836796, -1.1416993735510503, 0.3238352970164067],
        [0.9937918214101229, 1.4559528771431016, -1.4572133632930824, 1.0146817540979418, -0.4280958394112663],
    ]
)


def test_via_search_survives_ruckig_errors():
    # Ruckig raised "error in step 1, dof: 4" from the via search on this path (1 in 2,000).
    robot = get_robot("al5c")
    limits = replace(
        JointLimits.from_robot(robot), velocity=np.full(5, 2.0), acceleration=np.full(5, 4.0), jerk=np.full(5, 40.0)
    )
    traj = plan_trajectory(AL5C_RUCKIG_ERROR_CASE, limits)
    np.testing.assert_allclose(traj.sample(traj.waypoint_times).q, AL5C_RUCKIG_ERROR_CASE, atol=1e-9)
    assert max(traj.peak_ratios(None)[k] for k in ("velocity", "acceleration", "jerk")) <= 1 + LIMIT_TOLERANCE


def test_out_and_back_on_one_parabola_is_no_profile_not_a_crash():
    # Ruckig 0.19 crashes the process on a joint that returns to its start on one
    # constant-acceleration parabola (same acceleration at both ends, opposite velocities).
    from planner.motion.segments import SegmentSolver

    limits = JointLimits(5.236, 10.47197551196598, 104.7197551196598, lower=[-3.0], upper=[3.0])
    solver = SegmentSolver(np.array([[1.0], [1.0]]), limits)
    a = np.array([-10.47197551196598 * 0.999])
    duration, _, _ = solver.solve(0, np.array([0.3]), a, np.array([-0.3]), a)
    assert duration == math.inf


def test_segment_range_from_ruckig_extrema_equals_the_exact_piece_range():
    # Ruckig's position_extrema miss turning points inside phases of zero jerk; the range
    # check adds them, and must agree with the extrema computed from the pieces themselves.
    from planner.motion.limits import admissible_acceleration
    from planner.motion.segments import (
        SegmentSolver,
        merge_segment,
        piece_position_range,
        segment_position_range,
    )

    rng = np.random.default_rng(3)
    dof = 4
    limits = JointLimits(1.0, 2.0, 20.0, lower=np.full(dof, -3.0), upper=np.full(dof, 3.0))
    turned = 0
    for _ in range(300):
        q = rng.uniform(-1.0, 1.0, (2, dof))
        v = rng.uniform(-1.0, 1.0, (2, dof)) * rng.choice([0.0, 0.5, 1.0], (2, 1))
        a = admissible_acceleration(v, rng.uniform(-2.0, 2.0, (2, dof)), limits)
        duration, _, traj = SegmentSolver(q, limits).solve(0, v[0], a[0], v[1], a[1], keep=True)
        merged = merge_segment(traj, duration, (q[0], v[0], a[0]), q[1], limits)
        lo, hi = segment_position_range(traj, merged, duration)
        lo_exact, hi_exact = piece_position_range(merged.knots, merged.pieces, duration)
        np.testing.assert_allclose(lo, lo_exact, rtol=0.0, atol=1e-13)
        np.testing.assert_allclose(hi, hi_exact, rtol=0.0, atol=1e-13)
        turned += merged.missed is not None and bool(np.isfinite(merged.missed[0]).any())
        if merged.missed is not None:  # read from Ruckig's lists: exactly the turning points of its phases
            profiles = traj.profiles[0]
            pos, vel, acc = (np.array([getattr(p, x) for p in profiles])[:, :-1] for x in "pva")
            vel_end = np.array([p.v for p in profiles])[:, 1:]
            with np.errstate(divide="ignore", invalid="ignore"):
                tz = -vel / acc
                turn = pos + tz * (vel + tz * acc / 2.0)
            turns = (np.array([p.j for p in profiles]) == 0.0) & (vel * vel_end < 0.0)
            np.testing.assert_array_equal(merged.missed[0], np.where(turns, turn, np.inf).min(axis=1))
            np.testing.assert_array_equal(merged.missed[1], np.where(turns, turn, -np.inf).max(axis=1))
    assert turned > 100  # the case Ruckig's extrema miss is common with moving end states


def test_segment_solver_answers_a_repeated_state_from_its_cache():
    from planner.motion.segments import SegmentSolver

    limits = JointLimits(1.0, 2.0, 20.0, lower=[-2, -2], upper=[2, 2])
    solver = SegmentSolver(np.array([[0.0, 0.0], [1.0, -0.5], [0.5, 0.5]]), limits)
    v, a = np.array([0.3, -0.2]), np.array([0.1, 0.0])
    first = solver.solve(0, np.zeros(2), np.zeros(2), v, a)
    fresh = SegmentSolver(solver.q, limits).solve(0, np.zeros(2), np.zeros(2), v, a)
    assert solver.solve(0, np.zeros(2), np.zeros(2), v, a) is first
    assert first[0] == fresh[0]
    assert solver.solve(1, v, a, np.zeros(2), np.zeros(2))[0] != first[0]


def test_request_defaults_are_frozen_shared_zeros_and_flags_follow_the_fields():
    from planner.motion.request import TrajectoryRequest

    limits = JointLimits(1.0, 2.0, 20.0, lower=[-2, -2], upper=[2, 2])
    plain = TrajectoryRequest([[0.0, 0.0], [1.0, 1.0], [0.5, 0.0]], limits)
    for arr in (plain.start_velocity, plain.start_acceleration, plain.dwell, plain.via_accelerations):
        assert not arr.flags.writeable and not arr.any()
        with pytest.raises(ValueError):
            arr.setflags(write=True)
    assert np.isnan(plain.via_velocities).all() and plain.stops == ()
    assert not plain.moving_start and not plain.prescribed
    moving = TrajectoryRequest(plain.waypoints, limits, start_velocity=[0.0, -0.5], stops=[-1])
    assert moving.moving_start and not moving.prescribed and moving.stops == (2,)
    given = TrajectoryRequest(plain.waypoints, limits, min_durations=[0.0, 0.0])
    assert given.prescribed and not given.moving_start
    caller = np.array([0.1, 0.2])
    copied = TrajectoryRequest(plain.waypoints, limits, start_acceleration=caller)
    assert copied.moving_start and not copied.start_acceleration.flags.writeable
    caller[0] = 0.0
    assert copied.start_acceleration[0] == 0.1


@pytest.mark.parametrize(("turn", "limited"), [(0.01, False), (1.0, True)])
def test_turn_search_runs_only_where_a_turning_joint_sets_a_segment_duration(turn, limited):
    from planner.motion.vias import ViaChain

    # Joint 0 moves on through the via, joint 1 turns round there: a tiny turn never sets
    # the duration of a segment next to it, a big one does.
    q = np.array([[0.0, 0.0], [0.5, turn], [1.0, 0.0]])
    limits = JointLimits(1.0, 2.0, 20.0, lower=[-3, -3], upper=[3, 3])
    chain = ViaChain(q, limits, np.zeros(2), np.zeros(2), np.zeros(3, dtype=bool))
    turning = np.array([False, True])
    assert chain.limited_by(1, turning) is limited
    if not limited:  # no state of the turning joint shortens the pair, so the search is skipped
        current = chain.pair_cost(1, chain.v[1], chain.acc[1])[0]
        for v1 in np.linspace(-0.2, 0.2, 5):
            for a1 in np.linspace(-2.0, 2.0, 5):
                state_v, state_a = chain.v[1].copy(), chain.acc[1].copy()
                state_v[1], state_a[1] = v1, a1
                assert chain.pair_cost(1, state_v, state_a)[0] >= current


def test_lazily_built_pieces_behave_like_given_ones():
    # plan_trajectory builds the piece arrays on first use (JointTrajectory.lazy).
    import dataclasses

    from planner.motion.trajectory import JointTrajectory

    limits = JointLimits(1.0, 2.0, 20.0, lower=[-2, -2], upper=[2, 2])
    waypoints = [[0.0, 0.0], [1.0, -0.5], [0.5, 0.5], [0.0, 0.0]]
    first, second = plan_trajectory(waypoints, limits), plan_trajectory(waypoints, limits)
    sample = first.sample(np.linspace(0.0, first.duration, 50))
    copy = replace(second, duration=second.duration)  # replace reads (and so builds) the pieces
    np.testing.assert_array_equal(copy.knots, first.knots)
    np.testing.assert_array_equal(copy.sample(sample.t).q, sample.q)
    for name in ("knots", "p", "v", "a", "j"):
        assert not getattr(first, name).flags.writeable
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(first, name, np.zeros(1))
    with pytest.raises(InvalidArgumentError, match="needs the fields"):
        JointTrajectory.lazy(lambda: (), duration=1.0)


def test_tiny_moves_end_on_their_waypoints():
    # Ruckig's time synchronisation ended the smaller of two 1e-7 rad moves 20 % off target.
    limits = JointLimits(velocity=1.0, acceleration=2.0, jerk=20.0, lower=[-1, -1], upper=[1, 1])
    for waypoints in ([[0, 0], [1e-7, 5e-8]], [[0, 0], [1e-7, 5e-8], [0, 0]]):
        traj = plan_trajectory(waypoints, limits)
        t = np.linspace(0.0, traj.duration, 2001)
        q = traj.sample(t).q
        np.testing.assert_allclose(traj.sample(traj.waypoint_times).q, waypoints, atol=1e-15)
        # Continuous: no step between neighbouring samples beyond what the speed allows.
        assert np.all(np.abs(np.diff(q, axis=0)) <= 1.0 * (t[1] - t[0]) * (1 + 1e-6))
        assert np.all(np.abs(q[-1] - waypoints[-1]) <= 1e-15)


class _EagerStop(StopStrategy):
    """The stop strategy through the full via chain (plan_trajectory's shortcut skips it)."""


_TRAJECTORY_FIELDS = (
    "knots",
    "p",
    "v",
    "a",
    "j",
    "waypoints",
    "waypoint_times",
    "via_velocities",
    "via_accelerations",
    "dwell",
    "repaired",
)


def assert_same_plan(fast, eager):
    assert fast.duration == eager.duration
    assert fast.strategy == eager.strategy == "stop"
    assert fast.limits is eager.limits
    for name in _TRAJECTORY_FIELDS:
        mine, theirs = getattr(fast, name), getattr(eager, name)
        assert mine.dtype == theirs.dtype and mine.shape == theirs.shape, name
        np.testing.assert_array_equal(mine, theirs, err_msg=name)
        assert not mine.flags.writeable, name


@pytest.mark.parametrize("name", ["al5c", "three_joint", "dh3", "shelley"])
def test_stop_shortcut_equals_the_chain_bit_for_bit(name):
    # strategy="stop" plans rest-to-rest segments without the via chain, the pieces merged on
    # first use; every field must be what the chain makes of the same request.
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(7)
    for n in (2, 3, 5, 8):
        q = robot.random_configurations(rng, n)
        q[n // 2] = q[n // 2 - 1]  # a segment of zero length
        eager = plan_trajectory(q, limits, strategy=_EagerStop())
        fast = plan_trajectory(q, limits, strategy="stop")
        assert_same_plan(fast, eager)
        request = plan_trajectory_request(TrajectoryRequest(q, limits, strategy="stop"))
        assert_same_plan(request, eager)
        assert_within_limits(fast)


class _EagerOptimized(OptimizedStrategy):
    """The optimized strategy as a caller's own type: always through the full via chain."""


@pytest.mark.parametrize("name", ["al5c", "three_joint", "dh3", "shelley"])
def test_two_waypoint_plans_of_every_strategy_equal_the_chain_bit_for_bit(name):
    # Between two waypoints every registered strategy rests at both ends (no via to choose, a
    # prescribed state there overridden): such a plan is made as the stop strategy's, and every
    # field must be what the chain makes of it, under the request's strategy name.
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(5)
    for trial in range(6):
        q = robot.random_configurations(rng, 2)
        if trial == 0:
            q[1] = q[0]  # a segment of zero length
        eager = plan_trajectory_request(TrajectoryRequest(q, limits, strategy=_EagerOptimized()))
        ends = 0.5 * limits.velocity * rng.uniform(-1.0, 1.0, q.shape)
        for fields in (
            {},
            {"via_velocities": np.full(q.shape, np.nan), "via_accelerations": np.zeros(q.shape), "min_durations": [0]},
            {"via_velocities": ends, "stops": [1]},
        ):
            for strategy in VIA_STRATEGIES:
                fast = plan_trajectory_request(TrajectoryRequest(q, limits, strategy=strategy, **fields))
                assert fast.strategy == strategy
                assert fast.duration == eager.duration
                for field in _TRAJECTORY_FIELDS:
                    mine, theirs = getattr(fast, field), getattr(eager, field)
                    assert mine.dtype == theirs.dtype and mine.shape == theirs.shape, field
                    np.testing.assert_array_equal(mine, theirs, err_msg=field)
                    assert not mine.flags.writeable, field
                assert_within_limits(fast)


def test_two_waypoint_plans_with_a_minimum_duration_or_a_dwell_still_honour_them():
    limits = JointLimits(1.0, 2.0, 20.0, lower=[-2, -2], upper=[2, 2])
    q = [[0.0, 0.0], [0.5, -0.5]]
    quick = plan_trajectory(q, limits)
    slow = plan_trajectory(q, limits, min_durations=[quick.duration + 1.0])
    assert slow.duration == pytest.approx(quick.duration + 1.0) and slow.strategy == "optimized"
    rest = plan_trajectory(q, limits, dwell=[0.25, 0.0])
    assert rest.duration == pytest.approx(quick.duration + 0.25)
    np.testing.assert_array_equal(rest.sample(0.2).q, q[0])
    moving = plan_trajectory(q, limits, start_velocity=[0.5, 0.0])
    np.testing.assert_allclose(moving.sample(0.0).qd, [0.5, 0.0])


def test_stop_plans_share_zero_arrays_that_cannot_be_made_writeable():
    limits = JointLimits(1.0, 2.0, 20.0, lower=[-2, -2], upper=[2, 2])
    first = plan_trajectory([[0.0, 0.0], [1.0, 1.0], [0.5, -1.0]], limits, strategy="stop")
    second = plan_trajectory([[0.0, 1.0], [1.0, 0.0], [0.5, 1.0]], limits, strategy="stop")
    for name in ("via_velocities", "via_accelerations", "dwell", "repaired"):
        with pytest.raises(ValueError, match="WRITEABLE"):
            getattr(first, name).setflags(write=True)
        assert not getattr(second, name).any()


@pytest.mark.parametrize("name", ["al5c", "three_joint", "dh3", "shelley"])
def test_stop_shortcut_equals_the_chain_with_waypoints_at_the_range_ends(name):
    # Waypoints at or next to a range end: the shortcut reads Ruckig's profiles there (a turn
    # inside a phase of zero jerk could reach beyond the range) and must still decide as the chain.
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(11)
    lower, upper = limits.lower, limits.upper
    for n in (2, 3, 5):
        for offset in (0.0, 1e-9, 1e-4):
            q = robot.random_configurations(rng, n)
            ends = np.where(rng.random(q.shape) < 0.5, lower + offset, upper - offset)
            q = np.where((rng.random(q.shape) < 0.4) & np.isfinite(ends), ends, q)
            assert_same_plan(
                plan_trajectory(q, limits, strategy="stop"), plan_trajectory(q, limits, strategy=_EagerStop())
            )


@given(
    st.lists(
        st.lists(st.floats(-1.5, 1.5, allow_nan=False, allow_subnormal=False), min_size=2, max_size=2),
        min_size=2,
        max_size=6,
    ),
    st.sampled_from([1e-7, 1e-3, 1.0]),
)
@SETTINGS
def test_stop_shortcut_equals_the_chain_on_generated_waypoints(points, scale):
    # Small scales give tiny moves, where the chain re-solves joints unsynchronised.
    limits = JointLimits(velocity=[1.0, 0.3], acceleration=[2.0, 5.0], jerk=[20.0, 9.0], lower=-2, upper=2)
    q = np.array(points) * scale
    assert_same_plan(plan_trajectory(q, limits, strategy="stop"), plan_trajectory(q, limits, strategy=_EagerStop()))


@pytest.mark.parametrize(
    ("waypoints", "error", "match"),
    [
        ([[0.0, 0.0]], InvalidArgumentError, "at least two waypoints"),
        ([[0.0, 0.0], [0.0, 3.0]], JointLimitError, "3"),
        ([[0.0, 0.0], [0.0, math.nan]], InvalidConfigurationError, "nan"),
        ([[0.0, 0.0], [0.0, math.inf]], InvalidConfigurationError, "inf"),
        ([[0.0, 0.0], [0.0]], InvalidConfigurationError, "1 values"),
        ("ab", InvalidConfigurationError, "waypoint 0"),
    ],
)
def test_stop_shortcut_keeps_the_input_errors(waypoints, error, match):
    limits = JointLimits(1.0, 2.0, 20.0, lower=[-2, -2], upper=[2, 2])
    for strategy in ("stop", "optimized"):
        with pytest.raises(error, match=match):
            plan_trajectory(waypoints, limits, strategy=strategy)
    with pytest.raises(InvalidArgumentError, match="JointLimits"):
        plan_trajectory([[0.0, 0.0], [1.0, 1.0]], "fast", strategy="stop")


@pytest.mark.parametrize("strategy", ["heuristic", "optimized", "stop"])
def test_a_tiny_move_to_a_range_end_beside_moving_joints_plans(strategy):
    # Found by the slow property test: Ruckig's unsynchronised re-solve of the 5e-8 rad move
    # to the range end raised RuckigError ("error in step 2") out of plan_trajectory.
    end = 2.356194490192345
    limits = JointLimits(
        np.full(3, 5.23598775598299),
        np.full(3, 10.47197551196598),
        np.full(3, 104.7197551196598),
        -np.full(3, end),
        np.full(3, end),
    )
    q = np.array([[0.0, 0.0, 0.0], [-2.3561944401923447] * 3, [-end] * 3, [0.0, 0.0, -end]])
    traj = plan_trajectory(q, limits, strategy=strategy)
    assert_within_limits(traj)
    assert_passes_waypoints(traj, q)


@pytest.mark.parametrize(
    ("waypoints", "joint"),
    [
        ([[1.0, 0.0], [math.nan, 0.0], [0.5, 0.0]], "nan"),  # the NaN between the extremes of its joint
        ([[1.0, 0.0], [0.5, 0.0], [math.nan, 0.0]], "nan"),
        ([[0.0, 0.0], [0.0, -math.inf], [0.0, 1.0]], "inf"),
    ],
)
def test_waypoint_rows_within_rejects_what_min_and_max_would_hide(waypoints, joint):
    limits = JointLimits(1.0, 2.0, 20.0, lower=[-2, -2], upper=[2, 2])
    assert waypoint_rows_within(waypoints, limits) is None
    with pytest.raises(InvalidConfigurationError, match=joint):
        plan_trajectory(waypoints, limits, strategy="stop")


def test_waypoint_rows_within_gives_the_rows_and_extremes_of_accepted_waypoints():
    limits = JointLimits(1.0, 2.0, 20.0, lower=[-2, -math.inf], upper=[2, math.inf])
    q = np.array([[0.5, -1e300], [-2.0, 1e300], [2.0, 3.0]])
    whole, rows, low, high = waypoint_rows_within(q, limits)
    assert whole is not q and whole.flags.writeable
    np.testing.assert_array_equal(whole, q)
    assert rows == q.tolist() and low == [-2.0, -1e300] and high == [2.0, 1e300]
    assert waypoint_rows_within(q[:1], limits) is None
    assert waypoint_rows_within(q + [[0.0, 0.0], [-1e-12, 0.0], [0.0, 0.0]], limits) is None  # below the range
    # Values whose sum overflows are left to check_waypoints, which accepts them.
    huge = np.array([[0.0, 1e308], [0.0, 1e308]])
    assert waypoint_rows_within(huge, limits) is None
    np.testing.assert_array_equal(check_waypoints(huge, limits), huge)


@pytest.mark.parametrize("name", ["al5c", "dh3"])
def test_rest_to_rest_segments_the_same_with_the_rows_given(name):
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(3)
    for n in (2, 5):
        q = robot.random_configurations(rng, n)
        given = rest_to_rest_segments(q, limits, waypoint_rows_within(q, limits)[1:])
        alone = rest_to_rest_segments(q, limits)
        assert given == alone and len(given) == n - 1
        # The trajectories solved again for the pieces take exactly those durations.
        assert [rest_to_rest_trajectory(a, b, limits).duration for a, b in zip(q, q[1:])] == given


def test_stop_plans_with_other_limits_in_between_use_their_own():
    # The thread's rest-to-rest input keeps the last limits it was given: a change must reach it.
    q = [[0.0, 0.0], [1.0, -1.0], [0.2, 0.5]]
    slow = JointLimits(0.5, 1.0, 10.0, lower=[-2, -2], upper=[2, 2])
    fast = JointLimits(2.0, 8.0, 80.0, lower=[-2, -2], upper=[2, 2])
    same_as_fast = JointLimits(2.0, 8.0, 80.0, lower=[-2, -2], upper=[2, 2])
    for limits in (slow, fast, slow, same_as_fast, fast):
        assert_same_plan(plan_trajectory(q, limits, strategy="stop"), plan_trajectory(q, limits, strategy=_EagerStop()))
    assert plan_trajectory(q, fast, strategy="stop").duration < plan_trajectory(q, slow, strategy="stop").duration


def test_reach_time_inverts_the_distance_a_motion_from_rest_covers():
    from planner.motion.segments import reach_time

    v, a = 1.5, 3.0
    for t in (0.0, 0.1, 0.5, 1.0, 2.0, 7.0):
        covered = a * t * t / 2.0 if t <= v / a else v * t - v * v / (2.0 * a)
        assert reach_time(covered, v, a) == pytest.approx(t, rel=1e-12, abs=1e-12)
    assert reach_time(-1e-12, v, a) == -math.inf
    assert reach_time(math.inf, v, a) == math.inf


@pytest.mark.parametrize(
    "name",
    ["al5c", pytest.param("ur5", marks=needs_example_robot_data), pytest.param("z1", marks=needs_example_robot_data)],
)
def test_range_check_of_admissible_states_reads_only_reachable_ends_and_agrees_with_every_joint(name):
    # The solver given admissible end states reads Ruckig's extrema only for range ends a joint
    # could reach in the segment's duration: the answer (duration, joints out of range) must be
    # the one of the check over every joint, on waypoints near the range ends too.
    from planner.motion.limits import admissible_acceleration
    from planner.motion.segments import SegmentSolver

    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(11)
    lower, upper = limits.finite_range
    outside = screened = 0
    for case in range(150):
        q = robot.random_configurations(rng, 2)
        if case % 2:  # some joints a hair inside a range end
            edge = np.where(rng.random(q.shape) < 0.5, lower, upper)
            near = rng.random(q.shape) < 0.4
            q = np.where(near, edge - np.sign(edge - (lower + upper) / 2) * rng.uniform(0, 0.05, q.shape), q)
        v = rng.uniform(-1.0, 1.0, (2, robot.dof)) * limits.velocity * rng.choice([0.0, 0.3, 1.0], (2, 1))
        a = admissible_acceleration(v, rng.uniform(-1.0, 1.0, (2, robot.dof)) * limits.acceleration, limits)
        fast = SegmentSolver(q, limits, admissible=[True]).solve(0, v[0], a[0], v[1], a[1])
        full = SegmentSolver(q, limits).solve(0, v[0], a[0], v[1], a[1])
        assert fast[0] == full[0]
        if full[1] is None:
            assert fast[1] is None
        else:
            outside += 1
            np.testing.assert_array_equal(fast[1], full[1])
        screened += fast[2] is not None
    assert outside > 10 and screened > 100  # both outcomes are exercised


def test_a_start_state_that_is_not_admissible_gets_the_range_check_over_every_joint():
    # The reach times assume admissible states; a given start state need not be one (its
    # acceleration may exceed what its velocity allows), so the chain's first segment is
    # checked on every joint, as a solver told nothing does.
    from planner.motion.segments import SegmentSolver
    from planner.motion.vias import ViaChain

    limits = JointLimits(1.0, 2.0, 20.0, lower=[-1.0, -1.0], upper=[1.0, 1.0])
    q = np.array([[0.9, 0.0], [0.95, 0.5], [0.0, 0.9]])
    v0, a0 = np.array([0.9, 0.0]), np.array([2.0, 0.0])  # |v| + a^2 / (2 j) > v_max
    chain = ViaChain(q, limits, v0, a0, np.zeros(3, dtype=bool))

    full = SegmentSolver(q, limits)
    for v1 in (np.zeros(2), np.array([0.2, 0.5])):
        got = chain.seg.solve(0, v0, a0, v1, np.zeros(2))
        want = full.solve(0, v0, a0, v1, np.zeros(2))
        assert got[0] == want[0]
        assert (got[1] is None) == (want[1] is None)
        if want[1] is not None:
            np.testing.assert_array_equal(got[1], want[1])


@pytest.mark.parametrize("strategy", ["optimized", "stop"])
def test_a_pickled_or_copied_trajectory_is_the_same_motion(strategy):
    robot = get_robot("al5c")
    q = robot.random_configurations(np.random.default_rng(11), 4)
    limits = JointLimits.from_robot(robot)
    t = np.linspace(0.0, 1.0, 301)
    for built in (False, True):
        traj = plan_trajectory(q, limits, strategy=strategy)  # lazy: pieces built on first use
        if built:
            _ = traj.knots
        for twin in (pickle.loads(pickle.dumps(traj)), copy.deepcopy(traj)):
            assert twin.duration == traj.duration and twin.strategy == traj.strategy
            np.testing.assert_array_equal(twin.waypoint_times, traj.waypoint_times)
            np.testing.assert_array_equal(twin.knots, traj.knots)
            a, b = twin.sample(t * traj.duration), traj.sample(t * traj.duration)
            for name in ("q", "qd", "qdd", "qddd"):
                np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


@pytest.mark.parametrize("strategy", ["optimized", "stop"])
def test_a_move_longer_than_ruckig_can_time_is_a_planning_error(strategy):
    # Ruckig refuses a profile longer than 7e3 s with result -101, which its Python binding
    # has no Result member for: plan_trajectory leaked "ValueError: -101 is not a valid Result".
    from planner import PlanningError, load_robot

    robot = load_robot("al5c")
    middle, half = (robot.lower + robot.upper) / 2.0, 0.9 * (robot.upper - robot.lower) / 2.0
    waypoints = np.array([middle - half, middle + half, middle - half])
    with pytest.raises(PlanningError):
        plan_trajectory(waypoints, JointLimits.from_robot(robot, velocity=1e-4), strategy=strategy)
