"""PNG plots of plans, singularity margins, arm poses and IK benchmarks (needs matplotlib).

Every function takes plain arrays (so it can draw any planner's output), writes one PNG and
returns its path. matplotlib is an optional dependency (``pip install 'servo-arm-planner[demo]'``); it
is imported only when a plot is drawn, with the non-interactive Agg backend.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from planner.collision.scene import Box, Cylinder, Obstacle, Scene
from planner.core.version import install_hint
from planner.exceptions import PlannerError

if TYPE_CHECKING:
    from planner.app.motion_plan import MotionPlan
    from planner.model.robot import Robot

__all__ = [
    "draw_scene",
    "obstacle_points",
    "plot_arm_poses",
    "plot_ik_benchmark",
    "plot_joint_profiles",
    "plot_manipulability",
    "plot_plan",
    "pyplot",
]


def pyplot() -> Any:
    """matplotlib.pyplot with the non-interactive Agg backend, or a PlannerError naming the extra."""
    try:
        import matplotlib
    except ImportError as exc:
        raise PlannerError(f"plots need matplotlib: {install_hint('demo')}") from exc
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: str | Path) -> Path:
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    fig.clf()
    pyplot().close(fig)
    return out


def plot_joint_profiles(
    path: str | Path,
    times: np.ndarray,
    position: np.ndarray,
    velocity: np.ndarray,
    acceleration: np.ndarray,
    jerk: np.ndarray,
    *,
    joint_names: Sequence[str],
    limits: Mapping[str, np.ndarray] | None = None,
    waypoint_times: Sequence[float] = (),
    title: str = "",
) -> Path:
    """Joint position, velocity, acceleration and jerk against time, limits dashed.

    Args:
        path: PNG file to write.
        times: Sample times, shape (N,) [s].
        position: Shape (N, dof) [rad or m].
        velocity: Shape (N, dof) [rad/s or m/s].
        acceleration: Shape (N, dof) [rad/s^2 or m/s^2].
        jerk: Shape (N, dof) [rad/s^3 or m/s^3].
        joint_names: One label per joint.
        limits: Optional ``"lower"``, ``"upper"``, ``"velocity"``, ``"acceleration"``, ``"jerk"``
            arrays of shape (dof,), drawn as dashed lines (symmetric for the derivatives).
        waypoint_times: Times [s] marked by vertical dotted lines.
        title: Figure title.

    Returns:
        The PNG path.
    """
    plt = pyplot()
    limits = limits or {}
    fig, axes = plt.subplots(4, 1, figsize=(10, 10), sharex=True)
    rows = [
        ("position [rad]", position, ("lower", "upper")),
        ("velocity [rad/s]", velocity, ("velocity",)),
        ("acceleration [rad/s²]", acceleration, ("acceleration",)),
        ("jerk [rad/s³]", jerk, ("jerk",)),
    ]
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, (label, values, keys) in zip(axes, rows):
        for j, name in enumerate(joint_names):
            color = colors[j % len(colors)]
            ax.plot(times, values[:, j], color=color, label=name, linewidth=1.2)
            for key in keys:
                if key in limits:
                    bound = float(np.asarray(limits[key])[j])
                    if not np.isfinite(bound):
                        continue
                    ax.axhline(bound, color=color, linestyle="--", linewidth=0.7, alpha=0.7)
                    if key not in ("lower", "upper"):
                        ax.axhline(-bound, color=color, linestyle="--", linewidth=0.7, alpha=0.7)
        for t in waypoint_times:
            ax.axvline(t, color="0.5", linestyle=":", linewidth=0.8)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8, ncol=min(len(joint_names), 4))
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(title or "Joint trajectories (dashed: limits, dotted: waypoints)")
    fig.tight_layout()
    return _save(fig, path)


def plot_manipulability(
    path: str | Path,
    times: np.ndarray,
    values: np.ndarray,
    *,
    threshold: float | None = None,
    waypoint_times: Sequence[float] = (),
    ylabel: str = "inverse condition number",
    title: str = "",
) -> Path:
    """A singularity measure along a plan, with the threshold drawn.

    Args:
        path: PNG file to write.
        times: Shape (N,) [s].
        values: Shape (N,), e.g. the inverse condition number of the Jacobian.
        threshold: Drawn as a red dashed line when given.
        waypoint_times: Times [s] marked by vertical dotted lines.
        ylabel: Axis label naming the measure.
        title: Figure title.

    Returns:
        The PNG path.
    """
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 3.5))
    ax.plot(times, values, linewidth=1.4, label=ylabel)
    if threshold is not None:
        ax.axhline(threshold, color="tab:red", linestyle="--", label=f"threshold {threshold:.3g}")
    for t in waypoint_times:
        ax.axvline(t, color="0.5", linestyle=":", linewidth=0.8)
    ax.set_xlabel("time [s]")
    ax.set_ylabel(ylabel)
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title or "Distance from singularity along the plan")
    fig.tight_layout()
    return _save(fig, path)


def plot_arm_poses(
    path: str | Path,
    robot: Robot,
    configurations: np.ndarray,
    *,
    labels: Sequence[str] | None = None,
    title: str = "",
    scene: Scene | None = None,
) -> Path:
    """Stick figures of the arm at each configuration: a side view and a top view.

    The side view plots height against the signed horizontal distance along the first
    configuration's tip direction, so arms that turn at the base stay readable.

    Args:
        path: PNG file to write.
        robot: A :class:`planner.Robot`.
        configurations: Shape (K, dof) [rad or m].
        labels: One label per configuration (default: "1", "2", ...).
        title: Figure title.
        scene: Obstacles (grey: their outline from above, their height span against their
            distance from the base axis at the side) and the floor, or None.

    Returns:
        The PNG path.
    """
    plt = pyplot()
    qs = np.atleast_2d(np.asarray(configurations, dtype=float))
    labels = list(labels) if labels is not None else [str(k + 1) for k in range(len(qs))]
    chains = [robot.joint_positions(q) for q in qs]
    fig, (side, top) = plt.subplots(1, 2, figsize=(11, 5))
    colors = plt.cm.viridis(np.linspace(0, 0.9, len(qs)))
    for pts, label, color in zip(chains, labels, colors):
        radial = np.hypot(pts[:, 0], pts[:, 1]) * np.sign(pts[:, 0] * pts[-1, 0] + pts[:, 1] * pts[-1, 1] + 1e-300)
        side.plot(radial, pts[:, 2], "-o", color=color, markersize=3, linewidth=2, label=label)
        top.plot(pts[:, 0], pts[:, 1], "-o", color=color, markersize=3, linewidth=2, label=label)
        side.plot(radial[-1], pts[-1, 2], "*", color=color, markersize=10)
        top.plot(pts[-1, 0], pts[-1, 1], "*", color=color, markersize=10)
    if scene is not None:
        draw_scene(side, top, scene)
    side.set_xlabel("horizontal reach [m]")
    side.set_ylabel("z [m]")
    side.set_title("side view")
    top.set_xlabel("x [m]")
    top.set_ylabel("y [m]")
    top.set_title("top view")
    for ax in (side, top):
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    top.legend(loc="best", fontsize=7, ncol=2)
    fig.suptitle(title or f"{robot.name} at each waypoint (star: tip)")
    fig.tight_layout()
    return _save(fig, path)


def obstacle_points(obstacle: Obstacle) -> np.ndarray:
    """Points on the obstacle's outline (box corners, circles of a cylinder or sphere), shape (n, 3)."""
    shape = obstacle.shape
    a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    c, s = np.cos(a), np.sin(a)
    z0 = np.zeros_like(a)
    if isinstance(shape, Box):
        local = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * (np.array(shape.size) / 2)
    elif isinstance(shape, Cylinder):
        r, h = shape.radius, shape.length / 2
        local = np.vstack([np.column_stack([r * c, r * s, z0 + z]) for z in (-h, h)])
    else:
        r = shape.radius
        local = np.vstack([np.column_stack([r * c, r * s, z0]), np.column_stack([r * c, z0, r * s])])
    return local @ np.asarray(obstacle.rotation).T + np.asarray(obstacle.position)


