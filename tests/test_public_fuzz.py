"""Public entry points on inputs a user can give them: found by the review's random search
(hypothesis, not derandomized), kept here as fixed cases (derandomized where generated).
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import planner
from planner.app.cli import main as cli_main

from conftest import get_robot

METHODS = ("auto", "analytic", "nlp")


@pytest.mark.parametrize("name", ["shelley", "al5c", "dh3", "three_joint"])
@pytest.mark.parametrize("kind", ["position", "pitch", "pose"])
def test_a_target_astronomically_far_is_unreachable_not_an_overflow(name, kind):
    # A coordinate of 1e160 m squared overflows Python floats: solve_ik raised OverflowError
    # from the error and reach computations. It is a target beyond reach like any other.
    robot = get_robot(name)
    position = [1e160, -1e160, 0.1]
    target = {
        "position": planner.Target(position),
        "pitch": planner.Target(position, pitch=0.3),
        "pose": planner.Target(position, rotation=np.eye(3)),
    }[kind]
    for method in METHODS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            result = planner.solve_ik(robot, target, method=method, options=planner.IKOptions(time_budget=0.01))
        assert not result.success
        assert result.reason


def test_a_huge_manipulability_floor_is_a_result_not_an_overflow():
    # IKOptions accepts any positive finite floor; 1e300 raised OverflowError from squaring it
    # for the NLP's polish (and near the largest float Ipopt met NaN, with a flood of warnings).
    robot = get_robot("al5c")
    for floor in (1e160, 1e300):
        options = planner.IKOptions(manipulability_floor=floor, time_budget=0.01)
        result = planner.solve_ik(robot, [0.2, 0.0, 0.1], method="nlp", options=options)
        assert result.status == planner.IKStatus.BELOW_MANIPULABILITY_FLOOR
        assert f"{floor:g}" in result.reason


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e200, 1e308])
def test_a_quaternion_means_its_direction_at_any_scale(scale):
    # (1, 1, 1, 1) x 1e308 became the identity (its norm overflowed to inf): a wrong target
    # without a word. 120 deg about (1, 1, 1) maps x to y.
    rotation = planner.quaternion_to_matrix([scale] * 4)
    np.testing.assert_allclose(rotation @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    target = planner.Target.from_quaternion([0.1, 0.0, 0.1], [scale] * 4)
    np.testing.assert_allclose(target.rotation, rotation)


def test_a_zero_quaternion_is_refused_with_plain_numbers():
    with pytest.raises(planner.InvalidArgumentError, match=r"has zero norm: \[0\.0, 0\.0, 0\.0, 0\.0\]$"):
        planner.quaternion_to_matrix([0, 0, 0, 0])


def test_a_negative_rng_seed_is_refused_when_the_options_are_made():
    # It reached numpy.random.default_rng inside solve_ik: ValueError "expected non-negative integer".
    with pytest.raises(planner.InvalidArgumentError, match=r"rng: an int seed must be >= 0 .*, got -1"):
        planner.IKOptions(rng=-1)
    assert planner.IKOptions(rng=0).generator() is not None


@pytest.mark.parametrize("pose", ["x", [[1, 2], [3]], {"a": 1}])
def test_target_from_pose_refuses_what_is_not_numbers(pose):
    with pytest.raises(planner.InvalidArgumentError, match=r"pose must be a 4x4 array of numbers"):
        planner.Target.from_pose(pose)


def cli_error(capsys, *argv: str) -> str:
    """The one line a failing command prints on stderr (its exit status checked to be 1)."""
    assert cli_main(list(argv)) == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("waypoints: [[0, 1]\n", r"expected ',' or ']', but got '<stream end>' at line 2, column 1$"),
        ("a: 1\n\tb: 2\n", r"found character '\\t' that cannot start any token at line 2, column 1$"),
    ],
)
def test_a_plan_file_that_does_not_parse_is_one_line(tmp_path, capsys, text, message):
    # YAML's own message runs over five lines (its excerpt and a caret).
    path = tmp_path / "plan.yaml"
    path.write_text(text)
    for command in ("plan", "check"):
        assert re.search(message, cli_error(capsys, command, "dh3", str(path)))


def test_a_plan_file_that_is_not_text_is_refused(tmp_path, capsys):
    # UnicodeDecodeError (a ValueError) left read_data_file: a traceback.
    path = tmp_path / "plan.yaml"
    path.write_bytes(b"waypoints: [[0, 1], [\xff\xfe, 2]]\n")
    line = cli_error(capsys, "plan", "dh3", str(path))
    assert line.endswith("plan.yaml': not UTF-8 text (byte 0xff at offset 21)")
    with pytest.raises(planner.InvalidArgumentError, match="not UTF-8 text"):
        planner.load_motion_request(path)


DH3_PLAN = "units: {length: cm, angle: deg}\ntargets: [{position: [17, 0, 3]}, {position: [11, 0, 9]}]\n"


def test_an_animation_into_a_folder_that_cannot_be_made_is_one_line(tmp_path, capsys):
    # FileExistsError from creating the GIF's folder (a file stood there): a traceback.
    pytest.importorskip("matplotlib")
    plan = tmp_path / "plan.yaml"
    plan.write_text(DH3_PLAN)
    blocker = tmp_path / "taken"
    blocker.write_text("")
    line = cli_error(capsys, "plan", "dh3", str(plan), "--animate", str(blocker / "a.gif"))
    assert line == f"planner plan: error: cannot write {blocker / 'a.gif'}: File exists"


@pytest.mark.parametrize("where", ["folder", "under_a_file"])
def test_ik_batch_out_that_cannot_be_written_is_one_line(tmp_path, capsys, where):
    # IsADirectoryError / FileExistsError tracebacks, after solving every target.
    targets = tmp_path / "targets.csv"
    targets.write_text("x,y,z\n0.2,0,0.1\n")
    (tmp_path / "taken").write_text("")
    out = tmp_path if where == "folder" else tmp_path / "taken" / "answers.csv"
    line = cli_error(capsys, "ik", "al5c", "--batch", str(targets), "--out", str(out))
    reason = "Is a directory" if where == "folder" else "File exists"
    assert line == f"planner ik: error: cannot write --out {str(out)!r}: {reason}"


def test_plan_out_and_bench_out_that_cannot_be_written_are_one_line(tmp_path, capsys):
    # A folder where plan --out writes trajectory.csv, a file where bench --out makes its folder:
    # IsADirectoryError / FileExistsError tracebacks.
    plan = tmp_path / "plan.yaml"
    plan.write_text(DH3_PLAN)
    (tmp_path / "out" / "trajectory.csv").mkdir(parents=True)
    line = cli_error(capsys, "plan", "dh3", str(plan), "--out", str(tmp_path / "out"))
    assert line == f"planner plan: error: cannot write {str(tmp_path / 'out' / 'trajectory.csv')!r}: Is a directory"
    line = cli_error(capsys, "bench", "dh3", "--n", "1", "--out", str(plan))
    assert line == f"planner bench: error: {str(plan)!r}: File exists"


@pytest.mark.parametrize("rate", ["1e300", "2e5", "nan", "0"])
def test_plan_rate_beyond_what_memory_holds_is_refused_first(tmp_path, capsys, rate):
    # --rate 1e300 raised ValueError (Maximum allowed size exceeded), 1e7 ran out of memory in
    # the singularity check, before anything was said.
    plan = tmp_path / "plan.yaml"
    plan.write_text(DH3_PLAN)
    line = cli_error(capsys, "plan", "dh3", str(plan), "--rate", rate)
    assert line == f"planner plan: error: --rate must be a number in (0, 100000] [Hz], got {float(rate):g}"


BOM = b"\xef\xbb\xbf"


def test_a_target_file_saved_with_a_byte_order_mark_reads(tmp_path, capsys):
    # A spreadsheet's "CSV UTF-8" starts with a BOM: "column '\ufeffx': unknown column".
    from planner.app.target_file import read_targets

    path = tmp_path / "targets.csv"
    path.write_bytes(BOM + b"x,y,z\n0.1,0,0.1\n")
    np.testing.assert_array_equal(read_targets(path).positions, [[0.1, 0.0, 0.1]])
    assert cli_main(["ik", "dh3", "--batch", str(path)]) == 0
    assert capsys.readouterr().out.splitlines()[1].startswith("1,solved,")


@pytest.mark.parametrize("name", ["plan.json", "plan.yaml"])
def test_a_plan_file_saved_with_a_byte_order_mark_reads(tmp_path, name):
    # JSON refused it: "Unexpected UTF-8 BOM (decode using utf-8-sig)".
    path = tmp_path / name
    path.write_bytes(BOM + b'{"waypoints": [[0, 0, 0], [0.1, 0.1, 0.1]]}')
    request = planner.load_motion_request(path)
    np.testing.assert_array_equal(request.joints, [[0, 0, 0], [0.1, 0.1, 0.1]])


@pytest.mark.parametrize(
    ("obstacle", "message"),
    [
        (
            {"box": [1, 1, 1], "position": [1e200, 0, 0]},
            r"position must lie within 1e\+06 m of the base, got \[1e\+200",
        ),
        ({"sphere": 1e200, "position": [0, 0, -1e200]}, r"sphere radius must be at most 1e\+06 m, got 1e\+200 m"),
        ({"cylinder": {"radius": 0.1, "length": 1e7}, "position": [0, 0, 0]}, r"cylinder length must be at most"),
        ({"box": [1, 2e6, 1], "position": [0, 0, 0]}, r"box size must be at most 1e\+06 m, got 2000000.0 m"),
    ],
)
def test_an_obstacle_beyond_a_million_metres_is_refused(obstacle, message):
    # planner plan / check never returned: a 1 m box at 1e200 m (or a sphere of radius 1e200 m)
    # made the continuous check's distance bounds overflow to NaN, and its loop never advanced.
    data = {"waypoints": [[0, 0.5, -0.5], [0.5, 0.6, -0.4]], "scene": {"obstacles": [{"name": "b", **obstacle}]}}
    with pytest.raises(planner.InvalidArgumentError, match=r"scene\.obstacles\[0\]: .*" + message):
        planner.parse_motion_request(data)


def test_an_obstacle_a_thousand_kilometres_away_still_plans():
    data = {
        "waypoints": [[0, 0.5, -0.5], [0.5, 0.6, -0.4]],
        "scene": {"obstacles": [{"name": "b", "box": [1, 1, 1], "position": [1e6, 0, 0]}]},
    }
    plan = planner.plan_motion(get_robot("dh3"), planner.parse_motion_request(data))
    assert plan.summary()["collision"]["clear"]


@pytest.mark.parametrize("key", ["units", "tool", "base"])
@pytest.mark.parametrize("value", ["cm", [1, 2], 3])
def test_an_arm_description_section_that_is_not_a_mapping_is_refused(key, value):
    # `tool: gripper` (or units: cm, base: [..]) raised AttributeError: 'str' object has no attribute 'get'.
    row = {"theta": 0, "d": 0.1, "a": 0.1, "alpha": 0, "lower": -1, "upper": 1, "velocity": 1}
    description = {"dh": [row], key: value}
    with pytest.raises(planner.InvalidArgumentError, match=rf"^`{key}` must be a mapping such as {{.*}}, got "):
        planner.urdf_from_dh(description)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"fps": 1e-9}, r"^fps must be in \[0\.01, 60\] frames per second, got 1e-09$"),
        ({"fps": True}, r"^fps must be in \[0\.01, 60\] frames per second, got True$"),
        ({"speed": 1e-9}, r"^1\.3\d+e\+10 frames for a 0\.9 s plan at 15 fps and speed 1e-09; at most 3000 "),
        ({"speed": 1e-300}, r"^inf frames for a 0\.9 s plan at 15 fps and speed 1e-300; at most 3000 "),
    ],
)
def test_animation_rates_that_cannot_be_drawn_are_refused_first(tmp_path, options, message):
    # fps=1e-9 raised PIL's OverflowError (a frame delay past the GIF's 16 bits) after drawing;
    # speed=1e-9 asked NumPy for 98 GiB of frame times (MemoryError) before the frame-count check.
    pytest.importorskip("matplotlib")
    from planner.app.animation import animate_plan

    robot = get_robot("dh3")
    request = planner.parse_motion_request({"targets": [{"position": [0.14, 0, -0.04]}, {"position": [0, 0.14, 0.09]}]})
    plan = planner.plan_motion(robot, request)
    assert 0.85 < plan.trajectory.duration < 0.95
    with pytest.raises(planner.InvalidArgumentError, match=message):
        animate_plan(tmp_path / "a.gif", robot, plan, **options)


def test_a_servo_rating_that_makes_an_infinite_speed_is_refused():
    # 1e-320 s per 60 deg returned inf [rad/s] (a limit every check then divides by); a string
    # raised TypeError from math.isfinite.
    with pytest.raises(planner.InvalidLimitsError, match=r"^servo speed 1e-320 s per 60\.0 deg is an infinite joint"):
        planner.servo_speed_to_velocity(1e-320)
    with pytest.raises(planner.InvalidLimitsError, match=r"^servo speed time must be a number \[s\], got 'x'$"):
        planner.servo_speed_to_velocity("x")
    assert planner.servo_speed_to_velocity(0.2) == pytest.approx(np.radians(60) / 0.2)


def test_servo_conversions_refuse_what_is_not_numbers():
    # Each raised NumPy's ValueError ("could not convert string to float") or math's TypeError.
    calibration = planner.ServoCalibration(channel=0)
    cases = [
        (lambda: calibration.pulse("x"), r"angle for joint '' \(channel 0\) must be a number or an array of numbers"),
        (lambda: calibration.angle("x"), r"^pulse must be a number or an array of numbers, got 'x'$"),
        (lambda: planner.angle_to_steps("x", 1.6, 100), r"^angle must be a number or an array of numbers"),
        (lambda: planner.steps_to_angle("x", 1.6, 100), r"^steps must be a number or an array of numbers"),
        (lambda: planner.angle_to_steps(1.0, "x", 100), r"^max_rotation must be a number \[rad\], got 'x'$"),
        (lambda: planner.range_bearing_to_base("x", 0.0, [0, 0, 0]), r"^distance must be a number or an array"),
        (lambda: planner.range_bearing_to_base(1.0, 0.0, "x"), r"^sensor_pose must be a number or an array"),
    ]
    for call, message in cases:
        with pytest.raises(planner.InvalidArgumentError, match=message):
            call()


def test_a_step_count_past_2_to_the_53_is_refused_not_wrapped():
    # 2**70 steps gave angle_to_steps(1.0, 3.14, 2**70) == -9223372036854775808 (int64 wrapped).
    with pytest.raises(planner.InvalidArgumentError, match=r"^max_steps must be an integer in \[1, 2\*\*53\], got"):
        planner.angle_to_steps(1.0, 3.14, 2**70)
    assert planner.angle_to_steps(1.0, 2.0, 2**53) == 2**52


def test_a_wild_pulse_is_shown_in_a_few_digits():
    calibration = planner.ServoCalibration(channel=0, us_per_rad=1e308)
    with pytest.raises(
        planner.InvalidArgumentError, match=r"angle 1 rad needs pulse 1e\+308 us, outside \[500, 2500\]"
    ):
        calibration.pulse(1.0)


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--seed", "-1"], r"the seed must be an integer >= 0 \(NumPy's seeds are\), got -1$"),
        (["--n", "100000000000"], r"the number of targets must be an integer in \[1, 1000000\], got 100000000000$"),
    ],
)
def test_bench_refuses_a_negative_seed_and_a_count_no_memory_holds(capsys, flags, message):
    # --seed -1: NumPy's ValueError (expected non-negative integer); --n 1e11: MemoryError (2 TiB).
    line = cli_error(capsys, "bench", "dh3", *(["--n", "2"] if "--n" not in flags else []), *flags)
    assert re.search("^planner bench: error: " + message, line)


def test_yaml_numbers_in_exponent_notation_read_as_numbers(tmp_path):
    # PyYAML reads YAML 1.1, whose floats need a dot and a signed exponent: "dwell: 2e-1" and
    # "velocity: 1e3" came back as strings and were refused ("must be a number, got '2e-1'").
    path = tmp_path / "plan.yaml"
    path.write_text(
        "waypoints:\n  - {q: [0, 0, 0], dwell: 2e-1}\n  - [1E-1, 0.1, 1.5e-1]\nlimits: {velocity: 1e1, jerk: +2.5E3}\n"
    )
    request = planner.load_motion_request(path)
    np.testing.assert_array_equal(request.dwell, [0.2, 0.0])
    np.testing.assert_array_equal(request.joints[1], [0.1, 0.1, 0.15])
    assert request.limits == {"velocity": 10.0, "jerk": 2500.0}
    path.write_text("waypoints: [[e5, 0, 0], [1e, 0, 0]]\n")  # not numbers: still strings
    with pytest.raises(planner.InvalidArgumentError, match=r"waypoints\[0\]\[0\] must be a number, got 'e5'"):
        planner.load_motion_request(path)


def test_a_target_file_quaternion_means_its_direction_at_any_scale(tmp_path):
    # qx..qw = 1e200 each became the identity (the norm overflowed to inf, the quaternion to 0).
    from planner.app.target_file import read_targets

    path = tmp_path / "targets.csv"
    path.write_text("x,y,z,qx,qy,qz,qw\n0.1,0,0.1,1,1,1,1\n0.1,0,0.1,1e200,1e200,1e200,1e200\n0.1,0,0.1,0,0,0,0\n")
    with pytest.raises(planner.TargetFileError, match="line 4.*zero norm"):
        read_targets(path)
    path.write_text("x,y,z,qx,qy,qz,qw\n0.1,0,0.1,1,1,1,1\n0.1,0,0.1,1e200,1e200,1e200,1e200\n")
    rotations = read_targets(path).rotations
    np.testing.assert_allclose(rotations[1], rotations[0], atol=1e-15)
    np.testing.assert_allclose(rotations[0] @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)


def test_shelley_reaches_the_approach_pitch_of_its_own_configurations():
    # Target(FK(q) position, pitch=approach_pitch(q)) is reached by q (its pitch error is 0), yet
    # shelley's closed form (and "auto") answered orientation_not_achievable for every such target:
    # it asked for the one radial direction, where a pitch leaves the azimuth within the outward
    # half plane to the arm (planner.geometry.target). The NLP solved them all.
    robot = get_robot("shelley")
    solver = planner.closed_form_solver(robot)
    q_all = robot.random_configurations(np.random.default_rng(3), 40)
    positions = robot.fk(q_all)[:, :3, 3]
    pitches = planner.approach_pitch(robot, q_all)
    for position, pitch in zip(positions, pitches):
        for method in ("analytic", "auto"):
            result = planner.solve_ik(robot, planner.Target(position, pitch=pitch), method=method)
            assert result.success, result.reason
            axis = robot.fk(result.q)[:3, :3] @ robot.approach_axis
            assert planner.pitch_error(axis, position, pitch) < 1e-9
            assert np.linalg.norm(robot.fk(result.q)[:3, 3] - position) < 1e-9
    batch = solver.solve_batch(positions, pitch=pitches)
    assert batch.within_limits.any(axis=1).all()
    up = planner.solve_ik(robot, planner.Target(positions[0], pitch=0.5), method="analytic")
    assert up.status == planner.IKStatus.ORIENTATION_NOT_ACHIEVABLE and "stays at 0.00 deg" in up.reason


def _short_trajectory():
    robot = get_robot("al5c")
    limits = planner.JointLimits.from_robot(robot)
    q0 = (limits.lower + limits.upper) / 2
    return planner.plan_trajectory([q0, q0 + 0.2], limits)


def test_a_urdf_file_that_is_not_utf8_is_a_urdf_error(tmp_path):
    # The review: Robot.from_urdf on a file with a stray byte raised UnicodeDecodeError.
    path = tmp_path / "bin.urdf"
    path.write_bytes(b'<robot name="x">\xff</robot>')
    with pytest.raises(planner.URDFError, match="not UTF-8 text.*0xff"):
        planner.Robot.from_urdf(path)


def test_a_urdf_file_with_a_byte_order_mark_loads(tmp_path):
    # Windows editors start UTF-8 files with a byte-order mark; plan files accept one, so do URDFs.
    source = Path(get_robot("al5c").source)
    path = tmp_path / "bom.urdf"
    path.write_bytes(b"\xef\xbb\xbf" + source.read_bytes())
    robot = planner.Robot.from_urdf(path)
    assert robot.dof == get_robot("al5c").dof


def test_trajectory_times_that_are_not_numbers_are_an_invalid_argument():
    traj = _short_trajectory()
    for bad in ("x", [0.1, "y"], {"t": 1}):
        with pytest.raises(planner.InvalidArgumentError, match="time must be a number or an array of numbers"):
            traj.sample(bad)
        with pytest.raises(planner.InvalidArgumentError, match="time must be a number or an array of numbers"):
            traj.positions(bad)


def test_sampling_more_than_max_samples_is_refused_before_allocating():
    # The review: plan_motion(rate=1e7) and long dwells ran out of memory in the samples.
    from planner.motion.trajectory import MAX_SAMPLES

    traj = _short_trajectory()
    assert traj.times(1000.0)[-1] == traj.duration
    rate = 2 * MAX_SAMPLES / traj.duration
    with pytest.raises(planner.InvalidArgumentError, match="samples; at most"):
        traj.times(rate)
    with pytest.raises(planner.InvalidArgumentError, match="samples; at most"):
        traj.sampled(1e300)


def test_to_csv_into_a_folder_is_an_invalid_argument(tmp_path):
    traj = _short_trajectory()
    with pytest.raises(planner.InvalidArgumentError, match="cannot write"):
        traj.to_csv(tmp_path)
    assert traj.to_csv(tmp_path / "t.csv").read_text().startswith("t,")


@pytest.mark.parametrize("dwell", [7001.0, 1e4, 1e308])
def test_a_dwell_longer_than_a_segment_can_last_is_refused(dwell):
    # The review: a dwell of 1e4 s ran out of memory after a minute; 1e308 overflowed.
    limits = planner.JointLimits.from_robot(get_robot("al5c"))
    q0 = (limits.lower + limits.upper) / 2
    with pytest.raises(planner.InvalidArgumentError, match=r"dwell at waypoint 1 is .* at most 7000 s"):
        planner.plan_trajectory([q0, q0 + 0.1, q0], limits, dwell=[0.0, dwell, 0.0])
    assert planner.plan_trajectory([q0, q0 + 0.1, q0], limits, dwell=[0.0, 7000.0, 0.0]).duration > 7000.0


@pytest.mark.parametrize("rate", [True, False])
def test_a_boolean_rate_is_refused_not_read_as_one_hertz(rate):
    from planner.app.plan_file import parse_motion_request

    traj = _short_trajectory()
    for call in (traj.times, traj.sampled, traj.peak_ratios):
        with pytest.raises(planner.InvalidArgumentError, match="rate must be positive and finite"):
            call(rate)
    request = parse_motion_request({"waypoints": [[0.0, 0.5, 1.0], [1.0, 0.5, 1.0]], "units": {"angle": "rad"}})
    with pytest.raises(planner.InvalidArgumentError, match="rate must be positive and finite"):
        planner.plan_motion(get_robot("dh3"), request, rate=rate)
