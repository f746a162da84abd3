"""Timing of a straight Cartesian line's joint samples within the joint limits.

:func:`time_line` times the samples of a :class:`planner.motion.line.LinePath`: a path
parameter follows a jerk-limited profile whose speed limit varies along the line, so that no
joint exceeds its speed, acceleration or jerk limit; near a singularity the joints must move
far for a short stretch of line, so the tip slows down there (and only there) instead of asking
for unbounded joint speed. Every interval is checked with the joint-space Ruckig segment the
planner will chain there (:class:`planner.motion.segments.SegmentSolver`). The samples then
become via waypoints of the Ruckig chain (:func:`line_trajectory`) with the timing's states.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from ruckig import InputParameter, Result, Ruckig, RuckigError
from ruckig import Trajectory as RuckigTrajectory

from planner.core.arrays import read_only
from planner.exceptions import InvalidArgumentError
from planner.motion.limits import JointLimits, admissible_acceleration
from planner.motion.line import LinePath
from planner.motion.plan import plan_trajectory
from planner.motion.segments import SegmentSolver
from planner.motion.trajectory import JointTrajectory

__all__ = ["LineTiming", "line_trajectory", "time_line"]


@dataclass(frozen=True)
class LineTiming:
    """When and how fast a line's samples are passed (start and end at rest).

    Attributes:
        t: Time at each sample, shape (M,) [s], from 0.
        velocity: Joint velocities there, shape (M, dof).
        acceleration: Joint accelerations there, shape (M, dof).
        path_limits: The loosest path-parameter limits ``(v, a, j)`` of any zone [1/s, 1/s^2,
            1/s^3] (see :func:`time_line`).
        sigma: The path parameter at each sample, shape (M,), 0 first and 1 last; it advances
            with the speed-normalised joint motion.
        path_velocity: d sigma / dt at each sample, shape (M,) [1/s].
        speed_limit: The path speed above which some joint would exceed its speed,
            acceleration or jerk limit near each sample even at constant path speed, shape (M,)
            [1/s]: the least over the joints of ``v / |dq/dsigma|``, ``sqrt(a / |d2q/dsigma2|)``
            and ``cbrt(j / |d3q/dsigma3|)``.
        tip_speed: Speed of the tip along the line at each sample, shape (M,) [m/s].
        zones: First and last sample of each stretch timed with one set of path limits, shape
            (Z, 2); a single zone spanning the line for a uniform profile.
        zone_limits: The path limits ``(v, a, j)`` of each zone, shape (Z, 3).
    """

    t: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    path_limits: tuple[float, float, float]
    sigma: np.ndarray | None = None
    path_velocity: np.ndarray | None = None
    speed_limit: np.ndarray | None = None
    tip_speed: np.ndarray | None = None
    zones: np.ndarray | None = None
    zone_limits: np.ndarray | None = None


def _local_cubic_derivatives(x: np.ndarray, y: np.ndarray, half: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First three derivatives of y(x) from least-squares cubics over 2*half+1 neighbours.

    Plain finite differences of bisected, unevenly spaced IK samples are too noisy for second
    and third derivatives; a local cubic fit smooths them.
    """
    n = len(x)
    d1, d2, d3 = np.empty_like(y), np.empty_like(y), np.empty_like(y)
    for k in range(n):
        lo, hi = max(0, k - half), min(n, k + half + 1)
        if hi - lo < 4:
            lo, hi = max(0, min(lo, n - 4)), min(n, max(hi, lo + 4))
        h = x[lo:hi] - x[k]
        sc = max(float(np.max(np.abs(h))), 1e-12)
        deg = min(3, hi - lo - 1)
        coef, *_ = np.linalg.lstsq(np.vander(h / sc, deg + 1, increasing=True), y[lo:hi], rcond=None)
        coef = np.vstack([coef, np.zeros((4 - len(coef), y.shape[1]))])
        d1[k], d2[k], d3[k] = coef[1] / sc, 2 * coef[2] / sc**2, 6 * coef[3] / sc**3
    return d1, d2, d3


