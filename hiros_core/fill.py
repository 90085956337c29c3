"""Compiled byte-run copies that encoders use to fill a message in place (numba).

An encoder with a plan (``hiros_core.codec``) knows, per message shape, a byte template and
where each value goes. For a SkeletonGroup those values are a few packed integer fields and
runs of float64 rows (a box, a marker or link row: 22 or 20 floats each), read from the
group's ``SkeletonRows`` stack when its skeletons are one, else from their concatenation.
Copying them run by run in numpy would be hundreds of calls; one scatter needs an 8-byte
aligned target, which a message inside an MCAP chunk is not. This kernel copies the template
and every run in one call, into any uint8 buffer at any offset. It imports numba, so the
codec imports it at its first call (the rule: ``hiros_core.compiled``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["fill_runs"]


@njit(cache=True)
def fill_runs(  # noqa: PLR0917 - numba kernels take positional arguments
    out: np.ndarray,
    at: int,
    template: np.ndarray,
    packed: bytes,
    field_runs: np.ndarray,
    boxes: np.ndarray,
    markers: np.ndarray,
    links: np.ndarray,
    runs: np.ndarray,
) -> None:
    """Write the message at ``out[at:]``: the template, then the fields, then the floats.

    ``field_runs`` rows: (message offset, offset in ``packed``, bytes); ``runs`` rows:
    (message offset, source, offset in the source, floats), the source being ``boxes``,
    ``markers`` or ``links`` (0, 1, 2): flat float64 arrays, the three fields of a
    ``SkeletonRows`` or one concatenation of every value passed three times. Bits are copied
    as they are (NaN payloads included), exactly as a numpy scatter of the same values would.
    """
    sources = (boxes.view(np.uint8), markers.view(np.uint8), links.view(np.uint8))
    _copy(out, at, template, 0, template.size)
    for k in range(field_runs.shape[0]):
        _copy(out, at + field_runs[k, 0], packed, field_runs[k, 1], field_runs[k, 2])
    for k in range(runs.shape[0]):
        source = sources[runs[k, 1]]
        _copy(out, at + runs[k, 0], source, 8 * runs[k, 2], 8 * runs[k, 3])


@njit(cache=True, inline="always")
def _copy(out: np.ndarray, target: int, source: np.ndarray, start: int, size: int) -> None:
    """``out[target:target + size] = source[start:start + size]`` as a plain loop.

    Unsigned indices: with signed ones numba wraps negative indices, which keeps LLVM from
    vectorising the loop (~10x slower); numba's slice assignment is slower still.
    """
    target, start = np.uint64(target), np.uint64(start)
    for i in range(np.uint64(size)):
        out[target + i] = source[start + i]
