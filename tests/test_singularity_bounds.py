"""The bounded singularity measure against the exact one (every sample through Robot.conditioning)."""

from __future__ import annotations

import numpy as np
import pytest
from dh_arms import property_settings
from hypothesis import given
from hypothesis import strategies as st

from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory
from planner.motion.singularity import (
    SingularityReport,
    bounded_conditioning,
    inverse_condition_threshold,
    measure_singularities,
)

from conftest import HAVE_EXAMPLE_ROBOT_DATA, get_robot

ARMS = ["dh3", "al5c", "three_joint", "shelley"] + (["ur5", "panda", "z1"] if HAVE_EXAMPLE_ROBOT_DATA else [])


def _intervals(t: np.ndarray, low: np.ndarray) -> tuple[tuple[float, float], ...]:
    """The runs of `low` as (first, last) times: written out again here, independent of the module."""
    out, start = [], None
    for k, flag in enumerate(low):
        if flag and start is None:
            start = k
        if start is not None and (not flag or k == len(low) - 1):
            end = k if flag else k - 1
            out.append((float(t[start]), float(t[end])))
            start = None
    return tuple(out)


def _reference(robot, trajectory, threshold, task, rate) -> tuple[SingularityReport, np.ndarray, np.ndarray]:
    """The report as computed before the bounds: every sample measured exactly."""
    t = np.unique(np.concatenate([trajectory.times(rate), trajectory.waypoint_times]))
    q = trajectory.sample(t).q
    inv, man = robot.conditioning(q, task)
    w = np.searchsorted(t, trajectory.waypoint_times)
    k = int(np.argmin(inv))
    report = SingularityReport(
        threshold=threshold,
        task=task,
        rate=rate,
        waypoint_inverse_condition=inv[w],
        waypoint_manipulability=man[w],
        singular_waypoints=tuple(int(i) for i in np.nonzero(inv[w] < threshold)[0]),
        min_inverse_condition=float(inv[k]),
        min_manipulability=float(np.min(man)),
        time_of_minimum=float(t[k]),
        q_at_minimum=q[k],
        below_threshold=_intervals(t, inv < threshold),
    )
    return report, inv, man


def _check_bounded(inv, man, inv_all, man_all, threshold, keep) -> None:
    """What bounded_conditioning promises, against the exact values (man None: not checked).

    Exact at the rows `keep` and at the minimum (the global one, and that of every stretch between
    two rows of `keep` that dips below the threshold); elsewhere a lower bound on the same side of
    the threshold, above the threshold and the global minimum when above, above its stretch's
    minimum when below.
    """
    exact = inv == inv_all
    assert np.array_equal(inv < threshold, inv_all < threshold)
    assert np.all(inv <= inv_all) and exact[keep].all()
    assert inv.min() == inv_all.min() and int(np.argmin(inv)) == int(np.argmin(inv_all))
    assert np.all(inv[~exact & (inv_all >= threshold)] > max(threshold, inv_all.min()))
    ends = np.unique(np.concatenate([[0, len(inv) - 1], keep]))
    for a, b in zip(ends[:-1], ends[1:]):
        piece, piece_all = inv[a : b + 1], inv_all[a : b + 1]
        if piece_all.min() < threshold:
            assert int(np.argmin(piece)) == int(np.argmin(piece_all)) and piece.min() == piece_all.min()
            assert np.all(piece[piece != piece_all] > piece_all.min())
    if man is not None:
        assert np.all(man <= man_all) and np.array_equal(man[keep], man_all[keep])
        assert man.min() == man_all.min() and np.all(man[man != man_all] > man_all.min())


