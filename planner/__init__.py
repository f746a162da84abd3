"""planner: inverse kinematics and servo-speed-limited motion for robot arms from URDF.

Data flows one way: URDF -> :class:`Robot` (Pinocchio model) -> IK -> waypoints ->
trajectory -> samples / servo commands. SI units throughout (m, rad, s).

The names below are imported when first used (``import planner`` itself loads neither
Pinocchio nor CasADi); the exceptions are imported at once.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from planner.exceptions import (
    ControllerError,
    InvalidArgumentError,
    InvalidConfigurationError,
    InvalidLimitsError,
    JointLimitError,
    PlannerError,
    PlanningError,
    ServoExportError,
    StartPositionError,
    TargetFileError,
    UnknownFrameError,
    UnknownRobotError,
    UnsupportedChainError,
    URDFError,
)

if TYPE_CHECKING:
    from planner.app.motion_plan import MotionPlan, plan_motion
    from planner.app.plan_file import load_motion_request, parse_motion_request
    from planner.app.send import send_plan
    from planner.core.rotations import quaternion_to_matrix, rotation_error, rpy_to_matrix
    from planner.core.units import servo_speed_to_velocity
    from planner.core.version import __version__
    from planner.export.calibration import ServoCalibration, angle_to_steps, default_calibrations, steps_to_angle
    from planner.export.formats.ssc32 import ssc32_group_moves
    from planner.export.tables import pulse_table
    from planner.geometry.sensing import range_bearing_to_base
    from planner.geometry.target import Target, approach_pitch, pitch_error
    from planner.hardware.session import SendOptions, SendResult, SendStatus
    from planner.ik.analytic import (
        AnalyticBatchResult,
        AnalyticIK,
        AnalyticResult,
        AnalyticSolution,
        closed_form_solver,
    )
    from planner.ik.cross_check import CrossCheck, cross_check
    from planner.ik.numeric.kinematics import CasadiKinematics
    from planner.ik.numeric.solver import NlpIK
    from planner.ik.options import IKOptions
    from planner.ik.result import IKResult, IKSolution
    from planner.ik.solve import solve_analytic, solve_ik
    from planner.ik.status import IKStatus
    from planner.model.catalog import available_robots, load_robot
    from planner.model.description import dh_transform, load_arm_description, urdf_from_dh
    from planner.model.robot import Robot
    from planner.motion.detours import SingularityOptions, plan_clear_of_singularities
    from planner.motion.limits import JointLimits
    from planner.motion.plan import plan_trajectory, plan_trajectory_request
    from planner.motion.request import TrajectoryRequest
    from planner.motion.singularity import check_singularities
    from planner.motion.trajectory import JointTrajectory

__all__ = [
    "__version__",
    # robot model
    "Robot",
    "load_robot",
    "available_robots",
    # arm descriptions
    "urdf_from_dh",
    "load_arm_description",
    "dh_transform",
    "servo_speed_to_velocity",
    # targets and sensing
    "Target",
    "rpy_to_matrix",
    "quaternion_to_matrix",
    "rotation_error",
    "approach_pitch",
    "pitch_error",
    "range_bearing_to_base",
    # closed-form IK
    "AnalyticIK",
    "closed_form_solver",
    "solve_analytic",
    "AnalyticResult",
    "AnalyticSolution",
    "AnalyticBatchResult",
    # numerical IK, dispatcher and cross-check
    "NlpIK",
    "IKOptions",
    "IKResult",
    "IKSolution",
    "IKStatus",
    "CasadiKinematics",
    "solve_ik",
    "cross_check",
    "CrossCheck",
    # trajectories, singularities, servo export
    "JointLimits",
    "JointTrajectory",
    "plan_trajectory",
    "TrajectoryRequest",
    "plan_trajectory_request",
    "SingularityOptions",
    "check_singularities",
    "plan_clear_of_singularities",
    "ServoCalibration",
    "default_calibrations",
    "pulse_table",
    "ssc32_group_moves",
    "angle_to_steps",
    "steps_to_angle",
    "MotionPlan",
    "load_motion_request",
    "plan_motion",
    # driving a real arm
    "send_plan",
    "SendOptions",
    "SendResult",
    "SendStatus",
    "parse_motion_request",
    # errors
    "PlannerError",
    "PlanningError",
    "ControllerError",
    "StartPositionError",
    "ServoExportError",
    "URDFError",
    "InvalidLimitsError",
    "UnknownFrameError",
    "UnknownRobotError",
    "InvalidConfigurationError",
    "JointLimitError",
    "InvalidArgumentError",
    "UnsupportedChainError",
    "TargetFileError",
]

#: Where each lazily imported public name lives (the same names as the imports above).
_LAZY: dict[str, tuple[str, ...]] = {
    "planner.app.motion_plan": ("MotionPlan", "plan_motion"),
    "planner.app.plan_file": ("load_motion_request", "parse_motion_request"),
    "planner.app.send": ("send_plan",),
    "planner.hardware.session": ("SendOptions", "SendResult", "SendStatus"),
    "planner.core.rotations": ("quaternion_to_matrix", "rotation_error", "rpy_to_matrix"),
    "planner.core.units": ("servo_speed_to_velocity",),
    "planner.core.version": ("__version__",),
    "planner.export.calibration": ("ServoCalibration", "angle_to_steps", "default_calibrations", "steps_to_angle"),
    "planner.export.formats.ssc32": ("ssc32_group_moves",),
    "planner.export.tables": ("pulse_table",),
    "planner.geometry.sensing": ("range_bearing_to_base",),
    "planner.geometry.target": ("Target", "approach_pitch", "pitch_error"),
    "planner.ik.analytic": (
        "AnalyticBatchResult",
        "AnalyticIK",
        "AnalyticResult",
        "AnalyticSolution",
        "closed_form_solver",
    ),
    "planner.ik.cross_check": ("CrossCheck", "cross_check"),
    "planner.ik.numeric.kinematics": ("CasadiKinematics",),
    "planner.ik.numeric.solver": ("NlpIK",),
    "planner.ik.options": ("IKOptions",),
    "planner.ik.result": ("IKResult", "IKSolution"),
    "planner.ik.solve": ("solve_analytic", "solve_ik"),
    "planner.ik.status": ("IKStatus",),
    "planner.model.catalog": ("available_robots", "load_robot"),
    "planner.model.description": ("dh_transform", "load_arm_description", "urdf_from_dh"),
    "planner.model.robot": ("Robot",),
    "planner.motion.detours": ("SingularityOptions", "plan_clear_of_singularities"),
    "planner.motion.limits": ("JointLimits",),
    "planner.motion.plan": ("plan_trajectory", "plan_trajectory_request"),
    "planner.motion.request": ("TrajectoryRequest",),
    "planner.motion.singularity": ("check_singularities",),
    "planner.motion.trajectory": ("JointTrajectory",),
}
_MODULE_OF = {name: module for module, names in _LAZY.items() for name in names}
_SUBPACKAGES = ("core", "model", "geometry", "ik", "motion", "export", "hardware", "app")


def __getattr__(name: str) -> Any:
    """Import a public name (or a subpackage) on first use."""
    if name in _SUBPACKAGES:
        return importlib.import_module(f"planner.{name}")
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'planner' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The module's names, the lazy ones included."""
    return sorted(set(globals()) | set(__all__))