# Path-speed levels: neighbouring sample intervals whose speed limits lie within the same
# factor-of-_ZONE_RATIO band share one set of path limits.
_ZONE_RATIO = 1.5
# Fractions of the speed limit, and of the acceleration room left at that speed, tried for the
# path limits (one pair for all zones; the fastest plan wins).
_SPEED_FRACTIONS = (1.0, 0.95, 0.85, 0.75, 0.65, 0.55, 0.45, 0.35, 0.25, 0.15, 0.08, 0.04, 0.02, 0.01)
_ACCEL_FRACTIONS = (1.0, 0.9, 0.7, 0.5, 0.3)
# A zone whose joint motion cannot keep its planned timing gets its speed scaled by this.
_SHRINK = 0.9
_SHRINK_ROUNDS = 60


def _interval_bounds(d: np.ndarray) -> np.ndarray:
    """Largest |derivative| per joint over each sample interval and one sample either side, (M-1, dof)."""
    a = np.abs(d)
    lo = np.vstack([a[:1], a[:-1]])  # sample i-1 (clamped)
    hi = np.vstack([a[1:], a[-1:]])  # sample i+1 (clamped)
    per_sample = np.maximum(np.maximum(lo, hi), a)
    return np.maximum(per_sample[:-1], per_sample[1:])


def _speed_caps(b1: np.ndarray, b2: np.ndarray, b3: np.ndarray, limits: JointLimits) -> np.ndarray:
    """Path speed limits from derivative bounds (..., dof): velocity, curvature and jerk terms."""
    tiny = 1e-300
    caps = np.minimum(
        np.minimum(limits.velocity / np.maximum(b1, tiny), np.sqrt(limits.acceleration / np.maximum(b2, tiny))),
        np.cbrt(limits.jerk / np.maximum(b3, tiny)),
    )
    return np.min(caps, axis=-1)


def _zone_limits(
    bounds: tuple[np.ndarray, np.ndarray, np.ndarray], limits: JointLimits, speed: float, accel: float
) -> tuple[float, float, float] | None:
    """Path limits (v, a, j) that keep every joint within its limits, or None.

    With |q'| <= B1, |q''| <= B2, |q'''| <= B3 over the zone (derivatives by the path
    parameter), qd = q' sd, qdd = q' sdd + q'' sd^2 and qddd = q' sddd + 3 q'' sd sdd + q''' sd^3
    stay within v, a and j if B1 v <= v_max, B1 a + B2 v^2 <= a_max and
    B1 j + 3 B2 v a + B3 v^3 <= j_max. `speed` is the fraction of the speed cap used, `accel`
    the fraction of the acceleration room left at that speed.
    """
    b1, b2, b3 = bounds
    b1 = np.maximum(b1, 1e-12)
    v = speed * float(_speed_caps(b1, b2, b3, limits))
    a_room = float(np.min((limits.acceleration - b2 * v * v) / b1))
    if not (v > 0 and a_room > 0):
        return None
    a = accel * a_room
    j = float(np.min((limits.jerk - b3 * v**3 - 3.0 * b2 * v * a) / b1))
    if not j > 0:
        return None
    return v, a, j


def _reach(w0: float, dist: float, a: float, j: float, v: float) -> float:
    """Highest speed (at most v) reachable from speed w0 within distance dist, at zero acceleration.

    The speed change is a jerk-limited S-curve starting and ending at zero acceleration: a
    change ``dw >= a^2 / j`` takes ``dw / a + a / j``, a smaller one ``2 sqrt(dw / j)``; the
    distance is the mean speed times that time.
    """
    if dist <= 0.0:
        return w0
    # Small change: x^3 + 2 w0 x - dist sqrt(j) = 0 with x = sqrt(dw) (Cardano, one real root).
    p, qq = 2.0 * w0, -dist * math.sqrt(j)
    root = math.sqrt(qq * qq / 4.0 + p**3 / 27.0)
    x = float(np.cbrt(-qq / 2.0 + root) + np.cbrt(-qq / 2.0 - root))
    dw = x * x
    if dw > a * a / j:
        # (2 w0 + dw)(dw / a + a / j) = 2 dist: a quadratic in dw.
        qa, qb, qc = 1.0 / a, a / j + 2.0 * w0 / a, 2.0 * w0 * a / j - 2.0 * dist
        dw = (-qb + math.sqrt(qb * qb - 4.0 * qa * qc)) / (2.0 * qa)
    return min(v, w0 + dw * (1.0 - 1e-9))


