"""Loaded scenes, kept once per file version: a path is parsed again only after its file changes.

A file version is (resolved path, modification time in ns, size in bytes). Thread-safe; the loaded
objects are shared by every caller, so they must hand out copies of anything mutable.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Generic, TypeVar

__all__ = ["FileCache"]

T = TypeVar("T")


class FileCache(Generic[T]):
    """``get(path, load)``: ``load(path)`` once per version of the file at ``path``."""

    def __init__(self) -> None:
        self._items: dict[tuple[str, int, int], T] = {}
        self._lock = threading.Lock()

    def get(self, path: Path, load: Callable[[Path], T]) -> T:
        """The object loaded from ``path`` (resolved, existing) in its current version."""
        stat = path.stat()
        key = (str(path), stat.st_mtime_ns, stat.st_size)
        with self._lock:
            item = self._items.get(key)
            if item is None:
                item = load(path)
                self._items[key] = item
        return item

    def clear(self) -> None:
        """Forget every loaded object."""
        with self._lock:
            self._items.clear()
