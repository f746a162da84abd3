"""Benchmark: multi-waypoint trajectories against stop-and-go Ruckig and TOPPRA.

For every arm (the bundled seed arms, and the example-robot-data arms when installed), random
paths of 5 waypoints within the joint limits (fixed seed) are planned with limits
v = the URDF's speed, a = 2 v, j = 10 a:

- ``planner``: :func:`planner.plan_trajectory` (Ruckig segments, chosen via states), which
  honours v, a, j and the position range at every instant;
- ``stop``: the same Ruckig segments resting at every waypoint;
- ``toppra chord``: TOPPRA's time-optimal parametrisation of a clamped cubic spline through
  the same waypoints with chord-length knots (cumulative joint-space distance), what a careful
  user configures: the reference. ``toppra``: the same through TOPPRA's defaults (uniform
  path parameter, ``not-a-knot`` spline), kept as a column. Both take the same v and a limits;
  they ignore jerk, and the spline can leave the joint range: both are counted.
- ``raw ruckig``: the stop-and-go segments computed by Ruckig directly (one
  ``Ruckig.calculate`` per segment, rest to rest), the floor for ``stop``'s planning time.

With ``--optimum-every K``, every K-th path is also solved as one nonlinear program
(CasADi/IPOPT, direct transcription: per segment a free duration and ``--nodes`` intervals of
constant jerk per joint, v, a, j and position limits at the interval ends, rest to rest),
started from the planner's trajectory: an estimate of the true jerk-limited time optimum
through the same waypoints, i.e. of what any planner could reach. The "optimum" column is the
shorter of that and the planner's own duration (the fixed intervals can make the program a
little slower than a near-optimal plan). The same program without the jerk limit and the
position range (a path free to leave the spline TOPPRA follows) shows what a jerk- and
range-free optimum would reach. Both are references only (about a second per path).

Goals (from the issues): median plan time <= 1.5 ms for 5 waypoints on a 6-dof arm;
``strategy="stop"`` planned in <= 2 x the time raw Ruckig takes for the same segments (both
timed on the same path, one after the other, taking turns at going first); median duration
within 0.5 % of the NLP optimum estimate (the "optimum gap": duration / optimum - 1, median
over the paths solved as an NLP).
The duration figures are medians over paths of per-path ratios (duration / the reference's
duration); the ratio of the median durations is shown as well. Prints a Markdown table and
writes JSON and Markdown to benchmarks/results/. Times are the CPU time of the planning
thread (``time.thread_time``; ``--clock wall`` for wall time): the machine is shared, and wall
time counts the time other processes hold the CPU, process CPU time the spinning of the BLAS
threads TOPPRA leaves behind.

    python benchmarks/bench_trajectory.py [--paths 100] [--seed 0] [--optimum-every K] [--clock cpu|wall]
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np

from planner import available_robots, load_robot
from planner.app.benchmark import run_record
from planner.model.catalog import BUNDLED_ROBOTS
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory
from planner.motion.trajectory import LIMIT_TOLERANCE

RESULTS = Path(__file__).resolve().parent / "results"
#: The clock of every timing: the calling thread's CPU time by default (neither other processes
#: on a shared machine nor idle-spinning BLAS threads inflate it), wall time with ``--clock wall``.
CLOCKS = {"cpu": time.thread_time, "wall": time.perf_counter}
_clock = [CLOCKS["cpu"]]


def clock() -> float:
    """The selected clock [s]."""
    return _clock[0]()


def toppra_plan(q: np.ndarray, limits: JointLimits, *, chord: bool = False):
    """TOPPRA through a cubic spline of the waypoints; returns (trajectory or None, wall time).

    With `chord`, the spline is clamped (zero end slopes) with knots at the cumulative joint-space
    distance; else TOPPRA's defaults (uniform knots, not-a-knot).
    """
    import toppra
    import toppra.algorithm
    import toppra.constraint

    t0 = clock()
    if chord:
        knots = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))])
        path = toppra.SplineInterpolator(knots / knots[-1], q, bc_type="clamped")
    else:
        path = toppra.SplineInterpolator(np.linspace(0.0, 1.0, len(q)), q)
    vel = toppra.constraint.JointVelocityConstraint(np.column_stack([-limits.velocity, limits.velocity]))
    acc = toppra.constraint.JointAccelerationConstraint(np.column_stack([-limits.acceleration, limits.acceleration]))
    instance = toppra.algorithm.TOPPRA([vel, acc], path, parametrizer="ParametrizeConstAccel")
    traj = instance.compute_trajectory()
    return traj, clock() - t0


def raw_ruckig_stop(q: np.ndarray, limits: JointLimits) -> tuple[float, float]:
    """Rest-to-rest Ruckig segments through the waypoints: (total duration, wall time)."""
    from ruckig import InputParameter, Result, Ruckig, Trajectory

    t0 = clock()
    dof = q.shape[1]
    otg, inp, traj = Ruckig(dof), InputParameter(dof), Trajectory(dof)
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = (
        limits.velocity.tolist(),
        limits.acceleration.tolist(),
        limits.jerk.tolist(),
    )
    total = 0.0
    for a, b in zip(q, q[1:]):
        inp.current_position, inp.target_position = a.tolist(), b.tolist()
        if otg.calculate(inp, traj) not in (Result.Working, Result.Finished):  # pragma: no cover
            return float("nan"), clock() - t0
        total += traj.duration
    return total, clock() - t0


def toppra_checks(traj, limits: JointLimits, rate: float = 1000.0) -> dict:
    """Sampled range excursion and peak ratios of a TOPPRA trajectory (jerk by differences)."""
    t = np.arange(0.0, traj.duration, 1.0 / rate)
    q = traj(t)
    qd = traj(t, 1)
    qdd = traj(t, 2)
    jerk = np.diff(qdd, axis=0) * rate
    return {
        "leaves_range": bool(np.any(q < limits.lower - 1e-9) or np.any(q > limits.upper + 1e-9)),
        "velocity": float(np.max(np.abs(qd) / limits.velocity)),
        "acceleration": float(np.max(np.abs(qdd) / limits.acceleration)),
        "jerk": float(np.max(np.abs(jerk) / limits.jerk)) if len(jerk) else 0.0,
    }


def optimum_reference(
    q: np.ndarray, limits: JointLimits, init, *, jerk: bool = True, position: bool = True, nodes: int = 24
) -> float | None:
    """Shortest duration through waypoints q by direct transcription (IPOPT), or None if it fails.

    Per segment k a duration T_k and `nodes` intervals of constant jerk per joint; the state
    (q, qd, qdd) is integrated exactly, and |qd| <= v, |qdd| <= a (and the position range) are
    imposed at the interval ends, |jerk| <= j on the intervals. Rest at both ends, continuous
    velocity and acceleration at the waypoints. Started from `init` (a JointTrajectory).
    """
    import casadi as ca

    n, dof = q.shape
    opti = ca.Opti()
    T = opti.variable(n - 1)
    v_max = np.tile(limits.velocity, (nodes + 1, 1)).T
    a_max = np.tile(limits.acceleration, (nodes + 1, 1)).T
    j_max = np.tile(limits.jerk, (nodes, 1)).T if jerk else None
    lower = np.tile(np.where(np.isfinite(limits.lower), limits.lower, -1e9), (nodes + 1, 1)).T
    upper = np.tile(np.where(np.isfinite(limits.upper), limits.upper, 1e9), (nodes + 1, 1)).T
    states = []
    for k in range(n - 1):
        x = opti.variable(3 * dof, nodes + 1)  # rows: q, qd, qdd
        u = opti.variable(dof, nodes)
        h = T[k] / nodes
        qq, vv, aa = x[:dof, :-1], x[dof : 2 * dof, :-1], x[2 * dof :, :-1]
        opti.subject_to(x[:dof, 1:] == qq + h * vv + h**2 / 2 * aa + h**3 / 6 * u)
        opti.subject_to(x[dof : 2 * dof, 1:] == vv + h * aa + h**2 / 2 * u)
        opti.subject_to(x[2 * dof :, 1:] == aa + h * u)
        opti.subject_to(x[:dof, 0] == q[k])
        opti.subject_to(x[:dof, -1] == q[k + 1])
        opti.subject_to(opti.bounded(-v_max, x[dof : 2 * dof, :], v_max))
        opti.subject_to(opti.bounded(-a_max, x[2 * dof :, :], a_max))
        if jerk:
            opti.subject_to(opti.bounded(-j_max, u, j_max))
        if position:
            opti.subject_to(opti.bounded(lower, x[:dof, :], upper))
        opti.subject_to(T[k] >= 1e-3)
        if k > 0:
            opti.subject_to(x[dof:, 0] == states[-1][0][dof:, -1])
        states.append((x, u))
        t0, t1 = init.waypoint_times[k], init.waypoint_times[k + 1]
        s = init.sample(np.linspace(t0, t1, nodes + 1))
        opti.set_initial(T[k], max(t1 - t0, 1e-3))
        opti.set_initial(x, np.vstack([s.q.T, s.qd.T, s.qdd.T]))
        opti.set_initial(u, np.diff(s.qdd, axis=0).T / max((t1 - t0) / nodes, 1e-9))
    opti.subject_to(states[0][0][dof:, 0] == 0)
    opti.subject_to(states[-1][0][dof:, -1] == 0)
    opti.minimize(ca.sum1(T))
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "max_iter": 3000, "tol": 1e-8, "sb": "yes"})
    try:
        sol = opti.solve()
    except RuntimeError:
        return None
    return float(np.sum(sol.value(T)))


def bench_robot(
    name: str, paths: int, rng: np.random.Generator, have_toppra: bool, optimum_every: int = 0, nodes: int = 24
) -> dict:
    robot = load_robot(name)
    limits = JointLimits.from_robot(robot)  # v from the URDF, a = 2 v, j = 10 a
    q0 = robot.random_configurations(rng, 5)
    plan_trajectory(q0, limits)  # warm-up
    rows = []
    for index in range(paths):
        q = robot.random_configurations(rng, 5)
        t0 = clock()
        ours = plan_trajectory(q, limits)
        plan_time = clock() - t0
        # Whichever of the two runs first finds the caches cold after the plan above: take turns.
        if index % 2:
            raw_duration, raw_time = raw_ruckig_stop(q, limits)
        t0 = clock()
        stop = plan_trajectory(q, limits, strategy="stop")
        stop_time = clock() - t0
        if not index % 2:
            raw_duration, raw_time = raw_ruckig_stop(q, limits)
        peaks = ours.peak_ratios(1000.0)
        exact = ours.peak_ratios(None)
        row = {
            "duration": ours.duration,
            "stop_duration": stop.duration,
            "plan_time": plan_time,
            "stop_time": stop_time,
            "raw_ruckig_time": raw_time,
            "raw_ruckig_duration": raw_duration,
            "velocity": max(peaks["velocity"], exact["velocity"]),
            "acceleration": max(peaks["acceleration"], exact["acceleration"]),
            "jerk": max(peaks["jerk"], exact["jerk"]),
            "position_excess": max(peaks["position"], exact["position"]),
            "passes_waypoints": bool(np.max(np.abs(ours.sample(ours.waypoint_times).q - q)) <= 1e-12),
        }
        if have_toppra:
            traj, toppra_time = toppra_plan(q, limits)
            row["toppra_time"] = toppra_time
            if traj is None:
                row["toppra_duration"] = None
            else:
                row["toppra_duration"] = float(traj.duration)
                row.update({f"toppra_{k}": v for k, v in toppra_checks(traj, limits).items()})
            traj, chord_time = toppra_plan(q, limits, chord=True)
            row["chord_time"] = chord_time
            if traj is None:
                row["chord_duration"] = None
            else:
                row["chord_duration"] = float(traj.duration)
                row.update({f"chord_{k}": v for k, v in toppra_checks(traj, limits).items()})
        if optimum_every and index % optimum_every == 0:
            row["optimum_duration"] = optimum_reference(q, limits, ours, nodes=nodes)
            row["relaxed_optimum_duration"] = optimum_reference(
                q, limits, ours, jerk=False, position=False, nodes=nodes
            )
        rows.append(row)
    return {
        "robot": name,
        "dof": robot.dof,
        "source": "bundled" if name in BUNDLED_ROBOTS else "example-robot-data",
        "rows": rows,
    }


def summarise(result: dict) -> dict:
    rows = result["rows"]
    dur = np.array([r["duration"] for r in rows])
    stop = np.array([r["stop_duration"] for r in rows])
    times = np.array([r["plan_time"] for r in rows]) * 1e3
    out = {
        "robot": result["robot"],
        "dof": result["dof"],
        "source": result["source"],
        "paths": len(rows),
        "median_duration": float(np.median(dur)),
        "median_ratio_to_stop": float(np.median(dur / stop)),
        "plan_ms_mean": float(np.mean(times)),
        "plan_ms_median": float(np.median(times)),
        "plan_ms_worst": float(np.max(times)),
        "max_velocity_ratio": max(r["velocity"] for r in rows),
        "max_acceleration_ratio": max(r["acceleration"] for r in rows),
        "max_jerk_ratio": max(r["jerk"] for r in rows),
        "max_position_excess": max(r["position_excess"] for r in rows),
        "all_pass_waypoints": all(r["passes_waypoints"] for r in rows),
        "stop_ms_median": float(np.median([r["stop_time"] for r in rows]) * 1e3),
        "raw_ruckig_ms_median": float(np.median([r["raw_ruckig_time"] for r in rows]) * 1e3),
        "median_stop_time_ratio_to_raw_ruckig": float(np.median([r["stop_time"] / r["raw_ruckig_time"] for r in rows])),
        "stop_matches_raw_ruckig": bool(
            all(abs(r["stop_duration"] - r["raw_ruckig_duration"]) <= 1e-9 * r["stop_duration"] for r in rows)
        ),
    }
    chord = [r for r in rows if r.get("chord_duration")]
    if chord:
        out.update(
            {
                "chord_solved": len(chord),
                "median_ratio_to_toppra_chord": float(np.median([r["duration"] / r["chord_duration"] for r in chord])),
                "chord_leaves_range": int(sum(r["chord_leaves_range"] for r in chord)),
                "chord_median_jerk_ratio": float(np.median([r["chord_jerk"] for r in chord])),
                "chord_max_velocity_ratio": float(max(r["chord_velocity"] for r in chord)),
                "chord_max_acceleration_ratio": float(max(r["chord_acceleration"] for r in chord)),
                "toppra_default_over_chord": float(
                    np.median([r["toppra_duration"] / r["chord_duration"] for r in chord if r.get("toppra_duration")])
                ),
            }
        )
    ok = [r for r in rows if r.get("toppra_duration")]
    if ok:
        ratio = np.array([r["duration"] / r["toppra_duration"] for r in ok])
        out.update(
            {
                "toppra_solved": len(ok),
                "toppra_failed": len(rows) - len(ok),
                "median_ratio_to_toppra": float(np.median(ratio)),
                "ratio_of_medians_to_toppra": float(np.median([r["duration"] for r in ok]))
                / float(np.median([r["toppra_duration"] for r in ok])),
                "share_faster_than_toppra": float(np.mean(ratio < 1.0)),
                "toppra_leaves_range": int(sum(r["toppra_leaves_range"] for r in ok)),
                "toppra_median_jerk_ratio": float(np.median([r["toppra_jerk"] for r in ok])),
                "toppra_max_velocity_ratio": float(max(r["toppra_velocity"] for r in ok)),
                "toppra_max_acceleration_ratio": float(max(r["toppra_acceleration"] for r in ok)),
                "toppra_ms_median": float(np.median([r["toppra_time"] for r in ok]) * 1e3),
            }
        )
    ref = [r for r in ok if r.get("optimum_duration") and r.get("relaxed_optimum_duration")]
    if ref:
        out.update(
            {
                "optimum_paths": len(ref),
                "optimum_median_ratio_to_toppra": float(
                    np.median([min(r["optimum_duration"], r["duration"]) / r["toppra_duration"] for r in ref])
                ),
                "relaxed_optimum_median_ratio_to_toppra": float(
                    np.median([r["relaxed_optimum_duration"] / r["toppra_duration"] for r in ref])
                ),
                "planner_median_ratio_to_toppra_same_paths": float(
                    np.median([r["duration"] / r["toppra_duration"] for r in ref])
                ),
                "optimum_gap_median": optimum_gap(ref),
            }
        )
    return out


def optimum_gap(rows: list[dict]) -> float:
    """Median of duration / optimum - 1 over rows with an NLP optimum (the optimum is the shorter
    of the NLP's and the planner's own duration, so the gap is >= 0)."""
    return float(np.median([r["duration"] / min(r["optimum_duration"], r["duration"]) - 1.0 for r in rows]))


def markdown(summaries: list[dict]) -> str:
    head = (
        "| robot | dof | paths | median T / TOPPRA chord (/ TOPPRA default) | TOPPRA chord out of range, "
        "median peak jerk / limit, worst v, a / limit | median T / TOPPRA default (ratio of medians) "
        "| optimum / TOPPRA default (jerk-free) | optimum gap "
        "| median T / stop | plan ms median (worst) | stop ms / raw Ruckig ms "
        "| peak v, a, j / limit | TOPPRA default out of range | TOPPRA default median peak jerk / limit |"
    )
    lines = [head, "|" + "---|" * 14]
    for s in summaries:
        chord = (
            f"{s['median_ratio_to_toppra_chord']:.3f} (/ {s['toppra_default_over_chord']:.3f})"
            if "median_ratio_to_toppra_chord" in s
            else "n/a"
        )
        chord_checks = (
            f"{s['chord_leaves_range']}/{s['chord_solved']}, {s['chord_median_jerk_ratio']:.1f}, "
            f"{s['chord_max_velocity_ratio']:.3f}, {s['chord_max_acceleration_ratio']:.3f}"
            if "chord_solved" in s
            else "n/a"
        )
        toppra = s.get("median_ratio_to_toppra")
        optimum = (
            f"{s['optimum_median_ratio_to_toppra']:.3f} ({s['relaxed_optimum_median_ratio_to_toppra']:.3f})"
            if "optimum_paths" in s
            else "n/a"
        )
        lines.append(
            f"| {s['robot']} | {s['dof']} | {s['paths']} | {chord} | {chord_checks} | "
            + (f"{toppra:.3f} ({s['ratio_of_medians_to_toppra']:.3f})" if toppra is not None else "n/a")
            + f" | {optimum} | "
            + (f"{100 * s['optimum_gap_median']:.2f} %" if "optimum_paths" in s else "n/a")
            + f" | {s['median_ratio_to_stop']:.3f} | "
            f"{s['plan_ms_median']:.2f} ({s['plan_ms_worst']:.1f}) | "
            f"{s['stop_ms_median']:.3f} / {s['raw_ruckig_ms_median']:.3f} "
            f"({s['median_stop_time_ratio_to_raw_ruckig']:.2f}x) | "
            f"{s['max_velocity_ratio']:.4f}, {s['max_acceleration_ratio']:.4f}, {s['max_jerk_ratio']:.4f} | "
            + (f"{s['toppra_leaves_range']}/{s['toppra_solved']}" if toppra is not None else "n/a")
            + " | "
            + (f"{s['toppra_median_jerk_ratio']:.1f}" if toppra is not None else "n/a")
            + " |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=100, help="random paths per robot")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random waypoints")
    parser.add_argument("--robots", nargs="*", default=None, help="robots (default: every available one)")
    parser.add_argument(
        "--optimum-every", type=int, default=0, help="solve every K-th path as an NLP for the optimum (0: none)"
    )
    parser.add_argument("--nodes", type=int, default=24, help="constant-jerk intervals per segment in that NLP")
    parser.add_argument("--clock", choices=tuple(CLOCKS), default="cpu", help="time CPU time (default) or wall time")
    args = parser.parse_args(argv)
    _clock[0] = CLOCKS[args.clock]
    logging.getLogger("toppra").setLevel(logging.ERROR)
    try:
        import toppra  # noqa: F401

        have_toppra = True
    except ImportError:
        have_toppra = False
        print("toppra is not installed (pip install 'servo-arm-planner[bench]'): TOPPRA columns are skipped")
    names = args.robots or list(available_robots())
    skipped = [n for n in ("ur5", "panda", "so101", "z1") if n not in available_robots()]
    if skipped:
        print(f"example-robot-data not installed: skipping {', '.join(skipped)}")
    rng = np.random.default_rng(args.seed)
    results = [bench_robot(name, args.paths, rng, have_toppra, args.optimum_every, args.nodes) for name in names]
    summaries = [summarise(r) for r in results]
    table = markdown(summaries)
    print(table)
    six = [s for s in summaries if s["dof"] == 6]
    all_ratios = [
        r["duration"] / r["toppra_duration"] for res in results for r in res["rows"] if r.get("toppra_duration")
    ]
    pairs = [(r["duration"], r["toppra_duration"]) for res in results for r in res["rows"] if r.get("toppra_duration")]
    ref = [
        r
        for res in results
        for r in res["rows"]
        if r.get("toppra_duration") and r.get("optimum_duration") and r.get("relaxed_optimum_duration")
    ]
    chord_ratios = [
        r["duration"] / r["chord_duration"] for res in results for r in res["rows"] if r.get("chord_duration")
    ]
    overall = {
        "median_ratio_to_toppra_chord_all": float(np.median(chord_ratios)) if chord_ratios else None,
        "median_stop_time_ratio_to_raw_ruckig_all": float(
            np.median([r["stop_time"] / r["raw_ruckig_time"] for res in results for r in res["rows"]])
        ),
        "worst_arm_stop_time_ratio_to_raw_ruckig": max(
            (s["median_stop_time_ratio_to_raw_ruckig"], s["robot"]) for s in summaries
        ),
        "median_ratio_to_toppra_all": float(np.median(all_ratios)) if all_ratios else None,
        "ratio_of_medians_to_toppra_all": float(np.median([p[0] for p in pairs]) / np.median([p[1] for p in pairs]))
        if pairs
        else None,
        "optimum_paths": len(ref),
        "optimum_median_ratio_to_toppra_all": float(
            np.median([min(r["optimum_duration"], r["duration"]) / r["toppra_duration"] for r in ref])
        )
        if ref
        else None,
        "relaxed_optimum_median_ratio_to_toppra_all": float(
            np.median([r["relaxed_optimum_duration"] / r["toppra_duration"] for r in ref])
        )
        if ref
        else None,
        "planner_median_ratio_to_toppra_same_paths": float(
            np.median([r["duration"] / r["toppra_duration"] for r in ref])
        )
        if ref
        else None,
        "optimum_gap_median_all": optimum_gap(ref) if ref else None,
        "optimum_failures": sum(
            1
            for res in results
            for r in res["rows"]
            if "optimum_duration" in r and not (r["optimum_duration"] and r["relaxed_optimum_duration"])
        ),
        "median_plan_ms_6dof": float(
            np.median([r["plan_time"] for res in results if res["dof"] == 6 for r in res["rows"]]) * 1e3
        )
        if six
        else None,
        "median_raw_ruckig_ms_6dof": float(
            np.median([r["raw_ruckig_time"] for res in results if res["dof"] == 6 for r in res["rows"]]) * 1e3
        )
        if six
        else None,
        "limit_tolerance": LIMIT_TOLERANCE,
    }
    summary_lines: list[str] = []
    say = summary_lines.append
    if overall["median_ratio_to_toppra_chord_all"] is not None:
        say(
            "median duration / TOPPRA (chord-length knots, clamped spline) over all paths: "
            f"{overall['median_ratio_to_toppra_chord_all']:.3f}"
        )
    if overall["median_ratio_to_toppra_all"] is not None:
        say(f"median duration / TOPPRA default over all paths: {overall['median_ratio_to_toppra_all']:.3f}")
    if overall["ratio_of_medians_to_toppra_all"] is not None:
        say(
            "median duration / median TOPPRA default duration over all paths: "
            f"{overall['ratio_of_medians_to_toppra_all']:.3f}"
        )
    if overall["optimum_median_ratio_to_toppra_all"] is not None:
        say(
            f"on the {overall['optimum_paths']} paths solved as an NLP: optimum / TOPPRA median "
            f"{overall['optimum_median_ratio_to_toppra_all']:.3f} (without jerk and range limits "
            f"{overall['relaxed_optimum_median_ratio_to_toppra_all']:.3f}), planner "
            f"{overall['planner_median_ratio_to_toppra_same_paths']:.3f}"
        )
    if overall["optimum_gap_median_all"] is not None:
        say(
            f"optimum gap (duration / NLP optimum - 1), median over {overall['optimum_paths']} paths: "
            f"{100 * overall['optimum_gap_median_all']:.2f} % (goal <= 0.5 %)"
        )
    say(
        "median plan time of strategy='stop' / raw Ruckig on the same segments: "
        f"{overall['median_stop_time_ratio_to_raw_ruckig_all']:.2f}x, worst arm "
        f"{overall['worst_arm_stop_time_ratio_to_raw_ruckig'][1]} "
        f"{overall['worst_arm_stop_time_ratio_to_raw_ruckig'][0]:.2f}x (goal <= 2x on every arm)"
    )
    if overall["median_plan_ms_6dof"] is not None:
        say(
            f"median plan time, 5 waypoints, 6-dof arms: {overall['median_plan_ms_6dof']:.2f} ms (goal <= 1.5 ms); "
            f"raw Ruckig stop-and-go on the same paths {overall['median_raw_ruckig_ms_6dof']:.3f} ms"
        )
    print()
    print("\n".join(summary_lines))
    record = {
        **run_record("bench_trajectory", ("ruckig", "numpy", "pin", "toppra", "example-robot-data")),
        "settings": {
            "paths": args.paths,
            "seed": args.seed,
            "waypoints": 5,
            "limits": "v = URDF, a = 2 v, j = 10 a",
            "optimum_every": args.optimum_every,
            "nodes": args.nodes,
            "clock": args.clock,
        },
        "summary": summaries,
        "overall": overall,
        "table": table,
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = RESULTS / "bench_trajectory.json"
    out.write_text(json.dumps(record, indent=2) + "\n")
    (RESULTS / "bench_trajectory.md").write_text(table + "\n\n" + "\n".join(summary_lines) + "\n")
    print(f"\nwrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
