"""The arm's own collision geometry and the link pairs that can collide.

:func:`arm_collision_model` reads the URDF's ``<collision>`` elements through Pinocchio and
coal (meshes resolved next to the URDF and in example-robot-data's share folder); an arm whose
URDF has none gets a capsule along each link, from its joint to the next. Meshes are checked as their
convex hulls (which contain them). The pairs of links
checked against each other are every pair except adjacent links and links found in contact in
every one of a set of sampled configurations (what MoveIt's setup assistant does), computed
once per robot and kept in its ``derived`` cache.

Where a mesh is far from convex (a UR5 upper arm or forearm), its hull is a poor stand-in against
the arm's other links: two hulls may overlap where the meshes are centimetres apart. Such a mesh
also gets a few tighter convex pieces that together contain it
(:func:`~planner.collision.slabs.slab_hulls`), and a pair of links whose hulls overlap in sampled
configurations where their pieces keep apart is checked piece against piece instead. The scene
is always checked against the hulls.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import coal
import numpy as np
import pinocchio as pin

from planner.collision.slabs import MAX_TRIANGLES, mesh_arrays, slab_hulls
from planner.core.rotations import homogeneous
from planner.model.catalog import example_robot_data_dir
from planner.model.robot import Robot

__all__ = ["ArmCollisionModel", "arm_collision_model", "bounding_radius", "box_corners", "hull_points"]

#: Configurations sampled to find link pairs that are always in contact.
PAIR_SAMPLES = 300

#: Least number of those configurations in which a link pair's hulls must overlap while its
#: pieces keep apart for the pair to be checked piece against piece.
PIECE_SAMPLES = 3


@dataclass(frozen=True, eq=False)
class ArmCollisionModel:
    """The arm's collision geometry on the robot's (reduced) Pinocchio model.

    Attributes:
        geometry: The geometry model: one object per collision element, attached to the
            robot's joints, then the pieces of the elements checked in pieces (do not modify;
            checkers copy it).
        link_of: Per geometry object, the name of the link it belongs to.
        part_of: Per geometry object, the element it is a piece of (its own index for an
            element). Pieces are checked only against the arm's own links, never the scene.
        self_pairs: Index pairs of objects checked against each other.
        excluded: Link pairs never checked, with the reason (``"adjacent"`` or ``"always in contact"``).
        source: ``"urdf"`` or ``"capsules"`` (generated because the URDF has no collision geometry,
            or its meshes could not be found).
        reach: Per joint, an upper bound [m] on the distance from the joint's axis (or origin)
            to any point of the geometry it moves; bounds how fast the arm's surface can move.
        fixed_lowest: Geometry objects whose height never changes (a base column turning about
            a vertical axis), with the height of their lowest point [m]; found by sampling.
    """

    geometry: pin.GeometryModel
    link_of: tuple[str, ...]
    part_of: tuple[int, ...]
    self_pairs: tuple[tuple[int, int], ...]
    excluded: tuple[tuple[str, str, str], ...]
    source: str
    reach: np.ndarray
    fixed_lowest: Mapping[int, float]


def _package_dirs(robot: Robot) -> list[str]:
    dirs = []
    path = Path(robot.source)
    if path.is_file():
        dirs += [str(p) for p in list(path.resolve().parents)[:5]]
    root = example_robot_data_dir()
    if root is not None:
        dirs += [str(root.parent), str(root.parent.parent)]
    return dirs


def _from_urdf(robot: Robot) -> tuple[pin.GeometryModel, dict[int, list[coal.Convex]]] | None:
    """The URDF's collision elements (meshes as their hulls), and per far from convex mesh its pieces."""
    try:
        full = pin.buildModelFromXML(robot.urdf)
        geom = pin.buildGeomFromUrdfString(full, robot.urdf, pin.GeometryType.COLLISION, None, _package_dirs(robot))
    except Exception:  # Pinocchio raises plain errors for missing meshes and unknown shapes
        return None
    if geom.ngeoms == 0:
        return None
    if robot.locked_joints:
        q_ref = pin.neutral(full)
        for name, value in robot.locked_joints.items():
            q_ref[full.joints[full.getJointId(name)].idx_q] = value
        lock = [full.getJointId(n) for n in robot.locked_joints]
        _, geom = pin.buildReducedModel(full, geom, lock, q_ref)
    pieces = {}
    for k, obj in enumerate(geom.geometryObjects):
        # A mesh is checked as its convex hull: it contains the mesh (so a distance is never
        # overestimated) and GJK on it is far faster than a mesh-to-mesh distance.
        # buildConvexHull (qhull), not buildConvexRepresentation: that one takes the mesh's own
        # vertices and triangles as the polytope, and on a non-convex mesh GJK's hill-climbing
        # support search then stops at a local extreme and overestimates distances (by up to
        # 0.27 m on UR5 links that were in contact).
        if isinstance(obj.geometry, coal.BVHModelBase):
            mesh = obj.geometry
            mesh.buildConvexHull(True, "Qt")
            obj.geometry = mesh.convex
            if mesh.num_tris <= MAX_TRIANGLES:
                parts = slab_hulls(*mesh_arrays(mesh), float(mesh.convex.computeVolume()))
                if parts:
                    pieces[k] = parts
    return geom, pieces


