"""The approach-pitch convention (planner.geometry.target): approach_pitch measures it, pitch_error is the
distance of an approach axis from it, checked against a brute-force search of the allowed set."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner import approach_pitch, pitch_error
from planner.geometry.target import approach_direction

from conftest import HAVE_EXAMPLE_ROBOT_DATA, get_robot


def brute_force_error(a: np.ndarray, position: np.ndarray, pitch: float) -> float:
    """Smallest angle from `a` to a direction with this approach pitch, over a fine azimuth grid."""
    elevation = math.atan2(math.sin(pitch), abs(math.cos(pitch)))
    radial = position[:2] / np.linalg.norm(position[:2])
    side = np.array([-radial[1], radial[0]])
    phi = np.linspace(-math.pi / 2, math.pi / 2, 20001) + (math.pi if math.cos(pitch) < 0 else 0.0)
    horizontal = np.outer(np.cos(phi), radial) + np.outer(np.sin(phi), side)
    allowed = np.column_stack([math.cos(elevation) * horizontal, np.full(len(phi), math.sin(elevation))])
    return float(np.min(np.arccos(np.clip(allowed @ a, -1.0, 1.0))))


def test_pitch_error_is_the_distance_to_the_allowed_directions():
    rng = np.random.default_rng(40)
    axes = rng.normal(size=(400, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    positions = rng.normal(size=(400, 3))
    pitches = rng.uniform(-4.0, 4.0, 400)
    pitches[::10] = math.pi / 2
    batch = pitch_error(axes, positions, pitches)
    assert batch.shape == (400,)
    for a, p, pitch, b in zip(axes, positions, pitches, batch):
        single = pitch_error(a, p, pitch)
        assert single == pytest.approx(b, abs=1e-12)
        assert single == pytest.approx(brute_force_error(a, p, pitch), abs=1e-6)


def test_pitch_error_zero_exactly_on_the_convention():
    position = np.array([0.3, -0.2, 0.1])
    for pitch in (-math.pi / 2, -1.0, 0.0, 0.4, math.pi / 2, 2.5, -3.0):
        # The radial direction itself (arms whose plane holds the base axis) ...
        assert pitch_error(approach_direction(position, pitch), position, pitch) == pytest.approx(0.0, abs=1e-15)
        # ... and any direction of that elevation on the outward side (arms beside the axis).
        for turn in (-1.2, 0.5, 1.5):
            c, s = math.cos(turn), math.sin(turn)
            a = approach_direction(position, pitch)
            turned = np.array([c * a[0] - s * a[1], s * a[0] + c * a[1], a[2]])
            assert pitch_error(turned, position, pitch) == pytest.approx(0.0, abs=1e-15)
    # Pointing back at the base axis, horizontally: 90 deg from the nearest allowed direction.
    inward = -approach_direction(position, 0.0)
    assert pitch_error(inward, position, 0.0) == pytest.approx(math.pi / 2, abs=1e-12)
    assert pitch_error(inward, position, math.pi) == pytest.approx(0.0, abs=1e-12)


def test_pitch_error_straight_down_and_on_the_base_axis():
    a = np.array([math.sin(0.01), 0.0, -math.cos(0.01)])  # 0.01 rad off straight down
    assert pitch_error(a, np.array([-0.3, 0.1, 0.0]), -math.pi / 2) == pytest.approx(0.01, abs=1e-12)
    # On the base axis only the elevation counts, whatever the azimuth.
    for azimuth in (0.0, 2.0, -2.5):
        a = np.array([math.cos(0.3) * math.cos(azimuth), math.cos(0.3) * math.sin(azimuth), math.sin(0.3)])
        assert pitch_error(a, np.array([0.0, 0.0, 0.4]), 0.2) == pytest.approx(0.1, abs=1e-12)


@pytest.mark.parametrize("name", ["al5c", "three_joint", "so101"])
def test_approach_pitch_of_configurations(name):
    if name == "so101" and not HAVE_EXAMPLE_ROBOT_DATA:
        pytest.skip("example-robot-data is not installed")
    robot = get_robot(name)
    q = robot.random_configurations(np.random.default_rng(41), 50)
    pitch = approach_pitch(robot, q)
    assert pitch.shape == (50,) and np.all(np.abs(pitch) <= math.pi)
    poses = robot.fk(q)
    for k in range(50):
        a = poses[k, :3, :3] @ robot.approach_axis
        assert approach_pitch(robot, q[k]) == pitch[k]
        assert math.sin(pitch[k]) == pytest.approx(a[2], abs=1e-12)
        assert math.cos(pitch[k]) * (a[:2] @ poses[k, :2, 3]) >= 0.0
        assert pitch_error(a, poses[k, :3, 3], pitch[k]) <= 1e-12


def test_tip_errors_agree_with_pinocchio_log3():
    import pinocchio as pin

    from planner import Target
    from planner.geometry.target import tip_errors

    rng = np.random.default_rng(41)
    axis = np.array([0.0, 0.0, 1.0])
    for k in range(300):
        rotation, goal = pin.SE3.Random().rotation, pin.SE3.Random().rotation
        if k % 3 == 0:  # small and tiny angles, where atan2 of the antisymmetric part is needed
            goal = rotation @ pin.exp3(rng.normal(size=3) * 10.0 ** -rng.uniform(1, 12))
        if k % 50 == 1:  # at pi
            goal = rotation @ pin.exp3(np.array([0.0, math.pi, 0.0]))
        position, wanted = rng.normal(size=3), rng.normal(size=3)
        target = Target(wanted, rotation=goal)
        position_error, orientation_error = tip_errors(target, position, rotation, axis)
        assert position_error == pytest.approx(float(np.linalg.norm(position - wanted)), rel=1e-15, abs=1e-15)
        assert orientation_error == pytest.approx(float(np.linalg.norm(pin.log3(rotation.T @ goal))), abs=1e-9)
        # Pinocchio's Fortran-ordered placements give the same numbers as C-ordered copies.
        fortran = np.asfortranarray(rotation)
        assert tip_errors(target, position, fortran, axis) == (position_error, orientation_error)