@pytest.mark.parametrize("name", ARMS)
@given(seed=st.integers(0, 2**32 - 1), points=st.integers(2, 4), scale=st.sampled_from([1.0, 3.0, 10.0]))
@property_settings(8)
def test_bounded_measure_matches_the_exact_one(name, seed, points, scale):
    robot = get_robot(name)
    task = robot.resolve_task(None)
    # Thresholds up to 10 times the default: most samples near it, where bounds must give way.
    threshold = min(inverse_condition_threshold(None, task) * scale, 0.5)
    q = robot.random_configurations(np.random.default_rng(seed), points)
    trajectory = plan_trajectory(q, JointLimits.from_robot(robot))
    expected, inv_all, man_all = _reference(robot, trajectory, threshold, task, 1000.0)
    report, t, _, inv = measure_singularities(robot, trajectory, threshold, task, 1000.0)
    for field in expected.__dataclass_fields__:
        got, want = getattr(report, field), getattr(expected, field)
        if isinstance(want, np.ndarray):
            assert np.array_equal(got, want), field
        else:
            assert got == want, field
    # Exact below the threshold and at the minimum, a lower bound above the threshold elsewhere.
    _check_bounded(inv, None, inv_all, None, threshold, np.searchsorted(t, trajectory.waypoint_times))


@pytest.mark.parametrize("name", ARMS)
def test_bounded_conditioning_bounds_both_measures(name):
    robot = get_robot(name)
    task = robot.resolve_task(None)
    rng = np.random.default_rng(7)
    # A dense random walk, and rows far apart (bounds useless: everything measured).
    walk = robot.random_configurations(rng, 1) + np.cumsum(rng.normal(0.0, 2e-3, (3000, robot.dof)), axis=0)
    walk = np.clip(walk, robot.lower, robot.upper)
    for q in (walk, robot.random_configurations(rng, 200)):
        inv_all, man_all = robot.conditioning(q, task)
        inv, man = bounded_conditioning(robot, q, task, inverse_condition_threshold(None, task), keep=[5])
        assert np.all(inv <= inv_all) and np.all(man <= man_all)
        assert inv.min() == inv_all.min() and man.min() == man_all.min()
        assert int(np.argmin(inv)) == int(np.argmin(inv_all))
        assert inv[5] == inv_all[5] and man[5] == man_all[5]


@pytest.mark.parametrize("name", ARMS)
def test_conditioning_in_a_batch_equals_one_by_one(name):
    # Detours' gradient steps measure several configurations in one batch.
    robot = get_robot(name)
    q = robot.random_configurations(np.random.default_rng(11), 50)
    inv, man = robot.conditioning(q)
    for k, row in enumerate(q):
        one_inv, one_man = robot.conditioning(row)
        assert float(one_inv) == inv[k] and float(one_man) == man[k]


@pytest.mark.parametrize("name", ARMS)
@pytest.mark.parametrize("task", ["position", "pose"])
def test_conditioning_equals_the_direct_formula(name, task):
    # Written out as before the split into task_jacobians / task_singular_values / conditioning_from.
    robot = get_robot(name)
    q = robot.random_configurations(np.random.default_rng(13), 40)
    length = robot.characteristic_length
    prismatic = np.array(robot.joint_kinds) == "prismatic"
    jacs = np.array([robot.jacobian(row) for row in q])
    jacs = jacs[:, :3] if task == "position" else jacs
    scaled = jacs * np.where(prismatic, length, 1.0)
    if task == "pose":
        scaled[:, 3:] *= length
    k = min(jacs.shape[1:])
    s = np.linalg.svd(scaled, compute_uv=False)[:, :k]
    inverse = np.divide(s[:, -1], s[:, 0], out=np.zeros(len(q)), where=s[:, 0] != 0.0)
    if not prismatic.any() and task == "position":
        manipulability = np.prod(s, axis=1)
    elif not prismatic.any() and robot.dof >= 6:
        manipulability = np.prod(s, axis=1) / length**3
    else:
        manipulability = np.prod(np.linalg.svd(jacs, compute_uv=False)[:, :k], axis=1)
    inv, man = robot.conditioning(q, task)
    assert np.array_equal(inv, inverse) and np.array_equal(man, manipulability)


