"""Benchmark: which random configurations the singularity measure flags, before and after issue 11.

For every arm (the bundled seed arms and, when example-robot-data is installed, ur5, panda and
z1), ``--configs`` configurations drawn uniformly within the joint limits (``--seed``) are
measured twice:

- **before**: the inverse condition number of the raw task Jacobian (rows ``[v; omega]`` in
  m/rad and rad/rad for the pose task, so its value depends on the arm's size), against the
  old default threshold 1/30;
- **after**: :meth:`Robot.conditioning` (angular rows scaled by the arm's
  :attr:`~planner.model.robot.Robot.characteristic_length`), against the default threshold of
  the robot's task (:func:`planner.motion.singularity.inverse_condition_threshold`).

How near a flagged configuration really is to a singularity is judged by a reference that
depends on neither measure: ``d = w / |grad w|`` with ``w`` the Yoshikawa manipulability of the
raw Jacobian, a first-order estimate of the joint-space distance [rad] to the singular set
(``w`` is zero there and grows about linearly with the distance away from it; a constant scaling
of the rows multiplies ``w`` by a constant, which cancels). The table shows the share flagged,
the median, 95th percentile and largest ``d`` of the flagged configurations (small: flagged only
near a singularity) and the share of configurations with ``d < 0.05 rad`` that are flagged
(recall near one). Prints a Markdown table and writes JSON and the table to benchmarks/results/.

    python benchmarks/bench_singularity.py [--configs 2000] [--seed 0] [--arms ur5 panda z1 ...]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from planner import load_robot
from planner.app.benchmark import run_record
from planner.model.catalog import BUNDLED_ROBOTS, EXAMPLE_ROBOTS, example_robot_data_dir
from planner.model.robot import Robot
from planner.motion.singularity import inverse_condition_threshold

RESULTS = Path(__file__).resolve().parent / "results"
OLD_THRESHOLD = 1.0 / 30.0
NEAR = 0.05  # [rad]


def raw_inverse_condition(robot: Robot, q: np.ndarray, task: str) -> np.ndarray:
    """The measure before issue 11: smallest over largest singular value of the raw Jacobian."""
    out = np.empty(len(q))
    for k, row in enumerate(q):
        jac = robot.jacobian(row)
        jac = jac[:3] if task == "position" else jac
        s = np.linalg.svd(jac, compute_uv=False)[: min(jac.shape)]
        out[k] = s[-1] / s[0]
    return out


def distance_to_singular(robot: Robot, q: np.ndarray, task: str, h: float = 1e-6) -> np.ndarray:
    """First-order joint-space distance to the singular set, ``w / |grad w|`` [rad]."""
    out = np.empty(len(q))
    for k, row in enumerate(q):
        w = float(robot.manipulability(row, task))
        grad = np.empty(robot.dof)
        for i in range(robot.dof):
            e = np.zeros(robot.dof)
            e[i] = h
            grad[i] = (float(robot.manipulability(row + e, task)) - float(robot.manipulability(row - e, task))) / (
                2 * h
            )
        norm = float(np.linalg.norm(grad))
        out[k] = w / norm if norm > 0 else (0.0 if w == 0 else np.inf)
    return out


def flagged_stats(flags: np.ndarray, d: np.ndarray) -> dict:
    near = d < NEAR
    return {
        "flagged": float(flags.mean()),
        "d_median": float(np.median(d[flags])) if flags.any() else None,
        "d_p95": float(np.quantile(d[flags], 0.95)) if flags.any() else None,
        "d_max": float(d[flags].max()) if flags.any() else None,
        "recall_near": float(flags[near].mean()) if near.any() else None,
    }


def run(arm: str, configs: int, seed: int) -> dict:
    robot = load_robot(arm)
    task = robot.resolve_task(None)
    # Keep a hair inside the limits: the central differences step both ways.
    q = robot.random_configurations(np.random.default_rng(seed), configs)
    q = np.clip(q, robot.lower + 1e-5, robot.upper - 1e-5)
    before = raw_inverse_condition(robot, q, task)
    after = robot.conditioning(q, task)[0]
    threshold = inverse_condition_threshold(None, task)
    d = distance_to_singular(robot, q, task)
    return {
        "arm": arm,
        "dof": robot.dof,
        "task": task,
        "characteristic_length": robot.characteristic_length,
        "near_share": float(np.mean(d < NEAR)),
        "before": {"threshold": OLD_THRESHOLD, **flagged_stats(before < OLD_THRESHOLD, d)},
        "after": {"threshold": threshold, **flagged_stats(after < threshold, d)},
    }


def _f(x: float | None, fmt: str) -> str:
    return "-" if x is None else format(x, fmt)


def table(rows: list[dict]) -> str:
    lines = [
        "| arm | task | L [m] | d < 0.05 rad | threshold before / after | flagged before | flagged after "
        "| flagged d median / p95 / max [rad] before | after | recall d < 0.05 before / after |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        b, a = r["before"], r["after"]
        lines.append(
            f"| {r['arm']} | {r['task']} | {r['characteristic_length']:.3f} | {r['near_share']:.1%} "
            f"| {b['threshold']:.4f} / {a['threshold']:.4f} | {b['flagged']:.1%} | {a['flagged']:.1%} "
            f"| {_f(b['d_median'], '.3f')} / {_f(b['d_p95'], '.3f')} / {_f(b['d_max'], '.3f')} "
            f"| {_f(a['d_median'], '.3f')} / {_f(a['d_p95'], '.3f')} / {_f(a['d_max'], '.3f')} "
            f"| {_f(b['recall_near'], '.2f')} / {_f(a['recall_near'], '.2f')} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configs", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    examples = list(EXAMPLE_ROBOTS) if example_robot_data_dir() is not None else []
    default_arms = [*BUNDLED_ROBOTS, *(a for a in ("ur5", "panda", "z1") if a in examples)]
    parser.add_argument("--arms", nargs="+", default=default_arms)
    args = parser.parse_args(argv)
    rows = [run(arm, args.configs, args.seed) for arm in args.arms]
    text = table(rows)
    print(text)
    RESULTS.mkdir(exist_ok=True)
    record = run_record("bench_singularity", ["pin", "numpy"])
    record.update({"configs": args.configs, "seed": args.seed, "near": NEAR, "arms": rows})
    (RESULTS / "bench_singularity.json").write_text(json.dumps(record, indent=2) + "\n")
    (RESULTS / "bench_singularity.md").write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
