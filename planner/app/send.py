"""``planner send``: plan a motion and stream it to a servo controller over a serial port (or print it)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from planner.app.motion_plan import MotionPlan, plan_motion
from planner.app.plan_file import MotionRequest, load_motion_request
from planner.exceptions import InvalidArgumentError
from planner.hardware import controller_driver
from planner.hardware.link import Clock, DryRunLink, open_serial, virtual_clock
from planner.hardware.session import SendOptions, SendResult, prepare_stream, run_stream

if TYPE_CHECKING:
    from planner.model.robot import Robot

__all__ = ["send_plan"]


def send_plan(
    robot: Robot,
    plan: MotionPlan | MotionRequest | str | Path,
    *,
    port: str | None = None,
    controller: str | None = None,
    calibration: str | Path | None = None,
    options: SendOptions | None = None,
    dry_run: TextIO | None = None,
    clock: Clock | None = None,
) -> SendResult:
    """Plan a motion (unless given planned) and stream it to a controller.

    Args:
        robot: The robot.
        plan: A plan file path, a parsed request, or a plan already made (then `controller` and
            `calibration` must be None: the plan's own are used).
        port: Serial device (``/dev/ttyUSB0``, ``COM3``); not needed for a dry run.
        controller: ``"ssc32"`` or ``"feetech"`` (default: the plan file's, else ``"ssc32"``).
        calibration: Calibration file (default: the plan file's, else the one shipped for this
            arm and controller, else the controller's defaults).
        options: Baud rate, start check and approach (see :class:`SendOptions`).
        dry_run: When given, print the byte stream with its timestamps here instead of opening
            a port (no read-back: the stream starts as if the arm were at the first waypoint).
        clock: Monotonic time and sleep for the pacing (default the real ones).

    Returns:
        What was sent and how it ended (see :class:`planner.hardware.session.SendResult`).

    Raises:
        PlannerError: On a plan or calibration problem, a baud rate too slow for the stream,
            a port that cannot be opened, a controller that does not answer, or an arm far from
            the first waypoint (nothing is sent then).
    """
    options = options or SendOptions()
    if not isinstance(plan, MotionPlan):
        request = plan if isinstance(plan, MotionRequest) else load_motion_request(plan)
        controller = controller or request.controller or "ssc32"
        plan = plan_motion(robot, request, controller=controller, calibration=calibration)
    elif controller is not None or calibration is not None:
        raise InvalidArgumentError("a MotionPlan carries its controller and calibration: give neither")
    setup = plan.setup
    name = setup.controller if setup and setup.controller else "ssc32"  # no controller named: SSC-32 pulses
    driver = controller_driver(name, plan.calibrations, setup.settings if setup else {})
    baud = options.baud or driver.default_baud
    stream = prepare_stream(driver, plan.trajectory, plan.servo_period_ms, baud)
    if dry_run is not None:
        clock = virtual_clock()
        dry_run.write(
            f"# dry run: {robot.name} on {driver.name} ({Path(setup.source).name}), {len(stream.commands)} "
            f"commands every {plan.servo_period_ms} ms for {plan.trajectory.duration:.3f} s, "
            f"{stream.bits_per_second / 1000:.1f} of {baud / 1000:g} kbit/s; position not read\n#  t [s]  bytes\n"
        )
        link = DryRunLink(dry_run, clock)
    else:
        if not port:
            raise InvalidArgumentError("give the serial port (port=..., --port DEVICE), or a dry run")
        link = open_serial(port, baud)
    try:
        return run_stream(link, driver, stream, options, limits=plan.limits, clock=clock)
    finally:
        link.close()
