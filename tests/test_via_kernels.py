"""The via search's compiled loops (planner.motion.vias.kernels) against their Python forms, bit for bit."""

from __future__ import annotations

import math
import types

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planner import load_robot
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory
from planner.motion.vias import base, heuristic, kernels, optimized
from planner.motion.vias.kernels import (
    _library,
    blend_directions,
    choose_joints,
    choose_options,
    choose_probed,
    scale_states,
    spline_states,
)
from planner.motion.vias.optimized import _scaled_states, spline_via_states

pytestmark = pytest.mark.skipif(_library() is None, reason="no C compiler (or PLANNER_JIT=0): the Python paths only")

LIMITS = JointLimits(
    np.array([1.0, 2.5, 0.3]),
    np.array([2.0, 5.0, 0.6]),
    np.array([20.0, 50.0, 6.0]),
    np.full(3, -10.0),
    np.full(3, 10.0),
)

# Times with many ties (a few values), zeros of either sign and inf, as the probes give them.
times = st.one_of(st.sampled_from([0.0, -0.0, 0.5, 1.0, 1.5, 2.0, math.inf]), st.floats(0.0, 3.0))


def python_best_choice(rows1, rows2, monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(base, "choose_options", lambda a, b: None)
        best, choice = base.best_choice(rows1, rows2)
    return best, None if choice is None else choice.tolist()


@settings(max_examples=400, deadline=None)
@given(st.integers(1, 9), st.integers(1, 7), st.data())
def test_compiled_choice_equals_the_python_sweep(k, dof, data):
    rows1 = [data.draw(st.lists(times, min_size=dof, max_size=dof)) for _ in range(k)]
    rows2 = [data.draw(st.lists(times, min_size=dof, max_size=dof)) for _ in range(k)]
    rows1[0] = [x if x < math.inf else 1.0 for x in rows1[0]]  # the current state has finite times
    rows2[0] = [x if x < math.inf else 1.0 for x in rows2[0]]
    with pytest.MonkeyPatch.context() as monkeypatch:
        want = python_best_choice(rows1, rows2, monkeypatch)
    got = choose_options(rows1, rows2)
    assert got is not None
    assert got[0] == want[0] and got[1] == want[1]
    assert math.copysign(1.0, got[0]) == math.copysign(1.0, want[0])


def test_compiled_choice_leaves_nan_to_python():
    assert choose_options([[1.0, math.nan]], [[1.0, 2.0]]) is None
    assert choose_options([[1.0, 2.0], [0.5, 0.5]], [[1.0, 2.0], [math.nan, 0.5]]) is None


def test_best_choice_takes_the_compiled_path_where_there_is_one(monkeypatch):
    rows1 = [[1.0, 2.0], [0.5, 1.0]]
    rows2 = [[1.0, 2.0], [0.5, 1.0]]
    calls = []

    def spy(a, b):
        calls.append((a, b))
        return choose_options(a, b)

    monkeypatch.setattr(base, "choose_options", spy)
    best, choice = base.best_choice(rows1, rows2)
    assert calls and best == 2.0 and choice.tolist() == [0, 1]


components = st.one_of(st.sampled_from([0.0, -0.0, 1e-300, -1e-300, 5.0, -5.0]), st.floats(-1e3, 1e3))


@settings(max_examples=300, deadline=None)
@given(
    st.lists(components, min_size=3, max_size=3),
    st.lists(components, min_size=3, max_size=3),
    st.lists(st.one_of(st.sampled_from([0.0, 1.0, 1e100]), st.floats(0.0, 1e3)), min_size=1, max_size=6),
)
def test_compiled_scaled_states_equal_the_numpy_form(u, w, grid):
    u, w = np.array(u), np.array(w)
    limits = LIMITS.velocity.tobytes() + LIMITS.acceleration.tobytes() + LIMITS.twice_jerk.tobytes()
    cv, ca = scale_states(grid, u, w, limits)
    want_v, want_a = _scaled_states(np.array(grid), np.sign(u), np.abs(u), np.sign(w), np.abs(w), LIMITS)
    assert cv.tobytes() == want_v.tobytes() and ca.tobytes() == want_a.tobytes()


def test_many_options_take_the_python_path():
    rows = [[1.0 + 0.001 * k] * 10 for k in range(500)]  # 5000 entries
    assert choose_options(rows, rows) is None
    best, choice = base.best_choice(rows, rows)
    assert best == 2.0 and choice is None


@pytest.mark.parametrize("name", ["three_joint", "al5c", "dh3"])
def test_plans_are_the_same_with_and_without_the_compiled_loops(name, monkeypatch):
    robot = load_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(11)
    paths = [robot.random_configurations(rng, 5) for _ in range(12)]

    def arrays(traj):
        return [traj.duration, *(np.asarray(a).tobytes() for a in (traj.via_velocities, traj.via_accelerations))]

    compiled = [arrays(plan_trajectory(q, limits)) for q in paths]
    monkeypatch.setattr(kernels, "_library", lambda: None)
    assert [arrays(plan_trajectory(q, limits)) for q in paths] == compiled


# Waypoints, durations and end velocities as runs have them, and edge values (zeros of either
# sign, tiny and huge durations).
positions = st.one_of(st.sampled_from([0.0, -0.0, 1e-300, 3.0, -3.0]), st.floats(-10.0, 10.0))
durations = st.one_of(st.sampled_from([1e-300, 1e-9, 1.0, 1e300]), st.floats(1e-6, 1e3))


def python_spline(q, h, v_start, v_end, monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(optimized, "spline_states", lambda *args: None)
        return optimized.spline_via_states(q, h, v_start, v_end)


@settings(max_examples=300, deadline=None)
@given(st.integers(2, 6), st.integers(1, 7), st.data())
def test_compiled_spline_states_equal_the_python_form(m, dof, data):
    q = np.array([data.draw(st.lists(positions, min_size=dof, max_size=dof)) for _ in range(m + 1)])
    h = np.array(data.draw(st.lists(durations, min_size=m, max_size=m)))
    v_start = np.array(data.draw(st.lists(positions, min_size=dof, max_size=dof)))
    v_end = np.array(data.draw(st.lists(positions, min_size=dof, max_size=dof)))
    got = spline_states(q, h, v_start, v_end)
    assert got is not None
    with pytest.MonkeyPatch.context() as monkeypatch:
        want = python_spline(q, h, v_start, v_end, monkeypatch)
    assert got[0].shape == want[0].shape == (m - 1, dof) and got[1].shape == want[1].shape
    assert got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes()


def test_spline_states_leave_bad_durations_to_python():
    q = np.zeros((3, 2))
    v = np.zeros(2)
    assert spline_states(q, np.array([1.0, 0.0]), v, v) is None
    assert spline_states(q, np.array([1.0, math.inf]), v, v) is None
    assert spline_states(q, np.array([1.0, math.nan]), v, v) is None
    assert spline_states(q[:2], np.array([1.0]), v, v) is None
    assert spline_via_states(q, np.array([1.0, 2.0]), v, v)[0].tolist() == [[0.0, 0.0]]


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.lists(positions, min_size=3, max_size=3), min_size=3, max_size=3),
    durations,
    durations,
)
def test_compiled_slope_blend_equals_the_python_form(rows, tp, tn):
    q = np.array(rows)
    stop = np.zeros(3, dtype=bool)
    got = heuristic.via_directions(q, 1, np.array([tp, tn]), LIMITS, stop)
    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(heuristic, "blend_directions", lambda *args: None)
        want = heuristic.via_directions(q, 1, np.array([tp, tn]), LIMITS, stop)
    assert got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes()
    assert blend_directions(q, tp, tn, LIMITS.velocity, LIMITS.acceleration) is not None


