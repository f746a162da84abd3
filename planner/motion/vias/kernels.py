"""Compiled loops of the via search: the per-joint option choices and the time-scaled via states.

:func:`planner.motion.vias.base.best_choice` (a sweep over every option's times, run once per
via), :func:`planner.motion.vias.optimized._joint_choice` (its counterpart along a run, once per
run) and :func:`planner.motion.vias.optimized._scaled_states` (a few NumPy operations on arrays
of a few dozen entries) cost more in Python's and NumPy's call overhead than in arithmetic.
Here each is one C function (:mod:`planner.core.native`, compiled once), with the same
comparisons and operations in the same order: the same values bit for bit, the sign of a zero
included (``np.minimum`` and ``np.maximum`` return their second argument on a tie, as the C
does; the tests compare both paths). Without a compiler (or with ``PLANNER_JIT=0``) the
functions here return None (:func:`choose_joints` False) and the callers take their Python path.
"""

from __future__ import annotations

import ctypes
from array import array
from collections.abc import Sequence
from itertools import chain
from types import ModuleType

import numpy as np

from planner.core.native import C_API_HEAD, load_extension, load_functions

__all__ = [
    "blend_directions",
    "choose_joints",
    "choose_options",
    "choose_probed",
    "moved_states_compiled",
    "scale_states",
    "spline_states",
]

