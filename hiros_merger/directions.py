"""``fuse_directions``: fused limbs whose links follow the cameras' robust link directions.

Per limb, the joints are placed root-outward: the limb's first joint at its fused position,
each further joint ``j`` at its parent ``p`` plus the fused link length along the link's
robust mean direction over the cameras (``link_direction``); then the limb is shifted so
that its mean joint is the fused one. The angles come from a consensus of directions rather
than from positions stitched from different cameras.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hiros_core.compiled import refresh_stale_caches
from hiros_merger import numerics
from hiros_merger.kernel_args import BodyLayout, DirectionSettings, Observations
from hiros_merger.numerics import n_groups

__all__ = ["follow_directions", "link_direction"]


@njit(cache=True, error_model="numpy")
def link_direction(  # noqa: PLR0917 - one link's arrays
    positions: np.ndarray,
    finite: np.ndarray,
    final: np.ndarray,
    link: tuple[int, int],
    settings: DirectionSettings,
    units: np.ndarray,
    weights: np.ndarray,
    out: np.ndarray,
) -> bool:
    """Robust mean direction of ``link`` ``(p, j)`` over one track's cameras into ``out``.

    ``positions`` ``(C, J, 3)``, ``finite`` and the weights ``final`` ``(C, J)`` are the
    track's. Each camera's unit vector ``u_c`` from ``p`` to ``j`` counts with
    ``w_c = sqrt(final[c, j] · final[c, p])``; the start is the normalised weighted mean,
    then ``iterations`` Weiszfeld steps on the sphere,
    ``u <- normalise(Σ w_c u_c / max(angle(u, u_c), eps))``, move it to the weighted
    spherical median. ``units`` ``(C, 3)`` and ``weights`` ``(C,)`` are scratch. False: no
    camera has the link.
    """
    p, j = link
    n_slots = positions.shape[0]
    total = 0.0
    sx = sy = sz = 0.0
    for c in range(n_slots):
        weights[c] = 0.0
        if not (finite[c, j] and finite[c, p]):
            continue
        w = math.sqrt(final[c, j] * final[c, p])
        dx = positions[c, j, 0] - positions[c, p, 0]
        dy = positions[c, j, 1] - positions[c, p, 1]
        dz = positions[c, j, 2] - positions[c, p, 2]
        norm = math.sqrt(dx * dx + dy * dy + dz * dz)
        if not (w > 0 and norm > 0):
            continue
        units[c, 0], units[c, 1], units[c, 2] = dx / norm, dy / norm, dz / norm
        weights[c] = w
        total += w
        sx += w * units[c, 0]
        sy += w * units[c, 1]
        sz += w * units[c, 2]
    norm = math.sqrt(sx * sx + sy * sy + sz * sz)
    if not (total > 0 and norm > 0):
        return False
    ux, uy, uz = sx / norm, sy / norm, sz / norm
    for _ in range(settings.iterations):
        sx = sy = sz = 0.0
        for c in range(n_slots):
            if weights[c] > 0:
                cx = uy * units[c, 2] - uz * units[c, 1]
                cy = uz * units[c, 0] - ux * units[c, 2]
                cz = ux * units[c, 1] - uy * units[c, 0]
                dot = ux * units[c, 0] + uy * units[c, 1] + uz * units[c, 2]
                angle = math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz), dot)
                w = weights[c] / max(angle, settings.eps)
                sx += w * units[c, 0]
                sy += w * units[c, 1]
                sz += w * units[c, 2]
        norm = math.sqrt(sx * sx + sy * sy + sz * sz)
        if not norm > 0:
            break
        ux, uy, uz = sx / norm, sy / norm, sz / norm
    out[0], out[1], out[2] = ux, uy, uz
    return True


@njit(cache=True, error_model="numpy")
def follow_directions(
    seen: Observations,
    final: np.ndarray,
    fused: np.ndarray,
    body: BodyLayout,
    settings: DirectionSettings,
) -> np.ndarray:
    """Fused skeletons ``(M, J, 3)`` whose links point along the cameras' robust directions.

    The module docstring's placement, over the links ``settings.parents`` names inside each
    limb (``body.groups``) in ``body.order`` (parents first), from the cameras' ``seen``
    positions with the weights ``final`` ``(M, C, J)``. A link that no camera sees
    keeps its fused offset; a limb's links across to another limb are not rebuilt (the limbs
    are placed apart).
    """
    groups, parents = body.groups, settings.parents
    positions, finite = seen.positions, seen.finite
    n_tracks, n_slots, n_joints = positions.shape[:3]
    count = n_groups(groups)
    out = fused.copy()
    units = np.empty((n_slots, 3))
    weights = np.empty(n_slots)
    direction = np.empty(3)
    shift = np.zeros((count, 3))
    counts = np.zeros(count)
    for m in range(n_tracks):
        for k in range(n_joints):
            j = body.order[k]
            p = parents[j]
            if p < 0 or groups[p] != groups[j]:
                continue
            dx = fused[m, j, 0] - fused[m, p, 0]
            dy = fused[m, j, 1] - fused[m, p, 1]
            dz = fused[m, j, 2] - fused[m, p, 2]
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            if not math.isfinite(length):
                continue
            if link_direction(
                positions[m], finite[m], final[m], (p, j), settings, units, weights, direction
            ):
                dx, dy, dz = length * direction[0], length * direction[1], length * direction[2]
            out[m, j, 0] = out[m, p, 0] + dx
            out[m, j, 1] = out[m, p, 1] + dy
            out[m, j, 2] = out[m, p, 2] + dz
        shift[:] = 0.0
        counts[:] = 0.0
        for j in range(n_joints):
            if math.isfinite(fused[m, j, 0]) and math.isfinite(out[m, j, 0]):
                g = groups[j]
                counts[g] += 1.0
                for a in range(3):
                    shift[g, a] += fused[m, j, a] - out[m, j, a]
        for j in range(n_joints):
            g = groups[j]
            if counts[g] > 0:
                for a in range(3):
                    out[m, j, a] += shift[g, a] / counts[g]
    return out


refresh_stale_caches(globals(), numerics)  # the kernels above call numerics' kernels
