"""Checks along a motion, not only at sample points: nothing thin is passed through.

Between two checks no pair of bodies may approach each other by more than the distance found
at the last check (conservative advancement). Per pair, the speed at which the two bodies can
approach is bounded by ``V = sum_j |qd_j| r_j``: a joint both bodies hang from moves them
together and does not count; any other joint ``j`` moves its body's points at most
``|qd_j| r_j`` apart, ``r_j`` an upper bound on the distance from the joint to that body (the
joint offsets down the chain plus the body's own extent; 1 for a sliding joint). Along a
trajectory the joint speeds a time ``h`` after a check are at most ``|qd_j| + a_j h``
(``a_j`` the acceleration limit), so a pair approaches by at most ``V h + A h^2 / 2`` with
``A = sum_j a_j r_j``; the next check comes when that reaches ``d - clearance + tolerance``
for some pair (``d`` its distance found). Along a straight joint-space segment the bound is
``sum_j |dq_j| r_j`` per unit of path. A motion that passes every check therefore keeps at
least ``clearance - tolerance`` from everything checked, at every instant.

Bounding each pair by its own joints (rather than the whole arm's speed) matters most for
links that stay close in every configuration (a compact wrist): their distance changes only
with the few joints between them.
"""

from __future__ import annotations

import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from planner.collision.arm import bounding_radius, box_corners
from planner.collision.checker import Clearance, CollisionChecker
from planner.exceptions import InvalidArgumentError

__all__ = [
    "DEFAULT_TOLERANCE",
    "MotionClearance",
    "check_motion",
    "check_segment",
    "check_trajectory",
    "pair_weights",
    "segment_is_clear",
]

#: How far below the clearance a certified motion may come [m] (sets the smallest step).
DEFAULT_TOLERANCE = 1e-4


@dataclass(frozen=True)
class MotionClearance:
    """The result of checking a motion.

    Attributes:
        clear: Whether every check kept the clearance (so, by the step bound, the whole
            motion keeps ``clearance - tolerance``).
        closest: The closest pair found, at :attr:`where`.
        where: Time [s] (or path parameter in [0, 1]) of the closest check.
        first_hit: Time (or parameter) of the first check below the clearance, or None.
        hit: The pair at :attr:`first_hit` (the bodies and the depth), or None.
        checks: Number of distance checks made.
    """

    clear: bool
    closest: Clearance
    where: float
    first_hit: float | None
    hit: Clearance | None
    checks: int

    def describe(self, unit: str = "s") -> str:
        """One line for users: clear and how close, or where it hits what."""
        if self.clear:
            return f"clear: closest {self.closest} (at {self.where:.3f} {unit}, {self.checks} checks)"
        assert self.hit is not None
        if self.hit.in_collision:
            return f"collides at {self.first_hit:.3f} {unit}: {self.hit}"
        return (
            f"comes closer than the clearance ({self.hit.clearance * 1000:.1f} mm) at {self.first_hit:.3f} {unit}: "
            f"{self.hit}"
        )


_WEIGHTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


class _ArmReach:
    """Per object of an arm's collision model, its reach from every joint (kept in ``robot.derived``)."""

    def __init__(self) -> None:
        self.arm: object | None = None
        self.table: dict[int, np.ndarray] = {}
        self.chains: list[list[int]] = []


def _axis_reach(model, obj) -> float:
    """Largest distance of a geometry object from the axis of the revolute joint carrying it [m].

    The object lies within its bounding box, whose corners (in the joint's frame) bound the
    distance from the axis (a convex function): inf for a joint that is not a plain rotation.
    """
    joint = model.joints[obj.parentJoint]
    jdata = joint.createData()
    joint.calc(jdata, np.zeros(model.nq))
    motion = np.asarray(jdata.S, dtype=float).reshape(6, -1)
    if motion.shape[1] != 1 or np.linalg.norm(motion[:3, 0]) > 1e-12:
        return float("inf")
    axis = motion[3:, 0] / np.linalg.norm(motion[3:, 0])
    points = box_corners(obj) @ obj.placement.rotation.T + obj.placement.translation
    return float(np.max(np.linalg.norm(points - np.outer(points @ axis, axis), axis=1)))


