"""Motion requests (the ``planner plan`` file) and planning them into a :class:`MotionPlan`.

A plan file is YAML or JSON (``.json`` is read as JSON, anything else as YAML)::

    units: {length: cm, angle: deg}   # optional; default m and rad
    waypoints:                        # joint vectors, base to tip ...
      - [0, 30, 60]
      - {q: [45, 60, 90], dwell: 0.5} # ... or objects: q, dwell [s], stop, label
    targets:                          # ... or Cartesian targets instead of waypoints
      - {position: [17, 0, 3]}        # optional: pitch, or rpy [roll, pitch, yaw], or quaternion [x, y, z, w]
      - {position: [14, 0, -4], line: true, dwell: 0.5, label: grasp}
    limits:                           # optional; each a number for all joints or one per joint
      velocity: 60                    # [angle/s]; default from the URDF
      servo_seconds_per_60deg: 0.2    # instead of velocity
      acceleration: 120               # [angle/s^2]; default 2 x velocity
      jerk: 1200                      # [angle/s^3]; default 10 x acceleration
    start: {q: [...], velocity: [...], acceleration: [...]}   # optional state at the first waypoint
    singularity: {condition_number: 30, detours: true, max_detours: 8}
    strategy: optimized               # or heuristic, stop
    servos:                           # optional pulse-width calibration per joint
      - {channel: 0, pulse_at_zero: 1500, us_per_rad: 636.6, direction: 1, min_pulse: 500, max_pulse: 2500}
    servo_period_ms: 20

``line: true`` on a target makes the motion from the previous target to it a straight line.
Angles (joint values, pitch, rpy, angular limits) use the ``angle`` unit, lengths (positions,
prismatic joints) the ``length`` unit; time is always seconds. Everything inside is SI.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from planner.core.files import read_data_file
from planner.core.units import ANGLE_UNITS, LENGTH_UNITS
from planner.exceptions import InvalidArgumentError
from planner.export.servo import ServoCalibration, default_calibrations
from planner.geometry.target import Target
from planner.model.robot import Robot
from planner.motion.limits import JointLimits
from planner.motion.request import TrajectoryRequest
from planner.motion.singularity import (
    DEFAULT_CONDITION_NUMBER,
    Detour,
    SingularityOptions,
    SingularityReport,
    plan_clear_of_singularities,
)
from planner.motion.trajectory import JointTrajectory

__all__ = [
    "MotionPlan",
    "MotionRequest",
    "load_motion_request",
    "parse_motion_request",
    "plan_motion",
]

_TOP_KEYS = (
    "units",
    "waypoints",
    "targets",
    "limits",
    "start",
    "singularity",
    "strategy",
    "servos",
    "servo_period_ms",
    "name",
    "comment",
)
_LIMIT_KEYS = ("velocity", "acceleration", "jerk", "servo_seconds_per_60deg")
_WAYPOINT_KEYS = ("q", "dwell", "stop", "label")
_TARGET_KEYS = ("position", "pitch", "rpy", "quaternion", "dwell", "stop", "line", "label")
_SERVO_KEYS = ("channel", "pulse_at_zero", "us_per_rad", "us_per_deg", "direction", "min_pulse", "max_pulse")


def _fail(source: str, message: str) -> InvalidArgumentError:
    return InvalidArgumentError(f"{source}: {message}")


def _unknown_keys(obj: Mapping[str, Any], allowed: Sequence[str], where: str, source: str) -> None:
    extra = [k for k in obj if k not in allowed]
    if extra:
        raise _fail(source, f"unknown key {extra[0]!r} in {where}; valid keys: {', '.join(allowed)}")


def _number(value: Any, what: str, source: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(source, f"{what} must be a number, got {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise _fail(source, f"{what} must be finite, got {value!r}")
    return x


def _numbers(value: Any, what: str, source: str, length: int | None = None) -> np.ndarray:
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Sequence):
        raise _fail(source, f"{what} must be a list of numbers, got {value!r}")
    arr = np.array([_number(v, f"{what}[{k}]", source) for k, v in enumerate(value)], dtype=float)
    if length is not None and arr.shape != (length,):
        raise _fail(source, f"{what} must have {length} numbers, got {len(arr)}")
    return arr


def _limit_value(value: Any, what: str, source: str) -> float | np.ndarray:
    """A limit as given: one number or a list; positivity is checked against the robot later."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        x = float(value)
        if math.isnan(x):
            raise _fail(source, f"limits.{what} is NaN")
        return x
    if isinstance(value, Sequence) and not isinstance(value, (str, bytes)):
        out = []
        for k, v in enumerate(value):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise _fail(source, f"limits.{what}[{k}] must be a number, got {v!r}")
            out.append(float(v))
        return np.array(out)
    raise _fail(source, f"limits.{what} must be a number or a list of numbers, got {value!r}")


