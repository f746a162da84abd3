"""The real arm's forward kinematics (product of exponentials of its screws) and its errors.

The ideal geometry of :mod:`~planner.ik.analytic.yaw_planar.arm` differs from the real one on
inexact chains (SO-101's URDF); these evaluate the real one.
"""

from __future__ import annotations

import math

import numpy as np

from planner.core.rotations import rotation_error
from planner.geometry.chain import poe_fk
from planner.geometry.target import pitch_error
from planner.ik.analytic.yaw_planar.arm import ArmGeometry

__all__ = ["true_fk", "true_pitch", "orientation_errors"]

PI = math.pi


def true_fk(arm: ArmGeometry, q):
    """Tip positions S + (3,) [m] and rotations S + (3, 3) of the real arm at q, shape S + (dof,)."""
    return poe_fk(arm.axes, arm.points, arm.tip_position, arm.rot0, q)


def true_pitch(arm: ArmGeometry, q, fk_r):
    """Branch pitch (front: alpha, back: pi - alpha; see `core.solve_core`) of the real tip.

    alpha is the elevation of the real approach axis, its horizontal part counted positive
    along the arm's plane direction: the elevation itself, not its angle within the ideal
    plane, which differs (near vertical, by the square of the axis's small tilt out of that
    plane over its horizontal part) and would leave the target's elevation missed.
    """
    a = fk_r @ arm.approach_local
    yaw = arm.mu + arm.sigma * q[..., 0]
    along = np.cos(yaw) * a[..., 0] + np.sin(yaw) * a[..., 1]
    horiz = np.hypot(a[..., 0], a[..., 1])
    alpha = np.arctan2(a[..., 2], np.where(along >= 0.0, horiz, -horiz))
    return np.where(np.array([True, True, False, False]), alpha, PI - alpha)


def orientation_errors(arm: ArmGeometry, fk_r, pos, pit, rot):
    """Orientation errors (n, 4) of the real tip rotations for rotation or pitch targets, else None."""
    if rot is not None:
        return np.asarray(rotation_error(fk_r, np.broadcast_to(rot[:, None], fk_r.shape)))
    if pit is not None:
        return pitch_error(fk_r @ arm.approach_local, pos[:, None, :], pit[:, None])
    return None
