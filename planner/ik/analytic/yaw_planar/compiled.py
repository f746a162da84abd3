"""The batch closed form as one compiled function over targets (exact chains, position or pitch).

On exact chains (no correction on the real geometry) whose tip lies on the roll axis (or
that have no roll), position targets without a free end angle (two pitch joints) and
approach-pitch targets need no search: each target's four branches follow from a fixed
sequence of square roots and arc tangents. :class:`CompiledKernels` writes that sequence, the
same as :func:`~planner.ik.analytic.yaw_planar.core.solve_core`,
:func:`~planner.ik.analytic.yaw_planar.core.ideal_position_error`, the wrapping into the
joint ranges (:func:`~planner.geometry.chain.wrap_array`) and
:func:`~planner.ik.analytic.yaw_planar.status.status_codes`, as one CasADi SX function of
one target, maps it over a block of targets and compiles it to C
(:func:`~planner.ik.numeric.codegen.compile_function`; CasADi's virtual machine without a
compiler; :class:`CompiledKernels`). :func:`solve_compiled` runs it block by block. Branches, categories, statuses and
masks are the NumPy path's; joint values and errors agree to round-off.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from planner.geometry.chain import LIMIT_SNAP
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

__all__ = ["BLOCK", "SMALL_BLOCK", "CompiledKernels", "compiled_supported", "solve_compiled"]

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
#: How far beyond pi [rad] a wrapped value may lie (round-off; far less than this).
REACHED = 1e-6


def compiled_supported(arm: ArmGeometry, pit, rot, qc) -> bool:
    """Whether :func:`solve_compiled` gives the NumPy path's answers for these inputs."""
    if not arm.exact or rot is not None or not arm.tip_on_roll_axis or arm.elbow_seed > 0.0:
        return False
    # Without q_current the roll is 0, which must lie within its range (else NumPy wraps it).
    return not (qc is None and arm.has_roll and not arm.lower[arm.roll_idx] <= 0.0 <= arm.upper[arm.roll_idx])


def _where(cond, a, b):
    return ca.if_else(cond, a, b)


def _rint(y):
    """``numpy.round``: to the nearest integer, halves to even, for ``|y| < 2**51``.

    Adding and subtracting 1.5 * 2**52 leaves the integer that the addition rounds to (round
    to nearest, ties to even). ``fmax`` keeps CasADi from folding the pair away (the sum is
    positive; a NaN `y` gives a NaN value through the ``x - 2 pi r`` of :func:`_wrap`).
    """
    return ca.fmax(y + MAGIC, 0.0) - MAGIC


def _wrap_pi(x):
    """:func:`~planner.ik.analytic.geometry.wrap_pi` as NumPy's float remainder computes it."""
    m = ca.fmod(x + PI, TWO_PI)
    return _where(m < 0.0, m + TWO_PI, m) - PI


def _wrap(x, lower: float, upper: float, ref=0.0):
    """:func:`~planner.geometry.chain.wrap_array`, one value.

    With `ref` 0, after the turn to the nearest 2 pi multiple |x| <= pi (to round-off): a
    limit beyond pi + 1e-6 is never exceeded there, and its step is left out (the other step
    may still turn x past it: the snaps onto the limits stay).
    """
    x = x - TWO_PI * _rint((x - ref) / TWO_PI)
    if not (math.isfinite(lower) or math.isfinite(upper)):
        return x
    centred = isinstance(ref, float) and ref == 0.0
    over = upper < PI + REACHED or not centred
    if over:
        down = x - TWO_PI
        x = _where(x > upper, _where(ca.logic_or(down >= lower - LIMIT_SNAP, (x - upper) > (lower - down)), down, x), x)
    if over or lower > -PI - REACHED:  # (over includes not centred)
        up = x + TWO_PI
        x = _where(x < lower, _where(ca.logic_or(up <= upper + LIMIT_SNAP, (lower - x) > (up - upper)), up, x), x)
    x = _where(ca.logic_and(x > upper, x <= upper + LIMIT_SNAP), upper, x)
    x = _where(ca.logic_and(x < lower, x >= lower - LIMIT_SNAP), lower, x)
    return x


