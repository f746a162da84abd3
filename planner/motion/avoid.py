"""Moves around obstacles: straight joint-space lines and collision-free routes, ready to time.

A route from :func:`planner.collision.rrt.find_clear_path` is a polyline in joint space whose
edges are certified clear. :func:`joint_line` samples one edge densely as a
:class:`~planner.motion.line.LinePath` and :func:`time_joint_line` times it: every joint moves
in proportion, ``q(t) = q0 + s(t) (q1 - q0)``, with ``s`` one time-optimal jerk-limited profile
from rest to rest whose limits are the tightest of the joints' (``v_j / |dq_j|`` and likewise
for acceleration and jerk), which is what Ruckig's phase synchronisation does. The samples then
become via waypoints with those states, so the Ruckig chain through them stays on the edge (to
within a fraction of a millimetre, which the path search's margin covers), and the move takes
as long as the time-optimal straight move would.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from ruckig import InputParameter, Result, Ruckig, RuckigError
from ruckig import Trajectory as RuckigTrajectory

from planner.collision.checker import CollisionChecker
from planner.collision.rrt import PathOptions, PathResult, find_clear_path
from planner.core.arrays import read_only
from planner.core.text import plain
from planner.exceptions import PlanningError
from planner.model.robot import Robot
from planner.motion.limits import MAX_SEGMENT_DURATION, JointLimits, admissible_acceleration
from planner.motion.line import LinePath
from planner.motion.line_timing import LineTiming, time_line
from planner.motion.segments import SegmentSolver

__all__ = ["EDGE_SPACING", "clear_route", "joint_line", "time_joint_line"]

#: Largest joint change between two samples of a joint-space line [rad or m].
EDGE_SPACING = 0.05


def joint_line(robot: Robot, q_start: np.ndarray, q_end: np.ndarray, *, spacing: float = EDGE_SPACING) -> LinePath:
    """The straight joint-space line from `q_start` to `q_end`, sampled every `spacing` or finer."""
    q0, q1 = np.asarray(q_start, dtype=float), np.asarray(q_end, dtype=float)
    n = max(5, int(math.ceil(float(np.max(np.abs(q1 - q0))) / spacing)) + 1)
    s = np.linspace(0.0, 1.0, n)
    q = q0 + s[:, None] * (q1 - q0)
    inverse_condition, _ = robot.conditioning(q)
    return LinePath(s, q, robot.position(q), 0.0, float(np.min(inverse_condition)))


#: The share of each limit the edge profiles use, so that the chain through their samples can
#: keep every interval's time despite rounding.
_LIMIT_SHARE = 1.0 - 1e-6


#: Each time an interval's segment cannot keep its time, the profile's limits are scaled by this.
_SHRINK = 0.9
_SHRINK_ROUNDS = 12


def _proportional_states(
    q: np.ndarray, s: np.ndarray, delta: np.ndarray, moving: np.ndarray, limits: JointLimits, share: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[float, float, float]]:
    """Sample times, path speeds and joint states of the rest-to-rest profile of s using `share` of the limits."""
    m = len(q)
    dq = np.abs(delta)
    v = share * float(np.min(limits.velocity[moving] / dq[moving]))
    a = share * float(np.min(limits.acceleration[moving] / dq[moving]))
    j = share * float(np.min(limits.jerk[moving] / dq[moving]))
    otg, inp = Ruckig(1), InputParameter(1)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [0.0], [0.0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [1.0], [0.0], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v], [a], [j]
    traj = RuckigTrajectory(1)
    try:
        result = otg.calculate(inp, traj)
    except (RuckigError, ValueError):  # ValueError: a code the binding has no member for (-101)
        result = None
    if result not in (Result.Working, Result.Finished):  # rest to rest has one, up to Ruckig's 7e3 s
        raise PlanningError(
            f"the straight joint move of {plain(float(np.max(dq[moving])))} cannot be timed from rest to rest "
            f"(Ruckig plans at most {MAX_SEGMENT_DURATION:g} s): add waypoints or raise the limits"
        )
    t, sd, sdd = np.zeros(m), np.zeros(m), np.zeros(m)
    for k in range(1, m):
        local = traj.get_first_time_at_position(0, float(s[k])) if k < m - 1 else traj.duration
        t[k] = max(t[k - 1], traj.duration if local is None else local)
        _, vel, acc = traj.at_time(t[k])
        sd[k], sdd[k] = vel[0], acc[0]
    sd[-1] = sdd[-1] = 0.0
    velocity = np.clip(delta * sd[:, None], -limits.velocity, limits.velocity)
    acceleration = admissible_acceleration(velocity, delta * sdd[:, None], limits)
    velocity[0] = velocity[-1] = acceleration[0] = acceleration[-1] = 0.0
    return t, sd, velocity, acceleration, (v, a, j)


def time_joint_line(path: LinePath, limits: JointLimits) -> LineTiming:
    """Time a straight joint-space line from rest to rest, every joint in proportion.

    Args:
        path: Samples of a straight joint-space line (from :func:`joint_line`): ``path.q[k]``
            is ``q0 + path.s[k] (q1 - q0)``.
        limits: Joint limits.

    Returns:
        The sample times, joint velocities and accelerations (a
        :class:`~planner.motion.line_timing.LineTiming` with one zone).
    """
    q = np.asarray(path.q, dtype=float)
    s = np.asarray(path.s, dtype=float)
    dq = np.abs(q[-1] - q[0])
    m = len(q)
    moving = dq > 0.0
    if not moving.any():
        z, zero = read_only(np.zeros_like(q)), read_only(np.zeros(m))
        return LineTiming(zero, z, z, (0.0, 0.0, 0.0), zero, zero)
    share = _LIMIT_SHARE
    delta = q[-1] - q[0]
    for _ in range(_SHRINK_ROUNDS):
        t, sd, velocity, acceleration, lims = _proportional_states(q, s, delta, moving, limits, share)
        # The chain through the samples (plan_trajectory) must keep every interval's time and
        # range, else it would stray from the line between them: check each interval's segment.
        segments = SegmentSolver(q, limits, np.diff(t))
        ok = True
        for k in range(m - 1):
            duration, outside, _ = segments.solve(k, velocity[k], acceleration[k], velocity[k + 1], acceleration[k + 1])
            if outside is not None or duration > (t[k + 1] - t[k]) * (1.0 + 1e-6) + 1e-9:
                ok = False
                break
        if ok:
            break
        share *= _SHRINK
    else:
        return time_line(path, limits)  # the general line timing, which repairs such intervals
    v, a, j = lims
    return LineTiming(
        read_only(t),
        read_only(velocity),
        read_only(acceleration),
        (v, a, j),
        read_only(s.copy()),
        read_only(sd),
        zones=read_only(np.array([[0, m - 1]])),
        zone_limits=read_only(np.array([[v, a, j]])),
    )


def clear_route(
    checker: CollisionChecker,
    q_start: np.ndarray,
    q_end: np.ndarray,
    *,
    allow: Sequence[str] = (),
    options: PathOptions | None = None,
) -> tuple[list[LinePath], PathResult]:
    """Joint lines along a collision-free route from `q_start` to `q_end`.

    Returns:
        The lines (empty when no route was found) and the path search's result (its status
        and reason say why not).
    """
    options = options or PathOptions()
    result = find_clear_path(checker, q_start, q_end, options=options, allow=allow)
    if not result.found:
        return [], result
    return [joint_line(checker.robot, a, b) for a, b in zip(result.path, result.path[1:])], result
