"""Slab hulls of a non-convex mesh (planner.collision.slabs): they contain it and its solid, within its hull."""

from __future__ import annotations

import coal
import numpy as np

from planner.collision.slabs import MAX_SLABS, slab_hulls

#: An I-shaped outline (two 0.2 x 0.6 m ends joined by a 1.6 x 0.1 m bar), counter-clockwise.
OUTLINE = np.array(
    [
        [-1.0, -0.3],
        [-0.8, -0.3],
        [-0.8, -0.05],
        [0.8, -0.05],
        [0.8, -0.3],
        [1.0, -0.3],
        [1.0, 0.3],
        [0.8, 0.3],
        [0.8, 0.05],
        [-0.8, 0.05],
        [-0.8, 0.3],
        [-1.0, 0.3],
    ]
)
#: The outline cut into triangles that share their edges: each end fanned, the bar in two.
CAP = [(0, 1, 2), (0, 2, 9), (0, 9, 10), (0, 10, 11), (2, 3, 8), (2, 8, 9), (3, 4, 5), (3, 5, 6), (3, 6, 7), (3, 7, 8)]


def _i_beam(height: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The outline extruded from z = 0 to `height`: a closed mesh, outward triangles."""
    n = len(OUTLINE)
    vertices = np.vstack([np.column_stack([OUTLINE, np.zeros(n)]), np.column_stack([OUTLINE, np.full(n, height)])])
    triangles = [(c, b, a) for a, b, c in CAP] + [(a + n, b + n, c + n) for a, b, c in CAP]
    for i in range(n):
        j = (i + 1) % n
        triangles += [(i, j, j + n), (i, j + n, i + n)]
    return vertices, np.array(triangles, dtype=int)


def _inside_outline(xy: np.ndarray) -> np.ndarray:
    x, y = np.abs(xy[:, 0]), np.abs(xy[:, 1])
    return (x <= 1.0) & (y <= 0.3) & ((x >= 0.8) | (y <= 0.05))


def _gap(shape: coal.Convex, point: np.ndarray) -> float:
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    request.gjk_tolerance = 1e-12
    ball = coal.Sphere(1e-12)
    coal.distance(shape, coal.Transform3s(), ball, coal.Transform3s(np.eye(3), point), request, result)
    return float(result.min_distance)


def test_slab_hulls_contain_a_non_convex_solid_and_are_tighter_than_its_hull():
    vertices, triangles = _i_beam()
    whole = 2.0 * 0.6 * 1.0  # the hull: the outline's bounding rectangle, extruded
    pieces = slab_hulls(vertices, triangles, whole)
    assert 2 <= len(pieces) <= MAX_SLABS
    total = sum(p.computeVolume() for p in pieces)
    solid = 2 * 0.2 * 0.6 + 1.6 * 0.1  # 0.4 m^3
    assert solid - 1e-9 <= total < 0.6 * whole
    rng = np.random.default_rng(0)
    points = rng.uniform([-1.0, -0.3, 0.0], [1.0, 0.3, 1.0], size=(4000, 3))
    inside = points[_inside_outline(points[:, :2])]
    assert len(inside) > 1000
    for point in np.vstack([vertices, inside]):
        assert min(_gap(p, point) for p in pieces) <= 1e-9, point
    for p in pieces:  # each piece within the hull
        corners = np.array(p.points()).reshape(-1, 3)
        assert np.all(np.abs(corners[:, 0]) <= 1.0 + 1e-12)
        assert np.all(np.abs(corners[:, 1]) <= 0.3 + 1e-12)
        assert np.all((corners[:, 2] >= -1e-12) & (corners[:, 2] <= 1.0 + 1e-12))


def test_a_convex_mesh_is_not_cut():
    vertices, triangles = _i_beam()
    box = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-0.3, 0.3) for z in (0.0, 1.0)])
    faces = np.array(
        [
            (0, 2, 3),
            (0, 3, 1),
            (4, 5, 7),
            (4, 7, 6),
            (0, 1, 5),
            (0, 5, 4),
            (2, 6, 7),
            (2, 7, 3),
            (0, 4, 6),
            (0, 6, 2),
            (1, 3, 7),
            (1, 7, 5),
        ]
    )
    assert slab_hulls(box, faces, 1.2) == []
    assert slab_hulls(vertices, triangles[:0], 1.2) == []