@pytest.mark.parametrize("name", ARMS)
@pytest.mark.parametrize("task", ["position", "pose"])
def test_the_jacobian_moves_no_farther_than_its_bound(name, task):
    """||J(q1) - J(q0)||_F (scaled and raw, by Pinocchio) <= the bound from the joint change alone."""
    from planner.motion.singularity import jacobian_change_bound, jacobian_change_bounds

    robot = get_robot(name)
    change = jacobian_change_bounds(robot, task)
    if change is None:
        pytest.skip(f"{name}: no joint-change bound (sliding joints or a branched chain)")
    rho, angular, raw_angular = change
    rng = np.random.default_rng(17)
    q0 = robot.random_configurations(rng, 300)
    for size in (1e-3, 3e-2, 0.3, 3.0):
        q1 = q0 + rng.normal(0.0, size, q0.shape)
        raw0, scaled0 = robot.task_jacobians(q0, task)
        raw1, scaled1 = robot.task_jacobians(q1, task)
        moved = np.linalg.norm(scaled1 - scaled0, axis=(1, 2))
        assert np.all(moved <= jacobian_change_bound(q1 - q0, rho, angular) * (1 + 1e-12) + 1e-15), (name, size)
        moved_raw = np.linalg.norm(raw1 - raw0, axis=(1, 2))
        assert np.all(moved_raw <= jacobian_change_bound(q1 - q0, rho, raw_angular) * (1 + 1e-12) + 1e-15), (name, size)
    # One joint at a time (the earlier joints turn the column as a whole: where the bound is tight).
    raw0, scaled0 = robot.task_jacobians(q0, task)
    for j in range(robot.dof):
        for size in (1e-4, 1e-2, 0.5):
            u = np.zeros_like(q0)
            u[:, j] = size * rng.choice([-1.0, 1.0], len(q0))
            raw1, scaled1 = robot.task_jacobians(q0 + u, task)
            moved = np.linalg.norm(scaled1 - scaled0, axis=(1, 2))
            assert np.all(moved <= jacobian_change_bound(u, rho, angular) * (1 + 1e-12) + 1e-15), (name, j, size)
            moved_raw = np.linalg.norm(raw1 - raw0, axis=(1, 2))
            assert np.all(moved_raw <= jacobian_change_bound(u, rho, raw_angular) * (1 + 1e-12) + 1e-15), (name, j)


@pytest.mark.parametrize("name", ARMS)
@pytest.mark.parametrize("task", ["position", "pose"])
def test_the_jacobian_bends_no_more_than_its_curvature_bound(name, task):
    """Halfway along a straight joint move, ||J(mid) - (J(q0) + J(q1)) / 2||_F <= curvature / 8 (Pinocchio)."""
    from planner.motion.singularity import jacobian_change_bounds, jacobian_curvature_bound

    robot = get_robot(name)
    change = jacobian_change_bounds(robot, task)
    if change is None:
        pytest.skip(f"{name}: no joint-change bound (sliding joints or a branched chain)")
    rho, angular, raw_angular = change
    rng = np.random.default_rng(19)
    q0 = robot.random_configurations(rng, 300)
    moves = [rng.normal(0.0, size, q0.shape) for size in (1e-3, 3e-2, 0.3, 3.0)]
    for j in range(robot.dof):  # one joint at a time, and all but one
        for size in (1e-2, 0.5):
            u = np.zeros_like(q0)
            u[:, j] = size
            moves += [u, rng.normal(0.0, size, q0.shape) * (u == 0)]
    raw0, scaled0 = robot.task_jacobians(q0, task)
    for u in moves:
        raw1, scaled1 = robot.task_jacobians(q0 + u, task)
        raw_mid, scaled_mid = robot.task_jacobians(q0 + 0.5 * u, task)
        bent = np.linalg.norm(scaled_mid - 0.5 * (scaled0 + scaled1), axis=(1, 2))
        assert np.all(bent <= jacobian_curvature_bound(u, rho, angular) / 8 * (1 + 1e-12) + 1e-15), name
        bent_raw = np.linalg.norm(raw_mid - 0.5 * (raw0 + raw1), axis=(1, 2))
        assert np.all(bent_raw <= jacobian_curvature_bound(u, rho, raw_angular) / 8 * (1 + 1e-12) + 1e-15), name


