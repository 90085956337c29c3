"""Compiled (numba) forms of hiros_core's per-frame numpy helpers, same results bit for bit.

How hiros chooses between compiled and numpy code, one rule for the whole code base:

1. numba is a hard dependency. A helper that has a compiled kernel always runs it: the same
   call takes the same path whatever else the process has imported (a branch on the input,
   such as float64 rows or the driver's usual message, is the only choice left).
2. A kernel's numpy form is kept as the reference its test holds it equal to, never as a
   switch (no parameter, no branch on what is imported): beside the kernel where the product
   needs it too (for the inputs the kernel does not take; held equal bit for bit), else in
   ``test/support/`` (the stages' maths, held equal on random input by property tests).
3. ``hiros_core`` is imported by every command, and numba's import costs ~1 s: its callers
   import kernel modules (this one, ``fill``, ``driver.kernels``) inside the function, at the
   first call, not at module level. Live nodes and runs load them before their first
   message (the ``warm_up`` functions); ``make setup`` compiles them into numba's disk cache.

``model.link_rows`` runs for every person of every frame in the bridge and in most stages; its
dozen small numpy calls cost ~40 us where the arithmetic is a few hundred flops. Kernels
compile on first call and are cached on disk (``cache=True``).
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Mapping
from types import ModuleType
from typing import Any

import numpy as np
from numba import njit

__all__ = ["link_rows", "refresh_stale_caches", "unusable_rows"]


@njit(cache=True)
def _fmin(a: float, b: float) -> float:
    """``np.fmin``: the number when one is NaN, else the smaller; ``b`` when equal (-0/+0)."""
    if math.isnan(b):
        return a
    if math.isnan(a):
        return b
    return a if a < b else b


@njit(cache=True)
def _link_rows(
    markers: np.ndarray, present: np.ndarray, parents: np.ndarray, children: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    n_people, n_joints, width = markers.shape
    links = np.full((n_people, n_joints, width), np.nan)
    link_present = np.zeros((n_people, n_joints), dtype=np.bool_)
    for p in range(n_people):
        for k in range(children.size):
            parent, child = parents[k], children[k]
            if not (present[p, parent] and present[p, child]):
                continue
            link_present[p, child] = True
            row, a, c = links[p, child], markers[p, parent], markers[p, child]
            row[0] = _fmin(a[0], c[0])
            for i in range(1, 4):
                row[i] = (c[i] + a[i]) * 0.5
            for i in range(4, 8):
                row[i] = c[i]
    return links, link_present


def link_rows(
    markers: np.ndarray, marker_present: np.ndarray, parents: np.ndarray, children: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``model.link_rows`` for float64 ``(..., J, 20)`` rows (see there)."""
    shape = marker_present.shape
    n_joints, width = markers.shape[-2:]
    links, present = _link_rows(
        np.ascontiguousarray(markers).reshape(-1, n_joints, width),
        np.ascontiguousarray(marker_present).reshape(-1, n_joints),
        np.asarray(parents, dtype=np.intp),
        np.asarray(children, dtype=np.intp),
    )
    return links.reshape(*shape, width), present.reshape(shape)


@njit(cache=True, error_model="numpy")
def unusable_rows(markers: np.ndarray, present: np.ndarray) -> np.ndarray:
    """``(P,)`` True where a present joint of ``markers`` ``(P, J, 20)`` has a non-finite position.

    ``hiros_core.stacking.stack_frame``'s check, in one call instead of five numpy ones.
    """
    n_people, n = present.shape
    bad = np.zeros(n_people, dtype=np.bool_)
    for i in range(n_people):
        for j in range(n):
            if present[i, j] and not (
                np.isfinite(markers[i, j, 1])
                and np.isfinite(markers[i, j, 2])
                and np.isfinite(markers[i, j, 3])
            ):
                bad[i] = True
    return bad


def refresh_stale_caches(namespace: Mapping[str, Any], *dependencies: ModuleType) -> int:
    """Empty the disk caches of ``namespace``'s kernels written before a dependency changed.

    numba keys a cached kernel on its own source file only. A kernel that calls a kernel of
    another module (``_link_rows`` from here, say) would go on loading the machine code of
    the old callee after an edit or a ``git pull`` that changed only the callee's file. A
    module whose kernels call into ``dependencies`` calls this at its end: every kernel it
    defines whose cache index is older than the newest dependency source is flushed, so it
    compiles again (once) on its next call. Returns how many caches were flushed. Without a
    dependency, this module is the one compared with.
    """
    sources = dependencies or (sys.modules[__name__],)
    changed = max(os.stat(module.__file__).st_mtime for module in sources)
    flushed = 0
    for kernel in namespace.values():
        if getattr(getattr(kernel, "py_func", None), "__module__", None) != namespace["__name__"]:
            continue  # not a kernel, or one imported from elsewhere (its own module's to mind)
        cache = getattr(kernel, "_cache", None)
        index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
        try:
            if index is not None and os.stat(index).st_mtime < changed:
                cache.flush()
                flushed += 1
        except OSError:  # no index yet, or a read-only cache: nothing stale to load
            continue
    return flushed