_SOURCE = r"""
#include <math.h>

/* best_choice (planner.motion.vias.base) on rows (K, dof), row-major. Returns 1 and fills
   choice where a better choice exists, 0 where none, -1 where a NaN is among the times (the
   Python sort is then the reference). *best gets the best sum either way (unless -1). */
long best_choice(long K, long dof, const double *t1, const double *t2, double *best_out, long *choice) {
    long n = K * dof;
    for (long e = 0; e < n; ++e)
        if (isnan(t1[e]) || isnan(t2[e])) return -1;
    double m1 = t1[0], m2 = t2[0];
    for (long j = 1; j < dof; ++j) {
        if (t1[j] > m1) m1 = t1[j];
        if (t2[j] > m2) m2 = t2[j];
    }
    double best = m1 + m2;
    long order[n];
    for (long e = 0; e < n; ++e) {  /* a stable insertion sort by t1 (Python's sorted, a key) */
        long k = e;
        while (k > 0 && t1[e] < t1[order[k - 1]]) {
            order[k] = order[k - 1];
            --k;
        }
        order[k] = e;
    }
    double floor = 0.0;
    for (long j = 0; j < dof; ++j) {
        double lo = t2[j];
        for (long k = 1; k < K; ++k)
            if (t2[k * dof + j] < lo) lo = t2[k * dof + j];
        if (j == 0 || lo > floor) floor = lo;
    }
    double low[dof];
    for (long j = 0; j < dof; ++j) low[j] = INFINITY;
    long missing = dof, found = 0, last = n - 1;
    double d2 = INFINITY, f1 = 0.0, f2 = 0.0;
    for (long e = 0; e < n; ++e) {
        long index = order[e];
        double d1 = t1[index];
        if (d1 + floor >= best) break;
        long j = index % dof;
        double b = t2[index];
        if (low[j] == INFINITY) --missing;
        if (b < low[j]) {
            if (low[j] == d2) d2 = NAN;
            low[j] = b;
        }
        if (missing != 0 || (e < last && t1[order[e + 1]] == d1)) continue;
        if (!(d2 < INFINITY)) {
            d2 = low[0];
            for (long i = 1; i < dof; ++i)
                if (low[i] > d2) d2 = low[i];
        }
        if (d1 + d2 < best) {
            best = d1 + d2;
            found = 1;
            f1 = d1;
            f2 = d2;
        }
    }
    *best_out = best;
    if (!found) return 0;
    for (long j = 0; j < dof; ++j) {
        if (t1[j] <= f1 && t2[j] <= f2) {
            choice[j] = 0;
            continue;
        }
        long pick = 0;
        double smallest = INFINITY;
        for (long k = 0; k < K; ++k)
            if (t1[k * dof + j] <= f1 && t2[k * dof + j] < smallest) {
                pick = k;
                smallest = t2[k * dof + j];
            }
        choice[j] = pick;
    }
    return 1;
}

/* _joint_choice (planner.motion.vias.optimized) on times (K, m, dof), row-major: per option, segment
   and joint. Returns 1 and fills choice (dof), 0 where every option has an inf, -1 where a NaN is
   among the times (the Python loop is then the reference). The same comparisons and sums, in the
   same order. */
long joint_choice(long K, long m, long dof, long rounds, const double *t, long *choice) {
    long n = K * m * dof;
    for (long e = 0; e < n; ++e)
        if (isnan(t[e])) return -1;
    double best = INFINITY;
    long first = 0;
    for (long c = 0; c < K; ++c) {
        double total = 0.0;
        for (long r = 0; r < m; ++r) {
            const double *row = t + (c * m + r) * dof;
            double mx = row[0];
            for (long j = 1; j < dof; ++j)
                if (row[j] > mx) mx = row[j];
            total += mx;
        }
        if (c == 0 || total < best) {
            best = total;
            first = c;
        }
    }
    if (!(best < INFINITY)) return 0;
    double chosen[m * dof], others[m];
    for (long j = 0; j < dof; ++j) choice[j] = first;
    for (long e = 0; e < m * dof; ++e) chosen[e] = t[first * m * dof + e];
    for (long round = 0; round < rounds; ++round) {
        int changed = 0;
        for (long j = 0; j < dof; ++j) {
            int binding = 0;
            for (long r = 0; r < m; ++r) {
                const double *row = chosen + r * dof;
                double mx = row[0];
                for (long i = 1; i < dof; ++i)
                    if (row[i] > mx) mx = row[i];
                if (row[j] >= mx) binding = 1;
                double o = 0.0;
                int any = 0;
                for (long i = 0; i < dof; ++i) {
                    if (i == j) continue;
                    if (!any || row[i] > o) o = row[i];
                    any = 1;
                }
                others[r] = o;
            }
            if (!binding) continue;
            long pick = choice[j];
            for (long c = 0; c < K; ++c) {
                double total = 0.0;
                for (long r = 0; r < m; ++r) {
                    double o = others[r], x = t[(c * m + r) * dof + j];
                    total += o > x ? o : x;
                }
                if (total < best) {
                    best = total;
                    pick = c;
                }
            }
            if (pick != choice[j]) {
                choice[j] = pick;
                changed = 1;
                for (long r = 0; r < m; ++r) chosen[r * dof + j] = t[(pick * m + r) * dof + j];
            }
        }
        if (!changed) break;
    }
    return 1;
}

/* np.minimum / np.maximum: NaN propagates, a tie gives the second argument. */
static double np_min(double a, double b) { return isnan(a) ? a : isnan(b) ? b : a < b ? a : b; }
static double np_max(double a, double b) { return isnan(a) ? a : isnan(b) ? b : a > b ? a : b; }

/* np.sign: +0.0 for either zero, NaN for NaN. */
static double np_sign(double a) { return a > 0.0 ? 1.0 : a < 0.0 ? -1.0 : a == 0.0 ? 0.0 : a; }

/* _scaled_states (planner.motion.vias.optimized) of the direction (u, w), shapes (dof,): per
   scale x[g] and joint j the via state, cv at out[g * dof + j] and ca at out[(G + g) * dof + j],
   with the operations of its NumPy form in the same order (su = sign(u), mag = |u|, likewise
   for w), zeros made positive as there (+ 0.0). lims holds the velocity, acceleration and twice
   the jerk limits one after the other. */
void scaled_states(long G, long dof, const double *x, const double *u, const double *w, const double *lims,
                   double *out) {
    const double *velocity = lims, *acceleration = lims + dof, *twice_jerk = lims + 2 * dof;
    for (long g = 0; g < G; ++g) {
        double s = x[g], s2 = x[g] * x[g];
        for (long j = 0; j < dof; ++j) {
            double speed = np_min(velocity[j], s * fabs(u[j]));
            double a = np_sign(w[j]) * np_min(acceleration[j], s2 * fabs(w[j]));
            double amax = sqrt(twice_jerk[j] * (velocity[j] - speed));
            amax *= 1.0 - 1e-9;
            amax = np_min(acceleration[j], amax);
            a = np_min(a, amax);
            out[g * dof + j] = np_sign(u[j]) * speed + 0.0;
            out[(G + g) * dof + j] = np_max(a, -amax) + 0.0;
        }
    }
}
/* spline_via_states (planner.motion.vias.optimized): the clamped C2 cubic spline through q
   ((m + 1, dof), row-major) at the durations h (m), end velocities vs and ve (dof). Writes the
   velocities (m - 1, dof) at out and the accelerations after them. Returns 0, or -1 (nothing
   written) where m < 2 or a duration is not positive and finite (the Python form is then the
   reference). The operations of its Python form, in the same order. */
long spline_states(long m, long dof, const double *q, const double *h, const double *vs, const double *ve,
                   double *out) {
    if (m < 2) return -1;
    for (long r = 0; r < m; ++r)
        if (!(h[r] > 0.0 && h[r] < INFINITY)) return -1;
    long n = m - 1;
    double inv[m], slope[m * dof], c[n], diag[n], d[n * dof];
    double *v = out, *acc = out + n * dof;
    for (long r = 0; r < m; ++r) inv[r] = 1.0 / h[r];
    for (long r = 0; r < m; ++r)
        for (long j = 0; j < dof; ++j) slope[r * dof + j] = (q[(r + 1) * dof + j] - q[r * dof + j]) / h[r];
    /* rhs in d, solved in place row by row (Thomas algorithm) */
    for (long r = 0; r < n; ++r)
        for (long j = 0; j < dof; ++j)
            d[r * dof + j] = 3.0 * (slope[r * dof + j] * inv[r] + slope[(r + 1) * dof + j] * inv[r + 1]);
    for (long j = 0; j < dof; ++j) d[j] = d[j] - inv[0] * vs[j];
    for (long j = 0; j < dof; ++j) d[(n - 1) * dof + j] = d[(n - 1) * dof + j] - inv[m - 1] * ve[j];
    for (long r = 0; r < n; ++r) diag[r] = 2.0 * (inv[r] + inv[r + 1]);
    c[0] = inv[1] / diag[0];
    double den = diag[0];
    for (long j = 0; j < dof; ++j) d[j] = d[j] / den;
    for (long r = 1; r < n; ++r) {
        den = diag[r] - inv[r] * c[r - 1];
        c[r] = inv[r + 1] / den;
        for (long j = 0; j < dof; ++j) d[r * dof + j] = (d[r * dof + j] - inv[r] * d[(r - 1) * dof + j]) / den;
    }
    for (long j = 0; j < dof; ++j) v[(n - 1) * dof + j] = d[(n - 1) * dof + j];
    for (long r = n - 2; r >= 0; --r)
        for (long j = 0; j < dof; ++j) v[r * dof + j] = d[r * dof + j] - c[r] * v[(r + 1) * dof + j];
    for (long r = 0; r < n; ++r) {
        const double *next = r + 1 < n ? v + (r + 1) * dof : ve;
        for (long j = 0; j < dof; ++j)
            acc[r * dof + j] = (6.0 * slope[(r + 1) * dof + j] - 4.0 * v[r * dof + j] - 2.0 * next[j]) * inv[r + 1];
    }
    return 0;
}

/* via_directions (planner.motion.vias.heuristic) past its checks: the waypoints before, at and
   after the via (q, (3, dof), row-major), the durations tp and tn, the limits. Writes u (dof)
   at out and w after it, with the same operations and clipping (a NaN kept). */
void via_directions(long dof, double tp, double tn, const double *q, const double *velocity,
                    const double *acceleration, double *out) {
    double total = tp + tn;
    for (long j = 0; j < dof; ++j) {
        double before = q[j], at = q[dof + j], after = q[2 * dof + j], vm = velocity[j], am = acceleration[j];
        double sp = (at - before) / tp, sn = (after - at) / tn;
        double x = (sp * tn + sn * tp) / total;
        out[j] = (-vm <= x && x <= vm) ? x : x > vm ? vm : x < -vm ? -vm : x;
        x = 2.0 * (sn - sp) / total;
        out[dof + j] = (-am <= x && x <= am) ? x : x > am ? am : x < -am ? -am : x;
    }
}
/* best_choice on the K rows t1, t2 (K, dof) followed by P probed rows: probed row c of joint j is
   p1[c * count + m] where j is joints[m], inf for a joint not among joints (likewise t2 and p2).
   Returns as best_choice. */
long probed_choice(long K, long P, long count, long dof, const double *t1, const double *t2, const double *p1,
                   const double *p2, const long *joints, double *best_out, long *choice) {
    long where[dof];
    for (long j = 0; j < dof; ++j) where[j] = -1;
    for (long m = 0; m < count; ++m) where[joints[m]] = m;
    long n = (K + P) * dof;
    double r1[n], r2[n];
    for (long e = 0; e < K * dof; ++e) {
        r1[e] = t1[e];
        r2[e] = t2[e];
    }
    for (long c = 0; c < P; ++c)
        for (long j = 0; j < dof; ++j) {
            long m = where[j], e = (K + c) * dof + j;
            r1[e] = m < 0 ? INFINITY : p1[c * count + m];
            r2[e] = m < 0 ? INFINITY : p2[c * count + m];
        }
    return best_choice(K + P, dof, r1, r2, best_out, choice);
}
"""

