"""Lynxmotion SSC-32 group-move commands (Clothier and Shang's (2010) controller)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, ClassVar

from planner.exceptions import InvalidArgumentError
from planner.export.calibration import ServoCalibration, check_calibrations, pulse_widths
from planner.export.formats.base import ServoFormat, check_period_ms, command_times

if TYPE_CHECKING:
    from planner.motion.trajectory import JointTrajectory

__all__ = ["LINE_ENDINGS", "SSC32_MAX_CHANNEL", "Ssc32", "ssc32_group_moves"]

#: Largest channel number of an SSC-32.
SSC32_MAX_CHANNEL = 31


def ssc32_group_moves(
    trajectory: JointTrajectory, calibrations: Sequence[ServoCalibration], period_ms: int = 20
) -> list[str]:
    """Lynxmotion SSC-32 group-move commands that replay a trajectory.

    One command per `period_ms`, ``#<ch>P<pw>#<ch>P<pw>...T<ms>``: every listed servo moves
    to its pulse width and all arrive together after ``T`` ms (the controller interpolates
    linearly within it). The first command holds the start pose for one period; send them one
    period apart, each followed by a carriage return (ASCII 13).

    Args:
        trajectory: The joint trajectory.
        calibrations: One per joint (channels 0-31).
        period_ms: Time per command [ms], a positive integer.

    Returns:
        The command strings, without terminators.

    Raises:
        InvalidArgumentError: On a bad period, channel or calibration, or a pulse out of range.
    """
    check_period_ms(period_ms)
    check_calibrations(calibrations, trajectory.dof)
    for c in calibrations:
        if c.channel > SSC32_MAX_CHANNEL:
            raise InvalidArgumentError(
                f"joint {c.joint!r} uses channel {c.channel}; an SSC-32 has channels 0-{SSC32_MAX_CHANNEL}"
            )
    pulses = pulse_widths(calibrations, trajectory.sample(command_times(trajectory, period_ms)).q)
    return ["".join(f"#{c.channel}P{p}" for c, p in zip(calibrations, row)) + f"T{period_ms}" for row in pulses]


#: Line endings an SSC-32 file can use: the controller's carriage return, or CR LF.
LINE_ENDINGS = {"cr": "\r", "crlf": "\r\n"}


class Ssc32(ServoFormat):
    """:func:`ssc32_group_moves`, each command ended by a carriage return (or CR LF), in ASCII.

    Args:
        line_ending: ``"cr"`` (ASCII 13, the SSC-32's terminator) or ``"crlf"`` (CR then LF:
            the controller still sees CR, and the file reads as lines in a text editor).

    Raises:
        InvalidArgumentError: On another line ending.
    """

    name: ClassVar[str] = "ssc32"
    file_name: ClassVar[str] = "ssc32.txt"
    encoding: ClassVar[str] = "ascii"
    written_by_default: ClassVar[bool] = True
    option_names: ClassVar[tuple[str, ...]] = ("line_ending",)

    def __init__(self, line_ending: str = "cr"):
        if line_ending not in LINE_ENDINGS:
            raise InvalidArgumentError(
                f"unknown line ending {line_ending!r}; valid line endings: {', '.join(LINE_ENDINGS)}"
            )
        self.line_ending = line_ending

    def render(self, trajectory: JointTrajectory, calibrations: Sequence[ServoCalibration], period_ms: int) -> str:
        """The commands, one period apart, each followed by the line ending."""
        end = LINE_ENDINGS[self.line_ending]
        return "".join(c + end for c in ssc32_group_moves(trajectory, calibrations, period_ms=period_ms))
