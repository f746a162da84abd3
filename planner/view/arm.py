"""The arm in a viser scene: the URDF's visual meshes where they resolve, else link geometry.

:class:`ArmDrawing` draws a :class:`~planner.model.robot.Robot` once and moves it to any
configuration. Arms whose URDF has visual meshes that load (the example-robot-data arms) are
drawn with them (``viser.extras.ViserUrdf``); the others (the bundled arms, which have no
visuals) get simple link geometry: a cylinder between consecutive joint origins, a sphere at
each joint and a box for the gripper. Joint frames can be shown on request.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from planner.model.robot import Robot

__all__ = ["ARM_COLOR", "ArmDrawing", "link_segments", "quaternion_wxyz"]

#: The colour of the drawn links (RGB, 0..255): an orange that stands out from the grey grid.
ARM_COLOR = (255, 110, 0)
JOINT_COLOR = (60, 60, 70)
GRIPPER_COLOR = (40, 90, 200)


def link_segments(points: np.ndarray, min_length: float = 1e-6) -> list[tuple[int, int]]:
    """Index pairs of consecutive points further apart than `min_length` [m] (the links to draw)."""
    return [(k, k + 1) for k in range(len(points) - 1) if np.linalg.norm(points[k + 1] - points[k]) > min_length]


def _z_to(direction: np.ndarray) -> np.ndarray:
    """A rotation matrix taking the z axis onto the unit vector `direction`."""
    z = direction / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def quaternion_wxyz(rotation: np.ndarray) -> np.ndarray:
    """The unit quaternion (w, x, y, z) of a rotation matrix."""
    import viser.transforms as vtf

    return vtf.SO3.from_matrix(rotation).wxyz


def _mesh_handler(urdf_dir: Path) -> Any:
    """A yourdfpy filename handler resolving ``package://PKG/rest`` against the URDF's ancestors."""

    def handler(fname: str) -> str:
        match = re.match(r"package://([^/]+)/(.*)", fname)
        if match is None:
            return str(urdf_dir / fname) if not Path(fname).is_absolute() else fname
        package, rest = match.groups()
        for folder in (urdf_dir, *urdf_dir.parents):
            for candidate in (folder / rest, folder / package / rest):
                if candidate.is_file():
                    return str(candidate)
        return fname

    return handler


def _load_meshes(robot: Robot) -> Any | None:
    """The robot's URDF as a yourdfpy model with its visual meshes, or None when any is missing."""
    if "<visual" not in robot.urdf or "<mesh" not in robot.urdf:
        return None
    source = Path(robot.source)
    if not source.is_file():
        return None
    try:
        import yourdfpy

        urdf = yourdfpy.URDF.load(
            str(source),
            build_scene_graph=True,
            load_meshes=True,
            build_collision_scene_graph=False,
            load_collision_meshes=False,
            filename_handler=_mesh_handler(source.parent),
        )
    except Exception:  # noqa: BLE001 - any failure to read meshes means stick geometry instead
        return None
    geometry = getattr(urdf.scene, "geometry", {}) if urdf.scene is not None else {}
    return urdf if geometry else None


