"""Numerical inverse kinematics for any URDF chain, built on CasADi: :class:`NlpIK`.

How :meth:`NlpIK.solve` works:

0. **First stage: searches one after another in one compiled call**
   (:class:`~planner.ik.numeric.kernel.SequentialKernel`), without secondary objectives and
   when a seed or extra seeds are given: from the caller's seed, then the extra seeds, then
   random configurations (of each group of 16 in a fixed pool, the one whose tip pose is
   nearest the target), 33 starts in all, each search at most 16 Levenberg-Marquardt steps
   with light damping (``1e-6 + 0.03 |r|^2``) and steps up to 1.5 rad (a search still far from
   the target after 4 or 8 steps gives way to the next start), stopping at the first that
   converges. Most targets are reached from the seed in a few steps, so a call costs one
   short search, one Pinocchio FK and the result. The angles are shifted by whole turns
   towards the seed in the same compiled call. Only when none of these reaches the target do
   the batches below run (and only then are extra seeds given as a function computed).
1. **Batched damped Gauss-Newton in one compiled CasADi function**
   (:class:`~planner.ik.numeric.kernel.Kernel`; compiled and cached on disk by
   :mod:`planner.ik.numeric.codegen`): Levenberg-Marquardt steps clamped into the joint limits,
   so every iterate and every returned ``q`` lies within the limits, mapped over a batch of
   seeds (8 by default); the batch stops as soon as one seed has converged. A batch tries, in
   order: the caller's seed, any extra seeds given (e.g. the closed-form branches), then random
   configurations within the limits.
2. **Restarts.** While no attempt has reached the target, further batches run, until the
   caller's time budget [s] or attempt cap is used up: fresh random seeds, plus the two best
   attempts of the last batch when they are still converging (slow convergence near a
   singularity), with the orientation weight varied from batch to batch (0.25, 0.5, 0.12 of
   the chain length), which varies the basins of attraction. The attempt that succeeded and
   its kind (``"seed"``, ``"closed_form"``, ``"random"``) are reported; attempts count the
   first stage's searches too.
3. **Secondary objectives.** With ``near_seed=True`` or a manipulability floor, the batch runs
   to the end, its converged solutions are compared (nearest to the seed; above the floor)
   and, where the arm is redundant for the target, IPOPT moves along the redundancy
   (:class:`~planner.ik.numeric.polish.Polisher`).

Every answer is verified with Pinocchio: the errors in an :class:`IKResult` are Pinocchio's
forward kinematics against the target, not the solver's own residual.

``IKResult.solutions`` lists the distinct answers the batches found within the tolerances
(distinct: joint distance above :data:`DISTINCT`, angles modulo 2 pi; of near-duplicates the
chosen answer, else the most converged one, is kept), labelled with their attempt's kind,
nearest to the seed first (without a seed, smallest error first). They come from the batch
that reached the target (and, with secondary objectives, from every batch run): each further
distinct answer costs one Pinocchio FK, nothing else is recomputed. When the first stage
answered, one batch from the seed, the extra seeds and random starts runs to its end when the
solutions are first read, and its distinct answers follow the first stage's. All lie within
the limits.
"""

from __future__ import annotations

import math
import operator
import time
from collections.abc import Callable, Sequence

import numpy as np
import pinocchio as pin

from planner.core.arrays import read_only
from planner.core.text import plain
from planner.exceptions import InvalidArgumentError, InvalidConfigurationError
from planner.geometry.joint_space import angular_joints, configurations_close, wrapped_distance
from planner.geometry.target import Target, as_target, tip_errors
from planner.geometry.target_batch import BatchTargets
from planner.ik.numeric.batch import BatchIK
from planner.ik.numeric.batch_result import BatchIKResult
from planner.ik.numeric.kernel import (
    KERNEL_KINDS,
    SEARCH_DAMPING,
    SEARCH_MAX_STEP,
    Kernel,
    SequentialKernel,
)
from planner.ik.numeric.kinematics import CasadiKinematics
from planner.ik.numeric.polish import Polisher
from planner.ik.options import IKOptions
from planner.ik.result import IKResult, IKSolution, LazySolutions
from planner.ik.status import IKStatus
from planner.model.robot import Robot

__all__ = ["ATTEMPT_KINDS", "DISTINCT", "NlpIK"]

#: Where an attempt's starting configuration came from, in the order they are tried.
ATTEMPT_KINDS = ("seed", "closed_form", "random")

