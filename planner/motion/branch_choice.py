"""IK branch choice for Cartesian waypoints and line samples.

:class:`TargetSolver` asks :func:`planner.solve_ik`, the one IK entry point: the closed form
where the arm belongs to one of its families, else the CasADi NLP.
For a waypoint it picks, among the solutions within the joint limits, one free of collisions
(with a checker), clear of singularities and nearest the previous configuration, and says which branch it took
(:class:`IKChoice`); along a path it tracks the solution nearest the previous sample.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planner.collision.checker import CollisionChecker
from planner.core.arrays import read_only
from planner.exceptions import InvalidArgumentError, PlanningError
from planner.geometry.target import Target
from planner.ik.options import IKOptions
from planner.ik.solve import solve_ik
from planner.ik.solvers import IKSolvers
from planner.ik.status import IKStatus
from planner.model.robot import Robot, Task
from planner.motion.singularity import inverse_condition_threshold

__all__ = ["IKChoice", "TargetSolver"]

_DEFAULT = IKOptions()
_NEAR_SEED = IKOptions(near_seed=True)


@dataclass(frozen=True)
class IKChoice:
    """The configuration chosen for one Cartesian target.

    Attributes:
        q: Joint values, shape (dof,) [rad or m].
        branch: Closed-form branch name (e.g. ``"front/elbow-up"``), or ``"nlp"``.
        singular: Whether it is below the singularity threshold (kept and flagged: no clear
            solution within the limits exists).
        inverse_condition: Its inverse condition number.
        alternatives: How many other solutions within the limits there were.
        position_error: Tip distance to the target by Pinocchio's FK [m].
    """

    q: np.ndarray
    branch: str
    singular: bool
    inverse_condition: float
    alternatives: int
    position_error: float


class TargetSolver:
    """IK for waypoints and line samples: closed form where possible, else NLP.

    Attributes:
        robot: The robot.
        method: ``"analytic"`` or ``"nlp"``.
        threshold: Inverse condition number below which a solution counts as singular.
        task: Task Jacobian for that measure.
    """

    def __init__(
        self, robot: Robot, *, threshold: float | None = None, task: Task | None = None, method: str | None = None
    ):
        """Build the solver.

        Args:
            robot: The robot.
            threshold: Inverse condition number below which a solution is avoided if possible;
                None is the task's default (:func:`planner.motion.singularity.inverse_condition_threshold`).
            task: ``"position"`` or ``"pose"``; None as the robot chooses.
            method: ``"analytic"``, ``"nlp"`` or None (closed form when the chain allows).

        Raises:
            InvalidArgumentError: On an unknown method or a threshold outside [0, 1).
            UnsupportedChainError: If ``method="analytic"`` and the chain has no closed form.
        """
        if method not in (None, "analytic", "nlp"):
            raise InvalidArgumentError(f"unknown IK method {method!r}; valid: analytic, nlp")
        self.robot = robot
        self.threshold = inverse_condition_threshold(threshold, robot.resolve_task(task))
        self.task = task
        solvers = IKSolvers.of(robot)
        if method == "analytic":
            solvers.require_analytic()  # raises UnsupportedChainError naming the joint
        self.method = "analytic" if method != "nlp" and solvers.analytic is not None else "nlp"
        lo = np.where(np.isfinite(robot.lower), robot.lower, 0.0)
        hi = np.where(np.isfinite(robot.upper), robot.upper, 0.0)
        self._home = (lo + hi) / 2.0

    def _inverse_condition(self, q: np.ndarray) -> float:
        return float(self.robot.conditioning(q, self.task)[0])

    def _error(self, target: Target, q: np.ndarray) -> float:
        return float(np.linalg.norm(self.robot.position(q) - target.position))

    def candidates(
        self,
        target: Target,
        q_near: np.ndarray | None,
        *,
        nearest: bool = False,
        checker: CollisionChecker | None = None,
        allow: Sequence[str] = (),
    ) -> tuple[list[tuple[np.ndarray, str]], str]:
        """Solutions within the limits, ``(q, branch)``, and a reason when there are none.

        Both come from :func:`planner.solve_ik`: the closed form gives every branch; the NLP
        its answer, started from `q_near` (with `nearest`, the solution nearest `q_near`).
        With a `checker`, only solutions that keep the scene's clearance count.
        """
        options = _NEAR_SEED if nearest and q_near is not None else _DEFAULT
        result = solve_ik(self.robot, target, q_near, method=self.method, options=options, checker=checker, allow=allow)
        if result.method == "analytic" and result.success:
            sols = [
                (np.array(s.q, dtype=float), s.label)
                for s in result.solutions
                if s.within_limits and (checker is None or s.clearance >= checker.scene.clearance)
            ]
            return sols, ""
        if result.success:
            return [
                (np.array(result.q, dtype=float), result.solutions[0].label if result.method == "analytic" else "nlp")
            ], ""
        return [], f"{result.status}: {result.reason}"

    def choose(
        self,
        target: Target,
        q_previous: np.ndarray | None,
        *,
        label: str = "target",
        checker: CollisionChecker | None = None,
        allow: Sequence[str] = (),
    ) -> IKChoice:
        """The solution for a waypoint: collision-free, then clear of singularities, then nearest `q_previous`.

        Args:
            target: The Cartesian target.
            q_previous: The configuration before it; None uses the middle of the joint ranges.
            label: How to name the target in an error message.
            checker: Checks each solution against the arm itself and a scene; solutions
                closer than the scene's clearance are skipped (the NLP restarts from other
                seeds to find one that is not). None checks nothing.
            allow: Scene bodies the arm may touch at this target.

        Returns:
            The choice.

        Raises:
            InvalidArgumentError: If no solution within the joint limits exists (the message
                carries the solver's reason).
            PlanningError: If every solution collides (the message names the closest pair).
        """
        ref = self._home if q_previous is None else np.asarray(q_previous, dtype=float)
        sols, reason = self.candidates(target, ref, nearest=True, checker=checker, allow=allow)
        if not sols and reason.startswith(IKStatus.IN_COLLISION.value):
            raise PlanningError(
                f"{label} at position {np.round(target.position, 6).tolist()} m: {reason}. "
                "Move the target or the obstacle, or allow contact (allow: [...])"
            )
        if not sols:
            raise InvalidArgumentError(
                f"{label} at position {np.round(target.position, 6).tolist()} m has no IK solution within the joint "
                f"limits of {self.robot.name} ({reason})"
            )
        scored = []
        for q, branch in sols:
            ic = self._inverse_condition(q)
            scored.append((ic < self.threshold, float(np.linalg.norm(q - ref)), q, branch, ic))
        scored.sort(key=lambda s: (s[0], s[1]))
        singular, _, q, branch, ic = scored[0]
        return IKChoice(
            q=read_only(q),
            branch=branch,
            singular=bool(singular),
            inverse_condition=ic,
            alternatives=len(sols) - 1,
            position_error=self._error(target, q),
        )

    def track(self, target: Target, q_previous: np.ndarray) -> np.ndarray | None:
        """The solution nearest `q_previous` (continuation along a path), or None."""
        sols, _ = self.candidates(target, q_previous)
        if not sols:
            return None
        return min((q for q, _ in sols), key=lambda q: float(np.linalg.norm(q - q_previous)))
