"""Servo-controller file formats, one module each, registered by name.

Adding a format: a :class:`ServoFormat` subclass in a new module here, plus one line in
:data:`SERVO_FORMATS`. Plan files and calibration files name their controller by the key
(``controller: feetech``); plan outputs (:func:`planner.app.outputs.write_servo_files`) write the
named controller's file, or, when none is named, every format that is ``written_by_default``.
"""

from __future__ import annotations

from collections.abc import Mapping

from planner.exceptions import InvalidArgumentError
from planner.export.formats.base import ServoFormat
from planner.export.formats.feetech import Feetech
from planner.export.formats.pca9685 import Pca9685
from planner.export.formats.pulse_csv import PulseCsv
from planner.export.formats.ssc32 import Ssc32
from planner.export.formats.steps import Steps

__all__ = ["SERVO_FORMATS", "ServoFormat", "servo_format"]

#: Every servo format by name.
SERVO_FORMATS: Mapping[str, ServoFormat] = {
    PulseCsv.name: PulseCsv(),
    Ssc32.name: Ssc32(),
    Pca9685.name: Pca9685(),
    Feetech.name: Feetech(),
    Steps.name: Steps(),
}


def servo_format(name: str) -> ServoFormat:
    """The registered format called `name`.

    Raises:
        InvalidArgumentError: If there is none (the message lists the valid names).
    """
    if not isinstance(name, str) or name not in SERVO_FORMATS:
        raise InvalidArgumentError(f"unknown servo format {name!r}; valid formats: {', '.join(SERVO_FORMATS)}")
    return SERVO_FORMATS[name]
