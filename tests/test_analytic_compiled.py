"""The compiled batch closed form (planner.ik.analytic.yaw_planar.compiled) against the NumPy path.

On dh3, three_joint and al5c (exact yaw + 2 or 3 pitch arms) and on random exact arms of the
family: the same branches, masks, statuses and best branch as
:func:`~planner.ik.analytic.yaw_planar.batch.solve_arrays_within`, joint values and position
errors equal to round-off, for targets by FK of random configurations (some on the joint range
ends), targets moved off the reachable set and random points, with and without q_current (the
generating configuration or another), position targets with a free end angle included (the
targets the compiled function hands over to NumPy included); compiled to C and on CasADi's
virtual machine. Solved answers reproduce the target by Pinocchio FK.
"""

from __future__ import annotations

import functools

import casadi as ca
import numpy as np
import pytest
from dh_arms import property_settings
from hypothesis import assume, given
from hypothesis import strategies as st
from test_analytic_fast_paths import yaw_planar_arms

from planner import Target, load_robot
from planner.core.rotations import rotation_error
from planner.exceptions import InvalidArgumentError
from planner.geometry.chain import LIMIT_SNAP, wrap_array
from planner.geometry.target import approach_pitch
from planner.ik.analytic import STATUS_NAMES, closed_form_solver
from planner.ik.analytic.yaw_planar.batch import COMPILED_MIN, solve_arrays_within, solve_compiled_within
from planner.ik.analytic.yaw_planar.compiled import (
    SMALL_BLOCK,
    CompiledKernels,
    compiled_supported,
    cos_nonnegative,
    solve_compiled,
    wrap_within_sx,
)

# (robot, target kind, q_current); compiling takes 1-4 s each: the rest in the slow suite.
FAST_KINDS = [
    ("dh3", "position", False),
    ("dh3", "pitch", False),
    ("dh3", "pose", False),
    ("three_joint", "pitch", False),
    ("three_joint", "position", True),
    ("al5c", "position", False),
    ("al5c", "pose", True),
]
SLOW_KINDS = [
    ("dh3", "position", True),
    ("three_joint", "position", False),
    ("three_joint", "pose", False),
    ("three_joint", "pose", True),
    ("al5c", "pitch", False),
    ("al5c", "pitch", True),
    ("al5c", "position", True),
    ("al5c", "pose", False),
]
KINDS = FAST_KINDS + [pytest.param(*k, marks=pytest.mark.slow) for k in SLOW_KINDS]
TOL_POS = 1e-9


@functools.cache
def solver(name):
    return closed_form_solver(load_robot(name))


def targets(robot, rng, n):
    """Positions, pitches, rotations and q_current: FK of random configurations (a quarter with
    joints on their range ends), a quarter of them moved by up to 20 % of the reach, and random
    points (with random pitches and rotations); q_current the generating configuration for half
    the targets, another for the rest."""
    lo, hi = np.asarray(robot.lower), np.asarray(robot.upper)
    q = rng.uniform(lo, hi, (n, len(lo)))
    ends = rng.random((n, len(lo))) < 0.25
    q = np.where(ends, np.where(rng.random((n, len(lo))) < 0.5, lo, hi), q)
    pose = robot.fk(q)
    pos, rot = pose[:, :3, 3], pose[:, :3, :3].copy()
    pit = np.asarray(approach_pitch(robot, q), dtype=float)
    reach = float(np.max(np.linalg.norm(pos, axis=1)))
    moved = rng.random(n) < 0.25
    pos[moved] += rng.normal(0.0, 0.2 * reach, (int(moved.sum()), 3))
    loose = rng.random(n) < 0.1
    pos[loose] = rng.uniform(-1.5 * reach, 1.5 * reach, (int(loose.sum()), 3))
    pit[loose] = rng.uniform(-np.pi, np.pi, int(loose.sum()))
    rot[loose] = np.linalg.qr(rng.normal(size=(int(loose.sum()), 3, 3)))[0] * rng.choice([-1.0, 1.0], (1, 1, 1))
    rot[loose] *= np.linalg.det(rot[loose])[:, None, None]  # proper rotations
    # Exactly on the x axis, where the back branch's yaw is pi, on a range end.
    pos[:4, 1] = 0.0
    other = rng.random(n) < 0.5
    qc = np.where(other[:, None], rng.uniform(lo, hi, (n, len(lo))), q)
    return pos, pit, rot, qc