@pytest.mark.parametrize("name", ARMS)
@pytest.mark.parametrize("task", ["position", "pose"])
def test_a_row_off_the_line_is_within_the_interpolation_error_of_its_neighbours(name, task):
    """What step 2 of bounded_conditioning relies on: for rows q_r near the straight joint line
    between two exact rows (any lam, not only halfway, and off the line), ||J(q_r) - ((1 - lam)
    J_left + lam J_right)||_F <= the bound of _interpolation_error (Pinocchio's Jacobians)."""
    from planner.motion.singularity import _interpolation_error, jacobian_change_bounds

    robot = get_robot(name)
    change = jacobian_change_bounds(robot, task)
    if change is None:
        pytest.skip(f"{name}: no joint-change bound (sliding joints or a branched chain)")
    rho, angular, _ = change
    rng = np.random.default_rng(31)
    for size, off in ((1e-3, 1e-5), (3e-2, 1e-3), (0.3, 1e-2), (2.0, 0.1)):
        n, gap = 200, 16
        left_q = robot.random_configurations(rng, n)
        right_q = left_q + rng.normal(0.0, size, left_q.shape)
        r = rng.integers(1, gap, n)
        lam = r / gap
        row_q = left_q + lam[:, None] * (right_q - left_q) + rng.normal(0.0, off, left_q.shape)
        # Laid out as bounded_conditioning sees them: each row at lam between its exact neighbours.
        left = np.arange(n) * 2 * gap
        right = left + gap
        rows = left + r
        q_big = np.zeros((int(right[-1]) + 1, robot.dof))
        q_big[left], q_big[rows], q_big[right] = left_q, row_q, right_q
        got_lam, err = _interpolation_error(q_big, rows, left, right, (rho, angular))
        np.testing.assert_allclose(got_lam, lam, rtol=0, atol=1e-15)
        _, s_left = robot.task_jacobians(left_q, task)
        _, s_right = robot.task_jacobians(right_q, task)
        _, s_row = robot.task_jacobians(row_q, task)
        interpolated = (1.0 - lam)[:, None, None] * s_left + lam[:, None, None] * s_right
        missed = np.linalg.norm(s_row - interpolated, axis=(1, 2))
        assert np.all(missed <= err * (1 + 1e-12) + 1e-15), (name, size, float(np.max(missed / err)))


@pytest.mark.parametrize("name", ARMS)
@pytest.mark.parametrize("task", ["position", "pose"])
def test_the_interval_bounds_hold_at_every_row_between_exact_rows(name, task):
    """Step 0 of bounded_conditioning: one lower bound of the inverse condition number and of the
    product of the singular values per interval between exact rows, against every row of dense
    smooth walks (Pinocchio's Jacobians, NumPy's SVD): through a straight arm's neighbourhood and
    from random configurations, at spacings and speeds where the bound is tight and where it is
    useless, with exact rows at a regular and at an irregular spacing."""
    from planner.motion.singularity import _interval_bounds, jacobian_change_bounds

    robot = get_robot(name)
    change = jacobian_change_bounds(robot, task)
    if change is None or robot.manipulability_divisor(task) is None:
        pytest.skip(f"{name}: step 0 needs the joint-change bound and the scaled Jacobian's product")
    rho, angular, _ = change
    rng = np.random.default_rng(37)
    starts = robot.random_configurations(rng, 3)
    starts[0] = np.clip(np.zeros(robot.dof), robot.lower, robot.upper)  # a straight arm: singular
    useful = below = 0
    for q0 in starts:
        for speed in (3e-4, 3e-3, 3e-2):
            # Smooth walks: random jerks integrated three times, like a jerk-limited trajectory.
            jerk = rng.normal(0.0, 1.0, (2000, robot.dof))
            walk = np.cumsum(np.cumsum(np.cumsum(jerk, axis=0), axis=0), axis=0)
            walk = q0 + speed * walk / max(float(np.max(np.abs(np.diff(walk, axis=0)))), 1e-300)
            raw, scaled = robot.task_jacobians(walk, task)
            s = robot.task_singular_values(raw, scaled, task)[0]
            inv_all = s[:, -1] / s[:, 0]
            product = np.prod(s, axis=1)
            for exact_rows in (np.arange(0, len(walk), 16), np.unique(rng.integers(0, len(walk), 150))):
                ends = np.unique(np.concatenate([[0, len(walk) - 1], exact_rows]))
                rows = np.setdiff1d(np.arange(len(walk)), ends)
                right = np.searchsorted(ends, rows)
                left, right = ends[right - 1], ends[right]
                lo_inv, lo_product, hi_inv = _interval_bounds(walk, rows, left, right, scaled, s, (rho, angular))
                assert np.all(lo_inv <= inv_all[rows]), (name, task, speed)
                assert np.all(hi_inv >= inv_all[rows]), (name, task, speed)
                below += int(np.sum(hi_inv < 2.0 * inv_all[rows]))
                assert np.all(lo_product <= product[rows]), (name, task, speed)
                useful += int(np.sum(lo_inv > 0.5 * inv_all[rows]))
    assert useful > 0.2 * 3 * 3 * 2 * 1900, (name, task, useful)  # not vacuous: tight on many rows
    assert below > 0.1 * 3 * 3 * 2 * 1900, (name, task, below)


