"""`planner ik ROBOT --batch FILE.csv`: the CSV targets read as documented, the answers written per
row and checked by Pinocchio FK, bad files named by line and column."""

from __future__ import annotations

import csv
import io
import math

import numpy as np
import pytest
from dh_arms import property_settings
from hypothesis import given
from hypothesis import strategies as st

from planner import TargetFileError, quaternion_to_matrix, rpy_to_matrix
from planner.app.cli import main
from planner.app.target_file import read_targets
from planner.geometry.target import approach_pitch, target_errors
from planner.ik.options import IKOptions
from planner.ik.solvers import IKSolvers

from conftest import get_robot, needs_example_robot_data, run_cli


def parse_answers(text: str) -> tuple[list[str], list[dict[str, str]]]:
    reader = csv.DictReader(io.StringIO(text))
    return list(reader.fieldnames or []), list(reader)


def joint_values(robot, row: dict[str, str], deg: bool) -> np.ndarray:
    unit = "deg" if deg else "rad"
    q = []
    for name, kind in zip(robot.joint_names, robot.joint_kinds):
        if kind == "prismatic":
            q.append(float(row[f"{name} [m]"]))
        else:
            value = float(row[f"{name} [{unit}]"])
            q.append(math.radians(value) if deg else value)
    return np.array(q)


def test_pitch_targets_in_degrees_through_the_command(tmp_path):
    robot = get_robot("al5c")
    rng = np.random.default_rng(1)
    q_true = robot.random_configurations(rng, 8)
    lines = ["x,y,z,approach_pitch"]
    for q in q_true:
        p = robot.fk(q)[:3, 3]
        lines.append(",".join(repr(float(v)) for v in (*p, math.degrees(approach_pitch(robot, q)))))
    lines.insert(3, "# a comment line, skipped")
    lines.append("5.0,0.0,0.0,0")  # out of reach
    path = tmp_path / "targets.csv"
    path.write_text("\n".join(lines) + "\n")
    proc = run_cli("ik", "al5c", "--batch", str(path), "--deg", "--time-budget", "0.01")
    assert proc.returncode == 0, proc.stderr
    header, rows = parse_answers(proc.stdout)
    assert header == ["row", "status", *(f"{j} [deg]" for j in robot.joint_names), "position_error [m]",
                      "orientation_error [rad]"]  # fmt: skip
    assert [r["row"] for r in rows] == [str(i) for i in range(1, 10)]
    targets = read_targets(path, deg=True)
    for i, row in enumerate(rows[:8]):
        assert row["status"] == "solved"
        q = joint_values(robot, row, deg=True)
        assert robot.within_limits(q, tol=1e-9)
        position_error, orientation_error = target_errors(robot, targets.target(i), q)
        assert position_error <= 1e-6 and orientation_error <= 1e-6
    assert rows[8]["status"] == "not_converged"
    assert all(rows[8][f"{j} [deg]"] == "" for j in robot.joint_names)
    assert float(rows[8]["position_error [m]"]) > 1.0
    # The command gives what the API gives from the same seed (home: zero clipped into the limits).
    home = np.clip(np.zeros(robot.dof), robot.lower, robot.upper)
    api = IKSolvers.of(robot).nlp.solve_batch(targets, home, IKOptions(time_budget=0.01))
    for i, row in enumerate(rows[:8]):
        np.testing.assert_allclose(joint_values(robot, row, deg=True), api.q[i], atol=1e-8)


def test_position_targets_to_a_file_with_current(tmp_path, capsys):
    robot = get_robot("dh3")
    rng = np.random.default_rng(2)
    points = [robot.fk(q)[:3, 3] for q in robot.random_configurations(rng, 5)]
    source = tmp_path / "in.csv"
    source.write_text("z,x,y\n" + "".join(f"{p[2]},{p[0]},{p[1]}\n" for p in points))  # any column order
    out = tmp_path / "sub" / "answers.csv"
    current = robot.random_configurations(rng)
    code = main(["ik", "dh3", "--batch", str(source), "--out", str(out), "--current", *map(str, current)])
    assert code == 0
    assert "dh3: 5 of 5 targets solved" in capsys.readouterr().out
    _, rows = parse_answers(out.read_text())
    for p, row in zip(points, rows):
        q = joint_values(robot, row, deg=False)
        assert np.linalg.norm(robot.fk(q)[:3, 3] - p) <= 1e-6


