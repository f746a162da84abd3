"""What the arm must not touch: the floor, boxes, spheres and cylinders, and a clearance.

A :class:`Scene` is plain data in the robot's base frame (SI units). :func:`parse_scene` reads
the ``scene:`` block of a plan file::

    scene:
      floor: 0.0            # height of the floor in the base frame; omit for none
      clearance: 0.005      # minimum distance kept to every obstacle and between links
      obstacles:
        - {name: block, box: [0.04, 0.04, 0.10], position: [0.20, 0.10, 0.05]}
        - {name: post, cylinder: {radius: 0.02, length: 0.2}, position: [0.1, -0.15, 0.1]}
        - {name: ball, sphere: 0.03, position: [0.15, 0.0, 0.2], rpy: [0, 0, 0]}

A box is given by its full extents along its own x, y, z; a cylinder's axis is its own z;
`position` is the shape's centre and `rpy` its orientation (roll, pitch, yaw).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from planner.core.arrays import read_only
from planner.core.files import positive_number
from planner.core.rotations import rpy_to_matrix
from planner.core.text import plain
from planner.exceptions import InvalidArgumentError

__all__ = ["FLOOR", "MAX_EXTENT", "Box", "Cylinder", "Obstacle", "Scene", "Shape", "Sphere", "parse_scene"]

#: The name the floor goes by in reports.
FLOOR = "floor"

#: Largest obstacle size and distance from the base [m]. Anything farther is a units mistake, and
#: the distance bounds square these numbers: an obstacle at 1e200 m stalled the continuous check.
MAX_EXTENT = 1e6


def _extent(value: Any, what: str) -> float:
    x = positive_number(value, what)
    if x > MAX_EXTENT:
        raise InvalidArgumentError(f"{what} must be at most {MAX_EXTENT:g} m, got {plain(value)} m")
    return x


@dataclass(frozen=True)
class Box:
    """A box of full extents `size` [m] along its own x, y, z."""

    size: tuple[float, float, float]

    def __post_init__(self) -> None:
        if not isinstance(self.size, Sequence) or len(self.size) != 3:
            raise InvalidArgumentError(f"a box needs three sizes [x, y, z], got {plain(self.size)}")
        object.__setattr__(self, "size", tuple(_extent(v, "box size") for v in self.size))


@dataclass(frozen=True)
class Sphere:
    """A sphere of `radius` [m]."""

    radius: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "radius", _extent(self.radius, "sphere radius"))


@dataclass(frozen=True)
class Cylinder:
    """A cylinder of `radius` and `length` [m] along its own z, centred on its origin."""

    radius: float
    length: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "radius", _extent(self.radius, "cylinder radius"))
        object.__setattr__(self, "length", _extent(self.length, "cylinder length"))


Shape = Box | Sphere | Cylinder


@dataclass(frozen=True)
class Obstacle:
    """A named shape at a pose in the base frame.

    Attributes:
        name: Unique name, used in reports and in a target's ``allow`` list.
        shape: Its :class:`Box`, :class:`Sphere` or :class:`Cylinder`.
        position: Its centre [m], shape (3,).
        rotation: Its orientation, a 3x3 rotation matrix.
    """

    name: str
    shape: Shape
    position: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or self.name == FLOOR:
            raise InvalidArgumentError(f"an obstacle needs a name other than {FLOOR!r}, got {self.name!r}")
        if not isinstance(self.shape, (Box, Sphere, Cylinder)):
            raise InvalidArgumentError(f"obstacle {self.name!r}: shape must be a Box, Sphere or Cylinder")
        p = np.asarray(self.position, dtype=float).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise InvalidArgumentError(f"obstacle {self.name!r}: position must be 3 finite numbers, got {plain(p)}")
        if np.max(np.abs(p)) > MAX_EXTENT:
            raise InvalidArgumentError(
                f"obstacle {self.name!r}: position must lie within {MAX_EXTENT:g} m of the base, got {plain(p)} m"
            )
        r = np.asarray(self.rotation, dtype=float)
        if r.shape != (3, 3) or not np.allclose(r @ r.T, np.eye(3), atol=1e-9) or np.linalg.det(r) < 0:
            raise InvalidArgumentError(f"obstacle {self.name!r}: rotation must be a 3x3 rotation matrix")
        object.__setattr__(self, "position", read_only(p))
        object.__setattr__(self, "rotation", read_only(r))


@dataclass(frozen=True)
class Scene:
    """The floor, the obstacles and the clearance to keep, in the base frame.

    Attributes:
        floor: Height of the floor [m] (the arm must stay above ``z = floor``), or None.
        clearance: Minimum distance [m] kept to every obstacle, to the floor and between the
            arm's own links.
        obstacles: The obstacles, with distinct names.
    """

    floor: float | None = None
    clearance: float = 0.0
    obstacles: tuple[Obstacle, ...] = ()

    def __post_init__(self) -> None:
        if self.floor is not None:
            if isinstance(self.floor, bool) or not isinstance(self.floor, (int, float, np.integer, np.floating)):
                raise InvalidArgumentError(f"floor must be a height [m] or None, got {plain(self.floor)}")
            if not math.isfinite(self.floor):
                raise InvalidArgumentError(f"floor must be finite, got {plain(self.floor)}")
            object.__setattr__(self, "floor", float(self.floor))
        c = self.clearance
        if isinstance(c, bool) or not isinstance(c, (int, float, np.integer, np.floating)) or not (0 <= c < math.inf):
            raise InvalidArgumentError(f"clearance must be a distance >= 0 [m], got {plain(c)}")
        object.__setattr__(self, "clearance", float(c))
        obstacles = tuple(self.obstacles)
        names = [o.name for o in obstacles]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise InvalidArgumentError(f"obstacle names must differ; repeated: {', '.join(repeated)}")
        object.__setattr__(self, "obstacles", obstacles)

    @property
    def names(self) -> tuple[str, ...]:
        """The names of what can be hit: ``"floor"`` (when there is one) and each obstacle."""
        return ((FLOOR,) if self.floor is not None else ()) + tuple(o.name for o in self.obstacles)

    def check_names(self, names: Sequence[str], what: str = "allow") -> tuple[str, ...]:
        """Check that `names` name things in this scene.

        Raises:
            InvalidArgumentError: Naming the unknown one and the valid names.
        """
        out = tuple(str(n) for n in names)
        for n in out:
            if n not in self.names:
                valid = ", ".join(self.names) or "none (the scene is empty)"
                raise InvalidArgumentError(f"{what}: {n!r} is not in the scene; valid names: {valid}")
        return out


_SHAPES = ("box", "sphere", "cylinder")
_OBSTACLE_KEYS = {"name", "position", "rpy", *_SHAPES}


def _numbers(value: Any, what: str, n: int) -> np.ndarray:
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != n:
        raise InvalidArgumentError(f"{what} must be a list of {n} numbers, got {plain(value)}")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InvalidArgumentError(f"{what} must be a list of {n} finite numbers, got {plain(value)}")
        out.append(float(v))
    return np.array(out)


def _shape(entry: Mapping[str, Any], where: str, length: float) -> Shape:
    given = [k for k in _SHAPES if k in entry]
    if len(given) != 1:
        raise InvalidArgumentError(f"{where}: give exactly one shape ({', '.join(_SHAPES)}), got {given or 'none'}")
    kind, spec = given[0], entry[given[0]]
    if kind == "box":
        return Box(tuple(_numbers(spec, f"{where}: box", 3) * length))
    if kind == "sphere":
        radius = spec.get("radius") if isinstance(spec, Mapping) else spec
        return Sphere(positive_number(radius, f"{where}: sphere radius") * length)
    if not isinstance(spec, Mapping) or set(spec) != {"radius", "length"}:
        raise InvalidArgumentError(f"{where}: cylinder must be {{radius: R, length: L}}, got {plain(spec)}")
    return Cylinder(
        positive_number(spec["radius"], f"{where}: cylinder radius") * length,
        positive_number(spec["length"], f"{where}: cylinder length") * length,
    )


def parse_scene(
    data: Mapping[str, Any] | None, *, length_scale: float = 1.0, angle_scale: float = 1.0, source: str = "scene"
) -> Scene:
    """Read a ``scene:`` mapping (see the module docstring) in a file's units.

    Args:
        data: The mapping, or None for an empty scene.
        length_scale: Metres per file length unit.
        angle_scale: Radians per file angle unit (for ``rpy``).
        source: Where the mapping came from, for messages.

    Returns:
        The scene in SI units.

    Raises:
        InvalidArgumentError: On an unknown key, a missing or second shape, a non-positive
            size, repeated names; the message says where.
    """
    if data is None:
        return Scene()
    if not isinstance(data, Mapping):
        raise InvalidArgumentError(f"{source}: scene must be a mapping, got {plain(data)}")
    unknown = sorted(set(data) - {"floor", "clearance", "obstacles"})
    if unknown:
        raise InvalidArgumentError(
            f"{source}: unknown scene key(s) {', '.join(unknown)}; valid keys: floor, clearance, obstacles"
        )
    floor = data.get("floor")
    if floor is not None:
        if isinstance(floor, bool) or not isinstance(floor, (int, float)):
            raise InvalidArgumentError(f"{source}: scene.floor must be a height, got {plain(floor)}")
        floor = float(floor) * length_scale
    clearance = data.get("clearance", 0.0)
    if isinstance(clearance, bool) or not isinstance(clearance, (int, float)) or not 0 <= clearance < math.inf:
        raise InvalidArgumentError(f"{source}: scene.clearance must be a distance >= 0, got {plain(clearance)}")
    entries = data.get("obstacles", []) or []
    if not isinstance(entries, Sequence) or isinstance(entries, (str, bytes)):
        raise InvalidArgumentError(f"{source}: scene.obstacles must be a list, got {plain(entries)}")
    obstacles = []
    for k, entry in enumerate(entries):
        where = f"{source}: scene.obstacles[{k}]"
        if not isinstance(entry, Mapping):
            raise InvalidArgumentError(f"{where} must be a mapping, got {plain(entry)}")
        extra = sorted(set(entry) - _OBSTACLE_KEYS)
        if extra:
            raise InvalidArgumentError(
                f"{where}: unknown key(s) {', '.join(extra)}; valid keys: {', '.join(sorted(_OBSTACLE_KEYS))}"
            )
        name = entry.get("name", f"obstacle{k}")
        if "position" not in entry:
            raise InvalidArgumentError(f"{where} ({name!r}) needs a position")
        position = _numbers(entry["position"], f"{where}: position", 3) * length_scale
        rpy = _numbers(entry.get("rpy", [0, 0, 0]), f"{where}: rpy", 3) * angle_scale
        try:
            shape = _shape(entry, where, length_scale)
        except InvalidArgumentError as exc:
            raise InvalidArgumentError(str(exc) if str(exc).startswith(where) else f"{where}: {exc}") from exc
        try:
            obstacles.append(Obstacle(str(name), shape, position, rpy_to_matrix(rpy)))
        except InvalidArgumentError as exc:
            raise InvalidArgumentError(f"{where}: {exc}") from exc
    try:
        return Scene(floor=floor, clearance=float(clearance) * length_scale, obstacles=tuple(obstacles))
    except InvalidArgumentError as exc:
        raise InvalidArgumentError(f"{source}: scene: {exc}") from exc
