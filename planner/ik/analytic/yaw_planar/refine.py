"""Correction on the real geometry: closed-form solutions of inexact chains made exact.

Chains whose axes deviate from the ideal directions by round-off (up to
:data:`~planner.ik.analytic.base.FAMILY_ANGLE_TOL`, e.g. SO-101's URDF, a few micro-radians) are
solved on the ideal geometry and then corrected on the real one (product of exponentials):
each branch by Newton's steps on it (compiled: :func:`newton`), which square the error per
step; branches they do not settle (next to the boundary of the real reach) are finished by
damped Gauss-Newton steps (:func:`polish`). Without those Newton steps (two pitch joints and
no rotation) each branch is re-solved for the target shifted by the error it left, which
converges by about the deviation per round. Only branches that then reproduce the target
(1e-10 m, 1e-9 rad) are kept. On exact chains this only measures the errors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.core.rotations import rotation_error
from planner.ik.analytic.geometry import wrap_pi
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.branches import BEYOND, DUPLICATE, INSIDE, ORIENT, VALID
from planner.ik.analytic.yaw_planar.core import CoreBranches, solve_core
from planner.ik.analytic.yaw_planar.newton import newton_kernel
from planner.ik.analytic.yaw_planar.real_model import orientation_errors, true_fk, true_pitch

__all__ = ["Refined", "refine", "newton", "polish", "orthonormalize"]


@dataclass(frozen=True)
class Refined:
    """Branches of N targets by the real model (see :func:`refine`).

    Attributes:
        q: Joint values, shape (N, 4, dof) [rad].
        cat: Shape (N, 4) branch categories (failed corrections re-categorised).
        perr: Position errors by the real model, shape (N, 4) [m].
        oerr: Orientation errors, shape (N, 4) [rad], or None for position-only targets.
        dist: Wrist point to shoulder distances, shape (N, 4) [m].
        singular: Shape (N, 4) bool (branches merged into one flagged singular).
    """

    q: np.ndarray
    cat: np.ndarray
    perr: np.ndarray
    oerr: np.ndarray | None
    dist: np.ndarray
    singular: np.ndarray


def orthonormalize(r: np.ndarray) -> np.ndarray:
    """Nearest rotation matrices (polar decomposition by SVD), shape (..., 3, 3)."""
    u, _, vt = np.linalg.svd(r)
    out = u @ vt
    det = np.linalg.det(out)
    u[..., :, 2] *= np.where(det < 0, -1.0, 1.0)[..., None]
    return u @ vt


def refine(arm: ArmGeometry, core: CoreBranches, pos, pit, rot, qc, roll_free=None, max_rounds: int = 8):
    """Errors by the real (product of exponentials) model; correct inexact chains.

    Each branch is re-solved for its target shifted by the error its last solution left
    (position, approach pitch, or pose composed with the inverse error), which converges
    by a factor of about the model's deviation from the ideal family per round. Branches
    that do not settle (next to a stretched elbow the rate degrades) are finished by damped
    Gauss-Newton steps on the real model. A branch is kept only if it then reproduces the
    target within 1e-10 m (times the arm's size when above 1 m) and 1e-9 rad.

    Args:
        arm: The geometry.
        core: The ideal closed form of the targets.
        pos: Target positions, shape (N, 3) [m].
        pit: Approach pitches, shape (N,) [rad], or None.
        rot: Target rotations, shape (N, 3, 3), or None.
        qc: Current configurations, shape (N, dof) [rad], or None.
        roll_free: The free wrist roll per target, shape (N,) [rad] where finite, or None.
        max_rounds: Re-solving rounds at most.

    Returns:
        The branches by the real model.
    """
    n = pos.shape[0]
    singular = core.singular
    q = core.q.copy()
    cat = core.cat.copy()
    dist = core.dist
    branch_pitch = core.world_pitch
    p_eff = np.broadcast_to(pos[:, None, :], (n, 4, 3)).copy()
    # The branch pitch each branch must keep (see solve_core): the target's in the arm's plane, or
    # for a position-only target the one chosen for it (q_current's, measured on the real
    # arm, the default rule's, or the one the search within the limits found).
    pitch_eff = pitch_goal = None
    if arm.n_pitch == 3 and rot is None:
        pitch_goal = branch_pitch.copy()
        pitch_eff = pitch_goal.copy()
    rot_t = None if rot is None else np.broadcast_to(rot[:, None], (n, 4, 3, 3))
    rot_eff = None if rot is None else rot_t.copy()
    qc4 = None if qc is None else np.broadcast_to(qc[:, None, :], (n, 4, arm.dof))
    slot = np.tile(np.arange(4), n)
    settle_tol = 1e-14 * max(1.0, arm.scale)
    pos_tol = 1e-10 * max(1.0, arm.scale)
    valid = cat == VALID
    if not arm.exact and (rot is not None or arm.n_pitch == 3):
        # Newton's steps settle every branch that has a solution next to the ideal one; the
        # others (next to the boundary of the reach) go to the damped steps of `polish`.
        q = newton(arm, q, valid, pos, pitch_goal, rot)
        max_rounds = 0
    for round_ in range(max_rounds + 1):
        fk_p, fk_r = true_fk(arm, q)
        perr = np.linalg.norm(fk_p - pos[:, None, :], axis=-1)
        oerr = orientation_errors(arm, fk_r, pos, pit, rot)
        settled = perr <= settle_tol
        if oerr is not None:
            settled &= oerr <= 1e-13
        if pitch_goal is not None and not arm.exact:
            pitch_now = true_pitch(arm, q, fk_r)
            settled &= np.abs(wrap_pi(pitch_now - pitch_goal)) <= 1e-13
        if arm.exact or (~valid | settled).all() or round_ == max_rounds:
            break
        if rot is not None:
            # T_eff <- T_eff FK(q)^-1 T: the pose error, expressed at the tip, undone.
            fk_rt = np.swapaxes(fk_r, -1, -2)
            p_eff = p_eff + np.einsum("...ij,...jk,...k->...i", rot_eff, fk_rt, pos[:, None, :] - fk_p)
            rot_eff = orthonormalize(rot_eff @ fk_rt @ rot_t)
        else:
            p_eff = p_eff + (pos[:, None, :] - fk_p)
        if pitch_goal is not None:
            pitch_eff = pitch_eff + wrap_pi(pitch_goal - pitch_now)
        # Only the branches still unsettled move (those Newton's steps settled stay).
        sel = np.nonzero((valid & ~settled).reshape(-1))[0]
        sub = solve_core(
            arm,
            p_eff.reshape(-1, 3)[sel],
            None if pitch_eff is None else pitch_eff.reshape(-1)[sel],
            None if rot_eff is None else rot_eff.reshape(-1, 3, 3)[sel],
            None if qc4 is None else qc4.reshape(-1, arm.dof)[sel],
            arm.orient_tol,
            internal_pitch=True,
            roll_free=None if roll_free is None else np.repeat(roll_free, 4)[sel],
        )
        picked = np.arange(sel.size)
        took = sub.cat[picked, slot[sel]] == VALID
        q = q.copy()
        q.reshape(-1, arm.dof)[sel[took]] = sub.q[picked, slot[sel]][took]
        dist = dist.copy()
        dist.reshape(-1)[sel[took]] = sub.dist[picked, slot[sel]][took]
    if not arm.exact:
        todo = valid & ~settled
        if todo.any():
            idx = np.nonzero(todo)
            held = None if pitch_goal is None else pitch_goal[idx]
            q_sub = polish(arm, q[idx], pos[idx[0]], held, None if rot is None else rot[idx[0]], idx[1] < 2)
            q[idx] = q_sub
            fk_p, fk_r = true_fk(arm, q)
            perr = np.linalg.norm(fk_p - pos[:, None, :], axis=-1)
            oerr = orientation_errors(arm, fk_r, pos, pit, rot)
    ok = perr <= pos_tol
    if oerr is not None:
        ok &= oerr <= (1e-9 if not arm.exact else arm.orient_tol)
    if not arm.exact:
        # Branches that converged onto one solution (a singular target): keep the first.
        for a, b in ((0, 1), (2, 3), (0, 2), (0, 3), (1, 2), (1, 3)):
            both = (valid[:, a] & ok[:, a]) & (valid[:, b] & ok[:, b])
            twin = both & (np.max(np.abs(wrap_pi(q[:, a] - q[:, b])), axis=-1) < 1e-7)
            if twin.any():
                cat[twin, b] = DUPLICATE
                valid[twin, b] = False
                if singular is core.singular:
                    singular = singular.copy()
                singular[twin, a] = True
    failed = valid & ~ok
    if failed.any():
        if rot is not None or (pit is not None and arm.n_pitch == 2):
            fail_cat = np.full(cat.shape, ORIENT)
        else:
            middle = 0.5 * (abs(arm.l1 - arm.link_lengths[1]) + arm.l1 + arm.link_lengths[1])
            fail_cat = np.where(dist > middle, BEYOND, INSIDE)
        cat = np.where(failed, fail_cat, cat)
    return Refined(q, cat, perr, oerr, dist, singular)


def newton(arm: ArmGeometry, q, valid, pos, pitch_goal, rot, calls: int = 3):
    """The valid branches after Newton steps on the real model (:mod:`~planner.ik.analytic.yaw_planar.newton`).

    Position and pitch targets (three pitch joints) keep their branch pitch `pitch_goal`
    (N, 4) and their roll; rotation targets move every joint. Up to `calls` calls (2 steps
    each) for the branches not yet at round-off by the real model; branches the steps do not
    settle are left to the re-solving rounds and :func:`polish` (which start from them).

    Returns:
        q (N, 4, dof).
    """
    rows = np.nonzero(valid.reshape(-1))[0]
    if rows.size == 0:
        return q
    n = pos.shape[0]
    dof = arm.dof
    kernel = newton_kernel(arm)
    flat = q.reshape(-1, dof).copy()
    target = np.repeat(pos, 4, axis=0)
    if rot is not None:
        kind, other = "pose", np.repeat(rot, 4, axis=0)
    else:
        # true_pitch's front value: the goal itself in front, pi minus the back branches' goal.
        kind = "pitch"
        other = np.where(np.array([True, True, False, False]), pitch_goal, np.pi - pitch_goal).reshape(-1)
    settle = 1e-14 * max(1.0, arm.scale)
    for _ in range(calls):
        flat[rows] = kernel.many(flat[rows], target[rows], other[rows], kind)
        fk_p, fk_r = true_fk(arm, flat[rows])
        done = np.linalg.norm(fk_p - target[rows], axis=-1) <= settle
        if rot is not None:
            done &= np.asarray(rotation_error(fk_r, other[rows])) <= 1e-13
        else:
            a = fk_r @ arm.approach_local
            yaw = arm.mu + arm.sigma * flat[rows, 0]
            along = np.cos(yaw) * a[:, 0] + np.sin(yaw) * a[:, 1]
            horiz = np.hypot(a[:, 0], a[:, 1])
            alpha = np.arctan2(a[:, 2], np.where(along >= 0.0, horiz, -horiz))
            done &= np.abs(wrap_pi(alpha - other[rows])) <= 1e-13
        rows = rows[~done]
        if rows.size == 0:
            break
    return flat.reshape(n, 4, dof)


def polish(arm: ArmGeometry, q, pos, pit, rot, front, iterations: int = 40):
    """Damped Gauss-Newton on the real model for K rows; returns the new q (K, dof).

    Residuals: position (scaled by the arm's size), plus the approach pitch for pitch
    targets or the rotation error vector for rotation targets. The wrist roll moves only
    for rotation targets (elsewhere it is an input).
    """
    active = [j for j in range(arm.dof) if rot is not None or j != arm.roll_idx]
    inv_scale = 1.0 / arm.scale
    front4 = np.where(front, 0, 2)

    def residual(qq):
        fk_p, fk_r = true_fk(arm, qq)
        parts = [(fk_p - pos) * inv_scale]
        if rot is not None:
            rel = np.swapaxes(rot, -1, -2) @ fk_r
            parts.append(
                0.5
                * np.stack(
                    [rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0], rel[:, 1, 0] - rel[:, 0, 1]], axis=-1
                )
            )
        elif pit is not None and arm.n_pitch == 3:
            qq4 = np.repeat(qq[:, None, :], 4, axis=1)
            rr4 = np.repeat(fk_r[:, None], 4, axis=1)
            got = true_pitch(arm, qq4, rr4)[np.arange(len(qq)), front4]
            parts.append(wrap_pi(got - pit)[:, None])
        return np.concatenate(parts, axis=-1)

    step = 1e-7
    history = []
    for _ in range(iterations):
        r = residual(q)
        size = np.max(np.abs(r), axis=-1)
        if np.max(size) <= 1e-15:
            break
        # Stop once no row is still improving (by 1 % over the last 3 steps): the rows left
        # stalled at a residual that is not a solution (e.g. just beyond the real reach).
        history.append(size)
        if len(history) > 3 and np.all((size <= 1e-15) | (size > 0.99 * history[-4])):
            break
        jac = np.empty(r.shape + (len(active),))
        for k, j in enumerate(active):
            dq = q.copy()
            dq[:, j] += step
            jac[..., k] = (residual(dq) - r) / step
        jt = np.swapaxes(jac, -1, -2)
        lhs = jt @ jac + 1e-12 * np.eye(len(active))
        delta = np.linalg.solve(lhs, -(jt @ r[..., None]))[..., 0]
        q = q.copy()
        q[:, active] += delta
    return q
