"""Layer 5: export of trajectories to servo controllers (calibration, one module per format)."""
