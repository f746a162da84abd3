"""Collision geometry, scenes, distance checks, continuous checks and paths around obstacles."""

from __future__ import annotations

import math

import coal
import numpy as np
import pytest
from dh_arms import dh_descriptions, property_settings, robot_from_description
from hypothesis import given
from hypothesis import strategies as st

from planner import InvalidArgumentError, PlannerError, Robot, urdf_from_dh
from planner.collision import FLOOR, Box, CollisionChecker, Cylinder, Obstacle, Scene, Sphere, parse_scene
from planner.collision.arm import arm_collision_model
from planner.collision.checker import shared_checker
from planner.collision.continuous import check_segment, check_trajectory
from planner.collision.rrt import PathOptions, PathStatus, find_clear_path
from planner.core.rotations import rpy_to_matrix
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory

from conftest import get_robot, needs_example_robot_data

deg = np.radians

#: Two bundled arms (capsules) and two example-robot-data arms (meshes), the latter where installed.
MIXED_ARMS = [
    "al5c",
    "dh3",
    pytest.param("ur5", marks=needs_example_robot_data),
    pytest.param("panda", marks=needs_example_robot_data),
]


def _one_link(radius: float = 0.01, length: float = 0.3, speed: float = 60.0) -> Robot:
    """A single link turning about the vertical axis at height 0.1 m: a capsule from the axis out."""
    description = {
        "name": "stick",
        "units": {"length": "m", "angle": "deg"},
        "velocity": speed,
        "base": {"xyz": [0, 0, 0.1]},
        "joints": [{"name": "yaw", "axis": [0, 0, 1], "lower": -170, "upper": 170}],
        "tool": {"name": "tip", "xyz": [length, 0, 0], "radius": radius},
        "collision": {"radius": radius},
    }
    return Robot(urdf_from_dh(description), tip="tip")


# ---------------------------------------------------------------------------- scenes


def test_scene_from_the_plan_file_form_in_its_units():
    scene = parse_scene(
        {
            "floor": 0.0,
            "clearance": 5,
            "obstacles": [
                {"name": "block", "box": [40, 40, 100], "position": [200, 100, 50]},
                {"name": "post", "cylinder": {"radius": 20, "length": 200}, "position": [100, -150, 100]},
                {"name": "ball", "sphere": 30, "position": [150, 0, 200], "rpy": [0, 0, 90]},
            ],
        },
        length_scale=0.001,
        angle_scale=math.pi / 180,
    )
    assert scene.floor == 0.0 and scene.clearance == pytest.approx(0.005)
    block, post, ball = scene.obstacles
    assert block.shape == Box((0.04, 0.04, 0.1)) and np.allclose(block.position, [0.2, 0.1, 0.05])
    assert post.shape == Cylinder(0.02, 0.2) and ball.shape == Sphere(0.03)
    np.testing.assert_allclose(ball.rotation, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    assert scene.names == (FLOOR, "block", "post", "ball")


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"floor": 0, "walls": []}, "unknown scene key(s) walls; valid keys: floor, clearance, obstacles"),
        ({"obstacles": [{"name": "a", "position": [0, 0, 0]}]}, "give exactly one shape (box, sphere, cylinder)"),
        ({"obstacles": [{"name": "a", "box": [1, 1], "position": [0, 0, 0]}]}, "box must be a list of 3 numbers"),
        ({"obstacles": [{"name": "a", "sphere": -1, "position": [0, 0, 0]}]}, "sphere radius must be positive"),
        ({"obstacles": [{"name": "a", "sphere": 1}]}, "needs a position"),
        (
            {"obstacles": [{"name": "a", "sphere": 1, "position": [0, 0, 0]}] * 2},
            "obstacle names must differ; repeated: a",
        ),
        ({"clearance": -1}, "scene.clearance must be a distance >= 0"),
        (
            {"obstacles": [{"name": "a", "cylinder": 2, "position": [0, 0, 0]}]},
            "cylinder must be {radius: R, length: L}",
        ),
    ],
)
def test_bad_scenes_are_named(data, message):
    with pytest.raises(InvalidArgumentError, match="^plan.yaml: .*" + _escape(message)):
        parse_scene(data, source="plan.yaml")


def _escape(text: str) -> str:
    import re

    return re.escape(text)


def test_allow_names_must_be_in_the_scene():
    scene = Scene(floor=0.0, obstacles=(Obstacle("block", Sphere(0.1), np.zeros(3)),))
    with pytest.raises(InvalidArgumentError, match=r"allow: 'brick' is not in the scene; valid names: floor, block"):
        CollisionChecker(get_robot("dh3"), scene).clearance([0, 0.5, 0.5], allow=["brick"])


@pytest.mark.parametrize(
    ("allow", "message"),
    [
        ("block", "allow must be a list of scene names, got 'block'"),
        (5, "allow must be a list of scene names, got 5"),
        ([3], "allow must be a list of scene names, got 3 among them"),
    ],
)
def test_allow_must_be_a_list_of_names(allow, message):
    """A single name or a number is refused, not read letter by letter or leaked as a TypeError."""
    scene = Scene(floor=0.0, obstacles=(Obstacle("block", Sphere(0.1), np.zeros(3)),))
    checker = CollisionChecker(get_robot("dh3"), scene)
    for call in (
        lambda: checker.clearance([0, 0.5, 0.5], allow=allow),
        lambda: checker.in_collision([0, 0.5, 0.5], allow=allow),
        lambda: checker.closer_than(0.01, allow=allow),
        lambda: checker.pair_mask(allow),
    ):
        with pytest.raises(InvalidArgumentError, match=_escape(message)):
            call()
    # Tuples, lists and sets of names work alike; allowing the block leaves out its pairs.
    assert checker.pair_mask(("block",)).sum() < checker.pair_mask([]).sum()
    assert np.array_equal(checker.pair_mask({"block"}), checker.pair_mask(["block"]))


@pytest.mark.parametrize("distance", ["a", float("nan"), float("inf"), True, None])
def test_closer_than_needs_a_finite_distance(distance):
    checker = CollisionChecker(get_robot("dh3"), Scene(floor=0.0))
    with pytest.raises(InvalidArgumentError, match="distance must be a (finite )?number"):
        checker.closer_than(distance)


def test_pair_weights_needs_a_checker():
    from planner.collision.continuous import pair_weights

    with pytest.raises(InvalidArgumentError, match="pair_weights needs a CollisionChecker, got str"):
        pair_weights("x")


# ---------------------------------------------------------------------------- geometry and checks


def test_generated_capsules_against_hand_computed_distances():
    robot = _one_link(radius=0.01, length=0.3)
    arm = arm_collision_model(robot)
    assert arm.source == "urdf" and arm.geometry.ngeoms == 3  # cylinder and two end spheres
    rng = np.random.default_rng(3)
    for _ in range(20):
        yaw = rng.uniform(-2.5, 2.5)
        a, b = np.array([0, 0, 0.1]), np.array([0.3 * math.cos(yaw), 0.3 * math.sin(yaw), 0.1])
        # Capsule to plane: the lowest point of the segment, less the radius.
        floor = rng.uniform(-0.2, 0.05)
        plane = CollisionChecker(robot, Scene(floor=floor), self_collision=False)
        # The capsule turns about a vertical axis: its height never changes; standing on the
        # floor (within the clearance) it is not checked against it, else its distance is fixed.
        if 0.1 - 0.01 - floor > 0:
            assert plane.clearance([yaw]).distance == pytest.approx(0.1 - 0.01 - floor, abs=1e-9)
        else:
            assert plane.pair_count == 0
        # Capsule to box, by the distance of densely sampled segment points to the box.
        centre = rng.uniform([-0.3, -0.3, 0.0], [0.3, 0.3, 0.2])
        size = rng.uniform(0.02, 0.1, 3)
        box = CollisionChecker(robot, Scene(obstacles=(Obstacle("box", Box(tuple(size)), centre),)))
        pts = a + np.linspace(0, 1, 20001)[:, None] * (b - a)
        outside = np.maximum(np.abs(pts - centre) - size / 2, 0.0)
        expected = float(np.min(np.linalg.norm(outside, axis=1))) - 0.01
        got = box.clearance([yaw])
        if expected > 1e-4:
            assert got.distance == pytest.approx(expected, abs=2e-5)
            assert set(got.bodies) == {"yaw_link", "box"}
        else:
            assert got.in_collision


def test_capsule_to_floor_by_hand():
    # A link pitching about a horizontal axis: its lowest point changes with the angle.
    description = {
        "name": "pitcher",
        "units": {"length": "m", "angle": "deg"},
        "velocity": 60,
        "base": {"xyz": [0, 0, 0.2]},
        "joints": [{"name": "pitch", "axis": [0, 1, 0], "lower": -170, "upper": 170}],
        "tool": {"name": "tip", "xyz": [0.3, 0, 0]},
        "collision": {"radius": 0.02},
    }
    robot = Robot(urdf_from_dh(description), tip="tip")
    checker = CollisionChecker(robot, Scene(floor=0.05))
    for angle in np.linspace(-1.5, 1.5, 13):
        tip_z = 0.2 - 0.3 * math.sin(angle)  # +pitch about y turns +x down
        expected = min(0.2, tip_z) - 0.02 - 0.05
        got = checker.clearance([angle])
        assert got.distance == pytest.approx(expected, abs=1e-6) or (expected <= 0 and got.in_collision)
        assert got.bodies == ("pitch_link", FLOOR)


KNOWN = {
    # name: (free configuration, self-colliding configuration, configuration through the floor at 0)
    "al5c": ([0, deg(90), deg(-90), 0, 0], [0, deg(20), deg(-160), deg(-60), 0], None),
    "dh3": ([0, deg(45), deg(-45)], None, [0, deg(-60), 0]),
    "three_joint": ([0, deg(90), deg(-45), 0], [0, deg(90), deg(150), deg(150)], [0, deg(-10), deg(-90), 0]),
}


