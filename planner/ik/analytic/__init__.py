"""Closed-form (geometric) inverse kinematics for the seed arms' kinematic families.

One module per family, all built from the robot's Pinocchio model:

- :mod:`~planner.ik.analytic.planar2`: two joints about parallel vertical axes (Materick and Shapiro 1997).
- :mod:`~planner.ik.analytic.yaw_planar`: base yaw + 2 or 3 parallel pitch joints + optional
  wrist roll (Clothier and Shang 2010, Vaishnav, Sumadsad 2020, SO-101).

The families are registered in :data:`~planner.ik.analytic.families.FAMILIES`; each says by
``match(chain)`` whether a chain fits (None) or why not. Users call :func:`planner.solve_ik`;
a family solver, from :func:`closed_form_solver` (detects the family), answers with every
branch (:class:`AnalyticResult`) and solves batches of targets as arrays::

    solver = closed_form_solver(load_robot("al5c"))
    result = solver.solve(Target([0.25, 0.05, 0.10], pitch=-math.pi / 2), q_current=q)
    if result.ok:
        q_next = result.best.q
"""

from planner.geometry.chain import ChainAtZero, JointScrew, chain_at_zero, poe_fk
from planner.ik.analytic.base import FAMILY_ANGLE_TOL, AnalyticIK, ChainMismatch
from planner.ik.analytic.families import FAMILIES, closed_form_solver
from planner.ik.analytic.planar2 import PLANAR_BRANCHES, Planar2IK
from planner.ik.analytic.result import (
    STATUS_BEYOND_MAX_REACH,
    STATUS_CODES,
    STATUS_INSIDE_MIN_REACH,
    STATUS_NAMES,
    STATUS_OK,
    STATUS_ORIENTATION_NOT_ACHIEVABLE,
    STATUS_OUT_OF_PLANE,
    STATUS_OUTSIDE_JOINT_LIMITS,
    STATUS_SOLVED,
    AnalyticBatchResult,
    AnalyticResult,
    AnalyticSolution,
)
from planner.ik.analytic.yaw_planar import BRANCHES, YawPlanarIK

__all__ = [
    "AnalyticIK",
    "ChainMismatch",
    "FAMILIES",
    "closed_form_solver",
    "AnalyticResult",
    "AnalyticSolution",
    "AnalyticBatchResult",
    "YawPlanarIK",
    "Planar2IK",
    "BRANCHES",
    "PLANAR_BRANCHES",
    "STATUS_SOLVED",
    "STATUS_OK",
    "STATUS_OUTSIDE_JOINT_LIMITS",
    "STATUS_ORIENTATION_NOT_ACHIEVABLE",
    "STATUS_BEYOND_MAX_REACH",
    "STATUS_INSIDE_MIN_REACH",
    "STATUS_OUT_OF_PLANE",
    "STATUS_NAMES",
    "STATUS_CODES",
    "FAMILY_ANGLE_TOL",
    "ChainAtZero",
    "JointScrew",
    "chain_at_zero",
    "poe_fk",
]
