"""The answer of :func:`planner.solve_ik` for one planar 2-link target by one compiled call.

:meth:`~planner.ik.analytic.planar2.Planar2IK.nearest`'s lean path written as one CasADi SX
function of one target (position, or position and the rotation's nine entries row by row, then
the seed when there is one), in the same sequence of operations: the law of cosines (positions)
or the heading the rotation asks for (poses), each joint wrapped as
:func:`~planner.geometry.chain.wrap_scalar` (left as it is within its range and pi of the
reference), the limits mask and the pick of :func:`~planner.ik.analytic.nearest.nearest_entry`
(no seed: the first branch within the limits; a seed: the least wrapped joint distance).
Compiled to C and called through a buffer binding (one input and one output vector, bound
once), as the NLP's kernel.

The output is ``[sure, slot, q0, q1]``; ``sure`` is 0, and the caller takes the Python path,
wherever that path gives a status or something other than one clean pick: off the plane, beyond
or inside the reach, a singular or nearly singular elbow (:data:`ELBOW_MARGIN`), an
orientation the arm cannot take or that does not match the position, nothing within the
limits, or two branches at exactly the same distance.
Joint values agree with the Python path's to round-off (``hypot`` there is a square root
here); the caller confirms every answer by Pinocchio FK.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import casadi as ca
import numpy as np

from planner.geometry.chain import LIMIT_SNAP
from planner.ik.analytic.geometry import ORIENTATION_TOL, SINGULAR_TOL
from planner.ik.numeric.codegen import compile_function

__all__ = ["ELBOW_MARGIN", "Planar2Geometry", "Planar2Kernel", "planar2_kernel"]

_PI = math.pi
_TWO_PI = 2.0 * math.pi
#: |sin| of the elbow angle below which a position target is left to the Python path (its
#: joint values' round-off differences there would exceed about 1e-12 rad).
ELBOW_MARGIN = 2e-3
#: 1.5 * 2**52: y + MAGIC - MAGIC rounds y to an integer, halves to even (Python's round).
_MAGIC = 6755399441055744.0
#: As :data:`planner.ik.analytic.yaw_planar.compiled.FLAGS`: no FMA contraction (no -march).
_FLAGS = ("-O3", "-fno-math-errno", "-fno-semantic-interposition", "-fPIC", "-shared")


class Planar2Geometry(NamedTuple):
    """What the kernel needs of a :class:`~planner.ik.analytic.planar2.Planar2IK` (its values)."""

    s1: float
    s2: float
    bx: float
    by: float
    r1: float
    r2: float
    g1: float
    g2: float
    delta: float
    height: float
    len_tol: float
    consistency_tol: float
    lower: tuple[float, float]
    upper: tuple[float, float]
    rot0: np.ndarray


def _wrap_scalar(x, lower: float, upper: float, ref):
    """:func:`~planner.geometry.chain.wrap_scalar` (finite limits), after its shortcut's test."""
    turns = (ref - x) / _TWO_PI
    x = ca.if_else(ca.logic_and(turns >= -0.5, turns <= 0.5), x, x + _TWO_PI * (ca.fabs(turns + _MAGIC) - _MAGIC))
    down, up = x - _TWO_PI, x + _TWO_PI
    turned_down = ca.logic_or(down >= lower - LIMIT_SNAP, (x - upper) > (lower - down))
    turned_up = ca.logic_or(up <= upper + LIMIT_SNAP, (lower - x) > (up - upper))
    x = ca.if_else(x > upper, ca.if_else(turned_down, down, x), ca.if_else(x < lower, ca.if_else(turned_up, up, x), x))
    x = ca.if_else(ca.logic_and(x > upper, x <= upper + LIMIT_SNAP), upper, x)
    return ca.if_else(ca.logic_and(x >= lower - LIMIT_SNAP, x < lower), lower, x)


def _python_mod(a, m: float):
    """``a % m`` as Python computes it for floats (the sign of the divisor, m > 0)."""
    r = ca.fmod(a, m)
    return ca.if_else(r < 0.0, r + m, r)


