"""A minimal progress bar for long runs: drawn on a terminal, silent when piped or under CI."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterable, Iterator
from typing import TextIO, TypeVar

T = TypeVar("T")

__all__ = ["progress", "progress_enabled"]


def progress_enabled(stream: TextIO | None = None) -> bool:
    """Whether a progress bar should be drawn: on a terminal, and not when CI is set."""
    stream = stream or sys.stderr
    if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
        return False
    return bool(getattr(stream, "isatty", lambda: False)())


def progress(
    items: Iterable[T], total: int | None = None, label: str = "", stream: TextIO | None = None
) -> Iterator[T]:
    """Yield `items`, drawing ``label [#####.....] k/n  elapsed`` on stderr when enabled."""
    stream = stream or sys.stderr
    if not progress_enabled(stream):
        yield from items
        return
    if total is None:
        try:
            total = len(items)  # type: ignore[arg-type]
        except TypeError:
            total = 0
    start = last = time.perf_counter()
    width = 30
    done = 0
    for item in items:
        yield item
        done += 1
        now = time.perf_counter()
        if now - last >= 0.1 or done == total:
            last = now
            filled = int(width * done / total) if total else 0
            bar = "#" * filled + "." * (width - filled)
            count = f"{done}/{total}" if total else f"{done}"
            stream.write(f"\r{label} [{bar}] {count}  {now - start:5.1f} s")
            stream.flush()
    stream.write("\n")
    stream.flush()
