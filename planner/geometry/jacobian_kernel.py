"""The tip Jacobian of a robot's chain at many configurations in one compiled loop.

:meth:`Robot.task_jacobians` calls Pinocchio once per configuration (about 1 us each from
Python); the singularity measure and the detour search need hundreds at a time. Here one C
function (:mod:`planner.core.native`, compiled once for every robot: the chain is data) walks
the chain of :func:`~planner.geometry.chain.kinematic_chain` per configuration, as
:class:`~planner.ik.numeric.kinematics.CasadiKinematics` builds it symbolically: each joint's
frame is its parent's pose times its constant placement times its motion (a rotation by ``q``
about its unit axis, Rodrigues' formula, or a translation by ``q`` along it); column ``k`` is
``[a_k x (p - o_k); a_k]`` for a turning joint and ``[a_k; 0]`` for a sliding one (``a_k`` its
axis and ``o_k`` its origin in the base frame, ``p`` the tip), zero for joints that do not
move the tip. That is Pinocchio's ``LOCAL_WORLD_ALIGNED`` frame Jacobian (as
:meth:`Robot.jacobian`), equal to it to rounding (the tests compare both); about ten times
faster per configuration.
"""

from __future__ import annotations

import ctypes

import numpy as np

from planner.core.native import load_functions
from planner.exceptions import InvalidArgumentError, UnsupportedChainError
from planner.geometry.chain import kinematic_chain
from planner.model.robot import Robot

__all__ = ["JacobianKernel", "jacobian_kernel"]

_SOURCE = r"""
#include <math.h>

/* Loops unrolled (GCC; other compilers ignore it): the same operations in the same order, without
   the counters and branches of loops a few iterations long. */
#pragma GCC optimize("unroll-loops")

static void mul3(const double *a, const double *b, double *out) {
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            out[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j];
}

/* Tip Jacobians (n, 6, dof), row-major, rows [v; omega] in base-frame axes. */
void chain_jacobians(long n, long dof, const double *q, const long *parent, const long *sliding,
                     const long *aligned, const long *moves_tip, const double *rot, const double *trans,
                     const double *axis, long tip_parent, const double *tip_trans, double *out) {
    static const double eye[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1}, zero[3] = {0, 0, 0};
    double R[dof][9], t[dof][3], a[dof][3];
    for (long r = 0; r < n; ++r) {
        const double *qr = q + r * dof;
        double *J = out + r * 6 * dof;
        for (long k = 0; k < dof; ++k) {
            const double *Rp = parent[k] < 0 ? eye : R[parent[k]];
            const double *tp = parent[k] < 0 ? zero : t[parent[k]];
            const double *ax = axis + 3 * k, *tr = trans + 3 * k;
            double Rj[9];
            mul3(Rp, rot + 9 * k, Rj);
            for (int i = 0; i < 3; ++i) {
                t[k][i] = tp[i] + (Rp[3 * i] * tr[0] + Rp[3 * i + 1] * tr[1] + Rp[3 * i + 2] * tr[2]);
                a[k][i] = Rj[3 * i] * ax[0] + Rj[3 * i + 1] * ax[1] + Rj[3 * i + 2] * ax[2];
            }
            if (sliding[k]) {
                for (int i = 0; i < 3; ++i) t[k][i] += a[k][i] * qr[k];
                for (int i = 0; i < 9; ++i) R[k][i] = Rj[i];
            } else if (aligned[k] >= 0) {
                /* About a coordinate axis i (sign in the axis): columns j, l of Rj turn. */
                long i = aligned[k], j = (i + 1) % 3, l = (i + 2) % 3;
                double c = cos(qr[k]), s = ax[i] * sin(qr[k]);
                for (int m = 0; m < 3; ++m) {
                    R[k][3 * m + i] = Rj[3 * m + i];
                    R[k][3 * m + j] = c * Rj[3 * m + j] + s * Rj[3 * m + l];
                    R[k][3 * m + l] = c * Rj[3 * m + l] - s * Rj[3 * m + j];
                }
            } else {
                double c = cos(qr[k]), s = sin(qr[k]), v = 1.0 - c, M[9];
                double x = ax[0], y = ax[1], z = ax[2];
                M[0] = c + v * x * x;     M[1] = -s * z + v * x * y; M[2] = s * y + v * x * z;
                M[3] = s * z + v * y * x; M[4] = c + v * y * y;      M[5] = -s * x + v * y * z;
                M[6] = -s * y + v * z * x; M[7] = s * x + v * z * y; M[8] = c + v * z * z;
                mul3(Rj, M, R[k]);
            }
        }
        double p[3];
        for (int i = 0; i < 3; ++i) {
            p[i] = tip_parent < 0 ? tip_trans[i]
                                  : t[tip_parent][i] + (R[tip_parent][3 * i] * tip_trans[0] +
                                                        R[tip_parent][3 * i + 1] * tip_trans[1] +
                                                        R[tip_parent][3 * i + 2] * tip_trans[2]);
        }
        for (long k = 0; k < dof; ++k) {
            double col[6] = {0, 0, 0, 0, 0, 0};
            if (moves_tip[k]) {
                const double *w = a[k];
                if (sliding[k]) {
                    col[0] = w[0]; col[1] = w[1]; col[2] = w[2];
                } else {
                    double d0 = p[0] - t[k][0], d1 = p[1] - t[k][1], d2 = p[2] - t[k][2];
                    col[0] = w[1] * d2 - w[2] * d1;
                    col[1] = w[2] * d0 - w[0] * d2;
                    col[2] = w[0] * d1 - w[1] * d0;
                    col[3] = w[0]; col[4] = w[1]; col[5] = w[2];
                }
            }
            for (int i = 0; i < 6; ++i) J[i * dof + k] = col[i];
        }
    }
}
"""

