"""Checks along a motion, not only at sample points: nothing thin is passed through.

Between two checks no point of the arm may move farther than the distance found at the last
check (conservative advancement). A point of the arm moves at most
``sum_j |qd_j| * reach_j`` (:attr:`ArmCollisionModel.reach`: the farthest any geometry a joint
moves lies from that joint; 1 for a sliding joint). Along a trajectory the joint speeds a time
``h`` after a check are at most ``|qd_j| + a_j h`` (``a_j`` the acceleration limit), so the
arm's surface moves at most ``V h + A h^2 / 2`` with ``V = sum_j |qd_j| reach_j`` and
``A = sum_j a_j reach_j``; the next check comes when that reaches ``d - clearance + tolerance``
(``d`` the distance found). Along a straight joint-space segment the bound is the segment's
length-weighted ``sum_j |dq_j| reach_j`` per unit of path. Two links approach each other at most
twice as fast. A motion that passes every
check therefore keeps at least ``clearance - tolerance`` from everything checked, at every
instant.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from planner.collision.checker import Clearance, CollisionChecker
from planner.exceptions import InvalidArgumentError

__all__ = [
    "DEFAULT_TOLERANCE",
    "MotionClearance",
    "check_motion",
    "check_segment",
    "check_trajectory",
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


def _joint_factors(checker: CollisionChecker) -> np.ndarray:
    reach = np.asarray(checker.arm.reach, dtype=float)
    return np.where(np.array(checker.robot.joint_kinds) == "prismatic", 1.0, reach)


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
        sample: Returns the configuration at x and ``V``, the speed of the arm's surface there
            [m per unit x] (an upper bound).
        end: Last x.
        acceleration: ``A``: the surface speed ``h`` later is at most ``V + A h``.
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
    self_pairs = checker.self_pairs
    scene_pairs = ~self_pairs
    has_self, has_scene = bool(self_pairs.any()), bool(scene_pairs.any())
    x, checks, k_mask = 0.0, 0, 0
    best: tuple[float, float, np.ndarray] | None = None
    first_hit: float | None = None
    hit_d: np.ndarray | None = None
    acc = max(float(acceleration), 0.0)
    while True:
        while k_mask + 1 < len(masks) and masks[k_mask + 1][0] <= x:
            k_mask += 1
        q, speed = sample(x)
        speed = max(float(speed), 1e-12)
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
        d_scene = d[scene_pairs].min() if has_scene else np.inf
        d_self = d[self_pairs].min() if has_self else np.inf
        room = min(d_scene - c + tolerance, (d_self - c + tolerance) / 2.0)
        room = max(room, tolerance / 2.0)
        # The time h at which V h + A h^2 / 2 reaches the room left.
        if not np.isfinite(room):
            step = end - x  # nothing checked here: nothing to step around
        elif acc == 0.0:
            step = room / speed
        else:
            step = 2.0 * room / (speed + np.sqrt(speed * speed + 2.0 * acc * room))
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
    speed = float(np.sum(np.abs(dq) * _joint_factors(checker)))
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
    factors = _joint_factors(checker)
    # The limits hold to LIMIT_TOLERANCE; the bound takes a little more.
    acceleration = float(np.sum(np.asarray(trajectory.limits.acceleration) * factors)) * (1.0 + 1e-6)
    vmax = np.asarray(trajectory.limits.velocity) * (1.0 + 1e-6)

    def sample(t: float) -> tuple[np.ndarray, float]:
        state = trajectory.sample(t)
        return state.q, float(np.sum(np.minimum(np.abs(state.qd) + 1e-12, vmax) * factors))

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
