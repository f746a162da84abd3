"""Layer 2: geometry on top of the model: targets, the screw chain, sensor readings to base-frame points."""
