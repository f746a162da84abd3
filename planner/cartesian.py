"""Cartesian targets to joint configurations: IK branch choice and straight-line segments.

:class:`TargetSolver` wraps the project's two IK solvers (built once per robot by
:mod:`planner.ik`): the closed form (:class:`planner.analytic.AnalyticIK`) where the arm
belongs to one of its families, else the CasADi NLP (:class:`planner.nlp_ik.NlpIK`). For a
waypoint it picks, among the solutions within the joint limits, one clear of singularities
and nearest the previous configuration, and says which branch it took.

:func:`line_waypoints` follows a straight line between two targets: it samples the line
(position linearly; approach pitch linearly; orientation by spherical interpolation), solves
IK at every sample seeded by (closed form: nearest to) the previous one, and bisects wherever a
joint would jump more than a step bound, so the joint path is continuous. The samples become
via waypoints of the Ruckig chain (:func:`planner.trajectory.plan_trajectory`), which times
them within every joint's speed, acceleration and jerk limit: near a singularity the joints
must move far for a short stretch of line, so the motion slows down there instead of asking
for unbounded joint speed (the 002 seed's concern). :func:`line_deviation` measures how far
the sampled tip strays from the line between the samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .exceptions import InvalidArgumentError
from .robot import Robot, Task
from .singularity import conditioning
from .target import Target
from .trajectory import JointLimits

__all__ = [
    "IKChoice",
    "LinePath",
    "LineTiming",
    "TargetSolver",
    "interpolate_target",
    "line_deviation",
    "line_waypoints",
    "time_line",
]


@dataclass(frozen=True)
class IKChoice:
    """The configuration chosen for one Cartesian target.

    Attributes:
        q: Joint values, shape (dof,) [rad or m].
        branch: Closed-form branch name (e.g. ``"front/elbow-up"``), or ``"nlp"``.
        singular: Whether it is below the singularity threshold (kept and flagged: no clear
            solution within the limits exists).
        inverse_condition: Its inverse condition number.
        alternatives: How many other solutions within the limits there were.
        position_error: Tip distance to the target by Pinocchio's FK [m].
    """

    q: np.ndarray
    branch: str
    singular: bool
    inverse_condition: float
    alternatives: int
    position_error: float


class TargetSolver:
    """IK for waypoints and line samples: closed form where possible, else NLP.

    Attributes:
        robot: The robot.
        method: ``"analytic"`` or ``"nlp"``.
        threshold: Inverse condition number below which a solution counts as singular.
        task: Task Jacobian for that measure.
    """

    def __init__(
        self, robot: Robot, *, threshold: float = 1.0 / 30.0, task: Task | None = None, method: str | None = None
    ):
        """Build the solver.

        Args:
            robot: The robot.
            threshold: Inverse condition number below which a solution is avoided if possible.
            task: ``"position"`` or ``"pose"``; None as the robot chooses.
            method: ``"analytic"``, ``"nlp"`` or None (closed form when the chain allows).

        Raises:
            InvalidArgumentError: On an unknown method.
            UnsupportedChainError: If ``method="analytic"`` and the chain has no closed form.
        """
        if method not in (None, "analytic", "nlp"):
            raise InvalidArgumentError(f"unknown IK method {method!r}; valid: analytic, nlp")
        self.robot = robot
        self.threshold = float(threshold)
        self.task = task
        from .ik import analytic_solver, nlp_solver

        self._analytic = analytic_solver(robot) if method in (None, "analytic") else None
        if method == "analytic" and self._analytic is None:
            from .analytic import AnalyticIK

            AnalyticIK.from_robot(robot)  # raises UnsupportedChainError naming the joint
        self.method = "analytic" if self._analytic is not None else "nlp"
        self._nlp = nlp_solver(robot) if self._analytic is None else None
        lo = np.where(np.isfinite(robot.lower), robot.lower, 0.0)
        hi = np.where(np.isfinite(robot.upper), robot.upper, 0.0)
        self._home = (lo + hi) / 2.0

    def _inverse_condition(self, q: np.ndarray) -> float:
        return float(conditioning(self.robot, q, self.task)[0])

    def _error(self, target: Target, q: np.ndarray) -> float:
        return float(np.linalg.norm(self.robot.position(q) - target.position))

    def candidates(
        self, target: Target, q_near: np.ndarray | None, *, nearest: bool = False
    ) -> tuple[list[tuple[np.ndarray, str]], str]:
        """Solutions within the limits, ``(q, branch)``, and a reason when there are none.

        The closed form gives every branch; the NLP one solution, started from `q_near` (with
        `nearest`, the solution nearest `q_near` among those it finds).
        """
        if self._analytic is not None:
            res = self._analytic.solve(target, q_current=q_near)
            sols = [(np.array(s.q, dtype=float), s.branch) for s in res.solutions if s.within_limits]
            return sols, res.reason or res.status
        if q_near is None:
            res = self._nlp.solve(target)
        else:
            res = self._nlp.solve(target, q_seed=q_near, near_seed=nearest)
        if res.success:
            return [(np.array(res.q, dtype=float), "nlp")], ""
        return [], f"{res.status}: {res.reason}"

    def choose(self, target: Target, q_previous: np.ndarray | None, *, label: str = "target") -> IKChoice:
        """The solution for a waypoint: clear of singularities first, then nearest `q_previous`.

        Args:
            target: The Cartesian target.
            q_previous: The configuration before it; None uses the middle of the joint ranges.
            label: How to name the target in an error message.

        Returns:
            The choice.

        Raises:
            InvalidArgumentError: If no solution within the joint limits exists (the message
                carries the solver's reason).
        """
        ref = self._home if q_previous is None else np.asarray(q_previous, dtype=float)
        sols, reason = self.candidates(target, ref, nearest=True)
        if not sols:
            raise InvalidArgumentError(
                f"{label} at position {np.round(target.position, 6).tolist()} m has no IK solution within the joint "
                f"limits of {self.robot.name} ({reason})"
            )
        scored = []
        for q, branch in sols:
            ic = self._inverse_condition(q)
            scored.append((ic < self.threshold, float(np.linalg.norm(q - ref)), q, branch, ic))
        scored.sort(key=lambda s: (s[0], s[1]))
        singular, _, q, branch, ic = scored[0]
        return IKChoice(
            q=_ro(q),
            branch=branch,
            singular=bool(singular),
            inverse_condition=ic,
            alternatives=len(sols) - 1,
            position_error=self._error(target, q),
        )

    def track(self, target: Target, q_previous: np.ndarray) -> np.ndarray | None:
        """The solution nearest `q_previous` (continuation along a path), or None."""
        sols, _ = self.candidates(target, q_previous)
        if not sols:
            return None
        return min((q for q, _ in sols), key=lambda q: float(np.linalg.norm(q - q_previous)))


def _ro(a: np.ndarray) -> np.ndarray:
    out = np.array(a, dtype=float, copy=True)
    out.setflags(write=False)
    return out


def _slerp(ra: np.ndarray, rb: np.ndarray, s: float) -> np.ndarray:
    """Rotation a fraction s of the way from ra to rb (about their relative axis)."""
    rel = ra.T @ rb
    angle = math.acos(max(-1.0, min(1.0, (np.trace(rel) - 1.0) / 2.0)))
    if angle < 1e-12:
        return ra.copy()
    if math.pi - angle < 1e-6:
        # Axis from the symmetric part when the rotation is (close to) half a turn.
        w, v = np.linalg.eigh((rel + rel.T) / 2.0)
        axis = v[:, int(np.argmax(w))]
    else:
        axis = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]]) / (2.0 * math.sin(angle))
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    th = s * angle
    return ra @ (np.eye(3) + math.sin(th) * k + (1 - math.cos(th)) * (k @ k))


def interpolate_target(a: Target, b: Target, s: float) -> Target:
    """The target a fraction s in [0, 1] of the way along the straight line from a to b."""
    pos = (1.0 - s) * a.position + s * b.position
    if b.rotation is not None:
        if a.rotation is None:
            raise InvalidArgumentError("a line to a target with an orientation must start at one with an orientation")
        return Target(pos, rotation=_slerp(a.rotation, b.rotation, s))
    if b.pitch is not None:
        if a.pitch is None:
            raise InvalidArgumentError("a line to a target with an approach pitch must start at one with a pitch")
        return Target(pos, pitch=(1.0 - s) * a.pitch + s * b.pitch)
    return Target(pos)


@dataclass(frozen=True)
class LinePath:
    """Joint configurations along a straight Cartesian line.

    Attributes:
        s: Fractions of the way along the line, shape (M,), 0 first and 1 last.
        q: Joint values at each, shape (M, dof) [rad or m].
        points: Tip positions asked for, shape (M, 3) [m].
        max_position_error: Largest FK distance of the samples to their points [m].
        min_inverse_condition: Smallest inverse condition number among the samples.
    """

    s: np.ndarray
    q: np.ndarray
    points: np.ndarray
    max_position_error: float
    min_inverse_condition: float


def line_waypoints(
    solver: TargetSolver,
    start: Target,
    end: Target,
    q_start: np.ndarray,
    *,
    max_step: float = 0.005,
    max_joint_step: float = 0.02,
    min_step: float = 1e-5,
) -> LinePath:
    """Sample a straight line from `start` to `end` into a continuous joint path.

    Args:
        solver: IK for the robot.
        start: Target at the start of the line (its configuration is `q_start`).
        end: Target at its end.
        q_start: Joint values at the start, shape (dof,).
        max_step: Longest line step between samples [m].
        max_joint_step: Largest joint change between neighbouring samples [rad or m]; longer
            steps are bisected.
        min_step: Shortest line step bisection goes down to [m].

    Returns:
        The joint path (the last configuration solves `end`).

    Raises:
        InvalidArgumentError: If IK fails somewhere on the line or the joint path cannot be made
            continuous (the line leaves the workspace or crosses a branch boundary).
    """
    for name, val in (("max_step", max_step), ("max_joint_step", max_joint_step), ("min_step", min_step)):
        if not (isinstance(val, (int, float)) and math.isfinite(val) and val > 0):
            raise InvalidArgumentError(f"{name} must be positive, got {val!r}")
    length = float(np.linalg.norm(end.position - start.position))
    n0 = max(1, int(math.ceil(length / max_step)))
    q0 = np.asarray(q_start, dtype=float)
    s_list, q_list = [0.0], [q0]

    def solve_at(s: float, q_prev: np.ndarray) -> np.ndarray:
        q = solver.track(interpolate_target(start, end, s), q_prev)
        if q is None:
            p = (1.0 - s) * start.position + s * end.position
            a, b, near = (np.round(x, 6).tolist() for x in (start.position, end.position, p))
            raise InvalidArgumentError(
                f"the straight line from {a} to {b} m leaves what {solver.robot.name} can reach "
                f"within its joint limits near {near} m"
            )
        return q

    for k in range(1, n0 + 1):
        s_target = k / n0
        stack = [s_target]
        while stack:
            s_next = stack[-1]
            q_next = solve_at(s_next, q_list[-1])
            if (
                float(np.max(np.abs(q_next - q_list[-1]))) > max_joint_step
                and (s_next - s_list[-1]) * length > min_step
            ):
                stack.append((s_list[-1] + s_next) / 2.0)
                continue
            s_list.append(s_next)
            q_list.append(q_next)
            stack.pop()
    q = np.array(q_list)
    s = np.array(s_list)
    points = (1.0 - s)[:, None] * start.position + s[:, None] * end.position
    err = float(np.max(np.linalg.norm(solver.robot.position(q) - points, axis=1)))
    jumps = np.max(np.abs(np.diff(q, axis=0)), axis=1)
    if np.any(jumps > 10 * max_joint_step):
        k = int(np.argmax(jumps))
        raise InvalidArgumentError(
            f"the straight line to {np.round(end.position, 6).tolist()} m needs a jump of {jumps[k]:.3g} rad in the "
            f"joints near {np.round(points[k], 6).tolist()} m (a branch change at a singularity); split the line there"
        )
    inv = conditioning(solver.robot, q, solver.task)[0]
    return LinePath(_ro(s), _ro(q), _ro(points), err, float(np.min(inv)))


def line_deviation(robot: Robot, q: np.ndarray, start: np.ndarray, end: np.ndarray) -> float:
    """Largest distance of the tip positions of configurations q (M, dof) from the segment start-end [m]."""
    p = robot.position(q)
    d = np.asarray(end, dtype=float) - np.asarray(start, dtype=float)
    length2 = float(d @ d)
    if length2 == 0.0:
        return float(np.max(np.linalg.norm(p - start, axis=1)))
    s = np.clip((p - start) @ d / length2, 0.0, 1.0)
    return float(np.max(np.linalg.norm(p - (start + s[:, None] * d), axis=1)))


@dataclass(frozen=True)
class LineTiming:
    """When and how fast a line's samples are passed (start and end at rest).

    Attributes:
        t: Time at each sample, shape (M,) [s], from 0.
        velocity: Joint velocities there, shape (M, dof).
        acceleration: Joint accelerations there, shape (M, dof).
        path_limits: The limits ``(v, a, j)`` of the path parameter (see :func:`time_line`).
    """

    t: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    path_limits: tuple[float, float, float]


def _local_cubic_derivatives(x: np.ndarray, y: np.ndarray, half: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First three derivatives of y(x) from least-squares cubics over 2*half+1 neighbours.

    Plain finite differences of bisected, unevenly spaced IK samples are too noisy for second
    and third derivatives; a local cubic fit smooths them.
    """
    n = len(x)
    d1, d2, d3 = np.empty_like(y), np.empty_like(y), np.empty_like(y)
    for k in range(n):
        lo, hi = max(0, k - half), min(n, k + half + 1)
        if hi - lo < 4:
            lo, hi = max(0, min(lo, n - 4)), min(n, max(hi, lo + 4))
        h = x[lo:hi] - x[k]
        sc = max(float(np.max(np.abs(h))), 1e-12)
        deg = min(3, hi - lo - 1)
        coef, *_ = np.linalg.lstsq(np.vander(h / sc, deg + 1, increasing=True), y[lo:hi], rcond=None)
        coef = np.vstack([coef, np.zeros((4 - len(coef), y.shape[1]))])
        d1[k], d2[k], d3[k] = coef[1] / sc, 2 * coef[2] / sc**2, 6 * coef[3] / sc**3
    return d1, d2, d3


def time_line(path: LinePath, limits: JointLimits) -> LineTiming:
    """Time a line's joint path within the joints' speed, acceleration and jerk limits.

    The path is re-parametrised by sigma in [0, 1], advancing in proportion to the
    speed-normalised joint motion ``|dq / v_max|`` of each step; one jerk-limited Ruckig
    profile of sigma (rest to rest) is chosen with path limits that keep every joint's
    velocity, acceleration and jerk (estimated from local cubic fits of q(sigma)) within its
    limits. Where the line passes near a singularity the joints move far per metre, sigma
    advances quickly per metre, and the tip slows down accordingly.

    Args:
        path: Joint samples of the line.
        limits: Joint limits.

    Returns:
        Times and joint states at the samples.
    """
    from ruckig import InputParameter, Ruckig
    from ruckig import Trajectory as RuckigTrajectory

    q = np.asarray(path.q)
    vmax, amax, jmax = limits.velocity, limits.acceleration, limits.jerk
    steps = np.linalg.norm(np.diff(q, axis=0) / vmax, axis=1)
    total = float(steps.sum())
    m = len(q)
    if total <= 0.0:
        z = np.zeros_like(q)
        return LineTiming(_ro(np.zeros(m)), _ro(z), _ro(z), (0.0, 0.0, 0.0))
    sigma = np.concatenate([[0.0], np.cumsum(steps)]) / total
    d1, d2, d3 = _local_cubic_derivatives(sigma, q)
    big1, big2, big3 = (np.max(np.abs(d), axis=0) for d in (d1, d2, d3))
    big1 = np.maximum(big1, 1e-12)
    best = None
    otg, inp = Ruckig(1), InputParameter(1)
    inp.current_position, inp.target_position = [0.0], [1.0]
    for c in (1.0, 0.8, 0.6, 0.45, 0.3, 0.2, 0.12, 0.07, 0.04, 0.02, 0.01):
        v = c * float(np.min(vmax / big1))
        a_room = float(np.min((amax - big2 * v * v) / big1))
        if a_room <= 0:
            continue
        for fa in (1.0, 0.7, 0.5, 0.3):
            a = fa * a_room
            j = float(np.min((jmax - big3 * v**3 - 3.0 * big2 * v * a) / big1))
            if j <= 0:
                continue
            inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v], [a], [j]
            traj = RuckigTrajectory(1)
            otg.calculate(inp, traj)
            if best is None or traj.duration < best[0]:
                best = (traj.duration, traj, (v, a, j))
    if best is None:  # pragma: no cover - small enough path limits always fit
        raise InvalidArgumentError("cannot time the line within the joint limits")
    _, traj, plims = best
    t = np.empty(m)
    for k, sg in enumerate(sigma):
        found = None if k in (0, m - 1) else traj.get_first_time_at_position(0, float(sg))
        t[k] = 0.0 if k == 0 else traj.duration if k == m - 1 else (t[k - 1] if found is None else found)
    states = [traj.at_time(float(tk)) for tk in t]
    sd = np.array([st[1][0] for st in states])
    sdd = np.array([st[2][0] for st in states])
    vel = d1 * sd[:, None]
    acc = d2 * (sd * sd)[:, None] + d1 * sdd[:, None]
    vel[0] = vel[-1] = acc[0] = acc[-1] = 0.0
    return LineTiming(_ro(t), _ro(np.clip(vel, -vmax, vmax)), _ro(np.clip(acc, -amax, amax)), plims)
