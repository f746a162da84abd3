"""Singularity checks along trajectories and detours around avoidable ones."""

from __future__ import annotations

import re

import numpy as np
import pytest
from dh_arms import property_settings
from hypothesis import given
from hypothesis import strategies as st

from planner import InvalidArgumentError, Robot
from planner.motion.detours import SingularityOptions, plan_clear_of_singularities
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory
from planner.motion.request import TrajectoryRequest
from planner.motion.singularity import check_singularities
from planner.motion.trajectory import LIMIT_TOLERANCE

from conftest import HAVE_EXAMPLE_ROBOT_DATA, get_robot, needs_example_robot_data

THRESHOLD = 1.0 / 30.0


def test_conditioning_matches_the_robot():
    rng = np.random.default_rng(3)
    for name in ("dh3", "al5c", "three_joint", "shelley"):
        robot = get_robot(name)
        q = robot.random_configurations(rng, 20)
        inv, man = robot.conditioning(q)
        np.testing.assert_allclose(inv, robot.inverse_condition_number(q), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(man, robot.manipulability(q), rtol=1e-12, atol=1e-15)


def test_segment_through_a_singularity_gets_a_detour():
    # three_joint's planar part (shoulder, elbow, wrist) is stretched when elbow = wrist = 0:
    # a straight joint move from (+0.5, +0.5) to (-0.5, -0.5) passes right through it, while
    # both ends are well conditioned. The arm is redundant for positions, so a detour exists.
    robot = get_robot("three_joint")
    limits = JointLimits.from_robot(robot)
    q = np.array([[0.0, 1.0, 0.5, 0.5], [0.0, 1.0, -0.5, -0.5]])
    direct = check_singularities(robot, plan_trajectory(q, limits))
    assert direct.singular_waypoints == ()
    assert direct.min_inverse_condition < 1e-3
    assert direct.below_threshold

    plan = plan_clear_of_singularities(robot, TrajectoryRequest(q, limits))
    assert len(plan.detours) >= 1
    assert all(d.segment == 0 and d.inverse_condition >= THRESHOLD for d in plan.detours)
    assert plan.report.clear and plan.report.min_inverse_condition >= THRESHOLD
    assert plan.unresolved == ()
    traj = plan.trajectory
    np.testing.assert_allclose(traj.sample(plan.waypoint_times).q, q, atol=1e-12)
    assert len(traj.waypoints) == 2 + len(plan.detours)
    peaks = traj.peak_ratios(1000.0)
    assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
    assert peaks["position"] <= LIMIT_TOLERANCE


def test_singular_waypoint_is_kept_and_flagged():
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    q = np.array([[0.0, 0.0, 0.0], [0.5, 0.6, 1.2], [1.0, 0.5, 1.0]])  # the first is fully stretched
    plan = plan_clear_of_singularities(robot, TrajectoryRequest(q, limits))
    assert plan.singular_waypoints == (0,)
    assert plan.report.singular_waypoints == (0,)
    assert plan.report.waypoint_inverse_condition[0] == pytest.approx(0.0, abs=1e-12)
    assert plan.detours == ()
    assert plan.report.min_inverse_condition == pytest.approx(0.0, abs=1e-12)
    assert plan.report.time_of_minimum == 0.0
    np.testing.assert_allclose(plan.trajectory.sample(plan.waypoint_times).q, q, atol=1e-12)


def test_crossing_between_sign_changed_ends_is_reported_not_detoured():
    # dh3 is not redundant: elbow-up and elbow-down lie on either side of the stretched
    # configurations (det J changes sign), so every path between them crosses a singularity.
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    q = np.array([[0.0, 0.3, 0.6], [0.0, 0.6, -0.6]])
    inv_ends = robot.conditioning(q)[0]
    assert np.all(inv_ends > THRESHOLD)
    plan = plan_clear_of_singularities(robot, TrajectoryRequest(q, limits))
    assert plan.detours == ()
    assert plan.unresolved == (0,)
    assert plan.report.min_inverse_condition < THRESHOLD


def test_report_intervals_and_rate():
    robot = get_robot("three_joint")
    limits = JointLimits.from_robot(robot)
    traj = plan_trajectory([[0.0, 1.0, 0.5, 0.5], [0.0, 1.0, -0.5, -0.5]], limits)
    report = check_singularities(robot, traj, rate=200.0)
    assert len(report.below_threshold) == 1
    start, end = report.below_threshold[0]
    assert 0 < start < report.time_of_minimum < end < traj.duration
    assert report.rate == 200.0 and report.task == "position"


@pytest.mark.parametrize("threshold", [-0.1, 1.0, float("nan")])
def test_bad_threshold(threshold):
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    traj = plan_trajectory([[0, 0.5, 1], [0.5, 0.5, 1]], limits)
    with pytest.raises(InvalidArgumentError, match=r"threshold is an inverse condition number in \[0, 1\)"):
        check_singularities(robot, traj, threshold=threshold)


def test_mismatched_robot():
    limits = JointLimits.from_robot(get_robot("dh3"))
    traj = plan_trajectory([[0, 0.5, 1], [0.5, 0.5, 1]], limits)
    with pytest.raises(InvalidArgumentError, match="the trajectory has 3 joints; three_joint has 4"):
        check_singularities(get_robot("three_joint"), traj)
    with pytest.raises(InvalidArgumentError, match="the limits are for 3 joints; three_joint has 4"):
        plan_clear_of_singularities(get_robot("three_joint"), TrajectoryRequest([[0, 0.5, 1], [0.5, 0.5, 1]], limits))


def test_options_and_kept_segments():
    with pytest.raises(InvalidArgumentError, match="max_detours must be a non-negative integer, got -1"):
        SingularityOptions(max_detours=-1)
    with pytest.raises(InvalidArgumentError, match="margin must be >= 1, got 0.5"):
        SingularityOptions(margin=0.5)
    with pytest.raises(InvalidArgumentError, match=r"threshold is an inverse condition number in \[0, 1\)"):
        SingularityOptions(threshold=1.5)
    assert SingularityOptions(threshold=0.05).threshold == 0.05
    assert SingularityOptions().threshold is None  # the task's default, resolved with the robot
    robot = get_robot("three_joint")
    request = TrajectoryRequest([[0.0, 1.0, 0.5, 0.5], [0.0, 1.0, -0.5, -0.5]], JointLimits.from_robot(robot))
    # A kept segment (say, samples of a Cartesian line) gets no detour and is reported.
    kept = plan_clear_of_singularities(robot, request, keep_segments=[0])
    assert kept.detours == () and kept.unresolved == (0,)
    assert kept.report.threshold == pytest.approx(THRESHOLD) and kept.report.task == "position"
    none = plan_clear_of_singularities(robot, request, SingularityOptions(max_detours=0))
    assert none.detours == () and none.trajectory.duration == kept.trajectory.duration


@st.composite
def _elbow_crossing_paths(draw, alternate: bool) -> np.ndarray:
    """dh3 joint waypoints (2-6) whose elbow angle q3 changes sign on every segment (alternate)
    or at random; |q3| >= 0.1 rad, so the waypoints themselves are clear of the stretched arm."""
    robot = get_robot("dh3")
    n = draw(st.integers(2, 6))
    rows = []
    for k in range(n):
        q = [draw(st.floats(float(lo), float(hi))) for lo, hi in zip(robot.lower[:2], robot.upper[:2])]
        elbow = draw(st.floats(0.1, float(min(-robot.lower[2], robot.upper[2]))))
        sign = (1 if k % 2 == 0 else -1) if alternate else draw(st.sampled_from([-1, 1]))
        rows.append([*q, sign * elbow])
    return np.array(rows)


def _detoured_segments_clear(robot, plan, threshold: float) -> bool:
    """Independently of the plan's report: every user segment with a detour stays >= threshold."""
    traj, times = plan.trajectory, plan.waypoint_times
    for k in {d.segment for d in plan.detours}:
        t = np.linspace(times[k], times[k + 1], 400)
        if float(np.min(robot.conditioning(traj.sample(t).q)[0])) < threshold:
            return False
    return True


def _check_not_slower_than_resting(q: np.ndarray) -> None:
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    plan = plan_clear_of_singularities(robot, TrajectoryRequest(q, limits))
    rest = plan_trajectory(q, limits, strategy="stop")
    assert not {d.segment for d in plan.detours} & set(plan.unresolved)
    if plan.trajectory.duration > rest.duration * (1 + 1e-9):
        # Slower than resting at every waypoint only for detours that keep the arm clear.
        assert plan.detours and _detoured_segments_clear(robot, plan, THRESHOLD)


@property_settings(20)
@given(q=_elbow_crossing_paths(alternate=True))
def test_no_plan_is_slower_than_resting_at_every_waypoint_unless_its_detours_clear(q):
    _check_not_slower_than_resting(q)


@pytest.mark.slow
@property_settings(150)
@given(q=st.one_of(_elbow_crossing_paths(alternate=True), _elbow_crossing_paths(alternate=False)))
def test_no_plan_is_slower_than_resting_at_every_waypoint_unless_its_detours_clear_many(q):
    _check_not_slower_than_resting(q)


def test_a_detour_across_a_singularity_from_its_segment_is_not_planned(monkeypatch):
    # The stretched elbow lies between these (q3 changes sign) but det J keeps its sign (the
    # shoulder factor changes sign too); the ascent from the dip ends where det J has the
    # other sign, so a detour there would cross a singularity on either side: not planned.
    import planner.motion.detours as detours_module

    calls, ascents = [], []
    plan_request, ascend = detours_module.plan_trajectory_request, detours_module._ascend
    monkeypatch.setattr(detours_module, "plan_trajectory_request", lambda r: calls.append(r) or plan_request(r))
    monkeypatch.setattr(detours_module, "_ascend", lambda *a, **k: ascents.append(ascend(*a, **k)) or ascents[-1])
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    q = np.array([[0.925, -0.977, 2.349], [2.231, -0.95, -0.877]])
    minimum = 2 * plan_trajectory(q, limits).duration
    plan = plan_clear_of_singularities(robot, TrajectoryRequest(q, limits, min_durations=[minimum]))
    sign = [np.sign(np.linalg.det(robot.jacobian(x)[:3])) for x in (q[0], q[1], ascents[0][0])]
    assert sign[0] == sign[1] == -sign[2] != 0.0 and ascents[0][1] >= plan.report.threshold
    assert len(calls) == 1 and plan.detours == () and plan.unresolved == (0,)
    assert not plan.report.clear


def test_detours_taken_out_again_give_the_segment_its_minimum_duration_back(monkeypatch):
    # A dip between these that the detours tried (on the ends' side of the singularities) do not
    # clear: they are removed again.
    import planner.motion.detours as detours_module

    calls = []
    plan_request = detours_module.plan_trajectory_request
    monkeypatch.setattr(detours_module, "plan_trajectory_request", lambda r: calls.append(r) or plan_request(r))
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    q = np.array([[2.169, -0.459, -0.955], [1.619, -1.752, 1.09]])
    minimum = 2 * plan_trajectory(q, limits).duration
    plan = plan_clear_of_singularities(robot, TrajectoryRequest(q, limits, min_durations=[minimum]))
    assert len(calls) >= 2 and len(calls[-1].waypoints) > 2  # detours were planned, then taken out
    assert plan.detours == () and plan.unresolved == (0,)
    assert len(plan.trajectory.waypoints) == 2
    # Back to the first plan's nodes and states: that plan, not planned again.
    again = plan_request(calls[0])
    assert np.array_equal(plan.trajectory.waypoint_times, again.waypoint_times)
    assert plan.trajectory.duration == again.duration
    assert plan.trajectory.duration >= minimum * (1 - 1e-9)


# ------------------------------------------------------------------ the measure on 6- and 7-joint arms
POSE_THRESHOLD = 0.01  # DEFAULT_CONDITION_NUMBERS["pose"] = 100
UR5_A2, UR5_A3, UR5_D5 = 0.425, 0.39225, 0.09465  # UR5 DH lengths [m]
UR5_HOME = (0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0)


def _raw_inverse_condition(robot, q) -> float:
    """Smallest over largest singular value of the raw Jacobian: 0 exactly where it loses rank."""
    s = np.linalg.svd(robot.jacobian(q), compute_uv=False)[: min(6, robot.dof)]
    return float(s[-1] / s[0])


def _ur5_shoulder(q) -> tuple[float, np.ndarray]:
    """The UR shoulder factor of det J = -a2 a3 sin(q3) sin(q5) s(q) [m] and its gradient [m/rad]."""
    q2, q23, q234 = q[1], q[1] + q[2], q[1] + q[2] + q[3]
    s = UR5_A2 * np.cos(q2) + UR5_A3 * np.cos(q23) - UR5_D5 * np.sin(q234)
    d4 = -UR5_D5 * np.cos(q234)
    d3 = -UR5_A3 * np.sin(q23) + d4
    d2 = -UR5_A2 * np.sin(q2) + d3
    return float(s), np.array([0.0, d2, d3, d4, 0.0, 0.0])


def _ur5_shoulder_pose() -> np.ndarray:
    # From the home pose (q3 = pi/2, q4 = -pi/2) s = a2 cos q2 - (a3 + d5) sin q2.
    q = np.array(UR5_HOME)
    q[1] = np.arctan2(UR5_A2, UR5_A3 + UR5_D5) - np.pi
    return q


def _z1_shoulder_pose() -> np.ndarray:
    """z1 with the meeting point of its wrist axes 5 and 6 on the base axis (q2 by bisection)."""
    robot = get_robot("z1")
    base = np.array([0.3, 1.0, -1.2, 0.3, 0.4, 0.5])

    def radial(q2: float) -> float:  # signed distance of joint 5's origin from the base axis along x
        q = base.copy()
        q[1] = q2
        return float(robot.joint_positions(q)[5][0])

    lo, hi = 0.6, 1.4
    assert radial(lo) * radial(hi) < 0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if radial(lo) * radial(mid) > 0 else (lo, mid)
    q = base.copy()
    q[1] = 0.5 * (lo + hi)
    return q


@needs_example_robot_data
def test_measure_of_a_6_joint_arm_does_not_depend_on_its_size():
    # The same UR5 with every length times 10 (or in decimetres): equal measure, equal flags.
    robot = get_robot("ur5")
    scaled_text = re.sub(
        r'xyz="([^"]+)"', lambda m: 'xyz="' + " ".join(str(10 * float(v)) for v in m.group(1).split()) + '"', robot.urdf
    )
    scaled = Robot(scaled_text, tip=robot.tip, validate=False)
    assert scaled.characteristic_length == pytest.approx(10 * robot.characteristic_length, rel=1e-12)
    q = robot.random_configurations(np.random.default_rng(5), 50)
    np.testing.assert_allclose(scaled.conditioning(q)[0], robot.conditioning(q)[0], rtol=1e-9, atol=1e-12)
    raw = np.array([_raw_inverse_condition(robot, row) for row in q])
    raw_scaled = np.array([_raw_inverse_condition(scaled, row) for row in q])
    assert np.max(np.abs(raw_scaled - raw)) > 0.05  # the raw [v; omega] ratio does depend on it


@needs_example_robot_data
@pytest.mark.parametrize(("name", "task"), [("ur5", "pose"), ("panda", "pose"), ("so101", "pose"), ("ur5", "position")])
def test_manipulability_stays_yoshikawas_on_the_raw_jacobian(name, task):
    robot = get_robot(name)
    q = robot.random_configurations(np.random.default_rng(6), 10)
    rows = slice(0, 3) if task == "position" else slice(0, 6)
    expected = [np.prod(np.linalg.svd(robot.jacobian(row)[rows], compute_uv=False)) for row in q]
    np.testing.assert_allclose(robot.conditioning(q, task)[1], expected, rtol=1e-9)


@pytest.mark.parametrize("name", ["dh3", "three_joint", "al5c", "shelley"])
def test_position_measure_of_the_seed_arms_is_the_raw_ratio(name):
    robot = get_robot(name)
    q = robot.random_configurations(np.random.default_rng(2), 20)
    raw = []
    for row in q:
        s = np.linalg.svd(robot.jacobian(row)[:3], compute_uv=False)[: min(3, robot.dof)]
        raw.append(s[-1] / s[0])
    np.testing.assert_allclose(robot.conditioning(q)[0], raw, rtol=1e-12, atol=1e-15)
    # The arm's length: base-to-tip sum of the distances between joint origins, at any q.
    for row in q[:3]:
        points = robot.joint_positions(row)[1:]
        assert robot.characteristic_length == pytest.approx(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))


