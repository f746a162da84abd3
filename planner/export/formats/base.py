"""The interface every servo-controller file format implements."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from planner.core.text import plain
from planner.exceptions import InvalidArgumentError
from planner.export.calibration import ServoCalibration, default_calibrations

if TYPE_CHECKING:
    from planner.model.robot import Robot
    from planner.motion.trajectory import JointTrajectory

__all__ = ["ServoFormat", "check_period_ms", "command_times"]


class ServoFormat(ABC):
    """A file a servo controller (or its host program) replays a trajectory from.

    A new format is a subclass in its own module plus one line in
    :data:`planner.export.formats.SERVO_FORMATS`.

    Attributes:
        name: Registry key, e.g. ``"ssc32"``; plan files and calibration files name their
            controller by it (``controller: ssc32``).
        file_name: File name the plan outputs use, with its suffix (e.g. ``"ssc32.txt"``).
        encoding: Text encoding of the file.
        calibration_type: The calibration class each joint needs: :class:`ServoCalibration`
            (pulse widths) or :class:`planner.export.ticks.TickCalibration` (position ticks).
        option_names: Controller settings a calibration file may give (e.g. ``pwm_frequency_hz``);
            they are the constructor's keyword arguments.
        written_by_default: Whether a plan with no controller named writes this file.
    """

    name: ClassVar[str]
    file_name: ClassVar[str]
    encoding: ClassVar[str] = "utf-8"
    calibration_type: ClassVar[type] = ServoCalibration
    option_names: ClassVar[tuple[str, ...]] = ()
    written_by_default: ClassVar[bool] = False

    def configured(self, options: Mapping[str, Any]) -> ServoFormat:
        """This format with controller settings (see `option_names`), or itself when there are none.

        Raises:
            InvalidArgumentError: On a setting the format does not have (the message lists them).
        """
        if not options:
            return self
        unknown = [k for k in options if k not in self.option_names]
        if unknown:
            valid = ", ".join(self.option_names) or "none"
            raise InvalidArgumentError(
                f"controller {self.name!r} has no setting {unknown[0]!r}; valid settings: {valid}"
            )
        return type(self)(**options)

    def default_calibrations(
        self, robot: Robot, *, travel: tuple[np.ndarray, np.ndarray] | None = None
    ) -> tuple[Any, ...]:
        """Calibrations used when neither a plan file nor a calibration file gives any.

        Pulse formats centre each joint's range (or its `travel` in the plan, for a joint with
        no range) on consecutive channels (:func:`planner.export.calibration.default_calibrations`).

        Raises:
            InvalidArgumentError: If the controller has no sensible default (the message says
                what to give).
        """
        return default_calibrations(robot, travel=travel)

    @abstractmethod
    def render(self, trajectory: JointTrajectory, calibrations: Sequence[Any], period_ms: int) -> str:
        """The file's text for a trajectory.

        Args:
            trajectory: The joint trajectory.
            calibrations: One per joint, in joint order, of `calibration_type`.
            period_ms: Time between two servo updates [ms].

        Returns:
            The whole file, line terminators included.

        Raises:
            InvalidArgumentError: If a calibration does not fit the controller or an angle
                needs a value out of range.
        """


def check_period_ms(period_ms: int) -> None:
    """Check a servo period: an integer number of milliseconds in [1, 65535].

    Raises:
        InvalidArgumentError: If it is not (the message gives the value).
    """
    if isinstance(period_ms, bool) or not isinstance(period_ms, (int, np.integer)) or not 1 <= period_ms <= 65535:
        raise InvalidArgumentError(f"period_ms must be an integer in [1, 65535] ms, got {plain(period_ms)}")


def command_times(trajectory: JointTrajectory, period_ms: int) -> np.ndarray:
    """When each controller command of a stream applies: every `period_ms` from 0, the end included.

    Returns:
        Times shape (n,) [s]: ``k * period`` for ``k = 0 .. ceil(duration / period)``, the last
        one held at the trajectory's duration.
    """
    check_period_ms(period_ms)
    n = int(np.ceil(trajectory.duration * 1000.0 / period_ms - 1e-9)) + 1
    return np.minimum(np.arange(n) * period_ms / 1000.0, trajectory.duration)
