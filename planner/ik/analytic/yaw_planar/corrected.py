"""Targets on inexact chains (SO-101), in scalar arithmetic: every branch by a few Newton steps on the real arm.

The fast path of :meth:`~planner.ik.analytic.yaw_planar.solver.YawPlanarIK.solve` for chains
whose axes deviate from the family's by round-off: each branch is solved on the ideal geometry
(the closed form of :mod:`~planner.ik.analytic.yaw_planar.core`, both elbows of a side at
once), which misses the target by about the deviation (micro-radians) times the arm's size,
then taken to the real arm's solution by Newton's steps on its product of exponentials
(compiled, four branches per call, 2 steps per call, 3 in the first for position and pitch
targets: :mod:`~planner.ik.analytic.yaw_planar.newton`), the error squaring per step, and
checked by Pinocchio's FK to round-off (:data:`SETTLE`); up to :data:`CALLS` calls. Position and pitch
targets (:func:`solve_corrected_scalar`, 3 pitch joints) solve the tip position and the
branch's approach elevation (the roll is given); full poses (:func:`solve_corrected_pose`)
every joint by Gauss-Newton from the pose closed form of
:mod:`~planner.ik.analytic.yaw_planar.scalar_pose`. The branches start where ``solve_core``
starts them (apart next to a stretched elbow and next to the yaw axis), so they reach the
vectorised path's solutions. The approach pitch a position-only target leaves free is
``q_current``'s, measured on the real arm, where reachable, else the default choice
(:mod:`~planner.ik.analytic.yaw_planar.free_pitch`).

Pose branches whose steps stall far from the target are not solutions on the real arm (the
ideal model accepts an orientation residual up to about its deviation): ORIENT. Targets whose
branches do not settle within those calls (next to the boundary of the real reach: about 0.1 %
of SO-101's random targets), branches that merge, a free pitch without ``q_current``, the yaw
axis itself, poses whose end point lies next to it (where the vectorised path starts the yaws
apart and may find a solution as the other side's branch), or no branch within the limits
(the search) return None: the caller takes the vectorised path.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from planner.geometry.target import Target, pitch_error_scalar
from planner.ik.analytic.geometry import SINGULAR_TOL
from planner.ik.analytic.result import STATUS_SOLVED, AnalyticResult
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.branches import BEYOND, INSIDE, ORIENT, VALID
from planner.ik.analytic.yaw_planar.free_pitch import free_pitch_failure, free_pitch_scalar
from planner.ik.analytic.yaw_planar.newton import STEPS, NewtonKernel
from planner.ik.analytic.yaw_planar.scalar import finish_scalar
from planner.ik.analytic.yaw_planar.scalar_pose import PoseFrame, pose_branches
from planner.model.robot import Robot

__all__ = [
    "CALLS",
    "FIRST_STEPS",
    "RealTip",
    "TipPose",
    "corrected_result",
    "real_tip_pose",
    "solve_corrected_scalar",
    "solve_corrected_pose",
]

PI = math.pi
TWO_PI = 2.0 * math.pi

#: Calls of the compiled Newton steps (:data:`~planner.ik.analytic.yaw_planar.newton.STEPS`
#: each, the first of a position or pitch target :data:`FIRST_STEPS`) at most per target: one
#: settles well-conditioned branches; the others, only while a branch has not settled (started
#: next to a stretched elbow or the yaw axis).
CALLS = 3

#: Newton steps of the first call for position and pitch targets: one more than a later
#: call's, which settles most branches started next to a stretched elbow (1.5-2 % of random
#: SO-101 targets are not settled after two steps, 0.2-0.4 % after three). The compiled single
#: call (:mod:`~planner.ik.analytic.yaw_planar.corrected_single`) takes the same steps.
FIRST_STEPS = 3

#: Position error [m, times the arm's size above 1 m] of a settled branch (1e-13 rad for
#: orientations): round-off, which Newton's steps reach where the branch's Jacobian is regular;
#: at a stretched elbow (the boundary of the reach) they only creep, and the branch is left to
#: the vectorised path.
SETTLE = 1e-14


class RealTip:
    """The real arm's FK (Pinocchio) as lists, and its compiled Newton steps.

    The FK runs on a Pinocchio Data of its own (no input checks); the Newton steps are
    :class:`~planner.ik.analytic.yaw_planar.newton.NewtonKernel`, built on first use. Not
    thread-safe (its buffers serve one call at a time).
    """

    __slots__ = ("_fk", "_rows", "_kernel")

    def __init__(self, robot: Robot) -> None:
        model, fid = robot.model, robot.tip_frame_id
        self._kernel: NewtonKernel | None = None
        if model.nq != robot.dof:  # continuous joints: Pinocchio's (cos, sin) coordinates

            def converted(q: list[float]):
                p, r = robot.tip_pose(np.array(q))
                return p.tolist(), r.tolist()

            def converted_rows(q: list[float]):
                p, r = converted(q)
                return [r[0] + [p[0]], r[1] + [p[1]], r[2] + [p[2]], [0.0, 0.0, 0.0, 1.0]]

            self._fk, self._rows = converted, converted_rows
            return
        data = model.createData()
        forward, update, array = pin.forwardKinematics, pin.updateFramePlacement, np.array

        def direct(q: list[float]):
            forward(model, data, array(q))
            placement = update(model, data, fid)
            return placement.translation.tolist(), placement.rotation.tolist()

        def rows(q: list[float]):
            forward(model, data, array(q))
            return update(model, data, fid).homogeneous.tolist()

        self._fk, self._rows = direct, rows

    def __call__(self, q: list[float]) -> tuple[list[float], list[list[float]]]:
        """Tip position (list, 3) [m] and rotation rows (3 lists of 3) at q (list, dof) [rad]."""
        return self._fk(q)

    def rows(self, q: list[float]) -> list[list[float]]:
        """The tip's homogeneous transform at q as 4 rows (one conversion: the cheapest)."""
        return self._rows(q)

    def kernel(self, arm: ArmGeometry) -> NewtonKernel:
        """The arm's compiled Newton steps."""
        kernel = self._kernel
        if kernel is None or kernel.arm is not arm:
            kernel = self._kernel = NewtonKernel(arm)
        return kernel


