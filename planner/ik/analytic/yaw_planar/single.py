"""The answer of :func:`planner.solve_ik` for one target by one compiled call (exact chains).

:meth:`~planner.ik.analytic.yaw_planar.solver.YawPlanarIK.nearest` needs one configuration:
the solution within the limits nearest the seed. The batch closed form's function of one
target (:class:`~planner.ik.analytic.yaw_planar.compiled.CompiledKernels`, mapped over one
target: every branch, wrapped, its limits mask, the status) is extended here by that pick,
with the rule and arithmetic of :func:`~planner.ik.analytic.nearest.nearest_entry`: without a
seed the first branch within the limits in branch order; with one the branch within the limits
whose joint distance to it (angles modulo 2 pi as Python's float remainder, the square root of
the sum of squares in joint order) is least. The whole is compiled to C and called through a
buffer binding (one input vector, one output vector, bound once), as the NLP's kernel.

The output's first entry says whether the pick is the Python path's for sure; it is 0, and
the caller takes the Python path, where the status is not solved, where the function hands
the target over (a free end angle to the search, a target on the yaw axis with a seed),
where two branches within the limits lie at exactly the same distance (the Python path's
order among them is its sort key's), and near a stretched or folded elbow
(:data:`ELBOW_MARGIN`), where round-off differences grow.

Joint values agree with the Python path's to round-off (the same sequence of operations; the
C compiler without FMA contraction): the caller confirms every answer by Pinocchio FK.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

import planner.ik.analytic.base as analytic_base
from planner.geometry.target import RADIAL_EPS
from planner.ik.analytic.result import STATUS_CODES, STATUS_SOLVED
from planner.ik.analytic.yaw_planar.branches import BRANCHES
from planner.ik.analytic.yaw_planar.compiled import (
    FLAGS,
    CompiledKernels,
    forward_sx,
    kind_of,
    kind_supported,
    nearest_branch_sx,
    pick_branch_sx,
)
from planner.ik.numeric.codegen import compile_function

__all__ = [
    "ELBOW_MARGIN",
    "HALF_TURN_MARGIN",
    "KEY_MARGIN",
    "REACH_MARGIN",
    "SingleKernel",
    "SolveKernel",
    "SolveKernels",
    "single_kernel",
]

_PI = math.pi
_SOLVED = STATUS_CODES[STATUS_SOLVED]
#: |sin| of the elbow's interior angle below which the kernel leaves the pick to the Python path
#: (the joint values' round-off differences there would exceed about 1e-12 rad).
ELBOW_MARGIN = 2e-3
#: Relative difference of two branches' distances to the seed below which :class:`SolveKernel`
#: leaves the order to the Python path.
KEY_MARGIN = 1e-9
#: Distance [m, times the arm's size] of a wrist point from the reach limits below which
#: :class:`SolveKernel` leaves the branch categories to the Python path.
REACH_MARGIN = 1e-9
#: Distance [rad] of a joint value from half a turn off its seed (or off its range's middle)
#: below which :class:`SolveKernel` leaves the wrap to the Python path.
HALF_TURN_MARGIN = 1e-9


class SingleKernel:
    """One target kind's compiled closed form with the nearest pick, its buffers bound once.

    Fill :attr:`inputs` (position, then the pitch or the rotation's nine entries row by row,
    then the seed), call, read :attr:`outputs`: ``[sure, slot, q...]``.

    Attributes:
        inputs: The input vector.
        outputs: ``[1.0 if the pick is sure else 0.0, the chosen slot (branch index), q (dof)]``.
        compiled: Whether the function runs as C code (else the caller should not use it).

    Not thread-safe: its buffers serve one call at a time (each solver owns its kernels).
    """

    def __init__(self, kernels: CompiledKernels, kind: str, current: bool) -> None:
        arm = kernels.arm
        dof = arm.dof
        inner = kernels.function(kind, current, 1, compiled=False).expand()
        n_extra = {"position": 0, "pitch": 1, "pose": 9}[kind]
        n_in = 3 + n_extra + (dof if current else 0)
        x = ca.SX.sym("x", n_in)
        args = [x[0:3]]
        if n_extra:
            args.append(x[3 : 3 + n_extra])
        qc = x[3 + n_extra :] if current else None
        if current:
            args.append(qc)
        # The kernel's outputs: q (4 branches x dof), position errors, then per branch valid,
        # within and singular, then (status, best[, handed over]).
        q_flat, _, _, within_v, _, codes = inner(*args)
        q = [[q_flat[m * dof + j] for j in range(dof)] for m in range(4)]
        within = [within_v[m] for m in range(4)]
        sure = codes[0] == _SOLVED
        if codes.numel() > 2:  # handed over (a free end angle to the search, a target on the yaw axis)
            sure = ca.logic_and(sure, codes[2] == 0)
        if current:
            best, ties = nearest_branch_sx(q, within, qc)
            sure = ca.logic_and(sure, ca.logic_not(ties))
        else:
            best = codes[1]
        chosen = pick_branch_sx(q, best)
        sure = ca.logic_and(sure, best >= 0)
        # Near a stretched or folded elbow the two operation sequences' round-off grows as
        # 1 / |sin e| (the elbow's interior angle e, from the chosen q): leave those to Python.
        if arm.n_pitch == 3:
            g2 = arm.g2
        else:
            tu, tz, _ = arm.centre if kind == "pose" and arm.has_roll else arm.tip_fixed
            g2 = math.atan2(tz, tu)
        elbow = arm.signs[1] * chosen[arm.pitch_idx[1]] + g2 - arm.g1
        sure = ca.logic_and(sure, ca.fabs(ca.sin(elbow)) >= ELBOW_MARGIN)
        fn = ca.Function(f"yaw_planar_nearest_{kind}", [x], [ca.cse(ca.vertcat(sure, best, *chosen))])
        self.function = compile_function(fn, flags=FLAGS)
        self.compiled = self.function.class_name() == "External"
        self.inputs = np.zeros(n_in)
        self.outputs = np.zeros(2 + dof)
        self._buffer, self._evaluate = self.function.buffer()
        self._buffer.set_arg(0, memoryview(self.inputs))
        self._buffer.set_res(0, memoryview(self.outputs))

    def __call__(self) -> None:
        """Evaluate from :attr:`inputs` into :attr:`outputs`."""
        self._evaluate()


def single_kernel(kernels: CompiledKernels, kind: str, current: bool) -> SingleKernel | None:
    """The compiled :class:`SingleKernel`, or None where it would run in CasADi's virtual machine."""
    kernel = SingleKernel(kernels, kind, current)
    return kernel if kernel.compiled else None