def _singular_poses():
    wrist = np.array(UR5_HOME)
    wrist[4] = 0.0  # axes of joints 4 and 6 parallel
    elbow = np.array(UR5_HOME)
    elbow[2] = 0.0  # upper arm and forearm in line
    panda = np.array([0.0, 0.0, np.pi / 2, -1.5, 0.0, 1.5, 0.0])  # q2 = 0: joints 1 and 3 on one axis, q5 = 0
    panda_b = np.array([0.7, 0.0, -np.pi / 2, -2.2, 0.0, 2.5, -1.0])
    return [
        ("ur5", "wrist", wrist, 4),
        ("ur5", "elbow", elbow, 2),
        ("ur5", "shoulder", None, 1),
        ("panda", "shoulder", panda, 1),
        ("panda", "shoulder", panda_b, 4),
        ("z1", "shoulder", None, 1),
    ]


@needs_example_robot_data
@pytest.mark.parametrize(("name", "kind", "q", "joint"), _singular_poses())
def test_known_singular_poses_and_their_neighbourhood_are_flagged(name, kind, q, joint):
    robot = get_robot(name)
    if q is None:
        q = _ur5_shoulder_pose() if name == "ur5" else _z1_shoulder_pose()
    if name == "ur5" and kind == "shoulder":
        assert _ur5_shoulder(q)[0] == pytest.approx(0.0, abs=1e-12)
    assert _raw_inverse_condition(robot, q) < 1e-9  # the Jacobian really loses rank there
    assert robot.conditioning(q)[0] < 1e-9
    for step in (-0.02, 0.02):  # about one degree away: still flagged
        near = q.copy()
        near[joint] += step
        assert robot.conditioning(near)[0] < POSE_THRESHOLD, (kind, step)
    plan = check_singularities(robot, plan_trajectory([q, q + 0.3], JointLimits.from_robot(robot)))
    assert plan.threshold == pytest.approx(POSE_THRESHOLD) and plan.task == "pose"
    assert plan.singular_waypoints == (0,)


