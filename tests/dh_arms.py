"""Arms and inputs for the property tests: the bundled arms, and random DH tables built into
robots by our own generator (`planner.urdf_from_dh`), the way a user with a DH table would.

Everything here goes through the public API (`planner.load_robot`, `planner.urdf_from_dh`,
`planner.Robot`, `planner.Target`, `planner.approach_pitch`); Pinocchio is used directly only
to check answers independently (`tip_errors`).
"""

from __future__ import annotations

import contextlib
import functools
import math
import os

import numpy as np
import pinocchio as pin
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

import planner

# The arms bundled with the package (`planner.available_robots()` also lists the optional
# example-robot-data arms, which are not installed everywhere).
BUNDLED = ("shelley", "al5c", "three_joint", "dh3")

# Unit scales written into generated files, stated here so the tests do not borrow the
# package's own table: metres per length unit, radians per angle unit.
LENGTH_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}
ANGLE_SCALE = {"rad": 1.0, "deg": math.pi / 180.0}

_FLOAT = {"allow_nan": False, "allow_infinity": False, "allow_subnormal": False}


def property_settings(examples: int) -> settings:
    """The property tests' hypothesis settings: `examples` examples, derandomized, no deadline."""
    return settings(
        max_examples=examples,
        deadline=None,
        derandomize=True,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )


@functools.cache
def bundled_robot(name: str) -> planner.Robot:
    """A bundled robot, loaded once per test session (do not mutate it)."""
    return planner.load_robot(name)


@functools.lru_cache(maxsize=64)
def _robot_from_urdf(urdf: str, tip: str) -> planner.Robot:
    return planner.Robot(urdf, tip=tip)


def arm_specs() -> st.SearchStrategy[str | dict]:
    """A bundled arm's name (three times in four) or a random DH description.

    Tests draw the spec and build the robot with :func:`arm`, so a failing example prints
    the whole description, from which the robot can be rebuilt.
    """
    return st.one_of(st.sampled_from(BUNDLED), st.sampled_from(BUNDLED), st.sampled_from(BUNDLED), dh_descriptions())


def arm(spec: str | dict) -> planner.Robot:
    """The robot of a spec from :func:`arm_specs`."""
    return bundled_robot(spec) if isinstance(spec, str) else robot_from_description(spec)


def robot_from_description(description: dict) -> planner.Robot:
    """The robot a user gets from a DH description: `Robot(urdf_from_dh(description), tip=...)`."""
    tip = description.get("tool", {}).get("name", "tool")
    return _robot_from_urdf(planner.urdf_from_dh(description), tip)


@st.composite
def dh_descriptions(draw, min_joints: int = 2, max_joints: int = 6) -> dict:
    """A random arm description: 2-6 revolute DH rows, limits within [-pi, pi], random units.

    Geometry values mix special ones (0, +-pi/2, pi: the shapes the closed-form families
    recognise) with arbitrary ones, so some generated arms have a closed form and most do not.
    The mapping is written in the drawn units, as a user's file would be.
    """
    length_unit = draw(st.sampled_from(sorted(LENGTH_SCALE)))
    angle_unit = draw(st.sampled_from(sorted(ANGLE_SCALE)))
    to_length, to_angle = 1.0 / LENGTH_SCALE[length_unit], 1.0 / ANGLE_SCALE[angle_unit]
    special = st.sampled_from([0.0, math.pi / 2, -math.pi / 2, math.pi])
    angle = st.one_of(special, st.floats(-math.pi, math.pi, **_FLOAT))
    length = st.one_of(st.just(0.0), st.floats(-0.3, 0.3, **_FLOAT))
    rows = []
    for k in range(draw(st.integers(min_joints, max_joints))):
        lower = draw(st.floats(-math.pi, math.pi - 0.02, **_FLOAT))
        upper = draw(st.floats(lower + 0.01, math.pi, **_FLOAT))
        row = {
            "name": f"j{k + 1}",
            "theta": draw(angle) * to_angle,
            "d": draw(length) * to_length,
            "a": draw(length) * to_length,
            "alpha": draw(angle) * to_angle,
            "lower": lower * to_angle,
            "upper": upper * to_angle,
        }
        if draw(st.booleans()):
            row["velocity"] = draw(st.floats(0.2, 8.0, **_FLOAT)) * to_angle  # [angle unit / s]
        rows.append(row)
    description = {
        "name": "random_dh",
        "units": {"length": length_unit, "angle": angle_unit},
        "servo_seconds_per_60deg": draw(st.floats(0.05, 1.0, **_FLOAT)),
        "dh": rows,
    }
    if draw(st.booleans()):
        xyz = [draw(st.floats(-0.1, 0.1, **_FLOAT)) * to_length for _ in range(3)]
        description["tool"] = {"name": "tip", "xyz": xyz}
    return description


