"""The continuous checks with pair floors against a dense, independent re-check (review of 3a10dcb).

check_segment and check_trajectory leave out the pairs whose floor is beyond the clearance. A
motion they call clear must keep ``clearance - tolerance`` at every one of a dense sampling of
it, each pair's distance computed here with Pinocchio's computeDistance on a fresh
GeometryData (not the checker's own distance calls). The clearances are taken just under
some pairs' floors, so that those pairs are left out while only just: a floor too high, or a
motion leaving the joint limits, would show as a pair closer than the clearance.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from planner import load_robot
from planner.collision import CollisionChecker, parse_scene
from planner.collision.continuous import DEFAULT_TOLERANCE, check_segment, check_trajectory, floored
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory

from conftest import HAVE_EXAMPLE_ROBOT_DATA

ARMS = ["al5c", "dh3"] + (["panda", "ur5"] if HAVE_EXAMPLE_ROBOT_DATA else [])


def _dense_least(checker: CollisionChecker, qs: np.ndarray) -> float:
    """The least distance over the checker's pairs (its mask) at every row of `qs`, computed directly."""
    robot, geometry = checker.robot, checker.geometry
    model, data = robot.model, robot.model.createData()
    gdata = pin.GeometryData(geometry)
    pairs = np.flatnonzero(checker.pair_mask())
    least = np.inf
    for q in qs:
        pin.updateGeometryPlacements(model, data, geometry, gdata, robot._pin_q(q))
        for k in pairs:
            least = min(least, pin.computeDistance(geometry, gdata, int(k)).min_distance)
    return least


def _fuzz(name: str, seed: int, motions: int, samples: int) -> int:
    robot = load_robot(name)
    rng = np.random.default_rng(seed)
    finite = None
    checked = 0
    for _ in range(motions):
        if finite is None:
            floors = floored(CollisionChecker(robot, parse_scene({"floor": -5.0}))).floors
            finite = np.sort(floors[np.isfinite(floors) & (floors > 0.0)])
            assert len(finite)
        # A clearance just under one of the lower half of the finite floors (that pair and those
        # above left out; higher, random motions are seldom clear of the other pairs).
        floor = finite[rng.integers(0, max(len(finite) // 2, 1))]
        clearance = float(floor) * (1.0 - 10.0 ** rng.uniform(-6, -1))
        scene = parse_scene({"floor": -5.0, "clearance": clearance})
        checker, plain = floored(CollisionChecker(robot, scene)), CollisionChecker(robot, scene)
        qa, qb = robot.random_configurations(rng, 2)
        if rng.random() < 0.5:  # a short move (long ones of ur5 seldom keep clear of itself)
            qb = np.clip(qa + rng.normal(0.0, 0.2, robot.dof), robot.lower, robot.upper)
        segment = check_segment(checker, qa, qb)
        if segment.clear:
            s = np.linspace(0.0, 1.0, samples)[:, None]
            assert _dense_least(checker, qa + s * (qb - qa)) >= clearance - DEFAULT_TOLERANCE - 1e-9
            checked += 1
        assert segment.clear == check_segment(plain, qa, qb).clear
        trajectory = plan_trajectory(np.array([qa, qb]), JointLimits.from_robot(robot))
        timed = check_trajectory(checker, trajectory)
        if timed.clear:
            t = np.linspace(0.0, float(trajectory.duration), samples)
            assert _dense_least(checker, trajectory.positions(t)) >= clearance - DEFAULT_TOLERANCE - 1e-9
            checked += 1
        assert timed.clear == check_trajectory(plain, trajectory).clear
    return checked


@pytest.mark.parametrize("name", ARMS)
def test_floored_motion_checks_keep_the_clearance_on_a_dense_recheck(name):
    assert _fuzz(name, 3, 8, 150)


@pytest.mark.slow
@pytest.mark.parametrize("name", ARMS)
@pytest.mark.parametrize("seed", range(3))
def test_floored_motion_checks_keep_the_clearance_on_a_dense_recheck_long(name, seed):
    assert _fuzz(name, 40 + seed, 15, 2000)


def _pair_distance(checker: CollisionChecker, k: int, qs: np.ndarray) -> np.ndarray:
    """Pair `k`'s distance at each row of `qs`, computed directly."""
    robot, geometry = checker.robot, checker.geometry
    data, gdata = robot.model.createData(), pin.GeometryData(geometry)
    out = np.empty(len(qs))
    for r, q in enumerate(qs):
        pin.updateGeometryPlacements(robot.model, data, geometry, gdata, robot._pin_q(q))
        out[r] = pin.computeDistance(geometry, gdata, k).min_distance
    return out


def _through_closest(name: str, seed: int, pairs: int, samples: int) -> int:
    """Segments through the configuration where a floored pair comes closest, the clearance above its distance there.

    A floor set too high (or a left-out pair that can come closer) shows here: the floored
    check would call clear a motion the dense re-check finds closer than the clearance.
    """
    robot = load_robot(name)
    rng = np.random.default_rng(seed)
    floors = floored(CollisionChecker(robot, parse_scene({"floor": -5.0}))).floors
    candidates = np.flatnonzero(np.isfinite(floors) & (floors > 0.0))
    flagged = 0
    for k in rng.choice(candidates, size=min(pairs, len(candidates)), replace=False):
        base = CollisionChecker(robot, parse_scene({"floor": -5.0}))
        qs = robot.random_configurations(rng, 300)
        d = _pair_distance(base, int(k), qs)
        closest = qs[int(np.argmin(d))]
        # Between the floor and twice the pair's least distance found: the pair is left out (and
        # the correct floor keeps it there) or it is computed.
        clearance = float(rng.uniform(floors[k], 2.0 * d.min() + 1e-3))
        scene = parse_scene({"floor": -5.0, "clearance": clearance})
        checker, plain = floored(CollisionChecker(robot, scene)), CollisionChecker(robot, scene)
        step = rng.normal(0.0, 0.05, robot.dof)
        qa = np.clip(closest - step, robot.lower, robot.upper)
        qb = np.clip(closest + step, robot.lower, robot.upper)
        s = np.linspace(0.0, 1.0, samples)[:, None]
        least = _dense_least(checker, qa + s * (qb - qa))
        result = check_segment(checker, qa, qb)
        assert result.clear == check_segment(plain, qa, qb).clear
        if result.clear:
            assert least >= clearance - DEFAULT_TOLERANCE - 1e-9
        flagged += least < clearance
    return flagged


@pytest.mark.parametrize("name", ARMS)
def test_floored_segments_through_a_pairs_closest_configuration(name):
    _through_closest(name, 5, 2, 100)


@pytest.mark.slow
@pytest.mark.parametrize("name", ARMS)
def test_floored_segments_through_a_pairs_closest_configuration_long(name):
    _through_closest(name, 6, 20, 1000)