def _one_target(arm: ArmGeometry, pitch: bool, current: bool) -> ca.Function:
    """The closed form of one target as an SX function: (position, pitch, q_current) -> the per-target arrays.

    Where the end angle is free (three pitch joints, no pitch), the last output is 1 where
    :func:`solve_compiled` must hand the target to NumPy: not solved (the search within the
    limits), or q_current's end angle out of a side's reach (the default choice).
    """
    p = ca.SX.sym("p", 3)
    pit = ca.SX.sym("pit") if pitch else None
    qc = ca.SX.sym("qc", arm.dof) if current else None
    dof = arm.dof
    tu, tz, d = arm.tip_fixed
    hx = p[0] - arm.bx
    hy = p[1] - arm.by
    ze = p[2]
    rho2 = hx * hx + hy * hy
    axis_tol = arm.len_tol
    free = ca.logic_and(rho2 <= axis_tol * axis_tol, abs(d) <= axis_tol)
    len_tol = arm.core_len_tol
    under = rho2 - d * d
    cylinder = ca.logic_and(ca.logic_not(free), under < -2.0 * abs(d) * len_tol)
    u = ca.sqrt(ca.fmax(under, 0.0))
    ang = ca.atan2(hy, hx)
    if d == 0.0:
        # NumPy's atan2(-0.0, u) and atan2(-0.0, -u) for u >= 0 (CasADi folds -0.0 into 0).
        psi_f = ang - arm.mu
        psi_b = ang - arm.mu + PI
    else:
        psi_f = ang - arm.mu - ca.atan2(-d, u)
        psi_b = ang - arm.mu - ca.atan2(-d, -u)
    back_dup = ca.logic_or(free, u == 0.0)
    psi_f = _where(free, arm.sigma * qc[0] if current else 0.0, psi_f)
    u = _where(free, 0.0, u)
    psi = [psi_f, psi_b]
    ue = [u, -u]
    cat = [_where(cylinder, CYLINDER, VALID), _where(cylinder, CYLINDER, _where(back_dup, DUPLICATE, VALID))]
    cy = [ca.cos(psi[k] + arm.mu) for k in range(2)]
    sy = [ca.sin(psi[k] + arm.mu) for k in range(2)]
    alpha_t = None
    if pitch:
        alpha_t = [_where(cy[k] * p[0] + sy[k] * p[1] >= 0.0, pit, PI - pit) for k in range(2)]
    l1, g1, su, sz = arm.l1, arm.g1, arm.su, arm.sz
    sg, idx = arm.signs, arm.pitch_idx
    q = [[None] * dof for _ in range(4)]
    cat4 = [None] * 4
    free_end = arm.n_pitch == 3 and not pitch
    handover = None
    if free_end and current:
        phi_end, handover = _current_end_angle(arm, qc, psi, ue, ze)
    elif free_end:
        phi_end, fail = _default_end_angle(arm, ue, ze)
        cat = [_where(ca.logic_and(cat[k] == VALID, fail[k] != VALID), fail[k], cat[k]) for k in range(2)]
    if arm.n_pitch == 2 and pitch:
        l2 = math.hypot(tu, tz)
        g2 = math.atan2(tz, tu)
        dist2 = []
        sing2 = []
        for k in range(2):
            de = ca.sqrt((ue[k] - su) ** 2 + (ze - sz) ** 2)
            c = cat[k]
            c = _where(ca.logic_and(c == VALID, de > l1 + l2 + len_tol), BEYOND, c)
            c = _where(ca.logic_and(c == VALID, de < abs(l1 - l2) - len_tol), INSIDE, c)
            phi = alpha_t[k] - arm.beta
            cp, sp = ca.cos(phi), ca.sin(phi)
            ex = ue[k] - (cp * tu - sp * tz) - su
            ez = ze - (sp * tu + cp * tz) - sz
            tol = max(arm.consistency_tol, len_tol)
            c = _where(ca.logic_and(c == VALID, abs(ca.sqrt(ex * ex + ez * ez) - l1) > tol), ORIENT, c)
            a1 = ca.atan2(ez, ex)
            e = _wrap_pi(phi + g2 - a1)
            up = (e <= 0.0) if k == 0 else (e >= 0.0)
            phi2 = a1 - g1
            for m, chosen in ((2 * k, up), (2 * k + 1, ca.logic_not(up))):
                q[m][0] = arm.sigma * psi[k]
                q[m][idx[0]] = sg[0] * phi2
                q[m][idx[1]] = sg[1] * (phi - phi2)
                cat4[m] = _where(ca.logic_and(c == VALID, ca.logic_not(chosen)), DUPLICATE, c)
            dist2.append(de)
            sing2.append(
                ca.logic_or(ca.logic_or(abs(ca.sin(e)) < SINGULAR_TOL, free), abs(ue[k]) < SINGULAR_TOL * arm.scale)
            )
        dist = [dist2[r] for r in REP]
        singular = [sing2[r] for r in REP]
    else:
        if arm.n_pitch == 3:
            l2, g2 = arm.l2, arm.g2
            phi = phi_end if free_end else [alpha_t[k] - arm.beta for k in range(2)]
            cp = [ca.cos(phi[k]) for k in range(2)]
            sp = [ca.sin(phi[k]) for k in range(2)]
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
            cc = ca.fmin(ca.fmax((dk * dk - l1 * l1 - l2 * l2) / (2.0 * l1 * l2), -1.0), 1.0)
            s = ca.sqrt(1.0 - cc * cc)
            es = s < SINGULAR_TOL
            s = _where(es, 0.0, s)
            cc = _where(es, ca.sign(cc) + (cc == 0), cc)
            e_abs.append(ca.atan2(s, cc))
            base.append(ca.atan2(vz, vx))
            half.append(ca.atan2(l2 * s, l1 + l2 * cc))
            dist2.append(dk)
            sing2.append(es)
        e = [-e_abs[0], e_abs[0], e_abs[1], -e_abs[1]]
        a1 = [base[0] + half[0], base[0] - half[0], base[1] - half[1], base[1] + half[1]]
        for m in range(4):
            k = REP[m]
            phi2 = a1[m] - g1
            phi3 = a1[m] + e[m] - g2
            q[m][0] = arm.sigma * psi[k]
            q[m][idx[0]] = sg[0] * phi2
            q[m][idx[1]] = sg[1] * (phi3 - phi2)
            if arm.n_pitch == 3:
                q[m][idx[2]] = sg[2] * (phi[k] - phi3)
            if arm.has_roll:
                q[m][arm.roll_idx] = qc[arm.roll_idx] if current else ca.SX(0.0)
            c = cat[k]
            if m in (1, 3):
                c = _where(ca.logic_and(c == VALID, sing2[k]), DUPLICATE, c)
            cat4[m] = c
        dist = [dist2[r] for r in REP]
        singular = [
            ca.logic_or(ca.logic_or(sing2[REP[m]], free), abs(ue[REP[m]]) < SINGULAR_TOL * arm.scale) for m in range(4)
        ]
    # The ideal forward model's position error (before wrapping: 2 pi turns change nothing).
    perr = []
    for m in range(4):
        k = REP[m]
        phi2 = sg[0] * q[m][idx[0]]
        phi3 = phi2 + sg[1] * q[m][idx[1]]
        a = phi2 + arm.g1
        fu = arm.su + arm.l1 * ca.cos(a)
        fz = arm.sz + arm.l1 * ca.sin(a)
        if arm.n_pitch == 3:
            phi4 = phi3 + sg[2] * q[m][idx[2]]
            a = phi3 + arm.g2
            fu += arm.l2 * ca.cos(a)
            fz += arm.l2 * ca.sin(a)
        else:
            phi4 = phi3
        c4, s4 = ca.cos(phi4), ca.sin(phi4)
        fu += c4 * tu - s4 * tz
        fz += s4 * tu + c4 * tz
        # The yaw mu + sigma q0 is psi + mu (sigma is +-1): the same value as cy, sy's.
        cyk, syk = cy[k], sy[k]
        dx = arm.bx + cyk * fu + syk * d - p[0]
        dy = arm.by + syk * fu - cyk * d - p[1]
        dz = fz - p[2]
        perr.append(ca.sqrt(dx * dx + dy * dy + dz * dz))
    valid = [cat4[m] == VALID for m in range(4)]
    within = list(valid)
    nan = ca.SX(float("nan"))
    for m in range(4):
        for j in range(dof):
            if current:
                # A roll copied from q_current: unchanged within its range (see solve_arrays).
                q[m][j] = _wrap(q[m][j], arm.lower[j], arm.upper[j], qc[j])
            elif not (arm.has_roll and j == arm.roll_idx):
                q[m][j] = _wrap(q[m][j], arm.lower[j], arm.upper[j])
            within[m] = ca.logic_and(within[m], ca.logic_and(q[m][j] >= arm.lower[j], q[m][j] <= arm.upper[j]))
        q[m] = [_where(valid[m], x, nan) for x in q[m]]
        perr[m] = _where(valid[m], perr[m], nan)
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
            reach = ca.logic_and(reach, _where(valid[m], ca.logic_or(beyond[m], inside[m]), 1))
            any_beyond = ca.logic_or(any_beyond, ca.logic_and(valid[m], beyond[m]))
        status = _where(reach, _where(any_beyond, code[STATUS_BEYOND_MAX_REACH], code[STATUS_INSIDE_MIN_REACH]), status)
    live = [cat4[m] != DUPLICATE for m in range(4)]
    any_orient = ca.SX(0)
    any_beyond_cat = ca.SX(0)
    for m in range(4):
        any_orient = ca.logic_or(any_orient, ca.logic_and(live[m], cat4[m] == ORIENT))
        any_beyond_cat = ca.logic_or(any_beyond_cat, ca.logic_and(live[m], cat4[m] == BEYOND))
    none = _where(
        any_orient,
        code[STATUS_ORIENTATION_NOT_ACHIEVABLE],
        _where(any_beyond_cat, code[STATUS_BEYOND_MAX_REACH], code[STATUS_INSIDE_MIN_REACH]),
    )
    status = _where(any_valid, status, none)
    status = _where(any_within, code[STATUS_SOLVED], status)
    if current:
        # The within-limits branch nearest q_current (the first of equals, as numpy.argmin).
        best, nearest = ca.SX(-1), ca.SX(math.inf)
        for m in range(4):
            dist_m = sum((q[m][j] - qc[j]) ** 2 for j in range(dof))
            take = ca.logic_and(within[m], dist_m < nearest)
            best = _where(take, m, best)
            nearest = _where(take, dist_m, nearest)
    else:
        best = _where(within[0], 0, _where(within[1], 1, _where(within[2], 2, _where(within[3], 3, -1))))
    extra = []
    if free_end:
        unsolved = status != code[STATUS_SOLVED]
        extra = [unsolved if handover is None else ca.logic_or(unsolved, handover)]
    out = ca.vertcat(*[x for m in range(4) for x in q[m]], *valid, *within, *singular, *perr, status, best, *extra)
    inputs = [p] + ([pit] if pitch else []) + ([qc] if current else [])
    return ca.Function("yaw_planar_closed_form", inputs, [ca.cse(out)])


