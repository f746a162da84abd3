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

import numpy as np

from planner.core.arrays import read_only
from planner.core.text import plain
from planner.exceptions import InvalidArgumentError
from planner.model.robot import Robot, Task
from planner.motion.trajectory import JointTrajectory

__all__ = [
    "DEFAULT_CONDITION_NUMBER",
    "DEFAULT_CONDITION_NUMBERS",
    "SingularityReport",
    "bounded_conditioning",
    "check_singularities",
    "jacobian_change_bound",
    "jacobian_change_bounds",
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
    return np.unique(np.concatenate([trajectory.times(rate), trajectory.waypoint_times]))


def _intervals(t: np.ndarray, low: np.ndarray) -> tuple[tuple[float, float], ...]:
    """The runs of `low` as (first, last) times."""
    if not low.any():
        return ()
    edges = np.diff(np.concatenate([[False], low, [False]]).astype(np.int8))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    return tuple((float(t[a]), float(t[b])) for a, b in zip(starts, ends))


#: Samples between the first rows :func:`bounded_conditioning` measures exactly.
ANCHOR_SPACING = 8


def jacobian_change_bounds(robot: Robot, task: Task) -> tuple[np.ndarray, np.ndarray, float] | None:
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


def _inside(n: int, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Mask of the n rows strictly between each ``lo[i]`` and ``hi[i]`` (disjoint gaps)."""
    marks = np.zeros(n + 1, dtype=np.int64)
    np.add.at(marks, lo + 1, 1)
    np.add.at(marks, hi, -1)
    return np.cumsum(marks[:n]) > 0


def bounded_conditioning(
    robot: Robot, q: np.ndarray, task: Task, threshold: float, keep: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`Robot.conditioning` of a dense sequence of configurations, exact only where it matters.

    Every :data:`ANCHOR_SPACING`-th row, the last and the rows `keep` are measured exactly; every
    row between two exact ones gets lower bounds from both by Weyl's inequality: a singular value
    moves by at most the spectral norm (below the Frobenius norm) of the change of the matrix, so
    with ``e`` a bound on ``||J - J_a||_F`` the inverse condition number is at least
    ``(s_min(J_a) - e) / (s_max(J_a) + e)`` and the manipulability (a fixed factor times the
    product of the singular values of the matrix it is computed from) at least that factor times
    the product of ``max(s_i - e, 0)``. ``e`` is first the bound of
    :func:`jacobian_change_bounds` from the joint changes alone (no Jacobian needed); rows it
    leaves undecided get their Jacobian and ``e = ||J - J_a||_F`` itself. Where a bound between
    two exact rows could be below the threshold or below the smallest exact value so far, the
    row halfway is measured too, and so on: in the end every row below the threshold and the
    row of each minimum hold the exact value, and the others a lower bound above the threshold
    and above both minima.

    Args:
        robot: The robot.
        q: Configurations, shape (n, dof) [rad or m], checked.
        task: Resolved task (``"position"`` or ``"pose"``).
        threshold: Inverse condition number below which values must be exact.
        keep: Rows measured exactly in any case.

    Returns:
        ``(inverse_condition_number, manipulability)``, each of shape (n,).
    """
    n = len(q)
    dof = q.shape[1]
    m_rows = 3 if task == "position" else 6
    k = min(m_rows, dof)
    # The manipulability is a fixed factor times the product of the scaled Jacobian's singular
    # values, or of the raw Jacobian's: its bound is on the matrix it is computed from.
    divisor = robot.manipulability_divisor(task)
    raw, scaled = np.empty((n, m_rows, dof)), np.empty((n, m_rows, dof))
    have = np.zeros(n, dtype=bool)  # rows whose Jacobians are computed

    def jacobians(idx: np.ndarray) -> None:
        idx = idx[~have[idx]]
        if len(idx):
            raw[idx], scaled[idx] = robot.task_jacobians(q[idx], task)
            have[idx] = True

    inv, man = np.empty(n), np.empty(n)
    s_inv, s_man = np.zeros((n, k)), np.zeros((n, k))  # singular values at the exact rows
    exact = np.zeros(n, dtype=bool)

    def measure(idx: np.ndarray) -> None:
        jacobians(idx)
        s_inv[idx], s_man[idx] = robot.task_singular_values(raw[idx], scaled[idx], task)
        inv[idx], man[idx] = robot.conditioning_from(s_inv[idx], s_man[idx], task)
        exact[idx] = True

    first = np.concatenate([np.arange(0, n, ANCHOR_SPACING), [n - 1], [] if keep is None else np.asarray(keep)])
    measure(np.unique(first.astype(int)))
    scale = 1.0 if divisor is None else 1.0 / divisor
    lo_inv, lo_man = np.zeros(n), np.zeros(n)
    rows = np.nonzero(~exact)[0]  # rows whose bounds are (re)computed
    change = jacobian_change_bounds(robot, task)
    if change is not None and len(rows):
        rho, angular, raw_angular = change
        ends = np.nonzero(exact)[0]
        right = np.searchsorted(ends, rows)
        for a in (ends[right - 1], ends[right]):
            du = q[rows] - q[a]
            e = jacobian_change_bound(du, rho, angular) + 1e-9 * (s_inv[a, 0] + 1.0)
            e_man = (
                e if divisor is not None else jacobian_change_bound(du, rho, raw_angular) + 1e-9 * (s_man[a, 0] + 1.0)
            )
            lo_inv[rows] = np.maximum(lo_inv[rows], np.maximum(s_inv[a, -1] - e, 0.0) / (s_inv[a, 0] + e))
            lo_man[rows] = np.maximum(lo_man[rows], np.prod(np.maximum(s_man[a] - e_man[:, None], 0.0), axis=1))
        lo_man[rows] *= scale * (1.0 - 1e-9)
        # Rows these bounds settle keep them (the smallest exact values only fall as rows are
        # added); the others go on with their Jacobians.
        settled = (lo_inv[rows] > max(threshold, float(np.min(inv[exact])))) & (
            lo_man[rows] > float(np.min(man[exact]))
        )
        done = np.zeros(n, dtype=bool)
        done[rows[settled]] = True
        rows = rows[~settled]
    else:
        done = np.zeros(n, dtype=bool)
    while len(rows):
        jacobians(rows)
        ends = np.nonzero(exact)[0]
        right = np.searchsorted(ends, rows)
        lo_inv[rows], lo_man[rows] = 0.0, 0.0
        for a in (ends[right - 1], ends[right]):
            jacobians(np.unique(a))
            # Rounding of the SVDs and norms: a margin far above it.
            e = np.linalg.norm(scaled[rows] - scaled[a], axis=(1, 2)) + 1e-9 * (s_inv[a, 0] + 1.0)
            if divisor is None:
                e_man = np.linalg.norm(raw[rows] - raw[a], axis=(1, 2)) + 1e-9 * (s_man[a, 0] + 1.0)
            else:
                e_man = e
            lo_inv[rows] = np.maximum(lo_inv[rows], np.maximum(s_inv[a, -1] - e, 0.0) / (s_inv[a, 0] + e))
            lo_man[rows] = np.maximum(lo_man[rows], np.prod(np.maximum(s_man[a] - e_man[:, None], 0.0), axis=1))
        lo_man[rows] *= scale * (1.0 - 1e-9)
        # The smallest exact values only fall as rows are added: a row certified stays certified.
        open_rows = np.nonzero(~exact & ~done)[0]
        near = (lo_inv[open_rows] <= max(threshold, float(np.min(inv[exact])))) | (
            lo_man[open_rows] <= float(np.min(man[exact]))
        )
        if not near.any():
            break
        # Split each gap holding a row too near: its middle row (a short gap: all its rows).
        pos = np.searchsorted(ends, open_rows[near])
        lo_end, hi_end = np.unique(ends[pos - 1]), None
        hi_end = ends[np.searchsorted(ends, lo_end) + 1]
        short = hi_end - lo_end <= 4
        mids = (lo_end[~short] + hi_end[~short]) // 2
        whole = np.nonzero(_inside(n, lo_end[short], hi_end[short]))[0]
        measure(np.unique(np.concatenate([mids, whole])))
        # Bounds again for the rows of the gaps split (the others' ends are unchanged).
        split = _inside(n, lo_end[~short], hi_end[~short])
        rows = np.nonzero(split & ~exact & ~done)[0]
    free = ~exact
    inv[free], man[free] = lo_inv[free], lo_man[free]
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
        wherever below the threshold and at the minimum, elsewhere a lower bound above both
        (see :func:`bounded_conditioning`).
    """
    t = _sample_times(trajectory, rate)
    q = trajectory.sample(t).q
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
