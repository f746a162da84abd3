"""IK branch choice for Cartesian waypoints and line samples.

:class:`TargetSolver` wraps the project's two IK solvers (built once per robot by
:mod:`planner.ik.solve`): the closed form (:class:`planner.ik.analytic.AnalyticIK`) where the arm
belongs to one of its families, else the CasADi NLP (:class:`planner.ik.numeric.solver.NlpIK`).
For a waypoint it picks, among the solutions within the joint limits, one clear of
singularities and nearest the previous configuration, and says which branch it took
(:class:`IKChoice`); along a path it tracks the solution nearest the previous sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.core.arrays import read_only
from planner.exceptions import InvalidArgumentError
from planner.geometry.target import Target
from planner.model.robot import Robot, Task

__all__ = ["IKChoice", "TargetSolver"]


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
        self, robot: Robot, *, threshold: float = 1.0 / 30.0, task: Task | None = None, method: str | None = None
    ):
        """Build the solver.

        Args:
            robot: The robot.
            threshold: Inverse condition number below which a solution is avoided if possible.
            task: ``"position"`` or ``"pose"``; None as the robot chooses.
            method: ``"analytic"``, ``"nlp"`` or None (closed form when the chain allows).

        Raises:
            InvalidArgumentError: On an unknown method.
            UnsupportedChainError: If ``method="analytic"`` and the chain has no closed form.
        """
        if method not in (None, "analytic", "nlp"):
            raise InvalidArgumentError(f"unknown IK method {method!r}; valid: analytic, nlp")
        self.robot = robot
        self.threshold = float(threshold)
        self.task = task
        from planner.ik.solve import analytic_solver, nlp_solver

        self._analytic = analytic_solver(robot) if method in (None, "analytic") else None
        if method == "analytic" and self._analytic is None:
            from planner.ik.analytic import AnalyticIK

            AnalyticIK.from_robot(robot)  # raises UnsupportedChainError naming the joint
        self.method = "analytic" if self._analytic is not None else "nlp"
        self._nlp = nlp_solver(robot) if self._analytic is None else None
        lo = np.where(np.isfinite(robot.lower), robot.lower, 0.0)
        hi = np.where(np.isfinite(robot.upper), robot.upper, 0.0)
        self._home = (lo + hi) / 2.0

    def _inverse_condition(self, q: np.ndarray) -> float:
        return float(self.robot.conditioning(q, self.task)[0])

    def _error(self, target: Target, q: np.ndarray) -> float:
        return float(np.linalg.norm(self.robot.position(q) - target.position))

    def candidates(
        self, target: Target, q_near: np.ndarray | None, *, nearest: bool = False
    ) -> tuple[list[tuple[np.ndarray, str]], str]:
        """Solutions within the limits, ``(q, branch)``, and a reason when there are none.

        The closed form gives every branch; the NLP one solution, started from `q_near` (with
        `nearest`, the solution nearest `q_near` among those it finds).
        """
        if self._analytic is not None:
            res = self._analytic.solve(target, q_current=q_near)
            sols = [(np.array(s.q, dtype=float), s.branch) for s in res.solutions if s.within_limits]
            return sols, res.reason or res.status
        if q_near is None:
            res = self._nlp.solve(target)
        else:
            res = self._nlp.solve(target, q_seed=q_near, near_seed=nearest)
        if res.success:
            return [(np.array(res.q, dtype=float), "nlp")], ""
        return [], f"{res.status}: {res.reason}"

    def choose(self, target: Target, q_previous: np.ndarray | None, *, label: str = "target") -> IKChoice:
        """The solution for a waypoint: clear of singularities first, then nearest `q_previous`.

        Args:
            target: The Cartesian target.
            q_previous: The configuration before it; None uses the middle of the joint ranges.
            label: How to name the target in an error message.

        Returns:
            The choice.

        Raises:
            InvalidArgumentError: If no solution within the joint limits exists (the message
                carries the solver's reason).
        """
        ref = self._home if q_previous is None else np.asarray(q_previous, dtype=float)
        sols, reason = self.candidates(target, ref, nearest=True)
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
