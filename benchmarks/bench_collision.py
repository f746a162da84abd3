"""Benchmark: collision checks and collision-free plans against roboplan, in the same run.

For ur5 and panda (example-robot-data URDFs; roboplan reads the same URDF and that package's
SRDF, whose disabled pairs are its self-collision filter; ours samples its own) and one scene
for both: a table (a 1.6 x 1.6 x 0.05 m box whose top is 5 mm below the arm's base) and a box
(0.25 x 0.25 x 0.5 m at x = 0.45 m standing on the table).

1. **Checks per second**, on the same random configurations (fixed seed): ours
   :meth:`CollisionChecker.in_collision` and :meth:`CollisionChecker.clearance` (a distance,
   which roboplan has no call for), against roboplan's ``Scene.hasCollisions``; self only (no
   obstacles) and self + scene. roboplan runs twice: given exactly our body pairs (its
   ``setCollisions``: the same model and pair set) and with the arm's SRDF (what its users get;
   the pairs that differ are listed). CPU time, interleaved in blocks; the speed ratio is the
   median over blocks, on all configurations and again on those all checkers find free (where
   none stops at a first collision). The verdicts are compared: the shapes still differ (ours
   are the collision meshes' convex hulls, or slab hulls containing them in some pairs of the
   arm's own links, roboplan's the meshes' triangles).
2. **Plans**: random start/goal pairs within the joint limits that both checkers find
   collision-free (fixed seed). Ours: :func:`planner.app.motion_plan.plan_motion` with the
   scene (a straight move when it is clear, else RRT-Connect + shortcuts, then jerk-limited
   line timing along the route). roboplan: its RRT-Connect (5 s budget like ours, 10,000
   nodes), its ``PathShortcutter``, then its TOPP-RA in its default ``Hermite`` mode (rest at
   every waypoint of the path) and in ``Cubic`` mode (a spline through them). Same limits for
   all: v from the URDF, a = 2 v, j = 10 a (roboplan takes v and a; TOPP-RA ignores jerk).
   Planning time = wall time of the whole call, and beside it the process's CPU time (on a shared
   machine the wall time swings with the load; roboplan: RRT + shortcut + TOPP-RA at its
   default 10 ms output step). Each trajectory is then sampled at 1 kHz (roboplan's generated
   again with a 1 ms step; its velocities and accelerations as it reports them, jerk by
   differences) for the worst velocity, acceleration and jerk ratios to the limits, and
   checked for collisions at every sample by both checkers.

Goals (from the issue): checks per second at least roboplan's on the same model; 100 % success
wherever roboplan finds a path; planning time at most roboplan's median; duration within 10 %
of roboplan's. Prints a Markdown table and writes JSON and the table to benchmarks/results/.

    python benchmarks/bench_collision.py [--paths 50] [--arms ur5 panda] [--configs 2000] [--seed 0] [--phases]

``--phases`` also records, per plan of ours, the CPU time of its steps (path search, continuous
check, singularity measure and timing; the rest is IK-free bookkeeping, Ruckig and the request)
and prints their medians on the pairs both solved, straight and routed apart. Off by default:
the wrappers add a few calls to the time measured.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import planner.app.motion_plan as motion_plan
from planner import load_robot
from planner.app.benchmark import run_record
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
from planner.collision import CollisionChecker, parse_scene
from planner.exceptions import PlannerError
from planner.model.catalog import EXAMPLE_ROBOTS, example_robot_data_dir
from planner.motion.limits import JointLimits

RESULTS = Path(__file__).resolve().parent / "results"

#: The scene, in plan-file form (metres), for both planners.
SCENE = {
    "obstacles": [
        {"name": "table", "box": [1.6, 1.6, 0.05], "position": [0.0, 0.0, -0.03]},
        {"name": "box", "box": [0.25, 0.25, 0.5], "position": [0.45, 0.0, 0.25]},
    ]
}
#: Each arm's SRDF in example-robot-data, and roboplan's joint group for the arm (None: all joints).
SRDF = {"ur5": ("ur_description/srdf/ur5.srdf", None), "panda": ("panda_description/srdf/panda.srdf", "arm")}
BUDGET = 5.0  # seconds, both planners
RATE = 1000.0
#: plan_motion's steps timed with --phases: the functions planner.app.motion_plan calls, by step.
PHASES = {
    "path search": ("find_clear_path", "segment_is_clear", "segment_looks_clear"),
    "continuous check": ("check_trajectory", "check_segment"),
    "singularity measure and timing": (
        "plan_clear_of_singularities",
        "plan_trajectory_request",
        "measure_singularities",
        "smooth_lines",
    ),
}


@contextlib.contextmanager
def timed_phases(spent: dict):
    """Within it, CPU time [s] of each of :data:`PHASES`'s steps called by plan_motion is added to `spent`."""
    saved = {}

    def timed(phase: str, f):
        def call(*args, **kwargs):
            c0 = time.process_time()
            try:
                return f(*args, **kwargs)
            finally:
                spent[phase] = spent.get(phase, 0.0) + time.process_time() - c0

        return call

    for phase, names in PHASES.items():
        for name in names:
            saved[name] = getattr(motion_plan, name)
            setattr(motion_plan, name, timed(phase, saved[name]))
    try:
        yield spent
    finally:
        for name, f in saved.items():
            setattr(motion_plan, name, f)


