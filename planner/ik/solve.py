"""One entry point for inverse kinematics, and the closed-form vs numerical cross-check.

:func:`solve_ik` picks the method: ``"analytic"`` (the closed form of
:mod:`planner.ik.analytic`, for the seed arms' families), ``"nlp"`` (:class:`~planner.ik.numeric.solver.NlpIK`,
any URDF) or ``"auto"`` (the closed form where the arm and target kind have one, else the
NLP). Both answer with an :class:`~planner.ik.numeric.solver.IKResult` whose errors are Pinocchio's. The
solvers are built once per robot and cached on the robot object.

:func:`cross_check` solves one target both ways and says whether they agree: the NLP answer
coincides with one of the closed-form branches (joint-space distance, angles modulo 2 pi), or,
where the arm is redundant (or singular) for the target, both reach it; or both find the
target out of reach. Any other outcome is a bug in one of the two solvers, and the
:class:`CrossCheck` says which way they differ.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from planner.exceptions import InvalidArgumentError, UnsupportedChainError
from planner.geometry.target import Target, as_target, target_errors
from planner.ik.numeric.solver import NlpIK
from planner.ik.options import IKOptions
from planner.ik.result import IKResult
from planner.model.robot import Robot

__all__ = [
    "CrossCheck",
    "IKMethod",
    "analytic_solver",
    "compare",
    "cross_check",
    "joint_distance",
    "nlp_solver",
    "solve_ik",
    "task_rank",
]

IKMethod = Literal["auto", "analytic", "nlp"]

# The solvers are cached on the robot object itself: a solver refers to its robot, so a global
# (even weak-keyed) dictionary would keep every robot alive; an attribute forms a plain cycle
# that goes with the robot.
_NLP_ATTRIBUTE = "_planner_nlp_ik"
_ANALYTIC_ATTRIBUTE = "_planner_analytic_ik"


def nlp_solver(robot: Robot) -> NlpIK:
    """The robot's numerical solver, built on first use and then reused."""
    solver = getattr(robot, _NLP_ATTRIBUTE, None)
    if solver is None:
        solver = NlpIK(robot)
        setattr(robot, _NLP_ATTRIBUTE, solver)
    return solver


def analytic_solver(robot: Robot):
    """The robot's closed-form solver (:class:`planner.ik.analytic.AnalyticIK`), or None.

    None when the chain is outside the closed-form families. Built once per robot.
    """
    solver = getattr(robot, _ANALYTIC_ATTRIBUTE, None)
    if solver is None:
        from planner.ik.analytic import AnalyticIK

        try:
            solver = AnalyticIK.from_robot(robot)
        except UnsupportedChainError as exc:
            solver = str(exc)  # why there is none
        setattr(robot, _ANALYTIC_ATTRIBUTE, solver)
    return None if isinstance(solver, str) else solver


def _analytic_reason(robot: Robot) -> str:
    solver = getattr(robot, _ANALYTIC_ATTRIBUTE, None)
    return solver if isinstance(solver, str) else ""


def joint_distance(robot: Robot, q_a: np.ndarray, q_b: np.ndarray) -> float:
    """Joint-space distance, angle differences taken modulo 2 pi (prismatic ones as they are).

    Args:
        robot: The robot (for its joint kinds).
        q_a: Shape (dof,) [rad or m].
        q_b: Shape (dof,) [rad or m].

    Returns:
        The Euclidean norm of the wrapped differences [rad, m mixed].
    """
    diff = np.asarray(q_a, dtype=float) - np.asarray(q_b, dtype=float)
    angular = np.array([k != "prismatic" for k in robot.joint_kinds])
    diff[angular] = (diff[angular] + math.pi) % (2 * math.pi) - math.pi
    return float(np.linalg.norm(diff))


def _analytic_result(robot: Robot, target: Target, q_seed: np.ndarray | None):
    """The closed-form result, or None when the arm or this target kind has no closed form."""
    solver = analytic_solver(robot)
    if solver is None:
        return None
    try:
        return solver.solve(target, q_seed)
    except UnsupportedChainError:
        return None


