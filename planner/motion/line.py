"""Straight Cartesian lines sampled into continuous joint paths.

:func:`line_waypoints` follows a straight line between two targets: it samples the line
(position linearly; approach pitch linearly; orientation by spherical interpolation,
:func:`interpolate_target`), solves IK at every sample seeded by (closed form: nearest to) the
previous one, and bisects wherever a joint would jump more than a step bound, so the joint
path is continuous. Where a position line so tracked drives a joint into a range end (a
corner of the joint path, where the arm stops), the free approach pitch of a yaw-planar arm is
chosen instead, linear along the line, if that keeps the joints off their range ends.
:func:`line_deviation` measures how far a sampled tip strays from the line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from planner.core.arrays import read_only
from planner.exceptions import InvalidArgumentError
from planner.geometry.target import Target, approach_pitch
from planner.model.robot import Robot
from planner.motion.branch_choice import TargetSolver

#: End pitches tried for a position line's free angle (a grid over the turn), line samples
#: checked for a solution before a pitch line is followed, and pitch lines followed at most.
_PITCH_GRID = 24
_PROBES = 9
_MAX_TRIES = 3

__all__ = [
    "LinePath",
    "continues_line",
    "interpolate_target",
    "line_deviation",
    "line_waypoints",
    "on_range_end",
    "slerp",
]


def slerp(rotation_a: np.ndarray, rotation_b: np.ndarray, s: float) -> np.ndarray:
    """Rotation a fraction s of the way from `rotation_a` to `rotation_b` (about their relative axis).

    ``R_a exp(s log(R_a^T R_b))`` with Pinocchio's ``log3``/``exp3``: exact at s = 1 and
    accurate for relative angles near 0 and near half a turn (where an ``acos`` of the trace
    loses digits).

    Args:
        rotation_a: Shape (3, 3).
        rotation_b: Shape (3, 3).
        s: Fraction in [0, 1].

    Returns:
        Shape (3, 3).
    """
    return rotation_a @ pin.exp3(s * pin.log3(rotation_a.T @ rotation_b))


def interpolate_target(a: Target, b: Target, s: float) -> Target:
    """The target a fraction s in [0, 1] of the way along the straight line from a to b."""
    pos = (1.0 - s) * a.position + s * b.position
    if b.rotation is not None:
        if a.rotation is None:
            raise InvalidArgumentError("a line to a target with an orientation must start at one with an orientation")
        return Target(pos, rotation=slerp(a.rotation, b.rotation, s))
    if b.pitch is not None:
        if a.pitch is None:
            raise InvalidArgumentError("a line to a target with an approach pitch must start at one with a pitch")
        return Target(pos, pitch=(1.0 - s) * a.pitch + s * b.pitch)
    return Target(pos)


def continues_line(a: Target, b: Target, c: Target, tolerance: float = 1e-9) -> bool:
    """Whether the line from b to c goes straight on from the line from a to b.

    Straight on: the same direction (within `tolerance` [rad]) and the same change of the
    orientation or approach pitch per metre (within `tolerance` [rad/m]), so that the tip's
    motion along the two lines is one line traced at one rate: IK follows it without a kink at b.

    Args:
        a: Where the first line starts.
        b: Where it ends and the second one starts.
        c: Where the second line ends.
        tolerance: Largest difference of the directions [rad] and the rates [rad/m].

    Returns:
        True if both lines have a length and the second one continues the first.
    """
    d1, d2 = b.position - a.position, c.position - b.position
    l1, l2 = float(np.linalg.norm(d1)), float(np.linalg.norm(d2))
    if not (l1 > 0.0 and l2 > 0.0):
        return False
    u1, u2 = d1 / l1, d2 / l2
    if float(np.linalg.norm(np.cross(u1, u2))) > tolerance or float(u1 @ u2) <= 0.0:
        return False
    kinds = [(t.rotation is None, t.pitch is None) for t in (a, b, c)]
    if kinds[0] != kinds[1] or kinds[1] != kinds[2]:
        return False
    if b.rotation is not None:
        w1, w2 = pin.log3(a.rotation.T @ b.rotation) / l1, pin.log3(b.rotation.T @ c.rotation) / l2
        return float(np.linalg.norm(w1 - w2)) <= tolerance
    if b.pitch is not None:
        return abs((b.pitch - a.pitch) / l1 - (c.pitch - b.pitch) / l2) <= tolerance
    return True


@dataclass(frozen=True)
class LinePath:
    """Joint configurations along a straight Cartesian line.

    Attributes:
        s: Fractions of the way along the line, shape (M,), 0 first and 1 last.
        q: Joint values at each, shape (M, dof) [rad or m].
        points: Tip positions asked for, shape (M, 3) [m].
        max_position_error: Largest FK distance of the samples to their points [m].
        min_inverse_condition: Smallest inverse condition number among the samples.
    """

    s: np.ndarray
    q: np.ndarray
    points: np.ndarray
    max_position_error: float
    min_inverse_condition: float


def line_waypoints(
    solver: TargetSolver,
    start: Target,
    end: Target,
    q_start: np.ndarray,
    *,
    max_step: float = 0.005,
    max_joint_step: float = 0.02,
    min_step: float = 1e-5,
    free_pitch: bool = True,
) -> LinePath:
    """Sample a straight line from `start` to `end` into a continuous joint path.

    Args:
        solver: IK for the robot.
        start: Target at the start of the line (its configuration is `q_start`).
        end: Target at its end.
        q_start: Joint values at the start, shape (dof,).
        max_step: Longest line step between samples [m].
        max_joint_step: Largest joint change between neighbouring samples [rad or m]; longer
            steps are bisected.
        min_step: Shortest line step bisection goes down to [m].
        free_pitch: Whether a position line may take the linear approach pitch (above); False
            tracks it (a line going straight on into or from another one, whose joint paths
            must meet without a kink).

    A position line (no orientation, no pitch) on an arm with a closed form whose tracked path
    has a joint arrive at or leave a range end inside the line is sampled again with the
    approach pitch going linearly along it (start configuration's pitch to an end pitch with a
    solution), and that path is taken if it has fewer such corners and no larger joint step.

    Returns:
        The joint path (the last configuration solves `end`).

    Raises:
        InvalidArgumentError: If IK fails somewhere on the line or the joint path cannot be made
            continuous (the line leaves the workspace or crosses a branch boundary).
    """
    for name, val in (("max_step", max_step), ("max_joint_step", max_joint_step), ("min_step", min_step)):
        if not (isinstance(val, (int, float)) and math.isfinite(val) and val > 0):
            raise InvalidArgumentError(f"{name} must be positive, got {val!r}")
    steps = (max_step, max_joint_step, min_step)
    path = _track_line(solver, start, end, q_start, *steps)
    if free_pitch and all(t.rotation is None and t.pitch is None for t in (start, end)):
        return _smooth_free_pitch(solver, start, end, q_start, path, steps)
    return path


def _track_line(
    solver: TargetSolver,
    start: Target,
    end: Target,
    q_start: np.ndarray,
    max_step: float,
    max_joint_step: float,
    min_step: float,
) -> LinePath:
    """:func:`line_waypoints` by tracking: each sample's solution nearest the previous one."""
    length = float(np.linalg.norm(end.position - start.position))
    n0 = max(1, int(math.ceil(length / max_step)))
    q0 = np.asarray(q_start, dtype=float)
    s_list, q_list = [0.0], [q0]

    def solve_at(s: float, q_prev: np.ndarray) -> np.ndarray:
        q = solver.track(interpolate_target(start, end, s), q_prev)
        if q is None:
            p = (1.0 - s) * start.position + s * end.position
            a, b, near = (np.round(x, 6).tolist() for x in (start.position, end.position, p))
            raise InvalidArgumentError(
                f"the straight line from {a} to {b} m leaves what {solver.robot.name} can reach "
                f"within its joint limits near {near} m"
            )
        return q

    for k in range(1, n0 + 1):
        s_target = k / n0
        stack = [s_target]
        while stack:
            s_next = stack[-1]
            q_next = solve_at(s_next, q_list[-1])
            if (
                float(np.max(np.abs(q_next - q_list[-1]))) > max_joint_step
                and (s_next - s_list[-1]) * length > min_step
            ):
                stack.append((s_list[-1] + s_next) / 2.0)
                continue
            s_list.append(s_next)
            q_list.append(q_next)
            stack.pop()
    s_list, q_list = _bracket_range_ends(solve_at, s_list, q_list, solver.robot, min_step / max(length, 1e-300))
    q = np.array(q_list)
    s = np.array(s_list)
    points = (1.0 - s)[:, None] * start.position + s[:, None] * end.position
    err = float(np.max(np.linalg.norm(solver.robot.position(q) - points, axis=1)))
    jumps = np.max(np.abs(np.diff(q, axis=0)), axis=1)
    if np.any(jumps > 10 * max_joint_step):
        k = int(np.argmax(jumps))
        raise InvalidArgumentError(
            f"the straight line to {np.round(end.position, 6).tolist()} m needs a jump of {jumps[k]:.3g} rad in the "
            f"joints near {np.round(points[k], 6).tolist()} m (a branch change at a singularity); split the line there"
        )
    inv = solver.robot.conditioning(q, solver.task)[0]
    return LinePath(read_only(s), read_only(q), read_only(points), err, float(np.min(inv)))


