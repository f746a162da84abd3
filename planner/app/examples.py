"""The example plan files shipped with the package (``planner examples``).

An installed package maps the repository's top-level ``examples/`` folder to
``planner.examples``; imported from the source tree the folder is read where it is.
"""

from __future__ import annotations

import re
import shutil
from importlib import resources
from pathlib import Path

from planner.exceptions import InvalidArgumentError

__all__ = ["example_files", "examples_dir", "write_examples"]

_SUFFIXES = (".yaml", ".yml", ".json")


def examples_dir() -> Path:
    """The folder of the example plan files."""
    try:
        return Path(str(resources.files("planner.examples")))
    except ModuleNotFoundError:
        return Path(__file__).resolve().parents[2] / "examples"


def example_files() -> dict[str, str]:
    """Each example plan file's name and its ``name:`` (what it plans)."""
    out = {}
    for path in sorted(examples_dir().iterdir()):
        if path.suffix in _SUFFIXES:
            found = re.search(r'^\s*"?name"?\s*:\s*"?([^"\n,]+)', path.read_text(encoding="utf-8"), re.MULTILINE)
            out[path.name] = found.group(1).strip() if found else ""
    return out


def write_examples(out: str | Path) -> list[Path]:
    """Copy every example plan file into a directory (created if missing).

    Args:
        out: Destination directory; existing files of the same names are replaced.

    Returns:
        The paths written.

    Raises:
        InvalidArgumentError: If the directory cannot be created or written.
    """
    folder = Path(out)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        return [Path(shutil.copyfile(examples_dir() / name, folder / name)) for name in example_files()]
    except OSError as exc:
        raise InvalidArgumentError(f"cannot write examples into {str(folder)!r}: {exc.strerror}") from exc
