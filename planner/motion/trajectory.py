"""Smooth, jerk-limited joint trajectories through waypoints, chained from Ruckig segments.

The community edition of Ruckig computes time-optimal state-to-state motions (position,
velocity and acceleration at both ends) under velocity, acceleration and jerk limits, but it
has no intermediate waypoints (``intermediate_positions`` calls a cloud service) and no
position limits. This module chains one Ruckig segment per pair of consecutive waypoints,
time-synchronised so that every joint reaches the next waypoint at the same instant, and
chooses the state (velocity and acceleration) at every via waypoint itself:

1. **Spline-like via states.** From the current segment durations T1, T2 and the slopes
   s1 = dq1 / T1, s2 = dq2 / T2 of the two neighbouring segments, each joint gets the slope
   blend ``(s1 T2 + s2 T1) / (T1 + T2)`` (what a cubic spline through the waypoint times has
   there) as its via velocity and the acceleration ``2 (s2 - s1) / (T1 + T2)``, both within
   the joint's limits (the ``"heuristic"`` strategy stops here).
2. **A joint choice, then a search per via waypoint.** All via states between two fixed
   waypoints are then chosen together: the C2 cubic spline through the waypoints at the
   segment durations gives every via a velocity and an acceleration consistent with all
   the others (a joint with time to spare may pass its waypoint still moving and turn just
   beyond it, as a spline does); the durations are scaled by a common factor, found by
   golden-section search, to minimise the chained Ruckig durations. Then each via is refined
   on its own: scaling time by 1/x multiplies velocities by x and accelerations by x^2, so
   candidates ``(x v, x^2 a)`` of the slope blend (each joint saturating at its limits) are
   tried on a grid and refined by golden-section search, minimising the duration of the two
   segments next to the waypoint. A second search moves joints that turn round at the
   waypoint towards a time-optimal turn: at rest, still braking at full deceleration. Each
   search keeps the current state unless a candidate is faster, and stopping at the via
   is one of the candidates.
3. **Range repair.** A non-zero via state can carry a joint past its range inside a segment.
   The search discards such candidates (halving the offending joints' via state), and every
   final segment is checked exactly: the per-joint extrema of its constant-jerk pieces
   (:func:`_piece_position_range`; Ruckig's own ``position_extrema`` misses turning points
   inside constant-acceleration phases). Where one lies outside the range, that joint's via
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

import csv
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
from ruckig import ControlInterface, InputParameter, Result, Ruckig, Synchronization
from ruckig import Trajectory as _RuckigTrajectory

from planner.core.units import servo_speed_to_velocity
from planner.exceptions import InvalidArgumentError, InvalidConfigurationError, InvalidLimitsError, JointLimitError

if TYPE_CHECKING:
    from planner.model.robot import Robot

__all__ = [
    "LIMIT_TOLERANCE",
    "JointLimits",
    "JointTrajectory",
    "TrajectorySample",
    "ViaStrategy",
    "check_waypoints",
    "plan_trajectory",
]

#: Relative tolerance of the limit guarantee: a sampled |velocity|, |acceleration| or |jerk|
#: never exceeds ``limit * (1 + LIMIT_TOLERANCE)``, a position never leaves its range by more
#: than ``LIMIT_TOLERANCE * max(1, |bound|)`` [rad or m]. It only absorbs floating-point rounding.
LIMIT_TOLERANCE = 1e-9

ViaStrategy = Literal["optimized", "heuristic", "stop"]

_OVERSHOOT_TOL = 1e-10
# Scale factors tried first for each via state (1 = the slope blend itself).
_GRID = (0.0, 0.5, 1.0, 1.4, 2.0, 3.0)
_GOLDEN_STEPS = 5
# Spline stage: range of the common log time-scale of the segment durations searched, and
# golden-section evaluations (a simplex over every duration gained nothing on top).
_SPLINE_SCALE = (-0.5, 0.1)
_SPLINE_SCALE_EVALS = 8
# A segment whose Ruckig extrema leave the range counts this much longer in the search.
_SPLINE_PENALTY = 1.5
_TURN_GRID = (0.0, 0.5, 1.0)
_TURN_STEPS = 3
_REPAIR_HALVINGS = 24
_REPAIR_HALVINGS_BEFORE_REST = 6
_SEARCH_HALVINGS = 6


def _per_joint(value: float | Sequence[float] | np.ndarray, names: Sequence[str], what: str, unit: str) -> np.ndarray:
    """A positive, finite limit per joint from a scalar or a sequence."""
    try:
        arr = np.array(value, dtype=float, copy=True)
    except (TypeError, ValueError) as exc:
        raise InvalidLimitsError(f"{what} limit must be a number or one number per joint, got {value!r}") from exc
    if arr.ndim == 0:
        arr = np.full(len(names), float(arr))
    if arr.shape != (len(names),):
        raise InvalidLimitsError(
            f"{what} limit has {arr.size} values; give one number or {len(names)} (joints {', '.join(names)})",
            value=value,
        )
    for name, x in zip(names, arr):
        if not (math.isfinite(x) and x > 0.0):
            raise InvalidLimitsError(
                f"{what} limit of joint {name!r} must be positive and finite [{unit}], got {x:.6g}", joint=name, value=x
            )
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class JointLimits:
    """Per-joint motion limits.

    Attributes:
        velocity: Speed limits, shape (dof,) [rad/s or m/s], read-only.
        acceleration: Acceleration limits, shape (dof,) [rad/s^2 or m/s^2], read-only.
        jerk: Jerk limits, shape (dof,) [rad/s^3 or m/s^3], read-only.
        lower: Lower position limits, shape (dof,) [rad or m]; -inf for unbounded joints.
        upper: Upper position limits, shape (dof,) [rad or m]; +inf for unbounded joints.
        joint_names: Joint names, for messages.
    """

    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    joint_names: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        # The joints are those of the position range (or of the names, when given).
        dof = np.size(self.lower) if np.ndim(self.lower) else np.size(self.velocity)
        names = tuple(self.joint_names) or tuple(f"joint{k}" for k in range(dof))
        object.__setattr__(self, "joint_names", names)
        for attr, what, unit in (
            ("velocity", "velocity", "rad/s or m/s"),
            ("acceleration", "acceleration", "rad/s^2 or m/s^2"),
            ("jerk", "jerk", "rad/s^3 or m/s^3"),
        ):
            object.__setattr__(self, attr, _per_joint(getattr(self, attr), names, what, unit))
        bounds = []
        for attr in ("lower", "upper"):
            try:
                arr = np.array(getattr(self, attr), dtype=float, copy=True)
            except (TypeError, ValueError) as exc:
                raise InvalidLimitsError(
                    f"{attr} position limits must be numbers, got {getattr(self, attr)!r}"
                ) from exc
            if arr.ndim == 0:
                arr = np.full(len(names), float(arr))
            if arr.shape != (len(names),):
                raise InvalidLimitsError(f"{attr} position limits need {len(names)} values, got shape {arr.shape}")
            bounds.append(arr)
        lower, upper = bounds
        for name, lo, hi in zip(names, lower, upper):
            if math.isnan(lo) or math.isnan(hi):
                raise InvalidLimitsError(f"position range of joint {name!r} holds NaN: [{lo}, {hi}]", joint=name)
            if lo > hi:
                raise InvalidLimitsError(
                    f"joint {name!r} has lower limit {lo:.6g} > upper limit {hi:.6g}", joint=name, value=(lo, hi)
                )
        for attr, arr in (("lower", lower), ("upper", upper)):
            arr.setflags(write=False)
            object.__setattr__(self, attr, arr)

    @property
    def dof(self) -> int:
        """Number of joints."""
        return len(self.joint_names)

    @classmethod
    def from_robot(
        cls,
        robot: Robot,
        velocity: float | Sequence[float] | None = None,
        acceleration: float | Sequence[float] | None = None,
        jerk: float | Sequence[float] | None = None,
        *,
        servo_seconds_per_60deg: float | Sequence[float] | None = None,
        acceleration_per_velocity: float = 2.0,
        jerk_per_acceleration: float = 10.0,
    ) -> JointLimits:
        """Limits for a robot's chain joints, with defaults derived from its speed limits.

        Args:
            robot: The robot (position ranges and URDF speed limits come from it).
            velocity: Speed limit(s) [rad/s or m/s], one for all joints or one per joint;
                None uses the URDF's ``<limit velocity>``.
            acceleration: Acceleration limit(s) [rad/s^2]; None is
                ``acceleration_per_velocity * velocity``.
            jerk: Jerk limit(s) [rad/s^3]; None is ``jerk_per_acceleration * acceleration``.
            servo_seconds_per_60deg: A hobby-servo speed rating (time for 60 deg [s]), one or
                per joint, used instead of `velocity` (give only one of the two).
            acceleration_per_velocity: Default acceleration over velocity [1/s].
            jerk_per_acceleration: Default jerk over acceleration [1/s].

        Returns:
            The limits.

        Raises:
            InvalidLimitsError: If a limit is zero, negative, NaN or has the wrong length, or
                the URDF has no speed for a joint and none is given.
        """
        names = robot.joint_names
        if velocity is not None and servo_seconds_per_60deg is not None:
            raise InvalidLimitsError("give either velocity or servo_seconds_per_60deg, not both")
        if servo_seconds_per_60deg is not None:
            secs = _per_joint(servo_seconds_per_60deg, names, "servo_seconds_per_60deg", "s")
            vel = np.array([servo_speed_to_velocity(float(s)) for s in secs])
        elif velocity is not None:
            vel = _per_joint(velocity, names, "velocity", "rad/s or m/s")
        else:
            vel = np.array(robot.velocity_limit, dtype=float)
            missing = [n for n, v in zip(names, vel) if not (math.isfinite(v) and v > 0)]
            if missing:
                raise InvalidLimitsError(
                    f"the URDF gives no positive speed for joint {missing[0]!r} "
                    f"(velocity {vel[names.index(missing[0])]:.6g}); pass velocity= or servo_seconds_per_60deg=",
                    joint=missing[0],
                )
        for what, factor in (
            ("acceleration_per_velocity", acceleration_per_velocity),
            ("jerk_per_acceleration", jerk_per_acceleration),
        ):
            if not (isinstance(factor, (int, float)) and math.isfinite(factor) and factor > 0):
                raise InvalidLimitsError(f"{what} must be positive and finite [1/s], got {factor!r}", value=factor)
        acc = (
            _per_joint(acceleration, names, "acceleration", "rad/s^2 or m/s^2")
            if acceleration is not None
            else vel * acceleration_per_velocity
        )
        jrk = _per_joint(jerk, names, "jerk", "rad/s^3 or m/s^3") if jerk is not None else acc * jerk_per_acceleration
        return cls(vel, acc, jrk, robot.lower, robot.upper, names)


@dataclass(frozen=True)
class TrajectorySample:
    """States of a trajectory at one or more instants.

    Attributes:
        t: Time(s) [s], shape () or (n,).
        q: Positions [rad or m], shape (dof,) or (n, dof).
        qd: Velocities [rad/s or m/s], same shape as `q`.
        qdd: Accelerations [rad/s^2 or m/s^2], same shape as `q`.
        qddd: Jerks [rad/s^3 or m/s^3], same shape as `q` (piecewise constant; at a switching
            instant the value of the interval that starts there).
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    qddd: np.ndarray


