"""A second pass over the via states: per-joint velocity steps, timed by one unsynchronised Ruckig probe.

The first pass chooses each via next to a neighbour that is chosen after it (the via that
follows still holds its spline state): once every via is chosen, each one's best state given
its final neighbours is a little different. A segment lasts as long as its slowest joint needs
and each joint's time depends on its own states only, so the joints that set a segment's time
(within :data:`BINDING` of it) have their velocity moved by a few shares of the speed limit
either way (:data:`STEPS`; the acceleration kept within
:func:`planner.motion.limits.admissible_acceleration`); one Ruckig call times every such
(option, joint, segment) (:meth:`planner.motion.segments.SegmentSolver.probe_around`) and
:func:`best_choice` gives each joint its best option. The result is solved and kept only where
it is faster, its segments stay within the range (by Ruckig's extrema), reach their ends and
turn no joint beyond the range inside a phase of zero jerk (as the first pass keeps its states).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence

import numpy as np

from planner.motion.vias.base import ViaChain, best_choice
from planner.motion.vias.kernels import moved_states_compiled

__all__ = ["BINDING", "STEPS", "moved_states", "resweep_via", "step_binding_joints"]

#: The velocity steps of the second pass, shares of the speed limit (each taken either way, all
#: in one probe). Over every via of bench_trajectory's paths (seed 0) the median optimum gap falls
#: from 1.02 % to 0.71 %; 0.05 alone gives 0.83 %, 0.02, 0.05 and 0.1 0.68 % (more probed
#: entries), steps up to 0.2 gain no more. Two probes in turn (0.05 then 0.025) gave 0.74 %.
STEPS = (0.03, 0.1)
#: A joint sets a segment's time where its own time is at least this share of the segment's.
BINDING = 0.98


def moved_states(
    limits: tuple[Sequence[float], Sequence[float], Sequence[float]],
    state: tuple[list[float], list[float]],
    joints: Sequence[int],
    moves: Sequence[float],
) -> list[tuple[list[float], list[float]]]:
    """The states of `joints` with their velocity moved by each of `moves`, on plain floats.

    Args:
        limits: Per joint (all joints) the speed and acceleration limits and twice the jerk limit.
        state: Velocities and accelerations, lists over all joints.
        joints: The joints moved.
        moves: The moves, signed shares of the speed limit.

    Returns:
        Per move the velocities and accelerations of `joints`: each velocity clipped to the
        speed limit, each acceleration the joint's, limited as
        :func:`planner.motion.limits.admissible_acceleration` limits it (the same operations).
    """
    fast = moved_states_compiled(limits, state, joints, moves)  # compiled, the same operations
    if fast is not None:
        return fast
    velocity, acceleration, twice_jerk = limits
    cv, ca = state
    rows = [(velocity[j], acceleration[j], twice_jerk[j], cv[j], ca[j]) for j in joints]
    out = []
    for move in moves:
        nv, na = [], []
        for top, most, tj, x, y in rows:
            x += move * top
            x = top if x > top else -top if x < -top else x
            room = top - (x if x >= 0.0 else -x)
            amax = math.sqrt(tj * room) * (1.0 - 1e-9) if room > 0.0 else 0.0
            if amax > most:
                amax = most
            nv.append(x)
            na.append(amax if y > amax else -amax if y < -amax else y)
        out.append((nv, na))
    return out


def step_candidates(
    limits: tuple[Sequence[float], Sequence[float], Sequence[float]],
    state: tuple[list[float], list[float]],
    joints: Sequence[int],
    steps: Sequence[float],
) -> list[tuple[list[float], list[float]]]:
    """:func:`moved_states` with each of `steps` (positive) taken down, then up."""
    return moved_states(limits, state, joints, [-s for s in steps] + list(steps))


def step_binding_joints(
    chain: ViaChain,
    i: int,
    state: tuple[list[float], list[float]],
    times: tuple[list[float], list[float]],
    steps: Sequence[float] = STEPS,
    among: Collection[int] | None = None,
) -> bool:
    """Move the joints that set a segment's time at via i by :data:`STEPS` where that is faster.

    The other joints keep their states: for :func:`best_choice` they count as one joint
    with their largest times.

    Args:
        chain: The chain.
        i: The via.
        state: Velocities and accelerations at via i, lists over all joints (changed in place).
        times: Per joint its times in the segments before and after the via [s] (changed in
            place: a joint moved gets its probed times).
        steps: The moves, shares of the speed limit (each taken either way).
        among: The joints that may move (those of them that set a segment's time); None for all.

    Returns:
        Whether any joint moved.
    """
    cv, ca = state
    c1, c2 = times
    d1, d2 = BINDING * max(c1), BINDING * max(c2)
    joints, rest1, rest2 = [], 0.0, 0.0
    for j, (x, y) in enumerate(zip(c1, c2)):
        if (x >= d1 or y >= d2) and (among is None or j in among):
            joints.append(j)
        else:
            rest1 = x if x > rest1 else rest1
            rest2 = y if y > rest2 else rest2
    if not joints or not steps:
        return False
    joints = tuple(joints)
    lim = chain.limits
    velocity, acceleration, _ = lim.ruckig_limits
    candidates = step_candidates((velocity, acceleration, lim.twice_jerk.tolist()), state, joints, steps)
    start = (chain.v[i - 1].tolist(), chain.acc[i - 1].tolist())
    end = (chain.v[i + 1].tolist(), chain.acc[i + 1].tolist())
    probed = chain.seg.probe_around(i, start, end, joints, candidates)
    if probed is None:
        return False
    p1, p2 = probed
    count = len(joints)
    # Per option a row over the moved joints and one more for all the others (their current times).
    rows1 = [[c1[j] for j in joints] + [rest1]]
    rows2 = [[c2[j] for j in joints] + [rest2]]
    for c in range(len(candidates)):
        rows1.append(p1[c * count : (c + 1) * count] + [math.inf])
        rows2.append(p2[c * count : (c + 1) * count] + [math.inf])
    _, choice = best_choice(rows1, rows2)
    if choice is None:
        return False
    picks = choice.tolist()
    for m, j in enumerate(joints):
        g = picks[m]
        if g:
            nv, na = candidates[g - 1]
            cv[j], ca[j] = nv[m], na[m]
            c1[j], c2[j] = rows1[g][m], rows2[g][m]
    return True


def resweep_via(chain: ViaChain, i: int, steps: Sequence[float] = STEPS, among: Collection[int] | None = None) -> bool:
    """Second-pass step at via i: :func:`step_binding_joints`, kept where the solved pair is faster.

    `among`: the joints that may move (see :func:`step_binding_joints`); None for all.

    The current state is kept unless the new one's two segments are faster, within the range
    (by Ruckig's extrema and ``SegmentSolver.turns_beyond``) and reach their ends
    (``SegmentSolver.misses_end``). A current state that does not satisfy this is left alone.

    Returns:
        Whether the via state changed.
    """
    seg = chain.seg
    va, aa, vb, ab = chain.v[i - 1], chain.acc[i - 1], chain.v[i + 1], chain.acc[i + 1]
    both = seg.around(i, va, aa, vb, ab)
    (d1, bad1, traj1), (d2, bad2, traj2) = both(chain.v[i], chain.acc[i])
    if traj1 is None or traj2 is None or bad1 is not None or bad2 is not None:
        return False
    state = (chain.v[i].tolist(), chain.acc[i].tolist())
    times = (traj1.independent_min_durations, traj2.independent_min_durations)
    if not step_binding_joints(chain, i, state, times, steps, among):
        return False
    cv, ca = np.array(state[0]), np.array(state[1])
    (e1, bad1, traj1), (e2, bad2, traj2) = both(cv, ca)
    if traj1 is None or traj2 is None or bad1 is not None or bad2 is not None or not e1 + e2 < d1 + d2:
        return False
    if seg.misses_end(i - 1, va, aa, cv, ca) or seg.misses_end(i, cv, ca, vb, ab):
        return False
    if seg.turns_beyond(i - 1, traj1) or seg.turns_beyond(i, traj2):
        return False
    chain.v[i], chain.acc[i] = cv, ca
    return True
