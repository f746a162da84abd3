"""The approach pitch a position-only target leaves free (arms with a wrist pitch).

``q_current``'s approach when given and reachable, else the wrist centre on the line from the
shoulder to the target (straight out) or, when that is too close, at the nearest reachable
distance, approaching from above. The search within the joint limits
(:mod:`~planner.ik.analytic.yaw_planar.search`) may then pick another.
"""

from __future__ import annotations

import math

import numpy as np

from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.branches import BEYOND, INSIDE, VALID
from planner.ik.analytic.yaw_planar.real_model import true_fk, true_pitch

__all__ = ["free_pitch_scalar", "free_pitch_failure", "free_pitch_array", "current_alpha"]

PI = math.pi


def free_pitch_scalar(arm: ArmGeometry, psi, ue, ze, tu, tz, lt, gt, qc):
    """In-plane end angle phi for a position-only target on a wristed arm, or None."""
    su, sz = arm.su, arm.sz
    lo_geo, hi_geo = abs(arm.l1 - arm.l2), arm.l1 + arm.l2
    rmin, rmax = max(lo_geo, arm.rmin_lim), min(hi_geo, arm.rmax_lim)
    if qc is not None:
        # q_current's approach, kept in the world: mirrored when this branch faces the other way.
        alpha = arm.beta + sum(s * qc[i] for s, i in zip(arm.signs, arm.pitch_idx))
        if math.cos(psi - arm.sigma * qc[0]) < 0.0:
            alpha = PI - alpha
        phi = alpha - arm.beta
        cp, sp = math.cos(phi), math.sin(phi)
        dd = math.hypot(ue - (cp * tu - sp * tz) - su, ze - (sp * tu + cp * tz) - sz)
        if rmin - arm.len_tol <= dd <= rmax + arm.len_tol:
            return phi
    ex, ez = ue - su, ze - sz
    de = math.hypot(ex, ez)
    lo = max(abs(de - lt), rmin)
    hi = min(de + lt, rmax)
    if lo > hi + arm.len_tol or de == 0.0:
        return None
    rho = lo
    a = (rho * rho - lt * lt + de * de) / (2.0 * de)
    # On the line through the shoulder (rho = |de - lt|) the circles touch: h is 0, not the
    # square root of round-off (which would move the angle by ~1e-8).
    h = 0.0 if abs(de - lt) >= rmin else math.sqrt(max(rho * rho - a * a, 0.0))
    ux, uz = ex / de, ez / de
    best = None
    for sgn in (1.0, -1.0):
        wx = su + a * ux - sgn * h * uz
        wz = sz + a * uz + sgn * h * ux
        phi = math.atan2(ze - wz, ue - wx) - gt
        lift = math.sin(arm.beta + phi)
        if best is None or lift < best[0] - 1e-15:
            best = (lift, phi)
    return best[1]


def free_pitch_failure(arm: ArmGeometry, ue, ze, lt) -> int:
    """The category (BEYOND or INSIDE) of a side where :func:`free_pitch_scalar` found no angle."""
    de = math.hypot(ue - arm.su, ze - arm.sz)
    return BEYOND if de - lt > min(arm.l1 + arm.l2, arm.rmax_lim) else INSIDE


def free_pitch_array(arm: ArmGeometry, psi, ue, ze, tu, tz, qc):
    """Pitch sum phi (n, 2) and failure category for position-only targets on wristed arms."""
    su, sz = arm.su, arm.sz
    rmin = max(abs(arm.l1 - arm.l2), arm.rmin_lim)
    rmax = min(arm.l1 + arm.l2, arm.rmax_lim)
    lt = np.hypot(tu, tz)
    gt = np.arctan2(tz, tu)
    ex, ez = ue - su, ze - sz
    de = np.hypot(ex, ez)
    lo = np.maximum(np.abs(de - lt), rmin)
    hi = np.minimum(de + lt, rmax)
    fail = np.where((lo > hi + arm.core_len_tol) | (de == 0.0), np.where(de - lt > rmax, BEYOND, INSIDE), VALID)
    safe = np.where(de == 0.0, 1.0, de)
    with np.errstate(over="ignore"):  # a wrist centre almost on the shoulder: those rows fail above
        a = (lo * lo - lt * lt + safe * safe) / (2.0 * safe)
        h = np.where(np.abs(de - lt) >= rmin, 0.0, np.sqrt(np.maximum(lo * lo - a * a, 0.0)))
    ux, uz = ex / safe, ez / safe
    best_phi = None
    best_lift = None
    for sgn in (1.0, -1.0):
        wx = su + a * ux - sgn * h * uz
        wz = sz + a * uz + sgn * h * ux
        phi = np.arctan2(ze - wz, ue - wx) - gt
        lift = np.sin(arm.beta + phi)
        if best_phi is None:
            best_phi, best_lift = phi, lift
        else:
            take = lift < best_lift - 1e-15
            best_phi = np.where(take, phi, best_phi)
            best_lift = np.where(take, lift, best_lift)
    phi = best_phi
    if qc is not None:
        alpha = current_alpha(arm, qc)
        facing = np.cos(psi - arm.sigma * qc[:, 0:1]) >= 0.0
        alpha2 = np.where(facing, alpha[:, None], PI - alpha[:, None])
        phi_c = alpha2 - arm.beta
        cp, sp = np.cos(phi_c), np.sin(phi_c)
        dd = np.hypot(ue - (cp * tu - sp * tz) - su, ze - (sp * tu + cp * tz) - sz)
        ok = (dd >= rmin - arm.core_len_tol) & (dd <= rmax + arm.core_len_tol)
        phi = np.where(ok, phi_c, phi)
        fail = np.where(ok, VALID, fail)
    return phi, fail


def current_alpha(arm: ArmGeometry, qc):
    """In-plane approach angle (n,) of q_current.

    From the ideal model on exact chains, measured on the real one otherwise (its approach
    axis against its arm plane).
    """
    if arm.exact:
        return arm.beta + sum(s * qc[:, i] for s, i in zip(arm.signs, arm.pitch_idx))
    _, rot = true_fk(arm, qc)
    front = true_pitch(arm, qc[:, None, :], rot[:, None])  # (n, 1): alpha as a front branch
    return front[:, 0]
