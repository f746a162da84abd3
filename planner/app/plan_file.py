"""Plan files (the ``planner plan`` input) parsed into a :class:`MotionRequest`.

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
    singularity: {condition_number: 30, detours: true, max_detours: 8}   # default 30 (position), 100 (pose)
    strategy: optimized               # or heuristic, stop, refined
    blend_lines: true                 # lines blend into the moves around them (default); false: rest at their ends
    servos:                           # optional pulse-width calibration per joint
      - {channel: 0, pulse_at_zero: 1500, us_per_rad: 636.6, direction: 1, min_pulse: 500, max_pulse: 2500}
    servo_period_ms: 20
    controller: ssc32                 # optional: ssc32, pca9685, feetech, steps, pulses (the files written)
    calibration: my-arm.yaml          # optional calibration file (planner.export.calibration_file), instead of servos
    scene:                            # optional: what the arm must not touch (planner.collision.scene)
      floor: 0                        # floor height in the base frame [length]
      clearance: 0.5                  # distance kept to everything, links included [length]
      obstacles:
        - {name: block, box: [4, 4, 10], position: [20, 10, 5]}
    avoidance: {seed: 0, time_budget: 5}   # the path search around obstacles (seeded)

``line: true`` on a target makes the motion from the previous target to it a straight line.
A line blends into the joint moves before and after it (it starts or ends moving along the
line) unless the target at that end asks for a stop (``stop: true`` or a ``dwell``), is the
first or last one, or ``blend_lines: false``. Two lines meeting at a target stop there, unless
the second goes straight on from the first (the same direction and change of orientation or
pitch per metre) and the target asks for no stop: then the tip passes it without slowing down.
``allow: [block]`` on a waypoint or target lets the arm touch those scene bodies there (and on
the moves into and out of it), e.g. the block the gripper grasps. With a ``scene`` the plan
also keeps the arm's links apart from each other.
Angles (joint values, pitch, rpy, angular limits) use the ``angle`` unit, lengths (positions,
prismatic joints) the ``length`` unit; time is always seconds. Everything inside is SI.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from planner.collision.rrt import PathOptions
from planner.collision.scene import Scene, parse_scene
from planner.core.files import input_error, parse_number, parse_numbers, parse_units, read_data_file
from planner.core.text import plain
from planner.exceptions import InvalidArgumentError
from planner.export.formats import SERVO_FORMATS
from planner.geometry.target import Target
from planner.motion.vias import VIA_STRATEGIES

__all__ = ["MotionRequest", "load_motion_request", "parse_motion_request"]

_TOP_KEYS = (
    "units",
    "waypoints",
    "targets",
    "limits",
    "start",
    "singularity",
    "strategy",
    "blend_lines",
    "servos",
    "servo_period_ms",
    "controller",
    "calibration",
    "name",
    "comment",
    "scene",
    "avoidance",
)
_LIMIT_KEYS = ("velocity", "acceleration", "jerk", "servo_seconds_per_60deg")
_WAYPOINT_KEYS = ("q", "dwell", "stop", "label", "allow")
_TARGET_KEYS = ("position", "pitch", "rpy", "quaternion", "dwell", "stop", "line", "label", "allow")
_SERVO_KEYS = ("channel", "pulse_at_zero", "us_per_rad", "us_per_deg", "direction", "min_pulse", "max_pulse")


def _unknown_keys(obj: Mapping[str, Any], allowed: Sequence[str], where: str, source: str) -> None:
    extra = [k for k in obj if k not in allowed]
    if extra:
        raise input_error(source, f"unknown key {extra[0]!r} in {where}; valid keys: {', '.join(allowed)}")


def _limit_value(value: Any, what: str, source: str) -> float | np.ndarray:
    """A limit as given: one number or a list; positivity is checked against the robot later."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        x = float(value)
        if math.isnan(x):
            raise input_error(source, f"limits.{what} is NaN")
        return x
    if isinstance(value, Sequence) and not isinstance(value, (str, bytes)):
        out = []
        for k, v in enumerate(value):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise input_error(source, f"limits.{what}[{k}] must be a number, got {v!r}")
            out.append(float(v))
        return np.array(out)
    raise input_error(source, f"limits.{what} must be a number or a list of numbers, got {plain(value)}")


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
        condition_number: Singularity threshold as a Jacobian condition number; None is the
            default of the robot's task (:data:`planner.motion.singularity.DEFAULT_CONDITION_NUMBERS`).
        detours: Whether to insert detours around singularities.
        max_detours: Most detours to insert.
        strategy: Via strategy (see :func:`planner.motion.trajectory.plan_trajectory`).
        blend_lines: Whether lines blend into the joint moves before and after them where the
            waypoint there asks for no stop (see the module doc).
        servos: Servo calibration mappings as written, or None for defaults.
        servo_period_ms: Time between two servo updates in the servo files [ms].
        controller: The controller named (a key of ``SERVO_FORMATS``), or None.
        calibration: Calibration file path, or None.
        angle_scale: Radians per file angle unit.
        length_scale: Metres per file length unit.
        scene: What the arm must not touch (SI), or None for no collision checks.
        allow: Per waypoint, the scene bodies it may touch.
        path_options: Settings of the path search around obstacles.
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
    condition_number: float | None = None
    detours: bool = True
    max_detours: int = 8
    strategy: str = "optimized"
    blend_lines: bool = True
    servos: tuple[Mapping[str, Any], ...] | None = None
    servo_period_ms: int = 20
    controller: str | None = None
    calibration: Path | None = None
    angle_scale: float = 1.0
    length_scale: float = 1.0
    scene: Scene | None = None
    allow: tuple[tuple[str, ...], ...] = ()
    path_options: PathOptions = field(default_factory=PathOptions)
    source: str = "<request>"

    @property
    def count(self) -> int:
        """Number of waypoints or targets."""
        return len(self.dwell)


