"""The closed form and the NLP on one target, compared: :func:`cross_check`.

They agree when the NLP answer coincides with one of the closed-form branches (joint-space
distance, angles modulo 2 pi), or, where the arm is redundant (or singular) for the target, both
reach it; or both find the target out of reach. Any other outcome is a bug in one of the two
solvers, and the :class:`CrossCheck` says which way they differ.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planner.exceptions import UnsupportedChainError
from planner.geometry.joint_space import joint_distance
from planner.geometry.target import Target, as_target
from planner.ik.options import IKOptions
from planner.ik.result import IKResult
from planner.ik.solve import solve_ik
from planner.ik.solvers import IKSolvers
from planner.ik.task import joint_slack, task_rank
from planner.model.robot import Robot

__all__ = ["CrossCheck", "compare", "cross_check"]


@dataclass(frozen=True)
class CrossCheck:
    """The closed form and the NLP on one target, compared.

    Attributes:
        agree: Whether the two agree (see ``verdict``).
        verdict: ``"match"`` (the NLP answer is one of the closed-form branches),
            ``"both_reach"`` (no branch coincides, but the arm is redundant or singular for the
            target there and both reach it), ``"both_unreachable"``; or, when they disagree,
            ``"mismatch"`` (the NLP reaches the target in a configuration no branch has),
            ``"analytic_missed"`` (the NLP reaches a target the closed form calls unreachable
            within limits), ``"nlp_failed"`` (the closed form reaches it, the NLP did not) or
            ``"analytic_inaccurate"`` (a closed-form solution within limits misses the target
            by Pinocchio FK).
        reason: The verdict in a sentence, with the numbers.
        nlp: The NLP result.
        analytic: The closed-form result.
        branch: The closed-form branch nearest the NLP answer, or None.
        joint_distance: Distance [rad, m] from the NLP answer to that branch (angles modulo
            2 pi), or None.
        redundant: Whether the task Jacobian at the NLP answer has rank below the joint count
            (the solution set is not discrete there: redundant arm or singular configuration).
        analytic_position_error: Pinocchio position error of that branch [m], or None.
        analytic_orientation_error: Pinocchio orientation error of that branch [rad], or None.
    """

    agree: bool
    verdict: str
    reason: str
    nlp: IKResult
    analytic: IKResult
    branch: str | None
    joint_distance: float | None
    redundant: bool
    analytic_position_error: float | None
    analytic_orientation_error: float | None

    @property
    def analytic_status(self) -> str:
        """The closed form's status."""
        return self.analytic.status.value

    def as_dict(self) -> dict:
        """A JSON-ready mapping."""
        return {
            "agree": self.agree,
            "verdict": self.verdict,
            "reason": self.reason,
            "analytic_status": self.analytic_status,
            "branch": self.branch,
            "joint_distance": self.joint_distance,
            "redundant": self.redundant,
            "nlp_position_error": self.nlp.position_error,
            "nlp_orientation_error": self.nlp.orientation_error,
            "analytic_position_error": self.analytic_position_error,
            "analytic_orientation_error": self.analytic_orientation_error,
        }


def cross_check(
    robot: Robot,
    target: Target | Sequence[float] | np.ndarray,
    q_seed: Sequence[float] | np.ndarray | None = None,
    *,
    joint_tolerance: float = 1e-4,
    options: IKOptions | None = None,
) -> CrossCheck:
    """Solve one target with ``solve_ik`` both ways (the NLP started without the branches); compare.

    Args:
        robot: A robot with a closed form.
        target: A :class:`Target`, a position (3,) [m] or a pose (4, 4) [m].
        q_seed: Configuration (dof,) [rad or m]: the NLP's seed and the closed form's current
            configuration (which picks its free joints).
        joint_tolerance: Joint distance [rad, m] within which the NLP answer counts as a
            closed-form branch; near a singularity the bound widens to 10 times the NLP's task
            error over the smallest singular value of the task Jacobian at the branch (the
            distance a configuration with that error can lie from it).
        options: Tolerances (both solvers) and NLP settings; ``closed_form_seeds`` is forced
            off so that the NLP answers on its own.

    Returns:
        The comparison.

    Raises:
        UnsupportedChainError: If the arm or target kind has no closed form.
    """
    options = options or IKOptions()
    target = as_target(target)
    solvers = IKSolvers.of(robot)
    if solvers.analytic is None:
        raise UnsupportedChainError(f"{robot.name} has no closed-form IK to cross-check: {solvers.analytic_reason}")
    analytic = solve_ik(robot, target, q_seed, method="analytic", options=options)
    nlp = solve_ik(robot, target, q_seed, method="nlp", options=dataclasses.replace(options, closed_form_seeds=False))
    return compare(robot, target, analytic, nlp, joint_tolerance=joint_tolerance, options=options)


