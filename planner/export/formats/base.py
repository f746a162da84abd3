"""The interface every servo-controller file format implements."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import TYPE_CHECKING, ClassVar

if TYPE_CHECKING:
    from planner.export.calibration import ServoCalibration
    from planner.motion.trajectory import JointTrajectory

__all__ = ["ServoFormat"]


class ServoFormat(ABC):
    """A file a servo controller (or its host program) replays a trajectory from.

    A new format is a subclass in its own module plus one line in
    :data:`planner.export.formats.SERVO_FORMATS`.

    Attributes:
        name: Registry key, e.g. ``"ssc32"``.
        file_name: File name the plan outputs use, with its suffix (e.g. ``"ssc32.txt"``).
        encoding: Text encoding of the file.
    """

    name: ClassVar[str]
    file_name: ClassVar[str]
    encoding: ClassVar[str] = "utf-8"

    @abstractmethod
    def render(self, trajectory: JointTrajectory, calibrations: Sequence[ServoCalibration], period_ms: int) -> str:
        """The file's text for a trajectory.

        Args:
            trajectory: The joint trajectory.
            calibrations: One per joint, in joint order.
            period_ms: Time between two servo updates [ms].

        Returns:
            The whole file, line terminators included.

        Raises:
            InvalidArgumentError: If a calibration does not fit the controller or an angle
                needs a pulse out of range.
        """
