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
from typing import TYPE_CHECKING

import numpy as np

from planner.core.text import to_json
from planner.exceptions import InvalidArgumentError, PlannerError, ServoExportError
from planner.geometry.target import Target
from planner.model.catalog import BUNDLED_ROBOTS, available_robots, load_robot
from planner.model.description import urdf_from_dh
from planner.model.robot import Robot

if TYPE_CHECKING:
    from planner.app.motion_plan import MotionPlan
    from planner.app.plan_file import MotionRequest
    from planner.ik.options import IKOptions
    from planner.ik.result import IKResult

__all__ = ["main", "build_parser"]


def _print_json(obj: object) -> None:
    print(to_json(obj))


def _angles(values: Sequence[float], deg: bool, what: str = "angle", turn: float = 2 * np.pi) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if deg:
        return np.radians(arr)
    _warn_if_degrees(arr, what, turn)
    return arr


def _warn_if_degrees(values: np.ndarray, what: str, turn: float = 2 * np.pi) -> None:
    """Warn on stderr when radians look like degrees (a magnitude beyond `turn`)."""
    big = np.abs(values[np.isfinite(values)]) > turn
    if np.any(big):
        value = float(values[np.isfinite(values)][big][0])
        print(
            f"planner: warning: {what} {value:g} rad is more than {'half ' if turn < 4 else ''}a turn; "
            "did you mean degrees (--deg)?",
            file=sys.stderr,
        )


def _joint_values(values: Sequence[float], robot: Robot, deg: bool, what: str) -> np.ndarray:
    """Joint values from the command line in SI units (degrees converted for angular joints)."""
    q = np.asarray(values, dtype=float)
    if q.shape != (robot.dof,):
        return robot.check_configuration(q, batch=False)  # raises, naming the expected shape
    angular = np.array(robot.joint_kinds) != "prismatic"
    if deg:
        q = np.where(angular, np.radians(q), q)
    else:
        _warn_if_degrees(q[angular], what)
    return robot.check_configuration(q, batch=False)


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


