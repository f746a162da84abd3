"""Position-tick calibration: joint angles [rad] to the integer positions of bus servos and steppers.

Feetech STS/SCS bus servos take a goal position in encoder ticks (an STS3215 counts 4096 per
turn), and a stepper controller counts steps (Materick and Shapiro's (1997) symmetric map is
``steps = angle / max_rotation * max_steps``). Both are ``ticks = zero + direction * scale *
angle`` between two limits, rounded to whole ticks; nothing outside the limits is clipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.core.text import plain
from planner.exceptions import InvalidArgumentError
from planner.export.calibration import linear_units

__all__ = ["STS_TICKS_PER_TURN", "TickCalibration", "tick_positions"]

#: Encoder ticks per turn of a Feetech STS servo (12-bit magnetic encoder).
STS_TICKS_PER_TURN = 4096


def _number(value: object, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InvalidArgumentError(f"{what} must be a number, got {plain(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise InvalidArgumentError(f"{what} must be finite, got {plain(value)}")
    return x


@dataclass(frozen=True)
class TickCalibration:
    """How one joint's angle maps to a servo's or stepper's position ticks.

    ``ticks = ticks_at_zero + direction * ticks_per_rad * angle``, valid between `min_ticks` and
    `max_ticks`; nothing outside is clipped.

    Attributes:
        id: Servo id on the bus (Feetech: 0-253) or stepper channel.
        ticks_at_zero: Position at joint angle 0 [ticks] (2048, the middle of an STS turn).
        ticks_per_rad: Position change per radian [ticks/rad] (4096 / 2 pi for an STS servo).
        direction: +1, or -1 when the servo turns opposite to the joint.
        min_ticks: Smallest allowed position [ticks].
        max_ticks: Largest allowed position [ticks].
        joint: Joint name, for messages.
    """

    id: int
    ticks_at_zero: float = STS_TICKS_PER_TURN / 2
    ticks_per_rad: float = STS_TICKS_PER_TURN / (2 * math.pi)
    direction: int = 1
    min_ticks: float = 0.0
    max_ticks: float = STS_TICKS_PER_TURN - 1.0
    joint: str = ""

    def __post_init__(self) -> None:
        name = f"servo for joint {self.joint!r}" if self.joint else f"servo id {self.id!r}"
        if isinstance(self.id, bool) or not isinstance(self.id, (int, np.integer)) or self.id < 0:
            raise InvalidArgumentError(f"{name}: id must be a non-negative integer, got {self.id!r}")
        object.__setattr__(self, "id", int(self.id))
        if self.direction not in (1, -1) or isinstance(self.direction, bool):
            raise InvalidArgumentError(f"{name}: direction must be +1 or -1, got {self.direction!r}")
        for attr in ("ticks_at_zero", "ticks_per_rad", "min_ticks", "max_ticks"):
            object.__setattr__(self, attr, _number(getattr(self, attr), f"{name}: {attr}"))
        if self.ticks_per_rad <= 0:
            raise InvalidArgumentError(f"{name}: ticks_per_rad must be positive, got {self.ticks_per_rad:g}")
        if not self.min_ticks < self.max_ticks:
            raise InvalidArgumentError(
                f"{name}: need min_ticks < max_ticks, got {self.min_ticks:g} and {self.max_ticks:g}"
            )

    @property
    def channel(self) -> int:
        """The servo id (the name every calibration shares for its address on the controller)."""
        return self.id

    def ticks(self, angle: float | np.ndarray) -> float | np.ndarray:
        """Position [ticks, not rounded] for joint angle(s) [rad].

        Raises:
            InvalidArgumentError: If an angle is NaN or needs a position outside [min, max].
        """
        return linear_units(
            angle,
            self.ticks_at_zero,
            self.direction * self.ticks_per_rad,
            (self.min_ticks, self.max_ticks),
            f"joint {self.joint!r} (id {self.id})",
            ("position", "ticks"),
        )

    def angle(self, ticks: float | np.ndarray) -> float | np.ndarray:
        """Joint angle [rad] for position(s) [ticks]; the inverse of :meth:`ticks`."""
        a = (np.asarray(ticks, dtype=float) - self.ticks_at_zero) / (self.direction * self.ticks_per_rad)
        return float(a) if a.ndim == 0 else a

    def value(self, angle: float | np.ndarray) -> float | np.ndarray:
        """Same as :meth:`ticks` (the controller value every calibration kind answers)."""
        return self.ticks(angle)


def tick_positions(calibrations: tuple[TickCalibration, ...] | list[TickCalibration], q: np.ndarray) -> np.ndarray:
    """Positions of every servo, rounded to whole ticks.

    Args:
        calibrations: One per joint, in joint order.
        q: Joint angles, shape (n, dof) [rad].

    Returns:
        Positions, shape (n, dof) int [ticks].

    Raises:
        InvalidArgumentError: If an angle needs a position out of its calibration's range.
    """
    return np.column_stack([np.rint(c.ticks(q[:, k])) for k, c in enumerate(calibrations)]).astype(int)
