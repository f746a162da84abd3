"""Checks along a motion, not only at sample points: nothing thin is passed through.

Between two checks no pair of bodies may approach each other by more than the distance found
at the last check (conservative advancement). Per pair, the speed at which the two bodies can
approach is bounded by ``V = sum_j |qd_j| r_j``: a joint both bodies hang from moves them
together and does not count; any other joint ``j`` moves its body's points at most
``|qd_j| r_j`` apart, ``r_j`` an upper bound on the distance from the joint's axis to that
body's points (the joint offsets down the chain plus the body's own extent, where the first
offset may be the next joint's distance from the axis: zero in a wrist whose next joint sits on
it; for the joint right above the body's own, the largest distance of the body's hull turned
about its joint to every angle; 1 for a sliding joint). Where one body hangs below the other
(or is a scene body), ``r_j`` is at most the upper body's own distance from joint ``j``'s
axis (``R + D_j`` of the near-body bound below): the approach speed is
``sum_j qd_j n . (w_j x (p - o_j))`` (``w_j`` the axis through ``o_j``, ``n`` the direction
between the closest points) for either closest point ``p``, so each joint's term is bounded
by either body's distance from its axis. Against a fixed box whose face the body always
projects into along the face's normal ``n`` (a half-space: any body), the first joint's
(its axis ``w`` fixed) ``r_j`` is at most ``|n x w|`` times the body's: zero for a turntable
above a table. Along a
motion known only by its speeds (:func:`check_motion`) the joint speeds a time ``h`` after a
check are at most ``|qd_j| + a_j h`` (``a_j`` the acceleration limit), so a pair approaches by
at most ``V h + A h^2 / 2`` with ``A = sum_j a_j r_j``; the next check comes when that reaches
``d - clearance + tolerance`` for some pair (``d`` its distance found). Along a straight
joint-space segment the bound is ``sum_j |dq_j| r_j`` per unit of path. A timed trajectory is
known in advance: from ``x`` to ``t`` a pair approaches by at most ``sum_j r_j Q_j``, ``Q_j``
joint ``j``'s travel (total variation) over that time, read from a grid of times between which
no joint turns back (its knots and each piece's position and velocity extrema): no
acceleration bound is needed. A motion that passes every check therefore keeps at least
``clearance - tolerance`` from everything checked, at every instant.

Bounding each pair by its own joints (rather than the whole arm's speed) matters most for
links that stay close in every configuration (a compact wrist): their distance changes only
with the few joints between them.

Each pair is advanced on its own: it is certified up to its own next x, and a check computes
only the pairs due then (and those due within half their last step), so a pair far from
everything is computed rarely however often a close one needs it.

Along a timed trajectory several pairs can be advanced by one distance: the convex hull of
the objects one joint carries (a hand and its fingers,
:class:`~planner.collision.checker.BoundingPairs`) is no farther from an object than any of
them, and moves no faster than the fastest of them (the largest of their ``r_j``): while it
keeps :data:`BOUND_MARGIN` beyond the clearance, its steps hold for all its member pairs,
which are not computed. Pairs whose floor (:func:`pair_floors`, where the checker has them) is
beyond the clearance are not computed at all while the motion stays within the joint limits
(a straight segment between two configurations within them; a timed trajectory whose joints'
travel keeps them there): they cannot come closer anywhere there. The steps and bookkeeping
after each check (and the trajectory's grid) run in a small compiled loop
(:mod:`planner.core.native`) where a C compiler is found; NumPy does the same arithmetic
otherwise.

A second bound (the *near-body* bound) serves a small body ``A`` close to the joints that
move a long body ``B`` below it (a base beside a long upper arm): the first bound must let
the far end of ``B`` swing, the second only the points near ``A``. With ``A`` in a ball of
radius ``R`` around ``c`` and ``D_j`` a bound on the distance from ``c`` to joint ``j``'s
axis, a point of ``B`` at ``s`` from ``c`` moves at most ``|qd_j| (s + D_j)`` per joint; it
can only reach ``A`` if it moves more than ``max(d, s - R)``, so the pair keeps ``d - m``
while ``e^T ((R + d) T + sum_j D_j Q_j) <= m``, ``T = sum_j Q_j`` the joints' total turn
(``Q_j`` of joint ``j``, at most :data:`NEAR_TURN`) and ``e^T`` covering the points' own
drift (Gronwall); ``d`` counts as 0 where the bodies overlap (past a hit). A pair takes the
longer of the two steps.
"""

from __future__ import annotations

import bisect
import ctypes
import heapq
import itertools
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from planner.collision.arm import box_corners, hull_points
from planner.collision.checker import BoundingPairs, Clearance, CollisionChecker
from planner.core.arrays import read_only
from planner.core.native import load_functions
from planner.exceptions import InvalidArgumentError

__all__ = [
    "BOUND_MARGIN",
    "DEFAULT_TOLERANCE",
    "NEAR_TURN",
    "SWEEP_RESOLUTION",
    "MotionClearance",
    "NearBounds",
    "check_motion",
    "check_segment",
    "check_trajectory",
    "floored",
    "near_bounds",
    "pair_floors",
    "pair_weights",
    "segment_is_clear",
    "sweep_order",
]

#: How far below the clearance a certified motion may come [m] (sets the smallest step).
DEFAULT_TOLERANCE = 1e-4


@dataclass(frozen=True)
class MotionClearance:
    """The result of checking a motion.

    Attributes:
        clear: Whether every check kept the clearance (so, by the step bound, the whole
            motion keeps ``clearance - tolerance``).
        closest: The closest pair found, at :attr:`where` (among the pairs computed: not those
            left out by their floors, which keep farther than the clearance throughout).
        where: Time [s] (or path parameter in [0, 1]) of the closest check.
        first_hit: Time (or parameter) of the first check below the clearance, or None.
        hit: The pair at :attr:`first_hit` (the bodies and the depth), or None.
        checks: Number of distance checks made.
        unmeasured: Of the pairs left out by their floors (:func:`pair_floors`: a distance
            each provably never comes below within the joint limits, beyond the clearance),
            the one with the least floor, as a :class:`Clearance` whose distance is that
            floor: a lower bound of its distance throughout, not a distance found. None where
            no pair was left out. Where its floor is below :attr:`closest`'s distance, that
            pair may have come closer than :attr:`closest` (its distance was not computed).
    """

    clear: bool
    closest: Clearance
    where: float
    first_hit: float | None
    hit: Clearance | None
    checks: int
    unmeasured: Clearance | None = None

    def describe(self, unit: str = "s") -> str:
        """One line for users: clear and how close, or where it hits what."""
        if self.clear:
            line = f"clear: closest {self.closest} (at {self.where:.3f} {unit}, {self.checks} checks)"
            u = self.unmeasured
            if u is not None and u.distance < self.closest.distance:
                a, b = u.bodies
                line += (
                    f"; {a} and {b} not measured: never closer than {u.distance * 1000:.1f} mm "
                    "within the joint limits (their floor)"
                )
            return line
        assert self.hit is not None
        if self.hit.in_collision:
            return f"collides at {self.first_hit:.3f} {unit}: {self.hit}"
        return (
            f"comes closer than the clearance ({self.hit.clearance * 1000:.1f} mm) at {self.first_hit:.3f} {unit}: "
            f"{self.hit}"
        )


_WEIGHTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


class _ArmTables:
    """Per arm, the tables of checkers seen before, by what they check (kept in ``robot.derived``).

    Planning makes a checker per request; the same arm and scene give the same tables.
    """

    def __init__(self) -> None:
        self.arm: object | None = None
        self.tables: dict[tuple, object] = {}


def _checker_key(checker: CollisionChecker, what: str) -> tuple:
    """What a checker's tables depend on: its pairs and its scene's bodies (shapes and poses)."""
    scene = checker.scene
    bodies = tuple(
        (
            o.name,
            repr(o.shape),
            np.asarray(o.position, dtype=float).tobytes(),
            np.asarray(o.rotation, dtype=float).tobytes(),
        )
        for o in scene.obstacles
    )
    pairs = tuple((int(p.first), int(p.second)) for p in checker.geometry.collisionPairs)
    return (what, scene.floor, bodies, pairs)


def _arm_table(checker: CollisionChecker, what: str, make: Callable[[], object]) -> object:
    held = checker.robot.derived.get(_ArmTables, _ArmTables)
    if held.arm is not checker.arm:
        held.arm, held.tables = checker.arm, {}
    key = _checker_key(checker, what)
    table = held.tables.get(key)
    if table is None:
        if len(held.tables) >= 64:
            held.tables.clear()
        table = held.tables[key] = make()
    return table


class _ArmReach:
    """Per object of an arm's collision model, its reach from every joint (kept in ``robot.derived``)."""

    def __init__(self) -> None:
        self.arm: object | None = None
        self.table: dict[int, np.ndarray] = {}
        self.chains: list[list[int]] = []


def _joint_axis(model, jid: int) -> np.ndarray:
    """The unit axis of revolute joint `jid` in its own frame."""
    joint = model.joints[jid]
    jdata = joint.createData()
    joint.calc(jdata, np.zeros(model.nq))
    motion = np.asarray(jdata.S, dtype=float).reshape(6, -1)
    return motion[3:, 0] / np.linalg.norm(motion[3:, 0])


def _joint_points(obj) -> np.ndarray:
    """:func:`~planner.collision.arm.hull_points` of a geometry object in its joint's frame [m]."""
    return hull_points(obj) @ obj.placement.rotation.T + obj.placement.translation


def _axis_reach(model, obj) -> float:
    """Largest distance of a geometry object from the axis of the revolute joint carrying it [m].

    The object lies within the hull of :func:`~planner.collision.arm.hull_points`, whose points
    (in the joint's frame) bound the distance from the axis (a convex function): inf for a
    joint that is not a plain rotation.
    """
    axis = _joint_axis_or_none(model, obj.parentJoint)
    if axis is None:
        return float("inf")
    points = _joint_points(obj)
    return float(np.max(np.linalg.norm(points - np.outer(points @ axis, axis), axis=1)))


#: Angles at which :func:`_swept_reach` turns an object about its joint's axis.
_SWEEP_ANGLES = 360


def _swept_reach(model, obj, parent: int) -> float:
    """Largest distance of a geometry object from joint `parent`'s axis, its own joint turned to any angle [m].

    For an object whose revolute joint hangs directly below revolute joint `parent`: its hull's
    points turned about their joint's axis at `_SWEEP_ANGLES` angles, plus the farthest
    a point can move between two of them (its distance from that axis times half the angle
    between them). inf where a joint is not a plain rotation.
    """
    own = _joint_axis_or_none(model, obj.parentJoint)
    above = _joint_axis_or_none(model, parent)
    if own is None or above is None:
        return float("inf")
    points = _joint_points(obj)
    lever = float(np.max(np.linalg.norm(points - np.outer(points @ own, own), axis=1)))
    angles = np.linspace(0.0, 2.0 * np.pi, _SWEEP_ANGLES, endpoint=False)
    # Rodrigues for every angle at once: p + sin(a) k x p + (1 - cos(a)) k x (k x p).
    cross = np.cross(own, points)
    twice = np.cross(own, cross)
    turned = points + np.sin(angles)[:, None, None] * cross + (1.0 - np.cos(angles))[:, None, None] * twice
    place = model.jointPlacements[obj.parentJoint]
    at = turned @ place.rotation.T + place.translation
    best = float(np.max(np.linalg.norm(at - (at @ above)[..., None] * above, axis=-1)))
    return best + lever * np.pi / _SWEEP_ANGLES


