"""Ruckig state-to-state segments: solving, merging into common pieces, range checks, braking.

The community edition of Ruckig computes time-optimal state-to-state motions (position,
velocity and acceleration at both ends) under velocity, acceleration and jerk limits, but has
no intermediate waypoints and no position limits. :class:`SegmentSolver` solves the segments
between fixed positions (reusing one Ruckig instance) and flags joints that Ruckig's extrema put
outside their range (remembering the answers: the via search asks for some states more than
once); :func:`merge_segment` turns a segment into constant-jerk pieces common to all joints
(built when first used); :func:`segment_position_range` gives a segment's exact position
extrema from Ruckig's own plus the turning points they miss (:func:`piece_position_range`
computes them from the pieces); and :func:`brake_segment` brings a moving start state to rest.
"""

from __future__ import annotations

import math
import threading
from bisect import bisect_left
from collections.abc import Callable, Sequence
from itertools import chain, compress, islice, repeat
from operator import add, gt, lt, or_, sub

import numpy as np
from ruckig import ControlInterface, InputParameter, Result, Ruckig, RuckigError, Synchronization
from ruckig import Trajectory as RuckigTrajectory

from planner.exceptions import InvalidArgumentError, PlanningError
from planner.motion.limits import RANGE_TOLERANCE, JointLimits, reach_time
from planner.motion.segment_kernels import WatchTable, watch_times, zero_jerk_turns
from planner.motion.trajectory import LIMIT_TOLERANCE

__all__ = [
    "RANGE_TOLERANCE",
    "RUCKIG_PRECISION",
    "SegmentPieces",
    "SegmentSolver",
    "brake_segment",
    "merge_segment",
    "piece_position_range",
    "range_with_tolerance",
    "reach_time",
    "rest_to_rest_segments",
    "rest_to_rest_trajectory",
    "segment_position_range",
    "speed_overshoots",
]

#: End-position error [rad or m per unit of max(1, |target|)] beyond which a segment is corrected.
END_TOLERANCE = 1e-13
#: How far Ruckig may end a profile from its target state: position [rad or m], velocity
#: [rad/s or m/s], acceleration [rad/s^2 or m/s^2] (Ruckig's own acceptance thresholds). Where
#: a segment cannot be corrected within the limits, consecutive segments meet within these.
RUCKIG_PRECISION = (1e-8, 1e-8, 1e-10)
_SOLVED = (Result.Working, Result.Finished)


def range_with_tolerance(limits: JointLimits) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper position bounds widened by :data:`RANGE_TOLERANCE`, shapes (dof,) [rad or m]."""
    return limits.checked_range


def piece_position_range(knots: np.ndarray, pvaj: np.ndarray, end: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact per-joint min and max position of constant-jerk pieces, shapes (dof,).

    Ruckig's own ``position_extrema`` misses an extremum inside a constant-acceleration phase
    (zero jerk) where the velocity changes sign, so the extrema are recomputed here from the
    polynomial pieces: their ends and every interior root of the velocity.
    """
    p, v, a, j = pvaj
    h = (np.append(knots[1:], end) - knots)[:, None]
    cands = [p, p + h * (v + h * (a / 2.0 + h * j / 6.0))]
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = a * a - 2.0 * j * v
        sq = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
        roots = [(-a + sq) / j, (-a - sq) / j, np.where(j == 0.0, -v / a, np.nan)]
    for r in roots:
        r = np.where((j != 0.0) | (a != 0.0), r, np.nan)
        inside = np.isfinite(r) & (r > 0.0) & (r < h)
        tr = np.where(inside, r, 0.0)
        cands.append(np.where(inside, p + tr * (v + tr * (a / 2.0 + tr * j / 6.0)), p))
    stacked = np.concatenate(cands, axis=0)
    return stacked.min(axis=0), stacked.max(axis=0)


def rest_to_rest_segments(
    q: np.ndarray,
    limits: JointLimits,
    rows: tuple[list[list[float]], list[float], list[float]] | None = None,
) -> list[float] | None:
    """The durations of the rest-to-rest Ruckig segments between the rows of `q`, where they need nothing more.

    One Ruckig calculate per segment. The planner's chain (:class:`SegmentSolver` and the
    range repair) would take each profile as it is unless Ruckig finds none, a joint misses
    its target by more than :data:`END_TOLERANCE` (re-solved unsynchronised there), a joint
    turns round inside a phase of zero jerk (which Ruckig's extrema miss) outside the range or
    an extremum lies outside the range: in any of these cases this returns None and the chain
    decides. Else the durations are exactly the chain's, and so are the trajectories
    :func:`rest_to_rest_trajectory` solves again (the plan's pieces are made when first used).

    A rest-to-rest profile (jerk signs up-down-down-up or up-down-up-down) changes the sign
    of its acceleration at most twice, so its velocity at most once: a joint either moves
    monotonically or turns round once, at its farthest point. Where that turn lies beyond
    both ends of the segment, the profile's phase boundary next to it (which Ruckig's extrema
    include) lies beyond them too. So where every joint's Ruckig extrema stay within its two
    end positions (up to :data:`_HULL_SLACK`, rounding) and the waypoints lie at least
    :func:`_turn_reach` inside the range, no missed turn and no extremum can leave the range:
    the profiles are read only where this does not hold.

    Args:
        q: Waypoints within the limits, shape (N, dof) [rad or m].
        limits: The limits.
        rows: `q` as rows of floats with per joint its lowest and highest value (as
            :func:`planner.motion.checks.waypoint_rows_within` gives them), or None to take them from `q`.

    Returns:
        The durations of the segments [s], or None.
    """
    dof = q.shape[1]
    solver = _thread_solver(dof)
    otg, inp, _, traj = solver
    if solver[2] is not limits:  # the input keeps the limits it was last given
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = limits.ruckig_limits
        solver[2] = limits
    if rows is None:
        points = q.tolist()
        # Per joint, the lowest and highest waypoint (plain floats: faster than NumPy on a few).
        low_q, high_q = list(map(min, *points)), list(map(max, *points))
    else:
        points, low_q, high_q = rows
    bounded = limits.bounded
    if bounded:
        slack = _HULL_SLACK * max(1.0, max(high_q), -min(low_q))
    calculate = otg.calculate
    durations = []
    start = points[0]
    for goal in points[1:]:
        inp.current_position, inp.target_position = start, goal
        # Into the thread's scratch trajectory: read here, solved again when the pieces are made.
        try:
            if calculate(inp, traj) not in _SOLVED:
                return None
        except (RuckigError, ValueError):  # ValueError: see _solve
            return None
        duration = traj.duration
        # Where the chain would correct the end (see SegmentSolver._unsynchronise_missed): at_time
        # at the end gives every profile's last position, as one list. Its distance to the goal
        # bounds every joint's miss (within rounding, which _END_DISTANCE leaves room for).
        reached = traj.at_time(duration)[0]
        if not math.dist(reached, goal) <= _END_DISTANCE:
            for x, g in zip(reached, goal):
                if abs(x - g) > END_TOLERANCE * (g if g > 1.0 else -g if g < -1.0 else 1.0):
                    return None
        if bounded and duration > 0.0:
            for e, s, g in zip(traj.position_extrema, start, goal):
                if (e.min < s - slack or e.max > g + slack) if s < g else (e.min < g - slack or e.max > s + slack):
                    # Beyond its ends: the range checks the chain makes.
                    if _outside_or_turn(traj, limits):
                        return None
                    break
        durations.append(duration)
        start = goal
    if bounded and durations:
        # Within their ends, the joints stay in the range unless a missed turn could reach beyond it.
        reach = repeat(_turn_reach(slack, limits.max_jerk, max(durations)))
        lower, upper = limits.checked_floats
        if any(map(lt, map(sub, low_q, reach), lower)) or any(map(gt, map(add, high_q, reach), upper)):
            for start, goal, duration in zip(points, points[1:], durations):
                if duration > 0.0:
                    inp.current_position, inp.target_position = start, goal
                    calculate(inp, traj)
                    if _outside_or_turn(traj, limits):
                        return None
    return durations


def rest_to_rest_trajectory(start: np.ndarray, goal: np.ndarray, limits: JointLimits) -> RuckigTrajectory:
    """Ruckig's rest-to-rest trajectory from `start` to `goal` (as :func:`rest_to_rest_segments` solves it).

    Args:
        start: Start positions, shape (dof,) [rad or m].
        goal: Target positions, shape (dof,) [rad or m].
        limits: The limits.

    Raises:
        PlanningError: If Ruckig finds no profile (not for a segment rest_to_rest_segments took).
    """
    dof = len(start)
    inp = InputParameter(dof)
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = limits.ruckig_limits
    inp.current_position, inp.target_position = start.tolist(), goal.tolist()
    traj = RuckigTrajectory(dof)
    try:
        result = _thread_solver(dof)[0].calculate(inp, traj)
    except (RuckigError, ValueError):  # pragma: no cover - solved before; ValueError: -101 (> 7e3 s)
        result = None
    if result not in _SOLVED:  # pragma: no cover - solved before
        raise PlanningError("Ruckig found no rest-to-rest profile between two waypoints")
    return traj


