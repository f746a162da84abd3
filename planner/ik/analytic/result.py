"""Result types of the closed-form solvers and their status codes.

A solver never raises for a target it cannot reach: it returns a result whose ``status`` says
why. The statuses, best outcome first:

========================== ====================================================================
``"solved"``                At least one solution lies within every joint's limits.
``"outside_joint_limits"``  Solutions exist, but every one has a joint outside its range
                            (``reason`` names the joint and by how much, per branch).
``"orientation_not_achievable"`` The position is reachable but not with the asked orientation
                            or approach pitch: the arm has too few joints for it.
``"beyond_max_reach"``      Too far: no branch reaches (or, with the elbow's range, the
                            wrist centre is farther than the elbow's range allows).
``"inside_min_reach"``      Too close to the base or shoulder (Materick and Shapiro's (1997) minimum reach,
                            from the elbow's range), or inside the cylinder that a sideways
                            offset of the arm's plane leaves around the base axis.
``"out_of_plane"``          A planar arm asked for a point off its plane.
========================== ====================================================================

The statuses are members of :class:`planner.ik.status.IKStatus` (a ``str`` enum, so they compare
equal to these strings), the one outcome vocabulary of every IK method. Batch results carry them
as small integer codes (:data:`STATUS_CODES`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from planner.ik.status import IKStatus

__all__ = [
    "STATUS_SOLVED",
    "STATUS_OK",
    "STATUS_OUTSIDE_JOINT_LIMITS",
    "STATUS_ORIENTATION_NOT_ACHIEVABLE",
    "STATUS_BEYOND_MAX_REACH",
    "STATUS_INSIDE_MIN_REACH",
    "STATUS_OUT_OF_PLANE",
    "STATUS_NAMES",
    "STATUS_CODES",
    "AnalyticSolution",
    "AnalyticResult",
    "AnalyticBatchResult",
]

STATUS_SOLVED = IKStatus.SOLVED
STATUS_OUTSIDE_JOINT_LIMITS = IKStatus.OUTSIDE_JOINT_LIMITS
STATUS_ORIENTATION_NOT_ACHIEVABLE = IKStatus.ORIENTATION_NOT_ACHIEVABLE
STATUS_BEYOND_MAX_REACH = IKStatus.BEYOND_MAX_REACH
STATUS_INSIDE_MIN_REACH = IKStatus.INSIDE_MIN_REACH
STATUS_OUT_OF_PLANE = IKStatus.OUT_OF_PLANE
#: Former name of :data:`STATUS_SOLVED` (whose value was ``"ok"`` before the one vocabulary).
STATUS_OK = STATUS_SOLVED

#: Statuses in code order: ``STATUS_NAMES[code]`` (code 0 is solved).
STATUS_NAMES: tuple[IKStatus, ...] = (
    STATUS_SOLVED,
    STATUS_OUTSIDE_JOINT_LIMITS,
    STATUS_ORIENTATION_NOT_ACHIEVABLE,
    STATUS_BEYOND_MAX_REACH,
    STATUS_INSIDE_MIN_REACH,
    STATUS_OUT_OF_PLANE,
)
#: Status name to batch code.
STATUS_CODES: dict[IKStatus, int] = {name: code for code, name in enumerate(STATUS_NAMES)}


class AnalyticSolution(NamedTuple):
    """One joint configuration that puts the tip on the target.

    Attributes:
        q: Joint values, shape (dof,) [rad], read-only, each wrapped into its joint's range
            where an equivalent angle (+-2 pi) exists.
        within_limits: Whether every joint lies within its range.
        branch: Which closed-form branch, e.g. ``"front/elbow-up"``, ``"back/elbow-down"``
            (yaw arms) or ``"elbow-left"`` (planar arms).
        singular: Whether the configuration is (within 1e-7 relative) at a singularity:
            a stretched or folded elbow, or the end point on the base yaw axis.
        position_error: Distance from the tip to the target [m], by the solver's forward model.
        orientation_error: Angle to the asked orientation, or for an approach pitch
            :func:`planner.geometry.target.pitch_error` of the approach axis [rad]; None for a
            position-only target.
    """

    q: np.ndarray
    within_limits: bool
    branch: str
    singular: bool
    position_error: float
    orientation_error: float | None

    def __reduce__(self) -> tuple:
        return (_with_q_frozen, (AnalyticSolution, tuple(self)))

    def as_dict(self) -> dict:
        """A JSON-ready mapping of the solution."""
        return {
            "q": self.q.tolist(),
            "branch": self.branch,
            "within_limits": self.within_limits,
            "singular": self.singular,
            "position_error": self.position_error,
            "orientation_error": self.orientation_error,
            "status": STATUS_SOLVED if self.within_limits else STATUS_OUTSIDE_JOINT_LIMITS,
        }


class AnalyticResult(NamedTuple):
    """All closed-form solutions for one target.

    Attributes:
        status: One of the statuses of this module (:data:`STATUS_SOLVED` when a solution lies
            within the joint limits).
        reason: Human-readable explanation ("" when solved), naming the joint and the excess when
            limits are violated.
        solutions: Every exact solution, within limits or not, sorted by joint-space distance
            to ``q_current`` when one was given (else in branch order).
        singular: Whether any solution is singular.
    """

    status: IKStatus
    reason: str
    solutions: tuple[AnalyticSolution, ...]
    singular: bool

    @property
    def ok(self) -> bool:
        """Whether a solution lies within the joint limits."""
        return self.status == STATUS_SOLVED

    @property
    def best(self) -> AnalyticSolution | None:
        """The first (nearest to ``q_current``) solution within limits, or None."""
        for sol in self.solutions:
            if sol.within_limits:
                return sol
        return None

    def as_dict(self) -> dict:
        """A JSON-ready mapping of the result."""
        return {
            "status": self.status,
            "reason": self.reason,
            "singular": self.singular,
            "solutions": [s.as_dict() for s in self.solutions],
        }


class AnalyticBatchResult(NamedTuple):
    """Closed-form solutions of N targets, as arrays over targets and branches.

    Slots of branches that have no solution for a target hold NaN in ``q`` and
    ``position_error`` and False in every mask.

    Attributes:
        q: Shape (N, B, dof) [rad], read-only.
        valid: Shape (N, B): the branch has an exact solution.
        within_limits: Shape (N, B): valid and every joint within its range.
        singular: Shape (N, B): valid and singular.
        position_error: Shape (N, B) [m].
        status: Shape (N,) int8 status codes (``STATUS_NAMES[code]``).
        best: Shape (N,) index of the within-limits branch nearest ``q_current`` (the first in
            branch order without one), -1 where none lies within limits.
        branches: The B branch names.
    """

    q: np.ndarray
    valid: np.ndarray
    within_limits: np.ndarray
    singular: np.ndarray
    position_error: np.ndarray
    status: np.ndarray
    best: np.ndarray
    branches: tuple[str, ...]

    def __reduce__(self) -> tuple:
        return (_with_q_frozen, (AnalyticBatchResult, tuple(self)))

    @property
    def status_names(self) -> np.ndarray:
        """Shape (N,) status names."""
        return np.asarray(STATUS_NAMES, dtype=object)[self.status]

    @property
    def best_q(self) -> np.ndarray:
        """Shape (N, dof): the best solution per target, NaN where none lies within limits."""
        n, _, dof = self.q.shape
        out = np.full((n, dof), np.nan)
        has = self.best >= 0
        out[has] = self.q[np.nonzero(has)[0], self.best[has]]
        return out


def _with_q_frozen(cls: type, values: tuple):
    """``cls(*values)`` with its first field, ``q``, read-only (a pickled or copied array is not)."""
    values[0].setflags(write=False)
    return cls(*values)