@needs_example_robot_data
@pytest.mark.parametrize(
    ("name", "q"),
    [
        ("ur5", UR5_HOME),
        ("ur5", (0.3, -1.2, 1.5, -1.9, -1.4, 0.2)),
        ("panda", (0.0, -np.pi / 4, 0.0, -3 * np.pi / 4, 0.0, np.pi / 2, np.pi / 4)),  # its "ready" pose
        ("panda", (0.5, 0.3, -0.4, -2.0, 0.6, 1.8, 0.0)),
        ("z1", (0.0, 1.5, -1.5, 0.0, 0.0, 0.0)),
        ("z1", (0.3, 1.2, -1.8, 0.5, 0.0, 0.0)),
    ],
)
def test_regular_poses_are_not_flagged(name, q):
    robot = get_robot(name)
    assert robot.conditioning(np.array(q))[0] > 3 * POSE_THRESHOLD


@needs_example_robot_data
def test_ur5_flags_only_configurations_near_its_singularities():
    # UR5 is singular where sin(q3) = 0 (elbow), sin(q5) = 0 (wrist) or the shoulder factor
    # s(q) = 0; the joint-space distance to each set: |q3|, |q5| modulo pi, |s| / |grad s|.
    robot = get_robot("ur5")
    q = robot.random_configurations(np.random.default_rng(7), 600)
    inverse = robot.conditioning(q)[0]
    shoulder = np.array([abs(s) / np.linalg.norm(g) for s, g in map(_ur5_shoulder, q)])
    modulo_pi = np.abs((q + np.pi / 2) % np.pi - np.pi / 2)
    distance = np.minimum.reduce([modulo_pi[:, 2], modulo_pi[:, 4], shoulder])
    flagged = inverse < POSE_THRESHOLD
    assert np.all(distance[flagged] < 0.3)  # flagged: within 17 degrees of a singularity
    assert np.all(flagged[distance < 0.02])  # within about a degree: flagged
    assert flagged.mean() < 0.3  # the raw measure at 1/30 flagged about half


