"""Layer 6: driving a real arm: serial links, one driver per controller, paced streaming with a safe stop.

Adding a controller: a :class:`ControllerDriver` subclass in a new module here (named like its
export format in :data:`planner.export.formats.SERVO_FORMATS`), plus one line in :data:`DRIVERS`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from planner.exceptions import InvalidArgumentError
from planner.hardware.driver import ControllerDriver
from planner.hardware.feetech import FeetechDriver
from planner.hardware.ssc32 import Ssc32Driver

__all__ = ["DRIVERS", "ControllerDriver", "controller_driver"]

#: Every controller `planner send` drives, by name.
DRIVERS: Mapping[str, type[ControllerDriver]] = {
    Ssc32Driver.name: Ssc32Driver,
    FeetechDriver.name: FeetechDriver,
}


def controller_driver(
    name: str | None, calibrations: Sequence[Any], settings: Mapping[str, Any] | None = None
) -> ControllerDriver:
    """The driver of controller `name` for these calibrations.

    Raises:
        InvalidArgumentError: If `planner send` cannot drive it (the message lists those it can).
    """
    if name not in DRIVERS:
        raise InvalidArgumentError(
            f"planner send cannot drive controller {name!r}; valid controllers: {', '.join(DRIVERS)} "
            "(the others are export formats: planner plan --out)"
        )
    return DRIVERS[name](calibrations, settings)