def _joint_axis_or_none(model, jid: int) -> np.ndarray | None:
    """The unit axis of joint `jid` if it is a plain rotation about an axis through its origin, else None."""
    if jid <= 0:
        return None
    joint = model.joints[jid]
    jdata = joint.createData()
    joint.calc(jdata, np.zeros(model.nq))
    motion = np.asarray(jdata.S, dtype=float).reshape(6, -1)
    if motion.shape[1] != 1 or np.linalg.norm(motion[:3, 0]) > 1e-12:
        return None
    return motion[3:, 0] / np.linalg.norm(motion[3:, 0])


def pair_weights(checker: CollisionChecker) -> np.ndarray:
    """Per checked pair and joint, how fast the pair can approach per unit joint speed [m/rad or m/m].

    Row ``p`` holds ``r_j`` for the joints that move one body of pair ``p`` but not the other
    (see the module docstring), zero elsewhere; shape (pairs, dof). Computed once per checker.
    """
    if not isinstance(checker, CollisionChecker):
        raise InvalidArgumentError(f"pair_weights needs a CollisionChecker, got {type(checker).__name__}")
    cached = _WEIGHTS.get(checker)
    if cached is None:
        cached = _WEIGHTS[checker] = _arm_table(checker, "weights", lambda: _pair_weights(checker))
    return cached


def _pair_weights(checker: CollisionChecker) -> np.ndarray:
    """:func:`_reach_weights`, or per joint ``R + D_j`` of :func:`near_bounds` where smaller.

    The approach speed of two bodies is ``n . (w x (p - o))`` summed over the joints between
    them (``w`` a joint's axis through ``o``, ``n`` the direction between the closest points)
    for any point ``p`` on the line through the closest points: per joint, either closest
    point's distance from the axis bounds its term. The upper body's points lie within ``R``
    of the ball's centre, which is within ``D_j`` of joint ``j``'s axis.
    """
    reach = _reach_weights(checker)
    near = near_bounds(checker)
    ball = near.radius[:, None] + near.offsets  # R is inf where the bound does not apply
    weights = np.where(near.joints, np.minimum(reach, ball), reach)
    _face_weights(checker, reach, weights)
    weights.setflags(write=False)
    return weights


def _face_weights(checker: CollisionChecker, reach: np.ndarray, weights: np.ndarray) -> None:
    """Per pair of a fixed box (or half-space) and a body: the first joint's weight where a face is always closest.

    The body stays within ``rho`` (its reach) of the first joint's axis ``w`` (fixed in the
    world) and within ``H`` of the joint's origin. Where every such point projects along a
    face's normal ``n`` into the face (a half-space: always), the body off the box lies
    wholly beyond that face's plane (it is convex) and the closest points are a normal apart:
    the joint's term ``n . (w x r)`` is at most ``|n x w| rho``; zero where the axis is normal
    to the face (a turntable above a table). Written into `weights` where smaller.
    """
    model, geom = checker.robot.model, checker.geometry
    prismatic = np.array(checker.robot.joint_kinds) == "prismatic"
    # A bound on any arm point's distance from the first joint's origin: every offset, slide and object.
    height = sum(float(np.linalg.norm(model.jointPlacements[j].translation)) for j in range(1, model.njoints))
    height += float(np.sum(np.maximum(np.abs(checker.robot.lower), np.abs(checker.robot.upper))[prismatic]))
    objects = list(geom.geometryObjects)
    moving = [o for o in objects if o.parentJoint > 0]
    height += max((float(np.max(np.linalg.norm(_joint_points(o), axis=1))) for o in moving), default=0.0)
    for k, pair in enumerate(geom.collisionPairs):
        for fixed, body in ((objects[pair.first], objects[pair.second]), (objects[pair.second], objects[pair.first])):
            if fixed.parentJoint != 0 or body.parentJoint == 0:
                continue
            first = next(j for j in model.supports[body.parentJoint] if j > 0)
            axis = _joint_axis_or_none(model, first)
            if axis is None:
                continue
            w = model.jointPlacements[first].rotation @ axis
            origin = model.jointPlacements[first].translation
            rho = float(reach[k, first - 1])
            shape = fixed.geometry
            if isinstance(shape, coal.Halfspace):
                normal = np.asarray(fixed.placement.rotation @ shape.n, dtype=float)
                sines = [float(np.linalg.norm(np.cross(normal, w)))]
            elif isinstance(shape, coal.Box):
                rotation, half = fixed.placement.rotation, np.asarray(shape.halfSide, dtype=float)
                foot = origin - fixed.placement.translation
                sines = []
                for i in range(3):
                    n = rotation[:, i]
                    sine = float(np.linalg.norm(np.cross(n, w)))
                    # The body's points lie within rho of the axis, at most `height` along it from
                    # the origin: projected along n they stay within rho + height * tan of the foot.
                    cosine = abs(float(n @ w))
                    if cosine <= 0.5:
                        continue
                    spread = rho + height * sine / cosine
                    inside = all(abs(float(foot @ rotation[:, m])) + spread <= half[m] for m in range(3) if m != i)
                    if inside:
                        sines.append(sine)
            else:
                continue
            for sine in sines:
                weights[k, first - 1] = min(weights[k, first - 1], sine * rho)


def _reach_weights(checker: CollisionChecker) -> np.ndarray:
    """Per pair and joint, ``r_j`` of the module docstring: how far the lower body's points are from the axis."""
    robot = checker.robot
    model = robot.model
    geom = checker.geometry
    prismatic = np.array(robot.joint_kinds) == "prismatic"
    offset = np.array(
        [0.0] + [float(np.linalg.norm(model.jointPlacements[j].translation)) for j in range(1, model.njoints)]
    )
    travel = np.zeros(model.njoints)
    travel[1:] = np.where(prismatic, np.maximum(np.abs(robot.lower), np.abs(robot.upper)), 0.0)
    # Per moving object of the arm: r_j for every joint (0 off its chain), kept per arm (the
    # arm's objects come first in every checker's geometry, the scene's after them).
    held = robot.derived.get(_ArmReach, _ArmReach)
    if held.arm is not checker.arm:
        held.arm, held.table = checker.arm, {}
        held.chains = [sorted(set(model.supports[j]) - {0}) for j in range(model.njoints)]
    reach: dict[int, np.ndarray] = held.table
    chain_of = held.chains
    # Per joint, its origin's distance from its parent joint's axis (inf where the parent slides).
    axis_distance = np.full(model.njoints, np.inf)
    for j in range(2, model.njoints):
        parent = model.parents[j]
        if parent > 0 and not prismatic[parent - 1]:
            axis = _joint_axis(model, parent)
            at = np.asarray(model.jointPlacements[j].translation, dtype=float)
            axis_distance[j] = float(np.linalg.norm(at - (at @ axis) * axis))

    def reach_of(k: int) -> np.ndarray:
        if k not in reach:
            obj = geom.geometryObjects[k]
            chain = chain_of[obj.parentJoint]
            # The farthest point of the object from its joint's origin.
            own = float(np.max(np.linalg.norm(_joint_points(obj), axis=1)))
            r = np.zeros(robot.dof)
            for jid in chain:
                # Offsets from joint jid down to the object's joint (a slide adds its travel).
                below = [j for j in chain if j > jid]
                if prismatic[jid - 1]:
                    r[jid - 1] = 1.0
                    continue
                r[jid - 1] = own + offset[below].sum() + travel[below].sum()
                if below:
                    # What counts is the distance from jid's axis: the next joint's origin is at a
                    # fixed distance from it (often on it: a wrist), the object beyond as above.
                    beyond = own + offset[below[1:]].sum() + travel[below].sum()
                    r[jid - 1] = min(r[jid - 1], axis_distance[below[0]] + beyond)
                    if below == [obj.parentJoint]:
                        # The object's joint hangs directly below: its points turned to every angle.
                        r[jid - 1] = min(r[jid - 1], _swept_reach(model, obj, jid))
            if obj.parentJoint > 0 and not prismatic[obj.parentJoint - 1]:
                # The joint that carries the object itself turns it about its axis: what counts
                # is the object's distance from that axis, not from the joint's origin.
                r[obj.parentJoint - 1] = min(r[obj.parentJoint - 1], _axis_reach(model, obj))
            reach[k] = r
        return reach[k]

    weights = np.zeros((len(geom.collisionPairs), robot.dof))
    for k, pair in enumerate(geom.collisionPairs):
        ids = (pair.first, pair.second)
        chains = [set(chain_of[geom.geometryObjects[i].parentJoint]) for i in ids]
        for i, own, other in ((ids[0], chains[0], chains[1]), (ids[1], chains[1], chains[0])):
            only = [j - 1 for j in own - other]
            if only:
                weights[k, only] += reach_of(i)[only]
    return weights


#: Distance evaluations :func:`pair_floors` spends at most per pair.
FLOOR_EVALUATIONS = 6000

#: :func:`pair_floors` stops refining once its floor is this share of the least distance found.
FLOOR_SHARE = 0.5

#: Most joints a pair's distance may depend on for :func:`pair_floors` to bound it.
FLOOR_JOINTS = 2


class _ArmFloors:
    """Per arm, :func:`pair_floors` of its own pairs (kept in ``robot.derived``)."""

    def __init__(self) -> None:
        self.arm: object | None = None
        self.floors: dict[tuple[int, int], float] = {}


def pair_floors(checker: CollisionChecker) -> np.ndarray:
    """Per checked pair, a distance [m] it never comes below within the joint limits; ``-inf`` where none is known.

    Known for the pairs of the arm's own links whose distance depends on at most
    :data:`FLOOR_JOINTS` joints (those that move one link and not the other: a joint both hang
    from moves them alike), such as two wrist links with one joint between them. Over those
    joints' ranges (a turning joint's at most one turn: its distances repeat) a branch and
    bound: a cell of joint values whose centre is at distance ``d`` keeps at least ``d - sum_j
    r_j h_j`` (``h_j`` the cell's half-width, ``r_j`` of :func:`pair_weights`: how fast the pair
    can approach per unit of joint ``j``); the cell lowest so bounded is quartered (halved per
    joint) until its bound reaches :data:`FLOOR_SHARE` of the least distance found or is
    within 0.1 mm of its centre's, or :data:`FLOOR_EVALUATIONS` are spent; the least bound of
    all cells is the floor (none where the two links touch somewhere). Computed once per arm; the checker is given them
    (:meth:`CollisionChecker.use_floors`).
    """
    if not isinstance(checker, CollisionChecker):
        raise InvalidArgumentError(f"pair_floors needs a CollisionChecker, got {type(checker).__name__}")
    floors = checker.floors
    if floors is not None:
        return floors
    robot = checker.robot
    held = robot.derived.get(_ArmFloors, _ArmFloors)
    if held.arm is not checker.arm:
        held.arm, held.floors = checker.arm, {}
    weights = pair_weights(checker)
    objects = list(checker.geometry.geometryObjects)
    out = np.full(checker.pair_count, -np.inf)
    model, data = robot.model, robot.model.createData()
    gdata = pin.GeometryData(checker.geometry)
    lower, upper = np.asarray(robot.lower, dtype=float), np.asarray(robot.upper, dtype=float)
    # The other joints at their ranges' middles (0 where a range is unbounded): halves first, so
    # that neither an unbounded range (-inf + inf) nor a huge one overflows into a NumPy warning.
    bounded = np.isfinite(lower) & np.isfinite(upper)
    base = np.where(bounded, lower, 0.0) / 2.0 + np.where(bounded, upper, 0.0) / 2.0
    turns = np.array([kind != "prismatic" for kind in robot.joint_kinds])
    for k, pair in enumerate(checker.geometry.collisionPairs):
        if not checker.self_pairs[k]:
            continue
        key = (int(pair.first), int(pair.second))
        if key not in held.floors:
            held.floors[key] = _pair_floor(
                robot, model, data, checker.geometry, gdata, k, weights[k], base, lower, upper, turns, objects
            )
        out[k] = held.floors[key]
    checker.use_floors(out)
    return checker.floors


