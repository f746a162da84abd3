"""An interactive 3-D view of an arm (and optionally a plan) in the browser, served by viser.

:class:`Scene` starts a viser server on localhost and shows:

- the arm (:class:`~planner.view.arm.ArmDrawing`), with a slider per joint (the joint limits
  are the slider ranges) and live forward kinematics; the manipulability and the inverse
  condition number of the current configuration, in red below the singularity threshold;
- a draggable target: the closed form's branches (selectable) or the NLP's answer follow it,
  with the status and the reason when it is unreachable;
- with a plan: play, pause and scrub it in real time; the waypoints with their labels, the
  tip's path, singular waypoints (crimson), detours (purple) and the plan's obstacles (grey).
"""

from __future__ import annotations

import html
import threading
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from planner.core.version import install_hint
from planner.exceptions import InvalidArgumentError, PlannerError
from planner.geometry.target import Target
from planner.ik.result import IKResult
from planner.ik.solve import IK_METHODS, solve_ik
from planner.model.robot import Robot
from planner.motion.singularity import inverse_condition_threshold
from planner.view.arm import ArmDrawing, quaternion_wxyz

if TYPE_CHECKING:
    from planner.motion.detours import Detour
    from planner.motion.singularity import SingularityReport
    from planner.motion.trajectory import JointTrajectory


class PlanLike(Protocol):
    """What the scene reads from a plan; a :class:`planner.MotionPlan` has it all.

    A plan's ``scene`` of obstacles, when it has one, is drawn too.
    """

    trajectory: JointTrajectory
    waypoints: np.ndarray
    waypoint_times: np.ndarray
    singular_waypoints: tuple[int, ...]
    detours: tuple[Detour, ...]
    singularity: SingularityReport
    labels: tuple[str | None, ...]


__all__ = ["PlanLike", "Scene", "require_viser"]

WAYPOINT_COLOR = (20, 150, 60)
SINGULAR_COLOR = (210, 20, 90)
DETOUR_COLOR = (150, 60, 200)
PATH_COLOR = (40, 110, 220)
GHOST_COLOR = (150, 150, 150)
OBSTACLE_COLOR = (140, 145, 155)
FRAME_RATE = 30.0  # playback updates per second [Hz]
#: What the scene reads from a plan (a planner.MotionPlan has them all).
_PLAN_ATTRIBUTES = (
    "trajectory",
    "waypoints",
    "waypoint_times",
    "singular_waypoints",
    "detours",
    "singularity",
    "labels",
)


def require_viser() -> Any:
    """Import viser, or raise a PlannerError naming the extra to install."""
    try:
        import viser
    except ImportError as exc:
        raise PlannerError(f"the 3-D view needs viser: {install_hint('view')}") from exc
    return viser


