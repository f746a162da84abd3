"""Check: two source trees plan bench_collision's pairs bit for bit the same.

For ur5 and panda, bench_collision's start/goal pairs (its scene, seed 0, pairs both checkers
find free: ours and roboplan's when roboplan is installed) are planned with
:func:`planner.app.motion_plan.plan_motion` by each tree given (``--trees``, e.g. main's
checkout and a branch), in a subprocess per tree. Per plan a hash of the trajectory's
waypoints, times, via states, dwell and pieces, the plan's detours, unresolved segments,
routes, singularity report, collision verdict and JSON summary (a failed plan: its message).
Prints per arm how many plans agree and which do not; writes nothing.

    python benchmarks/check_same_plans.py --trees /path/to/main /path/to/branch [--paths 50]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve()


def worker(paths: int, seed: int) -> dict[str, list[str]]:
    """Hash every plan of the planner on ``sys.path``."""
    from planner import load_robot
    from planner.app.motion_plan import plan_motion
    from planner.app.plan_file import parse_motion_request
    from planner.collision import CollisionChecker, parse_scene
    from planner.exceptions import PlannerError
    from planner.motion.limits import JointLimits

    sys.path.insert(0, str(HERE.parent))
    from bench_collision import BUDGET, SCENE, Roboplan

    try:
        import roboplan.core  # noqa: F401
    except ImportError:
        have_roboplan = False
    else:
        have_roboplan = True
    out = {}
    for name in ("ur5", "panda"):
        robot = load_robot(name)
        checker = CollisionChecker(robot, parse_scene(SCENE))
        rp = Roboplan(name, robot, JointLimits.from_robot(robot), obstacles=True) if have_roboplan else None
        rng = np.random.default_rng(seed)
        pairs = []
        while len(pairs) < paths:
            qa, qb = robot.random_configurations(rng, 2)
            if checker.in_collision(qa) or checker.in_collision(qb):
                continue
            if rp is not None and (rp.in_collision(rp.q_full(qa)) or rp.in_collision(rp.q_full(qb))):
                continue
            pairs.append((qa, qb))
        hashes = []
        for i, (qa, qb) in enumerate(pairs):
            request = parse_motion_request(
                {
                    "waypoints": [qa.tolist(), qb.tolist()],
                    "scene": SCENE,
                    "avoidance": {"seed": seed + i, "time_budget": BUDGET},
                }
            )
            h = hashlib.sha256()
            try:
                plan = plan_motion(robot, request)
            except PlannerError as exc:
                h.update(f"failed: {exc}".encode())
                hashes.append(h.hexdigest()[:16])
                continue
            traj = plan.trajectory
            for arr in (
                traj.waypoints,
                traj.waypoint_times,
                traj.via_velocities,
                traj.via_accelerations,
                traj.dwell,
                traj.knots,
                traj.p,
                traj.v,
                traj.a,
                traj.j,
                plan.waypoint_times,
                plan.departure_times,
                plan.singularity.waypoint_inverse_condition,
            ):
                h.update(np.ascontiguousarray(arr).tobytes())
            detours = [(d.segment, d.q.tobytes(), d.inverse_condition, d.dip) for d in plan.detours]
            collision = plan.collision
            h.update(
                repr(
                    (
                        traj.duration,
                        traj.strategy,
                        plan.routes,
                        plan.unresolved,
                        detours,
                        plan.singularity.min_inverse_condition,
                        None if collision is None else (collision.clear, collision.checks, collision.closest.distance),
                    )
                ).encode()
            )
            h.update(json.dumps(plan.summary(), sort_keys=True, default=str).encode())
            hashes.append(h.hexdigest()[:16])
        out[name] = hashes
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trees", nargs=2, help="two source trees (PYTHONPATH) to compare")
    parser.add_argument("--paths", type=int, default=50, help="start/goal pairs per arm")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(json.dumps(worker(args.paths, args.seed)))
        return
    if not args.trees:
        parser.error("--trees is required")
    got = []
    for tree in args.trees:
        env = dict(os.environ, PYTHONPATH=tree)
        cmd = [sys.executable, str(HERE), "--worker", "--paths", str(args.paths), "--seed", str(args.seed)]
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
        got.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    for arm in got[0]:
        a, b = got[0][arm], got[1][arm]
        differ = [i for i, (x, y) in enumerate(zip(a, b)) if x != y]
        print(f"{arm}: {len(a) - len(differ)}/{len(a)} plans identical" + (f"; differ: {differ}" if differ else ""))


if __name__ == "__main__":
    main()
