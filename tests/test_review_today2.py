"""Review of the changes merged on b074e8a..b9440a2, through the public entry points.

- ``JointLimits.check_move_durations``'s bound on the first move (from rest) and the last (to
  rest), against Ruckig itself, and as ``plan_motion`` applies it to a motion starting moving.
- ``plan_motion`` with a scene (checked before its singularity measure): the trajectory it
  returns re-checked independently at 1 kHz with ``CollisionChecker.in_collision``, its
  singularity report against ``Robot.conditioning`` sampled at the plan's rate, and the same
  plan again from the same seed after other plans in the scene (the shared checker's GJK
  guesses forgotten only where ``in_collision`` ran).
"""

from __future__ import annotations

import numpy as np
import pytest
from dh_arms import property_settings
from hypothesis import given
from hypothesis import strategies as st
from ruckig import InputParameter, Result, Ruckig, Trajectory

import planner
from planner.app.plan_file import parse_motion_request
from planner.collision import CollisionChecker, parse_scene
from planner.exceptions import InvalidArgumentError, PlanningError
from planner.motion.detours import SingularityOptions, plan_clear_of_singularities
from planner.motion.limits import MAX_SEGMENT_DURATION, JointLimits
from planner.motion.plan import plan_trajectory_request
from planner.motion.request import TrajectoryRequest

from conftest import get_robot, needs_example_robot_data


def _least_time(d: float, v: float, a: float, j: float, v_end: float) -> float:
    """Ruckig's duration of a 1-dof move of `d` from rest to velocity `v_end` (inf where it refuses)."""
    inp = InputParameter(1)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [0.0], [0.0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [d], [v_end], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v], [a], [j]
    traj = Trajectory(1)
    result = Ruckig(1).calculate(inp, traj)
    return traj.duration if result in (Result.Working, Result.Finished) else float("inf")


@property_settings(60)
@given(
    v=st.floats(1e-4, 1.0),
    reach=st.floats(10.0, 2e4),  # v / a [s]
    travel=st.floats(0.05, 1.5),  # d / (v * 7000 s)
    first=st.booleans(),
)
def test_move_durations_refuse_only_what_ruckig_cannot_time(v, reach, travel, first):
    """A first (from rest) or last (to rest) move is refused iff Ruckig needs more than 7000 s for it."""
    a = v / reach
    j = a * 1e6  # jerk far above: Ruckig's time is the velocity-and-acceleration bound's
    d = travel * v * MAX_SEGMENT_DURATION
    limits = JointLimits([v], [a], [j], [-1e9], [1e9])
    # The move's least time: from rest to the fastest end state it can reach (and mirrored for the last).
    need = _least_time(d, v, a, j, min(v, float(np.sqrt(2.0 * a * d))) * (1.0 - 1e-12))
    if abs(need - MAX_SEGMENT_DURATION) < 1e-3 * MAX_SEGMENT_DURATION:
        return  # too close to call through Ruckig's jerk phases
    # The other move is short enough: from (last) or to (first) a standstill far off.
    q = np.array([[0.0], [d], [d + 1e-9]]) if first else np.array([[-1e-9], [0.0], [d]])
    try:
        limits.check_move_durations(q)
    except PlanningError as e:
        assert need > MAX_SEGMENT_DURATION, f"refused a move Ruckig times in {need:.6g} s: {e}"
        assert "rest within its velocity limit" in str(e) or "at its velocity limit" in str(e)
    else:
        assert need <= MAX_SEGMENT_DURATION


def _slow_base(start_velocity: list[float] | None) -> dict:
    """dh3's base joint at 0.5 mrad/s reaching it in 3000 s: a 2.8 rad move and a 1 rad one to rest."""
    v, a = 5e-4, 5e-4 / 3000.0
    data = {
        "waypoints": [[-2.3, 0.0, 0.0], [0.5, 0.0, 0.0], [1.25, 0.0, 0.0]],
        "limits": {"velocity": [v, 1.0, 1.0], "acceleration": [a, 1.0, 1.0], "jerk": [1.0, 10.0, 10.0]},
        "units": {"angle": "rad"},
    }
    if start_velocity is not None:
        data["start"] = {"velocity": start_velocity}
    return data