# The same functions callable from Python through the C API (see planner.core.native.load_extension):
# each takes the arguments its ctypes signature below does (C longs and doubles; pointers as bytes or
# as addresses), so the callers are the same for both.
_BINDINGS = r"""
static PyObject *py_best_choice(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[6];
    if (parse(args, nargs, "llpppp", a)) return NULL;
    return PyLong_FromLong(best_choice(a[0].l, a[1].l, a[2].p, a[3].p, a[4].p, a[5].p));
}

static PyObject *py_joint_choice(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[6];
    if (parse(args, nargs, "llllpp", a)) return NULL;
    return PyLong_FromLong(joint_choice(a[0].l, a[1].l, a[2].l, a[3].l, a[4].p, a[5].p));
}

static PyObject *py_scaled_states(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[7];
    if (parse(args, nargs, "llppppp", a)) return NULL;
    scaled_states(a[0].l, a[1].l, a[2].p, a[3].p, a[4].p, a[5].p, a[6].p);
    Py_RETURN_NONE;
}

static PyObject *py_spline_states(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[7];
    if (parse(args, nargs, "llppppp", a)) return NULL;
    return PyLong_FromLong(spline_states(a[0].l, a[1].l, a[2].p, a[3].p, a[4].p, a[5].p, a[6].p));
}

static PyObject *py_via_directions(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[7];
    if (parse(args, nargs, "lddpppp", a)) return NULL;
    via_directions(a[0].l, a[1].d, a[2].d, a[3].p, a[4].p, a[5].p, a[6].p);
    Py_RETURN_NONE;
}

static PyObject *py_probed_choice(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[11];
    if (parse(args, nargs, "llllppppppp", a)) return NULL;
    return PyLong_FromLong(
        probed_choice(a[0].l, a[1].l, a[2].l, a[3].l, a[4].p, a[5].p, a[6].p, a[7].p, a[8].p, a[9].p, a[10].p));
}

/* best_choice's answer as choose_options (planner.motion.vias.kernels) gives it: None for a NaN,
   else (best, choice or None). */
static PyObject *choice_answer(long found, double best, const long *choice, long dof) {
    if (found < 0) Py_RETURN_NONE;
    if (!found) return Py_BuildValue("(dO)", best, Py_None);
    PyObject *list = long_list(choice, dof);
    if (list == NULL) return NULL;
    return Py_BuildValue("(dN)", best, list);
}

/* choose_options on the rows themselves: (rows1, rows2, K, dof); None where the rows do not hold
   K dof floats each in all (ragged) or a time is NaN. */
static PyObject *py_choose_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "expected 4 arguments");
        return NULL;
    }
    long K = PyLong_AsLong(args[2]), dof = PyLong_AsLong(args[3]);
    if (PyErr_Occurred()) return NULL;
    double t1[K * dof], t2[K * dof], best = 0.0;
    long choice[dof];
    int ok = read_rows(args[0], t1, K * dof);
    if (ok > 0) ok = read_rows(args[1], t2, K * dof);
    if (ok < 0) return NULL;
    if (!ok) Py_RETURN_NONE;
    long found = best_choice(K, dof, t1, t2, &best, choice);
    return choice_answer(found, best, choice, dof);
}

/* choose_probed on the rows and probes themselves: (rows1, rows2, p1, p2, joints, K, P, count, dof),
   p1 and p2 holding P count floats, joints count indices below dof; None as py_choose_rows. */
static PyObject *py_choose_probed(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 9) {
        PyErr_SetString(PyExc_TypeError, "expected 9 arguments");
        return NULL;
    }
    long K = PyLong_AsLong(args[5]), P = PyLong_AsLong(args[6]), count = PyLong_AsLong(args[7]);
    long dof = PyLong_AsLong(args[8]);
    if (PyErr_Occurred()) return NULL;
    double t1[K * dof], t2[K * dof], p1[P * count], p2[P * count], best = 0.0;
    long choice[dof], joints[count];
    int ok = read_rows(args[0], t1, K * dof);
    if (ok > 0) ok = read_rows(args[1], t2, K * dof);
    if (ok < 0) return NULL;
    if (!ok) Py_RETURN_NONE;
    if (read_floats(args[2], p1, P * count) != P * count || read_floats(args[3], p2, P * count) != P * count) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "probed times of the wrong length");
        return NULL;
    }
    PyObject *seq = PySequence_Fast(args[4], "joints must be a sequence");
    if (seq == NULL) return NULL;
    if (PySequence_Fast_GET_SIZE(seq) != count) {
        Py_DECREF(seq);
        PyErr_SetString(PyExc_ValueError, "joints of the wrong length");
        return NULL;
    }
    for (long m = 0; m < count; ++m) {
        joints[m] = PyLong_AsLong(PySequence_Fast_GET_ITEM(seq, m));
        if (joints[m] == -1 && PyErr_Occurred()) {
            Py_DECREF(seq);
            return NULL;
        }
        if (joints[m] < 0 || joints[m] >= dof) {
            Py_DECREF(seq);
            PyErr_SetString(PyExc_ValueError, "a joint index out of range");
            return NULL;
        }
    }
    Py_DECREF(seq);
    long found = probed_choice(K, P, count, dof, t1, t2, p1, p2, joints, &best, choice);
    return choice_answer(found, best, choice, dof);
}

/* A new bytearray of n doubles (uninitialised), or NULL on an error. */
static PyObject *doubles(long n) { return PyByteArray_FromStringAndSize(NULL, (Py_ssize_t)(8 * (n > 0 ? n : 0))); }

/* via_directions into a new bytearray: (dof, tp, tn, q, velocity, acceleration). */
static PyObject *py_directions(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[6];
    if (parse(args, nargs, "lddppp", a)) return NULL;
    PyObject *out = doubles(2 * a[0].l);
    if (out != NULL)
        via_directions(a[0].l, a[1].d, a[2].d, a[3].p, a[4].p, a[5].p, (double *)PyByteArray_AS_STRING(out));
    return out;
}

/* scaled_states into a new bytearray: (scales (a sequence of floats), dof, u, w, lims). */
static PyObject *py_scaled(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[5];
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "expected 5 arguments");
        return NULL;
    }
    Py_ssize_t G = PyObject_Length(args[0]);
    if (G < 0 || parse(args + 1, 4, "lppp", a + 1)) return NULL;
    double x[G > 0 ? G : 1];
    if (read_floats(args[0], x, G) != G) return NULL;
    PyObject *out = doubles(2 * G * a[1].l);
    if (out != NULL) scaled_states(G, a[1].l, x, a[2].p, a[3].p, a[4].p, (double *)PyByteArray_AS_STRING(out));
    return out;
}

/* spline_states into a new bytearray: (m, dof, q, h, vs, ve); None where it returns -1. */
static PyObject *py_spline(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[6];
    if (parse(args, nargs, "llpppp", a)) return NULL;
    PyObject *out = doubles(2 * (a[0].l - 1) * a[1].l);
    if (out == NULL) return NULL;
    if (spline_states(a[0].l, a[1].l, a[2].p, a[3].p, a[4].p, a[5].p, (double *)PyByteArray_AS_STRING(out))) {
        Py_DECREF(out);
        Py_RETURN_NONE;
    }
    return out;
}

/* joint_choice on a sequence of floats: (times, K, m, dof, rounds); -1 where a NaN is among them,
   None where every option has an inf, else the choice (a list). */
static PyObject *py_joints(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[5];
    if (nargs != 5 || parse(args + 1, 4, "llll", a + 1)) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_TypeError, "expected 5 arguments");
        return NULL;
    }
    long K = a[1].l, m = a[2].l, dof = a[3].l, n = K * m * dof;
    double t[n > 0 ? n : 1];
    long choice[dof > 0 ? dof : 1];
    if (read_floats(args[0], t, n) != n) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "times of the wrong length");
        return NULL;
    }
    long found = joint_choice(K, m, dof, a[4].l, t, choice);
    if (found < 0) return PyLong_FromLong(-1);
    if (!found) Py_RETURN_NONE;
    return long_list(choice, dof);
}

/* moved_states (planner.motion.vias.joint_steps) on plain floats: (velocity, acceleration, twice_jerk,
   cv, ca, joints, moves), the same operations in the same order; per move (velocities, accelerations)
   of the joints, lists. */
static PyObject *py_moved(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 7) {
        PyErr_SetString(PyExc_TypeError, "expected 7 arguments");
        return NULL;
    }
    Py_ssize_t dof = PyObject_Length(args[0]), count = PyObject_Length(args[5]), many = PyObject_Length(args[6]);
    if (dof < 0 || count < 0 || many < 0) return NULL;
    double vel[dof + 1], acc[dof + 1], tj[dof + 1], cv[dof + 1], ca[dof + 1], moves[many + 1];
    if (read_floats(args[0], vel, dof) != dof || read_floats(args[1], acc, dof) != dof ||
        read_floats(args[2], tj, dof) != dof || read_floats(args[3], cv, dof) != dof ||
        read_floats(args[4], ca, dof) != dof || read_floats(args[6], moves, many) != many) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "limits or states of the wrong length");
        return NULL;
    }
    long joints[count + 1];
    PyObject *seq = PySequence_Fast(args[5], "joints must be a sequence");
    if (seq == NULL) return NULL;
    for (Py_ssize_t m = 0; m < count; ++m) {
        joints[m] = PyLong_AsLong(PySequence_Fast_GET_ITEM(seq, m));
        if ((joints[m] == -1 && PyErr_Occurred()) || joints[m] < -dof || joints[m] >= dof) {
            Py_DECREF(seq);
            if (!PyErr_Occurred()) PyErr_SetString(PyExc_IndexError, "a joint index out of range");
            return NULL;
        }
        if (joints[m] < 0) joints[m] += dof; /* as Python indexes */
    }
    Py_DECREF(seq);
    PyObject *out = PyList_New(many);
    if (out == NULL) return NULL;
    for (Py_ssize_t k = 0; k < many; ++k) {
        PyObject *nv = PyList_New(count), *na = PyList_New(count), *pair = NULL;
        if (nv == NULL || na == NULL) goto fail;
        for (Py_ssize_t m = 0; m < count; ++m) {
            long j = joints[m];
            double top = vel[j], most = acc[j], x = cv[j], y = ca[j];
            x += moves[k] * top;
            x = x > top ? top : x < -top ? -top : x;
            double room = top - (x >= 0.0 ? x : -x);
            double amax = room > 0.0 ? sqrt(tj[j] * room) * (1.0 - 1e-9) : 0.0;
            if (amax > most) amax = most;
            PyObject *fx = PyFloat_FromDouble(x), *fy = PyFloat_FromDouble(y > amax ? amax : y < -amax ? -amax : y);
            if (fx == NULL || fy == NULL) {
                Py_XDECREF(fx);
                Py_XDECREF(fy);
                goto fail;
            }
            PyList_SET_ITEM(nv, m, fx);
            PyList_SET_ITEM(na, m, fy);
        }
        pair = PyTuple_Pack(2, nv, na);
        if (pair == NULL) goto fail;
        Py_DECREF(nv);
        Py_DECREF(na);
        PyList_SET_ITEM(out, k, pair);
        continue;
    fail:
        Py_XDECREF(nv);
        Py_XDECREF(na);
        Py_DECREF(out);
        return NULL;
    }
    return out;
}

static PyMethodDef methods[] = {
    {"moved", (PyCFunction)(void (*)(void))py_moved, METH_FASTCALL, NULL},
    {"directions", (PyCFunction)(void (*)(void))py_directions, METH_FASTCALL, NULL},
    {"scaled", (PyCFunction)(void (*)(void))py_scaled, METH_FASTCALL, NULL},
    {"spline", (PyCFunction)(void (*)(void))py_spline, METH_FASTCALL, NULL},
    {"joints", (PyCFunction)(void (*)(void))py_joints, METH_FASTCALL, NULL},
    {"choose_rows", (PyCFunction)(void (*)(void))py_choose_rows, METH_FASTCALL, NULL},
    {"choose_probed", (PyCFunction)(void (*)(void))py_choose_probed, METH_FASTCALL, NULL},
    {"best_choice", (PyCFunction)(void (*)(void))py_best_choice, METH_FASTCALL, NULL},
    {"joint_choice", (PyCFunction)(void (*)(void))py_joint_choice, METH_FASTCALL, NULL},
    {"scaled_states", (PyCFunction)(void (*)(void))py_scaled_states, METH_FASTCALL, NULL},
    {"spline_states", (PyCFunction)(void (*)(void))py_spline_states, METH_FASTCALL, NULL},
    {"via_directions", (PyCFunction)(void (*)(void))py_via_directions, METH_FASTCALL, NULL},
    {"probed_choice", (PyCFunction)(void (*)(void))py_probed_choice, METH_FASTCALL, NULL},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "planner_via_kernels", NULL, -1, methods};

PyMODINIT_FUNC PyInit_planner_via_kernels(void) { return PyModule_Create(&module); }
"""

