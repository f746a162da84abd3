"""Newton steps on the real model of inexact chains, as one compiled function.

Chains whose axes deviate from the yaw-planar family by round-off (SO-101's URDF: micro-radians)
are solved on the ideal geometry, whose answer misses the target by about the deviation times
the arm's size; a fixed number (:data:`STEPS`) of Newton steps on the real model (the product
of exponentials of its screws, :func:`~planner.geometry.chain.poe_fk`) then take each branch to
round-off: the error squares per step (1e-6 -> 1e-12 -> round-off), so no search and no test
inside the loop.

- Position and approach-pitch targets (:func:`pitch_kernel`): the yaw and the three pitch joints
  (the roll is an input) solve the tip position and the branch's approach elevation
  (``real_model.true_pitch``): 4 equations, 4 unknowns.
- Full poses (:func:`pose_kernel`): every joint; the position (over the arm's size) and the
  rotation error vector, by Gauss-Newton (5 joints, 6 equations; zero residual at a
  solution, so it converges as Newton's method).

The Jacobian is the chain's geometric one (each joint's axis and point carried through the
product), not differentiated by CasADi. The functions are CasADi SX functions with the arm's
screws as a parameter input, so one compiled function (per number of joints, roll index and
kind, :func:`~planner.ik.numeric.codegen.compile_function`, cached on disk) serves every arm;
:class:`NewtonKernel` holds an arm's parameters and buffers for one-target calls (four branches
per call) and :meth:`NewtonKernel.many` runs any number of branches (the batch path). Callers
verify the answers (Pinocchio's FK) and decline those that did not converge (next to a
singularity the steps need not).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.numeric.codegen import compile_function

__all__ = ["STEPS", "NewtonKernel", "newton_kernel", "pitch_kernel", "pose_kernel", "arm_parameters", "tip_fk_sx"]

#: Newton steps per call. From the ideal answer (1e-6 of the arm's size off) two reach
#: round-off where the Jacobian is well conditioned; callers repeat the call for branches
#: that did not settle (started next to a stretched elbow or the yaw axis).
STEPS = 2

#: C compiler flags (as the batch closed form's: no errno after sqrt, no FMA contraction).
FLAGS = ("-O2", "-fno-math-errno", "-fPIC", "-shared")

#: Branches per call of the batch kernels (the last block padded), and for the rest.
BLOCK = 256
SMALL_BLOCK = 8

_FUNCTIONS: dict[tuple, ca.Function] = {}
_KERNELS: dict[int, NewtonKernel] = {}


def arm_parameters(arm: ArmGeometry) -> np.ndarray:
    """The parameter input of the kernels, one vector.

    Axes and points (3 x dof each, joint by joint), tip position (3), tip rotation (9,
    column-major), approach axis (3), mu, sigma, 1 / scale.
    """
    parts = [np.concatenate(arm.axes), np.concatenate(arm.points), arm.tip_position]
    parts += [np.asarray(arm.rot0).T.reshape(9), arm.approach_local, [arm.mu, arm.sigma, 1.0 / arm.scale]]
    return np.concatenate([np.asarray(p, dtype=float).reshape(-1) for p in parts])


def _unpack(prm, dof: int):
    axes = [prm[3 * i : 3 * i + 3] for i in range(dof)]
    o = 3 * dof
    points = [prm[o + 3 * i : o + 3 * i + 3] for i in range(dof)]
    o = 6 * dof
    tip_p = prm[o : o + 3]
    tip_r = ca.reshape(prm[o + 3 : o + 12], 3, 3)
    approach = prm[o + 12 : o + 15]
    return axes, points, tip_p, tip_r, approach, prm[o + 15], prm[o + 16], prm[o + 17]


def _rodrigues(a, angle):
    c, s = ca.cos(angle), ca.sin(angle)
    v = 1.0 - c
    x, y, z = a[0], a[1], a[2]
    return ca.vertcat(
        ca.horzcat(c + v * x * x, v * x * y - s * z, v * x * z + s * y),
        ca.horzcat(v * y * x + s * z, c + v * y * y, v * y * z - s * x),
        ca.horzcat(v * z * x - s * y, v * z * y + s * x, c + v * z * z),
    )


def _fk(q, axes, points, tip_p, tip_r):
    """Tip position, rotation, and per joint its world axis and a point of it, at q."""
    rot = ca.SX.eye(3)
    trans = ca.SX.zeros(3)
    ws, rs = [], []
    for i, (a, c) in enumerate(zip(axes, points)):
        ws.append(ca.mtimes(rot, a))
        rs.append(ca.mtimes(rot, c) + trans)
        r_i = _rodrigues(a, q[i])
        trans = trans + ca.mtimes(rot, c - ca.mtimes(r_i, c))
        rot = ca.mtimes(rot, r_i)
    return ca.mtimes(rot, tip_p) + trans, ca.mtimes(rot, tip_r), ws, rs


def tip_fk_sx(q, prm, dof: int):
    """The real tip's position (3 x 1) and rotation (3 x 3) at q (SX), from the parameter input `prm`."""
    axes, points, tip_p, tip_r, *_ = _unpack(prm, dof)
    p, rot, _, _ = _fk(q, axes, points, tip_p, tip_r)
    return p, rot


