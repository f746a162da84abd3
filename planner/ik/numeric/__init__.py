"""Numerical IK: CasADi kinematics built from the Pinocchio model, the compiled kernel, restarts."""
