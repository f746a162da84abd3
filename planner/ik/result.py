"""The one result type of :func:`planner.solve_ik`, whatever the method.

An :class:`IKResult` holds the chosen answer (``q``, ``success``, ``status``, errors by Pinocchio
forward kinematics, the method, timing) and, where the method yields several, all solutions
found (:class:`IKSolution`: the closed form's branches, or the NLP's distinct converged
answers), each marked within the joint limits or not, sorted by joint distance to the seed.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, fields
from typing import overload

import numpy as np

from planner.core.arrays import read_only
from planner.ik.status import IKStatus

__all__ = ["IKResult", "IKSolution", "LazySolutions"]


@dataclass(frozen=True)
class IKSolution:
    """One configuration that reaches the target (possibly outside the joint limits).

    Equal to another when every field is (``q`` by value); pickles and copies with ``q``
    read-only.

    Attributes:
        q: Joint values, shape (dof,) [rad or m], read-only.
        within_limits: Whether every joint lies within its range.
        label: Where it came from: the closed-form branch (``"front/elbow-up"``), or the NLP
            attempt's kind (``"seed"``, ``"closed_form"``, ``"random"``).
        position_error: Distance of the tip from the target by Pinocchio FK [m].
        orientation_error: Orientation error by Pinocchio FK [rad] (0 for a position target).
        distance: Joint distance to the seed [rad, m mixed; angles modulo 2 pi], or None
            without a seed.
        singular: Whether the configuration is at a singularity, where the method tells
            (closed form), else None.
        clearance: With a collision checker, the distance to the closest body [m] (negative:
            overlapping); else None.
    """

    q: np.ndarray
    within_limits: bool
    label: str
    position_error: float
    orientation_error: float
    distance: float | None = None
    singular: bool | None = None
    clearance: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", read_only(self.q))

    def __eq__(self, other: object) -> bool:
        if other.__class__ is not self.__class__:
            return NotImplemented
        return _same_fields(self, other)

    __hash__ = None  # type: ignore[assignment]

    def __reduce__(self) -> tuple:
        # Through the constructor: the copy's q read-only too.
        return (IKSolution, tuple(getattr(self, f.name) for f in fields(self)))

    def as_dict(self) -> dict:
        """A JSON-ready mapping."""
        return {
            "q": self.q.tolist(),
            "within_limits": self.within_limits,
            "label": self.label,
            "position_error": self.position_error,
            "orientation_error": self.orientation_error,
            "distance": self.distance,
            "singular": self.singular,
            "clearance": self.clearance,
        }


class LazySolutions(Sequence[IKSolution]):
    """The solutions of an IK call, verified by Pinocchio FK when first read.

    Checking every further solution costs a forward kinematics call each, about as much as the
    rest of a fast IK call; a caller who only wants the answer should not pay for it. The list
    is built once, on first access, and then behaves as a tuple.
    """

    __slots__ = ("_build", "_items")

    def __init__(self, build: Callable[[], Sequence[IKSolution]]) -> None:
        self._build: Callable[[], Sequence[IKSolution]] | None = build
        self._items: tuple[IKSolution, ...] | None = None

    def _get(self) -> tuple[IKSolution, ...]:
        if self._items is None:
            assert self._build is not None
            self._items = tuple(self._build())
            self._build = None  # frees what the builder held
        return self._items

    @overload
    def __getitem__(self, index: int) -> IKSolution: ...

    @overload
    def __getitem__(self, index: slice) -> tuple[IKSolution, ...]: ...

    def __getitem__(self, index: int | slice) -> IKSolution | tuple[IKSolution, ...]:
        return self._get()[index]

    def __len__(self) -> int:
        return len(self._get())

    def __iter__(self) -> Iterator[IKSolution]:
        return iter(self._get())

    def __add__(self, other: Sequence[IKSolution]) -> tuple[IKSolution, ...]:
        return self._get() + tuple(other)

    def __eq__(self, other: object) -> bool:
        if isinstance(other, (LazySolutions, tuple)):
            return self._get() == tuple(other)
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return repr(self._get()) if self._items is not None else "LazySolutions(<not yet read>)"

    def __reduce__(self) -> tuple:
        # The builder (a closure over the solver's state) does not pickle: the solutions, built.
        return (_built, (self._get(),))


def _built(items: tuple[IKSolution, ...]) -> LazySolutions:
    """A LazySolutions already read (what a pickled one becomes)."""
    solutions = LazySolutions(tuple)
    solutions._items, solutions._build = items, None
    return solutions


def _same_fields(a: object, b: object) -> bool:
    """Whether two dataclass objects hold equal fields (arrays by shape and value)."""
    for f in fields(a):  # type: ignore[arg-type]
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            if not np.array_equal(x, y, equal_nan=True):
                return False
        elif x != y and not (x != x and y != y):  # NaN errors equal NaN
            return False
    return True


@dataclass(frozen=True)
class IKResult:
    """Outcome of an IK call.

    Equal to another when every field is (``q`` by value, NaN errors equal). Pickling or
    copying (``copy.deepcopy``) first computes what is computed when read (``attempts``,
    ``attempt``, ``solutions``), so the copy is equal whether or not they had been read.

    Attributes:
        q: Joint values, shape (dof,) [rad or m], read-only, always within the joint limits:
            the answer when successful, else the best attempt (NLP) or the seed (closed form,
            when no solution lies within the limits; the solutions are in ``solutions``).
        success: Whether the target is reached within the tolerances, within the limits (and
            above the manipulability floor, when one was asked for).
        status: The outcome (:class:`~planner.ik.status.IKStatus`, a ``str``).
        reason: Why, in a sentence.
        position_error: Distance of the tip from the target by Pinocchio FK [m].
        orientation_error: By Pinocchio FK [rad]: the rotation angle to the target rotation for
            a pose, :func:`planner.geometry.target.pitch_error` of the approach axis for a pitch
            target, 0 for a position target.
        iterations: Iterations run (NLP; 0 for the closed form).
        attempts: Seeds tried (NLP) or solutions found (closed form).
        attempt: Index of the attempt (NLP) or of the solution in the closed form's branch order
            whose answer is returned when successful, else None.
        attempt_kind: ``"seed"``, ``"closed_form"`` or ``"random"`` for that attempt, else None.
        wall_time: Time spent in the call [s].
        method: ``"analytic"`` or ``"nlp"``: which solver answered.
        solutions: Every solution found, within limits or not, nearest to the seed first (a
            sequence of :class:`IKSolution`, verified by Pinocchio FK when first read).
    """

    q: np.ndarray
    success: bool
    status: IKStatus
    reason: str
    position_error: float
    orientation_error: float
    iterations: int
    attempts: int
    attempt: int | None
    attempt_kind: str | None
    wall_time: float
    method: str = "nlp"
    solutions: Sequence[IKSolution] = field(default=())

    def __post_init__(self) -> None:
        object.__setattr__(self, "q", read_only(self.q))
        object.__setattr__(self, "status", IKStatus(self.status))
        if not isinstance(self.solutions, LazySolutions):
            object.__setattr__(self, "solutions", tuple(self.solutions))

    @classmethod
    def from_solver(
        cls,
        q: np.ndarray,
        success: bool,
        status: IKStatus,
        reason: str,
        position_error: float,
        orientation_error: float,
        iterations: int,
        attempts: int,
        attempt: int | None,
        attempt_kind: str | None,
        wall_time: float,
        method: str = "nlp",
        solutions: tuple[IKSolution, ...] | LazySolutions = (),
        counts: Callable[[], tuple[int, int | None]] | None = None,
    ) -> IKResult:
        """The result a solver hands out, built without the constructor's conversions.

        Equal to ``IKResult(...)`` of the same arguments, for a solver whose values are already
        what the constructor would make of them (at a fraction of its cost, which counts in a
        call of a few tens of microseconds).

        Args:
            q: A new float array of shape (dof,) that nothing else references: it is made
                read-only and kept, not copied.
            success: As the attribute.
            status: An :class:`IKStatus`.
            reason: As the attribute.
            position_error: As the attribute [m].
            orientation_error: As the attribute [rad].
            iterations: As the attribute.
            attempts: As the attribute.
            attempt: As the attribute.
            attempt_kind: As the attribute.
            wall_time: As the attribute [s].
            method: As the attribute.
            solutions: A tuple of :class:`IKSolution` or a :class:`LazySolutions`.
            counts: None, or a function giving ``(attempts, attempt)``, called when either is
                first read (then the `attempts` and `attempt` arguments are ignored): for a
                solver that learns them only by building what the caller may never read.
        """
        q.setflags(write=False)
        result = object.__new__(cls)
        # The frozen dataclass's __setattr__ guards users; the solver sets the fields once, directly.
        result.__dict__.update(
            q=q,
            success=success,
            status=status,
            reason=reason,
            position_error=position_error,
            orientation_error=orientation_error,
            iterations=iterations,
            attempts=attempts,
            attempt=attempt,
            attempt_kind=attempt_kind,
            wall_time=wall_time,
            method=method,
            solutions=solutions,
        )
        if counts is not None:
            del result.__dict__["attempts"], result.__dict__["attempt"]
            result.__dict__["_counts"] = counts
        return result

    def __getattr__(self, name: str):
        # Only reached for attributes not set: the counts from_solver left to compute when read.
        counts = self.__dict__.get("_counts")
        if counts is None or name not in ("attempts", "attempt"):
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        self.__dict__["attempts"], self.__dict__["attempt"] = counts()
        del self.__dict__["_counts"]
        return self.__dict__[name]

    def __eq__(self, other: object) -> bool:
        if other.__class__ is not self.__class__:
            return NotImplemented
        return _same_fields(self, other)

    __hash__ = None  # type: ignore[assignment]

    def __reduce__(self) -> tuple:
        # Every field read (the lazy counts computed, the solutions built: their builders are
        # closures that do not pickle), through the constructor (q read-only in the copy too).
        return (IKResult, tuple(getattr(self, f.name) for f in fields(self)))

    @property
    def within_limits(self) -> tuple[IKSolution, ...]:
        """The solutions within the joint limits, nearest to the seed first."""
        return tuple(s for s in self.solutions if s.within_limits)

    def as_dict(self) -> dict:
        """A JSON-ready mapping (``q`` as a list, the wall time as ``time_ms``)."""
        return {
            "method": self.method,
            "success": self.success,
            "status": self.status.value,
            "reason": self.reason,
            "q": self.q.tolist(),
            "position_error": self.position_error,
            "orientation_error": self.orientation_error,
            "iterations": self.iterations,
            "attempts": self.attempts,
            "attempt": self.attempt,
            "attempt_kind": self.attempt_kind,
            "time_ms": self.wall_time * 1e3,
            "solutions": [s.as_dict() for s in self.solutions],
        }
