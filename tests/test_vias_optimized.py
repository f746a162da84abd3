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


class _Given(OptimizedStrategy):
    """The via states of a plan found by a search, set as they are."""

    name = "given"

    def __init__(self, v: np.ndarray, acc: np.ndarray):
        self.v, self.acc = v, acc

    def choose(self, chain: ViaChain) -> None:
        chain.v[1:-1], chain.acc[1:-1] = self.v, self.acc


def test_a_synchronised_profile_that_overshoots_the_speed_limit_is_repaired():
    # Ruckig 0.19 slows a joint that does not set the segment's time with a smaller jerk: from
    # an admissible start state still accelerating (|v| + a^2 / (2 j_max) <= v_max) its speed then
    # peaks at v + a^2 / (2 j) beyond v_max (0.66 % here, joint 2 of the middle segment; a via
    # state a search reached on dh3). The repair halves such a joint's via state.
    limits = JointLimits(
        np.full(3, 5.23598775598299),
        np.full(3, 10.47197551196598),
        np.full(3, 104.7197551196598),
        np.full(3, -math.pi),
        np.full(3, math.pi),
        ("a", "b", "c"),
    )
    q = np.array(
        [
            [0.0, -2.0, -1.5],
            [0.46268151635662047, -2.0769777037336987, -0.5295226621914773],
            [-0.8339215718214388, -1.6483949420639816, 1.4907081945128002],
            [-0.8, -1.0, 2.0],
        ]
    )
    v = np.array(
        [
            [-1.208868156963451, -1.8217782803157871, 4.72928041982788],
            [-1.5749470958167573, 3.4866726093029654, 1.6338919888129404],
        ]
    )
    acc = np.array(
        [
            [-6.4049499911413275, 10.47197551196598, 10.30167637361742],
            [6.019201632367009, 10.316835134010928, -10.47197551196598],
        ]
    )
    assert np.array_equal(admissible_acceleration(v, acc, limits), acc)
    traj = plan_trajectory(q, limits, strategy=_Given(v, acc))
    assert_within_limits(traj, rate=1000.0)
    assert traj.peak_ratios(None)["velocity"] <= 1.0 + 1e-9
    assert traj.repaired[2, 2]


@SETTINGS
@given(problems(), st.integers(0, 2**32 - 1), st.integers(1, 4))
def test_a_probe_gives_each_joints_own_time_as_the_synchronised_solve_and_flags_its_range(problem, seed, count):
    # probe_around's per-joint times are Ruckig's independent minimum durations of the full
    # synchronised solve (the reference: SegmentSolver.solve), joint by joint; an entry it
    # marks inf is one whose own time-optimal profile (a one-joint Ruckig solve) leaves the range.
    q, limits = problem
    if len(q) < 3:
        return
    chain = _random_chain(q, limits, seed)
    rng = np.random.default_rng(seed)
    i = int(rng.integers(1, chain.n - 1))
    joints = tuple(sorted(rng.choice(q.shape[1], size=int(rng.integers(1, q.shape[1] + 1)), replace=False).tolist()))
    states = []
    for _ in range(count):
        cv = chain.v[i].copy()
        cv[list(joints)] = rng.uniform(-1.0, 1.0, len(joints)) * limits.velocity[list(joints)]
        ca = chain.acc[i].copy()
        ca[list(joints)] = rng.uniform(-1.0, 1.0, len(joints)) * limits.acceleration[list(joints)]
        states.append((cv, admissible_acceleration(cv, ca, limits)))
    start = (chain.v[i - 1].tolist(), chain.acc[i - 1].tolist())
    end = (chain.v[i + 1].tolist(), chain.acc[i + 1].tolist())
    candidates = [([cv[j] for j in joints], [ca[j] for j in joints]) for cv, ca in states]
    probed = chain.seg.probe_around(i, start, end, joints, candidates)
    if probed is None:
        return  # Ruckig failed on one entry: the search takes no option from the probe
    first, second = probed
    for c, (cv, ca) in enumerate(states):
        (_, _, traj1), (_, _, traj2) = chain.seg.solve_around(
            i, chain.v[i - 1], chain.acc[i - 1], cv, ca, chain.v[i + 1], chain.acc[i + 1]
        )
        for m, j in enumerate(joints):
            e = c * len(joints) + m
            if np.any(q[i - 1 : i + 2, j] == q[i, j]) and (first[e] == math.inf or traj1 is None or traj2 is None):
                continue  # a joint still in a segment: Ruckig 0.19 may have no profile there (not probed)
            leaves = _own_profile_leaves_range(q, limits, i, j, cv[j], ca[j], chain)
            assert (first[e] == math.inf) == leaves
            assert (second[e] == math.inf) == leaves
            if not leaves:
                assert first[e] == traj1.independent_min_durations[j]
                assert second[e] == traj2.independent_min_durations[j]


def _one_joint(p0, v0, a0, p1, v1, a1, limits, j):
    from ruckig import InputParameter, Ruckig, Trajectory

    inp = InputParameter(1)
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = (
        [float(limits.velocity[j])],
        [float(limits.acceleration[j])],
        [float(limits.jerk[j])],
    )
    inp.current_position, inp.current_velocity, inp.current_acceleration = [p0], [v0], [a0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [p1], [v1], [a1]
    traj = Trajectory(1)
    Ruckig(1).calculate(inp, traj)
    return traj


def _own_profile_leaves_range(q, limits, i, j, v, a, chain) -> bool:
    """Whether joint j's own time-optimal profile in either segment next to via i leaves its checked range."""
    lower, upper = chain.seg.lower[j], chain.seg.upper[j]
    for traj in (
        _one_joint(q[i - 1, j], chain.v[i - 1, j], chain.acc[i - 1, j], q[i, j], v, a, limits, j),
        _one_joint(q[i, j], v, a, q[i + 1, j], chain.v[i + 1, j], chain.acc[i + 1, j], limits, j),
    ):
        e = traj.position_extrema[0]
        if e.min < lower or e.max > upper:
            return True
    return False


class _Probed(OptimizedStrategy):
    """The "optimized" search with the probed velocity steps in the sweep (no polish, no step pass)."""

    polish_joints = 0
    step_pass = False  # (its sweep probes no fixed velocity steps)


class _Unprobed(_Probed):
    """The "optimized" search without the probed velocity steps (nor the polish)."""

    probe_steps = ()


@pytest.mark.parametrize("name", ["dh3", "al5c", pytest.param("ur5", marks=needs_example_robot_data)])
def test_the_probed_velocity_steps_shorten_plans_through_five_waypoints_on_average(name):
    # As benchmarks/bench_trajectory.py plans them (5 random waypoints, v from the URDF, a = 2 v,
    # j = 10 a): the probed per-joint velocity steps make the plans shorter on average, and never
    # break a limit.
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(0)
    ratios = []
    for _ in range(30):
        q = robot.random_configurations(rng, 5)
        probed = plan_trajectory(q, limits, strategy=_Probed())
        ratios.append(probed.duration / plan_trajectory(q, limits, strategy=_Unprobed()).duration)
        assert_within_limits(probed, rate=1000.0)
        assert_passes_waypoints(probed, q)
    assert np.mean(ratios) < 1.0
    assert np.median(ratios) <= 1.0
