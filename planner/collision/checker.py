"""Distances between the arm, itself and a scene, for one configuration or many.

:class:`CollisionChecker` joins the arm's collision model (:mod:`planner.collision.arm`) with a
:class:`~planner.collision.scene.Scene` in one Pinocchio ``GeometryModel`` and answers, per
configuration, the smallest distance between any checked pair and which two bodies it is
between (negative: penetration depth). The floor is a coal half-space; geometry that stands
on it whatever the joints do (a base column turning about a vertical axis) is not checked
against it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from planner.collision.arm import arm_collision_model, hull_points
from planner.collision.scene import FLOOR, Box, Cylinder, Obstacle, Scene, Sphere
from planner.exceptions import InvalidArgumentError
from planner.model.robot import Robot

__all__ = ["BoundingPairs", "Clearance", "CollisionChecker", "shared_checker"]

_FLOAT = np.dtype(float)
_update, _distance = pin.updateGeometryPlacements, pin.computeDistance


@dataclass(frozen=True)
class Clearance:
    """The closest pair of bodies in one configuration.

    Attributes:
        distance: Their distance [m]; negative when they overlap (minus the penetration
            depth); ``inf`` when nothing is checked.
        bodies: The two bodies' names (links, obstacles or ``"floor"``), or ``("", "")``.
        clearance: The clearance the scene asks for [m].
    """

    distance: float
    bodies: tuple[str, str]
    clearance: float = 0.0

    @property
    def in_collision(self) -> bool:
        """Whether the two bodies touch or overlap."""
        return self.distance <= 0.0

    @property
    def clear(self) -> bool:
        """Whether the distance keeps the scene's clearance."""
        return self.distance >= self.clearance

    def __str__(self) -> str:
        if not np.isfinite(self.distance):
            return "nothing to hit"
        a, b = self.bodies
        if self.distance <= 0:
            return f"{a} and {b} overlap by {-self.distance * 1000:.1f} mm"
        return f"{a} and {b} are {self.distance * 1000:.1f} mm apart"


def _coal_shape(obstacle: Obstacle) -> coal.CollisionGeometry:
    shape = obstacle.shape
    if isinstance(shape, Box):
        return coal.Box(*shape.size)
    if isinstance(shape, Sphere):
        return coal.Sphere(shape.radius)
    if isinstance(shape, Cylinder):
        return coal.Cylinder(shape.radius, shape.length)
    raise InvalidArgumentError(f"obstacle {obstacle.name!r}: unknown shape {type(shape).__name__}")


