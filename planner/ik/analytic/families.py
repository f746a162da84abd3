"""The registry of closed-form families; :func:`closed_form_solver` tries them in this order.

Adding a family is one new module with an :class:`~planner.ik.analytic.base.AnalyticIK`
subclass (its ``mismatch`` says why a chain does not fit) and one line in :data:`FAMILIES`.
"""

from __future__ import annotations

from planner.exceptions import InvalidArgumentError, UnsupportedChainError
from planner.geometry.chain import chain_at_zero
from planner.ik.analytic.base import AnalyticIK
from planner.ik.analytic.planar2 import Planar2IK
from planner.ik.analytic.yaw_planar import YawPlanarIK
from planner.model.robot import Robot

__all__ = ["FAMILIES", "closed_form_solver"]

#: The closed-form families. The families are exclusive (a chain fits at most one); where none
#: fits, the error reports the one that fits the most leading joints (on a tie, the later one).
FAMILIES: tuple[type[AnalyticIK], ...] = (
    Planar2IK,
    YawPlanarIK,
)


def closed_form_solver(robot: Robot) -> AnalyticIK:
    """Detect the robot's closed-form family and build its solver.

    Args:
        robot: The robot; its chain is read from the Pinocchio model at q = 0.

    Returns:
        The solver of the first family of :data:`FAMILIES`
        that fits the chain.

    Raises:
        UnsupportedChainError: If the chain is outside every family; ``.joint`` names the
            first joint that breaks the family that fits most of the chain.
    """
    if not isinstance(robot, Robot):
        raise InvalidArgumentError(f"closed_form_solver needs a planner.Robot, got {type(robot).__name__}")
    chain = chain_at_zero(robot)
    if not chain.joints:
        raise UnsupportedChainError(f"{robot.name} has no joints on its chain to {robot.tip!r}")
    nearest = None
    for family in FAMILIES:
        mismatch = family.mismatch(chain)
        if mismatch is None:
            return family(robot, chain)
        if nearest is None or mismatch.depth >= nearest.depth:
            nearest = mismatch
    raise UnsupportedChainError(f"{robot.name}: {nearest.reason}", joint=nearest.joint)
