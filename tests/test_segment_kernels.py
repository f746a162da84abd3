"""The segment solver's compiled loops (planner.motion.segment_kernels) against their Python forms, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planner.motion import segments
from planner.motion.limits import JointLimits
from planner.motion.segment_kernels import _library
from planner.motion.segments import SegmentSolver

pytestmark = pytest.mark.skipif(_library() is None, reason="no C compiler (or PLANNER_JIT=0): the Python paths only")

# Range ends: finite, unbounded, near zero; positions anywhere in a few turns (beyond the ends too).
ends = st.one_of(st.sampled_from([0.0, -0.0, 1e-12, math.pi, 2.0 * math.pi, math.inf]), st.floats(0.0, 7.0))
positions = st.one_of(st.sampled_from([0.0, -0.0, math.pi, -math.pi]), st.floats(-8.0, 8.0))
limit = st.floats(0.01, 50.0)


def _watch(q, limits, admissible, monkeypatch, compiled):
    """The solver's watch lists and its reach times (the latter from the compiled loop, or _reach_times)."""
    with monkeypatch.context() as m:
        if not compiled:
            m.setattr(segments, "watch_times", lambda *args: None)
        segments._RANGE_ENDS.clear()
        solver = SegmentSolver(q, limits, None, admissible)
        reach = solver._reach_times() if solver._reach is None else solver._reach
        return solver._watch, reach


@settings(max_examples=300, deadline=None)
@given(st.integers(1, 7), st.integers(2, 6), st.data())
def test_compiled_watch_equals_the_python_loop(dof, n, data):
    velocity = np.array(data.draw(st.lists(limit, min_size=dof, max_size=dof)))
    acceleration = np.array(data.draw(st.lists(limit, min_size=dof, max_size=dof)))
    upper = np.array(data.draw(st.lists(ends, min_size=dof, max_size=dof)))
    lower = -np.array(data.draw(st.lists(ends, min_size=dof, max_size=dof)))
    limits = JointLimits(velocity, acceleration, 10.0 * acceleration, lower, upper)
    q = np.array([data.draw(st.lists(positions, min_size=dof, max_size=dof)) for _ in range(n)])
    admissible = data.draw(st.lists(st.booleans(), min_size=n - 1, max_size=n - 1))
    with pytest.MonkeyPatch.context() as monkeypatch:
        want, want_reach = _watch(q, limits, admissible, monkeypatch, compiled=False)
        got, got_reach = _watch(q, limits, admissible, monkeypatch, compiled=True)
    assert repr(got) == repr(want)  # (repr: the sign of zeros and infinities too)
    # The least per joint: equal (where two ends tie, the zero kept may have the other sign).
    assert got_reach == want_reach
    if limits.bounded and any(admissible):
        assert all((w is None) != ok for w, ok in zip(got, admissible))


def test_range_ends_are_made_once_per_set_of_limits():
    limits = JointLimits(np.ones(2), np.ones(2), np.ones(2), -np.ones(2), np.ones(2))
    first = segments._range_ends(limits)
    assert segments._range_ends(limits) is first
    other = JointLimits(np.ones(2), np.ones(2), np.ones(2), -np.ones(2), np.ones(2))
    assert segments._range_ends(other) is not first


def _admissible_numpy(v, a, limits, monkeypatch):
    """admissible_acceleration through its NumPy path."""
    from planner.motion import limits as limits_module

    with monkeypatch.context() as m:
        m.setattr(limits_module, "admissible_states", lambda *args: None)
        return limits_module.admissible_acceleration(v, a, limits)


# Velocities and accelerations anywhere (beyond the limits, zeros of either sign, infinities, NaN).
states = st.one_of(
    st.sampled_from([0.0, -0.0, math.inf, -math.inf, math.nan, 1e-300]), st.floats(-60.0, 60.0, allow_nan=False)
)


