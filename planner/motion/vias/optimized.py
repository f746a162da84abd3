"""The ``"optimized"`` via strategy (the default): a per-joint spline run search, then a search per via.

All via states between two fixed waypoints are first chosen together: the C2 cubic spline
through the waypoints at the segment durations gives every via a velocity and an acceleration
consistent with all the others (a joint with time to spare may pass its waypoint still moving
and turn just beyond it, as a spline does). A segment lasts as long as its slowest joint needs,
and each joint's time depends on its own states only: so the splines at a few time scales of
the durations, and the current states, are options per joint along the whole run, all timed by
one unsynchronised Ruckig probe, and every joint that sets a segment's time takes in turn the
option that makes the run fastest (each joint its own time scale: the optimum through the
waypoints has several joints setting each segment's time, each on its own pattern). Then each
via is refined on its own: scaling time by 1/x multiplies velocities by x and accelerations by
x^2, so the states ``(x v, x^2 a)`` of the slope blend (each joint saturating at its limits) on
a grid, the current velocity moved a little either way, and a time-optimal turn where a joint
reverses at the waypoint (at rest, still braking at full deceleration) are options per joint,
timed by one more probe; every joint takes its best option and the pick is confirmed by one
solve. Where the probes' per-joint times do not tell the segments' durations (a segment
lasting longer than its slowest joint needs: Ruckig's blocked intervals; or no profile within
the range), or where the pick is not kept once solved (slower, turning beyond the range or
missing a segment's end), the grid states are
solved one by one instead (resting at the via, scale 0, among them) and every joint picks among
those. Each search keeps the current state unless a candidate is faster.
Candidates that carry a joint out of its range (by Ruckig's extrema) have that joint's state
halved (a probed option whose joint's own profile leaves the range is not taken), and the
state kept at a via turns no joint beyond its range inside a phase of zero jerk (which Ruckig's
extrema miss and the planner's range repair would halve at any cost). A second pass
(:attr:`OptimizedStrategy.resweep_vias`, off by default) re-steps vias given their final
neighbours (:mod:`planner.motion.vias.joint_steps`). Arms of at most
:attr:`OptimizedStrategy.polish_joints` joints (5) then have every via stepped so, with finer
and finer steps, while a via changes (:meth:`OptimizedStrategy.polish`); the other arms have
every via stepped once (:attr:`OptimizedStrategy.step_pass`), their sweep without the fixed
velocity steps and the solved grid where the pick is not kept.

On bench_trajectory's paths (8 arms x 100, 5 waypoints; every 4th solved as an NLP, the
optimum gap is the median of duration / optimum - 1), against the golden-section search of one
common spline scale and the solved grid walk at every via before: optimum gap 1.01 -> 0.93 %
(seed 1: 0.88 -> 0.76 %), mean duration -0.08 %, 0.96 x the instructions per 6-dof plan
(callgrind, 60 plans of ur5, z1 and panda). With the second pass over the first two vias of
each run (``resweep_vias=2``) 0.72 % (seed 1: 0.54 %) at 1.05 x, over every via 0.56 % (0.43 %)
at about 1.10 x. The polish of the arms of 2 to 5 joints: 0.93 -> 0.50 % (seed 1: 0.76 -> 0.43 %),
those arms' plan time about doubled, 6-dof plans unchanged (about 3 % faster with the probe of
the joints within 0.9 of a segment's time and no rest state in the probed grid, the same plans).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from operator import itemgetter

import numpy as np

from planner.exceptions import InvalidArgumentError
from planner.motion.limits import JointLimits, admissible_acceleration
from planner.motion.vias.base import SEARCH_HALVINGS, ViaChain, ViaStrategy, best_choice
from planner.motion.vias.heuristic import via_directions
from planner.motion.vias.joint_steps import STEPS as RESWEEP_STEPS
from planner.motion.vias.joint_steps import moved_states, resweep_via
from planner.motion.vias.kernels import choose_joints, choose_probed, scale_states, spline_states

#: Largest time scale searched: keeps x * x finite where a via component is tiny (x * 0 is then
#: 0, not NaN), far beyond any scale at which every joint already saturates.
_MAX_SCALE = 1e100

__all__ = ["OptimizedStrategy", "golden_minimum", "golden_points", "spline_via_states"]

# Scale factors of the slope blend for each via state (1 = the blend itself). The sweep probes
# these states per joint (with the velocity steps and the turn below, one Ruckig call); where
# probes do not apply (see _probes_apply) or found nothing faster, the grid is walked, each state
# solved, from _GRID_START (the most frequent best) up while the duration falls, else down, and
# every joint picks its best among the states tried (combine_joints). The probed grid leaves out
# the scale 0 (resting at the via): no joint picked it on 300 6-dof plans, and no plan's
# duration changed on bench_trajectory's paths without it (1.4 % fewer instructions per plan).
_GRID = (0.0, 1.4, 2.0, 3.0)
_GRID_START = 1.4
# Spline stage (OptimizedStrategy.search_spline): the log time-scales of the segment durations
# whose splines give each joint its options along a run, the rounds of the per-joint choice among
# them, and how often joints whose extrema leave the range go back to the current states before
# the run keeps those. Only the joints whose time in a segment is at least _RUN_NEAR of the
# segment's with the current states are probed (the others keep them: no change on
# bench_trajectory's 800 paths at 0.5, +0.01 % mean duration at 0.7; _RUN_NEAR_STEPPED for the
# arms with the step pass, see _STEP_PASS). Where the mix, solved, is not faster (blocked
# intervals), the options common to all joints are solved instead. Three scales (-0.45, -0.2,
# 0.05) gave the same gaps within 0.05 % (and no fewer instructions with the step pass).
_SPLINE_SCALES = (-0.5, -0.3, -0.1, 0.1)
_CHOICE_ROUNDS = 2
_SPLINE_FIXES = 2
_RUN_NEAR = 0.7
_RUN_NEAR_STEPPED = 0.9
_FALLBACK_PROBE = False
# How many of the fastest states tried at a via that turn beyond the range are halved in turn
# (as the search halves states that leave it) before slower ones that fit are taken.
_TURN_HALVED = 1
# Rounds of halving the via states that leave the range before the search.
_SETTLE_HALVINGS = 24
# The per-joint options each via's joint choice probes besides the states tried: the velocity
# moved by these shares of the speed limit (the acceleration kept within the admissible range),
# for the joints whose time in a segment next to the via is at least _PROBE_NEAR of the
# segment's (the others cannot shorten it). On bench_trajectory's paths (seed 0) the median
# optimum gap falls from 1.34 % to 1.02 %; steps of 0.15 as well give 0.95 % at +8 %
# instructions per plan, a dense grid of 21 velocities and 3 accelerations per joint 0.54 %
# (one sweep) at many times the plan time. Probing the joints within 0.8 of the segment's time
# (not 0.9) made 4 % more instructions per 6-dof plan for no shorter plan on those paths
# (_PROBE_NEAR_STEPPED for the arms with the step pass, see _STEP_PASS).
_PROBE_STEPS = (-0.05, 0.05)
_PROBE_NEAR = 0.9
_PROBE_NEAR_STEPPED = 0.97
# Where the probed pick at a via, kept once solved, moved at least this many joints, those of
# them that now set a segment's time can have their velocity steps (OptimizedStrategy.reprobe_steps,
# off by default) probed again around their new states (resweep_via among them): the first probe
# took the steps around the states before the pick only. bench_trajectory's 6-dof paths (ur5, z1,
# panda) with their stored NLP optima, seeds 0 and 1: median optimum gap 0.67 -> 0.51 % with
# (0.05,), 0.44 % with (0.03, 0.1); about one such probe per plan, 6 in 10 kept. Its cost: +5 %
# instructions per 6-dof plan, but about +7 % time in a warm loop (ur5, z1; the two solves and
# checks of the new state more than the probe), more than _PROBE_NEAR 0.9 and the probed grid
# without scale 0 save (-3 %). Probing the steps around the pick before solving it (no second
# solve) gave 0.52 % at +5.5 % time.
_REPROBE_MOVED = 2
# A segment counts as lasting as long as its slowest joint needs up to this factor (rounding).
_OWN_TIMES = 1.0 + 1e-9
# The second pass (planner.motion.vias.joint_steps), off by default: on bench_trajectory's paths
# (seed 0; 5 waypoints, 3 vias) over the first two vias of each run (2) the median optimum gap
# falls from 0.93 % to 0.72 % (seed 1: 0.76 to 0.54 %; mean duration -0.24 %) at +10 %
# instructions per 6-dof plan (1.05 x those of the golden-section run search and solved grid
# walk before), over every via (None) to 0.56 % (0.43 %; mean duration -0.36 %) at about 1.10 x:
# most of a visit's cost is fixed (the probe call, the joint choice, the solve and range checks).
_RESWEEP_VIAS: int | None = 0
# The polish of arms with few joints (OptimizedStrategy.polish_joints): after the sweep, every
# via is stepped (planner.motion.vias.joint_steps.resweep_via) with each pair of velocity steps
# in turn, coarse to fine, in up to _POLISH_ROUNDS rounds per pair, a round visiting only the
# vias that changed in the one before and their neighbours. With few joints a segment's time is
# set by one or two joints, whose states at neighbouring vias trade time with each other: one
# pass of steps leaves much of that (bench_trajectory's paths, seed 0: the arms of 2 to 5 joints'
# median optimum gaps 0.96-1.41 % without the polish, 0.79-1.25 % with one pass over every via,
# 0.31-0.50 % with these three pairs and two rounds; one round 0.45-0.66 %, three 0.27-0.50 %;
# all arms, seeds 0 and 1: two rounds 0.505 and 0.431 %, three 0.493 and 0.408 %, a fourth pair
# (0.001, 0.003) 0.504 and 0.428 %). It about doubles those arms' plan time (so101 0.85 -> 1.98
# ms with three rounds, 1.78 ms with two; ur5 and z1 0.95 ms in the same loop): an arm of more
# joints (6-dof: +10 % per pass over every via) keeps the one sweep.
_POLISH_JOINTS = 5
# The step pass of the arms not polished (OptimizedStrategy.step_pass): after the sweep, every
# via is stepped once (resweep_via with the resweep_steps (0.03, 0.1), given its final
# neighbours), and that sweep probes no fixed velocity steps (_PROBE_STEPS) and solves no grid
# where the probed pick is not kept (the step pass moves such a via as well, for far less: that
# fallback cost 10.6 % of the instructions per 6-dof plan for about 15 % of the vias). On
# bench_trajectory's 6-dof paths (ur5, panda, z1) with their NLP optima, seeds 0 and 1 (150
# paths): median optimum gap 0.67 -> 0.33 % (ur5 0.51 -> 0.18, panda 0.71 -> 0.21, z1 0.83 ->
# 0.55 %), mean duration -0.24 % (3 paths slower by more than 0.5 %, at most 1.2 %; 27 faster);
# with the fallback and the fixed steps kept 0.27 % at +18 % instructions per 6-dof plan. The
# probes of fewer joints for these arms (_PROBE_NEAR_STEPPED 0.97, _RUN_NEAR_STEPPED 0.9; about
# the same gaps, 2 % fewer instructions than 0.95 and 0.8) pay for the rest: -3.6 % instructions
# per 6-dof plan in all (callgrind, four sets of 60 random plans of ur5, z1 and panda: +0.5,
# -8.1, -4.8 and -1.3 %). A second step pass over the vias the first one changed: median gap
# 0.13 % (z1 0.45 %) at +11 %. The small arms' probes keep their shares: with these, al5c and
# so101 plans were 0.1 % longer on average.
_STEP_PASS = True
_POLISH_STEPS = ((0.03, 0.1), (0.01, 0.03), (0.003, 0.01))
_POLISH_ROUNDS = 3


def golden_minimum(f: Callable[[float], float], lo: float, hi: float, evals: int) -> float:
    """Golden-section search for a minimum of f on [lo, hi] with `evals` evaluations.

    Returns:
        The best argument found (every evaluation goes through `f`, so a caching `f` keeps them all).
    """
    g = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
    f1, f2 = f(x1), f(x2)
    for _ in range(max(evals - 2, 0)):
        if f1 <= f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - g * (hi - lo)
            f1 = f(x1)
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + g * (hi - lo)
            f2 = f(x2)
    return x1 if f1 <= f2 else x2


def golden_points(lo: float, hi: float, evals: int) -> set[float]:
    """Every argument :func:`golden_minimum` may evaluate on [lo, hi] with `evals` evaluations.

    Both outcomes of each comparison are followed, with the same arithmetic.
    """
    g = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
    points = {x1, x2}
    brackets = [(lo, hi, x1, x2)]
    for _ in range(max(evals - 2, 0)):
        following = []
        for lo_, hi_, x1_, x2_ in brackets:
            left = x2_ - g * (x2_ - lo_)  # f1 <= f2: the bracket [lo, x2] with x1 kept as its upper point
            right = x1_ + g * (hi_ - x1_)  # else: [x1, hi] with x2 kept as its lower point
            points.update((left, right))
            following += [(lo_, x2_, left, x1_), (x1_, hi_, x2_, right)]
        brackets = following
    return points


# The inverse time scales exp(-x) of the spline stage and those squared, the same for every run.
_SPLINE_INV = np.array([math.exp(-x) for x in _SPLINE_SCALES])[:, None, None]
_SPLINE_INV2 = _SPLINE_INV * _SPLINE_INV


def spline_via_states(
    q: np.ndarray, h: np.ndarray, v_start: np.ndarray, v_end: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations at the inner knots of a cubic spline through waypoints.

    The C2 cubic spline through ``q[k]`` at the times ``cumsum(h)``, with the given end
    velocities (a clamped spline), couples every via to all others through the knot times.

    Args:
        q: Waypoints of the run, shape (m+1, dof), m >= 2.
        h: Segment durations, shape (m,) [s], positive.
        v_start: Velocity at ``q[0]``, shape (dof,).
        v_end: Velocity at ``q[m]``, shape (dof,).

    Returns:
        Velocities and accelerations at ``q[1:m]``, shapes (m-1, dof).
    """
    fast = spline_states(q, h, v_start, v_end)  # compiled, the same operations (None: the loops below)
    if fast is not None:
        return fast
    # On plain floats (a few vias and joints: faster than NumPy), row by row the operations the
    # array form (``slope = diff(q) / h``, ``rhs = 3 (slope[:-1] inv[:-1] + slope[1:] inv[1:])``, ...) has.
    rows, hs = q.tolist(), h.tolist()
    m = len(hs)
    inv = [1.0 / x for x in hs]
    slope = [[(y - x) / span for x, y in zip(r0, r1)] for r0, r1, span in zip(rows, rows[1:], hs)]
    # Tridiagonal system for v_1 .. v_{m-1} (Thomas algorithm, one right-hand side per joint).
    rhs = [[3.0 * (x * i0 + y * i1) for x, y in zip(s0, s1)] for s0, s1, i0, i1 in zip(slope, slope[1:], inv, inv[1:])]
    first, last = inv[0], inv[-1]
    rhs[0] = [x - first * y for x, y in zip(rhs[0], v_start.tolist())]
    end = v_end.tolist()
    rhs[-1] = [x - last * y for x, y in zip(rhs[-1], end)]
    diag = [2.0 * (x + y) for x, y in zip(inv, inv[1:])]
    c = [inv[1] / diag[0]]
    den = diag[0]
    d = [[x / den for x in rhs[0]]]
    for r in range(1, m - 1):
        den = diag[r] - inv[r] * c[r - 1]
        c.append(inv[r + 1] / den)
        ir = inv[r]
        d.append([(x - ir * y) / den for x, y in zip(rhs[r], d[r - 1])])
    v = d[:]
    for r in range(m - 3, -1, -1):
        cr = c[r]
        v[r] = [x - cr * y for x, y in zip(d[r], v[r + 1])]
    acc = [
        [(6.0 * s - 4.0 * x - 2.0 * y) * i for s, x, y in zip(sr, vr, nr)]
        for sr, vr, nr, i in zip(slope[1:], v, [*v[1:], end], inv[1:])
    ]
    return np.array(v), np.array(acc)