def _capsules(robot: Robot) -> pin.GeometryModel:
    """One capsule per joint, from its origin to the next joint (or the tip)."""
    model = robot.model
    geom = pin.GeometryModel()
    ends = {}
    for jid in range(1, model.njoints):
        children = [c for c in range(jid + 1, model.njoints) if model.parents[c] == jid]
        ends[jid] = [model.jointPlacements[c].translation for c in children]
    tip = model.frames[robot.tip_frame_id]
    tip_offset = tip.placement.translation
    if tip.parentJoint in ends and np.linalg.norm(tip_offset) > 0:
        ends[tip.parentJoint].append(tip_offset)
    lengths = [float(np.linalg.norm(p)) for v in ends.values() for p in v]
    radius = max(0.05 * sum(lengths), 1e-3)
    for jid, points in ends.items():
        frame = next(
            (i for i, f in enumerate(model.frames) if f.parentJoint == jid and f.type == pin.FrameType.BODY), 0
        )
        for k, p in enumerate(points):
            length = float(np.linalg.norm(p))
            if length <= 1e-9:
                continue
            axis = p / length
            helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
            x = np.cross(helper, axis)
            x /= np.linalg.norm(x)
            pose = homogeneous(np.column_stack([x, np.cross(axis, x), axis]), p / 2)
            obj = pin.GeometryObject(
                f"{model.names[jid]}_capsule_{k}", jid, frame, pin.SE3(pose), coal.Capsule(radius, length)
            )
            geom.addGeometryObject(obj)
    return geom


def _link_names(robot: Robot, geom: pin.GeometryModel) -> tuple[str, ...]:
    out = []
    for obj in geom.geometryObjects:
        frame = robot.model.frames[obj.parentFrame] if obj.parentFrame < len(robot.model.frames) else None
        if frame is not None and frame.parentJoint == obj.parentJoint:
            out.append(frame.name)
        else:
            out.append(robot.model.names[obj.parentJoint] + "_link" if obj.parentJoint else "base")
    return tuple(out)


def box_corners(obj: pin.GeometryObject) -> np.ndarray:
    """The 8 corners of a geometry object's bounding box in its own frame [m], shape (8, 3)."""
    g = obj.geometry
    g.computeLocalAABB()
    box = g.aabb_local
    return np.array(
        [
            [x, y, z]
            for x in (box.min_[0], box.max_[0])
            for y in (box.min_[1], box.max_[1])
            for z in (box.min_[2], box.max_[2])
        ]
    )


def hull_points(obj: pin.GeometryObject) -> np.ndarray:
    """Points whose convex hull contains a geometry object, in its own frame [m], shape (n, 3).

    A convex polytope's vertices (the arm's meshes are checked as their hulls), else the
    corners of the object's bounding box. A convex function of the point (a distance from a
    line or a point) is largest on the object at one of them.
    """
    g = obj.geometry
    if isinstance(g, coal.Convex) and g.getSweptSphereRadius() == 0.0 and g.num_points > 0:
        return np.array(g.points(), dtype=float).reshape(-1, 3)
    return box_corners(obj)


