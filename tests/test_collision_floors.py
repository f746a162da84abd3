"""Pair floors: distances a pair of the arm's links provably never comes below, and the tests that skip them."""

from __future__ import annotations

import numpy as np
import pytest

from planner import load_robot
from planner.collision import CollisionChecker, parse_scene
from planner.collision.continuous import floored, pair_floors
from planner.exceptions import InvalidArgumentError

from conftest import needs_example_robot_data

SCENE = {
    "obstacles": [
        {"name": "table", "box": [1.6, 1.6, 0.05], "position": [0.0, 0.0, -0.03]},
        {"name": "box", "box": [0.25, 0.25, 0.5], "position": [0.45, 0.0, 0.25]},
    ]
}


def _floors_hold(name: str, samples: int) -> None:
    robot = load_robot(name)
    checker = CollisionChecker(robot, parse_scene(SCENE))
    floors = pair_floors(checker)
    assert floors.shape == (checker.pair_count,)
    assert checker.floors is floors
    # Only the arm's own pairs get one; some do on every arm tried here.
    assert np.all(np.isneginf(floors[~checker.self_pairs]))
    assert np.isfinite(floors).any() and np.all(floors[np.isfinite(floors)] > 0.0)
    # No configuration within the limits has a pair closer than its floor (an independent
    # check: coal's distances of every pair at random configurations).
    mask = checker.pair_mask()
    qs = robot.random_configurations(np.random.default_rng(7), samples)
    distances = np.array([checker.pair_distances(q, mask) for q in qs])
    assert np.all(distances >= floors)


@pytest.mark.parametrize("name", ["al5c", "dh3", "three_joint"])
def test_floors_hold_bundled(name):
    _floors_hold(name, 400)


@needs_example_robot_data
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_floors_hold_example_arms(name):
    _floors_hold(name, 300)


def _verdicts(checker: CollisionChecker, qs: np.ndarray, distance: float) -> list[bool]:
    test = checker.closer_than(distance)
    return [bool(test(q)) for q in qs]


@pytest.mark.parametrize("name", ["al5c", "dh3"])
def test_proximity_verdicts_unchanged(name):
    """The proximity tests give the same verdicts with the floors (pairs beyond them left out) as without."""
    robot = load_robot(name)
    plain = CollisionChecker(robot, parse_scene({"floor": 0.0}))
    with_floors = floored(CollisionChecker(robot, parse_scene({"floor": 0.0})))
    assert plain.floors is None and with_floors.floors is not None
    qs = robot.random_configurations(np.random.default_rng(3), 600)
    for distance in (0.0, 0.002, 0.01, 0.05):
        assert _verdicts(plain, qs, distance) == _verdicts(with_floors, qs, distance)


def test_use_floors_checks_its_argument():
    checker = CollisionChecker(load_robot("al5c"))
    with pytest.raises(InvalidArgumentError):
        checker.use_floors(np.zeros(checker.pair_count + 1))
    with pytest.raises(InvalidArgumentError):
        checker.use_floors(np.full(checker.pair_count, np.nan))


def test_a_pair_beyond_its_floor_is_left_out():
    """A floor beyond the test's distance takes the pair out of that test (here: every pair, so nothing is close)."""
    robot = load_robot("al5c")
    checker = CollisionChecker(robot)
    q = robot.random_configurations(np.random.default_rng(1), 400)
    near = checker.closer_than(0.01)
    touching = [x for x in q if near(x)]
    assert touching  # some configurations have links within 1 cm
    checker.use_floors(np.full(checker.pair_count, 0.02))
    assert not any(checker.closer_than(0.01)(x) for x in touching)
    assert all(checker.closer_than(0.03)(x) for x in touching)


def _computed_pairs(checker: CollisionChecker, run) -> tuple[object, set[int]]:
    """`run()`'s result and the pairs whose distance it computed (both ways the checker computes them)."""
    seen: set[int] = set()
    placed, every = checker.placed_distances, checker.pair_distances

    def spy_placed(pairs):
        seen.update(np.asarray(pairs).tolist())
        return placed(pairs)

    def spy_every(q, mask):
        seen.update(np.flatnonzero(mask).tolist())
        return every(q, mask)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(checker, "placed_distances", spy_placed)
        patch.setattr(checker, "pair_distances", spy_every)
        return run(), seen


