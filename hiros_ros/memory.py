"""Giving freed memory back to the operating system in long-running nodes.

A node that now and then works through a large window (the ``calib`` node's estimates
allocate hundreds of megabytes of numpy arrays) keeps its resident size at the largest such
peak: glibc's malloc raises its mmap threshold after large frees, so later large arrays come
from the heap, and freed heap memory stays mapped. ``malloc_trim`` hands it back. Elsewhere
(another C library) this does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from functools import cache

__all__ = ["release_freed_memory"]


@cache
def _malloc_trim() -> ctypes._CFuncPtr | None:  # type: ignore[name-defined]
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        return ctypes.CDLL(name).malloc_trim
    except (OSError, AttributeError):
        return None


def release_freed_memory() -> bool:
    """Return the C heap's free memory to the operating system; True if it could be done."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