def _scaled_states(
    x: np.ndarray, su: np.ndarray, mag: np.ndarray, sw: np.ndarray, wmag: np.ndarray, limits: JointLimits
) -> tuple[np.ndarray, np.ndarray]:
    """The via states ``(x u, x^2 w)`` of :meth:`OptimizedStrategy.search_via`, shapes (G, dof).

    Per scale x (shape (G,)) the velocity ``sign(u) min(v_max, x |u|)`` and the acceleration
    ``sign(w) min(a_max, x^2 |w|)`` made admissible: :func:`admissible_acceleration` with
    ``|cv|`` at hand (bit for bit the same values; its ``max(v_max - |cv|, 0)`` is a no-op here),
    every zero positive (a state at rest has one cache key in :meth:`SegmentSolver.solve`,
    whatever the signs of the direction; -0.0 and 0.0 solved the same segment twice).
    """
    x = x[:, None]
    speed = np.minimum(limits.velocity, x * mag)  # |cv|, bit for bit
    cv = su * speed
    ca = sw * np.minimum(limits.acceleration, x * x * wmag)
    amax = np.subtract(limits.velocity, speed, out=speed)
    np.multiply(limits.twice_jerk, amax, out=amax)
    np.sqrt(amax, out=amax)
    amax *= 1.0 - 1e-9
    np.minimum(limits.acceleration, amax, out=amax)
    np.minimum(ca, amax, out=ca)
    np.maximum(ca, np.negative(amax, out=amax), out=ca)
    cv += 0.0  # zeros positive: a state that rests a joint has one cache key
    ca += 0.0
    return cv, ca


