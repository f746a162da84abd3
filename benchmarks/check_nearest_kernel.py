"""Check: solve_ik's answers by the compiled nearest kernel against the Python closed form's.

:meth:`YawPlanarIK.nearest <planner.ik.analytic.yaw_planar.solver.YawPlanarIK.nearest>` and
``Planar2IK.nearest`` answer ``solve_ik``'s closed-form calls by one compiled call
(:mod:`planner.ik.analytic.yaw_planar.single`, :mod:`planner.ik.analytic.planar2_single`) after
a few calls of a target kind. This script
runs ``planner.solve_ik`` on N generated targets per arm and kind twice, once with the kernel
switched off (``planner.ik.analytic.base.SINGLE_AFTER`` out of reach: the Python paths) and once with it on from
the first call, and compares every result: status, success, reason (it names the branch),
``attempts`` and ``attempt``, and ``q`` (the largest joint difference). Targets: half FK of a
random configuration within the limits, half that point moved by up to 2 cm (reachable or not);
pitch targets with the generating configuration's approach pitch (moved by up to 0.1 rad for the
moved ones), poses with its rotation; a random seed within the limits for half of them. Prints
a Markdown table; writes nothing.

    python benchmarks/check_nearest_kernel.py [--n 100000] [--robots al5c three_joint dh3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import planner.ik.analytic.base as analytic_base
from planner import Target, UnsupportedChainError, load_robot, solve_ik
from planner.geometry.target import approach_pitch
from planner.ik.analytic.planar2_single import Planar2Kernel
from planner.ik.analytic.yaw_planar.single import SingleKernel

KINDS = ("position", "pitch", "pose")


def targets(robot, kind: str, n: int, seed: int) -> list[tuple[Target, np.ndarray | None]]:
    """N (target, seed) pairs (see the module docstring)."""
    rng = np.random.default_rng(seed)
    qs = robot.random_configurations(rng, n)
    seeds = robot.random_configurations(rng, n)
    out = []
    for k in range(n):
        pose = robot.fk(qs[k])
        moved = k % 2 == 1
        position = pose[:3, 3] + (rng.uniform(-0.02, 0.02, 3) if moved else 0.0)
        if kind == "position":
            target = Target(position)
        elif kind == "pitch":
            target = Target(position, pitch=approach_pitch(robot, qs[k]) + (rng.uniform(-0.1, 0.1) if moved else 0.0))
        else:
            target = Target(position, rotation=pose[:3, :3])
        out.append((target, seeds[k] if k % 4 < 2 else None))
    return out


def run(robot, pairs, after: int) -> list[tuple]:
    analytic_base.SINGLE_AFTER = after
    rows = []
    for target, seed in pairs:
        r = solve_ik(robot, target, seed, method="analytic")
        rows.append((r.status, r.success, r.reason, r.attempts, r.attempt, r.q))
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100_000, help="targets per arm and kind")
    parser.add_argument("--robots", nargs="*", default=["al5c", "three_joint", "dh3", "shelley"])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    sure = [0, 0]
    for kernel_class in (SingleKernel, Planar2Kernel):

        def counted(self, original=kernel_class.__call__) -> None:
            original(self)
            sure[0] += 1
            sure[1] += self.outputs[0] != 0.0

        kernel_class.__call__ = counted
    print("| robot | kind | targets | answered by the kernel | status differs | reason differs | counts differ "
          "| q differs > 1e-12 | max joint difference [rad] | s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.robots:
        for kind in KINDS:
            start = time.perf_counter()
            pairs = targets(load_robot(name), kind, args.n, args.seed)
            try:
                solve_ik(load_robot(name), pairs[0][0], method="analytic")
            except UnsupportedChainError:
                continue  # no closed form of this kind
            python = run(load_robot(name), pairs, 10**12)  # a fresh robot: its own solvers
            sure[:] = [0, 0]
            kernel = run(load_robot(name), pairs, 1)
            status = reason = counts = far = 0
            worst = 0.0
            for a, b in zip(python, kernel):
                status += a[0] != b[0] or a[1] != b[1]
                reason += a[2] != b[2]
                counts += a[3:5] != b[3:5]
                d = float(np.max(np.abs(a[5] - b[5])))
                worst = max(worst, d)
                far += d > 1e-12
            print(
                f"| {name} | {kind} | {args.n} | {sure[1]} of {sure[0]} calls | {status} | {reason} | {counts} "
                f"| {far} | {worst:.2e} | {time.perf_counter() - start:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
