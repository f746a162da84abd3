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

Peers (issue 12), printed first: on ur5, panda, so101, z1 and ur10 (example-robot-data; skipped
when absent), ``planner.solve_ik(method="nlp")`` against roboticstoolbox-python's C++ ``ik_LM``
(restarts on, tol 1e-12) and TRAC-IK (pytracik, where installed), interleaved target by target
(the order of the solvers rotates from target to target) on the same random 6-D pose targets
and seeds (``--peer-n``, streams ``--seed + 100`` and ``+ 101``), with the same success test
(the errors above by Pinocchio FK, within the limits) for all. Every solver gets its target in
the form it takes, built before the clock starts (a ``planner.Target``, a 4x4 array, a
quaternion). TRAC-IK runs two threads per call, whose work slows the next call of whichever
solver follows on a two-core machine (both others' medians rose 1.5-3x beside it): it is timed
in a pass of its own over the same targets and seeds. The table gives median and p95 wall times
and the ratios planner / ik_LM; goal 1 of issue 12: both ratios <= 0.5 and 100 % solved. The
ratios of the calls' CPU times (``time.thread_time``, blind to time the process waits on a
shared machine) are given too.
Written to benchmarks/results/bench_ik.md and the ``peers`` entry of bench_ik.json.

Closed form vs NLP as users call them (issue 12, goal 3), printed next: on the arms with a
closed form (shelley, dh3, three_joint, al5c, and so101 where example-robot-data is installed)
and every target kind the arm's closed form solves (position, position + pitch, pose),
``solve_ik(robot, target, seed)`` (the default method, which takes the closed form) and
``solve_ik(..., method="nlp")``, each call interleaved target by target with one ``robot.fk``
call and the family solver's own ``solver.solve`` call (``--public-n`` targets, the main
table's streams). The table gives median and p95 times, each median as a ratio to fk, what
solve_ik adds to the solver's call (auto - solver: the medians' difference; solve_ik takes the
family's nearest solution without building the whole result, so this can be small or
negative), and auto / nlp (below 1: the closed form is the faster through the public entry).
Written to the ``public`` entry of bench_ik.json.

    python benchmarks/bench_ik.py [--n 1000] [--seed 0] [--robots ur5 panda] [--ipopt-baseline]
    python benchmarks/bench_ik.py --peers-only [--peer-n 500]
    python benchmarks/bench_ik.py --public-only [--public-n 2000] [--out /tmp/bench_ik.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from ik_peers import PEERS, make_peer

from planner import Robot, available_robots, load_robot, solve_ik
from planner.app.benchmark import (
    BUNDLED_KINDS,
    KINDS,
    ORIENTATION_TOL,
    POSITION_TOL,
    bench_robot,
    make_target,
    markdown,
    run_record,
    verify,
)
from planner.app.progress import progress
from planner.exceptions import UnsupportedChainError
from planner.geometry.target import Target
from planner.ik.numeric.solver import NlpIK
from planner.ik.solvers import IKSolvers
from planner.model.catalog import EXAMPLE_ROBOTS, example_robot_data_dir

RESULTS = Path(__file__).resolve().parent / "results"
#: The arms of goal 1 (example-robot-data): URDF below its robots folder and tip frame.
PEER_ARMS = {
    **{name: (EXAMPLE_ROBOTS[name].urdf, EXAMPLE_ROBOTS[name].tip) for name in ("ur5", "panda", "so101", "z1")},
    "ur10": ("ur_description/urdf/ur10_robot.urdf", "tool0"),
}


#: Peers timed in a pass of their own (see bench_peers).
SEPARATE = ("trac_ik",)


def _success(robot: Robot, target: Target, q: np.ndarray | None) -> bool:
    """The one success test: Pinocchio FK errors within 1e-4 m / 1e-3 rad, within the limits."""
    if q is None:
        return False
    q = np.asarray(q, dtype=float)
    if q.shape != (robot.dof,) or not np.all(np.isfinite(q)) or not robot.within_limits(q):
        return False
    pose = robot.fk(q)
    position_error = float(np.linalg.norm(pose[:3, 3] - target.position))
    rel = pose[:3, :3].T @ target.rotation
    orientation_error = float(np.arccos(np.clip(0.5 * (np.trace(rel) - 1.0), -1.0, 1.0)))
    return position_error < POSITION_TOL and orientation_error < ORIENTATION_TOL


def bench_peers(name: str, n: int, seed: int, peers: list[str]) -> dict:
    """planner (solve_ik, method nlp) and the peers, interleaved target by target on one arm."""
    root = example_robot_data_dir()
    urdf, tip = PEER_ARMS[name]
    robot = Robot.from_urdf(root / urdf, tip, name=name)
    q_targets = robot.random_configurations(np.random.default_rng(seed + 100), n)
    q_seeds = robot.random_configurations(np.random.default_rng(seed + 101), n)
    poses = [robot.fk(q) for q in q_targets]
    targets = [Target.from_pose(p) for p in poses]

    def ours(target: Target, q_seed: np.ndarray) -> np.ndarray:
        return solve_ik(robot, target, q_seed, method="nlp").q

    solvers = {"planner": (ours, targets)}
    skipped: dict[str, str] = {}
    notes: dict[str, str] = {}
    for peer_name in peers:
        peer = make_peer(peer_name, robot, root / urdf, root.parent, np.random.default_rng(seed))
        if isinstance(peer, str):
            skipped[peer_name] = peer
            continue
        solvers[peer_name] = (peer.solve, [peer.prepare(p) for p in poses])
        if peer.note:
            notes[peer_name] = peer.note
    names = list(solvers)
    for solve, prepared in solvers.values():  # warm-up: build and load compiled code
        solve(prepared[0], q_seeds[0])
    times = {label: np.zeros(n) for label in names}
    cpu = {label: np.zeros(n) for label in names}
    ok = {label: np.zeros(n, dtype=bool) for label in names}
    clock, cpu_clock = time.perf_counter, time.thread_time
    # TRAC-IK runs two threads per call (KDL and SQP), whose work spills into the next solver's
    # call on a small machine: it runs in a pass of its own after the interleaved ones.
    interleaved = [label for label in names if label not in SEPARATE]
    passes = [interleaved] + [[label] for label in names if label in SEPARATE]
    for group in passes:
        for i in progress(range(n), label=f"{name} {' / '.join(group)}"):
            for shift in range(len(group)):
                label = group[(i + shift) % len(group)]
                solve, prepared = solvers[label]
                c0, t0 = cpu_clock(), clock()
                q = solve(prepared[i], q_seeds[i])
                times[label][i], cpu[label][i] = clock() - t0, cpu_clock() - c0
                ok[label][i] = _success(robot, targets[i], q)
    out = {"robot": name, "dof": robot.dof, "n": n, "skipped": skipped, "notes": notes, "solvers": {}}
    for label in names:
        ms, cpu_ms = times[label] * 1e3, cpu[label] * 1e3
        out["solvers"][label] = {
            "solve_rate": float(ok[label].mean()),
            "median_ms": float(np.median(ms)),
            "p95_ms": float(np.percentile(ms, 95)),
            "max_ms": float(ms.max()),
            "cpu_median_ms": float(np.median(cpu_ms)),
            "cpu_p95_ms": float(np.percentile(cpu_ms, 95)),
        }
    if "ik_LM" in out["solvers"]:
        ref, own = out["solvers"]["ik_LM"], out["solvers"]["planner"]
        out["ratio_median"] = own["median_ms"] / ref["median_ms"]
        out["ratio_p95"] = own["p95_ms"] / ref["p95_ms"]
        out["cpu_ratio_median"] = own["cpu_median_ms"] / ref["cpu_median_ms"]
        out["cpu_ratio_p95"] = own["cpu_p95_ms"] / ref["cpu_p95_ms"]
        out["goal_met"] = out["ratio_median"] <= 0.5 and out["ratio_p95"] <= 0.5 and own["solve_rate"] == 1.0
    return out


#: The arms with a closed form timed through solve_ik (``--robots``; so101 where example-robot-data is
#: installed), and the target kinds tried.
PUBLIC_ROBOTS = ("shelley", "dh3", "three_joint", "al5c", "so101")
PUBLIC_KINDS = ("position", "pitch", "pose")


def bench_public(name: str, kind: str, n: int, seed: int) -> dict | None:
    """Closed form vs NLP as users call them: ``solve_ik`` (auto) and ``solve_ik(method="nlp")``.

    Per target, interleaved (the order rotating from target to target): one ``robot.fk`` call
    (the reference of the ratios), the family solver's own call (``solver.solve``), ``solve_ik``
    with the default method (the closed form where the arm has one) and with ``method="nlp"``,
    on the same targets and seeds (streams ``[seed, 1000]`` and ``[seed, 1001]``, as the main
    table). Success as the main table (Pinocchio FK errors, within the limits).

    Returns:
        The row, or None when the arm's closed form does not solve this kind of target.
    """
    robot = load_robot(name)
    analytic = IKSolvers.of(robot).analytic
    if analytic is None:
        return None
    q_targets = robot.random_configurations(np.random.default_rng([seed, 1000]), n)
    q_seeds = robot.random_configurations(np.random.default_rng([seed, 1001]), n)
    targets = [make_target(robot, kind, q) for q in q_targets]
    try:
        if not all(analytic.solve(t, s).ok for t, s in zip(targets[:20], q_seeds[:20])):
            return None
    except UnsupportedChainError:
        return None
    calls = {
        "fk": lambda i: robot.fk(q_targets[i]),
        "solver": lambda i: analytic.solve(targets[i], q_seeds[i]),
        "auto": lambda i: solve_ik(robot, targets[i], q_seeds[i]),
        "nlp": lambda i: solve_ik(robot, targets[i], q_seeds[i], method="nlp"),
    }
    labels = list(calls)
    for i in range(min(n, 50)):  # warm-up
        for call in calls.values():
            call(i)
    times = {label: np.zeros(n) for label in labels}
    ok = {label: np.zeros(n, dtype=bool) for label in ("auto", "nlp")}
    methods = set()
    clock = time.perf_counter
    for i in progress(range(n), label=f"{name} {kind} solve_ik"):
        for shift in range(len(labels)):
            label = labels[(i + shift) % len(labels)]
            call = calls[label]
            t0 = clock()
            out = call(i)
            times[label][i] = clock() - t0
            if label in ok:
                ok[label][i] = verify(robot, targets[i], out.q)[0] and out.success
                if label == "auto":
                    methods.add(out.method)
    med = {label: float(np.median(times[label])) for label in labels}
    p95 = {label: float(np.percentile(times[label], 95)) for label in labels}
    return {
        "robot": name,
        "kind": kind,
        "n": n,
        "fk_us": med["fk"] * 1e6,
        **{f"{label}_median_us": med[label] * 1e6 for label in labels[1:]},
        **{f"{label}_p95_us": p95[label] * 1e6 for label in labels[1:]},
        **{f"{label}_fk": med[label] / med["fk"] for label in labels[1:]},
        "auto_methods": sorted(methods),
        "auto_solve_rate": float(ok["auto"].mean()),
        "nlp_solve_rate": float(ok["nlp"].mean()),
        "auto_over_nlp": med["auto"] / med["nlp"],
        "auto_over_solver": med["auto"] / med["solver"],
        "auto_minus_solver_us": (med["auto"] - med["solver"]) * 1e6,
    }


def public_markdown(rows: list[dict]) -> str:
    """The solve_ik comparison as a Markdown table (times in us, ratios to fk in brackets)."""
    lines = [
        "| robot | target | auto answered by | solver.solve us (x fk) | solve_ik auto us (x fk) | p95 us "
        "| auto - solver us | solve_ik nlp us (x fk) | p95 us | auto / nlp | solved auto / nlp |",
        "|" + "---|" * 11,
    ]
    for r in rows:
        lines.append(
            f"| {r['robot']} | {r['kind']} | {', '.join(r['auto_methods'])} "
            f"| {r['solver_median_us']:.1f} ({r['solver_fk']:.2f}) | {r['auto_median_us']:.1f} ({r['auto_fk']:.2f}) "
            f"| {r['auto_p95_us']:.1f} | {r['auto_minus_solver_us']:.1f} "
            f"| {r['nlp_median_us']:.1f} ({r['nlp_fk']:.2f}) | {r['nlp_p95_us']:.1f} "
            f"| **{r['auto_over_nlp']:.2f}** | {100 * r['auto_solve_rate']:.1f} % / {100 * r['nlp_solve_rate']:.1f} % |"
        )
    return "\n".join(lines)


def peers_markdown(rows: list[dict]) -> str:
    """The side-by-side table: solve rate, median and p95 [ms] per solver, ratios planner / ik_LM."""
    peers = [p for p in PEERS if any(p in r["solvers"] for r in rows)]
    head = "| arm | dof | n | planner: solved · median · p95 [ms] |"
    head += "".join(f" {p}: solved · median · p95 [ms] |" for p in peers)
    head += " median ratio planner/ik_LM | p95 ratio planner/ik_LM | goal 1 (both <= 0.5, 100 %) |"
    head += " CPU-time ratios median · p95 |"
    lines = [head, "|" + "---|" * (7 + len(peers))]

    def cell(s: dict | None) -> str:
        if s is None:
            return " skipped |"
        return f" {100 * s['solve_rate']:.1f} % · {s['median_ms']:.3f} · {s['p95_ms']:.3f} |"

    for r in rows:
        line = f"| {r['robot']} | {r['dof']} | {r['n']} |" + cell(r["solvers"]["planner"])
        line += "".join(cell(r["solvers"].get(p)) for p in peers)
        if "ratio_median" in r:
            line += f" {r['ratio_median']:.2f} | {r['ratio_p95']:.2f} | {'met' if r['goal_met'] else 'missed'} |"
            line += f" {r['cpu_ratio_median']:.2f} · {r['cpu_ratio_p95']:.2f} |"
        else:
            line += " n/a | n/a | n/a | n/a |"
        lines.append(line)
    notes = [f"- {r['robot']}: {p} skipped: {why}" for r in rows for p, why in r["skipped"].items()]
    notes += [f"- {r['robot']}: {p}: {note}" for r in rows for p, note in r["notes"].items()]
    return "\n".join(lines + ([""] + notes if notes else []))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000, help="random targets per robot (default 1000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the target configurations (seeds: seed + 1)")
    parser.add_argument("--robots", nargs="*", default=None, help="robots (default: every available one)")
    parser.add_argument("--time-budget", type=float, default=0.05, help="NLP time budget per call [s]")
    parser.add_argument("--ipopt-baseline", action="store_true", help="add the single-IPOPT-solve baseline rows")
    parser.add_argument("--plot", type=Path, default=None, help="also write a PNG bar chart here (matplotlib)")
    parser.add_argument("--out", type=Path, default=RESULTS / "bench_ik.json", help="JSON output file")
    parser.add_argument("--peer-n", type=int, default=500, help="random pose targets per arm against the peers")
    parser.add_argument("--peers-only", action="store_true", help="only the comparison with the peers")
    parser.add_argument("--peers", nargs="*", default=list(PEERS), choices=list(PEERS), help="peers to compare with")
    parser.add_argument("--arms", nargs="*", default=list(PEER_ARMS), choices=list(PEER_ARMS), help="arms of the peers")
    parser.add_argument("--no-peers", action="store_true", help="skip the comparison with the peers")
    parser.add_argument("--public-n", type=int, default=2000, help="targets per arm and kind through solve_ik")
    parser.add_argument("--public-only", action="store_true", help="only closed form vs NLP through solve_ik")
    parser.add_argument("--no-public", action="store_true", help="skip closed form vs NLP through solve_ik")
    args = parser.parse_args(argv)
    if args.n < 1 or args.peer_n < 1 or args.public_n < 1:
        parser.error("--n, --peer-n and --public-n must be >= 1")
    if args.public_only and args.peers_only:
        parser.error("--public-only and --peers-only exclude each other")
    peer_rows = []
    if not (args.no_peers or args.public_only):
        if example_robot_data_dir() is None:
            print("example-robot-data not installed: skipping the comparison with the peers")
        else:
            peer_rows = [bench_peers(name, args.peer_n, args.seed, args.peers) for name in args.arms]
            peer_table = peers_markdown(peer_rows)
            print(peer_table)
            print()
            record = {
                **run_record("bench_ik", ("casadi", "pin", "numpy", "roboticstoolbox-python", "pytracik")),
                "peers_settings": {"n": args.peer_n, "seed": args.seed, **PEERS},
            }
            md = RESULTS / "bench_ik.md"
            md.parent.mkdir(parents=True, exist_ok=True)
            md.write_text(
                f"# bench_ik: planner NLP vs peers ({record['date']})\n\n`{record['command']}`\n\n"
                + "\n".join(f"- {k}: {v}" for k, v in PEERS.items())
                + f"\n- versions: {record['versions']}\n\n{peer_table}\n"
            )
            print(f"wrote {md}")
    if args.peers_only:
        _write(args.out, {"peers": peer_rows}, merge=True)
        return 0
    public_rows = []
    if not args.no_public:
        arms = [r for r in (args.robots or PUBLIC_ROBOTS) if r in PUBLIC_ROBOTS]
        if example_robot_data_dir() is None:
            arms = [r for r in arms if r != "so101"]
        public_rows = [
            row for name in arms for kind in PUBLIC_KINDS if (row := bench_public(name, kind, args.public_n, args.seed))
        ]
        if public_rows:
            print("Closed form vs NLP through solve_ik (interleaved; ratios to one robot.fk call in brackets):\n")
            print(public_markdown(public_rows))
            print()
    if args.public_only:
        _write(args.out, {"public": public_rows}, merge=True)
        return 0
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
        "peers": peer_rows,
        "public": public_rows,
    }
    _write(args.out, record, merge=bool(args.no_peers or args.no_public))
    print(f"\nwrote {args.out}")
    if args.plot is not None:
        from planner.app.plots import plot_ik_benchmark

        print(f"wrote {plot_ik_benchmark(args.plot, summaries)}")
    return 0


def _write(path: Path, record: dict, merge: bool) -> None:
    """Write the JSON; with `merge`, keep the entries and robots' rows this run did not make."""
    if merge and path.exists():
        old = json.loads(path.read_text())
        merged = {**old, **{k: v for k, v in record.items() if v or k not in old}}
        for key in ("summary", "peers", "public"):
            # Rows of robots this run did not measure (e.g. with --robots) are kept.
            if record.get(key) and isinstance(old.get(key), list):
                ran = {row["robot"] for row in record[key]}
                merged[key] = [row for row in old[key] if row.get("robot") not in ran] + record[key]
        record = merged
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=2, allow_nan=False) + "\n")


if __name__ == "__main__":
    sys.exit(main())