@given(
    seed=st.integers(0, 2**32 - 1),
    shape=st.sampled_from([(3, 3), (3, 6), (6, 6), (6, 7), (7, 6)]),
    size=st.floats(1e-7, 0.3),
)
@property_settings(40)
def test_the_manipulability_alone_certificate_holds_within_e(seed, shape, size):
    """Step 2's bound of the manipulability alone (see _inverse_trace): every matrix within e of
    J_lam in the Frobenius norm has a product of singular values of at least sqrt(det(G - f^2 I))
    (1 - e^2 / f^2)^(k / 2), G = J_lam's Gram matrix, f^2 = e (k / tr(G^-1))^(1/2); against
    NumPy's SVD, the change random and the one that lowers J_lam's smallest singular value by e."""
    from planner.motion.singularity import _inverse_trace

    rng = np.random.default_rng(seed)
    k = min(shape)
    j_lam = rng.normal(size=(300, *shape)) * 10.0 ** rng.uniform(-2, 0, (300, 1, shape[1]))
    u, s, vt = np.linalg.svd(j_lam)
    shift = size * np.sqrt(k / _inverse_trace(j_lam))
    shown = (s[:, -1] ** 2 > shift) & (shift > size * size)
    bound = np.sqrt(np.prod(np.maximum(s * s - shift[:, None], 0.0), axis=1)) * np.maximum(
        1 - size * size / shift, 0.0
    ) ** (k / 2)
    random = rng.normal(size=j_lam.shape)
    random *= size / np.linalg.norm(random, axis=(1, 2))[:, None, None]
    lowest = -size * u[:, :, k - 1 : k] @ vt[:, k - 1 : k, :]
    for change in (random, lowest):
        product = np.prod(np.linalg.svd(j_lam + change, compute_uv=False), axis=1)
        assert np.all(product[shown] >= bound[shown] * (1 - 1e-9)), float(np.min(product[shown] / bound[shown]))
    # Not vacuous: shown on many matrices where e is small, and tight where it is small beside the
    # smallest singular value.
    assert shown.sum() > 30 or size > 1e-3
    small = shown & (size < 1e-3 * s[:, -1])
    if small.any():
        assert np.median(bound[small] / np.prod(s[small], axis=1)) > 0.98


@pytest.mark.parametrize("compiled", [True, False])
def test_the_cholesky_certificate_agrees_with_the_eigenvalues(compiled, monkeypatch):
    # Gram matrices with a known spectrum, shifted just below and above their smallest eigenvalue,
    # through the compiled loops and through NumPy.
    import planner.motion.singularity as singularity
    from planner.motion.singularity import _extreme_bounds, _positive_definite

    if not compiled:
        monkeypatch.setattr(singularity, "cholesky_certificates", lambda gram, shift: None)
        monkeypatch.setattr(singularity, "extreme_bounds", lambda gram: None)
    rng = np.random.default_rng(23)
    for k in (2, 3, 6):
        basis = np.linalg.qr(rng.normal(size=(400, k, k)))[0]
        values = np.sort(10.0 ** rng.uniform(-8, 1, (400, k)), axis=1)
        gram = basis @ (values[:, :, None] * basis.transpose(0, 2, 1))
        trace = values.sum(axis=1)
        below = values[:, 0] * (1 - 1e-6) - 2e-12 * trace
        ok, product = _positive_definite(gram, below)
        clear = values[:, 0] - below > 1e-10 * trace  # well above rounding
        assert ok[clear].all()
        # Where it holds, the pivots' product bounds the product of the excesses from below.
        assert np.all(product[ok] <= np.prod(values[ok] - below[ok, None], axis=1) * (1 + 1e-6))
        ok_above, product_above = _positive_definite(gram, values[:, 0] * (1 + 1e-6))
        assert not ok_above.any() and not product_above.any()
        # The extreme eigenvalues and the determinant are bracketed, tightly on most matrices.
        low_min, high_min, low_max, high_max, product = _extreme_bounds(gram).T
        assert np.all(low_min <= values[:, 0]) and np.all(high_min >= values[:, 0])
        assert np.all(low_max <= values[:, -1]) and np.all(high_max >= values[:, -1])
        assert np.all(product <= np.prod(values, axis=1) * (1 + 1e-9))
        assert np.median(low_min / values[:, 0]) > 1 - 1e-3 and np.median(high_min / values[:, 0]) < 1 + 1e-3
        assert np.median(low_max / values[:, -1]) > 1 - 1e-3 and np.median(high_max / values[:, -1]) < 1 + 1e-3


