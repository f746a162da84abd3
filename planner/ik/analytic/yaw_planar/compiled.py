"""The batch closed form as one compiled function over targets (exact chains).

On exact chains (no correction on the real geometry), each target's four branches follow
from a fixed sequence of square roots, arc tangents, sines and cosines: position targets
(the tip on the roll axis, or no roll), approach-pitch targets and full poses, with or
without q_current. :class:`CompiledKernels` writes that sequence, the same as
:func:`~planner.ik.analytic.yaw_planar.core.solve_core` (with
:mod:`~planner.ik.analytic.yaw_planar.orientation` for poses and
:func:`~planner.ik.analytic.yaw_planar.free_pitch.free_pitch_array` for the free end angle of
three pitch joints), the errors (:func:`~planner.ik.analytic.yaw_planar.core.ideal_position_error`,
or for poses :func:`~planner.ik.analytic.yaw_planar.refine.refine`'s check by the product of
exponentials), the wrapping into the joint ranges nearest q_current
(:func:`~planner.geometry.chain.wrap_array`),
:func:`~planner.ik.analytic.yaw_planar.status.status_codes` and the branch nearest q_current,
as one CasADi SX function of one target, maps it over a block of targets and compiles it to C
(:func:`~planner.ik.numeric.codegen.compile_function`; CasADi's virtual machine without a
compiler). :func:`solve_compiled` runs it block by block. Targets that need the search within
the limits (a free end angle, not solved at the chosen one) or q_current's end angle out of
reach are handed back to NumPy (see :func:`~planner.ik.analytic.yaw_planar.batch.solve_compiled_within`).
Branches, categories, statuses and masks are the NumPy path's; joint values and errors agree
to round-off.

Speed: the checks run without libm calls. The cosines and sines of the computed angles that
feed only the errors' forward kinematics and the pose check by the product of exponentials
are carried along from the geometry that gave them (:class:`_Angle`: ``cos(atan2(y, x)) =
x / r``, the law of cosines, the sum formulas), and the orientation tests compare sines with
``sin(tol)`` instead of calling ``asin`` or ``atan2``. Whatever decides a returned angle or a
branch's side (the end angle's cosine and sine before the wrist point's arc tangents, the
yaw's in the rotation's pitch and roll, which side faces q_current) takes ``cos`` and ``sin``
of the same values as NumPy: the sum formulas' exact zeros (``sin(pi - 0) = 0`` where libm
gives 1.2e-16) would move answers at half turns by 2 pi (joint values of quarter-turn
configurations). So the joint values, masks, statuses and best branches are those of the
plain formulas bit for bit (1e6 generated targets per arm, kind and q_current); the position
errors change by round-off (< 1e-14 m). The end angle's two candidates (the approach pitch
alpha, or pi - alpha on the side facing away) get their cosines and sines before the side is
known (:func:`_chosen_end`): the ``sincos`` calls then need not wait for the yaw's arc
tangent. Each wrapped joint's limits test shares the comparisons of the snaps onto the limits
(:func:`wrap_within_sx`).

Compiler flags: ``-O3`` without ``-march``: the shared library is cached on disk by a hash of
the code and flags, not of the CPU, so it must run on any x86-64 (and FMA contraction would
change round-off against the NumPy path).
"""

from __future__ import annotations

import functools
import math
import struct
from decimal import Decimal
from fractions import Fraction

import casadi as ca
import numpy as np

from planner.geometry.chain import LIMIT_SNAP, rodrigues_rows
from planner.ik.analytic.geometry import SINGULAR_TOL
from planner.ik.analytic.result import (
    STATUS_BEYOND_MAX_REACH,
    STATUS_CODES,
    STATUS_INSIDE_MIN_REACH,
    STATUS_ORIENTATION_NOT_ACHIEVABLE,
    STATUS_OUTSIDE_JOINT_LIMITS,
    STATUS_SOLVED,
)
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.arrays import BranchArrays
from planner.ik.analytic.yaw_planar.branches import BEYOND, CYLINDER, DUPLICATE, INSIDE, ORIENT, VALID
from planner.ik.numeric.codegen import compile_function

__all__ = [
    "BLOCK",
    "SMALL_BLOCK",
    "CompiledKernels",
    "compiled_supported",
    "kind_supported",
    "cos_nonnegative",
    "forward_sx",
    "kind_of",
    "solve_compiled",
    "wrap_sx",
]

PI = math.pi
TWO_PI = 2.0 * math.pi
#: C compiler flags: no errno after sqrt (inline square roots), CasADi's helpers inlined; no
#: FMA contraction on x86-64 (no -march).
FLAGS = ("-O3", "-fno-math-errno", "-fno-semantic-interposition", "-fPIC", "-shared")
#: Targets per call of the compiled function (the last block is padded).
BLOCK = 4096
#: Targets per call for the rest.
SMALL_BLOCK = 64
REP = (0, 0, 1, 1)
#: 1.5 * 2**52: x + MAGIC - MAGIC rounds x to an integer, halves to even.
MAGIC = 6755399441055744.0


def compiled_supported(arm: ArmGeometry, pit, rot, qc) -> bool:
    """Whether :func:`solve_compiled` gives the NumPy path's answers for these inputs."""
    if not arm.exact or arm.elbow_seed > 0.0:
        return False
    if rot is not None:
        return pit is None
    if not arm.tip_on_roll_axis:
        return False
    # Without q_current the roll is 0, which must lie within its range (else NumPy wraps it).
    return not (qc is None and arm.has_roll and not arm.lower[arm.roll_idx] <= 0.0 <= arm.upper[arm.roll_idx])


def kind_supported(arm: ArmGeometry, kind: str, current: bool) -> bool:
    """:func:`compiled_supported` for every target of a kind, with or without q_current."""
    pit = 0.0 if kind == "pitch" else None
    rot = np.eye(3) if kind == "pose" else None
    return compiled_supported(arm, pit, rot, np.zeros(arm.dof) if current else None)


def _where(cond, a, b):
    return ca.if_else(cond, a, b)


def _code(cond, a, b):
    """``where(cond, a, b)`` for small integer codes `a`, `b` and a 0/1 `cond`: ``b + cond (a - b)`` (exact)."""
    return b + cond * (a - b)


def _max(x, c: float):
    """C's ``fmax(x, c)`` for a constant `c` (glibc's: x where ``x >= c``, c where x is NaN), inline.

    (CasADi's ``fmax`` compiles to a libm call.)
    """
    return _where(x >= c, x, c)


def _min(x, c: float):
    """C's ``fmin(x, c)`` for a constant `c`, inline (see :func:`_max`)."""
    return _where(x <= c, x, c)


def _rint(y):
    """``numpy.round``: to the nearest integer, halves to even, for ``|y| < 2**51``.

    Adding and subtracting 1.5 * 2**52 leaves the integer that the addition rounds to (round
    to nearest, ties to even). ``fabs`` of the (positive) sum keeps CasADi from folding the
    pair away; it compiles to one instruction (``fmax`` would be a call).
    """
    return ca.fabs(y + MAGIC) - MAGIC