#: The real arm's FK for one configuration (a list [rad]): tip position, rotation rows (lists).
TipPose = RealTip


def real_tip_pose(robot: Robot) -> RealTip:
    """The robot's FK (Pinocchio) as lists, with the compiled Newton steps (:class:`RealTip`).

    Args:
        robot: The robot.

    Returns:
        q (list, dof) -> tip position (list, 3) [m], rotation rows (3 lists of 3).
    """
    return RealTip(robot)


def _approach(rot, local) -> tuple[float, float, float]:
    """The approach axis ``rot @ local`` (rotation rows, or a transform's, local axis as lists)."""
    ax_l, ay_l, az_l = local
    (r00, r01, r02, *_), (r10, r11, r12, *_), (r20, r21, r22, *_) = rot[:3]
    return (
        r00 * ax_l + r01 * ay_l + r02 * az_l,
        r10 * ax_l + r11 * ay_l + r12 * az_l,
        r20 * ax_l + r21 * ay_l + r22 * az_l,
    )


def _branch_pitch(arm: ArmGeometry, q, a, front: bool) -> float:
    """The real tip's branch pitch of approach axis `a` (``real_model.true_pitch``): alpha in front, pi - alpha back."""
    ax, ay, az = a
    yaw = arm.mu + arm.sigma * q[0]
    horiz = math.hypot(ax, ay)
    if math.cos(yaw) * ax + math.sin(yaw) * ay < 0.0:
        horiz = -horiz
    alpha = math.atan2(az, horiz)
    return alpha if front else PI - alpha


def _end_vector(arm: ArmGeometry, roll: float) -> tuple[float, float, float]:
    """The in-plane end vector (tu, tz) and lateral offset d at a wrist roll."""
    if arm.tip_on_roll_axis:
        return arm.tip_fixed
    cr, sr = math.cos(roll), math.sin(roll)
    return (
        arm.tip0[0] + arm.tipc[0] * cr + arm.tips[0] * sr,
        arm.tip0[1] + arm.tipc[1] * cr + arm.tips[1] * sr,
        arm.tip0[2] + arm.tipc[2] * cr + arm.tips[2] * sr,
    )


