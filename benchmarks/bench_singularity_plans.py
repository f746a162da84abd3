"""Benchmark: the singularity side of plan_motion's plans, for two source trees, interleaved.

bench_collision's plans (ur5 and panda, its table-and-box scene, start/goal pairs clear of it
by our checker, seed 0; roboplan's own check of the pairs is left out) are planned with
:func:`planner.app.motion_plan.plan_motion` by each source tree given (``--trees``, e.g. main's
and a branch's checkout), in subprocesses that take turns (``--blocks`` rounds of one
subprocess per tree; each pair's figure is its smallest over the rounds). Per plan, in CPU time:

- **singularity side**: :func:`plan_clear_of_singularities` less the trajectory planning inside
  it (``plan_trajectory_request``): the measures, the detour searches and their bookkeeping;
- **measure**: :func:`measure_singularities` alone (all its calls in the plan);
- **bounded**: :func:`bounded_conditioning` alone (the measure less sampling the trajectory and
  building the report);
- **plan**: the whole ``plan_motion`` call.

Printed per arm, straight and routed plans apart: the median and mean of each, per tree, and the
median over the pairs of the second tree's over the first's. The plans themselves are compared
too (duration, the report's minimum inverse condition number, detours and unresolved segments):
the table counts the pairs where the trees agree. Pairs a tree fails to plan (no route found in
the time budget) are left out and counted. Prints a Markdown table and writes JSON and
the table to benchmarks/results/.

    python benchmarks/bench_singularity_plans.py --trees /path/to/main /path/to/branch [--paths 50] [--blocks 2]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
HERE = Path(__file__).resolve()


def worker(arm: str, paths: int, seed: int) -> list[dict]:
    """Plan every pair with the planner on ``sys.path`` and time its singularity side."""
    import planner.app.motion_plan as motion_plan
    import planner.motion.detours as detours
    import planner.motion.singularity as singularity
    from planner import load_robot
    from planner.app.plan_file import parse_motion_request
    from planner.collision import CollisionChecker, parse_scene
    from planner.exceptions import PlannerError

    sys.path.insert(0, str(HERE.parent))
    from bench_collision import BUDGET, SCENE

    robot = load_robot(arm)
    checker = CollisionChecker(robot, parse_scene(SCENE))
    rng = np.random.default_rng(seed)
    pairs = []
    while len(pairs) < paths:
        qa, qb = robot.random_configurations(rng, 2)
        if not (checker.in_collision(qa) or checker.in_collision(qb)):
            pairs.append((qa, qb))
    spent: dict[str, float] = {}

    def timed(module, name: str, key: str) -> None:
        f = getattr(module, name)

        def call(*args, **kwargs):
            start = time.process_time()
            try:
                return f(*args, **kwargs)
            finally:
                spent[key] = spent.get(key, 0.0) + time.process_time() - start

        setattr(module, name, call)

    timed(motion_plan, "plan_clear_of_singularities", "detours")
    timed(detours, "plan_trajectory_request", "timing")
    timed(detours, "measure_singularities", "measure")
    timed(motion_plan, "measure_singularities", "measure")
    timed(singularity, "bounded_conditioning", "bounded")
    rows = []
    warm = pairs[0]
    motion_plan.plan_motion(robot, parse_motion_request({"waypoints": [w.tolist() for w in warm], "scene": SCENE}))
    for i, (qa, qb) in enumerate(pairs):
        request = parse_motion_request(
            {
                "waypoints": [qa.tolist(), qb.tolist()],
                "scene": SCENE,
                "avoidance": {"seed": seed + i, "time_budget": BUDGET},
            }
        )
        spent.clear()
        start = time.process_time()
        try:
            plan = motion_plan.plan_motion(robot, request)
        except PlannerError:
            rows.append({"failed": True})
            continue
        total = time.process_time() - start
        rows.append(
            {
                "failed": False,
                "routed": bool(plan.routes),
                "plan": total,
                "side": spent.get("detours", 0.0) - spent.get("timing", 0.0),
                "measure": spent.get("measure", 0.0),
                "bounded": spent.get("bounded", 0.0),
                "duration": plan.trajectory.duration,
                "minimum": plan.singularity.min_inverse_condition,
                "detours": len(plan.detours),
                "unresolved": list(plan.unresolved),
            }
        )
    return rows


def run_block(tree: str, arm: str, paths: int, seed: int) -> list[dict]:
    env = dict(os.environ, PYTHONPATH=tree, OPENBLAS_NUM_THREADS="1")
    proc = subprocess.run(
        [sys.executable, str(HERE), "--worker", arm, "--paths", str(paths), "--seed", str(seed)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(proc.stdout.strip().splitlines()[-1])


def summary(arm: str, trees: list[str], blocks: list[list[list[dict]]]) -> dict:
    """Per tree, each pair's smallest figures over the rounds; then medians, means and ratios."""
    # The pairs every tree planned in every round.
    n = len(blocks[0][0])
    kept = [i for i in range(n) if not any(b[t][i]["failed"] for b in blocks for t in range(len(trees)))]
    best = []
    for t in range(len(trees)):
        rounds = [b[t] for b in blocks]
        best.append(
            [
                rounds[0][i] | {k: min(r[i][k] for r in rounds) for k in ("plan", "side", "measure", "bounded")}
                for i in kept
            ]
        )
    out: dict = {"arm": arm, "pairs": len(best[0]), "failed": n - len(kept)}
    same = [
        all(
            best[t][i][k] == best[0][i][k]
            for t in range(len(trees))
            for k in ("duration", "minimum", "detours", "unresolved")
        )
        for i in range(len(best[0]))
    ]
    out["plans_identical"] = int(sum(same))
    for kind, routed in (("straight", False), ("routed", True)):
        idx = [
            i for i, r in enumerate(best[0]) if r["routed"] == routed and all(b[i]["routed"] == routed for b in best)
        ]
        part: dict = {"plans": len(idx)}
        if idx:
            for key in ("side", "measure", "bounded", "plan"):
                values = [np.array([best[t][i][key] for i in idx]) * 1e3 for t in range(len(trees))]
                part[key] = {
                    "median_ms": [float(np.median(v)) for v in values],
                    "mean_ms": [float(np.mean(v)) for v in values],
                    "ratio_median": float(np.median(values[-1] / np.maximum(values[0], 1e-12))),
                }
        out[kind] = part
    return out


