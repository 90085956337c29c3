"""One camera pair's lag: the body pairs' consensus, its candidate lags and the refined lag.

Curves whose peak is high and sharp (robust z-score of the peak over the curve, the role of
Eichler's coefficient of variation) vote for their peak lag, the best ``BEST_FRACTION``
choose the winning lag and every good curve near it joins; a parabola through the pooled
curve's peak starts the continuous refinement (:mod:`~hiros_calib.sync.refine`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.ndimage import maximum_filter1d

from hiros_calib.signature import PoseSignature
from hiros_calib.sync.clock import PairOffset, fisher_significance, refused_pair
from hiros_calib.sync.correlation import Candidate, body_pair_candidates
from hiros_calib.sync.params import (
    BEST_FRACTION,
    CANDIDATE_RATIO,
    CONSENSUS_TOLERANCE,
    GRID_STEP,
    LOBE_CONTEXT,
    MAX_CANDIDATES,
    MIN_MOTION,
    MIN_OVERLAP,
    MIN_PRIOR_SIGNIFICANCE,
    MIN_REPEATED_PEAK,
    MIN_SHARPNESS,
    MIN_VOTERS,
    PEAK_SEPARATION,
    PRIOR_CONTRADICTION,
    SyncParams,
)
from hiros_calib.sync.refine import RefinePair, lag_windows, refine
from hiros_calib.sync.work import TrackWork
from hiros_calib.tracks import BodyTrack

__all__ = ["estimate_pair_offset"]


def estimate_pair_offset(
    tracks_a: list[BodyTrack],
    tracks_b: list[BodyTrack],
    params: SyncParams,
    *,
    camera_a: str = "a",
    camera_b: str = "b",
    prior: float | None = None,
    around: float | None = None,
    work: TrackWork | None = None,
) -> PairOffset:
    """The clock lag ``tau = t_a - t_b`` between two cameras from their body tracks.

    Every lag within ``± max_offset`` (all when 0) is searched. ``prior`` is the lag the
    message arrival times suggest (s): the lag within ``prior_window`` of it is taken unless
    the motion contradicts it (a far more significant lag elsewhere, or none clear near it).
    ``around`` pins the search to the lobe of one candidate lag (after the poses chose it).
    ``work`` shares per-track results between the pairs of one :func:`synchronise` call.
    """
    work = work if work is not None else TrackWork(params)
    names = {"camera_a": camera_a, "camera_b": camera_b}
    if around is not None:
        lobe = _lobe(around)
        return _estimate(tracks_a, tracks_b, params, lobe, work=work, one_lobe=True, **names)
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
        far = np.abs(free.candidates[:, 0] - near.offset) > CONSENSUS_TOLERANCE
        if far.all():
            peak = near.quality.get("peak", 0.0)
            free.candidates = np.vstack([free.candidates, [[near.offset, peak]]])
    return free


def _lobe(lag: float) -> tuple[float, float]:
    """The search range (s) of the correlation lobe around one candidate lag."""
    reach = max(3 * GRID_STEP, 2 * CONSENSUS_TOLERANCE)
    return lag - reach, lag + reach


def _lobe_context(lobe: tuple[float, float]) -> tuple[float, float]:
    """The lags (s) a peak within one ``lobe`` is judged against: ``LOBE_CONTEXT`` around it.

    The lobe alone is a few tenths of a second of the curve, whose robust z-score says
    nothing (its median is the peak's own shoulder); the arrival prior's window is as wide.
    """
    centre = 0.5 * (lobe[0] + lobe[1])
    return centre - LOBE_CONTEXT, centre + LOBE_CONTEXT


def _contradicts(free: PairOffset, near: PairOffset, params: SyncParams) -> bool:
    """Whether the best lag anywhere is far from, and far more significant than, the prior's."""
    if not free.ok or abs(free.offset - near.offset) <= params.prior_window:
        return False

    def strength(pair: PairOffset) -> float:
        return float(fisher_significance(pair.quality["peak"], pair.quality["overlap_s"]))

    return strength(free) > PRIOR_CONTRADICTION * strength(near)


def _estimate(
    tracks_a: list[BodyTrack],
    tracks_b: list[BodyTrack],
    params: SyncParams,
    search: tuple[float, float] | None,
    *,
    camera_a: str,
    camera_b: str,
    work: TrackWork,
    windowed: bool = False,
    one_lobe: bool = False,
) -> PairOffset:
    """The lag within ``search`` (s; None: every lag), with its candidates.

    ``windowed``: ``search`` is the arrival-time prior's window, where a body pair's peak is
    usable on its significance alone (``MIN_PRIOR_SIGNIFICANCE``). ``one_lobe``: ``search``
    is one candidate lag's lobe (:func:`_lobe`).
    """
    sig_a, sig_b = work.signatures(tracks_a), work.signatures(tracks_b)
    refusal = _refuse_unusable(
        camera_a, camera_b, sig_a=sig_a, sig_b=sig_b, params=params, work=work
    )
    if refusal is not None:
        return refusal
    context = _lobe_context(search) if one_lobe and search is not None else None
    candidates = body_pair_candidates(sig_a, sig_b, params, search, work, context=context)
    if not candidates:
        return refused_pair(
            camera_a,
            camera_b,
            f"no body is seen by both cameras for {MIN_OVERLAP:.1f} s at any lag"
            + (f" in {search[0]:+.2f}..{search[1]:+.2f} s" if search else ""),
        )
    good = [c for c in candidates if _clear(c, params, windowed=windowed)]
    best_any = max(candidates, key=lambda c: c.score)
    if not good:
        return refused_pair(
            camera_a,
            camera_b,
            f"no body pair correlates clearly (best peak {best_any.peak:.2f}, sharpness "
            f"{best_any.sharpness:.1f}; need {params.min_peak} and {MIN_SHARPNESS}, "
            f"or a peak of {MIN_REPEATED_PEAK})",
            peak=best_any.peak,
            sharpness=best_any.sharpness,
            pairs_considered=len(candidates),
        )
    used = _consensus(good, one_lobe=one_lobe)
    lags = _candidate_lags(used, params, search)
    chosen = round(lags[0, 0] / GRID_STEP)
    tolerance = max(1, round(CONSENSUS_TOLERANCE / GRID_STEP))
    if abs(chosen - used[0].lag_index) > tolerance:
        # the prior chose another of the lags the motion supports: redo the consensus there
        near = [c for c in good if abs(c.lag_index - chosen) <= tolerance]
        used = _consensus(near, one_lobe=True) if near else []
        if not used:
            pinned = _estimate(
                tracks_a, tracks_b, params, _lobe(float(lags[0, 0])),
                camera_a=camera_a, camera_b=camera_b, work=work, one_lobe=True,
            )  # fmt: skip
            pinned.candidates = lags[: max(2, MAX_CANDIDATES)]
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
    result.candidates = lags[: max(2, MAX_CANDIDATES)]
    result.quality.update(_lag_quality(lags))
    if not one_lobe and not windowed:
        result.rivals = _rival_lags(lags, good, used, search)
    return result


def _refuse_unusable(
    camera_a: str,
    camera_b: str,
    *,
    sig_a: list[PoseSignature],
    sig_b: list[PoseSignature],
    params: SyncParams,
    work: TrackWork,
) -> PairOffset | None:
    """A refusal when a camera saw no moving body for long enough, else None."""
    if not sig_a or not sig_b:
        return refused_pair(camera_a, camera_b, "a camera saw no body track")
    moving_a = [s for s in sig_a if work.motion(s) >= MIN_MOTION]
    moving_b = [s for s in sig_b if work.motion(s) >= MIN_MOTION]
    if not moving_a or not moving_b:
        still = camera_a if not moving_a else camera_b
        return refused_pair(
            camera_a,
            camera_b,
            f"the bodies {still} sees hardly move (less than {MIN_MOTION * 100:.0f} cm "
            "of joint-distance change), so their motion cannot time the cameras",
        )
    span_a = max(s.times[-1] - s.times[0] for s in moving_a)
    span_b = max(s.times[-1] - s.times[0] for s in moving_b)
    if min(span_a, span_b) < MIN_OVERLAP:
        return refused_pair(
            camera_a,
            camera_b,
            f"too short: the longest moving track lasts {min(span_a, span_b):.1f} s, "
            f"{MIN_OVERLAP:.1f} s are needed",
        )
    return None


def _clear(candidate: Candidate, params: SyncParams, *, windowed: bool = False) -> bool:
    """A body pair whose peak stands out of its curve, or is high though the motion repeats.

    Within the arrival-time prior's window the curve is too short for a robust z-score: a
    peak significant over its overlap is usable there.
    """
    if candidate.peak < params.min_peak:
        return False
    if windowed and candidate.significance >= MIN_PRIOR_SIGNIFICANCE:
        return True
    return candidate.sharpness >= MIN_SHARPNESS or candidate.peak >= MIN_REPEATED_PEAK


def _candidate_lags(
    used: list[Candidate], params: SyncParams, search: tuple[float, float] | None
) -> np.ndarray:
    """``(K, 2)`` candidate lags (s) and their pooled correlations, best first.

    The candidates are the pooled curve's local maxima of significance at least
    ``CANDIDATE_RATIO`` of the best's correlation, plus always the runner-up (so the poses can
    show how much worse the next lag fits).
    """
    step = GRID_STEP
    first, pooled, overlap = _pooled_curve(used, step)
    lags = (first + np.arange(len(pooled))) * step
    valid = (overlap >= MIN_OVERLAP) & np.isfinite(pooled)
    if search is not None:
        valid &= (lags >= search[0] - 1e-9) & (lags <= search[1] + 1e-9)
    significance = np.where(valid, fisher_significance(pooled, overlap), -np.inf)
    peaks = _local_maxima(significance, max(3, round(PEAK_SEPARATION / step)))
    # a lag whose overlap is much shorter than the best one's rests on too little data to
    # rival it (the poses would judge it on a transform fitted to a few seconds)
    peaks = [k for k in peaks if overlap[k] >= 0.5 * overlap[peaks[0]]]
    rows = np.array([(lags[k], pooled[k]) for k in peaks]).reshape(-1, 2)
    keep = rows[:, 1] >= CANDIDATE_RATIO * rows[0, 1]
    keep[: min(2, len(rows))] = True
    return rows[keep]


def _rival_lags(
    lags: np.ndarray,
    good: list[Candidate],
    used: list[Candidate],
    search: tuple[float, float] | None,
) -> np.ndarray:
    """``(R, 2)`` rival lags and their pooled correlation: other body pairs' consensus lags.

    The candidates (``lags``) come from the pooled curve of the body pairs that agree with
    the vote, which shows only the lags where those pairs overlap. Where a person is seen in
    several stretches (walking in and out of view) and repeats one motion, the pairs of
    stretches one repetition apart may win the vote, and the pairs of the same stretch, which
    agree on the true lag, are left out of the curve: the true lag is no candidate
    (docs/calibration-robustness.md, session 30). A lag that clear body pairs support with at
    least ``CANDIDATE_RATIO`` of the consensus's support (the vote's weight, score times
    overlap, summed over the pairs within ``CONSENSUS_TOLERANCE``) and that lies
    ``PEAK_SEPARATION`` or more from every one of ``lags`` is such a rival.
    """
    tolerance = max(1, round(CONSENSUS_TOLERANCE / GRID_STEP))
    separation = max(3, round(PEAK_SEPARATION / GRID_STEP))
    index = np.array([c.lag_index for c in good])
    support = _support(good, index, tolerance)
    needed = CANDIDATE_RATIO * _support(good, np.array([used[0].lag_index]), tolerance)[0]
    known = [round(lag / GRID_STEP) for lag in lags[:, 0]]
    rivals: list[tuple[float, float]] = []
    for k in np.argsort(-support, kind="stable"):
        if support[k] < needed:
            break
        centre = int(index[k])
        lag = centre * GRID_STEP
        if any(abs(centre - other) < separation for other in known) or (
            search is not None and not search[0] <= lag <= search[1]
        ):
            continue
        group = [c for c in good if abs(c.lag_index - centre) <= tolerance]
        first, pooled, _ = _pooled_curve(group, GRID_STEP)
        near = pooled[max(0, centre - tolerance - first) : centre + tolerance + 1 - first]
        rivals.append((lag, float(np.nanmax(near))))
        known.append(centre)
    return np.array(rivals).reshape(-1, 2)


def _local_maxima(values: np.ndarray, separation: int) -> list[int]:
    """Indices of finite values that are the largest within ``separation`` samples, best first."""
    finite = np.where(np.isfinite(values), values, -np.inf)
    neighbourhood = maximum_filter1d(finite, 2 * separation + 1, mode="constant", cval=-np.inf)
    peaks = np.flatnonzero(np.isfinite(finite) & (finite >= neighbourhood))
    return [int(k) for k in peaks[np.argsort(finite[peaks])[::-1]]]


def _lag_quality(lags: np.ndarray) -> dict[str, Any]:
    """The candidates' figures for the pair's quality: the runner-up and its margin.

    ``candidates_left_out`` counts the alike lags beyond ``MAX_CANDIDATES``, which the pair's
    ``candidates`` (the lags the poses check) leave out.
    """
    quality: dict[str, Any] = {
        "candidates": min(len(lags), max(2, MAX_CANDIDATES)),
        "candidates_left_out": max(0, len(lags) - max(2, MAX_CANDIDATES)),
        "arrival_prior": "none",
    }
    if len(lags) > 1:
        quality["runner_up_lag"] = round(float(lags[1, 0]), 3)
        quality["runner_up_ratio"] = round(float(lags[1, 1] / lags[0, 1]), 3)
    return quality


def _consensus(good: list[Candidate], *, one_lobe: bool = False) -> list[Candidate]:
    """The body pairs agreeing with the lag the sharpest pairs vote for.

    The sharpest ``BEST_FRACTION``, and at least ``MIN_VOTERS``, vote; each vote weighs the
    pair's score times its overlap. The pairs within ``CONSENSUS_TOLERANCE`` of the sharpest
    voter of the winning lag agree with it. Within ``one_lobe`` of the correlation (the
    search pinned to one candidate lag), which holds no other repetition of the motion, the
    sharpest pair alone may decide, as Eichler's 10 % does: a vote there would only move the
    lag between the pairs' noisy peaks.
    """
    tolerance = max(1, round(CONSENSUS_TOLERANCE / GRID_STEP))
    ranked = sorted(good, key=lambda c: c.score, reverse=True)
    fewest = 1 if one_lobe else min(MIN_VOTERS, len(ranked))
    voters = ranked[: max(fewest, math.ceil(BEST_FRACTION * len(ranked)))]
    lags = np.array([c.lag_index for c in voters])
    support = _support(voters, lags, tolerance)
    winner = int(lags[int(np.argmax(support))])
    # centred on the sharpest pair of the winning lag's group, so that a vote confirming the
    # sharpest pair keeps its peak (voters within the tolerance may peak a few steps apart)
    winner = next(c.lag_index for c in voters if abs(c.lag_index - winner) <= tolerance)
    # one body of camera a pairs with at most one body of camera b at a time: keep the best
    used: list[Candidate] = []
    for candidate in ranked:
        if abs(candidate.lag_index - winner) > tolerance:
            continue
        used.append(candidate)
    return used


def _support(pairs: list[Candidate], at: np.ndarray, tolerance: int) -> np.ndarray:
    """The vote's support of each lag index in ``at``.

    The vote weight (score times overlap) summed over the ``pairs`` whose peak lies within
    ``tolerance`` of it.
    """
    index = np.array([c.lag_index for c in pairs])
    weight = np.array([c.score * c.overlap for c in pairs])
    return np.array([(weight * (np.abs(index - k) <= tolerance)).sum() for k in at])


def _pooled_curve(used: list[Candidate], step: float) -> tuple[int, np.ndarray, np.ndarray]:
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
    used: list[Candidate],
    candidates: list[Candidate],
    sig_a: list[PoseSignature],
    sig_b: list[PoseSignature],
    params: SyncParams,
    work: TrackWork,
    centre: int,
) -> PairOffset:
    """The refined lag of the lobe at absolute lag index ``centre``, with its windows."""
    step = GRID_STEP
    first, pooled, _ = _pooled_curve(used, step)
    centre -= first
    half = max(3, round(0.1 / step))
    lo, hi = max(0, centre - half), min(len(pooled), centre + half + 1)
    local = int(np.nanargmax(pooled[lo:hi])) + lo
    tau_parabola = (first + _parabolic(pooled, local)) * step
    pairs = [
        RefinePair.build(work.spline(sig_a[c.index_a]), work.spline(sig_b[c.index_b])) for c in used
    ]
    # the whole-overlap search picks the correlation peak's lobe; the windows then search
    # around it (on real recordings the correlation can have side lobes a window alone
    # might settle on)
    tau, corr = refine(tau_parabola, 2 * step, pairs)
    windows = lag_windows(tau, pairs, params)
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