def _pi_parts() -> tuple[float, float, float]:
    """Three doubles P1 + P2 + P3 that sum to pi within 1e-31 (Cody and Waite 1980).

    P1 and P2 have 26 significant bits: their products with small half-integers are exact.
    """
    pi = Fraction(Decimal("3.14159265358979323846264338327950288419716939937510582097494459230781640628"))
    p1 = Fraction(math.floor(pi * 2**24), 2**24)
    p2 = Fraction(math.floor((pi - p1) * 2**50), 2**50)
    return float(p1), float(p2), float(pi - p1 - p2)


PI_PARTS = _pi_parts()
INV_PI = 1.0 / math.pi


def _div_const(x, c: float):
    """``x / c`` for a constant `c`; where c is a power of two, the product with ``1 / c`` (exactly the same double)."""
    mant, exp = math.frexp(c)
    if abs(mant) == 0.5 and -1000 < exp < 1000:
        return x * (1.0 / c)
    return x / c


def cos_nonnegative(x):
    """Whether ``cos(x) >= 0`` for `x` of moderate size (|x| < 1e6), without calling ``cos``.

    The cosine of a double is never 0 and libm's (as NumPy's) has the sign of the exact
    value, which is that of ``(-1)^(m + 1) e`` with e = x - (m + 1/2) pi for the zero
    (m + 1/2) pi of the cosine nearest x (any m with |e| < pi will do: m is rounded from
    ``x * (1 / pi)``, a product instead of a division, which may differ from x / pi by an
    ulp, so from the nearest m only where x is near a multiple of pi, where |e| is near
    pi / 2). e is computed with pi in three parts: exact near the zeros (Sterbenz), where only
    its sign matters.
    """
    m = _rint(x * INV_PI - 0.5)
    h = m + 0.5
    p1, p2, p3 = PI_PARTS
    e = ((x - h * p1) - h * p2) - h * p3
    odd = abs(m - 2.0 * _rint(0.5 * m)) > 0.5
    return odd == (e > 0.0)


def _wrap_pi(x):
    """:func:`~planner.ik.analytic.geometry.wrap_pi` as NumPy's float remainder computes it."""
    m = ca.fmod(x + PI, TWO_PI)
    return _where(m < 0.0, m + TWO_PI, m) - PI


class _Angle:
    """An angle [rad] (an SX value) with its cosine and sine, carried through sums and differences.

    The cosines and sines come from the geometry that gave the angles (``cos(atan2(y, x)) =
    x / r``) and the sum formulas, not from calls to ``sin`` and ``cos`` (except :meth:`of`);
    the values of the angles are the plain formulas', their cosines and sines agree with
    ``cos(value)`` and ``sin(value)`` to round-off.
    """

    __slots__ = ("a", "c", "s")

    def __init__(self, a, c, s) -> None:
        self.a, self.c, self.s = a, c, s

    @classmethod
    def of(cls, a) -> _Angle:
        """`a` with its cosine and sine by ``cos`` and ``sin`` (an input angle)."""
        return cls(a, ca.cos(a), ca.sin(a))

    @classmethod
    def const(cls, a: float) -> _Angle:
        return cls(ca.SX(a), math.cos(a), math.sin(a))

    @classmethod
    def atan2(cls, y, x, r=None) -> _Angle:
        """``atan2(y, x)``; `r`: ``hypot(x, y)`` if already computed.

        At ``x = y = 0`` the angle is +-0 or +-pi (the signs of the zeros): cosine +-1, sine 0.
        """
        a = ca.atan2(y, x)
        if r is None:
            r = ca.sqrt(x * x + y * y)
        zero = r == 0.0
        # The selections as sums with a zero where not chosen (r + 0 is r; c - 0 keeps -0.0), and
        # at r = 0 x -+ 1 is -+1 (|x| < 1e-154 there).
        safe = r + ca.if_else(zero, 1.0, 0.0)
        flip = ca.if_else(zero, ca.if_else(abs(a) < 1.0, -1.0, 1.0), 0.0)
        return cls(a, x / safe - flip, _where(zero, 0.0, y / safe))

    @staticmethod
    def where(cond, a: _Angle, b: _Angle) -> _Angle:
        return _Angle(_where(cond, a.a, b.a), _where(cond, a.c, b.c), _where(cond, a.s, b.s))

    def __add__(self, o: _Angle) -> _Angle:
        return _Angle(self.a + o.a, self.c * o.c - self.s * o.s, self.s * o.c + self.c * o.s)

    def __sub__(self, o: _Angle) -> _Angle:
        return _Angle(self.a - o.a, self.c * o.c + self.s * o.s, self.s * o.c - self.c * o.s)

    def __neg__(self) -> _Angle:
        return _Angle(-self.a, self.c, -self.s)

    def shift(self, k: float) -> _Angle:
        """``a + k`` for a constant k (``a - k`` is ``a + (-k)`` in floating point)."""
        if k == 0.0:
            return self
        if k == PI:
            return _Angle(self.a + k, -self.c, -self.s)
        ck, sk = math.cos(k), math.sin(k)
        return _Angle(self.a + k, self.c * ck - self.s * sk, self.s * ck + self.c * sk)

    def signed(self, sign: float) -> _Angle:
        """``sign a`` for sign +-1."""
        return _Angle(sign * self.a, self.c, sign * self.s)


def _chosen_end(cond, alpha, beta: float) -> _Angle:
    """``where(cond, alpha, pi - alpha) - beta`` with its cosine and sine by libm.

    The cosines and sines of both candidates (two ``sincos`` calls, shared by the sides),
    chosen afterwards: the calls need not wait for `cond`. The same doubles as
    ``_Angle.of`` of the chosen value: the candidates differ from it only in the sign of a
    zero (``where`` turns -0.0 into 0.0), where the cosine is 1 and the chosen sine is 0.0.
    """
    toward, away = _Angle.of(alpha - beta), _Angle.of((PI - alpha) - beta)
    c, s = _where(cond, toward.c, away.c), _where(cond, toward.s, away.s)
    return _Angle(_where(cond, alpha, PI - alpha) - beta, c, s)


def wrapped_sx(a, b):
    """``(a - b + pi) % (2 pi) - pi`` as Python computes it for floats (the sign of the divisor)."""
    m = ca.fmod(a - b + PI, TWO_PI)
    return ca.if_else(m < 0.0, m + TWO_PI, m) - PI


