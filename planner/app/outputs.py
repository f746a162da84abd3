"""The files a :class:`~planner.app.motion_plan.MotionPlan` is written to.

``trajectory.csv`` (t, then q, qd, qdd, qddd per joint, SI units), the servo files of the
plan's controller (:data:`planner.export.formats.SERVO_FORMATS`; with no controller named,
``servo_pulses.csv`` with the pulse width per servo channel [us] and ``ssc32.txt`` with
Lynxmotion SSC-32 group moves, each every servo period) and ``summary.json``
(:meth:`MotionPlan.summary`). The PNG plots are in :func:`planner.app.plots.plot_plan`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from planner.core.text import to_json
from planner.exceptions import InvalidArgumentError, ServoExportError
from planner.export.formats import SERVO_FORMATS, ServoFormat

if TYPE_CHECKING:
    from planner.export.calibration import ServoCalibration
    from planner.motion.trajectory import JointTrajectory

__all__ = ["default_formats", "write_plan_files", "write_servo_files"]


def default_formats() -> list[ServoFormat]:
    """The servo formats a plan with no controller named writes (``written_by_default``: pulses, ssc32)."""
    return [f for f in SERVO_FORMATS.values() if f.written_by_default]


def write_servo_files(
    folder: Path,
    trajectory: JointTrajectory,
    calibrations: Sequence[ServoCalibration],
    period_ms: int,
    formats: Sequence[ServoFormat] | None = None,
) -> list[Path]:
    """One file per registered servo format, named by the format, into an existing directory.

    Args:
        folder: Output directory.
        trajectory: The joint trajectory.
        calibrations: One per joint, in joint order.
        period_ms: Time between two servo updates [ms].
        formats: The formats to write; None writes every format that is ``written_by_default``.

    Returns:
        The paths written, in the order of `formats`.

    Raises:
        InvalidArgumentError: If a calibration does not fit a format or a pulse is out of range.
    """
    paths = []
    for fmt in default_formats() if formats is None else formats:
        path = folder / fmt.file_name
        path.write_bytes(fmt.render(trajectory, calibrations, period_ms).encode(fmt.encoding))
        paths.append(path)
    return paths


def write_plan_files(
    out: str | Path,
    trajectory: JointTrajectory,
    calibrations: Sequence[ServoCalibration],
    servo_period_ms: int,
    summary: dict,
    rate: float = 1000.0,
    extra_files: Sequence[Path] = (),
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
        extra_files: Files already written for the plan (e.g. its plots), listed in the summary.
        formats: The servo formats to write; None writes the default ones (see :func:`default_formats`).

    Returns:
        The paths written: the trajectory CSV, the servo files, the summary.

    Raises:
        InvalidArgumentError: If the directory cannot be created.
        ServoExportError: If a servo file cannot be made (a pulse out of its calibration's
            range); the other files are written first and listed in the error.
    """
    folder = Path(out)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InvalidArgumentError(f"cannot create output directory {str(folder)!r}: {exc.strerror}") from exc
    paths = [trajectory.to_csv(folder / "trajectory.csv", rate=rate)]
    # A servo file that cannot be made must not cost the user the trajectory and summary.
    failures: dict[str, str] = {}
    for fmt in default_formats() if formats is None else formats:
        try:
            paths.append(write_servo_files(folder, trajectory, calibrations, servo_period_ms, formats=[fmt])[0])
        except InvalidArgumentError as exc:
            failures[fmt.file_name] = str(exc)
    summary_path = folder / "summary.json"
    summary = {**summary}
    summary["files"] = sorted(str(p) for p in [*paths, *extra_files, summary_path])
    if failures:
        summary["servo_file_errors"] = failures
    summary_path.write_text(to_json(summary) + "\n")
    paths.append(summary_path)
    if failures:
        raise ServoExportError(failures, tuple(paths))
    return tuple(paths)
