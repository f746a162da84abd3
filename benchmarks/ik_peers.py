"""Peers of the IK benchmark: roboticstoolbox-python's C++ ``ik_LM`` and TRAC-IK (pytracik).

Each peer is built from the same URDF and tip frame as the planner's robot and checked before
use: its joint limits must equal the planner's (TRAC-IK's bundled URDF parser reads Panda's
``<safety_controller>`` soft limits, which clamp some joints to a single value; those limits
are then set to the URDF's and the table says so) and its forward kinematics must match
Pinocchio's at random configurations. A peer that is not installed, or fails a check, is
skipped with the reason.
"""

from __future__ import annotations

import contextlib
import io
import math
import warnings
from importlib import metadata

import numpy as np

__all__ = ["PEERS", "make_peer"]

#: Settings of each peer, as reported.
PEERS = {
    "ik_LM": "roboticstoolbox-python ETS.ik_LM (C++; Chan's Levenberg-Marquardt, ilimit=30 iterations per search, "
    "slimit=100 searches with random restarts, tol=1e-12, joint_limits=True)",
    "trac_ik": "TRAC-IK Speed via pytracik (KDL + SQP in threads, timeout 5 ms, epsilon 1e-5)",
}


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


class RtbLM:
    """roboticstoolbox-python's C++ ``ik_LM`` on the robot's base-to-tip chain."""

    name = "ik_LM"

    def __init__(self, robot, urdf_path, package_root) -> None:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")
            import roboticstoolbox as rtb
            import xacrodoc.packages

            xacrodoc.packages.update_package_cache({"example-robot-data": str(package_root)})
            self.ets = rtb.Robot.URDF(str(urdf_path)).ets(end=robot.tip)
        self.version = _version("roboticstoolbox-python")
        self.note = ""
        qlim = np.asarray(self.ets.qlim)
        if self.ets.n != robot.dof or not np.allclose(qlim, [robot.lower, robot.upper]):
            raise ValueError(f"its chain or limits differ: {qlim.tolist()}")

    def fk(self, q: np.ndarray) -> np.ndarray:
        return np.asarray(self.ets.eval(q))

    def prepare(self, pose: np.ndarray) -> np.ndarray:
        return pose

    def solve(self, pose: np.ndarray, seed: np.ndarray) -> np.ndarray | None:
        sol = self.ets.ik_LM(pose, q0=seed, ilimit=30, slimit=100, tol=1e-12, joint_limits=True)
        return sol.q


class TracIK:
    """TRAC-IK (Speed) through pytracik on the robot's base-to-tip chain."""

    name = "trac_ik"

    def __init__(self, robot, urdf_path, package_root) -> None:
        import pytracik

        self._ik = pytracik.ik
        self.solver = pytracik.TRAC_IK(
            robot.base, robot.tip, urdf_path.read_text(), 0.005, 1e-5, pytracik.SolveType.Speed
        )
        self.version = _version("pytracik")
        if pytracik.get_num_joints(self.solver) != robot.dof:
            raise ValueError(f"its chain has {pytracik.get_num_joints(self.solver)} joints, not {robot.dof}")
        lower = np.array(pytracik.get_joint_lower_bounds(self.solver))
        upper = np.array(pytracik.get_joint_upper_bounds(self.solver))
        self.note = ""
        if not (np.allclose(lower, robot.lower) and np.allclose(upper, robot.upper)):
            bad = [
                robot.joint_names[j]
                for j in np.flatnonzero(~np.isclose(lower, robot.lower) | ~np.isclose(upper, robot.upper))
            ]
            self.note = f"its URDF parser reported other limits for {', '.join(bad)}; set to the URDF's"
            pytracik.set_joint_limits(self.solver, robot.lower.tolist(), robot.upper.tolist())
        self._fk = pytracik.fk

    def fk(self, q: np.ndarray) -> np.ndarray:
        return np.asarray(self._fk(self.solver, q))

    def prepare(self, pose: np.ndarray) -> tuple[float, ...]:
        w, x, y, z = _quaternion(pose[:3, :3])
        return (float(pose[0, 3]), float(pose[1, 3]), float(pose[2, 3]), x, y, z, w)

    def solve(self, prepared: tuple[float, ...], seed: np.ndarray) -> np.ndarray | None:
        r = self._ik(self.solver, seed, *prepared)
        return None if r[0] < 0 else np.asarray(r[1:])


def _quaternion(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """(w, x, y, z) of a rotation matrix (Shepperd's method)."""
    m = rotation
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        return 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    i = int(np.argmax([m[0, 0], m[1, 1], m[2, 2]]))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * math.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
    v = [0.0, 0.0, 0.0]
    v[i] = 0.25 * s
    v[j] = (m[j, i] + m[i, j]) / s
    v[k] = (m[k, i] + m[i, k]) / s
    return (m[k, j] - m[j, k]) / s, v[0], v[1], v[2]


def make_peer(name: str, robot, urdf_path, package_root, rng: np.random.Generator):
    """A checked peer, or the reason it is skipped (a str)."""
    cls = {"ik_LM": RtbLM, "trac_ik": TracIK}[name]
    try:
        peer = cls(robot, urdf_path, package_root)
    except ImportError as exc:
        return f"not installed ({exc.name or exc})"
    except Exception as exc:  # a peer's own failure: reported, not fatal
        return f"cannot be built: {exc}"
    for q in robot.random_configurations(rng, 5):
        if not np.allclose(peer.fk(q), robot.fk(q), atol=1e-9):
            return "its forward kinematics differ from Pinocchio's"
    return peer
