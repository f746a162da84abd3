"""Lynxmotion SSC-32 / SSC-32U driver: group moves, ``QP`` pulse queries, ``STOP <ch>``."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

import numpy as np

from planner.exceptions import ControllerError
from planner.export.calibration import check_calibrations, pulse_widths
from planner.export.formats.ssc32 import ssc32_group_moves
from planner.hardware.driver import ControllerDriver

if TYPE_CHECKING:
    from planner.hardware.link import Link
    from planner.motion.trajectory import JointTrajectory

__all__ = ["Ssc32Driver"]

#: Time to wait for one ``QP`` answer [s].
QUERY_TIMEOUT = 0.2
#: ESC cancels a command the SSC-32 has not received the carriage return of.
CANCEL = b"\x1b"


class Ssc32Driver(ControllerDriver):
    """The SSC-32: ASCII commands ended by a carriage return.

    ``QP <ch>`` answers one byte, the pulse width [us] / 10 the board *commands* on that channel:
    a hobby servo reports nothing, and a channel not driven since power-up answers 0, which
    :meth:`read_positions` gives as NaN (unknown). ``STOP <ch>`` stops one servo where it is
    (SSC-32U guide, miscellaneous commands).
    """

    name: ClassVar[str] = "ssc32"
    baud_rates: ClassVar[tuple[int, ...]] = (2400, 9600, 38400, 115200)
    default_baud: ClassVar[int] = 115200

    def commands(self, trajectory: JointTrajectory, period_ms: int) -> list[bytes]:
        """:func:`planner.export.formats.ssc32.ssc32_group_moves`, each ended by a carriage return."""
        return [(c + "\r").encode("ascii") for c in ssc32_group_moves(trajectory, self.calibrations, period_ms)]

    def read_positions(self, link: Link) -> np.ndarray:
        """``QP <ch>`` for every channel in use: the commanded pulse as an angle, NaN for 0."""
        link.discard_input()
        q = np.full(len(self.calibrations), np.nan)
        for k, cal in enumerate(self.calibrations):
            link.write(f"QP {cal.channel}\r".encode("ascii"))
            answer = link.read(1, QUERY_TIMEOUT)
            if len(answer) != 1:
                raise ControllerError(
                    f"no answer to 'QP {cal.channel}' from the SSC-32 on {link.name}: check the port, the baud "
                    "rate (the board's jumpers) and its power"
                )
            if answer[0]:
                q[k] = cal.angle(answer[0] * 10.0)
        return q

    def approach(self, q: np.ndarray, seconds: float) -> bytes:
        """One group move to `q` taking `seconds` (``T`` in ms): the servos go there at once from wherever they are."""
        check_calibrations(self.calibrations, len(q))
        ms = int(round(seconds * 1000.0))
        if not 1 <= ms <= 65535:
            raise ControllerError(f"approach time must lie in [0.001, 65.535] s (the SSC-32's T), got {seconds:g} s")
        row = pulse_widths(self.calibrations, np.asarray(q, dtype=float)[None, :])[0]
        return ("".join(f"#{c.channel}P{p}" for c, p in zip(self.calibrations, row)) + f"T{ms}\r").encode("ascii")

    def stop(self, link: Link) -> str:
        """ESC (drops a half-sent command), then ``STOP <ch>`` for every channel in use."""
        commands = [f"STOP {c.channel}" for c in self.calibrations]
        link.write(CANCEL + "".join(c + "\r" for c in commands).encode("ascii"))
        return ", ".join(commands)
