"""Batch numerical IK: many targets through one compiled kernel (:class:`BatchIK`).

The damped Gauss-Newton step of :mod:`planner.ik.numeric.kernel` (the same residual, damping,
step cap and clamping into the joint limits as a single :meth:`NlpIK.solve
<planner.ik.numeric.solver.NlpIK.solve>` call) runs for one starting configuration per target,
and that per-target solver is mapped (``casadi.Function.map``) over a block of
:data:`BLOCK` targets and compiled to C (:mod:`planner.ik.numeric.codegen`): one call of
compiled code advances 64 targets. Each target stops on its own: when its squared residual is
below the stop threshold, or when a chunk of 5 steps no longer reduces it by a tenth
(:data:`STALL`) while it is still large (a local minimum: restarting is cheaper than
waiting).

How :meth:`BatchIK.solve` works:

1. **First pass:** every target from its own seed (attempt 0, kind ``"seed"``).
2. **Restart passes,** only for the targets not yet solved, from the solver's fixed restart
   configurations (the :class:`NlpIK`'s 512 random configurations, drawn once from
   ``numpy.random.default_rng(0)``): first the :data:`NEAREST` whose tip poses (Pinocchio FK,
   once per solver) lie nearest the target, then the others in order; fresh draws from
   ``options.rng`` when given. The orientation weight varies every 8 attempts as a single
   call's batches vary it. An attempt that ends still converging (slowly, near a singularity)
   goes on from where it stopped, up to :data:`MAX_CONTINUATIONS` times, as a single call
   carries such attempts into its next batch. Restarts stop when every target is solved, after
   ``options.max_attempts`` attempts per target (:data:`MAX_ATTEMPTS` without a cap), or when
   the time budget of N single calls (``N * options.time_budget``) is spent. Without seeds the
   restarts are all there is.
3. **Verification, as for a single call:** a candidate whose residual is small enough is
   wrapped (continuous joints into [-pi, pi)), checked by Pinocchio forward kinematics against
   the target (position and orientation errors within the tolerances) and within the joint
   limits (vectorised); only then is the target solved. With a seed, each angle of the answer
   is then taken nearest the seed (whole turns, where the limits allow), as a single call does.

So a target whose seed converges gets the answer a single call from that seed gets when it
answers from its seed (``attempt_kind == "seed"``): the same iterates, to rounding. A single
call also runs 7 random starts beside the seed and stops at the first that converges, so where
one of those wins, or where the seed fails, the two may return different (equally verified)
solutions. The secondary objectives (``near_seed``, ``manipulability_floor``) need the whole
set of solutions a single call compares: with them, the batch runs single calls in turn.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import casadi as ca
import numpy as np
import pinocchio as pin

from planner.core.rotations import rotation_error
from planner.exceptions import InvalidConfigurationError
from planner.geometry.joint_space import angular_joints
from planner.geometry.target import pitch_error
from planner.geometry.target_batch import BatchTargets
from planner.ik.numeric.batch_result import BatchIKResult
from planner.ik.numeric.codegen import compile_function
from planner.ik.numeric.kernel import (
    KERNEL_KINDS,
    N_PARAMS,
    PARAM_SCALE,
    PARAM_STOP,
    set_weighting_rows,
    step_functions,
    target_parameters,
)
from planner.ik.numeric.kinematics import CasadiKinematics
from planner.ik.options import IKOptions
from planner.ik.status import IKStatus
from planner.model.robot import Robot

__all__ = ["BLOCK", "MAX_ATTEMPTS", "MAX_CONTINUATIONS", "NEAREST", "STALL", "BatchIK"]

#: Targets per call of the compiled function.
BLOCK = 64
#: A target stops restarting after this many attempts when ``options.max_attempts`` is None.
MAX_ATTEMPTS = 512
#: A chunk of steps that leaves the squared residual above this fraction of its value before
#: the chunk, while above ``(0.01 * weight)^2``, ends the attempt (a local minimum).
STALL = 0.9
#: Restarts from the restart configurations nearest the target (in target space) before the rest.
NEAREST = 4
#: Times a slowly converging attempt (near a singularity) goes on for another run of steps.
MAX_CONTINUATIONS = 2


# ---------------------------------------------------------------------------- the kernel
def _block_function(
    step: ca.Function, cost: ca.Function, dof: int, chunk: int, max_chunks: int, block: int
) -> ca.Function:
    """``(q0 (dof, block), par (N_PARAMS, block)) -> (q, cost (1, block), iterations (1, block))``.

    Per target: chunks of `chunk` steps while its residual is above the stop threshold and each
    chunk still reduces it (:data:`STALL`); a switch skips the remaining chunks of a target
    that stopped, so a stopped target costs one flag test per chunk.
    """
    x_in = ca.MX.sym("q", dof)
    p_in = ca.MX.sym("par", N_PARAMS)
    c_in = ca.MX.sym("cost")
    x = x_in
    for _ in range(chunk):
        x = step(x, p_in)
    c = cost(x, p_in)
    stalled = ca.logic_and(c > STALL * c_in, c > (0.01 * p_in[PARAM_SCALE]) ** 2)
    stop = ca.logic_or(c < p_in[PARAM_STOP], stalled)
    run = ca.Function("gnb_chunk", [x_in, p_in, c_in], [x, c, stop])
    keep = ca.Function("gnb_keep", [x_in, p_in, c_in], [x_in, c_in, ca.MX(1)])
    maybe = ca.Function.if_else("gnb_maybe", keep, run)
    c = cost(x_in, p_in)
    done = c < p_in[PARAM_STOP]
    x, iterations = x_in, ca.MX(0)
    for _ in range(max_chunks):
        iterations = iterations + ca.if_else(done, 0, chunk)
        x, c, done = maybe(done, x, p_in, c)
    one = ca.Function("gnb_target", [x_in, p_in], [x, c, iterations])
    return one.map(f"gnb_{dof}x{block}", "serial", block, [], [])


class _BlockKernel:
    """The compiled block function with numpy buffers bound to it (rows are targets)."""

    def __init__(self, function: ca.Function, dof: int, block: int, compiled: bool) -> None:
        self.function = function
        self.compiled = compiled
        self.q0 = np.zeros((block, dof))
        self.par = np.zeros((block, N_PARAMS))
        self.q = np.zeros((block, dof))
        self.cost = np.zeros(block)
        self.iterations = np.zeros(block)
        self._buffer, self._evaluate = function.buffer()
        self._buffer.set_arg(0, memoryview(self.q0))
        self._buffer.set_arg(1, memoryview(self.par))
        self._buffer.set_res(0, memoryview(self.q))
        self._buffer.set_res(1, memoryview(self.cost))
        self._buffer.set_res(2, memoryview(self.iterations))

    def run(self, q0: np.ndarray, par: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Solve rows of starting configurations (M, dof) and parameters (M, N_PARAMS)."""
        m, block = len(q0), len(self.q0)
        q, cost, iterations = np.empty_like(q0), np.empty(m), np.empty(m)
        for s in range(0, m, block):
            e = min(m, s + block)
            k = e - s
            self.q0[:k] = q0[s:e]
            self.par[:k] = par[s:e]
            if k < block:
                # Padding rows stop at once: an infinite stop threshold.
                self.par[k:] = par[s]
                self.par[k:, PARAM_STOP] = math.inf
                self.q0[k:] = q0[s]
            self._evaluate()
            if self._buffer.ret() != 0:
                raise RuntimeError(f"CasADi function {self.function.name()!r} failed (code {self._buffer.ret()})")
            q[s:e], cost[s:e], iterations[s:e] = self.q[:k], self.cost[:k], self.iterations[:k]
        return q, cost, iterations