class CollisionChecker:
    """The arm against itself and a scene.

    Args:
        robot: The robot.
        scene: What to avoid; None (or an empty scene) checks only the arm against itself.
        self_collision: Check the arm's links against each other.

    Attributes:
        robot: The robot.
        scene: The scene.
        names: Per geometry object, the body it belongs to (a link, an obstacle, ``"floor"``).
    """

    def __init__(self, robot: Robot, scene: Scene | None = None, *, self_collision: bool = True) -> None:
        if scene is not None and not isinstance(scene, Scene):
            raise InvalidArgumentError(f"scene must be a planner Scene or None, got {type(scene).__name__}")
        self.robot = robot
        self.scene = scene or Scene()
        arm = arm_collision_model(robot)
        self.arm = arm
        geom = pin.GeometryModel()
        for obj in arm.geometry.geometryObjects:
            geom.addGeometryObject(obj)
        names = list(arm.link_of)
        n_arm = len(names)
        scene_ids: dict[str, int] = {}
        if self.scene.floor is not None:
            floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), self.scene.floor)
            scene_ids[FLOOR] = geom.addGeometryObject(pin.GeometryObject(FLOOR, 0, 0, pin.SE3.Identity(), floor))
            names.append(FLOOR)
        for obstacle in self.scene.obstacles:
            placement = pin.SE3(np.asarray(obstacle.rotation), np.asarray(obstacle.position))
            obj = pin.GeometryObject(obstacle.name, 0, 0, placement, _coal_shape(obstacle))
            scene_ids[obstacle.name] = geom.addGeometryObject(obj)
            names.append(obstacle.name)
        pairs: list[tuple[int, int]] = list(arm.self_pairs) if self_collision else []
        self._pair_scene: list[str | None] = [None] * len(pairs)
        fixed = set()
        if FLOOR in scene_ids:
            fixed = {a for a, low in arm.fixed_lowest.items() if low - self.scene.floor < self.scene.clearance}
        for name, sid in scene_ids.items():
            for a in range(n_arm):
                if arm.part_of[a] != a:
                    continue  # a piece: the scene is checked against the whole element
                if arm.geometry.geometryObjects[a].parentJoint == 0:
                    continue  # fixed to the base: it cannot move into anything
                if name == FLOOR and a in fixed:
                    continue  # stands on the floor: turns about a vertical axis only
                pairs.append((a, sid))
                self._pair_scene.append(name)
        for a, b in pairs:
            geom.addCollisionPair(pin.CollisionPair(a, b))
        self.geometry = geom
        self.names = tuple(names)
        self._pairs = np.array(pairs, dtype=int).reshape(-1, 2)
        self._self = np.array([s is None for s in self._pair_scene], dtype=bool)
        self._data = robot.model.createData()
        self._to_pinocchio = robot.pinocchio_configuration
        self._gdata = pin.GeometryData(geom)
        # in_collision runs the exact test only on pairs whose world AABBs overlap; it reads this
        # GeometryData's active pairs, so allow masks hold. With a few dozen objects coal's naive
        # manager (every AABB pair) is faster than its AABB trees (measured: about 1.5x).
        self._broadphase = pin.BroadPhaseManager_NaiveCollisionManager(robot.model, geom, self._gdata)
        for request in self._gdata.collisionRequests:
            # GJK starts from the pair's last separating direction (links keep their relative
            # poses roughly): 6 to 30 % faster on ur5 and panda; a verdict does not depend on it.
            request.gjk_initial_guess = coal.GJKInitialGuess.CachedGuess
        self._guessed = False  # whether in_collision has run since the guesses were last forgotten
        self._active: dict[tuple[str, ...], np.ndarray] = {}
        self._active_now: np.ndarray | None = None
        self._everything = self._mask(())
        self._near: dict[tuple, _CloserThan] = {}
        self._bounding: BoundingPairs | None = None
        self._floors: np.ndarray | None = None

    def forget_guesses(self) -> None:
        """Start GJK from its default direction again (as a new checker does).

        :meth:`in_collision` starts each pair's GJK from the direction of its last call; a
        checker used again for a new request forgets them, so that its answers do not depend
        on what it checked before (the distances never use them). Only :meth:`in_collision`
        leaves guesses: a checker it has not run on since has none to forget.
        """
        if not self._guessed:
            return
        self._guessed = False
        fresh = coal.CollisionRequest()
        guess, support = fresh.cached_gjk_guess, fresh.cached_support_func_guess
        for request in self._gdata.collisionRequests:
            request.cached_gjk_guess = guess
            request.cached_support_func_guess = support

    def __repr__(self) -> str:
        return (
            f"CollisionChecker({self.robot.name!r}, {len(self.arm.self_pairs)} self pairs, "
            f"scene {', '.join(self.scene.names) or 'empty'})"
        )

    @property
    def pair_count(self) -> int:
        """Number of pairs checked."""
        return len(self._pairs)

    def _mask(self, allow: Sequence[str]) -> np.ndarray:
        key = tuple(sorted(set(allow)))
        mask = self._active.get(key)
        if mask is None:
            self.scene.check_names(key)
            mask = np.array([s is None or s not in key for s in self._pair_scene], dtype=bool)
            self._active[key] = mask
        return mask

    def _checked(self, q: Sequence[float] | np.ndarray) -> np.ndarray:
        """`q` checked as one configuration; a float vector of the right size that is finite passes as is."""
        if type(q) is np.ndarray and q.dtype is _FLOAT and q.shape == (self.robot.dof,) and math.isfinite(q @ q):
            return q  # q @ q is finite only if every entry is (an overflow takes the full check)
        return self.robot.check_configuration(q, batch=False)

    def _set_active(self, mask: np.ndarray) -> None:
        if mask is self._active_now:
            return  # masks are cached per allow set: the same object is the same pairs
        for k, on in enumerate(mask):
            self._gdata.activeCollisionPairs[k] = bool(on)
        self._active_now = mask

    def clearance(self, q: Sequence[float] | np.ndarray, *, allow: Iterable[str] = ()) -> Clearance:
        """The closest pair of bodies at configuration `q`.

        Args:
            q: Joint values, shape (dof,) [rad or m].
            allow: Scene names whose contact is allowed (e.g. the object the gripper grasps).

        Returns:
            The :class:`Clearance`.
        """
        return self._clearance(
            self._checked(q), self._everything if type(allow) is tuple and not allow else self._mask(_allowed(allow))
        )

    def pair_distances(self, q: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """Distance [m] of every pair at `q` (unchecked), ``inf`` for pairs off `mask`."""
        if not mask.any():
            return np.full(len(self._pairs), np.inf)
        self._set_active(mask)
        pin.computeDistances(
            self.robot.model, self._data, self.geometry, self._gdata, self.robot.pinocchio_configuration(q)
        )
        d = np.fromiter((r.min_distance for r in self._gdata.distanceResults), float, len(self._pairs))
        return np.where(mask, d, np.inf)

    def distances_of(self, q: np.ndarray, pairs: np.ndarray) -> np.ndarray:
        """Distance [m] of the pairs with indices `pairs` at `q` (unchecked; masks do not apply).

        Only those pairs are computed (after the arm's placements at `q`): cheaper than
        :meth:`pair_distances` when few pairs are wanted.
        """
        self.place(q)
        return self.placed_distances(pairs)

    def place(self, q: np.ndarray) -> None:
        """Place the arm's objects at `q` (unchecked) for :meth:`placed_distances` and :meth:`bounding_pairs`."""
        _update(self.robot.model, self._data, self.geometry, self._gdata, self._to_pinocchio(q))

    def placed_distances(self, pairs: np.ndarray) -> np.ndarray:
        """Distance [m] of the pairs with indices `pairs` at the configuration last placed (:meth:`place`)."""
        geom, gdata = self.geometry, self._gdata
        return np.array([_distance(geom, gdata, k).min_distance for k in pairs.tolist()], dtype=float)

    def bounding_pairs(self) -> BoundingPairs:
        """The :class:`BoundingPairs` of this checker (built once)."""
        if self._bounding is None:
            self._bounding = BoundingPairs(self)
        return self._bounding

    def pair_clearance(self, k: int, distance: float) -> Clearance:
        """The :class:`Clearance` of pair `k` at `distance` [m] found at the last configuration computed.

        An overlap gets its penetration depth (from the placements of that configuration).
        """
        if distance <= 0.0:
            distance = self._depth(k, distance)
        a, b = (int(i) for i in self._pairs[k])
        return Clearance(float(distance), (self.names[a], self.names[b]), self.scene.clearance)

    @property
    def self_pairs(self) -> np.ndarray:
        """Per pair, whether it is between two of the arm's links (else arm and scene)."""
        return self._self

    def clearance_of(self, d: np.ndarray) -> Clearance:
        """The closest pair of a :meth:`pair_distances` vector, with the depth of an overlap."""
        if d.size == 0:
            return Clearance(float("inf"), ("", ""), self.scene.clearance)
        k = int(np.argmin(d))
        dist = float(d[k])
        if not np.isfinite(dist):
            return Clearance(float("inf"), ("", ""), self.scene.clearance)
        if dist <= 0.0:
            dist = self._depth(k, dist)
        a, b = (int(i) for i in self._pairs[k])
        return Clearance(dist, (self.names[a], self.names[b]), self.scene.clearance)

    def _clearance(self, q: np.ndarray, mask: np.ndarray) -> Clearance:
        if mask is not self._active_now:  # a mask without pairs is never made active
            if not mask.any():
                return Clearance(float("inf"), ("", ""), self.scene.clearance)
            self._set_active(mask)
        # Pinocchio returns the index of the active pair at the smallest distance: only that
        # one result is read back (not one Python object per pair).
        k = pin.computeDistances(
            self.robot.model, self._data, self.geometry, self._gdata, self.robot.pinocchio_configuration(q)
        )
        dist = float(self._gdata.distanceResults[k].min_distance)
        if dist <= 0.0:
            dist = self._depth(k, dist)
        a, b = (int(i) for i in self._pairs[k])
        return Clearance(dist, (self.names[a], self.names[b]), self.scene.clearance)

    def _depth(self, k: int, dist: float) -> float:
        """The penetration depth of pair `k` (coal's distance is 0 or a signed estimate when overlapping)."""
        request = coal.CollisionRequest()
        request.enable_contact = True
        request.num_max_contacts = 1
        result = coal.CollisionResult()
        a, b = (int(i) for i in self._pairs[k])
        oa, ob = self.geometry.geometryObjects[a], self.geometry.geometryObjects[b]
        pa = coal.Transform3s(self._gdata.oMg[a].rotation, self._gdata.oMg[a].translation)
        pb = coal.Transform3s(self._gdata.oMg[b].rotation, self._gdata.oMg[b].translation)
        coal.collide(oa.geometry, pa, ob.geometry, pb, request, result)
        if result.isCollision() and result.numContacts():
            return -abs(float(result.getContact(0).penetration_depth))
        return min(dist, 0.0)

    def clearances(self, qs: np.ndarray, *, allow: Iterable[str] = ()) -> list[Clearance]:
        """:meth:`clearance` for each row of `qs`, shape (n, dof)."""
        qs = self.robot.check_configuration(qs)
        mask = self._mask(_allowed(allow))
        return [self._clearance(q, mask) for q in np.atleast_2d(qs)]

    def in_collision(self, q: Sequence[float] | np.ndarray, *, allow: Iterable[str] = ()) -> bool:
        """Whether any checked pair touches or overlaps at `q` (faster than a distance)."""
        q = self._checked(q)
        mask = self._everything if type(allow) is tuple and not allow else self._mask(_allowed(allow))
        if mask is not self._active_now:  # a mask without pairs is never made active
            if not mask.any():
                return False
            self._set_active(mask)
        self._guessed = True
        return pin.computeCollisions(
            self.robot.model, self._data, self._broadphase, self.robot.pinocchio_configuration(q), True
        )

    def distance_at(self, q: np.ndarray, mask: np.ndarray | None = None) -> Clearance:
        """:meth:`clearance` without checking `q` (for inner loops); `mask` from :meth:`pair_mask`."""
        return self._clearance(q, self._everything if mask is None else mask)

    def closer_than(self, distance: float, allow: Iterable[str] = ()) -> Callable[[np.ndarray], bool]:
        """A test of configurations: whether any pair checked (`allow` allowed) is closer than `distance` [m].

        Coal's collision test with `distance` as its security margin: several times faster
        than computing the distances, with the same verdict. The test takes `q` unchecked (for
        inner loops); one is kept per distance and allow set. Pairs whose floor
        (:meth:`use_floors`) is beyond `distance` are left out: they cannot be closer.
        """
        if isinstance(distance, bool) or not isinstance(distance, (int, float, np.integer, np.floating)):
            raise InvalidArgumentError(f"distance must be a number [m], got {distance!r}")
        if not math.isfinite(distance):
            raise InvalidArgumentError(f"distance must be a finite number [m], got {distance!r}")
        names = _allowed(allow)
        mask = self._mask(names)
        key = (float(distance), tuple(sorted(set(names))))
        test = self._near.get(key)
        if test is None:
            if len(self._near) >= 32:
                self._near.clear()
            if self._floors is not None:
                mask = mask & ~(self._floors > float(distance))
            test = self._near[key] = _CloserThan(self, mask, float(distance))
        return test

    @property
    def floors(self) -> np.ndarray | None:
        """Per pair, a distance [m] it never comes below (see :meth:`use_floors`), or None."""
        return self._floors

    def use_floors(self, floors: np.ndarray) -> None:
        """Give per pair a distance [m] it never comes below in any configuration within the joint limits.

        From :func:`~planner.collision.continuous.pair_floors` (``-inf`` where none is known).
        :meth:`closer_than`'s tests then leave out each pair whose floor is beyond their
        distance: the same verdicts, fewer pairs tested (links that always keep apart, such as
        two wrist links with one joint between them).
        """
        try:
            floors = np.array(floors, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InvalidArgumentError(f"floors must be {len(self._pairs)} distances [m], got {floors!r}") from exc
        if floors.shape != (len(self._pairs),) or np.isnan(floors).any():
            raise InvalidArgumentError(f"floors must be {len(self._pairs)} distances [m], got shape {floors.shape}")
        floors.setflags(write=False)
        self._floors = floors
        self._near.clear()

    def pair_mask(self, allow: Iterable[str] = ()) -> np.ndarray:
        """The pairs checked when `allow` is allowed, for :meth:`distance_at`."""
        return self._mask(_allowed(allow))


def _allowed(allow: Iterable[str]) -> tuple[str, ...]:
    """`allow` as a tuple of names; a single string or a non-iterable is refused (not read letter by letter)."""
    if type(allow) is tuple and all(type(name) is str for name in allow):
        return allow
    if isinstance(allow, (str, bytes)) or not isinstance(allow, Iterable):
        raise InvalidArgumentError(f"allow must be a list of scene names, got {allow!r}")
    names = tuple(allow)
    bad = [name for name in names if not isinstance(name, str)]
    if bad:
        raise InvalidArgumentError(f"allow must be a list of scene names, got {bad[0]!r} among them")
    return names


#: Fewest objects on one joint for :class:`BoundingPairs` to bound them together (measured: with
#: two, the hull's longer reach costs more checks than it saves distances).
MIN_MEMBERS = 3


def _exact_points(obj: pin.GeometryObject) -> bool:
    """Whether :func:`~planner.collision.arm.hull_points` are the object's own corners (a polytope or a box).

    Of other shapes they are a bounding box's corners: a hull of those is far larger than the
    shapes (and distances to capsules and spheres are cheap anyway).
    """
    g = obj.geometry
    return isinstance(g, coal.Box) or (isinstance(g, coal.Convex) and g.getSweptSphereRadius() == 0.0)


class BoundingPairs:
    """Pairs whose one distance bounds several checked pairs' distances from below.

    Per joint that carries :data:`MIN_MEMBERS` or more of the arm's objects, each a polytope
    or a box, the convex hull of them all (of their :func:`~planner.collision.arm.hull_points`,
    so it contains each), paired with each object that every one of them is checked against:
    the hull's distance to it is at most each member pair's. One distance instead of several
    where the hull is far from the object (a hand and its fingers far from a box).

    Attributes:
        members: Per bounding pair, the indices of the checker's pairs it bounds.
        objects: Per bounding pair, the checker's object its hull is checked against.
    """

    def __init__(self, checker: CollisionChecker) -> None:
        self.checker = checker
        geometry = checker.geometry
        objects = list(geometry.geometryObjects)
        n_arm = len(checker.arm.link_of)
        by_joint: dict[int, list[int]] = {}
        for k in range(n_arm):
            joint = objects[k].parentJoint
            if joint > 0 and checker.arm.part_of[k] == k:  # elements, not their pieces
                by_joint.setdefault(joint, []).append(k)
        index = {(int(a), int(b)): k for k, (a, b) in enumerate(checker._pairs)}
        index.update({(b, a): k for (a, b), k in list(index.items())})
        model = pin.GeometryModel()
        for obj in objects:
            model.addGeometryObject(obj)
        self.members: list[np.ndarray] = []
        self.objects: list[int] = []
        for joint, group in by_joint.items():
            if len(group) < MIN_MEMBERS or not all(_exact_points(objects[m]) for m in group):
                continue
            others = [o for o in range(len(objects)) if all((m, o) in index for m in group)]
            if not others:
                continue
            points = np.vstack(
                [
                    hull_points(objects[m]) @ objects[m].placement.rotation.T + objects[m].placement.translation
                    for m in group
                ]
            )
            vertices = coal.StdVec_Vec3s()
            for p in points:
                vertices.append(p)
            hull = coal.Convex.convexHull(vertices, True, "Qt")
            hid = model.addGeometryObject(pin.GeometryObject(f"hull_{joint}", joint, 0, pin.SE3.Identity(), hull))
            for o in others:
                model.addCollisionPair(pin.CollisionPair(hid, o))
                self.members.append(np.array([index[(m, o)] for m in group], dtype=int))
                self.objects.append(o)
        self.geometry = model
        self._gdata = pin.GeometryData(model)

    def __len__(self) -> int:
        return len(self.members)

    def placed_distances(self, pairs: np.ndarray) -> np.ndarray:
        """Distance [m] of the bounding pairs `pairs` at the configuration the checker last placed."""
        checker, geom, gdata = self.checker, self.geometry, self._gdata
        pin.updateGeometryPlacements(checker.robot.model, checker._data, geom, gdata)
        return np.array([_distance(geom, gdata, k).min_distance for k in pairs.tolist()], dtype=float)


class _CloserThan:
    """:meth:`CollisionChecker.closer_than`'s test: its own geometry data with the margin set.

    Through a broad phase like :meth:`CollisionChecker.in_collision`: Pinocchio grows each
    object's bounding box by half the largest security margin of its pairs, so every pair
    closer than the margin still reaches the exact test.
    """

    def __init__(self, checker: CollisionChecker, mask: np.ndarray, distance: float) -> None:
        robot = checker.robot
        self.model, self.data = robot.model, robot.model.createData()
        self.gdata = pin.GeometryData(checker.geometry)
        for k, on in enumerate(mask):
            self.gdata.activeCollisionPairs[k] = bool(on)
        for request in self.gdata.collisionRequests:
            request.security_margin = distance
            request.enable_contact = False  # a verdict only: no contact points or depths
        self.broadphase = pin.BroadPhaseManager_NaiveCollisionManager(robot.model, checker.geometry, self.gdata)
        self.to_pinocchio = robot.pinocchio_configuration
        self.any = bool(np.any(mask))
        # For inner loops of float vectors (the path search's): the same test as one call of
        # Pinocchio's, the vector as it is where Pinocchio's configuration is the joint vector.
        model, data, manager, compute, keep = self.model, self.data, self.broadphase, pin.computeCollisions, self
        if not self.any:

            def floats(q: np.ndarray) -> bool:
                return False

        elif model.nq == robot.dof:

            def floats(q: np.ndarray, _keep=keep) -> bool:
                return compute(model, data, manager, q, True)

        else:
            to_pinocchio = self.to_pinocchio

            def floats(q: np.ndarray, _keep=keep) -> bool:
                return compute(model, data, manager, to_pinocchio(q), True)

        self.floats = floats

    def __call__(self, q: np.ndarray) -> bool:
        if not self.any:
            return False
        return bool(pin.computeCollisions(self.model, self.data, self.broadphase, self.to_pinocchio(q), True))


class _SharedCheckers:
    """Per robot, the checkers :func:`shared_checker` has built, by scene (in ``robot.derived``)."""

    def __init__(self) -> None:
        self.items: dict[tuple, CollisionChecker] = {}


def _scene_key(scene: Scene) -> tuple:
    bodies = tuple(
        (o.name, repr(o.shape), np.asarray(o.position, dtype=float).tobytes(), np.asarray(o.rotation).tobytes())
        for o in scene.obstacles
    )
    return (scene.floor, scene.clearance, bodies)


def shared_checker(robot: Robot, scene: Scene | None) -> CollisionChecker:
    """A :class:`CollisionChecker` of `robot` and `scene`, built once per robot and equal scene.

    Planning many requests in the same scene (as a user does) then builds the checker and its
    tables once. The checker is handed out with its GJK guesses forgotten
    (:meth:`CollisionChecker.forget_guesses`): its answers are those of a new checker. Not for
    two threads at once (as the robot itself).

    Args:
        robot: The robot.
        scene: The scene (None: the arm against itself).

    Returns:
        The checker (with self-collision).
    """
    if scene is not None and not isinstance(scene, Scene):
        raise InvalidArgumentError(f"scene must be a planner Scene or None, got {type(scene).__name__}")
    scene = scene or Scene()
    held = robot.derived.get(_SharedCheckers, _SharedCheckers)
    key = _scene_key(scene)
    checker = held.items.get(key)
    if checker is None or checker.arm is not arm_collision_model(robot):
        if len(held.items) >= 8:
            held.items.clear()
        checker = held.items[key] = CollisionChecker(robot, scene)
    else:
        checker.forget_guesses()
    return checker
