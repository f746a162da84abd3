"""Small C libraries compiled with the system compiler, cached on disk, loaded with ctypes.

For loops NumPy cannot batch cheaply (e.g. a serial chain's Jacobian at many configurations,
:mod:`planner.geometry.jacobian_kernel`). The C source is compiled with ``$CC`` (else ``gcc``)
and :data:`FLAGS` the first time it is needed and kept in ``$PLANNER_CACHE_DIR/native``, else
``$XDG_CACHE_HOME/planner/native``, else ``~/.cache/planner/native``, under a hash of the
source, the compiler and the flags (built in a temporary file and renamed into place, so
concurrent processes never load a half-written library). Without a compiler, with an
unwritable cache or with ``PLANNER_JIT=0`` (as for the CasADi kernels of
:mod:`planner.ik.numeric.codegen`), :func:`load_library` returns None and callers take their
NumPy or Pinocchio path: the same values to rounding, slower.
"""

from __future__ import annotations

import ctypes
import hashlib
import importlib.util
import os
import shlex
import shutil
import subprocess
import sysconfig
import tempfile
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import ModuleType

__all__ = [
    "C_API_HEAD",
    "FLAGS",
    "build_library",
    "cache_dir",
    "find_compiler",
    "load_extension",
    "load_functions",
    "load_library",
    "native_cache_dir",
]

#: Compiler flags: optimised without value-changing shortcuts (no -ffast-math), a shared library.
FLAGS = ("-O2", "-fPIC", "-shared")


def cache_dir(kind: str) -> Path:
    """Folder of compiled libraries of one kind (``"native"``, ``"casadi"``); not created here.

    ``$PLANNER_CACHE_DIR/<kind>``, else ``$XDG_CACHE_HOME/planner/<kind>``, else
    ``~/.cache/planner/<kind>``.
    """
    if os.environ.get("PLANNER_CACHE_DIR"):
        return Path(os.environ["PLANNER_CACHE_DIR"]) / kind
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "planner" / kind


def native_cache_dir() -> Path:
    """Folder of the compiled libraries of :func:`load_library` (see the module docstring)."""
    return cache_dir("native")


def find_compiler() -> str | None:
    """The C compiler command to build with (``$CC``, else ``gcc``); None without one or with ``PLANNER_JIT=0``.

    ``$CC`` may hold a command with arguments (``ccache gcc``): its first word is looked up on
    the ``PATH`` and replaced by its full path.
    """
    if os.environ.get("PLANNER_JIT", "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    try:
        words = shlex.split(os.environ.get("CC") or "gcc")
    except ValueError:  # unbalanced quotes
        return None
    found = shutil.which(words[0]) if words else None
    return None if found is None else shlex.join([found, *words[1:]])


def build_library(
    source: str, library: Path, compiler: str, flags: Sequence[str] = FLAGS, timeout: float = 600
) -> None:
    """Compile C `source` into the shared library `library` unless it exists.

    Built in a temporary folder beside it and renamed into place, so concurrent processes never
    load a half-written library.

    Raises:
        RuntimeError: When the compiler fails (its first error lines).
        OSError: When the folder cannot be written.
        subprocess.SubprocessError: When the compiler cannot run or times out.
    """
    if library.exists():
        return
    library.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=library.parent) as tmp:
        path = Path(tmp) / f"{library.stem}.c"
        path.write_text(source)
        built = Path(tmp) / library.name
        proc = subprocess.run(
            [*shlex.split(compiler), *flags, "-o", str(built), str(path), "-lm"],
            capture_output=True,
            text=True,
            timeout=timeout,
        )
        if proc.returncode != 0:
            raise RuntimeError(f"{compiler} failed: {proc.stderr.strip()[:500]}")
        os.replace(built, library)


