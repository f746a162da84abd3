"""Position and pitch targets on exact chains, in scalar arithmetic (no NumPy per step).

The fast path of :meth:`~planner.ik.analytic.yaw_planar.solver.YawPlanarIK.solve` (a few
microseconds: a few times one Pinocchio FK call): the same closed form as
:mod:`~planner.ik.analytic.yaw_planar.core`, one target at a time, with the same branch order
and categories, each branch verified by the closed-form forward model. Plain floats and
:mod:`math` throughout; the only NumPy object built is the one read-only array that holds
every solution's joint values (:func:`finish_scalar`).

With a plan's compiled closed form (one per solver), the same result comes from one call of
a CasADi function where that is sure (compiled to C after
:data:`~planner.ik.analytic.base.SINGLE_AFTER` calls of a kind; the same doubles before)
(:class:`~planner.ik.analytic.yaw_planar.single.SolveKernel`: the same branches, order, masks
and status; joint values and errors to round-off, each branch verified by the forward model
at its returned joint values); elsewhere (failures, ties, a free end angle to search, ...)
from the scalar arithmetic here.
"""

from __future__ import annotations

import math
import struct
from math import atan2, cos, hypot, sin, sqrt  # module names: one opcode fewer per call than locals
from operator import itemgetter
from typing import NamedTuple

import numpy as np

from planner.geometry.chain import wrap_scalar
from planner.geometry.target import Target, pitch_error_scalar
from planner.ik.analytic.geometry import SINGULAR_TOL
from planner.ik.analytic.result import STATUS_SOLVED, AnalyticResult, AnalyticSolution
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.branches import BEYOND, BRANCHES, CYLINDER, DUPLICATE, INSIDE, ORIENT, VALID
from planner.ik.analytic.yaw_planar.free_pitch import free_pitch_failure, free_pitch_scalar
from planner.ik.analytic.yaw_planar.single import SolveKernels
from planner.ik.analytic.yaw_planar.status import status_and_reason

__all__ = ["ScalarPlan", "EndPlan", "scalar_plan", "end_plan", "solve_scalar", "finish_scalar", "solutions_result"]

PI = math.pi
TWO_PI = 2.0 * math.pi
NEG_PI = -math.pi
_first = itemgetter(0)

#: Packers of k doubles (native layout, as float64 arrays hold them), by k.
_PACKERS = tuple(struct.Struct(f"{k}d").pack for k in range(33))
_new = tuple.__new__


class ScalarPlan(NamedTuple):
    """An arm's constants of :func:`solve_scalar`, computed once per solver (see its fields' code).

    ``compiled`` holds the solver's compiled closed form of whole results
    (:class:`~planner.ik.analytic.yaw_planar.single.SolveKernels`; not thread-safe), or None
    (the scalar arithmetic only).
    """

    three: bool
    has_roll: bool
    roll_idx: int | None
    dof: int
    bx: float
    by: float
    mu: float
    sigma: float
    beta: float
    len_tol: float
    len_tol_sq: float
    axis_tol: float
    l1: float
    g1: float
    su: float
    sz: float
    s0: float
    s1: float
    s2: float
    limits: tuple[float, ...]
    zeros: tuple[float, ...]
    end: EndPlan | None
    compiled: SolveKernels | None


class EndPlan(NamedTuple):
    """The constants that depend on the end point (tu, tz, d): fixed unless the roll moves the tip."""

    tu: float
    tz: float
    d: float
    d_small: bool
    cylinder_tol: float
    l2: float
    g2: float
    reach_hi: float
    reach_lo: float
    l1_sq: float
    l2_sq: float
    l1_l2: float
    has_lengths: bool
    lt: float
    gt: float
    fits_lo: float
    fits_hi: float