#: :data:`END_TOLERANCE` less a margin for the rounding of ``math.dist``: a distance at most
#: this puts every joint within END_TOLERANCE of its goal.
_END_DISTANCE = END_TOLERANCE * (1.0 - 1e-9)


def _outside_or_turn(traj: RuckigTrajectory, limits: JointLimits) -> bool:
    """Whether Ruckig's extrema leave the range, or a profile turns round inside a phase of zero jerk."""
    for e, (lo, hi) in zip(traj.position_extrema, zip(*limits.checked_floats)):
        if e.min < lo or e.max > hi:
            return True
    return _missed_turn(traj)


#: Rounding allowed when comparing a rest-to-rest profile's extrema with its end positions
#: [rad or m per unit of the largest |position|] (see :func:`rest_to_rest_segments`).
_HULL_SLACK = 1e-12


def _turn_reach(slack: float, jerk: float, duration: float) -> float:
    """How far a turn inside a phase of zero jerk can lie beyond a profile's ends [rad or m].

    A joint turning round beyond an end and then moving on to (or coming from) that end at
    rest needs a distance of at least ``|v|^1.5 / sqrt(jerk)`` to lose (or gain) the speed
    ``|v|`` it has at the phase boundary next to the turn; where that boundary lies within
    `slack` (plus rounding) of the end, ``|v| <= (4 slack^2 jerk)^(1/3)`` and the turn lies at
    most ``|v| duration / 2`` beyond the boundary. Twice that bound, plus the slack.

    Args:
        slack: The allowed distance of the extrema beyond the ends [rad or m].
        jerk: The largest jerk limit [rad/s^3 or m/s^3].
        duration: The segment's duration [s].
    """
    return 2.0 * slack + 2.0 * (slack * slack * jerk) ** (1.0 / 3.0) * duration


def _zero_jerk_turns(prof, v: list[float] | None = None) -> list[float]:
    """Where one joint's Ruckig profile turns round inside phases of zero jerk [rad or m], in order.

    Ruckig's extrema miss these turns; :meth:`SegmentSolver.turns_beyond` and
    :func:`_profile_turns` take them from here, so both see the same values bit for bit.

    Args:
        prof: One joint's Ruckig profile.
        v: Its velocities ``prof.v`` if already read.
    """
    if v is None:
        v = prof.v
    fast = zero_jerk_turns(prof, v)  # compiled, the same operations (None: the loop below)
    if fast is not None:
        return fast
    # The phases of zero jerk where the velocity changes sign (the accelerations and the
    # positions are read only where there is one).
    jerk = prof.j
    turns = []
    acc = pos = None
    # (A plain loop: cheaper than a comprehension's frame on seven phases.)
    for i in range(len(jerk)):
        if jerk[i] == 0.0 and v[i] * v[i + 1] < 0.0:
            if acc is None:
                acc, pos = prof.a, prof.p
            v0, a0 = v[i], acc[i]
            tz = -v0 / a0
            turns.append(pos[i] + tz * (v0 + tz * a0 / 2.0))
    return turns


def speed_overshoots(
    traj: RuckigTrajectory,
    start: tuple[list[float], list[float]],
    end: tuple[list[float], list[float]],
    limits: JointLimits,
    profiles: list | None = None,
) -> list[int]:
    """The joints whose Ruckig profile exceeds the speed limit near a moving end of the segment.

    Ruckig 0.19 moves a joint that does not set the segment's duration with a smaller jerk
    than the limit; from an end state still gaining speed (or arriving after losing it) its
    speed then peaks at ``|v + a^2 / (2 j)|`` inside the first (last) phases, beyond what an
    admissible state (:func:`planner.motion.limits.admissible_acceleration`) allows with the full
    jerk and beyond the limit (by 0.66 % in a case a search found). Only joints with
    ``a v > 0`` at the start (``a v < 0`` at the end) and ``|v| + |a| T / 2`` beyond the limit
    are looked at (the phase that reaches the peak lasts ``|a / j| <= T``; plain floats).

    Args:
        traj: The segment's Ruckig trajectory.
        start: Velocities and accelerations at the start, as lists.
        end: Velocities and accelerations at the end, as lists.
        limits: The limits.
        profiles: ``traj.profiles[0]`` if already read (see :meth:`SegmentSolver.profiles`).

    Returns:
        The joints (in order; empty for none).
    """
    velocity = limits.ruckig_limits[0]
    out = []
    half = traj.duration / 2.0
    for j, (v0, a0, v1, a1, v_max) in enumerate(zip(*start, *end, velocity)):
        # A phase reaching the peak lasts |a / jerk| <= the duration: the peak is below |v| + |a| T / 2.
        if not (
            (a0 * v0 > 0.0 and abs(v0) + abs(a0) * half > v_max) or (a1 * v1 < 0.0 and abs(v1) + abs(a1) * half > v_max)
        ):
            continue
        if profiles is None:
            profiles = traj.profiles[0]
        prof = profiles[j]
        v, a, jerk = prof.v, prof.a, prof.j
        bound = velocity[j] * (1.0 + _LIMIT_SLACK)
        for i in range(len(jerk)):
            # The speed peaks inside a phase where the acceleration changes sign.
            if jerk[i] != 0.0 and a[i] * a[i + 1] < 0.0 and abs(v[i] - a[i] * a[i] / (2.0 * jerk[i])) > bound:
                out.append(j)
                break
    return out


def _missed_turn(traj: RuckigTrajectory) -> bool:
    """Whether a profile turns round inside a phase of zero jerk (Ruckig's extrema miss it)."""
    for prof in traj.profiles[0]:
        v = prof.v
        if min(v) < 0.0 < max(v):  # a sign change, often only a rounding at the end
            j = prof.j
            w = v if j[-1] == 0.0 else v[:-1]
            if min(w) < 0.0 < max(w) and any(j[i] == 0.0 and v[i] * v[i + 1] < 0.0 for i in range(len(j))):
                return True
    return False


#: Allowance for a Ruckig profile's end position missing its target [rad or m] (Ruckig accepts
#: 1e-8; its time synchronisation misses by up to a few 1e-8 on tiny moves).
_END_MISS = 1e-6
#: Relative allowance on the velocity and acceleration limits Ruckig's profiles keep (it
#: accepts 1e-12 beyond them), and on rounding of the positions it reports.
_LIMIT_SLACK = 1e-6
_POSITION_SLACK = 1e-9


_LOCAL = threading.local()
#: Per set of limits (by identity, the limits held), what _range_ends made of them.
_RANGE_ENDS: dict[int, tuple[JointLimits, tuple]] = {}


def _range_ends(limits: JointLimits) -> tuple[list[tuple], list[tuple], WatchTable]:
    """The finite range ends :meth:`SegmentSolver._watch_ends` watches, made once per set of limits.

    Per joint and range end (uppers, then lowers): the joint, its speed and acceleration limits
    taken :data:`_LIMIT_SLACK` larger, reach_time's knee, the end and where the checks put it
    (:data:`_POSITION_SLACK` nearer); and the same as a :class:`WatchTable`.
    """
    known = _RANGE_ENDS.get(id(limits))
    if known is not None and known[0] is limits:
        return known[1]
    grow = 1.0 + _LIMIT_SLACK
    lows, highs = limits.checked_floats
    uppers, lowers = [], []
    for j, (v, a, lo, hi) in enumerate(zip(*limits.ruckig_limits[:2], lows, highs)):
        v, a = v * grow, a * grow
        knee = v * v / (2.0 * a)
        if hi < math.inf:
            uppers.append((j, v, a, knee, hi, hi - _POSITION_SLACK * max(1.0, abs(hi))))
        if lo > -math.inf:
            lowers.append((j, v, a, knee, lo, lo + _POSITION_SLACK * max(1.0, abs(lo))))
    made = uppers, lowers, WatchTable(uppers, lowers)
    if len(_RANGE_ENDS) >= 64:
        _RANGE_ENDS.clear()  # (a few sets of limits are in use at a time)
    _RANGE_ENDS[id(limits)] = (limits, made)
    return made


