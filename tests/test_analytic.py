"""Closed-form IK: family detection from the model, result types, branches, limits, batches."""

from __future__ import annotations

import gc
import math
import weakref

import numpy as np
import pytest

import planner
import planner.ik.analytic as analytic
from planner import Robot, Target, load_robot, solve_analytic
from planner.exceptions import InvalidArgumentError, InvalidConfigurationError, UnsupportedChainError
from planner.export.calibration import angle_to_steps, steps_to_angle
from planner.geometry.target import approach_pitch, pitch_error
from planner.ik.analytic import (
    BRANCHES,
    STATUS_BEYOND_MAX_REACH,
    STATUS_CODES,
    STATUS_INSIDE_MIN_REACH,
    STATUS_NAMES,
    STATUS_ORIENTATION_NOT_ACHIEVABLE,
    STATUS_OUTSIDE_JOINT_LIMITS,
    STATUS_SOLVED,
    Planar2IK,
    YawPlanarIK,
    chain_at_zero,
    closed_form_solver,
    poe_fk,
)
from planner.ik.solvers import IKSolvers
from planner.ik.status import IKStatus
from planner.model.catalog import BUNDLED_ROBOTS, example_robot_data_dir

TOL_POS = 1e-9


def serial_urdf(joints, tip_xyz=(0.0, 0.0, 0.0), name="test_arm", limit=3.0):
    """A serial chain: joints = [(name, type, xyz, rpy, axis)], then a fixed tip frame `tip`."""

    def f(v):
        return " ".join(repr(float(x)) for x in v)

    parts = [f'<robot name="{name}">', '<link name="base"/>']
    parent = "base"
    for i, (jname, jtype, xyz, rpy, axis) in enumerate(joints):
        child = f"link{i}"
        parts.append(f'<link name="{child}"/>')
        parts.append(
            f'<joint name="{jname}" type="{jtype}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{f(xyz)}" rpy="{f(rpy)}"/><axis xyz="{f(axis)}"/>'
            f'<limit lower="{-limit}" upper="{limit}" effort="1" velocity="1"/></joint>'
        )
        parent = child
    parts.append('<link name="tip"/>')
    parts.append(
        f'<joint name="tip_fixed" type="fixed"><parent link="{parent}"/><child link="tip"/>'
        f'<origin xyz="{f(tip_xyz)}" rpy="0 0 0"/></joint>'
    )
    parts.append("</robot>")
    return "".join(parts)


Z, Y, X = (0, 0, 1), (0, 1, 0), (1, 0, 0)
O3 = (0, 0, 0)


@pytest.fixture(scope="module")
def robots():
    return {name: load_robot(name) for name in BUNDLED_ROBOTS}


@pytest.fixture(scope="module")
def solvers(robots):
    return {name: closed_form_solver(robot) for name, robot in robots.items()}


def fk_position(robot, q):
    return robot.fk(q)[:3, 3]


# ---------------------------------------------------------------------------- detection
def test_families_of_the_bundled_arms(solvers):
    assert isinstance(solvers["shelley"], Planar2IK)
    for name in ("al5c", "three_joint", "dh3"):
        assert isinstance(solvers[name], YawPlanarIK)
    assert (solvers["al5c"].n_pitch, solvers["al5c"].has_roll) == (3, True)
    assert (solvers["three_joint"].n_pitch, solvers["three_joint"].has_roll) == (3, False)
    assert (solvers["dh3"].n_pitch, solvers["dh3"].has_roll) == (2, False)
    assert all(s.exact for name, s in solvers.items() if name != "shelley")


def test_lengths_and_offsets_are_read_from_the_model(solvers):
    # Values from urdf/*.yaml; the solver reads them from the Pinocchio joint placements.
    np.testing.assert_allclose(solvers["al5c"].link_lengths, (0.14605, 0.187325, 0.100), atol=1e-12)
    assert solvers["al5c"].describe()["shoulder"] == pytest.approx([0.0, 0.06731], abs=1e-12)
    np.testing.assert_allclose(solvers["three_joint"].link_lengths, (4.0, 4.0, 2.0), atol=1e-12)
    np.testing.assert_allclose(solvers["dh3"].link_lengths, (0.06, 0.11), atol=1e-12)
    # 004's alpha = 180 deg link flips the second pitch axis.
    assert solvers["dh3"].describe()["pitch_signs"] == [1.0, -1.0]
    shelley = solvers["shelley"]
    np.testing.assert_allclose(shelley.link_lengths, (0.10, math.hypot(0.08, 0.01)), atol=1e-12)
    assert shelley.tip_offset_angle == pytest.approx(math.atan2(0.01, 0.08), abs=1e-12)