def nearest_branch_sx(q: list, within: list, qc) -> tuple:
    """The branch within the limits nearest `qc` (Euclidean over the wrapped joint differences).

    Args:
        q: Per branch, its joints as SX scalars.
        within: Per branch, whether it lies within the limits (SX).
        qc: The reference configuration (SX, one entry per joint).

    Returns:
        ``(best, ties)``: the first nearest branch's index (-1: none within), and whether another
        branch within the limits is exactly as near.
    """
    dist = []
    for qm in q:
        total = ca.SX(0.0)
        for j, qj in enumerate(qm):
            d = wrapped_sx(qj, qc[j])
            total = d * d if j == 0 else total + d * d
        dist.append(ca.sqrt(total))
    best, nearest = ca.SX(-1), ca.SX(math.inf)
    for m in range(len(q)):
        take = ca.logic_and(within[m], dist[m] < nearest)
        best = ca.if_else(take, m, best)
        nearest = ca.if_else(take, dist[m], nearest)
    ties = ca.SX(0)
    for m in range(len(q)):
        ties = ca.logic_or(ties, ca.logic_and(ca.logic_and(within[m], m != best), dist[m] == nearest))
    return best, ties


def pick_branch_sx(q: list, best) -> list:
    """The joints of four branches' branch `best` (any other index: the last one's)."""
    return [
        ca.if_else(best == 0, q[0][j], ca.if_else(best == 1, q[1][j], ca.if_else(best == 2, q[2][j], q[3][j])))
        for j in range(len(q[0]))
    ]


def wrap_sx(x, lower: float, upper: float, ref=0.0):
    """:func:`~planner.geometry.chain.wrap_array`, one value.

    After the turn to the nearest 2 pi multiple of `ref`, wrap_array's steps towards the range
    (x - 2 pi for some x above it, then x + 2 pi for some x below it) each decide by a
    test that is monotone in x (differences of x with constants, rounded: non-decreasing in
    x), so each holds exactly from a threshold on, found once here on the doubles
    (:func:`_step_thresholds`): one comparison per step instead of eight operations. Then
    the snaps onto the limits.
    """
    return wrap_within_sx(x, lower, upper, ref)[0]


def wrap_within_sx(x, lower: float, upper: float, ref=0.0):
    """:func:`wrap_sx` and whether its value lies within ``[lower, upper]`` (the same test on it).

    The snaps move values within ``LIMIT_SNAP`` outside a limit onto it, so the wrapped value
    is within the range exactly where the value before the snaps lies within the range
    widened by the snaps (``lower - LIMIT_SNAP``, ``upper + LIMIT_SNAP`` as doubles): these
    two comparisons serve both the snaps and the test. Where ``x - limit`` is exact for the
    values that snap (Sterbenz 1974: the limit 0, or at least ``2 LIMIT_SNAP`` from it), the
    snap is ``x - (x - limit)``, that limit exactly (one operation less than a selection).
    """
    x = x - TWO_PI * _rint((x - ref) / TWO_PI)
    if not (math.isfinite(lower) and math.isfinite(upper)):
        x = _wrap_unbounded(x, lower, upper)
        return x, ca.logic_and(x >= lower, x <= upper)
    down_from, up_to = _step_thresholds(lower, upper)
    x = x - _where(x >= down_from, TWO_PI, 0.0)
    x = x + _where(x <= up_to, TWO_PI, 0.0)
    above, below = x >= lower - LIMIT_SNAP, x <= upper + LIMIT_SNAP
    snap_up, snap_down = ca.logic_and(x > upper, below), ca.logic_and(x < lower, above)
    x = _snap(x, snap_up, upper)
    return _snap(x, snap_down, lower), ca.logic_and(above, below)


def _snap(x, cond, limit: float):
    """``where(cond, limit, x)`` for `x` within LIMIT_SNAP of `limit` where `cond` holds."""
    if limit == 0.0 or abs(limit) >= 2.0 * LIMIT_SNAP:
        return x - ca.if_else(cond, x - limit, 0.0)
    return _where(cond, limit, x)


def _wrap_unbounded(x, lower: float, upper: float):
    """wrap_array's steps after the turn, for a range with an infinite limit (as written there)."""
    if not (math.isfinite(lower) or math.isfinite(upper)):
        return x
    down = x - TWO_PI
    turn = ca.logic_or(down >= lower - LIMIT_SNAP, (x - upper) > (lower - down))
    x = _where(ca.logic_and(x > upper, turn), down, x)
    up = x + TWO_PI
    turn = ca.logic_or(up <= upper + LIMIT_SNAP, (lower - x) > (up - upper))
    x = _where(ca.logic_and(x < lower, turn), up, x)
    x = _where(ca.logic_and(x > upper, x <= upper + LIMIT_SNAP), upper, x)
    return _where(ca.logic_and(x < lower, x >= lower - LIMIT_SNAP), lower, x)


def _step_down(x: float, lower: float, upper: float) -> bool:
    """wrap_array's test for x - 2 pi (in doubles, as NumPy computes it)."""
    down = x - TWO_PI
    return x > upper and (down >= lower - LIMIT_SNAP or (x - upper) > (lower - down))


def _step_up(x: float, lower: float, upper: float) -> bool:
    """wrap_array's test for x + 2 pi."""
    up = x + TWO_PI
    return x < lower and (up <= upper + LIMIT_SNAP or (lower - x) > (up - upper))


def _ordered(x: float) -> int:
    """An integer of the same order as the double x (finite x)."""
    (i,) = struct.unpack("<q", struct.pack("<d", x))
    return i if i >= 0 else -(i & 0x7FFFFFFFFFFFFFFF)


def _from_ordered(i: int) -> float:
    (x,) = struct.unpack("<d", struct.pack("<q", i if i >= 0 else (-i) | -0x8000000000000000))
    return x


@functools.lru_cache(maxsize=256)
def _step_thresholds(lower: float, upper: float) -> tuple[float, float]:
    """The doubles from which on wrap_array steps down (x >= first) and up to which it steps up (x <= second).

    Each test is monotone in x (:func:`wrap_sx`), so bisection on the doubles finds where it
    switches.
    """

    def edge(test, below: float, above: float) -> int:
        # The first double in (below, above] where test holds (false at below, true at above).
        a, b = _ordered(below), _ordered(above)
        if test(_from_ordered(a)) or not test(_from_ordered(b)):
            raise RuntimeError(f"wrap_sx: no threshold in [{below}, {above}] for the range [{lower}, {upper}]")
        while b - a > 1:
            mid = (a + b) // 2
            if test(_from_ordered(mid)):
                b = mid
            else:
                a = mid
        return b

    first_down = edge(lambda v: _step_down(v, lower, upper), upper, upper + 2.0 * TWO_PI)
    last_up = edge(lambda v: not _step_up(v, lower, upper), lower - 2.0 * TWO_PI, lower) - 1
    return _from_ordered(first_down), _from_ordered(last_up)


