"""The chain as the closed-form solvers see it: joint axes and points at q = 0, read from Pinocchio.

Every revolute joint of the chain is a screw: a unit axis through a point, both in the base
frame with all joints at zero. Forward kinematics is then the product of exponentials
``T(q) = exp(xi_1 q_1) ... exp(xi_n q_n) T(0)``, which :func:`poe_fk` evaluates for arrays of
configurations (tests check it against Pinocchio). The family detectors of the solvers read
lengths, offsets and axis directions from these screws, never from hand-typed constants.

The module also wraps angles into joint ranges and words limit violations.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from planner.core.arrays import read_only
from planner.exceptions import UnsupportedChainError
from planner.model.robot import Robot

__all__ = [
    "JointScrew",
    "ChainAtZero",
    "chain_at_zero",
    "poe_fk",
    "rotation_about",
    "wrap_scalar",
    "wrap_array",
    "limit_violation",
    "describe_violation",
    "LIMIT_SNAP",
]

TWO_PI = 2.0 * math.pi

#: Values at most this far outside a joint range [rad] are round-off and set onto the limit.
LIMIT_SNAP = 1e-10


@dataclass(frozen=True)
class JointScrew:
    """A revolute joint of the chain at q = 0.

    Attributes:
        name: Joint name.
        index: Position in ``q``.
        axis: Unit rotation axis in the base frame, shape (3,).
        point: A point of the axis (the joint frame origin) in the base frame, shape (3,) [m].
        lower: Lower limit [rad] (-inf for continuous joints).
        upper: Upper limit [rad] (+inf for continuous joints).
    """

    name: str
    index: int
    axis: np.ndarray
    point: np.ndarray
    lower: float
    upper: float


@dataclass(frozen=True)
class ChainAtZero:
    """The robot's chain with every joint at zero.

    Attributes:
        joints: The chain joints, base to tip.
        tip_position: Tip frame origin, shape (3,) [m].
        tip_rotation: Tip frame rotation, shape (3, 3).
        approach: The tip's approach axis in the base frame, shape (3,).
    """

    joints: tuple[JointScrew, ...]
    tip_position: np.ndarray
    tip_rotation: np.ndarray
    approach: np.ndarray


def chain_at_zero(robot: Robot) -> ChainAtZero:
    """Read the joint screws and the tip pose at q = 0 from the robot's Pinocchio model.

    Raises:
        UnsupportedChainError: If a chain joint is prismatic (naming it).
    """
    model = robot.model
    data = model.createData()
    q0 = pin.neutral(model)  # continuous joints at angle 0
    pin.forwardKinematics(model, data, q0)
    pin.updateFramePlacements(model, data)
    joints = []
    for k, (name, kind) in enumerate(zip(robot.joint_names, robot.joint_kinds)):
        if kind == "prismatic":
            raise UnsupportedChainError(
                f"joint {name!r} is prismatic; the closed-form solvers handle revolute joints only", joint=name
            )
        jid = k + 1
        motion = np.asarray(data.joints[jid].S, dtype=float).reshape(6, -1)[:, 0]
        placement = data.oMi[jid]
        axis = placement.rotation @ motion[3:]
        axis = axis / np.linalg.norm(axis)
        joints.append(
            JointScrew(
                name=name,
                index=k,
                axis=read_only(axis),
                point=read_only(placement.translation),
                lower=float(robot.lower[k]),
                upper=float(robot.upper[k]),
            )
        )
    tip = data.oMf[robot.tip_frame_id]
    return ChainAtZero(
        joints=tuple(joints),
        tip_position=read_only(tip.translation),
        tip_rotation=read_only(tip.rotation),
        approach=read_only(tip.rotation @ robot.approach_axis),
    )


def rotation_about(axis: np.ndarray, angle: np.ndarray | float) -> np.ndarray:
    """Rotation matrices about a fixed unit axis (Rodrigues).

    Args:
        axis: Unit axis, shape (3,).
        angle: Angles [rad], any shape S.

    Returns:
        Shape S + (3, 3).
    """
    a = np.asarray(angle, dtype=float)
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    s = np.sin(a)[..., None, None]
    c = np.cos(a)[..., None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def poe_fk(
    axes: Sequence[np.ndarray],
    points: Sequence[np.ndarray],
    tip_position: np.ndarray,
    tip_rotation: np.ndarray,
    q: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Tip pose by the product of exponentials of revolute screws.

    Args:
        axes: Unit joint axes at q = 0, n of shape (3,).
        points: Points of the axes at q = 0, n of shape (3,) [m].
        tip_position: Tip position at q = 0, shape (3,) [m].
        tip_rotation: Tip rotation at q = 0, shape (3, 3).
        q: Joint values, shape S + (n,) [rad].

    Returns:
        Tip positions, shape S + (3,) [m], and rotations, shape S + (3, 3).
    """
    q = np.asarray(q, dtype=float)
    shape = q.shape[:-1]
    rot = np.broadcast_to(np.eye(3), shape + (3, 3))
    trans = np.zeros(shape + (3,))
    for k, (axis, point) in enumerate(zip(axes, points)):
        r_k = rotation_about(axis, q[..., k])
        t_k = point - r_k @ point
        trans = trans + np.einsum("...ij,...j->...i", rot, t_k)
        rot = rot @ r_k
    return np.einsum("...ij,j->...i", rot, tip_position) + trans, rot @ tip_rotation


