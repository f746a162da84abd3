"""N targets through the whole closed form, as arrays over targets and branches.

:func:`solve_arrays` runs the ideal closed form (:mod:`~planner.ik.analytic.yaw_planar.core`),
the correction on the real geometry when the chain is inexact
(:mod:`~planner.ik.analytic.yaw_planar.refine`), wraps the joints into their ranges nearest
``q_current`` and derives the statuses (:class:`BranchArrays`). :func:`result_from_arrays`
turns one target's row into an :class:`~planner.ik.analytic.result.AnalyticResult`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from planner.core.arrays import read_only
from planner.geometry.chain import wrap_array
from planner.geometry.target import Target
from planner.ik.analytic.result import AnalyticResult, AnalyticSolution
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.branches import BRANCHES, VALID
from planner.ik.analytic.yaw_planar.core import ideal_position_error, roll_values, solve_core
from planner.ik.analytic.yaw_planar.orientation import ideal_pitch_error
from planner.ik.analytic.yaw_planar.refine import refine
from planner.ik.analytic.yaw_planar.status import status_and_reason, status_codes

__all__ = ["BranchArrays", "solve_arrays", "result_from_arrays"]

#: The fields of :class:`BranchArrays` per target and branch (the others are per target).
PER_BRANCH = ("q", "cat", "valid", "within", "singular", "perr", "oerr", "dist")


@dataclass(frozen=True)
class BranchArrays:
    """Closed-form solutions of N targets, per branch (4 slots, BRANCHES order).

    Slots without a solution hold NaN in ``q``, ``perr`` and ``oerr``, False in the masks.

    Attributes:
        q: Shape (N, 4, dof) [rad], wrapped into the joint ranges nearest ``q_current``.
        cat: Shape (N, 4) branch categories, or None (batch results).
        valid: Shape (N, 4): the branch has a solution.
        within: Shape (N, 4): valid and within the joint limits.
        singular: Shape (N, 4).
        perr: Position errors, shape (N, 4) [m].
        oerr: Orientation errors, shape (N, 4) [rad], or None.
        status: Shape (N,) int8 status codes, or None (per-branch extracts).
        best: Shape (N,): index of the within-limits branch nearest ``q_current``, -1 if none;
            or None (per-branch extracts).
        dist: Wrist point to shoulder distances, shape (N, 4) [m], or None (batch results).
    """

    q: np.ndarray
    cat: np.ndarray | None
    valid: np.ndarray
    within: np.ndarray
    singular: np.ndarray
    perr: np.ndarray
    oerr: np.ndarray | None
    status: np.ndarray | None
    best: np.ndarray | None
    dist: np.ndarray | None

    @classmethod
    def empty(cls, n: int, dof: int) -> BranchArrays:
        """Unfilled batch arrays for N targets (``cat``, ``oerr`` and ``dist`` None), to be written into."""
        return cls(
            q=np.empty((n, 4, dof)),
            cat=None,
            valid=np.empty((n, 4), dtype=bool),
            within=np.empty((n, 4), dtype=bool),
            singular=np.empty((n, 4), dtype=bool),
            perr=np.empty((n, 4)),
            oerr=None,
            status=np.empty(n, dtype=np.int8),
            best=np.empty(n, dtype=np.intp),
            dist=None,
        )

    def branch_diagonal(self, m: int) -> BranchArrays:
        """From arrays over 4 m rows (row 4 i + s solved for branch s), branch s of row 4 i + s.

        Returns:
            The per-branch fields, shape (m, 4, ...); ``status`` and ``best`` None.
        """
        k = np.arange(4)
        parts = {}
        for name in PER_BRANCH:
            value = getattr(self, name)
            parts[name] = None if value is None else value.reshape((m, 4) + value.shape[1:])[:, k, k]
        return replace(self, status=None, best=None, **parts)

    def copy(self) -> BranchArrays:
        """A copy whose arrays share no memory with these."""
        return replace(
            self,
            **{f.name: None if getattr(self, f.name) is None else getattr(self, f.name).copy() for f in fields(self)},
        )


def solve_arrays(
    arm: ArmGeometry, pos, pit, rot, qc, orientation_errors: bool = True, phi_free=None, roll_free=None
) -> BranchArrays:
    """Solve N targets: ideal closed form, correction when inexact, limits, status.

    `phi_free` (N, 2) and `roll_free` (N,): the free in-plane end angle per side and the
    free wrist roll where finite (see :func:`~planner.ik.analytic.yaw_planar.core.solve_core`).
    """
    n = pos.shape[0]
    core = solve_core(arm, pos, pit, rot, qc, arm.orient_tol, phi_free=phi_free, roll_free=roll_free)
    q = core.q
    cat = core.cat
    dist = core.dist
    singular = core.singular
    oerr = None
    if arm.exact and rot is None:
        perr = ideal_position_error(arm, core, pos)
        if pit is not None and orientation_errors:
            oerr = ideal_pitch_error(arm, q, pos, pit)
    else:
        real = refine(arm, core, pos, pit, rot, qc, roll_free)
        q, cat, perr, oerr, dist, singular = real.q, real.cat, real.perr, real.oerr, real.dist, real.singular
    valid = cat == VALID
    # Wrap into the joint ranges, nearest q_current.
    within = valid.copy()
    # A free roll copied from q_current (or 0 inside its range) needs no wrapping.
    copied_roll = False
    if arm.has_roll and rot is None:
        lo, hi = arm.lower[arm.roll_idx], arm.upper[arm.roll_idx]
        roll = roll_values(arm, n, qc, roll_free)
        copied_roll = bool(np.all((roll >= lo) & (roll <= hi)))
    for j in range(arm.dof):
        if copied_roll and j == arm.roll_idx:
            col = q[..., j]
        else:
            ref = qc[:, j][:, None] if qc is not None else 0.0
            col = wrap_array(q[..., j], arm.lower[j], arm.upper[j], ref)
            q[..., j] = col
        within &= (col >= arm.lower[j]) & (col <= arm.upper[j])
    q[~valid] = np.nan
    perr = np.where(valid, perr, np.nan)
    if oerr is not None:
        oerr = np.where(valid, oerr, np.nan)
    singular = singular & valid
    status = status_codes(arm, cat, valid, within, dist)
    if qc is not None:
        dist2 = np.sum((q - qc[:, None, :]) ** 2, axis=-1)
    else:
        dist2 = np.broadcast_to(np.arange(4.0), (n, 4))
    score = np.where(within, dist2, np.inf)
    best = np.where(within.any(axis=1), np.argmin(score, axis=1), -1)
    return BranchArrays(
        q=q,
        cat=cat,
        valid=valid,
        within=within,
        singular=singular,
        perr=perr,
        oerr=oerr,
        status=status.astype(np.int8),
        best=best,
        dist=dist,
    )


def result_from_arrays(
    arm: ArmGeometry, a: BranchArrays, i: int, target: Target, qc: list[float] | None
) -> AnalyticResult:
    """The result of target `i` of `a` (its solutions sorted by distance to `qc` when given)."""
    sols = []
    details = []
    for slot in range(4):
        if not a.valid[i, slot]:
            continue
        arr = read_only(a.q[i, slot])
        oerr = None if a.oerr is None else float(a.oerr[i, slot])
        sol = AnalyticSolution(
            arr,
            bool(a.within[i, slot]),
            BRANCHES[slot],
            bool(a.singular[i, slot]),
            float(a.perr[i, slot]),
            oerr,
        )
        sols.append(sol)
        details.append((slot, sol))
    if qc is not None and len(sols) > 1:
        sols.sort(key=lambda s: float(np.sum((s.q - np.asarray(qc)) ** 2)))
    cats = a.cat[i].tolist()
    dist = a.dist[i].tolist()
    status, reason = status_and_reason(arm, cats, dist, details, target)
    return AnalyticResult(status, reason, tuple(sols), any(s.singular for s in sols))