class SolveKernel:
    """One target kind's compiled closed form for :meth:`YawPlanarIK.solve`: every branch, verified.

    The batch closed form's function of one target (every branch wrapped into the limits,
    masks, status), then per branch the forward model at its returned joint values (the real
    chain's product of exponentials, each joint's cosine and sine by libm: the position error,
    and the orientation error of pitch and pose targets as the Python path defines them), its
    squared joint distance to the seed, as one CasADi function (compiled to C by :meth:`compile`)
    with its buffers bound once. Fill
    :attr:`inputs` as :class:`SingleKernel`'s, call, read :attr:`outputs`: ``[sure, any
    singular]``, then per branch ``[valid, within, singular, key, position error, orientation
    error, q...]``.

    ``sure`` is 0, and the caller takes the Python path, where the status is not solved, where
    the function hands the target over, where two valid branches lie within
    :data:`KEY_MARGIN` of the same distance to the seed, where a wrist point lies within
    :data:`REACH_MARGIN` of a reach limit, where a joint lies within :data:`HALF_TURN_MARGIN`
    of half a turn from its seed or its range's middle, and near a stretched or folded elbow
    (:data:`ELBOW_MARGIN`): where round-off could decide a branch's category, order or turn
    differently. Elsewhere the branches, their order, masks and the status are the Python
    path's and joint values agree to round-off.

    Not thread-safe (as :class:`SingleKernel`).
    """

    def __init__(self, kernels: CompiledKernels, kind: str, current: bool) -> None:
        arm = kernels.arm
        dof = arm.dof
        inner = kernels.function(kind, current, 1, compiled=False, distances=True).expand()
        n_extra = {"position": 0, "pitch": 1, "pose": 9}[kind]
        n_in = 3 + n_extra + (dof if current else 0)
        x = ca.SX.sym("x", n_in)
        p = x[0:3]
        args = [p]
        if n_extra:
            args.append(x[3 : 3 + n_extra])
        qc = x[3 + n_extra :] if current else None
        if current:
            args.append(qc)
        q_flat, _, valid_v, within_v, singular_v, codes, dist_v = inner(*args)
        sure = codes[0] == _SOLVED
        if codes.numel() > 2:
            sure = ca.logic_and(sure, codes[2] == 0)
        if arm.n_pitch == 3:
            l1, l2, g2 = arm.l1, arm.l2, arm.g2
        else:
            tu, tz, _ = arm.centre if kind == "pose" and arm.has_roll else arm.tip_fixed
            l1, l2, g2 = arm.l1, math.hypot(tu, tz), math.atan2(tz, tu)
        margin = REACH_MARGIN * arm.scale
        reach = (l1 + l2 + arm.core_len_tol, abs(l1 - l2) - arm.core_len_tol)
        any_singular = ca.SX(0)
        rows, keys = [], []
        for m in range(4):
            q = [q_flat[m * dof + j] for j in range(dof)]
            valid = valid_v[m]
            pos, rot = forward_sx(arm, q)
            perr = ca.sqrt((pos[0] - p[0]) ** 2 + (pos[1] - p[1]) ** 2 + (pos[2] - p[2]) ** 2)
            if kind == "pose":
                oerr = _rotation_error(rot, [[x[3 + 3 * i + j] for j in range(3)] for i in range(3)])
            elif kind == "pitch":
                approach = [sum(rot[i][k] * float(arm.approach_local[k]) for k in range(3)) for i in range(3)]
                oerr = _pitch_error(approach, p, x[3])
            else:
                oerr = ca.SX(0.0)
            key = sum((q[j] - qc[j]) ** 2 for j in range(dof)) if current else ca.SX(0.0)
            elbow = arm.signs[1] * q[arm.pitch_idx[1]] + g2 - arm.g1
            dist = dist_v[m]
            near = ca.logic_or(ca.fabs(dist - reach[0]) < margin, ca.fabs(dist - reach[1]) < margin)
            sure = ca.logic_and(sure, ca.logic_not(near))
            sure = ca.logic_and(sure, ca.logic_or(ca.logic_not(valid), ca.fabs(ca.sin(elbow)) >= ELBOW_MARGIN))
            # A joint half a turn from the seed (or 0), or equally far from its range both
            # ways: round-off decides which of the two values the wrap returns. (Not the yaw
            # of position and pitch targets: the same operations as the Python path's, and the
            # two sides' yaws lie half a turn apart.)
            for j in range(dof):
                half = ca.SX(0)
                if j != 0 or kind == "pose":
                    half = ca.fabs(ca.fabs(q[j] - (qc[j] if current else 0.0)) - _PI) < HALF_TURN_MARGIN
                lo, hi = arm.lower[j], arm.upper[j]
                if math.isfinite(lo) and math.isfinite(hi):
                    half = ca.logic_or(half, ca.fabs(ca.fabs(q[j] - 0.5 * (lo + hi)) - _PI) < HALF_TURN_MARGIN)
                sure = ca.logic_and(sure, ca.logic_not(ca.logic_and(valid, half)))
            any_singular = ca.logic_or(any_singular, singular_v[m])
            keys.append((valid, key))
            rows += [valid, within_v[m], singular_v[m], key, perr, oerr, *q]
        if current:
            for a in range(4):
                for b in range(a + 1, 4):
                    (va, ka), (vb, kb) = keys[a], keys[b]
                    tie = ca.fabs(ka - kb) <= KEY_MARGIN * (1.0 + ka + kb)
                    sure = ca.logic_and(sure, ca.logic_not(ca.logic_and(ca.logic_and(va, vb), tie)))
        self._source = ca.Function(f"yaw_planar_solve_{kind}", [x], [ca.cse(ca.vertcat(sure, any_singular, *rows))])
        self.stride = 6 + dof
        self.inputs = np.zeros(n_in)
        self.outputs = np.zeros(2 + 4 * self.stride)
        self.compiled = False
        self._bind(self._source)

    def _bind(self, function: ca.Function) -> None:
        self.function = function
        self._buffer, self._evaluate = function.buffer()
        self._buffer.set_arg(0, memoryview(self.inputs))
        self._buffer.set_res(0, memoryview(self.outputs))

    def compile(self) -> None:
        """Run as C from now on (where compiling falls back to CasADi's virtual machine, as before).

        See :func:`~planner.ik.numeric.codegen.compile_function`.
        """
        function = compile_function(self._source, flags=FLAGS)
        if function.class_name() == "External":
            self.compiled = True
            self._bind(function)

    def __call__(self) -> None:
        """Evaluate from :attr:`inputs` into :attr:`outputs`."""
        self._evaluate()