# ---------------------------------------------------------------------------- the solver
class _State:
    """The arrays over targets that :meth:`BatchIK.solve` fills."""

    def __init__(self, n: int, dof: int) -> None:
        self.q = np.zeros((n, dof))
        self.success = np.zeros(n, dtype=bool)
        self.position_error = np.zeros(n)
        self.orientation_error = np.zeros(n)
        self.iterations = np.zeros(n, dtype=int)
        self.attempts = np.zeros(n, dtype=int)
        self.attempt = np.full(n, -1)
        self.limit = "attempt cap"


class BatchIK:
    """Vectorised numerical IK of one robot (see the module docstring).

    Built by :meth:`NlpIK.solve_batch <planner.ik.numeric.solver.NlpIK.solve_batch>` with the
    single-call solver's settings; one compiled block function per target kind, on first use.
    Not thread-safe.

    Attributes:
        robot: The robot.
    """

    def __init__(
        self,
        robot: Robot,
        kinematics: CasadiKinematics,
        *,
        lower: np.ndarray,
        upper: np.ndarray,
        length: float,
        restarts: np.ndarray,
        scales: Sequence[float],
        scale_every: int,
        chunk: int,
        max_chunks: int,
        max_step: float,
        jit: bool,
    ) -> None:
        """Keep the settings; nothing is compiled here.

        Args:
            robot: The robot.
            kinematics: Its symbolic kinematics.
            lower: Finite lower joint limits (dof,) [rad or m].
            upper: Finite upper joint limits (dof,) [rad or m].
            length: Chain length [m]; orientation weights are fractions of it.
            restarts: Fixed restart configurations (M, dof), within the limits.
            scales: Orientation weights of successive groups of attempts, times `length`.
            scale_every: Attempts per orientation weight.
            chunk: Gauss-Newton steps between two convergence checks.
            max_chunks: Chunks per attempt at most.
            max_step: Longest joint step of one iteration [rad or m].
            jit: Compile to C.
        """
        self.robot = robot
        self._kinematics = kinematics
        self._lower, self._upper = lower, upper
        self._length = length
        self._restarts = restarts
        self._scales = tuple(scales)
        self._scale_every = scale_every
        self._chunk, self._max_chunks, self._max_step, self._jit = chunk, max_chunks, max_step, jit
        self._kernels: dict[str, _BlockKernel] = {}
        self._continuous = np.array([k == "continuous" for k in robot.joint_kinds], dtype=bool)
        self._angular = np.array(angular_joints(robot), dtype=bool)
        self._model = robot.model
        self._data = robot.model.createData()
        self._tip = robot.tip_frame_id
        self._axis = np.array(robot.approach_axis)
        self._pool_features: dict[str, np.ndarray] = {}

    def _kernel(self, kind: str) -> _BlockKernel:
        kernel = self._kernels.get(kind)
        if kernel is None:
            step, cost = step_functions(self._kinematics, kind, self._lower, self._upper, self._max_step)
            symbolic = _block_function(step, cost, self.robot.dof, self._chunk, self._max_chunks, BLOCK)
            function = compile_function(symbolic) if self._jit else symbolic
            kernel = _BlockKernel(function, self.robot.dof, BLOCK, function is not symbolic)
            self._kernels[kind] = kernel
        return kernel

    def compiled(self, kind: str = "pose") -> bool:
        """Whether the block function of a target kind runs as compiled C code (builds it if needed)."""
        return self._kernel(kind).compiled

    # ------------------------------------------------------------------ checks
    def check_seeds(self, q_seeds: Sequence[Sequence[float]] | np.ndarray | None, n: int) -> np.ndarray | None:
        """Seeds as an (n, dof) array (one configuration (dof,) is used for every target).

        Raises:
            InvalidConfigurationError: On a wrong shape or NaN values.
            JointLimitError: If a seed lies outside the joint limits (naming the target).
        """
        if q_seeds is None:
            return None
        robot = self.robot
        seeds = robot.check_configuration(q_seeds)
        if seeds.ndim == 1:
            seeds = np.broadcast_to(seeds, (n, robot.dof))
        elif len(seeds) != n:
            raise InvalidConfigurationError(f"got {n} targets but {len(seeds)} seeds; give one seed per target")
        outside = ~np.all((seeds >= robot.lower) & (seeds <= robot.upper), axis=1)
        if outside.any():
            i = int(np.argmax(outside))
            robot.check_limits(seeds[i], context=f"seed of target {i}")
        return seeds

    # ------------------------------------------------------------------ Pinocchio checks
    def _tip_poses(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tip positions (M, 3) and rotations (M, 3, 3) by Pinocchio FK."""
        m = len(q)
        positions, rotations = np.empty((m, 3)), np.empty((m, 3, 3))
        model, data, tip = self._model, self._data, self._tip
        convert = self.robot.pinocchio_configuration if self._continuous.any() else None
        for i in range(m):
            pin.forwardKinematics(model, data, q[i] if convert is None else convert(q[i]))
            placement = pin.updateFramePlacement(model, data, tip)
            positions[i] = placement.translation
            rotations[i] = placement.rotation
        return positions, rotations

    def errors(self, targets: BatchTargets, index: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position [m] and orientation [rad] errors by Pinocchio FK of rows `q` for targets `index`."""
        if len(index) == 0:
            return np.zeros(0), np.zeros(0)
        positions, rotations = self._tip_poses(q)
        position_error = np.linalg.norm(positions - targets.positions[index], axis=1)
        orientation_error = np.zeros(len(index))
        kinds = targets.kinds[index]
        pose = kinds == "pose"
        if pose.any():
            orientation_error[pose] = rotation_error(rotations[pose], targets.rotations[index[pose]])
        pitch = kinds == "pitch"
        if pitch.any():
            approach = rotations[pitch] @ self._axis
            orientation_error[pitch] = pitch_error(
                approach, targets.positions[index[pitch]], targets.pitches[index[pitch]]
            )
        return position_error, orientation_error

    def _wrap(self, q: np.ndarray) -> np.ndarray:
        if self._continuous.any():
            q[:, self._continuous] = (q[:, self._continuous] + math.pi) % (2 * math.pi) - math.pi
        return q

    def nearest_turns(self, q: np.ndarray, seeds: np.ndarray) -> np.ndarray:
        """Rows of `q` with each angle shifted by whole turns towards the seed where the limits allow."""
        out = q.copy()
        angular = self._angular & (np.abs(q - seeds) > math.pi)
        if not angular.any():
            return out
        turns = np.round((seeds - q) / (2 * math.pi))
        for k in (0.0, -1.0, 1.0):
            shifted = q + 2 * math.pi * (turns + k)
            better = (
                angular
                & (shifted >= self._lower)
                & (shifted <= self._upper)
                & (np.abs(shifted - seeds) < np.abs(out - seeds))
            )
            out = np.where(better, shifted, out)
        return out

    # ------------------------------------------------------------------ restarts
    def _features(self, kind: str, positions: np.ndarray, rotations: np.ndarray, pitches: np.ndarray) -> np.ndarray:
        """Target-space points whose distances approximate the residual between poses (M, 3 to 9)."""
        weight = self._scales[0] * self._length
        if kind == "pose":
            return np.hstack([positions, weight * rotations[:, :, 0], weight * rotations[:, :, 2]])
        if kind == "pitch":
            return np.column_stack([positions, weight * np.sin(pitches), weight * np.abs(np.cos(pitches))])
        return np.asarray(positions, dtype=float)

    def _restart_features(self, kind: str) -> np.ndarray:
        """:meth:`_features` of the restart configurations' tip poses (Pinocchio FK), once per kind."""
        features = self._pool_features.get(kind)
        if features is None:
            positions, rotations = self._tip_poses(self._restarts)
            approach = rotations @ self._axis
            pitches = np.arctan2(approach[:, 2], np.hypot(approach[:, 0], approach[:, 1]))
            features = self._features(kind, positions, rotations, pitches)
            self._pool_features[kind] = features
        return features

    def _nearest_restarts(self, kind: str, targets: BatchTargets, rows: np.ndarray) -> np.ndarray:
        """For each target row, the :data:`NEAREST` restart configurations nearest it in target space."""
        pool = self._restart_features(kind)
        points = self._features(kind, targets.positions[rows], targets.rotations[rows], targets.pitches[rows])
        count = min(NEAREST, len(pool))
        out = np.empty((len(rows), count), dtype=int)
        pool_sq = np.einsum("ij,ij->i", pool, pool)
        for s in range(0, len(rows), 512):
            distance = pool_sq[None, :] - 2.0 * points[s : s + 512] @ pool.T
            line = np.arange(len(distance))
            for j in range(count):
                nearest = distance.argmin(axis=1)
                out[s : s + 512, j] = nearest
                distance[line, nearest] = math.inf
        return out

    # ------------------------------------------------------------------ solving
    def solve(
        self,
        targets: BatchTargets,
        seeds: np.ndarray | None,
        options: IKOptions,
        start: float | None = None,
    ) -> BatchIKResult:
        """Solve checked targets from checked seeds (see the module docstring).

        Args:
            targets: The targets.
            seeds: One seed per target (N, dof) within the limits, or None.
            options: Tolerances, attempt cap, time budget and restart generator (the secondary
                objectives are not read here).
            start: ``time.perf_counter()`` at the start of the call (now if None).

        Returns:
            The results.
        """
        start = time.perf_counter() if start is None else start
        n, dof = len(targets), self.robot.dof
        state = _State(n, dof)
        cap = MAX_ATTEMPTS if options.max_attempts is None else int(options.max_attempts)
        deadline = start + options.time_budget * max(n, 1)
        rng = options.generator()
        for kind in KERNEL_KINDS:
            index = np.flatnonzero(targets.kinds == kind)
            if len(index):
                self._solve_kind(kind, targets, index, seeds, options, cap, deadline, rng, state)
        if seeds is not None and state.success.any():
            solved = np.flatnonzero(state.success)
            state.q[solved] = self.nearest_turns(state.q[solved], seeds[solved])
        status = np.full(n, IKStatus.NOT_CONVERGED, dtype=object)
        status[state.success] = IKStatus.SOLVED
        return BatchIKResult(
            state.q,
            state.success,
            status,
            state.position_error,
            state.orientation_error,
            state.iterations,
            state.attempts,
            state.attempt,
            seeded=seeds is not None,
            wall_time=time.perf_counter() - start,
            limit=state.limit,
            seeds=seeds,
            angular=self._angular.tolist(),
        )

    def _solve_kind(
        self,
        kind: str,
        targets: BatchTargets,
        index: np.ndarray,
        seeds: np.ndarray | None,
        options: IKOptions,
        cap: int,
        deadline: float,
        rng: np.random.Generator | None,
        state: _State,
    ) -> None:
        """Rounds of attempts for the targets `index` of one kind until solved or out of attempts."""
        kernel = self._kernel(kind)
        dof, m = self.robot.dof, len(index)
        par = target_parameters(kind, targets.positions[index], targets.rotations[index], targets.pitches[index])
        tolerance = (options.position_tolerance, options.orientation_tolerance)
        seeded = seeds is not None
        next_attempt = np.zeros(m, dtype=int)
        current = np.zeros(m, dtype=int)
        carried = np.zeros(m, dtype=bool)
        continued = np.zeros(m, dtype=int)
        last_q = np.zeros((m, dof))
        best_cost = np.full(m, math.inf)
        nearest = np.full((m, min(NEAREST, len(self._restarts))), -1)
        remaining = np.arange(m)  # positions in `index` of the targets not yet solved
        first = True
        while len(remaining):
            if not first and time.perf_counter() >= deadline:
                state.limit = "time budget"
                break
            first = False
            remaining = remaining[carried[remaining] | (next_attempt[remaining] < cap)]
            if not len(remaining):
                break
            q0 = np.empty((len(remaining), dof))
            carry = carried[remaining]
            q0[carry] = last_q[remaining[carry]]
            fresh = remaining[~carry]
            attempt = next_attempt[fresh]
            current[fresh] = attempt
            next_attempt[fresh] += 1
            q0[~carry] = self._starts(kind, targets, index, fresh, attempt - seeded, seeds, rng, nearest)
            scale = np.asarray(self._scales)[current[remaining] // self._scale_every % len(self._scales)] * self._length
            stop = np.maximum((0.01 * np.minimum(tolerance[0], scale * tolerance[1])) ** 2, 1e-30)
            accept = tolerance[0] ** 2 + 8.0 * (scale * math.sin(min(tolerance[1], 3.0) / 2)) ** 2
            p = par[remaining]
            set_weighting_rows(p, scale, stop)
            q, cost, its = kernel.run(q0, p)
            rows = index[remaining]
            state.iterations[rows] += its.astype(int)
            state.attempts[rows] += ~carry
            q = self._wrap(q)
            better = cost < best_cost[remaining]
            best_cost[remaining[better]] = cost[better]
            state.q[rows[better]] = q[better]
            close = np.flatnonzero(cost <= accept)
            solved = np.zeros(len(remaining), dtype=bool)
            if len(close):
                pe, oe = self.errors(targets, rows[close], q[close])
                inside = np.all((q[close] >= self._lower) & (q[close] <= self._upper), axis=1)
                good = (pe <= tolerance[0]) & (oe <= tolerance[1]) & inside
                done = rows[close[good]]
                state.success[done] = True
                state.attempt[done] = current[remaining[close[good]]]
                state.q[done] = q[close[good]]
                state.position_error[done], state.orientation_error[done] = pe[good], oe[good]
                solved[close[good]] = True
            # Attempts still converging (slowly, near a singularity) go on from where they are.
            going = ~solved & (cost < (0.01 * scale) ** 2) & (its >= self._chunk * self._max_chunks)
            going &= continued[remaining] < MAX_CONTINUATIONS
            carried[remaining] = going
            continued[remaining] = np.where(going, continued[remaining] + 1, 0)
            last_q[remaining[going]] = q[going]
            remaining = remaining[~solved]
        failed = index[~state.success[index]]
        state.position_error[failed], state.orientation_error[failed] = self.errors(targets, failed, state.q[failed])

    def _starts(
        self,
        kind: str,
        targets: BatchTargets,
        index: np.ndarray,
        fresh: np.ndarray,
        restart: np.ndarray,
        seeds: np.ndarray | None,
        rng: np.random.Generator | None,
        nearest: np.ndarray,
    ) -> np.ndarray:
        """Starting configurations of fresh attempts: the seed (restart -1), else restart configurations.

        Restart j < NEAREST of a target is its j-th nearest restart configuration in target
        space, later ones the restart configurations in order; with an `rng`, fresh draws.
        """
        q0 = np.empty((len(fresh), self.robot.dof))
        use_seed = restart < 0
        if use_seed.any():
            q0[use_seed] = seeds[index[fresh[use_seed]]]
        if rng is not None:
            q0[~use_seed] = self.robot.random_configurations(rng, int(np.sum(~use_seed)))
            return q0
        first = restart == 0
        if first.any():
            nearest[fresh[first]] = self._nearest_restarts(kind, targets, index[fresh[first]])
        near = (restart >= 0) & (restart < nearest.shape[1])
        if near.any():
            q0[near] = self._restarts[nearest[fresh[near], restart[near]]]
        later = restart >= nearest.shape[1]
        if later.any():
            q0[later] = self._restarts[(restart[later] - nearest.shape[1]) % len(self._restarts)]
        return q0
