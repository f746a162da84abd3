"""`planner send` against fake controllers on a pseudo-terminal: real byte streams, real pacing, no hardware.

Timing is reported (printed) and checked only with a loose bound on the average pace.
"""

from __future__ import annotations

import io
import sys

import numpy as np
import pytest

pytest.importorskip("serial", reason="planner send needs pyserial (pip install 'servo-arm-planner[hardware]')")

from planner import ControllerError, InvalidArgumentError, StartPositionError  # noqa: E402
from planner.app.cli import main  # noqa: E402
from planner.app.motion_plan import plan_motion  # noqa: E402
from planner.app.plan_file import load_motion_request  # noqa: E402
from planner.app.send import send_plan  # noqa: E402
from planner.export.formats.feetech import Feetech, goal_position_packet  # noqa: E402
from planner.export.formats.ssc32 import ssc32_group_moves  # noqa: E402
from planner.hardware.link import Clock, open_serial  # noqa: E402
from planner.hardware.session import SendOptions, SendStatus  # noqa: E402

from conftest import get_robot, needs_example_robot_data  # noqa: E402
from fake_controllers import FakeFeetechBus, FakeSsc32  # noqa: E402

PERIOD = 0.020
AL5C_PLAN = (
    "units: {angle: deg}\nwaypoints:\n  - [0, 90, -90, 0, 0]\n  - [30, 70, -100, 20, 0]\n  - [-10, 80, -80, 0, 10]\n"
)
DH3_PLAN = "units: {angle: deg}\nwaypoints:\n  - [0, 20, 40]\n  - [40, 50, 70]\n  - [10, 30, 50]\n"
SO101_PLAN = "units: {angle: deg}\nwaypoints:\n  - [0, 0, 0, 0, 0]\n  - [30, -20, 25, 10, 40]\n"


@pytest.fixture(autouse=True)
def _patient_ssc32_queries(monkeypatch):
    # The fake SSC-32 answers from a thread of this process: on a loaded machine that thread can
    # wait longer than a board's 0.2 s query timeout (a flaky "no answer to 'QP 0'"). No test here
    # relies on a query timing out.
    import planner.hardware.ssc32 as ssc32

    monkeypatch.setattr(ssc32, "QUERY_TIMEOUT", 2.0)


@pytest.fixture(scope="module")
def al5c_plan(tmp_path_factory):
    path = tmp_path_factory.mktemp("send") / "al5c.yaml"
    path.write_text(AL5C_PLAN)
    plan = plan_motion(get_robot("al5c"), load_motion_request(path), controller="ssc32")
    return path, plan


def _first_pulses(plan):
    return {c.channel: round(c.pulse(a)) for c, a in zip(plan.calibrations, plan.trajectory.waypoints[0])}


def _report_pace(label, times, n_commands):
    intervals = np.diff(times)
    mean = float(np.mean(intervals))
    print(
        f"\n{label}: {n_commands} commands over {times[-1] - times[0]:.3f} s, mean interval {mean * 1000:.2f} ms "
        f"(period {PERIOD * 1000:.0f} ms), max {np.max(intervals) * 1000:.2f} ms"
    )
    return mean


def test_ssc32_send_streams_every_command_in_order_at_pace(al5c_plan, capsys):
    path, plan = al5c_plan
    expected = ssc32_group_moves(plan.trajectory, plan.calibrations, 20)
    with FakeSsc32(_first_pulses(plan)) as fake:
        code = main(["send", "al5c", str(path), "--port", fake.port, "--controller", "ssc32"])
    out = capsys.readouterr().out
    assert code == 0, out
    assert f"sent {len(expected)} of {len(expected)} commands: the whole plan" in out
    # read-back first: one QP per channel in use (the gripper's channel 4 is not one)
    assert fake.log[:5] == ["QP 0", "QP 1", "QP 2", "QP 3", "QP 5"]
    assert fake.log[5:] == expected and not fake.errors
    assert len(expected) == int(np.ceil(plan.trajectory.duration / PERIOD - 1e-9)) + 1
    times = np.array([t for t, _, _ in fake.moves])
    mean = _report_pace("ssc32 over a pty", times, len(times))
    assert abs(mean - PERIOD) < 0.25 * PERIOD  # loose: pacing by deadlines keeps the average


def test_ssc32_channel_never_commanded_is_unknown_and_refused(al5c_plan, capsys):
    path, _ = al5c_plan
    with FakeSsc32() as fake:  # a board fresh from power-up: QP answers 0
        code = main(["send", "al5c", str(path), "--port", fake.port])
    err = capsys.readouterr().err
    assert code == 1
    assert "cannot tell where joint(s) base_yaw, shoulder, elbow, wrist_pitch, wrist_rotate are" in err
    assert "--approach-time S" in err and "the arm jumps" in err
    assert fake.moves == []