_SIGNATURES = {
    "best_choice": [ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 4],
    "scaled_states": [ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 5],
    "joint_choice": [ctypes.c_long, ctypes.c_long, ctypes.c_long, ctypes.c_long, ctypes.c_void_p, ctypes.c_void_p],
    "spline_states": [ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 5],
    "via_directions": [ctypes.c_long, ctypes.c_double, ctypes.c_double, *[ctypes.c_void_p] * 4],
    "probed_choice": [ctypes.c_long, ctypes.c_long, ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 7],
}


#: The most options times joints :func:`choose_options` takes (more: the Python path).
_MOST_ENTRIES = 4096


#: The library once loaded (the loaders keep it for the process too; this skips their lookup).
_LOADED: list[ModuleType | ctypes.CDLL | None] = []


def _library() -> ModuleType | ctypes.CDLL | None:
    """The compiled functions: through the C API where Python's headers are at hand, else ctypes (slower calls)."""
    if _LOADED:
        return _LOADED[0]
    library = load_extension(C_API_HEAD + _SOURCE + _BINDINGS, "planner_via_kernels")
    _LOADED.append(library if library is not None else _ctypes_library())
    return _LOADED[0]


def _ctypes_library() -> ctypes.CDLL | None:
    """The compiled functions through ctypes (where the C API's headers are missing)."""
    library = load_functions(_SOURCE, "via_kernels", _SIGNATURES)
    if library is not None and library.best_choice.restype is None:
        library.best_choice.restype = ctypes.c_long  # (load_functions sets None: it returns a code)
        library.joint_choice.restype = ctypes.c_long
        library.spline_states.restype = ctypes.c_long
        library.probed_choice.restype = ctypes.c_long
    return library


