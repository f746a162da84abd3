"""Arrays from callers: frozen copies of results and stored limits, floats checked to be numbers."""

from __future__ import annotations

from typing import Any

import numpy as np

from planner.core.text import plain
from planner.exceptions import InvalidArgumentError

__all__ = ["float_array", "read_only"]


def float_array(value: Any, what: str, expected: str = "a number or an array of numbers") -> np.ndarray:
    """``np.asarray(value, dtype=float)``, or an error naming `what` when it holds no numbers.

    Args:
        value: Any array-like.
        what: What the value is, for the message (e.g. ``"pose"``).
        expected: What it must be, for the message.

    Raises:
        InvalidArgumentError: If NumPy cannot read `value` as floats (a string, a ragged list):
            "<what> must be <expected>, got <value>".
    """
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidArgumentError(f"{what} must be {expected}, got {plain(value)}") from exc


def read_only(value: np.ndarray, dtype: type | None = float) -> np.ndarray:
    """A frozen copy of an array.

    Args:
        value: Any array-like.
        dtype: The copy's dtype (default float); None keeps the input's.

    Returns:
        A new array with ``writeable`` False, sharing no memory with ``value``.
    """
    out = np.array(value, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out
