"""Benchmark: the path search on routed requests, this tree against a reference tree, interleaved.

The start/goal pairs of ``bench_collision.py`` (its scene, seed and pair draw; pairs roboplan
finds in collision are skipped when roboplan is installed, as there) whose straight joint
segment is blocked (:func:`segment_looks_clear`, as :func:`plan_motion` decides to route),
searched the way :func:`plan_motion` searches: ``segment_looks_clear`` (at the tree's
plan_motion step) then
``find_clear_path(..., try_straight=False, certify=False)`` with the avoidance seed of the
pair. Each tree runs in its own process, alternating in blocks; per pair the median CPU time
over the rounds, then the median over pairs. Collision tests (the search's proximity tests) and
certificates per search are counted in a separate, untimed pass; the route's joint-space
length and whether :func:`certify_path` keeps it are compared per pair.

    python benchmarks/bench_path_search.py [--reference /work/main] [--arms ur5 panda] [--paths 50] [--rounds 5]

Without ``--reference`` only this tree is measured. Prints a table and writes
benchmarks/results/bench_path_search.json.
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
HERE = Path(__file__).resolve().parent.parent


def pairs_of(name: str, paths: int, seed: int) -> list[tuple[list, list, int]]:
    """bench_collision's pairs of arm `name` (index kept for the avoidance seed) that are routed."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_collision as bc

    from planner import load_robot
    from planner.collision import CollisionChecker, parse_scene
    from planner.collision.rrt import segment_looks_clear
    from planner.motion.limits import JointLimits

    robot = load_robot(name)
    checker = CollisionChecker(robot, parse_scene(bc.SCENE))
    try:
        rp = bc.Roboplan(name, robot, JointLimits.from_robot(robot), obstacles=True)
    except ImportError:
        rp = None
    rng = np.random.default_rng(seed)
    out, i = [], 0
    while i < paths:
        qa, qb = robot.random_configurations(rng, 2)
        if checker.in_collision(qa) or checker.in_collision(qb):
            continue
        if rp is not None and (rp.in_collision(rp.q_full(qa)) or rp.in_collision(rp.q_full(qb))):
            continue
        if not segment_looks_clear(checker, qa, qb):
            out.append((qa.tolist(), qb.tolist(), seed + i))
        i += 1
    return out