#: The C function's argument types: n, dof, then eight arrays, the tip's parent and two arrays.
_SIGNATURES = {
    "chain_jacobians": [ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 8, ctypes.c_long, *[ctypes.c_void_p] * 2]
}


def _library() -> ctypes.CDLL | None:
    return load_functions(_SOURCE, "chain_jacobians", _SIGNATURES)


class JacobianKernel:
    """The compiled tip Jacobian of one robot's chain (see the module docstring).

    Build it with :func:`jacobian_kernel`, which keeps one per robot.
    """

    def __init__(self, robot: Robot, library: ctypes.CDLL) -> None:
        """Read `robot`'s chain into the arrays the C function takes.

        Raises:
            UnsupportedChainError: If a chain joint is not a one-axis rotation or translation.
        """
        chain = kinematic_chain(robot)
        joints = chain.joints
        self.dof = robot.dof
        self._function = library.chain_jacobians
        on_path = chain.tip_path()
        self._parent = np.array([j.parent for j in joints], dtype=np.int64)
        self._sliding = np.array([j.kind == "prismatic" for j in joints], dtype=np.int64)
        # The coordinate axis a turning joint's axis lies along (either sign), else -1.
        self._aligned = np.array(
            [int(np.argmax(np.abs(j.axis))) if np.count_nonzero(j.axis) == 1 else -1 for j in joints], dtype=np.int64
        )
        self._moves_tip = np.array([k in on_path for k in range(len(joints))], dtype=np.int64)
        self._rot = np.ascontiguousarray([j.parent_rotation for j in joints], dtype=float).reshape(-1, 9)
        self._trans = np.ascontiguousarray([j.parent_translation for j in joints], dtype=float).reshape(-1, 3)
        self._axis = np.ascontiguousarray([j.axis for j in joints], dtype=float).reshape(-1, 3)
        self._tip_parent = int(chain.tip_parent)
        self._tip_trans = np.ascontiguousarray(chain.tip_translation, dtype=float)
        # The chain's arguments, fixed (the arrays above keep the memory alive).
        self._chain = (
            *(a.ctypes.data for a in (self._parent, self._sliding, self._aligned, self._moves_tip)),
            *(a.ctypes.data for a in (self._rot, self._trans, self._axis)),
            self._tip_parent,
            self._tip_trans.ctypes.data,
        )

    def __deepcopy__(self, memo: dict) -> JacobianKernel:
        # Immutable, and its arguments are addresses of its own arrays: copies share it.
        return self

    def __call__(self, q: np.ndarray) -> np.ndarray:
        """The tip Jacobians at configurations `q` (n, dof) [rad or m]: shape (n, 6, dof).

        Only the shape is checked (the C loop reads ``n * dof`` values); NaN gives NaN.

        Raises:
            InvalidArgumentError: If `q` is not of shape (n, dof).
        """
        q = np.ascontiguousarray(q, dtype=float)
        if q.ndim != 2 or q.shape[1] != self.dof:
            raise InvalidArgumentError(f"q must have shape (n, {self.dof}), got {q.shape}")
        out = np.empty((len(q), 6, self.dof))
        if len(q):
            self._function(len(q), self.dof, q.ctypes.data, *self._chain, out.ctypes.data)
        return out


class _Kernels:
    """Per robot, its kernel or None, built once (kept in ``robot.derived``)."""

    def __init__(self, robot: Robot) -> None:
        library = _library()
        self.kernel: JacobianKernel | None = None
        if library is not None and robot.dof > 0:
            try:
                self.kernel = JacobianKernel(robot, library)
            except UnsupportedChainError:
                self.kernel = None


def jacobian_kernel(robot: Robot) -> JacobianKernel | None:
    """`robot`'s compiled tip Jacobian, or None where there is none (no compiler, ``PLANNER_JIT=0``).

    Built on first use and kept with the robot (:attr:`Robot.derived`).
    """
    return robot.derived.get(_Kernels, lambda: _Kernels(robot)).kernel
