"""Smooth motion along densely sampled paths: one smooth time-scaling per stretch between corners.

A line (a straight Cartesian line, or a straight joint-space edge of a route around
obstacles) is first planned as Ruckig segments between its samples, each reaching the next
sample with the line timing's state (:mod:`planner.motion.line_timing`). Each of those
segments is time-optimal on its own: its jerk switches between +limit and -limit several times,
so along a line of 30 samples a joint's jerk changes sign a hundred times, and a servo driven
by it buzzes.

:func:`smooth_lines` replaces each such chain by a motion that is smooth by construction:

1. The joint path: the samples joined by a natural cubic spline ``q(sigma)`` in the
   speed-normalised joint arc length ``sigma`` (as :func:`planner.motion.line_timing.time_line`
   parametrises it). Where the samples turn a corner (a joint arriving at or leaving a range
   end, while the others take over its share of the line, or a turn by more than
   :data:`CORNER_ANGLE` at one sample: the joint path has a kink there, which no motion with
   bounded acceleration passes without stopping), the path is split and the arm stops at the
   corner for an instant. :func:`planner.motion.line.line_waypoints` brackets a range end
   between two samples a hair apart, so one kink is one stop (neighbouring corner samples
   merge), and the spline skips samples crowding a neighbour (a step that short points across
   the kink).
2. The time-scaling of each piece (:class:`_Speed`): ``sigma``'s speed rises from rest in a ramp
   (a smoothstep ``3x^2 - 2x^3``, or the longer-tailed ``10x^3 - 15x^4 + 6x^5``), falls to rest
   in another, and between them tilts linearly and bulges or dips in the middle. A joint's jerk
   is ``q3 sd^3 + 3 q2 sd sdd + q1 sddd`` (``qk`` its path's k-th derivative by ``sigma``): at a
   constant speed it follows the bends of its own path, which a tilt, a bump and unequal ramps
   shift, shrink or merge. First symmetric ramps of a few lengths (:data:`_RAMPS`), then for a
   few rounds shapes near the best so far and near the fastest (:func:`_variants`), each with
   two knot spacings (step 3), are screened exactly (:func:`_screen`). Of those within
   :data:`DURATION_SLACK` of the fastest, the one kept has the fewest jerk sign changes beyond
   what each joint's path needs (:func:`_targets`: its S-curve's 2, or 2 more than the times it
   turns back), then the fewest on its worst joint and in all, then is the fastest.
3. The trajectory: the C2 cubic spline in time (:func:`rest_to_rest_spline`) through the path
   at evenly spaced times (:data:`KNOT_SPACING`; knots where the speed's polynomial changes),
   at rest at both ends of the piece, then scaled in time uniformly so that the tightest joint
   just reaches its velocity, acceleration or jerk limit (evaluated exactly; ``v ~ 1/k``,
   ``a ~ 1/k^2``, ``j ~ 1/k^3``).

A line may blend into the move before or after it (``moving`` in :func:`smooth_lines`): that
end has no ramp, the path spline is clamped there to the samples' own tangent (a one-sided fit),
and the spline in time passes it with the cruise velocity and acceleration along the path
(:func:`line_end_states`), which the neighbouring move meets as its via state.

Jerk follows the path's own third derivative and the ramps instead of switching: a few sign
changes per joint and piece. A line running along a joint limit has samples exactly at it, and
the spline through them may ring slightly beyond: knots there are moved inward by twice the
excess (at most :data:`MAX_NUDGE`). A stretch whose smooth motion would leave a joint's range,
or take more than ``max_stretch`` times its chain, keeps its Ruckig chain.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from planner.core.arrays import read_only
from planner.motion.limits import JointLimits
from planner.motion.trajectory import LIMIT_TOLERANCE, JointTrajectory

__all__ = ["line_end_states", "path_corners", "rest_to_rest_spline", "smooth_lines"]


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


def _solve_tridiagonal(sub: np.ndarray, diag: np.ndarray, sup: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """The Thomas algorithm for a tridiagonal system with right-hand sides rhs (n, k), column by column.

    In plain floats: the columns are a few joints, the rows a few hundred knots, and a numpy
    operation per row costs more than the arithmetic.
    """
    n = len(diag)
    sub_, diag_, sup_ = sub.tolist(), diag.tolist(), sup.tolist()
    cp, den = [0.0] * n, [0.0] * n
    den[0] = diag_[0]
    cp[0] = sup_[0] / den[0]
    for k in range(1, n):
        den[k] = diag_[k] - sub_[k] * cp[k - 1]
        cp[k] = sup_[k] / den[k]
    out = np.empty_like(rhs)
    for c, col in enumerate(rhs.T.tolist()):
        x = [0.0] * n
        x[0] = col[0] / den[0]
        for k in range(1, n):
            x[k] = (col[k] - sub_[k] * x[k - 1]) / den[k]
        for k in range(n - 2, -1, -1):
            x[k] -= cp[k] * x[k + 1]
        out[:, c] = x
    return out


def rest_to_rest_spline(
    t: np.ndarray,
    q: np.ndarray,
    start_velocity: np.ndarray | None = None,
    end_velocity: np.ndarray | None = None,
    start_acceleration: np.ndarray | None = None,
    end_acceleration: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The C2 cubic spline through ``q[k]`` at ``t[k]``, at rest (v = a = 0) at both ends.

    Solved for the second derivatives at the knots (a tridiagonal system, linear in the number
    of samples): the positions at the two free knots follow from the end slopes. An end may
    move instead (a given velocity and acceleration): where a line blends into the next move.

    Args:
        t: Increasing times, shape (N,) with N >= 2 [s].
        q: Positions, shape (N, dof).
        start_velocity: Velocity at t[0], shape (dof,); None is at rest.
        end_velocity: Velocity at t[-1], shape (dof,); None is at rest.
        start_acceleration: Acceleration at t[0], shape (dof,); None is zero.
        end_acceleration: Acceleration at t[-1], shape (dof,); None is zero.

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
    a0 = np.zeros(q.shape[1]) if start_acceleration is None else np.asarray(start_acceleration, dtype=float)
    a1 = np.zeros(q.shape[1]) if end_acceleration is None else np.asarray(end_acceleration, dtype=float)
    if start_velocity is not None:
        y[1] = y[1] + h[0] * np.asarray(start_velocity, dtype=float)
    if end_velocity is not None:
        y[m - 1] = y[m - 1] - h[m - 1] * np.asarray(end_velocity, dtype=float)
    y[1] = y[1] + h[0] ** 2 * a0 / 3.0
    y[m - 1] = y[m - 1] + h[m - 1] ** 2 * a1 / 3.0
    free = {1: h[0] ** 2 / 6.0, m - 1: h[m - 1] ** 2 / 6.0}  # y_f = y_end + alpha_f * M_f
    # Rows i = 1..m-1: h_{i-1} M_{i-1} + 2 (h_{i-1} + h_i) M_i + h_i M_{i+1} = r_i (M_0 = M_m = 0).
    rows = np.arange(1, m)
    sub, sup = h[rows - 1].copy(), h[rows].copy()
    diag = 2.0 * (h[rows - 1] + h[rows])
    rhs = 6.0 * ((y[rows + 1] - y[rows]) / h[rows, None] - (y[rows] - y[rows - 1]) / h[rows - 1, None])
    rhs[0] -= h[0] * a0  # the known end moments M_0 = a0, M_m = a1
    rhs[-1] -= h[m - 1] * a1
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
    moments = np.zeros((m + 1, q.shape[1]))
    moments[0], moments[m] = a0, a1
    moments[1:m] = _solve_tridiagonal(sub, diag, sup, rhs)
    for f, alpha in free.items():
        y[f] += alpha * moments[f]
    v = (y[1:] - y[:-1]) / h[:, None] - h[:, None] * (2.0 * moments[:-1] + moments[1:]) / 6.0
    jerk = (moments[1:] - moments[:-1]) / h[:, None]
    return x[:-1], y[:-1], v, moments[:-1], jerk


#: Time between the knots of the smooth spline in time [s] (at least 6 intervals per piece),
#: before the uniform time scaling; where that stretches them, also after it (a second candidate).
KNOT_SPACING = 0.01
#: Angle between neighbouring sample steps (speed-normalised joint space) that marks a corner [rad].
CORNER_ANGLE = 0.1
#: Ramp lengths tried, as fractions of the time at constant speed (1: the ramps meet).
_RAMPS = (0.1, 0.2, 0.3, 0.45, 0.65, 1.0)
#: Factors on one ramp's length, tilts and bumps of the cruise speed tried around the best shape so far.
_RAMP_FACTORS = (0.6, 0.8, 1.25, 1.5)
_TILTS = (-0.2, -0.1, 0.1, 0.2)
_BUMPS = (-0.25, -0.12, 0.12, 0.25)
#: Rounds of trying shapes near the best one.
_ROUNDS = 3
#: Longer than the fastest smooth motion of a piece its motion may be, if it changes jerk sign less often
#: (beyond what its joint paths need; :func:`_smooth_piece`).
DURATION_SLACK = 0.07
#: The same for a piece passing an end moving: the moves it blends into would wait for it (a plan
#: blends a line only where that makes it shorter).
MOVING_SLACK = 0.03
#: Shortest step between the samples the path spline passes, over the median step.
NODE_GAP = 0.2
#: Largest move of a knot off a joint bound the spline may make [rad or m].
MAX_NUDGE = 1e-3


def smooth_lines(
    trajectory: JointTrajectory,
    stretches: Sequence[tuple[int, int]],
    *,
    max_stretch: float = 1.25,
    moving: Sequence[tuple[bool, bool]] | None = None,
    exact: Sequence[Sequence[int]] | None = None,
) -> tuple[JointTrajectory, int]:
    """Replace the trajectory between waypoints ``a`` and ``b`` of each stretch by a smooth motion.

    Args:
        trajectory: A trajectory that rests at waypoints ``a`` and ``b`` of each stretch (after
            ``a``'s dwell), unless `moving` says otherwise, and passes the waypoints between
            them (the samples of a line).
        stretches: ``(a, b)`` waypoint index pairs, a < b, not overlapping.
        max_stretch: A stretch whose smooth motion takes longer than this factor times its
            chain keeps the chain (everything after a smoothed stretch moves by the time it
            adds or saves).
        moving: Per stretch, whether it starts and ends moving (blending into the moves before
            and after it) instead of at rest: then the trajectory must pass that end with the
            velocity and acceleration :func:`line_end_states` gives (else the stretch
            keeps its chain). None: every stretch rests at both ends.
        exact: Per stretch, waypoints inside it the smooth motion passes exactly (the user's
            waypoints where lines join), not within the spline's interpolation error. None: none.

    Returns:
        The trajectory with every stretch smoothed whose motion keeps every limit, and how many
        stretches were smoothed (the others keep their Ruckig chain). The waypoints inside a
        smoothed stretch become the positions it passes at their times (within the spline's
        interpolation error of the samples, or a nudge off a joint bound).
    """
    traj = trajectory
    smoothed = 0
    lim = traj.limits
    bound = _bound(lim)
    order = sorted(range(len(stretches)), key=lambda i: stretches[i])
    for i in order:
        a, b = stretches[i]
        rest = (True, True) if moving is None else (not moving[i][0], not moving[i][1])
        start = float(traj.waypoint_times[a] + traj.dwell[a])
        chain = float(traj.waypoint_times[b] - start)
        q = np.array(traj.waypoints[a : b + 1], dtype=float)
        if b - a < 1 or not chain > 0:
            continue
        fixed = () if exact is None else tuple(int(w) - a for w in exact[i] if a < w < b)
        pieces = _line_pieces(q, traj, bound, rest, fixed)
        if pieces is None or sum(p[0][-1] for p in pieces) > max_stretch * chain:
            continue
        start_state, end_state = _piece_end_states(pieces)
        if not _matches(traj, a, start_state) or not _matches(traj, b, end_state):
            continue  # the moves around it do not blend in with this velocity (range repair)
        t, pos, parts, offset = [np.zeros(1)], [q[:1]], [], 0.0
        for times, positions, knots, p, v, acc, j in pieces:
            t.append(offset + times[1:])
            pos.append(positions[1:])
            parts.append((offset + knots, p, v, acc, j))
            offset += float(times[-1])
        knots, p, v, acc, j = (np.concatenate(x) for x in zip(*parts))
        traj = _splice(traj, a, b, start + np.concatenate(t), np.concatenate(pos), start + knots, p, v, acc, j)
        smoothed += 1
    return traj, smoothed


def line_end_states(
    q: np.ndarray, limits: JointLimits, moving: tuple[bool, bool], exact: Sequence[int] = ()
) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None:
    """The joint velocities and accelerations a smoothed line (samples q (M, dof)) starts and ends with.

    Where it blends into the move before or after it (`moving`), it passes that end at its
    cruise speed along the path; the neighbouring move must meet that state. The samples
    `exact` (inner indices) are passed exactly, as :func:`smooth_lines` is told.

    Returns:
        ``((v0, a0), (v1, a1))``, shapes (dof,); zeros for an end at rest; None if the line
        has no smooth motion within the limits.
    """
    q = np.asarray(q, dtype=float)
    template = _template(limits, q)
    pieces = _line_pieces(q, template, _bound(limits), (not moving[0], not moving[1]), tuple(exact))
    return None if pieces is None else _piece_end_states(pieces)


def _bound(lim: JointLimits) -> float:
    finite = np.concatenate([lim.lower[np.isfinite(lim.lower)], lim.upper[np.isfinite(lim.upper)]])
    return max(1.0, float(np.max(np.abs(finite), initial=1.0)))


def _template(limits: JointLimits, q: np.ndarray) -> JointTrajectory:
    """An empty trajectory with these limits, for :func:`_smooth_piece` to fill in."""
    dof = q.shape[1]
    zeros = np.zeros((1, dof))
    return JointTrajectory.lazy(
        lambda: (np.zeros(1), zeros, zeros, zeros, zeros),
        duration=0.0,
        waypoints=q[:1],
        waypoint_times=np.zeros(1),
        via_velocities=zeros,
        via_accelerations=zeros,
        dwell=np.zeros(1),
        limits=limits,
        strategy="line",
        repaired=np.zeros((1, dof), dtype=bool),
    )


def _line_pieces(
    q: np.ndarray, template: JointTrajectory, bound: float, rest: tuple[bool, bool], fixed: Sequence[int] = ()
) -> list | None:
    """The smooth pieces between the corners of the samples q, or None if one has none.

    The samples `fixed` (indices into q) are passed exactly.
    """
    cuts = [0, *path_corners(q, template.limits), len(q) - 1]
    pieces = []
    for n, (i, k) in enumerate(zip(cuts, cuts[1:])):
        ends = (rest[0] or n > 0, rest[1] or n < len(cuts) - 2)
        piece = _smooth_piece(q[i : k + 1], template, bound, ends, tuple(f - i for f in fixed if i < f < k))
        if piece is None:
            return None
        pieces.append(piece)
    return pieces


def _piece_end_states(pieces: list) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Velocity and acceleration where the first piece starts and the last one ends."""
    first, last = pieces[0], pieces[-1]
    knots, _, v, acc, j = last[2:]
    h = float(last[0][-1] - knots[-1])
    end = (v[-1] + acc[-1] * h + j[-1] * h * h / 2.0, acc[-1] + j[-1] * h)
    return (first[4][0].copy(), first[5][0].copy()), end


def _matches(traj: JointTrajectory, k: int, state: tuple[np.ndarray, np.ndarray]) -> bool:
    """Whether the trajectory passes waypoint k (after its dwell) with this velocity and acceleration."""
    at = traj.sample(np.array([traj.waypoint_times[k] + traj.dwell[k]]))
    lim = traj.limits
    return bool(
        np.all(np.abs(at.qd[0] - state[0]) <= 1e-9 * lim.velocity)
        and np.all(np.abs(at.qdd[0] - state[1]) <= 1e-9 * lim.acceleration)
    )


def path_corners(q: np.ndarray, limits: JointLimits) -> list[int]:
    """Inner samples where the path turns a corner.

    A joint arriving at or leaving a range end (the sample at the end next to one inside it),
    however small its share of the motion: its own path has a kink there. And a turn by more
    than :data:`CORNER_ANGLE` between neighbouring steps (speed-normalised joint space).
    """
    near = [1e-9 * np.maximum(1.0, np.abs(np.nan_to_num(b))) for b in (limits.lower, limits.upper)]
    on_end = (q <= limits.lower + near[0]) | (q >= limits.upper - near[1])
    change = on_end[1:] != on_end[:-1]  # between samples k and k + 1
    at_end = set(np.nonzero(np.any(change & on_end[1:], axis=1))[0] + 1)
    at_end |= set(np.nonzero(np.any(change & on_end[:-1], axis=1))[0])
    d = np.diff(q, axis=0) / limits.velocity
    h = np.linalg.norm(d, axis=1)
    if len(q) < 3 or np.any(h <= 0):
        return sorted(int(k) for k in at_end if 0 < k < len(q) - 1)
    u = d / h[:, None]
    angle = np.arccos(np.clip(np.sum(u[1:] * u[:-1], axis=1), -1.0, 1.0))  # at samples 1..M-2
    # A corner turns at one sample (or two, when it lies between them) while the path two
    # samples away runs straight on; a tight smooth bend turns as much at every sample.
    padded = np.concatenate([[0.0, 0.0], angle, [0.0, 0.0]])
    around = np.maximum(padded[:-4], padded[4:])
    turns = set(np.nonzero((angle > CORNER_ANGLE) & (angle > 3.0 * around))[0] + 1)
    return _merge(sorted(int(k) for k in turns | at_end if 0 < k < len(q) - 1), on_end, h)


def _merge(corners: list[int], on_end: np.ndarray, steps: np.ndarray) -> list[int]:
    """One corner per kink: corner samples a hair apart become the one where a joint sits at its end.

    Samples closer than :data:`NODE_GAP` times the median step (speed-normalised joint space)
    around a kink both read as corners (the turn, the arrival); stopping at each would stop
    twice for one kink. Corners a real step apart stay apart: IK may jump there (the arm's
    spare freedom turns while the tip waits), and the straight joint step between two stops
    keeps the tip nearest the line.
    """
    gap = NODE_GAP * float(np.median(steps)) if len(steps) else 0.0
    out: list[int] = []
    group: list[int] = []
    for k in corners:
        if group and not float(np.sum(steps[group[-1] : k])) < gap:
            out.append(_pick(group, on_end))
            group = []
        group.append(k)
    if group:
        out.append(_pick(group, on_end))
    return out


def _pick(group: list[int], on_end: np.ndarray) -> int:
    """The middle one of a group of corner samples that sits at a range end (else of all)."""
    ends = [k for k in group if np.any(on_end[k])] or group
    return ends[len(ends) // 2]


def _natural_spline(
    x: np.ndarray,
    y: np.ndarray,
    slopes: tuple[np.ndarray | None, np.ndarray | None] = (None, None),
    bends: tuple[np.ndarray | None, np.ndarray | None] = (None, None),
) -> np.ndarray:
    """Second derivatives at the nodes of the cubic spline through ``y`` at ``x``, shape of y.

    Natural (zero second derivative) at an end whose slope is None, else clamped to that slope.
    """
    n = len(x)
    if n < 2 or (n < 3 and slopes[0] is None and slopes[1] is None):
        return np.zeros_like(y)
    h = np.diff(x)
    sub, diag, sup = np.zeros(n), np.ones(n), np.zeros(n)
    rhs = np.zeros_like(y)
    sub[1:-1], diag[1:-1], sup[1:-1] = h[:-1], 2.0 * (h[:-1] + h[1:]), h[1:]
    rhs[1:-1] = 6.0 * ((y[2:] - y[1:-1]) / h[1:, None] - (y[1:-1] - y[:-2]) / h[:-1, None])
    if slopes[0] is not None:
        diag[0], sup[0] = 2.0 * h[0], h[0]
        rhs[0] = 6.0 * ((y[1] - y[0]) / h[0] - slopes[0])
    elif bends[0] is not None:
        rhs[0] = bends[0]
    if slopes[1] is not None:
        sub[-1], diag[-1] = h[-1], 2.0 * h[-1]
        rhs[-1] = 6.0 * (slopes[1] - (y[-1] - y[-2]) / h[-1])
    elif bends[1] is not None:
        rhs[-1] = bends[1]
    cp, dp = np.zeros(n), np.zeros_like(rhs)
    cp[0], dp[0] = sup[0] / diag[0], rhs[0] / diag[0]
    for k in range(1, n):
        den = diag[k] - sub[k] * cp[k - 1]
        cp[k] = sup[k] / den
        dp[k] = (rhs[k] - sub[k] * dp[k - 1]) / den
    for k in range(n - 2, -1, -1):
        dp[k] -= cp[k] * dp[k + 1]
    return dp


def _one_sided_bend(x: np.ndarray, y: np.ndarray, at_end: bool) -> np.ndarray | None:
    """d2y/dx2 at the first (or last) node from a least-squares cubic through up to six nodes there."""
    if len(x) < 5:
        return None
    idx = np.arange(max(0, len(x) - 6), len(x)) if at_end else np.arange(min(6, len(x)))
    h = x[idx] - x[idx[-1] if at_end else idx[0]]
    scale = float(np.max(np.abs(h)))
    coef, *_ = np.linalg.lstsq(np.vander(h / scale, 4, increasing=True), y[idx], rcond=None)
    return 2.0 * coef[2] / scale**2


def _one_sided_slope(x: np.ndarray, y: np.ndarray, at_end: bool) -> np.ndarray:
    """dy/dx at the first (or last) node from a least-squares quadratic through up to four nodes there."""
    idx = np.arange(max(0, len(x) - 4), len(x)) if at_end else np.arange(min(4, len(x)))
    h = x[idx] - x[idx[-1] if at_end else idx[0]]
    scale = float(np.max(np.abs(h)))
    coef, *_ = np.linalg.lstsq(np.vander(h / scale, min(3, len(idx)), increasing=True), y[idx], rcond=None)
    return coef[1] / scale


def _spline_at(x: np.ndarray, y: np.ndarray, moments: np.ndarray, xq: np.ndarray) -> np.ndarray:
    """The cubic spline with node values ``y`` and second derivatives ``moments`` at ``xq``."""
    i = np.clip(np.searchsorted(x, xq, side="right") - 1, 0, len(x) - 2)
    h = (x[i + 1] - x[i])[:, None]
    s0, s1 = (x[i + 1][:, None] - xq[:, None]) / h, (xq[:, None] - x[i][:, None]) / h
    return s0 * y[i] + s1 * y[i + 1] + h * h / 6.0 * ((s0**3 - s0) * moments[i] + (s1**3 - s1) * moments[i + 1])


#: Gauss-Legendre nodes and weights on [0, 1] (8 points: exact for the speed profiles' polynomials, degree <= 15).
_GAUSS_X, _GAUSS_W = (lambda x, w: ((x + 1.0) / 2.0, w / 2.0))(*np.polynomial.legendre.leggauss(8))


@dataclass(frozen=True)
class _Speed:
    """The path speed's shape over a piece, in time u in [0, 1] of the piece.

    ``rate(u) = up(u) down(u) (1 + tilt (2u - 1) + bump 16 u^2 (1 - u)^2)``: ramps from rest
    ``up`` and to rest ``down`` long (fractions of the piece, 0: that end is passed moving; the
    ramps may overlap), each a smoothstep ``3x^2 - 2x^3`` (or with `smoother` the C2
    ``10x^3 - 15x^4 + 6x^5``, whose tails are longer), and between them a speed that tilts
    linearly and bulges (or dips) in the middle. The ramps are 1 away from them, so the speed is
    C1 (the path's position C2) wherever the pieces join. A piecewise polynomial between
    :meth:`breaks`: its integral is exact by Gauss-Legendre quadrature.
    """

    up: float
    down: float
    tilt: float = 0.0
    bump: float = 0.0
    smoother: bool = False

    def rate(self, u: np.ndarray) -> np.ndarray:
        u = np.asarray(u, dtype=float)
        g = 1.0 + self.tilt * (2.0 * u - 1.0) + self.bump * 16.0 * (u * (1.0 - u)) ** 2
        for length, x in ((self.up, u), (self.down, 1.0 - u)):
            if length > 0:
                x = np.clip(x / length, 0.0, 1.0)
                g = g * (x * x * x * (10.0 - 15.0 * x + 6.0 * x * x) if self.smoother else x * x * (3.0 - 2.0 * x))
        return g

    @cached_property
    def whole(self) -> float:
        """The rate's integral over the piece."""
        return float(self.integral(np.ones(1))[0])

    def breaks(self) -> np.ndarray:
        """Where the rate's polynomial changes: 0, the ramps' ends, 1."""
        # Ramps meeting within rounding (up == 1 - down) have one break, not a sliver between two.
        inner = sorted(x for x in (self.up, 1.0 - self.down) if 1e-9 < x < 1.0 - 1e-9)
        if len(inner) == 2 and inner[1] - inner[0] < 1e-9:
            inner = inner[:1]
        return np.array([0.0, *inner, 1.0])

    def integral(self, u: np.ndarray) -> np.ndarray:
        """The rate's integral from 0 to each u in [0, 1] (exact up to rounding)."""
        u = np.asarray(u, dtype=float)
        b = self.breaks()
        parts = np.diff(b)[:, None] * self.rate(b[:-1, None] + np.diff(b)[:, None] * _GAUSS_X) @ _GAUSS_W
        before = np.concatenate([[0.0], np.cumsum(parts)])
        i = np.clip(np.searchsorted(b, u, side="right") - 1, 0, len(b) - 2)
        h = u - b[i]
        return before[i] + h * (self.rate(b[i][:, None] + h[:, None] * _GAUSS_X) @ _GAUSS_W)

    def time_at(self, fraction: np.ndarray) -> np.ndarray:
        """The u at which the integral reaches `fraction` of its total (bisection; it only grows)."""
        target = np.asarray(fraction, dtype=float) * self.whole
        lo, hi = np.zeros_like(target), np.ones_like(target)
        for _ in range(55):
            mid = (lo + hi) / 2.0
            below = self.integral(mid) < target
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        return (lo + hi) / 2.0


def _grid(speed: _Speed, total: float, spacing: float) -> np.ndarray:
    """Knot times at most `spacing` apart over ``[0, total]``: evenly spaced between the speed's breaks."""
    b = speed.breaks()
    parts = [np.zeros(1)]
    for a, c in zip(b, b[1:]):
        parts.append(np.linspace(a, c, max(2, int(math.ceil((c - a) * total / spacing))) + 1)[1:])
    return np.concatenate(parts) * total


def _pin_knots(grid: np.ndarray, times: np.ndarray, keep: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """The knot grid with knots at `times`, and their indices in it.

    The knot nearest each time moves there, unless it is one to `keep` (the ends and the
    speed's breaks, where the time-scaling's jerk steps); knots closer than a third of the
    spacing to it go.
    """
    out = grid
    for t in times:
        if np.any(out == t):
            continue
        near = np.abs(out - t) < spacing / 3.0
        near &= ~np.isin(out, keep)
        out = np.sort(np.append(out[~near], t))
    return out, np.searchsorted(out, times)


def _end_slopes(x: np.ndarray, y: np.ndarray, moments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """dq/dsigma of the spline (nodes x, values y, second derivatives moments) at its two ends."""
    h0, h1 = x[1] - x[0], x[-1] - x[-2]
    first = (y[1] - y[0]) / h0 - h0 * (2.0 * moments[0] + moments[1]) / 6.0
    last = (y[-1] - y[-2]) / h1 + h1 * (moments[-2] + 2.0 * moments[-1]) / 6.0
    return first, last


def _speeds(rest: tuple[bool, bool]) -> list[_Speed]:
    """The first round of speed shapes: symmetric smoothstep ramps of :data:`_RAMPS` lengths."""
    out = []
    for f in _RAMPS:
        r = f / (1.0 + f)  # f of the time at constant speed, as a fraction of the piece
        out.append(_Speed(r if rest[0] else 0.0, r if rest[1] else 0.0))
    return out


def _variants(best: _Speed, rest: tuple[bool, bool]) -> list[_Speed]:
    """Shapes near `best`: one ramp longer or shorter, a tilt, a bump or dip, the longer-tailed ramp."""
    out = []
    for i, at_rest in enumerate(rest):
        if not at_rest:
            continue
        for factor in _RAMP_FACTORS:
            ramp = min(1.0, (best.up, best.down)[i] * factor)
            out.append(replace(best, up=ramp) if i == 0 else replace(best, down=ramp))
    if all(rest):
        out += [replace(best, tilt=best.tilt + d) for d in _TILTS if abs(best.tilt + d) < 0.7]
    out += [replace(best, bump=best.bump + d) for d in _BUMPS if -0.6 < best.bump + d < 1.0]
    if any(rest):
        out.append(replace(best, smoother=not best.smoother))
    return out


def _targets(q: np.ndarray, eps: float = 1e-3) -> np.ndarray:
    """Per joint, the fewest jerk sign changes a rest-to-rest motion along the samples q (M, dof) needs.

    Two for a joint that moves (its S-curve's), 0 for one that does not; a joint whose path
    turns back r times (by more than `eps` [rad or m]) has r + 1 velocity extrema and r + 2
    acceleration extrema between the rests, so at least r + 2 jerk sign changes.
    """
    out = np.zeros(q.shape[1], dtype=int)
    for d in range(q.shape[1]):
        x = q[:, d]
        direction, extreme, turns = 0, float(x[0]), 0
        for v in x[1:]:
            if direction == 0:
                if abs(v - extreme) > eps:
                    direction, extreme = (1 if v > extreme else -1), float(v)
            elif (v - extreme) * direction > 0:
                extreme = float(v)
            elif abs(v - extreme) > eps:
                direction, extreme, turns = -direction, float(v), turns + 1
        out[d] = turns + 2 if direction != 0 else (2 if np.ptp(x) > 0 else 0)
    return out


def _screen(
    q: np.ndarray,
    path: tuple[np.ndarray, np.ndarray, np.ndarray],
    slopes: tuple[np.ndarray, np.ndarray],
    speed: _Speed,
    spacing: float,
    lim: JointLimits,
    bounds: tuple[np.ndarray, np.ndarray],
    rest: tuple[bool, bool],
    pinned: tuple[np.ndarray, np.ndarray] | None,
) -> tuple[float, float, np.ndarray] | None:
    """Duration, time scale and per-joint jerk sign changes of the spline in time along this speed.

    The spline through the knots, scaled in time so that the tightest joint just reaches its
    velocity, acceleration or jerk limit (peaks of the piecewise cubic, exact), and its jerk
    sign changes where above 1 % of the limit (per interval: the jerk is constant on each).
    The range is not checked (:func:`_scaled_spline` does, for the motion chosen).
    """
    qk, grid = _knot_positions(q, path, speed, spacing, bounds, pinned)
    knots, p, v, acc, j = _time_spline(qk, grid, path, slopes, 1.0, rest)
    total = float(grid[-1])
    h = np.diff(np.append(knots, total))[:, None]
    vmax = np.maximum(np.abs(v), np.abs(v + acc * h + j * h * h / 2.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        at = np.where(j != 0, -acc / j, -1.0)
    inside = (at > 0) & (at < h)
    vmax = np.where(inside, np.maximum(vmax, np.abs(v - acc * acc / (2.0 * np.where(j != 0, j, 1.0)))), vmax)
    amax = np.maximum(np.abs(acc), np.abs(acc + j * h))
    k = max(
        float(np.max(vmax / lim.velocity)),
        float(np.max(amax / lim.acceleration)) ** 0.5,
        float(np.max(np.abs(j) / lim.jerk)) ** (1.0 / 3.0),
    )
    if not (k > 0 and np.isfinite(k)):
        return None
    big = np.abs(j) > 0.01 * lim.jerk * k**3
    counts = np.array([int(np.sum(np.diff(np.sign(j[big[:, d], d])) != 0)) for d in range(j.shape[1])])
    return total * k, k, counts


def _time_spline(
    qk: np.ndarray,
    grid: np.ndarray,
    path: tuple[np.ndarray, np.ndarray, np.ndarray],
    slopes: tuple[np.ndarray, np.ndarray],
    scale: float,
    rest: tuple[bool, bool],
) -> tuple:
    """The spline in time through the positions qk at the knot times grid, time scaled by `scale`.

    An end passed moving has the path's slope and bend there (the speed is 1 there).

    Returns:
        ``(knots, p, v, a, j)`` (:func:`rest_to_rest_spline`'s pieces).
    """
    moments = path[2]
    ends = [None if at_rest else slope / scale for at_rest, slope in zip(rest, slopes)]
    curves = [None if at_rest else bend / scale**2 for at_rest, bend in zip(rest, (moments[0], moments[-1]))]
    return rest_to_rest_spline(grid * scale, qk, *ends, *curves)


def _knot_times(
    speed: _Speed, total: float, spacing: float, pinned: tuple[np.ndarray, np.ndarray] | None
) -> tuple[np.ndarray, np.ndarray]:
    """The knot times (unscaled) and the indices of the pinned ones."""
    grid = _grid(speed, total, spacing)
    if pinned is None or not len(pinned[0]):
        return grid, np.zeros(0, dtype=int)
    return _pin_knots(grid, speed.time_at(pinned[0]) * total, speed.breaks() * total, spacing)


def _knot_positions(
    q: np.ndarray,
    path: tuple[np.ndarray, np.ndarray, np.ndarray],
    speed: _Speed,
    spacing: float,
    bounds: tuple[np.ndarray, np.ndarray],
    pinned: tuple[np.ndarray, np.ndarray] | None,
) -> tuple[np.ndarray, np.ndarray]:
    """The path's positions at the knots of this speed (clipped to the range), and the knot times.

    The piece lasts ``length / whole`` before the time scaling: the speed's mean over the piece
    is then ``whole`` times its scale, 1 where it cruises (and at an end passed moving).
    """
    sigma_nodes, q_nodes, moments = path
    length = float(sigma_nodes[-1])
    whole = speed.whole
    total = length / whole
    grid, where = _knot_times(speed, total, spacing, pinned)
    s = np.clip(length * speed.integral(grid / total) / whole, 0.0, length)
    qk = np.clip(_spline_at(sigma_nodes, q_nodes, moments, s), *bounds)
    qk[0], qk[-1] = q[0], q[-1]
    if len(where):
        qk[where] = pinned[1]
    return qk, grid


def _smooth_piece(
    q: np.ndarray,
    template: JointTrajectory,
    bound: float,
    rest: tuple[bool, bool] = (True, True),
    fixed: tuple[int, ...] = (),
) -> tuple | None:
    """The fastest smooth motion along the samples q (M, dof) within every limit.

    `rest` says whether it starts and ends at rest; an end not at rest is passed at the
    cruise speed (zero acceleration), to blend into the move before or after it. The samples
    `fixed` (inner indices) are nodes of the path spline and knots of the spline in time, so
    the motion passes them exactly.

    Returns:
        ``(t, positions, knots, p, v, a, j)`` from time 0: the times at which the samples are
        passed and the positions there, and the spline's pieces; None if none keeps the range.
    """
    lim = template.limits
    steps = np.linalg.norm(np.diff(q, axis=0) / lim.velocity, axis=1)
    sigma = np.concatenate([[0.0], np.cumsum(steps)])
    length = float(sigma[-1])
    if not np.all(steps > 0):
        return None  # a repeated sample: no path parameter through it
    nodes = np.union1d(_spline_nodes(sigma), np.asarray(fixed, dtype=int))
    q_nodes, sigma_nodes = q[nodes], sigma[nodes]
    # An end passed moving keeps the path's own direction there (a natural end would straighten it).
    moments = _natural_spline(
        sigma_nodes,
        q_nodes,
        tuple(None if r else _one_sided_slope(sigma_nodes, q_nodes, end) for r, end in zip(rest, (False, True))),
        tuple(_one_sided_bend(sigma_nodes, q_nodes, end) for end in (False, True)),
    )
    path = (sigma_nodes, q_nodes, moments)
    slopes = _end_slopes(sigma_nodes, q_nodes, moments)
    bounds = (
        np.where(np.isfinite(lim.lower), lim.lower, -np.inf),
        np.where(np.isfinite(lim.upper), lim.upper, np.inf),
    )
    pinned = (sigma[list(fixed)] / length, q[list(fixed)]) if fixed else None
    target = _targets(q)
    seen: dict = {}

    def screen(speeds: list[_Speed]) -> None:
        for speed in speeds:
            spacing = KNOT_SPACING
            for _ in range(2):
                # Knots KNOT_SPACING apart before the time scaling, and (where that scaling
                # stretches them) KNOT_SPACING apart after it: the spline through fewer knots
                # smooths the path spline's bends, the one through more follows them.
                if (speed, spacing) in seen:
                    break
                out = _screen(q, path, slopes, speed, spacing, lim, bounds, rest, pinned)
                seen[(speed, spacing)] = out
                if out is None or out[1] * spacing <= 1.5 * KNOT_SPACING:
                    break
                spacing = KNOT_SPACING / out[1]

    def ranked() -> list:
        found = [(out[0], out[2], key) for key, out in seen.items() if out is not None]
        if not found:
            return []
        fastest = min(f[0] for f in found)
        slack = DURATION_SLACK if all(rest) else MOVING_SLACK
        within = [f for f in found if f[0] <= fastest * (1.0 + slack)]
        # Fewest sign changes beyond what the joint paths need (their S-curve's 2, or their
        # reversal floor), then fewest on the worst joint and in all, then the fastest.
        return sorted(
            within,
            key=lambda f: (
                int(f[1].max()) > 9,
                int(np.maximum(f[1] - target, 0).sum()),
                int(f[1].max()),
                int(f[1].sum()),
                f[0],
            ),
        )

    screen(_speeds(rest))
    for _ in range(_ROUNDS):
        best = ranked()
        if not best:
            break
        before = len(seen)
        # Around the smoothest within the slack, and around the fastest (which widens the slack).
        screen(_variants(best[0][2][0], rest))
        fastest = min((out[0], i) for i, out in enumerate(seen.values()) if out is not None)[1]
        screen(_variants(list(seen)[fastest][0], rest))
        if len(seen) == before:
            break
    for _, _, (speed, spacing) in ranked():
        fit = _scaled_spline(
            q, path, slopes, speed, spacing, seen[(speed, spacing)][1], template, bound, bounds, rest, pinned
        )
        if fit is None:
            continue
        knots, p, v, acc, j, alone, grid, scale = fit
        duration = float(alone.duration)
        at = speed.time_at(sigma / length) * grid[-1] * scale
        at[0], at[-1] = 0.0, duration
        if fixed:
            _, where = _knot_times(speed, float(grid[-1]), spacing, pinned)
            at[list(fixed)] = grid[where] * scale  # their knots' times
        positions = alone.sample(at).q
        positions[0], positions[-1] = q[0], q[-1]
        return at, positions, knots, p, v, acc, j
    return None


def _scaled_spline(
    q: np.ndarray,
    path: tuple[np.ndarray, np.ndarray, np.ndarray],
    slopes: tuple[np.ndarray, np.ndarray],
    speed: _Speed,
    spacing: float,
    scale: float,
    template: JointTrajectory,
    bound: float,
    bounds: tuple[np.ndarray, np.ndarray],
    rest: tuple[bool, bool],
    pinned: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple | None:
    """The spline in time along the path with this speed, scaled so the tightest joint reaches its limit.

    Starts from the time `scale` the screening found; knots a spline through them carries
    beyond a joint's range are nudged inward (:func:`_nudge`).

    Returns:
        ``(knots, p, v, a, j, trajectory, grid, scale)`` (grid: the knot times before the
        scaling); None if none keeps the range.
    """
    lower, upper = bounds
    qk, grid = _knot_positions(q, path, speed, spacing, bounds, pinned)
    for _ in range(8):
        knots, p, v, acc, j = _time_spline(qk, grid, path, slopes, scale, rest)
        alone = replace(template, knots=knots, p=p, v=v, a=acc, j=j, duration=float(grid[-1] * scale))
        peaks = alone.peak_ratios(None)
        if peaks["position"] > LIMIT_TOLERANCE * bound:
            if not _nudge(qk, alone, lower, upper):
                return None
            continue
        # A uniform time scaling by k scales v, a, j by 1/k, 1/k^2, 1/k^3: the tightest
        # joint then reaches its limit (faster or slower).
        k = max(peaks["velocity"], peaks["acceleration"] ** 0.5, peaks["jerk"] ** (1.0 / 3.0))
        if max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE and k > 1 - 1e-6:
            return knots, p, v, acc, j, alone, grid, scale
        scale *= k * (1.0 + 1e-9)
    return None


def _spline_nodes(sigma: np.ndarray) -> np.ndarray:
    """Indices of the samples the path spline passes: all but those crowding a neighbour.

    A sample closer than :data:`NODE_GAP` times the median step to the node before it (or to
    the piece's end) is left out: there the line was bisected to bracket a corner, and a step
    that short points across the corner, which a spline through it would ring around.
    """
    gap = NODE_GAP * float(np.median(np.diff(sigma)))
    keep = [0]
    for i in range(1, len(sigma) - 1):
        if sigma[i] - sigma[keep[-1]] >= gap and sigma[-1] - sigma[i] >= gap:
            keep.append(i)
    keep.append(len(sigma) - 1)
    return np.array(keep)


def _nudge(q: np.ndarray, spline: JointTrajectory, lower: np.ndarray, upper: np.ndarray) -> bool:
    """Move inner knots near a joint bound inward by twice the spline's excess there.

    A line running along a joint limit has samples exactly at it; the spline through them rings
    a little beyond. Returns whether a knot was moved (never by more than :data:`MAX_NUDGE`).
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
    end = float(t[-1])
    before = traj.knots < t0 - 1e-12
    after = traj.knots >= t1 - 1e-12
    times = traj.waypoint_times.copy()
    times[first + 1 : last + 1] = t[1:]
    waypoints = traj.waypoints.copy()
    waypoints[first : last + 1] = q
    # What follows starts from the new end time plus how long after the old one it came (never
    # negative), not from its old time plus the shift, which can round below the new end time.
    times[last + 1 :] = end + (traj.waypoint_times[last + 1 :] - t1)
    return replace(
        traj,
        knots=read_only(np.concatenate([traj.knots[before], knots, end + (traj.knots[after] - t1)])),
        p=read_only(np.concatenate([traj.p[before], p, traj.p[after]])),
        v=read_only(np.concatenate([traj.v[before], v, traj.v[after]])),
        a=read_only(np.concatenate([traj.a[before], a, traj.a[after]])),
        j=read_only(np.concatenate([traj.j[before], j, traj.j[after]])),
        # From the last waypoint's new time plus what followed it (its dwell), so that the
        # duration is never a rounding below the last waypoint time (as duration + shift can be).
        duration=float(times[-1] + (traj.duration - traj.waypoint_times[-1])),
        waypoint_times=read_only(times),
        waypoints=read_only(waypoints),
    )
