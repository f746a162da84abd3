"""Check and time: two source trees plan bench_trajectory's paths, the same plans, how fast.

bench_trajectory.py's random paths (every available arm in its order, 5 waypoints, its
limits v = URDF, a = 2 v, j = 10 a, seed 0) are planned with :func:`planner.plan_trajectory`
(``--strategy``, default ``"optimized"``) by each tree given (``--trees``, e.g. main's
checkout and a branch), in subprocesses with ``PYTHONPATH`` set to the tree.

- Same plans: per plan a hash of its duration, waypoint times, via velocities and
  accelerations, repair flags and pieces (knots, p, v, a, j); prints per arm how many agree
  (and the duration ratios second / first where they do not); with ``--zero-sign-blind``
  plans that differ only in the sign of zeros count as the same.
  With ``--mixed N``, also N varied requests per arm (waypoints near the range ends, moving
  start states, stops, dwell, prescribed via velocities, minimum durations; seed 5), a
  failure hashed by its message.
- Speed: ``--rounds`` rounds, each one subprocess per tree in turn (the order alternating),
  timing every plan of the 6-dof arms (ur5, z1) ``--reps`` times (thread CPU time, the least
  counts). Prints per tree the median over rounds of the median plan time and the ratio of
  the second tree's to the first's per round (the machine may be shared: only the ratio,
  measured interleaved, means much).

    python benchmarks/trajectory_trees.py --trees /path/to/main . [--paths 100] [--rounds 6] [--reps 3]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve()
SIX_DOF = ("ur5", "z1")


def bench_paths(paths: int, seed: int) -> dict:
    """bench_trajectory's paths per arm: (limits, list of (5, dof) waypoints), drawn in its order."""
    from planner import available_robots, load_robot
    from planner.motion.limits import JointLimits

    rng = np.random.default_rng(seed)
    out = {}
    for name in available_robots():
        robot = load_robot(name)
        limits = JointLimits.from_robot(robot)
        robot.random_configurations(rng, 5)  # bench_trajectory's warm-up path
        out[name] = (limits, [robot.random_configurations(rng, 5) for _ in range(paths)])
    return out


#: With ``--zero-sign-blind``, the hashes take -0.0 as 0.0 (plans equal but for the sign of zeros agree).
_ZERO_SIGN_BLIND = os.environ.get("TRAJECTORY_TREES_ZERO_SIGN_BLIND") == "1"


def plan_hash(traj) -> str:
    """A hash of everything a plan holds."""
    h = hashlib.sha256()
    if _ZERO_SIGN_BLIND:
        for arr in (
            traj.waypoint_times,
            traj.via_velocities,
            traj.via_accelerations,
            traj.knots,
            traj.p,
            traj.v,
            traj.a,
        ):
            h.update((np.ascontiguousarray(arr, dtype=float) + 0.0).tobytes())
        h.update((np.ascontiguousarray(traj.j, dtype=float) + 0.0).tobytes())
        h.update(np.ascontiguousarray(traj.repaired).tobytes())
        h.update(repr((traj.duration + 0.0, traj.strategy)).encode())
        return h.hexdigest()[:16]
    for arr in (
        traj.waypoint_times,
        traj.via_velocities,
        traj.via_accelerations,
        traj.repaired,
        traj.knots,
        traj.p,
        traj.v,
        traj.a,
        traj.j,
    ):
        h.update(np.ascontiguousarray(arr).tobytes())
    h.update(repr((traj.duration, traj.strategy)).encode())
    return h.hexdigest()[:16]


def mixed_hashes(count: int, strategy: str) -> dict[str, list[str]]:
    """Per arm, the hashes of `count` varied requests (see the module docstring)."""
    from planner import available_robots, load_robot
    from planner.exceptions import PlannerError
    from planner.motion.limits import JointLimits
    from planner.motion.plan import plan_trajectory

    rng = np.random.default_rng(5)
    out = {}
    for name in available_robots():
        robot = load_robot(name)
        limits = JointLimits.from_robot(robot)
        upper = np.where(np.isfinite(limits.upper), limits.upper, 3.0)
        lower = np.where(np.isfinite(limits.lower), limits.lower, -3.0)
        hashes = []
        for _ in range(count):
            n = int(rng.integers(2, 8))
            q = robot.random_configurations(rng, n)
            options: dict = {"strategy": strategy}
            if rng.random() < 0.3:  # some waypoints near the upper range ends
                q = np.where(rng.random(q.shape) < 0.3, upper - rng.uniform(0, 0.05, q.shape) * (upper - lower), q)
            if rng.random() < 0.2:
                options["start_velocity"] = rng.uniform(-0.3, 0.3, robot.dof) * limits.velocity
            if rng.random() < 0.2 and n > 2:
                options["stops"] = [int(rng.integers(1, n - 1))]
            if rng.random() < 0.1:
                options["dwell"] = 0.1
            if rng.random() < 0.15 and n > 2:
                given = np.full((n, robot.dof), np.nan)
                given[1] = rng.uniform(-0.5, 0.5, robot.dof) * limits.velocity
                options["via_velocities"] = given
            if rng.random() < 0.1:
                options["min_durations"] = rng.uniform(0, 2, n - 1)
            try:
                hashes.append(plan_hash(plan_trajectory(q, limits, **options)))
            except PlannerError as exc:
                hashes.append(hashlib.sha256(f"failed: {exc}".encode()).hexdigest()[:16])
        out[name] = hashes
    return out


