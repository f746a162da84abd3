"""A mesh as a few convex pieces that together contain it: the hulls of its parts between parallel planes.

A non-convex link (a UR5 upper arm: a tube with a motor housing at each end) is a poor fit for
its single convex hull: the hull fills the bend between the housings, and two links whose hulls
overlap may be far apart. Cut by parallel planes into slabs, each slab's part of the mesh has a
hull far closer to it (:func:`slab_hulls`).

Why the pieces contain the mesh and the solid it bounds: a point ``p`` of the solid within a
slab lies on a line through ``p`` parallel to the planes (so within the slab); the solid is
bounded, so the line leaves it on both sides of ``p`` at points of the mesh's surface, in the
slab. Those lie on the mesh's triangles clipped to the slab: convex polygons whose corners are
the mesh's vertices within the slab and the points where its edges cross the slab's two planes.
The hull of those points therefore contains ``p``, and every point of the mesh's surface in the
slab. Each piece lies within the mesh's hull (its points are on the mesh), so a distance to a
piece is never below the distance to the hull, and the least distance to the pieces is never
above the distance to the mesh.
"""

from __future__ import annotations

import coal
import numpy as np

__all__ = ["MAX_SLABS", "MAX_TRIANGLES", "SLAB_GAIN", "SLAB_GRID", "mesh_arrays", "slab_hulls"]

#: Most slabs a mesh is cut into.
MAX_SLABS = 4

#: Share of the hull's volume a further slab must save, on average, to be made.
SLAB_GAIN = 0.05

#: Most triangles of a mesh that is cut (reading a mesh's triangles from coal costs about 8 us
#: each): a larger one is checked as its hull alone.
MAX_TRIANGLES = 20000

#: Planes the cuts are chosen among: this many slabs of equal width along the mesh's longest axis.
SLAB_GRID = 12


def mesh_arrays(mesh: coal.BVHModelBase) -> tuple[np.ndarray, np.ndarray]:
    """A coal mesh's vertices [m], shape (n, 3), and triangles (vertex indices), shape (m, 3)."""
    vertices = np.array(mesh.vertices(), dtype=float).reshape(-1, 3)
    triangles = np.array(
        [[t[0], t[1], t[2]] for t in (mesh.tri_indices(i) for i in range(mesh.num_tris))], dtype=int
    ).reshape(-1, 3)
    return vertices, triangles


def _hull(points: np.ndarray) -> coal.Convex:
    vertices = coal.StdVec_Vec3s()
    vertices.extend(list(points))
    return coal.Convex.convexHull(vertices, True, "Qt")


def _volume(points: np.ndarray) -> float:
    """The volume of the points' hull [m^3]; inf where there is no hull (too few points, or flat)."""
    if len(points) < 4:
        return float("inf")
    try:
        return float(_hull(points).computeVolume())
    except Exception:  # qhull refuses flat or degenerate sets with a plain error
        return float("inf")


def _edges(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's edges (vertex index pairs, each once, shape (e, 2)) and how many triangles share each."""
    sides = np.sort(np.vstack([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    return np.unique(sides, axis=0, return_counts=True)


def _closed_volume(vertices: np.ndarray, triangles: np.ndarray, counts: np.ndarray) -> float | None:
    """The volume the mesh bounds [m^3] when every edge is shared by two triangles, else None.

    `counts`: per edge, the triangles sharing it (of :func:`_edges`).
    """
    if not np.all(counts == 2):
        return None
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    return abs(float(np.sum(np.einsum("ij,ij->i", a, np.cross(b, c)))) / 6.0)


def slab_hulls(vertices: np.ndarray, triangles: np.ndarray, whole: float) -> list[coal.Convex]:
    """Convex pieces whose union contains a mesh and the solid it bounds (see the module docstring).

    The mesh is cut by planes normal to its longest (principal) axis, chosen among
    :data:`SLAB_GRID` equal slabs to make the pieces' total volume least, into at most
    :data:`MAX_SLABS` slabs, each slab past the first charged :data:`SLAB_GAIN` of the hull's
    volume (so a cut is made where it saves more than that). A closed mesh whose hull exceeds the
    solid it bounds by less than twice that share (convex, or nearly) is not cut.

    Args:
        vertices: The mesh's vertices [m], shape (n, 3).
        triangles: Its triangles (indices into `vertices`), shape (m, 3).
        whole: The volume of its convex hull [m^3].

    Returns:
        The pieces (two or more), or an empty list where cutting saves too little.
    """
    if len(triangles) == 0 or not np.isfinite(whole) or whole <= 0.0:
        return []
    edges, counts = _edges(triangles)
    inside = _closed_volume(vertices, triangles, counts)
    if inside is not None and whole - inside < 2.0 * SLAB_GAIN * whole:
        # The pieces contain the solid, so they save at most what the hull exceeds it by, and
        # cuts between parallel planes recover only part of that: not worth the hulls (UR5's
        # shoulder and wrists, within 8 % of their hulls; Panda's meshes, convex).
        return []
    _, _, axes = np.linalg.svd(vertices - vertices.mean(axis=0), full_matrices=False)
    s = vertices @ axes[0]
    cuts = np.linspace(float(s.min()), float(s.max()), SLAB_GRID + 1)
    crossings = []
    for c in cuts:
        a, b = s[edges[:, 0]] - c, s[edges[:, 1]] - c
        crossing = a * b < 0.0
        f = (a[crossing] / (a[crossing] - b[crossing]))[:, None]
        p, q = vertices[edges[crossing, 0]], vertices[edges[crossing, 1]]
        crossings.append(p + f * (q - p))

    # Per cell between two neighbouring cuts, the corners of the triangles clipped to it, kept to
    # their hull's vertices: a slab of several cells has the hull of its cells' points.
    cells = []
    for k in range(SLAB_GRID):
        corners = np.vstack([vertices[(s >= cuts[k]) & (s <= cuts[k + 1])], crossings[k], crossings[k + 1]])
        try:
            corners = np.array(_hull(corners).points(), dtype=float).reshape(-1, 3)
        except Exception:  # too few points, or flat (qhull raises a plain error): kept as they are
            pass
        cells.append(corners)

    def points(i: int, j: int) -> np.ndarray:
        """Points whose hull is that of the triangles clipped to the slab between cuts i and j."""
        return np.vstack(cells[i:j])

    volumes: dict[tuple[int, int], float] = {}

    def volume(i: int, j: int) -> float:
        if (i, j) not in volumes:
            volumes[(i, j)] = whole if (i, j) == (0, SLAB_GRID) else _volume(points(i, j))
        return volumes[(i, j)]

    # Least total volume covering cuts 0..j with k slabs, and the cuts (dynamic programming); each
    # slab past the first is charged SLAB_GAIN of the hull's volume.
    best = {(1, j): (volume(0, j), (0, j)) for j in range(1, SLAB_GRID + 1)}
    chosen, charged = best[(1, SLAB_GRID)], whole
    for k in range(2, MAX_SLABS + 1):
        for j in range(k, SLAB_GRID + 1):
            best[(k, j)] = min(
                ((best[(k - 1, i)][0] + volume(i, j), (*best[(k - 1, i)][1], j)) for i in range(k - 1, j)),
                key=lambda row: row[0],
            )
        cost = best[(k, SLAB_GRID)][0] + (k - 1) * SLAB_GAIN * whole
        if cost < charged:
            chosen, charged = best[(k, SLAB_GRID)], cost
    bounds = chosen[1]
    if len(bounds) <= 2 or not np.isfinite(chosen[0]):
        return []
    return [_hull(points(i, j)) for i, j in zip(bounds[:-1], bounds[1:])]
