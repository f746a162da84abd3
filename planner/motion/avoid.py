"""Moves around obstacles: straight joint-space lines and collision-free routes, ready to time.

A route from :func:`planner.collision.rrt.find_clear_path` is a polyline in joint space whose
edges are certified clear. :func:`joint_line` samples one edge densely as a
:class:`~planner.motion.line.LinePath`, so the line timing
(:func:`planner.motion.line_timing.time_line`) moves the arm along it, jerk-limited, from rest
to rest, and the Ruckig chain through the samples stays on the edge (to within a fraction of a
millimetre, which the path search's margin covers).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from planner.collision.checker import CollisionChecker
from planner.collision.rrt import PathOptions, PathResult, find_clear_path
from planner.model.robot import Robot
from planner.motion.line import LinePath

__all__ = ["EDGE_SPACING", "clear_route", "joint_line"]

#: Largest joint change between two samples of a joint-space line [rad or m].
EDGE_SPACING = 0.05


def joint_line(robot: Robot, q_start: np.ndarray, q_end: np.ndarray, *, spacing: float = EDGE_SPACING) -> LinePath:
    """The straight joint-space line from `q_start` to `q_end`, sampled every `spacing` or finer."""
    q0, q1 = np.asarray(q_start, dtype=float), np.asarray(q_end, dtype=float)
    n = max(5, int(math.ceil(float(np.max(np.abs(q1 - q0))) / spacing)) + 1)
    s = np.linspace(0.0, 1.0, n)
    q = q0 + s[:, None] * (q1 - q0)
    inverse_condition, _ = robot.conditioning(q)
    return LinePath(s, q, robot.position(q), 0.0, float(np.min(inverse_condition)))


def clear_route(
    checker: CollisionChecker,
    q_start: np.ndarray,
    q_end: np.ndarray,
    *,
    allow: Sequence[str] = (),
    options: PathOptions | None = None,
) -> tuple[list[LinePath], PathResult]:
    """Joint lines along a collision-free route from `q_start` to `q_end`.

    Returns:
        The lines (empty when no route was found) and the path search's result (its status
        and reason say why not).
    """
    options = options or PathOptions()
    result = find_clear_path(checker, q_start, q_end, options=options, allow=allow)
    if not result.found:
        return [], result
    return [joint_line(checker.robot, a, b) for a, b in zip(result.path, result.path[1:])], result