def inputs(s, rng, n, kind, current):
    """(positions, pitches or None, rotations or None, q_current or None) of `kind` targets."""
    pos, pit, rot, qc = targets(s.robot, rng, n)
    return pos, pit if kind == "pitch" else None, rot if kind == "pose" else None, qc if current else None


def assert_same(got, want):
    for name in ("valid", "within", "singular", "status", "best"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
    np.testing.assert_array_equal(np.isnan(got.q), np.isnan(want.q))
    # An angle that lands on +-pi (a target on an axis) is one angle written two ways: the two
    # paths may round it to either side (the sign of a zero), so +pi and -pi count as equal there.
    q_got = np.where((np.abs(np.abs(got.q) - np.pi) < 1e-9) & (np.abs(np.abs(want.q) - np.pi) < 1e-9), want.q, got.q)
    np.testing.assert_allclose(q_got, want.q, rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(got.perr, want.perr, rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("compiled", [True, False], ids=["C", "vm"])
@pytest.mark.parametrize(("name", "kind", "current"), KINDS)
def test_compiled_equals_numpy(name, kind, current, compiled):
    s = solver(name)
    arm = s.arm
    rng = np.random.default_rng(12)
    n = 4096 + 3 * SMALL_BLOCK + 17  # a full block, small blocks and a padded rest
    pos, pit, rot, qc = inputs(s, rng, n, kind, current)
    assert compiled_supported(arm, pit, rot, qc)
    kernels = CompiledKernels(arm)
    _, handed = solve_compiled(kernels, pos, pit, rot, qc, compiled=compiled)
    # With q_current, position and pitch targets on the yaw axis are NumPy's (their yaw is q_current's).
    _, _, d = arm.tip_fixed
    rho2 = (pos[:, 0] - arm.bx) ** 2 + (pos[:, 1] - arm.by) ** 2
    on_axis = np.flatnonzero((rho2 <= arm.len_tol**2) & (abs(d) <= arm.len_tol)) if current and rot is None else []
    if arm.n_pitch == 3 and kind == "position":
        assert 0 < handed.size < n  # the search within the limits: NumPy's
        assert set(on_axis) <= set(handed.tolist())
    else:
        assert sorted(handed.tolist()) == sorted(on_axis)
    got = solve_compiled_within(kernels, pos, pit, rot, qc, compiled=compiled)
    want = solve_arrays_within(arm, pos, pit, rot, qc)
    assert_same(got, want)
    statuses = set(np.unique(got.status).tolist())
    assert 0 in statuses and len(statuses) >= 2  # solved and failing targets both met
    solved = got.best >= 0
    q = got.q[np.flatnonzero(solved), got.best[solved]]
    pose = s.robot.fk(q)
    assert np.max(np.linalg.norm(pose[:, :3, 3] - pos[solved], axis=1)) < TOL_POS
    if pit is not None:
        err = np.abs(np.asarray(approach_pitch(s.robot, q)) - pit[solved])
        assert np.max(np.minimum(err, 2 * np.pi - err)) < 1e-9
    if rot is not None:
        assert np.max(rotation_error(pose[:, :3, :3], rot[solved])) < 1e-9
    assert np.all(s.robot.within_limits(q))


@pytest.mark.parametrize(("name", "kind", "current"), KINDS)
def test_solve_batch_uses_the_same_answers(name, kind, current):
    """The public solve_batch (the compiled path here) equals the NumPy arrays."""
    s = solver(name)
    rng = np.random.default_rng(3)
    pos, pit, rot, qc = inputs(s, rng, 1500, kind, current)
    batch = s.solve_batch(pos, pitch=pit, rotations=rot, q_current=qc)
    want = solve_arrays_within(s.arm, pos, pit, rot, qc)
    np.testing.assert_array_equal(batch.status, want.status)
    np.testing.assert_array_equal(batch.best, want.best)
    np.testing.assert_array_equal(batch.valid, want.valid)
    np.testing.assert_array_equal(batch.within_limits, want.within)
    np.testing.assert_allclose(batch.q, want.q, rtol=0.0, atol=1e-9)


@pytest.mark.parametrize(("name", "kind", "current"), KINDS)
def test_compiled_batch_agrees_with_single_solves(name, kind, current):
    """solve_batch over enough targets for the compiled path gives each target's single-call answer.

    Joint values compared modulo 2 pi: at a yaw range end of +-pi (three_joint, targets from
    configurations on their range ends) the single pose call returns -pi where the batch
    paths (NumPy and compiled alike) return pi.
    """
    s = solver(name)
    rng = np.random.default_rng(8)
    n = 1100
    pos, pit, rot, qc = inputs(s, rng, n, kind, current)
    assert n >= COMPILED_MIN and compiled_supported(s.arm, pit, rot, qc)
    batch = s.solve_batch(pos, pitch=pit, rotations=rot, q_current=qc)
    for i in rng.choice(n, 60, replace=False):
        target = Target(pos[i], pitch=None if pit is None else float(pit[i]), rotation=None if rot is None else rot[i])
        single = s.solve(target, q_current=None if qc is None else qc[i])
        assert STATUS_NAMES[batch.status[i]] == single.status
        assert int(batch.valid[i].sum()) == len(single.solutions)
        for sol in single.solutions:
            k = s.branches.index(sol.branch)
            assert np.max(turns(batch.q[i, k] - sol.q)) < 1e-9
            assert batch.within_limits[i, k] == sol.within_limits
            assert batch.singular[i, k] == sol.singular
        if single.best is None:
            assert batch.best[i] == -1
        else:
            assert np.max(turns(batch.best_q[i] - single.best.q)) < 1e-9


def turns(d):
    """|d| modulo 2 pi [rad]."""
    return np.abs((d + np.pi) % (2 * np.pi) - np.pi)


def test_supported_kinds():
    three = solver("three_joint").arm
    assert compiled_supported(three, None, None, None)  # free end angle (searched by NumPy)
    assert compiled_supported(three, np.zeros(1), None, np.zeros((1, 4)))
    assert compiled_supported(three, None, np.eye(3)[None], None)


@property_settings(25)
@given(
    robot=yaw_planar_arms(),
    seed=st.integers(0, 2**32 - 1),
    kind=st.sampled_from(["position", "pitch", "pose"]),
    current=st.booleans(),
)
def test_random_exact_arms_vm(robot, seed, kind, current):
    s = closed_form_solver(robot)
    rng = np.random.default_rng(seed)
    pos, pit, rot, qc = inputs(s, rng, 40, kind, current)
    assume(s.arm.exact and (pit is None or s.arm.pitch_supported) and compiled_supported(s.arm, pit, rot, qc))
    got = solve_compiled_within(CompiledKernels(s.arm), pos, pit, rot, qc, compiled=False)
    assert_same(got, solve_arrays_within(s.arm, pos, pit, rot, qc))


LIMITS = [
    (-2.356, 2.356),  # both inside (-pi, pi)
    (-0.17, 3.316),  # the upper beyond pi
    (-np.pi, np.pi),
    (0.0873, 2.443),
    (-2.88, -0.436),
    (-4.0, 1.0),  # the lower beyond -pi
    (-1e9, 1e9),
    (-1.0, 0.0),  # a limit 0: the snap x - (x - 0)
    (-1.5e-10, 5e-11),  # limits within 2 LIMIT_SNAP of 0: the snaps as selections
]


@pytest.mark.parametrize(("lower", "upper"), LIMITS)
@pytest.mark.parametrize("centred", [True, False], ids=["ref0", "ref"])
def test_wrap_sx_equals_wrap_array(lower, upper, centred):
    """The compiled wrapping into a joint range (its steps by 2 pi as comparisons with
    thresholds, the snaps onto the limits as differences) equals wrap_array on values around
    the limits, their 2 pi shifts, the half turns and the doubles where the steps switch on,
    signs of zeros included; its within-limits flag is the test on wrap_array's value."""
    rng = np.random.default_rng(5)
    edges = np.array([lower, upper, np.pi, -np.pi, 0.0])
    offsets = np.array([0.0, 0.5, 1.0, 1.5, 2.0, -0.5, -1.0, -1.5, -2.0]) * LIMIT_SNAP
    near = (edges[:, None, None] + offsets[None, :, None] + 2 * np.pi * np.arange(-2, 3)[None, None, :]).ravel()
    # Where wrap_array's steps by 2 pi switch on (x - 2 pi nearer the range than x, or within
    # the snap): 64 doubles either side of each (the compiled form compares with thresholds).
    mid = 0.5 * (lower + upper)
    switches = [min(lower + 2 * np.pi - LIMIT_SNAP, mid + np.pi), max(upper + LIMIT_SNAP - 2 * np.pi, mid - np.pi)]
    ulps = []
    for v in switches:
        if np.isfinite(v):
            below, above = np.full(64, v), np.full(64, v)
            for k in range(1, 64):
                below[k], above[k] = np.nextafter(below[k - 1], -np.inf), np.nextafter(above[k - 1], np.inf)
            ulps += [below, above]
    x = np.concatenate([near, *ulps, rng.uniform(-4 * np.pi, 4 * np.pi, 4000), [np.nan]])
    ref = rng.uniform(-2 * np.pi, 2 * np.pi, x.size) if not centred else np.zeros(x.size)
    if not centred:  # the doubles at the switches as they are (no turn)
        at = slice(near.size, near.size + sum(u.size for u in ulps))
        ref[at] = x[at]
    sx, sref = ca.SX.sym("x"), ca.SX.sym("ref")
    wrapped, within = wrap_within_sx(sx, lower, upper, sref if not centred else 0.0)
    f = ca.Function("wrap", [sx, sref], [wrapped, within]).map(x.size)
    got, got_within = (np.asarray(v).ravel() for v in f(x, ref))
    want = wrap_array(x.copy(), lower, upper, ref)
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(np.signbit(got), np.signbit(want))
    np.testing.assert_array_equal(got_within != 0.0, (want >= lower) & (want <= upper))
    if max(abs(lower), abs(upper)) < 10.0:  # (at 1e9, x +- LIMIT_SNAP rounds to x)
        assert np.any(np.isin(want, [lower, upper]) & ~np.isin(x, [lower, upper]))  # snaps met


def test_batch_rotation_check_finds_the_bad_row():
    """solve_batch's rotation check (entry by entry, in slices of 16384) names the first
    improper or non-orthonormal rotation, in any slice, and accepts round-off."""
    s = solver("al5c")
    rng = np.random.default_rng(4)
    n = 16384 + 40
    rot = np.linalg.qr(rng.normal(size=(n, 3, 3)))[0]
    rot *= np.linalg.det(rot)[:, None, None]
    pos = np.zeros((n, 3))
    s.solve_batch(pos, rotations=rot * (1.0 + 1e-9))
    for row, change in ((16390, -1.0), (3, 1.0 + 2e-6), (n - 1, np.diag([1.0, 1.0, -1.0]))):
        bad = rot.copy()
        bad[row] = bad[row] @ change if np.ndim(change) else bad[row] * change
        with pytest.raises(InvalidArgumentError, match=rf"rotations\[{row}\] is not a proper orthonormal"):
            s.solve_batch(pos, rotations=bad)


@pytest.mark.parametrize("compiled", [True, False], ids=["C", "vm"])
@pytest.mark.parametrize(("name", "kind", "current"), KINDS)
def test_compiled_on_the_axes(name, kind, current, compiled):
    """Targets exactly on the x and y axes, q_current's yaw 0, +-pi / 2 or pi (on its range),
    pitches of 0 and +-pi / 2, rotations by quarter turns about z: the sign tests at right
    angles (e.g. which side faces q_current) and the wrapping at half turns from q_current
    decide as on the NumPy path. The best branch may differ only between branches equally
    near q_current (to round-off)."""
    s = solver(name)
    arm = s.arm
    rng = np.random.default_rng(7)
    n = 600
    pos = np.zeros((n, 3))
    t = rng.uniform(0.05, 0.9, n) * arm.scale * rng.choice([-1.0, 1.0], n)
    on_y = rng.random(n) < 0.5
    pos[on_y, 1], pos[~on_y, 0] = t[on_y], t[~on_y]
    pos[:, 2] = rng.uniform(-0.3, 0.6, n) * arm.scale
    yaw = rng.choice([0.0, np.pi / 2, -np.pi / 2, np.pi], n)
    qc = np.clip(np.zeros((n, arm.dof)) + (np.arange(arm.dof) == 0) * yaw[:, None], arm.lower, arm.upper)
    pit = rng.choice([0.0, np.pi / 2, -np.pi / 2, 0.3], n) if kind == "pitch" else None
    rot = None
    if kind == "pose":
        c, sn = np.round(np.cos(yaw)), np.round(np.sin(yaw))
        rot = np.zeros((n, 3, 3))
        rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = c, -sn, sn, c, 1.0
    qc = qc if current else None
    got = solve_compiled_within(CompiledKernels(arm), pos, pit, rot, qc, compiled=compiled)
    want = solve_arrays_within(arm, pos, pit, rot, qc)
    for field in ("valid", "within", "singular", "status"):
        np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=field)
    np.testing.assert_array_equal(np.isnan(got.q), np.isnan(want.q))
    np.testing.assert_allclose(got.q, want.q, rtol=0.0, atol=1e-9)
    differ = np.flatnonzero(got.best != want.best)
    assert np.all((got.best[differ] >= 0) & (want.best[differ] >= 0))
    ref = np.zeros((n, arm.dof)) if qc is None else qc
    for i in differ:
        near = [np.sum((got.q[i, b] - ref[i]) ** 2) for b in (got.best[i], want.best[i])]
        assert qc is not None and abs(near[0] - near[1]) < 1e-12


def test_cos_nonnegative_equals_numpy_next_to_the_zeros():
    """The sign of the cosine without calling cos equals NumPy's on the 80 doubles around each
    zero (m + 1/2) pi, m = -12 ... 11, around the multiples of pi, and on random values."""
    values = []
    for m in range(-12, 12):
        v = (m + 0.5) * np.pi
        for _ in range(40):
            v = np.nextafter(v, -np.inf)
        for _ in range(80):
            values.append(v)
            v = np.nextafter(v, np.inf)
        values += [m * np.pi, np.nextafter(m * np.pi, np.inf), np.nextafter(m * np.pi, -np.inf)]
    x = np.concatenate([values, np.random.default_rng(2).uniform(-40.0, 40.0, 20000), [0.0, -0.0]])
    sx = ca.SX.sym("x")
    f = ca.Function("f", [sx], [cos_nonnegative(sx)]).map(x.size)
    np.testing.assert_array_equal(np.asarray(f(x)).ravel() != 0.0, np.cos(x) >= 0.0)
