"""The approach pitch a position-only target leaves free, within the joint limits.

The pitch joints are continuous functions of the in-plane end angle, and the angles where a
branch appears or a pitch joint meets a limit are the roots of ``|V - R(phi) m|^2 = k`` (closed
form, up to 16 per branch side); testing one point inside each interval between them (and the
roots themselves, where a joint's extreme value just meets its limit) gives every interval
within the limits, and the branch takes the angle nearest the preferred one.
"""

from __future__ import annotations

import math

import numpy as np

from planner.geometry.chain import wrap_array
from planner.ik.analytic.geometry import wrap_pi
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.branches import VALID
from planner.ik.analytic.yaw_planar.core import CoreBranches, ideal_position_error, solve_core

__all__ = ["limit_values", "within_ideal", "phi_boundaries", "intervals", "phi_choices"]

PI = math.pi
TWO_PI = 2.0 * math.pi


def limit_values(arm: ArmGeometry, j: int) -> tuple[float, ...]:
    """Joint j's limits, or () when every angle has an equivalent within them."""
    lo, hi = arm.lower[j], arm.upper[j]
    return (lo, hi) if hi - lo < TWO_PI else ()


def within_ideal(arm: ArmGeometry, core: CoreBranches, pos, qc):
    """Mask (n, 4): the ideal core's branch reaches the target and lies within the limits.

    Reaches `pos` (n, 3) to 1e-10 m (not merely within the core's reach tolerance); the
    limits checked after wrapping as in `solve_arrays`. On inexact chains, also clear of
    the yaw axis's cylinder by more than the start separation of `solve_core` (closer, the
    correction onto the real geometry is unreliable).
    """
    q = core.q
    within = core.cat == VALID
    within &= ideal_position_error(arm, core, pos) <= 1e-10 * max(1.0, arm.scale)
    if not arm.exact:
        within &= ~core.seeded[:, None]
    for j in range(arm.dof):
        if limit_values(arm, j):
            lo, hi = arm.lower[j], arm.upper[j]
            col = wrap_array(q[..., j], lo, hi, qc[:, j][:, None] if qc is not None else 0.0)
            within &= (col >= lo) & (col <= hi)
    return within


def phi_boundaries(arm: ArmGeometry, ue, ze, tu, tz):
    """In-plane end angles (n, 2, K) [rad] where a branch appears or a pitch joint meets a limit.

    Between two of them (on the circle) every branch exists or not throughout and keeps each
    pitch joint within its limits or outside them, since the joints are continuous functions
    of the end angle phi there. Each boundary is a root of ``|V - R(phi) m|^2 = k`` for an
    in-plane vector V fixed by the end point and m by the end vector, i.e. of
    ``cos(phi + angle(m) - angle(V)) = (|V|^2 + |m|^2 - k) / (2 |V| |m|)``: the wrist point
    at the reach of the shoulder-elbow pair (its ends, and the elbow at a limit: the law of
    cosines), at link 2's length from the elbow of the shoulder at a limit, or the elbow at
    link 1's length from the shoulder with the wrist at a limit (links 2 and 3 then one
    rigid vector m). NaN pads rows with fewer roots.
    """
    su, sz, l1, l2, g1, g2 = arm.su, arm.sz, arm.l1, arm.l2, arm.g1, arm.g2
    s0, s1, s2 = arm.signs
    i0, i1, i2 = arm.pitch_idx
    # Per equation: the offset of V from (end point - shoulder), m - (end vector), and k.
    eqs = [(0.0, 0.0, 0.0, 0.0, (l1 + l2) ** 2), (0.0, 0.0, 0.0, 0.0, (l1 - l2) ** 2)]
    for limit in limit_values(arm, i1):
        e = s1 * limit - g1 + g2
        eqs.append((0.0, 0.0, 0.0, 0.0, l1 * l1 + l2 * l2 + 2.0 * l1 * l2 * math.cos(e)))
    for limit in limit_values(arm, i0):
        a = s0 * limit + g1
        eqs.append((-l1 * math.cos(a), -l1 * math.sin(a), 0.0, 0.0, l2 * l2))
    for limit in limit_values(arm, i2):
        c = g2 - s2 * limit
        eqs.append((0.0, 0.0, l2 * math.cos(c), l2 * math.sin(c), l1 * l1))
    dvx, dvz, dmx, dmz, k = (np.array(col) for col in zip(*eqs))
    ax = (ue - su)[..., None] + dvx  # (n, 2, E)
    az = (ze[:, None] - sz)[..., None] + dvz
    mx = tu[:, None, None] + dmx
    mz = tz[:, None, None] + dmz
    v2, m2 = ax * ax + az * az, mx * mx + mz * mz
    denom = 2.0 * np.sqrt(v2 * m2)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = (v2 + m2 - k) / denom
    # A tangency (a joint's extreme value exactly at its limit) may round to |c| just above 1.
    ok = (denom > 0.0) & (np.abs(c) <= 1.0 + 1e-12)
    base = np.arctan2(az, ax) - np.arctan2(mz, mx)
    half = np.arccos(np.clip(np.where(ok, c, 0.0), -1.0, 1.0))
    roots = np.concatenate([np.where(ok, base + half, np.nan), np.where(ok, base - half, np.nan)], axis=-1)
    return wrap_pi(roots)


