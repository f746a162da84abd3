"""Options of an IK call, one frozen object for every method.

The tolerances apply to both methods (success is judged by Pinocchio FK against them); the
remaining fields steer the numerical solver and are ignored by the closed form.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from planner.core.text import plain
from planner.exceptions import InvalidArgumentError

__all__ = ["IKOptions"]


def _positive(label: str, value: object, unit: str) -> None:
    unit = f" [{unit}]" if unit else ""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InvalidArgumentError(f"{label} must be a positive number{unit}, got {plain(value)}")
    if not math.isfinite(value) or value <= 0:
        raise InvalidArgumentError(f"{label} must be a positive finite number{unit}, got {plain(value)}")


@dataclass(frozen=True)
class IKOptions:
    """How an IK call solves and when it counts as solved.

    Attributes:
        position_tolerance: Success threshold on the position error [m].
        orientation_tolerance: Success threshold on the orientation error [rad].
        time_budget: NLP: wall time [s] after which no further batch of restarts starts (the
            batch under way finishes, and at least one batch always runs).
        max_attempts: NLP: cap on the seeds tried (whole batches); None: only the time budget.
        near_seed: NLP: of the solutions found, return the nearest to the seed (angles shifted
            by whole turns towards it where the limits allow); where the arm is redundant for
            the target, the nearest point of the solution set (IPOPT). Needs a seed.
        manipulability_floor: NLP: the answer's manipulability must be at least this; where the
            arm is redundant, IPOPT moves along the solution set to meet it.
        manipulability_task: ``"position"`` or ``"pose"`` for that manipulability; None: pose
            for arms of 6 or more joints, else position.
        closed_form_seeds: NLP: also start from the closed-form branches where the arm has a
            closed form.
        rng: NLP: seed (int) or generator of the random starts; None uses a fixed set drawn once
            per solver from ``numpy.random.default_rng(0)``, so every call is reproducible.

    Raises:
        InvalidArgumentError: On a tolerance, budget or floor that is not a positive number, a
            bad attempt cap, an unknown task, or an rng that is neither an int >= 0 nor a generator.
    """

    position_tolerance: float = 1e-6
    orientation_tolerance: float = 1e-6
    time_budget: float = 0.05
    max_attempts: int | None = None
    near_seed: bool = False
    manipulability_floor: float | None = None
    manipulability_task: Literal["position", "pose"] | None = None
    closed_form_seeds: bool = True
    rng: int | np.random.Generator | None = None

    def __post_init__(self) -> None:
        _positive("position_tolerance", self.position_tolerance, "m")
        _positive("orientation_tolerance", self.orientation_tolerance, "rad")
        _positive("time_budget", self.time_budget, "s")
        if self.max_attempts is not None and (
            isinstance(self.max_attempts, bool)
            or not isinstance(self.max_attempts, (int, np.integer))
            or self.max_attempts < 1
        ):
            raise InvalidArgumentError(
                f"max_attempts must be a positive integer or None, got {plain(self.max_attempts)}"
            )
        if self.manipulability_floor is not None:
            _positive("manipulability_floor", self.manipulability_floor, "")
        if self.manipulability_task not in (None, "position", "pose"):
            raise InvalidArgumentError(
                f"unknown manipulability_task {self.manipulability_task!r}; valid: position, pose"
            )
        if self.rng is not None and (
            isinstance(self.rng, bool) or not isinstance(self.rng, (int, np.integer, np.random.Generator))
        ):
            raise InvalidArgumentError(
                f"rng must be an int seed, a numpy.random.Generator or None, got {type(self.rng).__name__}"
            )
        if isinstance(self.rng, (int, np.integer)) and not isinstance(self.rng, bool) and self.rng < 0:
            raise InvalidArgumentError(f"rng: an int seed must be >= 0 (NumPy's seeds are), got {self.rng}")

    def generator(self) -> np.random.Generator | None:
        """The generator of the random starts: a new one from an int seed, the given one, or None."""
        if self.rng is None or isinstance(self.rng, np.random.Generator):
            return self.rng
        return np.random.default_rng(int(self.rng))