_SLIDER = """<robot name="slider">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="tip"/>
  <joint name="yaw" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="pitch" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 0.05"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="slide" type="prismatic"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.2 0 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.3" effort="1" velocity="0.1"/></joint>
  <joint name="fixed_tip" type="fixed"><parent link="l3"/><child link="tip"/><origin xyz="0.05 0 0"/></joint>
</robot>"""


@pytest.mark.parametrize("task", ["position", "pose"])
def test_measure_with_a_prismatic_joint_does_not_depend_on_the_unit_of_length(task):
    # The same arm in decimetres (lengths and the slide's travel times 10): the same measure.
    robot = Robot(_SLIDER, tip="tip", validate=False)
    text = re.sub(r'(xyz|lower|upper)="([^"]+)"', lambda m: f'{m[1]}="{_times_ten(m[2], m[1])}"', _SLIDER)
    decimetres = Robot(text, tip="tip", validate=False)
    assert robot.characteristic_length == pytest.approx(0.3)  # 0.05 + 0.2 + 0.05 at q = 0
    assert decimetres.characteristic_length == pytest.approx(3.0)
    q = robot.random_configurations(np.random.default_rng(4), 30)
    q10 = q * np.array([1.0, 1.0, 10.0])
    np.testing.assert_allclose(decimetres.conditioning(q10, task)[0], robot.conditioning(q, task)[0], rtol=1e-9)


