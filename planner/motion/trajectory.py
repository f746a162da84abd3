"""The trajectory value: a jerk-limited joint trajectory as piecewise-cubic pieces.

:class:`JointTrajectory` is what :func:`planner.motion.plan.plan_trajectory` returns: it
samples states at any instant, reports its peak velocity, acceleration and jerk over the
limits, and writes itself as CSV. :data:`LIMIT_TOLERANCE` states the limit guarantee.
"""

from __future__ import annotations

import csv
import ctypes
import dataclasses
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planner.core.arrays import float_array
from planner.core.native import load_functions
from planner.core.text import plain
from planner.exceptions import InvalidArgumentError
from planner.motion.limits import JointLimits

__all__ = ["LIMIT_TOLERANCE", "MAX_SAMPLES", "JointTrajectory", "TrajectorySample"]

#: Relative tolerance of the limit guarantee: a sampled |velocity|, |acceleration| or |jerk|
#: never exceeds ``limit * (1 + LIMIT_TOLERANCE)``, a position never leaves its range by more
#: than ``LIMIT_TOLERANCE * max(1, |bound|)`` [rad or m]. It only absorbs floating-point rounding.
LIMIT_TOLERANCE = 1e-9
#: Most samples :meth:`JointTrajectory.times` gives at once (10 million: 2.8 h at 1 kHz; a
#: 7-dof sample of that many states takes about 2 GB).
MAX_SAMPLES = 10_000_000


@dataclass(frozen=True)
class TrajectorySample:
    """States of a trajectory at one or more instants.

    Attributes:
        t: Time(s) [s], shape () or (n,).
        q: Positions [rad or m], shape (dof,) or (n, dof).
        qd: Velocities [rad/s or m/s], same shape as `q`.
        qdd: Accelerations [rad/s^2 or m/s^2], same shape as `q`.
        qddd: Jerks [rad/s^3 or m/s^3], same shape as `q` (piecewise constant; at a switching
            instant the value of the interval that starts there).
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    qddd: np.ndarray


_BUILD_LOCK = threading.Lock()

_SOURCE = r"""
/* JointTrajectory._positions_at after its _locate, one time at a time: the interval of each time
   (numpy.searchsorted(knots, t, side="right") - 1, clipped to [0, K - 1]) by bisection, then
   p + dt (v + dt (a / 2 + dt j / 6)) operation by operation as the NumPy path does them (the same
   values: -O2 without -ffast-math contracts nothing), the final waypoint at and after the end. */
void positions(long n, long dof, long count, const double *t, const double *knots, const double *p,
               const double *v, const double *a, const double *j, double duration, const double *last,
               double *out) {
    for (long r = 0; r < n; ++r) {
        double time = t[r], *o = out + r * dof;
        if (time >= duration) {
            for (long i = 0; i < dof; ++i) o[i] = last[i];
            continue;
        }
        long lo = 0, hi = count;
        while (lo < hi) {
            long mid = lo + (hi - lo) / 2;
            if (knots[mid] <= time) lo = mid + 1;
            else hi = mid;
        }
        long k = lo > 0 ? lo - 1 : 0;
        double dt = time - knots[k];
        const double *pk = p + k * dof, *vk = v + k * dof, *ak = a + k * dof, *jk = j + k * dof;
        for (long i = 0; i < dof; ++i) {
            double x = jk[i] * dt;
            x /= 6.0;
            x += ak[i] / 2.0;
            x *= dt;
            x += vk[i];
            x *= dt;
            x += pk[i];
            o[i] = x;
        }
    }
}
"""

_SIGNATURES = {
    "positions": [
        *[ctypes.c_long] * 3,
        *[ctypes.c_void_p] * 6,
        ctypes.c_double,
        *[ctypes.c_void_p] * 2,
    ]
}


class _Pieces:
    """A piece array of :class:`JointTrajectory`: given to the constructor, or built on first use."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, obj: JointTrajectory | None, objtype: type | None = None) -> np.ndarray:
        if obj is None:
            raise AttributeError(self.name)  # no class-level value: the dataclass field has no default
        try:
            return obj.__dict__[self.name]
        except KeyError:
            with _BUILD_LOCK:  # one thread builds, the others then find the arrays
                if self.name not in obj.__dict__:
                    build = obj.__dict__["_build_pieces"]
                    for name, value in zip(("knots", "p", "v", "a", "j"), build()):
                        obj.__dict__[name] = value
                    del obj.__dict__["_build_pieces"]
            return obj.__dict__[self.name]

    def __set__(self, obj: JointTrajectory, value: np.ndarray) -> None:
        obj.__dict__[self.name] = value