def wrap_scalar(x: float, lower: float, upper: float, ref: float) -> float:
    """The angle equivalent to `x` (+-2 pi k) inside [lower, upper], nearest `ref` if several.

    Without an equivalent inside the range, the one nearest the range is returned (so the
    violation it shows is the smallest). Values within :data:`LIMIT_SNAP` outside a limit are
    set onto it.
    """
    x = x + TWO_PI * round((ref - x) / TWO_PI)
    if x > upper:
        if x - TWO_PI >= lower - LIMIT_SNAP or (x - upper) > (lower - (x - TWO_PI)):
            x -= TWO_PI
    elif x < lower:
        if x + TWO_PI <= upper + LIMIT_SNAP or (lower - x) > ((x + TWO_PI) - upper):
            x += TWO_PI
    if upper < x <= upper + LIMIT_SNAP:
        x = upper
    elif lower - LIMIT_SNAP <= x < lower:
        x = lower
    return x


def wrap_array(x: np.ndarray, lower: float, upper: float, ref: np.ndarray | float) -> np.ndarray:
    """Array version of :func:`wrap_scalar` (same rules, element-wise); returns a new array."""
    x = x - TWO_PI * np.round((x - ref) / TWO_PI)
    if not (math.isfinite(lower) or math.isfinite(upper)):
        return x
    over = x > upper
    if over.any():
        xo = x[over]
        down = xo - TWO_PI
        x[over] = np.where((down >= lower - LIMIT_SNAP) | ((xo - upper) > (lower - down)), down, xo)
    under = x < lower
    if under.any():
        xu = x[under]
        up = xu + TWO_PI
        x[under] = np.where((up <= upper + LIMIT_SNAP) | ((lower - xu) > (up - upper)), up, xu)
    x[(x > upper) & (x <= upper + LIMIT_SNAP)] = upper
    x[(x < lower) & (x >= lower - LIMIT_SNAP)] = lower
    return x


def limit_violation(x: float, lower: float, upper: float) -> float:
    """Signed excess of `x` over its range [rad]: negative below, positive above, 0 inside."""
    if x < lower:
        return x - lower
    if x > upper:
        return x - upper
    return 0.0


def describe_violation(name: str, x: float, lower: float, upper: float) -> str:
    """Words for a joint outside its range, with the value and the excess in rad and deg."""
    excess = limit_violation(x, lower, upper)
    side, limit = ("below its lower", lower) if excess < 0 else ("above its upper", upper)
    return (
        f"joint {name!r} needs {x:.4f} rad ({math.degrees(x):.2f} deg), {abs(excess):.4f} rad "
        f"({math.degrees(abs(excess)):.2f} deg) {side} limit {limit:.4f} rad ({math.degrees(limit):.2f} deg)"
    )