def _parse_waypoint(item: Any, k: int, source: str) -> tuple[np.ndarray, float, bool, str | None]:
    if isinstance(item, Mapping):
        _unknown_keys(item, _WAYPOINT_KEYS, f"waypoints[{k}]", source)
        if "q" not in item:
            raise input_error(source, f"waypoints[{k}] needs a 'q' list of joint values")
        q = parse_numbers(item["q"], f"waypoints[{k}].q", source)
        return q, *_extras(item, f"waypoints[{k}]", source)
    return parse_numbers(item, f"waypoints[{k}]", source), 0.0, False, None


def _extras(item: Mapping[str, Any], where: str, source: str) -> tuple[float, bool, str | None]:
    dwell = parse_number(item.get("dwell", 0.0), f"{where}.dwell", source)
    if dwell < 0:
        raise input_error(source, f"{where}.dwell must be >= 0 [s], got {dwell:g}")
    stop = item.get("stop", False)
    if not isinstance(stop, bool):
        raise input_error(source, f"{where}.stop must be true or false, got {stop!r}")
    label = item.get("label")
    return dwell, stop, None if label is None else str(label)


def _allow(item: Any, where: str, source: str) -> tuple[str, ...]:
    if not isinstance(item, Mapping) or "allow" not in item:
        return ()
    names = item["allow"]
    if isinstance(names, str):
        names = [names]
    if not isinstance(names, Sequence) or not all(isinstance(n, str) for n in names):
        raise input_error(source, f"{where}.allow must be a list of scene names, got {plain(names)}")
    return tuple(names)


