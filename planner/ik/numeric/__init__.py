"""Numerical IK: CasADi kinematics, C code generation and its cache, the batched kernel, IPOPT, NlpIK.

Modules, bottom up: ``kinematics`` (symbolic FK from :mod:`planner.geometry.chain`),
``codegen`` (compiling CasADi functions, the disk cache), ``kernel`` (the batched damped
Gauss-Newton function), ``polish`` (IPOPT for the secondary objectives), ``solver``
(:class:`~planner.ik.numeric.solver.NlpIK`: seeds, restarts, choice, solutions).
"""
