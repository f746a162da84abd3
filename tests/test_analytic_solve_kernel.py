"""``YawPlanarIK.solve``'s compiled path (``yaw_planar.single.SolveKernel``) against the Python paths.

After ``SINGLE_AFTER`` calls of a target kind, ``solve`` answers exact yaw-planar chains by one
compiled call where it is sure. Its result must be the Python paths' (status, reason, the
solutions in the same order with the same branches and masks, joint values equal to round-off),
every solution confirmed here by Pinocchio FK; where it is not sure the Python paths answer.
Generated targets (reachable, random and far; positions, pitches and poses) with and without a
seed on the bundled yaw-planar arms.
"""

from __future__ import annotations

import numpy as np
import pytest
from dh_arms import property_settings, seeds, targets, tip_errors
from hypothesis import given
from hypothesis import strategies as st

from planner import Target, load_robot
from planner.exceptions import UnsupportedChainError
from planner.geometry.target import approach_pitch
from planner.ik.analytic import closed_form_solver

from conftest import single_after

ARMS = ("al5c", "three_joint", "dh3")
# Round-off of two operation sequences [rad].
ROUND_OFF = 1e-12


def _solvers(name):
    """Two closed-form solvers of one arm, built once: one with its compiled path, one with the
    Python paths only (its plan without the compiled closed form)."""
    cache = _solvers.__dict__.setdefault("cache", {})
    if name not in cache:
        slow = closed_form_solver(load_robot(name))
        slow._scalar_plan = slow._scalar_plan._replace(compiled=None)
        cache[name] = (closed_form_solver(load_robot(name)), slow)
    return cache[name]


@property_settings(400)
@given(name=st.sampled_from(ARMS), data=st.data())
def test_compiled_solve_answers_as_the_python_paths(name, data):
    fast, slow = _solvers(name)
    target, _ = data.draw(targets(fast.robot))
    seed = data.draw(seeds(fast.robot))
    try:
        expected = slow.solve(target, seed)
    except UnsupportedChainError:
        return
    result = single_after(1, lambda: fast.solve(target, seed))
    assert (result.status, result.reason, result.singular) == (expected.status, expected.reason, expected.singular)
    assert [s.branch for s in result.solutions] == [s.branch for s in expected.solutions]
    for got, want in zip(result.solutions, expected.solutions):
        assert (got.within_limits, got.singular) == (want.within_limits, want.singular)
        assert np.max(np.abs(got.q - want.q)) <= ROUND_OFF
        assert not got.q.flags.writeable
        position_error, orientation_error, _ = tip_errors(fast.robot, target, got.q)
        assert position_error <= 1e-9 and got.position_error <= 1e-9
        assert got.within_limits == bool(fast.robot.within_limits(got.q))
        if target.pitch is None and target.rotation is None:
            assert got.orientation_error is None
        else:
            assert orientation_error <= 1e-9 and got.orientation_error <= 1e-9


@pytest.mark.parametrize("name", ARMS)
def test_compiled_solve_used_on_reachable_targets(name):
    """On reachable targets the compiled path answers most calls of every kind (with a seed or not)."""
    solver = closed_form_solver(load_robot(name))
    robot = solver.robot
    compiled = solver._scalar_plan.compiled
    rng = np.random.default_rng(3)
    qs = robot.random_configurations(rng, 40)
    poses = robot.fk(qs)
    for kind in ("position", "pitch", "pose"):
        for with_seed in (False, True):
            answered = 0
            for pose, q in zip(poses, qs):  # the seed: the generating configuration (a nearby q_current)
                pitch = approach_pitch(robot, q) if kind == "pitch" else None
                rotation = pose[:3, :3] if kind == "pose" else None
                qc = q.tolist() if with_seed else None
                found = single_after(1, lambda p=pose[:3, 3], a=pitch, r=rotation, c=qc: compiled.entries(p, a, r, c))
                answered += found is not None
            # (Poses with a seed on arms with a roll: the two sides' yaws, from the rotation, lie
            # half a turn apart, where the wrap towards the seed is left to the Python path.)
            if not (kind == "pose" and with_seed and solver.arm.has_roll):
                assert answered >= 30, (kind, with_seed, answered)


@pytest.mark.parametrize("name", ARMS)
def test_answers_do_not_depend_on_earlier_calls(name):
    """A solver's first calls (CasADi's virtual machine) and later ones (compiled C) give the same doubles."""
    robot = load_robot(name)
    rng = np.random.default_rng(11)
    qs = robot.random_configurations(rng, 30)
    poses = robot.fk(qs)
    targets_ = [Target(p[:3, 3]) for p in poses] + [Target(p[:3, 3], rotation=p[:3, :3]) for p in poses]
    warm = closed_form_solver(robot)
    for target, q in zip(targets_ * 2, np.concatenate([qs, qs, qs, qs])):  # compiled after SINGLE_AFTER calls
        warm.solve(target, q)
    assert all(k.compiled for k in warm._scalar_plan.compiled._built.values() if k)
    # One solver whose kernels are never compiled: every call as a fresh solver's first call of
    # its kind (the virtual machine), without building a kernel (0.1-0.3 s) per target.
    cold = closed_form_solver(robot)
    for target, q in zip(targets_, np.concatenate([qs, qs])):
        first, later = single_after(10**12, lambda t=target, c=q: cold.solve(t, c)), warm.solve(target, q)
        assert (first.status, first.reason) == (later.status, later.reason)
        assert [s.branch for s in first.solutions] == [s.branch for s in later.solutions]
        for a, b in zip(first.solutions, later.solutions):
            assert a.q.tobytes() == b.q.tobytes()
            assert (a.position_error, a.orientation_error) == (b.position_error, b.orientation_error)
    assert cold._scalar_plan.compiled._built and not any(
        k.compiled for k in cold._scalar_plan.compiled._built.values() if k
    )