@pytest.mark.parametrize("name", list(BUNDLED_ROBOTS) + ["so101"])
def test_product_of_exponentials_matches_pinocchio(name):
    if name == "so101" and example_robot_data_dir() is None:
        pytest.skip("example-robot-data is not installed")
    robot = load_robot(name)
    chain = chain_at_zero(robot)
    q = robot.random_configurations(np.random.default_rng(3), 20)
    pos, rot = poe_fk(
        [j.axis for j in chain.joints], [j.point for j in chain.joints], chain.tip_position, chain.tip_rotation, q
    )
    ref = robot.fk(q)
    np.testing.assert_allclose(pos, ref[:, :3, 3], atol=1e-12)
    np.testing.assert_allclose(rot, ref[:, :3, :3], atol=1e-12)


def _chain_error(joints, tip_xyz=(0.1, 0, 0)):
    robot = Robot(serial_urdf(joints, tip_xyz))
    with pytest.raises(UnsupportedChainError) as info:
        closed_form_solver(robot)
    return info.value


def test_family_registry_and_match():
    assert analytic.FAMILIES == (Planar2IK, YawPlanarIK)
    chain = chain_at_zero(load_robot("al5c"))
    assert YawPlanarIK.match(chain) is None
    assert "not parallel to the first joint" in Planar2IK.match(chain)
    planar = chain_at_zero(load_robot("shelley"))
    assert Planar2IK.match(planar) is None
    assert "like the base yaw" in YawPlanarIK.match(planar)


def test_solve_analytic_caches_the_solver_with_the_robot():
    joints = [
        ("yaw", "revolute", O3, O3, Z),
        ("p0", "revolute", (0, 0, 0.1), O3, Y),
        ("p1", "revolute", (0.1, 0, 0), O3, Y),
    ]
    robot = Robot(serial_urdf(joints, (0.1, 0, 0)))
    assert solve_analytic(robot, Target([0.15, 0.02, 0.12])).success
    assert IKSolvers in robot.derived
    solver = IKSolvers.of(robot).analytic
    assert solve_analytic(robot, Target([0.15, 0.02, 0.12])).success and IKSolvers.of(robot).analytic is solver
    ref = weakref.ref(robot)
    del robot, solver
    gc.collect()
    assert ref() is None  # the cache lives and dies with the robot


def test_solve_analytic_raises_for_unsupported_chains_every_time():
    robot = Robot(serial_urdf([(f"v{k}", "revolute", (0.1 * (k > 0), 0, 0), O3, Z) for k in range(3)], (0.1, 0, 0)))
    for _ in range(2):
        with pytest.raises(UnsupportedChainError, match="'v2'"):
            solve_analytic(robot, Target([0.1, 0.0, 0.0]))
    assert IKSolvers.of(robot).analytic is None  # the reason is kept: the chain does not change


def test_first_joint_must_be_vertical():
    err = _chain_error([("j1", "revolute", O3, O3, Y), ("j2", "revolute", (0.1, 0, 0), O3, Y)])
    assert err.joint == "j1"
    assert "'j1'" in str(err) and "vertical" in str(err)


def test_a_single_pitch_joint_is_named():
    err = _chain_error(
        [
            ("yaw", "revolute", O3, O3, Z),
            ("pitch", "revolute", (0, 0, 0.1), O3, Y),
            ("roll", "revolute", (0.1, 0, 0), O3, X),
        ]
    )
    assert err.joint == "roll"


def test_a_fourth_pitch_joint_is_named():
    joints = [("yaw", "revolute", O3, O3, Z)] + [(f"p{k}", "revolute", (0.1 * (k > 0), 0, 0), O3, Y) for k in range(4)]
    err = _chain_error(joints)
    assert err.joint == "p3"
    assert "fourth" in str(err)


def test_a_joint_after_the_roll_is_named():
    joints = [
        ("yaw", "revolute", O3, O3, Z),
        ("p0", "revolute", (0, 0, 0.1), O3, Y),
        ("p1", "revolute", (0.1, 0, 0), O3, Y),
        ("roll", "revolute", (0.1, 0, 0), O3, X),
        ("extra", "revolute", (0.05, 0, 0), O3, Y),
    ]
    assert _chain_error(joints).joint == "extra"


def test_a_skew_joint_is_named():
    skew = (0.0, 1 / math.sqrt(2), 1 / math.sqrt(2))
    joints = [
        ("yaw", "revolute", O3, O3, Z),
        ("p0", "revolute", (0, 0, 0.1), O3, Y),
        ("p1", "revolute", (0.1, 0, 0), O3, Y),
        ("skew", "revolute", (0.1, 0, 0), O3, skew),
    ]
    err = _chain_error(joints)
    assert err.joint == "skew"
    assert "neither parallel" in str(err)