def _symbolic(g: Planar2Geometry, pose: bool, current: bool) -> ca.Function:
    n_in = 3 + (9 if pose else 0) + (2 if current else 0)
    x = ca.SX.sym("x", n_in)
    px, py, pz = x[0], x[1], x[2]
    ref = [x[n_in - 2], x[n_in - 1]] if current else [0.0, 0.0]
    r1, r2 = g.r1, g.r2
    h, k = px - g.bx, py - g.by
    dd = ca.sqrt(h * h + k * k)
    sure = ca.logic_and(ca.fabs(pz - g.height) <= g.len_tol, dd <= r1 + r2 + g.len_tol)
    sure = ca.logic_and(sure, dd >= abs(r1 - r2) - g.len_tol)
    if pose:
        rot = [[x[3 + 3 * i + j] for j in range(3)] for i in range(3)]
        r0 = np.asarray(g.rot0, dtype=float)
        # m = R @ rot0.T, entry by entry as NumPy's matmul sums three products.
        m = [[rot[i][0] * r0[j, 0] + rot[i][1] * r0[j, 1] + rot[i][2] * r0[j, 2] for j in range(3)] for i in range(3)]
        heading = ca.atan2(m[1][0], m[0][0])
        c, s = ca.cos(heading), ca.sin(heading)
        rz = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
        rel = [[sum(rz[r][i] * m[r][j] for r in range(3)) for j in range(3)] for i in range(3)]  # rz.T @ m
        cos_r = 0.5 * (rel[0][0] + rel[1][1] + rel[2][2] - 1.0)
        sin_r = 0.5 * ca.sqrt(
            (rel[2][1] - rel[1][2]) ** 2 + (rel[0][2] - rel[2][0]) ** 2 + (rel[1][0] - rel[0][1]) ** 2
        )
        residual = ca.atan2(sin_r, ca.fmin(1.0, ca.fmax(-1.0, cos_r)))
        sure = ca.logic_and(sure, residual <= ORIENTATION_TOL)
        ex = h - r2 * ca.cos(heading + g.g2)
        ey = k - r2 * ca.sin(heading + g.g2)
        sure = ca.logic_and(sure, ca.fabs(ca.sqrt(ex * ex + ey * ey) - r1) <= g.consistency_tol)
        a1 = ca.atan2(ey, ex)
        e = _python_mod(heading + g.g2 - a1 + _PI, _TWO_PI) - _PI
        # One branch, named by the elbow's side; slot 0 ("elbow-left") or 1.
        branches = [(a1, e)]
        # A stretched or folded elbow (|sin e| < SINGULAR_TOL): elbow-left, as the Python path.
        slot_of = [ca.if_else(ca.logic_or(e <= 0.0, ca.fabs(ca.sin(e)) < SINGULAR_TOL), 0, 1)]
    else:
        c = ca.fmin(1.0, ca.fmax(-1.0, (dd * dd - r1 * r1 - r2 * r2) / (2.0 * r1 * r2)))
        s = ca.sqrt(1.0 - c * c)
        # A singular elbow gives one branch (the Python path's); near one, the round-off
        # differences (hypot there, a square root here) grow as 1 / s: both left to Python.
        sure = ca.logic_and(sure, s >= max(SINGULAR_TOL, ELBOW_MARGIN))
        e_abs = ca.atan2(s, c)
        base = ca.atan2(k, h)
        half = ca.atan2(r2 * s, r1 + r2 * c)
        branches = [(base + half, -e_abs), (base - half, e_abs)]
        slot_of = [ca.SX(0), ca.SX(1)]
    (lo0, lo1), (hi0, hi1) = g.lower, g.upper
    rows, within = [], []
    for a1, e in branches:
        v0, v1 = g.s1 * (a1 - g.g1), g.s2 * (e - g.delta)
        keep0 = ca.logic_and(ca.logic_and(v0 >= lo0, v0 <= hi0), ca.logic_and(v0 - ref[0] >= -_PI, v0 - ref[0] <= _PI))
        keep1 = ca.logic_and(ca.logic_and(v1 >= lo1, v1 <= hi1), ca.logic_and(v1 - ref[1] >= -_PI, v1 - ref[1] <= _PI))
        v0 = ca.if_else(keep0, v0, _wrap_scalar(v0, lo0, hi0, ref[0]))
        v1 = ca.if_else(keep1, v1, _wrap_scalar(v1, lo1, hi1, ref[1]))
        rows.append((v0, v1))
        within.append(ca.logic_and(ca.logic_and(v0 >= lo0, v0 <= hi0), ca.logic_and(v1 >= lo1, v1 <= hi1)))
    if len(rows) == 1:
        best = ca.SX(0)
        sure = ca.logic_and(sure, within[0])
    elif current:
        dist = []
        for v0, v1 in rows:
            d0 = _python_mod(v0 - ref[0] + _PI, _TWO_PI) - _PI
            d1 = _python_mod(v1 - ref[1] + _PI, _TWO_PI) - _PI
            dist.append(ca.sqrt(d0 * d0 + d1 * d1))
        both = ca.logic_and(within[0], within[1])
        best = ca.if_else(both, ca.if_else(dist[1] < dist[0], 1, 0), ca.if_else(within[0], 0, 1))
        sure = ca.logic_and(sure, ca.logic_or(within[0], within[1]))
        sure = ca.logic_and(sure, ca.logic_not(ca.logic_and(both, dist[0] == dist[1])))
    else:
        best = ca.if_else(within[0], 0, 1)
        sure = ca.logic_and(sure, ca.logic_or(within[0], within[1]))
    if len(rows) == 1:
        q0, q1 = rows[0]
        slot = slot_of[0]
    else:
        q0 = ca.if_else(best == 0, rows[0][0], rows[1][0])
        q1 = ca.if_else(best == 0, rows[0][1], rows[1][1])
        slot = best
    return ca.Function("planar2_nearest", [x], [ca.cse(ca.vertcat(sure, slot, q0, q1))])


class Planar2Kernel:
    """The compiled function of one target kind, its buffers bound once.

    Attributes:
        inputs: Position, then the rotation's nine entries row by row (poses), then the seed.
        outputs: ``[sure, slot, q0, q1]`` (see the module docstring).
        compiled: Whether the function runs as C code.

    Not thread-safe: its buffers serve one call at a time (each solver owns its kernels).
    """

    def __init__(self, geometry: Planar2Geometry, pose: bool, current: bool) -> None:
        self.function = compile_function(_symbolic(geometry, pose, current), flags=_FLAGS)
        self.compiled = self.function.class_name() == "External"
        self.inputs = np.zeros(3 + (9 if pose else 0) + (2 if current else 0))
        self.outputs = np.zeros(4)
        self._buffer, self._evaluate = self.function.buffer()
        self._buffer.set_arg(0, memoryview(self.inputs))
        self._buffer.set_res(0, memoryview(self.outputs))

    def __call__(self) -> None:
        """Evaluate from :attr:`inputs` into :attr:`outputs`."""
        self._evaluate()


def planar2_kernel(geometry: Planar2Geometry, pose: bool, current: bool) -> Planar2Kernel | None:
    """The compiled :class:`Planar2Kernel`, or None where it would not be compiled C (or limits are infinite)."""
    if not all(math.isfinite(v) for v in (*geometry.lower, *geometry.upper)):
        return None
    kernel = Planar2Kernel(geometry, pose, current)
    return kernel if kernel.compiled else None
