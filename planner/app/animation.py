"""Animated GIFs of a plan: the arm moving through it at real speed (needs matplotlib).

:func:`animate_plan` draws the arm as a stick figure at evenly spaced times of the plan,
either as a side view and a top view or as one 3-D view, with the time and the current
waypoint's label on each frame, and writes a GIF with matplotlib's ``PillowWriter`` (Pillow
comes with matplotlib). Frames are spaced ``speed / fps`` seconds of plan time apart, so the
GIF plays at real speed for ``speed=1``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from planner.app.plots import draw_scene, obstacle_points, pyplot
from planner.exceptions import InvalidArgumentError

if TYPE_CHECKING:
    from planner.app.motion_plan import MotionPlan
    from planner.model.robot import Robot

__all__ = ["ANIMATION_VIEWS", "animate_plan", "frame_times"]

#: The views :func:`animate_plan` draws.
ANIMATION_VIEWS: tuple[str, ...] = ("side-top", "3d")
DPI = 80
MAX_FRAMES = 3000
#: Lowest fps: a GIF stores a frame's delay in 1/100 s in 16 bits (at most 655.35 s).
MIN_FPS = 0.01

ARM = "#ff6e00"
PATH = "#2870dc"
WAYPOINT = "#149632"
SINGULAR = "#d2145a"
DETOUR = "#963cc8"


def _canvas_pillow_writer() -> type:
    from matplotlib.animation import PillowWriter
    from PIL import Image

    class CanvasPillowWriter(PillowWriter):
        """matplotlib's PillowWriter taking each frame from the drawn canvas, without a redraw.

        The stock writer saves the whole figure once per frame (every axis and tick label
        again) and leaves Pillow to find a palette per frame; here only the moving artists are
        drawn onto a cached background, and every frame takes the first frame's palette (the
        colours do not change from frame to frame: the GIF is about half the size, and
        written several times faster).
        """

        _palette: Any = None

        def grab_frame(self, **savefig_kwargs: Any) -> None:
            canvas = self.fig.canvas
            width, height = canvas.get_width_height(physical=True)
            frame = Image.frombuffer("RGBA", (width, height), bytes(canvas.buffer_rgba())).convert("RGB")
            if self._palette is None:
                self._palette = frame.quantize(colors=256, method=Image.Quantize.FASTOCTREE)
            self._frames.append(frame.quantize(palette=self._palette, dither=Image.Dither.NONE))

    return CanvasPillowWriter


def frame_times(duration: float, fps: float, speed: float = 1.0) -> np.ndarray:
    """Plan times [s] of the frames: every ``speed / fps`` seconds, and the end.

    Args:
        duration: Plan duration [s].
        fps: Frames per second of the GIF [Hz].
        speed: Plan seconds per GIF second.

    Returns:
        Shape (K,), from 0 to `duration` inclusive, K >= 2.
    """
    step = speed / fps
    n = max(int(math.ceil(duration / step - 1e-9)), 1)
    return np.minimum(np.arange(n + 1) * step, duration)


def _check(fps: float, speed: float, size: Sequence[int], view: str, duration: float, path: Path) -> tuple[int, int]:
    if path.suffix.lower() != ".gif":
        raise InvalidArgumentError(f"an animation is written as a GIF: the file name must end in .gif, got {path}")
    if isinstance(fps, bool) or not (isinstance(fps, (int, float)) and math.isfinite(fps) and MIN_FPS <= fps <= 60):
        raise InvalidArgumentError(f"fps must be in [{MIN_FPS:g}, 60] frames per second, got {fps}")
    if isinstance(speed, bool) or not (isinstance(speed, (int, float)) and math.isfinite(speed) and speed > 0):
        raise InvalidArgumentError(f"speed must be a positive number (plan seconds per second), got {speed}")
    if view not in ANIMATION_VIEWS:
        raise InvalidArgumentError(f"unknown view {view!r}; valid: {', '.join(ANIMATION_VIEWS)}")
    try:
        width, height = (int(v) for v in size)
    except (TypeError, ValueError) as exc:
        raise InvalidArgumentError(f"size must be (width, height) in pixels, got {size!r}") from exc
    if not (64 <= width <= 4096 and 64 <= height <= 4096):
        raise InvalidArgumentError(f"size must be between 64 and 4096 pixels each way, got {width}x{height}")
    # Counted before frame_times makes them: a tiny speed asked for billions (out of memory).
    frames = max(math.ceil(duration * fps / speed - 1e-9), 1) + 1 if duration * fps / speed < 1e15 else math.inf
    if frames > MAX_FRAMES:
        raise InvalidArgumentError(
            f"{frames:g} frames for a {duration:.1f} s plan at {fps:g} fps and speed {speed:g}; at most {MAX_FRAMES} "
            "(lower the fps or raise the speed)"
        )
    return width, height


def _outline(obstacle: Any, points: np.ndarray) -> list[np.ndarray]:
    """Polylines of an obstacle's wireframe from its outline points (:func:`obstacle_points`)."""
    from planner.collision.scene import Box

    if isinstance(obstacle.shape, Box):  # 8 corners, index 4x + 2y + z: edges join corners one bit apart
        return [points[[a, b]] for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
    circles = [np.vstack([c, c[:1]]) for c in np.split(points, 2)]  # two closed circles of 24 points
    return circles + [points[[k, k + 24]] for k in (0, 6, 12, 18)]


def _side(points: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Signed horizontal distance along `heading` (unit, horizontal) and height: the side view."""
    radial = np.hypot(points[..., 0], points[..., 1])
    sign = np.sign(points[..., 0] * heading[0] + points[..., 1] * heading[1] + 1e-12)
    return np.stack([radial * sign, points[..., 2]], axis=-1)


def animate_plan(
    path: str | Path,
    robot: Robot,
    plan: MotionPlan,
    *,
    labels: Sequence[str | None] | None = None,
    fps: float = 15.0,
    speed: float = 1.0,
    size: Sequence[int] = (640, 400),
    view: Literal["side-top", "3d"] = "side-top",
    title: str = "",
) -> Path:
    """Write a GIF of the arm moving through a plan.

    Each frame shows the arm, the tip's whole path, the waypoints (singular ones crimson,
    detours purple), the plan's obstacles (grey), the time and the label of the last waypoint
    reached.

    Args:
        path: GIF file to write (its folder is created).
        robot: The robot the plan is for.
        plan: The plan (:class:`planner.MotionPlan`).
        labels: One label per waypoint (None: the plan's own labels; missing entries: none).
        fps: Frames per second [Hz], in (0, 60].
        speed: Plan seconds per GIF second (1: real speed; 2: twice as fast).
        size: GIF width and height [pixels].
        view: ``"side-top"`` (side and top views) or ``"3d"``.
        title: Title over the frames (default: the robot's name and the plan's duration).

    Returns:
        The GIF path.

    Raises:
        InvalidArgumentError: On a name not ending in ``.gif``, a bad fps, speed, size or view,
            more than 3000 frames, or a plan for another number of joints.
        PlannerError: If matplotlib is missing or the file cannot be written.
    """
    out = Path(path)
    traj = plan.trajectory
    duration = float(traj.duration)
    width, height = _check(fps, speed, size, view, duration, out)
    if plan.waypoints.shape[1] != robot.dof:
        raise InvalidArgumentError(f"the plan has {plan.waypoints.shape[1]} joints; {robot.name} has {robot.dof}")
    plt = pyplot()
    times = frame_times(duration, fps, speed)
    q = np.clip(traj.sample(times).q, robot.lower, robot.upper)
    chains = np.array([robot.joint_positions(row) for row in q])  # (K, dof + 2, 3)
    t_path = np.linspace(0.0, duration, max(2, int(duration * 100.0) + 1))
    tip_path = robot.position(traj.sample(t_path).q)
    tips = robot.position(plan.waypoints)
    detours = np.array([robot.position(d.q) for d in plan.detours]).reshape(-1, 3)
    names = list(plan.labels if labels is None else labels) + [None] * len(plan.waypoints)
    captions = [f"waypoint {k}" + (f": {names[k]}" if names[k] else "") for k in range(len(plan.waypoints))]
    reached = np.clip(np.searchsorted(plan.waypoint_times, times + 1e-9, side="right") - 1, 0, None)
    singular = np.isin(np.arange(len(tips)), plan.singular_waypoints)
    scene = getattr(plan, "scene", None)
    obstacles = [obstacle_points(o) for o in scene.obstacles] if scene is not None else []
    everything = np.vstack([chains.reshape(-1, 3), tip_path, *obstacles])
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    pad = 0.08 * float(np.max(hi - lo)) + 1e-3

    fig = plt.figure(figsize=(width / DPI, height / DPI), dpi=DPI)
    artists: list[tuple[Any, Any]] = []  # (line, function of a chain -> data)
    if view == "3d":
        ax = fig.add_subplot(1, 1, 1, projection="3d")
        ax.plot(*tip_path.T, color=PATH, linewidth=1.0)
        ax.scatter(*tips[~singular].T, color=WAYPOINT, s=18)
        ax.scatter(*tips[singular].T, color=SINGULAR, s=24)
        if len(detours):
            ax.scatter(*detours.T, color=DETOUR, s=18)
        for obstacle, pts in zip(scene.obstacles if scene is not None else (), obstacles):
            for edge in _outline(obstacle, pts):
                ax.plot(*edge.T, color="0.55", linewidth=1.0)
            ax.text(*pts.mean(axis=0), obstacle.name, fontsize=7, color="0.35")
        span = float(np.max(hi - lo)) / 2 + pad
        mid = (lo + hi) / 2
        ax.set(
            xlim=(mid[0] - span, mid[0] + span), ylim=(mid[1] - span, mid[1] + span), zlim=(lo[2] - pad, hi[2] + pad)
        )
        ax.set_box_aspect((1.0, 1.0, (hi[2] - lo[2] + 2 * pad) / (2 * span)))
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_zlabel("z [m]")
        (arm,) = ax.plot([], [], [], "-o", color=ARM, linewidth=4, markersize=5, markerfacecolor="#333")
        (tip,) = ax.plot([], [], [], "*", color=ARM, markersize=12)
        artists += [(arm, lambda c: c.T), (tip, lambda c: c[-1:].T)]
    else:
        side, top = fig.subplots(1, 2)
        heading = tip_path[:, :2].mean(axis=0)
        heading = heading / np.linalg.norm(heading) if np.linalg.norm(heading) > 1e-9 else np.array([1.0, 0.0])
        s_path, s_tips = _side(tip_path, heading), _side(tips, heading)
        spans = [np.column_stack([np.hypot(p[:, 0], p[:, 1]), p[:, 2]]) for p in obstacles]
        s_all = np.vstack([_side(chains.reshape(-1, 3), heading), s_path, *spans])
        side.plot(*s_path.T, color=PATH, linewidth=1.0)
        top.plot(*tip_path[:, :2].T, color=PATH, linewidth=1.0)
        for ax, pts in ((side, s_tips), (top, tips[:, :2])):
            ax.scatter(*pts[~singular].T, color=WAYPOINT, s=18, zorder=3)
            ax.scatter(*pts[singular].T, color=SINGULAR, s=24, zorder=3)
        if len(detours):
            side.scatter(*_side(detours, heading).T, color=DETOUR, s=18, zorder=3)
            top.scatter(*detours[:, :2].T, color=DETOUR, s=18, zorder=3)
        if scene is not None:
            draw_scene(side, top, scene)
        side.set(xlim=(s_all[:, 0].min() - pad, s_all[:, 0].max() + pad), ylim=(lo[2] - pad, hi[2] + pad))
        top.set(xlim=(lo[0] - pad, hi[0] + pad), ylim=(lo[1] - pad, hi[1] + pad))
        side.set_xlabel("horizontal reach [m]")
        side.set_ylabel("z [m]")
        side.set_title("side view", fontsize=9)
        top.set_xlabel("x [m]")
        top.set_ylabel("y [m]")
        top.set_title("top view", fontsize=9)
        for ax in (side, top):
            ax.set_aspect("equal", adjustable="box")
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
        for ax, project in ((side, lambda c: _side(c, heading)), (top, lambda c: c[:, :2])):
            (arm,) = ax.plot([], [], "-o", color=ARM, linewidth=3, markersize=4, markerfacecolor="#333", zorder=4)
            (tip,) = ax.plot([], [], "*", color=ARM, markersize=11, zorder=5)
            artists += [(arm, lambda c, p=project: p(c).T), (tip, lambda c, p=project: p(c)[-1:].T)]
    fig.suptitle(title or f"{plan.robot}: {duration:.2f} s plan", fontsize=10)
    caption = fig.text(0.01, 0.01, "", fontsize=9, family="monospace")
    fig.tight_layout(rect=(0, 0.05, 1, 1))

    moving = [line for line, _ in artists] + [caption]
    for artist in moving:
        artist.set_animated(True)  # left out of the background, drawn on it per frame
    canvas = fig.canvas
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)
    writer = _canvas_pillow_writer()(fps=fps)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with writer.saving(fig, str(out), DPI):
            for k in range(len(times)):
                canvas.restore_region(background)
                for line, data in artists:
                    xyz = data(chains[k])
                    if view == "3d":
                        line.set_data_3d(*xyz)
                    else:
                        line.set_data(*xyz)
                    line.axes.draw_artist(line)
                caption.set_text(f"t = {times[k]:5.2f} s   {captions[reached[k]]}")
                fig.draw_artist(caption)
                writer.grab_frame()
    except OSError as exc:
        raise InvalidArgumentError(f"cannot write {out}: {exc.strerror or exc}") from exc
    finally:
        plt.close(fig)
    return out