@pytest.mark.parametrize("name", ARMS)
def test_bounded_measure_equals_the_one_by_one_measure(name):
    # Dense random walks through a singular configuration's neighbourhood and far from it, at
    # thresholds from 0 to where nearly every row is below: the exact rows equal Robot.conditioning
    # of that configuration alone, the others are bounds as bounded_conditioning promises.
    robot = get_robot(name)
    task = robot.resolve_task(None)
    rng = np.random.default_rng(29)
    start = robot.random_configurations(rng, 2)
    start[1] = np.clip(np.zeros(robot.dof), robot.lower, robot.upper)  # straight arms are singular
    for q0 in start:
        walk = np.clip(q0 + np.cumsum(rng.normal(0.0, 1e-3, (1500, robot.dof)), axis=0), robot.lower, robot.upper)
        one = np.array([robot.conditioning(row, task) for row in walk])
        for threshold in (0.0, inverse_condition_threshold(None, task), 0.2, 0.9):
            inv, man = bounded_conditioning(robot, walk, task, threshold, keep=[3, 700])
            _check_bounded(inv, man, one[:, 0], one[:, 1], threshold, np.array([3, 700]))


@pytest.mark.parametrize(
    ("q", "keep", "match"),
    [
        (np.zeros((0, 3)), None, "non-empty"),
        (np.zeros(3), None, "shape"),
        (np.zeros((4, 2)), None, "shape"),
        (np.zeros((4, 3)), [0, 4], r"\[0, 3\]"),
        (np.zeros((4, 3)), [-1], r"\[0, 3\]"),
    ],
)
def test_bounded_conditioning_rejects_bad_input(q, keep, match):
    """Empty or misshapen configurations and rows outside them name the valid choices."""
    from planner.exceptions import InvalidArgumentError

    with pytest.raises(InvalidArgumentError, match=match):
        bounded_conditioning(get_robot("dh3"), q, "position", 0.05, keep)


def test_a_zero_threshold_through_a_singular_waypoint_divides_by_nothing():
    # Threshold 0 and a singular waypoint: the certificate's level is 0 and its floor 0 on rows
    # with no interpolation error; the manipulability's shrink factor was 0 / 0 (a RuntimeWarning
    # and a NaN bound, which then had the row measured exactly).
    import warnings

    robot = get_robot("dh3")
    q = np.array([[0.645416746068515, -1.084854553197284, -2.1631113075078927], [0.0, 0.0, 0.0], [0.5, 1.08, 0.2]])
    trajectory = plan_trajectory(q, JointLimits.from_robot(robot))
    task = robot.resolve_task(None)
    t = np.unique(np.concatenate([trajectory.times(1000.0), trajectory.waypoint_times]))
    keep = np.searchsorted(t, trajectory.waypoint_times)
    samples = trajectory.sample(t).q
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        inv, man = bounded_conditioning(robot, samples, task, 0.0, keep)
    inv_all, man_all = robot.conditioning(samples, task)
    _check_bounded(inv, man, inv_all, man_all, 0.0, keep)