def test_a_motion_starting_at_full_speed_is_not_bounded_as_from_rest():
    """plan_motion bounded a moving start's first move by the time from rest (7100 s): refused a 5600 s move."""
    robot = get_robot("dh3")
    plan = planner.plan_motion(robot, parse_motion_request(_slow_base([5e-4, 0.0, 0.0])), rate=2.0)
    moves = np.diff(plan.waypoint_times)
    # 2.8 rad at 0.5 mrad/s all the way: 5600 s, not the 7100 s from rest (the via state may be a
    # little below full speed where that shortens the braking move after it: the optimized
    # strategy's polish of small arms takes 5600.0135 + 3000.0068 s against 5600 + 3000.0316 s).
    assert moves[0] == pytest.approx(5600.0, abs=0.1)
    assert np.all(moves < MAX_SEGMENT_DURATION)
    # The same from rest needs 2.8 rad / 0.5 mrad/s + 1500 s to reach the velocity limit: refused.
    with pytest.raises(PlanningError, match=r"at least 7\d{3}[.0-9]* s from rest within its velocity limit 0\.0005"):
        planner.plan_motion(robot, parse_motion_request(_slow_base(None)), rate=2.0)


@pytest.mark.xfail(
    strict=True,
    reason=(
        "the via choosers start from rest-to-rest segments, which here exceed Ruckig's 7000 s (9165 s), "
        "so every candidate they compare lasts forever and they keep the via at rest; the plan exists "
        "(6700 s + 6250 s at full speed through the via). Refused with a PlanningError naming the joint, "
        "its rest-to-rest time and the 7000 s limit (test_a_segment_too_long_even_at_rest_is_named)"
    ),
)
def test_a_move_the_duration_check_accepts_is_timed():
    v, a = 5e-4, 1e-7  # reaches its velocity limit in 5000 s over 1.25 rad
    limits = JointLimits.from_robot(
        get_robot("dh3"), velocity=[v, 1.0, 1.0], acceleration=[a, 1.0, 1.0], jerk=[1.0, 10.0, 10.0]
    )
    q = np.zeros((3, 3))
    q[:, 0] = [-2.0, 0.1, 1.975]
    limits.check_move_durations(q)  # accepted: 6700 s from rest, 6250 s to rest
    traj = plan_trajectory_request(TrajectoryRequest(q, limits))
    assert np.all(np.diff(traj.waypoint_times) <= MAX_SEGMENT_DURATION)


SCENE = {
    "obstacles": [
        {"name": "table", "box": [1.6, 1.6, 0.05], "position": [0.0, 0.0, -0.03]},
        {"name": "box", "box": [0.25, 0.25, 0.5], "position": [0.45, 0.0, 0.25]},
    ]
}


def _scene_plan(robot, a, b, seed):
    request = parse_motion_request(
        {
            "waypoints": [list(a), list(b)],
            "scene": SCENE,
            "avoidance": {"seed": seed},
            "units": {"angle": "rad"},
        }
    )
    return planner.plan_motion(robot, request)


def _assert_plan_honest(robot, checker, plan):
    """The plan's collision verdict and singularity report, checked independently of the planner."""
    traj = plan.trajectory
    t = np.append(np.arange(0.0, traj.duration, 1e-3), traj.duration)
    q = traj.sample(t).q
    if plan.collision.clear:
        hits = [float(s) for s, row in zip(t, q) if checker.in_collision(row)]
        assert not hits, f"plan reported clear collides at t = {hits[:3]} s"
    report = plan.singularity
    ts = np.union1d(np.append(np.arange(0.0, traj.duration, 1.0 / report.rate), traj.duration), traj.waypoint_times)
    inv = robot.conditioning(traj.sample(ts).q, robot.resolve_task(report.task))[0]
    assert inv.min() == pytest.approx(report.min_inverse_condition, rel=1e-9, abs=1e-12)
    inside = np.zeros(len(ts), dtype=bool)
    for s, e in report.below_threshold:
        inside |= (ts >= s - 1e-9) & (ts <= e + 1e-9)
    assert np.all(inside[inv < report.threshold])
    assert not np.any(inside & (inv > report.threshold * (1.0 + 1e-9)))