def floored(checker: CollisionChecker) -> CollisionChecker:
    """`checker`, given its :func:`pair_floors` first (a stand-in that is no :class:`CollisionChecker` as it is)."""
    if isinstance(checker, CollisionChecker) and checker.floors is None:
        pair_floors(checker)
    return checker


def _apart(checker: CollisionChecker, low: np.ndarray, high: np.ndarray, clearance: float) -> np.ndarray | None:
    """The pairs whose floor (:func:`pair_floors`, where the checker has them) is beyond `clearance`, or None.

    Only where the motion stays within the joint limits the floors hold in: every joint between
    `low` and `high` (bounds of its positions along the motion) within its range.
    """
    floors = checker.floors
    if floors is None:
        return None
    robot = checker.robot
    if not (np.all(low >= robot.lower) and np.all(high <= robot.upper)):
        return None
    apart = floors > clearance
    return apart if apart.any() else None


def _pair_floor(robot, model, data, geom, gdata, k, weights, base, lower, upper, turns, objects) -> float:
    """:func:`pair_floors` of pair `k`: the branch and bound over the joints it depends on."""
    joints = np.flatnonzero(weights > 0.0)
    if len(joints) == 0 or len(joints) > FLOOR_JOINTS:
        return -np.inf
    with np.errstate(over="ignore"):  # a range wider than the largest float: inf, a whole turn below
        lo, width = lower[joints].copy(), upper[joints] - lower[joints]
    for i, j in enumerate(joints):
        if turns[j] and not width[i] <= 2.0 * np.pi:  # a whole turn (or an unlimited joint)
            lo[i] = lo[i] if np.isfinite(lo[i]) else -np.pi
            width[i] = 2.0 * np.pi
    if not np.all(np.isfinite(width)) or not np.all(np.isfinite(lo)):
        return -np.inf
    w = weights[joints]
    q = base.copy()

    def distance(centre: np.ndarray) -> float:
        q[joints] = centre
        pin.updateGeometryPlacements(model, data, geom, gdata, robot.pinocchio_configuration(q))
        return float(pin.computeDistance(geom, gdata, k).min_distance)

    # Cells of at most 0.2 rad (or m) to start with, fewer and wider where that would spend more
    # than half the evaluations (a long slide: 0.2 m cells of a 1 km rail took 15 s); a heap by
    # their lower bound.
    counts = np.maximum(1.0, np.ceil(width / 0.2))
    most = FLOOR_EVALUATIONS // 2
    if np.prod(counts) > most:
        counts = np.maximum(1.0, np.floor(counts * (most / np.prod(counts)) ** (1.0 / len(counts))))
    counts = counts.astype(int)
    half = width / counts / 2.0
    heap: list[tuple[float, float, int, tuple[float, ...], tuple[float, ...]]] = []
    evaluations = 0
    for index in np.ndindex(*counts):
        centre = lo + (2.0 * np.array(index) + 1.0) * half
        d = distance(centre)
        evaluations += 1
        heapq.heappush(heap, (d - float(w @ half), d, evaluations, tuple(centre), tuple(half)))
    least = min(cell[1] for cell in heap)
    # GJK's distances are exact to about its tolerance (1e-6 m): a margin far above it.
    slack = 1e-5
    while True:
        bound, d, _, centre, h = heap[0]
        if least <= 0.0:
            return -np.inf  # they touch: no floor above zero
        if bound >= FLOOR_SHARE * least or d - bound <= 1e-4 or evaluations + 2 ** len(joints) > FLOOR_EVALUATIONS:
            return bound - slack
        heapq.heappop(heap)
        c, h2 = np.array(centre), np.array(h) / 2.0
        for signs in itertools.product((-1.0, 1.0), repeat=len(joints)):
            child = c + np.array(signs) * h2
            dc = distance(child)
            least = min(least, dc)
            evaluations += 1
            heapq.heappush(heap, (dc - float(w @ h2), dc, evaluations, tuple(child), tuple(h2)))


#: Largest total joint rotation between two checks of a pair under the near-body bound [rad].
NEAR_TURN = 0.1
_NEAR_GROWTH = float(np.exp(NEAR_TURN))

_NEAR: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@dataclass(frozen=True)
class NearBounds:
    """Per pair, the near-body bound of the module docstring (from :func:`near_bounds`).

    Attributes:
        radius: ``R``, the radius of a ball around the pair's upper body ``A`` (the one the
            other hangs below, or a scene body) [m]; inf where the bound does not apply.
        offsets: ``D_j``, per pair and joint between the two, a bound on the distance from the
            ball's centre to joint ``j``'s axis [m]; 0 for the other joints.
        joints: Per pair and joint, whether the joint moves one body relative to the other.
    """

    radius: np.ndarray
    offsets: np.ndarray
    joints: np.ndarray


def _near_row(robot, objects: list, ids: tuple[int, int]) -> tuple[float, np.ndarray, np.ndarray]:
    """``(R, D, joints)`` of one pair of geometry objects (R inf where the bound does not apply)."""
    model = robot.model
    offsets, joints = np.zeros(robot.dof), np.zeros(robot.dof, dtype=bool)
    objs = [objects[i] for i in ids]
    chains = [list(model.supports[o.parentJoint]) for o in objs]
    if set(chains[1]) <= set(chains[0]):
        objs, chains = objs[::-1], chains[::-1]
    upper = objs[0]
    if not set(chains[0]) <= set(chains[1]):
        return np.inf, offsets, joints  # on different branches
    between = [j for j in chains[1] if j not in chains[0]]
    joints[[j - 1 for j in between]] = True
    if not between or any(robot.joint_kinds[j - 1] == "prismatic" for j in between):
        return np.inf, offsets, joints
    if model.parents[between[0]] != upper.parentJoint:
        return np.inf, offsets, joints
    corners = box_corners(upper)
    if not np.all(np.abs(corners) < 1e6):
        return np.inf, offsets, joints  # a half-space
    centre_local = (corners.min(axis=0) + corners.max(axis=0)) / 2.0
    centre = upper.placement.rotation @ centre_local + upper.placement.translation
    # The first joint's axis is fixed to A: what counts is the centre's distance from it.
    first = model.jointPlacements[between[0]]
    axis = first.rotation @ _joint_axis(model, between[0])
    # The point of the axis nearest the centre, c': the next joint turns about the axis, so
    # its distance from c' never changes; farther joints add their offsets.
    arm = centre - first.translation
    foot = first.translation + (arm @ axis) * axis
    reach = float(np.linalg.norm(centre - foot))
    offsets[between[0] - 1] = reach
    if len(between) > 1:
        # Or from the first joint's origin (whichever is shorter).
        second = first.translation + first.rotation @ model.jointPlacements[between[1]].translation
        reach = min(
            reach + float(np.linalg.norm(second - foot)),
            float(np.linalg.norm(arm)) + float(np.linalg.norm(second - first.translation)),
        )
        for j in between[1:]:
            if j != between[1]:
                reach += float(np.linalg.norm(model.jointPlacements[j].translation))
            offsets[j - 1] = reach
    return float(np.max(np.linalg.norm(corners - centre_local, axis=1))), offsets, joints


def near_bounds(checker: CollisionChecker) -> NearBounds:
    """The near-body bound's constants per checked pair (computed once per checker and arm).

    It applies to a pair whose upper body ``A`` (a scene body, or a link the other hangs
    below) has a finite extent and whose joints in between all turn.
    """
    cached = _NEAR.get(checker)
    if cached is None:
        cached = _NEAR[checker] = _arm_table(checker, "near", lambda: _near_bounds(checker))
    return cached


def _near_bounds(checker: CollisionChecker) -> NearBounds:
    robot, geom = checker.robot, checker.geometry
    objects = list(geom.geometryObjects)
    rows = [_near_row(robot, objects, (int(p.first), int(p.second))) for p in geom.collisionPairs]
    n = len(rows)
    radius = np.array([r[0] for r in rows], dtype=float).reshape(n)
    offsets = np.array([r[1] for r in rows], dtype=float).reshape(n, robot.dof)
    joints = np.array([r[2] for r in rows], dtype=bool).reshape(n, robot.dof)
    return NearBounds(read_only(radius), read_only(offsets), read_only(joints, dtype=bool))


def check_motion(
    checker: CollisionChecker,
    sample: Callable[[float], tuple[np.ndarray, float]],
    end: float,
    acceleration: float = 0.0,
    *,
    masks: Sequence[tuple[float, np.ndarray]] | None = None,
    tolerance: float = DEFAULT_TOLERANCE,
    stop_at_first: bool = False,
    clearance: float | None = None,
) -> MotionClearance:
    """Check a motion ``q(x)``, x from 0 to `end`, with a bound on how fast the arm's surface moves.

    Each pair is advanced on its own (see the module docstring): at a check only the pairs
    whose certified stretch ends there (or soon) are computed.

    Args:
        checker: The collision checker.
        sample: Returns the configuration at x and ``V``, an upper bound on how fast pairs
            approach there [m per unit x]: one number for the whole arm's surface, or one per
            pair (from :func:`pair_weights`).
        end: Last x.
        acceleration: ``A``: the speed ``h`` later is at most ``V + A h`` (one number, or one
            per pair).
        masks: ``(x_from, pair_mask)`` in ascending x: the pairs checked from each x on (from
            :meth:`CollisionChecker.pair_mask`); None checks every pair throughout.
        tolerance: See the module docstring [m].
        stop_at_first: Return at the first check below the clearance.
        clearance: The distance to keep [m]; None is the scene's.

    Returns:
        The :class:`MotionClearance`; :attr:`MotionClearance.checks` counts the configurations
        at which distances were computed.
    """
    n_pairs = checker.pair_count
    # A scalar bound is the whole arm's: two links approach each other at most twice as fast.
    double = np.where(checker.self_pairs, 2.0, 1.0)
    acc = np.maximum(np.asarray(acceleration, dtype=float), 0.0)
    acc = np.broadcast_to(acc * double if acc.ndim == 0 else acc, (n_pairs,))

    def steps(speed, due: np.ndarray, d: np.ndarray, room: np.ndarray) -> np.ndarray:
        speed = np.asarray(speed, dtype=float)
        v = np.maximum(speed * double[due] if speed.ndim == 0 else speed[due], 1e-12)
        a = acc[due]
        return 2.0 * room / (v + np.sqrt(v * v + 2.0 * a * room))

    return _advance(checker, sample, steps, end, masks, tolerance, stop_at_first, clearance)


