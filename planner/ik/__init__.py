"""Layer 3: inverse kinematics (one entry point, closed-form families, the numerical solver)."""