def scalar_plan(arm: ArmGeometry) -> ScalarPlan:
    """The constants of :func:`solve_scalar` for an arm."""
    three = arm.n_pitch == 3
    limits = []
    for j in range(4):
        limits += (arm.lower[j], arm.upper[j]) if j < arm.dof and j <= arm.n_pitch else (0.0, 0.0)
    limits += (arm.lower[arm.roll_idx], arm.upper[arm.roll_idx]) if arm.has_roll else (0.0, 0.0)
    return ScalarPlan(
        three=three,
        has_roll=arm.has_roll,
        roll_idx=arm.roll_idx,
        dof=arm.dof,
        bx=arm.bx,
        by=arm.by,
        mu=arm.mu,
        sigma=arm.sigma,
        beta=arm.beta,
        len_tol=arm.len_tol,
        len_tol_sq=arm.len_tol * arm.len_tol,
        axis_tol=SINGULAR_TOL * arm.scale,
        l1=arm.l1,
        g1=arm.g1,
        su=arm.su,
        sz=arm.sz,
        s0=arm.signs[0],
        s1=arm.signs[1],
        s2=arm.signs[2] if three else 0.0,
        limits=tuple(limits),
        zeros=(0.0,) * arm.dof,
        end=end_plan(arm, *arm.tip_fixed) if arm.tip_on_roll_axis else None,
        compiled=SolveKernels(arm),
    )


def end_plan(arm: ArmGeometry, tu: float, tz: float, d: float) -> EndPlan:
    """The end-point constants of :func:`solve_scalar` for the end point (tu, tz, d)."""
    len_tol, l1 = arm.len_tol, arm.l1
    if arm.n_pitch == 3:
        l2, g2 = arm.l2, arm.g2
        lt, gt = math.hypot(tu, tz), math.atan2(tz, tu)
        # free_pitch_scalar's reach test of the wrist centre.
        fits_lo = max(abs(l1 - l2), arm.rmin_lim) - len_tol
        fits_hi = min(l1 + l2, arm.rmax_lim) + len_tol
    else:
        l2, g2 = math.hypot(tu, tz), math.atan2(tz, tu)
        lt = gt = fits_lo = fits_hi = math.nan
    return EndPlan(
        tu=tu,
        tz=tz,
        d=d,
        d_small=abs(d) <= len_tol,
        cylinder_tol=-2.0 * abs(d) * len_tol,
        l2=l2,
        g2=g2,
        reach_hi=l1 + l2 + len_tol,
        reach_lo=abs(l1 - l2) - len_tol,
        l1_sq=l1 * l1,
        l2_sq=l2 * l2,
        l1_l2=2.0 * l1 * l2,
        has_lengths=l1 > 0.0 and l2 > 0.0,
        lt=lt,
        gt=gt,
        fits_lo=fits_lo,
        fits_hi=fits_hi,
    )