def _scene_pairs(name: str, seed: int, count: int):
    """`count` (start, goal) pairs clear of the scene, drawn from `seed`."""
    robot = get_robot(name)
    checker = CollisionChecker(robot, parse_scene(SCENE))
    rng = np.random.default_rng(seed)
    pairs = []
    while len(pairs) < count:
        a, b = robot.random_configurations(rng, 2)
        if not (checker.in_collision(a) or checker.in_collision(b)):
            pairs.append((a, b))
    return robot, checker, pairs


@needs_example_robot_data
@pytest.mark.parametrize("name", ["ur5", "panda"])
@property_settings(4)
@given(seed=st.integers(0, 2**31 - 1))
def test_scene_plans_are_clear_measured_and_reproducible(name, seed):
    robot, checker, pairs = _scene_pairs(name, seed, 2)
    plans = []
    for i, (a, b) in enumerate(pairs):
        try:
            plans.append(_scene_plan(robot, a, b, seed + i))
        except planner.PlannerError:
            plans.append(None)
            continue
        _assert_plan_honest(robot, checker, plans[-1])
    # The first again, after the second in the same scene (its shared checker reused): the same plan.
    if plans[0] is not None:
        again = _scene_plan(robot, *pairs[0], seed)
        np.testing.assert_array_equal(again.trajectory.waypoints, plans[0].trajectory.waypoints)
        np.testing.assert_array_equal(again.trajectory.waypoint_times, plans[0].trajectory.waypoint_times)
        assert again.collision.closest.distance == plans[0].collision.closest.distance
        assert again.singularity.below_threshold == plans[0].singularity.below_threshold


@pytest.mark.slow
@needs_example_robot_data
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_many_scene_plans_are_clear_and_measured(name):
    """300 pairs per arm were run this way in review (none failed); 40 here."""
    robot, checker, pairs = _scene_pairs(name, 11, 40)
    for i, (a, b) in enumerate(pairs):
        try:
            plan = _scene_plan(robot, a, b, i)
        except planner.PlannerError:
            continue
        _assert_plan_honest(robot, checker, plan)


def test_a_trajectory_timed_for_another_request_is_refused():
    """plan_clear_of_singularities(timed=) took any trajectory through the waypoints: one timed at a
    tenth of the velocity limits, or from a moving start, came back as the request's plan."""
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    q = robot.random_configurations(np.random.default_rng(5), 3)
    request = TrajectoryRequest(q, limits)
    options = SingularityOptions(max_detours=0)
    own = plan_trajectory_request(request)
    assert plan_clear_of_singularities(robot, request, options, timed=own).trajectory is own
    moving = TrajectoryRequest(q, limits, start_velocity=np.full(robot.dof, 0.1))
    moving_own = plan_trajectory_request(moving)
    assert plan_clear_of_singularities(robot, moving, options, timed=moving_own).trajectory is moving_own
    others = [
        TrajectoryRequest(q, JointLimits.from_robot(robot, velocity=[0.1] * robot.dof)),
        TrajectoryRequest(q, limits, dwell=[0.0, 0.5, 0.0]),
        moving,
    ]
    for other in others:
        with pytest.raises(InvalidArgumentError, match="timed must be the JointTrajectory planned from the request"):
            plan_clear_of_singularities(robot, request, options, timed=plan_trajectory_request(other))
    with pytest.raises(InvalidArgumentError, match="timed must be"):
        plan_clear_of_singularities(robot, moving, options, timed=own)


