"""IK targets: a tip position, optionally with a full orientation or an approach pitch.

Orientation conventions used across `planner`:

- ``rotation`` is the tip frame's 3x3 rotation matrix in the base frame.
- ``rpy`` is URDF roll-pitch-yaw [rad]: ``R = Rz(yaw) Ry(pitch) Rx(roll)``.
- A quaternion is given as ``(x, y, z, w)`` (the ROS / SciPy order).
- ``pitch`` is the *approach pitch* [rad] of the tip's approach axis (see
  ``Robot.approach_axis``): the axis lies in the vertical plane through the base z axis and
  the target, at angle `pitch` from the horizontal, 0 pointing radially away from the base
  axis, +pi/2 straight up, -pi/2 straight down (the 001 seed's parallel and straight-down
  approaches are 0 and -pi/2). Where the target lies on the base axis the radial direction is
  the one of the arm's yaw.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .exceptions import InvalidArgumentError

__all__ = [
    "Target",
    "approach_direction",
    "rotation_error",
    "rpy_to_matrix",
    "quaternion_to_matrix",
]

_ORTHONORMAL_TOL = 1e-6


def _finite_vector(value: Sequence[float] | np.ndarray, n: int, what: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float, copy=True)
    except (TypeError, ValueError) as exc:
        raise InvalidArgumentError(f"{what} must be {n} numbers, got {value!r}") from exc
    if arr.shape != (n,):
        raise InvalidArgumentError(f"{what} must have shape ({n},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InvalidArgumentError(f"{what} must be finite, got {arr.tolist()}")
    return arr


def rpy_to_matrix(rpy: Sequence[float] | np.ndarray) -> np.ndarray:
    """Rotation matrix of URDF roll-pitch-yaw angles ``R = Rz(y) Ry(p) Rx(r)`` [rad]."""
    r, p, y = _finite_vector(rpy, 3, "rpy")
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def quaternion_to_matrix(quaternion: Sequence[float] | np.ndarray) -> np.ndarray:
    """Rotation matrix of a quaternion ``(x, y, z, w)``; it is normalised first.

    Raises:
        InvalidArgumentError: If the quaternion is NaN or has (near) zero norm.
    """
    q = _finite_vector(quaternion, 4, "quaternion (x, y, z, w)")
    norm = float(np.linalg.norm(q))
    if norm < 1e-12:
        raise InvalidArgumentError(f"quaternion (x, y, z, w) has zero norm: {q.tolist()}")
    x, y, z, w = q / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _check_rotation(rotation: Sequence[Sequence[float]] | np.ndarray) -> np.ndarray:
    try:
        rot = np.array(rotation, dtype=float, copy=True)
    except (TypeError, ValueError) as exc:
        raise InvalidArgumentError(f"rotation must be a 3x3 matrix, got {rotation!r}") from exc
    if rot.shape != (3, 3):
        raise InvalidArgumentError(f"rotation must have shape (3, 3), got {rot.shape}")
    if not np.all(np.isfinite(rot)):
        raise InvalidArgumentError("rotation holds NaN or infinite values")
    deviation = float(np.max(np.abs(rot.T @ rot - np.eye(3))))
    if deviation > _ORTHONORMAL_TOL or np.linalg.det(rot) < 0:
        raise InvalidArgumentError(
            f"rotation is not a proper orthonormal matrix (|R^T R - I| = {deviation:.3g}, "
            f"det = {np.linalg.det(rot):.6g}); give a rotation matrix, rpy or a quaternion"
        )
    return rot


def rotation_error(rotation_a: np.ndarray, rotation_b: np.ndarray) -> np.ndarray | float:
    """Angle of the rotation between two orientations [rad], in [0, pi].

    Args:
        rotation_a: Shape (3, 3) or (N, 3, 3).
        rotation_b: Shape (3, 3) or (N, 3, 3).

    Returns:
        A float, or shape (N,) for batches.
    """
    rel = np.swapaxes(rotation_a, -1, -2) @ rotation_b
    cos = (np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0
    # arccos loses precision near 0; the antisymmetric part keeps small angles accurate.
    skew = np.stack(
        [rel[..., 2, 1] - rel[..., 1, 2], rel[..., 0, 2] - rel[..., 2, 0], rel[..., 1, 0] - rel[..., 0, 1]], axis=-1
    )
    sin = np.linalg.norm(skew, axis=-1) / 2.0
    angle = np.arctan2(sin, np.clip(cos, -1.0, 1.0))
    return float(angle) if np.ndim(angle) == 0 else angle


def approach_direction(position: np.ndarray, pitch: float, yaw: float | None = None) -> np.ndarray:
    """Unit approach direction for an approach pitch at a target position (base frame).

    Args:
        position: Target position, shape (3,) [m].
        pitch: Approach pitch [rad] (see the module docstring).
        yaw: Direction of the radial axis [rad] when the target lies on the base z axis;
            None uses 0 there.

    Returns:
        Shape (3,) unit vector.
    """
    radial = math.hypot(position[0], position[1])
    if radial > 1e-12:
        cy, sy = position[0] / radial, position[1] / radial
    else:
        a = 0.0 if yaw is None else yaw
        cy, sy = math.cos(a), math.sin(a)
    return np.array([math.cos(pitch) * cy, math.cos(pitch) * sy, math.sin(pitch)])


@dataclass(frozen=True)
class Target:
    """Where the tip should go.

    Attributes:
        position: Tip position in the base frame, shape (3,) [m], read-only.
        rotation: Tip orientation in the base frame, shape (3, 3), or None for position only.
        pitch: Approach pitch [rad] (see the module docstring), or None.
    """

    position: np.ndarray
    rotation: np.ndarray | None = None
    pitch: float | None = None

    def __post_init__(self) -> None:
        pos = _finite_vector(self.position, 3, "target position")
        pos.setflags(write=False)
        object.__setattr__(self, "position", pos)
        if self.rotation is not None and self.pitch is not None:
            raise InvalidArgumentError("give either a rotation or an approach pitch, not both")
        if self.rotation is not None:
            rot = _check_rotation(self.rotation)
            rot.setflags(write=False)
            object.__setattr__(self, "rotation", rot)
        if self.pitch is not None:
            if isinstance(self.pitch, bool) or not isinstance(self.pitch, (int, float, np.floating, np.integer)):
                raise InvalidArgumentError(f"pitch must be a number [rad], got {self.pitch!r}")
            if not math.isfinite(self.pitch):
                raise InvalidArgumentError(f"pitch must be finite, got {self.pitch!r}")
            object.__setattr__(self, "pitch", float(self.pitch))

    @classmethod
    def from_rpy(cls, position: Sequence[float], rpy: Sequence[float]) -> Target:
        """Target from a position [m] and URDF roll-pitch-yaw [rad]."""
        return cls(position, rotation=rpy_to_matrix(rpy))

    @classmethod
    def from_quaternion(cls, position: Sequence[float], quaternion: Sequence[float]) -> Target:
        """Target from a position [m] and a quaternion ``(x, y, z, w)``."""
        return cls(position, rotation=quaternion_to_matrix(quaternion))

    @classmethod
    def from_pose(cls, pose: np.ndarray) -> Target:
        """Target from a 4x4 homogeneous transform [m]."""
        arr = np.asarray(pose, dtype=float)
        if arr.shape != (4, 4):
            raise InvalidArgumentError(f"pose must have shape (4, 4), got {arr.shape}")
        return cls(arr[:3, 3], rotation=arr[:3, :3])

    @property
    def kind(self) -> str:
        """``"pose"``, ``"pitch"`` or ``"position"``."""
        if self.rotation is not None:
            return "pose"
        return "pitch" if self.pitch is not None else "position"
