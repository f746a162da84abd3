"""Many targets as arrays: :class:`BatchTargets`, checked once for a batch IK call."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from planner.core.arrays import float_array, read_only
from planner.core.rotations import ORTHONORMAL_TOL
from planner.exceptions import InvalidArgumentError, PlannerError
from planner.geometry.target import Target, as_target

__all__ = ["TARGET_KINDS", "BatchTargets"]

#: The kinds of target, as :attr:`Target.kind <planner.geometry.target.Target.kind>` names them.
TARGET_KINDS = ("position", "pose", "pitch")


class BatchTargets:
    """N targets as arrays, checked once (vectorised for arrays of positions or poses).

    Attributes:
        positions: Shape (N, 3) [m].
        rotations: Shape (N, 3, 3); identity rows for targets without a rotation.
        pitches: Shape (N,) approach pitches [rad]; 0 for targets without one.
        kinds: Shape (N,) ``"position"``, ``"pose"`` or ``"pitch"``.
    """

    def __init__(self, positions: np.ndarray, rotations: np.ndarray, pitches: np.ndarray, kinds: np.ndarray) -> None:
        """Targets from arrays, checked (vectorised): shapes, kinds, finite values, proper rotations.

        Raises:
            InvalidArgumentError: Naming the first bad target.
        """
        try:
            positions = np.array(positions, dtype=float)
            rotations = np.array(rotations, dtype=float)
            pitches = np.array(pitches, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InvalidArgumentError(f"targets must be numbers: {exc}") from exc
        kinds = np.array(kinds, dtype=object)
        n = len(positions) if positions.ndim else 0
        shapes = {"positions": (n, 3), "rotations": (n, 3, 3), "pitches": (n,), "kinds": (n,)}
        for label, arr in (("positions", positions), ("rotations", rotations), ("pitches", pitches), ("kinds", kinds)):
            if arr.shape != shapes[label]:
                raise InvalidArgumentError(f"{label} must have shape {shapes[label]}, got {arr.shape}")
        unknown = ~np.isin(kinds, TARGET_KINDS)
        if unknown.any():
            i = int(np.argmax(unknown))
            raise InvalidArgumentError(f"target {i}: unknown kind {kinds[i]!r}; valid: {', '.join(TARGET_KINDS)}")
        values = np.hstack([positions, rotations.reshape(n, 9), pitches[:, None]])
        bad = ~np.isfinite(values).all(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            raise InvalidArgumentError(f"target {i} holds NaN or infinite values: {values[i].tolist()}")
        pose = np.flatnonzero(kinds == "pose")
        if len(pose):
            rot = rotations[pose]
            deviation = np.abs(np.swapaxes(rot, 1, 2) @ rot - np.eye(3)).max(axis=(1, 2))
            det = np.linalg.det(rot)
            bad = (deviation > ORTHONORMAL_TOL) | (det < 0)
            if bad.any():
                j = int(np.argmax(bad))
                raise InvalidArgumentError(
                    f"target {int(pose[j])}: rotation is not a proper orthonormal matrix "
                    f"(|R^T R - I| = {deviation[j]:.3g}, det = {det[j]:.6g})"
                )
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
        if isinstance(targets, np.ndarray):
            if targets.dtype != object:
                return cls._from_array(targets)
            targets = list(targets)
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
        arr = float_array(arr, "targets", "numbers")
        n = len(arr) if arr.ndim else 0
        if arr.ndim == 2 and arr.shape[1] == 3:
            return cls(arr, np.tile(np.eye(3), (n, 1, 1)), np.zeros(n), np.full(n, "position", dtype=object))
        if arr.ndim == 3 and arr.shape[1:] == (4, 4):
            return cls(arr[:, :3, 3], arr[:, :3, :3], np.zeros(n), np.full(n, "pose", dtype=object))
        raise InvalidArgumentError(
            f"targets must have shape (N, 3) (positions [m]) or (N, 4, 4) (poses), got {arr.shape}"
        )

    def target(self, i: int) -> Target:
        """Target ``i`` as a :class:`~planner.geometry.target.Target`."""
        kind = self.kinds[i]
        if kind == "pose":
            return Target(self.positions[i], rotation=self.rotations[i])
        return Target(self.positions[i], pitch=float(self.pitches[i]) if kind == "pitch" else None)