def _from_analytic(
    robot: Robot,
    target: Target,
    result,
    q_seed: np.ndarray | None,
    position_tolerance: float,
    orientation_tolerance: float,
    start: float,
) -> IKResult:
    """An :class:`IKResult` of a closed-form answer, its errors by Pinocchio FK."""
    best = result.best
    if best is not None:
        q = np.array(best.q, dtype=float)
        index = result.solutions.index(best)
    else:
        # No solution within the limits: report the first one clipped into them (or the seed),
        # so q keeps its promise of lying within the limits.
        index = None
        if result.solutions:
            q = np.array(result.solutions[0].q, dtype=float)
        elif q_seed is not None:
            q = np.array(q_seed, dtype=float)
        else:
            q = np.zeros(robot.dof)
        lo = np.where(np.isfinite(robot.lower), robot.lower, -math.pi)
        hi = np.where(np.isfinite(robot.upper), robot.upper, math.pi)
        q = np.clip(q, lo, hi)
    position_error, orientation_error = target_errors(robot, target, q)
    success = best is not None and position_error <= position_tolerance and orientation_error <= orientation_tolerance
    if best is not None and not success:
        status = "inaccurate"
        reason = (
            f"the closed-form solution ({best.branch}) misses the target by {position_error:.3g} m and "
            f"{orientation_error:.3g} rad by Pinocchio FK"
        )
    else:
        status = "solved" if success else result.status
        reason = f"closed-form branch {best.branch}" if success else result.reason
    return IKResult(
        q=q,
        success=success,
        status=status,
        reason=reason,
        position_error=position_error,
        orientation_error=orientation_error,
        iterations=0,
        attempts=len(result.solutions),
        attempt=index if success else None,
        attempt_kind="closed_form" if success else None,
        wall_time=time.perf_counter() - start,
        method="analytic",
    )


def _branch_seeds(robot: Robot, target: Target, q_seed: np.ndarray | None) -> np.ndarray | None:
    result = _analytic_result(robot, target, q_seed)
    if result is None or not result.solutions:
        return None
    return np.array([s.q for s in result.solutions], dtype=float)


def solve_ik(
    robot: Robot,
    target: Target | Sequence[float] | np.ndarray,
    q_seed: Sequence[float] | np.ndarray | None = None,
    *,
    method: IKMethod = "auto",
    closed_form_seeds: bool = True,
    position_tolerance: float = 1e-6,
    orientation_tolerance: float = 1e-6,
    **nlp_options,
) -> IKResult:
    """Joint values that put the tip on a target, by closed form or numerically.

    Args:
        robot: The robot.
        target: A :class:`Target`, a position (3,) [m] or a pose (4, 4) [m].
        q_seed: Current or starting configuration (dof,) [rad or m], within the limits; the
            closed form sorts its branches by distance to it, the NLP starts from it.
        method: ``"analytic"``, ``"nlp"``, or ``"auto"``: the closed form where the arm and
            the target kind have one, else the NLP; and the NLP (started from the seed and the
            branches) also when every closed-form branch lies outside the joint limits and the
            arm is redundant for the target: the closed form searches the free joints (approach
            pitch, wrist roll) on its ideal geometry, sampling the roll, so a solution at the
            very edge of the limits can still escape it.
        closed_form_seeds: For ``"nlp"``, also start from the closed-form branches where there
            are some (reported as ``"closed_form"`` attempts).
        position_tolerance: Success threshold on the position error [m].
        orientation_tolerance: Success threshold on the orientation error [rad].
        **nlp_options: Further options of :meth:`NlpIK.solve` (``time_budget``,
            ``max_attempts``, ``near_seed``, ``manipulability_floor``, ``rng``, ...); not used
            by the closed form.

    Returns:
        The result (``method`` says which solver answered). For the closed form, ``status`` is
        ``"solved"``, one of :mod:`planner.ik.analytic`'s statuses (``"beyond_max_reach"``, ...),
        or ``"inaccurate"`` if Pinocchio FK disagrees with the closed form.

    Raises:
        InvalidArgumentError: On an unknown method, bad target or options.
        UnsupportedChainError: For ``"analytic"`` on an arm or target kind without a closed form.
        InvalidConfigurationError: If `q_seed` has the wrong length or NaN values.
        JointLimitError: If `q_seed` is outside the joint limits.
    """
    start = time.perf_counter()
    if method not in ("auto", "analytic", "nlp"):
        raise InvalidArgumentError(f"unknown IK method {method!r}; valid: auto, analytic, nlp")
    target = as_target(target)
    nlp = nlp_solver(robot)
    seed = nlp.check_seed(q_seed)
    if method in ("auto", "analytic"):
        if method == "analytic" and analytic_solver(robot) is None:
            raise UnsupportedChainError(f"{robot.name} has no closed-form IK: {_analytic_reason(robot)}")
        if method == "analytic":
            result = analytic_solver(robot).solve(target, seed)
        else:
            result = _analytic_result(robot, target, seed)
        if result is not None:
            answer = _from_analytic(robot, target, result, seed, position_tolerance, orientation_tolerance, start)
            # Where the arm is redundant for the target, the closed form's search of the free joints
            # may miss a solution at the very edge of the limits: "auto" asks the NLP too.
            if (
                method == "analytic"
                or answer.success
                or result.status != "outside_joint_limits"
                or task_rank(robot, target, np.asarray(result.solutions[0].q)) == robot.dof
            ):
                return answer
            extra = np.array([sol.q for sol in result.solutions], dtype=float)
            options = IKOptions(
                **nlp_options, position_tolerance=position_tolerance, orientation_tolerance=orientation_tolerance
            )
            fallback = nlp.solve(target, seed, options, extra_seeds=extra)
            return fallback if fallback.success else answer
    extra = _branch_seeds(robot, target, seed) if closed_form_seeds else None
    options = IKOptions(
        **nlp_options, position_tolerance=position_tolerance, orientation_tolerance=orientation_tolerance
    )
    return nlp.solve(target, seed, options, extra_seeds=extra)


