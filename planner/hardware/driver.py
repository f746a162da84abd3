"""The interface every controller driver implements: commands, position read-back, approach, safe stop."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from planner.exceptions import ControllerError

if TYPE_CHECKING:
    from planner.hardware.link import Link
    from planner.motion.trajectory import JointTrajectory

__all__ = ["ControllerDriver"]


class ControllerDriver(ABC):
    """Drives one kind of servo controller over a :class:`~planner.hardware.link.Link`.

    A new controller is a subclass in its own module plus one line in
    :data:`planner.hardware.DRIVERS`.

    Attributes:
        name: Registry key, the same as its export format's (``"ssc32"``).
        baud_rates: Baud rates the controller can be set to, slowest first.
        default_baud: The rate it ships with.

    Args:
        calibrations: One per joint, of the kind its export format takes.
        settings: Controller settings of the calibration file (e.g. the Feetech ``series``).
    """

    name: ClassVar[str]
    baud_rates: ClassVar[tuple[int, ...]]
    default_baud: ClassVar[int]

    def __init__(self, calibrations: Sequence[Any], settings: Mapping[str, Any] | None = None):
        self.calibrations = tuple(calibrations)
        self.settings = dict(settings or {})

    @abstractmethod
    def commands(self, trajectory: JointTrajectory, period_ms: int) -> list[bytes]:
        """The bytes to send every `period_ms`, from the start pose to the end (one command each).

        Raises:
            InvalidArgumentError: If a calibration does not fit the controller or a value is out of range.
        """

    @abstractmethod
    def read_positions(self, link: Link) -> np.ndarray:
        """Where the controller says each joint is [rad], NaN where it cannot tell.

        Raises:
            ControllerError: If the controller does not answer, or answers garbage.
        """

    def begin(self, link: Link) -> None:  # noqa: B027 - most controllers need nothing
        """Make the servos ready to follow the stream, after the start check and before the first command.

        Raises:
            ControllerError: If the link fails.
        """

    def approach(self, q: np.ndarray, seconds: float) -> bytes:
        """One timed move to `q` [rad] taking `seconds`, for when the position is unknown.

        Raises:
            ControllerError: If the controller has no timed move (it can read its position instead).
        """
        raise ControllerError(
            f"the {self.name} controller reads its servos' positions; use --from-current instead of --approach-time"
        )

    @abstractmethod
    def stop(self, link: Link) -> str:
        """Stop every servo in use where it is; returns what was sent, for the report.

        Raises:
            ControllerError: If the link fails while stopping.
        """
