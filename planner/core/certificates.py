"""Cholesky certificates and eigenvalue bounds of many small symmetric matrices, in compiled loops.

The singularity measure (:func:`planner.motion.singularity.bounded_conditioning`) factors a few
hundred 3 x 3 to 6 x 6 Gram matrices at a time. Written out over the batch in NumPy that takes
a few dozen array operations per call whatever the batch size; here one C loop (compiled once
and cached by :mod:`planner.core.native`) does the same arithmetic, matrix by matrix, in the
same order. Both functions return None where the library cannot be built (no compiler,
``PLANNER_JIT=0``) or for matrices larger than :data:`LARGEST`; the caller then takes its
NumPy path.
"""

from __future__ import annotations

import ctypes

import numpy as np

from planner.core.native import load_functions
from planner.exceptions import InvalidArgumentError

__all__ = ["LARGEST", "cholesky_certificates", "extreme_bounds", "grams"]

#: Largest matrix size the compiled loops take.
LARGEST = 8

_SOURCE = r"""
#include <math.h>

/* Cholesky factor L (row-major, lower) of g - (shift + 1e-12 tr g) I and its pivots; 1 if all > 0. */
static int factor(long k, const double *g, double shift, double *L, double *piv) {
    double tr = 0.0;
    for (long i = 0; i < k; ++i) tr += g[i * k + i];
    double margin = shift + 1e-12 * tr;
    int ok = 1;
    for (long j = 0; j < k; ++j) {
        double s = 0.0;
        for (long i = 0; i < j; ++i) s += L[j * k + i] * L[j * k + i];
        double p = g[j * k + j] - margin - s;
        piv[j] = p;
        if (!(p > 0.0)) ok = 0;
        double root = sqrt(p > 0.0 ? p : 1.0);
        L[j * k + j] = root;
        for (long r = j + 1; r < k; ++r) {
            double t = 0.0;
            for (long i = 0; i < j; ++i) t += L[r * k + i] * L[j * k + i];
            L[r * k + j] = (g[r * k + j] - t) / root;
        }
    }
    return ok;
}

void cholesky_certificates(long n, long k, const double *g, const double *shift, long *ok, double *product) {
    double L[64], piv[8];
    for (long m = 0; m < n; ++m) {
        ok[m] = factor(k, g + m * k * k, shift[m], L, piv);
        double p = 1.0;
        for (long j = 0; j < k; ++j) p *= ok[m] ? piv[j] : 0.0;
        product[m] = ok[m] ? p : 0.0;
    }
}

static double quotient(long k, const double *g, const double *x) {
    double num = 0.0, den = 0.0;
    for (long i = 0; i < k; ++i) {
        double gx = 0.0;
        for (long j = 0; j < k; ++j) gx += g[i * k + j] * x[j];
        num += x[i] * gx;
        den += x[i] * x[i];
    }
    return num / den;
}

/* Whether the Cholesky factorisation of sign (g - shift I) - margin I has positive pivots. */
static int positive(long k, const double *g, double sign, double shift, double margin, double *L) {
    for (long j = 0; j < k; ++j) {
        double s = 0.0;
        for (long i = 0; i < j; ++i) s += L[j * k + i] * L[j * k + i];
        double p = sign * (g[j * k + j] - shift) - margin - s;
        if (!(p > 0.0)) return 0;
        double root = sqrt(p);
        L[j * k + j] = root;
        for (long r = j + 1; r < k; ++r) {
            double t = 0.0;
            for (long i = 0; i < j; ++i) t += L[r * k + i] * L[j * k + i];
            L[r * k + j] = (sign * g[r * k + j] - t) / root;
        }
    }
    return 1;
}

/* Per matrix: bounds of the smallest eigenvalue (lower, upper), of the largest (lower, upper)
   and a lower bound of the product of the eigenvalues, into out[5 m .. 5 m + 4]. */
void extreme_bounds(long n, long k, const double *g, double *out) {
    static const double loose[3] = {1e-4, 0.05, 0.5};
    double L[64], piv[8], x[8], y[8];
    for (long m = 0; m < n; ++m) {
        const double *G = g + m * k * k;
        double *o = out + 5 * m;
        double tr = 0.0;
        for (long i = 0; i < k; ++i) tr += G[i * k + i];
        double margin = 1e-12 * tr;
        /* The product: pivots of G - margin I (zero unless all positive). */
        int ok = factor(k, G, 0.0, L, piv);
        double product = 1.0;
        for (long j = 0; j < k; ++j) product *= piv[j];
        o[4] = ok ? product : 0.0;
        /* Smallest: inverse iteration with the factor of G + 1e-10 tr I (positive definite), six
           steps from ones; its Rayleigh quotient (+ margin) is an upper bound. */
        factor(k, G, -1e-10 * tr - 1e-300, L, piv);
        double inv_d[8];
        for (long i = 0; i < k; ++i) inv_d[i] = 1.0 / L[i * k + i];
        for (long i = 0; i < k; ++i) x[i] = 1.0;
        for (int it = 0; it < 6; ++it) {
            for (long i = 0; i < k; ++i) {
                double s = x[i];
                for (long j = 0; j < i; ++j) s -= L[i * k + j] * y[j];
                y[i] = s * inv_d[i];
            }
            double norm = 0.0;
            for (long i = k - 1; i >= 0; --i) {
                double s = y[i];
                for (long j = i + 1; j < k; ++j) s -= L[j * k + i] * x[j];
                x[i] = s * inv_d[i];
                norm += x[i] * x[i];
            }
            norm = 1.0 / sqrt(norm);
            for (long i = 0; i < k; ++i) x[i] *= norm;
        }
        double low = quotient(k, G, x);
        o[1] = low + margin;
        o[0] = 0.0;
        if (ok) /* G - margin I positive definite: the smallest eigenvalue is positive */
            for (int t = 0; t < 3; ++t) {
                double c = low * (1.0 - loose[t]);
                if (c > 0.0 && positive(k, G, 1.0, c, margin, L)) {
                    o[0] = c;
                    break;
                }
            }
        /* Largest: power iteration on G^32 (five squarings of G / tr G, each scaled by its trace),
           three steps from 1 + 0.1 i: its quotient with G (- margin) is a lower bound, and c I - G
           positive definite an upper bound c (else the trace). */
        double P[64], Q[64];
        for (long i = 0; i < k * k; ++i) P[i] = tr > 0.0 ? G[i] / tr : 0.0;
        for (int sq = 0; sq < 5; ++sq) {
            double t2 = 0.0;
            for (long i = 0; i < k; ++i)
                for (long j = i; j < k; ++j) {
                    double v = 0.0;
                    for (long l = 0; l < k; ++l) v += P[i * k + l] * P[j * k + l];
                    Q[i * k + j] = Q[j * k + i] = v;
                }
            for (long i = 0; i < k; ++i) t2 += Q[i * k + i];
            double scale = t2 > 0.0 ? 1.0 / t2 : 1.0;
            for (long i = 0; i < k * k; ++i) P[i] = Q[i] * scale;
        }
        for (long i = 0; i < k; ++i) x[i] = 1.0 + 0.1 * (double)i;
        for (int it = 0; it < 3; ++it) {
            double norm = 0.0;
            for (long i = 0; i < k; ++i) {
                double s = 0.0;
                for (long j = 0; j < k; ++j) s += P[i * k + j] * x[j];
                y[i] = s;
                norm += s * s;
            }
            if (!(norm > 0.0)) break; /* P x = 0: x stays */
            norm = sqrt(norm);
            for (long i = 0; i < k; ++i) x[i] = y[i] / norm;
        }
        double high = quotient(k, G, x);
        o[2] = high - margin;
        o[3] = tr + margin;
        for (int t = 0; t < 3; ++t) {
            double c = high * (1.0 + loose[t]);
            if (positive(k, G, -1.0, c, margin, L)) {
                o[3] = c < o[3] ? c : o[3];
                break;
            }
        }
    }
}

/* Gram matrices of (n, r, c) matrices: S S^T (r x r) when r <= c, else S^T S (c x c). */
void grams(long n, long r, long c, const double *S, double *out) {
    long k = r <= c ? r : c;
    for (long m = 0; m < n; ++m) {
        const double *A = S + m * r * c;
        double *G = out + m * k * k;
        for (long i = 0; i < k; ++i)
            for (long j = 0; j <= i; ++j) {
                double v = 0.0;
                if (r <= c)
                    for (long l = 0; l < c; ++l) v += A[i * c + l] * A[j * c + l];
                else
                    for (long l = 0; l < r; ++l) v += A[l * c + i] * A[l * c + j];
                G[i * k + j] = G[j * k + i] = v;
            }
    }
}
"""

