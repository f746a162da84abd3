"""The answer of :func:`planner.solve_ik` on inexact chains (SO-101) by one compiled call.

:meth:`~planner.ik.analytic.yaw_planar.solver.YawPlanarIK.nearest` needs one configuration: the
solution within the limits nearest the seed. On chains whose axes deviate from the family's by
round-off, :mod:`~planner.ik.analytic.yaw_planar.corrected` finds every branch on the ideal
geometry, takes each to the real arm's solution by the compiled Newton steps of
:mod:`~planner.ik.analytic.yaw_planar.newton` and checks it by Pinocchio's FK. Here the same
sequence is one CasADi SX function of one target, compiled to C: the ideal branches (the
formulas of ``solve_corrected_scalar`` for position and pitch targets, with q_current's
approach or the default one of
:func:`~planner.ik.analytic.yaw_planar.free_pitch.free_pitch_scalar`, and of
:func:`~planner.ik.analytic.yaw_planar.scalar_pose.pose_branches` for poses), the Newton steps
of the Python path's first call (:data:`STEPS`; for poses its first two calls, two steps each,
a branch settled after the first kept there, whose errors decide which branches stall) on the
product of exponentials of the real screws for all four branches, the settle check on that
model, the wrapping into the limits and the pick of
:func:`~planner.ik.analytic.nearest.nearest_entry`.

The output's first entry says whether the answer is the Python path's for sure (for poses
next to a stretched elbow, which that path leaves to the vectorised one, the vectorised path's:
the same starts, apart, and steps); it is 0 (the caller takes the Python path) wherever that
path would not answer from its Newton steps: a branch not settled after this call's (or
settled within a factor :data:`MARGIN` of the threshold, where the two FK codes could
disagree), next to the yaw axis (the seeded yaws), the roll out of its range, merged branches,
a pose's end point next to the yaw axis, a branch started next to a stretched elbow that
stalls, no branch within the limits (the search), and two branches within the limits at
exactly the same distance. Newton's steps converge to the same root from starts that differ by
round-off, so the joint values agree with the Python path's to round-off; the caller verifies
every answer by Pinocchio's FK.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from planner.geometry.target import RADIAL_EPS
from planner.ik.analytic.geometry import SINGULAR_TOL
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.compiled import nearest_branch_sx, pick_branch_sx, wrap_sx, wrapped_sx
from planner.ik.analytic.yaw_planar.corrected import FIRST_STEPS, SETTLE
from planner.ik.analytic.yaw_planar.newton import FLAGS, arm_parameters, pitch_kernel, pose_kernel, tip_fk_sx
from planner.ik.analytic.yaw_planar.scalar_pose import PoseFrame
from planner.ik.numeric.codegen import compile_function

__all__ = ["MARGIN", "STEPS", "CorrectedKernel", "corrected_kernel", "corrected_supported"]

PI = math.pi
#: A branch counts as settled only this far inside the Python path's thresholds (its check is
#: Pinocchio's FK, this one the product of exponentials: they differ by round-off).
MARGIN = 0.5
#: Branches closer than this on every joint [rad] may be the Python path's twins (1e-7): left to it.
TWIN = 2e-7
#: Newton steps of position and pitch targets: the Python path's first call's.
STEPS = FIRST_STEPS
#: A pose branch counts as settled after two steps only this far inside the Python path's
#: thresholds; up to their inverse outside them, the Python path decides.
EARLY = 0.8
#: A pose branch's steps stalled for sure where its error after four steps is at least this
#: share of its error after two (the Python path's test: 0.5).
STALL = 0.75


def corrected_supported(arm: ArmGeometry, joint_kinds) -> bool:
    """Whether :class:`CorrectedKernel` covers this arm: inexact, yaw + 3 pitch joints + roll, revolute."""
    return (
        not arm.exact
        and arm.n_pitch == 3
        and arm.has_roll
        and arm.dof == 5
        and tuple(arm.pitch_idx) == (1, 2, 3)
        and arm.roll_idx == 4
        and all(kind == "revolute" for kind in joint_kinds)
    )


def _if(cond, a, b):
    return ca.if_else(cond, a, b)


def _and(*conds):
    out = conds[0]
    for c in conds[1:]:
        out = ca.logic_and(out, c)
    return out


def _or(*conds):
    out = conds[0]
    for c in conds[1:]:
        out = ca.logic_or(out, c)
    return out


def _hypot(x, y):
    return ca.hypot(x, y)


def _clamp(x, lo: float, hi: float):
    return _if(x > hi, hi, _if(x < lo, lo, x))


def _end_vector(arm: ArmGeometry, roll):
    """The in-plane end vector (tu, tz) and lateral offset d at a wrist roll (corrected._end_vector)."""
    if arm.tip_on_roll_axis:
        return tuple(float(v) for v in arm.tip_fixed)
    if isinstance(roll, float):
        cr, sr = math.cos(roll), math.sin(roll)
    else:
        cr, sr = ca.cos(roll), ca.sin(roll)
    return tuple(float(arm.tip0[i]) + float(arm.tipc[i]) * cr + float(arm.tips[i]) * sr for i in range(3))


def _free_pitch_default(arm: ArmGeometry, ue, ze, tu, tz, lt, gt):
    """:func:`~planner.ik.analytic.yaw_planar.free_pitch.free_pitch_scalar` without q_current: (phi, found)."""
    su, sz = arm.su, arm.sz
    rmin = max(abs(arm.l1 - arm.l2), arm.rmin_lim)
    rmax = min(arm.l1 + arm.l2, arm.rmax_lim)
    ex, ez = ue - su, ze - sz
    de = _hypot(ex, ez)
    lo = _if(ca.fabs(de - lt) >= rmin, ca.fabs(de - lt), rmin)
    hi = _if(de + lt <= rmax, de + lt, rmax)
    found = ca.logic_not(_or(lo > hi + arm.len_tol, de == 0.0))
    safe = _if(de == 0.0, 1.0, de)
    a = (lo * lo - lt * lt + safe * safe) / (2.0 * safe)
    under = lo * lo - a * a
    h = _if(ca.fabs(de - lt) >= rmin, 0.0, ca.sqrt(_if(under > 0.0, under, 0.0)))
    ux, uz = ex / safe, ez / safe
    options = []
    for sgn in (1.0, -1.0):
        wx = su + a * ux - sgn * h * uz
        wz = sz + a * uz + sgn * h * ux
        phi = ca.atan2(ze - wz, ue - wx) - gt
        options.append((phi, ca.sin(arm.beta + phi)))
    (phi1, lift1), (phi2, lift2) = options
    return _if(lift2 < lift1 - 1e-15, phi2, phi1), found


def _side(arm: ArmGeometry, psi, ue, pz, alpha, tu, tz, roll, front: bool):
    """corrected._side: a side's two starts (elbow-up first) and whether the wrist is within reach."""
    cos, sin, atan2 = ca.cos, ca.sin, ca.atan2
    l1, l2, g1, g2 = arm.l1, arm.l2, arm.g1, arm.g2
    phi = alpha - arm.beta
    cp, sp = cos(phi), sin(phi)
    vx = ue - (cp * tu - sp * tz) - arm.su
    vz = pz - (sp * tu + cp * tz) - arm.sz
    dd = _hypot(vx, vz)
    reach = _and(dd <= l1 + l2 + arm.core_len_tol, dd >= abs(l1 - l2) - arm.core_len_tol)
    c = _clamp((dd * dd - l1 * l1 - l2 * l2) / (2.0 * l1 * l2), -1.0, 1.0)
    s = ca.sqrt(1.0 - c * c)
    near = math.sin(arm.elbow_seed)
    small = s < near
    c = _if(small, _if(c > 0.0, math.cos(arm.elbow_seed), -math.cos(arm.elbow_seed)), c)
    s = _if(small, near, s)
    e_abs = atan2(s, c)
    base = atan2(vz, vx)
    half = atan2(l2 * s, l1 + l2 * c)
    pairs = ((base + half, -e_abs), (base - half, e_abs)) if front else ((base - half, e_abs), (base + half, -e_abs))
    signs = arm.signs
    out = []
    for a1, e in pairs:
        phi2 = a1 - g1
        phi3 = a1 + e - g2
        out.append([arm.sigma * psi, signs[0] * phi2, signs[1] * (phi3 - phi2), signs[2] * (phi - phi3), roll])
    return out, reach