def _frozen_bool(a: np.ndarray) -> np.ndarray:
    out = np.array(a, dtype=bool, copy=True)
    out.setflags(write=False)
    return out


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class JointTrajectory:
    """A jerk-limited joint trajectory through waypoints (piecewise-constant jerk).

    Build one with :func:`plan_trajectory`. Time runs from 0 to :attr:`duration`; the state
    at ``waypoint_times[k]`` is exactly ``waypoints[k]`` with velocity ``via_velocities[k]``.

    Attributes:
        knots: Start times of the constant-jerk intervals, shape (K,) [s], ascending, knots[0] = 0.
        p: Positions at the interval starts, shape (K, dof) [rad or m].
        v: Velocities at the interval starts, shape (K, dof).
        a: Accelerations at the interval starts, shape (K, dof).
        j: Jerk within each interval, shape (K, dof).
        duration: Total duration [s].
        waypoints: The waypoints passed through, shape (N, dof).
        waypoint_times: When each waypoint is reached, shape (N,) [s]; with a dwell the arm
            arrives at this time and leaves ``dwell[k]`` later.
        via_velocities: The velocity at each waypoint, shape (N, dof).
        via_accelerations: The acceleration at each waypoint, shape (N, dof).
        dwell: Time spent at rest at each waypoint, shape (N,) [s].
        limits: The limits the trajectory honours.
        strategy: How the via velocities were chosen (see :func:`plan_trajectory`).
        repaired: Per waypoint and joint, whether the final range check lowered the via state
            (velocity and acceleration) to keep a joint inside its range, shape (N, dof) bool.
            The optimizing search already avoids states that leave the range, so this is set
            mostly for the ``"heuristic"`` strategy and prescribed via states.
    """

    knots: np.ndarray
    p: np.ndarray
    v: np.ndarray
    a: np.ndarray
    j: np.ndarray
    duration: float
    waypoints: np.ndarray
    waypoint_times: np.ndarray
    via_velocities: np.ndarray
    via_accelerations: np.ndarray
    dwell: np.ndarray
    limits: JointLimits
    strategy: str
    repaired: np.ndarray

    @property
    def dof(self) -> int:
        """Number of joints."""
        return self.waypoints.shape[1]

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Joint names, from the limits."""
        return self.limits.joint_names

    def __repr__(self) -> str:
        return (
            f"JointTrajectory(duration={self.duration:.6g} s, waypoints={len(self.waypoints)}, "
            f"dof={self.dof}, strategy={self.strategy!r})"
        )

    def sample(self, t: float | Sequence[float] | np.ndarray) -> TrajectorySample:
        """State at time(s) `t`.

        Args:
            t: A time or an array of times in [0, duration] [s].

        Returns:
            The sample; arrays have shape (dof,) for a scalar `t`, (n, dof) for n times.

        Raises:
            InvalidArgumentError: If a time is NaN or outside [0, duration].
        """
        tt = np.asarray(t, dtype=float)
        scalar = tt.ndim == 0
        flat = tt.reshape(-1)
        if flat.size and (
            not np.all(np.isfinite(flat)) or flat.min() < 0.0 or flat.max() > self.duration * (1 + 1e-12)
        ):
            bad = flat[~np.isfinite(flat) | (flat < 0) | (flat > self.duration * (1 + 1e-12))][0]
            raise InvalidArgumentError(f"time {bad!r} s is outside the trajectory [0, {self.duration:.6g}] s")
        idx = np.clip(np.searchsorted(self.knots, flat, side="right") - 1, 0, len(self.knots) - 1)
        dt = (flat - self.knots[idx])[:, None]
        p, v, a, j = self.p[idx], self.v[idx], self.a[idx], self.j[idx]
        q = p + dt * (v + dt * (a / 2.0 + dt * j / 6.0))
        qd = v + dt * (a + dt * j / 2.0)
        qdd = a + dt * j
        qddd = j.copy()
        end = flat >= self.duration
        if end.any():
            q[end], qd[end], qdd[end], qddd[end] = self.waypoints[-1], 0.0, 0.0, 0.0
        if scalar:
            return TrajectorySample(tt.copy(), q[0], qd[0], qdd[0], qddd[0])
        shape = tt.shape + (self.dof,)
        return TrajectorySample(
            flat.reshape(tt.shape), q.reshape(shape), qd.reshape(shape), qdd.reshape(shape), qddd.reshape(shape)
        )

    def times(self, rate: float = 1000.0) -> np.ndarray:
        """Sample times at `rate` [Hz] from 0, with the final time appended, shape (n,) [s]."""
        if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
            raise InvalidArgumentError(f"rate must be positive and finite [Hz], got {rate!r}")
        n = int(math.floor(self.duration * rate + 1e-9)) + 1
        t = np.arange(n) / rate
        if t[-1] < self.duration:
            t = np.append(t, self.duration)
        return t

    def sampled(self, rate: float = 1000.0) -> TrajectorySample:
        """The trajectory sampled at `rate` [Hz] (plus the final instant), arrays (n, dof)."""
        return self.sample(self.times(rate))

    def peak_ratios(self, rate: float | None = 1000.0) -> dict[str, float]:
        """Peak |velocity|, |acceleration| and |jerk| over their limits, and the position margin.

        Args:
            rate: Sampling rate [Hz]; None evaluates the piecewise polynomials exactly
                (interval ends and interior velocity extrema).

        Returns:
            ``{"velocity": ..., "acceleration": ..., "jerk": ..., "position": ...}``: the
            largest ratio over all joints (1.0 means a limit is reached), and for position the
            largest excess beyond the range [rad or m] (<= 0 inside).
        """
        if rate is None:
            s = self._extreme_states()
        else:
            s = self.sampled(rate)
        lim = self.limits
        over_lo = np.where(np.isfinite(lim.lower), lim.lower - s.q, -np.inf)
        over_hi = np.where(np.isfinite(lim.upper), s.q - lim.upper, -np.inf)
        pos = float(np.max(np.maximum(over_lo, over_hi))) if s.q.size else -math.inf
        return {
            "velocity": float(np.max(np.abs(s.qd) / lim.velocity)),
            "acceleration": float(np.max(np.abs(s.qdd) / lim.acceleration)),
            "jerk": float(np.max(np.abs(s.qddd) / lim.jerk)),
            "position": pos,
        }

    def _extreme_states(self) -> TrajectorySample:
        """States at every knot, interval end and interior velocity/position extremum."""
        ends = np.append(self.knots[1:], self.duration)
        h = (ends - self.knots)[:, None]
        extra = []
        # Interior extrema of v (where a = 0) and of q (where v = 0) of each cubic piece.
        with np.errstate(divide="ignore", invalid="ignore"):
            tv = -self.a / self.j
            extra.append(np.where((self.j != 0) & (tv > 0) & (tv < h), tv, np.nan))
            disc = self.a**2 - 2.0 * self.j * self.v
            sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
            for r in ((-self.a + sq) / self.j, (-self.a - sq) / self.j):
                extra.append(np.where((self.j != 0) & (r > 0) & (r < h), r, np.nan))
            lin = -self.v / self.a
            extra.append(np.where((self.j == 0) & (self.a != 0) & (lin > 0) & (lin < h), lin, np.nan))
        t = [self.knots, np.minimum(ends, self.duration)]
        for e in extra:
            rows = self.knots[:, None] + e
            t.append(rows[np.isfinite(rows)])
        times = np.clip(np.unique(np.concatenate(t)), 0.0, self.duration)
        s = self.sample(times)
        # Jerk is piecewise constant: its peak is over the intervals themselves.
        jerk = np.vstack([s.qddd, self.j]) if len(self.j) else s.qddd
        return TrajectorySample(s.t, s.q, s.qd, s.qdd, jerk)

    def to_csv(self, path: str | Path, rate: float = 1000.0) -> Path:
        """Write the trajectory sampled at `rate` [Hz] as CSV.

        Columns: ``t`` [s], then ``q_<joint>``, ``qd_<joint>``, ``qdd_<joint>``,
        ``qddd_<joint>`` for every joint (SI units).

        Returns:
            The path written.
        """
        s = self.sampled(rate)
        out = Path(path)
        names = self.joint_names
        header = ["t"] + [f"{k}_{n}" for k in ("q", "qd", "qdd", "qddd") for n in names]
        with out.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(header)
            data = np.hstack([s.t[:, None], s.q, s.qd, s.qdd, s.qddd])
            for row in data:
                w.writerow([repr(float(x)) for x in row])
        return out


# ---------------------------------------------------------------------------- input checks
def check_waypoints(waypoints: Sequence[Sequence[float]] | np.ndarray, limits: JointLimits) -> np.ndarray:
    """Validate joint waypoints against limits and return them as a new (N, dof) float array.

    Raises:
        InvalidArgumentError: If there are fewer than two waypoints.
        InvalidConfigurationError: If a waypoint has the wrong length or a NaN/infinite value.
        JointLimitError: If a waypoint lies outside a joint's range (joint and value named).
    """
    names = limits.joint_names
    rows = list(waypoints) if not isinstance(waypoints, np.ndarray) else list(waypoints)
    if len(rows) < 2:
        raise InvalidArgumentError(f"a trajectory needs at least two waypoints, got {len(rows)}")
    out = np.empty((len(rows), limits.dof))
    for k, row in enumerate(rows):
        try:
            arr = np.array(row, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InvalidConfigurationError(f"waypoint {k} must be {limits.dof} numbers, got {row!r}") from exc
        if arr.shape != (limits.dof,):
            raise InvalidConfigurationError(
                f"waypoint {k} has {arr.size} values; expected {limits.dof}, one per joint ({', '.join(names)})"
            )
        bad = np.nonzero(~np.isfinite(arr))[0]
        if bad.size:
            raise InvalidConfigurationError(
                f"waypoint {k} holds {arr[bad[0]]} for joint {names[bad[0]]!r}; values must be finite"
            )
        out_of_range = np.nonzero((arr < limits.lower) | (arr > limits.upper))[0]
        if out_of_range.size:
            jj = int(out_of_range[0])
            raise JointLimitError(names[jj], arr[jj], limits.lower[jj], limits.upper[jj], context=f"waypoint {k}")
        out[k] = arr
    return out


def _check_state(
    value: Sequence[float] | np.ndarray | None, limit: np.ndarray, names: Sequence[str], what: str
) -> np.ndarray:
    if value is None:
        return np.zeros(len(names))
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidArgumentError(f"{what} must be {len(names)} numbers, got {value!r}") from exc
    if arr.shape != (len(names),):
        raise InvalidArgumentError(f"{what} has {arr.size} values; expected {len(names)} ({', '.join(names)})")
    for name, x, lim in zip(names, arr, limit):
        if not math.isfinite(x):
            raise InvalidArgumentError(f"{what} of joint {name!r} must be finite, got {x}")
        if abs(x) > lim:
            raise InvalidArgumentError(f"{what} of joint {name!r} is {x:.6g}, beyond its limit +-{lim:.6g}")
    return arr


def _check_given(
    velocities: np.ndarray | None,
    accelerations: np.ndarray | None,
    min_durations: Sequence[float] | np.ndarray | None,
    n: int,
    limits: JointLimits,
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    if velocities is None and accelerations is None and min_durations is None:
        return None
    dof = limits.dof
    out = []
    for what, value, lim in (
        ("via_velocities", velocities, limits.velocity),
        ("via_accelerations", accelerations, limits.acceleration),
    ):
        arr = np.full((n, dof), np.nan) if value is None else np.array(value, dtype=float)
        if arr.shape != (n, dof):
            raise InvalidArgumentError(f"{what} must have shape ({n}, {dof}), got {arr.shape}")
        given = np.isfinite(arr)
        if np.any(np.abs(arr[given]) > np.broadcast_to(lim, arr.shape)[given] * (1 + 1e-12)):
            k, j = np.argwhere(given & (np.abs(np.nan_to_num(arr)) > lim * (1 + 1e-12)))[0]
            raise InvalidArgumentError(
                f"{what}[{k}] of joint {limits.joint_names[j]!r} is {arr[k, j]:.6g}, beyond its limit +-{lim[j]:.6g}"
            )
        out.append(arr)
    v, a = out
    rows = np.all(np.isfinite(v), axis=1)
    a = np.where(np.isfinite(a), a, 0.0)
    v = np.where(rows[:, None], v, np.nan)
    md = np.zeros(n - 1) if min_durations is None else np.array(min_durations, dtype=float)
    if md.shape != (n - 1,) or np.any(~np.isfinite(md)) or np.any(md < 0):
        raise InvalidArgumentError(f"min_durations needs {n - 1} finite values >= 0 [s], got {min_durations!r}")
    return v, a, md


def _check_stops(stops: Sequence[int] | None, n: int) -> np.ndarray:
    stop = np.zeros(n, dtype=bool)
    for s in stops or ():
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or not -n <= s < n:
            raise InvalidArgumentError(f"stop index {s!r} is not a waypoint index (0..{n - 1})")
        stop[s] = True
    return stop


def _check_dwell(dwell: float | Sequence[float] | None, n: int) -> np.ndarray:
    if dwell is None:
        return np.zeros(n)
    arr = np.array(dwell, dtype=float)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise InvalidArgumentError(f"dwell needs one time per waypoint ({n}), got {arr.size}")
    bad = np.nonzero(~np.isfinite(arr) | (arr < 0))[0]
    if bad.size:
        raise InvalidArgumentError(f"dwell at waypoint {int(bad[0])} must be >= 0 and finite [s], got {arr[bad[0]]}")
    return arr


# ---------------------------------------------------------------------------- Ruckig segments


def _piece_position_range(knots: np.ndarray, pvaj: np.ndarray, end: float) -> tuple[np.ndarray, np.ndarray]:
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


class _Segments:
    """Ruckig state-to-state segments between fixed positions, with position-range checks."""

    def __init__(self, q: np.ndarray, limits: JointLimits, min_durations: np.ndarray | None = None):
        self.q = q
        self.rows = [row.tolist() for row in q]
        self.min_durations = min_durations
        self._min_set = False
        self.dof = q.shape[1]
        self.lower = limits.lower - _OVERSHOOT_TOL * np.maximum(1.0, np.abs(np.nan_to_num(limits.lower)))
        self.upper = limits.upper + _OVERSHOOT_TOL * np.maximum(1.0, np.abs(np.nan_to_num(limits.upper)))
        self._bounds = list(zip(self.lower.tolist(), self.upper.tolist()))
        self.bounded = bool(np.any(np.isfinite(limits.lower)) or np.any(np.isfinite(limits.upper)))
        self.otg = Ruckig(self.dof)
        self.inp = InputParameter(self.dof)
        self.inp.max_velocity = limits.velocity.tolist()
        self.inp.max_acceleration = limits.acceleration.tolist()
        self.inp.max_jerk = limits.jerk.tolist()
        self.scratch = _RuckigTrajectory(self.dof)

    def solve(
        self, k: int, va: np.ndarray, aa: np.ndarray, vb: np.ndarray, ab: np.ndarray, keep: bool = False
    ) -> tuple[float, np.ndarray | None, _RuckigTrajectory | None]:
        """Segment k from state (va, aa) to (vb, ab).

        Returns:
            The duration [s] (inf when Ruckig finds no profile), a bool mask of the joints that
            Ruckig's extrema put outside their range (None when none does), and the Ruckig
            trajectory when `keep`.
        """
        inp = self.inp
        inp.current_position = self.rows[k]
        inp.current_velocity = va.tolist()
        inp.current_acceleration = aa.tolist()
        inp.target_position = self.rows[k + 1]
        inp.target_velocity = vb.tolist()
        inp.target_acceleration = ab.tolist()
        if self.min_durations is not None and self.min_durations[k] > 0:
            inp.minimum_duration = float(self.min_durations[k])
            self._min_set = True
        elif self._min_set:
            inp.minimum_duration = None
            self._min_set = False
        traj = _RuckigTrajectory(self.dof) if keep else self.scratch
        result = self.otg.calculate(inp, traj)
        if result not in (Result.Working, Result.Finished):
            return math.inf, None, None
        bad = None
        if self.bounded:
            flags = [e.min < lo or e.max > hi for e, (lo, hi) in zip(traj.position_extrema, self._bounds)]
            if any(flags):
                bad = np.array(flags)
        return traj.duration, bad, traj if keep else None


def _via_directions(
    q: np.ndarray, i: int, durations: np.ndarray, limits: JointLimits, stop: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Heuristic via velocity and acceleration at waypoint i, shapes (dof,).

    The velocity is the time-weighted blend of the average slopes of the two neighbouring
    segments (what a cubic spline through the waypoint times would have) for a joint that
    keeps its direction, zero for one that reverses or rests on a side. The acceleration is
    the spline's (the slope change over the mean segment time) for a joint that keeps its
    direction and full deceleration for one that turns round at the waypoint: there it is
    at rest but still braking, as in a time-optimal turn.
    """
    dof = q.shape[1]
    zero = np.zeros(dof)
    if stop[i]:
        return zero, zero
    dp, dn = q[i] - q[i - 1], q[i + 1] - q[i]
    tp, tn = durations[i - 1], durations[i]
    if not (math.isfinite(tp) and math.isfinite(tn)) or tp <= 0 or tn <= 0:
        return zero, zero
    sp, sn = dp / tp, dn / tn
    u = (sp * tn + sn * tp) / (tp + tn)
    u = np.clip(u, -limits.velocity, limits.velocity)
    w = 2.0 * (sn - sp) / (tp + tn)
    return u, np.clip(w, -limits.acceleration, limits.acceleration)