class SolveKernels:
    """An exact arm's :class:`SolveKernel` per target kind.

    Each built at the first call of its kind and evaluated by CasADi's virtual machine (3-6 us;
    0.06-0.16 s to build), compiled to C after :data:`~planner.ik.analytic.base.SINGLE_AFTER`
    calls: the virtual machine and the C code give the same doubles (the same operations,
    libm's functions, no FMA contraction), so an answer does not depend on how many calls came
    before it.

    Owned by the arm's :class:`~planner.ik.analytic.yaw_planar.scalar.ScalarPlan` (one per solver).
    """

    def __init__(self, arm) -> None:
        self.arm = arm
        self._kernels = CompiledKernels(arm)
        # By (kind, with q_current): a SolveKernel or False (none); the calls of kernels not yet compiled.
        self._built: dict[tuple[str, bool], SolveKernel | bool] = {}
        self._calls: dict[tuple[str, bool], int] = {}

    def entries(self, position, pitch, rotation, qc: list[float] | None):
        """A target's solutions by the compiled path, or None where it is not sure or not built.

        Returns:
            (entries, singular): the solutions as
            :func:`~planner.ik.analytic.yaw_planar.scalar.solutions_result` takes them (all
            verified, one within the limits) and whether any is singular; None where the
            caller takes the Python path.
        """
        key = (kind_of(pitch, rotation), qc is not None)
        kernel = self._built.get(key)
        if kernel is None:
            kernel = self._built[key] = self._build(key)
        if kernel is False:
            return None
        if key in self._calls:  # not compiled yet
            calls = self._calls[key] = self._calls[key] + 1
            if calls >= analytic_base.SINGLE_AFTER:
                del self._calls[key]
                kernel.compile()
        analytic_base.fill_kernel_inputs(kernel.inputs, position, pitch, rotation, qc)
        kernel()
        out = kernel.outputs.tolist()
        if not out[0]:
            return None
        stride = kernel.stride
        orient = pitch is not None or rotation is not None
        entries = []
        for m in range(4):
            b = 2 + m * stride
            if out[b]:
                entries.append(
                    (
                        out[b + 3],
                        m,
                        out[b + 6 : b + stride],
                        (out[b + 1] != 0.0, BRANCHES[m], out[b + 2] != 0.0, out[b + 4], out[b + 5] if orient else None),
                    )
                )
        return entries, out[1] != 0.0

    def _build(self, key: tuple[str, bool]) -> SolveKernel | bool:
        kind, current = key
        if not kind_supported(self.arm, kind, current):
            return False
        self._calls[key] = 0
        return SolveKernel(self._kernels, kind, current)