def bounding_radius(obj: pin.GeometryObject) -> float:
    """Largest distance from an object's placement origin to a point of it [m] (upper bound)."""
    return float(np.max(np.linalg.norm(box_corners(obj), axis=1)))


def _reach(robot: Robot, geom: pin.GeometryModel) -> np.ndarray:
    """Per joint, the largest distance from its origin to any point of the geometry it moves.

    Measured over the joint placements of the chain (a bound that holds in every configuration:
    distances within the chain below a joint add up at most to the sum of the offsets).
    """
    model = robot.model
    reach = np.zeros(model.njoints - 1)
    for jid in range(1, model.njoints):
        best = 0.0
        for obj in geom.geometryObjects:
            chain = model.supports[obj.parentJoint]
            if jid not in chain:
                continue
            # Offsets from joint jid down to the object's joint, then the object itself.
            path = [j for j in chain if j > jid or j == jid]
            dist = sum(float(np.linalg.norm(model.jointPlacements[j].translation)) for j in path if j != jid)
            for j in path:  # a slide adds its travel
                if robot.joint_kinds[j - 1] == "prismatic":
                    dist += max(abs(robot.lower[j - 1]), abs(robot.upper[j - 1]))
            dist += float(np.linalg.norm(obj.placement.translation)) + bounding_radius(obj)
            best = max(best, dist)
        reach[jid - 1] = best
    return reach


def _self_pairs(
    robot: Robot, geom: pin.GeometryModel, link_of: tuple[str, ...], pieces: Mapping[int, list[coal.Convex]]
) -> tuple[tuple[tuple[int, int], ...], tuple[tuple[str, str, str], ...], list[tuple[int, int]]]:
    """The pairs checked, the link pairs excluded, and the pairs of elements to check in pieces."""
    model = robot.model
    candidates, excluded = [], {}
    for a in range(geom.ngeoms):
        for b in range(a + 1, geom.ngeoms):
            ja, jb = geom.geometryObjects[a].parentJoint, geom.geometryObjects[b].parentJoint
            if ja == jb:
                continue
            if model.parents[ja] == jb or model.parents[jb] == ja:
                excluded[tuple(sorted((link_of[a], link_of[b])))] = "adjacent"
                continue
            candidates.append((a, b))
    if not candidates:
        return (), tuple((a, b, why) for (a, b), why in sorted(excluded.items())), []
    work = pin.GeometryModel()
    for obj in geom.geometryObjects:
        work.addGeometryObject(obj)
    for a, b in candidates:
        work.addCollisionPair(pin.CollisionPair(a, b))
    data, gdata = model.createData(), pin.GeometryData(work)
    rng = np.random.default_rng(0)
    always = np.ones(len(candidates), dtype=bool)
    apart = np.zeros(len(candidates), dtype=int)  # hulls overlap, pieces apart
    request = coal.CollisionRequest()
    for q in robot.random_configurations(rng, PAIR_SAMPLES):
        pin.computeCollisions(model, data, work, gdata, robot.pinocchio_configuration(q), False)
        hit = np.array([r.isCollision() for r in gdata.collisionResults])
        always &= hit
        if not pieces:
            if not always.any():
                break
            continue
        for i in np.flatnonzero(hit).tolist():
            a, b = candidates[i]
            if a in pieces or b in pieces:
                apart[i] += not _pieces_collide(geom, gdata, a, b, pieces, request)
    pairs = []
    for (a, b), stuck in zip(candidates, always):
        if stuck:
            excluded.setdefault(tuple(sorted((link_of[a], link_of[b]))), "always in contact")
        else:
            pairs.append((a, b))
    # Links found always in contact through one pair of elements are excluded as a whole.
    dropped = {k for k, why in excluded.items() if why == "always in contact"}
    pairs = [(a, b) for a, b in pairs if tuple(sorted((link_of[a], link_of[b]))) not in dropped]
    split = [pair for pair, n in zip(candidates, apart) if n >= PIECE_SAMPLES and pair in pairs]
    return tuple(pairs), tuple((a, b, why) for (a, b), why in sorted(excluded.items())), split


