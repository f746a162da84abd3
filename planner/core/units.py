"""Units at the edges: the length and angle units input files may declare, servo speed ratings.

Everything inside the package is SI (m, rad, s); these are the only conversions.
"""

from __future__ import annotations

import math

import numpy as np

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
    for value, what, unit in ((seconds, "time", "s"), (degrees, "travel", "deg")):
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise InvalidLimitsError(f"servo speed {what} must be a number [{unit}], got {plain(value)}", value=value)
        if not (math.isfinite(value) and value > 0.0):
            raise InvalidLimitsError(
                f"servo speed {what} must be positive and finite, got {plain(value)} {unit}", value=value
            )
    velocity = math.radians(degrees) / seconds
    if not math.isfinite(velocity):
        raise InvalidLimitsError(
            f"servo speed {plain(seconds)} s per {plain(degrees)} deg is an infinite joint speed", value=seconds
        )
    return velocity
