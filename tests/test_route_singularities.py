"""Routes around obstacles between ends on opposite sides of a singularity get no detours.

Any joint path between configurations whose square task Jacobian has determinants of opposite
signs passes a singular configuration, so, as for a straight move between them, no detour can
keep such a route above the threshold (issue 11: no detours that clear nothing; issue 17: their
search was most of the CPU of some routed UR5 plans).
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import planner
import planner.motion.detours as detours
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
from planner.motion.detours import must_cross_singularity

from conftest import get_robot, needs_example_robot_data

SCENE = {
    "obstacles": [
        {"name": "table", "box": [1.6, 1.6, 0.05], "position": [0.0, 0.0, -0.03]},
        {"name": "box", "box": [0.25, 0.25, 0.5], "position": [0.45, 0.0, 0.25]},
    ]
}


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_crossing_means_opposite_determinant_signs(seed):
    robot = get_robot("dh3")  # 3 joints, position task: a square 3x3 Jacobian
    a, b = robot.random_configurations(np.random.default_rng(seed), 2)
    signs = [np.sign(np.linalg.det(robot.jacobian(q)[:3])) for q in (a, b)]
    assert must_cross_singularity(robot, a, b) == (signs[0] * signs[1] < 0)
    assert must_cross_singularity(robot, a, b) == must_cross_singularity(robot, b, a)
    assert not must_cross_singularity(robot, a, a)


def test_dh3_elbow_sides_and_a_redundant_arm():
    dh3 = get_robot("dh3")
    up, down = np.array([0.3, 0.8, 0.9]), np.array([0.3, 0.8, -0.9])
    assert must_cross_singularity(dh3, up, down)
    assert not must_cross_singularity(dh3, up, up * [1.0, 1.2, 0.5])
    al5c = get_robot("al5c")  # 5 joints for a 3-D position: never forced
    q = al5c.random_configurations(np.random.default_rng(3), 2)
    assert not must_cross_singularity(al5c, q[0], q[1])


@needs_example_robot_data
def test_a_ur5_route_across_the_wrist_singularity_searches_no_detour(monkeypatch):
    robot = planner.load_robot("ur5")
    # One of bench_collision's routed pairs (rounded): the wrist's middle joint changes sign.
    start = [-4.137, 4.431, -1.046, 3.843, 1.36, -3.553]
    goal = [-1.009, 3.855, 2.326, -1.85, 3.525, -5.564]
    assert must_cross_singularity(robot, np.array(start), np.array(goal))
    ascents = []
    ascend = detours._ascend
    monkeypatch.setattr(detours, "_ascend", lambda *a, **k: ascents.append(1) or ascend(*a, **k))
    request = parse_motion_request({"waypoints": [start, goal], "scene": SCENE, "avoidance": {"seed": 16}})
    plan = plan_motion(robot, request)
    assert plan.routes == (0,) and plan.collision is not None and plan.collision.clear
    # Before: two detour searches, both taken out again as they cleared nothing.
    assert ascents == []
    assert plan.detours == () and plan.unresolved == (0,)
    assert plan.singularity.min_inverse_condition < plan.singularity.threshold
