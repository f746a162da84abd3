"""planner.core.native.load_extension: C kernels called through the C API."""

from __future__ import annotations

import sysconfig
from pathlib import Path

import pytest

from planner.core import native
from planner.core.native import C_API_HEAD, find_compiler, load_extension

_HAVE_HEADERS = (Path(sysconfig.get_paths().get("include", "")) / "Python.h").is_file()
pytestmark = pytest.mark.skipif(
    find_compiler() is None or not _HAVE_HEADERS, reason="no C compiler or no Python headers"
)

_SOURCE = (
    C_API_HEAD
    + r"""
static double scaled_sum(long n, const double *x, double s) {
    double total = 0.0;
    for (long i = 0; i < n; ++i) total += s * x[i];
    return total;
}

static PyObject *py_scaled_sum(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    arg_t a[3];
    if (parse(args, nargs, "lpd", a)) return NULL;
    return PyFloat_FromDouble(scaled_sum(a[0].l, a[1].p, a[2].d));
}

static PyMethodDef methods[] = {
    {"scaled_sum", (PyCFunction)(void (*)(void))py_scaled_sum, METH_FASTCALL, NULL},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "planner_test_extension", NULL, -1, methods};

PyMODINIT_FUNC PyInit_planner_test_extension(void) { return PyModule_Create(&module); }
"""
)


def test_extension_takes_ctypes_style_arguments(tmp_path, monkeypatch):
    from array import array

    monkeypatch.setenv("PLANNER_CACHE_DIR", str(tmp_path))
    module = load_extension(_SOURCE, "planner_test_extension")
    assert module is not None
    assert load_extension(_SOURCE, "planner_test_extension") is module  # once per process
    x = array("d", [1.0, 2.0, 3.5])
    assert module.scaled_sum(3, x.tobytes(), 2.0) == 13.0  # bytes: their data
    assert module.scaled_sum(2, x.buffer_info()[0], 1) == 3.0  # an address; an int as a double
    with pytest.raises(TypeError, match="expected 3 arguments, got 2"):
        module.scaled_sum(3, x.tobytes())
    with pytest.raises(TypeError):
        module.scaled_sum(3.0, x.tobytes(), 1.0)  # a float is no C long
    assert module.scaled_sum(0, 0, 1.0) == 0.0  # 0: NULL, as ctypes passes an empty array's address


def test_extension_is_none_when_switched_off_or_broken(tmp_path, monkeypatch):
    monkeypatch.setenv("PLANNER_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(native, "_EXTENSIONS", {})
    monkeypatch.setenv("PLANNER_JIT", "0")
    assert load_extension(_SOURCE, "planner_test_extension") is None
    monkeypatch.delenv("PLANNER_JIT")
    with pytest.warns(RuntimeWarning, match="cannot build the C extension 'planner_broken'"):
        assert load_extension("this is not C", "planner_broken") is None
