"""Collision checking: the arm's geometry, a scene of obstacles, distances and clear paths.

Between the model and the IK layers: it reads a :class:`~planner.model.robot.Robot` and is used
by IK (answers checked), motion (trajectories checked and planned around obstacles) and the app.
"""

from planner.collision.arm import ArmCollisionModel, arm_collision_model
from planner.collision.checker import Clearance, CollisionChecker
from planner.collision.scene import FLOOR, Box, Cylinder, Obstacle, Scene, Sphere, parse_scene

__all__ = [
    "FLOOR",
    "ArmCollisionModel",
    "Box",
    "Clearance",
    "CollisionChecker",
    "Cylinder",
    "Obstacle",
    "Scene",
    "Sphere",
    "arm_collision_model",
    "parse_scene",
]
