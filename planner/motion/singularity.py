"""Singularity checks along a joint trajectory (detours around them: :mod:`planner.motion.detours`).

Closeness to a singularity is measured by the inverse condition number of the task Jacobian
(smallest over largest singular value, see :meth:`Robot.conditioning`): 1 is isotropic, 0
singular. For the pose task the Jacobian's angular rows are first multiplied by the arm's
characteristic length (:attr:`Robot.characteristic_length`, the length of its chain from the
first joint to the tip), so that a tip rotation of 1 rad weighs like a tip translation of one
arm length and the measure does not depend on the arm's size or the unit of length (with raw
``[v; omega]`` rows it does, and the old threshold 1/30 flagged about half of the random
configurations of ur5, panda and z1). That length is chosen because the kinematics alone fix
it (no sampling, no tuning per arm) and it grows with the arm like the lever arms of its base
joints; on ur5, lengths from a quarter of it to all of it separate configurations near a
singularity from the others about equally well. A configuration is *too close* when it falls
below a threshold.

The default threshold depends on the task, as the two measures reach different values: the
position rows of a 3-joint arm are often near isotropic, while a 6-joint pose Jacobian, whose
wrist joints move the tip by a few centimetres, has an inverse condition number of about 0.12
in good configurations of ur5 and panda. Defaults: a condition number of 30 for ``"position"``
(inverse 1/30) and 100 for ``"pose"`` (inverse 0.01). The pose default is calibrated on random
configurations of ur5, panda and z1 (``benchmarks/bench_singularity.py``): it flags 23 %, 15 %
and 11 % of them (the raw measure at 1/30 flagged 46 %, 38 % and 49 %), among them 96-100 %
of those within 0.05 rad of a singular configuration, and 95 % of the flagged lie within 0.16,
0.25 and 0.15 rad of one (a first-order joint-space distance). From UR5's home pose the
threshold is crossed 5 degrees from its wrist alignment (q5 = 0), 8 degrees from its stretched
elbow (q3 = 0) and 3 degrees (of q2) from its shoulder singularity. The Yoshikawa
manipulability (product of the singular values) is reported beside it.

:func:`check_singularities` measures a trajectory at its waypoints and along samples.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import NamedTuple

import numpy as np

from planner.core.arrays import read_only
from planner.core.certificates import (
    anchor_bounds,
    cholesky_certificates,
    extreme_bounds,
    grams,
    interval_certificates,
    own_certificates,
)
from planner.core.text import plain
from planner.exceptions import InvalidArgumentError
from planner.geometry.jacobian_kernel import jacobian_kernel
from planner.model.robot import Robot, Task
from planner.motion.trajectory import JointTrajectory

_EPS = float(np.finfo(float).eps)

__all__ = [
    "DEFAULT_CONDITION_NUMBER",
    "DEFAULT_CONDITION_NUMBERS",
    "SingularityReport",
    "bounded_conditioning",
    "check_singularities",
    "jacobian_change_bound",
    "jacobian_change_bounds",
    "jacobian_curvature_bound",
    "inverse_condition_threshold",
    "measure_singularities",
]

#: Default largest acceptable Jacobian condition number of the position task (inverse 1/30).
DEFAULT_CONDITION_NUMBER = 30.0

#: Default largest acceptable condition number per task (the pose Jacobian's rows scaled by
#: the arm's characteristic length; see the module docstring for the calibration).
DEFAULT_CONDITION_NUMBERS: Mapping[str, float] = MappingProxyType({"position": DEFAULT_CONDITION_NUMBER, "pose": 100.0})


def inverse_condition_threshold(threshold: float | None, task: Task = "position") -> float:
    """A checked inverse-condition-number threshold in [0, 1) (None: the task's default).

    Args:
        threshold: The threshold, or None for ``1 / DEFAULT_CONDITION_NUMBERS[task]``.
        task: The task the threshold is for (``"position"`` or ``"pose"``).

    Raises:
        InvalidArgumentError: Outside [0, 1) (the message relates it to a condition number), or
            on an unknown task.
    """
    if task not in DEFAULT_CONDITION_NUMBERS:
        raise InvalidArgumentError(f"unknown task {task!r}; valid: {', '.join(DEFAULT_CONDITION_NUMBERS)}")
    default = DEFAULT_CONDITION_NUMBERS[task]
    if threshold is None:
        return 1.0 / default
    if isinstance(threshold, bool) or not isinstance(threshold, (int, float)) or not 0.0 <= threshold < 1.0:
        raise InvalidArgumentError(
            f"threshold is an inverse condition number in [0, 1), got {plain(threshold)} "
            f"(a condition number of {default:g} is {1 / default:.6g})"
        )
    return float(threshold)


@dataclass(frozen=True)
class SingularityReport:
    """How close a trajectory comes to singularities.

    Attributes:
        threshold: Inverse condition number below which a configuration is too close.
        task: The task Jacobian used (``"position"`` or ``"pose"``).
        rate: Sampling rate of the check [Hz] (waypoint instants are always included).
        waypoint_inverse_condition: At each waypoint, shape (N,).
        waypoint_manipulability: At each waypoint, shape (N,).
        singular_waypoints: Indices of waypoints below the threshold (kept, but flagged).
        min_inverse_condition: Minimum along the sampled trajectory.
        min_manipulability: Minimum manipulability along the sampled trajectory.
        time_of_minimum: When the inverse condition number is smallest [s].
        q_at_minimum: The configuration there, shape (dof,).
        below_threshold: Time intervals ``(start, end)`` [s] spent below the threshold.
    """

    threshold: float
    task: str
    rate: float
    waypoint_inverse_condition: np.ndarray
    waypoint_manipulability: np.ndarray
    singular_waypoints: tuple[int, ...]
    min_inverse_condition: float
    min_manipulability: float
    time_of_minimum: float
    q_at_minimum: np.ndarray
    below_threshold: tuple[tuple[float, float], ...]

    @property
    def clear(self) -> bool:
        """Whether the whole sampled trajectory stays at or above the threshold."""
        return self.min_inverse_condition >= self.threshold


def _sample_times(trajectory: JointTrajectory, rate: float) -> np.ndarray:
    """The times at `rate` and the waypoint instants, sorted, each once (``np.unique`` of both, without its sort)."""
    t, w = trajectory.times(rate), np.unique(trajectory.waypoint_times)
    at = np.searchsorted(t, w)
    new = np.ones(len(w), dtype=bool)
    inside = at < len(t)
    new[inside] = t[at[inside]] != w[inside]
    return np.insert(t, at[new], w[new]) if new.any() else t


def _intervals(t: np.ndarray, low: np.ndarray) -> tuple[tuple[float, float], ...]:
    """The runs of `low` as (first, last) times."""
    if not low.any():
        return ()
    edges = np.diff(np.concatenate([[False], low, [False]]).astype(np.int8))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    return tuple((float(t[a]), float(t[b])) for a, b in zip(starts, ends))


#: Samples between the first rows :func:`bounded_conditioning` measures exactly.
ANCHOR_SPACING = 16

#: Samples between those rows where they are bracketed from the compiled Jacobian instead (cheaper
#: than an exact measure: closer together, so that fewer rows between them need their own).
BRACKETED_SPACING = 12


def jacobian_change_bounds(robot: Robot, task: Task) -> tuple[np.ndarray, float, float] | None:
    """Constants of a bound on how far the task Jacobian moves with the joints, or None.

    For an arm of turning joints in one chain to the tip, column ``i`` of the Jacobian (in the
    world-aligned tip frame) is ``[z_i x (p - o_i); z_i]``. Along a straight joint-space move
    by ``u`` its derivative is at most ``a_i = rho_i U_i + sum_{k >= i} rho_k |u_k|`` (linear
    part) and ``b_i = U_i`` (angular part), with ``U_i = sum_{k < i} |u_k|`` and ``rho_i`` the
    chain's length from joint ``i`` to the tip (a bound on ``|p - o_i|``): the joints before
    ``i`` turn the column as a whole, at an angular speed of at most ``U_i`` (``z_i`` and
    ``p - o_i`` turn together: ``(w x z) x r + z x (w x r) = w x (z x r)``), and in the
    frame of joint ``i`` only ``p`` moves, by at most ``rho_k |u_k|`` per joint ``k >= i``. So the change of the
    scaled Jacobian is at most ``sqrt(sum_i a_i^2 + L^2 b_i^2)`` in the Frobenius norm (the
    angular rows only for ``"pose"``; ``L`` the characteristic length) and of the raw one
    ``sqrt(sum_i a_i^2 + b_i^2)``.

    Returns:
        ``(rho, angular_scale, raw_angular)``: ``rho`` per joint [m], the angular rows' weights
        in the scaled and raw bounds (0 for ``"position"``); None for arms with sliding
        joints or joints off the tip's chain (their bounds use the Jacobians themselves).
    """
    model = robot.model
    if any(kind == "prismatic" for kind in robot.joint_kinds) or model.nv != robot.dof:
        return None
    frame = model.frames[robot.tip_frame_id]
    chain = [j for j in model.supports[frame.parentJoint] if j > 0]
    if chain != list(range(1, robot.dof + 1)) or any(model.joints[j].nv != 1 for j in chain):
        return None
    offsets = [float(np.linalg.norm(model.jointPlacements[j].translation)) for j in chain]
    tip = float(np.linalg.norm(frame.placement.translation))
    # rho_i: the offsets of the joints after i, then the tip's.
    rho = np.array([sum(offsets[i + 1 :]) + tip for i in range(robot.dof)]) * (1.0 + 1e-9)
    if task == "position":
        return rho, 0.0, 0.0
    return rho, robot.characteristic_length, 1.0


class _ChangeBounds:
    """Per robot, :func:`jacobian_change_bounds` by task, computed once (kept in ``robot.derived``)."""

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.by_task: dict[str, tuple[np.ndarray, float, float] | None] = {}

    def of(self, task: Task) -> tuple[np.ndarray, float, float] | None:
        if task not in self.by_task:
            self.by_task[task] = jacobian_change_bounds(self.robot, task)
        return self.by_task[task]


def jacobian_change_bound(u: np.ndarray, rho: np.ndarray, angular: float) -> np.ndarray:
    """Per row of joint changes `u` (rows, dof) [rad], the bound of :func:`jacobian_change_bounds` [m/rad].

    `rho` and `angular` as :func:`jacobian_change_bounds` returns them (its second value for
    the scaled Jacobian, its third for the raw one).
    """
    u = np.abs(u)
    before = np.cumsum(u, axis=1) - u
    after = np.cumsum((rho * u)[:, ::-1], axis=1)[:, ::-1]
    a = rho * before + after
    return np.sqrt(np.sum(a * a, axis=1) + angular * angular * np.sum(before * before, axis=1))


def jacobian_curvature_bound(u: np.ndarray, rho: np.ndarray, angular: float) -> np.ndarray:
    """Per row of joint changes `u` (rows, dof), a bound on the second derivative of the Jacobian.

    Along the straight move ``q + s u`` (s in [0, 1]) of an arm as in
    :func:`jacobian_change_bounds`, ``||d^2 J / ds^2||_F`` is at most
    ``sqrt(sum_i c_i^2 + L^2 g_i^2)``, from the derivatives of the column ``[z_i x r_i; z_i]``
    (``r_i = p - o_i``): with ``w_i = sum_{k < i} z_k u_k`` the angular velocity of joint
    ``i``'s axis (``|w_i| <= U_i = sum_{k < i} |u_k|``, ``|w_i'| <= V_i = sum_{k < i} U_k |u_k|``),
    ``z_i'' = w_i' x z_i + w_i x z_i'`` gives ``g_i = V_i + U_i^2``; ``r_i' = w_i x r_i + sum_{k >= i}
    (z_k x r_k) u_k`` is at most ``a_i`` (:func:`jacobian_change_bound`), and its derivative at most
    ``e_i = V_i rho_i + U_i a_i + sum_{k >= i} (U_k rho_k + a_k) |u_k|``; so
    ``(z x r)'' = z'' x r + 2 z' x r' + z x r''`` is at most ``c_i = g_i rho_i + 2 U_i a_i + e_i``.
    A straight line between two configurations then misses the Jacobian halfway along it by at most
    an eighth of this bound, at ``s`` by ``s (1 - s) / 2`` of it. `rho` and `angular` as for
    :func:`jacobian_change_bound` [m/rad^2].
    """
    u = np.abs(u)
    before = np.cumsum(u, axis=1) - u
    turn = np.cumsum(before * u, axis=1) - before * u
    a = rho * before + np.cumsum((rho * u)[:, ::-1], axis=1)[:, ::-1]
    tail = np.cumsum(((before * rho + a) * u)[:, ::-1], axis=1)[:, ::-1]
    g = turn + before * before
    c = g * rho + 3.0 * before * a + turn * rho + tail
    return np.sqrt(np.sum(c * c, axis=1) + angular * angular * np.sum(g * g, axis=1))


def _positive_definite(gram: np.ndarray, shift: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Whether each ``gram - shift I`` is positive definite, by a Cholesky factorisation.

    `gram` (N, k, k) holds the Gram matrices of scaled Jacobians (their eigenvalues the squared
    singular values). The factorisation in floating point gives ``LL^T = gram - shift I + E`` with
    ``|E| <= (k + 1) eps tr(gram)`` (Demmel 1989), and forming the Gram matrix rounds by as much,
    so the shift is raised by ``1e-12 tr(gram)``, thousands of times both: where every pivot is
    positive, ``gram - shift I`` is then at least ``LL^T``, every eigenvalue of `gram` exceeds
    `shift` and the product of their excesses is at least the product of the pivots. In the
    compiled loop of :func:`planner.core.certificates.cholesky_certificates`, else written out
    over the batch in NumPy (:func:`_cholesky`).

    Returns:
        The mask (N,) and the product of the pivots (0 where the mask is False).
    """
    compiled = cholesky_certificates(gram, shift)
    return compiled if compiled is not None else _cholesky(gram, shift)[:2]


