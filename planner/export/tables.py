"""Controller units sampled along a trajectory: pulse widths per servo, or Materick and Shapiro's (1997) steps."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from planner.export.calibration import ServoCalibration, angle_to_steps, check_calibrations, pulse_widths

if TYPE_CHECKING:
    from planner.motion.trajectory import JointTrajectory

__all__ = ["pulse_table", "steps_table"]


def pulse_table(
    trajectory: JointTrajectory, calibrations: Sequence[ServoCalibration], rate: float = 50.0
) -> tuple[np.ndarray, np.ndarray]:
    """Pulse widths of every servo along a trajectory.

    Args:
        trajectory: The joint trajectory.
        calibrations: One per joint, in joint order.
        rate: Sampling rate [Hz] (hobby servos take a new pulse every 20 ms: 50 Hz).

    Returns:
        ``(t, pulses)``: times shape (n,) [s] (the final instant included) and pulse widths
        rounded to whole microseconds, shape (n, dof) int.

    Raises:
        InvalidArgumentError: If a calibration is missing or an angle needs a pulse out of range.
    """
    check_calibrations(calibrations, trajectory.dof)
    t = trajectory.times(rate)
    return t, pulse_widths(calibrations, trajectory.sample(t).q)


def steps_table(
    trajectory: JointTrajectory, max_rotation: float, max_steps: int, rate: float = 50.0
) -> tuple[np.ndarray, np.ndarray]:
    """Materick and Shapiro's (1997) controller steps (see :func:`angle_to_steps`) along a trajectory.

    Returns:
        ``(t, steps)``: times shape (n,) [s] and steps shape (n, dof) int.
    """
    t = trajectory.times(rate)
    return t, np.asarray(angle_to_steps(trajectory.sample(t).q, max_rotation, max_steps))
