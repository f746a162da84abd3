"""Compact arm descriptions (a Denavit-Hartenberg table or a joint list) turned into URDF.

Every seed document describes its arm by a DH table; a user with such a table gets a URDF
from :func:`urdf_from_dh`. The description is a mapping (as read from YAML or JSON)::

    name: dh3
    comment: free text written into the URDF
    units: {length: cm, angle: deg}      # optional, default m and rad
    servo_seconds_per_60deg: 0.20        # default joint speed, or `velocity` per joint
    dh:                                  # standard DH, one row per joint
      - {name: base, theta: 0, d: 3, a: 0, alpha: 90, lower: -135, upper: 135}
      - ...
    tool: {name: claw, xyz: [0, 0, 0], rpy: [0, 0, 0]}   # optional fixed tip offset
    collision: {radius: 1.5}             # optional capsule radius of every link

Each link gets collision and visual geometry: a capsule (a cylinder closed by two spheres,
written as those three URDF primitives) along the offset to the next joint, split into the
part along the joint axis and the rest. Its radius is ``radius`` on the joint's row (the
tool's for the last link), else ``collision.radius``, else 5 % of the sum of the offsets;
``collision: false`` writes none.

Standard DH convention: the transform from frame i-1 to frame i is
``Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``; joint i turns about (revolute) or slides
along (prismatic) ``z_{i-1}``. For a revolute row, `theta` is the offset added to the joint
variable (the URDF's zero is DH theta = offset); for a prismatic row, `d` is the offset.

Instead of `dh`, a `joints` list places each joint explicitly relative to the previous
joint's frame: ``{name, type, xyz, rpy, axis, lower, upper, velocity}`` (the URDF joint
origin); `tool` then places the tip relative to the last joint.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.sax.saxutils import escape

import numpy as np

from planner.core.files import parse_number, parse_numbers, parse_units, read_data_file
from planner.core.rotations import homogeneous, matrix_to_rpy, rpy_to_matrix
from planner.core.text import plain
from planner.core.units import servo_speed_to_velocity
from planner.exceptions import InvalidArgumentError, InvalidLimitsError

__all__ = [
    "dh_transform",
    "load_arm_description",
    "urdf_from_dh",
]

_JOINT_TYPES = ("revolute", "prismatic", "continuous")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")


def dh_transform(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """Standard Denavit-Hartenberg transform ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``.

    Args:
        theta: Joint angle [rad].
        d: Offset along the previous z axis [m].
        a: Length along the new x axis [m].
        alpha: Twist about the new x axis [rad].

    Returns:
        The 4x4 homogeneous transform from frame i-1 to frame i.
    """
    ct, st = math.cos(theta), math.sin(theta)
    ca, sa = math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def load_arm_description(path: str | Path) -> dict[str, Any]:
    """Read an arm description from a YAML or JSON file.

    Args:
        path: File path; ``.json`` is read as JSON, anything else as YAML.

    Returns:
        The description as a plain mapping.

    Raises:
        InvalidArgumentError: If the file is missing or does not parse to a mapping.
    """
    data = read_data_file(path, "arm description")
    if not isinstance(data, Mapping):
        raise InvalidArgumentError(f"arm description {str(path)!r} must be a mapping, got {type(data).__name__}")
    return dict(data)


@dataclass(frozen=True)
class _Joint:
    name: str
    kind: str
    origin: np.ndarray  # 4x4, parent frame -> joint frame
    axis: tuple[float, float, float]
    lower: float
    upper: float
    velocity: float
    effort: float


def _vector(value: Any, what: str, scale: float) -> np.ndarray:
    return parse_numbers(value, what, length=3) * scale


def _pose(xyz: np.ndarray, rpy: np.ndarray) -> np.ndarray:
    return homogeneous(rpy_to_matrix(rpy), xyz)


def _joint_velocity(row: Mapping[str, Any], default: Mapping[str, Any], angular: float, name: str) -> float:
    for source in (row, default):
        if "velocity" in source:
            v = parse_number(source["velocity"], f"joint {name!r} velocity")
            if v <= 0:
                raise InvalidLimitsError(f"joint {name!r} velocity must be positive, got {v!r}", joint=name, value=v)
            return v * angular
        if "servo_seconds_per_60deg" in source:
            s = parse_number(source["servo_seconds_per_60deg"], f"joint {name!r} servo_seconds_per_60deg")
            if s <= 0:
                raise InvalidLimitsError(
                    f"joint {name!r} servo_seconds_per_60deg must be positive, got {s!r}", joint=name, value=s
                )
            return servo_speed_to_velocity(s)
    raise InvalidArgumentError(
        f"joint {name!r} has no speed: give `velocity` or `servo_seconds_per_60deg` for it or for the whole arm"
    )


def _limits(row: Mapping[str, Any], kind: str, scale: float, name: str) -> tuple[float, float]:
    if kind == "continuous":
        return -math.inf, math.inf
    for key in ("lower", "upper"):
        if key not in row:
            raise InvalidArgumentError(f"joint {name!r} needs `lower` and `upper` limits (missing {key!r})")
    lower = parse_number(row["lower"], f"joint {name!r} lower") * scale
    upper = parse_number(row["upper"], f"joint {name!r} upper") * scale
    if lower > upper:
        raise InvalidLimitsError(
            f"joint {name!r} has lower limit {lower:.6g} > upper limit {upper:.6g}", joint=name, value=(lower, upper)
        )
    return lower, upper


def _parse_joints(desc: Mapping[str, Any], length: float, angle: float) -> tuple[list[_Joint], np.ndarray]:
    """Joint frames (origins relative to the previous joint frame) and the last fixed offset."""
    joints: list[_Joint] = []
    if ("dh" in desc) == ("joints" in desc):
        raise InvalidArgumentError("an arm description needs exactly one of `dh` (a DH table) or `joints` (a list)")
    rows = desc.get("dh", desc.get("joints"))
    if not isinstance(rows, Sequence) or isinstance(rows, str) or not rows:
        raise InvalidArgumentError("`dh`/`joints` must be a non-empty list of rows")
    effort_default = parse_number(desc.get("effort", 1.0), "effort")
    previous_fixed = np.eye(4)
    seen: set[str] = set()
    for i, row in enumerate(rows, start=1):
        if not isinstance(row, Mapping):
            raise InvalidArgumentError(f"row {i} must be a mapping, got {row!r}")
        name = str(row.get("name", f"joint{i}"))
        if not _NAME.match(name) or name in seen:
            raise InvalidArgumentError(f"row {i}: joint name {name!r} is invalid or repeated")
        seen.add(name)
        kind = str(row.get("type", "revolute"))
        if kind not in _JOINT_TYPES:
            raise InvalidArgumentError(f"joint {name!r}: unknown type {kind!r}; valid types: {', '.join(_JOINT_TYPES)}")
        limit_scale = length if kind == "prismatic" else angle
        lower, upper = _limits(row, kind, limit_scale, name)
        velocity = _joint_velocity(row, desc, limit_scale, name)
        effort = parse_number(row.get("effort", effort_default), f"joint {name!r} effort")
        if "dh" in desc:
            for key in ("d", "a", "alpha"):
                if key not in row:
                    raise InvalidArgumentError(f"DH row {i} ({name!r}) is missing {key!r}")
            theta = parse_number(row.get("theta", 0.0), f"joint {name!r} theta") * angle
            d = parse_number(row["d"], f"joint {name!r} d") * length
            a = parse_number(row["a"], f"joint {name!r} a") * length
            alpha = parse_number(row["alpha"], f"joint {name!r} alpha") * angle
            origin, axis = previous_fixed, (0.0, 0.0, 1.0)
            previous_fixed = dh_transform(theta, d, a, alpha)
        else:
            xyz = _vector(row.get("xyz", [0, 0, 0]), f"joint {name!r} xyz", length)
            rpy = _vector(row.get("rpy", [0, 0, 0]), f"joint {name!r} rpy", angle)
            ax = _vector(row.get("axis", [0, 0, 1]), f"joint {name!r} axis", 1.0)
            norm = float(np.linalg.norm(ax))
            if norm == 0.0:
                raise InvalidArgumentError(f"joint {name!r} axis must not be zero")
            origin, axis = _pose(xyz, rpy), tuple(float(v) for v in ax / norm)
            previous_fixed = np.eye(4)
        joints.append(_Joint(name, kind, origin, axis, lower, upper, velocity, effort))  # type: ignore[arg-type]
    return joints, previous_fixed


def _link_radii(
    desc: Mapping[str, Any], joints: list[_Joint], tool: Mapping[str, Any], offsets: list[np.ndarray], length: float
) -> list[float]:
    """Capsule radius [m] of each joint's link (0 for none)."""
    settings = desc.get("collision", {})
    if settings is False:
        return [0.0] * len(joints)
    if not isinstance(settings, Mapping):
        raise InvalidArgumentError(f"`collision` must be a mapping such as {{radius: 0.02}} or false, got {settings!r}")
    total = sum(float(np.linalg.norm(t[:3, 3])) for t in offsets)
    default = parse_number(settings["radius"], "collision radius") * length if "radius" in settings else 0.05 * total
    rows = desc.get("dh", desc.get("joints"))
    radii = []
    for k, j in enumerate(joints):
        row = tool if k == len(joints) - 1 and "radius" in tool else rows[k]
        r = parse_number(row["radius"], f"joint {j.name!r} radius") * length if "radius" in row else default
        if not (math.isfinite(r) and r >= 0):
            raise InvalidArgumentError(f"joint {j.name!r}: the link radius must be >= 0, got {r!r}")
        radii.append(r)
    return radii