def _pieces_collide(
    geom: pin.GeometryModel,
    gdata: pin.GeometryData,
    a: int,
    b: int,
    pieces: Mapping[int, list[coal.Convex]],
    request: coal.CollisionRequest,
) -> bool:
    """Whether elements `a` and `b`, placed as in `gdata`, touch piece against piece."""
    placed = [coal.Transform3s(gdata.oMg[i].rotation, gdata.oMg[i].translation) for i in (a, b)]
    shapes = [pieces.get(i, [geom.geometryObjects[i].geometry]) for i in (a, b)]
    return any(
        coal.collide(x, placed[0], y, placed[1], request, coal.CollisionResult()) for x in shapes[0] for y in shapes[1]
    )


def _with_pieces(
    geom: pin.GeometryModel,
    link_of: tuple[str, ...],
    pairs: tuple[tuple[int, int], ...],
    split: list[tuple[int, int]],
    pieces: Mapping[int, list[coal.Convex]],
) -> tuple[tuple[str, ...], tuple[int, ...], tuple[tuple[int, int], ...]]:
    """Add to `geom` the pieces the pairs in `split` need; those pairs become pairs of their pieces.

    Returns the new ``link_of``, ``part_of`` and pairs.
    """
    link_of, part_of = list(link_of), list(range(geom.ngeoms))
    ids: dict[int, list[int]] = {}
    for element in sorted({i for pair in split for i in pair if i in pieces}):
        obj = geom.geometryObjects[element]
        ids[element] = []
        for n, shape in enumerate(pieces[element]):
            piece = pin.GeometryObject(f"{obj.name}_piece_{n}", obj.parentJoint, obj.parentFrame, obj.placement, shape)
            ids[element].append(geom.addGeometryObject(piece))
            link_of.append(link_of[element])
            part_of.append(element)
    out = []
    for a, b in pairs:
        if (a, b) in split:
            out += [(x, y) for x in ids.get(a, [a]) for y in ids.get(b, [b])]
        else:
            out.append((a, b))
    return tuple(link_of), tuple(part_of), tuple(out)


def arm_collision_model(robot: Robot) -> ArmCollisionModel:
    """The arm's collision model, built once per robot (kept in ``robot.derived``)."""
    return robot.derived.get(ArmCollisionModel, lambda: _build(robot))


def _fixed_lowest(robot: Robot, geom: pin.GeometryModel) -> Mapping[int, float]:
    """Objects whose distance to a floor is the same in 24 sampled configurations, and their lowest height."""
    probe = pin.GeometryModel()
    for obj in geom.geometryObjects:
        probe.addGeometryObject(obj)
    n = probe.ngeoms  # the elements only: pieces are never checked against a floor
    floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), -10.0)
    probe.addGeometryObject(pin.GeometryObject("probe_floor", 0, 0, pin.SE3.Identity(), floor))
    for a in range(n):
        probe.addCollisionPair(pin.CollisionPair(a, n))
    data, gdata = robot.model.createData(), pin.GeometryData(probe)
    rows = []
    for q in robot.random_configurations(np.random.default_rng(0), 24):
        pin.computeDistances(robot.model, data, probe, gdata, robot.pinocchio_configuration(q))
        rows.append([r.min_distance for r in gdata.distanceResults])
    d = np.array(rows)
    # Distances to the probe floor at z = -10 m, less those 10 m: the lowest point's height.
    return MappingProxyType({a: float(d[0, a]) - 10.0 for a in range(n) if np.ptp(d[:, a]) <= 1e-9})


def _build(robot: Robot) -> ArmCollisionModel:
    found = _from_urdf(robot)
    source = "urdf"
    if found is None:
        geom, pieces, source = _capsules(robot), {}, "capsules"
    else:
        geom, pieces = found
    link_of = _link_names(robot, geom)
    pairs, excluded, split = _self_pairs(robot, geom, link_of, pieces)
    reach, lowest = _reach(robot, geom), _fixed_lowest(robot, geom)
    link_of, part_of, pairs = _with_pieces(geom, link_of, pairs, split, pieces)
    return ArmCollisionModel(geom, link_of, part_of, pairs, excluded, source, reach, lowest)
