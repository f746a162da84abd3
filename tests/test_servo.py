"""Servo export: step units (Materick and Shapiro 1997), pulse widths, SSC-32 moves (Clothier and Shang 2010)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from planner import InvalidArgumentError
from planner.export.calibration import (
    SSC32_US_PER_RAD,
    ServoCalibration,
    angle_to_steps,
    default_calibrations,
    steps_to_angle,
)
from planner.export.formats import SERVO_FORMATS, ServoFormat, servo_format
from planner.export.formats.ssc32 import ssc32_group_moves
from planner.export.tables import pulse_table, steps_table
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory

from conftest import get_robot


@pytest.fixture(scope="module")
def dh3_trajectory():
    robot = get_robot("dh3")
    q = np.radians([[0, 0, 30], [45, 60, 90], [90, 30, 45]])
    return robot, plan_trajectory(q, JointLimits.from_robot(robot))


def test_step_functions_kept():
    assert angle_to_steps(math.radians(92.5), math.radians(92.5), 1000) == 1000
    assert angle_to_steps(0.0, 1.0, 100) == 0
    np.testing.assert_array_equal(angle_to_steps(np.array([-0.5, 0.25]), 1.0, 100), [-50, 25])
    assert steps_to_angle(50, 1.0, 100) == pytest.approx(0.5)


def test_ssc32_convention_is_1000us_per_90deg():
    cal = ServoCalibration(0)
    assert cal.pulse(math.pi / 2) == pytest.approx(2500.0)
    assert cal.pulse(-math.pi / 2) == pytest.approx(500.0)
    assert SSC32_US_PER_RAD == pytest.approx(1000.0 / (math.pi / 2))


def test_calibration_round_trip_and_direction():
    cal = ServoCalibration(
        3, pulse_at_zero=1400.0, us_per_rad=600.0, direction=-1, min_pulse=600, max_pulse=2400, joint="elbow"
    )
    angles = np.linspace(-1.0, 1.0, 11)
    pulses = cal.pulse(angles)
    np.testing.assert_allclose(pulses, 1400.0 - 600.0 * angles)
    np.testing.assert_allclose(cal.angle(pulses), angles)


def test_pulse_out_of_range_is_an_error_not_clipped():
    cal = ServoCalibration(2, joint="elbow")
    with pytest.raises(
        InvalidArgumentError,
        match=r"joint 'elbow' \(channel 2\) angle 2 rad needs pulse 2773.2 us, outside \[500, 2500\] us",
    ):
        cal.pulse(2.0)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"channel": -1}, "channel must be a non-negative integer"),
        ({"channel": 0, "us_per_rad": 0.0}, "us_per_rad must be positive"),
        ({"channel": 0, "direction": 2}, "direction must be"),
        ({"channel": 0, "min_pulse": 2500, "max_pulse": 500}, "need 0 < min_pulse < max_pulse"),
        ({"channel": 0, "pulse_at_zero": float("nan")}, "pulse_at_zero must be a finite number"),
    ],
)
def test_bad_calibrations(kwargs, message):
    with pytest.raises(InvalidArgumentError, match=message):
        ServoCalibration(**kwargs)


def test_default_calibrations_fit_each_joint_range():
    for name in ("dh3", "al5c", "three_joint", "shelley"):
        robot = get_robot(name)
        cals = default_calibrations(robot)
        assert [c.channel for c in cals] == list(range(robot.dof))
        for cal, lo, hi in zip(cals, robot.lower, robot.upper):
            assert 500.0 - 1e-9 <= cal.pulse(lo) <= 2500.0 + 1e-9
            assert 500.0 - 1e-9 <= cal.pulse(hi) <= 2500.0 + 1e-9
            assert cal.us_per_rad <= SSC32_US_PER_RAD + 1e-9
    # dh3 has +-135 deg joints: 1000 us per 135 deg.
    assert default_calibrations(get_robot("dh3"))[0].us_per_rad == pytest.approx(1000.0 / math.radians(135))


def test_pulse_table_matches_the_trajectory(dh3_trajectory):
    robot, traj = dh3_trajectory
    cals = default_calibrations(robot)
    t, pulses = pulse_table(traj, cals, rate=50.0)
    assert pulses.dtype.kind == "i" and pulses.shape == (len(t), 3)
    assert t[-1] == traj.duration
    q = traj.sample(t).q
    angles = np.column_stack([c.angle(pulses[:, k]) for k, c in enumerate(cals)])
    # Whole microseconds: within half a microsecond of the exact pulse.
    assert np.max(np.abs(angles - q) * cals[0].us_per_rad) <= 0.5 + 1e-9


def test_ssc32_group_moves(dh3_trajectory):
    robot, traj = dh3_trajectory
    cals = default_calibrations(robot)
    commands = ssc32_group_moves(traj, cals, period_ms=20)
    pattern = re.compile(r"^#0P(\d+)#1P(\d+)#2P(\d+)T20$")
    assert all(pattern.match(c) for c in commands)
    assert len(commands) == math.ceil(traj.duration * 1000 / 20) + 1
    first = [int(x) for x in pattern.match(commands[0]).groups()]
    last = [int(x) for x in pattern.match(commands[-1]).groups()]
    assert first == [int(round(c.pulse(a))) for c, a in zip(cals, traj.waypoints[0])]
    assert last == [int(round(c.pulse(a))) for c, a in zip(cals, traj.waypoints[-1])]
    with pytest.raises(InvalidArgumentError, match="period_ms must be an integer"):
        ssc32_group_moves(traj, cals, period_ms=0)
    far = [ServoCalibration.fit_range(40 + k, -2.4, 2.4, joint=n) for k, n in enumerate(robot.joint_names)]
    with pytest.raises(InvalidArgumentError, match=r"joint 'base_yaw' uses channel 40; an SSC-32 has channels 0-31"):
        ssc32_group_moves(traj, far)
    with pytest.raises(InvalidArgumentError, match="servo channels must differ"):
        ssc32_group_moves(traj, [cals[0], cals[0], cals[2]])
    with pytest.raises(InvalidArgumentError, match=r"need one ServoCalibration per joint \(3\), got 2"):
        pulse_table(traj, cals[:2])


def test_steps_table(dh3_trajectory):
    _, traj = dh3_trajectory
    t, steps = steps_table(traj, math.radians(135), 2048, rate=25.0)
    np.testing.assert_array_equal(steps, angle_to_steps(traj.sample(t).q, math.radians(135), 2048))
    with pytest.raises(InvalidArgumentError, match="beyond the servo's travel"):
        steps_table(traj, math.radians(60), 2048)


def test_servo_format_registry(dh3_trajectory):
    robot, traj = dh3_trajectory
    cals = default_calibrations(robot)
    assert list(SERVO_FORMATS) == ["pulses", "ssc32", "pca9685", "feetech", "steps"]
    for name, fmt in SERVO_FORMATS.items():
        assert isinstance(fmt, ServoFormat) and fmt.name == name and servo_format(name) is fmt
    text = servo_format("ssc32").render(traj, cals, 20)
    assert text == "".join(c + "\r" for c in ssc32_group_moves(traj, cals, period_ms=20))
    rows = servo_format("pulses").render(traj, cals, 40).splitlines()
    t, pulses = pulse_table(traj, cals, rate=25.0)
    assert rows[0] == "t,ch0_base_yaw,ch1_shoulder,ch2_elbow"
    assert rows[1:] == [f"{ti:.6f}," + ",".join(str(x) for x in row) for ti, row in zip(t, pulses)]
    valid = "pulses, ssc32, pca9685, feetech, steps"
    with pytest.raises(InvalidArgumentError, match=rf"unknown servo format 'dmx'; valid formats: {valid}"):
        servo_format("dmx")
