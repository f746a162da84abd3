"""Stepper steps as CSV, by Materick and Shapiro's (1997) symmetric map: one row per servo period."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from planner.exceptions import InvalidArgumentError
from planner.export.calibration import check_calibrations
from planner.export.formats.base import ServoFormat, command_times
from planner.export.ticks import TickCalibration, tick_positions

if TYPE_CHECKING:
    from planner.model.robot import Robot
    from planner.motion.trajectory import JointTrajectory

__all__ = ["Steps"]


class Steps(ServoFormat):
    """``t,ch<channel>_<joint>,...`` then ``<t [s]>,<steps>,...`` every servo period.

    Each joint's steps are ``zero + direction * scale * angle`` of its
    :class:`~planner.export.ticks.TickCalibration`; Materick and Shapiro's (1997) controller
    counts ``+-max_steps`` over ``+-max_rotation``, so ``zero: 0``, ``scale: max_steps /
    max_rotation`` and ``limits: [-max_steps, max_steps]``
    (:func:`planner.export.calibration.angle_to_steps` gives the same numbers).
    """

    name: ClassVar[str] = "steps"
    file_name: ClassVar[str] = "steps.csv"
    calibration_type: ClassVar[type] = TickCalibration

    def default_calibrations(
        self, robot: Robot, *, travel: tuple[np.ndarray, np.ndarray] | None = None
    ) -> tuple[TickCalibration, ...]:
        """None: a stepper's steps per radian are the user's to give.

        Raises:
            InvalidArgumentError: Always, saying to give a calibration file.
        """
        raise InvalidArgumentError(
            "controller 'steps' has no default calibration: give a calibration file (controller: steps, "
            "one servo per joint with channel, zero, direction, scale [steps/rad], limits [steps])"
        )

    def render(self, trajectory: JointTrajectory, calibrations: Sequence[Any], period_ms: int) -> str:
        """The CSV text (see the class docstring); times to the microsecond."""
        t = command_times(trajectory, period_ms)
        check_calibrations(calibrations, trajectory.dof, TickCalibration)
        steps = tick_positions(calibrations, trajectory.sample(t).q)
        lines = [",".join(["t"] + [f"ch{c.channel}_{c.joint}" for c in calibrations])]
        lines += [f"{ti:.6f}," + ",".join(str(int(x)) for x in row) for ti, row in zip(t, steps)]
        return "".join(line + "\n" for line in lines)