def _joint_choice(times: list[float], shape: tuple[int, int, int]) -> list[int] | None:
    """Per joint one of several options along a run, so that the run's duration (estimated) falls.

    The run's duration is estimated as the sum over its segments of the slowest joint's time.

    From the best option common to all joints, each joint that sets a segment's time takes in
    turn the option that makes the sum smallest given the others' choices (the first smallest:
    its own unless beaten), for :data:`_CHOICE_ROUNDS` rounds or until none changes.

    Args:
        times: Per option, segment and joint, the joint's time [s] (inf: not allowed), flat
            (option by option, segment by segment).
        shape: The number of options, segments and joints.

    Returns:
        The option per joint, or None where every option has an inf.
    """
    fast = choose_joints(times, shape, _CHOICE_ROUNDS)  # compiled, the same loop (False: none, or a NaN)
    if fast is not False:
        return fast
    count, m, dof = shape
    span = m * dof
    times = [[times[c * span + r * dof : c * span + (r + 1) * dof] for r in range(m)] for c in range(count)]
    totals = [sum(map(max, option)) for option in times]
    best = min(totals)
    if not best < math.inf:
        return None
    first = totals.index(best)
    choice = [first] * dof
    chosen = [list(row) for row in times[first]]  # per segment the chosen times of every joint
    for _ in range(_CHOICE_ROUNDS):
        changed = False
        for j in range(dof):
            if not any(row[j] >= max(row) for row in chosen):
                continue  # the joint sets no segment's time: no option of its own makes the run faster
            others = [max(row[:j] + row[j + 1 :], default=0.0) for row in chosen]
            pick = choice[j]
            for c, option in enumerate(times):
                total = 0.0
                for o, row in zip(others, option):
                    t = row[j]
                    total += o if o > t else t
                if total < best:
                    best, pick = total, c
            if pick != choice[j]:
                choice[j], changed = pick, True
                for row, option_row in zip(chosen, times[pick]):
                    row[j] = option_row[j]
        if not changed:
            break
    return choice


