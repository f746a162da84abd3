"""The ``"heuristic"`` via strategy: the slope blend of the neighbouring segments.

From the current segment durations T1, T2 and the slopes s1 = dq1 / T1, s2 = dq2 / T2 of the
two segments next to a via, each joint gets the slope blend ``(s1 T2 + s2 T1) / (T1 + T2)``
(what a cubic spline through the waypoint times has there) as its via velocity and the
acceleration ``2 (s2 - s1) / (T1 + T2)``, both within the joint's limits.
"""

from __future__ import annotations

import math

import numpy as np

from planner.motion.limits import JointLimits, admissible_acceleration
from planner.motion.vias.base import ViaChain, ViaStrategy
from planner.motion.vias.kernels import blend_directions

__all__ = ["HeuristicStrategy", "via_directions"]


def via_directions(
    q: np.ndarray, i: int, durations: np.ndarray, limits: JointLimits, stop: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Heuristic via velocity and acceleration at waypoint i, shapes (dof,).

    The velocity is the time-weighted blend of the average slopes of the two neighbouring
    segments (what a cubic spline through the waypoint times would have) for a joint that
    keeps its direction, zero for one that reverses or rests on a side. The acceleration is
    the spline's (the slope change over the mean segment time) for a joint that keeps its
    direction and full deceleration for one that turns round at the waypoint: there it is
    at rest but still braking, as in a time-optimal turn.

    Args:
        q: Waypoints, shape (N, dof) [rad or m].
        i: Index of the via waypoint, 0 < i < N-1.
        durations: Current segment durations, shape (N-1,) [s].
        limits: The limits (both results are clipped to them).
        stop: Waypoints to rest at, bool shape (N,); a stop gets zeros.
    """
    tp, tn = float(durations[i - 1]), float(durations[i])
    if stop[i] or not (math.isfinite(tp) and math.isfinite(tn)) or tp <= 0 or tn <= 0:
        zero = np.zeros(q.shape[1])
        return zero, zero
    fast = blend_directions(q[i - 1 : i + 2], tp, tn, limits.velocity, limits.acceleration)  # compiled, the same
    if fast is not None:
        return fast
    # On plain floats (faster than NumPy on a few joints; the same arithmetic, element by element).
    total = tp + tn
    velocity, acceleration, _ = limits.ruckig_limits
    u, w = [], []
    for before, at, after, v_max, a_max in zip(*q[i - 1 : i + 2].tolist(), velocity, acceleration):
        sp, sn = (at - before) / tp, (after - at) / tn
        # min(max(x, -top), top) written out (the same value, NaN too).
        x = (sp * tn + sn * tp) / total
        u.append(x if -v_max <= x <= v_max else v_max if x > v_max else -v_max if x < -v_max else x)
        x = 2.0 * (sn - sp) / total
        w.append(x if -a_max <= x <= a_max else a_max if x > a_max else -a_max if x < -a_max else x)
    return np.array(u), np.array(w)


class HeuristicStrategy(ViaStrategy):
    """Via states from the slope blend at the rest-to-rest segment durations (no search)."""

    name = "heuristic"

    def choose(self, chain: ViaChain) -> None:
        """Set every free via to the slope blend, its acceleration made admissible."""
        durations = chain.durations()
        for i in range(1, chain.n - 1):
            if chain.fixed[i]:
                continue
            u, w = via_directions(chain.q, i, durations, chain.limits, chain.stop)
            chain.v[i] = u
            chain.acc[i] = admissible_acceleration(u, w, chain.limits)
