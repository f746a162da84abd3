"""One entry point for inverse kinematics: :func:`solve_ik`.

``method`` picks the solver: ``"analytic"`` (the closed form of :mod:`planner.ik.analytic`, for
the seed arms' families), ``"nlp"`` (:class:`~planner.ik.numeric.solver.NlpIK`, any URDF) or
``"auto"`` (the closed form where the arm and target kind have one, else the NLP). Whatever the
method, the answer is one :class:`~planner.ik.result.IKResult`: the chosen configuration with
its errors by Pinocchio FK, and every solution found (closed-form branches or the NLP's distinct
answers), each marked within the joint limits or not, nearest to the seed first.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from typing import Literal

import numpy as np
import pinocchio as pin

from planner.collision.checker import CollisionChecker
from planner.exceptions import InvalidArgumentError, UnsupportedChainError
from planner.geometry.joint_space import angular_joints, wrapped_distance
from planner.geometry.target import Target, as_target, target_errors, tip_errors
from planner.ik.analytic import AnalyticIK, AnalyticResult
from planner.ik.analytic.nearest import NearestSolution
from planner.ik.options import IKOptions
from planner.ik.result import IKResult, IKSolution, LazySolutions
from planner.ik.solvers import IKSolvers
from planner.ik.status import IKStatus
from planner.ik.task import task_rank
from planner.model.robot import Robot

__all__ = ["IK_METHODS", "IKMethod", "closed_form_answer", "solve_analytic", "solve_ik"]

IKMethod = Literal["auto", "analytic", "nlp"]
#: The methods :func:`solve_ik` accepts.
IK_METHODS: tuple[str, ...] = ("auto", "analytic", "nlp")

_DEFAULT_OPTIONS = IKOptions()


def solve_ik(
    robot: Robot,
    target: Target | Sequence[float] | np.ndarray,
    q_seed: Sequence[float] | np.ndarray | None = None,
    *,
    method: IKMethod = "auto",
    options: IKOptions | None = None,
    checker: CollisionChecker | None = None,
    allow: Sequence[str] = (),
) -> IKResult:
    """Joint values that put the tip on a target, by closed form or numerically.

    Args:
        robot: The robot.
        target: A :class:`~planner.geometry.target.Target`, a position (3,) [m] or a pose
            (4, 4) [m].
        q_seed: Current or starting configuration (dof,) [rad or m], within the limits; the
            solutions are sorted by distance to it, and the NLP starts from it.
        method: ``"analytic"``, ``"nlp"``, or ``"auto"``: the closed form where the arm and the
            target kind have one, else the NLP; and the NLP (started from the seed and the
            branches) also when every closed-form branch lies outside the joint limits and the
            arm is redundant for the target (the closed form searches the free joints on its
            ideal geometry, so a solution at the very edge of the limits can escape it).
        options: Tolerances and NLP settings (:class:`~planner.ik.options.IKOptions`); None for
            the defaults.
        checker: A :class:`~planner.collision.checker.CollisionChecker` (the robot's scene):
            every solution gets its ``clearance``; the answer is the nearest solution that keeps
            the scene's clearance; when none does, the NLP restarts from other seeds, and the
            result is ``"in_collision"`` if it finds none either. None checks nothing.
        allow: Scene bodies the arm may touch (with `checker`).

    Returns:
        The result; an unreachable target is a result with ``success=False``, a ``status`` and
        a ``reason``. ``method`` says which solver answered.

    Raises:
        InvalidArgumentError: On an unknown method, a bad target or options.
        UnsupportedChainError: For ``"analytic"`` on an arm or target kind without a closed form.
        InvalidConfigurationError: If `q_seed` has the wrong length or NaN values.
        JointLimitError: If `q_seed` is outside the joint limits.
    """
    start = time.perf_counter()
    result = _solve(robot, target, q_seed, method, options, start)
    if checker is None:
        return result
    if checker.robot is not robot:
        raise InvalidArgumentError("the collision checker is for another robot")
    return _collision_free(robot, as_target(target), result, checker, allow, options or _DEFAULT_OPTIONS, start)


#: NLP restarts from other seeds when every solution found collides.
COLLISION_RESTARTS = 8


def _collision_free(
    robot: Robot,
    target: Target,
    result: IKResult,
    checker: CollisionChecker,
    allow: Sequence[str],
    options: IKOptions,
    start: float,
) -> IKResult:
    """The result with each solution's clearance, its answer the nearest one that keeps it."""
    mask = checker.pair_mask(allow)
    tolerances = (options.position_tolerance, options.orientation_tolerance)

    def usable(s: IKSolution) -> bool:
        return (
            s.within_limits
            and s.position_error <= tolerances[0]
            and s.orientation_error <= tolerances[1]
            and s.clearance is not None
            and s.clearance >= checker.scene.clearance
        )

    sols = [dataclasses.replace(s, clearance=checker.distance_at(s.q, mask).distance) for s in result.solutions]
    found = next((s for s in sols if usable(s)), None) if result.success else None
    if found is None and result.success:
        # Restart the NLP from seeds drawn with a fixed generator (the same answer every call).
        solvers = IKSolvers.of(robot)
        rng = np.random.default_rng(0)
        for seed in robot.random_configurations(rng, COLLISION_RESTARTS):
            more = solvers.nlp.solve(target, seed, dataclasses.replace(options, closed_form_seeds=False))
            extra = [dataclasses.replace(s, clearance=checker.distance_at(s.q, mask).distance) for s in more.solutions]
            sols += extra
            found = next((s for s in extra if usable(s)), None)
            if found is not None:
                break
    wall = time.perf_counter() - start
    if found is not None:
        reason = (
            result.reason
            if np.array_equal(found.q, result.q)
            else f"the nearest collision-free solution ({found.label})"
        )
        return dataclasses.replace(
            result,
            q=found.q,
            position_error=found.position_error,
            orientation_error=found.orientation_error,
            reason=reason,
            solutions=tuple(sols),
            wall_time=wall,
        )
    if not result.success:
        return dataclasses.replace(result, solutions=tuple(sols), wall_time=wall)
    closest = checker.distance_at(result.q, mask)
    return dataclasses.replace(
        result,
        success=False,
        status=IKStatus.IN_COLLISION,
        reason=f"every solution found collides or comes closer than the clearance; the answer's: {closest}",
        solutions=tuple(sols),
        wall_time=wall,
    )


def _solve(
    robot: Robot,
    target: Target | Sequence[float] | np.ndarray,
    q_seed: Sequence[float] | np.ndarray | None,
    method: str,
    options: IKOptions | None,
    start: float,
) -> IKResult:
    if method not in IK_METHODS:
        raise InvalidArgumentError(f"unknown IK method {method!r}; valid: {', '.join(IK_METHODS)}")
    if options is None:
        options = _DEFAULT_OPTIONS
    elif not isinstance(options, IKOptions):
        raise InvalidArgumentError(f"options must be a planner.IKOptions, got {type(options).__name__}")
    if not isinstance(robot, Robot):
        raise InvalidArgumentError(f"solve_ik needs a planner.Robot, got {type(robot).__name__}")
    target = as_target(target)
    solvers = IKSolvers.of(robot)
    if method == "nlp":
        return _numeric(solvers, target, q_seed, options)  # NlpIK.solve checks the seed
    seed = solvers.nlp.check_seed(q_seed)
    analytic = solvers.require_analytic() if method == "analytic" else solvers.analytic
    if analytic is None:
        return _numeric(solvers, target, seed, options)
    try:
        nearest = analytic.nearest(target, seed)
        if nearest is not None and (answer := _nearest_answer(robot, analytic, target, nearest, seed, options, start)):
            return answer
        family = analytic.solve(target, seed)
    except UnsupportedChainError:
        if method == "analytic":
            raise
        return _numeric(solvers, target, seed, options)
    answer = closed_form_answer(robot, target, family, seed, options, start)
    # Where the arm is redundant for the target, the closed form's search of the free joints may
    # miss a solution at the very edge of the limits: "auto" asks the NLP too.
    if (
        method == "analytic"
        or answer.success
        or answer.status != IKStatus.OUTSIDE_JOINT_LIMITS
        or task_rank(robot, target, answer.solutions[0].q) == robot.dof
    ):
        return answer
    fallback = _numeric(solvers, target, seed, options, extra=np.array([s.q for s in answer.solutions]))
    if not fallback.success:
        return dataclasses.replace(answer, wall_time=time.perf_counter() - start)
    return dataclasses.replace(
        fallback, solutions=fallback.solutions + answer.solutions, wall_time=time.perf_counter() - start
    )


def _numeric(
    solvers: IKSolvers,
    target: Target,
    seed: Sequence[float] | np.ndarray | None,
    options: IKOptions,
    extra: np.ndarray | None = None,
) -> IKResult:
    """The NLP's answer, started from the seed and (by default) the closed-form branches.

    The seed is checked by the NLP. With a seed, the branches are computed only when the NLP
    asks for them: when its first searches (from the seed) miss the target, or when the
    solutions are read.
    """
    if extra is None and options.closed_form_seeds and solvers.analytic is not None:
        analytic = solvers.analytic

        def branches() -> np.ndarray | None:
            try:
                found = analytic.solve(target, solvers.nlp.check_seed(seed)).solutions
            except UnsupportedChainError:
                return None
            return np.array([s.q for s in found], dtype=float) if found else None

        return solvers.nlp.solve(target, seed, options, extra_seeds=branches if seed is not None else branches())
    return solvers.nlp.solve(target, seed, options, extra_seeds=extra)


class _TipCheck:
    """What verifying closed-form answers by Pinocchio FK needs of one robot, looked up once.

    Kept in ``robot.derived``: a call of a few microseconds should not pay for finding the
    joint kinds, the model and the tip frame again.
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.model, self.data, self.frame = robot.model, robot.data, robot.tip_frame_id
        # Pinocchio takes q as it is unless a continuous joint needs (cos, sin): then Robot.tip_pose.
        self.direct = "continuous" not in robot.joint_kinds
        self.axis = robot.approach_axis
        self.angular = angular_joints(robot)
        self.all_angular = all(self.angular)

    def errors(self, target: Target, q: np.ndarray) -> tuple[float, float]:
        """Position [m] and orientation [rad] errors of ``q`` by Pinocchio FK (:func:`tip_errors`)."""
        if self.direct:
            pin.forwardKinematics(self.model, self.data, q)
            placement = pin.updateFramePlacement(self.model, self.data, self.frame)
            if target.rotation is None and target.pitch is None:
                (x, y, z), (tx, ty, tz) = placement.translation.tolist(), target.position.tolist()
                return math.hypot(x - tx, y - ty, z - tz), 0.0
            return tip_errors(target, placement.translation, placement.rotation, self.axis)
        position, rotation = self.robot.tip_pose(q)
        return tip_errors(target, position, rotation, self.axis)

    def distances(self, solutions: Sequence, seed: np.ndarray) -> list[float]:
        """:func:`wrapped_distance` of each solution's ``q`` to the seed, on Python floats."""
        reference = seed.tolist()
        if not self.all_angular:
            return [wrapped_distance(sol.q.tolist(), reference, self.angular) for sol in solutions]
        pi, two_pi, sqrt = math.pi, _TWO_PI, math.sqrt
        out = []
        for sol in solutions:
            total = 0.0
            for a, b in zip(sol.q.tolist(), reference):
                d = (a - b + pi) % two_pi - pi
                total += d * d
            out.append(sqrt(total))
        return out


_TWO_PI = 2.0 * math.pi


def _nearest_answer(
    robot: Robot,
    analytic: AnalyticIK,
    target: Target,
    nearest: NearestSolution,
    seed: np.ndarray | None,
    options: IKOptions,
    start: float,
) -> IKResult | None:
    """:func:`closed_form_answer` of the family's result, from its nearest solution (None if that misses).

    The family picked the solution :func:`closed_form_answer` tries first (without building
    its result); when Pinocchio FK confirms it, it is that function's answer, else None (the
    caller builds the result and tries the others). The other solutions are computed when read.
    """
    check = robot.derived.get(_TipCheck, lambda: _TipCheck(robot))
    q = np.array(nearest.q)
    position_error, orientation_error = check.errors(target, q)
    if position_error > options.position_tolerance or orientation_error > options.orientation_tolerance:
        return None
    family: list[AnalyticResult] = []  # the whole result, built once when read

    def raw() -> tuple:
        if not family:
            family.append(analytic.solve(target, seed))
        return family[0].solutions

    def counts() -> tuple[int, int]:
        found = raw()
        return len(found), next(i for i, sol in enumerate(found) if sol.branch == nearest.branch)

    solutions = LazySolutions(lambda: _every_solution(check, target, raw(), seed, {}))
    return IKResult.from_solver(
        q, True, IKStatus.SOLVED, f"closed-form branch {nearest.branch}", position_error, orientation_error, 0,
        nearest.count, nearest.index, "closed_form", time.perf_counter() - start, "analytic", solutions,
        None if nearest.count is not None else counts,
    )  # fmt: skip


def _every_solution(
    check: _TipCheck, target: Target, raw: Sequence, seed: np.ndarray | None, errors: dict[int, tuple[float, float]]
) -> tuple[IKSolution, ...]:
    """Every solution of a family's result, nearest to the seed first, with its errors by Pinocchio FK.

    `errors` holds the errors already computed, by index in `raw` (filled in here).
    """

    def solution(i: int, distance: float | None) -> IKSolution:
        sol = raw[i]
        error = errors.get(i)
        if error is None:
            error = errors[i] = check.errors(target, sol.q)
        return IKSolution(sol.q, sol.within_limits, sol.branch, *error, distance, sol.singular)

    if seed is None or not raw:
        return tuple(solution(i, None) for i in range(len(raw)))
    distances = check.distances(raw, seed)
    return tuple(solution(i, distances[i]) for i in sorted(range(len(raw)), key=distances.__getitem__))


def closed_form_answer(
    robot: Robot,
    target: Target,
    family: AnalyticResult,
    seed: np.ndarray | None,
    options: IKOptions,
    start: float,
) -> IKResult:
    """The :class:`IKResult` of a closed-form family's answer, errors by Pinocchio FK.

    The chosen solution is the nearest to the seed (the family's order otherwise) that lies
    within the limits and reaches the target by Pinocchio FK within the tolerances.

    Args:
        robot: The robot.
        target: The target solved.
        family: The family solver's raw answer (every branch).
        seed: The checked seed, or None.
        options: The tolerances.
        start: ``time.perf_counter()`` at the start of the call.

    Returns:
        The result (``method="analytic"``). Without a solution within the limits, ``q`` is the
        seed (or the configuration nearest zero within the limits) and ``status`` is the
        family's; with solutions within the limits that all miss the target by Pinocchio FK,
        ``status`` is ``"inaccurate"``.
    """
    check = robot.derived.get(_TipCheck, lambda: _TipCheck(robot))
    raw = family.solutions
    # The solutions within the limits, nearest to the seed first (a stable sort: the family's
    # order among equal distances, as in the sorted list of all solutions, built when read).
    within = [i for i, sol in enumerate(raw) if sol.within_limits]
    if seed is not None and len(within) > 1:
        near = check.distances([raw[i] for i in within], seed)
        within = [within[k] for k in sorted(range(len(within)), key=near.__getitem__)]
    errors: dict[int, tuple[float, float]] = {}
    position_tolerance, orientation_tolerance = options.position_tolerance, options.orientation_tolerance
    index = None
    first = within[0] if within else None
    for i in within:
        position_error, orientation_error = errors[i] = check.errors(target, raw[i].q)
        if position_error <= position_tolerance and orientation_error <= orientation_tolerance:
            index = i
            break

    solutions = LazySolutions(lambda: _every_solution(check, target, raw, seed, errors))
    if index is not None:
        position_error, orientation_error = errors[index]
        return IKResult.from_solver(
            raw[index].q.copy(), True, IKStatus.SOLVED, f"closed-form branch {raw[index].branch}", position_error,
            orientation_error, 0, len(raw), index, "closed_form", time.perf_counter() - start, "analytic", solutions,
        )  # fmt: skip
    if first is not None:
        position_error, orientation_error = errors[first]
        q, status = raw[first].q.copy(), IKStatus.INACCURATE
        reason = (
            f"the closed-form solution ({raw[first].branch}) misses the target by {position_error:.3g} m and "
            f"{orientation_error:.3g} rad by Pinocchio FK"
        )
    else:
        q = seed.copy() if seed is not None else np.clip(np.zeros(robot.dof), robot.lower, robot.upper)
        status, reason = IKStatus(family.status), family.reason
        position_error, orientation_error = target_errors(robot, target, q)
    return IKResult(
        q=q,
        success=False,
        status=status,
        reason=reason,
        position_error=position_error,
        orientation_error=orientation_error,
        iterations=0,
        attempts=len(raw),
        attempt=None,
        attempt_kind=None,
        wall_time=time.perf_counter() - start,
        method="analytic",
        solutions=solutions,
    )


def solve_analytic(
    robot: Robot, target: Target | Sequence[float] | np.ndarray, q_current: Sequence[float] | np.ndarray | None = None
) -> IKResult:
    """Closed-form IK: ``solve_ik(robot, target, q_current, method="analytic")``.

    Kept for earlier users; it returns an :class:`IKResult` (every branch in ``solutions``).

    Raises:
        UnsupportedChainError: If the arm or target kind has no closed form.
    """
    return solve_ik(robot, target, q_current, method="analytic")