def worker(name: str, pairs: list, count: bool) -> list[dict]:
    """Search each pair as plan_motion does; CPU time, or (with `count`) tests, certificates and the path."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_collision as bc

    import planner.app.motion_plan as motion_plan
    import planner.collision.rrt as rrt
    from planner import load_robot
    from planner.collision import parse_scene
    from planner.collision.checker import shared_checker

    robot = load_robot(name)
    scene = parse_scene(bc.SCENE)
    counts = {"tests": 0, "certificates": 0}
    if count:
        # The search's proximity tests: its own (rrt._proximity_test) where the tree has one,
        # else closer_than's (a reference tree from before).
        patched = hasattr(rrt, "_proximity_test")
        real_test = rrt._proximity_test if patched else rrt.CollisionChecker.closer_than
        real_check = rrt.check_segment

        def closer_than(self, distance, allow=()):
            test = real_test(self, distance, allow)

            def counted(q):
                counts["tests"] += 1
                return test(q)

            return counted

        def check_segment(*args, **kwargs):
            counts["certificates"] += 1
            return real_check(*args, **kwargs)

        if patched:
            rrt._proximity_test = closer_than
        else:
            rrt.CollisionChecker.closer_than = closer_than
        rrt.check_segment = check_segment
    # The points plan_motion decides with that a straight segment is blocked, in that tree.
    look = getattr(motion_plan, "_PLAINLY_BLOCKED", 0.05)
    rows = []
    for qa, qb, seed in pairs:
        qa, qb = np.array(qa), np.array(qb)
        checker = shared_checker(robot, scene)
        options = rrt.PathOptions(seed=seed, time_budget=bc.BUDGET)
        counts.update(tests=0, certificates=0)
        c0 = time.process_time()
        rrt.segment_looks_clear(checker, qa, qb, resolution=look)
        found = rrt.find_clear_path(checker, qa, qb, options=options, try_straight=False, certify=False)
        cpu = time.process_time() - c0
        row: dict = {"cpu": cpu, "found": found.found, "iterations": found.iterations}
        if count:
            row.update(tests=counts["tests"])
            if found.found:
                path = np.asarray(found.path)
                row["length"] = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
                row["nodes"] = len(path)
                row["path"] = path.tolist()
                counts.update(tests=0, certificates=0)
                certified = rrt.certify_path(checker, found, options=options)
                row["certified_same"] = bool(np.array_equal(certified.path, found.path))
                row["certify_certificates"] = counts["certificates"]
        rows.append(row)
    return rows


def _median(values: list) -> float | None:
    return float(np.median(values)) if values else None


def _f(x: float | None, fmt: str = ".2f") -> str:
    return "n/a" if x is None else format(x, fmt)


def run(tree: str, name: str, pairs_file: str, count: bool) -> list[dict]:
    env = dict(os.environ, PYTHONPATH=tree, OPENBLAS_NUM_THREADS="1")
    cmd = [sys.executable, __file__, "--worker", name, pairs_file] + (["--count"] if count else [])
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True, cwd=tree)
    return json.loads(out.stdout)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reference", help="another tree (e.g. /work/main) to compare against")
    parser.add_argument("--arms", nargs="*", default=["ur5", "panda"])
    parser.add_argument("--paths", type=int, default=50, help="bench_collision's pairs per arm (routed ones kept)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rounds", type=int, default=5, help="timed runs per tree (interleaved)")
    parser.add_argument("--worker", nargs=2, help=argparse.SUPPRESS)
    parser.add_argument("--count", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        name, pairs_file = args.worker
        print(json.dumps(worker(name, json.loads(Path(pairs_file).read_text()), args.count)))
        return 0
    from planner.model.catalog import example_robot_data_dir

    if example_robot_data_dir() is None:
        print("example-robot-data is not installed: nothing to do")
        return 0
    trees = {"this": str(HERE)} | ({"reference": args.reference} if args.reference else {})
    RESULTS.mkdir(parents=True, exist_ok=True)
    record: dict = {"settings": vars(args) | {"trees": trees}, "arms": {}}
    lines = [
        "| arm | tree | routed pairs | found | CPU ms median (found) | p90 | tests median | length median | "
        "certify keeps | CPU ms median (not found) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name in args.arms:
        pairs = pairs_of(name, args.paths, args.seed)
        pairs_file = RESULTS / f"bench_path_search_{name}_pairs.json"
        pairs_file.write_text(json.dumps(pairs))
        cpu = {t: [] for t in trees}
        for _ in range(args.rounds):
            for t, tree in trees.items():
                cpu[t].append([r["cpu"] for r in run(tree, name, str(pairs_file), False)])
        counted = {t: run(tree, name, str(pairs_file), True) for t, tree in trees.items()}
        arm: dict = {"pairs": len(pairs)}
        for t in trees:
            per_pair = np.median(np.array(cpu[t]), axis=0) * 1e3
            rows = counted[t]
            for row, ms in zip(rows, per_pair):
                row["cpu_ms"] = float(ms)
            ok = [r for r in rows if r["found"]]
            missed = [r for r in rows if not r["found"]]
            arm[t] = {
                "rows": rows,
                "found": len(ok),
                "cpu_ms_median": _median([r["cpu_ms"] for r in ok]),
                "cpu_ms_p90": float(np.percentile([r["cpu_ms"] for r in ok], 90)) if ok else None,
                "tests_median": _median([r["tests"] for r in ok]),
                "length_median": _median([r["length"] for r in ok]),
                "certify_keeps": sum(r["certified_same"] for r in ok),
                "not_found_cpu_ms_median": _median([r["cpu_ms"] for r in missed]),
            }
            a = arm[t]
            lines.append(
                f"| {name} | {t} | {len(pairs)} | {a['found']} | {_f(a['cpu_ms_median'])} | {_f(a['cpu_ms_p90'])} | "
                f"{_f(a['tests_median'], '.0f')} | {_f(a['length_median'], '.3f')} | "
                f"{a['certify_keeps']}/{a['found']} | "
                f"{_f(a['not_found_cpu_ms_median'], '.1f')} |"
            )
        if "reference" in trees:
            both = [(a, b) for a, b in zip(arm["this"]["rows"], arm["reference"]["rows"]) if a["found"] and b["found"]]
            arm["cpu_ratio_median"] = _median([a["cpu_ms"] / b["cpu_ms"] for a, b in both])
            arm["tests_ratio_median"] = _median([a["tests"] / b["tests"] for a, b in both])
            arm["length_ratio_median"] = _median([a["length"] / b["length"] for a, b in both])
            arm["same_paths"] = sum(a["path"] == b["path"] for a, b in both)
            lines.append(
                f"| {name} | this / reference ({len(both)} both found; per-pair medians) | | | "
                f"{_f(arm['cpu_ratio_median'])} | | {_f(arm['tests_ratio_median'])} | "
                f"{_f(arm['length_ratio_median'])} | "
                f"same path {arm['same_paths']}/{len(both)} | |"
            )
        record["arms"][name] = arm
        pairs_file.unlink()
    table = "\n".join(lines)
    print(table)
    (RESULTS / "bench_path_search.json").write_text(json.dumps(record, indent=1) + "\n")
    (RESULTS / "bench_path_search.md").write_text(table + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