#: Orientation weights of successive batches, times the chain length: varying the weighting
#: varies the basins of attraction, which helps arms with fewer joints than the task.
_SCALES = (0.25, 0.5, 0.12)
_RANDOM_POOL = 64  # random seeds drawn once per solver for calls without an rng (times the batch size)
#: The first stage: searches one after another (the seed, the extra seeds, then random starts),
#: each at most _SEARCH_CHUNKS chunks of _SEARCH_CHUNK steps, with lighter damping and longer
#: steps than the batches (it converges in fewer steps from most starts); see _GIVE_UP. Chosen
#: on the cost histories of 300 random pose targets and 16 starts each on ur5 and panda (fewest
#: steps per target: median, p95 and mean).
_SEARCHES = 33  # the seed's search and 4 blocks of 8 (planner.ik.numeric.kernel)
_SEARCH_CHUNK = 4
_SEARCH_CHUNKS = 4
#: (chunks, share of the chain length): a search whose residual is still above that share of
#: the chain length after that many chunks gives way to the next start.
_GIVE_UP = ((1, 0.24), (2, 0.03))
_DEFAULT_OPTIONS = IKOptions()
_PLANS = 64  # options objects whose plan is kept at most
#: Joint distance [rad, m mixed; angles modulo 2 pi] at or below which two answers are one solution.
DISTINCT = 1e-4


def _finite_bounds(values: np.ndarray) -> np.ndarray:
    """Limits with infinite values replaced by +-1e20 (what CasADi and IPOPT take as none)."""
    return np.where(np.isfinite(values), values, np.sign(values) * 1e20)


