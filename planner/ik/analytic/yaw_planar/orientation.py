"""Orientation targets on the ideal geometry: yaw, pitch sum and roll from a rotation or a pitch.

A rotation fixes the yaw (the azimuth of the pitch axis or the roll axis), the in-plane end
angle (the pitch sum) and the roll; an approach pitch fixes the in-plane approach angle per
side (``planner.geometry.target``'s convention: the elevation of the approach axis, its
horizontal part pointing away from the base z axis).
"""

from __future__ import annotations

import math

import numpy as np

from planner.core.rotations import rotation_error
from planner.geometry.chain import rotation_about
from planner.geometry.target import pitch_error
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.branches import CYLINDER, DUPLICATE, ORIENT, VALID

__all__ = ["branch_alpha", "yaw_for_rotation", "pitch_from_rotation", "roll_from_rotation", "ideal_pitch_error"]

PI = math.pi


def branch_alpha(arm: ArmGeometry, pos, psi, pit):
    """In-plane approach angle (n, 2) per side for approach pitch `pit` (n,) at `pos` (n, 3).

    The pitch where the arm's plane direction at yaw psi points away from the base z axis
    (non-negative dot product with the target's horizontal position), else pi - pitch: the
    approach axis's horizontal part then points outward (planner.geometry.target).
    """
    yaw = psi + arm.mu
    outward = np.cos(yaw) * pos[:, 0:1] + np.sin(yaw) * pos[:, 1:2] >= 0.0
    return np.where(outward, pit[:, None], PI - pit[:, None])


def yaw_for_rotation(arm: ArmGeometry, m_rot, hx, hy, d, u, psi, ue, cat, free):
    """Rotation targets: take the yaw from the rotation where it fixes it better.

    The position fixes the yaw only as well as the end point's distance u from the yaw axis
    allows (a position error e turns it by e / u); the rotation fixes it by the azimuth of
    the pitch axis (arms without roll: always) or of the roll axis (unless that is
    vertical). With the yaw from the rotation, the position must lie in the arm's plane:
    its sideways offset must be the arm's ``d`` (else the branch is not achievable).
    """
    n_axis = arm.n
    if arm.has_roll:
        w = m_rot @ arm.r0
        horiz = np.hypot(w[:, 0], w[:, 1])
        psi_a = np.arctan2(w[:, 1], w[:, 0]) - arm.mu
        use = (horiz > 1e-9) & (horiz * arm.scale >= u)
    else:
        w = m_rot @ n_axis
        psi_a = np.arctan2(w[:, 1], w[:, 0]) - math.atan2(n_axis[1], n_axis[0])
        use = np.ones(len(psi_a), dtype=bool)
    if not use.any():
        return psi, ue, cat
    cy, sy = np.cos(arm.mu + psi_a), np.sin(arm.mu + psi_a)
    ue_a = hx * cy + hy * sy  # in-plane and sideways coordinates of the end point at psi_a
    lat_a = hx * sy - hy * cy
    forward = ue_a >= 0.0
    tol = max(arm.consistency_tol, arm.core_len_tol)
    off_plane = np.abs(lat_a - d) > tol
    cat_rot = np.zeros_like(cat)
    if arm.has_roll:
        # psi_a and psi_a + pi (the roll axis pointing forward or back in the arm's frame);
        # the one with the end point in front is the front branch.
        psi_front = np.where(forward, psi_a, psi_a + PI)
        psi_rot = np.stack([psi_front, psi_front + PI], axis=1)
        off_back = np.abs(-lat_a - d) > tol
        cat_rot[:, 0] = np.where(np.where(forward, off_plane, off_back), ORIENT, VALID)
        cat_rot[:, 1] = np.where(np.where(forward, off_back, off_plane), ORIENT, VALID)
    else:
        # One yaw: the end point lies in front of the yaw axis or behind it.
        psi_rot = np.stack([psi_a, psi_a], axis=1)
        bad = np.where(off_plane, ORIENT, VALID)
        cat_rot[:, 0] = np.where(forward, bad, DUPLICATE)
        cat_rot[:, 1] = np.where(forward, DUPLICATE, bad)
    ue_rot = np.stack([np.abs(ue_a), -np.abs(ue_a)], axis=1)
    cat_rot = np.where(cat == CYLINDER, cat, cat_rot)
    use2 = use[:, None]
    return np.where(use2, psi_rot, psi), np.where(use2, ue_rot, ue), np.where(use2, cat_rot, cat)


def pitch_from_rotation(arm: ArmGeometry, m_rot, psi):
    """Pitch sum phi (n, 2), roll (n, 2) or None, residual [rad] (n, 2) for given yaws."""
    e_u, n_axis = arm.e_u, arm.n
    cz, sz = np.cos(psi), np.sin(psi)

    # N = Rz(-psi) M, applied to a vector v: Rz(-psi) (M v).
    def unyaw(v):
        x, y = v[..., 0], v[..., 1]
        return np.stack([cz * x + sz * y, -sz * x + cz * y, np.broadcast_to(v[..., 2], cz.shape)], axis=-1)

    if arm.has_roll:
        x = unyaw((m_rot @ arm.r0)[:, None, :])
        phi = np.arctan2(x[..., 2], x @ e_u) - arm.kappa
        residual = np.arcsin(np.clip(np.abs(x @ n_axis), 0.0, 1.0))
        return phi, None, residual
    x = unyaw((m_rot @ e_u)[:, None, :])
    phi = np.arctan2(x[..., 2], x @ e_u)
    rot_ideal = rotation_about(n_axis, phi)  # (n, 2, 3, 3)
    rz = np.zeros(psi.shape + (3, 3))
    rz[..., 0, 0], rz[..., 0, 1], rz[..., 1, 0], rz[..., 1, 1], rz[..., 2, 2] = cz, -sz, sz, cz, 1.0
    residual = rotation_error(rz @ rot_ideal, np.broadcast_to(m_rot[:, None], rz.shape))
    return phi, None, np.asarray(residual)


def roll_from_rotation(arm: ArmGeometry, m_rot, psi4, phi4):
    """Roll angle (n, 4) that completes yaw psi and pitch sum phi to rotation M (ideal axes)."""
    n_axis, r0 = arm.n, arm.r0
    cz, sz = np.cos(psi4), np.sin(psi4)
    mn = (m_rot @ n_axis)[:, None, :]
    x, y, zc = mn[..., 0], mn[..., 1], mn[..., 2]
    un = np.stack([cz * x + sz * y, -sz * x + cz * y, np.broadcast_to(zc, cz.shape)], axis=-1)
    # y = Rn(-phi) N n ; Rr(theta) n = cos n + sin (r0 x n).
    back = np.einsum("...ij,...j->...i", rotation_about(n_axis, -phi4), un)
    rxn = np.cross(r0, n_axis)
    return np.arctan2(back @ rxn, back @ n_axis)


def ideal_pitch_error(arm: ArmGeometry, q, pos, pit):
    """planner.geometry.target.pitch_error (n, 4) of the ideal model's approach axis at q."""
    sg, idx = arm.signs, arm.pitch_idx
    alpha = arm.beta + sum(s * q[..., i] for s, i in zip(sg, idx))
    yaw = arm.mu + arm.sigma * q[..., 0]
    ca = np.cos(alpha)
    approach = np.stack([ca * np.cos(yaw), ca * np.sin(yaw), np.sin(alpha)], axis=-1)
    return pitch_error(approach, pos[:, None, :], pit[:, None])
