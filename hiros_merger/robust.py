"""The robust mean of each track's detections: weighted median start, Cauchy reweighting.

Each joint starts at the weighted median of its cameras' positions (per coordinate), then
``iterations`` times becomes the weighted mean with the reliability weight ``w`` of each
camera multiplied by a Cauchy weight of its distance ``r`` to the current estimate::

    w' = w / (1 + (r / outlier_scale)²)        0 where r is not finite
    w' = 0  if r > outlier_cutoff or r_own > limb_cutoff, unless no camera is left

``r`` is the mean distance over the joint's limb in that detection and ``r_own`` the limb's
farthest joint, so a camera's limb is kept or dropped whole (a joint that is not finite keeps
its own distance in both). The final
weights are the same rule around the final estimate; they weigh the confidences and the
velocities too.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hiros_core.compiled import refresh_stale_caches
from hiros_merger import numerics
from hiros_merger.kernel_args import Observations, RobustSettings
from hiros_merger.numerics import finite3, n_groups

__all__ = ["final_weights", "robust_mean", "weighted_means", "weighted_median"]


@njit(cache=True, error_model="numpy")
def weighted_median(positions: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Per coordinate, the smallest value whose cumulative weight reaches half the total.

    ``positions`` ``(M, C, J, 3)``, ``weight`` ``(M, C, J)``; only finite values of positive
    weight count; NaN where none does. Returns ``(M, J, 3)``.
    """
    n_tracks, n_slots, n_joints = positions.shape[:3]
    fused = np.empty((n_tracks, n_joints, 3))
    keys = np.empty(n_slots)
    weights = np.empty(n_slots)
    for m in range(n_tracks):
        for j in range(n_joints):
            for a in range(3):
                count = 0
                for c in range(n_slots):
                    value = positions[m, c, j, a]
                    w = weight[m, c, j] if math.isfinite(value) else 0.0
                    if w > 0:  # insertion sort of the few weighted values
                        i = count
                        while i > 0 and keys[i - 1] > value:
                            keys[i] = keys[i - 1]
                            weights[i] = weights[i - 1]
                            i -= 1
                        keys[i] = value
                        weights[i] = w
                        count += 1
                total = 0.0
                for i in range(count):
                    total += weights[i]
                if not total > 0:
                    fused[m, j, a] = np.nan
                    continue
                cumulative = 0.0
                for i in range(count):
                    cumulative += weights[i]
                    if cumulative >= 0.5 * total:
                        fused[m, j, a] = keys[i]
                        break
    return fused


@njit(cache=True, error_model="numpy")
def residuals(positions: np.ndarray, fused: np.ndarray, residual: np.ndarray) -> None:
    """``residual`` ``(M, C, J)``: each detection's joint distances to ``fused`` ``(M, J, 3)``."""
    n_tracks, n_slots, n_joints = positions.shape[:3]
    for m in range(n_tracks):
        for c in range(n_slots):
            for j in range(n_joints):
                dx = positions[m, c, j, 0] - fused[m, j, 0]
                dy = positions[m, c, j, 1] - fused[m, j, 1]
                dz = positions[m, c, j, 2] - fused[m, j, 2]
                residual[m, c, j] = math.sqrt(dx * dx + dy * dy + dz * dz)


@njit(cache=True, error_model="numpy")
def limb_means(
    values: np.ndarray, finite: np.ndarray, groups: np.ndarray, out: np.ndarray, peak: np.ndarray
) -> None:
    """``out[m, c, j]`` mean and ``peak[m, c, j]`` max of ``values[m, c, k]`` over j's limb.

    Over the finite joints k of the limb (``groups``) in that detection; a joint that is not
    finite keeps its own value in both.
    """
    n_tracks, n_slots, n_joints = values.shape
    count = n_groups(groups)
    sums = np.zeros(count)
    counts = np.zeros(count)
    highest = np.zeros(count)
    for m in range(n_tracks):
        for c in range(n_slots):
            sums[:] = 0.0
            counts[:] = 0.0
            highest[:] = 0.0
            for j in range(n_joints):
                if finite[m, c, j] and math.isfinite(values[m, c, j]):
                    g = groups[j]
                    sums[g] += values[m, c, j]
                    counts[g] += 1.0
                    highest[g] = max(highest[g], values[m, c, j])
            for j in range(n_joints):
                g = groups[j]
                if finite[m, c, j] and counts[g] > 0:
                    out[m, c, j] = sums[g] / counts[g]
                    peak[m, c, j] = highest[g]
                else:
                    out[m, c, j] = values[m, c, j]
                    peak[m, c, j] = values[m, c, j]


@njit(cache=True, error_model="numpy")
def judged_residuals(  # noqa: PLR0917
    positions: np.ndarray,
    fused: np.ndarray,
    finite: np.ndarray,
    groups: np.ndarray,
    residual: np.ndarray,
    limb: np.ndarray,
    peak: np.ndarray,
) -> None:
    """Each detection's joint distances to ``fused``, and what the weights judge them by.

    ``limb``/``peak``: the mean/max over each joint's limb (``limb_means``).
    """
    residuals(positions, fused, residual)
    limb_means(residual, finite, groups, limb, peak)


