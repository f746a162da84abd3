"""Reading the project's YAML/JSON input files (arm descriptions, plan files)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from planner.exceptions import InvalidArgumentError

__all__ = ["ANGLE_UNITS", "LENGTH_UNITS", "read_data_file"]

#: Length units an input file may declare, in metres.
LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
#: Angle units an input file may declare, in radians.
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}


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
