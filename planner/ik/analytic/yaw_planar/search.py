"""Free joints within the limits: the values a target leaves free, searched per branch.

Where no branch lies within the joint limits at the default choices, ``solve`` and
``solve_batch`` search the joints the target leaves free, per branch: the approach pitch of a
position-only target (:mod:`~planner.ik.analytic.yaw_planar.end_angle`) and the wrist roll where
it moves the tip (SO-101, for position and pitch targets): rolls outwards from ``q_current``'s
every 2.5 deg until one admits the branch, then the boundary by bisection, so the nearest such
roll (a window narrower than a step may be missed). On inexact chains the search runs on the
ideal geometry, keeps clear of its boundaries (1e-4 rad in pitch, 1e-3 rad in roll) and the
result is checked on the real one; where the ideal model is unsure (a branch it misses by about
its deviation, next to a stretched elbow, or a joint next to a limit) the real one decides
(:func:`within_real`).
"""

from __future__ import annotations

import math

import numpy as np

from planner.geometry.chain import wrap_array
from planner.ik.analytic.result import STATUS_CODES, STATUS_SOLVED
from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.arrays import PER_BRANCH, BranchArrays, solve_arrays
from planner.ik.analytic.yaw_planar.branches import VALID
from planner.ik.analytic.yaw_planar.core import ideal_position_error, roll_values, solve_core
from planner.ik.analytic.yaw_planar.end_angle import limit_values, phi_choices, within_ideal
from planner.ik.analytic.yaw_planar.real_model import orientation_errors, true_fk
from planner.ik.analytic.yaw_planar.refine import newton
from planner.ik.analytic.yaw_planar.status import status_codes

__all__ = ["free_joints", "search", "solve_searched", "within_real"]

TWO_PI = 2.0 * math.pi
#: Ideal-model misses [times the chain's deviation and size] the search checks on the real
#: model: next to a stretched elbow the real reach exceeds the ideal one by about the
#: deviation times the arm's size.
NEAR_MISS = 10.0
#: Joint values this close to a limit [rad] on the ideal model are checked on the real one
#: (SO-101's differ by about 4 times its deviation, 1.5e-5 rad).
LIMIT_MARGIN = 1e-3


def free_joints(arm: ArmGeometry, pit, rot) -> tuple[bool, bool]:
    """What a target leaves free that moves the arm: (the in-plane end angle, the wrist roll).

    The end angle of position-only targets on wristed arms; the roll where the tip sits off
    the roll axis.
    """
    if rot is not None:
        return False, False
    return pit is None and arm.n_pitch == 3, arm.has_roll and not arm.tip_on_roll_axis


