"""Calibration files shipped with `planner`, one per arm and controller (``<robot>-<controller>.yaml``)."""
