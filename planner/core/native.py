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
import os
import shlex
import shutil
import subprocess
import tempfile
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

__all__ = ["FLAGS", "build_library", "cache_dir", "find_compiler", "load_functions", "load_library", "native_cache_dir"]

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