def configurations(robot: planner.Robot) -> st.SearchStrategy[np.ndarray]:
    """Joint vectors within the robot's limits (bounds included), shape (dof,) [rad or m]."""
    return st.tuples(*(st.floats(float(lo), float(hi), **_FLOAT) for lo, hi in zip(robot.lower, robot.upper))).map(
        lambda q: np.array(q, dtype=float)
    )


def reach_bound(robot: planner.Robot) -> float:
    """An upper bound [m] on the distance of the tip from the base origin, over all configurations.

    The distance between consecutive joint origins (and from the last one to the tip) does not
    change with q, so their sum bounds the tip's distance from the base.
    """
    points = robot.joint_positions(np.clip(np.zeros(robot.dof), robot.lower, robot.upper))
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))


@st.composite
def targets(draw, robot: planner.Robot) -> tuple[planner.Target, str]:
    """A target and where it lies: ``"reachable"`` (FK of q within the limits), ``"random"``
    (a point in a box around the workspace, reachable or not) or ``"far"`` (beyond any reach).

    The kind is a position, a pose (`rotation=`) or an approach pitch (`pitch=`).
    """
    kind = draw(st.sampled_from(["position", "pose", "pitch"]))
    where = draw(st.sampled_from(["reachable", "random", "far"]))
    if where == "reachable":
        q = draw(configurations(robot))
        pose = robot.fk(q)
        if kind == "pose":
            return planner.Target(pose[:3, 3], rotation=pose[:3, :3]), where
        if kind == "pitch":
            return planner.Target(pose[:3, 3], pitch=planner.approach_pitch(robot, q)), where
        return planner.Target(pose[:3, 3]), where
    reach = reach_bound(robot)
    if where == "random":
        box = 1.2 * reach + 0.01
        position = np.array([draw(st.floats(-box, box, **_FLOAT)) for _ in range(3)])
    else:
        direction = np.array([draw(st.floats(-1.0, 1.0, **_FLOAT)) for _ in range(3)])
        norm = float(np.linalg.norm(direction))
        direction = direction / norm if norm > 1e-3 else np.array([1.0, 0.0, 0.0])
        position = direction * (draw(st.floats(1.05, 20.0, **_FLOAT)) * reach + 1e-3)
    if kind == "pose":
        rpy = [draw(st.floats(-math.pi, math.pi, **_FLOAT)) for _ in range(3)]
        return planner.Target.from_rpy(position, rpy), where
    if kind == "pitch":
        return planner.Target(position, pitch=draw(st.floats(-math.pi, math.pi, **_FLOAT))), where
    return planner.Target(position), where


def seeds(robot: planner.Robot) -> st.SearchStrategy[np.ndarray | None]:
    """None or a joint vector within the limits."""
    return st.one_of(st.none(), configurations(robot))


def tip_errors(robot: planner.Robot, target: planner.Target, q: np.ndarray) -> tuple[float, float, float]:
    """Errors of a configuration for a target, computed here from Pinocchio FK.

    Returns:
        ``(position error [m], orientation error [rad], elevation error [rad])``: the
        orientation error is the rotation angle to the target rotation (pose), the package's
        documented :func:`planner.pitch_error` of the approach axis (pitch), else 0; the
        elevation error is, for a pitch target, the difference of the approach axis's
        elevation from the pitch's (a lower bound of any angle to a direction with that
        pitch, computed without the package), else 0.
    """
    pose = robot.fk(q)
    position_error = float(np.linalg.norm(pose[:3, 3] - target.position))
    rotation = pose[:3, :3]
    if target.rotation is not None:
        return position_error, float(np.linalg.norm(pin.log3(target.rotation.T @ rotation))), 0.0
    if target.pitch is not None:
        axis = rotation @ robot.approach_axis
        elevation = math.atan2(axis[2], math.hypot(axis[0], axis[1]))
        wanted = math.atan2(math.sin(target.pitch), abs(math.cos(target.pitch)))
        pitch_error = float(planner.pitch_error(axis, target.position, target.pitch))
        return position_error, pitch_error, abs(elevation - wanted)
    return position_error, 0.0, 0.0


@contextlib.contextmanager
def uncompiled_nlp():
    """Run the NLP's CasADi functions in CasADi's virtual machine (``PLANNER_JIT=0``) meanwhile.

    Each generated arm is new to the solver's compiled-code cache: compiling its C code takes
    0.2-0.3 s per target kind, and shrinking a failure meets hundreds of arms. The virtual
    machine gives the same answers (the package's documented fallback), only slower per call.
    """
    old = os.environ.get("PLANNER_JIT")
    os.environ["PLANNER_JIT"] = "0"
    try:
        yield
    finally:
        if old is None:
            del os.environ["PLANNER_JIT"]
        else:
            os.environ["PLANNER_JIT"] = old
