"""The parameters of the time-offset estimation, and the method's constants.

``SyncParams`` holds what a user may tune (the node's parameters of the same names); the
constants below are the method's statistical and numerical choices, fixed by the tests and
benchmarks in ``docs/calibration-robustness.md`` rather than per recording.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hiros_calib.signature import DEFAULT_JOINTS

__all__ = [
    "BEST_FRACTION",
    "CANDIDATE_RATIO",
    "CONSENSUS_TOLERANCE",
    "GRID_STEP",
    "LOBE_CONTEXT",
    "LOOP_OVERRULE_STRENGTH",
    "MAX_CANDIDATES",
    "MAX_DRIFT",
    "MIN_DRIFT_SPAN",
    "MIN_LAG_MARGIN",
    "MIN_MOTION",
    "MIN_OVERLAP",
    "MIN_PRIOR_SIGNIFICANCE",
    "MIN_REPEATED_PEAK",
    "MIN_SHARPNESS",
    "MIN_VOTERS",
    "PEAK_SEPARATION",
    "PRIOR_CONTRADICTION",
    "REFINE_STEP",
    "SyncParams",
]


GRID_STEP: float = 0.01
"""Coarse correlation grid (s); the refinement goes below it."""

REFINE_STEP: float = 0.01
"""Grid (s) on which the continuous refinement compares interpolated signatures."""

MIN_DRIFT_SPAN: float = 30.0
"""Shortest span (s) of window measurements for a drift estimate."""

MAX_DRIFT: float = 1e-3
"""Largest drift (s/s) the window search allows for (real clocks drift within 1e-4)."""

LOBE_CONTEXT: float = 1.0
"""Half-width (s) of the correlation curve against which a body pair's peak is judged (its
sharpness) when the search is pinned to one lobe, around a lag the poses or a loop chose;
the arrival-time prior's window (``prior_window``) is as wide by default."""

MIN_PRIOR_SIGNIFICANCE: float = 0.8
"""Within the arrival-time prior's window, a body pair whose peak's significance (Fisher
z times the square root of the overlap, s) reaches this is usable: a correlation of 0.13
over 40 s, far beyond chance among the few lags of the window."""

PRIOR_CONTRADICTION: float = 1.5
"""The motion contradicts the arrival-time prior when the best lag outside
``prior_window`` is this many times more significant (Fisher z of the correlation times
the square root of the overlap) than the best lag within it; the search then takes every
lag and the pair's quality says ``arrival_prior: contradicted``."""

MIN_OVERLAP: float = 3.0
"""Seconds two tracks must overlap at a lag for that lag to count: a correlation over less is
more often chance than motion (a body pair's significance also grows with the overlap)."""

MIN_MOTION: float = 0.01
"""A track whose smoothed signature moves less than this (m) is a still body: skipped."""

MIN_SHARPNESS: float = 4.0
"""Lowest robust z-score of a usable peak over its correlation curve (motion that does
not repeat)."""

MIN_REPEATED_PEAK: float = 0.3
"""A peak this high is usable even when its curve has other high peaks (motion repeated
over the whole recording, where the z-score over the curve is low however clear the
peak); the lags it competes with are then decided by the poses (see ``candidates``)."""

CANDIDATE_RATIO: float = 0.6
"""Local maxima of the pooled correlation at least this fraction of the peak are the
pair's candidate lags, for the poses to check."""

PEAK_SEPARATION: float = 0.25
"""Seconds two candidate (or rival) lags lie apart at least: closer peaks are one lobe of the
pooled correlation."""

MAX_CANDIDATES: int = 12
"""At most this many candidate lags per camera pair (best first)."""

MIN_LAG_MARGIN: float = 1.15
"""The poses decide between candidate lags when the skeletons' rigid-fit residual at one
lag is this many times smaller than at every other (see :mod:`~hiros_calib.lags`)."""

BEST_FRACTION: float = 0.1
"""Fraction of the sharpest body pairs that choose the consensus lag (Eichler: 10 %)."""

MIN_VOTERS: int = 3
"""Fewest body pairs (all, when fewer are clear) that choose the consensus lag: with a
handful of clear pairs, 10 % is one pair, whose peak may be a repetition of its person's
motion that the others' peaks contradict."""

CONSENSUS_TOLERANCE: float = 0.05
"""Body pairs whose peak lies within this (s) of the consensus join it."""

LOOP_OVERRULE_STRENGTH: float = 1.5
"""With three or more cameras, a pair whose lag the other pairs' loop contradicts is
left out when its refined correlation's significance (Fisher z times the square root of
the overlap, s) is below this and every other pair's is above. Unrelated motion signals,
correlated over about half a second, reach about 0.7 on this scale (one standard
deviation), so such a lag is noise, not a measurement (see :func:`overrule_weak_pairs`)."""


@dataclass
class SyncParams:
    """Parameters of the time-offset estimation (same names as the ``calib`` node's)."""

    joints: list[str] = field(default_factory=lambda: list(DEFAULT_JOINTS))
    """Joints whose distances form the signature; names missing from a layout are skipped."""
    max_offset: float = 0.0
    """Largest |offset| searched (s) without arrival times; 0 searches every lag."""
    prior_window: float = 1.0
    """How far (s) the true lag may lie from the lag the arrival times suggest.

    Lag aliases of repeated motion correlate nearly as well as the true lag; the times the
    messages arrived at one receiver pin the lag to within network latency. The lag found
    within this window is checked against the best lag anywhere (see ``PRIOR_CONTRADICTION``),
    so a prior the motion contradicts is noticed and ignored, never silently obeyed.
    """
    min_peak: float = 0.05
    """Lowest peak correlation of a usable body pair (noisy SDK joints correlate weakly;
    the sharpness is the stronger test)."""
    max_ambiguity: float = 0.5
    """A camera pair whose runner-up lag correlates this nearly as well as the best (its
    correlation over the best's) cannot be timed by the motion alone: the poses decide
    between the candidate lags, and the pair is refused when they cannot either. Motion
    repeated over the whole recording correlates about as well at every repetition."""
    window: float = 10.0
    """Window length (s) of the offset-over-time measurements that give the drift."""
    estimate_drift: bool = True
    """Fit a clock drift per camera (needs ``MIN_DRIFT_SPAN`` of common motion)."""
    drift_prior: float = 1e-4
    """Typical clock drift (s/s, a standard deviation): short recordings whose windows
    cannot tell a drift apart from noise get a drift shrunk towards 0 (ridge prior)."""
