"""The planner's fast paths against the plain forms they replace, bit for bit.

The via search computes some values on plain floats or with fewer array operations than the
forms that define them (the spline's via states, the range ends a joint can reach, the scaled
via states, the slope blend, the move-duration check) and skips work it can prove needless
(the turning points of a merged segment until asked for): each must give exactly what the
plain form gives.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planner.exceptions import PlanningError
from planner.motion.limits import JointLimits, admissible_acceleration
from planner.motion.plan import plan_trajectory
from planner.motion.segments import (
    _END_MISS,
    _LIMIT_SLACK,
    _POSITION_SLACK,
    SegmentSolver,
    _missed_turns,
    _profile_phases,
    merge_segment,
    reach_time,
)
from planner.motion.vias.heuristic import via_directions
from planner.motion.vias.optimized import _scaled_states, spline_via_states

from conftest import HAVE_EXAMPLE_ROBOT_DATA, needs_example_robot_data

#: Arms for the reach-time comparison: the bundled ones, and example-robot-data's where installed.
_ARMS = ["three_joint", "al5c", "dh3", *(["ur5", "panda", "so101", "z1"] if HAVE_EXAMPLE_ROBOT_DATA else [])]

finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
LIMITS3 = JointLimits(
    np.array([1.0, 2.5, 0.3]),
    np.array([2.0, 5.0, 0.6]),
    np.array([20.0, 50.0, 6.0]),
    np.full(3, -10.0),
    np.full(3, 10.0),
)


def spline_reference(q, h, v_start, v_end):
    """spline_via_states as arrays (the form the float version writes out)."""
    m = len(h)
    slope = (q[1:] - q[:-1]) / h[:, None]
    inv = 1.0 / h
    diag = (2.0 * (inv[:-1] + inv[1:])).tolist()
    rhs = 3.0 * (slope[:-1] * inv[:-1, None] + slope[1:] * inv[1:, None])
    inv_list = inv.tolist()
    rhs[0] -= inv_list[0] * v_start
    rhs[-1] -= inv_list[-1] * v_end
    c = [inv_list[1] / diag[0]]
    d = np.empty_like(rhs)
    d[0] = rhs[0] / diag[0]
    for r in range(1, m - 1):
        den = diag[r] - inv_list[r] * c[r - 1]
        c.append(inv_list[r + 1] / den)
        d[r] = (rhs[r] - inv_list[r] * d[r - 1]) / den
    v = np.empty_like(rhs)
    v[-1] = d[-1]
    for r in range(m - 3, -1, -1):
        v[r] = d[r] - c[r] * v[r + 1]
    v_next = np.empty_like(v)
    v_next[:-1], v_next[-1] = v[1:], v_end
    acc = (6.0 * slope[1:] - 4.0 * v - 2.0 * v_next) * inv[1:, None]
    return v, acc


@settings(max_examples=200, deadline=None)
@given(st.integers(2, 7), st.integers(1, 7), st.integers(0, 2**32 - 1), st.booleans())
def test_spline_via_states_equal_the_array_form_bit_for_bit(m, dof, seed, moving):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(m + 1, dof)) * 10.0 ** rng.uniform(-4, 2)
    h = rng.uniform(1e-3, 5.0, m)
    v_start = rng.normal(size=dof) if moving else np.zeros(dof)
    v_end = rng.normal(size=dof) if moving else np.zeros(dof)
    got, want = spline_via_states(q, h, v_start, v_end), spline_reference(q, h, v_start, v_end)
    for a, b in zip(got, want):
        assert a.shape == b.shape and a.tobytes() == b.tobytes()


def watch_reference(solver: SegmentSolver, limits: JointLimits, admissible):
    """SegmentSolver._watch_ends with reach_time called per end (the form it writes out)."""
    grow = 1.0 + _LIMIT_SLACK
    lows, highs = limits.checked_floats
    joints = [
        (
            j,
            v * grow,
            a * grow,
            lo,
            hi,
            lo + _POSITION_SLACK * max(1.0, abs(lo)),
            hi - _POSITION_SLACK * max(1.0, abs(hi)),
        )
        for j, (v, a, lo, hi) in enumerate(zip(*limits.ruckig_limits[:2], lows, highs))
    ]
    out = []
    for k, ok in enumerate(admissible):
        if not ok:
            out.append(None)
            continue
        ends = []
        for j, v, a, lo, hi, low, high in joints:
            start, end = solver.rows[k][j], solver.rows[k + 1][j]
            if hi < math.inf:
                ends.append((reach_time(high - start, v, a) + reach_time(high - end - _END_MISS, v, a), j, True, hi))
            if lo > -math.inf:
                ends.append((reach_time(start - low, v, a) + reach_time(end - _END_MISS - low, v, a), j, False, lo))
        ends.sort()
        out.append(ends)
    return out


@settings(max_examples=150, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from(_ARMS), st.booleans())
def test_watched_range_ends_equal_reach_time_per_end(seed, name, near_ends):
    from planner import load_robot

    robot = load_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(seed)
    q = robot.random_configurations(rng, int(rng.integers(2, 7)))
    if near_ends:  # waypoints on and next to the range ends (reach times 0 and tiny)
        upper = np.where(np.isfinite(limits.upper), limits.upper, 1.0)
        lower = np.where(np.isfinite(limits.lower), limits.lower, -1.0)
        q = np.where(rng.random(q.shape) < 0.3, upper - rng.uniform(0, 1e-6, q.shape), q)
        q = np.where(rng.random(q.shape) < 0.3, lower, q)
    admissible = (rng.random(len(q) - 1) < 0.8).tolist()
    admissible[0] = True
    solver = SegmentSolver(q, limits, None, admissible)
    assert solver._watch == watch_reference(solver, limits, admissible)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(finite, min_size=3, max_size=3),
    st.lists(finite, min_size=3, max_size=3),
    st.lists(st.floats(0.0, 1e3, allow_nan=False), min_size=1, max_size=6),
)
def test_scaled_states_equal_admissible_acceleration_of_the_scaled_blend(u, w, grid):
    limits = LIMITS3
    u, w, x = np.array(u), np.array(w), np.array([0.0, *grid])
    mag, wmag, su, sw = np.abs(u), np.abs(w), np.sign(u), np.sign(w)
    cv, ca = _scaled_states(x, su, mag, sw, wmag, limits)
    want_v = su * np.minimum(limits.velocity, x[:, None] * mag)
    want_a = admissible_acceleration(want_v, sw * np.minimum(limits.acceleration, x[:, None] ** 2 * wmag), limits)
    # Zeros made positive (one cache key for a joint at rest), every other value bit for bit.
    want_v, want_a = want_v + 0.0, want_a + 0.0
    assert cv.tobytes() == want_v.tobytes() and ca.tobytes() == want_a.tobytes()
    assert not np.signbit(cv[cv == 0.0]).any() and not np.signbit(ca[ca == 0.0]).any()


def via_directions_reference(q, i, durations, limits):
    tp, tn = float(durations[i - 1]), float(durations[i])
    total = tp + tn
    sp, sn = (q[i] - q[i - 1]) / tp, (q[i + 1] - q[i]) / tn
    u = np.minimum(np.maximum((sp * tn + sn * tp) / total, -limits.velocity), limits.velocity)
    w = np.minimum(np.maximum(2.0 * (sn - sp) / total, -limits.acceleration), limits.acceleration)
    return u, w


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.lists(finite, min_size=3, max_size=3), min_size=3, max_size=3), st.floats(1e-3, 10), st.floats(1e-3, 10)
)
def test_via_directions_equal_the_clipped_slope_blend(rows, tp, tn):
    limits = LIMITS3
    q = np.array(rows)
    got = via_directions(q, 1, np.array([tp, tn]), limits, np.zeros(3, dtype=bool))
    want = via_directions_reference(q, 1, np.array([tp, tn]), limits)
    for a, b in zip(got, want):
        assert a.tobytes() == b.tobytes()


def refusal(limits: JointLimits, q: np.ndarray, from_rest: bool) -> str | None:
    """check_move_durations' message, or None where it accepts."""
    try:
        limits.check_move_durations(q, from_rest=from_rest)
    except PlanningError as exc:
        return str(exc)
    return None


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.lists(st.one_of(st.floats(-1e7, 1e7), st.floats(-1e308, 1e308)), min_size=2, max_size=2),
        min_size=2,
        max_size=5,
    ),
    st.floats(1e-6, 1e3),
    st.booleans(),
)
def test_move_duration_check_accepts_at_once_only_what_the_full_check_accepts(rows, acceleration, from_rest):
    # The quick accept (plain floats) must give what the full check gives (its message too).
    def limits():
        return JointLimits(
            np.array([0.5, 2.0]),
            np.array([acceleration, 4.0]),
            np.array([10.0, 40.0]),
            np.full(2, -np.inf),
            np.full(2, np.inf),
        )

    q = np.array(rows)
    full = limits()
    full.__dict__["_quick_move"] = (-1.0, -1.0)  # no quick accept
    assert refusal(limits(), q, from_rest) == refusal(full, q, from_rest)


