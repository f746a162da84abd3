"""Review of the compiled singularity measure and the plan_motion glue, as users call them.

Random DH arms of 1 to 7 joints mixing revolute, prismatic and continuous joints (ranges
without ends), planned and measured through the public API, against Pinocchio's Jacobian and
NumPy's SVD (:meth:`Robot.conditioning`) at every sampled row; two-waypoint plans of every
registered strategy against the stop strategy's; plan_motion's per-robot caches (limits,
default controller setups) against what is made afresh; the rounding of huge continuous joint
angles and joint counts too large for the compiled loops' stack arrays.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import pickle
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import planner
from planner import PlannerError
from planner.app.plan_file import parse_motion_request
from planner.core.certificates import grams
from planner.motion.limits import JointLimits
from planner.motion.singularity import bounded_conditioning

COMPILED = grams(np.zeros((1, 1, 1))) is not None
_FLOAT = {"allow_nan": False, "allow_infinity": False, "allow_subnormal": False}
_FIELDS = ("knots", "p", "v", "a", "j", "waypoints", "waypoint_times", "via_velocities", "via_accelerations", "dwell")


def _settings(examples: int) -> settings:
    return settings(
        max_examples=examples,
        deadline=None,
        derandomize=True,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
        database=None,
    )


@st.composite
def _arms(draw, kinds=("revolute", "revolute", "prismatic", "continuous")) -> dict:
    """A DH description of 1-7 joints of the given kinds (continuous: no range ends)."""
    angle = st.one_of(
        st.sampled_from([0.0, math.pi / 2, -math.pi / 2, math.pi]), st.floats(-math.pi, math.pi, **_FLOAT)
    )
    length = st.one_of(st.just(0.0), st.floats(-0.3, 0.3, **_FLOAT))
    rows = []
    for k in range(draw(st.integers(1, 7))):
        kind = draw(st.sampled_from(kinds))
        lower = draw(st.floats(-math.pi, math.pi - 0.02, **_FLOAT))
        upper = draw(st.floats(lower + 0.01, math.pi, **_FLOAT))
        row = {"name": f"j{k + 1}", "type": kind, "theta": draw(angle), "d": draw(length), "a": draw(length)}
        row.update(alpha=draw(angle), velocity=draw(st.floats(0.2, 8.0, **_FLOAT)))
        if kind != "continuous":
            scale = 0.1 if kind == "prismatic" else 1.0
            row.update(lower=lower * scale, upper=upper * scale)
        rows.append(row)
    return {"name": "review_dh", "units": {"length": "m", "angle": "rad"}, "dh": rows}


def _robot(description: dict) -> planner.Robot:
    return planner.Robot(planner.urdf_from_dh(description), tip="tool")


def _box(robot: planner.Robot, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """The joint ranges, continuous joints given one turn around `offset`."""
    return (
        np.where(np.isfinite(robot.lower), robot.lower, offset - math.pi),
        np.where(np.isfinite(robot.upper), robot.upper, offset + math.pi),
    )


def _assert_same_trajectory(a, b) -> None:
    assert a.duration == b.duration
    for name in _FIELDS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def _rows(robot: planner.Robot, rng: np.random.Generator, count: int, kind: str, offset: float) -> np.ndarray:
    lo, hi = _box(robot, offset)
    if kind == "smooth":  # random jerks integrated three times, across part of the box
        walk = np.cumsum(np.cumsum(np.cumsum(rng.normal(size=(count, robot.dof)), 0), 0), 0)
        walk /= max(float(np.max(np.abs(walk))), 1e-300)
        q = rng.uniform(lo, hi) + walk * (hi - lo) * rng.uniform(0.0, 1.0)
    elif kind == "still":
        q = np.repeat(rng.uniform(lo, hi)[None], count, axis=0)
    elif kind == "creep":  # steps far below the certificates' margins
        q = rng.uniform(lo, hi) + np.cumsum(rng.normal(0.0, 1e-12, (count, robot.dof)), axis=0)
    else:  # jumps between random configurations
        q = rng.uniform(lo, hi, (count, robot.dof))
    return np.clip(q, lo, hi)


@given(
    description=st.one_of(_arms(("revolute", "revolute", "continuous")), _arms()),
    seed=st.integers(0, 2**32 - 1),
    count=st.one_of(st.integers(1, 3), st.integers(4, 300)),
    kind=st.sampled_from(["smooth", "smooth", "still", "creep", "jumps"]),
    threshold=st.one_of(st.sampled_from([0.0, 0.01, 1 / 30, 0.5]), st.floats(0.0, 0.99, **_FLOAT)),
    task=st.sampled_from(["position", "pose"]),
    offset=st.sampled_from([0.0, 100.0, 1e4]),
)
@_settings(60)
def test_the_measure_sorts_every_row_as_the_exact_svd_on_random_arms(
    description, seed, count, kind, threshold, task, offset
):
    # bounded_conditioning's contract at every row against Robot.conditioning (Pinocchio, SVD):
    # the same rows below the threshold, both minima exact at a lowest row, lower bounds elsewhere.
    robot = _robot(description)
    rng = np.random.default_rng(seed)
    q = _rows(robot, rng, count, kind, offset)
    keep = np.unique(rng.integers(0, count, int(rng.integers(0, 4))))
    inv, man = bounded_conditioning(robot, q, task, threshold, keep)
    inv_all, man_all = robot.conditioning(q, task)
    assert np.array_equal(inv < threshold, inv_all < threshold)
    assert np.all(inv <= inv_all) and np.all(man <= man_all)
    assert np.array_equal(inv[keep], inv_all[keep]) and np.array_equal(man[keep], man_all[keep])
    assert inv.min() == inv_all.min() and inv_all[int(np.argmin(inv))] == inv_all.min()
    assert man.min() == man_all.min() and man_all[int(np.argmin(man))] == man_all.min()


@given(
    description=_arms(),
    seed=st.integers(0, 2**32 - 1),
    count=st.integers(2, 4),
    strategy=st.sampled_from(["optimized", "refined", "stop", "heuristic"]),
    velocity=st.one_of(st.none(), st.floats(1e-2, 1e2, **_FLOAT)),
    threshold=st.one_of(st.none(), st.floats(0.0, 0.5, **_FLOAT)),
    rate=st.sampled_from([1000.0, 97.0, 5000.0]),
    offset=st.sampled_from([0.0, 1e3, 1e6]),
)
@_settings(40)
def test_check_singularities_reports_the_exact_measure_of_the_sampled_rows(
    description, seed, count, strategy, velocity, threshold, rate, offset
):
    robot = _robot(description)
    rng = np.random.default_rng(seed)
    lo, hi = _box(robot, offset)
    waypoints = rng.uniform(lo, hi, (count, robot.dof))
    try:
        trajectory = planner.plan_trajectory(
            waypoints, JointLimits.from_robot(robot, velocity=velocity), strategy=strategy
        )
    except PlannerError:
        return
    report = planner.check_singularities(robot, trajectory, threshold=threshold, rate=rate)
    t = np.unique(np.concatenate([trajectory.times(rate), trajectory.waypoint_times]))
    inv, man = robot.conditioning(trajectory.positions(t), report.task)
    assert report.min_inverse_condition == inv.min() and report.min_manipulability == man.min()
    np.testing.assert_array_equal(report.waypoint_inverse_condition, inv[np.searchsorted(t, trajectory.waypoint_times)])
    assert inv[np.searchsorted(t, report.time_of_minimum)] == inv.min()
    assert report.singular_waypoints == tuple(np.flatnonzero(report.waypoint_inverse_condition < report.threshold))


@given(
    description=_arms(),
    seed=st.integers(0, 2**32 - 1),
    move=st.sampled_from(["random", "none", "tiny", "to a range end"]),
    given_states=st.sampled_from(["none", "via velocities", "stops", "zero dwell"]),
    velocity=st.one_of(st.none(), st.floats(1e-3, 1e3, **_FLOAT)),
)
@_settings(60)
def test_a_two_waypoint_plan_of_every_strategy_is_the_stop_strategys_under_its_own_name(
    description, seed, move, given_states, velocity
):
    # Both ends rest and there is no via to choose: every registered strategy plans what the
    # stop strategy plans, and its name is the one asked for.
    robot = _robot(description)
    rng = np.random.default_rng(seed)
    lo, hi = _box(robot, 0.0)
    a = rng.uniform(lo, hi)
    b = {
        "random": rng.uniform(lo, hi),
        "none": a,
        "tiny": np.clip(a + rng.normal(0.0, 1e-9, a.shape), lo, hi),
        "to a range end": np.where(np.isfinite(robot.upper), robot.upper, a + 1.0),
    }[move]
    limits = JointLimits.from_robot(robot, velocity=velocity)
    extra = {
        "none": {},
        "via velocities": {"via_velocities": rng.uniform(-1.0, 1.0, (2, robot.dof)) * limits.velocity},
        "stops": {"stops": [0, 1]},
        "zero dwell": {"dwell": 0.0},
    }[given_states]
    try:
        stop = planner.plan_trajectory([a, b], limits, strategy="stop")
    except PlannerError:
        return
    assert stop.duration >= 0.0 and stop.strategy == "stop"
    for strategy in ("optimized", "refined", "heuristic"):
        plan = planner.plan_trajectory([a, b], limits, strategy=strategy, **extra)
        _assert_same_trajectory(plan, stop)
        assert plan.strategy == strategy


def _plan(robot: planner.Robot, spec: dict):
    return planner.plan_motion(robot, parse_motion_request({"units": {"angle": "rad", "length": "m"}, **spec}))


@pytest.mark.parametrize("name", ["dh3", "al5c", "shelley"])
def test_plans_of_interleaved_limit_requests_each_get_their_own_values(name):
    # The limits made once per robot and values: a request never gets another's limits, and
    # each plan's limits are what JointLimits.from_robot makes of its values.
    robot = planner.load_robot(name)
    rng = np.random.default_rng(7)
    q = robot.random_configurations(rng, 2).tolist()
    asks = [{}, {"velocity": 0.5}, {"velocity": 0.25}, {"velocity": [0.5] * robot.dof}, {"jerk": 9.0}]
    asks += [{"servo_seconds_per_60deg": 0.3}, {"velocity": 0.5, "acceleration": 2.0}, {"velocity": 0.25}]
    asks += [{"velocity": v} for v in np.linspace(0.1, 1.0, 10).tolist()]  # past the cache's size
    made = {}
    for ask in asks + asks[::-1]:
        plan = _plan(robot, {"waypoints": q, "limits": ask} if ask else {"waypoints": q})
        want = JointLimits.from_robot(robot, **ask)
        for field in ("velocity", "acceleration", "jerk", "lower", "upper"):
            np.testing.assert_array_equal(getattr(plan.limits, field), getattr(want, field), err_msg=str(ask))
        key = repr(sorted(ask.items()))
        if key in made:
            _assert_same_trajectory(plan.trajectory, made[key])
        made[key] = plan.trajectory


@pytest.mark.parametrize("controller", [None, "ssc32", "pca9685", "feetech", "steps", "pulses"])
def test_a_plans_setup_changed_by_the_user_leaves_the_next_plan_alone(controller):
    robot = planner.load_robot("dh3")
    spec = {"waypoints": [[0.0, 0.5, 1.0], [1.0, 0.5, 1.0]]}
    if controller is not None:
        spec["controller"] = controller
    try:
        first = _plan(robot, spec)
    except PlannerError:
        return  # no default calibration for this controller
    fresh = _plan(planner.load_robot("dh3"), spec)
    first.setup.settings["pwm_frequency_hz"] = 1.0  # type: ignore[index]
    second = _plan(robot, spec)
    assert second.setup.settings == fresh.setup.settings
    assert second.setup.settings is not first.setup.settings
    assert second.setup.calibrations == fresh.setup.calibrations and second.setup.source == fresh.setup.source


def test_a_copied_or_pickled_robot_plans_as_the_original():
    robot = planner.load_robot("al5c")
    spec = {"waypoints": robot.random_configurations(np.random.default_rng(2), 3).tolist(), "limits": {"velocity": 0.7}}
    plan = _plan(robot, spec)
    for other in (copy.copy(robot), copy.deepcopy(robot), pickle.loads(pickle.dumps(robot)), robot):
        again = _plan(other, spec)
        _assert_same_trajectory(again.trajectory, plan.trajectory)
        assert again.setup.calibrations == plan.setup.calibrations
        for field in ("velocity", "acceleration", "jerk"):
            np.testing.assert_array_equal(getattr(again.limits, field), getattr(plan.limits, field))


@pytest.mark.parametrize("value", ["fast", [1.0, "x", 2.0], {"a": 1}, None])
def test_a_request_made_in_code_with_limits_that_are_not_numbers_is_refused_with_a_planner_error(value):
    # A MotionRequest is a dataclass: one made or replaced in code is not checked as a file is.
    # Its limits reach JointLimits, which names the bad value (was: NumPy's ValueError/TypeError).
    robot = planner.load_robot("dh3")
    request = parse_motion_request({"waypoints": [[0.0, 0.5, 1.0], [1.0, 0.5, 1.0]], "units": {"angle": "rad"}})
    for key in ("velocity", "acceleration", "jerk"):
        with pytest.raises(PlannerError, match=key):
            planner.plan_motion(robot, dataclasses.replace(request, limits={key: value}))


def _two_link_continuous() -> planner.Robot:
    row = {"type": "continuous", "theta": 0.0, "d": 0.0, "a": 0.3, "alpha": 0.0, "velocity": 1.0}
    description = {"name": "two_link", "units": {"length": "m", "angle": "rad"}}
    description["dh"] = [{"name": "j1", **row}, {"name": "j2", **row}]
    return planner.Robot(planner.urdf_from_dh(description), tip="tool")


def test_check_singularities_sorts_the_rows_of_huge_continuous_joint_angles_as_the_exact_measure():
    robot = _two_link_continuous()
    x0 = 1000000000000041.9  # sin(x0) = 0.0024: the elbow near straight
    trajectory = planner.plan_trajectory([[0.3, x0], [0.3, x0 + 0.5]], JointLimits.from_robot(robot))
    threshold = 0.00048019356559871333
    report = planner.check_singularities(robot, trajectory, threshold=threshold, task="position")
    t = np.unique(np.concatenate([trajectory.times(1000.0), trajectory.waypoint_times]))
    below = robot.conditioning(trajectory.positions(t), "position")[0] < threshold
    assert report.below_threshold[0][1] == t[np.flatnonzero(below)[-1]]  # 0.304 s; reported: 0.3 s


def test_the_measure_sorts_rows_a_few_spacings_apart_at_1e9_rad_as_the_exact_measure():
    robot = _two_link_continuous()
    x = 1e9
    while not 0.0 < math.sin(x) < 0.01:
        x += 0.01
    q = np.array([[0.3, x]] * 12 + [[0.3, x + 4 * np.spacing(x)]] * 13)
    inv_all = robot.conditioning(q, "position")[0]
    wrong = 0
    for threshold in np.linspace(inv_all[0], inv_all[12], 41)[1:-1]:
        inv = bounded_conditioning(robot, q, "position", float(threshold), np.array([0, 24]))[0]
        wrong += not np.array_equal(inv < threshold, inv_all < threshold)
    assert wrong == 0


@pytest.mark.skipif(not COMPILED, reason="no C compiler (or PLANNER_JIT=0)")
def test_interval_certificates_refuse_or_take_any_joint_count_without_crashing():
    code = textwrap.dedent(
        """
        import numpy as np
        from planner.exceptions import InvalidArgumentError
        from planner.core.certificates import interval_certificates
        dof, m = 400_000, 3
        args = (np.zeros((3, dof)), np.array([0, 2]), np.ones((2, m, dof)), np.ones((2, 6)), np.zeros(1), np.ones(dof))
        try:
            interval_certificates(*args, (0.0, 0.5, 0.5, 0.5, 1e9, 1.0))
        except InvalidArgumentError:
            pass
        print("survived")
        """
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "survived" in done.stdout, (done.returncode, done.stderr[-500:])