def _times_ten(text: str, key: str) -> str:
    if key == "xyz":
        return " ".join(str(10 * float(v)) for v in text.split())
    value = float(text)
    return str(10 * value) if value in (0.0, 0.3) else text  # only the slide's limits are lengths


@needs_example_robot_data
def test_default_thresholds_follow_the_task():
    from planner.motion.branch_choice import TargetSolver

    assert TargetSolver(get_robot("ur5")).threshold == pytest.approx(POSE_THRESHOLD)
    assert TargetSolver(get_robot("dh3")).threshold == pytest.approx(THRESHOLD)
    assert TargetSolver(get_robot("ur5"), task="position").threshold == pytest.approx(THRESHOLD)
    ur5 = get_robot("ur5")
    with pytest.raises(InvalidArgumentError, match=r"a condition number of 100 is 0.01\)"):
        check_singularities(ur5, plan_trajectory([UR5_HOME, UR5_HOME], JointLimits.from_robot(ur5)), threshold=2)


def _ascend_one_by_one(robot, q, limits, target, task, clear=0.0):
    """The detour ascent as first written: the probes and each candidate measured apart."""
    lo = np.where(np.isfinite(limits.lower), limits.lower, -np.inf)
    hi = np.where(np.isfinite(limits.upper), limits.upper, np.inf)
    inset = 1e-3 * np.where(np.isfinite(hi - lo), hi - lo, 1.0)
    lo, hi = lo + inset, hi - inset
    x = np.clip(q, lo, hi)
    f = float(robot.conditioning(x, task)[0])
    step, h = 0.05, 1e-5
    since_clear = 0
    for _ in range(200):
        if f >= target or since_clear >= 30:
            break
        if f >= clear:
            since_clear += 1
        probes = x + np.diag(np.where(x + h <= hi, h, -h))
        grad = np.array([float(robot.conditioning(p, task)[0]) - f for p in probes]) / (probes.diagonal() - x)
        norm = float(np.linalg.norm(grad))
        if norm == 0.0 or not np.isfinite(norm):
            break
        cand = np.clip(x + step * grad / norm, lo, hi)
        fc = float(robot.conditioning(cand, task)[0])
        if fc > f:
            x, f = cand, fc
            step = min(step * 1.5, 0.5)
        else:
            step *= 0.5
            if step < 1e-6:
                break
    return x, f