def _probe(otg: Ruckig, inp: InputParameter, traj: RuckigTrajectory, v0, a0, v1, a1) -> list[float] | None:
    """One unsynchronised calculate of a probe's end states (lists).

    Returns:
        Ruckig's minimum duration per entry, or None where it fails.
    """
    inp.current_velocity, inp.current_acceleration = v0, a0
    inp.target_velocity, inp.target_acceleration = v1, a1
    try:
        result = otg.calculate(inp, traj)
    except (RuckigError, ValueError):  # see SegmentSolver._solve
        return None
    if result not in _SOLVED:
        return None
    return traj.independent_min_durations


def _pick(values: Sequence[float], joints: Sequence[int]) -> list[float]:
    """``[values[j] for j in joints]`` (one C loop)."""
    return list(map(values.__getitem__, joints))


def _interleave(first: list[float], second: list[float]) -> list[float]:
    """``[first[0], second[0], first[1], second[1], ...]`` for lists of one length."""
    out = first * 2
    out[0::2], out[1::2] = first, second
    return out


def _thread_solver(dof: int) -> list:
    """This thread's Ruckig for `dof` joints, an input for rest-to-rest segments, its limits, a scratch trajectory.

    Kept between plans (making them costs as much as solving a segment): Ruckig's calculate
    depends on its input only. Only :func:`rest_to_rest_segments` sets this input, always both
    positions, and the limits where they are not those of the last plan (the third entry, None
    at first). :func:`rest_to_rest_segments` solves into the scratch trajectory (fourth entry)
    and reads it at once.
    """
    solvers = getattr(_LOCAL, "solvers", None)
    if solvers is None:
        solvers = _LOCAL.solvers = {}
    entry = solvers.get(dof)
    if entry is None:
        entry = solvers[dof] = [Ruckig(dof), InputParameter(dof), None, RuckigTrajectory(dof)]
    return entry


def _thread_prober(n: int) -> tuple[Ruckig, InputParameter, RuckigTrajectory]:
    """This thread's unsynchronised Ruckig for `n` degrees of freedom, an input and a trajectory (for probes).

    The caller sets every field of the input it uses (positions, limits and states) each time.
    """
    probers = getattr(_LOCAL, "probers", None)
    if probers is None:
        probers = _LOCAL.probers = {}
    entry = probers.get(n)
    if entry is None:
        inp = InputParameter(n)
        inp.synchronization = Synchronization.No
        entry = probers[n] = (Ruckig(n), inp, RuckigTrajectory(n))
    return entry


