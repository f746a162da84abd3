"""The "refined" via strategy: per-joint choice, limits held, never slower than "optimized"."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_trajectory import problems
from trajectory_checks import assert_passes_waypoints, assert_within_limits

from planner import InvalidArgumentError
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory
from planner.motion.vias import VIA_STRATEGIES, OptimizedStrategy, RefinedStrategy, via_strategy
from planner.motion.vias.refined import best_choice

from conftest import BUNDLED, get_robot

SETTINGS = settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


def test_best_choice_moves_joints_together_and_only_where_needed():
    # Joint 0 limits segment 1 and joint 1 segment 2; joint 2 never limits anything.
    t1 = np.array([[1.0, 0.5, 0.1], [0.8, 0.6, 0.2], [1.1, 0.4, 0.1]])
    t2 = np.array([[0.5, 1.0, 0.1], [0.6, 0.9, 0.05], [0.4, 1.2, 0.1]])
    value, choice = best_choice(t1, t2)
    # Option 1 for joints 0 and 1 gives max t1 = 0.8, max t2 = 0.9; joint 2 needs no move.
    assert value == pytest.approx(1.7)
    assert choice.tolist() == [1, 1, 0]
    # Brute force over all 27 choices agrees on the value.
    brute = min(
        max(t1[a, 0], t1[b, 1], t1[c, 2]) + max(t2[a, 0], t2[b, 1], t2[c, 2])
        for a in range(3)
        for b in range(3)
        for c in range(3)
    )
    assert value == pytest.approx(brute)


def test_best_choice_keeps_the_current_state_unless_beaten():
    t1 = np.array([[1.0, 0.5], [1.2, math.inf]])
    t2 = np.array([[0.5, 1.0], [0.1, 0.1]])
    assert best_choice(t1, t2) == (1.0 + 1.0, None)


@given(st.integers(2, 4), st.integers(1, 6), st.integers(0, 2**32 - 1))
@SETTINGS
def test_best_choice_is_the_brute_force_optimum(options, dof, seed):
    rng = np.random.default_rng(seed)
    t1, t2 = rng.uniform(0.1, 1.0, (options, dof)), rng.uniform(0.1, 1.0, (options, dof))
    t1[rng.random((options, dof)) < 0.1] = math.inf
    t1[0], t2[0] = np.minimum(t1[0], 1.0), t2[0]  # the current state is always allowed
    value, choice = best_choice(t1, t2)
    brute = min(
        max(t1[c, range(dof)]) + max(t2[c, range(dof)])
        for c in (np.array(np.unravel_index(k, (options,) * dof)) for k in range(options**dof))
    )
    assert value == pytest.approx(min(brute, t1[0].max() + t2[0].max()))
    if choice is not None:
        cols = np.arange(dof)
        assert t1[choice, cols].max() + t2[choice, cols].max() == pytest.approx(value)


def test_registered_by_name_and_checks_its_settings():
    assert VIA_STRATEGIES["refined"] is RefinedStrategy
    assert isinstance(via_strategy("refined"), RefinedStrategy)
    with pytest.raises(InvalidArgumentError, match=r"sweeps must be an integer >= 0, got -1"):
        RefinedStrategy(sweeps=-1)
    with pytest.raises(InvalidArgumentError, match=r"levels must be an integer >= 0, got 1.5"):
        RefinedStrategy(levels=1.5)
    with pytest.raises(InvalidArgumentError, match=r"step must be a number in \(0, 2\] .*, got nan"):
        RefinedStrategy(step=float("nan"))


class _RefinedUnpolished(RefinedStrategy):
    """The refined search from the optimized sweep's states, without the polish (nor the step pass)."""

    polish_joints = 0
    step_pass = False


class _OptimizedUnpolished(OptimizedStrategy):
    """The optimized sweep alone (no polish, no step pass)."""

    polish_joints = 0
    step_pass = False


