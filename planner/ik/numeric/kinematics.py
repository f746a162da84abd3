"""Symbolic forward kinematics of a :class:`~planner.model.robot.Robot`'s tip in CasADi.

``pinocchio.casadi`` is not part of the PyPI wheel, so the tip pose is rebuilt here as a
CasADi ``SX`` expression from the Pinocchio model itself: for every chain joint, its constant
placement in the parent joint frame (``model.jointPlacements``, which already holds every
fixed joint and locked joint Pinocchio merged into it), then its motion, then finally the tip
frame's constant placement. A joint's motion is read from its motion subspace at the neutral
configuration, so every one-degree-of-freedom joint Pinocchio builds from a URDF is covered:
revolute and continuous joints about any axis (a rotation by ``q`` about the unit axis) and
prismatic joints along any axis (a translation by ``q``). ``q`` holds one value per chain
joint, as for :class:`~planner.model.robot.Robot` (an angle for continuous joints, not Pinocchio's
``(cos, sin)`` pair).

The expressions are exact (no approximation), so their numeric value equals Pinocchio's FK to
rounding; the tests compare both on every bundled and example-robot-data arm and on inline
URDFs with unaligned, continuous, prismatic and fixed joints.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import pinocchio as pin

from planner.exceptions import InvalidConfigurationError, UnsupportedChainError
from planner.model.robot import Robot

__all__ = ["ChainJoint", "CasadiKinematics", "chain_joints"]

_AXIS_TOL = 1e-12


@dataclass(frozen=True)
class ChainJoint:
    """One chain joint as the symbolic FK sees it.

    Attributes:
        name: Joint name.
        kind: ``"revolute"``, ``"continuous"`` or ``"prismatic"``.
        parent_rotation: Rotation of the joint frame in its parent joint's frame at q = 0, (3, 3).
        parent_translation: Origin of the joint frame in the parent joint's frame at q = 0, (3,) [m].
        axis: Unit joint axis in the joint's own frame, (3,).
        parent: Index (into the chain, 0-based) of the parent joint, or -1 for the base.
    """

    name: str
    kind: str
    parent_rotation: np.ndarray
    parent_translation: np.ndarray
    axis: np.ndarray
    parent: int


def chain_joints(robot: Robot) -> tuple[ChainJoint, ...]:
    """The chain joints of a robot with their placements and axes, base to tip.

    Raises:
        UnsupportedChainError: If a joint is neither a one-axis rotation nor a one-axis
            translation, or its motion at q = 0 is not the identity.
    """
    model = robot.model
    q0 = pin.neutral(model)
    joints = []
    for jid in range(1, model.njoints):
        jm = model.joints[jid]
        name = model.names[jid]
        if jm.nv != 1:
            raise UnsupportedChainError(
                f"joint {name!r} ({jm.shortname()}) has {jm.nv} degrees of freedom; only one-axis joints are supported",
                joint=name,
            )
        jd = jm.createData()
        jm.calc(jd, q0)
        subspace = np.array(jd.S).reshape(6)
        linear, angular = subspace[:3], subspace[3:]
        if not np.allclose(jd.M.homogeneous, np.eye(4), atol=1e-12):
            raise UnsupportedChainError(
                f"joint {name!r} ({jm.shortname()}) does not rest at the identity at its neutral configuration",
                joint=name,
            )
        kind = robot.joint_kinds[jid - 1]
        if kind in ("revolute", "continuous"):
            if np.linalg.norm(linear) > _AXIS_TOL or np.linalg.norm(angular) < _AXIS_TOL:
                raise UnsupportedChainError(f"joint {name!r} ({jm.shortname()}) is not a pure rotation", joint=name)
            axis = angular
        else:
            if np.linalg.norm(angular) > _AXIS_TOL or np.linalg.norm(linear) < _AXIS_TOL:
                raise UnsupportedChainError(f"joint {name!r} ({jm.shortname()}) is not a pure translation", joint=name)
            axis = linear
        placement = model.jointPlacements[jid]
        joints.append(
            ChainJoint(
                name=name,
                kind=kind,
                parent_rotation=np.array(placement.rotation),
                parent_translation=np.array(placement.translation),
                axis=axis / np.linalg.norm(axis),
                parent=model.parents[jid] - 1,
            )
        )
    return tuple(joints)


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
        self.joints = chain_joints(robot)
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
        model = self.robot.model
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
        frame = model.frames[self.robot.tip_frame_id]
        parent = frame.parentJoint - 1
        r_last = rotations[parent] if parent >= 0 else ca.SX.eye(3)
        t_last = translations[parent] if parent >= 0 else ca.SX.zeros(3, 1)
        position = t_last + ca.mtimes(r_last, ca.SX(np.array(frame.placement.translation)))
        rotation = ca.mtimes(r_last, ca.SX(np.array(frame.placement.rotation)))

        on_path = set()
        j = parent
        while j >= 0:
            on_path.add(j)
            j = self.joints[j].parent
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
