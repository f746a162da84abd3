"""Numerical IK: CasADi kinematics, C code generation and its cache, the batched kernel, IPOPT, NlpIK.

Modules, bottom up: ``kinematics`` (symbolic FK from :mod:`planner.geometry.chain`),
``codegen`` (compiling CasADi functions, the disk cache), ``kernel`` (the batched damped
Gauss-Newton function), ``polish`` (IPOPT for the secondary objectives), ``batch`` and
``batch_result`` (many targets through one compiled kernel, vectorised), ``solver``
(:class:`~planner.ik.numeric.solver.NlpIK`: seeds, restarts, choice, solutions).
"""