def _one_target(arm: ArmGeometry, kind: str, current: bool, distances: bool = False) -> ca.Function:
    """The closed form of one target as an SX function of (position, pitch or rotation, q_current).

    `kind` is "position", "pitch" or "pose" (the rotation's nine entries row by row). The
    outputs are the per-target arrays; where the end angle is free (three pitch joints,
    position targets), a last one is 1 where :func:`solve_compiled` must hand the target to
    NumPy: not solved (the search within the limits), or q_current's end angle out of a
    side's reach (the default choice); with q_current (position and pitch targets) that last
    one is also 1 for a target on the yaw axis (the yaw is q_current's). With `distances`, one
    more output: each branch's wrist point to shoulder distance [m] (its side's).
    """
    pitch, pose = kind == "pitch", kind == "pose"
    p = ca.SX.sym("p", 3)
    pit = ca.SX.sym("pit") if pitch else None
    rflat = ca.SX.sym("rot", 9) if pose else None
    qc = ca.SX.sym("qc", arm.dof) if current else None
    dof = arm.dof
    rot = m_rot = None
    end = p
    if pose:
        rot = [[rflat[3 * i + j] for j in range(3)] for i in range(3)]
        m_rot = _matmul(rot, np.asarray(arm.rot0).T.tolist())
    if pose and arm.has_roll:
        tu, tz, d = arm.centre
        c = [float(v) for v in arm.centre_to_tip_local]
        end = [p[i] - (rot[i][0] * c[0] + rot[i][1] * c[1] + rot[i][2] * c[2]) for i in range(3)]
    else:
        tu, tz, d = arm.tip_fixed
    hx = end[0] - arm.bx
    hy = end[1] - arm.by
    ze = end[2]
    rho2 = hx * hx + hy * hy
    axis_tol = arm.len_tol
    free = ca.logic_and(rho2 <= axis_tol * axis_tol, abs(d) <= axis_tol)
    len_tol = arm.core_len_tol
    under = rho2 - d * d
    cylinder = ca.logic_and(ca.logic_not(free), under < -2.0 * abs(d) * len_tol)
    rho = ca.sqrt(rho2)
    # (Without a lateral offset, u is rho: sqrt(max(rho2, 0)) = sqrt(rho2) for finite targets.)
    u = rho if d == 0.0 else ca.sqrt(_max(under, 0.0))
    ang = _Angle.atan2(hy, hx, rho).shift(-arm.mu)
    if d == 0.0:
        # NumPy's atan2(-0.0, u) and atan2(-0.0, -u) for u >= 0 (CasADi folds -0.0 into 0).
        psi_f = ang
        psi_b = ang.shift(PI)
    else:
        r_d = ca.sqrt(u * u + d * d)
        psi_f = ang - _Angle(ca.atan2(-d, u), u / r_d, -d / r_d)
        psi_b = ang - _Angle(ca.atan2(-d, -u), -u / r_d, -d / r_d)
    back_dup = ca.logic_or(free, u == 0.0)
    # q_current's yaw sigma q0 [rad] (poses); position and pitch targets on the yaw axis with
    # q_current are handed over (rare: its cosine and sine would cost two libm calls per target).
    yaw_qc = _Angle.of(qc[0]).signed(arm.sigma) if current and pose else None
    psi_f = _Angle.where(free, yaw_qc if yaw_qc is not None else _Angle.const(0.0), psi_f)
    u = _where(free, 0.0, u)
    psi = [psi_f, psi_b]
    ue = [u, -u]
    cat = [_where(cylinder, CYLINDER, VALID), _where(cylinder, CYLINDER, _where(back_dup, DUPLICATE, VALID))]
    phi_rot = roll_side = None
    if pose:
        psi, ue, cat = _yaw_for_rotation(arm, m_rot, hx, hy, d, u, psi, ue, cat)
        phi_rot, residual = _pitch_from_rotation(arm, m_rot, psi)
        if arm.has_roll:
            roll_side = _roll_from_rotation(arm, m_rot, psi, phi_rot)
        if arm.n_pitch == 3:
            cat = [_where(ca.logic_and(cat[k] == VALID, residual[k]), ORIENT, cat[k]) for k in range(2)]
    # The cosines and sines of the yaws psi + mu.
    cy = [psi[k].shift(arm.mu).c for k in range(2)]
    sy = [psi[k].shift(arm.mu).s for k in range(2)]
    end_t = None
    if pitch:
        end_t = [_chosen_end(cy[k] * p[0] + sy[k] * p[1] >= 0.0, pit, arm.beta) for k in range(2)]
    l1, g1, su, sz = arm.l1, arm.g1, arm.su, arm.sz
    sg, idx = arm.signs, arm.pitch_idx
    # Per branch: the joint angles, the in-plane angles of the links and of the end (the
    # position error's forward kinematics).
    qa = [[None] * dof for _ in range(4)]
    links, ends = [None] * 4, [None] * 4
    cat4 = [None] * 4
    free_end = arm.n_pitch == 3 and kind == "position"
    # The roll of position and pitch targets: q_current's or 0 (its cosine and sine unused).
    roll_q = None
    if arm.has_roll and not pose:
        roll_q = _Angle(qc[arm.roll_idx], None, None) if current else _Angle.const(0.0)
    handover = None
    if free_end and current:
        phi_end, handover = _current_end_angle(arm, qc, psi, ue, ze)
    elif free_end:
        phi_end, fail = _default_end_angle(arm, ue, ze)
        cat = [_where(ca.logic_and(cat[k] == VALID, fail[k] != VALID), fail[k], cat[k]) for k in range(2)]
    if arm.n_pitch == 2 and (pitch or pose):
        l2 = math.hypot(tu, tz)
        g2 = math.atan2(tz, tu)
        dist2 = []
        sing2 = []
        for k in range(2):
            de = ca.sqrt((ue[k] - su) ** 2 + (ze - sz) ** 2)
            c = cat[k]
            c = _where(ca.logic_and(c == VALID, de > l1 + l2 + len_tol), BEYOND, c)
            c = _where(ca.logic_and(c == VALID, de < abs(l1 - l2) - len_tol), INSIDE, c)
            if pose:
                phi = phi_rot[k]
                c = _where(ca.logic_and(c == VALID, residual[k]), ORIENT, c)
            else:
                phi = end_t[k]
            cp, sp = phi.c, phi.s
            ex = ue[k] - (cp * tu - sp * tz) - su
            ez = ze - (sp * tu + cp * tz) - sz
            tol = max(arm.consistency_tol, len_tol)
            r_e = ca.sqrt(ex * ex + ez * ez)
            c = _where(ca.logic_and(c == VALID, abs(r_e - l1) > tol), ORIENT, c)
            a1 = _Angle.atan2(ez, ex, r_e)
            e = _wrap_pi(phi.a + g2 - a1.a)
            sin_e = (phi.shift(g2) - a1).s
            # A stretched or folded elbow: one solution, labelled elbow-up (as solve_core_pose2).
            up = ca.logic_or((e <= 0.0) if k == 0 else (e >= 0.0), abs(sin_e) < SINGULAR_TOL)
            phi2 = a1.shift(-g1)
            for m, chosen in ((2 * k, up), (2 * k + 1, ca.logic_not(up))):
                qa[m][0] = psi[k].signed(arm.sigma)
                qa[m][idx[0]] = phi2.signed(sg[0])
                qa[m][idx[1]] = (phi - phi2).signed(sg[1])
                if arm.has_roll:
                    qa[m][arm.roll_idx] = roll_side[k] if pose else roll_q
                cat4[m] = _where(ca.logic_and(c == VALID, ca.logic_not(chosen)), DUPLICATE, c)
                links[m], ends[m] = [a1], phi
            dist2.append(de)
            sing2.append(
                ca.logic_or(ca.logic_or(abs(sin_e) < SINGULAR_TOL, free), abs(ue[k]) < SINGULAR_TOL * arm.scale)
            )
        dist = [dist2[r] for r in REP]
        singular = [sing2[r] for r in REP]
    else:
        if arm.n_pitch == 3:
            l2, g2 = arm.l2, arm.g2
            phi = phi_end if free_end else phi_rot if pose else end_t
            cp = [phi[k].c for k in range(2)]
            sp = [phi[k].s for k in range(2)]
            wu = [ue[k] - (cp[k] * tu - sp[k] * tz) for k in range(2)]
            wz = [ze - (sp[k] * tu + cp[k] * tz) for k in range(2)]
        else:
            l2 = math.hypot(tu, tz)
            g2 = math.atan2(tz, tu)
            wu, wz = ue, [ze, ze]
        dist2, sing2, e_abs, base, half = [], [], [], [], []
        for k in range(2):
            vx = wu[k] - su
            vz = wz[k] - sz
            dk = ca.sqrt(vx * vx + vz * vz)
            c = cat[k]
            c = _where(ca.logic_and(c == VALID, dk > l1 + l2 + len_tol), BEYOND, c)
            cat[k] = _where(ca.logic_and(c == VALID, dk < abs(l1 - l2) - len_tol), INSIDE, c)
            cc = _min(_max(_div_const(dk * dk - l1 * l1 - l2 * l2, 2.0 * l1 * l2), -1.0), 1.0)
            s = ca.sqrt(1.0 - cc * cc)
            es = s < SINGULAR_TOL
            s = _where(es, 0.0, s)
            cc = _where(es, ca.sign(cc) + (cc == 0), cc)
            e_abs.append(_Angle(ca.atan2(s, cc), cc, s))
            base.append(_Angle.atan2(vz, vx, dk))
            half.append(_Angle.atan2(l2 * s, l1 + l2 * cc))
            dist2.append(dk)
            sing2.append(es)
        e = [-e_abs[0], e_abs[0], e_abs[1], -e_abs[1]]
        a1 = [base[0] + half[0], base[0] - half[0], base[1] - half[1], base[1] + half[1]]
        for m in range(4):
            k = REP[m]
            elbow = a1[m] + e[m]
            phi2 = a1[m].shift(-g1)
            phi3 = elbow.shift(-g2)
            qa[m][0] = psi[k].signed(arm.sigma)
            qa[m][idx[0]] = phi2.signed(sg[0])
            qa[m][idx[1]] = (phi3 - phi2).signed(sg[1])
            if arm.n_pitch == 3:
                qa[m][idx[2]] = (phi[k] - phi3).signed(sg[2])
            if arm.has_roll:
                qa[m][arm.roll_idx] = roll_side[k] if pose else roll_q
            links[m] = [a1[m], elbow] if arm.n_pitch == 3 else [a1[m]]
            ends[m] = phi[k] if arm.n_pitch == 3 else phi3
            c = cat[k]
            if m in (1, 3):
                c = _where(ca.logic_and(c == VALID, sing2[k]), DUPLICATE, c)
            cat4[m] = c
        dist = [dist2[r] for r in REP]
        singular = [
            ca.logic_or(ca.logic_or(sing2[REP[m]], free), abs(ue[REP[m]]) < SINGULAR_TOL * arm.scale) for m in range(4)
        ]
    q = [[qa[m][j].a for j in range(dof)] for m in range(4)]
    if pose:
        # Errors by the real model (product of exponentials; refine's on exact chains), before wrapping.
        pos_tol = 1e-10 * max(1.0, arm.scale)
        perr = []
        for m in range(4):
            fk_p, fk_r = _poe_fk(arm, qa[m])
            perr.append(ca.sqrt(sum((fk_p[i] - p[i]) ** 2 for i in range(3))))
            ok = ca.logic_and(perr[m] <= pos_tol, _rotation_beyond(fk_r, rot, arm.orient_tol) <= 0.0)
            cat4[m] = _where(ca.logic_and(cat4[m] == VALID, ca.logic_not(ok)), ORIENT, cat4[m])
    else:
        perr = _ideal_position_error(arm, links, ends, cy, sy, p)
    valid = [cat4[m] == VALID for m in range(4)]
    within = list(valid)
    nan = ca.SX(float("nan"))
    for m in range(4):
        for j in range(dof):
            if current or pose or not (arm.has_roll and j == arm.roll_idx):
                # A roll copied from q_current: unchanged within its range (see solve_arrays).
                q[m][j], inside = wrap_within_sx(q[m][j], arm.lower[j], arm.upper[j], qc[j] if current else 0.0)
            else:
                inside = ca.logic_and(q[m][j] >= arm.lower[j], q[m][j] <= arm.upper[j])
            within[m] = ca.logic_and(within[m], inside)
        # NaN where not valid: one product per value (x * 1.0 is x, -0.0 included; CasADi
        # folds a product with a constant 0, so constants are selected).
        keep = _where(valid[m], 1.0, nan)
        q[m] = [_where(valid[m], x, nan) if ca.SX(x).is_constant() else x * keep for x in q[m]]
        perr[m] = perr[m] * keep
        singular[m] = ca.logic_and(singular[m], valid[m])
    any_valid = ca.logic_or(ca.logic_or(valid[0], valid[1]), ca.logic_or(valid[2], valid[3]))
    any_within = ca.logic_or(ca.logic_or(within[0], within[1]), ca.logic_or(within[2], within[3]))
    code = STATUS_CODES
    status = ca.SX(code[STATUS_OUTSIDE_JOINT_LIMITS])
    if arm.n_pitch == 3:
        beyond = [dist[m] > arm.rmax_lim + arm.len_tol for m in range(4)]
        inside = [dist[m] < arm.rmin_lim - arm.len_tol for m in range(4)]
        reach = any_valid
        any_beyond = ca.SX(0)
        for m in range(4):
            reach = ca.logic_and(reach, ca.logic_or(ca.logic_not(valid[m]), ca.logic_or(beyond[m], inside[m])))
            any_beyond = ca.logic_or(any_beyond, ca.logic_and(valid[m], beyond[m]))
        status = _code(reach, _code(any_beyond, code[STATUS_BEYOND_MAX_REACH], code[STATUS_INSIDE_MIN_REACH]), status)
    live = [cat4[m] != DUPLICATE for m in range(4)]
    any_orient = ca.SX(0)
    any_beyond_cat = ca.SX(0)
    for m in range(4):
        any_orient = ca.logic_or(any_orient, ca.logic_and(live[m], cat4[m] == ORIENT))
        any_beyond_cat = ca.logic_or(any_beyond_cat, ca.logic_and(live[m], cat4[m] == BEYOND))
    none = _code(
        any_orient,
        code[STATUS_ORIENTATION_NOT_ACHIEVABLE],
        _code(any_beyond_cat, code[STATUS_BEYOND_MAX_REACH], code[STATUS_INSIDE_MIN_REACH]),
    )
    status = _code(any_valid, status, none)
    status = _code(any_within, code[STATUS_SOLVED], status)
    if current:
        # The within-limits branch nearest q_current (the first of equals, as numpy.argmin).
        best, nearest = ca.SX(-1), ca.SX(math.inf)
        for m in range(4):
            dist_m = sum((q[m][j] - qc[j]) ** 2 for j in range(dof))
            take = ca.logic_and(within[m], dist_m < nearest)
            best = _code(take, m, best)
            nearest = _where(take, dist_m, nearest)
    else:
        best = _code(within[0], 0, _code(within[1], 1, _code(within[2], 2, _code(within[3], 3, -1))))
    extra = []
    if free_end:
        unsolved = status != code[STATUS_SOLVED]
        extra = [unsolved if handover is None else ca.logic_or(ca.logic_or(unsolved, handover), free)]
    elif current and not pose:
        extra = [free]
    outputs = [
        ca.vertcat(*[x for m in range(4) for x in q[m]]),
        ca.vertcat(*perr),
        ca.vertcat(*valid),
        ca.vertcat(*within),
        ca.vertcat(*singular),
        ca.vertcat(status, best, *extra),
    ] + ([ca.vertcat(*dist)] if distances else [])
    inputs = [p] + ([pit] if pitch else []) + ([rflat] if pose else []) + ([qc] if current else [])
    return ca.Function("yaw_planar_closed_form", inputs, ca.cse(outputs))


