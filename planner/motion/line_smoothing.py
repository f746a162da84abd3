"""Smooth motion along densely sampled paths: one C2 cubic spline in time instead of a chain.

A line (a straight Cartesian line, or a straight joint-space edge of a route around
obstacles) is planned as Ruckig segments between its samples, each reaching the next sample
with the line timing's state (:mod:`planner.motion.line_timing`). Each of those segments is
time-optimal on its own: its jerk switches between +limit and -limit several times, so along a
line of 30 samples a joint's jerk changes sign a hundred times, and a servo driven by it buzzes.

:func:`smooth_lines` replaces each such stretch by the cubic spline in time through the same
samples at the same times, at rest at both ends (velocity and acceleration zero: two extra
knots, in the first and last interval, give the spline the freedom for that). A cubic spline is
twice continuously differentiable: velocity and acceleration are continuous and the jerk,
constant per interval, follows the path's own third derivative instead of switching. The
spline passes through every sample; where it would exceed a limit (velocity, acceleration,
jerk, evaluated exactly), it is slowed down by the least factor that keeps them (up to
``max_stretch``); where it would leave a joint's range, the stretch keeps its Ruckig chain.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from planner.core.arrays import read_only
from planner.motion.trajectory import LIMIT_TOLERANCE, JointTrajectory

__all__ = ["rest_to_rest_spline", "smooth_lines"]


def _knots(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The spline's knots and, per knot, the index of its sample or -1.

    The knots are the sample times plus one free knot in the first and last interval.
    """
    n = len(t)
    if n == 2:
        h = t[1] - t[0]
        return np.array([t[0], t[0] + h / 3, t[0] + 2 * h / 3, t[1]]), np.array([0, -1, -1, 1])
    knots = np.concatenate([[t[0], (t[0] + t[1]) / 2], t[1:-1], [(t[-2] + t[-1]) / 2, t[-1]]])
    sample = np.concatenate([[0, -1], np.arange(1, n - 1), [-1, n - 1]])
    return knots, sample


