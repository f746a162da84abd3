"""Feetech STS/SCS bus servos (the SO-100/SO-101 arms): packets of the FT-SCS protocol and a sync-write file.

Every packet is ``0xFF 0xFF ID LEN INSTR PARAMS... CHECKSUM`` with ``LEN = len(PARAMS) + 2`` and
``CHECKSUM = ~(ID + LEN + INSTR + sum(PARAMS)) & 0xFF``; a servo answers ``0xFF 0xFF ID LEN
ERROR PARAMS... CHECKSUM``. A sync write (instruction 0x83 to the broadcast id 0xFE) sets the
same registers of several servos in one packet, and no servo answers it. The STS series (magnetic
encoder, 4096 ticks per turn) sends 16-bit values low byte first, with bit 15 as the sign of a
position; the SCS series (potentiometer) sends them high byte first (Feetech's "Communication
Protocol User Manual", sections 1.0-1.3; the control-table addresses are the STS3215's).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from enum import IntEnum
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from planner.core.text import plain
from planner.exceptions import InvalidArgumentError
from planner.export.calibration import check_calibrations
from planner.export.formats.base import ServoFormat, command_times
from planner.export.ticks import TickCalibration, tick_positions

if TYPE_CHECKING:
    from planner.model.robot import Robot
    from planner.motion.trajectory import JointTrajectory

__all__ = [
    "BROADCAST_ID",
    "FEETECH_SERIES",
    "GOAL_POSITION",
    "PRESENT_POSITION",
    "Feetech",
    "Instruction",
    "StatusPacket",
    "TORQUE_ENABLE",
    "checksum",
    "decode_position",
    "encode_position",
    "goal_position_packet",
    "packet",
    "parse_status",
    "read_packet",
    "sync_write_packet",
    "write_packet",
]

HEADER = b"\xff\xff"
#: The id every servo on the bus obeys (and none answers, except to PING).
BROADCAST_ID = 0xFE
#: Largest id of a single servo.
MAX_SERVO_ID = 253
#: The protocol's series: byte order of 16-bit values.
FEETECH_SERIES = ("sts", "scs")
#: STS3215 control table: torque switch, 1 byte (0 off, 1 on).
TORQUE_ENABLE = 0x28
#: STS3215 control table: goal position, 2 bytes (goal time at 0x2C and goal speed at 0x2E follow).
GOAL_POSITION = 0x2A
#: STS3215 control table: present position, 2 bytes, read only.
PRESENT_POSITION = 0x38


class Instruction(IntEnum):
    """Instruction codes of the FT-SCS protocol."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83


def checksum(body: bytes) -> int:
    """``~(ID + LEN + INSTR_or_ERROR + sum(PARAMS)) & 0xFF`` over a packet without its header and checksum."""
    return ~sum(body) & 0xFF


def _byte(value: int, what: str, top: int = 0xFF) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= top:
        raise InvalidArgumentError(f"{what} must be an integer in [0, {top}], got {plain(value)}")
    return value


def packet(servo_id: int, instruction: int, params: bytes = b"") -> bytes:
    """An instruction packet: header, id, length, instruction, parameters, checksum.

    Raises:
        InvalidArgumentError: If the id is not 0-254 or the packet would be too long.
    """
    _byte(servo_id, "servo id", BROADCAST_ID)
    if len(params) > 250:
        raise InvalidArgumentError(f"a packet holds at most 250 parameter bytes, got {len(params)}")
    body = bytes([servo_id, len(params) + 2, int(instruction)]) + bytes(params)
    return HEADER + body + bytes([checksum(body)])


def _series(series: str) -> str:
    if series not in FEETECH_SERIES:
        raise InvalidArgumentError(f"unknown Feetech series {series!r}; valid series: {', '.join(FEETECH_SERIES)}")
    return series


def encode_position(ticks: int, series: str = "sts") -> bytes:
    """A position as the two bytes the series sends.

    STS: low byte first, a negative position as its magnitude with bit 15 set. SCS: high byte
    first, never negative.

    Raises:
        InvalidArgumentError: If the position does not fit the series' 16 bits.
    """
    if _series(series) == "sts":
        if not -0x7FFF <= ticks <= 0x7FFF:
            raise InvalidArgumentError(f"an STS position must lie in [-32767, 32767] ticks, got {ticks}")
        raw = -ticks | 0x8000 if ticks < 0 else ticks
        return raw.to_bytes(2, "little")
    if not 0 <= ticks <= 0xFFFF:
        raise InvalidArgumentError(f"an SCS position must lie in [0, 65535] ticks, got {ticks}")
    return ticks.to_bytes(2, "big")


def decode_position(data: bytes, series: str = "sts") -> int:
    """The position two bytes of the series stand for (the inverse of :func:`encode_position`)."""
    if len(data) != 2:
        raise InvalidArgumentError(f"a position is 2 bytes, got {len(data)}")
    if _series(series) == "sts":
        raw = int.from_bytes(data, "little")
        return -(raw & 0x7FFF) if raw & 0x8000 else raw
    return int.from_bytes(data, "big")


def write_packet(servo_id: int, address: int, data: bytes) -> bytes:
    """WRITE: ``data`` into one servo's control table from ``address`` (the servo answers a status)."""
    return packet(servo_id, Instruction.WRITE, bytes([_byte(address, "address")]) + bytes(data))