def intervals(bounds, pref):
    """The circular intervals between boundary angles.

    Args:
        bounds: Shape S + (K,) [rad], NaN-padded.
        pref: Shape S [rad].

    Returns:
        start, end, valid (S + (K,)): interval j runs from the j-th smallest boundary to the
        next (the last one to the first + 2 pi); without boundaries, one interval, the whole
        circle centred on `pref`.
    """
    b = np.sort(bounds, axis=-1)
    k = b.shape[-1]
    count = np.sum(np.isfinite(b), axis=-1)[..., None]
    j = np.arange(k)
    following = np.concatenate([b[..., 1:], b[..., :1]], axis=-1)
    end = np.where(j == count - 1, b[..., :1] + TWO_PI, following)
    whole = (count == 0) & (j == 0)
    start = np.where(whole, pref[..., None] - PI, b)
    end = np.where(whole, pref[..., None] + PI, end)
    return start, end, (j < count) | whole


def phi_choices(arm: ArmGeometry, pos, qc, roll_free, margin):
    """Per branch, the in-plane end angle within the limits nearest the default one.

    For position-only targets on wristed arms, on the ideal model.

    Returns:
        feasible (n, 4): some end angle puts the branch within the limits; phi (n, 4) [rad]:
        the default angle where it does, else the nearest end of the nearest interval that
        does, moved `margin` (at most half the interval) into it; phi_mid (n, 4) [rad]: the
        default angle or the middle of that interval. NaN where not feasible.
    """
    n = pos.shape[0]
    core = solve_core(arm, pos, None, None, qc, arm.orient_tol, roll_free=roll_free)
    pref = np.nan_to_num(core.phi)
    bounds = phi_boundaries(arm, core.ue, core.ze, core.tu, core.tz)
    start, end, valid = intervals(bounds, pref)
    if arm.exact:
        # The boundaries themselves too, as intervals of zero width: where a joint's extreme
        # value just meets its limit, the one point there may be all there is. (Inexact
        # chains keep only intervals wide enough for the real arm to share.)
        start = np.concatenate([start, bounds], axis=-1)
        end = np.concatenate([end, bounds], axis=-1)
        valid = np.concatenate([valid, np.isfinite(bounds)], axis=-1)
    mid = 0.5 * (start + end)
    k = start.shape[-1]

    def rep(a):
        return None if a is None else np.repeat(a, k, axis=0)

    sub = solve_core(
            arm,
        rep(pos), None, None, rep(qc), arm.orient_tol,
        phi_free=np.where(valid, mid, 0.0).transpose(0, 2, 1).reshape(n * k, 2), roll_free=rep(roll_free),
    )  # fmt: skip
    side = [0, 0, 1, 1]
    ok = within_ideal(arm, sub, rep(pos), rep(qc)).reshape(n, k, 4).transpose(0, 2, 1) & valid[:, side]
    start, end, mid, pref = start[:, side], end[:, side], mid[:, side], pref[:, side]
    width = end - start
    if not arm.exact:
        ok &= width >= 2.0 * margin  # narrower, the real arm may have none
    inset = np.minimum(margin, 0.5 * width)
    # The point of each interval nearest pref (at least `inset` inside it), unwrapped near pref.
    shifted = start + (pref[..., None] - start) % TWO_PI
    near = np.where(
        shifted <= end,
        np.clip(shifted, start + inset, end - inset),
        np.where(shifted - end <= start + TWO_PI - shifted, end - inset, start + inset + TWO_PI),
    )
    dist = np.where(ok, np.abs(near - shifted), np.inf)
    best = np.argmin(dist, axis=-1)[..., None]
    feasible = np.isfinite(np.take_along_axis(dist, best, axis=-1)[..., 0])
    phi = wrap_pi(np.take_along_axis(near, best, axis=-1)[..., 0])
    inside = np.take_along_axis(shifted <= end, best, axis=-1)[..., 0]
    phi_mid = np.where(inside, phi, wrap_pi(np.take_along_axis(mid, best, axis=-1)[..., 0]))
    return feasible, np.where(feasible, phi, np.nan), np.where(feasible, phi_mid, np.nan)
