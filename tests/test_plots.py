"""Plots are written as valid, non-trivial PNG files (matplotlib is an optional extra)."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import get_robot, png_size

pytest.importorskip("matplotlib")

from planner.app import plots  # noqa: E402


def test_joint_profiles_and_manipulability(tmp_path):
    robot = get_robot("al5c")
    t = np.linspace(0, 2, 300)
    q = np.stack([np.sin((k + 1) * t) for k in range(robot.dof)], axis=1)
    limits = {"lower": robot.lower, "upper": robot.upper, "velocity": robot.velocity_limit}
    out = plots.plot_joint_profiles(
        tmp_path / "p.png", t, q, q, q, q, joint_names=robot.joint_names, limits=limits, waypoint_times=[0, 1, 2]
    )
    w, h = png_size(out)
    assert w >= 600 and h >= 600
    out = plots.plot_manipulability(tmp_path / "m.png", t, np.abs(np.sin(t)), threshold=1 / 30, waypoint_times=[1])
    assert png_size(out)[0] >= 600


def test_arm_poses_and_benchmark_chart(tmp_path):
    robot = get_robot("dh3")
    qs = robot.random_configurations(np.random.default_rng(0), 3)
    assert png_size(plots.plot_arm_poses(tmp_path / "a.png", robot, qs, labels=["a", "b", "c"]))[0] >= 600
    rows = [
        {"robot": "dh3", "method": "analytic", "solve_rate": 1.0, "median_ms": 0.01},
        {"robot": "dh3", "method": "nlp", "solve_rate": 0.98, "median_ms": 0.3},
    ]
    assert png_size(plots.plot_ik_benchmark(tmp_path / "deep" / "b.png", rows))[0] >= 600


def test_arm_poses_show_the_scene(tmp_path):
    from planner.collision import Box, Cylinder, Obstacle, Scene, Sphere

    robot = get_robot("al5c")
    scene = Scene(
        floor=0.0,
        obstacles=(
            Obstacle("block", Box((0.04, 0.04, 0.1)), np.array([0.2, 0.1, 0.05])),
            Obstacle("post", Cylinder(0.02, 0.2), np.array([0.1, -0.15, 0.1])),
            Obstacle("ball", Sphere(0.03), np.array([0.15, 0.0, 0.2])),
        ),
    )
    q = np.array([[0, 1.2, -1.4, -0.8, 0], [0.5, 1.0, -1.2, -0.6, 0]])
    plain = plots.plot_arm_poses(tmp_path / "plain.png", robot, q)
    shown = plots.plot_arm_poses(tmp_path / "scene.png", robot, q, scene=scene)
    assert png_size(shown) == png_size(plain)
    assert shown.read_bytes() != plain.read_bytes()