@pytest.mark.parametrize(
    "name", ["al5c", "three_joint", *(pytest.param(n, marks=needs_example_robot_data) for n in ("ur5", "z1", "panda"))]
)
def test_lazy_turning_points_of_plain_segments_are_those_of_their_phases(name):
    # A plain merged segment computes its turning points (missed) only when asked: they must be
    # the ones the phase arrays give, and the range repair's turns_beyond must flag exactly the
    # joints whose turning points leave the range.
    from planner import load_robot

    robot = load_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(7)
    lower, upper = limits.checked_range
    plain = 0
    for _ in range(20):
        traj = plan_trajectory(robot.random_configurations(rng, 5), limits)
        q, v, a = traj.waypoints, traj.via_velocities, traj.via_accelerations
        solver = SegmentSolver(q, limits, None, [True] * (len(q) - 1))
        for k in range(len(q) - 1):
            d, _, rt = solver.solve(k, v[k], a[k], v[k + 1], a[k + 1])
            merged = merge_segment(rt, d, (q[k], v[k], a[k]), q[k + 1], limits)
            if not merged.plain:
                continue
            plain += 1
            low, high = merged.missed
            want_low, want_high = _missed_turns(_profile_phases(rt.profiles[0])[1])
            assert low.tobytes() == want_low.tobytes() and high.tobytes() == want_high.tobytes()
            beyond = set(np.nonzero((low < lower) | (high > upper))[0].tolist())
            assert set(solver.turns_beyond(k, rt)) == beyond
            assert set(solver.turns_beyond(k, rt)) == beyond  # remembered
    assert plain > 0


