"""The compiled tip Jacobian equals Pinocchio's, joint type by joint type, and its users agree without it."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from dh_arms import property_settings
from hypothesis import given
from hypothesis import strategies as st
from test_casadi_kinematics import mixed_robot

import planner.motion.singularity as singularity
from planner import InvalidArgumentError
from planner.core.native import load_library
from planner.geometry.jacobian_kernel import jacobian_kernel
from planner.motion.singularity import bounded_conditioning, inverse_condition_threshold

from conftest import BUNDLED, EXAMPLES, get_robot, needs_example_robot_data


def _pinocchio_jacobians(robot, q: np.ndarray) -> np.ndarray:
    """Each row's tip Jacobian from pin.computeFrameJacobian itself (LOCAL_WORLD_ALIGNED)."""
    model, data = robot.model, robot.model.createData()
    ref = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    jacobian = pin.computeFrameJacobian
    return np.stack(
        [
            np.reshape(
                jacobian(model, data, robot.pinocchio_configuration(row), robot.tip_frame_id, ref), (6, model.nv)
            )
            for row in q
        ]
    )


def _check(robot, seed: int, n: int) -> None:
    kernel = jacobian_kernel(robot)
    assert kernel is not None
    rng = np.random.default_rng(seed)
    # Inside the limits, and far outside them for continuous joints.
    q = robot.random_configurations(rng, n)
    q[:, [k for k, kind in enumerate(robot.joint_kinds) if kind == "continuous"]] *= 5.0
    got = kernel(q)
    assert got.shape == (n, 6, robot.dof)
    np.testing.assert_allclose(got, _pinocchio_jacobians(robot, q), rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", BUNDLED)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 40))
@property_settings(10)
def test_bundled_arms_match_pinocchio(name, seed, n):
    _check(get_robot(name), seed, n)


@needs_example_robot_data
@pytest.mark.parametrize("name", EXAMPLES)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 40))
@property_settings(10)
def test_example_arms_match_pinocchio(name, seed, n):
    _check(get_robot(name), seed, n)


@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 40))
@property_settings(20)
def test_every_joint_type_matches_pinocchio(seed, n):
    # Revolute about unaligned and negative axes, continuous, prismatic along x and a slant,
    # fixed joints between them and a locked gripper joint off the chain.
    _check(mixed_robot(), seed, n)


def test_no_rows_give_an_empty_batch():
    robot = get_robot("dh3")
    assert jacobian_kernel(robot)(np.zeros((0, robot.dof))).shape == (0, 6, robot.dof)


def test_switched_off_or_without_compiler_there_is_no_library(monkeypatch):
    monkeypatch.setenv("PLANNER_JIT", "0")
    assert load_library("int f(void) { return 1; }", "switched_off") is None
    monkeypatch.setenv("PLANNER_JIT", "1")
    monkeypatch.setenv("CC", "no-such-compiler-here")
    assert load_library("int f(void) { return 1; }", "no_compiler") is None


def test_a_broken_source_warns_and_gives_no_library(tmp_path, monkeypatch):
    monkeypatch.setenv("PLANNER_CACHE_DIR", str(tmp_path))
    with pytest.warns(RuntimeWarning, match="cannot build the C library 'broken'"):
        assert load_library("this is not C", "broken") is None


@pytest.mark.parametrize("name", ["dh3", "al5c", "three_joint"])
def test_bounded_measure_is_the_same_without_the_kernel(name, monkeypatch):
    # The kernel's Jacobians only feed bounds; Pinocchio's give the same exact rows and bounds
    # on the same sides (the values of bounds may differ in the last bits).
    robot = get_robot(name)
    task = robot.resolve_task(None)
    rng = np.random.default_rng(3)
    q0 = np.clip(np.zeros(robot.dof), robot.lower, robot.upper)
    walk = np.clip(q0 + np.cumsum(rng.normal(0.0, 1e-3, (1500, robot.dof)), axis=0), robot.lower, robot.upper)
    exact = robot.conditioning(walk, task)[0]
    for threshold in (inverse_condition_threshold(None, task), 0.2):
        with_kernel = bounded_conditioning(robot, walk, task, threshold, keep=[3, 700])[0]
        monkeypatch.setattr(singularity, "jacobian_kernel", lambda robot: None)
        without = bounded_conditioning(robot, walk, task, threshold, keep=[3, 700])[0]
        monkeypatch.undo()
        for inv in (with_kernel, without):
            assert np.array_equal(inv < threshold, exact < threshold)
            assert inv.min() == exact.min() and np.all(inv <= exact)


def test_a_copied_robot_keeps_a_working_kernel():
    # The kernel passes the addresses of its arrays to C: a deep copy of the robot must not
    # keep addresses of arrays that die with the original.
    import copy
    import gc

    robot = mixed_robot()
    q = robot.random_configurations(np.random.default_rng(4), 5)
    want = jacobian_kernel(robot)(q)
    twin = copy.deepcopy(robot)
    del robot
    gc.collect()
    np.testing.assert_array_equal(jacobian_kernel(twin)(q), want)


def test_a_batch_of_the_wrong_shape_is_refused_not_read_past_its_end():
    # The C loop reads n * dof values: a single configuration (dof,) was read as dof rows, and
    # rows of too few joints past the buffer's end (garbage values, or a crash).
    robot = get_robot("dh3")
    kernel = jacobian_kernel(robot)
    for q in (np.zeros(robot.dof), np.zeros((2, robot.dof - 1)), np.zeros((2, robot.dof, 1))):
        with pytest.raises(InvalidArgumentError, match=rf"q must have shape \(n, {robot.dof}\)"):
            kernel(q)


def test_a_compiler_command_with_arguments_builds(tmp_path, monkeypatch):
    # $CC may be a command with arguments (as "ccache gcc"); it was looked up whole on the PATH,
    # not found, and the compiled loops were skipped without a word.
    import shutil

    if shutil.which("gcc") is None or shutil.which("env") is None:
        pytest.skip("needs gcc and env")
    monkeypatch.setenv("PLANNER_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("CC", "env gcc")
    lib = load_library("int planner_answer(void) { return 42; }", "with_arguments")
    assert lib is not None and lib.planner_answer() == 42
