"""The time-scaling family of smoothed lines: speed shapes, their exact screening, and the choice."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from line_cases import random_position_line

from planner.motion.limits import JointLimits
from planner.motion.line_smoothing import (
    KNOT_SPACING,
    _end_slopes,
    _natural_spline,
    _one_sided_bend,
    _scaled_spline,
    _screen,
    _smooth_piece,
    _Speed,
    _spline_nodes,
    _targets,
    _template,
    path_corners,
)

from conftest import get_robot

SHAPES = [
    _Speed(0.3, 0.3),
    _Speed(0.15, 0.45, tilt=0.3, bump=-0.25),
    _Speed(0.6, 0.6, tilt=-0.2, bump=0.5, smoother=True),
    _Speed(0.0, 0.25, bump=0.3),
    _Speed(0.2, 0.0, smoother=True),
]


@pytest.mark.parametrize("speed", SHAPES)
def test_the_speed_integral_is_exact_and_time_at_inverts_it(speed):
    u = np.linspace(0.0, 1.0, 200_001)
    rate = speed.rate(u)
    # An independent reference: the trapezoid rule on a fine grid (error below 1e-10 here).
    reference = np.concatenate([[0.0], np.cumsum((rate[1:] + rate[:-1]) / 2.0 * np.diff(u))])
    at = np.linspace(0.0, 1.0, 37)
    np.testing.assert_allclose(speed.integral(at), np.interp(at, u, reference), rtol=0, atol=1e-10)
    whole = float(speed.integral(np.ones(1))[0])
    np.testing.assert_allclose(speed.integral(speed.time_at(at)) / whole, at, atol=1e-12)
    assert np.all(rate[1:-1] > 0)


@pytest.mark.parametrize("speed", SHAPES)
def test_the_speed_is_c1_and_at_rest_only_at_ramped_ends(speed):
    # C1 across every break (the path's position is C2 in time): the speed and its slope on
    # either side of each break agree.
    h = 1e-7
    for b in speed.breaks()[1:-1]:
        left, right = speed.rate(np.array([b - h, b])), speed.rate(np.array([b, b + h]))
        assert abs(left[1] - right[0]) <= 1e-12
        assert abs((left[1] - left[0]) / h - (right[1] - right[0]) / h) <= 1e-4
    ends = speed.rate(np.array([0.0, 1.0]))
    assert (ends[0] == 0.0) == (speed.up > 0) and (ends[1] == 0.0) == (speed.down > 0)


def line_piece(name: str, seed: int):
    robot = get_robot(name)
    lim = JointLimits.from_robot(robot)
    rng = np.random.default_rng(seed)
    while True:
        _, path = random_position_line(robot, rng)
        q = np.asarray(path.q)
        if not path_corners(q, lim):
            return q, lim


@pytest.mark.parametrize(("name", "seed"), [("al5c", 1), ("al5c", 2), ("three_joint", 3)])
def test_the_screening_is_the_motion_it_stands_for(name, seed):
    # The screening's duration and jerk sign changes (per interval of the piecewise cubic) are
    # the scaled trajectory's, sampled at 1 kHz as issue 11 counts them.
    q, lim = line_piece(name, seed)
    template = _template(lim, q)
    sigma = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0) / lim.velocity, axis=1))])
    nodes = _spline_nodes(sigma)
    bends = tuple(_one_sided_bend(sigma[nodes], q[nodes], end) for end in (False, True))
    path = (sigma[nodes], q[nodes], _natural_spline(sigma[nodes], q[nodes], (None, None), bends))
    slopes, bounds = _end_slopes(*path), (lim.lower, lim.upper)
    for speed in SHAPES[:3]:
        duration, scale, counts = _screen(q, path, slopes, speed, KNOT_SPACING, lim, bounds, (True, True), None)
        fit = _scaled_spline(q, path, slopes, speed, KNOT_SPACING, scale, template, 1.0, bounds, (True, True))
        assert fit is not None
        traj = fit[5]
        assert traj.duration == pytest.approx(duration, rel=1e-6)
        peaks = traj.peak_ratios(None)
        assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) == pytest.approx(1.0, abs=1e-6)
        np.testing.assert_array_equal(traj.jerk_sign_changes(), counts)


def test_targets_count_each_turn_back_of_a_joint_path():
    x = np.linspace(0.0, 1.0, 101)
    q = np.column_stack([x, np.sin(2 * np.pi * x), np.zeros_like(x), 1e-4 * np.sin(9 * x), 0.5 + 0 * x])
    q[-1, 2] = 1e-9  # a joint that hardly moves still has its S-curve's two
    np.testing.assert_array_equal(_targets(q), [2, 4, 2, 2, 0])


@pytest.mark.parametrize(("name", "seed"), [("al5c", 4), ("three_joint", 5)])
def test_the_chosen_motion_is_no_rougher_than_symmetric_ramps_as_fast(name, seed):
    # The symmetric smoothstep ramps are in the family: the motion chosen changes jerk sign
    # beyond its joints' needs no more often than the best of them that is no slower.
    q, lim = line_piece(name, seed)
    template = _template(lim, q)
    piece = _smooth_piece(q, template, 1.0)
    assert piece is not None
    at, _, knots, p, v, a, j = piece
    chosen = replace(template, knots=knots, p=p, v=v, a=a, j=j, duration=float(at[-1]))
    target = _targets(q)
    excess = int(np.maximum(chosen.jerk_sign_changes() - target, 0).sum())
    sigma = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0) / lim.velocity, axis=1))])
    nodes = _spline_nodes(sigma)
    bends = tuple(_one_sided_bend(sigma[nodes], q[nodes], end) for end in (False, True))
    path = (sigma[nodes], q[nodes], _natural_spline(sigma[nodes], q[nodes], (None, None), bends))
    for f in (0.1, 0.2, 0.3, 0.45, 0.65, 1.0):
        r = f / (1.0 + f)
        out = _screen(
            q, path, _end_slopes(*path), _Speed(r, r), KNOT_SPACING, lim, (lim.lower, lim.upper), (True, True), None
        )
        if out[0] <= chosen.duration:
            assert excess <= int(np.maximum(out[2] - target, 0).sum())
