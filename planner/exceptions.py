"""Exceptions raised by `planner`.

Every error the library raises on bad input derives from :class:`PlannerError`, so a caller
can catch one class. An unreachable target is *not* an error: solvers return a result with a
status instead.
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = [
    "PlannerError",
    "URDFError",
    "InvalidLimitsError",
    "UnknownFrameError",
    "UnknownRobotError",
    "InvalidConfigurationError",
    "JointLimitError",
    "InvalidArgumentError",
    "UnsupportedChainError",
    "PlanningError",
    "ServoExportError",
    "ControllerError",
    "StartPositionError",
]


def _listing(choices: Iterable[str], most: int = 40) -> str:
    items = list(choices)
    shown = ", ".join(items[:most])
    if len(items) > most:
        shown += f", ... ({len(items) - most} more)"
    return shown


class PlannerError(Exception):
    """Root of every exception raised by `planner` for bad input or misuse."""


class URDFError(PlannerError):
    """The URDF text is malformed or describes something this library cannot model."""


class InvalidLimitsError(PlannerError):
    """A joint or motion limit is invalid (lower > upper, negative or zero speed, NaN).

    Attributes:
        joint: Name of the joint the limit belongs to, or None when it applies to all.
        value: The offending value.
    """

    def __init__(self, message: str, *, joint: str | None = None, value: object = None):
        super().__init__(message)
        self.joint = joint
        self.value = value


class UnknownFrameError(PlannerError):
    """A frame name does not exist in the model.

    Attributes:
        frame: The requested name.
        choices: The frame names that do exist.
    """

    def __init__(self, frame: str, choices: Iterable[str]):
        self.frame = frame
        self.choices = tuple(choices)
        super().__init__(f"unknown frame {frame!r}; valid frames: {_listing(self.choices)}")


class UnknownRobotError(PlannerError):
    """A robot name is neither bundled, nor an installed example-robot-data arm, nor a file.

    Attributes:
        name: The requested name.
        choices: The names that can be loaded on this machine.
    """

    def __init__(self, name: str, choices: Iterable[str], hint: str = ""):
        self.name = name
        self.choices = tuple(choices)
        message = f"unknown robot {name!r}; valid names: {_listing(self.choices)}"
        if hint:
            message += f" ({hint})"
        super().__init__(message)


class InvalidConfigurationError(PlannerError):
    """A joint configuration has the wrong shape or holds NaN or infinite values."""


class JointLimitError(PlannerError):
    """A joint value lies outside its position range.

    Attributes:
        joint: Joint name.
        value: The offending value [rad or m].
        lower: Lower limit [rad or m].
        upper: Upper limit [rad or m].
    """

    def __init__(self, joint: str, value: float, lower: float, upper: float, context: str = ""):
        self.joint = joint
        self.value = float(value)
        self.lower = float(lower)
        self.upper = float(upper)
        where = f"{context}: " if context else ""
        super().__init__(
            f"{where}joint {joint!r} value {self.value:.6g} is outside its range [{self.lower:.6g}, {self.upper:.6g}]"
        )


class InvalidArgumentError(PlannerError, ValueError):
    """An argument has an invalid value (NaN target, non-positive time budget, ...)."""


class TargetFileError(InvalidArgumentError):
    """A file of IK targets (``planner ik --batch``) cannot be read; the message names the place.

    Attributes:
        path: The file, or None.
        line: 1-based line of the file (the header is a line), or None.
        column: The column's name, or None.
    """

    def __init__(self, message: str, *, path: str | None = None, line: int | None = None, column: str | None = None):
        self.path = path
        self.line = line
        self.column = column
        where = ", ".join(
            part
            for part in (
                path,
                None if line is None else f"line {line}",
                None if column is None else f"column {column!r}",
            )
            if part
        )
        super().__init__(f"{where}: {message}" if where else message)


class UnsupportedChainError(PlannerError):
    """A kinematic chain is outside the family a solver handles.

    Attributes:
        joint: Name of the first joint that breaks the family, or None.
    """

    def __init__(self, message: str, *, joint: str | None = None):
        super().__init__(message)
        self.joint = joint


class PlanningError(PlannerError):
    """A valid request that the planner cannot turn into a motion; the message says what to change."""


class ServoExportError(PlannerError):
    """Servo files could not be made for a plan; the plan's other files were written.

    Attributes:
        failures: Per servo format name, the reason (naming the joint and the fix).
        written: The files that were written.
    """

    def __init__(self, failures: dict[str, str], written: tuple = ()):
        self.failures = dict(failures)
        self.written = tuple(written)
        lines = [f"{name}: {reason}" for name, reason in self.failures.items()]
        done = ", ".join(str(p) for p in self.written) or "nothing"
        super().__init__(
            "servo files not written (" + "; ".join(lines) + f"); written: {done}. Give the joint a calibration "
            "that covers its travel (a plan file's `servos:` entry: pulse_at_zero, us_per_deg, min_pulse, max_pulse)"
        )


class ControllerError(PlannerError):
    """A servo controller or its serial port failed, answered wrongly, or cannot carry a stream."""


class StartPositionError(ControllerError):
    """The arm is not at the plan's first waypoint (or cannot say where it is): nothing was sent.

    Attributes:
        joint: The joint furthest from its first-waypoint value, or None when the position is unknown.
        value: Its read angle [rad] (NaN when unknown).
        expected: Its first-waypoint angle [rad].
    """

    def __init__(self, message: str, *, joint: str | None = None, value: float = float("nan"), expected: float = 0.0):
        super().__init__(message)
        self.joint = joint
        self.value = value
        self.expected = expected