def _detour_cases():
    yield "three_joint", np.array([[0.0, 1.0, 0.5, 0.5], [0.0, 1.0, -0.5, -0.5]])
    rng = np.random.default_rng(5)
    for name in ("dh3", "al5c"):
        yield name, get_robot(name).random_configurations(rng, 4)
    if HAVE_EXAMPLE_ROBOT_DATA:  # the 5th and 6th of these panda moves get a detour each
        pairs = get_robot("panda").random_configurations(np.random.default_rng(7), 12).reshape(6, 2, 7)
        yield "panda", pairs[4]
        yield "panda", pairs[5]


def test_detours_equal_those_of_the_one_by_one_ascent(monkeypatch):
    # The ascent measures each candidate with the probes around it in one batch, and keeps the
    # gradient after a loss: the same steps, so the same detours, bit for bit.
    import planner.motion.detours as detours_module

    cases = list(_detour_cases())
    plans = [
        plan_clear_of_singularities(get_robot(n), TrajectoryRequest(q, JointLimits.from_robot(get_robot(n))))
        for n, q in cases
    ]
    monkeypatch.setattr(detours_module, "_ascend", _ascend_one_by_one)
    detoured = 0
    for (name, q), plan in zip(cases, plans):
        robot = get_robot(name)
        want = plan_clear_of_singularities(robot, TrajectoryRequest(q, JointLimits.from_robot(robot)))
        assert len(plan.detours) == len(want.detours), name
        for got, ref in zip(plan.detours, want.detours):
            assert np.array_equal(got.q, ref.q) and got.inverse_condition == ref.inverse_condition
        assert np.array_equal(plan.trajectory.waypoints, want.trajectory.waypoints)
        assert plan.report.min_inverse_condition == want.report.min_inverse_condition
        detoured += len(plan.detours)
    assert detoured >= (4 if HAVE_EXAMPLE_ROBOT_DATA else 2)


