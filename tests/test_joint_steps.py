"""The second pass over the via states: per-joint velocity steps of the joints that set a segment's time."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_trajectory import assert_passes_waypoints, assert_within_limits, problems
from test_vias_optimized import _random_chain

from planner.motion.limits import JointLimits, admissible_acceleration
from planner.motion.plan import plan_trajectory
from planner.motion.vias import OptimizedStrategy
from planner.motion.vias.joint_steps import STEPS, resweep_via, step_binding_joints, step_candidates

from conftest import get_robot, needs_example_robot_data

SETTINGS = settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
# Many random chains have a first pair without a profile or nothing to step: more examples.
MORE = settings(SETTINGS, max_examples=200)


@SETTINGS
@given(problems(), st.integers(0, 2**32 - 1), st.lists(st.floats(0.0, 2.5), min_size=1, max_size=3))
def test_step_candidates_are_the_moved_velocities_with_admissible_accelerations(problem, seed, steps):
    # Reference: the velocity moved and clipped with NumPy, the acceleration limited by
    # admissible_acceleration (the rule every via state follows).
    q, limits = problem
    chain = _random_chain(q, limits, seed) if len(q) >= 3 else None
    rng = np.random.default_rng(seed)
    v = rng.uniform(-1.0, 1.0, q.shape[1]) * limits.velocity if chain is None else chain.v[1]
    a = rng.uniform(-1.0, 1.0, q.shape[1]) * limits.acceleration if chain is None else chain.acc[1]
    joints = sorted(rng.choice(q.shape[1], size=int(rng.integers(1, q.shape[1] + 1)), replace=False).tolist())
    velocity, acceleration, _ = limits.ruckig_limits
    out = step_candidates((velocity, acceleration, limits.twice_jerk.tolist()), (v.tolist(), a.tolist()), joints, steps)
    moves = [-s for s in steps] + list(steps)
    assert len(out) == len(moves)
    for move, (nv, na) in zip(moves, out):
        expected_v = np.clip(
            v[joints] + move * limits.velocity[joints], -limits.velocity[joints], limits.velocity[joints]
        )
        full_v, full_a = v.copy(), a.copy()
        full_v[joints] = expected_v
        expected_a = admissible_acceleration(full_v, full_a, limits)[joints]
        np.testing.assert_array_equal(nv, expected_v)
        np.testing.assert_array_equal(na, expected_a)  # the same operations, on floats
        full_a[joints] = na
        assert np.all(np.abs(full_v) <= limits.velocity)


@MORE
@given(problems(), st.integers(0, 2**32 - 1))
def test_a_step_moves_only_binding_joints_and_takes_their_probed_times(problem, seed):
    # The joints moved are ones that set a segment's time; their new times are what a Ruckig
    # solve of the two segments gives each joint alone (its independent minimum duration), and
    # the pair's estimate max t1 + max t2 is below the one before.
    q, limits = problem
    if len(q) < 3:
        return
    chain = _random_chain(q, limits, seed)
    i = 1
    (_, bad1, traj1), (_, bad2, traj2) = chain.seg.solve_around(
        i, chain.v[i - 1], chain.acc[i - 1], chain.v[i], chain.acc[i], chain.v[i + 1], chain.acc[i + 1]
    )
    if traj1 is None or traj2 is None:
        return
    c1, c2 = traj1.independent_min_durations, traj2.independent_min_durations
    before = (list(c1), list(c2))
    state = (chain.v[i].tolist(), chain.acc[i].tolist())
    old = (list(state[0]), list(state[1]))
    if not step_binding_joints(chain, i, state, (c1, c2)):
        assert state == old and (c1, c2) == before
        return
    moved = [j for j in range(q.shape[1]) if (state[0][j], state[1][j]) != (old[0][j], old[1][j])]
    for j in moved:
        assert before[0][j] >= 0.98 * max(before[0]) or before[1][j] >= 0.98 * max(before[1])
    assert max(c1) + max(c2) < max(before[0]) + max(before[1])
    cv, ca = np.array(state[0]), np.array(state[1])
    assert np.all(np.abs(cv) <= limits.velocity)
    assert np.array_equal(admissible_acceleration(cv, ca, limits), ca)
    (_, _, new1), (_, _, new2) = chain.seg.solve_around(
        i, chain.v[i - 1], chain.acc[i - 1], cv, ca, chain.v[i + 1], chain.acc[i + 1]
    )
    for j in range(q.shape[1]):
        if j in moved:
            assert c1[j] == new1.independent_min_durations[j] and c2[j] == new2.independent_min_durations[j]
        else:
            assert c1[j] == before[0][j] and c2[j] == before[1][j]


@MORE
@given(problems(), st.integers(0, 2**32 - 1))
def test_the_second_pass_keeps_a_state_only_where_its_pair_is_faster_and_fits(problem, seed):
    q, limits = problem
    if len(q) < 3:
        return
    chain = _random_chain(q, limits, seed)
    seg = chain.seg
    i = int(np.random.default_rng(seed).integers(1, chain.n - 1))
    v0, a0 = chain.v[i].copy(), chain.acc[i].copy()
    around = seg.around(i, chain.v[i - 1], chain.acc[i - 1], chain.v[i + 1], chain.acc[i + 1])
    (d1, _, _), (d2, _, _) = around(v0, a0)
    changed = resweep_via(chain, i)
    if not changed:
        assert np.array_equal(chain.v[i], v0) and np.array_equal(chain.acc[i], a0)
        return
    (e1, bad1, traj1), (e2, bad2, traj2) = around(chain.v[i], chain.acc[i])
    assert e1 + e2 < d1 + d2
    assert bad1 is None and bad2 is None
    assert not seg.turns_beyond(i - 1, traj1) and not seg.turns_beyond(i, traj2)
    assert np.all(np.abs(chain.v[i]) <= limits.velocity)
    assert np.array_equal(admissible_acceleration(chain.v[i], chain.acc[i], limits), chain.acc[i])


class _OneSweep(OptimizedStrategy):
    """The "optimized" search without the polish of small arms nor the step pass of the others: the sweep alone."""

    polish_joints = 0
    step_pass = False


class _FirstVia(_OneSweep):
    """The "optimized" search with the second pass over the first via of each run."""

    resweep_vias = 1


class _EveryVia(_OneSweep):
    """The "optimized" search with the second pass over every via."""

    resweep_vias = None


@SETTINGS
@given(problems(max_points=6))
def test_plans_with_the_second_pass_over_every_via_hold_every_limit(problem):
    q, limits = problem
    traj = plan_trajectory(q, limits, strategy=_EveryVia())
    assert_within_limits(traj)
    assert_passes_waypoints(traj, q)


@pytest.mark.parametrize("strategy", [_FirstVia(), _EveryVia()], ids=["first via", "every via"])
@pytest.mark.parametrize("name", ["dh3", "al5c", pytest.param("ur5", marks=needs_example_robot_data)])
def test_the_second_pass_shortens_plans_through_five_waypoints_on_average(name, strategy):
    # As benchmarks/bench_trajectory.py plans them (5 random waypoints, v from the URDF, a = 2 v,
    # j = 10 a): the second pass makes the plans shorter on average, and never breaks a limit.
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(1)
    ratios = []
    for _ in range(30):
        q = robot.random_configurations(rng, 5)
        traj = plan_trajectory(q, limits, strategy=strategy)
        ratios.append(traj.duration / plan_trajectory(q, limits, strategy=_OneSweep()).duration)
        assert_within_limits(traj, rate=1000.0)
        assert_passes_waypoints(traj, q)
    assert np.mean(ratios) < 1.0
    assert np.median(ratios) <= 1.0
    assert all(math.isfinite(r) for r in ratios)


def test_the_second_pass_is_off_by_default_and_its_steps_are_shares_of_the_speed_limit():
    assert all(0.0 < s < 1.0 for s in STEPS)
    assert OptimizedStrategy.resweep_steps == STEPS and OptimizedStrategy.resweep_vias == 0
    q = np.array([[0.0, 0.0], [0.5, -0.3], [0.9, 0.2], [0.4, 0.6], [0.0, 0.0]])
    limits = JointLimits(np.ones(2), 2 * np.ones(2), 20 * np.ones(2), -np.ones(2), np.ones(2))
    off = _FirstVia()
    off.resweep_steps = ()
    one_sweep = plan_trajectory(q, limits, strategy=_OneSweep())
    assert one_sweep.duration == plan_trajectory(q, limits, strategy=off).duration


def test_the_second_pass_is_set_when_the_strategy_is_made_and_bad_counts_are_refused():
    from planner import InvalidArgumentError

    assert OptimizedStrategy().resweep_vias == 0
    assert OptimizedStrategy(resweep_vias=2).resweep_vias == 2 and OptimizedStrategy(None).resweep_vias is None
    robot = get_robot("al5c")
    limits = JointLimits.from_robot(robot)
    q = robot.random_configurations(np.random.default_rng(3), 5)
    made, subclassed = OptimizedStrategy(resweep_vias=None, polish_joints=0), _EveryVia()
    made.step_pass = False  # as _EveryVia's (the step pass would visit every via in its own way)
    assert (
        plan_trajectory(q, limits, strategy=made).duration == plan_trajectory(q, limits, strategy=subclassed).duration
    )
    for bad in (-1, 1.5, True, "all"):
        with pytest.raises(InvalidArgumentError, match="resweep_vias must be None .* or an integer >= 0"):
            OptimizedStrategy(resweep_vias=bad)


def _polish_problem(seed: int, dof: int) -> tuple[np.ndarray, JointLimits]:
    """Five random waypoints within a range of +-2 for `dof` joints, with bench-like limits (a = 2 v, j = 10 a)."""
    rng = np.random.default_rng(seed)
    velocity = rng.uniform(0.5, 3.0, dof)
    limits = JointLimits(velocity, 2 * velocity, 20 * velocity, -2.0 * np.ones(dof), 2.0 * np.ones(dof))
    return rng.uniform(-1.9, 1.9, (5, dof)), limits


def test_the_polish_is_on_for_arms_of_up_to_five_joints_and_set_when_the_strategy_is_made():
    from planner import InvalidArgumentError

    assert OptimizedStrategy.reprobe_steps == ()  # the second probe of a kept pick: off by default

    assert OptimizedStrategy.polish_joints == 5 and OptimizedStrategy().polish_joints == 5
    assert OptimizedStrategy(polish_joints=0).polish_joints == 0
    assert all(0.0 < s < 1.0 for steps in OptimizedStrategy.polish_steps for s in steps)
    for bad in (-1, 2.5, False, "5"):
        with pytest.raises(InvalidArgumentError, match="polish_joints must be an integer >= 0"):
            OptimizedStrategy(polish_joints=bad)
    # Six joints: no polish by default, the plans the same as without it (both with the step pass).
    for seed in range(5):
        q, limits = _polish_problem(seed, 6)
        unpolished = OptimizedStrategy(polish_joints=0)
        assert plan_trajectory(q, limits).duration == plan_trajectory(q, limits, strategy=unpolished).duration


@pytest.mark.parametrize("dof", [2, 4, 6])
def test_the_polish_never_lengthens_the_chosen_pairs_and_keeps_every_limit(dof):
    # Per plan: never longer than the sweep alone beyond what the range repair adds (it halves
    # states the strategy's checks let through, a neighbour's polished state can lose more there),
    # shorter on average, every limit held and every waypoint passed.
    strategy = OptimizedStrategy(polish_joints=dof)
    ratios = []
    for seed in range(12):
        q, limits = _polish_problem(seed, dof)
        traj = plan_trajectory(q, limits, strategy=strategy)
        ratios.append(traj.duration / plan_trajectory(q, limits, strategy=_OneSweep()).duration)
        assert traj.duration <= plan_trajectory(q, limits, strategy="stop").duration
        assert_within_limits(traj, rate=1000.0)
        assert_passes_waypoints(traj, q)
    assert np.mean(ratios) < 1.0
    assert np.median(ratios) <= 1.0


@SETTINGS
@given(problems(max_points=6))
def test_plans_with_the_polish_hold_every_limit(problem):
    q, limits = problem
    traj = plan_trajectory(q, limits, strategy=OptimizedStrategy(polish_joints=q.shape[1]))
    assert_within_limits(traj)
    assert_passes_waypoints(traj, q)


@SETTINGS
@given(problems(), st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1))
def test_a_step_among_given_joints_moves_only_those(problem, seed, pick):
    q, limits = problem
    if len(q) < 3:
        return
    chain = _random_chain(q, limits, seed)
    i = 1
    (_, _, traj1), (_, _, traj2) = chain.seg.solve_around(
        i, chain.v[i - 1], chain.acc[i - 1], chain.v[i], chain.acc[i], chain.v[i + 1], chain.acc[i + 1]
    )
    if traj1 is None or traj2 is None:
        return
    rng = np.random.default_rng(pick)
    among = sorted(rng.choice(q.shape[1], size=int(rng.integers(0, q.shape[1] + 1)), replace=False).tolist())
    c1, c2 = traj1.independent_min_durations, traj2.independent_min_durations
    before = max(c1) + max(c2)
    state = (chain.v[i].tolist(), chain.acc[i].tolist())
    old = (list(state[0]), list(state[1]))
    if not step_binding_joints(chain, i, state, (c1, c2), among=among):
        assert state == old
        return
    moved = [j for j in range(q.shape[1]) if (state[0][j], state[1][j]) != (old[0][j], old[1][j])]
    assert set(moved) <= set(among)
    assert max(c1) + max(c2) < before


class _Reprobe(_OneSweep):
    """The "optimized" sweep with the second probe around a kept pick's new states."""

    reprobe_steps = (0.05,)


