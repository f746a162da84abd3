"""plan_motion's glue: what it plans once and reuses, and that reuse changes no plan."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from planner.app.motion_plan import plan_motion
from planner.app.plan_file import parse_motion_request
from planner.exceptions import PlannerError
from planner.motion.detours import SingularityOptions, plan_clear_of_singularities
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory_request
from planner.motion.request import TrajectoryRequest

from conftest import get_robot

_FIELDS = ("knots", "p", "v", "a", "j", "waypoints", "waypoint_times", "via_velocities", "via_accelerations", "dwell")


def _assert_same(a, b) -> None:
    assert a.duration == b.duration and a.strategy == b.strategy
    for name in _FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def _requests(robot, limits, rng):
    """Requests of every kind plan_clear_of_singularities is given: plain, with stops and dwell,
    prescribed via states with minimum durations, a moving start, the stop strategy."""
    q = robot.random_configurations(rng, 4)
    v = np.full(q.shape, np.nan)
    v[1] = 0.2 * limits.velocity
    yield TrajectoryRequest(q, limits)
    yield TrajectoryRequest(q[:2], limits)
    yield TrajectoryRequest(q, limits, stops=[2], dwell=[0.0, 0.1, 0.0, 0.0])
    yield TrajectoryRequest(
        q, limits, via_velocities=v, via_accelerations=np.zeros(q.shape), min_durations=[0.5, 0.0, 0.2]
    )
    yield TrajectoryRequest(q, limits, start_velocity=0.1 * limits.velocity, strategy="heuristic")
    yield TrajectoryRequest(q, limits, strategy="stop")


@pytest.mark.parametrize("name", ["dh3", "three_joint", "al5c"])
def test_a_plan_without_detours_is_the_requests_own_plan(name):
    # Without detours the plan is made from the request itself: bit for bit what its nodes and
    # states derived anew (as after detours taken out again) plan to.
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(3)
    for _ in range(3):
        for request in _requests(robot, limits, rng):
            plan = plan_clear_of_singularities(robot, request, SingularityOptions(max_detours=0))
            n = len(request.waypoints)
            derived = replace(
                request,
                waypoints=np.array(list(request.waypoints)),
                stops=list(request.stops),
                dwell=np.array(request.dwell),
                via_velocities=np.array(request.via_velocities),
                via_accelerations=np.array(request.via_accelerations),
                min_durations=np.array(request.min_durations),
            )
            _assert_same(plan.trajectory, plan_trajectory_request(derived))
            _assert_same(plan.trajectory, plan_trajectory_request(request))
            np.testing.assert_array_equal(plan.waypoint_indices, np.arange(n))


def test_plans_asking_for_the_same_limits_share_them_and_bad_limits_are_refused_every_time():
    robot = get_robot("dh3")

    def plan(limits):
        spec = {"waypoints": [[0.0, 0.5, 1.0], [1.0, 0.5, 1.0]], "units": {"angle": "rad"}}
        if limits is not None:
            spec["limits"] = limits
        return plan_motion(robot, parse_motion_request(spec))

    default, again = plan(None), plan(None)
    assert default.limits is again.limits
    np.testing.assert_array_equal(default.limits.velocity, JointLimits.from_robot(robot).velocity)
    slow = plan({"velocity": 0.5})
    assert slow.limits is not default.limits and plan({"velocity": 0.5}).limits is slow.limits
    np.testing.assert_array_equal(slow.limits.velocity, np.full(3, 0.5))
    np.testing.assert_array_equal(slow.limits.acceleration, np.full(3, 1.0))
    assert slow.trajectory.duration > default.trajectory.duration
    per_joint = plan({"velocity": [0.5, 0.5, 0.25]})
    np.testing.assert_array_equal(per_joint.limits.velocity, [0.5, 0.5, 0.25])
    for _ in range(2):
        with pytest.raises(PlannerError, match="velocity limit of joint"):
            plan({"velocity": [0.5, 0.0, 0.5]})
        with pytest.raises(PlannerError, match="velocity limit has 2 values"):
            plan({"velocity": [0.5, 0.5]})


def _joint_plan(robot, q, **kwargs):
    spec = {"waypoints": [list(map(float, row)) for row in q], "units": {"angle": "rad"}}
    spec.update(kwargs)
    return parse_motion_request(spec)


@pytest.mark.parametrize("name", ["dh3", "al5c"])
def test_joint_moves_plan_as_a_request_with_every_via_state_free(name):
    # Without lines plan_motion prescribes nothing: its plan is that of a request whose via
    # states are all free and segments without minimum, given explicitly or not.
    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(2)
    for count in (2, 4):
        q = robot.random_configurations(rng, count)
        plan = plan_motion(robot, _joint_plan(robot, q))
        explicit = TrajectoryRequest(
            q,
            limits,
            via_velocities=np.full(q.shape, np.nan),
            via_accelerations=np.zeros(q.shape),
            min_durations=np.zeros(len(q) - 1),
        )
        want = plan_clear_of_singularities(robot, explicit, SingularityOptions(threshold=plan.singularity.threshold))
        assert len(plan.detours) == len(want.detours)
        for mine, theirs in zip(plan.detours, want.detours):
            assert mine.inverse_condition == theirs.inverse_condition and np.array_equal(mine.q, theirs.q)
        _assert_same(plan.trajectory, want.trajectory)


@pytest.mark.parametrize(("name", "controller"), [("dh3", None), ("dh3", "pca9685"), ("al5c", "ssc32"), ("al5c", None)])
def test_default_controller_setups_are_made_once_and_each_plan_gets_its_own(name, controller):
    from planner.export.calibration_file import controller_setup

    robot = get_robot(name)
    q = robot.random_configurations(np.random.default_rng(4), 2)
    first = plan_motion(robot, _joint_plan(robot, q), controller=controller)
    second = plan_motion(robot, _joint_plan(robot, q), controller=controller)
    want = controller_setup(robot, controller)
    for plan in (first, second):
        assert plan.setup == want and plan.calibrations == want.calibrations
    assert first.setup is not second.setup and first.setup.settings is not second.setup.settings
    first.setup.settings["changed"] = True  # one plan's settings are its own
    assert "changed" not in plan_motion(robot, _joint_plan(robot, q), controller=controller).setup.settings
    if want.source == "defaults":
        assert first.calibrations is second.calibrations
    # A servo list or a calibration file is read for every plan as before.
    servos = [{"us_per_deg": 10.0} for _ in range(robot.dof)]
    with_servos = plan_motion(robot, _joint_plan(robot, q, servos=servos), controller=None)
    assert with_servos.setup.source == "plan servos"


@pytest.mark.parametrize("name", ["dh3", "al5c", "three_joint"])
def test_unresolved_segments_are_those_the_final_plan_dips_in(name):
    # Where no detour went in, the dips found while looking for detours are reused as the
    # unresolved segments: they must be those the final plan's own measure shows.
    from planner.motion.detours import dipping_segments
    from planner.motion.singularity import measure_singularities

    robot = get_robot(name)
    limits = JointLimits.from_robot(robot)
    rng = np.random.default_rng(8)
    seen = 0
    for trial in range(30):
        q = robot.random_configurations(rng, int(rng.integers(2, 5)))
        options = SingularityOptions(max_detours=trial % 3)
        plan = plan_clear_of_singularities(robot, TrajectoryRequest(q, limits), options)
        task = robot.resolve_task(None)
        report, t, _, inv = measure_singularities(robot, plan.trajectory, plan.report.threshold, task, 1000.0)
        segments = np.arange(len(plan.trajectory.waypoints) - 1)
        owners = np.searchsorted(plan.waypoint_indices, segments, side="right") - 1
        assert plan.unresolved == tuple(sorted(dipping_segments(plan.trajectory, report, t, inv, owners)))
        seen += bool(plan.unresolved)
    assert seen  # some plans dip
