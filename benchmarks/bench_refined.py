"""Benchmark: the ``"refined"`` via strategy against the default ``"optimized"`` one.

The same random paths as ``bench_trajectory.py`` (5 waypoints per path, same seed and order,
v = the URDF's speed, a = 2 v, j = 10 a). Per arm: the median plan time of each strategy (CPU
time of the planning thread, both timed on the same path one after the other, taking turns at
going first) and its ratio, the median duration ratio refined / optimized, and with
``--optimum-every K`` the optimum gap of both (duration / NLP optimum - 1, median over every
K-th path; the NLP of ``bench_trajectory.optimum_reference``, started from each of the two plans, the
shorter answer; the optimum is the shortest of the NLP's and both plans' durations, so gaps are >= 0).
Limits are checked on every refined plan (sampled at 1 kHz and exactly), and the sampled
position at each waypoint time (within 1e-12 of the waypoint, as in ``bench_trajectory.py``).

    python benchmarks/bench_refined.py [--paths 100] [--seed 0] [--optimum-every 4] [--robots ur5 ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_trajectory import RESULTS, optimum_reference  # noqa: E402

from planner import available_robots, load_robot  # noqa: E402
from planner.motion.limits import JointLimits  # noqa: E402
from planner.motion.plan import plan_trajectory  # noqa: E402


def timed(q: np.ndarray, limits: JointLimits, strategy: str):
    t0 = time.thread_time()
    traj = plan_trajectory(q, limits, strategy=strategy)
    return traj, time.thread_time() - t0


def bench_robot(name: str, paths: int, rng: np.random.Generator, optimum_every: int) -> dict:
    robot = load_robot(name)
    limits = JointLimits.from_robot(robot)
    q0 = robot.random_configurations(rng, 5)
    plan_trajectory(q0, limits, strategy="refined")  # warm-up
    rows = []
    for index in range(paths):
        q = robot.random_configurations(rng, 5)
        if index % 2:
            opt, opt_time = timed(q, limits, "optimized")
            ref, ref_time = timed(q, limits, "refined")
        else:
            ref, ref_time = timed(q, limits, "refined")
            opt, opt_time = timed(q, limits, "optimized")
        peaks = [ref.peak_ratios(1000.0), ref.peak_ratios(None)]
        row = {
            "optimized": opt.duration,
            "refined": ref.duration,
            "optimized_time": opt_time,
            "refined_time": ref_time,
            "peak": max(max(p["velocity"], p["acceleration"], p["jerk"]) for p in peaks),
            "position_excess": max(p["position"] for p in peaks),
            "passes_waypoints": bool(np.max(np.abs(ref.sample(ref.waypoint_times).q - q)) <= 1e-12),
            "waypoint_error": float(np.max(np.abs(ref.sample(ref.waypoint_times).q - q))),
        }
        if optimum_every and index % optimum_every == 0:
            # Started from each plan (IPOPT finds a local optimum near its start): the shorter one.
            found = [d for d in (optimum_reference(q, limits, ref), optimum_reference(q, limits, opt)) if d]
            row["nlp"] = min(found) if found else None
        rows.append(row)
    return {"robot": name, "dof": robot.dof, "rows": rows}


def gap(rows: list[dict], key: str) -> float | None:
    solved = [r for r in rows if r.get("nlp")]
    if not solved:
        return None
    return float(np.median([r[key] / min(r["nlp"], r["optimized"], r["refined"]) - 1.0 for r in solved]))


def summarise(result: dict) -> dict:
    rows = result["rows"]
    return {
        "robot": result["robot"],
        "dof": result["dof"],
        "paths": len(rows),
        "gap_optimized": gap(rows, "optimized"),
        "gap_refined": gap(rows, "refined"),
        "median_duration_ratio": float(np.median([r["refined"] / r["optimized"] for r in rows])),
        "slower_paths": sum(r["refined"] > r["optimized"] for r in rows),
        "optimized_ms": float(np.median([r["optimized_time"] for r in rows]) * 1e3),
        "refined_ms": float(np.median([r["refined_time"] for r in rows]) * 1e3),
        "median_time_ratio": float(np.median([r["refined_time"] / r["optimized_time"] for r in rows])),
        "max_peak_ratio": max(r["peak"] for r in rows),
        "max_position_excess": max(r["position_excess"] for r in rows),
        "all_pass_waypoints": all(r["passes_waypoints"] for r in rows),
        "max_waypoint_error": max(r["waypoint_error"] for r in rows),
    }


def pct(x: float | None) -> str:
    return "n/a" if x is None else f"{100 * x:.2f} %"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=100, help="random paths per robot")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random waypoints")
    parser.add_argument("--robots", nargs="*", default=None, help="robots (default: every available one)")
    parser.add_argument("--optimum-every", type=int, default=4, help="solve every K-th path as an NLP (0: none)")
    args = parser.parse_args(argv)
    # Every robot is drawn from one generator, as in bench_trajectory: the paths match its own.
    rng = np.random.default_rng(args.seed)
    names = list(available_robots())
    results = []
    for name in names:
        if args.robots and name not in args.robots:
            robot = load_robot(name)  # draw this robot's paths all the same, to keep the sequence
            robot.random_configurations(rng, 5)
            for _ in range(args.paths):
                robot.random_configurations(rng, 5)
            continue
        results.append(bench_robot(name, args.paths, rng, args.optimum_every))
    summaries = [summarise(r) for r in results]
    lines = [
        "| robot | dof | paths | optimum gap optimized | optimum gap refined | median T refined / optimized "
        "| paths slower | plan ms optimized | plan ms refined | median time ratio | peak v, a, j / limit "
        "| position excess | waypoints within 1e-12 (worst error) |",
        "|" + "---|" * 13,
    ]
    for s in summaries:
        lines.append(
            f"| {s['robot']} | {s['dof']} | {s['paths']} | {pct(s['gap_optimized'])} | {pct(s['gap_refined'])} | "
            f"{s['median_duration_ratio']:.4f} | {s['slower_paths']} | {s['optimized_ms']:.2f} | "
            f"{s['refined_ms']:.2f} | {s['median_time_ratio']:.2f}x | {s['max_peak_ratio']:.4f} | "
            f"{s['max_position_excess']:.1e} | {'all' if s['all_pass_waypoints'] else 'MISSED'} "
            f"({s['max_waypoint_error']:.0e}) |"
        )
    rows = [r for res in results for r in res["rows"]]
    six = [r for res in results if res["dof"] == 6 for r in res["rows"]]
    overall = {
        "optimum_paths": sum(1 for r in rows if r.get("nlp")),
        "gap_optimized_all": gap(rows, "optimized"),
        "gap_refined_all": gap(rows, "refined"),
        "median_time_ratio_all": float(np.median([r["refined_time"] / r["optimized_time"] for r in rows])),
        "optimized_ms_6dof": float(np.median([r["optimized_time"] for r in six]) * 1e3) if six else None,
        "refined_ms_6dof": float(np.median([r["refined_time"] for r in six]) * 1e3) if six else None,
    }
    summary = [
        f"optimum gap, median over {overall['optimum_paths']} paths: optimized {pct(overall['gap_optimized_all'])}, "
        f"refined {pct(overall['gap_refined_all'])} (goal <= 0.5 %)",
        f"median plan time refined / optimized on the same paths: {overall['median_time_ratio_all']:.2f}x",
    ]
    if six:
        summary.append(
            f"median plan time, 6-dof arms: optimized {overall['optimized_ms_6dof']:.2f} ms, "
            f"refined {overall['refined_ms_6dof']:.2f} ms"
        )
    table = "\n".join(lines)
    print(table + "\n\n" + "\n".join(summary))
    RESULTS.mkdir(parents=True, exist_ok=True)
    record = {"settings": vars(args), "summary": summaries, "overall": overall, "table": table}
    (RESULTS / "bench_refined.json").write_text(json.dumps(record, indent=2) + "\n")
    (RESULTS / "bench_refined.md").write_text(table + "\n\n" + "\n".join(summary) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
