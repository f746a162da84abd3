"""Byte links to a controller: a serial port (pyserial, the ``hardware`` extra) or a dry run that prints.

A link writes and reads bytes; any failure of the port is a
:class:`~planner.exceptions.ControllerError`, so a stream can stop safely on it.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import TextIO

from planner.core.version import install_hint
from planner.exceptions import ControllerError

__all__ = ["Clock", "DryRunLink", "Link", "SerialLink", "open_serial", "show_bytes", "virtual_clock"]


@dataclass(frozen=True)
class Clock:
    """Where a stream gets its time: a monotonic clock [s] and a sleep [s] (both injectable)."""

    now: Callable[[], float] = time.monotonic
    sleep: Callable[[float], None] = time.sleep

    def wait_until(self, deadline: float) -> float:
        """Sleep until `deadline` [s on `now`'s scale]; returns how late it is then [s] (0 if on time)."""
        ahead = deadline - self.now()
        if ahead > 0:
            self.sleep(ahead)
        return max(0.0, self.now() - deadline)


def virtual_clock() -> Clock:
    """A clock that only moves when slept on: a dry run prints a stream's schedule without waiting."""
    t = [0.0]

    def sleep(seconds: float) -> None:
        t[0] += max(0.0, seconds)

    return Clock(now=lambda: t[0], sleep=sleep)


class Link(ABC):
    """A byte link to a controller.

    Attributes:
        name: The port's name, for messages.
        can_read: Whether the link hears the controller (a dry run does not).
    """

    name: str = ""
    can_read: bool = True

    @abstractmethod
    def write(self, data: bytes) -> None:
        """Send bytes.

        Raises:
            ControllerError: If the port fails.
        """

    @abstractmethod
    def read(self, size: int, timeout: float) -> bytes:
        """Up to `size` bytes, waiting at most `timeout` [s] (fewer when the controller says less).

        Raises:
            ControllerError: If the port fails.
        """

    def discard_input(self) -> None:  # noqa: B027 - optional for links that buffer nothing
        """Drop bytes received and not read yet."""

    def close(self) -> None:  # noqa: B027 - optional for links with nothing to release
        """Release the port."""


def show_bytes(data: bytes) -> str:
    r"""Bytes as a dry run prints them: ASCII with ``\r`` and ``\x1b`` escaped, else hex."""
    if all(32 <= b < 127 or b in (13, 27) for b in data):
        return data.decode("ascii").replace("\r", "\\r").replace("\x1b", "\\x1b")
    return data.hex(" ")


class DryRunLink(Link):
    """Prints each write as ``<t [s]>  <bytes>`` (see :func:`show_bytes`) instead of sending it."""

    can_read = False

    def __init__(self, out: TextIO, clock: Clock):
        self.name = "dry run"
        self._out = out
        self._clock = clock
        self._t0 = clock.now()

    def write(self, data: bytes) -> None:
        """Print the bytes with the time since the link was made."""
        self._out.write(f"{self._clock.now() - self._t0:9.3f}  {show_bytes(data)}\n")

    def read(self, size: int, timeout: float) -> bytes:
        """Nothing: a dry run hears no controller."""
        return b""


class SerialLink(Link):
    """A serial port opened with pyserial (8 data bits, no parity, 1 stop bit)."""

    def __init__(self, port: object, name: str):
        self._port = port
        self.name = name

    def write(self, data: bytes) -> None:
        """Send bytes and wait until the OS has taken them all."""
        try:
            self._port.write(data)
        except Exception as exc:  # pyserial raises SerialException, OSError or ValueError on a closed port
            raise ControllerError(f"writing to {self.name} failed: {exc}") from exc

    def read(self, size: int, timeout: float) -> bytes:
        """Up to `size` bytes within `timeout` [s]."""
        try:
            self._port.timeout = timeout
            return bytes(self._port.read(size))
        except Exception as exc:
            raise ControllerError(f"reading from {self.name} failed: {exc}") from exc

    def discard_input(self) -> None:
        """Drop bytes received and not read yet."""
        try:
            self._port.reset_input_buffer()
        except Exception as exc:
            raise ControllerError(f"{self.name} failed: {exc}") from exc

    def close(self) -> None:
        """Close the port (errors on closing a broken port are ignored)."""
        try:
            self._port.close()
        except Exception:  # noqa: S110 - a port that failed mid-stream may fail again on close
            pass


def open_serial(port: str, baud: int) -> SerialLink:
    """Open a serial port with pyserial.

    Raises:
        ControllerError: If pyserial is not installed (the message names the extra to install)
            or the port cannot be opened.
    """
    try:
        import serial
    except ImportError as exc:
        raise ControllerError(f"planner send needs pyserial: {install_hint('hardware')}") from exc
    try:
        handle = serial.Serial(port, baudrate=baud, timeout=0.1, write_timeout=2.0)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise ControllerError(f"cannot open serial port {port!r} at {baud} baud: {exc}") from exc
    return SerialLink(handle, port)