_SIGNATURES = {
    "cholesky_certificates": [ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 4],
    "extreme_bounds": [ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 2],
    "grams": [ctypes.c_long, ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 2],
}


def _library() -> ctypes.CDLL | None:
    return load_functions(_SOURCE, "certificates", _SIGNATURES)


def cholesky_certificates(gram: np.ndarray, shift: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Whether each ``gram - shift I`` is positive definite, by a Cholesky factorisation.

    The shift is first raised by ``1e-12 tr(gram)`` (far above the factorisation's rounding,
    Demmel 1989): where every pivot is positive, every eigenvalue of `gram` exceeds `shift`
    and the product of their excesses is at least the product of the pivots.

    Args:
        gram: Symmetric matrices, shape (N, k, k).
        shift: One shift per matrix, shape (N,).

    Returns:
        The mask (N,) and the product of the pivots (0 where the mask is False), or None
        without the compiled library or for k above :data:`LARGEST`.

    Raises:
        InvalidArgumentError: If `gram` is not of shape (N, k, k) or `shift` not of shape (N,).
    """
    gram, shift = _square_batch(gram), np.ascontiguousarray(shift, dtype=float)
    n, k = gram.shape[0], gram.shape[1]
    if shift.shape != (n,):
        raise InvalidArgumentError(f"shift must have shape ({n},), got {shift.shape}")
    lib = _library()
    if lib is None or k > LARGEST:
        return None
    ok, product = np.empty(n, dtype=np.int64), np.empty(n)
    if n:
        lib.cholesky_certificates(n, k, gram.ctypes.data, shift.ctypes.data, ok.ctypes.data, product.ctypes.data)
    return ok.astype(bool), product


def extreme_bounds(gram: np.ndarray) -> np.ndarray | None:
    """Bounds of the smallest and the largest eigenvalue of each symmetric positive semi-definite `gram`.

    The smallest: an upper bound from the Rayleigh quotient ``x^T G x / x^T x`` (at least the
    smallest eigenvalue for any ``x``) after six steps of inverse iteration, and a lower bound
    ``c`` where ``G - c I`` is shown positive definite by :func:`cholesky_certificates`' test at
    ``c`` 1e-4 below the quotient, else 5 % or 50 % below, else 0. The largest: a lower bound
    from the quotient after three steps of power iteration on ``G^32`` (five squarings), and an
    upper bound ``c`` where ``c I - G`` is shown positive definite (``c`` 1e-4, else 5 % or 50 %
    above the quotient), else the trace. The product of the eigenvalues (the determinant): at
    least the product of the pivots of ``G`` when they are all positive, else 0. Each quotient
    and factorisation is moved by ``1e-12 tr(G)``, far above their rounding (Demmel 1989).

    Args:
        gram: Symmetric positive semi-definite matrices, shape (N, k, k).

    Returns:
        Shape (N, 5): per matrix ``(smallest lower, smallest upper, largest lower, largest
        upper, product lower)``, or None without the compiled library or for k above
        :data:`LARGEST`.

    Raises:
        InvalidArgumentError: If `gram` is not of shape (N, k, k).
    """
    gram = _square_batch(gram)
    n, k = gram.shape[0], gram.shape[1]
    lib = _library()
    if lib is None or k > LARGEST:
        return None
    out = np.empty((n, 5))
    if n:
        lib.extreme_bounds(n, k, gram.ctypes.data, out.ctypes.data)
    return out


def grams(matrices: np.ndarray) -> np.ndarray | None:
    """``S S^T`` of each matrix `S` of `matrices` (N, r, c), or ``S^T S`` for tall ones (r > c).

    Each entry a dot product summed in order (rounding below ``c eps |s_i| |s_j|``, covered by
    the margins of :func:`cholesky_certificates` and :func:`extreme_bounds`).

    Returns:
        Shape (N, k, k) with ``k = min(r, c)``, or None without the compiled library or for k
        above :data:`LARGEST`.

    Raises:
        InvalidArgumentError: If `matrices` is not of shape (N, r, c).
    """
    matrices = np.ascontiguousarray(matrices, dtype=float)
    if matrices.ndim != 3:
        raise InvalidArgumentError(f"matrices must have shape (N, r, c), got {matrices.shape}")
    n, r, c = matrices.shape
    k = min(r, c)
    lib = _library()
    if lib is None or k > LARGEST:
        return None
    out = np.empty((n, k, k))
    if n and k:
        lib.grams(n, r, c, matrices.ctypes.data, out.ctypes.data)
    return out


def _square_batch(gram: np.ndarray) -> np.ndarray:
    """`gram` as a C-contiguous float array, checked to be of shape (N, k, k) (the C loops read N k^2 values)."""
    gram = np.ascontiguousarray(gram, dtype=float)
    if gram.ndim != 3 or gram.shape[1] != gram.shape[2]:
        raise InvalidArgumentError(f"gram must have shape (N, k, k), got {gram.shape}")
    return gram