def worker(mode: str, paths: int, seed: int, strategy: str, reps: int, mixed: int = 0) -> dict:
    """Hash (mode "hash") or time (mode "time") the plans of the planner on ``sys.path``."""
    from planner.motion.plan import plan_trajectory

    data = bench_paths(paths, seed)
    if mode == "hash":
        out = {}
        for name, (limits, qs) in data.items():
            plans = [plan_trajectory(q, limits, strategy=strategy) for q in qs]
            out[name] = [(plan_hash(p), p.duration) for p in plans]
        if mixed:
            out["mixed"] = mixed_hashes(mixed, strategy)
        return out
    clock = time.thread_time
    times = {}
    for name in SIX_DOF:
        if name not in data:
            continue
        limits, qs = data[name]
        plan_trajectory(qs[0], limits, strategy=strategy)  # warm-up
        best = [float("inf")] * len(qs)
        for _ in range(reps):
            for p, q in enumerate(qs):
                t0 = clock()
                plan_trajectory(q, limits, strategy=strategy)
                best[p] = min(best[p], clock() - t0)
        times[name] = best
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trees", nargs=2, help="two source trees (PYTHONPATH) to compare")
    parser.add_argument("--paths", type=int, default=100, help="paths per arm")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--strategy", default="optimized")
    parser.add_argument("--rounds", type=int, default=6, help="timing rounds (0: only compare the plans)")
    parser.add_argument("--reps", type=int, default=3, help="timings per plan in a round (the least counts)")
    parser.add_argument("--no-hash", action="store_true", help="only time")
    parser.add_argument("--mixed", type=int, default=0, help="varied requests per arm to compare as well")
    parser.add_argument(
        "--zero-sign-blind", action="store_true", help="plans equal but for the sign of zeros count as the same"
    )
    parser.add_argument("--worker", choices=("hash", "time"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(worker(args.worker, args.paths, args.seed, args.strategy, args.reps, args.mixed)))
        return
    if not args.trees:
        parser.error("--trees is required")
    trees = [str(Path(t).resolve()) for t in args.trees]

    def child(tree: str, mode: str) -> dict:
        env = dict(os.environ, PYTHONPATH=tree, OPENBLAS_NUM_THREADS="1")
        env["TRAJECTORY_TREES_ZERO_SIGN_BLIND"] = "1" if args.zero_sign_blind else "0"
        cmd = [sys.executable, str(HERE), "--worker", mode, "--paths", str(args.paths), "--seed", str(args.seed)]
        cmd += ["--strategy", args.strategy, "--reps", str(args.reps), "--mixed", str(args.mixed)]
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
        return json.loads(proc.stdout.strip().splitlines()[-1])

    if not args.no_hash:
        first, second = (child(t, "hash") for t in trees)
        mixed = first.pop("mixed", {}), second.pop("mixed", {})
        for arm in mixed[0]:
            a, b = mixed[0][arm], mixed[1][arm]
            differ = [i for i, (x, y) in enumerate(zip(a, b)) if x != y]
            print(
                f"{arm} (varied requests): {len(a) - len(differ)}/{len(a)} plans identical"
                + (f"; differ: {differ}" if differ else "")
            )
        for arm in first:
            a, b = first[arm], second[arm]
            differ = [i for i, (x, y) in enumerate(zip(a, b)) if x[0] != y[0]]
            line = f"{arm}: {len(a) - len(differ)}/{len(a)} plans identical"
            if differ:
                ratio = np.array([b[i][1] / a[i][1] for i in differ])
                line += (
                    f"; differ: {differ[:20]}{' ...' if len(differ) > 20 else ''}; duration second / first "
                    f"mean {ratio.mean():.6f}, worst {ratio.max():.6f}, best {ratio.min():.6f}"
                )
            print(line)
    if args.rounds:
        medians = {t: [] for t in trees}
        for r in range(args.rounds):
            for t in trees if r % 2 == 0 else trees[::-1]:
                got = child(t, "time")
                medians[t].append(float(np.median([x for arm in got.values() for x in arm])) * 1e3)
        ratios = [b / a for a, b in zip(medians[trees[0]], medians[trees[1]])]
        for t in trees:
            print(f"{t}: median plan time (6-dof, least of {args.reps}) {np.median(medians[t]):.3f} ms over rounds")
        listed = ", ".join(f"{x:.3f}" for x in ratios)
        print(f"ratio second / first per round: {listed}; median {np.median(ratios):.3f}")


if __name__ == "__main__":
    main()
