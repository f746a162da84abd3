"""Pulse widths as CSV: one row per servo period, one column per servo channel."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, ClassVar

from planner.export.formats.base import ServoFormat
from planner.export.tables import pulse_table

if TYPE_CHECKING:
    from planner.export.calibration import ServoCalibration
    from planner.motion.trajectory import JointTrajectory

__all__ = ["PulseCsv"]


class PulseCsv(ServoFormat):
    """``t,ch<channel>_<joint>,...`` then ``<t [s]>,<pulse [us]>,...`` every servo period.

    The rows are :func:`planner.export.tables.pulse_table` at ``1000 / period_ms`` Hz (the
    final instant included); times to the microsecond, pulses in whole microseconds.
    """

    name: ClassVar[str] = "pulses"
    file_name: ClassVar[str] = "servo_pulses.csv"
    written_by_default: ClassVar[bool] = True

    def render(self, trajectory: JointTrajectory, calibrations: Sequence[ServoCalibration], period_ms: int) -> str:
        """The CSV text (see the class docstring)."""
        t, pulses = pulse_table(trajectory, calibrations, rate=1000.0 / period_ms)
        lines = [",".join(["t"] + [f"ch{c.channel}_{c.joint}" for c in calibrations])]
        lines += [f"{ti:.6f}," + ",".join(str(int(x)) for x in row) for ti, row in zip(t, pulses)]
        return "".join(line + "\n" for line in lines)
