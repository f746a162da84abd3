"""Benchmark: what the singularity checks of a plan cost, against measuring every sample exactly.

For every arm (the bundled seed arms and, when example-robot-data is installed, ur5 and panda),
``--pairs`` random waypoint pairs within the joint limits (``--seed``) are planned with
:func:`planner.app.motion_plan.plan_motion` (no scene: the demo's path; with ``--scene`` also in
bench_collision's table-and-box scene for ur5 and panda, pairs clear of it, as that benchmark
draws them). Each planned trajectory is then measured twice, interleaved, in CPU time:

- **bounded**: :func:`planner.motion.singularity.measure_singularities` as the planner calls it
  (1 kHz samples; exact values only where a decision needs them, bounds elsewhere);
- **exact**: every sample through :meth:`Robot.conditioning`, the report built from those.

The two reports must be identical (same minimum, where, which samples are below the threshold,
waypoint values): the table counts the pairs where they are. It shows the median plan time, the
median CPU time of both measures and their ratio, and how many Jacobians (Pinocchio's and the
compiled kernel's) and SVDs the bounded measure computed per sample. Prints a Markdown table
and writes JSON and the table to benchmarks/results/.

    python benchmarks/bench_singularity_cost.py [--pairs 20] [--seed 7] [--scene] [--arms ur5 panda ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import planner.motion.singularity as singularity
from planner import load_robot
from planner.app.benchmark import run_record
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
from planner.exceptions import PlannerError
from planner.geometry.jacobian_kernel import jacobian_kernel
from planner.model.catalog import BUNDLED_ROBOTS, EXAMPLE_ROBOTS, example_robot_data_dir
from planner.motion.singularity import SingularityReport, inverse_condition_threshold, measure_singularities

RESULTS = Path(__file__).resolve().parent / "results"
RATE = 1000.0


def exact_report(robot, trajectory, threshold: float, task: str) -> SingularityReport:
    """The report from every sample measured exactly (the measure before the bounds)."""
    t = np.unique(np.concatenate([trajectory.times(RATE), trajectory.waypoint_times]))
    q = trajectory.sample(t).q
    inv, man = robot.conditioning(q, task)
    w = np.searchsorted(t, trajectory.waypoint_times)
    k = int(np.argmin(inv))
    low = np.concatenate([[False], inv < threshold, [False]]).astype(np.int8)
    starts, ends = np.flatnonzero(np.diff(low) == 1), np.flatnonzero(np.diff(low) == -1) - 1
    return SingularityReport(
        threshold=threshold,
        task=task,
        rate=RATE,
        waypoint_inverse_condition=inv[w],
        waypoint_manipulability=man[w],
        singular_waypoints=tuple(int(i) for i in np.nonzero(inv[w] < threshold)[0]),
        min_inverse_condition=float(inv[k]),
        min_manipulability=float(np.min(man)),
        time_of_minimum=float(t[k]),
        q_at_minimum=q[k],
        below_threshold=tuple((float(t[a]), float(t[b])) for a, b in zip(starts, ends)),
    )


def same(a: SingularityReport, b: SingularityReport) -> bool:
    for name in a.__dataclass_fields__:
        x, y = getattr(a, name), getattr(b, name)
        if not (np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y):
            return False
    return True


class Counting:
    """Counts the rows of a robot's Jacobians and SVDs (wraps its methods on the instance).

    ``jacobians`` counts Pinocchio's (:meth:`Robot.task_jacobians`), ``compiled`` those of the
    compiled chain kernel the measure takes for its bounds (:mod:`planner.geometry.jacobian_kernel`).
    """

    def __init__(self, robot) -> None:
        self.jacobians = self.svds = self.compiled = 0
        jacobians, singular_values = robot.task_jacobians, robot.task_singular_values
        kernel, find = jacobian_kernel(robot), singularity.jacobian_kernel

        def counted(q):
            self.compiled += len(q)
            return kernel(q)

        if kernel is not None:
            singularity.jacobian_kernel = lambda other: counted if other is robot else find(other)

        def task_jacobians(q, task=None):
            self.jacobians += len(q)
            return jacobians(q, task)

        def task_singular_values(raw, scaled, task=None):
            self.svds += len(raw)
            return singular_values(raw, scaled, task)

        robot.task_jacobians, robot.task_singular_values = task_jacobians, task_singular_values


def cpu(f, *args) -> tuple[float, object]:
    """CPU time of ``f(*args)`` [s] (other processes on the machine do not count) and its value."""
    start = time.process_time()
    out = f(*args)
    return time.process_time() - start, out


def pairs_for(robot, n: int, seed: int, scene: dict | None) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    checker = None
    if scene is not None:
        from planner.collision import CollisionChecker, parse_scene

        checker = CollisionChecker(robot, parse_scene(scene))
    out = []
    while len(out) < n:
        a, b = robot.random_configurations(rng, 2)
        if checker is None or not (checker.in_collision(a) or checker.in_collision(b)):
            out.append((a, b))
    return out


def run(arm: str, pairs: int, seed: int, scene: dict | None) -> dict:
    robot = load_robot(arm)
    task = robot.resolve_task(None)
    threshold = inverse_condition_threshold(None, task)
    counting = Counting(robot)
    plan_times, bounded, exact, samples, agree, failed = [], [], [], 0, 0, 0
    jacobians = svds = compiled = 0  # of the bounded measure
    for i, (a, b) in enumerate(pairs_for(robot, pairs, seed, scene)):
        spec: dict = {"waypoints": [a.tolist(), b.tolist()]}
        if scene is not None:
            spec.update(scene=scene, avoidance={"seed": i, "time_budget": 5.0})
        try:
            seconds, plan = cpu(plan_motion, robot, parse_motion_request(spec))
        except PlannerError:
            failed += 1
            continue
        plan_times.append(seconds)
        trajectory = plan.trajectory
        before = (counting.jacobians, counting.svds, counting.compiled)
        t_bounded, (report, t, _, _) = cpu(measure_singularities, robot, trajectory, threshold, task, RATE)
        jac_svd = (counting.jacobians - before[0], counting.svds - before[1], counting.compiled - before[2])
        t_exact, reference = cpu(exact_report, robot, trajectory, threshold, task)
        # Interleaved once more, the other way round, against drifts of the machine's speed.
        t_exact2 = cpu(exact_report, robot, trajectory, threshold, task)[0]
        t_bounded2 = cpu(measure_singularities, robot, trajectory, threshold, task, RATE)[0]
        bounded.append(min(t_bounded, t_bounded2))
        exact.append(min(t_exact, t_exact2))
        samples += len(t)
        jacobians, svds, compiled = jacobians + jac_svd[0], svds + jac_svd[1], compiled + jac_svd[2]
        agree += same(report, reference)
    n = len(plan_times)
    return {
        "arm": arm,
        "scene": scene is not None,
        "pairs": pairs,
        "planned": n,
        "failed": failed,
        "samples": samples,
        "plan_ms_median": float(np.median(plan_times) * 1e3) if n else None,
        "bounded_ms_median": float(np.median(bounded) * 1e3) if n else None,
        "exact_ms_median": float(np.median(exact) * 1e3) if n else None,
        "exact_over_bounded": float(np.sum(exact) / np.sum(bounded)) if n else None,
        "jacobians_per_sample": jacobians / samples if samples else None,
        "svds_per_sample": svds / samples if samples else None,
        "compiled_jacobians_per_sample": compiled / samples if samples else None,
        "reports_identical": agree,
    }


def _f(x, fmt: str) -> str:
    return "-" if x is None else format(x, fmt)


def table(rows: list[dict]) -> str:
    lines = [
        "| arm | scene | planned | plan median [ms] | bounded measure median [ms] | exact median [ms] "
        "| exact / bounded | Jacobians / sample | compiled Jacobians / sample | SVDs / sample | reports identical |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['arm']} | {'table and box' if r['scene'] else 'none'} | {r['planned']}/{r['pairs']} "
            f"| {_f(r['plan_ms_median'], '.2f')} | {_f(r['bounded_ms_median'], '.2f')} "
            f"| {_f(r['exact_ms_median'], '.2f')} | {_f(r['exact_over_bounded'], '.2f')} "
            f"| {_f(r['jacobians_per_sample'], '.3f')} | {_f(r['compiled_jacobians_per_sample'], '.3f')} "
            f"| {_f(r['svds_per_sample'], '.3f')} "
            f"| {r['reports_identical']}/{r['planned']} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=20)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--scene", action="store_true", help="also plan ur5 and panda in bench_collision's scene")
    examples = list(EXAMPLE_ROBOTS) if example_robot_data_dir() is not None else []
    default_arms = [*BUNDLED_ROBOTS, *(a for a in ("ur5", "panda") if a in examples)]
    parser.add_argument("--arms", nargs="+", default=default_arms)
    args = parser.parse_args(argv)
    rows = [run(arm, args.pairs, args.seed, None) for arm in args.arms]
    if args.scene:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from bench_collision import SCENE

        rows += [run(arm, args.pairs, args.seed, SCENE) for arm in args.arms if arm in ("ur5", "panda")]
    text = table(rows)
    print(text)
    RESULTS.mkdir(exist_ok=True)
    record = run_record("bench_singularity_cost", ["pin", "numpy"])
    record.update({"pairs": args.pairs, "seed": args.seed, "rate": RATE, "arms": rows})
    (RESULTS / "bench_singularity_cost.json").write_text(json.dumps(record, indent=2) + "\n")
    (RESULTS / "bench_singularity_cost.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
