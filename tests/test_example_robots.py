"""example-robot-data arms load by name; their FK equals Pinocchio's on the full model.

Skipped cleanly when example-robot-data is not installed.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from planner.model.catalog import EXAMPLE_ROBOTS, example_robot_data_dir

from conftest import EXAMPLES, get_robot, needs_example_robot_data

pytestmark = needs_example_robot_data


@pytest.mark.parametrize("name", EXAMPLES)
def test_fk_matches_pinocchio_on_the_full_model(name):
    robot = get_robot(name)
    full = pin.buildModelFromUrdf(str(example_robot_data_dir() / EXAMPLE_ROBOTS[name].urdf))
    data = full.createData()
    fid = [i for i, f in enumerate(full.frames) if f.name == robot.tip and f.type == pin.FrameType.BODY][0]
    rng = np.random.default_rng(11)
    for q in robot.random_configurations(rng, 25):
        q_full = pin.neutral(full)
        for jid in range(1, full.njoints):
            jm = full.joints[jid]
            if full.names[jid] in robot.joint_names:
                q_full[jm.idx_q] = q[robot.joint_names.index(full.names[jid])]
            else:  # locked off-chain joints sit at 0 or the nearest end of their range
                lo, hi = full.lowerPositionLimit[jm.idx_q], full.upperPositionLimit[jm.idx_q]
                q_full[jm.idx_q] = min(max(0.0, lo), hi)
        pin.framesForwardKinematics(full, data, q_full)
        np.testing.assert_allclose(robot.fk(q), data.oMf[fid].homogeneous, atol=1e-12)


def test_dof_and_locked_grippers():
    assert get_robot("ur5").dof == 6
    assert get_robot("panda").dof == 7 and "panda_finger_joint1" not in get_robot("panda").joint_names
    assert get_robot("so101").dof == 5 and "gripper" not in get_robot("so101").joint_names
    assert get_robot("z1").dof == 6 and "jointGripper" not in get_robot("z1").joint_names


@pytest.mark.parametrize("name", EXAMPLES)
def test_jacobian_finite_differences(name):
    robot = get_robot(name)
    q = robot.random_configurations(np.random.default_rng(3))
    jac = robot.jacobian(q)
    h = 1e-6
    for i in range(robot.dof):
        dq = np.zeros(robot.dof)
        dq[i] = h
        fd = (robot.position(q + dq) - robot.position(q - dq)) / (2 * h)
        np.testing.assert_allclose(jac[:3, i], fd, atol=1e-7)