# ---------------------------------------------------------------------------- examples
def _add_examples(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("examples", help="list the example plan files, or copy them into a folder")
    p.add_argument("--out", type=Path, default=None, help="copy the example plan files into this folder")


def _run_examples(args: argparse.Namespace) -> int:
    from planner.app.examples import example_files, examples_dir, write_examples

    if args.out is not None:
        print(f"wrote {', '.join(str(p) for p in write_examples(args.out))}")
        return 0
    print(_table(["file", "what it plans"], list(example_files().items())))
    print(f"in {examples_dir()}; `planner examples --out DIR` copies them")
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
    import pinocchio as pin

    from planner.core.rotations import matrix_to_rpy

    robot = load_robot(args.robot, tip=args.tip)
    q = _joint_values(args.q, robot, args.deg, "joint value")
    pose = robot.fk(q)
    rpy = matrix_to_rpy(pose[:3, :3])
    quaternion = pin.Quaternion(pose[:3, :3]).coeffs()  # (x, y, z, w)
    result = {
        "robot": robot.name,
        "tip": robot.tip,
        "q": q.tolist(),
        "position": pose[:3, 3].tolist(),
        "rpy": rpy.tolist(),
        "quaternion": quaternion.tolist(),
        "matrix": pose.tolist(),
        "manipulability": robot.manipulability(q),
        "within_limits": bool(robot.within_limits(q)),
    }
    if args.json:
        _print_json(result)
    else:
        x, y, z = _no_negative_zero(pose[:3, 3])
        print(f"{robot.name} tip {robot.tip!r}: position [m] = ({x:.6f}, {y:.6f}, {z:.6f})")
        unit, shown = ("deg", np.degrees(rpy)) if args.deg else ("rad", rpy)
        r, p, w = _no_negative_zero(shown)
        print(f"rpy [{unit}] = ({r:.6f}, {p:.6f}, {w:.6f}) (feeds `planner ik ... --rpy`)")
        qx, qy, qz, qw = _no_negative_zero(quaternion)
        print(f"quaternion (x, y, z, w) = ({qx:.6f}, {qy:.6f}, {qz:.6f}, {qw:.6f})")
        print(np.array2string(_no_negative_zero(pose), precision=6, suppress_small=True))
        print(f"manipulability {result['manipulability']:.6g}, within limits: {result['within_limits']}")
    return 0


def _no_negative_zero(values: np.ndarray, decimals: int = 6) -> np.ndarray:
    """Values rounded as printed, with -0.0 (a tiny negative rounded away) shown as 0."""
    return np.round(np.asarray(values, dtype=float), decimals) + 0.0


# ---------------------------------------------------------------------------- urdf-from-dh
def _add_urdf_from_dh(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "urdf-from-dh",
        help="write a URDF for an arm described by a DH table (YAML or JSON)",
        description="Print the URDF for a compact arm description; see planner.model.description for the format.",
    )
    p.add_argument("table", type=Path, help="arm description file (.yaml or .json)")


def _run_urdf_from_dh(args: argparse.Namespace) -> int:
    sys.stdout.write(urdf_from_dh(args.table))
    return 0


# ---------------------------------------------------------------------------- demo
def _add_demo(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="the main job: the source papers' pick-and-place tasks planned on the bundled arms",
        description="Plan Sumadsad's (2020) pick-and-place on dh3 (closed-form IK checked by the NLP, one smooth "
        "servo-limited trajectory, stretched states flagged singular) and Clothier and Shang's (2010) range-bearing "
        "pick-and-place on al5c (approach from above, straight-line lowering, SSC-32 commands); print a summary "
        "table and write CSV, servo commands, PNG plots and an animated GIF per arm.",
    )
    p.add_argument("--out", type=Path, default=Path("planner-demo"), help="output directory (default: planner-demo)")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots and animations (no matplotlib needed)")


def _run_demo(args: argparse.Namespace) -> int:
    from planner.app.demo import run_demo

    run_demo(args.out, plots=not args.no_plots)
    return 0


# ---------------------------------------------------------------------------- plan
def _add_plan(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plan",
        help="a smooth, limit-honouring trajectory through waypoints or Cartesian targets",
        description="Plan a jerk-limited trajectory through the waypoints of a plan file (YAML or JSON; "
        "the format is in the README and planner.app.plan_file).",
    )
    p.add_argument("robot", help="robot name (see `planner robots`) or URDF path")
    p.add_argument("waypoints_file", type=Path, help="plan file (.yaml or .json)")
    p.add_argument("--out", type=Path, default=None, help="directory for trajectory.csv, servo files and summary.json")
    p.add_argument(
        "--rate", type=float, default=1000.0, help="sample rate of the checks and the CSV [Hz] (default 1000)"
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument(
        "--plot", action="store_true", help="also draw joints.png, singularity.png and arm.png (into --out or .)"
    )
    p.add_argument(
        "--line-ending",
        choices=("cr", "crlf"),
        default="cr",
        help="end of each ssc32.txt command: cr, the controller's terminator (default), or crlf to read as lines",
    )
    p.add_argument(
        "--controller",
        choices=("pulses", "ssc32", "pca9685", "feetech", "steps"),
        default=None,
        help="write this controller's servo file (default: the plan file's controller; else pulses and ssc32)",
    )
    p.add_argument("--calibration", type=Path, default=None, help="calibration file (README: Driving a real arm)")
    p.add_argument("--view", action="store_true", help="then show the plan in the browser (planner view; Ctrl-C stops)")
    p.add_argument("--port", type=int, default=8080, help="port of --view (default 8080; 0: a free one)")
    p.add_argument("--animate", type=Path, default=None, metavar="FILE.gif", help="write a GIF of the arm moving")
    p.add_argument("--speed", type=float, default=1.0, help="--animate: plan seconds per GIF second (default 1)")
    p.add_argument("--fps", type=float, default=15.0, help="--animate: frames per second (default 15)")
    p.add_argument("--size", type=int, nargs=2, default=(640, 400), metavar=("W", "H"), help="--animate: pixels")
    p.add_argument("--animate-view", choices=("side-top", "3d"), default="side-top", help="--animate: the view")


#: Highest --rate [Hz]: every check and the CSV sample the plan at it, and 1e7 samples of a
#: 100 s plan already take gigabytes (1e7 Hz ran out of memory inside the singularity check).
MAX_RATE = 1e5


def _run_plan(args: argparse.Namespace) -> int:
    from planner.app.motion_plan import plan_motion
    from planner.app.plan_file import load_motion_request
    from planner.export.formats.ssc32 import Ssc32

    if not (np.isfinite(args.rate) and 0 < args.rate <= MAX_RATE):
        raise InvalidArgumentError(f"--rate must be a number in (0, {MAX_RATE:g}] [Hz], got {args.rate:g}")
    robot = load_robot(args.robot)
    request = load_motion_request(args.waypoints_file)
    plan = plan_motion(robot, request, rate=args.rate, controller=args.controller, calibration=args.calibration)
    summary = plan.summary(args.rate)
    files: list[Path] = []
    servo_error = None
    if args.plot:
        from planner.app.plots import plot_plan

        files += plot_plan(args.out or Path("."), robot, plan)
    if args.animate is not None:
        from planner.app.animation import animate_plan

        kw = {"fps": args.fps, "speed": args.speed, "size": args.size, "view": args.animate_view}
        files.append(animate_plan(args.animate, robot, plan, **kw))
    if args.out is not None:
        try:
            formats = [Ssc32(args.line_ending) if fmt.name == Ssc32.name else fmt for fmt in plan.setup.formats()]
            files += plan.write_files(args.out, rate=args.rate, extra_files=files, formats=formats)
        except ServoExportError as exc:
            servo_error = exc
            files += exc.written
    if files:
        summary["files"] = sorted(str(f) for f in files)
    if servo_error is not None:
        summary["servo_file_errors"] = servo_error.failures
    if args.json:
        _print_json(summary)
        _view_plan(args, robot, plan)
        return _report_servo_error(servo_error)
    print(
        f"{robot.name}: {len(plan.waypoints)} waypoints, duration {plan.trajectory.duration:.4f} s "
        f"({plan.trajectory.strategy} via states)"
    )
    print(_waypoint_table(robot, plan, request))
    print(
        f"peak / limit: velocity {summary['max_velocity_ratio']:.4f}, acceleration "
        f"{summary['max_acceleration_ratio']:.4f}, jerk {summary['max_jerk_ratio']:.4f} "
        f"(sampled at {args.rate:g} Hz)"
    )
    print(
        f"min manipulability {summary['min_manipulability']:.4g}, min inverse condition number "
        f"{summary['min_inverse_condition']:.4g} (threshold 1/{summary['condition_number_threshold']:g})"
    )
    if plan.detours:
        print(f"detours inserted: {len(plan.detours)} (segments {sorted({d.segment for d in plan.detours})})")
    if plan.unresolved:
        print(f"segments still passing near a singularity: {list(plan.unresolved)}")
    if files:
        print(f"wrote {', '.join(summary['files'])}")
    _view_plan(args, robot, plan)
    return _report_servo_error(servo_error)


def _waypoint_table(robot: Robot, plan: MotionPlan, request: MotionRequest) -> str:
    """The plan's waypoints in the plan file's own units, with their labels."""
    from planner.core.units import ANGLE_UNITS, LENGTH_UNITS

    angle = next(k for k, v in ANGLE_UNITS.items() if v == request.angle_scale)
    length = next(k for k, v in LENGTH_UNITS.items() if v == request.length_scale)
    kinds = set(robot.joint_kinds)
    unit = "/".join(([angle] if kinds - {"prismatic"} else []) + ([length] if "prismatic" in kinds else []))
    scale = np.array([request.length_scale if k == "prismatic" else request.angle_scale for k in robot.joint_kinds])
    dwell = np.any(plan.departure_times > plan.waypoint_times)
    rows = []
    for k, q in enumerate(plan.waypoints):
        leave = [f"{plan.departure_times[k]:.4f}"] if dwell else []
        rows.append(
            (
                k,
                plan.labels[k] or "",
                f"{plan.waypoint_times[k]:.4f}",
                *leave,
                " ".join(f"{x + 0.0:+.4f}" for x in q / scale),
                plan.branches[k] or "-",
                "SINGULAR" if k in plan.singular_waypoints else "",
            )
        )
    header = ["#", "label", "t [s]", *(["leaves [s]"] if dwell else []), f"q [{unit}]", "branch", ""]
    return _table(header, rows)


# ---------------------------------------------------------------------------- check
def _add_check(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "check",
        help="plan a plan file and report its clearance: the closest approach, when, between what",
        description="Plan the plan file as `planner plan` does and check the trajectory continuously against the "
        "plan file's scene (floor, obstacles) and the arm itself; without a scene, against the arm itself.",
    )
    p.add_argument("robot", help="robot name (see `planner robots`) or URDF path")
    p.add_argument("plan_file", type=Path, help="plan file (YAML or JSON)")
    p.add_argument("--json", action="store_true", help="print the collision report as JSON")


def _run_check(args: argparse.Namespace) -> int:
    import dataclasses

    from planner.app.motion_plan import plan_motion
    from planner.app.plan_file import load_motion_request
    from planner.collision.scene import Scene

    robot = load_robot(args.robot)
    request = load_motion_request(args.plan_file)
    no_scene = request.scene is None
    if no_scene:
        request = dataclasses.replace(request, scene=Scene())
    plan = plan_motion(robot, request)
    collision = plan.collision
    assert collision is not None
    summary = plan.summary()
    if args.json:
        _print_json({"robot": robot.name, "scene": not no_scene, **{k: summary[k] for k in ("collision", "routes")}})
        return 0 if collision.clear else 1
    if no_scene:
        print("no scene in the plan file: the arm checked against itself only")
    print(f"{robot.name}: duration {plan.trajectory.duration:.4f} s, {collision.describe()}")
    if plan.routes:
        print(f"routed around obstacles: segment {', '.join(str(k) for k in plan.routes)}")
    return 0 if collision.clear else 1


def _report_servo_error(error: ServoExportError | None) -> int:
    if error is None:
        return 0
    print(f"planner plan: error: {error}", file=sys.stderr)
    return 1


# ---------------------------------------------------------------------------- send
def _add_send(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "send",
        help="plan, then stream the servo commands to a controller over a serial port",
        description="Plan a plan file, read where the arm is, then send one command per servo period, paced by a "
        "monotonic clock; Ctrl-C or a port error stops every servo in use. Needs pyserial (the hardware extra).",
    )
    p.add_argument("robot", help="robot name (see `planner robots`) or URDF path")
    p.add_argument("plan_file", type=Path, help="plan file (.yaml or .json)")
    p.add_argument("--port", default=None, help="serial device, e.g. /dev/ttyUSB0 or COM3")
    p.add_argument("--baud", type=int, default=None, help="baud rate (default: the controller's, 115200 / 1000000)")
    p.add_argument(
        "--controller", choices=("ssc32", "feetech"), default=None, help="default: the plan file's, else ssc32"
    )
    p.add_argument("--calibration", type=Path, default=None, help="calibration file (default: shipped, else defaults)")
    p.add_argument("--dry-run", action="store_true", help="print the byte stream with timestamps; open no port")
    p.add_argument("--from-current", action="store_true", help="far from the first waypoint: plan a move from there")
    p.add_argument(
        "--approach-time",
        type=float,
        default=None,
        metavar="S",
        help="position unknown (SSC-32): one timed move to the first waypoint taking S seconds first; the arm JUMPS "
        "there if a servo was elsewhere",
    )
    p.add_argument(
        "--start-tolerance", type=float, default=0.05, metavar="RAD", help="counts as at the first waypoint [rad]"
    )


def _run_send(args: argparse.Namespace) -> int:
    from planner.app.send import send_plan
    from planner.hardware.session import SendOptions, SendStatus

    options = SendOptions(args.baud, args.from_current, args.approach_time, args.start_tolerance)
    if args.port is None and not args.dry_run:
        raise InvalidArgumentError("give --port DEVICE (or --dry-run to print the stream)")
    result = send_plan(
        load_robot(args.robot),
        args.plan_file,
        port=args.port,
        controller=args.controller,
        calibration=args.calibration,
        options=options,
        dry_run=sys.stdout if args.dry_run else None,
    )
    print(f"{'# ' if args.dry_run else ''}{result.message}")
    return {SendStatus.COMPLETED: 0, SendStatus.INTERRUPTED: 130}.get(result.status, 1)


def _view_plan(args: argparse.Namespace, robot: Robot, plan: MotionPlan) -> None:
    """With --view, serve the plan in the browser until Ctrl-C."""
    if args.view:
        from planner.app.viewing import run_view

        run_view(robot, plan=plan, port=args.port)


# ---------------------------------------------------------------------------- view
def _add_view(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "view",
        help="an interactive 3-D view of an arm (and a plan) in the browser (needs the view extra)",
        description="Serve the arm on localhost with viser: joint sliders with live FK and singularity measures, a "
        "draggable IK target, and with a plan file playback of the plan. Ctrl-C stops.",
    )
    p.add_argument("robot", help="robot name (see `planner robots`) or URDF path")
    p.add_argument("plan_file", type=Path, nargs="?", default=None, help="plan file to plan and play (optional)")
    p.add_argument("--port", type=int, default=8080, help="port on localhost (default 8080; 0: a free one)")


def _run_view(args: argparse.Namespace) -> int:
    from planner.app.viewing import run_view

    return run_view(args.robot, args.plan_file, port=args.port)


# ---------------------------------------------------------------------------- ik
def _add_ik(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "ik",
        help="inverse kinematics: joint values that put the tip on a target",
        description="Solve inverse kinematics for a tip position, optionally with an approach pitch "
        "(--pitch) or a full orientation (--rpy); or, with --batch FILE.csv, for every target of a CSV file "
        "(header line x,y,z and optionally roll,pitch,yaw or qx,qy,qz,qw or approach_pitch; angles in rad, deg "
        "with --deg), writing a CSV of joint values and status per target. An unreachable target is a result "
        "(exit code 0) whose status says why; bad input exits 1.",
    )
    p.add_argument("robot", help="robot name (see `planner robots`) or URDF path")
    p.add_argument("x", type=float, nargs="?", help="target x [m]")
    p.add_argument("y", type=float, nargs="?", help="target y [m]")
    p.add_argument("z", type=float, nargs="?", help="target z [m]")
    p.add_argument(
        "--batch",
        default=None,
        metavar="FILE.csv",
        help="solve every target of a CSV file ('-': standard input) with the vectorised numerical solver, "
        "seeded with --current; columns x,y,z [m], optionally roll,pitch,yaw or qx,qy,qz,qw or approach_pitch",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="FILE.csv",
        help="with --batch: write the answers here (default: standard output)",
    )
    p.add_argument(
        "--pitch",
        type=float,
        default=None,
        help="approach pitch [rad; deg with --deg]: 0 horizontal away from the base axis, -90 deg straight down",
    )
    p.add_argument(
        "--rpy",
        type=float,
        nargs=3,
        metavar=("R", "P", "Y"),
        default=None,
        help="tip orientation as URDF roll-pitch-yaw [rad; deg with --deg]",
    )
    p.add_argument("--deg", action="store_true", help="angles (--pitch, --rpy, --current, output table) in degrees")
    p.add_argument(
        "--method",
        choices=("auto", "analytic", "nlp", "both"),
        default="auto",
        help="auto (default, as planner.solve_ik: the closed form where the arm has one, else the NLP), "
        "analytic (closed form), nlp (CasADi), or both (cross-check)",
    )
    p.add_argument(
        "--current",
        type=float,
        nargs="+",
        default=None,
        metavar="Q",
        help="current joint values: the IK seed, solutions sorted by distance to them and each angle taken "
        "nearest them (default: zero, clipped into the limits) [rad; deg with --deg]",
    )
    p.add_argument("--tip", default=None, help="tip frame (default: the arm's tool frame)")
    p.add_argument("--all", action="store_true", help="every solution (default: the best one within limits)")
    p.add_argument(
        "--time-budget",
        type=float,
        default=0.05,
        metavar="S",
        help="NLP: wall time after which no new restart begins [s] (default 0.05)",
    )
    p.add_argument("--json", action="store_true", help="print JSON")


def _ik_target(args: argparse.Namespace) -> Target:
    if args.out is not None:
        raise InvalidArgumentError("--out is for --batch; a single target prints its answer")
    if None in (args.x, args.y, args.z):
        raise InvalidArgumentError("give the target x y z [m], or --batch FILE.csv")
    position = [args.x, args.y, args.z]
    if args.rpy is not None:
        if args.pitch is not None:
            raise InvalidArgumentError("give either --pitch or --rpy, not both")
        return Target.from_rpy(position, _angles(args.rpy, args.deg, "rpy angle"))
    pitch = None if args.pitch is None else float(_angles([args.pitch], args.deg, "approach pitch", np.pi)[0])
    return Target(position, pitch=pitch)


def _ik_current(args: argparse.Namespace, robot: Robot) -> np.ndarray:
    """The seed: --current, else the arm's home (zero, clipped into the joint limits)."""
    if args.current is None:
        return np.clip(np.zeros(robot.dof), robot.lower, robot.upper)
    return _joint_values(args.current, robot, args.deg, "--current value")


def _ik_options(args: argparse.Namespace) -> IKOptions:
    from planner.ik.options import IKOptions

    return IKOptions(time_budget=args.time_budget)


def _ik_solutions(result: IKResult, every: bool) -> tuple[list[dict], int | None]:
    """The solutions to print (all with --all, else the chosen one) and the chosen one's index."""
    chosen = next((i for i, s in enumerate(result.solutions) if result.success and np.array_equal(s.q, result.q)), None)
    if every:
        return [s.as_dict() for s in result.solutions], chosen
    if chosen is None:
        return [], None
    return [result.solutions[chosen].as_dict()], 0


def _run_ik(args: argparse.Namespace) -> int:
    from planner.ik.cross_check import cross_check
    from planner.ik.solve import solve_ik

    robot = load_robot(args.robot, tip=args.tip)
    if args.batch is not None:
        return _run_ik_batch(args, robot)
    target = _ik_target(args)
    current = _ik_current(args, robot)
    head = {
        "robot": robot.name,
        "tip": robot.tip,
        "target": {
            "position": target.position.tolist(),
            "pitch": target.pitch,
            "rotation": None if target.rotation is None else target.rotation.tolist(),
        },
    }
    if args.method == "both":
        check = cross_check(robot, target, current, options=_ik_options(args))
        result = check.analytic
        extra = {"agree": check.agree, "cross_check": check.as_dict(), "nlp": check.nlp.as_dict()}
    else:
        result = solve_ik(robot, target, current, method=args.method, options=_ik_options(args))
        extra = {}
    out = {**head, **result.as_dict(), **extra}
    out["solutions"], out["best"] = _ik_solutions(result, args.all)
    if args.method == "both":
        out["method"], out["reason"] = "both", check.reason
    if args.json:
        _print_json(out)
        return 0
    unit = "deg" if args.deg else "rad"
    print(f"{robot.name} {out['method']} IK, target {np.round(target.position, 6).tolist()} m: {out['status']}")
    if out.get("reason"):
        print(f"  {out['reason']}")
    rows = []
    for s in out["solutions"]:
        q = np.degrees(s["q"]) if args.deg else np.asarray(s["q"])
        rows.append(
            (
                s["label"],
                " ".join(f"{v:+.4f}" for v in q),
                "yes" if s["within_limits"] else "NO",
                "yes" if s.get("singular") else "",
                f"{s['position_error']:.3g}",
            )
        )
    if rows:
        print(_table(["solution", f"q [{unit}]", "within limits", "singular", "position error [m]"], rows))
    return 0


def _run_ik_batch(args: argparse.Namespace, robot: Robot) -> int:
    """``planner ik ROBOT --batch FILE.csv``: every target of the file, answers as CSV."""
    from planner.app.target_file import read_targets, write_answers
    from planner.ik.solvers import IKSolvers

    given = [
        flag
        for flag, value in (
            ("x y z", args.x is not None),
            ("--pitch", args.pitch is not None),
            ("--rpy", args.rpy is not None),
            ("--all", args.all),
            ("--json", args.json),
        )
        if value
    ]
    if given:
        raise InvalidArgumentError(
            f"--batch reads the targets (and their orientations) from the file; drop {', '.join(given)}"
        )
    if args.method not in ("auto", "nlp"):
        raise InvalidArgumentError(
            f"--batch solves with the vectorised numerical solver; --method {args.method} is for one target "
            "(valid with --batch: auto, nlp)"
        )
    targets = read_targets(sys.stdin if args.batch == "-" else args.batch, deg=args.deg)
    current = _ik_current(args, robot)
    result = IKSolvers.of(robot).nlp.solve_batch(targets, current, _ik_options(args))
    if args.out is None:
        write_answers(sys.stdout, robot, result, deg=args.deg)
        return 0
    try:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        with args.out.open("w", newline="") as stream:
            write_answers(stream, robot, result, deg=args.deg)
    except OSError as exc:
        raise InvalidArgumentError(f"cannot write --out {str(args.out)!r}: {exc.strerror or exc}") from exc
    solved = int(np.sum(result.success))
    print(f"{robot.name}: {solved} of {len(result)} targets solved in {result.wall_time:.3g} s; wrote {args.out}")
    return 0


# ---------------------------------------------------------------------------- bench
def _add_bench(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench",
        help="benchmark closed-form vs numerical IK on random reachable targets",
        description="Time closed-form and CasADi IK on N random targets per robot (FK of random configurations "
        "within the limits, fixed seed); success is checked by Pinocchio FK. Prints a Markdown table. The full "
        "benchmark with its recorded results is benchmarks/bench_ik.py.",
    )
    p.add_argument("robots", nargs="*", help="robots (default: every bundled arm)")
    p.add_argument("--n", type=int, default=200, help="random targets per robot (default 200)")
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the targets and of the IK seeds (two streams apart from the solver's own; default 0)",
    )
    p.add_argument("--time-budget", type=float, default=0.05, metavar="S", help="NLP time budget per call [s]")
    p.add_argument("--out", type=Path, default=None, help="write bench_ik.json (and with --plot bench_ik.png) here")
    p.add_argument("--plot", action="store_true", help="draw the solve rate and time chart (into --out or .)")
    p.add_argument("--json", action="store_true", help="print the summaries as JSON instead of the table")


def _run_bench(args: argparse.Namespace) -> int:
    from planner.app.benchmark import bench_robot, markdown

    if args.n < 1:
        raise InvalidArgumentError(f"--n must be at least 1, got {args.n}")
    if not (np.isfinite(args.time_budget) and args.time_budget > 0):
        raise InvalidArgumentError(f"--time-budget must be positive [s], got {args.time_budget}")
    names = args.robots or list(BUNDLED_ROBOTS)
    for name in names:
        load_robot(name)  # fail on an unknown name before any work
    summaries = []
    for name in names:
        summaries += bench_robot(name, args.n, args.seed, args.time_budget)
    if args.json:
        _print_json(summaries)
    else:
        print(markdown(summaries))
    written = []
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        path = args.out / "bench_ik.json"
        path.write_text(json.dumps(summaries, indent=2, allow_nan=False) + "\n")
        written.append(path)
    if args.plot:
        from planner.app.plots import plot_ik_benchmark

        written.append(plot_ik_benchmark((args.out or Path(".")) / "bench_ik.png", summaries))
    if written and not args.json:
        print(f"wrote {', '.join(str(w) for w in written)}")
    return 0


_COMMANDS: dict[str, tuple[Callable[[argparse._SubParsersAction], None], Callable[[argparse.Namespace], int]]] = {
    "robots": (_add_robots, _run_robots),
    "examples": (_add_examples, _run_examples),
    "check": (_add_check, _run_check),
    "fk": (_add_fk, _run_fk),
    "ik": (_add_ik, _run_ik),
    "plan": (_add_plan, _run_plan),
    "send": (_add_send, _run_send),
    "demo": (_add_demo, _run_demo),
    "view": (_add_view, _run_view),
    "bench": (_add_bench, _run_bench),
    "urdf-from-dh": (_add_urdf_from_dh, _run_urdf_from_dh),
}


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``planner`` command."""
    from planner.core.version import __version__

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
    except OSError as exc:  # a file the command writes: a folder in its place, no room, no permission
        where = f"{exc.filename!r}: " if exc.filename else ""
        print(f"planner {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # e.g. Ctrl-C while planning; a stream handles its own and stops the servos
        print(f"planner {args.command}: interrupted", file=sys.stderr)
        return 130