def test_a_tilted_second_joint_is_named():
    tilted = (0.0, 1 / math.sqrt(2), 1 / math.sqrt(2))
    assert _chain_error([("yaw", "revolute", O3, O3, Z), ("t", "revolute", (0, 0, 0.1), O3, tilted)]).joint == "t"


def test_a_prismatic_joint_is_named():
    joints = [
        ("yaw", "revolute", O3, O3, Z),
        ("slide", "prismatic", (0, 0, 0.1), O3, Z),
        ("p1", "revolute", (0.1, 0, 0), O3, Y),
    ]
    err = _chain_error(joints)
    assert err.joint == "slide"
    assert "prismatic" in str(err)


def test_three_vertical_joints_are_not_planar2():
    joints = [(f"v{k}", "revolute", (0.1 * (k > 0), 0, 0), O3, Z) for k in range(3)]
    assert _chain_error(joints).joint == "v2"


@pytest.mark.parametrize(("name", "joint"), [("ur5", "wrist_3_joint"), ("panda", "panda_joint3")])
def test_example_arms_outside_the_family(name, joint):
    if example_robot_data_dir() is None:
        pytest.skip("example-robot-data is not installed")
    with pytest.raises(UnsupportedChainError) as info:
        closed_form_solver(load_robot(name))
    assert info.value.joint == joint


def test_so101_fits_the_family_within_round_off():
    if example_robot_data_dir() is None:
        pytest.skip("example-robot-data is not installed")
    solver = closed_form_solver(load_robot("so101"))
    info = solver.describe()
    assert (info["n_pitch"], info["has_roll"]) == (3, True)
    # Its URDF's axes are off the ideal directions by micro-radians: corrected, not exact.
    assert not info["exact"] and 1e-7 < info["deviation"] < 1e-5
    assert not info["tip_on_roll_axis"]  # the gripper frame sits ~8 mm off the roll axis


# ---------------------------------------------------------------------------- results
def test_results_are_frozen(solvers, robots):
    res = solvers["dh3"].solve(Target(fk_position(robots["dh3"], np.radians([10, 40, 60]))))
    sol = res.solutions[0]
    with pytest.raises(ValueError):
        sol.q[0] = 1.0
    with pytest.raises(AttributeError):
        sol.q = np.zeros(3)
    with pytest.raises(AttributeError):
        res.status = "solved"
    assert isinstance(res.solutions, tuple)
    assert res.ok and res.best is res.solutions[0]


def test_status_names_and_codes():
    assert STATUS_NAMES[STATUS_CODES[STATUS_SOLVED]] == STATUS_SOLVED
    assert STATUS_CODES[STATUS_SOLVED] == 0 and all(isinstance(name, IKStatus) for name in STATUS_NAMES)
    assert set(STATUS_NAMES) == {
        "solved",
        "outside_joint_limits",
        "orientation_not_achievable",
        "beyond_max_reach",
        "inside_min_reach",
        "out_of_plane",
    }


def test_public_names_resolve():
    for name in analytic.__all__:
        assert getattr(analytic, name) is not None
    for name in ("AnalyticIK", "AnalyticResult", "AnalyticSolution", "AnalyticBatchResult"):
        assert name in planner.__all__ and getattr(planner, name) is getattr(analytic, name)
    assert "solve_analytic" in planner.__all__  # a thin wrapper of solve_ik


def test_solve_analytic_matches_the_solver(robots, solvers):
    target = Target(fk_position(robots["three_joint"], [0.3, 0.8, -0.6, 0.2]), pitch=-0.3)
    a = solve_analytic(robots["three_joint"], target)
    b = solvers["three_joint"].solve(target)
    assert a.method == "analytic"
    assert [s.label for s in a.solutions] == [s.branch for s in b.solutions]
    for sa, sb in zip(a.solutions, b.solutions):
        np.testing.assert_array_equal(sa.q, sb.q)


def test_bad_inputs_raise(solvers):
    s = solvers["al5c"]
    with pytest.raises(InvalidArgumentError, match="planner.Target"):
        s.solve([0.2, 0.0, 0.1])
    with pytest.raises(InvalidConfigurationError, match=r"expects \(5,\)"):
        s.solve(Target([0.2, 0.0, 0.1]), q_current=[0.0, 0.0])
    with pytest.raises(InvalidConfigurationError, match="finite"):
        s.solve(Target([0.2, 0.0, 0.1]), q_current=[0.0, 0.0, math.nan, 0.0, 0.0])
    with pytest.raises(InvalidArgumentError):
        closed_form_solver("al5c")