def _segment_steps(checker: CollisionChecker) -> Callable:
    """The step rule of a straight joint segment, sampled with its constant joint speeds ``|dq_j|``.

    Per pair, the longer of the steps the two bounds of the module docstring allow (``room / V``;
    the near-body bound only for the pairs where it can be the longer one).
    """
    weights = pair_weights(checker)
    near = near_bounds(checker)
    n = len(weights)
    # The near-body bound is never the longer where (R + D_j) e^T >= r_j for every joint.
    useful = np.isfinite(near.radius) & np.any(
        near.joints
        & (_NEAR_GROWTH * (np.where(np.isfinite(near.radius), near.radius, 0.0)[:, None] + near.offsets) < weights),
        axis=1,
    )
    rows = np.flatnonzero(useful)
    # One product per speed: the first bound's V, and per useful pair T and sum_j D_j Q_j.
    stacked = np.vstack([weights, near.joints[rows].astype(float), near.offsets[rows]])
    radius = near.radius[rows]
    slot = np.full(n, -1)
    slot[rows] = np.arange(len(rows))
    state: dict[str, object] = {"speed": None}

    def steps(speed: np.ndarray, due: np.ndarray, d: np.ndarray, room: np.ndarray) -> np.ndarray:
        if state["speed"] is not speed:
            product = stacked @ speed
            state["speed"], state["v"] = speed, np.maximum(product[:n], 1e-12)
            turn, lever = product[n : n + len(rows)], product[n + len(rows) :]
            state["turn"], state["lever"] = turn, lever
            state["cap"] = NEAR_TURN / np.maximum(turn, 1e-300)
        step = room / state["v"][due]
        where = slot[due]
        hit = where >= 0
        if hit.any():
            k = where[hit]
            # A pair that overlaps (d < 0, past a hit) counts as touching: the ball stays R.
            v = _NEAR_GROWTH * ((radius[k] + np.maximum(d[hit], 0.0)) * state["turn"][k] + state["lever"][k])
            step[hit] = np.maximum(step[hit], np.minimum(room[hit] / np.maximum(v, 1e-300), state["cap"][k]))
        return step

    return steps