class SegmentSolver:
    """Ruckig state-to-state segments between fixed positions, with position-range checks.

    Attributes:
        q: The fixed positions, shape (N, dof) [rad or m]; segment k runs from q[k] to q[k+1].
        min_durations: Shortest duration per segment, shape (N-1,) [s], or None for none.
        lower: Lower bounds of the range checks (with :data:`RANGE_TOLERANCE`), shape (dof,).
        upper: Upper bounds, likewise.
        bounded: Whether any joint has a finite range end.
    """

    def __init__(
        self,
        q: np.ndarray,
        limits: JointLimits,
        min_durations: np.ndarray | None = None,
        admissible: Sequence[bool] | None = None,
    ):
        """Prepare one Ruckig instance for the segments between the rows of `q`.

        Args:
            q: Positions, shape (N, dof) [rad or m].
            limits: Velocity, acceleration, jerk and position limits.
            min_durations: Shortest duration per segment, shape (N-1,) [s]; None or all zero is none.
            admissible: Per segment, whether every end state it will be solved with is
                admissible (see :meth:`_watch_ends`), as every via state the strategies choose
                is; there the range check reads Ruckig's extrema only of the joints that could
                reach a range end. None: no segment is known to be.
        """
        self.q = q
        self.rows = rows = q.tolist()
        self.min_durations = (
            min_durations if min_durations is not None and any(d > 0 for d in min_durations.tolist()) else None
        )
        self.dof = q.shape[1]
        self.lower, self.upper = range_with_tolerance(limits)
        self.limits = limits
        self._lows, self._highs = limits.checked_floats
        self.bounded = limits.bounded
        self.otg = _thread_solver(self.dof)[0]
        self._limits = limits.ruckig_limits
        # One Ruckig input per segment (made when first used), holding its positions: the
        # searches alternate between the two segments next to a via.
        self._inputs: list[InputParameter | None] = [None] * (len(q) - 1)
        # Per input, the cache key of the states it holds (None: unknown).
        self._held: list[tuple | None] = [None] * (len(q) - 1)
        # Per segment, the joints that do not move: only they can go out and back on one
        # parabola, which Ruckig 0.19 cannot take (see _on_one_parabola).
        self._still = [
            [
                j
                for j, (x, y) in enumerate(zip(a, b))
                if abs(y - x) <= 1e-9 * (y if y > 1.0 else -y if y < -1.0 else 1.0)
            ]
            or None
            for a, b in zip(rows, rows[1:])
        ]
        self._cache: dict[tuple, tuple[float, np.ndarray | None, RuckigTrajectory | None]] = {}
        # Per trajectory, its profiles as read (see profiles).
        self._profiles: dict[RuckigTrajectory, list] = {}
        # Per trajectory, what misses_end found.
        self._misses_end: dict[RuckigTrajectory, bool] = {}
        # Per (segment, trajectory), what turns_beyond found.
        self._turns_beyond: dict[tuple[int, RuckigTrajectory], list[int]] = {}
        # Per (waypoint, joints, candidates), the positions and limits of probe_around's input.
        self._probes: dict[tuple, tuple[list[float], ...]] = {}
        # Per segment, the range ends a joint could reach, in the order of the time it needs
        # to (see _watch_ends): (time, joint, whether the upper end, the end); None: check all.
        self._watch: list[list[tuple[float, int, bool, float]] | None] = [None] * (len(q) - 1)
        # Per segment, the times of its _watch entries (ascending; for bisection).
        self._watch_times: list[list[float] | None] = [None] * (len(q) - 1)
        # Per segment and joint, the least time in which it can reach a range end (see _reach_times).
        self._reach: list[list[float]] | None = None
        if self.bounded and admissible is not None and any(admissible):
            self._watch_ends(limits, admissible)

    def _watch_ends(self, limits: JointLimits, admissible: Sequence[bool]) -> None:
        """Fill :attr:`_watch` for the admissible segments.

        For admissible end states (``|v| <= v_max`` and ``|v| + a^2 / (2 j_max) <= v_max``, the
        states :func:`planner.motion.limits.admissible_acceleration` gives), Ruckig's profile
        keeps ``|v| <= v_max`` and ``|a| <= a_max`` throughout (it checks the velocity at every
        phase boundary and wherever the acceleration changes sign, except in the first two
        phases, which an admissible start state keeps within the limit). At its farthest point
        a joint is at rest, so it got there from its start and goes on to its end each within
        the distance :func:`reach_time` allows: a segment that lasts no longer than the two
        reach times of a range end cannot get there. The limits are taken
        :data:`_LIMIT_SLACK` larger (Ruckig accepts 1e-12 beyond them), the range ends of the
        checks :data:`_POSITION_SLACK` nearer (rounding of Ruckig's extrema), and the end
        position missed by up to :data:`_END_MISS`.
        """
        uppers, lowers, table = _range_ends(limits)
        rows = self.rows
        compiled = watch_times(rows, table, _END_MISS)  # the same operations (None: no compiler)
        if compiled is not None:
            times, least = compiled
            count, joints, flags, ends = table.count, table.joints, table.uppers, table.ends
            dof = self.dof
            reach = []
            for k, ok in enumerate(admissible):
                if ok:
                    self._watched(k, sorted(zip(times[k * count : (k + 1) * count], joints, flags, ends)))
                    reach.append(least[k * dof : (k + 1) * dof])
                else:
                    reach.append([0.0] * dof)
            self._reach = reach  # what _reach_times gives (a tie may differ only in the sign of a zero)
            return
        sqrt = math.sqrt
        for k, ok in enumerate(admissible):
            if not ok:
                continue
            before, after = rows[k], rows[k + 1]
            ends = []
            # reach_time written out (the same operations): the time to the end and back.
            for j, v, a, knee, hi, high in uppers:
                d, e = high - before[j], high - after[j] - _END_MISS
                t = -math.inf if d < 0.0 else sqrt(2.0 * d / a) if d <= knee else (d + knee) / v
                t += -math.inf if e < 0.0 else sqrt(2.0 * e / a) if e <= knee else (e + knee) / v
                ends.append((t, j, True, hi))
            for j, v, a, knee, lo, low in lowers:
                d, e = before[j] - low, after[j] - _END_MISS - low
                t = -math.inf if d < 0.0 else sqrt(2.0 * d / a) if d <= knee else (d + knee) / v
                t += -math.inf if e < 0.0 else sqrt(2.0 * e / a) if e <= knee else (e + knee) / v
                ends.append((t, j, False, lo))
            ends.sort()
            self._watched(k, ends)

    def _watched(self, k: int, watch: list[tuple[float, int, bool, float]]) -> None:
        """Keep segment k's range ends in the order of their times (see :attr:`_watch`) and their times."""
        self._watch[k] = watch
        self._watch_times[k] = [entry[0] for entry in watch]

    def solve(
        self, k: int, va: np.ndarray, aa: np.ndarray, vb: np.ndarray, ab: np.ndarray, keep: bool = False
    ) -> tuple[float, np.ndarray | None, RuckigTrajectory | None]:
        """Segment k from state (va, aa) to (vb, ab).

        Answers are kept per end states: the searches ask for the same state more than once
        (a line search's current state, the chain's durations between searches), and the
        final chain takes its trajectories from them.

        Args:
            k: The segment, from ``q[k]`` to ``q[k+1]``.
            va: Start velocities, shape (dof,).
            aa: Start accelerations, shape (dof,).
            vb: End velocities, shape (dof,).
            ab: End accelerations, shape (dof,).
            keep: The trajectory is kept by the caller: a joint that Ruckig's time
                synchronisation leaves short of a target at rest is then solved on its own
                (see :meth:`_unsynchronise_missed`), in a new trajectory.

        Returns:
            The duration [s] (inf when Ruckig finds no profile), a bool mask of the joints that
            Ruckig's extrema put outside their range (None when none does), and the Ruckig
            trajectory (None without a profile; not to be changed).
        """
        key = (k, va.tobytes(), aa.tobytes(), vb.tobytes(), ab.tobytes())
        hit = self._cache.get(key)
        if hit is None:
            hit = self._cache[key] = self._solve(k, va, aa, vb, ab, key)
        if keep and hit[2] is not None:
            return self._unsynchronise_missed(k, hit, va, aa, vb, ab)
        return hit

    def solve_around(
        self, i: int, va: np.ndarray, aa: np.ndarray, cv: np.ndarray, ca: np.ndarray, vb: np.ndarray, ab: np.ndarray
    ) -> tuple[tuple[float, np.ndarray | None, RuckigTrajectory | None], ...]:
        """:meth:`solve` of segments i-1 and i with state (cv, ca) at waypoint i between them.

        Args:
            i: The waypoint, 0 < i < N-1.
            va: Velocities at waypoint i-1, shape (dof,); `aa` its accelerations.
            aa: Accelerations at waypoint i-1, shape (dof,).
            cv: Velocities at waypoint i, shape (dof,).
            ca: Accelerations at waypoint i, shape (dof,).
            vb: Velocities at waypoint i+1, shape (dof,).
            ab: Accelerations at waypoint i+1, shape (dof,).

        Returns:
            The answers of both segments, as :meth:`solve` gives them.
        """
        bv, ba = cv.tobytes(), ca.tobytes()
        cache = self._cache
        key = (i - 1, va.tobytes(), aa.tobytes(), bv, ba)
        first = cache.get(key)
        if first is None:
            first = cache[key] = self._solve(i - 1, va, aa, cv, ca, key)
        key = (i, bv, ba, vb.tobytes(), ab.tobytes())
        second = cache.get(key)
        if second is None:
            second = cache[key] = self._solve(i, cv, ca, vb, ab, key)
        return first, second

    def around(
        self, i: int, va: np.ndarray, aa: np.ndarray, vb: np.ndarray, ab: np.ndarray
    ) -> Callable[[np.ndarray, np.ndarray], tuple[tuple[float, np.ndarray | None, RuckigTrajectory | None], ...]]:
        """:meth:`solve_around` at waypoint i with the states at waypoints i-1 and i+1 held.

        For searches over the state at waypoint i: the neighbours' cache keys are made once.
        The neighbour arrays must not change while the returned function is used.

        Returns:
            A function of (cv, ca) at waypoint i giving what :meth:`solve_around` gives.
        """
        cache, solve = self._cache, self._solve
        bva, baa, bvb, bab = va.tobytes(), aa.tobytes(), vb.tobytes(), ab.tobytes()

        def both(
            cv: np.ndarray, ca: np.ndarray
        ) -> tuple[tuple[float, np.ndarray | None, RuckigTrajectory | None], ...]:
            bv, ba = cv.tobytes(), ca.tobytes()
            key = (i - 1, bva, baa, bv, ba)
            first = cache.get(key)
            state = None  # (cv, ca) as lists, made once for both segments
            if first is None:
                state = (cv.tolist(), ca.tolist())
                first = cache[key] = solve(i - 1, va, aa, cv, ca, key, None, state)
            key = (i, bv, ba, bvb, bab)
            second = cache.get(key)
            if second is None:
                if state is None:
                    state = (cv.tolist(), ca.tolist())
                second = cache[key] = solve(i, cv, ca, vb, ab, key, state)
            return first, second

        return both

    def probe_around(
        self,
        i: int,
        start: tuple[list[float], list[float]],
        end: tuple[list[float], list[float]],
        joints: tuple[int, ...],
        candidates: Sequence[tuple[list[float], list[float]]],
    ) -> tuple[list[float], list[float]] | None:
        """Per-joint minimum times of segments i-1 and i for candidate states at waypoint i, in one Ruckig call.

        A segment lasts at least as long as each joint alone needs (Ruckig's
        ``independent_min_durations``, which depend on that joint's end states only). Every
        (candidate, joint, segment) is one degree of freedom of a single unsynchronised Ruckig
        calculate: Ruckig's first step only, and one call from Python for all of them. A probe
        is an estimate for a search: the synchronised segment can last longer (Ruckig's blocked
        intervals), and the joint's own time-optimal profile is not the synchronised one; the
        search solves what it keeps (:meth:`solve`). An entry whose own profile leaves the range
        by Ruckig's extrema (looked at only where the joint could reach a range end, see
        :meth:`_watch_ends`), or where Ruckig 0.19 would fail on a joint going out and back on
        one parabola (:meth:`_on_one_parabola`, not solved), gets inf.

        Args:
            i: The waypoint, 0 < i < N-1.
            start: Velocities and accelerations at waypoint i-1, lists over all joints.
            end: Velocities and accelerations at waypoint i+1, likewise.
            joints: The joints probed (ascending indices).
            candidates: Velocities and accelerations at waypoint i, lists over `joints`, each
                admissible (see :func:`planner.motion.limits.admissible_acceleration`).

        Returns:
            The times in segment i-1 and in segment i [s], flat lists with the entry of
            candidate c and the m-th joint at ``c * len(joints) + m``; None where Ruckig fails.
        """
        if not joints or not candidates:
            return [], []
        key = (i, joints, len(candidates))
        fixed = self._probes.get(key)
        if fixed is None:
            fixed = self._probes[key] = self._probe_fixed(i, joints, len(candidates))
        otg, inp, traj = _thread_prober(len(fixed[0]))
        inp.current_position, inp.target_position, inp.max_velocity, inp.max_acceleration, inp.max_jerk = fixed
        count = len(joints)
        va, aa = _pick(start[0], joints), _pick(start[1], joints)
        vb, ab = _pick(end[0], joints), _pick(end[1], joints)
        skipped = []
        still1, still2 = self._still[i - 1], self._still[i]
        if still1 is not None or still2 is not None:
            for c, (cv, ca) in enumerate(candidates):
                for m, j in enumerate(joints):
                    if (still1 is not None and j in still1 and _parabola(va[m], aa[m], cv[m], ca[m])) or (
                        still2 is not None and j in still2 and _parabola(cv[m], ca[m], vb[m], ab[m])
                    ):
                        skipped.append(c * count + m)
                        cv, ca = list(cv), list(ca)
                        cv[m] = ca[m] = 0.0
                        candidates = [*candidates[:c], (cv, ca), *candidates[c + 1 :]]
        # Per (candidate, joint) the two degrees of freedom, interleaved by slice assignment.
        many = len(candidates)
        cvs, cas = zip(*candidates)
        cvs, cas = list(chain.from_iterable(cvs)), list(chain.from_iterable(cas))
        v0, a0, v1, a1 = cvs * 2, cas * 2, cvs * 2, cas * 2
        v0[0::2], v0[1::2] = va * many, cvs
        a0[0::2], a0[1::2] = aa * many, cas
        v1[0::2], v1[1::2] = cvs, vb * many
        a1[0::2], a1[1::2] = cas, ab * many
        times = _probe(otg, inp, traj, v0, a0, v1, a1)
        if times is None:
            return None
        first, second = times[0::2], times[1::2]
        for e in skipped:
            first[e] = second[e] = math.inf
        if self.bounded:
            # Only a profile that lasts longer than the joint needs to reach a range end can leave the range.
            reach = self._reach_table()
            reach1 = _pick(reach[i - 1], joints) * many
            reach2 = _pick(reach[i], joints) * many
            # The entries that last longer than their joint needs to reach a range end (C loops).
            longer = list(map(or_, map(gt, first, reach1), map(gt, second, reach2)))
            if True in longer:
                check = list(compress(range(len(longer)), longer))
                extrema = traj.position_extrema
                lows, highs = self._lows, self._highs
                for e in check:
                    j = joints[e % count]
                    low, high = extrema[2 * e], extrema[2 * e + 1]
                    if min(low.min, high.min) < lows[j] or max(low.max, high.max) > highs[j]:
                        first[e] = second[e] = math.inf
        return first, second

    def probe_run(
        self, a: int, velocities: np.ndarray, accelerations: np.ndarray, joints: tuple[int, ...] | None = None
    ) -> list[float] | None:
        """Per-joint minimum times of the segments from waypoint a on, for several options of the states at their ends.

        As :meth:`probe_around`, one unsynchronised Ruckig calculate for every (option,
        segment, joint): a segment lasts at least as long as each joint alone needs, and that
        depends on the joint's own end states only. An entry whose own profile leaves the
        range by Ruckig's extrema (looked at only where the joint could reach a range end), or
        where Ruckig 0.19 would fail on a joint going out and back on one parabola (not
        solved), gets inf.

        Args:
            a: The first waypoint.
            velocities: Per option, the velocities of `joints` at waypoints a .. a+m, shape
                (options, m+1, len(joints)), a + m < N, each state admissible (see
                :func:`planner.motion.limits.admissible_acceleration`).
            accelerations: Per option, the accelerations, likewise.
            joints: The joints probed (ascending indices); None for all.

        Returns:
            The times [s], a flat list with the entry of option c, segment a+r and the i-th
            joint probed at ``(c m + r) len(joints) + i``; None where Ruckig fails.
        """
        many, m, count = velocities.shape
        m -= 1
        if not many:
            return []
        if joints is None:
            joints = tuple(range(self.dof))
        key = ("run", a, m, many, joints)
        fixed = self._probes.get(key)
        if fixed is None:
            picked = [_pick(row, joints) for row in self.rows[a : a + m + 1]]
            p0, p1 = list(chain.from_iterable(picked[:-1])), list(chain.from_iterable(picked[1:]))
            velocity, acceleration, jerk = (_pick(limit, joints) for limit in self._limits)
            reps = m * many
            fixed = self._probes[key] = (p0 * many, p1 * many, velocity * reps, acceleration * reps, jerk * reps)
        otg, inp, traj = _thread_prober(len(fixed[0]))
        inp.current_position, inp.target_position, inp.max_velocity, inp.max_acceleration, inp.max_jerk = fixed
        v0, a0 = velocities[:, :-1].ravel().tolist(), accelerations[:, :-1].ravel().tolist()
        v1, a1 = velocities[:, 1:].ravel().tolist(), accelerations[:, 1:].ravel().tolist()
        skipped = []
        for r, still in enumerate(self._still[a : a + m]):
            if still is None:
                continue
            for i, j in enumerate(joints):
                if j not in still:
                    continue
                for c in range(many):
                    e = (c * m + r) * count + i
                    if _parabola(v0[e], a0[e], v1[e], a1[e]):
                        skipped.append(e)
                        v0[e] = a0[e] = v1[e] = a1[e] = 0.0
        times = _probe(otg, inp, traj, v0, a0, v1, a1)
        if times is None:
            return None
        for e in skipped:
            times[e] = math.inf
        if self.bounded:
            # Only a profile that lasts longer than the joint needs to reach a range end can leave the range.
            reach = self._reach_table()
            limit = list(chain.from_iterable(_pick(row, joints) for row in reach[a : a + m])) * many
            check = list(compress(range(len(times)), map(gt, times, limit)))
            if check:
                extrema = traj.position_extrema
                lows, highs = self._lows, self._highs
                for e in check:
                    j = joints[e % count]
                    bound = extrema[e]
                    if bound.min < lows[j] or bound.max > highs[j]:
                        times[e] = math.inf
        return times

    def _reach_table(self) -> list[list[float]]:
        """:meth:`_reach_times`, made at the first call (or by :meth:`_watch_ends`) and kept."""
        reach = self._reach
        if reach is None:
            reach = self._reach = self._reach_times()
        return reach

    def _reach_times(self) -> list[list[float]]:
        """Per segment and joint, the least time in which it can reach a range end [s] (0 where unknown)."""
        out = []
        for watch in self._watch:
            if watch is None:
                out.append([0.0] * self.dof)
                continue
            reach = [math.inf] * self.dof
            for time, j, _, _ in watch:
                if time < reach[j]:
                    reach[j] = time
            out.append(reach)
        return out

    def _probe_fixed(self, i: int, joints: tuple[int, ...], count: int) -> tuple[list[float], ...]:
        """The positions and limits of :meth:`probe_around`'s Ruckig input (start, target, v, a, j)."""
        velocity, acceleration, jerk = (_pick(limit, joints) for limit in self._limits)
        before, at, after = (_pick(row, joints) for row in self.rows[i - 1 : i + 2])
        return (
            _interleave(before, at) * count,
            _interleave(at, after) * count,
            _interleave(velocity, velocity) * count,
            _interleave(acceleration, acceleration) * count,
            _interleave(jerk, jerk) * count,
        )

    def _input(
        self, k: int, va: np.ndarray, aa: np.ndarray, vb: np.ndarray, ab: np.ndarray, key: tuple | None = None
    ) -> InputParameter:
        """Ruckig's input for segment k between the given states.

        `key` is the states' cache key (:meth:`solve`): an end state the input already holds
        (a line search changes one end of a segment) is not set again.
        """
        inp = self._inputs[k]
        if inp is None:
            inp = self._new_input(k)
        held = self._held[k]
        if key is None or held is None or key[1] != held[1] or key[2] != held[2]:
            inp.current_velocity = va.tolist()
            inp.current_acceleration = aa.tolist()
        if key is None or held is None or key[3] != held[3] or key[4] != held[4]:
            inp.target_velocity = vb.tolist()
            inp.target_acceleration = ab.tolist()
        self._held[k] = key
        return inp

    def _new_input(self, k: int) -> InputParameter:
        """Segment k's Ruckig input with its limits and positions (no end states held yet)."""
        inp = self._inputs[k] = InputParameter(self.dof)
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = self._limits
        inp.current_position = self.rows[k]
        inp.target_position = self.rows[k + 1]
        if self.min_durations is not None and self.min_durations[k] > 0:
            inp.minimum_duration = float(self.min_durations[k])
        return inp

    def _solve(
        self,
        k: int,
        va: np.ndarray,
        aa: np.ndarray,
        vb: np.ndarray,
        ab: np.ndarray,
        key: tuple | None = None,
        start: tuple[list[float], list[float]] | None = None,
        end: tuple[list[float], list[float]] | None = None,
    ) -> tuple[float, np.ndarray | None, RuckigTrajectory | None]:
        """:meth:`solve` without the cache (and without `keep`); `key` as for :meth:`_input`.

        `start` and `end` are the end states as lists, where the caller has them already.
        """
        still = self._still[k]
        if still is not None and self._on_one_parabola(still, va, aa, vb, ab):
            return math.inf, None, None
        # :meth:`_input`, written out (this runs once per Ruckig solve of the searches).
        inp = self._inputs[k]
        if inp is None:
            inp = self._new_input(k)
        held = self._held[k]
        if key is None or held is None or key[1] != held[1] or key[2] != held[2]:
            inp.current_velocity, inp.current_acceleration = (va.tolist(), aa.tolist()) if start is None else start
        if key is None or held is None or key[3] != held[3] or key[4] != held[4]:
            inp.target_velocity, inp.target_acceleration = (vb.tolist(), ab.tolist()) if end is None else end
        self._held[k] = key
        traj = RuckigTrajectory(self.dof)
        try:
            result = self.otg.calculate(inp, traj)
        # Ruckig's own failure on an input it accepts: no profile from it. ValueError: a result
        # code the binding has no Result member for (-101: longer than Ruckig's 7e3 s).
        except (RuckigError, ValueError):
            return math.inf, None, None
        if result not in _SOLVED:
            return math.inf, None, None
        if self.bounded:
            watch = self._watch[k]
            if watch is None:
                extrema = traj.position_extrema
                for e, lo, hi in zip(extrema, self._lows, self._highs):
                    if e.min < lo or e.max > hi:
                        return traj.duration, self._outside_mask(extrema), traj
                return traj.duration, None, traj
            # Only the range ends a joint can reach within the duration: each of Ruckig's
            # extrema costs about as much to read as a tenth of the solve.
            duration = traj.duration
            reachable = bisect_left(self._watch_times[k], duration)  # the entries with a time below it
            if reachable:
                extrema = traj.position_extrema
                # Whether a reachable upper end lies below its joint's highest position, or a lower
                # one above the lowest (C loops over the entries' joints and ends).
                for _, j, upper, end in islice(watch, reachable):
                    if extrema[j].max > end if upper else extrema[j].min < end:
                        return duration, self._outside_mask(extrema), traj
            return duration, None, traj
        return traj.duration, None, traj

    def misses_end(self, k: int, va: np.ndarray, aa: np.ndarray, vb: np.ndarray, ab: np.ndarray) -> bool:
        """Whether segment k between the given states ends where the planner rests its free ends.

        That is where Ruckig finds no profile, or a joint's profile misses its target by more
        than :data:`END_TOLERANCE` and :func:`merge_segment` cannot correct it within the
        limits (Ruckig's time synchronisation loses precision on a joint whose move is tiny
        next to the segment's): the range repair then sets the via states at the segment's free
        ends to rest, whatever that costs. Ruckig's end positions are read first (one call);
        only a miss is merged.
        """
        traj = self.solve(k, va, aa, vb, ab)[2]
        return traj is None or self.traj_misses_end(k, traj, va, aa, vb, ab)

    def traj_misses_end(
        self, k: int, traj: RuckigTrajectory, va: np.ndarray, aa: np.ndarray, vb: np.ndarray, ab: np.ndarray
    ) -> bool:
        """:meth:`misses_end` with the trajectory :meth:`solve` gave for these states at hand (not None)."""
        known = self._misses_end.get(traj)  # (the searches ask again for some states)
        if known is None:
            duration = traj.duration  # (what solve returned with it)
            if math.dist(traj.at_time(duration)[0], self.rows[k + 1]) <= _END_DISTANCE:
                known = False
            else:
                duration, _, kept = self.solve(k, va, aa, vb, ab, keep=True)
                merged = merge_segment(kept, duration, (self.q[k], va, aa), self.q[k + 1], self.limits)
                known = bool(merged.residual.any())
            self._misses_end[traj] = known
        return known

    def profiles(self, traj: RuckigTrajectory) -> list:
        """Ruckig's profiles of a trajectory :meth:`solve` gave, read once (not to be changed).

        Reading ``traj.profiles`` copies every profile (about a tenth of a solve's cost): the
        search's range checks and the range repair's merge and speed checks share one copy.
        """
        known = self._profiles.get(traj)
        if known is None:
            known = self._profiles[traj] = traj.profiles[0]
        return known

    def turns_beyond(self, k: int, traj: RuckigTrajectory) -> list[int]:
        """The joints of segment k that turn round beyond their range inside a phase of zero jerk.

        Ruckig's extrema (which :meth:`solve` checks) miss such a turn; the planner's range
        repair finds it and halves the joint's via states, which can cost much time: the
        searches check their final choice with this (checking every candidate costs about
        a quarter of the plan time). Only the range ends a joint can reach within the
        duration are looked at (see :meth:`_watch_ends`).

        Args:
            k: The segment.
            traj: Its trajectory, as :meth:`solve` gives it (not None).

        Returns:
            The joints, in no order (empty for none).
        """
        if not self.bounded:
            return []
        # The searches and the range repair ask again for some trajectories (keys hold them alive).
        known = self._turns_beyond.get((k, traj))
        if known is not None:
            return known[:]
        duration = traj.duration
        watch = self._watch[k]
        if watch is None:
            watch = [
                (0.0, j, upper, end)
                for j, ends in enumerate(zip(self._lows, self._highs))
                for upper, end in ((False, ends[0]), (True, ends[1]))
            ]
            reachable = len(watch) if duration > 0.0 else 0
        else:
            reachable = bisect_left(self._watch_times[k], duration)  # the entries with a time below it
        profiles = None
        out = []
        # Per joint its turns, computed once (a joint can be watched at both range ends).
        turns_of: dict[int, Sequence[float]] = {}
        for _, j, upper, end in islice(watch, reachable):
            turns = turns_of.get(j)
            if turns is None:
                if profiles is None:
                    profiles = self.profiles(traj)
                prof = profiles[j]
                v = prof.v
                # No sign change of the velocity, no turn (the common case).
                turns = turns_of[j] = _zero_jerk_turns(prof, v) if min(v) < 0.0 < max(v) else ()
            if turns and any(map(end.__lt__ if upper else end.__gt__, turns)):  # turn > end, turn < end
                out.append(j)
        self._turns_beyond[k, traj] = out[:]
        return out

    def _outside_mask(self, extrema: list) -> np.ndarray:
        """The joints whose Ruckig extrema lie outside their range (bool mask)."""
        return np.array([e.min < lo or e.max > hi for e, lo, hi in zip(extrema, self._lows, self._highs)])

    def _outside(self, traj: RuckigTrajectory) -> np.ndarray | None:
        """The joints that Ruckig's extrema put outside their range (bool mask), or None."""
        if self.bounded:
            extrema = traj.position_extrema
            for e, lo, hi in zip(extrema, self._lows, self._highs):
                if e.min < lo or e.max > hi:
                    return self._outside_mask(extrema)
        return None

    @staticmethod
    def _on_one_parabola(still: np.ndarray, va: np.ndarray, aa: np.ndarray, vb: np.ndarray, ab: np.ndarray) -> bool:
        """Whether a joint that ends where it starts goes out and back on one parabola.

        Same acceleration at both ends, opposite velocities, and the constant-acceleration
        motion between them returning to the start: Ruckig 0.19 fails on such a joint (an
        error, or a crash of the process) instead of returning that jerk-free profile. The
        segment is treated as having no profile, which the via strategies and the range repair
        avoid like any other infeasible via state.

        Args:
            still: Indices of the joints whose start and end positions coincide.
            va: Start velocities, shape (dof,).
            aa: Start accelerations, shape (dof,).
            vb: End velocities, shape (dof,).
            ab: End accelerations, shape (dof,).
        """
        return any(_parabola(va[j], aa[j], vb[j], ab[j]) for j in still)

    def _unsynchronise_missed(
        self,
        k: int,
        solved: tuple[float, np.ndarray | None, RuckigTrajectory],
        va: np.ndarray,
        aa: np.ndarray,
        vb: np.ndarray,
        ab: np.ndarray,
    ) -> tuple[float, np.ndarray | None, RuckigTrajectory | None]:
        """`solved` re-solved where its synchronised profile misses a target that is at rest.

        Ruckig's time synchronisation loses precision on very small moves (a joint moving
        1e-7 rad beside one that sets the duration ends 20 % off). Such a joint, when it is to
        arrive at rest, is solved unsynchronised: it reaches its target on its own time-optimal
        profile and rests there until the segment ends (same duration). Misses at other end
        states are corrected by :func:`merge_segment`. `solved` itself is left as it is.
        """
        duration, _, traj = solved
        target = self.rows[k + 1]
        # The end positions of all profiles in one call (see rest_to_rest_segments).
        reached = traj.at_time(duration)[0]
        if math.dist(reached, target) <= _END_DISTANCE:
            return solved  # every joint within END_TOLERANCE of its target
        rest = ((vb == 0.0) & (ab == 0.0)).tolist()
        missed = [
            r and abs(x - goal) > END_TOLERANCE * max(1.0, abs(goal)) for r, x, goal in zip(rest, reached, target)
        ]
        if not any(missed):
            return solved
        inp = self._input(k, va, aa, vb, ab)
        out = RuckigTrajectory(self.dof)
        inp.per_dof_synchronization = [Synchronization.No if m else Synchronization.Time for m in missed]
        try:
            result = self.otg.calculate(inp, out)
        except (RuckigError, ValueError):  # its step 2 can fail on such tiny moves beside moving joints
            result = None
        finally:
            inp.per_dof_synchronization = None
        if result not in _SOLVED or out.duration != duration:
            return solved  # keep the synchronised profile; merge_segment corrects it
        return duration, self._outside(out), out