def draw_scene(side: Any, top: Any, scene: Scene) -> None:
    """Obstacles in grey on a side view (height span against reach) and a top view (outline), the floor as a line."""
    from matplotlib.patches import Polygon, Rectangle

    for obstacle in scene.obstacles:
        pts = obstacle_points(obstacle)
        xy = pts[:, :2]
        centre = xy.mean(axis=0)
        order = np.argsort(np.arctan2(xy[:, 1] - centre[1], xy[:, 0] - centre[0]))
        top.add_patch(Polygon(xy[order], closed=True, color="0.6", alpha=0.5))
        top.annotate(obstacle.name, centre, fontsize=7, ha="center", va="center")
        radial = np.hypot(xy[:, 0], xy[:, 1])
        lo, hi = radial.min(), radial.max()
        side.add_patch(
            Rectangle((lo, pts[:, 2].min()), hi - lo, np.ptp(pts[:, 2]), color="0.6", alpha=0.35, linewidth=0)
        )
        side.annotate(obstacle.name, ((lo + hi) / 2, pts[:, 2].max()), fontsize=7, ha="center", va="bottom")
    if scene.floor is not None:
        side.axhline(scene.floor, color="0.4", linewidth=2, label="floor")


def plot_ik_benchmark(path: str | Path, rows: Sequence[Mapping[str, Any]], *, title: str = "") -> Path:
    """Solve rate and median time per call, grouped by robot, one bar per method.

    Args:
        path: PNG file to write.
        rows: Mappings with ``"robot"``, ``"method"``, ``"solve_rate"`` (0..1) and
            ``"median_ms"`` [ms].
        title: Figure title.

    Returns:
        The PNG path.
    """
    plt = pyplot()
    robots = list(dict.fromkeys(str(r["robot"]) for r in rows))
    methods = list(dict.fromkeys(str(r["method"]) for r in rows))
    width = 0.8 / max(len(methods), 1)
    x = np.arange(len(robots))
    fig, (ax_rate, ax_time) = plt.subplots(1, 2, figsize=(12, 4.5))
    for k, method in enumerate(methods):
        rate = [np.nan] * len(robots)
        time_ms = [np.nan] * len(robots)
        for r in rows:
            if str(r["method"]) == method:
                i = robots.index(str(r["robot"]))
                rate[i] = 100.0 * float(r["solve_rate"])
                time_ms[i] = float(r["median_ms"])
        ax_rate.bar(x + k * width, rate, width, label=method)
        ax_time.bar(x + k * width, time_ms, width, label=method)
    for ax in (ax_rate, ax_time):
        ax.set_xticks(x + width * (len(methods) - 1) / 2, robots, rotation=20)
        ax.grid(axis="y", alpha=0.3)
    ax_rate.set_ylabel("solve rate [%]")
    ax_rate.set_ylim(0, 105)
    ax_time.set_ylabel("median time per call [ms]")
    ax_time.set_yscale("log")
    ax_rate.legend(fontsize=8)
    fig.suptitle(title or "IK: analytic vs optimised")
    fig.tight_layout()
    return _save(fig, path)