def _slow_line() -> dict:
    """dh3 along a Cartesian line, its base turning 1.12 rad at 0.2 mrad/s reached in 3000 s."""
    robot = get_robot("dh3")
    v, a = 2e-4, 2e-4 / 3000.0

    def position(q: list[float]) -> list[float]:
        return np.asarray(robot.fk(q))[:3, 3].tolist()

    return {
        "targets": [{"position": position([-0.56, 0.4, 0.5])}, {"position": position([0.56, 0.4, 0.5]), "line": True}],
        "limits": {"velocity": [v, v, v], "acceleration": [a, a, a], "jerk": [1.0, 1.0, 1.0]},
        "units": {"length": "m", "angle": "rad"},
    }


def test_a_line_is_not_bounded_as_one_segment_from_rest():
    """A line is timed in many segments: its ends' least time from and to rest as one segment
    (7100 s) does not bound it. plan_motion refused such a line since b074e8a (see the slow test)."""
    limits = JointLimits.from_robot(get_robot("dh3"), velocity=[2e-4] * 3, acceleration=[2e-4 / 3000.0] * 3)
    q = np.array([[-0.56, 0.4, 0.5], [0.56, 0.4, 0.5]])
    limits.check_move_durations(q, from_rest=False, to_rest=False)
    with pytest.raises(PlanningError, match="from rest within its velocity limit"):
        limits.check_move_durations(q)
    with pytest.raises(PlanningError, match="to rest within its velocity limit"):
        limits.check_move_durations(q, from_rest=False)


@pytest.mark.slow
def test_a_slow_line_is_planned():
    """About 4 min: the line takes 1.9e4 s (as b074e8a planned it), timed sample by sample."""
    plan = planner.plan_motion(get_robot("dh3"), parse_motion_request(_slow_line()), rate=0.5)
    assert plan.waypoint_times[-1] > MAX_SEGMENT_DURATION
    assert np.all(np.diff(plan.trajectory.waypoint_times) <= MAX_SEGMENT_DURATION)


def test_a_segment_too_long_even_at_rest_is_named():
    """A segment Ruckig cannot time at rest at both ends names the joint and the 7000 s limit."""
    v, a = 5e-4, 1e-7
    limits = JointLimits.from_robot(
        get_robot("dh3"), velocity=[v, 1.0, 1.0], acceleration=[a, 1.0, 1.0], jerk=[1.0, 10.0, 10.0]
    )
    q = np.zeros((3, 3))
    q[:, 0] = [-2.0, 0.1, 1.975]
    for strategy in ("stop", "heuristic", "optimized"):
        with pytest.raises(
            PlanningError,
            match=r"waypoint 0 -> waypoint 1: joint \w+ moves 2\.1, at least 9165\.15 s from rest to rest "
            r"within its velocity limit 0\.0005 and acceleration limit 1e-07; a segment can last at most 7000 s",
        ):
            plan_trajectory_request(TrajectoryRequest(q, limits, strategy=strategy))


def test_positions_too_far_from_zero_for_ruckig_are_named():
    """Where Ruckig fails on a short move far from zero (a continuous joint at 1e9 rad), the
    refusal says the positions are too coarse for its precision, not that a range was left."""
    limits = JointLimits([1.0, 1.0], [2.0, 2.0], [10.0, 10.0], [-np.inf, -np.inf], [np.inf, np.inf])
    q = np.array([[1e9, 0.0], [1e9 + 1.0, 0.5]])
    with pytest.raises(PlanningError, match=r"too coarse for Ruckig's precision 1e-08: turn continuous joints"):
        plan_trajectory_request(TrajectoryRequest(q, limits))
    # The same move near zero plans.
    assert plan_trajectory_request(TrajectoryRequest(q - [1e9, 0.0], limits)).duration > 0.0