def _zone_profiles(
    sigma: np.ndarray, zones: list[tuple[int, int]], lims: list[tuple[float, float, float]]
) -> tuple[float, list] | None:
    """Jerk-limited profile of the path parameter, one Ruckig segment per zone.

    Each zone is entered and left at zero path acceleration, at the highest speed both zones
    allow that can still be reached from the previous boundary and braked to the next one
    (forward and backward passes). Returns the duration and the Ruckig trajectories.
    """
    n = len(zones)
    w = np.zeros(n + 1)
    for b in range(1, n):
        w[b] = min(lims[b - 1][0], lims[b][0])
    for b in range(1, n + 1):
        (s, e), (v, a, j) = zones[b - 1], lims[b - 1]
        w[b] = min(w[b], _reach(w[b - 1], sigma[e] - sigma[s], a, j, v))
    w[n] = 0.0
    for b in range(n - 1, -1, -1):
        (s, e), (v, a, j) = zones[b], lims[b]
        w[b] = min(w[b], _reach(w[b + 1], sigma[e] - sigma[s], a, j, v))
    otg, inp = Ruckig(1), InputParameter(1)
    total, trajs = 0.0, []
    for b, ((s, e), (v, a, j)) in enumerate(zip(zones, lims)):
        inp.current_position, inp.current_velocity, inp.current_acceleration = [sigma[s]], [w[b]], [0.0]
        inp.target_position, inp.target_velocity, inp.target_acceleration = [sigma[e]], [w[b + 1]], [0.0]
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v], [a], [j]
        traj = RuckigTrajectory(1)
        try:
            result = otg.calculate(inp, traj)
        except (RuckigError, ValueError):  # ValueError: a code the binding has no member for (-101: > 7e3 s)
            return None
        if result not in (Result.Working, Result.Finished):  # pragma: no cover - passes fit
            return None
        total += traj.duration
        trajs.append(traj)
    return total, trajs