# ---------------------------------------------------------------------------- branches
def test_four_branches_for_a_yaw_two_link_arm(robots, solvers):
    robot = robots["dh3"]
    target = Target(fk_position(robot, np.radians([30, 50, 70])))
    res = solvers["dh3"].solve(target)
    assert res.status == STATUS_SOLVED
    assert sorted(s.branch for s in res.solutions) == sorted(BRANCHES)
    assert len({tuple(np.round(s.q, 9)) for s in res.solutions}) == 4
    for sol in res.solutions:
        assert np.linalg.norm(fk_position(robot, sol.q) - target.position) < TOL_POS
        assert not sol.singular


def test_fewer_branches_at_the_boundary_and_none_outside(robots, solvers):
    robot, solver = robots["dh3"], solvers["dh3"]
    stretched = Target(fk_position(robot, np.radians([20, 35, 0])))  # elbow straight: max reach
    res = solver.solve(stretched)
    assert len(res.solutions) == 2
    assert {s.branch for s in res.solutions} == {"front/elbow-up", "back/elbow-up"}
    assert res.singular and all(s.singular for s in res.solutions)
    for sol in res.solutions:
        assert np.all(np.isfinite(sol.q))
        assert np.linalg.norm(fk_position(robot, sol.q) - stretched.position) < TOL_POS
    outside = solver.solve(Target(stretched.position * 1.01))
    assert outside.status == STATUS_BEYOND_MAX_REACH and outside.solutions == ()
    assert outside.best is None


def test_four_branches_with_a_pitch_on_a_three_link_arm(robots, solvers):
    robot = robots["three_joint"]
    q = np.array([0.4, 0.9, -1.1, 0.3])
    res = solvers["three_joint"].solve(Target(fk_position(robot, q), pitch=0.9 - 1.1 + 0.3))
    assert len(res.solutions) == 4
    assert any(np.allclose(s.q, q, atol=1e-9) for s in res.solutions)


def test_solutions_sorted_by_distance_to_q_current(robots, solvers):
    robot, solver = robots["dh3"], solvers["dh3"]
    target = Target(fk_position(robot, np.radians([30, 50, 70])))
    for sol in solver.solve(target).solutions:
        res = solver.solve(target, q_current=sol.q)
        np.testing.assert_allclose(res.solutions[0].q, sol.q, atol=1e-9)
        dists = [np.linalg.norm(s.q - sol.q) for s in res.solutions]
        assert dists == sorted(dists)
        if sol.within_limits:
            assert res.best is res.solutions[0]


def test_angles_wrap_towards_q_current(robots, solvers):
    # three_joint's yaw spans -180..180 deg: a target behind the base gives +pi or -pi.
    solver = solvers["three_joint"]
    target = Target([-6.0, 0.0, 1.0], pitch=0.0)
    up = solver.solve(target, q_current=[3.0, 0.5, -0.5, 0.0]).solutions[0]
    down = solver.solve(target, q_current=[-3.0, 0.5, -0.5, 0.0]).solutions[0]
    assert up.q[0] == pytest.approx(math.pi, abs=1e-9) and down.q[0] == pytest.approx(-math.pi, abs=1e-9)
    assert up.within_limits and down.within_limits


def test_every_angle_in_range_when_an_equivalent_exists(robots, solvers):
    rng = np.random.default_rng(11)
    for name in ("al5c", "three_joint", "dh3"):
        robot, solver = robots[name], solvers[name]
        for q in robot.random_configurations(rng, 30):
            res = solver.solve(Target(fk_position(robot, q)), q_current=q)
            for sol in res.solutions:
                for v, lo, hi in zip(sol.q, robot.lower, robot.upper):
                    if not lo <= v <= hi:
                        shifted = v + 2 * np.pi * np.arange(-3, 4)
                        assert not np.any((shifted >= lo) & (shifted <= hi))
                assert sol.within_limits == bool(robot.within_limits(sol.q))


def test_outside_joint_limits_names_the_joint_and_amount(robots, solvers):
    # shelley: a target behind the base; both branches need servo 1 beyond +-92.5 deg.
    robot, solver = robots["shelley"], solvers["shelley"]
    res = solver.solve(Target([-0.15, 0.0, 0.0]))
    assert res.status == STATUS_OUTSIDE_JOINT_LIMITS and len(res.solutions) == 2
    assert res.best is None
    for sol in res.solutions:
        assert not sol.within_limits
        assert np.linalg.norm(fk_position(robot, sol.q) - [-0.15, 0.0, 0.0]) < TOL_POS
        v = sol.q[0]
        excess = math.degrees(abs(v)) - 92.5
        assert f"joint 'servo1' needs {v:.4f} rad ({math.degrees(v):.2f} deg)" in res.reason
        assert f"({excess:.2f} deg)" in res.reason