def _advance(
    checker: CollisionChecker,
    sample: Callable[[float], tuple[np.ndarray, object]],
    steps: Callable[[object, np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    end: float,
    masks: Sequence[tuple[float, np.ndarray]] | None,
    tolerance: float,
    stop_at_first: bool,
    clearance: float | None,
    native: Callable | None = None,
    bounds: BoundingPairs | None = None,
    apart: np.ndarray | None = None,
) -> MotionClearance:
    """Conservative advancement pair by pair: `sample` gives q and a speed state, `steps` each due pair's step.

    `native`, where given, replaces the steps and the bookkeeping after a check
    (:class:`_NativeSteps`): ``native(x, due, d, clearance, tolerance, coarse, until, early,
    bound)`` updates `until` and `early` and returns the next x, the pairs due there and the
    configuration there (``sample(x)[0]``; ``sample(x)[1]`` is taken to be x, as in a timed
    trajectory).

    `bounds` (whose pairs `steps` takes as pairs ``pair_count + k``) stand for their members
    while their distance keeps :data:`BOUND_MARGIN` beyond the clearance: the members are then
    not computed (a member's distance is at least its bounding pair's, so the bounding pair's
    steps hold for it). Where one comes closer its members are computed from then on, and it
    is tried again when its distance could have grown back.

    `apart` (a mask of pairs, or None) marks pairs that cannot come within the clearance
    anywhere on the motion (:func:`_apart`): they are never computed, nor handed back by a
    bounding pair, which is left off where all its members are apart.
    """
    if not (tolerance > 0 and np.isfinite(tolerance)):
        raise InvalidArgumentError(f"tolerance must be a positive distance [m], got {tolerance!r}")
    c = checker.scene.clearance if clearance is None else float(clearance)
    masks = list(masks) if masks else [(0.0, checker.pair_mask())]
    n_pairs = checker.pair_count
    n_bounds = len(bounds) if bounds is not None else 0
    left_out = None
    if apart is not None and apart.any():
        left_out = np.logical_or.reduce([mask for _, mask in masks]) & apart  # for the report
        masks = [(x_from, mask & ~apart) for x_from, mask in masks]
    else:
        apart = None
    members, live, firsts, flat = _bound_members(bounds, apart)
    threshold = c + BOUND_MARGIN
    # Per pair, the x up to which it is certified, and from which it is computed with the
    # pairs due then (halfway through its last step: one more pair costs far less than one
    # more configuration); -inf: due now (as after it is switched on), inf: off the mask or
    # stood for by a bounding pair (`covered`).
    until = np.full(n_pairs + n_bounds, -np.inf)
    early = np.full(n_pairs + n_bounds, -np.inf)
    covered = np.zeros(n_pairs, dtype=bool)
    standing = np.zeros(n_bounds, dtype=bool)  # bounding pairs that stand for their members
    x, checks, k_mask = 0.0, 0, -1
    mask = masks[0][1]
    best: tuple[float, float, Clearance | None] = (np.inf, 0.0, None)
    best_pair = -1
    best_bound = (np.inf, 0.0, -1)
    first_hit: float | None = None
    hit: Clearance | None = None
    coarse = end / 2000.0  # past a hit: coarse steps, only to find the worst
    half = tolerance / 2.0
    due: np.ndarray | None = None
    q_next: np.ndarray | None = None  # the configuration at x where `native` gave it
    if native is not None:
        constants = (c, tolerance, threshold, threshold + BOUND_MARGIN)
        native.attach(n_pairs, flat, until, early, covered, standing, constants)
        best, best_pair, best_bound, first_hit, hit, checks = _native_loop(
            checker, sample, native, end, masks, tolerance, stop_at_first, c, bounds, members, firsts, live
        )
    while native is None:
        while k_mask + 1 < len(masks) and masks[k_mask + 1][0] <= x:
            k_mask += 1
            due = None
            mask = _switch_mask(masks, k_mask, firsts, live, members, until, early, covered, standing)
        if due is None:
            due = (early <= x).nonzero()[0]
        if due.size:
            q, speed = (q_next, x) if q_next is not None else sample(x)
            if n_bounds:
                d, d_bounds, due, due_bounds, x_best = _check_bounds(
                    checker, bounds, members, q, due, until, early, covered, standing, threshold, c, tolerance
                )
                if x_best is not None and x_best[0] < best_bound[0]:
                    best_bound = (x_best[0], x, x_best[1])
            elif checks == 0 or due.size == n_pairs:
                d = checker.pair_distances(q, mask)[due]
            else:
                d = checker.distances_of(q, due)
            checks += 1
            if d.size:
                i = int(d.argmin())
                dmin = float(d[i])
                if dmin < best[0]:
                    best = (dmin, x, checker.pair_clearance(int(due[i]), dmin) if dmin <= 0.0 else None)
                    best_pair = int(due[i])
                if dmin < c and first_hit is None:
                    first_hit = x
                    # The closest pair of all at this instant (not only of those due).
                    hit = checker.clearance_of(checker.pair_distances(q, mask))
                    if stop_at_first:
                        break
            if n_bounds and due_bounds.size:
                due, d = np.concatenate([due, due_bounds]), np.concatenate([d, d_bounds])
            room = d - c
            room += tolerance
            np.maximum(room, half, out=room)
            step = steps(speed, due, d, room)
            if first_hit is not None:
                step = np.maximum(step, coarse)
            until[due] = x + step
            early[due] = x + 0.5 * step
        if x >= end:
            break
        x_next = float(until.min()) if n_pairs else end
        if k_mask + 1 < len(masks):
            x_next = min(x_next, masks[k_mask + 1][0])  # a change of mask: check at the boundary
        x = min(x_next if x_next > x else float(np.nextafter(x, np.inf)), end)
        due, q_next = None, None
    if best_bound[0] < best[0]:
        # A bounding pair came closer than every pair computed: its members where it did.
        checker.place(sample(best_bound[1])[0])
        pairs = members[best_bound[2]]
        dm = checker.placed_distances(pairs)
        if float(dm.min()) < best[0]:
            best, best_pair = (float(dm.min()), best_bound[1], None), int(pairs[int(dm.argmin())])
    if best[2] is not None:
        closest = best[2]
    elif np.isfinite(best[0]):
        closest = checker.pair_clearance(best_pair, best[0])
    else:
        closest = checker.clearance_of(np.zeros(0))
    unmeasured = None
    if left_out is not None and left_out.any():
        # The left-out pairs some allowance mask checks: the one with the least floor.
        left = np.flatnonzero(left_out)
        floors = checker.floors
        assert floors is not None  # apart comes from them
        k = int(left[int(floors[left].argmin())])
        unmeasured = checker.pair_clearance(k, float(floors[k]))
    return MotionClearance(first_hit is None, closest, best[1], first_hit, hit, checks, unmeasured)


_MEMBERS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _bound_members(bounds: BoundingPairs | None, apart: np.ndarray | None) -> tuple:
    """Per bounding pair its members not `apart`, whether it has any, its first (or 0); the members flat.

    A bounding pair is on with its members (those of one share their scene body's allowance).
    The members flat: all of them one after another, and where each bounding pair's start
    (int64, for :meth:`_NativeSteps.attach`). Kept per bounding pairs and `apart` (the same for
    most motions of a checker).
    """
    if bounds is None:
        none = np.zeros(0, dtype=np.int64)
        return [], np.ones(0, dtype=bool), np.zeros(0, dtype=int), (none, np.zeros(1, dtype=np.int64))
    held = _MEMBERS.setdefault(bounds, {})
    key = b"" if apart is None else apart.tobytes()
    out = held.get(key)
    if out is None:
        members = list(bounds.members) if apart is None else [m[~apart[m]] for m in bounds.members]
        live = np.array([len(m) > 0 for m in members], dtype=bool).reshape(len(members))
        firsts = np.array([m[0] if len(m) else 0 for m in members], dtype=int).reshape(len(members))
        starts = np.zeros(len(members) + 1, dtype=np.int64)
        np.cumsum([len(m) for m in members], out=starts[1:])
        flat = np.concatenate([np.asarray(m, dtype=np.int64) for m in members]) if members else starts[:0]
        if len(held) >= 16:
            held.clear()
        out = held[key] = (members, live, firsts, (flat, starts))
    return out


def _switch_mask(
    masks: Sequence[tuple[float, np.ndarray]],
    k_mask: int,
    firsts: np.ndarray,
    live: np.ndarray,
    members: Sequence[np.ndarray],
    until: np.ndarray,
    early: np.ndarray,
    covered: np.ndarray,
    standing: np.ndarray,
) -> np.ndarray:
    """:func:`_advance`'s change to mask `k_mask`: pairs switched on due now, those off never; returns the mask."""
    was, mask = (None if k_mask == 0 else masks[k_mask - 1][1]), masks[k_mask][1]
    full = np.concatenate([mask, mask[firsts] & live])  # a bounding pair is on with its members
    on = full if was is None else full & ~np.concatenate([was, was[firsts]])
    until[on], early[on] = -np.inf, -np.inf
    until[~full], early[~full] = np.inf, np.inf
    if len(standing):
        # Bounding pairs switched on are tried at once; their members are due now too.
        standing &= full[len(covered) :]
        covered[:] = False
        for k in np.flatnonzero(standing):
            covered[members[k]] = True
    return mask


def _native_loop(
    checker: CollisionChecker,
    sample: Callable[[float], tuple[np.ndarray, object]],
    native: _NativeSteps,
    end: float,
    masks: Sequence[tuple[float, np.ndarray]],
    tolerance: float,
    stop_at_first: bool,
    c: float,
    bounds: BoundingPairs | None,
    members: Sequence[np.ndarray],
    firsts: np.ndarray,
    live: np.ndarray,
) -> tuple:
    """:func:`_advance`'s loop with `native` (attached to its state) doing the bookkeeping.

    The same checks as the loop in Python with :func:`_check_bounds`: per check the bounding
    pairs due are computed first and their standing updated (``trajectory_bounds``), then the
    pairs due; the steps, the next x and the pairs and bounding pairs due there come from one
    compiled call (``trajectory_next``) into the buffers of `native`. Returns the closest pair
    found (distance, x, Clearance or None), its index, the closest bounding pair (distance, x,
    index), the first hit, the hit and the number of checks.
    """
    n_pairs = checker.pair_count
    n_bounds = len(members)
    until, early, covered, standing = native.loop[:4]
    coarse = end / 2000.0  # past a hit: coarse steps, only to find the worst
    due_buffer, bound_buffer, out = native.due, native.due_b, native.out
    distances, bound_distances = native.distances, native.bound_distances
    head, advance, stand = native.head_at, native.next, native.bounds
    place, placed = checker.place, checker.placed_distances
    bound_placed = bounds.placed_distances if n_bounds else None
    x, checks, k_mask = 0.0, 0, -1
    mask = masks[0][1]
    switch = masks[0][0]  # where the next mask starts (inf: none)
    limit = min(switch, end)  # the compiled call's next x at most
    late = 0.0  # its least step: 0, past a hit `coarse`
    best: tuple[float, float, Clearance | None] = (np.inf, 0.0, None)
    best_pair = -1
    best_bound = (np.inf, 0.0, -1)
    first_hit: float | None = None
    hit: Clearance | None = None
    fresh = True  # the pairs due are to be found from `early` (not given by the compiled call)
    m = mb = 0  # pairs and bounding pairs due, in the buffers
    q_next: np.ndarray | None = None
    while True:
        while switch <= x:
            k_mask += 1
            fresh = True
            mask = _switch_mask(masks, k_mask, firsts, live, members, until, early, covered, standing)
            switch = masks[k_mask + 1][0] if k_mask + 1 < len(masks) else np.inf
            limit = min(switch, end)
        if fresh:
            fresh = False
            due = (early <= x).nonzero()[0]
            m = int(due.searchsorted(n_pairs))
            mb = len(due) - m
            due_buffer[:m] = due[:m]
            bound_buffer[:mb] = due[m:] - n_pairs
        if m or mb:
            q = q_next if q_next is not None else sample(x)[0]
            pairs = due_buffer[:m]
            if n_bounds:
                place(q)
                if mb:
                    bound_distances[:mb] = bound_placed(bound_buffer[:mb])
                    stand(head, mb, m)
                    _, m, _, _, _, closest, which, *_ = out.tolist()
                    m = int(m)
                    pairs = due_buffer[:m]
                    if closest < best_bound[0]:
                        best_bound = (closest, x, int(which))
                d = placed(pairs)
            elif checks == 0 or m == n_pairs:
                d = checker.pair_distances(q, mask)[pairs]
            else:
                d = checker.distances_of(q, pairs)
            checks += 1
            if m:
                dmin = float(d.min())
                if dmin < best[0]:
                    i = int(d.argmin())
                    dmin = float(d[i])  # (the same number; of zeros, the first's sign)
                    best = (dmin, x, checker.pair_clearance(int(pairs[i]), dmin) if dmin <= 0.0 else None)
                    best_pair = int(pairs[i])
                if dmin < c and first_hit is None:
                    first_hit, late = x, coarse
                    # The closest pair of all at this instant (not only of those due).
                    hit = checker.clearance_of(checker.pair_distances(q, mask))
                    if stop_at_first:
                        break
            if x >= end:
                break
            # The steps of the pairs and bounding pairs computed (those after the pairs in the
            # buffers), the next x (at most the next change of mask) and the pairs due there.
            distances[:m] = d
            advance(head, x, m + mb, late, limit)
            x, m, _, _, mb, *_ = out.tolist()
            m, mb, q_next = int(m), int(mb), native.q
            continue
        if x >= end:
            break
        x_next = float(until.min()) if n_pairs else end
        x_next = min(x_next, switch)  # a change of mask: check at the boundary
        x = min(x_next if x_next > x else float(np.nextafter(x, np.inf)), end)
        fresh, q_next = True, None
    return best, best_pair, best_bound, first_hit, hit, checks


_NONE, _NONE_DUE = np.zeros(0), np.zeros(0, dtype=int)


def _check_bounds(
    checker: CollisionChecker,
    bounds: BoundingPairs,
    members: Sequence[np.ndarray],
    q: np.ndarray,
    due: np.ndarray,
    until: np.ndarray,
    early: np.ndarray,
    covered: np.ndarray,
    standing: np.ndarray,
    threshold: float,
    c: float,
    tolerance: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[float, int] | None]:
    """One check of :func:`_advance` with bounding pairs: the bounding pairs due first, then the pairs.

    A bounding pair at least `threshold` away stands for its members (they are taken off the
    schedule); one closer hands them back (due now) and is tried again when its distance could
    have grown to `threshold` (its distance is passed on as the one that gives that room).
    `members`: per bounding pair, the member pairs it stands for (those not apart).
    Returns the pairs' distances, the bounding pairs' (as passed on), the pairs computed, the
    bounding pairs (indices past the pairs) and the closest bounding pair (distance, index).
    """
    n_pairs = len(covered)
    split = int(due.searchsorted(n_pairs))
    checker.place(q)
    if split == due.size:
        return checker.placed_distances(due), _NONE, due, _NONE_DUE, None
    due_bounds = due[split:]
    due = due[:split]
    local = due_bounds - n_pairs
    d_bounds = bounds.placed_distances(local)
    far = d_bounds >= threshold
    changed = far != standing[local]
    if True in changed.tolist():  # a handful of bounding pairs: faster than changed.any()
        for k, ok in zip(local[changed].tolist(), far[changed].tolist()):
            pairs = members[k]
            standing[k] = covered[pairs] = ok
            until[pairs] = early[pairs] = np.inf if ok else -np.inf
            if not ok:
                due = np.union1d(due, pairs)
        due = due[~covered[due]]
    i = int(d_bounds.argmin())
    closest = (float(d_bounds[i]), int(local[i]))
    if False in far.tolist():
        # Not standing: tried again when its distance could have grown a margin past the threshold.
        d_bounds = np.where(far, d_bounds, c - tolerance + (threshold + BOUND_MARGIN - d_bounds))
    return checker.placed_distances(due), d_bounds, due, due_bounds, closest


def check_segment(
    checker: CollisionChecker,
    q_start: np.ndarray,
    q_end: np.ndarray,
    *,
    allow: Sequence[str] = (),
    tolerance: float = DEFAULT_TOLERANCE,
    stop_at_first: bool = True,
    clearance: float | None = None,
) -> MotionClearance:
    """Check the straight joint-space segment from `q_start` to `q_end` (parameter 0 to 1).

    `allow` names scene bodies whose contact is allowed; `clearance` overrides the scene's.
    """
    q0, q1 = np.asarray(q_start, dtype=float), np.asarray(q_end, dtype=float)
    dq = q1 - q0
    speed = np.abs(dq)
    c = checker.scene.clearance if clearance is None else float(clearance)
    # The segment stays in the box its ends span (the floors' pairs are left out within the limits).
    apart = _apart(checker, np.minimum(q0, q1), np.maximum(q0, q1), c)
    return _advance(
        checker,
        lambda s: (q0 + s * dq, speed),
        _segment_steps(checker),
        1.0,
        [(0.0, checker.pair_mask(allow))],
        tolerance,
        stop_at_first,
        clearance,
        apart=apart,
    )


def segment_is_clear(
    checker: CollisionChecker, q_start: np.ndarray, q_end: np.ndarray, *, allow: Sequence[str] = (), margin: float = 0.0
) -> bool:
    """Whether the straight joint segment keeps the scene's clearance plus `margin` throughout.

    Points every :data:`SWEEP_RESOLUTION` are tested first (cheap collision tests with that
    distance as security margin, in bisection order): a point closer than that decides at once;
    else :func:`check_segment` certifies the whole segment.
    """
    a, b = np.asarray(q_start, dtype=float), np.asarray(q_end, dtype=float)
    need = checker.scene.clearance + margin
    near = floored(checker).closer_than(need, allow)
    d = b - a
    n = max(1, int(np.ceil(float(np.max(np.abs(d), initial=0.0)) / SWEEP_RESOLUTION)))
    if near(a) or any(map(near, a + sweep_order(n)[:, None] * d)):
        return False
    return check_segment(checker, a, b, allow=allow, clearance=need).clear


#: Largest joint change between the points :func:`segment_is_clear` tests first [rad or m].
SWEEP_RESOLUTION = 0.05

_ORDERS: dict[int, np.ndarray] = {}


def sweep_order(n: int) -> np.ndarray:
    """The points k / n, k = 1..n, the end first, then by bisection (halves, quarters, ...).

    A blocked edge is usually blocked over a stretch: bisection meets it after few checks.
    """
    out = _ORDERS.get(n)
    if out is None:
        seen, order, step = {n}, [n], n
        while step > 1:
            step = (step + 1) // 2
            for k in range(step, n, step):
                if k not in seen:
                    seen.add(k)
                    order.append(k)
        order += [k for k in range(1, n) if k not in seen]
        out = np.array(order, dtype=float) / n
        if len(_ORDERS) < 4096:
            _ORDERS[n] = out
    return out


def check_trajectory(
    checker: CollisionChecker,
    trajectory,
    *,
    allow: Sequence[tuple[float, Sequence[str]]] = (),
    tolerance: float = DEFAULT_TOLERANCE,
    stop_at_first: bool = False,
) -> MotionClearance:
    """Check a :class:`~planner.motion.trajectory.JointTrajectory` over its whole duration.

    Args:
        checker: The collision checker.
        trajectory: The trajectory; its velocity limits bound the joint speeds.
        allow: ``(t_from, names)`` in ascending time: scene names whose contact is allowed from
            each time on (e.g. around the waypoint where the gripper grasps a block).
        tolerance: See the module docstring [m].
        stop_at_first: Return at the first check below the clearance.
    """
    # The limits hold to LIMIT_TOLERANCE; the bound takes a little more.
    vmax = np.asarray(trajectory.limits.velocity) * (1.0 + 1e-6)
    duration, last = float(trajectory.duration), np.asarray(trajectory.waypoints[-1], dtype=float)
    # The trajectory's pieces, evaluated here one time at a time (JointTrajectory.sample's
    # polynomial without its checks and array bookkeeping); made at the first call (with the
    # compiled steps, which sample the trajectory themselves, only the first check's and the
    # closest bounding pair's configurations are taken from here).
    pieces: list = []
    # At 0 (the first check), piece 0 at its start: p + 0 (v + ...) is p (with -0.0 as +0.0).
    start = (
        np.asarray(trajectory.p[0], dtype=float) + 0.0 if len(trajectory.knots) and trajectory.knots[0] == 0.0 else None
    )

    def sample(t: float) -> tuple[np.ndarray, float]:
        if t >= duration:
            return last, t
        if t == 0.0 and start is not None:
            return start, t
        if not pieces:
            # Per piece its rows (a list of rows is faster to index than the arrays).
            a, j = trajectory.a, trajectory.j
            pieces.extend([np.asarray(trajectory.knots, dtype=float).tolist()])
            pieces.extend(list(x) for x in (trajectory.p, trajectory.v, a / 2.0, j / 6.0))
        knots, p, v, half_a, sixth_j = pieces
        i = max(bisect.bisect_right(knots, t) - 1, 0)
        dt = t - knots[i]
        return p[i] + dt * (v[i] + dt * (half_a[i] + dt * sixth_j[i])), t

    masks = [(0.0, checker.pair_mask())] + [(float(t), checker.pair_mask(names)) for t, names in allow]
    masks.sort(key=lambda m: m[0])
    steps = _trajectory_steps(checker, trajectory, last, vmax, max(checker.scene.clearance - tolerance, 0.0))
    apart = None
    travel = getattr(steps, "travel", None)
    if travel is not None and checker.floors is not None:
        # Joint j's position at t is within its travel from 0 to t of the start and within the
        # rest of the travel of the end: between (q_0 + q_end -+ C_j) / 2, C_j its total travel
        # (the ends' values exactly where the joint moves one way).
        mid = (np.asarray(trajectory.p[0], dtype=float) + last) / 2.0
        apart = _apart(checker, mid - travel / 2.0, mid + travel / 2.0, checker.scene.clearance)
    return _advance(
        checker,
        sample,
        steps,
        duration,
        masks,
        tolerance,
        stop_at_first,
        None,
        getattr(steps, "native", None),
        checker.bounding_pairs(),
        apart,
    )


#: Evenly spaced times per trajectory that :func:`_trajectory_steps` adds to its grid.
GRID_POINTS = 16


def _trajectory_grid(trajectory, last: np.ndarray, vmax: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times ``t`` over a trajectory between which every joint moves one way at a speed moving one way.

    See :func:`_numpy_grid`; the compiled ``trajectory_grid`` does the same arithmetic where
    it can be built.
    """
    lib = _native_library()
    if lib is None:
        return _numpy_grid(trajectory, last, vmax)
    return _native_grid(lib, trajectory, last, vmax)[:3]


def _native_grid(lib, trajectory, last: np.ndarray, vmax: np.ndarray) -> tuple:
    """:func:`_trajectory_grid` compiled: ``t, c, top``, and the block of its inputs with their addresses.

    The inputs (knots, p, v, a, j, last, vmax) serve :class:`_NativeSteps` too.
    """
    k, dof = np.shape(trajectory.p)
    # The inputs in one block and the outputs in another (an array's address costs more than
    # copying a few pieces): knots, p, v, a, j, last, vmax; then t, c, top and the count.
    inputs, at = _packed([trajectory.knots, trajectory.p, trajectory.v, trajectory.a, trajectory.j, last, vmax])
    size = k + 1 + GRID_POINTS + 4 * k * dof
    out = np.empty(size * (1 + 2 * dof) + 1)
    base = out.ctypes.data
    t, c = out[:size], out[size : size * (1 + dof)].reshape(size, dof)
    top = out[size * (1 + dof) : size * (1 + 2 * dof)].reshape(size, dof)
    count = out[-1:].view(np.int64)
    lib.trajectory_grid(
        *at[:5],
        k,
        dof,
        float(trajectory.duration),
        *at[5:7],
        GRID_POINTS,
        base,
        *(base + 8 * size * m for m in (1, 1 + dof, 1 + 2 * dof)),
    )
    g = int(count[0])
    return t[:g], c[:g], top[: max(g - 1, 0)], inputs, at


def _packed(arrays: Sequence) -> tuple[np.ndarray, list[int]]:
    """`arrays` as floats one after another in one block (each C order), and each one's address in it."""
    sizes = [np.size(x) for x in arrays]
    block = np.empty(sum(sizes))
    base, at, o = block.ctypes.data, [], 0
    for x, n in zip(arrays, sizes):
        block[o : o + n] = np.ravel(x)
        at.append(base + 8 * o)
        o += n
    return block, at


def _numpy_grid(trajectory, last: np.ndarray, vmax: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_trajectory_grid` in NumPy.

    The knots, each piece's interior extrema of position and velocity, and :data:`GRID_POINTS`
    evenly spaced times. Returns ``t`` (G,), ``C`` (G, dof): each joint's travel (total
    variation) from 0 to ``t[k]`` (``|q(t[k+1]) - q(t[k])|`` summed: exact as the joint does not
    turn back in between), and ``top`` (G - 1, dof): each joint's largest speed in each
    interval (the larger of its ends', as the speed is monotone there, plus the largest jump
    of a joint's speed from one piece to the next: rounding).
    """
    knots = np.asarray(trajectory.knots, dtype=float)
    p, v, a, j = (np.asarray(x, dtype=float) for x in (trajectory.p, trajectory.v, trajectory.a, trajectory.j))
    duration = float(trajectory.duration)
    h = np.append(np.diff(knots), duration - knots[-1])[:, None]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # Velocity extrema (a = 0), position extrema (v = 0) of each piece's cubic (and more
        # where a root is not one: a time more does no harm).
        sq = np.sqrt(np.maximum(a * a - 2.0 * j * v, 0.0))
        roots = np.concatenate([-a / j, (-a + sq) / j, (-a - sq) / j, -v / a])
    inside = (roots > 0.0) & (roots < np.tile(h, (4, 1)))
    at = np.tile(knots, 4)[:, None] + roots
    t = np.unique(np.concatenate([knots, [duration], np.linspace(0.0, duration, GRID_POINTS), at[inside]]))
    t = t[: np.searchsorted(t, duration, side="right")]
    idx = np.maximum(np.searchsorted(knots, t, side="right") - 1, 0)
    dt = (t - knots[idx])[:, None]
    vi, ai, ji = v[idx], a[idx], j[idx]
    q = p[idx] + dt * (vi + dt * (ai / 2.0 + dt * (ji / 6.0)))
    qd = np.abs(vi + dt * (ai + dt * (ji / 2.0)))
    travel = np.abs(np.diff(q, axis=0))
    if len(travel):
        # The motion ends at the last waypoint exactly (the polynomial there to rounding).
        travel[-1] += np.abs(last - q[-1])
    travel *= 1.0 + 1e-9
    c = np.zeros_like(q)
    np.cumsum(travel, axis=0, out=c[1:])
    hk = h[:-1]
    jump = np.abs(v[:-1] + hk * (a[:-1] + hk * (j[:-1] / 2.0)) - v[1:]).max(axis=0, initial=0.0)
    top = np.minimum(np.maximum(qd[:-1], qd[1:]) * (1.0 + 1e-9) + (jump + 1e-12), vmax)
    return t, c, top


_RATES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: Up to how many due pairs :func:`_trajectory_steps` computes pair by pair.
_FEW = 8
#: A pair's three rooms (its own, its own, the turn cap) as ``room * _ROOMS + _TURN`` (less a slack).
_ROOMS, _TURN = np.array([1.0, 1.0, 0.0]), np.array([0.0, 0.0, NEAR_TURN])


def _step_rates(checker: CollisionChecker, floor: float) -> tuple[np.ndarray, list[bool]]:
    """:func:`_trajectory_steps`'s weights: per pair three rows, shape (3 pairs, dof); per pair whether they differ.

    A pair's first bound, its near-body bound and its turn; a pair where the near-body bound
    cannot be the longer has its first bound in all three rows (its step with the turn's room
    is then at most the step with its own: the first bound's step holds).
    """
    held = _RATES.setdefault(checker, {})
    out = held.get(floor)
    if out is None:
        weights, near = pair_weights(checker), near_bounds(checker)
        finite = np.isfinite(near.radius)
        factor = _NEAR_GROWTH / (1.0 - _NEAR_GROWTH * NEAR_TURN)
        ball = np.where(finite, near.radius, 0.0) + floor
        turn = near.joints.astype(float)
        lever = factor * (ball[:, None] * turn + near.offsets)
        # The near-body bound can only be the longer where some joint's weight is below r_j.
        useful = (finite & np.any(near.joints & (lever < weights), axis=1))[:, None]
        rates = np.stack([weights, np.where(useful, lever, weights), np.where(useful, turn, weights)], axis=1)
        bound = np.repeat(_bound_weights(checker), 3, axis=0)
        if len(held) >= 8:
            held.clear()
        rows = np.vstack([rates.reshape(-1, weights.shape[1]), bound])
        out = held[floor] = (rows, useful[:, 0].tolist() + [False] * (len(bound) // 3))
    return out


def _native_rates(checker: CollisionChecker, floor: float, rates: np.ndarray, useful: list[bool]) -> tuple:
    """:func:`_step_rates`'s rows (C order) and flags as bytes, and their addresses (kept with them)."""
    held = _RATES.setdefault(checker, {})
    key = (floor, "native")
    out = held.get(key)
    if out is None or out[0] is not rates:
        rows, flags = np.ascontiguousarray(rates), np.asarray(useful, dtype=np.uint8)
        out = held[key] = (rates, rows, flags, (rows.ctypes.data, flags.ctypes.data))
    return out[1:]


#: How far beyond the clearance a :class:`~planner.collision.checker.BoundingPairs` hull must be
#: for its one distance to stand for its member pairs' [m].
BOUND_MARGIN = 0.05


def _bound_weights(checker: CollisionChecker) -> np.ndarray:
    """Per bounding pair of the checker, :func:`pair_weights`'s row: the largest of its members' rows.

    The members hang from the same joint and are checked against the same object: the same
    joints count for each, and each ``r_j`` bounds a convex function of the points (their
    distance from an axis or a point), largest on the hull at one of its members' points.
    """
    weights = pair_weights(checker)
    bounds = checker.bounding_pairs()
    return np.array([weights[m].max(axis=0) for m in bounds.members], dtype=float).reshape(-1, weights.shape[1])


def _trajectory_steps(
    checker: CollisionChecker, trajectory, last: np.ndarray, vmax: np.ndarray, floor: float
) -> Callable:
    """The step rule of a timed trajectory: per pair, up to where its joints' travel uses its room.

    With ``W_p(t) = sum_j r_j C_j(t)`` (``C_j`` joint ``j``'s travel from the start, ``r_j``
    from :func:`pair_weights`) a pair approaches by at most ``W_p(t) - W_p(x)`` from ``x`` to
    ``t``: its step is the longest with that at most its room ``m``. The near-body bound of the
    module docstring in the same form: with ``d <= m + floor`` (`floor` the clearance less the
    tolerance, at least 0) and ``T <= NEAR_TURN`` it holds while
    ``K ((R + floor) T + sum_j D_j Q_j) <= m``, ``K = e^NEAR_TURN / (1 - e^NEAR_TURN NEAR_TURN)``:
    weights ``K ((R + floor) [j between] + D_j)`` on the travels, and ``T`` itself (weights 1
    on the joints between) at most :data:`NEAR_TURN`. A pair takes the longer of the two steps.

    Computed on the grid of :func:`_trajectory_grid`: from the check to the next grid time
    and within the last interval from the interval's largest speeds, in between from ``W_p``
    at the grid times. `steps` takes the time of the check as its state.
    """
    rates, useful = _step_rates(checker, floor)
    lib = _native_library()
    if lib is not None:
        t, c, top, inputs, at = _native_grid(lib, trajectory, last, vmax)
    else:
        t, c, top = _numpy_grid(trajectory, last, vmax)
    g = len(t)
    if g < 2:
        return lambda x, due, d, room: np.full(len(due), np.inf)
    # Per row and grid time, flattened: W plus an offset per row that keeps the whole ascending
    # (one search for every row), per interval its largest rate and the inverse, its start
    # time and length. Every room is made smaller by `slack` (a nanometre and the offsets'
    # rounding) against rounding. The compiled path evaluates W and the rates where it
    # searches them: the tables are built only for the Python steps, when first called.
    w_end = rates @ c[-1]
    offset = float(w_end.max(initial=0.0)) + 1.0
    slack = 1e-9 + 1e-15 * (float(w_end[-1]) + (len(rates) - 1) * offset if len(rates) else 0.0)
    turn_room = _TURN - slack
    tables: list[np.ndarray] = []

    def build() -> list[np.ndarray]:
        w = rates @ c.T
        flat = (w + (np.arange(len(rates)) * offset)[:, None]).ravel()
        speed = np.zeros((len(rates), g))
        speed[:, :-1] = rates @ top.T
        inverse = (1.0 / np.maximum(speed, 1e-300)).ravel()
        start = np.tile(t, len(rates))
        width = np.tile(np.append(np.diff(t), np.inf), len(rates))
        tables.extend([flat, speed.ravel(), inverse, start, width])
        return tables

    rows = np.array([0, g, 2 * g])  # a pair's three rows, from its first entry
    per_pair = 3 * g
    times = t.tolist()
    end = times[-1]

    def row_step(a: int, room: float, x: float, ahead: float, last: int) -> float:
        """One row's step, `a` its entry at the check's interval: the same arithmetic as below."""
        flat, speed, inverse, start, width = tables
        first = speed[a] * ahead
        if room < first:
            return float(room * inverse[a])
        target = flat[a + 1] + room - first
        j = bisect.bisect_right(flat, target, a + 1, last + 1) - 1
        return float(min((target - flat[j]) * inverse[j], width[j]) + start[j] - x)

    def steps(x: float, due: np.ndarray, d: np.ndarray, room: np.ndarray) -> np.ndarray:
        if x >= end:
            return np.full(len(due), np.inf)
        flat, speed, inverse, start, width = tables or build()
        k0 = min(bisect.bisect_right(times, x) - 1, g - 2)
        if len(due) <= _FEW:
            # Pair by pair in Python: fewer calls than the whole-array operations below.
            ahead, out, cap = times[k0 + 1] - x, [], NEAR_TURN - slack
            for p, r in zip(due.tolist(), (room - slack).tolist()):
                a = p * per_pair + k0
                end_of = a + g - 1 - k0  # the row's last entry
                step = row_step(a, r, x, ahead, end_of)
                if useful[p]:
                    near = row_step(a + g, r, x, ahead, end_of + g)
                    step = max(step, min(near, row_step(a + 2 * g, cap, x, ahead, end_of + 2 * g)))
                out.append(step)
            return np.array(out)
        at = due * per_pair
        at += k0
        at = at[:, None] + rows
        rooms = room[:, None] * _ROOMS
        rooms += turn_room
        s0 = speed[at]
        first = s0 * (times[k0 + 1] - x)  # the most the row grows until the next grid time
        target = flat[at + 1]
        target += rooms
        target -= first
        j = flat.searchsorted(target, side="right")
        j -= 1
        np.minimum(j, at + (g - 1 - k0), out=j)  # the row's last entry at most
        until = target - flat[j]
        until *= inverse[j]
        np.minimum(until, width[j], out=until)
        until += start[j]
        until -= x
        # Where the room ends before the next grid time (the search's answer is then meaningless).
        until = np.where(rooms < first, rooms * inverse[at], until)
        return np.maximum(until[:, 0], np.minimum(until[:, 1], until[:, 2]))

    if lib is not None:
        ordered, flags, addresses = _native_rates(checker, floor, rates, useful)
        arrays = (c, top, t, ordered, flags)
        native = _NativeSteps(lib, arrays, addresses, g, c.shape[1], slack, len(useful), trajectory, (inputs, at))
        steps.native = native  # type: ignore[attr-defined]
    steps.travel = c[-1]  # type: ignore[attr-defined]  # each joint's total travel (from above)
    return steps


_NATIVE_SOURCE = r"""
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

static int ascending(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* _numpy_grid's times, travel c and interval speeds top (rows of dof), their number in count[0]:
   the same arithmetic. t has room for k + 1 + points + 4 k dof times, c and top as many rows. */
void trajectory_grid(const double *knots, const double *p, const double *v, const double *a, const double *j, long k,
                     long dof, double duration, const double *last, const double *vmax, long points, double *t,
                     double *c, double *top, int64_t *count) {
    long n = 0;
    for (long i = 0; i < k; ++i) t[n++] = knots[i];
    t[n++] = duration;
    double step = duration / (double)(points - 1);
    for (long i = 0; i < points; ++i) t[n++] = i == points - 1 ? duration : (double)i * step;
    for (long i = 0; i < k; ++i) {
        double h = i + 1 < k ? knots[i + 1] - knots[i] : duration - knots[i];
        for (long d = 0; d < dof; ++d) {
            double ai = a[i * dof + d], vi = v[i * dof + d], ji = j[i * dof + d];
            double disc = ai * ai - 2.0 * ji * vi;
            double sq = sqrt(disc > 0.0 ? disc : 0.0);
            double roots[4] = {-ai / ji, (-ai + sq) / ji, (-ai - sq) / ji, -vi / ai};
            for (int r = 0; r < 4; ++r)
                if (roots[r] > 0.0 && roots[r] < h) t[n++] = knots[i] + roots[r];
        }
    }
    qsort(t, n, sizeof(double), ascending);
    long g = 0;
    for (long i = 0; i < n; ++i) {
        if (t[i] > duration) break;
        if (g == 0 || t[i] != t[g - 1]) t[g++] = t[i];
    }
    for (long m = 0; m < g; ++m) {
        long lo = 0, hi = k;
        while (lo < hi) {
            long mid = lo + (hi - lo) / 2;
            if (t[m] < knots[mid]) hi = mid; else lo = mid + 1;
        }
        long i = lo - 1 > 0 ? lo - 1 : 0;
        double dt = t[m] - knots[i];
        for (long d = 0; d < dof; ++d) {
            long e = i * dof + d;
            /* q in c (turned into the travel below), |qd| in top */
            c[m * dof + d] = p[e] + dt * (v[e] + dt * (a[e] / 2.0 + dt * (j[e] / 6.0)));
            top[m * dof + d] = fabs(v[e] + dt * (a[e] + dt * (j[e] / 2.0)));
        }
    }
    for (long d = 0; d < dof; ++d) {
        double jump = 0.0;
        for (long i = 0; i + 1 < k; ++i) {
            double h = knots[i + 1] - knots[i];
            long e = i * dof + d;
            double gap = fabs(v[e] + h * (a[e] + h * (j[e] / 2.0)) - v[e + dof]);
            if (gap > jump) jump = gap;
        }
        double previous = c[d], total = 0.0;
        for (long m = 0; m + 1 < g; ++m) {
            double q = c[(m + 1) * dof + d];
            double travel = fabs(q - previous);
            if (m + 2 == g) travel += fabs(last[d] - q);
            travel *= 1.0 + 1e-9;
            previous = q;
            c[m * dof + d] = total; /* row m's travel, written after its q was read */
            total += travel;
            double fast = top[m * dof + d] > top[(m + 1) * dof + d] ? top[m * dof + d] : top[(m + 1) * dof + d];
            double bound = fast * (1.0 + 1e-9) + (jump + 1e-12);
            top[m * dof + d] = bound < vmax[d] ? bound : vmax[d];
        }
        c[(g - 1) * dof + d] = total;
    }
    count[0] = g;
}

/* Row `rate` (dof weights) times row k of a (rows, dof) matrix. */
static double dot(const double *rate, const double *m, long k, long dof) {
    double s = 0.0;
    for (long i = 0; i < dof; ++i) s += rate[i] * m[k * dof + i];
    return s;
}

/* One row's step from x in grid interval k0: row_step of _trajectory_steps, with W = rate . c
   and the interval's rate bound rate . top evaluated where they are needed. */
static double row_step(const double *rate, const double *c, const double *top, const double *t, long g, long dof,
                       long k0, double room, double x, double ahead) {
    double speed = dot(rate, top, k0, dof);
    double first = speed * ahead;
    if (room < first) return room * (1.0 / (speed > 1e-300 ? speed : 1e-300));
    double target = dot(rate, c, k0 + 1, dof) + room - first;
    long lo = k0 + 1, hi = g; /* the last grid time with W <= target, from k0 + 1 on */
    while (lo < hi) {
        long mid = lo + (hi - lo) / 2;
        if (target < dot(rate, c, mid, dof)) hi = mid; else lo = mid + 1;
    }
    long j = lo - 1;
    double rate_j = j < g - 1 ? dot(rate, top, j, dof) : 0.0;
    double width = j < g - 1 ? t[j + 1] - t[j] : INFINITY;
    double until = (target - dot(rate, c, j, dof)) * (1.0 / (rate_j > 1e-300 ? rate_j : 1e-300));
    if (width < until) until = width;
    return until + t[j] - x;
}

/* After a check at x of the n pairs `due` (distances d): each one's step (from its room
   max(d - cl + tolerance, tolerance / 2), at least `coarse`), until = x + step, early = x + step / 2;
   returns the next x (the least until, at most `bound`, past x, at most the end). `rates` holds
   three rows per pair (_step_rates), c and top the grid of _trajectory_grid at the times t. */
static double advance(const int64_t *head, double x, long n, double cl, double tolerance, double coarse,
                      double bound) {
    /* The tables and buffers (addresses) and sizes of _NativeSteps.head, in its order. */
    const double *rates = (const double *)(intptr_t)head[0], *c = (const double *)(intptr_t)head[1];
    const double *top = (const double *)(intptr_t)head[2], *t = (const double *)(intptr_t)head[3];
    const unsigned char *useful = (const unsigned char *)(intptr_t)head[4];
    long g = (long)head[5], dof = (long)head[6], npairs = (long)head[7];
    const int64_t *due = (const int64_t *)(intptr_t)head[16];
    const double *d = (const double *)(intptr_t)head[17];
    double *until = (double *)(intptr_t)head[18], *early = (double *)(intptr_t)head[19];
    const double *out = (const double *)(intptr_t)head[20];
    double slack = out[2], cap = out[3];
    double end = t[g - 1];
    long lo = 0, hi = g;
    while (lo < hi) {
        long mid = lo + (hi - lo) / 2;
        if (x < t[mid]) hi = mid; else lo = mid + 1;
    }
    long k0 = lo - 1;
    if (k0 > g - 2) k0 = g - 2;
    double ahead = t[k0 + 1] - x;
    for (long i = 0; i < n; ++i) {
        long p = due[i];
        double step;
        if (x >= end) {
            step = INFINITY;
        } else {
            double room = d[i] - cl;
            room += tolerance;
            if (room < tolerance / 2.0) room = tolerance / 2.0;
            double r = room - slack;
            const double *rate = rates + 3 * p * dof;
            step = row_step(rate, c, top, t, g, dof, k0, r, x, ahead);
            if (useful[p]) {
                double near = row_step(rate + dof, c, top, t, g, dof, k0, r, x, ahead);
                double turn = row_step(rate + 2 * dof, c, top, t, g, dof, k0, cap, x, ahead);
                double m = turn < near ? turn : near;
                if (m > step) step = m;
            }
        }
        if (step < coarse) step = coarse;
        until[p] = x + step;
        early[p] = x + 0.5 * step;
    }
    double next = end;
    if (npairs > 0) {
        next = until[0];
        for (long i = 1; i < npairs; ++i)
            if (until[i] < next) next = until[i];
    }
    if (bound < next) next = bound;
    next = next > x ? next : nextafter(x, INFINITY);
    if (end < next) next = end;
    return next;
}

/* The configuration at x (check_trajectory's sample) into the q buffer. */
static void place_q(const int64_t *head, double x) {
    const double *t = (const double *)(intptr_t)head[3];
    long g = (long)head[5], dof = (long)head[6], k = (long)head[9];
    const double *knots = (const double *)(intptr_t)head[8], *p = (const double *)(intptr_t)head[10];
    const double *v = (const double *)(intptr_t)head[11], *acc = (const double *)(intptr_t)head[12];
    const double *jerk = (const double *)(intptr_t)head[13], *last = (const double *)(intptr_t)head[14];
    double *q = (double *)(intptr_t)head[15];
    if (x >= t[g - 1]) {
        for (long i = 0; i < dof; ++i) q[i] = last[i];
        return;
    }
    long a = 0, b = k;
    while (a < b) {
        long mid = a + (b - a) / 2;
        if (x < knots[mid]) b = mid; else a = mid + 1;
    }
    long i = a - 1 > 0 ? a - 1 : 0;
    double dt = x - knots[i];
    for (long e = 0; e < dof; ++e) {
        long r = i * dof + e;
        q[e] = p[r] + dt * (v[r] + dt * (acc[r] / 2.0 + dt * (jerk[r] / 6.0)));
    }
}

/* advance, then the pairs due at the next x (early <= next x) written to `due`, their number in
   out[1], the next x in out[0] and the configuration there in q. */
void trajectory_update(const int64_t *head, double x, long n, double cl, double tolerance, double coarse,
                       double bound) {
    double next = advance(head, x, n, cl, tolerance, coarse, bound);
    long npairs = (long)head[7];
    int64_t *due = (int64_t *)(intptr_t)head[16];
    const double *early = (const double *)(intptr_t)head[19];
    double *out = (double *)(intptr_t)head[20];
    long m = 0;
    for (long i = 0; i < npairs; ++i)
        if (early[i] <= next) due[m++] = i;
    out[0] = next;
    out[1] = (double)m;
    place_q(head, next);
}

/* trajectory_update (the clearance and tolerance in out[8] and out[9]) with the pairs due apart
   from the bounding pairs (the entries from head[21] on): the pairs in `due` (their number in
   out[1]), the bounding pairs' own indices in due_b (their number in out[4]). */
void trajectory_next(const int64_t *head, double x, long n, double coarse, double bound) {
    double *out = (double *)(intptr_t)head[20];
    double next = advance(head, x, n, out[8], out[9], coarse, bound);
    long npairs = (long)head[7], split = (long)head[21];
    int64_t *due = (int64_t *)(intptr_t)head[16], *due_b = (int64_t *)(intptr_t)head[22];
    const double *early = (const double *)(intptr_t)head[19];
    long m = 0, mb = 0;
    for (long i = 0; i < npairs; ++i)
        if (early[i] <= next) {
            if (i < split) due[m++] = i; else due_b[mb++] = i - split;
        }
    out[0] = next;
    out[1] = (double)m;
    out[4] = (double)mb;
    place_q(head, next);
}

/* _check_bounds's bookkeeping after the distances db of the nb bounding pairs due_b at a check,
   with the m pairs due in `due`: a bounding pair at least `threshold` away stands for its members
   (covered, until = early = inf), one closer hands them back (until = early = -inf, due now);
   where any changed, the pairs due become those due and those handed back, less the covered,
   ascending. Their number in out[1] (and 1 in out[7] where any changed, else 0), the closest
   bounding pair's distance and index in out[5] and out[6]; after the pairs in due and d the
   bounding pairs (indices past the pairs) with the distance passed on: their own where at least
   `threshold`, else cl - tolerance + (retry - db), which gives the room up to `retry` (cl,
   tolerance, threshold and retry in out[8] to out[11]). */
void trajectory_bounds(const int64_t *head, long nb, long m) {
    long split = (long)head[21];
    int64_t *due = (int64_t *)(intptr_t)head[16];
    const int64_t *due_b = (const int64_t *)(intptr_t)head[22];
    const double *db = (const double *)(intptr_t)head[23];
    unsigned char *standing = (unsigned char *)(intptr_t)head[24], *covered = (unsigned char *)(intptr_t)head[25];
    const int64_t *members = (const int64_t *)(intptr_t)head[26], *starts = (const int64_t *)(intptr_t)head[27];
    unsigned char *mark = (unsigned char *)(intptr_t)head[28];
    double *d = (double *)(intptr_t)head[17];
    double *until = (double *)(intptr_t)head[18], *early = (double *)(intptr_t)head[19];
    double *out = (double *)(intptr_t)head[20];
    double cl = out[8], tolerance = out[9], threshold = out[10], retry = out[11];
    int changed = 0;
    long best = 0;
    for (long i = 0; i < nb; ++i) {
        long b = due_b[i];
        unsigned char far = db[i] >= threshold;
        if (db[i] < db[best]) best = i;
        if (far == standing[b]) continue;
        if (!changed) {
            changed = 1;
            for (long j = 0; j < m; ++j) mark[due[j]] = 1;
        }
        standing[b] = far;
        for (long j = starts[b]; j < starts[b + 1]; ++j) {
            long pair = members[j];
            covered[pair] = far;
            until[pair] = early[pair] = far ? INFINITY : -INFINITY;
            if (!far) mark[pair] = 1;
        }
    }
    if (changed) {
        m = 0;
        for (long pair = 0; pair < split; ++pair) {
            if (mark[pair] && !covered[pair]) due[m++] = pair;
            mark[pair] = 0;
        }
    }
    for (long i = 0; i < nb; ++i) {
        due[m + i] = split + due_b[i];
        d[m + i] = db[i] >= threshold ? db[i] : cl - tolerance + (retry - db[i]);
    }
    out[1] = (double)m;
    out[5] = nb ? db[best] : INFINITY;
    out[6] = (double)(nb ? due_b[best] : -1);
    out[7] = (double)changed;
}
"""
_P, _L, _D = ctypes.c_void_p, ctypes.c_long, ctypes.c_double
_NATIVE_SIGNATURES = {
    "trajectory_grid": [_P] * 5 + [_L, _L, _D, _P, _P, _L, _P, _P, _P, _P],
    "trajectory_update": [_P, _D, _L, _D, _D, _D, _D],
    "trajectory_next": [_P, _D, _L, _D, _D],
    "trajectory_bounds": [_P, _L, _L],
}


def _native_library():
    """The compiled :func:`_trajectory_steps` bookkeeping, or None (``PLANNER_JIT=0``, no compiler)."""
    return load_functions(_NATIVE_SOURCE, "continuous", _NATIVE_SIGNATURES)


class _NativeSteps:
    """:func:`_advance`'s step and bookkeeping after a check of a timed trajectory, in one compiled call.

    The same arithmetic as :func:`_trajectory_steps`'s steps (the pair-by-pair `row_step`) and
    :func:`_advance`'s loop; the pairs due next are written into a buffer of this object, and
    the configuration at the next x (:func:`check_trajectory`'s sample) into another.
    """

    def __init__(
        self,
        lib,
        arrays: tuple[np.ndarray, ...],
        addresses: tuple[int, int],
        g: int,
        dof: int,
        slack: float,
        n_pairs: int,
        trajectory,
        pieces: tuple[np.ndarray, list[int]],
    ) -> None:
        k = len(trajectory.knots)
        size = max(n_pairs, 1)
        # q, the distances and out (next x, pairs due; the slack, the turn cap; for the loop of
        # :meth:`attach`: bounding pairs due, the closest one's distance and index, whether the
        # pairs due changed; its clearance, tolerance, threshold and retry) in one block.
        floats = np.zeros(dof + size + 12)
        self.q, self.distances, self.out = floats[:dof], floats[dof : dof + size], floats[dof + size :]
        self.out[2:4] = slack, NEAR_TURN - slack
        self.due = np.zeros(size, dtype=np.int64)
        # The trajectory's knots, p, v, a, j and last waypoint: the grid's inputs (_native_grid).
        self.pieces, at = pieces
        # Kept alive here: C reads them through the addresses in `head`.
        self.kept = tuple(np.ascontiguousarray(a) for a in arrays)
        self.function = lib.trajectory_update
        self.size = n_pairs  # the pairs and bounding pairs it schedules
        base = floats.ctypes.data
        buffers = [base, self.due.ctypes.data, base + 8 * dof]
        kept = [addresses[0], *(a.ctypes.data for a in self.kept[:3]), addresses[1]]  # rates, c, top, t, flags
        self.head = np.array(
            [*kept, g, dof, n_pairs, at[0], k, *at[1:6], *buffers, 0, 0, base + 8 * (dof + size), *[0] * 8],
            dtype=np.int64,
        )
        self.head_at = self.head.ctypes.data
        self.arrays: tuple[np.ndarray | None, ...] = (None, None)
        self.lib = lib

    def attach(
        self,
        n_pairs: int,
        members: tuple[np.ndarray, np.ndarray],
        until: np.ndarray,
        early: np.ndarray,
        covered: np.ndarray,
        standing: np.ndarray,
        constants: tuple[float, float, float, float],
    ) -> None:
        """Give the state of :func:`_native_loop` (the arrays themselves, changed in place).

        `n_pairs` of the :attr:`size` scheduled entries are pairs, the rest bounding pairs whose
        `members` are given flat (:func:`_bound_members`); `covered` and `standing` are bool
        arrays (one byte each). `constants`: the clearance, tolerance, bounding pairs'
        threshold and retry distance [m].
        """
        self.out[8:12] = constants
        flat, starts = members
        count = len(starts) - 1
        self.due_b = np.zeros(max(count, 1), dtype=np.int64)
        self.bound_distances = np.zeros(max(count, 1))
        mark = np.zeros(max(n_pairs, 1), dtype=np.uint8)
        self.loop = (until, early, covered, standing, flat, starts, mark)  # kept alive: C reads them
        addresses = [self.due_b, self.bound_distances, standing, covered, flat, starts, mark]
        self.head[18], self.head[19] = until.ctypes.data, early.ctypes.data
        self.head[21] = n_pairs
        self.head[22:29] = [a.ctypes.data for a in addresses]
        self.arrays = (until, early)
        self.next, self.bounds = self.lib.trajectory_next, self.lib.trajectory_bounds

    def __call__(self, x, due, d, c, tolerance, coarse, until, early, bound) -> tuple[float, np.ndarray, np.ndarray]:
        n = len(due)
        buffer = self.due
        if due.base is not buffer:
            buffer[:n] = due
        self.distances[:n] = d
        if self.arrays[0] is not until or self.arrays[1] is not early:
            self.arrays = (until, early)
            self.head[18], self.head[19] = until.ctypes.data, early.ctypes.data
        self.function(self.head_at, x, n, c, tolerance, coarse, bound)
        out = self.out
        return float(out[0]), buffer[: int(out[1])], self.q
