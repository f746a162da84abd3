"""Correction on the real geometry: closed-form solutions of inexact chains made exact.

Chains whose axes deviate from the ideal directions by round-off (up to
:data:`~planner.ik.analytic.base.FAMILY_ANGLE_TOL`, e.g. SO-101's URDF, a few micro-radians) are
solved on the ideal geometry and then corrected on the real one (product of exponentials):
each branch is re-solved for the target shifted by the error it left, which converges by about
the deviation per round, and branches that do not settle (next to a stretched elbow) are
finished by damped Gauss-Newton steps. Only branches that then reproduce the target (1e-10 m,
1e-9 rad) are kept. On exact chains this only measures the errors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.ik.analytic.geometry import wrap_pi
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.branches import BEYOND, DUPLICATE, INSIDE, ORIENT, VALID
from planner.ik.analytic.yaw_planar.core import CoreBranches, solve_core
from planner.ik.analytic.yaw_planar.real_model import orientation_errors, true_fk, true_pitch

__all__ = ["Refined", "refine", "polish", "orthonormalize"]


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
    rows = np.arange(4 * n)
    slot = np.tile(np.arange(4), n)
    settle_tol = 1e-14 * max(1.0, arm.scale)
    pos_tol = 1e-10 * max(1.0, arm.scale)
    valid = cat == VALID
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
        sub = solve_core(
            arm,
            p_eff.reshape(-1, 3),
            None if pitch_eff is None else pitch_eff.reshape(-1),
            None if rot_eff is None else rot_eff.reshape(-1, 3, 3),
            None if qc4 is None else qc4.reshape(-1, arm.dof),
            arm.orient_tol,
            internal_pitch=True,
            roll_free=None if roll_free is None else np.repeat(roll_free, 4),
        )
        q_new = sub.q[rows, slot].reshape(n, 4, arm.dof)
        took = valid & (sub.cat[rows, slot].reshape(n, 4) == VALID)
        q = np.where(took[..., None], q_new, q)
        dist = np.where(took, sub.dist[rows, slot].reshape(n, 4), dist)
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
    for _ in range(iterations):
        r = residual(q)
        if np.max(np.abs(r)) <= 1e-15:
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
