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

import casadi as ca
import numpy as np

from planner.exceptions import InvalidArgumentError
from planner.geometry.target import RADIAL_EPS, Target
from planner.ik.numeric.codegen import compile_function
from planner.ik.numeric.kinematics import CasadiKinematics

__all__ = ["KERNEL_KINDS", "VERTICAL", "Kernel", "outward_direction"]

#: The target kinds a kernel is built for.
KERNEL_KINDS = ("position", "pose", "pitch")
#: |cos(pitch)| at or below which a pitch target is straight up or down (one direction).
VERTICAL = 1e-12

# Kernel parameters: target position 3, rotation 9 (column-major), outward direction 3,
# sin(pitch) 1, |cos(pitch)| 1, unused 1, stop threshold 1, orientation weight [m] 1.
_N_PARAMS = 20
_STOP = 18
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


#: Length of a kernel's parameter vector (:meth:`Kernel.set_target` and :func:`target_parameters`).
N_PARAMS = _N_PARAMS
#: Where the stop threshold and the orientation weight [m] sit in a parameter vector.
PARAM_STOP, PARAM_SCALE = _STOP, _SCALE


def step_functions(
    kinematics: CasadiKinematics, kind: str, lower: np.ndarray, upper: np.ndarray, max_step: float
) -> tuple[ca.Function, ca.Function]:
    """The damped Gauss-Newton step of one configuration and its squared residual, as in :class:`Kernel`.

    For other drivers of the same iteration (:mod:`planner.ik.numeric.batch` maps them over
    many targets).

    Args:
        kinematics: The robot's symbolic kinematics.
        kind: ``"position"``, ``"pose"`` or ``"pitch"``.
        lower: Finite lower joint limits, shape (dof,) [rad or m].
        upper: Finite upper joint limits, shape (dof,) [rad or m].
        max_step: Longest joint step of one iteration [rad or m].

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
    step = -_ldl_solve(ca.mtimes(jac.T, jac) + (1e-6 + cost) * ca.SX.eye(n), ca.mtimes(jac.T, r))
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
