"""Compiled loops of the segment solver: the reach times of the range ends.

:meth:`planner.motion.segments.SegmentSolver._watch_ends` computes, per admissible segment and
range end, the least time a joint needs to reach that end and come back (two reach times, a
few dozen of them per plan): in Python that costs more in the interpreter's overhead than in
arithmetic. Here it is one C function (:mod:`planner.core.native`, compiled once) with the
same operations in the same order (divisions, square roots and sums, no product added to
another, so no fused multiply-add can change a rounding): the same values bit for bit (the
tests compare both paths). Without a compiler (or with ``PLANNER_JIT=0``) :func:`watch_times`
returns None and the caller takes its Python path.
"""

from __future__ import annotations

import ctypes
from array import array
from itertools import chain
from types import ModuleType

import numpy as np

from planner.core.native import C_API_HEAD, load_extension, load_functions

__all__ = ["WatchTable", "admissible_states", "watch_times", "zero_jerk_turns"]

_SOURCE = r"""
#include <math.h>

/* One reach time written out as SegmentSolver._watch_ends has it (planner.motion.segments). */
static double reach_time(double d, double a, double knee, double v) {
    return d < 0.0 ? -INFINITY : d <= knee ? sqrt(2.0 * d / a) : (d + knee) / v;
}

/* Per segment k (rows k and k + 1 of q, (K + 1, dof), row-major) and range end e, the time to
   the end and back at out[k * E + e], E = U + L: first the U upper ends (joint ju[e], limits vu,
   au, knee ku, the end as the checks put it hu), then the L lower ones (likewise). miss is
   _END_MISS. Per segment and joint the least of its times at reach[k * dof + j] (inf for none). */
/* np.minimum / np.maximum: NaN propagates, a tie gives the second argument. */
static double np_min(double a, double b) { return isnan(a) ? a : isnan(b) ? b : a < b ? a : b; }
static double np_max(double a, double b) { return isnan(a) ? a : isnan(b) ? b : a > b ? a : b; }

/* admissible_acceleration (planner.motion.limits) on n states of dof joints (v, a row-major), the
   operations of its NumPy form in the same order: amax = min(a_max, sqrt(2 j_max max(v_max - |v|, 0))
   (1 - 1e-9)), out = max(min(a, amax), -amax). lims holds the velocity, acceleration and twice the
   jerk limits one after the other. */
void admissible(long n, long dof, const double *v, const double *a, const double *lims, double *out) {
    const double *velocity = lims, *acceleration = lims + dof, *twice_jerk = lims + 2 * dof;
    for (long r = 0; r < n; ++r)
        for (long j = 0; j < dof; ++j) {
            long e = r * dof + j;
            double amax = np_max(velocity[j] - fabs(v[e]), 0.0);
            amax = sqrt(twice_jerk[j] * amax);
            amax *= 1.0 - 1e-9;
            amax = np_min(acceleration[j], amax);
            out[e] = np_max(np_min(a[e], amax), -amax);
        }
}

void watch_times(long K, long dof, const double *q, long U, const long *ju, const double *vu, const double *au,
                 const double *ku, const double *hu, long L, const long *jl, const double *vl, const double *al,
                 const double *kl, const double *ll, double miss, double *out, double *reach) {
    long E = U + L;
    for (long k = 0; k < K; ++k) {
        const double *before = q + k * dof, *after = q + (k + 1) * dof;
        double *t = out + k * E, *r = reach + k * dof;
        for (long j = 0; j < dof; ++j) r[j] = INFINITY;
        for (long e = 0; e < U; ++e) {
            long j = ju[e];
            double d = hu[e] - before[j], f = hu[e] - after[j] - miss;
            double s = reach_time(d, au[e], ku[e], vu[e]);
            s += reach_time(f, au[e], ku[e], vu[e]);
            t[e] = s;
            if (s < r[j]) r[j] = s;
        }
        for (long e = 0; e < L; ++e) {
            long j = jl[e];
            double d = before[j] - ll[e], f = after[j] - miss - ll[e];
            double s = reach_time(d, al[e], kl[e], vl[e]);
            s += reach_time(f, al[e], kl[e], vl[e]);
            t[U + e] = s;
            if (s < r[j]) r[j] = s;
        }
    }
}
"""

