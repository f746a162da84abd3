"""The outcomes of inverse kinematics: one vocabulary for the closed form and the NLP.

An unreachable target is not an error: every IK call answers with a status. The values are
strings, so JSON output and comparisons with plain strings (``result.status == "solved"``)
keep working.
"""

from __future__ import annotations

from enum import Enum

__all__ = ["IKStatus"]


class IKStatus(str, Enum):
    """Why an IK call succeeded or not, best outcome first.

    Attributes:
        SOLVED: A configuration within every joint's limits reaches the target (checked by
            Pinocchio FK within the tolerances).
        OUTSIDE_JOINT_LIMITS: Configurations reach the target, but every one has a joint
            outside its range (closed form; the reason names the joint and the excess).
        BELOW_MANIPULABILITY_FLOOR: Reached, but by no configuration above the asked
            manipulability floor (NLP).
        IN_COLLISION: Reached, but every configuration found collides with the scene or the
            arm itself, or comes closer than the clearance (with a collision checker).
        INACCURATE: A closed-form configuration misses the target by Pinocchio FK (a model the
            closed form does not fit exactly).
        ORIENTATION_NOT_ACHIEVABLE: The position is reachable, not with the asked orientation or
            approach pitch: the arm has too few joints for it (closed form).
        BEYOND_MAX_REACH: Too far for the arm (closed form).
        INSIDE_MIN_REACH: Too close to the base or shoulder (closed form).
        OUT_OF_PLANE: A planar arm asked for a point off its plane (closed form).
        NOT_CONVERGED: No attempt of the NLP reached the target: it may be out of reach.
    """

    SOLVED = "solved"
    OUTSIDE_JOINT_LIMITS = "outside_joint_limits"
    BELOW_MANIPULABILITY_FLOOR = "below_manipulability_floor"
    IN_COLLISION = "in_collision"
    INACCURATE = "inaccurate"
    ORIENTATION_NOT_ACHIEVABLE = "orientation_not_achievable"
    BEYOND_MAX_REACH = "beyond_max_reach"
    INSIDE_MIN_REACH = "inside_min_reach"
    OUT_OF_PLANE = "out_of_plane"
    NOT_CONVERGED = "not_converged"

    def __str__(self) -> str:
        return self.value