def _range_end_changes(robot: Robot, q: np.ndarray) -> int:
    """How many inner samples of a joint path (M, dof) a joint arrives at or leaves a range end at (corners)."""
    ends = on_range_end(robot, q)
    change = ends[1:] != ends[:-1]  # between samples k and k + 1
    at = set(np.nonzero(np.any(change & ends[1:], axis=1))[0] + 1) | set(
        np.nonzero(np.any(change & ends[:-1], axis=1))[0]
    )
    return sum(1 for k in at if 0 < k < len(q) - 1)


def _smooth_free_pitch(
    solver: TargetSolver, start: Target, end: Target, q_start: np.ndarray, tracked: LinePath, steps: tuple
) -> LinePath:
    """A position line whose free approach pitch changes linearly, where that avoids range ends.

    Tracking a position line keeps the free end angle of a yaw-planar arm (al5c, three_joint)
    near the previous sample's, which can drive a joint into a range end, where the joint path
    turns a corner (the arm stops there). This tries the same line with the approach pitch
    going linearly from the start configuration's to an end pitch (the nearest to the tracked
    end's first, among those with a solution at a few samples of the line). A pitch target
    leaves the arm no free angle, so a joint at a range end would mean no solution there. The
    first such line with fewer range-end corners and no larger joint step replaces the tracked
    one; otherwise the tracked line stays. One whose joint reaches a range end at the line's
    end, moving into it, is taken only if none of the tries ends off it: a line ending so
    cannot blend into the move after it (that move could not keep the line's end velocity
    inside the range).
    """
    robot = solver.robot
    corners = _range_end_changes(robot, tracked.q)
    if corners == 0 or solver.method != "analytic":
        return tracked
    p0 = float(approach_pitch(robot, q_start))
    p_end = float(approach_pitch(robot, tracked.q[-1]))
    grid = [p_end, p0, *np.linspace(-math.pi, math.pi, _PITCH_GRID, endpoint=False)]
    ends = sorted({p0 + math.remainder(p - p0, 2.0 * math.pi) for p in grid}, key=lambda p: abs(p - p_end))
    probes = np.linspace(0.0, 1.0, _PROBES)
    step = float(np.max(np.abs(np.diff(tracked.q, axis=0)))) if len(tracked.q) > 1 else 0.0
    bound = max(step, steps[1])
    tries, found = 0, None
    for p1 in ends:
        a, b = Target(start.position, pitch=p0), Target(end.position, pitch=p1)
        if not all(solver.candidates(interpolate_target(a, b, float(s)), None)[0] for s in probes[1:]):
            continue
        tries += 1
        try:
            path = _track_line(solver, a, b, q_start, *steps)
        except InvalidArgumentError:
            path = None
        if path is not None:
            jumps = np.max(np.abs(np.diff(path.q, axis=0)), axis=1)
            if (
                _range_end_changes(robot, path.q) < corners
                and float(np.max(jumps)) <= bound
                and path.max_position_error <= max(tracked.max_position_error, 1e-6)
            ):
                if not _arrives_at_range_end(robot, path.q):
                    return path
                found = found or path
        if tries >= _MAX_TRIES:
            break
    return found or tracked