def solve_scalar(
    arm: ArmGeometry, target: Target, qc: list[float] | None, plan: ScalarPlan | None = None, lean: bool = False
) -> AnalyticResult | list | None:
    """Position or pitch targets on an exact chain, in scalar arithmetic (no NumPy per step).

    The joints are ``q = (yaw, pitch joints..., roll)`` in this order (the family's layout).
    `plan` is :func:`scalar_plan` of the arm (computed here when None). With `lean`, the
    solutions' entries (as :func:`solutions_result` takes them, unsorted, without the forward
    check: errors None) when one lies within the limits, else None, instead of the result
    (for :mod:`~planner.ik.analytic.nearest`).
    """
    if plan is None:
        plan = scalar_plan(arm)
    if plan.compiled and (found := plan.compiled.entries(target.position, target.pitch, None, qc)):
        # (lean: the same entries, so that nearest's answer is the result's row bitwise)
        return found[0] if lean else solutions_result(arm, found[0], qc is not None, True, found[1], None, None, target)
    (
        three, has_roll, roll_idx, dof, bx, by, mu, sigma, beta, len_tol, len_tol_sq, axis_tol,
        l1, g1, su, sz, s0, s1, s2, limits, zeros, end, _,
    ) = plan  # fmt: skip
    px, py, pz = target.position.tolist()
    pitch = target.pitch
    sort = qc is not None
    ref = qc if sort else zeros
    # End point: the tip, moved by the roll when it sits off the roll axis.
    roll_value = qc[roll_idx] if has_roll and sort else 0.0
    if end is None:
        cr, sr = cos(roll_value), sin(roll_value)
        tip0, tipc, tips = arm.tip0, arm.tipc, arm.tips
        end = end_plan(
            arm,
            tip0[0] + tipc[0] * cr + tips[0] * sr,
            tip0[1] + tipc[1] * cr + tips[1] * sr,
            tip0[2] + tipc[2] * cr + tips[2] * sr,
        )
    (
        tu, tz, d, d_small, cylinder_tol, l2, g2, reach_hi, reach_lo, l1_sq, l2_sq, l1_l2, has_lengths,
        lt, gt, fits_lo, fits_hi,
    ) = end  # fmt: skip
    hx, hy = px - bx, py - by
    rho2 = hx * hx + hy * hy
    free = rho2 <= len_tol_sq and d_small
    cats = [VALID, VALID, VALID, VALID]
    dists = [math.nan, math.nan]  # per side (the 4 branches' distances, for failures)
    # (side 0 front / 1 back, psi, u)
    if free:
        yaws: tuple = ((0, sigma * qc[0] if sort else 0.0, 0.0),)
        cats[2] = cats[3] = DUPLICATE
    else:
        ang = atan2(hy, hx)
        under = rho2 - d * d
        if under < cylinder_tol:
            yaws = ()
            cats = [CYLINDER, CYLINDER, CYLINDER, CYLINDER]
        elif under > 0.0:
            u = sqrt(under)
            yaws = ((0, ang - mu - atan2(-d, u), u), (1, ang - mu - atan2(-d, -u), -u))
        else:
            yaws = ((0, ang - mu - atan2(-d, 0.0), 0.0),)
            cats[2] = cats[3] = DUPLICATE
    if pitch is not None:
        cos_p, sin_p = cos(pitch), sin(pitch)
        elevation_p = atan2(sin_p, abs(cos_p))
    elif three and sort:
        # q_current's in-plane approach angle (free_pitch_scalar's first choice).
        alpha_c = beta + (0.0 + s0 * qc[1] + s1 * qc[2] + s2 * qc[3])
        yaw_c = sigma * qc[0]
    # Each joint wrapped into its limits nearest ref (finish_scalar's rule), inline: the yaw
    # once per side, the roll once; keys: squared distances to q_current, summed in joint order.
    lo0, hi0, lo1, hi1, lo2, hi2, lo3, hi3, lo4, hi4 = limits
    r0, r1, r2 = ref[0], ref[1], ref[2]
    if three:
        r3 = ref[3]
    # The roll's term of the keys: added last (joint order), 0.0 without a roll (adds exactly).
    roll_ok, roll_key = True, 0.0
    if has_roll:
        r = ref[roll_idx]
        if not (lo4 <= roll_value and roll_value <= hi4 and NEG_PI <= roll_value - r <= PI):
            roll_value = wrap_scalar(roll_value, lo4, hi4, r)
            roll_ok = lo4 <= roll_value <= hi4
        roll_key = (roll_value - r) * (roll_value - r)
    # (key, slot, q, within limits, singular, position error, orientation error)
    sols: list[tuple] = []
    append = sols.append
    any_within = singular = False
    for side, psi, ue in yaws:
        if pitch is not None or not lean:  # (the forward check's, and the pitch's side)
            cy, sy = cos(psi + mu), sin(psi + mu)
        if pitch is not None:
            # In-plane approach angle: the pitch, or pi - pitch where the arm's plane
            # direction points towards the base z axis (planner.geometry.target's outward side).
            phi = (pitch if cy * px + sy * py >= 0.0 else PI - pitch) - beta
            cp, sp = cos(phi), sin(phi)
        elif three:
            phi = None
            if qc is not None:
                # q_current's approach, kept in the world: mirrored when this branch faces the other way.
                phi = (PI - alpha_c if cos(psi - yaw_c) < 0.0 else alpha_c) - beta
                cp, sp = cos(phi), sin(phi)
                vx = ue - (cp * tu - sp * tz) - su
                vz = pz - (sp * tu + cp * tz) - sz
                dd = hypot(vx, vz)
                if not fits_lo <= dd <= fits_hi:
                    phi = None
            if phi is None:
                phi = free_pitch_scalar(arm, psi, ue, pz, tu, tz, lt, gt, None)
                if phi is None:
                    cats[2 * side] = cats[2 * side + 1] = free_pitch_failure(arm, ue, pz, lt)
                    continue
                cp, sp = cos(phi), sin(phi)
                vx = ue - (cp * tu - sp * tz) - su
                vz = pz - (sp * tu + cp * tz) - sz
                dd = hypot(vx, vz)
        if pitch is not None:
            if three:
                vx = ue - (cp * tu - sp * tz) - su
                vz = pz - (sp * tu + cp * tz) - sz
            else:
                vx, vz = ue - su, pz - sz
            dd = hypot(vx, vz)
        elif not three:
            vx, vz = ue - su, pz - sz
            dd = hypot(vx, vz)
        dists[side] = dd
        if dd > reach_hi:
            cats[2 * side] = cats[2 * side + 1] = BEYOND
            continue
        if dd < reach_lo:
            cats[2 * side] = cats[2 * side + 1] = INSIDE
            continue
        # Candidates (slot, shoulder link angle a1, relative elbow angle e, elbow singular).
        if not three and pitch is not None:
            # The pitch fixes the last link: the elbow is the end point minus that link,
            # the shoulder points at the elbow (one solution, well conditioned).
            ex = ue - (cp * tu - sp * tz) - su
            ez = pz - (sp * tu + cp * tz) - sz
            if abs(hypot(ex, ez) - l1) > arm.consistency_tol:
                cats[2 * side] = cats[2 * side + 1] = ORIENT
                continue
            a1 = atan2(ez, ex)
            e = (phi + g2 - a1 + PI) % TWO_PI - PI  # wrap_pi
            straight = abs(sin(e)) < SINGULAR_TOL
            # A stretched or folded elbow: one solution, labelled elbow-up on every path.
            up = straight or (e <= 0.0 if side == 0 else e >= 0.0)
            slot = 2 * side + (0 if up else 1)
            cats[slot ^ 1] = DUPLICATE
            cands: tuple = ((slot, a1, e, straight),)
        else:
            c = (dd * dd - l1_sq - l2_sq) / l1_l2 if has_lengths else 1.0
            c = 1.0 if c > 1.0 else (-1.0 if c < -1.0 else c)
            s = sqrt(1.0 - c * c)
            base = atan2(vz, vx)
            if s < SINGULAR_TOL:  # a stretched or folded elbow: one solution
                c = 1.0 if c > 0 else -1.0
                e_abs = atan2(0.0, c)
                half = atan2(0.0, l1 + l2 * c)
                if side == 0:
                    cands = ((0, base + half, -e_abs, True),)
                    cats[1] = DUPLICATE
                else:
                    cands = ((2, base - half, e_abs, True),)
                    cats[3] = DUPLICATE
            else:
                e_abs = atan2(s, c)
                half = atan2(l2 * s, l1 + l2 * c)
                if side == 0:
                    cands = ((0, base + half, -e_abs, False), (1, base - half, e_abs, False))
                else:
                    cands = ((2, base - half, e_abs, False), (3, base + half, -e_abs, False))
        off_axis = free or abs(ue) < axis_tol
        v0 = sigma * psi
        side_ok = roll_ok
        if not (lo0 <= v0 and v0 <= hi0 and NEG_PI <= v0 - r0 <= PI):
            v0 = wrap_scalar(v0, lo0, hi0, r0)
            side_ok = side_ok and lo0 <= v0 <= hi0
        side_key = 0.0 + (v0 - r0) * (v0 - r0) if sort else 0.0
        for slot, a1, e, elbow_singular in cands:
            phi2 = a1 - g1
            phi3 = a1 + e - g2
            d32 = phi3 - phi2
            if lean:  # unchecked: solve_ik checks the one it answers with by Pinocchio FK
                perr = oerr = None
                d43 = phi - phi3 if three else 0.0
            else:
                # Forward check: the closed-form forward model at the assembled q; its pitch sums
                # (f2, f3, f4) are sign * q of the joints below, i.e. these (the signs are +-1).
                f3 = phi2 + d32
                a2, a3 = phi2 + g1, f3 + g2
                fu = su + l1 * cos(a2) + l2 * cos(a3)
                fz = sz + l1 * sin(a2) + l2 * sin(a3)
                if three:
                    d43 = phi - phi3
                    f4 = f3 + d43
                    if f4 == phi:  # mostly: the side's sine and cosine reused
                        ct, st = cp, sp
                    else:
                        ct, st = cos(f4), sin(f4)
                    fu += ct * tu - st * tz
                    fz += st * tu + ct * tz
                else:
                    f4 = f3
                dx = bx + cy * fu + sy * d - px
                dy = by + sy * fu - cy * d - py
                dz = fz - pz
                perr = sqrt(dx * dx + dy * dy + dz * dz)
                oerr = None
                if pitch is not None:
                    alpha = beta + f4
                    if alpha == pitch:
                        c_alpha, s_alpha = cos_p, sin_p
                    else:
                        c_alpha, s_alpha = cos(alpha), sin(alpha)
                    ax, ay = c_alpha * cy, c_alpha * sy
                    # pitch_error_scalar, its first line inline; the rest where it applies.
                    oerr = abs(atan2(s_alpha, hypot(ax, ay)) - elevation_p)
                    if cos_p * (ax * px + ay * py) < 0.0:
                        oerr = pitch_error_scalar(ax, ay, s_alpha, px, py, cos_p, sin_p, elevation_p)
            within = side_ok
            v1 = s0 * phi2
            t1 = v1 - r1
            if not (lo1 <= v1 and v1 <= hi1 and NEG_PI <= t1 and t1 <= PI):
                v1 = wrap_scalar(v1, lo1, hi1, r1)
                t1 = v1 - r1
                within = within and lo1 <= v1 <= hi1
            v2 = s1 * d32
            t2 = v2 - r2
            if not (lo2 <= v2 and v2 <= hi2 and NEG_PI <= t2 and t2 <= PI):
                v2 = wrap_scalar(v2, lo2, hi2, r2)
                t2 = v2 - r2
                within = within and lo2 <= v2 <= hi2
            if three:
                v3 = s2 * d43
                t3 = v3 - r3
                if not (lo3 <= v3 and v3 <= hi3 and NEG_PI <= t3 and t3 <= PI):
                    v3 = wrap_scalar(v3, lo3, hi3, r3)
                    t3 = v3 - r3
                    within = within and lo3 <= v3 <= hi3
                q = (v0, v1, v2, v3, roll_value) if has_roll else (v0, v1, v2, v3)
                key = side_key + t1 * t1 + t2 * t2 + t3 * t3 + roll_key if sort else 0.0
            else:
                q = (v0, v1, v2, roll_value) if has_roll else (v0, v1, v2)
                key = side_key + t1 * t1 + t2 * t2 + roll_key if sort else 0.0
            sing = elbow_singular or off_axis
            append((key, slot, q, (within, BRANCHES[slot], sing, perr, oerr)))
            any_within = any_within or within
            singular = singular or sing
    if lean:
        return sols if any_within else None
    d0, d1 = dists
    return solutions_result(arm, sols, sort, any_within, singular, cats, [d0, d0, d1, d1], target)