def _elevation(q, rot, approach, mu, sigma):
    """The approach axis and its elevation (``real_model.true_pitch``'s front value).

    Returns:
        The axis, the sign of its part along the plane direction, its horizontal size, that
        size counted along the plane direction, and the elevation.
    """
    a = ca.mtimes(rot, approach)
    yaw = mu + sigma * q[0]
    along = ca.cos(yaw) * a[0] + ca.sin(yaw) * a[1]
    h = ca.sqrt(a[0] * a[0] + a[1] * a[1])
    sign = ca.if_else(along >= 0.0, 1.0, -1.0)
    return a, sign, h, sign * h, ca.atan2(a[2], sign * h)


def _wrapped(x):
    return ca.atan2(ca.sin(x), ca.cos(x))


def _pitch_step(q, target, goal, prm, dof: int, active: tuple[int, ...]):
    axes, points, tip_p, tip_r, approach, mu, sigma, _ = _unpack(prm, dof)
    p, rot, ws, rs = _fk(q, axes, points, tip_p, tip_r)
    a, sign, h, big_s, alpha = _elevation(q, rot, approach, mu, sigma)
    res = ca.vertcat(p - target, _wrapped(alpha - goal))
    denom = a[2] * a[2] + big_s * big_s
    cols = []
    for j in active:
        w = ws[j]
        dp = ca.cross(w, p - rs[j])
        da = ca.cross(w, a)
        ds = sign * (a[0] * da[0] + a[1] * da[1]) / h
        cols.append(ca.vertcat(dp, (big_s * da[2] - a[2] * ds) / denom))
    jac = ca.horzcat(*cols)
    step = ca.solve(jac, res)
    out = ca.SX(q)
    for k, j in enumerate(active):
        out[j] = q[j] - step[k]
    return out


def _pose_step(q, target, rot_t, prm, dof: int):
    axes, points, tip_p, tip_r, _, _, _, inv_scale = _unpack(prm, dof)
    p, rot, ws, rs = _fk(q, axes, points, tip_p, tip_r)
    rel = ca.mtimes(rot, rot_t.T)
    # R R_t^T = exp([e]): e's first-order part, the rotation error in the world frame.
    err = 0.5 * ca.vertcat(rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1])
    res = ca.vertcat((p - target) * inv_scale, err)
    jac = ca.horzcat(*[ca.vertcat(ca.cross(ws[j], p - rs[j]) * inv_scale, ws[j]) for j in range(dof)])
    jt = jac.T
    return q - ca.solve(ca.mtimes(jt, jac), ca.mtimes(jt, res))


def pitch_kernel(dof: int, roll_idx: int | None, steps: int = STEPS) -> ca.Function:
    """SX function (q0 (dof), target (3), branch elevation goal, parameters) -> q (dof), miss.

    `miss`: the elevation's miss [rad] at the returned q, by this model.

    The goal is the approach axis's elevation ``alpha`` (``real_model.true_pitch``'s front value:
    its horizontal part counted along the arm's plane direction at the branch's yaw).
    """
    q0 = ca.SX.sym("q0", dof)
    target = ca.SX.sym("p", 3)
    goal = ca.SX.sym("alpha")
    prm = ca.SX.sym("prm", 6 * dof + 18)
    active = tuple(j for j in range(dof) if j != roll_idx)
    q = q0
    for _ in range(steps):
        q = _pitch_step(q, target, goal, prm, dof, active)
    axes, points, tip_p, tip_r, approach, mu, sigma, _ = _unpack(prm, dof)
    _, rot, _, _ = _fk(q, axes, points, tip_p, tip_r)
    miss = _wrapped(_elevation(q, rot, approach, mu, sigma)[4] - goal)
    return ca.Function("newton_pitch", [q0, target, goal, prm], [q, miss])


def pose_kernel(dof: int, steps: int = STEPS) -> ca.Function:
    """SX function (q0 (dof), target position (3), rotation (3 x 3), parameters) -> q (dof)."""
    q0 = ca.SX.sym("q0", dof)
    target = ca.SX.sym("p", 3)
    rot_t = ca.SX.sym("r", 3, 3)
    prm = ca.SX.sym("prm", 6 * dof + 18)
    q = q0
    for _ in range(steps):
        q = _pose_step(q, target, rot_t, prm, dof)
    return ca.Function("newton_pose", [q0, target, rot_t, prm], [q])


