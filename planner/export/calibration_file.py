"""Calibration files: which controller drives an arm, and how each joint maps to it (YAML or JSON).

A calibration file names the controller (a key of
:data:`planner.export.formats.SERVO_FORMATS`) and gives one servo per joint::

    robot: al5c                 # optional; checked against the arm it is used with
    controller: ssc32           # ssc32, pca9685, pulses (pulse widths [us]), feetech, steps (ticks)
    settings: {pwm_frequency_hz: 50}   # optional controller settings (pca9685; feetech: series)
    servos:                     # in joint order, or each with its joint's name
      - {joint: base_yaw, channel: 0, zero: 1500, direction: 1, scale: 636.62, limits: [500, 2500]}

``channel`` (or ``id`` for a bus servo) addresses the servo; ``zero`` is the controller value at
joint angle 0, ``scale`` the change per radian (or ``scale_per_deg`` per degree), ``direction``
+1 or -1, ``limits`` the smallest and largest value allowed. Values are pulse widths [us] for
pulse controllers and position ticks for ``feetech`` and ``steps``. Calibrations shipped with
`planner` are in ``planner/export/calibrations`` (:func:`shipped_calibration`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from planner.core.files import input_error, parse_number, parse_numbers, read_data_file
from planner.core.text import plain
from planner.exceptions import PlannerError
from planner.export.calibration import ServoCalibration, check_calibrations
from planner.export.formats import SERVO_FORMATS, ServoFormat, servo_format
from planner.export.ticks import TickCalibration

if TYPE_CHECKING:
    from planner.model.robot import Robot

__all__ = ["ControllerSetup", "controller_setup", "load_calibration", "parse_calibration", "shipped_calibration"]

_TOP_KEYS = ("robot", "controller", "settings", "servos", "comment")
_SERVO_KEYS = ("joint", "channel", "id", "zero", "direction", "scale", "scale_per_deg", "limits")
#: Each calibration kind's fields for a file's zero, scale and limits.
_FIELDS = {
    ServoCalibration: ("pulse_at_zero", "us_per_rad", ("min_pulse", "max_pulse")),
    TickCalibration: ("ticks_at_zero", "ticks_per_rad", ("min_ticks", "max_ticks")),
}


@dataclass(frozen=True)
class ControllerSetup:
    """A controller and the calibration of every joint on it.

    Attributes:
        controller: The controller's format name (a key of ``SERVO_FORMATS``), or None for the
            default pulse-width outputs.
        calibrations: One per joint, in joint order.
        settings: Controller settings (e.g. ``pwm_frequency_hz``).
        source: Where the calibrations came from, for messages.
    """

    controller: str | None
    calibrations: tuple[Any, ...]
    settings: Mapping[str, Any] = field(default_factory=dict)
    source: str = "defaults"

    def formats(self) -> tuple[ServoFormat, ...]:
        """The formats to write: the controller's, or every default one when none is named."""
        if self.controller is None:
            return tuple(f for f in SERVO_FORMATS.values() if f.written_by_default)
        return (servo_format(self.controller).configured(self.settings),)


def _servo(item: Any, k: int, kind: type, joint: str, source: str) -> Any:
    where = f"servos[{k}]"
    if not isinstance(item, Mapping):
        raise input_error(source, f"{where} must be a mapping, got {item!r}")
    extra = [key for key in item if key not in _SERVO_KEYS]
    if extra:
        raise input_error(source, f"unknown key {extra[0]!r} in {where}; valid keys: {', '.join(_SERVO_KEYS)}")
    if ("channel" in item) == ("id" in item):
        raise input_error(source, f"{where} needs its address: give channel (or id for a bus servo), exactly one")
    if "scale" in item and "scale_per_deg" in item:
        raise input_error(source, f"{where}: give scale [per rad] or scale_per_deg, not both")
    address = item.get("channel", item.get("id"))
    zero, scale, (low, high) = _FIELDS[kind]
    args: dict[str, Any] = {"joint": joint}
    if "direction" in item:
        args["direction"] = item["direction"]
    if "zero" in item:
        args[zero] = parse_number(item["zero"], f"{where}.zero", source)
    if "scale" in item:
        args[scale] = parse_number(item["scale"], f"{where}.scale", source)
    if "scale_per_deg" in item:
        args[scale] = parse_number(item["scale_per_deg"], f"{where}.scale_per_deg", source) * 180.0 / math.pi
    if "limits" in item:
        args[low], args[high] = parse_numbers(item["limits"], f"{where}.limits", source, 2).tolist()
    try:
        return kind(address, **args)
    except PlannerError as exc:  # the calibration's own message, located in the file
        raise input_error(source, f"{where}: {exc}") from exc


