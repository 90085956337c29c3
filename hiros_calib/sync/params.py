"""The parameters of the time-offset estimation."""

from __future__ import annotations

from dataclasses import dataclass, field

from hiros_calib.signature import DEFAULT_JOINTS

__all__ = ["SyncParams"]


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
