"""The outcome of a batch IK call: :class:`BatchIKResult`, arrays over targets that read as IKResults."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import overload

import numpy as np

from planner.core.arrays import read_only
from planner.geometry.joint_space import wrapped_distance
from planner.ik.result import IKResult, IKSolution

__all__ = ["BatchIKResult"]


class BatchIKResult(Sequence[IKResult]):
    """The outcomes of N targets as arrays; item ``i`` is target i's :class:`IKResult`.

    Attributes:
        q: Shape (N, dof) [rad or m], read-only, within the joint limits: the answer where
            solved, else the best attempt.
        success: Shape (N,) bool.
        status: Shape (N,) :class:`~planner.ik.status.IKStatus` values (object array).
        position_error: Shape (N,) by Pinocchio FK [m].
        orientation_error: Shape (N,) by Pinocchio FK [rad].
        iterations: Shape (N,) Gauss-Newton steps run per target.
        attempts: Shape (N,) starting configurations tried per target.
        attempt: Shape (N,) index of the attempt that answered, -1 where none did.
        seeded: Whether attempt 0 of every target was its seed (else every attempt is a
            restart from the fixed random starts).
        wall_time: Time of the whole batch [s] (each item's ``wall_time`` is its share, the
            time over N).
        limit: What ended the restarts of the targets not solved: ``"attempt cap"`` or
            ``"time budget"``.
    """

    def __init__(
        self,
        q: np.ndarray,
        success: np.ndarray,
        status: np.ndarray,
        position_error: np.ndarray,
        orientation_error: np.ndarray,
        iterations: np.ndarray,
        attempts: np.ndarray,
        attempt: np.ndarray,
        *,
        seeded: bool,
        wall_time: float,
        limit: str = "attempt cap",
        seeds: np.ndarray | None = None,
        angular: Sequence[bool] = (),
        results: Sequence[IKResult] | None = None,
    ) -> None:
        self.q = read_only(q)
        self.success = read_only(success, None)
        self.status = read_only(status, None)
        self.position_error = read_only(position_error)
        self.orientation_error = read_only(orientation_error)
        self.iterations = read_only(iterations, None)
        self.attempts = read_only(attempts, None)
        self.attempt = read_only(attempt, None)
        self.seeded = seeded
        self.wall_time = wall_time
        self.limit = limit
        self._seeds = seeds
        self._angular = list(angular)
        self._results = None if results is None else tuple(results)

    @classmethod
    def from_results(cls, results: Sequence[IKResult], dof: int, wall_time: float) -> BatchIKResult:
        """Arrays over single-call results (kept, with their solutions, as the items)."""
        n = len(results)
        return cls(
            np.array([r.q for r in results], dtype=float).reshape(n, dof),
            np.array([r.success for r in results], dtype=bool),
            np.array([r.status for r in results], dtype=object),
            np.array([r.position_error for r in results], dtype=float),
            np.array([r.orientation_error for r in results], dtype=float),
            np.array([r.iterations for r in results], dtype=int),
            np.array([r.attempts for r in results], dtype=int),
            np.array([-1 if r.attempt is None else r.attempt for r in results], dtype=int),
            seeded=any(r.attempt_kind == "seed" for r in results),
            wall_time=wall_time,
            results=results,
        )

    def __len__(self) -> int:
        return len(self.q)

    @property
    def solve_rate(self) -> float:
        """Share of the targets solved (1.0 for an empty batch)."""
        return float(np.mean(self.success)) if len(self) else 1.0

    def attempt_kind(self, i: int) -> str | None:
        """``"seed"`` or ``"random"`` for the attempt that answered target i, None if none did."""
        a = int(self.attempt[i])
        if a < 0:
            return None
        return "seed" if a == 0 and self.seeded else "random"

    def reason(self, i: int) -> str:
        """Why target i got its status, in a sentence (as a single call says it)."""
        if self._results is not None:
            return self._results[i].reason
        if self.success[i]:
            return f"reached by attempt {int(self.attempt[i])} ({self.attempt_kind(i)})"
        return (
            f"none of {int(self.attempts[i])} attempts reached the target before the {self.limit} ran out (best: "
            f"position error {self.position_error[i]:.3g} m, orientation error {self.orientation_error[i]:.3g} rad); "
            "it may be out of reach"
        )

    def _item(self, i: int) -> IKResult:
        if self._results is not None:
            return self._results[i]
        q = self.q[i]
        solutions: tuple[IKSolution, ...] = ()
        if self.success[i]:
            distance = None if self._seeds is None else wrapped_distance(q, self._seeds[i], self._angular)
            solutions = (
                IKSolution(
                    q,
                    True,
                    self.attempt_kind(i) or "random",
                    float(self.position_error[i]),
                    float(self.orientation_error[i]),
                    distance,
                ),
            )
        return IKResult(
            q,
            bool(self.success[i]),
            self.status[i],
            self.reason(i),
            float(self.position_error[i]),
            float(self.orientation_error[i]),
            int(self.iterations[i]),
            int(self.attempts[i]),
            None if self.attempt[i] < 0 else int(self.attempt[i]),
            self.attempt_kind(i),
            self.wall_time / max(len(self), 1),
            solutions=solutions,
        )

    @overload
    def __getitem__(self, index: int) -> IKResult: ...

    @overload
    def __getitem__(self, index: slice) -> list[IKResult]: ...

    def __getitem__(self, index: int | slice) -> IKResult | list[IKResult]:
        if isinstance(index, slice):
            return [self._item(i) for i in range(len(self))[index]]
        i = int(index)
        if not -len(self) <= i < len(self):
            raise IndexError(f"target index {index} out of range for {len(self)} targets")
        return self._item(i % len(self))

    def __iter__(self) -> Iterator[IKResult]:
        return (self._item(i) for i in range(len(self)))

    def __repr__(self) -> str:
        return f"BatchIKResult({len(self)} targets, {int(np.sum(self.success))} solved, {self.wall_time:.3g} s)"
