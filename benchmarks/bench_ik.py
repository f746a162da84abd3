"""Benchmark: closed-form vs numerical (CasADi) inverse kinematics.

For every arm (the bundled seed arms and, when example-robot-data is installed, ur5, panda,
so101 and z1): N random configurations within the joint limits (``--seed``) give the targets,
their FK pose for the example-robot-data arms (a full 6-D pose, also for the 5-dof so101), a
position plus approach pitch for al5c and three_joint, a position for shelley and dh3. The
seeds / current configurations are another fixed draw (``--seed + 1``). Methods:

- ``analytic``: the closed form (:mod:`planner.ik.analytic`), where the arm has one;
- ``nlp``: :class:`planner.NlpIK` from the seed, random restarts within ``--time-budget``,
  without the closed-form branches (so it stands on its own);
- ``ipopt-1``: with ``--ipopt-baseline``, one plain bounded least-squares NLP solved by IPOPT
  from the seed, no restarts: the textbook baseline.

Success = position error < 1e-4 m and orientation error < 1e-3 rad by Pinocchio FK (computed
here, not taken from the solvers), and within the joint limits. Times are wall times of the
solve call, after a warm-up call (one-off setup: building, compiling or loading the compiled
solver, is reported separately). Cross-check: for arms with a closed form, the share of targets
where the NLP answer coincides with a closed-form branch, or both reach the target where the
arm is redundant (:func:`planner.ik.solve.compare`).

Goals (issue 4): 100 % solve rate on ur5, panda, so101, z1; median time per call <= 1 ms,
then < 0.3 ms. Prints a Markdown table, writes JSON to benchmarks/results/bench_ik.json.

    python benchmarks/bench_ik.py [--n 1000] [--seed 0] [--robots ur5 panda] [--ipopt-baseline]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from planner import available_robots, load_robot
from planner.app.benchmark import BUNDLED_KINDS, KINDS, ORIENTATION_TOL, POSITION_TOL, bench_robot, markdown, run_record
from planner.ik.numeric.solver import NlpIK

RESULTS = Path(__file__).resolve().parent / "results"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000, help="random targets per robot (default 1000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the target configurations (seeds: seed + 1)")
    parser.add_argument("--robots", nargs="*", default=None, help="robots (default: every available one)")
    parser.add_argument("--time-budget", type=float, default=0.05, help="NLP time budget per call [s]")
    parser.add_argument("--ipopt-baseline", action="store_true", help="add the single-IPOPT-solve baseline rows")
    parser.add_argument("--plot", type=Path, default=None, help="also write a PNG bar chart here (matplotlib)")
    parser.add_argument("--out", type=Path, default=RESULTS / "bench_ik.json", help="JSON output file")
    args = parser.parse_args(argv)
    if args.n < 1:
        parser.error("--n must be >= 1")
    names = args.robots or list(available_robots())
    skipped = [n for n in ("ur5", "panda", "so101", "z1") if n not in available_robots()]
    if skipped:
        print(f"example-robot-data not installed: skipping {', '.join(skipped)}")
    summaries = []
    for name in names:
        for kind in KINDS.get(name, ("pose",)):
            summaries += bench_robot(name, args.n, args.seed, args.time_budget, args.ipopt_baseline, kind)
    table = markdown(summaries)
    print(table)

    goal_arms = [s for s in summaries if s["method"] == "nlp" and s["robot"] in ("ur5", "panda", "so101", "z1")]
    overall = {}
    if goal_arms:
        overall = {
            "nlp_min_solve_rate_goal_arms": min(s["solve_rate"] for s in goal_arms),
            "nlp_max_median_ms_goal_arms": max(s["median_ms"] for s in goal_arms),
        }
        print()
        print(
            f"NLP on ur5/panda/so101/z1: lowest solve rate {100 * overall['nlp_min_solve_rate_goal_arms']:.2f} % "
            f"(goal 100 %), highest median {overall['nlp_max_median_ms_goal_arms']:.3f} ms (goals <= 1 ms, < 0.3 ms)"
        )
    probe = NlpIK(load_robot(names[0]))
    record = {
        **run_record("bench_ik", ("casadi", "pin", "numpy", "example-robot-data")),
        "settings": {
            "n": args.n,
            "seed": args.seed,
            "time_budget_s": args.time_budget,
            "success": f"position < {POSITION_TOL} m, orientation < {ORIENTATION_TOL} rad (Pinocchio FK), in limits",
            "nlp_compiled": probe.compiled(BUNDLED_KINDS.get(names[0], "pose")),
            "nlp_batch_size": probe.batch_size,
        },
        "summary": summaries,
        "overall": overall,
        "table": table,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record, indent=2, allow_nan=False) + "\n")
    print(f"\nwrote {args.out}")
    if args.plot is not None:
        from planner.app.plots import plot_ik_benchmark

        print(f"wrote {plot_ik_benchmark(args.plot, summaries)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
