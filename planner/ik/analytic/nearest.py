"""The solution :func:`planner.solve_ik` answers with, picked without building the whole result.

A closed-form call through ``solve_ik`` needs one configuration: the solution within the joint
limits nearest the seed. :meth:`~planner.ik.analytic.base.AnalyticIK.nearest` picks it from a
solver's raw entries (the rows :func:`~planner.ik.analytic.yaw_planar.scalar.solutions_result`
would turn into an :class:`~planner.ik.analytic.result.AnalyticResult`) by the same rule and the
same arithmetic as ``solve_ik`` applies to the result: the result's order (by the solver's key,
stably), then the within-limits solutions by their joint distance to the seed (angles modulo
2 pi, stably). The whole result is built only when the caller reads every solution.
"""

from __future__ import annotations

import math
from math import sqrt
from operator import itemgetter
from typing import NamedTuple

__all__ = ["NearestSolution", "nearest_entry"]

_first = itemgetter(0)
_PI = math.pi
_TWO_PI = 2.0 * math.pi


class NearestSolution(NamedTuple):
    """The solution within the limits nearest the seed, as the solver's result would order it.

    Attributes:
        q: Joint values [rad] (the result's row, bitwise).
        branch: Its branch name.
        count: How many solutions the result holds, or None where that takes the whole result
            (full poses: whether a branch is a solution is known once it is verified; the
            compiled kernels' answers, which pick without counting).
        index: Its place in the result's solutions, or None (as `count`).
    """

    q: tuple[float, ...]
    branch: str
    count: int | None
    index: int | None


def nearest_entry(entries: list, reference: list[float] | None) -> NearestSolution:
    """The entry within the limits nearest `reference` (see the module docstring).

    Args:
        entries: Per solution (key, slot, q, (within limits, branch name, ...)), unsorted, at
            least one within the limits; sorted in place.
        reference: The seed (dof floats), or None (the result's branch order, first within).

    Returns:
        The chosen solution.
    """
    if reference is None:
        best = next(k for k, entry in enumerate(entries) if entry[3][0])
    else:
        if len(entries) > 1:
            entries.sort(key=_first)
        within = [k for k, entry in enumerate(entries) if entry[3][0]]
        best = within[0]
        if len(within) > 1:
            best_distance = _distance(entries[best][2], reference)
            for k in within[1:]:
                distance = _distance(entries[k][2], reference)
                if distance < best_distance:  # the first of equal distances stays (a stable sort's)
                    best, best_distance = k, distance
    entry = entries[best]
    return NearestSolution(tuple(entry[2]), entry[3][1], len(entries), best)


def _distance(q, reference: list[float]) -> float:
    """planner.ik.solve's joint distance (angles modulo 2 pi), term by term the same."""
    total = 0.0
    for a, b in zip(q, reference):
        d = (a - b + _PI) % _TWO_PI - _PI
        total += d * d
    return sqrt(total)
