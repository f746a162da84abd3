"""The yaw-planar family's solver: :class:`YawPlanarIK`."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from planner.core.rotations import rotation_error
from planner.exceptions import UnsupportedChainError
from planner.geometry.chain import ChainAtZero
from planner.geometry.target import Target, approach_pitch
from planner.ik.analytic.base import FLOAT64, AnalyticIK, ChainMismatch, fill_kernel_inputs
from planner.ik.analytic.nearest import NearestSolution, nearest_entry
from planner.ik.analytic.result import (
    STATUS_CODES,
    STATUS_ORIENTATION_NOT_ACHIEVABLE,
    STATUS_OUTSIDE_JOINT_LIMITS,
    STATUS_SOLVED,
    AnalyticBatchResult,
    AnalyticResult,
)
from planner.ik.analytic.yaw_planar.arm import arm_geometry
from planner.ik.analytic.yaw_planar.arrays import BranchArrays, result_from_arrays, solve_arrays
from planner.ik.analytic.yaw_planar.batch import solve_chunked
from planner.ik.analytic.yaw_planar.branches import BRANCHES
from planner.ik.analytic.yaw_planar.compiled import CompiledKernels, kind_of, kind_supported
from planner.ik.analytic.yaw_planar.corrected import (
    corrected_result,
    real_tip_pose,
    solve_corrected_pose,
    solve_corrected_scalar,
)
from planner.ik.analytic.yaw_planar.corrected_single import CorrectedKernel, corrected_kernel, corrected_supported
from planner.ik.analytic.yaw_planar.layout import chain_layout
from planner.ik.analytic.yaw_planar.real_model import true_fk
from planner.ik.analytic.yaw_planar.scalar import scalar_plan, solve_scalar
from planner.ik.analytic.yaw_planar.scalar_pose import pose_frame, pose_nearest, solve_pose_scalar
from planner.ik.analytic.yaw_planar.search import free_joints, solve_searched
from planner.ik.analytic.yaw_planar.single import SingleKernel, single_kernel
from planner.model.robot import Robot

__all__ = ["YawPlanarIK"]


class YawPlanarIK(AnalyticIK):
    """Closed-form IK of a base yaw + 2 or 3 parallel pitch joints + optional wrist roll.

    Build it with :func:`~planner.ik.analytic.closed_form_solver`. See :mod:`planner.ik.analytic.yaw_planar` for
    the geometry, the branches and how each kind of target is solved.

    Attributes:
        arm: The arm's geometry (:class:`~planner.ik.analytic.yaw_planar.arm.ArmGeometry`).
        n_pitch: Number of pitch joints (2 or 3).
        has_roll: Whether a wrist roll joint ends the chain.
        exact: Whether the model's axes are exactly (within 1e-12 rad) of the family; if not,
            solutions are corrected on the real geometry.
        link_lengths: In-plane lengths [m]: shoulder-elbow, elbow-wrist (or elbow-end), and
            wrist-end (3 pitch joints).
        lateral_offset: Sideways offset of the tip from the yaw axis at roll 0 [m].
    """

    family = "yaw_planar"

    @classmethod
    def mismatch(cls, chain: ChainAtZero) -> ChainMismatch | None:
        """Why a chain is not a base yaw + 2 or 3 pitch joints + optional roll (None when it is)."""
        layout = chain_layout(chain)
        return layout if isinstance(layout, ChainMismatch) else None

    def __init__(self, robot: Robot, chain: ChainAtZero) -> None:
        super().__init__(robot, chain)
        self.branches = BRANCHES
        layout = chain_layout(chain)
        if isinstance(layout, ChainMismatch):
            raise UnsupportedChainError(f"{robot.name}: {layout.reason}", joint=layout.joint)
        arm = arm_geometry(robot, chain, layout)
        self.arm = arm
        self.deviation = arm.deviation
        self.exact = arm.exact
        self.n_pitch = arm.n_pitch
        self.has_roll = arm.has_roll
        self.link_lengths = arm.link_lengths
        self.lateral_offset = arm.lateral_offset
        self._pose_frame = pose_frame(arm)
        self._scalar_plan = scalar_plan(arm) if arm.exact else None
        self._real_tip_pose = None if arm.exact else real_tip_pose(robot)
        self._kernels = CompiledKernels(arm)
        # nearest's distances are modulo 2 pi on every joint (revolute joints, as planner.ik.solve's).
        self._nearest_ok = arm.exact and all(kind == "revolute" for kind in robot.joint_kinds)
        self._corrected_ok = corrected_supported(arm, robot.joint_kinds)
        # nearest's compiled kernels by (kind, with a seed): a SingleKernel (a CorrectedKernel on
        # inexact chains), False (none), or the calls so far (an int) until SINGLE_AFTER.
        self._single: dict[tuple, SingleKernel | CorrectedKernel | bool | int] = {}

    def describe(self) -> dict:
        """The detected geometry, for reports and tests (lengths [m], angles [rad])."""
        arm = self.arm
        out = {
            "family": self.family,
            "n_pitch": arm.n_pitch,
            "has_roll": arm.has_roll,
            "exact": arm.exact,
            "deviation": arm.deviation,
            "yaw_axis_point": [arm.bx, arm.by],
            "yaw_sign": arm.sigma,
            "pitch_signs": list(arm.signs),
            "shoulder": [arm.su, arm.sz],
            "link_lengths": list(arm.link_lengths),
            "lateral_offset": arm.lateral_offset,
            "approach_angle": arm.beta,
            "tip_on_roll_axis": arm.tip_on_roll_axis,
        }
        if arm.n_pitch == 3:
            out["elbow_reach"] = [arm.rmin_lim, arm.rmax_lim]
        return out

    # ------------------------------------------------------------------ one target
    def solve(self, target: Target, q_current: Sequence[float] | np.ndarray | None = None) -> AnalyticResult:
        """Every closed-form solution for one target (see :meth:`AnalyticIK.solve`)."""
        if not isinstance(target, Target):
            self._check_target(target)
        qc = None
        if q_current is not None:
            if type(q_current) is np.ndarray and q_current.dtype is FLOAT64 and q_current.shape == self._q_shape:
                qc = q_current.tolist()  # the common case, checked inline (see _q_current_list)
                if not math.isfinite(sum(qc)):
                    qc = self._q_current_list(q_current)
            else:
                qc = self._q_current_list(q_current)
        arm = self.arm
        if target.pitch is not None and not arm.pitch_supported:
            self._raise_pitch_unsupported()
        arrays = None
        if arm.exact:
            if target.rotation is None:
                result = solve_scalar(arm, target, qc, self._scalar_plan)
            else:
                result = solve_pose_scalar(arm, self._pose_frame, target, qc, self._scalar_plan)
            if result.status is STATUS_SOLVED:
                return result
        elif result := self._solve_corrected(target, qc):
            return result
        else:
            arrays = solve_arrays(arm, *_one_target_arrays(target, qc))
            result = result_from_arrays(arm, arrays, 0, target, qc)
        if result.status is STATUS_ORIENTATION_NOT_ACHIEVABLE:
            result = result._replace(reason=self._orientation_reason(target, qc))
        if not result.ok and any(free_joints(arm, target.pitch, target.rotation)):
            return self._search_one(target, qc, result, arrays)
        return result

    def nearest(self, target: Target, seed: np.ndarray | None) -> NearestSolution | None:
        """The solution within the limits nearest the seed (see :meth:`AnalyticIK.nearest`).

        On exact chains, from the scalar paths' entries, or after :data:`~planner.ik.analytic.base.SINGLE_AFTER` calls
        of a target kind by one compiled call
        (:class:`~planner.ik.analytic.yaw_planar.single.SingleKernel`; where it is not sure,
        the scalar paths; joint values the same to round-off; ``count`` and ``index`` None).
        On inexact chains (SO-101) after as many calls by one compiled call of the corrected
        closed form (:class:`~planner.ik.analytic.yaw_planar.corrected_single.CorrectedKernel`),
        else None.
        """
        arm = self.arm
        if self._corrected_ok:
            return self._corrected_nearest(target, seed)
        if not self._nearest_ok or (target.pitch is not None and not arm.pitch_supported):
            return None
        key = (kind_of(target.pitch, target.rotation), seed is not None)
        kernel = self._counted_kernel(key, self._single_kernel)
        if kernel.__class__ is SingleKernel:
            fill_kernel_inputs(kernel.inputs, target.position, target.pitch, target.rotation, seed)
            kernel()
            out = kernel.outputs.tolist()
            if out[0]:
                return NearestSolution(tuple(out[2:]), BRANCHES[int(out[1])], None, None)
        qc = None if seed is None else seed.tolist()
        if target.rotation is not None:
            return pose_nearest(arm, self._pose_frame, target, qc, self._scalar_plan)
        entries = solve_scalar(arm, target, qc, self._scalar_plan, True)
        return None if entries is None else nearest_entry(entries, qc)

    def _corrected_nearest(self, target: Target, seed: np.ndarray | None) -> NearestSolution | None:
        """:meth:`nearest` on inexact chains: the compiled corrected closed form's answer where sure, else None."""
        if target.pitch is not None and not self.arm.pitch_supported:
            return None
        key = (kind_of(target.pitch, target.rotation), seed is not None)
        kernel = self._counted_kernel(key, self._corrected_kernel)
        if kernel.__class__ is not CorrectedKernel:
            return None
        fill_kernel_inputs(kernel.inputs, target.position, target.pitch, target.rotation, seed)
        kernel()
        out = kernel.outputs.tolist()
        return NearestSolution(tuple(out[2:]), BRANCHES[int(out[1])], None, None) if out[0] else None

    def _corrected_kernel(self, key: tuple) -> CorrectedKernel | bool:
        """The compiled kernel of a target kind, or False where there is none.

        `key`: (kind, with a seed) for :meth:`_corrected_nearest`, ("every", kind, with a seed)
        for :meth:`_solve_corrected`.
        """
        every = key[0] == "every"
        kind, current = key[1:] if every else key
        return corrected_kernel(self.arm, self._pose_frame, kind, current, every) or False

    def _solve_corrected(self, target: Target, qc: list[float] | None) -> AnalyticResult | None:
        """:meth:`solve` on inexact chains: every branch by the corrected closed form, or None.

        After :data:`~planner.ik.analytic.base.SINGLE_AFTER` calls of a target kind by one
        compiled call (:func:`~planner.ik.analytic.yaw_planar.corrected.corrected_result`) where it
        is sure, else by :func:`~planner.ik.analytic.yaw_planar.corrected.solve_corrected_scalar`
        or :func:`~planner.ik.analytic.yaw_planar.corrected.solve_corrected_pose`.
        """
        arm = self.arm
        if self._corrected_ok:
            kind = kind_of(target.pitch, target.rotation)
            kernel = self._counted_kernel(("every", kind, qc is not None), self._corrected_kernel)
            if kernel.__class__ is CorrectedKernel:
                fill_kernel_inputs(kernel.inputs, target.position, target.pitch, target.rotation, qc)
                kernel()
                result = corrected_result(arm, self._real_tip_pose, target, qc, kernel.outputs.tolist())
                if result is not None:
                    return result
        if target.rotation is None:
            return solve_corrected_scalar(arm, self._real_tip_pose, target, qc)
        return solve_corrected_pose(arm, self._pose_frame, self._real_tip_pose, target, qc)

    def _single_kernel(self, key: tuple[str, bool]) -> SingleKernel | bool:
        """The compiled kernel of :meth:`nearest` for a target kind, or False where there is none."""
        kind, current = key
        if not kind_supported(self.arm, kind, current):
            return False
        return single_kernel(self._kernels, kind, current) or False

    def _search_one(
        self, target: Target, qc: list[float] | None, result: AnalyticResult, base: BranchArrays | None
    ) -> AnalyticResult:
        """The result at free joint values within the limits (see `search.search`), else `result`.

        `base` holds `result`'s arrays, or None when the scalar path solved it.
        """
        arm = self.arm
        pos, pit, _, qca = _one_target_arrays(target, qc)
        if base is None:
            base = solve_arrays(arm, pos, pit, None, qca)
        arrays = solve_searched(arm, pos, pit, qca, base)
        if arrays is base or arrays.status[0] != STATUS_CODES[STATUS_SOLVED]:
            if result.status != STATUS_OUTSIDE_JOINT_LIMITS:
                return result
            free_phi, free_roll = free_joints(arm, target.pitch, None)
            what = " or ".join(w for w, f in (("approach pitch", free_phi), ("wrist roll", free_roll)) if f)
            return result._replace(reason=f"{result.reason} (no other {what} brings a branch within them)")
        return result_from_arrays(arm, arrays, 0, target, qc)

    def _orientation_reason(self, target: Target, qc: list[float] | None) -> str:
        """Why the orientation fails, with what the position alone allows (failures only)."""
        arm = self.arm
        name = arm.name
        plain = self.solve(Target(target.position), q_current=qc).solutions
        if target.pitch is not None:
            got = [math.degrees(approach_pitch(self.robot, sol.q)) for sol in plain]
            return (
                f"{name} has no wrist pitch joint: at this position its approach pitch can only be "
                f"{', '.join(f'{g:.2f}' for g in sorted(set(round(g, 6) for g in got)))} deg, "
                f"not {math.degrees(target.pitch):.2f} deg"
            )
        text = f"{name} ({arm.dof} joints) cannot reach this position with this orientation"
        if arm.n_pitch == 2 and plain:
            _, rot = true_fk(arm, np.array([s.q for s in plain]))
            miss = np.asarray(rotation_error(rot, np.broadcast_to(target.rotation, rot.shape)))
            text += f"; at this position the nearest reachable orientation is {float(miss.min()):.3g} rad away"
        else:
            text += " (the orientation fixes the arm's vertical plane, which must also hold the wrist centre)"
        return text

    # ------------------------------------------------------------------ batch
    def solve_batch(
        self,
        positions: np.ndarray,
        pitch: np.ndarray | float | None = None,
        rotations: np.ndarray | None = None,
        q_current: np.ndarray | None = None,
    ) -> AnalyticBatchResult:
        """Closed-form solutions of N targets at once (see :meth:`AnalyticIK.solve_batch`)."""
        pos, pit, rot, qc = self._batch_inputs(positions, pitch, rotations, q_current)
        if pit is not None and not self.arm.pitch_supported:
            self._raise_pitch_unsupported()
        a = solve_chunked(self.arm, pos, pit, rot, qc, kernels=self._kernels)
        for arr in (a.q, a.valid, a.within, a.singular, a.perr):
            arr.setflags(write=False)  # freshly built here: frozen in place, not copied
        return AnalyticBatchResult(
            q=a.q,
            valid=a.valid,
            within_limits=a.within,
            singular=a.singular,
            position_error=a.perr,
            status=a.status,
            best=a.best,
            branches=BRANCHES,
        )

    def _raise_pitch_unsupported(self) -> None:
        arm = self.arm
        raise UnsupportedChainError(
            f"{arm.name}: approach-pitch targets need the approach axis {self.chain.approach.round(6).tolist()} "
            "in the arm's plane"
            + (" and along the wrist roll axis" if arm.has_roll else "")
            + "; give a rotation or a position instead",
            joint=arm.joint_names[arm.roll_idx] if arm.has_roll else arm.joint_names[arm.pitch_idx[-1]],
        )


def _one_target_arrays(target: Target, qc: list[float] | None):
    """A target and q_current as the arrays of a batch of one: positions, pitch, rotations, q_current."""
    pos = np.asarray(target.position, dtype=float)[None, :]
    pit = None if target.pitch is None else np.array([target.pitch])
    rot = None if target.rotation is None else np.asarray(target.rotation)[None]
    qca = None if qc is None else np.asarray(qc, dtype=float)[None, :]
    return pos, pit, rot, qca