def _function(kind: str, dof: int, roll_idx: int | None, width: int, steps: int = STEPS) -> ca.Function:
    """The compiled kernel of a kind over `width` branches, `steps` Newton steps each.

    Width 4: one target's branches (the target and its rotation shared); else any branches
    (only the parameters shared).
    """
    key = (kind, dof, roll_idx if kind == "pitch" else None, width, steps)
    fn = _FUNCTIONS.get(key)
    if fn is None:
        one = pitch_kernel(dof, roll_idx, steps) if kind == "pitch" else pose_kernel(dof, steps)
        if width == 4:
            # One target's: its inputs as one vector (one copy per call): the 4 starts, the
            # target position, the 4 goals or the rotation (column-major).
            mapped = one.map(f"{one.name()}_4", "serial", 4, [1, 2, 3] if kind == "pose" else [1, 3], [])
            x = ca.MX.sym("x", 4 * dof + 3 + (9 if kind == "pose" else 4))
            prm = ca.MX.sym("prm", 6 * dof + 18)
            o = 4 * dof
            other = ca.reshape(x[o + 3 :], 3, 3) if kind == "pose" else ca.reshape(x[o + 3 :], 1, 4)
            out = mapped(ca.reshape(x[:o], dof, 4), x[o : o + 3], other, prm)
            fn = ca.Function(f"{one.name()}_one", [x, prm], list(out) if isinstance(out, (tuple, list)) else [out])
        else:
            fn = one.map(f"{one.name()}_{width}", "serial", width, [3], [])
        fn = compile_function(fn, flags=FLAGS)
        _FUNCTIONS[key] = fn
    return fn


class NewtonKernel:
    """An arm's compiled Newton steps, with buffers for one target's four branches per call.

    Not thread-safe: one target at a time per instance (each solver owns one).
    """

    def __init__(self, arm: ArmGeometry) -> None:
        self.arm = arm
        self.dof = arm.dof
        self.prm = arm_parameters(arm)
        self._calls: dict[tuple[str, int], tuple] = {}

    def _call(self, kind: str, steps: int) -> tuple:
        call = self._calls.get((kind, steps))
        if call is None:
            fn = _function(kind, self.dof, self.arm.roll_idx, 4, steps)
            x = np.zeros(4 * self.dof + 3 + (9 if kind == "pose" else 4))
            prm = self.prm.copy()
            out = np.zeros(4 * self.dof)
            miss = np.zeros(4)
            buffer, evaluate = fn.buffer()
            buffer.set_arg(0, memoryview(x))
            buffer.set_arg(1, memoryview(prm))
            buffer.set_res(0, memoryview(out))
            if kind == "pitch":
                buffer.set_res(1, memoryview(miss))
            call = (buffer, evaluate, x, prm, out, miss)
            self._calls[(kind, steps)] = call
        return call

    def pitch(
        self, q0: list[float], target: list[float], goals: list[float], steps: int = STEPS
    ) -> tuple[list[float], list[float]]:
        """Four branches (q0: 4 x dof, flat) at their elevation goals (4) -> q (4 x dof, flat), misses (4)."""
        _, evaluate, x, _, out, miss = self._call("pitch", steps)
        x[:] = q0 + target + goals
        evaluate()
        return out.tolist(), miss.tolist()

    def pose(self, q0: list[float], target: list[float], rotation: list[float]) -> list[float]:
        """Four branches (q0: 4 x dof, flat) of a pose (rotation column-major, 9) -> q (4 x dof, flat)."""
        _, evaluate, x, _, out, _ = self._call("pose", STEPS)
        x[:] = q0 + target + rotation
        evaluate()
        return out.tolist()

    def many(self, q0: np.ndarray, target: np.ndarray, other: np.ndarray, kind: str) -> np.ndarray:
        """K branches at once: q0 (K, dof), targets (K, 3), goals (K,) or rotations (K, 3, 3) -> q (K, dof).

        In blocks of :data:`BLOCK` branches, the rest in blocks of :data:`SMALL_BLOCK` (two
        compiled functions per kind).
        """
        k = q0.shape[0]
        out = np.empty((k, self.dof))
        full = k // BLOCK * BLOCK
        for width, start, stop in ((BLOCK, 0, full), (SMALL_BLOCK, full, k)):
            if start >= stop:
                continue
            fn = _function(kind, self.dof, self.arm.roll_idx, width)
            for first in range(start, stop, width):
                last = min(first + width, stop)
                rows = np.arange(first, first + width).clip(max=last - 1)
                if kind == "pose":
                    per = np.transpose(other[rows], (1, 0, 2)).reshape(3, 3 * width)
                else:
                    per = np.asarray(other, dtype=float)[rows][None, :]
                res = fn(q0[rows].T, target[rows].T, per, self.prm)
                res = np.asarray(res[0] if isinstance(res, (tuple, list)) else res)
                out[first:last] = res.T[: last - first]
        return out


def newton_kernel(arm: ArmGeometry) -> NewtonKernel:
    """A shared :class:`NewtonKernel` of `arm` (for :meth:`NewtonKernel.many`; the last 16 arms kept)."""
    kernel = _KERNELS.get(id(arm))
    if kernel is None or kernel.arm is not arm:
        if len(_KERNELS) >= 16:
            _KERNELS.clear()
        kernel = _KERNELS[id(arm)] = NewtonKernel(arm)
    return kernel