@njit(cache=True, error_model="numpy", inline="always")
def within_cutoffs(residual: float, own: float, settings: RobustSettings) -> bool:
    """Whether a joint is within ``outlier_cutoff`` and its own within ``limb_cutoff``."""
    return residual <= settings.outlier_cutoff and own <= settings.limb_cutoff


@njit(cache=True, error_model="numpy")
def cauchy_weights(
    weight: np.ndarray,
    residual: np.ndarray,
    own: np.ndarray,
    settings: RobustSettings,
    out: np.ndarray,
) -> None:
    """The module docstring's ``w'`` of every joint of every detection into ``out``.

    All ``(M, C, J)``: ``residual`` is what the Cauchy weight and ``outlier_cutoff`` judge,
    ``own`` what ``limb_cutoff`` judges (``judged_residuals``' ``limb`` and ``peak``).
    """
    n_tracks, n_slots, n_joints = weight.shape
    for m in range(n_tracks):
        for j in range(n_joints):
            inside_total = 0.0
            for c in range(n_slots):
                r = residual[m, c, j]
                scaled = r / settings.outlier_scale
                robust = weight[m, c, j] / (1.0 + scaled * scaled)
                if not math.isfinite(r):
                    robust = 0.0
                out[m, c, j] = robust
                if within_cutoffs(r, own[m, c, j], settings):
                    inside_total += robust
            if inside_total > 0:
                for c in range(n_slots):
                    if not within_cutoffs(residual[m, c, j], own[m, c, j], settings):
                        out[m, c, j] = 0.0


@njit(cache=True, error_model="numpy", inline="always")
def weighted_mean3(
    values: np.ndarray, weights: np.ndarray, m: int, j: int, out: np.ndarray
) -> None:
    """``out[m, j]``: the ``weights[m, :, j]`` mean of the finite ``values[m, :, j]`` ``(3,)``.

    ``values`` ``(M, C, J, 3)``, ``weights`` ``(M, C, J)``; summed in camera order; NaN where
    the weights sum to 0.
    """
    total = 0.0
    sx = sy = sz = 0.0
    for c in range(weights.shape[1]):
        x, y, z = values[m, c, j, 0], values[m, c, j, 1], values[m, c, j, 2]
        if finite3(x, y, z):
            w = weights[m, c, j]
            total += w
            sx += x * w
            sy += y * w
            sz += z * w
    out[m, j, 0] = sx / total if total != 0 else np.nan
    out[m, j, 1] = sy / total if total != 0 else np.nan
    out[m, j, 2] = sz / total if total != 0 else np.nan


@njit(cache=True, error_model="numpy")
def robust_mean(
    seen: Observations, groups: np.ndarray, settings: RobustSettings, fused: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reweight ``fused`` ``(M, J, 3)`` (the start) ``iterations`` times into the robust mean.

    Of the ``seen`` positions with their reliability weights. Returns the final estimate's
    ``residual``, ``limb`` and ``peak`` ``(M, C, J)`` (``judged_residuals``).
    """
    positions, finite, weight = seen.positions, seen.finite, seen.weight
    n_tracks, n_slots, n_joints = weight.shape
    residual = np.empty((n_tracks, n_slots, n_joints))
    limb = np.empty((n_tracks, n_slots, n_joints))
    peak = np.empty((n_tracks, n_slots, n_joints))
    robust = np.empty((n_tracks, n_slots, n_joints))
    for _ in range(settings.iterations):
        judged_residuals(positions, fused, finite, groups, residual, limb, peak)
        cauchy_weights(weight, limb, peak, settings, robust)
        for m in range(n_tracks):
            for j in range(n_joints):
                weighted_mean3(positions, robust, m, j, fused)
    judged_residuals(positions, fused, finite, groups, residual, limb, peak)
    return residual, limb, peak


@njit(cache=True, error_model="numpy")
def final_weights(
    weight: np.ndarray, limb: np.ndarray, peak: np.ndarray, settings: RobustSettings
) -> np.ndarray:
    """``(M, C, J)`` the Cauchy weights around the final estimate (``robust_mean``'s)."""
    final = np.empty(weight.shape)
    cauchy_weights(weight, limb, peak, settings, final)
    return final


@njit(cache=True, error_model="numpy")
def weighted_means(
    final: np.ndarray, confidences: np.ndarray, velocities: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The ``final`` weighted mean confidence ``(M, J)`` and velocity ``(M, J, 3)``.

    Confidences over the detections of positive weight, velocities over the finite ones;
    NaN where their weights sum to 0.
    """
    n_tracks, n_slots, n_joints = final.shape
    confidence = np.empty((n_tracks, n_joints))
    velocity = np.empty((n_tracks, n_joints, 3))
    for m in range(n_tracks):
        for j in range(n_joints):
            total = mean = 0.0
            for c in range(n_slots):
                w = final[m, c, j]
                if w > 0:
                    total += w
                    mean += confidences[m, c, j] * w
            confidence[m, j] = mean / total if total != 0 else np.nan
            weighted_mean3(velocities, final, m, j, velocity)
    return confidence, velocity


refresh_stale_caches(globals(), numerics)  # the kernels above call numerics' kernels
