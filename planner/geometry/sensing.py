"""Sensor readings turned into targets in the arm's base frame."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from planner.core.arrays import float_array
from planner.core.rotations import check_rotation, homogeneous, rpy_to_matrix
from planner.core.text import plain
from planner.exceptions import InvalidArgumentError

__all__ = ["range_bearing_to_base"]


def _pose_matrix(sensor_pose: Sequence[float] | np.ndarray) -> np.ndarray:
    """The sensor pose as a 4x4 transform in the base frame [m]."""
    arr = float_array(sensor_pose, "sensor_pose")
    if arr.shape == (4, 4):
        if not np.all(np.isfinite(arr)):
            raise InvalidArgumentError("sensor_pose holds NaN or infinite values")
        try:
            check_rotation(arr[:3, :3])
        except InvalidArgumentError as exc:
            raise InvalidArgumentError(f"sensor_pose is not a rigid transform: {exc}") from None
        if not np.allclose(arr[3], [0, 0, 0, 1]):
            raise InvalidArgumentError(f"sensor_pose is not a rigid transform: last row {arr[3].tolist()}")
        return arr
    if arr.shape in ((3,), (4,)):
        if not np.all(np.isfinite(arr)):
            raise InvalidArgumentError(f"sensor_pose holds NaN or infinite values: {arr.tolist()}")
        yaw = arr[3] if arr.shape == (4,) else 0.0
        return homogeneous(rpy_to_matrix((0.0, 0.0, yaw)), arr[:3])
    raise InvalidArgumentError(
        f"sensor_pose must be a 4x4 transform, (x, y, z) or (x, y, z, yaw); got shape {arr.shape}"
    )


def range_bearing_to_base(
    distance: float | np.ndarray,
    bearing: float | np.ndarray,
    sensor_pose: Sequence[float] | np.ndarray,
) -> np.ndarray:
    """The point a range-bearing sensor sees, in the arm's base frame.

    The sensor measures in its own horizontal plane: bearing 0 along its x axis, positive
    toward its y axis, so it sees the point ``(d cos(bearing), d sin(bearing), 0)`` in its frame
    (Clothier and Shang's (2010) equation 5); the sensor's pose in the base frame then moves that point
    into the base frame (the seed's equation 6, with the mount offsets as a pose).

    Args:
        distance: Range reading(s) [m], >= 0; scalar or shape (N,).
        bearing: Bearing reading(s) [rad]; scalar or shape (N,).
        sensor_pose: Sensor frame in the base frame: a 4x4 transform, or ``(x, y, z)``, or
            ``(x, y, z, yaw)`` [m, rad] for a sensor turned about the vertical.

    Returns:
        The point(s) in the base frame, shape (3,) or (N, 3) [m].

    Raises:
        InvalidArgumentError: On NaN, a negative distance, or a malformed pose.
    """
    d = float_array(distance, "distance")
    b = float_array(bearing, "bearing")
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(b))):
        raise InvalidArgumentError(f"distance and bearing must be finite, got {plain(distance)}, {plain(bearing)}")
    if np.any(d < 0):
        raise InvalidArgumentError(f"distance must be >= 0, got {plain(distance)}")
    pose = _pose_matrix(sensor_pose)
    d, b = np.broadcast_arrays(d, b)
    local = np.stack([d * np.cos(b), d * np.sin(b), np.zeros_like(d)], axis=-1)
    return local @ pose[:3, :3].T + pose[:3, 3]
