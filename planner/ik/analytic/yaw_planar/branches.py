"""The yaw-planar family's branches and the per-branch failure categories.

Up to four solutions per target: the yaw from the end point's horizontal position gives two
sides ("front", and "back" = turned by about pi, the shoulder reaching back over the base), the
law of cosines two elbows per side. Arrays over branches hold them in :data:`BRANCHES` order
(slot 2 * side + elbow). Each slot carries a category: :data:`VALID` or why the branch has no
solution there (internal; the statuses of :mod:`planner.ik.analytic.result` are derived from
them).
"""

from __future__ import annotations

__all__ = ["BRANCHES", "VALID", "BEYOND", "INSIDE", "CYLINDER", "ORIENT", "DUPLICATE"]

#: Branch names in batch order.
BRANCHES = ("front/elbow-up", "front/elbow-down", "back/elbow-up", "back/elbow-down")

#: Per-branch categories (int8 codes in the arrays): a solution; the wrist point beyond the
#: reach; inside it; the end point inside the cylinder the plane's sideways offset leaves
#: around the yaw axis; the orientation not achievable; the same solution as another slot.
VALID, BEYOND, INSIDE, CYLINDER, ORIENT, DUPLICATE = range(6)