def _pitch_starts(arm: ArmGeometry, p, pit, qc, prm):
    """The ideal branches of a position or pitch target (solve_corrected_scalar's).

    Returns:
        (starts: 4 joint lists, aims: 4 elevation goals, valid: 4 flags, ok: whether the Python
        path's preconditions hold, u: the end point's distance from the yaw axis [m]).
    """
    px, py, pz = p
    ok = ca.SX(1)
    ri = arm.roll_idx
    if qc is not None:
        roll = qc[ri]
        ok = _and(ok, roll >= float(arm.lower[ri]), roll <= float(arm.upper[ri]))
    else:
        roll = 0.0
    tu, tz, d = _end_vector(arm, roll)
    hx, hy = px - arm.bx, py - arm.by
    under = hx * hx + hy * hy - d * d
    u = ca.sqrt(_if(under > 0.0, under, 0.0))
    ok = _and(ok, u > arm.len_tol)
    ang = ca.atan2(hy, hx) - arm.mu
    psi_f = ang - ca.atan2(-d, u)
    psi_b = ang - ca.atan2(-d, -u)
    # Next to the yaw axis the Python path starts the yaws apart (seeded): left to it.
    ok = _and(ok, u >= ca.sqrt(2.0 * abs(d) * arm.core_len_tol))
    reached = [ca.SX(1), ca.SX(1)]
    if pit is not None:
        goals = []
        for psi in (psi_f, psi_b):
            yaw = psi + arm.mu
            outward = ca.cos(yaw) * px + ca.sin(yaw) * py >= 0.0
            goals.append(_if(outward, pit, PI - pit))
        goals[1] = PI - goals[1]
    else:
        _, rot_c = tip_fk_sx(ca.vertcat(*qc), prm, arm.dof)
        lx, ly, lz = (float(v) for v in arm.approach_local)
        ax, ay, az = (rot_c[i, 0] * lx + rot_c[i, 1] * ly + rot_c[i, 2] * lz for i in range(3))
        yaw = arm.mu + arm.sigma * qc[0]
        horiz = _hypot(ax, ay)
        horiz = _if(ca.cos(yaw) * ax + ca.sin(yaw) * ay < 0.0, -horiz, horiz)
        alpha_c = ca.atan2(az, horiz)
        rmin = max(abs(arm.l1 - arm.l2), arm.rmin_lim) - arm.core_len_tol
        rmax = min(arm.l1 + arm.l2, arm.rmax_lim) + arm.core_len_tol
        lt, gt = _hypot(tu, tz), ca.atan2(tz, tu)
        goals = []
        for side, (psi, ue) in enumerate(((psi_f, u), (psi_b, -u))):
            alpha = _if(ca.cos(psi - arm.sigma * qc[0]) >= 0.0, alpha_c, PI - alpha_c)
            phi = alpha - arm.beta
            cp, sp = ca.cos(phi), ca.sin(phi)
            dd = _hypot(ue - (cp * tu - sp * tz) - arm.su, pz - (sp * tu + cp * tz) - arm.sz)
            inside = _and(dd >= rmin, dd <= rmax)
            phi_default, found = _free_pitch_default(arm, ue, pz, tu, tz, lt, gt)
            reached[side] = ca.logic_or(inside, found)
            alpha = _if(inside, alpha, arm.beta + phi_default)
            goals.append(alpha if side == 0 else PI - alpha)
    starts, aims, valid = [], [], []
    for side in (0, 1):
        alpha = goals[0] if side == 0 else PI - goals[1]
        branches, reach = _side(
            arm, psi_f if side == 0 else psi_b, u if side == 0 else -u, pz, alpha, tu, tz, roll, side == 0
        )
        starts += branches
        aims += [alpha, alpha]
        valid += [ca.logic_and(reached[side], reach)] * 2
    return starts, aims, valid, ok, u


