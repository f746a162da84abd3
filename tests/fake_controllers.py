"""Fake servo controllers on the far end of a pseudo-terminal, for `planner send` tests.

Each fake opens a pty pair: the sender opens the device side (``port``) with pyserial, exactly as
it opens a USB serial adapter; the fake reads and answers on the controller side in a thread and
records what arrived, with monotonic arrival times.
"""

from __future__ import annotations

import os
import re
import select
import threading
import time
import tty

from planner.export.formats.feetech import checksum, decode_position, encode_position

GROUP_MOVE = re.compile(r"^((?:#\d+P\d+)+)T(\d+)$")


class FakePort(threading.Thread):
    """The controller side of a pty; subclasses parse what arrives in `feed`."""

    def __init__(self):
        super().__init__(daemon=True)
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.port = os.ttyname(self.slave)
        self.received: list[tuple[float, bytes]] = []
        self._halt = threading.Event()
        self.hang_up_after: int | None = None  # close the line after this many recorded commands
        self._closed = False

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self._halt.set()
        self.join(timeout=2)
        self.hang_up()

    def hang_up(self) -> None:
        if not self._closed:
            self._closed = True
            os.close(self.slave)
            os.close(self.master)

    def answer(self, data: bytes) -> None:
        os.write(self.master, data)

    def run(self):
        while not self._halt.is_set():
            try:
                ready, _, _ = select.select([self.master], [], [], 0.02)
                if not ready:
                    continue
                chunk = os.read(self.master, 4096)
            except OSError:
                return
            now = time.monotonic()
            self.received.append((now, chunk))
            self.feed(chunk, now)
            if self.hang_up_after is not None and self.command_count() >= self.hang_up_after:
                self.hang_up()
                return

    def feed(self, chunk: bytes, now: float) -> None:
        raise NotImplementedError

    def command_count(self) -> int:
        raise NotImplementedError


class FakeSsc32(FakePort):
    """An SSC-32: group moves, ``QP <ch>`` (pulse / 10 last commanded, 0 if never), ``Q``, ``STOP <ch>``, ESC."""

    def __init__(self, pulses: dict[int, int] | None = None):
        super().__init__()
        self.pulses = dict(pulses or {})  # channel -> last commanded pulse [us]
        self.moves: list[tuple[float, dict[int, int], int]] = []  # (arrival, {channel: pulse}, T [ms])
        self.log: list[str] = []  # every command, in order
        self.errors: list[str] = []
        self._buffer = b""

    def command_count(self) -> int:
        return len(self.moves)

    def feed(self, chunk: bytes, now: float) -> None:
        for byte in chunk:
            if byte == 0x1B:  # ESC cancels the command being received
                self._buffer = b""
            elif byte == 0x0D:
                self.command(self._buffer.decode("ascii", "replace"), now)
                self._buffer = b""
            else:
                self._buffer += bytes([byte])

    def command(self, text: str, now: float) -> None:
        self.log.append(text)
        if text.startswith("QP"):
            channel = int(text[2:].strip())
            self.answer(bytes([self.pulses.get(channel, 0) // 10]))
        elif text == "Q":
            self.answer(b".")
        elif text.startswith("STOP"):
            int(text[4:].strip())
        elif m := GROUP_MOVE.match(text):
            targets = {int(c): int(p) for c, p in re.findall(r"#(\d+)P(\d+)", m.group(1))}
            self.pulses.update(targets)
            self.moves.append((now, targets, int(m.group(2))))
        else:
            self.errors.append(text)


class FakeFeetechBus(FakePort):
    """Feetech STS servos on one bus: checks every packet's checksum, answers READ, records SYNC WRITEs."""

    def __init__(self, positions: dict[int, int]):
        super().__init__()
        self.positions = dict(positions)  # id -> present position [ticks]
        self.packets: list[tuple[float, bytes]] = []  # every instruction packet, in order
        self.writes: list[tuple[float, dict[int, int]]] = []  # goal-position sync writes
        self.bad: list[bytes] = []  # packets with a wrong checksum or an unknown shape
        self.torque: dict[int, int] = {}  # id -> torque switch
        self._buffer = b""

    def command_count(self) -> int:
        return len(self.writes)

    def feed(self, chunk: bytes, now: float) -> None:
        self._buffer += chunk
        while True:
            start = self._buffer.find(b"\xff\xff")
            if start < 0 or len(self._buffer) < start + 4:
                return
            size = self._buffer[start + 3] + 4
            if len(self._buffer) < start + size:
                return
            pkt, self._buffer = self._buffer[start : start + size], self._buffer[start + size :]
            self.packets.append((now, pkt))
            if checksum(pkt[2:-1]) != pkt[-1]:
                self.bad.append(pkt)
                continue
            self.handle(pkt, now)

    def handle(self, pkt: bytes, now: float) -> None:
        servo, instr, params = pkt[2], pkt[4], pkt[5:-1]
        if instr == 0x02 and params[0] == 0x38 and params[1] == 2 and servo in self.positions:
            body = bytes([servo, 4, 0]) + encode_position(self.positions[servo])
            self.answer(b"\xff\xff" + body + bytes([checksum(body)]))
        elif instr == 0x83 and servo == 0xFE and params[0] == 0x2A and params[1] == 2:
            goals = {params[i]: decode_position(params[i + 1 : i + 3]) for i in range(2, len(params), 3)}
            self.positions.update(goals)  # these servos arrive at once
            self.writes.append((now, goals))
        elif instr == 0x83 and servo == 0xFE and params[0] == 0x28 and params[1] == 1:
            self.torque.update({params[i]: params[i + 1] for i in range(2, len(params), 2)})
        else:
            self.bad.append(pkt)
