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
``max_stretch``). A line running along a joint limit has samples exactly at it, and the spline
through them rings slightly beyond: those inner samples are moved inward by twice the excess
(at most :data:`MAX_NUDGE`); if that does not keep the range, the stretch keeps its Ruckig chain.
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

    Solved for the second derivatives at the knots (a tridiagonal system, linear in the number
    of samples): the positions at the two free knots follow from the zero end slopes.

    Args:
        t: Increasing times, shape (N,) with N >= 2 [s].
        q: Positions, shape (N, dof).

    Returns:
        ``(knots, p, v, a, j)``: interval start times, shape (M,) (M = N + 1), and the state and
        constant jerk at each interval start, shape (M, dof); the last interval ends at t[-1].
    """
    x, sample = _knots(np.asarray(t, dtype=float))
    q = np.asarray(q, dtype=float)
    m = len(x) - 1
    h = np.diff(x)
    y = np.zeros((m + 1, q.shape[1]))
    known = sample >= 0
    y[known] = q[sample[known]]
    # The free knots 1 and m-1 take the end positions for now; their dependence on M moves left.
    y[1], y[m - 1] = q[0], q[-1]
    free = {1: h[0] ** 2 / 6.0, m - 1: h[m - 1] ** 2 / 6.0}  # y_f = y_end + alpha_f * M_f
    # Rows i = 1..m-1: h_{i-1} M_{i-1} + 2 (h_{i-1} + h_i) M_i + h_i M_{i+1} = r_i (M_0 = M_m = 0).
    rows = np.arange(1, m)
    sub, sup = h[rows - 1].copy(), h[rows].copy()
    diag = 2.0 * (h[rows - 1] + h[rows])
    rhs = 6.0 * ((y[rows + 1] - y[rows]) / h[rows, None] - (y[rows] - y[rows - 1]) / h[rows - 1, None])
    for f, alpha in free.items():
        for i in (f - 1, f, f + 1):
            if not 1 <= i <= m - 1:
                continue
            if f == i:
                kappa = -6.0 / h[i] - 6.0 / h[i - 1]
            elif f == i + 1:
                kappa = 6.0 / h[i]
            else:
                kappa = 6.0 / h[i - 1]
            k = i - 1  # row index
            if f == i:
                diag[k] -= kappa * alpha
            elif f == i + 1:
                sup[k] -= kappa * alpha
            else:
                sub[k] -= kappa * alpha
    # Thomas algorithm, all joints at once.
    n = m - 1
    cp = np.zeros(n)
    dp = np.zeros_like(rhs)
    cp[0] = sup[0] / diag[0]
    dp[0] = rhs[0] / diag[0]
    for k in range(1, n):
        den = diag[k] - sub[k] * cp[k - 1]
        cp[k] = sup[k] / den
        dp[k] = (rhs[k] - sub[k] * dp[k - 1]) / den
    moments = np.zeros((m + 1, q.shape[1]))
    moments[n] = dp[n - 1]
    for k in range(n - 2, -1, -1):
        dp[k] -= cp[k] * dp[k + 1]
    moments[1:m] = dp
    for f, alpha in free.items():
        y[f] += alpha * moments[f]
    v = (y[1:] - y[:-1]) / h[:, None] - h[:, None] * (2.0 * moments[:-1] + moments[1:]) / 6.0
    jerk = (moments[1:] - moments[:-1]) / h[:, None]
    return x[:-1], y[:-1], v, moments[:-1], jerk


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
        q = np.array(traj.waypoints[a : b + 1], dtype=float)
        span = float(t[-1] - t[0])
        for _ in range(4):
            knots, p, v, acc, j = rest_to_rest_spline(t, q)
            alone = replace(traj, knots=knots - t[0], p=p, v=v, a=acc, j=j, duration=span)
            peaks = alone.peak_ratios(None)
            if peaks["position"] <= LIMIT_TOLERANCE * bound or not _nudge(q, alone, lim.lower, lim.upper):
                break
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
            # Only the new piece can break a limit: the rest of the trajectory just moves later.
            alone = replace(traj, knots=knots - t[0], p=p, v=v, a=acc, j=j, duration=float(t[-1] - t[0]))
            peaks = alone.peak_ratios(None)
        if max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) > 1 + LIMIT_TOLERANCE:
            continue
        traj = _splice(traj, a, b, t, q, knots, p, v, acc, j)
        smoothed += 1
    return traj, smoothed


#: Largest move of a line's inner sample off a joint bound the spline may make [rad or m].
MAX_NUDGE = 1e-3


def _nudge(q: np.ndarray, spline: JointTrajectory, lower: np.ndarray, upper: np.ndarray) -> bool:
    """Move inner samples that sit at a joint bound inward by twice the spline's excess there.

    A line running along a joint limit has samples exactly at it; the spline through them rings
    a little beyond. Returns whether a sample was moved (never by more than :data:`MAX_NUDGE`).
    """
    s = spline.sample(np.linspace(0.0, spline.duration, 40 * len(q)))
    below = np.maximum(lower - s.q.min(axis=0), 0.0)
    above = np.maximum(s.q.max(axis=0) - upper, 0.0)
    moved = False
    for d in range(q.shape[1]):
        for excess, bound, sign in ((below[d], lower[d], 1.0), (above[d], upper[d], -1.0)):
            if not excess > 0 or not np.isfinite(bound):
                continue
            step = 2.0 * excess
            near = np.nonzero(np.abs(q[1:-1, d] - bound) <= step)[0] + 1
            if not near.size or step > MAX_NUDGE:
                continue
            q[near, d] = bound + sign * step
            moved = True
    return moved


def _splice(
    traj: JointTrajectory,
    first: int,
    last: int,
    t: np.ndarray,
    q: np.ndarray,
    knots: np.ndarray,
    p: np.ndarray,
    v: np.ndarray,
    a: np.ndarray,
    j: np.ndarray,
) -> JointTrajectory:
    """The trajectory with the motion from waypoint `first` (after its dwell) to `last` replaced.

    The new pieces pass the waypoints in between at times `t` and positions `q` (inner samples
    may have been nudged off a joint bound); what follows moves later by the time they add.
    """
    t0, t1 = traj.waypoint_times[first] + traj.dwell[first], traj.waypoint_times[last]
    shift = float(t[-1] - t1)
    before = traj.knots < t0 - 1e-12
    after = traj.knots >= t1 - 1e-12
    times = traj.waypoint_times.copy()
    times[first + 1 : last + 1] = t[1:]
    waypoints = traj.waypoints.copy()
    waypoints[first : last + 1] = q
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
        waypoints=read_only(waypoints),
    )
