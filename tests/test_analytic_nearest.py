"""``AnalyticIK.nearest`` (the solution ``solve_ik`` answers with) against the family's whole result.

The reference applies ``solve_ik``'s rule to ``solver.solve``'s result: the solutions within the
limits, in the result's order, sorted stably by their wrapped joint distance to the seed; the
first one. ``nearest`` must pick that solution bitwise, with its place in the result and the
result's count, on random arms of the yaw-planar family and the bundled arms, for reachable
targets and targets moved off them.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from dh_arms import property_settings
from hypothesis import given
from hypothesis import strategies as st
from test_analytic_fast_paths import configuration, yaw_planar_arms

import planner.ik.analytic.base as analytic_base
from planner import Target, load_robot, solve_ik
from planner.exceptions import PlannerError
from planner.geometry.joint_space import angular_joints, wrapped_distance
from planner.geometry.target import approach_pitch
from planner.ik.analytic import closed_form_solver


def _expected(solver, target, seed):
    """(q, branch, count, index) by solve_ik's rule on the whole result, or None without one within the limits."""
    result = solver.solve(target, seed)
    if not result.ok:
        return None
    raw = result.solutions
    within = [i for i, s in enumerate(raw) if s.within_limits]
    if seed is not None:
        angular = angular_joints(solver.robot)
        within.sort(key=lambda i: wrapped_distance(raw[i].q.tolist(), seed.tolist(), angular))
    i = within[0]
    return raw[i].q.tolist(), raw[i].branch, len(raw), i


def _check(solver, target, seed) -> bool:
    """Whether nearest answered (None: solve_ik builds the whole result), checked against the reference."""
    try:
        expected = _expected(solver, target, seed)
    except PlannerError:
        assert solver.nearest(target, seed) is None
        return False
    got = solver.nearest(target, seed)
    if got is None:  # no shortcut: inexact chains, or none within the limits before the search
        return False
    assert expected is not None
    q, branch, count, index = expected
    assert list(got.q) == q  # bitwise
    assert got.branch == branch
    if got.count is None:  # yaw-planar full poses: known once every branch is verified, left to the caller
        assert target.rotation is not None and got.index is None
    else:
        assert (got.count, got.index) == (count, index)
    return True


def _targets(robot, q, shift):
    pose = robot.fk(q)
    position = pose[:3, 3] + shift
    return (
        Target(position),
        Target(position, pitch=approach_pitch(robot, q)),
        Target(position, rotation=pose[:3, :3]),
    )


@property_settings(150)
@given(robot=yaw_planar_arms(), data=st.data())
def test_nearest_on_random_arms(robot, data):
    solver = closed_form_solver(robot)
    q = configuration(data, robot)
    seed = configuration(data, robot) if data.draw(st.booleans()) else None
    far = data.draw(st.booleans())
    shift = np.array([data.draw(st.floats(-0.1, 0.1)) for _ in range(3)]) if far else np.zeros(3)
    for target in _targets(robot, q, shift):
        _check(solver, target, seed)


@pytest.mark.parametrize("name", ["shelley", "dh3", "three_joint", "al5c"])
def test_nearest_on_bundled_arms(name, monkeypatch):
    # The scalar paths, bitwise (test_analytic_single checks the compiled kernel).
    monkeypatch.setattr(analytic_base, "SINGLE_AFTER", 10**12)
    robot = load_robot(name)
    solver = closed_form_solver(robot)
    rng = np.random.default_rng(3)
    answered = 0
    for q, seed in zip(robot.random_configurations(rng, 150), robot.random_configurations(rng, 150)):
        reachable = rng.random() < 0.7
        shift = np.zeros(3) if reachable else rng.uniform(-0.05, 0.05, 3)
        for target in _targets(robot, q, shift):
            answered += _check(solver, target, seed) + _check(solver, target, None)
    if name != "shelley":  # a yaw-planar arm: the shortcut answers most reachable targets
        assert answered > 150


def test_solve_ik_counts_of_a_pose_are_read_from_the_whole_result():
    """solve_ik's pose answer leaves attempts and attempt to the whole result, built when first read."""
    robot = load_robot("al5c")
    q, seed = robot.random_configurations(np.random.default_rng(5), 2)
    target = _targets(robot, q, np.zeros(3))[2]
    result = solve_ik(robot, target, seed)
    assert result.success and result.method == "analytic"
    family = closed_form_solver(robot).solve(target, seed)
    branch = result.reason.removeprefix("closed-form branch ")
    assert result.attempt == next(i for i, s in enumerate(family.solutions) if s.branch == branch)
    assert result.attempts == len(family.solutions)
    copy = dataclasses.replace(result, wall_time=0.0)
    assert (copy.attempts, copy.attempt) == (result.attempts, result.attempt)
    with pytest.raises(AttributeError):
        _ = result.no_such_field
