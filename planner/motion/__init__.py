"""Layer 4: motion: joint limits, trajectories (Ruckig), Cartesian lines, singularity detours."""
