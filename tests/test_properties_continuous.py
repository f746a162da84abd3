"""Property tests of the continuous check against an independent dense check.

Generated motions (timed trajectories and straight joint segments between random
configurations) in the table-and-box scene, sometimes with a 5 mm plate anywhere in reach,
are checked by :func:`check_trajectory`, :func:`check_segment` and :func:`segment_is_clear`,
then re-checked at 1 kHz (1000 points per segment) by a fresh checker's distance of every pair
and its collision test. Whatever the motion:

- where the dense check finds a distance below the clearance less the tolerance (or, with a
  clearance above the tolerance, a collision) before the first hit reported, the check cannot
  have reported the motion clear (nothing is passed through between checks, however thin);
- every distance reported (the closest pair, the first hit) is the pair's true distance at its
  instant, never more: the motion's true minimum is at most the reported closest distance;
- the samples before the first hit keep the clearance less the tolerance.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from dh_arms import property_settings
from hypothesis import given, note
from hypothesis import strategies as st

from planner.collision import CollisionChecker, parse_scene
from planner.collision.arm import arm_collision_model
from planner.collision.continuous import DEFAULT_TOLERANCE, check_segment, check_trajectory, segment_is_clear
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory

from conftest import get_robot, needs_example_robot_data

ARMS = [
    "al5c",
    pytest.param("ur5", marks=needs_example_robot_data),
    pytest.param("panda", marks=needs_example_robot_data),
]
#: The benchmark's scene, scaled to the arm's size: a table and a box standing on it.
_TABLE = {"name": "table", "box": [1.6, 1.6, 0.05], "position": [0.0, 0.0, -0.03]}
_BOX = {"name": "box", "box": [0.25, 0.25, 0.5], "position": [0.45, 0.0, 0.25]}
_FLOAT = {"allow_nan": False, "allow_infinity": False, "allow_subnormal": False}
#: GJK stops within coal's tolerance: distances from two code paths agree to a few micrometres.
_SLOP = 1e-5


def _scene(draw, robot, along: np.ndarray) -> dict:
    """The table and the box (scaled to the arm), a clearance, and maybe a 5 mm plate.

    The plate is anywhere in reach, or in the way: through (or up to 3 cm beside) the centre
    of one of the arm's bodies at one of the configurations `along` the motion.
    """
    reach = 0.7 * robot.characteristic_length
    scale = reach / 0.9
    box = {**_BOX, "box": [s * scale for s in _BOX["box"]], "position": [p * scale for p in _BOX["position"]]}
    obstacles = [_TABLE, box]
    where = draw(st.sampled_from(["none", "anywhere", "in the way"]))
    rpy = [draw(st.floats(-3.1, 3.1, **_FLOAT)) for _ in range(3)]
    side = draw(st.floats(0.1, 0.5, **_FLOAT)) * reach
    if where == "anywhere":
        centre = [draw(st.floats(-0.7, 0.7, **_FLOAT)) * reach for _ in range(2)]
        centre.append(draw(st.floats(0.05, 0.8, **_FLOAT)) * reach)
    elif where == "in the way":
        q = along[draw(st.integers(0, len(along) - 1))]
        geom = arm_collision_model(robot).geometry
        moving = [k for k, o in enumerate(geom.geometryObjects) if o.parentJoint > 0]
        gdata = pin.GeometryData(geom)
        pin.updateGeometryPlacements(
            robot.model, robot.model.createData(), geom, gdata, robot.pinocchio_configuration(q)
        )
        middle = gdata.oMg[draw(st.sampled_from(moving))].translation
        offset = np.array([draw(st.floats(-1.0, 1.0, **_FLOAT)) for _ in range(3)]) * 0.03
        centre = list(middle + offset)
    if where != "none":
        obstacles.append({"name": "plate", "box": [side, side, 0.005], "position": centre, "rpy": rpy})
    clearance = draw(st.sampled_from([0.0, 0.002, 0.005]))
    return {"clearance": clearance, "obstacles": obstacles}


def _configuration(draw, robot) -> np.ndarray:
    lower, upper = np.maximum(robot.lower, -np.pi), np.minimum(robot.upper, np.pi)
    fractions = np.array([draw(st.floats(0.0, 1.0, **_FLOAT)) for _ in range(robot.dof)])
    return np.clip(lower + fractions * (upper - lower), lower, upper)


def _between(qa: np.ndarray, qb: np.ndarray, fraction: float, robot) -> np.ndarray:
    """The point `fraction` of the way from `qa` to `qb` (within the limits despite rounding)."""
    return np.clip(qa + fraction * (qb - qa), robot.lower, robot.upper)


class _Dense:
    """The independent check: a fresh checker's distances (every pair) and collision test per sample."""

    def __init__(self, robot, scene) -> None:
        self.checker = CollisionChecker(robot, scene)
        names = self.checker.names
        self.pairs = [(names[p.first], names[p.second]) for p in self.checker.geometry.collisionPairs]

    def distances(self, qs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per sample the smallest distance [m] and whether anything touches."""
        d = np.array([self.checker.clearance(q).distance for q in qs])
        hits = np.array([self.checker.in_collision(q) for q in qs])
        return d, hits

    def pair_distance(self, q: np.ndarray, bodies: tuple[str, str]) -> float:
        """The smallest distance [m] between the two named bodies at `q` (every pair of their objects)."""
        d = self.checker.pair_distances(q, self.checker.pair_mask())
        mine = [k for k, pair in enumerate(self.pairs) if pair == bodies]
        assert mine, bodies
        return float(d[mine].min())


def _check_result(result, dense: _Dense, at, samples: np.ndarray, qs: np.ndarray, clearance: float) -> None:
    """The properties of the module docstring for one result; `at(x)` is the configuration at x."""
    d, hits = dense.distances(qs)
    note(f"{result.describe()}; dense minimum {d.min():.6f} m, {hits.sum()} samples in collision")
    before = samples < result.first_hit if result.first_hit is not None else np.ones(len(samples), dtype=bool)
    # Nothing passed through: the certified stretch keeps the clearance less the tolerance. With
    # clearance 0 that admits a contact shallower than the tolerance (the distances bound it).
    floor = clearance - DEFAULT_TOLERANCE - _SLOP
    if floor > 0:
        assert not hits[before].any(), (samples[before][hits[before]][:3], result.describe())
    assert np.all(d[before] >= floor), (d[before].min(), result.describe())
    if (floor > 0 and hits.any()) or d.min() < floor:
        assert not result.clear
    # Reported distances are the true ones at their instants (so never above the true minimum).
    if np.isfinite(result.closest.distance):
        true = dense.pair_distance(at(result.where), result.closest.bodies)
        if result.closest.distance > 0:
            assert abs(result.closest.distance - true) <= _SLOP, (result.closest, true)
        else:
            assert true <= _SLOP, (result.closest, true)
    if result.hit is not None:
        true = dense.checker.clearance(at(result.first_hit)).distance
        assert result.hit.distance < clearance
        if result.hit.distance > 0:
            assert abs(result.hit.distance - true) <= _SLOP, (result.hit, true)
        else:
            assert true <= _SLOP, (result.hit, true)


def _timed_motion(data, name: str) -> None:
    robot = get_robot(name)
    waypoints = [_configuration(data.draw, robot) for _ in range(data.draw(st.integers(2, 3)))]
    # Short moves too: most of a short move is near its ends, where the arm is slow.
    waypoints[1] = _between(waypoints[0], waypoints[1], data.draw(st.sampled_from([0.1, 0.4, 1.0])), robot)
    traj = plan_trajectory(waypoints, JointLimits.from_robot(robot))
    scene = parse_scene(_scene(data.draw, robot, traj.sample(np.linspace(0.0, traj.duration, 50)).q))
    checker = CollisionChecker(robot, scene)
    stop = data.draw(st.booleans())
    result = check_trajectory(checker, traj, stop_at_first=stop)
    times = np.append(np.arange(0.0, traj.duration, 1e-3), traj.duration)
    qs = traj.sample(times).q
    _check_result(result, _Dense(robot, scene), lambda t: traj.sample(np.array([t])).q[0], times, qs, scene.clearance)


def _segment(data, name: str) -> None:
    robot = get_robot(name)
    qa, qb = _configuration(data.draw, robot), _configuration(data.draw, robot)
    qb = _between(qa, qb, data.draw(st.sampled_from([0.1, 0.4, 1.0])), robot)
    s = np.linspace(0.0, 1.0, 1001)
    qs = qa + s[:, None] * (qb - qa)
    scene = parse_scene(_scene(data.draw, robot, qs[::20]))
    checker = CollisionChecker(robot, scene)
    dense = _Dense(robot, scene)
    result = check_segment(checker, qa, qb, stop_at_first=data.draw(st.booleans()))
    _check_result(result, dense, lambda x: qa + x * (qb - qa), s, qs, scene.clearance)
    margin = data.draw(st.sampled_from([0.0, 0.01]))
    if segment_is_clear(checker, qa, qb, margin=margin):
        d, hits = dense.distances(qs)
        assert not hits.any() and d.min() >= scene.clearance + margin - DEFAULT_TOLERANCE - _SLOP


@pytest.mark.parametrize("name", ARMS)
@given(data=st.data())
@property_settings(8)
def test_timed_motions_agree_with_a_1khz_check(name, data):
    _timed_motion(data, name)


@pytest.mark.parametrize("name", ARMS)
@given(data=st.data())
@property_settings(10)
def test_segments_agree_with_a_dense_check(name, data):
    _segment(data, name)


@pytest.mark.slow
@pytest.mark.parametrize("name", ARMS)
@given(data=st.data())
@property_settings(100)
def test_timed_motions_agree_with_a_1khz_check_many(name, data):
    _timed_motion(data, name)


@pytest.mark.slow
@pytest.mark.parametrize("name", ARMS)
@given(data=st.data())
@property_settings(100)
def test_segments_agree_with_a_dense_check_many(name, data):
    _segment(data, name)