def test_orientation_not_achievable_without_a_wrist(robots, solvers):
    robot, solver = robots["dh3"], solvers["dh3"]
    q = np.radians([30, 50, 70])
    pose = robot.fk(q)
    ok = solver.solve(Target.from_pose(pose))
    assert ok.status == STATUS_SOLVED and any(np.allclose(s.q, q, atol=1e-9) for s in ok.solutions)
    tilted = pose.copy()
    tilted[:3, :3] = pose[:3, :3] @ planner.rpy_to_matrix([0.3, 0.0, 0.0])
    res = solver.solve(Target.from_pose(tilted))
    assert res.status == STATUS_ORIENTATION_NOT_ACHIEVABLE and res.solutions == ()
    res = solver.solve(Target(pose[:3, 3], pitch=1.0))
    assert res.status == STATUS_ORIENTATION_NOT_ACHIEVABLE
    assert "no wrist pitch joint" in res.reason


def test_free_roll_takes_q_current(robots, solvers):
    robot, solver = robots["al5c"], solvers["al5c"]
    q = np.array([0.3, 1.0, -1.2, -0.4, 0.7])
    target = Target(fk_position(robot, q), pitch=1.0 - 1.2 - 0.4)
    assert all(s.q[4] == 0.0 for s in solver.solve(target).solutions)
    assert all(s.q[4] == 0.7 for s in solver.solve(target, q_current=q).solutions)


def test_inside_min_reach_near_the_shoulder(robots, solvers):
    solver = solvers["three_joint"]
    # The wrist centre (-1.5, 0.2) is 1.51 m from the shoulder: the links fold that far only with
    # the elbow beyond its 150 deg (Materick and Shapiro's (1997) minimum reach from the elbow's range: 2.07 m).
    res = solver.solve(Target([0.5, 0.0, 0.2], pitch=0.0))
    assert res.status == STATUS_INSIDE_MIN_REACH
    assert "closer than joint 'elbow''s range" in res.reason
    assert res.solutions and not any(s.within_limits for s in res.solutions)
    assert solver.describe()["elbow_reach"][0] == pytest.approx(math.sqrt(32 + 32 * math.cos(math.radians(150))))
    # Closer than |L1 - L2| = 0 is impossible; closer than the tip link is geometry alone.
    res = solver.solve(Target([0.0, 0.0, 0.0], pitch=0.0), q_current=[0.0, 0.0, 0.0, 0.0])
    assert res.status == STATUS_INSIDE_MIN_REACH


# ---------------------------------------------------------------------------- lateral offset
def offset_arm() -> Robot:
    """Yaw + 3 pitch + roll with every in-plane and sideways offset, tip off the roll axis."""
    joints = [
        ("yaw", "revolute", (0.01, -0.02, 0.05), O3, Z),
        ("shoulder", "revolute", (0.02, 0.03, 0.06), O3, Y),
        ("elbow", "revolute", (0.15, -0.01, 0.02), O3, Y),
        ("wrist", "revolute", (0.12, 0.015, -0.01), O3, (0, -1, 0)),
        ("roll", "revolute", (0.03, 0.0, 0.005), O3, X),
    ]
    urdf = serial_urdf(joints, tip_xyz=(0.06, 0.004, -0.012), name="offset_arm")
    return Robot(urdf, tip="tip", approach_axis=(1.0, 0.0, 0.0))


def test_offset_arm_is_exact_and_reads_its_offsets():
    solver = closed_form_solver(offset_arm())
    info = solver.describe()
    assert info["exact"] and info["n_pitch"] == 3 and info["has_roll"]
    signs = info["pitch_signs"]
    assert signs[1] == signs[0] and signs[2] == -signs[0]
    assert info["yaw_axis_point"] == pytest.approx([0.01, -0.02])
    # Sideways offset of the tip at roll 0: 0.03 - 0.01 + 0.015 + 0 + 0.004 (along +y, n = -y).
    assert abs(info["lateral_offset"]) == pytest.approx(0.039 - 0.0, abs=1e-12)


def test_offset_arm_inside_its_sideways_offset():
    solver = closed_form_solver(offset_arm())
    res = solver.solve(Target([0.01, -0.02, 0.25], pitch=0.0))
    assert res.status == STATUS_INSIDE_MIN_REACH
    assert "sideways offset" in res.reason