@settings(max_examples=400, deadline=None)
@given(st.integers(1, 4), st.integers(1, 6), st.integers(1, 7), st.data())
def test_compiled_probed_choice_equals_the_python_sweep_on_the_rows(k, probes, dof, data):
    rows1 = [data.draw(st.lists(times, min_size=dof, max_size=dof)) for _ in range(k)]
    rows2 = [data.draw(st.lists(times, min_size=dof, max_size=dof)) for _ in range(k)]
    rows1[0] = [x if x < math.inf else 1.0 for x in rows1[0]]  # the current state has finite times
    rows2[0] = [x if x < math.inf else 1.0 for x in rows2[0]]
    joints = tuple(sorted(data.draw(st.sets(st.integers(0, dof - 1), min_size=1))))
    count = len(joints)
    p1 = data.draw(st.lists(times, min_size=probes * count, max_size=probes * count))
    p2 = data.draw(st.lists(times, min_size=probes * count, max_size=probes * count))
    # The rows the probed times stand for: inf for a joint not probed.
    full1 = [[p1[c * count + joints.index(j)] if j in joints else math.inf for j in range(dof)] for c in range(probes)]
    full2 = [[p2[c * count + joints.index(j)] if j in joints else math.inf for j in range(dof)] for c in range(probes)]
    with pytest.MonkeyPatch.context() as monkeypatch:
        want = python_best_choice(rows1 + full1, rows2 + full2, monkeypatch)
    got = choose_probed(rows1, rows2, (p1, p2), joints)
    assert got is not None
    assert got[0] == want[0] and got[1] == want[1]
    assert math.copysign(1.0, got[0]) == math.copysign(1.0, want[0])
    # The search's Python path (no library) builds the same rows.
    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(optimized, "choose_probed", lambda *args: None)
        monkeypatch.setattr(base, "choose_options", lambda a, b: None)
        assert optimized._probed_choice(rows1, rows2, ([], joints, (p1, p2))) == want[1]
    assert optimized._probed_choice(rows1, rows2, ([], joints, (p1, p2))) == want[1]


