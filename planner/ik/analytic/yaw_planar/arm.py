"""The yaw-planar arm's geometry, read from its chain at q = 0 (:class:`ArmGeometry`).

All read from the Pinocchio model (:mod:`planner.geometry.chain`):

- the yaw axis: a vertical line through ``b`` (it need not pass through the base origin);
- the arm plane: unit pitch axis ``n`` (horizontal), in-plane horizontal ``e_u = z x n``;
  a pitch joint turning by ``q_i`` turns the plane's (u, z) coordinates by ``s_i q_i``
  (``s_i = +-1``: Sumadsad's (2020) alpha = 180 deg link flips the second pitch axis, s = -1);
- in-plane link vectors between the pitch joints (any in-plane offsets), and the end
  vector from the last pitch joint to the end point, which is the tip, or the wrist roll
  centre when a full orientation fixes the roll;
- the end point's sideways (``n``) offset ``d`` from the yaw axis, constant under the pitch
  joints: the arm's plane passes at distance ``|d|`` from the yaw axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.core.arrays import read_only
from planner.geometry.chain import ChainAtZero
from planner.ik.analytic.base import FAMILY_ANGLE_TOL
from planner.ik.analytic.geometry import LENGTH_TOL, ORIENTATION_TOL, angle_to_line, angle_to_plane, reach_interval
from planner.ik.analytic.yaw_planar.layout import ChainLayout
from planner.model.robot import Robot

__all__ = ["ArmGeometry", "arm_geometry", "EXACT_TOL"]

#: Deviation [rad] below which a chain is treated as exactly of the family.
EXACT_TOL = 1e-12

Vec3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class ArmGeometry:
    """The arm's closed-form geometry and tolerances (lengths [m], angles [rad]).

    Plane coordinates (u, z, lateral) are along ``e_u``, vertical, and along ``n``, relative
    to the yaw axis's foot ``b3``.

    Attributes:
        name: The robot's name (for messages).
        joint_names: Joint names in ``q`` order.
        dof: Number of joints.
        lower: Lower joint limits [rad], per joint.
        upper: Upper joint limits [rad], per joint.
        deviation: Largest deviation of the axes from the family's ideal directions.
        exact: ``deviation <= EXACT_TOL``: solutions need no correction on the real geometry.
        n: Unit pitch axis (horizontal), shape (3,).
        e_u: In-plane horizontal unit vector ``z x n``, shape (3,) (the tip at u >= 0 at q = 0).
        b3: The yaw axis's foot at z = 0, shape (3,).
        sigma: +1 or -1: the yaw joint's direction about z.
        bx: Yaw axis x.
        by: Yaw axis y.
        mu: Azimuth of ``e_u`` at q = 0.
        n_pitch: Number of pitch joints (2 or 3).
        signs: Per pitch joint, +1 or -1 (its direction about ``n``).
        pitch_idx: Per pitch joint, its index in ``q``.
        su: Shoulder u.
        sz: Shoulder z.
        l1: Shoulder-elbow length.
        g1: Shoulder-elbow angle in the plane at q = 0.
        l2: Elbow-wrist length (3 pitch joints), else None.
        g2: Elbow-wrist angle at q = 0 (3 pitch joints), else None.
        last_u: The last pitch joint's u.
        last_z: The last pitch joint's z.
        has_roll: Whether a wrist roll ends the chain.
        roll_idx: The roll's index in ``q``, or None.
        tip_on_roll_axis: Whether the tip lies on the roll axis (the roll does not move it).
        r0: The roll axis projected into the plane, unit, shape (3,), or None.
        kappa: The roll axis's angle in the plane at q = 0, or None.
        tip0: The tip's foot on the roll axis, from the last pitch joint (u, z, lateral), or None.
        tipc: The tip's offset from the roll axis at roll 0 (u, z, lateral), or None.
        tips: That offset turned by 90 deg about the roll axis (u, z, lateral), or None.
        centre: The roll centre from the last pitch joint (u, z, lateral), or None.
        centre_to_tip_local: Roll centre to tip in the tip frame, shape (3,), or None.
        tip_fixed: The tip from the last pitch joint at roll 0 (u, z, lateral).
        beta: The approach axis's angle in the plane at q = 0.
        pitch_supported: Whether approach-pitch targets apply (the approach axis in the plane
            and along the roll axis).
        rot0: Tip rotation at q = 0, shape (3, 3).
        approach_local: The approach axis in the tip frame, shape (3,).
        tip_position: Tip position at q = 0, shape (3,).
        axes: Joint axes at q = 0 (for the product of exponentials).
        points: Points of the joint axes at q = 0.
        link_lengths: In-plane lengths: shoulder-elbow, elbow-wrist (or elbow-end), wrist-end.
        lateral_offset: Sideways offset of the tip from the yaw axis at roll 0.
        scale: The arm's size (sum of the link lengths and the shoulder's distance).
        len_tol: Length tolerance ``LENGTH_TOL * scale``.
        rmin_lim: Shoulder-elbow reach within the elbow's range, min (3 pitch joints), else None.
        rmax_lim: The same, max, else None.
        orient_tol: Orientation residual accepted on the ideal model.
        consistency_tol: How well position and orientation must agree where both fix a joint.
        elbow_seed: Start separation of the elbow branches near a stretched elbow (inexact).
        core_len_tol: Length tolerance of the ideal model (wider on inexact chains).
    """

    name: str
    joint_names: tuple[str, ...]
    dof: int
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    deviation: float
    exact: bool
    n: np.ndarray
    e_u: np.ndarray
    b3: np.ndarray
    sigma: float
    bx: float
    by: float
    mu: float
    n_pitch: int
    signs: tuple[float, ...]
    pitch_idx: tuple[int, ...]
    su: float
    sz: float
    l1: float
    g1: float
    l2: float | None
    g2: float | None
    last_u: float
    last_z: float
    has_roll: bool
    roll_idx: int | None
    tip_on_roll_axis: bool
    r0: np.ndarray | None
    kappa: float | None
    tip0: Vec3 | None
    tipc: Vec3 | None
    tips: Vec3 | None
    centre: Vec3 | None
    centre_to_tip_local: np.ndarray | None
    tip_fixed: Vec3
    beta: float
    pitch_supported: bool
    rot0: np.ndarray
    approach_local: np.ndarray
    tip_position: np.ndarray
    axes: tuple[np.ndarray, ...]
    points: tuple[np.ndarray, ...]
    link_lengths: tuple[float, ...]
    lateral_offset: float
    scale: float
    len_tol: float
    rmin_lim: float | None
    rmax_lim: float | None
    orient_tol: float
    consistency_tol: float
    elbow_seed: float
    core_len_tol: float


def arm_geometry(robot: Robot, chain: ChainAtZero, layout: ChainLayout) -> ArmGeometry:
    """Read the arm's geometry from its chain.

    Args:
        robot: The robot (name, joint names, limits, approach axis).
        chain: Its chain at q = 0.
        layout: The chain split into the family's joints (:func:`~planner.ik.analytic.yaw_planar.layout.chain_layout`).

    Returns:
        The geometry.
    """
    yaw, pitch, roll, deviation = layout.yaw, layout.pitch, layout.roll, layout.deviation
    lower = tuple(float(v) for v in robot.lower)
    upper = tuple(float(v) for v in robot.upper)
    z = np.array([0.0, 0.0, 1.0])
    n_raw = pitch[0].axis
    exact = deviation <= EXACT_TOL

    # Ideal plane: n horizontal, e_u = z x n, oriented so the tip lies at u >= 0 at q = 0.
    n = np.array([n_raw[0], n_raw[1], 0.0])
    n /= np.linalg.norm(n)
    b3 = np.array([yaw.point[0], yaw.point[1], 0.0])
    e_u = np.cross(z, n)
    if (chain.tip_position - b3) @ e_u < 0:
        n, e_u = -n, -e_u
    n_pitch = len(pitch)
    signs = tuple(1.0 if j.axis @ n > 0 else -1.0 for j in pitch)
    pitch_idx = tuple(j.index for j in pitch)

    def plane(p):
        rel = p - b3
        return float(rel @ e_u), float(p[2]), float(rel @ n)

    pts = [plane(j.point)[:2] for j in pitch]
    su, sz = pts[0]
    v1 = (pts[1][0] - pts[0][0], pts[1][1] - pts[0][1])
    l1, g1 = math.hypot(*v1), math.atan2(v1[1], v1[0])
    last = pts[-1]
    l2 = g2 = None
    if n_pitch == 3:
        v2 = (pts[2][0] - pts[1][0], pts[2][1] - pts[1][1])
        l2, g2 = math.hypot(*v2), math.atan2(v2[1], v2[0])
    # End geometry: the tip (possibly moved by the roll) and the roll centre.
    tip = chain.tip_position
    tip_on_roll_axis = True
    r0 = kappa = tip0 = tipc = tips = centre = centre_to_tip_local = None
    if roll is not None:
        r0 = roll.axis - (roll.axis @ n) * n
        r0 /= np.linalg.norm(r0)
        kappa = math.atan2(r0[2], r0 @ e_u)
        pr = roll.point
        v = tip - pr
        v_par = r0 * (r0 @ v)
        v_perp = v - v_par
        w = np.cross(r0, v)
        centre_tip = plane(pr + v_par)
        tip0 = (centre_tip[0] - last[0], centre_tip[1] - last[1], centre_tip[2])
        tipc = (float(v_perp @ e_u), float(v_perp[2]), float(v_perp @ n))
        tips = (float(w @ e_u), float(w[2]), float(w @ n))
        tip_on_roll_axis = bool(np.linalg.norm(v_perp) <= LENGTH_TOL * max(1.0, np.linalg.norm(v)))
        c = plane(pr)
        centre = (c[0] - last[0], c[1] - last[1], c[2])
        # Tip offset from the roll centre in tip-frame coordinates (moves rigidly with the tip).
        centre_to_tip_local = read_only(chain.tip_rotation.T @ (tip - pr))
    tp = plane(tip)
    tip_fixed = (tp[0] - last[0], tp[1] - last[1], tp[2])
    if roll is not None and not tip_on_roll_axis:
        tp = (tip0[0] + tipc[0], tip0[1] + tipc[1], tip0[2] + tipc[2])
    # Approach axis: in the plane, at angle beta; pitch targets need it to stay there.
    a0 = chain.approach
    beta = math.atan2(a0[2], a0 @ e_u)
    in_plane = angle_to_plane(a0, n) <= FAMILY_ANGLE_TOL
    along_roll = roll is None or angle_to_line(a0, r0) <= FAMILY_ANGLE_TOL

    t_len = math.hypot(tip_fixed[0], tip_fixed[1])
    link_lengths = (l1, l2, t_len) if n_pitch == 3 else (l1, t_len)
    lateral_offset = float(tp[2]) if roll is None else float(tip0[2] + tipc[2])
    scale = max(1e-9, sum(link_lengths) + math.hypot(su, sz))
    len_tol = LENGTH_TOL * scale
    # Reach of the shoulder-elbow pair within the elbow's range (Materick and Shapiro's (1997) min reach).
    elbow = pitch_idx[1]
    rmin_lim = rmax_lim = None
    if n_pitch == 3:
        rmin, rmax = reach_interval(l1, l2, g2 - g1, lower[elbow], upper[elbow], signs[1])
        rmin_lim, rmax_lim = float(rmin), float(rmax)
    return ArmGeometry(
        name=robot.name,
        joint_names=tuple(robot.joint_names),
        dof=robot.dof,
        lower=lower,
        upper=upper,
        deviation=deviation,
        exact=exact,
        n=read_only(n),
        e_u=read_only(e_u),
        b3=read_only(b3),
        sigma=1.0 if yaw.axis[2] > 0 else -1.0,
        bx=float(b3[0]),
        by=float(b3[1]),
        mu=math.atan2(e_u[1], e_u[0]),
        n_pitch=n_pitch,
        signs=signs,
        pitch_idx=pitch_idx,
        su=su,
        sz=sz,
        l1=l1,
        g1=g1,
        l2=l2,
        g2=g2,
        last_u=last[0],
        last_z=last[1],
        has_roll=roll is not None,
        roll_idx=roll.index if roll is not None else None,
        tip_on_roll_axis=tip_on_roll_axis,
        r0=None if r0 is None else read_only(r0),
        kappa=kappa,
        tip0=tip0,
        tipc=tipc,
        tips=tips,
        centre=centre,
        centre_to_tip_local=centre_to_tip_local,
        tip_fixed=tip_fixed,
        beta=beta,
        pitch_supported=in_plane and along_roll,
        rot0=read_only(chain.tip_rotation),
        approach_local=read_only(robot.approach_axis),
        tip_position=chain.tip_position,
        axes=tuple(j.axis for j in chain.joints),
        points=tuple(j.point for j in chain.joints),
        link_lengths=link_lengths,
        lateral_offset=lateral_offset,
        scale=scale,
        len_tol=len_tol,
        rmin_lim=rmin_lim,
        rmax_lim=rmax_lim,
        orient_tol=ORIENTATION_TOL if exact else max(ORIENTATION_TOL, 1e3 * deviation),
        # Position and orientation of a target must agree this well where the orientation
        # fixes joints the position also fixes (arms without a wrist pitch).
        consistency_tol=1e-9 * scale,
        elbow_seed=0.0 if exact else 2.0 * math.sqrt(deviation),
        # Inexact chains: the ideal model may put a reachable target just outside its reach.
        core_len_tol=len_tol if exact else max(LENGTH_TOL, 1e2 * deviation) * scale,
    )
