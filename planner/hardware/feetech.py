"""Feetech STS/SCS bus-servo driver: goal-position sync writes, present-position reads, hold-in-place stop."""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

import numpy as np

from planner.exceptions import ControllerError, PlannerError
from planner.export.formats.feetech import (
    PRESENT_POSITION,
    TORQUE_ENABLE,
    Feetech,
    decode_position,
    goal_position_packet,
    parse_status,
    read_packet,
    sync_write_packet,
)
from planner.hardware.driver import ControllerDriver

if TYPE_CHECKING:
    from planner.hardware.link import Link
    from planner.motion.trajectory import JointTrajectory

__all__ = ["FeetechDriver"]

#: Time to wait for one servo's answer [s].
READ_TIMEOUT = 0.1


class FeetechDriver(ControllerDriver):
    """Feetech STS (default) or SCS servos on one half-duplex bus (setting ``series``).

    The stream is one goal-position sync write per period (no servo answers it); the present
    position (address 0x38) is read from each servo before moving. Before the first command
    each servo's goal is set to its present position and its torque switched on (address
    0x28), so a servo left limp (e.g. after calibrating by hand) follows the stream without
    first jumping to an old goal; a stop writes each servo's present position as its goal.
    """

    name: ClassVar[str] = "feetech"
    baud_rates: ClassVar[tuple[int, ...]] = (38400, 57600, 76800, 115200, 128000, 250000, 500000, 1000000)
    default_baud: ClassVar[int] = 1000000

    @property
    def _format(self) -> Feetech:
        return Feetech(**self.settings)

    def commands(self, trajectory: JointTrajectory, period_ms: int) -> list[bytes]:
        """The goal-position sync writes of :meth:`planner.export.formats.feetech.Feetech.packets`."""
        return [p for _, p in self._format.packets(trajectory, self.calibrations, period_ms)]

    def _read_ticks(self, link: Link, servo_id: int) -> int:
        link.write(read_packet(servo_id, PRESENT_POSITION, 2))
        answer = link.read(8, READ_TIMEOUT)
        if not answer:
            raise ControllerError(
                f"servo id {servo_id} does not answer on {link.name}: check its id, the baud rate and the bus power"
            )
        try:
            status = parse_status(answer)
        except PlannerError as exc:
            raise ControllerError(f"servo id {servo_id} answered garbage on {link.name}: {exc}") from exc
        if status.id != servo_id or len(status.params) != 2:
            raise ControllerError(f"asked servo id {servo_id} for its position, got {answer.hex(' ')}")
        return decode_position(status.params, self._format.series)

    def read_positions(self, link: Link) -> np.ndarray:
        """Each servo's present position [rad] (a bus servo always knows it)."""
        link.discard_input()
        return np.array([c.angle(self._read_ticks(link, c.id)) for c in self.calibrations])

    def begin(self, link: Link) -> None:
        """Goal = present position for every servo, then torque on (two sync writes)."""
        ids = [c.id for c in self.calibrations]
        present = [self._read_ticks(link, i) for i in ids]
        link.write(goal_position_packet(ids, present, self._format.series))
        link.write(sync_write_packet(TORQUE_ENABLE, {i: b"\x01" for i in ids}))

    def stop(self, link: Link) -> str:
        """Read each servo's present position and write it back as its goal (one sync write)."""
        ids, ticks, missing = [], [], []
        for c in self.calibrations:
            try:
                ticks.append(self._read_ticks(link, c.id))
                ids.append(c.id)
            except ControllerError:
                missing.append(c.id)
        if ids:
            link.write(goal_position_packet(ids, ticks, self._format.series))
        held = f"goal = present position for ids {', '.join(map(str, ids))}" if ids else "no servo answered"
        return held + (f"; ids {', '.join(map(str, missing))} did not answer" if missing else "")
