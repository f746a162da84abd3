"""A collision-free joint path between two configurations: RRT-Connect, then shortcuts.

:func:`find_clear_path` grows two trees (Kuffner and LaValle's RRT-Connect) from the start and
the goal, lazily (Bohlin and Kavraki 2000): each new node is tested as it is added, the points
every :attr:`PathOptions.resolution` along an edge only when the trees meet, and then only on
the edges of the path through them that its greedy prune keeps (the pass that joins each node
to the farthest later one it sees: a tree edge a longer edge passes over is never tested); a
blocked edge cuts its node off and the trees grow on, and where they meet again the edges
tested at an earlier meeting keep their verdicts. Half of the trees' random targets are
drawn near the straight segment from the start to the goal (the rest uniformly within the
joint limits): an obstacle usually blocks a stretch of that segment and the shortest way
around passes near it, where uniform targets over a wide joint range (an arm whose joints turn
twice around) make the trees wander. The pruned path is shortened by straight edges between
random points along it (not only its nodes; Geraerts and Overmars 2007 call these partial
shortcuts) and the greedy pass again, all decided by the same cheap checks as the trees'
edges (the clearance plus :attr:`PathOptions.margin`, the distance the certificate then asks
for; an edge's points are tested from the one nearest where the last edge was blocked, then
by bisection); then every edge is certified with
:func:`~planner.collision.continuous.check_segment`. If one fails, the trees' own path is
certified and shortened by certified edges only, and if that fails too new trees are grown. A
caller that certifies the motion along the path itself asks without certificates first, and
where that fails has :func:`certify_path` certify the same search's result (without growing
its trees again). It draws from its own generator seeded by :attr:`PathOptions.seed`: the same
seed gives the same path; no global state is touched.
"""

from __future__ import annotations

import bisect
import enum
import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from planner.collision.checker import CollisionChecker
from planner.collision.continuous import check_segment, floored, segment_is_clear, sweep_order
from planner.core.arrays import read_only
from planner.exceptions import InvalidArgumentError

__all__ = [
    "PathOptions",
    "PathResult",
    "PathStatus",
    "certify_path",
    "find_clear_path",
    "ends_margin",
    "path_margin",
    "segment_looks_clear",
]


class PathStatus(str, enum.Enum):
    """How a path search ended."""

    FOUND = "found"
    START_IN_COLLISION = "start_in_collision"
    GOAL_IN_COLLISION = "goal_in_collision"
    NOT_FOUND = "not_found"


