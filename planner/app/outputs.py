"""The files a :class:`~planner.app.motion_plan.MotionPlan` is written to.

``trajectory.csv`` (t, then q, qd, qdd, qddd per joint, SI units), the servo files of the
plan's controller (:data:`planner.export.formats.SERVO_FORMATS`; with no controller named,
``servo_pulses.csv`` with the pulse width per servo channel [us] and ``ssc32.txt`` with
Lynxmotion SSC-32 group moves, each every servo period) and ``summary.json``
(:meth:`MotionPlan.summary`). A servo file that cannot be made (a pulse out of range) does not
stop the others, the CSV or the summary: they are written, then the error is raised. The PNG
plots are in :func:`planner.app.plots.plot_plan`.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from planner.exceptions import InvalidArgumentError, PlannerError
from planner.export.formats import SERVO_FORMATS, ServoFormat

if TYPE_CHECKING:
    from planner.export.calibration import ServoCalibration
    from planner.motion.trajectory import JointTrajectory

__all__ = ["write_plan_files", "write_servo_files"]


def write_servo_files(
    folder: Path,
    trajectory: JointTrajectory,
    calibrations: Sequence[ServoCalibration],
    period_ms: int,
    formats: Sequence[ServoFormat] | None = None,
) -> tuple[list[Path], list[str]]:
    """One file per servo format, named by the format, into an existing directory.

    Args:
        folder: Output directory.
        trajectory: The joint trajectory.
        calibrations: One per joint, in joint order.
        period_ms: Time between two servo updates [ms].
        formats: The formats to write; None writes every format that is ``written_by_default``.

    Returns:
        ``(paths, errors)``: the paths written, in order, and one message per format that
        could not be made (a calibration that does not fit it, a value out of range).
    """
    if formats is None:
        formats = [f for f in SERVO_FORMATS.values() if f.written_by_default]
    paths, errors = [], []
    for fmt in formats:
        try:
            data = fmt.render(trajectory, calibrations, period_ms).encode(fmt.encoding)
        except PlannerError as exc:
            errors.append(f"{fmt.file_name} ({fmt.name}): {exc}")
            continue
        path = folder / fmt.file_name
        path.write_bytes(data)
        paths.append(path)
    return paths, errors


def write_plan_files(
    out: str | Path,
    trajectory: JointTrajectory,
    calibrations: Sequence[ServoCalibration],
    servo_period_ms: int,
    summary: dict,
    rate: float = 1000.0,
    formats: Sequence[ServoFormat] | None = None,
) -> tuple[Path, ...]:
    """Write a plan's files into a directory (created if missing); see the module docstring.

    Args:
        out: Output directory.
        trajectory: The plan's trajectory.
        calibrations: One servo calibration per joint.
        servo_period_ms: Time between two servo updates [ms].
        summary: The plan's summary (:meth:`MotionPlan.summary`); the file list is added to it.
        rate: Sample rate of the CSV [Hz].
        formats: Servo formats to write (None: the default ones, see :func:`write_servo_files`).

    Returns:
        The paths written: the trajectory CSV, the servo files, the summary.

    Raises:
        InvalidArgumentError: If the directory cannot be created, or a servo file cannot be made
            (raised after everything else is written; the summary lists it under ``servo_errors``).
    """
    folder = Path(out)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InvalidArgumentError(f"cannot create output directory {str(folder)!r}: {exc.strerror}") from exc
    paths = [trajectory.to_csv(folder / "trajectory.csv", rate=rate)]
    servo_paths, errors = write_servo_files(folder, trajectory, calibrations, servo_period_ms, formats)
    paths += servo_paths
    summary_path = folder / "summary.json"
    summary = {**summary}
    summary["files"] = sorted(str(p) for p in [*paths, summary_path])
    if errors:
        summary["servo_errors"] = errors
    summary_path.write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n")
    paths.append(summary_path)
    if errors:
        written = ", ".join(p.name for p in paths)
        raise InvalidArgumentError(f"wrote {written} in {folder}, but not {'; '.join(errors)}")
    return tuple(paths)