def _current_end_angle(arm: ArmGeometry, qc, psi, ue, ze):
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
        facing = ca.cos(psi[k] - arm.sigma * qc[0]) >= 0.0
        phi_k = _where(facing, alpha, PI - alpha) - arm.beta
        cp, sp = ca.cos(phi_k), ca.sin(phi_k)
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
        lo = ca.fmax(abs(de - lt), rmin)
        hi = ca.fmin(de + lt, rmax)
        bad = ca.logic_or(lo > hi + arm.core_len_tol, de == 0.0)
        fail.append(_where(bad, _where(de - lt > rmax, BEYOND, INSIDE), VALID))
        safe = _where(de == 0.0, 1.0, de)
        a = (lo * lo - lt * lt + safe * safe) / (2.0 * safe)
        h = _where(abs(de - lt) >= rmin, 0.0, ca.sqrt(ca.fmax(lo * lo - a * a, 0.0)))
        ux, uz = ex / safe, ez / safe
        options = []
        for sgn in (1.0, -1.0):
            wx = su + a * ux - sgn * h * uz
            wz = sz + a * uz + sgn * h * ux
            phi_s = ca.atan2(ze - wz, ue[k] - wx) - gt
            options.append((phi_s, ca.sin(arm.beta + phi_s)))
        (phi1, lift1), (phi2, lift2) = options
        phi.append(_where(lift2 < lift1 - 1e-15, phi2, phi1))
    return phi, fail


