"""The main job: the source papers' own tasks planned end to end on the bundled arms.

1. Sumadsad's (2020) pick-and-place state table on ``dh3``: closed-form IK for every state,
   checked against the CasADi NLP, one smooth servo-limited trajectory through all states,
   the fully stretched states flagged singular.
2. Clothier and Shang's (2010) scenario on ``al5c``: a range-bearing sensor at a known mount pose sees an
   object; the arm approaches it from above (approach pitch -90 deg), lowers onto it in a
   straight line, grasps, lifts, carries it to its left and puts it down; SSC-32 group-move
   commands are written out.

Nothing is downloaded and no service is used; :func:`run_demo` returns the figures it prints.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from planner.app.motion_plan import MotionPlan, plan_motion
from planner.app.plan_file import MotionRequest, parse_motion_request
from planner.geometry.sensing import range_bearing_to_base
from planner.ik.cross_check import cross_check
from planner.model.catalog import load_robot
from planner.model.robot import Robot

__all__ = ["DH3_STATES_CM", "DemoMove", "DemoReport", "al5c_request", "dh3_request", "run_demo"]

#: Sumadsad's (2020) state table: tip positions [cm] and what the claw does there.
DH3_STATES_CM: tuple[tuple[tuple[float, float, float], str], ...] = (
    ((17, 0, 3), "state 1: start, claw open"),
    ((14, 0, -4), "state 2: reach the object"),
    ((14, 0, -4), "state 3: close the claw"),
    ((11, 0, 9), "state 4: lift"),
    ((7.7, 7.7, 9), "state 5: swing"),
    ((0, 11, 9), "state 6: swing"),
    ((0, 17, 3), "state 7: reach out"),
    ((0, 14, -4), "state 8: lower"),
    ((0, 14, -4), "state 9: open the claw"),
    ((17, 0, 3), "back to state 1"),
)

#: Clothier and Shang's (2010) set-up (ours; the paper gives no numbers): a range sensor 5 cm ahead of the
#: arm's base and 12 cm to its right, at table height, looking along the base's x axis.
AL5C_SENSOR_POSE = (0.05, -0.12, 0.0, 0.0)
#: What it reads: the object 0.17 m away at 35 deg to its left.
AL5C_READING = (0.17, math.radians(35.0))
#: Where the object is put down: on the arm's left, as in the paper's experiment.
AL5C_PLACE = (0.02, 0.20, 0.0)
GRASP_HEIGHT = 0.015  # gripper point above the table at the grasp [m]
CLEARANCE = 0.08  # approach and lift height above the grasp [m]
AL5C_BLOCK_SIZE = (0.04, 0.04, 0.14)  # a block on the table between the pick and the place [m]
AL5C_BLOCK_CENTRE = (0.12, 0.10, 0.07)
AL5C_SCENE_CLEARANCE = 0.002  # distance kept to the table, the block and between links [m]
#: How the demo animates each plan: real speed, small enough to mail.
DEMO_ANIMATION: Mapping[str, Any] = {"fps": 12.0, "size": (560, 340)}


@dataclass(frozen=True)
class DemoMove:
    """One planned move of the demo.

    Attributes:
        scenario: ``"dh3 pick and place"`` or ``"al5c range-bearing pick and place"``.
        label: The move's end waypoint label.
        ik_method: How the end target was solved (and checked).
        ik_position_error: Tip distance from the target by Pinocchio FK [m].
        duration: Time of the move [s].
        peak_velocity_ratio: Largest sampled joint speed over its limit in the move.
        min_manipulability: Smallest manipulability along the move.
        singular_end: Whether the end waypoint is flagged singular.
    """

    scenario: str
    label: str
    ik_method: str
    ik_position_error: float
    duration: float
    peak_velocity_ratio: float
    min_manipulability: float
    singular_end: bool


@dataclass(frozen=True)
class DemoReport:
    """Everything the demo computed.

    Attributes:
        moves: One entry per move, in order.
        plans: The motion plan of each scenario, by scenario name.
        files: Every file written.
        object_position: Where the al5c's sensor saw the object, shape (3,) [m].
        wall_time: Time the demo took [s].
    """

    moves: tuple[DemoMove, ...]
    plans: Mapping[str, MotionPlan]
    files: tuple[Path, ...]
    object_position: np.ndarray
    wall_time: float


def _moves(scenario: str, robot: Robot, plan: MotionPlan, request: MotionRequest) -> list[DemoMove]:
    """One row per move: the end target's IK (checked by the NLP), timing, peaks, singularity margin."""
    traj = plan.trajectory
    targets = request.targets or ()
    # A move runs from leaving one waypoint to leaving the next, so a dwell counts in its move.
    leave = plan.departure_times
    moves = []
    for k in range(1, len(plan.waypoints)):
        t0, t1 = leave[k - 1], leave[k]
        s = traj.sample(np.linspace(t0, t1, max(2, int(math.ceil((t1 - t0) * 1000.0)) + 1)))
        _, manipulability = robot.conditioning(s.q, plan.singularity.task)
        check = cross_check(robot, targets[k], q_seed=plan.waypoints[k - 1])
        method = "line" if plan.branches[k] == "line" else "closed form"
        moves.append(
            DemoMove(
                scenario=scenario,
                label=request.labels[k] or f"waypoint {k}",
                ik_method=f"{method}, NLP {'agrees' if check.agree else 'DISAGREES'}",
                ik_position_error=float(np.linalg.norm(robot.position(plan.waypoints[k]) - targets[k].position)),
                duration=float(t1 - t0),
                peak_velocity_ratio=float(np.max(np.abs(s.qd) / plan.limits.velocity)),
                min_manipulability=float(np.min(manipulability)),
                singular_end=k in plan.singular_waypoints,
            )
        )
    return moves