def search(arm: ArmGeometry, pos, pit, qc, roll_step: float = math.radians(2.5)):
    """Free joint values that put each branch within the limits, per target (ideal model).

    The wrist roll, where it moves the tip: q_current's (else 0) when some end angle (or, for
    pitch targets, the target itself) allows the branch there, else the nearest roll that
    does: sampled every `roll_step` outwards, then bisected to the boundary. The in-plane end
    angle of position-only targets: see :func:`~planner.ik.analytic.yaw_planar.end_angle.phi_choices`.

    Returns:
        found (n, 4); phi, roll (n, 4): the nearest values [rad] (NaN where not free or not
        found); phi_safe, roll_safe (n, 4): values further inside (the middle of the end
        angle's interval, the roll sample), for inexact chains whose real joints may differ
        from the ideal ones at a boundary.
    """
    free_phi, free_roll = free_joints(arm, pit, None)
    n = pos.shape[0]
    # Steps into the intervals with solutions, past their ends: within round-off on exact
    # chains; on inexact ones, past the ideal model's deviation from the real one.
    margin = 1e-9 if arm.exact else 1e-4
    margin_roll = 1e-3
    nan4 = np.full((n, 4), np.nan)

    def oracle(rows, roll, real=True):
        # real: where the ideal model is unsure, the real one decides (not while bisecting:
        # the roll it ends at is decided again).
        q_rows = None if qc is None else qc[rows]
        if free_phi:
            return phi_choices(arm, pos[rows], q_rows, roll, margin)
        pit_rows = None if pit is None else pit[rows]
        core = solve_core(arm, pos[rows], pit_rows, None, q_rows, arm.orient_tol, roll_free=roll)
        ok = within_ideal(arm, core, pos[rows], q_rows)
        if real:
            ok = within_real(arm, core, pos[rows], pit_rows, q_rows, roll, ok)
        return ok, np.full(ok.shape, np.nan), np.full(ok.shape, np.nan)

    roll0 = None
    if free_roll:
        lo, hi = arm.lower[arm.roll_idx], arm.upper[arm.roll_idx]
        bounded = hi - lo < TWO_PI
        roll0 = roll_values(arm, n, qc, None)
        if bounded:
            roll0 = np.clip(roll0, lo, hi)
    found, phi, phi_safe = oracle(np.arange(n), roll0)
    roll = nan4.copy() if roll0 is None else np.repeat(roll0[:, None], 4, axis=1)
    roll_safe = roll.copy()
    pending = ~found
    if not free_roll or not pending.any():
        return found, phi, roll, phi_safe, roll_safe
    # Roll samples outwards from roll0: k steps up, then k steps down, k = 1, 2, ...
    steps = int(math.ceil((hi - lo if bounded else TWO_PI) / roll_step))
    inner = np.full((n, 4), np.nan)
    first = 1
    while first <= steps:
        # A few steps first (often enough), then all the others at once (cheaper than many calls).
        ks = np.arange(first, min(first + 4, steps + 1) if first == 1 else steps + 1)
        first = ks[-1] + 1
        offsets = np.stack([ks, -ks], axis=1).ravel() * roll_step  # (m,)
        samples = roll0[:, None] + offsets
        previous = roll0[:, None] + offsets - np.sign(offsets) * roll_step
        if bounded:
            usable = (previous > lo) & (previous < hi) | (np.abs(previous - roll0[:, None]) < 1e-15)
            usable &= (previous >= lo) & (previous <= hi)
            samples = np.clip(samples, lo, hi)
        else:
            usable = np.ones(samples.shape, dtype=bool)
        targets = np.nonzero(pending.any(axis=1))[0]
        if targets.size == 0:
            break
        m = offsets.size
        rows = np.repeat(targets, m)
        ok, ph, ph_mid = oracle(rows, samples[targets].ravel())
        ok = ok.reshape(targets.size, m, 4) & usable[targets][..., None]
        for a, i in enumerate(targets):
            for s in np.nonzero(pending[i])[0]:
                hit = np.nonzero(ok[a, :, s])[0]
                if hit.size:
                    h = hit[0]
                    found[i, s], pending[i, s] = True, False
                    roll[i, s] = roll_safe[i, s] = samples[i, h]
                    phi[i, s], phi_safe[i, s] = ph[a * m + h, s], ph_mid[a * m + h, s]
                    inner[i, s] = np.clip(previous[i, h], lo, hi) if bounded else previous[i, h]
    # Bisect between the last roll without and the first with a solution, nearest roll0; on
    # inexact chains, then step a little back into the rolls with one (towards the sample).
    pairs = np.nonzero(np.isfinite(inner))
    if pairs[0].size:
        bad, good = inner[pairs].copy(), roll[pairs].copy()
        sample = good.copy()
        # 15 rolls between per round, the bracket 16 times shorter each: to 3e-9 rad on exact
        # chains, on inexact ones to well within the step back.
        parts = 16
        fractions = np.arange(1, parts) / parts
        index = np.arange(len(bad))
        for _ in range(6 if arm.exact else 2):
            trial = bad[:, None] + (good - bad)[:, None] * fractions  # (p, parts - 1)
            ok = oracle(np.repeat(pairs[0], parts - 1), trial.ravel(), False)[0]
            hit = ok[np.arange(trial.size), np.repeat(pairs[1], parts - 1)].reshape(trial.shape)
            # The first trial with a solution (from the bad end): the bracket ends there.
            k = np.where(hit.any(axis=1), np.argmax(hit, axis=1), parts - 1)
            good = np.where(k < parts - 1, trial[index, np.minimum(k, parts - 2)], good)
            bad = np.where(k > 0, trial[index, np.maximum(k - 1, 0)], bad)
        if not arm.exact:
            good = good + np.clip(sample - good, -margin_roll, margin_roll)
        ok, ph, _ = oracle(pairs[0], good)
        hit = ok[np.arange(len(good)), pairs[1]]
        roll[pairs] = np.where(hit, good, roll[pairs])
        phi[pairs] = np.where(hit, ph[np.arange(len(good)), pairs[1]], phi[pairs])
    return found, phi, roll, phi_safe, roll_safe