class Roboplan:
    """roboplan's scene (same URDF, the arm's SRDF, the same limits and obstacles), RRT and TOPP-RA."""

    def __init__(self, name: str, robot, limits: JointLimits, obstacles: bool) -> None:
        import roboplan.core as rc
        import roboplan.rrt as rr
        import roboplan.toppra as rt

        self.rc, self.rt = rc, rt
        root = example_robot_data_dir()
        assert root is not None
        desc = rc.loadUrdfSceneDescription(str(root / EXAMPLE_ROBOTS[name].urdf), [str(root.parent.parent)])
        self.scene = rc.Scene(name, desc)
        srdf, group = SRDF[name]
        self.scene.importSrdf((root / srdf).read_text())
        self.group = group or ""
        names = self.scene.getJointNames()
        self.arm_joints = list(robot.joint_names)
        # The full configuration: the arm's joints, the others (fingers) at planner's locked values.
        self.index = np.array([names.index(j) for j in self.arm_joints])
        self.full = np.array([robot.locked_joints.get(j, 0.0) for j in names])
        with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as f:
            f.write("joint_limits:\n")
            for j, a, jerk in zip(self.arm_joints, limits.acceleration, limits.jerk):
                f.write(f"  {j}:\n    max_acceleration: [{float(a)!r}]\n    max_jerk: [{float(jerk)!r}]\n")
        self.scene.importJointLimitsFromConfig(rc.loadJointLimitsConfig(f.name))
        Path(f.name).unlink()
        v = self.scene.getVelocityLimitVectors(self.group)[1]
        a = self.scene.getAccelerationLimitVectors(self.group)[1]
        assert np.allclose(v, limits.velocity) and np.allclose(a, limits.acceleration), (v, a)
        if obstacles:
            for ob in SCENE["obstacles"]:
                tform = np.eye(4)
                tform[:3, 3] = ob["position"]
                color = np.array([0.5, 0.5, 0.5, 1.0])
                self.scene.addBoxGeometry(ob["name"], "universe", rc.Box(*ob["box"]), tform, color)
        self.scene.setJointPositions(self.full)
        options = rr.RRTOptions()
        options.group_name = self.group
        options.rrt_connect = True
        options.max_planning_time = BUDGET
        options.max_nodes = 10000
        options.max_connection_distance = 1.0
        options.collision_check_step_size = 0.05
        self.rrt = rr.RRT(self.scene, options)
        self.shortcutter = rc.PathShortcutter(self.scene, rc.PathShortcuttingOptions(group_name=self.group))
        self.toppra = rt.PathParameterizerTOPPRA(self.scene, self.group)

    def q_full(self, q: np.ndarray) -> np.ndarray:
        full = self.full.copy()
        full[self.index] = q
        return full

    def in_collision(self, q_full: np.ndarray) -> bool:
        return bool(self.scene.hasCollisions(q_full))

    def plan(self, qa: np.ndarray, qb: np.ndarray, seed: int) -> dict:
        """RRT-Connect + shortcut; then TOPP-RA per mode. Times and 1 ms trajectories."""
        rc, rt = self.rc, self.rt
        self.rrt.setRngSeed(seed)
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            path = self.rrt.plan(rc.JointConfiguration(self.arm_joints, qa), rc.JointConfiguration(self.arm_joints, qb))
        except RuntimeError as exc:  # it raises when it gives up
            return {"found": False, "path_time": time.perf_counter() - t0, "reason": str(exc)}
        if path is None:
            return {"found": False, "path_time": time.perf_counter() - t0, "reason": "no path"}
        path = self.shortcutter.shortcut(path)
        path_time, path_cpu = time.perf_counter() - t0, time.process_time() - c0
        points = np.array(path.positions)
        out: dict = {
            "found": True,
            "path_time": path_time,
            "path_points": len(points),
            "path_length": float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1))),
        }
        for mode in ("Hermite", "Cubic"):
            m = getattr(rt.SplineFittingMode, mode)
            t1, c1 = time.perf_counter(), time.process_time()
            traj = self.toppra.generate(path, rt.TOPPRAOptions(dt=0.01, mode=m))
            out[mode] = {
                "plan_time": path_time + time.perf_counter() - t1,
                "plan_cpu": path_cpu + time.process_time() - c1,
                "duration": float(traj.times[-1]),
            }
            fine = self.toppra.generate(path, rt.TOPPRAOptions(dt=1.0 / RATE, mode=m))
            out[mode]["samples"] = (
                np.array(fine.times),
                np.array(fine.positions),
                np.array(fine.velocities),
                np.array(fine.accelerations),
            )
        return out


