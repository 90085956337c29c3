"""Clock offsets between cameras from the people's own motion.

Method (Eichler et al., Sensors 2022, section 3.2, extended):

1. Every body track gets a camera-independent :mod:`~hiros_calib.signature`, resampled on a
   common grid of camera-clock multiples of ``grid_step``; for the coarse search its time
   derivative is used, which whitens the slow posture changes and sharpens the peak.
2. For a camera pair, every pair of body tracks (one per camera) gives a normalised
   cross-correlation curve over all lags at once (FFT; channels pooled: the sum of
   per-channel covariances over the square root of the summed variances).
3. Consensus: curves whose peak is high and sharp (robust z-score of the peak over the
   curve, the role of Eichler's coefficient of variation) vote for their peak lag, the best
   ``best_fraction`` choose the winning lag and every good curve near it joins.
4. Sub-frame refinement: a parabola through the pooled curve's peak, then the lag that
   maximises the pooled correlation of the cubic-spline interpolated signatures, searched as
   a continuous variable, so 30 Hz streams give millisecond offsets. Both signatures are
   evaluated on one fine grid, so neither stream's sample instants are favoured.
5. Drift: the same continuous refinement in sliding windows gives the lag over time.
6. N cameras: :func:`solve_clocks` fits one offset (and drift) per camera to all pairwise
   window measurements by robust least squares, reference camera fixed, so the offsets are
   globally consistent (loops close).

Sign convention: a pair's lag ``tau = t_a - t_b`` for the same event, so the signature of
camera b shifted by ``tau`` matches camera a; with the DESIGN.md clock model
``t_ref = t_cam + time_offset + drift (t_cam - drift_epoch)`` this means
``time_offset_b - time_offset_a = tau`` when there is no drift.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft
from scipy.interpolate import make_interp_spline
from scipy.ndimage import maximum_filter1d
from scipy.optimize import minimize_scalar

from hiros_calib.signature import DEFAULT_JOINTS, PoseSignature, pose_signature, select_joints
from hiros_calib.tracks import BodyTrack

__all__ = [
    "CameraClock",
    "PairOffset",
    "SyncParams",
    "clock_epochs",
    "close_loops",
    "contest_candidates",
    "estimate_pair_offset",
    "solve_clocks",
    "synchronise",
]


@dataclass
class SyncParams:
    """Parameters of the time-offset estimation (same names as the ``calib`` node's)."""

    joints: list[str] = field(default_factory=lambda: list(DEFAULT_JOINTS))
    """Joints whose distances form the signature; names missing from a layout are skipped."""
    mirror_invariant: bool = True
    """Make the signature immune to SDKs swapping left and right (see signature.py)."""
    grid_step: float = 0.01
    """Coarse correlation grid (s); the refinement goes below it."""
    refine_step: float = 0.01
    """Grid (s) on which the continuous refinement compares interpolated signatures."""
    max_offset: float = 0.0
    """Largest |offset| searched (s) without arrival times; 0 searches every lag."""
    prior_window: float = 1.0
    """How far (s) the true lag may lie from the lag the arrival times suggest.

    Lag aliases of repeated motion correlate nearly as well as the true lag; the times the
    messages arrived at one receiver pin the lag to within network latency. The lag found
    within this window is checked against the best lag anywhere (see ``prior_contradiction``),
    so a prior the motion contradicts is noticed and ignored, never silently obeyed.
    """
    min_prior_significance: float = 0.8
    """Within the arrival-time prior's window, a body pair whose peak's significance (Fisher
    z times the square root of the overlap, s) reaches this is usable: a correlation of 0.13
    over 40 s, far beyond chance among the few lags of the window."""
    prior_contradiction: float = 1.5
    """The motion contradicts the arrival-time prior when the best lag outside
    ``prior_window`` is this many times more significant (Fisher z of the correlation times
    the square root of the overlap) than the best lag within it; the search then takes every
    lag and the pair's quality says ``arrival_prior: contradicted``."""
    min_overlap: float = 3.0
    """Seconds two tracks must overlap at a lag for that lag to count."""
    min_motion: float = 0.01
    """A track whose smoothed signature moves less than this (m) is a still body: skipped."""
    min_peak: float = 0.05
    """Lowest peak correlation of a usable body pair (noisy SDK joints correlate weakly;
    the sharpness is the stronger test)."""
    min_sharpness: float = 4.0
    """Lowest robust z-score of a usable peak over its correlation curve (motion that does
    not repeat)."""
    min_repeated_peak: float = 0.3
    """A peak this high is usable even when its curve has other high peaks (motion repeated
    over the whole recording, where the z-score over the curve is low however clear the
    peak); the lags it competes with are then decided by the poses (see ``candidates``)."""
    candidate_ratio: float = 0.6
    """Local maxima of the pooled correlation at least this fraction of the peak are the
    pair's candidate lags, for the poses to check."""
    max_candidates: int = 4
    """At most this many candidate lags per camera pair (best first)."""
    max_ambiguity: float = 0.5
    """A camera pair whose runner-up lag correlates this nearly as well as the best (its
    correlation over the best's) cannot be timed by the motion alone: the poses decide
    between the candidate lags, and the pair is refused when they cannot either. Motion
    repeated over the whole recording correlates about as well at every repetition."""
    min_lag_margin: float = 1.15
    """The poses decide between candidate lags when the skeletons' rigid-fit residual at one
    lag is this many times smaller than at every other (see :mod:`~hiros_calib.lags`)."""
    best_fraction: float = 0.1
    """Fraction of the sharpest body pairs that choose the consensus lag (Eichler: 10 %)."""
    consensus_tolerance: float = 0.05
    """Body pairs whose peak lies within this (s) of the consensus join it."""
    loop_overrule_strength: float = 1.5
    """With three or more cameras, a pair whose lag the other pairs' loop contradicts is
    left out when its refined correlation's significance (Fisher z times the square root of
    the overlap, s) is below this and every other pair's is above. Unrelated motion signals,
    correlated over about half a second, reach about 0.7 on this scale (one standard
    deviation), so such a lag is noise, not a measurement (see :func:`overrule_weak_pairs`)."""
    window: float = 10.0
    """Window length (s) of the offset-over-time measurements that give the drift."""
    estimate_drift: bool = True
    """Fit a clock drift per camera (needs ``min_drift_span`` of common motion)."""
    min_drift_span: float = 30.0
    """Shortest span (s) of window measurements for a drift estimate."""
    max_drift: float = 1e-3
    """Largest drift (s/s) the window search allows for."""
    drift_prior: float = 1e-4
    """Typical clock drift (s/s, a standard deviation): short recordings whose windows
    cannot tell a drift apart from noise get a drift shrunk towards 0 (ridge prior)."""


@dataclass
class PairOffset:
    """The clock lag of camera b relative to camera a, or why there is none.

    Attributes:
        camera_a, camera_b: the two cameras.
        status: ``"ok"`` or ``"refused"``.
        reason: why it was refused (empty when ok).
        offset: ``tau = t_a - t_b`` (s) for the same event, over the whole overlap.
        windows: ``(W, 4)`` per window: centre time on b's clock, tau, weight, correlation.
        quality: peak correlation, sharpness, ambiguity, body pairs used/considered, ...
        lags: ``(L,)`` lags (s) of the pooled correlation curve (for plots).
        correlation: ``(L,)`` pooled correlation at those lags.
        body_pairs: ``(track_a, track_b)`` indices of the body pairs in the consensus.
        candidates: ``(K, 2)`` lags (s) the motion supports and their pooled correlation,
            best first; the first is ``offset``'s lobe. Other rows are lags one repetition
            away, or side lobes, for the poses to rule out.

    """

    camera_a: str
    camera_b: str
    status: str = "refused"
    reason: str = ""
    offset: float = math.nan
    windows: np.ndarray = field(default_factory=lambda: np.empty((0, 4)))
    quality: dict[str, Any] = field(default_factory=dict)
    lags: np.ndarray = field(default_factory=lambda: np.empty(0))
    correlation: np.ndarray = field(default_factory=lambda: np.empty(0))
    body_pairs: list[tuple[int, int]] = field(default_factory=list)
    candidates: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))

    @property
    def ok(self) -> bool:
        """True when the offset was determined."""
        return self.status == "ok"


