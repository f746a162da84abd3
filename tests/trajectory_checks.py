"""Checks of a planned joint trajectory, computed here from its samples (shared by the property tests).

Two independent views of the motion limits:

- the trajectory's own sampled derivatives (``sample(t).qd``, ``.qdd``, ``.qddd``) on a dense grid
  plus every knot and knot midpoint;
- finite differences of densely sampled positions only: the n-th difference quotient over a
  step h is a weighted average of the n-th derivative over ``n h`` (mean-value theorem, B-spline
  kernels), so it is bounded by the same limit whatever h is. A jump in position, velocity or
  acceleration (which the own derivatives would not show) makes it blow up. The only slack
  is floating-point rounding of the sampled positions, amplified by ``2**n / h**n``.
"""

from __future__ import annotations

import numpy as np

# The guarantee documented by planner.motion.trajectory (LIMIT_TOLERANCE): sampled |velocity|,
# |acceleration| and |jerk| never exceed limit * (1 + REL); positions never leave their range by
# more than REL * max(1, |bound|). It absorbs floating-point rounding only.
REL = 1e-9
# Grid sizes of the finite differences of order 1, 2, 3 (coarser for higher orders, which
# amplify rounding more).
FD_STEPS = {1: 4000, 2: 1000, 3: 250}
# How far a waypoint's sampled position may be from the waypoint [rad or m].
WAYPOINT_ATOL = 1e-7


def assert_passes_waypoints(traj, times: np.ndarray, waypoints: np.ndarray) -> None:
    """The trajectory is at each waypoint at its time."""
    times = np.asarray(times, dtype=float)
    assert np.all(np.isfinite(times))
    assert np.all(times >= 0.0) and np.all(times <= traj.duration)
    assert np.all(np.diff(times) >= 0.0), f"waypoint times go backwards: {times.tolist()}"
    np.testing.assert_allclose(traj.sample(times).q, waypoints, rtol=0.0, atol=WAYPOINT_ATOL)


def assert_within_limits(traj, velocity, acceleration, jerk, lower, upper) -> None:
    """Positions within [lower, upper]; |qd|, |qdd|, |qddd| within their limits, both views.

    Args:
        traj: A :class:`planner.JointTrajectory`.
        velocity: Per-joint limits, shape (dof,) [rad/s or m/s]; acceleration and jerk likewise.
        lower: Position range, shape (dof,) [rad or m]; upper likewise.
    """
    limits = {1: np.asarray(velocity, float), 2: np.asarray(acceleration, float), 3: np.asarray(jerk, float)}
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    duration = float(traj.duration)
    assert np.isfinite(duration) and duration >= 0.0

    # The trajectory's own states.
    knots = np.asarray(traj.knots, dtype=float)
    ends = np.append(knots[1:], duration)
    t = np.unique(np.clip(np.concatenate([np.linspace(0.0, duration, 4001), knots, (knots + ends) / 2]), 0, duration))
    s = traj.sample(t)
    for name, values, order in (("velocity", s.qd, 1), ("acceleration", s.qdd, 2), ("jerk", s.qddd, 3)):
        assert np.all(np.isfinite(values))
        excess = np.abs(values) - limits[order] * (1 + REL)
        assert np.all(excess <= 0.0), _where(name, t, excess, limits[order])
    slack = REL * np.maximum(1.0, np.maximum(np.abs(lower), np.abs(upper)))
    assert np.all(np.isfinite(s.q))
    assert np.all(s.q >= lower - slack), _where("position below the range", t, lower - slack - s.q, lower)
    assert np.all(s.q <= upper + slack), _where("position above the range", t, s.q - upper - slack, upper)

    # Finite differences of the positions alone.
    if duration <= 0.0:
        return
    for order, steps in FD_STEPS.items():
        grid = np.linspace(0.0, duration, steps + 1)
        q = traj.sample(grid).q
        h = duration / steps
        # Rounding of each sampled position: of its value, and of the sample time times the speed.
        noise = 16 * np.finfo(float).eps * (max(1.0, float(np.max(np.abs(q)))) + float(np.max(limits[1])) * duration)
        if h**order < noise:
            continue  # so short that rounding alone could exceed any limit: this view says nothing
        quotient = np.diff(q, n=order, axis=0) / h**order
        allowed = limits[order] * (1 + REL) + 2**order * noise / h**order
        excess = np.abs(quotient) - allowed
        assert np.all(excess <= 0.0), _where(f"finite-difference order {order} (h = {h:.3g} s)", grid, excess, allowed)


def _where(what: str, t: np.ndarray, excess: np.ndarray, limit: np.ndarray) -> str:
    i, j = np.unravel_index(int(np.argmax(excess)), excess.shape)
    bound = np.broadcast_to(limit, excess.shape)[i, j]
    return f"{what} exceeds its limit {bound:.9g} by {excess[i, j]:.3g} at t={t[i]:.9g} s, joint {j}"
