"""The batch driver: N targets in slices, each solved and searched within the limits."""

from __future__ import annotations

from planner.ik.analytic.yaw_planar.arm import ArmGeometry
from planner.ik.analytic.yaw_planar.arrays import BranchArrays, solve_arrays
from planner.ik.analytic.yaw_planar.compiled import CompiledKernels, compiled_supported, kind_of, solve_compiled
from planner.ik.analytic.yaw_planar.search import free_joints, solve_searched

__all__ = ["solve_chunked", "solve_arrays_within", "solve_compiled_within"]

#: Targets per slice: keeps the temporaries in cache.
CHUNK = 16384
#: The fewest targets for the compiled path (smaller batches: NumPy, no compiling for them).
COMPILED_MIN = 1024
#: The fields of the batch arrays.
NAMES = ("q", "valid", "within", "singular", "perr", "status", "best")


def solve_chunked(
    arm: ArmGeometry, pos, pit, rot, qc, chunk: int = CHUNK, kernels: CompiledKernels | None = None
) -> BranchArrays:
    """:func:`solve_arrays_within` over slices of the targets, or the compiled closed form.

    With `kernels` (`arm`'s), from :data:`COMPILED_MIN` targets, where
    :func:`~planner.ik.analytic.yaw_planar.compiled.compiled_supported` holds and a C compiler
    built the function, :func:`solve_compiled_within` gives the same arrays (1.5-8 times as
    fast, most for poses).

    Args:
        arm: The geometry.
        pos: Target positions, shape (N, 3) [m].
        pit: Approach pitches, shape (N,) [rad], or None.
        rot: Target rotations, shape (N, 3, 3), or None.
        qc: Current configurations, shape (N, dof) [rad], or None.
        chunk: Targets per slice.
        kernels: The arm's compiled closed form, or None (NumPy only).

    Returns:
        The branch arrays (``cat``, ``oerr`` and ``dist`` None when sliced).
    """
    n = pos.shape[0]
    if (
        n >= COMPILED_MIN
        and kernels is not None
        and compiled_supported(arm, pit, rot, qc)
        and kernels.available(kind_of(pit, rot), qc is not None)
    ):
        return solve_compiled_within(kernels, pos, pit, rot, qc)
    if n <= chunk:
        return solve_arrays_within(arm, pos, pit, rot, qc)
    out = BranchArrays.empty(n, arm.dof)
    for start in range(0, n, chunk):
        sl = slice(start, start + chunk)
        part = solve_arrays_within(
            arm,
            pos[sl],
            None if pit is None else pit[sl],
            None if rot is None else rot[sl],
            None if qc is None else qc[sl],
        )
        for name in NAMES:
            getattr(out, name)[sl] = getattr(part, name)
    return out


def solve_compiled_within(kernels: CompiledKernels, pos, pit, rot, qc, *, compiled: bool = True) -> BranchArrays:
    """The compiled closed form; the targets it hands over by :func:`solve_arrays_within`.

    :func:`~planner.ik.analytic.yaw_planar.compiled.solve_compiled`'s arrays, the same as
    :func:`solve_arrays_within`'s (to round-off) where
    :func:`~planner.ik.analytic.yaw_planar.compiled.compiled_supported` holds.
    """
    out, rows = solve_compiled(kernels, pos, pit, rot, qc, compiled=compiled)
    if rows.size:
        part = solve_arrays_within(
            kernels.arm,
            pos[rows],
            None if pit is None else pit[rows],
            None if rot is None else rot[rows],
            None if qc is None else qc[rows],
        )
        for name in NAMES:
            getattr(out, name)[rows] = getattr(part, name)
    return out


def solve_arrays_within(arm: ArmGeometry, pos, pit, rot, qc) -> BranchArrays:
    """`solve_arrays` for a batch, then the search within the limits where targets leave joints free."""
    arrays = solve_arrays(arm, pos, pit, rot, qc, orientation_errors=False)
    if any(free_joints(arm, pit, rot)):
        arrays = solve_searched(arm, pos, pit, qc, arrays, orientation_errors=False)
    return arrays