@pytest.mark.parametrize("name", ["dh3", "al5c", pytest.param("ur5", marks=needs_example_robot_data)])
def test_the_second_probe_around_a_kept_pick_shortens_plans_on_average(name):
    # As bench_trajectory.py plans them: probing the velocity steps again around the states a
    # kept pick moved makes the plans shorter on average, and never breaks a limit.
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(2)
    ratios = []
    for _ in range(30):
        q = robot.random_configurations(rng, 5)
        traj = plan_trajectory(q, limits, strategy=_Reprobe())
        ratios.append(traj.duration / plan_trajectory(q, limits, strategy=_OneSweep()).duration)
        assert_within_limits(traj, rate=1000.0)
        assert_passes_waypoints(traj, q)
    assert np.mean(ratios) < 1.0
    assert np.median(ratios) <= 1.0


def test_the_step_pass_is_on_for_arms_not_polished_and_shortens_their_plans_on_average():
    # Six joints (more than polish_joints): every via stepped once after the sweep, which has no
    # fixed probe steps and no solved grid. Shorter than the sweep alone on average, never slower
    # than resting at every waypoint, every limit held and every waypoint passed.
    assert OptimizedStrategy.step_pass is True
    ratios = []
    for seed in range(12):
        q, limits = _polish_problem(seed, 6)
        traj = plan_trajectory(q, limits)
        ratios.append(traj.duration / plan_trajectory(q, limits, strategy=_OneSweep()).duration)
        assert traj.duration <= plan_trajectory(q, limits, strategy="stop").duration
        assert_within_limits(traj, rate=1000.0)
        assert_passes_waypoints(traj, q)
    assert np.mean(ratios) < 1.0
    assert np.median(ratios) <= 1.0
    # Arms of at most polish_joints joints are polished instead: no step pass, the same plans.
    q, limits = _polish_problem(0, 4)
    off = OptimizedStrategy()
    off.step_pass = False
    assert plan_trajectory(q, limits).duration == plan_trajectory(q, limits, strategy=off).duration


@SETTINGS
@given(problems(max_points=6))
def test_plans_with_the_step_pass_hold_every_limit(problem):
    q, limits = problem
    traj = plan_trajectory(q, limits, strategy=OptimizedStrategy(polish_joints=0))  # the step pass on every arm
    assert_within_limits(traj)
    assert_passes_waypoints(traj, q)