def _pose_starts(arm: ArmGeometry, frame: PoseFrame, p, rflat, qc):
    """The ideal branches of a pose (pose_branches' with a roll and 3 pitch joints).

    Returns:
        (starts, valid, ok, apart) as :func:`_pitch_starts` (without aims): ok is 0 where a valid
        branch lies next to the yaw axis (flagged singular); apart, whether a valid side's elbow
        branches start apart next to a stretched or folded elbow (where solve_corrected_pose
        declines and the vectorised path answers).
    """
    px, py, pz = p
    lin = np.asarray(frame.linear)
    flat = []
    for row in lin:
        terms = [float(w) * rflat[k] for k, w in enumerate(row) if w != 0.0]
        flat.append(sum(terms[1:], terms[0]) if terms else ca.SX(0.0))
    m = (flat[0:3], flat[3:6], flat[6:9])
    tu, tz, d = (float(v) for v in arm.centre)
    if frame.shift_local is not None:
        ex, ey, ez = px - flat[9], py - flat[10], pz - flat[11]
    else:
        ex, ey, ez = px, py, pz
    hx, hy = ex - arm.bx, ey - arm.by
    rho2 = hx * hx + hy * hy
    axis_tol = arm.len_tol
    free = _and(rho2 <= axis_tol * axis_tol, ca.SX(float(abs(d) <= axis_tol)))
    len_tol = arm.core_len_tol
    under = rho2 - d * d
    cylinder = _and(ca.logic_not(free), under < -2.0 * abs(d) * len_tol)
    u_pos = ca.sqrt(_if(under > 0.0, under, 0.0))
    u = _if(free, 0.0, u_pos)
    mu = arm.mu
    w1, w2 = m[0][1], m[1][1]
    horiz = _hypot(w1, w2)
    psi_a = ca.atan2(-w1, w2)
    use = _and(horiz > 1e-9, horiz * arm.scale >= u)
    # From the position (the roll axis next to vertical).
    ang = ca.atan2(hy, hx)
    psi_p0 = _if(free, arm.sigma * qc[0] if qc is not None else 0.0, ang - mu - ca.atan2(-d, u_pos))
    psi_p1 = ang - mu - ca.atan2(-d, -u_pos)
    valid_p = [ca.logic_not(cylinder), _and(ca.logic_not(cylinder), ca.logic_not(_or(free, u_pos == 0.0)))]
    # From the rotation.
    cy, sy = ca.cos(mu + psi_a), ca.sin(mu + psi_a)
    ue_a = hx * cy + hy * sy
    lat_a = hx * sy - hy * cy
    forward = ue_a >= 0.0
    tol = max(arm.consistency_tol, arm.core_len_tol)
    in_plane = ca.fabs(lat_a - d) <= tol
    in_back = ca.fabs(-lat_a - d) <= tol
    front = _if(forward, psi_a, psi_a + PI)
    psi = [_if(use, front, psi_p0), _if(use, front + PI, psi_p1)]
    ue = [_if(use, ca.fabs(ue_a), u), _if(use, -ca.fabs(ue_a), -u)]
    valid_side = [
        _if(use, _and(ca.logic_not(cylinder), _if(forward, in_plane, in_back)), valid_p[0]),
        _if(use, _and(ca.logic_not(cylinder), _if(forward, in_back, in_plane)), valid_p[1]),
    ]
    kappa, ck, sk = frame.kappa, frame.cos_kappa, frame.sin_kappa
    col0 = (m[0][0], m[1][0], m[2][0])
    col1 = (m[0][1], m[1][1], m[2][1])
    reach_hi, reach_lo, l1_sq, l2_sq, l1_l2, _ = frame.elbow
    l1, l2, g1, g2, su, sz = arm.l1, arm.l2, arm.g1, arm.g2, arm.su, arm.sz
    signs = arm.signs
    near_elbow = math.sin(arm.elbow_seed)
    # Next to the yaw axis (corrected._seeded_pose; a little wider, for round-off) the Python path
    # leaves the pose to the vectorised one.
    seeded = _and(ca.logic_not(cylinder), u_pos < (1.0 + 1e-9) * math.sqrt(2.0 * abs(d) * len_tol))
    ok = _and(ca.logic_not(free), ca.logic_not(seeded))
    starts, valid = [], []
    apart = ca.SX(0)
    for side in (0, 1):
        cp_, sp_ = ca.cos(psi[side]), ca.sin(psi[side])
        x1 = cp_ * col1[0] + sp_ * col1[1]
        x2 = -sp_ * col1[0] + cp_ * col1[1]
        x3 = col1[2]
        phi = ca.atan2(x3, x2) - kappa
        twisted = ca.asin(_if(ca.fabs(x1) < 1.0, ca.fabs(x1), 1.0)) > arm.orient_tol
        v1 = cp_ * col0[0] + sp_ * col0[1]
        v2 = -sp_ * col0[0] + cp_ * col0[1]
        v3 = col0[2]
        cf, sf = ca.cos(phi), ca.sin(phi)
        b2 = cf * v2 + sf * v3
        b3 = -sf * v2 + cf * v3
        roll = ca.atan2(sk * b2 - ck * b3, v1)
        vx = ue[side] - (cf * tu - sf * tz) - su
        vz = ez - (sf * tu + cf * tz) - sz
        dd = _hypot(vx, vz)
        good = _and(valid_side[side], ca.logic_not(twisted), dd <= reach_hi, dd >= reach_lo)
        c = _clamp((dd * dd - l1_sq - l2_sq) / l1_l2, -1.0, 1.0)
        s = ca.sqrt(1.0 - c * c)
        # Next to a stretched or folded elbow the two elbow branches start apart, as solve_core
        # starts them on inexact chains (the vectorised path, which answers there: the Python
        # path declines such poses).
        small = s < near_elbow
        c = _if(small, _if(c > 0.0, math.cos(arm.elbow_seed), -math.cos(arm.elbow_seed)), c)
        s = _if(small, near_elbow, s)
        apart = _or(apart, _and(good, small))
        e_abs = ca.atan2(s, c)
        base = ca.atan2(vz, vx)
        half = ca.atan2(l2 * s, l1 + l2 * c)
        # Next to the yaw axis (flagged singular there): declined.
        declined = ca.fabs(ue[side]) < SINGULAR_TOL * arm.scale
        if side == 0:
            pairs = ((base + half, -e_abs), (base - half, e_abs))
        else:
            pairs = ((base - half, e_abs), (base + half, -e_abs))
        for a1, e in pairs:
            phi2_3 = a1 + e - g2
            phi2 = a1 - g1
            q = [arm.sigma * psi[side], signs[0] * phi2, signs[1] * (phi2_3 - phi2), signs[2] * (phi - phi2_3), roll]
            ok = _and(ok, ca.logic_not(_and(good, declined)))
            starts.append(q)
            valid.append(good)
    return starts, valid, ok, apart