def _link_xml(name: str, offset: np.ndarray, radius: float) -> list[str]:
    """A link whose capsule runs from its joint to `offset` (along the joint's z, then the rest)."""
    corner = np.array([0.0, 0.0, offset[2]])
    points = [np.zeros(3), corner, offset]
    segments = [(a, b) for a, b in zip(points, points[1:]) if np.linalg.norm(b - a) > 1e-12]
    if radius <= 0 or not segments:
        return [f'  <link name="{name}"/>']
    shapes = []
    for a, b in segments:
        axis = (b - a) / np.linalg.norm(b - a)
        helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(helper, axis)
        x /= np.linalg.norm(x)
        pose = homogeneous(np.column_stack([x, np.cross(axis, x), axis]), (a + b) / 2)
        shapes.append((pose, f'<cylinder radius="{_fmt(radius)}" length="{_fmt(float(np.linalg.norm(b - a)))}"/>'))
    ends = []
    for p in [segments[0][0]] + [b for _, b in segments]:
        if not any(np.allclose(p, e) for e in ends):
            ends.append(p)
    shapes += [(homogeneous(np.eye(3), p), f'<sphere radius="{_fmt(radius)}"/>') for p in ends]
    out = [f'  <link name="{name}">']
    for tag in ("visual", "collision"):
        for pose, geometry in shapes:
            out.append(f"    <{tag}>{_origin_xml(pose)}<geometry>{geometry}</geometry></{tag}>")
    out.append("  </link>")
    return out