def _flat_rows(rows1: list[list[float]], rows2: list[list[float]], size: int) -> tuple[array, array] | None:
    """Both segments' rows as flat C doubles, or None where either does not hold `size` floats (ragged)."""
    flat1 = array("d", list(chain.from_iterable(rows1)))  # (C loops: a comprehension costs more)
    flat2 = array("d", list(chain.from_iterable(rows2)))
    if len(flat1) != size or len(flat2) != size:
        return None
    return flat1, flat2


def choose_options(rows1: list[list[float]], rows2: list[list[float]]) -> tuple[float, list[int] | None] | None:
    """:func:`planner.motion.vias.base.best_choice` on rows of floats, compiled.

    Returns:
        The best sum and the choice per joint (None where no choice is better), or None where
        there is no compiled library or a time is NaN (the caller's Python path decides).
    """
    library = _library()
    if library is None:
        return None
    k, dof = len(rows1), len(rows1[0])
    if k * dof > _MOST_ENTRIES:
        return None  # (the C function sorts on its stack)
    if type(library) is ModuleType:  # the C API reads the rows itself (None: ragged, or a NaN)
        return library.choose_rows(rows1, rows2, k, dof)
    flat = _flat_rows(rows1, rows2, k * dof)
    if flat is None:
        return None  # ragged rows: the Python path says what is wrong
    flat1, flat2 = flat
    out = array("d", [0.0])
    choice = array("l", [0]) * dof  # C longs, as the function's
    found = library.best_choice(
        k, dof, flat1.buffer_info()[0], flat2.buffer_info()[0], out.buffer_info()[0], choice.buffer_info()[0]
    )
    if found < 0:
        return None
    return out[0], (choice.tolist() if found else None)


