"""The task a target sets, seen from joint space: its Jacobian, rank and joint slack.

A position target constrains 3 task directions, a pitch target 4 (one for the elevation of the
approach axis, two when straight up or down), a pose 6. Where the rank of the task Jacobian is
below the joint count, the configurations that reach the target form a continuum: the arm is
redundant for that kind of target, or the configuration is singular.
"""

from __future__ import annotations

import math

import numpy as np

from planner.geometry.target import Target
from planner.model.robot import Robot

__all__ = ["joint_slack", "task_jacobian", "task_rank"]


def task_jacobian(robot: Robot, target: Target, q: np.ndarray) -> np.ndarray:
    """Jacobian of the target's task at ``q``: position rows [m], then orientation rows [rad].

    Args:
        robot: The robot.
        target: The target (its kind selects the rows).
        q: Shape (dof,) [rad or m].

    Returns:
        Shape (3, dof) for a position, (4, dof) or (5, dof) for a pitch, (6, dof) for a pose.
    """
    jac = robot.jacobian(q)
    if target.rotation is not None:
        return jac
    if target.pitch is not None:
        a = robot.fk(q)[:3, :3] @ robot.approach_axis
        skew = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
        turning = -skew @ jac[3:]  # d(approach axis)/dq in base axes
        if abs(math.cos(target.pitch)) <= 1e-12:
            return np.vstack([jac[:3], turning[:2]])  # straight up or down: one direction
        # Otherwise the pitch fixes only the elevation asin(a_z) (planner.geometry.target).
        return np.vstack([jac[:3], turning[2:3] / max(math.hypot(a[0], a[1]), 1e-12)])
    return jac[:3]


def task_rank(robot: Robot, target: Target, q: np.ndarray, rtol: float = 1e-6) -> int:
    """Rank of the target's task Jacobian at ``q`` (singular values above rtol times the largest).

    Below the joint count, the configurations reaching the target form a continuum there: the
    arm is redundant for this kind of target, or ``q`` is singular.
    """
    s = np.linalg.svd(task_jacobian(robot, target, q), compute_uv=False)
    return int(np.sum(s > rtol * s[0])) if s.size and s[0] > 0 else 0


def joint_slack(robot: Robot, target: Target, q: np.ndarray, position_error: float, orientation_error: float) -> float:
    """How far [rad, m] from ``q`` a configuration with these task errors can lie (error / sigma_min).

    Returns:
        0 where ``q`` is not an isolated solution (redundant or singular): no distance bound.
    """
    s = np.linalg.svd(task_jacobian(robot, target, q), compute_uv=False)
    if s.size < robot.dof or s[-1] <= 1e-6 * s[0]:
        return 0.0
    return math.hypot(position_error, orientation_error) / s[-1]
