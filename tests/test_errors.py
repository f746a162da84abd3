"""Bad input raises a clear error from the root PlannerError, with a message that helps."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

import planner

from conftest import get_robot

GOOD = """<robot name="r"><link name="a"/><link name="b"/>
<joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
<limit lower="{lower}" upper="{upper}" effort="1" velocity="{velocity}"/></joint></robot>"""


def make(lower="-1", upper="1", velocity="1") -> str:
    return GOOD.format(lower=lower, upper=upper, velocity=velocity)


def test_every_error_derives_from_planner_error():
    for name in planner.__all__:
        obj = getattr(planner, name)
        if isinstance(obj, type) and issubclass(obj, Exception):
            assert issubclass(obj, planner.PlannerError), name


def test_malformed_urdf_text():
    with pytest.raises(planner.URDFError, match=r"<urdf>: malformed XML: .*line 1"):
        planner.Robot("<robot name='x'><link")


def test_urdf_with_wrong_root_and_dangling_link():
    with pytest.raises(planner.URDFError, match=r"root element is <foo>, a URDF's must be <robot>"):
        planner.Robot("<foo/>")
    dangling = make().replace('<child link="b"/>', '<child link="c"/>')
    with pytest.raises(planner.URDFError, match=r"joint 'j' names child link 'c', which is not defined; links: a, b"):
        planner.Robot(dangling)


def test_urdf_with_lower_above_upper():
    with pytest.raises(planner.InvalidLimitsError, match=r"joint 'j' has lower limit 1 > upper limit -1") as info:
        planner.Robot(make(lower="1", upper="-1"))
    assert info.value.joint == "j"


def test_urdf_with_negative_or_nan_speed():
    with pytest.raises(planner.InvalidLimitsError, match=r"joint 'j' has a negative velocity limit -2"):
        planner.Robot(make(velocity="-2"))
    with pytest.raises(planner.InvalidLimitsError, match=r"joint 'j' lower limit is NaN"):
        planner.Robot(make(lower="nan"))


def test_urdf_file_that_does_not_exist(tmp_path):
    with pytest.raises(planner.URDFError, match=r"cannot read URDF file .*missing.urdf"):
        planner.load_robot(tmp_path / "missing.urdf")


def test_unknown_tip_frame_lists_the_frames():
    message = r"unknown frame 'claw'; valid frames: .*base_link.*hand"
    with pytest.raises(planner.UnknownFrameError, match=message) as info:
        planner.load_robot("dh3", tip="claw")
    assert "hand" in info.value.choices
    with pytest.raises(planner.UnknownFrameError, match=r"unknown frame 'nope'; valid frames: .*gripper"):
        get_robot("al5c").fk(np.zeros(5), frame="nope")


def test_q_of_wrong_length():
    with pytest.raises(
        planner.InvalidConfigurationError,
        match=r"q has shape \(2,\); dh3 expects \(3,\) or \(N, 3\) for joints base_yaw, shoulder, elbow",
    ):
        get_robot("dh3").fk([0.1, 0.2])


def test_nan_in_q_names_the_joint():
    message = r"q holds nan for joint 'shoulder'; values must be finite"
    with pytest.raises(planner.InvalidConfigurationError, match=message):
        get_robot("dh3").fk([0.1, math.nan, 0.2])
    with pytest.raises(planner.InvalidConfigurationError, match=r"q holds inf for joint 'elbow'"):
        get_robot("dh3").jacobian([0.1, 0.2, math.inf])


def test_unknown_robot_name_lists_the_names():
    with pytest.raises(
        planner.UnknownRobotError, match=r"unknown robot 'puma'; valid names: shelley, al5c, three_joint, dh3"
    ) as info:
        planner.load_robot("puma")
    assert info.value.choices[:4] == ("shelley", "al5c", "three_joint", "dh3")


def test_messages_show_plain_numbers():
    import numpy as np

    import planner

    robot = planner.load_robot("dh3")
    cases = [
        lambda: planner.IKOptions(time_budget=np.float64(-1)),
        lambda: planner.ServoCalibration(channel=0, pulse_at_zero=1500.0, us_per_rad=np.float64(-5)),
        lambda: planner.plan_trajectory([[0, 0, 0], [0, 0.1, 0]], planner.JointLimits.from_robot(robot)).sample(
            np.float64(99.0)
        ),
        lambda: planner.servo_speed_to_velocity(np.float64(-0.2)),
    ]
    for case in cases:
        with pytest.raises(planner.PlannerError) as info:
            case()
        assert "np." not in str(info.value) and "float64" not in str(info.value), str(info.value)


# A robot whose tip only fixed joints lead to had no joints: Ruckig divided by zero (SIGFPE, the
# process killed) when asked for its trajectory, and the path search raised ValueError. Such a
# robot is refused, as are limits for no joints. Run apart so a crash fails the test.
_NO_JOINTS = """
import numpy as np, planner
urdf = ('<robot name="r"><link name="base"/><link name="flange"/><link name="arm"/>'
        '<joint name="bolt" type="fixed"><parent link="base"/><child link="flange"/></joint>'
        '<joint name="j" type="revolute"><parent link="flange"/><child link="arm"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>')
try:
    planner.Robot(urdf, tip="flange")
