"""The IK benchmark: closed-form vs numerical (CasADi) inverse kinematics on random targets.

Used by ``planner bench`` and ``benchmarks/bench_ik.py``. For each arm, N random
configurations within the joint limits (seeded) give the targets: their FK pose for arms with
6 or more joints (and the 5-dof so101), a position plus approach pitch for al5c and
three_joint, a position for shelley and dh3; the seeds / current configurations are another
seeded draw. Success = position error < 1e-4 m and orientation error < 1e-3 rad by Pinocchio
FK (computed here, not taken from the solvers), within the joint limits. Times are wall times
of the solve call after a warm-up call.
"""

from __future__ import annotations

import collections
import datetime
import math
import os
import platform
import sys
import time
from collections.abc import Sequence
from importlib import metadata
from pathlib import Path

import casadi as ca
import numpy as np

from planner.app.progress import progress
from planner.core.rotations import rotation_error
from planner.exceptions import InvalidArgumentError
from planner.geometry.target import Target, approach_pitch, target_errors
from planner.ik.cross_check import compare
from planner.ik.numeric.kinematics import CasadiKinematics
from planner.ik.numeric.solver import NlpIK
from planner.ik.options import IKOptions
from planner.ik.solve import closed_form_answer
from planner.ik.solvers import IKSolvers
from planner.model.catalog import BUNDLED_ROBOTS, load_robot

__all__ = ["BUNDLED_KINDS", "KINDS", "bench_robot", "run_record", "make_target", "markdown", "summarise", "verify"]

POSITION_TOL = 1e-4
ORIENTATION_TOL = 1e-3
#: Target kind of each bundled arm (what its joints can reach); example-robot-data arms: pose.
BUNDLED_KINDS = {"shelley": "position", "dh3": "position", "three_joint": "pitch", "al5c": "pitch"}
#: Target kinds benchmarked per robot: its own kind, and for the 5-dof so101 (a servo arm of
#: the source papers' family) the position + approach pitch targets a user of such an arm would give.
KINDS = {**{name: (kind,) for name, kind in BUNDLED_KINDS.items()}, "so101": ("pose", "pitch")}
#: Most random targets per robot (each is an NLP solve of up to the time budget).
MAX_TARGETS = 1_000_000


def make_target(robot, kind: str, q: np.ndarray) -> Target:
    """The target of `kind` (``"pose"``, ``"pitch"``, ``"position"``) that configuration q reaches."""
    pose = robot.fk(q)
    if kind == "pose":
        return Target.from_pose(pose)
    if kind == "pitch":
        return Target(pose[:3, 3], pitch=approach_pitch(robot, q))
    return Target(pose[:3, 3])


def verify(robot, target: Target, q: np.ndarray | None) -> tuple[bool, float, float]:
    """Success by Pinocchio FK and the limits; (success, position error, orientation error)."""
    if q is None:
        return False, math.nan, math.nan
    pose = robot.fk(q)
    pe = float(np.linalg.norm(pose[:3, 3] - target.position))
    if target.rotation is not None:
        oe = float(rotation_error(pose[:3, :3], target.rotation))
    else:
        oe = target_errors(robot, target, q)[1]  # planner.geometry.target.pitch_error for a pitch
    ok = pe < POSITION_TOL and oe < ORIENTATION_TOL and bool(robot.within_limits(q))
    return ok, pe, oe


class IpoptBaseline:
    """One bounded least-squares NLP, IPOPT from the seed, no restarts."""

    def __init__(self, robot, kind: str) -> None:
        kin = CasadiKinematics(robot)
        q = ca.SX.sym("q", robot.dof)
        p = ca.SX.sym("p", 12)
        position, rotation, _ = kin.expressions(q)
        r = position - p[:3]
        if kind == "pose":
            r = ca.vertcat(r, 0.25 * (rotation - ca.reshape(p[3:12], 3, 3))[:])
        opts = {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-12, "max_iter": 200}}
        self.solver = ca.nlpsol("baseline", "ipopt", {"x": q, "p": p, "f": ca.sumsqr(r)}, opts)
        self.lower = np.where(np.isfinite(robot.lower), robot.lower, -1e20)
        self.upper = np.where(np.isfinite(robot.upper), robot.upper, 1e20)

    def solve(self, target: Target, seed: np.ndarray) -> np.ndarray:
        p = np.zeros(12)
        p[:3] = target.position
        if target.rotation is not None:
            p[3:] = target.rotation.ravel(order="F")
        out = self.solver(x0=seed, p=p, lbx=self.lower, ubx=self.upper)
        return np.clip(np.array(out["x"]).ravel(), self.lower, self.upper)


