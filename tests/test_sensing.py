"""Clothier and Shang's (2010) object finding: a range-bearing reading becomes a base-frame target."""

from __future__ import annotations

import math

import numpy as np
import pytest

import planner


def test_reading_in_the_sensor_frame_follows_equation_5():
    # Sensor at the base origin, unrotated: the point is (D cos phi, D sin phi, 0).
    p = planner.range_bearing_to_base(0.30, math.radians(30), (0, 0, 0))
    np.testing.assert_allclose(p, [0.30 * math.cos(math.radians(30)), 0.15, 0.0], atol=1e-15)


def test_sensor_offsets_follow_equation_6():
    # A sensor mounted x_diff ahead of and y_diff beside the base: base = sensor reading + offsets.
    x_diff, y_diff = 0.12, -0.08
    d, phi = 0.25, math.radians(-20)
    p = planner.range_bearing_to_base(d, phi, (x_diff, y_diff, 0.02))
    np.testing.assert_allclose(p, [x_diff + d * math.cos(phi), y_diff + d * math.sin(phi), 0.02], atol=1e-15)


def test_turned_sensor_and_full_pose_agree():
    yaw = math.radians(90)
    pose = np.eye(4)
    pose[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    pose[:3, 3] = [0.1, 0.0, 0.05]
    a = planner.range_bearing_to_base([0.2, 0.3], [0.0, 0.1], (0.1, 0.0, 0.05, yaw))
    b = planner.range_bearing_to_base([0.2, 0.3], [0.0, 0.1], pose)
    np.testing.assert_allclose(a, b, atol=1e-15)
    np.testing.assert_allclose(a[0], [0.1, 0.2, 0.05], atol=1e-15)


def test_bad_readings():
    with pytest.raises(planner.InvalidArgumentError, match="distance and bearing must be finite"):
        planner.range_bearing_to_base(math.nan, 0.0, (0, 0, 0))
    with pytest.raises(planner.InvalidArgumentError, match="distance must be >= 0"):
        planner.range_bearing_to_base(-0.1, 0.0, (0, 0, 0))
    with pytest.raises(planner.InvalidArgumentError, match=r"sensor_pose must be a 4x4 transform, \(x, y, z\)"):
        planner.range_bearing_to_base(0.1, 0.0, (0, 0))
    with pytest.raises(planner.InvalidArgumentError, match="not a rigid transform"):
        planner.range_bearing_to_base(0.1, 0.0, 2 * np.eye(4))
    skewed = np.eye(4)
    skewed[3] = [0.0, 0.0, 0.1, 1.0]
    with pytest.raises(planner.InvalidArgumentError, match=r"not a rigid transform: last row \[0.0, 0.0, 0.1, 1.0\]"):
        planner.range_bearing_to_base(0.1, 0.0, skewed)
