"""Streaming a trajectory to a controller: checks up front, position read-back, paced sends, safe stop.

:func:`prepare_stream` turns a trajectory into one command per servo period and checks, before any
port is opened, that the baud rate carries it. :func:`run_stream` reads where the arm is, refuses
to start far from the first waypoint (or plans a first move from there, or makes one slow timed
move when the controller cannot tell), then sends each command at ``t0 + k * period`` on a
monotonic clock (a late command never delays the next ones), and on Ctrl-C or a port failure
stops every servo in use and reports how far the plan got.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

import numpy as np

from planner.core.text import plain
from planner.exceptions import ControllerError, InvalidArgumentError, JointLimitError, StartPositionError
from planner.export.formats.base import check_period_ms
from planner.hardware.link import Clock

if TYPE_CHECKING:
    from planner.hardware.driver import ControllerDriver
    from planner.hardware.link import Link
    from planner.motion.limits import JointLimits
    from planner.motion.trajectory import JointTrajectory

__all__ = ["SendOptions", "SendResult", "SendStatus", "Stream", "prepare_stream", "run_stream"]

#: Bits on the wire per byte: 8 data bits, a start bit and a stop bit (8N1).
BITS_PER_BYTE = 10


class SendStatus(str, Enum):
    """How a stream ended."""

    COMPLETED = "completed"
    INTERRUPTED = "interrupted"
    LINK_ERROR = "link error"


@dataclass(frozen=True)
class SendOptions:
    """How to stream a plan.

    Attributes:
        baud: Serial speed [bit/s]; None uses the controller's default.
        from_current: When the arm is far from the first waypoint, plan a first move from where
            it is (at the plan's limits) instead of refusing.
        approach_time: When the controller cannot tell where the arm is (an SSC-32 channel not
            driven since power-up), make one timed move to the first waypoint taking this long
            [s] before the plan; the arm jumps if a servo was elsewhere. None refuses instead.
        start_tolerance: Largest distance of any joint from the first waypoint that counts as
            being there [rad].
    """

    baud: int | None = None
    from_current: bool = False
    approach_time: float | None = None
    start_tolerance: float = 0.05

    def __post_init__(self) -> None:
        if self.baud is not None and (isinstance(self.baud, bool) or not isinstance(self.baud, int) or self.baud <= 0):
            raise InvalidArgumentError(f"baud must be a positive integer [bit/s], got {plain(self.baud)}")
        if self.approach_time is not None and not (math.isfinite(self.approach_time) and self.approach_time > 0):
            raise InvalidArgumentError(f"approach_time must be positive [s], got {plain(self.approach_time)}")
        if not (math.isfinite(self.start_tolerance) and self.start_tolerance > 0):
            raise InvalidArgumentError(f"start_tolerance must be positive [rad], got {plain(self.start_tolerance)}")


@dataclass(frozen=True)
class Stream:
    """The commands of a trajectory, one per servo period (see :func:`prepare_stream`).

    Attributes:
        trajectory: The trajectory.
        commands: The bytes of each command.
        period: Time between two commands [s].
        baud: The baud rate checked against [bit/s].
        bits_per_second: The largest command's bits over one period [bit/s].
    """

    trajectory: JointTrajectory
    commands: tuple[bytes, ...]
    period: float
    baud: int
    bits_per_second: float


@dataclass(frozen=True)
class SendResult:
    """What a stream did.

    Attributes:
        status: How it ended.
        commands_sent: Plan commands sent.
        commands_total: Plan commands in the stream.
        plan_time: Plan time of the last command sent [s] (-1 when none was).
        duration: The plan's duration [s].
        start_q: Joint angles read before moving [rad] (NaN where unknown), or None when not read.
        prelude: ``""``, ``"from current"`` (a planned move from where the arm was) or
            ``"approach"`` (one timed move).
        stop: What was sent to stop the servos, or None when the plan completed.
        max_lateness: The latest any command left after its deadline [s].
        message: One line for people.
    """

    status: SendStatus
    commands_sent: int
    commands_total: int
    plan_time: float
    duration: float
    start_q: np.ndarray | None
    prelude: str
    stop: str | None
    max_lateness: float
    message: str


def prepare_stream(driver: ControllerDriver, trajectory: JointTrajectory, period_ms: int, baud: int) -> Stream:
    """A trajectory's commands, checked to fit the baud rate; nothing is opened or sent.

    Raises:
        InvalidArgumentError: On a bad period or a value out of a calibration's range.
        ControllerError: If the baud rate cannot carry one command per period (the message names
            the controller's slowest rate that can).
    """
    check_period_ms(period_ms)
    commands = tuple(driver.commands(trajectory, period_ms))
    period = period_ms / 1000.0
    bits = max(len(c) for c in commands) * BITS_PER_BYTE
    need = bits / period
    if need > baud:
        fast = [b for b in driver.baud_rates if b >= need]
        advice = f"use {fast[0]} baud or faster" if fast else "lengthen the servo period (servo_period_ms)"
        raise ControllerError(
            f"{baud} baud carries {baud * period:.0f} bits per {period_ms} ms period, but each {driver.name} command "
            f"needs up to {bits} ({need / 1000:.1f} kbit/s): {advice} "
            f"(the {driver.name} takes {', '.join(map(str, driver.baud_rates))})"
        )
    return Stream(trajectory, commands, period, baud, need)


def _prelude(
    link: Link, driver: ControllerDriver, stream: Stream, options: SendOptions, limits: JointLimits | None
) -> tuple[np.ndarray | None, str, list[tuple[float, bytes]], float]:
    """Read the arm; returns (start_q, kind, [(offset [s], bytes)], offset of the plan's first command)."""
    q0 = stream.trajectory.waypoints[0]
    names = [getattr(c, "joint", "") or f"#{k}" for k, c in enumerate(driver.calibrations)]
    approach = options.approach_time
    if not link.can_read:
        if approach is None:
            return None, "", [], 0.0
        return None, "approach", [(0.0, driver.approach(q0, approach))], approach
    q = driver.read_positions(link)
    unknown = [n for n, v in zip(names, q) if math.isnan(v)]
    if unknown:
        if approach is None:
            raise StartPositionError(
                f"the {driver.name} cannot tell where joint(s) {', '.join(unknown)} are (a hobby servo reports "
                "nothing, and a channel not driven since power-up reads 0): nothing was sent; give --approach-time S "
                "for one slow timed move to the first waypoint (the arm jumps if a servo was elsewhere)",
                joint=unknown[0],
                expected=float(q0[names.index(unknown[0])]),
            )
        return q, "approach", [(0.0, driver.approach(q0, approach))], approach
    error = np.abs(q - q0)
    k = int(np.argmax(error))
    if error[k] <= options.start_tolerance:
        return q, "", [], 0.0
    if options.from_current:
        from planner.motion.plan import plan_trajectory

        if limits is None:
            raise InvalidArgumentError("from_current needs the plan's joint limits")
        try:
            first = plan_trajectory(np.array([q, q0]), limits)
        except JointLimitError as exc:  # the reading, not the plan's waypoint 0, is out of range
            raise StartPositionError(
                f"the {driver.name} reads joint {exc.joint!r} at {exc.value:.6g} rad, outside its range "
                f"[{exc.lower:.6g}, {exc.upper:.6g}]: nothing was sent; no move from there can be planned (move the "
                "joint into its range, or give --approach-time S for one timed move to the first waypoint)",
                joint=exc.joint,
                value=exc.value,
                expected=float(q0[names.index(exc.joint)]) if exc.joint in names else float("nan"),
            ) from exc
        commands = driver.commands(first, int(round(stream.period * 1000)))
        offsets = [i * stream.period for i in range(len(commands))]
        return q, "from current", list(zip(offsets, commands)), len(commands) * stream.period
    if approach is not None:
        return q, "approach", [(0.0, driver.approach(q0, approach))], approach
    raise StartPositionError(
        f"joint {names[k]!r} is at {q[k]:.4f} rad, {error[k]:.4f} rad from the plan's first waypoint "
        f"({q0[k]:.4f} rad; tolerance {options.start_tolerance:g} rad): nothing was sent; give --from-current to "
        "plan a first move from where the arm is",
        joint=names[k],
        value=float(q[k]),
        expected=float(q0[k]),
    )


def run_stream(
    link: Link,
    driver: ControllerDriver,
    stream: Stream,
    options: SendOptions | None = None,
    *,
    limits: JointLimits | None = None,
    clock: Clock | None = None,
) -> SendResult:
    """Send a prepared stream: read-back and start check, paced commands, safe stop on trouble.

    Args:
        link: The open link (a dry run does not read back: it prints the stream as planned).
        driver: The controller's driver.
        stream: From :func:`prepare_stream`.
        options: Start-check and approach choices.
        limits: Joint limits, for ``from_current``'s first move.
        clock: Monotonic time and sleep (default the real ones).

    Returns:
        The result; Ctrl-C (KeyboardInterrupt) or a port failure while streaming is an outcome
        (``INTERRUPTED``, ``LINK_ERROR``) after the servos are told to stop, not an exception.

    Raises:
        StartPositionError: If the arm is far from the first waypoint, or its position is
            unknown, and no way to get there was asked for; nothing was sent.
        ControllerError: If the controller does not answer the read-back.
    """
    options = options or SendOptions()
    clock = clock or Clock()
    start_q, kind, schedule, offset = _prelude(link, driver, stream, options, limits)
    schedule = [(t, c, None) for t, c in schedule]
    schedule += [(offset + k * stream.period, c, k) for k, c in enumerate(stream.commands)]
    sent, lateness, status, why = 0, 0.0, SendStatus.COMPLETED, ""
    try:
        if link.can_read:
            driver.begin(link)
        t0 = clock.now()
        for at, command, k in schedule:
            lateness = max(lateness, clock.wait_until(t0 + at))
            link.write(command)
            if k is not None:
                sent = k + 1
    except KeyboardInterrupt:
        status, why = SendStatus.INTERRUPTED, "interrupted (Ctrl-C)"
    except ControllerError as exc:
        status, why = SendStatus.LINK_ERROR, str(exc)
    stop = None
    if status is not SendStatus.COMPLETED:
        try:
            stop = driver.stop(link)
        except ControllerError as exc:
            stop = f"could not stop the servos: {exc}"
    duration = stream.trajectory.duration
    plan_time = min((sent - 1) * stream.period, duration) if sent else -1.0
    total = len(stream.commands)
    if status is SendStatus.COMPLETED:
        message = (
            f"sent {sent} of {total} commands: the whole plan ({duration:.3f} s); the latest left "
            f"{lateness * 1000:.1f} ms after its deadline"
        )
    else:
        reached = f"at t = {plan_time:.3f} s of {duration:.3f} s" if sent else f"before the {duration:.3f} s plan began"
        message = f"stopped {reached} (command {sent} of {total}): {why}; {stop}"
    return SendResult(status, sent, total, plan_time, duration, start_q, kind, stop, lateness, message)