def test_compiled_probed_choice_leaves_nan_to_python():
    assert choose_probed([[1.0, 2.0]], [[1.0, 2.0]], ([math.nan], [0.5]), (1,)) is None
    assert choose_probed([[1.0, 2.0]], [[1.0, 2.0]], ([], []), ()) is None
    assert optimized._probed_choice([[1.0, 2.0]], [[1.0, 2.0]], ([], (1,), ([0.5], [0.5]))) == [0, 1]


@pytest.mark.parametrize("name", ["three_joint", "dh3"])
def test_plans_are_the_same_through_the_c_api_and_ctypes(name, monkeypatch):
    from planner.motion import segment_kernels

    if not isinstance(kernels._library(), types.ModuleType):
        pytest.skip("no Python headers: the kernels are called through ctypes only")
    robot = load_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(12)
    paths = [robot.random_configurations(rng, 5) for _ in range(12)]

    def arrays(traj):
        return [traj.duration, *(np.asarray(a).tobytes() for a in (traj.via_velocities, traj.via_accelerations))]

    through_c_api = [arrays(plan_trajectory(q, limits)) for q in paths]
    monkeypatch.setattr(kernels, "_LOADED", [kernels._ctypes_library()])
    monkeypatch.setattr(segment_kernels, "_LOADED", [segment_kernels._ctypes_library()])
    assert [arrays(plan_trajectory(q, limits)) for q in paths] == through_c_api


