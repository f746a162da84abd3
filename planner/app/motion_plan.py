"""Planning a :class:`~planner.app.plan_file.MotionRequest` for a robot into a :class:`MotionPlan`.

:func:`plan_motion` meets the request with the robot: units to SI, IK for Cartesian targets
(one branch per target, dense samples along straight-line segments), one trajectory through
everything with detours around singularities, and the servo calibrations. The files a plan
writes are in :mod:`planner.app.outputs`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from planner.app.outputs import write_plan_files
from planner.app.plan_file import MotionRequest
from planner.collision.checker import CollisionChecker, shared_checker
from planner.collision.continuous import (
    MotionClearance,
    check_segment,
    check_trajectory,
    floored,
    segment_is_clear,
)
from planner.collision.rrt import PathResult, certify_path, ends_margin, find_clear_path, segment_looks_clear
from planner.collision.scene import Scene
from planner.core.arrays import read_only
from planner.core.files import input_error, parse_number
from planner.exceptions import PlanningError
from planner.export.calibration import ServoCalibration
from planner.export.calibration_file import ControllerSetup, controller_setup
from planner.export.formats import ServoFormat
from planner.model.robot import Robot
from planner.motion.avoid import joint_line, time_joint_line
from planner.motion.detours import (
    Detour,
    SingularityAwarePlan,
    SingularityOptions,
    dipping_segments,
    must_cross_singularity,
    plan_clear_of_singularities,
)
from planner.motion.limits import JointLimits
from planner.motion.line import LinePath
from planner.motion.line_smoothing import line_end_states, smooth_lines
from planner.motion.plan import plan_trajectory_request
from planner.motion.request import TrajectoryRequest
from planner.motion.singularity import SingularityReport, inverse_condition_threshold, measure_singularities
from planner.motion.trajectory import JointTrajectory

__all__ = ["MotionPlan", "plan_motion"]


@dataclass(frozen=True)
class MotionPlan:
    """The result of :func:`plan_motion`.

    Attributes:
        robot: Robot name.
        trajectory: The joint trajectory (through the waypoints, line samples and detours).
        singularity: Singularity report of the trajectory.
        waypoints: The joint configuration of each requested waypoint, shape (N, dof).
        waypoint_times: When each is reached, shape (N,) [s].
        departure_times: When the arm leaves each, after its dwell, shape (N,) [s].
        branches: Per waypoint, the IK branch taken (None for joint waypoints).
        labels: Per waypoint, its label in the plan file, or None.
        singular_waypoints: Indices of requested waypoints below the singularity threshold.
        detours: Waypoints inserted around singularities.
        unresolved: Requested segments still dipping below the threshold with clear ends.
        line_deviation: Per requested segment, the largest distance of the tip from the
            straight line [m] for line segments, else None.
        limits: The limits planned with.
        collision: With a scene, the continuous check of the trajectory (clear, or where it
            first comes too close, between which bodies and how deep); None without a scene.
        routes: Requested segments planned around obstacles (along a clear joint route).
        scene: The scene planned in (SI), or None.
        calibrations: Servo calibration per joint (pulse widths, or position ticks for a
            Feetech bus or a stepper controller).
        servo_period_ms: Time between two servo updates in the servo files [ms].
        setup: The controller and calibrations the servo files are written for (None: the
            default pulse-width files).
    """

    robot: str
    trajectory: JointTrajectory
    singularity: SingularityReport
    waypoints: np.ndarray
    waypoint_times: np.ndarray
    departure_times: np.ndarray
    branches: tuple[str | None, ...]
    labels: tuple[str | None, ...]
    singular_waypoints: tuple[int, ...]
    detours: tuple[Detour, ...]
    unresolved: tuple[int, ...]
    line_deviation: tuple[float | None, ...]
    limits: JointLimits
    collision: MotionClearance | None
    routes: tuple[int, ...]
    scene: Scene | None
    calibrations: tuple
    servo_period_ms: int
    setup: ControllerSetup | None = None

    def summary(self, rate: float = 1000.0) -> dict[str, Any]:
        """A JSON-ready summary; the ratios are sampled peaks over the limits at `rate` [Hz]."""
        peaks = self.trajectory.peak_ratios(rate)
        return {
            "robot": self.robot,
            "joints": list(self.limits.joint_names),
            "duration": self.trajectory.duration,
            "waypoint_times": self.waypoint_times.tolist(),
            "departure_times": self.departure_times.tolist(),
            "max_velocity_ratio": peaks["velocity"],
            "max_acceleration_ratio": peaks["acceleration"],
            "max_jerk_ratio": peaks["jerk"],
            "max_position_excess": max(peaks["position"], 0.0),
            "min_manipulability": self.singularity.min_manipulability,
            "min_inverse_condition": self.singularity.min_inverse_condition,
            "condition_number_threshold": 1.0 / self.singularity.threshold,
            "singular_waypoints": list(self.singular_waypoints),
            "waypoints": self.waypoints.tolist(),
            "branches": list(self.branches),
            "labels": list(self.labels),
            "detours": [
                {"segment": d.segment, "q": d.q.tolist(), "inverse_condition": d.inverse_condition}
                for d in self.detours
            ],
            "unresolved_segments": list(self.unresolved),
            "line_deviation": list(self.line_deviation),
            "jerk_sign_changes": [
                self.trajectory.jerk_sign_changes(a, b, rate).tolist()
                for a, b in zip(self.departure_times[:-1], self.waypoint_times[1:])
            ],
            "strategy": self.trajectory.strategy,
            "controller": None if self.setup is None else self.setup.controller,
            "sample_rate": rate,
            **(
                {}
                if self.collision is None
                else {"collision": _collision_summary(self.collision), "routes": list(self.routes)}
            ),
        }

    @property
    def collision_free(self) -> bool | None:
        """Whether the trajectory keeps the scene's clearance throughout (None without a scene)."""
        return None if self.collision is None else self.collision.clear

    def write_files(
        self,
        out: str | Path,
        rate: float = 1000.0,
        extra_files: Sequence[Path] = (),
        formats: Sequence[ServoFormat] | None = None,
    ) -> tuple[Path, ...]:
        """Write the plan's files into a directory (see :func:`planner.app.outputs.write_plan_files`).

        Args:
            out: Output directory.
            rate: Sample rate of the CSV and of the summary's limit checks [Hz].
            extra_files: Files already written for the plan (its plots), listed in the summary.
            formats: The servo formats to write; None writes the plan's controller's (see `setup`).

        Returns:
            The paths written.

        Raises:
            InvalidArgumentError: If the directory cannot be created.
            ServoExportError: If a servo file cannot be made (the other files are written).
        """
        if formats is None and self.setup is not None:
            formats = self.setup.formats()
        summary = self.summary(rate)
        return write_plan_files(
            out,
            self.trajectory,
            self.calibrations,
            self.servo_period_ms,
            summary,
            rate=rate,
            extra_files=extra_files,
            formats=formats,
        )