def table(rows: list[dict], trees: list[str]) -> str:
    names = " / ".join(Path(t).name or t for t in trees)
    lines = [
        f"| arm | plans | what | median ms ({names}) | mean ms ({names}) | median per-plan ratio |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        for kind in ("straight", "routed"):
            part = r[kind]
            for key, label in (
                ("side", "singularity side"),
                ("measure", "measure"),
                ("bounded", "bounded_conditioning"),
                ("plan", "whole plan"),
            ):
                if key not in part:
                    continue
                p = part[key]
                medians = " / ".join(f"{x:.2f}" for x in p["median_ms"])
                means = " / ".join(f"{x:.2f}" for x in p["mean_ms"])
                lines.append(
                    f"| {r['arm']} | {kind} {part['plans']} | {label} | {medians} | {means} | {p['ratio_median']:.2f} |"
                )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trees", nargs="+", help="source trees (PYTHONPATH) to compare; the first is the reference")
    parser.add_argument("--arms", nargs="+", default=["ur5", "panda"])
    parser.add_argument("--paths", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--blocks", type=int, default=2, help="rounds of one subprocess per tree")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.worker, args.paths, args.seed)))
        return 0
    if not args.trees:
        parser.error("--trees is required")
    rows = []
    for arm in args.arms:
        blocks = []
        for b in range(args.blocks):
            order = range(len(args.trees)) if b % 2 == 0 else reversed(range(len(args.trees)))
            got = {t: run_block(args.trees[t], arm, args.paths, args.seed) for t in order}
            blocks.append([got[t] for t in range(len(args.trees))])
        rows.append(summary(arm, args.trees, blocks))
    text = table(rows, args.trees)
    lines = [
        f"{r['arm']}: plans identical in both trees on {r['plans_identical']}/{r['pairs']} pairs "
        f"({r['failed']} pairs left out: not planned by a tree in a round)"
        for r in rows
    ]
    print(text + "\n\n" + "\n".join(lines))
    RESULTS.mkdir(parents=True, exist_ok=True)
    record = {"args": vars(args), "rows": rows}
    (RESULTS / "bench_singularity_plans.json").write_text(json.dumps(record, indent=1) + "\n")
    (RESULTS / "bench_singularity_plans.md").write_text(text + "\n\n" + "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