def _current_end_angle(arm: ArmGeometry, qc, psi: list[_Angle], ue, ze):
    """q_current's in-plane end angle per side, and whether a side cannot take it.

    As :func:`~planner.ik.analytic.yaw_planar.free_pitch.free_pitch_array`; where a side
    cannot, NumPy's default choice applies: the target is handed over.
    """
    tu, tz, _ = arm.tip_fixed
    rmin = max(abs(arm.l1 - arm.l2), arm.rmin_lim)
    rmax = min(arm.l1 + arm.l2, arm.rmax_lim)
    alpha = arm.beta + sum(s * qc[i] for s, i in zip(arm.signs, arm.pitch_idx))
    phi, handover = [], ca.SX(0)
    for k in range(2):
        # The sign of the cosine of the same value as NumPy's (not of the sum formula's: they
        # differ at +-pi / 2, e.g. for q0 = 0 and a target on the y axis).
        facing = cos_nonnegative(psi[k].a - arm.sigma * qc[0])
        # (The sines and cosines do not wait for the yaw's arc tangent and this test.)
        phi_k = _chosen_end(facing, alpha, arm.beta)
        cp, sp = phi_k.c, phi_k.s
        du = ue[k] - (cp * tu - sp * tz) - arm.su
        dz = ze - (sp * tu + cp * tz) - arm.sz
        dd = ca.sqrt(du * du + dz * dz)
        ok = ca.logic_and(dd >= rmin - arm.core_len_tol, dd <= rmax + arm.core_len_tol)
        handover = ca.logic_or(handover, ca.logic_not(ok))
        phi.append(phi_k)
    return phi, handover


