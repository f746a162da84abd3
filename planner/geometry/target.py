"""IK targets: a tip position, optionally with a full orientation or an approach pitch.

Orientation conventions used across `planner`:

- ``rotation`` is the tip frame's 3x3 rotation matrix in the base frame.
- ``rpy`` is URDF roll-pitch-yaw [rad]: ``R = Rz(yaw) Ry(pitch) Rx(roll)``.
- A quaternion is given as ``(x, y, z, w)`` (the ROS / SciPy order).
- ``pitch`` is the *approach pitch* [rad] of the tip's approach axis ``a`` (see
  ``Robot.approach_axis``, in base-frame coordinates): its elevation above the horizontal,
  ``a_z = sin(pitch)``, with its horizontal part pointing away from the base z axis, i.e. a
  non-negative dot product with the radial direction from the base z axis to the target (for
  ``|pitch| > pi/2``: towards it; ``cos(pitch)`` gives the side). So 0 is horizontal and
  outward, +pi/2 straight up, -pi/2 straight down (Clothier and Shang's (2010) parallel and straight-down
  approaches are 0 and -pi/2). Which way the horizontal part points within that half plane is
  left to the arm: for an arm whose pitch plane contains the base z axis it is the radial
  direction itself (:func:`approach_direction`); an arm whose plane passes beside the axis
  (SO-101) or whose yaw axis is not the base z axis points it along its own plane. Where the
  target lies on the base z axis only the elevation counts.

:func:`approach_pitch` measures the approach pitch of a configuration, :func:`pitch_error` how
far an approach axis is from a target pitch (the orientation error of a pitch target, used by
every solver and the tests).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planner.core.arrays import float_array
from planner.core.rotations import check_rotation, finite_vector, quaternion_to_matrix, rpy_to_matrix
from planner.core.text import plain
from planner.exceptions import InvalidArgumentError
from planner.model.robot import Robot

__all__ = [
    "Target",
    "as_target",
    "target_errors",
    "tip_errors",
    "approach_direction",
    "approach_pitch",
    "pitch_error",
    "pitch_error_scalar",
]

#: Targets closer than this to the base z axis [m] have no radial direction: only the
#: elevation of the approach axis counts there.
RADIAL_EPS = 1e-12


def approach_direction(position: np.ndarray, pitch: float, yaw: float | None = None) -> np.ndarray:
    """The approach direction of a pitch in the vertical plane through the base z axis and the target.

    For an arm whose pitch plane contains the base z axis (al5c, three_joint) this is the one
    direction with approach pitch `pitch` that it can take at `position`; in general it is one
    of many (see the module docstring).

    Args:
        position: Target position, shape (3,) [m].
        pitch: Approach pitch [rad].
        yaw: Direction of the radial axis [rad] when the target lies on the base z axis;
            None uses 0 there.

    Returns:
        Shape (3,) unit vector (base frame).
    """
    radial = math.hypot(position[0], position[1])
    if radial > RADIAL_EPS:
        cy, sy = position[0] / radial, position[1] / radial
    else:
        a = 0.0 if yaw is None else yaw
        cy, sy = math.cos(a), math.sin(a)
    return np.array([math.cos(pitch) * cy, math.cos(pitch) * sy, math.sin(pitch)])


def approach_pitch(robot, q: Sequence[float] | np.ndarray) -> float | np.ndarray:
    """The approach pitch [rad] of a configuration (the module docstring's convention).

    ``atan2(a_z, +-|a_h|)`` of the approach axis ``a`` at FK(q), its horizontal part ``a_h``
    counted positive when it points away from the base z axis (or when the tip is on that
    axis), so ``Target(tip position, pitch=approach_pitch(robot, q))`` is reached by q.

    Args:
        robot: A :class:`~planner.model.robot.Robot`.
        q: Shape (dof,) or (N, dof) [rad or m].

    Returns:
        A float in (-pi, pi], or shape (N,).
    """
    pose = np.asarray(robot.fk(q))
    a = pose[..., :3, :3] @ np.asarray(robot.approach_axis, dtype=float)
    p = pose[..., :3, 3]
    horizontal = np.hypot(a[..., 0], a[..., 1])
    inward = (np.hypot(p[..., 0], p[..., 1]) > RADIAL_EPS) & (a[..., 0] * p[..., 0] + a[..., 1] * p[..., 1] < 0.0)
    pitch = np.arctan2(a[..., 2], np.where(inward, -horizontal, horizontal))
    return float(pitch) if np.ndim(pitch) == 0 else pitch


def pitch_error_scalar(
    ax: float, ay: float, az: float, px: float, py: float, cos_p: float, sin_p: float, elevation: float
) -> float:
    """:func:`pitch_error` [rad] of one approach axis, in scalar arithmetic (no NumPy per call).

    The pitch is given by its cosine, sine and elevation ``atan2(sin, |cos|)`` (callers with many
    axes compute them once).

    Args:
        ax: Approach axis x component (unit axis in the base frame).
        ay: Approach axis y component.
        az: Approach axis z component.
        px: Target position x [m].
        py: Target position y [m].
        cos_p: Cosine of the target's approach pitch.
        sin_p: Sine of the target's approach pitch.
        elevation: ``atan2(sin_p, |cos_p|)`` [rad].

    Returns:
        The error in [0, pi].
    """
    error = abs(math.atan2(az, math.hypot(ax, ay)) - elevation)
    if cos_p * (ax * px + ay * py) < 0.0 and (radial := math.hypot(px, py)) > RADIAL_EPS:
        # The horizontal part points to the wrong side: the nearest allowed direction has its
        # horizontal part perpendicular to the radial direction, on the side of a's.
        tx, ty = -py / radial, px / radial
        if ax * tx + ay * ty < 0.0:
            tx, ty = -tx, -ty
        bx, by, bz = abs(cos_p) * tx, abs(cos_p) * ty, sin_p
        cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        error = math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz), ax * bx + ay * by + az * bz)
    return error


def pitch_error(
    approach: Sequence[float] | np.ndarray, position: Sequence[float] | np.ndarray, pitch: float | np.ndarray
) -> float | np.ndarray:
    """Orientation error [rad] of an approach axis for a pitch target.

    The angle between `approach` and the nearest direction that has approach pitch `pitch` at
    `position` (module docstring): ``|elevation - pitch's elevation|`` when the horizontal part
    points to the right side (away from the base z axis for ``|pitch| < pi/2``), else the angle
    to the nearest direction of that elevation whose horizontal part is perpendicular to the
    radial direction. 0 exactly when the approach axis satisfies the convention; continuous.

    Args:
        approach: Approach axis in the base frame, unit, shape (3,) or (N, 3).
        position: Target position, shape (3,) or (N, 3) [m].
        pitch: Target approach pitch [rad], a scalar or shape (N,).

    Returns:
        A float in [0, pi], or shape (N,) for batches.
    """
    a = np.asarray(approach, dtype=float)
    p = np.asarray(position, dtype=float)
    if a.ndim == 1 and p.ndim == 1 and np.ndim(pitch) == 0:
        cos_p, sin_p = math.cos(pitch), math.sin(pitch)
        return pitch_error_scalar(
            float(a[0]), float(a[1]), float(a[2]), float(p[0]), float(p[1]), cos_p, sin_p, math.atan2(sin_p, abs(cos_p))
        )
    pitch = np.asarray(pitch, dtype=float)
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    px, py = p[..., 0], p[..., 1]
    cos_p, sin_p = np.cos(pitch), np.sin(pitch)
    error = np.abs(np.arctan2(az, np.hypot(ax, ay)) - np.arctan2(sin_p, np.abs(cos_p)))
    radial = np.hypot(px, py)
    wrong = (radial > RADIAL_EPS) & (cos_p * (ax * px + ay * py) < 0.0)
    if np.any(wrong):
        safe = np.where(radial > RADIAL_EPS, radial, 1.0)
        tx, ty = -py / safe, px / safe
        side = np.where(ax * tx + ay * ty < 0.0, -1.0, 1.0)
        bx, by, bz = np.abs(cos_p) * side * tx, np.abs(cos_p) * side * ty, sin_p
        cross = np.stack(np.broadcast_arrays(ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx), axis=-1)
        to_edge = np.arctan2(np.linalg.norm(cross, axis=-1), ax * bx + ay * by + az * bz)
        error = np.where(wrong, to_edge, error)
    return float(error) if np.ndim(error) == 0 else error


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
        pos = finite_vector(self.position, 3, "target position")
        pos.setflags(write=False)
        object.__setattr__(self, "position", pos)
        if self.rotation is not None and self.pitch is not None:
            raise InvalidArgumentError("give either a rotation or an approach pitch, not both")
        if self.rotation is not None:
            rot = check_rotation(self.rotation)
            rot.setflags(write=False)
            object.__setattr__(self, "rotation", rot)
        if self.pitch is not None:
            if isinstance(self.pitch, bool) or not isinstance(self.pitch, (int, float, np.floating, np.integer)):
                raise InvalidArgumentError(f"pitch must be a number [rad], got {plain(self.pitch)}")
            if not math.isfinite(self.pitch):
                raise InvalidArgumentError(f"pitch must be finite, got {plain(self.pitch)}")
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
        arr = float_array(pose, "pose", "a 4x4 array of numbers")
        if arr.shape != (4, 4):
            raise InvalidArgumentError(f"pose must have shape (4, 4), got {arr.shape}")
        return cls(arr[:3, 3], rotation=arr[:3, :3])

    @property
    def kind(self) -> str:
        """``"pose"``, ``"pitch"`` or ``"position"``."""
        if self.rotation is not None:
            return "pose"
        return "pitch" if self.pitch is not None else "position"


def as_target(target: Target | Sequence[float] | np.ndarray) -> Target:
    """A :class:`Target` from a Target, a position (3,) [m] or a homogeneous pose (4, 4) [m].

    Raises:
        InvalidArgumentError: For another shape, NaN or infinite values, or a rotation that is
            not orthonormal (the :class:`Target` checks).
    """
    if isinstance(target, Target):
        return target
    arr = float_array(target, "target", "a planner.Target, a position (3,) or a pose (4, 4)")
    if arr.shape == (3,):
        return Target(arr)
    if arr.shape == (4, 4):
        return Target.from_pose(arr)
    raise InvalidArgumentError(
        f"target must be a planner.Target, a position (3,) or a pose (4, 4), got shape {arr.shape}"
    )


def tip_errors(
    target: Target, position: np.ndarray, rotation: np.ndarray, approach_axis: np.ndarray
) -> tuple[float, float]:
    """Position [m] and orientation [rad] errors of a tip pose (see :func:`target_errors`)."""
    (x, y, z), (tx, ty, tz) = position.tolist(), target.position.tolist()
    position_error = math.hypot(x - tx, y - ty, z - tz)
    if target.rotation is not None:
        # rotation_error's formula (atan2 of the antisymmetric part and the trace of R^T R_target,
        # accurate near 0) on Python floats: a third of the time of indexing the array.
        # (ndarray.dot: half the time of the @ operator on 3x3 arrays.)
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation.T.dot(target.rotation).ravel().tolist()
        cos = 0.5 * (r00 + r11 + r22 - 1.0)
        sin = 0.5 * math.sqrt((r21 - r12) ** 2 + (r02 - r20) ** 2 + (r10 - r01) ** 2)
        return position_error, math.atan2(sin, min(1.0, max(-1.0, cos)))
    if target.pitch is not None:
        # pitch_error's scalar path, without its array conversions.
        ax, ay, az = (rotation @ approach_axis).tolist()
        pitch = target.pitch
        cos_p, sin_p = math.cos(pitch), math.sin(pitch)
        return position_error, pitch_error_scalar(ax, ay, az, tx, ty, cos_p, sin_p, math.atan2(sin_p, abs(cos_p)))
    return position_error, 0.0


def target_errors(robot: Robot, target: Target, q: Sequence[float] | np.ndarray) -> tuple[float, float]:
    """Position and orientation errors of a configuration for a target, by Pinocchio FK.

    Args:
        robot: The robot.
        target: The target.
        q: Shape (dof,) [rad or m].

    Returns:
        ``(position_error [m], orientation_error [rad])``. The orientation error is the
        rotation angle to the target rotation for a pose target; for a pitch target,
        :func:`planner.geometry.target.pitch_error` of the tip's approach axis (the angle to the nearest
        direction with the target's approach pitch); 0 for a position target.
    """
    pose = robot.fk(q)
    return tip_errors(target, pose[:3, 3], pose[:3, :3], robot.approach_axis)