@pytest.mark.parametrize("name", sorted(KNOWN))
def test_known_configurations_of_the_bundled_arms(name):
    robot = get_robot(name)
    free, self_hit, floor_hit = KNOWN[name]
    floor = -1.0 if name == "three_joint" else 0.0  # three_joint's shoulder axis is at its base
    checker = CollisionChecker(robot, Scene(floor=floor))
    assert checker.clearance(free).distance > 0.005
    assert not checker.in_collision(free)
    if self_hit is not None:
        c = checker.clearance(self_hit)
        assert c.in_collision and FLOOR not in c.bodies and checker.in_collision(self_hit)
    if floor_hit is not None:
        c = checker.clearance(floor_hit)
        assert c.in_collision and FLOOR in c.bodies
    # al5c: a block where the gripper reaches forward.
    if name == "al5c":
        q = np.array([0, deg(60), deg(-60), deg(-60), 0])
        tip = robot.position(q)
        box = Scene(obstacles=(Obstacle("block", Box((0.03, 0.03, 0.03)), tip),))
        c = CollisionChecker(robot, box).clearance(q)
        assert c.in_collision and c.bodies == ("wrist_rotate_link", "block")
        assert CollisionChecker(robot, box).clearance(q, allow=["block"]).distance > 0


def test_self_collision_pairs_exclude_adjacent_and_always_touching_links():
    arm = arm_collision_model(get_robot("al5c"))
    reasons = {(a, b): why for a, b, why in arm.excluded}
    assert reasons[("base_yaw_link", "shoulder_link")] == "adjacent"
    # The ulna and the gripper meet at the wrist (the wrist pitch link has no length).
    assert reasons[("elbow_link", "wrist_rotate_link")] == "always in contact"
    links = {(arm.link_of[a], arm.link_of[b]) for a, b in arm.self_pairs}
    assert ("base_yaw_link", "wrist_rotate_link") in links


@needs_example_robot_data
@pytest.mark.parametrize(
    ("name", "free", "self_hit", "floor_hit"),
    [
        ("ur5", [0, -deg(90), 0, -deg(90), 0, 0], [0, -deg(90), deg(160), 0, 0, 0], [0, deg(30), 0, 0, 0, 0]),
        (
            "panda",
            [0, 0, 0, -deg(90), 0, deg(90), deg(45)],
            [0, 0, 0, -deg(170), 0, 0, 0],
            [0, deg(100), 0, -deg(10), 0, deg(90), 0],
        ),
    ],
)
def test_known_configurations_of_mesh_arms(name, free, self_hit, floor_hit):
    robot = get_robot(name)
    checker = CollisionChecker(robot, Scene(floor=0.0))
    assert arm_collision_model(robot).source == "urdf"
    assert checker.clearance(free).distance > 0.01 and not checker.in_collision(free)
    c = checker.clearance(self_hit)
    assert c.in_collision and FLOOR not in c.bodies
    c = checker.clearance(floor_hit)
    assert c.in_collision and FLOOR in c.bodies


@needs_example_robot_data
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_mesh_hulls_contain_the_meshes(name):
    """Every contact of the URDF meshes is a contact of their hulls or pieces (UR5 links are not convex)."""
    import pinocchio as pin

    from planner.collision.arm import _package_dirs

    robot = get_robot(name)
    checker = CollisionChecker(robot)
    full = pin.buildModelFromXML(robot.urdf)
    meshes = pin.buildGeomFromUrdfString(full, robot.urdf, pin.GeometryType.COLLISION, None, _package_dirs(robot))
    if robot.locked_joints:
        q_ref = pin.neutral(full)
        for joint, value in robot.locked_joints.items():
            q_ref[full.joints[full.getJointId(joint)].idx_q] = value
        _, meshes = pin.buildReducedModel(full, meshes, [full.getJointId(j) for j in robot.locked_joints], q_ref)
    part_of = checker.arm.part_of
    # The checked pairs of each pair of URDF elements (one, or several between their pieces).
    checked: dict[tuple[int, int], list[int]] = {}
    for k, (a, b) in enumerate(checker.arm.self_pairs):
        checked.setdefault((part_of[a], part_of[b]), []).append(k)
    for a, b in checked:
        meshes.addCollisionPair(pin.CollisionPair(a, b))
    data, gdata = robot.model.createData(), pin.GeometryData(meshes)
    contacts = 0
    for q in robot.random_configurations(np.random.default_rng(1), 150):
        pin.computeCollisions(robot.model, data, meshes, gdata, robot.pinocchio_configuration(q), False)
        shapes = checker.pair_distances(q, checker.pair_mask())
        for pair, result in zip(checked, gdata.collisionResults):
            if result.isCollision():
                contacts += 1
                assert min(shapes[checked[pair]]) <= 0.0, (q, pair)
    assert contacts > 0


@needs_example_robot_data
def test_slab_pieces_contain_the_mesh_and_its_solid():
    """UR5's upper arm and forearm are checked in pieces against some links; the pieces hold every
    vertex of the mesh and every point inside it, and lie within the hull."""
    import coal
    import pinocchio as pin

    from planner.collision.arm import _package_dirs
    from planner.collision.slabs import mesh_arrays

    robot = get_robot("ur5")
    arm = arm_collision_model(robot)
    full = pin.buildModelFromXML(robot.urdf)
    meshes = pin.buildGeomFromUrdfString(full, robot.urdf, pin.GeometryType.COLLISION, None, _package_dirs(robot))
    split = {arm.link_of[e] for k, e in enumerate(arm.part_of) if k != e}
    assert {"upper_arm_link", "forearm_link"} <= split
    # The URDF's elements first, their pieces after them; the scene is checked against elements only.
    assert all(e == k for k, e in enumerate(arm.part_of[: meshes.ngeoms]))
    assert all(e < meshes.ngeoms for e in arm.part_of)
    scene = Scene(obstacles=(Obstacle("block", Box((0.2, 0.2, 0.2)), np.array([0.4, 0.0, 0.3])),))
    checker = CollisionChecker(robot, scene)
    for (a, b), own in zip(checker._pairs, checker.self_pairs):
        if not own:
            assert arm.part_of[min(a, b)] == min(a, b)
    request = coal.DistanceRequest()
    request.gjk_tolerance = 1e-12
    rng = np.random.default_rng(4)
    tested = 0
    for element in sorted(set(arm.part_of)):
        pieces = [
            arm.geometry.geometryObjects[k].geometry for k, e in enumerate(arm.part_of) if e == element and k != e
        ]
        if not pieces:
            continue
        mesh = meshes.geometryObjects[element].geometry
        vertices, triangles = mesh_arrays(mesh)
        hull = arm.geometry.geometryObjects[element].geometry
        assert sum(p.computeVolume() for p in pieces) < hull.computeVolume()

        def gap(shape, point):
            result = coal.DistanceResult()
            ball = coal.Sphere(1e-9)
            coal.distance(shape, coal.Transform3s(), ball, coal.Transform3s(np.eye(3), point), request, result)
            return result.min_distance

        # Points on the surface (vertices and points inside triangles) and inside the solid:
        # midpoints of chords between surface points that stay inside (crossing no triangle).
        weights = rng.dirichlet(np.ones(3), size=len(triangles))
        surface = np.vstack([vertices, np.einsum("ij,ijk->ik", weights, vertices[triangles])])
        for point in surface:
            assert min(gap(p, point) for p in pieces) <= 1e-7, (element, point)
        inside = 0
        for point in surface[rng.choice(len(surface), 400)]:
            other = surface[rng.integers(len(surface))]
            middle = (point + other) / 2.0
            # Inside the closed mesh: a ray from the middle crosses it an odd number of times.
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            a, b, c = (vertices[triangles[:, i]] for i in range(3))
            e1, e2 = b - a, c - a
            h = np.cross(direction, e2)
            det = np.einsum("ij,ij->i", e1, h)
            ok = np.abs(det) > 1e-15
            f = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            s = middle - a
            u = f * np.einsum("ij,ij->i", s, h)
            qv = np.cross(s, e1)
            v = f * (qv @ direction)
            t = f * np.einsum("ij,ij->i", e2, qv)
            crossings = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
            if crossings.sum() % 2 == 1:
                inside += 1
                assert min(gap(p, middle) for p in pieces) <= 1e-7, (element, middle)
            assert gap(hull, middle) <= 1e-7 or crossings.sum() % 2 == 0
        for p in pieces:
            for point in np.array(p.points()).reshape(-1, 3):
                assert gap(hull, point) <= 1e-7
        assert inside > 20
        tested += 1
    assert tested >= 2


def _independent_pair_checks(checker: CollisionChecker, q: np.ndarray, mask: np.ndarray):
    """Per active pair, coal's own distance and collision verdict at `q` (no Pinocchio query, no broadphase)."""
    import coal
    import pinocchio as pin

    geom = checker.geometry
    data, gdata = checker.robot.model.createData(), pin.GeometryData(geom)
    pin.updateGeometryPlacements(checker.robot.model, data, geom, gdata, checker.robot.pinocchio_configuration(q))
    placed = [coal.Transform3s(m.rotation, m.translation) for m in gdata.oMg]
    request = coal.DistanceRequest()
    request.gjk_tolerance, request.gjk_max_iterations = 1e-12, 1000  # as close to exact as GJK gets
    distances, hits = [], []
    for pair, on in zip(geom.collisionPairs, mask):
        if not on:
            continue
        a, b = geom.geometryObjects[pair.first].geometry, geom.geometryObjects[pair.second].geometry
        ta, tb = placed[pair.first], placed[pair.second]
        d, c = coal.DistanceResult(), coal.CollisionResult()
        coal.distance(a, ta, b, tb, request, d)
        coal.collide(a, ta, b, tb, coal.CollisionRequest(), c)
        distances.append(d.min_distance)
        hits.append(c.isCollision())
    return np.array(distances), np.array(hits)


