"""Generated straight-line cases shared by the line tests."""

from __future__ import annotations

import numpy as np

import planner
from planner.app.plan_file import parse_motion_request
from planner.motion.branch_choice import TargetSolver
from planner.motion.line import line_waypoints


def random_position_line(robot: planner.Robot, rng: np.random.Generator, tries: int = 40):
    """Plan-file data for a line between the tips of two random configurations IK can follow, and its path."""
    solver = TargetSolver(robot)
    for _ in range(tries):
        q = robot.random_configurations(rng, 2)
        data = {
            "targets": [
                {"position": robot.position(q[0]).tolist()},
                {"position": robot.position(q[1]).tolist(), "line": True},
            ]
        }
        request = parse_motion_request(data)
        try:
            start = solver.choose(request.targets[0], None).q
            path = line_waypoints(solver, request.targets[0], request.targets[1], start)
        except planner.PlannerError:
            continue
        return data, path
    return None
