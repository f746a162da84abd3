"""Per-joint motion limits: speed, acceleration, jerk and position range.

:class:`JointLimits` holds one value per joint, validated and read-only; its
:meth:`JointLimits.from_robot` derives defaults from a robot's URDF speeds (or a hobby-servo speed
rating). :func:`admissible_acceleration` is the per-joint rule every via state obeys.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from planner.core.arrays import read_only
from planner.core.text import plain
from planner.core.units import servo_speed_to_velocity
from planner.exceptions import InvalidLimitsError, PlanningError
from planner.motion.segment_kernels import admissible_states

if TYPE_CHECKING:
    from planner.model.robot import Robot

__all__ = [
    "MAX_SEGMENT_DURATION",
    "RANGE_TOLERANCE",
    "JointLimits",
    "admissible_acceleration",
    "per_joint_limit",
    "reach_time",
]

#: Relative slack of the position-range checks [rad or m per unit of max(1, |bound|)]: a joint
#: counts as leaving its range only beyond it, so that rounding at a range end is no overshoot.
RANGE_TOLERANCE = 1e-10


def reach_time(distance: float, velocity: float, acceleration: float) -> float:
    """The least time a joint needs to cover `distance` from rest or to rest within the limits [s].

    Within ``|v| <= velocity`` and ``|a| <= acceleration``, a motion that ends (or starts) at rest
    covers at most ``a t^2 / 2`` in time t up to ``t = v / a``, then ``v t - v^2 / (2 a)``; this
    is the inverse of that bound.

    Args:
        distance: The distance [rad or m]; negative gives -inf.
        velocity: The velocity limit [rad/s or m/s].
        acceleration: The acceleration limit [rad/s^2 or m/s^2].
    """
    if distance < 0.0:
        return -math.inf
    knee = velocity * velocity / (2.0 * acceleration)
    if distance <= knee:
        return math.sqrt(2.0 * distance / acceleration)
    return (distance + knee) / velocity


def per_joint_limit(
    value: float | Sequence[float] | np.ndarray, names: Sequence[str], what: str, unit: str
) -> np.ndarray:
    """A positive, finite limit per joint from a scalar or a sequence.

    Args:
        value: One number for every joint, or one per joint.
        names: Joint names, shape (dof,); they name the joint in a message.
        what: What the limit is (``"velocity"``), for messages.
        unit: Its unit, for messages.

    Returns:
        A read-only array of shape (dof,).

    Raises:
        InvalidLimitsError: If a value is not a positive finite number or the count is wrong.
    """
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
    return read_only(arr)


#: Ruckig's longest trajectory [s]: beyond it, it returns no profile (result -101).
MAX_SEGMENT_DURATION = 7e3


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
        if not names:  # Ruckig divides by the joint count (SIGFPE)
            raise InvalidLimitsError("limits need at least one joint, got none (a tip no joint moves?)")
        object.__setattr__(self, "joint_names", names)
        for attr, what, unit in (
            ("velocity", "velocity", "rad/s or m/s"),
            ("acceleration", "acceleration", "rad/s^2 or m/s^2"),
            ("jerk", "jerk", "rad/s^3 or m/s^3"),
        ):
            object.__setattr__(self, attr, per_joint_limit(getattr(self, attr), names, what, unit))
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
        object.__setattr__(self, "lower", read_only(lower))
        object.__setattr__(self, "upper", read_only(upper))

    @property
    def dof(self) -> int:
        """Number of joints."""
        return len(self.joint_names)

    @cached_property
    def twice_jerk(self) -> np.ndarray:
        """2 * jerk, shape (dof,) [rad/s^3 or m/s^3] (read-only; for the via-state rule)."""
        return read_only(2.0 * self.jerk)

    @cached_property
    def kernel_limits(self) -> bytes:
        """Velocity, acceleration and twice the jerk limits as float64 bytes, one after the other (for C kernels)."""
        return self.velocity.tobytes() + self.acceleration.tobytes() + self.twice_jerk.tobytes()

    @cached_property
    def checked_range(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of the range checks, widened by :data:`RANGE_TOLERANCE`, shapes (dof,)."""
        lower = self.lower - RANGE_TOLERANCE * np.maximum(1.0, np.abs(np.nan_to_num(self.lower)))
        upper = self.upper + RANGE_TOLERANCE * np.maximum(1.0, np.abs(np.nan_to_num(self.upper)))
        return read_only(lower), read_only(upper)

    @cached_property
    def finite_range(self) -> tuple[np.ndarray, np.ndarray]:
        """The position range with infinite ends replaced by the largest finite floats, shapes (dof,).

        A value lies within it exactly when it is finite and within the range.
        """
        big = np.finfo(float).max
        return read_only(np.where(np.isfinite(self.lower), self.lower, -big)), read_only(
            np.where(np.isfinite(self.upper), self.upper, big)
        )

    @cached_property
    def finite_bounds(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """:attr:`finite_range` as tuples of floats (lower, upper)."""
        lower, upper = self.finite_range
        return tuple(lower.tolist()), tuple(upper.tolist())

    @cached_property
    def ruckig_limits(self) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
        """Velocity, acceleration and jerk limits as tuples of floats, for Ruckig's ``InputParameter``."""
        return tuple(self.velocity.tolist()), tuple(self.acceleration.tolist()), tuple(self.jerk.tolist())

    @cached_property
    def bounded(self) -> bool:
        """Whether any joint has a finite range end."""
        return bool(np.any(np.isfinite(self.lower)) or np.any(np.isfinite(self.upper)))

    @cached_property
    def checked_floats(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """:attr:`checked_range` as tuples of floats (lower, upper)."""
        lower, upper = self.checked_range
        return tuple(lower.tolist()), tuple(upper.tolist())

    @cached_property
    def max_jerk(self) -> float:
        """The largest jerk limit [rad/s^3 or m/s^3]."""
        return float(np.max(self.jerk))

    @cached_property
    def _quick_move(self) -> tuple[float, ...]:
        """Per joint, a move [rad or m] that surely lasts less than :data:`MAX_SEGMENT_DURATION`, or -1.

        Half the distance the joint covers in that time at its velocity limit, where reaching the
        limit from rest takes at most a quarter of it (then such a move lasts at most 5/8 of it,
        from or to rest too); -1 (no move) otherwise.
        """
        v, a = self.velocity.tolist(), self.acceleration.tolist()
        return tuple(
            0.5 * MAX_SEGMENT_DURATION * x if x <= 0.25 * MAX_SEGMENT_DURATION * y else -1.0 for x, y in zip(v, a)
        )

    def check_move_durations(
        self,
        waypoints: np.ndarray,
        labels: Sequence[str] | None = None,
        *,
        from_rest: bool = True,
        to_rest: bool = True,
    ) -> None:
        """Refuse a move between consecutive `waypoints` longer than :data:`MAX_SEGMENT_DURATION`.

        A joint moving ``d`` at velocity limit ``v`` needs at least ``d / v``; the first move
        (when it starts at rest) and the last (when it is one segment ending at rest) at least
        :func:`reach_time` within the velocity and acceleration limits.
        Ruckig plans no segment longer than its 7e3 s (its result -101), and sweeps along such a
        move (a continuous joint told to turn a million radians) would sample it without bound.

        Args:
            waypoints: Shape (N, dof), SI units.
            labels: Names of the waypoints for the message (default ``waypoint k``).
            from_rest: Whether the first move starts at rest (and is one segment).
            to_rest: Whether the last move is one segment ending at rest (a plan's last move
                along a line is timed in many segments).

        Raises:
            PlanningError: Naming the two waypoints, the joint, its move, the time it needs and
                the limits that make it so.
        """
        q = np.asarray(waypoints, dtype=float)
        if len(q) < 2:
            return
        # At once (plain floats) where no joint's waypoints span more than such a move.
        quick = self._quick_move
        if (
            q.ndim == 2
            and q.shape[1] == len(quick)
            and all(max(col) - min(col) <= most for col, most in zip(zip(*q.tolist()), quick))
        ):
            return
        with np.errstate(invalid="ignore", over="ignore"):
            d = np.abs(np.diff(q, axis=0))
            need = d / self.velocity
        ends = ([len(d) - 1] if to_rest else []) + ([0] if from_rest else [])
        v, a = self.velocity.tolist(), self.acceleration.tolist()
        for k in ends:
            need[k] = np.fmax(need[k], [reach_time(x, y, z) for x, y, z in zip(d[k].tolist(), v, a)])
        worst = np.where(np.isfinite(need), need, np.inf)  # an overflow or NaN counts as too long
        too_long = np.nonzero(worst.max(axis=1) > MAX_SEGMENT_DURATION)[0]
        if too_long.size:
            k = int(too_long[0])
            j = int(np.argmax(worst[k]))
            a, b = (labels[k], labels[k + 1]) if labels is not None else (f"waypoint {k}", f"waypoint {k + 1}")
            by = f"at its velocity limit {plain(float(self.velocity[j]))}"
            with np.errstate(over="ignore"):  # a move of 1e308 rad: inf
                by_velocity = d[k, j] / self.velocity[j]
            if k in ends and not need[k, j] <= by_velocity:
                by = (
                    f"{'from' if k == 0 and from_rest else 'to'} rest within its velocity limit "
                    f"{plain(float(self.velocity[j]))} and acceleration limit {plain(float(self.acceleration[j]))}"
                )
            raise PlanningError(
                f"{a} -> {b}: joint {self.joint_names[j]} moves {plain(float(d[k, j]))}, at least "
                f"{float(need[k, j]):.6g} s {by}; a segment can last at most {MAX_SEGMENT_DURATION:g} s "
                "(Ruckig's limit): add waypoints between them or raise the limits"
            )

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
            secs = per_joint_limit(servo_seconds_per_60deg, names, "servo_seconds_per_60deg", "s")
            vel = np.array([servo_speed_to_velocity(float(s)) for s in secs])
        elif velocity is not None:
            vel = per_joint_limit(velocity, names, "velocity", "rad/s or m/s")
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
                raise InvalidLimitsError(f"{what} must be positive and finite [1/s], got {plain(factor)}", value=factor)
        acc = (
            per_joint_limit(acceleration, names, "acceleration", "rad/s^2 or m/s^2")
            if acceleration is not None
            else vel * acceleration_per_velocity
        )
        jrk = (
            per_joint_limit(jerk, names, "jerk", "rad/s^3 or m/s^3")
            if jerk is not None
            else acc * jerk_per_acceleration
        )
        return cls(vel, acc, jrk, robot.lower, robot.upper, names)


def admissible_acceleration(v: np.ndarray, a: np.ndarray, limits: JointLimits) -> np.ndarray:
    """Limit a via acceleration so the state can be reached and left within the limits.

    A state with ``|v| + a^2 / (2 j_max) > v_max`` would have needed (or would need) a speed
    beyond v_max on one side of the waypoint.

    Args:
        v: Velocities, shape (..., dof) [rad/s or m/s], within the speed limits.
        a: Accelerations, same shape [rad/s^2 or m/s^2].
        limits: The limits.

    Returns:
        The accelerations, each clipped to what its velocity allows (a new array).
    """
    fast = admissible_states(v, a, limits.kernel_limits)  # compiled, the same operations (None: below)
    if fast is not None:
        return fast
    # The same operations as room = max(v_max - |v|, 0), amax = min(a_max, sqrt(2 j_max room) (1 - 1e-9)),
    # max(min(a, amax), -amax), in place on two arrays.
    amax = np.abs(v)
    np.subtract(limits.velocity, amax, out=amax)
    np.maximum(amax, 0.0, out=amax)
    np.multiply(limits.twice_jerk, amax, out=amax)
    np.sqrt(amax, out=amax)
    amax *= 1.0 - 1e-9
    np.minimum(limits.acceleration, amax, out=amax)
    out = np.minimum(a, amax)
    return np.maximum(out, np.negative(amax, out=amax), out=out)
