"""Via strategies: how a trajectory passes its via waypoints, one module each, and their registry.

Add a strategy as one module with a :class:`ViaStrategy` subclass and one line in
:data:`VIA_STRATEGIES`; :func:`planner.motion.plan.plan_trajectory` then accepts its name.
"""

from __future__ import annotations

from planner.exceptions import InvalidArgumentError
from planner.motion.vias.base import ViaChain, ViaStrategy
from planner.motion.vias.heuristic import HeuristicStrategy
from planner.motion.vias.optimized import OptimizedStrategy
from planner.motion.vias.refined import RefinedStrategy
from planner.motion.vias.stop import StopStrategy

__all__ = [
    "VIA_STRATEGIES",
    "HeuristicStrategy",
    "OptimizedStrategy",
    "RefinedStrategy",
    "StopStrategy",
    "ViaChain",
    "ViaStrategy",
    "via_strategy",
]

#: Via strategies by name, in the order messages list them.
VIA_STRATEGIES: dict[str, type[ViaStrategy]] = {
    "optimized": OptimizedStrategy,
    "heuristic": HeuristicStrategy,
    "stop": StopStrategy,
    "refined": RefinedStrategy,
}


def via_strategy(strategy: str | ViaStrategy) -> ViaStrategy:
    """The strategy object for a registered name (an instance is returned as it is).

    Raises:
        InvalidArgumentError: On an unknown name (the message lists the valid ones).
    """
    if isinstance(strategy, ViaStrategy):
        return strategy
    cls = VIA_STRATEGIES.get(strategy) if isinstance(strategy, str) else None
    if cls is None:
        raise InvalidArgumentError(f"unknown strategy {strategy!r}; valid: {', '.join(VIA_STRATEGIES)}")
    return cls()
