"""Read-only arrays: results and stored limits are frozen copies, never views of caller data."""

from __future__ import annotations

import numpy as np

__all__ = ["read_only"]


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
