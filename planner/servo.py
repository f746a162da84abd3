"""Conversions between joint angles [rad] and servo controller units, at the edge of the library."""

from __future__ import annotations

import math

import numpy as np

from .exceptions import InvalidArgumentError

__all__ = ["angle_to_steps", "steps_to_angle"]


def _check_span(max_rotation: float, max_steps: int) -> None:
    if not (math.isfinite(max_rotation) and max_rotation > 0):
        raise InvalidArgumentError(f"max_rotation must be positive and finite [rad], got {max_rotation!r}")
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or max_steps <= 0:
        raise InvalidArgumentError(f"max_steps must be a positive integer, got {max_steps!r}")


def angle_to_steps(angle: float | np.ndarray, max_rotation: float, max_steps: int) -> np.ndarray | int:
    """Joint angle to controller steps by the symmetric linear map of the 000 seed.

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
    a = np.asarray(angle, dtype=float)
    if not np.all(np.isfinite(a)):
        raise InvalidArgumentError(f"angle must be finite, got {angle!r}")
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
    s = np.asarray(steps, dtype=float)
    a = s / max_steps * max_rotation
    return float(a) if a.ndim == 0 else a
