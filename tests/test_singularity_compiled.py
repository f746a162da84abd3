"""bounded_conditioning's compiled steps against its NumPy path and against the exact measure.

The compiled loops (:func:`planner.core.certificates.interval_certificates`,
:func:`~planner.core.certificates.own_certificates`) and the NumPy path (taken with
``PLANNER_JIT=0``, here by switching the compiled steps off) must both keep the contract of
:func:`planner.motion.singularity.bounded_conditioning` against every row measured by
:meth:`Robot.conditioning` (Pinocchio's Jacobian, NumPy's SVD): the same rows below the
threshold, the same minima where they are (ties accepted), exact values at the rows `keep`,
lower bounds elsewhere. Walks: planned trajectories sampled at 1 kHz (as plans are measured),
and dense smooth walks through a straight arm (singular) at thresholds from 0 to 0.9.
"""

from __future__ import annotations

import numpy as np
import pytest
from dh_arms import BUNDLED, dh_descriptions, property_settings, robot_from_description
from hypothesis import given
from hypothesis import strategies as st

import planner.motion.singularity as singularity
from planner import InvalidArgumentError
from planner.core.certificates import anchor_bounds, grams, interval_certificates, own_certificates
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory
from planner.motion.singularity import bounded_conditioning, inverse_condition_threshold

from conftest import HAVE_EXAMPLE_ROBOT_DATA, get_robot

ARMS = list(BUNDLED) + (["ur5", "panda", "z1"] if HAVE_EXAMPLE_ROBOT_DATA else [])
COMPILED = grams(np.zeros((1, 1, 1))) is not None
needs_compiler = pytest.mark.skipif(not COMPILED, reason="no C compiler (or PLANNER_JIT=0): only the NumPy path")


def _both(robot, q, task, threshold, keep) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray], int]:
    """bounded_conditioning compiled and written out, and how often the compiled steps ran."""
    calls = []

    def spy(*args):
        calls.append(1)
        return interval_certificates(*args)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(singularity, "interval_certificates", spy)
        compiled = bounded_conditioning(robot, q, task, threshold, keep)
    with pytest.MonkeyPatch.context() as patch:
        # Every compiled loop off but the Jacobian kernel (PLANNER_JIT=0 switches that off too).
        for name in ("interval_certificates", "anchor_bounds", "extreme_bounds", "cholesky_certificates", "grams"):
            patch.setattr(singularity, name, lambda *args: None)
        written_out = bounded_conditioning(robot, q, task, threshold, keep)
    return compiled, written_out, len(calls)


def _check_contract(inv, man, inv_all, man_all, threshold, keep) -> None:
    """What bounded_conditioning promises, ties of the minima accepted (see test_singularity_bounds)."""
    exact = inv == inv_all
    assert np.array_equal(inv < threshold, inv_all < threshold)
    assert np.all(inv <= inv_all) and np.all(man <= man_all)
    assert exact[keep].all() and np.array_equal(man[keep], man_all[keep])
    # The minima: their values exact, at a row where the exact measure is smallest.
    assert inv.min() == inv_all.min() and inv_all[int(np.argmin(inv))] == inv_all.min()
    assert man.min() == man_all.min() and man_all[int(np.argmin(man))] == man_all.min()
    assert np.all(inv[~exact & (inv_all >= threshold)] > max(threshold, inv_all.min()))
    assert np.all(man[man != man_all] > man_all.min())
    ends = np.unique(np.concatenate([[0, len(inv) - 1], keep]))
    for a, b in zip(ends[:-1], ends[1:]):
        piece, piece_all = inv[a : b + 1], inv_all[a : b + 1]
        if piece_all.min() < threshold:
            # Each stretch's lowest row: exact, at a lowest row of the exact measure.
            assert piece.min() == piece_all.min() and piece_all[int(np.argmin(piece))] == piece_all.min()
            assert np.all(piece[piece != piece_all] > piece_all.min())


def _check_same_report(first, second, threshold, keep) -> None:
    """Two results that keep the contract report the same: minima, rows below, stretch minima."""
    (inv_a, man_a), (inv_b, man_b) = first, second
    assert np.array_equal(inv_a < threshold, inv_b < threshold)
    assert inv_a.min() == inv_b.min() and man_a.min() == man_b.min()
    assert np.array_equal(inv_a[keep], inv_b[keep]) and np.array_equal(man_a[keep], man_b[keep])


def _check_all(robot, q, task, threshold, keep) -> int:
    inv_all, man_all = robot.conditioning(q, task)
    compiled, written_out, calls = _both(robot, q, task, threshold, keep)
    for inv, man in (compiled, written_out):
        _check_contract(inv, man, inv_all, man_all, threshold, keep)
    _check_same_report(compiled, written_out, threshold, keep)
    return calls


