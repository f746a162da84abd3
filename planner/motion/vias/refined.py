"""The ``"refined"`` via strategy: the optimized via states, then a per-joint pattern search.

A Ruckig segment lasts as long as its slowest joint needs (up to Ruckig's blocked intervals):
its duration is the largest of the joints' independent minimum durations, and each of those
depends only on that joint's own states at the segment's two ends. So one Ruckig solve of the
two segments next to a via, with every joint's via state moved at once, tells for each joint
alone what its move would do to both segments; any subset of the moves can then be scored
without solving again (the pair lasts ``max_j t1_j + max_j t2_j``), and the best subset is
solved once to confirm it. The search (a pattern search, Hooke and Jeeves 1961, over every
joint's velocity and acceleration at the via, all joints in parallel) thereby moves the joints
together where several limit a segment, which the one-parameter searches of
:class:`~planner.motion.vias.optimized.OptimizedStrategy` cannot. A move is kept only if the
two segments get shorter and stay within the range by the same exact check the planner's range
repair makes. The search starts from the ``"optimized"`` states brought within the range by
the range repair's own rules (:meth:`RefinedStrategy.fit_range`, which then gives the
``"optimized"`` plan bit for bit), so the plan is never slower than that one.

It costs about four times the plan time of ``"optimized"`` (``benchmarks/bench_refined.py``),
which is why it is an option and not the default.
"""

from __future__ import annotations

import math

import numpy as np

from planner.exceptions import InvalidArgumentError
from planner.motion.limits import admissible_acceleration
from planner.motion.segments import merge_segment, segment_position_range, speed_overshoots
from planner.motion.vias.base import ViaChain, best_choice
from planner.motion.vias.optimized import OptimizedStrategy

__all__ = ["RefinedStrategy", "best_choice"]

#: Halvings of a joint's via state that runs it out of range before it is set to rest.
_FIT_HALVINGS = 6
#: Directions tried per joint in the (velocity, acceleration) plane, in units of the step.
_DIRECTIONS = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])