@dataclass
class CameraClock:
    """One camera's clock relative to the reference (DESIGN.md model), or why it is unknown."""

    camera: str
    status: str = "refused"
    reason: str = ""
    time_offset: float = math.nan
    drift: float = 0.0
    drift_epoch: float = 0.0
    quality: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when the clock is determined."""
        return self.status == "ok"

    def to_reference(self, t_camera: np.ndarray | float) -> np.ndarray | float:
        """Camera-clock seconds to reference seconds."""
        return t_camera + self.time_offset + self.drift * (t_camera - self.drift_epoch)

    def from_reference(self, t_reference: np.ndarray | float) -> np.ndarray | float:
        """Reference seconds to camera-clock seconds (inverse of :meth:`to_reference`)."""
        return (t_reference - self.time_offset + self.drift * self.drift_epoch) / (1 + self.drift)


Settle = Callable[[PairOffset, Callable[[float], PairOffset]], PairOffset]
"""A check of one pair's lag before the global solve: ``settle(pair, repin) -> pair``."""


def _significance(correlation: Any, overlap: Any) -> Any:
    """Fisher z of a correlation times the square root of its overlap (s), per element.

    A high correlation over a few seconds of overlap is more often chance than a slightly
    lower one over the whole recording; this weighs the two alike.
    """
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.arctanh(np.clip(correlation, -0.999, 0.999)) * np.sqrt(overlap)


# --------------------------------------------------------------------------- grid signals


@dataclass
class _GridSignal:
    """A signature on the camera's grid ``k * step`` from index ``k0``, mean-free, weighted."""

    k0: int
    values: np.ndarray  # (N, C) weighted, mean-free derivative of the signature
    present: np.ndarray  # (N,) 1 inside the track, 0 in gaps
    energy: np.ndarray  # (N,) sum over channels of values**2