@pytest.mark.parametrize("name", BUNDLED)
def test_random_paths_hold_limits_and_are_never_slower(name):
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(7)
    faster = repaired = 0
    for _ in range(12):
        q = robot.random_configurations(rng, 5)
        optimized = plan_trajectory(q, limits)
        refined = plan_trajectory(q, limits, strategy="refined")
        assert refined.strategy == "refined"
        fitted = plan_trajectory(q, limits, strategy=RefinedStrategy(sweeps=0))
        assert fitted.duration == optimized.duration
        np.testing.assert_array_equal(fitted.repaired, optimized.repaired)
        repaired += optimized.repaired.any()
        assert refined.duration <= optimized.duration
        # What the search finds, counted from the sweep's states alone (the optimized strategy's
        # polish of arms with few joints takes part of it first: three_joint 5 of these 12).
        unpolished = plan_trajectory(q, limits, strategy=_OptimizedUnpolished())
        faster += plan_trajectory(q, limits, strategy=_RefinedUnpolished()).duration < unpolished.duration
        assert_passes_waypoints(refined, refined.waypoint_times, q)
        np.testing.assert_allclose(refined.sample(refined.waypoint_times).q, q, rtol=0, atol=1e-12)
        assert_within_limits(refined, limits.velocity, limits.acceleration, limits.jerk, limits.lower, limits.upper)
        assert refined.peak_ratios(None)["position"] <= 0.0
    assert faster >= 6  # the search finds something on most random paths
    # Paths whose optimized states the range repair lowers are rare (the search avoids the turns
    # it would halve): draw on until one is among them, and check it the same way.
    for _ in range(100):
        if repaired:
            break
        q = robot.random_configurations(rng, 5)
        optimized = plan_trajectory(q, limits)
        if not optimized.repaired.any():
            continue
        repaired += 1
        fitted = plan_trajectory(q, limits, strategy=RefinedStrategy(sweeps=0))
        assert fitted.duration == optimized.duration
        np.testing.assert_array_equal(fitted.repaired, optimized.repaired)
        refined = plan_trajectory(q, limits, strategy="refined")
        assert refined.duration <= optimized.duration
        assert_within_limits(refined, limits.velocity, limits.acceleration, limits.jerk, limits.lower, limits.upper)
    assert repaired >= 1


def stops_or_start(q, limits, seed, speed):
    """A stop at a random inner waypoint (3 in 10), else a start velocity up to `speed` of the limits (half)."""
    rng = np.random.default_rng(seed)
    kwargs = {}
    if rng.random() < 0.3 and len(q) > 2:
        kwargs["stops"] = [int(rng.integers(1, len(q) - 1))]
    elif rng.random() < 0.5:
        kwargs["start_velocity"] = rng.uniform(-speed, speed, q.shape[1]) * limits.velocity
    return kwargs


@given(problems(max_dof=4, max_points=5), st.integers(0, 2**32 - 1))
@SETTINGS
def test_generated_problems_with_stops_and_start_states(problem, seed):
    q, limits = problem
    kwargs = stops_or_start(q, limits, seed, 0.3)
    try:
        optimized = plan_trajectory(q, limits, **kwargs)
    except InvalidArgumentError:  # a start state that cannot stop within the range: so for both
        with pytest.raises(InvalidArgumentError, match="even braking at once"):
            plan_trajectory(q, limits, strategy="refined", **kwargs)
        return
    refined = plan_trajectory(q, limits, strategy="refined", **kwargs)
    assert refined.duration <= optimized.duration
    assert_passes_waypoints(refined, refined.waypoint_times, q)
    assert_within_limits(refined, limits.velocity, limits.acceleration, limits.jerk, limits.lower, limits.upper)


@given(problems(), st.integers(0, 2**32 - 1))
@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
def test_without_sweeps_it_is_the_optimized_plan_bit_for_bit(problem, seed):
    # The search starts from the optimized states brought within range by the planner's own
    # repair rules (fit_range): with no sweep the plan is the optimized one, repairs included.
    q, limits = problem
    kwargs = stops_or_start(q, limits, seed, 0.5)
    try:
        optimized = plan_trajectory(q, limits, **kwargs)
    except InvalidArgumentError:
        return
    fitted = plan_trajectory(q, limits, strategy=RefinedStrategy(sweeps=0), **kwargs)
    assert fitted.duration == optimized.duration
    np.testing.assert_array_equal(fitted.via_velocities, optimized.via_velocities)
    np.testing.assert_array_equal(fitted.via_accelerations, optimized.via_accelerations)
    np.testing.assert_array_equal(fitted.repaired, optimized.repaired)


@pytest.mark.parametrize("strategy", [["refined"], {"refined": {"sweeps": 1}}, 3])
def test_a_plan_file_strategy_that_is_no_name_is_refused_by_name(strategy):
    # A YAML list or mapping raised TypeError (unhashable) from the membership test.
    from planner import PlannerError
    from planner.app.plan_file import parse_motion_request

    with pytest.raises(PlannerError, match=r"unknown strategy .*; valid: optimized, heuristic, stop, refined"):
        parse_motion_request({"waypoints": [[0, 0, 0], [1, 1, 1]], "strategy": strategy})
