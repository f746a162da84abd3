"""Robots by name: the bundled seed arms and, when installed, example-robot-data arms."""

from __future__ import annotations

import functools
import importlib.metadata
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from planner.core.version import install_hint
from planner.exceptions import UnknownRobotError
from planner.model.robot import Robot

__all__ = [
    "BUNDLED_ROBOTS",
    "EXAMPLE_ROBOTS",
    "RobotSpec",
    "available_robots",
    "bundled_urdf_path",
    "example_robot_data_dir",
    "load_robot",
]


@dataclass(frozen=True)
class RobotSpec:
    """How to load a named robot.

    Attributes:
        urdf: URDF file name (bundled) or path below example-robot-data's ``robots`` folder.
        tip: Default tip frame (the tool frame).
        approach_axis: The tip's approach axis in tip-frame coordinates.
    """

    urdf: str
    tip: str
    approach_axis: tuple[float, float, float]


_X, _Z = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)

#: Bundled seed arms. The DH-frame tips of shelley, three_joint and dh3 point along x.
BUNDLED_ROBOTS: Mapping[str, RobotSpec] = {
    "shelley": RobotSpec("shelley.urdf", "claw", _X),
    "al5c": RobotSpec("al5c.urdf", "gripper", _Z),
    "three_joint": RobotSpec("three_joint.urdf", "gripper", _X),
    "dh3": RobotSpec("dh3.urdf", "hand", _X),
}

#: example-robot-data arms, loaded when that package is installed.
EXAMPLE_ROBOTS: Mapping[str, RobotSpec] = {
    "ur5": RobotSpec("ur_description/urdf/ur5_robot.urdf", "tool0", _Z),
    "panda": RobotSpec("panda_description/urdf/panda.urdf", "panda_hand_tcp", _Z),
    "so101": RobotSpec("so_arm_description/urdf/so101.urdf", "gripper_frame_link", _Z),
    "z1": RobotSpec("z1_description/urdf/z1.urdf", "gripperStator", _X),
}


def bundled_urdf_path(name: str) -> Path:
    """Path of a bundled arm's URDF file.

    Raises:
        UnknownRobotError: If `name` is not bundled (the message lists the bundled names).
    """
    if name not in BUNDLED_ROBOTS:
        raise UnknownRobotError(name, BUNDLED_ROBOTS)
    return bundled_urdf_dir() / BUNDLED_ROBOTS[name].urdf


@functools.cache
def bundled_urdf_dir() -> Path:
    """The folder of the bundled arms' URDF and YAML files.

    An installed package maps the repository's top-level ``urdf/`` folder to ``planner.urdf``;
    imported from the source tree (the repository root on ``sys.path``, e.g. ``python -m
    planner`` run there) that mapping does not exist, and the folder is read where it is.
    """
    try:
        return Path(str(resources.files("planner.urdf")))
    except ModuleNotFoundError:
        return Path(__file__).resolve().parents[2] / "urdf"


@functools.cache
def example_robot_data_dir() -> Path | None:
    """The ``robots`` folder of the installed example-robot-data package, or None."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:
        return None
    for f in dist.files or ():
        parts = Path(str(f)).parts
        if "robots" in parts and parts[-1].endswith(".urdf"):
            root = Path(str(dist.locate_file(Path(*parts[: parts.index("robots") + 1]))))
            if root.is_dir():
                return root
    return None


def available_robots() -> tuple[str, ...]:
    """Names :func:`load_robot` accepts on this machine: bundled, then installed example arms."""
    names = list(BUNDLED_ROBOTS)
    if example_robot_data_dir() is not None:
        names += list(EXAMPLE_ROBOTS)
    return tuple(names)


def load_robot(name: str | Path, tip: str | None = None, *, locked: Mapping[str, float] | None = None) -> Robot:
    """Load a robot by bundled name, example-robot-data name, or URDF file path.

    Args:
        name: ``"shelley"``, ``"al5c"``, ``"three_joint"``, ``"dh3"``; ``"ur5"``, ``"panda"``,
            ``"so101"``, ``"z1"`` when example-robot-data is installed; or a path to a URDF.
        tip: Tip frame; None uses the arm's tool frame.
        locked: Values [rad or m] for joints off the base-to-tip chain (e.g. grippers).

    Returns:
        The robot.

    Raises:
        UnknownRobotError: If the name is none of these (the message lists the valid names).
        URDFError: If the URDF is malformed.
        UnknownFrameError: If `tip` does not exist.
    """
    key = str(name)
    if key in BUNDLED_ROBOTS or key in EXAMPLE_ROBOTS:
        if key in BUNDLED_ROBOTS:
            spec, path = BUNDLED_ROBOTS[key], bundled_urdf_path(key)
        else:
            root = example_robot_data_dir()
            if root is None:
                raise UnknownRobotError(
                    key, available_robots(), hint=f"install example-robot-data, e.g. {install_hint('bench')}"
                )
            spec = EXAMPLE_ROBOTS[key]
            path = root / spec.urdf
        # The default approach axis belongs to the default tip; another tip keeps z.
        axis = spec.approach_axis if tip in (None, spec.tip) else _Z
        return Robot.from_urdf(
            path, tip or spec.tip, name=key, locked=locked, approach_axis=axis, validate=key not in BUNDLED_ROBOTS
        )
    path = Path(key)
    if path.suffix.lower() == ".urdf" or path.is_file():
        return Robot.from_urdf(path, tip, locked=locked)
    raise UnknownRobotError(key, available_robots(), hint="or give a path to a .urdf file")
