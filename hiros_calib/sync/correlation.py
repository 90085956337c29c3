"""Every body pair's correlation over all lags at once, and its peak.

A track's signature is resampled on camera-clock multiples of ``GRID_STEP`` and
differentiated (which whitens slow posture changes and sharpens the peak); a body pair's
normalised cross-correlation over every lag comes from one FFT, its channels pooled: the
sum of per-channel covariances over the square root of the summed variances.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.fft import irfft, next_fast_len

from hiros_calib.signature import PoseSignature
from hiros_calib.sync.clock import fisher_significance
from hiros_calib.sync.params import GRID_STEP, MIN_MOTION, MIN_OVERLAP, SyncParams

if TYPE_CHECKING:
    from hiros_calib.sync.work import TrackWork

__all__ = ["Candidate", "Curve", "GridSignal", "body_pair_candidates", "grid_signal", "resample"]


@dataclass
class GridSignal:
    """A signature on the camera's grid ``k * step`` from index ``k0``, mean-free, weighted."""

    k0: int
    values: np.ndarray  # (N, C) weighted, mean-free derivative of the signature
    present: np.ndarray  # (N,) 1 inside the track, 0 in gaps
    energy: np.ndarray  # (N,) sum over channels of values**2


def resample(times: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``(T, C)`` samples at ``grid`` (inside the sample span)."""
    idx = np.clip(np.searchsorted(times, grid, side="right") - 1, 0, len(times) - 2)
    frac = ((grid - times[idx]) / (times[idx + 1] - times[idx]))[:, None]
    frac = frac.astype(values.dtype, copy=False)  # keep single precision single
    low = values[idx]
    return low + (values[idx + 1] - low) * frac


def grid_signal(signature: PoseSignature, step: float) -> GridSignal | None:
    """The signature's weighted, mean-free derivative on its camera's grid (None: too short)."""
    times = signature.times
    k0, k1 = math.ceil(times[0] / step), math.floor(times[-1] / step)
    if k1 - k0 < 4:
        return None
    grid = np.arange(k0, k1 + 1) * step
    weights = signature.weights
    total = weights.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(total > 0, np.nansum(signature.values * weights, axis=0) / total, 0.0)
    # single precision: these only feed the coarse FFT correlation
    centred = np.where(weights > 0, signature.values - mean, 0.0).astype(np.float32)
    values = resample(times, centred, grid)
    w = resample(times, weights.astype(np.float32), grid)
    derivative = np.gradient(values, step, axis=0) * w
    return GridSignal(k0, derivative, np.ones(len(grid)), (derivative**2).sum(axis=1))


@dataclass
class Curve:
    """Pooled correlation sums of one body pair over absolute lag indices ``first..``."""

    first: int  # absolute lag index (lag = index * step) of element 0
    sab: np.ndarray
    saa: np.ndarray
    sbb: np.ndarray
    count: np.ndarray

    def correlation(self) -> np.ndarray:
        """The normalised correlation at each lag (NaN where a variance is 0)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.sab / np.sqrt(self.saa * self.sbb)


def _correlate(a: GridSignal, b: GridSignal, nfft: int, work: TrackWork) -> Curve:
    """All-lag sums for ``tau = (a.k0 - b.k0 + k) * step``: a[n] against b[n - k]."""
    fa, pa, ea = work.spectra(a, nfft)
    fb, pb, eb = work.spectra(b, nfft)
    sab = irfft(np.einsum("fc,fc->f", fa, np.conj(fb)), n=nfft)
    saa = irfft(ea * np.conj(pb), n=nfft)
    sbb = irfft(pa * np.conj(eb), n=nfft)
    count = irfft(pa * np.conj(pb), n=nfft)
    na, nb = len(a.present), len(b.present)
    # circular lags: k in [-(nb-1), na-1]; reorder to ascending
    order = np.r_[nfft - (nb - 1) : nfft, 0:na]
    return Curve(
        a.k0 - b.k0 - (nb - 1),
        sab[order].astype(float),
        np.maximum(saa[order], 0).astype(float),
        np.maximum(sbb[order], 0).astype(float),
        np.round(count[order]).astype(float),
    )


@dataclass
class Candidate:
    """One body pair's correlation peak."""

    index_a: int
    index_b: int
    curve: Curve
    lag_index: int  # absolute lag index of the peak
    peak: float
    sharpness: float
    ambiguity: float
    overlap: float  # seconds

    @property
    def score(self) -> float:
        """Peak times sharpness: how the sharpest pairs are ranked for the consensus."""
        return self.peak * self.sharpness

    @property
    def significance(self) -> float:
        """Fisher z of the peak times the square root of the overlap (s)."""
        return float(fisher_significance(self.peak, self.overlap))


def _peak(
    curve: Curve,
    params: SyncParams,
    search: tuple[float, float] | None,
    context: tuple[float, float] | None = None,
) -> tuple[int, float, float, float, float] | None:
    """(lag index, peak, sharpness, ambiguity, overlap s) of a curve, None when nothing valid.

    The peak is the lag of greatest significance, Fisher's z of the correlation times the
    square root of the overlap: a high correlation over a few seconds of overlap at the edge
    of the lag range is more often chance than one slightly lower over the whole recording.
    Its sharpness is measured against the curve within ``context`` (s; default ``search``).
    """
    step = GRID_STEP
    r = curve.correlation()
    lags = (curve.first + np.arange(len(r))) * step
    overlap = curve.count * step
    usable = (overlap >= MIN_OVERLAP) & np.isfinite(r)
    valid = usable & _within(lags, search)
    if valid.sum() < 5:
        return None
    significance = np.where(valid, fisher_significance(r, overlap), -np.inf)
    best = int(np.argmax(significance))
    peak = float(r[best])
    spread = r[usable & _within(lags, context)] if context is not None else r[valid]
    median = float(np.median(spread))
    mad = 1.4826 * float(np.median(np.abs(spread - median)))
    sharpness = (peak - median) / max(mad, 1e-6)
    # second most significant lag away from the main lobe, relative to the best
    exclusion = max(3, round(0.25 / step))
    far = np.abs(np.arange(len(r)) - best) > exclusion
    others = significance[far]
    top = float(significance[best])
    ambiguity = float(others.max() / top) if np.isfinite(others).any() and top > 0 else 0.0
    return curve.first + best, peak, sharpness, max(ambiguity, 0.0), float(overlap[best])


def _within(lags: np.ndarray, span: tuple[float, float] | None) -> np.ndarray | bool:
    """Which ``lags`` (s) lie in ``span`` (all when None)."""
    return True if span is None else (lags >= span[0]) & (lags <= span[1])


def body_pair_candidates(
    sig_a: list[PoseSignature],
    sig_b: list[PoseSignature],
    params: SyncParams,
    search: tuple[float, float] | None,
    work: TrackWork,
    *,
    context: tuple[float, float] | None = None,
) -> list[Candidate]:
    """Every moving body pair's correlation curve and peak within ``search``.

    Each peak's sharpness is measured within ``context`` (s; default ``search``).
    """
    grid_a = {i: work.grid(s) for i, s in enumerate(sig_a) if work.motion(s) >= MIN_MOTION}
    grid_b = {j: work.grid(s) for j, s in enumerate(sig_b) if work.motion(s) >= MIN_MOTION}
    grid_a = {i: g for i, g in grid_a.items() if g is not None}
    grid_b = {j: g for j, g in grid_b.items() if g is not None}
    if not grid_a or not grid_b:
        return []
    length = max(len(g.present) for g in grid_a.values()) + max(
        len(g.present) for g in grid_b.values()
    )
    nfft = work.nfft if work.nfft >= length else next_fast_len(length)
    candidates: list[Candidate] = []
    for i, ga in grid_a.items():
        for j, gb in grid_b.items():
            curve = _correlate(ga, gb, nfft, work)
            found = _peak(curve, params, search, context)
            if found is not None:
                candidates.append(Candidate(i, j, curve, *found))
    return candidates