def _planned(robot, seed: int, points: int) -> tuple[np.ndarray, np.ndarray]:
    """A planned trajectory through random configurations, sampled as measure_singularities does."""
    waypoints = robot.random_configurations(np.random.default_rng(seed), points)
    trajectory = plan_trajectory(waypoints, JointLimits.from_robot(robot))
    t = np.unique(np.concatenate([trajectory.times(1000.0), trajectory.waypoint_times]))
    return trajectory.positions(t), np.searchsorted(t, trajectory.waypoint_times)


def _through_straight(robot, seed: int, rows: int = 1500) -> np.ndarray:
    """A smooth walk (random jerks integrated three times) through the straight arm (singular)."""
    rng = np.random.default_rng(seed)
    jerk = rng.normal(0.0, 1.0, (rows, robot.dof))
    walk = np.cumsum(np.cumsum(np.cumsum(jerk, axis=0), axis=0), axis=0)
    walk = walk / max(float(np.max(np.abs(np.diff(walk, axis=0)))), 1e-300) * 2e-3
    walk -= walk[rows // 2]
    return np.clip(walk + np.clip(np.zeros(robot.dof), robot.lower, robot.upper), robot.lower, robot.upper)


@pytest.mark.parametrize("name", ARMS)
@given(seed=st.integers(0, 2**32 - 1), points=st.integers(2, 4), scale=st.sampled_from([0.0, 1.0, 5.0, 30.0]))
@property_settings(6)
def test_compiled_and_numpy_paths_keep_the_contract_on_planned_trajectories(name, seed, points, scale):
    robot = get_robot(name)
    for task in ("position", "pose"):
        threshold = min(inverse_condition_threshold(None, task) * scale, 0.9)
        q, keep = _planned(robot, seed, points)
        _check_all(robot, q, task, threshold, keep)


@pytest.mark.parametrize("name", ARMS)
def test_compiled_and_numpy_paths_keep_the_contract_through_a_singularity(name):
    robot = get_robot(name)
    for task in ("position", "pose"):
        for seed in (3, 4):
            q = _through_straight(robot, seed)
            for threshold in (0.0, inverse_condition_threshold(None, task), 0.2, 0.9):
                _check_all(robot, q, task, threshold, np.array([5, 700]))


@given(description=dh_descriptions(min_joints=3, max_joints=6), seed=st.integers(0, 2**32 - 1))
@property_settings(25)
def test_compiled_and_numpy_paths_keep_the_contract_on_random_dh_arms(description, seed):
    robot = robot_from_description(description)
    for task in ("position", "pose"):
        threshold = inverse_condition_threshold(None, task) * 3.0
        q, keep = _planned(robot, seed, 3)
        _check_all(robot, q, task, threshold, keep)
        q = _through_straight(robot, seed, 600)
        _check_all(robot, q, task, threshold, np.array([0, 300]))


@needs_compiler
@pytest.mark.skipif(not HAVE_EXAMPLE_ROBOT_DATA, reason="needs ur5 and panda")
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_the_compiled_steps_run_and_leave_few_rows_to_measure(name, monkeypatch):
    # Not vacuous: the compiled steps take ur5's and panda's pose measure, and settle most rows
    # (those measured exactly go through Robot.task_jacobians: counted here).
    robot = get_robot(name)
    q, keep = _planned(robot, 5, 3)
    measured = []
    task_jacobians = robot.task_jacobians

    def counted(rows, task=None):
        measured.append(len(rows))
        return task_jacobians(rows, task)

    threshold = inverse_condition_threshold(None, "pose")
    with monkeypatch.context() as patch:
        patch.setattr(robot, "task_jacobians", counted)
        inv, man = bounded_conditioning(robot, q, "pose", threshold, keep)
    _check_contract(inv, man, *robot.conditioning(q, "pose"), threshold, keep)
    assert _both(robot, q, "pose", threshold, keep)[2] == 1
    assert 0 < sum(measured) < 0.05 * len(q)


@needs_compiler
@pytest.mark.skipif(not HAVE_EXAMPLE_ROBOT_DATA, reason="needs panda")
@pytest.mark.parametrize("seed", [5, 6])
def test_step_two_settles_the_manipulability_of_most_rows(seed, monkeypatch):
    # Step 2's bound of the manipulability alone (f^2 = e (k / tr(G^-1))^(1/2)) is tight enough
    # that few rows whose inverse condition number it settles need their own Jacobian for the
    # manipulability (the earlier (k e s^2)^(1/3) shift left 11 % and 24 % of these rows open).
    robot = get_robot("panda")
    q, keep = _planned(robot, seed, 3)
    got = []

    def spy(*args):
        got.append((args[1], interval_certificates(*args)))
        return got[-1][1]

    threshold = inverse_condition_threshold(None, "pose")
    monkeypatch.setattr(singularity, "interval_certificates", spy)
    inv, man = bounded_conditioning(robot, q, "pose", threshold, keep)
    _check_contract(inv, man, *robot.conditioning(q, "pose"), threshold, keep)
    (anchors, (_, _, flags)), rows = got[0], np.ones(len(q), dtype=bool)
    rows[anchors] = False
    manipulability_open = ((flags[rows] & 2) != 0) & ((flags[rows] & 4) == 0)
    assert manipulability_open.sum() < 0.06 * rows.sum()


@needs_compiler
def test_own_certificates_refuse_arrays_they_would_write_past():
    scaled = np.zeros((4, 6, 7))
    good = (np.zeros(4), np.zeros(4), np.zeros(4), np.zeros(4, dtype=np.int64))
    for k, bad in enumerate([np.zeros(3), np.zeros(4, dtype=np.int64), np.zeros(4, dtype=np.int32)]):
        args = list(good)
        args[[1, 2, 3][k]] = bad
        with pytest.raises(InvalidArgumentError, match="C-contiguous"):
            own_certificates(scaled, *args, (0.01, 0.01, 0.0, 1.0))


@needs_compiler
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 40),
    shape=st.sampled_from([(3, 3), (3, 7), (6, 6), (6, 7), (6, 4)]),
)
@property_settings(40)
def test_anchor_bounds_bracket_the_singular_values(seed, n, shape):
    # Matrices with singular values from 1e-6 to 10 (NumPy's SVD as the reference, rounding allowed).
    rng = np.random.default_rng(seed)
    m, dof = shape
    k = min(shape)
    u = np.linalg.qr(rng.normal(size=(n, m, m)))[0][:, :, :k]
    v = np.linalg.qr(rng.normal(size=(n, dof, dof)))[0][:, :, :k]
    values = np.sort(10.0 ** rng.uniform(-6, 1, (n, k)), axis=1)[:, ::-1]
    scaled = u @ (values[:, :, None] * v.transpose(0, 2, 1))
    s = np.linalg.svd(scaled, compute_uv=False)[:, :k]
    top, bottom, product, min_up, max_low, low, up, man_up = anchor_bounds(scaled, 0.5).T
    slack = 1e-9
    assert np.all(top >= s[:, 0] * (1 - slack)) and np.all(max_low <= s[:, 0] * (1 + slack))
    assert np.all(bottom <= s[:, -1] * (1 + slack) + 1e-15) and np.all(min_up >= s[:, -1] * (1 - slack))
    assert np.all(product <= np.prod(s, axis=1) * (1 + slack))
    inverse = s[:, -1] / s[:, 0]
    assert np.all(low <= inverse * (1 + slack)) and np.all(up >= inverse * (1 - slack))
    assert np.all(man_up >= 0.5 * np.prod(s, axis=1) * (1 - slack))


