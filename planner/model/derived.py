"""A robot's cache of objects derived from it (IK solvers, collision models).

Higher layers build expensive objects from a :class:`~planner.model.robot.Robot` once and reuse
them: the IK layer's solvers, for instance. They are kept here, in a cache the robot owns, keyed
by the object's class: no module-level registry (which would keep every robot alive through the
objects that refer to it) and no attributes set on the robot by other modules. A derived object
that refers back to its robot forms a plain reference cycle, which the garbage collector frees
with the robot.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

__all__ = ["DerivedCache"]

T = TypeVar("T")


class DerivedCache:
    """Objects built from one robot on demand, one per class."""

    def __init__(self) -> None:
        self._items: dict[type, object] = {}

    def get(self, kind: type[T], build: Callable[[], T]) -> T:
        """The cached object of class ``kind``, built by ``build()`` on first use.

        Args:
            kind: The object's class (the cache key).
            build: Builds the object; called at most once per cache and class.

        Returns:
            The object.
        """
        item = self._items.get(kind)
        if item is None:
            item = build()
            self._items[kind] = item
        return item  # type: ignore[return-value]

    def clear(self) -> None:
        """Forget every derived object (they are rebuilt on next use)."""
        self._items.clear()

    def __contains__(self, kind: type) -> bool:
        return kind in self._items

    def __repr__(self) -> str:
        return f"DerivedCache({', '.join(k.__name__ for k in self._items)})"
