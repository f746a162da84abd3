"""NXP PCA9685 16-channel, 12-bit PWM board: on/off counter ticks per channel every servo period."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from planner.core.text import plain
from planner.exceptions import InvalidArgumentError
from planner.export.calibration import ServoCalibration, check_calibrations, pulse_widths
from planner.export.formats.base import ServoFormat, command_times

if TYPE_CHECKING:
    from planner.motion.trajectory import JointTrajectory

__all__ = ["PCA9685_MAX_CHANNEL", "PCA9685_TICKS", "Pca9685", "pca9685_off_ticks"]

#: Counter steps per PWM period of a PCA9685 (a 12-bit counter).
PCA9685_TICKS = 4096
#: Largest channel number of a PCA9685.
PCA9685_MAX_CHANNEL = 15
#: PWM frequencies the PCA9685's prescaler reaches with its 25 MHz oscillator (prescale 255 to 3) [Hz].
PCA9685_FREQUENCY_RANGE = (24.0, 1526.0)


def pca9685_off_ticks(pulse_us: np.ndarray, frequency_hz: float) -> np.ndarray:
    """The counter tick at which a pulse that starts at tick 0 ends.

    ``off = round(pulse [us] * frequency [Hz] * 4096 / 1e6)``.

    Args:
        pulse_us: Pulse widths [us].
        frequency_hz: PWM frequency [Hz].

    Returns:
        Off ticks, int, same shape.

    Raises:
        InvalidArgumentError: If a pulse does not fit in one PWM period (ticks 0-4095).
    """
    off = np.rint(np.asarray(pulse_us, dtype=float) * frequency_hz * PCA9685_TICKS / 1e6).astype(int)
    if np.any(off > PCA9685_TICKS - 1):
        worst = float(np.max(pulse_us))
        raise InvalidArgumentError(
            f"a {worst:g} us pulse does not fit in one {1e6 / frequency_hz:g} us PWM period at {frequency_hz:g} Hz; "
            "lower pwm_frequency_hz"
        )
    return off


class Pca9685(ServoFormat):
    """``t,ch<channel>_<joint>_on,ch<channel>_<joint>_off,...`` every servo period, as CSV.

    Each servo's pulse starts at counter tick 0 (``on``) and ends at ``off`` =
    :func:`pca9685_off_ticks` of its pulse width at the configured PWM frequency: the values a
    host writes to the board's ``LEDn_ON`` and ``LEDn_OFF`` registers.

    Args:
        pwm_frequency_hz: The board's PWM frequency [Hz] (50 Hz: a hobby servo's 20 ms frame).
    """

    name: ClassVar[str] = "pca9685"
    file_name: ClassVar[str] = "pca9685.csv"
    option_names: ClassVar[tuple[str, ...]] = ("pwm_frequency_hz",)

    def __init__(self, pwm_frequency_hz: float = 50.0):
        lo, hi = PCA9685_FREQUENCY_RANGE
        if (
            isinstance(pwm_frequency_hz, bool)
            or not isinstance(pwm_frequency_hz, (int, float))
            or not lo <= pwm_frequency_hz <= hi
        ):
            raise InvalidArgumentError(
                f"pwm_frequency_hz must be a number in [{lo:g}, {hi:g}] Hz (the PCA9685 prescaler's range), "
                f"got {plain(pwm_frequency_hz)}"
            )
        self.pwm_frequency_hz = float(pwm_frequency_hz)

    def render(self, trajectory: JointTrajectory, calibrations: Sequence[ServoCalibration], period_ms: int) -> str:
        """The CSV text (see the class docstring); times to the microsecond."""
        t = command_times(trajectory, period_ms)
        check_calibrations(calibrations, trajectory.dof)
        for c in calibrations:
            if c.channel > PCA9685_MAX_CHANNEL:
                raise InvalidArgumentError(
                    f"joint {c.joint!r} uses channel {c.channel}; a PCA9685 has channels 0-{PCA9685_MAX_CHANNEL}"
                )
        off = pca9685_off_ticks(pulse_widths(calibrations, trajectory.sample(t).q), self.pwm_frequency_hz)
        head = ["t"] + [f"ch{c.channel}_{c.joint}_{edge}" for c in calibrations for edge in ("on", "off")]
        lines = [",".join(head)]
        lines += [f"{ti:.6f}," + ",".join(f"0,{x}" for x in row) for ti, row in zip(t, off)]
        return "".join(line + "\n" for line in lines)
