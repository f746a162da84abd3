"""The secondary objectives: a bounded NLP (IPOPT) along the solution set of a redundant arm.

Where the arm has more joints than the target has equations (a position target on a 4-joint
arm, a pose on a 7-joint one), the solutions form a set, and IPOPT moves along it from a
converged solution: the joint limits are hard bounds, the task is a set of equality
constraints (for an approach pitch the elevation, or the direction when straight up or down,
with the outward side an inequality), ``det(J J^T) >= floor^2`` an inequality when a
manipulability floor is asked for, and the objective the squared distance to a reference
configuration (the seed for ``near_seed``, else the converged solution itself).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from planner.geometry.target import Target
from planner.ik.numeric.kernel import VERTICAL, outward_direction
from planner.ik.numeric.kinematics import CasadiKinematics
from planner.model.robot import Task

__all__ = ["Polisher"]

#: Cap on the squared floor: floor**2 overflows past 1e154 and Ipopt meets NaN near the largest
#: float; no arm comes near det(J J^T) = 1e200, and answers are checked against the floor itself.
_FLOOR_SQUARED_CAP = 1e200
_EQUALITIES = {"position": 3, "pose": 6, "pitch": 4, "pitch_vertical": 5}
_IPOPT_OPTIONS = {
    "print_time": False,
    "ipopt": {
        "print_level": 0,
        "sb": "yes",
        "max_iter": 200,
        "tol": 1e-12,
        "constr_viol_tol": 1e-10,
        "bound_relax_factor": 0.0,
    },
}


class Polisher:
    """IPOPT solvers of one robot's secondary objectives, built on first use per task.

    Attributes:
        kinematics: The robot's symbolic kinematics.
    """

    def __init__(self, kinematics: CasadiKinematics, lower: np.ndarray, upper: np.ndarray) -> None:
        """Polish within the joint limits `lower`, `upper` (finite, shape (dof,) [rad or m])."""
        self.kinematics = kinematics
        self._lower = lower
        self._upper = upper
        self._axis = np.array(kinematics.robot.approach_axis)
        self._solvers: dict[tuple[str, str, bool], ca.Function] = {}

    @staticmethod
    def task_kind(target: Target) -> str:
        """The polisher's task: the target kind, or ``"pitch_vertical"``.

        A straight up or down pitch is a single direction, whose elevation alone would be a
        degenerate constraint.
        """
        if target.pitch is not None and abs(math.cos(target.pitch)) <= VERTICAL:
            return "pitch_vertical"
        return target.kind

    def redundant(self, kind: str) -> bool:
        """Whether the arm has more joints than a task of this kind has equations."""
        return self.kinematics.dof > _EQUALITIES[kind]

    def polish(
        self, kind: str, target: Target, q_start: np.ndarray, q_ref: np.ndarray, task: Task, floor: float | None
    ) -> tuple[np.ndarray, int]:
        """Move along the solution set towards `q_ref` (and above a manipulability floor).

        Args:
            kind: The task kind (:meth:`task_kind`).
            target: The target.
            q_start: A solution to start from, shape (dof,) [rad or m].
            q_ref: The configuration to come nearest to, shape (dof,) [rad or m].
            task: ``"position"`` or ``"pose"``: the manipulability's task.
            floor: Least manipulability, or None for none.

        Returns:
            IPOPT's answer clipped into the limits (not verified here), and its iteration count.
        """
        n = self.kinematics.dof
        par = np.zeros(19 + n + 1)
        par[0:3] = target.position
        if target.rotation is not None:
            par[3:12] = target.rotation.ravel(order="F")
        neq = _EQUALITIES[kind]
        lbg, ubg = np.zeros(neq), np.zeros(neq)
        if kind == "pitch":
            outward = outward_direction(target)
            par[12:15] = outward
            par[15] = math.sin(float(target.pitch))
            # The approach axis's horizontal part must not point against the outward side.
            lbg = np.append(lbg, 0.0 if outward.any() else -np.inf)
            ubg = np.append(ubg, np.inf)
        par[19 : 19 + n] = q_ref
        if floor is not None:
            par[19 + n] = min(floor * floor, _FLOOR_SQUARED_CAP)
            lbg, ubg = np.append(lbg, 0.0), np.append(ubg, np.inf)
        solver = self._solver(kind, task, floor is not None)
        out = solver(x0=q_start, p=par, lbx=self._lower, ubx=self._upper, lbg=lbg, ubg=ubg)
        q = np.clip(np.array(out["x"]).ravel(), self._lower, self._upper)
        return q, int(solver.stats().get("iter_count", 0))

    def _task_equalities(self, kind: str, q: ca.SX, par: ca.SX) -> ca.SX:
        position, rotation, _ = self.kinematics.expressions(q)
        approach = ca.mtimes(rotation, ca.DM(self._axis))
        rows = [position - par[0:3]]
        if kind == "pose":
            rel = ca.mtimes(ca.reshape(par[3:12], 3, 3).T, rotation)
            rows.append(0.5 * ca.vertcat(rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]))
        elif kind == "pitch":
            # The elevation; the outward side is an inequality (see polish).
            rows += [approach[2] - par[15], ca.dot(approach, par[12:15])]
        elif kind == "pitch_vertical":
            rows.append(approach[0:2])
        return ca.vertcat(*rows)

    def _solver(self, kind: str, task: Task, floor: bool) -> ca.Function:
        key = (kind, task, floor)
        if key not in self._solvers:
            n = self.kinematics.dof
            q = ca.SX.sym("q", n)
            # target position 3, rotation 9, outward direction 3, sin(pitch) 1, unused 3,
            # reference configuration n, squared manipulability floor 1
            par = ca.SX.sym("par", 19 + n + 1)
            constraints = [self._task_equalities(kind, q, par)]
            if floor:
                jac = self.kinematics.expressions(q)[2]
                rows = jac[:3, :] if task == "position" else jac
                gram = ca.mtimes(rows, rows.T) if rows.shape[0] <= n else ca.mtimes(rows.T, rows)
                constraints.append(ca.det(gram) - par[19 + n])
            nlp = {"x": q, "p": par, "f": ca.sumsqr(q - par[19 : 19 + n]), "g": ca.vertcat(*constraints)}
            self._solvers[key] = ca.nlpsol(f"ik_polish_{kind}", "ipopt", nlp, _IPOPT_OPTIONS)
        return self._solvers[key]