def finish_scalar(arm: ArmGeometry, sols, cats, dist, qc, target) -> AnalyticResult:
    """The result from the branches' raw solutions: wrapped into the limits, sorted, with status.

    Args:
        arm: The geometry.
        sols: Per solution (slot, q, singular, position error, orientation error), q a sequence
            of joint values not yet wrapped into the limits.
        cats: The 4 branch categories.
        dist: The 4 wrist point to shoulder distances [m].
        qc: The current configuration (list), or None.
        target: The target (for the reason of a failure).

    Returns:
        The result (see :func:`solutions_result`).
    """
    lower, upper = arm.lower, arm.upper
    sort = qc is not None
    ref = qc if sort else [0.0] * arm.dof
    entries = []
    any_within = singular = False
    for slot, q, sing, perr, oerr in sols:
        row = []
        within = True
        key = 0.0
        for v, lo, hi, r in zip(q, lower, upper, ref):
            if not (lo <= v and v <= hi and NEG_PI <= v - r <= PI):
                v = wrap_scalar(v, lo, hi, r)
                if not lo <= v <= hi:
                    within = False
            row.append(v)
            key += (v - r) * (v - r)
        entries.append((key, slot, row, (within, BRANCHES[slot], sing, perr, oerr)))
        any_within = any_within or within
        singular = singular or sing
    return solutions_result(arm, entries, sort, any_within, bool(singular), cats, dist, target)