def _resample(times: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``(T, C)`` samples at ``grid`` (inside the sample span)."""
    idx = np.clip(np.searchsorted(times, grid, side="right") - 1, 0, len(times) - 2)
    frac = ((grid - times[idx]) / (times[idx + 1] - times[idx]))[:, None]
    frac = frac.astype(values.dtype, copy=False)  # keep single precision single
    low = values[idx]
    return low + (values[idx + 1] - low) * frac


def _grid_signal(signature: PoseSignature, step: float) -> _GridSignal | None:
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
    values = _resample(times, centred, grid)
    w = _resample(times, weights.astype(np.float32), grid)
    derivative = np.gradient(values, step, axis=0) * w
    return _GridSignal(k0, derivative, np.ones(len(grid)), (derivative**2).sum(axis=1))


# --------------------------------------------------------------------------- correlation


@dataclass
class _Curve:
    """Pooled correlation sums of one body pair over absolute lag indices ``first..``."""

    first: int  # absolute lag index (lag = index * step) of element 0
    sab: np.ndarray
    saa: np.ndarray
    sbb: np.ndarray
    count: np.ndarray

    def correlation(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.sab / np.sqrt(self.saa * self.sbb)


def _correlate(a: _GridSignal, b: _GridSignal, nfft: int, work: _TrackWork) -> _Curve:
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
    return _Curve(
        a.k0 - b.k0 - (nb - 1),
        sab[order].astype(float),
        np.maximum(saa[order], 0).astype(float),
        np.maximum(sbb[order], 0).astype(float),
        np.round(count[order]).astype(float),
    )


@dataclass
class _Candidate:
    """One body pair's correlation peak."""

    index_a: int
    index_b: int
    curve: _Curve
    lag_index: int  # absolute lag index of the peak
    peak: float
    sharpness: float
    ambiguity: float
    overlap: float  # seconds

    @property
    def score(self) -> float:
        return self.peak * self.sharpness

    @property
    def significance(self) -> float:
        """Fisher z of the peak times the square root of the overlap (s)."""
        return float(_significance(self.peak, self.overlap))


def _peak(
    curve: _Curve, params: SyncParams, search: tuple[float, float] | None
) -> tuple[int, float, float, float, float] | None:
    """(lag index, peak, sharpness, ambiguity, overlap s) of a curve, None when nothing valid.

    The peak is the lag of greatest significance, Fisher's z of the correlation times the
    square root of the overlap: a high correlation over a few seconds of overlap at the edge
    of the lag range is more often chance than one slightly lower over the whole recording.
    """
    step = params.grid_step
    r = curve.correlation()
    lags = (curve.first + np.arange(len(r))) * step
    overlap = curve.count * step
    valid = (overlap >= params.min_overlap) & np.isfinite(r)
    if search is not None:
        valid &= (lags >= search[0]) & (lags <= search[1])
    if valid.sum() < 5:
        return None
    significance = np.where(valid, _significance(r, overlap), -np.inf)
    best = int(np.argmax(significance))
    peak = float(r[best])
    spread = r[valid]
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


# --------------------------------------------------------------------------- refinement


@dataclass
class _Spline:
    """A track's mean-free signature as a cubic spline, with weights on a grid.

    ``values`` is evaluated at arbitrary (shifted) times; ``weights`` are tabulated every
    ``step`` from ``start`` and looked up by nearest sample, which is plenty for weights and
    much cheaper than interpolating them at every trial lag (see :meth:`weights_from`).
    """

    start: float
    end: float
    step: float
    values: Any
    weights: np.ndarray  # (N, C) on start + k * step

    @classmethod
    def build(cls, signature: PoseSignature, step: float) -> _Spline:
        times, weights = signature.times, signature.weights
        total = weights.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(total > 0, np.nansum(signature.values * weights, axis=0) / total, 0.0)
        centred = np.where(weights > 0, signature.values - mean, 0.0)
        spline = make_interp_spline(times, centred, k=3)
        grid = np.arange(times[0], times[-1], step)
        return cls(float(times[0]), float(times[-1]), step, spline, _resample(times, weights, grid))

    def weights_from(self, t0: float, count: int) -> np.ndarray:
        """Weights at ``t0 + k * step`` for ``k < count`` (nearest sample, clamped at the ends).

        The trial instants share the tabulation's step, so this is a slice, not a gather.
        """
        first = round((t0 - self.start) / self.step)
        if first >= 0 and first + count <= len(self.weights):
            return self.weights[first : first + count]
        index = np.clip(np.arange(first, first + count), 0, len(self.weights) - 1)
        return self.weights[index]

    @cached_property
    def tabulated(self) -> tuple[np.ndarray, np.ndarray]:
        """``(N,)`` the weight grid's times and ``(N, C)`` the values there."""
        times = self.start + np.arange(len(self.weights)) * self.step
        return times, self.values(times)


@dataclass
class _RefinePair:
    """One body pair prepared for the continuous lag search: a tabulated on its own grid."""

    a: _Spline
    b: _Spline
    times: np.ndarray  # (N,) a's grid
    values: np.ndarray  # (N, C) a's signature there
    weights: np.ndarray  # (N, C)

    @classmethod
    def build(cls, a: _Spline, b: _Spline) -> _RefinePair:
        times, values = a.tabulated
        return cls(a, b, times, values, a.weights)

    def sums(self, tau: float, span: tuple[float, float]) -> tuple[float, float, float]:
        """Weighted covariance and variances (summed over channels) with b shifted by ``tau``.

        Means are taken over the common part only, per channel, so tracks covering different
        stretches of a walk do not bias the lag.
        """
        lo = max(self.b.start + tau, span[0])
        hi = min(self.b.end + tau, span[1])
        i0, i1 = np.searchsorted(self.times, [lo, hi])
        if i1 - i0 < 4:
            return 0.0, 0.0, 0.0
        t = self.times[i0:i1]
        w = self.weights[i0:i1] * self.b.weights_from(float(t[0]) - tau, i1 - i0)
        va, vb = self.values[i0:i1], self.b.values(t - tau)
        # sum w (a - mean_a)(b - mean_b) = sum w a b - (sum w a)(sum w b) / sum w, per channel
        total = np.maximum(w.sum(axis=0), 1e-12)
        wa, wb = w * va, w * vb
        sum_a, sum_b = wa.sum(axis=0), wb.sum(axis=0)
        sab = np.einsum("nc,nc->c", wa, vb) - sum_a * sum_b / total
        saa = np.einsum("nc,nc->c", wa, va) - sum_a * sum_a / total
        sbb = np.einsum("nc,nc->c", wb, vb) - sum_b * sum_b / total
        return float(sab.sum()), float(saa.sum()), float(sbb.sum())

    def overlap(self, tau: float, span: tuple[float, float]) -> float:
        """Seconds of common data with b shifted by ``tau`` inside ``span``."""
        lo = max(self.a.start, self.b.start + tau, span[0])
        hi = min(self.a.end, self.b.end + tau, span[1])
        return max(0.0, hi - lo)


def _pooled_correlation(tau: float, pairs: list[_RefinePair], span: tuple[float, float]) -> float:
    """Correlation of all body pairs' signatures with b shifted by ``tau``.

    Both signatures are cubic-spline interpolants evaluated on one grid of a's clock (b at
    ``t - tau``); ``span`` limits the grid for windowed estimates.
    """
    sums = np.array([pair.sums(tau, span) for pair in pairs]).sum(axis=0)
    if sums[1] <= 0 or sums[2] <= 0:
        return 0.0
    return float(sums[0] / math.sqrt(sums[1] * sums[2]))


def _refine(
    tau0: float,
    half_width: float,
    pairs: list[_RefinePair],
    span: tuple[float, float] = (-math.inf, math.inf),
) -> tuple[float, float]:
    """The lag in ``tau0 ± half_width`` maximising the pooled correlation, and that value."""
    result = minimize_scalar(
        lambda tau: -_pooled_correlation(tau, pairs, span),
        bounds=(tau0 - half_width, tau0 + half_width),
        method="bounded",
        options={"xatol": 2e-5},
    )
    return float(result.x), float(-result.fun)


# --------------------------------------------------------------------------- shared work


class _TrackWork:
    """Per-track results that every camera pair of the track's camera reuses.

    With N cameras each camera is in N - 1 pairs; its tracks' signatures, grid signals,
    spectra and splines are computed once. Keys are object ids of inputs the cache keeps
    alive (tracks are kept with their signature), so an id is never reused for another
    object while the cache exists.
    """

    def __init__(self, params: SyncParams, nfft: int = 0) -> None:
        self.params = params
        self.nfft = nfft
        self._signature: dict[int, tuple[BodyTrack, PoseSignature]] = {}
        self._motion: dict[int, float] = {}
        self._grid: dict[int, _GridSignal | None] = {}
        self._spectra: dict[tuple[int, int], tuple[np.ndarray, ...]] = {}
        self._spline: dict[int, _Spline] = {}

    def signatures(self, tracks: list[BodyTrack]) -> list[PoseSignature]:
        out = []
        for track in tracks:
            if id(track) not in self._signature:
                joints = select_joints(track.layout, self.params.joints)
                signature = pose_signature(
                    track, joints, mirror_invariant=self.params.mirror_invariant
                )
                self._signature[id(track)] = (track, signature)
            out.append(self._signature[id(track)][1])
        return out

    def motion(self, signature: PoseSignature) -> float:
        if id(signature) not in self._motion:
            self._motion[id(signature)] = signature.motion()
        return self._motion[id(signature)]

    def grid(self, signature: PoseSignature) -> _GridSignal | None:
        if id(signature) not in self._grid:
            self._grid[id(signature)] = _grid_signal(signature, self.params.grid_step)
        return self._grid[id(signature)]

    def spectra(self, signal: _GridSignal, nfft: int) -> tuple[np.ndarray, ...]:
        key = (id(signal), nfft)
        if key not in self._spectra:
            # single precision is plenty to find the coarse peak, and twice as fast
            self._spectra[key] = (
                rfft(signal.values, n=nfft, axis=0),
                rfft(signal.present.astype(np.float32), n=nfft),
                rfft(signal.energy.astype(np.float32), n=nfft),
            )
        return self._spectra[key]

    def spline(self, signature: PoseSignature) -> _Spline:
        if id(signature) not in self._spline:
            self._spline[id(signature)] = _Spline.build(signature, self.params.refine_step)
        return self._spline[id(signature)]


# --------------------------------------------------------------------------- pair estimate


def _refused(a: str, b: str, reason: str, **quality: Any) -> PairOffset:
    return PairOffset(a, b, status="refused", reason=reason, quality=quality)


def estimate_pair_offset(
    tracks_a: list[BodyTrack],
    tracks_b: list[BodyTrack],
    params: SyncParams,
    *,
    camera_a: str = "a",
    camera_b: str = "b",
    prior: float | None = None,
    around: float | None = None,
    work: _TrackWork | None = None,
) -> PairOffset:
    """The clock lag ``tau = t_a - t_b`` between two cameras from their body tracks.

    Every lag within ``± max_offset`` (all when 0) is searched. ``prior`` is the lag the
    message arrival times suggest (s): the lag within ``prior_window`` of it is taken unless
    the motion contradicts it (a far more significant lag elsewhere, or none clear near it).
    ``around`` pins the search to the lobe of one candidate lag (after the poses chose it).
    ``work`` shares per-track results between the pairs of one :func:`synchronise` call.
    """
    work = work if work is not None else _TrackWork(params)
    names = {"camera_a": camera_a, "camera_b": camera_b}
    if around is not None:
        return _estimate(tracks_a, tracks_b, params, _lobe(around, params), work=work, **names)
    anywhere = (-params.max_offset, params.max_offset) if params.max_offset > 0 else None
    free = _estimate(tracks_a, tracks_b, params, anywhere, work=work, **names)
    if prior is None:
        return free
    window = (prior - params.prior_window, prior + params.prior_window)
    near = _estimate(tracks_a, tracks_b, params, window, work=work, windowed=True, **names)
    if near.ok and not _contradicts(free, near, params):
        near.quality["arrival_prior"] = "used"
        return near
    free.quality["arrival_prior"] = "contradicted"
    if near.ok:
        # the poses (the calibrator's settle step) must confirm the motion over the prior
        free.quality["prior_lag"] = near.offset
        far = np.abs(free.candidates[:, 0] - near.offset) > params.consensus_tolerance
        if far.all():
            peak = near.quality.get("peak", 0.0)
            free.candidates = np.vstack([free.candidates, [[near.offset, peak]]])
    return free


def _lobe(lag: float, params: SyncParams) -> tuple[float, float]:
    """The search range (s) of the correlation lobe around one candidate lag."""
    reach = max(3 * params.grid_step, 2 * params.consensus_tolerance)
    return lag - reach, lag + reach


def _contradicts(free: PairOffset, near: PairOffset, params: SyncParams) -> bool:
    """Whether the best lag anywhere is far from, and far more significant than, the prior's."""
    if not free.ok or abs(free.offset - near.offset) <= params.prior_window:
        return False

    def strength(pair: PairOffset) -> float:
        return float(_significance(pair.quality["peak"], pair.quality["overlap_s"]))

    return strength(free) > params.prior_contradiction * strength(near)


def _estimate(
    tracks_a: list[BodyTrack],
    tracks_b: list[BodyTrack],
    params: SyncParams,
    search: tuple[float, float] | None,
    *,
    camera_a: str,
    camera_b: str,
    work: _TrackWork,
    windowed: bool = False,
) -> PairOffset:
    """The lag within ``search`` (s; None: every lag), with its candidates.

    ``windowed``: ``search`` is the arrival-time prior's window, where a body pair's peak is
    usable on its significance alone (``min_prior_significance``).
    """
    sig_a, sig_b = work.signatures(tracks_a), work.signatures(tracks_b)
    refusal = _refuse_unusable(
        camera_a, camera_b, sig_a=sig_a, sig_b=sig_b, params=params, work=work
    )
    if refusal is not None:
        return refusal
    candidates = _body_pair_candidates(sig_a, sig_b, params, search, work)
    if not candidates:
        return _refused(
            camera_a,
            camera_b,
            f"no body is seen by both cameras for {params.min_overlap:.1f} s at any lag"
            + (f" in {search[0]:+.2f}..{search[1]:+.2f} s" if search else ""),
        )
    good = [c for c in candidates if _clear(c, params, windowed=windowed)]
    best_any = max(candidates, key=lambda c: c.score)
    if not good:
        return _refused(
            camera_a,
            camera_b,
            f"no body pair correlates clearly (best peak {best_any.peak:.2f}, sharpness "
            f"{best_any.sharpness:.1f}; need {params.min_peak} and {params.min_sharpness}, "
            f"or a peak of {params.min_repeated_peak})",
            peak=best_any.peak,
            sharpness=best_any.sharpness,
            pairs_considered=len(candidates),
        )
    used = _consensus(good, params)
    lags = _candidate_lags(used, params, search)
    chosen = round(lags[0, 0] / params.grid_step)
    tolerance = max(1, round(params.consensus_tolerance / params.grid_step))
    if abs(chosen - used[0].lag_index) > tolerance:
        # the prior chose another of the lags the motion supports: redo the consensus there
        near = [c for c in good if abs(c.lag_index - chosen) <= tolerance]
        used = _consensus(near, params) if near else []
        if not used:
            pinned = _estimate(
                tracks_a, tracks_b, params, _lobe(float(lags[0, 0]), params),
                camera_a=camera_a, camera_b=camera_b, work=work,
            )  # fmt: skip
            pinned.candidates = lags
            pinned.quality.update(_lag_quality(lags))
            return pinned
    result = _finish(
        camera_a,
        camera_b,
        used=used,
        candidates=candidates,
        sig_a=sig_a,
        sig_b=sig_b,
        params=params,
        work=work,
        centre=chosen,
    )
    result.candidates = lags
    result.quality.update(_lag_quality(lags))
    return result


def _refuse_unusable(
    camera_a: str,
    camera_b: str,
    *,
    sig_a: list[PoseSignature],
    sig_b: list[PoseSignature],
    params: SyncParams,
    work: _TrackWork,
) -> PairOffset | None:
    """A refusal when a camera saw no moving body for long enough, else None."""
    if not sig_a or not sig_b:
        return _refused(camera_a, camera_b, "a camera saw no body track")
    moving_a = [s for s in sig_a if work.motion(s) >= params.min_motion]
    moving_b = [s for s in sig_b if work.motion(s) >= params.min_motion]
    if not moving_a or not moving_b:
        still = camera_a if not moving_a else camera_b
        return _refused(
            camera_a,
            camera_b,
            f"the bodies {still} sees hardly move (less than {params.min_motion * 100:.0f} cm "
            "of joint-distance change), so their motion cannot time the cameras",
        )
    span_a = max(s.times[-1] - s.times[0] for s in moving_a)
    span_b = max(s.times[-1] - s.times[0] for s in moving_b)
    if min(span_a, span_b) < params.min_overlap:
        return _refused(
            camera_a,
            camera_b,
            f"too short: the longest moving track lasts {min(span_a, span_b):.1f} s, "
            f"{params.min_overlap:.1f} s are needed",
        )
    return None


def _body_pair_candidates(
    sig_a: list[PoseSignature],
    sig_b: list[PoseSignature],
    params: SyncParams,
    search: tuple[float, float] | None,
    work: _TrackWork,
) -> list[_Candidate]:
    """Every moving body pair's correlation curve and peak within ``search``."""
    grid_a = {i: work.grid(s) for i, s in enumerate(sig_a) if work.motion(s) >= params.min_motion}
    grid_b = {j: work.grid(s) for j, s in enumerate(sig_b) if work.motion(s) >= params.min_motion}
    grid_a = {i: g for i, g in grid_a.items() if g is not None}
    grid_b = {j: g for j, g in grid_b.items() if g is not None}
    if not grid_a or not grid_b:
        return []
    length = max(len(g.present) for g in grid_a.values()) + max(
        len(g.present) for g in grid_b.values()
    )
    nfft = work.nfft if work.nfft >= length else next_fast_len(length)
    candidates: list[_Candidate] = []
    for i, ga in grid_a.items():
        for j, gb in grid_b.items():
            curve = _correlate(ga, gb, nfft, work)
            found = _peak(curve, params, search)
            if found is not None:
                candidates.append(_Candidate(i, j, curve, *found))
    return candidates


def _clear(candidate: _Candidate, params: SyncParams, *, windowed: bool = False) -> bool:
    """A body pair whose peak stands out of its curve, or is high though the motion repeats.

    Within the arrival-time prior's window the curve is too short for a robust z-score: a
    peak significant over its overlap is usable there.
    """
    if candidate.peak < params.min_peak:
        return False
    if windowed and candidate.significance >= params.min_prior_significance:
        return True
    return candidate.sharpness >= params.min_sharpness or candidate.peak >= params.min_repeated_peak


def _candidate_lags(
    used: list[_Candidate], params: SyncParams, search: tuple[float, float] | None
) -> np.ndarray:
    """``(K, 2)`` candidate lags (s) and their pooled correlations, best first.

    The candidates are the pooled curve's local maxima of significance at least
    ``candidate_ratio`` of the best's correlation, plus always the runner-up (so the poses can
    show how much worse the next lag fits).
    """
    step = params.grid_step
    first, pooled, overlap = _pooled_curve(used, step)
    lags = (first + np.arange(len(pooled))) * step
    valid = (overlap >= params.min_overlap) & np.isfinite(pooled)
    if search is not None:
        valid &= (lags >= search[0] - 1e-9) & (lags <= search[1] + 1e-9)
    significance = np.where(valid, _significance(pooled, overlap), -np.inf)
    peaks = _local_maxima(significance, max(3, round(0.25 / step)))
    # a lag whose overlap is much shorter than the best one's rests on too little data to
    # rival it (the poses would judge it on a transform fitted to a few seconds)
    peaks = [k for k in peaks if overlap[k] >= 0.5 * overlap[peaks[0]]]
    rows = np.array([(lags[k], pooled[k]) for k in peaks]).reshape(-1, 2)
    keep = rows[:, 1] >= params.candidate_ratio * rows[0, 1]
    keep[: min(2, len(rows))] = True
    return rows[keep][: max(2, params.max_candidates)]


def _local_maxima(values: np.ndarray, separation: int) -> list[int]:
    """Indices of finite values that are the largest within ``separation`` samples, best first."""
    finite = np.where(np.isfinite(values), values, -np.inf)
    neighbourhood = maximum_filter1d(finite, 2 * separation + 1, mode="constant", cval=-np.inf)
    peaks = np.flatnonzero(np.isfinite(finite) & (finite >= neighbourhood))
    return [int(k) for k in peaks[np.argsort(finite[peaks])[::-1]]]


def _lag_quality(lags: np.ndarray) -> dict[str, Any]:
    """The candidates' figures for the pair's quality: the runner-up and its margin."""
    quality: dict[str, Any] = {"candidates": len(lags), "arrival_prior": "none"}
    if len(lags) > 1:
        quality["runner_up_lag"] = round(float(lags[1, 0]), 3)
        quality["runner_up_ratio"] = round(float(lags[1, 1] / lags[0, 1]), 3)
    return quality


def _consensus(good: list[_Candidate], params: SyncParams) -> list[_Candidate]:
    """The body pairs agreeing with the lag the sharpest pairs vote for."""
    tolerance = max(1, round(params.consensus_tolerance / params.grid_step))
    ranked = sorted(good, key=lambda c: c.score, reverse=True)
    voters = ranked[: max(1, math.ceil(params.best_fraction * len(ranked)))]
    lags = np.array([c.lag_index for c in voters])
    weights = np.array([c.score * c.overlap for c in voters])
    support = [(weights * (np.abs(lags - lag) <= tolerance)).sum() for lag in lags]
    winner = int(lags[int(np.argmax(support))])
    # one body of camera a pairs with at most one body of camera b at a time: keep the best
    used: list[_Candidate] = []
    for candidate in ranked:
        if abs(candidate.lag_index - winner) > tolerance:
            continue
        used.append(candidate)
    return used


def _pooled_curve(used: list[_Candidate], step: float) -> tuple[int, np.ndarray, np.ndarray]:
    """(first lag index, correlation, overlap s) of the body pairs' summed correlation sums.

    The overlap at a lag is the longest single body pair's there (body pairs of one camera
    pair overlap each other in time, so their sum would overstate it).
    """
    first = min(c.curve.first for c in used)
    last = max(c.curve.first + len(c.curve.sab) for c in used)
    sums = np.zeros((3, last - first))
    overlap = np.zeros(last - first)
    for c in used:
        start = c.curve.first - first
        stop = start + len(c.curve.sab)
        sums[:, start:stop] += np.stack([c.curve.sab, c.curve.saa, c.curve.sbb])
        overlap[start:stop] = np.maximum(overlap[start:stop], c.curve.count * step)
    with np.errstate(invalid="ignore", divide="ignore"):
        return first, sums[0] / np.sqrt(sums[1] * sums[2]), overlap


def _parabolic(r: np.ndarray, index: int) -> float:
    """Sub-sample peak position by a parabola through three samples."""
    if index <= 0 or index >= len(r) - 1 or not np.isfinite(r[index - 1 : index + 2]).all():
        return float(index)
    left, mid, right = r[index - 1], r[index], r[index + 1]
    denom = left - 2 * mid + right
    if denom >= 0:
        return float(index)
    return index + 0.5 * (left - right) / denom


def _finish(
    camera_a: str,
    camera_b: str,
    *,
    used: list[_Candidate],
    candidates: list[_Candidate],
    sig_a: list[PoseSignature],
    sig_b: list[PoseSignature],
    params: SyncParams,
    work: _TrackWork,
    centre: int,
) -> PairOffset:
    """The refined lag of the lobe at absolute lag index ``centre``, with its windows."""
    step = params.grid_step
    first, pooled, _ = _pooled_curve(used, step)
    centre -= first
    half = max(3, round(0.1 / step))
    lo, hi = max(0, centre - half), min(len(pooled), centre + half + 1)
    local = int(np.nanargmax(pooled[lo:hi])) + lo
    tau_parabola = (first + _parabolic(pooled, local)) * step
    pairs = [
        _RefinePair.build(work.spline(sig_a[c.index_a]), work.spline(sig_b[c.index_b]))
        for c in used
    ]
    # the whole-overlap search picks the correlation peak's lobe; the windows then search
    # around it (on real recordings the correlation can have side lobes a window alone
    # might settle on)
    tau, corr = _refine(tau_parabola, 2 * step, pairs)
    windows = _windows(tau, pairs, params)
    quality = {
        "peak": round(float(np.nanmax(pooled[lo:hi])), 4),
        "refined_correlation": round(corr, 4),
        "sharpness": round(max(c.sharpness for c in used), 2),
        "ambiguity": round(min(c.ambiguity for c in used), 3),
        "pairs_used": len(used),
        "pairs_considered": len(candidates),
        "overlap_s": round(sum(c.overlap for c in used), 1),
        "windows": len(windows),
    }
    keep = slice(max(0, centre - round(2.0 / step)), centre + round(2.0 / step) + 1)
    return PairOffset(
        camera_a,
        camera_b,
        status="ok",
        offset=tau,
        windows=windows,
        quality=quality,
        lags=(first + np.arange(len(pooled)))[keep] * step,
        correlation=pooled[keep],
        body_pairs=[(c.index_a, c.index_b) for c in used],
    )


def _windows(tau: float, pairs: list[_RefinePair], params: SyncParams) -> np.ndarray:
    """Lag measured in sliding windows of a's clock: rows (t_b centre, tau, weight, corr)."""
    start = min(max(p.a.start, p.b.start + tau) for p in pairs)
    end = max(min(p.a.end, p.b.end + tau) for p in pairs)
    span = end - start
    count = max(1, round(span / params.window))
    bounds = np.linspace(start, end, count + 1)
    edges = list(itertools.pairwise(bounds))
    half_width = 2 * params.grid_step + params.max_drift * span
    rows = []
    for lo, hi in edges:
        overlap = sum(p.overlap(tau, (lo, hi)) for p in pairs)
        if overlap < min(params.min_overlap, 0.5 * (hi - lo)):
            continue
        value, corr = _refine(tau, half_width, pairs, (lo, hi))
        if corr < params.min_peak:
            continue
        rows.append((0.5 * (lo + hi) - value, value, overlap * corr**2, corr))
    return np.array(rows).reshape(-1, 4)


CONTEST_WINDOW = 5.0
"""Seconds per window when a pair's candidate lags are compared window by window."""

CONTEST_MIN_WINDOWS = 6
"""Fewest windows both lags must share for their comparison to count."""

CONTEST_DECISIVE_T = 4.0
"""Paired t-statistic at which the best lag's lead over another is taken as decisive."""

WINDOW_REACH = 0.03
"""How far (s) a window's lag may lie from the lag found over the whole overlap."""


def contest_candidates(
    pair: PairOffset,
    tracks_a: list[BodyTrack],
    tracks_b: list[BodyTrack],
    params: SyncParams,
    work: _TrackWork | None = None,
) -> None:
    """Compare the pair's best candidate lag with each other one, window by window.

    One repetition away, a repeated motion can correlate over the whole recording nearly as
    well as at the true lag; window by window it cannot: at the true lag the two cameras see
    the same motion in every window, while repetitions differ in speed and form, so the other
    lag matches some windows well and others badly. Per window of ``CONTEST_WINDOW`` s
    (camera a's clock) each lag's refined correlation is taken as a Fisher z; the best lag's
    lead over another is the paired t-statistic of those differences over the windows both
    cover. Where the whole-recording correlations are alike (the runner-up's within
    ``max_ambiguity`` of the best's), sets the pair's quality ``motion_window_t``, the
    smallest lead over the other candidates (0 when a candidate shares fewer than
    ``CONTEST_MIN_WINDOWS`` windows with the best), which
    :func:`~hiros_calib.lags.settle_lag` reads as the motion deciding. Motion that repeats
    exactly leaves every lead near 0, and nothing is decided.
    """
    if not pair.ok or len(pair.candidates) < 2 or not pair.body_pairs:
        return
    if pair.candidates[1, 1] < params.max_ambiguity * pair.candidates[0, 1]:
        return  # the whole recording decides already
    work = work if work is not None else _TrackWork(params)
    sig_a, sig_b = work.signatures(tracks_a), work.signatures(tracks_b)
    pairs = [
        _RefinePair.build(work.spline(sig_a[i]), work.spline(sig_b[j])) for i, j in pair.body_pairs
    ]
    start = min(p.a.start for p in pairs)
    end = max(p.a.end for p in pairs)
    count = max(1, round((end - start) / CONTEST_WINDOW))
    bounds = list(itertools.pairwise(np.linspace(start, end, count + 1)))
    lags = [
        pair.offset if abs(lag - pair.offset) < 0.1 else _refine(float(lag), 0.1, pairs)[0]
        for lag in pair.candidates[:, 0]
    ]  # the pair's own lag is refined already
    scores = [_window_scores(lag, pairs, bounds) for lag in lags]
    leads = [_paired_t(scores[0] - other) for other in scores[1:]]
    pair.quality["motion_window_t"] = round(min(leads), 2)


def _window_scores(
    tau: float, pairs: list[_RefinePair], bounds: list[tuple[float, float]]
) -> np.ndarray:
    """Per window the Fisher z of the refined correlation near ``tau`` (NaN: too little data)."""
    scores = np.full(len(bounds), np.nan)
    for k, (lo, hi) in enumerate(bounds):
        if sum(p.overlap(tau, (lo, hi)) for p in pairs) >= 0.5 * (hi - lo):
            correlation = _refine(tau, WINDOW_REACH, pairs, (lo, hi))[1]
            scores[k] = np.arctanh(np.clip(correlation, -0.99, 0.99))
    return scores


def _paired_t(differences: np.ndarray) -> float:
    """The one-sample t-statistic of the finite differences (0 with too few of them)."""
    shared = differences[np.isfinite(differences)]
    if len(shared) < CONTEST_MIN_WINDOWS:
        return 0.0
    spread = float(np.std(shared, ddof=1))
    mean = float(np.mean(shared))
    if spread == 0.0:
        return math.copysign(math.inf, mean) if mean else 0.0
    return mean / (spread / math.sqrt(len(shared)))


# --------------------------------------------------------------------------- N cameras


def solve_clocks(
    cameras: list[str],
    reference: str,
    pairs: list[PairOffset],
    epochs: dict[str, float],
    params: SyncParams,
) -> dict[str, CameraClock]:
    """Globally consistent clocks from all pairwise lags (robust weighted least squares).

    Each window measurement of pair (a, b) at b-time ``t_b`` with lag ``tau`` says
    ``tau + o_a + d_a (t_b + tau - e_a) - o_b - d_b (t_b - e_b) = 0`` (offsets ``o``, drifts
    ``d``, epochs ``e``); the reference has ``o = d = 0``. Cameras not linked to the
    reference through usable pairs are refused with the pairs' reasons.
    """
    clocks = {c: CameraClock(c, drift_epoch=epochs.get(c, 0.0)) for c in cameras}
    clocks[reference] = CameraClock(
        reference, "ok", time_offset=0.0, drift_epoch=epochs.get(reference, 0.0)
    )
    usable = [p for p in pairs if p.ok and len(p.windows)]
    linked = _linked(reference, usable)
    for camera in cameras:
        if camera not in linked:
            reasons = [
                f"{p.camera_a}-{p.camera_b}: {p.reason or 'no window measurement'}"
                for p in pairs
                if camera in (p.camera_a, p.camera_b)
            ]
            clocks[camera].reason = f"cannot link {camera} to the reference {reference}: " + (
                "; ".join(reasons) if reasons else "no camera pair includes it"
            )
    unknown = [c for c in cameras if c in linked and c != reference]
    if not unknown:
        return clocks
    usable = [p for p in usable if p.camera_a in linked and p.camera_b in linked]
    spans = _drift_spans(usable)
    with_drift = [
        c for c in unknown if params.estimate_drift and spans.get(c, 0.0) >= params.min_drift_span
    ]
    column = {("o", c): k for k, c in enumerate(unknown)}
    column.update({("d", c): len(unknown) + k for k, c in enumerate(with_drift)})
    rows, rhs, weights = [], [], []
    for pair in usable:
        for t_b, tau, weight, _ in pair.windows:
            row = np.zeros(len(column))
            for camera, sign, at in ((pair.camera_a, 1.0, t_b + tau), (pair.camera_b, -1.0, t_b)):
                if ("o", camera) in column:
                    row[column["o", camera]] = sign
                if ("d", camera) in column:
                    row[column["d", camera]] = sign * (at - clocks[camera].drift_epoch)
            rows.append(row)
            rhs.append(-tau)
            weights.append(weight)
    for camera in with_drift:
        row = np.zeros(len(column))
        row[column["d", camera]] = 1.0
        rows.append(row)
        rhs.append(0.0)
        weights.append(0.0)
    prior = np.zeros(len(rows), dtype=bool)
    prior[len(rows) - len(with_drift) :] = True
    design, target, weight = np.array(rows), np.array(rhs), np.array(weights)
    solution, residual = _robust_lstsq(
        design, target, weight, prior, prior_sigma=params.drift_prior
    )
    for camera in unknown:
        clock = clocks[camera]
        clock.status = "ok"
        clock.time_offset = float(solution[column["o", camera]])
        if ("d", camera) in column:
            clock.drift = float(solution[column["d", camera]])
        mine = np.array(
            [camera in (p.camera_a, p.camera_b) for p in usable for _ in range(len(p.windows))]
        )
        clock.quality = {
            "window_residual_ms": round(1e3 * float(np.sqrt(np.mean(residual[mine] ** 2))), 3),
            "windows": int(mine.sum()),
            "drift_estimated": ("d", camera) in column,
        }
    return clocks


def _linked(reference: str, pairs: list[PairOffset]) -> set[str]:
    linked, frontier = {reference}, [reference]
    while frontier:
        camera = frontier.pop()
        for p in pairs:
            for here, there in ((p.camera_a, p.camera_b), (p.camera_b, p.camera_a)):
                if here == camera and there not in linked:
                    linked.add(there)
                    frontier.append(there)
    return linked


def _drift_spans(pairs: list[PairOffset]) -> dict[str, float]:
    """Per camera, the time span its window measurements cover (drift is only defined then)."""
    times: dict[str, list[float]] = {}
    for p in pairs:
        if len(p.windows) < 3:
            continue
        for camera in (p.camera_a, p.camera_b):
            times.setdefault(camera, []).extend(p.windows[:, 0].tolist())
    return {c: max(t) - min(t) for c, t in times.items()}


def _robust_lstsq(
    design: np.ndarray,
    target: np.ndarray,
    weight: np.ndarray,
    prior: np.ndarray,
    *,
    prior_sigma: float,
    iterations: int = 6,
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least squares, Huber-reweighted, with ridge rows for the drift prior.

    Measurement weights are relative, so their scale (the variance per unit weight) is
    estimated from the residuals at each pass; a prior row ``d = 0`` then gets the weight
    that makes its standard deviation ``prior_sigma``. Returns the solution and the
    measurement rows' residuals.
    """
    robust = np.ones_like(weight)
    measured = ~prior
    variance = 1e-6  # (1 ms)^2 per unit weight until the residuals say otherwise
    solution = np.zeros(design.shape[1])
    for _ in range(iterations):
        w = weight * robust
        w[prior] = variance / prior_sigma**2
        root = np.sqrt(w)[:, None]
        solution = np.linalg.lstsq(design * root, target * root[:, 0], rcond=None)[0]
        residual = (design @ solution - target)[measured]
        scaled = residual * np.sqrt(weight[measured])
        sigma = max(1.4826 * float(np.median(np.abs(scaled))), 1e-9)
        ratio = np.abs(scaled) / (1.5 * sigma)
        robust[measured] = np.where(ratio <= 1, 1.0, 1.0 / np.maximum(ratio, 1e-12))
        dof = max(1, int(measured.sum()) - design.shape[1])
        variance = max(float((robust[measured] * scaled**2).sum()) / dof, 1e-12)
    return solution, (design @ solution - target)[measured]


def synchronise(
    tracks: dict[str, list[BodyTrack]],
    reference: str,
    params: SyncParams,
    arrival_offsets: dict[str, float] | None = None,
    settle: Settle | None = None,
) -> tuple[dict[str, CameraClock], list[PairOffset]]:
    """Clocks of every camera from their body tracks: all pairs, then the global solve.

    ``arrival_offsets`` gives per camera the typical ``arrival time - stamp`` (s) of its
    messages at one receiver; an event stamped ``t_a`` and ``t_b`` arrives at about the same
    time, so ``tau = t_a - t_b`` is about ``arrival_b - arrival_a`` (the search prior).
    ``settle(pair, repin)`` may check each pair's lag before the solve (the calibrator has the
    poses decide between candidate lags); ``repin(lag)`` re-estimates the pair at that lag.
    """
    cameras = list(tracks)
    arrival = arrival_offsets or {}
    step = params.grid_step
    longest = max(
        (math.floor(t.end / step) - math.ceil(t.start / step) + 1 for ts in tracks.values()
         for t in ts),
        default=0,
    )  # fmt: skip
    # one FFT length for every pair, so each track's spectra serve all its camera's pairs
    work = _TrackWork(params, next_fast_len(2 * longest))
    pairs, repins = [], []
    for k, a in enumerate(cameras):
        for b in cameras[k + 1 :]:
            prior = arrival[b] - arrival[a] if a in arrival and b in arrival else None
            pair = estimate_pair_offset(
                tracks[a], tracks[b], params, camera_a=a, camera_b=b, prior=prior, work=work
            )
            repin = functools.partial(_repin, tracks[a], tracks[b], pair, work)
            contest_candidates(pair, tracks[a], tracks[b], params, work)
            if settle is not None:
                pair = settle(pair, repin)
            pairs.append(_unless_uncorrelated(pair, params))
            repins.append(repin)
    pairs = close_loops(pairs, repins, params)
    pairs = overrule_weak_pairs(pairs, params)
    return solve_clocks(cameras, reference, pairs, clock_epochs(tracks), params), pairs


def close_loops(
    pairs: list[PairOffset], repins: list[Callable[[float], PairOffset]], params: SyncParams
) -> list[PairOffset]:
    """Pairs refused as ambiguous, decided where the other pairs imply one of their lags.

    With three or more cameras, a pair whose motion repeats may still be timed through the
    others: the lags of a-c and c-b add up to the lag of a-b. A refused pair that listed
    candidate lags takes the one within ``consensus_tolerance`` of that sum (re-estimated
    there by ``repins[k]``), until no more can be decided. Two such pairs of a camera
    triangle whose third pair is timed are decided together when exactly one combination of
    their candidates closes the triangle (:func:`_decide_two_by_triangle`).
    """
    pairs = list(pairs)
    progress = True
    while progress:
        progress = _decide_two_by_triangle(pairs, repins, params)
        for k, pair in enumerate(pairs):
            if pair.ok or len(pair.candidates) == 0:
                continue
            implied = _implied_lag(pair.camera_a, pair.camera_b, [p for p in pairs if p.ok])
            if implied is None:
                continue
            distance = np.abs(pair.candidates[:, 0] - implied)
            best = int(np.argmin(distance))
            if distance[best] > params.consensus_tolerance:
                continue
            decided = repins[k](float(pair.candidates[best, 0]))
            if not decided.ok:
                continue
            decided.candidates = pair.candidates
            decided.quality.update(lag_decided_by="loop", loop_implied_lag=round(implied, 4))
            pairs[k] = decided
            progress = True
    return pairs


def _unless_uncorrelated(pair: PairOffset, params: SyncParams) -> PairOffset:
    """The pair, or its refusal when the motion does not correlate at the lag it ended on.

    A lag kept for the arrival times, or chosen by the poses, may sit where the refined
    correlation is below ``min_peak``, the least a usable body pair's peak needs: nothing in
    the motion supports it then. The refusal keeps the candidates, so a loop may decide.
    """
    correlation = pair.quality.get("refined_correlation", 0.0)
    if not pair.ok or correlation >= params.min_peak:
        return pair
    refused = _refused(
        pair.camera_a,
        pair.camera_b,
        f"the motion does not correlate at its lag {pair.offset:+.3f} s (correlation "
        f"{correlation:.2f} over {pair.quality.get('overlap_s', 0.0):.0f} s; a usable lag "
        f"needs {params.min_peak})",
    )
    refused.candidates = pair.candidates
    return refused


def _decide_two_by_triangle(
    pairs: list[PairOffset], repins: list[Callable[[float], PairOffset]], params: SyncParams
) -> bool:
    """Two ambiguous pairs decided by the timed third side of their triangle (in place).

    Each lists candidate lags; a combination closes the triangle when its lags add up to the
    third pair's within ``consensus_tolerance``. Only a single closing combination decides:
    motion repeated with one period in both pairs closes it as well one repetition up in
    one and down in the other, and then nothing is decided. True when a pair was decided.
    """
    ambiguous = [k for k, p in enumerate(pairs) if not p.ok and len(p.candidates)]
    timed = [p for p in pairs if p.ok]
    for k, m in itertools.combinations(ambiguous, 2):
        first, second = pairs[k], pairs[m]
        cameras = {first.camera_a, first.camera_b, second.camera_a, second.camera_b}
        third = next((r for r in timed if {r.camera_a, r.camera_b} <= cameras), None)
        if len(cameras) != 3 or third is None:
            continue
        closing = [
            (lag_1, lag_2)
            for lag_1 in first.candidates[:, 0]
            for lag_2 in second.candidates[:, 0]
            if abs(
                _implied_lag(
                    third.camera_a,
                    third.camera_b,
                    [replace(first, offset=lag_1), replace(second, offset=lag_2)],
                )
                - third.offset
            )
            <= params.consensus_tolerance
        ]
        if len(closing) != 1:
            continue
        decided = [repins[k](float(closing[0][0])), repins[m](float(closing[0][1]))]
        if not all(d.ok for d in decided):
            continue
        for index, old, new in ((k, first, decided[0]), (m, second, decided[1])):
            new.candidates = old.candidates
            new.quality.update(
                lag_decided_by="loop", loop_closed_by=f"{third.camera_a}-{third.camera_b}"
            )
            pairs[index] = new
        return True
    return False


def overrule_weak_pairs(pairs: list[PairOffset], params: SyncParams) -> list[PairOffset]:
    """Pairs left out whose chance-level lag the other pairs' loop contradicts.

    With three or more cameras the lags around a loop add up to zero. A pair whose lag is
    more than ``consensus_tolerance`` from the lag the other pairs imply, and whose refined
    correlation is no more significant than chance gives (``loop_overrule_strength``) while
    every other pair's is, measured noise rather than its lag: it is left out, with the
    reason. Any other conflict is left as it is, for the loop check to flag: re-timing the
    weaker pair where the others imply would close a loop around two pairs that are both
    one repetition off, and hide them.
    """
    pairs = list(pairs)
    for k in sorted(
        (k for k, p in enumerate(pairs) if p.ok), key=lambda k: _pair_strength(pairs[k])
    ):
        pair = pairs[k]
        others = [p for p in pairs if p.ok and p is not pair]
        implied = _implied_lag(pair.camera_a, pair.camera_b, others)
        if implied is None or abs(pair.offset - implied) <= params.consensus_tolerance:
            continue
        weakest_other = min(_pair_strength(p) for p in others)
        if not _pair_strength(pair) < params.loop_overrule_strength <= weakest_other:
            continue
        pairs[k] = _refused(
            pair.camera_a,
            pair.camera_b,
            f"its lag {pair.offset:+.3f} s rests on a correlation of "
            f"{pair.quality.get('refined_correlation', 0.0):.2f} over "
            f"{pair.quality.get('overlap_s', 0.0):.0f} s, no more than chance gives, and the "
            f"other pairs' loop implies {implied:+.3f} s",
            loop_implied_lag=round(implied, 4),
            loop_overruled_lag=round(pair.offset, 4),
        )
    return pairs


def _pair_strength(pair: PairOffset) -> float:
    """How much a pair's lag rests on: its refined correlation's significance."""
    return float(
        _significance(
            pair.quality.get("refined_correlation", 0.0), pair.quality.get("overlap_s", 0.0)
        )
    )


def _implied_lag(camera_a: str, camera_b: str, pairs: list[PairOffset]) -> float | None:
    """``t_a - t_b`` through a chain of other pairs' lags (None when none links a to b)."""
    offsets = {camera_a: 0.0}  # o_x - o_a, where a pair's lag is tau = o_y - o_x
    frontier = [camera_a]
    while frontier:
        here = frontier.pop()
        for p in pairs:
            for x, y, sign in ((p.camera_a, p.camera_b, 1.0), (p.camera_b, p.camera_a, -1.0)):
                if x == here and y not in offsets:
                    offsets[y] = offsets[here] + sign * p.offset
                    frontier.append(y)
    return offsets.get(camera_b)


def _repin(
    tracks_a: list[BodyTrack], tracks_b: list[BodyTrack], pair: PairOffset, work: _TrackWork,
    lag: float,
) -> PairOffset:  # fmt: skip
    """The pair re-estimated in the lobe of ``lag``."""
    return estimate_pair_offset(
        tracks_a, tracks_b, work.params, camera_a=pair.camera_a, camera_b=pair.camera_b,
        around=lag, work=work,
    )  # fmt: skip


def clock_epochs(tracks: dict[str, list[BodyTrack]]) -> dict[str, float]:
    """Per camera the middle of its tracks (camera clock), used as the drift epoch.

    There an offset and a drift estimated from the same data are least correlated.
    """
    return {
        c: 0.5 * (min(t.start for t in ts) + max(t.end for t in ts)) if ts else 0.0
        for c, ts in tracks.items()
    }