@pytest.mark.parametrize("name", MIXED_ARMS)
def test_checks_equal_an_independent_per_pair_computation(name):
    """in_collision (AABB tree) and clearance (Pinocchio's closest pair) against coal pair by pair."""
    robot = get_robot(name)
    qs = robot.random_configurations(np.random.default_rng(3), 40)
    r = max(float(np.linalg.norm(robot.position(q))) for q in qs)
    scene = Scene(
        floor=-0.05 * r,
        obstacles=(
            Obstacle("block", Box((0.3 * r, 0.3 * r, 0.4 * r)), np.array([0.6, 0.2, 0.2]) * r),
            Obstacle("post", Cylinder(0.08 * r, r), np.array([-0.4, 0.5, 0.5]) * r, rpy_to_matrix([0.3, 0.0, 0.0])),
            Obstacle("ball", Sphere(0.15 * r), np.array([0.0, -0.6, 0.6]) * r),
        ),
    )
    checker = CollisionChecker(robot, scene)
    verdicts = []
    allows = ((), ("block",), ("floor", "ball"))
    for q in qs:
        checks = [_independent_pair_checks(checker, q, checker.pair_mask(allow)) for allow in allows]
        # Each kind of query in turn over all allow sets, in opposite orders: a stale mask would show.
        for allow, (_, hits) in zip(allows, checks):
            assert checker.in_collision(q, allow=allow) == hits.any(), (q, allow)
            verdicts.append(hits.any())
        for allow, (distances, _) in reversed(list(zip(allows, checks))):
            c = checker.clearance(q, allow=allow)
            if distances.min() > 0:
                # The checker's GJK stops at coal's default tolerance (1e-6), from a warm start
                # that depends on earlier calls: equal to a few micrometres.
                assert c.distance == pytest.approx(distances.min(), abs=1e-5), (q, allow)
            else:
                assert c.distance <= 0, (q, allow)
    assert any(verdicts) and not all(verdicts)


# ---------------------------------------------------------------------------- continuous checks


def test_the_continuous_check_catches_a_thin_plate_that_sampling_misses():
    robot = _one_link(radius=0.0005, length=0.3, speed=600.0)  # 10 rad/s: the tip moves 3 m/s
    limits = JointLimits.from_robot(robot)
    traj = plan_trajectory([[-1.5], [1.5]], limits)
    t = np.arange(0.0, traj.duration, 0.01)
    angles = traj.sample(t).q[:, 0]
    # A 5 mm plate across the tip's circle, midway between the two 10 ms samples that are farthest apart.
    k = int(np.argmax(np.diff(angles)))
    mid = (angles[k] + angles[k + 1]) / 2
    plate = Obstacle(
        "plate",
        Box((0.1, 0.005, 0.05)),
        np.array([0.25 * math.cos(mid), 0.25 * math.sin(mid), 0.1]),
        np.array([[math.cos(mid), -math.sin(mid), 0], [math.sin(mid), math.cos(mid), 0], [0, 0, 1]]),
    )
    checker = CollisionChecker(robot, Scene(obstacles=(plate,)))
    assert not any(checker.in_collision([a]) for a in angles)  # every 10 ms sample is clear
    result = check_trajectory(checker, traj)
    assert not result.clear and result.hit.bodies == ("yaw_link", "plate") and result.hit.in_collision
    assert t[k] <= result.first_hit <= t[k + 1]
    assert "collides at" in result.describe()


def test_a_full_check_goes_on_past_an_overlap_deeper_than_the_near_body_ball():
    """Without stop_at_first a check goes on past the first hit to find the worst. A 4 mm pin
    inside al5c's base link overlaps it by 44 mm, more than the pin's ball radius: the near-body
    bound's ball R + d was negative, the step NaN, and the check never ended (NaN is never due).
    Floating-point errors raise here, so that fails at once instead of hanging."""
    import pinocchio as pin

    robot = get_robot("al5c")
    lo, hi = robot.lower, robot.upper
    qa, qb = lo + 0.3 * (hi - lo), lo + 0.7 * (hi - lo)
    traj = plan_trajectory([qa, qb], JointLimits.from_robot(robot))
    geom = arm_collision_model(robot).geometry
    gdata = pin.GeometryData(geom)
    pin.updateGeometryPlacements(robot.model, robot.model.createData(), geom, gdata, robot.pinocchio_configuration(qa))
    base = next(k for k, o in enumerate(geom.geometryObjects) if o.parentJoint > 0)
    pin_ = Obstacle("pin", Sphere(0.004), np.array(gdata.oMg[base].translation))
    checker = CollisionChecker(robot, Scene(obstacles=(pin_,)))
    with np.errstate(invalid="raise"):
        timed = check_trajectory(checker, traj, stop_at_first=False)
        segment = check_segment(checker, qa, qb, stop_at_first=False)
    for result in (timed, segment):
        assert not result.clear and result.first_hit == 0.0 and "pin" in result.hit.bodies
        assert result.closest.distance <= result.hit.distance < -0.004


@pytest.mark.parametrize("name", ["al5c", pytest.param("ur5", marks=needs_example_robot_data)])
def test_the_step_rule_is_the_longer_of_the_two_bounds_per_pair(name):
    """_segment_steps against the module docstring's two bounds evaluated pair by pair in plain Python."""
    import planner.collision.continuous as cc

    robot = get_robot(name)
    block = Obstacle("block", Box((0.06, 0.06, 0.25)), np.array([0.23, 0.0, 0.125]))
    checker = CollisionChecker(robot, Scene(floor=-0.01, clearance=0.005, obstacles=(block,)))
    weights, near = cc.pair_weights(checker), cc.near_bounds(checker)
    growth = math.exp(cc.NEAR_TURN)
    rng = np.random.default_rng(3)
    rule = cc._segment_steps(checker)
    n = checker.pair_count
    for _ in range(20):
        # Every joint moving a little (with a joint at rest a pair may never approach: both
        # bounds' steps are then "never", as 1e-12 and 1e-300 floors of their speeds tell).
        speed = rng.uniform(0.0, 2.0, robot.dof) * (rng.random(robot.dof) < 0.8) + 0.01
        due = np.flatnonzero(rng.random(n) < 0.5)
        d = rng.uniform(-0.002, 0.3, len(due))
        room = np.maximum(d - 0.005 + 1e-4, 5e-5)
        got = rule(speed, due, d, room)
        for p, dp, r, step in zip(due, d, room, got):
            # Constant speeds (a straight segment): each bound's step is the room over its speed.
            want = r / max(weights[p] @ speed, 1e-12)
            if np.isfinite(near.radius[p]):
                turn = near.joints[p] @ speed
                ball = near.radius[p] + max(dp, 0.0)  # overlapping (past a hit): as touching
                v = growth * (ball * turn + near.offsets[p] @ speed)
                want = max(want, min(r / max(v, 1e-300), cc.NEAR_TURN / max(turn, 1e-300)))
            assert step == pytest.approx(want, rel=1e-9)


@pytest.mark.parametrize("name", ["al5c", pytest.param("ur5", marks=needs_example_robot_data)])
def test_a_timed_step_keeps_each_pair_within_its_room_by_its_joints_travel(name):
    """_trajectory_steps: over each step, a pair's bound on the joints' travel (sampled densely) fits its room.

    Per pair, its first bound ``sum_j r_j Q_j`` (``Q_j`` joint j's travel over the step, summed
    over 20,000 samples of the trajectory) or the near-body bound with its turn cap is at most
    the room, at checks anywhere in the trajectory; every step is positive, and the same
    whether the pairs are computed together or one by one.
    """
    import planner.collision.continuous as cc

    robot = get_robot(name)
    block = Obstacle("block", Box((0.06, 0.06, 0.25)), np.array([0.23, 0.0, 0.125]))
    checker = CollisionChecker(robot, Scene(floor=-0.01, clearance=0.005, obstacles=(block,)))
    weights, near = cc.pair_weights(checker), cc.near_bounds(checker)
    growth = math.exp(cc.NEAR_TURN)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(11)
    n = checker.pair_count
    for _ in range(4):
        traj = plan_trajectory(robot.random_configurations(rng, 3), limits)
        last = np.asarray(traj.waypoints[-1], dtype=float)
        floor = 0.005 - cc.DEFAULT_TOLERANCE
        rule = cc._trajectory_steps(checker, traj, last, np.asarray(limits.velocity) * (1 + 1e-6), floor)
        fine = np.linspace(0.0, traj.duration, 20001)
        q = traj.sample(fine).q
        travel = np.vstack([np.zeros(robot.dof), np.cumsum(np.abs(np.diff(q, axis=0)), axis=0)])
        for x in rng.uniform(0.0, traj.duration, 6):
            due = np.flatnonzero(rng.random(n) < 0.6)
            d = rng.uniform(-0.002, 0.3, len(due))
            room = np.maximum(d - 0.005 + cc.DEFAULT_TOLERANCE, cc.DEFAULT_TOLERANCE / 2)
            steps = rule(float(x), due, d, room)
            assert np.all(steps > 0)
            # Pair by pair (the rule's path for few pairs) the same steps.
            alone = [rule(float(x), due[k : k + 1], d[k : k + 1], room[k : k + 1])[0] for k in range(len(due))]
            np.testing.assert_allclose(alone, steps, rtol=1e-9, atol=0.0)  # (rows differ in rounding)
            for p, dp, r, h in zip(due, d, room, steps):
                # The travel from x to x + h: the samples strictly between, and the ends exactly.
                a, b = np.searchsorted(fine, [x, min(x + h, traj.duration)], side="right")
                ends = traj.sample(np.array([x, min(x + h, traj.duration)])).q
                if a < b:
                    inner = travel[b - 1] - travel[a]
                    used = np.abs(q[a] - ends[0]) + inner + np.abs(ends[1] - q[b - 1])
                else:
                    used = np.abs(ends[1] - ends[0])
                first = weights[p] @ used
                if first <= r * (1 + 1e-9) + 1e-12:
                    continue
                assert np.isfinite(near.radius[p]), (p, first, r)
                turn = near.joints[p] @ used
                lever = growth * ((near.radius[p] + max(dp, 0.0)) * turn + near.offsets[p] @ used)
                assert turn <= cc.NEAR_TURN * (1 + 1e-9) and lever <= r * (1 + 1e-9) + 1e-12, (p, r, turn, lever)


