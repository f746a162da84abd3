"""Units at the edges: the length and angle units input files may declare, servo speed ratings.

Everything inside the package is SI (m, rad, s); these are the only conversions.
"""

from __future__ import annotations

import math

from planner.core.text import plain
from planner.exceptions import InvalidLimitsError

__all__ = ["ANGLE_UNITS", "LENGTH_UNITS", "servo_speed_to_velocity"]

#: Length units an input file may declare, in metres.
LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
#: Angle units an input file may declare, in radians.
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}


def servo_speed_to_velocity(seconds: float, degrees: float = 60.0) -> float:
    """Convert a hobby-servo speed rating ("0.20 s per 60 deg") to a joint speed.

    Args:
        seconds: Time the servo takes for `degrees` of travel [s].
        degrees: Travel the rating refers to [deg].

    Returns:
        The angular speed [rad/s].

    Raises:
        InvalidLimitsError: If either number is not finite and positive.
    """
    if not (math.isfinite(seconds) and seconds > 0.0):
        raise InvalidLimitsError(f"servo speed time must be positive and finite, got {plain(seconds)} s", value=seconds)
    if not (math.isfinite(degrees) and degrees > 0.0):
        raise InvalidLimitsError(
            f"servo speed travel must be positive and finite, got {plain(degrees)} deg", value=degrees
        )
    return math.radians(degrees) / seconds