def _grid_top(u: np.ndarray, w: np.ndarray, lim: JointLimits) -> float:
    """The largest scale of the grid of states ``(x u, x^2 w)``: where the last joint stops gaining speed."""
    tops = [1.0]
    # On plain floats: the largest scale at which a joint still gains speed (acceleration).
    velocity, acceleration, _ = lim.ruckig_limits
    scales = [top / m for top, m in zip(velocity, map(abs, u.tolist())) if m > 0]
    if scales:
        tops.append(max(scales))
    scales = [top / m for top, m in zip(acceleration, map(abs, w.tolist())) if m > 0]
    if scales:
        tops.append(math.sqrt(max(scales)))
    return min(max(tops), _MAX_SCALE)


def _capped_grid(top: float) -> list[float]:
    """The scales of :data:`_GRID` capped at `top` (see :func:`_grid_top`), and `top` itself, ascending."""
    if top > _GRID[-1]:
        return [*_GRID, top]  # (the common case of the line below: _GRID is sorted)
    return sorted({min(g, top) for g in _GRID} | {top})


def _grid_candidates(x: list[float], u: np.ndarray, w: np.ndarray, lim: JointLimits) -> tuple[np.ndarray, np.ndarray]:
    """The admissible states ``(x u, x^2 w)`` at the scales x, shapes (G, dof) (:func:`_scaled_states`)."""
    fast = scale_states(x, u, w, lim.kernel_limits)  # compiled, the same operations
    if fast is not None:
        return fast
    return _scaled_states(np.array(x), np.sign(u), np.abs(u), np.sign(w), np.abs(w), lim)


def _probes_apply(chain: ViaChain, i: int) -> bool:
    """Whether the sweep may probe the grid states at via i per joint instead of solving them.

    That is where both segments next to via i, with its current state, have a profile within
    the range and last as long as their slowest joint alone needs. Where Ruckig's time
    synchronisation makes a segment last longer (a joint cannot take the slowest joint's time:
    its blocked intervals), the per-joint times of probes say little about the solved
    durations; where the current state has no such profile, the states solved on the grid are
    the fallbacks of :meth:`OptimizedStrategy.combine_joints`.
    """
    v, acc = chain.state_rows()
    seg = chain.seg
    (d1, bad1, traj1), (d2, bad2, traj2) = seg.solve_around(i, v[i - 1], acc[i - 1], v[i], acc[i], v[i + 1], acc[i + 1])
    if traj1 is None or traj2 is None or bad1 is not None or bad2 is not None:
        return False
    return (
        d1 <= max(traj1.independent_min_durations) * _OWN_TIMES
        and d2 <= max(traj2.independent_min_durations) * _OWN_TIMES
    )


def _gather(indices: list[int]) -> Callable[[Sequence[float]], tuple[float, ...]]:
    """The entries of a sequence at `indices`, as a tuple (one :func:`operator.itemgetter` call)."""
    if len(indices) == 1:
        (index,) = indices
        return lambda seq: (seq[index],)
    return itemgetter(*indices)


def _probed_choice(
    t1s: list[Sequence[float]],
    t2s: list[Sequence[float]],
    probed: tuple[list, tuple[int, ...], tuple[list[float], list[float]]] | None,
) -> list[int] | None:
    """:func:`best_choice` among the options timed (rows) and those probed (:meth:`OptimizedStrategy._probe_options`).

    Returns:
        Per joint the option to take (probed state c is option ``len(t1s) + c``), or None where
        no choice is better.
    """
    if probed is None:
        choice = best_choice(t1s, t2s)[1]
        return None if choice is None else choice.tolist()
    _, joints, times = probed
    fast = choose_probed(t1s, t2s, times, joints)  # compiled, the rows below (None: a NaN, or no library)
    if fast is not None:
        return fast[1]
    p1, p2 = times
    count, dof = len(joints), len(t1s[0])
    # Per joint where its entry lies: the m-th probed joint at m, the others after the probed
    # entries (an inf time: their current state), gathered by one itemgetter.
    where = {j: m for m, j in enumerate(joints)}
    entries = _gather([where.get(j, count) for j in range(dof)])
    tail = [math.inf]
    rows1 = [entries(p1[c : c + count] + tail) for c in range(0, len(p1), count)]
    rows2 = [entries(p2[c : c + count] + tail) for c in range(0, len(p2), count)]
    choice = best_choice(t1s + rows1, t2s + rows2)[1]
    return None if choice is None else choice.tolist()


def _picked_states(
    options: list[tuple[float, np.ndarray, np.ndarray]],
    probed: tuple[list[tuple[list[float], list[float]]], tuple[int, ...], tuple] | None,
    picks: list[int],
) -> tuple[np.ndarray, np.ndarray]:
    """The state that gives joint j option ``picks[j]`` (:func:`_probed_choice`), velocities and accelerations.

    A probed state gives a joint not probed its current state (that of ``options[0]``).
    """
    k = len(options)
    if probed is None or max(picks) < k:
        return (
            np.array([options[g][1][j] for j, g in enumerate(picks)]),
            np.array([options[g][2][j] for j, g in enumerate(picks)]),
        )
    candidates, joints, _ = probed
    cv, ca = [], []
    for j, g in enumerate(picks):
        if g < k:
            cv.append(options[g][1][j])
            ca.append(options[g][2][j])
        elif j in joints:
            m = joints.index(j)
            cv.append(candidates[g - k][0][m])
            ca.append(candidates[g - k][1][m])
        else:
            cv.append(options[0][1][j])
            ca.append(options[0][2][j])
    return np.array(cv), np.array(ca)


#: :class:`OptimizedStrategy`'s argument left out (its class attribute holds).
_CLASS_DEFAULT = object()


def _count(x: object) -> bool:
    """Whether `x` is an integer >= 0 (not a bool)."""
    return not isinstance(x, bool) and isinstance(x, (int, np.integer)) and x >= 0


