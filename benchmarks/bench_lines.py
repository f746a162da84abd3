"""Benchmark: how smooth straight Cartesian lines are, and how long they take (issue 11).

For the demo's AL5C plan (``planner demo``) and for random lines on al5c and three_joint (two
random configurations within the joint limits per line, ``--seed``; the tip positions by
forward kinematics; lines IK cannot follow are skipped and counted), ``plan_motion`` plans the
line and the trajectory is sampled at 1 kHz from the departure to the arrival:

- jerk sign changes per joint: sign changes of the sampled jerk where |jerk| > 1 % of the
  joint's jerk limit (the count of issue 11); per line, the worst joint;
- per piece: the same between two instants where the arm rests inside the line (it stops at
  corners of the joint path: a joint arriving at or leaving a range end);
- every limit: peak velocity, acceleration and jerk over their limits (exact and 1 kHz) and the
  position excess; the tip's largest distance from the line (``line_deviation``);
- duration over the Ruckig chain the line had before it was smoothed (the line timing's
  segments between the samples, :func:`planner.motion.line_timing.line_trajectory`).

Lines whose joint path turns corners (:func:`planner.motion.line_smoothing.path_corners`: a
joint reaching or leaving a range end, where the arm must stop) get rows of their own.

Blending: plans of a joint move, a line and a joint move between the tips of four random
configurations (``--plans`` per arm), planned with the line at rest at both ends
(``blend_lines: false``) and blended into the moves around it (the default): the duration
ratio, the line's ends passed moving, every limit and the tip's distance from the line.
Junctions: two lines straight on from one another (``--plans`` per arm), passing the target
between them (the default) and with ``stop: true`` there (:func:`collinear_plans`).

Goal (issue 11): per joint and line, no more jerk sign changes than the joint-space S-curve of
the same move (:func:`s_curve_reference`: Ruckig rest-to-rest segments through the line's start,
its stops and its end), single digits. Where a joint reverses along the line, no motion along it
reaches the S-curve's count (:func:`reversal_floor`); the table counts both. Prints Markdown
tables, writes JSON to benchmarks/results/bench_lines.json (and the tables to bench_lines.md).

    python benchmarks/bench_lines.py [--lines 40] [--seed 5] [--plans 20]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

import planner
from planner.app.demo import al5c_request
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
from planner.model.robot import Robot
from planner.motion.branch_choice import TargetSolver
from planner.motion.line import line_waypoints
from planner.motion.line_smoothing import path_corners
from planner.motion.line_timing import line_trajectory
from planner.motion.plan import plan_trajectory

RESULTS = Path(__file__).resolve().parent / "results"


def line_figures(plan, k: int) -> dict:
    """Figures of the line into user waypoint k of a plan."""
    traj, lim = plan.trajectory, plan.limits
    t0, t1 = float(plan.departure_times[k - 1]), float(plan.waypoint_times[k])
    inside = traj.waypoint_times[(traj.waypoint_times > t0 + 1e-9) & (traj.waypoint_times < t1 - 1e-9)]
    rests = [t for t in inside if np.all(np.abs(traj.sample(np.array([t])).qd[0]) <= 1e-9 * lim.velocity)]
    bounds = [t0, *rests, t1]
    pieces = [int(traj.jerk_sign_changes(a, b).max()) for a, b in zip(bounds, bounds[1:])]
    counts = traj.jerk_sign_changes(t0, t1)
    reference = s_curve_reference(traj, bounds)
    floor = sum(reversal_floor(traj, a, b) for a, b in zip(bounds, bounds[1:]))
    peaks = [traj.peak_ratios(None), traj.peak_ratios(1000.0)]
    return {
        "sign_changes": counts.tolist(),
        "worst_joint": int(counts.max()),
        "s_curve_sign_changes": reference.tolist(),
        "within_s_curve": bool(np.all(counts <= reference)),
        "excess_over_s_curve": int(np.max(counts - reference)),
        "reversal_floor": floor.tolist(),
        "within_floor": bool(np.all(counts <= np.maximum(reference, floor))),
        "pieces": len(pieces),
        "worst_piece": max(pieces),
        "limit_ratio": max(max(p["velocity"], p["acceleration"], p["jerk"]) for p in peaks),
        "position_excess": max(p["position"] for p in peaks),
        "deviation": float(plan.line_deviation[k - 1]),
        "duration": t1 - t0,
    }


def s_curve_reference(traj, bounds: list[float]) -> np.ndarray:
    """Issue 11's reference: per joint, the jerk sign changes of the joint-space S-curve of the same move.

    Ruckig rest-to-rest segments (``strategy="stop"``) with the same limits through the
    configurations where the line rests: its start, its stops inside (its corners) and its end.
    """
    q = traj.sample(np.array(bounds)).q
    keep = np.concatenate([[True], np.any(np.abs(np.diff(q, axis=0)) > 0, axis=1)])
    if keep.sum() < 2:
        return np.zeros(traj.dof, dtype=int)
    scurve = plan_trajectory(q[keep], traj.limits, strategy="stop")
    return scurve.jerk_sign_changes(0.0, scurve.duration)


def reversals(x: np.ndarray, eps: float) -> tuple[int, bool]:
    """How often the sequence x turns back by more than eps, and whether it moves more than eps at all."""
    direction, extreme, count = 0, float(x[0]), 0
    for v in x[1:]:
        if direction == 0:
            if abs(v - extreme) > eps:
                direction, extreme = (1 if v > extreme else -1), float(v)
        elif (v - extreme) * direction > 0:
            extreme = float(v)
        elif abs(v - extreme) > eps:
            direction, extreme, count = -direction, float(v), count + 1
    return count, direction != 0


def reversal_floor(traj, t0: float, t1: float, eps: float = 1e-3) -> np.ndarray:
    """Per joint, the fewest jerk sign changes a rest-to-rest motion along this piece's joint path has.

    A joint that reverses r times between two rests has r + 1 velocity extrema and r + 2
    acceleration extrema (the acceleration is 0 at both rests), so its jerk changes sign at
    least r + 2 times; a joint that does not move, 0 times. Where a line's joint reverses, the
    S-curve (which moves it straight) has fewer than any motion along the line can. Reversals
    by less than `eps` [rad or m] are not counted (their jerk may stay under the count's floor).
    """
    q = traj.sample(np.arange(t0, t1, 1e-3), clamp=True).q
    out = np.zeros(traj.dof, dtype=int)
    for d in range(traj.dof):
        count, moves = reversals(q[:, d], eps)
        out[d] = count + 2 if moves else 0
    return out


def random_lines(robot: Robot, count: int, rng: np.random.Generator) -> tuple[list[dict], int]:
    out, skipped = [], 0
    solver = TargetSolver(robot)
    while len(out) < count:
        q = robot.random_configurations(rng, 2)
        data = {
            "targets": [
                {"position": robot.position(q[0]).tolist()},
                {"position": robot.position(q[1]).tolist(), "line": True},
            ]
        }
        try:
            request = parse_motion_request(data)
            plan = plan_motion(robot, request)
        except planner.PlannerError:
            skipped += 1
            continue
        fig = line_figures(plan, 1)
        # The chain through the same samples (the same IK from the same start).
        start = solver.choose(request.targets[0], None).q
        path = line_waypoints(solver, request.targets[0], request.targets[1], start)
        chain = line_trajectory(path, plan.limits)
        fig["chain_ratio"] = fig["duration"] / chain.duration
        fig["corners"] = len(path_corners(np.asarray(path.q), plan.limits))
        out.append(fig)
    return out, skipped


def blended_plans(robot: Robot, count: int, rng: np.random.Generator) -> tuple[list[dict], int]:
    """Joint move, line, joint move between random tips: planned at rest at the line's ends and blended."""
    out, skipped = [], 0
    while len(out) < count:
        q = robot.random_configurations(rng, 4)
        targets = [{"position": robot.position(x).tolist()} for x in q]
        targets[2]["line"] = True
        plans = {}
        try:
            for blend in (False, True):
                plans[blend] = plan_motion(robot, parse_motion_request({"targets": targets, "blend_lines": blend}))
        except planner.PlannerError:
            skipped += 1
            continue
        rest, blended = plans[False], plans[True]
        traj = blended.trajectory
        peaks = [traj.peak_ratios(None), traj.peak_ratios(1000.0)]
        t0, t1 = float(blended.departure_times[1]), float(blended.waypoint_times[2])
        ends = np.abs(traj.sample(np.array([t0, t1])).qd) / blended.limits.velocity
        out.append(
            {
                "ratio": traj.duration / rest.trajectory.duration,
                "moving_ends": int(np.sum(ends.max(axis=1) > 1e-6)),
                "limit_ratio": max(max(p["velocity"], p["acceleration"], p["jerk"]) for p in peaks),
                "position_excess": max(p["position"] for p in peaks),
                "deviation": float(blended.line_deviation[1]),
                "worst_joint": int(traj.jerk_sign_changes(t0, t1).max()),
            }
        )
    return out, skipped


def collinear_plans(robot: Robot, count: int, rng: np.random.Generator) -> tuple[list[dict], int]:
    """Two lines straight on from one another (tips of two random configurations, split in the middle).

    Planned passing the junction (the default) and with ``stop: true`` there: the duration
    ratio, the speed at the junction, every limit, the tip's distance from the lines, and the jerk
    sign changes from the first line's start to the second's end against the S-curve's.
    """
    out, skipped = [], 0
    while len(out) < count:
        q = robot.random_configurations(rng, 2)
        a, c = robot.position(q)
        targets = [{"position": a.tolist()}, {"position": ((a + c) / 2).tolist(), "line": True}]
        targets.append({"position": c.tolist(), "line": True})
        stopped = [dict(t) for t in targets]
        stopped[1]["stop"] = True
        try:
            rest = plan_motion(robot, parse_motion_request({"targets": stopped}))
            through = plan_motion(robot, parse_motion_request({"targets": targets}))
        except planner.PlannerError:
            skipped += 1
            continue
        traj, lim = through.trajectory, through.limits
        peaks = [traj.peak_ratios(None), traj.peak_ratios(1000.0)]
        t0, t1 = float(through.departure_times[0]), float(through.waypoint_times[2])
        inside = traj.waypoint_times[(traj.waypoint_times > t0 + 1e-9) & (traj.waypoint_times < t1 - 1e-9)]
        rests = [t for t in inside if np.all(np.abs(traj.sample(np.array([t])).qd[0]) <= 1e-9 * lim.velocity)]
        counts = traj.jerk_sign_changes(t0, t1)
        reference = s_curve_reference(traj, [t0, *rests, t1])
        junction = traj.sample(np.array([through.waypoint_times[1]])).qd[0]
        out.append(
            {
                "ratio": traj.duration / rest.trajectory.duration,
                "junction_speed": float(np.max(np.abs(junction) / lim.velocity)),
                "limit_ratio": max(max(p["velocity"], p["acceleration"], p["jerk"]) for p in peaks),
                "position_excess": max(p["position"] for p in peaks),
                "deviation": max(float(d) for d in through.line_deviation if d is not None),
                "worst_joint": int(counts.max()),
                "within_s_curve": bool(np.all(counts <= reference)),
            }
        )
    return out, skipped


def _plan_cells(plans: list[dict]) -> str:
    """The cells both plan tables share: duration ratio median (range), peak limit ratio, tip off
    line, worst joint's sign changes median / max."""
    ratios = [f["ratio"] for f in plans]
    worst = [f["worst_joint"] for f in plans]
    return (
        f"{np.median(ratios):.3f} ({min(ratios):.3f}-{max(ratios):.3f}) "
        f"| {max(f['limit_ratio'] for f in plans):.9f} | {max(f['deviation'] for f in plans):.1e} "
        f"| {np.median(worst):g} / {max(worst)}"
    )


def junction_table(rows: list[tuple[str, list[dict], int]]) -> str:
    head = (
        "| two lines straight on | count (skipped) | junction passed moving | duration passing / stopping: median "
        "(range) | peak limit ratio | tip off line max [m] | worst joint sign changes: median / max | "
        "lines <= the S-curve's |\n|---|---|---|---|---|---|---|---|\n"
    )
    body = ""
    for name, plans, skipped in rows:
        body += (
            f"| {name} | {len(plans)} ({skipped}) | {sum(f['junction_speed'] > 1e-6 for f in plans)} / {len(plans)} "
            f"| {_plan_cells(plans)} | {sum(f['within_s_curve'] for f in plans)} / {len(plans)} |\n"
        )
    return head + body


def blend_table(rows: list[tuple[str, list[dict], int]]) -> str:
    head = (
        "| plans (joint move, line, joint move) | count (skipped) | line ends moving | duration blended / at rest: "
        "median (range) | peak limit ratio | tip off line max [m] | line's worst joint sign changes: median / max |\n"
        "|---|---|---|---|---|---|---|\n"
    )
    body = ""
    for name, plans, skipped in rows:
        body += (
            f"| {name} | {len(plans)} ({skipped}) | {sum(f['moving_ends'] for f in plans)} / {2 * len(plans)} "
            f"| {_plan_cells(plans)} |\n"
        )
    return head + body


def summary(name: str, lines: list[dict]) -> dict | None:
    if not lines:
        return None
    per_joint = [c for f in lines for c in f["sign_changes"]]
    worst = [f["worst_joint"] for f in lines]
    pieces = [f["worst_piece"] for f in lines]
    ratios = [f["chain_ratio"] for f in lines if "chain_ratio" in f]
    return {
        "robot": name,
        "lines": len(lines),
        "with_corners": sum(f["pieces"] > 1 for f in lines),
        "per_joint_median": float(np.median(per_joint)),
        "per_joint_max": int(max(per_joint)),
        "worst_joint_median": float(np.median(worst)),
        "worst_joint_max": int(max(worst)),
        "single_digit_lines": sum(w <= 9 for w in worst),
        "within_s_curve_lines": sum(f["within_s_curve"] for f in lines),
        "within_floor_lines": sum(f["within_floor"] for f in lines),
        "excess_over_s_curve_max": max(f["excess_over_s_curve"] for f in lines),
        "s_curve_worst_joint_max": max(max(f["s_curve_sign_changes"]) for f in lines),
        "worst_piece_max": int(max(pieces)),
        "limit_ratio_max": max(f["limit_ratio"] for f in lines),
        "position_excess_max": max(f["position_excess"] for f in lines),
        "deviation_max": max(f["deviation"] for f in lines),
        "chain_ratio": [float(np.median(ratios)), min(ratios), max(ratios)] if ratios else None,
        "duration_median": float(np.median([f["duration"] for f in lines])),
        "stops_max": max(f["pieces"] for f in lines) - 1,
    }


def table(rows: list[dict]) -> str:
    columns = (
        "lines",
        "count (with corners)",
        "stops inside max",
        "sign changes per joint: median / max",
        "worst joint per line: median / max",
        "lines single digit",
        "S-curve's worst joint max",
        "lines <= the S-curve's (every joint)",
        "lines <= max(S-curve's, reversal floor)",
        "excess over the S-curve max",
        "worst piece",
        "peak limit ratio",
        "tip off line max [m]",
        "duration median [s]",
        "duration / chain: median (range)",
    )
    head = "| " + " | ".join(columns) + " |\n" + "|---" * len(columns) + "|\n"
    body = ""
    for r in rows:
        if r is None:
            continue
        ratio = "-" if r["chain_ratio"] is None else "{:.2f} ({:.2f}-{:.2f})".format(*r["chain_ratio"])
        n = r["lines"]
        cells = (
            r["robot"],
            f"{n} ({r['with_corners']})",
            r["stops_max"],
            f"{r['per_joint_median']:g} / {r['per_joint_max']}",
            f"{r['worst_joint_median']:g} / {r['worst_joint_max']}",
            f"{r['single_digit_lines']} / {n}",
            r["s_curve_worst_joint_max"],
            f"{r['within_s_curve_lines']} / {n}",
            f"{r['within_floor_lines']} / {n}",
            r["excess_over_s_curve_max"],
            r["worst_piece_max"],
            f"{r['limit_ratio_max']:.9f}",
            f"{r['deviation_max']:.1e}",
            f"{r['duration_median']:.2f}",
            ratio,
        )
        body += "| " + " | ".join(str(c) for c in cells) + " |\n"
    return head + body


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--lines", type=int, default=40, help="random lines per robot")
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--plans", type=int, default=20, help="blended plans per robot")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    rows, record = [], {"seed": args.seed, "lines_per_robot": args.lines, "robots": {}}
    request, _ = al5c_request()
    al5c = planner.load_robot("al5c")
    demo = plan_motion(al5c, parse_motion_request(request))
    demo_lines = [line_figures(demo, k) for k in range(1, len(demo.waypoints)) if demo.branches[k] == "line"]
    rows.append(summary("al5c demo", demo_lines))
    record["robots"]["al5c demo"] = {"summary": rows[-1], "lines": demo_lines}
    for name in ("al5c", "three_joint"):
        robot = planner.load_robot(name)
        lines, skipped = random_lines(robot, args.lines, rng)
        rows.append(summary(name, lines))
        record["robots"][name] = {"summary": rows[-1], "skipped": skipped, "lines": lines}
        # Lines whose joint path turns corners (a joint reaching or leaving a range end), apart.
        cornered = [f for f in lines if f["corners"]]
        rows.append(summary(f"{name}, lines with corners", cornered))
        record["robots"][f"{name}, lines with corners"] = {"summary": rows[-1]}
        print(f"{name}: {len(lines)} lines, {skipped} skipped (IK cannot follow)", file=sys.stderr)
    blends = []
    for name in ("al5c", "three_joint"):
        plans, skipped = blended_plans(planner.load_robot(name), args.plans, rng)
        blends.append((name, plans, skipped))
        record["blending"] = record.get("blending", {}) | {name: {"skipped": skipped, "plans": plans}}
    junctions = []
    for name in ("al5c", "three_joint"):
        plans, skipped = collinear_plans(planner.load_robot(name), args.plans, rng)
        junctions.append((name, plans, skipped))
        record["junctions"] = record.get("junctions", {}) | {name: {"skipped": skipped, "plans": plans}}
    text = table(rows) + "\n" + blend_table(blends) + "\n" + junction_table(junctions)
    print(text)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "bench_lines.json").write_text(json.dumps(record, indent=2) + "\n")
    (RESULTS / "bench_lines.md").write_text(text)


if __name__ == "__main__":
    main()
