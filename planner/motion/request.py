"""The trajectory request: everything the planner takes, validated once and carried as one object.

A :class:`TrajectoryRequest` travels from the caller (a plan file, a Cartesian line, a test)
through :func:`planner.motion.singularity.plan_clear_of_singularities` (which derives requests
with detour waypoints by :func:`dataclasses.replace`) to
:func:`planner.motion.plan.plan_trajectory_request`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from planner.core.arrays import read_only
from planner.exceptions import InvalidArgumentError
from planner.motion.checks import check_dwell, check_given, check_state, check_stops, check_waypoints
from planner.motion.limits import JointLimits
from planner.motion.vias import ViaStrategy, via_strategy

__all__ = ["TrajectoryRequest"]


@dataclass(frozen=True, eq=False)
class TrajectoryRequest:
    """A trajectory to plan: waypoints, limits and how to pass them.

    Construction validates every field and stores it normalised (arrays as read-only copies),
    so a request that exists is one the planner accepts. Derive variants with
    :func:`dataclasses.replace` (they are validated again).

    Attributes:
        waypoints: Joint configurations to pass through, shape (N, dof), N >= 2 [rad or m].
        limits: Velocity, acceleration, jerk and position limits.
        start_velocity: Velocity at the first waypoint, shape (dof,); None (at rest) becomes zeros.
        start_acceleration: Acceleration at the first waypoint, shape (dof,); None becomes zeros.
        stops: Indices of waypoints where the arm must come to rest (the first and last always
            do, unless a start state is given); normalised to sorted indices in 0..N-1.
        dwell: Time at rest at each waypoint [s]: one number for all or one per waypoint (a
            positive dwell implies a stop); normalised to shape (N,).
        strategy: A name in :data:`planner.motion.vias.VIA_STRATEGIES` or a
            :class:`planner.motion.vias.ViaStrategy` instance.
        via_velocities: Prescribed velocities at via waypoints, shape (N, dof); rows holding a
            NaN are chosen by the planner (normalised: such rows all NaN; None: all free).
        via_accelerations: Prescribed accelerations for the same rows, shape (N, dof) (NaN or
            None: zero).
        min_durations: Shortest duration of each segment, shape (N-1,) [s]; None or 0: none.

    Raises:
        InvalidArgumentError: Fewer than two waypoints, a bad start state, stop, dwell, strategy
            or prescribed state.
        InvalidConfigurationError: A waypoint with the wrong length or a NaN.
        JointLimitError: A waypoint outside its joint range (joint and value named).
    """

    waypoints: np.ndarray
    limits: JointLimits
    start_velocity: np.ndarray | None = None
    start_acceleration: np.ndarray | None = None
    stops: Sequence[int] | None = ()
    dwell: np.ndarray | float | None = None
    strategy: str | ViaStrategy = "optimized"
    via_velocities: np.ndarray | None = None
    via_accelerations: np.ndarray | None = None
    min_durations: np.ndarray | None = None

    def __post_init__(self) -> None:
        via_strategy(self.strategy)
        limits = self.limits
        if not isinstance(limits, JointLimits):
            raise InvalidArgumentError(f"limits must be a JointLimits, got {type(limits).__name__}")
        q = check_waypoints(self.waypoints, limits)
        n = len(q)
        names = limits.joint_names
        v0 = check_state(self.start_velocity, limits.velocity, names, "start velocity")
        a0 = check_state(self.start_acceleration, limits.acceleration, names, "start acceleration")
        dw = check_dwell(self.dwell, n)
        stop = check_stops(self.stops, n)
        if (stop[0] or dw[0] > 0) and (np.any(v0) or np.any(a0)):
            raise InvalidArgumentError("waypoint 0 is a stop, but a non-zero start state was given")
        gv, ga, md = check_given(self.via_velocities, self.via_accelerations, self.min_durations, n, limits)
        for name, value in (
            ("waypoints", q),
            ("start_velocity", v0),
            ("start_acceleration", a0),
            ("dwell", dw),
            ("via_velocities", gv),
            ("via_accelerations", ga),
            ("min_durations", md),
        ):
            object.__setattr__(self, name, read_only(value))
        object.__setattr__(self, "stops", tuple(int(k) for k in np.nonzero(stop)[0]))

    @property
    def moving_start(self) -> bool:
        """Whether the start state is not at rest."""
        return bool(np.any(self.start_velocity) or np.any(self.start_acceleration))

    def __repr__(self) -> str:
        strategy = self.strategy if isinstance(self.strategy, str) else type(self.strategy).__name__
        return (
            f"TrajectoryRequest(waypoints={len(self.waypoints)}, dof={self.limits.dof}, "
            f"strategy={strategy!r}, stops={self.stops})"
        )
