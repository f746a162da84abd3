"""Export for the servo buses in use: Feetech STS/SCS packets, PCA9685 ticks, stepper steps, calibration files."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from planner import InvalidArgumentError
from planner.app.cli import main
from planner.export.calibration import angle_to_steps, default_calibrations
from planner.export.calibration_file import controller_setup, load_calibration, shipped_calibration
from planner.export.formats import servo_format
from planner.export.formats.base import command_times
from planner.export.formats.feetech import (
    GOAL_POSITION,
    Instruction,
    decode_position,
    encode_position,
    packet,
    parse_status,
    read_packet,
    sync_write_packet,
    write_packet,
)
from planner.export.formats.pca9685 import Pca9685, pca9685_off_ticks
from planner.export.ticks import TickCalibration
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory

from conftest import get_robot


def hexbytes(text: str) -> bytes:
    return bytes.fromhex(text)


@pytest.fixture(scope="module")
def dh3_trajectory():
    robot = get_robot("dh3")
    q = np.radians([[0, 0, 30], [45, 60, 90], [90, 30, 45]])
    return robot, plan_trajectory(q, JointLimits.from_robot(robot))


# Worked examples of Feetech's "Communication Protocol User Manual" (FT-SCS protocol), sections
# 1.3.1 PING, 1.3.2 READ DATA, 1.3.3 WRITE DATA (example 2) and 1.3.6 SYNC WRITE, byte for byte.
def test_feetech_ping_read_write_match_the_manual():
    assert packet(1, Instruction.PING) == hexbytes("FF FF 01 02 01 FB")
    assert read_packet(1, 0x38, 2) == hexbytes("FF FF 01 04 02 38 02 BE")
    # ID 1 to position 2048, time 0, speed 1000, from address 0x2A (STS: low byte first)
    data = encode_position(2048) + (0).to_bytes(2, "little") + (1000).to_bytes(2, "little")
    assert write_packet(1, GOAL_POSITION, data) == hexbytes("FF FF 01 09 03 2A 00 08 00 00 E8 03 D5")


def test_feetech_sync_write_matches_the_manual():
    data = encode_position(2048) + (0).to_bytes(2, "little") + (1000).to_bytes(2, "little")
    expected = hexbytes(
        "FF FF FE 20 83 2A 06 01 00 08 00 00 E8 03 02 00 08 00 00 E8 03 03 00 08 00 00 E8 03 04 00 08 00 00 E8 03 58"
    )
    assert sync_write_packet(0x2A, {i: data for i in (1, 2, 3, 4)}) == expected


def test_feetech_status_packets_from_the_manual():
    # 1.3.2: the answer to the read above, position 0x0518 = 1304
    status = parse_status(hexbytes("FF FF 01 04 00 18 05 DD"))
    assert (status.id, status.error, decode_position(status.params)) == (1, 0, 1304)
    # 1.3.7: a sync-read answer of 8 bytes from 0x38 (position 2048 first)
    status = parse_status(hexbytes("FF FF 01 0A 00 00 08 00 00 00 00 79 1E 55"))
    assert decode_position(status.params[:2]) == 2048
    assert parse_status(hexbytes("FF FF 01 02 00 FC")).params == b""
    with pytest.raises(InvalidArgumentError, match="checksum is 0xdc, expected 0xdd"):
        parse_status(hexbytes("FF FF 01 04 00 18 05 DC"))
    with pytest.raises(InvalidArgumentError, match="length byte says 8 bytes, got 7"):
        parse_status(hexbytes("FF FF 01 04 00 18 DD"))


def test_feetech_position_byte_order_and_sign():
    assert encode_position(2048, "sts") == b"\x00\x08"
    assert encode_position(2048, "scs") == b"\x08\x00"  # SCS: high byte first
    assert encode_position(-100, "sts") == (100 | 0x8000).to_bytes(2, "little")  # bit 15 is the sign
    for ticks in (-32767, -1, 0, 1, 4095, 32767):
        assert decode_position(encode_position(ticks)) == ticks
    assert decode_position(encode_position(1023, "scs"), "scs") == 1023
    with pytest.raises(InvalidArgumentError, match=r"an SCS position must lie in \[0, 65535\] ticks, got -1"):
        encode_position(-1, "scs")
    with pytest.raises(InvalidArgumentError, match="unknown Feetech series 'xl'; valid series: sts, scs"):
        encode_position(0, "xl")
    with pytest.raises(InvalidArgumentError, match="same data length"):
        sync_write_packet(0x2A, {1: b"\x00", 2: b"\x00\x00"})


def test_feetech_file_is_one_sync_write_per_period(dh3_trajectory):
    robot, traj = dh3_trajectory
    fmt = servo_format("feetech")
    cals = fmt.default_calibrations(robot)
    assert [c.id for c in cals] == [1, 2, 3]
    lines = fmt.render(traj, cals, 20).splitlines()
    t = command_times(traj, 20)
    assert len(lines) == len(t)
    first = hexbytes(lines[0].split(" ", 1)[1])
    assert first[:7] == hexbytes("FF FF FE 0D 83 2A 02")  # LEN = (2 + 1) * 3 + 4 = 13
    ticks = [decode_position(first[8 + 3 * k : 10 + 3 * k]) for k in range(3)]
    assert ticks == [round(c.ticks(a)) for c, a in zip(cals, traj.waypoints[0])]
    with pytest.raises(InvalidArgumentError, match="this controller needs one TickCalibration per joint"):
        fmt.render(traj, default_calibrations(robot), 20)


def test_tick_calibration_direction_and_limits():
    cal = TickCalibration(3, ticks_at_zero=2000, direction=-1, joint="elbow")
    assert cal.ticks(0.5) == pytest.approx(2000 - 0.5 * 4096 / (2 * math.pi))
    assert cal.angle(cal.ticks(0.5)) == pytest.approx(0.5)
    with pytest.raises(InvalidArgumentError, match=r"joint 'elbow' \(id 3\) angle 4 rad needs position"):
        cal.ticks(4.0)


def test_pca9685_ticks(dh3_trajectory):
    robot, traj = dh3_trajectory
    assert pca9685_off_ticks(np.array([1500.0, 500.0, 2500.0]), 50.0).tolist() == [307, 102, 512]
    assert pca9685_off_ticks(np.array([1500.0]), 60.0).tolist() == [369]
    cals = default_calibrations(robot)
    rows = Pca9685(pwm_frequency_hz=60).render(traj, cals, 20).splitlines()
    assert rows[0] == "t,ch0_base_yaw_on,ch0_base_yaw_off,ch1_shoulder_on,ch1_shoulder_off,ch2_elbow_on,ch2_elbow_off"
    values = [int(x) for x in rows[1].split(",")[1:]]
    pulses = [round(c.pulse(a)) for c, a in zip(cals, traj.waypoints[0])]
    assert values == [v for p in pulses for v in (0, round(p * 60 * 4096 / 1e6))]
    with pytest.raises(InvalidArgumentError, match=r"pwm_frequency_hz must be a number in \[24, 1526\] Hz"):
        Pca9685(pwm_frequency_hz=2000)
    with pytest.raises(InvalidArgumentError, match="does not fit in one 1000 us PWM period at 1000 Hz"):
        Pca9685(pwm_frequency_hz=1000).render(traj, cals, 20)


def test_steps_match_materick_and_shapiro(dh3_trajectory, tmp_path):
    robot, traj = dh3_trajectory
    travel, max_steps = math.radians(135), 2048
    path = tmp_path / "steps.yaml"
    servos = [
        {"channel": k, "zero": 0, "scale": max_steps / travel, "limits": [-max_steps, max_steps]} for k in range(3)
    ]
    path.write_text(json.dumps({"controller": "steps", "servos": servos}))
    setup = load_calibration(path, robot)
    rows = servo_format("steps").render(traj, setup.calibrations, 40).splitlines()
    t = command_times(traj, 40)
    expected = angle_to_steps(traj.sample(t).q, travel, max_steps)
    assert [[int(x) for x in r.split(",")[1:]] for r in rows[1:]] == expected.tolist()
    with pytest.raises(InvalidArgumentError, match="controller 'steps' has no default calibration"):
        controller_setup(robot, "steps")


def test_shipped_calibrations():
    path = shipped_calibration("al5c", "ssc32")
    setup = load_calibration(path, get_robot("al5c"))
    assert setup.controller == "ssc32"
    assert [c.channel for c in setup.calibrations] == [0, 1, 2, 3, 5]
    robot = get_robot("al5c")
    for cal, lo, hi in zip(setup.calibrations, robot.lower, robot.upper):
        assert 500 <= cal.pulse(lo) <= 2500 and 500 <= cal.pulse(hi) <= 2500
    assert shipped_calibration("so101", "feetech").is_file()
    assert shipped_calibration("dh3", "ssc32") is None


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"controller": "dmx", "servos": []}, "unknown controller 'dmx'; valid controllers: pulses, ssc32"),
        # A list or mapping raised TypeError (unhashable) from the membership test.
        ({"controller": ["ssc32"], "servos": []}, r"unknown controller \['ssc32'\]; valid controllers: pulses, ssc32"),
        ({"controller": "ssc32", "servos": [{"channel": 0}]}, "servos must list one servo per joint: dh3 has 3"),
        ({"controller": "ssc32", "robot": "al5c", "servos": []}, "this calibration is for robot 'al5c', not 'dh3'"),
        (
            {"controller": "ssc32", "servos": [{"channel": 0}, {"channel": 1}, {"id": 1}]},
            "servo channels must differ, got",
        ),
        (
            {"controller": "feetech", "servos": [{"id": 1}, {"id": 2}, {"id": 3, "direction": 2}]},
            r"servos\[2\]: servo for joint 'elbow': direction must be \+1 or -1, got 2",
        ),
        (
            {"controller": "ssc32", "servos": [{"channel": 0, "zero": 1500, "offset": 3}, {"channel": 1}, {"id": 2}]},
            r"unknown key 'offset' in servos\[0\]; valid keys: joint, channel, id, zero",
        ),
        (
            {"controller": "pca9685", "settings": {"frequency": 50}, "servos": []},
            "controller 'pca9685' has no setting 'frequency'; valid settings: pwm_frequency_hz",
        ),
    ],
)
def test_bad_calibration_files(tmp_path, data, message):
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(data))
    with pytest.raises(InvalidArgumentError, match=message):
        load_calibration(path, get_robot("dh3"))


def test_calibration_by_joint_name_in_any_order(tmp_path):
    path = tmp_path / "cal.yaml"
    path.write_text(
        "controller: feetech\nservos:\n"
        "  - {joint: elbow, id: 7, scale_per_deg: 11.3778}\n"
        "  - {joint: base_yaw, id: 5}\n"
        "  - {joint: shoulder, id: 6, direction: -1, zero: 2000, limits: [100, 4000]}\n"
    )
    cals = load_calibration(path, get_robot("dh3")).calibrations
    assert [c.id for c in cals] == [5, 6, 7]
    assert cals[1].min_ticks == 100 and cals[1].direction == -1
    assert cals[2].ticks_per_rad == pytest.approx(11.3778 * 180 / math.pi)


def test_plan_out_writes_the_controllers_file(tmp_path, capsys):
    plan = tmp_path / "p.yaml"
    plan.write_text("waypoints:\n  - [0, 0.5, 1]\n  - [0.5, 0.8, 1.2]\ncontroller: feetech\n")
    out = tmp_path / "run"
    assert main(["plan", "dh3", str(plan), "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["feetech.txt", "summary.json", "trajectory.csv"]
    assert json.loads((out / "summary.json").read_text())["controller"] == "feetech"
    out2 = tmp_path / "run2"
    assert main(["plan", "al5c", str(_al5c_plan(tmp_path)), "--out", str(out2), "--controller", "pca9685"]) == 0
    assert (out2 / "pca9685.csv").read_text().startswith("t,ch0_base_yaw_on,ch0_base_yaw_off")
    capsys.readouterr()


def _al5c_plan(tmp_path):
    path = tmp_path / "al5c.yaml"
    path.write_text("units: {angle: deg}\nwaypoints:\n  - [0, 90, -90, 0, 0]\n  - [20, 80, -80, 10, 0]\n")
    return path


def test_a_format_problem_keeps_the_trajectory_and_summary(tmp_path, capsys):
    plan = tmp_path / "p.yaml"
    # channel 20 suits an SSC-32 but not a PCA9685 (channels 0-15)
    plan.write_text(
        "waypoints:\n  - [0, 0.5, 1]\n  - [0.5, 0.8, 1.2]\ncontroller: pca9685\n"
        "servos:\n  - {channel: 20}\n  - {channel: 1}\n  - {channel: 2}\n"
    )
    out = tmp_path / "run"
    assert main(["plan", "dh3", str(plan), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "pca9685.csv: joint 'base_yaw' uses channel 20; a PCA9685 has channels 0-15" in err
    assert (out / "trajectory.csv").is_file()
    assert "pca9685.csv" in json.loads((out / "summary.json").read_text())["servo_file_errors"]


def test_cli_controller_choices_are_the_registries():
    from planner.app.cli import build_parser
    from planner.export.formats import SERVO_FORMATS
    from planner.hardware import DRIVERS

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for command, registry in (("plan", SERVO_FORMATS), ("send", DRIVERS)):
        action = next(a for a in sub.choices[command]._actions if a.dest == "controller")
        assert tuple(action.choices) == tuple(registry)


def test_readme_dry_run_output_is_real(tmp_path, capsys, monkeypatch):
    from pathlib import Path

    readme = Path(__file__).resolve().parent.parent / "README.md"
    if not readme.is_file():
        pytest.skip("README.md is not next to the tests")
    text = readme.read_text()
    start = text.index("$ planner send al5c wave.yaml --dry-run\n")
    shown = text[start:].split("\n", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    Path("wave.yaml").write_text("{units: {angle: deg}, waypoints: [[0, 90, -90, 0, 0], [10, 85, -95, 5, 0]]}\n")
    assert main(["send", "al5c", "wave.yaml", "--dry-run"]) == 0
    assert capsys.readouterr().out == shown


@pytest.mark.parametrize("controller", [["ssc32"], {"ssc32": 1}])
def test_a_controller_that_is_no_name_is_refused_by_name(controller):
    # A plan file's or an API caller's list or mapping raised TypeError (unhashable).
    from planner.app.plan_file import parse_motion_request

    with pytest.raises(InvalidArgumentError, match=r"unknown controller .*; valid controllers: pulses, ssc32"):
        parse_motion_request({"waypoints": [[0, 0, 0], [1, 1, 1]], "controller": controller})
    with pytest.raises(InvalidArgumentError, match=r"unknown controller .*; valid controllers: pulses, ssc32"):
        controller_setup(get_robot("dh3"), controller)