def test_pitch_outward_from_the_base_axis_not_the_yaw_axis():
    # offset_arm's yaw axis stands 22 mm from the base z axis. For targets whose arm-plane
    # direction points away from the yaw axis but towards the base z axis, "outward" (the
    # planner.geometry.target convention) is the other side: the approach axis's in-plane angle is
    # pi - pitch there. Every solution follows the convention, in single and batch calls.
    robot = offset_arm()
    solver = closed_form_solver(robot)
    q_all = robot.random_configurations(np.random.default_rng(12), 4000)
    poses = robot.fk(q_all)
    yaw_point = np.array(solver.describe()["yaw_axis_point"])
    plane = np.array([np.cross([0.0, 0.0, 1.0], robot.jacobian(q)[3:, 1])[:2] for q in q_all])
    from_yaw = np.sum((poses[:, :2, 3] - yaw_point) * plane, axis=1)
    from_base = np.sum(poses[:, :2, 3] * plane, axis=1)
    flipped = np.nonzero(np.sign(from_yaw) != np.sign(from_base))[0][:25]
    assert len(flipped) == 25
    q_sel = q_all[flipped]
    pitch = approach_pitch(robot, q_sel)
    batch = solver.solve_batch(poses[flipped, :3, 3], pitch=pitch, q_current=q_sel)
    for i, q in enumerate(q_sel):
        target = Target(poses[flipped[i], :3, 3], pitch=float(pitch[i]))
        res = solver.solve(target, q_current=q)
        assert res.status == STATUS_SOLVED and any(np.allclose(s.q, q, atol=1e-9) for s in res.solutions)
        for sol in res.solutions:
            got = robot.fk(sol.q)
            a = got[:3, :3] @ robot.approach_axis
            assert np.linalg.norm(got[:3, 3] - target.position) < TOL_POS
            assert math.cos(target.pitch) * (a[:2] @ target.position[:2]) >= 0.0
            assert pitch_error(a, target.position, target.pitch) < 1e-9
            assert sol.orientation_error < 1e-9
            np.testing.assert_allclose(batch.q[i, solver.branches.index(sol.branch)], sol.q, atol=1e-12)


# ---------------------------------------------------------------------------- batches
@pytest.mark.parametrize("name", ["dh3", "three_joint", "al5c", "shelley"])
def test_batch_agrees_with_single_solves(name, robots, solvers):
    robot, solver = robots[name], solvers[name]
    rng = np.random.default_rng(5)
    q = robot.random_configurations(rng, 40)
    poses = robot.fk(q)
    pos = poses[:, :3, 3]
    pos[::7] *= 3.0  # some unreachable
    pitch = rng.uniform(-1.5, 1.5, 40)
    pitch[::3] = 0.0
    for rot, pit in ((None, None), (poses[:, :3, :3], None), (None, pitch)):
        batch = solver.solve_batch(pos, pitch=pit, rotations=rot, q_current=q)
        assert batch.q.shape == (40, len(solver.branches), robot.dof)
        assert batch.branches == solver.branches
        assert not batch.q.flags.writeable
        for i in range(40):
            target = Target(pos[i], rotation=None if rot is None else rot[i], pitch=None if pit is None else pit[i])
            single = solver.solve(target, q_current=q[i])
            assert STATUS_NAMES[batch.status[i]] == single.status
            got = batch.q[i][batch.valid[i]]
            assert len(got) == len(single.solutions)
            assert np.all(np.isnan(batch.q[i][~batch.valid[i]]))
            for sol in single.solutions:
                k = solver.branches.index(sol.branch)
                np.testing.assert_allclose(batch.q[i, k], sol.q, atol=1e-12)
                assert batch.within_limits[i, k] == sol.within_limits
                assert batch.singular[i, k] == sol.singular
            if single.best is None:
                assert batch.best[i] == -1 and np.all(np.isnan(batch.best_q[i]))
            else:
                np.testing.assert_allclose(batch.best_q[i], single.best.q, atol=1e-12)


@pytest.mark.parametrize("name", ["al5c", "offset_arm", "so101"])
def test_batch_searches_free_joints_like_single_solves(name):
    # Random q_current: its approach pitch (and roll, which moves offset_arm's and so101's tip)
    # often leaves no branch within the limits; batch and single calls search alike.
    if name == "so101" and example_robot_data_dir() is None:
        pytest.skip("example-robot-data is not installed")
    robot = offset_arm() if name == "offset_arm" else load_robot(name)
    solver = closed_form_solver(robot)
    rng = np.random.default_rng(3)
    q, q_current = robot.random_configurations(rng, 30), robot.random_configurations(rng, 30)
    pos = robot.position(q)
    kinds = [None] if name == "al5c" else [None, approach_pitch(robot, q)]
    searched = 0
    for pitch in kinds:
        batch = solver.solve_batch(pos, pitch=pitch, q_current=q_current)
        assert np.all(batch.status == STATUS_CODES[STATUS_SOLVED])  # FK targets: always within reach
        for i in range(len(q)):
            target = Target(pos[i], pitch=None if pitch is None else float(pitch[i]))
            single = solver.solve(target, q_current=q_current[i])
            assert single.status == STATUS_SOLVED
            got = batch.q[i][batch.valid[i]]
            assert len(got) == len(single.solutions)
            for sol in single.solutions:
                k = solver.branches.index(sol.branch)
                np.testing.assert_allclose(batch.q[i, k], sol.q, atol=1e-9)
                assert batch.within_limits[i, k] == sol.within_limits == bool(robot.within_limits(sol.q))
            np.testing.assert_allclose(batch.best_q[i], single.best.q, atol=1e-9)
            # The search ran where the best solution left q_current's free joints.
            best = single.best.q
            moved_roll = solver.has_roll and abs(best[-1] - q_current[i, -1]) > 1e-9
            moved_pitch = (
                pitch is None
                and abs(
                    (approach_pitch(robot, best) - approach_pitch(robot, q_current[i]) + math.pi) % (2 * math.pi)
                    - math.pi
                )
                > 1e-6
            )
            searched += (moved_roll and name != "al5c") or moved_pitch
    assert searched >= 5