def _s_curve_per_knot(out: np.ndarray, knots: np.ndarray, duration: float, error: np.ndarray) -> None:
    """The end correction's S-curve added knot by knot (the plain form of segments._add_s_curve)."""
    quarter = duration / 4.0
    big_j = 32.0 * error / duration**3
    state = [np.zeros_like(error), np.zeros_like(error), np.zeros_like(error)]
    table = []
    for sign in (1.0, -1.0, -1.0, 1.0):
        j = sign * big_j
        table.append((*state, j))
        p, v, a = state
        state = [
            p + quarter * (v + quarter * (a / 2.0 + quarter * j / 6.0)),
            v + quarter * (a + quarter * j / 2.0),
            a + quarter * j,
        ]
    for k, t in enumerate(knots):
        phase = min(int(t / quarter + 1e-9), 3)
        p, v, a, j = table[phase]
        dt = t - phase * quarter
        out[0, k] += p + dt * (v + dt * (a / 2.0 + dt * j / 6.0))
        out[1, k] += v + dt * (a + dt * j / 2.0)
        out[2, k] += a + dt * j
        out[3, k] += j


@settings(max_examples=200, deadline=None)
@given(
    st.integers(1, 7),
    st.lists(st.floats(0.0, 1.0, allow_nan=False), min_size=0, max_size=12),
    st.floats(1e-3, 50.0),
    st.integers(0, 2**32 - 1),
)
def test_end_correction_adds_its_s_curve_at_every_knot_as_knot_by_knot(dof, shares, duration, seed):
    # segments._add_s_curve adds the S-curve at all knots at once: the same operations as knot by
    # knot, so the same values bit for bit; the quarters of the segment are knots as merge_segment makes them.
    from planner.motion.segments import _add_s_curve

    rng = np.random.default_rng(seed)
    knots = np.unique(np.concatenate([[0.0], np.array(shares) * duration, duration * np.array([0.25, 0.5, 0.75])]))
    knots = knots[knots < duration]
    error = rng.normal(size=dof) * 1e-6 * (rng.random(dof) < 0.7)
    pieces = rng.normal(size=(4, len(knots), dof))
    expected, got = pieces.copy(), pieces.copy()
    _s_curve_per_knot(expected, knots, duration, error)
    assert _add_s_curve(got, knots, duration, error, None)
    assert got.tobytes() == expected.tobytes()
    # And it is the S-curve: half the error at mid-segment, exactly where the joint was without it.
    alone = np.zeros((4, len(knots), dof))
    _add_s_curve(alone, knots, duration, error, None)
    mid = int(np.flatnonzero(knots == duration * 0.5)[0])
    np.testing.assert_allclose(alone[0, mid], error / 2.0, rtol=1e-12, atol=1e-30)
    np.testing.assert_array_equal(alone[:3, 0], np.zeros((3, dof)))  # from rest, with the jerk J = 32 e / T^3
    np.testing.assert_array_equal(alone[3, 0], 32.0 * error / duration**3)
