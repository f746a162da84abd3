"""Many targets as arrays: :class:`BatchTargets`, checked once for a batch IK call."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from planner.core.arrays import read_only
from planner.core.rotations import ORTHONORMAL_TOL
from planner.exceptions import InvalidArgumentError, PlannerError
from planner.geometry.target import Target, as_target

__all__ = ["BatchTargets"]


class BatchTargets:
    """N targets as arrays, checked once (vectorised for arrays of positions or poses).

    Attributes:
        positions: Shape (N, 3) [m].
        rotations: Shape (N, 3, 3); identity rows for targets without a rotation.
        pitches: Shape (N,) approach pitches [rad]; 0 for targets without one.
        kinds: Shape (N,) ``"position"``, ``"pose"`` or ``"pitch"``.
    """

    def __init__(self, positions: np.ndarray, rotations: np.ndarray, pitches: np.ndarray, kinds: np.ndarray) -> None:
        self.positions = read_only(positions)
        self.rotations = read_only(rotations)
        self.pitches = read_only(pitches)
        self.kinds = read_only(kinds, None)

    def __len__(self) -> int:
        return len(self.positions)

    @classmethod
    def of(cls, targets: BatchTargets | Sequence[Target | Sequence[float] | np.ndarray] | np.ndarray) -> BatchTargets:
        """Targets from a :class:`BatchTargets`, an array, or a sequence of targets.

        Args:
            targets: Positions (N, 3) [m], poses (N, 4, 4) [m], or a sequence of
                :class:`~planner.geometry.target.Target`, positions (3,) or poses (4, 4).

        Raises:
            InvalidArgumentError: Naming the first bad target: NaN or infinite values, a
                rotation that is not orthonormal, or a wrong shape.
        """
        if isinstance(targets, BatchTargets):
            return targets
        if isinstance(targets, np.ndarray) and targets.dtype != object:
            return cls._from_array(targets)
        if not isinstance(targets, Sequence) or isinstance(targets, str):
            raise InvalidArgumentError(
                f"targets must be an array of positions (N, 3) or poses (N, 4, 4), or a sequence of targets, "
                f"got {type(targets).__name__}"
            )
        n = len(targets)
        positions, rotations = np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1))
        pitches, kinds = np.zeros(n), np.empty(n, dtype=object)
        for i, item in enumerate(targets):
            try:
                target = as_target(item)
            except PlannerError as exc:
                raise InvalidArgumentError(f"target {i}: {exc}") from exc
            positions[i] = target.position
            if target.rotation is not None:
                rotations[i] = target.rotation
            elif target.pitch is not None:
                pitches[i] = target.pitch
            kinds[i] = target.kind
        return cls(positions, rotations, pitches, kinds)

    @classmethod
    def _from_array(cls, arr: np.ndarray) -> BatchTargets:
        try:
            arr = np.asarray(arr, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InvalidArgumentError(f"targets must be numbers, got {arr!r}") from exc
        if arr.ndim == 2 and arr.shape[1] == 3:
            positions, rotations, kind = arr.copy(), np.tile(np.eye(3), (len(arr), 1, 1)), "position"
        elif arr.ndim == 3 and arr.shape[1:] == (4, 4):
            positions, rotations, kind = arr[:, :3, 3].copy(), arr[:, :3, :3].copy(), "pose"
        else:
            raise InvalidArgumentError(
                f"targets must have shape (N, 3) (positions [m]) or (N, 4, 4) (poses), got {arr.shape}"
            )
        bad = ~np.isfinite(arr.reshape(len(arr), arr[0].size if len(arr) else 0)).all(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            raise InvalidArgumentError(f"target {i} holds NaN or infinite values: {arr[i].tolist()}")
        if kind == "pose":
            deviation = np.abs(np.swapaxes(rotations, 1, 2) @ rotations - np.eye(3)).max(axis=(1, 2))
            bad = (deviation > ORTHONORMAL_TOL) | (np.linalg.det(rotations) < 0)
            if bad.any():
                i = int(np.argmax(bad))
                raise InvalidArgumentError(
                    f"target {i}: rotation is not a proper orthonormal matrix (|R^T R - I| = {deviation[i]:.3g}, "
                    f"det = {np.linalg.det(rotations[i]):.6g})"
                )
        kinds = np.full(len(arr), kind, dtype=object)
        return cls(positions, rotations, np.zeros(len(arr)), kinds)

    def target(self, i: int) -> Target:
        """Target ``i`` as a :class:`~planner.geometry.target.Target`."""
        kind = self.kinds[i]
        if kind == "pose":
            return Target(self.positions[i], rotation=self.rotations[i])
        return Target(self.positions[i], pitch=float(self.pitches[i]) if kind == "pitch" else None)