def test_batch_pitch_targets_reproduce_the_target(robots, solvers):
    robot, solver = robots["three_joint"], solvers["three_joint"]
    q = robot.random_configurations(np.random.default_rng(8), 200)
    poses = robot.fk(q)
    approach = poses[:, :3, :3] @ robot.approach_axis
    radial = poses[:, :2, 3] / np.linalg.norm(poses[:, :2, 3], axis=1)[:, None]
    pitch = np.arctan2(approach[:, 2], np.sum(approach[:, :2] * radial, axis=1))
    batch = solver.solve_batch(poses[:, :3, 3], pitch=pitch)
    assert np.all(batch.status == STATUS_CODES[STATUS_SOLVED])
    sol = batch.q[batch.valid]
    target = np.repeat(poses[:, None, :3, 3], 4, axis=1)[batch.valid]
    assert np.max(np.linalg.norm(robot.position(sol) - target, axis=1)) < TOL_POS
    assert np.nanmax(batch.position_error) < TOL_POS
    wrapped = np.abs((batch.q - q[:, None, :] + np.pi) % (2 * np.pi) - np.pi).max(axis=2)
    assert np.all(np.nanmin(wrapped, axis=1) < 1e-9)


def test_batch_input_errors(solvers):
    s = solvers["al5c"]
    with pytest.raises(InvalidArgumentError, match=r"shape \(N, 3\)"):
        s.solve_batch(np.zeros((4, 2)))
    with pytest.raises(InvalidArgumentError, match="not both"):
        s.solve_batch(np.zeros((2, 3)), pitch=0.0, rotations=np.broadcast_to(np.eye(3), (2, 3, 3)))
    with pytest.raises(InvalidArgumentError, match=r"shape \(3,\)"):
        s.solve_batch(np.zeros((3, 3)), pitch=np.zeros(2))
    with pytest.raises(InvalidArgumentError, match="not finite"):
        s.solve_batch(np.array([[0.1, 0.0, np.nan]]))
    with pytest.raises(InvalidArgumentError, match="orthonormal"):
        s.solve_batch(np.zeros((1, 3)), rotations=np.full((1, 3, 3), 0.5))
    with pytest.raises(InvalidConfigurationError, match=r"\(5,\) or \(2, 5\)"):
        s.solve_batch(np.zeros((2, 3)), q_current=np.zeros((3, 5)))
    empty = s.solve_batch(np.zeros((0, 3)), pitch=0.0)
    assert empty.q.shape == (0, 4, 5) and empty.status.shape == (0,)


# ---------------------------------------------------------------------------- servo units (Materick and Shapiro 1997)
def test_shelley_solutions_in_servo_steps(robots, solvers):
    robot, solver = robots["shelley"], solvers["shelley"]
    travel = math.radians(92.5)
    for target in ([0.15, 0.02, 0.0], [0.12, -0.06, 0.0], [0.0, 0.16, 0.0]):
        best = solver.solve(Target(target)).best
        steps = angle_to_steps(best.q, travel, 1400)
        back = steps_to_angle(steps, travel, 1400)
        assert np.all(np.abs(back - best.q) <= 0.5 * travel / 1400 + 1e-15)
        # a step is ~1.2 mrad: the tip lands within (r1 + r2) * half a step per joint of the target
        assert np.linalg.norm(fk_position(robot, back) - target) < 0.19 * 2 * 0.5 * travel / 1400


