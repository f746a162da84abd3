"""Property tests of the path search around obstacles (generated starts, goals and boxes).

Whatever the boxes and ends, :func:`find_clear_path` gives the same answer for the same seed;
a path it returns starts and ends where asked and keeps the clearance along every edge when
re-checked densely by collision queries (not the distances it decided by); where it finds
none, the result says why (an end that does not keep the clearance, or the budget spent). The
same holds for :func:`plan_motion` with such a scene: the same seed gives the same plan.
"""

from __future__ import annotations

import numpy as np
import pytest
from dh_arms import bundled_robot, configurations, property_settings
from hypothesis import event, given, note
from hypothesis import strategies as st

import planner
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request, parse_scene
from planner.collision import CollisionChecker
from planner.collision.rrt import PathOptions, PathStatus, certify_path, find_clear_path, path_margin

from conftest import get_robot, needs_example_robot_data

_FLOAT = {"allow_nan": False, "allow_infinity": False, "allow_subnormal": False}
#: Largest joint change between the dense re-check's samples of an edge [rad].
_DENSE = 0.005


@st.composite
def boxes(draw, robot: planner.Robot, qa: np.ndarray, qb: np.ndarray) -> dict:
    """One or two boxes: the first where the straight joint move from `qa` to `qb` takes the tip halfway."""
    middle = robot.position((qa + qb) / 2.0)
    obstacles = []
    for k in range(draw(st.integers(1, 2))):
        size = [draw(st.floats(0.02, 0.12, **_FLOAT)) for _ in range(3)]
        offset = [draw(st.floats(-0.1, 0.1, **_FLOAT)) for _ in range(3)]
        centre = (middle + offset if k == 0 else np.array(offset) * 3.0).tolist()
        obstacles.append({"name": f"b{k}", "box": size, "position": centre})
    return {"clearance": draw(st.sampled_from([0.0, 0.005])), "obstacles": obstacles}


def _scene(data: dict):
    robot = bundled_robot("al5c")
    return parse_motion_request({"waypoints": [[0.0] * robot.dof] * 2, "scene": data}).scene


def _edges_clear_densely(checker: CollisionChecker, path: np.ndarray, keep: float) -> bool:
    near = checker.closer_than(keep)
    for a, b in zip(path, path[1:]):
        n = max(1, int(np.ceil(np.max(np.abs(b - a)) / _DENSE)))
        if any(near(a + s * (b - a)) for s in np.linspace(0.0, 1.0, n + 1)):
            return False
    return True


@given(data=st.data(), seed=st.integers(0, 2**16))
@property_settings(40)
def test_a_path_search_is_repeatable_and_its_path_clear_or_it_says_why(data, seed):
    robot = bundled_robot("al5c")
    qa, qb = data.draw(configurations(robot)), data.draw(configurations(robot))
    checker = CollisionChecker(robot, _scene(data.draw(boxes(robot, qa, qb))))
    # A tiny budget of extensions too: a search that runs out says so.
    options = PathOptions(
        seed=seed,
        time_budget=0.3,
        max_iterations=data.draw(st.sampled_from([2, 600])),
        line_bias=data.draw(st.sampled_from([0.0, 0.5, 1.0])),
    )
    # The trees are grown even where the straight segment is clear (they are what is tested).
    first = find_clear_path(checker, qa, qb, options=options, try_straight=False)
    again = find_clear_path(checker, qa, qb, options=options, try_straight=False)
    note(f"{first.status}: {first.reason}, {len(first.path)} nodes")
    event(f"{first.status.value} {min(len(first.path), 3)}")
    assert first.status is again.status and np.array_equal(first.path, again.path)
    clearance = checker.scene.clearance
    if first.found:
        assert first.reason == "" and first.path.shape[1] == robot.dof
        np.testing.assert_array_equal(first.path[[0, -1]], [qa, qb])
        # The certified edges keep the clearance (less the certificate's tolerance).
        assert _edges_clear_densely(checker, first.path, max(clearance - 1e-4, 0.0))
        return
    assert first.reason and first.path.shape == (0, robot.dof)
    ends = [checker.clearance(q).distance for q in (qa, qb)]
    if first.status is PathStatus.START_IN_COLLISION:
        assert ends[0] < clearance
    elif first.status is PathStatus.GOAL_IN_COLLISION:
        assert ends[0] >= clearance > ends[1]
    else:
        assert first.status is PathStatus.NOT_FOUND and min(ends) >= clearance
        assert "extensions" in first.reason or " s" in first.reason


@given(data=st.data(), seed=st.integers(0, 2**16))
@property_settings(25)
def test_certifying_a_search_without_certificates_gives_the_search_with_them(data, seed):
    # plan_motion searches without certificates and, where the timed motion along the route
    # fails its check, certifies that result instead of growing the same trees again.
    robot = bundled_robot("al5c")
    qa, qb = data.draw(configurations(robot)), data.draw(configurations(robot))
    checker = CollisionChecker(robot, _scene(data.draw(boxes(robot, qa, qb))))
    options = PathOptions(seed=seed, time_budget=10.0, max_iterations=600)
    lazy = find_clear_path(checker, qa, qb, options=options, try_straight=False, certify=False)
    certified = certify_path(checker, lazy, options=options)
    direct = find_clear_path(checker, qa, qb, options=options, try_straight=False)
    event(f"{direct.status.value}, {'same' if np.array_equal(lazy.path, direct.path) else 'other'} path")
    assert certified.status is direct.status and np.array_equal(certified.path, direct.path)
    assert certified.iterations == direct.iterations