def _scenario(
    name: str, robot_name: str, request: Mapping[str, Any], out: Path | None, plots: bool
) -> tuple[MotionPlan, list[DemoMove], list[Path]]:
    robot = load_robot(robot_name)
    parsed = parse_motion_request(request, source=f"demo: {robot_name}")
    plan = plan_motion(robot, parsed)
    moves = _moves(name, robot, plan, parsed)
    files: list[Path] = []
    if out is not None:
        if plots:
            from planner.app.animation import animate_plan
            from planner.app.plots import plot_plan

            files += plot_plan(out / robot_name, robot, plan)
            title = f"{request['name']}: {plan.trajectory.duration:.2f} s"
            files.append(animate_plan(out / robot_name / "animation.gif", robot, plan, title=title, **DEMO_ANIMATION))
        files += plan.write_files(out / robot_name, extra_files=files)
    return plan, moves, files


def dh3_request() -> dict[str, Any]:
    """Sumadsad's (2020) state table as a plan request for ``dh3`` (cm; a dwell where the claw acts)."""
    return {
        "name": "dh3 pick and place (Sumadsad 2020)",
        "units": {"length": "cm", "angle": "deg"},
        "targets": [
            {"position": list(p), "label": label, **({"dwell": 0.5} if "the claw" in label else {})}
            for p, label in DH3_STATES_CM
        ],
    }


def al5c_request() -> tuple[dict[str, Any], np.ndarray]:
    """Clothier and Shang's (2010) scenario as a plan request for ``al5c``, and where the sensor saw the object [m]."""
    seen = range_bearing_to_base(*AL5C_READING, AL5C_SENSOR_POSE)
    grasp = seen + (0.0, 0.0, GRASP_HEIGHT)
    place = np.asarray(AL5C_PLACE) + (0.0, 0.0, GRASP_HEIGHT)
    up = np.array([0.0, 0.0, CLEARANCE])
    steps = [
        (grasp + up, False, 0.0, "above the object"),
        (grasp, True, 0.5, "lower and grasp"),
        (grasp + up, True, 0.0, "lift"),
        (place + up, False, 0.0, "carry to the left"),
        (place, True, 0.5, "lower and release"),
        (place + up, True, 0.0, "retreat"),
    ]
    request = {
        "name": "al5c pick and place (Clothier and Shang 2010)",
        "targets": [
            {"position": p.tolist(), "pitch": -math.pi / 2, "line": line, "dwell": dwell, "label": label}
            for p, line, dwell, label in steps
        ],
        # The first target's IK branch is the one nearest a folded, upright home pose.
        "start": {"q": [0.0, math.radians(90), math.radians(-90), math.radians(-90), 0.0]},
        # The table the arm stands on, and a block standing between the pick and the place:
        # the carry is planned around it.
        "scene": {
            "floor": 0.0,
            "clearance": AL5C_SCENE_CLEARANCE,
            "obstacles": [{"name": "block", "box": list(AL5C_BLOCK_SIZE), "position": list(AL5C_BLOCK_CENTRE)}],
        },
    }
    return request, seen


