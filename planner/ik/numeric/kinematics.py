"""Symbolic forward kinematics of a :class:`~planner.model.robot.Robot`'s tip in CasADi.

``pinocchio.casadi`` is not part of the PyPI wheel, so the tip pose is rebuilt here as a
CasADi ``SX`` expression from the chain read out of the Pinocchio model
(:func:`planner.geometry.chain.kinematic_chain`): for every chain joint, its constant
placement in the parent joint frame, then its motion (a rotation by ``q`` about its unit axis
for revolute and continuous joints, a translation by ``q`` along it for prismatic ones), then
finally the tip frame's constant placement. ``q`` holds one value per chain
joint, as for :class:`~planner.model.robot.Robot` (an angle for continuous joints, not Pinocchio's
``(cos, sin)`` pair).

The expressions are exact (no approximation), so their numeric value equals Pinocchio's FK to
rounding; the tests compare both on every bundled and example-robot-data arm and on inline
URDFs with unaligned, continuous, prismatic and fixed joints.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from planner.exceptions import InvalidConfigurationError
from planner.geometry.chain import kinematic_chain
from planner.model.robot import Robot

__all__ = ["CasadiKinematics"]


def _axis_rotation(axis: np.ndarray, angle: ca.SX) -> ca.SX:
    """Rotation matrix about a constant unit axis by a symbolic angle (Rodrigues)."""
    c, s = ca.cos(angle), ca.sin(angle)
    nonzero = np.abs(axis) > 0.0
    if np.count_nonzero(nonzero) == 1:
        # Keep the exact zeros of an axis-aligned rotation so CasADi drops them from the graph.
        k = int(np.argmax(nonzero))
        sign = float(np.sign(axis[k]))
        i, j = (k + 1) % 3, (k + 2) % 3
        rot = ca.SX.eye(3)
        rot[i, i], rot[j, j] = c, c
        rot[j, i], rot[i, j] = sign * s, -sign * s
        return rot
    x, y, z = (float(v) for v in axis)
    skew = ca.SX(np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]))
    outer = ca.SX(np.outer(axis, axis))
    return c * ca.SX.eye(3) + s * skew + (1 - c) * outer


class CasadiKinematics:
    """The tip pose and geometric Jacobian of a robot as CasADi ``SX`` expressions.

    Build one per robot and reuse it; every expression is built once in the constructor.

    Attributes:
        robot: The robot.
        chain: Its chain (:class:`~planner.geometry.chain.KinematicChain`).
        joints: The chain joints, base to tip (``chain.joints``).
        dof: Number of chain joints.
        q: The joint symbol, ``SX`` of shape (dof, 1) [rad or m].
        position: Tip position in the base frame, ``SX`` (3, 1) [m].
        rotation: Tip rotation in the base frame, ``SX`` (3, 3).
        approach: The tip's approach axis (``robot.approach_axis``) in base-frame axes, ``SX`` (3, 1).
        jacobian: Geometric Jacobian of the tip, ``SX`` (6, dof), rows ``[v; omega]`` in base-frame
            axes (Pinocchio's LOCAL_WORLD_ALIGNED, as :meth:`Robot.jacobian`).
        fk_function: ``casadi.Function`` ``q -> (position, rotation)``.
        jacobian_function: ``casadi.Function`` ``q -> jacobian``.
    """

    def __init__(self, robot: Robot) -> None:
        """Build the symbolic kinematics of `robot`'s base-to-tip chain.

        Raises:
            UnsupportedChainError: If a chain joint is not a one-axis rotation or translation.
        """
        self.robot = robot
        self.chain = kinematic_chain(robot)
        self.joints = self.chain.joints
        self.dof = robot.dof
        self.q = ca.SX.sym("q", self.dof)
        self.position, self.rotation, self.jacobian = self.expressions(self.q)
        self.approach = ca.mtimes(self.rotation, ca.DM(np.array(robot.approach_axis)))
        self.fk_function = ca.Function("fk", [self.q], [self.position, self.rotation], ["q"], ["position", "rotation"])
        self.jacobian_function = ca.Function("jacobian", [self.q], [self.jacobian], ["q"], ["jacobian"])

    def expressions(self, q: ca.SX) -> tuple[ca.SX, ca.SX, ca.SX]:
        """Tip position, rotation and geometric Jacobian for a given joint expression.

        Args:
            q: ``SX`` of shape (dof, 1) [rad or m].

        Returns:
            ``(position (3, 1), rotation (3, 3), jacobian (6, dof))`` in the base frame.
        """
        rotations: list[ca.SX] = []
        translations: list[ca.SX] = []
        axes_world: list[ca.SX] = []
        for k, joint in enumerate(self.joints):
            if joint.parent < 0:
                r_parent, t_parent = ca.SX.eye(3), ca.SX.zeros(3, 1)
            else:
                r_parent, t_parent = rotations[joint.parent], translations[joint.parent]
            r_joint = ca.mtimes(r_parent, ca.SX(joint.parent_rotation))
            t_joint = t_parent + ca.mtimes(r_parent, ca.SX(joint.parent_translation))
            axes_world.append(ca.mtimes(r_joint, ca.SX(joint.axis)))
            if joint.kind == "prismatic":
                t_joint = t_joint + axes_world[-1] * q[k]
            else:
                r_joint = ca.mtimes(r_joint, _axis_rotation(joint.axis, q[k]))
            rotations.append(r_joint)
            translations.append(t_joint)
        parent = self.chain.tip_parent
        r_last = rotations[parent] if parent >= 0 else ca.SX.eye(3)
        t_last = translations[parent] if parent >= 0 else ca.SX.zeros(3, 1)
        position = t_last + ca.mtimes(r_last, ca.SX(self.chain.tip_translation))
        rotation = ca.mtimes(r_last, ca.SX(self.chain.tip_rotation))

        on_path = self.chain.tip_path()
        columns = []
        for k, joint in enumerate(self.joints):
            if k not in on_path:
                columns.append(ca.SX.zeros(6, 1))
            elif joint.kind == "prismatic":
                columns.append(ca.vertcat(axes_world[k], ca.SX.zeros(3, 1)))
            else:
                lever = position - translations[k]
                columns.append(ca.vertcat(ca.cross(axes_world[k], lever), axes_world[k]))
        jacobian = ca.horzcat(*columns) if columns else ca.SX.zeros(6, 0)
        return position, rotation, jacobian

    def _values(self, q: np.ndarray | list[float]) -> np.ndarray:
        arr = np.asarray(q, dtype=float)
        if arr.shape != (self.dof,):
            raise InvalidConfigurationError(f"q has shape {arr.shape}; {self.robot.name} expects ({self.dof},)")
        return arr

    def fk(self, q: np.ndarray | list[float]) -> np.ndarray:
        """Numeric tip pose from the symbolic model, a (4, 4) homogeneous transform [m]."""
        position, rotation = self.fk_function(self._values(q))
        pose = np.eye(4)
        pose[:3, :3] = np.array(rotation)
        pose[:3, 3] = np.array(position).ravel()
        return pose

    def jacobian_at(self, q: np.ndarray | list[float]) -> np.ndarray:
        """Numeric geometric Jacobian of the tip from the symbolic model, shape (6, dof)."""
        return np.array(self.jacobian_function(self._values(q)))