@needs_compiler
@pytest.mark.skipif(not HAVE_EXAMPLE_ROBOT_DATA, reason="needs panda")
def test_anchor_bounds_are_tight_on_most_jacobians():
    # Not vacuous: panda's scaled pose Jacobians at random configurations (NumPy's SVD).
    robot = get_robot("panda")
    scaled = robot.task_jacobians(robot.random_configurations(np.random.default_rng(41), 500), "pose")[1]
    s = np.linalg.svd(scaled, compute_uv=False)
    top, bottom, product, _, _, low, up, man_up = anchor_bounds(scaled, 1.0).T
    inverse = s[:, -1] / s[:, 0]
    assert np.mean((low >= inverse * (1 - 1e-3)) & (up <= inverse * (1 + 1e-3))) > 0.8
    assert np.mean(product >= np.prod(s, axis=1) * (1 - 1e-6)) > 0.8
    assert np.mean(man_up <= np.prod(s, axis=1) * (1 + 1e-4)) > 0.8


@pytest.mark.parametrize(
    "change",
    ["anchors past the end", "anchors out of order", "scaled rows", "ends columns", "least length", "rho length"],
)
def test_interval_certificates_refuse_arrays_they_would_read_past(change):
    n, dof, m = 30, 3, 3
    q, anchors = np.zeros((n, dof)), np.array([0, 12, 24, 29])
    scaled, ends, least, rho = np.zeros((4, m, dof)), np.zeros((4, 6)), np.zeros(3), np.ones(dof)
    if change == "anchors past the end":
        anchors = np.array([0, 12, 24, 30])
    elif change == "anchors out of order":
        anchors = np.array([0, 24, 12, 29])
    elif change == "scaled rows":
        scaled = np.zeros((3, m, dof))
    elif change == "ends columns":
        ends = np.zeros((4, 5))
    elif change == "least length":
        least = np.zeros(4)
    else:
        rho = np.ones(dof + 1)
    with pytest.raises(InvalidArgumentError, match="interval_certificates"):
        interval_certificates(q, anchors, scaled, ends, least, rho, (0.0,) * 6)