def _rotation_angle(r, t):
    """corrected._angle: the angle [rad] between two rotations (SX 3 x 3, and rows of SX)."""
    trace = sum(r[i, j] * t[i][j] for i in range(3) for j in range(3))

    def column_dot(a: int, b: int):
        return r[0, a] * t[0][b] + r[1, a] * t[1][b] + r[2, a] * t[2][b]

    s0 = column_dot(1, 2) - column_dot(2, 1)
    s1 = column_dot(2, 0) - column_dot(0, 2)
    s2 = column_dot(0, 1) - column_dot(1, 0)
    cos_a = _clamp(0.5 * (trace - 1.0), -1.0, 1.0)
    return ca.atan2(0.5 * ca.sqrt(s0 * s0 + s1 * s1 + s2 * s2), cos_a)


def _pitch_error_ok(a, px, py, pit):
    """Whether :func:`~planner.geometry.target.pitch_error_scalar` of approach axis `a` is surely <= 1e-9."""
    cos_p, sin_p = ca.cos(pit), ca.sin(pit)
    elevation = ca.atan2(sin_p, ca.fabs(cos_p))
    error = ca.fabs(ca.atan2(a[2], _hypot(a[0], a[1])) - elevation)
    wrong = _and(cos_p * (a[0] * px + a[1] * py) < 0.0, _hypot(px, py) > RADIAL_EPS)
    return _and(ca.logic_not(wrong), error <= MARGIN * 1e-9)


