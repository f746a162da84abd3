"""Position and pitch targets on exact chains, in scalar arithmetic (no NumPy per step).

The fast path of :meth:`~planner.ik.analytic.yaw_planar.solver.YawPlanarIK.solve` (tens of
microseconds): the same closed form as :mod:`~planner.ik.analytic.yaw_planar.core`, one target
at a time, with the same branch order and categories.
"""

from __future__ import annotations

import math

import numpy as np

from planner.geometry.chain import wrap_scalar
from planner.geometry.target import Target, pitch_error_scalar
from planner.ik.analytic.geometry import SINGULAR_TOL, wrap_pi
from planner.ik.analytic.result import STATUS_SOLVED, AnalyticResult, AnalyticSolution
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.branches import BEYOND, BRANCHES, CYLINDER, DUPLICATE, INSIDE, ORIENT, VALID
from planner.ik.analytic.yaw_planar.free_pitch import free_pitch_failure, free_pitch_scalar
from planner.ik.analytic.yaw_planar.status import status_and_reason

__all__ = ["solve_scalar", "finish_scalar"]

PI = math.pi
TWO_PI = 2.0 * math.pi


def solve_scalar(arm: ArmGeometry, target: Target, qc: list[float] | None) -> AnalyticResult:
    """Position or pitch targets on an exact chain, in scalar arithmetic (no NumPy per step)."""
    px, py, pz = target.position.tolist()
    pitch = target.pitch
    if pitch is not None:
        cos_p, sin_p = math.cos(pitch), math.sin(pitch)
        elevation_p = math.atan2(sin_p, abs(cos_p))
    dof = arm.dof
    three = arm.n_pitch == 3
    cos, sin, atan2, sqrt, hypot = math.cos, math.sin, math.atan2, math.sqrt, math.hypot
    # End point: the tip, moved by the roll when it sits off the roll axis.
    roll_value = 0.0
    if arm.has_roll:
        roll_value = qc[arm.roll_idx] if qc is not None else 0.0
    if arm.tip_on_roll_axis:
        tu, tz, d = arm.tip_fixed
    else:
        cr, sr = cos(roll_value), sin(roll_value)
        tu = arm.tip0[0] + arm.tipc[0] * cr + arm.tips[0] * sr
        tz = arm.tip0[1] + arm.tipc[1] * cr + arm.tips[1] * sr
        d = arm.tip0[2] + arm.tipc[2] * cr + arm.tips[2] * sr
    hx, hy = px - arm.bx, py - arm.by
    rho2 = hx * hx + hy * hy
    len_tol = arm.len_tol
    free = rho2 <= len_tol * len_tol and abs(d) <= len_tol
    ang = atan2(hy, hx)
    mu = arm.mu
    yaws: list[tuple[int, float, float]] = []  # (side 0 front / 1 back, psi, u)
    cats = [VALID] * 4
    if free:
        psi0 = arm.sigma * qc[0] if qc is not None else 0.0
        yaws.append((0, psi0, 0.0))
        cats[2] = cats[3] = DUPLICATE
    else:
        under = rho2 - d * d
        if under < -2.0 * abs(d) * len_tol:
            cats = [CYLINDER] * 4
        else:
            u = sqrt(under) if under > 0.0 else 0.0
            yaws.append((0, ang - mu - atan2(-d, u), u))
            if u > 0.0:
                yaws.append((1, ang - mu - atan2(-d, -u), -u))
            else:
                cats[2] = cats[3] = DUPLICATE
    l1, g1, su, sz = arm.l1, arm.g1, arm.su, arm.sz
    beta, sigma, bx, by = arm.beta, arm.sigma, arm.bx, arm.by
    signs, idx, roll_idx = arm.signs, arm.pitch_idx, arm.roll_idx
    axis_tol = SINGULAR_TOL * arm.scale
    sols: list[tuple[int, list[float], bool, float, float | None]] = []
    dist = [math.nan] * 4
    for side, psi, ue in yaws:
        # Candidates (slot, shoulder link angle a1, relative elbow angle e, elbow singular).
        cands: list[tuple[int, float, float, bool]] = []
        phi = 0.0
        cy, sy = cos(psi + mu), sin(psi + mu)
        if pitch is not None:
            # In-plane approach angle: the pitch, or pi - pitch where the arm's plane
            # direction points towards the base z axis (planner.geometry.target's outward side).
            alpha_t = pitch if cy * px + sy * py >= 0.0 else PI - pitch
        if three:
            l2, g2 = arm.l2, arm.g2
            if pitch is not None:
                phi = alpha_t - beta
            else:
                phi = free_pitch_scalar(arm, psi, ue, pz, tu, tz, hypot(tu, tz), atan2(tz, tu), qc)
                if phi is None:
                    cats[2 * side] = cats[2 * side + 1] = free_pitch_failure(arm, ue, pz, hypot(tu, tz))
                    continue
            cp, sp = cos(phi), sin(phi)
            wu = ue - (cp * tu - sp * tz)
            wz = pz - (sp * tu + cp * tz)
        else:
            l2, g2 = hypot(tu, tz), atan2(tz, tu)
            wu, wz = ue, pz
        vx, vz = wu - su, wz - sz
        dd = hypot(vx, vz)
        dist[2 * side] = dist[2 * side + 1] = dd
        if dd > l1 + l2 + len_tol:
            cats[2 * side] = cats[2 * side + 1] = BEYOND
            continue
        if dd < abs(l1 - l2) - len_tol:
            cats[2 * side] = cats[2 * side + 1] = INSIDE
            continue
        if not three and pitch is not None:
            # The pitch fixes the last link: the elbow is the end point minus that link,
            # the shoulder points at the elbow (one solution, well conditioned).
            phi = alpha_t - beta
            cp, sp = cos(phi), sin(phi)
            ex = ue - (cp * tu - sp * tz) - su
            ez = pz - (sp * tu + cp * tz) - sz
            if abs(hypot(ex, ez) - l1) > arm.consistency_tol:
                cats[2 * side] = cats[2 * side + 1] = ORIENT
                continue
            a1 = atan2(ez, ex)
            e = wrap_pi(phi + g2 - a1)
            up = e <= 0.0 if side == 0 else e >= 0.0
            slot = 2 * side + (0 if up else 1)
            cats[slot ^ 1] = DUPLICATE
            cands.append((slot, a1, e, abs(sin(e)) < SINGULAR_TOL))
        else:
            c = (dd * dd - l1 * l1 - l2 * l2) / (2.0 * l1 * l2) if l1 > 0.0 and l2 > 0.0 else 1.0
            c = 1.0 if c > 1.0 else (-1.0 if c < -1.0 else c)
            s = sqrt(1.0 - c * c)
            elbow_singular = s < SINGULAR_TOL
            if elbow_singular:
                s, c = 0.0, (1.0 if c > 0 else -1.0)
            e_abs = atan2(s, c)
            base = atan2(vz, vx)
            half = atan2(l2 * s, l1 + l2 * c)
            if side == 0:
                cands.append((0, base + half, -e_abs, elbow_singular))
                if elbow_singular:
                    cats[1] = DUPLICATE
                else:
                    cands.append((1, base - half, e_abs, False))
            else:
                cands.append((2, base - half, e_abs, elbow_singular))
                if elbow_singular:
                    cats[3] = DUPLICATE
                else:
                    cands.append((3, base + half, -e_abs, False))
        q0 = sigma * psi
        for slot, a1, e, elbow_singular in cands:
            phi2 = a1 - g1
            phi3 = a1 + e - g2
            q = [0.0] * dof
            q[0] = q0
            q[idx[0]] = signs[0] * phi2
            q[idx[1]] = signs[1] * (phi3 - phi2)
            if three:
                q[idx[2]] = signs[2] * (phi - phi3)
            if roll_idx is not None:
                q[roll_idx] = roll_value
            # Forward check: the closed-form forward model evaluated at the assembled q.
            f2 = signs[0] * q[idx[0]]
            f3 = f2 + signs[1] * q[idx[1]]
            fu = su + l1 * cos(f2 + g1) + l2 * cos(f3 + g2)
            fz = sz + l1 * sin(f2 + g1) + l2 * sin(f3 + g2)
            if three:
                f4 = f3 + signs[2] * q[idx[2]]
                ct, st = cos(f4), sin(f4)
                fu += ct * tu - st * tz
                fz += st * tu + ct * tz
            else:
                f4 = f3
            fx = bx + cy * fu + sy * d
            fy = by + sy * fu - cy * d
            perr = sqrt((fx - px) ** 2 + (fy - py) ** 2 + (fz - pz) ** 2)
            oerr = None
            if pitch is not None:
                c_alpha, s_alpha = cos(beta + f4), sin(beta + f4)
                oerr = pitch_error_scalar(c_alpha * cy, c_alpha * sy, s_alpha, px, py, cos_p, sin_p, elevation_p)
            singular = elbow_singular or free or abs(ue) < axis_tol
            sols.append((slot, q, singular, perr, oerr))
    return finish_scalar(arm, sols, cats, dist, qc, target)


