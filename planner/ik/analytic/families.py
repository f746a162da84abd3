"""The registry of closed-form families: :meth:`AnalyticIK.from_robot` tries them in this order.

Adding a family is one new module with an :class:`~planner.ik.analytic.base.AnalyticIK`
subclass (its ``mismatch`` says why a chain does not fit) and one line in :data:`FAMILIES`.
"""

from __future__ import annotations

from planner.ik.analytic.base import AnalyticIK
from planner.ik.analytic.planar2 import Planar2IK
from planner.ik.analytic.yaw_planar import YawPlanarIK

__all__ = ["FAMILIES"]

#: The closed-form families. The families are exclusive (a chain fits at most one); where none
#: fits, the error reports the one that fits the most leading joints (on a tie, the later one).
FAMILIES: tuple[type[AnalyticIK], ...] = (
    Planar2IK,
    YawPlanarIK,
)