def _spline_via_states(
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
    m = len(h)
    slope = np.diff(q, axis=0) / h[:, None]  # (m, dof)
    inv = 1.0 / h
    # Tridiagonal system for v_1 .. v_{m-1} (Thomas algorithm, one right-hand side per joint).
    diag = 2.0 * (inv[:-1] + inv[1:])
    rhs = 3.0 * (slope[:-1] * inv[:-1, None] + slope[1:] * inv[1:, None])
    rhs[0] -= inv[0] * v_start
    rhs[-1] -= inv[-1] * v_end
    c = np.empty(m - 1)
    d = np.empty_like(rhs)
    c[0], d[0] = inv[1] / diag[0], rhs[0] / diag[0]
    for r in range(1, m - 1):
        den = diag[r] - inv[r] * c[r - 1]
        c[r] = inv[r + 1] / den
        d[r] = (rhs[r] - inv[r] * d[r - 1]) / den
    v = np.empty_like(rhs)
    v[-1] = d[-1]
    for r in range(m - 3, -1, -1):
        v[r] = d[r] - c[r] * v[r + 1]
    v_next = np.vstack([v[1:], v_end[None]])
    acc = (6.0 * slope[1:] - 4.0 * v - 2.0 * v_next) * inv[1:, None]
    return v, acc


def _golden_minimum(f: Callable[[float], float], lo: float, hi: float, evals: int) -> float:
    """Golden-section search for a minimum of f on [lo, hi] with `evals` evaluations."""
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


def _admissible_acceleration(v: np.ndarray, a: np.ndarray, limits: JointLimits) -> np.ndarray:
    """Limit a via acceleration so the state can be reached and left within the limits.

    A state with |v| + a^2 / (2 j_max) > v_max would have needed (or would need) a speed beyond
    v_max on one side of the waypoint.
    """
    room = np.maximum(limits.velocity - np.abs(v), 0.0)
    amax = np.minimum(limits.acceleration, np.sqrt(2.0 * limits.jerk * room) * (1.0 - 1e-9))
    return np.maximum(np.minimum(a, amax), -amax)


class _Planner:
    def __init__(
        self,
        q: np.ndarray,
        limits: JointLimits,
        v0: np.ndarray,
        a0: np.ndarray,
        stop: np.ndarray,
        given: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ):
        self.q = q
        self.n = len(q)
        self.limits = limits
        self.v = np.zeros_like(q)
        self.acc = np.zeros_like(q)
        self.stop = stop
        self.fixed = np.zeros(self.n, dtype=bool)
        min_durations = None
        if given is not None:
            gv, ga, min_durations = given
            rows = np.all(np.isfinite(gv), axis=1) & ~stop
            self.v[rows], self.acc[rows] = gv[rows], _admissible_acceleration(gv[rows], ga[rows], limits)
            self.fixed |= rows
        self.v[0], self.acc[0] = v0, a0
        self.fixed[0] = self.fixed[-1] = True
        self.fixed |= stop
        self.v[-1] = self.acc[-1] = 0.0
        self.v[stop & (np.arange(self.n) > 0)] = 0.0
        self.acc[stop & (np.arange(self.n) > 0)] = 0.0
        self.seg = _Segments(q, limits, min_durations)
        self.repaired = np.zeros(q.shape, dtype=bool)

    def durations(self) -> np.ndarray:
        out = np.empty(self.n - 1)
        for k in range(self.n - 1):
            out[k] = self.seg.solve(k, self.v[k], self.acc[k], self.v[k + 1], self.acc[k + 1])[0]
        return out

    def pair_cost(self, i: int, cv: np.ndarray, ca: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """Duration of the two segments around via i with state (cv, ca) there.

        A joint that would leave its range gets its via speed and acceleration halved until
        it does not (Ruckig's extrema are used here for speed; the final plan rechecks exactly).
        """
        cv = np.array(cv, dtype=float)
        ca = _admissible_acceleration(cv, np.asarray(ca, dtype=float), self.limits)
        for attempt in range(_SEARCH_HALVINGS + 1):
            d1, bad1, _ = self.seg.solve(i - 1, self.v[i - 1], self.acc[i - 1], cv, ca)
            d2, bad2, _ = self.seg.solve(i, cv, ca, self.v[i + 1], self.acc[i + 1])
            if bad1 is None and bad2 is None:
                return d1 + d2, cv, ca
            bad_any = (bad1 if bad1 is not None else False) | (bad2 if bad2 is not None else False)
            bad = bad_any & ((cv != 0) | (ca != 0))
            if not bad.any():
                return math.inf, cv, ca
            scale = 0.0 if attempt >= _SEARCH_HALVINGS - 1 else 0.5
            cv[bad] *= scale
            ca[bad] *= scale
        return math.inf, cv, ca

    def _line_search(
        self,
        i: int,
        make: Callable[[float], tuple[np.ndarray, np.ndarray]],
        top: float,
        grid: Sequence[float] = _GRID,
        steps: int = _GOLDEN_STEPS,
    ) -> None:
        """Minimise the pair cost over a scalar parameter in [0, top] (grid, then golden section)."""
        cache: dict[float, tuple[float, np.ndarray, np.ndarray]] = {}

        def cost(x: float) -> float:
            if x not in cache:
                cache[x] = self.pair_cost(i, *make(x))
            return cache[x][0]

        current = self.pair_cost(i, self.v[i], self.acc[i])
        grid = sorted({min(g, top) for g in grid} | {top})
        values = [cost(g) for g in grid]
        b = int(np.argmin(values))
        lo, hi = grid[max(b - 1, 0)], grid[min(b + 1, len(grid) - 1)]
        _golden_minimum(cost, lo, hi, steps + 2)  # its evaluations fill the cache
        best = min(cache.values(), key=lambda c: c[0])
        if best[0] < current[0]:
            _, self.v[i], self.acc[i] = best
        else:
            _, self.v[i], self.acc[i] = current

    def search_via(self, i: int, u: np.ndarray, w: np.ndarray) -> None:
        """Time-scale the spline-like via state (u, w) at via i to minimise its segments' time.

        Scaling a trajectory's time by 1/x multiplies velocities by x and accelerations by
        x^2, so the candidates are ``(x u, x^2 w)``, each joint saturating at its limits.
        """
        lim = self.limits
        mag, wmag = np.abs(u), np.abs(w)
        tops = [1.0]
        if np.any(mag > 0):
            tops.append(float(np.max(lim.velocity[mag > 0] / mag[mag > 0])))
        if np.any(wmag > 0):
            tops.append(math.sqrt(float(np.max(lim.acceleration[wmag > 0] / wmag[wmag > 0]))))
        self._line_search(
            i,
            lambda x: (
                np.sign(u) * np.minimum(lim.velocity, x * mag),
                np.sign(w) * np.minimum(lim.acceleration, x * x * wmag),
            ),
            max(tops),
        )

    def _settle(self, free: list[int]) -> None:
        """Halve the via states of joints that (by Ruckig's extrema) leave their range.

        Done before the search, so that each via is searched next to neighbours that fit.
        """
        for _ in range(_REPAIR_HALVINGS):
            changed = False
            for k in range(self.n - 1):
                bad = self.seg.solve(k, self.v[k], self.acc[k], self.v[k + 1], self.acc[k + 1])[1]
                if bad is None:
                    continue
                for idx in (k, k + 1):
                    if idx in free and np.any((self.v[idx] != 0) & bad):
                        self.v[idx] = np.where(bad, 0.5 * self.v[idx], self.v[idx])
                        self.acc[idx] = np.where(bad, 0.5 * self.acc[idx], self.acc[idx])
                        changed = True
            if not changed:
                return

    def search_spline(self, a: int, b: int, durations: np.ndarray) -> None:
        """Choose the via states between fixed waypoints a and b jointly, from a timed spline.

        Given segment durations, the C2 cubic spline through the waypoints at those times
        gives every via a velocity and an acceleration that fit all the others (a joint that
        turns round at a waypoint may pass it still moving, turning just beyond, as on the
        spline). A common time scale of the durations is searched (golden section, in log
        scale) to minimise the Ruckig durations of segments a..b-1 with those via states;
        the best states whose segments stay within the range (by Ruckig's extrema) replace
        the current ones if they are faster.
        """
        lim = self.limits
        h0 = durations[a:b]
        if not np.all(np.isfinite(h0)) or np.any(h0 <= 0):
            return
        q_run = self.q[a : b + 1]
        v_a, v_b = self.v[a], self.v[b]
        best: list = [math.inf, None, None]

        def cost(log_h: np.ndarray) -> float:
            v, acc = _spline_via_states(q_run, np.exp(log_h), v_a, v_b)
            v = np.clip(v, -lim.velocity, lim.velocity)
            acc = _admissible_acceleration(v, acc, lim)
            total, inside = 0.0, True
            for k in range(a, b):
                va, aa = (self.v[a], self.acc[a]) if k == a else (v[k - a - 1], acc[k - a - 1])
                vb, ab = (self.v[b], self.acc[b]) if k == b - 1 else (v[k - a], acc[k - a])
                d, bad, _ = self.seg.solve(k, va, aa, vb, ab)
                if bad is not None:
                    inside = False
                    d *= _SPLINE_PENALTY
                total += d
            if inside and total < best[0]:
                best[:] = [total, v, acc]
            return total

        current = 0.0
        for k in range(a, b):
            d, bad, _ = self.seg.solve(k, self.v[k], self.acc[k], self.v[k + 1], self.acc[k + 1])
            current += math.inf if bad is not None else d
        log_h = np.log(h0)
        _golden_minimum(lambda x: cost(log_h + x), *_SPLINE_SCALE, _SPLINE_SCALE_EVALS)
        if best[0] < current:
            self.v[a + 1 : b], self.acc[a + 1 : b] = best[1], best[2]

    def search_turn(self, i: int) -> None:
        """Let joints that turn round at via i pass it at rest but still braking.

        A joint at its time limit turns fastest at rest with full deceleration (a bang-bang
        turn); the slope blend gives it a small speed and acceleration instead. Candidates
        move the turning joints from their current state towards that one.
        """
        dp, dn = self.q[i] - self.q[i - 1], self.q[i + 1] - self.q[i]
        turning = dp * dn < 0
        if not turning.any():
            return
        lim = self.limits
        v_now, a_now = self.v[i].copy(), self.acc[i].copy()
        a_turn = -np.sign(dp) * lim.acceleration

        def make(y: float) -> tuple[np.ndarray, np.ndarray]:
            return (
                np.where(turning, (1.0 - y) * v_now, v_now),
                np.where(turning, (1.0 - y) * a_now + y * a_turn, a_now),
            )

        self._line_search(i, make, 1.0, grid=_TURN_GRID, steps=_TURN_STEPS)

    def optimize(self, strategy: str) -> None:
        """Choose the via states: none (stop), the slope blend (heuristic), or a searched one."""
        if strategy == "stop" or self.n < 3:
            return
        free = [i for i in range(1, self.n - 1) if not self.fixed[i]]
        durations = self.durations()
        for i in free:
            u, w = _via_directions(self.q, i, durations, self.limits, self.stop)
            self.v[i] = u
            if strategy == "heuristic":
                self.acc[i] = _admissible_acceleration(u, w, self.limits)
        if strategy == "heuristic":
            return
        self._settle(free)
        # All via states of a run between fixed waypoints at once, from a timed spline.
        durations = self.durations()
        fixed = [i for i in range(self.n) if self.fixed[i]]
        for a, b in zip(fixed[:-1], fixed[1:]):
            if b - a >= 2:
                self.search_spline(a, b, durations)
        # Then one sweep: the slope blend from the durations, time-scaled per via, and the
        # turn search (more sweeps or per-joint refinement gained about 1 % in tests).
        durations = self.durations()
        for i in free:
            u, w = _via_directions(self.q, i, durations, self.limits, self.stop)
            if np.any(u) or np.any(w):
                self.search_via(i, u, w)
            self.search_turn(i)
            durations[i - 1] = self.seg.solve(i - 1, self.v[i - 1], self.acc[i - 1], self.v[i], self.acc[i])[0]
            durations[i] = self.seg.solve(i, self.v[i], self.acc[i], self.v[i + 1], self.acc[i + 1])[0]

    def repair(self) -> list[tuple[float, np.ndarray, np.ndarray]]:
        """Lower via velocities until no segment carries a joint outside its range.

        Returns:
            Per segment: its duration, local knot times and stacked (p, v, a, j) pieces.
        """
        before = np.hstack([self.v, self.acc])
        halved = np.zeros(self.v.shape, dtype=int)
        for _ in range(4 * _REPAIR_HALVINGS + self.n):
            segments, any_bad = [], False
            for k in range(self.n - 1):
                start = (self.q[k], self.v[k], self.acc[k])
                d, _, traj = self.seg.solve(k, self.v[k], self.acc[k], self.v[k + 1], self.acc[k + 1], keep=True)
                if traj is None:
                    # Ruckig found no profile: rest at the free ends of this segment.
                    for idx in (k, k + 1):
                        if idx > 0:
                            self.v[idx] = 0.0
                            self.acc[idx] = 0.0
                    any_bad = True
                    continue
                local, pieces = _merge_segment(traj, d, start)
                segments.append((d, local, pieces))
                if not self.seg.bounded or not len(local):
                    continue
                lo, hi = _piece_position_range(local, pieces, d)
                bad = (lo < self.seg.lower) | (hi > self.seg.upper)
                if not bad.any():
                    continue
                any_bad = True
                movable = [
                    idx
                    for idx in (k, k + 1)
                    if idx > 0 and (np.any(self.v[idx][bad] != 0) or np.any(self.acc[idx][bad] != 0))
                ]
                if not movable:
                    raise _StartOvershoot
                for idx in movable:
                    # Halve a few times, then rest: a joint running along its range end over
                    # many samples would otherwise pass the overshoot on from via to via.
                    small = (np.abs(self.v[idx]) < 1e-6 * self.limits.velocity) & (
                        np.abs(self.acc[idx]) < 1e-6 * self.limits.acceleration
                    ) | (halved[idx] >= _REPAIR_HALVINGS_BEFORE_REST)
                    halved[idx] += bad
                    factor = np.where(bad, np.where(small, 0.0, 0.5), 1.0)
                    self.v[idx] *= factor
                    self.acc[idx] *= factor
            if not any_bad:
                after = np.hstack([self.v, self.acc])
                dof = self.v.shape[1]
                self.repaired |= (after[:, :dof] != before[:, :dof]) | (after[:, dof:] != before[:, dof:])
                return segments
        raise RuntimeError("via-velocity repair did not converge")  # pragma: no cover - zero via speeds always fit


def _merge_segment(
    traj: _RuckigTrajectory, duration: float, start: tuple[np.ndarray, np.ndarray, np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """One Ruckig segment as constant-jerk pieces common to all joints.

    Every joint has its own seven phases (plus, for a start state beyond the limits, two brake
    phases); the pieces start at the union of their switching times.

    Returns:
        Local knot times, shape (K,) [s], and the stacked (p, v, a, j) at each knot, shape
        (4, K, dof).
    """
    profiles = traj.profiles[0]
    dof = len(profiles)
    if duration <= 0.0:
        return np.empty(0), np.empty((4, 0, dof))
    t = np.array([prof.t for prof in profiles])  # (dof, 7)
    jerk = np.array([prof.j for prof in profiles])
    acc = np.array([prof.a for prof in profiles])  # (dof, 8): phase starts and the end state
    vel = np.array([prof.v for prof in profiles])
    pos = np.array([prof.p for prof in profiles])
    # An 8th phase holds the end state (zero jerk) in case a joint's profile ends early.
    jerk = np.hstack([jerk, np.zeros((dof, 1))])
    starts = np.hstack([np.zeros((dof, 1)), np.cumsum(t, axis=1)])  # (dof, 8)
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
    if any(prof.accel.duration > 0 for prof in profiles):  # pragma: no cover - via states are admissible
        raise RuntimeError("Ruckig needed a post-profile: a via state exceeds the limits")
    knots = np.unique(starts[starts < duration])
    if knots[0] != 0.0:  # pragma: no cover - every profile starts at 0
        knots = np.insert(knots, 0, 0.0)
    # The phase of each joint in force at each knot (the last one starting at or before it).
    idx = np.sum(starts[:, None, :] <= knots[None, :, None], axis=2).T - 1  # (K, dof)
    cols = np.arange(dof)
    dt = knots[:, None] - starts.T[idx, cols]
    p0, v0, a0, j0 = pos.T[idx, cols], vel.T[idx, cols], acc.T[idx, cols], jerk.T[idx, cols]
    out = np.stack(
        [
            p0 + dt * (v0 + dt * (a0 / 2.0 + dt * j0 / 6.0)),
            v0 + dt * (a0 + dt * j0 / 2.0),
            a0 + dt * j0,
            j0,
        ]
    )
    # The segment starts exactly at its waypoint state.
    out[0, 0], out[1, 0], out[2, 0] = start
    return knots, out


class _StartOvershoot(Exception):
    """The given start state runs a joint out of its range in the first segment."""


def _brake_segment(
    q0: np.ndarray, v0: np.ndarray, a0: np.ndarray, limits: JointLimits
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Bring every joint to rest as fast as it can, each on its own (unsynchronised).

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
    traj = _RuckigTrajectory(dof)
    result = Ruckig(dof).calculate(inp, traj)
    if result not in (Result.Working, Result.Finished):  # pragma: no cover - braking always has a profile
        raise InvalidArgumentError(f"cannot brake from the start state (Ruckig: {result})")
    duration = float(traj.duration)
    rest = np.array([prof.p[-1] for prof in traj.profiles[0]])
    local, pieces = _merge_segment(traj, duration, (q0, v0, a0))
    lo, hi = _piece_position_range(local, pieces, duration) if len(local) else (q0, q0)
    lower = limits.lower - _OVERSHOOT_TOL * np.maximum(1.0, np.abs(np.nan_to_num(limits.lower)))
    upper = limits.upper + _OVERSHOOT_TOL * np.maximum(1.0, np.abs(np.nan_to_num(limits.upper)))
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


def plan_trajectory(
    waypoints: Sequence[Sequence[float]] | np.ndarray,
    limits: JointLimits,
    *,
    start_velocity: Sequence[float] | np.ndarray | None = None,
    start_acceleration: Sequence[float] | np.ndarray | None = None,
    stops: Sequence[int] | None = None,
    dwell: float | Sequence[float] | None = None,
    strategy: ViaStrategy = "optimized",
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
        strategy: ``"optimized"`` (default: heuristic via velocities, then a duration search
            per via waypoint), ``"heuristic"`` (the slope blend only) or ``"stop"`` (rest at
            every waypoint, the baseline).
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
    if strategy not in ("optimized", "heuristic", "stop"):
        raise InvalidArgumentError(f"unknown strategy {strategy!r}; valid: optimized, heuristic, stop")
    if not isinstance(limits, JointLimits):
        raise InvalidArgumentError(f"limits must be a JointLimits, got {type(limits).__name__}")
    q = check_waypoints(waypoints, limits)
    n = len(q)
    names = limits.joint_names
    v0 = _check_state(start_velocity, limits.velocity, names, "start velocity")
    a0 = _check_state(start_acceleration, limits.acceleration, names, "start acceleration")
    dw = _check_dwell(dwell, n)
    stop = _check_stops(stops, n)
    stop |= dw > 0
    if stop[0] and (np.any(v0) or np.any(a0)):
        raise InvalidArgumentError("waypoint 0 is a stop, but a non-zero start state was given")
    if strategy == "stop":
        stop[:] = True
        stop[0] = not (np.any(v0) or np.any(a0))
    given = _check_given(via_velocities, via_accelerations, min_durations, n, limits)

    try:
        planner = _Planner(q, limits, v0, a0, stop, given)
        planner.optimize(strategy)
        segments = planner.repair()
        v, acc, repaired = planner.v, planner.acc, planner.repaired
        head = None
    except _StartOvershoot:
        # A joint that is not the slowest of the first segment gets a stretched profile that
        # can run past its range; brake every joint as hard as it can first, then go on.
        *head, q_rest = _brake_segment(q[0], v0, a0, limits)
        inner = np.vstack([q_rest, q[1:]])
        planner = _Planner(inner, limits, np.zeros_like(v0), np.zeros_like(a0), stop, given)
        planner.optimize(strategy)
        segments = planner.repair()
        v, acc, repaired = planner.v.copy(), planner.acc.copy(), planner.repaired.copy()
        v[0], acc[0] = v0, a0

    knots, blocks, times = [], [], np.empty(n)
    t = 0.0
    if head is not None:
        knots.append(head[1])
        blocks.append(head[2])
        t = head[0]
    for k in range(n):
        times[k] = 0.0 if k == 0 else t
        if dw[k] > 0:
            knots.append(np.array([t]))
            blocks.append(
                np.stack([q[k][None], np.zeros((1, q.shape[1])), np.zeros((1, q.shape[1])), np.zeros((1, q.shape[1]))])
            )
            t += dw[k]
        if k == n - 1:
            break
        dur, local, states = segments[k]
        if len(local):
            knots.append(t + local)
            blocks.append(states)
        t += dur
    if knots:
        all_knots = np.concatenate(knots)
        pvaj = np.concatenate(blocks, axis=1)
    else:  # every waypoint identical, no dwell: a motionless trajectory
        all_knots = np.array([0.0])
        pvaj = np.stack([q[:1], np.zeros((1, q.shape[1])), np.zeros((1, q.shape[1])), np.zeros((1, q.shape[1]))])
    return JointTrajectory(
        knots=_frozen(all_knots),
        p=_frozen(pvaj[0]),
        v=_frozen(pvaj[1]),
        a=_frozen(pvaj[2]),
        j=_frozen(pvaj[3]),
        duration=float(t),
        waypoints=_frozen(q),
        waypoint_times=_frozen(times),
        via_velocities=_frozen(v),
        via_accelerations=_frozen(acc),
        dwell=_frozen(dw),
        limits=limits,
        strategy=strategy,
        repaired=_frozen_bool(repaired),
    )
