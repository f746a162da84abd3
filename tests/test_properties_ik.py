"""Property tests of `planner.solve_ik` through the public API, with generated inputs.

Every method ("auto", "analytic", "nlp") on every bundled arm and on arms built from random
DH tables by `planner.urdf_from_dh`; reachable targets (FK of q within the limits), random
points and points beyond any reach; positions, poses and approach pitches; random seeds or
none. With valid input, every call answers with an `IKResult` (only `method="analytic"` on an
arm or target kind without a closed form may raise, with `UnsupportedChainError`), and every
answer is checked here against Pinocchio FK:

- ``q`` has the robot's shape and lies within its joint limits (the `IKResult` promise);
- the reported errors are those of ``q`` by Pinocchio FK;
- ``success`` holds exactly when the status is ``"solved"``, and then the errors are within
  the default tolerances (1e-6 m, 1e-6 rad); a target beyond the arm's reach never succeeds;
- the status is a string, and a failure says why in ``reason``.
"""

from __future__ import annotations

import numpy as np
import pytest
from dh_arms import (
    BUNDLED,
    bundled_robot,
    dh_descriptions,
    property_settings,
    robot_from_description,
    seeds,
    targets,
    tip_errors,
    uncompiled_nlp,
)
from hypothesis import given, note
from hypothesis import strategies as st

import planner

METHODS = ("auto", "analytic", "nlp")
# The defaults of solve_ik, which these tests do not change [m], [rad].
POSITION_TOLERANCE = 1e-6
ORIENTATION_TOLERANCE = 1e-6
# Recomputing an error here may differ from the solver's own Pinocchio call by rounding.
ROUNDING = 1e-12
STATUSES = {status.value for status in planner.IKStatus}


def check_ik(robot: planner.Robot, target: planner.Target, where: str, q_seed, method: str) -> None:
    """Call solve_ik as a user would and check the answer independently."""
    note(f"robot {robot.name} ({robot.dof} joints), method {method!r}, {where} {target.kind} target {target}")
    note(f"q_seed = {None if q_seed is None else q_seed.tolist()}")
    try:
        result = planner.solve_ik(robot, target, q_seed, method=method)
    except planner.UnsupportedChainError as exc:
        if method == "analytic":
            return  # the arm or this target kind has no closed form: documented
        pytest.fail(f"method {method!r} raised {exc!r} on valid input")
    except planner.PlannerError as exc:
        pytest.fail(f"method {method!r} raised {exc!r} on valid input (target and seed are valid)")
    note(f"result: success={result.success} status={result.status} method={result.method} q={result.q.tolist()}")

    assert isinstance(result, planner.IKResult)
    assert isinstance(result.status, str) and result.status in STATUSES
    assert isinstance(result.success, bool)
    assert result.success == (result.status == "solved"), (result.success, result.status)
    assert isinstance(result.reason, str)
    if not result.success:
        assert result.reason.strip(), f"failed with status {result.status} but no reason"
    assert result.method in ("analytic", "nlp")
    if method != "auto":
        assert result.method == method

    q = np.asarray(result.q)
    assert q.shape == (robot.dof,)
    assert np.all(np.isfinite(q))
    assert np.all(q >= robot.lower) and np.all(q <= robot.upper), (
        f"q outside the joint limits: {q.tolist()} not in [{robot.lower.tolist()}, {robot.upper.tolist()}]"
    )

    position_error, orientation_error, elevation_error = tip_errors(robot, target, q)
    assert result.position_error == pytest.approx(position_error, rel=1e-9, abs=ROUNDING)
    assert result.orientation_error == pytest.approx(orientation_error, rel=1e-9, abs=1e-9)
    if result.success:
        assert position_error <= POSITION_TOLERANCE + ROUNDING
        assert orientation_error <= ORIENTATION_TOLERANCE + ROUNDING
        assert elevation_error <= ORIENTATION_TOLERANCE + ROUNDING
    if where == "far":
        assert not result.success, "a target beyond the arm's reach was reported reached"


def _bundled_ik_test(examples: int):
    @pytest.mark.parametrize("method", METHODS)
    @pytest.mark.parametrize("name", BUNDLED)
    @property_settings(examples)
    @given(data=st.data())
    def test(name, method, data):
        robot = bundled_robot(name)
        target, where = data.draw(targets(robot), label="target")
        q_seed = data.draw(seeds(robot), label="q_seed")
        check_ik(robot, target, where, q_seed, method)

    return test


def _dh_ik_test(examples: int):
    @property_settings(examples)
    @given(description=dh_descriptions(), data=st.data())
    def test(description, data):
        robot = robot_from_description(description)
        target, where = data.draw(targets(robot), label="target")
        q_seed = data.draw(seeds(robot), label="q_seed")
        with uncompiled_nlp():
            for method in METHODS:
                check_ik(robot, target, where, q_seed, method)

    return test


test_solve_ik_on_bundled_arms = _bundled_ik_test(80)
test_solve_ik_on_random_dh_arms = _dh_ik_test(60)
test_solve_ik_on_bundled_arms_many = pytest.mark.slow(_bundled_ik_test(500))
test_solve_ik_on_random_dh_arms_many = pytest.mark.slow(_dh_ik_test(200))