def _default_end_angle(arm: ArmGeometry, ue, ze):
    """The default in-plane end angle per side and its failure category.

    As :func:`~planner.ik.analytic.yaw_planar.free_pitch.free_pitch_array` without q_current.
    """
    tu, tz, _ = arm.tip_fixed
    su, sz = arm.su, arm.sz
    rmin = max(abs(arm.l1 - arm.l2), arm.rmin_lim)
    rmax = min(arm.l1 + arm.l2, arm.rmax_lim)
    lt = float(np.hypot(tu, tz))
    gt = float(np.arctan2(tz, tu))
    phi, fail = [], []
    for k in range(2):
        ex, ez = ue[k] - su, ze - sz
        de = ca.sqrt(ex * ex + ez * ez)
        lo = _max(abs(de - lt), rmin)
        hi = _min(de + lt, rmax)
        bad = ca.logic_or(lo > hi + arm.core_len_tol, de == 0.0)
        fail.append(_where(bad, _where(de - lt > rmax, BEYOND, INSIDE), VALID))
        safe = _where(de == 0.0, 1.0, de)
        a = (lo * lo - lt * lt + safe * safe) / (2.0 * safe)
        h = _where(abs(de - lt) >= rmin, 0.0, ca.sqrt(_max(lo * lo - a * a, 0.0)))
        ux, uz = ex / safe, ez / safe
        options = []
        for sgn in (1.0, -1.0):
            wx = su + a * ux - sgn * h * uz
            wz = sz + a * uz + sgn * h * ux
            phi_s = ca.atan2(ze - wz, ue[k] - wx) - gt
            options.append((phi_s, ca.sin(arm.beta + phi_s)))
        (phi1, lift1), (phi2, lift2) = options
        phi.append(_Angle.of(_where(lift2 < lift1 - 1e-15, phi2, phi1)))
    return phi, fail


def _ideal_position_error(arm: ArmGeometry, links, ends, cy, sy, p):
    """:func:`~planner.ik.analytic.yaw_planar.core.ideal_position_error` of the 4 branches (before wrapping).

    `links[m]`: the in-plane angles of the links (phi2 + g1, and phi3 + g2 with three pitch
    joints), `ends[m]`: the end angle; `cy`, `sy`: the cosine and sine of each side's yaw
    mu + sigma q0 (sigma is +-1: psi + mu).
    """
    tu, tz, d = arm.tip_fixed
    perr = []
    for m in range(4):
        k = REP[m]
        a = links[m][0]
        fu = arm.su + arm.l1 * a.c
        fz = arm.sz + arm.l1 * a.s
        if arm.n_pitch == 3:
            a = links[m][1]
            fu += arm.l2 * a.c
            fz += arm.l2 * a.s
        c4, s4 = ends[m].c, ends[m].s
        fu += c4 * tu - s4 * tz
        fz += s4 * tu + c4 * tz
        dx = arm.bx + cy[k] * fu + sy[k] * d - p[0]
        dy = arm.by + sy[k] * fu - cy[k] * d - p[1]
        dz = fz - p[2]
        perr.append(ca.sqrt(dx * dx + dy * dy + dz * dz))
    return perr


def _matmul(a, b):
    """The product of two 3 x 3 matrices given as nested lists (NumPy's order of the sums)."""
    return [[a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j] for j in range(3)] for i in range(3)]


def _matvec(a, v):
    """A 3 x 3 matrix (nested lists) times a vector."""
    v = [x if isinstance(x, ca.SX) else float(x) for x in v]
    return [a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2] for i in range(3)]


