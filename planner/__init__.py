"""planner: inverse kinematics and servo-speed-limited motion for robot arms from URDF.

Data flows one way: URDF -> :class:`Robot` (Pinocchio model) -> IK -> waypoints ->
trajectory -> samples / servo commands. SI units throughout (m, rad, s).
"""

from .description import dh_transform, load_arm_description, servo_speed_to_velocity, urdf_from_dh
from .exceptions import (
    InvalidArgumentError,
    InvalidConfigurationError,
    InvalidLimitsError,
    JointLimitError,
    PlannerError,
    UnknownFrameError,
    UnknownRobotError,
    UnsupportedChainError,
    URDFError,
)
from .robot import Robot
from .robots import available_robots, load_robot
from .sensing import range_bearing_to_base
from .target import Target, quaternion_to_matrix, rotation_error, rpy_to_matrix

__version__ = "0.1.0"

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
    "range_bearing_to_base",
    # errors
    "PlannerError",
    "URDFError",
    "InvalidLimitsError",
    "UnknownFrameError",
    "UnknownRobotError",
    "InvalidConfigurationError",
    "JointLimitError",
    "InvalidArgumentError",
    "UnsupportedChainError",
]