# The same functions through the C API (planner.core.native.load_extension), with their ctypes arguments.
_BINDINGS = r"""
static PyObject *py_watch_times(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[18];
    if (parse(args, nargs, "llplppppplpppppdpp", a)) return NULL;
    watch_times(a[0].l, a[1].l, a[2].p, a[3].l, a[4].p, a[5].p, a[6].p, a[7].p, a[8].p, a[9].l, a[10].p, a[11].p,
                a[12].p, a[13].p, a[14].p, a[15].d, a[16].p, a[17].p);
    Py_RETURN_NONE;
}

static PyObject *py_admissible(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[6];
    if (parse(args, nargs, "llpppp", a)) return NULL;
    admissible(a[0].l, a[1].l, a[2].p, a[3].p, a[4].p, a[5].p);
    Py_RETURN_NONE;
}

/* watch_times on the waypoint rows themselves, (rows, K, dof, U, ju, vu, au, ku, hu, L, jl, vl, al, kl,
   ll, miss), the times and the least per joint as lists of floats; None where the rows do not hold
   (K + 1) dof floats. */
static PyObject *py_watch_lists(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[16];
    if (nargs != 16 || parse(args + 1, 15, "lllppppplpppppd", a + 1)) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_TypeError, "expected 16 arguments");
        return NULL;
    }
    long K = a[1].l, dof = a[2].l, E = a[3].l + a[9].l;
    if (K < 1 || dof < 1) Py_RETURN_NONE;
    double q[(K + 1) * dof], out[K * E > 0 ? K * E : 1], reach[K * dof];
    int ok = read_rows(args[0], q, (K + 1) * dof);
    if (ok < 0) return NULL;
    if (!ok) Py_RETURN_NONE;
    watch_times(K, dof, q, a[3].l, a[4].p, a[5].p, a[6].p, a[7].p, a[8].p, a[9].l, a[10].p, a[11].p, a[12].p,
                a[13].p, a[14].p, a[15].d, out, reach);
    PyObject *times = float_list(out, K * E);
    if (times == NULL) return NULL;
    return Py_BuildValue("(NN)", times, float_list(reach, K * dof));
}

/* admissible into a new bytearray: (n, dof, v, a, lims). */
static PyObject *py_admissible_out(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[5];
    if (parse(args, nargs, "llppp", a)) return NULL;
    long size = a[0].l * a[1].l;
    PyObject *out = PyByteArray_FromStringAndSize(NULL, (Py_ssize_t)(8 * (size > 0 ? size : 0)));
    if (out != NULL) admissible(a[0].l, a[1].l, a[2].p, a[3].p, a[4].p, (double *)PyByteArray_AS_STRING(out));
    return out;
}

/* A sequence attribute of obj read into out (at most n floats); its length, or -1 on an error. */
static Py_ssize_t read_attribute(PyObject *obj, const char *name, double *out, Py_ssize_t n) {
    PyObject *seq = PyObject_GetAttrString(obj, name);
    if (seq == NULL) return -1;
    Py_ssize_t m = read_floats(seq, out, n);
    Py_DECREF(seq);
    return m;
}

/* _zero_jerk_turns (planner.motion.segments) of one Ruckig profile: (prof, v), v its velocities (a
   list); the turns (a list), or None where the profile's lists are longer than 16 or shorter than
   its loop reads, or a turn has a zero acceleration (the Python loop is then the reference). */
static PyObject *py_zero_jerk_turns(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "expected 2 arguments");
        return NULL;
    }
    double v[17], jerk[17], acc[17], pos[17];
    Py_ssize_t nv = read_floats(args[1], v, 17), nj = read_attribute(args[0], "j", jerk, 17), na = -2, np = -2;
    if (nv < 0 || nj < 0) return NULL;
    if (nv > 16 || nj > 16) Py_RETURN_NONE;
    PyObject *turns = PyList_New(0);
    if (turns == NULL) return NULL;
    for (Py_ssize_t i = 0; i < nj; ++i) {
        if (jerk[i] != 0.0) continue;
        if (i + 1 >= nv) goto python;
        if (!(v[i] * v[i + 1] < 0.0)) continue;
        if (na == -2) {
            na = read_attribute(args[0], "a", acc, 17);
            np = na < 0 ? -1 : read_attribute(args[0], "p", pos, 17);
            if (na < 0 || np < 0) {
                Py_DECREF(turns);
                return NULL;
            }
        }
        if (i >= na || i >= np || na > 16 || np > 16 || acc[i] == 0.0) goto python;
        double v0 = v[i], a0 = acc[i];
        double tz = -v0 / a0;
        PyObject *turn = PyFloat_FromDouble(pos[i] + tz * (v0 + tz * a0 / 2.0));
        if (turn == NULL || PyList_Append(turns, turn) < 0) {
            Py_XDECREF(turn);
            Py_DECREF(turns);
            return NULL;
        }
        Py_DECREF(turn);
    }
    return turns;
python:
    Py_DECREF(turns);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"zero_jerk_turns", (PyCFunction)(void (*)(void))py_zero_jerk_turns, METH_FASTCALL, NULL},
    {"watch_lists", (PyCFunction)(void (*)(void))py_watch_lists, METH_FASTCALL, NULL},
    {"admissible_out", (PyCFunction)(void (*)(void))py_admissible_out, METH_FASTCALL, NULL},
    {"watch_times", (PyCFunction)(void (*)(void))py_watch_times, METH_FASTCALL, NULL},
    {"admissible", (PyCFunction)(void (*)(void))py_admissible, METH_FASTCALL, NULL},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "planner_segment_kernels", NULL, -1, methods};

PyMODINIT_FUNC PyInit_planner_segment_kernels(void) { return PyModule_Create(&module); }
"""

