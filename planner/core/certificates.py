"""Cholesky certificates and eigenvalue bounds of many small symmetric matrices, in compiled loops.

The singularity measure (:func:`planner.motion.singularity.bounded_conditioning`) factors a few
hundred 3 x 3 to 6 x 6 Gram matrices at a time. Written out over the batch in NumPy that takes
a few dozen array operations per call whatever the batch size; here one C loop (compiled once
and cached by :mod:`planner.core.native`) does the same arithmetic, matrix by matrix, in the
same order. :func:`interval_certificates` and :func:`own_certificates` run the measure's steps
0 to 3 themselves, row by row. The functions return None (False) where the library cannot be
built (no compiler, ``PLANNER_JIT=0``) or for matrices larger than :data:`LARGEST`; the caller
then takes its NumPy path.
"""

from __future__ import annotations

import ctypes

import numpy as np

from planner.core.native import load_functions
from planner.exceptions import InvalidArgumentError

__all__ = [
    "LARGEST",
    "MOST_JOINTS",
    "anchor_bounds",
    "cholesky_certificates",
    "extreme_bounds",
    "grams",
    "interval_certificates",
    "own_certificates",
]

#: Largest matrix size the compiled loops take.
LARGEST = 8

#: Most joints :func:`interval_certificates` takes (its per-joint arrays live on the C stack);
#: longer chains take the NumPy path.
MOST_JOINTS = 256

