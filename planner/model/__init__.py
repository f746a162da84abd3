"""Layer 1: the robot model (URDF -> Pinocchio), the catalog of arms and the DH-to-URDF generator."""
