"""The common interface of the closed-form solvers and the family detection.

:func:`planner.ik.analytic.families.closed_form_solver` reads the robot's chain from its
Pinocchio model and returns the solver of the family it belongs to, trying each family of the
registry (:data:`planner.ik.analytic.families.FAMILIES`):

- :class:`~planner.ik.analytic.planar2.Planar2IK`: two joints about parallel vertical axes (the
  horizontal 2-link of Materick and Shapiro (1997)).
- :class:`~planner.ik.analytic.yaw_planar.YawPlanarIK`: a base yaw, then 2 or 3 parallel pitch
  joints, then optionally a wrist roll (Clothier and Shang (2010), Vaishnav, and Sumadsad (2020), SO-101).

A family says whether a chain fits by :meth:`AnalyticIK.match` (None, or why not). A chain
outside every family raises :class:`~planner.exceptions.UnsupportedChainError` naming the
first joint that breaks the family that fits most of it.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planner.exceptions import InvalidArgumentError, InvalidConfigurationError, UnsupportedChainError
from planner.geometry.chain import ChainAtZero
from planner.geometry.target import Target
from planner.ik.analytic.geometry import angle_to_line
from planner.ik.analytic.nearest import NearestSolution
from planner.ik.analytic.result import AnalyticBatchResult, AnalyticResult
from planner.model.robot import Robot

__all__ = [
    "AnalyticIK",
    "ChainMismatch",
    "base_yaw_mismatch",
    "fill_kernel_inputs",
    "FAMILY_ANGLE_TOL",
    "FLOAT64",
    "SINGLE_AFTER",
]

#: Largest deviation [rad] of an axis from the family's ideal directions (vertical, parallel,
#: perpendicular) that a solver accepts. Deviations above 1e-12 rad (CAD round-off, as in
#: SO-101's URDF) are solved on the ideal geometry and then corrected on the real one.
FAMILY_ANGLE_TOL = 1e-4
#: The dtype of float arrays (a singleton: compared by identity on hot paths).
FLOAT64 = np.dtype(np.float64)
#: Calls of a family's :meth:`AnalyticIK.nearest` of one target kind after which it builds that
#: kind's compiled kernel (:meth:`AnalyticIK._counted_kernel`; compiled to C the first time,
#: then 0.1-0.5 s to build and load from the disk cache): an arm met for a call or two never
#: pays for it. The yaw-planar family's ``solve`` counts its calls the same way
#: (:class:`~planner.ik.analytic.yaw_planar.single.SolveKernels`).
SINGLE_AFTER = 8


@dataclass(frozen=True)
class ChainMismatch:
    """Why a chain is outside a closed-form family.

    Attributes:
        reason: The explanation, naming the joint (without the robot's name).
        joint: Name of the first joint that breaks the family, or None (an empty chain).
        depth: How many leading joints fit the family's pattern: of several families that do
            not fit, the error reports the one that fits the most.
    """

    reason: str
    joint: str | None
    depth: int


def base_yaw_mismatch(chain: ChainAtZero) -> ChainMismatch | None:
    """The check every family starts with: a first joint about the vertical and a second one.

    Args:
        chain: The chain at q = 0.

    Returns:
        None when the chain starts with a base yaw followed by another joint, else why not.
    """
    joints = chain.joints
    if not joints:
        return ChainMismatch("the chain has no joints", None, 0)
    first = joints[0]
    tilt = angle_to_line(first.axis, np.array([0.0, 0.0, 1.0]))
    if tilt > FAMILY_ANGLE_TOL:
        return ChainMismatch(
            f"the first joint {first.name!r} turns about {np.round(first.axis, 6).tolist()}, "
            f"{math.degrees(tilt):.3g} deg from vertical; the closed-form families start with a base "
            "yaw about the base z axis",
            first.name,
            0,
        )
    if len(joints) < 2:
        return ChainMismatch(
            f"the chain has only joint {first.name!r}; the closed-form families need 2 to 5 joints", first.name, 1
        )
    return None


def fill_kernel_inputs(inputs: np.ndarray, position, pitch, rotation, seed) -> None:
    """Write one target into the input vector of a compiled single-target kernel.

    The layout they all take: the position, then the rotation's nine entries row by row or the
    approach pitch (neither for a position target), then the seed at the end where one is given.
    """
    inputs[0:3] = position
    if rotation is not None:
        inputs[3:12] = rotation.ravel()
    elif pitch is not None:
        inputs[3] = pitch
    if seed is not None:
        inputs[-len(seed) :] = seed


class AnalyticIK(ABC):
    """Closed-form inverse kinematics of one robot (one subclass per family).

    Build one with :func:`~planner.ik.analytic.families.closed_form_solver`.

    Attributes:
        robot: The robot the solver was built from.
        family: ``"planar2"`` or ``"yaw_planar"``.
        dof: Number of joints.
        joint_names: Joint names in ``q`` order.
        lower: Lower joint limits [rad], read-only.
        upper: Upper joint limits [rad], read-only.
        branches: Names of the branches, in the order of batch results.
        deviation: Largest deviation [rad] of the model's axes from the family's ideal ones.
    """

    family: str = ""

    def __init__(self, robot: Robot, chain: ChainAtZero) -> None:
        self.robot = robot
        self.chain = chain
        self.dof = robot.dof
        self.joint_names = robot.joint_names
        self.lower = robot.lower
        self.upper = robot.upper
        self._lower = [float(v) for v in robot.lower]
        self._upper = [float(v) for v in robot.upper]
        self._q_shape = (self.dof,)
        self.branches: tuple[str, ...] = ()
        self.deviation = 0.0

    def __repr__(self) -> str:
        return f"{type(self).__name__}(robot={self.robot.name!r}, branches={len(self.branches)})"

    @classmethod
    def match(cls, chain: ChainAtZero) -> str | None:
        """Whether a chain fits this family.

        Args:
            chain: The chain at q = 0 (:func:`planner.geometry.chain.chain_at_zero`).

        Returns:
            None when it fits, else the reason it does not, naming the joint.
        """
        mismatch = cls.mismatch(chain)
        return None if mismatch is None else mismatch.reason

    @classmethod
    @abstractmethod
    def mismatch(cls, chain: ChainAtZero) -> ChainMismatch | None:
        """Why a chain is outside this family (None when it fits); see :meth:`match`."""

    def _check_chain(self, chain: ChainAtZero) -> None:
        """Raise UnsupportedChainError if `chain` does not fit this solver's family."""
        mismatch = self.mismatch(chain)
        if mismatch is not None:
            raise UnsupportedChainError(f"{self.robot.name}: {mismatch.reason}", joint=mismatch.joint)

    # ------------------------------------------------------------------ interface
    @abstractmethod
    def solve(self, target: Target, q_current: Sequence[float] | np.ndarray | None = None) -> AnalyticResult:
        """Every closed-form solution for one target.

        Args:
            target: The target (position, plus an approach pitch or a rotation).
            q_current: The current configuration, shape (dof,) [rad]: solutions are sorted by
                distance to it, angles wrapped nearest to it, and free joints take its values
                (where that leaves no branch within the limits, the nearest values that do).

        Returns:
            The result; unreachable targets give a status, not an exception.
        """

    def nearest(self, target: Target, seed: np.ndarray | None) -> NearestSolution | None:
        """The solution :func:`planner.solve_ik` answers with, without building the whole result.

        The first solution within the limits of ``solve(target, seed).solutions`` nearest the
        seed (joint distance, angles modulo 2 pi; the first in the result's order among equal
        distances), and its place there; None when the family has no such shortcut for this
        target (the caller then uses :meth:`solve`): e.g. when no branch lies within the
        limits before a search of the free joints.

        Args:
            target: The target.
            seed: A checked seed (float array of shape (dof,), within the limits), or None.
        """
        return None

    def _counted_kernel(self, key: tuple, build):
        """:meth:`nearest`'s compiled kernel for target kind `key`, kept in ``self._single``.

        The calls of that kind are counted there (an int) until :data:`SINGLE_AFTER`; then
        ``build(key)`` is kept and returned (the kernel, or False where there is none). Returns
        the count before that.
        """
        kernel = self._single.get(key, 0)
        if kernel.__class__ is int:
            kernel = self._single[key] = kernel + 1 if kernel + 1 < SINGLE_AFTER else build(key)
        return kernel

    @abstractmethod
    def solve_batch(
        self,
        positions: np.ndarray,
        pitch: np.ndarray | float | None = None,
        rotations: np.ndarray | None = None,
        q_current: np.ndarray | None = None,
    ) -> AnalyticBatchResult:
        """Closed-form solutions of N targets at once, without a Python loop over targets.

        Args:
            positions: Target positions, shape (N, 3) [m].
            pitch: Approach pitch, a scalar or shape (N,) [rad], or None.
            rotations: Target rotations, shape (N, 3, 3), or None (not with `pitch`).
            q_current: Current configuration, shape (dof,) or (N, dof) [rad], or None.

        Returns:
            The batch result.
        """

    # ------------------------------------------------------------------ input checks
    def _q_current_list(self, q_current: Sequence[float] | np.ndarray | None) -> list[float] | None:
        if q_current is None:
            return None
        if isinstance(q_current, np.ndarray) and q_current.dtype is FLOAT64 and q_current.shape == self._q_shape:
            values = q_current.tolist()  # the common case, checked without a NumPy round trip
            if math.isfinite(sum(values)):  # a NaN or an infinity makes the sum so
                return values
        return self.robot.check_configuration(q_current, batch=False).tolist()

    def _check_target(self, target: Target) -> None:
        if not isinstance(target, Target):
            raise InvalidArgumentError(
                f"target must be a planner.Target (e.g. Target(position, pitch=...)), got {type(target).__name__}"
            )

    def _batch_inputs(
        self,
        positions: np.ndarray,
        pitch: np.ndarray | float | None,
        rotations: np.ndarray | None,
        q_current: np.ndarray | None,
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        """Validate batch inputs; returns float arrays (N,3), (N,)|None, (N,3,3)|None, (N,dof)|None."""
        try:
            pos = np.array(positions, dtype=float, copy=True)
        except (TypeError, ValueError) as exc:
            raise InvalidArgumentError(f"positions must be an (N, 3) array of numbers, got {positions!r}") from exc
        if pos.ndim != 2 or pos.shape[1] != 3:
            raise InvalidArgumentError(f"positions must have shape (N, 3), got {pos.shape}")
        n = pos.shape[0]
        if not np.all(np.isfinite(pos)):
            row = int(np.argwhere(~np.isfinite(pos))[0, 0])
            raise InvalidArgumentError(f"positions[{row}] = {pos[row].tolist()} is not finite")
        if pitch is not None and rotations is not None:
            raise InvalidArgumentError("give either pitch or rotations, not both")
        pit = None
        if pitch is not None:
            pit = np.array(pitch, dtype=float, copy=True)
            if pit.ndim == 0:
                pit = np.full(n, float(pit))
            if pit.shape != (n,):
                raise InvalidArgumentError(f"pitch must be a scalar or have shape ({n},), got {pit.shape}")
            if not np.all(np.isfinite(pit)):
                raise InvalidArgumentError("pitch holds NaN or infinite values")
        rot = None
        if rotations is not None:
            rot = np.array(rotations, dtype=float, copy=True)
            if rot.shape != (n, 3, 3):
                raise InvalidArgumentError(f"rotations must have shape ({n}, 3, 3), got {rot.shape}")
            if not np.all(np.isfinite(rot)):
                raise InvalidArgumentError("rotations hold NaN or infinite values")
            dev, det = _rotation_defects(rot)
            bad = (dev > 1e-6) | (det < 0)
            if np.any(bad):
                row = int(np.argmax(bad))
                raise InvalidArgumentError(
                    f"rotations[{row}] is not a proper orthonormal matrix (|R^T R - I| = {dev[row]:.3g})"
                )
        qc = None
        if q_current is not None:
            qc = np.array(q_current, dtype=float, copy=True)
            if qc.shape == (self.dof,):
                qc = np.broadcast_to(qc, (n, self.dof))
            if qc.shape != (n, self.dof):
                raise InvalidConfigurationError(
                    f"q_current has shape {qc.shape}; expected ({self.dof},) or ({n}, {self.dof}) for joints "
                    f"{', '.join(self.joint_names)}"
                )
            if not np.all(np.isfinite(qc)):
                raise InvalidConfigurationError("q_current holds NaN or infinite values")
        return pos, pit, rot, qc


def _rotation_defects(rot: np.ndarray, chunk: int = 16384) -> tuple[np.ndarray, np.ndarray]:
    """The largest entry of ``|R^T R - I|`` and ``det R`` of N rotations (N, 3, 3).

    Entry by entry on the columns (arrays over the rotations, `chunk` at a time to stay in
    the cache): 20 times as fast as a batched matrix product and determinant.
    """
    n = rot.shape[0]
    dev, det = np.zeros(n), np.empty(n)
    for start in range(0, n, chunk):
        part = slice(start, start + chunk)
        cols = np.ascontiguousarray(np.moveaxis(rot[part], 0, -1))  # (3, 3, k): cols[:, j] is column j
        c0, c1, c2 = cols[:, 0], cols[:, 1], cols[:, 2]
        d = dev[part]
        for a, b, one in ((c0, c0, 1.0), (c1, c1, 1.0), (c2, c2, 1.0), (c0, c1, 0.0), (c0, c2, 0.0), (c1, c2, 0.0)):
            np.maximum(d, np.abs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] - one), out=d)
        cross = (c1[1] * c2[2] - c1[2] * c2[1], c1[2] * c2[0] - c1[0] * c2[2], c1[0] * c2[1] - c1[1] * c2[0])
        det[part] = c0[0] * cross[0] + c0[1] * cross[1] + c0[2] * cross[2]
    return dev, det