def read_packet(servo_id: int, address: int, length: int) -> bytes:
    """READ: ask one servo for ``length`` bytes of its control table from ``address``."""
    _byte(servo_id, "servo id", MAX_SERVO_ID)
    return packet(servo_id, Instruction.READ, bytes([_byte(address, "address"), _byte(length, "length")]))


def sync_write_packet(address: int, data_by_id: Mapping[int, bytes]) -> bytes:
    """SYNC WRITE to the broadcast id: the same registers of several servos, ``LEN = (L + 1) * N + 4``.

    Raises:
        InvalidArgumentError: If there are no servos, an id is not 0-253, or the data lengths differ.
    """
    if not data_by_id:
        raise InvalidArgumentError("a sync write needs at least one servo")
    lengths = {len(d) for d in data_by_id.values()}
    if len(lengths) != 1:
        raise InvalidArgumentError(f"every servo of a sync write needs the same data length, got {sorted(lengths)}")
    params = bytearray([_byte(address, "address"), lengths.pop()])
    for servo_id, data in data_by_id.items():
        params.append(_byte(servo_id, "servo id", MAX_SERVO_ID))
        params += data
    return packet(BROADCAST_ID, Instruction.SYNC_WRITE, bytes(params))


def goal_position_packet(ids: Sequence[int], ticks: Sequence[int], series: str = "sts") -> bytes:
    """One sync write of the goal position (address 0x2A, 2 bytes) of every servo."""
    return sync_write_packet(GOAL_POSITION, {i: encode_position(int(p), series) for i, p in zip(ids, ticks)})


class StatusPacket:
    """A servo's answer: its id, error byte and parameters (see :func:`parse_status`).

    Attributes:
        id: The servo id.
        error: The error byte (0: no error).
        params: The returned bytes.
    """

    __slots__ = ("id", "error", "params")

    def __init__(self, servo_id: int, error: int, params: bytes):
        self.id, self.error, self.params = servo_id, error, params


def parse_status(data: bytes) -> StatusPacket:
    """Parse one complete status packet, checking its header, length and checksum.

    Raises:
        InvalidArgumentError: If it is malformed (the message says how).
    """
    if len(data) < 6 or data[:2] != HEADER:
        raise InvalidArgumentError(f"not a Feetech status packet: {data.hex(' ')}")
    length = data[3]
    if len(data) != length + 4:
        raise InvalidArgumentError(f"status packet length byte says {length + 4} bytes, got {len(data)}")
    if checksum(data[2:-1]) != data[-1]:
        raise InvalidArgumentError(
            f"status packet checksum is {data[-1]:#04x}, expected {checksum(data[2:-1]):#04x}: {data.hex(' ')}"
        )
    return StatusPacket(data[2], data[4], bytes(data[5:-1]))


class Feetech(ServoFormat):
    """Goal-position sync writes, one per servo period: ``<t [s]> <packet bytes in hex>`` a line.

    The packets are the bytes ``planner send --controller feetech`` writes to the bus.

    Args:
        series: ``"sts"`` (default; STS3215 and kin, low byte first) or ``"scs"`` (high byte first).
    """

    name: ClassVar[str] = "feetech"
    file_name: ClassVar[str] = "feetech.txt"
    encoding: ClassVar[str] = "ascii"
    calibration_type: ClassVar[type] = TickCalibration
    option_names: ClassVar[tuple[str, ...]] = ("series",)

    def __init__(self, series: str = "sts"):
        self.series = _series(series)

    def default_calibrations(
        self, robot: Robot, *, travel: tuple[np.ndarray, np.ndarray] | None = None
    ) -> tuple[TickCalibration, ...]:
        """Ids 1, 2, ... in joint order; joint zero at tick 2048, 4096 ticks per turn, ticks 0-4095."""
        return tuple(TickCalibration(k + 1, joint=name) for k, name in enumerate(robot.joint_names))

    def packets(
        self, trajectory: JointTrajectory, calibrations: Sequence[TickCalibration], period_ms: int
    ) -> list[tuple[float, bytes]]:
        """``(t [s], packet)`` for every servo period (see :func:`planner.export.formats.base.command_times`).

        Raises:
            InvalidArgumentError: If a calibration is not a :class:`TickCalibration`, two share an
                id, an id is beyond 253, or a position is out of its calibration's range.
        """
        t = command_times(trajectory, period_ms)
        check_calibrations(calibrations, trajectory.dof, TickCalibration)
        for c in calibrations:
            if c.id > MAX_SERVO_ID:
                raise InvalidArgumentError(f"joint {c.joint!r} uses id {c.id}; Feetech ids are 0-{MAX_SERVO_ID}")
        ticks = tick_positions(calibrations, trajectory.sample(t).q)
        ids = [c.id for c in calibrations]
        return [(float(ti), goal_position_packet(ids, row, self.series)) for ti, row in zip(t, ticks)]

    def render(self, trajectory: JointTrajectory, calibrations: Sequence[Any], period_ms: int) -> str:
        """One line per packet: the time to the microsecond, then the bytes in hex."""
        return "".join(f"{t:.6f} {p.hex(' ')}\n" for t, p in self.packets(trajectory, calibrations, period_ms))
