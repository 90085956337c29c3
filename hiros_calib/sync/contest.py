"""A camera pair's candidate lags compared window by window."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from hiros_calib.sync.clock import PairOffset, fisher_z
from hiros_calib.sync.params import SyncParams
from hiros_calib.sync.refine import RefinePair, refine, window_edges
from hiros_calib.sync.work import TrackWork
from hiros_calib.tracks import BodyTrack

__all__ = [
    "CONTEST_DECISIVE_T",
    "CONTEST_MIN_WINDOWS",
    "CONTEST_WINDOW",
    "WINDOW_CORRELATION_LIMIT",
    "WINDOW_REACH",
    "contest_candidates",
]

CONTEST_WINDOW = 5.0
"""Seconds per window when a pair's candidate lags are compared window by window."""


CONTEST_MIN_WINDOWS = 6
"""Fewest windows both lags must share for their comparison to count."""


CONTEST_DECISIVE_T = 4.0
"""Paired t-statistic at which the best lag's lead over another is taken as decisive."""


WINDOW_REACH = 0.03
"""How far (s) a window's lag may lie from the lag found over the whole overlap."""


WINDOW_CORRELATION_LIMIT = 0.99
"""A window's correlation counts at most this much (its Fisher z at most 2.65), so one
near-perfect window cannot decide a contest alone."""


def contest_candidates(
    pair: PairOffset,
    tracks_a: list[BodyTrack],
    tracks_b: list[BodyTrack],
    params: SyncParams,
    work: TrackWork | None = None,
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
    work = work if work is not None else TrackWork(params)
    sig_a, sig_b = work.signatures(tracks_a), work.signatures(tracks_b)
    pairs = [
        RefinePair.build(work.spline(sig_a[i]), work.spline(sig_b[j])) for i, j in pair.body_pairs
    ]
    start = min(p.a.start for p in pairs)
    end = max(p.a.end for p in pairs)
    bounds = window_edges(start, end, CONTEST_WINDOW)
    lags = [
        pair.offset if abs(lag - pair.offset) < 0.1 else refine(float(lag), 0.1, pairs)[0]
        for lag in pair.candidates[:, 0]
    ]  # the pair's own lag is refined already
    scores = [_window_scores(lag, pairs, bounds) for lag in lags]
    leads = [_paired_t(scores[0] - other) for other in scores[1:]]
    pair.quality["motion_window_t"] = round(min(leads), 2)


def _window_scores(
    tau: float, pairs: list[RefinePair], bounds: list[tuple[float, float]]
) -> np.ndarray:
    """Per window the Fisher z of the refined correlation near ``tau`` (NaN: too little data)."""
    scores = np.full(len(bounds), np.nan)
    for k, (lo, hi) in enumerate(bounds):
        if sum(p.overlap(tau, (lo, hi)) for p in pairs) >= 0.5 * (hi - lo):
            correlation = refine(tau, WINDOW_REACH, pairs, (lo, hi))[1]
            scores[k] = fisher_z(correlation, WINDOW_CORRELATION_LIMIT)
    return scores


def _paired_t(differences: np.ndarray) -> float:
    """The one-sample t-statistic of the finite differences (0 with too few of them)."""
    shared = differences[np.isfinite(differences)]
    if len(shared) < CONTEST_MIN_WINDOWS:
        return 0.0
    if np.ptp(shared) == 0.0:  # no spread: scipy would divide by zero
        mean = float(shared[0])
        return math.copysign(math.inf, mean) if mean else 0.0
    return float(stats.ttest_1samp(shared, 0.0).statistic)