def _parse_target(
    item: Any, k: int, source: str, length: float, angle: float
) -> tuple[Target, float, bool, bool, str | None]:
    where = f"targets[{k}]"
    if not isinstance(item, Mapping):
        raise input_error(source, f"{where} must be a mapping with a 'position', got {item!r}")
    _unknown_keys(item, _TARGET_KEYS, where, source)
    if "position" not in item:
        raise input_error(source, f"{where} needs a 'position' [x, y, z]")
    pos = parse_numbers(item["position"], f"{where}.position", source, 3) * length
    given = [key for key in ("pitch", "rpy", "quaternion") if key in item]
    if len(given) > 1:
        raise input_error(source, f"{where} gives {' and '.join(given)}; give at most one of pitch, rpy, quaternion")
    if "pitch" in item:
        target = Target(pos, pitch=parse_number(item["pitch"], f"{where}.pitch", source) * angle)
    elif "rpy" in item:
        target = Target.from_rpy(pos, parse_numbers(item["rpy"], f"{where}.rpy", source, 3) * angle)
    elif "quaternion" in item:
        target = Target.from_quaternion(pos, parse_numbers(item["quaternion"], f"{where}.quaternion", source, 4))
    else:
        target = Target(pos)
    line = item.get("line", False)
    if not isinstance(line, bool):
        raise input_error(source, f"{where}.line must be true or false, got {line!r}")
    if line and k == 0:
        raise input_error(source, f"{where}.line: the first target has no previous target to draw a line from")
    dwell, stop, label = _extras(item, where, source)
    return target, dwell, stop, line, label