@dataclass(frozen=True)
class MotionRequest:
    """A parsed plan file, in the file's units until :func:`plan_motion` meets the robot.

    Attributes:
        joints: Joint waypoints as written, shape (N, dof), or None when `targets` are given.
        targets: Cartesian targets (SI), or None when `joints` are given.
        dwell: Time at rest at each waypoint [s], shape (N,).
        stops: Indices of waypoints to stop at.
        lines: Whether the motion into each waypoint is a straight Cartesian line, shape (N,).
        labels: A label per waypoint, or None.
        limits: The ``limits`` mapping as written (velocity etc. in the file's units).
        start_q: Start configuration as written, or None: with joint waypoints it must equal
            the first one; with targets the first IK solution is chosen nearest it.
        start_velocity: Velocity at the first waypoint as written, or None (at rest).
        start_acceleration: Acceleration at the first waypoint as written, or None.
        condition_number: Singularity threshold as a Jacobian condition number.
        detours: Whether to insert detours around singularities.
        max_detours: Most detours to insert.
        strategy: Via strategy (see :func:`planner.motion.plan.plan_trajectory`).
        servos: Servo calibration mappings as written, or None for defaults.
        servo_period_ms: Period of the SSC-32 commands [ms].
        angle_scale: Radians per file angle unit.
        length_scale: Metres per file length unit.
        source: Where the request came from, for messages.
    """

    joints: np.ndarray | None
    targets: tuple[Target, ...] | None
    dwell: np.ndarray
    stops: tuple[int, ...]
    lines: np.ndarray
    labels: tuple[str | None, ...]
    limits: Mapping[str, Any] = field(default_factory=dict)
    start_q: np.ndarray | None = None
    start_velocity: np.ndarray | None = None
    start_acceleration: np.ndarray | None = None
    condition_number: float = DEFAULT_CONDITION_NUMBER
    detours: bool = True
    max_detours: int = 8
    strategy: str = "optimized"
    servos: tuple[Mapping[str, Any], ...] | None = None
    servo_period_ms: int = 20
    angle_scale: float = 1.0
    length_scale: float = 1.0
    source: str = "<request>"

    @property
    def count(self) -> int:
        """Number of waypoints or targets."""
        return len(self.dwell)


def _parse_waypoint(item: Any, k: int, source: str) -> tuple[np.ndarray, float, bool, str | None]:
    if isinstance(item, Mapping):
        _unknown_keys(item, _WAYPOINT_KEYS, f"waypoints[{k}]", source)
        if "q" not in item:
            raise _fail(source, f"waypoints[{k}] needs a 'q' list of joint values")
        q = _numbers(item["q"], f"waypoints[{k}].q", source)
        return q, *_extras(item, f"waypoints[{k}]", source)
    return _numbers(item, f"waypoints[{k}]", source), 0.0, False, None


