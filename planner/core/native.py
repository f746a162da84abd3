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
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

__all__ = ["FLAGS", "load_library", "native_cache_dir"]

#: Compiler flags: optimised without value-changing shortcuts (no -ffast-math), a shared library.
FLAGS = ("-O2", "-fPIC", "-shared")


def native_cache_dir() -> Path:
    """Folder of the compiled libraries (see the module docstring); not created here."""
    if os.environ.get("PLANNER_CACHE_DIR"):
        return Path(os.environ["PLANNER_CACHE_DIR"]) / "native"
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "planner" / "native"


def load_library(source: str, name: str) -> ctypes.CDLL | None:
    """The compiled `source`, from the cache when there, or None where it cannot be built.

    Args:
        source: C source text.
        name: A short name for the library file (the cache key is added to it).

    Returns:
        The loaded library, or None when compiling is switched off (``PLANNER_JIT=0``), no
        compiler is found, or compiling or loading fails (then with a ``RuntimeWarning``).
    """
    if os.environ.get("PLANNER_JIT", "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    compiler = shutil.which(os.environ.get("CC") or "gcc")
    if compiler is None:
        return None
    key = hashlib.sha256("\0".join([source, compiler, *FLAGS]).encode()).hexdigest()[:24]
    folder = native_cache_dir()
    library = folder / f"{name}_{key}.so"
    try:
        if not library.exists():
            folder.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=folder) as tmp:
                path = Path(tmp) / f"{name}.c"
                path.write_text(source)
                built = Path(tmp) / f"{name}.so"
                proc = subprocess.run(
                    [compiler, *FLAGS, "-o", str(built), str(path), "-lm"], capture_output=True, text=True, timeout=120
                )
                if proc.returncode != 0:
                    raise RuntimeError(f"{compiler} failed: {proc.stderr.strip()[:500]}")
                os.replace(built, library)
        return ctypes.CDLL(str(library))
    except (OSError, RuntimeError, subprocess.SubprocessError) as exc:
        warnings.warn(
            f"planner: cannot build the C library {name!r} ({exc}); using the slower path", RuntimeWarning, stacklevel=2
        )
        return None