@needs_example_robot_data
@pytest.mark.parametrize("orientation", ["rpy", "quaternion"])
def test_pose_targets_on_ur5(tmp_path, capsys, orientation):
    robot = get_robot("ur5")
    rng = np.random.default_rng(3)
    lines = ["x,y,z,roll,pitch,yaw" if orientation == "rpy" else "x,y,z,qx,qy,qz,qw"]
    poses = [robot.fk(q) for q in robot.random_configurations(rng, 20)]
    import pinocchio as pin

    for pose in poses:
        p = pose[:3, 3]
        if orientation == "rpy":
            extra = pin.rpy.matrixToRpy(pose[:3, :3])
        else:
            extra = pin.Quaternion(pose[:3, :3]).coeffs()  # x, y, z, w
        lines.append(",".join(repr(float(v)) for v in (*p, *extra)))
    path = tmp_path / "poses.csv"
    path.write_text("\n".join(lines) + "\n")
    assert main(["ik", "ur5", "--batch", str(path)]) == 0
    _, rows = parse_answers(capsys.readouterr().out)
    for pose, row in zip(poses, rows):
        assert row["status"] == "solved"
        found = robot.fk(joint_values(robot, row, deg=False))
        assert np.linalg.norm(found[:3, 3] - pose[:3, 3]) <= 1e-6
        assert np.abs(found[:3, :3] - pose[:3, :3]).max() <= 1e-6


BAD_FILES = [
    ("", None, None, "no header line"),
    ("x,y,z\n", None, None, "no targets after the header line"),
    ("x,y,w\n1,2,3\n", 1, "w", "unknown column; valid: x, y, z, roll"),
    ("x,y\n1,2\n", 1, "z", "missing column (x, y and z are required)"),
    ("x,y,z,x\n1,2,3,4\n", 1, "x", "the column appears twice"),
    ("x,y,z,roll,yaw\n1,2,3,0,0\n", 1, "pitch", "missing column of the rpy orientation"),
    ("x,y,z,roll,pitch,yaw,qw\n1,2,3,0,0,0,1\n", 1, None, "give at most one orientation, got rpy and quaternion"),
    ("x,y,z\n0.1,0.2,0.3\n\n0.1,,0.3\n", 4, "y", "empty cell"),
    ("x,y,z\n0.1,abc,0.3\n", 2, "y", "'abc' is not a number"),
    ("x,y,z\n0.1,0.2,inf\n", 2, "z", "'inf' is not finite"),
    ("x,y,z\n0.1,0.2\n", 2, None, "2 cells, the header has 3 (x, y, z)"),
    ("x,y,z,qx,qy,qz,qw\n0.1,0.2,0.3,0,0,0,0\n", 2, None, "the quaternion (qx, qy, qz, qw) has zero norm"),
]


@pytest.mark.parametrize(("text", "line", "column", "message"), BAD_FILES)
def test_bad_files_name_the_line_and_column(tmp_path, capsys, text, line, column, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(TargetFileError) as info:
        read_targets(path)
    assert (info.value.line, info.value.column) == (line, column)
    assert message in str(info.value)
    assert str(info.value).startswith(str(path))
    assert main(["ik", "dh3", "--batch", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("planner ik: error: ") and message in err and len(err.strip().splitlines()) == 1


def test_unreadable_file_and_conflicting_flags(tmp_path, capsys):
    with pytest.raises(TargetFileError, match="cannot read the target file"):
        read_targets(tmp_path / "missing.csv")
    path = tmp_path / "t.csv"
    path.write_text("x,y,z\n0.1,0.2,0.3\n")
    cases = [
        (["0.1", "0.2", "0.3"], "drop x y z"),
        (["--rpy", "0", "0", "0"], "drop --rpy"),
        (["--pitch", "0", "--json"], "drop --pitch, --json"),
        (["--method", "analytic"], "--method analytic is for one target (valid with --batch: auto, nlp)"),
    ]
    for extra, message in cases:
        assert main(["ik", "dh3", *extra, "--batch", str(path)]) == 1
        assert message in capsys.readouterr().err
    assert main(["ik", "dh3", "0.1", "0.2", "0.3", "--out", str(tmp_path / "o.csv")]) == 1
    assert "--out is for --batch" in capsys.readouterr().err
    assert main(["ik", "dh3", "0.1"]) == 1
    assert "give the target x y z [m], or --batch FILE.csv" in capsys.readouterr().err


angles = st.floats(-math.pi, math.pi, allow_nan=False)


@given(rpy=st.tuples(angles, angles, angles), quaternion=st.tuples(*[st.floats(-1, 1)] * 4), deg=st.booleans())
@property_settings(60)
def test_orientation_columns_match_the_single_target_conversions(rpy, quaternion, deg):
    shown = [math.degrees(a) for a in rpy] if deg else list(rpy)
    text = "x,y,z,roll,pitch,yaw\n" + ",".join(repr(v) for v in (0.1, 0.2, 0.3, *shown)) + "\n"
    targets = read_targets(io.StringIO(text), deg=deg)
    np.testing.assert_allclose(targets.rotations[0], rpy_to_matrix(rpy), atol=1e-12)
    assert targets.kinds.tolist() == ["pose"]
    if np.linalg.norm(quaternion) < 1e-3:
        return
    text = "x,y,z,qx,qy,qz,qw\n" + ",".join(repr(v) for v in (0.1, 0.2, 0.3, *quaternion)) + "\n"
    targets = read_targets(io.StringIO(text))
    np.testing.assert_allclose(targets.rotations[0], quaternion_to_matrix(quaternion), atol=1e-12)