def compare(
    robot: Robot,
    target: Target,
    analytic: IKResult,
    nlp: IKResult,
    *,
    joint_tolerance: float = 1e-4,
    options: IKOptions | None = None,
) -> CrossCheck:
    """Compare a closed-form result and an NLP result for the same target (see :func:`cross_check`).

    Args:
        robot: The robot.
        target: The target both solved.
        analytic: The closed form's result (``solve_ik(..., method="analytic")``).
        nlp: The NLP's result.
        joint_tolerance: As for :func:`cross_check` [rad, m].
        options: The tolerances applied to the closed-form solutions.

    Returns:
        The comparison.
    """
    options = options or IKOptions()

    def reaches(position_error: float, orientation_error: float) -> bool:
        return position_error <= options.position_tolerance and orientation_error <= options.orientation_tolerance

    for sol in analytic.within_limits:
        if not reaches(sol.position_error, sol.orientation_error):
            return CrossCheck(
                False, "analytic_inaccurate",
                f"closed-form branch {sol.label} misses the target by {sol.position_error:.3g} m, "
                f"{sol.orientation_error:.3g} rad (Pinocchio FK)",
                nlp, analytic, sol.label, None, False, sol.position_error, sol.orientation_error,
            )  # fmt: skip
    within = analytic.within_limits
    nearest = min(analytic.solutions, key=lambda s: joint_distance(robot, nlp.q, s.q), default=None)
    distance = None if nearest is None else joint_distance(robot, nlp.q, nearest.q)
    a_pe = None if nearest is None else nearest.position_error
    a_oe = None if nearest is None else nearest.orientation_error
    # At a singular branch (e.g. fully stretched) a task error e allows joint deviations of
    # order sqrt(e), beyond any linear bound: like redundancy, only "both reach" can be asked.
    redundant = nlp.success and (
        task_rank(robot, target, nlp.q) < robot.dof
        or (nearest is not None and task_rank(robot, target, nearest.q) < robot.dof)
    )
    branch = None if nearest is None else nearest.label

    def check(agree: bool, verdict: str, reason: str) -> CrossCheck:
        return CrossCheck(agree, verdict, reason, nlp, analytic, branch, distance, redundant, a_pe, a_oe)

    # Near a singularity a configuration within the task tolerance may lie error / sigma_min away.
    slack = joint_tolerance
    if nlp.success and nearest is not None:
        slack = max(
            joint_tolerance, 10.0 * joint_slack(robot, target, nearest.q, nlp.position_error, nlp.orientation_error)
        )
    if nlp.success and distance is not None and distance <= slack:
        if not nearest.within_limits:
            return check(
                False,
                "mismatch",
                f"the NLP answer is branch {branch} (distance {distance:.3g}), which the "
                "closed form marks outside the joint limits, yet it lies within them",
            )
        return check(True, "match", f"the NLP answer is closed-form branch {branch} (joint distance {distance:.3g})")
    if nlp.success and within:
        if redundant:
            return check(
                True,
                "both_reach",
                f"both reach the target; the arm is redundant or singular there (nearest "
                f"branch {branch} at joint distance {distance:.3g})",
            )
        return check(
            False,
            "mismatch",
            f"the NLP reaches the target at {np.round(nlp.q, 6).tolist()}, "
            f"{distance:.3g} from the nearest closed-form branch {branch}",
        )
    if nlp.success:
        note = " (the arm is redundant for this target; the closed form searched its free joints)"
        return check(
            False,
            "analytic_missed",
            f"the NLP reaches the target within limits at "
            f"{np.round(nlp.q, 6).tolist()}; the closed form says {analytic.status}"
            f"{note if redundant else ''}: {analytic.reason}",
        )
    if within:
        return check(
            False,
            "nlp_failed",
            f"the closed form reaches the target ({within[0].label}); the NLP did not: {nlp.reason}",
        )
    return check(
        True, "both_unreachable", f"neither reaches the target: closed form {analytic.status}, NLP {nlp.status}"
    )