# ------------------------------------------------------------------------------------ cross-check
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
        analytic_status: The closed form's status.
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
    analytic_status: str
    branch: str | None
    joint_distance: float | None
    redundant: bool
    analytic_position_error: float | None
    analytic_orientation_error: float | None

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


def _task_jacobian(robot: Robot, target: Target, q: np.ndarray) -> np.ndarray:
    """Jacobian of the target's task at ``q``: position rows [m], then orientation rows [rad]."""
    jac = robot.jacobian(q)
    if target.rotation is not None:
        return jac
    if target.pitch is not None:
        a = robot.fk(q)[:3, :3] @ robot.approach_axis
        skew = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
        turning = -skew @ jac[3:]  # d(approach axis)/dq in base axes
        if abs(math.cos(target.pitch)) <= 1e-12:
            return np.vstack([jac[:3], turning[:2]])  # straight up or down: one direction
        # Otherwise the pitch fixes only the elevation asin(a_z) (planner.geometry.target).
        return np.vstack([jac[:3], turning[2:3] / max(math.hypot(a[0], a[1]), 1e-12)])
    return jac[:3]


def task_rank(robot: Robot, target: Target, q: np.ndarray, rtol: float = 1e-6) -> int:
    """Rank of the target's task Jacobian at ``q`` (singular values above rtol times the largest).

    Below the joint count, the configurations reaching the target form a continuum there: the
    arm is redundant for this kind of target, or ``q`` is singular.
    """
    s = np.linalg.svd(_task_jacobian(robot, target, q), compute_uv=False)
    return int(np.sum(s > rtol * s[0])) if s.size and s[0] > 0 else 0


def _joint_slack(robot: Robot, target: Target, q: np.ndarray, position_error: float, orientation_error: float) -> float:
    """How far [rad, m] from ``q`` a configuration with these task errors can lie (error / sigma_min)."""
    s = np.linalg.svd(_task_jacobian(robot, target, q), compute_uv=False)
    if s.size < robot.dof or s[-1] <= 1e-6 * s[0]:
        return 0.0  # not an isolated solution: no distance bound; the redundant case decides
    return math.hypot(position_error, orientation_error) / s[-1]


def cross_check(
    robot: Robot,
    target: Target | Sequence[float] | np.ndarray,
    q_seed: Sequence[float] | np.ndarray | None = None,
    *,
    joint_tolerance: float = 1e-4,
    position_tolerance: float = 1e-6,
    orientation_tolerance: float = 1e-6,
    **nlp_options,
) -> CrossCheck:
    """Solve one target in closed form and with the NLP (started without the branches); compare.

    Args:
        robot: A robot with a closed form.
        target: A :class:`Target`, a position (3,) [m] or a pose (4, 4) [m].
        q_seed: Configuration (dof,) [rad or m]: the NLP's seed and the closed form's current
            configuration (which picks its free joints).
        joint_tolerance: Joint distance [rad, m] within which the NLP answer counts as a
            closed-form branch; near a singularity the bound widens to 10 times the NLP's task
            error over the smallest singular value of the task Jacobian at the branch (the
            distance a configuration with that error can lie from it).
        position_tolerance: Success threshold of both solvers [m].
        orientation_tolerance: Success threshold of both solvers [rad].
        **nlp_options: Options of :meth:`NlpIK.solve` (``time_budget``, ``max_attempts``, ``rng``).

    Returns:
        The comparison.

    Raises:
        UnsupportedChainError: If the arm or target kind has no closed form.
    """
    target = as_target(target)
    nlp = nlp_solver(robot)
    seed = nlp.check_seed(q_seed)
    if analytic_solver(robot) is None:
        raise UnsupportedChainError(f"{robot.name} has no closed-form IK to cross-check: {_analytic_reason(robot)}")
    analytic = analytic_solver(robot).solve(target, seed)
    options = IKOptions(
        **nlp_options, position_tolerance=position_tolerance, orientation_tolerance=orientation_tolerance
    )
    result = nlp.solve(target, seed, options)
    return compare(
        robot,
        target,
        analytic,
        result,
        joint_tolerance=joint_tolerance,
        position_tolerance=position_tolerance,
        orientation_tolerance=orientation_tolerance,
    )


