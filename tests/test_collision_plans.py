"""Plans with a scene: planned around obstacles, checked continuously, refused with reasons."""

from __future__ import annotations

import json

import numpy as np
import pytest

from planner import PlannerError, PlanningError
from planner.app.cli import main
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
from planner.collision import CollisionChecker
from planner.motion.trajectory import LIMIT_TOLERANCE

from conftest import get_robot, needs_example_robot_data

BLOCK_PLAN = {
    "units": {"length": "mm", "angle": "deg"},
    "targets": [
        {"position": [200, -150, 60], "pitch": -90, "label": "pick"},
        {"position": [200, 150, 60], "pitch": -90, "label": "place"},
    ],
    "scene": {
        "floor": 0,
        "clearance": 5,
        "obstacles": [{"name": "block", "box": [60, 60, 200], "position": [230, 0, 100]}],
    },
}


def independent_check(robot, plan, scene_clearance: float, allow_everywhere=()) -> None:
    """Re-check a plan at 1 kHz with collision queries (not the distances the planner stepped by)."""
    traj = plan.trajectory
    s = traj.sample(traj.times(1000.0))
    checker = CollisionChecker(robot, plan.scene)
    for q in s.q:
        assert not checker.in_collision(q, allow=allow_everywhere)
    assert min(checker.clearance(q, allow=allow_everywhere).distance for q in s.q[::5]) >= scene_clearance - 1e-4
    peaks = traj.peak_ratios(1000.0)
    assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
    assert peaks["position"] <= LIMIT_TOLERANCE
    np.testing.assert_allclose(traj.sample(plan.waypoint_times).q, plan.waypoints, atol=1e-9)


def plan_with_scene(robot, data):
    return plan_motion(robot, parse_motion_request(data))


def test_a_block_between_pick_and_place_is_planned_around():
    robot = get_robot("al5c")
    plan = plan_with_scene(robot, BLOCK_PLAN)
    assert plan.routes == (0,) and plan.collision_free
    assert plan.collision.closest.distance >= 0.005 - 1e-4
    independent_check(robot, plan, 0.005)
    summary = plan.summary()
    assert summary["collision"]["clear"] and summary["routes"] == [0]
    # The straight joint move would have gone through the block.
    from planner.collision.continuous import check_segment

    checker = CollisionChecker(robot, parse_motion_request(BLOCK_PLAN).scene)
    assert not check_segment(checker, plan.waypoints[0], plan.waypoints[1]).clear


def test_same_seed_same_plan_and_the_seed_matters():
    robot = get_robot("al5c")
    a = plan_with_scene(robot, BLOCK_PLAN)
    b = plan_with_scene(robot, BLOCK_PLAN)
    np.testing.assert_array_equal(a.trajectory.p, b.trajectory.p)
    other = plan_with_scene(robot, {**BLOCK_PLAN, "avoidance": {"seed": 7}})
    assert other.collision_free


def test_a_line_through_an_obstacle_is_refused_naming_it():
    data = {
        **BLOCK_PLAN,
        "targets": [BLOCK_PLAN["targets"][0], {**BLOCK_PLAN["targets"][1], "line": True}],
    }
    with pytest.raises(
        PlanningError, match=r"the straight line into waypoint 1 \(place\) (collides|comes closer) .*block"
    ):
        plan_with_scene(get_robot("al5c"), data)


def test_a_target_inside_an_obstacle_is_refused_or_allowed():
    robot = get_robot("al5c")
    data = {
        "units": {"length": "mm", "angle": "deg"},
        "targets": [
            {"position": [200, -150, 60], "pitch": -90},
            {"position": [230, 0, 30], "pitch": -90, "label": "grasp"},
        ],
        "scene": {"floor": 0, "obstacles": [{"name": "block", "box": [20, 20, 40], "position": [230, 0, 20]}]},
    }
    with pytest.raises(PlanningError, match=r"target 1 \(grasp\).*in_collision: every solution found collides.*block"):
        plan_with_scene(robot, data)
    data["targets"][1]["allow"] = ["block"]
    plan = plan_with_scene(robot, data)
    assert plan.collision_free
    with pytest.raises(
        PlannerError, match=r"targets\[1\].allow: 'brick' is not in the scene; valid names: floor, block"
    ):
        parse_motion_request({**data, "targets": [data["targets"][0], {**data["targets"][1], "allow": ["brick"]}]})


