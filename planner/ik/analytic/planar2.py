"""Two revolute joints about parallel vertical axes (Materick and Shapiro's (1997) horizontal 2-link), in closed form.

Materick and Shapiro (1997) finds the elbow on the intersection of two circles, one of radius r1 about the
base and one of radius r2 about the target, and takes either intersection. Here the two
intersections are the two branches, by the law of cosines (which needs no special case for a
target on an axis, the seed's k = 0, nor divides by a coordinate):

- ``"elbow-left"``: the elbow left of the line from the base to the target (seen from above),
- ``"elbow-right"``: right of it.

The tip need not lie on the second link's line: Materick and Shapiro's (1997) claw sits to one side of r2,
which it corrects by the constant angle asin(offset / r2). Here the tip's offset is read from
the model, so the effective second link is the vector from the elbow axis to the tip (length
``hypot(r2, offset)``) and its angle is compensated exactly.

Reach: at most ``r1 + r2`` with the elbow straight (when its range allows), at least the
distance with the elbow turned as far as its range allows (the seed's EQ 3-8 / ``MINREACH``).
A target closer than that is ``"inside_min_reach"`` (the base itself, h = k = 0, included);
the height of the target must be the tip's plane (else ``"out_of_plane"``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from planner.core.rotations import rotation_error
from planner.geometry.chain import ChainAtZero, describe_violation, poe_fk, wrap_array, wrap_scalar
from planner.geometry.target import Target, pitch_error, pitch_error_scalar
from planner.ik.analytic.base import (
    FAMILY_ANGLE_TOL,
    FLOAT64,
    AnalyticIK,
    ChainMismatch,
    base_yaw_mismatch,
    fill_kernel_inputs,
)
from planner.ik.analytic.geometry import LENGTH_TOL, ORIENTATION_TOL, SINGULAR_TOL, angle_to_line, reach_interval
from planner.ik.analytic.nearest import NearestSolution, nearest_entry
from planner.ik.analytic.planar2_single import Planar2Geometry, Planar2Kernel, planar2_kernel
from planner.ik.analytic.result import (
    STATUS_BEYOND_MAX_REACH,
    STATUS_CODES,
    STATUS_INSIDE_MIN_REACH,
    STATUS_ORIENTATION_NOT_ACHIEVABLE,
    STATUS_OUT_OF_PLANE,
    STATUS_OUTSIDE_JOINT_LIMITS,
    STATUS_SOLVED,
    AnalyticBatchResult,
    AnalyticResult,
    AnalyticSolution,
)
from planner.model.robot import Robot

__all__ = ["Planar2IK", "PLANAR_BRANCHES"]

PI = math.pi

#: Branch names in batch order.
PLANAR_BRANCHES = ("elbow-left", "elbow-right")

#: Largest axis deviation [rad] from vertical/parallel accepted (no correction is made).
PLANAR_ANGLE_TOL = 1e-9


class Planar2IK(AnalyticIK):
    """Closed-form IK of two joints about parallel vertical axes.

    Attributes:
        link_lengths: (r1, r2): base axis to elbow axis, elbow axis to tip, in the plane [m].
        tip_offset_angle: Angle [rad] between the second link (elbow axis to the next joint
            frame origin) and the line from the elbow axis to the tip: the seed's claw correction.
        height: Height of the tip's plane [m].
        reach: (min, max) distance [m] from the base axis the tip reaches within the elbow's range.
    """

    family = "planar2"

    @classmethod
    def mismatch(cls, chain: ChainAtZero) -> ChainMismatch | None:
        """Why a chain is not two joints about parallel vertical axes (None when it is)."""
        common = base_yaw_mismatch(chain)
        if common is not None:
            return common
        joints = chain.joints
        if angle_to_line(joints[1].axis, joints[0].axis) > FAMILY_ANGLE_TOL:
            return ChainMismatch(
                f"joint {joints[1].name!r} is not parallel to the first joint {joints[0].name!r}; the planar "
                "family has two vertical joints",
                joints[1].name,
                1,
            )
        if len(joints) > 2:
            return ChainMismatch(
                f"joint {joints[2].name!r} follows two vertical joints; the planar family has exactly two",
                joints[2].name,
                2,
            )
        dev = _deviation(chain)
        if dev > PLANAR_ANGLE_TOL:
            z = np.array([0.0, 0.0, 1.0])
            bad = joints[0] if angle_to_line(joints[0].axis, z) > PLANAR_ANGLE_TOL else joints[1]
            return ChainMismatch(
                f"joint {bad.name!r} is {dev:.3g} rad off the vertical; the planar 2-link solver needs vertical "
                f"axes within {PLANAR_ANGLE_TOL:g} rad",
                bad.name,
                2,
            )
        p1, p2, tip = joints[0].point, joints[1].point, chain.tip_position
        r1, r2 = float(np.hypot(*(p2[:2] - p1[:2]))), float(np.hypot(*(tip[:2] - p2[:2])))
        if min(r1, r2) <= 1e-9 * max(r1 + r2, 1e-3):
            bad = joints[1] if r1 <= r2 else joints[0]
            return ChainMismatch(
                f"joint {bad.name!r} ends a planar link of zero length (links {r1:.3g} m and {r2:.3g} m); the "
                "planar 2-link solver needs two links of non-zero length",
                bad.name,
                2,
            )
        return None

    def __init__(self, robot: Robot, chain: ChainAtZero) -> None:
        super().__init__(robot, chain)
        self._check_chain(chain)
        joints = chain.joints
        dev = _deviation(chain)
        self.deviation = dev
        self.branches = PLANAR_BRANCHES
        self._s1 = 1.0 if joints[0].axis[2] > 0 else -1.0
        self._s2 = 1.0 if joints[1].axis[2] > 0 else -1.0
        p1, p2, tip = joints[0].point, joints[1].point, chain.tip_position
        self._bx, self._by = float(p1[0]), float(p1[1])
        l1 = p2[:2] - p1[:2]
        l2 = tip[:2] - p2[:2]
        self._r1, self._g1 = float(np.hypot(*l1)), float(math.atan2(l1[1], l1[0]))
        self._r2, self._g2 = float(np.hypot(*l2)), float(math.atan2(l2[1], l2[0]))
        self._delta = self._g2 - self._g1
        self.height = float(tip[2])
        self.link_lengths = (self._r1, self._r2)
        self.tip_offset_angle = self._delta
        self._scale = max(1e-9, self._r1 + self._r2)
        self._len_tol = LENGTH_TOL * self._scale
        self._consistency_tol = 1e-9 * self._scale
        rmin, rmax = reach_interval(self._r1, self._r2, self._delta, self._lower[1], self._upper[1], self._s2)
        self.reach = (float(rmin), float(rmax))
        self._rot0 = np.array(chain.tip_rotation)
        self._a0 = np.array(chain.approach)
        self._axes = [j.axis for j in joints]
        self._points = [j.point for j in joints]
        # nearest's distances are modulo 2 pi on both joints (revolute joints, as planner.ik.solve's).
        self._nearest_ok = all(kind == "revolute" for kind in robot.joint_kinds)
        # nearest's compiled kernels by (pose, with a seed): a Planar2Kernel, False (none), or
        # the calls so far (an int) until SINGLE_AFTER.
        self._single: dict[tuple[bool, bool], Planar2Kernel | bool | int] = {}

    def describe(self) -> dict:
        """The detected geometry (lengths [m], angles [rad])."""
        return {
            "family": self.family,
            "link_lengths": list(self.link_lengths),
            "tip_offset_angle": self.tip_offset_angle,
            "height": self.height,
            "reach": list(self.reach),
            "axis_signs": [self._s1, self._s2],
        }

    # ------------------------------------------------------------------ single target
    def solve(self, target: Target, q_current: Sequence[float] | np.ndarray | None = None) -> AnalyticResult:
        """Both closed-form solutions (elbow left and right) for one target."""
        if not isinstance(target, Target):
            self._check_target(target)
        if q_current is None:
            qc = None
        elif type(q_current) is np.ndarray and q_current.dtype is FLOAT64 and q_current.shape == self._q_shape:
            qc = q_current.tolist()  # the common case, checked inline (see _q_current_list)
            if not math.isfinite(sum(qc)):
                qc = self._q_current_list(q_current)
        else:
            qc = self._q_current_list(q_current)
        return self._solve(target, qc, False)

    def nearest(self, target: Target, seed: np.ndarray | None) -> NearestSolution | None:
        """The solution within the limits nearest the seed (see :meth:`AnalyticIK.nearest`).

        After :data:`~planner.ik.analytic.base.SINGLE_AFTER` calls of a position or pose target
        kind, by one compiled call (:mod:`~planner.ik.analytic.planar2_single`; where it is not
        sure, the Python path; joint values the same to round-off; ``count`` and ``index`` None).
        """
        if not self._nearest_ok:
            return None
        if target.pitch is None:
            key = (target.rotation is not None, seed is not None)
            kernel = self._counted_kernel(key, self._planar2_kernel)
            if kernel.__class__ is Planar2Kernel:
                fill_kernel_inputs(kernel.inputs, target.position, None, target.rotation, seed)
                kernel()
                sure, slot, q0, q1 = kernel.outputs.tolist()
                if sure:
                    return NearestSolution((q0, q1), PLANAR_BRANCHES[int(slot)], None, None)
        found = self._solve(target, None if seed is None else seed.tolist(), True)
        return None if isinstance(found, AnalyticResult) else found

    def _planar2_kernel(self, key: tuple[bool, bool]) -> Planar2Kernel | bool:
        """The compiled kernel of :meth:`nearest` for (pose, with a seed), or False."""
        geometry = Planar2Geometry(
            self._s1, self._s2, self._bx, self._by, self._r1, self._r2, self._g1, self._g2, self._delta,
            self.height, self._len_tol, self._consistency_tol, tuple(self._lower), tuple(self._upper), self._rot0,
        )  # fmt: skip
        return planar2_kernel(geometry, *key) or False

    def _solve(self, target: Target, qc: list[float] | None, lean: bool) -> AnalyticResult | NearestSolution | None:
        """:meth:`solve` for a checked q_current (a list or None); with `lean`, :meth:`nearest`'s answer.

        With `lean`, a target without a solution gives its result (as without), one with
        solutions only outside the limits None.
        """
        px, py, pz = target.position.tolist()
        if abs(pz - self.height) > self._len_tol:
            return AnalyticResult(
                STATUS_OUT_OF_PLANE,
                f"{self.robot.name} moves its tip in the plane z = {self.height:.6g} m; the target is at "
                f"z = {pz:.6g} m",
                (),
                False,
            )
        h, k = px - self._bx, py - self._by
        r1, r2 = self._r1, self._r2
        dd = math.hypot(h, k)
        if dd > r1 + r2 + self._len_tol:
            return AnalyticResult(
                STATUS_BEYOND_MAX_REACH,
                f"the target is {dd:.6g} m from the base axis, beyond the reach r1 + r2 = {r1 + r2:.6g} m",
                (),
                False,
            )
        if dd < abs(r1 - r2) - self._len_tol:
            return AnalyticResult(
                STATUS_INSIDE_MIN_REACH,
                f"the target is {dd:.6g} m from the base axis, closer than |r1 - r2| = {abs(r1 - r2):.6g} m"
                + (f" (and the elbow's range keeps the tip beyond {self.reach[0]:.6g} m)" if self.reach[0] > 0 else ""),
                (),
                False,
            )
        if target.pitch is not None and (why := self._pitch_elevation_mismatch(target.pitch)):
            return AnalyticResult(STATUS_ORIENTATION_NOT_ACHIEVABLE, why, (), False)
        if target.rotation is not None:
            heading, why = self._heading_scalar(target)
            if heading is None:
                return AnalyticResult(STATUS_ORIENTATION_NOT_ACHIEVABLE, why, (), False)
            # The heading fixes the second link: the elbow is the tip minus it (one solution).
            ex = h - r2 * math.cos(heading + self._g2)
            ey = k - r2 * math.sin(heading + self._g2)
            if abs(math.hypot(ex, ey) - r1) > self._consistency_tol:
                plain = self.solve(Target(target.position))
                got = ", ".join(
                    f"{math.degrees(self._s1 * s.q[0] + self._s2 * s.q[1] + math.atan2(self._a0[1], self._a0[0])):.2f}"
                    for s in plain.solutions
                )
                return AnalyticResult(
                    STATUS_ORIENTATION_NOT_ACHIEVABLE,
                    f"{self.robot.name} has 2 joints: the position fixes the tip's heading (approach axis at "
                    f"{got} deg from x here), which the asked orientation does not match",
                    (),
                    False,
                )
            a1 = math.atan2(ey, ex)
            e = (heading + self._g2 - a1 + math.pi) % (2 * math.pi) - math.pi
            singular = abs(math.sin(e)) < SINGULAR_TOL
            # A stretched or folded elbow: one solution, named elbow-left on every path.
            branches = [("elbow-left" if e <= 0 or singular else "elbow-right", a1, e)]
        else:
            c = (dd * dd - r1 * r1 - r2 * r2) / (2.0 * r1 * r2)
            c = min(1.0, max(-1.0, c))
            s = math.sqrt(1.0 - c * c)
            singular = s < SINGULAR_TOL
            if singular:
                s, c = 0.0, (1.0 if c > 0 else -1.0)
            e_abs = math.atan2(s, c)
            base = math.atan2(k, h)
            half = math.atan2(r2 * s, r1 + r2 * c)
            branches = [("elbow-left", base + half, -e_abs)]
            if not singular:
                branches.append(("elbow-right", base - half, e_abs))
        s1, s2, g1, g2, bx, by, height = self._s1, self._s2, self._g1, self._g2, self._bx, self._by, self.height
        (lo0, lo1), (hi0, hi1) = self._lower, self._upper
        ref0, ref1 = (0.0, 0.0) if qc is None else qc
        position_only = target.rotation is None and target.pitch is None
        solutions = []
        keys = []
        any_within = False
        pitch_misses = []
        for name, a1, e in branches:
            v0, v1 = s1 * (a1 - g1), s2 * (e - self._delta)
            if target.pitch is not None:  # the position fixes the heading: keep the branches whose axis fits
                pitch_err = self._orientation_error_scalar(s1 * v0 + s2 * v1, target)
                if pitch_err > ORIENTATION_TOL:
                    pitch_misses.append(f"{name} {math.degrees(pitch_err):.2f} deg")
                    continue
            if lean:  # unchecked: solve_ik checks the one it answers with by Pinocchio FK
                # wrap_scalar, which within the range and pi of the reference adds 0.0.
                v0 = v0 + 0.0 if lo0 <= v0 <= hi0 and -PI <= v0 - ref0 <= PI else wrap_scalar(v0, lo0, hi0, ref0)
                v1 = v1 + 0.0 if lo1 <= v1 <= hi1 and -PI <= v1 - ref1 <= PI else wrap_scalar(v1, lo1, hi1, ref1)
                within = lo0 <= v0 <= hi0 and lo1 <= v1 <= hi1
                any_within = any_within or within
                key = (v0 - ref0) * (v0 - ref0) + (v1 - ref1) * (v1 - ref1) if qc is not None else 0.0
                solutions.append((key, len(solutions), (v0, v1), (within, name)))
                continue
            th1, th12 = s1 * v0, s1 * v0 + s2 * v1
            fx = bx + r1 * math.cos(th1 + g1) + r2 * math.cos(th12 + g2)
            fy = by + r1 * math.sin(th1 + g1) + r2 * math.sin(th12 + g2)
            perr = math.hypot(fx - px, fy - py, height - pz)
            oerr = None if position_only else self._orientation_error_scalar(th12, target)
            v0 = v0 + 0.0 if lo0 <= v0 <= hi0 and -PI <= v0 - ref0 <= PI else wrap_scalar(v0, lo0, hi0, ref0)
            v1 = v1 + 0.0 if lo1 <= v1 <= hi1 and -PI <= v1 - ref1 <= PI else wrap_scalar(v1, lo1, hi1, ref1)
            within = lo0 <= v0 <= hi0 and lo1 <= v1 <= hi1
            any_within = any_within or within
            if qc is not None:  # the squared distance to qc, as NumPy sums two squares
                keys.append((v0 - ref0) * (v0 - ref0) + (v1 - ref1) * (v1 - ref1))
            q = np.array((v0, v1))
            q.setflags(write=False)
            solutions.append(AnalyticSolution(q, within, name, singular, perr, oerr))
        if not solutions and pitch_misses:
            return AnalyticResult(
                STATUS_ORIENTATION_NOT_ACHIEVABLE,
                f"{self.robot.name} has 2 joints: the position fixes the tip's heading, and no branch's approach "
                f"axis has approach pitch {math.degrees(target.pitch):.2f} deg here (off by {', '.join(pitch_misses)})",
                (),
                False,
            )
        if lean:
            return nearest_entry(solutions, qc) if any_within else None
        if qc is not None and len(solutions) > 1:
            solutions = [solutions[i] for i in sorted(range(len(solutions)), key=keys.__getitem__)]
        if any_within:
            return AnalyticResult(STATUS_SOLVED, "", tuple(solutions), singular)
        rmin, rmax = self.reach
        if dd < rmin - self._len_tol:
            status = STATUS_INSIDE_MIN_REACH
            reason = (
                f"the target is {dd:.6g} m from the base axis, closer than the minimum reach {rmin:.6g} m that "
                f"joint {self.joint_names[1]!r}'s range allows"
            )
        elif dd > rmax + self._len_tol:
            status = STATUS_BEYOND_MAX_REACH
            reason = (
                f"the target is {dd:.6g} m from the base axis, beyond the {rmax:.6g} m that joint "
                f"{self.joint_names[1]!r}'s range allows"
            )
        else:
            status = STATUS_OUTSIDE_JOINT_LIMITS
            parts = []
            for sol in solutions:
                q = sol.q.tolist()
                bad = [
                    describe_violation(self.joint_names[j], q[j], self._lower[j], self._upper[j])
                    for j in range(2)
                    if not self._lower[j] <= q[j] <= self._upper[j]
                ]
                parts.append(f"{sol.branch}: " + "; ".join(bad))
            reason = "no branch within the joint limits: " + " | ".join(parts)
        return AnalyticResult(status, reason, tuple(solutions), singular)

    def _heading_scalar(self, target: Target) -> tuple[float | None, str]:
        """Tip heading (the turn about z of the whole arm from q = 0) a rotation asks for."""
        m = target.rotation @ self._rot0.T
        heading = math.atan2(m[1, 0], m[0, 0])
        c, s = math.cos(heading), math.sin(heading)
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        residual = float(rotation_error(rz, m))
        if residual > ORIENTATION_TOL:
            return None, (
                f"{self.robot.name} turns its tip about the vertical only; the orientation is {residual:.3g} rad "
                "from any such turn"
            )
        return heading, ""

    def _pitch_elevation_mismatch(self, pitch: float) -> str:
        """Why no configuration has this approach pitch's elevation ("" when the arm's axis has it)."""
        a0 = self._a0
        if abs(a0[2] - math.sin(pitch)) > ORIENTATION_TOL:
            return (
                f"{self.robot.name}'s approach axis stays at {math.degrees(math.asin(max(-1.0, min(1.0, a0[2])))):.2f} "
                f"deg from the horizontal; approach pitch {math.degrees(pitch):.2f} deg is not achievable"
            )
        return ""

    def _orientation_error_scalar(self, th12: float, target: Target) -> float | None:
        if target.rotation is None and target.pitch is None:
            return None
        c, s = math.cos(th12), math.sin(th12)
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        if target.rotation is not None:
            return float(rotation_error(rz @ self._rot0, target.rotation))
        ax, ay, az = (rz @ self._a0).tolist()
        px, py = target.position[0], target.position[1]
        cos_p, sin_p = math.cos(target.pitch), math.sin(target.pitch)
        return pitch_error_scalar(ax, ay, az, px, py, cos_p, sin_p, math.atan2(sin_p, abs(cos_p)))

    # ------------------------------------------------------------------ batch
    def solve_batch(
        self,
        positions: np.ndarray,
        pitch: np.ndarray | float | None = None,
        rotations: np.ndarray | None = None,
        q_current: np.ndarray | None = None,
    ) -> AnalyticBatchResult:
        """Both branches for N targets at once (see :meth:`AnalyticIK.solve_batch`)."""
        pos, pit, rot, qc = self._batch_inputs(positions, pitch, rotations, q_current)
        n = pos.shape[0]
        r1, r2 = self._r1, self._r2
        h = pos[:, 0] - self._bx
        k = pos[:, 1] - self._by
        off_plane = np.abs(pos[:, 2] - self.height) > self._len_tol
        dd = np.hypot(h, k)
        beyond = dd > r1 + r2 + self._len_tol
        inside = dd < abs(r1 - r2) - self._len_tol
        geo = ~(off_plane | beyond | inside)
        orient_fail = np.zeros(n, dtype=bool)
        if rot is None:
            c = np.clip((dd * dd - r1 * r1 - r2 * r2) / (2.0 * r1 * r2), -1.0, 1.0)
            s = np.sqrt(1.0 - c * c)
            singular = s < SINGULAR_TOL
            s = np.where(singular, 0.0, s)
            c = np.where(singular, np.sign(c) + (c == 0), c)
            e_abs = np.arctan2(s, c)
            e = np.stack([-e_abs, e_abs], axis=1)
            half = np.arctan2(r2 * s, r1 + r2 * c)
            base = np.arctan2(k, h)
            a1 = np.stack([base + half, base - half], axis=1)
            valid = np.stack([geo, geo & ~singular], axis=1)
            if pit is not None:  # the position fixes the heading: keep the branches whose axis fits
                heading = a1 - self._g1 + e - self._delta  # th12 of each branch
                a0 = self._a0
                axes = np.stack(
                    [
                        np.cos(heading) * a0[0] - np.sin(heading) * a0[1],
                        np.sin(heading) * a0[0] + np.cos(heading) * a0[1],
                        np.full_like(heading, a0[2]),
                    ],
                    axis=-1,
                )
                pitches = np.broadcast_to(np.asarray(pit, dtype=float).reshape(-1, 1), heading.shape)
                errors = pitch_error(axes.reshape(-1, 3), np.repeat(pos, 2, axis=0), pitches.reshape(-1))
                fits = np.asarray(errors).reshape(n, 2) <= ORIENTATION_TOL
                orient_fail = geo & ~(valid & fits).any(axis=1)
                valid &= fits
        else:
            # The orientation fixes the heading, hence the second link: one solution per target.
            m = rot @ self._rot0.T
            heading = np.arctan2(m[:, 1, 0], m[:, 0, 0])
            c_h, s_h = np.cos(heading), np.sin(heading)
            rz = np.zeros((n, 3, 3))
            rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1], rz[:, 2, 2] = c_h, -s_h, s_h, c_h, 1.0
            orient_ok = np.asarray(rotation_error(rz, m)) <= ORIENTATION_TOL
            ex = h - r2 * np.cos(heading + self._g2)
            ey = k - r2 * np.sin(heading + self._g2)
            orient_ok &= np.abs(np.hypot(ex, ey) - r1) <= self._consistency_tol
            a1_one = np.arctan2(ey, ex)
            e_one = (heading + self._g2 - a1_one + math.pi) % (2 * math.pi) - math.pi
            singular = np.abs(np.sin(e_one)) < SINGULAR_TOL
            left = (e_one <= 0) | singular  # a stretched or folded elbow: elbow-left
            a1 = np.stack([a1_one, a1_one], axis=1)
            e = np.stack([e_one, e_one], axis=1)
            valid = np.stack([geo & orient_ok & left, geo & orient_ok & ~left], axis=1)
            orient_fail = geo & ~orient_ok
        q = np.stack([self._s1 * (a1 - self._g1), self._s2 * (e - self._delta)], axis=-1)
        fk_p, _ = poe_fk(self._axes, self._points, self.chain.tip_position, self._rot0, q)
        perr = np.linalg.norm(fk_p - pos[:, None, :], axis=-1)
        within = valid.copy()
        for j in range(2):
            ref = qc[:, j][:, None] if qc is not None else 0.0
            q[..., j] = wrap_array(q[..., j], self._lower[j], self._upper[j], ref)
            within &= (q[..., j] >= self._lower[j]) & (q[..., j] <= self._upper[j])
        q[~valid] = np.nan
        perr = np.where(valid, perr, np.nan)
        rmin, rmax = self.reach
        status = np.full(n, STATUS_CODES[STATUS_OUTSIDE_JOINT_LIMITS])
        status = np.where(dd < rmin - self._len_tol, STATUS_CODES[STATUS_INSIDE_MIN_REACH], status)
        status = np.where(dd > rmax + self._len_tol, STATUS_CODES[STATUS_BEYOND_MAX_REACH], status)
        status = np.where(inside, STATUS_CODES[STATUS_INSIDE_MIN_REACH], status)
        status = np.where(beyond, STATUS_CODES[STATUS_BEYOND_MAX_REACH], status)
        status = np.where(orient_fail, STATUS_CODES[STATUS_ORIENTATION_NOT_ACHIEVABLE], status)
        status = np.where(off_plane, STATUS_CODES[STATUS_OUT_OF_PLANE], status)
        status = np.where(within.any(axis=1), STATUS_CODES[STATUS_SOLVED], status)
        if qc is not None:
            dist2 = np.sum((q - qc[:, None, :]) ** 2, axis=-1)
        else:
            dist2 = np.broadcast_to(np.arange(2.0), (n, 2))
        best = np.where(within.any(axis=1), np.argmin(np.where(within, dist2, np.inf), axis=1), -1)
        singular2 = np.stack([singular, singular], axis=1) & valid
        for arr in (q, valid, within, singular2, perr):
            arr.setflags(write=False)
        return AnalyticBatchResult(
            q=q,
            valid=valid,
            within_limits=within,
            singular=singular2,
            position_error=perr,
            status=status.astype(np.int8),
            best=best,
            branches=PLANAR_BRANCHES,
        )


def _deviation(chain: ChainAtZero) -> float:
    """Largest angle [rad] of the first two joints' axes from the vertical and from each other."""
    joints = chain.joints
    z = np.array([0.0, 0.0, 1.0])
    return max(angle_to_line(joints[0].axis, z), angle_to_line(joints[1].axis, joints[0].axis))