def _collision_summary(c: MotionClearance) -> dict[str, Any]:
    # Nothing to hit (an arm without checked self pairs and an empty scene): no distance, JSON null.
    distance = c.closest.distance if math.isfinite(c.closest.distance) else None
    out: dict[str, Any] = {
        "clear": c.clear,
        "min_distance": distance,
        "closest_bodies": list(c.closest.bodies),
        "closest_time": c.where,
        "clearance": c.closest.clearance,
        "checks": c.checks,
    }
    if c.hit is not None:
        out.update(first_hit_time=c.first_hit, hit_bodies=list(c.hit.bodies), hit_distance=c.hit.distance)
    if c.unmeasured is not None:
        # Pairs left out by their floors: the least floor, a lower bound of that pair's distance.
        out.update(unmeasured_bodies=list(c.unmeasured.bodies), unmeasured_floor=c.unmeasured.distance)
    return out


def _joint_scale(robot: Robot, request: MotionRequest) -> np.ndarray:
    return np.array([request.length_scale if k == "prismatic" else request.angle_scale for k in robot.joint_kinds])


def _per_joint_si(value: float | np.ndarray, scale: np.ndarray) -> np.ndarray:
    """A limit in the file's units (one number or one per joint) in SI, per joint."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):  # not numbers: JointLimits names the value in its error
        return value
    if arr.ndim == 0 or arr.shape == scale.shape:
        return arr * scale
    return arr  # the wrong length: JointLimits names the joints in its error


class _PlanLimits:
    """Per robot (in its derived cache), the limits :func:`plan_motion` made, by the values asked for.

    A robot's ranges and speeds are read-only and :class:`JointLimits` is immutable: the plans
    of requests asking for the same limits share one, with the tables it computes when first
    used.
    """

    def __init__(self) -> None:
        self.items: dict[tuple, JointLimits] = {}


def _plan_limits(robot: Robot, lim_kw: dict[str, Any]) -> JointLimits:
    """``JointLimits.from_robot(robot, **lim_kw)``, made once per robot and values (see :class:`_PlanLimits`)."""
    try:
        key = tuple((k, np.shape(v), np.asarray(v, dtype=float).tobytes()) for k, v in lim_kw.items())
    except (TypeError, ValueError):  # not numbers: from_robot names the value
        return JointLimits.from_robot(robot, **lim_kw)
    held = robot.derived.get(_PlanLimits, _PlanLimits)
    limits = held.items.get(key)
    if limits is None:
        if len(held.items) >= 8:
            held.items.clear()
        limits = held.items[key] = JointLimits.from_robot(robot, **lim_kw)
    return limits


class _DefaultSetups:
    """Per robot (in its derived cache), the default controller setups by controller name.

    What :func:`controller_setup` gives where no calibration file, no servos and no travel are
    given and it falls back to the controller's defaults: those depend only on the robot's
    (read-only) ranges and joint names. Its calibrations are immutable and shared.
    """

    def __init__(self) -> None:
        self.items: dict[str | None, ControllerSetup] = {}


def _controller_setup(
    robot: Robot,
    controller: str | None,
    calibration: str | Path | None,
    servos: tuple[ServoCalibration, ...] | None,
    travel: tuple[np.ndarray, np.ndarray] | None,
) -> ControllerSetup:
    """:func:`controller_setup`, its defaults made once per robot and controller (see :class:`_DefaultSetups`)."""
    if (
        calibration is not None
        or servos is not None
        or travel is not None
        or not isinstance(controller, (str, type(None)))
    ):
        return controller_setup(robot, controller, calibration, servos, travel=travel)
    held = robot.derived.get(_DefaultSetups, _DefaultSetups)
    setup = held.items.get(controller)
    if setup is None:
        setup = controller_setup(robot, controller, None, None)
        if setup.source != "defaults":  # a calibration file shipped for the arm: read each time
            return setup
        held.items[controller] = setup
    # Each plan its own setup (its settings a dict of its own), the calibrations shared.
    return ControllerSetup(setup.controller, setup.calibrations, {}, setup.source)


def _check_against_scene(
    checker: CollisionChecker,
    request: MotionRequest,
    q_user: np.ndarray,
    paths: list[list[LinePath] | None],
    cartesian: list[bool],
    labels: list[str],
    allow: Sequence[tuple[str, ...]],
) -> None:
    """Check the waypoints and the Cartesian lines against the scene.

    Raises:
        PlanningError: If a waypoint or a Cartesian line collides (naming the bodies).
    """
    n = len(q_user)
    # A waypoint farther than the path search's end test (one proximity test, the search's own)
    # keeps the clearance; only a nearer one needs its distance.
    wide = checker.scene.clearance + 2.0 * request.path_options.margin
    for k in range(n):
        if not checker.closer_than(wide, allow[k])(q_user[k]):
            continue
        c = checker.distance_at(q_user[k], checker.pair_mask(allow[k]))
        if not c.clear:
            raise PlanningError(
                f"{request.source}: {labels[k]} does not keep the clearance "
                f"({checker.scene.clearance * 1000:g} mm): {c}"
            )
    for k in range(1, n):
        if not cartesian[k]:
            continue  # free moves: checked once timed (plan_motion)
        names = tuple(set(allow[k - 1]) | set(allow[k]))
        samples = paths[k][0].q
        for i, (a, b) in enumerate(zip(samples, samples[1:])):
            result = check_segment(checker, a, b, allow=names)
            if not result.clear:
                assert result.first_hit is not None and result.hit is not None
                where = 100.0 * (i + result.first_hit) / (len(samples) - 1)
                what = "collides" if result.hit.in_collision else "comes closer than the clearance"
                raise PlanningError(
                    f"{request.source}: the straight line into {labels[k]} {what} {where:.0f} % of the way: "
                    f"{result.hit}; move the line or the obstacle, or drop `line: true` so the arm may go around"
                )


#: Largest joint change [rad or m] between the points that decide, before timing, that a free
#: move's straight segment is blocked (and the move is routed at once). Not a certificate: one
#: blocked between them is found by the continuous check of the timed motion and routed then,
#: into the same plan (the same search), only later. Measured on 1000 random moves among a
#: table and a box: 0.05 rad finds 5 of panda's 762 clear-looking ones blocked that 0.2 rad
#: does not (none of ur5's 129), for a quarter of the tests on every clear move.
_PLAINLY_BLOCKED = 0.2


def _route(
    checker: CollisionChecker,
    request: MotionRequest,
    q_user: np.ndarray,
    k: int,
    labels: list[str],
    allow: Sequence[tuple[str, ...]],
    *,
    certify: bool = True,
    found: PathResult | None = None,
    blocked: bool = False,
) -> tuple[list[np.ndarray], bool, PathResult | None]:
    """The nodes of a clear way into waypoint k, whether its edges are certified, and the search's result.

    Its straight joint segment if that is clear (with the path search's margin, certified;
    then no search result), else a route found around the obstacles, its edges certified only
    if `certify` (else checked at points: the timed motion along them is certified by
    plan_motion's check). `found`: this route's search without certificates, made before; with
    `certify` its result is certified (:func:`certify_path`) instead of searching again.
    `blocked`: the straight segment is known blocked at the scene's clearance
    (:func:`segment_looks_clear`), so also with the search's margin: it is not tested again.

    Raises:
        PlanningError: If no clear route exists (with the search's reason).
    """
    names = tuple(set(allow[k - 1]) | set(allow[k]))
    options = request.path_options
    if found is not None and certify:
        # Where neither of its paths certifies, its trees are grown anew: that may find none.
        result = certify_path(checker, found, options=options, allow=names)
    else:
        if not blocked:
            margin = ends_margin(checker, q_user[k - 1 : k + 1], names, options.margin)
            if segment_is_clear(checker, q_user[k - 1], q_user[k], allow=names, margin=margin):
                return [q_user[k - 1], q_user[k]], True, None
        # The search would test the straight segment again with the same margin: it is blocked.
        result = find_clear_path(
            checker, q_user[k - 1], q_user[k], options=options, allow=names, try_straight=False, certify=certify
        )
        if result.found and not certify and len(result.path) == 2:
            # A straight edge is followed along its line at once: that needs its certificate.
            result = certify_path(checker, result, options=options, allow=names)
            certify = True
    if not result.found:
        raise PlanningError(
            f"{request.source}: no collision-free way from {labels[k - 1]} to {labels[k]}: {result.reason} "
            f"({result.status.value}); try another avoidance seed or time_budget, or move the obstacle"
        )
    return list(result.path), certify, result


def _calibrations(robot: Robot, request: MotionRequest) -> tuple[ServoCalibration, ...] | None:
    if request.servos is None:
        return None
    if len(request.servos) != robot.dof:
        raise input_error(
            request.source, f"servos has {len(request.servos)} entries; {robot.name} has {robot.dof} joints"
        )
    out = []
    for k, (s, name) in enumerate(zip(request.servos, robot.joint_names)):
        kw = dict(s)
        if "us_per_deg" in kw:
            if "us_per_rad" in kw:
                raise input_error(request.source, f"servos[{k}]: give us_per_rad or us_per_deg, not both")
            kw["us_per_rad"] = (
                parse_number(kw.pop("us_per_deg"), f"servos[{k}].us_per_deg", request.source) * 180.0 / math.pi
            )
        kw.setdefault("channel", k)
        out.append(ServoCalibration(joint=name, **kw))
    return tuple(out)


def _blends(
    request: MotionRequest,
    cartesian: list[bool],
    paths: list[list[LinePath] | None],
    routes: dict[int, list[np.ndarray]],
    seg: int,
) -> tuple[bool, bool]:
    """Whether the line of requested segment `seg` (into waypoint seg + 1) may start and end moving.

    A Cartesian line blends into a free joint move before or after it, where the waypoint
    between them asks for no stop (``stop``, a dwell) and is neither the first nor the last.
    """
    k = seg + 1
    if not (request.blend_lines and cartesian[k]):
        return False, False

    def free(j: int, n: int) -> bool:  # waypoint j, between the moves into j and out of it (into j + 1)
        if j <= 0 or j >= n - 1 or j in request.stops or request.dwell[j] > 0:
            return False
        other = j if j != k else j + 1  # the move on the far side of the waypoint from the line
        return paths[other] is None and other not in routes

    n = request.count
    return free(k - 1, n), free(k, n)


def _line_groups(
    request: MotionRequest, cartesian: list[bool], line_ranges: list[tuple[int, int, int]]
) -> list[list[int]]:
    """Runs of consecutive lines (indices into `line_ranges`) that pass their junctions without stopping.

    A Cartesian line into waypoint k + 1 continues the one into waypoint k where both meet at
    k, the second goes straight on from the first (:func:`planner.motion.line.continues_line`),
    the request blends lines and asks for no stop or dwell at k.
    """
    from planner.motion.line import continues_line

    groups: list[list[int]] = []
    for i, (seg, a, _) in enumerate(line_ranges):
        if groups:
            prev_seg, _, prev_b = line_ranges[groups[-1][-1]]
            k = seg  # the waypoint between the two lines
            if (
                request.blend_lines
                and prev_seg == seg - 1
                and prev_b == a
                and cartesian[k]
                and cartesian[k + 1]
                and k not in request.stops
                and not request.dwell[k] > 0
                and request.targets is not None
                and continues_line(request.targets[k - 1], request.targets[k], request.targets[k + 1])
            ):
                groups[-1].append(i)
                continue
        groups.append([i])
    return groups


def plan_motion(
    robot: Robot,
    request: MotionRequest,
    *,
    rate: float = 1000.0,
    controller: str | None = None,
    calibration: str | Path | None = None,
) -> MotionPlan:
    """Plan a motion request for a robot: IK for targets, line sampling, trajectory, singularities.

    Args:
        robot: The robot.
        request: The parsed request.
        rate: Sampling rate of the singularity checks [Hz].
        controller: Controller to write servo files for (a key of
            :data:`planner.export.formats.SERVO_FORMATS`), instead of the request's.
        calibration: Calibration file, instead of the request's (see
            :func:`planner.export.calibration_file.controller_setup` for the order of choice).

    Returns:
        The plan.

    Raises:
        PlannerError: On input the robot cannot take (wrong joint count, a waypoint out of
            range, an unreachable target, bad limits), with a message naming what is wrong.
    """
    scale = _joint_scale(robot, request)
    src = request.source
    lim_kw = {}
    for key in ("velocity", "acceleration", "jerk"):
        if key in request.limits:
            lim_kw[key] = _per_joint_si(request.limits[key], scale)
    if "servo_seconds_per_60deg" in request.limits:
        lim_kw["servo_seconds_per_60deg"] = request.limits["servo_seconds_per_60deg"]
    limits = _plan_limits(robot, lim_kw)
    cond = request.condition_number
    threshold = inverse_condition_threshold(None if cond is None else 1.0 / cond, robot.resolve_task(None))

    def state(value: np.ndarray | None, what: str) -> np.ndarray | None:
        if value is None:
            return None
        if value.shape != (robot.dof,):
            names = ", ".join(robot.joint_names)
            raise input_error(
                src, f"start.{what} has {value.size} values; {robot.name} has {robot.dof} joints ({names})"
            )
        return value * scale

    start_q = state(request.start_q, "q")
    start_v = state(request.start_velocity, "velocity")
    start_a = state(request.start_acceleration, "acceleration")
    if start_q is not None:
        robot.check_limits(start_q, context="start.q")

    n = request.count
    labels = [f"waypoint {k}" + (f" ({request.labels[k]})" if request.labels[k] else "") for k in range(n)]
    # Its floors first: the proximity tests leave out the pairs that always keep apart.
    checker = floored(shared_checker(robot, request.scene)) if request.scene is not None else None
    allow = request.allow or ((),) * n
    branches: list[str | None] = [None] * n
    # The joint configuration of each requested waypoint, and how each requested segment moves:
    # None for a free joint-space move, else joint samples along lines (a Cartesian line, or the
    # edges of a route around obstacles) with a flag for Cartesian lines.
    q_list: list[np.ndarray] = []
    paths: list[list[LinePath] | None] = [None] * n  # paths[k]: the move into waypoint k
    cartesian = [False] * n
    if request.joints is not None:
        if request.joints.shape[1] != robot.dof:
            raise input_error(
                src,
                f"waypoints have {request.joints.shape[1]} values; {robot.name} has {robot.dof} joints "
                f"({', '.join(robot.joint_names)})",
            )
        q_list = list(request.joints * scale)
        if start_q is not None and not np.allclose(start_q, q_list[0], atol=1e-9):
            raise input_error(
                src, "start.q differs from the first waypoint; with joint waypoints the first one is the start"
            )
    else:
        from planner.motion.branch_choice import TargetSolver
        from planner.motion.line import continues_line, line_waypoints

        solver = TargetSolver(robot, threshold=threshold)
        q_prev = start_q
        for k, target in enumerate(request.targets):
            label = f"target {k}" + (f" ({request.labels[k]})" if request.labels[k] else "")
            if request.lines[k]:
                targets = request.targets
                straight_on = (k >= 2 and request.lines[k - 1] and continues_line(*targets[k - 2 : k + 1])) or (
                    k + 1 < n and request.lines[k + 1] and continues_line(*targets[k - 1 : k + 2])
                )
                path = line_waypoints(solver, targets[k - 1], target, q_list[-1], free_pitch=not straight_on)
                paths[k], cartesian[k], branches[k] = [path], True, "line"
                q_list.append(np.array(path.q[-1]))
                q_prev = q_list[-1]
                continue
            choice = solver.choose(target, q_prev, label=label, checker=checker, allow=allow[k])
            branches[k] = choice.branch
            q_list.append(np.array(choice.q))
            q_prev = q_list[-1]
    q_user = np.array(q_list)
    # routes[k]: the nodes of a clear route into waypoint k. Its edges are passed as via
    # waypoints, smoothly; an edge the timed motion strays from into an obstacle is halved,
    # and a half it strays from is followed along its straight (clear) joint line instead
    # (`dense`), from rest to rest.
    routes: dict[int, list[np.ndarray]] = {}
    dense: set[tuple[int, int]] = set()
    edge_lines: dict[tuple[int, int], LinePath] = {}
    # Routes whose edges passed only the path search's checks at points: most timed motions
    # along them pass the continuous check as they are; where one does not, the route is
    # asked for again with its edges certified before an edge is followed along its line.
    unproven: set[int] = set()
    searches: dict[int, PathResult | None] = {}  # per route, its search's result (None: straight)

    def route(k: int, certify: bool = False, blocked: bool = False) -> None:
        found = searches.get(k) if certify else None
        routes[k], proven, searches[k] = _route(
            checker, request, q_user, k, labels, allow, certify=certify, found=found, blocked=blocked
        )
        if not proven:
            unproven.add(k)
        elif len(routes[k]) == 2:
            # The straight segment, certified clear: its midpoint is passed too (the timed motion
            # keeps closer to it than a move between its ends), and a half the motion strays from
            # is followed along its line.
            a, b = routes[k]
            routes[k] = [a, (a + b) / 2.0, b]
            halves.update({(k, 0), (k, 1)})

    # Route edges made by halving one the timed motion strayed from: followed along their line
    # if it strays from them too.
    halves: set[tuple[int, int]] = set()

    def follow(k: int, e: int) -> None:
        """Keep the timed motion closer to edge e of route k: first through its midpoint too, then along its line."""
        if (k, e) in halves:
            dense.add((k, e))
            return
        routes[k] = [*routes[k][: e + 1], (routes[k][e] + routes[k][e + 1]) / 2.0, *routes[k][e + 1 :]]

        def shift(key: tuple[int, int]) -> tuple[int, int]:
            return (key[0], key[1] + 1) if key[0] == k and key[1] > e else key

        for keys in (dense, halves):
            moved = {shift(key) for key in keys}
            keys.clear()
            keys.update(moved)
        lines = {shift(key): line for key, line in edge_lines.items()}
        edge_lines.clear()
        edge_lines.update(lines)
        halves.update({(k, e), (k, e + 1)})

    if request.joints is not None:
        # Before the scene's sweeps: one from a waypoint far outside its range (1e9) took
        # memory without bound (points every 0.05 rad); the timing would refuse it anyway.
        for k, q in enumerate(q_user):
            robot.check_limits(q, context=f"waypoint {k}")
    # So is a move no segment can time (a continuous joint told to turn a million radians).
    # The least time from or to rest bounds the first or last move only where it starts or ends
    # at rest in one segment: not from a moving start, nor along a line (timed in many segments).
    moving_start = any(s is not None and bool(np.any(s)) for s in (start_v, start_a))
    limits.check_move_durations(
        q_user, labels, from_rest=not (moving_start or cartesian[min(1, n - 1)]), to_rest=not cartesian[n - 1]
    )
    if checker is not None:
        _check_against_scene(checker, request, q_user, paths, cartesian, labels, allow)
        for k in range(1, n):
            # A free move whose straight segment is plainly blocked is routed before timing.
            names = tuple(set(allow[k - 1]) | set(allow[k]))
            if not cartesian[k] and not segment_looks_clear(
                checker, q_user[k - 1], q_user[k], allow=names, resolution=_PLAINLY_BLOCKED
            ):
                route(k, blocked=True)

    timings: dict[int, Any] = {}  # line timing per LinePath (by id), kept across re-plans
    crossings: dict[int, bool] = {}

    def crossing(k: int) -> bool:
        """Whether the move into waypoint k must pass a singularity (on any path)."""
        if k not in crossings:
            crossings[k] = must_cross_singularity(robot, q_user[k - 1], q_user[k])
        return crossings[k]

    def build(paths: list[list[LinePath] | None]) -> tuple:
        """Nodes through every waypoint and line sample, and the line bookkeeping."""
        from planner.motion.line_timing import time_line

        nodes = [q_user[0]]
        user_pos = [0]
        line_ranges: list[tuple[int, int, int]] = []  # (user segment, first node, last node)
        line_timing = []
        owner: list[tuple[int, int | None]] = []  # per node interval: (user segment into k, route edge)

        def add_line(k: int, path: LinePath, edge: int | None) -> None:
            first = len(nodes) - 1
            nodes.extend(path.q[1:])
            owner.extend([(k, edge)] * (len(path.q) - 1))
            line_ranges.append((k - 1, first, len(nodes) - 1))
            if id(path) not in timings:
                # A Cartesian line bends in joint space; a route's edge is straight there.
                timings[id(path)] = time_line(path, limits) if cartesian[k] else time_joint_line(path, limits)
            line_timing.append(timings[id(path)])

        for k in range(1, n):
            if k in routes:
                for e, (a, b) in enumerate(zip(routes[k], routes[k][1:])):
                    if (k, e) in dense:
                        if (k, e) not in edge_lines:
                            edge_lines[k, e] = joint_line(robot, a, b)
                        add_line(k, edge_lines[k, e], e)
                    else:
                        nodes.append(b)
                        owner.append((k, e))
            elif paths[k] is None:
                nodes.append(q_user[k])
                owner.append((k, None))
            else:
                for path in paths[k]:
                    add_line(k, path, None)
            user_pos.append(len(nodes) - 1)
        return np.array(nodes), user_pos, line_ranges, line_timing, owner

    # The measure of the last plan made without it (plan_once with measure False): a function
    # giving the measured plan.
    pending: list[Callable[[], SingularityAwarePlan]] = []

    def plan_once(
        paths: list[list[LinePath] | None], blend: bool = True, merge: bool = True, measure: bool = True
    ) -> tuple:
        """The plan through `paths`.

        Without `measure`, a motion without lines (none to smooth) is only timed: its plan has
        no report (None) until ``pending``'s function measures it (from the same timing).
        """
        q_nodes, user_pos, line_ranges, line_timing, owner = build(paths)
        m = len(q_nodes)
        dwell = np.zeros(m)
        dwell[user_pos] = request.dwell
        stops = [user_pos[k] for k in request.stops]
        keep = {s for _, a, b in line_ranges for s in range(a, b)}
        # A route between ends on opposite sides of a singularity crosses it on some edge: like
        # a straight move between them, none of its edges gets a detour.
        keep.update(i for i, (k, edge) in enumerate(owner) if edge is not None and crossing(k))
        via_v = np.full(q_nodes.shape, np.nan)
        via_a = np.zeros(q_nodes.shape)
        min_dur = np.zeros(m - 1)
        moving = [
            _blends(request, cartesian, paths, routes, seg) if blend else (False, False) for seg, _, _ in line_ranges
        ]
        for (_, a, b), timing in zip(line_ranges, line_timing):
            # A line is timed from rest to rest: its samples get the timing's states.
            via_v[a : b + 1] = timing.velocity
            via_a[a : b + 1] = timing.acceleration
            min_dur[a:b] = np.diff(timing.t)
        # Lines going straight on from one another are smoothed as one (the chain rests between).
        groups = _line_groups(request, cartesian, line_ranges) if merge else [[i] for i in range(len(line_ranges))]
        moving = [(moving[g[0]][0], moving[g[-1]][1]) for g in groups]
        for i, g in enumerate(groups):
            a, b = line_ranges[g[0]][1], line_ranges[g[-1]][2]
            if any(moving[i]):
                # It blends into a neighbouring joint move: that move meets its end velocity.
                joins = [line_ranges[j][2] - a for j in g[:-1]]
                ends = line_end_states(q_nodes[a : b + 1], limits, moving[i], joins)
                if ends is None:
                    moving[i] = (False, False)
                for end, node, moves in zip(ends or (), (a, b), moving[i]):
                    if moves:
                        via_v[node], via_a[node] = end
            stops += [node for node, moves in zip((a, b), moving[i]) if not moves]
        # Without lines nothing is prescribed: every via state free, no minimum duration.
        prescribed = bool(line_ranges)
        trajectory_request = TrajectoryRequest(
            q_nodes,
            limits,
            start_velocity=start_v,
            start_acceleration=start_a,
            stops=stops,
            dwell=dwell,
            strategy=request.strategy,
            via_velocities=via_v if prescribed else None,
            via_accelerations=via_a if prescribed else None,
            min_durations=min_dur if prescribed else None,
        )
        options = SingularityOptions(
            threshold=threshold, rate=rate, max_detours=request.max_detours if request.detours else 0
        )
        if not measure and not line_ranges:
            timed = plan_trajectory_request(trajectory_request)
            pending[:] = [
                lambda: plan_clear_of_singularities(
                    robot, trajectory_request, options, keep_segments=sorted(keep), timed=timed
                )
            ]
            # What plan_clear_of_singularities gives where it inserts no detour, not yet measured.
            plan = SingularityAwarePlan(timed, None, read_only(np.arange(m), None), (), ())  # type: ignore[arg-type]
            return plan, user_pos, line_ranges, m, owner
        plan = plan_clear_of_singularities(robot, trajectory_request, options, keep_segments=sorted(keep))
        if line_ranges:
            # Each line as smooth pieces between its corners, not a chain of bang-bang segments.
            stretches = [
                (int(plan.waypoint_indices[line_ranges[g[0]][1]]), int(plan.waypoint_indices[line_ranges[g[-1]][2]]))
                for g in groups
            ]
            # The user's waypoints where lines join are passed exactly.
            joins = [[int(plan.waypoint_indices[line_ranges[i][2]]) for i in g[:-1]] for g in groups]
            smooth, count = smooth_lines(plan.trajectory, stretches, moving=moving, exact=joins)
            if count < len(stretches) and len(groups) < len(line_ranges):
                # A run of lines that did not smooth as one: each on its own, resting between.
                return plan_once(paths, blend, merge=False)
            if any(map(any, moving)):
                # Blended only where every line smoothed and the whole motion got shorter.
                rest = plan_once(paths, blend=False, merge=merge)
                if count < len(stretches) or not smooth.duration < rest[0].trajectory.duration:
                    return rest
            if count:
                report, t, _, inv = measure_singularities(robot, smooth, threshold, robot.resolve_task(None), rate)
                # Segments dipping are found again on the smoothed motion, as plan_clear_of_singularities did.
                segments = np.arange(len(smooth.waypoint_times) - 1)
                owners = np.searchsorted(plan.waypoint_indices, segments, side="right") - 1
                still = dipping_segments(smooth, report, t, inv, np.minimum(owners, m - 2))
                plan = dataclasses.replace(plan, trajectory=smooth, report=report, unresolved=tuple(sorted(still)))
        return plan, user_pos, line_ranges, m, owner

    # With a scene, a motion without lines is checked for collisions before its singularity
    # measure: a round the check sends back (to route a move, halve or follow an edge) is
    # not measured at all. The motion the check passes is measured then (from the same
    # timing); where that inserts detours, the detoured motion is checked in turn.
    plan, user_pos, line_ranges, m, owner = plan_once(paths, measure=checker is None)
    collision = None
    if checker is not None:
        # Check the timed motion continuously. Where a free move comes too close, it follows
        # its straight joint segment if that is clear (with the path search's margin), else a
        # route found around the obstacles; where a route's edge does, that edge is halved (its
        # midpoint passed too: the motion keeps closer to it), and where one of its halves does,
        # that half is followed along its straight joint line. Then the motion is re-planned and
        # checked again. Each round adds a route, halves an edge not made by halving or follows
        # an edge, so the rounds end.
        while True:
            times = plan.trajectory.waypoint_times[plan.waypoint_indices[user_pos]]
            windows = [(float(times[k - 1]), tuple(set(allow[k - 1]) | set(allow[k]))) for k in range(1, n)]
            collision = check_trajectory(checker, plan.trajectory, allow=windows, stop_at_first=True)
            k, edge = -1, None
            if not collision.clear:
                node_times = plan.trajectory.waypoint_times[plan.waypoint_indices]
                i = int(np.searchsorted(node_times, collision.first_hit, side="right")) - 1
                k, edge = owner[min(max(i, 0), m - 2)]
            settled = collision.clear or not (
                (k in unproven and edge is not None)
                or (k in routes and edge is not None and (k, edge) not in dense)
                or (k not in routes and paths[k] is None)
            )
            if settled:
                if plan.report is None:
                    checked = plan.trajectory
                    plan = pending.pop()()
                    if plan.trajectory is not checked:
                        continue  # detoured: that motion is checked
                if not collision.clear:
                    # Already along clear lines: reported as it is, with the closest pair throughout.
                    collision = check_trajectory(checker, plan.trajectory, allow=windows)
                break
            if k in unproven and edge is not None:
                # The same search (same seed) again, its edges certified: the same route where
                # they pass, whose edge is then followed along its line.
                unproven.discard(k)
                before = routes[k]
                route(k, certify=True)
                same = len(before) == len(routes[k]) and all(map(np.array_equal, before, routes[k]))
                if same:
                    follow(k, edge)
                else:
                    for key in [key for key in edge_lines if key[0] == k]:
                        del edge_lines[key]
                    dense -= {(k, e) for e in range(len(before))}
            elif k in routes and edge is not None and (k, edge) not in dense:
                follow(k, edge)
            else:
                route(k)
            plan, user_pos, line_ranges, m, owner = plan_once(paths, measure=False)

    traj = plan.trajectory
    node_idx = plan.waypoint_indices
    user_idx = node_idx[user_pos]
    times = traj.waypoint_times[user_idx]
    inv_user = plan.report.waypoint_inverse_condition[user_idx]
    singular = tuple(int(k) for k in np.nonzero(inv_user < threshold)[0])
    # Map node segments back to requested segments.
    node_to_user = np.searchsorted(np.array(user_pos), np.arange(m), side="right") - 1
    detours = tuple(Detour(int(node_to_user[d.segment]), d.q, d.inverse_condition, d.dip) for d in plan.detours)
    unresolved = tuple(sorted({int(node_to_user[s]) for s in plan.unresolved}))
    deviation: list[float | None] = [None] * (n - 1)
    if any(cartesian):
        from planner.motion.line import line_deviation

        for seg, a, b in line_ranges:
            if not cartesian[seg + 1]:
                continue
            t0, t1 = traj.waypoint_times[node_idx[a]], traj.waypoint_times[node_idx[b]]
            t = np.linspace(t0, t1, max(2, int(math.ceil((t1 - t0) * rate)) + 1))
            deviation[seg] = line_deviation(
                robot, traj.sample(t).q, request.targets[seg].position, request.targets[seg + 1].position
            )
    # Continuous joints have no range to fit: default calibrations fit the plan's travel, sampled
    # at 1 kHz, with a margin far above what the servo files' own sample times can add to it.
    travel = None
    if not (np.all(np.isfinite(robot.lower)) and np.all(np.isfinite(robot.upper))):
        q_travel = traj.sample(np.append(np.arange(0.0, traj.duration, 1e-3), traj.duration)).q
        travel = (q_travel.min(axis=0) - 1e-3, q_travel.max(axis=0) + 1e-3)
    setup = _controller_setup(
        robot,
        controller or request.controller,
        calibration if calibration is not None else request.calibration,
        None if calibration is not None else _calibrations(robot, request),
        travel,
    )
    return MotionPlan(
        robot=robot.name,
        trajectory=traj,
        singularity=plan.report,
        waypoints=read_only(q_user),
        waypoint_times=read_only(times),
        departure_times=read_only(times + traj.dwell[user_idx]),
        branches=tuple(branches),
        labels=tuple(request.labels),
        singular_waypoints=singular,
        detours=detours,
        unresolved=unresolved,
        line_deviation=tuple(deviation),
        limits=limits,
        collision=collision,
        routes=tuple(k - 1 for k in sorted(routes)),
        scene=request.scene,
        calibrations=setup.calibrations,
        servo_period_ms=request.servo_period_ms,
        setup=setup,
    )
