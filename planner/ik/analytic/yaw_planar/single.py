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

from planner.ik.analytic.result import STATUS_CODES, STATUS_SOLVED
from planner.ik.analytic.yaw_planar.compiled import FLAGS, CompiledKernels
from planner.ik.numeric.codegen import compile_function

__all__ = ["ELBOW_MARGIN", "SingleKernel", "single_kernel"]

_PI = math.pi
_TWO_PI = 2.0 * math.pi
_SOLVED = STATUS_CODES[STATUS_SOLVED]
#: |sin| of the elbow's interior angle below which the kernel leaves the pick to the Python path
#: (the joint values' round-off differences there would exceed about 1e-12 rad).
ELBOW_MARGIN = 2e-3


def _wrapped(a, b):
    """``(a - b + pi) % (2 pi) - pi`` as Python computes it for floats (the sign of the divisor)."""
    m = ca.fmod(a - b + _PI, _TWO_PI)
    return ca.if_else(m < 0.0, m + _TWO_PI, m) - _PI


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
            dist = []
            for m in range(4):
                total = ca.SX(0.0)
                for j in range(dof):
                    d = _wrapped(q[m][j], qc[j])
                    total = d * d if j == 0 else total + d * d
                dist.append(ca.sqrt(total))
            best, nearest = ca.SX(-1), ca.SX(math.inf)
            for m in range(4):
                take = ca.logic_and(within[m], dist[m] < nearest)
                best = ca.if_else(take, m, best)
                nearest = ca.if_else(take, dist[m], nearest)
            ties = ca.SX(0)
            for m in range(4):
                ties = ca.logic_or(ties, ca.logic_and(ca.logic_and(within[m], m != best), dist[m] == nearest))
            sure = ca.logic_and(sure, ca.logic_not(ties))
        else:
            best = codes[1]
        chosen = [
            ca.if_else(best == 0, q[0][j], ca.if_else(best == 1, q[1][j], ca.if_else(best == 2, q[2][j], q[3][j])))
            for j in range(dof)
        ]
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