def limit_ratios(t, q, qd, qdd, limits: JointLimits) -> dict:
    """Worst |v|, |a| over the limits at the samples, |jerk| by differences of qdd."""
    dt = np.diff(t)
    jerk = np.diff(qdd, axis=0) / dt[:, None] if len(t) > 1 else np.zeros((0, q.shape[1]))
    return {
        "velocity": float(np.max(np.abs(qd) / limits.velocity)),
        "acceleration": float(np.max(np.abs(qdd) / limits.acceleration)),
        "jerk": float(np.max(np.abs(jerk) / limits.jerk)) if len(jerk) else 0.0,
        "leaves_range": bool(np.any(q < limits.lower - 1e-9) or np.any(q > limits.upper + 1e-9)),
    }


def path_length(q: np.ndarray) -> float:
    """Length of a joint path sampled densely [rad, Euclidean in joint space]."""
    return float(np.sum(np.linalg.norm(np.diff(q, axis=0), axis=1)))


def collisions(q: np.ndarray, ours: CollisionChecker, theirs: Roboplan | None) -> dict:
    """Samples in collision by our checker and by roboplan's."""
    out = {"ours_hits": int(sum(ours.in_collision(x) for x in q))}
    if theirs is not None:
        out["roboplan_hits"] = int(sum(theirs.in_collision(theirs.q_full(x)) for x in q))
    return out


