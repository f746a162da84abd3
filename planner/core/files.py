"""Reading the project's YAML/JSON input files (arm descriptions, plan files) and their values.

The value readers check what a file gave (a number, a list of numbers, a unit name) and
name the offending key and value in an :class:`InvalidArgumentError`, prefixed with where the
input came from when a `source` is given.
"""

from __future__ import annotations

import functools
import json
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from planner.core.text import plain
from planner.core.units import ANGLE_UNITS, LENGTH_UNITS
from planner.exceptions import InvalidArgumentError, PlannerError

__all__ = [
    "input_error",
    "parse_number",
    "parse_numbers",
    "parse_units",
    "positive_number",
    "read_data_file",
    "read_text_file",
]


def positive_number(value: Any, what: str) -> float:
    """`value` as a positive finite float.

    Raises:
        InvalidArgumentError: If it is not a number (booleans are not), or not positive and finite.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InvalidArgumentError(f"{what} must be a number, got {plain(value)}")
    x = float(value)
    if not (math.isfinite(x) and x > 0):
        raise InvalidArgumentError(f"{what} must be positive and finite, got {plain(value)}")
    return x


def read_text_file(path: str | Path, what: str, error: type[PlannerError] = InvalidArgumentError) -> str:
    """A UTF-8 text file's text, without a leading byte-order mark (Windows editors write one).

    Args:
        path: The file.
        what: What the file is, for messages (e.g. ``"URDF file"``).
        error: The error raised.

    Raises:
        PlannerError: `error`, if the file cannot be read or is not UTF-8 text.
    """
    p = Path(path)
    try:
        return p.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise error(f"cannot read {what} {str(p)!r}: {exc.strerror}") from exc
    except UnicodeDecodeError as exc:
        raise error(
            f"cannot read {what} {str(p)!r}: not UTF-8 text (byte {exc.object[exc.start]:#04x} at offset {exc.start})"
        ) from exc


def read_data_file(path: str | Path, what: str) -> Any:
    """Parse a file as JSON (``.json``) or YAML (anything else).

    Args:
        path: The file.
        what: What the file is, for messages (e.g. ``"plan file"``).

    Returns:
        The parsed data.

    Raises:
        InvalidArgumentError: If the file cannot be read or does not parse.
    """
    p = Path(path)
    text = read_text_file(p, what)
    try:
        if p.suffix.lower() == ".json":
            return json.loads(text)
        import yaml

        return yaml.load(text, Loader=_yaml_loader())  # noqa: S506 - a SafeLoader subclass
    except Exception as exc:  # yaml and json raise several unrelated types
        raise InvalidArgumentError(f"cannot parse {what} {str(p)!r}: {_one_line(exc)}") from exc


@functools.cache
def _yaml_loader() -> type:
    """PyYAML's safe loader that also reads ``1e-3`` and ``2E5`` as numbers (YAML 1.2 floats).

    PyYAML follows YAML 1.1, whose floats need a dot (``1.0e-3``): ``velocity: 1e3`` came back
    as the string ``'1e3'`` and was refused as "must be a number".
    """
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    exponent = re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9][0-9_]*)[eE][-+]?[0-9]+$")
    Loader.add_implicit_resolver("tag:yaml.org,2002:float", exponent, list("-+0123456789."))
    return Loader


def _one_line(exc: Exception) -> str:
    """A parser's error in one line: YAML's problem and where, without its quoted excerpt."""
    problem, mark = getattr(exc, "problem", None), getattr(exc, "problem_mark", None)
    if problem and mark is not None:
        return f"{problem} at line {mark.line + 1}, column {mark.column + 1}"
    return " ".join(str(exc).split())


def input_error(source: str | None, message: str) -> InvalidArgumentError:
    """The error for a bad input value, its message prefixed with ``"<source>: "`` when given.

    Args:
        source: Where the input came from (a file name, ``"<request>"``), or None.
        message: What is wrong, naming the key and the value.

    Returns:
        The error, for the caller to raise.
    """
    return InvalidArgumentError(f"{source}: {message}" if source else message)


def parse_number(value: Any, what: str, source: str | None = None) -> float:
    """A finite number from an input file (a bool is not a number).

    Args:
        value: The value as read.
        what: The key, for messages (e.g. ``"targets[2].pitch"``).
        source: Where the input came from, for messages, or None.

    Returns:
        The value as a float.

    Raises:
        InvalidArgumentError: If it is not an int or float, or not finite.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise input_error(source, f"{what} must be a number, got {plain(value)}")
    x = float(value)
    if not math.isfinite(x):
        raise input_error(source, f"{what} must be finite, got {plain(value)}")
    return x


def parse_numbers(value: Any, what: str, source: str | None = None, length: int | None = None) -> np.ndarray:
    """A list of finite numbers from an input file (see :func:`parse_number`).

    Args:
        value: The value as read: a list (not a string or a mapping).
        what: The key, for messages; an element is named ``what[k]``.
        source: Where the input came from, for messages, or None.
        length: The number of values required, or None for any.

    Returns:
        The values, shape (n,) float.

    Raises:
        InvalidArgumentError: If it is not a list, an element is not a finite number, or the
            length differs from `length`.
    """
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Sequence):
        raise input_error(source, f"{what} must be a list of numbers, got {plain(value)}")
    arr = np.array([parse_number(v, f"{what}[{k}]", source) for k, v in enumerate(value)], dtype=float)
    if length is not None and arr.shape != (length,):
        raise input_error(source, f"{what} must have {length} numbers, got {len(arr)}")
    return arr


def parse_units(length: Any = "m", angle: Any = "rad", source: str | None = None) -> tuple[float, float]:
    """The scales of the length and angle units an input file declares.

    Args:
        length: Length unit name, one of :data:`planner.core.units.LENGTH_UNITS`.
        angle: Angle unit name, one of :data:`planner.core.units.ANGLE_UNITS`.
        source: Where the input came from, for messages, or None.

    Returns:
        ``(metres per length unit, radians per angle unit)``.

    Raises:
        InvalidArgumentError: For an unknown unit (the message lists the valid ones).
    """
    if not isinstance(length, str) or length not in LENGTH_UNITS:
        raise input_error(source, f"unknown length unit {length!r}; valid units: {', '.join(LENGTH_UNITS)}")
    if not isinstance(angle, str) or angle not in ANGLE_UNITS:
        raise input_error(source, f"unknown angle unit {angle!r}; valid units: {', '.join(ANGLE_UNITS)}")
    return LENGTH_UNITS[length], ANGLE_UNITS[angle]
