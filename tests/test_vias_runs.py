"""The "optimized" strategy's run stage: per-joint options along a run, timed by one probe, chosen per joint."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_trajectory import assert_passes_waypoints, assert_within_limits, problems
from test_vias_optimized import SETTINGS, _one_joint, _random_chain

from planner import load_robot
from planner.motion.limits import JointLimits, admissible_acceleration
from planner.motion.plan import plan_trajectory
from planner.motion.vias import OptimizedStrategy, kernels
from planner.motion.vias import optimized as opt
from planner.motion.vias.kernels import _library, choose_joints


@SETTINGS
@given(problems(), st.integers(0, 2**32 - 1), st.integers(1, 3))
def test_a_run_probe_gives_each_joints_own_time_and_flags_its_range(problem, seed, count):
    # probe_run's entries are each joint's own time-optimal Ruckig time from its state at one
    # waypoint to its state at the next (a one-joint solve, the reference), inf where that
    # profile leaves the range.
    q, limits = problem
    if len(q) < 3:
        return
    chain = _random_chain(q, limits, seed)
    rng = np.random.default_rng(seed)
    n, dof = q.shape
    a = int(rng.integers(0, n - 2))
    m = int(rng.integers(1, n - a))
    v = np.empty((count, m + 1, dof))
    acc = np.empty((count, m + 1, dof))
    for c in range(count):
        v[c] = rng.uniform(-1.0, 1.0, (m + 1, dof)) * limits.velocity
        acc[c] = admissible_acceleration(v[c], rng.uniform(-1.0, 1.0, (m + 1, dof)) * limits.acceleration, limits)
    probed = chain.seg.probe_run(a, v, acc)
    if probed is None:
        return  # Ruckig failed on one entry: the search keeps the current states
    assert len(probed) == count * m * dof
    lower, upper = chain.seg.lower, chain.seg.upper
    for c in range(count):
        for r in range(m):
            for j in range(dof):
                e = (c * m + r) * dof + j
                k = a + r
                if q[k, j] == q[k + 1, j] and probed[e] == math.inf:
                    continue  # a joint still in a segment: Ruckig 0.19 may have no profile there (not probed)
                traj = _one_joint(
                    q[k, j], v[c, r, j], acc[c, r, j], q[k + 1, j], v[c, r + 1, j], acc[c, r + 1, j], limits, j
                )
                extrema = traj.position_extrema[0]
                leaves = extrema.min < lower[j] or extrema.max > upper[j]
                assert (probed[e] == math.inf) == leaves
                if not leaves:
                    assert probed[e] == pytest.approx(traj.duration, rel=1e-12, abs=1e-12)


def _python_joint_choice(times, shape, monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(opt, "choose_joints", lambda *args: False)
        return opt._joint_choice(times, shape)


times = st.one_of(st.sampled_from([0.0, 0.5, 1.0, 1.5, 2.0, math.inf]), st.floats(0.0, 3.0))


@pytest.mark.skipif(_library() is None, reason="no C compiler (or PLANNER_JIT=0): the Python path only")
@settings(max_examples=300, deadline=None)
@given(st.integers(1, 6), st.integers(1, 5), st.integers(1, 7), st.data())
def test_compiled_joint_choice_equals_the_python_loop(count, m, dof, data):
    flat = data.draw(st.lists(times, min_size=count * m * dof, max_size=count * m * dof))
    with pytest.MonkeyPatch.context() as monkeypatch:
        want = _python_joint_choice(flat, (count, m, dof), monkeypatch)
    assert choose_joints(flat, (count, m, dof), opt._CHOICE_ROUNDS) == want


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 5), st.integers(1, 4), st.integers(1, 6), st.data())
def test_the_joint_choice_never_estimates_the_run_slower_than_the_best_common_option(count, m, dof, data):
    flat = data.draw(st.lists(times, min_size=count * m * dof, max_size=count * m * dof))
    choice = opt._joint_choice(flat, (count, m, dof))

    def run(picks):  # per segment the slowest joint's time, summed
        return sum(max(flat[(picks[j] * m + r) * dof + j] for j in range(dof)) for r in range(m))

    common = min(run([c] * dof) for c in range(count))
    if choice is None:
        assert common == math.inf
    else:
        assert run(choice) <= common


def test_the_compiled_joint_choice_leaves_nan_to_python():
    assert choose_joints([1.0, math.nan], (1, 1, 2), 2) is False


@SETTINGS
@given(problems(), st.integers(0, 2**32 - 1))
def test_the_run_stage_never_makes_a_run_slower_or_carries_it_out_of_the_range(problem, seed):
    q, limits = problem
    if len(q) < 3:
        return
    chain = _random_chain(q, limits, seed)
    durations = chain.durations()
    before = (chain.v.copy(), chain.acc.copy())
    OptimizedStrategy().search_spline(chain, 0, chain.n - 1, durations)
    if np.array_equal(chain.v, before[0]) and np.array_equal(chain.acc, before[1]):
        return  # kept
    seg = chain.seg
    total = 0.0
    for k in range(chain.n - 1):
        d, bad, _ = seg.solve(k, chain.v[k], chain.acc[k], chain.v[k + 1], chain.acc[k + 1])
        assert bad is None
        total += d
    old = 0.0
    for k in range(chain.n - 1):
        d, bad, _ = seg.solve(k, before[0][k], before[1][k], before[0][k + 1], before[1][k + 1])
        old += math.inf if bad is not None else d
    assert total < old
    assert np.all(np.abs(chain.v) <= limits.velocity)
    assert np.array_equal(admissible_acceleration(chain.v, chain.acc, limits), chain.acc)


@pytest.mark.parametrize("name", ["three_joint", "al5c", "dh3"])
def test_plans_hold_every_limit_and_are_the_same_without_the_compiled_joint_choice(name, monkeypatch):
    robot = load_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(3)
    paths = [robot.random_configurations(rng, 6) for _ in range(8)]
    plans = [plan_trajectory(q, limits) for q in paths]
    for traj, q in zip(plans, paths):
        assert_within_limits(traj, rate=1000.0)
        assert_passes_waypoints(traj, q)
    monkeypatch.setattr(kernels, "_library", lambda: None)
    again = [plan_trajectory(q, limits) for q in paths]
    assert [t.duration for t in again] == [t.duration for t in plans]