def parse_motion_request(data: Mapping[str, Any], source: str = "<request>") -> MotionRequest:
    """Parse a plan mapping (as read from YAML or JSON); see the module docstring.

    Raises:
        InvalidArgumentError: On any malformed entry (the message names the key and value).
    """
    if not isinstance(data, Mapping):
        raise input_error(source, f"a plan must be a mapping, got {type(data).__name__}")
    _unknown_keys(data, _TOP_KEYS, "the plan", source)
    units = data.get("units", {}) or {}
    if not isinstance(units, Mapping):
        raise input_error(source, f"units must be a mapping like {{length: cm, angle: deg}}, got {units!r}")
    _unknown_keys(units, ("length", "angle"), "units", source)
    length, angle = parse_units(units.get("length", "m"), units.get("angle", "rad"), source)

    has_w, has_t = "waypoints" in data, "targets" in data
    if has_w == has_t:
        raise input_error(source, "give either 'waypoints' (joint vectors) or 'targets' (Cartesian), exactly one")
    items = data["waypoints"] if has_w else data["targets"]
    if not isinstance(items, Sequence) or isinstance(items, (str, bytes)):
        raise input_error(source, f"{'waypoints' if has_w else 'targets'} must be a list")
    if len(items) < 2:
        raise input_error(source, f"a plan needs at least two {'waypoints' if has_w else 'targets'}, got {len(items)}")
    dwell, stops, lines, labels = [], [], [], []
    allow = [_allow(item, f"{'waypoints' if has_w else 'targets'}[{k}]", source) for k, item in enumerate(items)]
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
            raise input_error(source, f"waypoints have different lengths: {[len(r) for r in rows]}")
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
        raise input_error(source, f"limits must be a mapping, got {limits!r}")
    _unknown_keys(limits, _LIMIT_KEYS, "limits", source)
    if "velocity" in limits and "servo_seconds_per_60deg" in limits:
        raise input_error(source, "limits: give either velocity or servo_seconds_per_60deg, not both")
    limits = {k: _limit_value(v, k, source) for k, v in limits.items()}

    start = data.get("start", {}) or {}
    if not isinstance(start, Mapping):
        raise input_error(source, f"start must be a mapping with q, velocity, acceleration, got {start!r}")
    _unknown_keys(start, ("q", "velocity", "acceleration"), "start", source)
    start_arrays = {
        k: (parse_numbers(start[k], f"start.{k}", source) if k in start else None)
        for k in ("q", "velocity", "acceleration")
    }

    sing = data.get("singularity", {}) or {}
    if not isinstance(sing, Mapping):
        raise input_error(source, f"singularity must be a mapping, got {sing!r}")
    _unknown_keys(sing, ("condition_number", "inverse_condition", "detours", "max_detours"), "singularity", source)
    if "condition_number" in sing and "inverse_condition" in sing:
        raise input_error(source, "singularity: give condition_number or inverse_condition, not both")
    cond: float | None = None
    if "condition_number" in sing:
        cond = parse_number(sing["condition_number"], "singularity.condition_number", source)
        if cond <= 1.0:
            raise input_error(source, f"singularity.condition_number must be > 1, got {cond:g}")
    if "inverse_condition" in sing:
        inv = parse_number(sing["inverse_condition"], "singularity.inverse_condition", source)
        if not 0.0 < inv < 1.0:
            raise input_error(source, f"singularity.inverse_condition must lie in (0, 1), got {inv:g}")
        cond = 1.0 / inv
    detours = sing.get("detours", True)
    if not isinstance(detours, bool):
        raise input_error(source, f"singularity.detours must be true or false, got {detours!r}")
    max_detours = sing.get("max_detours", 8)
    if isinstance(max_detours, bool) or not isinstance(max_detours, int) or max_detours < 0:
        raise input_error(source, f"singularity.max_detours must be a non-negative integer, got {plain(max_detours)}")

    strategy = data.get("strategy", "optimized")
    blend_lines = data.get("blend_lines", True)
    if not isinstance(blend_lines, bool):
        raise input_error(source, f"blend_lines must be true or false, got {blend_lines!r}")
    if not isinstance(strategy, str) or strategy not in VIA_STRATEGIES:
        raise input_error(source, f"unknown strategy {plain(strategy)}; valid: {', '.join(VIA_STRATEGIES)}")
    servos = data.get("servos")
    if servos is not None:
        if not isinstance(servos, Sequence) or isinstance(servos, (str, bytes)):
            raise input_error(source, "servos must be a list with one mapping per joint")
        for k, s in enumerate(servos):
            if not isinstance(s, Mapping):
                raise input_error(source, f"servos[{k}] must be a mapping, got {s!r}")
            _unknown_keys(s, _SERVO_KEYS, f"servos[{k}]", source)
        servos = tuple(dict(s) for s in servos)
    period = data.get("servo_period_ms", 20)
    if isinstance(period, bool) or not isinstance(period, int) or not 1 <= period <= 65535:
        raise input_error(source, f"servo_period_ms must be an integer in [1, 65535], got {plain(period)}")
    controller = data.get("controller")
    if controller is not None and (not isinstance(controller, str) or controller not in SERVO_FORMATS):
        raise input_error(
            source, f"unknown controller {plain(controller)}; valid controllers: {', '.join(SERVO_FORMATS)}"
        )
    calibration = data.get("calibration")
    if calibration is not None:
        if not isinstance(calibration, str) or not calibration:
            raise input_error(source, f"calibration must be a file path, got {plain(calibration)}")
        if servos is not None:
            raise input_error(source, "give servos or a calibration file, not both")
        calibration = Path(calibration)
        if not calibration.is_absolute() and source != "<request>":
            calibration = Path(source).parent / calibration

    scene = None
    if "scene" in data:
        scene = parse_scene(data["scene"], length_scale=length, angle_scale=angle, source=source)
    for k, names in enumerate(allow):
        if names:
            if scene is None:
                raise input_error(source, f"{'waypoints' if has_w else 'targets'}[{k}].allow needs a scene")
            try:
                scene.check_names(names, f"{'waypoints' if has_w else 'targets'}[{k}].allow")
            except InvalidArgumentError as exc:
                raise input_error(source, str(exc)) from exc
    avoidance = data.get("avoidance", {}) or {}
    if not isinstance(avoidance, Mapping):
        raise input_error(
            source, f"avoidance must be a mapping like {{seed: 0, time_budget: 5}}, got {plain(avoidance)}"
        )
    _unknown_keys(avoidance, ("seed", "time_budget"), "avoidance", source)
    try:
        path_options = PathOptions(**dict(avoidance))
    except (InvalidArgumentError, TypeError) as exc:
        raise input_error(source, f"avoidance: {exc}") from exc

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
        blend_lines=blend_lines,
        servos=servos,
        servo_period_ms=period,
        controller=controller,
        calibration=calibration,
        angle_scale=angle,
        length_scale=length,
        scene=scene,
        allow=tuple(allow),
        path_options=path_options,
        source=source,
    )


def load_motion_request(path: str | Path) -> MotionRequest:
    """Read a plan file (YAML, or JSON for ``.json``); see the module docstring.

    Raises:
        InvalidArgumentError: If the file is missing, does not parse, or is malformed.
    """
    return parse_motion_request(read_data_file(path, "plan file"), source=str(path))