def choose_probed(
    rows1: list[list[float]], rows2: list[list[float]], probed: tuple[list[float], list[float]], joints: tuple[int, ...]
) -> tuple[float, list[int] | None] | None:
    """:func:`planner.motion.vias.base.best_choice` on rows of floats followed by probed rows, compiled.

    Args:
        rows1: Per option and joint the joint's time in the first segment [s], K rows of dof floats.
        rows2: Likewise in the second segment.
        probed: The probed times in the first and second segment [s], flat: the entry of
            probed option c and joint ``joints[m]`` at ``c * len(joints) + m``
            (:meth:`planner.motion.segments.SegmentSolver.probe_around`); a joint not among
            `joints` has the time inf in every probed option.
        joints: The joints probed, distinct indices below dof.

    Returns:
        The best sum and the option per joint (probed option c is option K + c; None where no
        choice is better), or None where there is no compiled library, too many entries or a
        NaN among the times (the caller's Python path decides).
    """
    library = _library()
    if library is None:
        return None
    k, dof, count = len(rows1), len(rows1[0]), len(joints)
    if not count:
        return None
    p1, p2 = probed
    extra = len(p1) // count
    if (k + extra) * dof > _MOST_ENTRIES or len(p1) != extra * count or len(p2) != len(p1):
        return None  # (the C function sorts on its stack)
    if type(library) is ModuleType:  # the C API reads the rows and probes itself (None: ragged, or a NaN)
        return library.choose_probed(rows1, rows2, p1, p2, joints, k, extra, count, dof)
    flat = _flat_rows(rows1, rows2, k * dof)
    if flat is None:
        return None  # ragged rows: the Python path says what is wrong
    flat1, flat2 = flat
    out = array("d", [0.0])
    choice = array("l", [0]) * dof  # C longs, as the function's
    found = library.probed_choice(
        k,
        extra,
        count,
        dof,
        flat1.buffer_info()[0],
        flat2.buffer_info()[0],
        array("d", p1).tobytes(),
        array("d", p2).tobytes(),
        array("l", joints).tobytes(),
        out.buffer_info()[0],
        choice.buffer_info()[0],
    )
    if found < 0:
        return None
    return out[0], (choice.tolist() if found else None)