class Scene:
    """A viser scene of a robot, with joint sliders, a draggable IK target and plan playback.

    The server runs in background threads from construction until :meth:`close`; open
    :attr:`url` in a browser. Every method may be called from the user's own thread.

    Args:
        robot: The robot to show.
        plan: A :class:`planner.MotionPlan` to play (None: no plan).
        labels: One label per plan waypoint (None: the plan's own labels; missing entries:
            "waypoint k" alone).
        host: Interface to serve on (default: localhost only).
        port: TCP port; 0 picks a free one. A port in use is skipped for the next free one.
        meshes: Draw the URDF's visual meshes where they resolve (else link geometry).
        threshold: Inverse-condition-number threshold below which a configuration counts as
            singular (None: the plan's, else 1/30).
        ik_method: The target's IK method at start: ``"auto"``, ``"analytic"`` or ``"nlp"``.

    Attributes:
        robot: The robot.
        plan: The plan, or None.
        server: The ``viser.ViserServer``.
        threshold: The singularity threshold in use.

    Raises:
        PlannerError: If viser is not installed (the message names the extra).
        InvalidArgumentError: If the plan is for another number of joints, or on a bad
            `labels`, `port` or `ik_method`.
    """

    def __init__(
        self,
        robot: Robot,
        plan: PlanLike | None = None,
        *,
        labels: Sequence[str | None] | None = None,
        host: str = "127.0.0.1",
        port: int = 8080,
        meshes: bool = True,
        threshold: float | None = None,
        ik_method: str = "auto",
    ) -> None:
        viser = require_viser()
        if not isinstance(robot, Robot):
            raise InvalidArgumentError(f"Scene needs a planner.Robot, got {type(robot).__name__}")
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise InvalidArgumentError(f"port must be an integer in 0..65535, got {port!r}")
        if ik_method not in IK_METHODS:
            raise InvalidArgumentError(f"unknown IK method {ik_method!r}; valid: {', '.join(IK_METHODS)}")
        if plan is not None:
            missing = [a for a in _PLAN_ATTRIBUTES if not hasattr(plan, a)]
            if missing:
                raise InvalidArgumentError(
                    f"plan must be a planner.MotionPlan, got {type(plan).__name__} (no {', '.join(missing)})"
                )
            if plan.waypoints.shape[1] != robot.dof:
                raise InvalidArgumentError(
                    f"the plan has {plan.waypoints.shape[1]} joints; {robot.name} has {robot.dof}"
                )
        self.robot = robot
        self.plan = plan
        if threshold is None and plan is not None:
            threshold = plan.singularity.threshold
        task = robot.resolve_task(None if plan is None else plan.singularity.task)
        self.threshold = inverse_condition_threshold(threshold, task)
        n_way = 0 if plan is None else len(plan.waypoints)
        given = list((plan.labels if plan is not None else ()) if labels is None else labels)
        if len(given) > n_way:
            raise InvalidArgumentError(f"{len(given)} labels for {n_way} plan waypoints")
        given += [None] * (n_way - len(given))
        self._given = given
        self._labels = [f"waypoint {k}" + (f": {lb}" if lb else "") for k, lb in enumerate(given)]
        self._lock = threading.RLock()
        self._syncing = False
        self._q = np.clip(np.zeros(robot.dof), robot.lower, robot.upper)
        if plan is not None:
            self._q = np.array(plan.waypoints[0], dtype=float)
        self._time = 0.0
        self._playing = False
        self._speed = 1.0
        self._ik: IKResult | None = None
        self._ik_busy = threading.Lock()
        self._ik_pending: np.ndarray | None = None

        self.server = viser.ViserServer(host=host, port=port, verbose=False)
        try:
            self.server.scene.set_up_direction("+z")
            self.arm = ArmDrawing(self.server, robot, meshes=meshes)
            self._ghosts: Any = None
            self._add_floor_and_camera()
            self._add_joint_panel()
            self._add_target_panel()
            if plan is not None:
                self._add_plan_markers()
                self._add_plan_panel()
            self._show(self._q)
        except BaseException:
            self.server.stop()  # a scene that failed to build leaves no server behind
            raise
        self._stop = threading.Event()
        self._player = threading.Thread(target=self._play_loop, name="planner-view-player", daemon=True)
        self._player.start()

    # ------------------------------------------------------------------ properties
    @property
    def port(self) -> int:
        """The TCP port the server listens on."""
        return int(self.server.get_port())

    @property
    def url(self) -> str:
        """Where to open the scene in a browser."""
        host = self.server.get_host()
        return f"http://{'127.0.0.1' if host in ('0.0.0.0', '') else host}:{self.port}"

    @property
    def q(self) -> np.ndarray:
        """The configuration shown, shape (dof,) [rad or m] (a copy)."""
        with self._lock:
            return self._q.copy()

    @property
    def time(self) -> float:
        """The plan time shown [s] (0 without a plan)."""
        return self._time

    @property
    def playing(self) -> bool:
        """Whether the plan is playing."""
        return self._playing

    @property
    def ik_result(self) -> IKResult | None:
        """The last answer for the draggable target, or None before the first."""
        return self._ik

    # ------------------------------------------------------------------ arm and sliders
    def set_q(self, q: Sequence[float] | np.ndarray) -> None:
        """Show the arm at configuration `q`, shape (dof,) [rad or m]; the sliders follow, a playing plan pauses.

        Raises:
            InvalidConfigurationError: On the wrong length or non-finite values.
            JointLimitError: If a joint is outside its limits.
        """
        arr = self.robot.check_configuration(q, batch=False)
        self.robot.check_limits(arr, context="Scene.set_q")
        self.pause()
        self._show(arr)

    def measures(self, q: Sequence[float] | np.ndarray | None = None) -> tuple[float, float]:
        """Inverse condition number and manipulability at `q` (default: the shown configuration)."""
        task = None if self.plan is None else self.plan.singularity.task
        inverse, manipulability = self.robot.conditioning(self.q if q is None else q, task)
        return float(inverse), float(manipulability)

    def _show(self, q: np.ndarray) -> None:
        with self._lock:
            self._q = np.array(q, dtype=float)
            self._syncing = True
            try:
                for slider, value in zip(self._sliders, self._q):
                    slider.value = float(np.clip(value, slider.min, slider.max))
            finally:
                self._syncing = False
            self.arm.update(self._q)
            inverse, manipulability = self.measures(self._q)
            singular = inverse < self.threshold
            color = "#d01010" if singular else "#206020"
            tip = self.robot.position(self._q)
            self._measure_html.content = (
                f'<div style="font-size:0.85em;padding:0 0.5em;color:{color}">'
                f"manipulability {manipulability:.3g}<br>"
                f"inverse condition number {inverse:.3g} (singular below {self.threshold:.3g})"
                f"{'<br><b>near a singularity</b>' if singular else ''}<br>"
                f'<span style="color:#333">tip ({tip[0]:.3f}, {tip[1]:.3f}, {tip[2]:.3f}) m</span></div>'
            )

    def _slider_moved(self, _: Any) -> None:
        if self._syncing:
            return
        self.pause()
        self._show(np.array([s.value for s in self._sliders], dtype=float))

    def _add_joint_panel(self) -> None:
        gui = self.server.gui
        robot = self.robot
        self._sliders = []
        with gui.add_folder("Joints"):
            for name, kind, lo, hi in zip(robot.joint_names, robot.joint_kinds, robot.lower, robot.upper):
                lo, hi = (-np.pi, np.pi) if not np.isfinite(lo) or not np.isfinite(hi) else (float(lo), float(hi))
                unit = "m" if kind == "prismatic" else "rad"
                slider = gui.add_slider(
                    f"{name} [{unit}]", min=lo, max=hi, step=(hi - lo) / 1000.0 or 1e-3, initial_value=0.5 * (lo + hi)
                )
                slider.on_update(self._slider_moved)
                self._sliders.append(slider)
            self._measure_html = gui.add_html("")
            frames = gui.add_checkbox("joint frames", initial_value=False)

            @frames.on_update
            def _(_: Any) -> None:
                self.arm.show_frames(frames.value, self.q)

    # ------------------------------------------------------------------ floor and camera
    def _add_floor_and_camera(self) -> None:
        reach = self.arm.reach
        cell = float(10.0 ** np.floor(np.log10(reach / 2.0)))
        obstacles = getattr(self.plan, "scene", None)
        floor = obstacles.floor if obstacles is not None and obstacles.floor is not None else 0.0
        self.server.scene.add_grid(
            "/floor",
            width=3 * reach,
            height=3 * reach,
            cell_size=cell,
            section_size=5 * cell,
            shadow_opacity=0.0,
            position=(0.0, 0.0, floor),
        )
        points = self.robot.joint_positions(self._q)
        if self.plan is not None:
            points = np.vstack([points, self.robot.position(self.plan.waypoints)])
        centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
        distance = max(reach, 1.3 * float(np.max(np.ptp(points, axis=0))))
        self.server.initial_camera.look_at = tuple(centre)
        self.server.initial_camera.position = tuple(centre + distance * np.array([0.9, -1.25, 0.75]))
        self.server.initial_camera.up = (0.0, 0.0, 1.0)

    # ------------------------------------------------------------------ draggable target
    def _add_target_panel(self) -> None:
        gui = self.server.gui
        tip = self.robot.position(self._q)
        self._gizmo = self.server.scene.add_transform_controls(
            "/target", scale=0.35 * self.arm.reach, disable_rotations=True, position=tuple(tip), visible=False
        )
        self._target_ball = self.server.scene.add_icosphere(
            "/target/ball", radius=0.04 * self.arm.reach, color=(230, 180, 0), visible=False
        )
        with gui.add_folder("Target (drag it)"):
            self._show_target = gui.add_checkbox("show target", initial_value=False)
            self._method = gui.add_dropdown("IK method", IK_METHODS, initial_value="auto")
            self._branch = gui.add_dropdown("solution", ("-",), initial_value="-")
            self._ik_html = gui.add_html("")
            to_tip = gui.add_button("target to the tip")

        @self._show_target.on_update
        def _(_: Any) -> None:
            self._gizmo.visible = self._show_target.value
            self._target_ball.visible = self._show_target.value
            if self._show_target.value:
                self._solve_from_gui(self._gizmo.position)

        @self._gizmo.on_update
        def _(_: Any) -> None:
            self._request_ik(np.array(self._gizmo.position, dtype=float))

        @self._method.on_update
        def _(_: Any) -> None:
            self._solve_from_gui(self._gizmo.position)

        @self._branch.on_update
        def _(_: Any) -> None:
            if self._syncing or self._ik is None:
                return
            options = list(self._branch.options)
            if self._branch.value in options and self._ik.solutions:
                k = options.index(self._branch.value)
                if k < len(self._ik.solutions):
                    self.pause()
                    self._show(np.clip(self._ik.solutions[k].q, self.robot.lower, self.robot.upper))

        @to_tip.on_click
        def _(_: Any) -> None:
            self._gizmo.position = tuple(self.robot.position(self.q))

    def _request_ik(self, position: np.ndarray) -> None:
        """Solve for the newest dragged position, skipping positions passed while a solve runs."""
        self._ik_pending = position
        if not self._ik_busy.acquire(blocking=False):
            return
        try:
            while self._ik_pending is not None:
                pending, self._ik_pending = self._ik_pending, None
                self._solve_from_gui(pending)
        finally:
            self._ik_busy.release()

    def solve_target(self, position: Sequence[float] | np.ndarray, method: str | None = None) -> IKResult:
        """Solve IK for a tip position, show the answer and list every solution.

        Args:
            position: Target tip position, shape (3,) [m] in the base frame.
            method: ``"auto"``, ``"analytic"`` or ``"nlp"``; None uses the panel's choice.

        Returns:
            The IK result (an unreachable target is a result whose status says why).

        Raises:
            InvalidArgumentError: On a bad position or method.
            UnsupportedChainError: For ``"analytic"`` on an arm without a closed form.
        """
        if method is not None and method not in IK_METHODS:
            raise InvalidArgumentError(f"unknown IK method {method!r}; valid: {', '.join(IK_METHODS)}")
        result = solve_ik(self.robot, Target(position), self.q, method=method or self._method.value)
        self._ik = result
        names = [
            f"{k + 1}: {s.label}" + ("" if s.within_limits else " (outside limits)")
            for k, s in enumerate(result.solutions)
        ]
        chosen = next((k for k, s in enumerate(result.solutions) if np.array_equal(s.q, result.q)), None)
        with self._lock:
            self._syncing = True
            try:
                self._branch.options = names or ["-"]
                self._branch.value = names[chosen] if chosen is not None and names else (names or ["-"])[0]
            finally:
                self._syncing = False
        color = "#206020" if result.success else "#d01010"
        reason = "" if result.success else f"<br>{html.escape(result.reason)}"
        self._ik_html.content = (
            f'<div style="font-size:0.85em;padding:0 0.5em;color:{color}">{result.method}: '
            f"<b>{html.escape(str(result.status))}</b>, {len(result.solutions)} solution(s), "
            f"tip error {result.position_error:.2g} m{reason}</div>"
        )
        self._draw_ghosts(result)
        if result.success:
            self.pause()
            self._show(np.array(result.q, dtype=float))
        return result

    def _solve_from_gui(self, position: Sequence[float] | np.ndarray) -> None:
        """:meth:`solve_target` for the panel: an error (no closed form for the arm) is shown, not raised."""
        try:
            self.solve_target(position)
        except PlannerError as exc:
            self._ik_html.content = f'<div style="color:#d01010;padding:0 0.5em">{html.escape(str(exc))}</div>'

    def _draw_ghosts(self, result: IKResult) -> None:
        """The other solutions within limits as grey stick figures."""
        segments = []
        for s in result.solutions:
            if s.within_limits and not np.array_equal(s.q, result.q):
                pts = self.robot.joint_positions(s.q)
                segments += [(pts[k], pts[k + 1]) for k in range(len(pts) - 1)]
        if self._ghosts is not None:
            self._ghosts.remove()
            self._ghosts = None
        if segments:
            self._ghosts = self.server.scene.add_line_segments(
                "/ik_ghosts", np.array(segments), GHOST_COLOR, thickness=0.006 * self.arm.reach
            )

    # ------------------------------------------------------------------ plan playback
    def _add_obstacles(self) -> None:
        """The plan's obstacles, grey and half transparent, each with its name."""
        from planner.collision.scene import Box, Cylinder

        obstacles = getattr(self.plan, "scene", None)
        for k, obstacle in enumerate(obstacles.obstacles if obstacles is not None else ()):
            name, shape = f"/obstacles/{k}", obstacle.shape
            pose = {"position": tuple(obstacle.position), "wxyz": quaternion_wxyz(obstacle.rotation)}
            if isinstance(shape, Box):
                self.server.scene.add_box(name, color=OBSTACLE_COLOR, dimensions=shape.size, opacity=0.6, **pose)
                top = shape.size[2] / 2
            elif isinstance(shape, Cylinder):
                self.server.scene.add_cylinder(
                    name, radius=shape.radius, height=shape.length, color=OBSTACLE_COLOR, opacity=0.6, **pose
                )
                top = shape.length / 2
            else:
                self.server.scene.add_icosphere(name, radius=shape.radius, color=OBSTACLE_COLOR, opacity=0.6, **pose)
                top = shape.radius
            self.server.scene.add_label(f"{name}/label", obstacle.name, position=(0.0, 0.0, top), font_screen_scale=0.6)

    def _add_plan_markers(self) -> None:
        self._add_obstacles()
        plan, robot, scene = self.plan, self.robot, self.server.scene
        r = 0.03 * self.arm.reach
        traj = plan.trajectory
        t = np.linspace(0.0, traj.duration, max(2, int(traj.duration * 100.0) + 1))
        path = robot.position(traj.sample(t).q)
        scene.add_line_segments("/plan/path", np.stack([path[:-1], path[1:]], axis=1), PATH_COLOR, thickness=0.15 * r)
        tips = robot.position(plan.waypoints)
        # Waypoints at one place (a dwell, a return to the start) share one marker and one label.
        groups: dict[int, list[int]] = {}
        for k, tip in enumerate(tips):
            first = next((g for g in groups if np.linalg.norm(tips[g] - tip) < 1e-6), k)
            groups.setdefault(first, []).append(k)
        for first, members in groups.items():
            singular = any(k in plan.singular_waypoints for k in members)
            names = " / ".join(dict.fromkeys(self._given[k] for k in members if self._given[k]))
            text = ", ".join(str(k) for k in members) + (f": {names}" if names else "")
            scene.add_icosphere(
                f"/plan/waypoint{first}",
                radius=r,
                color=SINGULAR_COLOR if singular else WAYPOINT_COLOR,
                position=tips[first],
            )
            scene.add_label(
                f"/plan/waypoint{first}/label",
                text + (" (singular)" if singular else ""),
                position=(0.0, 0.0, 1.5 * r),
                font_screen_scale=0.6,
            )
        for k, detour in enumerate(plan.detours):
            where = robot.position(detour.q)
            scene.add_icosphere(f"/plan/detour{k}", radius=0.8 * r, color=DETOUR_COLOR, position=where)
            scene.add_label(
                f"/plan/detour{k}/label",
                f"detour (segment {detour.segment})",
                position=(0.0, 0.0, 1.5 * r),
                font_screen_scale=0.6,
            )

    def _add_plan_panel(self) -> None:
        gui = self.server.gui
        duration = float(self.plan.trajectory.duration)
        with gui.add_folder("Plan"):
            play = gui.add_button("play / pause", icon=None)
            self._time_slider = gui.add_slider(
                "time [s]", min=0.0, max=duration, step=max(duration / 1000.0, 1e-3), initial_value=0.0
            )
            speed = gui.add_slider("speed", min=0.1, max=3.0, step=0.1, initial_value=1.0)
            self._plan_html = gui.add_html("")

        @play.on_click
        def _(_: Any) -> None:
            if self._playing:
                self.pause()
            else:
                self.play()

        @self._time_slider.on_update
        def _(_: Any) -> None:
            if not self._syncing:
                self.pause()
                self.set_time(self._time_slider.value)

        @speed.on_update
        def _(_: Any) -> None:
            self._speed = float(speed.value)

        self.set_time(0.0)

    def current_waypoint(self, t: float | None = None) -> int:
        """Index of the last plan waypoint reached by time `t` [s] (default: the time shown)."""
        if self.plan is None:
            raise InvalidArgumentError("the scene has no plan")
        when = self._time if t is None else t
        return max(int(np.searchsorted(self.plan.waypoint_times, when + 1e-9, side="right")) - 1, 0)

    def set_time(self, t: float) -> None:
        """Show the plan at time `t` [s], clipped into [0, duration].

        Raises:
            InvalidArgumentError: Without a plan, or on a non-finite time.
        """
        if self.plan is None:
            raise InvalidArgumentError("the scene has no plan to show a time of")
        if isinstance(t, bool) or not isinstance(t, (int, float, np.number)) or not np.isfinite(t):
            raise InvalidArgumentError(f"time must be a finite number [s], got {t!r}")
        traj = self.plan.trajectory
        t = float(np.clip(t, 0.0, traj.duration))
        with self._lock:
            self._time = t
            self._syncing = True
            try:
                self._time_slider.value = t
            finally:
                self._syncing = False
            q = np.asarray(traj.sample(np.array([t])).q[0], dtype=float)
            self._show(np.clip(q, self.robot.lower, self.robot.upper))
            k = self.current_waypoint(t)
            state = "playing" if self._playing else "paused"
            self._plan_html.content = (
                f'<div style="font-size:0.85em;padding:0 0.5em">t = {t:.2f} s of {traj.duration:.2f} s '
                f"({state})<br>{html.escape(self._labels[k])}</div>"
            )

    def play(self) -> None:
        """Play the plan in real time (times the speed slider), from the time shown; loops at the end."""
        if self.plan is None:
            raise InvalidArgumentError("the scene has no plan to play")
        self._playing = True

    def pause(self) -> None:
        """Stop the playback where it is."""
        self._playing = False

    def _play_loop(self) -> None:
        last = time.perf_counter()
        while not self._stop.wait(1.0 / FRAME_RATE):
            now = time.perf_counter()
            step, last = now - last, now
            if not self._playing or self.plan is None:
                continue
            t = self._time + step * self._speed
            self.set_time(0.0 if t > self.plan.trajectory.duration + 0.5 else t)

    # ------------------------------------------------------------------ life cycle
    def close(self) -> None:
        """Stop the playback and the server."""
        self._stop.set()
        self._player.join(timeout=2.0)
        self.server.stop()

    def serve_forever(self) -> None:
        """Block until Ctrl-C, then close the scene."""
        try:
            while True:
                time.sleep(0.5)
        except KeyboardInterrupt:
            pass
        finally:
            self.close()

    def __enter__(self) -> Scene:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