except planner.InvalidArgumentError as exc:
    print("refused:", exc)
try:
    empty = planner.JointLimits(velocity=[], acceleration=[], jerk=[], lower=[], upper=[])
    planner.plan_trajectory(np.zeros((2, 0)), empty)
except planner.InvalidLimitsError as exc:
    print("refused:", exc)
"""


def test_a_tip_no_joint_moves_and_limits_without_joints_are_refused_not_a_crash():
    proc = subprocess.run([sys.executable, "-c", _NO_JOINTS], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    robot, limits = proc.stdout.splitlines()
    assert "no joint moves the tip frame 'flange'" in robot and "arm" in robot
    assert "at least one joint" in limits


# With a scene, plan_motion swept the straight move between joint waypoints (points every
# 0.05 rad) before the timing checked their ranges: a waypoint at 1e9 asked for 2e10 points
# (memory without bound). Run apart under a memory cap so the old behaviour fails, not the machine.
_FAR_WAYPOINT = """
import resource
resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))
import planner
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
robot = planner.load_robot("three_joint")
request = {"waypoints": [[0.0, 1.0, 0.5, 0.5], [1e9] * 4], "scene": {"obstacles": []}}
try:
    plan_motion(robot, parse_motion_request(request))
except planner.JointLimitError as exc:
    print("refused:", exc)
"""


def test_a_waypoint_far_outside_its_range_is_refused_before_the_scene_sweeps_it():
    proc = subprocess.run([sys.executable, "-c", _FAR_WAYPOINT], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "refused: waypoint 1: joint 'yaw' value 1e+09 is outside its range" in proc.stdout


# A continuous joint has no range to refuse a waypoint a million radians away: with a scene,
# plan_motion swept that move (points every 0.05 rad, 2e7 of them) for minutes, and at 1e9 ran
# out of memory. No segment can time such a move (Ruckig plans at most 7e3 s): it is refused
# first, naming the joint. Run apart under a memory cap and a timeout.
_LONG_TURN = """
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))
sys.path.insert(0, {tests!r})
import planner
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
from test_casadi_kinematics import mixed_robot
robot = mixed_robot()
for turn in (1e6, 1e9):
    request = {{
        "limits": {{"velocity": 1.0}},
        "waypoints": [[0.0] * 5, [0.0, turn, 0.0, 0.0, 0.0]],
        "scene": {{"obstacles": [{{"name": "b", "box": [0.01, 0.01, 0.01], "position": [5, 5, 5]}}]}},
    }}
    try:
        plan_motion(robot, parse_motion_request(request))
    except planner.PlanningError as exc:
        print("refused:", exc)
"""


def test_a_move_no_segment_can_time_is_refused_before_the_scene_sweeps_it():
    from pathlib import Path

    code = _LONG_TURN.format(tests=str(Path(__file__).parent))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.splitlines()
    assert len(lines) == 2, proc.stdout
    for line in lines:
        assert line.startswith("refused: waypoint 0 -> waypoint 1: joint ") and "at most 7000 s" in line


def test_plan_trajectory_names_the_joint_of_a_move_longer_than_ruckig_times():
    from planner import PlanningError, load_robot
    from planner.motion.limits import JointLimits
    from planner.motion.plan import plan_trajectory

    robot = load_robot("al5c")
    middle, half = (robot.lower + robot.upper) / 2.0, 0.9 * (robot.upper - robot.lower) / 2.0
    waypoints = np.array([middle - half, middle + half])
    with pytest.raises(PlanningError, match=r"waypoint 0 -> waypoint 1: joint \S+ moves .* at most 7000 s"):
        plan_trajectory(waypoints, JointLimits.from_robot(robot, velocity=1e-4))


@pytest.mark.parametrize("acceleration", [1e-10, 1e-9])
def test_a_first_or_last_move_too_slow_for_its_acceleration_names_the_acceleration(acceleration):
    # Before: "the via states could not be brought within the joint ranges" (Ruckig's -101 deep inside).
    from planner import PlanningError, load_robot
    from planner.motion.limits import JointLimits
    from planner.motion.plan import plan_trajectory

    robot = load_robot("dh3")
    limits = JointLimits.from_robot(robot, acceleration=acceleration)
    waypoints = np.array([[0.0, 0.3, 0.2], [0.4, 0.5, 0.1], [0.1, 0.1, 0.1]])
    with pytest.raises(
        PlanningError, match=r"waypoint 0 -> waypoint 1: joint \S+ moves .* s from rest .* acceleration limit"
    ):
        plan_trajectory(waypoints, limits)
    creep = np.array([[0.0, 0.0, 0.0], [1e-12, 0.0, 0.0], [0.4, 0.0, 0.0]])
    with pytest.raises(
        PlanningError, match=r"waypoint 1 -> waypoint 2: joint base_yaw moves .* s to rest .* acceleration limit"
    ):
        plan_trajectory(creep, limits)
    # Where the bound from rest stays under Ruckig's limit, the plan is made and lasts at least that bound.
    gentle = JointLimits.from_robot(robot, acceleration=1e-6)
    traj = plan_trajectory(waypoints, gentle)
    assert traj.duration >= np.sqrt(2.0 * 0.4 / 1e-6)