def test_no_way_around_is_refused_with_the_reason():
    # Shelley's first link sweeps the horizontal plane about the base; a post in its way
    # between -60 and +60 deg cannot be passed, and the other way round is beyond the joints' ranges.
    data = {
        "units": {"angle": "deg"},
        "waypoints": [[-60, 0], [60, 0]],
        "scene": {
            "obstacles": [{"name": "post", "cylinder": {"radius": 0.005, "length": 1.0}, "position": [0.06, 0, 0]}]
        },
        "avoidance": {"seed": 1, "time_budget": 0.3},
    }
    with pytest.raises(PlanningError, match=r"no collision-free way from waypoint 0 to waypoint 1: no clear path"):
        plan_with_scene(get_robot("shelley"), data)


def _clear_waypoints(robot, scene_data, rng, count=3):
    checker = CollisionChecker(
        robot, parse_motion_request({"waypoints": [[0] * robot.dof] * 2, "scene": scene_data}).scene
    )
    found = []
    for q in robot.random_configurations(rng, 400):
        if checker.clearance(q).clear:
            found.append(q)
            if len(found) == count:
                return np.array(found)
    return None


def test_random_waypoints_and_boxes_on_the_bundled_arms():
    # Fixed seeds: random boxes, and random waypoints clear of them. Every plan returned is
    # clear when re-checked at 1 kHz by collision queries, keeps every limit and passes every
    # waypoint; any refusal is a PlannerError with a reason.
    rng = np.random.default_rng(2026)
    from planner.collision.continuous import check_segment

    planned = blocked = 0
    for name, floor in (("al5c", 0.0), ("dh3", -0.02), ("three_joint", -1.0)):
        robot = get_robot(name)
        reach = float(np.sum(np.linalg.norm(np.diff(robot.joint_positions(np.zeros(robot.dof)), axis=0), axis=1)))
        for _ in range(5):
            size = rng.uniform(0.1, 0.3, 3) * reach
            centre = rng.uniform([-0.6, -0.6, 0.0], [0.6, 0.6, 0.6]) * reach
            scene = {
                "floor": floor,
                "clearance": 0.002 * reach,
                "obstacles": [{"name": "box", "box": size.tolist(), "position": centre.tolist()}],
            }
            waypoints = _clear_waypoints(robot, scene, rng)
            if waypoints is None:
                continue
            data = {"waypoints": waypoints.tolist(), "scene": scene, "avoidance": {"seed": 3, "time_budget": 1.0}}
            try:
                plan = plan_with_scene(robot, data)
            except PlannerError as error:
                assert "no collision-free way" in str(error)
                continue
            planned += 1
            # The box stands in the way of a straight joint move (the plan goes around it, by a
            # route or along the curve its timing takes, and is re-checked below).
            checker = CollisionChecker(robot, plan.scene)
            blocked += bool(plan.routes) or not all(
                check_segment(checker, a, b).clear for a, b in zip(plan.waypoints, plan.waypoints[1:])
            )
            if plan.collision_free:
                independent_check(robot, plan, 0.002 * reach)
            else:  # an outcome that names the time, the bodies and the depth
                assert plan.collision.first_hit is not None and plan.collision.hit.bodies[0]
    assert planned >= 10 and blocked >= 2


