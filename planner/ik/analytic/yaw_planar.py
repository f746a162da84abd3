"""Base yaw + 2 or 3 parallel pitch joints + optional wrist roll, in closed form.

The family of the 001 (AL5C), 002 (three-joint coursework) and 004 (DH arm) seeds and of the
SO-101: the first joint turns about the vertical, the next 2 or 3 about parallel horizontal
axes (the arm's plane is perpendicular to them), and an optional last joint rolls about an
axis in that plane.

Geometry, all read from the Pinocchio model at q = 0 (:mod:`planner.geometry.chain`):

- the yaw axis: a vertical line through ``b`` (it need not pass through the base origin);
- the arm plane: unit pitch axis ``n`` (horizontal), in-plane horizontal ``e_u = z x n``;
  a pitch joint turning by ``q_i`` turns the plane's (u, z) coordinates by ``s_i q_i``
  (``s_i = +-1``: the 004 seed's alpha = 180 deg link flips the second pitch axis, s = -1);
- in-plane link vectors between the pitch joints (any in-plane offsets), and the end
  vector from the last pitch joint to the end point, which is the tip, or the wrist roll
  centre when a full orientation fixes the roll;
- the end point's sideways (``n``) offset ``d`` from the yaw axis, constant under the pitch
  joints: the arm's plane passes at distance ``|d|`` from the yaw axis.

Solving, per target: the yaw from the end point's horizontal position (two branches: "front",
and "back" = turned by about pi with the shoulder reaching back over the base); then the
wrist point from the approach angle; then the shoulder-elbow pair by the law of cosines
(elbow up and down). Up to four solutions.

Targets:

- ``pitch`` (``planner.geometry.target``'s convention: the elevation of the approach axis, its
  horizontal part pointing away from the base z axis): the approach axis lies in the arm's
  plane, so per branch its in-plane angle is `pitch` where the plane's direction ``e_u`` (at
  that branch's yaw) points away from the base z axis, else pi - `pitch`; this holds for arms
  whose plane passes beside the yaw axis and whose yaw axis is not the base z axis as well
  (SO-101). On arms without a wrist pitch (2 pitch joints) the pitch fixes the last link: the
  elbow is the end point minus that link and the shoulder points at it (one solution per
  side, kept if the shoulder link then fits to 1e-9 of the arm's size).
- ``rotation``: the yaw from the rotation (the azimuth of the pitch axis, or of the roll axis
  unless that is vertical) where it fixes the yaw better than the position (whose hold on it
  weakens as the end point nears the yaw axis), the position then checked to lie in that
  plane; the pitch sum and the roll from the rotation. Arms without roll or without wrist
  pitch keep only the branches the rotation allows.
- position only: arms without a wrist pitch solve it directly. Arms with one are redundant:
  the approach pitch is ``q_current``'s when given and reachable, else the wrist centre is put
  on the line from the shoulder to the target (straight out) or, when that is too close, at the
  nearest reachable distance, approaching from above.

A free wrist roll (no rotation given) takes ``q_current``'s value, else 0; a free yaw (the end
point on the yaw axis) takes ``q_current``'s, else 0, and the solution is flagged singular.

Free joints within the limits: where no branch lies within the joint limits at those choices,
``solve`` and ``solve_batch`` search the joints the target leaves free, per branch. The
approach pitch of a position-only target: the pitch joints are continuous functions of the
in-plane end angle, and the angles where a branch appears or a pitch joint meets a limit are
the roots of ``|V - R(phi) m|^2 = k`` (closed form, up to 16 per branch side); testing one
point inside each interval between them (and the roots themselves, where a joint's extreme
value just meets its limit) gives every interval within the limits, and the branch takes the
angle nearest the preferred one. The wrist roll, where it moves the tip (SO-101, for position
and pitch targets): rolls outwards from ``q_current``'s every 2.5 deg until one admits the
branch, then the boundary by bisection, so the nearest such roll (a window narrower than a
step may be missed). On inexact chains the search runs on the ideal geometry, keeps clear of
its boundaries (1e-4 rad in pitch, 1e-3 rad in roll) and the result is checked on the real
one.

Chains whose axes deviate from the ideal directions by round-off (up to
:data:`~planner.ik.analytic.base.FAMILY_ANGLE_TOL`, e.g. SO-101's URDF, a few micro-radians) are
solved on the ideal geometry and then corrected on the real one (product of exponentials):
each branch is re-solved for the target shifted by the error it left, which converges by about
the deviation per round, and branches that do not settle (next to a stretched elbow) are
finished by damped Gauss-Newton steps. Only branches that then reproduce the target (1e-10 m,
1e-9 rad) are returned.

Speed: :meth:`YawPlanarIK.solve` runs position and pitch targets on exact chains in scalar
arithmetic (tens of microseconds); rotation targets and inexact chains go through the
vectorised path (hundreds of microseconds for one target). ``solve_batch`` is vectorised over
targets (in slices of 16384 to stay in cache). The search within the limits, only for targets
that need it, costs about 1.5 ms for the approach pitch and 3-12 ms with SO-101's roll.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planner.core.arrays import read_only
from planner.core.rotations import rotation_error
from planner.exceptions import UnsupportedChainError
from planner.geometry.chain import (
    ChainAtZero,
    JointScrew,
    describe_violation,
    poe_fk,
    rotation_about,
    wrap_array,
    wrap_scalar,
)
from planner.geometry.target import Target, approach_pitch, pitch_error, pitch_error_scalar
from planner.ik.analytic.base import FAMILY_ANGLE_TOL, AnalyticIK, ChainMismatch, base_yaw_mismatch
from planner.ik.analytic.geometry import (
    LENGTH_TOL,
    ORIENTATION_TOL,
    SINGULAR_TOL,
    angle_to_line,
    angle_to_plane,
    reach_interval,
    wrap_pi,
)
from planner.ik.analytic.result import (
    STATUS_BEYOND_MAX_REACH,
    STATUS_CODES,
    STATUS_INSIDE_MIN_REACH,
    STATUS_ORIENTATION_NOT_ACHIEVABLE,
    STATUS_OUTSIDE_JOINT_LIMITS,
    STATUS_SOLVED,
    AnalyticBatchResult,
    AnalyticResult,
    AnalyticSolution,
)
from planner.model.robot import Robot

__all__ = ["YawPlanarIK", "BRANCHES", "ChainLayout", "chain_layout"]

PI = math.pi
TWO_PI = 2.0 * math.pi

#: Branch names in batch order.
BRANCHES = ("front/elbow-up", "front/elbow-down", "back/elbow-up", "back/elbow-down")

#: Deviation [rad] below which a chain is treated as exactly of the family.
EXACT_TOL = 1e-12

# Per-branch failure categories (internal).
_VALID, _BEYOND, _INSIDE, _CYLINDER, _ORIENT, _DUPLICATE = range(6)


class YawPlanarIK(AnalyticIK):
    """Closed-form IK of a base yaw + 2 or 3 parallel pitch joints + optional wrist roll.

    Build it with :meth:`AnalyticIK.from_robot`. See the module docstring for the geometry,
    the branches and how each kind of target is solved.

    Attributes:
        n_pitch: Number of pitch joints (2 or 3).
        has_roll: Whether a wrist roll joint ends the chain.
        exact: Whether the model's axes are exactly (within 1e-12 rad) of the family; if not,
            solutions are corrected on the real geometry.
        link_lengths: In-plane lengths [m]: shoulder-elbow, elbow-wrist (or elbow-end), and
            wrist-end (3 pitch joints).
        lateral_offset: Sideways offset of the tip from the yaw axis at roll 0 [m].
    """

    family = "yaw_planar"

    def __init__(self, robot: Robot, chain: ChainAtZero) -> None:
        super().__init__(robot, chain)
        self.branches = BRANCHES
        self._detect(chain)

    # ------------------------------------------------------------------ geometry
    @classmethod
    def mismatch(cls, chain: ChainAtZero) -> ChainMismatch | None:
        """Why a chain is not a base yaw + 2 or 3 pitch joints + optional roll (None when it is)."""
        layout = chain_layout(chain)
        return layout if isinstance(layout, ChainMismatch) else None

    def _detect(self, chain: ChainAtZero) -> None:
        layout = chain_layout(chain)
        if isinstance(layout, ChainMismatch):
            raise UnsupportedChainError(f"{self.robot.name}: {layout.reason}", joint=layout.joint)
        yaw, pitch, roll, deviation = layout.yaw, list(layout.pitch), layout.roll, layout.deviation
        z = np.array([0.0, 0.0, 1.0])
        n_raw = pitch[0].axis
        self.deviation = deviation
        self.exact = deviation <= EXACT_TOL

        # Ideal plane: n horizontal, e_u = z x n, oriented so the tip lies at u >= 0 at q = 0.
        n = np.array([n_raw[0], n_raw[1], 0.0])
        n /= np.linalg.norm(n)
        b3 = np.array([yaw.point[0], yaw.point[1], 0.0])
        e_u = np.cross(z, n)
        if (chain.tip_position - b3) @ e_u < 0:
            n, e_u = -n, -e_u
        self._n, self._e_u, self._b3 = n, e_u, b3
        self._sigma = 1.0 if yaw.axis[2] > 0 else -1.0
        self._bx, self._by = float(b3[0]), float(b3[1])
        self._mu = math.atan2(e_u[1], e_u[0])
        self.n_pitch = len(pitch)
        self._signs = [1.0 if j.axis @ n > 0 else -1.0 for j in pitch]
        self._pitch_idx = [j.index for j in pitch]

        def plane(p):
            rel = p - b3
            return float(rel @ e_u), float(p[2]), float(rel @ n)

        pts = [plane(j.point)[:2] for j in pitch]
        self._su, self._sz = pts[0]
        l1 = (pts[1][0] - pts[0][0], pts[1][1] - pts[0][1])
        self._l1, self._g1 = math.hypot(*l1), math.atan2(l1[1], l1[0])
        last = pts[-1]
        self._last_u, self._last_z = last
        if self.n_pitch == 3:
            l2 = (pts[2][0] - pts[1][0], pts[2][1] - pts[1][1])
            self._l2, self._g2 = math.hypot(*l2), math.atan2(l2[1], l2[0])
        # End geometry: the tip (possibly moved by the roll) and the roll centre.
        tip = chain.tip_position
        self.has_roll = roll is not None
        self._roll_idx = roll.index if roll is not None else None
        self._tip_on_roll_axis = True
        if roll is not None:
            r0 = roll.axis - (roll.axis @ n) * n
            r0 /= np.linalg.norm(r0)
            self._r0 = r0
            self._kappa = math.atan2(r0[2], r0 @ e_u)
            pr = roll.point
            v = tip - pr
            v_par = r0 * (r0 @ v)
            v_perp = v - v_par
            w = np.cross(r0, v)
            centre_tip = plane(pr + v_par)
            self._tip0 = (centre_tip[0] - last[0], centre_tip[1] - last[1], centre_tip[2])
            self._tipc = (float(v_perp @ e_u), float(v_perp[2]), float(v_perp @ n))
            self._tips = (float(w @ e_u), float(w[2]), float(w @ n))
            self._tip_on_roll_axis = bool(np.linalg.norm(v_perp) <= LENGTH_TOL * max(1.0, np.linalg.norm(v)))
            c = plane(pr)
            self._centre = (c[0] - last[0], c[1] - last[1], c[2])
            # Tip offset from the roll centre in tip-frame coordinates (moves rigidly with the tip).
            self._centre_to_tip_local = chain.tip_rotation.T @ (tip - pr)
        tp = plane(tip)
        self._tip_fixed = (tp[0] - last[0], tp[1] - last[1], tp[2])
        if roll is not None and not self._tip_on_roll_axis:
            tp = (self._tip0[0] + self._tipc[0], self._tip0[1] + self._tipc[1], self._tip0[2] + self._tipc[2])
        # Approach axis: in the plane, at angle beta; pitch targets need it to stay there.
        a0 = chain.approach
        self._beta = math.atan2(a0[2], a0 @ e_u)
        in_plane = angle_to_plane(a0, n) <= FAMILY_ANGLE_TOL
        along_roll = roll is None or angle_to_line(a0, self._r0) <= FAMILY_ANGLE_TOL
        self._pitch_supported = in_plane and along_roll
        self._rot0 = np.array(chain.tip_rotation)
        self._approach_local = np.array(self.robot.approach_axis)

        t_len = math.hypot(self._tip_fixed[0], self._tip_fixed[1])
        self.link_lengths = (self._l1, self._l2, t_len) if self.n_pitch == 3 else (self._l1, t_len)
        self.lateral_offset = float(tp[2]) if roll is None else float(self._tip0[2] + self._tipc[2])
        self._scale = max(1e-9, sum(self.link_lengths) + math.hypot(self._su, self._sz))
        self._len_tol = LENGTH_TOL * self._scale
        # Reach of the shoulder-elbow pair within the elbow's range (the 000 seed's min reach).
        elbow = self._pitch_idx[1]
        if self.n_pitch == 3:
            rmin, rmax = reach_interval(
                self._l1, self._l2, self._g2 - self._g1, self._lower[elbow], self._upper[elbow], self._signs[1]
            )
            self._rmin_lim, self._rmax_lim = float(rmin), float(rmax)
        self._axes = [j.axis for j in chain.joints]
        self._points = [j.point for j in chain.joints]
        self._orient_tol = ORIENTATION_TOL if self.exact else max(ORIENTATION_TOL, 1e3 * deviation)
        # Position and orientation of a target must agree this well where the orientation
        # fixes joints the position also fixes (arms without a wrist pitch).
        self._consistency_tol = 1e-9 * self._scale
        self._elbow_seed = 0.0 if self.exact else 2.0 * math.sqrt(deviation)
        # Inexact chains: the ideal model may put a reachable target just outside its reach.
        self._core_len_tol = self._len_tol if self.exact else max(LENGTH_TOL, 1e2 * deviation) * self._scale

    def describe(self) -> dict:
        """The detected geometry, for reports and tests (lengths [m], angles [rad])."""
        out = {
            "family": self.family,
            "n_pitch": self.n_pitch,
            "has_roll": self.has_roll,
            "exact": self.exact,
            "deviation": self.deviation,
            "yaw_axis_point": [self._bx, self._by],
            "yaw_sign": self._sigma,
            "pitch_signs": list(self._signs),
            "shoulder": [self._su, self._sz],
            "link_lengths": list(self.link_lengths),
            "lateral_offset": self.lateral_offset,
            "approach_angle": self._beta,
            "tip_on_roll_axis": self._tip_on_roll_axis,
        }
        if self.n_pitch == 3:
            out["elbow_reach"] = [self._rmin_lim, self._rmax_lim]
        return out

    # ------------------------------------------------------------------ public API
    def solve(self, target: Target, q_current: Sequence[float] | np.ndarray | None = None) -> AnalyticResult:
        """Every closed-form solution for one target (see :meth:`AnalyticIK.solve`)."""
        self._check_target(target)
        qc = self._q_current_list(q_current)
        if target.pitch is not None and not self._pitch_supported:
            self._raise_pitch_unsupported()
        arrays = None
        if self.exact and target.rotation is None:
            result = self._solve_scalar(target, qc)
        else:
            arrays = self._solve_arrays(*self._one_target_arrays(target, qc))
            result = self._result_from_arrays(arrays, 0, target, qc)
        if not result.ok and any(self._free_joints(target.pitch, target.rotation)):
            return self._search_one(target, qc, result, arrays)
        return result

    @staticmethod
    def _one_target_arrays(target: Target, qc: list[float] | None):
        """A target and q_current as the arrays of a batch of one: positions, pitch, rotations, q_current."""
        pos = np.asarray(target.position, dtype=float)[None, :]
        pit = None if target.pitch is None else np.array([target.pitch])
        rot = None if target.rotation is None else np.asarray(target.rotation)[None]
        qca = None if qc is None else np.asarray(qc, dtype=float)[None, :]
        return pos, pit, rot, qca

    def _search_one(self, target: Target, qc: list[float] | None, result: AnalyticResult, base) -> AnalyticResult:
        """The result at free joint values within the limits (see `_search`), else `result`.

        `base` holds `result`'s arrays, or None when the scalar path solved it.
        """
        pos, pit, _, qca = self._one_target_arrays(target, qc)
        if base is None:
            base = self._solve_arrays(pos, pit, None, qca)
        arrays = self._solve_searched(pos, pit, qca, base)
        if arrays is base or arrays["status"][0] != STATUS_CODES[STATUS_SOLVED]:
            if result.status != STATUS_OUTSIDE_JOINT_LIMITS:
                return result
            free_phi, free_roll = self._free_joints(target.pitch, None)
            what = " or ".join(w for w, f in (("approach pitch", free_phi), ("wrist roll", free_roll)) if f)
            return result._replace(reason=f"{result.reason} (no other {what} brings a branch within them)")
        return self._result_from_arrays(arrays, 0, target, qc)

    def solve_batch(
        self,
        positions: np.ndarray,
        pitch: np.ndarray | float | None = None,
        rotations: np.ndarray | None = None,
        q_current: np.ndarray | None = None,
    ) -> AnalyticBatchResult:
        """Closed-form solutions of N targets at once (see :meth:`AnalyticIK.solve_batch`)."""
        pos, pit, rot, qc = self._batch_inputs(positions, pitch, rotations, q_current)
        if pit is not None and not self._pitch_supported:
            self._raise_pitch_unsupported()
        a = self._solve_chunked(pos, pit, rot, qc)
        q = a["q"]
        q.setflags(write=False)
        for key in ("valid", "within", "singular", "perr"):
            a[key].setflags(write=False)
        return AnalyticBatchResult(
            q=q,
            valid=a["valid"],
            within_limits=a["within"],
            singular=a["singular"],
            position_error=a["perr"],
            status=a["status"],
            best=a["best"],
            branches=BRANCHES,
        )

    def _solve_chunked(self, pos, pit, rot, qc, chunk: int = 16384):
        """`_solve_arrays` over slices of the targets (keeps the temporaries in cache)."""
        n = pos.shape[0]
        if n <= chunk:
            return self._solve_arrays_within(pos, pit, rot, qc)
        out = {
            "q": np.empty((n, 4, self.dof)),
            "valid": np.empty((n, 4), dtype=bool),
            "within": np.empty((n, 4), dtype=bool),
            "singular": np.empty((n, 4), dtype=bool),
            "perr": np.empty((n, 4)),
            "status": np.empty(n, dtype=np.int8),
            "best": np.empty(n, dtype=np.intp),
        }
        for start in range(0, n, chunk):
            sl = slice(start, start + chunk)
            part = self._solve_arrays_within(
                pos[sl],
                None if pit is None else pit[sl],
                None if rot is None else rot[sl],
                None if qc is None else qc[sl],
            )
            for key, arr in out.items():
                arr[sl] = part[key]
        return out

    def _solve_arrays_within(self, pos, pit, rot, qc):
        """`_solve_arrays` for a batch, then the search within the limits where targets leave joints free."""
        arrays = self._solve_arrays(pos, pit, rot, qc, orientation_errors=False)
        if any(self._free_joints(pit, rot)):
            arrays = self._solve_searched(pos, pit, qc, arrays, orientation_errors=False)
        return arrays

    def _raise_pitch_unsupported(self) -> None:
        raise UnsupportedChainError(
            f"{self.robot.name}: approach-pitch targets need the approach axis {self.chain.approach.round(6).tolist()} "
            "in the arm's plane"
            + (" and along the wrist roll axis" if self.has_roll else "")
            + "; give a rotation or a position instead",
            joint=self.joint_names[self._roll_idx] if self.has_roll else self.joint_names[self._pitch_idx[-1]],
        )

    # ------------------------------------------------------------------ scalar fast path
    def _solve_scalar(self, target: Target, qc: list[float] | None) -> AnalyticResult:
        """Position or pitch targets on an exact chain, in scalar arithmetic (no NumPy per step)."""
        px, py, pz = target.position.tolist()
        pitch = target.pitch
        if pitch is not None:
            cos_p, sin_p = math.cos(pitch), math.sin(pitch)
            elevation_p = math.atan2(sin_p, abs(cos_p))
        dof = self.dof
        three = self.n_pitch == 3
        cos, sin, atan2, sqrt, hypot = math.cos, math.sin, math.atan2, math.sqrt, math.hypot
        # End point: the tip, moved by the roll when it sits off the roll axis.
        roll_value = 0.0
        if self.has_roll:
            roll_value = qc[self._roll_idx] if qc is not None else 0.0
        if self._tip_on_roll_axis:
            tu, tz, d = self._tip_fixed
        else:
            cr, sr = cos(roll_value), sin(roll_value)
            tu = self._tip0[0] + self._tipc[0] * cr + self._tips[0] * sr
            tz = self._tip0[1] + self._tipc[1] * cr + self._tips[1] * sr
            d = self._tip0[2] + self._tipc[2] * cr + self._tips[2] * sr
        hx, hy = px - self._bx, py - self._by
        rho2 = hx * hx + hy * hy
        len_tol = self._len_tol
        free = rho2 <= len_tol * len_tol and abs(d) <= len_tol
        ang = atan2(hy, hx)
        mu = self._mu
        yaws: list[tuple[int, float, float]] = []  # (side 0 front / 1 back, psi, u)
        cats = [_VALID] * 4
        if free:
            psi0 = self._sigma * qc[0] if qc is not None else 0.0
            yaws.append((0, psi0, 0.0))
            cats[2] = cats[3] = _DUPLICATE
        else:
            under = rho2 - d * d
            if under < -2.0 * abs(d) * len_tol:
                cats = [_CYLINDER] * 4
            else:
                u = sqrt(under) if under > 0.0 else 0.0
                yaws.append((0, ang - mu - atan2(-d, u), u))
                if u > 0.0:
                    yaws.append((1, ang - mu - atan2(-d, -u), -u))
                else:
                    cats[2] = cats[3] = _DUPLICATE
        l1, g1, su, sz = self._l1, self._g1, self._su, self._sz
        beta, sigma, bx, by = self._beta, self._sigma, self._bx, self._by
        signs, idx, roll_idx = self._signs, self._pitch_idx, self._roll_idx
        axis_tol = SINGULAR_TOL * self._scale
        sols: list[tuple[int, list[float], bool, float, float | None]] = []
        dist = [math.nan] * 4
        for side, psi, ue in yaws:
            # Candidates (slot, shoulder link angle a1, relative elbow angle e, elbow singular).
            cands: list[tuple[int, float, float, bool]] = []
            phi = 0.0
            cy, sy = cos(psi + mu), sin(psi + mu)
            if pitch is not None:
                # In-plane approach angle: the pitch, or pi - pitch where the arm's plane
                # direction points towards the base z axis (planner.geometry.target's outward side).
                alpha_t = pitch if cy * px + sy * py >= 0.0 else PI - pitch
            if three:
                l2, g2 = self._l2, self._g2
                if pitch is not None:
                    phi = alpha_t - beta
                else:
                    phi = self._free_pitch_scalar(psi, ue, pz, tu, tz, hypot(tu, tz), atan2(tz, tu), qc)
                    if phi is None:
                        cats[2 * side] = cats[2 * side + 1] = self._free_pitch_failure(ue, pz, hypot(tu, tz))
                        continue
                cp, sp = cos(phi), sin(phi)
                wu = ue - (cp * tu - sp * tz)
                wz = pz - (sp * tu + cp * tz)
            else:
                l2, g2 = hypot(tu, tz), atan2(tz, tu)
                wu, wz = ue, pz
            vx, vz = wu - su, wz - sz
            dd = hypot(vx, vz)
            dist[2 * side] = dist[2 * side + 1] = dd
            if dd > l1 + l2 + len_tol:
                cats[2 * side] = cats[2 * side + 1] = _BEYOND
                continue
            if dd < abs(l1 - l2) - len_tol:
                cats[2 * side] = cats[2 * side + 1] = _INSIDE
                continue
            if not three and pitch is not None:
                # The pitch fixes the last link: the elbow is the end point minus that link,
                # the shoulder points at the elbow (one solution, well conditioned).
                phi = alpha_t - beta
                cp, sp = cos(phi), sin(phi)
                ex = ue - (cp * tu - sp * tz) - su
                ez = pz - (sp * tu + cp * tz) - sz
                if abs(hypot(ex, ez) - l1) > self._consistency_tol:
                    cats[2 * side] = cats[2 * side + 1] = _ORIENT
                    continue
                a1 = atan2(ez, ex)
                e = wrap_pi(phi + g2 - a1)
                up = e <= 0.0 if side == 0 else e >= 0.0
                slot = 2 * side + (0 if up else 1)
                cats[slot ^ 1] = _DUPLICATE
                cands.append((slot, a1, e, abs(sin(e)) < SINGULAR_TOL))
            else:
                c = (dd * dd - l1 * l1 - l2 * l2) / (2.0 * l1 * l2) if l1 > 0.0 and l2 > 0.0 else 1.0
                c = 1.0 if c > 1.0 else (-1.0 if c < -1.0 else c)
                s = sqrt(1.0 - c * c)
                elbow_singular = s < SINGULAR_TOL
                if elbow_singular:
                    s, c = 0.0, (1.0 if c > 0 else -1.0)
                e_abs = atan2(s, c)
                base = atan2(vz, vx)
                half = atan2(l2 * s, l1 + l2 * c)
                if side == 0:
                    cands.append((0, base + half, -e_abs, elbow_singular))
                    if elbow_singular:
                        cats[1] = _DUPLICATE
                    else:
                        cands.append((1, base - half, e_abs, False))
                else:
                    cands.append((2, base - half, e_abs, elbow_singular))
                    if elbow_singular:
                        cats[3] = _DUPLICATE
                    else:
                        cands.append((3, base + half, -e_abs, False))
            q0 = sigma * psi
            for slot, a1, e, elbow_singular in cands:
                phi2 = a1 - g1
                phi3 = a1 + e - g2
                q = [0.0] * dof
                q[0] = q0
                q[idx[0]] = signs[0] * phi2
                q[idx[1]] = signs[1] * (phi3 - phi2)
                if three:
                    q[idx[2]] = signs[2] * (phi - phi3)
                if roll_idx is not None:
                    q[roll_idx] = roll_value
                # Forward check: the closed-form forward model evaluated at the assembled q.
                f2 = signs[0] * q[idx[0]]
                f3 = f2 + signs[1] * q[idx[1]]
                fu = su + l1 * cos(f2 + g1) + l2 * cos(f3 + g2)
                fz = sz + l1 * sin(f2 + g1) + l2 * sin(f3 + g2)
                if three:
                    f4 = f3 + signs[2] * q[idx[2]]
                    ct, st = cos(f4), sin(f4)
                    fu += ct * tu - st * tz
                    fz += st * tu + ct * tz
                else:
                    f4 = f3
                fx = bx + cy * fu + sy * d
                fy = by + sy * fu - cy * d
                perr = sqrt((fx - px) ** 2 + (fy - py) ** 2 + (fz - pz) ** 2)
                oerr = None
                if pitch is not None:
                    c_alpha, s_alpha = cos(beta + f4), sin(beta + f4)
                    oerr = pitch_error_scalar(c_alpha * cy, c_alpha * sy, s_alpha, px, py, cos_p, sin_p, elevation_p)
                singular = elbow_singular or free or abs(ue) < axis_tol
                sols.append((slot, q, singular, perr, oerr))
        return self._finish_scalar(sols, cats, dist, qc, target)

    def _free_pitch_scalar(self, psi, ue, ze, tu, tz, lt, gt, qc):
        """In-plane end angle phi for a position-only target on a wristed arm, or None."""
        su, sz = self._su, self._sz
        lo_geo, hi_geo = abs(self._l1 - self._l2), self._l1 + self._l2
        rmin, rmax = max(lo_geo, self._rmin_lim), min(hi_geo, self._rmax_lim)
        if qc is not None:
            # q_current's approach, kept in the world: mirrored when this branch faces the other way.
            alpha = self._beta + sum(s * qc[i] for s, i in zip(self._signs, self._pitch_idx))
            if math.cos(psi - self._sigma * qc[0]) < 0.0:
                alpha = PI - alpha
            phi = alpha - self._beta
            cp, sp = math.cos(phi), math.sin(phi)
            dd = math.hypot(ue - (cp * tu - sp * tz) - su, ze - (sp * tu + cp * tz) - sz)
            if rmin - self._len_tol <= dd <= rmax + self._len_tol:
                return phi
        ex, ez = ue - su, ze - sz
        de = math.hypot(ex, ez)
        lo = max(abs(de - lt), rmin)
        hi = min(de + lt, rmax)
        if lo > hi + self._len_tol or de == 0.0:
            return None
        rho = lo
        a = (rho * rho - lt * lt + de * de) / (2.0 * de)
        h = math.sqrt(max(rho * rho - a * a, 0.0))
        ux, uz = ex / de, ez / de
        best = None
        for sgn in (1.0, -1.0):
            wx = su + a * ux - sgn * h * uz
            wz = sz + a * uz + sgn * h * ux
            phi = math.atan2(ze - wz, ue - wx) - gt
            lift = math.sin(self._beta + phi)
            if best is None or lift < best[0] - 1e-15:
                best = (lift, phi)
        return best[1]

    def _free_pitch_failure(self, ue, ze, lt) -> int:
        de = math.hypot(ue - self._su, ze - self._sz)
        return _BEYOND if de - lt > min(self._l1 + self._l2, self._rmax_lim) else _INSIDE

    def _finish_scalar(self, sols, cats, dist, qc, target) -> AnalyticResult:
        lower, upper = self._lower, self._upper
        names = self.joint_names
        solutions = []
        details = []
        dof = self.dof
        for slot, q, singular, perr, oerr in sols:
            within = True
            for j in range(dof):
                v, lo, hi = q[j], lower[j], upper[j]
                ref = qc[j] if qc is not None else 0.0
                if lo <= v <= hi and -PI <= v - ref <= PI:
                    continue  # already in range and the equivalent nearest ref
                v = wrap_scalar(v, lo, hi, ref)
                q[j] = v
                if v < lo or v > hi:
                    within = False
            sol = AnalyticSolution(read_only(q), within, BRANCHES[slot], singular, perr, oerr)
            solutions.append(sol)
            details.append((slot, sol))
        if qc is not None and len(solutions) > 1:
            order = sorted(
                range(len(solutions)), key=lambda i: sum((a - b) ** 2 for a, b in zip(solutions[i].q.tolist(), qc))
            )
            solutions = [solutions[i] for i in order]
        status, reason = self._status_and_reason(cats, dist, details, target, names, qc)
        return AnalyticResult(status, reason, tuple(solutions), any(s.singular for s in solutions))

    # ------------------------------------------------------------------ status and reason
    def _status_and_reason(self, cats, dist, details, target, names, qc=None):
        """Overall status and its explanation from per-branch categories and solutions."""
        sols = [s for _, s in details]
        if any(s.within_limits for s in sols):
            return STATUS_SOLVED, ""
        if sols:
            rmin, rmax = self._reach_limits()
            reach_fail = []
            for slot, _ in details:
                dd = dist[slot]
                if rmax is not None and dd > rmax + self._len_tol:
                    reach_fail.append((slot, "beyond", dd))
                elif rmin is not None and dd < rmin - self._len_tol:
                    reach_fail.append((slot, "inside", dd))
            if len(reach_fail) == len(details):
                beyond = any(kind == "beyond" for _, kind, _ in reach_fail)
                parts = [
                    f"{BRANCHES[slot]}: wrist centre {dd:.6g} m from the shoulder, "
                    + (f"beyond {rmax:.6g} m" if kind == "beyond" else f"within {rmin:.6g} m")
                    for slot, kind, dd in reach_fail
                ]
                elbow = names[self._pitch_idx[1]]
                what = "farther" if beyond else "closer"
                return (
                    STATUS_BEYOND_MAX_REACH if beyond else STATUS_INSIDE_MIN_REACH,
                    f"the target is {what} than joint {elbow!r}'s range "
                    f"[{math.degrees(self._lower[self._pitch_idx[1]]):.2f}, "
                    f"{math.degrees(self._upper[self._pitch_idx[1]]):.2f}] deg lets the arm reach ("
                    + "; ".join(parts)
                    + ")",
                )
            parts = []
            for _, s in details:
                q = s.q.tolist()
                bad = [
                    describe_violation(names[j], q[j], self._lower[j], self._upper[j])
                    for j in range(self.dof)
                    if q[j] < self._lower[j] or q[j] > self._upper[j]
                ]
                parts.append(f"{s.branch}: " + "; ".join(bad))
            return STATUS_OUTSIDE_JOINT_LIMITS, "no branch within the joint limits: " + " | ".join(parts)
        live = [c for c in cats if c != _DUPLICATE]
        if _ORIENT in live:
            return STATUS_ORIENTATION_NOT_ACHIEVABLE, self._orientation_reason(target, qc)
        if _CYLINDER in live:
            d = abs(self.lateral_offset)
            return (
                STATUS_INSIDE_MIN_REACH,
                f"the target is closer to the base yaw axis than the {d:.6g} m sideways offset of the arm's plane",
            )
        lengths = " + ".join(f"{v:.6g}" for v in self.link_lengths)
        known = [d for d in dist if not math.isnan(d)]
        if target.pitch is not None and known:
            where = (
                f"with approach pitch {math.degrees(target.pitch):.2f} deg the wrist centre is {min(known):.6g} m "
                f"from joint {names[self._pitch_idx[0]]!r}"
            )
        else:
            where = f"the target is {self._end_distance(target):.6g} m from joint {names[self._pitch_idx[0]]!r}"
        pair = self._l1 + (self._l2 if self.n_pitch == 3 else self.link_lengths[1])
        if _BEYOND in live:
            reach = pair if (target.pitch is not None and known) else sum(self.link_lengths)
            return STATUS_BEYOND_MAX_REACH, f"{where}, beyond the {reach:.6g} m the links ({lengths} m) reach"
        inner = abs(self._l1 - (self._l2 if self.n_pitch == 3 else self.link_lengths[1]))
        return STATUS_INSIDE_MIN_REACH, f"{where}, too close for the links ({lengths} m; |L1 - L2| = {inner:.6g} m)"

    def _end_distance(self, target) -> float:
        """Distance [m] from the shoulder axis to the target in the arm's (front) plane."""
        px, py, pz = target.position.tolist()
        d = self.lateral_offset
        u = math.sqrt(max((px - self._bx) ** 2 + (py - self._by) ** 2 - d * d, 0.0))
        return math.hypot(u - self._su, pz - self._sz)

    def _orientation_reason(self, target, qc) -> str:
        """Why the orientation fails, with what the position alone allows (failures only)."""
        name = self.robot.name
        plain = self.solve(Target(target.position), q_current=qc).solutions
        if target.pitch is not None:
            got = [math.degrees(approach_pitch(self.robot, sol.q)) for sol in plain]
            return (
                f"{name} has no wrist pitch joint: at this position its approach pitch can only be "
                f"{', '.join(f'{g:.2f}' for g in sorted(set(round(g, 6) for g in got)))} deg, "
                f"not {math.degrees(target.pitch):.2f} deg"
            )
        text = f"{name} ({self.dof} joints) cannot reach this position with this orientation"
        if self.n_pitch == 2 and plain:
            _, rot = self._true_fk(np.array([s.q for s in plain]))
            miss = np.asarray(rotation_error(rot, np.broadcast_to(target.rotation, rot.shape)))
            text += f"; at this position the nearest reachable orientation is {float(miss.min()):.3g} rad away"
        else:
            text += " (the orientation fixes the arm's vertical plane, which must also hold the wrist centre)"
        return text

    def _reach_limits(self):
        if self.n_pitch == 3:
            return self._rmin_lim, self._rmax_lim
        return None, None

    # ------------------------------------------------------------------ vectorised core
    def _roll_values(self, n, qc, roll_free):
        """The free wrist roll (n,): `roll_free` where finite, else q_current's, else 0."""
        roll = qc[:, self._roll_idx] if qc is not None else np.zeros(n)
        if roll_free is not None:
            roll = np.where(np.isfinite(roll_free), roll_free, roll)
        return roll

    def _end_geometry(self, n, rot, qc, roll_free=None):
        """Per-target end vector (tu, tz), lateral offset d, end-point shift, roll value."""
        if self.has_roll and rot is not None:
            tu, tz, d = self._centre
            shift = -np.einsum("nij,j->ni", rot, self._centre_to_tip_local)
            return np.full(n, tu), np.full(n, tz), np.full(n, d), shift, None
        roll = None
        if self.has_roll:
            roll = self._roll_values(n, qc, roll_free)
        if self._tip_on_roll_axis:
            tu, tz, d = self._tip_fixed
            return np.full(n, tu), np.full(n, tz), np.full(n, d), None, roll
        cr, sr = np.cos(roll), np.sin(roll)
        tu = self._tip0[0] + self._tipc[0] * cr + self._tips[0] * sr
        tz = self._tip0[1] + self._tipc[1] * cr + self._tips[1] * sr
        d = self._tip0[2] + self._tipc[2] * cr + self._tips[2] * sr
        return tu, tz, d, None, roll

    def _core(self, pos, pit, rot, qc, orient_tol, internal_pitch=False, phi_free=None, roll_free=None):
        """The ideal-geometry closed form for N targets; returns a dict of (N, 4) arrays.

        `pit` is the target's approach pitch, or with `internal_pitch` each row's branch pitch
        (the in-plane approach angle alpha on the front side, pi - alpha on the back side, as
        the ``world_pitch`` this returns). `phi_free` (N, 2), where finite, sets the in-plane
        end angle of position-only targets per side instead of the default choice; `roll_free`
        (N,), where finite, the free wrist roll instead of q_current's.
        """
        n = pos.shape[0]
        dof = self.dof
        three = self.n_pitch == 3
        tu, tz, d, shift, roll = self._end_geometry(n, rot, qc, roll_free)
        end = pos if shift is None else pos + shift
        hx = end[:, 0] - self._bx
        hy = end[:, 1] - self._by
        ze = end[:, 2]
        rho2 = hx * hx + hy * hy
        axis_tol = self._len_tol  # the yaw axis is exact in the ideal model too
        free = (rho2 <= axis_tol * axis_tol) & (np.abs(d) <= axis_tol)
        len_tol = self._core_len_tol
        under = rho2 - d * d
        cylinder = ~free & (under < -2.0 * np.abs(d) * len_tol)
        u = np.sqrt(np.maximum(under, 0.0))
        seeded = np.zeros(n, dtype=bool)
        u_end = u  # the end point's own, for the outward side of pitch targets
        if not self.exact:
            # Inexact chains, end point next to the cylinder |d| around the yaw axis: the real
            # front and back yaws may differ where the ideal model merges them; start apart.
            # (The yaw is ill-conditioned there: such solutions are flagged singular.)
            u_seed = np.sqrt(2.0 * np.abs(d) * len_tol)
            seeded = ~free & ~cylinder & (u < u_seed)
            u = np.where(seeded, u_seed, u)
        ang = np.arctan2(hy, hx)
        psi_f = ang - self._mu - np.arctan2(-d, u)
        psi_b = ang - self._mu - np.arctan2(-d, -u)
        back_dup = free | (u == 0.0)
        psi0 = self._sigma * qc[:, 0] if qc is not None else np.zeros(n)
        m_rot = None
        if rot is not None:
            m_rot = rot @ self._rot0.T
        if np.any(free):
            psi_f = np.where(free, psi0, psi_f)
            u = np.where(free, 0.0, u)
        psi = np.stack([psi_f, psi_b], axis=1)  # (n, 2)
        ue = np.stack([u, -u], axis=1)
        cat = np.zeros((n, 2), dtype=np.int8)
        cat[cylinder] = _CYLINDER
        cat[:, 1] = np.where(back_dup & ~cylinder, _DUPLICATE, cat[:, 1])
        if rot is not None:
            psi, ue, cat = self._yaw_for_rotation(m_rot, hx, hy, d, u, psi, ue, cat, free)
        alpha_t = None
        if pit is not None:
            # In-plane approach angle per side.
            if internal_pitch:
                alpha_t = np.stack([pit, PI - pit], axis=1)
            else:
                # The side from the yaws the end point itself gives (not the seeded ones: next to
                # the yaw axis those turn the plane enough to flip it).
                psi_end = psi
                if seeded.any():
                    psi_end = np.where(
                        seeded[:, None],
                        np.stack([ang - np.arctan2(-d, u_end), ang - np.arctan2(-d, -u_end)], axis=1) - self._mu,
                        psi,
                    )
                alpha_t = self._branch_alpha(end, psi_end, pit)
        ze2 = np.broadcast_to(ze[:, None], (n, 2))
        tu2, tz2 = tu[:, None], tz[:, None]
        roll_q = None if roll is None else np.broadcast_to(roll[:, None], (n, 2))
        phi = None
        orient_res = np.zeros((n, 2))
        if three:
            l2, g2 = self._l2, self._g2
            if pit is not None:
                phi = alpha_t - self._beta
            elif rot is not None:
                phi, roll_q, orient_res = self._pitch_from_rotation(m_rot, psi)
                cat = np.where((cat == _VALID) & (orient_res > orient_tol), _ORIENT, cat)
            elif phi_free is not None and np.isfinite(phi_free).all():
                phi = phi_free
            else:
                phi, fail = self._free_pitch_array(psi, ue, ze2, tu2, tz2, qc)
                if phi_free is not None:
                    given = np.isfinite(phi_free)
                    phi = np.where(given, phi_free, phi)
                    fail = np.where(given, _VALID, fail)
                cat = np.where((cat == _VALID) & (fail != _VALID), fail, cat)
            cp, sp = np.cos(phi), np.sin(phi)
            wu = ue - (cp * tu2 - sp * tz2)
            wz = ze2 - (sp * tu2 + cp * tz2)
        else:
            if pit is not None or rot is not None:
                return self._core_two_oriented(
                    alpha_t, m_rot, psi, ue, ze2, tu, tz, d, cat, free | seeded, roll_q, end, orient_tol
                )
            l2 = np.hypot(tu, tz)[:, None]  # (n, 1): the end vector is the second link
            g2 = np.arctan2(tz, tu)[:, None]
            wu, wz = ue, ze2
        l1, g1 = self._l1, self._g1
        vx = wu - self._su
        vz = wz - self._sz
        dist = np.hypot(vx, vz)
        cat = np.where((cat == _VALID) & (dist > l1 + l2 + len_tol), _BEYOND, cat)
        cat = np.where((cat == _VALID) & (dist < np.abs(l1 - l2) - len_tol), _INSIDE, cat)
        with np.errstate(invalid="ignore", divide="ignore"):
            c = (dist * dist - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
        c = np.clip(np.nan_to_num(c, nan=1.0), -1.0, 1.0)
        s = np.sqrt(1.0 - c * c)
        elbow_sing = s < SINGULAR_TOL
        s = np.where(elbow_sing, 0.0, s)
        c = np.where(elbow_sing, np.sign(c) + (c == 0), c)
        if self._elbow_seed > 0.0:
            # Inexact chains: next to a stretched or folded elbow the real arm's two elbow
            # solutions lie about sqrt(deviation) apart where the ideal model sees one; start
            # the two branches that far apart so the correction finds both.
            near = s < math.sin(self._elbow_seed)
            e_seed = np.where(c > 0, self._elbow_seed, PI - self._elbow_seed)
            s = np.where(near, math.sin(self._elbow_seed), s)
            c = np.where(near, np.cos(e_seed), c)
            elbow_sing = np.zeros_like(elbow_sing)
        e_abs = np.arctan2(s, c)
        base = np.arctan2(vz, vx)
        # (n, 4): front-up (e<=0), front-down, back-up (e>=0), back-down.
        e = np.stack([-e_abs[:, 0], e_abs[:, 0], e_abs[:, 1], -e_abs[:, 1]], axis=1)
        rep = [0, 0, 1, 1]
        # Shoulder: a1 = base - atan2(l2 sin e, l1 + l2 cos e); the sign of e flips the second term.
        half = np.arctan2(l2 * s, l1 + l2 * c)
        a1 = np.stack(
            [base[:, 0] + half[:, 0], base[:, 0] - half[:, 0], base[:, 1] - half[:, 1], base[:, 1] + half[:, 1]], axis=1
        )
        phi2 = a1 - g1
        phi3 = a1 + e - g2
        q = np.empty((n, 4, dof))
        q[:, :, 0] = self._sigma * psi[:, rep]
        sg, idx = self._signs, self._pitch_idx
        q[:, :, idx[0]] = sg[0] * phi2
        q[:, :, idx[1]] = sg[1] * (phi3 - phi2)
        if three:
            phi4 = phi[:, rep]
            q[:, :, idx[2]] = sg[2] * (phi4 - phi3)
            total = phi4
        else:
            total = phi3
        if self.has_roll:
            if roll_q is None:
                roll_q = self._roll_from_rotation(m_rot, psi[:, rep], total)
                q[:, :, self._roll_idx] = roll_q
            else:
                q[:, :, self._roll_idx] = roll_q[:, rep] if roll_q.shape[1] == 2 else roll_q
        cat4 = cat[:, rep].copy()
        cat4[:, 1] = np.where((cat4[:, 1] == _VALID) & elbow_sing[:, 0], _DUPLICATE, cat4[:, 1])
        cat4[:, 3] = np.where((cat4[:, 3] == _VALID) & elbow_sing[:, 1], _DUPLICATE, cat4[:, 3])
        world_pitch = None
        if three:
            alpha = self._beta + total
            world_pitch = np.where(np.array([True, True, False, False]), alpha, PI - alpha)
        singular = elbow_sing[:, rep] | (free | seeded)[:, None] | (np.abs(ue[:, rep]) < SINGULAR_TOL * self._scale)
        return {
            "q": q,
            "cat": cat4,
            "dist": dist[:, rep],
            "singular": singular,
            "world_pitch": world_pitch,
            "end": end,
            "d": d,
            "tu": tu,
            "tz": tz,
            "ue": ue,
            "ze": ze,
            "phi": phi,
            "seeded": seeded,
        }

    def _core_two_oriented(self, alpha_t, m_rot, psi, ue, ze2, tu, tz, d, cat, free, roll_q, end, orient_tol):
        """Arms without a wrist pitch, with a pitch or rotation target: one solution per side.

        The orientation fixes the last link, so the elbow is the end point minus that link and
        the shoulder points at it: well conditioned, unlike filtering the position's two
        solutions by orientation (whose elbow angle degrades to sqrt(eps) near a stretched
        elbow).
        """
        n = psi.shape[0]
        dof = self.dof
        l1, g1, su, sz = self._l1, self._g1, self._su, self._sz
        len_tol = self._core_len_tol
        tu2, tz2 = tu[:, None], tz[:, None]
        l2 = np.hypot(tu2, tz2)
        g2 = np.arctan2(tz2, tu2)
        de = np.hypot(ue - su, ze2 - sz)
        cat = np.where((cat == _VALID) & (de > l1 + l2 + len_tol), _BEYOND, cat)
        cat = np.where((cat == _VALID) & (de < np.abs(l1 - l2) - len_tol), _INSIDE, cat)
        if alpha_t is not None:
            phi = alpha_t - self._beta
        else:
            phi, _, residual = self._pitch_from_rotation(m_rot, psi)
            cat = np.where((cat == _VALID) & (residual > orient_tol), _ORIENT, cat)
        cp, sp = np.cos(phi), np.sin(phi)
        ex = ue - (cp * tu2 - sp * tz2) - su
        ez = ze2 - (sp * tu2 + cp * tz2) - sz
        tol = max(self._consistency_tol, len_tol)
        cat = np.where((cat == _VALID) & (np.abs(np.hypot(ex, ez) - l1) > tol), _ORIENT, cat)
        a1 = np.arctan2(ez, ex)
        e = wrap_pi(phi + g2 - a1)
        up = np.stack([e[:, 0] <= 0.0, e[:, 1] >= 0.0], axis=1)
        rep = [0, 0, 1, 1]
        q2 = np.empty((n, 2, dof))
        q2[:, :, 0] = self._sigma * psi
        sg, idx = self._signs, self._pitch_idx
        phi2 = a1 - g1
        q2[:, :, idx[0]] = sg[0] * phi2
        q2[:, :, idx[1]] = sg[1] * (phi - phi2)
        if self.has_roll:
            if roll_q is None:
                q2[:, :, self._roll_idx] = self._roll_from_rotation(m_rot, psi, phi)
            else:
                q2[:, :, self._roll_idx] = roll_q
        q = q2[:, rep]
        cat4 = cat[:, rep].copy()
        chosen = np.stack([up[:, 0], ~up[:, 0], up[:, 1], ~up[:, 1]], axis=1)
        cat4 = np.where((cat4 == _VALID) & ~chosen, _DUPLICATE, cat4)
        singular = (np.abs(np.sin(e)) < SINGULAR_TOL) | free[:, None] | (np.abs(ue) < SINGULAR_TOL * self._scale)
        return {
            "q": q,
            "cat": cat4,
            "dist": de[:, rep],
            "singular": singular[:, rep],
            "world_pitch": None,
            "end": end,
            "d": d,
            "tu": tu,
            "tz": tz,
        }

    def _branch_alpha(self, pos, psi, pit):
        """In-plane approach angle (n, 2) per side for approach pitch `pit` (n,) at `pos` (n, 3).

        The pitch where the arm's plane direction at yaw psi points away from the base z axis
        (non-negative dot product with the target's horizontal position), else pi - pitch: the
        approach axis's horizontal part then points outward (planner.geometry.target).
        """
        yaw = psi + self._mu
        outward = np.cos(yaw) * pos[:, 0:1] + np.sin(yaw) * pos[:, 1:2] >= 0.0
        return np.where(outward, pit[:, None], PI - pit[:, None])

    def _yaw_for_rotation(self, m_rot, hx, hy, d, u, psi, ue, cat, free):
        """Rotation targets: take the yaw from the rotation where it fixes it better.

        The position fixes the yaw only as well as the end point's distance u from the yaw axis
        allows (a position error e turns it by e / u); the rotation fixes it by the azimuth of
        the pitch axis (arms without roll: always) or of the roll axis (unless that is
        vertical). With the yaw from the rotation, the position must lie in the arm's plane:
        its sideways offset must be the arm's ``d`` (else the branch is not achievable).
        """
        n_axis = self._n
        if self.has_roll:
            w = m_rot @ self._r0
            horiz = np.hypot(w[:, 0], w[:, 1])
            psi_a = np.arctan2(w[:, 1], w[:, 0]) - self._mu
            use = (horiz > 1e-9) & (horiz * self._scale >= u)
        else:
            w = m_rot @ n_axis
            psi_a = np.arctan2(w[:, 1], w[:, 0]) - math.atan2(n_axis[1], n_axis[0])
            use = np.ones(len(psi_a), dtype=bool)
        if not use.any():
            return psi, ue, cat
        cy, sy = np.cos(self._mu + psi_a), np.sin(self._mu + psi_a)
        ue_a = hx * cy + hy * sy  # in-plane and sideways coordinates of the end point at psi_a
        lat_a = hx * sy - hy * cy
        forward = ue_a >= 0.0
        tol = max(self._consistency_tol, self._core_len_tol)
        off_plane = np.abs(lat_a - d) > tol
        cat_rot = np.zeros_like(cat)
        if self.has_roll:
            # psi_a and psi_a + pi (the roll axis pointing forward or back in the arm's frame);
            # the one with the end point in front is the front branch.
            psi_front = np.where(forward, psi_a, psi_a + PI)
            psi_rot = np.stack([psi_front, psi_front + PI], axis=1)
            off_back = np.abs(-lat_a - d) > tol
            cat_rot[:, 0] = np.where(np.where(forward, off_plane, off_back), _ORIENT, _VALID)
            cat_rot[:, 1] = np.where(np.where(forward, off_back, off_plane), _ORIENT, _VALID)
        else:
            # One yaw: the end point lies in front of the yaw axis or behind it.
            psi_rot = np.stack([psi_a, psi_a], axis=1)
            bad = np.where(off_plane, _ORIENT, _VALID)
            cat_rot[:, 0] = np.where(forward, bad, _DUPLICATE)
            cat_rot[:, 1] = np.where(forward, _DUPLICATE, bad)
        ue_rot = np.stack([np.abs(ue_a), -np.abs(ue_a)], axis=1)
        cat_rot = np.where(cat == _CYLINDER, cat, cat_rot)
        use2 = use[:, None]
        return np.where(use2, psi_rot, psi), np.where(use2, ue_rot, ue), np.where(use2, cat_rot, cat)

    def _pitch_from_rotation(self, m_rot, psi):
        """Pitch sum phi (n, 2), roll (n, 2) or None, residual [rad] (n, 2) for given yaws."""
        e_u, n_axis = self._e_u, self._n
        cz, sz = np.cos(psi), np.sin(psi)

        # N = Rz(-psi) M, applied to a vector v: Rz(-psi) (M v).
        def unyaw(v):
            x, y = v[..., 0], v[..., 1]
            return np.stack([cz * x + sz * y, -sz * x + cz * y, np.broadcast_to(v[..., 2], cz.shape)], axis=-1)

        if self.has_roll:
            x = unyaw((m_rot @ self._r0)[:, None, :])
            phi = np.arctan2(x[..., 2], x @ e_u) - self._kappa
            residual = np.arcsin(np.clip(np.abs(x @ n_axis), 0.0, 1.0))
            return phi, None, residual
        x = unyaw((m_rot @ e_u)[:, None, :])
        phi = np.arctan2(x[..., 2], x @ e_u)
        rot_ideal = rotation_about(n_axis, phi)  # (n, 2, 3, 3)
        rz = np.zeros(psi.shape + (3, 3))
        rz[..., 0, 0], rz[..., 0, 1], rz[..., 1, 0], rz[..., 1, 1], rz[..., 2, 2] = cz, -sz, sz, cz, 1.0
        residual = rotation_error(rz @ rot_ideal, np.broadcast_to(m_rot[:, None], rz.shape))
        return phi, None, np.asarray(residual)

    def _roll_from_rotation(self, m_rot, psi4, phi4):
        """Roll angle (n, 4) that completes yaw psi and pitch sum phi to rotation M (ideal axes)."""
        n_axis, r0 = self._n, self._r0
        cz, sz = np.cos(psi4), np.sin(psi4)
        mn = (m_rot @ n_axis)[:, None, :]
        x, y, zc = mn[..., 0], mn[..., 1], mn[..., 2]
        un = np.stack([cz * x + sz * y, -sz * x + cz * y, np.broadcast_to(zc, cz.shape)], axis=-1)
        # y = Rn(-phi) N n ; Rr(theta) n = cos n + sin (r0 x n).
        back = np.einsum("...ij,...j->...i", rotation_about(n_axis, -phi4), un)
        rxn = np.cross(r0, n_axis)
        return np.arctan2(back @ rxn, back @ n_axis)

    def _free_pitch_array(self, psi, ue, ze, tu, tz, qc):
        """Pitch sum phi (n, 2) and failure category for position-only targets on wristed arms."""
        su, sz = self._su, self._sz
        rmin = max(abs(self._l1 - self._l2), self._rmin_lim)
        rmax = min(self._l1 + self._l2, self._rmax_lim)
        lt = np.hypot(tu, tz)
        gt = np.arctan2(tz, tu)
        ex, ez = ue - su, ze - sz
        de = np.hypot(ex, ez)
        lo = np.maximum(np.abs(de - lt), rmin)
        hi = np.minimum(de + lt, rmax)
        fail = np.where(
            (lo > hi + self._core_len_tol) | (de == 0.0), np.where(de - lt > rmax, _BEYOND, _INSIDE), _VALID
        )
        safe = np.where(de == 0.0, 1.0, de)
        a = (lo * lo - lt * lt + safe * safe) / (2.0 * safe)
        h = np.sqrt(np.maximum(lo * lo - a * a, 0.0))
        ux, uz = ex / safe, ez / safe
        best_phi = None
        best_lift = None
        for sgn in (1.0, -1.0):
            wx = su + a * ux - sgn * h * uz
            wz = sz + a * uz + sgn * h * ux
            phi = np.arctan2(ze - wz, ue - wx) - gt
            lift = np.sin(self._beta + phi)
            if best_phi is None:
                best_phi, best_lift = phi, lift
            else:
                take = lift < best_lift - 1e-15
                best_phi = np.where(take, phi, best_phi)
                best_lift = np.where(take, lift, best_lift)
        phi = best_phi
        if qc is not None:
            alpha = self._current_alpha(qc)
            facing = np.cos(psi - self._sigma * qc[:, 0:1]) >= 0.0
            alpha2 = np.where(facing, alpha[:, None], PI - alpha[:, None])
            phi_c = alpha2 - self._beta
            cp, sp = np.cos(phi_c), np.sin(phi_c)
            dd = np.hypot(ue - (cp * tu - sp * tz) - su, ze - (sp * tu + cp * tz) - sz)
            ok = (dd >= rmin - self._core_len_tol) & (dd <= rmax + self._core_len_tol)
            phi = np.where(ok, phi_c, phi)
            fail = np.where(ok, _VALID, fail)
        return phi, fail

    def _current_alpha(self, qc):
        """In-plane approach angle (n,) of q_current.

        From the ideal model on exact chains, measured on the real one otherwise (its approach
        axis against its arm plane).
        """
        if self.exact:
            return self._beta + sum(s * qc[:, i] for s, i in zip(self._signs, self._pitch_idx))
        _, rot = self._true_fk(qc)
        front = self._true_pitch(qc[:, None, :], rot[:, None])  # (n, 1): alpha as a front branch
        return front[:, 0]

    # ------------------------------------------------------------------ arrays pipeline
    def _true_fk(self, q):
        return poe_fk(self._axes, self._points, self.chain.tip_position, self._rot0, q)

    def _ideal_position_error(self, core, pos):
        """Distance (n, 4) [m] from the target to the tip of the ideal closed-form forward model at q."""
        q = core["q"]
        sg, idx = self._signs, self._pitch_idx
        phi2 = sg[0] * q[..., idx[0]]
        phi3 = phi2 + sg[1] * q[..., idx[1]]
        tu, tz, d = core["tu"][:, None], core["tz"][:, None], core["d"][:, None]
        a = phi2 + self._g1
        fu = self._su + self._l1 * np.cos(a)
        fz = self._sz + self._l1 * np.sin(a)
        if self.n_pitch == 3:
            phi4 = phi3 + sg[2] * q[..., idx[2]]
            a = phi3 + self._g2
            fu += self._l2 * np.cos(a)
            fz += self._l2 * np.sin(a)
        else:
            phi4 = phi3
        c4, s4 = np.cos(phi4), np.sin(phi4)
        fu += c4 * tu - s4 * tz
        fz += s4 * tu + c4 * tz
        yaw = self._mu + self._sigma * q[:, ::2, 0]  # one yaw per side (front, back)
        cy, sy = np.cos(yaw)[:, [0, 0, 1, 1]], np.sin(yaw)[:, [0, 0, 1, 1]]
        dx = self._bx + cy * fu + sy * d - pos[:, 0:1]
        dy = self._by + sy * fu - cy * d - pos[:, 1:2]
        dz = fz - pos[:, 2:3]
        return np.sqrt(dx * dx + dy * dy + dz * dz)

    def _solve_arrays(self, pos, pit, rot, qc, orientation_errors: bool = True, phi_free=None, roll_free=None):
        """Solve N targets: ideal closed form, correction when inexact, limits, status.

        `phi_free` (N, 2) and `roll_free` (N,): the free in-plane end angle per side and the
        free wrist roll where finite (see `_core`).
        """
        n = pos.shape[0]
        core = self._core(pos, pit, rot, qc, self._orient_tol, phi_free=phi_free, roll_free=roll_free)
        q = core["q"]
        cat = core["cat"]
        oerr = None
        if self.exact and rot is None:
            perr = self._ideal_position_error(core, pos)
            if pit is not None and orientation_errors:
                oerr = self._pitch_error(q, pos, pit)
        else:
            q, cat, perr, oerr = self._refine(core, pos, pit, rot, qc, roll_free)
        valid = cat == _VALID
        # Wrap into the joint ranges, nearest q_current.
        within = valid.copy()
        # A free roll copied from q_current (or 0 inside its range) needs no wrapping.
        copied_roll = False
        if self.has_roll and rot is None:
            lo, hi = self._lower[self._roll_idx], self._upper[self._roll_idx]
            roll = self._roll_values(n, qc, roll_free)
            copied_roll = bool(np.all((roll >= lo) & (roll <= hi)))
        for j in range(self.dof):
            if copied_roll and j == self._roll_idx:
                col = q[..., j]
            else:
                ref = qc[:, j][:, None] if qc is not None else 0.0
                col = wrap_array(q[..., j], self._lower[j], self._upper[j], ref)
                q[..., j] = col
            within &= (col >= self._lower[j]) & (col <= self._upper[j])
        q[~valid] = np.nan
        perr = np.where(valid, perr, np.nan)
        if oerr is not None:
            oerr = np.where(valid, oerr, np.nan)
        singular = core["singular"] & valid
        status = self._status_codes(cat, valid, within, core["dist"])
        if qc is not None:
            dist2 = np.sum((q - qc[:, None, :]) ** 2, axis=-1)
        else:
            dist2 = np.broadcast_to(np.arange(4.0), (n, 4))
        score = np.where(within, dist2, np.inf)
        best = np.where(within.any(axis=1), np.argmin(score, axis=1), -1)
        return {
            "q": q,
            "cat": cat,
            "valid": valid,
            "within": within,
            "singular": singular,
            "perr": perr,
            "oerr": oerr,
            "status": status.astype(np.int8),
            "best": best,
            "dist": core["dist"],
        }

    def _pitch_error(self, q, pos, pit):
        """planner.geometry.target.pitch_error (n, 4) of the ideal model's approach axis at q."""
        sg, idx = self._signs, self._pitch_idx
        alpha = self._beta + sum(s * q[..., i] for s, i in zip(sg, idx))
        yaw = self._mu + self._sigma * q[..., 0]
        ca = np.cos(alpha)
        approach = np.stack([ca * np.cos(yaw), ca * np.sin(yaw), np.sin(alpha)], axis=-1)
        return pitch_error(approach, pos[:, None, :], pit[:, None])

    def _status_codes(self, cat, valid, within, dist):
        n = cat.shape[0]
        any_valid = valid.any(axis=1)
        any_within = within.any(axis=1)
        status = np.full(n, STATUS_CODES[STATUS_OUTSIDE_JOINT_LIMITS])
        if self.n_pitch == 3:
            beyond_lim = dist > self._rmax_lim + self._len_tol
            inside_lim = dist < self._rmin_lim - self._len_tol
            reach = np.where(valid, beyond_lim | inside_lim, True).all(axis=1) & any_valid
            any_beyond = (valid & beyond_lim).any(axis=1)
            status = np.where(
                reach,
                np.where(any_beyond, STATUS_CODES[STATUS_BEYOND_MAX_REACH], STATUS_CODES[STATUS_INSIDE_MIN_REACH]),
                status,
            )
        live = cat != _DUPLICATE
        none = np.where(
            (live & (cat == _ORIENT)).any(axis=1),
            STATUS_CODES[STATUS_ORIENTATION_NOT_ACHIEVABLE],
            np.where(
                (live & (cat == _BEYOND)).any(axis=1),
                STATUS_CODES[STATUS_BEYOND_MAX_REACH],
                STATUS_CODES[STATUS_INSIDE_MIN_REACH],
            ),
        )
        status = np.where(any_valid, status, none)
        return np.where(any_within, STATUS_CODES[STATUS_SOLVED], status)

    # ------------------------------------------------------------------ correction on the real geometry
    def _refine(self, core, pos, pit, rot, qc, roll_free=None, max_rounds: int = 8):
        """Errors by the real (product of exponentials) model; correct inexact chains.

        Each branch is re-solved for its target shifted by the error its last solution left
        (position, approach pitch, or pose composed with the inverse error), which converges
        by a factor of about the model's deviation from the ideal family per round. Branches
        that do not settle (next to a stretched elbow the rate degrades) are finished by damped
        Gauss-Newton steps on the real model. A branch is kept only if it then reproduces the
        target within 1e-10 m (times the arm's size when above 1 m) and 1e-9 rad.
        """
        n = pos.shape[0]
        q = core["q"].copy()
        cat = core["cat"].copy()
        dist = core["dist"]
        branch_pitch = core["world_pitch"]
        p_eff = np.broadcast_to(pos[:, None, :], (n, 4, 3)).copy()
        # The branch pitch each branch must keep (see _core): the target's in the arm's plane, or
        # for a position-only target the one chosen for it (q_current's, measured on the real
        # arm, the default rule's, or the one the search within the limits found).
        pitch_eff = pitch_goal = None
        if self.n_pitch == 3 and rot is None:
            pitch_goal = branch_pitch.copy()
            pitch_eff = pitch_goal.copy()
        rot_t = None if rot is None else np.broadcast_to(rot[:, None], (n, 4, 3, 3))
        rot_eff = None if rot is None else rot_t.copy()
        qc4 = None if qc is None else np.broadcast_to(qc[:, None, :], (n, 4, self.dof))
        rows = np.arange(4 * n)
        slot = np.tile(np.arange(4), n)
        settle_tol = 1e-14 * max(1.0, self._scale)
        pos_tol = 1e-10 * max(1.0, self._scale)
        valid = cat == _VALID
        for round_ in range(max_rounds + 1):
            fk_p, fk_r = self._true_fk(q)
            perr = np.linalg.norm(fk_p - pos[:, None, :], axis=-1)
            oerr = self._orientation_errors(fk_r, pos, pit, rot)
            settled = perr <= settle_tol
            if oerr is not None:
                settled &= oerr <= 1e-13
            if pitch_goal is not None and not self.exact:
                true_pitch = self._true_pitch(q, fk_r)
                settled &= np.abs(wrap_pi(true_pitch - pitch_goal)) <= 1e-13
            if self.exact or (~valid | settled).all() or round_ == max_rounds:
                break
            if rot is not None:
                # T_eff <- T_eff FK(q)^-1 T: the pose error, expressed at the tip, undone.
                fk_rt = np.swapaxes(fk_r, -1, -2)
                p_eff = p_eff + np.einsum("...ij,...jk,...k->...i", rot_eff, fk_rt, pos[:, None, :] - fk_p)
                rot_eff = _orthonormalize(rot_eff @ fk_rt @ rot_t)
            else:
                p_eff = p_eff + (pos[:, None, :] - fk_p)
            if pitch_goal is not None:
                pitch_eff = pitch_eff + wrap_pi(pitch_goal - true_pitch)
            sub = self._core(
                p_eff.reshape(-1, 3),
                None if pitch_eff is None else pitch_eff.reshape(-1),
                None if rot_eff is None else rot_eff.reshape(-1, 3, 3),
                None if qc4 is None else qc4.reshape(-1, self.dof),
                self._orient_tol,
                internal_pitch=True,
                roll_free=None if roll_free is None else np.repeat(roll_free, 4),
            )
            q_new = sub["q"][rows, slot].reshape(n, 4, self.dof)
            took = valid & (sub["cat"][rows, slot].reshape(n, 4) == _VALID)
            q = np.where(took[..., None], q_new, q)
            dist = np.where(took, sub["dist"][rows, slot].reshape(n, 4), dist)
        if not self.exact:
            todo = valid & ~settled
            if todo.any():
                idx = np.nonzero(todo)
                held = None if pitch_goal is None else pitch_goal[idx]
                q_sub = self._polish(q[idx], pos[idx[0]], held, None if rot is None else rot[idx[0]], idx[1] < 2)
                q[idx] = q_sub
                fk_p, fk_r = self._true_fk(q)
                perr = np.linalg.norm(fk_p - pos[:, None, :], axis=-1)
                oerr = self._orientation_errors(fk_r, pos, pit, rot)
        ok = perr <= pos_tol
        if oerr is not None:
            ok &= oerr <= (1e-9 if not self.exact else self._orient_tol)
        if not self.exact:
            # Branches that converged onto one solution (a singular target): keep the first.
            for a, b in ((0, 1), (2, 3), (0, 2), (0, 3), (1, 2), (1, 3)):
                both = (valid[:, a] & ok[:, a]) & (valid[:, b] & ok[:, b])
                twin = both & (np.max(np.abs(wrap_pi(q[:, a] - q[:, b])), axis=-1) < 1e-7)
                if twin.any():
                    cat[twin, b] = _DUPLICATE
                    valid[twin, b] = False
                    core["singular"][twin, a] = True
        failed = valid & ~ok
        if failed.any():
            if rot is not None or (pit is not None and self.n_pitch == 2):
                fail_cat = np.full(cat.shape, _ORIENT)
            else:
                middle = 0.5 * (abs(self._l1 - self.link_lengths[1]) + self._l1 + self.link_lengths[1])
                fail_cat = np.where(dist > middle, _BEYOND, _INSIDE)
            cat = np.where(failed, fail_cat, cat)
        core["dist"] = dist
        return q, cat, perr, oerr

    def _polish(self, q, pos, pit, rot, front, iterations: int = 40):
        """Damped Gauss-Newton on the real model for K rows; returns the new q (K, dof).

        Residuals: position (scaled by the arm's size), plus the approach pitch for pitch
        targets or the rotation error vector for rotation targets. The wrist roll moves only
        for rotation targets (elsewhere it is an input).
        """
        active = [j for j in range(self.dof) if rot is not None or j != self._roll_idx]
        inv_scale = 1.0 / self._scale
        front4 = np.where(front, 0, 2)

        def residual(qq):
            fk_p, fk_r = self._true_fk(qq)
            parts = [(fk_p - pos) * inv_scale]
            if rot is not None:
                rel = np.swapaxes(rot, -1, -2) @ fk_r
                parts.append(
                    0.5
                    * np.stack(
                        [rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0], rel[:, 1, 0] - rel[:, 0, 1]], axis=-1
                    )
                )
            elif pit is not None and self.n_pitch == 3:
                qq4 = np.repeat(qq[:, None, :], 4, axis=1)
                rr4 = np.repeat(fk_r[:, None], 4, axis=1)
                got = self._true_pitch(qq4, rr4)[np.arange(len(qq)), front4]
                parts.append(wrap_pi(got - pit)[:, None])
            return np.concatenate(parts, axis=-1)

        step = 1e-7
        for _ in range(iterations):
            r = residual(q)
            if np.max(np.abs(r)) <= 1e-15:
                break
            jac = np.empty(r.shape + (len(active),))
            for k, j in enumerate(active):
                dq = q.copy()
                dq[:, j] += step
                jac[..., k] = (residual(dq) - r) / step
            jt = np.swapaxes(jac, -1, -2)
            lhs = jt @ jac + 1e-12 * np.eye(len(active))
            delta = np.linalg.solve(lhs, -(jt @ r[..., None]))[..., 0]
            q = q.copy()
            q[:, active] += delta
        return q

    def _true_pitch(self, q, fk_r):
        """Branch pitch (front: alpha, back: pi - alpha; see `_core`) of the real tip.

        alpha is the elevation of the real approach axis, its horizontal part counted positive
        along the arm's plane direction: the elevation itself, not its angle within the ideal
        plane, which differs (near vertical, by the square of the axis's small tilt out of that
        plane over its horizontal part) and would leave the target's elevation missed.
        """
        a = fk_r @ self._approach_local
        yaw = self._mu + self._sigma * q[..., 0]
        along = np.cos(yaw) * a[..., 0] + np.sin(yaw) * a[..., 1]
        horiz = np.hypot(a[..., 0], a[..., 1])
        alpha = np.arctan2(a[..., 2], np.where(along >= 0.0, horiz, -horiz))
        return np.where(np.array([True, True, False, False]), alpha, PI - alpha)

    def _orientation_errors(self, fk_r, pos, pit, rot):
        """Orientation errors (n, 4) of the real tip rotations for rotation or pitch targets, else None."""
        if rot is not None:
            return np.asarray(rotation_error(fk_r, np.broadcast_to(rot[:, None], fk_r.shape)))
        if pit is not None:
            return pitch_error(fk_r @ self._approach_local, pos[:, None, :], pit[:, None])
        return None

    # ------------------------------------------------------------------ free joints within the limits
    def _free_joints(self, pit, rot) -> tuple[bool, bool]:
        """What a target leaves free that moves the arm: (the in-plane end angle, the wrist roll).

        The end angle of position-only targets on wristed arms; the roll where the tip sits off
        the roll axis.
        """
        if rot is not None:
            return False, False
        return pit is None and self.n_pitch == 3, self.has_roll and not self._tip_on_roll_axis

    def _limit_values(self, j: int) -> tuple[float, ...]:
        """Joint j's limits, or () when every angle has an equivalent within them."""
        lo, hi = self._lower[j], self._upper[j]
        return (lo, hi) if hi - lo < TWO_PI else ()

    def _within_ideal(self, core, pos, qc):
        """Mask (n, 4): the ideal core's branch reaches the target and lies within the limits.

        Reaches `pos` (n, 3) to 1e-10 m (not merely within the core's reach tolerance); the
        limits checked after wrapping as in `_solve_arrays`. On inexact chains, also clear of
        the yaw axis's cylinder by more than the start separation of `_core` (closer, the
        correction onto the real geometry is unreliable).
        """
        q = core["q"]
        within = core["cat"] == _VALID
        within &= self._ideal_position_error(core, pos) <= 1e-10 * max(1.0, self._scale)
        if not self.exact:
            within &= ~core["seeded"][:, None]
        for j in range(self.dof):
            if self._limit_values(j):
                lo, hi = self._lower[j], self._upper[j]
                col = wrap_array(q[..., j], lo, hi, qc[:, j][:, None] if qc is not None else 0.0)
                within &= (col >= lo) & (col <= hi)
        return within

    def _phi_boundaries(self, ue, ze, tu, tz):
        """In-plane end angles (n, 2, K) [rad] where a branch appears or a pitch joint meets a limit.

        Between two of them (on the circle) every branch exists or not throughout and keeps each
        pitch joint within its limits or outside them, since the joints are continuous functions
        of the end angle phi there. Each boundary is a root of ``|V - R(phi) m|^2 = k`` for an
        in-plane vector V fixed by the end point and m by the end vector, i.e. of
        ``cos(phi + angle(m) - angle(V)) = (|V|^2 + |m|^2 - k) / (2 |V| |m|)``: the wrist point
        at the reach of the shoulder-elbow pair (its ends, and the elbow at a limit: the law of
        cosines), at link 2's length from the elbow of the shoulder at a limit, or the elbow at
        link 1's length from the shoulder with the wrist at a limit (links 2 and 3 then one
        rigid vector m). NaN pads rows with fewer roots.
        """
        su, sz, l1, l2, g1, g2 = self._su, self._sz, self._l1, self._l2, self._g1, self._g2
        s0, s1, s2 = self._signs
        i0, i1, i2 = self._pitch_idx
        # Per equation: the offset of V from (end point - shoulder), m - (end vector), and k.
        eqs = [(0.0, 0.0, 0.0, 0.0, (l1 + l2) ** 2), (0.0, 0.0, 0.0, 0.0, (l1 - l2) ** 2)]
        for limit in self._limit_values(i1):
            e = s1 * limit - g1 + g2
            eqs.append((0.0, 0.0, 0.0, 0.0, l1 * l1 + l2 * l2 + 2.0 * l1 * l2 * math.cos(e)))
        for limit in self._limit_values(i0):
            a = s0 * limit + g1
            eqs.append((-l1 * math.cos(a), -l1 * math.sin(a), 0.0, 0.0, l2 * l2))
        for limit in self._limit_values(i2):
            c = g2 - s2 * limit
            eqs.append((0.0, 0.0, l2 * math.cos(c), l2 * math.sin(c), l1 * l1))
        dvx, dvz, dmx, dmz, k = (np.array(col) for col in zip(*eqs))
        ax = (ue - su)[..., None] + dvx  # (n, 2, E)
        az = (ze[:, None] - sz)[..., None] + dvz
        mx = tu[:, None, None] + dmx
        mz = tz[:, None, None] + dmz
        v2, m2 = ax * ax + az * az, mx * mx + mz * mz
        denom = 2.0 * np.sqrt(v2 * m2)
        with np.errstate(invalid="ignore", divide="ignore"):
            c = (v2 + m2 - k) / denom
        # A tangency (a joint's extreme value exactly at its limit) may round to |c| just above 1.
        ok = (denom > 0.0) & (np.abs(c) <= 1.0 + 1e-12)
        base = np.arctan2(az, ax) - np.arctan2(mz, mx)
        half = np.arccos(np.clip(np.where(ok, c, 0.0), -1.0, 1.0))
        roots = np.concatenate([np.where(ok, base + half, np.nan), np.where(ok, base - half, np.nan)], axis=-1)
        return wrap_pi(roots)

    @staticmethod
    def _intervals(bounds, pref):
        """The circular intervals between boundary angles.

        Args:
            bounds: Shape S + (K,) [rad], NaN-padded.
            pref: Shape S [rad].

        Returns:
            start, end, valid (S + (K,)): interval j runs from the j-th smallest boundary to the
            next (the last one to the first + 2 pi); without boundaries, one interval, the whole
            circle centred on `pref`.
        """
        b = np.sort(bounds, axis=-1)
        k = b.shape[-1]
        count = np.sum(np.isfinite(b), axis=-1)[..., None]
        j = np.arange(k)
        following = np.concatenate([b[..., 1:], b[..., :1]], axis=-1)
        end = np.where(j == count - 1, b[..., :1] + TWO_PI, following)
        whole = (count == 0) & (j == 0)
        start = np.where(whole, pref[..., None] - PI, b)
        end = np.where(whole, pref[..., None] + PI, end)
        return start, end, (j < count) | whole

    def _phi_choices(self, pos, qc, roll_free, margin):
        """Per branch, the in-plane end angle within the limits nearest the default one.

        For position-only targets on wristed arms, on the ideal model.

        Returns:
            feasible (n, 4): some end angle puts the branch within the limits; phi (n, 4) [rad]:
            the default angle where it does, else the nearest end of the nearest interval that
            does, moved `margin` (at most half the interval) into it; phi_mid (n, 4) [rad]: the
            default angle or the middle of that interval. NaN where not feasible.
        """
        n = pos.shape[0]
        core = self._core(pos, None, None, qc, self._orient_tol, roll_free=roll_free)
        pref = np.nan_to_num(core["phi"])
        bounds = self._phi_boundaries(core["ue"], core["ze"], core["tu"], core["tz"])
        start, end, valid = self._intervals(bounds, pref)
        if self.exact:
            # The boundaries themselves too, as intervals of zero width: where a joint's extreme
            # value just meets its limit, the one point there may be all there is. (Inexact
            # chains keep only intervals wide enough for the real arm to share.)
            start = np.concatenate([start, bounds], axis=-1)
            end = np.concatenate([end, bounds], axis=-1)
            valid = np.concatenate([valid, np.isfinite(bounds)], axis=-1)
        mid = 0.5 * (start + end)
        k = start.shape[-1]

        def rep(a):
            return None if a is None else np.repeat(a, k, axis=0)

        sub = self._core(
            rep(pos), None, None, rep(qc), self._orient_tol,
            phi_free=np.where(valid, mid, 0.0).transpose(0, 2, 1).reshape(n * k, 2), roll_free=rep(roll_free),
        )  # fmt: skip
        side = [0, 0, 1, 1]
        ok = self._within_ideal(sub, rep(pos), rep(qc)).reshape(n, k, 4).transpose(0, 2, 1) & valid[:, side]
        start, end, mid, pref = start[:, side], end[:, side], mid[:, side], pref[:, side]
        width = end - start
        if not self.exact:
            ok &= width >= 2.0 * margin  # narrower, the real arm may have none
        inset = np.minimum(margin, 0.5 * width)
        # The point of each interval nearest pref (at least `inset` inside it), unwrapped near pref.
        shifted = start + (pref[..., None] - start) % TWO_PI
        near = np.where(
            shifted <= end,
            np.clip(shifted, start + inset, end - inset),
            np.where(shifted - end <= start + TWO_PI - shifted, end - inset, start + inset + TWO_PI),
        )
        dist = np.where(ok, np.abs(near - shifted), np.inf)
        best = np.argmin(dist, axis=-1)[..., None]
        feasible = np.isfinite(np.take_along_axis(dist, best, axis=-1)[..., 0])
        phi = wrap_pi(np.take_along_axis(near, best, axis=-1)[..., 0])
        inside = np.take_along_axis(shifted <= end, best, axis=-1)[..., 0]
        phi_mid = np.where(inside, phi, wrap_pi(np.take_along_axis(mid, best, axis=-1)[..., 0]))
        return feasible, np.where(feasible, phi, np.nan), np.where(feasible, phi_mid, np.nan)

    def _search(self, pos, pit, qc, roll_step: float = math.radians(2.5)):
        """Free joint values that put each branch within the limits, per target (ideal model).

        The wrist roll, where it moves the tip: q_current's (else 0) when some end angle (or, for
        pitch targets, the target itself) allows the branch there, else the nearest roll that
        does: sampled every `roll_step` outwards, then bisected to the boundary. The in-plane end
        angle of position-only targets: see `_phi_choices`.

        Returns:
            found (n, 4); phi, roll (n, 4): the nearest values [rad] (NaN where not free or not
            found); phi_safe, roll_safe (n, 4): values further inside (the middle of the end
            angle's interval, the roll sample), for inexact chains whose real joints may differ
            from the ideal ones at a boundary.
        """
        free_phi, free_roll = self._free_joints(pit, None)
        n = pos.shape[0]
        # Steps into the intervals with solutions, past their ends: within round-off on exact
        # chains; on inexact ones, past the ideal model's deviation from the real one.
        margin = 1e-9 if self.exact else 1e-4
        margin_roll = 1e-3
        nan4 = np.full((n, 4), np.nan)

        def oracle(rows, roll):
            q_rows = None if qc is None else qc[rows]
            if free_phi:
                return self._phi_choices(pos[rows], q_rows, roll, margin)
            core = self._core(pos[rows], None if pit is None else pit[rows], None, q_rows, self._orient_tol,
                              roll_free=roll)  # fmt: skip
            ok = self._within_ideal(core, pos[rows], q_rows)
            return ok, np.full(ok.shape, np.nan), np.full(ok.shape, np.nan)

        roll0 = None
        if free_roll:
            lo, hi = self._lower[self._roll_idx], self._upper[self._roll_idx]
            bounded = hi - lo < TWO_PI
            roll0 = self._roll_values(n, qc, None)
            if bounded:
                roll0 = np.clip(roll0, lo, hi)
        found, phi, phi_safe = oracle(np.arange(n), roll0)
        roll = nan4.copy() if roll0 is None else np.repeat(roll0[:, None], 4, axis=1)
        roll_safe = roll.copy()
        pending = ~found
        if not free_roll or not pending.any():
            return found, phi, roll, phi_safe, roll_safe
        # Roll samples outwards from roll0: k steps up, then k steps down, k = 1, 2, ...
        steps = int(math.ceil((hi - lo if bounded else TWO_PI) / roll_step))
        inner = np.full((n, 4), np.nan)
        first = 1
        while first <= steps:
            # A few steps first (often enough), then all the others at once (cheaper than many calls).
            ks = np.arange(first, min(first + 4, steps + 1) if first == 1 else steps + 1)
            first = ks[-1] + 1
            offsets = np.stack([ks, -ks], axis=1).ravel() * roll_step  # (m,)
            samples = roll0[:, None] + offsets
            previous = roll0[:, None] + offsets - np.sign(offsets) * roll_step
            if bounded:
                usable = (previous > lo) & (previous < hi) | (np.abs(previous - roll0[:, None]) < 1e-15)
                usable &= (previous >= lo) & (previous <= hi)
                samples = np.clip(samples, lo, hi)
            else:
                usable = np.ones(samples.shape, dtype=bool)
            targets = np.nonzero(pending.any(axis=1))[0]
            if targets.size == 0:
                break
            m = offsets.size
            rows = np.repeat(targets, m)
            ok, ph, ph_mid = oracle(rows, samples[targets].ravel())
            ok = ok.reshape(targets.size, m, 4) & usable[targets][..., None]
            for a, i in enumerate(targets):
                for s in np.nonzero(pending[i])[0]:
                    hit = np.nonzero(ok[a, :, s])[0]
                    if hit.size:
                        h = hit[0]
                        found[i, s], pending[i, s] = True, False
                        roll[i, s] = roll_safe[i, s] = samples[i, h]
                        phi[i, s], phi_safe[i, s] = ph[a * m + h, s], ph_mid[a * m + h, s]
                        inner[i, s] = np.clip(previous[i, h], lo, hi) if bounded else previous[i, h]
        # Bisect between the last roll without and the first with a solution, nearest roll0; on
        # inexact chains, then step a little back into the rolls with one (towards the sample).
        pairs = np.nonzero(np.isfinite(inner))
        if pairs[0].size:
            bad, good = inner[pairs].copy(), roll[pairs].copy()
            sample = good.copy()
            # 15 rolls between per round, the bracket 16 times shorter each: to 3e-9 rad on exact
            # chains, on inexact ones to well within the step back.
            parts = 16
            fractions = np.arange(1, parts) / parts
            index = np.arange(len(bad))
            for _ in range(6 if self.exact else 2):
                trial = bad[:, None] + (good - bad)[:, None] * fractions  # (p, parts - 1)
                ok = oracle(np.repeat(pairs[0], parts - 1), trial.ravel())[0]
                hit = ok[np.arange(trial.size), np.repeat(pairs[1], parts - 1)].reshape(trial.shape)
                # The first trial with a solution (from the bad end): the bracket ends there.
                k = np.where(hit.any(axis=1), np.argmax(hit, axis=1), parts - 1)
                good = np.where(k < parts - 1, trial[index, np.minimum(k, parts - 2)], good)
                bad = np.where(k > 0, trial[index, np.maximum(k - 1, 0)], bad)
            if not self.exact:
                good = good + np.clip(sample - good, -margin_roll, margin_roll)
            ok, ph, _ = oracle(pairs[0], good)
            hit = ok[np.arange(len(good)), pairs[1]]
            roll[pairs] = np.where(hit, good, roll[pairs])
            phi[pairs] = np.where(hit, ph[np.arange(len(good)), pairs[1]], phi[pairs])
        return found, phi, roll, phi_safe, roll_safe

    def _solve_searched(self, pos, pit, qc, base, orientation_errors: bool = True):
        """`_solve_arrays`' result `base`, re-solved at free joint values within the limits.

        For the targets without a solution within the limits, each branch at the values `_search`
        finds. Branches the search finds nothing for keep their solution at the default values.
        """
        todo = np.nonzero(base["status"] != STATUS_CODES[STATUS_SOLVED])[0]
        if todo.size == 0:
            return base
        sub_pit = None if pit is None else pit[todo]
        sub_qc = None if qc is None else qc[todo]
        found, phi, roll, phi_safe, roll_safe = self._search(pos[todo], sub_pit, sub_qc)
        if not found.any():
            return base
        m = todo.size
        slots = np.tile(np.arange(4), m)
        use = np.zeros((m, 4), dtype=bool)
        chosen = None
        for phi_s, roll_s in ((phi, roll), (phi_safe, roll_safe)):
            retry = found & ~use
            if not retry.any():
                break
            phi_rows = np.full((4 * m, 2), np.nan)
            phi_rows[np.arange(4 * m), slots // 2] = phi_s.ravel()
            a = self._solve_arrays(
                np.repeat(pos[todo], 4, axis=0), None if sub_pit is None else np.repeat(sub_pit, 4),
                None, None if sub_qc is None else np.repeat(sub_qc, 4, axis=0), orientation_errors,
                phi_free=phi_rows, roll_free=roll_s.ravel(),
            )  # fmt: skip
            a = {key: _diagonal(value, m) for key, value in a.items() if key not in ("status", "best")}
            ok = retry & a["within"]
            if chosen is None:
                chosen = {key: None if value is None else value.copy() for key, value in a.items()}
            else:
                for key, value in a.items():
                    if value is not None:
                        chosen[key][ok] = value[ok]
            use |= ok
        if not use.any():
            return base
        out = {key: (value.copy() if isinstance(value, np.ndarray) else value) for key, value in base.items()}
        for key, value in chosen.items():
            if value is not None and out.get(key) is not None:
                part = out[key][todo]
                part[use] = value[use]
                out[key][todo] = part
        rows = out["q"][todo]
        status = self._status_codes(out["cat"][todo], out["valid"][todo], out["within"][todo], out["dist"][todo])
        out["status"][todo] = status
        if sub_qc is not None:
            dist2 = np.sum((rows - sub_qc[:, None, :]) ** 2, axis=-1)
        else:
            dist2 = np.broadcast_to(np.arange(4.0), (m, 4))
        within = out["within"][todo]
        out["best"][todo] = np.where(within.any(axis=1), np.argmin(np.where(within, dist2, np.inf), axis=1), -1)
        return out

    # ------------------------------------------------------------------ arrays -> result
    def _result_from_arrays(self, a, i, target, qc) -> AnalyticResult:
        sols = []
        details = []
        for slot in range(4):
            if not a["valid"][i, slot]:
                continue
            arr = read_only(a["q"][i, slot])
            oerr = None if a["oerr"] is None else float(a["oerr"][i, slot])
            sol = AnalyticSolution(
                arr,
                bool(a["within"][i, slot]),
                BRANCHES[slot],
                bool(a["singular"][i, slot]),
                float(a["perr"][i, slot]),
                oerr,
            )
            sols.append(sol)
            details.append((slot, sol))
        if qc is not None and len(sols) > 1:
            sols.sort(key=lambda s: float(np.sum((s.q - np.asarray(qc)) ** 2)))
        cats = a["cat"][i].tolist()
        dist = a["dist"][i].tolist()
        status, reason = self._status_and_reason(cats, dist, details, target, self.joint_names, qc)
        return AnalyticResult(status, reason, tuple(sols), any(s.singular for s in sols))


def _orthonormalize(r: np.ndarray) -> np.ndarray:
    """Nearest rotation matrices (polar decomposition by SVD), shape (..., 3, 3)."""
    u, _, vt = np.linalg.svd(r)
    out = u @ vt
    det = np.linalg.det(out)
    u[..., :, 2] *= np.where(det < 0, -1.0, 1.0)[..., None]
    return u @ vt


def _diagonal(a, m):
    """Branch s of row 4 i + s, from arrays over 4 m rows and 4 branches: shape (m, 4, ...).

    None stays None.
    """
    if a is None:
        return None
    a = a.reshape((m, 4) + a.shape[1:])
    k = np.arange(4)
    return a[:, k, k]


@dataclass(frozen=True)
class ChainLayout:
    """A chain split into the family's joints.

    Attributes:
        yaw: The base yaw joint.
        pitch: The 2 or 3 parallel pitch joints.
        roll: The wrist roll joint, or None.
        deviation: Largest angle [rad] of the axes from the family's ideal directions.
    """

    yaw: JointScrew
    pitch: tuple[JointScrew, ...]
    roll: JointScrew | None
    deviation: float


def chain_layout(chain: ChainAtZero) -> ChainLayout | ChainMismatch:
    """Split a chain into base yaw, pitch joints and wrist roll, or say why it does not fit.

    Args:
        chain: The chain at q = 0.

    Returns:
        The layout, or the mismatch naming the first joint that breaks the family.
    """
    common = base_yaw_mismatch(chain)
    if common is not None:
        return common
    joints = chain.joints
    z = np.array([0.0, 0.0, 1.0])
    yaw = joints[0]
    if angle_to_line(joints[1].axis, yaw.axis) <= FAMILY_ANGLE_TOL:
        return ChainMismatch(
            f"joint {joints[1].name!r} turns about the vertical like the base yaw {yaw.name!r}: a planar arm, "
            "not a pitch joint after the base yaw",
            joints[1].name,
            1,
        )
    deviation = angle_to_line(yaw.axis, z)
    n_raw = joints[1].axis
    off = angle_to_plane(n_raw, z)
    if off > FAMILY_ANGLE_TOL:
        return ChainMismatch(
            f"joint {joints[1].name!r} turns about {np.round(n_raw, 6).tolist()}, neither vertical "
            "(a planar 2-link) nor horizontal (a pitch joint after the base yaw)",
            joints[1].name,
            1,
        )
    deviation = max(deviation, off)
    pitch = [joints[1]]
    k = 2
    while k < len(joints) and angle_to_line(joints[k].axis, n_raw) <= FAMILY_ANGLE_TOL:
        deviation = max(deviation, angle_to_line(joints[k].axis, n_raw))
        pitch.append(joints[k])
        k += 1
    if len(pitch) > 3:
        return ChainMismatch(
            f"joint {pitch[3].name!r} is a fourth parallel pitch joint; the family has 2 or 3 "
            "(more make the arm's plane redundant)",
            pitch[3].name,
            4,
        )
    if len(pitch) < 2:
        bad = joints[k] if k < len(joints) else joints[1]
        return ChainMismatch(
            f"joint {bad.name!r} "
            + ("is not parallel to the first pitch joint" if k < len(joints) else "ends the chain")
            + f" after a single pitch joint {joints[1].name!r}; the family needs 2 or 3 parallel pitch joints",
            bad.name,
            2,
        )
    roll = None
    if k < len(joints):
        cand = joints[k]
        perp = angle_to_plane(cand.axis, n_raw)
        if perp > FAMILY_ANGLE_TOL:
            return ChainMismatch(
                f"joint {cand.name!r} turns about {np.round(cand.axis, 6).tolist()}, neither parallel "
                "to the pitch axes nor perpendicular to them (a wrist roll)",
                cand.name,
                k,
            )
        deviation = max(deviation, perp)
        roll = cand
        k += 1
    if k < len(joints):
        return ChainMismatch(
            f"joint {joints[k].name!r} follows the wrist roll {roll.name!r}; the family ends there "
            "(base yaw, 2 or 3 pitch joints, optional wrist roll)",
            joints[k].name,
            k,
        )
    return ChainLayout(yaw, tuple(pitch), roll, deviation)