def _extras(item: Mapping[str, Any], where: str, source: str) -> tuple[float, bool, str | None]:
    dwell = _number(item.get("dwell", 0.0), f"{where}.dwell", source)
    if dwell < 0:
        raise _fail(source, f"{where}.dwell must be >= 0 [s], got {dwell:g}")
    stop = item.get("stop", False)
    if not isinstance(stop, bool):
        raise _fail(source, f"{where}.stop must be true or false, got {stop!r}")
    label = item.get("label")
    return dwell, stop, None if label is None else str(label)


def _parse_target(
    item: Any, k: int, source: str, length: float, angle: float
) -> tuple[Target, float, bool, bool, str | None]:
    where = f"targets[{k}]"
    if not isinstance(item, Mapping):
        raise _fail(source, f"{where} must be a mapping with a 'position', got {item!r}")
    _unknown_keys(item, _TARGET_KEYS, where, source)
    if "position" not in item:
        raise _fail(source, f"{where} needs a 'position' [x, y, z]")
    pos = _numbers(item["position"], f"{where}.position", source, 3) * length
    given = [key for key in ("pitch", "rpy", "quaternion") if key in item]
    if len(given) > 1:
        raise _fail(source, f"{where} gives {' and '.join(given)}; give at most one of pitch, rpy, quaternion")
    if "pitch" in item:
        target = Target(pos, pitch=_number(item["pitch"], f"{where}.pitch", source) * angle)
    elif "rpy" in item:
        target = Target.from_rpy(pos, _numbers(item["rpy"], f"{where}.rpy", source, 3) * angle)
    elif "quaternion" in item:
        target = Target.from_quaternion(pos, _numbers(item["quaternion"], f"{where}.quaternion", source, 4))
    else:
        target = Target(pos)
    line = item.get("line", False)
    if not isinstance(line, bool):
        raise _fail(source, f"{where}.line must be true or false, got {line!r}")
    if line and k == 0:
        raise _fail(source, f"{where}.line: the first target has no previous target to draw a line from")
    dwell, stop, label = _extras(item, where, source)
    return target, dwell, stop, line, label


