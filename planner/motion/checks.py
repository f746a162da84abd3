"""Input checks of a trajectory request: waypoints, start state, stops, dwell, given via states.

Each check returns a new float array in the planner's normalised form and raises a
:class:`planner.exceptions.PlannerError` subclass naming the offending waypoint, joint and value.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from operator import le

import numpy as np

from planner.core.text import plain
from planner.exceptions import InvalidArgumentError, InvalidConfigurationError, JointLimitError
from planner.motion.limits import MAX_SEGMENT_DURATION, JointLimits

__all__ = [
    "check_dwell",
    "check_given",
    "check_state",
    "check_stops",
    "check_waypoints",
    "waypoint_rows_within",
    "waypoints_within",
]


def waypoints_within(waypoints: Sequence[Sequence[float]] | np.ndarray, limits: JointLimits) -> np.ndarray | None:
    """The waypoints as a new (N, dof) float array if :func:`check_waypoints` accepts them at once, else None.

    The common case on plain floats (see :func:`waypoint_rows_within`); None leaves the
    diagnosis to :func:`check_waypoints`.
    """
    within = waypoint_rows_within(waypoints, limits)
    return None if within is None else within[0]


def waypoint_rows_within(
    waypoints: Sequence[Sequence[float]] | np.ndarray, limits: JointLimits
) -> tuple[np.ndarray, list[list[float]], list[float], list[float]] | None:
    """:func:`waypoints_within` with the waypoints also as rows of floats and per joint their extremes.

    On plain floats (on a few waypoints faster than NumPy): a sum of all values that is not
    finite rejects NaN and infinities (and the rare sums that overflow), and then each joint's
    lowest and highest value lie within :attr:`JointLimits.finite_bounds` exactly when all of
    its values do. None leaves the diagnosis to :func:`check_waypoints`.

    Returns:
        The new (N, dof) float array, its rows as lists of floats and per joint the lowest and
        the highest waypoint value (lists of dof floats) [rad or m]; or None.
    """
    try:
        whole = np.array(waypoints, dtype=float)
    except (TypeError, ValueError):
        return None
    if whole.ndim != 2 or whole.shape[0] < 2 or whole.shape[1] != limits.dof:
        return None
    rows = whole.tolist()
    if not math.isfinite(sum(map(sum, rows))):
        return None
    low, high = list(map(min, *rows)), list(map(max, *rows))
    lows, highs = limits.finite_bounds
    if all(map(le, lows, low)) and all(map(le, high, highs)):
        return whole, rows, low, high
    return None


def check_waypoints(waypoints: Sequence[Sequence[float]] | np.ndarray, limits: JointLimits) -> np.ndarray:
    """Validate joint waypoints against limits and return them as a new (N, dof) float array.

    Raises:
        InvalidArgumentError: If there are fewer than two waypoints.
        InvalidConfigurationError: If a waypoint has the wrong length or a NaN/infinite value.
        JointLimitError: If a waypoint lies outside a joint's range (joint and value named).
    """
    whole = waypoints_within(waypoints, limits)
    if whole is not None:
        return whole
    names = limits.joint_names
    rows = list(waypoints)
    if len(rows) < 2:
        raise InvalidArgumentError(f"a trajectory needs at least two waypoints, got {len(rows)}")
    out = np.empty((len(rows), limits.dof))
    for k, row in enumerate(rows):
        try:
            arr = np.array(row, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InvalidConfigurationError(f"waypoint {k} must be {limits.dof} numbers, got {row!r}") from exc
        if arr.shape != (limits.dof,):
            raise InvalidConfigurationError(
                f"waypoint {k} has {arr.size} values; expected {limits.dof}, one per joint ({', '.join(names)})"
            )
        bad = np.nonzero(~np.isfinite(arr))[0]
        if bad.size:
            raise InvalidConfigurationError(
                f"waypoint {k} holds {arr[bad[0]]} for joint {names[bad[0]]!r}; values must be finite"
            )
        out_of_range = np.nonzero((arr < limits.lower) | (arr > limits.upper))[0]
        if out_of_range.size:
            jj = int(out_of_range[0])
            raise JointLimitError(names[jj], arr[jj], limits.lower[jj], limits.upper[jj], context=f"waypoint {k}")
        out[k] = arr
    return out


def check_state(
    value: Sequence[float] | np.ndarray | None, limit: np.ndarray, names: Sequence[str], what: str
) -> np.ndarray:
    """A start velocity or acceleration as a new float array within its limits.

    Args:
        value: One value per joint [rad/s or m/s, rad/s^2 or m/s^2]; None is zero.
        limit: Its limit per joint, shape (dof,).
        names: Joint names, for messages.
        what: What the state is (``"start velocity"``), for messages.

    Returns:
        Shape (dof,).

    Raises:
        InvalidArgumentError: On the wrong length, a NaN or a value beyond its limit.
    """
    if value is None:
        return np.zeros(len(names))
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidArgumentError(f"{what} must be {len(names)} numbers, got {value!r}") from exc
    if arr.shape != (len(names),):
        raise InvalidArgumentError(f"{what} has {arr.size} values; expected {len(names)} ({', '.join(names)})")
    for name, x, lim in zip(names, arr, limit):
        if not math.isfinite(x):
            raise InvalidArgumentError(f"{what} of joint {name!r} must be finite, got {x}")
        if abs(x) > lim:
            raise InvalidArgumentError(f"{what} of joint {name!r} is {x:.6g}, beyond its limit +-{lim:.6g}")
    return arr


def check_given(
    velocities: np.ndarray | None,
    accelerations: np.ndarray | None,
    min_durations: Sequence[float] | np.ndarray | None,
    n: int,
    limits: JointLimits,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Prescribed via states and minimum segment durations in the planner's form.

    Args:
        velocities: Via velocities, shape (N, dof); NaN entries are free (a row with any NaN is
            free as a whole); None leaves every row free.
        accelerations: Via accelerations, shape (N, dof); NaN or None is zero.
        min_durations: Shortest duration per segment, shape (N-1,) [s]; None is 0 (none).
        n: Number of waypoints N.
        limits: The limits (velocities and accelerations are checked against them).

    Returns:
        Velocities (N, dof) with NaN rows where free, accelerations (N, dof) and minimum
        durations (N-1,), all new arrays.

    Raises:
        InvalidArgumentError: On a wrong shape, a value beyond its limit or a negative duration.
    """
    dof = limits.dof
    if velocities is None and accelerations is None and min_durations is None:
        return np.full((n, dof), np.nan), np.zeros((n, dof)), np.zeros(n - 1)
    out = []
    for what, value, lim in (
        ("via_velocities", velocities, limits.velocity),
        ("via_accelerations", accelerations, limits.acceleration),
    ):
        arr = np.full((n, dof), np.nan) if value is None else np.array(value, dtype=float)
        if arr.shape != (n, dof):
            raise InvalidArgumentError(f"{what} must have shape ({n}, {dof}), got {arr.shape}")
        given = np.isfinite(arr)
        if np.any(np.abs(arr[given]) > np.broadcast_to(lim, arr.shape)[given] * (1 + 1e-12)):
            k, j = np.argwhere(given & (np.abs(np.nan_to_num(arr)) > lim * (1 + 1e-12)))[0]
            raise InvalidArgumentError(
                f"{what}[{k}] of joint {limits.joint_names[j]!r} is {arr[k, j]:.6g}, beyond its limit +-{lim[j]:.6g}"
            )
        out.append(arr)
    v, a = out
    rows = np.all(np.isfinite(v), axis=1)
    a = np.where(np.isfinite(a), a, 0.0)
    v = np.where(rows[:, None], v, np.nan)
    md = np.zeros(n - 1) if min_durations is None else np.array(min_durations, dtype=float)
    if md.shape != (n - 1,) or np.any(~np.isfinite(md)) or np.any(md < 0):
        raise InvalidArgumentError(f"min_durations needs {n - 1} finite values >= 0 [s], got {plain(min_durations)}")
    return v, a, md


