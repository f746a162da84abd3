"""``planner view`` and ``planner plan --view``: a robot and optionally a plan file in the browser.

The scene itself is :class:`planner.view.Scene` (needs the ``view`` extra, viser); this module
meets it with the command line: a robot name or URDF, a plan file planned first, a port.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from planner.app.motion_plan import MotionPlan, plan_motion
from planner.app.plan_file import load_motion_request
from planner.model.catalog import load_robot
from planner.model.robot import Robot

if TYPE_CHECKING:
    from planner.view.scene import Scene

__all__ = ["open_scene", "run_view", "serve_scene"]


def open_scene(
    robot: str | Path | Robot,
    plan_file: str | Path | None = None,
    *,
    port: int = 8080,
    host: str = "127.0.0.1",
    plan: MotionPlan | None = None,
    labels: Sequence[str | None] | None = None,
) -> Scene:
    """Start a scene of a robot and, from a plan file or a plan, its plan.

    Args:
        robot: A robot name (``planner robots``), a URDF path or a :class:`planner.Robot`.
        plan_file: A plan file (YAML or JSON) to plan and play; None for the arm alone.
        port: TCP port (0: a free one).
        host: Interface to serve on.
        plan: An already made plan to play instead of a plan file.
        labels: The plan's waypoint labels (None: the plan's own).

    Returns:
        The running scene (close it with :meth:`~planner.view.Scene.close`).

    Raises:
        PlannerError: If viser is missing (the message names the extra), on an unknown robot or
            a bad plan file.
    """
    from planner.view import require_viser

    require_viser()  # before any planning: say which extra is missing first
    from planner.view.scene import Scene

    arm = robot if isinstance(robot, Robot) else load_robot(robot)
    if plan_file is not None:
        request = load_motion_request(plan_file)
        plan = plan_motion(arm, request)
    return Scene(arm, plan, labels=labels, host=host, port=port)


def _say(line: str) -> None:
    print(line, flush=True)  # at once, also when stdout is a pipe


def serve_scene(scene: Scene, log: Callable[[str], None] = _say) -> None:
    """Say where the scene is and serve it until Ctrl-C."""
    log(f"planner view: {scene.robot.name} at {scene.url} (Ctrl-C stops)")
    scene.serve_forever()


def run_view(
    robot: str | Path | Robot,
    plan_file: str | Path | None = None,
    *,
    plan: MotionPlan | None = None,
    port: int = 8080,
    log: Callable[[str], None] = _say,
) -> int:
    """:func:`open_scene` then :func:`serve_scene`, until Ctrl-C; the exit code of ``planner view``.

    Ctrl-C while the scene is still being built stops it as quietly as Ctrl-C later.

    Returns:
        0 when stopped after serving, 130 (interrupted) when stopped while starting.
    """
    try:
        scene = open_scene(robot, plan_file, plan=plan, port=port)
    except KeyboardInterrupt:
        return 130
    serve_scene(scene, log)
    return 0
