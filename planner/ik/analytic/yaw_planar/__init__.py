"""Base yaw + 2 or 3 parallel pitch joints + optional wrist roll, in closed form.

The family of the arms of Clothier and Shang (2010, AL5C), Vaishnav (three-joint coursework),
Sumadsad (2020, DH arm) and of the SO-101: the first joint turns about the vertical, the next
2 or 3 about parallel horizontal axes (the arm's plane is perpendicular to them), and an
optional last joint rolls about an axis in that plane.

Geometry: :mod:`~planner.ik.analytic.yaw_planar.arm` (read from the Pinocchio model at q = 0).

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
``solve`` and ``solve_batch`` search the joints the target leaves free, per branch
(:mod:`~planner.ik.analytic.yaw_planar.search`, :mod:`~planner.ik.analytic.yaw_planar.end_angle`).

Chains whose axes deviate from the ideal directions by round-off are solved on the ideal
geometry and then corrected on the real one (:mod:`~planner.ik.analytic.yaw_planar.refine`).

Speed: :meth:`YawPlanarIK.solve` runs every target on exact chains in scalar arithmetic, each
branch verified by the forward model (a few ``robot.fk`` call times: ``scalar`` for position and
pitch targets, ``scalar_pose`` for full poses); on inexact chains every branch is solved on
the ideal geometry and corrected by compiled Newton steps on the real model (``corrected``,
``newton``); the targets that path declines (branches that do not settle, next to the
boundary of the real reach; a free pitch without ``q_current``; no branch within the limits) go through the
vectorised path (hundreds of microseconds for one target, milliseconds with its search).
``solve_batch`` is vectorised over targets (in slices of 16384 to stay in cache); on exact
chains, position targets of two-pitch arms and approach-pitch targets run through the same
closed form compiled to C instead (``compiled``: about twice as fast, the same answers). The search
within the limits, only for targets that need it, costs about 1.5 ms for the approach pitch
and 3-12 ms with SO-101's roll.

Modules, in the order of the data flow: ``layout`` (does a chain fit, which joint is which),
``arm`` (the geometry, :class:`~planner.ik.analytic.yaw_planar.arm.ArmGeometry`), ``branches``
(branch names and failure categories), ``orientation`` and ``free_pitch`` (the end angle, yaw
and roll a target fixes or leaves free), ``core`` (the ideal closed form over arrays),
``scalar``, ``scalar_pose`` and ``corrected`` (the same for one target without NumPy),
``real_model``, ``newton`` and ``refine`` (the real geometry), ``status`` (status and reason), ``arrays``
(the pipeline per batch), ``end_angle`` and ``search`` (free joints within the limits),
``compiled`` (the batch closed form as one compiled CasADi function), ``batch`` (slices or
the compiled path), ``solver`` (:class:`YawPlanarIK`).
"""

from planner.ik.analytic.yaw_planar.branches import BRANCHES
from planner.ik.analytic.yaw_planar.layout import ChainLayout, chain_layout
from planner.ik.analytic.yaw_planar.solver import YawPlanarIK

__all__ = ["YawPlanarIK", "BRANCHES", "ChainLayout", "chain_layout"]