def parse_motion_request(data: Mapping[str, Any], source: str = "<request>") -> MotionRequest:
    """Parse a plan mapping (as read from YAML or JSON); see the module docstring.

    Raises:
        InvalidArgumentError: On any malformed entry (the message names the key and value).
    """
    if not isinstance(data, Mapping):
        raise _fail(source, f"a plan must be a mapping, got {type(data).__name__}")
    _unknown_keys(data, _TOP_KEYS, "the plan", source)
    units = data.get("units", {}) or {}
    if not isinstance(units, Mapping):
        raise _fail(source, f"units must be a mapping like {{length: cm, angle: deg}}, got {units!r}")
    _unknown_keys(units, ("length", "angle"), "units", source)
    lu, au = units.get("length", "m"), units.get("angle", "rad")
    if lu not in LENGTH_UNITS:
        raise _fail(source, f"unknown length unit {lu!r}; valid: {', '.join(LENGTH_UNITS)}")
    if au not in ANGLE_UNITS:
        raise _fail(source, f"unknown angle unit {au!r}; valid: {', '.join(ANGLE_UNITS)}")
    length, angle = LENGTH_UNITS[lu], ANGLE_UNITS[au]

    has_w, has_t = "waypoints" in data, "targets" in data
    if has_w == has_t:
        raise _fail(source, "give either 'waypoints' (joint vectors) or 'targets' (Cartesian), exactly one")
    items = data["waypoints"] if has_w else data["targets"]
    if not isinstance(items, Sequence) or isinstance(items, (str, bytes)):
        raise _fail(source, f"{'waypoints' if has_w else 'targets'} must be a list")
    if len(items) < 2:
        raise _fail(source, f"a plan needs at least two {'waypoints' if has_w else 'targets'}, got {len(items)}")
    dwell, stops, lines, labels = [], [], [], []
    joints = targets = None
    if has_w:
        rows = []
        for k, item in enumerate(items):
            q, dw, st, lb = _parse_waypoint(item, k, source)
            rows.append(q)
            dwell.append(dw)
            stops.append(st)
            labels.append(lb)
            lines.append(False)
        sizes = {len(r) for r in rows}
        if len(sizes) != 1:
            raise _fail(source, f"waypoints have different lengths: {[len(r) for r in rows]}")
        joints = np.array(rows)
    else:
        tl = []
        for k, item in enumerate(items):
            tg, dw, st, ln, lb = _parse_target(item, k, source, length, angle)
            tl.append(tg)
            dwell.append(dw)
            stops.append(st)
            lines.append(ln)
            labels.append(lb)
        targets = tuple(tl)

    limits = data.get("limits", {}) or {}
    if not isinstance(limits, Mapping):
        raise _fail(source, f"limits must be a mapping, got {limits!r}")
    _unknown_keys(limits, _LIMIT_KEYS, "limits", source)
    if "velocity" in limits and "servo_seconds_per_60deg" in limits:
        raise _fail(source, "limits: give either velocity or servo_seconds_per_60deg, not both")
    limits = {k: _limit_value(v, k, source) for k, v in limits.items()}

    start = data.get("start", {}) or {}
    if not isinstance(start, Mapping):
        raise _fail(source, f"start must be a mapping with q, velocity, acceleration, got {start!r}")
    _unknown_keys(start, ("q", "velocity", "acceleration"), "start", source)
    start_arrays = {
        k: (_numbers(start[k], f"start.{k}", source) if k in start else None) for k in ("q", "velocity", "acceleration")
    }

    sing = data.get("singularity", {}) or {}
    if not isinstance(sing, Mapping):
        raise _fail(source, f"singularity must be a mapping, got {sing!r}")
    _unknown_keys(sing, ("condition_number", "inverse_condition", "detours", "max_detours"), "singularity", source)
    if "condition_number" in sing and "inverse_condition" in sing:
        raise _fail(source, "singularity: give condition_number or inverse_condition, not both")
    cond = DEFAULT_CONDITION_NUMBER
    if "condition_number" in sing:
        cond = _number(sing["condition_number"], "singularity.condition_number", source)
        if cond <= 1.0:
            raise _fail(source, f"singularity.condition_number must be > 1, got {cond:g}")
    if "inverse_condition" in sing:
        inv = _number(sing["inverse_condition"], "singularity.inverse_condition", source)
        if not 0.0 < inv < 1.0:
            raise _fail(source, f"singularity.inverse_condition must lie in (0, 1), got {inv:g}")
        cond = 1.0 / inv
    detours = sing.get("detours", True)
    if not isinstance(detours, bool):
        raise _fail(source, f"singularity.detours must be true or false, got {detours!r}")
    max_detours = sing.get("max_detours", 8)
    if isinstance(max_detours, bool) or not isinstance(max_detours, int) or max_detours < 0:
        raise _fail(source, f"singularity.max_detours must be a non-negative integer, got {max_detours!r}")

    strategy = data.get("strategy", "optimized")
    if strategy not in ("optimized", "heuristic", "stop"):
        raise _fail(source, f"unknown strategy {strategy!r}; valid: optimized, heuristic, stop")
    servos = data.get("servos")
    if servos is not None:
        if not isinstance(servos, Sequence) or isinstance(servos, (str, bytes)):
            raise _fail(source, "servos must be a list with one mapping per joint")
        for k, s in enumerate(servos):
            if not isinstance(s, Mapping):
                raise _fail(source, f"servos[{k}] must be a mapping, got {s!r}")
            _unknown_keys(s, _SERVO_KEYS, f"servos[{k}]", source)
        servos = tuple(dict(s) for s in servos)
    period = data.get("servo_period_ms", 20)
    if isinstance(period, bool) or not isinstance(period, int) or not 1 <= period <= 65535:
        raise _fail(source, f"servo_period_ms must be an integer in [1, 65535], got {period!r}")

    return MotionRequest(
        joints=joints,
        targets=targets,
        dwell=np.array(dwell),
        stops=tuple(k for k, s in enumerate(stops) if s),
        lines=np.array(lines, dtype=bool),
        labels=tuple(labels),
        limits=limits,
        start_q=start_arrays["q"],
        start_velocity=start_arrays["velocity"],
        start_acceleration=start_arrays["acceleration"],
        condition_number=cond,
        detours=detours,
        max_detours=max_detours,
        strategy=strategy,
        servos=servos,
        servo_period_ms=period,
        angle_scale=angle,
        length_scale=length,
        source=source,
    )