def plot_plan(
    out: str | Path, robot: Robot, plan: MotionPlan, *, rate: float = 200.0, prefix: str = ""
) -> tuple[Path, ...]:
    """The three pictures of a :class:`planner.MotionPlan`, written into a directory.

    ``joints.png`` (position, velocity, acceleration, jerk with limits and waypoints),
    ``singularity.png`` (inverse condition number along the plan, threshold drawn) and
    ``arm.png`` (the arm at each waypoint).

    Args:
        out: Output directory (created if missing).
        robot: The :class:`planner.Robot` the plan is for.
        plan: The plan.
        rate: Sampling rate of the curves [Hz].
        prefix: Prepended to each file name.

    Returns:
        The three PNG paths.
    """
    folder = Path(out)
    traj = plan.trajectory
    t = np.unique(np.concatenate([traj.times(rate), traj.waypoint_times]))
    s = traj.sample(t)
    lim = plan.limits
    limits = {
        "lower": lim.lower,
        "upper": lim.upper,
        "velocity": lim.velocity,
        "acceleration": lim.acceleration,
        "jerk": lim.jerk,
    }
    name = plan.robot
    joints = plot_joint_profiles(
        folder / f"{prefix}joints.png",
        t,
        s.q,
        s.qd,
        s.qdd,
        s.qddd,
        joint_names=robot.joint_names,
        limits=limits,
        waypoint_times=plan.waypoint_times,
        title=f"{name}: joint trajectories, {traj.duration:.2f} s (dashed: limits, dotted: waypoints)",
    )
    inverse, _ = robot.conditioning(s.q, plan.singularity.task)
    singular = plot_manipulability(
        folder / f"{prefix}singularity.png",
        t,
        inverse,
        threshold=plan.singularity.threshold,
        waypoint_times=plan.waypoint_times,
        ylabel=f"inverse condition number ({plan.singularity.task} Jacobian)",
        title=f"{name}: distance from singularity along the plan",
    )
    labels = [f"{k}" + (" (singular)" if k in plan.singular_waypoints else "") for k in range(len(plan.waypoints))]
    arm = plot_arm_poses(
        folder / f"{prefix}arm.png",
        robot,
        plan.waypoints,
        labels=labels,
        title=f"{name} at each waypoint (star: tip)"
        + (", grey: obstacles" if plan.scene and plan.scene.obstacles else ""),
        scene=plan.scene,
    )
    return joints, singular, arm