def finish_scalar(arm: ArmGeometry, sols, cats, dist, qc, target) -> AnalyticResult:
    """The result from the branches' raw solutions: wrapped into the limits, sorted, with status."""
    lower, upper = arm.lower, arm.upper
    dof = arm.dof
    ref = qc if qc is not None else [0.0] * dof
    within_flags = []
    any_within = False
    for _, q, _, _, _ in sols:
        within = True
        for j in range(dof):
            v, lo, hi, r = q[j], lower[j], upper[j], ref[j]
            if lo <= v <= hi and -PI <= v - r <= PI:
                continue  # already in range and the equivalent nearest ref
            w = v + TWO_PI * round((r - v) / TWO_PI)  # wrap_scalar's first step; in range, its answer
            if not lo <= w <= hi:
                w = wrap_scalar(v, lo, hi, r)
                if w < lo or w > hi:
                    within = False
            q[j] = w
        within_flags.append(within)
        any_within = any_within or within
    n = len(sols)
    order = range(n)
    if qc is not None and n > 1:
        order = sorted(order, key=lambda i: sum((a - b) * (a - b) for a, b in zip(sols[i][1], qc)))
    # One frozen array for all solutions; each solution's q is a (read-only) row of it.
    rows = np.array([sols[i][1] for i in order], dtype=float).reshape(n, dof)
    rows.setflags(write=False)
    solutions = tuple(
        AnalyticSolution(row, within_flags[i], BRANCHES[sols[i][0]], sols[i][2], sols[i][3], sols[i][4])
        for row, i in zip(rows, order)
    )
    singular = any(s[2] for s in sols)
    if any_within:
        return AnalyticResult(STATUS_SOLVED, "", solutions, singular)
    by_slot = {sols[i][0]: sol for i, sol in zip(order, solutions)}
    details = [(slot, by_slot[slot]) for slot in sorted(by_slot)]
    status, reason = status_and_reason(arm, cats, dist, details, target)
    return AnalyticResult(status, reason, solutions, singular)