def summarise(name: str, kind: str, method: str, dof: int, rows: list[dict], setup_s: float) -> dict:
    """Solve rate, time percentiles [ms], median errors and cross-check verdicts of one method's rows."""
    times = np.array([r["time"] for r in rows]) * 1e3
    ok = np.array([r["ok"] for r in rows])
    pe = np.array([r["pe"] for r in rows])
    oe = np.array([r["oe"] for r in rows])
    out = {
        "robot": name,
        "source": "bundled" if name in BUNDLED_ROBOTS else "example-robot-data",
        "dof": dof,
        "kind": kind,
        "method": method,
        "n": len(rows),
        "solve_rate": float(ok.mean()),
        "solved": int(ok.sum()),
        "median_ms": float(np.median(times)),
        "p95_ms": float(np.percentile(times, 95)),
        "max_ms": float(np.max(times)),
        "median_position_error": float(np.nanmedian(pe)) if np.any(np.isfinite(pe)) else None,
        "median_orientation_error": float(np.nanmedian(oe)) if np.any(np.isfinite(oe)) else None,
        "setup_s": setup_s,
    }
    if "attempts" in rows[0]:
        attempts = np.array([r["attempts"] for r in rows])
        out["mean_attempts"] = float(attempts.mean())
        out["max_attempts"] = int(attempts.max())
        kinds = collections.Counter(r["attempt_kind"] for r in rows)
        out["attempt_kinds"] = {str(k): v for k, v in kinds.items()}
    if rows and "verdict" in rows[0]:
        verdicts = collections.Counter(r["verdict"] for r in rows)
        out["cross_check_agreement"] = float(np.mean([r["agree"] for r in rows]))
        out["cross_check_verdicts"] = dict(verdicts)
        out["disagreements"] = [r["case"] for r in rows if not r["agree"]][:10]
    return out


