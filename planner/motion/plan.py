"""Smooth, jerk-limited joint trajectories through waypoints, chained from Ruckig segments.

The community edition of Ruckig computes time-optimal state-to-state motions (position,
velocity and acceleration at both ends) under velocity, acceleration and jerk limits, but it
has no intermediate waypoints (``intermediate_positions`` calls a cloud service) and no
position limits. This module (:func:`plan_trajectory`) chains one Ruckig segment per pair of consecutive waypoints,
time-synchronised so that every joint reaches the next waypoint at the same instant, and
chooses the state (velocity and acceleration) at every via waypoint itself:

1. **Spline-like via states.** From the current segment durations T1, T2 and the slopes
   s1 = dq1 / T1, s2 = dq2 / T2 of the two neighbouring segments, each joint gets the slope
   blend ``(s1 T2 + s2 T1) / (T1 + T2)`` (what a cubic spline through the waypoint times has
   there) as its via velocity and the acceleration ``2 (s2 - s1) / (T1 + T2)``, both within
   the joint's limits (the ``"heuristic"`` strategy stops here).
2. **A joint choice, then a search per via waypoint.** All via states between two fixed
   waypoints are then chosen together: the C2 cubic spline through the waypoints at the
   segment durations gives every via a velocity and an acceleration consistent with all the
   others (a joint with time to spare may pass its waypoint still moving and turn just
   beyond it, as a spline does); a segment lasts as long as its slowest joint needs and each
   joint's time depends on its own states only, so every joint takes, along the whole run,
   the spline of the time scale of the durations that makes the run fastest (one
   unsynchronised Ruckig probe times every option). Then each via is refined on its own:
   scaling time by 1/x multiplies velocities by x and accelerations by x^2, so candidates
   ``(x v, x^2 a)`` of the slope blend (each joint saturating at its limits) on a grid, the
   velocity moved a little either way, or a time-optimal turn where a joint reverses at the
   waypoint (at rest, still braking at full deceleration) are every joint's options, and each
   joint takes its best (see :mod:`planner.motion.vias.optimized`). Each search keeps the
   current state unless a candidate is faster; resting at the via (scale 0) is on the grid.
3. **Range repair.** A non-zero via state can carry a joint past its range inside a segment.
   The search discards such candidates (halving the offending joints' via state), and every
   final segment is checked exactly: the per-joint extrema of its constant-jerk pieces
   (:func:`planner.motion.segments.segment_position_range`: Ruckig's own ``position_extrema``
   plus the turning points inside constant-acceleration phases that they miss). Where one
   lies outside the range, that joint's via
   state at the segment's ends is halved until it fits (after six halvings it is set to
   rest). Samples are never clipped: a joint at rest at both ends of a segment moves
   monotonically, so the repair ends inside the range.
   A given start state that would run a joint out of range first brakes every joint as hard
   as it can (each on its own), or is rejected if even that leaves the range.

The result, :class:`JointTrajectory`, is piecewise cubic (constant jerk per piece). It passes
exactly through every waypoint at :attr:`JointTrajectory.waypoint_times` (the sampled state
there is the waypoint, bit for bit) and stays within every limit at every instant, up to the
floating-point rounding bounded by :data:`LIMIT_TOLERANCE`. The ``"stop"`` strategy (rest at
every waypoint) is the baseline it is compared with.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from itertools import accumulate
from operator import gt, lt

import numpy as np

from planner.core.arrays import read_only
from planner.core.text import plain
from planner.exceptions import InvalidArgumentError, PlanningError
from planner.motion.checks import waypoint_rows_within
from planner.motion.limits import MAX_SEGMENT_DURATION, JointLimits, reach_time
from planner.motion.request import TrajectoryRequest
from planner.motion.segments import (
    RUCKIG_PRECISION,
    SegmentPieces,
    brake_segment,
    merge_segment,
    rest_to_rest_segments,
    rest_to_rest_trajectory,
    segment_position_range,
    speed_overshoots,
)
from planner.motion.trajectory import JointTrajectory
from planner.motion.vias import VIA_STRATEGIES, StopStrategy, ViaChain, ViaStrategy, via_strategy

__all__ = ["plan_trajectory", "plan_trajectory_request"]

_REPAIR_HALVINGS = 24
#: The registered via strategies' types (see :data:`planner.motion.vias.VIA_STRATEGIES`).
_REGISTERED = frozenset(VIA_STRATEGIES.values())
_REPAIR_HALVINGS_BEFORE_REST = 6


class _StartOvershoot(Exception):
    """The given start state runs a joint out of its range in the first segment (caught by the planner)."""


def _rest_to_rest(d: np.ndarray, v: np.ndarray, a: np.ndarray, jerk: np.ndarray) -> np.ndarray:
    """The least time [s] a joint needs to move `d` from rest to rest within its velocity, acceleration and jerk limits.

    The time-optimal profile (Ruckig's for one joint): where the move reaches the velocity limit,
    ``d / v`` plus the ramp to it (``v / a + a / j`` where the ramp reaches the acceleration
    limit, ``v j >= a^2``, else ``2 sqrt(v / j)``); else, with a peak velocity below ``v``,
    ``a / j + sqrt(a^2 / j^2 + 4 d / a)`` where it reaches the acceleration limit
    (``d >= 2 a^3 / j^2``), else ``4 (d / 2 j)^(1/3)``. inf where a term overflows.
    """
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        ramp = np.where(v * jerk >= a * a, v / a + a / jerk, 2.0 * np.sqrt(v / jerk))
        below = np.where(
            d >= 2.0 * a**3 / jerk**2,
            a / jerk + np.sqrt((a / jerk) ** 2 + 4.0 * d / a),
            4.0 * np.cbrt(d / (2.0 * jerk)),
        )
        need = np.where(d >= v * ramp, d / v + ramp, below)
    return np.where(np.isnan(need), np.inf, need)


def _no_profile(chain: ViaChain, k: int) -> PlanningError:
    """The error for segment `k`, which Ruckig cannot time even at rest at its free ends.

    Names the joint that needs longest from rest to rest (:func:`_rest_to_rest`; at least twice
    :func:`~planner.motion.limits.reach_time` of half its move, more with the jerk limit) where
    that exceeds
    :data:`~planner.motion.limits.MAX_SEGMENT_DURATION`; else Ruckig's failure as it is.
    """
    limits = chain.limits
    d = np.abs(chain.q[k + 1] - chain.q[k])
    v, a = limits.velocity, limits.acceleration
    # Without the jerk limit: twice the least time to cover half the move from rest.
    without_jerk = np.array([2.0 * reach_time(x / 2.0, y, z) for x, y, z in zip(d.tolist(), v.tolist(), a.tolist())])
    need = np.fmax(without_jerk, _rest_to_rest(d, v, a, limits.jerk))
    j = int(np.argmax(need))
    where = f"waypoint {k} -> waypoint {k + 1}"
    start = " from the given start state" if k == 0 and (chain.v[0].any() or chain.acc[0].any()) else ""
    if need[j] > MAX_SEGMENT_DURATION:
        # The jerk limit is named where it is what makes the move too long.
        by = (
            f"its velocity limit {plain(float(v[j]))} and acceleration limit {plain(float(a[j]))}"
            if without_jerk[j] > MAX_SEGMENT_DURATION
            else f"its velocity limit {plain(float(v[j]))}, acceleration limit {plain(float(a[j]))} and jerk "
            f"limit {plain(float(limits.jerk[j]))}"
        )
        return PlanningError(
            f"{where}: joint {limits.joint_names[j]} moves {plain(float(d[j]))}, at least {float(need[j]):.6g} s "
            f"from rest to rest within {by}; a segment can last at most {MAX_SEGMENT_DURATION:g} s (Ruckig's "
            "limit): add waypoints between them or raise the limits"
        )
    largest = float(np.max(np.abs(chain.q[k : k + 2])))
    hint = "check the waypoints and limits"
    if np.spacing(largest) > 0.1 * RUCKIG_PRECISION[0]:
        hint = (
            f"positions this far from zero are spaced {np.spacing(largest):.3g} apart, too coarse for Ruckig's "
            f"precision {RUCKIG_PRECISION[0]:g}: turn continuous joints' waypoints by whole turns nearer zero"
        )
    return PlanningError(
        f"{where}: Ruckig found no jerk-limited profile{start} with the arm at rest at waypoint {k + 1} "
        f"(largest position {plain(largest)}); {hint}"
    )


def _repair_range(chain: ViaChain) -> list[tuple[float, SegmentPieces]]:
    """Lower via velocities until no segment carries a joint outside its range or beyond its speed.

    Every segment is checked exactly (:func:`planner.motion.segments.segment_position_range`);
    where a joint leaves its range, or Ruckig's profile takes it beyond its speed limit
    (:func:`planner.motion.segments.speed_overshoots`), its via state at the segment's free ends
    is halved (after a few halvings set to rest) and the chain is solved again. Sets
    ``chain.repaired``.

    Args:
        chain: The chain with its chosen via states (changed in place).

    Returns:
        Per segment: its duration and its pieces.

    Raises:
        _StartOvershoot: If the given start state itself carries a joint out of its range.
    """
    before_v, before_acc = chain.v.copy(), chain.acc.copy()
    halved = np.zeros(chain.v.shape, dtype=int)
    # Row views (live: every change below is in place) and the range bounds as floats.
    q_rows, v_rows, acc_rows = list(chain.q), list(chain.v), list(chain.acc)
    limits = chain.limits
    lows, highs = limits.checked_floats
    for _ in range(4 * _REPAIR_HALVINGS + chain.n):
        segments, any_bad = [], False
        for k in range(chain.n - 1):
            start = (q_rows[k], v_rows[k], acc_rows[k])
            d, outside, traj = chain.seg.solve(k, v_rows[k], acc_rows[k], v_rows[k + 1], acc_rows[k + 1], keep=True)
            if traj is None:
                # Ruckig found no profile: rest at the ends of this segment (the start's state
                # is given), or refuse where they are at rest already.
                moving_ends = [idx for idx in (k, k + 1) if idx > 0 and (v_rows[idx].any() or acc_rows[idx].any())]
                if not moving_ends:
                    raise _no_profile(chain, k)
                for idx in moving_ends:
                    chain.v[idx] = 0.0
                    chain.acc[idx] = 0.0
                any_bad = True
                continue
            profiles = chain.seg.profiles(traj)  # (read once for the merge and the checks below)
            merged = merge_segment(traj, d, start, q_rows[k + 1], chain.limits, profiles)
            if any(merged.residual.tolist()):
                free = [
                    idx
                    for idx in (k, k + 1)
                    if idx > 0 and not chain.fixed[idx] and (chain.v[idx].any() or chain.acc[idx].any())
                ]
                if free:
                    # Ruckig's profile misses its end and no correction fits the limits: rest at
                    # the free ends, where it is exact. (Prescribed via states keep Ruckig's
                    # profile, which meets the next segment within its precision, RUCKIG_PRECISION.)
                    for idx in free:
                        chain.v[idx] = 0.0
                        chain.acc[idx] = 0.0
                    any_bad = True
                    continue
            segments.append((d, merged))
            if d <= 0.0:
                continue
            ends = (v_rows[k].tolist(), acc_rows[k].tolist()), (v_rows[k + 1].tolist(), acc_rows[k + 1].tolist())
            fast = speed_overshoots(traj, *ends, limits, profiles)
            if not chain.seg.bounded and not fast:
                continue
            if not chain.seg.bounded:
                bad = np.zeros(chain.q.shape[1], dtype=bool)
            elif merged.plain:
                # Ruckig's extrema (which the solver checked) and the turns inside phases of zero
                # jerk they miss, where a joint can reach a range end (its merged.missed, compared
                # with the range, only where it can matter).
                turns = chain.seg.turns_beyond(k, traj)
                if outside is None and not fast and not turns:
                    continue  # (the common case)
                bad = np.zeros(chain.q.shape[1], dtype=bool) if outside is None else outside.copy()
                bad[turns] = True
            elif merged.missed is None:
                lo, hi = segment_position_range(traj, merged, d)
                bad = (lo < chain.seg.lower) | (hi > chain.seg.upper)
            else:  # segment_position_range from Ruckig's extrema, which the solver checked already
                lo, hi = merged.missed
                if (
                    outside is None
                    and not fast
                    and not (any(map(lt, lo.tolist(), lows)) or any(map(gt, hi.tolist(), highs)))
                ):
                    continue  # (the common case, on floats)
                bad = (lo < chain.seg.lower) | (hi > chain.seg.upper)
                if outside is not None:
                    bad |= outside
            if fast:
                bad[fast] = True
            if not bad.any():
                continue
            any_bad = True
            movable = [
                idx
                for idx in (k, k + 1)
                if idx > 0 and ((chain.v[idx][bad] != 0).any() or (chain.acc[idx][bad] != 0).any())
            ]
            if not movable:
                raise _StartOvershoot
            for idx in movable:
                # Halve a few times, then rest: a joint running along its range end over
                # many samples would otherwise pass the overshoot on from via to via.
                small = (np.abs(chain.v[idx]) < 1e-6 * chain.limits.velocity) & (
                    np.abs(chain.acc[idx]) < 1e-6 * chain.limits.acceleration
                ) | (halved[idx] >= _REPAIR_HALVINGS_BEFORE_REST)
                halved[idx] += bad
                factor = np.where(bad, np.where(small, 0.0, 0.5), 1.0)
                chain.v[idx] *= factor
                chain.acc[idx] *= factor
        if not any_bad:
            chain.repaired |= (chain.v != before_v) | (chain.acc != before_acc)
            return segments
    raise PlanningError(  # pragma: no cover - zero via speeds always fit
        "the via states could not be brought within the joint ranges; add stops at the waypoints near the range ends"
    )


def plan_trajectory(
    waypoints: Sequence[Sequence[float]] | np.ndarray,
    limits: JointLimits,
    *,
    start_velocity: Sequence[float] | np.ndarray | None = None,
    start_acceleration: Sequence[float] | np.ndarray | None = None,
    stops: Sequence[int] | None = None,
    dwell: float | Sequence[float] | None = None,
    strategy: str | ViaStrategy = "optimized",
    via_velocities: np.ndarray | None = None,
    via_accelerations: np.ndarray | None = None,
    min_durations: Sequence[float] | np.ndarray | None = None,
) -> JointTrajectory:
    """Plan a jerk-limited trajectory through joint waypoints without stopping at each one.

    Args:
        waypoints: Joint configurations to pass through, shape (N, dof) with N >= 2 [rad or m].
        limits: Velocity, acceleration, jerk and position limits (see :class:`JointLimits`).
        start_velocity: Velocity at the first waypoint, shape (dof,); None is at rest.
        start_acceleration: Acceleration at the first waypoint, shape (dof,); None is zero.
        stops: Indices of waypoints where the arm must come to rest (the first and last
            always are, unless a start state is given).
        dwell: Time at rest at each waypoint [s]: one number for all, or one per waypoint;
            a positive dwell implies a stop.
        strategy: A name in :data:`planner.motion.vias.VIA_STRATEGIES`: ``"optimized"``
            (default: heuristic via velocities, then a duration search per via waypoint),
            ``"heuristic"`` (the slope blend only) or ``"stop"`` (rest at every waypoint, the
            baseline); or a :class:`planner.motion.vias.ViaStrategy` instance.
        via_velocities: Prescribed velocities at via waypoints, shape (N, dof); rows of NaN
            are chosen by the planner. Used for sampled paths (straight Cartesian lines)
            whose timing is already known; lowered only if a joint would leave its range.
        via_accelerations: Prescribed accelerations for the same rows, shape (N, dof).
        min_durations: Shortest duration of each segment [s], shape (N-1,); 0 for none.

    Returns:
        The trajectory; it passes through every waypoint exactly and honours every limit.

    Raises:
        InvalidArgumentError: Fewer than two waypoints, a bad start state, dwell or strategy.
        InvalidConfigurationError: A waypoint with the wrong length or a NaN.
        JointLimitError: A waypoint outside its joint range (joint and value named).
    """
    if (
        isinstance(strategy, str)
        and strategy == StopStrategy.name
        and isinstance(limits, JointLimits)
        and start_velocity is None
        and start_acceleration is None
        and stops is None
        and dwell is None
        and via_velocities is None
        and via_accelerations is None
        and min_durations is None
    ):
        # The baseline at Ruckig's own speed: nothing to choose, so no request and no chain
        # unless the waypoints or a segment need them (they then give the same plan or error).
        within = waypoint_rows_within(waypoints, limits)
        planned = _plan_at_rest(within[0], limits, within[1:]) if within is not None else None
        if planned is not None:
            return planned
    return plan_trajectory_request(
        TrajectoryRequest(
            waypoints,
            limits,
            start_velocity=start_velocity,
            start_acceleration=start_acceleration,
            stops=stops,
            dwell=dwell,
            strategy=strategy,
            via_velocities=via_velocities,
            via_accelerations=via_accelerations,
            min_durations=min_durations,
        )
    )


def plan_trajectory_request(request: TrajectoryRequest) -> JointTrajectory:
    """Plan the trajectory a request asks for (see :func:`plan_trajectory` for the fields).

    Args:
        request: The validated request.

    Returns:
        The trajectory; it passes through every waypoint exactly and honours every limit.

    Raises:
        InvalidArgumentError: If a given start state runs a joint out of its range even when
            braking at once.
        PlanningError: If a move between two waypoints needs longer than Ruckig plans
            (:data:`~planner.motion.limits.MAX_SEGMENT_DURATION`).
    """
    if not isinstance(request, TrajectoryRequest):
        raise InvalidArgumentError(f"request must be a TrajectoryRequest, got {type(request).__name__}")
    chooser = via_strategy(request.strategy)
    limits = request.limits
    moving = request.moving_start
    limits.check_move_durations(request.waypoints, from_rest=not moving)
    q, v0, a0, dw = request.waypoints, request.start_velocity, request.start_acceleration, request.dwell
    dwelling = any(dw.tolist())
    n = len(q)
    # At rest at every waypoint: the stop strategy's plans, and every registered strategy's
    # between two waypoints (both ends rest, a prescribed state there is overridden and there
    # is no via to choose; a strategy of the caller's own type goes through the chain).
    if (
        (type(chooser) is StopStrategy or (n == 2 and type(chooser) in _REGISTERED))
        and not moving
        and not dwelling
        and not any(request.min_durations.tolist())
    ):
        planned = _plan_at_rest(q, limits, strategy=chooser.name)
        if planned is not None:
            return planned
    stop = np.zeros(n, dtype=bool)
    if request.stops:
        stop[list(request.stops)] = True
    if dwelling:
        stop |= dw > 0
    stop = chooser.stop_mask(stop, moving)
    given = (request.via_velocities, request.via_accelerations, request.min_durations) if request.prescribed else None

    try:
        chain = ViaChain(q, limits, v0, a0, stop, given)
        if chain.n >= 3:
            chooser.choose(chain)
        segments = _repair_range(chain)
        v, acc, repaired = chain.v, chain.acc, chain.repaired
        head = None
    except _StartOvershoot:
        # A joint that is not the slowest of the first segment gets a stretched profile that
        # can run past its range; brake every joint as hard as it can first, then go on.
        *head, q_rest = brake_segment(q[0], v0, a0, limits)
        inner = np.vstack([q_rest, q[1:]])
        chain = ViaChain(inner, limits, np.zeros_like(v0), np.zeros_like(a0), stop, given)
        if chain.n >= 3:
            chooser.choose(chain)
        try:
            segments = _repair_range(chain)
        except _StartOvershoot:
            raise PlanningError(
                "the first segment leaves a joint's position range even from rest after braking; move the "
                "first waypoints further inside the range"
            ) from None
        v, acc, repaired = chain.v.copy(), chain.acc.copy(), chain.repaired.copy()
        v[0], acc[0] = v0, a0

    # The waypoint times now, the pieces when first used (JointTrajectory.lazy).
    times, rests, starts = [], [], []
    t = head[0] if head is not None else 0.0
    for k, pause in enumerate(dw.tolist()):
        times.append(0.0 if k == 0 else t)
        rests.append(t)
        t += pause
        starts.append(t)
        if k < n - 1:
            t += segments[k][0]
    times, rests, starts = np.array(times), np.array(rests), np.array(starts)

    def build() -> tuple[np.ndarray, ...]:
        return _assemble(q, dw, rests, starts, [merged for _, merged in segments], head)

    return JointTrajectory.lazy(
        build,
        duration=float(t),
        waypoints=q if not q.flags.writeable else read_only(q),
        waypoint_times=_frozen(times),
        via_velocities=_frozen(v),
        via_accelerations=_frozen(acc),
        dwell=dw if not dw.flags.writeable else read_only(dw),
        limits=limits,
        strategy=chooser.name,
        repaired=_frozen(repaired),
    )


def _assemble(
    q: np.ndarray,
    dw: np.ndarray,
    rests: np.ndarray,
    starts: np.ndarray,
    merged: list[SegmentPieces],
    head: list | None,
) -> tuple[np.ndarray, ...]:
    """The trajectory's read-only ``knots, p, v, a, j`` from its segments, rests and braking head."""
    dof = q.shape[1]
    knots, blocks = [], []
    if head is not None:
        knots.append(head[1])
        blocks.append(head[2])
    for k in range(len(q)):
        if dw[k] > 0:
            knots.append(np.array([rests[k]]))
            blocks.append(np.concatenate([q[k][None, None], np.zeros((3, 1, dof))]))
        if k < len(q) - 1 and len(merged[k].knots):
            knots.append(starts[k] + merged[k].knots)
            blocks.append(merged[k].pieces)
    if knots:
        all_knots = np.concatenate(knots)
        pvaj = np.concatenate(blocks, axis=1)
    else:  # every waypoint identical, no dwell: a motionless trajectory
        all_knots = np.array([0.0])
        pvaj = np.concatenate([q[:1][None], np.zeros((3, 1, dof))])
    # Every array here is new: freeze them in place.
    pvaj.setflags(write=False)
    return _frozen(all_knots), pvaj[0], pvaj[1], pvaj[2], pvaj[3]


def _plan_at_rest(
    q: np.ndarray,
    limits: JointLimits,
    rows: tuple[list[list[float]], list[float], list[float]] | None = None,
    strategy: str = StopStrategy.name,
) -> JointTrajectory | None:
    """The plan resting at every waypoint (no dwell, no start state), or None if the chain must decide.

    What :func:`plan_trajectory_request` makes of such a request, bit for bit, with one Ruckig
    calculate per segment (:func:`planner.motion.segments.rest_to_rest_segments`); the pieces
    are merged when first used. None where a segment needs the chain's corrections.

    Args:
        q: Validated waypoints, shape (N, dof) [rad or m]; kept (frozen) as the result's.
        limits: The limits.
        rows: `q` as rows of floats and its per-joint extremes, if at hand (see
            :func:`planner.motion.segments.rest_to_rest_segments`).
        strategy: The name the result carries (the request's strategy: between two waypoints
            every strategy rests at both).
    """
    durations = rest_to_rest_segments(q, limits, rows)
    if durations is None:
        return None
    n, dof = q.shape
    times = list(accumulate(durations, initial=0.0))
    via, dw, repaired = _rest_arrays(n, dof)
    waypoint_times = np.array(times)
    waypoint_times.setflags(write=False)
    q.setflags(write=False)  # new, or the request's own (read-only) array

    def build() -> tuple[np.ndarray, ...]:
        rest = np.zeros(dof)
        merged = [
            merge_segment(rest_to_rest_trajectory(q[k], q[k + 1], limits), d, (q[k], rest, rest), q[k + 1], limits)
            for k, d in enumerate(durations)
        ]
        return _assemble(q, dw, waypoint_times, waypoint_times, merged, None)

    return JointTrajectory.lazy(
        build,
        duration=times[-1],
        waypoints=q,
        waypoint_times=waypoint_times,
        via_velocities=via,
        via_accelerations=via,
        dwell=dw,
        limits=limits,
        strategy=strategy,
        repaired=repaired,
    )


@lru_cache(maxsize=16)
def _rest_arrays(n: int, dof: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read-only zero via states (N, dof), dwell (N,) and repair flags (N, dof) of a plan at rest.

    Shared by the plans of that shape: views of frozen arrays, which cannot be made writeable
    again (``setflags(write=True)`` raises).
    """
    via, dwell, repaired = np.zeros((n, dof)), np.zeros(n), np.zeros((n, dof), dtype=bool)
    return _frozen(via)[...], _frozen(dwell)[...], _frozen(repaired)[...]


def _frozen(arr: np.ndarray) -> np.ndarray:
    """`arr` itself, made read-only (for arrays no one else holds)."""
    arr.setflags(write=False)
    return arr