def _sample_profile(
    sigma: np.ndarray, zones: list[tuple[int, int]], trajs: list
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time, path speed and path acceleration at every sample, shapes (M,)."""
    m = len(sigma)
    t, sd, sdd = np.zeros(m), np.zeros(m), np.zeros(m)
    t0 = 0.0
    for (s, e), traj in zip(zones, trajs):
        for k in range(s + 1, e + 1):
            local = traj.get_first_time_at_position(0, float(sigma[k])) if k < e else traj.duration
            local = t[k - 1] - t0 if local is None else max(local, t[k - 1] - t0)
            t[k] = t0 + local
            _, vel, acc = traj.at_time(local)
            sd[k], sdd[k] = vel[0], acc[0]
        t0 += traj.duration
    sd[-1] = sdd[-1] = 0.0
    return t, sd, sdd


def _joint_states(
    d1: np.ndarray, d2: np.ndarray, sd: np.ndarray, sdd: np.ndarray, limits: JointLimits
) -> tuple[np.ndarray, np.ndarray]:
    """Joint velocities and accelerations from the path states, within what a via may hold.

    The acceleration is limited as :func:`planner.motion.plan.plan_trajectory` limits a given
    via acceleration (:func:`planner.motion.limits.admissible_acceleration`), so that the
    states checked here are the ones it will chain.
    """
    vel = np.clip(d1 * sd[:, None], -limits.velocity, limits.velocity)
    acc = admissible_acceleration(vel, d2 * (sd * sd)[:, None] + d1 * sdd[:, None], limits)
    vel[0] = vel[-1] = acc[0] = acc[-1] = 0.0
    return vel, acc


def _check_intervals(
    q: np.ndarray, t: np.ndarray, vel: np.ndarray, acc: np.ndarray, limits: JointLimits
) -> tuple[list[int], np.ndarray]:
    """Check every sample interval with the joint-space Ruckig segment chained through it.

    These are the segments :func:`planner.motion.plan.plan_trajectory` chains through the
    samples. Where one cannot keep the planned duration, the joints would fall behind the
    line's timing (and stray from the line between the samples): the path limits there were
    too optimistic. Where one leaves a joint's range (by Ruckig's extrema), the chain would
    lower that joint's via states, with the same effect.

    Returns:
        The lagging intervals, and per interval the joints that leave their range, (M-1, dof) bool.
    """
    m, dof = q.shape
    planned = np.diff(t)
    segments = SegmentSolver(q, limits, planned)
    lagging, outside = [], np.zeros((m - 1, dof), dtype=bool)
    for k in range(m - 1):
        duration, bad, _ = segments.solve(k, vel[k], acc[k], vel[k + 1], acc[k + 1])
        if duration > planned[k] * (1.0 + 1e-6) + 1e-9:  # inf when Ruckig finds no profile
            lagging.append(k)
        if bad is not None:
            outside[k] = bad
    return lagging, outside


def _time_zones(
    q: np.ndarray,
    sigma: np.ndarray,
    derivs: tuple[np.ndarray, np.ndarray, np.ndarray],
    bounds: tuple[np.ndarray, np.ndarray, np.ndarray],
    zones: list[tuple[int, int]],
    limits: JointLimits,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[tuple[float, float, float]], bool]:
    """Time the samples with one set of path limits per zone, checked against the joints.

    Returns:
        Sample times, path speeds, joint velocities and accelerations at the samples, the zone
        limits, and whether every interval keeps its time in joint space.
    """
    zb = [tuple(b[s:e].max(axis=0) for b in bounds) for s, e in zones]
    best = None
    for speed in _SPEED_FRACTIONS:
        for accel in _ACCEL_FRACTIONS:
            lims = [_zone_limits(b, limits, speed, accel) for b in zb]
            if any(lim is None for lim in lims):
                continue
            prof = _zone_profiles(sigma, zones, lims)
            if prof is not None and (best is None or prof[0] < best[0]):
                best = (prof[0], prof[1], lims, speed, accel)
        if best is not None and speed < 0.5:
            break  # slower fractions matter only when nothing faster fits
    if best is None:  # pragma: no cover - the smallest fractions always fit
        raise InvalidArgumentError("cannot time the line within the joint limits")
    _, trajs, lims, speed, accel = best
    scale = np.ones(len(zones))
    ends = np.array([e for _, e in zones])
    at_rest = np.zeros(q.shape, dtype=bool)
    for round_ in range(_SHRINK_ROUNDS + 1):
        t, sd, sdd = _sample_profile(sigma, zones, trajs)
        vel, acc = _joint_states(derivs[0], derivs[1], sd, sdd, limits)
        vel[at_rest], acc[at_rest] = 0.0, 0.0
        lagging, outside = _check_intervals(q, t, vel, acc, limits)
        if round_ == _SHRINK_ROUNDS or not (lagging or outside.any()):
            break
        # A joint carried out of its range passes those samples at rest (as the chain's range
        # repair would make it), and the timing is checked again with that.
        at_rest[:-1] |= outside
        at_rest[1:] |= outside
        if not lagging:
            continue
        if round_ < _SHRINK_ROUNDS // 2:
            for z in set(np.searchsorted(ends, lagging, side="right").tolist()):
                scale[min(z, len(zones) - 1)] *= _SHRINK
        else:  # the lag persists: slow every zone
            scale *= _SHRINK
        new = [_zone_limits(b, limits, speed * sc, accel) for b, sc in zip(zb, scale)]
        prof = None if any(lim is None for lim in new) else _zone_profiles(sigma, zones, new)
        if prof is None:  # pragma: no cover - smaller path limits always fit
            break
        lims, trajs = new, prof[1]
    return t, sd, vel, acc, lims, not (lagging or outside.any())


def time_line(path: LinePath, limits: JointLimits, *, local: bool = True) -> LineTiming:
    """Time a line's joint path within the joints' speed, acceleration and jerk limits.

    The path is re-parametrised by sigma in [0, 1], advancing in proportion to the
    speed-normalised joint motion ``|dq / v_max|`` of each step, and the derivatives of
    q(sigma) are estimated at every sample from local cubic fits. Near a singularity the joints
    move far per metre, so sigma advances quickly per metre and the tip slows down; the joint
    path also bends sharply there, which limits the path speed through the joints'
    acceleration and jerk. The path speed limit therefore varies along the line
    (:attr:`LineTiming.speed_limit`).

    With `local` (the default), sample intervals are grouped into zones of similar speed limit
    (within a factor 1.5), each with its own path limits ``(v, a, j)`` that keep every joint's
    velocity, acceleration and jerk within its limits there; sigma follows one time-optimal,
    jerk-limited Ruckig profile per zone, entering and leaving each zone at zero path
    acceleration and at the highest speed both zones allow that can still be reached and
    braked in time (forward and backward passes). So the tip moves fast where it can and slows
    down only near the singularity. Without `local`, one set of path limits, set by the worst
    stretch, covers the whole line (a uniform profile).

    Every interval between samples is then checked with the joint-space Ruckig segment that
    :func:`planner.motion.plan.plan_trajectory` will chain there (the samples become via
    waypoints with these states): where one cannot keep its planned time, the derivative
    estimates were too optimistic, so that zone's path limits are lowered and the line is
    re-timed. The local timing is compared with the uniform one and the faster of those that
    keep their times is returned.

    Args:
        path: Joint samples of the line.
        limits: Joint limits.
        local: Path limits per zone (True) or one set for the whole line (False).

    Returns:
        Times and joint states at the samples.
    """
    q = np.asarray(path.q)
    m = len(q)
    steps = np.linalg.norm(np.diff(q, axis=0) / limits.velocity, axis=1)
    total = float(steps.sum())
    if total <= 0.0:
        z, zero = read_only(np.zeros_like(q)), read_only(np.zeros(m))
        return LineTiming(
            zero,
            z,
            z,
            (0.0, 0.0, 0.0),
            zero,
            zero,
            zero,
            zero,
            read_only(np.array([[0, m - 1]])),
            read_only(np.zeros((1, 3))),
        )
    sigma = np.concatenate([[0.0], np.cumsum(steps)]) / total
    sigma[-1] = 1.0
    d1, d2, d3 = _local_cubic_derivatives(sigma, q)
    # A joint lying on a range end there is at an extremum of the path (IK keeps it inside):
    # its velocity and acceleration are zero, whatever the fit across the end gives.
    near = [1e-9 * np.maximum(1.0, np.abs(np.nan_to_num(b))) for b in (limits.lower, limits.upper)]
    on_end = (q <= limits.lower + near[0]) | (q >= limits.upper - near[1])
    d1, d2 = np.where(on_end, 0.0, d1), np.where(on_end, 0.0, d2)
    derivs = (d1, d2, d3)
    bounds = tuple(_interval_bounds(d) for d in derivs)
    candidates = [[(0, m - 1)]]
    if local:
        caps = np.clip(_speed_caps(*bounds, limits), 1e-12, 1e12)
        level = np.floor(np.log(caps) / math.log(_ZONE_RATIO)).astype(int)
        starts = [0] + [i for i in range(1, m - 1) if level[i] != level[i - 1]]
        if len(starts) > 1:
            candidates.insert(0, list(zip(starts, starts[1:] + [m - 1])))
    best = None
    for zones in candidates:
        t, sd, vel, acc, lims, consistent = _time_zones(q, sigma, derivs, bounds, zones, limits)
        key = (not consistent, float(t[-1]))
        if best is None or key < best[0]:
            best = (key, t, sd, vel, acc, lims, zones)
    _, t, sd, vel, acc, lims, zones = best
    tip = np.linalg.norm(_local_cubic_derivatives(sigma, np.asarray(path.points))[0], axis=1) * sd
    zone_limits = np.array(lims)
    return LineTiming(
        read_only(t),
        read_only(vel),
        read_only(acc),
        tuple(float(x) for x in zone_limits.max(axis=0)),
        read_only(sigma),
        read_only(sd),
        read_only(_speed_caps(*(np.abs(d) for d in derivs), limits)),
        read_only(tip),
        read_only(np.array(zones)),
        read_only(zone_limits),
    )


def line_trajectory(path: LinePath, limits: JointLimits, timing: LineTiming | None = None) -> JointTrajectory:
    """The joint trajectory along a line: Ruckig segments through its samples, at rest at both ends.

    Every sample is a via waypoint with the timing's joint velocity and acceleration, and each
    segment lasts at least the timing's interval (as :func:`planner.app.motion_plan.plan_motion`
    chains a line), so the result passes every sample exactly, within every joint limit.

    Args:
        path: Joint samples of the line.
        limits: Joint limits.
        timing: The line's timing; None is ``time_line(path, limits)``.

    Returns:
        The trajectory; its ``waypoint_times`` are the timing's sample times when the joints can
        keep them (:func:`time_line` checks that they can).
    """
    if timing is None:
        timing = time_line(path, limits)
    m = len(path.q)
    return plan_trajectory(
        path.q,
        limits,
        stops=[0, m - 1],
        via_velocities=timing.velocity,
        via_accelerations=timing.acceleration,
        min_durations=np.diff(timing.t),
    )