def compare(
    robot: Robot,
    target: Target,
    analytic,
    result: IKResult,
    *,
    joint_tolerance: float = 1e-4,
    position_tolerance: float = 1e-6,
    orientation_tolerance: float = 1e-6,
) -> CrossCheck:
    """Compare a closed-form result and an NLP result for the same target (see :func:`cross_check`).

    Args:
        robot: The robot.
        target: The target both solved.
        analytic: The :class:`planner.ik.analytic.AnalyticResult`.
        result: The NLP's :class:`IKResult`.
        joint_tolerance: As for :func:`cross_check` [rad, m].
        position_tolerance: Success threshold [m] applied to the closed-form solutions.
        orientation_tolerance: Success threshold [rad] applied to the closed-form solutions.

    Returns:
        The comparison.
    """

    def reaches(q: np.ndarray) -> tuple[bool, float, float]:
        pe, oe = target_errors(robot, target, q)
        return pe <= position_tolerance and oe <= orientation_tolerance, pe, oe

    for sol in analytic.solutions:
        if sol.within_limits:
            ok, pe, oe = reaches(np.asarray(sol.q))
            if not ok:
                return CrossCheck(
                    False, "analytic_inaccurate",
                    f"closed-form branch {sol.branch} misses the target by {pe:.3g} m, {oe:.3g} rad (Pinocchio FK)",
                    result, analytic.status, sol.branch, None, False, pe, oe,
                )  # fmt: skip
    within = [s for s in analytic.solutions if s.within_limits]
    nearest = None
    if analytic.solutions:
        nearest = min(analytic.solutions, key=lambda s: joint_distance(robot, result.q, s.q))
    distance = None if nearest is None else joint_distance(robot, result.q, nearest.q)
    a_pe = a_oe = None
    if nearest is not None:
        a_pe, a_oe = target_errors(robot, target, np.asarray(nearest.q))
    # At a singular branch (e.g. fully stretched) a task error e allows joint deviations of
    # order sqrt(e), beyond any linear bound: like redundancy, only "both reach" can be asked.
    redundant = result.success and (
        task_rank(robot, target, result.q) < robot.dof
        or (nearest is not None and task_rank(robot, target, np.asarray(nearest.q)) < robot.dof)
    )
    branch = None if nearest is None else nearest.branch

    def check(agree: bool, verdict: str, reason: str) -> CrossCheck:
        return CrossCheck(agree, verdict, reason, result, analytic.status, branch, distance, redundant, a_pe, a_oe)

    # Near a singularity a configuration within the task tolerance may lie error / sigma_min away.
    slack = joint_tolerance
    if result.success and nearest is not None:
        slack = max(
            joint_tolerance,
            10.0 * _joint_slack(robot, target, np.asarray(nearest.q), result.position_error, result.orientation_error),
        )
    if result.success and distance is not None and distance <= slack:
        if not nearest.within_limits:
            return check(
                False,
                "mismatch",
                f"the NLP answer is branch {branch} (distance {distance:.3g}), which the "
                "closed form marks outside the joint limits, yet it lies within them",
            )
        return check(True, "match", f"the NLP answer is closed-form branch {branch} (joint distance {distance:.3g})")
    if result.success and within:
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
            f"the NLP reaches the target at {np.round(result.q, 6).tolist()}, "
            f"{distance:.3g} from the nearest closed-form branch {branch}",
        )
    if result.success:
        note = " (the arm is redundant for this target; the closed form searched its free joints)"
        return check(
            False,
            "analytic_missed",
            f"the NLP reaches the target within limits at "
            f"{np.round(result.q, 6).tolist()}; the closed form says {analytic.status}"
            f"{note if redundant else ''}: {analytic.reason}",
        )
    if within:
        return check(
            False,
            "nlp_failed",
            f"the closed form reaches the target ({within[0].branch}); the NLP did not: {result.reason}",
        )
    return check(
        True, "both_unreachable", f"neither reaches the target: closed form {analytic.status}, NLP {result.status}"
    )
