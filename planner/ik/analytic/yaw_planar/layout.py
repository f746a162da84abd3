"""Whether a chain is of the yaw-planar family, and which joint plays which part.

The family: a first joint about the vertical (the base yaw), then 2 or 3 joints about parallel
horizontal axes (the pitch joints; the arm's plane is perpendicular to them), then optionally a
joint about an axis in that plane (the wrist roll). Axes may deviate from these directions by
up to :data:`~planner.ik.analytic.base.FAMILY_ANGLE_TOL` (CAD round-off): such chains are solved
on the ideal geometry and corrected on the real one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.geometry.chain import ChainAtZero, JointScrew
from planner.ik.analytic.base import FAMILY_ANGLE_TOL, ChainMismatch, base_yaw_mismatch
from planner.ik.analytic.geometry import angle_to_line, angle_to_plane

__all__ = ["ChainLayout", "chain_layout"]


@dataclass(frozen=True)
class ChainLayout:
    """A chain split into the family's joints.

    Attributes:
        yaw: The base yaw joint.
        pitch: The 2 or 3 parallel pitch joints.
        roll: The wrist roll joint, or None.
        deviation: Largest angle [rad] of the axes from the family's ideal directions.
    """

    yaw: JointScrew
    pitch: tuple[JointScrew, ...]
    roll: JointScrew | None
    deviation: float


def chain_layout(chain: ChainAtZero) -> ChainLayout | ChainMismatch:
    """Split a chain into base yaw, pitch joints and wrist roll, or say why it does not fit.

    Args:
        chain: The chain at q = 0.

    Returns:
        The layout, or the mismatch naming the first joint that breaks the family.
    """
    common = base_yaw_mismatch(chain)
    if common is not None:
        return common
    joints = chain.joints
    z = np.array([0.0, 0.0, 1.0])
    yaw = joints[0]
    if angle_to_line(joints[1].axis, yaw.axis) <= FAMILY_ANGLE_TOL:
        return ChainMismatch(
            f"joint {joints[1].name!r} turns about the vertical like the base yaw {yaw.name!r}: a planar arm, "
            "not a pitch joint after the base yaw",
            joints[1].name,
            1,
        )
    deviation = angle_to_line(yaw.axis, z)
    n_raw = joints[1].axis
    off = angle_to_plane(n_raw, z)
    if off > FAMILY_ANGLE_TOL:
        return ChainMismatch(
            f"joint {joints[1].name!r} turns about {np.round(n_raw, 6).tolist()}, neither vertical "
            "(a planar 2-link) nor horizontal (a pitch joint after the base yaw)",
            joints[1].name,
            1,
        )
    deviation = max(deviation, off)
    pitch = [joints[1]]
    k = 2
    while k < len(joints) and angle_to_line(joints[k].axis, n_raw) <= FAMILY_ANGLE_TOL:
        deviation = max(deviation, angle_to_line(joints[k].axis, n_raw))
        pitch.append(joints[k])
        k += 1
    if len(pitch) > 3:
        return ChainMismatch(
            f"joint {pitch[3].name!r} is a fourth parallel pitch joint; the family has 2 or 3 "
            "(more make the arm's plane redundant)",
            pitch[3].name,
            4,
        )
    if len(pitch) < 2:
        bad = joints[k] if k < len(joints) else joints[1]
        return ChainMismatch(
            f"joint {bad.name!r} "
            + ("is not parallel to the first pitch joint" if k < len(joints) else "ends the chain")
            + f" after a single pitch joint {joints[1].name!r}; the family needs 2 or 3 parallel pitch joints",
            bad.name,
            2,
        )
    roll = None
    if k < len(joints):
        cand = joints[k]
        perp = angle_to_plane(cand.axis, n_raw)
        if perp > FAMILY_ANGLE_TOL:
            return ChainMismatch(
                f"joint {cand.name!r} turns about {np.round(cand.axis, 6).tolist()}, neither parallel "
                "to the pitch axes nor perpendicular to them (a wrist roll)",
                cand.name,
                k,
            )
        deviation = max(deviation, perp)
        roll = cand
        k += 1
    if k < len(joints):
        return ChainMismatch(
            f"joint {joints[k].name!r} follows the wrist roll {roll.name!r}; the family ends there "
            "(base yaw, 2 or 3 pitch joints, optional wrist roll)",
            joints[k].name,
            k,
        )
    return ChainLayout(yaw, tuple(pitch), roll, deviation)