def _poe_fk(arm: ArmGeometry, q: list[_Angle]):
    """The real arm's tip position and rotation at `q` (:func:`~planner.geometry.chain.poe_fk`'s sums).

    Entries of the model within 1e-15 (times the arm's size for points) of zero are taken as
    zero (round-off of the URDF's angles; the products then skip them): the tip moves by
    less than 1e-14 x the arm's size.
    """
    rot = trans = None
    for k in range(arm.dof):
        r_k = rodrigues_rows(_tidy(arm.axes[k], 1.0), q[k].s, q[k].c)
        pt = _tidy(arm.points[k], arm.scale)
        t_k = [pt[i] - (r[0] * pt[0] + r[1] * pt[1] + r[2] * pt[2]) for i, r in enumerate(r_k)]
        if rot is None:
            rot, trans = r_k, t_k
            continue
        trans = [trans[i] + rot[i][0] * t_k[0] + rot[i][1] * t_k[1] + rot[i][2] * t_k[2] for i in range(3)]
        rot = _matmul(rot, r_k)
    tp = _tidy(arm.tip_position, arm.scale)
    pos = [rot[i][0] * tp[0] + rot[i][1] * tp[1] + rot[i][2] * tp[2] + trans[i] for i in range(3)]
    return pos, _matmul(rot, [_tidy(row, 1.0) for row in np.asarray(arm.rot0)])


def forward_sx(arm: ArmGeometry, q: list) -> tuple[list, list]:
    """The real arm's tip position (3) and rotation (3 x 3 nested lists) at joint values `q` (SX).

    The product of exponentials (:func:`~planner.geometry.chain.poe_fk`'s sums) with each
    joint's cosine and sine by libm.
    """
    return _poe_fk(arm, [_Angle.of(v) for v in q])


def _tidy(v, scale: float) -> list[float]:
    """`v`'s entries, those within 1e-15 x `scale` of zero set to zero."""
    return [0.0 if abs(float(x)) <= 1e-15 * scale else float(x) for x in v]


def _rotation_beyond(a, b, tol: float):
    """Positive where the rotation error of two rotations (nested lists) exceeds `tol` [rad].

    The error is :func:`~planner.core.rotations.rotation_error`'s batch formula; the value is
    <= 0 where it does not exceed `tol`, NaN where either rotation is.

    The error is ``atan2(sin, cos)`` with ``sin >= 0``: it exceeds ``tol`` (< pi / 2) where
    ``sin cos(tol) - cos sin(tol) > 0`` (no arc tangent).
    """
    rel = _matmul([[a[j][i] for j in range(3)] for i in range(3)], b)
    cos = _min(_max((rel[0][0] + rel[1][1] + rel[2][2] - 1.0) / 2.0, -1.0), 1.0)
    k = [rel[2][1] - rel[1][2], rel[0][2] - rel[2][0], rel[1][0] - rel[0][1]]
    sin = ca.sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2]) / 2.0
    if not 0.0 < tol < PI / 2:
        return ca.atan2(sin, cos) - tol
    return sin * math.cos(tol) - cos * math.sin(tol)


def _yaw_for_rotation(arm: ArmGeometry, m_rot, hx, hy, d, u, psi, ue, cat):
    """:func:`~planner.ik.analytic.yaw_planar.orientation.yaw_for_rotation` for one target."""
    if arm.has_roll:
        w = _matvec(m_rot, arm.r0)
        horiz = ca.sqrt(w[0] * w[0] + w[1] * w[1])
        psi_a = _Angle.atan2(w[1], w[0], horiz).shift(-arm.mu)
        use = ca.logic_and(horiz > 1e-9, horiz * arm.scale >= u)
    else:
        w = _matvec(m_rot, arm.n)
        psi_a = _Angle.atan2(w[1], w[0]).shift(-math.atan2(float(arm.n[1]), float(arm.n[0])))
        use = None
    cy, sy = ca.cos(arm.mu + psi_a.a), ca.sin(arm.mu + psi_a.a)
    ue_a = hx * cy + hy * sy
    lat_a = hx * sy - hy * cy
    forward = ue_a >= 0.0
    tol = max(arm.consistency_tol, arm.core_len_tol)
    off_plane = abs(lat_a - d) > tol
    if arm.has_roll:
        psi_front = _Angle.where(forward, psi_a, psi_a.shift(PI))
        psi_rot = [psi_front, psi_front.shift(PI)]
        off_back = abs(-lat_a - d) > tol
        cat_rot = [
            _where(_where(forward, off_plane, off_back), ORIENT, VALID),
            _where(_where(forward, off_back, off_plane), ORIENT, VALID),
        ]
    else:
        psi_rot = [psi_a, psi_a]
        bad = _where(off_plane, ORIENT, VALID)
        cat_rot = [_where(forward, bad, DUPLICATE), _where(forward, DUPLICATE, bad)]
    ue_rot = [abs(ue_a), -abs(ue_a)]
    cat_rot = [_where(cat[k] == CYLINDER, cat[k], cat_rot[k]) for k in range(2)]
    if use is None:
        return psi_rot, ue_rot, cat_rot
    return (
        [_Angle.where(use, psi_rot[k], psi[k]) for k in range(2)],
        *([_where(use, new[k], old[k]) for k in range(2)] for new, old in ((ue_rot, ue), (cat_rot, cat))),
    )


def _unyaw(v, cz, sz):
    """Rz(-psi) v."""
    return [cz * v[0] + sz * v[1], -sz * v[0] + cz * v[1], v[2]]


def _pitch_from_rotation(arm: ArmGeometry, m_rot, psi: list[_Angle]):
    """:func:`~planner.ik.analytic.yaw_planar.orientation.pitch_from_rotation` per side.

    Returns:
        phi, and whether the residual exceeds the orientation tolerance (the residual
        ``asin(|x . n|)`` with a roll: ``|x . n| > sin(tol)``; without, by :func:`_rotation_beyond`).
    """
    e_u = [float(v) for v in arm.e_u]
    n = [float(v) for v in arm.n]
    phi, beyond = [], []
    for k in range(2):
        cz, sz = ca.cos(psi[k].a), ca.sin(psi[k].a)
        if arm.has_roll:
            x = _unyaw(_matvec(m_rot, arm.r0), cz, sz)
            phi.append(_Angle.of(ca.atan2(x[2], x[0] * e_u[0] + x[1] * e_u[1] + x[2] * e_u[2]) - arm.kappa))
            xn = x[0] * n[0] + x[1] * n[1] + x[2] * n[2]
            beyond.append(_min(_max(abs(xn), 0.0), 1.0) > math.sin(arm.orient_tol))
        else:
            x = _unyaw(_matvec(m_rot, e_u), cz, sz)
            phi_k = _Angle.of(ca.atan2(x[2], x[0] * e_u[0] + x[1] * e_u[1] + x[2] * e_u[2]))
            rz = [[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]]
            ideal = _matmul(rz, rodrigues_rows(n, phi_k.s, phi_k.c))
            phi.append(phi_k)
            beyond.append(_rotation_beyond(ideal, m_rot, arm.orient_tol) > 0.0)
    return phi, beyond


