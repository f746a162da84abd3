"""The distribution's name and version; the version is kept in one place, pyproject.toml."""

from __future__ import annotations

import re
from importlib import metadata
from pathlib import Path

__all__ = ["DISTRIBUTION", "__version__", "install_hint"]

#: The name to ``pip install`` (the import name is ``planner``; ``planner`` on PyPI is another project).
DISTRIBUTION = "servo-arm-planner"


def _version() -> str:
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        # Imported from a source tree that was never installed: read pyproject.toml.
        pyproject = Path(__file__).resolve().parents[2] / "pyproject.toml"
        try:
            found = re.search(r'^version\s*=\s*"([^"]+)"', pyproject.read_text(), re.MULTILINE)
        except OSError:
            found = None
        return found.group(1) if found else "0+unknown"


__version__ = _version()


def install_hint(extra: str) -> str:
    """The command that installs an optional extra, e.g. ``pip install 'servo-arm-planner[demo]'``."""
    return f"pip install '{DISTRIBUTION}[{extra}]'"