def rest_to_rest_spline(
    t: np.ndarray, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The C2 cubic spline through ``q[k]`` at ``t[k]``, at rest (v = a = 0) at both ends.

    Args:
        t: Increasing times, shape (N,) with N >= 2 [s].
        q: Positions, shape (N, dof).

    Returns:
        ``(knots, p, v, a, j)``: interval start times, shape (M,) (M = N + 1), and the state and
        constant jerk at each interval start, shape (M, dof); the last interval ends at t[-1].
    """
    knots, sample = _knots(np.asarray(t, dtype=float))
    m = len(knots) - 1
    h = np.diff(knots)
    size = 4 * m
    A = np.zeros((size, size))
    rhs = np.zeros((size, q.shape[1]))
    row = 0

    def put(coeffs: dict[int, float], value: np.ndarray | float = 0.0) -> None:
        nonlocal row
        for col, c in coeffs.items():
            A[row, col] = c
        rhs[row] = value
        row += 1

    # Interval i: q = c0 + c1 s + c2 s^2 + c3 s^3, s = time since its start; columns 4i..4i+3.
    put({0: 1.0}, q[0])
    put({1: 1.0})
    put({2: 1.0})
    for i in range(1, m):
        k, dt = 4 * (i - 1), h[i - 1]
        put({k: 1.0, k + 1: dt, k + 2: dt**2, k + 3: dt**3, 4 * i: -1.0})
        put({k + 1: 1.0, k + 2: 2 * dt, k + 3: 3 * dt**2, 4 * i + 1: -1.0})
        put({k + 2: 2.0, k + 3: 6 * dt, 4 * i + 2: -2.0})
        if sample[i] >= 0:
            put({4 * i: 1.0}, q[sample[i]])
    k, dt = 4 * (m - 1), h[-1]
    put({k: 1.0, k + 1: dt, k + 2: dt**2, k + 3: dt**3}, q[-1])
    put({k + 1: 1.0, k + 2: 2 * dt, k + 3: 3 * dt**2})
    put({k + 2: 2.0, k + 3: 6 * dt})
    c = np.linalg.solve(A, rhs).reshape(m, 4, -1)
    return knots[:-1], c[:, 0], c[:, 1], 2.0 * c[:, 2], 6.0 * c[:, 3]


def smooth_lines(
    trajectory: JointTrajectory, stretches: Sequence[tuple[int, int]], *, max_stretch: float = 1.25
) -> tuple[JointTrajectory, int]:
    """Replace the trajectory between waypoints ``a`` and ``b`` of each stretch by a rest-to-rest spline.

    Args:
        trajectory: A trajectory that rests at waypoints ``a`` and ``b`` of each stretch (after
            ``a``'s dwell) and passes the waypoints between them (the samples of a line).
        stretches: ``(a, b)`` waypoint index pairs, a < b, not overlapping.
        max_stretch: Where the spline at the chain's times would exceed a limit, it is slowed
            down by the factor that brings it within (everything after it moves later by the
            time added), up to this factor; beyond it the stretch keeps its chain.

    Returns:
        The trajectory with every stretch smoothed whose spline keeps every limit, and how many
        stretches were smoothed (the others keep their Ruckig chain).
    """
    traj = trajectory
    smoothed = 0
    lim = traj.limits
    finite = np.concatenate([lim.lower[np.isfinite(lim.lower)], lim.upper[np.isfinite(lim.upper)]])
    bound = max(1.0, float(np.max(np.abs(finite), initial=1.0)))
    for a, b in sorted(stretches):
        t = traj.waypoint_times[a : b + 1].copy()
        t[0] += traj.dwell[a]
        if b - a < 1 or np.any(np.diff(t) <= 0):
            continue
        q = traj.waypoints[a : b + 1]
        span = float(t[-1] - t[0])
        knots, p, v, acc, j = rest_to_rest_spline(t, q)
        alone = replace(traj, knots=knots - t[0], p=p, v=v, a=acc, j=j, duration=span)
        peaks = alone.peak_ratios(None)
        if peaks["position"] > LIMIT_TOLERANCE * bound:
            continue  # the spline bulges out of a joint's range: keep the chain
        # Slower by the factor that brings every derivative within its limit (v ~ 1/k,
        # a ~ 1/k^2, j ~ 1/k^3), if the spline's timing is tighter than the chain's.
        k = max(1.0, peaks["velocity"], peaks["acceleration"] ** 0.5, peaks["jerk"] ** (1.0 / 3.0))
        if k > max_stretch:
            continue
        if k > 1.0:
            k *= 1.0 + 1e-9
            t = t[0] + (t - t[0]) * k
            knots, p, v, acc, j = rest_to_rest_spline(t, q)
        candidate = _splice(traj, a, b, t, knots, p, v, acc, j)
        final = candidate.peak_ratios(None)
        if max(final["velocity"], final["acceleration"], final["jerk"]) > 1 + LIMIT_TOLERANCE:
            continue
        traj = candidate
        smoothed += 1
    return traj, smoothed


def _splice(
    traj: JointTrajectory,
    first: int,
    last: int,
    t: np.ndarray,
    knots: np.ndarray,
    p: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    j: np.ndarray,
) -> JointTrajectory:
    """The trajectory with the motion from waypoint `first` (after its dwell) to `last` replaced.

    The new pieces pass the waypoints in between at times `t`; what follows moves later by the
    time they add.
    """
    t0, t1 = traj.waypoint_times[first] + traj.dwell[first], traj.waypoint_times[last]
    shift = float(t[-1] - t1)
    before = traj.knots < t0 - 1e-12
    after = traj.knots >= t1 - 1e-12
    times = traj.waypoint_times.copy()
    times[first + 1 : last + 1] = t[1:]
    times[last + 1 :] += shift
    return replace(
        traj,
        knots=read_only(np.concatenate([traj.knots[before], knots, traj.knots[after] + shift])),
        p=read_only(np.concatenate([traj.p[before], p, traj.p[after]])),
        v=read_only(np.concatenate([traj.v[before], v, traj.v[after]])),
        a=read_only(np.concatenate([traj.a[before], a, traj.a[after]])),
        j=read_only(np.concatenate([traj.j[before], j, traj.j[after]])),
        duration=float(traj.duration + shift),
        waypoint_times=read_only(times),
    )