class ArmDrawing:
    """The arm in a viser scene, moved by :meth:`update`.

    Args:
        server: A ``viser.ViserServer``.
        robot: The robot to draw.
        name: Scene-tree name of the arm's root node.
        meshes: Use the URDF's visual meshes when they resolve.
        color: RGB of the link geometry (0..255).
        opacity: Opacity of the link geometry (None: opaque); ghosts use less.
        radius: Link radius [m]; None scales it with the arm's size.

    Attributes:
        uses_meshes: Whether the URDF's visual meshes are drawn (else link geometry).
        reach: Total length of the links at the arm's home configuration [m].
    """

    def __init__(
        self,
        server: Any,
        robot: Robot,
        *,
        name: str = "/arm",
        meshes: bool = True,
        color: tuple[int, int, int] = ARM_COLOR,
        opacity: float | None = None,
        radius: float | None = None,
    ) -> None:
        self._server = server
        self._robot = robot
        self._name = name
        home = np.clip(np.zeros(robot.dof), robot.lower, robot.upper)
        points = robot.joint_positions(home)
        self.reach = float(sum(np.linalg.norm(np.diff(points, axis=0), axis=1))) or 0.1
        self._radius = radius if radius is not None else max(0.012 * self.reach / 0.3, 0.004)
        self._urdf_view: Any = None
        self._urdf_joints: tuple[str, ...] = ()
        self._urdf_default: np.ndarray = np.zeros(0)
        self.uses_meshes = False
        if meshes:
            urdf = _load_meshes(robot)
            if urdf is not None:
                from viser.extras import ViserUrdf

                self._urdf_view = ViserUrdf(server, urdf, root_node_name=name)
                self._urdf_joints = tuple(self._urdf_view.get_actuated_joint_names())
                limits = self._urdf_view.get_actuated_joint_limits()
                lo = np.array([v[0] if v[0] is not None else -np.inf for v in limits.values()])
                hi = np.array([v[1] if v[1] is not None else np.inf for v in limits.values()])
                self._urdf_default = np.clip(np.zeros(len(lo)), lo, hi)
                self.uses_meshes = True
        self._links: list[tuple[tuple[int, int], Any]] = []
        self._joints: list[Any] = []
        self._gripper: Any = None
        if not self.uses_meshes:
            self._build_links(points, color, opacity)
        self._frames = [
            server.scene.add_frame(
                f"{name}_frames/{j}",
                axes_length=2.5 * self._radius,
                axes_radius=0.25 * self._radius,
                visible=False,
            )
            for j in robot.joint_names
        ]
        self.update(home)

    def _build_links(self, points: np.ndarray, color: tuple[int, int, int], opacity: float | None) -> None:
        scene = self._server.scene
        r = self._radius
        for k, (a, b) in enumerate(link_segments(points)):
            handle = scene.add_cylinder(
                f"{self._name}/link{k}", radius=r, height=1.0, color=color, opacity=opacity, radial_segments=20
            )
            self._links.append(((a, b), handle))
        joint_color = color if opacity is not None else JOINT_COLOR
        for k in range(len(points) - 1):
            self._joints.append(
                scene.add_icosphere(f"{self._name}/joint{k}", radius=1.3 * r, color=joint_color, opacity=opacity)
            )
        grip = GRIPPER_COLOR if opacity is None else color
        self._gripper = scene.add_box(
            f"{self._name}/gripper", dimensions=(2.2 * r, 2.2 * r, 3.0 * r), color=grip, opacity=opacity
        )

    def _urdf_configuration(self, q: np.ndarray) -> np.ndarray:
        values = dict(zip(self._robot.joint_names, q))
        return np.array(
            [values.get(name, default) for name, default in zip(self._urdf_joints, self._urdf_default)], dtype=float
        )

    def update(self, q: np.ndarray) -> None:
        """Move the drawing to configuration `q`, shape (dof,) [rad or m]."""
        robot = self._robot
        points = robot.joint_positions(q)
        if self._urdf_view is not None:
            self._urdf_view.update_cfg(self._urdf_configuration(np.asarray(q, dtype=float)))
        else:
            for (a, b), handle in self._links:
                d = points[b] - points[a]
                length = float(np.linalg.norm(d))
                handle.visible = length > 1e-6
                if length > 1e-6:
                    handle.position = 0.5 * (points[a] + points[b])
                    handle.wxyz = quaternion_wxyz(_z_to(d))
                    handle.scale = (1.0, 1.0, length)
            for k, handle in enumerate(self._joints):
                handle.position = points[k]
            tip = robot.fk(q)
            self._gripper.position = tip[:3, 3]
            self._gripper.wxyz = quaternion_wxyz(tip[:3, :3] @ _z_to(robot.approach_axis))
        if any(f.visible for f in self._frames):
            self._place_frames(q)

    def _place_frames(self, q: np.ndarray) -> None:
        for name, frame in zip(self._robot.joint_names, self._frames):
            pose = self._robot.fk(q, name)
            frame.position = pose[:3, 3]
            frame.wxyz = quaternion_wxyz(pose[:3, :3])

    def show_frames(self, visible: bool, q: np.ndarray) -> None:
        """Show or hide a coordinate frame at each joint, placed for configuration `q`."""
        if visible:
            self._place_frames(q)
        for frame in self._frames:
            frame.visible = visible

    def set_visible(self, visible: bool) -> None:
        """Show or hide the whole drawing."""
        for _, handle in self._links:
            handle.visible = visible
        for handle in self._joints:
            handle.visible = visible
        if self._gripper is not None:
            self._gripper.visible = visible

    def remove(self) -> None:
        """Take the drawing out of the scene."""
        for _, handle in self._links:
            handle.remove()
        for handle in [*self._joints, *self._frames]:
            handle.remove()
        if self._gripper is not None:
            self._gripper.remove()
        if self._urdf_view is not None:
            self._urdf_view.remove()
