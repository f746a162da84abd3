"""The symbolic CasADi FK of the tip equals Pinocchio's FK, joint type by joint type."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from planner import InvalidConfigurationError, Robot
from planner.geometry.chain import kinematic_chain
from planner.ik.numeric.kinematics import CasadiKinematics

from conftest import BUNDLED, EXAMPLES, get_robot, needs_example_robot_data

# Every joint type the chain may hold: revolute about an unaligned and a negative axis,
# continuous about an unaligned axis, prismatic along x and along an unaligned axis, fixed
# joints in between, and a gripper joint off the chain (locked by Robot).
MIXED_URDF = """<robot name="mixed">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/>
  <link name="l5"/><link name="l6"/><link name="tool"/><link name="finger"/>
  <joint name="yaw" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0.1 0.2 0.3" rpy="0.1 0.2 0.3"/><axis xyz="0 0 -1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="spin" type="continuous"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.1 0 0.1" rpy="0.3 0 0"/><axis xyz="0.3 0.5 0.2"/></joint>
  <joint name="slide" type="prismatic"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.1 0 0" rpy="0 0.4 0"/><axis xyz="1 0 0"/>
    <limit lower="-0.2" upper="0.3" effort="1" velocity="1"/></joint>
  <joint name="bracket" type="fixed"><parent link="l3"/><child link="l4"/>
    <origin xyz="0 0.1 0" rpy="0.5 0.2 0.1"/></joint>
  <joint name="slant_slide" type="prismatic"><parent link="l4"/><child link="l5"/>
    <origin xyz="0.1 0 0" rpy="0 0.4 0"/><axis xyz="1 1 0"/>
    <limit lower="-0.2" upper="0.3" effort="1" velocity="1"/></joint>
  <joint name="tilt" type="revolute"><parent link="l5"/><child link="l6"/>
    <origin xyz="0.1 0 0" rpy="0 0.4 0"/><axis xyz="0.6 -0.8 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="flange" type="fixed"><parent link="l6"/><child link="tool"/>
    <origin xyz="0.05 0.01 0.02" rpy="0.2 -0.3 0.4"/></joint>
  <joint name="grip" type="prismatic"><parent link="l6"/><child link="finger"/>
    <origin xyz="0 0.02 0"/><axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>
</robot>"""


def mixed_robot() -> Robot:
    return Robot(MIXED_URDF, tip="tool")


def check_against_pinocchio(robot: Robot, seed: int, n: int = 40) -> None:
    kin = CasadiKinematics(robot)
    for q in robot.random_configurations(np.random.default_rng(seed), n):
        np.testing.assert_allclose(kin.fk(q), robot.fk(q), rtol=0, atol=1e-12)
        np.testing.assert_allclose(kin.jacobian_at(q), robot.jacobian(q), rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", BUNDLED)
def test_bundled_arms_match_pinocchio(name):
    check_against_pinocchio(get_robot(name), seed=1)


@needs_example_robot_data
@pytest.mark.parametrize("name", EXAMPLES)
def test_example_arms_match_pinocchio(name):
    check_against_pinocchio(get_robot(name), seed=2)


def test_every_joint_type_matches_pinocchio():
    robot = mixed_robot()
    assert robot.joint_kinds == ("revolute", "continuous", "prismatic", "prismatic", "revolute")
    check_against_pinocchio(robot, seed=3)
    # Continuous joints take any angle, not only the [-pi, pi) that random_configurations draws.
    kin = CasadiKinematics(robot)
    q = np.array([0.3, 7.5, 0.1, -0.1, 1.0])
    np.testing.assert_allclose(kin.fk(q), robot.fk(q), rtol=0, atol=1e-12)


def test_kinematic_chain_reads_kinds_and_axes():
    chain = kinematic_chain(mixed_robot())
    joints = chain.joints
    assert [j.index for j in joints] == [0, 1, 2, 3, 4]
    assert chain.tip_parent == 4 and chain.tip_path() == frozenset(range(5))
    assert not joints[0].axis.flags.writeable and not chain.tip_translation.flags.writeable
    assert [j.name for j in joints] == ["yaw", "spin", "slide", "slant_slide", "tilt"]
    assert [j.kind for j in joints] == ["revolute", "continuous", "prismatic", "prismatic", "revolute"]
    np.testing.assert_allclose(joints[0].axis, [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(joints[1].axis, np.array([0.3, 0.5, 0.2]) / np.linalg.norm([0.3, 0.5, 0.2]))
    np.testing.assert_allclose(joints[3].axis, np.array([1, 1, 0]) / np.sqrt(2))
    assert [j.parent for j in joints] == [-1, 0, 1, 2, 3]


def test_jacobian_matches_finite_differences_of_the_symbolic_position():
    robot = mixed_robot()
    kin = CasadiKinematics(robot)
    q = robot.random_configurations(np.random.default_rng(4))
    h = 1e-6
    jac = kin.jacobian_at(q)
    for i in range(robot.dof):
        dq = np.zeros(robot.dof)
        dq[i] = h
        fd = (kin.fk(q + dq)[:3, 3] - kin.fk(q - dq)[:3, 3]) / (2 * h)
        np.testing.assert_allclose(jac[:3, i], fd, atol=1e-8)


def test_expressions_are_symbolic_and_reusable():
    robot = get_robot("al5c")
    kin = CasadiKinematics(robot)
    assert isinstance(kin.position, ca.SX) and kin.position.shape == (3, 1)
    assert kin.rotation.shape == (3, 3) and kin.jacobian.shape == (6, robot.dof)
    # The same model evaluated on another symbol, e.g. inside a larger expression.
    x = ca.SX.sym("x", robot.dof)
    position, _, _ = kin.expressions(2 * x)
    f = ca.Function("f", [x], [position])
    q = np.array([0.1, 0.5, -1.0, 0.2, 0.3])
    np.testing.assert_allclose(np.array(f(q / 2)).ravel(), robot.position(q), atol=1e-12)
    # The approach axis is the tip's, in base-frame axes.
    approach = ca.Function("a", [kin.q], [kin.approach])
    np.testing.assert_allclose(np.array(approach(q)).ravel(), robot.fk(q)[:3, :3] @ robot.approach_axis, atol=1e-12)


def test_wrong_length_is_rejected():
    kin = CasadiKinematics(get_robot("dh3"))
    with pytest.raises(InvalidConfigurationError, match=r"q has shape \(2,\); dh3 expects \(3,\)"):
        kin.fk([0.0, 0.0])