def test_ssc32_approach_time_makes_one_timed_move_first(al5c_plan, capsys):
    path, plan = al5c_plan
    expected = ssc32_group_moves(plan.trajectory, plan.calibrations, 20)
    with FakeSsc32() as fake:
        code = main(["send", "al5c", str(path), "--port", fake.port, "--approach-time", "0.3"])
    assert code == 0, capsys.readouterr().err
    first = fake.moves[0]
    assert first[2] == 300 and first[1] == _first_pulses(plan)
    assert fake.log[6:] == expected
    assert fake.moves[1][0] - first[0] > 0.25  # the plan waits for the approach


def test_far_from_first_waypoint_is_refused_or_planned_from_current(al5c_plan, capsys):
    path, plan = al5c_plan
    pulses = _first_pulses(plan)
    pulses[0] += 300  # base about 27 deg off
    with FakeSsc32(pulses) as fake:
        code = main(["send", "al5c", str(path), "--port", fake.port])
    err = capsys.readouterr().err
    assert code == 1 and "joint 'base_yaw' is at" in err and "give --from-current" in err
    assert fake.moves == []
    with FakeSsc32(pulses) as fake:
        code = main(["send", "al5c", str(path), "--port", fake.port, "--from-current"])
    assert code == 0, capsys.readouterr().err
    moves = [m for _, m, _ in fake.moves]
    assert moves[0][0] == pulses[0]  # the first move starts where the base was (QP resolution 10 us)
    plan_start = len(moves) - len(ssc32_group_moves(plan.trajectory, plan.calibrations, 20))
    assert plan_start > 1 and moves[plan_start - 1] == _first_pulses(plan) == moves[plan_start]


def test_ctrl_c_stops_every_channel_in_use(al5c_plan):
    path, plan = al5c_plan
    sleeps = []

    def sleep_then_ctrl_c(seconds):
        sleeps.append(seconds)
        if len(sleeps) == 12:
            raise KeyboardInterrupt
        Clock().sleep(seconds)

    with FakeSsc32(_first_pulses(plan)) as fake:
        result = send_plan(get_robot("al5c"), path, port=fake.port, clock=Clock(sleep=sleep_then_ctrl_c))
        Clock().sleep(0.2)
    assert result.status is SendStatus.INTERRUPTED
    assert result.stop == "STOP 0, STOP 1, STOP 2, STOP 3, STOP 5"
    assert 0 < result.commands_sent == len(fake.moves) < result.commands_total
    assert fake.log[-5:] == ["STOP 0", "STOP 1", "STOP 2", "STOP 3", "STOP 5"]
    assert result.plan_time == pytest.approx((result.commands_sent - 1) * PERIOD)
    assert f"command {result.commands_sent} of {result.commands_total}" in result.message


def test_serial_error_mid_stream_is_reported(al5c_plan):
    path, plan = al5c_plan
    with FakeSsc32(_first_pulses(plan)) as fake:
        fake.hang_up_after = 5
        result = send_plan(get_robot("al5c"), path, port=fake.port)
    assert result.status is SendStatus.LINK_ERROR
    assert 5 <= result.commands_sent < result.commands_total
    assert "could not stop the servos" in result.stop and "stopped at t =" in result.message


def test_baud_rate_too_slow_is_refused_before_opening_the_port(al5c_plan, capsys):
    path, _ = al5c_plan
    assert main(["send", "al5c", str(path), "--port", "/dev/does-not-exist", "--baud", "9600"]) == 1
    err = capsys.readouterr().err
    assert "9600 baud carries 192 bits per 20 ms period, but each ssc32 command needs up to 390 (19.5 kbit/s)" in err
    assert "use 38400 baud or faster" in err


def test_missing_port_and_missing_pyserial(al5c_plan, capsys, monkeypatch):
    path, _ = al5c_plan
    assert main(["send", "al5c", str(path)]) == 1
    assert "give --port DEVICE" in capsys.readouterr().err
    with pytest.raises(ControllerError, match="cannot open serial port '/dev/does-not-exist'"):
        open_serial("/dev/does-not-exist", 115200)
    monkeypatch.setitem(sys.modules, "serial", None)
    with pytest.raises(ControllerError, match=r"needs pyserial: pip install 'servo-arm-planner\[hardware\]'"):
        open_serial("/dev/ttyUSB0", 115200)