def check_stops(stops: Sequence[int] | None, n: int) -> np.ndarray:
    """Stop indices (negative ones count from the end) as a bool mask of shape (n,).

    Raises:
        InvalidArgumentError: If `stops` is not a list, tuple, set or 1-D array of indices, or
            an index is not an integer waypoint index.
    """
    stop = np.zeros(n, dtype=bool)
    if stops is None:
        return stop
    if isinstance(stops, (str, bytes)) or not isinstance(stops, (Sequence, np.ndarray, set, frozenset)):
        raise InvalidArgumentError(f"stops must be a list of waypoint indices (0..{n - 1}), got {plain(stops)}")
    for s in stops:
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or not -n <= s < n:
            raise InvalidArgumentError(f"stop index {plain(s)} is not a waypoint index (0..{n - 1})")
        stop[s] = True
    return stop


def check_dwell(dwell: float | Sequence[float] | None, n: int) -> np.ndarray:
    """Dwell times [s] per waypoint, shape (n,), from one number, one per waypoint or None (0).

    Raises:
        InvalidArgumentError: On the wrong count, a negative or non-finite time, or one longer than
            :data:`~planner.motion.limits.MAX_SEGMENT_DURATION` (like a move: split longer rests
            into separate plans).
    """
    if dwell is None:
        return np.zeros(n)
    arr = np.array(dwell, dtype=float)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise InvalidArgumentError(f"dwell needs one time per waypoint ({n}), got {arr.size}")
    bad = np.nonzero(~np.isfinite(arr) | (arr < 0))[0]
    if bad.size:
        raise InvalidArgumentError(f"dwell at waypoint {int(bad[0])} must be >= 0 and finite [s], got {arr[bad[0]]}")
    long = np.nonzero(arr > MAX_SEGMENT_DURATION)[0]
    if long.size:
        raise InvalidArgumentError(
            f"dwell at waypoint {int(long[0])} is {plain(arr[long[0]])} s; a rest in a plan lasts at most "
            f"{MAX_SEGMENT_DURATION:g} s (as a move): split a longer rest into separate plans"
        )
    return arr