def _arrives_at_range_end(robot: Robot, q: np.ndarray) -> bool:
    """Whether a joint of the path q (M, dof) reaches a range end only at its last sample."""
    ends = on_range_end(robot, q[-2:])
    return len(q) > 1 and bool(np.any(ends[-1] & ~ends[0]))


def on_range_end(robot: Robot, q: np.ndarray) -> np.ndarray:
    """Which joints of configurations q (..., dof) sit at a range end (within 1e-9 relative), bool."""
    lower, upper = np.asarray(robot.lower, dtype=float), np.asarray(robot.upper, dtype=float)
    near = [1e-9 * np.maximum(1.0, np.abs(np.nan_to_num(b))) for b in (lower, upper)]
    return (q <= lower + near[0]) | (q >= upper - near[1])


def _bracket_range_ends(solve_at, s_list: list, q_list: list, robot: Robot, ds: float) -> tuple[list, list]:
    """Samples added where a joint reaches or leaves a range end, within `ds` of where it does.

    There IK turns the joint path a corner (the joint stays at its end, the others take over):
    bisection finds it within `ds` (a fraction of the line), and the sample at the range end
    there is added, so that the motion can stop at the corner instead of at two samples a
    whole step apart.
    """
    ends = on_range_end(robot, np.array(q_list))
    s_out, q_out = [s_list[0]], [q_list[0]]
    for k in range(1, len(s_list)):
        if np.array_equal(ends[k - 1], ends[k]):
            s_out.append(s_list[k])
            q_out.append(q_list[k])
            continue
        lo, q_lo, hi, q_hi = s_list[k - 1], q_list[k - 1], s_list[k], q_list[k]
        while hi - lo > ds:
            mid = (lo + hi) / 2.0
            q_mid = solve_at(mid, q_lo)
            if np.array_equal(on_range_end(robot, q_mid), ends[k - 1]):
                lo, q_lo = mid, q_mid
            else:
                hi, q_hi = mid, q_mid
        # The sample at the range end nearest the corner (the other side is at most `ds` off).
        s_new, q_new = (hi, q_hi) if np.any(on_range_end(robot, q_hi) & ~ends[k - 1]) else (lo, q_lo)
        if min(abs(s_new - s_list[k - 1]), abs(s_list[k] - s_new)) > ds:
            s_out.append(s_new)
            q_out.append(q_new)
        if s_list[k] != s_out[-1]:
            s_out.append(s_list[k])
            q_out.append(q_list[k])
    return s_out, q_out


def line_deviation(robot: Robot, q: np.ndarray, start: np.ndarray, end: np.ndarray) -> float:
    """Largest distance of the tip positions of configurations q (M, dof) from the segment start-end [m]."""
    p = robot.position(q)
    d = np.asarray(end, dtype=float) - np.asarray(start, dtype=float)
    length2 = float(d @ d)
    if length2 == 0.0:
        return float(np.max(np.linalg.norm(p - start, axis=1)))
    s = np.clip((p - start) @ d / length2, 0.0, 1.0)
    return float(np.max(np.linalg.norm(p - (start + s[:, None] * d), axis=1)))