class RefinedStrategy(OptimizedStrategy):
    """The ``"optimized"`` via states refined by a pattern search over every joint's via state.

    Args:
        sweeps: Passes over the via waypoints.
        levels: Step sizes per via and pass, each a third of the one before.
        step: The first step, as a fraction of each joint's velocity and acceleration limits.

    Raises:
        InvalidArgumentError: A negative or non-integer number of sweeps or levels, or a step
            outside (0, 2].
    """

    name = "refined"

    def __init__(self, sweeps: int = 3, levels: int = 4, step: float = 0.2):
        for what, value in (("sweeps", sweeps), ("levels", levels)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise InvalidArgumentError(f"{what} must be an integer >= 0, got {value!r}")
        if isinstance(step, bool) or not isinstance(step, (int, float, np.number)) or not 0.0 < step <= 2.0:
            raise InvalidArgumentError(f"step must be a number in (0, 2] (a fraction of the limits), got {step!r}")
        self.sweeps = int(sweeps)
        self.levels = int(levels)
        self.step = float(step)

    def choose(self, chain: ViaChain) -> None:
        """The ``"optimized"`` via states, then the pattern search at every free via."""
        super().choose(chain)
        if not self.fit_range(chain):
            return  # left to the planner's range repair (a fixed state runs a joint out)
        free = [i for i in range(1, chain.n - 1) if not chain.fixed[i]]
        # A via whose state and neighbours are as at its last search would search the same again.
        stale = set(free)
        for _ in range(self.sweeps):
            for i in free:
                if i not in stale:
                    continue
                if self.refine_via(chain, i):
                    stale |= {i - 1, i + 1}
                else:
                    stale.discard(i)
            if not stale:
                return

    def _pair(
        self, chain: ViaChain, i: int, v: np.ndarray, acc: np.ndarray
    ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray] | None:
        """The two segments at via i with state (v, acc): total, per-joint times and out-of-range joints."""
        (d1, bad1, traj1), (d2, bad2, traj2) = chain.seg.solve_around(
            i, chain.v[i - 1], chain.acc[i - 1], v, acc, chain.v[i + 1], chain.acc[i + 1]
        )
        if traj1 is None or traj2 is None:
            return None
        bad = np.zeros(len(v), dtype=bool)
        for b in (bad1, bad2):
            if b is not None:
                bad |= b
        t1 = np.array(traj1.independent_min_durations)
        t2 = np.array(traj2.independent_min_durations)
        return d1 + d2, t1, t2, bad

    def _outside_joints(
        self, chain: ViaChain, k: int, i: int = -1, v: np.ndarray | None = None, acc: np.ndarray | None = None
    ) -> np.ndarray | None:
        """The joints that segment k carries out of range or past their speed by the exact checks (bool mask).

        With state (v, acc) at via i if given. None where the segment has no usable profile
        (none from Ruckig, or an end it misses beyond correction): the planner rests there.
        """
        va, aa = (v, acc) if k == i else (chain.v[k], chain.acc[k])
        vb, ab = (v, acc) if k + 1 == i else (chain.v[k + 1], chain.acc[k + 1])
        d, outside, traj = chain.seg.solve(k, va, aa, vb, ab, keep=True)
        if traj is None:
            return None
        merged = merge_segment(traj, d, (chain.q[k], va, aa), chain.q[k + 1], chain.limits)
        if merged.residual.any():
            return None
        bad = np.zeros(chain.q.shape[1], dtype=bool) if outside is None else outside.copy()
        if chain.seg.bounded and d > 0.0:
            lo, hi = segment_position_range(traj, merged, d)
            bad |= (lo < chain.seg.lower) | (hi > chain.seg.upper)
        if d > 0.0:  # the speed check of the range repair too
            fast = speed_overshoots(traj, (va.tolist(), aa.tolist()), (vb.tolist(), ab.tolist()), chain.limits)
            if fast:
                bad[fast] = True
        return bad

    def _exact_inside(
        self, chain: ViaChain, k: int, i: int = -1, v: np.ndarray | None = None, acc: np.ndarray | None = None
    ) -> bool:
        """Whether segment k passes the planner's range checks, with state (v, acc) at via i if given."""
        bad = self._outside_joints(chain, k, i, v, acc)
        return bad is not None and not bad.any()

    def fit_range(self, chain: ViaChain) -> bool:
        """Lower the via states that carry a joint out of range until every segment passes.

        By the rules of the planner's range repair, so that the search starts from the states
        the planner would make of these (a joint's state at the free ends of a segment that
        carries it out is halved, after :data:`_FIT_HALVINGS` halvings or once negligible set
        to rest; a segment without a usable profile rests at its free ends). Where that would
        change a fixed state, nothing is changed and False returned: the planner repairs it.

        Returns:
            Whether every segment passes the exact range check now.
        """
        before = chain.v.copy(), chain.acc.copy()
        halved = np.zeros(chain.v.shape, dtype=int)
        lim = chain.limits
        for _ in range(4 * _FIT_HALVINGS + chain.n):
            changed = False
            for k in range(chain.n - 1):
                bad = self._outside_joints(chain, k)
                ends = [idx for idx in (k, k + 1) if idx > 0]
                if bad is None:
                    moving = [idx for idx in ends if chain.v[idx].any() or chain.acc[idx].any()]
                    if not moving:
                        continue
                    if any(chain.fixed[idx] for idx in moving):
                        break
                    for idx in moving:
                        chain.v[idx] = chain.acc[idx] = 0.0
                    changed = True
                    continue
                if not bad.any():
                    continue
                movable = [idx for idx in ends if np.any(chain.v[idx][bad] != 0) or np.any(chain.acc[idx][bad] != 0)]
                if not movable or any(chain.fixed[idx] for idx in movable):
                    break
                for idx in movable:
                    small = (np.abs(chain.v[idx]) < 1e-6 * lim.velocity) & (
                        np.abs(chain.acc[idx]) < 1e-6 * lim.acceleration
                    ) | (halved[idx] >= _FIT_HALVINGS)
                    halved[idx] += bad
                    factor = np.where(bad, np.where(small, 0.0, 0.5), 1.0)
                    chain.v[idx] *= factor
                    chain.acc[idx] *= factor
                changed = True
            else:
                if not changed:
                    chain.repaired |= (chain.v != before[0]) | (chain.acc != before[1])
                    return True
                continue
            break  # a fixed state would have to change
        chain.v[:], chain.acc[:] = before
        return False

    def _inside_around(self, chain: ViaChain, i: int, v: np.ndarray, acc: np.ndarray) -> bool:
        """Whether both segments at via i with state (v, acc) there pass the planner's range checks."""
        return self._exact_inside(chain, i - 1, i, v, acc) and self._exact_inside(chain, i, i, v, acc)

    def refine_via(self, chain: ViaChain, i: int) -> bool:
        """Pattern search over every joint's state at via i; returns whether it changed.

        Each round moves every joint's velocity up and down and its acceleration up and down
        by the step (four trial states, each solved once for all joints), picks per joint the
        best of its five options (:func:`best_choice`) and keeps the result if it is faster
        and within the range; a round without gain divides the step by three.
        """
        current = self._pair(chain, i, chain.v[i], chain.acc[i])
        if current is None or current[3].any():
            return False
        lim = chain.limits
        step, changed, level = self.step, False, 0
        while level < self.levels:
            # The four trial states at once, shape (4, dof).
            vs = np.minimum(
                np.maximum(chain.v[i] + _DIRECTIONS[:, :1] * (step * lim.velocity), -lim.velocity), lim.velocity
            )
            accs = chain.acc[i] + _DIRECTIONS[:, 1:] * (step * lim.acceleration)
            accs = admissible_acceleration(vs, np.minimum(np.maximum(accs, -lim.acceleration), lim.acceleration), lim)
            options, t1s, t2s = [0], [current[1]], [current[2]]
            for g in range(len(_DIRECTIONS)):
                trial = self._pair(chain, i, vs[g], accs[g])
                if trial is None:
                    continue
                _, t1, t2, bad = trial
                options.append(g + 1)
                if bad.any():
                    t1, t2 = np.where(bad, math.inf, t1), np.where(bad, math.inf, t2)
                t1s.append(t1)
                t2s.append(t2)
            vs = np.concatenate([chain.v[i][None], vs])
            accs = np.concatenate([chain.acc[i][None], accs])
            _, choice = best_choice(np.array(t1s), np.array(t2s))
            found = None
            if choice is not None:
                cols = np.arange(len(choice))
                rows = np.array(options)[choice]
                v = vs[rows, cols]
                acc = admissible_acceleration(v, accs[rows, cols], lim)
                found = self._pair(chain, i, v, acc)
                if (
                    found is None
                    or found[3].any()
                    or found[0] >= current[0]
                    or not self._inside_around(chain, i, v, acc)
                ):
                    found = None
            if found is None:
                step /= 3.0
                level += 1
                continue
            chain.v[i], chain.acc[i] = v, acc
            current, changed = found, True
        return changed