@settings(max_examples=300, deadline=None)
@given(st.integers(1, 7), st.lists(st.integers(1, 3), max_size=2), st.data())
def test_compiled_admissible_acceleration_equals_numpy(dof, lead, data):
    from planner.motion.limits import admissible_acceleration

    velocity = np.array(data.draw(st.lists(limit, min_size=dof, max_size=dof)))
    acceleration = np.array(data.draw(st.lists(limit, min_size=dof, max_size=dof)))
    limits = JointLimits(velocity, acceleration, 10.0 * acceleration, -np.ones(dof), np.ones(dof))
    shape = (*lead, dof)
    size = int(np.prod(shape))
    v = np.array(data.draw(st.lists(states, min_size=size, max_size=size))).reshape(shape)
    a = np.array(data.draw(st.lists(states, min_size=size, max_size=size))).reshape(shape)
    with pytest.MonkeyPatch.context() as monkeypatch:
        want = _admissible_numpy(v, a, limits, monkeypatch)
    got = admissible_acceleration(v, a, limits)
    assert got.shape == want.shape
    assert got.tobytes() == want.tobytes()  # bit for bit, the sign of zeros and NaN included
    assert got is not a and got.flags.writeable


def test_admissible_acceleration_takes_numpy_for_other_inputs():
    from planner.motion.segment_kernels import admissible_states

    limits = JointLimits(np.ones(2), np.ones(2), np.ones(2), -np.ones(2), np.ones(2))
    v = np.zeros(2)
    assert admissible_states(v, np.zeros(3), limits.kernel_limits) is None  # shapes differ
    assert admissible_states(v, np.zeros(2, dtype=np.float32), limits.kernel_limits) is None
    assert admissible_states(v, [0.0, 0.0], limits.kernel_limits) is None
    assert admissible_states(np.zeros((2, 3)), np.zeros((2, 3)), limits.kernel_limits) is None  # dof differs


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 6), st.integers(2, 5), st.data())
def test_watch_and_admissible_are_the_same_through_the_c_api_and_ctypes(dof, n, data):
    import types

    from planner.motion import segment_kernels
    from planner.motion.limits import admissible_acceleration

    if not isinstance(segment_kernels._library(), types.ModuleType):
        pytest.skip("no Python headers: the kernels are called through ctypes only")
    velocity = np.array(data.draw(st.lists(limit, min_size=dof, max_size=dof)))
    upper = np.array(data.draw(st.lists(ends, min_size=dof, max_size=dof)))
    limits = JointLimits(velocity, 2.0 * velocity, 20.0 * velocity, -upper, upper)
    q = np.array([data.draw(st.lists(positions, min_size=dof, max_size=dof)) for _ in range(n)])
    v = np.array(data.draw(st.lists(states, min_size=n * dof, max_size=n * dof))).reshape(n, dof)

    def outputs():
        segments._RANGE_ENDS.clear()
        solver = SegmentSolver(q, limits, None, [True] * (n - 1))
        return repr((solver._watch, solver._reach)), admissible_acceleration(v, v, limits).tobytes()

    through_c_api = outputs()
    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(segment_kernels, "_LOADED", [segment_kernels._ctypes_library()])
        assert outputs() == through_c_api


class _Profile:
    """A stand-in for a Ruckig profile: its per-phase lists."""

    def __init__(self, j, a, p, v):
        self.j, self.a, self.p, self.v = j, a, p, v


@settings(max_examples=300, deadline=None)
@given(st.data())
def test_compiled_zero_jerk_turns_equal_the_python_loop(data):
    import types

    from planner.motion import segment_kernels

    if not isinstance(segment_kernels._library(), types.ModuleType):
        pytest.skip("no Python headers: the Python loop only")
    values = st.one_of(st.sampled_from([0.0, -0.0, 1.0, -1.0, math.inf, math.nan]), st.floats(-5.0, 5.0))
    phases = data.draw(st.integers(0, 8))
    jerk = data.draw(st.lists(st.one_of(st.just(0.0), values), min_size=phases, max_size=phases))
    v, a, p = (data.draw(st.lists(values, min_size=phases + 1, max_size=phases + 1)) for _ in range(3))
    if data.draw(st.booleans()):  # lists too short for the loop
        v, a = v[: data.draw(st.integers(0, phases))], a[: data.draw(st.integers(0, phases))]
    prof = _Profile(jerk, a, p, v)

    def python():
        with pytest.MonkeyPatch.context() as m:
            m.setattr(segments, "zero_jerk_turns", lambda *args: None)
            try:
                return repr(segments._zero_jerk_turns(prof, v))
            except (IndexError, ZeroDivisionError) as exc:
                return type(exc).__name__

    try:
        got = repr(segments._zero_jerk_turns(prof, v))
    except (IndexError, ZeroDivisionError) as exc:
        got = type(exc).__name__
    assert got == python()  # (repr: NaN and the sign of zeros too)
