"""The ``"stop"`` via strategy: rest at every waypoint (the baseline the others beat)."""

from __future__ import annotations

import numpy as np

from planner.motion.vias.base import ViaChain, ViaStrategy

__all__ = ["StopStrategy"]


class StopStrategy(ViaStrategy):
    """Rest at every waypoint; a moving start state is kept at the first one."""

    name = "stop"

    def stop_mask(self, stop: np.ndarray, moving_start: bool) -> np.ndarray:
        """Every waypoint is a stop, the first one unless the start state moves."""
        out = np.ones_like(stop)
        out[0] = not moving_start
        return out

    def choose(self, chain: ViaChain) -> None:
        """Nothing to choose: every via is fixed at rest."""