def _table(moves: Sequence[DemoMove]) -> str:
    headers = ("scenario", "move to", "IK", "IK error [m]", "duration [s]", "peak v/limit", "min manip.", "")
    rows = [
        (
            m.scenario.split()[0],
            m.label,
            m.ik_method,
            f"{m.ik_position_error:.1e}",
            f"{m.duration:.3f}",
            f"{m.peak_velocity_ratio:.3f}",
            f"{m.min_manipulability:.2e}",
            "singular" if m.singular_end else "",
        )
        for m in moves
    ]
    cells = [list(headers)] + [list(r) for r in rows]
    widths = [max(len(r[k]) for r in cells) for k in range(len(headers))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def run_demo(
    out: str | Path | None = None, *, plots: bool = True, log: Callable[[str], None] | None = print
) -> DemoReport:
    """Plan both seed scenarios, print a summary table, and write the files.

    Args:
        out: Directory for the files (``dh3/`` and ``al5c/`` inside: ``trajectory.csv``,
            ``servo_pulses.csv``, ``ssc32.txt``, ``summary.json`` and, with `plots`,
            ``joints.png``, ``singularity.png``, ``arm.png`` and ``animation.gif``, the arm
            moving through the plan at real speed); None writes nothing.
        plots: Whether to draw the PNG plots and the animation (needs matplotlib).
        log: Where the progress lines and the table go; None is silent.

    Returns:
        The report.
    """
    start = time.perf_counter()
    say = log or (lambda _: None)
    folder = None if out is None else Path(out)
    dh3_plan, dh3_moves, dh3_files = _scenario("dh3 pick and place", "dh3", dh3_request(), folder, plots)
    labels = [label for _, label in DH3_STATES_CM]
    say(
        f"dh3 (Sumadsad 2020): {len(dh3_plan.waypoints)} states in {dh3_plan.trajectory.duration:.2f} s; "
        f"fully stretched, flagged singular: {', '.join(labels[k] for k in dh3_plan.singular_waypoints)}"
    )
    request, seen = al5c_request()
    al5c_plan, al5c_moves, al5c_files = _scenario("al5c range-bearing pick and place", "al5c", request, folder, plots)
    say(
        f"al5c (Clothier and Shang 2010): sensor saw the object at ({seen[0]:.3f}, {seen[1]:.3f}, {seen[2]:.3f}) m; "
        f"{len(al5c_plan.waypoints)} targets, approach from above, in {al5c_plan.trajectory.duration:.2f} s"
    )
    if al5c_plan.collision is not None:
        around = ", ".join(al5c_moves[k].label for k in al5c_plan.routes) or "none"
        say(f"  table and block: planned around the block: {around}; {al5c_plan.collision.describe()}")
    moves = tuple(dh3_moves + al5c_moves)
    say("")
    say(_table(moves))
    files = tuple(dh3_files + al5c_files)
    wall = time.perf_counter() - start
    if files:
        say(f"\nwrote {len(files)} files into {folder}/ (dh3/, al5c/) in {wall:.1f} s")
    return DemoReport(
        moves=moves,
        plans={"dh3": dh3_plan, "al5c": al5c_plan},
        files=files,
        object_position=seen,
        wall_time=wall,
    )
