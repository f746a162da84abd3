"""CSV files of IK targets (``planner ik ROBOT --batch FILE.csv``) and the CSV of their answers.

The input has a header line naming its columns, then one target per line (blank lines and
lines starting with ``#`` are skipped)::

    x,y,z,roll,pitch,yaw
    0.4,0.1,0.3,0,90,0

Columns: ``x``, ``y``, ``z`` (the tip position [m], required), and at most one orientation:
``roll``, ``pitch``, ``yaw`` (URDF roll-pitch-yaw), ``qx``, ``qy``, ``qz``, ``qw`` (a
quaternion, normalised here), or ``approach_pitch`` (the approach pitch of
:class:`~planner.geometry.target.Target`). Angles are radians, degrees with ``--deg``, as
everywhere on the command line. Without an orientation the targets are positions.

The output has one line per target, in the input's order: ``row`` (1-based target number),
``status``, one column per joint (``<joint> [rad]``, ``[deg]`` with ``--deg``, ``[m]`` for
prismatic joints; empty where the target was not solved), ``position_error [m]`` and
``orientation_error [rad]`` (by Pinocchio FK; of the best attempt where not solved).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

import numpy as np

from planner.core.rotations import unit_quaternions
from planner.exceptions import TargetFileError
from planner.geometry.target_batch import BatchTargets
from planner.ik.numeric.batch_result import BatchIKResult
from planner.model.robot import Robot

__all__ = ["ORIENTATION_COLUMNS", "POSITION_COLUMNS", "read_targets", "write_answers"]

POSITION_COLUMNS = ("x", "y", "z")
#: The orientation column groups a file may have (at most one).
ORIENTATION_COLUMNS = {
    "rpy": ("roll", "pitch", "yaw"),
    "quaternion": ("qx", "qy", "qz", "qw"),
    "approach_pitch": ("approach_pitch",),
}
_VALID = ", ".join(POSITION_COLUMNS + tuple(c for group in ORIENTATION_COLUMNS.values() for c in group))


def _rpy_matrices(rpy: np.ndarray) -> np.ndarray:
    """Rotation matrices ``Rz(yaw) Ry(pitch) Rx(roll)`` of rows (N, 3) [rad], shape (N, 3, 3)."""
    cr, sr = np.cos(rpy[:, 0]), np.sin(rpy[:, 0])
    cp, sp = np.cos(rpy[:, 1]), np.sin(rpy[:, 1])
    cy, sy = np.cos(rpy[:, 2]), np.sin(rpy[:, 2])
    return np.stack(
        [
            np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], axis=-1),
            np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], axis=-1),
            np.stack([-sp, cp * sr, cp * cr], axis=-1),
        ],
        axis=1,
    )


def _quaternion_matrices(xyzw: np.ndarray) -> np.ndarray:
    """Rotation matrices of unit quaternions (N, 4) ``(x, y, z, w)``, shape (N, 3, 3)."""
    x, y, z, w = xyzw.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=1,
    )


def read_targets(source: str | Path | TextIO, *, deg: bool = False) -> BatchTargets:
    """The targets of a CSV file (see the module docstring).

    Args:
        source: A path, or an open text stream (``-`` is not special here).
        deg: Angles in the file are degrees.

    Returns:
        The targets, in the file's order.

    Raises:
        TargetFileError: Naming the file, line and column: a missing or unknown column, a
            partial or second orientation group, a cell that is empty, not a number, NaN or
            infinite, a zero quaternion, or no targets at all.
    """
    name = None
    if isinstance(source, (str, Path)):
        name = str(source)
        try:
            text = Path(source).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise TargetFileError(f"cannot read the target file: {exc}", path=name) from exc
        stream: TextIO = io.StringIO(text)
    else:
        stream = source
    lines = [
        (number, row)
        for number, row in enumerate(csv.reader(stream), start=1)
        if row and any(cell.strip() for cell in row) and not row[0].lstrip().startswith("#")
    ]
    if not lines:
        raise TargetFileError(f"no header line; the first line names the columns ({_VALID})", path=name)
    header_line, header = lines[0]
    # A byte-order mark (spreadsheets' "CSV UTF-8") is no part of the first column's name.
    columns = [cell.strip().lower() for cell in [header[0].lstrip("\ufeff"), *header[1:]]]
    for column in columns:
        if column not in _VALID.split(", "):
            raise TargetFileError(f"unknown column; valid: {_VALID}", path=name, line=header_line, column=column)
    for column in set(columns):
        if columns.count(column) > 1:
            raise TargetFileError("the column appears twice", path=name, line=header_line, column=column)
    for column in POSITION_COLUMNS:
        if column not in columns:
            raise TargetFileError(
                "missing column (x, y and z are required)", path=name, line=header_line, column=column
            )
    groups = [g for g, cols in ORIENTATION_COLUMNS.items() if any(c in columns for c in cols)]
    if len(groups) > 1:
        raise TargetFileError(
            f"give at most one orientation, got {' and '.join(groups)} columns", path=name, line=header_line
        )
    group = groups[0] if groups else None
    if group is not None:
        for column in ORIENTATION_COLUMNS[group]:
            if column not in columns:
                raise TargetFileError(
                    f"missing column of the {group} orientation ({', '.join(ORIENTATION_COLUMNS[group])})",
                    path=name,
                    line=header_line,
                    column=column,
                )
    wanted = POSITION_COLUMNS + (ORIENTATION_COLUMNS[group] if group else ())
    where = [columns.index(c) for c in wanted]
    rows = lines[1:]
    if not rows:
        raise TargetFileError("no targets after the header line", path=name)
    values = np.empty((len(rows), len(wanted)))
    for k, (number, row) in enumerate(rows):
        if len(row) != len(columns):
            raise TargetFileError(
                f"{len(row)} cells, the header has {len(columns)} ({', '.join(columns)})", path=name, line=number
            )
        for j, (column, index) in enumerate(zip(wanted, where)):
            cell = row[index].strip()
            try:
                value = float(cell)
            except ValueError:
                raise TargetFileError(
                    "empty cell" if not cell else f"{cell!r} is not a number", path=name, line=number, column=column
                ) from None
            if not math.isfinite(value):
                raise TargetFileError(f"{cell!r} is not finite", path=name, line=number, column=column)
            values[k, j] = value
    positions = values[:, :3]
    n = len(rows)
    rotations, pitches = np.tile(np.eye(3), (n, 1, 1)), np.zeros(n)
    kind = "position"
    if group == "rpy":
        rpy = np.radians(values[:, 3:6]) if deg else values[:, 3:6]
        rotations, kind = _rpy_matrices(rpy), "pose"
    elif group == "quaternion":
        unit, zero = unit_quaternions(values[:, 3:7])
        if np.any(zero):
            k = int(np.argmax(zero))
            raise TargetFileError("the quaternion (qx, qy, qz, qw) has zero norm", path=name, line=rows[k][0])
        rotations, kind = _quaternion_matrices(unit), "pose"
    elif group == "approach_pitch":
        pitches = np.radians(values[:, 3]) if deg else values[:, 3]
        kind = "pitch"
    return BatchTargets(positions, rotations, pitches, np.full(n, kind, dtype=object))


def write_answers(stream: TextIO, robot: Robot, result: BatchIKResult, *, deg: bool = False) -> None:
    """Write the answers of a batch as CSV (see the module docstring).

    Args:
        stream: Where to write.
        robot: The robot solved for (joint names and kinds).
        result: The batch's result.
        deg: Angles in degrees.
    """
    angular = np.array(robot.joint_kinds) != "prismatic"
    unit = "deg" if deg else "rad"
    writer = csv.writer(stream, lineterminator="\n")
    joints: Sequence[str] = [f"{j} [{unit if a else 'm'}]" for j, a in zip(robot.joint_names, angular)]
    writer.writerow(["row", "status", *joints, "position_error [m]", "orientation_error [rad]"])
    q = np.where(angular, np.degrees(result.q), result.q) if deg else result.q
    for i in range(len(result)):
        cells = [f"{v:.10g}" for v in q[i]] if result.success[i] else [""] * robot.dof
        writer.writerow(
            [
                i + 1,
                str(result.status[i]),
                *cells,
                f"{result.position_error[i]:.3g}",
                f"{result.orientation_error[i]:.3g}",
            ]
        )
