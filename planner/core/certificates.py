"""Cholesky certificates and Rayleigh bounds of many small symmetric matrices, in compiled loops.

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

__all__ = ["LARGEST", "cholesky_certificates", "rayleigh_bounds"]

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

void rayleigh_bounds(long n, long k, const double *g, double *smallest, double *largest) {
    double L[64], piv[8], x[8], y[8];
    for (long m = 0; m < n; ++m) {
        const double *G = g + m * k * k;
        factor(k, G, 0.0, L, piv);
        double tr = 0.0;
        for (long i = 0; i < k; ++i) tr += G[i * k + i];
        double margin = 1e-12 * tr;
        for (long i = 0; i < k; ++i) x[i] = 1.0;
        for (int it = 0; it < 2; ++it) {
            for (long i = 0; i < k; ++i) {
                double s = 0.0;
                for (long j = 0; j < i; ++j) s += L[i * k + j] * y[j];
                y[i] = (x[i] - s) / L[i * k + i];
            }
            for (long i = k - 1; i >= 0; --i) {
                double s = 0.0;
                for (long j = i + 1; j < k; ++j) s += L[j * k + i] * x[j];
                x[i] = (y[i] - s) / L[i * k + i];
            }
            double norm = 0.0;
            for (long i = 0; i < k; ++i) norm += x[i] * x[i];
            norm = sqrt(norm);
            for (long i = 0; i < k; ++i) x[i] /= norm;
        }
        smallest[m] = quotient(k, G, x) + margin;
        for (long i = 0; i < k; ++i) x[i] = 1.0 + 0.1 * (double)i;
        for (int it = 0; it < 3; ++it) {
            double norm = 0.0;
            for (long i = 0; i < k; ++i) {
                double s = 0.0;
                for (long j = 0; j < k; ++j) s += G[i * k + j] * x[j];
                y[i] = s;
                norm += s * s;
            }
            norm = sqrt(norm);
            for (long i = 0; i < k; ++i) x[i] = y[i] / (norm > 0.0 ? norm : 1.0);
        }
        largest[m] = quotient(k, G, x) - margin;
    }
}
"""

_SIGNATURES = {
    "cholesky_certificates": [ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 4],
    "rayleigh_bounds": [ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 3],
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


def rayleigh_bounds(gram: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """An upper bound of the smallest and a lower bound of the largest eigenvalue of each `gram`.

    Rayleigh quotients ``x^T G x / x^T x``: for the smallest, ``x`` after two steps of inverse
    iteration from ones (solves with the Cholesky factor of ``G - 1e-12 tr(G) I``), for the
    largest after three steps of power iteration from ``1 + 0.1 i``; the rounding of the
    quotients (below ``k eps tr(G)``) is covered by ``1e-12 tr(G)``.

    Args:
        gram: Symmetric positive definite matrices (those :func:`cholesky_certificates` shows
            so with no shift), shape (N, k, k).

    Returns:
        ``(upper bounds of the smallest eigenvalues, lower bounds of the largest)``, each (N,),
        or None without the compiled library or for k above :data:`LARGEST`.

    Raises:
        InvalidArgumentError: If `gram` is not of shape (N, k, k).
    """
    gram = _square_batch(gram)
    n, k = gram.shape[0], gram.shape[1]
    lib = _library()
    if lib is None or k > LARGEST:
        return None
    smallest, largest = np.empty(n), np.empty(n)
    if n:
        lib.rayleigh_bounds(n, k, gram.ctypes.data, smallest.ctypes.data, largest.ctypes.data)
    return smallest, largest


def _square_batch(gram: np.ndarray) -> np.ndarray:
    """`gram` as a C-contiguous float array, checked to be of shape (N, k, k) (the C loops read N k^2 values)."""
    gram = np.ascontiguousarray(gram, dtype=float)
    if gram.ndim != 3 or gram.shape[1] != gram.shape[2]:
        raise InvalidArgumentError(f"gram must have shape (N, k, k), got {gram.shape}")
    return gram
