"""The command line: robots, fk, errors as one line on stderr."""

from __future__ import annotations

import json
import math
import re

import numpy as np

import planner

from conftest import BUNDLED, run_cli


def test_robots_json_lists_bundled_arms_with_limits():
    result = run_cli("robots", "--json")
    assert result.returncode == 0, result.stderr
    info = json.loads(result.stdout)
    assert list(info)[:4] == list(BUNDLED)
    dh3 = info["dh3"]
    assert dh3["joints"] == ["base_yaw", "shoulder", "elbow"]
    assert dh3["tip"] == "hand" and dh3["dof"] == 3
    np.testing.assert_allclose(dh3["lower"], [-math.radians(135)] * 3)
    np.testing.assert_allclose(dh3["upper"], [math.radians(135)] * 3)
    assert set(info) == set(planner.available_robots())


def test_robots_table():
    result = run_cli("robots")
    assert result.returncode == 0
    assert "three_joint" in result.stdout and "dof" in result.stdout


def test_fk_json_in_degrees_is_the_seed_example():
    result = run_cli("fk", "dh3", "45", "90", "90", "--deg", "--json")
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    np.testing.assert_allclose(np.round(np.array(out["position"]) * 100, 2), [7.78, 7.78, 9.0])
    assert np.array(out["matrix"]).shape == (4, 4)
    np.testing.assert_allclose(np.array(out["matrix"])[:3, 3], out["position"])


def test_fk_other_tip_and_radians():
    result = run_cli("fk", "al5c", "0", "0", "0", "0", "0", "--tip", "wrist_rotate_link", "--json")
    out = json.loads(result.stdout)
    np.testing.assert_allclose(out["position"], [0.14605 + 0.187325, 0, 0.06731], atol=1e-12)


def test_errors_are_one_line_without_traceback():
    for args, text in [
        (("fk", "puma", "0"), "unknown robot 'puma'; valid names: shelley, al5c"),
        (("fk", "dh3", "0", "0"), "q has shape (2,)"),
        (("fk", "dh3", "0", "0", "0", "--tip", "claw"), "unknown frame 'claw'; valid frames:"),
        (("fk", "dh3", "nan", "0", "0"), "q holds nan for joint 'base_yaw'"),
    ]:
        result = run_cli(*args)
        assert result.returncode == 1, args
        assert result.stderr.count("\n") == 1, result.stderr
        assert text in result.stderr and "Traceback" not in result.stderr


def test_version_and_help():
    result = run_cli("--version")
    assert result.returncode == 0 and planner.__version__ in result.stdout
    result = run_cli("--help")
    assert result.returncode == 0 and "fk" in result.stdout and "robots" in result.stdout


def test_bench_compares_methods_and_draws_the_chart(tmp_path):
    result = run_cli("bench", "dh3", "--n", "5", "--json", "--plot", "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    rows = json.loads(result.stdout)
    assert [(r["robot"], r["method"]) for r in rows] == [("dh3", "analytic"), ("dh3", "nlp")]
    assert all(r["solve_rate"] == 1.0 and r["n"] == 5 for r in rows)
    assert rows[1]["cross_check_agreement"] == 1.0
    assert (tmp_path / "bench_ik.png").read_bytes()[:4] == b"\x89PNG"
    assert json.loads((tmp_path / "bench_ik.json").read_text()) == rows
    assert result.stderr == ""  # no progress bar when piped


def test_bench_bad_input():
    result = run_cli("bench", "dh3", "--n", "0")
    assert result.returncode == 1 and "--n must be at least 1, got 0" in result.stderr
    result = run_cli("bench", "dh3", "--time-budget", "-1")
    assert result.returncode == 1 and "--time-budget must be positive" in result.stderr


def test_every_subcommand_has_help():
    for command in ("robots", "examples", "fk", "ik", "plan", "demo", "bench", "urdf-from-dh"):
        result = run_cli(command, "--help")
        assert result.returncode == 0 and "usage: planner " + command in result.stdout


def test_runs_from_the_repository_root():
    # From the root, the source tree's planner/ shadows an installed (non-editable) package,
    # whose planner.urdf maps the top-level urdf/ folder: bundled arms must load either way.
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    result = subprocess.run(
        [sys.executable, "-m", "planner", "fk", "al5c", "0", "1", "-1", "0", "0", "--json"],
        cwd=root,
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["robot"] == "al5c"


def test_example_plan_files_ship_with_the_package(tmp_path):
    # Run away from the repository (the installed package) and from its root (the source tree).
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    shipped = sorted(p.name for p in (root / "examples").iterdir() if p.suffix in (".yaml", ".json"))
    for cwd in (tmp_path, root):
        listing = run_cli("examples", cwd=cwd)
        assert listing.returncode == 0, listing.stderr
        assert all(name in listing.stdout for name in shipped)
    out = tmp_path / "copies"
    copied = run_cli("examples", "--out", str(out), cwd=tmp_path)
    assert copied.returncode == 0, copied.stderr
    assert sorted(p.name for p in out.iterdir()) == shipped
    for name in shipped:
        assert (out / name).read_bytes() == (root / "examples" / name).read_bytes()
    planned = run_cli("plan", "dh3", str(out / "dh3_pick_and_place.yaml"), "--json", cwd=tmp_path)
    assert planned.returncode == 0 and json.loads(planned.stdout)["singular_waypoints"] == [0, 6, 9]


def test_radians_that_look_like_degrees_are_warned_about():
    result = run_cli("fk", "al5c", "0", "45", "-90", "-45", "0")
    assert result.returncode == 0
    assert "joint value 45 rad is more than a turn; did you mean degrees (--deg)?" in result.stderr
    result = run_cli("ik", "al5c", "0.25", "0.05", "0.12", "--pitch", "-60")
    assert "approach pitch -60 rad is more than half a turn" in result.stderr
    result = run_cli("fk", "al5c", "0", "45", "-90", "-45", "0", "--deg")
    assert result.returncode == 0 and result.stderr == ""
    # Values that round to zero print as 0, never -0.
    assert "(0.235732, 0.000000, -0.061876)" in result.stdout and not re.search(r"-0\.0+\b|-0\.(?!\d)", result.stdout)


def test_fk_orientation_feeds_ik():
    q = ["0.3", "1.2", "-1.4", "-0.5", "0.2"]
    fk = json.loads(run_cli("fk", "al5c", *q, "--json").stdout)
    assert len(fk["rpy"]) == 3 and len(fk["quaternion"]) == 4
    np.testing.assert_allclose(planner.rpy_to_matrix(fk["rpy"]), np.asarray(fk["matrix"])[:3, :3], atol=1e-12)
    np.testing.assert_allclose(
        planner.quaternion_to_matrix(fk["quaternion"]), np.asarray(fk["matrix"])[:3, :3], atol=1e-12
    )
    x, y, z = fk["position"]
    ik = run_cli("ik", "al5c", repr(x), repr(y), repr(z), "--rpy", *map(repr, fk["rpy"]), "--json")
    assert ik.returncode == 0 and json.loads(ik.stdout)["success"]
