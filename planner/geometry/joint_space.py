"""Distances in joint space: angle differences modulo 2 pi, lengths as they are."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from planner.model.robot import Robot

__all__ = ["joint_distance"]


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
    diff = np.asarray(q_a, dtype=float) - np.asarray(q_b, dtype=float)
    if "prismatic" in robot.joint_kinds:
        angular = np.array([k != "prismatic" for k in robot.joint_kinds])
        diff[..., angular] = (diff[..., angular] + math.pi) % (2 * math.pi) - math.pi
    else:
        diff = (diff + math.pi) % (2 * math.pi) - math.pi
    if diff.ndim == 1:
        return math.sqrt(float(diff @ diff))
    return np.sqrt((diff * diff).sum(axis=-1))
