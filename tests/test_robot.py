"""The Pinocchio robot model: FK against independent formulas, Jacobian, manipulability, limits."""

from __future__ import annotations

import concurrent.futures
import copy
import math
import multiprocessing
import pickle

import numpy as np
import pinocchio as pin
import pytest

import planner

from conftest import BUNDLED, get_robot

RNG_SEED = 20261122


# --------------------------------------------------------------------------- FK vs the seeds
def dh3_seed_fk(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sumadsad's (2020) closed-form forward model (its 'Full Model'), in cm."""
    t1, t2, t3 = q
    c1, s1 = math.cos(t1), math.sin(t1)
    c23, s23 = math.cos(t2 - t3), math.sin(t2 - t3)
    reach = 6 * math.cos(t2) + 11 * c23
    position = np.array([c1 * reach, s1 * reach, 6 * math.sin(t2) + 11 * s23 + 3])
    rotation = np.array([[c1 * c23, c1 * s23, -s1], [s1 * c23, s1 * s23, c1], [s23, -c23, 0.0]])
    return position, rotation


def test_dh3_matches_seed_closed_form_at_random_angles():
    robot = get_robot("dh3")
    rng = np.random.default_rng(RNG_SEED)
    for q in rng.uniform(-math.pi, math.pi, size=(500, 3)):
        pose = robot.fk(q) if robot.within_limits(q) else None
        if pose is None:  # FK is defined beyond the limits too; compute it for the whole circle
            pose = robot.fk(q)
        position_cm, rotation = dh3_seed_fk(q)
        np.testing.assert_allclose(pose[:3, 3] * 100, position_cm, atol=1e-12 * 100)
        np.testing.assert_allclose(pose[:3, :3], rotation, atol=1e-12)


def test_dh3_seed_worked_example():
    robot = get_robot("dh3")
    position_cm = robot.position(np.radians([45, 90, 90])) * 100
    np.testing.assert_allclose(np.round(position_cm, 2), [7.78, 7.78, 9.0])


def planar_chain(yaw: float, pitches: list[float], lengths: list[float], height: float) -> np.ndarray:
    """Yaw, then a chain of pitch joints in the vertical plane, each angle relative to the last link."""
    radial, z, angle = 0.0, height, 0.0
    for pitch, length in zip(pitches, lengths):
        angle += pitch
        radial += length * math.cos(angle)
        z += length * math.sin(angle)
    return np.array([radial * math.cos(yaw), radial * math.sin(yaw), z])


def test_three_joint_matches_plane_geometry():
    robot = get_robot("three_joint")
    rng = np.random.default_rng(RNG_SEED)
    for q in robot.random_configurations(rng, 200):
        pose = robot.fk(q)
        np.testing.assert_allclose(pose[:3, 3], planar_chain(q[0], list(q[1:]), [4.0, 4.0, 2.0], 0.0), atol=1e-12)
        # The gripper (tip x axis) points at pitch alpha = theta2 + theta3 + theta4.
        alpha = q[1] + q[2] + q[3]
        expected = [math.cos(alpha) * math.cos(q[0]), math.cos(alpha) * math.sin(q[0]), math.sin(alpha)]
        np.testing.assert_allclose(pose[:3, 0], expected, atol=1e-12)


def test_al5c_matches_plane_geometry():
    robot = get_robot("al5c")
    h0, l1, l2, l3 = 0.06731, 0.14605, 0.187325, 0.100
    rng = np.random.default_rng(RNG_SEED)
    for q in robot.random_configurations(rng, 200):
        pose = robot.fk(q)
        np.testing.assert_allclose(pose[:3, 3], planar_chain(q[0], list(q[1:4]), [l1, l2, l3], h0), atol=1e-12)
        pitch = q[1] + q[2] + q[3]
        approach = [math.cos(pitch) * math.cos(q[0]), math.cos(pitch) * math.sin(q[0]), math.sin(pitch)]
        np.testing.assert_allclose(pose[:3, :3] @ robot.approach_axis, approach, atol=1e-12)


def test_al5c_wrist_rotate_does_not_move_the_gripper_point():
    robot = get_robot("al5c")
    q = np.radians([20, 60, -100, -30, 0])
    for roll in np.radians([-90, -30, 45, 90]):
        q2 = q.copy()
        q2[4] = roll
        np.testing.assert_allclose(robot.position(q2), robot.position(q), atol=1e-15)


def test_shelley_matches_two_circle_geometry():
    robot = get_robot("shelley")
    rng = np.random.default_rng(RNG_SEED)
    for a1, a2 in robot.random_configurations(rng, 200):
        elbow = 0.10 * np.array([math.cos(a1), math.sin(a1)])
        c, s = math.cos(a1 + a2), math.sin(a1 + a2)
        claw = elbow + np.array([c * 0.08 - s * 0.01, s * 0.08 + c * 0.01])
        np.testing.assert_allclose(robot.position([a1, a2]), [*claw, 0.0], atol=1e-15)


def test_batched_fk_equals_single_calls(bundled_robot):
    rng = np.random.default_rng(RNG_SEED)
    q = bundled_robot.random_configurations(rng, 20)
    batch = bundled_robot.fk(q)
    assert batch.shape == (20, 4, 4)
    for k in range(20):
        np.testing.assert_array_equal(batch[k], bundled_robot.fk(q[k]))
    assert bundled_robot.position(q).shape == (20, 3)
    assert bundled_robot.fk(np.empty((0, bundled_robot.dof))).shape == (0, 4, 4)


# --------------------------------------------------------------------------- Jacobian
@pytest.mark.parametrize("name", BUNDLED)
def test_jacobian_equals_central_finite_differences(name):
    robot = get_robot(name)
    rng = np.random.default_rng(RNG_SEED)
    h = 1e-6
    for q in robot.random_configurations(rng, 10):
        jac = robot.jacobian(q)
        assert jac.shape == (6, robot.dof)
        fd = np.empty_like(jac)
        for i in range(robot.dof):
            dq = np.zeros(robot.dof)
            dq[i] = h
            plus, minus = robot.fk(q + dq), robot.fk(q - dq)
            fd[:3, i] = (plus[:3, 3] - minus[:3, 3]) / (2 * h)
            fd[3:, i] = pin.log3(plus[:3, :3] @ minus[:3, :3].T) / (2 * h)
        scale = max(1.0, float(np.max(np.abs(jac))))
        np.testing.assert_allclose(jac, fd, atol=1e-7 * scale)


def test_jacobian_local_frame_is_rotated_world_aligned():
    robot = get_robot("al5c")
    q = np.radians([30, 50, -80, 20, 10])
    rot = robot.fk(q)[:3, :3]
    aligned = robot.jacobian(q)
    local = robot.jacobian(q, reference="local")
    np.testing.assert_allclose(local[:3], rot.T @ aligned[:3], atol=1e-12)
    np.testing.assert_allclose(local[3:], rot.T @ aligned[3:], atol=1e-12)
    with pytest.raises(planner.InvalidArgumentError, match="unknown reference 'body'; valid: world, local"):
        robot.jacobian(q, reference="body")


# --------------------------------------------------------------------------- manipulability
def test_manipulability_is_zero_fully_stretched_and_positive_inside():
    robot = get_robot("dh3")
    for t1, t2 in [(0.0, 0.0), (0.7, -0.4), (-1.2, 1.1)]:
        stretched = np.array([t1, t2, 0.0])  # theta3 = 0: the 11 cm link continues the 6 cm link
        assert robot.manipulability(stretched) == pytest.approx(0.0, abs=1e-9)
        assert robot.inverse_condition_number(stretched) == pytest.approx(0.0, abs=1e-7)
    rng = np.random.default_rng(RNG_SEED)
    q = robot.random_configurations(rng, 200)
    q = q[np.abs(np.sin(q[:, 2])) > 0.05]  # away from stretched / folded
    q = q[np.abs(6 * np.cos(q[:, 1]) + 11 * np.cos(q[:, 1] - q[:, 2])) > 0.5]  # wrist away from the base axis
    w = robot.manipulability(q)
    assert w.shape == (len(q),) and np.all(w > 0)
    ic = robot.inverse_condition_number(q)
    assert np.all((ic > 0) & (ic <= 1))


def test_manipulability_equals_yoshikawa_formula(bundled_robot):
    rng = np.random.default_rng(RNG_SEED)
    for q in bundled_robot.random_configurations(rng, 5):
        jac = bundled_robot.jacobian(q)[:3]
        gram = jac @ jac.T if jac.shape[0] <= jac.shape[1] else jac.T @ jac
        expected = math.sqrt(abs(np.linalg.det(gram)))
        assert bundled_robot.manipulability(q) == pytest.approx(expected, rel=1e-9, abs=1e-15)


def test_planar_two_link_manipulability_is_r1_r2_sin_elbow_without_offset():
    urdf = planner.urdf_from_dh(
        {
            "name": "two",
            "velocity": 1.0,
            "dh": [
                {"a": 0.1, "d": 0, "alpha": 0, "lower": -3, "upper": 3},
                {"a": 0.08, "d": 0, "alpha": 0, "lower": -3, "upper": 3},
            ],
        }
    )
    robot = planner.Robot(urdf)
    for a2 in [0.3, 1.0, -2.0]:
        assert robot.manipulability([0.4, a2]) == pytest.approx(0.1 * 0.08 * abs(math.sin(a2)), rel=1e-12)


# --------------------------------------------------------------------------- limits, sampling
def test_limits_are_read_only_and_match_the_urdf():
    robot = get_robot("shelley")
    for arr in (robot.lower, robot.upper, robot.velocity_limit, robot.approach_axis):
        with pytest.raises(ValueError):
            arr[0] = 0.0
    np.testing.assert_allclose(robot.upper, np.radians([92.5, 92.5]))
    np.testing.assert_allclose(robot.velocity_limit, [math.radians(60) / 0.20] * 2)


def test_random_configurations_use_only_the_given_generator(bundled_robot):
    state = np.random.get_state()
    a = bundled_robot.random_configurations(np.random.default_rng(7), 100)
    b = bundled_robot.random_configurations(np.random.default_rng(7), 100)
    np.testing.assert_array_equal(a, b)
    assert np.all(bundled_robot.within_limits(a))
    assert bundled_robot.random_configurations(np.random.default_rng(7)).shape == (bundled_robot.dof,)
    after = np.random.get_state()
    assert state[0] == after[0] and np.array_equal(state[1], after[1]) and state[2:] == after[2:]


def test_random_configurations_need_a_generator():
    with pytest.raises(planner.InvalidArgumentError, match="rng must be a numpy.random.Generator"):
        get_robot("dh3").random_configurations(42, 3)


def test_check_limits_names_the_joint():
    robot = get_robot("al5c")
    message = r"joint 'elbow' value 0 is outside its range \[-2.87979, -0.436332\]"
    with pytest.raises(planner.JointLimitError, match=message):
        robot.check_limits(np.radians([0, 30, 0, 0, 0]))
    assert robot.within_limits(np.radians([0, 30, -60, 0, 0])) is True


# --------------------------------------------------------------------------- tips and locking
GRIPPER_URDF = """<robot name="g">
  <link name="base"/><link name="l1"/><link name="hand"/><link name="finger"/><link name="tcp"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="hand"/><origin xyz="0.2 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="2"/></joint>
  <joint name="finger_joint" type="prismatic"><parent link="hand"/><child link="finger"/>
    <origin xyz="0.05 0 0"/><axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="0.1"/></joint>
  <joint name="tcp_joint" type="fixed"><parent link="hand"/><child link="tcp"/><origin xyz="0.1 0 0"/></joint>
</robot>"""


def test_off_chain_joints_are_locked():
    robot = planner.Robot(GRIPPER_URDF, tip="tcp")
    assert robot.joint_names == ("j1", "j2")
    np.testing.assert_allclose(robot.position([0.0, 0.0]), [0.3, 0.0, 0.0])
    locked = planner.Robot(GRIPPER_URDF, tip="finger", locked={})
    assert locked.joint_names == ("j1", "j2", "finger_joint")
    with pytest.raises(planner.JointLimitError, match="locked joint: joint 'finger_joint' value 0.5"):
        planner.Robot(GRIPPER_URDF, tip="tcp", locked={"finger_joint": 0.5})
    with pytest.raises(planner.InvalidArgumentError, match="cannot lock unknown joints nope"):
        planner.Robot(GRIPPER_URDF, tip="tcp", locked={"nope": 0.0})


def test_other_frames_and_default_tip():
    robot = planner.Robot(GRIPPER_URDF, tip="tcp")
    np.testing.assert_allclose(robot.position([0.0, 0.0], frame="hand"), [0.2, 0.0, 0.0])
    # The default tip is the end of the deepest chain (the finger, three joints deep).
    assert planner.Robot(GRIPPER_URDF).tip == "finger"


def test_continuous_joints_take_one_angle():
    urdf = GRIPPER_URDF.replace('type="revolute"><parent link="base"/>', 'type="continuous"><parent link="base"/>')
    robot = planner.Robot(urdf, tip="tcp")
    assert robot.joint_kinds == ("continuous", "revolute")
    assert robot.lower[0] == -math.inf and robot.upper[0] == math.inf
    np.testing.assert_allclose(robot.position([math.pi / 2, 0.0]), [0.0, 0.3, 0.0], atol=1e-15)
    jac = robot.jacobian([0.3, 0.2])
    assert jac.shape == (6, 2)
    q = robot.random_configurations(np.random.default_rng(1), 50)
    assert np.all(np.abs(q[:, 0]) <= math.pi)


def test_bundled_urdfs_pass_the_full_validation():
    # load_robot skips yourdfpy for the bundled arms (their files are generated): check them here.
    from planner.model.catalog import BUNDLED_ROBOTS, bundled_urdf_path

    for name in BUNDLED_ROBOTS:
        planner.Robot(bundled_urdf_path(name).read_text(), tip=BUNDLED_ROBOTS[name].tip)


def test_a_one_joint_arm_has_a_jacobian_and_conditioning():
    description = {
        "name": "stick",
        "units": {"length": "m", "angle": "deg"},
        "velocity": 60,
        "joints": [{"name": "yaw", "axis": [0, 0, 1], "lower": -170, "upper": 170}],
        "tool": {"name": "tip", "xyz": [0.3, 0, 0]},
    }
    robot = planner.Robot(planner.urdf_from_dh(description), tip="tip")
    jac = robot.jacobian([0.3])
    assert jac.shape == (6, 1)
    np.testing.assert_allclose(jac[:3, 0], [-0.3 * np.sin(0.3), 0.3 * np.cos(0.3), 0.0], atol=1e-12)
    inverse, manipulability = robot.conditioning(np.zeros((3, 1)))
    np.testing.assert_allclose(inverse, 1.0)
    np.testing.assert_allclose(manipulability, 0.3)


def _fk_in_worker(robot: planner.Robot, q: np.ndarray) -> np.ndarray:
    return robot.fk(q)


@pytest.mark.parametrize("name", [*BUNDLED, "gripper"])
def test_a_pickled_or_copied_robot_is_the_same_robot(name):
    robot = (
        planner.Robot(GRIPPER_URDF, tip="tcp", locked={"finger_joint": 0.03}) if name == "gripper" else get_robot(name)
    )
    q = robot.random_configurations(np.random.default_rng(7), 20)
    planner.solve_ik(robot, planner.Target(position=robot.position(q[0])))  # fills robot.derived
    for twin in (pickle.loads(pickle.dumps(robot)), copy.deepcopy(robot)):
        assert twin is not robot and twin.data is not robot.data
        assert (twin.name, twin.tip, twin.source, twin.joint_names) == (
            robot.name,
            robot.tip,
            robot.source,
            robot.joint_names,
        )
        assert dict(twin.locked_joints) == dict(robot.locked_joints)
        np.testing.assert_array_equal(twin.approach_axis, robot.approach_axis)
        np.testing.assert_array_equal(twin.lower, robot.lower)
        np.testing.assert_array_equal(twin.upper, robot.upper)
        np.testing.assert_array_equal(twin.fk(q), robot.fk(q))
        result = planner.solve_ik(twin, planner.Target(position=robot.position(q[1])))
        assert result.success, result.reason
        np.testing.assert_allclose(robot.position(result.q), robot.position(q[1]), atol=1e-9)


def test_a_robot_goes_to_a_worker_process():
    robot = get_robot("al5c")
    q = robot.random_configurations(np.random.default_rng(8), 4)
    context = multiprocessing.get_context("fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn")
    with concurrent.futures.ProcessPoolExecutor(max_workers=1, mp_context=context) as pool:
        np.testing.assert_array_equal(pool.submit(_fk_in_worker, robot, q).result(), robot.fk(q))