_SIGNATURES = {
    "watch_times": [
        ctypes.c_long,
        ctypes.c_long,
        ctypes.c_void_p,
        ctypes.c_long,
        *[ctypes.c_void_p] * 5,
        ctypes.c_long,
        *[ctypes.c_void_p] * 5,
        ctypes.c_double,
        ctypes.c_void_p,
        ctypes.c_void_p,
    ],
    "admissible": [ctypes.c_long, ctypes.c_long, *[ctypes.c_void_p] * 4],
}


#: The library once loaded (the loaders keep it for the process too; this skips their lookup).
_LOADED: list[ModuleType | ctypes.CDLL | None] = []


def _library() -> ModuleType | ctypes.CDLL | None:
    """The compiled functions: through the C API where Python's headers are at hand, else ctypes (slower calls)."""
    if not _LOADED:
        library = load_extension(C_API_HEAD + _SOURCE + _BINDINGS, "planner_segment_kernels")
        _LOADED.append(library if library is not None else _ctypes_library())
    return _LOADED[0]


def _ctypes_library() -> ctypes.CDLL | None:
    """The compiled functions through ctypes (where the C API's headers are missing)."""
    return load_functions(_SOURCE, "segment_kernels", _SIGNATURES)


class WatchTable:
    """The range ends :meth:`SegmentSolver._watch_ends` watches, as C arrays (made once per set of limits).

    Args:
        uppers: Per finite upper range end ``(joint, speed limit, acceleration limit, knee, end,
            end as checked)``, as ``_watch_ends`` lists them.
        lowers: Likewise for the lower ends.

    Attributes:
        count: How many range ends.
        joints: Per range end its joint (uppers first).
        uppers: Per range end whether it is an upper one.
        ends: Per range end the end itself [rad or m].
    """

    __slots__ = ("_args", "_columns", "count", "ends", "joints", "uppers")

    def __init__(self, uppers: list[tuple], lowers: list[tuple]):
        self.count = len(uppers) + len(lowers)
        self.joints = [e[0] for e in uppers] + [e[0] for e in lowers]
        self.uppers = [True] * len(uppers) + [False] * len(lowers)
        self.ends = [e[4] for e in uppers] + [e[4] for e in lowers]

        def columns(rows: list[tuple]) -> list[array]:
            return [array("l", [r[0] for r in rows])] + [array("d", [r[i] for r in rows]) for i in (1, 2, 3, 5)]

        # Per side the joints, v, a, knee and the end as checked (held here), passed by address.
        self._columns = columns(uppers), columns(lowers)
        up, low = ([c.buffer_info()[0] for c in side] for side in self._columns)
        self._args = (len(uppers), *up, len(lowers), *low)