def load_library(source: str, name: str) -> ctypes.CDLL | None:
    """The compiled `source`, from the cache when there, or None where it cannot be built.

    Args:
        source: C source text.
        name: A short name for the library file (the cache key is added to it).

    Returns:
        The loaded library, or None when compiling is switched off (``PLANNER_JIT=0``), no
        compiler is found, or compiling or loading fails (then with a ``RuntimeWarning``).
    """
    compiler = find_compiler()
    if compiler is None:
        return None
    key = hashlib.sha256("\0".join([source, compiler, *FLAGS]).encode()).hexdigest()[:24]
    library = native_cache_dir() / f"{name}_{key}.so"
    try:
        build_library(source, library, compiler, timeout=120)
        return ctypes.CDLL(str(library))
    except (OSError, RuntimeError, subprocess.SubprocessError) as exc:
        warnings.warn(
            f"planner: cannot build the C library {name!r} ({exc}); using the slower path", RuntimeWarning, stacklevel=2
        )
        return None


_LOADED: dict[tuple[str, str], ctypes.CDLL | None] = {}


def load_functions(source: str, name: str, signatures: Mapping[str, Sequence]) -> ctypes.CDLL | None:
    """:func:`load_library` once per process and source, with its functions' argument types set.

    Args:
        source: C source text.
        name: A short name for the library file.
        signatures: Per function of the source that returns nothing, its ctypes argument types.

    Returns:
        The library (the same object on every call), or None where it cannot be built (then
        the callers take their slower path for the rest of the process).
    """
    key = (name, source)
    if key not in _LOADED:
        lib = load_library(source, name)
        if lib is not None:
            for function, argtypes in signatures.items():
                getattr(lib, function).restype = None
                getattr(lib, function).argtypes = list(argtypes)
        _LOADED[key] = lib
    return _LOADED[key]


#: The start of a :func:`load_extension` source: Python's header (first, as it asks) and ``parse``,
#: which reads the arguments of a METH_FASTCALL function by type codes as ctypes would take them:
#: ``l`` a C long, ``d`` a double, ``p`` a pointer (bytes: their data; else an integer address).
#: So one C function can be called through the C API and through ctypes with the same arguments.
#: ``read_floats`` and ``read_rows`` copy a sequence of floats, or rows of them, into C doubles;
#: ``float_list`` and ``long_list`` make Python lists of C doubles and longs.
C_API_HEAD = r"""#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <string.h>

typedef union {
    long l;
    double d;
    void *p;
} arg_t;

/* The arguments by type code: l a C long, d a double, p a pointer (bytes: its data; else an address). */
static int parse(PyObject *const *args, Py_ssize_t nargs, const char *codes, arg_t *out) {
    Py_ssize_t n = (Py_ssize_t)strlen(codes);
    if (nargs != n) {
        PyErr_Format(PyExc_TypeError, "expected %zd arguments, got %zd", n, nargs);
        return -1;
    }
    for (Py_ssize_t i = 0; i < n; ++i) {
        PyObject *o = args[i];
        if (codes[i] == 'l') {
            out[i].l = PyLong_AsLong(o);
            if (out[i].l == -1 && PyErr_Occurred()) return -1;
        } else if (codes[i] == 'd') {
            out[i].d = PyFloat_AsDouble(o);
            if (out[i].d == -1.0 && PyErr_Occurred()) return -1;
        } else if (PyBytes_Check(o)) {
            out[i].p = PyBytes_AS_STRING(o);
        } else {
            out[i].p = PyLong_AsVoidPtr(o); /* 0: NULL, as ctypes passes it (an empty array's address) */
            if (out[i].p == NULL && PyErr_Occurred()) return -1;
        }
    }
    return 0;
}

/* Up to n floats of a flat sequence into out; the count read, or -1 on an error (set). */
static Py_ssize_t read_floats(PyObject *items, double *out, Py_ssize_t n) {
    PyObject *seq = PySequence_Fast(items, "expected a sequence of floats");
    if (seq == NULL) return -1;
    Py_ssize_t m = PySequence_Fast_GET_SIZE(seq);
    PyObject **xs = PySequence_Fast_ITEMS(seq);
    for (Py_ssize_t i = 0; i < m && i < n; ++i) {
        out[i] = PyFloat_CheckExact(xs[i]) ? PyFloat_AS_DOUBLE(xs[i]) : PyFloat_AsDouble(xs[i]);
        if (out[i] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(seq);
            return -1;
        }
    }
    Py_DECREF(seq);
    return m;
}

/* Rows of floats one after the other into out (n floats); 1 where they hold n floats, 0 where not
   (ragged: the caller's Python path decides), -1 on an error. */
static int read_rows(PyObject *rows, double *out, Py_ssize_t n) {
    PyObject *seq = PySequence_Fast(rows, "expected a sequence of rows");
    if (seq == NULL) return -1;
    Py_ssize_t k = PySequence_Fast_GET_SIZE(seq), at = 0;
    PyObject **items = PySequence_Fast_ITEMS(seq);
    for (Py_ssize_t r = 0; r < k; ++r) {
        Py_ssize_t m = read_floats(items[r], out + at, n - at);
        if (m < 0 || at + m > n) {
            Py_DECREF(seq);
            return m < 0 ? -1 : 0;
        }
        at += m;
    }
    Py_DECREF(seq);
    return at == n;
}

/* A list of n floats. */
static PyObject *float_list(const double *x, long n) {
    PyObject *list = PyList_New(n);
    if (list == NULL) return NULL;
    for (long i = 0; i < n; ++i) {
        PyObject *f = PyFloat_FromDouble(x[i]);
        if (f == NULL) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SET_ITEM(list, i, f);
    }
    return list;
}

/* A list of n integers. */
static PyObject *long_list(const long *x, long n) {
    PyObject *list = PyList_New(n);
    if (list == NULL) return NULL;
    for (long i = 0; i < n; ++i) {
        PyObject *f = PyLong_FromLong(x[i]);
        if (f == NULL) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SET_ITEM(list, i, f);
    }
    return list;
}
"""