@pytest.mark.parametrize("name", ["al5c", "dh3"])
def test_motion_checks_leave_out_pairs_beyond_their_floors(name):
    """check_trajectory and check_segment compute no pair whose floor is beyond the clearance, and keep their verdicts.

    Only while the motion stays within the joint limits (where the floors hold): with the limits
    narrowed so that it leaves them, every pair is computed again.
    """
    from planner.collision.continuous import check_segment, check_trajectory
    from planner.motion.limits import JointLimits
    from planner.motion.plan import plan_trajectory

    robot = load_robot(name)
    scene = parse_scene({"floor": 0.0})
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(5)
    left_out = 0
    for _ in range(12):
        qa, qb = robot.random_configurations(rng, 2)
        traj = plan_trajectory(np.array([qa, qb]), limits)
        plain, with_floors = CollisionChecker(robot, scene), floored(CollisionChecker(robot, scene))
        apart = set(np.flatnonzero(with_floors.floors > scene.clearance).tolist())
        assert apart  # these arms have pairs that never come within the clearance
        for check in (
            lambda c, traj=traj: check_trajectory(c, traj, stop_at_first=False),
            lambda c, qa=qa, qb=qb: check_segment(c, qa, qb, stop_at_first=False),
        ):
            a = check(plain)
            b, computed = _computed_pairs(with_floors, lambda check=check, c=with_floors: check(c))
            assert a.clear == b.clear and (a.first_hit is None) == (b.first_hit is None)
            assert not computed & apart
            left_out += 1
    assert left_out
    # Limits narrowed to the segment's middle: the motion leaves them, the floors do not hold.
    qa, qb = robot.random_configurations(np.random.default_rng(6), 2)
    narrow = floored(CollisionChecker(robot, scene))
    mid = (qa + qb) / 2.0
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(type(robot), "lower", property(lambda self: mid - 1e-6))
        patch.setattr(type(robot), "upper", property(lambda self: mid + 1e-6))
        _, computed = _computed_pairs(narrow, lambda: check_segment(narrow, qa, qb, stop_at_first=False))
    assert set(np.flatnonzero(narrow.floors > scene.clearance).tolist()) <= computed


@pytest.mark.parametrize("name", ["al5c", "dh3"])
def test_left_out_pairs_are_reported_with_their_least_floor(name):
    """A check that leaves pairs out names the one with the least floor, a true lower bound of its distance.

    The closest pair reported is among the pairs computed; the report says which pair was not
    measured and the floor it keeps, and the line for users mentions it where that floor is
    below the closest distance found. The reference: the pair's distance at 1 kHz by a checker
    without floors.
    """
    from planner.collision.continuous import check_trajectory
    from planner.motion.limits import JointLimits
    from planner.motion.plan import plan_trajectory

    robot = load_robot(name)
    scene = parse_scene({"floor": 0.0})
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(7)
    for _ in range(6):
        qa, qb = robot.random_configurations(rng, 2)
        traj = plan_trajectory(np.array([qa, qb]), limits)
        plain, with_floors = CollisionChecker(robot, scene), floored(CollisionChecker(robot, scene))
        assert check_trajectory(plain, traj).unmeasured is None
        report = check_trajectory(with_floors, traj)
        u = report.unmeasured
        assert u is not None
        floors = with_floors.floors
        apart = np.flatnonzero((floors > scene.clearance) & with_floors.pair_mask())
        assert u.distance == pytest.approx(float(floors[apart].min()), abs=0.0)
        k = next(int(i) for i in apart if with_floors.pair_clearance(int(i), 1.0).bodies == u.bodies)
        mask = np.zeros(plain.pair_count, dtype=bool)
        mask[k] = True
        qs = traj.sample(np.append(np.arange(0.0, traj.duration, 1e-3), traj.duration)).q
        least = min(float(plain.pair_distances(q, mask)[k]) for q in qs)
        assert least >= u.distance - 1e-9
        assert ("not measured" in report.describe()) == (u.distance < report.closest.distance)