@dataclass(frozen=True)
class PathOptions:
    """Settings of :func:`find_clear_path`.

    Attributes:
        seed: Seed of the search's own random generator.
        step: Longest edge the trees grow by [rad or m, largest joint change].
        max_iterations: Extensions per tree before giving up.
        time_budget: Wall-clock limit of the search [s].
        shortcuts: Shortcut attempts on the path found.
        margin: Extra distance [m] kept beyond the scene's clearance, so that the timed
            trajectory, which follows the path closely but not exactly, still keeps it (less
            where the start or goal is closer than that: see :func:`path_margin`).
        resolution: Largest joint change [rad or m] between the cheap distance checks that
            decide edges while the trees grow (the path found is then certified edge by edge).
        line_bias: Share of the trees' random targets drawn near the straight segment from
            the start to the goal (the rest uniformly within the joint limits): most
            obstacles block a stretch of it, and the way around is near it.
        line_spread: Spread of those targets about a point of the segment drawn uniformly:
            per joint a normal spread of this share of the joint's range.
    """

    seed: int = 0
    step: float = 0.6
    max_iterations: int = 4000
    time_budget: float = 5.0
    shortcuts: int = 60
    margin: float = 0.002
    resolution: float = 0.05
    line_bias: float = 0.5
    line_spread: float = 0.1

    def __post_init__(self) -> None:
        for name in ("step", "time_budget", "resolution", "line_spread"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
                raise InvalidArgumentError(f"PathOptions.{name} must be positive, got {v!r}")
        for name in ("max_iterations", "shortcuts", "seed"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise InvalidArgumentError(f"PathOptions.{name} must be a non-negative integer, got {v!r}")
        if not (isinstance(self.margin, (int, float)) and 0 <= self.margin < np.inf):
            raise InvalidArgumentError(f"PathOptions.margin must be >= 0 [m], got {self.margin!r}")
        if not (isinstance(self.line_bias, (int, float)) and 0 <= self.line_bias <= 1):
            raise InvalidArgumentError(f"PathOptions.line_bias must be a share from 0 to 1, got {self.line_bias!r}")


@dataclass(frozen=True)
class PathResult:
    """A path search's outcome.

    Attributes:
        status: The :class:`PathStatus`.
        path: The configurations, start and goal included, shape (n, dof); empty unless found.
        reason: Why no path was found (empty when found).
        iterations: Tree extensions made.
        tree_path: The trees' own path that `path` was shortened from, shape (m, dof); empty
            when no trees were grown (the straight segment, or no path).
    """

    status: PathStatus
    path: np.ndarray
    reason: str
    iterations: int
    tree_path: np.ndarray = field(default_factory=lambda: read_only(np.zeros((0, 0))))

    @property
    def found(self) -> bool:
        """Whether a path was found."""
        return self.status is PathStatus.FOUND


class _Tree:
    """One RRT tree: its nodes, their parents, and which edges (parent to node) passed their test.

    A node whose edge from its parent turns out blocked is cut off with everything grown from
    it (:meth:`cut`): it stays listed but :meth:`nearest` no longer finds it.
    """

    def __init__(self, root: np.ndarray) -> None:
        self._array = np.empty((64, len(root)))
        self._array[0] = root
        # Per node |q|^2 / 2: the nearest has the largest q . target - |q|^2 / 2 (the same as the
        # smallest |q|^2 - 2 q . target: scaling by 2 rounds alike).
        self._half = np.empty(64)
        self._half[0] = 0.5 * float(root @ root)
        self.nodes = [root]
        self.parent = [-1]
        self.tested = [True]  # per node, whether its edge from the parent has passed the edge test
        self.alive = [True]

    def nearest(self, q: np.ndarray) -> int:
        n = len(self.nodes)
        return int((self._array[:n] @ q - self._half[:n]).argmax())

    def add(self, q: np.ndarray, parent: int) -> int:
        n = len(self.nodes)
        if n == len(self._array):
            self._array = np.concatenate([self._array, np.empty_like(self._array)])
            self._half = np.concatenate([self._half, np.empty_like(self._half)])
        self._array[n] = q
        self._half[n] = 0.5 * float(q @ q)
        self.nodes.append(q)
        self.parent.append(parent)
        self.tested.append(False)
        self.alive.append(True)
        return n

    def cut(self, k: int) -> None:
        """Drop node `k` (not the root) and every node grown from it."""
        self.alive[k] = False
        for i in range(k, len(self.nodes)):  # a node comes after its parent
            if i == k or not self.alive[self.parent[i]]:
                self.alive[i] = False
                self._array[i], self._half[i] = 0.0, np.inf  # never the nearest again

    def chain(self, k: int) -> list[int]:
        """The nodes from the root to node `k` (indices)."""
        out = []
        while k >= 0:
            out.append(k)
            k = self.parent[k]
        return out[::-1]


def segment_looks_clear(
    checker: CollisionChecker,
    q_start: np.ndarray,
    q_end: np.ndarray,
    *,
    allow: Sequence[str] = (),
    resolution: float = 0.05,
) -> bool:
    """Whether the straight joint segment keeps the scene's clearance at points every `resolution`.

    Cheap (collision tests with the clearance as security margin), not a certificate: between
    the points it may come closer (:func:`~planner.collision.continuous.segment_is_clear` is
    the certificate). A segment this finds blocked is blocked.
    """
    a, b = np.asarray(q_start, dtype=float), np.asarray(q_end, dtype=float)
    near = _proximity_test(checker, checker.scene.clearance, allow)
    d = b - a
    n = max(1, int(np.ceil(float(np.abs(d).max()) / resolution)))
    return not near(a) and not any(map(near, a + sweep_order(n)[:, None] * d))


def _proximity_test(checker: CollisionChecker, distance: float, allow: Sequence[str]) -> Callable[[np.ndarray], bool]:
    """:meth:`CollisionChecker.closer_than`'s test, as one call of Pinocchio's collision test (its ``floats``).

    The same pairs, margin, broad phase and test object, so the same verdicts; for an arm
    without continuous joints the search's float vectors go to Pinocchio as they are. Kept
    per checker, distance and allow set by :meth:`CollisionChecker.closer_than`; a stand-in
    checker (not a :class:`CollisionChecker`) gives its own test.
    """
    test = floored(checker).closer_than(distance, allow)
    return getattr(test, "floats", test)


def path_margin(clearance: float, end_distance: float, margin: float) -> float:
    """The margin a path can keep [m]: `margin`, or less when an end of it is closer than that.

    A path cannot keep more distance than its ends have: where the start or the goal lies
    within ``clearance + margin`` of something, the path keeps half of what that end has
    beyond the clearance.
    """
    return float(min(margin, max(0.0, (end_distance - clearance) / 2.0)))


def ends_margin(checker: CollisionChecker, ends: Sequence[np.ndarray], allow: Sequence[str], margin: float) -> float:
    """:func:`path_margin` of a path between `ends` [m], from their distances to the scene.

    An end at least ``clearance + 2 margin`` from everything (one proximity test) keeps the
    whole margin; only a nearer one needs its distance.
    """
    mask = checker.pair_mask(allow)
    near = floored(checker).closer_than(checker.scene.clearance + 2.0 * margin, allow)
    end = min([math.inf] + [checker.distance_at(q, mask).distance for q in ends if near(q)])
    return path_margin(checker.scene.clearance, end, margin)


def find_clear_path(
    checker: CollisionChecker,
    q_start: Sequence[float] | np.ndarray,
    q_goal: Sequence[float] | np.ndarray,
    *,
    options: PathOptions | None = None,
    allow: Sequence[str] = (),
    try_straight: bool = True,
    certify: bool = True,
) -> PathResult:
    """A joint path from `q_start` to `q_goal` that keeps the scene's clearance (plus a margin).

    Args:
        checker: The collision checker (robot and scene).
        q_start: Start configuration, shape (dof,).
        q_goal: Goal configuration, shape (dof,).
        options: :class:`PathOptions`; None uses the defaults.
        allow: Scene names whose contact is allowed along the path.
        try_straight: Whether to test the straight segment first (and return it if clear);
            False when the caller has just found it blocked with the same margin
            (:func:`path_margin`), so that its certificate is not computed twice.
        certify: Whether to certify the path's edges (conservative advancement). False returns
            the shortened path whose edges passed only the cheap checks at points every
            :attr:`PathOptions.resolution`, for a caller that certifies the motion along it
            itself (and asks again with True where that fails).

    Returns:
        The :class:`PathResult`; when the ends themselves collide or the search runs out of
        iterations or time, a status and a reason instead of a path.

    Raises:
        InvalidConfigurationError: If an end has the wrong shape or a value that is not finite.
        JointLimitError: If an end lies outside the joint ranges (naming the joint).
    """
    options = options or PathOptions()
    certify_edges = bool(certify)
    robot = checker.robot
    q0 = robot.check_configuration(q_start, batch=False)
    q1 = robot.check_configuration(q_goal, batch=False)
    robot.check_limits(q0, context="path start")
    robot.check_limits(q1, context="path goal")
    mask = checker.pair_mask(allow)
    empty = read_only(np.zeros((0, robot.dof)))
    # An end at least clearance + 2 margin from everything (one proximity test) keeps the whole
    # margin for the path (path_margin); only a nearer one needs its distance.
    far = floored(checker).closer_than(checker.scene.clearance + 2.0 * options.margin, allow)
    ends = [np.inf]
    for q, status, what in ((q0, PathStatus.START_IN_COLLISION, "start"), (q1, PathStatus.GOAL_IN_COLLISION, "goal")):
        if not far(q):
            continue
        c = checker.distance_at(q, mask)
        if c.distance < checker.scene.clearance:
            return PathResult(status, empty, f"the {what} does not keep the clearance: {c}", 0)
        ends.append(c.distance)
    margin = path_margin(checker.scene.clearance, min(ends), options.margin)
    need = checker.scene.clearance + margin

    def clear(a: np.ndarray, b: np.ndarray) -> bool:
        return segment_is_clear(checker, a, b, allow=allow, margin=margin)

    near, quick, between, certify = _edge_tests(checker, need, allow, options.resolution)

    if try_straight and clear(q0, q1):
        return PathResult(PathStatus.FOUND, read_only(np.array([q0, q1])), "", 0)
    rng = np.random.default_rng(options.seed)
    lo = np.where(np.isfinite(robot.lower), robot.lower, q0 - np.pi)
    hi = np.where(np.isfinite(robot.upper), robot.upper, q0 + np.pi)
    deadline = time.perf_counter() + options.time_budget
    iterations = 0
    # Grow the trees with cheap edge checks, shorten the path found with cheap checks (kept a
    # little farther from everything, so that certifying the shortened edges is quick), and
    # certify its edges (conservative advancement). If a shortened edge fails its certificate,
    # the tree's own path is certified instead and shortened only by certified edges; if that
    # fails too, grow new trees (the generator has moved on) until one certifies or the
    # budget is spent.
    while iterations < options.max_iterations and time.perf_counter() <= deadline:
        left = options.max_iterations - iterations
        found, used = _grow(q0, q1, near, between, rng, lo, hi, options, deadline, left)
        iterations += used
        if found is None:
            break
        path = _merge_collinear(found[0])
        short = _shortcut(found[1], quick, between, rng, options.shortcuts)
        tree_path = read_only(np.array(path))
        if not certify_edges or all(certify(a, b) for a, b in zip(short, short[1:])):
            return PathResult(PathStatus.FOUND, read_only(np.array(short)), "", iterations, tree_path)
        if all(certify(a, b) for a, b in zip(path, path[1:])):
            path = _prune(path, lambda a, b: between(a, b) and certify(a, b))
            return PathResult(PathStatus.FOUND, read_only(np.array(path)), "", iterations, tree_path)
    if time.perf_counter() > deadline:
        return PathResult(PathStatus.NOT_FOUND, empty, f"no clear path within {options.time_budget:g} s", iterations)
    return PathResult(PathStatus.NOT_FOUND, empty, f"no clear path in {options.max_iterations} extensions", iterations)


def _edge_tests(checker: CollisionChecker, need: float, allow: Sequence[str], resolution: float) -> tuple:
    """The search's tests at distance `need` [m]: a configuration's, two cheap ones of edges, an edge's certificate."""
    near = _proximity_test(checker, need, allow)
    # Where an edge was last found blocked: the point of a new edge nearest it is tested first
    # (an obstacle that blocked one edge likely blocks the next one tried there), then the rest
    # in bisection order. The same points, the same verdicts.
    blocker: list[np.ndarray] = []

    def blocked(a: np.ndarray, d: np.ndarray, n: int, first: int, last: int, order: np.ndarray, skip: list) -> int:
        """Whether a point ``a + k / n d`` (k from `first` to `last`; `order` their sweep) is too close.

        Returns -2 where one is, else the k tested first (-1: none); ``skip[k]`` is where k / n
        comes in `order` (``len(order)`` where not), so that it is not tested twice.
        """
        at = -1
        if blocker and first <= last:
            dd = float(d @ d)
            at = min(max(round(float((blocker[0] - a) @ d) * n / dd), first), last) if dd > 0.0 else first
            q = a + (at / n) * d
            if near(q):
                blocker[:] = [q]
                return -2
        points = a + order[:, None] * d
        i = skip[at] if at >= 0 else len(points)
        for q in itertools.chain(points[:i], points[i + 1 :]):
            if near(q):
                blocker[:] = [q]
                return -2
        return at

    def quick(a: np.ndarray, b: np.ndarray) -> bool:
        """Proximity checks every `resolution` along the edge, end first, start last: not a certificate.

        The start is tested too: a shortcut starts at a point along the path, not at a tested node.
        """
        d = b - a
        n = max(1, math.ceil(max(map(abs, d.tolist())) / resolution))
        order, skip, _ = _sweep(n)
        first = blocked(a, d, n, 0, n, order, skip)
        return first != -2 and (first == 0 or not near(a))

    def between(a: np.ndarray, b: np.ndarray) -> bool:
        """`quick` without the end (a tree's node, tested when it was added)."""
        d = b - a
        n = max(1, math.ceil(max(map(abs, d.tolist())) / resolution))
        order, _, skip = _sweep(n)
        return blocked(a, d, n, 1, n - 1, order[1:], skip) != -2

    def certify(a: np.ndarray, b: np.ndarray) -> bool:
        """The certificate of an edge `quick` has passed (its sweep would repeat quick's tests)."""
        return check_segment(checker, a, b, allow=allow, clearance=need).clear

    return near, quick, between, certify


_SWEEPS: dict[int, tuple[np.ndarray, list[int], list[int]]] = {}


def _sweep(n: int) -> tuple[np.ndarray, list[int], list[int]]:
    """:func:`sweep_order` of `n` points, and per k where k / n comes in it and in it without its first (the end)."""
    out = _SWEEPS.get(n)
    if out is None:
        order = sweep_order(n)
        where = [n] * (n + 1)  # k = 0 (the start) is not in the sweep
        for i, k in enumerate(np.rint(order * n).astype(int).tolist()):
            where[k] = i
        out = (order, where, [i - 1 for i in where])
        if len(_SWEEPS) < 4096:
            _SWEEPS[n] = out
    return out


def certify_path(
    checker: CollisionChecker,
    found: PathResult,
    *,
    options: PathOptions | None = None,
    allow: Sequence[str] = (),
) -> PathResult:
    """What :func:`find_clear_path` returns with certificates, from its result without them.

    `found` is the result of ``find_clear_path(checker, a, b, options=options, allow=allow,
    certify=False)``: the same search certifies the shortened path's edges, else the trees'
    path's edges (then shortened by certified edges only), else grows new trees. The first two
    are done here from `found` (its trees are not grown again); only the last searches anew.

    Args:
        checker: The collision checker `found` was searched with.
        found: The search's result without certificates.
        options: The same :class:`PathOptions`; None uses the defaults.
        allow: The same scene names.

    Returns:
        The :class:`PathResult` the search with certificates gives (`found` itself where no
        trees were grown: the straight segment, certified, or no path).
    """
    if not found.found or len(found.tree_path) == 0:
        return found
    options = options or PathOptions()
    q0, q1 = np.array(found.path[0]), np.array(found.path[-1])
    need = checker.scene.clearance + ends_margin(checker, (q0, q1), allow, options.margin)
    _, _, between, certify = _edge_tests(checker, need, allow, options.resolution)
    short, path = list(found.path), list(found.tree_path)
    if all(certify(a, b) for a, b in zip(short, short[1:])):
        return found
    if all(certify(a, b) for a, b in zip(path, path[1:])):
        path = _prune(path, lambda a, b: between(a, b) and certify(a, b))
        return PathResult(PathStatus.FOUND, read_only(np.array(path)), "", found.iterations, found.tree_path)
    return find_clear_path(checker, q0, q1, options=options, allow=allow, try_straight=False)


def _grow(
    q0: np.ndarray,
    q1: np.ndarray,
    blocked,
    edge_ok,
    rng: np.random.Generator,
    lo: np.ndarray,
    hi: np.ndarray,
    options: PathOptions,
    deadline: float,
    budget: int,
) -> tuple[tuple[list[np.ndarray], list[np.ndarray]] | None, int]:
    """RRT-Connect from both ends, lazily: `blocked` rejects new nodes, `edge_ok` decides the edges of a path found.

    Nodes are tested as they are added; the points between them only once the trees meet, on
    the edges of the path through them (most edges the trees grow never join a path). A
    blocked tree edge cuts its node off (with what grew from it) and the trees grow on.
    `edge_ok(a, b)` tests the points strictly between `a` and `b`. A share
    :attr:`PathOptions.line_bias` of the targets is drawn near the segment from `q0` to `q1`.

    Returns:
        The trees' path and its greedy prune (:func:`_settle`), start first, or None; and the
        extensions used.
    """
    trees = (_Tree(q0), _Tree(q1))
    seen: dict[tuple[int, int], bool] = {}  # edges tested where the trees met (by their nodes' ids)
    step, bias = options.step, options.line_bias
    span = hi - lo  # lo + span * rng.random(n) draws as rng.uniform(lo, hi), without its argument checks
    spread, line = options.line_spread * span, q1 - q0
    dof = len(lo)
    for it in range(1, budget + 1):
        if time.perf_counter() > deadline:
            return None, it
        a, b = trees if it % 2 else trees[::-1]
        if bias and rng.random() < bias:
            target = np.minimum(np.maximum(q0 + rng.random() * line + spread * rng.standard_normal(dof), lo), hi)
        else:
            target = lo + span * rng.random(dof)
        # Extend: one step from the nearest node toward the target.
        k = a.nearest(target)
        q_near = a.nodes[k]
        delta = target - q_near
        far = max(map(abs, delta.tolist()))  # the largest joint change (as np.abs(delta).max())
        if far == 0.0:
            continue
        q_new = q_near + delta * min(1.0, step / far)
        if blocked(q_new):
            continue
        new = a.add(q_new, k)
        # Connect: grow the other tree toward the new node until it arrives or is blocked.
        k = b.nearest(q_new)
        while True:
            q_near = b.nodes[k]
            delta = q_new - q_near
            far = max(map(abs, delta.tolist()))
            if far <= step:
                found = _settle(a, new, b, k, trees[0] is a, edge_ok, seen)
                if found is not None:
                    return found, it
                break
            q_next = q_near + delta * (step / far)
            if blocked(q_next):
                break
            k = b.add(q_next, k)
    return None, budget


def _settle(
    a: _Tree, ka: int, b: _Tree, kb: int, a_is_start: bool, edge_ok, seen: dict | None = None
) -> tuple[list[np.ndarray], list[np.ndarray]] | None:
    """The path where the trees meet (`a`'s node `ka` beside `b`'s `kb`) and its greedy prune.

    The prune (:func:`_prune`) joins each node to the farthest later one `edge_ok` passes; a
    tree edge is tested only where no longer edge passes over it (then its verdict is kept in
    the tree, and a blocked one is cut off with what grew from it), as is the edge between the
    trees. `seen` keeps the verdicts of the edges tested (by their nodes' identity) for the
    trees' next meeting: where that path shares nodes with one found blocked, the edges
    between them are not tested again.

    Returns:
        The path and its prune, start first; None where an edge it needs is blocked.
    """
    if seen is not None:
        test = edge_ok

        def edge_ok(p: np.ndarray, q: np.ndarray) -> bool:
            key = (id(p), id(q))
            ok = seen.get(key)
            if ok is None:
                ok = seen[key] = test(p, q)
            return ok

    chain_a, chain_b = a.chain(ka), b.chain(kb)[::-1]  # root to ka; kb to root
    nodes = [a.nodes[i] for i in chain_a] + [b.nodes[i] for i in chain_b]
    # Per edge (node e to e + 1): its tree and child node, or None between the trees.
    edges: list[tuple[_Tree, int] | None] = [(a, i) for i in chain_a[1:]] + [None] + [(b, i) for i in chain_b[:-1]]
    if not a_is_start:
        nodes, edges = nodes[::-1], edges[::-1]
    out, i, n = [nodes[0]], 0, len(nodes)
    while i < n - 1:
        j = n - 1
        while j > i + 1 and not edge_ok(nodes[i], nodes[j]):
            j -= 1
        if j == i + 1:
            edge = edges[i]
            if edge is None:
                if not edge_ok(nodes[i], nodes[j]):
                    return None
            else:
                tree, child = edge
                if not tree.tested[child]:
                    if not edge_ok(nodes[i], nodes[j]):
                        tree.cut(child)
                        return None
                    tree.tested[child] = True
        out.append(nodes[j])
        i = j
    return nodes, out


def _merge_collinear(path: list[np.ndarray]) -> list[np.ndarray]:
    """Drop nodes where the path goes straight on (the trees' connect steps): the edge is the same."""
    out = [path[0]]
    for k in range(1, len(path) - 1):
        u, w = path[k] - out[-1], path[k + 1] - path[k]
        nu, nw = math.sqrt(float(u @ u)), math.sqrt(float(w @ w))  # as np.linalg.norm computes them
        if nu > 0 and nw > 0 and float(u @ w) >= nu * nw * (1.0 - 1e-12):
            continue
        out.append(path[k])
    out.append(path[-1])
    return out


def _prune(path: list[np.ndarray], edge_ok) -> list[np.ndarray]:
    """From each node, the farthest later node `edge_ok` connects it to straight (greedy).

    `edge_ok(a, b)` need not test `b` (a node of the path, tested already).
    """
    out, i = [path[0]], 0
    while i < len(path) - 1:
        j = len(path) - 1
        while j > i + 1 and not edge_ok(path[i], path[j]):
            j -= 1
        out.append(path[j])
        i = j
    return out


#: Least share of its stretch along the path a shortcut must save to be tried.
_GAIN = 0.05


def _shortcut(path: list[np.ndarray], edge_ok, inner_ok, rng: np.random.Generator, attempts: int) -> list[np.ndarray]:
    """Shorten a pruned path: straight edges between random points along it, then the greedy prune.

    The points are drawn by length along the path (not only its nodes), so a corner is cut
    wherever the straight edge past it is clear (`edge_ok`; `inner_ok` where its end is a
    node, as in the prune). An edge that would save less than :data:`_GAIN` of the stretch it
    replaces is not tried.
    """
    path = list(path)
    cum: list[float] | None = None  # the length along the path at each node, until the path changes
    edges: list[np.ndarray] = []  # path[k + 1] - path[k], likewise
    for _ in range(attempts):
        if len(path) <= 2:
            break
        if cum is None:
            edges = [b - a for a, b in zip(path, path[1:])]
            cum = [0.0, *itertools.accumulate(math.sqrt(float(e @ e)) for e in edges)]
        # As rng.uniform(0, cum[-1], 2) draws (0 + range * random), without its argument checks.
        x, y = sorted((cum[-1] * rng.random(2)).tolist())
        last = len(path) - 2
        i, j = min(bisect.bisect_right(cum, x) - 1, last), min(bisect.bisect_right(cum, y) - 1, last)
        if i == j:
            continue
        a = path[i] + (x - cum[i]) / (cum[i + 1] - cum[i]) * edges[i]
        b = path[j] + (y - cum[j]) / (cum[j + 1] - cum[j]) * edges[j]
        if (y - x) - math.sqrt(float((b - a) @ (b - a))) <= _GAIN * (y - x):
            continue  # nearly straight there already: not worth the edge's checks
        if edge_ok(a, b):
            path = path[: i + 1] + [a, b] + path[j + 1 :]
            cum = None
    return _prune(path, inner_ok)
