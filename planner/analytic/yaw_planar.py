"""Base yaw + 2 or 3 parallel pitch joints + optional wrist roll, in closed form.

The family of the 001 (AL5C), 002 (three-joint coursework) and 004 (DH arm) seeds and of the
SO-101: the first joint turns about the vertical, the next 2 or 3 about parallel horizontal
axes (the arm's plane is perpendicular to them), and an optional last joint rolls about an
axis in that plane.

Geometry, all read from the Pinocchio model at q = 0 (:mod:`planner.analytic.chain`):

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

- ``pitch``: the approach axis in the arm's vertical plane at `pitch` from the horizontal
  (``planner.target`` convention; "radially away" is away from the yaw axis along the arm's
  plane, which for arms whose yaw axis is the base z axis and without sideways offset is
  exactly the convention). On arms without a wrist pitch (2 pitch joints) the pitch fixes the
  last link: the elbow is the end point minus that link and the shoulder points at it (one
  solution per side, kept if the shoulder link then fits to 1e-9 of the arm's size).
- ``rotation``: the yaw from the rotation (the azimuth of the pitch axis, or of the roll axis
  unless that is vertical) where it fixes the yaw better than the position (whose hold on it
  weakens as the end point nears the yaw axis), the position then checked to lie in that
  plane; the pitch sum and the roll from the rotation. Arms without roll or without wrist
  pitch keep only the branches the rotation allows.
- position only: arms without a wrist pitch solve it directly. Arms with one are redundant:
  the approach pitch is ``q_current``'s when given and reachable, else the wrist centre is put
  on the line from the shoulder to the target (straight out) or, when that is too close, at the
  nearest reachable distance, approaching from above. If no solution at that pitch lies within
  the joint limits, :meth:`YawPlanarIK.solve` tries the nearest approach pitches on a 5-degree
  grid (``solve_batch`` does not).

A free wrist roll (no rotation given) takes ``q_current``'s value, else 0; a free yaw (the end
point on the yaw axis) takes ``q_current``'s, else 0, and the solution is flagged singular.

Chains whose axes deviate from the ideal directions by round-off (up to
:data:`~planner.analytic.base.FAMILY_ANGLE_TOL`, e.g. SO-101's URDF, a few micro-radians) are
solved on the ideal geometry and then corrected on the real one (product of exponentials):
each branch is re-solved for the target shifted by the error it left, which converges by about
the deviation per round, and branches that do not settle (next to a stretched elbow) are
finished by damped Gauss-Newton steps. Only branches that then reproduce the target (1e-10 m,
1e-9 rad) are returned.

Speed: :meth:`YawPlanarIK.solve` runs position and pitch targets on exact chains in scalar
arithmetic (tens of microseconds); rotation targets and inexact chains go through the
vectorised path (hundreds of microseconds for one target). ``solve_batch`` is vectorised over
targets (in slices of 16384 to stay in cache).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..exceptions import UnsupportedChainError
from ..robot import Robot
from ..target import Target, rotation_error
from .base import FAMILY_ANGLE_TOL, AnalyticIK, _angle_to_line, _angle_to_plane
from .chain import ChainAtZero, describe_violation, poe_fk, rotation_about, wrap_array, wrap_scalar
from .result import (
    STATUS_BEYOND_MAX_REACH,
    STATUS_CODES,
    STATUS_INSIDE_MIN_REACH,
    STATUS_OK,
    STATUS_ORIENTATION_NOT_ACHIEVABLE,
    STATUS_OUTSIDE_JOINT_LIMITS,
    AnalyticBatchResult,
    AnalyticResult,
    AnalyticSolution,
)

__all__ = ["YawPlanarIK", "BRANCHES"]

PI = math.pi
TWO_PI = 2.0 * math.pi

#: Branch names in batch order.
BRANCHES = ("front/elbow-up", "front/elbow-down", "back/elbow-up", "back/elbow-down")

#: A stretched/folded elbow with |sin| below this is set exactly singular (the position changes
#: by its square only); also the relative distance to the yaw axis flagged singular.
SINGULAR_TOL = 1e-7
#: Relative (to the arm's size) length tolerance: reach round-off, the yaw axis.
LENGTH_TOL = 1e-12
#: Orientation residual [rad] up to which an asked orientation counts as achieved.
ORIENTATION_TOL = 1e-7
#: Deviation [rad] below which a chain is treated as exactly of the family.
EXACT_TOL = 1e-12

# Per-branch failure categories (internal).
_VALID, _BEYOND, _INSIDE, _CYLINDER, _ORIENT, _DUPLICATE = range(6)


def _wrap_pi(x):
    """Angle(s) wrapped into [-pi, pi)."""
    return (x + PI) % TWO_PI - PI


def _reach_interval(l1: float, l2, delta, lo: float, hi: float, sign: float):
    """Reach bounds of a 2-link whose relative angle is ``sign * q + delta``, q in [lo, hi].

    Returns (r_min, r_max) [m] (arrays if l2/delta are arrays).
    """
    a, b = sorted((sign * lo, sign * hi))
    width = b - a
    e_lo = np.asarray(a + delta, dtype=float)
    e_hi = np.asarray(b + delta, dtype=float)
    if not math.isfinite(width) or width >= TWO_PI:
        cmax = np.ones_like(e_lo)
        cmin = -np.ones_like(e_lo)
    else:
        has_zero = np.floor(e_hi / TWO_PI) >= np.ceil(e_lo / TWO_PI)
        has_pi = np.floor((e_hi - PI) / TWO_PI) >= np.ceil((e_lo - PI) / TWO_PI)
        ends_max = np.maximum(np.cos(e_lo), np.cos(e_hi))
        ends_min = np.minimum(np.cos(e_lo), np.cos(e_hi))
        cmax = np.where(has_zero, 1.0, ends_max)
        cmin = np.where(has_pi, -1.0, ends_min)
    base = l1 * l1 + l2 * l2
    r_max = np.sqrt(np.maximum(base + 2 * l1 * l2 * cmax, 0.0))
    r_min = np.sqrt(np.maximum(base + 2 * l1 * l2 * cmin, 0.0))
    return r_min, r_max


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
    def _detect(self, chain: ChainAtZero) -> None:
        name = self.robot.name
        joints = chain.joints
        z = np.array([0.0, 0.0, 1.0])
        yaw = joints[0]
        deviation = _angle_to_line(yaw.axis, z)
        n_raw = joints[1].axis
        off = _angle_to_plane(n_raw, z)
        if off > FAMILY_ANGLE_TOL:
            raise UnsupportedChainError(
                f"{name}: joint {joints[1].name!r} turns about {np.round(n_raw, 6).tolist()}, neither vertical "
                "(a planar 2-link) nor horizontal (a pitch joint after the base yaw)",
                joint=joints[1].name,
            )
        deviation = max(deviation, off)
        pitch = [joints[1]]
        k = 2
        while k < len(joints) and _angle_to_line(joints[k].axis, n_raw) <= FAMILY_ANGLE_TOL:
            deviation = max(deviation, _angle_to_line(joints[k].axis, n_raw))
            pitch.append(joints[k])
            k += 1
        if len(pitch) > 3:
            raise UnsupportedChainError(
                f"{name}: joint {pitch[3].name!r} is a fourth parallel pitch joint; the family has 2 or 3 "
                "(more make the arm's plane redundant)",
                joint=pitch[3].name,
            )
        if len(pitch) < 2:
            bad = joints[k] if k < len(joints) else joints[1]
            raise UnsupportedChainError(
                f"{name}: joint {bad.name!r} "
                + ("is not parallel to the first pitch joint" if k < len(joints) else "ends the chain")
                + f" after a single pitch joint {joints[1].name!r}; the family needs 2 or 3 parallel pitch joints",
                joint=bad.name,
            )
        roll = None
        if k < len(joints):
            cand = joints[k]
            perp = _angle_to_plane(cand.axis, n_raw)
            if perp > FAMILY_ANGLE_TOL:
                raise UnsupportedChainError(
                    f"{name}: joint {cand.name!r} turns about {np.round(cand.axis, 6).tolist()}, neither parallel "
                    "to the pitch axes nor perpendicular to them (a wrist roll)",
                    joint=cand.name,
                )
            deviation = max(deviation, perp)
            roll = cand
            k += 1
        if k < len(joints):
            raise UnsupportedChainError(
                f"{name}: joint {joints[k].name!r} follows the wrist roll {roll.name!r}; the family ends there "
                "(base yaw, 2 or 3 pitch joints, optional wrist roll)",
                joint=joints[k].name,
            )
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
        in_plane = _angle_to_plane(a0, n) <= FAMILY_ANGLE_TOL
        along_roll = roll is None or _angle_to_line(a0, self._r0) <= FAMILY_ANGLE_TOL
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
            rmin, rmax = _reach_interval(
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
        result = self._solve_one(target, qc)
        if target.kind == "position" and self.n_pitch == 3 and not result.ok:
            return self._search_pitch(target, qc) or result
        return result

    def _solve_one(self, target: Target, qc: list[float] | None) -> AnalyticResult:
        if self.exact and target.rotation is None:
            return self._solve_scalar(target, qc)
        pos = np.asarray(target.position, dtype=float)[None, :]
        pit = None if target.pitch is None else np.array([target.pitch])
        rot = None if target.rotation is None else np.asarray(target.rotation)[None]
        qca = None if qc is None else np.asarray(qc)[None, :]
        arrays = self._solve_arrays(pos, pit, rot, qca)
        return self._result_from_arrays(arrays, 0, target, qc)

    def _search_pitch(self, target: Target, qc: list[float] | None) -> AnalyticResult | None:
        """The nearest grid pitch that puts a position-only target within the limits, or None.

        For wristed arms whose chosen approach pitch gives no solution within the joint limits;
        the grid has 5-degree steps.
        """
        ref = 0.0
        if qc is not None:
            ref = float(self._current_alpha(np.asarray([qc]))[0])
        grid = np.radians(np.arange(-175.0, 181.0, 5.0))
        for pitch in sorted(grid.tolist(), key=lambda p: abs(_wrap_pi(p - ref))):
            res = self._solve_one(Target(target.position, pitch=pitch), qc)
            if res.ok:
                sols = tuple(s._replace(orientation_error=None) for s in res.solutions)
                return AnalyticResult(res.status, "", sols, res.singular)
        return None

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
            return self._solve_arrays(pos, pit, rot, qc, orientation_errors=False)
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
            part = self._solve_arrays(
                pos[sl], None if pit is None else pit[sl], None if rot is None else rot[sl],
                None if qc is None else qc[sl], orientation_errors=False,
            )
            for key, arr in out.items():
                arr[sl] = part[key]
        return out

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
            if three:
                l2, g2 = self._l2, self._g2
                if pitch is not None:
                    phi = (pitch if side == 0 else PI - pitch) - beta
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
                phi = (pitch if side == 0 else PI - pitch) - beta
                cp, sp = cos(phi), sin(phi)
                ex = ue - (cp * tu - sp * tz) - su
                ez = pz - (sp * tu + cp * tz) - sz
                if abs(hypot(ex, ez) - l1) > self._consistency_tol:
                    cats[2 * side] = cats[2 * side + 1] = _ORIENT
                    continue
                a1 = atan2(ez, ex)
                e = _wrap_pi(phi + g2 - a1)
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
            cy, sy = cos(psi + mu), sin(psi + mu)
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
                    oerr = abs(_wrap_pi(beta + f4 - (pitch if side == 0 else PI - pitch)))
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
            arr = np.array(q)
            arr.setflags(write=False)
            sol = AnalyticSolution(arr, within, BRANCHES[slot], singular, perr, oerr)
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
            return STATUS_OK, ""
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
            got = []
            for sol in plain:
                alpha = self._beta + sum(s * sol.q[i] for s, i in zip(self._signs, self._pitch_idx))
                got.append(math.degrees(_wrap_pi(alpha if sol.branch.startswith("front") else PI - alpha)))
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
    def _end_geometry(self, n, rot, qc):
        """Per-target end vector (tu, tz), lateral offset d, end-point shift, roll value."""
        if self.has_roll and rot is not None:
            tu, tz, d = self._centre
            shift = -np.einsum("nij,j->ni", rot, self._centre_to_tip_local)
            return np.full(n, tu), np.full(n, tz), np.full(n, d), shift, None
        roll = None
        if self.has_roll:
            roll = qc[:, self._roll_idx] if qc is not None else np.zeros(n)
        if self._tip_on_roll_axis:
            tu, tz, d = self._tip_fixed
            return np.full(n, tu), np.full(n, tz), np.full(n, d), None, roll
        cr, sr = np.cos(roll), np.sin(roll)
        tu = self._tip0[0] + self._tipc[0] * cr + self._tips[0] * sr
        tz = self._tip0[1] + self._tipc[1] * cr + self._tips[1] * sr
        d = self._tip0[2] + self._tipc[2] * cr + self._tips[2] * sr
        return tu, tz, d, None, roll

    def _core(self, pos, pit, rot, qc, orient_tol):
        """The ideal-geometry closed form for N targets; returns a dict of (N, 4) arrays."""
        n = pos.shape[0]
        dof = self.dof
        three = self.n_pitch == 3
        tu, tz, d, shift, roll = self._end_geometry(n, rot, qc)
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
        ze2 = np.broadcast_to(ze[:, None], (n, 2))
        tu2, tz2 = tu[:, None], tz[:, None]
        roll_q = None if roll is None else np.broadcast_to(roll[:, None], (n, 2))
        phi = None
        orient_res = np.zeros((n, 2))
        if three:
            l2, g2 = self._l2, self._g2
            if pit is not None:
                # phi = alpha - beta with alpha = pitch (front) or pi - pitch (back).
                phi = np.stack([pit - self._beta, PI - pit - self._beta], axis=1)
                cpb, spb = np.cos(pit + self._beta), np.sin(pit + self._beta)
                cmb, smb = np.cos(pit - self._beta), np.sin(pit - self._beta)
                cp, sp = np.stack([cmb, -cpb], axis=1), np.stack([smb, spb], axis=1)
            elif rot is not None:
                phi, roll_q, orient_res = self._pitch_from_rotation(m_rot, psi)
                cat = np.where((cat == _VALID) & (orient_res > orient_tol), _ORIENT, cat)
            else:
                phi, fail = self._free_pitch_array(psi, ue, ze2, tu2, tz2, qc)
                cat = np.where((cat == _VALID) & (fail != _VALID), fail, cat)
            if pit is None:
                cp, sp = np.cos(phi), np.sin(phi)
            wu = ue - (cp * tu2 - sp * tz2)
            wz = ze2 - (sp * tu2 + cp * tz2)
        else:
            if pit is not None or rot is not None:
                return self._core_two_oriented(
                    pit, m_rot, psi, ue, ze2, tu, tz, d, cat, free | seeded, roll_q, end, orient_tol
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
        a1 = np.stack([base[:, 0] + half[:, 0], base[:, 0] - half[:, 0], base[:, 1] - half[:, 1],
                       base[:, 1] + half[:, 1]], axis=1)
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
        singular = (
            elbow_sing[:, rep] | (free | seeded)[:, None] | (np.abs(ue[:, rep]) < SINGULAR_TOL * self._scale)
        )
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
        }

    def _core_two_oriented(self, pit, m_rot, psi, ue, ze2, tu, tz, d, cat, free, roll_q, end, orient_tol):
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
        if pit is not None:
            phi = np.stack([pit - self._beta, PI - pit - self._beta], axis=1)
        else:
            phi, _, residual = self._pitch_from_rotation(m_rot, psi)
            cat = np.where((cat == _VALID) & (residual > orient_tol), _ORIENT, cat)
        cp, sp = np.cos(phi), np.sin(phi)
        ex = ue - (cp * tu2 - sp * tz2) - su
        ez = ze2 - (sp * tu2 + cp * tz2) - sz
        tol = max(self._consistency_tol, len_tol)
        cat = np.where((cat == _VALID) & (np.abs(np.hypot(ex, ez) - l1) > tol), _ORIENT, cat)
        a1 = np.arctan2(ez, ex)
        e = _wrap_pi(phi + g2 - a1)
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
        a = rot @ self._approach_local
        yaw = self._mu + self._sigma * qc[:, 0]
        return np.arctan2(a[:, 2], np.cos(yaw) * a[:, 0] + np.sin(yaw) * a[:, 1])

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

    def _solve_arrays(self, pos, pit, rot, qc, orientation_errors: bool = True):
        """Solve N targets: ideal closed form, correction when inexact, limits, status."""
        n = pos.shape[0]
        core = self._core(pos, pit, rot, qc, self._orient_tol)
        q = core["q"]
        cat = core["cat"]
        oerr = None
        if self.exact and rot is None:
            perr = self._ideal_position_error(core, pos)
            if pit is not None and orientation_errors:
                oerr = self._pitch_error(q, pit)
        else:
            q, cat, perr, oerr = self._refine(core, pos, pit, rot, qc)
        valid = cat == _VALID
        # Wrap into the joint ranges, nearest q_current.
        within = valid.copy()
        # A free roll copied from q_current (or 0 inside its range) needs no wrapping.
        copied_roll = False
        if self.has_roll and rot is None:
            lo, hi = self._lower[self._roll_idx], self._upper[self._roll_idx]
            roll = qc[:, self._roll_idx] if qc is not None else np.zeros(1)
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

    def _pitch_error(self, q, pit):
        sg, idx = self._signs, self._pitch_idx
        total = sum(s * q[..., i] for s, i in zip(sg, idx))
        alpha = self._beta + total
        target = np.stack([pit, pit, PI - pit, PI - pit], axis=1)
        return np.abs(_wrap_pi(alpha - target))

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
        return np.where(any_within, STATUS_CODES[STATUS_OK], status)

    # ------------------------------------------------------------------ correction on the real geometry
    def _refine(self, core, pos, pit, rot, qc, max_rounds: int = 8):
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
        pitch_t = None if pit is None else np.stack([pit, pit, pit, pit], axis=1)
        # The approach pitch each branch must keep: the target's, or for a position-only target
        # the one chosen for it (q_current's, measured on the real arm, or the default rule's).
        pitch_eff = pitch_goal = None
        if self.n_pitch == 3 and rot is None:
            pitch_goal = (pitch_t if pitch_t is not None else branch_pitch).copy()
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
            oerr = self._orientation_errors(q, fk_r, pit, rot)
            settled = perr <= settle_tol
            if oerr is not None:
                settled &= oerr <= 1e-13
            if pitch_goal is not None and not self.exact:
                true_pitch = self._true_pitch(q, fk_r)
                settled &= np.abs(_wrap_pi(true_pitch - pitch_goal)) <= 1e-13
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
                pitch_eff = pitch_eff + _wrap_pi(pitch_goal - true_pitch)
            sub = self._core(
                p_eff.reshape(-1, 3),
                None if pitch_eff is None else pitch_eff.reshape(-1),
                None if rot_eff is None else rot_eff.reshape(-1, 3, 3),
                None if qc4 is None else qc4.reshape(-1, self.dof),
                self._orient_tol,
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
                oerr = self._orientation_errors(q, fk_r, pit, rot)
        ok = perr <= pos_tol
        if oerr is not None:
            ok &= oerr <= (1e-9 if not self.exact else self._orient_tol)
        if not self.exact:
            # Branches that converged onto one solution (a singular target): keep the first.
            for a, b in ((0, 1), (2, 3), (0, 2), (0, 3), (1, 2), (1, 3)):
                both = (valid[:, a] & ok[:, a]) & (valid[:, b] & ok[:, b])
                twin = both & (np.max(np.abs(_wrap_pi(q[:, a] - q[:, b])), axis=-1) < 1e-7)
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
                parts.append(0.5 * np.stack([rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0],
                                             rel[:, 1, 0] - rel[:, 0, 1]], axis=-1))
            elif pit is not None and self.n_pitch == 3:
                qq4 = np.repeat(qq[:, None, :], 4, axis=1)
                rr4 = np.repeat(fk_r[:, None], 4, axis=1)
                got = self._true_pitch(qq4, rr4)[np.arange(len(qq)), front4]
                parts.append(_wrap_pi(got - pit)[:, None])
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
        """World approach pitch per branch (front: alpha, back: pi - alpha) of the real tip."""
        a = fk_r @ self._approach_local
        yaw = self._mu + self._sigma * q[..., 0]
        horiz = np.cos(yaw) * a[..., 0] + np.sin(yaw) * a[..., 1]
        alpha = np.arctan2(a[..., 2], horiz)
        return np.where(np.array([True, True, False, False]), alpha, PI - alpha)

    def _orientation_errors(self, q, fk_r, pit, rot):
        if rot is not None:
            return np.asarray(rotation_error(fk_r, np.broadcast_to(rot[:, None], fk_r.shape)))
        if pit is not None:
            target = np.stack([pit, pit, pit, pit], axis=1)
            return np.abs(_wrap_pi(self._true_pitch(q, fk_r) - target))
        return None

    # ------------------------------------------------------------------ arrays -> result
    def _result_from_arrays(self, a, i, target, qc) -> AnalyticResult:
        sols = []
        details = []
        for slot in range(4):
            if not a["valid"][i, slot]:
                continue
            arr = np.array(a["q"][i, slot])
            arr.setflags(write=False)
            oerr = None if a["oerr"] is None else float(a["oerr"][i, slot])
            sol = AnalyticSolution(
                arr, bool(a["within"][i, slot]), BRANCHES[slot], bool(a["singular"][i, slot]),
                float(a["perr"][i, slot]), oerr,
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