def _parabola(va: float, aa: float, vb: float, ab: float) -> bool:
    """Whether one joint that ends where it starts goes out and back on one parabola (see ``_on_one_parabola``)."""
    if aa != 0.0 and aa == ab and va * vb < 0.0:
        t = (vb - va) / aa
        return t > 0.0 and abs(t * (va + t * aa / 2.0)) <= 1e-9 * max(1.0, abs(va) * t)
    return False


class SegmentPieces:
    """One Ruckig segment as constant-jerk pieces common to all joints (see :func:`merge_segment`).

    The pieces are built on first use of :attr:`knots` or :attr:`pieces` (the range check
    needs only :attr:`missed` and Ruckig's own extrema), and so is :attr:`missed` of
    :attr:`plain` pieces.

    Attributes:
        residual: The end error left per joint, shape (dof,) [rad or m].
        missed: Per joint, the lowest and highest turning point inside a phase of zero jerk
            (which Ruckig's ``position_extrema`` misses), shapes (dof,) (inf and -inf where
            none); None where the pieces are not Ruckig's profile (an end correction added).
    """

    __slots__ = ("_build", "_knots", "_missed", "_pieces", "_plain", "_turns", "residual")

    def __init__(
        self,
        build: Callable[[], tuple[np.ndarray, np.ndarray]],
        residual: np.ndarray,
        missed: tuple[np.ndarray, np.ndarray] | None,
        turns: Callable[[], tuple[np.ndarray, np.ndarray]] | None = None,
    ):
        """Pieces that `build` makes (local knots (K,), stacked (p, v, a, j) (4, K, dof)).

        `missed` as the attribute holds it, or None with `turns` computing it when first used
        (for pieces that are Ruckig's profiles as they are, see :attr:`plain`).
        """
        self._build: Callable[[], tuple[np.ndarray, np.ndarray]] | None = build
        self._knots: np.ndarray | None = None
        self._pieces: np.ndarray | None = None
        self.residual = residual
        self._missed = missed
        self._turns = turns
        self._plain = turns is not None

    @property
    def missed(self) -> tuple[np.ndarray, np.ndarray] | None:
        """See the class attributes (computed when first used)."""
        if self._turns is not None:
            self._missed = self._turns()
            self._turns = None
        return self._missed

    @property
    def plain(self) -> bool:
        """Whether the pieces are Ruckig's profiles as they are (no brake phase, no end correction)."""
        return self._plain

    def _made(self) -> None:
        if self._build is not None:
            self._knots, self._pieces = self._build()
            self._build = None

    @property
    def knots(self) -> np.ndarray:
        """Local knot times, shape (K,) [s]."""
        self._made()
        return self._knots

    @property
    def pieces(self) -> np.ndarray:
        """The stacked (p, v, a, j) at each knot, shape (4, K, dof)."""
        self._made()
        return self._pieces


