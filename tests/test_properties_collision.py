"""Property tests of plans with a scene: bundled arms and random DH arms, random obstacles.

Whatever the arm, scene and waypoints, `plan_motion` either refuses with a `PlannerError`, or
returns a plan that keeps every limit, passes every waypoint and is clear when re-checked at
1 kHz by collision queries (or says where it is not: an outcome, never a silent success).
"""

from __future__ import annotations

import numpy as np
import pytest
from dh_arms import arm, arm_specs, configurations, property_settings, reach_bound
from hypothesis import given, note
from hypothesis import strategies as st

import planner
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
from planner.collision import CollisionChecker
from planner.motion.trajectory import LIMIT_TOLERANCE

_FLOAT = {"allow_nan": False, "allow_infinity": False, "allow_subnormal": False}


@st.composite
def obstacles(draw, reach: float) -> list[dict]:
    out = []
    for k in range(draw(st.integers(0, 2))):
        centre = [draw(st.floats(-0.8, 0.8, **_FLOAT)) * reach for _ in range(3)]
        kind = draw(st.sampled_from(["box", "sphere", "cylinder"]))
        size = draw(st.floats(0.05, 0.4, **_FLOAT)) * reach
        shape = {
            "box": {"box": [size, size / 2, size * 1.5]},
            "sphere": {"sphere": size / 2},
            "cylinder": {"cylinder": {"radius": size / 3, "length": size * 2}},
        }[kind]
        rpy = [draw(st.floats(-3.1, 3.1, **_FLOAT)) for _ in range(3)]
        out.append({"name": f"o{k}", **shape, "position": centre, "rpy": rpy})
    return out


@given(data=st.data(), spec=arm_specs())
@property_settings(25)
def test_plans_with_random_scenes_are_clear_or_refused(data, spec):
    _check_a_random_scene(data, spec)


@pytest.mark.slow
@given(data=st.data(), spec=arm_specs())
@property_settings(400)
def test_plans_with_random_scenes_are_clear_or_refused_many(data, spec):
    _check_a_random_scene(data, spec)


def _check_a_random_scene(data, spec) -> None:
    robot = arm(spec)
    reach = max(reach_bound(robot), 1e-3)
    scene = {
        "clearance": data.draw(st.floats(0.0, 0.02, **_FLOAT)) * reach,
        "obstacles": data.draw(obstacles(reach)),
    }
    if data.draw(st.booleans()):
        scene["floor"] = data.draw(st.floats(-1.0, 0.0, **_FLOAT)) * reach
    waypoints = [data.draw(configurations(robot)).tolist() for _ in range(3)]
    request = {"waypoints": waypoints, "scene": scene, "avoidance": {"seed": 0, "time_budget": 0.3}}
    note(f"{request}")
    try:
        plan = plan_motion(robot, parse_motion_request(request))
    except planner.PlannerError as error:
        note(f"refused: {error}")
        return
    traj = plan.trajectory
    peaks = traj.peak_ratios(1000.0)
    assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
    assert peaks["position"] <= LIMIT_TOLERANCE
    np.testing.assert_allclose(traj.sample(plan.waypoint_times).q, plan.waypoints, atol=1e-9)
    assert plan.collision is not None
    if plan.collision.clear:
        checker = CollisionChecker(robot, plan.scene)
        for q in traj.sample(traj.times(1000.0)).q:
            assert not checker.in_collision(q)
    else:
        assert plan.collision.first_hit is not None and plan.collision.hit is not None