def _fmt(x: float) -> str:
    if abs(x) < 1e-15:
        return "0"
    # Unit conversion leaves float noise (67.31 mm -> 0.06731000000000001 m); drop it when
    # the short form is within two ulps, keep full precision otherwise (pi/2 stays exact).
    short = f"{x:.15g}"
    if abs(float(short) - x) <= 2 * np.spacing(abs(x)):
        return short
    return repr(float(x))


def _origin_xml(t: np.ndarray) -> str:
    xyz = " ".join(_fmt(v) for v in t[:3, 3])
    rpy = " ".join(_fmt(v) for v in matrix_to_rpy(t[:3, :3]))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def _section(desc: Mapping[str, Any], key: str, example: str) -> Mapping[str, Any]:
    """An optional mapping of the description (empty when absent or null)."""
    value = desc.get(key) or {}
    if not isinstance(value, Mapping):
        raise InvalidArgumentError(f"`{key}` must be a mapping such as {example}, got {plain(value)}")
    return value


def urdf_from_dh(description: Mapping[str, Any] | str | Path) -> str:
    """Build a URDF from a compact arm description (DH table or joint list).

    Args:
        description: The description mapping, or a path to a YAML/JSON file holding it. See
            the module docstring for the keys.

    Returns:
        URDF XML text: a serial chain ``base_link -> <joint>_link ... -> tip`` with position
        limits [rad or m], velocity limits [rad/s or m/s] and a fixed tip frame named by
        ``tool.name`` (default ``"tool"``).

    Raises:
        InvalidArgumentError: If a key is missing or malformed.
        InvalidLimitsError: If a joint has lower > upper or a non-positive speed.
    """
    desc = load_arm_description(description) if isinstance(description, (str, Path)) else description
    if not isinstance(desc, Mapping):
        raise InvalidArgumentError(f"an arm description must be a mapping, got {type(desc).__name__}")
    name = str(desc.get("name", "arm"))
    units = _section(desc, "units", "{length: cm, angle: deg}")
    length, angle = parse_units(str(units.get("length", "m")), str(units.get("angle", "rad")))

    joints, last_fixed = _parse_joints(desc, length, angle)
    tool = _section(desc, "tool", "{name: tool, xyz: [0, 0, 0.05]}")
    tip = str(tool.get("name", "tool"))
    link_names = ["base_link", *(f"{j.name}_link" for j in joints), tip]
    if len(set(link_names)) != len(link_names) or not _NAME.match(tip):
        raise InvalidArgumentError(
            f"link names must be unique and valid; this description makes {', '.join(link_names)} "
            "(each joint's link is named <joint>_link; rename the joint or the tool)"
        )
    tool_pose = _pose(
        _vector(tool.get("xyz", [0, 0, 0]), "tool xyz", length), _vector(tool.get("rpy", [0, 0, 0]), "tool rpy", angle)
    )
    base = _section(desc, "base", "{xyz: [0, 0, 0.1], rpy: [0, 0, 0]}")
    base_pose = _pose(
        _vector(base.get("xyz", [0, 0, 0]), "base xyz", length), _vector(base.get("rpy", [0, 0, 0]), "base rpy", angle)
    )

    offsets = [base_pose @ joints[0].origin] + [j.origin for j in joints[1:]] + [last_fixed @ tool_pose]
    radii = _link_radii(desc, joints, tool, offsets, length)
    lines = ['<?xml version="1.0"?>']
    comment = str(desc.get("comment", "")).strip()
    header = f"Generated by planner.urdf_from_dh from the description of {name!r}."
    body = (header + "\n" + comment).replace("--", "- -")
    lines.append("<!--\n" + "\n".join("  " + ln if ln else "" for ln in body.splitlines()) + "\n-->")
    lines.append(f'<robot name="{escape(name)}">')
    lines.append('  <link name="base_link"/>')
    parent = "base_link"
    for k, j in enumerate(joints):
        origin = base_pose @ j.origin if k == 0 else j.origin
        child = f"{j.name}_link"
        lines.extend(_link_xml(child, offsets[k + 1][:3, 3], radii[k]))
        lines.append(f'  <joint name="{j.name}" type="{j.kind}">')
        lines.append(f'    <parent link="{parent}"/>')
        lines.append(f'    <child link="{child}"/>')
        lines.append(f"    {_origin_xml(origin)}")
        lines.append(f'    <axis xyz="{" ".join(_fmt(v) for v in j.axis)}"/>')
        limits = "" if j.kind == "continuous" else f'lower="{_fmt(j.lower)}" upper="{_fmt(j.upper)}" '
        lines.append(f'    <limit {limits}effort="{_fmt(j.effort)}" velocity="{_fmt(j.velocity)}"/>')
        lines.append("  </joint>")
        parent = child
    tip_pose = last_fixed @ tool_pose
    lines.append(f'  <link name="{escape(tip)}"/>')
    lines.append(f'  <joint name="{escape(tip)}_fixed" type="fixed">')
    lines.append(f'    <parent link="{parent}"/>')
    lines.append(f'    <child link="{escape(tip)}"/>')
    lines.append(f"    {_origin_xml(tip_pose)}")
    lines.append("  </joint>")
    lines.append("</robot>")
    return "\n".join(lines) + "\n"