def parse_calibration(data: Any, robot: Robot, source: str = "<calibration>") -> ControllerSetup:
    """Parse a calibration mapping (as read from YAML or JSON) for a robot; see the module docstring.

    Raises:
        InvalidArgumentError: On a malformed entry, an unknown controller or setting, a servo
            count or joint name that does not match the robot, or two servos on one channel.
    """
    if not isinstance(data, Mapping):
        raise input_error(source, f"a calibration file must be a mapping, got {type(data).__name__}")
    extra = [key for key in data if key not in _TOP_KEYS]
    if extra:
        raise input_error(source, f"unknown key {extra[0]!r}; valid keys: {', '.join(_TOP_KEYS)}")
    if "robot" in data and str(data["robot"]) != robot.name:
        raise input_error(source, f"this calibration is for robot {data['robot']!r}, not {robot.name!r}")
    controller = data.get("controller")
    if not isinstance(controller, str) or controller not in SERVO_FORMATS:
        raise input_error(
            source, f"unknown controller {plain(controller)}; valid controllers: {', '.join(SERVO_FORMATS)}"
        )
    settings = data.get("settings", {}) or {}
    if not isinstance(settings, Mapping):
        raise input_error(source, f"settings must be a mapping, got {settings!r}")
    fmt = SERVO_FORMATS[controller]
    try:
        fmt.configured(settings)
    except PlannerError as exc:
        raise input_error(source, str(exc)) from exc
    servos = data.get("servos")
    if not isinstance(servos, list) or len(servos) != robot.dof:
        count = len(servos) if isinstance(servos, list) else 0
        raise input_error(
            source,
            f"servos must list one servo per joint: {robot.name} has {robot.dof} "
            f"({', '.join(robot.joint_names)}), got {count}",
        )
    named = [isinstance(s, Mapping) and "joint" in s for s in servos]
    if any(named) and not all(named):
        raise input_error(source, "give every servo its joint name, or none (then they are in joint order)")
    order = list(range(robot.dof))
    if all(named):
        by_name = {str(s["joint"]): k for k, s in enumerate(servos)}
        unknown = [n for n in by_name if n not in robot.joint_names]
        if unknown or len(by_name) != robot.dof:
            bad = unknown[0] if unknown else "a repeated joint"
            raise input_error(source, f"servo joint {bad!r} does not match; joints: {', '.join(robot.joint_names)}")
        order = [by_name[n] for n in robot.joint_names]
    cals = tuple(_servo(servos[k], k, fmt.calibration_type, name, source) for k, name in zip(order, robot.joint_names))
    try:
        check_calibrations(cals, robot.dof, fmt.calibration_type)
    except PlannerError as exc:
        raise input_error(source, str(exc)) from exc
    return ControllerSetup(controller, cals, dict(settings), source)


def load_calibration(path: str | Path, robot: Robot) -> ControllerSetup:
    """Read a calibration file (YAML, or JSON for ``.json``) for a robot; see the module docstring.

    Raises:
        InvalidArgumentError: If the file is missing, does not parse, or is malformed.
    """
    return parse_calibration(read_data_file(path, "calibration file"), robot, source=str(path))


def shipped_calibration(robot_name: str, controller: str) -> Path | None:
    """The calibration file shipped for an arm on a controller (``<robot>-<controller>.yaml``), or None."""
    path = Path(str(resources.files("planner.export.calibrations").joinpath(f"{robot_name}-{controller}.yaml")))
    return path if path.is_file() else None


def controller_setup(
    robot: Robot,
    controller: str | None = None,
    calibration: str | Path | None = None,
    servos: tuple[ServoCalibration, ...] | None = None,
    *,
    travel: tuple[np.ndarray, np.ndarray] | None = None,
) -> ControllerSetup:
    """The controller and calibrations to use, from what was asked for.

    In order: a calibration file (its controller must agree with `controller` when both are
    given); pulse calibrations given elsewhere (`servos`, e.g. a plan file's ``servos:``); the
    file shipped for this arm on `controller`; the controller's defaults (fitted to `travel`,
    the smallest and largest angle of each joint in the plan [rad], where a joint has no range).

    Raises:
        InvalidArgumentError: On an unknown controller, a disagreement between the controller
            and the calibration, or a controller with no default calibration.
    """
    if controller is not None and (not isinstance(controller, str) or controller not in SERVO_FORMATS):
        raise input_error(
            None, f"unknown controller {plain(controller)}; valid controllers: {', '.join(SERVO_FORMATS)}"
        )
    if calibration is not None:
        setup = load_calibration(calibration, robot)
        if controller is not None and setup.controller != controller:
            raise input_error(
                str(calibration), f"this calibration is for controller {setup.controller!r}, not {controller!r}"
            )
        return setup
    kind = SERVO_FORMATS[controller].calibration_type if controller else ServoCalibration
    if servos is not None:
        if kind is not ServoCalibration:
            raise input_error(
                None, f"controller {controller!r} needs a calibration file (servos: in a plan gives pulse widths)"
            )
        return ControllerSetup(controller, tuple(servos), {}, "plan servos")
    if controller is not None:
        shipped = shipped_calibration(robot.name, controller)
        if shipped is not None:
            return load_calibration(shipped, robot)
        defaults = SERVO_FORMATS[controller].default_calibrations(robot, travel=travel)
        return ControllerSetup(controller, defaults, {}, "defaults")
    return ControllerSetup(None, SERVO_FORMATS["ssc32"].default_calibrations(robot, travel=travel), {}, "defaults")