@given(data=st.data(), seed=st.integers(0, 2**16))
@property_settings(12)
def test_a_plan_around_boxes_is_repeatable_and_clear_or_refused(data, seed):
    robot = bundled_robot("al5c")
    qa, qb = data.draw(configurations(robot)), data.draw(configurations(robot))
    scene = data.draw(boxes(robot, qa, qb))
    waypoints = [qa.tolist(), qb.tolist()]
    request = {"waypoints": waypoints, "scene": scene, "avoidance": {"seed": seed, "time_budget": 0.3}}
    note(f"{request}")
    try:
        plan = plan_motion(robot, parse_motion_request(request))
    except planner.PlannerError as error:
        note(f"refused: {error}")
        event("refused")
        return
    event(f"routed {bool(plan.routes)}, clear {plan.collision_free}")
    again = plan_motion(robot, parse_motion_request(request))
    assert plan.routes == again.routes
    np.testing.assert_array_equal(plan.trajectory.waypoints, again.trajectory.waypoints)
    assert plan.trajectory.duration == again.trajectory.duration
    if plan.collision_free:
        checker = CollisionChecker(robot, plan.scene)
        for q in plan.trajectory.sample(plan.trajectory.times(1000.0)).q:
            assert not checker.in_collision(q)
    else:
        assert plan.collision.first_hit is not None


def test_the_search_options_name_a_bad_value():
    for field, value in (("line_bias", 1.5), ("line_bias", -0.1), ("line_spread", 0.0), ("step", -1.0)):
        try:
            PathOptions(**{field: value})
        except planner.PlannerError as error:
            assert field in str(error) and repr(value) in str(error)
        else:
            raise AssertionError(f"PathOptions({field}={value!r}) was accepted")


def test_a_search_between_ends_outside_the_joint_ranges_names_the_joint():
    robot = planner.load_robot("al5c")
    checker = CollisionChecker(robot, parse_scene({"floor": -0.2}))
    inside = (robot.lower + robot.upper) / 2.0
    for end in ("start", "goal"):
        outside = inside.copy()
        outside[2] = robot.upper[2] + 0.1  # the elbow
        ends = (outside, inside) if end == "start" else (inside, outside)
        try:
            find_clear_path(checker, *ends)
        except planner.JointLimitError as error:
            assert "elbow" in str(error) and f"path {end}" in str(error)
        else:
            raise AssertionError(f"a {end} outside the elbow's range was accepted")


#: bench_collision's table: its top 5 mm below the arm's base.
_TABLE = {"name": "table", "box": [1.6, 1.6, 0.05], "position": [0.0, 0.0, -0.03]}


def _example_scene(draw, robot: planner.Robot, qa: np.ndarray, qb: np.ndarray) -> dict:
    """A table under the arm's base and a box where the straight move from `qa` to `qb` takes the tip halfway."""
    middle = robot.position((qa + qb) / 2.0)
    size = [draw(st.floats(0.05, 0.3, **_FLOAT)) for _ in range(3)]
    offset = [draw(st.floats(-0.05, 0.05, **_FLOAT)) for _ in range(3)]
    return {
        "clearance": draw(st.sampled_from([0.0, 0.005])),
        "obstacles": [
            _TABLE,
            {"name": "box", "box": size, "position": (middle + offset).tolist()},
        ],
    }


@pytest.mark.parametrize("name", ["ur5", "panda"])
@needs_example_robot_data
@given(data=st.data(), seed=st.integers(0, 2**16))
@property_settings(15)
def test_a_search_on_an_example_arm_keeps_its_margin_along_every_edge_or_says_why(name, data, seed):
    # The margin the path keeps is computed here from the ends' distances (path_margin), apart
    # from the search's own shortcut for far ends; the certified edges keep it on a dense
    # re-check by collision queries, the same seed gives the same path, and certifying the
    # search without certificates gives the search with them.
    robot = get_robot(name)
    # Ends clear of the table (most random ur5 configurations are not): the first two that a
    # generator seeded by hypothesis draws.
    table = CollisionChecker(robot, parse_scene({"obstacles": [_TABLE]}))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    ends = []
    while len(ends) < 2:
        q = robot.random_configurations(rng, 1)[0]
        if not table.in_collision(q):
            ends.append(q)
    qa, qb = ends
    checker = CollisionChecker(robot, parse_scene(_example_scene(data.draw, robot, qa, qb)))
    options = PathOptions(seed=seed, time_budget=2.0, max_iterations=800)
    first = find_clear_path(checker, qa, qb, options=options, try_straight=False)
    again = find_clear_path(checker, qa, qb, options=options, try_straight=False)
    lazy = find_clear_path(checker, qa, qb, options=options, try_straight=False, certify=False)
    note(f"{first.status}: {first.reason}, {len(first.path)} nodes")
    event(f"{first.status.value}")
    assert first.status is again.status and np.array_equal(first.path, again.path)
    certified = certify_path(checker, lazy, options=options)
    assert certified.status is first.status and np.array_equal(certified.path, first.path)
    clearance = checker.scene.clearance
    ends = [checker.clearance(q).distance for q in (qa, qb)]
    if not first.found:
        assert first.reason and first.path.shape == (0, robot.dof)
        if first.status is PathStatus.START_IN_COLLISION:
            assert ends[0] < clearance
        elif first.status is PathStatus.GOAL_IN_COLLISION:
            assert ends[0] >= clearance > ends[1]
        else:
            assert min(ends) >= clearance and ("extensions" in first.reason or " s" in first.reason)
        return
    np.testing.assert_array_equal(first.path[[0, -1]], [qa, qb])
    keep = clearance + path_margin(clearance, min(ends), options.margin)
    assert _edges_clear_densely(checker, first.path, max(keep - 1e-4, 0.0))
