"""Plans clear of singularities: detours around avoidable dips between joint waypoints.

:func:`plan_clear_of_singularities` plans through joint waypoints and, where a segment dips
below the threshold although both of its ends are clear, inserts a detour waypoint (the
configuration of the dip pushed up the gradient of the inverse condition number until it is
clear) and plans again. A waypoint that is itself singular is kept, as the user asked for it,
and flagged. For a square task Jacobian a sign change of its determinant between the ends of
a segment means every path between them crosses a singularity; such segments are reported as
unresolved instead of detoured (another IK branch is the remedy there), and so is a segment
whose deepest dip its last detour did not raise (the dip moved along the segment instead of
being passed: more detours would only push it further); no detour goes in where the sign is
the other than at an end of its segment (its path there would cross); detours that did not
clear their segment are taken out again, so they never cost time for nothing (where that leads
back to nodes and states planned before, that plan and its measure are reused, not made again).
The measure and its threshold are those of :mod:`planner.motion.singularity`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from planner.core.arrays import read_only
from planner.core.text import plain
from planner.exceptions import InvalidArgumentError
from planner.model.robot import Robot, Task
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory_request
from planner.motion.request import TrajectoryRequest
from planner.motion.singularity import SingularityReport, inverse_condition_threshold, measure_singularities
from planner.motion.trajectory import JointTrajectory

__all__ = ["Detour", "SingularityAwarePlan", "SingularityOptions", "plan_clear_of_singularities"]


@dataclass(frozen=True)
class SingularityOptions:
    """How :func:`plan_clear_of_singularities` checks and detours.

    Attributes:
        threshold: Inverse condition number below which a configuration is too close; None
            is the task's default, ``1 / DEFAULT_CONDITION_NUMBERS[task]`` of
            :mod:`planner.motion.singularity` (resolved when the robot's task is known).
        task: Task Jacobian (``"position"`` or ``"pose"``); None as the robot chooses.
        rate: Sampling rate of the checks [Hz].
        max_detours: Most waypoints to insert.
        margin: A detour waypoint is pushed to ``margin * threshold``.

    Raises:
        InvalidArgumentError: On a threshold outside [0, 1), a negative or non-integer
            ``max_detours`` or a margin below 1.
    """

    threshold: float | None = None
    task: Task | None = None
    rate: float = 1000.0
    max_detours: int = 8
    margin: float = 3.0

    def __post_init__(self) -> None:
        if self.threshold is not None:
            object.__setattr__(self, "threshold", inverse_condition_threshold(self.threshold))
        max_detours = self.max_detours
        if isinstance(max_detours, bool) or not isinstance(max_detours, int) or max_detours < 0:
            raise InvalidArgumentError(f"max_detours must be a non-negative integer, got {plain(max_detours)}")
        if not (isinstance(self.margin, (int, float)) and math.isfinite(self.margin) and self.margin >= 1.0):
            raise InvalidArgumentError(f"margin must be >= 1, got {plain(self.margin)}")


@dataclass(frozen=True)
class Detour:
    """A waypoint inserted to keep a segment clear of a singularity.

    Attributes:
        segment: Index k of the user segment (from waypoint k to k+1) it belongs to.
        q: The inserted configuration, shape (dof,) [rad or m].
        inverse_condition: Its inverse condition number.
        dip: The minimum inverse condition number of the segment piece it replaced.
    """

    segment: int
    q: np.ndarray
    inverse_condition: float
    dip: float


@dataclass(frozen=True)
class SingularityAwarePlan:
    """A trajectory through the user's waypoints plus any detours, and its singularity report.

    Attributes:
        trajectory: The planned trajectory; its waypoints include the detours.
        report: Singularity report of the trajectory (its ``singular_waypoints`` index the
            trajectory's waypoints; see :attr:`singular_waypoints` for the user's).
        waypoint_indices: Index in ``trajectory.waypoints`` of each user waypoint, shape (N,).
        detours: The inserted waypoints.
        unresolved: User segments that still dip below the threshold although both ends are
            clear (for example because the determinant changes sign between them).
    """

    trajectory: JointTrajectory
    report: SingularityReport
    waypoint_indices: np.ndarray
    detours: tuple[Detour, ...]
    unresolved: tuple[int, ...]

    @property
    def waypoint_times(self) -> np.ndarray:
        """When each user waypoint is reached, shape (N,) [s]."""
        return self.trajectory.waypoint_times[self.waypoint_indices]

    @property
    def singular_waypoints(self) -> tuple[int, ...]:
        """Indices of the user waypoints that are too close to a singularity."""
        w = self.report.waypoint_inverse_condition[self.waypoint_indices]
        return tuple(int(k) for k in np.nonzero(w < self.report.threshold)[0])


#: Steps the detour ascent takes at most, and at most after it has cleared the threshold.
ASCENT_STEPS, ASCENT_STEPS_CLEAR = 200, 30


def _ascend(
    robot: Robot, q: np.ndarray, limits: JointLimits, target: float, task: Task, clear: float = 0.0
) -> tuple[np.ndarray, float]:
    """Push q up the (finite-difference) gradient of the inverse condition number.

    Gradient steps whose length grows by 1.5 after a gain and halves after a loss, until the
    value reaches `target`, at most :data:`ASCENT_STEPS` steps and at most
    :data:`ASCENT_STEPS_CLEAR` once it is at or above `clear` (the threshold: the target's margin
    above it is a preference; on a ridge the steps zig-zag and gain a few 1e-5 each, and 200 of
    them cost some 10 ms). Each batch of measurements holds a candidate step and the
    forward-difference probes around it, as it becomes the next point when it gains: one batch
    per step instead of two, with the same values as measured one by one; after a loss the
    gradient at the unchanged point is kept.
    """
    lo = np.where(np.isfinite(limits.lower), limits.lower, -np.inf)
    hi = np.where(np.isfinite(limits.upper), limits.upper, np.inf)
    inset = 1e-3 * np.where(np.isfinite(hi - lo), hi - lo, 1.0)
    lo, hi = lo + inset, hi - inset
    h = 1e-5
    joints = np.arange(len(q))

    def measure_with_probes(point: np.ndarray) -> tuple[float, np.ndarray]:
        # Forward differences, one joint a row (a probe steps back where a step forward
        # would leave the limits), measured together with the point itself: the inverse
        # condition numbers as Robot.conditioning computes them (the same SVD and ratio).
        rows = np.tile(point, (len(point) + 1, 1))
        rows[joints + 1, joints] += np.where(point + h <= hi, h, -h)
        scaled = robot.task_jacobians(rows, task)[1]
        s = np.linalg.svd(scaled, compute_uv=False)[:, : min(scaled.shape[1:])]
        values = np.divide(s[:, -1], s[:, 0], out=np.zeros(len(s)), where=s[:, 0] != 0.0)
        return float(values[0]), (values[1:] - values[0]) / (rows[joints + 1, joints] - point)

    x = np.minimum(np.maximum(q, lo), hi)
    f, grad = measure_with_probes(x)
    step = 0.05
    since_clear = 0
    for _ in range(ASCENT_STEPS):
        if f >= target or since_clear >= ASCENT_STEPS_CLEAR:
            break
        since_clear += f >= clear
        norm = math.sqrt(float(grad @ grad))
        if norm == 0.0 or not math.isfinite(norm):
            break
        cand = np.minimum(np.maximum(x + step * grad / norm, lo), hi)
        fc, grad_c = measure_with_probes(cand)
        if fc > f:
            x, f, grad = cand, fc, grad_c
            step = min(step * 1.5, 0.5)
        else:
            step *= 0.5
            if step < 1e-6:
                break
    return x, f


def _det_sign(robot: Robot, q: np.ndarray, task: Task) -> float:
    jac = robot.jacobian(q)
    jac = jac[:3] if task == "position" else jac
    return float(np.sign(np.linalg.det(jac))) if jac.shape[0] == jac.shape[1] else 0.0


def must_cross_singularity(robot: Robot, a: np.ndarray, b: np.ndarray, task: Task | None = None) -> bool:
    """Whether every continuous joint path from `a` to `b` passes a singular configuration.

    True where the task Jacobian is square and its determinant has opposite signs at the two
    ends (it is continuous along any path, so it is zero somewhere between): e.g. a UR5 wrist
    flip (the wrist's middle joint changing sign). No detour can keep such a move above any
    threshold, so :func:`plan_clear_of_singularities` does not try (pass the segments of a
    multi-segment move between such ends as ``keep_segments``).

    Args:
        robot: The robot.
        a: Joint configuration at one end [rad or m].
        b: Joint configuration at the other end.
        task: ``"position"`` or ``"pose"``; None is the robot's default task.
    """
    t_task = robot.resolve_task(task)
    return _det_sign(robot, a, t_task) * _det_sign(robot, b, t_task) < 0


def dipping_segments(
    trajectory: JointTrajectory,
    report: SingularityReport,
    t: np.ndarray,
    inverse_condition: np.ndarray,
    owners: Sequence[int],
) -> set[int]:
    """The segments whose samples dip below the threshold although both their ends are above it.

    Args:
        trajectory: The measured trajectory.
        report: Its singularity report (threshold and inverse condition at each waypoint).
        t: The measure's sample times [s].
        inverse_condition: The inverse condition number at each of them.
        owners: For each of the trajectory's waypoint segments, the segment it belongs to (a
            detour splits a segment in two; both halves belong to it).

    Returns:
        The owners of the waypoint segments that dip.
    """
    return {int(owners[s]) for _, s, _ in _segment_dips(trajectory, report, t, inverse_condition, len(owners))}


def _segment_dips(
    trajectory: JointTrajectory, report: SingularityReport, t: np.ndarray, inverse_condition: np.ndarray, count: int
) -> list[tuple[float, int, int]]:
    """Of the first `count` waypoint segments, those whose ends are clear but whose samples dip below the threshold.

    Returns:
        Per such segment: its lowest sampled value, the segment, and the index of that sample
        (the first, where several are lowest).
    """
    w_inv = report.waypoint_inverse_condition
    wt = trajectory.waypoint_times
    thr = report.threshold
    found = []
    for s in range(count):
        if w_inv[s] < thr or w_inv[s + 1] < thr:
            continue
        mask = (t >= wt[s]) & (t <= wt[s + 1])
        if not mask.any():
            continue
        k = int(np.argmin(np.where(mask, inverse_condition, np.inf)))
        if inverse_condition[k] < thr:
            found.append((float(inverse_condition[k]), s, k))
    return found


def _timed_for(timed: object, request: TrajectoryRequest) -> bool:
    """Whether `timed` passes `request`'s waypoints with its dwells and start state, within its limits."""
    if not isinstance(timed, JointTrajectory):
        return False
    lim, own = timed.limits, request.limits
    return (
        np.array_equal(timed.waypoints, request.waypoints)
        and np.array_equal(timed.dwell, request.dwell)
        and np.array_equal(timed.via_velocities[0], request.start_velocity)
        and np.array_equal(timed.via_accelerations[0], request.start_acceleration)
        and (
            lim is own
            or all(
                np.array_equal(getattr(lim, f), getattr(own, f))
                for f in ("velocity", "acceleration", "jerk", "lower", "upper")
            )
        )
    )


def plan_clear_of_singularities(
    robot: Robot,
    request: TrajectoryRequest,
    options: SingularityOptions | None = None,
    *,
    keep_segments: Sequence[int] = (),
    timed: JointTrajectory | None = None,
) -> SingularityAwarePlan:
    """Plan a trajectory request, detouring around singularities a segment would pass.

    Args:
        robot: The robot.
        request: The trajectory to plan (waypoints, limits, start state, stops, dwell, strategy,
            prescribed via states); its stops, dwell and prescribed states refer to its own
            waypoints, and stay with them when detours are inserted.
        options: Threshold, task, sampling rate, detour count and margin; None is the defaults.
        keep_segments: Segments of the request (k: from waypoint k to k+1) that must not get
            detours, e.g. samples of a straight Cartesian line.
        timed: The request's own trajectory (``plan_trajectory_request(request)``), where the
            caller has made it already (to check it for collisions before it is measured): used
            instead of planning it again. The plan is the same.

    Returns:
        The plan with its report, detours and unresolved segments.

    Raises:
        InvalidArgumentError: If the request is for another number of joints, on a start
            state the planner cannot brake from, or if `timed` is not a trajectory through
            the request's waypoints with its dwells and start state within its limits.
    """
    opts = SingularityOptions() if options is None else options
    t_task = robot.resolve_task(opts.task)
    thr = inverse_condition_threshold(opts.threshold, t_task)
    rate, max_detours, margin = opts.rate, opts.max_detours, opts.margin
    limits = request.limits
    if limits.dof != robot.dof:
        raise InvalidArgumentError(f"the limits are for {limits.dof} joints; {robot.name} has {robot.dof}")
    user = request.waypoints
    n = len(user)
    if timed is not None and not _timed_for(timed, request):
        raise InvalidArgumentError(
            "timed must be the JointTrajectory planned from the request (its waypoints, dwells, start state and limits)"
        )
    # Per augmented waypoint: prescribed (velocity, acceleration), and the minimum duration of
    # the segment that starts there (detours split a segment and drop its minimum).
    states: list[tuple[np.ndarray, np.ndarray, float]] = [
        (
            request.via_velocities[k],
            request.via_accelerations[k],
            float(request.min_durations[k]) if k < n - 1 else 0.0,
        )
        for k in range(n)
    ]
    # Each augmented waypoint: (q, user index or None, user segment it lies in).
    nodes: list[tuple[np.ndarray, int | None, int]] = [(user[k], k, min(k, n - 2)) for k in range(n)]
    detours: list[Detour] = []
    given_up: set[int] = {int(k) for k in keep_segments}
    replaced: dict[int, float] = {}  # per segment, the dip its last detour replaced

    def plan_nodes() -> JointTrajectory:
        if len(nodes) == n:
            # No detour: the request's own nodes and states (a user segment whole again has its
            # minimum duration back), already validated.
            return timed if timed is not None else plan_trajectory_request(request)
        q = np.array([nd[0] for nd in nodes])
        user_pos = [i for i, nd in enumerate(nodes) if nd[1] is not None]
        d = np.zeros(len(nodes))
        d[user_pos] = request.dwell
        return plan_trajectory_request(
            replace(
                request,
                waypoints=q,
                stops=[user_pos[s] for s in request.stops],
                dwell=d,
                via_velocities=np.array([st_[0] for st_ in states]),
                via_accelerations=np.array([st_[1] for st_ in states]),
                min_durations=np.array([st_[2] for st_ in states[:-1]]),
            )
        )

    # Plans and their measures by their nodes and states: taking out detours that cleared
    # nothing often leads back to a plan made before (the first one, when none is kept).
    planned: dict[bytes, tuple[JointTrajectory, SingularityReport, np.ndarray, np.ndarray]] = {}

    def plan_and_measure() -> tuple[JointTrajectory, SingularityReport, np.ndarray, np.ndarray]:
        key = b"".join(
            [np.array([nd[0] for nd in nodes]).tobytes(), bytes(nd[1] is not None for nd in nodes)]
            + [np.concatenate([st_[0], st_[1], [st_[2]]]).tobytes() for st_ in states]
        )
        if key not in planned:
            traj = plan_nodes()
            report, t, _, inv = measure_singularities(robot, traj, thr, t_task, rate)
            planned[key] = traj, report, t, inv
        return planned[key]

    while True:
        traj, report, t, inv = plan_and_measure()
        found = None  # the dips of this plan's segments, once looked for
        if len(detours) >= max_detours:
            break
        found = _segment_dips(traj, report, t, inv, len(nodes) - 1)
        dips = [d for d in found if nodes[d[1]][2] not in given_up]
        # A segment whose deepest dip its last detour did not raise is given up: the dip moved
        # along instead of being passed (its detours are taken out below).
        for seg, before in replaced.items():
            if min((dip for dip, s, _ in dips if nodes[s][2] == seg), default=math.inf) <= before:
                given_up.add(seg)
        dips = [d for d in dips if nodes[d[1]][2] not in given_up]
        inserted = False
        for dip, s, k in sorted(dips):
            seg = nodes[s][2]
            signs = _det_sign(robot, nodes[s][0], t_task), _det_sign(robot, nodes[s + 1][0], t_task)
            if signs[0] * signs[1] < 0:
                given_up.add(seg)
                continue
            q_new, f_new = _ascend(robot, traj.positions(t[k]), limits, margin * thr, t_task, thr)
            # A detour on the other side of a singularity from either end does not clear the
            # segment either: its path there must cross the singularity (the determinant changes
            # sign), so the segment still dips and the detour would only be taken out again.
            sign = _det_sign(robot, q_new, t_task)
            if f_new < thr or sign * signs[0] < 0 or sign * signs[1] < 0:
                given_up.add(seg)
                continue
            nodes.insert(s + 1, (q_new, None, seg))
            states[s] = (states[s][0], states[s][1], 0.0)
            states.insert(s + 1, (np.full(robot.dof, np.nan), np.zeros(robot.dof), 0.0))
            detours.append(Detour(segment=seg, q=read_only(q_new), inverse_condition=f_new, dip=dip))
            replaced[seg] = dip
            inserted = True
            break
        if not inserted:
            break

    def unresolved_segments() -> set[int]:
        return dipping_segments(traj, report, t, inv, [nd[2] for nd in nodes[:-1]])

    # Where no detour went in, the plan's dips are known: the segments they lie in are unresolved.
    still = {nodes[s][2] for _, s, _ in found} if found is not None else unresolved_segments()
    # Detours that did not clear their segment only cost time: take them out again. Planning
    # again changes the via states, so a neighbour's path may dip anew: repeat until none does.
    useless = [i for i, nd in enumerate(nodes) if nd[1] is None and nd[2] in still]
    while useless:
        for i in reversed(useless):
            del nodes[i]
            del states[i]
        for i, (_, k, _) in enumerate(nodes[:-1]):  # a user segment whole again gets its minimum back
            if k is not None and nodes[i + 1][1] == k + 1:
                states[i] = (states[i][0], states[i][1], float(request.min_durations[k]))
        detours = [d for d in detours if d.segment not in still]
        traj, report, t, inv = plan_and_measure()
        still = unresolved_segments()
        useless = [i for i, nd in enumerate(nodes) if nd[1] is None and nd[2] in still]
    user_idx = np.array([i for i, nd in enumerate(nodes) if nd[1] is not None])
    user_idx.setflags(write=False)
    return SingularityAwarePlan(
        trajectory=traj,
        report=report,
        waypoint_indices=user_idx,
        detours=tuple(detours),
        unresolved=tuple(sorted(still)),
    )
