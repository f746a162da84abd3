"""Benchmark: the closed-form IK (:mod:`planner.ik.analytic`), single calls and batches, per arm.

For every arm of the closed-form families (the bundled seed arms and, when example-robot-data
is installed, SO-101), random configurations within the joint limits (``--seed``) give the
targets by forward kinematics:

- ``shelley``, ``dh3`` (no wrist pitch): the tip position;
- ``three_joint``, ``al5c``, ``so101``: the tip position and its approach pitch (the elevation
  of the approach axis, outward from the base z axis: ``planner.geometry.target``). SO-101's gripper frame sits
  off its wrist roll axis, so the roll moves the tip: its targets pass the configuration as
  ``q_current`` (the source of the free roll). The others get no ``q_current``.

Timed: ``solver.solve(target)`` per target (wall time of the call, after a warm-up; median,
mean, 99th percentile, max over ``--single`` targets), and ``solver.solve_batch`` over
``--batch`` targets (best of 3; targets per second, position errors included; SO-101, whose
answers are corrected on its real geometry, at most 20,000). A second table does the same for
full-pose targets (FK rotation given, no ``q_current``; at most 500 single calls and 100,000
batched targets). Solve rate: the
share of targets where the result is "solved", every solution reproduces the target by Pinocchio
FK (< 1e-9 m, < 1e-9 rad pitch; checked for the single calls) and one solution equals the
generating configuration modulo 2 pi (< 1e-6 rad; checked for single calls and batches; for
al5c without the wrist roll, which is free there and set to 0).

Goals (issue 3), for a yaw + 3-link arm (three_joint, al5c): median single call <= 20 us, batch
>= 1,000,000 targets/s on one core, 100 % solve rate. Prints a Markdown table, writes JSON to
benchmarks/results/bench_analytic.json (and the table to bench_analytic.md).

    python benchmarks/bench_analytic.py [--single 3000] [--batch 1000000] [--seed 0]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one core
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from planner import Target, load_robot  # noqa: E402
from planner.app.benchmark import run_record  # noqa: E402
from planner.ik.analytic import chain_at_zero, closed_form_solver, poe_fk  # noqa: E402
from planner.model.catalog import example_robot_data_dir  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
PITCH_ARMS = ("three_joint", "al5c", "so101")
GOAL_ARMS = ("three_joint", "al5c")


def fk_targets(robot, q):
    """Tip positions (N, 3) and approach pitches (N,) of configurations, by the product of
    exponentials of the model's screws (vectorised; equal to Pinocchio's FK to 1e-12)."""
    chain = chain_at_zero(robot)
    pos, rot = poe_fk(
        [j.axis for j in chain.joints], [j.point for j in chain.joints], chain.tip_position, chain.tip_rotation, q
    )
    approach = rot @ robot.approach_axis
    yaw = chain.joints[0]
    sign = 1.0 if yaw.axis[2] > 0 else -1.0
    n0 = chain.joints[1].axis
    ang = sign * q[:, 0]
    # The first pitch axis turned by the yaw, then the arm plane's horizontal direction.
    n = np.stack([np.cos(ang) * n0[0] - np.sin(ang) * n0[1], np.sin(ang) * n0[0] + np.cos(ang) * n0[1]], axis=1)
    e_u = np.stack([-n[:, 1], n[:, 0]], axis=1) / np.linalg.norm(n, axis=1)[:, None]
    # planner.geometry.target: the horizontal part counts positive pointing away from the base z axis.
    side = np.sign(np.sum(pos[:, :2] * e_u, axis=1))
    side[side == 0] = 1.0
    along = np.sign(np.sum(approach[:, :2] * e_u, axis=1))  # the approach axis lies in the plane
    horiz = np.hypot(approach[:, 0], approach[:, 1]) * np.where(along == 0, 1.0, along) * side
    return pos, np.arctan2(approach[:, 2], horiz)


def same(a, b, free=None):
    """Equal modulo 2 pi (< 1e-6 rad) on every joint but the `free` one."""
    d = np.abs((a - b + np.pi) % (2 * np.pi) - np.pi)
    if free is not None:
        d = np.delete(d, free, axis=-1)
    return np.max(d, axis=-1) < 1e-6


def bench_arm(name, n_single, n_batch, seed):
    robot = load_robot(name)
    solver = closed_form_solver(robot)
    rng = np.random.default_rng(seed)
    use_pitch = name in PITCH_ARMS
    use_current = name == "so101"
    # al5c's wrist roll turns about the approach axis through the tip: without q_current it is
    # free (set to 0), so the comparison with the generating q skips it.
    free = solver.dof - 1 if getattr(solver, "has_roll", False) and not use_current else None
    n_batch = n_batch if solver.family == "planar2" or getattr(solver, "exact", True) else min(n_batch, 20000)

    q1 = robot.random_configurations(rng, n_single)
    p1, pitch1 = fk_targets(robot, q1)
    targets = [Target(p, pitch=float(a) if use_pitch else None) for p, a in zip(p1, pitch1)]
    currents = [q if use_current else None for q in q1]
    solver.solve(targets[0], currents[0])  # warm-up
    times = np.empty(n_single)
    results = []
    clock = time.perf_counter_ns
    for k, (target, qc) in enumerate(zip(targets, currents)):
        t0 = clock()
        res = solver.solve(target, qc)
        times[k] = clock() - t0
        results.append(res)
    times *= 1e-3  # us
    ok = 0
    worst_pos = 0.0
    worst_pitch = 0.0
    for q, target, res in zip(q1, targets, results):
        if res.status != "solved" or not res.solutions:
            continue
        qs = np.array([s.q for s in res.solutions])
        poses = robot.fk(qs)
        err = np.linalg.norm(poses[:, :3, 3] - target.position, axis=1)
        worst_pos = max(worst_pos, float(err.max()))
        good = bool(err.max() < 1e-9) and bool(np.any(same(qs, q, free)))
        if use_pitch:
            _, got = fk_targets(robot, qs)
            perr = np.abs((got - target.pitch + np.pi) % (2 * np.pi) - np.pi)
            worst_pitch = max(worst_pitch, float(perr.max()))
            good &= bool(perr.max() < 1e-9)
        ok += good

    q2 = robot.random_configurations(rng, n_batch)
    p2, pitch2 = fk_targets(robot, q2)
    kwargs = {"pitch": pitch2 if use_pitch else None, "q_current": q2 if use_current else None}
    solver.solve_batch(
        p2[:10], pitch=None if not use_pitch else pitch2[:10], q_current=None if not use_current else q2[:10]
    )  # warm-up
    best = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        batch = solver.solve_batch(p2, **kwargs)
        best = min(best, time.perf_counter() - t0)
    found = np.any(np.where(batch.valid, same(batch.q, q2[:, None, :], free), False), axis=1)
    batch_ok = (batch.status == 0) & found

    # Pose targets (a full rotation): the vectorised path also for one target.
    chain = chain_at_zero(robot)
    screws = ([j.axis for j in chain.joints], [j.point for j in chain.joints], chain.tip_position, chain.tip_rotation)
    n_pose = min(n_single, 500)
    q3 = robot.random_configurations(rng, n_pose)
    p3, r3 = poe_fk(*screws, q3)
    pose_targets = [Target(p, rotation=r) for p, r in zip(p3, r3)]
    solver.solve(pose_targets[0])
    pose_times = np.empty(n_pose)
    pose_ok = 0
    for k, (q, target) in enumerate(zip(q3, pose_targets)):
        t0 = clock()
        res = solver.solve(target)
        pose_times[k] = clock() - t0
        qs = np.array([s.q for s in res.solutions]) if res.solutions else np.zeros((0, robot.dof))
        pose_ok += res.status == "solved" and bool(np.any(same(qs, q)))
    pose_times *= 1e-3
    n_pose_batch = min(n_batch, 100_000)
    q4 = robot.random_configurations(rng, n_pose_batch)
    p4, r4 = poe_fk(*screws, q4)
    t0 = time.perf_counter()
    pose_batch = solver.solve_batch(p4, rotations=r4)
    pose_seconds = time.perf_counter() - t0
    pose_found = np.any(np.where(pose_batch.valid, same(pose_batch.q, q4[:, None, :]), False), axis=1)
    return {
        "robot": name,
        "family": solver.family,
        "dof": robot.dof,
        "target": "position + pitch" if use_pitch else "position",
        "q_current": use_current,
        "exact": bool(getattr(solver, "exact", True)),
        "single_n": n_single,
        "single_median_us": float(np.median(times)),
        "single_mean_us": float(np.mean(times)),
        "single_p99_us": float(np.percentile(times, 99)),
        "single_max_us": float(np.max(times)),
        "single_solve_rate": ok / n_single,
        "single_worst_position_error_m": worst_pos,
        "single_worst_pitch_error_rad": worst_pitch,
        "batch_n": n_batch,
        "batch_seconds": best,
        "batch_targets_per_s": n_batch / best,
        "batch_solve_rate": float(np.mean(batch_ok)),
        "batch_worst_position_error_m": float(np.nanmax(batch.position_error)),
        "pose_single_n": n_pose,
        "pose_single_median_us": float(np.median(pose_times)),
        "pose_single_p99_us": float(np.percentile(pose_times, 99)),
        "pose_single_solve_rate": pose_ok / n_pose,
        "pose_batch_n": n_pose_batch,
        "pose_batch_targets_per_s": n_pose_batch / pose_seconds,
        "pose_batch_solve_rate": float(np.mean((pose_batch.status == 0) & pose_found)),
    }


def markdown(rows):
    lines = [
        "| robot | target | single median [us] | mean | p99 | max | solve rate | batch [targets/s] | batch N | "
        "batch solve rate |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        target = r["target"] + (" (q_current)" if r["q_current"] else "")
        lines.append(
            f"| {r['robot']}{'' if r['exact'] else ' (corrected)'} | {target} | {r['single_median_us']:.1f} | "
            f"{r['single_mean_us']:.1f} | {r['single_p99_us']:.1f} | {r['single_max_us']:.0f} | "
            f"{100 * r['single_solve_rate']:.2f} % | {r['batch_targets_per_s']:,.0f} | {r['batch_n']:,} | "
            f"{100 * r['batch_solve_rate']:.2f} % |"
        )
    lines += [
        "",
        "Full-pose targets (rotation given; the vectorised path, also for single calls):",
        "",
        "| robot | single median [us] | p99 | solve rate | batch [targets/s] | batch N | batch solve rate |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        lines.append(
            f"| {r['robot']} | {r['pose_single_median_us']:.0f} | {r['pose_single_p99_us']:.0f} | "
            f"{100 * r['pose_single_solve_rate']:.2f} % | {r['pose_batch_targets_per_s']:,.0f} | "
            f"{r['pose_batch_n']:,} | {100 * r['pose_batch_solve_rate']:.2f} % |"
        )
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--single", type=int, default=3000, help="targets for single-call timing")
    parser.add_argument("--batch", type=int, default=1_000_000, help="targets for the batch timing")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--robots", nargs="*", default=None)
    args = parser.parse_args(argv)
    names = args.robots or ["shelley", "dh3", "three_joint", "al5c"] + (
        ["so101"] if example_robot_data_dir() is not None else []
    )
    rows = []
    for name in names:
        rows.append(bench_arm(name, args.single, args.batch, args.seed))
        print(f"{name}: done", file=sys.stderr)
    table = markdown(rows)
    goal = [r for r in rows if r["robot"] in GOAL_ARMS]

    def meets(ok):
        return "meets" if ok else "misses"

    verdict = "; ".join(
        f"{r['robot']}: median {r['single_median_us']:.1f} us ({meets(r['single_median_us'] <= 20)} <= 20 us), "
        f"batch {r['batch_targets_per_s']:,.0f}/s ({meets(r['batch_targets_per_s'] >= 1e6)} >= 1e6/s), "
        f"solve rate {100 * min(r['single_solve_rate'], r['batch_solve_rate']):.2f} %"
        for r in goal
    )
    print(table)
    print()
    print("Goal (yaw + 3-link arm): " + verdict)
    record = {
        **run_record("bench_analytic", ("numpy", "pin", "example-robot-data")),
        "settings": {"single": args.single, "batch": args.batch, "seed": args.seed},
        "goal": verdict,
        "rows": rows,
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "bench_analytic.json").write_text(json.dumps(record, indent=2) + "\n")
    (RESULTS / "bench_analytic.md").write_text(
        f"# bench_analytic ({record['date']})\n\n`{record['command']}`\n\n{table}\n\n"
        f"Goal (yaw + 3-link arm): {verdict}\n"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
