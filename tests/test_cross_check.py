"""Closed form vs numerical IK: random sweeps on every arm with a closed form must agree;
and the solve_ik dispatcher."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from test_nlp_ik import make_target

from planner import IKOptions, InvalidArgumentError, Target, UnsupportedChainError
from planner.geometry.joint_space import joint_distance
from planner.geometry.target import approach_direction, approach_pitch
from planner.ik.cross_check import CrossCheck, cross_check
from planner.ik.solve import solve_ik
from planner.ik.solvers import IKSolvers
from planner.ik.task import task_rank

from conftest import HAVE_EXAMPLE_ROBOT_DATA, get_robot, needs_example_robot_data

# Target kinds the closed form covers completely (the arm is not redundant for them, except
# al5c's wrist roll for a pitch target, which the agreement rule allows for).
COMPLETE = [
    ("shelley", "position"),
    ("dh3", "position"),
    ("three_joint", "pitch"),
    ("al5c", "pitch"),
]
# Redundant target kinds: a wrist pitch (and on so101 the wrist roll, which moves its tip) leaves
# a continuum of solutions; the closed form searches it for one within the limits.
REDUNDANT = [
    ("three_joint", "position"),
    ("al5c", "position"),
    ("so101", "position"),
    ("so101", "pitch"),
]
AGREE = {"match", "both_reach", "both_unreachable"}


def sweep(name: str, kind: str, n: int, seed: int) -> list[CrossCheck]:
    robot = get_robot(name)
    rng = np.random.default_rng(seed)
    checks = []
    for q, q_seed in zip(robot.random_configurations(rng, n), robot.random_configurations(rng, n)):
        check = cross_check(robot, make_target(robot, kind, q), q_seed, options=IKOptions(time_budget=1.0))
        checks.append(check)
    return checks


def assert_all_agree(checks: list[CrossCheck]) -> None:
    bad = [c.reason for c in checks if not c.agree]
    assert not bad, f"{len(bad)} disagreements, e.g. {bad[:3]}"
    assert all(c.verdict in AGREE for c in checks)
    assert all(c.nlp.success for c in checks)


@pytest.mark.parametrize(("name", "kind"), COMPLETE)
def test_bundled_arms_agree(name, kind):
    checks = sweep(name, kind, 40, seed=30)
    assert_all_agree(checks)
    # Where the target fixes the configuration up to the branch, the NLP lands on a branch.
    if name != "al5c":
        assert all(c.verdict == "match" for c in checks)


@needs_example_robot_data
def test_so101_pose_agrees():
    assert_all_agree(sweep("so101", "pose", 25, seed=31))


@pytest.mark.slow
@pytest.mark.parametrize(("name", "kind"), COMPLETE + REDUNDANT + [("so101", "pose")])
def test_long_sweep_agrees(name, kind):
    if name == "so101" and not HAVE_EXAMPLE_ROBOT_DATA:
        pytest.skip("example-robot-data is not installed")
    checks = sweep(name, kind, 1000, seed=32)
    assert_all_agree(checks)
    assert all(c.analytic_status == "solved" for c in checks)


def assert_the_closed_form_reaches_what_the_nlp_reaches(checks: list[CrossCheck]) -> None:
    """Redundant targets from FK within the limits: the closed form, free joints at q_seed's values
    where they allow it and searched otherwise, finds a solution within the limits whenever the
    NLP does (here: always), and the two agree."""
    assert_all_agree(checks)
    for check in checks:
        assert check.redundant, check.reason
        assert check.analytic_status == "solved", check.reason
        assert check.verdict == "both_reach" or (check.verdict == "match" and check.joint_distance <= 1e-4)


@pytest.mark.parametrize(("name", "kind"), REDUNDANT)
def test_redundant_targets_agree(name, kind):
    if name == "so101" and not HAVE_EXAMPLE_ROBOT_DATA:
        pytest.skip("example-robot-data is not installed")
    # Random seeds: their approach pitch (and roll) often leave no branch within the limits.
    assert_the_closed_form_reaches_what_the_nlp_reaches(sweep(name, kind, 60, seed=33))


@pytest.mark.parametrize("name", ["al5c", "so101"])
def test_closed_form_finds_a_solution_within_limits_whenever_the_nlp_does(name):
    # Position targets scattered a few cm around FK points (some reachable within the limits,
    # some not), random seeds; the NLP tries 64 starts.
    if name == "so101" and not HAVE_EXAMPLE_ROBOT_DATA:
        pytest.skip("example-robot-data is not installed")
    robot = get_robot(name)
    rng = np.random.default_rng(36)
    points = robot.position(robot.random_configurations(rng, 50)) + rng.normal(0.0, 0.04, (50, 3))
    reached = 0
    for point, q_seed in zip(points, robot.random_configurations(rng, 50)):
        check = cross_check(robot, Target(point), q_seed, options=IKOptions(max_attempts=64, time_budget=10.0))
        if check.nlp.success:
            reached += 1
            assert check.analytic_status == "solved", check.reason
        assert check.agree, check.reason
    assert 10 <= reached < 50  # both outcomes occur


# Cases where the NLP reached a position target within the limits and the closed form, which
# then kept the approach pitch (and so101's wrist roll) at q_seed's values, reported no branch
# within them.
MISSED = [
    (
        "al5c",
        [1.328614, 2.406141, -2.663832, 1.556425, -1.506541],
        [-0.777678, 1.189633, -2.456487, -1.34108, -1.296084],
    ),
    (
        "so101",
        [1.810661, -0.584052, -0.343829, -0.98518, -2.460665],
        [-0.874231, -0.229907, 0.059493, 0.058926, -1.358987],
    ),
    (
        "so101",
        [0.260565, 1.583278, 0.268398, 0.487849, -0.936363],
        [-1.303413, 0.95005, -0.758772, -1.048367, -1.642429],
    ),
]


@pytest.mark.parametrize(("name", "q_target", "q_seed"), MISSED)
def test_closed_form_finds_redundant_solutions_within_limits(name, q_target, q_seed):
    if name in ("so101",) and not HAVE_EXAMPLE_ROBOT_DATA:
        pytest.skip("example-robot-data is not installed")
    robot = get_robot(name)
    target = Target(robot.position(np.array(q_target)))
    check = cross_check(robot, target, np.array(q_seed))
    assert check.nlp.success  # reachable within the limits ...
    assert check.agree and check.analytic_status == "solved", check.reason  # ... so the closed form finds it too
    result = solve_ik(robot, target, np.array(q_seed), method="analytic")
    for sol in result.solutions:
        assert np.linalg.norm(robot.position(sol.q) - target.position) <= 1e-9
        assert sol.within_limits == bool(robot.within_limits(sol.q))


@needs_example_robot_data
def test_so101_pitch_target_follows_the_approach_convention():
    # Its arm plane passes 8 mm beside its yaw axis, which is 39 mm from the base z axis: the
    # literal direction towards the target is out of reach; the elevation, outward, is not.
    robot = get_robot("so101")
    q = np.array([-1.591, -0.9187, 1.0183, 0.2725, -2.2181])
    target = make_target(robot, "pitch", q)
    assert target.pitch == pytest.approx(approach_pitch(robot, q))
    check = cross_check(robot, target, q, options=IKOptions(time_budget=0.2))
    assert check.agree and check.verdict in ("match", "both_reach"), check.reason
    assert check.analytic_orientation_error <= 1e-9 and check.nlp.orientation_error <= 1e-6
    literal = approach_direction(target.position, target.pitch)
    approach = robot.fk(q)[:3, :3] @ robot.approach_axis
    assert np.linalg.norm(approach - literal) > 0.05  # the old literal convention would fail it


@needs_example_robot_data
def test_so101_pitch_sweep_agrees():
    checks = sweep("so101", "pitch", 40, seed=37)
    assert_all_agree(checks)
    assert all(c.analytic_status == "solved" and c.analytic_orientation_error <= 1e-9 for c in checks)


def test_near_singular_targets_match():
    # Arm almost stretched: the branches nearly coincide, the bound on the distance widens.
    robot = get_robot("shelley")
    for elbow in (1e-3, 1e-5, 0.0):
        check = cross_check(robot, Target(robot.position(np.array([0.3, elbow]))), np.array([-0.5, 1.0]))
        assert check.agree and check.verdict == "match", check.reason


def test_unreachable_targets_agree_as_unreachable():
    robot = get_robot("shelley")
    check = cross_check(robot, Target([0.5, 0.0, 0.0]), options=IKOptions(max_attempts=16))
    assert check.agree and check.verdict == "both_unreachable"
    assert check.analytic_status == "beyond_max_reach" and check.nlp.status == "not_converged"
    assert json.loads(json.dumps(check.as_dict()))["verdict"] == "both_unreachable"


def test_cross_check_reports_errors_of_both():
    robot = get_robot("dh3")
    check = cross_check(robot, Target(robot.position(np.array([0.5, 0.7, 0.9]))), np.zeros(3))
    assert check.verdict == "match" and check.branch is not None
    assert check.joint_distance <= 1e-4
    assert check.analytic_position_error <= 1e-12 and check.nlp.position_error <= 1e-6
    d = check.as_dict()
    assert d["nlp_position_error"] == check.nlp.position_error and d["analytic_status"] == "solved"


@needs_example_robot_data
def test_cross_check_needs_a_closed_form():
    with pytest.raises(UnsupportedChainError, match="ur5 has no closed-form IK to cross-check"):
        cross_check(get_robot("ur5"), Target([0.3, 0.1, 0.4]))


def test_joint_distance_wraps_angles_not_lengths():
    robot = get_robot("dh3")
    assert joint_distance(robot, [math.pi - 0.1, 0.0, 0.0], [-math.pi + 0.1, 0.0, 0.0]) == pytest.approx(0.2)
    assert joint_distance(robot, [2 * math.pi, 0.0, 0.0], [0.0, 0.0, 0.0]) == pytest.approx(0.0, abs=1e-12)


def test_task_rank_sees_the_free_wrist_roll():
    robot = get_robot("al5c")
    q = np.array([0.3, 1.0, -1.2, 0.4, 0.2])
    assert task_rank(robot, make_target(robot, "pitch", q), q) == 4  # wrist roll moves nothing that counts
    robot = get_robot("dh3")
    assert task_rank(robot, make_target(robot, "position", np.array([0.3, 0.5, 0.9])), np.array([0.3, 0.5, 0.9])) == 3


# ------------------------------------------------------------------------------ solve_ik
def test_auto_uses_the_closed_form_where_there_is_one():
    robot = get_robot("three_joint")
    target = make_target(robot, "pitch", np.array([0.5, 1.0, -0.5, 0.3]))
    result = solve_ik(robot, target)
    assert result.method == "analytic" and result.success and result.attempt_kind == "closed_form"
    assert result.position_error <= 1e-9 and result.orientation_error <= 1e-9
    assert robot.within_limits(result.q)


@needs_example_robot_data
def test_auto_uses_the_nlp_elsewhere():
    robot = get_robot("z1")
    target = make_target(robot, "pose", np.array([0.3, 1.0, -1.0, 0.2, 0.3, 0.4]))
    result = solve_ik(robot, target)
    assert result.method == "nlp" and result.success
    with pytest.raises(UnsupportedChainError, match="z1 has no closed-form IK"):
        solve_ik(robot, target, method="analytic")


def test_nlp_method_starts_from_the_branches():
    robot = get_robot("dh3")
    target = make_target(robot, "position", np.array([0.5, 0.7, 0.9]))
    result = solve_ik(robot, target, method="nlp")
    assert result.method == "nlp" and result.success and result.attempt_kind == "closed_form"
    plain = solve_ik(robot, target, method="nlp", options=IKOptions(closed_form_seeds=False))
    assert plain.success and plain.attempt_kind == "random"


def test_auto_asks_the_nlp_when_the_free_joints_block_the_closed_form():
    name, q, q_seed = MISSED[0]
    robot = get_robot(name)
    target = Target(robot.position(np.array(q)))
    closed = solve_ik(robot, target, q_seed, method="analytic")
    result = solve_ik(robot, target, q_seed)
    if closed.success:  # the closed form handles it (after a fix): auto keeps it
        assert result.method == "analytic"
    else:
        assert closed.status == "outside_joint_limits" and robot.within_limits(closed.q)
        assert result.method == "nlp" and result.success


def test_auto_keeps_the_closed_form_verdict_where_the_arm_is_not_redundant():
    robot = get_robot("shelley")
    result = solve_ik(robot, Target([-0.15, 0.0, 0.0]))  # behind the base: servo 1 would need 150 deg
    assert result.method == "analytic" and result.status == "outside_joint_limits" and not result.success
    assert "joint 'servo1' needs" in result.reason and robot.within_limits(result.q)


def test_analytic_result_for_an_unreachable_target():
    robot = get_robot("shelley")
    result = solve_ik(robot, Target([0.5, 0.0, 0.0]), method="analytic")
    assert not result.success and result.status == "beyond_max_reach" and result.attempt is None
    assert robot.within_limits(result.q)


def test_solvers_are_built_once_per_robot():
    robot = get_robot("dh3")
    assert IKSolvers.of(robot) is IKSolvers.of(robot)
    assert IKSolvers.of(robot).nlp is IKSolvers.of(robot).nlp
    assert IKSolvers.of(robot).analytic is IKSolvers.of(robot).analytic is not None


def test_cached_solvers_do_not_keep_robots_alive():
    import gc
    import weakref

    from test_casadi_kinematics import MIXED_URDF

    from planner import Robot

    robot = Robot(MIXED_URDF, tip="tool")
    for method in ("auto", "nlp"):
        solve_ik(robot, robot.position(np.zeros(robot.dof)), method=method)
    assert IKSolvers in robot.derived
    ref = weakref.ref(robot)
    del robot
    gc.collect()
    assert ref() is None


def test_bad_method_and_inputs():
    robot = get_robot("dh3")
    with pytest.raises(InvalidArgumentError, match="unknown IK method 'fast'; valid: auto, analytic, nlp"):
        solve_ik(robot, Target([0.1, 0.0, 0.1]), method="fast")  # type: ignore[arg-type]
    with pytest.raises(InvalidArgumentError, match="target position must be finite"):
        solve_ik(robot, [math.nan, 0.0, 0.1])
    with pytest.raises(InvalidArgumentError, match="time_budget must be a positive finite number"):
        solve_ik(robot, Target([0.1, 0.0, 0.1]), method="nlp", options=IKOptions(time_budget=-1.0))


# ------------------------------------------------------------------------------ CLI
def run_ik(capsys, *args: str) -> tuple[int, str, str]:
    from planner.app.cli import main

    code = main(["ik", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_methods_answer_in_one_shape(capsys):
    robot = get_robot("dh3")
    q = np.array([0.5, 0.7, 0.9])
    x, y, z = robot.position(q)
    outputs = {}
    for method in ("auto", "analytic", "nlp"):
        code, out, _ = run_ik(capsys, "dh3", str(x), str(y), str(z), "--method", method, "--json")
        assert code == 0
        outputs[method] = json.loads(out)
    assert set(outputs["nlp"]) == set(outputs["analytic"]) == set(outputs["auto"])
    assert outputs["auto"]["method"] == "analytic"  # the closed form answers where the arm has one
    nlp = outputs["nlp"]
    assert nlp["status"] == "solved" and nlp["method"] == "nlp" and nlp["attempts"] >= 1 and nlp["time_ms"] > 0
    np.testing.assert_allclose(robot.position(nlp["q"]), [x, y, z], atol=1e-6)
    (solution,) = nlp["solutions"]  # without --all: the chosen one
    assert set(solution) == set(outputs["analytic"]["solutions"][0])
    assert solution["within_limits"] and solution["q"] == nlp["q"]


def test_cli_both_reports_the_cross_check(capsys):
    robot = get_robot("three_joint")
    q = np.array([0.5, 1.0, -0.5, 0.3])
    target = make_target(robot, "pitch", q)
    x, y, z = target.position
    args = ["three_joint", str(x), str(y), str(z), "--pitch", repr(target.pitch), "--method", "both"]
    code, out, _ = run_ik(capsys, *args, "--json", "--all")
    assert code == 0
    result = json.loads(out)
    assert result["agree"] and result["cross_check"]["verdict"] == "match"
    assert len(result["solutions"]) == 4  # every closed-form branch
    assert result["nlp"]["success"] and result["cross_check"]["branch"] in [s["label"] for s in result["solutions"]]
    code, out, _ = run_ik(capsys, *args)
    assert code == 0 and "both IK" in out and "closed-form branch" in out


def test_cli_nlp_errors(capsys):
    code, _, err = run_ik(capsys, "dh3", "0.1", "0", "0.1", "--method", "nlp", "--time-budget", "0")
    assert code == 1 and "time_budget must be a positive finite number [s], got 0.0" in err
    code, _, err = run_ik(capsys, "dh3", "0.1", "0", "0.1", "--method", "nlp", "--current", "0", "0", "3")
    assert code == 1 and "seed: joint 'elbow' value 3 is outside its range" in err
    code, out, _ = run_ik(capsys, "shelley", "0.5", "0", "0", "--method", "nlp", "--json", "--time-budget", "0.01")
    assert code == 0 and json.loads(out)["status"] == "not_converged" and json.loads(out)["solutions"] == []


@needs_example_robot_data
def test_cli_both_needs_a_closed_form(capsys):
    code, _, err = run_ik(capsys, "ur5", "0.3", "0.1", "0.4", "--method", "both")
    assert code == 1 and "ur5 has no closed-form IK" in err