@needs_example_robot_data
def test_a_segment_whose_dip_a_detour_only_moves_along_is_given_up(monkeypatch):
    # This panda move dips near its goal; a detour clears the first stretch and the dip reappears
    # after it as deep: the segment is given up after that one detour (before, detours went on
    # until max_detours, each pushing the dip further, and were all taken out in the end).
    import planner.motion.detours as detours_module

    robot = get_robot("panda")
    q = np.array(
        [[-2.86, 0.961, 2.771, -1.301, -1.045, 0.689, 1.0], [-1.767, 0.274, 0.592, -0.183, -2.479, 1.867, 1.414]]
    )
    request = TrajectoryRequest(q, JointLimits.from_robot(robot))
    ascents = []
    ascend = detours_module._ascend
    monkeypatch.setattr(detours_module, "_ascend", lambda *a: ascents.append(1) or ascend(*a))
    plan = plan_clear_of_singularities(robot, request)
    assert len(ascents) == 1
    assert plan.detours == () and plan.unresolved == (0,)
    assert plan.report.min_inverse_condition < POSE_THRESHOLD / 10
    # The plan without detours, as when they are switched off.
    none = plan_clear_of_singularities(robot, request, SingularityOptions(max_detours=0))
    assert np.array_equal(plan.trajectory.waypoints, none.trajectory.waypoints)
    assert plan.trajectory.duration == none.trajectory.duration