def choose_joints(times: list[float], shape: tuple[int, int, int], rounds: int) -> list[int] | None | bool:
    """:func:`planner.motion.vias.optimized._joint_choice` on flat times, compiled.

    Args:
        times: Per option, segment and joint the joint's time [s], flat (option by option).
        shape: The number of options, segments and joints.
        rounds: The rounds of the choice.

    Returns:
        The option per joint, None where every option has an inf, or False where there is no
        compiled library, too many entries or a NaN among the times (the caller's Python path decides).
    """
    library = _library()
    count, m, dof = shape
    if library is None or count * m * dof > _MOST_ENTRIES:
        return False  # (the C function keeps the chosen times on its stack)
    if type(library) is ModuleType:  # the C API reads the times itself
        found = library.joints(times, count, m, dof, rounds)
        return False if found == -1 else found
    flat = array("d", times)
    choice = array("l", [0]) * dof  # C longs, as the function's
    found = library.joint_choice(count, m, dof, rounds, flat.buffer_info()[0], choice.buffer_info()[0])
    if found < 0:
        return False
    return choice.tolist() if found else None


def scale_states(x: list[float], u: np.ndarray, w: np.ndarray, limits: bytes) -> tuple[np.ndarray, np.ndarray] | None:
    """``_scaled_states`` of :mod:`planner.motion.vias.optimized`, compiled (None without a library).

    Args:
        x: The scales, G floats.
        u: The velocity direction, shape (dof,), float64.
        w: The acceleration direction, shape (dof,), float64.
        limits: The velocity, acceleration and twice the jerk limits, float64 bytes, one after
            the other (3 dof values).

    Returns:
        The velocities and accelerations, shapes (G, dof) (views of one new buffer).
    """
    library = _library()
    if library is None:
        return None
    count, dof = len(x), len(u)
    if type(library) is ModuleType:  # the C API reads the scales and makes the buffer
        both = np.frombuffer(library.scaled(x, dof, u.tobytes(), w.tobytes(), limits)).reshape(2, count, dof)
        return both[0], both[1]
    out = array("d", bytes(16 * count * dof))
    scales = array("d", x)  # (held here while the C function reads it)
    library.scaled_states(count, dof, scales.buffer_info()[0], u.tobytes(), w.tobytes(), limits, out.buffer_info()[0])
    both = np.frombuffer(out).reshape(2, count, dof)
    return both[0], both[1]