def test_dry_run_prints_the_stream_with_timestamps(al5c_plan, capsys):
    path, plan = al5c_plan
    expected = ssc32_group_moves(plan.trajectory, plan.calibrations, 20)
    assert main(["send", "al5c", str(path), "--dry-run"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("# dry run: al5c on ssc32 (al5c-ssc32.yaml)")
    body = [line.split() for line in lines[2:-1]]
    assert [b[1] for b in body] == [c + "\\r" for c in expected]
    np.testing.assert_allclose([float(b[0]) for b in body], np.arange(len(expected)) * PERIOD, atol=1e-9)
    assert lines[-1].startswith("# sent")


def _feetech_send(robot_name, plan_text, tmp_path, extra=()):
    path = tmp_path / f"{robot_name}.yaml"
    path.write_text(plan_text)
    robot = get_robot(robot_name)
    plan = plan_motion(robot, load_motion_request(path), controller="feetech")
    packets = Feetech().packets(plan.trajectory, plan.calibrations, 20)
    start = {c.id: round(c.ticks(a)) for c, a in zip(plan.calibrations, plan.trajectory.waypoints[0])}
    return path, plan, packets, start


def _check_feetech_stream(fake, plan, packets):
    ids = [c.id for c in plan.calibrations]
    assert fake.bad == []
    n = len(ids)
    # read-back, then (begin) the present positions again, goal = present, torque on; then the stream
    reads = [p for _, p in fake.packets[:n] + fake.packets[n : 2 * n]]
    assert [(p[2], p[4], p[5], p[6]) for p in reads] == [(i, 0x02, 0x38, 2) for i in ids] * 2
    hold, torque = fake.packets[2 * n][1], fake.packets[2 * n + 1][1]
    assert hold == goal_position_packet(ids, [fake.writes[0][1][i] for i in ids])
    assert torque[4:7] == bytes([0x83, 0x28, 1]) and fake.torque == dict.fromkeys(ids, 1)
    assert [p for _, p in fake.packets[2 * n + 2 :]] == [p for _, p in packets]
    times = np.array([t for t, _ in fake.writes[1:]])
    return _report_pace("feetech over a pty", times, len(times))


def test_feetech_send_on_a_bundled_arm(tmp_path, capsys):
    path, plan, packets, start = _feetech_send("dh3", DH3_PLAN, tmp_path)
    with FakeFeetechBus(start) as fake:
        code = main(["send", "dh3", str(path), "--port", fake.port, "--controller", "feetech"])
    assert code == 0, capsys.readouterr().err
    mean = _check_feetech_stream(fake, plan, packets)
    assert abs(mean - PERIOD) < 0.25 * PERIOD


def test_feetech_interrupt_holds_each_servo_where_it_is(tmp_path):
    path, plan, packets, start = _feetech_send("dh3", DH3_PLAN, tmp_path)
    calls = []

    def sleep_then_ctrl_c(seconds):
        calls.append(seconds)
        if len(calls) == 10:
            raise KeyboardInterrupt
        Clock().sleep(seconds)

    with FakeFeetechBus(start) as fake:
        result = send_plan(
            get_robot("dh3"), path, port=fake.port, controller="feetech", clock=Clock(sleep=sleep_then_ctrl_c)
        )
        Clock().sleep(0.2)
    assert result.status is SendStatus.INTERRUPTED and result.stop == "goal = present position for ids 1, 2, 3"
    assert fake.bad == []
    stream_writes = fake.writes[1:-1]  # after the goal = present write of the start
    assert len(stream_writes) == result.commands_sent
    # after the last streamed goal: three position reads, then one sync write of those positions
    last_reads = [p for _, p in fake.packets[-4:-1]]
    assert [p[4] for p in last_reads] == [0x02, 0x02, 0x02]
    assert fake.writes[-1][1] == stream_writes[-1][1]


def test_feetech_far_from_start_is_refused(tmp_path):
    path, _, _, start = _feetech_send("dh3", DH3_PLAN, tmp_path)
    start[2] += 400  # about 35 deg
    with FakeFeetechBus(start) as fake:
        with pytest.raises(StartPositionError, match="joint 'shoulder' is at") as info:
            send_plan(get_robot("dh3"), path, port=fake.port, controller="feetech")
    assert info.value.joint == "shoulder" and fake.writes == []
    with FakeFeetechBus(start) as fake:
        with pytest.raises(ControllerError, match="use --from-current instead of --approach-time"):
            send_plan(
                get_robot("dh3"), path, port=fake.port, controller="feetech", options=SendOptions(approach_time=1.0)
            )


@needs_example_robot_data
def test_feetech_send_so101(tmp_path, capsys):
    path, plan, packets, start = _feetech_send("so101", SO101_PLAN, tmp_path)
    assert plan.setup.source.endswith("so101-feetech.yaml")
    with FakeFeetechBus(start) as fake:
        code = main(["send", "so101", str(path), "--port", fake.port, "--controller", "feetech"])
    assert code == 0, capsys.readouterr().err
    _check_feetech_stream(fake, plan, packets)


def test_dry_run_feetech_is_hex(tmp_path):
    path, _, packets, _ = _feetech_send("dh3", DH3_PLAN, tmp_path)
    out = io.StringIO()
    result = send_plan(get_robot("dh3"), path, controller="feetech", dry_run=out)
    assert result.status is SendStatus.COMPLETED and result.start_q is None
    line = out.getvalue().splitlines()[2]
    assert line.split(None, 1)[1] == packets[0][1].hex(" ")


def test_send_options_and_controllers_are_checked(al5c_plan):
    path, _ = al5c_plan
    with pytest.raises(InvalidArgumentError, match="approach_time must be positive"):
        SendOptions(approach_time=0.0)
    with pytest.raises(InvalidArgumentError, match=r"baud must be a positive integer \[bit/s\], got -5"):
        SendOptions(baud=-5)
    with pytest.raises(InvalidArgumentError, match="planner send cannot drive controller 'pca9685'; valid controllers"):
        send_plan(get_robot("al5c"), path, controller="pca9685", dry_run=io.StringIO())
    with pytest.raises(InvalidArgumentError, match="give the serial port"):
        send_plan(get_robot("al5c"), path)


def test_scs_series_streams_high_byte_first(tmp_path):
    path = tmp_path / "dh3.yaml"
    path.write_text(DH3_PLAN)
    cal = tmp_path / "scs.yaml"
    cal.write_text(
        "controller: feetech\nsettings: {series: scs}\nservos:\n"
        + "".join(f"  - {{id: {k + 1}, zero: 512, scale: 195.6, limits: [0, 1023]}}\n" for k in range(3))
    )
    out = io.StringIO()
    send_plan(get_robot("dh3"), path, controller="feetech", calibration=cal, dry_run=out)
    first = bytes.fromhex(out.getvalue().splitlines()[2].split(None, 1)[1])
    ticks = round(512 + 195.6 * np.radians(0))
    assert first[7:10] == bytes([1]) + ticks.to_bytes(2, "big")


def test_from_current_with_a_reading_outside_the_range_names_the_reading(al5c_plan):
    # It said "waypoint 0: joint 'base_yaw' value 1.64939 is outside its range": the plan's
    # waypoint 0 was fine; the arm's reading (2550 us, beyond the calibration) was not.
    path, plan = al5c_plan
    pulses = _first_pulses(plan)
    pulses[0] = 2550
    with FakeSsc32(pulses) as fake:
        with pytest.raises(
            StartPositionError, match=r"^the ssc32 reads joint 'base_yaw' at 1\.6\d+ rad, outside its range"
        ) as info:
            send_plan(get_robot("al5c"), path, port=fake.port, options=SendOptions(from_current=True))
    assert info.value.joint == "base_yaw" and fake.moves == []
    assert info.value.expected == pytest.approx(plan.trajectory.waypoints[0][0])


class FeetechBusThatFallsSilent(FakeFeetechBus):
    """Answers the first `reads` position reads, then none (a servo unplugged after the start check)."""

    def __init__(self, positions, reads):
        super().__init__(positions)
        self.reads_left = reads

    def handle(self, pkt, now):
        if pkt[4] == 0x02:
            if self.reads_left <= 0:
                return
            self.reads_left -= 1
        super().handle(pkt, now)


def test_a_stream_stopped_before_its_first_command_says_so_in_plain_words(tmp_path):
    # The message read "stopped at before the plan's first command of 0.241 s (command 0 of 14)".
    path, plan, _, start = _feetech_send("dh3", DH3_PLAN, tmp_path)
    with FeetechBusThatFallsSilent(start, reads=3) as fake:  # the start check's reads, not begin's
        result = send_plan(get_robot("dh3"), path, port=fake.port, controller="feetech")
    assert result.status is SendStatus.LINK_ERROR and result.commands_sent == 0
    total, duration = result.commands_total, plan.trajectory.duration
    assert result.message == (
        f"stopped before the {duration:.3f} s plan began (command 0 of {total}): servo id 1 does not answer on "
        f"{fake.port}: check its id, the baud rate and the bus power; no servo answered; ids 1, 2, 3 did not answer"
    )
