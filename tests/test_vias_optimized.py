"""The "optimized" via strategy: per-joint choice among the states tried, turns the range repair would halve."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_trajectory import assert_passes_waypoints, assert_within_limits, problems

from planner.motion.limits import JointLimits, admissible_acceleration
from planner.motion.plan import plan_trajectory
from planner.motion.segments import merge_segment
from planner.motion.vias import OptimizedStrategy, ViaChain
from planner.motion.vias.heuristic import via_directions

from conftest import get_robot, needs_example_robot_data

SETTINGS = settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


def _random_chain(q: np.ndarray, limits: JointLimits, seed: int) -> ViaChain:
    """A chain whose free via states are random admissible ones (as every strategy's are)."""
    rng = np.random.default_rng(seed)
    chain = ViaChain(q, limits, np.zeros(q.shape[1]), np.zeros(q.shape[1]), np.zeros(len(q), dtype=bool))
    for i in range(1, chain.n - 1):
        v = rng.uniform(-1.0, 1.0, q.shape[1]) * limits.velocity
        chain.v[i] = v
        chain.acc[i] = admissible_acceleration(v, rng.uniform(-1.0, 1.0, q.shape[1]) * limits.acceleration, limits)
    return chain


@SETTINGS
@given(problems(max_points=4), st.integers(0, 2**32 - 1))
def test_turns_beyond_finds_what_the_range_repairs_exact_check_finds(problem, seed):
    # The range repair reads the turns inside phases of zero jerk from merge_segment (which
    # Ruckig's extrema miss); turns_beyond must flag exactly the joints whose turns leave the range.
    q, limits = problem
    chain = _random_chain(q, limits, seed)
    seg = chain.seg
    for k in range(chain.n - 1):
        d, _, traj = seg.solve(k, chain.v[k], chain.acc[k], chain.v[k + 1], chain.acc[k + 1])
        if traj is None:
            continue
        merged = merge_segment(traj, d, (q[k], chain.v[k], chain.acc[k]), q[k + 1], limits)
        if merged.missed is None:
            continue  # an end correction: the repair reads the pieces, not the turns
        low, high = merged.missed
        expected = set(np.nonzero((low < seg.lower) | (high > seg.upper))[0].tolist())
        assert set(seg.turns_beyond(k, traj)) == expected


@SETTINGS
@given(problems(), st.integers(0, 2**32 - 1))
def test_the_joint_choice_is_never_slower_than_any_state_tried_that_turns_within_the_range(problem, seed):
    q, limits = problem
    if len(q) < 3:
        return
    chain = _random_chain(q, limits, seed)
    strategy = OptimizedStrategy()
    i = 1
    durations = chain.durations()
    u, w = via_directions(chain.q, i, durations, limits, chain.stop)
    current = chain.pair_cost(i, chain.v[i], chain.acc[i])
    tried = strategy.search_via(chain, i, u, w) if u.any() or w.any() else []
    both = chain.seg.around(i, chain.v[i - 1], chain.acc[i - 1], chain.v[i + 1], chain.acc[i + 1])

    def turns_within(state) -> bool:
        (_, _, first), (_, _, second) = both(state[1], state[2])
        return not chain.seg.turns_beyond(i - 1, first) and not chain.seg.turns_beyond(i, second)

    fitting = [c[0] for c in [current, *tried] if c[0] < math.inf and turns_within(c)]
    strategy.combine_joints(chain, i, tried)
    chosen = chain.pair_cost(i, chain.v[i], chain.acc[i])
    assert np.array_equal(chosen[1], chain.v[i]) and np.array_equal(chosen[2], chain.acc[i])  # nothing halved
    if fitting:
        assert turns_within(chosen)
        assert chosen[0] <= min(fitting)
    assert np.all(np.abs(chain.v[i]) <= limits.velocity)
    assert np.array_equal(admissible_acceleration(chain.v[i], chain.acc[i], limits), chain.acc[i])


@needs_example_robot_data
@pytest.mark.parametrize("name", ["ur5", "z1"])
@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), points=st.integers(3, 7))
def test_six_dof_arms_hold_every_limit_at_1khz_and_pass_their_waypoints(name, seed, points):
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    q = robot.random_configurations(np.random.default_rng(seed), points)
    traj = plan_trajectory(q, limits)
    assert_within_limits(traj, rate=1000.0)
    assert_passes_waypoints(traj, q)
    assert traj.duration <= plan_trajectory(q, limits, strategy="stop").duration * (1 + 1e-12)