def rates(calls: dict, blocks: int = 20) -> dict:
    """Time each ``name: (fn, inputs)`` interleaved in `blocks` blocks (CPU time of this process).

    Returns:
        Per name: calls per second over all blocks, the time of each block [s] and the results.
    """
    times: dict = {k: [] for k in calls}
    results: dict = {k: [] for k in calls}
    for fn, inputs in calls.values():
        fn(inputs[0])  # warm-up
    n = len(next(iter(calls.values()))[1])
    for b in range(blocks):
        part = slice(b * n // blocks, (b + 1) * n // blocks)
        for name, (fn, inputs) in calls.items():
            t0 = time.process_time()
            out = [fn(x) for x in inputs[part]]
            times[name].append(time.process_time() - t0)
            results[name] += out
    return {k: (n / sum(times[k]), np.array(times[k]), results[k]) for k in calls}


def body_pairs(checker: CollisionChecker) -> set:
    """The (sorted) body-name pairs our checker checks."""
    return {tuple(sorted((checker.names[p.first], checker.names[p.second]))) for p in checker.geometry.collisionPairs}


def same_pairs(rp: Roboplan, checker: CollisionChecker) -> int:
    """Give roboplan's scene exactly the body pairs our checker checks; the number of its geometry pairs."""
    import pinocchio as pin

    full = pin.buildModelFromXML(checker.robot.urdf)
    bodies = [f.name for f in full.frames if f.type == pin.FrameType.BODY] + list(checker.scene.names)
    ids = {b: list(rp.scene.getCollisionGeometryIDs(b)) for b in bodies}
    bodies = [b for b in bodies if ids[b]]
    ours = sorted(body_pairs(checker))
    rp.scene.setCollisions([(a, b) for k, a in enumerate(bodies) for b in bodies[k + 1 :]], False)
    rp.scene.setCollisions(ours, True)
    return sum(len(ids[a]) * len(ids[b]) for a, b in ours)


def srdf_pairs(name: str, robot, obstacles: bool) -> tuple[int, set, dict]:
    """What roboplan checks with the arm's SRDF (its loading steps replayed with Pinocchio).

    Returns:
        The number of geometry pairs, the body-name pairs, and the SRDF's reason per disabled pair.
    """
    import xml.etree.ElementTree as ET

    import pinocchio as pin

    root = example_robot_data_dir()
    assert root is not None
    full = pin.buildModelFromXML(robot.urdf)
    geom = pin.buildGeomFromUrdfString(full, robot.urdf, pin.GeometryType.COLLISION, None, [str(root.parent.parent)])
    geom.addAllCollisionPairs()
    pin.removeCollisionPairs(full, geom, str(root / SRDF[name][0]))
    names = [full.frames[o.parentFrame].name for o in geom.geometryObjects]
    count = len(geom.collisionPairs)
    bodies = {tuple(sorted((names[p.first], names[p.second]))) for p in geom.collisionPairs}
    if obstacles:  # roboplan pairs each added obstacle with every geometry before it
        for ob in SCENE["obstacles"]:
            count += len(names)
            bodies |= {tuple(sorted((n, ob["name"]))) for n in names}
            names = [*names, ob["name"]]
    reasons = {
        tuple(sorted((e.get("link1"), e.get("link2")))): e.get("reason", "no reason given")
        for e in ET.parse(root / SRDF[name][0]).getroot().iter("disable_collisions")
    }
    return count, bodies, reasons


def bench_checks(name: str, robot, scene, limits, n: int, seed: int, have_roboplan: bool) -> dict:
    qs = robot.random_configurations(np.random.default_rng(seed), n)
    out: dict = {"configs": n}
    for kind, sc in (("self", None), ("scene", scene)):
        checker = CollisionChecker(robot, sc)
        out[f"{kind}_pairs"] = checker.pair_count
        calls: dict = {"in_collision": (checker.in_collision, qs), "clearance": (checker.clearance, qs)}
        if have_roboplan:
            srdf = Roboplan(name, robot, limits, obstacles=sc is not None)
            same = Roboplan(name, robot, limits, obstacles=sc is not None)
            out[f"roboplan_same_{kind}_pairs"] = same_pairs(same, checker)
            count, theirs, reasons = srdf_pairs(name, robot, sc is not None)
            ours = body_pairs(checker)
            out[f"roboplan_srdf_{kind}_pairs"] = count
            out[f"srdf_{kind}_only_ours"] = [
                f"{a}-{b} ({reasons.get((a, b), 'not in the SRDF')})" for a, b in sorted(ours - theirs)
            ]
            out[f"srdf_{kind}_only_roboplan"] = [f"{a}-{b}" for a, b in sorted(theirs - ours)]
            full = np.array([srdf.q_full(q) for q in qs])
            calls["roboplan_same"] = (same.in_collision, full)
            calls["roboplan_srdf"] = (srdf.in_collision, full)
        timed = rates(calls)
        hits = np.array(timed["in_collision"][2])
        out[f"ours_{kind}_in_collision_per_s"] = timed["in_collision"][0]
        out[f"ours_{kind}_clearance_per_s"] = timed["clearance"][0]
        out[f"ours_{kind}_colliding"] = int(hits.sum())
        out[f"ours_{kind}_clearance_agrees"] = bool(np.all(hits == [c.in_collision for c in timed["clearance"][2]]))
        for pairs in ("same", "srdf") if have_roboplan else ():
            rate, block_times, verdicts = timed[f"roboplan_{pairs}"]
            theirs = np.array(verdicts)
            out[f"roboplan_{pairs}_{kind}_per_s"] = rate
            # Speed ratio per block (the same configurations, back to back), then the median: robust
            # to other processes' load on a shared machine.
            out[f"ratio_{pairs}_{kind}"] = float(np.median(block_times / timed["in_collision"][1]))
            out[f"roboplan_{pairs}_{kind}_colliding"] = int(theirs.sum())
            out[f"{pairs}_{kind}_agreement"] = float(np.mean(hits == theirs))
            out[f"{pairs}_{kind}_ours_only"] = int(np.sum(hits & ~theirs))
            out[f"{pairs}_{kind}_roboplan_only"] = int(np.sum(theirs & ~hits))
        if have_roboplan:
            # Where a checker finds a collision it may stop at the first pair: time again on the
            # configurations all find free, where every checker tests every pair.
            free = ~hits & ~np.array(timed["roboplan_same"][2]) & ~np.array(timed["roboplan_srdf"][2])
            out[f"{kind}_free_configs"] = int(free.sum())
            again = rates(
                {k: (calls[k][0], calls[k][1][free]) for k in ("in_collision", "roboplan_same", "roboplan_srdf")}
            )
            for pairs in ("same", "srdf"):
                ratio = again[f"roboplan_{pairs}"][1] / again["in_collision"][1]
                out[f"ratio_free_{pairs}_{kind}"] = float(np.median(ratio))
    return out


def bench_plans(
    name: str, robot, limits, paths: int, seed: int, have_roboplan: bool, phases: bool = False
) -> list[dict]:
    checker = CollisionChecker(robot, parse_scene(SCENE))
    rp = Roboplan(name, robot, limits, obstacles=True) if have_roboplan else None
    rng = np.random.default_rng(seed)
    pairs, drawn = [], 0
    while len(pairs) < paths:
        qa, qb = robot.random_configurations(rng, 2)
        drawn += 1
        if checker.in_collision(qa) or checker.in_collision(qb):
            continue
        if rp is not None and (rp.in_collision(rp.q_full(qa)) or rp.in_collision(rp.q_full(qb))):
            continue
        pairs.append((qa, qb))
    # Warm-up (imports, CasADi/Ruckig first calls) on a pair outside the measured set.
    qa, qb = pairs[0]
    plan_motion(robot, parse_motion_request({"waypoints": [qa.tolist(), qb.tolist()], "scene": SCENE}))
    rows = []
    for i, (qa, qb) in enumerate(pairs):
        row: dict = {"start": qa.tolist(), "goal": qb.tolist(), "drawn": drawn}
        request = parse_motion_request(
            {
                "waypoints": [qa.tolist(), qb.tolist()],
                "scene": SCENE,
                "avoidance": {"seed": seed + i, "time_budget": BUDGET},
            }
        )
        spent: dict = {}
        timing = timed_phases(spent) if phases else contextlib.nullcontext()
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            with timing:
                plan = plan_motion(robot, request)
        except PlannerError as exc:
            row["ours"] = {"found": False, "plan_time": time.perf_counter() - t0, "reason": str(exc)}
        else:
            traj = plan.trajectory
            elapsed, cpu = time.perf_counter() - t0, time.process_time() - c0
            peaks = traj.peak_ratios(RATE)
            exact = traj.peak_ratios(None)
            t = np.append(np.arange(0.0, traj.duration, 1.0 / RATE), traj.duration)
            ours = {
                "found": True,
                "plan_time": elapsed,
                "plan_cpu": cpu,
                "duration": traj.duration,
                "routed": bool(plan.routes),
                "waypoints": len(traj.waypoints),
                "path_length": path_length(traj.sample(t).q),
                "reported_clear": bool(plan.collision is not None and plan.collision.clear),
                "velocity": max(peaks["velocity"], exact["velocity"]),
                "acceleration": max(peaks["acceleration"], exact["acceleration"]),
                "jerk": max(peaks["jerk"], exact["jerk"]),
                "leaves_range": max(peaks["position"], exact["position"]) > 1e-9,
            }
            if phases:
                ours["phases"] = {k: spent.get(k, 0.0) for k in PHASES}
            ours.update(collisions(traj.sample(t).q, checker, rp))
            row["ours"] = ours
        if rp is not None:
            res = rp.plan(qa, qb, seed + i)
            theirs: dict = {"found": res["found"], "path_time": res["path_time"], "reason": res.get("reason", "")}
            if res["found"]:
                theirs["path_points"] = res["path_points"]
                theirs["path_length"] = res["path_length"]
                for mode in ("Hermite", "Cubic"):
                    tt, q, qd, qdd = res[mode].pop("samples")
                    entry = dict(res[mode])
                    entry.update(limit_ratios(tt, q, qd, qdd, limits))
                    entry.update(collisions(q, checker, rp))
                    theirs[mode] = entry
            row["roboplan"] = theirs
        rows.append(row)
    return rows


def _p(values, q) -> float | None:
    return float(np.percentile(values, q)) if len(values) else None


def summarise(name: str, dof: int, checks: dict, rows: list[dict]) -> dict:
    ok = [r for r in rows if r["ours"]["found"]]
    s: dict = {"robot": name, "dof": dof, "paths": len(rows), "checks": checks}
    s["ours"] = {
        "success": len(ok) / len(rows),
        "routed": sum(r["ours"].get("routed", False) for r in ok),
        "plan_ms_median": _p([r["ours"]["plan_time"] * 1e3 for r in rows], 50),
        "plan_ms_p95": _p([r["ours"]["plan_time"] * 1e3 for r in rows], 95),
        "duration_median": _p([r["ours"]["duration"] for r in ok], 50),
        "max_velocity_ratio": max((r["ours"]["velocity"] for r in ok), default=None),
        "max_acceleration_ratio": max((r["ours"]["acceleration"] for r in ok), default=None),
        "max_jerk_ratio": max((r["ours"]["jerk"] for r in ok), default=None),
        "leaves_range": sum(r["ours"]["leaves_range"] for r in ok),
        "colliding_ours_check": sum(r["ours"]["ours_hits"] > 0 for r in ok),
        "colliding_roboplan_check": sum(r["ours"].get("roboplan_hits", 0) > 0 for r in ok),
        "failures": [r["ours"]["reason"] for r in rows if not r["ours"]["found"]],
    }
    if rows and "roboplan" in rows[0]:
        found = [r for r in rows if r["roboplan"]["found"]]
        s["roboplan_success"] = len(found) / len(rows)
        s["ours_success_where_roboplan_found"] = sum(r["ours"]["found"] for r in found) / len(found) if found else None
        solved = [r for r in found if r["ours"]["found"]]
        routed = [r for r in solved if r["ours"]["routed"]]
        s["solved_by_both"] = {
            "count": len(solved),
            "routed": len(routed),
            "ours_plan_ms_median": _p([r["ours"]["plan_time"] * 1e3 for r in solved], 50),
            "roboplan_plan_ms_median": _p([r["roboplan"]["Hermite"]["plan_time"] * 1e3 for r in solved], 50),
            "ours_plan_cpu_ms_median": _p([r["ours"]["plan_cpu"] * 1e3 for r in solved], 50),
            "roboplan_plan_cpu_ms_median": _p([r["roboplan"]["Hermite"]["plan_cpu"] * 1e3 for r in solved], 50),
            "plan_cpu_ratio_median": _p(
                [r["ours"]["plan_cpu"] / r["roboplan"]["Hermite"]["plan_cpu"] for r in solved], 50
            ),
            "path_length_ratio_median": _p(
                [r["ours"]["path_length"] / r["roboplan"]["path_length"] for r in solved], 50
            ),
            "routed_path_length_ratio_median": _p(
                [r["ours"]["path_length"] / r["roboplan"]["path_length"] for r in routed], 50
            ),
            "routed_waypoints_median": _p([r["ours"]["waypoints"] for r in routed], 50),
            "routed_plan_cpu_ratio_median": _p(
                [r["ours"]["plan_cpu"] / r["roboplan"]["Hermite"]["plan_cpu"] for r in routed], 50
            ),
            "straight_plan_cpu_ratio_median": _p(
                [
                    r["ours"]["plan_cpu"] / r["roboplan"]["Hermite"]["plan_cpu"]
                    for r in solved
                    if not r["ours"]["routed"]
                ],
                50,
            ),
            "routed_roboplan_points_median": _p([r["roboplan"]["path_points"] for r in routed], 50),
        }
        if solved and "phases" in solved[0]["ours"]:
            s["phases_ms_median"] = {
                kind: {
                    "plans": len(group),
                    "total": _p([r["ours"]["plan_cpu"] * 1e3 for r in group], 50),
                    **{k: _p([r["ours"]["phases"][k] * 1e3 for r in group], 50) for k in PHASES},
                }
                for kind, group in (
                    ("straight", [r for r in solved if not r["ours"]["routed"]]),
                    ("routed", routed),
                )
                if group
            }
        for mode in ("Hermite", "Cubic"):
            both = [r for r in found if r["ours"]["found"]]
            times = [r["roboplan"][mode]["plan_time"] * 1e3 if r["roboplan"]["found"] else None for r in rows]
            # A failed search counts with the time it took.
            times = [t if t is not None else r["roboplan"]["path_time"] * 1e3 for t, r in zip(times, rows)]
            m = [r["roboplan"][mode] for r in found]
            s[f"roboplan_{mode}"] = {
                "plan_ms_median": _p(times, 50),
                "plan_ms_p95": _p(times, 95),
                "duration_median": _p([e["duration"] for e in m], 50),
                "max_velocity_ratio": max((e["velocity"] for e in m), default=None),
                "max_acceleration_ratio": max((e["acceleration"] for e in m), default=None),
                "max_jerk_ratio": max((e["jerk"] for e in m), default=None),
                "leaves_range": sum(e["leaves_range"] for e in m),
                "colliding_ours_check": sum(e["ours_hits"] > 0 for e in m),
                "colliding_roboplan_check": sum(e["roboplan_hits"] > 0 for e in m),
                "median_ratio_ours_to_it": _p(
                    [r["ours"]["duration"] / r["roboplan"][mode]["duration"] for r in both], 50
                ),
                "median_ratio_routed": _p(
                    [r["ours"]["duration"] / r["roboplan"][mode]["duration"] for r in both if r["ours"]["routed"]], 50
                ),
                "both_solved": len(both),
            }
    return s


def _f(x, fmt: str = ".3f") -> str:
    return "n/a" if x is None else format(x, fmt)


def _k(x) -> str:
    return "n/a" if x is None else f"{x / 1000:.1f} k"


def markdown(summaries: list[dict]) -> str:
    lines = [
        "Collision checks per second (the same random configurations; CPU time, interleaved in 20 blocks; "
        "ours / roboplan: median over the blocks of the speed ratio; in brackets on the configurations "
        "that all find free, where no checker stops early). "
        "roboplan's Scene is given exactly our pair set (same pairs) and, beside, the arm's SRDF "
        "(its disabled pairs: what a roboplan user gets). Agreement: same verdict; ours only / roboplan "
        "only: configurations only that checker finds in collision:",
        "",
        "| arm | checks | pairs ours / roboplan SRDF | ours in_collision | ours clearance (distance) "
        "| roboplan hasCollisions, same pairs | ours / roboplan | agreement, same pairs (ours only / roboplan only) "
        "| roboplan hasCollisions, SRDF pairs | ours / roboplan SRDF "
        "| agreement, SRDF pairs (ours only / roboplan only) |",
        "|" + "---|" * 11,
    ]
    for s in summaries:
        c = s["checks"]
        for kind, label in (("self", "self"), ("scene", "self + table + box")):
            ours = c[f"ours_{kind}_in_collision_per_s"]
            row = [s["robot"], label, f"{c[f'{kind}_pairs']} / {c.get(f'roboplan_srdf_{kind}_pairs', 'n/a')}"]
            row += [_k(ours), _k(c[f"ours_{kind}_clearance_per_s"])]
            for pairs in ("same", "srdf"):
                row += [
                    _k(c.get(f"roboplan_{pairs}_{kind}_per_s")),
                    f"{_f(c.get(f'ratio_{pairs}_{kind}'), '.2f')} ({_f(c.get(f'ratio_free_{pairs}_{kind}'), '.2f')})",
                ]
                if f"{pairs}_{kind}_agreement" in c:
                    row.append(
                        f"{100 * c[f'{pairs}_{kind}_agreement']:.1f} % ({c[f'{pairs}_{kind}_ours_only']} / "
                        f"{c[f'{pairs}_{kind}_roboplan_only']})"
                    )
                else:
                    row.append("n/a")
            lines.append("| " + " | ".join(row) + " |")
    lines += [
        "",
        "Same pairs, different shapes: ours checks each URDF collision mesh as its convex hull (it "
        "contains the mesh), or, between links whose hulls are a poor stand-in (ur5's base, upper arm "
        "and forearm against some links), as a few slab hulls that together contain it; roboplan checks "
        "the mesh's triangles, so a configuration only ours finds in "
        "collision is one where the hulls (or slab hulls) touch and the meshes do not. With the SRDF the pair sets "
        "differ too (body pairs; the SRDF's reason for disabling in brackets):",
    ]
    for s in summaries:
        c = s["checks"]
        for kind in ("self", "scene"):
            if f"srdf_{kind}_only_ours" in c:
                lines.append(
                    f"- {s['robot']} {kind}: only ours checks {', '.join(c[f'srdf_{kind}_only_ours']) or 'none'}; "
                    f"only roboplan checks {', '.join(c[f'srdf_{kind}_only_roboplan']) or 'none'}"
                )
    lines += [
        "",
        "Plans on the table-and-box scene (random collision-free start/goal pairs; limit ratios: worst "
        "sampled |v|, |a|, |j| / limit at 1 kHz; colliding: trajectories with a sample in collision "
        "by our check / roboplan's):",
        "",
        "| arm | method | success | plan ms median (p95) | median duration s | median duration ours / it "
        "| worst v, a, j / limit | colliding |",
        "|" + "---|" * 8,
    ]
    for s in summaries:
        o = s["ours"]
        lines.append(
            f"| {s['robot']} | ours (plan_motion; {o['routed']} routed around the box) | {100 * o['success']:.0f} % | "
            f"{_f(o['plan_ms_median'], '.1f')} ({_f(o['plan_ms_p95'], '.1f')}) | {_f(o['duration_median'])} | | "
            f"{_f(o['max_velocity_ratio'], '.4f')}, {_f(o['max_acceleration_ratio'], '.4f')}, "
            f"{_f(o['max_jerk_ratio'], '.4f')} | {o['colliding_ours_check']} / {o['colliding_roboplan_check']} |"
        )
        for mode, label in (("Hermite", "default: rest at waypoints"), ("Cubic", "cubic spline through")):
            e = s.get(f"roboplan_{mode}")
            if e is None:
                continue
            lines.append(
                f"| {s['robot']} | roboplan RRT-Connect + TOPP-RA ({label}) | {100 * s['roboplan_success']:.0f} % | "
                f"{_f(e['plan_ms_median'], '.1f')} ({_f(e['plan_ms_p95'], '.1f')}) | {_f(e['duration_median'])} | "
                f"{_f(e['median_ratio_ours_to_it'])} | {_f(e['max_velocity_ratio'], '.4f')}, "
                f"{_f(e['max_acceleration_ratio'], '.4f')}, {_f(e['max_jerk_ratio'], '.1f')} | "
                f"{e['colliding_ours_check']} / {e['colliding_roboplan_check']} |"
            )
    return "\n".join(lines)


def goals(summaries: list[dict]) -> list[str]:
    out = []
    for s in summaries:
        c, o = s["checks"], s["ours"]
        if "roboplan_same_self_per_s" not in c:
            continue
        for kind in ("self", "scene"):
            out.append(
                f"{s['robot']}: {kind} checks/s ours / roboplan = {c[f'ratio_same_{kind}']:.2f} on the same pairs "
                f"({c[f'ratio_free_same_{kind}']:.2f} on free configurations) (goal >= 1); "
                f"{c[f'ratio_srdf_{kind}']:.2f} ({c[f'ratio_free_srdf_{kind}']:.2f}) against roboplan on its "
                "SRDF's pairs"
            )
        out.append(
            f"{s['robot']}: success where roboplan found a path: "
            f"{_f(100 * (s['ours_success_where_roboplan_found'] or 0), '.0f')} % (goal 100 %)"
        )
        b = s["solved_by_both"]
        ours_ms, their_ms = _f(b["ours_plan_ms_median"], ".1f"), _f(b["roboplan_plan_ms_median"], ".1f")
        out.append(
            f"{s['robot']}: on the {b['count']} pairs both solved: median plan time ours {ours_ms} ms vs roboplan "
            f"{their_ms} ms (CPU time: {_f(b['ours_plan_cpu_ms_median'], '.1f')} ms vs "
            f"{_f(b['roboplan_plan_cpu_ms_median'], '.1f')} ms, median per-pair ratio "
            f"{_f(b['plan_cpu_ratio_median'], '.2f')}); joint path length ours / roboplan median "
            f"{_f(b['path_length_ratio_median'])}; on the "
            f"{b['routed']} we routed: path length ratio {_f(b['routed_path_length_ratio_median'])}, duration ratio "
            f"(Hermite) {_f(s['roboplan_Hermite']['median_ratio_routed'])}, median trajectory waypoints ours "
            f"{_f(b['routed_waypoints_median'], '.0f')} vs roboplan path points "
            f"{_f(b['routed_roboplan_points_median'], '.0f')}; median per-pair CPU ratio straight "
            f"{_f(b['straight_plan_cpu_ratio_median'], '.2f')}, routed {_f(b['routed_plan_cpu_ratio_median'], '.2f')}"
        )
        for kind, m in s.get("phases_ms_median", {}).items():
            steps = ", ".join(f"{k} {_f(m[k], '.1f')}" for k in PHASES)
            out.append(
                f"{s['robot']}: ours, {kind} ({m['plans']} plans both solved), CPU ms median: whole plan "
                f"{_f(m['total'], '.1f')}; {steps}"
            )
        for mode in ("Hermite", "Cubic"):
            e = s[f"roboplan_{mode}"]
            out.append(
                f"{s['robot']}: median plan time ours {o['plan_ms_median']:.1f} ms vs roboplan ({mode}) "
                f"{e['plan_ms_median']:.1f} ms (goal <=); median duration ours / roboplan ({mode}) "
                f"{_f(e['median_ratio_ours_to_it'])} (goal <= 1.10)"
            )
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=50, help="random start/goal pairs per arm")
    parser.add_argument("--arms", nargs="*", default=["ur5", "panda"], help="arms (default: ur5 panda)")
    parser.add_argument("--configs", type=int, default=2000, help="random configurations for the checks/s")
    parser.add_argument("--seed", type=int, default=0, help="seed of the configurations and pairs")
    parser.add_argument("--phases", action="store_true", help="also time the steps of our plans (CPU)")
    args = parser.parse_args(argv)
    if example_robot_data_dir() is None:
        print("example-robot-data is not installed (pip install 'servo-arm-planner[bench]'): nothing to do")
        return 0
    try:
        import roboplan.core  # noqa: F401
        import roboplan.rrt  # noqa: F401
        import roboplan.toppra  # noqa: F401

        have_roboplan = True
    except ImportError as exc:
        have_roboplan = False
        print(f"roboplan is not importable ({exc}; pip install 'servo-arm-planner[bench]'): its columns are skipped")
    summaries, raw = [], {}
    for name in args.arms:
        if name not in SRDF:
            print(f"{name}: no SRDF known for roboplan; supported arms: {', '.join(SRDF)}")
            continue
        robot = load_robot(name)
        limits = JointLimits.from_robot(robot)  # v from the URDF, a = 2 v, j = 10 a
        t0 = time.perf_counter()
        checks = bench_checks(name, robot, parse_scene(SCENE), limits, args.configs, args.seed, have_roboplan)
        rows = bench_plans(name, robot, limits, args.paths, args.seed, have_roboplan, args.phases)
        print(f"{name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
        summaries.append(summarise(name, robot.dof, checks, rows))
        raw[name] = rows
    table = markdown(summaries)
    print(table)
    print()
    lines = goals(summaries)
    for line in lines:
        print(line)
    record = {
        **run_record("bench_collision", ("pin", "coal", "ruckig", "numpy", "example-robot-data", "roboplan")),
        "settings": {
            "paths": args.paths,
            "arms": args.arms,
            "configs": args.configs,
            "seed": args.seed,
            "phases": args.phases,
            "scene": SCENE,
            "limits": "v = URDF, a = 2 v, j = 10 a",
            "budget_s": BUDGET,
            "roboplan": "RRT-Connect (max_nodes 10000, max_connection_distance 1.0, collision_check_step_size "
            "0.05), PathShortcutter defaults, TOPP-RA dt 0.01 (timed) and 0.001 (checked)",
            "sample_rate": RATE,
        },
        "summary": summaries,
        "goals": lines,
        "table": table,
        "rows": raw,
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = RESULTS / "bench_collision.json"
    out.write_text(json.dumps(record, indent=1) + "\n")
    (RESULTS / "bench_collision.md").write_text(table + "\n\n" + "\n".join(lines) + "\n")
    print(f"\nwrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
