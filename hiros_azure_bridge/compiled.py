"""Compiled (numba) form of the bridge's usual frame, same rows bit for bit as the numpy path.

The driver's usual message (every marker an ADD of a known joint, ids in increasing order, as
the ids of earlier messages showed) turns into marker rows by a dozen small numpy calls per
message in ``DriverBridge._kept_markers``/``_skeletons``; this kernel does it in one call.
Imported only when numba is loaded already (the pipeline's stages load it), so the bridge node
and light commands never pay numba's import; compiled on first call, cached on disk.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["driver_rows"]


@njit(cache=True)
def driver_rows(  # noqa: PLR0917 - a compiled kernel takes plain positional values
    poses: np.ndarray,
    levels: np.ndarray,
    rows: np.ndarray,
    n_people: int,
    n_joints: int,
    position_scale: float,
    confidence_levels: float,
) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(P, J, 20)`` marker rows and ``(P, J)`` presence of a usual driver message.

    ``poses`` ``(n, 7)`` position and orientation per marker, ``levels`` ``(n,)`` confidence
    levels (NaN: none), ``rows`` each marker's row in the flattened people x joints. Rows hold
    [level / confidence_levels, position * position_scale, orientation], the orientation NaN
    when its squared norm is not positive (zero or NaN: the driver's "unknown"); every other
    value NaN. The flag is False when a position is not finite: the caller then takes the
    general path, which counts and drops such markers.
    """
    markers = np.full((n_people * n_joints, 20), np.nan)
    present = np.zeros(n_people * n_joints, dtype=np.bool_)
    shaped = (n_people, n_joints)
    for i in range(poses.shape[0]):
        row = markers[rows[i]]
        for k in range(3):
            value = poses[i, k]
            if position_scale != 1.0:
                value *= position_scale
            if not math.isfinite(value):
                return (
                    markers.reshape(n_people, n_joints, 20),
                    present.reshape(n_people, n_joints),
                    False,
                )
            row[1 + k] = value
        norm = 0.0
        for k in range(3, 7):
            norm += poses[i, k] * poses[i, k]
        if norm > 0:
            for k in range(3, 7):
                row[1 + k] = poses[i, k]
        row[0] = levels[i] / confidence_levels
        present[rows[i]] = True
    return markers.reshape(*shaped, 20), present.reshape(shaped), True
