"""The overall status of a target from its branches, and the reason in words.

The statuses are :mod:`planner.ik.analytic.result`'s: solved where a branch lies within the
limits; else, where branches have solutions, outside the joint limits (naming the joints) or
beyond/inside the reach the elbow's range allows; else, from the branch categories, the
orientation not achievable, inside the cylinder around the yaw axis, or beyond/inside the
links' reach.
"""

from __future__ import annotations

import math

import numpy as np

from planner.geometry.chain import describe_violation
from planner.geometry.target import Target
from planner.ik.analytic.result import (
    STATUS_BEYOND_MAX_REACH,
    STATUS_CODES,
    STATUS_INSIDE_MIN_REACH,
    STATUS_ORIENTATION_NOT_ACHIEVABLE,
    STATUS_OUTSIDE_JOINT_LIMITS,
    STATUS_SOLVED,
    AnalyticSolution,
)
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.branches import BEYOND, BRANCHES, CYLINDER, DUPLICATE, ORIENT
from planner.ik.status import IKStatus

__all__ = ["status_and_reason", "end_distance", "reach_limits", "status_codes"]


def status_and_reason(
    arm: ArmGeometry,
    cats: list[int],
    dist: list[float],
    details: list[tuple[int, AnalyticSolution]],
    target: Target,
) -> tuple[IKStatus, str]:
    """Overall status and its explanation from per-branch categories and solutions.

    Args:
        arm: The geometry.
        cats: The 4 branch categories.
        dist: The 4 wrist point to shoulder distances [m] (NaN where not computed).
        details: (slot, solution) of every branch with a solution.
        target: The target.

    Returns:
        The status and the reason; for :data:`STATUS_ORIENTATION_NOT_ACHIEVABLE` the reason is
        "" (the solver words it: it needs the solutions at the position alone).
    """
    names = arm.joint_names
    sols = [s for _, s in details]
    if any(s.within_limits for s in sols):
        return STATUS_SOLVED, ""
    if sols:
        rmin, rmax = reach_limits(arm)
        reach_fail = []
        for slot, _ in details:
            dd = dist[slot]
            if rmax is not None and dd > rmax + arm.len_tol:
                reach_fail.append((slot, "beyond", dd))
            elif rmin is not None and dd < rmin - arm.len_tol:
                reach_fail.append((slot, "inside", dd))
        if len(reach_fail) == len(details):
            beyond = any(kind == "beyond" for _, kind, _ in reach_fail)
            parts = [
                f"{BRANCHES[slot]}: wrist centre {dd:.6g} m from the shoulder, "
                + (f"beyond {rmax:.6g} m" if kind == "beyond" else f"within {rmin:.6g} m")
                for slot, kind, dd in reach_fail
            ]
            elbow = names[arm.pitch_idx[1]]
            what = "farther" if beyond else "closer"
            return (
                STATUS_BEYOND_MAX_REACH if beyond else STATUS_INSIDE_MIN_REACH,
                f"the target is {what} than joint {elbow!r}'s range "
                f"[{math.degrees(arm.lower[arm.pitch_idx[1]]):.2f}, "
                f"{math.degrees(arm.upper[arm.pitch_idx[1]]):.2f}] deg lets the arm reach (" + "; ".join(parts) + ")",
            )
        parts = []
        for _, s in details:
            q = s.q.tolist()
            bad = [
                describe_violation(names[j], q[j], arm.lower[j], arm.upper[j])
                for j in range(arm.dof)
                if q[j] < arm.lower[j] or q[j] > arm.upper[j]
            ]
            parts.append(f"{s.branch}: " + "; ".join(bad))
        return STATUS_OUTSIDE_JOINT_LIMITS, "no branch within the joint limits: " + " | ".join(parts)
    live = [c for c in cats if c != DUPLICATE]
    if ORIENT in live:
        return STATUS_ORIENTATION_NOT_ACHIEVABLE, ""
    if CYLINDER in live:
        d = abs(arm.lateral_offset)
        return (
            STATUS_INSIDE_MIN_REACH,
            f"the target is closer to the base yaw axis than the {d:.6g} m sideways offset of the arm's plane",
        )
    lengths = " + ".join(f"{v:.6g}" for v in arm.link_lengths)
    known = [d for d in dist if not math.isnan(d)]
    if target.pitch is not None and known:
        where = (
            f"with approach pitch {math.degrees(target.pitch):.2f} deg the wrist centre is {min(known):.6g} m "
            f"from joint {names[arm.pitch_idx[0]]!r}"
        )
    else:
        where = f"the target is {end_distance(arm, target):.6g} m from joint {names[arm.pitch_idx[0]]!r}"
    pair = arm.l1 + (arm.l2 if arm.n_pitch == 3 else arm.link_lengths[1])
    if BEYOND in live:
        reach = pair if (target.pitch is not None and known) else sum(arm.link_lengths)
        return STATUS_BEYOND_MAX_REACH, f"{where}, beyond the {reach:.6g} m the links ({lengths} m) reach"
    inner = abs(arm.l1 - (arm.l2 if arm.n_pitch == 3 else arm.link_lengths[1]))
    return STATUS_INSIDE_MIN_REACH, f"{where}, too close for the links ({lengths} m; |L1 - L2| = {inner:.6g} m)"


def end_distance(arm: ArmGeometry, target: Target) -> float:
    """Distance [m] from the shoulder axis to the target in the arm's (front) plane."""
    px, py, pz = target.position.tolist()
    d = arm.lateral_offset
    h = math.hypot(px - arm.bx, py - arm.by)
    u = math.sqrt(max((h - d) * (h + d), 0.0))
    return math.hypot(u - arm.su, pz - arm.sz)


def reach_limits(arm: ArmGeometry) -> tuple[float | None, float | None]:
    """The shoulder-elbow reach (min, max) [m] within the elbow's range, or (None, None) for 2 pitch joints."""
    if arm.n_pitch == 3:
        return arm.rmin_lim, arm.rmax_lim
    return None, None


def status_codes(
    arm: ArmGeometry, cat: np.ndarray, valid: np.ndarray, within: np.ndarray, dist: np.ndarray
) -> np.ndarray:
    """Batch status codes (N,) (:data:`~planner.ik.analytic.result.STATUS_CODES`) from the branch arrays (N, 4)."""
    n = cat.shape[0]
    any_valid = valid.any(axis=1)
    any_within = within.any(axis=1)
    status = np.full(n, STATUS_CODES[STATUS_OUTSIDE_JOINT_LIMITS])
    if arm.n_pitch == 3:
        beyond_lim = dist > arm.rmax_lim + arm.len_tol
        inside_lim = dist < arm.rmin_lim - arm.len_tol
        reach = np.where(valid, beyond_lim | inside_lim, True).all(axis=1) & any_valid
        any_beyond = (valid & beyond_lim).any(axis=1)
        status = np.where(
            reach,
            np.where(any_beyond, STATUS_CODES[STATUS_BEYOND_MAX_REACH], STATUS_CODES[STATUS_INSIDE_MIN_REACH]),
            status,
        )
    live = cat != DUPLICATE
    none = np.where(
        (live & (cat == ORIENT)).any(axis=1),
        STATUS_CODES[STATUS_ORIENTATION_NOT_ACHIEVABLE],
        np.where(
            (live & (cat == BEYOND)).any(axis=1),
            STATUS_CODES[STATUS_BEYOND_MAX_REACH],
            STATUS_CODES[STATUS_INSIDE_MIN_REACH],
        ),
    )
    status = np.where(any_valid, status, none)
    return np.where(any_within, STATUS_CODES[STATUS_SOLVED], status)