def _cholesky(gram: np.ndarray, shift: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_positive_definite` in NumPy, and the factor ``L`` as (k, k, N).

    One column at a time over the batch (NumPy's own factorisation stops the batch at the first
    failure); ``L`` is meaningless where the mask is False.
    """
    k = gram.shape[1]
    g = np.ascontiguousarray(gram.transpose(1, 2, 0))  # (k, k, N): whole vectors per entry
    low = np.zeros_like(g)
    pivots = np.empty((k, len(gram)))
    margin = shift + 1e-12 * np.trace(g)
    for j in range(k):
        pivots[j] = g[j, j] - margin - (low[j, :j] * low[j, :j]).sum(axis=0)
        root = np.sqrt(np.where(pivots[j] > 0.0, pivots[j], 1.0))
        low[j, j] = root
        low[j + 1 :, j] = (g[j + 1 :, j] - (low[j + 1 :, :j] * low[j, :j]).sum(axis=1)) / root
    ok = np.all(pivots > 0.0, axis=0)
    return ok, np.where(ok, np.prod(np.where(ok, pivots, 0.0), axis=0), 0.0), low


def _extreme_bounds(gram: np.ndarray) -> np.ndarray:
    """Bounds of the extreme eigenvalues and of the determinant of each positive semi-definite `gram`.

    Those of :func:`planner.core.certificates.extreme_bounds` (compiled), else NumPy's
    eigenvalues moved by ``1e-11 tr(G)`` (far above their rounding: LAPACK's symmetric
    eigenvalues are those of ``G + E`` with ``||E||`` a small multiple of ``eps ||G||``).

    Returns:
        Shape (N, 5): ``(smallest lower, smallest upper, largest lower, largest upper, product
        lower)`` per matrix.
    """
    compiled = extreme_bounds(gram)
    if compiled is not None:
        return compiled
    values = np.linalg.eigvalsh(gram)
    spread = 1e-11 * np.abs(np.trace(gram, axis1=1, axis2=2))
    low = values - spread[:, None]
    product = np.where(np.all(low > 0.0, axis=1), np.prod(np.maximum(low, 0.0), axis=1), 0.0)
    return np.stack(
        [np.maximum(low[:, 0], 0.0), values[:, 0] + spread, low[:, -1], values[:, -1] + spread, product], axis=1
    )


def _condition_bracket(bounds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of the inverse condition number from rows of :func:`_extreme_bounds`.

    ``sqrt(lambda_min / lambda_max)`` of ``J J^T`` from its eigenvalue bounds, each widened by
    1e-9 for the rounding of the root and the division.

    Returns:
        Per row, ``(lower bound, upper bound)``: 0 where the largest eigenvalue's upper bound is
        not positive, inf where its lower bound is not (nothing shown).
    """
    l_min, h_min, l_max, h_max = bounds[:, :4].T
    with np.errstate(invalid="ignore", divide="ignore"):
        low = np.sqrt(np.maximum(l_min, 0.0) / h_max) * (1.0 - 1e-9)
        up = np.sqrt(h_min / l_max) * (1.0 + 1e-9)
    return np.where(h_max > 0.0, low, 0.0), np.where((l_max > 0.0) & np.isfinite(up), up, np.inf)


def _gram(scaled: np.ndarray) -> np.ndarray:
    """``S S^T`` of each matrix of `scaled` (or ``S^T S`` for tall ones): eigenvalues ``s_i^2``.

    In the compiled loop of :func:`planner.core.certificates.grams`, else NumPy's.
    """
    compiled = grams(scaled)
    if compiled is not None:
        return compiled
    if scaled.shape[1] <= scaled.shape[2]:
        return scaled @ scaled.transpose(0, 2, 1)
    return scaled.transpose(0, 2, 1) @ scaled


def _inverse_trace(scaled: np.ndarray) -> np.ndarray:
    """``tr(G^-1)`` of the Gram matrix of each matrix of `scaled` (inf where one is not positive definite).

    Step 2's bound of the manipulability alone (see :func:`bounded_conditioning`): where ``G -
    f^2 I`` is positive definite for the Gram matrix ``G`` of ``J_lam`` and ``f > e``, every
    singular value ``s_i`` of ``J_lam`` exceeds ``f`` and ``s_i - e >= (s_i^2 - f^2)^(1/2) (1 -
    e^2 / f^2)^(1/2)`` (the squares differ by ``(f - s_i e / f)^2``), so the row's product of singular
    values is at least the root of ``det(G - f^2 I)`` times ``(1 - e^2 / f^2)^(k / 2)``. The relative
    loss, about ``f^2 tr(G^-1) / 2 + k e^2 / (2 f^2)``, is least at ``f^2 = e (k / tr(G^-1))^(1/2)``;
    ``tr(G^-1)`` is estimated by the neighbours' larger (any estimate gives a bound).
    """
    values = np.linalg.eigvalsh(_gram(scaled))
    with np.errstate(divide="ignore"):
        return np.where(np.all(values > 0.0, axis=1), np.sum(1.0 / values, axis=1), np.inf)


def _interpolation_error(
    q: np.ndarray, rows: np.ndarray, left: np.ndarray, right: np.ndarray, bounds: tuple[np.ndarray, float]
) -> tuple[np.ndarray, np.ndarray]:
    """``lam`` and ``e`` of the rows between two exact rows, for :func:`bounded_conditioning`.

    Row ``r`` at ``lam = (r - left) / (right - left)`` lies off the straight joint-space line
    between its neighbours by ``d = q_r - ((1 - lam) q_left + lam q_right)``, so its scaled
    Jacobian is the interpolation ``(1 - lam) J_left + lam J_right`` up to
    ``e = change(d) + lam (1 - lam) / 2 curvature(q_right - q_left)`` in the Frobenius norm
    (:func:`jacobian_change_bound`, :func:`jacobian_curvature_bound`) [m/rad]. `rows` sorted, so
    that those between the same neighbours are consecutive.
    """
    rho, angular = bounds
    lam = (rows - left) / (right - left)
    # The curvature bound once per interval (the rows come sorted, grouped by their left end).
    starts = np.flatnonzero(np.concatenate([[True], left[1:] != left[:-1]]))
    counts = np.diff(np.append(starts, len(rows)))
    u = q[right[starts]] - q[left[starts]]
    curvature = np.repeat(jacobian_curvature_bound(u, rho, angular), counts)
    off = np.abs(q[rows] - (q[left] + lam[:, None] * np.repeat(u, counts, axis=0)))
    # Plus the rounding of that difference (a spacing of q at huge angles on continuous joints).
    off += 2.0 * _EPS * (np.abs(q[rows]) + np.abs(q[left]) + np.abs(q[right]))
    err = jacobian_change_bound(off, rho, angular) + 0.5 * lam * (1.0 - lam) * curvature
    return lam, err


class _RowStore:
    """Values at some rows of a long sequence, kept compactly and indexed by row.

    Writing every :data:`ANCHOR_SPACING`-th row of an (n, 6, 7) array would touch every page of
    it (a fresh allocation each measure: hundreds of page faults); only the rows written are
    stored here. Each row is written once.
    """

    def __init__(self, n: int, shape: tuple[int, ...]) -> None:
        self.slot = np.full(n, -1, dtype=np.intp)
        self.data = np.empty((0, *shape))
        self.shape = (n, *shape)

    def __setitem__(self, rows: np.ndarray, values: np.ndarray) -> None:
        self.slot[rows] = len(self.data) + np.arange(len(values))
        self.data = np.concatenate([self.data, values])

    def __getitem__(self, key: np.ndarray | tuple) -> np.ndarray:
        if isinstance(key, tuple):
            return self.data[(self.slot[key[0]], *key[1:])]
        return self.data[self.slot[key]]


class _Ends(NamedTuple):
    """Bounds at the rows that end intervals, each of shape (n,) (valid at those rows).

    Attributes:
        top: Upper bounds of the largest singular value.
        bottom: Lower bounds of the smallest.
        product: Lower bounds of the product of the singular values.
        min_up: Upper bounds of the smallest singular value.
        max_low: Lower bounds of the largest.
    """

    top: np.ndarray
    bottom: np.ndarray
    product: np.ndarray
    min_up: np.ndarray
    max_low: np.ndarray

    @classmethod
    def exact(cls, s: np.ndarray | _RowStore, n: int, at: np.ndarray) -> _Ends:
        """From the singular values `s` (largest first) at rows `at` of `n`."""
        ends = cls(*(np.zeros(n) for _ in range(5)))
        values = s[at]
        ends.top[at] = ends.max_low[at] = values[:, 0]
        ends.bottom[at] = ends.min_up[at] = values[:, -1]
        ends.product[at] = np.prod(values, axis=1)
        return ends


def _interval_bounds(
    q: np.ndarray,
    rows: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    scaled: np.ndarray | _RowStore,
    s: np.ndarray | _RowStore | _Ends,
    bounds: tuple[np.ndarray, float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lower bounds of ``s_min / s_max`` and of ``prod(s)`` over every row between two exact rows.

    One bound per interval between exact neighbours (step 0 of :func:`bounded_conditioning`),
    second order in its length. With ``D = J_right - J_left`` (scaled Jacobians, ``d = ||D||_F``),
    the interpolation ``J_lam`` has the Gram matrix ``G(lam) = (1 - lam) G_left + lam G_right -
    lam (1 - lam) D D^T`` (``J J^T``, or ``J^T J`` for tall ones), and ``lam (1 - lam) D D^T`` is
    at most ``c = d^2 / 4`` times the identity. The smallest eigenvalue is concave, so that of
    ``G(lam)`` is at least ``m2 - c`` with ``m2`` the smaller of the ends' smallest squared
    singular values; the largest singular value is convex along the line, at most the larger
    end's. The determinant is log-concave, so ``M = (1 - lam) G_left + lam G_right`` has
    ``det M >= min(det G_left, det G_right)``, its eigenvalues between ``m2`` and the larger
    end's largest, and ``det G(lam) >= det(M - c I)``, bounded below over every such ``M`` by
    :func:`_shifted_det` (at least ``min(det G_left, det G_right) (1 - c / m2)^k``: only the
    eigenvalues near ``m2`` lose much). Each row is within ``e`` of ``J_lam`` (:func:`_interpolation_error`, here
    with ``lam (1 - lam) <= 1 / 4`` and a bound of the rows' deviation from the straight line
    between the ends: ``h L^2 / 8`` for ``L`` steps whose second differences are at most ``h``);
    by Weyl's inequality its singular values are within ``e`` of ``J_lam``'s: the inverse
    condition number is at least ``(sqrt(m2 - c) - e) / (s_max + e)`` and the product of the
    singular values at least ``sqrt(det G(lam)) (1 - e / sqrt(m2 - c))^k``. The singular values
    of the ends are first moved by ``1e-9 (s_max + 1)``, far above their rounding.

    Args:
        q: All configurations, shape (n, dof).
        rows: The rows to bound, sorted, shape (n_rows,).
        left: The exact row before each of `rows` (n_rows,).
        right: The exact row after each of `rows` (n_rows,).
        scaled: Scaled Jacobians, valid at the exact rows, shape (n, m, dof).
        s: Their singular values, largest first, valid at the exact rows, shape (n, k); or bounds
            of them (:class:`_Ends`).
        bounds: ``(rho, angular)`` of :func:`jacobian_change_bounds`.

    Returns:
        Per row of `rows`: the lower bounds of the inverse condition number and of the product of
        the singular values, and an upper bound of the inverse condition number (first order in
        the interval's length: ``(s_min + d / 2 + e) / (s_max - d / 2 - e)`` from the ends' mean
        singular values, Weyl's inequality along the interpolation).
    """
    rho, angular = bounds
    k = min(scaled.shape[1:])
    if not isinstance(s, _Ends):
        s = _Ends.exact(s, len(q), np.unique(np.concatenate([left, right])))
    starts = np.flatnonzero(np.concatenate([[True], left[1:] != left[:-1]]))
    a, b = left[starts], right[starts]
    # The rows a..b deviate from the straight line between q_a and q_b by at most h L^2 / 8,
    # h their largest second difference and L = b - a (discrete maximum principle).
    bend = np.abs(np.diff(q, 2, axis=0))
    # Plus the rounding of the differences.
    bend += 2.0 * _EPS * (np.abs(q[:-2]) + 2.0 * np.abs(q[1:-1]) + np.abs(q[2:]))
    # Those of each interval alone: second differences a .. b - 2 (the odd segments dropped).
    cuts = np.stack([a, b - 1], axis=1).ravel()
    bend = np.maximum.reduceat(bend, cuts[cuts < len(bend)], axis=0)[::2]
    deviation = bend * (0.125 * (b - a) ** 2)[:, None] * (1.0 + 1e-9)
    top = np.maximum(s.top[a], s.top[b])
    margin = 1e-9 * (top + 1.0)
    err = jacobian_change_bound(deviation, rho, angular) + 0.125 * jacobian_curvature_bound(q[b] - q[a], rho, angular)
    err = err * (1.0 + 1e-9) + margin
    d = np.linalg.norm(scaled[b] - scaled[a], axis=(1, 2)) * (1.0 + 1e-9)
    smallest = np.maximum(np.minimum(s.bottom[a], s.bottom[b]) - margin, 0.0)
    m2, c = smallest * smallest, 0.25 * d * d
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma = np.sqrt(np.maximum(m2 - c, 0.0))
        inv = np.maximum(sigma - err, 0.0) / (top + margin + err)
        # prod(s_i - margin) >= prod(s_i) (1 - margin / s_min)^k.
        shift = np.where(smallest > 0.0, np.maximum(1.0 - margin / (smallest + margin), 0.0), 0.0) ** k
        product = np.minimum(s.product[a], s.product[b]) * shift
        high = top + margin
        shrink = np.where(sigma > err, np.maximum(1.0 - err / sigma, 0.0), 0.0) ** k
        man = np.sqrt(_shifted_det(k, m2, high * high, product * product, c)) * shrink
    # From above: s_min(J_lam) <= min(s_min(a) + lam d, s_min(b) + (1 - lam) d) <= (s_min(a) +
    # s_min(b) + d) / 2 and s_max(J_lam) >= (s_max(a) + s_max(b) - d) / 2 (Weyl), each moved by e.
    with np.errstate(divide="ignore", invalid="ignore"):
        top_low = 0.5 * (s.max_low[a] + s.max_low[b] - d) - margin - err
        upper = (0.5 * (s.min_up[a] + s.min_up[b] + d) + margin + err) / top_low * (1.0 + 1e-9)
    upper = np.where(top_low > 0.0, upper, np.inf)
    counts = np.diff(np.append(starts, len(rows)))
    return np.repeat(inv, counts), np.repeat(man, counts), np.repeat(upper, counts)


def _shifted_det(k: int, m2: np.ndarray, top: np.ndarray, product: np.ndarray, c: np.ndarray) -> np.ndarray:
    """A lower bound of ``det(M - c I)`` over symmetric ``M`` with eigenvalues in ``[m2, top]``, ``det M >= product``.

    ``det(M - c I) = prod(mu_i - c)`` grows with each eigenvalue ``mu_i``: it is least where
    ``prod(mu_i)`` is `product` (raised to ``m2^k``, at most ``top^k``); in ``x_i = log(mu_i)``
    it is the sum of the concave ``log(e^x - c)`` over the polytope ``sum(x_i) = log(product)``,
    ``x_i`` in ``[log(m2), log(top)]``, so least at a vertex: ``j`` eigenvalues at ``m2``,
    ``k - 1 - j`` at `top` and one between (for each ``j`` where that one is at most `top`; one
    below ``m2`` is taken at ``m2``, a point of larger product: no lower than the least). 0 where
    ``c >= m2``. The same arithmetic as the compiled ``shifted_det`` of
    :mod:`planner.core.certificates`; all arrays of one shape.
    """
    product = np.minimum(np.maximum(product, m2**k), top**k)
    least = np.full(np.shape(m2), np.inf)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for j in range(k):
            mu = product / (m2**j * top ** (k - 1 - j))
            vertex = mu <= top * (1.0 + 1e-12)
            mu = np.minimum(np.maximum(mu, m2), top)
            value = (m2 - c) ** j * (top - c) ** (k - 1 - j) * (mu - c)
            least = np.where(vertex, np.minimum(least, value), least)
    least = np.where(np.isfinite(least), least, (m2 - c) ** k)
    return np.where(m2 > c, least, 0.0)


def bounded_conditioning(
    robot: Robot, q: np.ndarray, task: Task, threshold: float, keep: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`Robot.conditioning` of a dense sequence of configurations, exact only where it matters.

    The first, the last and the rows `keep` are measured exactly (their singular values), and
    so is every :data:`ANCHOR_SPACING`-th row (an *anchor*), except where step 0 applies and the
    compiled Jacobian is at hand: there every :data:`BRACKETED_SPACING`-th row is an anchor, and
    an anchor's extreme singular values and the product of all of them are bracketed from its
    Gram matrix (:func:`_extreme_bounds`, and the pivots of
    ``G + 1e-12 tr(G) I`` for the product from above), and it is measured exactly only where
    that does not show it as below (there the rows `keep` are bracketed first as well, and
    measured at the end with the rows left open, in one batch). `keep` cuts the rows into
    stretches (ends included). Every
    other row is then shown either above the threshold and above an upper bound of an anchor's
    value (inverse condition number), or below the threshold and above such a bound in its
    stretch, and in both cases its manipulability above an upper bound of an anchor's; or else
    it is measured exactly too. An anchor's value is at least the final minimum, so a row shown
    above it is not the minimum. Each row goes through these steps until one shows it:

    0. Each interval between two anchors at once (arms where step 1 applies and the
       manipulability is a fixed factor times the product of the scaled Jacobian's singular
       values): :func:`_interval_bounds` bounds the inverse condition number and that product
       from below over every row of the interval, to second order in its length (the
       interpolated Gram matrix, concavity of its smallest eigenvalue, log-concavity of its
       determinant), and the inverse condition number from above, to first order (a whole
       interval under the threshold shows its rows below it). Far from a singularity this settles
       most rows with a few operations per interval (about 70 % of them on bench_collision's ur5
       and panda plans).
    1. Where step 0 does not apply, joint changes alone: a singular value moves by at most the spectral norm (below the
       Frobenius norm) of the change of the matrix (Weyl's inequality), and
       :func:`jacobian_change_bound` bounds ``e >= ||J - J_a||_F`` from the nearer exact row
       ``a``: the inverse condition number is at least ``(s_min(J_a) - e) / (s_max(J_a) + e)``
       and the manipulability its fixed factor times the product of ``max(s_i - e, 0)``.
    2. Where the inverse condition number is still open, the exact neighbours' Jacobians: the
       row's Jacobian is their interpolation ``J_lam`` up to ``e`` (:func:`_interpolation_error`,
       second order in the spacing); the largest singular value is at most ``s_up = (1 - lam)
       s_max(J_left) + lam s_max(J_right) + e`` (the spectral norm is convex) and the others at
       least those of ``J_lam`` less ``e``, so ``J_lam J_lam^T - f^2 I`` positive definite
       (:func:`_positive_definite`) for ``f = level s_up + e`` shows the inverse condition number
       above ``level`` (the threshold, or the smallest exact value when that is larger). There
       every ``s_i(J_lam) > f``, so ``s_i - e >= (s_i^2 - f^2)^(1/2) (1 - e^2 / f^2)^(1/2)`` and
       the manipulability is at least the root of ``det(J_lam J_lam^T - f^2 I)`` (at least the
       product of the pivots) times ``(1 - e^2 / f^2)^(k / 2)``. A row shown below the threshold
       is certified the same way above its stretch's smallest value (``f = least s_up + e``).
       Where the inverse condition number is settled and the manipulability is not, the same
       certificate with ``f^2 = e (k / tr(G^-1))^(1/2)`` (the loss's least, ``tr(G^-1)`` the
       neighbours' larger: :func:`_inverse_trace`) bounds the manipulability alone.
    3. The row's own Jacobian (the compiled one of :mod:`planner.geometry.jacobian_kernel`,
       equal to Pinocchio's to rounding): :func:`_extreme_bounds` brackets the smallest and the
       largest eigenvalue of ``J J^T`` (the squared extreme singular values) and bounds its
       determinant from below, so the inverse condition number from both sides and the
       manipulability from below; a bracket under the threshold shows the row below it.
    4. The row is measured exactly.

    Where step 0 applies and C can be compiled, steps 0 to 3 run in the loops of
    :func:`planner.core.certificates.interval_certificates` and
    :func:`~planner.core.certificates.own_certificates` (the same bounds, with each row taken
    at its projection on the line between its anchors instead of at ``lam = (r - left) / (right
    - left)``: any ``lam`` in [0, 1] gives a bound, and a row on that line, as along a straight
    joint move however it is timed, is then off it only by rounding), and step 2 also bounds the
    inverse condition number from above where step 0 did not show a row below: the Rayleigh
    quotients of ``J_lam J_lam^T`` at the neighbours' estimated extreme eigenvectors bound its
    smallest eigenvalue from above and its largest from below, and the row's singular values
    are within ``e`` of ``J_lam``'s (Weyl), so fewer rows in a dip below the threshold need
    their own Jacobian.

    In the end the rows `keep`, the row of each minimum (inverse condition number and
    manipulability) and the row of the minimum of every stretch that dips below the threshold
    hold the exact values; every other row holds lower bounds on the same side of the threshold
    as the exact value: above the threshold and both minima when above it, above its stretch's
    minimum when below it. So the minima, where they are, which rows lie below the threshold and
    where each stretch is lowest are the exact measure's.

    Args:
        robot: The robot.
        q: Configurations, shape (n, dof) [rad or m], checked.
        task: Resolved task (``"position"`` or ``"pose"``).
        threshold: Inverse condition number the rows are sorted against.
        keep: Rows measured exactly in any case, and the ends of the stretches (sorted).

    Returns:
        ``(inverse_condition_number, manipulability)``, each of shape (n,).
    """
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or len(q) == 0 or q.shape[1] != robot.dof:
        raise InvalidArgumentError(
            f"q must be a non-empty array of configurations of shape (n, {robot.dof}), got shape {q.shape}"
        )
    n = len(q)
    if keep is not None:
        keep = np.asarray(keep)
        if keep.size and (keep.dtype.kind not in "iu" or keep.min() < 0 or keep.max() >= n):
            raise InvalidArgumentError(f"keep must hold row indices in [0, {n - 1}], got {keep.tolist()}")
    dof = q.shape[1]
    m_rows = 3 if task == "position" else 6
    k = min(m_rows, dof)
    # The manipulability is a fixed factor times the product of the scaled Jacobian's singular
    # values, or of the raw Jacobian's: its bound is on the matrix it is computed from.
    divisor = robot.manipulability_divisor(task)
    scale = 1.0 if divisor is None else 1.0 / divisor
    scaled_all = _RowStore(n, (m_rows, dof))
    inv, man = np.empty(n), np.empty(n)
    # The singular values at the exact rows (the manipulability's are the scaled Jacobian's
    # where a fixed divisor relates them: one store).
    s_inv = _RowStore(n, (k,))
    s_man = s_inv if divisor is not None else _RowStore(n, (k,))
    exact = np.zeros(n, dtype=bool)

    def measure(idx: np.ndarray, raw: np.ndarray | None = None, scaled: np.ndarray | None = None) -> None:
        if raw is None or scaled is None:
            raw, scaled = robot.task_jacobians(q[idx], task)
        scaled_all[idx] = scaled
        values = robot.task_singular_values(raw, scaled, task)
        s_inv[idx] = values[0]
        if s_man is not s_inv:
            s_man[idx] = values[1]
        inv[idx], man[idx] = robot.conditioning_from(*values, task)
        exact[idx] = True

    bounds_of = np.unique(np.concatenate([[0, n - 1], [] if keep is None else np.asarray(keep)]).astype(int))
    change = robot.derived.get(_ChangeBounds, lambda: _ChangeBounds(robot)).of(task)
    kernel = jacobian_kernel(robot)
    # The anchors other than the rows `keep`: their extreme singular values bracketed from the
    # compiled Jacobian (where step 0 applies), measured exactly only if that settles nothing.
    bracketed = change is not None and divisor is not None and kernel is not None
    is_anchor = np.zeros(n, dtype=bool)
    is_anchor[:: BRACKETED_SPACING if bracketed else ANCHOR_SPACING] = True
    is_anchor[bounds_of] = True
    anchors = np.flatnonzero(is_anchor)
    # Bracketed, the rows `keep` too (measured exactly with the rows left open, in one batch),
    # where there are rows between the anchors.
    deferred = bracketed and len(anchors) < n
    if deferred:
        loose = anchors
    elif bracketed:
        is_loose = is_anchor.copy()
        is_loose[bounds_of] = False
        loose = np.flatnonzero(is_loose)
    else:
        loose = anchors[:0]
    if not deferred:
        measure(bounds_of if bracketed else anchors)  # the anchors not in `loose`
    # Deferred, every anchor is bracketed below (no exact row yet): only the anchors' entries are read.
    ends_at = _Ends(*(np.empty(n) for _ in range(5))) if deferred else _Ends.exact(s_inv, n, np.nonzero(exact)[0])
    value_up = inv.copy()  # at the anchors: an upper bound of the inverse condition number
    scaled_loose = robot.task_rows(kernel(q[loose]), task)[1] if len(loose) else None
    if scaled_loose is not None:
        scaled_all[loose] = scaled_loose
    bracketed_anchors = anchor_bounds(scaled_loose, scale) if scaled_loose is not None else None
    if bracketed_anchors is not None:
        top, bottom, product, min_up, max_low, loose_low, value_up[loose], man_up = bracketed_anchors.T
        ends_at.top[loose], ends_at.bottom[loose], ends_at.product[loose] = top, bottom, product
        ends_at.min_up[loose], ends_at.max_low[loose] = min_up, max_low
    elif len(loose):
        gram = _gram(scaled_all[loose])
        brackets = _extreme_bounds(gram)
        l_min, h_min, l_max, h_max, l_product = brackets.T
        # The determinant from above: the pivots of G + 1e-12 tr(G) I (the factorisation's
        # rounding, far below that shift, keeps the factored matrix above G).
        trace = np.trace(gram, axis1=1, axis2=2)
        ok, h_product = _positive_definite(gram, -2e-12 * trace)
        man_up = np.where(ok, np.sqrt(h_product) * (1.0 + 1e-9) * scale, np.inf)
        ends_at.top[loose], ends_at.min_up[loose] = np.sqrt(h_max), np.sqrt(h_min)
        ends_at.bottom[loose], ends_at.max_low[loose] = np.sqrt(np.maximum(l_min, 0.0)), np.sqrt(np.maximum(l_max, 0.0))
        ends_at.product[loose] = np.sqrt(np.maximum(l_product, 0.0))
        loose_low, value_up[loose] = _condition_bracket(brackets)
    rows = np.flatnonzero(~is_anchor)
    if not len(rows) and not len(loose):
        return inv, man
    # Every row shown above these is above an exact value (the final minimum is no larger).
    level = max(threshold, float(np.min(value_up[anchors])))
    level_man = min(
        float(np.min(man[exact], initial=np.inf)), float(np.min(man_up, initial=np.inf)) if len(loose) else np.inf
    )
    lifted = level * (1.0 + 1e-9)  # what a certificate shows the rows to be above
    ends = anchors
    # The stretches between the rows `keep`: the smallest exact value in each (ends included),
    # over the anchors from one row of `keep` to the next (the rows `keep` are anchors).
    at_ends, values = np.searchsorted(ends, bounds_of), value_up[ends]
    least_of = np.minimum(np.minimum.reduceat(values, at_ends[:-1]), values[at_ends[1:]])

    def weyl(take: np.ndarray, a: np.ndarray, e: np.ndarray, e_man: np.ndarray) -> None:
        # Rounding of the SVDs and norms: a margin far above it.
        e = e + 1e-9 * (s_inv[a, 0] + 1.0)
        e_man = e_man + 1e-9 * (s_man[a, 0] + 1.0)
        lo_inv[take] = np.maximum(lo_inv[take], np.maximum(s_inv[a, -1] - e, 0.0) / (s_inv[a, 0] + e))
        low = np.prod(np.maximum(s_man[a] - e_man[:, None], 0.0), axis=1) * (scale * (1.0 - 1e-9))
        lo_man[take] = np.maximum(lo_man[take], low)

    def settled_inv() -> np.ndarray:
        return (lo_inv > level) | (below & (lo_inv > least))

    def settled() -> np.ndarray:
        return settled_inv() & (lo_man > level_man)

    def hopeless(take: np.ndarray) -> np.ndarray:
        # Both neighbours below the level: the certificate above it will not hold (saves the attempt).
        return (value_up[left[take]] <= level) & (value_up[right[take]] <= level)

    def interpolated(take: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # Step 2's interpolation of the neighbours' Jacobians: its Gram matrices, s_up - e and e.
        lam, err = _interpolation_error(q, rows[take], left[take], right[take], change[:2])
        s_lam = (1.0 - lam) * ends_at.top[left[take]] + lam * ends_at.top[right[take]]
        # Rounding of the interpolation and of the singular values: a margin far above it.
        err = err * (1.0 + 1e-9) + 1e-9 * (s_lam + 1.0)
        lam = lam[:, None, None]
        return _gram((1.0 - lam) * scaled_all[left[take]] + lam * scaled_all[right[take]]), s_lam, err

    def certify(
        take: np.ndarray, gram: np.ndarray, s_up: np.ndarray, err: np.ndarray, lift: float | np.ndarray = lifted
    ) -> None:
        floor = lift * s_up + err
        ok, det = _positive_definite(gram, floor * floor)
        lo_inv[take[ok]] = np.maximum(lo_inv[take[ok]], lift if np.ndim(lift) == 0 else lift[ok])
        if divisor is not None:  # the manipulability is that of the scaled Jacobian
            # A zero floor (level 0, no error) leaves the singular values as they are.
            ratio = np.divide(err[ok], floor[ok], out=np.zeros(int(ok.sum())), where=floor[ok] > 0.0)
            shrink = np.maximum(1.0 - ratio * ratio, 0.0) ** (0.5 * k)  # see _inverse_trace
            lo_man[take[ok]] = np.maximum(lo_man[take[ok]], np.sqrt(det[ok]) * shrink * (scale * (1.0 - 1e-9)))

    compiled, pending = None, rows[:0]
    if bracketed:
        rho, angular, _ = change
        if deferred and bracketed_anchors is not None:
            # The anchors are the bracketed rows, in order: their bounds as anchor_bounds gave them.
            anchor_ends, anchor_scaled = bracketed_anchors[:, [0, 1, 2, 3, 4, 6]], scaled_loose
        else:
            anchor_ends = np.stack([values[anchors] for values in (*ends_at, value_up)], axis=1)
            anchor_scaled = scaled_all[anchors]
        of_interval = np.minimum(np.searchsorted(bounds_of, anchors[:-1], side="right") - 1, len(least_of) - 1)
        params = (angular, threshold, level, lifted, level_man, scale)
        compiled = interval_certificates(q, anchors, anchor_scaled, anchor_ends, least_of[of_interval], rho, params)
    if compiled is not None:
        # Steps 0 to 3 in compiled loops (planner.core.certificates), the same bounds. Their
        # arrays (n,) hold the rows' bounds (flags 0 at the anchors): they become the measure,
        # with the anchors' values in place.
        bounds_inv, bounds_man, flags = compiled
        bounds_inv[anchors], bounds_man[anchors] = inv[anchors], man[anchors]
        inv, man = bounds_inv, bounds_man
        take = np.flatnonzero(flags & 2)  # rows
        if len(take):
            scaled = robot.task_rows(kernel(q[take]), task)[1]
            t_inv, t_man, t_flags = inv[take], man[take], flags[take]
            least = least_of[np.searchsorted(bounds_of, take) - 1]
            if own_certificates(scaled, least, t_inv, t_man, t_flags, (threshold, level, level_man, scale)):
                inv[take], man[take] = t_inv, t_man
                take = take[(t_flags & 2) != 0]
            pending = take  # measured below, with the bracketed anchors left open
    else:
        right = np.searchsorted(ends, rows)
        left, right = ends[right - 1], ends[right]  # the anchors on either side of each row
        least = least_of[np.searchsorted(bounds_of, rows) - 1]  # of each row's stretch
        lo_inv, lo_man = np.zeros(len(rows)), np.zeros(len(rows))
        below = np.zeros(len(rows), dtype=bool)  # shown below the threshold
        if change is not None:
            rho, angular, raw_angular = change
            if divisor is not None:
                lo_inv[:], lo_man[:], upper = _interval_bounds(
                    q, rows, left, right, scaled_all, ends_at, (rho, angular)
                )
                below[:] = upper < threshold
                lo_inv *= 1.0 - 1e-9
                lo_man *= scale * (1.0 - 1e-9)
            else:
                take = np.arange(len(rows))
                near = np.where(rows[take] - left[take] <= right[take] - rows[take], left[take], right[take])
                du = q[rows[take]] - q[near]
                e = jacobian_change_bound(du, rho, angular)
                weyl(take, near, e, e if divisor is not None else jacobian_change_bound(du, rho, raw_angular))
            take = np.nonzero(~settled())[0]
            # Rows whose inverse condition number is settled (the manipulability is not) go to step
            # 3 directly: there its bound comes from one cheap factorisation, tight.
            take = take[~hopeless(take) & ~settled_inv()[take]]
            if len(take):
                gram, s_lam, err = interpolated(take)
                certify(take, gram, s_lam + err, err)
            # Shown below the threshold: above the stretch's least value suffices.
            take = np.nonzero(below & ~settled_inv())[0]
            if len(take):
                gram, s_lam, err = interpolated(take)
                certify(take, gram, s_lam + err, err, least[take] * (1.0 + 1e-9))
            if divisor is not None:
                # The manipulability alone where the inverse condition number is settled.
                take = np.nonzero(settled_inv() & ~(lo_man > level_man))[0]
                if len(take):
                    gram, _, err = interpolated(take)
                    inverse = np.maximum(*(_inverse_trace(scaled_all[at[take]]) for at in (left, right)))
                    shift = err * np.sqrt(k / inverse)
                    ok, det = _positive_definite(gram, shift)
                    ok &= shift > err * err
                    loss = (1.0 - err[ok] ** 2 / shift[ok]) ** (0.5 * k)
                    lo_man[take[ok]] = np.maximum(lo_man[take[ok]], np.sqrt(det[ok]) * loss * (scale * (1.0 - 1e-9)))
        take = np.nonzero(~settled())[0]
        if len(take):
            # For bounds only (the rows measured exactly in the end take Pinocchio's Jacobians again).
            if kernel is None:
                raw, scaled = robot.task_jacobians(q[rows[take]], task)
            else:
                raw, scaled = robot.task_rows(kernel(q[rows[take]]), task)
            gram = _gram(scaled)
            # The inverse condition number from both sides where it is not settled yet; the
            # manipulability alone from the factorisation elsewhere.
            open_inv = ~settled_inv()[take]
            product = np.zeros(len(take))
            if open_inv.any():
                brackets = _extreme_bounds(gram[open_inv])
                product[open_inv] = brackets[:, 4]
                floor, ceiling = _condition_bracket(brackets)
                at = take[open_inv]
                lo_inv[at] = np.maximum(lo_inv[at], floor)
                below[at] |= ceiling < threshold
            if divisor is None:
                product = _positive_definite(_gram(raw), np.zeros(len(take)))[1]
            else:
                open_man = ~open_inv & ~(lo_man[take] > level_man)
                product[open_man] = _positive_definite(gram[open_man], np.zeros(int(open_man.sum())))[1]
            lo_man[take] = np.maximum(lo_man[take], np.sqrt(np.maximum(product, 0.0)) * (scale * (1.0 - 1e-9)))
            rest = ~settled()[take]
            if rest.any():
                measure(rows[take[rest]], *((raw[rest], scaled[rest]) if kernel is None else ()))

    if len(loose):
        # The bracketed anchors, settled as the rows are, or measured exactly.
        loose_man = ends_at.product[loose] * (scale * (1.0 - 1e-9))
        dip = (value_up[loose] < threshold) & (loose_low > least_of[np.searchsorted(bounds_of, loose) - 1])
        shown = ((loose_low > level) | dip) & (loose_man > level_man)
        if deferred:
            shown[np.searchsorted(loose, bounds_of)] = False  # the rows `keep`: measured
        inv[loose[shown]], man[loose[shown]] = loose_low[shown], loose_man[shown]
        pending = np.concatenate([pending, loose[~shown]])
    if compiled is None:
        free = ~exact[rows]
        inv[rows[free]], man[rows[free]] = lo_inv[free], lo_man[free]
    if len(pending):
        measure(pending)
    return inv, man


def measure_singularities(
    robot: Robot, trajectory: JointTrajectory, threshold: float, task: Task, rate: float
) -> tuple[SingularityReport, np.ndarray, np.ndarray, np.ndarray]:
    """The report of a trajectory and what it was computed from.

    Args:
        robot: The robot.
        trajectory: The trajectory.
        threshold: Checked inverse-condition-number threshold.
        task: Resolved task (``"position"`` or ``"pose"``).
        rate: Sample rate [Hz].

    Returns:
        The report, the sample times (n,) [s], the sampled configurations (n, dof) and their
        inverse condition numbers (n,): exact (as :meth:`Robot.conditioning`) at the waypoints,
        at the minimum and at the lowest sample between two waypoints where that is below the
        threshold; elsewhere a lower bound on the same side of the threshold, above the minimum
        (and above the threshold) or above the lowest sample between its waypoints (see
        :func:`bounded_conditioning`).
    """
    t = _sample_times(trajectory, rate)
    q = trajectory.positions(t)
    w_idx = np.searchsorted(t, trajectory.waypoint_times)
    inv, man = bounded_conditioning(robot, q, task, threshold, w_idx)
    w_inv, w_man = inv[w_idx], man[w_idx]
    k = int(np.argmin(inv))
    report = SingularityReport(
        threshold=threshold,
        task=task,
        rate=float(rate),
        waypoint_inverse_condition=read_only(w_inv),
        waypoint_manipulability=read_only(w_man),
        singular_waypoints=tuple(int(i) for i in np.nonzero(w_inv < threshold)[0]),
        min_inverse_condition=float(inv[k]),
        min_manipulability=float(np.min(man)),
        time_of_minimum=float(t[k]),
        q_at_minimum=read_only(q[k]),
        below_threshold=_intervals(t, inv < threshold),
    )
    return report, t, q, inv


def check_singularities(
    robot: Robot,
    trajectory: JointTrajectory,
    *,
    threshold: float | None = None,
    task: Task | None = None,
    rate: float = 1000.0,
) -> SingularityReport:
    """Measure how close a trajectory comes to singular configurations.

    Args:
        robot: The robot the trajectory is for.
        trajectory: A joint trajectory of that robot.
        threshold: Inverse condition number below which a configuration is too close; None
            is the task's default, ``1 / DEFAULT_CONDITION_NUMBERS[task]`` (1/30 for
            ``"position"``, 0.01 for ``"pose"``).
        task: Task Jacobian (``"position"`` or ``"pose"``); None as the robot chooses.
        rate: Sampling rate [Hz]; the waypoint instants are always checked too.

    Returns:
        The report.

    Raises:
        InvalidArgumentError: On a threshold outside [0, 1), an unknown task, a bad rate or a
            trajectory for another number of joints.
    """
    if trajectory.dof != robot.dof:
        raise InvalidArgumentError(f"the trajectory has {trajectory.dof} joints; {robot.name} has {robot.dof}")
    t_task = robot.resolve_task(task)
    return measure_singularities(robot, trajectory, inverse_condition_threshold(threshold, t_task), t_task, rate)[0]