def load_motion_request(path: str | Path) -> MotionRequest:
    """Read a plan file (YAML, or JSON for ``.json``); see the module docstring.

    Raises:
        InvalidArgumentError: If the file is missing, does not parse, or is malformed.
    """
    return parse_motion_request(read_data_file(path, "plan file"), source=str(path))


@dataclass(frozen=True)
class MotionPlan:
    """The result of :func:`plan_motion`.

    Attributes:
        robot: Robot name.
        trajectory: The joint trajectory (through the waypoints, line samples and detours).
        singularity: Singularity report of the trajectory.
        waypoints: The joint configuration of each requested waypoint, shape (N, dof).
        waypoint_times: When each is reached, shape (N,) [s].
        branches: Per waypoint, the IK branch taken (None for joint waypoints).
        singular_waypoints: Indices of requested waypoints below the singularity threshold.
        detours: Waypoints inserted around singularities.
        unresolved: Requested segments still dipping below the threshold with clear ends.
        line_deviation: Per requested segment, the largest distance of the tip from the
            straight line [m] for line segments, else None.
        limits: The limits planned with.
        calibrations: Servo calibration per joint.
        servo_period_ms: Period of the SSC-32 commands [ms].
    """

    robot: str
    trajectory: JointTrajectory
    singularity: SingularityReport
    waypoints: np.ndarray
    waypoint_times: np.ndarray
    branches: tuple[str | None, ...]
    singular_waypoints: tuple[int, ...]
    detours: tuple[Detour, ...]
    unresolved: tuple[int, ...]
    line_deviation: tuple[float | None, ...]
    limits: JointLimits
    calibrations: tuple[ServoCalibration, ...]
    servo_period_ms: int

    def summary(self, rate: float = 1000.0) -> dict[str, Any]:
        """A JSON-ready summary; the ratios are sampled peaks over the limits at `rate` [Hz]."""
        peaks = self.trajectory.peak_ratios(rate)
        return {
            "robot": self.robot,
            "joints": list(self.limits.joint_names),
            "duration": self.trajectory.duration,
            "waypoint_times": self.waypoint_times.tolist(),
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
            "detours": [
                {"segment": d.segment, "q": d.q.tolist(), "inverse_condition": d.inverse_condition}
                for d in self.detours
            ],
            "unresolved_segments": list(self.unresolved),
            "line_deviation": list(self.line_deviation),
            "strategy": self.trajectory.strategy,
            "sample_rate": rate,
        }

    def write_files(self, out: str | Path, rate: float = 1000.0) -> tuple[Path, ...]:
        """Write the plan's files into a directory (created if missing).

        Files: ``trajectory.csv`` (t, then q, qd, qdd, qddd per joint, SI units, at `rate`),
        ``servo_pulses.csv`` (pulse width per servo channel [us] every servo period),
        ``ssc32.txt`` (Lynxmotion SSC-32 group moves, one per servo period, each ended by a
        carriage return) and ``summary.json`` (:meth:`summary`).

        Args:
            out: Output directory.
            rate: Sample rate of the CSV and of the summary's limit checks [Hz].

        Returns:
            The paths written.

        Raises:
            InvalidArgumentError: If the directory cannot be created.
        """
        from planner.export.servo import pulse_table, ssc32_group_moves

        folder = Path(out)
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InvalidArgumentError(f"cannot create output directory {str(folder)!r}: {exc.strerror}") from exc
        paths = [self.trajectory.to_csv(folder / "trajectory.csv", rate=rate)]
        period = self.servo_period_ms
        t, pulses = pulse_table(self.trajectory, self.calibrations, rate=1000.0 / period)
        pulse_path = folder / "servo_pulses.csv"
        with pulse_path.open("w") as fh:
            fh.write(",".join(["t"] + [f"ch{c.channel}_{c.joint}" for c in self.calibrations]) + "\n")
            for ti, row in zip(t, pulses):
                fh.write(f"{ti:.6f}," + ",".join(str(int(x)) for x in row) + "\n")
        paths.append(pulse_path)
        commands = ssc32_group_moves(self.trajectory, self.calibrations, period_ms=period)
        ssc32_path = folder / "ssc32.txt"
        ssc32_path.write_bytes("".join(c + "\r" for c in commands).encode("ascii"))
        paths.append(ssc32_path)
        summary_path = folder / "summary.json"
        summary = self.summary(rate)
        summary["files"] = sorted(str(p) for p in [*paths, summary_path])
        summary_path.write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
        paths.append(summary_path)
        return tuple(paths)