_SOURCE = r"""
#include <math.h>
#include <float.h>

/* Loops unrolled (GCC; other compilers ignore it): the same operations in the same order, without
   the counters and branches of loops a few iterations long (about a fifth of this file's
   instructions on bench_collision's plans). */
#pragma GCC optimize("unroll-loops")

/* Every helper is inlined into the exported loops, and each loop is built once per common size
   (k = 3 or 6; m = 3 or 6 task rows of 6 or 7 joints) besides the general one: with the sizes
   constant the compiler unrolls the small loops. The arithmetic and its order are the same. */
#define INLINE static inline __attribute__((always_inline))

/* x^k and x^(k/2) for x >= 0 by multiplications (and one root for odd k): a few roundings (of
   the order of k ulp), far below the 1e-9 every bound they enter gives up; cheaper than pow. */
INLINE double int_power(double x, long k) {
    double r = 1.0;
    for (long i = 0; i < k; ++i) r *= x;
    return r;
}

INLINE double half_power(double x, long k) {
    double r = (k & 1) ? sqrt(x) : 1.0;
    for (long i = 0; i < k / 2; ++i) r *= x;
    return r;
}

/* A lower bound of det(M - c I) = prod(mu_i - c) over the symmetric k x k matrices M whose
   eigenvalues mu_i lie in [m2, T] and whose determinant is at least P (0 unless c < m2). The
   product grows with each mu_i: least where prod(mu_i) = P, raised to m2^k (and at most T^k);
   in x_i = log(mu_i) it is the sum of the concave log(e^x - c) over the polytope sum(x_i) =
   log(P), x_i in [log(m2), log(T)], so least at a vertex: j of the mu_i at m2, k - 1 - j at T
   and one between (for j where that one is at most T; one below m2 is taken at m2, a point of
   product above P: no lower than the least). */
INLINE double shifted_det(long k, double m2, double T, double P, double c) {
    if (!(m2 > c)) return 0.0;
    double low = int_power(m2, k), high = int_power(T, k);
    P = P > low ? P : low;
    P = P < high ? P : high;
    double least = INFINITY;
    for (long j = 0; j < k; ++j) {
        double mu = P / (int_power(m2, j) * int_power(T, k - 1 - j));
        if (!(mu <= T * (1.0 + 1e-12))) continue; /* no vertex with j at m2 */
        mu = mu < m2 ? m2 : (mu > T ? T : mu);
        double v = int_power(m2 - c, j) * int_power(T - c, k - 1 - j) * (mu - c);
        least = v < least ? v : least;
    }
    return least < INFINITY ? least : int_power(m2 - c, k);
}

/* Cholesky factor L (row-major, lower) of g - (shift + 1e-12 tr g) I and its pivots; 1 if all > 0. */
INLINE int factor(long k, const double *g, double shift, double *L, double *piv) {
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

INLINE double quotient(long k, const double *g, const double *x) {
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
INLINE int positive(long k, const double *g, double sign, double shift, double margin, double *L) {
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

/* `iterations` steps of the power method x <- M x / |M x| (y: work space); x stays where M x = 0. */
INLINE void power_steps(long k, const double *M, double *x, double *y, int iterations) {
    for (int it = 0; it < iterations; ++it) {
        double norm = 0.0;
        for (long i = 0; i < k; ++i) {
            double v = 0.0;
            for (long j = 0; j < k; ++j) v += M[i * k + j] * x[j];
            y[i] = v;
            norm += v * v;
        }
        if (!(norm > 0.0)) break;
        norm = 1.0 / sqrt(norm);
        for (long i = 0; i < k; ++i) x[i] = y[i] * norm;
    }
}

/* `iterations` steps of inverse iteration x <- A^-1 x / |A^-1 x|, A = L L^T (L lower, row-major; y: work space). */
INLINE void inverse_steps(long k, const double *L, double *x, double *y, int iterations) {
    for (int it = 0; it < iterations; ++it) {
        for (long i = 0; i < k; ++i) {
            double v = x[i];
            for (long j = 0; j < i; ++j) v -= L[i * k + j] * y[j];
            y[i] = v / L[i * k + i];
        }
        double norm = 0.0;
        for (long i = k - 1; i >= 0; --i) {
            double v = y[i];
            for (long j = i + 1; j < k; ++j) v -= L[j * k + i] * x[j];
            x[i] = v / L[i * k + i];
            norm += x[i] * x[i];
        }
        norm = 1.0 / sqrt(norm);
        for (long i = 0; i < k; ++i) x[i] *= norm;
    }
}

/* bracket's bounds of one matrix G into o[0 .. 4] from vectors vl, vh (any: the Rayleigh quotient
   at vl is at least the smallest eigenvalue, at vh at most the largest; near the eigenvectors, the
   bounds are tight): the smallest eigenvalue's upper bound (quotient + margin) and lower bound c,
   1e-7, 1e-4, 5 % or 50 % below the quotient, where G - c I - margin I is positive definite (else
   0; only where ok: G - margin I positive definite); the largest's lower bound (quotient -
   margin) and upper bound c, as much above its quotient, where c I - G - margin I is (else the
   trace + margin); the product of G's eigenvalues from below (`product`, the pivots of G -
   margin I, where ok; else 0). margin = 1e-12 tr G. L: work space. */
INLINE void bounds_from_vectors(long k, const double *G, double tr, int ok, double product, const double *vl,
                                const double *vh, double *L, double *o) {
    static const double loose[4] = {1e-7, 1e-4, 0.05, 0.5};
    double margin = 1e-12 * tr;
    o[4] = ok ? product : 0.0;
    double low = quotient(k, G, vl);
    o[1] = low + margin;
    o[0] = 0.0;
    if (ok) /* G - margin I positive definite: the smallest eigenvalue is positive */
        for (int t = 0; t < 4; ++t) {
            double c = low * (1.0 - loose[t]);
            if (c > 0.0 && positive(k, G, 1.0, c, margin, L)) {
                o[0] = c;
                break;
            }
        }
    double high = quotient(k, G, vh);
    o[2] = high - margin;
    o[3] = tr + margin;
    for (int t = 0; t < 4; ++t) {
        double c = high * (1.0 + loose[t]);
        if (positive(k, G, -1.0, c, margin, L)) {
            o[3] = c < o[3] ? c : o[3];
            break;
        }
    }
}

/* Power iteration on G^(2^squarings) (squarings of G / tr G, each scaled by its trace), `steps`
   steps from x (x stays where a step gives 0). */
INLINE void top_vector(long k, const double *G, double tr, double *x, int squarings, int steps) {
    double P[64], Q[64], y[8];
    for (long i = 0; i < k * k; ++i) P[i] = tr > 0.0 ? G[i] / tr : 0.0;
    for (int sq = 0; sq < squarings; ++sq) {
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
    for (int it = 0; it < steps; ++it) {
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
}

/* Per matrix: bounds of the smallest eigenvalue (lower, upper), of the largest (lower, upper)
   and a lower bound of the product of the eigenvalues of one matrix G, into o[0 .. 4]
   (bounds_from_vectors); the vectors they come from into vl and vh (k each), from no estimate. */
INLINE void bracket(long k, const double *G, double *o, double *vl, double *vh) {
    double L[64], piv[8], y[8];
    double tr = 0.0;
    for (long i = 0; i < k; ++i) tr += G[i * k + i];
    /* The product: pivots of G - margin I (zero unless all positive). */
    int ok = factor(k, G, 0.0, L, piv);
    double product = 1.0;
    for (long j = 0; j < k; ++j) product *= piv[j];
    /* Smallest: power iteration on M^4, M the inverse of G + 1e-10 tr I (positive definite,
       from its factor), two steps from ones (inverse iteration, eight steps). */
    factor(k, G, -1e-10 * tr - 1e-300, L, piv);
    double W[64], M[64], N[64];
    for (long i = 0; i < k; ++i) {
        W[i * k + i] = 1.0 / L[i * k + i];
        for (long j = 0; j < i; ++j) {
            double s = 0.0;
            for (long l = j; l < i; ++l) s += L[i * k + l] * W[l * k + j];
            W[i * k + j] = -s * W[i * k + i];
        }
    }
    double trace_m = 0.0;
    for (long i = 0; i < k; ++i)
        for (long j = 0; j <= i; ++j) {
            double s = 0.0;
            for (long l = i; l < k; ++l) s += W[l * k + i] * W[l * k + j];
            M[i * k + j] = M[j * k + i] = s;
            if (i == j) trace_m += s;
        }
    for (int sq = 0; sq < 2; ++sq) {
        double t2 = 0.0, scale = trace_m > 0.0 ? 1.0 / trace_m : 1.0;
        for (long i = 0; i < k; ++i)
            for (long j = i; j < k; ++j) {
                double v = 0.0;
                for (long l = 0; l < k; ++l) v += M[i * k + l] * M[j * k + l];
                N[i * k + j] = N[j * k + i] = v * scale * scale;
            }
        for (long i = 0; i < k; ++i) t2 += N[i * k + i];
        for (long i = 0; i < k * k; ++i) M[i] = N[i];
        trace_m = t2;
    }
    for (long i = 0; i < k; ++i) vl[i] = 1.0;
    power_steps(k, M, vl, y, 2);
    /* Largest: power iteration on G^32, three steps from 1 + 0.1 i. */
    for (long i = 0; i < k; ++i) vh[i] = 1.0 + 0.1 * (double)i;
    top_vector(k, G, tr, vh, 5, 3);
    bounds_from_vectors(k, G, tr, ok, product, vl, vh, L, o);
}

/* bracket's bounds of G from estimates vl, vh of its extreme eigenvectors (a neighbour's vectors
   along a trajectory), refined in place by WARM_STEPS steps of inverse iteration (with the factor
   of G - 1e-12 tr I) and of power iteration, where G - 1e-12 tr I is positive definite (else
   bracket from no estimate). */
#ifndef WARM_STEPS
#define WARM_STEPS 3
#endif
#ifndef WARM_POWER_STEPS
#define WARM_POWER_STEPS 4
#endif
#ifndef WARM_SQUARINGS
#define WARM_SQUARINGS 1
#endif
INLINE void bracket_warm(long k, const double *G, double *o, double *vl, double *vh) {
    double L[64], piv[8], y[8], tr = 0.0;
    for (long i = 0; i < k; ++i) tr += G[i * k + i];
    if (!factor(k, G, 0.0, L, piv)) {
        bracket(k, G, o, vl, vh);
        return;
    }
    double product = 1.0;
    for (long j = 0; j < k; ++j) product *= piv[j];
    inverse_steps(k, L, vl, y, WARM_STEPS);
    top_vector(k, G, tr, vh, WARM_SQUARINGS, WARM_POWER_STEPS);
    bounds_from_vectors(k, G, tr, 1, product, vl, vh, L, o);
    if (!(isfinite(o[1]) && isfinite(o[2]))) /* vectors lost (not finite): from no estimate */
        bracket(k, G, o, vl, vh);
}

/* bracket, from the vectors vl, vh of the previous matrix Gp where *warm is set and G is within
   WARM_NEAR tr G of it (Frobenius norm; bracket_warm), else from no estimate (bracket). Then vl, vh
   and Gp hold G's for the next, and *warm is set. */
#ifndef WARM_NEAR
#define WARM_NEAR 0.05
#endif
INLINE void bracket_from(long k, const double *G, double *o, double *vl, double *vh, double *Gp, int *warm) {
    double tr = 0.0, change = 0.0;
    for (long i = 0; i < k; ++i) tr += G[i * k + i];
    for (long i = 0; i < k * k; ++i) {
        change += (G[i] - Gp[i]) * (G[i] - Gp[i]);
        Gp[i] = G[i];
    }
    if (*warm && change <= WARM_NEAR * WARM_NEAR * tr * tr)
        bracket_warm(k, G, o, vl, vh);
    else
        bracket(k, G, o, vl, vh);
    *warm = 1;
}

INLINE void extreme_bounds_of(long n, long k, const double *g, double *out) {
    double vl[8], vh[8];
    for (long m = 0; m < n; ++m) bracket(k, g + m * k * k, out + 5 * m, vl, vh);
}

void extreme_bounds(long n, long k, const double *g, double *out) {
    if (k == 3) extreme_bounds_of(n, 3, g, out);
    else if (k == 6) extreme_bounds_of(n, 6, g, out);
    else extreme_bounds_of(n, k, g, out);
}

/* Gram matrices of (n, r, c) matrices: S S^T (r x r) when r <= c, else S^T S (c x c). */
INLINE void grams_of(long n, long r, long c, const double *S, double *out) {
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

INLINE void gram_one(long r, long c, const double *A, double *G) {
    grams_of(1, r, c, A, G);
}

/* A B^T + B A^T of two (r, c) matrices when r <= c, else A^T B + B^T A: the cross term of the Gram
   matrix of a combination of A and B. */
INLINE void cross_gram(long r, long c, const double *A, const double *B, double *C) {
    long k = r <= c ? r : c;
    for (long i = 0; i < k; ++i)
        for (long j = 0; j <= i; ++j) {
            double v = 0.0;
            if (r <= c)
                for (long l = 0; l < c; ++l) v += A[i * c + l] * B[j * c + l] + B[i * c + l] * A[j * c + l];
            else
                for (long l = 0; l < r; ++l) v += A[l * c + i] * B[l * c + j] + B[l * c + i] * A[l * c + j];
            C[i * k + j] = C[j * k + i] = v;
        }
}

/* jacobian_change_bound of one joint change u (dof). */
INLINE double change_bound(long dof, const double *u, const double *rho, double angular) {
    double before[dof], after[dof], sum = 0.0, a2 = 0.0, b2 = 0.0;
    for (long i = 0; i < dof; ++i) {
        before[i] = sum;
        sum += fabs(u[i]);
    }
    sum = 0.0;
    for (long i = dof - 1; i >= 0; --i) {
        sum += rho[i] * fabs(u[i]);
        after[i] = sum;
    }
    for (long i = 0; i < dof; ++i) {
        double a = rho[i] * before[i] + after[i];
        a2 += a * a;
        b2 += before[i] * before[i];
    }
    return sqrt(a2 + angular * angular * b2);
}

/* jacobian_curvature_bound of one joint change u (dof). */
INLINE double curvature_bound(long dof, const double *u, const double *rho, double angular) {
    double before[dof], turn[dof], a[dof], sum = 0.0, t = 0.0, c2 = 0.0, g2 = 0.0;
    for (long i = 0; i < dof; ++i) {
        double ui = fabs(u[i]);
        before[i] = sum;
        turn[i] = t;
        t += sum * ui;
        sum += ui;
    }
    sum = 0.0;
    for (long i = dof - 1; i >= 0; --i) {
        sum += rho[i] * fabs(u[i]);
        a[i] = rho[i] * before[i] + sum;
    }
    double tail = 0.0;
    for (long i = dof - 1; i >= 0; --i) {
        tail += (before[i] * rho[i] + a[i]) * fabs(u[i]);
        double g = turn[i] + before[i] * before[i];
        double c = g * rho[i] + 3.0 * before[i] * a[i] + turn[i] * rho[i] + tail;
        c2 += c * c;
        g2 += g * g;
    }
    return sqrt(c2 + angular * angular * g2);
}

/* Whether J_lam J_lam^T - f^2 I is positive definite for f = lift s_up + e (then every row
   within e of J_lam is above lift): raises *li to lift and *lm to the manipulability shown. */
INLINE void certify(long k, const double *G, double lift, double s_up, double e, double scale, double *L,
                    double *piv, double *li, double *lm) {
    double floor = lift * s_up + e;
    if (!factor(k, G, floor * floor, L, piv)) return;
    double det = 1.0;
    for (long i = 0; i < k; ++i) det *= piv[i];
    *li = *li > lift ? *li : lift;
    double ratio = floor > 0.0 ? e / floor : 0.0; /* s_i - e >= (s_i^2 - f^2)^(1/2) (1 - ratio^2)^(1/2) */
    double loss = 1.0 - ratio * ratio;
    double got = sqrt(det) * half_power(loss > 0.0 ? loss : 0.0, k) * (scale * (1.0 - 1e-9));
    *lm = *lm > got ? *lm : got;
}

/* tr(G^-1) of G = S S^T (or S^T S) for (m, dof) S: the squared Frobenius norm of the inverse of
   G's factor (inf where the factorisation fails). */
INLINE double inverse_trace(long m, long dof, const double *S) {
    long k = m < dof ? m : dof;
    double G[64], L[64], W[64], piv[8], sum = 0.0;
    gram_one(m, dof, S, G);
    if (!factor(k, G, 0.0, L, piv)) return INFINITY;
    for (long i = 0; i < k; ++i) {
        W[i * k + i] = 1.0 / L[i * k + i];
        sum += W[i * k + i] * W[i * k + i];
        for (long j = 0; j < i; ++j) {
            double s = 0.0;
            for (long l = j; l < i; ++l) s += L[i * k + l] * W[l * k + j];
            W[i * k + j] = -s * W[i * k + i];
            sum += W[i * k + j] * W[i * k + j];
        }
    }
    return sum;
}

/* A lower bound of prod(s_i - e) over the singular values s_i of a matrix with Gram matrix G, or 0:
   where G - f^2 I is positive definite (f > e), every s_i > f and s_i - e >= (s_i^2 - f^2)^(1/2)
   (1 - e^2 / f^2)^(1/2) (the square of the left side less that of the right is (f - s_i e / f)^2),
   so the product is at least the root of the pivots' product times (1 - e^2 / f^2)^(k / 2). The
   relative loss, about f^2 tr(G^-1) / 2 + k e^2 / (2 f^2), is least at f^2 = e (k / tr(G^-1))^(1/2);
   `inverse` estimates tr(G^-1) (any value gives a bound). */
INLINE double manipulability_alone(long k, const double *G, double e, double inverse, double *L, double *piv) {
    double shift = e * sqrt((double)k / inverse);
    if (!(shift > e * e) || !factor(k, G, shift, L, piv)) return 0.0;
    double det = 1.0;
    for (long i = 0; i < k; ++i) det *= piv[i];
    return sqrt(det) * half_power(1.0 - e * e / shift, k);
}

/* Unit estimates of the eigenvectors of the smallest and the largest eigenvalue of S S^T (or S^T S):
   inverse iteration (the factor of G + 1e-10 tr I) and power iteration, a few steps each. */
INLINE void extreme_vectors(long m, long dof, const double *S, double *low, double *high) {
    long k = m < dof ? m : dof;
    double G[64], L[64], piv[8], y[8], tr = 0.0;
    gram_one(m, dof, S, G);
    for (long i = 0; i < k; ++i) tr += G[i * k + i];
    factor(k, G, -1e-10 * tr - 1e-300, L, piv);
    for (long i = 0; i < k; ++i) low[i] = 1.0, high[i] = 1.0 + 0.1 * (double)i;
    inverse_steps(k, L, low, y, 4);
    power_steps(k, G, high, y, 6);
}

/* Where row qr lies along the line from qa by u (uu = |u|^2): its projection on it, clamped to
   [0, 1] (`fallback` where u = 0). Any lam in [0, 1] gives a bound; the projection a small one. */
INLINE double projection(long dof, const double *qa, const double *qr, const double *u, double uu, double fallback) {
    if (!(uu > 0.0)) return fallback;
    double dot = 0.0;
    for (long i = 0; i < dof; ++i) dot += (qr[i] - qa[i]) * u[i];
    double lam = dot / uu;
    return lam < 0.0 ? 0.0 : (lam > 1.0 ? 1.0 : lam);
}

/* Joint i's distance of row qr from the point qa + lam u, plus the rounding of that difference
   (a spacing of q at huge angles on continuous joints). */
INLINE double off_line(const double *qa, const double *qb, const double *qr, const double *u, double lam, long i) {
    return fabs(qr[i] - (qa[i] + lam * u[i])) + 2.0 * DBL_EPSILON * (fabs(qa[i]) + fabs(qb[i]) + fabs(qr[i]));
}

/* Steps 0 and 2 of bounded_conditioning over the rows between consecutive anchors.
   ends (na, 6) per anchor: top, bottom, product, min_up, max_low, value_up; least (na - 1) per
   interval; params: angular, threshold, level, lifted, level_man, scale. Per row between anchors:
   lo_inv, lo_man and flags (1 below, 2 not settled, 4 inverse condition number not settled). */
INLINE void interval_certificates_of(long n, long dof, long m, const double *q, long na, const long *anchors,
                           const double *S, const double *ends, const double *least, const double *rho,
                           const double *params, double *lo_inv, double *lo_man, long *flags) {
    double angular = params[0], threshold = params[1], level = params[2], lifted = params[3];
    double level_man = params[4], scale = params[5];
    long md = m * dof, k = m < dof ? m : dof;
    double u[dof], dev[dof], off[dof], J[md], G[64], L[64], piv[8];
    double va_low[8], va_high[8], vb_low[8], vb_high[8];
    double Ga[64], Gb[64], Gab[64], trace_a = 0.0, trace_b = 0.0;
    long grams_at = -1; /* the anchor whose Gram matrix Gb holds */
    long cached = -1; /* the anchor whose vectors vb_low, vb_high hold */
    long inverse_at = -1; /* the interval whose anchors' tr(G^-1) `inverse` holds */
    double inverse = INFINITY;
    (void)n;
    for (long j = 0; j + 1 < na; ++j) {
        long a = anchors[j], b = anchors[j + 1];
        if (b - a < 2) continue;
        const double *ea = ends + 6 * j, *eb = ends + 6 * (j + 1);
        const double *Sa = S + j * md, *Sb = S + (j + 1) * md;
        const double *qa = q + a * dof, *qb = q + b * dof;
        /* Step 0: each row r of a..b at its point q_a + lam_r u of the line from q_a to q_b
           (projection); dev, per joint, the largest distance of a row from its point. */
        double span = (double)(b - a), uu = 0.0;
        for (long i = 0; i < dof; ++i) {
            u[i] = qb[i] - qa[i];
            uu += u[i] * u[i];
            dev[i] = 0.0;
        }
        for (long r = a + 1; r < b; ++r) {
            const double *qr = q + r * dof;
            double lam = projection(dof, qa, qr, u, uu, (double)(r - a) / span);
            for (long i = 0; i < dof; ++i) {
                double o = off_line(qa, qb, qr, u, lam, i);
                if (o > dev[i]) dev[i] = o;
            }
        }
        for (long i = 0; i < dof; ++i) dev[i] *= 1.0 + 1e-9;
        double top = ea[0] > eb[0] ? ea[0] : eb[0];
        double margin = 1e-9 * (top + 1.0);
        double curvature = curvature_bound(dof, u, rho, angular);
        double err = (change_bound(dof, dev, rho, angular) + 0.125 * curvature) * (1.0 + 1e-9) + margin;
        double d = 0.0;
        for (long i = 0; i < md; ++i) d += (Sb[i] - Sa[i]) * (Sb[i] - Sa[i]);
        d = sqrt(d) * (1.0 + 1e-9);
        double smallest = (ea[1] < eb[1] ? ea[1] : eb[1]) - margin;
        smallest = smallest > 0.0 ? smallest : 0.0;
        double m2 = smallest * smallest, c = 0.25 * d * d;
        double sigma = sqrt(m2 - c > 0.0 ? m2 - c : 0.0);
        double inv0 = (sigma - err > 0.0 ? sigma - err : 0.0) / (top + margin + err);
        double shift = smallest > 0.0 ? 1.0 - margin / (smallest + margin) : 0.0;
        shift = int_power(shift > 0.0 ? shift : 0.0, k);
        double product = (ea[2] < eb[2] ? ea[2] : eb[2]) * shift, high = top + margin;
        double shrink = sigma > err ? int_power(1.0 - err / sigma > 0.0 ? 1.0 - err / sigma : 0.0, k) : 0.0;
        double man0 = sqrt(shifted_det(k, m2, high * high, product * product, c)) * shrink;
        double top_low = 0.5 * (ea[4] + eb[4] - d) - margin - err;
        double upper = top_low > 0.0 ? (0.5 * (ea[3] + eb[3] + d) + margin + err) / top_low * (1.0 + 1e-9) : INFINITY;
        int below = upper < threshold;
        int hopeless = ea[5] <= level && eb[5] <= level;
        double row_inv = inv0 * (1.0 - 1e-9), row_man = man0 * (scale * (1.0 - 1e-9));
        int vectors = 0, pair = 0; /* pair: Ga, Gb and Gab hold this interval's */
        for (long r = a + 1; r < b; ++r) {
            double li = row_inv, lm = row_man;
            int below_r = below;
            int settled_inv = li > level || (below && li > least[j]);
            int need_inv = !settled_inv && !hopeless;
            if (!settled_inv || !(lm > level_man)) {
                /* Step 2: the interpolation of the anchors' Jacobians, up to e. */
                const double *qr = q + r * dof;
                double lam = projection(dof, qa, qr, u, uu, (double)(r - a) / span);
                for (long i = 0; i < dof; ++i) off[i] = off_line(qa, qb, qr, u, lam, i);
                double e = change_bound(dof, off, rho, angular) + 0.5 * lam * (1.0 - lam) * curvature;
                double s_lam = (1.0 - lam) * ea[0] + lam * eb[0];
                e = e * (1.0 + 1e-9) + 1e-9 * (s_lam + 1.0);
                /* The Gram matrix of J_lam = (1 - lam) S_a + lam S_b from the anchors' (and their cross
                   term's), computed once per interval: its rounding is at most 12 eps ((1 - lam) tr G_a +
                   lam tr G_b) (each entry's, less than 12 eps w_i w_j with w_i = (1 - lam) |a_i| + lam |b_i|
                   for rows a_i, b_i), covered by the 1e-12 tr G_lam of every test on G where tr G_lam is
                   at least 1 % of that; else (cancellation) J_lam's own Gram matrix. */
                if (!pair) {
                    if (grams_at != j) {
                        gram_one(m, dof, Sa, Ga);
                        trace_a = 0.0;
                        for (long i = 0; i < k; ++i) trace_a += Ga[i * k + i];
                    } else
                        for (long i = 0; i < k * k; ++i) Ga[i] = Gb[i];
                    trace_a = grams_at == j ? trace_b : trace_a;
                    gram_one(m, dof, Sb, Gb);
                    trace_b = 0.0;
                    for (long i = 0; i < k; ++i) trace_b += Gb[i * k + i];
                    cross_gram(m, dof, Sa, Sb, Gab);
                    grams_at = j + 1;
                    pair = 1;
                }
                double wa = (1.0 - lam) * (1.0 - lam), wb = lam * lam, wab = lam * (1.0 - lam), tr_lam = 0.0;
                for (long i = 0; i < k * k; ++i) G[i] = wa * Ga[i] + wb * Gb[i] + wab * Gab[i];
                for (long i = 0; i < k; ++i) tr_lam += G[i * k + i];
                if (!(tr_lam >= 0.01 * ((1.0 - lam) * trace_a + lam * trace_b))) {
                    for (long i = 0; i < md; ++i) J[i] = (1.0 - lam) * Sa[i] + lam * Sb[i];
                    gram_one(m, dof, J, G);
                }
                if (need_inv) {
                    certify(k, G, lifted, s_lam + e, e, scale, L, piv, &li, &lm);
                    settled_inv = li > level || (below_r && li > least[j]);
                }
                if (!settled_inv && !below_r && li < threshold) {
                    /* From above: Rayleigh quotients of J_lam J_lam^T at the anchors' extreme
                       eigenvectors bound its extreme eigenvalues (the smallest from above, the
                       largest from below); the row's singular values are within e of J_lam's. */
                    if (!vectors) { /* b's vectors are the next interval's a's */
                        if (cached == j)
                            for (long i = 0; i < k; ++i) va_low[i] = vb_low[i], va_high[i] = vb_high[i];
                        else
                            extreme_vectors(m, dof, Sa, va_low, va_high);
                        extreme_vectors(m, dof, Sb, vb_low, vb_high);
                        vectors = 1;
                        cached = j + 1;
                    }
                    double tr = 0.0;
                    for (long i = 0; i < k; ++i) tr += G[i * k + i];
                    double q_low = quotient(k, G, va_low), q_low_b = quotient(k, G, vb_low);
                    double q_high = quotient(k, G, va_high), q_high_b = quotient(k, G, vb_high);
                    q_low = (q_low < q_low_b ? q_low : q_low_b) + 2e-12 * tr;
                    q_high = (q_high > q_high_b ? q_high : q_high_b) - 2e-12 * tr;
                    double top_low = sqrt(q_high > 0.0 ? q_high : 0.0) - e;
                    double up = (sqrt(q_low > 0.0 ? q_low : 0.0) + e) / top_low * (1.0 + 1e-9);
                    below_r = top_low > 0.0 && up < threshold;
                }
                if (!settled_inv && below_r) {
                    /* Shown below the threshold: above the stretch's least value suffices. */
                    certify(k, G, least[j] * (1.0 + 1e-9), s_lam + e, e, scale, L, piv, &li, &lm);
                    settled_inv = li > least[j];
                }
                if (settled_inv && !(lm > level_man)) {
                    /* The manipulability alone (manipulability_alone; tr(G^-1) estimated by the
                       anchors' larger). */
                    if (inverse_at != j) {
                        inverse = inverse_trace(m, dof, Sa);
                        double at_b = inverse_trace(m, dof, Sb);
                        inverse = inverse > at_b ? inverse : at_b;
                        inverse_at = j;
                    }
                    double got = manipulability_alone(k, G, e, inverse, L, piv) * (scale * (1.0 - 1e-9));
                    lm = lm > got ? lm : got;
                }
            }
            lo_inv[r] = li;
            lo_man[r] = lm;
            flags[r] = below_r | (settled_inv && lm > level_man ? 0 : 2) | (settled_inv ? 0 : 4);
        }
    }
}

/* The bracketed anchors of bounded_conditioning, (t, m, dof) scaled Jacobians: per anchor into
   out (t, 8) the largest singular value's upper bound, the smallest's lower bound, the product's
   lower bound, the smallest's upper bound, the largest's lower bound, the inverse condition
   number's lower and upper bounds and the manipulability's upper bound (times scale). */
INLINE void anchor_bounds_of(long t, long m, long dof, const double *S, double scale, double *out) {
    long md = m * dof, k = m < dof ? m : dof;
    double G[64], L[64], piv[8], o[5], vl[8], vh[8], Gp[64];
    int warm = 0; /* the previous anchor's vectors start this one's iterations */
    for (long r = 0; r < t; ++r) {
        double *w = out + 8 * r;
        gram_one(m, dof, S + r * md, G);
        bracket_from(k, G, o, vl, vh, Gp, &warm);
        double tr = 0.0, product = 1.0;
        for (long i = 0; i < k; ++i) tr += G[i * k + i];
        int ok = factor(k, G, -2e-12 * tr, L, piv);
        for (long i = 0; i < k; ++i) product *= piv[i];
        double l_min = o[0] > 0.0 ? o[0] : 0.0, l_max = o[2] > 0.0 ? o[2] : 0.0;
        w[0] = sqrt(o[3]);
        w[1] = sqrt(l_min);
        w[2] = sqrt(o[4] > 0.0 ? o[4] : 0.0);
        w[3] = sqrt(o[1]);
        w[4] = sqrt(l_max);
        w[5] = o[3] > 0.0 ? sqrt(l_min / o[3]) * (1.0 - 1e-9) : 0.0;
        double up = sqrt(o[1] / o[2]) * (1.0 + 1e-9);
        w[6] = o[2] > 0.0 && isfinite(up) ? up : INFINITY;
        w[7] = ok ? sqrt(product) * (1.0 + 1e-9) * scale : INFINITY;
    }
}

/* Step 3 of bounded_conditioning: rows (t, m, dof) of their own scaled Jacobians; lo_inv, lo_man
   and flags (as interval_certificates gives them) updated; least (t) per row; params: threshold,
   level, level_man, scale. */
INLINE void own_certificates_of(long t, long m, long dof, const double *S, const double *least, const double *params,
                      double *lo_inv, double *lo_man, long *flags) {
    double threshold = params[0], level = params[1], level_man = params[2], scale = params[3];
    long md = m * dof, k = m < dof ? m : dof;
    double G[64], L[64], piv[8], o[5], vl[8], vh[8], Gp[64];
    int warm = 0; /* the previous bracketed row's vectors start the next one's iterations */
    for (long r = 0; r < t; ++r) {
        int below = flags[r] & 1;
        double li = lo_inv[r], lm = lo_man[r], product = 0.0;
        int open_inv = !(li > level || (below && li > least[r]));
        gram_one(m, dof, S + r * md, G);
        if (open_inv) {
            bracket_from(k, G, o, vl, vh, Gp, &warm);
            product = o[4];
            double l_min = o[0] > 0.0 ? o[0] : 0.0;
            double low = o[3] > 0.0 ? sqrt(l_min / o[3]) * (1.0 - 1e-9) : 0.0;
            double up = sqrt(o[1] / o[2]) * (1.0 + 1e-9);
            if (!(o[2] > 0.0 && isfinite(up))) up = INFINITY;
            li = li > low ? li : low;
            if (up < threshold) below = 1;
        } else if (!(lm > level_man)) {
            int ok = factor(k, G, 0.0, L, piv);
            product = 1.0;
            for (long i = 0; i < k; ++i) product *= ok ? piv[i] : 0.0;
            product = ok ? product : 0.0;
        }
        double got = sqrt(product > 0.0 ? product : 0.0) * (scale * (1.0 - 1e-9));
        lm = lm > got ? lm : got;
        int settled_inv = li > level || (below && li > least[r]);
        lo_inv[r] = li;
        lo_man[r] = lm;
        flags[r] = below | (settled_inv && lm > level_man ? 0 : 2) | (settled_inv ? 0 : 4);
    }
}

/* CALL with m_ and d_ for m and dof: constants where they are a common pair. */
#define SIZED(m, dof, CALL)                                      \
    do {                                                         \
        if (m == 6 && dof == 6) { const long m_ = 6, d_ = 6; CALL; } \
        else if (m == 6 && dof == 7) { const long m_ = 6, d_ = 7; CALL; } \
        else if (m == 3 && dof == 6) { const long m_ = 3, d_ = 6; CALL; } \
        else if (m == 3 && dof == 7) { const long m_ = 3, d_ = 7; CALL; } \
        else { const long m_ = m, d_ = dof; CALL; }              \
    } while (0)

void grams(long n, long r, long c, const double *S, double *out) {
    SIZED(r, c, grams_of(n, m_, d_, S, out));
}

void interval_certificates(long n, long dof, long m, const double *q, long na, const long *anchors,
                           const double *S, const double *ends, const double *least, const double *rho,
                           const double *params, double *lo_inv, double *lo_man, long *flags) {
    SIZED(m, dof,
          interval_certificates_of(n, d_, m_, q, na, anchors, S, ends, least, rho, params, lo_inv, lo_man, flags));
}

void anchor_bounds(long t, long m, long dof, const double *S, double scale, double *out) {
    SIZED(m, dof, anchor_bounds_of(t, m_, d_, S, scale, out));
}

void own_certificates(long t, long m, long dof, const double *S, const double *least, const double *params,
                      double *lo_inv, double *lo_man, long *flags) {
    SIZED(m, dof, own_certificates_of(t, m_, d_, S, least, params, lo_inv, lo_man, flags));
}
"""

