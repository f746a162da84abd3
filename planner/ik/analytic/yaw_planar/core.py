"""The closed form on the ideal geometry, vectorised over targets: yaw, wrist point, elbow.

Per target (rows) and branch (front/back x elbow up/down, :data:`~planner.ik.analytic.yaw_planar.branches.BRANCHES`):
the yaw from the end point's horizontal position (or the rotation), the in-plane end angle
(the pitch, the rotation, or the free choice of :mod:`~planner.ik.analytic.yaw_planar.free_pitch`),
the wrist point, then the shoulder and elbow by the law of cosines. The result is the ideal
model's: :mod:`~planner.ik.analytic.yaw_planar.refine` corrects it on inexact chains.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.ik.analytic.geometry import SINGULAR_TOL, wrap_pi
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.branches import BEYOND, CYLINDER, DUPLICATE, INSIDE, ORIENT, VALID
from planner.ik.analytic.yaw_planar.free_pitch import free_pitch_array
from planner.ik.analytic.yaw_planar.orientation import (
    branch_alpha,
    pitch_from_rotation,
    roll_from_rotation,
    yaw_for_rotation,
)

__all__ = ["CoreBranches", "roll_values", "end_geometry", "solve_core", "ideal_position_error"]

PI = math.pi


@dataclass(frozen=True)
class CoreBranches:
    """The ideal closed form of N targets, per branch (4 slots, :data:`BRANCHES` order).

    Attributes:
        q: Joint values, shape (N, 4, dof) [rad], not yet wrapped into the limits.
        cat: Shape (N, 4) int8 branch categories (:mod:`~planner.ik.analytic.yaw_planar.branches`).
        dist: Shape (N, 4): wrist point to shoulder distance [m].
        singular: Shape (N, 4) bool.
        world_pitch: Shape (N, 4): each branch's pitch (front: alpha, back: pi - alpha) [rad],
            for arms with a wrist pitch, else None.
        end: Shape (N, 3): the end point (the tip, or the roll centre for rotation targets) [m].
        d: Shape (N,): sideways offset of the end point from the yaw axis [m].
        tu: Shape (N,): in-plane end vector, along the plane [m].
        tz: Shape (N,): in-plane end vector, vertical [m].
        ue: Shape (N, 2): the end point's in-plane distance from the yaw axis per side [m]
            (None for arms without a wrist pitch given an orientation).
        ze: Shape (N,): the end point's height [m] (None as ``ue``).
        phi: Shape (N, 2): the in-plane end angle per side [rad] (None without a wrist pitch).
        seeded: Shape (N,): the yaws started apart next to the yaw axis (inexact chains; None
            as ``ue``).
    """

    q: np.ndarray
    cat: np.ndarray
    dist: np.ndarray
    singular: np.ndarray
    world_pitch: np.ndarray | None
    end: np.ndarray
    d: np.ndarray
    tu: np.ndarray
    tz: np.ndarray
    ue: np.ndarray | None = None
    ze: np.ndarray | None = None
    phi: np.ndarray | None = None
    seeded: np.ndarray | None = None


def roll_values(arm: ArmGeometry, n: int, qc, roll_free):
    """The free wrist roll (n,): `roll_free` where finite, else q_current's, else 0."""
    roll = qc[:, arm.roll_idx] if qc is not None else np.zeros(n)
    if roll_free is not None:
        roll = np.where(np.isfinite(roll_free), roll_free, roll)
    return roll


def end_geometry(arm: ArmGeometry, n: int, rot, qc, roll_free=None):
    """Per-target end vector (tu, tz), lateral offset d, end-point shift, roll value."""
    if arm.has_roll and rot is not None:
        tu, tz, d = arm.centre
        shift = -np.einsum("nij,j->ni", rot, arm.centre_to_tip_local)
        return np.full(n, tu), np.full(n, tz), np.full(n, d), shift, None
    roll = None
    if arm.has_roll:
        roll = roll_values(arm, n, qc, roll_free)
    if arm.tip_on_roll_axis:
        tu, tz, d = arm.tip_fixed
        return np.full(n, tu), np.full(n, tz), np.full(n, d), None, roll
    cr, sr = np.cos(roll), np.sin(roll)
    tu = arm.tip0[0] + arm.tipc[0] * cr + arm.tips[0] * sr
    tz = arm.tip0[1] + arm.tipc[1] * cr + arm.tips[1] * sr
    d = arm.tip0[2] + arm.tipc[2] * cr + arm.tips[2] * sr
    return tu, tz, d, None, roll