def _rotation_error(a, b):
    """The angle [rad] between two rotations (nested lists of SX), as the Python path computes it."""
    rel = [[a[0][i] * b[0][j] + a[1][i] * b[1][j] + a[2][i] * b[2][j] for j in range(3)] for i in range(3)]
    cos = 0.5 * (rel[0][0] + rel[1][1] + rel[2][2] - 1.0)
    w = [rel[2][1] - rel[1][2], rel[0][2] - rel[2][0], rel[1][0] - rel[0][1]]
    sin = 0.5 * ca.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    return ca.atan2(sin, ca.if_else(cos > 1.0, 1.0, ca.if_else(cos < -1.0, -1.0, cos)))


def _pitch_error(a, p, pitch):
    """:func:`~planner.geometry.target.pitch_error` of an approach axis (SX)."""
    ax, ay, az = a
    px, py = p[0], p[1]
    cos_p, sin_p = ca.cos(pitch), ca.sin(pitch)
    error = ca.fabs(ca.atan2(az, ca.sqrt(ax * ax + ay * ay)) - ca.atan2(sin_p, ca.fabs(cos_p)))
    radial = ca.sqrt(px * px + py * py)
    wrong = ca.logic_and(radial > RADIAL_EPS, cos_p * (ax * px + ay * py) < 0.0)
    safe = ca.if_else(radial > RADIAL_EPS, radial, 1.0)
    tx, ty = -py / safe, px / safe
    side = ca.if_else(ax * tx + ay * ty < 0.0, -1.0, 1.0)
    bx, by, bz = ca.fabs(cos_p) * side * tx, ca.fabs(cos_p) * side * ty, sin_p
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    to_edge = ca.atan2(ca.sqrt(cx * cx + cy * cy + cz * cz), ax * bx + ay * by + az * bz)
    return ca.if_else(wrong, to_edge, error)