def within_real(arm: ArmGeometry, core, pos, pit, qc, roll, ok) -> np.ndarray:
    """The mask `ok` (n, 4) of :func:`within_ideal`, decided on the real model where the ideal one is unsure.

    On inexact chains the ideal model's answer can be wrong by about its deviation: next to a
    stretched elbow the real arm reaches wrist points up to about the deviation times its size
    beyond the ideal reach (SO-101: a window of wrist rolls 3 deg wide where the ideal model
    misses by 3e-7 m), and joint values next to a limit may lie on its other side on the real
    arm. Branches valid on the ideal model, clear of the yaw axis, that miss the target by more
    than round-off but less than :data:`NEAR_MISS` times the deviation and size, or reach it
    with a joint within :data:`LIMIT_MARGIN` of a limit, are solved on the real model
    (Newton's steps of :func:`~planner.ik.analytic.yaw_planar.refine.newton`, checked as
    ``refine`` checks), whose answer they take.
    """
    n = pos.shape[0]
    if arm.exact or n == 0:
        return ok
    error = ideal_position_error(arm, core, pos)
    scale = max(1.0, arm.scale)
    near = (core.cat == VALID) & ~core.seeded[:, None] & (error <= NEAR_MISS * arm.deviation * arm.scale)
    edge = error > 1e-10 * scale
    for j in range(arm.dof):
        # The roll is an input here, the same on both models.
        if limit_values(arm, j) and j != arm.roll_idx:
            lo, hi = arm.lower[j], arm.upper[j]
            col = wrap_array(core.q[..., j], lo, hi, qc[:, j][:, None] if qc is not None else 0.0)
            edge |= (np.abs(col - lo) < LIMIT_MARGIN) | (np.abs(col - hi) < LIMIT_MARGIN)
    near &= edge
    rows = np.nonzero(near.any(axis=1))[0]
    if rows.size == 0:
        return ok
    # Newton's steps on the real model (refine's, without its damped steps: a branch they do
    # not settle counts as not reaching), then the checks of refine and within_ideal.
    sub = near[rows]
    q = newton(arm, core.q[rows], sub, pos[rows], core.world_pitch[rows], None)
    fk_p, fk_r = true_fk(arm, q)
    real = sub & (np.linalg.norm(fk_p - pos[rows][:, None, :], axis=-1) <= 1e-10 * scale)
    errors = orientation_errors(arm, fk_r, pos[rows], None if pit is None else pit[rows], None)
    if errors is not None:
        real &= errors <= 1e-9
    qc_rows = None if qc is None else qc[rows]
    for j in range(arm.dof):
        if limit_values(arm, j):
            lo, hi = arm.lower[j], arm.upper[j]
            col = wrap_array(q[..., j], lo, hi, qc_rows[:, j][:, None] if qc_rows is not None else 0.0)
            real &= (col >= lo) & (col <= hi)
    out = ok.copy()
    out[rows] = np.where(sub, real, ok[rows])
    return out


def solve_searched(arm: ArmGeometry, pos, pit, qc, base: BranchArrays, orientation_errors: bool = True) -> BranchArrays:
    """`solve_arrays`' result `base`, re-solved at free joint values within the limits.

    For the targets without a solution within the limits, each branch at the values `search`
    finds. Branches the search finds nothing for keep their solution at the default values.
    """
    todo = np.nonzero(base.status != STATUS_CODES[STATUS_SOLVED])[0]
    if todo.size == 0:
        return base
    sub_pit = None if pit is None else pit[todo]
    sub_qc = None if qc is None else qc[todo]
    found, phi, roll, phi_safe, roll_safe = search(arm, pos[todo], sub_pit, sub_qc)
    if not found.any():
        return base
    m = todo.size
    slots = np.tile(np.arange(4), m)
    use = np.zeros((m, 4), dtype=bool)
    chosen = None
    for phi_s, roll_s in ((phi, roll), (phi_safe, roll_safe)):
        retry = found & ~use
        if not retry.any():
            break
        phi_rows = np.full((4 * m, 2), np.nan)
        phi_rows[np.arange(4 * m), slots // 2] = phi_s.ravel()
        a = solve_arrays(
            arm,
            np.repeat(pos[todo], 4, axis=0), None if sub_pit is None else np.repeat(sub_pit, 4),
            None, None if sub_qc is None else np.repeat(sub_qc, 4, axis=0), orientation_errors,
            phi_free=phi_rows, roll_free=roll_s.ravel(),
        )  # fmt: skip
        a = a.branch_diagonal(m)
        ok = retry & a.within
        if chosen is None:
            chosen = a.copy()
        else:
            for name in PER_BRANCH:
                value = getattr(a, name)
                if value is not None:
                    getattr(chosen, name)[ok] = value[ok]
        use |= ok
    if not use.any():
        return base
    out = base.copy()
    for name in PER_BRANCH:
        value, merged = getattr(chosen, name), getattr(out, name)
        if value is not None and merged is not None:
            part = merged[todo]
            part[use] = value[use]
            merged[todo] = part
    rows = out.q[todo]
    status = status_codes(arm, out.cat[todo], out.valid[todo], out.within[todo], out.dist[todo])
    out.status[todo] = status
    if sub_qc is not None:
        dist2 = np.sum((rows - sub_qc[:, None, :]) ** 2, axis=-1)
    else:
        dist2 = np.broadcast_to(np.arange(4.0), (m, 4))
    within = out.within[todo]
    out.best[todo] = np.where(within.any(axis=1), np.argmin(np.where(within, dist2, np.inf), axis=1), -1)
    return out