def _yaws(arm: ArmGeometry, px: float, py: float, d: float):
    """The yaws of an end point on the ideal geometry, or None on the yaw axis.

    Returns:
        (psi front, psi back, u, seeded, psi front, psi back, u): the yaws and in-plane
        distance ``solve_core`` starts the branches at (next to the yaw axis, where the yaw
        is ill-conditioned, apart: `seeded`; the vectorised path flags such branches singular,
        so does this one), then the end point's own.
    """
    hx, hy = px - arm.bx, py - arm.by
    under = hx * hx + hy * hy - d * d
    u = math.sqrt(under) if under > 0.0 else 0.0
    if u <= arm.len_tol:
        return None
    ang = math.atan2(hy, hx) - arm.mu
    own = ang - math.atan2(-d, u), ang - math.atan2(-d, -u), u
    u_seed = math.sqrt(2.0 * abs(d) * arm.core_len_tol)
    if u >= u_seed:
        return (*own, False, *own)
    return ang - math.atan2(-d, u_seed), ang - math.atan2(-d, -u_seed), u_seed, True, *own


def _side(arm: ArmGeometry, psi: float, ue: float, pz: float, alpha: float, tu, tz, roll, front: bool):
    """A side's two branches of the ideal closed form: (q elbow-up, q elbow-down, category, wrist distance).

    The q are None unless the category is VALID; `alpha` is the side's in-plane approach angle.
    Elbow-up is e <= 0 in front, e >= 0 at the back (solve_core's slots 0 and 3).
    """
    cos, sin, atan2 = math.cos, math.sin, math.atan2
    l1, l2, g1, g2 = arm.l1, arm.l2, arm.g1, arm.g2
    phi = alpha - arm.beta
    cp, sp = cos(phi), sin(phi)
    vx = ue - (cp * tu - sp * tz) - arm.su
    vz = pz - (sp * tu + cp * tz) - arm.sz
    dd = math.hypot(vx, vz)
    len_tol = arm.core_len_tol
    if dd > l1 + l2 + len_tol:
        return None, None, BEYOND, dd
    if dd < abs(l1 - l2) - len_tol:
        return None, None, INSIDE, dd
    c = (dd * dd - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
    c = 1.0 if c > 1.0 else (-1.0 if c < -1.0 else c)
    s = math.sqrt(1.0 - c * c)
    near = math.sin(arm.elbow_seed)
    if s < near:
        # Next to a stretched or folded elbow the real arm's two elbow solutions lie about
        # sqrt(deviation) apart where the ideal model sees one: start them apart (solve_core's seeds).
        s = near
        c = math.cos(arm.elbow_seed) if c > 0.0 else -math.cos(arm.elbow_seed)
    e_abs = atan2(s, c)
    base = atan2(vz, vx)
    half = atan2(l2 * s, l1 + l2 * c)
    signs, idx, roll_idx = arm.signs, arm.pitch_idx, arm.roll_idx
    q0 = arm.sigma * psi
    out = []
    for a1, e in (
        ((base + half, -e_abs), (base - half, e_abs)) if ue >= 0.0 else ((base - half, e_abs), (base + half, -e_abs))
    ):
        phi2 = a1 - g1
        phi3 = a1 + e - g2
        q = [0.0] * arm.dof
        q[0] = q0
        q[idx[0]] = signs[0] * phi2
        q[idx[1]] = signs[1] * (phi3 - phi2)
        q[idx[2]] = signs[2] * (phi - phi3)
        if roll_idx is not None:
            q[roll_idx] = roll
        out.append(q)
    return out[0], out[1], VALID, dd


def solve_corrected_scalar(
    arm: ArmGeometry, tip_pose: TipPose, target: Target, qc: list[float] | None
) -> AnalyticResult | None:
    """Every branch of a position or pitch target on an inexact 3-pitch chain, or None (see the module).

    Args:
        arm: The geometry (inexact, 3 pitch joints).
        tip_pose: The real arm's FK: q (dof,) -> tip position (3,), rotation (3, 3).
        target: A position or position + pitch target.
        qc: The current configuration, or None.

    Returns:
        The result when every branch settles and one lies within the limits, else None.
    """
    if arm.n_pitch != 3 or target.rotation is not None:
        return None
    pitch = target.pitch
    if pitch is None and qc is None:
        return None
    local = arm.approach_local.tolist()
    px, py, pz = target.position.tolist()
    roll = qc[arm.roll_idx] if arm.has_roll and qc is not None else 0.0
    if arm.has_roll and not arm.lower[arm.roll_idx] <= roll <= arm.upper[arm.roll_idx]:
        return None
    tu, tz, d = _end_vector(arm, roll)
    yaws = _yaws(arm, px, py, d)
    if yaws is None:
        return None
    psi_f, psi_b, u, seeded, end_f, end_b, u_end = yaws
    # The branch pitch goal per side (core: world_pitch; front alpha, back pi - alpha).
    goals = []
    unreached = [None, None]  # per side, the category where no pitch reaches
    if pitch is not None:
        # The side from the yaws the end point itself gives (solve_core: not the seeded ones,
        # which next to the yaw axis turn the plane enough to flip it).
        for psi in (end_f, end_b):
            yaw = psi + arm.mu
            outward = math.cos(yaw) * px + math.sin(yaw) * py >= 0.0
            alpha = pitch if outward else PI - pitch
            goals.append(alpha)
        goals[1] = PI - goals[1]
    else:
        # q_current's approach, measured on the real arm as a front branch (free_pitch.current_alpha).
        alpha_c = _branch_pitch(arm, qc, _approach(tip_pose.rows(qc), local), True)
        rmin = max(abs(arm.l1 - arm.l2), arm.rmin_lim) - arm.core_len_tol
        rmax = min(arm.l1 + arm.l2, arm.rmax_lim) + arm.core_len_tol
        for side, (psi, ue) in enumerate(((psi_f, u), (psi_b, -u))):
            alpha = alpha_c if math.cos(psi - arm.sigma * qc[0]) >= 0.0 else PI - alpha_c
            phi = alpha - arm.beta
            cp, sp = math.cos(phi), math.sin(phi)
            dd = math.hypot(ue - (cp * tu - sp * tz) - arm.su, pz - (sp * tu + cp * tz) - arm.sz)
            if not rmin <= dd <= rmax:
                # Out of reach at q_current's pitch: the default choice (free_pitch.free_pitch_array).
                lt = math.hypot(tu, tz)
                phi = free_pitch_scalar(arm, psi, ue, pz, tu, tz, lt, math.atan2(tz, tu), None)
                if phi is None:
                    unreached[side] = free_pitch_failure(arm, ue, pz, lt)
                    phi = 0.0
                alpha = arm.beta + phi
            goals.append(alpha if side == 0 else PI - alpha)
    cats = [VALID] * 4
    dist = [math.nan] * 4
    slots, starts, aims = [], [], []
    for side in (0, 1):
        if unreached[side] is not None:
            cats[2 * side] = cats[2 * side + 1] = unreached[side]
            continue
        alpha = goals[0] if side == 0 else PI - goals[1]
        up, down, cat, dd = _side(
            arm, psi_f if side == 0 else psi_b, u if side == 0 else -u, pz, alpha, tu, tz, roll, side == 0
        )
        if up is None and seeded:
            # The seeds moved the wrist out of reach (the vectorised path stops there): start
            # at the end point's own yaw instead.
            up, down, cat, dd = _side(
                arm, end_f if side == 0 else end_b, u_end if side == 0 else -u_end, pz, alpha, tu, tz, roll, side == 0
            )
        # Slots: front-up, front-down, back-up, back-down.
        dist[2 * side] = dist[2 * side + 1] = dd
        if up is None:
            cats[2 * side] = cats[2 * side + 1] = cat
            continue
        slots += [2 * side, 2 * side + 1]
        starts += [up, down]
        aims += [alpha, alpha]
    sols = []
    if slots:
        settled = _settle_pitch(arm, tip_pose, px, py, pz, slots, starts, aims, local)
        if settled is None:
            return None
        if pitch is not None:
            cos_p, sin_p = math.cos(pitch), math.sin(pitch)
            elevation = math.atan2(sin_p, abs(cos_p))
        axis_tol = SINGULAR_TOL * arm.scale
        for slot, (q, perr, a) in zip(slots, settled):
            oerr = None
            if pitch is not None:
                oerr = pitch_error_scalar(a[0], a[1], a[2], px, py, cos_p, sin_p, elevation)
                if oerr > 1e-9:
                    return None
            sols.append((slot, q, seeded or u_end < axis_tol, perr, oerr))
    # Branches that converged onto one solution (refine's twins): the vectorised path.
    if _twins(arm, sols):
        return None
    result = finish_scalar(arm, sols, cats, dist, qc, target)
    return result if result.status == STATUS_SOLVED else None


def _settle_pitch(arm: ArmGeometry, tip_pose: RealTip, px, py, pz, slots, starts, aims, local):
    """The branches' Newton steps on the real model, each verified by its FK (Pinocchio).

    Returns:
        Per branch (q, position error [m], approach axis), or None when a branch did not settle
        to round-off (:data:`SETTLE`) within :data:`CALLS` calls (the ideal closed form's
        branches exist on the real arm but next to the boundary of the reach or the yaw axis,
        where the steps need not converge: the vectorised path decides).
    """
    dof = arm.dof
    kernel = tip_pose.kernel(arm)
    pos_tol = SETTLE * max(1.0, arm.scale)
    k = len(slots)
    flat = [v for i in range(4) for v in starts[i if i < k else 0]]
    aim4 = [aims[i if i < k else 0] for i in range(4)]
    target = [px, py, pz]
    lx, ly, lz = local
    rows = tip_pose.rows
    out = [None] * k
    pending = range(k)
    for call in range(CALLS):
        flat, misses = kernel.pitch(flat, target, aim4, FIRST_STEPS if call == 0 else STEPS)
        left = []
        for i in pending:
            q = flat[i * dof : (i + 1) * dof]
            (r00, r01, r02, x), (r10, r11, r12, y), (r20, r21, r22, z), _ = rows(q)
            dx, dy, dz = px - x, py - y, pz - z
            perr = math.sqrt(dx * dx + dy * dy + dz * dz)
            # The position by Pinocchio's FK; the branch's elevation (not the target's, for a
            # position target) by the compiled model's.
            if perr <= pos_tol and abs(misses[i]) <= 1e-13:
                a = (r00 * lx + r01 * ly + r02 * lz, r10 * lx + r11 * ly + r12 * lz, r20 * lx + r21 * ly + r22 * lz)
                out[i] = (q, perr, a)
            else:
                left.append(i)
        if not left:
            return out
        pending = left
    return None


def _angle(rot_a: list[list[float]], rot_b: list[list[float]]) -> float:
    """Angle [rad] of the rotation between two orientations (``rotation_error``), given by rows.

    The first may have 4 columns (a homogeneous transform's rows); the fourth is ignored.
    """
    (a00, a01, a02, *_), (a10, a11, a12, *_), (a20, a21, a22, *_) = rot_a[:3]
    (b00, b01, b02), (b10, b11, b12), (b20, b21, b22) = rot_b
    # rel = A^T B: its trace and the differences of its off-diagonal pairs.
    trace = a00 * b00 + a10 * b10 + a20 * b20 + a01 * b01 + a11 * b11 + a21 * b21 + a02 * b02 + a12 * b12 + a22 * b22
    s0 = (a01 * b02 + a11 * b12 + a21 * b22) - (a02 * b01 + a12 * b11 + a22 * b21)
    s1 = (a02 * b00 + a12 * b10 + a22 * b20) - (a00 * b02 + a10 * b12 + a20 * b22)
    s2 = (a00 * b01 + a10 * b11 + a20 * b21) - (a01 * b00 + a11 * b10 + a21 * b20)
    cos_a = 0.5 * (trace - 1.0)
    sin_a = 0.5 * math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    return math.atan2(sin_a, min(1.0, max(-1.0, cos_a)))


def solve_corrected_pose(
    arm: ArmGeometry, frame: PoseFrame, tip_pose: TipPose, target: Target, qc: list[float] | None
) -> AnalyticResult | None:
    """Every branch of a full-pose target on an inexact chain, or None (see the module).

    Each branch of the ideal closed form (:func:`~planner.ik.analytic.yaw_planar.scalar_pose.pose_branches`)
    is taken to the real model's solution by Gauss-Newton steps on it (compiled,
    :mod:`~planner.ik.analytic.yaw_planar.newton`). Branches whose steps stall far from the
    target are not solutions on the real arm (the ideal model accepts an orientation residual
    up to about the chain's deviation): categorised ORIENT, as the vectorised path does.

    Args:
        arm: The geometry (inexact).
        frame: Its plane-basis constants.
        tip_pose: The real arm's FK (:func:`real_tip_pose`).
        target: A full-pose target.
        qc: The current configuration, or None.

    Returns:
        The result when every branch settles and one lies within the limits, else None.
    """
    pos = target.position
    rot = target.rotation
    position = pos.tolist()
    if _seeded_pose(arm, position, rot):
        # Next to the yaw axis the vectorised path starts the yaws apart and may find a
        # solution as the other side's branch: it answers there.
        return None
    sols, cats, dist = pose_branches(arm, frame, position, rot, qc)
    # Next to a stretched or folded elbow the vectorised path starts the elbow branches apart
    # (solve_core's seeds): take it there.
    near_elbow = math.sin(arm.elbow_seed)
    for _, q, singular, _, _ in sols:
        e = arm.signs[1] * q[arm.pitch_idx[1]] + (arm.g2 if arm.n_pitch == 3 else 0.0) - arm.g1
        if singular or (arm.n_pitch == 3 and abs(math.sin(e)) < 2.0 * near_elbow):
            return None
    if not sols:
        result = finish_scalar(arm, sols, cats, dist, qc, target)
        return result if result.status == STATUS_SOLVED else None
    dof = arm.dof
    kernel = tip_pose.kernel(arm)
    pos_tol = SETTLE * max(1.0, arm.scale)
    k = len(sols)
    flat = [v for i in range(4) for v in sols[i if i < k else 0][1]]
    px, py, pz = position
    rot_rows = rot.tolist()
    rot_columns = rot.T.reshape(9).tolist()
    rows = tip_pose.rows
    found = [None] * k
    last = [math.inf] * k
    pending = range(k)
    for _ in range(CALLS):
        flat = kernel.pose(flat, position, rot_columns)
        left = []
        for i in pending:
            slot, _, singular, _, _ = sols[i]
            q = flat[i * dof : (i + 1) * dof]
            r = rows(q)
            dx, dy, dz = px - r[0][3], py - r[1][3], pz - r[2][3]
            perr = math.sqrt(dx * dx + dy * dy + dz * dz)
            oerr = _angle(r, rot_rows)
            error = perr / arm.scale + oerr
            if perr <= pos_tol and oerr <= 1e-13:
                found[i] = (slot, q, singular, perr, oerr)
            elif error > 1e-9 and error >= 0.5 * last[i]:
                # The steps stalled far from the target: no solution next to the ideal one
                # (its orientation residual, accepted up to the chain's deviation, is real).
                cats[slot] = ORIENT
            else:
                last[i] = error
                left.append(i)
        if not left:
            break
        pending = left
    else:
        return None
    out = [f for f in found if f is not None]
    if _twins(arm, out):
        return None
    result = finish_scalar(arm, out, cats, dist, qc, target)
    return result if result.status == STATUS_SOLVED else None


def corrected_result(
    arm: ArmGeometry, tip_pose: TipPose, target: Target, qc: list[float] | None, out: list[float]
) -> AnalyticResult | None:
    """The result of :func:`solve_corrected_scalar` or :func:`solve_corrected_pose` from the compiled branches.

    `out` is the output of the compiled corrected closed form with every branch
    (:class:`~planner.ik.analytic.yaw_planar.corrected_single.CorrectedKernel`: sure, the
    singular flag, 4 valid flags, 4 x dof joint values after the Newton steps). Each branch is
    verified here as those functions verify theirs (Pinocchio's FK: the position to
    :data:`SETTLE`, the pitch or the rotation), then wrapped and sorted by
    :func:`~planner.ik.analytic.yaw_planar.scalar.finish_scalar`.

    Returns:
        The result, or None where the kernel is not sure, a branch misses by Pinocchio's FK, or
        no branch lies within the limits (the caller takes the Python path).
    """
    if not out[0]:
        return None
    dof = arm.dof
    position = target.position.tolist()
    px, py, pz = position
    rot = target.rotation
    pitch = target.pitch
    if rot is not None:
        rot_rows = rot.tolist()
        if _seeded_pose(arm, position, rot):
            return None  # solve_corrected_pose leaves it to the vectorised path
        singular = False
    else:
        singular = out[1] != 0.0
        local = arm.approach_local.tolist()
        if pitch is not None:
            cos_p, sin_p = math.cos(pitch), math.sin(pitch)
            elevation = math.atan2(sin_p, abs(cos_p))
    pos_tol = SETTLE * max(1.0, arm.scale)
    rows = tip_pose.rows
    sols = []
    for slot in range(4):
        if not out[2 + slot]:
            continue
        q = out[6 + slot * dof : 6 + (slot + 1) * dof]
        r = rows(q)
        dx, dy, dz = px - r[0][3], py - r[1][3], pz - r[2][3]
        perr = math.sqrt(dx * dx + dy * dy + dz * dz)
        if perr > pos_tol:
            return None
        oerr = None
        if rot is not None:
            oerr = _angle(r, rot_rows)
            if oerr > 1e-13:
                return None
        elif pitch is not None:
            a = _approach(r, local)
            oerr = pitch_error_scalar(a[0], a[1], a[2], px, py, cos_p, sin_p, elevation)
            if oerr > 1e-9:
                return None
        sols.append((slot, q, singular, perr, oerr))
    if not sols:
        return None
    result = finish_scalar(arm, sols, [VALID] * 4, [math.nan] * 4, qc, target)
    return result if result.status == STATUS_SOLVED else None


def _seeded_pose(arm: ArmGeometry, position: list[float], rot: np.ndarray) -> bool:
    """Whether ``solve_core`` starts this pose's yaws apart next to the yaw axis (and flags them singular)."""
    ex, ey = position[0], position[1]
    if arm.has_roll:
        shift = rot @ arm.centre_to_tip_local
        ex, ey = ex - float(shift[0]), ey - float(shift[1])
        d = arm.centre[2]
    else:
        d = arm.tip_fixed[2]
    hx, hy = ex - arm.bx, ey - arm.by
    rho2 = hx * hx + hy * hy
    if rho2 <= arm.len_tol * arm.len_tol and abs(d) <= arm.len_tol:
        return False  # free: flagged singular by the closed form itself
    under = rho2 - d * d
    if under < -2.0 * abs(d) * arm.core_len_tol:
        return False  # the cylinder
    return math.sqrt(max(under, 0.0)) < math.sqrt(2.0 * abs(d) * arm.core_len_tol)


def _twins(arm: ArmGeometry, sols) -> bool:
    """Whether two branches converged onto one solution (refine's twins: 1e-7 rad on every joint)."""
    shoulder = arm.pitch_idx[0]
    near = TWO_PI - 1e-7
    n = len(sols)
    for i in range(n):
        qi = sols[i][1]
        for j in range(i + 1, n):
            qj = sols[j][1]
            if 1e-7 <= (qi[shoulder] - qj[shoulder]) % TWO_PI <= near:
                continue  # the usual case: the shoulders differ
            if all(not 1e-7 <= (a - b) % TWO_PI <= near for a, b in zip(qi, qj)):
                return True
    return False