def solutions_result(arm: ArmGeometry, entries, sort, any_within, singular, cats, dist, target) -> AnalyticResult:
    """The result from wrapped solutions: sorted, in one read-only array, with the status.

    Args:
        arm: The geometry.
        entries: Per solution (key, slot, q, (within limits, branch name, singular, position
            error, orientation error)), q wrapped into the limits (a sequence of dof floats),
            key its squared joint distance to q_current.
        sort: Whether to sort by the keys (stable: branch order among equal keys).
        any_within: Whether a solution lies within the limits.
        singular: Whether a solution is singular.
        cats: The 4 branch categories.
        dist: The 4 wrist point to shoulder distances [m].
        target: The target (for the reason of a failure).

    Returns:
        The result.
    """
    n = len(entries)
    if sort and n > 1:
        entries.sort(key=_first)
    # One read-only array for all solutions (over immutable bytes); each q is a row of it.
    # Unrolled for the common counts (a comprehension is a function call of its own).
    dof = arm.dof
    if n == 4:
        e0, e1, e2, e3 = entries
        table = np.frombuffer(_PACKERS[4 * dof](*e0[2], *e1[2], *e2[2], *e3[2]))
        table.shape = (4, dof)
        solutions = (
            _new(AnalyticSolution, (table[0],) + e0[3]),
            _new(AnalyticSolution, (table[1],) + e1[3]),
            _new(AnalyticSolution, (table[2],) + e2[3]),
            _new(AnalyticSolution, (table[3],) + e3[3]),
        )
    elif n == 2:
        e0, e1 = entries
        table = np.frombuffer(_PACKERS[2 * dof](*e0[2], *e1[2]))
        table.shape = (2, dof)
        solutions = (_new(AnalyticSolution, (table[0],) + e0[3]), _new(AnalyticSolution, (table[1],) + e1[3]))
    else:
        flat: list[float] = []
        for entry in entries:
            flat += entry[2]
        k = len(flat)
        table = np.frombuffer((_PACKERS[k] if k < len(_PACKERS) else struct.Struct(f"{k}d").pack)(*flat))
        table.shape = (n, dof)
        solutions = tuple([_new(AnalyticSolution, (table[i],) + e[3]) for i, e in enumerate(entries)])
    if any_within:
        return _new(AnalyticResult, (STATUS_SOLVED, "", solutions, singular))
    details = sorted(((e[1], sol) for e, sol in zip(entries, solutions)), key=_first)
    status, reason = status_and_reason(arm, cats, dist, details, target)
    return _new(AnalyticResult, (status, reason, solutions, singular))
