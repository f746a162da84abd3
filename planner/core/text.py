"""Values in messages: numbers as a user typed them, never ``np.float64(...)``."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["plain"]


def plain(value: Any) -> str:
    """``repr`` of a value with NumPy scalars and arrays shown as plain Python numbers and lists."""
    return repr(_python(value))


def _python(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return type(value)(_python(v) for v in value)
    return value
