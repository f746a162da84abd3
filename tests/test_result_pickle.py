"""IK results pickle and copy to equal objects, whether or not their lazy fields were read.

``solve_ik`` leaves some fields to compute when first read (the closed form's ``attempts`` and
``attempt`` on full poses, every ``solutions`` list): their builders are closures that do not
pickle. Results from the public ``solve_ik`` on generated targets go through ``pickle`` (every
protocol) and ``copy.deepcopy`` with those fields unread, and the copy must equal the result
read afterwards, field by field, with ``q`` still read-only. The closed-form solvers' own
results (``AnalyticResult``, ``AnalyticBatchResult``) round-trip too.
"""

from __future__ import annotations

import copy
import functools
import pickle

import numpy as np
from dh_arms import bundled_robot, property_settings, seeds, targets
from hypothesis import given
from hypothesis import strategies as st

from planner import IKResult, UnsupportedChainError, solve_ik
from planner.ik.analytic import closed_form_solver

from conftest import single_after

ARMS = ("al5c", "three_joint", "shelley")


def _copies(value, how: str):
    if how == "deepcopy":
        return copy.deepcopy(value)
    return pickle.loads(pickle.dumps(value, protocol=int(how)))


def _check_frozen(result: IKResult) -> None:
    assert not result.q.flags.writeable
    for solution in result.solutions:
        assert not solution.q.flags.writeable


@property_settings(120)
@given(
    name=st.sampled_from(ARMS),
    data=st.data(),
    method=st.sampled_from(["auto", "analytic", "nlp"]),
    how=st.sampled_from(["deepcopy", *map(str, range(2, pickle.HIGHEST_PROTOCOL + 1))]),
    read_first=st.booleans(),
)
def test_solve_ik_results_round_trip(name, data, method, how, read_first):
    robot = bundled_robot(name)
    target, _ = data.draw(targets(robot))
    seed = data.draw(seeds(robot))
    try:
        result = solve_ik(robot, target, seed, method=method)
    except UnsupportedChainError:  # method="analytic" on a kind without a closed form: documented
        assert method == "analytic"
        return
    if read_first:
        _ = result.attempts, result.attempt, len(result.solutions)
    copied = _copies(result, how)
    assert type(copied) is IKResult
    # Read only now: the copy was made with the lazy fields unread (unless read_first).
    assert copied == result and result == copied
    assert copied.as_dict() == result.as_dict()
    assert (copied.attempts, copied.attempt) == (result.attempts, result.attempt)
    assert tuple(copied.solutions) == tuple(result.solutions)
    _check_frozen(copied)
    # The copy pickles again (its solutions are built now).
    assert _copies(copied, how) == result


def test_lazy_result_round_trip_unread():
    """A closed-form full-pose answer on al5c: counts and solutions lazy, pickled unread."""
    robot = bundled_robot("al5c")
    q = np.array([0.3, 0.4, -0.8, 0.2, 0.1])[: robot.dof]
    pose = robot.fk(q)
    result = solve_ik(robot, pose, q + 0.01)
    assert result.method == "analytic" and result.success
    assert "attempts" not in vars(result) and repr(result.solutions) == "LazySolutions(<not yet read>)"
    copied = pickle.loads(pickle.dumps(result))
    assert copied == result
    assert copied.attempts == len(copied.solutions) == len(result.solutions)
    _check_frozen(copied)


def test_result_equality_is_by_value():
    robot = bundled_robot("three_joint")
    target = robot.fk(np.zeros(robot.dof))[:3, 3]
    a = solve_ik(robot, target)
    b = solve_ik(robot, target)
    assert a != b or a.wall_time == b.wall_time  # wall times differ
    assert a == copy.deepcopy(a)
    assert a != "solved" and (a == None) is False  # noqa: E711


@functools.cache
def _solver(name):
    """One closed-form solver per arm for this module (its kernels built once, not per example)."""
    return closed_form_solver(bundled_robot(name))


@property_settings(60)
@given(name=st.sampled_from(ARMS), data=st.data(), how=st.sampled_from(["deepcopy", "2", "5"]))
def test_analytic_results_round_trip(name, data, how):
    solver = _solver(name)
    robot = solver.robot
    target, _ = data.draw(targets(robot))
    seed = data.draw(seeds(robot))
    try:
        # Never compiled: the path of a fresh solver's first call, as when each example built one.
        result = single_after(10**12, lambda: solver.solve(target, seed))
    except UnsupportedChainError:
        return
    copied = _copies(result, how)
    assert type(copied) is type(result)
    assert (copied.status, copied.reason, copied.singular) == (result.status, result.reason, result.singular)
    assert len(copied.solutions) == len(result.solutions)
    for a, b in zip(copied.solutions, result.solutions):
        assert type(a) is type(b)
        assert np.array_equal(a.q, b.q) and not a.q.flags.writeable
        assert a[1:] == b[1:]
    positions = np.array([robot.fk(q)[:3, 3] for q in (np.zeros(robot.dof), (robot.lower + robot.upper) / 2)])
    batch = solver.solve_batch(positions)
    copied_batch = _copies(batch, how)
    assert type(copied_batch) is type(batch) and copied_batch.branches == batch.branches
    for a, b in zip(copied_batch[:-1], batch[:-1]):
        assert np.array_equal(a, b, equal_nan=True)
    assert not copied_batch.q.flags.writeable