def bench_robot(
    name: str, n: int, seed: int, time_budget: float, baseline: bool = False, kind: str | None = None
) -> list[dict]:
    """Benchmark one robot: closed form (where it has one), NLP, and optionally one plain IPOPT solve.

    Args:
        name: Robot name for :func:`planner.load_robot`.
        n: Number of random targets.
        seed: Seed of the target configurations (stream ``[seed, 1000]``) and of the seeds / current
            configurations (``[seed, 1001]``).
        time_budget: NLP time budget per call [s].
        baseline: Also time one bounded IPOPT solve from the seed (pose targets only).
        kind: Target kind (``"pose"``, ``"pitch"``, ``"position"``); None is the robot's first
            kind in :data:`KINDS` (pose for arms not listed).

    Returns:
        One summary mapping per method (see :func:`summarise`).

    Raises:
        InvalidArgumentError: If `n` is not an integer in [1, MAX_TARGETS] or `seed` not one >= 0.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= MAX_TARGETS:
        raise InvalidArgumentError(f"the number of targets must be an integer in [1, {MAX_TARGETS}], got {n!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InvalidArgumentError(f"the seed must be an integer >= 0 (NumPy's seeds are), got {seed!r}")
    robot = load_robot(name)
    kind = kind or KINDS.get(name, ("pose",))[0]
    # Streams apart from the NLP's fixed restart pool (drawn from default_rng(0)): targets drawn
    # from that stream would be the pool's own configurations, solved by a restart at once.
    q_targets = robot.random_configurations(np.random.default_rng([seed, 1000]), n)
    q_seeds = robot.random_configurations(np.random.default_rng([seed, 1001]), n)
    targets = [make_target(robot, kind, q) for q in q_targets]
    summaries = []

    analytic = IKSolvers.of(robot).analytic
    t0 = time.perf_counter()
    nlp = NlpIK(robot).prepare([kind])
    nlp_setup = time.perf_counter() - t0
    options = IKOptions(time_budget=time_budget)
    nlp.solve(targets[0], q_seeds[0], options)  # warm-up

    analytic_results = []
    if analytic is not None:
        analytic.solve(targets[0], q_seeds[0])  # warm-up
        rows = []
        for target, q_seed in zip(progress(targets, label=f"{name} analytic"), q_seeds):
            t = time.perf_counter()
            result = analytic.solve(target, q_seed)
            elapsed = time.perf_counter() - t
            analytic_results.append((result, t))
            best = result.best
            ok, pe, oe = verify(robot, target, None if best is None else np.asarray(best.q))
            rows.append({"time": elapsed, "ok": ok, "pe": pe, "oe": oe})
        summaries.append(summarise(name, kind, "analytic", robot.dof, rows, 0.0))

    rows = []
    for i, (target, q_seed) in enumerate(zip(progress(targets, label=f"{name} nlp"), q_seeds)):
        t = time.perf_counter()
        result = nlp.solve(target, q_seed, options)
        elapsed = time.perf_counter() - t
        ok, pe, oe = verify(robot, target, result.q)
        row = {
            "time": elapsed,
            "ok": ok,
            "pe": pe,
            "oe": oe,
            "attempts": result.attempts,
            "attempt_kind": result.attempt_kind,
        }
        if analytic is not None:
            family, started = analytic_results[i]
            closed = closed_form_answer(robot, target, family, q_seed, IKOptions(), started)
            check = compare(robot, target, closed, result)
            row.update(
                agree=check.agree,
                verdict=check.verdict,
                case={
                    "q_target": q_targets[i].tolist(),
                    "q_seed": q_seed.tolist(),
                    "verdict": check.verdict,
                    "reason": check.reason,
                },
            )
        rows.append(row)
    summaries.append(summarise(name, kind, "nlp", robot.dof, rows, nlp_setup))

    if baseline and kind == "pose":
        t0 = time.perf_counter()
        ipopt = IpoptBaseline(robot, kind)
        setup = time.perf_counter() - t0
        ipopt.solve(targets[0], q_seeds[0])
        rows = []
        for target, q_seed in zip(progress(targets, label=f"{name} ipopt-1"), q_seeds):
            t = time.perf_counter()
            q = ipopt.solve(target, q_seed)
            elapsed = time.perf_counter() - t
            ok, pe, oe = verify(robot, target, q)
            rows.append({"time": elapsed, "ok": ok, "pe": pe, "oe": oe})
        summaries.append(summarise(name, kind, "ipopt-1", robot.dof, rows, setup))
    return summaries


def _fmt(value: float | None, spec: str) -> str:
    return "n/a" if value is None else format(value, spec)


def markdown(summaries: list[dict]) -> str:
    """The summaries as a Markdown table."""
    head = (
        "| robot | dof | target | method | solve rate | median ms | p95 ms | max ms | median pos. err. [m] "
        "| median orient. err. [rad] | mean attempts | cross-check agreement |"
    )
    lines = [head, "|" + "---|" * 12]
    for s in summaries:
        agreement = s.get("cross_check_agreement")
        lines.append(
            f"| {s['robot']} | {s['dof']} | {s['kind']} | {s['method']} | {100 * s['solve_rate']:.2f} % "
            f"| {s['median_ms']:.3f} | {s['p95_ms']:.3f} | {s['max_ms']:.2f} "
            f"| {_fmt(s['median_position_error'], '.1e')} | {_fmt(s['median_orientation_error'], '.1e')} "
            f"| {_fmt(s.get('mean_attempts'), '.2f')} "
            f"| {'n/a' if agreement is None else f'{100 * agreement:.2f} %'} |"
        )
    return "\n".join(lines)


def run_record(benchmark: str, packages: Sequence[str]) -> dict:
    """What a results file records about its run: name, UTC date, command, machine, versions.

    Args:
        benchmark: The benchmark's name.
        packages: Distributions whose installed versions matter (None where not installed).

    Returns:
        A JSON-ready mapping; the caller adds its settings and figures.
    """
    versions: dict[str, str | None] = {}
    for pkg in packages:
        try:
            versions[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            versions[pkg] = None
    try:
        load = list(os.getloadavg())
    except OSError:
        load = None
    return {
        "benchmark": benchmark,
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(),
            "load_average": load,
            "python": platform.python_version(),
        },
        "versions": versions,
    }
