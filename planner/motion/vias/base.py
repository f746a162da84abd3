"""The via-state chain every strategy works on, and the interface of a via strategy.

A :class:`ViaChain` holds the waypoints, the via state (velocity and acceleration) at each of
them, which ones are fixed (the ends, stops, prescribed states), and the Ruckig segments
between them. A :class:`ViaStrategy` chooses the free via states; the planner then repairs
any range overshoot and assembles the trajectory.
"""

from __future__ import annotations

import functools
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import ClassVar

import numpy as np

from planner.motion.limits import JointLimits, admissible_acceleration
from planner.motion.segments import SegmentSolver
from planner.motion.vias.kernels import choose_options

__all__ = ["SEARCH_HALVINGS", "ViaChain", "ViaStrategy", "best_choice"]

#: How often a candidate via state that carries a joint out of its range is halved (the last
#: two times to rest) before it counts as infeasible.
SEARCH_HALVINGS = 6


class ViaChain:
    """Waypoints with their via states and the Ruckig segments between them.

    Attributes:
        q: Waypoints, shape (N, dof) [rad or m].
        n: Number of waypoints N.
        limits: The limits.
        v: Via velocities, shape (N, dof), changed in place by the strategies.
        acc: Via accelerations, shape (N, dof), likewise.
        stop: Waypoints where the arm rests, bool shape (N,).
        fixed: Waypoints whose state no strategy may change, bool shape (N,) (the ends, stops
            and prescribed states).
        seg: The segment solver.
        repaired: Per waypoint and joint, whether the range repair lowered the via state.
    """

    def __init__(
        self,
        q: np.ndarray,
        limits: JointLimits,
        v0: np.ndarray,
        a0: np.ndarray,
        stop: np.ndarray,
        given: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ):
        """Set up the chain: start state, rest at stops and at the end, prescribed states fixed.

        Args:
            q: Waypoints, shape (N, dof) [rad or m].
            limits: The limits.
            v0: Start velocity, shape (dof,).
            a0: Start acceleration, shape (dof,).
            stop: Waypoints to rest at, bool shape (N,).
            given: Prescribed via velocities (N, dof; NaN rows free), accelerations (N, dof)
                and minimum segment durations (N-1,) [s], as :func:`planner.motion.checks.check_given`
                returns them; None for none.
        """
        self.q = q
        self.n = len(q)
        self.limits = limits
        self.v = np.zeros(q.shape)
        self.acc = np.zeros(q.shape)
        self.stop = stop
        self.fixed = stop.copy()
        min_durations = None
        if given is not None:
            gv, ga, min_durations = given
            rows = np.all(np.isfinite(gv), axis=1) & ~stop
            if True in rows.tolist():
                self.v[rows], self.acc[rows] = gv[rows], admissible_acceleration(gv[rows], ga[rows], limits)
                self.fixed |= rows
        self.v[0], self.acc[0] = v0, a0
        self.fixed[0] = self.fixed[-1] = True
        self.v[-1] = self.acc[-1] = 0.0
        rest = [k for k, s in enumerate(stop.tolist()) if s and k > 0]
        if rest:
            self.v[rest] = 0.0
            self.acc[rest] = 0.0
        # The range checks may skip joints that cannot reach a range end where every state is
        # admissible: the strategies' via states are, a given start state need not be.
        start_ok = not (any(v0.tolist()) or any(a0.tolist())) or _admissible(v0, a0, limits)
        given_ok = given is None or bool(np.all(np.abs(self.v) <= limits.velocity))
        admissible = [start_ok and given_ok] + [given_ok] * (self.n - 2)
        self.seg = SegmentSolver(q, limits, min_durations, admissible)
        self.repaired = np.zeros(q.shape, dtype=bool)
        self._rows: tuple[np.ndarray, np.ndarray, list[np.ndarray], list[np.ndarray]] | None = None

    def state_rows(self) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """The rows of :attr:`v` and :attr:`acc` as views (live: they follow every change in place).

        Made once per pair of arrays (indexing a row makes a new view each time).
        """
        rows = self._rows
        if rows is None or rows[0] is not self.v or rows[1] is not self.acc:
            rows = self._rows = (self.v, self.acc, list(self.v), list(self.acc))
        return rows[2], rows[3]

    def durations(self) -> np.ndarray:
        """Duration of every segment with the current via states, shape (N-1,) [s] (inf: no profile)."""
        (v, acc), solve = self.state_rows(), self.seg.solve
        return np.array([solve(k, v[k], acc[k], v[k + 1], acc[k + 1])[0] for k in range(self.n - 1)])

    def limited_by(self, i: int, joints: np.ndarray) -> bool:
        """Whether changing only `joints` (bool mask) at via i could shorten a segment next to it.

        A Ruckig segment takes at least as long as each joint alone needs for its move
        (``independent_min_durations``): where a segment next to via i already takes no longer
        than the other joints alone need, no state of `joints` at via i shortens it. A segment
        without a profile, or whose extrema leave the range (the search would halve states
        there), counts as limited: the argument assumes the current pair is within range.
        """
        for k in (i - 1, i):
            duration, bad, traj = self.seg.solve(k, self.v[k], self.acc[k], self.v[k + 1], self.acc[k + 1])
            if traj is None or bad is not None:
                return True
            others = [t for t, moved in zip(traj.independent_min_durations, joints.tolist()) if not moved]
            if not others or duration > max(others):
                return True
        return False

    def pair_cost(
        self, i: int, cv: np.ndarray, ca: np.ndarray, admissible: bool = False
    ) -> tuple[float, np.ndarray, np.ndarray]:
        """Duration of the two segments around via i with state (cv, ca) there.

        A joint that would leave its range gets its via speed and acceleration halved until
        it does not (Ruckig's extrema are used here for speed; the final plan rechecks exactly).
        With `admissible`, `ca` already obeys :func:`admissible_acceleration` for `cv`.
        """
        if not admissible:
            cv = np.array(cv, dtype=float)
            ca = admissible_acceleration(cv, ca, self.limits)
        both = self.seg.around(i, self.v[i - 1], self.acc[i - 1], self.v[i + 1], self.acc[i + 1])
        return _halved_pair_cost(both, cv, ca)

    def pair_coster(self, i: int) -> Callable[[np.ndarray, np.ndarray], tuple[float, np.ndarray, np.ndarray]]:
        """:meth:`pair_cost` at via i for admissible states, with the neighbours' states as they are now.

        For line searches over via i, which change no other via state while they search.
        """
        v, acc = self.state_rows()
        both = self.seg.around(i, v[i - 1], acc[i - 1], v[i + 1], acc[i + 1])
        halved = functools.partial(_halved_pair_cost, both)

        def pair(cv: np.ndarray, ca: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
            first, second = both(cv, ca)
            if first[1] is None and second[1] is None:  # _halved_pair_cost's first attempt, inline
                return first[0] + second[0], cv, ca
            return halved(cv, ca)

        return pair


def best_choice(
    t1: np.ndarray | Sequence[Sequence[float]], t2: np.ndarray | Sequence[Sequence[float]]
) -> tuple[float, np.ndarray | None]:
    """Per joint one of K options so that ``max t1 + max t2`` over the joints is smallest.

    Option 0 is the joint's current state; a joint leaves it only where it has to (where its
    current times exceed the best choice's segment durations). The first segment's duration
    d1 is swept upwards over the options' t1; per joint the smallest t2 among its options
    with ``t1 <= d1`` is kept as the sweep goes (plain floats: K and dof are small).

    Args:
        t1: Per option and joint, the joint's time in the first segment, shape (K, dof) [s]
            (inf: the option is not allowed); an array or K rows of floats.
        t2: Likewise in the second segment.

    Returns:
        The best ``max t1 + max t2`` [s] and per joint the option to take, shape (dof,), or
        the current value and None where no choice is better.
    """
    rows1 = t1.tolist() if isinstance(t1, np.ndarray) else t1
    rows2 = t2.tolist() if isinstance(t2, np.ndarray) else t2
    dof = len(rows1[0])
    if dof:
        fast = choose_options(rows1, rows2)  # compiled, the same sweep (None: none, or a NaN)
        if fast is not None:
            return fast[0], None if fast[1] is None else np.array(fast[1])
    best = max(rows1[0]) + max(rows2[0])
    flat1 = [x for row in rows1 for x in row]
    flat2 = [x for row in rows2 for x in row]
    order = sorted(range(len(flat1)), key=flat1.__getitem__)  # stable, as np.argsort(kind="stable")
    # The second segment lasts at least as long as any joint's fastest option there: past
    # d1 = best - floor, no choice is better (the sweep stops there).
    floor = max(map(min, zip(*rows2)))
    low = [math.inf] * dof
    missing = dof
    found = None
    last = len(order) - 1
    d2 = math.inf
    for e, index in enumerate(order):
        d1 = flat1[index]
        if d1 + floor >= best:
            break
        j, b = index % dof, flat2[index]
        if low[j] == math.inf:
            missing -= 1
        if b < low[j]:
            if low[j] == d2:
                d2 = math.nan  # the largest one fell: found again below
            low[j] = b
        if missing or (e < last and flat1[order[e + 1]] == d1):
            continue  # not every joint has an option yet, or more options share this d1
        if not d2 < math.inf:
            d2 = max(low)
        if d1 + d2 < best:
            best, found = d1 + d2, (d1, d2)
    if found is None:
        return best, None
    d1, d2 = found
    choice = []
    for j in range(dof):
        if rows1[0][j] <= d1 and rows2[0][j] <= d2:
            choice.append(0)
            continue
        pick, smallest = 0, math.inf  # the first smallest t2 among the allowed options
        for k, (row1, row2) in enumerate(zip(rows1, rows2)):
            if row1[j] <= d1 and row2[j] < smallest:
                pick, smallest = k, row2[j]
        choice.append(pick)
    return best, np.array(choice)


def _admissible(v: np.ndarray, a: np.ndarray, limits: JointLimits) -> bool:
    """Whether a state is within the speed limits and keeps its acceleration under :func:`admissible_acceleration`."""
    return bool(np.all(np.abs(v) <= limits.velocity) and np.array_equal(admissible_acceleration(v, a, limits), a))


def _halved_pair_cost(both: Callable, cv: np.ndarray, ca: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """:meth:`ViaChain.pair_cost` with `both` as :meth:`SegmentSolver.around` returns it.

    `cv` and `ca` are not changed: halved states are new arrays. The masks are worked out on
    plain floats (a few joints: faster than NumPy, with the same products).
    """
    for attempt in range(SEARCH_HALVINGS + 1):
        (d1, bad1, _), (d2, bad2, _) = both(cv, ca)
        if bad1 is None and bad2 is None:
            return d1 + d2, cv, ca
        if bad1 is None or bad2 is None:
            out = (bad2 if bad1 is None else bad1).tolist()
        else:
            out = [x or y for x, y in zip(bad1.tolist(), bad2.tolist())]
        velocities, accelerations = cv.tolist(), ca.tolist()
        bad = [o and (x != 0 or y != 0) for o, x, y in zip(out, velocities, accelerations)]
        if True not in bad:
            return math.inf, cv, ca
        scale = 0.0 if attempt >= SEARCH_HALVINGS - 1 else 0.5
        cv = np.array([x * scale if b else x for b, x in zip(bad, velocities)])
        ca = np.array([x * scale if b else x for b, x in zip(bad, accelerations)])
    return math.inf, cv, ca


class ViaStrategy(ABC):
    """How the free via states of a chain are chosen.

    A strategy is one module in :mod:`planner.motion.vias` plus one line in
    :data:`planner.motion.vias.VIA_STRATEGIES`; :func:`planner.motion.plan.plan_trajectory`
    takes its name.

    Attributes:
        name: The name the registry and :attr:`JointTrajectory.strategy` use.
    """

    name: ClassVar[str]

    def stop_mask(self, stop: np.ndarray, moving_start: bool) -> np.ndarray:
        """The waypoints to rest at, from those the request asks for (shape (N,) bool).

        Args:
            stop: The requested stops (dwell included), bool shape (N,).
            moving_start: Whether the request gives a non-zero start state.

        Returns:
            The stop mask to plan with (by default the requested one).
        """
        return stop

    @abstractmethod
    def choose(self, chain: ViaChain) -> None:
        """Set the free via states of `chain` (``chain.v``, ``chain.acc``) in place.

        Called only for chains of three or more waypoints; fixed waypoints keep their states.
        """