class OptimizedStrategy(ViaStrategy):
    """Via states chosen by a spline search per run, then a duration search per via waypoint.

    Args:
        resweep_vias: How many vias of each run the optional second pass visits
            (:attr:`resweep_vias`): 0 none, None every one; left out, the class's (0).
        polish_joints: Arms of at most this many joints are polished (:attr:`polish_joints`;
            0: none); left out, the class's (5).

    Raises:
        InvalidArgumentError: If `resweep_vias` is neither None nor an integer >= 0, or
            `polish_joints` is not an integer >= 0.
    """

    name = "optimized"
    #: The velocity steps probed per joint at each via (shares of the speed limit; see :meth:`combine_joints`).
    probe_steps: tuple[float, ...] = _PROBE_STEPS
    #: The velocity steps probed again around a kept pick's new states where it moved two
    #: joints or more (see _REPROBE_MOVED; each taken either way). () (none), the default:
    #: ``(0.05,)`` costs about 7 % more time per 6-dof plan.
    reprobe_steps: tuple[float, ...] = ()
    #: The velocity steps of the second pass (:func:`~planner.motion.vias.joint_steps.resweep_via`; () for none).
    resweep_steps: tuple[float, ...] = RESWEEP_STEPS
    #: How many vias of each run between fixed waypoints, from its first, the second pass visits
    #: (0: none, the default; None: all). Each costs about 5 % of a 6-dof plan's instructions
    #: through 5 waypoints (see _RESWEEP_VIAS).
    resweep_vias: int | None = _RESWEEP_VIAS
    #: Arms of at most this many joints have their via states polished after the sweep
    #: (:meth:`polish`; 0: none). Each polish about doubles such an arm's plan time.
    polish_joints: int = _POLISH_JOINTS
    #: The pairs of velocity steps of the polish, coarse to fine (shares of the speed limit).
    polish_steps: tuple[tuple[float, ...], ...] = _POLISH_STEPS
    #: Arms of more joints than :attr:`polish_joints` have every via stepped once after the
    #: sweep (:func:`~planner.motion.vias.joint_steps.resweep_via` with :attr:`resweep_steps`),
    #: and their sweep probes no :attr:`probe_steps` and solves no grid where the probed pick is
    #: not kept (see _STEP_PASS). False: the sweep alone (with those), as for every arm before.
    step_pass: bool = _STEP_PASS

    def __init__(
        self, resweep_vias: int | None | object = _CLASS_DEFAULT, polish_joints: int | object = _CLASS_DEFAULT
    ) -> None:
        if resweep_vias is not _CLASS_DEFAULT:  # else the class's (a subclass may set its own)
            if resweep_vias is not None and not _count(resweep_vias):
                raise InvalidArgumentError(
                    f"resweep_vias must be None (every via) or an integer >= 0, got {resweep_vias!r}"
                )
            self.resweep_vias = None if resweep_vias is None else int(resweep_vias)
        if polish_joints is not _CLASS_DEFAULT:
            if not _count(polish_joints):
                raise InvalidArgumentError(f"polish_joints must be an integer >= 0, got {polish_joints!r}")
            self.polish_joints = int(polish_joints)

    def choose(self, chain: ViaChain) -> None:
        """Spline-like via states, a joint spline search per run between fixed waypoints, then one sweep."""
        free = [i for i in range(1, chain.n - 1) if not chain.fixed[i]]
        stepped = self._stepped(chain)
        durations = chain.durations()
        for i in free:
            chain.v[i] = via_directions(chain.q, i, durations, chain.limits, chain.stop)[0]
        self._settle(chain, free)
        # All via states of a run between fixed waypoints at once, from a timed spline.
        durations = chain.durations()
        fixed = [i for i in range(chain.n) if chain.fixed[i]]
        for a, b in zip(fixed[:-1], fixed[1:]):
            if b - a >= 2:
                self.search_spline(chain, a, b, durations)
        # Then one sweep: the slope blend from the durations, time-scaled per via, then every
        # joint's best state among those tried and a time-optimal turn (more sweeps or a
        # per-joint pattern search gained about 1 % in tests, at twice the time or more).
        durations = chain.durations()
        for i in free:
            u, w = via_directions(chain.q, i, durations, chain.limits, chain.stop)
            grid, tried = None, []
            if any(u.tolist()) or any(w.tolist()):
                if _probes_apply(chain, i):
                    grid = self.grid_states(chain, u, w)
                else:
                    tried = self.search_via(chain, i, u, w)  # (resting at the via among them)
            if grid is None:
                self.combine_joints(chain, i, tried)
            else:
                before = chain.v[i].tolist()
                if self.combine_joints(chain, i, [], grid, steps=() if stepped else None):
                    if not stepped:  # (else the step pass moves the via)
                        # The probed pick was not kept once solved: the grid states solved instead.
                        self.combine_joints(chain, i, self.search_via(chain, i, u, w), probe=_FALLBACK_PROBE)
                elif self.reprobe_steps:
                    moved = [j for j, (x, y) in enumerate(zip(before, chain.v[i].tolist())) if x != y]
                    if len(moved) >= _REPROBE_MOVED:
                        resweep_via(chain, i, self.reprobe_steps, moved)
            v, acc = chain.state_rows()
            durations[i - 1] = chain.seg.solve(i - 1, v[i - 1], acc[i - 1], v[i], acc[i])[0]
            durations[i] = chain.seg.solve(i, v[i], acc[i], v[i + 1], acc[i + 1])[0]
        # A second pass over the first vias of each run (every via with the step pass), given
        # their final neighbours.
        vias = None if stepped else self.resweep_vias
        if self.resweep_steps and vias != 0:
            for a, b in zip(fixed[:-1], fixed[1:]):
                for i in range(a + 1, b if vias is None else min(b, a + 1 + vias)):
                    resweep_via(chain, i, self.resweep_steps)
        if chain.q.shape[1] <= self.polish_joints:
            self.polish(chain, free)

    def _stepped(self, chain: ViaChain) -> bool:
        """Whether the chain's arm has the step pass (:attr:`step_pass`): more joints than :attr:`polish_joints`."""
        return self.step_pass and bool(self.resweep_steps) and chain.q.shape[1] > self.polish_joints

    def polish(self, chain: ViaChain, free: list[int]) -> None:
        """Step the via states with finer and finer velocity steps while a via changes.

        For each of :attr:`polish_steps` in turn, every free via is stepped
        (:func:`~planner.motion.vias.joint_steps.resweep_via`: the joints that set a segment's
        time, each velocity moved either way, kept only where the pair is faster and stays within
        the range), then for up to :data:`_POLISH_ROUNDS` - 1 more rounds the vias that changed
        and their free neighbours again.

        Args:
            chain: The chain.
            free: The vias the strategy may change, ascending.
        """
        if len(free) == 0:
            return
        allowed = set(free)
        for steps in self.polish_steps:
            visit = free
            for _ in range(_POLISH_ROUNDS):
                again = set()
                for i in visit:
                    if resweep_via(chain, i, steps):
                        again.update(k for k in (i - 1, i, i + 1) if k in allowed)
                if not again:
                    break
                visit = sorted(again)

    def _line_search(
        self,
        chain: ViaChain,
        i: int,
        make: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
        top: float,
        start: float = 0.0,
    ) -> list[tuple[float, np.ndarray, np.ndarray]]:
        """Minimise the pair cost over a scalar parameter in [0, top] on the grid :func:`_capped_grid` makes of `top`.

        The grid is walked from `start` upwards while the duration falls, else downwards; the
        best point is kept if it is faster than the current state. (No refinement between the
        grid points: the joint choice that follows picks among them per joint.)
        `make` maps parameters (G floats) to admissible via states, shapes (G, dof); the
        chain's current via state is admissible too (every strategy step keeps it so).

        Returns:
            Every state tried, the current one first, each as (pair duration, velocities,
            accelerations) after the halving of :meth:`ViaChain.pair_cost`.
        """
        pair = chain.pair_coster(i)
        current = pair(chain.v[i], chain.acc[i])
        grid = _capped_grid(top)
        if not math.isfinite(current[0]) and 0.0 not in grid:
            grid.insert(0, 0.0)  # resting at the via: the fallback where the current state has no profile
        n = len(grid)
        cvs, cas = make(grid)  # in one batch
        tried: list[tuple[float, np.ndarray, np.ndarray] | None] = [None] * n

        def at(g: int) -> float:
            tried[g] = pair(cvs[g], cas[g])
            return tried[g][0]

        # Walk the grid from `start` upwards while the duration falls, else downwards: the
        # duration is mostly unimodal in the parameter.
        g0 = next((g for g, x in enumerate(grid) if x >= start), n - 1)
        g = g0
        value = at(g)
        while g + 1 < n and (step := at(g + 1)) <= value:
            g, value = g + 1, step
        if g == g0 or not math.isfinite(value):
            g = g0
            value = tried[g][0]
            while g > 0 and (step := at(g - 1)) <= value:
                g, value = g - 1, step
        states = [current, *[t for t in tried if t is not None]]
        best = min(states, key=itemgetter(0))  # the first smallest: the current state unless beaten
        _, chain.v[i], chain.acc[i] = best
        return states

    def search_via(
        self, chain: ViaChain, i: int, u: np.ndarray, w: np.ndarray
    ) -> list[tuple[float, np.ndarray, np.ndarray]]:
        """Time-scale the spline-like via state (u, w) at via i to minimise its segments' time.

        Scaling a trajectory's time by 1/x multiplies velocities by x and accelerations by
        x^2, so the candidates are ``(x u, x^2 w)``, each joint saturating at its limits,
        each solved (the sweep of :meth:`choose` probes them per joint instead, see
        :meth:`grid_states`; this search is its fallback where the current state has no profile).

        Returns:
            The states tried (see :meth:`_line_search`).
        """
        lim = chain.limits

        def candidates(x: list[float]) -> tuple[np.ndarray, np.ndarray]:
            return _grid_candidates(x, u, w, lim)

        return self._line_search(chain, i, candidates, _grid_top(u, w, lim), start=_GRID_START)

    def grid_states(self, chain: ViaChain, u: np.ndarray, w: np.ndarray) -> tuple[list[list[float]], list[list[float]]]:
        """The states ``(x u, x^2 w)`` of :meth:`search_via` at every scale x > 0 of its grid, as rows of floats.

        Returns:
            Per scale the velocities and the accelerations (lists over all joints).
        """
        lim = chain.limits
        top = _grid_top(u, w, lim)
        cvs, cas = _grid_candidates([x for x in _capped_grid(top) if x > 0.0], u, w, lim)
        return cvs.tolist(), cas.tolist()

    def _settle(self, chain: ViaChain, free: list[int]) -> None:
        """Halve the via states of joints that (by Ruckig's extrema) leave their range.

        Done before the search, so that each via is searched next to neighbours that fit.
        """
        v, acc = chain.state_rows()
        for _ in range(_SETTLE_HALVINGS):
            changed = False
            for k in range(chain.n - 1):
                bad = chain.seg.solve(k, v[k], acc[k], v[k + 1], acc[k + 1])[1]
                if bad is None:
                    continue
                for idx in (k, k + 1):
                    if idx in free and ((chain.v[idx] != 0) & bad).any():
                        chain.v[idx] = np.where(bad, 0.5 * chain.v[idx], chain.v[idx])
                        chain.acc[idx] = np.where(bad, 0.5 * chain.acc[idx], chain.acc[idx])
                        changed = True
            if not changed:
                return

    def search_spline(self, chain: ViaChain, a: int, b: int, durations: np.ndarray) -> None:
        """Choose the via states between fixed waypoints a and b jointly, from timed splines, per joint.

        Given segment durations, the C2 cubic spline through the waypoints at those times
        gives every via a velocity and an acceleration that fit all the others (a joint that
        turns round at a waypoint may pass it still moving, turning just beyond, as on the
        spline). The durations scaled by each of :data:`_SPLINE_SCALES` (in log scale) give
        one option per scale for the states of every joint along the run, the current states
        one more. A segment lasts as long as its slowest joint needs and each joint's time
        depends on its own states only: one unsynchronised Ruckig probe times every (option,
        segment, joint) (:meth:`SegmentSolver.probe_run`; only the joints near a segment's
        time with the current states, the others keep them), and every joint that sets a
        segment's time takes in turn the option that makes the run fastest given the others'
        (from the best option common to all joints). The result is solved; joints whose
        extrema leave the range there take the current states again. It replaces the current
        states if it is faster, within the range and every segment reaches its end; else (the
        solved run slower than its joints' own times tell: Ruckig's blocked intervals) the
        fastest option common to all joints does, solved, under the same conditions.
        """
        lim = chain.limits
        h0 = durations[a:b]
        if not all(0.0 < h < math.inf for h in h0.tolist()):
            return  # a segment without a profile (inf or NaN) or of no duration
        seg, m, dof = chain.seg, b - a, chain.q.shape[1]
        rows_v, rows_acc = chain.state_rows()
        # The current states: their per-joint times, and the duration to beat.
        current, now = 0.0, []
        for k in range(a, b):
            d, bad, traj = seg.solve(k, rows_v[k], rows_acc[k], rows_v[k + 1], rows_acc[k + 1])
            if traj is None:
                return  # (durations are finite: not reached)
            times = traj.independent_min_durations
            if bad is not None:
                current = math.inf
                times = [math.inf if out else t for out, t in zip(bad.tolist(), times)]
            current += d
            now.append(times)
        q_run = chain.q[a : b + 1]
        v_a, v_b = chain.v[a], chain.v[b]
        # Scaling every duration by s scales the spline's via velocities by 1/s and its via
        # accelerations by 1/s^2, except the parts due to the end velocities (by 1 and 1/s):
        # one spline at the durations h0 gives the via states at every scale.
        zero = np.zeros(dof)
        v_q, acc_q = spline_via_states(q_run, h0, zero, zero)
        vs, accs = v_q * _SPLINE_INV, acc_q * _SPLINE_INV2
        if any(v_a.tolist()) or any(v_b.tolist()):
            v_e, acc_e = spline_via_states(q_run, h0, v_a, v_b)
            vs += v_e - v_q
            accs += (acc_e - acc_q) * _SPLINE_INV
        vs = np.minimum(np.maximum(vs, -lim.velocity), lim.velocity)
        accs = admissible_acceleration(vs, accs, lim)
        count = len(vs)
        # Per option the states at waypoints a..b (the ends are the chain's), the current ones last.
        states_v = np.empty((count + 1, m + 1, dof))
        states_a = np.empty((count + 1, m + 1, dof))
        states_v[:, 0], states_v[:count, 1:m], states_v[count, 1:m], states_v[:, m] = v_a, vs, chain.v[a + 1 : b], v_b
        states_a[:, 0], states_a[:count, 1:m], states_a[count, 1:m], states_a[:, m] = (
            chain.acc[a],
            accs,
            chain.acc[a + 1 : b],
            chain.acc[b],
        )
        # Only the joints near a segment's time with the current states are probed: the others
        # keep them (their other options count as not allowed).
        share = _RUN_NEAR_STEPPED if self._stepped(chain) else _RUN_NEAR
        near = [share * max(times) for times in now]
        joints = tuple(j for j in range(dof) if any(times[j] >= x for times, x in zip(now, near)))
        if len(joints) == dof:
            probed = seg.probe_run(a, states_v[:count], states_a[:count])
        else:
            probed = seg.probe_run(a, states_v[:count, :, joints], states_a[:count, :, joints], joints)
            if probed is not None:
                fill = [math.inf] * (count * m * dof)
                for i, j in enumerate(joints):
                    fill[j::dof] = probed[i :: len(joints)]
                probed = fill
        if probed is None:
            return
        choice = _joint_choice(probed + [t for times in now for t in times], (count + 1, m, dof))
        if choice is None:
            return
        columns = np.arange(dof)
        start, end = (rows_v[a], rows_acc[a]), (rows_v[b], rows_acc[b])

        def solved(v: np.ndarray, acc: np.ndarray) -> tuple[float, set[int], list]:
            """The run's duration with via states (v, acc), the joints out of the range, the states."""
            states = [start, *zip(v, acc), end]
            total, out = 0.0, set()
            for k in range(a, b):
                (va, aa), (vb, ab) = states[k - a], states[k - a + 1]
                d, bad, _ = seg.solve(k, va, aa, vb, ab)
                if bad is not None:
                    out.update(j for j, x in enumerate(bad.tolist()) if x)
                total += d
            return total, out, states

        def reaches(states: list) -> bool:
            """Whether every segment reaches its end (else the range repair would rest at the vias)."""
            return not any(seg.misses_end(k, *states[k - a], *states[k - a + 1]) for k in range(a, b))

        for _ in range(_SPLINE_FIXES + 1):
            picks = np.array(choice)
            v = np.ascontiguousarray(states_v[picks, 1:m, columns].T)
            acc = np.ascontiguousarray(states_a[picks, 1:m, columns].T)
            total, out, states = solved(v, acc)
            if not out:
                if total < current and reaches(states):
                    chain.v[a + 1 : b], chain.acc[a + 1 : b] = v, acc
                    return
                break
            # Joints out of the range take the current states (already solved: within it, or no better).
            if all(choice[j] == count for j in out):
                break
            for j in out:
                choice[j] = count
        # The mix not kept (slower than its joints' own times tell, Ruckig's blocked intervals):
        # the options common to all joints, solved.
        best, kept = current, None
        for c in range(count):
            v, acc = states_v[c, 1:m], states_a[c, 1:m]
            total, out, states = solved(v, acc)
            if not out and total < best:
                best, kept = total, (v, acc, states)
        if kept is not None and reaches(kept[2]):
            chain.v[a + 1 : b], chain.acc[a + 1 : b] = kept[0], kept[1]

    def _probe_options(
        self,
        chain: ViaChain,
        i: int,
        current: tuple[float, np.ndarray, np.ndarray],
        times: tuple[list[float], list[float]],
        dp: list[float],
        turning: list[bool],
        grid: tuple[list[list[float]], list[list[float]]] | None = None,
        steps: Sequence[float] | None = None,
    ) -> tuple[list[tuple[list[float], list[float]]], tuple[int, ...], tuple[list[float], list[float]]] | None:
        """More options per joint at via i, their times in both segments from one Ruckig probe.

        The current velocity moved by each of :attr:`probe_steps` (shares of the speed limit;
        the acceleration kept, within :func:`admissible_acceleration`) for the joints near a
        segment's time, a time-optimal turn (at rest, still braking at full deceleration)
        for those of them that reverse at the via, and their states in `grid`
        (:meth:`SegmentSolver.probe_around`).

        Args:
            chain: The chain.
            i: The via.
            current: Its state, (pair duration, velocities, accelerations).
            times: The state's per-joint times in the segments before and after the via [s].
            dp: Per joint, the move into the via [rad or m].
            turning: Per joint, whether it reverses at the via.
            grid: More states, per state the velocities and the accelerations of all joints
                (:meth:`grid_states`); None for none.
            steps: The velocity steps; None for :attr:`probe_steps`.

        Returns:
            The states probed (velocities and accelerations, lists over the joints probed; the
            others keep their current states), the joints probed, and the times in the segment
            before and after the via [s], flat (:meth:`SegmentSolver.probe_around`: probed
            state c and the m-th joint probed at ``c * len(joints) + m``; inf where the joint's
            own profile leaves the range); None where nothing was probed.
        """
        t1, t2 = times
        share = _PROBE_NEAR_STEPPED if self._stepped(chain) else _PROBE_NEAR
        near1, near2 = share * max(t1), share * max(t2)
        joints = tuple(j for j, (x, y) in enumerate(zip(t1, t2)) if x >= near1 or y >= near2)
        lim = chain.limits
        velocity, acceleration, _ = lim.ruckig_limits
        twice_jerk = lim.twice_jerk.tolist()
        v, a = current[1].tolist(), current[2].tolist()
        steps = self.probe_steps if steps is None else steps
        candidates = moved_states((velocity, acceleration, twice_jerk), (v, a), joints, steps)
        if any(turning[j] for j in joints):
            cv, ca = [], []
            for j in joints:
                top, most, tj, x, y = velocity[j], acceleration[j], twice_jerk[j], v[j], a[j]
                if turning[j]:
                    amax = min(most, math.sqrt(tj * top) * (1.0 - 1e-9))
                    cv.append(0.0)
                    ca.append(max(min(-most if dp[j] > 0 else most, amax), -amax))
                else:
                    cv.append(x)
                    ca.append(y)
            candidates.append((cv, ca))
        if grid is not None and joints:
            states = _gather(list(joints))
            candidates += [(list(states(cv)), list(states(ca))) for cv, ca in zip(*grid)]
        if not joints or not candidates:
            return None
        start = (chain.v[i - 1].tolist(), chain.acc[i - 1].tolist())
        end = (chain.v[i + 1].tolist(), chain.acc[i + 1].tolist())
        probed = chain.seg.probe_around(i, start, end, joints, candidates)
        if probed is None:
            return None
        return candidates, joints, probed

    def combine_joints(
        self,
        chain: ViaChain,
        i: int,
        tried: list[tuple[float, np.ndarray, np.ndarray]],
        grid: tuple[list[list[float]], list[list[float]]] | None = None,
        probe: bool = True,
        steps: Sequence[float] | None = None,
    ) -> bool:
        """Give every joint at via i its best state among those tried, and a time-optimal turn.

        A segment lasts as long as its slowest joint needs (Ruckig's independent minimum
        durations, up to its blocked intervals), and each joint's time depends only on its own
        states. So the states already solved, plus per joint near a segment's time its velocity
        moved by :attr:`probe_steps`, its states in `grid` and, where it reverses at the via, a
        time-optimal turn (at rest, still braking at full deceleration), timed by one unsynchronised Ruckig probe
        (:meth:`_probe_options`), give each joint several options whose best pick
        (:func:`best_choice`) is known without solving; that pick is solved once. The fastest
        of these states is kept whose joints do not turn round beyond their range inside a
        phase of zero jerk (``SegmentSolver.turns_beyond``: the range repair would halve such a
        state at whatever cost); the offending joints of the fastest ones are halved as the
        search halves joints that leave the range. A state whose segment misses its end beyond
        correction is passed over (``SegmentSolver.misses_end``: the repair would rest there).

        Args:
            chain: The chain.
            i: The via.
            tried: States tried at via i, (pair duration, velocities, accelerations) each.
            grid: States probed per joint, not solved (:meth:`grid_states`); None for none.
            probe: Whether to probe more options per joint (:meth:`_probe_options`); else the
                joints pick among the states tried only.
            steps: The velocity steps probed; None for :attr:`probe_steps`.

        Returns:
            Whether the joints' best pick, once solved, was not kept (slower than its estimate,
            or turning beyond the range or missing a segment's end), or no state was kept.
        """
        lim = chain.limits
        pair = chain.pair_coster(i)
        current = pair(chain.v[i], chain.acc[i])
        states = [current, *tried]
        # On plain floats (a few joints): the same differences and products as on arrays.
        rows = chain.seg.rows
        dp = [x - w for w, x in zip(rows[i - 1], rows[i])]
        flags = [d * (y - x) < 0 for d, x, y in zip(dp, rows[i], rows[i + 1])]
        both = chain.seg.around(i, chain.v[i - 1], chain.acc[i - 1], chain.v[i + 1], chain.acc[i + 1])
        t1s, t2s, options = [], [], []
        for state in states:
            if not state[0] < math.inf:
                continue
            (_, _, traj1), (_, _, traj2) = both(state[1], state[2])  # within the range: no joint masked
            t1s.append(traj1.independent_min_durations)
            t2s.append(traj2.independent_min_durations)
            options.append(state)
        found, probed = None, None
        if probe and options and options[0] is current:
            probed = self._probe_options(chain, i, current, (t1s[0], t2s[0]), dp, flags, grid, steps)
        if probed is not None or len(t1s) > 1:
            picks = _probed_choice(t1s, t2s, probed)
            if picks is not None:
                found = pair(*_picked_states(options, probed, picks))
                if found[0] < math.inf:
                    options.append(found)
        # The fastest state whose joints turn nowhere beyond their range: Ruckig's extrema
        # miss a turn inside a phase of zero jerk, which the range repair would find and halve
        # (at any cost). A faster state that turns beyond has those joints halved here instead,
        # as the search halves joints that leave the range.
        seg, lim = chain.seg, chain.limits
        pool, halve = [], _TURN_HALVED
        va, aa, vb, ab = chain.v[i - 1], chain.acc[i - 1], chain.v[i + 1], chain.acc[i + 1]

        def misses_end(cv: np.ndarray, ca: np.ndarray, traj1, traj2) -> bool:  # (trajs: both's for cv, ca)
            return seg.traj_misses_end(i - 1, traj1, va, aa, cv, ca) or seg.traj_misses_end(i, traj2, cv, ca, vb, ab)

        for state in sorted(options, key=lambda c: c[0]):
            (_, _, traj1), (_, _, traj2) = both(state[1], state[2])  # (finite: both profiles there)
            if misses_end(state[1], state[2], traj1, traj2):
                continue  # the range repair would rest at the via
            out = seg.turns_beyond(i - 1, traj1) + seg.turns_beyond(i, traj2)
            if not out:
                pool.append(state)
                break  # every later state is slower
            if not halve:
                continue
            halve -= 1
            for _ in range(SEARCH_HALVINGS):
                cv, ca = state[1].copy(), state[2].copy()
                cv[out] *= 0.5
                ca[out] *= 0.5
                state = pair(cv, admissible_acceleration(cv, ca, lim))
                if not state[0] < math.inf:
                    break
                (_, _, traj1), (_, _, traj2) = both(state[1], state[2])
                out = seg.turns_beyond(i - 1, traj1) + seg.turns_beyond(i, traj2)
                if not out:
                    if not misses_end(state[1], state[2], traj1, traj2):
                        pool.append(state)
                    break
        best = min(pool, key=lambda c: c[0], default=None)
        if best is not None:
            _, chain.v[i], chain.acc[i] = best
        return best is None or (found is not None and best is not found)