def _roll_from_rotation(arm: ArmGeometry, m_rot, psi: list[_Angle], phi: list[_Angle]) -> list[_Angle]:
    """:func:`~planner.ik.analytic.yaw_planar.orientation.roll_from_rotation` per side.

    By the cosines and sines of psi and phi as NumPy computes them (libm): at the half turn
    (the back side's roll when the front's is 0, common for rotations by quarter turns) the
    sign of a zero decides between pi and -pi.
    """
    n = [float(v) for v in arm.n]
    rxn = np.cross(arm.r0, arm.n).tolist()
    mn = _matvec(m_rot, n)
    roll = []
    for k in range(2):
        # -phi's: sin(-x) = -sin(x) exactly (libm's sine is odd), shared with phi's.
        yaw, pitch = _Angle.of(psi[k].a), -phi[k]
        un = _unyaw(mn, yaw.c, yaw.s)
        back = _matvec(rodrigues_rows(n, pitch.s, pitch.c), un)
        roll.append(
            _Angle.atan2(
                back[0] * rxn[0] + back[1] * rxn[1] + back[2] * rxn[2], back[0] * n[0] + back[1] * n[1] + back[2] * n[2]
            )
        )
    return roll


class CompiledKernels:
    """The compiled closed-form functions of one arm, built on first use (owned by its solver).

    Attributes:
        arm: The geometry.
    """

    def __init__(self, arm: ArmGeometry) -> None:
        self.arm = arm
        self._functions: dict[tuple[str, bool, int, bool, bool], ca.Function] = {}

    def function(
        self, kind: str, current: bool = False, block: int = BLOCK, compiled: bool = True, distances: bool = False
    ) -> ca.Function:
        """The closed form of `kind` targets (with q_current or not) mapped over `block` targets.

        `kind`: "position", "pitch" or "pose" (:func:`kind_of`); with `distances`, one more
        output: each branch's wrist distance [m] (:func:`_one_target`).

        With `compiled`, built to C by :func:`~planner.ik.numeric.codegen.compile_function`
        (which falls back to CasADi's virtual machine without a compiler or with
        ``PLANNER_JIT=0``); without, the virtual machine's.
        """
        key = (kind, current, block, compiled, distances)
        fn = self._functions.get(key)
        if fn is None:
            fn = _one_target(self.arm, kind, current, distances).map(block, "serial")
            if compiled:
                fn = compile_function(fn, flags=FLAGS)
            self._functions[key] = fn
        return fn

    def available(self, kind: str, current: bool = False) -> bool:
        """Whether :meth:`function` is compiled C (without a compiler NumPy is faster)."""
        return self.function(kind, current).class_name() == "External"


def kind_of(pit, rot) -> str:
    """The target kind of :meth:`CompiledKernels.function` for these inputs."""
    return "pose" if rot is not None else "pitch" if pit is not None else "position"


def solve_compiled(
    kernels: CompiledKernels,
    pos: np.ndarray,
    pit: np.ndarray | None,
    rot: np.ndarray | None = None,
    qc: np.ndarray | None = None,
    block: int = BLOCK,
    *,
    compiled: bool = True,
) -> tuple[BranchArrays, np.ndarray]:
    """The batch closed form of N targets by the compiled function (see the module docstring).

    Only where :func:`compiled_supported` holds; `compiled` as :meth:`CompiledKernels.function`'s.

    Returns:
        The arrays of :func:`~planner.ik.analytic.yaw_planar.batch.solve_chunked` (``cat``,
        ``oerr``, ``dist`` None), and the indices of the targets the function hands over to
        NumPy (a free end angle: see :func:`_one_target`), whose rows hold no answer.
    """
    n = pos.shape[0]
    arm = kernels.arm
    out = BranchArrays.empty(n, arm.dof)
    args = [np.ascontiguousarray(pos, dtype=float)]
    if pit is not None:
        args.append(np.ascontiguousarray(pit, dtype=float))
    if rot is not None:
        args.append(np.ascontiguousarray(rot, dtype=float).reshape(n, 9))
    if qc is not None:
        args.append(np.ascontiguousarray(qc, dtype=float))
    free_end = arm.n_pitch == 3 and pit is None and rot is None
    handover = np.zeros(n, dtype=bool) if free_end or (qc is not None and rot is None) else None
    # Full blocks, then the rest in small ones (two compiled functions per arm and kind).
    full = n // block * block
    key = (kind_of(pit, rot), qc is not None)
    _run(kernels.function(*key, block, compiled), args, out, handover, 0, full, block)
    _run(kernels.function(*key, SMALL_BLOCK, compiled), args, out, handover, full, n, SMALL_BLOCK)
    return out, np.flatnonzero(handover) if handover is not None else np.zeros(0, dtype=np.intp)


def _run(fn: ca.Function, args, out: BranchArrays, handover, start: int, stop: int, b: int) -> None:
    """Rows `start` to `stop` of `out` (and `handover`) by `fn` (mapped over `b` targets), block by block.

    (b, m) rows in C order are CasADi's (m, b) columns: full blocks read the inputs and write
    the joint values and errors in place; the masks and codes go through reused buffers, one
    per output (converted from contiguous rows: 7 times as fast as from strided columns).
    """
    if start >= stop:
        return
    buffer, evaluate = fn.buffer()
    dof = out.q.shape[2]
    masks = [np.empty((b, 4)) for _ in range(3)]
    codes = np.empty((b, 2 + (handover is not None)))
    for i, res in enumerate([*masks, codes]):
        buffer.set_res(2 + i, memoryview(res))
    q_part = perr_part = None
    for first in range(start, stop, b):
        last = min(first + b, stop)
        k = last - first
        rows = slice(first, last)
        # Kept referenced until evaluated (the buffer holds only their addresses).
        blocks = [_block(arg[rows], b) for arg in args]
        for i, arg in enumerate(blocks):
            buffer.set_arg(i, memoryview(arg))
        if k == b:
            buffer.set_res(0, memoryview(out.q[rows]))
            buffer.set_res(1, memoryview(out.perr[rows]))
        else:
            q_part, perr_part = np.empty((b, 4, dof)), np.empty((b, 4))
            buffer.set_res(0, memoryview(q_part))
            buffer.set_res(1, memoryview(perr_part))
        evaluate()
        if k < b:
            out.q[rows] = q_part[:k]
            out.perr[rows] = perr_part[:k]
        for mask, name in zip(masks, ("valid", "within", "singular")):
            np.not_equal(mask[:k], 0.0, out=getattr(out, name)[rows])
        out.status[rows] = codes[:k, 0]
        out.best[rows] = codes[:k, 1]
        if handover is not None:
            np.not_equal(codes[:k, 2], 0.0, out=handover[rows])


def _block(x: np.ndarray, b: int) -> np.ndarray:
    """`x` (k, ...) padded with copies of its last row to (b, ...)."""
    k = x.shape[0]
    if k == b:
        return x
    return np.concatenate([x, np.repeat(x[-1:], b - k, axis=0)], axis=0)