def _check_rate(rate: object) -> None:
    """Refuse a sample rate that is not a positive, finite number [Hz] (a bool is not one)."""
    if isinstance(rate, bool) or not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        raise InvalidArgumentError(f"rate must be positive and finite [Hz], got {plain(rate)}")


@dataclass(frozen=True, eq=False)
class JointTrajectory:
    """A jerk-limited joint trajectory through waypoints (piecewise-constant jerk).

    Build one with :func:`planner.motion.plan.plan_trajectory`. Time runs from 0 to :attr:`duration`; the state
    at ``waypoint_times[k]`` is exactly ``waypoints[k]`` with velocity ``via_velocities[k]``.

    Attributes:
        knots: Start times of the constant-jerk intervals, shape (K,) [s], ascending, knots[0] = 0.
        p: Positions at the interval starts, shape (K, dof) [rad or m].
        v: Velocities at the interval starts, shape (K, dof).
        a: Accelerations at the interval starts, shape (K, dof).
        j: Jerk within each interval, shape (K, dof).
        duration: Total duration [s].
        waypoints: The waypoints passed through, shape (N, dof).
        waypoint_times: When each waypoint is reached, shape (N,) [s]; with a dwell the arm
            arrives at this time and leaves ``dwell[k]`` later.
        via_velocities: The velocity at each waypoint, shape (N, dof).
        via_accelerations: The acceleration at each waypoint, shape (N, dof).
        dwell: Time spent at rest at each waypoint, shape (N,) [s].
        limits: The limits the trajectory honours.
        strategy: How the via velocities were chosen (see :func:`planner.motion.plan.plan_trajectory`).
        repaired: Per waypoint and joint, whether the final range check lowered the via state
            (velocity and acceleration) to keep a joint inside its range, shape (N, dof) bool.
            The optimizing search already avoids states that leave the range, so this is set
            mostly for the ``"heuristic"`` strategy and prescribed via states.
    """

    knots: np.ndarray = _Pieces()
    p: np.ndarray = _Pieces()
    v: np.ndarray = _Pieces()
    a: np.ndarray = _Pieces()
    j: np.ndarray = _Pieces()
    duration: float
    waypoints: np.ndarray
    waypoint_times: np.ndarray
    via_velocities: np.ndarray
    via_accelerations: np.ndarray
    dwell: np.ndarray
    limits: JointLimits
    strategy: str
    repaired: np.ndarray

    @classmethod
    def lazy(
        cls, build: Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]], **fields: object
    ) -> JointTrajectory:
        """A trajectory whose piece arrays are made by `build` when first used.

        The planner decides a trajectory without its pieces (the segments' durations and range
        checks come from Ruckig directly); building them costs about as much again.

        Args:
            build: Returns the read-only ``knots, p, v, a, j`` (see the attributes).
            **fields: Every other attribute.
        """
        if fields.keys() != _LAZY_FIELDS:
            missing = _LAZY_FIELDS - fields.keys()
            raise InvalidArgumentError(
                f"JointTrajectory.lazy needs the fields {', '.join(sorted(missing or _LAZY_FIELDS))}"
                + (f", not {', '.join(sorted(fields.keys() - _LAZY_FIELDS))}" if fields.keys() - _LAZY_FIELDS else "")
            )
        obj = cls.__new__(cls)
        # Plain attributes: the frozen dataclass's fields live in the instance dict.
        obj.__dict__.update(fields)
        obj.__dict__["_build_pieces"] = build
        return obj

    def __getstate__(self) -> dict:
        """Pickling: the piece arrays are built first (a lazy trajectory's builder is a closure)."""
        _ = self.knots
        return dict(self.__dict__)

    @property
    def dof(self) -> int:
        """Number of joints."""
        return self.waypoints.shape[1]

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Joint names, from the limits."""
        return self.limits.joint_names

    def __repr__(self) -> str:
        return (
            f"JointTrajectory(duration={self.duration:.6g} s, waypoints={len(self.waypoints)}, "
            f"dof={self.dof}, strategy={self.strategy!r})"
        )

    def _checked_times(self, t: float | Sequence[float] | np.ndarray, clamp: bool) -> tuple[np.ndarray, ...]:
        """`t` as an array, flattened, and flattened within [0, duration] (clamped or checked)."""
        tt = float_array(t, "time")
        asked = tt.reshape(-1)
        if asked.size and not np.all(np.isfinite(asked)):
            bad = asked[~np.isfinite(asked)][0]
            raise InvalidArgumentError(f"time {plain(bad)} s is not a finite number")
        flat = np.clip(asked, 0.0, self.duration) if clamp else asked
        if flat.size and (flat.min() < 0.0 or flat.max() > self.duration * (1 + 1e-12)):
            bad = flat[(flat < 0) | (flat > self.duration * (1 + 1e-12))][0]
            raise InvalidArgumentError(
                f"time {plain(bad)} s is outside the trajectory [0, {self.duration:.6g}] s "
                "(clamp=True holds the end states)"
            )
        return tt, asked, flat

    def positions(self, t: float | Sequence[float] | np.ndarray, *, clamp: bool = False) -> np.ndarray:
        """Positions at time(s) `t`: ``sample(t, clamp=clamp).q`` (the same values), without the other states.

        Returns:
            Shape (dof,) for a scalar `t`, else ``t.shape + (dof,)`` [rad or m].

        Raises:
            InvalidArgumentError: As :meth:`sample`.
        """
        tt, _, flat = self._checked_times(t, clamp)
        q = self._compiled_positions(flat)
        if q is None:
            q = self._positions_at(*self._locate(flat))
        return q[0] if tt.ndim == 0 else q.reshape(tt.shape + (self.dof,))

    def _compiled_positions(self, flat: np.ndarray) -> np.ndarray | None:
        """:meth:`_positions_at` of :meth:`_locate` in one compiled loop (the same values), or None.

        None for a few times (the NumPy path is as fast there), without the compiled library
        (no compiler, ``PLANNER_JIT=0``) or without pieces.
        """
        if len(flat) < 16 or not len(self.knots):
            return None
        lib = load_functions(_SOURCE, "trajectory", _SIGNATURES)
        if lib is None:
            return None
        flat = np.ascontiguousarray(flat, dtype=float)
        pieces = [np.ascontiguousarray(x, dtype=float) for x in (self.knots, self.p, self.v, self.a, self.j)]
        last = np.ascontiguousarray(self.waypoints[-1], dtype=float)
        out = np.empty((len(flat), self.dof))
        lib.positions(
            len(flat),
            self.dof,
            len(pieces[0]),
            flat.ctypes.data,
            *(x.ctypes.data for x in pieces),
            float(self.duration),
            last.ctypes.data,
            out.ctypes.data,
        )
        return out

    def _locate(self, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per time of `flat` in [0, duration]: its interval, the time into it (n, 1) [s], whether it is the end."""
        idx = np.clip(np.searchsorted(self.knots, flat, side="right") - 1, 0, len(self.knots) - 1)
        return idx, (flat - self.knots[idx])[:, None], flat >= self.duration

    def _positions_at(self, idx: np.ndarray, dt: np.ndarray, end: np.ndarray) -> np.ndarray:
        """``p + dt (v + dt (a / 2 + dt j / 6))`` at times `dt` into intervals `idx`, the `end` at rest.

        Written in place, operation by operation as the expression reads (the same values), a
        few times faster than with a temporary array per operation; the rows are gathered with
        ``take`` (the same rows as indexing with `idx`, in about half the time).
        """
        q = self.j.take(idx, axis=0)
        q *= dt
        q /= 6.0
        half = self.a.take(idx, axis=0)
        half /= 2.0
        q += half
        q *= dt
        q += self.v.take(idx, axis=0)
        q *= dt
        q += self.p.take(idx, axis=0)
        if end.any():
            q[end] = self.waypoints[-1]
        return q

    def sample(self, t: float | Sequence[float] | np.ndarray, *, clamp: bool = False) -> TrajectorySample:
        """State at time(s) `t`.

        Args:
            t: A time or an array of times in [0, duration] [s].
            clamp: Accept times outside [0, duration]: before the start they give the state at
                0, after the end the final state (at rest); ``sample.t`` keeps the times asked for.

        Returns:
            The sample; arrays have shape (dof,) for a scalar `t`, (n, dof) for n times.

        Raises:
            InvalidArgumentError: If a time is NaN, or outside [0, duration] without `clamp`.
        """
        tt, asked, flat = self._checked_times(t, clamp)
        scalar = tt.ndim == 0
        idx, dt, end = self._locate(flat)
        v, a, j = self.v.take(idx, axis=0), self.a.take(idx, axis=0), self.j.take(idx, axis=0)
        q = self._positions_at(idx, dt, end)
        qd = v + dt * (a + dt * j / 2.0)
        qdd = a + dt * j
        qddd = j  # a new array (take copies)
        if end.any():
            qd[end], qdd[end], qddd[end] = 0.0, 0.0, 0.0
        if scalar:
            return TrajectorySample(tt.copy(), q[0], qd[0], qdd[0], qddd[0])
        shape = tt.shape + (self.dof,)
        return TrajectorySample(
            asked.reshape(tt.shape).copy(), q.reshape(shape), qd.reshape(shape), qdd.reshape(shape), qddd.reshape(shape)
        )

    def times(self, rate: float = 1000.0) -> np.ndarray:
        """Sample times at `rate` [Hz] from 0, with the final time appended, shape (n,) [s].

        Raises:
            InvalidArgumentError: On a rate that is not positive and finite, or more than
                :data:`MAX_SAMPLES` samples.
        """
        _check_rate(rate)
        count = self.duration * rate
        if not count <= MAX_SAMPLES:
            raise InvalidArgumentError(
                f"sampling {self.duration:.6g} s at {plain(rate)} Hz gives {count:.3g} samples; at most "
                f"{MAX_SAMPLES:.0e} are taken at once (lower the rate or sample times of your own)"
            )
        n = int(math.floor(count + 1e-9)) + 1
        t = np.arange(n) / rate
        if t[-1] < self.duration:
            t = np.append(t, self.duration)
        return t

    def sampled(self, rate: float = 1000.0) -> TrajectorySample:
        """The trajectory sampled at `rate` [Hz] (plus the final instant), arrays (n, dof)."""
        return self.sample(self.times(rate))

    def peak_ratios(self, rate: float | None = 1000.0) -> dict[str, float]:
        """Peak |velocity|, |acceleration| and |jerk| over their limits, and the position margin.

        Args:
            rate: Sampling rate [Hz]; None evaluates the piecewise polynomials exactly
                (interval ends and interior velocity extrema).

        Returns:
            ``{"velocity": ..., "acceleration": ..., "jerk": ..., "position": ...}``: the
            largest ratio over all joints (1.0 means a limit is reached), and for position the
            largest excess beyond the range [rad or m] (<= 0 inside).
        """
        if rate is None:
            s = self._extreme_states()
        else:
            s = self.sampled(rate)
        lim = self.limits
        over_lo = np.where(np.isfinite(lim.lower), lim.lower - s.q, -np.inf)
        over_hi = np.where(np.isfinite(lim.upper), s.q - lim.upper, -np.inf)
        pos = float(np.max(np.maximum(over_lo, over_hi))) if s.q.size else -math.inf
        return {
            "velocity": float(np.max(np.abs(s.qd) / lim.velocity)),
            "acceleration": float(np.max(np.abs(s.qdd) / lim.acceleration)),
            "jerk": float(np.max(np.abs(s.qddd) / lim.jerk)),
            "position": pos,
        }

    def jerk_sign_changes(
        self, t0: float = 0.0, t1: float | None = None, rate: float = 1000.0, floor: float = 0.01
    ) -> np.ndarray:
        """Per joint, how often the sampled jerk changes sign between `t0` and `t1` [s].

        The smoothness count of issue 11: samples at `rate` [Hz] from `t0` (up to, not
        including, `t1`; None: the end), those with |jerk| above `floor` times the joint's jerk
        limit, and the sign changes between consecutive ones. A jerk-limited S-curve between
        two rests has a few; a chain of time-optimal segments through many samples switches
        between +limit and -limit at every one.

        Returns:
            Shape (dof,), integers.

        Raises:
            InvalidArgumentError: On a rate that is not positive and finite.
        """
        _check_rate(rate)
        end = self.duration if t1 is None else float(t1)
        s = self.sample(np.arange(float(t0), end, 1.0 / rate), clamp=True)
        out = np.zeros(self.dof, dtype=int)
        for d in range(self.dof):
            x = s.qddd[:, d]
            x = x[np.abs(x) > floor * self.limits.jerk[d]]
            out[d] = int(np.sum(np.sign(x[1:]) != np.sign(x[:-1])))
        return out

    def _extreme_states(self) -> TrajectorySample:
        """States at every knot, interval end and interior velocity/position extremum."""
        ends = np.append(self.knots[1:], self.duration)
        h = (ends - self.knots)[:, None]
        extra = []
        # Interior extrema of v (where a = 0) and of q (where v = 0) of each cubic piece.
        with np.errstate(divide="ignore", invalid="ignore"):
            tv = -self.a / self.j
            extra.append(np.where((self.j != 0) & (tv > 0) & (tv < h), tv, np.nan))
            disc = self.a**2 - 2.0 * self.j * self.v
            sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
            for r in ((-self.a + sq) / self.j, (-self.a - sq) / self.j):
                extra.append(np.where((self.j != 0) & (r > 0) & (r < h), r, np.nan))
            lin = -self.v / self.a
            extra.append(np.where((self.j == 0) & (self.a != 0) & (lin > 0) & (lin < h), lin, np.nan))
        t = [self.knots, np.minimum(ends, self.duration)]
        for e in extra:
            rows = self.knots[:, None] + e
            t.append(rows[np.isfinite(rows)])
        times = np.clip(np.unique(np.concatenate(t)), 0.0, self.duration)
        s = self.sample(times)
        # Jerk is piecewise constant: its peak is over the intervals themselves.
        jerk = np.vstack([s.qddd, self.j]) if len(self.j) else s.qddd
        return TrajectorySample(s.t, s.q, s.qd, s.qdd, jerk)

    def to_csv(self, path: str | Path, rate: float = 1000.0) -> Path:
        """Write the trajectory sampled at `rate` [Hz] as CSV.

        Columns: ``t`` [s], then ``q_<joint>``, ``qd_<joint>``, ``qdd_<joint>``,
        ``qddd_<joint>`` for every joint (SI units).

        Returns:
            The path written.

        Raises:
            InvalidArgumentError: As :meth:`times`, or if the file cannot be written.
        """
        s = self.sampled(rate)
        out = Path(path)
        names = self.joint_names
        header = ["t"] + [f"{k}_{n}" for k in ("q", "qd", "qdd", "qddd") for n in names]
        try:
            with out.open("w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(header)
                data = np.hstack([s.t[:, None], s.q, s.qd, s.qdd, s.qddd])
                for row in data:
                    w.writerow([repr(float(x)) for x in row])
        except OSError as exc:
            raise InvalidArgumentError(f"cannot write {str(out)!r}: {exc.strerror or exc}") from exc
        return out


#: The fields :meth:`JointTrajectory.lazy` takes (all but the piece arrays).
_LAZY_FIELDS = frozenset(f.name for f in dataclasses.fields(JointTrajectory)) - {"knots", "p", "v", "a", "j"}