def watch_times(rows: list[list[float]], table: WatchTable, miss: float) -> tuple[list[float], list[float]] | None:
    """Every segment's reach times of every range end in `table`, and per joint the least, or None without a library.

    Args:
        rows: The waypoints, K + 1 rows of dof floats.
        table: The range ends.
        miss: The end position's allowed miss [rad or m].

    Returns:
        The times [s], flat: segment k's at ``k * table.count`` on; and per segment and joint
        the least of them (inf where none), flat: segment k's at ``k * dof`` on.
    """
    library = _library()
    if library is None:
        return None
    segments, dof = len(rows) - 1, len(rows[0])
    if type(library) is ModuleType:  # the C API reads the rows and makes the lists (None: ragged rows)
        return library.watch_lists(rows, segments, dof, *table._args, miss)
    q = array("d", list(chain.from_iterable(rows)))
    out = array("d", bytes(8 * segments * table.count))
    reach = array("d", bytes(8 * segments * dof))
    library.watch_times(
        segments, dof, q.buffer_info()[0], *table._args, miss, out.buffer_info()[0], reach.buffer_info()[0]
    )
    return out.tolist(), reach.tolist()


def admissible_states(v: np.ndarray, a: np.ndarray, limits: bytes) -> np.ndarray | None:
    """:func:`planner.motion.limits.admissible_acceleration`, compiled (None without a library or for other shapes).

    Args:
        v: Velocities, shape (..., dof), float64.
        a: Accelerations, the same shape and type (else None: the caller's NumPy path).
        limits: The velocity, acceleration and twice the jerk limits, float64 bytes, one after
            the other (3 dof values).

    Returns:
        The accelerations made admissible, a new array of `v`'s shape.
    """
    library = _library()
    if (
        library is None
        or type(v) is not np.ndarray
        or type(a) is not np.ndarray
        or v.shape != a.shape
        or v.dtype != np.float64
        or a.dtype != np.float64
        or not v.ndim
    ):
        return None
    dof = v.shape[-1]
    size = v.size
    if not dof or 24 * dof != len(limits):
        return None
    if type(library) is ModuleType:  # the C API makes the buffer
        made = library.admissible_out(size // dof, dof, v.tobytes(), a.tobytes(), limits)
        return np.frombuffer(made).reshape(v.shape)
    out = array("d", bytes(8 * size))
    library.admissible(size // dof, dof, v.tobytes(), a.tobytes(), limits, out.buffer_info()[0])
    return np.frombuffer(out).reshape(v.shape)


def zero_jerk_turns(prof: object, v: list[float]) -> list[float] | None:
    """``_zero_jerk_turns`` of :mod:`planner.motion.segments` in C, the same operations (None: its Python loop decides).

    Args:
        prof: One joint's Ruckig profile.
        v: Its velocities ``prof.v``.
    """
    library = _library()
    if type(library) is not ModuleType:
        return None
    return library.zero_jerk_turns(prof, v)
