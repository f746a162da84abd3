"""The batched damped Gauss-Newton kernel: one compiled CasADi function per robot and target kind.

The tip residual (the position error, plus for a pose the errors of the tip's x and z axes,
or for an approach pitch the errors of the approach axis's vertical and horizontal parts, the
horizontal one counted negative while it points against the outward side; see
``planner.geometry.target``) is built symbolically from
:class:`~planner.ik.numeric.kinematics.CasadiKinematics`, orientation rows weighted by a length
[m] of the arm. A Levenberg-Marquardt step ``dq = -(J^T J + (1e-6 + |r|^2) I)^-1 J^T r``
(solved by a symbolic LDL^T factorisation), shortened to at most ``max_step`` and then clamped
into the joint limits, so every iterate and every returned ``q`` lies within the limits, is
mapped over a batch of seeds (8 by default). Steps run in chunks of 5; the function skips the
remaining chunks as soon as one seed has converged (its squared residual below the stop
threshold), so an easy target costs a few iterations.

The function is compiled to C (:mod:`planner.ik.numeric.codegen`) and called through a
:class:`Kernel`, which binds numpy buffers to its inputs and outputs once, so a call converts
nothing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import casadi as ca
import numpy as np

from planner.exceptions import InvalidArgumentError
from planner.geometry.target import RADIAL_EPS, Target
from planner.ik.numeric.codegen import compile_function
from planner.ik.numeric.kinematics import CasadiKinematics

__all__ = [
    "KERNEL_KINDS",
    "SEARCH_DAMPING",
    "SEARCH_MAX_STEP",
    "VERTICAL",
    "Kernel",
    "SequentialKernel",
    "outward_direction",
]

#: The target kinds a kernel is built for.
KERNEL_KINDS = ("position", "pose", "pitch")
#: |cos(pitch)| at or below which a pitch target is straight up or down (one direction).
VERTICAL = 1e-12
#: Levenberg-Marquardt damping per unit squared residual of a single call's first stage
#: (:class:`SequentialKernel`) and of :func:`step_functions`; the batched :class:`Kernel` uses 1.
SEARCH_DAMPING = 0.03
#: Longest joint step [rad or m] of one iteration of the first stage.
SEARCH_MAX_STEP = 1.5

# Kernel parameters: target position 3, rotation 9 (column-major), outward direction 3,
# sin(pitch) 1, |cos(pitch)| 1, searches allowed 1 (sequential kernel), stop threshold 1,
# orientation weight [m] 1.
_N_PARAMS = 20
_SEARCHES = 17
_STOP = 18
_SEARCH_BLOCK = 8  # later searches of a sequential kernel per switch
_SCALE = 19


def outward_direction(target: Target) -> np.ndarray:
    """Unit horizontal direction the approach axis of a pitch target must not point against.

    Away from the base z axis (towards it for ``|pitch| > pi/2``); zero where any direction
    will do: the target on the base z axis, or a straight up or down pitch.

    Returns:
        Shape (3,), in the base frame.
    """
    x, y = float(target.position[0]), float(target.position[1])
    radial = math.hypot(x, y)
    cos_p = math.cos(float(target.pitch))
    if radial <= RADIAL_EPS or abs(cos_p) <= VERTICAL:
        return np.zeros(3)
    sign = 1.0 if cos_p > 0.0 else -1.0
    return np.array([sign * x / radial, sign * y / radial, 0.0])


def _ldl_solve(matrix: ca.SX, rhs: ca.SX) -> ca.SX:
    """Solve a symmetric positive definite system symbolically by LDL^T (no square roots)."""
    n = matrix.shape[0]
    lower = [[ca.SX(0)] * n for _ in range(n)]
    diag = [ca.SX(0)] * n
    for j in range(n):
        diag[j] = matrix[j, j] - sum((lower[j][k] ** 2 * diag[k] for k in range(j)), ca.SX(0))
        for i in range(j + 1, n):
            lower[i][j] = (
                matrix[i, j] - sum((lower[i][k] * lower[j][k] * diag[k] for k in range(j)), ca.SX(0))
            ) / diag[j]
    y = [ca.SX(0)] * n
    for i in range(n):
        y[i] = rhs[i] - sum((lower[i][k] * y[k] for k in range(i)), ca.SX(0))
    x = [ca.SX(0)] * n
    for i in reversed(range(n)):
        x[i] = y[i] / diag[i] - sum((lower[k][i] * x[k] for k in range(i + 1, n)), ca.SX(0))
    return ca.vertcat(*x)


def _residual(kinematics: CasadiKinematics, kind: str, q: ca.SX, par: ca.SX) -> ca.SX:
    """The tip residual of a target kind, orientation rows weighted by ``par[_SCALE]`` [m]."""
    position, rotation, _ = kinematics.expressions(q)
    rows = [position - par[0:3]]
    s = par[_SCALE]
    if kind == "pose":
        goal = ca.reshape(par[3:12], 3, 3)
        # Two axes fix a rotation; the third row would only add work.
        rows += [s * (rotation[:, 0] - goal[:, 0]), s * (rotation[:, 2] - goal[:, 2])]
    elif kind == "pitch":
        # Elevation: the approach axis's vertical part sin(pitch) and horizontal length
        # |cos(pitch)| (their errors make the chord of the elevation error, well
        # conditioned at any pitch); a horizontal part pointing against the outward side
        # counts negative, so for an arm whose plane holds the base axis the residual is
        # that of the one approach direction, without a local minimum pointing inward.
        a = ca.mtimes(rotation, ca.DM(np.array(kinematics.robot.approach_axis)))
        horizontal = ca.sqrt(a[0] * a[0] + a[1] * a[1] + 1e-30)
        outward = ca.dot(a, par[12:15])
        rows += [s * (a[2] - par[15]), s * (horizontal - par[16] + 2.0 * ca.fmin(outward, 0.0))]
    return ca.vertcat(*rows)


def _symbolic_kernel(
    kinematics: CasadiKinematics,
    kind: str,
    batch_size: int,
    lower: np.ndarray,
    upper: np.ndarray,
    chunk: int,
    max_chunks: int,
    max_step: float,
) -> ca.Function:
    """The batched solver ``(q0 (dof, batch), par) -> (q, cost (batch,), iterations)``."""
    n, k = kinematics.dof, batch_size
    q = ca.SX.sym("q", n)
    par = ca.SX.sym("par", _N_PARAMS)
    r = _residual(kinematics, kind, q, par)
    jac = ca.jacobian(r, q)
    cost = ca.dot(r, r)
    step = -_ldl_solve(ca.mtimes(jac.T, jac) + (1e-6 + cost) * ca.SX.eye(n), ca.mtimes(jac.T, r))
    step = step * ca.fmin(1.0, max_step / (ca.norm_2(step) + 1e-300))
    q_next = ca.fmin(ca.fmax(q + step, ca.DM(lower)), ca.DM(upper))
    step_f = ca.Function("gn_step", [q, par], [q_next]).map("gn_steps", "serial", k, [1], [])
    cost_f = ca.Function("gn_cost", [q, par], [cost]).map("gn_costs", "serial", k, [1], [])

    x_in = ca.MX.sym("q", n, k)
    p_in = ca.MX.sym("par", _N_PARAMS)
    x = x_in
    for _ in range(chunk):
        x = step_f(x, p_in)
    run_chunk = ca.Function("gn_chunk", [x_in, p_in], [x])
    keep = ca.Function("gn_keep", [x_in, p_in], [x_in])
    # A switch evaluates only the branch taken: converged batches skip the rest.
    maybe_chunk = ca.Function.if_else("gn_maybe_chunk", keep, run_chunk)
    x = x_in
    iterations = ca.MX(0)
    for _ in range(max_chunks):
        done = ca.mmin(cost_f(x, p_in)) < p_in[_STOP]
        x = maybe_chunk(done, x, p_in)
        iterations = iterations + ca.if_else(done, 0, chunk)
    return ca.Function(
        f"gn_{kind}_{n}x{k}",
        [x_in, p_in],
        [x, cost_f(x, p_in), iterations],
        ["q0", "par"],
        ["q", "cost", "iterations"],
    )


def _turn_nearest(q: ca.SX, ref: ca.SX, lower: np.ndarray, upper: np.ndarray, angular: np.ndarray) -> ca.SX:
    """`q` with each angle shifted by whole turns towards `ref` where the limits allow (same pose)."""
    out = []
    for j in range(q.shape[0]):
        if not angular[j]:
            out.append(q[j])
            continue
        turns = ca.floor((ref[j] - q[j]) / (2 * math.pi) + 0.5)
        best = q[j]
        for k in (turns, turns - 1, turns + 1):
            shifted = q[j] + 2 * math.pi * k
            better = (
                (shifted >= lower[j]) * (shifted <= upper[j]) * (ca.fabs(shifted - ref[j]) < ca.fabs(best - ref[j]))
            )
            best = ca.if_else(better, shifted, best)
        out.append(best)
    return ca.vertcat(*out)


def _symbolic_sequential(
    kinematics: CasadiKinematics,
    kind: str,
    searches: int,
    lower: np.ndarray,
    upper: np.ndarray,
    chunk: int,
    chunks: int,
    max_step: float,
    damping: float,
    give_up: Sequence[tuple[int, float]],
    continuous: np.ndarray,
    angular: np.ndarray,
    pool: np.ndarray,
    pool_poses: np.ndarray,
) -> ca.Function:
    """Searches one after another: ``(q0, par, pooled) -> (q, q_near, cost, iterations, search)``.

    ``q0`` has shape (dof, searches), ``pooled`` (searches,).

    Search s starts from column s of `q0` and runs up to `chunks` chunks of `chunk` steps (after
    k chunks, only while its squared residual is at most t, for each (k, t) in `give_up`); the next
    search starts only while none has converged (squared residual below ``par[_STOP]``) and s
    is below ``par[_SEARCHES]``. Where ``pooled[s]`` is nonzero, search s starts instead from
    the configuration of group s - 1 of `pool` (rows ``(s - 1) * G`` to ``s * G``, G = its
    rows // (searches - 1)) whose tip pose (`pool_poses`: position, x axis, z axis) is nearest
    the target. ``q`` is the lowest-residual end point, continuous joints
    wrapped into [-pi, pi); ``q_near`` is ``q`` with its angles shifted by whole turns towards
    column 0 of `q0` (the seed) where the limits allow.
    """
    n = kinematics.dof
    q = ca.SX.sym("q", n)
    par = ca.SX.sym("par", _N_PARAMS)
    r = _residual(kinematics, kind, q, par)
    jac = ca.jacobian(r, q)
    cost = ca.dot(r, r)
    step = -_ldl_solve(ca.mtimes(jac.T, jac) + (1e-6 + damping * cost) * ca.SX.eye(n), ca.mtimes(jac.T, r))
    step = step * ca.fmin(1.0, max_step / (ca.norm_2(step) + 1e-300))
    q_next = ca.fmin(ca.fmax(q + step, ca.DM(lower)), ca.DM(upper))
    step_f = ca.Function("sq_step", [q, par], [q_next])
    cost_f = ca.Function("sq_cost", [q, par], [cost])
    ref = ca.SX.sym("ref", n)
    wrapped = ca.vertcat(
        *[q[j] - 2 * math.pi * ca.floor((q[j] + math.pi) / (2 * math.pi)) if continuous[j] else q[j] for j in range(n)]
    )
    finish_f = ca.Function("sq_finish", [q, ref], [wrapped, _turn_nearest(wrapped, ref, lower, upper, angular)])

    x_in = ca.MX.sym("x", n)
    c_in = ca.MX.sym("c")
    p_in = ca.MX.sym("par", _N_PARAMS)
    x = x_in
    for _ in range(chunk):
        x = step_f(x, p_in)
    run_chunk = ca.Function("sq_chunk", [x_in, c_in, p_in], [x, cost_f(x, p_in)])
    keep = ca.Function("sq_keep", [x_in, c_in, p_in], [x_in, c_in])
    maybe_chunk = ca.Function.if_else("sq_maybe_chunk", keep, run_chunk)
    # One search: its chunks, each skipped once converged or, from chunk k on, while the squared
    # residual stays above t for a (k, t) of `give_up` (far from converging); its iterations.
    x, c, its = x_in, c_in, ca.MX(0)
    for i in range(chunks):
        done = c < p_in[_STOP]
        for after, threshold in give_up:
            if i >= after:
                done = done + (c > threshold)
        x, c = maybe_chunk(done, x, c, p_in)
        its = its + ca.if_else(done, 0, chunk)
    search_f = ca.Function("sq_search", [x_in, c_in, p_in], [x, c, its])
    # A later search starts (from s_in) only while none has converged: a converged batch
    # costs one switch per remaining search.
    # Its start: s_in, or (pooled) the configuration of a group of the pool whose tip pose is
    # nearest the target (position, and for a pose the x and z axes weighted by par[_SCALE]).
    group = pool_poses.shape[0] // max(searches - 1, 1)
    poses_in = ca.SX.sym("poses", 9, group)
    configs_in = ca.SX.sym("configs", n, group)
    par_sx = ca.SX.sym("par", _N_PARAMS)
    goal = ca.reshape(par_sx[3:12], 3, 3)
    pick, nearest = configs_in[:, 0], ca.SX(np.inf)
    for j in range(group):
        d = ca.sumsqr(poses_in[0:3, j] - par_sx[0:3])
        if kind == "pose":
            d = d + par_sx[_SCALE] ** 2 * (
                ca.sumsqr(poses_in[3:6, j] - goal[:, 0]) + ca.sumsqr(poses_in[6:9, j] - goal[:, 2])
            )
        pick = ca.if_else(d < nearest, configs_in[:, j], pick)
        nearest = ca.fmin(d, nearest)
    pick_f = ca.Function("sq_pick", [par_sx, poses_in, configs_in], [pick])
    s_in = ca.MX.sym("s", n)
    pooled_in = ca.MX.sym("pooled")
    poses_mx, configs_mx = ca.MX.sym("poses", 9, group), ca.MX.sym("configs", n, group)
    start = ca.if_else(pooled_in, pick_f(p_in, poses_mx, configs_mx), s_in)
    fresh = search_f(start, cost_f(start, p_in), p_in)
    inputs = [x_in, c_in, p_in, s_in, pooled_in, poses_mx, configs_mx]
    run_search = ca.Function("sq_fresh", inputs, [*fresh, ca.MX(1)])
    stay = ca.Function("sq_stay", inputs, [x_in, c_in, ca.MX(0), ca.MX(0)])
    maybe_search = ca.Function.if_else("sq_maybe_search", stay, run_search)

    # The later searches in blocks of `block`: a block starts only while none has converged,
    # so a converged call skips the rest at one switch per block.
    block = _SEARCH_BLOCK if (searches - 1) % _SEARCH_BLOCK == 0 else 1
    bx, bc, bbx, bbc = ca.MX.sym("x", n), ca.MX.sym("c"), ca.MX.sym("best_x", n), ca.MX.sym("best_c")
    b_first = ca.MX.sym("first")  # index of the block's first search
    b_q0, b_pooled = ca.MX.sym("q0", n, block), ca.MX.sym("pooled", block)
    b_poses, b_configs = ca.MX.sym("poses", 9, group * block), ca.MX.sym("configs", n, group * block)
    x, c, best_x, best_c, its_b, last = bx, bc, bbx, bbc, ca.MX(0), ca.MX(0)
    for b in range(block):
        idle = (c < p_in[_STOP]) + (p_in[_SEARCHES] <= b_first + b)
        cols = slice(b * group, (b + 1) * group)
        x, c, its, ran = maybe_search(idle, x, c, p_in, b_q0[:, b], b_pooled[b], b_poses[:, cols], b_configs[:, cols])
        its_b, last = its_b + its, last + ran
        lower_cost = c < best_c
        best_x, best_c = ca.if_else(lower_cost, x, best_x), ca.fmin(c, best_c)
    b_inputs = [bx, bc, bbx, bbc, p_in, b_first, b_q0, b_pooled, b_poses, b_configs]
    run_block = ca.Function("sq_block", b_inputs, [x, c, best_x, best_c, its_b, last])
    skip_block = ca.Function("sq_skip", b_inputs, [bx, bc, bbx, bbc, ca.MX(0), ca.MX(0)])
    maybe_block = ca.Function.if_else("sq_maybe_block", skip_block, run_block)

    q0 = ca.MX.sym("q0", n, searches)
    pooled = ca.MX.sym("pooled", searches)
    x, c, iterations = search_f(q0[:, 0], cost_f(q0[:, 0], p_in), p_in)
    best_x, best_c = x, c
    search = ca.MX(0)
    for first in range(1, searches, block):
        idle = (c < p_in[_STOP]) + (p_in[_SEARCHES] <= first)
        cols = slice(first, first + block)
        rows = slice((first - 1) * group, (first - 1 + block) * group)
        x, c, best_x, best_c, its, ran = maybe_block(
            idle, x, c, best_x, best_c, p_in, first, q0[:, cols], pooled[cols],
            ca.DM(pool_poses[rows].T), ca.DM(pool[rows].T),
        )  # fmt: skip
        iterations = iterations + its
        search = search + ran
    q_out, q_near = finish_f(best_x, q0[:, 0])
    return ca.Function(
        f"sq_{kind}_{n}x{searches}",
        [q0, p_in, pooled],
        [q_out, q_near, best_c, iterations, search],
        ["q0", "par", "pooled"],
        ["q", "q_near", "cost", "iterations", "search"],
    )


class Kernel:
    """A batched solver function with numpy buffers bound to it (no conversion per call).

    Fill :attr:`q0` and the parameters (:meth:`set_target`, :meth:`set_weighting`), call the
    kernel, read :attr:`q`, :attr:`cost` and :attr:`iterations`.

    Attributes:
        function: The CasADi function (compiled or not).
        compiled: Whether it runs as compiled C code.
        q0: Starting configurations, shape (batch, dof) [rad or m]; row k is seed k.
        par: The parameter vector (target, stop threshold, orientation weight).
        q: Final configurations, shape (batch, dof) [rad or m], within the limits.
        cost: Squared weighted residual of each row of :attr:`q`, shape (batch,).
        iterations: Gauss-Newton steps run per seed, shape (1,).
    """

    def __init__(self, function: ca.Function, batch: int, dof: int, compiled: bool) -> None:
        """Bind buffers of a batch of `batch` seeds of `dof` joints to `function`."""
        self.function = function
        self.compiled = compiled
        # Row k of a C-ordered (batch, dof) array is seed k: CasADi's column-major (dof, batch).
        self.q0 = np.zeros((batch, dof))
        self.par = np.zeros(_N_PARAMS)
        self.q = np.zeros((batch, dof))
        self.cost = np.zeros(batch)
        self.iterations = np.zeros(1)
        self._buffer, self._evaluate = function.buffer()
        self._buffer.set_arg(0, memoryview(self.q0))
        self._buffer.set_arg(1, memoryview(self.par))
        self._buffer.set_res(0, memoryview(self.q))
        self._buffer.set_res(1, memoryview(self.cost))
        self._buffer.set_res(2, memoryview(self.iterations))

    @classmethod
    def build(
        cls,
        kinematics: CasadiKinematics,
        kind: str,
        *,
        batch_size: int,
        lower: np.ndarray,
        upper: np.ndarray,
        chunk: int,
        max_chunks: int,
        max_step: float,
        jit: bool,
    ) -> Kernel:
        """Build (and compile, or load from the cache) the kernel of one target kind.

        Args:
            kinematics: The robot's symbolic kinematics.
            kind: ``"position"``, ``"pose"`` or ``"pitch"``.
            batch_size: Seeds per call.
            lower: Finite lower joint limits, shape (dof,) [rad or m].
            upper: Finite upper joint limits, shape (dof,) [rad or m].
            chunk: Gauss-Newton steps between two convergence checks.
            max_chunks: Chunks per call at most.
            max_step: Longest joint step of one iteration [rad or m].
            jit: Compile to C (:func:`~planner.ik.numeric.codegen.compile_function`).

        Raises:
            InvalidArgumentError: On an unknown target kind.
        """
        if kind not in KERNEL_KINDS:
            raise InvalidArgumentError(f"unknown target kind {kind!r}; valid: {', '.join(KERNEL_KINDS)}")
        symbolic = _symbolic_kernel(kinematics, kind, batch_size, lower, upper, chunk, max_chunks, max_step)
        function = compile_function(symbolic) if jit else symbolic
        return cls(function, batch_size, kinematics.dof, function is not symbolic)

    def set_target(self, target: Target) -> None:
        """Write a target into the parameters (clears the stop threshold and the weight)."""
        par = self.par
        par[:] = 0.0
        par[0:3] = target.position
        if target.rotation is not None:
            par[3:12] = target.rotation.ravel(order="F")
        elif target.pitch is not None:
            par[12:15] = outward_direction(target)
            par[15] = math.sin(target.pitch)
            par[16] = abs(math.cos(target.pitch))

    def set_weighting(self, scale: float, stop: float) -> None:
        """Set the orientation weight [m] and the stop threshold on the squared residual.

        A negative `stop` never stops early: every chunk runs.
        """
        self.par[_SCALE] = scale
        self.par[_STOP] = stop

    def __call__(self) -> None:
        """Run the batch from :attr:`q0` into :attr:`q`, :attr:`cost` and :attr:`iterations`."""
        self._evaluate()
        if self._buffer.ret() != 0:
            raise RuntimeError(f"CasADi function {self.function.name()!r} failed (code {self._buffer.ret()})")


class SequentialKernel(Kernel):
    """Searches one after another in one compiled call, with numpy buffers bound to it.

    The fast first stage of :class:`~planner.ik.numeric.solver.NlpIK`: search s starts from row
    s of :attr:`q0` and runs only while no earlier one has converged, so an easy target costs
    one search of a few iterations. Fill :attr:`q0` and the parameters (:meth:`set_target`,
    :meth:`set_weighting`, :meth:`set_searches`), call it, read :attr:`q`, :attr:`q_near`,
    :attr:`cost`, :attr:`iterations` and :attr:`search`.

    Attributes:
        function: The CasADi function (compiled or not).
        compiled: Whether it runs as compiled C code.
        q0: Starting configurations, shape (searches, dof) [rad or m]; row s starts search s
            unless :attr:`pooled` says otherwise.
        par: The parameter vector.
        pooled: Shape (searches,): where nonzero, search s starts instead from the configuration
            of the pool's group s - 1 whose tip pose is nearest the target (row 0 ignores it).
        q: The end point of lowest residual, shape (dof,) [rad or m], within the limits,
            continuous joints wrapped into [-pi, pi).
        q_near: :attr:`q` with its angles shifted by whole turns towards row 0 of :attr:`q0`
            where the limits allow, shape (dof,).
        cost: Squared weighted residual of :attr:`q`, shape (1,).
        iterations: Gauss-Newton steps run in all, shape (1,).
        search: Index of the last search run (the converged one when one has), shape (1,).
    """

    def __init__(self, function: ca.Function, searches: int, dof: int, compiled: bool) -> None:
        """Bind buffers of `searches` starts of `dof` joints to `function`."""
        self.function = function
        self.compiled = compiled
        self.q0 = np.zeros((searches, dof))
        self.par = np.zeros(_N_PARAMS)
        self.pooled = np.zeros(searches)
        self.q = np.zeros(dof)
        self.q_near = np.zeros(dof)
        self.cost = np.zeros(1)
        self.iterations = np.zeros(1)
        self.search = np.zeros(1)
        self._buffer, self._evaluate = function.buffer()
        self._buffer.set_arg(0, memoryview(self.q0))
        self._buffer.set_arg(1, memoryview(self.par))
        self._buffer.set_arg(2, memoryview(self.pooled))
        for i, out in enumerate((self.q, self.q_near, self.cost, self.iterations, self.search)):
            self._buffer.set_res(i, memoryview(out))
        self._position = self.par[0:3]
        self._rotation = self.par[3:12].reshape((3, 3), order="F")  # a view: column-major like CasADi

    @classmethod
    def build_sequential(
        cls,
        kinematics: CasadiKinematics,
        kind: str,
        *,
        searches: int,
        lower: np.ndarray,
        upper: np.ndarray,
        chunk: int,
        chunks: int,
        max_step: float,
        damping: float,
        give_up: Sequence[tuple[int, float]],
        continuous: np.ndarray,
        angular: np.ndarray,
        pool: np.ndarray,
        pool_poses: np.ndarray,
        jit: bool,
    ) -> SequentialKernel:
        """Build (and compile, or load from the cache) the sequential kernel of one target kind.

        Args:
            kinematics: The robot's symbolic kinematics.
            kind: ``"position"``, ``"pose"`` or ``"pitch"``.
            searches: Starts per call at most.
            lower: Finite lower joint limits, shape (dof,) [rad or m].
            upper: Finite upper joint limits, shape (dof,) [rad or m].
            chunk: Gauss-Newton steps between two convergence checks.
            chunks: Chunks per search at most.
            max_step: Longest joint step of one iteration [rad or m].
            damping: Levenberg-Marquardt damping per unit squared residual (the damping is
                ``1e-6 + damping * |r|^2``).
            give_up: Pairs (k, t): after k chunks, a search whose squared residual is above t
                [m^2] stops (it is unlikely to converge: the next start is tried).
            continuous: Which joints are continuous (wrapped into [-pi, pi)), shape (dof,).
            angular: Which joints are angles (shifted by whole turns), shape (dof,).
            pool: Configurations within the limits, shape (G * (searches - 1), dof): the
                pooled starts (see :attr:`pooled`), G per search.
            pool_poses: Their tip poses, shape (G * (searches - 1), 9): position [m], x
                axis, z axis in the base frame.
            jit: Compile to C (:func:`~planner.ik.numeric.codegen.compile_function`).

        Raises:
            InvalidArgumentError: On an unknown target kind.
        """
        if kind not in KERNEL_KINDS:
            raise InvalidArgumentError(f"unknown target kind {kind!r}; valid: {', '.join(KERNEL_KINDS)}")
        symbolic = _symbolic_sequential(
            kinematics, kind, searches, lower, upper, chunk, chunks, max_step, damping, give_up,
            continuous, angular, pool, pool_poses,
        )  # fmt: skip
        function = compile_function(symbolic) if jit else symbolic
        return cls(function, searches, kinematics.dof, function is not symbolic)

    def set_target(self, target: Target) -> None:
        """Write a target into the parameters (the stop threshold and weight are kept).

        Through views of the parameter vector: a call per target costs two copies.
        """
        self._position[:] = target.position
        if target.rotation is not None:
            self._rotation[:] = target.rotation
        elif target.pitch is not None:
            par = self.par
            par[12:15] = outward_direction(target)
            par[15] = math.sin(target.pitch)
            par[16] = abs(math.cos(target.pitch))

    def __call__(self) -> None:
        """Run the searches from :attr:`q0` into :attr:`q`, :attr:`q_near` and the counts."""
        self._evaluate()
        # Compiled code of plain arithmetic cannot fail; CasADi's virtual machine reports here.
        if not self.compiled and self._buffer.ret() != 0:
            raise RuntimeError(f"CasADi function {self.function.name()!r} failed (code {self._buffer.ret()})")

    def set_searches(self, count: int) -> None:
        """Run at most `count` searches (rows of :attr:`q0`) in the next call."""
        self.par[_SEARCHES] = count


#: Length of a kernel's parameter vector (:meth:`Kernel.set_target` and :func:`target_parameters`).
N_PARAMS = _N_PARAMS
#: Where the stop threshold and the orientation weight [m] sit in a parameter vector.
PARAM_STOP, PARAM_SCALE = _STOP, _SCALE


def step_functions(
    kinematics: CasadiKinematics,
    kind: str,
    lower: np.ndarray,
    upper: np.ndarray,
    max_step: float,
    damping: float = SEARCH_DAMPING,
) -> tuple[ca.Function, ca.Function]:
    """The damped Gauss-Newton step of one configuration and its squared residual.

    By default that of a single call's first stage (:class:`SequentialKernel`, damping
    :data:`SEARCH_DAMPING`), so that other drivers of the same iteration
    (:mod:`planner.ik.numeric.batch` maps them over many targets) reach the same answer from
    the same seed.

    Args:
        kinematics: The robot's symbolic kinematics.
        kind: ``"position"``, ``"pose"`` or ``"pitch"``.
        lower: Finite lower joint limits, shape (dof,) [rad or m].
        upper: Finite upper joint limits, shape (dof,) [rad or m].
        max_step: Longest joint step of one iteration [rad or m].
        damping: Levenberg-Marquardt damping per unit squared residual (``1e-6 + damping |r|^2``).

    Returns:
        ``(step, cost)``: ``step(q (dof,), par (N_PARAMS,)) -> q_next`` (within the limits) and
        ``cost(q, par) -> |r|^2``.

    Raises:
        InvalidArgumentError: On an unknown target kind.
    """
    if kind not in KERNEL_KINDS:
        raise InvalidArgumentError(f"unknown target kind {kind!r}; valid: {', '.join(KERNEL_KINDS)}")
    n = kinematics.dof
    q = ca.SX.sym("q", n)
    par = ca.SX.sym("par", _N_PARAMS)
    r = _residual(kinematics, kind, q, par)
    jac = ca.jacobian(r, q)
    cost = ca.dot(r, r)
    step = -_ldl_solve(ca.mtimes(jac.T, jac) + (1e-6 + damping * cost) * ca.SX.eye(n), ca.mtimes(jac.T, r))
    step = step * ca.fmin(1.0, max_step / (ca.norm_2(step) + 1e-300))
    q_next = ca.fmin(ca.fmax(q + step, ca.DM(lower)), ca.DM(upper))
    return ca.Function("gn_step", [q, par], [q_next]), ca.Function("gn_cost", [q, par], [cost])


def target_parameters(
    kind: str,
    positions: np.ndarray,
    rotations: np.ndarray | None = None,
    pitches: np.ndarray | None = None,
) -> np.ndarray:
    """The parameter vectors of N targets of one kind, as :meth:`Kernel.set_target` writes them.

    Args:
        kind: ``"position"``, ``"pose"`` or ``"pitch"``.
        positions: Shape (N, 3) [m].
        rotations: Shape (N, 3, 3), for poses.
        pitches: Shape (N,) approach pitches [rad], for pitch targets.

    Returns:
        Shape (N, N_PARAMS); the stop threshold and the orientation weight are zero
        (:func:`set_weighting_rows` sets them).
    """
    positions = np.asarray(positions, dtype=float)
    par = np.zeros((len(positions), _N_PARAMS))
    par[:, 0:3] = positions
    if kind == "pose":
        par[:, 3:12] = np.asarray(rotations, dtype=float).transpose(0, 2, 1).reshape(-1, 9)
    elif kind == "pitch":
        pitches = np.asarray(pitches, dtype=float)
        cos_p = np.cos(pitches)
        radial = np.hypot(positions[:, 0], positions[:, 1])
        free = (radial <= RADIAL_EPS) | (np.abs(cos_p) <= VERTICAL)
        scale = np.where(free, 0.0, np.sign(cos_p) / np.where(free, 1.0, radial))
        par[:, 12] = scale * positions[:, 0]
        par[:, 13] = scale * positions[:, 1]
        par[:, 15] = np.sin(pitches)
        par[:, 16] = np.abs(cos_p)
    return par


def set_weighting_rows(par: np.ndarray, scale: float, stop: float) -> None:
    """Set the orientation weight [m] and stop threshold of parameter rows (N, N_PARAMS), in place."""
    par[:, _SCALE] = scale
    par[:, _STOP] = stop