class CorrectedKernel:
    """One target kind's compiled corrected closed form with the nearest pick, its buffers bound once.

    Fill :attr:`inputs` (position, then the pitch or the rotation's nine entries row by row,
    then the seed), call, read :attr:`outputs`: ``[sure, slot, q...]``; with `every`, every
    branch for :meth:`~planner.ik.analytic.yaw_planar.solver.YawPlanarIK.solve`: ``[sure,
    singular, valid (4), q (4 x dof, not yet wrapped into the limits)]``
    (:func:`~planner.ik.analytic.yaw_planar.corrected.corrected_result` checks and assembles them).

    Attributes:
        inputs: The input vector.
        outputs: ``[1.0 if the answer is the Python path's else 0.0, the chosen slot, q (dof)]``,
            or with `every` as above (`singular`: the position and pitch branches' flag, next
            to the yaw axis; 0 for poses).
        compiled: Whether the function runs as C code (else the caller should not use it).

    Not thread-safe: its buffers serve one call at a time (each solver owns its kernels).
    """

    def __init__(self, arm: ArmGeometry, frame: PoseFrame, kind: str, current: bool, every: bool = False) -> None:
        dof = arm.dof
        n_extra = {"position": 0, "pitch": 1, "pose": 9}[kind]
        n_in = 3 + n_extra + (dof if current else 0)
        x = ca.SX.sym("x", n_in)
        prm = ca.SX.sym("prm", 6 * dof + 18)
        name = f"yaw_planar_corrected_{kind}" + ("_every" if every else "")
        self.function = self._compile(name, x, prm, self._expression(arm, frame, kind, current, every, x, prm, False))
        self.compiled = self.function.class_name() == "External"
        self.inputs = np.zeros(n_in)
        self.outputs = np.zeros(self.function.numel_out(0))
        self._prm = arm_parameters(arm)
        self._buffer, self._evaluate = self._bind(self.function, self.outputs)
        # Poses: first the valid side's two branches, two steps each (most poses: one side only
        # is valid and both settle), the full kernel above where that is not sure. With
        # `every`, the joints of branches not valid are not the full kernel's (not used).
        self._quick = None
        if kind == "pose" and self.compiled:
            quick = self._compile(
                name + "_quick", x, prm, self._expression(arm, frame, kind, current, every, x, prm, True)
            )
            if quick.class_name() == "External":
                self._quick_outputs = np.zeros(quick.numel_out(0))
                self._quick_function = quick
                self._quick = self._bind(quick, self._quick_outputs)

    @staticmethod
    def _compile(name: str, x, prm, out) -> ca.Function:
        return compile_function(ca.Function(name, [x, prm], [ca.cse(out)]), flags=FLAGS)

    def _bind(self, function: ca.Function, outputs: np.ndarray) -> tuple:
        buffer, evaluate = function.buffer()
        buffer.set_arg(0, memoryview(self.inputs))
        buffer.set_arg(1, memoryview(self._prm))
        buffer.set_res(0, memoryview(outputs))
        return buffer, evaluate

    @staticmethod
    def _expression(arm: ArmGeometry, frame: PoseFrame, kind: str, current: bool, every: bool, x, prm, two_lanes: bool):
        """The output expression; with `two_lanes` (poses) the quick one: sure only where one side is valid."""
        dof = arm.dof
        n_extra = {"position": 0, "pitch": 1, "pose": 9}[kind]
        p = [x[0], x[1], x[2]]
        qc = [x[3 + n_extra + j] for j in range(dof)] if current else None
        target = ca.vertcat(*p)
        pos_tol = MARGIN * SETTLE * max(1.0, arm.scale)
        qs, settled = [], []
        if kind == "pose":
            rflat = [x[3 + k] for k in range(9)]
            rows = [rflat[0:3], rflat[3:6], rflat[6:9]]
            starts, valid, sure, apart = _pose_starts(arm, frame, p, rflat, qc)
            flag = ca.SX(0.0)
            step = pose_kernel(dof, 2)
            rot_t = ca.vertcat(*[ca.horzcat(*row) for row in rows])

            def errors(q):
                tip, rot = tip_fk_sx(q, prm, dof)
                return ca.norm_2(target - tip), _rotation_angle(rot, rows)

        if kind == "pose" and two_lanes:
            # One side's branches valid and started as usual (not apart), both settled after two
            # steps (within EARLY of the threshold: the full kernel's q2, which it keeps): the
            # full kernel's answer. Anything else is left to it.
            front = ca.logic_or(valid[0], valid[1])
            sure = _and(sure, ca.logic_not(apart), ca.logic_not(_and(front, ca.logic_or(valid[2], valid[3]))))
            lanes = []
            for lane in range(2):
                q0 = ca.vertcat(*[_if(front, a, b) for a, b in zip(starts[lane], starts[2 + lane])])
                q0 = _if(ca.logic_or(valid[lane], valid[2 + lane]), q0, 0.0)
                q = step(q0, target, rot_t, prm)
                perr, oerr = errors(q)
                lanes.append(([q[j] for j in range(dof)], _and(perr <= pos_tol, oerr <= MARGIN * 1e-13)))
            for m in range(4):
                q, done = lanes[m % 2]
                qs.append(list(q))
                settled.append(done)
        elif kind == "pose":
            # Every branch is stepped: the rotation fixes the arm's plane up to a half turn of
            # the yaw, and where the roll axis is next to vertical both sides are valid on the
            # ideal model (10 % of random poses); on the real arm one of them may have no
            # solution: its steps stall (solve_corrected_pose's ORIENT, decided from the errors
            # after its first two calls, two steps each: the same here, with margins).
            for m in range(4):
                q2 = step(_if(valid[m], ca.vertcat(*starts[m]), 0.0), target, rot_t, prm)
                q4 = step(q2, target, rot_t, prm)
                perr2, oerr2 = errors(q2)
                perr, oerr = errors(q4)
                error2 = perr2 / arm.scale + oerr2
                error = perr / arm.scale + oerr
                # The Python and the vectorised paths stop a branch settled after two steps (those
                # and two more may differ by more than round-off): the same here, unsure within
                # EARLY of their threshold (the two FK codes differ by round-off).
                early = _and(perr2 <= EARLY * pos_tol / MARGIN, oerr2 <= EARLY * 1e-13)
                close = _and(perr2 <= pos_tol / (MARGIN * EARLY), oerr2 <= 1e-13 / EARLY)
                unsure = _and(close, ca.logic_not(early))
                sure = _and(sure, ca.logic_not(_and(valid[m], unsure)))
                q = _if(early, q2, q4)
                # The Python path: error > 1e-9 and error >= 0.5 x error2.
                stalled = _and(error2 > 1e-9 / MARGIN, error > 1e-9 / MARGIN, error >= STALL * error2)
                qs.append([q[j] for j in range(dof)])
                settled.append(_or(early, _and(perr <= pos_tol, oerr <= MARGIN * 1e-13)))
                # Started apart, the vectorised path's damped steps decide a stalled branch.
                sure = _and(sure, ca.logic_not(_and(apart, valid[m], stalled)))
                valid[m] = _and(valid[m], ca.logic_not(stalled))
        else:
            pit = x[3] if kind == "pitch" else None
            starts, aims, valid, sure, u = _pitch_starts(arm, p, pit, qc, prm)
            # The branches' singular flag (corrected: u_end < SINGULAR_TOL x the arm's size).
            flag = u < SINGULAR_TOL * arm.scale
            step = pitch_kernel(dof, arm.roll_idx, STEPS)
            lx, ly, lz = (float(v) for v in arm.approach_local)
            for m in range(4):
                q0 = ca.vertcat(*[_if(valid[m], v, 0.0) for v in starts[m]])
                q, miss = step(q0, target, _if(valid[m], aims[m], 0.0), prm)
                tip, rot = tip_fk_sx(q, prm, dof)
                perr = ca.norm_2(target - tip)
                done = _and(perr <= pos_tol, ca.fabs(miss) <= MARGIN * 1e-13)
                if pit is not None:
                    a = [rot[i, 0] * lx + rot[i, 1] * ly + rot[i, 2] * lz for i in range(3)]
                    done = _and(done, _pitch_error_ok(a, p[0], p[1], pit))
                qs.append([q[j] for j in range(dof)])
                settled.append(done)
        for m in range(4):
            sure = _and(sure, _or(ca.logic_not(valid[m]), settled[m]))
        # Merged branches (corrected._twins): left to the Python path.
        for i in range(4):
            for j in range(i + 1, 4):
                close = ca.SX(1)
                for k in range(dof):
                    close = _and(close, ca.fabs(wrapped_sx(qs[i][k], qs[j][k])) < TWIN)
                sure = _and(sure, ca.logic_not(_and(valid[i], valid[j], close)))
        raw = [list(q) for q in qs]
        within = []
        for m in range(4):
            inside = valid[m]
            for j in range(dof):
                lo, hi = float(arm.lower[j]), float(arm.upper[j])
                qs[m][j] = wrap_sx(qs[m][j], lo, hi, qc[j]) if current else wrap_sx(qs[m][j], lo, hi)
                inside = _and(inside, qs[m][j] >= lo, qs[m][j] <= hi)
            within.append(inside)
        if current:
            best, ties = nearest_branch_sx(qs, within, qc)
            if not every:  # ties: the Python path's order among them is its sort key's
                sure = _and(sure, ca.logic_not(ties))
        else:
            best = _if(within[0], 0, _if(within[1], 1, _if(within[2], 2, _if(within[3], 3, -1))))
        sure = _and(sure, best >= 0)
        chosen = pick_branch_sx(qs, best)
        if every:
            return ca.vertcat(sure, flag, *valid, *[v for q in raw for v in q])
        return ca.vertcat(sure, best, *chosen)

    def __call__(self) -> None:
        """Evaluate from :attr:`inputs` into :attr:`outputs`."""
        if self._quick is not None:
            self._quick[1]()
            if self._quick_outputs[0]:
                self.outputs[:] = self._quick_outputs
                return
        self._evaluate()


def corrected_kernel(
    arm: ArmGeometry, frame: PoseFrame, kind: str, current: bool, every: bool = False
) -> CorrectedKernel | None:
    """The compiled :class:`CorrectedKernel`, or None where the Python path always answers.

    None for position targets without q_current (the Python path hands them to the vectorised
    one), without q_current where roll 0 lies outside its range, and without a C compiler.
    """
    if kind == "position" and not current:
        return None
    ri = arm.roll_idx
    if not current and kind != "pose" and not arm.lower[ri] <= 0.0 <= arm.upper[ri]:
        return None
    kernel = CorrectedKernel(arm, frame, kind, current, every)
    return kernel if kernel.compiled else None