@settings(max_examples=300, deadline=None)
@given(st.integers(1, 6), st.integers(0, 4), st.integers(1, 6), st.data())
def test_choices_are_the_same_through_the_c_api_and_ctypes(k, probes, dof, data):
    if not isinstance(kernels._library(), types.ModuleType):
        pytest.skip("no Python headers: the kernels are called through ctypes only")
    values = st.one_of(times, st.just(math.nan))
    rows1 = [data.draw(st.lists(values, min_size=dof, max_size=dof)) for _ in range(k)]
    rows2 = [data.draw(st.lists(values, min_size=dof, max_size=dof)) for _ in range(k)]
    if data.draw(st.booleans()):  # ragged rows (the same total or not)
        rows1[-1] = rows1[-1][:-1] + data.draw(st.lists(values, max_size=2))
    joints = tuple(sorted(data.draw(st.sets(st.integers(0, dof - 1), min_size=1))))
    p1 = data.draw(st.lists(values, min_size=probes * len(joints), max_size=probes * len(joints)))
    p2 = data.draw(st.lists(values, min_size=len(p1), max_size=len(p1)))

    def both():
        return repr(choose_options(rows1, rows2)), repr(choose_probed(rows1, rows2, (p1, p2), joints))

    through_c_api = both()
    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(kernels, "_LOADED", [kernels._ctypes_library()])
        assert both() == through_c_api  # (repr: NaN and the sign of zeros too)


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 5), st.integers(2, 4), st.data())
def test_states_and_joint_choice_are_the_same_through_the_c_api_and_ctypes(dof, m, data):
    if not isinstance(kernels._library(), types.ModuleType):
        pytest.skip("no Python headers: the kernels are called through ctypes only")
    floats = st.one_of(st.sampled_from([0.0, -0.0, math.inf, 1e-300]), st.floats(-10.0, 10.0))
    u, w, v_start, v_end = (np.array(data.draw(st.lists(floats, min_size=dof, max_size=dof))) for _ in range(4))
    q = np.array([data.draw(st.lists(floats, min_size=dof, max_size=dof)) for _ in range(m + 1)])
    h = np.array(data.draw(st.lists(st.one_of(st.just(0.0), st.floats(0.01, 5.0)), min_size=m, max_size=m)))
    grid = data.draw(st.lists(st.floats(0.0, 5.0), max_size=5))
    limits = JointLimits(
        np.linspace(1.0, 2.0, dof),
        np.linspace(2.0, 3.0, dof),
        np.linspace(20.0, 30.0, dof),
        -np.ones(dof),
        np.ones(dof),
    )
    size = 3 * m * dof
    run_times = data.draw(st.lists(st.one_of(times, st.just(math.nan)), min_size=size, max_size=size))
    tp, tn = data.draw(st.floats(0.01, 5.0)), data.draw(st.floats(0.01, 5.0))

    def outputs():
        spline = spline_states(q, h, v_start, v_end)
        return repr(
            [
                None if spline is None else [x.tobytes() for x in spline],
                [x.tobytes() for x in scale_states(grid, u, w, limits.kernel_limits)],
                [x.tobytes() for x in blend_directions(q[:3], tp, tn, limits.velocity, limits.acceleration)],
                choose_joints(run_times, (3, m, dof), 2),
            ]
        )

    through_c_api = outputs()
    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(kernels, "_LOADED", [kernels._ctypes_library()])
        assert outputs() == through_c_api


@settings(max_examples=300, deadline=None)
@given(st.integers(1, 6), st.data())
def test_compiled_moved_states_equal_the_python_loop(dof, data):
    from planner.motion.vias import joint_steps

    if not isinstance(kernels._library(), types.ModuleType):
        pytest.skip("no Python headers: the Python loop only")
    floats = st.one_of(st.sampled_from([0.0, -0.0, math.inf, math.nan, 1e-300]), st.floats(-10.0, 10.0))
    limit_rows = [tuple(data.draw(st.lists(st.floats(0.0, 50.0), min_size=dof, max_size=dof))) for _ in range(3)]
    state = tuple(data.draw(st.lists(floats, min_size=dof, max_size=dof)) for _ in range(2))
    joints = tuple(sorted(data.draw(st.sets(st.integers(0, dof - 1)))))
    moves = data.draw(st.lists(st.one_of(st.sampled_from([0.0, -0.05, 0.05]), st.floats(-1.0, 1.0)), max_size=4))
    got = joint_steps.moved_states(tuple(limit_rows), state, joints, moves)
    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(joint_steps, "moved_states_compiled", lambda *args: None)
        want = joint_steps.moved_states(tuple(limit_rows), state, joints, moves)
    assert repr(got) == repr(want)  # (repr: NaN and the sign of zeros too)
