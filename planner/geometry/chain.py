"""The robot's chain read out of Pinocchio: the one place the IK layers get it from.

Two views of the same chain:

- :func:`kinematic_chain` (:class:`KinematicChain` of :class:`ChainJoint`): every chain joint's
  constant placement in its parent joint's frame (``model.jointPlacements``, which already
  holds every fixed and locked joint Pinocchio merged into it), its kind and its axis in its
  own frame, and the tip frame's placement in its joint's frame; the CasADi kinematics
  (:mod:`planner.ik.numeric.kinematics`) compose these recursively, for revolute, continuous
  and prismatic joints about any axis.
- :func:`chain_at_zero` (:class:`ChainAtZero` of :class:`JointScrew`): the screws the closed
  form works with.

Every revolute joint of the chain is a screw: a unit axis through a point, both in the base
frame with all joints at zero. Forward kinematics is then the product of exponentials
``T(q) = exp(xi_1 q_1) ... exp(xi_n q_n) T(0)``, which :func:`poe_fk` evaluates for arrays of
configurations (tests check it against Pinocchio). The family detectors of the solvers read
lengths, offsets and axis directions from these screws, never from hand-typed constants.

The module also wraps angles into joint ranges, measures joint distances (angles modulo
2 pi) and words limit violations.
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
    "ChainJoint",
    "KinematicChain",
    "kinematic_chain",
    "JointScrew",
    "ChainAtZero",
    "chain_at_zero",
    "poe_fk",
    "rotation_about",
    "rodrigues_rows",
    "wrap_scalar",
    "wrap_array",
    "limit_violation",
    "describe_violation",
    "LIMIT_SNAP",
]

TWO_PI = 2.0 * math.pi

#: Values at most this far outside a joint range [rad] are round-off and set onto the limit.
LIMIT_SNAP = 1e-10
_AXIS_TOL = 1e-12


@dataclass(frozen=True)
class ChainJoint:
    """One chain joint, placed in its parent joint's frame.

    Attributes:
        name: Joint name.
        index: Position in ``q``.
        kind: ``"revolute"``, ``"continuous"`` or ``"prismatic"``.
        parent_rotation: Rotation of the joint frame in its parent joint's frame at q = 0,
            shape (3, 3), read-only.
        parent_translation: Origin of the joint frame in its parent joint's frame at q = 0,
            shape (3,) [m], read-only.
        axis: Unit joint axis in the joint's own frame, shape (3,), read-only: a rotation by
            ``q`` about it, or a translation by ``q`` along it.
        parent: Index (into the chain, 0-based) of the parent joint, or -1 for the base.
    """

    name: str
    index: int
    kind: str
    parent_rotation: np.ndarray
    parent_translation: np.ndarray
    axis: np.ndarray
    parent: int


@dataclass(frozen=True)
class KinematicChain:
    """The chain joints, base to tip, and where the tip frame sits.

    Forward kinematics composes, joint by joint, the parent's pose, the joint's placement
    and its motion; then the tip's placement in its joint's frame.

    Attributes:
        joints: The chain joints, base to tip (``joints[k].index == k``).
        tip_parent: Index of the joint carrying the tip frame, or -1 for the base.
        tip_rotation: Rotation of the tip frame in that joint's frame, shape (3, 3), read-only.
        tip_translation: Origin of the tip frame in that joint's frame, shape (3,) [m], read-only.
    """

    joints: tuple[ChainJoint, ...]
    tip_parent: int
    tip_rotation: np.ndarray
    tip_translation: np.ndarray

    def offsets_length(self) -> float:
        """Summed lengths of the joint and tip placement offsets [m] (a scale of the arm)."""
        total = sum(float(np.linalg.norm(joint.parent_translation)) for joint in self.joints)
        return total + float(np.linalg.norm(self.tip_translation))

    def tip_path(self) -> frozenset[int]:
        """Indices of the joints that move the tip (from the tip's joint down to the base)."""
        path = set()
        k = self.tip_parent
        while k >= 0:
            path.add(k)
            k = self.joints[k].parent
        return frozenset(path)


def kinematic_chain(robot: Robot) -> KinematicChain:
    """Read the chain joints' placements, kinds and axes and the tip placement from Pinocchio.

    A joint's motion is read from its motion subspace at the neutral configuration, so every
    one-degree-of-freedom joint Pinocchio builds from a URDF is covered: revolute and
    continuous joints about any axis and prismatic joints along any axis.

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
                index=jid - 1,
                kind=kind,
                parent_rotation=read_only(placement.rotation),
                parent_translation=read_only(placement.translation),
                axis=read_only(axis / np.linalg.norm(axis)),
                parent=model.parents[jid] - 1,
            )
        )
    frame = model.frames[robot.tip_frame_id]
    return KinematicChain(
        joints=tuple(joints),
        tip_parent=frame.parentJoint - 1,
        tip_rotation=read_only(frame.placement.rotation),
        tip_translation=read_only(frame.placement.translation),
    )


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
    out = np.empty(a.shape + (3, 3))
    for i, row in enumerate(rodrigues_rows(axis, np.sin(a), np.cos(a))):
        for j, value in enumerate(row):
            out[..., i, j] = value
    return out


def rodrigues_rows(axis, s, c):
    """The rows of ``c I + s [axis]x + (1 - c) axis axis^T`` as nested lists.

    Plain arithmetic on `s` and `c` (the sine and cosine of the angle): floats, arrays or
    CasADi symbols alike.
    """
    x, y, z = (float(v) for v in axis)
    v = 1.0 - c
    vx, vy, vz = v * x, v * y, v * z
    sx, sy, sz = s * x, s * y, s * z
    return [
        [c + vx * x, vx * y - sz, vx * z + sy],
        [vy * x + sz, c + vy * y, vy * z - sx],
        [vz * x - sy, vz * y + sx, c + vz * z],
    ]


def poe_fk(
    axes: Sequence[np.ndarray],
    points: Sequence[np.ndarray],
    tip_position: np.ndarray,
    tip_rotation: np.ndarray,
    q: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Tip pose by the product of exponentials of revolute screws.

    Computed on the nine components as separate arrays (contiguous, one pass per product), not on
    stacks of 3x3 matrices.

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
    rot = None
    trans = None
    for k, (axis, point) in enumerate(zip(axes, points)):
        angle = q[..., k]
        r_k = rodrigues_rows(axis, np.sin(angle), np.cos(angle))
        p = [float(v) for v in point]
        t_k = [p[i] - (r[0] * p[0] + r[1] * p[1] + r[2] * p[2]) for i, r in enumerate(r_k)]
        if rot is None:
            rot, trans = r_k, t_k
            continue
        trans = [trans[i] + rot[i][0] * t_k[0] + rot[i][1] * t_k[1] + rot[i][2] * t_k[2] for i in range(3)]
        rot = [
            [rot[i][0] * r_k[0][j] + rot[i][1] * r_k[1][j] + rot[i][2] * r_k[2][j] for j in range(3)] for i in range(3)
        ]
    pos_out = np.empty(shape + (3,))
    rot_out = np.empty(shape + (3, 3))
    tp = [float(v) for v in tip_position]
    tr = np.asarray(tip_rotation, dtype=float).tolist()
    if rot is None:  # no joints
        pos_out[...] = tp
        rot_out[...] = tr
        return pos_out, rot_out
    for i in range(3):
        r0, r1, r2 = rot[i]
        pos_out[..., i] = r0 * tp[0] + r1 * tp[1] + r2 * tp[2] + trans[i]
        for j in range(3):
            rot_out[..., i, j] = r0 * tr[0][j] + r1 * tr[1][j] + r2 * tr[2][j]
    return pos_out, rot_out


def wrap_scalar(x: float, lower: float, upper: float, ref: float) -> float:
    """The angle equivalent to `x` (+-2 pi k) inside [lower, upper], nearest `ref` if several.

    Without an equivalent inside the range, the one nearest the range is returned (so the
    violation it shows is the smallest). Values within :data:`LIMIT_SNAP` outside a limit are
    set onto it.
    """
    turns = (ref - x) / TWO_PI
    # round() of a turn count within half a turn is 0: skip the call (x + 0.0 keeps -0.0 -> 0.0).
    x = x + 0.0 if -0.5 <= turns <= 0.5 else x + TWO_PI * round(turns)
    if lower <= x <= upper:
        return x  # the common case: inside the range, nothing to snap
    if x > upper:
        down = x - TWO_PI
        if down >= lower - LIMIT_SNAP or (x - upper) > (lower - down):
            x = down
    else:
        up = x + TWO_PI
        if up <= upper + LIMIT_SNAP or (lower - x) > (up - upper):
            x = up
    if upper < x <= upper + LIMIT_SNAP:
        return upper
    if lower - LIMIT_SNAP <= x < lower:
        return lower
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