class CompiledKernels:
    """The compiled closed-form functions of one arm, built on first use (owned by its solver).

    Attributes:
        arm: The geometry.
    """

    def __init__(self, arm: ArmGeometry) -> None:
        self.arm = arm
        self._functions: dict[tuple[bool, bool, int, bool], ca.Function] = {}

    def function(self, pitch: bool, current: bool = False, block: int = BLOCK, compiled: bool = True) -> ca.Function:
        """The closed form of pitch or position targets (with q_current or not) mapped over `block` targets.

        With `compiled`, built to C by :func:`~planner.ik.numeric.codegen.compile_function`
        (which falls back to CasADi's virtual machine without a compiler or with
        ``PLANNER_JIT=0``); without, the virtual machine's.
        """
        key = (pitch, current, block, compiled)
        fn = self._functions.get(key)
        if fn is None:
            fn = _one_target(self.arm, pitch, current).map(block, "serial")
            if compiled:
                fn = compile_function(fn, flags=FLAGS)
            self._functions[key] = fn
        return fn

    def available(self, pitch: bool, current: bool = False) -> bool:
        """Whether :meth:`function` is compiled C (without a compiler NumPy is faster)."""
        return self.function(pitch, current).class_name() == "External"


def solve_compiled(
    kernels: CompiledKernels,
    pos: np.ndarray,
    pit: np.ndarray | None,
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
    if qc is not None:
        args.append(np.ascontiguousarray(qc, dtype=float))
    free_end = arm.n_pitch == 3 and pit is None
    handover = np.zeros(n, dtype=bool) if free_end else None
    # Full blocks, then the rest in small ones (two compiled functions per arm and kind).
    full = n // block * block
    key = (pit is not None, qc is not None)
    _run(kernels.function(*key, block, compiled), args, out, handover, 0, full, block)
    _run(kernels.function(*key, SMALL_BLOCK, compiled), args, out, handover, full, n, SMALL_BLOCK)
    return out, np.flatnonzero(handover) if handover is not None else np.zeros(0, dtype=np.intp)


def _run(fn: ca.Function, args, out: BranchArrays, handover, start: int, stop: int, b: int) -> None:
    """Rows `start` to `stop` of `out` (and `handover`) by `fn` (mapped over `b` targets), block by block."""
    if start >= stop:
        return
    buffer, evaluate = fn.buffer()
    dof = out.q.shape[2]
    o = 4 * dof
    # One block's results, reused (in cache): (b, width) in C order is CasADi's (width, b).
    res = np.empty((b, o + 4 * 4 + 2 + (handover is not None)))
    buffer.set_res(0, memoryview(res))
    for first in range(start, stop, b):
        last = min(first + b, stop)
        k = last - first
        # (b, m) rows in C order are CasADi's (m, b) columns: no copies for full blocks.
        # Kept referenced until evaluated (the buffer holds only their addresses).
        blocks = [_block(arg[first:last], b) for arg in args]
        for i, arg in enumerate(blocks):
            buffer.set_arg(i, memoryview(arg))
        evaluate()
        rows = slice(first, last)
        out.q[rows] = res[:k, :o].reshape(k, 4, dof)
        np.not_equal(res[:k, o : o + 4], 0.0, out=out.valid[rows])
        np.not_equal(res[:k, o + 4 : o + 8], 0.0, out=out.within[rows])
        np.not_equal(res[:k, o + 8 : o + 12], 0.0, out=out.singular[rows])
        out.perr[rows] = res[:k, o + 12 : o + 16]
        out.status[rows] = res[:k, o + 16]
        out.best[rows] = res[:k, o + 17]
        if handover is not None:
            np.not_equal(res[:k, o + 18], 0.0, out=handover[rows])


def _block(x: np.ndarray, b: int) -> np.ndarray:
    """`x` (k, ...) padded with copies of its last row to (b, ...)."""
    k = x.shape[0]
    if k == b:
        return x
    return np.concatenate([x, np.repeat(x[-1:], b - k, axis=0)], axis=0)
