"""The ``planner`` command line.

Every subcommand has a ``_add_<name>`` function that declares its arguments and a
``_run_<name>`` function that does the work and returns the exit code. Angles on the command
line are radians unless ``--deg`` is given; lengths are metres. Errors print one line to
stderr and exit 1 (2 for usage errors, as argparse does).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from .description import urdf_from_dh
from .exceptions import PlannerError
from .robots import BUNDLED_ROBOTS, available_robots, load_robot

__all__ = ["main", "build_parser"]


def _print_json(obj: object) -> None:
    print(json.dumps(obj, indent=2, allow_nan=False))


def _angles(values: Sequence[float], deg: bool) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    return np.radians(arr) if deg else arr


def _table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    cells = [[str(h) for h in headers]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[k]) for r in cells) for k in range(len(headers))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


# ---------------------------------------------------------------------------- robots
def _add_robots(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("robots", help="list the robots that can be loaded by name")
    p.add_argument("--json", action="store_true", help="print a JSON object keyed by robot name")


def _run_robots(args: argparse.Namespace) -> int:
    info = {}
    for name in available_robots():
        robot = load_robot(name)
        info[name] = {
            "dof": robot.dof,
            "joints": list(robot.joint_names),
            "lower": robot.lower.tolist(),
            "upper": robot.upper.tolist(),
            "velocity": robot.velocity_limit.tolist(),
            "tip": robot.tip,
            "bundled": name in BUNDLED_ROBOTS,
        }
    if args.json:
        _print_json(info)
        return 0
    rows = [
        (name, d["dof"], d["tip"], "bundled" if d["bundled"] else "example-robot-data", ", ".join(d["joints"]))
        for name, d in info.items()
    ]
    print(_table(["robot", "dof", "tip", "source", "joints"], rows))
    return 0


# ---------------------------------------------------------------------------- fk
def _add_fk(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fk", help="forward kinematics: the tip pose for joint values")
    p.add_argument("robot", help="robot name (see `planner robots`) or URDF path")
    p.add_argument("q", nargs="+", type=float, help="joint values, base to tip [rad or m; deg with --deg]")
    p.add_argument("--deg", action="store_true", help="revolute joint values are in degrees")
    p.add_argument("--tip", default=None, help="tip frame (default: the arm's tool frame)")
    p.add_argument("--json", action="store_true", help="print JSON")


def _run_fk(args: argparse.Namespace) -> int:
    robot = load_robot(args.robot, tip=args.tip)
    q = np.asarray(args.q, dtype=float)
    if args.deg and q.shape == (robot.dof,):
        q = np.where(np.array(robot.joint_kinds) == "prismatic", q, np.radians(q))
    q = robot.check_configuration(q, batch=False)
    pose = robot.fk(q)
    result = {
        "robot": robot.name,
        "tip": robot.tip,
        "q": q.tolist(),
        "position": pose[:3, 3].tolist(),
        "matrix": pose.tolist(),
        "manipulability": robot.manipulability(q),
        "within_limits": bool(robot.within_limits(q)),
    }
    if args.json:
        _print_json(result)
    else:
        x, y, z = result["position"]
        print(f"{robot.name} tip {robot.tip!r}: position [m] = ({x:.6f}, {y:.6f}, {z:.6f})")
        print(np.array2string(pose, precision=6, suppress_small=True))
        print(f"manipulability {result['manipulability']:.6g}, within limits: {result['within_limits']}")
    return 0


# ---------------------------------------------------------------------------- urdf-from-dh
def _add_urdf_from_dh(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "urdf-from-dh",
        help="write a URDF for an arm described by a DH table (YAML or JSON)",
        description="Print the URDF for a compact arm description; see planner.description for the format.",
    )
    p.add_argument("table", type=Path, help="arm description file (.yaml or .json)")


def _run_urdf_from_dh(args: argparse.Namespace) -> int:
    sys.stdout.write(urdf_from_dh(args.table))
    return 0


# ---------------------------------------------------------------------------- demo
def _add_demo(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="the main job: a planning run on the bundled arms")
    p.add_argument("--seed", type=int, default=0, help="seed of the random configurations")


def _run_demo(args: argparse.Namespace) -> int:
    rng = np.random.default_rng(args.seed)
    rows = []
    for name in BUNDLED_ROBOTS:
        robot = load_robot(name)
        q = robot.random_configurations(rng, 200)
        pos = robot.position(q)
        w = robot.manipulability(q)
        reach = f"{np.max(np.linalg.norm(pos, axis=1)):.4f}"
        rows.append((name, robot.dof, robot.tip, reach, f"{np.min(w):.3g}", f"{np.max(w):.3g}"))
    print("Forward kinematics of 200 random configurations within limits per bundled arm")
    print(_table(["robot", "dof", "tip", "max reach seen [m]", "min manip.", "max manip."], rows))
    return 0


_COMMANDS: dict[str, tuple[Callable[[argparse._SubParsersAction], None], Callable[[argparse.Namespace], int]]] = {
    "robots": (_add_robots, _run_robots),
    "fk": (_add_fk, _run_fk),
    "urdf-from-dh": (_add_urdf_from_dh, _run_urdf_from_dh),
    "demo": (_add_demo, _run_demo),
}


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``planner`` command."""
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="planner",
        description="Inverse kinematics and servo-speed-limited trajectories for robot arms from URDF.",
    )
    parser.add_argument("--version", action="version", version=f"planner {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add, _ in _COMMANDS.values():
        add(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``planner`` command; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return _COMMANDS[args.command][1](args)
    except PlannerError as exc:
        print(f"planner {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except BrokenPipeError:
        return 0
