"""The IK solvers of one robot, built once and kept in the robot's derived-object cache.

:meth:`IKSolvers.of` returns the robot's solvers: the closed form (or the reason the arm has
none) and the numerical solver, each built on first use. They live in
``robot.derived`` (:class:`~planner.model.derived.DerivedCache`), so they are freed with the robot;
no module-level cache keeps robots alive.
"""

from __future__ import annotations

from planner.exceptions import UnsupportedChainError
from planner.ik.analytic import AnalyticIK, closed_form_solver
from planner.ik.numeric.solver import NlpIK
from planner.model.robot import Robot

__all__ = ["IKSolvers"]


class IKSolvers:
    """The closed-form and numerical solvers of one robot, built on first use.

    Attributes:
        robot: The robot.
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self._nlp: NlpIK | None = None
        self._analytic: AnalyticIK | None = None
        self._analytic_reason: str | None = None

    @classmethod
    def of(cls, robot: Robot) -> IKSolvers:
        """The robot's solvers (one object per robot, cached in ``robot.derived``)."""
        return robot.derived.get(cls, lambda: cls(robot))

    @property
    def nlp(self) -> NlpIK:
        """The numerical solver (any chain)."""
        if self._nlp is None:
            self._nlp = NlpIK(self.robot)
        return self._nlp

    def _detect(self) -> None:
        if self._analytic is None and self._analytic_reason is None:
            try:
                self._analytic = closed_form_solver(self.robot)
                self._analytic_reason = ""
            except UnsupportedChainError as exc:
                self._analytic_reason = str(exc)

    @property
    def analytic(self) -> AnalyticIK | None:
        """The closed-form solver, or None when the chain is outside the closed-form families."""
        if self._analytic_reason is None:
            self._detect()
        return self._analytic

    @property
    def analytic_reason(self) -> str:
        """Why the chain has no closed form ("" when it has one)."""
        self._detect()
        return self._analytic_reason or ""

    def require_analytic(self) -> AnalyticIK:
        """The closed-form solver.

        Raises:
            UnsupportedChainError: If the chain has none (the message says why).
        """
        solver = self.analytic
        if solver is None:
            raise UnsupportedChainError(
                f"{self.robot.name} has no closed-form IK: {self.analytic_reason}; use the method 'nlp' (or "
                "'auto', which takes the closed form where an arm has one)"
            )
        return solver

    def __repr__(self) -> str:
        return f"IKSolvers(robot={self.robot.name!r})"
