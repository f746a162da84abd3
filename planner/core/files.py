"""Reading the project's YAML/JSON input files (arm descriptions, plan files)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from planner.exceptions import InvalidArgumentError

__all__ = ["read_data_file"]


def read_data_file(path: str | Path, what: str) -> Any:
    """Parse a file as JSON (``.json``) or YAML (anything else).

    Args:
        path: The file.
        what: What the file is, for messages (e.g. ``"plan file"``).

    Returns:
        The parsed data.

    Raises:
        InvalidArgumentError: If the file cannot be read or does not parse.
    """
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise InvalidArgumentError(f"cannot read {what} {str(p)!r}: {exc.strerror}") from exc
    try:
        if p.suffix.lower() == ".json":
            return json.loads(text)
        import yaml

        return yaml.safe_load(text)
    except Exception as exc:  # yaml and json raise several unrelated types
        raise InvalidArgumentError(f"cannot parse {what} {str(p)!r}: {exc}") from exc