def pair_weights(checker: CollisionChecker) -> np.ndarray:
    """Per checked pair and joint, how fast the pair can approach per unit joint speed [m/rad or m/m].

    Row ``p`` holds ``r_j`` for the joints that move one body of pair ``p`` but not the other
    (see the module docstring), zero elsewhere; shape (pairs, dof). Computed once per checker.
    """
    cached = _WEIGHTS.get(checker)
    if cached is not None:
        return cached
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

    def reach_of(k: int) -> np.ndarray:
        if k not in reach:
            obj = geom.geometryObjects[k]
            chain = chain_of[obj.parentJoint]
            own = float(np.linalg.norm(obj.placement.translation)) + bounding_radius(obj)
            r = np.zeros(robot.dof)
            for jid in chain:
                # Offsets from joint jid down to the object's joint (a slide adds its travel).
                below = [j for j in chain if j > jid]
                r[jid - 1] = 1.0 if prismatic[jid - 1] else own + offset[below].sum() + travel[[jid, *below]].sum()
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
    weights.setflags(write=False)
    _WEIGHTS[checker] = weights
    return weights


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
        The :class:`MotionClearance`.
    """
    if not (tolerance > 0 and np.isfinite(tolerance)):
        raise InvalidArgumentError(f"tolerance must be a positive distance [m], got {tolerance!r}")
    c = checker.scene.clearance if clearance is None else float(clearance)
    masks = list(masks) if masks else [(0.0, checker.pair_mask())]
    # A scalar bound is the whole arm's: two links approach each other at most twice as fast.
    double = np.where(checker.self_pairs, 2.0, 1.0)
    acc = np.maximum(np.asarray(acceleration, dtype=float), 0.0)
    acc = acc * double if acc.ndim == 0 else acc
    x, checks, k_mask = 0.0, 0, 0
    best: tuple[float, float, np.ndarray] | None = None
    first_hit: float | None = None
    hit_d: np.ndarray | None = None
    while True:
        while k_mask + 1 < len(masks) and masks[k_mask + 1][0] <= x:
            k_mask += 1
        q, speed = sample(x)
        speed = np.asarray(speed, dtype=float)
        speed = np.maximum(speed * double if speed.ndim == 0 else speed, 1e-12)
        d = checker.pair_distances(q, masks[k_mask][1])
        checks += 1
        dmin = float(d.min()) if d.size else np.inf
        if best is None or dmin < best[0]:
            best = (dmin, x, d)
        if dmin < c and first_hit is None:
            first_hit, hit_d = x, d
            if stop_at_first:
                break
        if x >= end:
            break
        live = np.isfinite(d)
        if not live.any():
            step = end - x  # nothing checked here: nothing to step around
        else:
            # Per pair, the time h at which V h + A h^2 / 2 reaches the room left.
            room = np.maximum(d[live] - c + tolerance, tolerance / 2.0)
            v = speed[live] if speed.ndim else speed
            a = acc[live] if acc.ndim else acc
            step = float(np.min(2.0 * room / (v + np.sqrt(v * v + 2.0 * a * room))))
        if first_hit is not None:
            step = max(step, end / 2000.0)  # past a hit: coarse steps, only to find the worst
        # Change of mask: check at the boundary too.
        if k_mask + 1 < len(masks):
            step = min(step, masks[k_mask + 1][0] - x)
        x = min(x + step, end)
    assert best is not None
    closest = checker.clearance_of(best[2])
    hit = checker.clearance_of(hit_d) if hit_d is not None else None
    return MotionClearance(first_hit is None, closest, best[1], first_hit, hit, checks)


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
    speed = pair_weights(checker) @ np.abs(dq)
    return check_motion(
        checker,
        lambda s: (q0 + s * dq, speed),
        1.0,
        masks=[(0.0, checker.pair_mask(allow))],
        tolerance=tolerance,
        stop_at_first=stop_at_first,
        clearance=clearance,
    )


def segment_is_clear(
    checker: CollisionChecker, q_start: np.ndarray, q_end: np.ndarray, *, allow: Sequence[str] = (), margin: float = 0.0
) -> bool:
    """Whether the straight joint segment keeps the scene's clearance plus `margin` throughout."""
    return check_segment(checker, q_start, q_end, allow=allow, clearance=checker.scene.clearance + margin).clear


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
    weights = pair_weights(checker)
    # The limits hold to LIMIT_TOLERANCE; the bound takes a little more.
    acceleration = weights @ np.asarray(trajectory.limits.acceleration) * (1.0 + 1e-6)
    vmax = np.asarray(trajectory.limits.velocity) * (1.0 + 1e-6)

    def sample(t: float) -> tuple[np.ndarray, np.ndarray]:
        state = trajectory.sample(t)
        return state.q, weights @ np.minimum(np.abs(state.qd) + 1e-12, vmax)

    masks = [(0.0, checker.pair_mask())] + [(float(t), checker.pair_mask(names)) for t, names in allow]
    masks.sort(key=lambda m: m[0])
    return check_motion(
        checker,
        sample,
        trajectory.duration,
        acceleration,
        masks=masks,
        tolerance=tolerance,
        stop_at_first=stop_at_first,
    )
