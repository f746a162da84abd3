"""Cartesian targets: IK branch choice, and straight-line segments timed within the joint limits."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import planner
from planner import InvalidArgumentError, Target, rotation_error, rpy_to_matrix
from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
from planner.motion.branch_choice import TargetSolver
from planner.motion.limits import JointLimits
from planner.motion.line import line_deviation, line_waypoints, slerp
from planner.motion.line_timing import line_trajectory, time_line
from planner.motion.trajectory import LIMIT_TOLERANCE

from conftest import get_robot, needs_example_robot_data


def assert_within_limits(traj):
    peaks = traj.peak_ratios(1000.0)
    assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
    assert peaks["position"] <= LIMIT_TOLERANCE


def assert_within_limits_sampled_and_exact(traj):
    # 1 kHz samples, and the piecewise polynomials at every knot and interior extremum.
    for peaks in (traj.peak_ratios(1000.0), traj.peak_ratios(None)):
        assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
        assert peaks["position"] <= LIMIT_TOLERANCE


def test_branch_nearest_the_previous_configuration():
    robot = get_robot("dh3")
    solver = TargetSolver(robot)
    target = Target([0.14, 0.0, -0.04])
    up = solver.choose(target, np.radians([0, 10, 50]))
    down = solver.choose(target, np.radians([0, -60, -50]))
    assert up.branch == "front/elbow-up" and down.branch == "front/elbow-down"
    for choice in (up, down):
        np.testing.assert_allclose(robot.position(choice.q), target.position, atol=1e-12)
        assert not choice.singular and choice.alternatives >= 1


def test_singular_solution_only_when_nothing_clear_exists():
    robot = get_robot("dh3")
    choice = TargetSolver(robot).choose(Target([0.17, 0.0, 0.03]), None)
    assert choice.singular and choice.inverse_condition == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(InvalidArgumentError, match="has no IK solution within the joint limits of dh3"):
        TargetSolver(robot).choose(Target([0.3, 0.0, 0.03]), None)


def test_line_segment_stays_on_the_line_within_limits():
    robot = get_robot("dh3")
    request = parse_motion_request(
        {"units": {"length": "cm"}, "targets": [{"position": [11, 0, 9]}, {"position": [0, 11, 9], "line": True}]}
    )
    plan = plan_motion(robot, request)
    assert plan.branches[1] == "line"
    assert plan.line_deviation[0] < 2e-4  # [m]
    traj = plan.trajectory
    assert_within_limits(traj)
    np.testing.assert_allclose(robot.position(plan.waypoints), [[0.11, 0, 0.09], [0, 0.11, 0.09]], atol=1e-9)
    # Every sample of the motion lies near the straight line.
    q = traj.sampled(500.0).q
    assert line_deviation(robot, q, np.array([0.11, 0, 0.09]), np.array([0, 0.11, 0.09])) < 2e-4


def test_line_slows_down_approaching_a_singularity():
    # The line ends where the arm is fully stretched: the elbow must turn ever faster per metre,
    # so the tip slows down instead of the joints exceeding their speed.
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    solver = TargetSolver(robot)
    start, end = Target([0.14, 0.0, -0.04]), Target([0.17, 0.0, 0.03])
    path = line_waypoints(solver, start, end, solver.choose(start, None).q)
    assert path.min_inverse_condition == pytest.approx(0.0, abs=1e-9)
    timing = time_line(path, limits)
    assert np.all(np.abs(timing.velocity) <= limits.velocity + 1e-12)
    # Tip speed along the line from the sample times: slow over the last millimetre.
    ds = np.linalg.norm(np.diff(path.points, axis=0), axis=1)
    speed = ds / np.maximum(np.diff(timing.t), 1e-15)
    s_mid = (path.s[:-1] + path.s[1:]) / 2
    near_end = speed[s_mid > 1 - 0.001 / np.linalg.norm(end.position - start.position)]
    assert near_end.max() < 0.3 * speed.max()
    request = parse_motion_request(
        {"targets": [{"position": [0.14, 0, -0.04]}, {"position": [0.17, 0, 0.03], "line": True}]}
    )
    plan = plan_motion(robot, request)
    assert_within_limits(plan.trajectory)
    assert plan.singular_waypoints == (1,)
    assert plan.line_deviation[0] < 2e-4


def test_line_past_a_singularity_slows_down_only_near_it():
    # The line passes 5 mm from dh3's base axis: there the yaw joint moves the tip by only 5 mm
    # per radian (the position Jacobian nearly loses rank) and must swing through most of its
    # travel over a few millimetres of line. A uniform profile is set by the worst stretch for
    # the whole line; the local one is fast elsewhere and slows down only near the axis.
    robot = get_robot("dh3")
    limits = JointLimits.from_robot(robot)
    solver = TargetSolver(robot)
    a, b = np.array([0.005, -0.06, 0.13]), np.array([0.005, 0.06, 0.13])
    start = Target(a)
    path = line_waypoints(solver, start, Target(b), solver.choose(start, None).q)
    assert path.min_inverse_condition < 0.05  # condition number > 20 near the axis
    local, uniform = time_line(path, limits), time_line(path, limits, local=False)
    assert len(local.zones) > 1 and len(uniform.zones) == 1
    # The speed limit of the path parameter varies along the line, and the local profile uses it.
    assert local.speed_limit.max() > 3 * local.speed_limit.min()
    assert local.path_velocity.max() > 1.5 * uniform.path_velocity.max()
    fast, slow = line_trajectory(path, limits, local), line_trajectory(path, limits, uniform)
    for traj, timing in ((fast, local), (slow, uniform)):
        # The joints keep the timing (every sample passed exactly, at its planned time) ...
        np.testing.assert_allclose(traj.waypoint_times, timing.t, rtol=0, atol=1e-9)
        np.testing.assert_allclose(traj.sample(traj.waypoint_times).q, path.q, rtol=0, atol=1e-12)
        # ... within every limit at every 1 kHz sample, and on the line.
        assert_within_limits_sampled_and_exact(traj)
        assert line_deviation(robot, traj.sampled(1000.0).q, a, b) < 1e-4
    assert fast.duration < 0.8 * slow.duration
    # Tip speed from FK of the 1 kHz samples: it dips where the line passes the axis.
    q = fast.sampled(1000.0).q
    tip = robot.position(q)
    speed = np.linalg.norm(np.diff(tip, axis=0), axis=1) * 1000.0
    y = (tip[:-1, 1] + tip[1:, 1]) / 2.0
    assert speed[np.abs(y) < 0.002].max() < 0.25 * speed.max()
    assert speed[np.abs(y) > 0.02].max() > 0.9 * speed.max()
    # The timing's own tip speed shows the same dip.
    nearest = int(np.argmin(np.abs(path.points[:, 1])))
    assert local.tip_speed[nearest] < 0.25 * local.tip_speed.max()


@pytest.mark.parametrize(("name", "seed"), [("dh3", 1), ("dh3", 2), ("al5c", 3), ("shelley", 4)])
def test_random_lines_keep_their_timing_within_the_limits(name, seed):
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    solver = TargetSolver(robot)
    rng = np.random.default_rng(seed)
    done = 0
    while done < 3:
        qa, qb = robot.random_configurations(rng, 2)
        pa, pb = robot.position(qa), robot.position(qb)
        start, end = (Target(pa, pitch=-0.5), Target(pb, pitch=-0.5)) if name == "al5c" else (Target(pa), Target(pb))
        try:
            path = line_waypoints(solver, start, end, solver.choose(start, None).q)
        except InvalidArgumentError:  # the line leaves the workspace
            continue
        local, uniform = time_line(path, limits), time_line(path, limits, local=False)
        assert local.t[-1] <= uniform.t[-1] * (1 + 1e-12)
        traj = line_trajectory(path, limits, local)
        np.testing.assert_allclose(traj.waypoint_times, local.t, rtol=0, atol=1e-9)
        assert_within_limits_sampled_and_exact(traj)
        assert np.all(np.abs(local.velocity) <= limits.velocity)
        assert line_deviation(robot, traj.sampled(1000.0).q, pa, pb) < 1e-3
        done += 1


def test_line_leaving_the_workspace_is_an_error():
    robot = get_robot("dh3")
    request = parse_motion_request(
        {
            "targets": [
                {"position": [0.16, 0.0, 0.03]},
                {"position": [0.0, 0.16, 0.03]},
                {"position": [0.0, 0.15, 0.08], "line": True},
            ]
        }
    )
    plan_motion(robot, request)  # reachable along the line
    bad = parse_motion_request(
        {"targets": [{"position": [0.0, -0.16, 0.03]}, {"position": [0.0, 0.16, 0.03], "line": True}]}
    )
    with pytest.raises(InvalidArgumentError, match="straight line from .* leaves what dh3 can reach"):
        plan_motion(robot, bad)


def test_pitch_targets_on_al5c():
    robot = get_robot("al5c")
    request = parse_motion_request(
        {
            "units": {"angle": "deg"},
            "targets": [
                {"position": [0.2, 0.0, 0.1], "pitch": -90},
                {"position": [0.2, 0.1, 0.1], "pitch": -90, "line": True},
                {"position": [0.15, -0.1, 0.15], "pitch": 0},
            ],
        }
    )
    plan = plan_motion(robot, request)
    assert_within_limits(plan.trajectory)
    np.testing.assert_allclose(
        robot.position(plan.waypoints), [[0.2, 0, 0.1], [0.2, 0.1, 0.1], [0.15, -0.1, 0.15]], atol=1e-9
    )
    assert plan.branches[1] == "line" and plan.branches[0] is not None
    assert plan.line_deviation[0] < 2e-4


@needs_example_robot_data
def test_pose_targets_through_the_nlp_on_ur5():
    robot = get_robot("ur5")
    q = np.array([[0.1, -1.0, 1.2, -0.5, 0.3, 0.2], [0.5, -1.2, 1.0, -0.3, 0.6, 0.1], [0.9, -0.8, 1.4, -0.9, 0.2, 0.5]])
    poses = robot.fk(q)
    targets = [{"position": p[:3, 3].tolist(), "quaternion": _quaternion(p[:3, :3])} for p in poses]
    targets[2]["line"] = True
    plan = plan_motion(robot, parse_motion_request({"targets": targets, "start": {"q": q[0].tolist()}}))
    assert plan.branches == ("nlp", "nlp", "line")
    reached = robot.fk(plan.waypoints)
    np.testing.assert_allclose(reached[:, :3, 3], poses[:, :3, 3], atol=1e-6)
    assert np.all(rotation_error(reached[:, :3, :3], poses[:, :3, :3]) < 1e-6)
    assert_within_limits(plan.trajectory)
    assert plan.line_deviation[1] < 1e-3


def _quaternion(rot: np.ndarray) -> list[float]:
    """(x, y, z, w) of a rotation matrix (w > 0 branch is enough for these poses)."""
    w = np.sqrt(max(1.0 + np.trace(rot), 1e-12)) / 2.0
    return [(rot[2, 1] - rot[1, 2]) / (4 * w), (rot[0, 2] - rot[2, 0]) / (4 * w), (rot[1, 0] - rot[0, 1]) / (4 * w), w]


def test_slerp_interpolates_about_the_relative_axis():
    rng = np.random.default_rng(5)
    for _ in range(50):
        ra = rpy_to_matrix(rng.uniform(-3, 3, 3))
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = rng.uniform(1e-6, np.pi - 1e-3)
        rb = ra @ pin.exp3(axis * angle)
        np.testing.assert_allclose(slerp(ra, rb, 0.0), ra, atol=1e-15)
        np.testing.assert_allclose(slerp(ra, rb, 1.0), rb, atol=1e-12)
        for s in (0.25, 0.5, 0.8):
            # The rotation s of the way lies at angle s * angle from ra and the rest from rb.
            mid = slerp(ra, rb, s)
            assert rotation_error(ra, mid) == pytest.approx(s * angle, abs=1e-9)
            assert rotation_error(mid, rb) == pytest.approx((1 - s) * angle, abs=1e-9)


def _jerk_sign_changes(traj, t0: float, t1: float, limits) -> list[int]:
    """Per joint, how often the sampled jerk changes sign (|jerk| above 1 % of its limit)."""
    s = traj.sample(np.arange(t0, t1, 1e-3))
    out = []
    for d in range(s.qddd.shape[1]):
        x = s.qddd[:, d]
        x = x[np.abs(x) > 0.01 * limits.jerk[d]]
        out.append(int(np.sum(np.sign(x[1:]) != np.sign(x[:-1]))))
    return out


def test_the_demo_lines_are_smooth_splines_within_every_limit():
    from planner.app.demo import al5c_request
    from planner.app.motion_plan import plan_motion
    from planner.app.plan_file import parse_motion_request
    from planner.motion.trajectory import LIMIT_TOLERANCE

    request, _ = al5c_request()
    robot = get_robot("al5c")
    plan = plan_motion(robot, parse_motion_request(request))
    traj = plan.trajectory
    peaks = traj.peak_ratios(None)
    assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
    assert peaks["position"] <= LIMIT_TOLERANCE
    np.testing.assert_allclose(traj.sample(traj.waypoint_times).q, traj.waypoints, atol=1e-12)
    for k in range(1, len(plan.waypoints)):
        counts = _jerk_sign_changes(traj, plan.departure_times[k - 1], plan.waypoint_times[k], plan.limits)
        if plan.branches[k] == "line":
            # A chain of time-optimal segments between the samples switched 100-120 times here.
            assert max(counts) <= 9, (k, counts)
            assert plan.line_deviation[k - 1] <= 1e-5
    # The summary (and the demo's summary.json) reports the same count per move and joint.
    summary = plan.summary()
    expected = [
        _jerk_sign_changes(traj, plan.departure_times[k - 1], plan.waypoint_times[k], plan.limits)
        for k in range(1, len(plan.waypoints))
    ]
    assert summary["jerk_sign_changes"] == expected
    assert traj.jerk_sign_changes(traj.duration, traj.duration).tolist() == [0] * robot.dof
    with pytest.raises(planner.InvalidArgumentError, match="rate"):
        traj.jerk_sign_changes(rate=0.0)


def test_random_lines_are_smooth_and_keep_every_limit():
    from planner.app.motion_plan import plan_motion
    from planner.app.plan_file import parse_motion_request
    from planner.motion.trajectory import LIMIT_TOLERANCE

    rng = np.random.default_rng(5)
    worst, pieces = [], []
    for name, lines in (("al5c", 6), ("three_joint", 3)):  # three_joint's lines are metres long
        robot = get_robot(name)
        planned = 0
        while planned < lines:
            q = robot.random_configurations(rng, 2)
            data = {
                "targets": [
                    {"position": robot.position(q[0]).tolist()},
                    {"position": robot.position(q[1]).tolist(), "line": True},
                ]
            }
            try:
                plan = plan_motion(robot, parse_motion_request(data))
            except planner.PlannerError:
                continue
            planned += 1
            traj = plan.trajectory
            for peaks in (traj.peak_ratios(None), traj.peak_ratios(1000.0)):
                assert max(peaks["velocity"], peaks["acceleration"], peaks["jerk"]) <= 1 + LIMIT_TOLERANCE
                assert peaks["position"] <= LIMIT_TOLERANCE * 4
            np.testing.assert_allclose(traj.sample(traj.waypoint_times).q, traj.waypoints, atol=1e-12)
            np.testing.assert_allclose(traj.sample(plan.waypoint_times).q, plan.waypoints, atol=1e-12)
            assert plan.line_deviation[0] <= 1e-4  # [m]
            t0, t1 = plan.departure_times[0], plan.waypoint_times[1]
            counts = _jerk_sign_changes(traj, t0, t1, plan.limits)
            # Every line is smoothed: the chain of time-optimal segments switches hundreds of times.
            assert max(counts) <= 30, counts
            worst.append(max(counts))
            # Between two instants at rest (the line's ends and its corners, where a joint
            # reaches or leaves a range end) the motion is one smooth rest-to-rest piece: single
            # digits per joint, like a joint-space S-curve.
            inside = traj.waypoint_times[(traj.waypoint_times > t0 + 1e-9) & (traj.waypoint_times < t1 - 1e-9)]
            speed = np.abs(traj.sample(inside).qd) / plan.limits.velocity
            rests = [t0, *inside[np.all(speed <= 1e-9, axis=1)], t1]
            for a, b in zip(rests, rests[1:]):
                pieces.append(max(_jerk_sign_changes(traj, a, b, plan.limits)))
    assert max(pieces) <= 9, pieces
    assert max(worst) <= 9, worst


@pytest.mark.parametrize("count", [2, 3, 4, 9, 400])
def test_the_rest_to_rest_spline_is_c2_through_its_samples(count):
    from planner.motion.line_smoothing import rest_to_rest_spline

    rng = np.random.default_rng(count)
    t = np.cumsum(rng.uniform(0.01, 0.3, count))
    q = rng.normal(size=(count, 3))
    knots, p, v, a, j = rest_to_rest_spline(t, q)
    h = np.diff(np.append(knots, t[-1]))[:, None]
    end_p = p + v * h + a * h**2 / 2 + j * h**3 / 6
    end_v = v + a * h + j * h**2 / 2
    end_a = a + j * h
    np.testing.assert_allclose(end_p[:-1], p[1:], atol=1e-9)
    np.testing.assert_allclose(end_v[:-1], v[1:], atol=1e-8)
    np.testing.assert_allclose(end_a[:-1], a[1:], atol=1e-7)
    np.testing.assert_allclose([v[0], a[0], end_v[-1], end_a[-1]], 0.0, atol=1e-8)
    np.testing.assert_allclose(p[0], q[0], atol=1e-12)
    np.testing.assert_allclose(end_p[-1], q[-1], atol=1e-9)
    on_samples = np.isin(knots, t)
    np.testing.assert_allclose(p[on_samples], q[: int(on_samples.sum())], atol=1e-9)
    assert len(knots) == count + 1


def test_a_path_into_a_range_end_stops_at_the_corner_and_is_smooth_on_either_side():
    from planner.motion.line_smoothing import smooth_lines
    from planner.motion.plan import plan_trajectory

    # Joint 0 runs into its upper end at sample 40 and stays there while joint 1 takes over
    # (as IK does when a joint reaches a range end): its path has a kink there.
    limits = JointLimits(
        velocity=[1.0, 1.5], acceleration=[4.0, 6.0], jerk=[40.0, 60.0], lower=[-1, -2], upper=[0.5, 2]
    )
    u = np.linspace(0.0, 1.0, 81)
    q = np.column_stack([np.minimum(-0.5 + 2.0 * u, 0.5), np.sin(u) - 0.3 * np.maximum(u - 0.5, 0.0)])
    chain = plan_trajectory(q, limits)
    traj, count = smooth_lines(chain, [(0, len(q) - 1)])
    assert count == 1
    assert_within_limits_sampled_and_exact(traj)
    np.testing.assert_allclose(traj.sample(traj.waypoint_times).q, traj.waypoints, atol=1e-12)
    np.testing.assert_allclose(traj.waypoints, q, atol=1e-6)  # the path through the samples
    np.testing.assert_allclose(traj.sample(traj.waypoint_times[[0, 40, 80]]).qd, 0.0, atol=1e-12)
    for a, b in ((0, 40), (40, 80)):  # one smooth rest-to-rest piece on either side
        counts = _jerk_sign_changes(traj, traj.waypoint_times[a], traj.waypoint_times[b], limits)
        assert max(counts) <= 4, counts
    assert traj.duration < chain.duration
