"""Benchmark: the continuous check's CPU time per plan, two source trees interleaved.

The continuous checks (:func:`~planner.collision.continuous.check_trajectory` and
:func:`~planner.collision.continuous.check_segment`) that :func:`planner.app.motion_plan.plan_motion`
makes on bench_collision.py's start/goal pairs (its table-and-box scene, seed 0; pairs our
checker finds collision-free) are recorded once with the first tree, then replayed by each tree
in turn (a subprocess per tree and round, ``PYTHONPATH`` set to the tree), so that the trees
check the very same trajectories on the same machine under the same load. Per plan: CPU time of
its checks (the least of ``--reps`` repetitions), configurations checked, pair distances
computed (all of them, a check of every pair too) and bounding pairs' distances
(:class:`~planner.collision.checker.BoundingPairs`); medians over the straight plans and the
routed ones apart. Each replay also compares its results with the recorded ones: the same
verdicts, first hits within 1 ms, closest distances within 2 mm (the checks fall at other
instants).

    python benchmarks/bench_continuous.py --trees /work/main . [--paths 30] [--rounds 3] [--reps 5]

Prints a Markdown table and writes it with the JSON to benchmarks/results/.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
ARMS = ("panda", "ur5")


def record(path: str, paths: int) -> None:
    """Plan `paths` pairs per arm and pickle every continuous check call with its result to `path`."""
    import planner.app.motion_plan as motion_plan
    from planner import load_robot
    from planner.app.plan_file import parse_motion_request
    from planner.collision import CollisionChecker, parse_scene
    from planner.exceptions import PlannerError

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_collision import BUDGET, SCENE

    out: dict = {}
    saved = motion_plan.check_trajectory, motion_plan.check_segment
    calls: list = []

    def trajectory(checker, traj, **kw):
        r = saved[0](checker, traj, **kw)
        calls.append(("t", traj, kw, (r.clear, r.first_hit, r.closest.distance)))
        return r

    def segment(checker, a, b, **kw):
        r = saved[1](checker, a, b, **kw)
        calls.append(("s", (a, b), kw, (r.clear, r.first_hit, r.closest.distance)))
        return r

    motion_plan.check_trajectory, motion_plan.check_segment = trajectory, segment
    try:
        for name in ARMS:
            robot = load_robot(name)
            checker = CollisionChecker(robot, parse_scene(SCENE))
            rng = np.random.default_rng(0)
            plans = []
            while len(plans) < paths:
                qa, qb = robot.random_configurations(rng, 2)
                if checker.in_collision(qa) or checker.in_collision(qb):
                    continue
                calls = []
                request = {"waypoints": [qa.tolist(), qb.tolist()], "scene": SCENE}
                request["avoidance"] = {"seed": len(plans), "time_budget": BUDGET}
                try:
                    plan = motion_plan.plan_motion(robot, parse_motion_request(request))
                except PlannerError:
                    plans.append((None, []))
                    continue
                plans.append((bool(plan.routes), calls))
            out[name] = plans
    finally:
        motion_plan.check_trajectory, motion_plan.check_segment = saved
    Path(path).write_bytes(pickle.dumps(out))


def _count_distances(checker, computed: list[int]) -> None:
    """Count in `computed` the pair distances the checker computes, and its bounding pairs' (trees without them: 0).

    Every distance counts, those of a check's every pair too (:meth:`pair_distances`, the pairs
    on its mask). Trees with ``placed_distances`` compute through it (``distances_of`` too).
    """
    wrap = "placed_distances" if hasattr(checker, "placed_distances") else "distances_of"
    inner = getattr(checker, wrap)
    whole = checker.pair_distances

    def counted(*args):
        computed[0] += len(args[-1])
        return inner(*args)

    def counted_all(q, mask):
        computed[0] += int(mask.sum())
        return whole(q, mask)

    setattr(checker, wrap, counted)
    checker.pair_distances = counted_all
    if hasattr(checker, "bounding_pairs"):
        bounds = checker.bounding_pairs()
        bounded = bounds.placed_distances

        def counted_bounds(pairs):
            computed[1] += len(pairs)
            return bounded(pairs)

        bounds.placed_distances = counted_bounds


def replay(path: str, reps: int) -> dict:
    """Per arm, the medians of the recorded plans' checks replayed by the tree on ``sys.path``."""
    from planner import load_robot
    from planner.collision import CollisionChecker, parse_scene
    from planner.collision.continuous import check_segment, check_trajectory

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_collision import SCENE

    recorded = pickle.loads(Path(path).read_bytes())
    summary: dict = {}
    for name, plans in recorded.items():
        checker = CollisionChecker(load_robot(name), parse_scene(SCENE))
        computed = [0, 0]
        _count_distances(checker, computed)

        def run(call, checker=checker):
            kind, what, kw, _ = call
            return check_trajectory(checker, what, **kw) if kind == "t" else check_segment(checker, *what, **kw)

        rows: dict = {"straight": [], "routed": []}
        differ = 0
        for routed, calls in plans:
            if routed is None or not calls:
                continue
            for call in calls:  # warm-up, and the results against the recorded ones
                r, (clear, hit, closest) = run(call), call[3]
                if r.clear != clear or abs((r.first_hit or 0.0) - (hit or 0.0)) > 1e-3:
                    differ += 1
                elif abs(r.closest.distance - closest) > 2e-3:
                    differ += 1
            best = np.inf
            for _ in range(reps):
                c0 = time.process_time()
                for call in calls:
                    run(call)
                best = min(best, time.process_time() - c0)
            before = list(computed)
            checks = sum(run(call).checks for call in calls)
            pairs, bounding = computed[0] - before[0], computed[1] - before[1]
            rows["routed" if routed else "straight"].append((best * 1e3, checks, pairs, bounding))
        summary[name] = {"differ": differ}
        for kind, values in rows.items():
            if values:
                a = np.array(values)
                summary[name][kind] = {
                    "plans": len(values),
                    "cpu_ms": float(np.median(a[:, 0])),
                    "checks": float(np.median(a[:, 1])),
                    "pair_distances": float(np.median(a[:, 2])),
                    "bounding_distances": float(np.median(a[:, 3])),
                }
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trees", nargs="+", default=["."], help="source trees to compare (first: reference)")
    parser.add_argument("--paths", type=int, default=30, help="start/goal pairs per arm")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of one replay per tree")
    parser.add_argument("--reps", type=int, default=5, help="repetitions per plan in a replay (the least counts)")
    parser.add_argument("--record", help=argparse.SUPPRESS)
    parser.add_argument("--replay", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.record:
        record(args.record, args.paths)
        return 0
    if args.replay:
        print(json.dumps(replay(args.replay, args.reps)))
        return 0
    trees = [str(Path(t).resolve()) for t in args.trees]
    me = str(Path(__file__).resolve())

    def child(tree: str, *extra: str) -> str:
        env = {**os.environ, "PYTHONPATH": tree, "OPENBLAS_NUM_THREADS": "1"}
        return subprocess.run([sys.executable, me, *extra], env=env, check=True, capture_output=True, text=True).stdout

    with tempfile.TemporaryDirectory() as tmp:
        calls = str(Path(tmp) / "calls.pkl")
        child(trees[0], "--record", calls, "--paths", str(args.paths))
        runs: dict = {t: [] for t in trees}
        for _ in range(args.rounds):
            for t in trees:
                runs[t].append(json.loads(child(t, "--replay", calls, "--reps", str(args.reps))))
    lines = [
        "| tree | arm | plans | CPU ms per plan (median of rounds) | checks | pair distances | bounding distances "
        "| results differing |",
        "|---|---|---|---|---|---|---|---|",
    ]
    record_out: dict = {"paths": args.paths, "rounds": args.rounds, "reps": args.reps, "trees": {}}
    for t in trees:
        record_out["trees"][t] = runs[t]
        for name in ARMS:
            for kind in ("straight", "routed"):
                got = [r[name][kind] for r in runs[t] if kind in r[name]]
                if not got:
                    continue
                cpu = float(np.median([g["cpu_ms"] for g in got]))
                lines.append(
                    f"| {t} | {name} {kind} | {got[0]['plans']} | {cpu:.2f} | {got[0]['checks']:.0f} | "
                    f"{got[0]['pair_distances']:.0f} | {got[0].get('bounding_distances', 0):.0f} | "
                    f"{max(r[name]['differ'] for r in runs[t])} |"
                )
    table = "\n".join(lines)
    print(table)
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_continuous.json").write_text(json.dumps(record_out, indent=1) + "\n")
    (RESULTS / "bench_continuous.md").write_text(table + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
