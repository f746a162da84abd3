"""Full-pose targets on exact chains, in scalar arithmetic (no NumPy per branch).

The fast path of :meth:`~planner.ik.analytic.yaw_planar.solver.YawPlanarIK.solve` for rotation
targets: the closed form of :func:`~planner.ik.analytic.yaw_planar.core.solve_core` with a
rotation (:mod:`~planner.ik.analytic.yaw_planar.orientation`), one target at a time, with the
same branch order, categories and tolerances, and each branch verified by the forward model.
As :func:`~planner.ik.analytic.yaw_planar.scalar.solve_scalar`, the result comes from one
call of the plan's compiled closed form where that is sure.

Everything orientational is done in the plane basis ``B = [n, e_u, z]`` (right-handed; a
rotation about z, so it commutes with the yaw): there the tip rotation relative to q = 0 is
``Rz(psi) Rx(phi + kappa) Ry(roll) Rx(-kappa)`` (yaw, pitch sum, roll about the in-plane roll
axis at angle kappa), and the target enters once as ``m = B^T R rot0^T B Rx(kappa)``, whose
columns give the roll axis's and the pitch axis's images.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from math import atan2, cos, hypot, sin, sqrt  # module names: one opcode fewer per call than locals

import numpy as np

from planner.geometry.chain import wrap_scalar
from planner.geometry.target import Target
from planner.ik.analytic.geometry import SINGULAR_TOL, wrap_pi
from planner.ik.analytic.nearest import NearestSolution, nearest_entry
from planner.ik.analytic.result import AnalyticResult
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.branches import BEYOND, BRANCHES, CYLINDER, DUPLICATE, INSIDE, ORIENT, VALID
from planner.ik.analytic.yaw_planar.scalar import NEG_PI, ScalarPlan, scalar_plan, solutions_result

__all__ = ["PoseFrame", "pose_frame", "pose_branches", "pose_nearest", "solve_pose_scalar"]

PI = math.pi


@dataclass(frozen=True)
class PoseFrame:
    """Constants of the plane basis for rotation targets (see the module docstring).

    Attributes:
        linear: Shape (9, 9) or (12, 9): ``m`` (row-major) from the target rotation ``R``
            (row-major) as one product, ``kron(B^T, C^T)`` with ``C = rot0^T B Rx(kappa)``,
            then (with a tip offset) the rows of ``R l``.
        kappa: The roll axis's in-plane angle (0 without a roll).
        tip_offset: The roll centre to the tip in the tip frame, as ``Rx(-kappa) B^T rot0 l``
            (plane basis), or None when the tip is the roll centre (or there is no roll).
        shift_local: The roll centre to the tip in the tip frame, shape (3,), or None (as above).
        cos_kappa: cos(kappa).
        sin_kappa: sin(kappa).
        cos_mu: cos(mu) (the arm's plane direction at yaw 0).
        sin_mu: sin(mu).
        elbow: The elbow's constants for 3-pitch arms (:func:`_three_pitch`): the reach limits
            l1 + l2 + tol and abs(l1 - l2) - tol [m], l1 ** 2, l2 ** 2, 2 l1 l2, and whether
            both lengths are positive (NaN and False for 2-pitch arms).
    """

    linear: np.ndarray
    kappa: float
    tip_offset: tuple[float, float, float] | None
    shift_local: tuple[float, float, float] | None
    cos_kappa: float
    sin_kappa: float
    cos_mu: float
    sin_mu: float
    elbow: tuple[float, float, float, float, float, bool]


def _rot_x(a: float) -> np.ndarray:
    ca, sa = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])


def pose_frame(arm: ArmGeometry) -> PoseFrame:
    """The plane-basis constants of an arm (computed once per solver)."""
    b = np.column_stack([arm.n, arm.e_u, [0.0, 0.0, 1.0]])
    kappa = float(arm.kappa) if arm.has_roll else 0.0
    c = arm.rot0.T @ b @ _rot_x(kappa)
    tip_offset = shift_local = None
    if arm.has_roll and float(np.linalg.norm(arm.centre_to_tip_local)) > 0.0:
        local = np.asarray(arm.centre_to_tip_local, dtype=float)
        shift_local = tuple(local.tolist())
        tip_offset = tuple((_rot_x(-kappa) @ b.T @ arm.rot0 @ local).tolist())
    linear = np.kron(b.T, c.T)
    if shift_local is not None:
        linear = np.vstack([linear, np.kron(np.eye(3), np.asarray(shift_local)[None, :])])
    mu = arm.mu
    l1, l2, len_tol = arm.l1, arm.l2, arm.core_len_tol
    if arm.n_pitch == 3:
        elbow = (l1 + l2 + len_tol, abs(l1 - l2) - len_tol, l1 * l1, l2 * l2, 2.0 * l1 * l2, l1 > 0.0 and l2 > 0.0)
    else:
        elbow = (math.nan, math.nan, math.nan, math.nan, math.nan, False)
    return PoseFrame(
        linear, kappa, tip_offset, shift_local, math.cos(kappa), math.sin(kappa), math.cos(mu), math.sin(mu), elbow
    )


def solve_pose_scalar(
    arm: ArmGeometry, frame: PoseFrame, target: Target, qc: list[float] | None, plan: ScalarPlan | None = None
) -> AnalyticResult:
    """Every closed-form solution of a full-pose target on an exact chain (scalar arithmetic).

    `plan` is :func:`~planner.ik.analytic.yaw_planar.scalar.scalar_plan` of the arm (computed
    here when None): its joint limits.
    """
    if plan is None:
        plan = scalar_plan(arm)
    if plan.compiled and (found := plan.compiled.entries(target.position, None, target.rotation, qc)):
        return solutions_result(arm, found[0], qc is not None, True, found[1], None, None, target)
    entries, cats, dist, any_within, singular = _pose(arm, frame, target.position.tolist(), target.rotation, qc, plan)
    return solutions_result(arm, entries, qc is not None, any_within, singular, cats, dist, target)


def pose_nearest(
    arm: ArmGeometry, frame: PoseFrame, target: Target, qc: list[float] | None, plan: ScalarPlan
) -> NearestSolution | None:
    """The solution of :func:`solve_pose_scalar` solve_ik answers with, or None.

    Only the candidates within the limits are verified by the forward model (the others are
    assembled and wrapped, not checked); where one is not, the count and place are left None.
    """
    if plan.compiled and (found := plan.compiled.entries(target.position, None, target.rotation, qc)):
        return nearest_entry(found[0], qc)  # the result's row bitwise (solve_pose_scalar's entries)
    return _pose(arm, frame, target.position.tolist(), target.rotation, qc, plan, True)


def pose_branches(arm: ArmGeometry, frame: PoseFrame, position: list[float], rotation: np.ndarray, qc):
    """The ideal closed form's branches of a pose, unverified (for the correction of inexact chains).

    Args:
        arm: The geometry.
        frame: Its plane-basis constants (:func:`pose_frame`).
        position: Target position [m] (3 floats).
        rotation: Target rotation, shape (3, 3).
        qc: The current configuration (list), or None.

    Returns:
        (solutions, categories, distances): solutions as (slot, q, singular, None, None), q a
        list not yet wrapped into the limits; the 4 branch categories; the 4 wrist distances.
    """
    return _pose(arm, frame, position, rotation, qc, None)


def _pose(arm: ArmGeometry, frame: PoseFrame, position, rotation, qc, plan: ScalarPlan | None, lean: bool = False):
    """The branches of a pose: verified and wrapped with `plan` (as solve_scalar), else raw.

    With a plan: (entries as in solutions_result, categories, distances, any within limits,
    any singular); without: (solutions as pose_branches returns them, categories, distances).
    With a plan and `lean`: the verified solution within the limits nearest `qc` (as
    :func:`~planner.ik.analytic.nearest.nearest_entry` picks it from the verified entries),
    or None; only the candidates within the limits are verified, and where one outside them
    is not, its count and place (which depend on every check) are left None.
    """
    px, py, pz = position
    flat = frame.linear.dot(rotation.ravel()).tolist()  # ndarray.dot: half the time of @ for this size
    m = (flat[0:3], flat[3:6], flat[6:9])
    # End point: the tip, or the roll centre (the tip minus its offset turned by the target).
    if arm.has_roll:
        tu, tz, d = arm.centre
        if frame.shift_local is not None:
            ex, ey, ez = px - flat[9], py - flat[10], pz - flat[11]
        else:
            ex, ey, ez = px, py, pz
    else:
        tu, tz, d = arm.tip_fixed
        ex, ey, ez = px, py, pz
    hx, hy = ex - arm.bx, ey - arm.by
    rho2 = hx * hx + hy * hy
    axis_tol = arm.len_tol
    free = rho2 <= axis_tol * axis_tol and abs(d) <= axis_tol
    len_tol = arm.core_len_tol
    under = rho2 - d * d
    cylinder = not free and under < -2.0 * abs(d) * len_tol
    u_pos = sqrt(under) if under > 0.0 else 0.0
    u = 0.0 if free else u_pos
    mu = arm.mu
    has_roll = arm.has_roll
    same_yaw = False  # both sides at one yaw (no roll: the rotation fixes it), so side 1 repeats side 0
    # The yaw from the rotation where it fixes it better (orientation.yaw_for_rotation), else
    # from the position.
    if has_roll:
        w1, w2 = m[0][1], m[1][1]  # the roll axis's image (its n and e_u parts)
        horiz = hypot(w1, w2)
        psi_a = atan2(-w1, w2)
        use = horiz > 1e-9 and horiz * arm.scale >= u
    else:
        psi_a = atan2(m[1][0], m[0][0])  # the pitch axis's image, from n
        use = True
    if not use:
        ang = atan2(hy, hx)
        psi = [ang - mu - atan2(-d, u_pos), ang - mu - atan2(-d, -u_pos)]
        if free:
            psi[0] = arm.sigma * qc[0] if qc is not None else 0.0
        ue = [u, -u]
        if cylinder:
            cat = [CYLINDER, CYLINDER]
        else:
            cat = [VALID, DUPLICATE if free or u_pos == 0.0 else VALID]
    else:
        cy, sy = cos(mu + psi_a), sin(mu + psi_a)
        ue_a = hx * cy + hy * sy
        lat_a = hx * sy - hy * cy
        forward = ue_a >= 0.0
        tol = max(arm.consistency_tol, arm.core_len_tol)
        off_plane = ORIENT if abs(lat_a - d) > tol else VALID
        if has_roll:
            off_back = ORIENT if abs(-lat_a - d) > tol else VALID
            front = psi_a if forward else psi_a + PI
            psi = [front, front + PI]
            cat_rot = [off_plane, off_back] if forward else [off_back, off_plane]
        else:
            psi = [psi_a, psi_a]
            cat_rot = [off_plane, DUPLICATE] if forward else [DUPLICATE, off_plane]
        ue = [abs(ue_a), -abs(ue_a)]
        same_yaw = not has_roll
        cat = [CYLINDER, CYLINDER] if cylinder else cat_rot
    # Per side: the pitch sum and its residual, the roll (orientation.pitch_from_rotation).
    orient_tol = arm.orient_tol
    kappa = frame.kappa
    ck, sk = frame.cos_kappa, frame.sin_kappa
    col0 = (m[0][0], m[1][0], m[2][0])
    col1 = (m[0][1], m[1][1], m[2][1])
    phis = [0.0, 0.0]
    rolls = [0.0, 0.0]
    twisted = [False, False]  # the rotation is not the arm's at this yaw
    # Sines and cosines of each side's yaw and pitch sum, computed once (reused below).
    cpsi, spsi, cphi, sphi = [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]
    for side in (0, 1):
        if side == 1 and same_yaw:
            cpsi[1], spsi[1], cphi[1], sphi[1] = cpsi[0], spsi[0], cphi[0], sphi[0]
            phis[1], twisted[1] = phis[0], twisted[0]
            break
        cpsi[side] = cp_ = cos(psi[side])
        spsi[side] = sp_ = sin(psi[side])
        x1 = cp_ * col1[0] + sp_ * col1[1]
        x2 = -sp_ * col1[0] + cp_ * col1[1]
        x3 = col1[2]
        if has_roll:
            phi = atan2(x3, x2) - kappa
            residual = math.asin(min(1.0, abs(x1)))
            # roll: Rx(-phi) Rz(-psi) (the pitch axis's image).
            v1 = cp_ * col0[0] + sp_ * col0[1]
            v2 = -sp_ * col0[0] + cp_ * col0[1]
            v3 = col0[2]
            cphi[side] = cf = cos(phi)
            sphi[side] = sf = sin(phi)
            b2 = cf * v2 + sf * v3
            b3 = -sf * v2 + cf * v3
            rolls[side] = atan2(sk * b2 - ck * b3, v1)
        else:
            phi = atan2(x3, x2)
            cphi[side] = cf = cos(phi)
            sphi[side] = sf = sin(phi)
            residual = _rotation_angle_unrolled(m, cp_, sp_, cf, sf)
        phis[side] = phi
        twisted[side] = residual > orient_tol
    if arm.n_pitch == 3:
        c0, c1 = cat
        cat = [ORIENT if c0 == VALID and twisted[0] else c0, ORIENT if c1 == VALID and twisted[1] else c1]
        cands, cats, dist = _three_pitch(arm, frame.elbow, ue, ez, tu, tz, cphi, sphi, cat)
    else:
        cands, cats, dist = _two_pitch(arm, ue, ez, tu, tz, phis, cat, twisted)
    # Assemble each branch; with a plan, verify it by the forward model (tip position and
    # rotation) and wrap its joints into the limits.
    dof = arm.dof
    sigma, signs, roll_idx = arm.sigma, arm.signs, arm.roll_idx
    s0, s1 = signs[0], signs[1]
    three = arm.n_pitch == 3
    s2 = signs[2] if three else 0.0
    l1, g1, l2, g2, su, sz = arm.l1, arm.g1, arm.l2, arm.g2, arm.su, arm.sz
    scale_axis = SINGULAR_TOL * arm.scale
    if plan is None:
        sols = []
        for slot, side, a1, phi2_3, elbow_singular in cands:
            q = [0.0] * dof
            q[0] = sigma * psi[side]
            phi2 = a1 - g1
            q[1] = s0 * phi2
            q[2] = s1 * (phi2_3 - phi2)
            if three:
                q[3] = s2 * (phis[side] - phi2_3)
            if roll_idx is not None:
                q[roll_idx] = rolls[side]
            sols.append((slot, q, elbow_singular or free or abs(ue[side]) < scale_axis, None, None))
        return sols, cats, dist
    bx, by = arm.bx, arm.by
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = m
    pos_tol = 1e-10 * max(1.0, arm.scale)
    offset = frame.tip_offset
    smu, cmu = frame.sin_mu, frame.cos_mu
    lo0, hi0, lo1, hi1, lo2, hi2, lo3, hi3, lo4, hi4 = plan.limits
    sort = qc is not None
    ref = qc if sort else plan.zeros
    r0, r1, r2 = ref[0], ref[1], ref[2]
    r3 = ref[3] if three else 0.0
    r4 = ref[roll_idx] if roll_idx is not None else 0.0
    entries = []
    any_within = singular = False
    orient_side = None
    # lean: only the candidates within the limits are verified (solve_ik picks one of them).
    unchecked = False
    for slot, side, a1, phi2_3, elbow_singular in cands:
        phi = phis[side]
        phi2 = a1 - g1
        d32 = phi2_3 - phi2
        if three:
            d43 = phi - phi2_3
        if side != orient_side:
            orient_side = side
            side_psi, theta = psi[side], rolls[side]
            side_singular = free or abs(ue[side]) < scale_axis
            side_checked = False  # the side's constants of the forward check are computed on first use
            # The joints wrapped into their limits nearest ref (finish_scalar's rule): the yaw
            # and the roll once per side; the key: the squared distance to ref, in joint order.
            v0 = sigma * side_psi
            side_ok = True
            if not (lo0 <= v0 and v0 <= hi0 and NEG_PI <= v0 - r0 <= PI):
                v0 = wrap_scalar(v0, lo0, hi0, r0)
                side_ok = lo0 <= v0 <= hi0
            v4 = theta
            if roll_idx is not None and not (lo4 <= v4 <= hi4 and NEG_PI <= v4 - r4 <= PI):
                v4 = wrap_scalar(v4, lo4, hi4, r4)
                side_ok = side_ok and lo4 <= v4 <= hi4
            side_key = 0.0 + (v0 - r0) * (v0 - r0) if sort else 0.0
            # Added last (joint order); 0.0 without a roll adds exactly (a key is never -0.0).
            roll_key = (v4 - r4) * (v4 - r4) if roll_idx is not None else 0.0
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
            q = (v0, v1, v2, v3, v4) if roll_idx is not None else (v0, v1, v2, v3)
            key = side_key + t1 * t1 + t2 * t2 + t3 * t3 + roll_key if sort else 0.0
        else:
            q = (v0, v1, v2, v4) if roll_idx is not None else (v0, v1, v2)
            key = side_key + t1 * t1 + t2 * t2 + roll_key if sort else 0.0
        if within or not lean:
            if not side_checked:
                side_checked = True
                cyw, syw = cpsi[side], spsi[side]
                yaw_plane = mu + side_psi
                if yaw_plane == side_psi:  # mu = 0 (the seed arms)
                    cm, sm = cyw, syw
                else:
                    cm, sm = cos(yaw_plane), sin(yaw_plane)
                ct, st = cos(theta), sin(theta)
                last_f4 = None
            # Forward model at q; its pitch sums (f2, f3, f4) are sign * q of the joints below,
            # the yaw sigma * q[0] (the signs are +-1).
            f3 = phi2 + d32
            a2 = phi2 + g1
            fu = su + l1 * cos(a2)
            fz = sz + l1 * sin(a2)
            if three:
                a3 = f3 + g2
                fu += l2 * cos(a3)
                fz += l2 * sin(a3)
                f4 = f3 + d43
            else:
                f4 = f3
            # Each sine and cosine computed once: of an angle equal to one known before, reused.
            if f4 == phi:
                c4, s4 = cphi[side], sphi[side]
            else:
                c4, s4 = cos(f4), sin(f4)
            fu += c4 * tu - s4 * tz
            fz += s4 * tu + c4 * tz
            if f4 != last_f4:  # the elbow branches of a side share the rotation (bitwise, mostly)
                last_f4 = f4
                alpha = f4 + kappa
                if alpha == f4:
                    ca, sa = c4, s4
                else:
                    ca, sa = cos(alpha), sin(alpha)
                if roll_idx is None:
                    oerr = _rotation_angle_unrolled(m, cyw, syw, ca, sa)
                else:
                    # The angle between E = Rz(yaw) Rx(alpha) Ry(theta) and m (as rotation_error).
                    ssa, csa = syw * sa, cyw * sa
                    e00, e01, e02 = cyw * ct - ssa * st, -syw * ca, cyw * st + ssa * ct
                    e10, e11, e12 = syw * ct + csa * st, cyw * ca, syw * st - csa * ct
                    e20, e21, e22 = -ca * st, sa, ca * ct
                    # rel = E^T m
                    r00 = e00 * m00 + e10 * m10 + e20 * m20
                    r11 = e01 * m01 + e11 * m11 + e21 * m21
                    r22 = e02 * m02 + e12 * m12 + e22 * m22
                    r21 = e02 * m01 + e12 * m11 + e22 * m21
                    r12 = e01 * m02 + e11 * m12 + e21 * m22
                    r02 = e00 * m02 + e10 * m12 + e20 * m22
                    r20 = e02 * m00 + e12 * m10 + e22 * m20
                    r10 = e01 * m00 + e11 * m10 + e21 * m20
                    r01 = e00 * m01 + e10 * m11 + e20 * m21
                    cos_a = 0.5 * (r00 + r11 + r22 - 1.0)
                    w0, w1, w2 = r21 - r12, r02 - r20, r10 - r01
                    sin_a = 0.5 * sqrt(w0 * w0 + w1 * w1 + w2 * w2)
                    # min(1.0, max(-1.0, cos_a)) of a finite cos_a, without the calls.
                    oerr = atan2(sin_a, cos_a if -1.0 <= cos_a <= 1.0 else (1.0 if cos_a > 1.0 else -1.0))
                if offset is not None:
                    # Rz(yaw) Rx(alpha) Ry(theta) offset (plane basis), then in the base frame:
                    # B = [n, e_u, z], n = (sin mu, -cos mu, 0), e_u = (cos mu, sin mu, 0).
                    x, y, z = offset
                    ta = ct * x + st * z
                    tc = -st * x + ct * z
                    tb, oz = ca * y - sa * tc, sa * y + ca * tc
                    ox, oy = cyw * ta - syw * tb, syw * ta + cyw * tb
                    ox, oy = smu * ox + cmu * oy, -cmu * ox + smu * oy
            fx = bx + cm * fu + sm * d
            fy = by + sm * fu - cm * d
            if offset is not None:
                dx, dy, dz = fx + ox - px, fy + oy - py, fz + oz - pz
            else:
                dx, dy, dz = fx - ex, fy - ey, fz - ez
            perr = sqrt(dx * dx + dy * dy + dz * dz)
            if perr > pos_tol or oerr > orient_tol:
                cats[slot] = ORIENT
                continue
        else:  # lean, outside the limits: not verified
            perr = oerr = None
            unchecked = True
        sing = elbow_singular or side_singular
        entries.append((key, slot, q, (within, BRANCHES[slot], sing, perr, oerr)))
        any_within = any_within or within
        singular = singular or sing
    if lean:
        if not any_within:
            return None
        found = nearest_entry(entries, qc)
        # With a candidate unverified, which of them are solutions (the count, the place) is unknown.
        return found._replace(count=None, index=None) if unchecked else found
    return entries, cats, dist, any_within, singular


def _three_pitch(arm: ArmGeometry, elbow, ue, ze, tu, tz, cphi, sphi, cat):
    """Branch candidates (slot, side, a1, e + a1 (link 2's angle), elbow singular) of a 3-pitch arm.

    `elbow`: :attr:`PoseFrame.elbow`; `cphi`, `sphi`: per side, the cosine and sine of the pitch sum.
    """
    l1, l2, su, sz, g2 = arm.l1, arm.l2, arm.su, arm.sz, arm.g2
    reach_hi, reach_lo, l1_sq, l2_sq, l1_l2, has_lengths = elbow
    cats = [cat[0], cat[0], cat[1], cat[1]]
    dist = [0.0] * 4
    cands = []
    for side in (0, 1):
        cp, sp = cphi[side], sphi[side]
        vx = ue[side] - (cp * tu - sp * tz) - su
        vz = ze - (sp * tu + cp * tz) - sz
        dd = hypot(vx, vz)
        dist[2 * side] = dist[2 * side + 1] = dd
        if cat[side] != VALID:
            continue
        if dd > reach_hi:
            cats[2 * side] = cats[2 * side + 1] = BEYOND
            continue
        if dd < reach_lo:
            cats[2 * side] = cats[2 * side + 1] = INSIDE
            continue
        c = (dd * dd - l1_sq - l2_sq) / l1_l2 if has_lengths else 1.0
        c = 1.0 if c > 1.0 else (-1.0 if c < -1.0 else c)
        s = sqrt(1.0 - c * c)
        singular = s < SINGULAR_TOL
        if singular:
            s, c = 0.0, (1.0 if c >= 0 else -1.0)
        e_abs = atan2(s, c)
        base = atan2(vz, vx)
        half = atan2(l2 * s, l1 + l2 * c)
        if side == 0:
            a_first, e_first, a_second, e_second = base + half, -e_abs, base - half, e_abs
        else:
            a_first, e_first, a_second, e_second = base - half, e_abs, base + half, -e_abs
        # Link 2's angle a1 + e (less g2, as solve_core's phi3).
        cands.append((2 * side, side, a_first, a_first + e_first - g2, singular))
        if singular:
            cats[2 * side + 1] = DUPLICATE
        else:
            cands.append((2 * side + 1, side, a_second, a_second + e_second - g2, False))
    return cands, cats, dist


def _two_pitch(arm: ArmGeometry, ue, ze, tu, tz, phis, cat, twisted):
    """Branch candidates of a 2-pitch arm: the rotation fixes the last link, one per side."""
    cos, sin, atan2, hypot = math.cos, math.sin, math.atan2, math.hypot
    l1, su, sz = arm.l1, arm.su, arm.sz
    len_tol = arm.core_len_tol
    l2, g2 = hypot(tu, tz), atan2(tz, tu)
    tol = max(arm.consistency_tol, len_tol)
    cats = [cat[0], cat[0], cat[1], cat[1]]
    dist = [0.0] * 4
    cands = []
    for side in (0, 1):
        de = hypot(ue[side] - su, ze - sz)
        dist[2 * side] = dist[2 * side + 1] = de
        side_cat = cat[side]
        if side_cat == VALID and de > l1 + l2 + len_tol:
            side_cat = BEYOND
        elif side_cat == VALID and de < abs(l1 - l2) - len_tol:
            side_cat = INSIDE
        if side_cat == VALID and twisted[side]:
            side_cat = ORIENT
        phi = phis[side]
        cp, sp = cos(phi), sin(phi)
        ex = ue[side] - (cp * tu - sp * tz) - su
        ez = ze - (sp * tu + cp * tz) - sz
        if side_cat == VALID and abs(hypot(ex, ez) - l1) > tol:
            side_cat = ORIENT
        if side_cat != VALID:
            cats[2 * side] = cats[2 * side + 1] = side_cat
            continue
        a1 = atan2(ez, ex)
        e = wrap_pi(phi + g2 - a1)
        straight = abs(math.sin(e)) < SINGULAR_TOL
        # A stretched or folded elbow: one solution, labelled elbow-up on every path.
        up = straight or (e <= 0.0 if side == 0 else e >= 0.0)
        slot = 2 * side + (0 if up else 1)
        cats[slot ^ 1] = DUPLICATE
        # The last link's angle is the pitch sum: phi3 = phi.
        cands.append((slot, side, a1, phi, straight))
    return cands, cats, dist


def _rotation_angle_unrolled(m, cyw: float, syw: float, ca: float, sa: float) -> float:
    """The angle [rad] between ``E = Rz(yaw) Rx(alpha)`` and ``m`` (as rotation_error), from their cosines and sines.

    :func:`_pose`'s rotation check (``E = Rz(yaw) Rx(alpha) Ry(theta)``) at roll 0, its terms
    in cos 0 = 1 and sin 0 = 0 dropped.

    The dropped terms are zeros added to (or multiplied into) finite sums, which changes no
    result but the sign of an exact zero, which the angle does not see.
    """
    e01, e02 = -syw * ca, syw * sa
    e11, e12 = cyw * ca, -(cyw * sa)
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = m
    # rel = E^T m (E's third row: 0, sin, cos)
    r00 = cyw * m00 + syw * m10
    r11 = e01 * m01 + e11 * m11 + sa * m21
    r22 = e02 * m02 + e12 * m12 + ca * m22
    r21 = e02 * m01 + e12 * m11 + ca * m21
    r12 = e01 * m02 + e11 * m12 + sa * m22
    r02 = cyw * m02 + syw * m12
    r20 = e02 * m00 + e12 * m10 + ca * m20
    r10 = e01 * m00 + e11 * m10 + sa * m20
    r01 = cyw * m01 + syw * m11
    cos_a = 0.5 * (r00 + r11 + r22 - 1.0)
    sin_a = 0.5 * math.sqrt((r21 - r12) ** 2 + (r02 - r20) ** 2 + (r10 - r01) ** 2)
    return math.atan2(sin_a, min(1.0, max(-1.0, cos_a)))
