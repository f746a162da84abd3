"""Fuzz: thousands of random paths with random per-joint limits on every bundled arm (fixed seeds).

Each plan must either succeed or raise a `planner.PlannerError`; a success must pass every
waypoint and hold every limit by an independent check of the sampled derivatives (the
trajectory's own states at 1 kHz and at every knot, and finite differences of its positions).
A fuzz run of 1 in 2,000 paths once let `ruckig.RuckigError` escape; this keeps that closed.
"""

from __future__ import annotations

import numpy as np
import pytest
from trajectory_checks import assert_passes_waypoints, assert_within_limits

import planner
from planner.motion.vias import VIA_STRATEGIES

PATHS_PER_ARM = 750


def _limits(robot: planner.Robot, rng: np.random.Generator) -> planner.JointLimits:
    velocity = rng.uniform(0.1, 6.0, robot.dof)
    acceleration = velocity * rng.uniform(0.5, 20.0, robot.dof)
    jerk = acceleration * rng.uniform(2.0, 100.0, robot.dof)
    return planner.JointLimits.from_robot(robot, velocity=velocity, acceleration=acceleration, jerk=jerk)


@pytest.mark.parametrize("name", ["shelley", "al5c", "three_joint", "dh3"])
def test_random_paths_plan_within_limits(name):
    robot = planner.load_robot(name)
    rng = np.random.default_rng(sum(map(ord, name)))
    refused = 0
    for _ in range(PATHS_PER_ARM):
        limits = _limits(robot, rng)
        waypoints = robot.random_configurations(rng, int(rng.integers(2, 7)))
        strategy = str(rng.choice(list(VIA_STRATEGIES)))
        try:
            traj = planner.plan_trajectory(waypoints, limits, strategy=strategy)
        except planner.PlannerError:
            refused += 1
            continue
        assert_passes_waypoints(traj, traj.waypoint_times, waypoints)
        assert_within_limits(traj, limits.velocity, limits.acceleration, limits.jerk, limits.lower, limits.upper)
    assert refused == 0, f"{refused} of {PATHS_PER_ARM} valid paths refused on {name}"