class NlpIK:
    """Numerical IK for one robot: batched compiled damped Gauss-Newton, restarts, IPOPT.

    Build one per robot and reuse it: the symbolic model is built in the constructor and each
    target kind's compiled solver once, on first use (:meth:`prepare` builds them ahead).
    Not thread-safe (it owns its buffers and a Pinocchio workspace).

    Attributes:
        robot: The robot.
        kinematics: Its symbolic kinematics.
        batch_size: Seeds per batch (per call of the compiled function).
        iterations_per_batch: Gauss-Newton steps per seed and batch at most.
        length: Summed link offsets of the chain [m]; the orientation rows of the residual are
            weighted by a fraction of it (0.25, then 0.5, 0.12 in later batches).
    """

    def __init__(
        self,
        robot: Robot,
        *,
        batch_size: int = 8,
        chunk: int = 5,
        max_chunks: int = 10,
        max_step: float = 0.6,
        jit: bool = True,
    ) -> None:
        """Build the solver.

        Args:
            robot: The robot.
            batch_size: Seeds per batch.
            chunk: Gauss-Newton steps between two convergence checks.
            max_chunks: Chunks per batch at most (``chunk * max_chunks`` steps per seed).
            max_step: Longest joint step of one iteration [rad or m].
            jit: Compile the batched solver to C (cached on disk; see :mod:`planner.ik.numeric.codegen`).

        Raises:
            InvalidArgumentError: If a size is not a positive integer or `max_step` is not > 0.
            UnsupportedChainError: If a chain joint is not a one-axis rotation or translation.
        """
        if not isinstance(robot, Robot):
            raise InvalidArgumentError(f"NlpIK needs a planner.Robot, got {type(robot).__name__}")
        for label, value in (("batch_size", batch_size), ("chunk", chunk), ("max_chunks", max_chunks)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise InvalidArgumentError(f"{label} must be a positive integer, got {plain(value)}")
        if isinstance(max_step, bool) or not isinstance(max_step, (int, float)) or not 0 < max_step < math.inf:
            raise InvalidArgumentError(f"max_step must be a positive number [rad or m], got {plain(max_step)}")
        self.robot = robot
        self.kinematics = CasadiKinematics(robot)
        self.batch_size = int(batch_size)
        self.iterations_per_batch = int(chunk) * int(max_chunks)
        self._chunk, self._max_chunks, self._max_step, self._jit = int(chunk), int(max_chunks), float(max_step), jit
        self._lower = _finite_bounds(robot.lower)
        self._upper = _finite_bounds(robot.upper)
        self._lower_list, self._upper_list = self._lower.tolist(), self._upper.tolist()
        self._continuous = np.array([k == "continuous" for k in robot.joint_kinds], dtype=bool)
        self._has_continuous = bool(self._continuous.any())
        self._q_shape = (robot.dof,)
        self._no_seeds = read_only(np.empty((0, robot.dof)))
        self._angular_list = list(angular_joints(robot))
        self.length = self._chain_length()
        self._orientation_weight = 0.25 * self.length  # [m]: ranks attempts by position + weighted orientation error
        self._model = robot.model
        self._data = robot.model.createData()
        self._tip = robot.tip_frame_id
        self._axis = np.array(robot.approach_axis)
        self._idx_q = [robot.model.joints[j].idx_q for j in range(1, robot.model.njoints)]
        self._q_pin = np.zeros(robot.model.nq)
        self._pool = robot.random_configurations(np.random.default_rng(0), _RANDOM_POOL * self.batch_size)
        self._kernels: dict[str, Kernel] = {}
        self._sequential: dict[str, SequentialKernel] = {}
        self._first_kinds: dict[tuple[int, int], list[str]] = {}  # attempt kinds of the first stage
        self._seed_kinds = self._first_kinds[(1, 0)] = ["seed"] + ["random"] * (_SEARCHES - 1)
        self._pooled_from: dict[int, int] = {}  # the first pooled row of each sequential kernel
        self._plans: dict[int, tuple] = {}  # per options object (see _plan)
        self._polisher = Polisher(self.kinematics, self._lower, self._upper)
        self._batch: BatchIK | None = None

    @classmethod
    def from_robot(cls, robot: Robot, **options) -> NlpIK:
        """Build the solver for `robot` (options as for the constructor)."""
        return cls(robot, **options)

    def __repr__(self) -> str:
        return f"NlpIK(robot={self.robot.name!r}, batch_size={self.batch_size})"

    def prepare(self, kinds: Sequence[str] = KERNEL_KINDS) -> NlpIK:
        """Build (and compile, or load from the cache) the solvers of these target kinds now.

        Returns:
            The solver itself.
        """
        for kind in kinds:
            self._kernel(kind)
            self._sequential_kernel(kind)
        return self

    def compiled(self, kind: str = "pose") -> bool:
        """Whether the solver of a target kind runs as compiled C code (builds it if needed)."""
        return self._kernel(kind).compiled

    def _chain_length(self) -> float:
        total = self.kinematics.chain.offsets_length()
        for k, kind in enumerate(self.robot.joint_kinds):
            if kind == "prismatic":
                total += float(max(abs(self._lower[k]), abs(self._upper[k])))
        return total if total > 0 else 1.0

    def _kernel(self, kind: str) -> Kernel:
        kernel = self._kernels.get(kind)
        if kernel is None:
            kernel = Kernel.build(
                self.kinematics,
                kind,
                batch_size=self.batch_size,
                lower=self._lower,
                upper=self._upper,
                chunk=self._chunk,
                max_chunks=self._max_chunks,
                max_step=self._max_step,
                jit=self._jit,
            )
            self._kernels[kind] = kernel
        return kernel

    def _sequential_kernel(self, kind: str) -> SequentialKernel:
        kernel = self._sequential.get(kind)
        if kernel is None:
            pooled = len(self._pool) // (_SEARCHES - 1) * (_SEARCHES - 1)
            poses = np.asarray(self.robot.fk(self._pool[:pooled]))
            kernel = SequentialKernel.build_sequential(
                self.kinematics,
                kind,
                searches=_SEARCHES,
                lower=self._lower,
                upper=self._upper,
                chunk=_SEARCH_CHUNK,
                chunks=_SEARCH_CHUNKS,
                max_step=SEARCH_MAX_STEP,
                damping=SEARCH_DAMPING,
                give_up=tuple((after, (share * self.length) ** 2) for after, share in _GIVE_UP),
                continuous=self._continuous,
                angular=np.array(self._angular_list, dtype=bool),
                pool=self._pool[:pooled],
                pool_poses=np.concatenate([poses[:, :3, 3], poses[:, :3, 0], poses[:, :3, 2]], axis=1),
                jit=self._jit,
            )
            self._sequential[kind] = kernel
        return kernel

    # -------------------------------------------------------------------- Pinocchio checks
    def _pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._has_continuous:
            for k, iq in enumerate(self._idx_q):
                if self._continuous[k]:
                    self._q_pin[iq], self._q_pin[iq + 1] = math.cos(q[k]), math.sin(q[k])
                else:
                    self._q_pin[iq] = q[k]
            q = self._q_pin
        pin.forwardKinematics(self._model, self._data, q)
        placement = pin.updateFramePlacement(self._model, self._data, self._tip)
        return placement.translation, placement.rotation

    def _errors(self, target: Target, q: np.ndarray) -> tuple[float, float]:
        position, rotation = self._pose(q)
        return tip_errors(target, position, rotation, self._axis)

    # -------------------------------------------------------------------- input checks
    def check_seed(self, q_seed: Sequence[float] | np.ndarray | None) -> np.ndarray | None:
        """A seed as a float array (None stays None).

        Raises:
            InvalidConfigurationError: On a wrong length or NaN values.
            JointLimitError: If a joint lies outside its limits (context ``"seed"``).
        """
        if q_seed is None:
            return None
        try:
            q = np.array(q_seed, dtype=float)
        except (TypeError, ValueError):
            q = None
        # Comparisons with the finite bounds also reject NaN and infinite values; the full checks
        # then say what is wrong. (On Python floats: a third of the time of numpy's for a few joints.)
        if (
            q is None
            or q.shape != self._q_shape
            or not all(map(operator.le, self._lower_list, values := q.tolist()))
            or not all(map(operator.le, values, self._upper_list))
        ):
            q = self.robot.check_configuration(q_seed, batch=False)
            self.robot.check_limits(q, context="seed")
        return q

    def _check_extra_seeds(self, extra: Sequence[Sequence[float]] | np.ndarray | None) -> np.ndarray:
        if extra is None:
            return self._no_seeds
        try:
            arr = np.array(extra, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InvalidConfigurationError(f"extra_seeds must be numbers, got {extra!r}") from exc
        if arr.size == 0:
            return self._no_seeds
        if arr.ndim != 2:
            raise InvalidConfigurationError(f"extra_seeds must have shape (M, {self.robot.dof}), got {arr.shape}")
        arr = self.robot.check_configuration(arr)
        return np.clip(arr, self._lower, self._upper)

    def _nearest_turn(self, q: np.ndarray, seed: np.ndarray) -> np.ndarray:
        """``q`` with angles shifted by whole turns towards `seed` where the limits allow (same pose)."""
        if np.all(np.abs(q - seed) <= math.pi):
            return q  # already the nearest equivalent of every angle
        out = q.copy()
        for j, kind in enumerate(self.robot.joint_kinds):
            if kind == "prismatic":
                continue
            turns = round((seed[j] - q[j]) / (2 * math.pi))
            for k in (turns, turns - 1, turns + 1):
                shifted = q[j] + 2 * math.pi * k
                if self._lower[j] <= shifted <= self._upper[j] and abs(shifted - seed[j]) < abs(out[j] - seed[j]):
                    out[j] = shifted
        return out

    def _wrap(self, q: np.ndarray) -> np.ndarray:
        """`q` with its continuous joints wrapped into [-pi, pi), in place; returns `q`."""
        if self._has_continuous:
            q[self._continuous] = (q[self._continuous] + math.pi) % (2 * math.pi) - math.pi
        return q

    # -------------------------------------------------------------------- solving
    def solve(
        self,
        target: Target | Sequence[float] | np.ndarray,
        q_seed: Sequence[float] | np.ndarray | None = None,
        options: IKOptions | None = None,
        *,
        extra_seeds: Sequence[Sequence[float]] | np.ndarray | Callable[[], Sequence | np.ndarray] | None = None,
    ) -> IKResult:
        """Joint values that put the tip on a target.

        Args:
            target: A :class:`Target` (position, pose, or position + approach pitch), a
                position (3,) [m] or a pose (4, 4) [m].
            q_seed: Starting configuration (dof,) [rad or m], tried first; it must lie within
                the joint limits. None: random starts only.
            options: Tolerances, time budget, attempt cap, secondary objectives (``near_seed``
                needs `q_seed`) and the random starts' generator; None: the defaults of
                :class:`~planner.ik.options.IKOptions`. ``closed_form_seeds`` is not read here
                (pass the branches as `extra_seeds`).
            extra_seeds: Further starting configurations (M, dof), tried right after `q_seed`
                and reported as ``"closed_form"`` attempts (meant for the closed-form
                branches); clipped into the limits. Or a function returning them, called
                only when needed: with a `q_seed` and an arm not redundant for the target,
                when the first stage's searches from the seed and random starts do not
                reach the target (or when the solutions are read); else at once.

        Returns:
            The result (status ``SOLVED``, ``NOT_CONVERGED`` or ``BELOW_MANIPULABILITY_FLOOR``,
            with the distinct answers found in ``solutions``); a target not reached is a result
            with ``success=False``.

        Raises:
            InvalidArgumentError: On a NaN/infinite target, a rotation that is not orthonormal,
                options that are not an :class:`IKOptions`, or `near_seed` without a seed.
            InvalidConfigurationError: If a seed has the wrong length or NaN values.
            JointLimitError: If `q_seed` is outside the joint limits.
        """
        start = time.perf_counter()
        if target.__class__ is not Target:
            target = as_target(target)
        seed = self.check_seed(q_seed)
        if options is None:
            options = _DEFAULT_OPTIONS
        plan = self._plans.get(id(options))
        if plan is None or plan[0] is not options:
            plan = self._plan(options)
        _, position_tolerance, orientation_tolerance, max_attempts, secondary, searches, scale, stop, accept = plan
        if options.near_seed and seed is None:
            raise InvalidArgumentError("near_seed=True needs a q_seed to stay near")
        rng = None if options.rng is None else options.generator()
        deferred = None
        if extra_seeds is None:
            extra = self._no_seeds
        elif callable(extra_seeds):
            # Computed only when the first stage misses, except where the arm is redundant for
            # the target: there they come before the random starts, which would move the joints
            # the target leaves free.
            if seed is not None and not self._polisher.redundant(self._polisher.task_kind(target)):
                deferred, extra = extra_seeds, self._no_seeds
            else:
                extra = self._check_extra_seeds(extra_seeds())
        else:
            extra = self._check_extra_seeds(extra_seeds)
        kinds: list[str] = []
        iterations = 0
        best: tuple[float, np.ndarray, float, float] | None = None

        if not secondary and (seed is not None or len(extra)):
            # First stage: one search after another in one compiled call; most targets are
            # reached from the first start.
            kind = target.kind
            quick = self._sequential.get(kind) or self._sequential_kernel(kind)
            quick.set_target(target)
            quick.set_weighting(scale, stop)
            first = self._fill_sequential(quick, seed, extra, rng)
            quick.set_searches(searches)
            quick()
            iterations = int(quick.iterations[0])
            index = int(quick.search[0])
            kinds = first[: index + 1]
            q = (quick.q_near if seed is not None else quick.q).copy()
            position_error, orientation_error = self._errors(target, q)
            if (
                quick.cost[0] <= accept
                and position_error <= position_tolerance
                and orientation_error <= orientation_tolerance
            ):
                found = (index, q, position_error, orientation_error)
                solutions = LazySolutions(
                    lambda: self._more_solutions(target, found, seed, extra, deferred, kinds, plan[1:3], scale, accept)
                )
                return IKResult.from_solver(
                    q, True, IKStatus.SOLVED, f"reached by attempt {index} ({kinds[index]})", position_error,
                    orientation_error, iterations, index + 1, index, kinds[index], time.perf_counter() - start,
                    "nlp", solutions,
                )  # fmt: skip
            best = (position_error + self._orientation_weight * orientation_error, q, position_error, orientation_error)
        if deferred is not None:
            extra = self._check_extra_seeds(deferred())
        if max_attempts is not None and len(kinds) >= max_attempts:
            return self._not_converged(best, len(kinds), max_attempts, iterations, start)
        return self._batches(target, seed, extra, options, rng, kinds, iterations, best, start)

    def _plan(self, options: IKOptions) -> tuple[IKOptions, float, float, int | None, bool, int, float, float, float]:
        """What a call with these options needs before its first search, worked out once per options object.

        Returns:
            ``(options, position tolerance [m], orientation tolerance [rad], attempt cap,
            whether there are secondary objectives, first-stage searches, the first stage's
            orientation weight [m], stop and acceptance thresholds on the squared residual)``.

        Raises:
            InvalidArgumentError: If `options` is not an :class:`IKOptions`.
        """
        if not isinstance(options, IKOptions):
            raise InvalidArgumentError(f"options must be a planner.IKOptions or None, got {type(options).__name__}")
        position_tolerance = options.position_tolerance
        orientation_tolerance = options.orientation_tolerance
        max_attempts = options.max_attempts
        scale = _SCALES[0] * self.length
        stop = max((0.01 * min(position_tolerance, scale * orientation_tolerance)) ** 2, 1e-30)
        accept = position_tolerance**2 + 8.0 * (scale * math.sin(min(orientation_tolerance, 3.0) / 2)) ** 2
        plan = (
            options,
            position_tolerance,
            orientation_tolerance,
            max_attempts,
            options.near_seed or options.manipulability_floor is not None,
            _SEARCHES if max_attempts is None else min(_SEARCHES, max_attempts),
            scale,
            stop,
            accept,
        )
        if len(self._plans) >= _PLANS:
            self._plans.clear()
        # Keyed by identity and holding the options: an id is not reused while the entry lives.
        self._plans[id(options)] = plan
        return plan

    def _fill_sequential(
        self,
        kernel: SequentialKernel,
        seed: np.ndarray | None,
        extra: np.ndarray,
        rng: np.random.Generator | None,
    ) -> list[str]:
        """Write the starts into a sequential kernel: seed, extra seeds, random; their kinds.

        Without a generator, the random starts are the pool's configurations nearest the target
        (one of each group, chosen in the kernel); with one, its draws.
        """
        rows = kernel.q0
        if seed is not None and not len(extra) and rng is None and self._pooled_from.get(id(kernel)) == 1:
            rows[0] = seed  # the common call: a seed, nothing else, the pool as before
            return self._seed_kinds
        fixed = 0
        if seed is not None:
            rows[0] = seed
            fixed = 1
        count = min(len(extra), _SEARCHES - fixed)
        if count:
            rows[fixed : fixed + count] = extra[:count]
        key = (fixed, count)
        kinds = self._first_kinds.get(key)
        if kinds is None:
            kinds = self._first_kinds[key] = (
                ["seed"] * fixed + ["closed_form"] * count + ["random"] * (_SEARCHES - fixed - count)
            )
        fixed += count
        if rng is not None:
            rows[fixed:] = self.robot.random_configurations(rng, _SEARCHES - fixed)
            kernel.pooled[:] = 0.0
            self._pooled_from[id(kernel)] = _SEARCHES
        elif self._pooled_from.get(id(kernel)) != fixed:
            kernel.pooled[:fixed] = 0.0
            kernel.pooled[fixed:] = 1.0
            self._pooled_from[id(kernel)] = fixed
        return kinds

    def _not_converged(
        self,
        best: tuple[float, np.ndarray, float, float] | None,
        attempts: int,
        max_attempts: int | None,
        iterations: int,
        start: float,
    ) -> IKResult:
        assert best is not None
        _, q, position_error, orientation_error = best
        limit = "attempt cap" if max_attempts is not None and attempts >= max_attempts else "time budget"
        return IKResult(
            q, False, IKStatus.NOT_CONVERGED,
            f"none of {attempts} attempts reached the target before the {limit} ran out (best: position error "
            f"{position_error:.3g} m, orientation error {orientation_error:.3g} rad); it may be out of reach",
            position_error, orientation_error, iterations, attempts, None, None, time.perf_counter() - start,
        )  # fmt: skip

    def _batches(
        self,
        target: Target,
        seed: np.ndarray | None,
        extra: np.ndarray,
        options: IKOptions,
        rng: np.random.Generator | None,
        kinds: list[str],
        iterations: int,
        best: tuple[float, np.ndarray, float, float] | None,
        start: float,
    ) -> IKResult:
        """Batches of seeds with restarts, after the attempts in `kinds` (the first stage's)."""
        position_tolerance = options.position_tolerance
        orientation_tolerance = options.orientation_tolerance
        time_budget = options.time_budget
        max_attempts = options.max_attempts
        near_seed = options.near_seed
        manipulability_floor = options.manipulability_floor
        task = options.manipulability_task or ("pose" if self.robot.dof >= 6 else "position")
        secondary = near_seed or manipulability_floor is not None

        kernel = self._kernel(target.kind)
        kernel.set_target(target)

        fixed = ([seed] if seed is not None else []) + list(extra)
        fixed_kinds = (["seed"] if seed is not None else []) + ["closed_form"] * len(extra)
        k = self.batch_size
        base = len(kinds)
        carried: list[tuple[int, np.ndarray]] = []
        pool_used = _SEARCHES if base else 0  # the first stage's random starts: the pool's first rows
        reached: list[tuple[int, np.ndarray, float, float]] = []
        found: tuple[int, np.ndarray, float, float] | None = None
        further: tuple[np.ndarray, list[int]] | None = None  # rows of the last batch to check lazily
        while found is None:
            scale = _SCALES[(len(kinds) - base) // k % len(_SCALES)] * self.length
            # Stop when converged well inside the tolerances (Gauss-Newton converges quadratically).
            stop = (0.01 * min(position_tolerance, scale * orientation_tolerance)) ** 2
            kernel.set_weighting(scale, -1.0 if secondary else max(stop, 1e-30))
            # The residual can only be this small when both errors are within tolerance.
            accept = position_tolerance**2 + 8.0 * (scale * math.sin(min(orientation_tolerance, 3.0) / 2)) ** 2
            slots: list[int] = []  # the attempt each row of the batch belongs to
            while len(slots) < k and len(kinds) - base < len(fixed):
                kernel.q0[len(slots)] = fixed[len(kinds) - base]
                slots.append(len(kinds))
                kinds.append(fixed_kinds[len(kinds) - base])
            # Attempts still converging (slowly, e.g. near a singularity) continue in this batch.
            for index, q in carried[: k - len(slots)]:
                kernel.q0[len(slots)] = q
                slots.append(index)
            n_random = k - len(slots)
            if n_random:
                if rng is None and pool_used + n_random <= len(self._pool):
                    kernel.q0[len(slots) :] = self._pool[pool_used : pool_used + n_random]
                    pool_used += n_random
                else:
                    rng = rng or np.random.default_rng(1)
                    kernel.q0[len(slots) :] = self.robot.random_configurations(rng, n_random)
                slots += range(len(kinds), len(kinds) + n_random)
                kinds += ["random"] * n_random
            kernel()
            iterations += int(kernel.iterations[0])
            new = []
            candidates = sorted(np.flatnonzero(kernel.cost <= accept), key=lambda j: slots[j])
            for position, j in enumerate(candidates):
                # A copy: the kernel's buffers are overwritten by the next batch.
                q = self._wrap(kernel.q[j].copy())
                position_error, orientation_error = self._errors(target, q)
                if position_error <= position_tolerance and orientation_error <= orientation_tolerance:
                    new.append((slots[j], q, position_error, orientation_error))
                    if not secondary:
                        further = self._other_rows(kernel, candidates[position + 1 :], slots)
                        break
            if new and not secondary:
                found = new[0]
                reached = new
                break
            reached += new
            if new:
                found, extra_iterations = self._choose(
                    target, new, seed, near_seed, manipulability_floor, task, position_tolerance, orientation_tolerance
                )
                iterations += extra_iterations
                if found is not None:
                    break
            order = np.argsort(kernel.cost, kind="stable")
            q = self._wrap(kernel.q[order[0]].copy())
            position_error, orientation_error = self._errors(target, q)
            merit = position_error + self._orientation_weight * orientation_error
            if best is None or merit < best[0]:
                best = (merit, q, position_error, orientation_error)
            if time.perf_counter() - start >= time_budget or (max_attempts is not None and len(kinds) >= max_attempts):
                break
            carried = [
                (slots[j], kernel.q[j].copy()) for j in order[:2] if accept < kernel.cost[j] < (0.01 * scale) ** 2
            ]

        attempts = len(kinds)
        if found is not None:
            if seed is not None and not near_seed:
                # No needless whole turns: each angle the equivalent nearest the seed.
                found = (found[0], self._nearest_turn(found[1], seed), found[2], found[3])
            index, q, position_error, orientation_error = found
            if secondary:
                reached = self._distinct(found, reached, seed if near_seed else None)
                solutions = self._solutions(reached, kinds, seed)
            else:
                tolerances = (position_tolerance, orientation_tolerance)
                solutions = LazySolutions(lambda: self._solutions(
                    [found, *self._further_solutions(target, q, further, tolerances)], kinds, seed
                ))  # fmt: skip
            return IKResult(
                q, True, IKStatus.SOLVED, f"reached by attempt {index} ({kinds[index]})", position_error,
                orientation_error, iterations, attempts, index, kinds[index], time.perf_counter() - start,
                solutions=solutions,
            )  # fmt: skip
        if reached:
            _, q, position_error, orientation_error = reached[0]
            solutions = self._solutions(self._distinct(reached[0], reached, seed if near_seed else None), kinds, seed)
            return IKResult(
                q, False, IKStatus.BELOW_MANIPULABILITY_FLOOR,
                f"{len(reached)} of {attempts} attempts reached the target, none with manipulability "
                f">= {manipulability_floor:g} ({task} task)",
                position_error, orientation_error, iterations, attempts, None, None, time.perf_counter() - start,
                solutions=solutions,
            )  # fmt: skip
        return self._not_converged(best, attempts, max_attempts, iterations, start)

    # -------------------------------------------------------------------- the solutions found
    def _other_rows(
        self, kernel: Kernel, rows: Sequence[int], slots: Sequence[int]
    ) -> tuple[np.ndarray, list[int]] | None:
        """The batch rows below the acceptance residual besides the answer, lowest residual first.

        A copy (the kernel's buffers are overwritten by the next batch), with each row's attempt
        index; :meth:`_further_solutions` checks them when the solutions are read.
        """
        if not rows:
            return None
        if len(rows) > 1:
            rows = sorted(rows, key=kernel.cost.__getitem__)
        return kernel.q[rows], [slots[r] for r in rows]

    def _more_solutions(
        self,
        target: Target,
        found: tuple[int, np.ndarray, float, float],
        seed: np.ndarray | None,
        extra: np.ndarray,
        deferred: Callable[[], Sequence[Sequence[float]] | np.ndarray] | None,
        kinds: list[str],
        tolerances: tuple[float, float],
        scale: float,
        accept: float,
    ) -> tuple[IKSolution, ...]:
        """The first stage's answer and the distinct answers of one batch run to its end.

        Run when the solutions are first read: one batch from the seed, the extra seeds and
        random starts, every row to its last iteration; each distinct row that reaches the
        target is verified by Pinocchio FK.
        """
        if deferred is not None:
            extra = self._check_extra_seeds(deferred())
        fixed = ([seed] if seed is not None else []) + list(extra)
        labels = (["seed"] if seed is not None else []) + ["closed_form"] * len(extra)
        kernel = self._kernel(target.kind)
        k = self.batch_size
        fixed, labels = fixed[:k], labels[:k]
        kernel.set_target(target)
        kernel.set_weighting(scale, -1.0)
        if fixed:
            kernel.q0[: len(fixed)] = fixed
        kernel.q0[len(fixed) :] = self._pool[: k - len(fixed)]
        kernel()
        all_kinds = kinds + labels + ["random"] * (k - len(fixed))
        rows = self._other_rows(
            kernel, np.flatnonzero(kernel.cost <= accept).tolist(), range(len(kinds), len(all_kinds))
        )
        return self._solutions([found, *self._further_solutions(target, found[1], rows, tolerances)], all_kinds, seed)

    def _further_solutions(
        self,
        target: Target,
        q_found: np.ndarray,
        rows: tuple[np.ndarray, list[int]] | None,
        tolerances: tuple[float, float],
    ) -> list[tuple[int, np.ndarray, float, float]]:
        """The other rows that reached the target, distinct from `q_found` and each other.

        Rows come lowest residual first, so of near-duplicates the most converged one is kept;
        each distinct one is verified by Pinocchio FK (the only extra cost, paid when the
        solutions are read).
        """
        out: list[tuple[int, np.ndarray, float, float]] = []
        if rows is None:
            return out
        block, row_slots = rows
        position_tolerance, orientation_tolerance = tolerances
        angular = self._angular_list
        kept = [q_found.tolist()]
        for i, values in enumerate(block.tolist()):
            for other in kept:
                if configurations_close(values, other, angular, DISTINCT):
                    break
            else:
                kept.append(values)
                q = self._wrap(block[i])
                position_error, orientation_error = self._errors(target, q)
                if position_error <= position_tolerance and orientation_error <= orientation_tolerance:
                    out.append((row_slots[i], q, position_error, orientation_error))
        return out

    def _distinct(
        self,
        chosen: tuple[int, np.ndarray, float, float],
        reached: list[tuple[int, np.ndarray, float, float]],
        seed: np.ndarray | None,
    ) -> list[tuple[int, np.ndarray, float, float]]:
        """`chosen`, then the answers of `reached` distinct from it and each other (best first).

        With a `seed`, the answers' angles are shifted by whole turns towards it, as the
        chosen one's are.
        """
        angular = self._angular_list
        kept = [chosen]
        for item in sorted(reached, key=lambda item: item[2] + self._orientation_weight * item[3]):
            if item is chosen:
                continue
            values = item[1].tolist()
            if any(configurations_close(values, q.tolist(), angular, DISTINCT) for _, q, _, _ in kept):
                continue
            if seed is not None:
                item = (item[0], self._nearest_turn(item[1], seed), item[2], item[3])
            kept.append(item)
        return kept

    def _solutions(
        self, items: list[tuple[int, np.ndarray, float, float]], kinds: Sequence[str], seed: np.ndarray | None
    ) -> tuple[IKSolution, ...]:
        """Distinct verified answers as solutions, nearest the seed first (else smallest error first)."""
        if seed is None:
            solutions = [
                IKSolution(q, True, kinds[index], position_error, orientation_error)
                for index, q, position_error, orientation_error in items
            ]
            if len(solutions) > 1:
                solutions.sort(key=lambda s: s.position_error + self._orientation_weight * s.orientation_error)
            return tuple(solutions)
        angular, reference = self._angular_list, seed.tolist()
        solutions = []
        for index, q, position_error, orientation_error in items:
            q = self._nearest_turn(q, seed)
            distance = wrapped_distance(q, reference, angular)
            solutions.append(IKSolution(q, True, kinds[index], position_error, orientation_error, distance))
        if len(solutions) > 1:
            solutions.sort(key=lambda s: s.distance)
        return tuple(solutions)

    # -------------------------------------------------------------------- secondary objectives
    def _choose(
        self,
        target: Target,
        reached: list[tuple[int, np.ndarray, float, float]],
        seed: np.ndarray | None,
        near_seed: bool,
        floor: float | None,
        task: str,
        position_tolerance: float,
        orientation_tolerance: float,
    ) -> tuple[tuple[int, np.ndarray, float, float] | None, int]:
        """Pick among solutions by the secondary objectives; move along the redundancy with IPOPT."""
        if near_seed:
            reached = [(i, self._nearest_turn(q, seed), pe, oe) for i, q, pe, oe in reached]
            reached.sort(key=lambda item: float(np.linalg.norm(item[1] - seed)))

        def good(q: np.ndarray) -> bool:
            return floor is None or float(self.robot.manipulability(q, task)) >= floor

        kind = self._polisher.task_kind(target)
        iterations = 0
        if self._polisher.redundant(kind):
            for index, q, _, _ in reached[:3]:
                polished, its = self._polisher.polish(kind, target, q, seed if near_seed else q, task, floor)
                iterations += its
                polished = self._nearest_turn(polished, seed) if near_seed else self._wrap(polished)
                position_error, orientation_error = self._errors(target, polished)
                if (
                    position_error <= position_tolerance
                    and orientation_error <= orientation_tolerance
                    and good(polished)
                ):
                    return (index, polished, position_error, orientation_error), iterations
        for item in reached:
            if good(item[1]):
                return item, iterations
        return None, iterations

    def solve_batch(
        self,
        targets: BatchTargets | Sequence[Target | Sequence[float] | np.ndarray] | np.ndarray,
        q_seeds: Sequence[Sequence[float]] | np.ndarray | None = None,
        options: IKOptions | None = None,
    ) -> BatchIKResult:
        """Solve many targets at once, vectorised (:mod:`planner.ik.numeric.batch`).

        One compiled kernel advances a block of targets per call: first every target from its
        seed, then fixed restart configurations for the targets not yet solved. Every answer is
        verified as a single call's (Pinocchio FK within the tolerances, within the joint
        limits; each angle nearest the seed). With ``near_seed`` or a manipulability floor the
        targets are solved by single calls in turn.

        Args:
            targets: Positions (N, 3) [m], poses (N, 4, 4) [m], or a sequence of
                :class:`Target` (any kinds, mixed), positions (3,) or poses (4, 4).
            q_seeds: Seeds (N, dof) [rad or m] within the limits, one configuration (dof,) for
                every target, or None (restarts only).
            options: Tolerances, attempt cap per target, time budget (the batch's restarts stop
                after ``N * time_budget``), restart generator; None: the defaults.

        Returns:
            A sequence of N :class:`IKResult` (status ``SOLVED`` or ``NOT_CONVERGED`` each) with
            the arrays over targets as attributes.

        Raises:
            InvalidArgumentError: On a bad target (naming it) or options.
            InvalidConfigurationError: On seeds of the wrong shape or with NaN values.
            JointLimitError: If a seed is outside the joint limits (naming its target).
        """
        start = time.perf_counter()
        batch = BatchTargets.of(targets)
        if options is None:
            options = _DEFAULT_OPTIONS
        elif not isinstance(options, IKOptions):
            raise InvalidArgumentError(f"options must be a planner.IKOptions or None, got {type(options).__name__}")
        if self._batch is None:
            self._batch = BatchIK(
                self.robot,
                self.kinematics,
                lower=self._lower,
                upper=self._upper,
                length=self.length,
                restarts=self._pool,
                scales=_SCALES,
                scale_every=self.batch_size,
                chunk=self._chunk,
                max_chunks=self._max_chunks,
                # The first stage's step (kernel.step_functions' default damping): the same answer
                # from the same seed as a single call.
                max_step=SEARCH_MAX_STEP,
                jit=self._jit,
            )
        seeds = self._batch.check_seeds(q_seeds, len(batch))
        if options.near_seed or options.manipulability_floor is not None:
            results = [
                self.solve(batch.target(i), None if seeds is None else seeds[i], options) for i in range(len(batch))
            ]
            return BatchIKResult.from_results(results, self.robot.dof, time.perf_counter() - start)
        return self._batch.solve(batch, seeds, options, start)
