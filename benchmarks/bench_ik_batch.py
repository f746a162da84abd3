"""Benchmark: batch numerical IK (``NlpIK.solve_batch``, one compiled kernel) against single calls.

For every arm (ur5, panda, so101, z1, ur10 when example-robot-data is installed, and the
bundled arms): N random configurations within the limits (``--seed``) give the targets (full
6-D poses for the example-robot-data arms, position + approach pitch for al5c and
three_joint, positions for shelley and dh3), another draw the seeds, one per target (both from
``numpy.random.default_rng((seed, 1))`` and ``((seed, 2))``: streams apart from the solver's
restart configurations, ``default_rng(0)``). ``solve_batch(targets, seeds)`` is timed against ``--singles`` single
``NlpIK.solve(target, seed)`` calls on the first targets, interleaved in ``--rounds`` rounds so
both see the same machine load; the ratio is the batch's targets/s over the single calls'.

Success = position error < 1e-4 m and orientation error < 1e-3 rad by Pinocchio FK computed
here (``Robot.fk``, not the solver's figures), within the joint limits. Rates are targets per
second of wall time and of this process's CPU time (the machine is shared: the CPU figure is
what one core does). BLAS is held to one thread (set before numpy loads). One-off setup
(building or loading the compiled kernels) is done before timing.

Goal (issue 12): >= 20,000 pose targets/s on one core for ur5, 100 % solved.

    python benchmarks/bench_ik_batch.py [--n 20000] [--singles 1000] [--robots ur5 al5c]
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from planner import available_robots, load_robot  # noqa: E402
from planner.app.benchmark import BUNDLED_KINDS, ORIENTATION_TOL, POSITION_TOL, make_target, run_record  # noqa: E402
from planner.core.rotations import rotation_error  # noqa: E402
from planner.geometry.target import target_errors  # noqa: E402
from planner.ik.numeric.solver import NlpIK  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
EXAMPLE_ARMS = ("ur5", "panda", "so101", "z1", "ur10")
GOAL_ROBOT, GOAL_RATE = "ur5", 20_000.0


def _verified(robot, targets, q: np.ndarray) -> np.ndarray:
    """Success of each row of q by Pinocchio FK (Robot.fk), the tolerances and the limits."""
    ok = np.zeros(len(q), dtype=bool)
    for i, (target, row) in enumerate(zip(targets, q)):
        pose = robot.fk(row)
        pe = float(np.linalg.norm(pose[:3, 3] - target.position))
        if target.rotation is not None:
            oe = float(rotation_error(pose[:3, :3], target.rotation))
        else:
            oe = target_errors(robot, target, row)[1]
        ok[i] = pe < POSITION_TOL and oe < ORIENTATION_TOL
    return ok & robot.within_limits(q)


def bench(name: str, n: int, singles: int, rounds: int, seed: int) -> dict:
    """One arm: batch and single-call rates, solve rates, attempts."""
    robot = load_robot(name)
    kind = BUNDLED_KINDS.get(name, "pose")
    ik = NlpIK(robot)
    # Streams of their own: NlpIK's restart configurations come from default_rng(0), and targets
    # drawn from the same stream would hand the batch their exact solutions as restarts.
    q_true = robot.random_configurations(np.random.default_rng((seed, 1)), n)
    seeds = robot.random_configurations(np.random.default_rng((seed, 2)), n)
    targets = [make_target(robot, kind, q) for q in q_true]
    # Arrays where the kind has an array form (what a user with many poses passes).
    if kind == "pose":
        batch_input = np.stack([robot.fk(q) for q in q_true])
    elif kind == "position":
        batch_input = np.array([t.position for t in targets])
    else:
        batch_input = targets
    t0 = time.perf_counter()
    ik.solve_batch(batch_input[:4], seeds[:4])
    ik.solve(targets[0], seeds[0])
    setup = time.perf_counter() - t0

    singles = min(singles, n)
    batch_q = np.zeros((n, robot.dof))
    batch_attempts = np.zeros(n, dtype=int)
    batch_seed = np.zeros(n, dtype=bool)
    single_q = np.zeros((singles, robot.dof))
    wall = {"batch": 0.0, "single": 0.0}
    cpu = {"batch": 0.0, "single": 0.0}
    cuts = np.linspace(0, n, rounds + 1).astype(int)
    single_cuts = np.linspace(0, singles, rounds + 1).astype(int)
    for r in range(rounds):
        a, b = cuts[r], cuts[r + 1]
        w, c = time.perf_counter(), time.process_time()
        result = ik.solve_batch(batch_input[a:b], seeds[a:b])
        cpu["batch"] += time.process_time() - c
        wall["batch"] += time.perf_counter() - w
        batch_q[a:b] = result.q
        batch_attempts[a:b] = result.attempts
        batch_seed[a:b] = result.attempt == 0
        for i in range(single_cuts[r], single_cuts[r + 1]):
            w, c = time.perf_counter(), time.process_time()
            answer = ik.solve(targets[i], seeds[i])
            cpu["single"] += time.process_time() - c
            wall["single"] += time.perf_counter() - w
            single_q[i] = answer.q
    batch_ok = _verified(robot, targets, batch_q)
    single_ok = _verified(robot, targets[:singles], single_q)
    rate = {k: n / wall["batch"] if k == "wall" else n / cpu["batch"] for k in ("wall", "cpu")}
    single_rate = {k: singles / (wall if k == "wall" else cpu)["single"] for k in ("wall", "cpu")}
    return {
        "robot": name,
        "dof": robot.dof,
        "kind": kind,
        "n": n,
        "singles": singles,
        "batch_targets_per_s_wall": rate["wall"],
        "batch_targets_per_s_cpu": rate["cpu"],
        "single_targets_per_s_wall": single_rate["wall"],
        "single_targets_per_s_cpu": single_rate["cpu"],
        "ratio_wall": rate["wall"] / single_rate["wall"],
        "ratio_cpu": rate["cpu"] / single_rate["cpu"],
        "batch_solve_rate": float(batch_ok.mean()),
        "single_solve_rate": float(single_ok.mean()),
        "batch_mean_attempts": float(batch_attempts.mean()),
        "batch_max_attempts": int(batch_attempts.max()),
        "batch_answered_by_seed": float(batch_seed.mean()),
        "compiled": ik.compiled(kind),
        "setup_s": setup,
    }


def markdown(rows: list[dict]) -> str:
    """The results as a Markdown table."""
    lines = [
        "| arm | dof | target | N | batch targets/s (CPU) | batch targets/s (wall) | single calls/s (CPU) | "
        "batch / single (CPU) | batch / single (wall) | batch solved | singles solved | mean attempts | "
        "by the seed |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['robot']} | {r['dof']} | {r['kind']} | {r['n']} | {r['batch_targets_per_s_cpu']:,.0f} | "
            f"{r['batch_targets_per_s_wall']:,.0f} | {r['single_targets_per_s_cpu']:,.0f} | "
            f"{r['ratio_cpu']:.1f}x | {r['ratio_wall']:.1f}x | {100 * r['batch_solve_rate']:.2f} % | "
            f"{100 * r['single_solve_rate']:.2f} % ({r['singles']}) | {r['batch_mean_attempts']:.2f} | "
            f"{100 * r['batch_answered_by_seed']:.1f} % |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20_000, help="targets per arm (default 20000)")
    parser.add_argument("--singles", type=int, default=1000, help="single calls timed per arm (default 1000)")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds of batch and single calls")
    parser.add_argument("--seed", type=int, default=0, help="seed of the target and seed configurations")
    parser.add_argument("--robots", nargs="*", default=None, help="robots (default: every available one)")
    parser.add_argument("--out", type=Path, default=RESULTS / "bench_ik_batch", help="output stem (.md, .json)")
    args = parser.parse_args(argv)
    if args.n < 1 or args.singles < 1 or args.rounds < 1:
        parser.error("--n, --singles and --rounds must be >= 1")
    available = set(available_robots())
    names = args.robots or [r for r in (*EXAMPLE_ARMS, *BUNDLED_KINDS) if r in available]
    missing = [r for r in EXAMPLE_ARMS if r not in available]
    if missing:
        print(f"example-robot-data not installed: skipping {', '.join(missing)}")
    rows = []
    for name in names:
        rows.append(bench(name, args.n, args.singles, args.rounds, args.seed))
        print(markdown(rows[-1:]).splitlines()[-1], flush=True)
    table = markdown(rows)
    print()
    print(table)
    goal = next((r for r in rows if r["robot"] == GOAL_ROBOT), None)
    verdict = ""
    if goal is not None:
        met = goal["batch_targets_per_s_cpu"] >= GOAL_RATE and goal["batch_solve_rate"] == 1.0
        verdict = (
            f"Goal (issue 12): >= {GOAL_RATE:,.0f} {GOAL_ROBOT} pose targets/s on one core with 100 % solved: "
            f"{goal['batch_targets_per_s_cpu']:,.0f}/s of CPU time ({goal['batch_targets_per_s_wall']:,.0f}/s of wall "
            f"time on a shared machine), {100 * goal['batch_solve_rate']:.2f} % solved: "
            f"{'met' if met else 'NOT met'}."
        )
        print()
        print(verdict)
    record = {
        **run_record("bench_ik_batch", ("casadi", "pin", "numpy", "example-robot-data")),
        "settings": {
            "n": args.n,
            "singles": args.singles,
            "rounds": args.rounds,
            "seed": args.seed,
            "success": f"position < {POSITION_TOL} m, orientation < {ORIENTATION_TOL} rad (Pinocchio FK), in limits",
            "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
        },
        "rows": rows,
        "goal": verdict,
        "table": table,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    json_path, md_path = args.out.with_suffix(".json"), args.out.with_suffix(".md")
    json_path.write_text(json.dumps(record, indent=2, allow_nan=False) + "\n")
    md_path.write_text(
        "# Batch numerical IK vs single calls\n\n"
        f"`{record['command']}` on {record['date']} ({record['machine']['processor']}, "
        f"{record['machine']['cpus']} CPUs, load average {record['machine']['load_average']}).\n\n"
        f"{table}\n\n{verdict}\n"
    )
    print(f"\nwrote {json_path}, {md_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