def solve_core(arm: ArmGeometry, pos, pit, rot, qc, orient_tol, internal_pitch=False, phi_free=None, roll_free=None):
    """The ideal-geometry closed form for N targets, per branch (:class:`CoreBranches`).

    `pit` is the target's approach pitch, or with `internal_pitch` each row's branch pitch
    (the in-plane approach angle alpha on the front side, pi - alpha on the back side, as
    the ``world_pitch`` this returns). `phi_free` (N, 2), where finite, sets the in-plane
    end angle of position-only targets per side instead of the default choice; `roll_free`
    (N,), where finite, the free wrist roll instead of q_current's.
    """
    n = pos.shape[0]
    dof = arm.dof
    three = arm.n_pitch == 3
    tu, tz, d, shift, roll = end_geometry(arm, n, rot, qc, roll_free)
    end = pos if shift is None else pos + shift
    hx = end[:, 0] - arm.bx
    hy = end[:, 1] - arm.by
    ze = end[:, 2]
    rho2 = hx * hx + hy * hy
    axis_tol = arm.len_tol  # the yaw axis is exact in the ideal model too
    free = (rho2 <= axis_tol * axis_tol) & (np.abs(d) <= axis_tol)
    len_tol = arm.core_len_tol
    under = rho2 - d * d
    cylinder = ~free & (under < -2.0 * np.abs(d) * len_tol)
    u = np.sqrt(np.maximum(under, 0.0))
    seeded = np.zeros(n, dtype=bool)
    u_end = u  # the end point's own, for the outward side of pitch targets
    if not arm.exact:
        # Inexact chains, end point next to the cylinder |d| around the yaw axis: the real
        # front and back yaws may differ where the ideal model merges them; start apart.
        # (The yaw is ill-conditioned there: such solutions are flagged singular.)
        u_seed = np.sqrt(2.0 * np.abs(d) * len_tol)
        seeded = ~free & ~cylinder & (u < u_seed)
        u = np.where(seeded, u_seed, u)
    ang = np.arctan2(hy, hx)
    psi_f = ang - arm.mu - np.arctan2(-d, u)
    psi_b = ang - arm.mu - np.arctan2(-d, -u)
    back_dup = free | (u == 0.0)
    psi0 = arm.sigma * qc[:, 0] if qc is not None else np.zeros(n)
    m_rot = None
    if rot is not None:
        m_rot = rot @ arm.rot0.T
    if np.any(free):
        psi_f = np.where(free, psi0, psi_f)
        u = np.where(free, 0.0, u)
    psi = np.stack([psi_f, psi_b], axis=1)  # (n, 2)
    ue = np.stack([u, -u], axis=1)
    cat = np.zeros((n, 2), dtype=np.int8)
    cat[cylinder] = CYLINDER
    cat[:, 1] = np.where(back_dup & ~cylinder, DUPLICATE, cat[:, 1])
    if rot is not None:
        psi, ue, cat = yaw_for_rotation(arm, m_rot, hx, hy, d, u, psi, ue, cat, free)
    alpha_t = None
    if pit is not None:
        # In-plane approach angle per side.
        if internal_pitch:
            alpha_t = np.stack([pit, PI - pit], axis=1)
        else:
            # The side from the yaws the end point itself gives (not the seeded ones: next to
            # the yaw axis those turn the plane enough to flip it).
            psi_end = psi
            if seeded.any():
                psi_end = np.where(
                    seeded[:, None],
                    np.stack([ang - np.arctan2(-d, u_end), ang - np.arctan2(-d, -u_end)], axis=1) - arm.mu,
                    psi,
                )
            alpha_t = branch_alpha(arm, end, psi_end, pit)
    ze2 = np.broadcast_to(ze[:, None], (n, 2))
    tu2, tz2 = tu[:, None], tz[:, None]
    roll_q = None if roll is None else np.broadcast_to(roll[:, None], (n, 2))
    phi = None
    orient_res = np.zeros((n, 2))
    if three:
        l2, g2 = arm.l2, arm.g2
        if pit is not None:
            phi = alpha_t - arm.beta
        elif rot is not None:
            phi, roll_q, orient_res = pitch_from_rotation(arm, m_rot, psi)
            cat = np.where((cat == VALID) & (orient_res > orient_tol), ORIENT, cat)
        elif phi_free is not None and np.isfinite(phi_free).all():
            phi = phi_free
        else:
            phi, fail = free_pitch_array(arm, psi, ue, ze2, tu2, tz2, qc)
            if phi_free is not None:
                given = np.isfinite(phi_free)
                phi = np.where(given, phi_free, phi)
                fail = np.where(given, VALID, fail)
            cat = np.where((cat == VALID) & (fail != VALID), fail, cat)
        cp, sp = np.cos(phi), np.sin(phi)
        wu = ue - (cp * tu2 - sp * tz2)
        wz = ze2 - (sp * tu2 + cp * tz2)
    else:
        if pit is not None or rot is not None:
            return _core_two_oriented(
                arm, alpha_t, m_rot, psi, ue, ze2, tu, tz, d, cat, free | seeded, roll_q, end, orient_tol
            )
        l2 = np.hypot(tu, tz)[:, None]  # (n, 1): the end vector is the second link
        g2 = np.arctan2(tz, tu)[:, None]
        wu, wz = ue, ze2
    l1, g1 = arm.l1, arm.g1
    vx = wu - arm.su
    vz = wz - arm.sz
    dist = np.hypot(vx, vz)
    cat = np.where((cat == VALID) & (dist > l1 + l2 + len_tol), BEYOND, cat)
    cat = np.where((cat == VALID) & (dist < np.abs(l1 - l2) - len_tol), INSIDE, cat)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = (dist * dist - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
    c = np.clip(np.nan_to_num(c, nan=1.0), -1.0, 1.0)
    s = np.sqrt(1.0 - c * c)
    elbow_sing = s < SINGULAR_TOL
    s = np.where(elbow_sing, 0.0, s)
    c = np.where(elbow_sing, np.sign(c) + (c == 0), c)
    if arm.elbow_seed > 0.0:
        # Inexact chains: next to a stretched or folded elbow the real arm's two elbow
        # solutions lie about sqrt(deviation) apart where the ideal model sees one; start
        # the two branches that far apart so the correction finds both.
        near = s < math.sin(arm.elbow_seed)
        e_seed = np.where(c > 0, arm.elbow_seed, PI - arm.elbow_seed)
        s = np.where(near, math.sin(arm.elbow_seed), s)
        c = np.where(near, np.cos(e_seed), c)
        elbow_sing = np.zeros_like(elbow_sing)
    e_abs = np.arctan2(s, c)
    base = np.arctan2(vz, vx)
    # (n, 4): front-up (e<=0), front-down, back-up (e>=0), back-down.
    e = np.stack([-e_abs[:, 0], e_abs[:, 0], e_abs[:, 1], -e_abs[:, 1]], axis=1)
    rep = [0, 0, 1, 1]
    # Shoulder: a1 = base - atan2(l2 sin e, l1 + l2 cos e); the sign of e flips the second term.
    half = np.arctan2(l2 * s, l1 + l2 * c)
    a1 = np.stack(
        [base[:, 0] + half[:, 0], base[:, 0] - half[:, 0], base[:, 1] - half[:, 1], base[:, 1] + half[:, 1]], axis=1
    )
    phi2 = a1 - g1
    phi3 = a1 + e - g2
    q = np.empty((n, 4, dof))
    q[:, :, 0] = arm.sigma * psi[:, rep]
    sg, idx = arm.signs, arm.pitch_idx
    q[:, :, idx[0]] = sg[0] * phi2
    q[:, :, idx[1]] = sg[1] * (phi3 - phi2)
    if three:
        phi4 = phi[:, rep]
        q[:, :, idx[2]] = sg[2] * (phi4 - phi3)
        total = phi4
    else:
        total = phi3
    if arm.has_roll:
        if roll_q is None:
            roll_q = roll_from_rotation(arm, m_rot, psi[:, rep], total)
            q[:, :, arm.roll_idx] = roll_q
        else:
            q[:, :, arm.roll_idx] = roll_q[:, rep] if roll_q.shape[1] == 2 else roll_q
    cat4 = cat[:, rep].copy()
    cat4[:, 1] = np.where((cat4[:, 1] == VALID) & elbow_sing[:, 0], DUPLICATE, cat4[:, 1])
    cat4[:, 3] = np.where((cat4[:, 3] == VALID) & elbow_sing[:, 1], DUPLICATE, cat4[:, 3])
    world_pitch = None
    if three:
        alpha = arm.beta + total
        world_pitch = np.where(np.array([True, True, False, False]), alpha, PI - alpha)
    singular = elbow_sing[:, rep] | (free | seeded)[:, None] | (np.abs(ue[:, rep]) < SINGULAR_TOL * arm.scale)
    return CoreBranches(
        q=q,
        cat=cat4,
        dist=dist[:, rep],
        singular=singular,
        world_pitch=world_pitch,
        end=end,
        d=d,
        tu=tu,
        tz=tz,
        ue=ue,
        ze=ze,
        phi=phi,
        seeded=seeded,
    )


def _core_two_oriented(arm: ArmGeometry, alpha_t, m_rot, psi, ue, ze2, tu, tz, d, cat, free, roll_q, end, orient_tol):
    """Arms without a wrist pitch, with a pitch or rotation target: one solution per side.

    The orientation fixes the last link, so the elbow is the end point minus that link and
    the shoulder points at it: well conditioned, unlike filtering the position's two
    solutions by orientation (whose elbow angle degrades to sqrt(eps) near a stretched
    elbow).
    """
    n = psi.shape[0]
    dof = arm.dof
    l1, g1, su, sz = arm.l1, arm.g1, arm.su, arm.sz
    len_tol = arm.core_len_tol
    tu2, tz2 = tu[:, None], tz[:, None]
    l2 = np.hypot(tu2, tz2)
    g2 = np.arctan2(tz2, tu2)
    de = np.hypot(ue - su, ze2 - sz)
    cat = np.where((cat == VALID) & (de > l1 + l2 + len_tol), BEYOND, cat)
    cat = np.where((cat == VALID) & (de < np.abs(l1 - l2) - len_tol), INSIDE, cat)
    if alpha_t is not None:
        phi = alpha_t - arm.beta
    else:
        phi, _, residual = pitch_from_rotation(arm, m_rot, psi)
        cat = np.where((cat == VALID) & (residual > orient_tol), ORIENT, cat)
    cp, sp = np.cos(phi), np.sin(phi)
    ex = ue - (cp * tu2 - sp * tz2) - su
    ez = ze2 - (sp * tu2 + cp * tz2) - sz
    tol = max(arm.consistency_tol, len_tol)
    cat = np.where((cat == VALID) & (np.abs(np.hypot(ex, ez) - l1) > tol), ORIENT, cat)
    a1 = np.arctan2(ez, ex)
    e = wrap_pi(phi + g2 - a1)
    # A stretched or folded elbow (sin e ~ 0) has one solution: labelled elbow-up on every path,
    # whatever the sign round-off gives e there.
    straight = np.abs(np.sin(e)) < SINGULAR_TOL
    up = np.stack([e[:, 0] <= 0.0, e[:, 1] >= 0.0], axis=1) | straight
    rep = [0, 0, 1, 1]
    q2 = np.empty((n, 2, dof))
    q2[:, :, 0] = arm.sigma * psi
    sg, idx = arm.signs, arm.pitch_idx
    phi2 = a1 - g1
    q2[:, :, idx[0]] = sg[0] * phi2
    q2[:, :, idx[1]] = sg[1] * (phi - phi2)
    if arm.has_roll:
        if roll_q is None:
            q2[:, :, arm.roll_idx] = roll_from_rotation(arm, m_rot, psi, phi)
        else:
            q2[:, :, arm.roll_idx] = roll_q
    q = q2[:, rep]
    cat4 = cat[:, rep].copy()
    chosen = np.stack([up[:, 0], ~up[:, 0], up[:, 1], ~up[:, 1]], axis=1)
    cat4 = np.where((cat4 == VALID) & ~chosen, DUPLICATE, cat4)
    singular = straight | free[:, None] | (np.abs(ue) < SINGULAR_TOL * arm.scale)
    return CoreBranches(
        q=q,
        cat=cat4,
        dist=de[:, rep],
        singular=singular[:, rep],
        world_pitch=None,
        end=end,
        d=d,
        tu=tu,
        tz=tz,
    )


def ideal_position_error(arm: ArmGeometry, core, pos):
    """Distance (n, 4) [m] from the target to the tip of the ideal closed-form forward model at q."""
    q = core.q
    sg, idx = arm.signs, arm.pitch_idx
    phi2 = sg[0] * q[..., idx[0]]
    phi3 = phi2 + sg[1] * q[..., idx[1]]
    tu, tz, d = core.tu[:, None], core.tz[:, None], core.d[:, None]
    a = phi2 + arm.g1
    fu = arm.su + arm.l1 * np.cos(a)
    fz = arm.sz + arm.l1 * np.sin(a)
    if arm.n_pitch == 3:
        phi4 = phi3 + sg[2] * q[..., idx[2]]
        a = phi3 + arm.g2
        fu += arm.l2 * np.cos(a)
        fz += arm.l2 * np.sin(a)
    else:
        phi4 = phi3
    c4, s4 = np.cos(phi4), np.sin(phi4)
    fu += c4 * tu - s4 * tz
    fz += s4 * tu + c4 * tz
    yaw = arm.mu + arm.sigma * q[:, ::2, 0]  # one yaw per side (front, back)
    cy, sy = np.cos(yaw)[:, [0, 0, 1, 1]], np.sin(yaw)[:, [0, 0, 1, 1]]
    dx = arm.bx + cy * fu + sy * d - pos[:, 0:1]
    dy = arm.by + sy * fu - cy * d - pos[:, 1:2]
    dz = fz - pos[:, 2:3]
    return np.sqrt(dx * dx + dy * dy + dz * dz)