@pytest.mark.parametrize("name", ["al5c", pytest.param("panda", marks=needs_example_robot_data)])
def test_the_compiled_bookkeeping_takes_the_python_steps(name):
    """_NativeSteps: per due pair the Python rule's step (until, early), then the least until, pairs due, q there."""
    import planner.collision.continuous as cc

    if cc._native_library() is None:
        pytest.skip("no C compiler (PLANNER_JIT=0): the Python steps only")
    robot = get_robot(name)
    block = Obstacle("block", Box((0.06, 0.06, 0.25)), np.array([0.23, 0.0, 0.125]))
    checker = CollisionChecker(robot, Scene(floor=-0.01, clearance=0.005, obstacles=(block,)))
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(5)
    n = checker.pair_count + len(checker.bounding_pairs())  # the bounding pairs (of panda's hand) too
    for _ in range(3):
        traj = plan_trajectory(robot.random_configurations(rng, 3), limits)
        last = np.asarray(traj.waypoints[-1], dtype=float)
        floor = 0.005 - cc.DEFAULT_TOLERANCE
        rule = cc._trajectory_steps(checker, traj, last, np.asarray(limits.velocity) * (1 + 1e-6), floor)
        assert rule.native.size == n
        for x in [0.0, *rng.uniform(0.0, traj.duration, 8), traj.duration]:
            due = np.flatnonzero(rng.random(n) < 0.5)
            if not due.size:
                continue
            d = rng.uniform(-0.002, 0.3, len(due))
            room = np.maximum(d - 0.005 + cc.DEFAULT_TOLERANCE, cc.DEFAULT_TOLERANCE / 2)
            coarse = float(rng.choice([0.0, 0.01]))
            want = np.maximum(rule(float(x), due, d, room), coarse)
            until, early = rng.uniform(x, x + 1.0, n), rng.uniform(x, x + 1.0, n)
            bound = float(rng.uniform(x, traj.duration + 1.0))
            got_x, got_due, got_q = rule.native(
                float(x), due, d, 0.005, cc.DEFAULT_TOLERANCE, coarse, until, early, bound
            )
            # The configuration there: check_trajectory's sample (the pieces' polynomial, the last waypoint at the end).
            i = max(int(np.searchsorted(traj.knots, got_x, side="right")) - 1, 0)
            dt = got_x - traj.knots[i]
            polynomial = traj.p[i] + dt * (traj.v[i] + dt * (traj.a[i] / 2.0 + dt * (traj.j[i] / 6.0)))
            np.testing.assert_array_equal(got_q, last if got_x >= traj.duration else polynomial)
            # (W to rounding: the Python rows carry offsets; steps past the end are only "never".)
            big = 1e6 * traj.duration
            np.testing.assert_allclose(np.minimum(until[due] - x, big), np.minimum(want, big), rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(
                np.minimum(early[due] - x, big), np.minimum(want / 2, big), rtol=1e-9, atol=1e-12
            )
            after = min(float(until.min()), bound)
            assert got_x == min(after if after > x else np.nextafter(x, np.inf), traj.duration)
            np.testing.assert_array_equal(got_due, np.flatnonzero(early <= got_x))


@needs_example_robot_data
def test_bounding_pairs_due_with_pairs_take_the_same_steps_compiled_and_in_python():
    """check_trajectory on panda near a block (its hand's bounding pairs due at checks with pairs, handed to
    the compiled loop in its buffers): the same checks, verdict, first hit and closest pair as the Python steps."""
    import planner.collision.continuous as cc

    loader = cc._native_library
    compiled = loader()
    if compiled is None:
        pytest.skip("no C compiler (PLANNER_JIT=0): the Python steps only")
    robot = get_robot("panda")
    block = Obstacle("block", Box((0.1, 0.1, 0.5)), np.array([0.45, 0.0, 0.25]))
    scene = Scene(floor=-0.01, clearance=0.005, obstacles=(block,))
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(3)
    mixed = 0
    for _ in range(4):
        traj = plan_trajectory(robot.random_configurations(rng, 3), limits)
        results, counts = [], []
        for lib in (compiled, None):
            cc._native_library = lambda lib=lib: lib
            try:
                checker = CollisionChecker(robot, scene)
                bounds, seen = checker.bounding_pairs(), [0]
                inner = bounds.placed_distances

                def counted(pairs, inner=inner, seen=seen):
                    seen[0] += len(pairs)
                    return inner(pairs)

                bounds.placed_distances = counted
                results.append(check_trajectory(checker, traj))
                counts.append(seen[0])
            finally:
                cc._native_library = loader
        a, b = results
        assert (a.clear, a.checks, a.first_hit is None) == (b.clear, b.checks, b.first_hit is None)
        assert abs((a.first_hit or 0.0) - (b.first_hit or 0.0)) <= 1e-7 * max(traj.duration, 1.0)
        assert a.closest.bodies == b.closest.bodies and a.closest.distance == pytest.approx(
            b.closest.distance, abs=1e-9
        )
        assert counts[0] == counts[1]
        mixed += counts[0] > 0
    assert mixed  # bounding pairs were computed


@pytest.mark.parametrize("name", ["al5c", "dh3", pytest.param("panda", marks=needs_example_robot_data)])
def test_the_compiled_grid_is_numpys(name):
    """_trajectory_grid's compiled loop: the NumPy grid's times, travels and speeds, to the last bit."""
    import planner.collision.continuous as cc

    if cc._native_library() is None:
        pytest.skip("no C compiler (PLANNER_JIT=0): the NumPy grid only")
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(9)
    for count in (2, 2, 3, 5):
        waypoints = robot.random_configurations(rng, count)
        if count == 2:
            waypoints[1] = waypoints[0] + 0.01 * (waypoints[1] - waypoints[0])  # a short move too
        traj = plan_trajectory(waypoints, limits)
        last, vmax = np.asarray(traj.waypoints[-1], dtype=float), np.asarray(limits.velocity) * (1 + 1e-6)
        for got, want in zip(cc._trajectory_grid(traj, last, vmax), cc._numpy_grid(traj, last, vmax)):
            assert got.shape == want.shape
            np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("name", ["al5c", pytest.param("panda", marks=needs_example_robot_data)])
def test_timed_checks_give_the_same_results_without_the_compiled_bookkeeping(name, monkeypatch):
    """check_trajectory with _NativeSteps and with the Python steps: the same verdicts, hits and checks."""
    import planner.collision.continuous as cc

    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(8)
    blocks = [
        Obstacle(f"block{k}", Box((0.04, 0.04, 0.1)), np.array([x, 0.25, 0.05])) for k, x in enumerate([0.0, 0.25])
    ]
    checker = CollisionChecker(robot, Scene(floor=-0.01, clearance=0.005, obstacles=tuple(blocks)))
    cases = []
    while len(cases) < 12:
        k = len(cases) // 2
        waypoints = robot.random_configurations(rng, 3)
        if any(checker.in_collision(q) for q in waypoints):
            continue
        traj = plan_trajectory(waypoints, limits)
        allow = [(0.3 * traj.duration, ["block0"]), (0.6 * traj.duration, [])] if k % 2 else []
        cases += [(traj, allow, stop) for stop in (False, True)]

    def run():
        return [check_trajectory(checker, traj, allow=allow, stop_at_first=stop) for traj, allow, stop in cases]

    compiled = run()
    monkeypatch.setattr(cc, "_native_library", lambda: None)
    plain = run()
    assert any(not r.clear for r in plain) and any(r.clear for r in plain)
    for a, b in zip(compiled, plain):
        assert (a.clear, a.checks, a.closest.bodies) == (b.clear, b.checks, b.closest.bodies)
        assert a.first_hit == pytest.approx(b.first_hit, abs=1e-9)
        assert a.where == pytest.approx(b.where, abs=1e-9)
        assert a.closest.distance == pytest.approx(b.closest.distance, abs=1e-8)


@needs_example_robot_data
def test_a_bounding_pair_is_never_farther_than_its_members():
    """BoundingPairs: panda's hand, fingers and last link as one hull; its distance at most each member's."""
    from planner.collision.checker import BoundingPairs

    robot = get_robot("panda")
    checker = CollisionChecker(robot, parse_scene(_TABLE_AND_BOX))
    bounds = checker.bounding_pairs()
    assert isinstance(bounds, BoundingPairs) and len(bounds) >= 2
    names = {checker.names[o] for o in bounds.objects}
    assert {"table", "box"} <= names
    rng = np.random.default_rng(4)
    for q in robot.random_configurations(rng, 100):
        checker.place(q)
        hull = bounds.placed_distances(np.arange(len(bounds)))
        for k, pairs in enumerate(bounds.members):
            assert len(pairs) >= 3
            assert checker.placed_distances(pairs).min() >= hull[k] - 2e-6  # GJK's tolerance
    # Capsules (al5c) are not bounded together: the hull of their boxes is far larger than they are.
    assert len(CollisionChecker(get_robot("al5c"), Scene(floor=0.0)).bounding_pairs()) == 0


@needs_example_robot_data
def test_a_bounding_pairs_step_keeps_its_hull_within_its_room():
    """Over each step the rule gives a bounding pair, its hull (densely sampled) keeps its distance less the room."""
    import planner.collision.continuous as cc

    robot = get_robot("panda")
    checker = CollisionChecker(robot, parse_scene(_TABLE_AND_BOX))
    bounds = checker.bounding_pairs()
    n = checker.pair_count
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(12)
    for _ in range(3):
        traj = plan_trajectory(robot.random_configurations(rng, 3), limits)
        last = np.asarray(traj.waypoints[-1], dtype=float)
        rule = cc._trajectory_steps(checker, traj, last, np.asarray(limits.velocity) * (1 + 1e-6), 0.0)
        for x in rng.uniform(0.0, traj.duration, 4):
            checker.place(traj.sample(np.array([x])).q[0])
            local = np.arange(len(bounds))
            d = bounds.placed_distances(local)
            room = np.maximum(d + cc.DEFAULT_TOLERANCE, cc.DEFAULT_TOLERANCE / 2)
            steps = rule(float(x), local + n, d, room)
            for k in local:
                times = np.linspace(x, min(x + steps[k], traj.duration), 200)
                for q in traj.sample(times).q:
                    checker.place(q)
                    assert bounds.placed_distances(np.array([k]))[0] >= d[k] - room[k] - 2e-6


def test_a_clear_certificate_holds_between_checks():
    robot = get_robot("dh3")
    scene = Scene(floor=-0.01, clearance=0.004, obstacles=(Obstacle("ball", Sphere(0.02), np.array([0.1, 0.1, 0.12])),))
    checker = CollisionChecker(robot, scene)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(5)
    for _ in range(10):
        qa, qb = robot.random_configurations(rng, 2)
        if not (checker.clearance(qa).clear and checker.clearance(qb).clear):
            continue
        traj = plan_trajectory([qa, qb], limits)
        result = check_trajectory(checker, traj)
        dense = [checker.clearance(q).distance for q in traj.sample(traj.times(2000.0)).q]
        if result.clear:
            assert min(dense) >= scene.clearance - 1e-4
        else:
            assert result.first_hit is not None


# ---------------------------------------------------------------------------- paths around obstacles


def _al5c_block_scene():
    block = Obstacle("block", Box((0.06, 0.06, 0.25)), np.array([0.23, 0.0, 0.125]))
    return Scene(floor=0.0, clearance=0.005, obstacles=(block,))


def test_path_around_a_block_is_clear_and_repeatable():
    robot = get_robot("al5c")
    checker = CollisionChecker(robot, _al5c_block_scene())
    qa, qb = np.array([-0.6, 1.2, -1.4, -0.8, 0.0]), np.array([0.6, 1.2, -1.4, -0.8, 0.0])
    assert not check_segment(checker, qa, qb).clear
    first = find_clear_path(checker, qa, qb, options=PathOptions(seed=4))
    again = find_clear_path(checker, qa, qb, options=PathOptions(seed=4))
    assert first.found and np.array_equal(first.path, again.path)
    np.testing.assert_array_equal(first.path[0], qa)
    np.testing.assert_array_equal(first.path[-1], qb)
    for a, b in zip(first.path, first.path[1:]):
        assert check_segment(checker, a, b).clear


def test_a_blocked_tree_edge_cuts_its_node_and_what_grew_from_it():
    # The trees test their nodes as they grow and the edges only on a path found (lazily), and
    # there only the edges the path's greedy prune keeps: a tree edge a longer edge passes over
    # is never tested. A blocked one cuts its node off, with its subtree; a tested one is kept.
    from planner.collision.rrt import _settle, _Tree

    a, b = _Tree(np.zeros(2)), _Tree(np.array([4.0, 0.0]))
    one = a.add(np.array([1.0, 1.0]), 0)
    two = a.add(np.array([2.0, 0.0]), one)
    a.add(np.array([1.0, 2.0]), one)  # a branch off the path
    near = b.add(np.array([3.0, 1.0]), 0)
    tested = []

    def clear(p, q):
        tested.append((tuple(p), tuple(q)))
        return True

    nodes, pruned = _settle(a, two, b, near, True, clear)
    assert [tuple(q) for q in nodes] == [(0, 0), (1, 1), (2, 0), (3, 1), (4, 0)]
    assert [tuple(q) for q in pruned] == [(0, 0), (4, 0)] and tested == [((0, 0), (4, 0))]
    assert a.tested == [True, False, False, False]  # passed over, not tested

    def short_and_not_b(p, q):  # edges longer than 1.5 are blocked, and b's own edge
        tested.append((tuple(p), tuple(q)))
        return np.linalg.norm(q - p) < 1.5 and not {tuple(p), tuple(q)} == {(3.0, 1.0), (4.0, 0.0)}

    tested.clear()
    assert _settle(a, two, b, near, True, short_and_not_b) is None
    assert a.tested == [True, True, True, False] and b.alive == [True, False]
    assert b.nearest(np.array([3.0, 1.0])) == 0
    tested.clear()
    # From the goal's side (b grew the node the other tree reached): the same path, start first.
    c = _Tree(np.array([4.0, 0.0]))
    c.add(np.array([3.0, 1.0]), 0)
    assert _settle(c, 1, a, two, False, short_and_not_b) is None
    assert tested[-1] == ((3.0, 1.0), (4.0, 0.0)) and c.alive == [True, False]
    a.cut(one)
    assert a.alive == [True, False, False, False]
    assert a.nearest(np.array([1.0, 2.0])) == 0


def test_edges_tested_where_the_trees_met_are_not_tested_again_at_their_next_meeting():
    # A meeting whose path is blocked leaves its edges' verdicts (`seen`); the next meeting
    # through the same nodes reuses them: the same verdicts, each edge tested once.
    from planner.collision.rrt import _settle, _Tree

    a, b = _Tree(np.zeros(2)), _Tree(np.array([4.0, 0.0]))
    one = a.add(np.array([1.0, 1.0]), 0)
    up = b.add(np.array([3.0, 1.0]), 0)
    down = b.add(np.array([3.0, -1.0]), 0)
    tested = []

    def short(p, q):  # edges of 1.5 and longer are blocked
        tested.append((tuple(p), tuple(q)))
        return bool(np.linalg.norm(q - p) < 1.5)

    seen: dict = {}
    assert _settle(a, one, b, up, True, short, seen) is None  # (1, 1) to (3, 1) is blocked
    first = list(tested)
    assert ((0.0, 0.0), (4.0, 0.0)) in first and ((1.0, 1.0), (4.0, 0.0)) in first
    tested.clear()
    assert _settle(a, one, b, down, True, short, seen) is None
    assert not set(tested) & set(first)  # (0, 0) and (1, 1) to the goal: verdicts kept
    tested.clear()
    assert _settle(a, one, b, down, True, short) is None  # without `seen`: tested again
    assert ((0.0, 0.0), (4.0, 0.0)) in tested


def test_an_edge_is_tested_first_where_the_last_one_was_blocked():
    # The same points and verdicts as the bisection sweep; only the order: the point nearest the
    # configuration that blocked the last edge comes first.
    from planner.collision.rrt import _edge_tests

    tested = []

    def wall(q):  # too close where 0.45 <= x <= 0.55
        tested.append(tuple(q))
        return 0.45 <= q[0] <= 0.55

    class Checker:
        def closer_than(self, distance, allow):
            return wall

    _, quick, between, _ = _edge_tests(Checker(), 0.0, (), 0.1)
    assert not between(np.array([0.0, 0.0]), np.array([1.0, 0.0]))
    assert tested == [(0.5, 0.0)]  # bisection: the middle first (the ends are nodes)
    tested.clear()
    assert not quick(np.array([0.0, 1.0]), np.array([1.0, 1.0]))
    assert tested == [(0.5, 1.0)]  # nearest (0.5, 0): before the end, which bisection tests first
    tested.clear()
    assert quick(np.array([0.0, 2.0]), np.array([0.3, 2.0]))  # clear: its 3 points and its start
    xs = [round(x, 9) for x, _ in tested]
    assert xs[0] == 0.3 and sorted(xs) == [0.0, 0.1, 0.2, 0.3]  # the point nearest the blocker first, once
    tested.clear()
    assert quick(np.array([0.0, 3.0]), np.array([0.4, 3.0]))
    xs = [round(x, 9) for x, _ in tested]
    assert xs[0] == 0.4 and sorted(xs) == [0.0, 0.1, 0.2, 0.3, 0.4]
    tested.clear()  # blocked again at x = 0.5; nearest it on the next edge: its start, tested first and once
    assert not between(np.array([0.3, 0.0]), np.array([0.7, 0.0]))
    tested.clear()
    assert quick(np.array([0.6, 0.0]), np.array([0.9, 0.0]))
    xs = [round(x, 9) for x, _ in tested]
    assert xs[0] == 0.6 and xs[-1] != 0.6 and len(set(xs)) == len(xs) and max(xs) == 0.9


def test_the_path_search_can_skip_its_straight_test(monkeypatch):
    # plan_motion's route has just found the straight segment blocked (same margin): the
    # search grows its trees at once; on a clear segment it then finds a certified path too.
    import planner.collision.rrt as rrt

    robot = get_robot("al5c")
    checker = CollisionChecker(robot, _al5c_block_scene())
    calls = []
    real = rrt.segment_is_clear
    monkeypatch.setattr(rrt, "segment_is_clear", lambda *a, **k: calls.append(a) or real(*a, **k))
    qa, qb = np.array([-0.6, 1.2, -1.4, -0.8, 0.0]), np.array([0.6, 1.2, -1.4, -0.8, 0.0])
    blocked = find_clear_path(checker, qa, qb, options=PathOptions(seed=4), try_straight=False)
    assert not calls
    assert blocked.found and np.array_equal(
        blocked.path, find_clear_path(checker, qa, qb, options=PathOptions(seed=4)).path
    )
    calls.clear()
    qc = np.array([-0.7, 1.2, -1.4, -0.8, 0.0])
    straight = find_clear_path(checker, qa, qc, options=PathOptions(seed=4))
    assert len(calls) == 1 and len(straight.path) == 2
    grown = find_clear_path(checker, qa, qc, options=PathOptions(seed=4), try_straight=False)
    assert grown.found
    for a, b in zip(grown.path, grown.path[1:]):
        assert check_segment(checker, a, b).clear


def test_unreachable_without_collision_is_an_outcome_with_a_reason():
    robot = get_robot("al5c")
    qa, qb = np.array([-0.6, 1.2, -1.4, -0.8, 0.0]), np.array([0.6, 1.2, -1.4, -0.8, 0.0])
    cage = Obstacle("cage", Box((0.4, 0.1, 0.4)), robot.position(qb) + [0, 0.0, 0.0])
    checker = CollisionChecker(robot, Scene(obstacles=(cage,)))
    result = find_clear_path(checker, qa, qb, options=PathOptions(seed=0, time_budget=0.5))
    assert result.status is PathStatus.GOAL_IN_COLLISION and not result.found
    assert "goal does not keep the clearance" in result.reason and "cage" in result.reason
    assert result.path.shape == (0, 5)


# ---------------------------------------------------------------------------- IK answers


def test_ik_answers_are_checked_and_colliding_branches_skipped():
    from planner import IKStatus, Target, solve_ik

    robot = get_robot("dh3")
    target = Target(position=[0.12, 0.0, 0.06])
    free = solve_ik(robot, target, method="analytic")
    assert free.success and free.solutions[0].label == "front/elbow-up"
    assert all(s.clearance is None for s in free.solutions)
    # A ball at the elbow-up answer's elbow: that branch collides, elbow-down does not.
    elbow = robot.joint_positions(free.q)[3]
    checker = CollisionChecker(robot, Scene(obstacles=(Obstacle("ball", Sphere(0.01), elbow),)))
    assert checker.clearance(free.q).in_collision
    for method in ("analytic", "auto"):
        checked = solve_ik(robot, target, method=method, checker=checker)
        assert checked.success and checker.clearance(checked.q).clear
        assert "elbow-down" in checked.reason
        assert all(s.clearance is not None for s in checked.solutions)
        assert np.linalg.norm(robot.position(checked.q) - target.position) < 1e-9
    # Allowing the contact gives back the nearest answer.
    allowed = solve_ik(robot, target, method="auto", checker=checker, allow=["ball"])
    np.testing.assert_allclose(allowed.q, free.q)
    # Nothing clear anywhere (al5c has one branch within its limits; the NLP restarts too):
    # an outcome with the status and the bodies.
    al5c = get_robot("al5c")
    grasp = Target(position=[0.2, 0.0, 0.05], pitch=-math.pi / 2)
    cage = CollisionChecker(al5c, Scene(obstacles=(Obstacle("cage", Sphere(0.08), grasp.position),)))
    for method in ("auto", "nlp"):
        caged = solve_ik(al5c, grasp, method=method, checker=cage)
        assert not caged.success and caged.status is IKStatus.IN_COLLISION and "cage" in caged.reason


def test_batch_clearances_match_single_ones():
    robot = get_robot("al5c")
    checker = CollisionChecker(robot, _al5c_block_scene())
    qs = robot.random_configurations(np.random.default_rng(8), 20)
    batch = checker.clearances(qs, allow=["block"])
    assert batch == [checker.clearance(q, allow=["block"]) for q in qs]


# ---------------------------------------------------------------------------- per-pair speed bounds


@pytest.mark.parametrize("name", ["al5c", "dh3", pytest.param("ur5", marks=needs_example_robot_data)])
def test_no_pair_approaches_faster_than_its_bound(name):
    """|d_p(q + dq) - d_p(q)| <= pair_weights[p] . |dq| for small random joint steps (coal distances, to 1e-6 m)."""
    from planner.collision.continuous import pair_weights

    robot = get_robot(name)
    scene = Scene(
        floor=-0.05,
        obstacles=(Obstacle("box", Box((0.1, 0.1, 0.1)), np.array([0.25, 0.05, 0.1])),),
    )
    checker = CollisionChecker(robot, scene)
    weights = pair_weights(checker)
    assert weights.shape == (checker.pair_count, robot.dof) and np.all(weights >= 0)
    # Every pair of links moves with some joint (a body turning above the floor may not approach it).
    assert not np.any(np.all(weights[checker.self_pairs] == 0, axis=1))
    rng = np.random.default_rng(3)
    mask = checker.pair_mask()
    for q in robot.random_configurations(rng, 40):
        dq = rng.normal(size=robot.dof) * 0.01
        q2 = np.clip(q + dq, robot.lower, robot.upper)
        d0, d1 = checker.pair_distances(q, mask), checker.pair_distances(q2, mask)
        both = (d0 > 0) & (d1 > 0)  # coal's distance of overlapping bodies is not a distance
        bound = weights @ np.abs(q2 - q)
        assert np.all(np.abs(d1 - d0)[both] <= bound[both] + 1e-6)


def test_a_pair_inside_the_wrist_is_bounded_by_the_wrist_joints_only():
    from planner.collision.continuous import pair_weights

    robot = get_robot("al5c")
    checker = CollisionChecker(robot)
    weights = pair_weights(checker)
    model, geom = robot.model, checker.geometry
    for k, pair in enumerate(geom.collisionPairs):
        joints = [geom.geometryObjects[i].parentJoint for i in (pair.first, pair.second)]
        common = set(model.supports[joints[0]]) & set(model.supports[joints[1]]) - {0}
        # A joint both bodies hang from moves them together: it cannot bring them closer.
        assert all(weights[k, j - 1] == 0 for j in common)


def test_ends_closer_than_the_margin_still_get_a_path_keeping_what_they_have():
    from planner.collision.rrt import path_margin

    assert path_margin(0.005, 0.006, 0.002) == pytest.approx(0.0005)
    assert path_margin(0.005, 0.5, 0.002) == 0.002
    assert path_margin(0.0, 0.0, 0.002) == 0.0
    robot = get_robot("al5c")
    checker = CollisionChecker(robot, _al5c_block_scene())
    qa, qb = np.array([-0.6, 1.2, -1.4, -0.8, 0.0]), np.array([0.6, 1.2, -1.4, -0.8, 0.0])
    ends = min(checker.clearance(qa).distance, checker.clearance(qb).distance)
    options = PathOptions(seed=4, margin=1.0)  # far more than the ends have
    result = find_clear_path(checker, qa, qb, options=options)
    assert result.found
    keep = checker.scene.clearance + path_margin(checker.scene.clearance, ends, options.margin)
    for a, b in zip(result.path, result.path[1:]):
        assert check_segment(checker, a, b, clearance=keep).clear


def test_a_segment_the_cheap_check_finds_blocked_is_blocked():
    from planner.collision.rrt import segment_looks_clear

    robot = get_robot("al5c")
    checker = CollisionChecker(robot, _al5c_block_scene())
    rng = np.random.default_rng(11)
    seen = set()
    for qa, qb in zip(robot.random_configurations(rng, 30), robot.random_configurations(rng, 30)):
        looks, certified = segment_looks_clear(checker, qa, qb), check_segment(checker, qa, qb).clear
        assert looks or not certified  # blocked at a sample point: no certificate either
        seen.add((looks, certified))
    assert (False, False) in seen and (True, True) in seen


# ---------------------------------------------------------------------------- bounds of the continuous check


_TABLE_AND_BOX = {
    "obstacles": [
        {"name": "table", "box": [1.6, 1.6, 0.05], "position": [0.0, 0.0, -0.03]},
        {"name": "box", "box": [0.25, 0.25, 0.5], "position": [0.45, 0.0, 0.25]},
    ]
}


def _placements(checker, q):
    import pinocchio as pin

    robot = checker.robot
    gdata = pin.GeometryData(checker.geometry)
    pin.updateGeometryPlacements(
        robot.model, robot.model.createData(), checker.geometry, gdata, robot.pinocchio_configuration(q)
    )
    return [pin.SE3(m) for m in gdata.oMg]


@pytest.mark.parametrize("name", MIXED_ARMS)
def test_pair_bounds_never_underestimate_the_relative_motion_of_two_bodies(name):
    """Along random joint segments, densely sampled by FK: every vertex of one body's hull, seen
    from the other body, moves no farther than _reach_weights (the lower body's side) allows (how far a point moves is a
    convex function of it: no point of the body moves farther than its hull's vertices)."""
    from planner.collision.arm import hull_points
    from planner.collision.continuous import _reach_weights

    robot = get_robot(name)
    checker = CollisionChecker(robot, parse_scene(_TABLE_AND_BOX))
    weights = _reach_weights(checker)
    geom = checker.geometry
    model = robot.model
    # Pairs of a body and one it hangs below (or a scene body): the lower one's corners, seen
    # from the upper one (bodies on two branches move apart by the sum of two such motions).
    pairs, corners = [], {}
    for k, p in enumerate(geom.collisionPairs):
        upper, lower = p.first, p.second
        chain = [set(model.supports[geom.geometryObjects[i].parentJoint]) for i in (upper, lower)]
        if chain[1] <= chain[0]:
            upper, lower, chain = lower, upper, chain[::-1]
        if chain[0] <= chain[1]:
            pairs.append((k, upper, lower))
            corners[lower] = hull_points(geom.geometryObjects[lower])
    assert pairs
    rng = np.random.default_rng(11)
    for q0, q1 in zip(*(robot.random_configurations(rng, 6) for _ in range(2))):
        s = np.linspace(0.0, 1.0, 50)
        start = _placements(checker, q0)
        for si in s[1:]:
            now = _placements(checker, q0 + si * (q1 - q0))
            bound = weights @ np.abs(si * (q1 - q0))
            for k, upper, lower in pairs:
                then = start[upper].actInv(start[lower]).act
                later = now[upper].actInv(now[lower]).act
                moved = max(float(np.linalg.norm(later(p) - then(p))) for p in corners[lower])
                assert moved <= bound[k] + 1e-9, (name, k, si, moved, bound[k])


@pytest.mark.parametrize(
    "name",
    [
        "al5c",
        pytest.param("ur5", marks=needs_example_robot_data),
        pytest.param("panda", marks=needs_example_robot_data),
    ],
)
def test_the_near_body_bound_never_overstates_a_distance(name):
    """d(s) >= d(0) - e^T ((R + d(0)) turn(s) + sum_j D_j |dq_j| s) along random segments while the
    pair's joints turn at most NEAR_TURN in all (distances by coal, densely sampled)."""
    from planner.collision.continuous import NEAR_TURN, near_bounds

    robot = get_robot(name)
    checker = CollisionChecker(robot, parse_scene(_TABLE_AND_BOX))
    near = near_bounds(checker)
    rows = np.flatnonzero(np.isfinite(near.radius))
    assert rows.size  # the base and the scene's boxes at least
    mask = checker.pair_mask()
    rng = np.random.default_rng(12)
    tested = 0
    for q0 in robot.random_configurations(rng, 12):
        dq = rng.uniform(-1.0, 1.0, robot.dof)
        dq *= NEAR_TURN / np.sum(np.abs(dq))  # every pair turns at most NEAR_TURN over the segment
        q1 = np.clip(q0 + dq, robot.lower, robot.upper)
        d0 = checker.pair_distances(q0, mask)
        for si in np.linspace(0.0, 1.0, 60)[1:]:
            d = checker.pair_distances(q0 + si * (q1 - q0), mask)
            step = np.abs(si * (q1 - q0))
            turn = near.joints @ step
            lower = d0 - np.exp(NEAR_TURN) * ((near.radius + d0) * turn + near.offsets @ step)
            ok = rows[d0[rows] > 0]
            # Coal's distance of overlapping bodies is no distance: there the bound must allow contact.
            assert np.all(np.where(d[ok] > 0, d[ok] >= lower[ok] - 1e-6, lower[ok] <= 1e-6)), (name, si)
            tested += ok.size
    assert tested > 0


@pytest.mark.parametrize(
    "name", [pytest.param("ur5", marks=needs_example_robot_data), pytest.param("panda", marks=needs_example_robot_data)]
)
def test_a_clear_certificate_holds_between_checks_on_the_table_and_box_scene(name):
    """Segments and trajectories the pair-by-pair check finds clear keep the clearance at 2 kHz samples."""
    robot = get_robot(name)
    scene = parse_scene({**_TABLE_AND_BOX, "clearance": 0.002})
    checker = CollisionChecker(robot, scene)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(13)
    clear = 0
    for _ in range(200):
        qa, qb = robot.random_configurations(rng, 2)
        qb = qa + 0.3 * (qb - qa)
        if not (checker.clearance(qa).clear and checker.clearance(qb).clear):
            continue
        segment = check_segment(checker, qa, qb)
        if not segment.clear:
            continue
        clear += 1
        dense = [checker.clearance(qa + s * (qb - qa)).distance for s in np.linspace(0, 1, 1001)]
        assert min(dense) >= scene.clearance - 1e-4
        traj = plan_trajectory([qa, qb], limits)
        result = check_trajectory(checker, traj)
        if result.clear:
            dense = [checker.clearance(q).distance for q in traj.sample(traj.times(2000.0)).q]
            assert min(dense) >= scene.clearance - 1e-4
        if clear == 4:
            break
    assert clear == 4


@pytest.mark.parametrize("name", MIXED_ARMS)
def test_closer_than_agrees_with_the_distances(name):
    """The broad-phase proximity test says "closer" exactly where some checked pair's distance is below it."""
    robot = get_robot(name)
    scene = parse_scene({**_TABLE_AND_BOX, "floor": -0.02})
    checker = CollisionChecker(robot, scene)
    qs = robot.random_configurations(np.random.default_rng(19), 400)
    for allow in ((), ("box",)):
        mask = checker.pair_mask(allow)
        nearest = np.array([checker.pair_distances(q, mask).min() for q in qs])
        for distance in (0.0, 0.005, 0.02, 0.1):
            near = checker.closer_than(distance, allow)
            verdicts = np.array([near(q) for q in qs])
            # GJK stops within coal's tolerance: pairs within a micrometre of the margin may go either way.
            sure = np.abs(nearest - distance) > 1e-6
            np.testing.assert_array_equal(verdicts[sure], (nearest < distance)[sure])


def test_check_motion_with_per_pair_speeds_agrees_with_check_segment():
    """The public check_motion (speeds per pair, or one number for the whole arm) on straight segments."""
    from planner.collision.continuous import check_motion, pair_weights

    robot = get_robot("al5c")
    checker = CollisionChecker(robot, _al5c_block_scene())
    weights = pair_weights(checker)
    rng = np.random.default_rng(23)
    seen = set()
    for _ in range(30):
        qa, qb = robot.random_configurations(rng, 2)
        if not (checker.clearance(qa).clear and checker.clearance(qb).clear):
            continue
        dq = qb - qa
        reference = check_segment(checker, qa, qb, stop_at_first=False)
        per_pair = check_motion(checker, lambda s, dq=dq, qa=qa: (qa + s * dq, weights @ np.abs(dq)), 1.0)
        whole = check_motion(checker, lambda s, dq=dq, qa=qa: (qa + s * dq, float(np.max(weights @ np.abs(dq)))), 1.0)
        assert per_pair.clear == reference.clear and whole.clear == reference.clear
        if reference.clear:
            dense = [checker.clearance(qa + s * dq).distance for s in np.linspace(0.0, 1.0, 401)]
            assert min(dense) >= checker.scene.clearance - 1e-4
        seen.add(reference.clear)
    assert seen == {True, False}


@pytest.mark.parametrize(("name", "size"), [("al5c", 0.1), pytest.param("panda", 0.5, marks=needs_example_robot_data)])
def test_a_shared_checker_is_reused_per_scene_and_answers_as_a_new_one(name, size):
    robot = get_robot(name)
    box, at = Box((size / 2, size / 2, size)), np.array([0.9 * size, 0.0, size / 2])

    def scene_at(y):
        return Scene(floor=0.0, clearance=0.005, obstacles=(Obstacle("box", box, at + [0.0, y, 0.0]),))

    scene, same, moved = scene_at(0.0), scene_at(0.0), scene_at(size / 5)
    first = shared_checker(robot, scene)
    assert shared_checker(robot, same) is first
    assert shared_checker(robot, moved) is not first and shared_checker(robot, None) is not first
    q = robot.random_configurations(np.random.default_rng(3), 200)
    for row in q:  # GJK's guesses now come from these calls
        first.in_collision(row)
    again = shared_checker(robot, same)
    fresh = CollisionChecker(robot, same)
    assert [again.in_collision(row) for row in q[::-1]] == [fresh.in_collision(row) for row in q[::-1]]
    for row in q[:20]:
        assert again.clearance(row) == fresh.clearance(row)
    with pytest.raises(InvalidArgumentError):
        shared_checker(robot, "table")


def test_only_in_collision_leaves_gjk_guesses_to_forget():
    """forget_guesses skips a checker in_collision has not run on since: nothing else moves its guesses."""
    robot = get_robot("al5c")
    scene = Scene(floor=0.0, clearance=0.005, obstacles=(Obstacle("box", Box((0.05, 0.05, 0.1)), [0.09, 0.0, 0.05]),))
    checker = CollisionChecker(robot, scene)
    fresh = coal.CollisionRequest().cached_gjk_guess

    def guesses_fresh() -> bool:
        return all(np.array_equal(r.cached_gjk_guess, fresh) for r in checker._gdata.collisionRequests)

    q = robot.random_configurations(np.random.default_rng(4), 100)
    for row in q:  # distances, proximity tests and path checks leave the guesses alone
        checker.clearance(row)
        checker.closer_than(0.02)(row)
    assert guesses_fresh()
    checker.forget_guesses()  # nothing to forget: a no-op
    assert guesses_fresh()
    for row in q:
        checker.in_collision(row)
    checker.forget_guesses()
    assert guesses_fresh()
    new = CollisionChecker(robot, scene)
    assert [checker.in_collision(row) for row in q] == [new.in_collision(row) for row in q]


@pytest.mark.parametrize("name", MIXED_ARMS)
def test_swept_reach_bounds_the_body_turned_by_forward_kinematics(name):
    """_swept_reach is at least the largest distance, found by Pinocchio FK at 2000 angles of the
    body's joint, from the axis of the joint above to the body's hull (and not much more)."""
    import pinocchio as pin

    from planner.collision.arm import hull_points
    from planner.collision.continuous import _joint_axis, _swept_reach

    robot = get_robot(name)
    model, data = robot.model, robot.model.createData()
    geom = arm_collision_model(robot).geometry
    tested = 0
    for obj in geom.geometryObjects:
        jid = obj.parentJoint
        parent = model.parents[jid] if jid > 0 else 0
        bound = _swept_reach(model, obj, parent) if parent > 0 else math.inf
        if not math.isfinite(bound):
            continue
        points = hull_points(obj)
        axis = _joint_axis(model, parent)
        rng = np.random.default_rng(jid)
        q = robot.random_configurations(rng, 1)[0]
        farthest = 0.0
        for angle in np.linspace(-math.pi, math.pi, 2000):
            q[jid - 1] = angle
            pin.forwardKinematics(model, data, robot.pinocchio_configuration(q))
            # The body's points in the parent joint's frame, where that joint's axis is fixed.
            where = data.oMi[parent].actInv(data.oMi[jid] * obj.placement)
            at = points @ where.rotation.T + where.translation
            farthest = max(farthest, float(np.max(np.linalg.norm(at - np.outer(at @ axis, axis), axis=1))))
        assert farthest <= bound + 1e-9, (name, obj.name, farthest, bound)
        assert bound <= farthest + 0.01, (name, obj.name, farthest, bound)
        tested += 1
    assert tested > 0


@pytest.mark.parametrize("name", [*MIXED_ARMS, "mixed"])
def test_the_path_search_test_gives_closer_thans_verdicts(name):
    """The search's own proximity test (no contact details, Pinocchio called directly) decides as closer_than's."""
    from planner.collision.rrt import _proximity_test

    if name == "mixed":
        from test_casadi_kinematics import mixed_robot

        robot = mixed_robot()  # a continuous joint: cosine and sine in Pinocchio's configuration
        assert robot.model.nq > robot.dof
    else:
        robot = get_robot(name)
    scene = parse_scene({**_TABLE_AND_BOX, "floor": -0.02})
    checker = CollisionChecker(robot, scene)
    qs = robot.random_configurations(np.random.default_rng(23), 400)
    hits = 0
    for allow in ((), ("box",), ("table", "box", FLOOR)):
        for distance in (0.0, 0.002, 0.02, 0.1):
            ours, theirs = _proximity_test(checker, distance, allow), checker.closer_than(distance, allow)
            assert _proximity_test(checker, distance, list(allow)[::-1]) is ours  # kept per distance and set
            verdicts = [ours(q) for q in qs]
            assert verdicts == [theirs(q) for q in qs]
            hits += sum(verdicts)
    assert 0 < hits < 12 * len(qs)


# ---------------------------------------------------------------------------- the compiled loop against Python


@st.composite
def _fuzz_cases(draw):
    """A random DH arm (1 to 6 joints) or a one-joint stick, a random scene (maybe no pairs at
    all), a trajectory through 2 to 4 random configurations (maybe a tiny or a zero first move)."""
    if draw(st.booleans()):
        robot = robot_from_description(draw(dh_descriptions(min_joints=1, max_joints=6)))
    else:
        robot = _one_link(length=draw(st.floats(0.05, 0.5)), speed=draw(st.floats(5.0, 200.0)))
    size = max(robot.characteristic_length, 0.05)
    obstacles = []
    for k in range(draw(st.integers(0, 5))):
        at = np.array([draw(st.floats(-1.0, 1.0)) for _ in range(3)]) * size
        if draw(st.booleans()):
            obstacles.append(Obstacle(f"o{k}", Sphere(draw(st.floats(0.001, 0.3)) * size), at))
        else:
            obstacles.append(Obstacle(f"o{k}", Box(tuple(draw(st.floats(0.002, 0.5)) * size for _ in range(3))), at))
    floor = draw(st.sampled_from([None, -0.05, 0.0]))
    scene = Scene(floor=floor, clearance=draw(st.sampled_from([0.0, 0.005, 0.02])), obstacles=tuple(obstacles))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    waypoints = robot.random_configurations(rng, draw(st.integers(2, 4)))
    waypoints[1] = waypoints[0] + draw(st.sampled_from([0.0, 1e-6, 0.3, 1.0])) * (waypoints[1] - waypoints[0])
    allow = [(draw(st.floats(0.0, 1.0)), [obstacles[0].name])] if obstacles and draw(st.booleans()) else []
    return robot, scene, waypoints, allow, draw(st.booleans()), rng


@given(case=_fuzz_cases())
@property_settings(60)
def test_random_arms_and_scenes_give_the_same_results_with_and_without_the_compiled_loop(case):
    """check_trajectory with _NativeSteps and with the Python steps (each with a new checker: coal's
    distance of overlapping bodies depends on what it computed before): the same verdicts and
    checks; the steps and the pairs due next of single calls as the Python rule's."""
    import planner.collision.continuous as cc

    loader = cc._native_library
    compiled = loader()
    if compiled is None:
        pytest.skip("no C compiler (PLANNER_JIT=0): the Python steps only")
    robot, scene, waypoints, allow, stop, rng = case
    try:
        traj = plan_trajectory(waypoints, JointLimits.from_robot(robot))
    except PlannerError:
        return
    allow = [(f * traj.duration, names) for f, names in allow]
    results = []
    for lib in (compiled, None):
        cc._native_library = lambda lib=lib: lib
        try:
            results.append(check_trajectory(CollisionChecker(robot, scene), traj, allow=allow, stop_at_first=stop))
        finally:
            cc._native_library = loader
    a, b = results
    assert (a.clear, a.checks) == (b.clear, b.checks)
    # The closest pair, unless two pairs tie (found by CI's hypothesis: two links of a random
    # arm 377.6 mm deep in the floor, equal to 1e-16 m, and rounding named either).
    tie = abs(a.closest.distance - b.closest.distance) <= 1e-9
    assert a.closest.bodies == b.closest.bodies or tie, (a.closest, b.closest)
    assert (a.first_hit is None) == (b.first_hit is None)
    # (x drifts apart in the last bits over many checks: the Python rows carry offsets.)
    slack = 1e-7 * max(traj.duration, 1.0)
    assert abs((a.first_hit or 0.0) - (b.first_hit or 0.0)) <= slack
    if a.closest.distance > 0:
        # (not `where`: at a flat minimum or a tie, checks a rounding apart find the closest elsewhere)
        assert a.closest.distance == pytest.approx(b.closest.distance, abs=1e-8)
    checker = CollisionChecker(robot, scene)
    last, vmax = np.asarray(traj.waypoints[-1], dtype=float), np.asarray(traj.limits.velocity) * (1 + 1e-6)
    rule = cc._trajectory_steps(checker, traj, last, vmax, max(scene.clearance - cc.DEFAULT_TOLERANCE, 0.0))
    if not hasattr(rule, "native"):
        return  # a grid of one time: nothing to step
    n = rule.native.size
    for x in [0.0, *rng.uniform(0.0, traj.duration, 3), traj.duration]:
        due = np.flatnonzero(rng.random(n) < 0.5)
        d = rng.uniform(-0.002, 0.3, len(due))
        room = np.maximum(d - scene.clearance + cc.DEFAULT_TOLERANCE, cc.DEFAULT_TOLERANCE / 2)
        want = rule(float(x), due, d, room)
        until, early = np.full(n, np.inf), np.full(n, np.inf)
        got_x, got_due, got_q = rule.native(
            float(x), due, d, scene.clearance, cc.DEFAULT_TOLERANCE, 0.0, until, early, traj.duration
        )
        big = 1e6 * traj.duration
        # The Python rows carry an offset per row (one search over all of them), which rounds W
        # by up to 1e-15 of the offsets (the `slack` both paths take off every room): the steps
        # agree to that rounding, not bit for bit (CI's hypothesis found 4e-11 s on a 1.1 s
        # trajectory, 1.2e-9 of the step).
        np.testing.assert_allclose(
            np.minimum(until[due] - x, big), np.minimum(want, big), rtol=1e-9, atol=1e-9 * max(traj.duration, 1.0)
        )
        after = min(float(until.min(initial=np.inf)), traj.duration)
        assert got_x == min(after if after > x else np.nextafter(x, np.inf), traj.duration)
        np.testing.assert_array_equal(got_due, np.flatnonzero(early <= got_x))
        assert got_q.shape == (robot.dof,) and np.all(np.isfinite(got_q))


# ---------------------------------------------------------------------------- either body's reach


def _either_side_holds(robot, scene: Scene, rng: np.random.Generator, configurations: int) -> int:
    """Per pair and joint moving one body against the other, at random configurations (by FK):
    pair_weights' entry is at least the smaller of the two bodies' largest distance from the joint's
    axis (hull points; the axis where FK puts it), or, where it is smaller still (a fixed box's face,
    _face_weights), the body projects along the face's normal into the face and the entry is at
    least |n x w| times the body's distance from the axis. Returns how many entries were smaller
    than the lower body's reach alone (_reach_weights)."""
    import coal
    import pinocchio as pin

    from planner.collision.arm import hull_points
    from planner.collision.continuous import _joint_axis_or_none, _reach_weights, near_bounds, pair_weights

    checker = CollisionChecker(robot, scene)
    weights, reach, near = pair_weights(checker), _reach_weights(checker), near_bounds(checker)
    either = np.where(near.joints, np.minimum(reach, near.radius[:, None] + near.offsets), reach)
    assert np.all(weights <= either)
    model, data, geom = robot.model, robot.model.createData(), checker.geometry
    axes = [_joint_axis_or_none(model, j) for j in range(model.njoints)]
    points = [hull_points(o) if np.all(np.abs(hull_points(o)) < 1e6) else None for o in geom.geometryObjects]
    tighter = np.flatnonzero(np.any(weights < reach, axis=1))
    gdata = pin.GeometryData(geom)
    for q in robot.random_configurations(rng, configurations):
        pin.forwardKinematics(model, data, robot.pinocchio_configuration(q))
        pin.updateGeometryPlacements(model, data, geom, gdata)
        for k in tighter.tolist():
            pair = geom.collisionPairs[k]
            ends = []
            for i in (pair.first, pair.second):
                place = gdata.oMg[i]
                ends.append(None if points[i] is None else points[i] @ place.rotation.T + place.translation)
            for j in np.flatnonzero(weights[k] < reach[k]).tolist():
                axis = axes[j + 1]
                assert axis is not None  # the tighter entries are revolute joints'
                at, w = data.oMi[j + 1].translation, data.oMi[j + 1].rotation @ axis
                far = [
                    np.inf if e is None else float(np.max(np.linalg.norm(np.cross(e - at, w), axis=1))) for e in ends
                ]
                if weights[k, j] >= either[k, j]:
                    assert min(far) <= weights[k, j] + 1e-9, (robot.name, k, j, far, weights[k, j])
                    continue
                # A face: the fixed body is a box or a half-space, the other one projects into a face.
                which = 0 if geom.geometryObjects[pair.first].parentJoint == 0 else 1
                fixed, body = geom.geometryObjects[(pair.first, pair.second)[which]], ends[1 - which]
                shape = fixed.geometry
                if isinstance(shape, coal.Halfspace):
                    normals = [fixed.placement.rotation @ shape.n]
                else:
                    assert isinstance(shape, coal.Box)
                    local = (body - fixed.placement.translation) @ fixed.placement.rotation
                    half = np.asarray(shape.halfSide)
                    normals = [
                        fixed.placement.rotation[:, i]
                        for i in range(3)
                        if all(np.all(np.abs(local[:, m]) <= half[m] + 1e-9) for m in range(3) if m != i)
                    ]
                assert normals, (robot.name, k, j)
                least = min(float(np.linalg.norm(np.cross(n, w))) for n in normals)
                assert least * far[1 - which] <= weights[k, j] + 1e-9, (robot.name, k, j, least, weights[k, j])
    return int(np.sum(weights < reach))


@pytest.mark.parametrize("name", MIXED_ARMS)
def test_a_pair_bound_is_either_bodys_reach_from_each_joint_axis(name):
    robot = get_robot(name)
    rng = np.random.default_rng(4)
    assert _either_side_holds(robot, parse_scene(_TABLE_AND_BOX), rng, 200) > 0


@given(description=dh_descriptions(min_joints=1, max_joints=6), seed=st.integers(0, 2**32 - 1))
@property_settings(30)
def test_a_pair_bound_is_either_bodys_reach_on_random_arms(description, seed):
    robot = robot_from_description(description)
    size = max(robot.characteristic_length, 0.05)
    box = Obstacle("box", Box((0.3 * size, 0.2 * size, 0.4 * size)), np.array([0.5, 0.1, 0.2]) * size)
    _either_side_holds(robot, Scene(floor=-0.05 * size, obstacles=(box,)), np.random.default_rng(seed), 40)


@pytest.mark.parametrize("name", MIXED_ARMS)
def test_no_pair_distance_falls_faster_than_its_bound_along_dense_segments(name):
    """d_p(s) >= d_p(0) - pair_weights[p] . |dq| s at 400 points of random joint segments (coal distances)."""
    from planner.collision.continuous import pair_weights

    robot = get_robot(name)
    checker = CollisionChecker(robot, parse_scene(_TABLE_AND_BOX))
    weights, mask = pair_weights(checker), checker.pair_mask()
    rng = np.random.default_rng(6)
    for q0, q1 in zip(*(robot.random_configurations(rng, 4) for _ in range(2))):
        q1 = q0 + 0.3 * (q1 - q0)
        d0 = checker.pair_distances(q0, mask)
        bound = weights @ np.abs(q1 - q0)
        for s in np.linspace(0.0, 1.0, 401)[1:]:
            d = checker.pair_distances(q0 + s * (q1 - q0), mask)
            both = (d0 > 0) & (d > 0) & np.isfinite(d0)
            # (coal's GJK stops within a few micrometres: a body turning above a table reads +-0.3 um)
            assert np.all(d[both] >= d0[both] - s * bound[both] - 1e-5), name
