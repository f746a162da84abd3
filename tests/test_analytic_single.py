"""The compiled nearest kernels (``yaw_planar.single``, ``planar2_single``) against the Python paths.

``YawPlanarIK.nearest`` and ``Planar2IK.nearest`` answer by one compiled call after
``SINGLE_AFTER`` calls of a target kind. Its answer must be the Python paths' (the same
branch, joint values equal to round-off) wherever it answers, and ``solve_ik`` through it must
give the result of the Python paths
(status, reason, counts; ``q`` to round-off), every answer within the limits and confirmed
here by Pinocchio FK; where it is not sure (not solved, ties, a free end angle handed to the
search) the Python paths answer. Generated targets (reachable, random and far; positions,
pitches and poses) on the bundled yaw-planar arms and shelley (planar 2-link).
"""

from __future__ import annotations

import numpy as np
import pytest
from dh_arms import property_settings, seeds, targets, tip_errors
from hypothesis import given
from hypothesis import strategies as st

import planner.ik.analytic.base as analytic_base
from planner import Target, load_robot, solve_ik
from planner.exceptions import UnsupportedChainError
from planner.ik.analytic import closed_form_solver

from conftest import single_after

ARMS = ("al5c", "three_joint", "dh3", "shelley")
# Round-off of two operation sequences (the kernels leave a nearly singular elbow to Python) [rad].
ROUND_OFF = 1e-12


def _pair(name):
    """Two robots of one arm, built once: one for the kernel, one for the scalar paths."""
    cache = _pair.__dict__.setdefault("cache", {})
    if name not in cache:
        cache[name] = (load_robot(name), load_robot(name))
    return cache[name]


def _solvers(name):
    """The closed-form solvers of :func:`_pair`'s robots, built once (each keeps its kernels)."""
    cache = _solvers.__dict__.setdefault("cache", {})
    if name not in cache:
        cache[name] = tuple(closed_form_solver(robot) for robot in _pair(name))
    return cache[name]


@pytest.fixture
def kernel_first(monkeypatch):
    """SINGLE_AFTER 1: the kernel from the first call of a kind."""
    monkeypatch.setattr(analytic_base, "SINGLE_AFTER", 1)


def _scalar(call):
    return single_after(10**12, call)


def _kernel(call):
    return single_after(1, call)


@property_settings(300)
@given(name=st.sampled_from(ARMS), data=st.data())
def test_kernel_answers_as_the_scalar_paths(name, data):
    fast, slow = _solvers(name)
    target, _ = data.draw(targets(fast.robot))
    seed = data.draw(seeds(fast.robot))
    try:
        expected = _scalar(lambda: slow.nearest(target, seed))
    except UnsupportedChainError:
        return
    got = _kernel(lambda: fast.nearest(target, seed))
    if got is None or expected is None:
        assert got is None and expected is None
        return
    assert got.branch == expected.branch
    assert np.max(np.abs(np.subtract(got.q, expected.q))) <= ROUND_OFF


@property_settings(300)
@given(name=st.sampled_from(ARMS), data=st.data())
def test_solve_ik_through_the_kernel(name, data):
    fast, slow = _pair(name)
    target, _ = data.draw(targets(fast))
    seed = data.draw(seeds(fast))
    try:
        expected = _scalar(lambda: solve_ik(slow, target, seed, method="analytic"))
    except UnsupportedChainError:
        with pytest.raises(UnsupportedChainError):
            _kernel(lambda: solve_ik(fast, target, seed, method="analytic"))
        return
    result = _kernel(lambda: solve_ik(fast, target, seed, method="analytic"))
    assert (result.status, result.success, result.reason) == (expected.status, expected.success, expected.reason)
    assert (result.attempts, result.attempt) == (expected.attempts, expected.attempt)
    assert np.max(np.abs(result.q - expected.q)) <= ROUND_OFF
    assert np.all(result.q >= fast.lower) and np.all(result.q <= fast.upper)
    position_error, orientation_error, _ = tip_errors(fast, target, result.q)
    assert result.position_error == pytest.approx(position_error, abs=1e-12)
    assert result.orientation_error == pytest.approx(orientation_error, abs=1e-9)
    if result.success:
        assert position_error <= 1e-6 and orientation_error <= 1e-6
    assert len(result.solutions) == len(expected.solutions)


def test_kernel_used_on_reachable_targets(kernel_first):
    """On reachable targets the kernel answers most calls (count and index left to the result)."""
    robot = load_robot("three_joint")
    solver = closed_form_solver(robot)
    rng = np.random.default_rng(7)
    answered = 0
    for q, seed in zip(robot.random_configurations(rng, 50), robot.random_configurations(rng, 50)):
        nearest = solver.nearest(Target(robot.fk(q)[:3, 3]), seed)
        answered += nearest is not None and nearest.count is None
    # A seed whose end angle one side cannot take hands the target to the search (about half here).
    assert answered >= 20


def test_no_kernel_without_compiler(kernel_first, monkeypatch):
    """With PLANNER_JIT=0 the kernel would run in CasADi's virtual machine: the scalar paths answer."""
    monkeypatch.setenv("PLANNER_JIT", "0")
    robot = load_robot("dh3")
    q = robot.random_configurations(np.random.default_rng(2), 1)[0]
    nearest = closed_form_solver(robot).nearest(Target(robot.fk(q)[:3, 3]), None)
    assert nearest is not None and nearest.count is not None


def test_planar_kernel_used_on_reachable_targets(kernel_first):
    """Shelley's positions and poses through the kernel (count and index left to the result)."""
    robot = load_robot("shelley")
    solver = closed_form_solver(robot)
    rng = np.random.default_rng(8)
    answered = 0
    for q, seed in zip(robot.random_configurations(rng, 20), robot.random_configurations(rng, 20)):
        pose = robot.fk(q)
        for target in (Target(pose[:3, 3]), Target(pose[:3, 3], rotation=pose[:3, :3])):
            nearest = solver.nearest(target, seed)
            answered += nearest is not None and nearest.count is None
    assert answered >= 30