def test_position_only_searches_another_pitch_within_limits(robots, solvers):
    # al5c, straight out from the shoulder the wrist would need more than its +-90 deg: with
    # q_current's approach pitch no branch fits the limits; each branch takes the approach pitch
    # nearest q_current's that puts it within them.
    robot, solver = robots["al5c"], solvers["al5c"]
    target = Target([0.071, 0.026, 0.008])
    q_current = np.array([0.3, 1.0, -1.2, 0.2, 0.0])
    preferred = approach_pitch(robot, q_current)
    assert not solver.solve(Target(target.position, pitch=preferred), q_current).ok
    res = solver.solve(target, q_current)
    assert res.status == STATUS_SOLVED
    within = [s for s in res.solutions if s.within_limits]
    assert within and res.best is within[0]
    step = math.radians(0.05)
    for sol in within:
        assert np.linalg.norm(fk_position(robot, sol.q) - target.position) < TOL_POS
        assert sol.orientation_error is None and robot.within_limits(sol.q)
        # No approach pitch nearer q_current's puts this branch within the limits (0.05 deg scan).
        offset = approach_pitch(robot, sol.q) - preferred
        offset = (offset + math.pi) % (2 * math.pi) - math.pi
        for p in preferred + np.arange(0.0, abs(offset) - 1e-6, step) * np.sign(offset):
            same = [
                s for s in solver.solve(Target(target.position, pitch=p), q_current).solutions if s.branch == sol.branch
            ]
            assert not any(s.within_limits for s in same), (sol.branch, p)
    # Without q_current, from the default pitch; the batch finds the same.
    res = solver.solve(target)
    assert res.status == STATUS_SOLVED and robot.within_limits(res.best.q)
    batch = solver.solve_batch(target.position[None])
    assert STATUS_NAMES[batch.status[0]] == STATUS_SOLVED
    np.testing.assert_allclose(batch.best_q[0], res.best.q, atol=1e-12)


def test_position_only_without_any_pitch_within_limits(solvers):
    # Far below the shoulder and behind it: reachable by the links, but the shoulder would have
    # to turn below its 5 deg (or the base beyond its 90 deg) for every approach pitch.
    solver = solvers["al5c"]
    for position in ([0.15, 0.0, -0.25], [-0.2, 0.0, -0.1]):
        res = solver.solve(Target(position))
        assert res.status == STATUS_OUTSIDE_JOINT_LIMITS and res.solutions and res.best is None
        assert "no other approach pitch brings a branch within them" in res.reason
        for p in np.radians(np.arange(-180.0, 180.0, 0.5)):
            assert not solver.solve(Target(position, pitch=p)).ok


def test_continuous_joints():
    joints = [
        ("yaw", "continuous", O3, O3, Z),
        ("shoulder", "revolute", (0, 0, 0.1), O3, Y),
        ("elbow", "revolute", (0.2, 0, 0), O3, Y),
        ("roll", "continuous", (0.15, 0, 0), O3, X),
    ]
    robot = Robot(serial_urdf(joints, tip_xyz=(0.05, 0.0, 0.0)), tip="tip", approach_axis=(1.0, 0.0, 0.0))
    assert robot.joint_kinds == ("continuous", "revolute", "revolute", "continuous")
    solver = closed_form_solver(robot)
    assert solver.n_pitch == 2 and solver.has_roll
    for q in robot.random_configurations(np.random.default_rng(9), 20):
        q = q + np.array([4 * np.pi, 0.0, 0.0, -2 * np.pi])  # far from the principal values
        pose = robot.fk(q)
        res = solver.solve(Target.from_pose(pose), q_current=q)
        assert res.status == STATUS_SOLVED
        # Unbounded joints take the equivalent angle nearest q_current.
        np.testing.assert_allclose(res.solutions[0].q, q, atol=1e-9)
        for sol in res.solutions:
            assert np.linalg.norm(robot.fk(sol.q)[:3, 3] - pose[:3, 3]) < TOL_POS
            assert planner.rotation_error(robot.fk(sol.q)[:3, :3], pose[:3, :3]) < 1e-9


def test_pose_target_next_to_the_yaw_axis(robots, solvers):
    # The wrist centre 1e-9 m from the yaw axis: the position barely fixes the yaw, the
    # rotation does; the pose is reached and q is among the solutions.
    robot, solver = robots["al5c"], solvers["al5c"]
    l1, l2, a = 0.14605, 0.187325, 2.0
    for eps in (1e-6, 1e-9, 0.0):
        elbow = -(a - math.acos((eps - l1 * math.cos(a)) / l2))
        q = np.array([0.3, a, elbow, 0.4, 0.2])
        assert robot.within_limits(q)
        pose = robot.fk(q)
        res = solver.solve(Target.from_pose(pose))
        assert res.status == STATUS_SOLVED
        assert any(np.allclose(s.q, q, atol=1e-9) for s in res.solutions)
        for sol in res.solutions:
            got = robot.fk(sol.q)
            assert np.linalg.norm(got[:3, 3] - pose[:3, 3]) < TOL_POS
            assert planner.rotation_error(got[:3, :3], pose[:3, :3]) < 1e-9