_SIGNATURES = {
    "cholesky_certificates": [ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 4],
    "extreme_bounds": [ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 2],
    "grams": [ctypes.c_long, ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 2],
    "interval_certificates": [*[ctypes.c_long] * 3, ctypes.c_void_p, ctypes.c_long, *[ctypes.c_void_p] * 9],
    "own_certificates": [*[ctypes.c_long] * 3, *[ctypes.c_void_p] * 6],
    "anchor_bounds": [*[ctypes.c_long] * 3, ctypes.c_void_p, ctypes.c_double, ctypes.c_void_p],
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
    smallest eigenvalue for any ``x``) after two power steps on ``M^4``, ``M`` the inverse of
    ``G + 1e-10 tr(G) I`` (inverse iteration, eight steps), and a lower bound
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


def interval_certificates(
    q: np.ndarray,
    anchors: np.ndarray,
    scaled: np.ndarray,
    ends: np.ndarray,
    least: np.ndarray,
    rho: np.ndarray,
    params: tuple[float, float, float, float, float, float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Steps 0 and 2 of :func:`planner.motion.singularity.bounded_conditioning` in one compiled loop.

    The same bounds as its NumPy path, interval by interval and row by row: step 0's bounds of
    the interval, then the certificates of the interpolated Jacobian ``J_lam`` (above the level
    where not both anchors are at or below it; above the stretch's least value where the row is
    shown below the threshold; the manipulability alone where the inverse condition number is
    settled), its Gram matrix taken as ``(1 - lam)^2 G_a + lam^2 G_b + lam (1 - lam) (S_a S_b^T +
    S_b S_a^T)`` from the anchors' (computed once per interval; its rounding, below ``12 eps ((1 -
    lam) tr G_a + lam tr G_b)``, is covered by the tests' ``1e-12 tr`` margins, and ``J_lam``'s own
    is taken where cancellation leaves its trace under 1 % of that). Compiled only: where step 0
    does not show a row below the threshold (and its lower bound is under it), the Rayleigh
    quotients of ``J_lam J_lam^T`` at the two anchors' estimated eigenvectors of their smallest
    and largest eigenvalues (a few steps of inverse and power iteration) bound its extreme
    eigenvalues from above and from below (any unit vector does; ``2e-12 tr`` covers their
    rounding), and ``e`` more or less those of the row (Weyl): a quotient under the threshold
    shows the row below it. Also compiled only: each row is taken
    at its projection ``lam`` on the line between its anchors (clamped to [0, 1]; the NumPy path
    takes ``(r - a) / (b - a)``), in step 0's deviation from the line (the rows' largest distance
    from their points on it, per joint, instead of the second differences' bound) and in step 2's
    interpolation: any ``lam`` in [0, 1] gives the bounds, and a row on the line (a straight
    joint move, however it is timed) is then off it only by rounding, where the row's fraction of
    the interval is off it by as much as the timing bends (a move's slow start and end).

    Args:
        q: Configurations, shape (n, dof).
        anchors: Sorted rows with known Jacobians, shape (na,), first 0 and last n - 1.
        scaled: Their scaled Jacobians, shape (na, m, dof).
        ends: Per anchor ``(top, bottom, product, min_up, max_low, value_up)``, shape (na, 6).
        least: Per interval between anchors, the least value of its stretch, shape (na - 1,).
        rho: Per joint, the chain lengths of :func:`~planner.motion.singularity.jacobian_change_bounds`.
        params: ``(angular, threshold, level, lifted, level_man, scale)``.

    Returns:
        Per row (n,), valid between anchors: ``lo_inv``, ``lo_man`` and flags (1: shown below the
        threshold, 2: not settled, 4: the inverse condition number not settled); None without
        the compiled library, for k above :data:`LARGEST` or more than :data:`MOST_JOINTS`
        joints or task rows.
    """
    q = np.ascontiguousarray(q, dtype=float)
    anchors = np.ascontiguousarray(anchors, dtype=np.int64)
    scaled, ends = np.ascontiguousarray(scaled, dtype=float), np.ascontiguousarray(ends, dtype=float)
    least, rho = np.ascontiguousarray(least, dtype=float), np.ascontiguousarray(rho, dtype=float)
    if q.ndim != 2 or scaled.ndim != 3:
        raise InvalidArgumentError(f"q must have shape (n, dof) and scaled (na, m, dof), got {q.shape}, {scaled.shape}")
    (n, dof), na, m = q.shape, len(anchors), scaled.shape[1]
    if (
        anchors.ndim != 1
        or scaled.shape != (na, m, dof)
        or ends.shape != (na, 6)
        or least.shape != (max(na - 1, 0),)
        or rho.shape != (dof,)
        or len(params) != 6
        or (na and (anchors[0] < 0 or anchors[-1] >= n or np.any(np.diff(anchors) <= 0)))
    ):
        raise InvalidArgumentError(
            "interval_certificates: arrays of mismatched shapes or anchors not rows of q in order"
        )
    lib = _library()
    if lib is None or min(m, dof) > LARGEST or dof > MOST_JOINTS or m > MOST_JOINTS:
        return None
    values = np.array(params, dtype=float)
    lo_inv, lo_man, flags = np.zeros(n), np.zeros(n), np.zeros(n, dtype=np.int64)
    lib.interval_certificates(
        n,
        dof,
        m,
        q.ctypes.data,
        len(anchors),
        anchors.ctypes.data,
        scaled.ctypes.data,
        ends.ctypes.data,
        least.ctypes.data,
        rho.ctypes.data,
        values.ctypes.data,
        lo_inv.ctypes.data,
        lo_man.ctypes.data,
        flags.ctypes.data,
    )
    return lo_inv, lo_man, flags


def anchor_bounds(scaled: np.ndarray, scale: float) -> np.ndarray | None:
    """Bounds of the singular values of scaled Jacobians from their Gram matrices, in one compiled loop.

    For the anchors :func:`planner.motion.singularity.bounded_conditioning` brackets: the square
    roots of :func:`extreme_bounds`' bounds (negative lower bounds taken as 0), with one change:
    where a matrix's Gram matrix lies within 5 % of its trace (Frobenius norm) of the previous
    one's, as along a trajectory, the Rayleigh quotients are taken at the previous matrix's
    vectors after three steps of inverse iteration (with the factor of ``G - 1e-12 tr(G) I``)
    and four of power iteration on ``G^2`` instead of from fixed starts (any vectors give the
    bounds; these, far cheaper, about as tight), the inverse condition
    number bracketed from them (each side widened by 1e-9; 0 and inf where nothing is shown) and
    the manipulability from above (the root of the pivots' product of ``G + 1e-12 tr(G) I``,
    widened by 1e-9, times `scale`; inf where that factorisation fails).

    Args:
        scaled: Matrices, shape (t, m, dof).
        scale: The manipulability over the product of the singular values.

    Returns:
        Shape (t, 8): per matrix ``(s_max upper, s_min lower, product lower, s_min upper, s_max
        lower, inverse condition lower, inverse condition upper, manipulability upper)``, or
        None without the compiled library or for k above :data:`LARGEST`.

    Raises:
        InvalidArgumentError: If `scaled` is not of shape (t, m, dof).
    """
    scaled = np.ascontiguousarray(scaled, dtype=float)
    if scaled.ndim != 3:
        raise InvalidArgumentError(f"scaled must have shape (t, m, dof), got {scaled.shape}")
    t, m, dof = scaled.shape
    lib = _library()
    if lib is None or min(m, dof) > LARGEST:
        return None
    out = np.empty((t, 8))
    if t:
        lib.anchor_bounds(t, m, dof, scaled.ctypes.data, float(scale), out.ctypes.data)
    return out


def own_certificates(
    scaled: np.ndarray,
    least: np.ndarray,
    lo_inv: np.ndarray,
    lo_man: np.ndarray,
    flags: np.ndarray,
    params: tuple[float, float, float, float],
) -> bool:
    """Step 3 of :func:`planner.motion.singularity.bounded_conditioning` in one compiled loop, in place.

    Per row, from its own scaled Jacobian's Gram matrix: the inverse condition number bracketed
    (:func:`extreme_bounds`; from the previous row's vectors where its Gram matrix is near, as in
    :func:`anchor_bounds`) where it is open, else the manipulability's factorisation where that
    is open, as the NumPy path does.

    Args:
        scaled: The rows' scaled Jacobians, shape (t, m, dof).
        least: Per row, the least value of its stretch, shape (t,).
        lo_inv: Lower bounds of the inverse condition number (t,), raised in place.
        lo_man: Lower bounds of the manipulability (t,), raised in place.
        flags: As :func:`interval_certificates` gives them (t,) (int64), updated in place.
        params: ``(threshold, level, level_man, scale)``.

    Returns:
        False (nothing changed) without the compiled library or for k above :data:`LARGEST`.
    """
    if np.ndim(scaled) != 3 or len(params) != 4:
        raise InvalidArgumentError(f"scaled must have shape (t, m, dof) and params 4 values, got {np.shape(scaled)}")
    lib = _library()
    t, m, dof = scaled.shape
    if lib is None or min(m, dof) > LARGEST:
        return False
    if np.shape(least) != (t,):
        raise InvalidArgumentError(f"least must have shape ({t},), got {np.shape(least)}")
    for array, kind in ((lo_inv, np.float64), (lo_man, np.float64), (flags, np.int64)):
        if array.dtype != kind or not array.flags.c_contiguous or array.shape != (t,):
            raise InvalidArgumentError(f"own_certificates needs C-contiguous {kind.__name__} arrays of shape ({t},)")
    scaled, least = np.ascontiguousarray(scaled, dtype=float), np.ascontiguousarray(least, dtype=float)
    values = np.array(params, dtype=float)
    if t:
        lib.own_certificates(
            t,
            m,
            dof,
            scaled.ctypes.data,
            least.ctypes.data,
            values.ctypes.data,
            lo_inv.ctypes.data,
            lo_man.ctypes.data,
            flags.ctypes.data,
        )
    return True


def _square_batch(gram: np.ndarray) -> np.ndarray:
    """`gram` as a C-contiguous float array, checked to be of shape (N, k, k) (the C loops read N k^2 values)."""
    gram = np.ascontiguousarray(gram, dtype=float)
    if gram.ndim != 3 or gram.shape[1] != gram.shape[2]:
        raise InvalidArgumentError(f"gram must have shape (N, k, k), got {gram.shape}")
    return gram
