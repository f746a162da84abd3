"""Values users read: numbers as a user typed them, never ``np.float64(...)`` or ``-0.0``."""

from __future__ import annotations

import json
from typing import Any

import numpy as np

__all__ = ["plain", "to_json"]


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


def to_json(value: Any) -> str:
    """Indented JSON of plain data; NumPy values become Python numbers, ``-0.0`` becomes ``0.0``.

    Raises:
        ValueError: If a number is NaN or infinite (JSON has none).
    """
    return json.dumps(_json_ready(value), indent=2, allow_nan=False)


def _json_ready(value: Any) -> Any:
    value = _python(value)
    if isinstance(value, float):
        return value + 0.0  # -0.0 + 0.0 is 0.0
    if isinstance(value, dict):
        return {k: _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    return value
