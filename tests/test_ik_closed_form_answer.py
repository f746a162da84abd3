"""solve_ik's closed-form answer against a plain reference built from the family solver and FK.

The reference follows the documented contract step by step (every branch verified by forward
kinematics, sorted by wrapped joint distance to the seed, the answer the nearest branch within
the limits that reaches the target within the tolerances), without the call's shortcuts.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planner import IKOptions, IKStatus, Target, load_robot, solve_ik
from planner.exceptions import PlannerError
from planner.geometry.joint_space import angular_joints, wrapped_distance
from planner.geometry.target import approach_pitch, target_errors
from planner.ik.solvers import IKSolvers

from conftest import single_after

ARMS = ("shelley", "dh3", "three_joint", "al5c")
KINDS = ("position", "pitch", "pose")


def _reference(robot, target, seed, options):
    """(status, q, errors, attempt, [(q, label, within, errors, distance)]) by the contract."""
    family = IKSolvers.of(robot).analytic.solve(target, seed)
    raw = family.solutions
    angular = angular_joints(robot)
    distances = [None if seed is None else wrapped_distance(s.q, seed, angular) for s in raw]
    order = list(range(len(raw)))
    if seed is not None:
        order.sort(key=distances.__getitem__)
    errors = [target_errors(robot, target, s.q) for s in raw]
    ok = [
        i
        for i in order
        if raw[i].within_limits
        and errors[i][0] <= options.position_tolerance
        and errors[i][1] <= options.orientation_tolerance
    ]
    solutions = [(raw[i].q, raw[i].branch, raw[i].within_limits, errors[i], distances[i]) for i in order]
    if ok:
        return IKStatus.SOLVED, raw[ok[0]].q, errors[ok[0]], ok[0], solutions
    within = [i for i in order if raw[i].within_limits]
    if within:
        return IKStatus.INACCURATE, raw[within[0]].q, errors[within[0]], None, solutions
    return IKStatus(family.status), None, None, None, solutions


def _target(robot, kind, q, shift):
    pose = robot.fk(q)
    position = pose[:3, 3] + shift
    if kind == "pose":
        return Target(position, rotation=pose[:3, :3])
    if kind == "pitch":
        return Target(position, pitch=approach_pitch(robot, q))
    return Target(position)


@pytest.mark.parametrize("name", ARMS)
@settings(max_examples=60, deadline=None)
@given(
    data=st.integers(0, 2**32 - 1),
    kind=st.sampled_from(KINDS),
    with_seed=st.booleans(),
    far=st.booleans(),
    strict=st.booleans(),
)
def test_closed_form_answer_matches_the_reference(name, data, kind, with_seed, far, strict):
    # One robot per arm for this module (its solvers built once, not once per example); their
    # kernels never compiled, so every example takes the paths a fresh robot's first calls take.
    single_after(10**12, lambda: _check_answer(_robot(name), data, kind, with_seed, far, strict))


@functools.cache
def _robot(name):
    return load_robot(name)


def _check_answer(robot, data, kind, with_seed, far, strict):
    rng = np.random.default_rng(data)
    q_target, q_seed = robot.random_configurations(rng, 2)
    shift = rng.uniform(-0.3, 0.3, 3) if far else np.zeros(3)
    target = _target(robot, kind, q_target, shift)
    seed = q_seed if with_seed else None
    options = IKOptions(position_tolerance=1e-17, orientation_tolerance=1e-17) if strict else IKOptions()
    try:
        expected = _reference(robot, target, seed, options)
    except PlannerError as exc:  # the family does not take this kind: solve_ik must say the same
        with pytest.raises(type(exc)):
            solve_ik(robot, target, seed, method="analytic", options=options)
        return
    result = solve_ik(robot, target, seed, method="analytic", options=options)
    status, q, errors, attempt, solutions = expected
    assert result.method == "analytic"
    assert result.status == status
    assert result.success == (status == IKStatus.SOLVED)
    assert result.attempt == attempt
    if q is not None:
        np.testing.assert_array_equal(result.q, q)
        assert (result.position_error, result.orientation_error) == pytest.approx(errors, abs=1e-13)
    else:
        np.testing.assert_array_equal(result.q, seed if seed is not None else np.clip(0.0, robot.lower, robot.upper))
    assert not result.q.flags.writeable
    assert len(result.solutions) == len(solutions)
    for got, (q_s, label, within, errors_s, distance) in zip(result.solutions, solutions):
        np.testing.assert_array_equal(got.q, q_s)
        assert (got.label, got.within_limits, got.distance) == (label, within, distance)
        assert (got.position_error, got.orientation_error) == pytest.approx(errors_s, abs=1e-13)
