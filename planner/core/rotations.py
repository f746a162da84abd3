"""Rotations: roll-pitch-yaw, quaternions and the angle between two orientations, via Pinocchio.

One copy of each conversion for the whole package; Pinocchio (``pin.rpy``, ``pin.Quaternion``)
does the arithmetic, this module adds input checks that name the bad value.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from planner.exceptions import InvalidArgumentError

__all__ = [
    "check_rotation",
    "finite_vector",
    "homogeneous",
    "matrix_to_rpy",
    "quaternion_to_matrix",
    "rotation_error",
    "rpy_to_matrix",
    "unit_quaternions",
]

#: Largest |R^T R - I| entry accepted for a rotation matrix.
ORTHONORMAL_TOL = 1e-6


def finite_vector(value: Sequence[float] | np.ndarray, n: int, what: str) -> np.ndarray:
    """A float copy of ``value`` checked to hold ``n`` finite numbers.

    Raises:
        InvalidArgumentError: Naming ``what`` and the offending value.
    """
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
    r, p, y = finite_vector(rpy, 3, "rpy")
    return np.array(pin.rpy.rpyToMatrix(r, p, y))


def homogeneous(rotation: np.ndarray, position: Sequence[float] | np.ndarray) -> np.ndarray:
    """The 4x4 homogeneous transform of a rotation (3, 3) and a translation (3,) [m]."""
    return np.array(pin.SE3(np.asarray(rotation, dtype=float), np.asarray(position, dtype=float)).homogeneous)


def matrix_to_rpy(rotation: np.ndarray) -> np.ndarray:
    """URDF roll-pitch-yaw angles (3,) [rad] of a rotation matrix (pitch in [-pi/2, pi/2])."""
    return np.array(pin.rpy.matrixToRpy(np.asarray(rotation, dtype=float)))


def quaternion_to_matrix(quaternion: Sequence[float] | np.ndarray) -> np.ndarray:
    """Rotation matrix of a quaternion ``(x, y, z, w)``; it is normalised first.

    Raises:
        InvalidArgumentError: If the quaternion is NaN or has (near) zero norm.
    """
    arr = finite_vector(quaternion, 4, "quaternion (x, y, z, w)")
    unit, zero = unit_quaternions(arr[None])
    if zero[0]:
        raise InvalidArgumentError(f"quaternion (x, y, z, w) has zero norm: {arr.tolist()}")
    x, y, z, w = unit[0]
    return np.array(pin.Quaternion(w, x, y, z).normalized().matrix())


def unit_quaternions(xyzw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Finite quaternions (N, 4) scaled to unit norm, and which of them have (near) zero norm.

    Each is divided by its largest component before its norm is taken: the squares of
    components past 1e154 overflow (and Pinocchio would then normalise to the identity).

    Returns:
        ``(unit, zero)``: the unit quaternions (N, 4) (rows of zero norm are not meaningful) and
        a boolean mask (N,) of those whose norm is below 1e-12.
    """
    largest = np.max(np.abs(xyzw), axis=1)
    scaled = xyzw / np.where(largest > 0, largest, 1.0)[:, None]
    norm = np.linalg.norm(scaled, axis=1)
    with np.errstate(over="ignore"):  # a norm past 1e308 is inf: not zero
        zero = largest * norm < 1e-12
    return scaled / np.where(zero, 1.0, norm)[:, None], zero


def check_rotation(rotation: Sequence[Sequence[float]] | np.ndarray) -> np.ndarray:
    """A float copy of a proper rotation matrix (orthonormal within 1e-6, det +1).

    Raises:
        InvalidArgumentError: If it is not a 3x3 finite proper rotation (the message gives the
            deviation and the determinant).
    """
    try:
        rot = np.array(rotation, dtype=float, copy=True)
    except (TypeError, ValueError) as exc:
        raise InvalidArgumentError(f"rotation must be a 3x3 matrix, got {rotation!r}") from exc
    if rot.shape != (3, 3):
        raise InvalidArgumentError(f"rotation must have shape (3, 3), got {rot.shape}")
    if not np.all(np.isfinite(rot)):
        raise InvalidArgumentError("rotation holds NaN or infinite values")
    deviation = float(np.max(np.abs(rot.T @ rot - np.eye(3))))
    if deviation > ORTHONORMAL_TOL or np.linalg.det(rot) < 0:
        raise InvalidArgumentError(
            f"rotation is not a proper orthonormal matrix (|R^T R - I| = {deviation:.3g}, "
            f"det = {np.linalg.det(rot):.6g}); give a rotation matrix, rpy or a quaternion"
        )
    return rot


def rotation_error(rotation_a: np.ndarray, rotation_b: np.ndarray) -> np.ndarray | float:
    """Angle of the rotation between two orientations [rad], in [0, pi].

    For single matrices this is ``|pin.log3(A^T B)|``; batches use the same formula on arrays.

    Args:
        rotation_a: Shape (3, 3) or (N, 3, 3).
        rotation_b: Shape (3, 3) or (N, 3, 3).

    Returns:
        A float, or shape (N,) for batches.
    """
    rel = np.swapaxes(rotation_a, -1, -2) @ rotation_b
    if rel.shape == (3, 3):  # the common single case without array temporaries
        cos = 0.5 * (rel[0, 0] + rel[1, 1] + rel[2, 2] - 1.0)
        sin = 0.5 * math.sqrt(
            (rel[2, 1] - rel[1, 2]) ** 2 + (rel[0, 2] - rel[2, 0]) ** 2 + (rel[1, 0] - rel[0, 1]) ** 2
        )
        return math.atan2(sin, min(1.0, max(-1.0, float(cos))))
    cos = (np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0
    # arccos loses precision near 0; the antisymmetric part keeps small angles accurate.
    skew = np.stack(
        [rel[..., 2, 1] - rel[..., 1, 2], rel[..., 0, 2] - rel[..., 2, 0], rel[..., 1, 0] - rel[..., 0, 1]], axis=-1
    )
    sin = np.linalg.norm(skew, axis=-1) / 2.0
    angle = np.arctan2(sin, np.clip(cos, -1.0, 1.0))
    return float(angle) if np.ndim(angle) == 0 else angle