def merge_segment(
    traj: RuckigTrajectory,
    duration: float,
    start: tuple[np.ndarray, np.ndarray, np.ndarray],
    end: np.ndarray | None = None,
    limits: JointLimits | None = None,
    profiles: list | None = None,
) -> SegmentPieces:
    """One Ruckig segment as constant-jerk pieces common to all joints.

    Every joint has its own seven phases (plus, for a start state beyond the limits, two brake
    phases); the pieces start at the union of their switching times.

    Ruckig's time synchronisation can lose precision on a joint whose move is small next to
    what its limits allow (1e-7 rad beside a joint that sets the duration: 20 % off; 3 mm at
    via speeds of mm/s: 4e-10 rad off). With `end`, such a joint's end error is removed by
    adding the jerk-limited S-curve of that distance over the segment (four equal phases of
    jerk +J, -J, -J, +J, J = 32 e / T^3), which leaves its start and end velocity and
    acceleration as they are; with `limits`, the corrected joint is checked against them.

    Args:
        traj: The Ruckig trajectory of the segment.
        duration: Its duration [s].
        start: The start state (q, qd, qdd), each shape (dof,): the segment starts exactly there.
        end: Target positions, shape (dof,) [rad or m]; None: no end correction.
        limits: Limits to check a corrected joint against.
        profiles: ``traj.profiles[0]`` if already read (see :meth:`SegmentSolver.profiles`).

    Returns:
        The pieces; their residual is the end error left per joint: where the correction
        would take a joint beyond its limits (a joint at its jerk limit all along), the joint
        keeps Ruckig's profile, and the caller decides (see
        :func:`planner.motion.plan.plan_trajectory_request`).
    """
    if profiles is None:
        profiles = traj.profiles[0]
    dof = len(profiles)
    if duration <= 0.0:
        return SegmentPieces(lambda: (np.empty(0), np.empty((4, 0, dof))), np.zeros(dof), None)
    if _plain_profiles(profiles, end):
        # The common case, decided from Ruckig's lists: the arrays are read when first used,
        # the turning points too (the range repair asks SegmentSolver.turns_beyond instead).
        def build_plain() -> tuple[np.ndarray, np.ndarray]:
            return _merged_pieces(*_profile_phases(profiles), duration, start)

        return SegmentPieces(build_plain, np.zeros(dof), None, lambda: _profile_turns(profiles))
    starts, phases = _profile_phases(profiles)
    pos = phases[0]

    def build(extra: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        return _merged_pieces(starts, phases, duration, start, extra)

    residual = np.zeros(dof)
    if end is not None:
        error = np.asarray(end, dtype=float) - pos[:, -1]  # each profile's end position
        off = np.abs(error) > END_TOLERANCE * np.maximum(1.0, np.abs(end))
        if off.any():
            knots, out = build(duration * np.array([0.25, 0.5, 0.75]))
            corrected = out.copy()
            if _add_s_curve(corrected, knots, duration, np.where(off, error, 0.0), limits):
                corrected[0, 0], corrected[1, 0], corrected[2, 0] = start
                return SegmentPieces(lambda: (knots, corrected), residual, None)
            residual = np.where(off, error, 0.0)
            return SegmentPieces(lambda: (knots, out), residual, _missed_turns(phases))
    return SegmentPieces(build, residual, _missed_turns(phases))


def _plain_profiles(profiles: list, end: np.ndarray | None) -> bool:
    """Whether :func:`merge_segment` takes Ruckig's profiles as they are.

    That is: no brake phase and every profile ending on `end` within :data:`END_TOLERANCE`
    (no end correction).

    Raises:
        RuntimeError: If a profile needed a post-profile (a via state beyond the limits).
    """
    goals = None if end is None else np.asarray(end, dtype=float).tolist()
    plain = True
    for k, prof in enumerate(profiles):
        # (Checked here for every profile, in the same pass.)
        if prof.accel.duration > 0:  # pragma: no cover - via states are admissible
            raise RuntimeError("Ruckig needed a post-profile: a via state exceeds the limits")
        if not plain:
            continue
        if prof.brake.duration > 0:
            plain = False
        elif goals is not None:
            goal = goals[k]
            if abs(goal - prof.p[-1]) > END_TOLERANCE * (goal if goal > 1.0 else -goal if goal < -1.0 else 1.0):
                plain = False
    return plain


def _profile_turns(profiles: list) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_missed_turns` from Ruckig's lists (for profiles :func:`_plain_profiles` accepts), bit for bit."""
    dof = len(profiles)
    low, high = [math.inf] * dof, [-math.inf] * dof
    for k, prof in enumerate(profiles):
        v = prof.v
        if min(v) < 0.0 < max(v):  # a sign change, often only a rounding at the end
            for turn in _zero_jerk_turns(prof, v):
                low[k], high[k] = min(low[k], turn), max(high[k], turn)
    return np.array(low), np.array(high)


def _profile_phases(profiles: list) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """Per joint, the phase start times (dof, P) and the (p, v, a, j) at each phase start (dof, P)."""
    dof = len(profiles)
    # An 8th phase holds the end state (zero jerk) in case a joint's profile ends early.
    jerk = np.array([prof.j + [0.0] for prof in profiles])
    acc = np.array([prof.a for prof in profiles])  # (dof, 8): phase starts and the end state
    vel = np.array([prof.v for prof in profiles])
    pos = np.array([prof.p for prof in profiles])
    starts = np.zeros((dof, 8))
    np.cumsum(np.array([prof.t for prof in profiles]), axis=1, out=starts[:, 1:])
    brakes = [prof.brake for prof in profiles]
    if any(b.duration > 0 for b in brakes):
        offset = np.array([b.duration for b in brakes])[:, None]
        bt = np.array([b.t for b in brakes])
        starts = np.hstack([np.zeros((dof, 1)), bt[:, :1], starts + offset])
        jerk = np.hstack([np.array([b.j for b in brakes]), jerk])
        acc = np.hstack([np.array([b.a for b in brakes]), acc])
        vel = np.hstack([np.array([b.v for b in brakes]), vel])
        pos = np.hstack([np.array([b.p for b in brakes]), pos])
        # A joint without a brake phase has zero-length ones: skip them.
        none = offset[:, 0] <= 0
        starts[none, :2] = 0.0
    return starts, (pos, vel, acc, jerk)


def _merged_pieces(
    starts: np.ndarray,
    phases: tuple[np.ndarray, ...],
    duration: float,
    start: tuple[np.ndarray, np.ndarray, np.ndarray],
    extra: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Local knots (the distinct phase starts, and `extra` times) and the stacked (p, v, a, j) there."""
    knots = np.sort(starts if extra is None else np.append(starts, extra), axis=None)
    knots = knots[knots < duration]
    first = np.empty(len(knots), dtype=bool)
    first[0] = True
    np.not_equal(knots[1:], knots[:-1], out=first[1:])
    knots = knots[first]  # the distinct phase starts (every profile starts at 0)
    out = _phase_states(knots, starts, phases)
    # The segment starts exactly at its waypoint state.
    out[0, 0], out[1, 0], out[2, 0] = start
    return knots, out


def _missed_turns(phases: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Per joint, the lowest and highest turning point inside a phase of zero jerk, shapes (dof,).

    Ruckig's position extrema miss them (see :func:`piece_position_range`): a velocity that
    changes sign across such a phase. inf and -inf where a joint has none.
    """
    pos, vel, acc, jerk = phases
    v0, a0 = vel[:, :-1], acc[:, :-1]
    turns = (jerk[:, :-1] == 0.0) & (v0 * vel[:, 1:] < 0.0)
    if not turns.any():
        return np.full(len(pos), np.inf), np.full(len(pos), -np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        tz = -v0 / a0
        p_turn = pos[:, :-1] + tz * (v0 + tz * a0 / 2.0)
    return np.where(turns, p_turn, np.inf).min(axis=1), np.where(turns, p_turn, -np.inf).max(axis=1)


def segment_position_range(
    traj: RuckigTrajectory, segment: SegmentPieces, duration: float
) -> tuple[np.ndarray, np.ndarray]:
    """Exact per-joint min and max position of a merged segment, shapes (dof,) [rad or m].

    Ruckig's own extrema (computed in C++) with the turning points they miss, or
    :func:`piece_position_range` where the pieces are not Ruckig's profile. The segment
    should have been merged with its `end`: Ruckig's extrema take its profile's end
    position, which the pieces reach only after the end correction.

    Args:
        traj: The Ruckig trajectory the segment was merged from.
        segment: What :func:`merge_segment` made of it.
        duration: The segment's duration [s].
    """
    if segment.missed is None:
        return piece_position_range(segment.knots, segment.pieces, duration)
    extrema = traj.position_extrema
    lo = np.array([e.min for e in extrema])
    hi = np.array([e.max for e in extrema])
    return np.minimum(lo, segment.missed[0]), np.maximum(hi, segment.missed[1])


def _phase_states(times: np.ndarray, starts: np.ndarray, phases: tuple[np.ndarray, ...]) -> np.ndarray:
    """The stacked (p, v, a, j), shape (4, len(times), dof), of per-joint phases at the given times."""
    pos, vel, acc, jerk = phases
    # The phase of each joint in force at each time (the last one starting at or before it).
    idx = np.count_nonzero(starts[:, None, :] <= times[None, :, None], axis=2).T - 1  # (K, dof)
    flat = idx + np.arange(starts.shape[0]) * starts.shape[1]
    dt = times[:, None] - starts.ravel()[flat]
    out = np.empty((4,) + flat.shape)
    p0, v0, a0, j0 = pos.ravel()[flat], vel.ravel()[flat], acc.ravel()[flat], jerk.ravel()[flat]
    out[0] = p0 + dt * (v0 + dt * (a0 / 2.0 + dt * j0 / 6.0))
    out[1] = v0 + dt * (a0 + dt * j0 / 2.0)
    out[2] = a0 + dt * j0
    out[3] = j0
    return out


def _add_s_curve(
    out: np.ndarray, knots: np.ndarray, duration: float, error: np.ndarray, limits: JointLimits | None
) -> bool:
    """Add to the pieces the rest-to-rest S-curve over `error` [rad or m] per joint (see merge_segment).

    Returns:
        Whether the corrected joints stay within `limits` (True without limits).
    """
    quarter = duration / 4.0
    big_j = 32.0 * error / duration**3
    # Phase starts (p, v, a) of the S-curve and its jerk per phase.
    signs = (1.0, -1.0, -1.0, 1.0)
    # Per phase (rows) its start state and jerk, shapes (4, dof).
    table = np.zeros((4, 4, len(error)))
    p, v, a = table[0, 0], table[1, 0], table[2, 0]
    for phase, sign in enumerate(signs):
        j = table[3, phase] = sign * big_j
        if phase < 3:
            p = table[0, phase + 1] = p + quarter * (v + quarter * (a / 2.0 + quarter * j / 6.0))
            v = table[1, phase + 1] = v + quarter * (a + quarter * j / 2.0)
            a = table[2, phase + 1] = a + quarter * j
    # Every knot at once, with the operations of one knot (the same values bit for bit).
    phase = np.minimum((knots / quarter + 1e-9).astype(np.intp), 3)
    dt = (knots - phase * quarter)[:, None]
    p, v, a, j = table[:, phase]
    out[0] += p + dt * (v + dt * (a / 2.0 + dt * j / 6.0))
    out[1] += v + dt * (a + dt * j / 2.0)
    out[2] += a + dt * j
    out[3] += j
    if limits is None:
        return True
    h = np.append(np.diff(knots), duration - knots[-1])[:, None]
    v0, a0, j0 = out[1], out[2], out[3]
    # Velocity extremes inside a piece lie where the acceleration crosses zero.
    with np.errstate(divide="ignore", invalid="ignore"):
        tz = np.where(j0 != 0.0, -a0 / j0, -1.0)
    inside = (tz > 0.0) & (tz < h)
    v_ext = np.where(inside, v0 + tz * (a0 + tz * j0 / 2.0), 0.0)
    a_end = a0 + h * j0
    v_end = v0 + h * (a0 + h * j0 / 2.0)
    tol = 1.0 + LIMIT_TOLERANCE
    corrected = error != 0.0
    speed = np.maximum.reduce([np.abs(v0), np.abs(v_end), np.abs(v_ext)])
    return not (
        np.any((np.abs(j0) > limits.jerk * tol) & corrected)
        or np.any((np.maximum(np.abs(a0), np.abs(a_end)) > limits.acceleration * tol) & corrected)
        or np.any((speed > limits.velocity * tol) & corrected)
    )


def brake_segment(
    q0: np.ndarray, v0: np.ndarray, a0: np.ndarray, limits: JointLimits
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Bring every joint to rest as fast as it can, each on its own (unsynchronised).

    Args:
        q0: Start positions, shape (dof,) [rad or m].
        v0: Start velocities, shape (dof,).
        a0: Start accelerations, shape (dof,).
        limits: The limits.

    Returns:
        Duration [s], local knots, stacked (p, v, a, j) pieces and the rest positions.

    Raises:
        InvalidArgumentError: If even that carries a joint outside its range.
    """
    dof = len(q0)
    inp = InputParameter(dof)
    inp.control_interface = ControlInterface.Velocity
    inp.synchronization = Synchronization.No
    inp.current_position, inp.current_velocity, inp.current_acceleration = q0.tolist(), v0.tolist(), a0.tolist()
    inp.target_velocity, inp.target_acceleration = [0.0] * dof, [0.0] * dof
    inp.max_velocity = limits.velocity.tolist()
    inp.max_acceleration = limits.acceleration.tolist()
    inp.max_jerk = limits.jerk.tolist()
    traj = RuckigTrajectory(dof)
    try:
        result = Ruckig(dof).calculate(inp, traj)
    except (RuckigError, ValueError) as exc:  # ValueError: -101, braking would take over 7e3 s
        result = exc
    if result not in (Result.Working, Result.Finished):  # braking has a profile within Ruckig's 7e3 s
        raise InvalidArgumentError(f"cannot brake from the start state within the limits (Ruckig: {result})")
    duration = float(traj.duration)
    rest = np.array([prof.p[-1] for prof in traj.profiles[0]])
    merged = merge_segment(traj, duration, (q0, v0, a0))
    local, pieces = merged.knots, merged.pieces
    lo, hi = piece_position_range(local, pieces, duration) if len(local) else (q0, q0)
    lower, upper = range_with_tolerance(limits)
    bad = np.nonzero((lo < lower) | (hi > upper))[0]
    if bad.size:
        jj = int(bad[0])
        reach = lo[jj] if lo[jj] < lower[jj] else hi[jj]
        raise InvalidArgumentError(
            f"the start state carries joint {limits.joint_names[jj]!r} to {reach:.6g}, outside its range "
            f"[{limits.lower[jj]:.6g}, {limits.upper[jj]:.6g}], even braking at once; "
            "lower the start velocity or acceleration"
        )
    return duration, local, pieces, np.clip(rest, limits.lower, limits.upper)
