"""The trajectory request: everything the planner takes, validated once and carried as one object.

A :class:`TrajectoryRequest` travels from the caller (a plan file, a Cartesian line, a test)
through :func:`planner.motion.singularity.plan_clear_of_singularities` (which derives requests
with detour waypoints by :func:`dataclasses.replace`) to
:func:`planner.motion.plan.plan_trajectory_request`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

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
        n, dof = q.shape
        names = limits.joint_names
        # Every check returns a new array, frozen here in place; what is not given is a view of
        # one frozen array shared by the requests of that shape.
        v0 = (
            _zeros(dof)
            if self.start_velocity is None
            else check_state(self.start_velocity, limits.velocity, names, "start velocity")
        )
        a0 = (
            _zeros(dof)
            if self.start_acceleration is None
            else check_state(self.start_acceleration, limits.acceleration, names, "start acceleration")
        )
        dw = _zeros(n) if self.dwell is None else check_dwell(self.dwell, n)
        stops = self.stops
        stop = None if stops is None or (isinstance(stops, tuple) and not stops) else check_stops(stops, n)
        moving = any(v0.tolist()) or any(a0.tolist())
        if moving and ((stop is not None and stop[0]) or dw[0] > 0):
            raise InvalidArgumentError("waypoint 0 is a stop, but a non-zero start state was given")
        if self.via_velocities is None and self.via_accelerations is None and self.min_durations is None:
            gv, ga, md = _nans(n, dof), _zeros(n, dof), _zeros(n - 1)
            prescribed = False
        else:
            gv, ga, md = check_given(self.via_velocities, self.via_accelerations, self.min_durations, n, limits)
            prescribed = True
        for name, value in (
            ("waypoints", q),
            ("start_velocity", v0),
            ("start_acceleration", a0),
            ("dwell", dw),
            ("via_velocities", gv),
            ("via_accelerations", ga),
            ("min_durations", md),
        ):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "stops", () if stop is None else tuple(int(k) for k in np.nonzero(stop)[0]))
        object.__setattr__(self, "_moving_start", moving)
        object.__setattr__(self, "_prescribed", prescribed)

    @property
    def moving_start(self) -> bool:
        """Whether the start state is not at rest."""
        return self._moving_start

    @property
    def prescribed(self) -> bool:
        """Whether via states or minimum durations were given (they may still all be free or zero)."""
        return self._prescribed

    def __repr__(self) -> str:
        strategy = self.strategy if isinstance(self.strategy, str) else type(self.strategy).__name__
        return (
            f"TrajectoryRequest(waypoints={len(self.waypoints)}, dof={self.limits.dof}, "
            f"strategy={strategy!r}, stops={self.stops})"
        )


@lru_cache(maxsize=64)
def _filled(shape: tuple[int, ...], value: float) -> np.ndarray:
    """A frozen array of `shape` holding `value` everywhere (shared: hand out views)."""
    arr = np.full(shape, value)
    arr.setflags(write=False)
    return arr


def _zeros(*shape: int) -> np.ndarray:
    """A read-only view of zeros (a view of a frozen array cannot be made writeable again)."""
    return _filled(shape, 0.0)[...]


def _nans(*shape: int) -> np.ndarray:
    """A read-only view of NaNs, like :func:`_zeros`."""
    return _filled(shape, math.nan)[...]
