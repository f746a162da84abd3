"""Servo calibration: joint angles [rad] to controller units and back, one joint at a time.

Two kinds of controller: Materick and Shapiro's (1997) step counts (:func:`angle_to_steps`), and hobby
servos driven by pulse widths, each with a :class:`ServoCalibration` (Clothier and Shang's (2010) SSC-32
convention of 1000 us per 90 deg by default). Files for a controller are written by the
formats in :mod:`planner.export.formats`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from planner.core.arrays import float_array
from planner.core.files import positive_number
from planner.core.text import plain
from planner.exceptions import InvalidArgumentError

if TYPE_CHECKING:
    from planner.model.robot import Robot

__all__ = [
    "SSC32_US_PER_RAD",
    "ServoCalibration",
    "angle_to_steps",
    "check_calibrations",
    "default_calibrations",
    "linear_units",
    "pulse_widths",
    "steps_to_angle",
]

#: The SSC-32 convention of Clothier and Shang (2010): about 1000 us of pulse per 90 deg of travel.
SSC32_US_PER_RAD = 1000.0 / (math.pi / 2.0)


#: Largest step count: counts above 2**53 are not exact as floats (and overflowed int64 silently).
MAX_STEPS = 2**53


def _check_span(max_rotation: float, max_steps: int) -> None:
    if isinstance(max_rotation, bool) or not isinstance(max_rotation, (int, float, np.integer, np.floating)):
        raise InvalidArgumentError(f"max_rotation must be a number [rad], got {plain(max_rotation)}")
    if not (math.isfinite(max_rotation) and max_rotation > 0):
        raise InvalidArgumentError(f"max_rotation must be positive and finite [rad], got {plain(max_rotation)}")
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or not 0 < max_steps <= MAX_STEPS:
        raise InvalidArgumentError(f"max_steps must be an integer in [1, 2**53], got {plain(max_steps)}")


def angle_to_steps(angle: float | np.ndarray, max_rotation: float, max_steps: int) -> np.ndarray | int:
    """Joint angle to controller steps by the symmetric linear map of Materick and Shapiro (1997).

    The servo turns +-`max_rotation` about a centred zero, and the controller counts
    +-`max_steps` over the same travel, so ``steps = round(angle / max_rotation * max_steps)``.

    Args:
        angle: Joint angle(s) [rad].
        max_rotation: The servo's travel on either side of zero [rad] (e.g. 92.5 deg).
        max_steps: Controller steps for that travel (the seed gives none: a parameter).

    Returns:
        Steps as an int, or an int array for array input.

    Raises:
        InvalidArgumentError: If an angle is NaN or beyond +-`max_rotation` (nothing is clipped),
            or the span is not positive.
    """
    _check_span(max_rotation, max_steps)
    a = float_array(angle, "angle")
    if not np.all(np.isfinite(a)):
        raise InvalidArgumentError(f"angle must be finite, got {plain(angle)}")
    beyond = np.abs(a) > max_rotation * (1 + 1e-12)
    if np.any(beyond):
        bad = float(a[beyond].flat[0]) if a.ndim else float(a)
        raise InvalidArgumentError(
            f"angle {bad:.6g} rad is beyond the servo's travel +-{max_rotation:.6g} rad; it is not clipped"
        )
    steps = np.rint(a / max_rotation * max_steps).astype(int)
    return int(steps) if steps.ndim == 0 else steps


def steps_to_angle(steps: int | np.ndarray, max_rotation: float, max_steps: int) -> np.ndarray | float:
    """Controller steps back to the joint angle [rad]; the inverse of :func:`angle_to_steps`."""
    _check_span(max_rotation, max_steps)
    s = float_array(steps, "steps")
    a = s / max_steps * max_rotation
    return float(a) if a.ndim == 0 else a


def linear_units(
    angle: float | np.ndarray,
    at_zero: float,
    per_rad: float,
    valid: tuple[float, float],
    who: str,
    unit: tuple[str, str],
) -> float | np.ndarray:
    """A controller value ``at_zero + per_rad * angle`` for joint angle(s) [rad], checked, not clipped.

    Args:
        angle: Joint angle(s) [rad].
        at_zero: The value at angle 0.
        per_rad: Change per radian, signed by the servo's direction.
        valid: The smallest and largest value the controller takes.
        who: The joint and its channel or id, for messages.
        unit: What the value is and its unit, e.g. ``("pulse", "us")``.

    Raises:
        InvalidArgumentError: If an angle is NaN or needs a value outside `valid` (naming both).
    """
    a = float_array(angle, f"angle for {who}")
    if not np.all(np.isfinite(a)):
        raise InvalidArgumentError(f"angle for {who} must be finite, got {plain(angle)}")
    p = at_zero + per_rad * a
    lo, hi = valid
    out = (p < lo - 1e-9) | (p > hi + 1e-9)
    if np.any(out):
        k = np.argmax(out.reshape(-1))
        bad_a, bad_p = float(a.reshape(-1)[k]), float(p.reshape(-1)[k])
        shown = f"{bad_p:.1f}" if abs(bad_p) < 1e9 else f"{bad_p:.6g}"  # not 300 digits of a wild calibration
        raise InvalidArgumentError(
            f"{who} angle {bad_a:.6g} rad needs {unit[0]} {shown} {unit[1]}, "
            f"outside [{lo:g}, {hi:g}] {unit[1]}; adjust its calibration"
        )
    return float(p) if p.ndim == 0 else p


@dataclass(frozen=True)
class ServoCalibration:
    """How one joint's angle maps to a hobby servo's pulse width.

    ``pulse = pulse_at_zero + direction * us_per_rad * angle``, valid between `min_pulse` and
    `max_pulse`; nothing outside is clipped.

    Attributes:
        channel: Controller channel (0-31 on an SSC-32).
        pulse_at_zero: Pulse width at joint angle 0 [us].
        us_per_rad: Pulse change per radian [us/rad] (1000 us per 90 deg is about 636.6).
        direction: +1, or -1 when the servo turns opposite to the joint.
        min_pulse: Smallest allowed pulse width [us].
        max_pulse: Largest allowed pulse width [us].
        joint: Joint name, for messages.
    """

    channel: int
    pulse_at_zero: float = 1500.0
    us_per_rad: float = SSC32_US_PER_RAD
    direction: int = 1
    min_pulse: float = 500.0
    max_pulse: float = 2500.0
    joint: str = ""

    def __post_init__(self) -> None:
        name = f"servo for joint {self.joint!r}" if self.joint else f"servo on channel {self.channel!r}"
        if isinstance(self.channel, bool) or not isinstance(self.channel, (int, np.integer)) or self.channel < 0:
            raise InvalidArgumentError(f"{name}: channel must be a non-negative integer, got {self.channel!r}")
        object.__setattr__(self, "channel", int(self.channel))
        object.__setattr__(self, "us_per_rad", positive_number(self.us_per_rad, f"{name}: us_per_rad"))
        if self.direction not in (1, -1) or isinstance(self.direction, bool):
            raise InvalidArgumentError(f"{name}: direction must be +1 or -1, got {self.direction!r}")
        for attr in ("pulse_at_zero", "min_pulse", "max_pulse"):
            v = getattr(self, attr)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
                raise InvalidArgumentError(f"{name}: {attr} must be a finite number [us], got {v!r}")
            object.__setattr__(self, attr, float(v))
        if not 0 < self.min_pulse < self.max_pulse:
            raise InvalidArgumentError(
                f"{name}: need 0 < min_pulse < max_pulse, got {self.min_pulse:g} and {self.max_pulse:g} us"
            )

    @classmethod
    def fit_range(
        cls,
        channel: int,
        lower: float,
        upper: float,
        *,
        joint: str = "",
        min_pulse: float = 500.0,
        max_pulse: float = 2500.0,
        direction: int = 1,
    ) -> ServoCalibration:
        """A centred calibration (joint zero at the middle pulse) that covers a joint range.

        It uses the SSC-32's 1000 us per 90 deg when the range [lower, upper] [rad] fits in
        [min_pulse, max_pulse], else the largest scale that makes it fit.
        """
        centre = (min_pulse + max_pulse) / 2.0
        reach = max(abs(lower), abs(upper)) if math.isfinite(lower) and math.isfinite(upper) else 0.0
        scale = SSC32_US_PER_RAD
        if reach > 0 and centre + SSC32_US_PER_RAD * reach > max_pulse:
            scale = (max_pulse - centre) / reach
        return cls(channel, centre, scale, direction, min_pulse, max_pulse, joint)

    def pulse(self, angle: float | np.ndarray) -> float | np.ndarray:
        """Pulse width [us] for joint angle(s) [rad].

        Raises:
            InvalidArgumentError: If an angle is NaN or needs a pulse outside [min, max].
        """
        return linear_units(
            angle,
            self.pulse_at_zero,
            self.direction * self.us_per_rad,
            (self.min_pulse, self.max_pulse),
            f"joint {self.joint!r} (channel {self.channel})",
            ("pulse", "us"),
        )

    def angle(self, pulse: float | np.ndarray) -> float | np.ndarray:
        """Joint angle [rad] for pulse width(s) [us]; the inverse of :meth:`pulse`."""
        a = (float_array(pulse, "pulse") - self.pulse_at_zero) / (self.direction * self.us_per_rad)
        return float(a) if a.ndim == 0 else a

    def value(self, angle: float | np.ndarray) -> float | np.ndarray:
        """Same as :meth:`pulse` (the controller value every calibration kind answers)."""
        return self.pulse(angle)


def default_calibrations(
    robot: Robot, first_channel: int = 0, *, travel: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[ServoCalibration, ...]:
    """One centred calibration per chain joint on consecutive channels (see :meth:`ServoCalibration.fit_range`).

    Each covers its joint's range; a joint without a finite range (a continuous joint) covers
    its `travel` instead, or +-90 deg at the SSC-32's scale when no travel is given.

    Args:
        robot: The robot.
        first_channel: Channel of the first joint.
        travel: The smallest and largest angle [rad] each joint takes in a plan, two arrays of
            shape (dof,); joints whose range is finite keep fitting their range.

    Returns:
        One calibration per joint.
    """
    lower, upper = np.array(robot.lower, dtype=float), np.array(robot.upper, dtype=float)
    if travel is not None:
        lo, hi = (np.asarray(x, dtype=float).reshape(-1) for x in travel)
        if lo.shape != (robot.dof,) or hi.shape != (robot.dof,):
            raise InvalidArgumentError(f"travel needs two arrays of {robot.dof} angles, got {lo.size} and {hi.size}")
        free = ~(np.isfinite(lower) & np.isfinite(upper))
        lower[free], upper[free] = np.minimum(lo[free], 0.0), np.maximum(hi[free], 0.0)
    return tuple(
        ServoCalibration.fit_range(first_channel + k, lo, hi, joint=name)
        for k, (name, lo, hi) in enumerate(zip(robot.joint_names, lower, upper))
    )


def check_calibrations(calibrations: Sequence[ServoCalibration], dof: int, kind: type = ServoCalibration) -> None:
    """Check that there is one calibration of the right kind per joint, on distinct channels.

    Args:
        calibrations: The calibrations, in joint order.
        dof: Number of joints.
        kind: The calibration class the controller needs (:class:`ServoCalibration` for pulse
            widths, :class:`planner.export.ticks.TickCalibration` for position ticks).

    Raises:
        InvalidArgumentError: If one is missing or of another kind, or two share a channel.
    """
    if len(calibrations) != dof:
        raise InvalidArgumentError(f"need one {kind.__name__} per joint ({dof}), got {len(calibrations)}")
    wrong = [c for c in calibrations if not isinstance(c, kind)]
    if wrong:
        raise InvalidArgumentError(
            f"this controller needs one {kind.__name__} per joint, got a {type(wrong[0]).__name__}"
            f"{f' for joint {wrong[0].joint!r}' if getattr(wrong[0], 'joint', '') else ''}"
        )
    channels = [c.channel for c in calibrations]
    if len(set(channels)) != len(channels):
        raise InvalidArgumentError(f"servo channels must differ, got {channels}")


def pulse_widths(calibrations: Sequence[ServoCalibration], q: np.ndarray) -> np.ndarray:
    """Pulse widths of every servo, rounded to whole microseconds.

    Args:
        calibrations: One per joint, in joint order (see :func:`check_calibrations`).
        q: Joint angles, shape (n, dof) [rad].

    Returns:
        Pulse widths, shape (n, dof) int [us].

    Raises:
        InvalidArgumentError: If an angle needs a pulse out of its calibration's range.
    """
    return np.column_stack([np.rint(c.pulse(q[:, k])) for k, c in enumerate(calibrations)]).astype(int)
