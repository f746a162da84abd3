"""Layer 0: helpers every layer may use (input files and units, rotations, read-only arrays)."""