def test_planner_check_reports_the_clearance(tmp_path, capsys):
    path = tmp_path / "block.json"
    path.write_text(json.dumps(BLOCK_PLAN))
    assert main(["check", "al5c", str(path)]) == 0
    out = capsys.readouterr().out
    assert "clear" in out and "mm" in out and "routed around obstacles: segment 0" in out
    assert main(["check", "al5c", str(path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["collision"]["clear"] and report["collision"]["min_distance"] >= 0.005 - 1e-4
    plain = tmp_path / "plain.json"
    plain.write_text(json.dumps({"waypoints": [[0, 1, -1, 0, 0], [0.5, 1, -1, 0, 0]]}))
    assert main(["check", "al5c", str(plain)]) == 0
    assert "no scene" in capsys.readouterr().out


def test_a_check_with_nothing_to_hit_reports_no_distance(tmp_path, capsys):
    # shelley has no self pairs checked: with no obstacles the closest distance is inf, written as
    # null (before, JSON refused it and planner check --json and planner plan --out raised ValueError).
    path = tmp_path / "free.json"
    path.write_text(json.dumps({"waypoints": [[0.1, 0.2], [0.5, 0.6]], "scene": {"obstacles": []}}))
    assert main(["check", "shelley", str(path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["collision"]["clear"] and report["collision"]["min_distance"] is None
    assert main(["plan", "shelley", str(path), "--out", str(tmp_path / "out")]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["collision"]["min_distance"] is None and summary["collision"]["checks"] == 0


def test_the_example_plan_file_goes_around_its_block(capsys):
    from pathlib import Path

    example = Path(__file__).resolve().parents[1] / "examples" / "al5c_around_a_block.yaml"
    assert main(["check", "al5c", str(example), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["collision"]["clear"] and report["routes"] == [0]


def test_the_readme_shows_what_planner_check_prints(capsys):
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    readme = (root / "README.md").read_text()
    start = readme.index("planner check al5c examples/al5c_around_a_block.yaml\n# ")
    block = readme[start : readme.index("```", start)].splitlines()[1:]
    shown = [line.removeprefix("# ") for line in block if line.startswith("# ")]
    assert main(["check", "al5c", str(root / "examples" / "al5c_around_a_block.yaml")]) == 0
    assert capsys.readouterr().out.splitlines() == shown


def test_a_route_edge_is_timed_straight_within_the_limits():
    """time_joint_line: every joint in proportion (on the line), within every limit, as fast as a direct move."""
    from planner.collision.rrt import PathOptions
    from planner.motion.avoid import joint_line, time_joint_line
    from planner.motion.limits import JointLimits
    from planner.motion.plan import plan_trajectory

    robot = get_robot("al5c")
    limits = JointLimits.from_robot(robot)
    reach = CollisionChecker(robot).arm.reach
    rng = np.random.default_rng(7)
    for qa, qb in zip(robot.random_configurations(rng, 4), robot.random_configurations(rng, 4)):
        line = joint_line(robot, qa, qb)
        timing = time_joint_line(line, limits)
        traj = plan_trajectory(
            line.q,
            limits,
            stops=[0, len(line.q) - 1],
            via_velocities=timing.velocity,
            via_accelerations=timing.acceleration,
            min_durations=np.diff(timing.t),
        )
        peaks = traj.peak_ratios(1000.0)
        assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
        q = traj.sample(traj.times(1000.0)).q
        s = (q - qa) @ (qb - qa) / ((qb - qa) @ (qb - qa))
        # How far any point of the arm can be from where the line puts it [m] (reach-weighted).
        off_line = np.max(np.abs(q - (qa + s[:, None] * (qb - qa))) @ reach)
        assert off_line < PathOptions().margin
        direct = plan_trajectory(np.array([qa, qb]), limits).duration
        assert traj.duration <= direct * 1.1  # the profile may be slowed a little so the chain keeps it


def test_a_route_is_passed_smoothly_and_stays_clear():
    """The route's nodes are passed without stopping where the timed motion stays clear."""
    robot = get_robot("al5c")
    plan = plan_with_scene(robot, BLOCK_PLAN)
    assert plan.routes == (0,) and plan.collision_free
    independent_check(robot, plan, 0.005)
    traj = plan.trajectory
    inner = traj.waypoints[1:-1]
    assert len(inner) >= 1
    moving = [np.max(np.abs(traj.sample(np.array([t])).qd)) for t in traj.waypoint_times[1:-1]]
    assert max(moving) > 0.1  # [rad/s]: not at rest at every node


def test_an_uncertified_route_is_certified_where_the_timed_motion_comes_too_close(monkeypatch):
    """plan_motion routes with edges checked at points only; where the timed motion along such a
    route is reported too close, the same search's result is certified (certify_path), the
    edge is halved (passed through its midpoint too), and the plan that comes out keeps the
    clearance (re-checked at 1 kHz)."""
    import planner.app.motion_plan as mp
    from planner.collision.continuous import MotionClearance

    robot = get_robot("al5c")
    # A seed whose route keeps its shortened edges once they are certified (with others the
    # certified search may return another route, which is then planned instead).
    request = {**BLOCK_PLAN, "avoidance": {"seed": 1}}
    plain = plan_with_scene(robot, request)
    asked = []
    real_search, real_certify, real_check = mp.find_clear_path, mp.certify_path, mp.check_trajectory

    def search(*args, **kwargs):
        asked.append(kwargs.get("certify", True))
        return real_search(*args, **kwargs)

    def certify(*args, **kwargs):
        asked.append("certify the same search's path")
        return real_certify(*args, **kwargs)

    def check(checker, trajectory, **kwargs):
        result = real_check(checker, trajectory, **kwargs)
        if len(asked) == 1 and result.clear and kwargs.get("stop_at_first"):
            # Report the first check as too close in the middle of the route, as a real hit would be.
            middle = trajectory.duration / 2
            return MotionClearance(False, result.closest, middle, middle, result.closest, result.checks)
        return result

    monkeypatch.setattr(mp, "find_clear_path", search)
    monkeypatch.setattr(mp, "certify_path", certify)
    monkeypatch.setattr(mp, "check_trajectory", check)
    plan = plan_with_scene(robot, request)
    # The trees are not grown again: the search's result is certified.
    assert asked == [False, "certify the same search's path"]
    assert plan.routes == (0,) and plan.collision_free
    independent_check(robot, plan, 0.005)
    # The edge the motion was reported to stray from is halved: its midpoint is a node now.
    nodes = plan.trajectory.waypoints
    assert any(np.allclose(nodes[i], (nodes[i - 1] + nodes[i + 1]) / 2.0) for i in range(1, len(nodes) - 1))
    assert len(nodes) == len(plain.trajectory.waypoints) + 1


def test_a_route_whose_certified_search_finds_none_is_refused_not_dropped(monkeypatch):
    """Where the timed motion along an uncertified route is reported too close and its search,
    certified, finds no path (certify_path grows new trees when neither of its paths certifies,
    and they may run out of time), the plan is refused with the search's reason. Before, the
    empty path became the route: the waypoint was skipped (its time that of the one before)."""
    import planner.app.motion_plan as mp
    from planner.collision.continuous import MotionClearance
    from planner.collision.rrt import PathResult, PathStatus

    robot = get_robot("al5c")
    third = {"position": [200, 100, 150], "pitch": -60}
    request = {**BLOCK_PLAN, "avoidance": {"seed": 1}, "targets": [*BLOCK_PLAN["targets"], third]}
    real_check = mp.check_trajectory
    hits = []

    def check(checker, trajectory, **kwargs):
        result = real_check(checker, trajectory, **kwargs)
        if not hits and result.clear and kwargs.get("stop_at_first"):
            hits.append(trajectory.duration / 4)  # on the route into "place"
            return MotionClearance(False, result.closest, hits[0], hits[0], result.closest, result.checks)
        return result

    def certify(checker, found, **kwargs):
        reason = "no clear path within 5 s"
        return PathResult(PathStatus.NOT_FOUND, np.zeros((0, robot.dof)), reason, found.iterations)

    monkeypatch.setattr(mp, "check_trajectory", check)
    monkeypatch.setattr(mp, "certify_path", certify)
    with pytest.raises(PlanningError, match="from waypoint 0 .pick. to waypoint 1 .place.: no clear path within 5 s"):
        plan_with_scene(robot, request)
    assert hits


def test_a_move_straying_beside_its_clear_straight_segment_passes_its_midpoint(monkeypatch):
    """Where the timed motion of a free move is reported too close but its straight joint segment
    is clear, the move passes the segment's midpoint too (not every sample of the line, each
    with its own state, which times and checks far more waypoints); the plan keeps the clearance."""
    import planner.app.motion_plan as mp
    from planner.collision.continuous import MotionClearance

    robot = get_robot("al5c")
    scene = {**BLOCK_PLAN["scene"], "obstacles": [{"name": "block", "box": [60, 60, 200], "position": [-230, 0, 100]}]}
    request = {**BLOCK_PLAN, "scene": scene}
    plain = plan_with_scene(robot, request)
    assert not plain.routes and len(plain.trajectory.waypoints) == 2
    real_check = mp.check_trajectory
    calls = []

    def check(checker, trajectory, **kwargs):
        result = real_check(checker, trajectory, **kwargs)
        calls.append(result.clear)
        if len(calls) == 1:
            middle = trajectory.duration / 2
            return MotionClearance(False, result.closest, middle, middle, result.closest, result.checks)
        return result

    monkeypatch.setattr(mp, "check_trajectory", check)
    plan = plan_with_scene(robot, request)
    assert plan.routes == (0,) and plan.collision_free
    nodes = plan.trajectory.waypoints
    assert len(nodes) == 3 and np.allclose(nodes[1], (nodes[0] + nodes[2]) / 2.0)
    independent_check(robot, plan, 0.005)


def test_the_path_search_without_certificates_keeps_its_seed_and_checks_its_points():
    from planner.collision.continuous import check_segment
    from planner.collision.rrt import PathOptions, find_clear_path, segment_looks_clear

    robot = get_robot("al5c")
    checker = CollisionChecker(robot, parse_motion_request(BLOCK_PLAN).scene)
    qa, qb = np.array([-0.6, 1.2, -1.4, -0.8, 0.0]), np.array([0.6, 1.2, -1.4, -0.8, 0.0])
    assert not check_segment(checker, qa, qb).clear
    first = find_clear_path(checker, qa, qb, options=PathOptions(seed=4), certify=False)
    again = find_clear_path(checker, qa, qb, options=PathOptions(seed=4), certify=False)
    assert first.found and np.array_equal(first.path, again.path)
    np.testing.assert_array_equal(first.path[[0, -1]], [qa, qb])
    for a, b in zip(first.path, first.path[1:]):
        assert segment_looks_clear(checker, a, b)


def test_the_collision_benchmark_times_the_steps_of_a_plan_and_puts_them_back():
    """bench_collision --phases: CPU per step of plan_motion, the module's functions restored after."""
    import importlib.util
    from pathlib import Path

    import planner.app.motion_plan as motion_plan

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_collision.py"
    spec = importlib.util.spec_from_file_location("bench_collision_under_test", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    before = {name: getattr(motion_plan, name) for names in bench.PHASES.values() for name in names}
    robot = get_robot("al5c")
    with bench.timed_phases({}) as spent:
        plan = motion_plan.plan_motion(robot, parse_motion_request(BLOCK_PLAN))
    assert plan.routes and set(spent) == set(bench.PHASES)
    assert all(t > 0.0 for t in spent.values())
    assert all(getattr(motion_plan, name) is f for name, f in before.items())


@needs_example_robot_data
def test_a_path_without_certificates_has_every_node_tested():
    # Found by fuzzing (panda, three random boxes): a shortcut starts at a point along an edge,
    # not at a node the trees tested; the lazy search returned that point 1.3 mm inside a box
    # (the timed motion passes its nodes exactly, so its continuous check could only fail). The
    # edges between nodes passed only the cheap checks: they may come closer (not tested here).
    from planner.collision.rrt import PathOptions, find_clear_path

    robot = get_robot("panda")
    boxes = [
        (
            [0.1677647097178717, 0.09867295494193301, 0.08310953720003629],
            [0.5348312909632295, 0.23217142777593588, 0.15977434199177762],
        ),
        (
            [0.35180432776197995, 0.13529354388875983, 0.2668685046172039],
            [0.20066027500047862, -0.6340715567983585, 0.629524931368346],
        ),
        (
            [0.15460727724575668, 0.15857495313023726, 0.16611398285808696],
            [-0.4497673754867603, -0.4986493698302009, 0.9374138005641638],
        ),
    ]
    scene = {
        "clearance": 0.0,
        "obstacles": [{"name": f"b{i}", "box": s, "position": p} for i, (s, p) in enumerate(boxes)],
    }
    checker = CollisionChecker(robot, parse_motion_request({"waypoints": [[0] * robot.dof] * 2, "scene": scene}).scene)
    qa = np.array(
        [
            -1.1152323384017027,
            -0.7004849088116276,
            -2.441215373233062,
            -0.2413966382780628,
            0.8449316900567649,
            2.8320039465713793,
            -0.999244383483906,
        ]
    )
    qb = np.array(
        [
            1.769307443634483,
            -1.539452051940878,
            -1.703665985301331,
            -1.127999859180886,
            2.472873439296013,
            0.2471638816233266,
            -1.8169414975611915,
        ]
    )
    result = find_clear_path(checker, qa, qb, options=PathOptions(seed=63, time_budget=2.0), certify=False)
    assert result.found
    mask = checker.pair_mask(())
    assert all(checker.distance_at(q, mask).distance >= 0.0 for q in result.path)


@pytest.mark.parametrize("gap", [0.003, 0.006, 0.02])
def test_a_joint_waypoint_is_refused_exactly_when_it_is_closer_than_the_clearance(gap):
    # The waypoints are checked with one proximity test at clearance + 2 margin, and a distance
    # only when that fails: a waypoint between the two (0.006) is planned, a nearer one refused.
    robot = get_robot("al5c")
    q = [0.0, 1.2, -1.4, -0.8, 0.0]
    tip = robot.fk(np.array(q))[:3, 3]
    # A 20 mm ball under the wrist: the distance is the gap (measured below, not assumed).
    scene = {
        "clearance": 0.005,
        "obstacles": [{"name": "ball", "sphere": 0.02, "position": (tip - [0.0, 0.0, 0.032 + gap]).tolist()}],
    }
    request = parse_motion_request({"waypoints": [q, [0.0, 1.0, -1.0, -0.8, 0.0]], "scene": scene})
    distance = CollisionChecker(robot, request.scene).clearance(q).distance
    assert distance == pytest.approx(gap, abs=2e-4)
    if distance < 0.005:
        with pytest.raises(PlanningError, match=r"waypoint 0 does not keep the clearance \(5 mm\).*ball"):
            plan_motion(robot, request)
    else:
        plan = plan_motion(robot, request)
        assert plan.collision_free
        independent_check(robot, plan, 0.005)


def test_a_blocked_move_the_quick_look_misses_is_routed_into_the_same_plan(monkeypatch):
    # plan_motion routes a move before timing where points every 0.2 rad of its straight segment
    # find it blocked; one blocked only between them is caught by the continuous check of the
    # timed motion and routed then, with the same search: the same plan, only later.
    import planner.app.motion_plan as motion_plan

    robot = get_robot("al5c")
    first = plan_with_scene(robot, BLOCK_PLAN)
    monkeypatch.setattr(motion_plan, "_PLAINLY_BLOCKED", 100.0)  # only the ends: never blocked
    late = plan_with_scene(robot, BLOCK_PLAN)
    assert first.routes == late.routes == (0,) and late.collision_free
    np.testing.assert_array_equal(first.trajectory.p, late.trajectory.p)
    independent_check(robot, late, 0.005)
