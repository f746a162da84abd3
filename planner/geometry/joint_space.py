"""Distances in joint space: angle differences modulo 2 pi, lengths as they are."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from planner.model.robot import Robot

__all__ = ["angular_joints", "configurations_close", "joint_distance", "wrapped_distance"]

_TWO_PI = 2.0 * math.pi


def wrapped_distance(
    q_a: Sequence[float] | np.ndarray, q_b: Sequence[float] | np.ndarray, angular: Sequence[bool]
) -> float:
    """Joint-space distance, angle differences taken modulo 2 pi (prismatic ones as they are).

    Plain Python arithmetic: for one pair of configurations it is several times faster than
    numpy's temporaries.

    Args:
        q_a: Shape (n,) [rad or m].
        q_b: Shape (n,) [rad or m].
        angular: Which joints are angles (revolute or continuous), n booleans.

    Returns:
        The Euclidean norm of the wrapped differences [rad, m mixed].
    """
    if isinstance(q_a, np.ndarray):
        q_a = q_a.tolist()
    if isinstance(q_b, np.ndarray):
        q_b = q_b.tolist()
    total = 0.0
    for a, b, is_angle in zip(q_a, q_b, angular):
        d = a - b
        if is_angle:
            d = (d + math.pi) % _TWO_PI - math.pi
        total += d * d
    return math.sqrt(total)


def configurations_close(q_a: Sequence[float], q_b: Sequence[float], angular: Sequence[bool], tolerance: float) -> bool:
    """Whether :func:`wrapped_distance` of two configurations is at most `tolerance`.

    Stops at the first joints whose differences already exceed it (distinct solutions mostly
    differ in the first joints), so pass plain lists for speed.

    Args:
        q_a: Shape (n,) [rad or m].
        q_b: Shape (n,) [rad or m].
        angular: Which joints are angles (revolute or continuous), n booleans.
        tolerance: Distance [rad, m mixed].
    """
    limit = tolerance * tolerance
    total = 0.0
    for a, b, is_angle in zip(q_a, q_b, angular):
        d = a - b
        if is_angle:
            d = (d + math.pi) % _TWO_PI - math.pi
        total += d * d
        if total > limit:
            return False
    return True


def angular_joints(robot: Robot) -> tuple[bool, ...]:
    """Which of the robot's joints are angles (revolute or continuous), in ``q`` order."""
    return tuple(kind != "prismatic" for kind in robot.joint_kinds)


def joint_distance(
    robot: Robot, q_a: Sequence[float] | np.ndarray, q_b: Sequence[float] | np.ndarray
) -> float | np.ndarray:
    """Joint-space distance, angle differences taken modulo 2 pi (prismatic ones as they are).

    Args:
        robot: The robot (for its joint kinds).
        q_a: Shape (dof,) or (N, dof) [rad or m].
        q_b: Shape (dof,) or (N, dof) [rad or m] (broadcast against `q_a`).

    Returns:
        The Euclidean norm of the wrapped differences [rad, m mixed]: a float, or shape (N,).
    """
    if np.ndim(q_a) == 1 and np.ndim(q_b) == 1:
        return wrapped_distance(q_a, q_b, angular_joints(robot))
    diff = np.asarray(q_a, dtype=float) - np.asarray(q_b, dtype=float)
    if "prismatic" in robot.joint_kinds:
        angular = np.array([k != "prismatic" for k in robot.joint_kinds])
        diff[..., angular] = (diff[..., angular] + math.pi) % (2 * math.pi) - math.pi
    else:
        diff = (diff + math.pi) % (2 * math.pi) - math.pi
    return np.sqrt((diff * diff).sum(axis=-1))