def spline_states(
    q: np.ndarray, h: np.ndarray, v_start: np.ndarray, v_end: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`planner.motion.vias.optimized.spline_via_states`, compiled.

    Args:
        q: Waypoints of the run, shape (m+1, dof), float64.
        h: Segment durations, shape (m,) [s].
        v_start: Velocity at ``q[0]``, shape (dof,), float64.
        v_end: Velocity at ``q[m]``, shape (dof,), float64.

    Returns:
        The velocities and accelerations at ``q[1:m]``, shapes (m-1, dof) (views of one new
        buffer), or None where there is no compiled library, m < 2, too many entries or a
        duration is not positive and finite (the caller's Python path decides).
    """
    library = _library()
    if library is None:
        return None
    m, dof = len(h), len(v_start)
    if m < 2 or q.shape != (m + 1, dof) or m * dof > _MOST_ENTRIES:
        return None  # (the C function keeps its rows on its stack)
    q = q.astype(np.float64, copy=False)  # (as the Python form's floats)
    if type(library) is ModuleType:  # the C API makes the buffer (None: -1 from the C function)
        made = library.spline(m, dof, q.tobytes(), h.tobytes(), v_start.tobytes(), v_end.tobytes())
        if made is None:
            return None
        both = np.frombuffer(made).reshape(2, m - 1, dof)
        return both[0], both[1]
    out = array("d", bytes(16 * (m - 1) * dof))
    if library.spline_states(
        m, dof, q.tobytes(), h.tobytes(), v_start.tobytes(), v_end.tobytes(), out.buffer_info()[0]
    ):
        return None
    both = np.frombuffer(out).reshape(2, m - 1, dof)
    return both[0], both[1]


def blend_directions(
    q: np.ndarray, tp: float, tn: float, velocity: np.ndarray, acceleration: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`planner.motion.vias.heuristic.via_directions` past its checks, compiled (None without a library).

    Args:
        q: The waypoints before, at and after the via, shape (3, dof), float64.
        tp: The duration of the segment before the via [s], positive and finite.
        tn: Likewise after it.
        velocity: The speed limits, shape (dof,), float64.
        acceleration: The acceleration limits, shape (dof,), float64.

    Returns:
        The velocity and acceleration directions, shapes (dof,) (views of one new buffer).
    """
    library = _library()
    if library is None:
        return None
    dof = len(velocity)
    q = q.astype(np.float64, copy=False)  # (as the Python form's floats)
    if type(library) is ModuleType:  # the C API makes the buffer
        both = np.frombuffer(library.directions(dof, tp, tn, q.tobytes(), velocity.tobytes(), acceleration.tobytes()))
        return both[:dof], both[dof:]
    out = array("d", bytes(16 * dof))
    library.via_directions(dof, tp, tn, q.tobytes(), velocity.tobytes(), acceleration.tobytes(), out.buffer_info()[0])
    both = np.frombuffer(out).reshape(2, dof)
    return both[0], both[1]


def moved_states_compiled(
    limits: tuple[Sequence[float], Sequence[float], Sequence[float]],
    state: tuple[Sequence[float], Sequence[float]],
    joints: Sequence[int],
    moves: Sequence[float],
) -> list[tuple[list[float], list[float]]] | None:
    """:func:`planner.motion.vias.joint_steps.moved_states` in C (None without the C API: the caller's Python loop).

    The same operations in the same order on the same floats (bit for bit).
    """
    library = _library()
    if type(library) is not ModuleType:
        return None
    return library.moved(*limits, *state, joints, moves)