_EXTENSIONS: dict[tuple[str, str], ModuleType | None] = {}


def load_extension(source: str, name: str) -> ModuleType | None:
    """`source`, a CPython extension module defining ``PyInit_<name>``, compiled and imported once per process.

    For kernels called many times per plan on a few numbers: a call through the C API costs a
    small part of a ctypes call (whose argument conversion costs far more than such a kernel's
    arithmetic). Built like :func:`load_library` (cached on disk under a hash of the source, the
    compiler, the flags and Python's include folder and extension suffix), with Python's headers.

    Returns:
        The module (the same object on every call), or None where it cannot be built: compiling
        switched off (``PLANNER_JIT=0``), no compiler, no ``Python.h`` (no warning), or
        compiling or importing fails (then with a ``RuntimeWarning``); the callers then take
        their Python path.
    """
    key = (name, source)
    if key in _EXTENSIONS:
        return _EXTENSIONS[key]
    module = None
    compiler = find_compiler()
    include = sysconfig.get_paths().get("include")
    suffix = sysconfig.get_config_var("EXT_SUFFIX") or ".so"
    if compiler is not None and include and (Path(include) / "Python.h").is_file():
        flags = (*FLAGS, f"-I{include}")
        digest = hashlib.sha256("\0".join([source, compiler, *flags, suffix]).encode()).hexdigest()[:24]
        library = native_cache_dir() / f"{name}_{digest}{suffix}"
        try:
            build_library(source, library, compiler, flags, timeout=120)
            spec = importlib.util.spec_from_file_location(name, library)
            if spec is None or spec.loader is None:
                raise ImportError(f"cannot import {library}")
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
        except (OSError, RuntimeError, ImportError, subprocess.SubprocessError) as exc:
            warnings.warn(
                f"planner: cannot build the C extension {name!r} ({exc}); using the slower path",
                RuntimeWarning,
                stacklevel=2,
            )
            module = None
    _EXTENSIONS[key] = module
    return module