def _joint_scale(robot: Robot, request: MotionRequest) -> np.ndarray:
    return np.array([request.length_scale if k == "prismatic" else request.angle_scale for k in robot.joint_kinds])


def _per_joint_si(value: float | np.ndarray, scale: np.ndarray) -> np.ndarray:
    """A limit in the file's units (one number or one per joint) in SI, per joint."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0 or arr.shape == scale.shape:
        return arr * scale
    return arr  # the wrong length: JointLimits names the joints in its error


def _calibrations(robot: Robot, request: MotionRequest) -> tuple[ServoCalibration, ...]:
    if request.servos is None:
        return default_calibrations(robot)
    if len(request.servos) != robot.dof:
        raise _fail(request.source, f"servos has {len(request.servos)} entries; {robot.name} has {robot.dof} joints")
    out = []
    for k, (s, name) in enumerate(zip(request.servos, robot.joint_names)):
        kw = dict(s)
        if "us_per_deg" in kw:
            if "us_per_rad" in kw:
                raise _fail(request.source, f"servos[{k}]: give us_per_rad or us_per_deg, not both")
            kw["us_per_rad"] = (
                _number(kw.pop("us_per_deg"), f"servos[{k}].us_per_deg", request.source) * 180.0 / math.pi
            )
        kw.setdefault("channel", k)
        out.append(ServoCalibration(joint=name, **kw))
    return tuple(out)


def plan_motion(robot: Robot, request: MotionRequest, *, rate: float = 1000.0) -> MotionPlan:
    """Plan a motion request for a robot: IK for targets, line sampling, trajectory, singularities.

    Args:
        robot: The robot.
        request: The parsed request.
        rate: Sampling rate of the singularity checks [Hz].

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
    limits = JointLimits.from_robot(robot, **lim_kw)
    threshold = 1.0 / request.condition_number

    def state(value: np.ndarray | None, what: str) -> np.ndarray | None:
        if value is None:
            return None
        if value.shape != (robot.dof,):
            names = ", ".join(robot.joint_names)
            raise _fail(src, f"start.{what} has {value.size} values; {robot.name} has {robot.dof} joints ({names})")
        return value * scale

    start_q = state(request.start_q, "q")
    start_v = state(request.start_velocity, "velocity")
    start_a = state(request.start_acceleration, "acceleration")
    if start_q is not None:
        robot.check_limits(start_q, context="start.q")

    n = request.count
    branches: list[str | None] = [None] * n
    # Each requested waypoint, then dense samples of line segments between them.
    nodes: list[np.ndarray] = []
    user_pos: list[int] = []
    line_ranges: list[tuple[int, int, int]] = []  # (user segment, first node, last node)
    line_timing = []
    if request.joints is not None:
        if request.joints.shape[1] != robot.dof:
            raise _fail(
                src,
                f"waypoints have {request.joints.shape[1]} values; {robot.name} has {robot.dof} joints "
                f"({', '.join(robot.joint_names)})",
            )
        q_user = request.joints * scale
        for k in range(n):
            user_pos.append(len(nodes))
            nodes.append(q_user[k])
        if start_q is not None and not np.allclose(start_q, q_user[0], atol=1e-9):
            raise _fail(src, "start.q differs from the first waypoint; with joint waypoints the first one is the start")
    else:
        from planner.motion.branch_choice import TargetSolver
        from planner.motion.line import line_waypoints
        from planner.motion.line_timing import time_line

        solver = TargetSolver(robot, threshold=threshold)
        q_prev = start_q
        for k, target in enumerate(request.targets):
            label = f"target {k}" + (f" ({request.labels[k]})" if request.labels[k] else "")
            if request.lines[k]:
                path = line_waypoints(solver, request.targets[k - 1], target, nodes[-1])
                timing = time_line(path, limits)
                first = len(nodes) - 1
                nodes.extend(path.q[1:])
                line_ranges.append((k - 1, first, len(nodes) - 1))
                line_timing.append(timing)
                branches[k] = "line"
                user_pos.append(len(nodes) - 1)
                q_prev = nodes[-1]
                continue
            choice = solver.choose(target, q_prev, label=label)
            branches[k] = choice.branch
            user_pos.append(len(nodes))
            nodes.append(np.array(choice.q))
            q_prev = nodes[-1]
        q_user = np.array([nodes[i] for i in user_pos])

    q_nodes = np.array(nodes)
    m = len(q_nodes)
    dwell = np.zeros(m)
    dwell[user_pos] = request.dwell
    stops = [user_pos[k] for k in request.stops]
    keep = sorted({s for _, a, b in line_ranges for s in range(a, b)})
    via_v = np.full(q_nodes.shape, np.nan)
    via_a = np.zeros(q_nodes.shape)
    min_dur = np.zeros(m - 1)
    for (_, a, b), timing in zip(line_ranges, line_timing):
        # A line is timed from rest to rest: its samples get the timing's states.
        via_v[a : b + 1] = timing.velocity
        via_a[a : b + 1] = timing.acceleration
        min_dur[a:b] = np.diff(timing.t)
        stops += [a, b]
    trajectory_request = TrajectoryRequest(
        q_nodes,
        limits,
        start_velocity=start_v,
        start_acceleration=start_a,
        stops=stops,
        dwell=dwell,
        strategy=request.strategy,
        via_velocities=via_v,
        via_accelerations=via_a,
        min_durations=min_dur,
    )
    options = SingularityOptions(
        threshold=threshold, rate=rate, max_detours=request.max_detours if request.detours else 0
    )
    plan = plan_clear_of_singularities(robot, trajectory_request, options, keep_segments=keep)
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
    if line_ranges:
        from planner.motion.line import line_deviation

        for seg, a, b in line_ranges:
            t0, t1 = traj.waypoint_times[node_idx[a]], traj.waypoint_times[node_idx[b]]
            t = np.linspace(t0, t1, max(2, int(math.ceil((t1 - t0) * rate)) + 1))
            deviation[seg] = line_deviation(
                robot, traj.sample(t).q, request.targets[seg].position, request.targets[seg + 1].position
            )
    return MotionPlan(
        robot=robot.name,
        trajectory=traj,
        singularity=plan.report,
        waypoints=_ro(q_user),
        waypoint_times=_ro(times),
        branches=tuple(branches),
        singular_waypoints=singular,
        detours=detours,
        unresolved=unresolved,
        line_deviation=tuple(deviation),
        limits=limits,
        calibrations=_calibrations(robot, request),
        servo_period_ms=request.servo_period_ms,
    )


def _ro(a: np.ndarray) -> np.ndarray:
    out = np.array(a, dtype=float, copy=True)
    out.setflags(write=False)
    return out
