"""Choosing a camera pair's clock lag among the lags the motion supports, by the poses.

People repeating a motion (exercises, waving, walking one loop) correlate nearly as well one
repetition away as at the true lag, so the correlation alone cannot tell those lags apart
(:mod:`~hiros_calib.sync` lists them as a pair's ``candidates``). The skeletons can: at the
true lag the two cameras see the same pose at the same instant, so one rigid transform maps
one camera's joints onto the other's up to the SDKs' noise; one repetition off, the limbs
are elsewhere and no transform fits as well.

For every candidate lag this fits a rigid transform to the same-instant joints (a light
RANSAC fit, no per-joint offsets; two-fold cross-validated over alternating 2 s blocks, so a
lag with little common data gains nothing from over-fitting) and measures the *lag fit
residual*: per frame the mean distance of the joints after the fit (left and right as the
SDKs gave them or swapped, whichever fits), then per person (a track of camera a) the median
over the frames of theirs that every candidate shares, and the mean over the people, so that
everyone counts: one repetition of one person's walk off, that person fits, the others do
not. The decision:

- the lag the motion prefers and the one the poses prefer agree: taken;
- the motion cannot decide (the runner-up correlates ``max_ambiguity`` as well or more
  over the whole recording, and the best lag does not correlate better window by window:
  :func:`~hiros_calib.sync.contest_candidates`) and the poses prefer one lag by
  ``MIN_LAG_MARGIN``: the poses' lag is taken;
- the motion decides but the poses clearly prefer another lag: the motion's lag is kept and
  the pair is flagged as doubtful;
- neither can decide: the pair is refused, listing the candidate lags. So is an ambiguous
  pair whose best lag leaves the skeletons more than ``MAX_LAG_FIT`` apart: a lag that fits
  least badly among lags that do not fit is no evidence.

The residual at the chosen lag against the best other lag is kept in the pair's quality as
evidence that the lag is right (``lag_fit_residual_m``, ``lag_fit_runner_up_m``).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hiros_calib.extrinsics import (
    QUICK_SAMPLING,
    Correspondences,
    ExtrinsicsParams,
    associate,
    estimate_pair_pose,
    pair_correspondences,
    relative_error,
    second_half,
)
from hiros_calib.sync import CONTEST_DECISIVE_T, CameraClock, PairOffset
from hiros_calib.tracks import BodyTrack
from hiros_core.geometry import RigidTransform

__all__ = [
    "KNOWN_POSES",
    "MAX_LAG_FIT",
    "MIN_FIT_COVERAGE",
    "REPEATS_EXACTLY",
    "LagFit",
    "compare_fits",
    "fit_at_lag",
    "frame_residuals",
    "settle_lag",
    "split_half_spread",
]


KNOWN_POSES = "known poses"
"""``lag_decided_by`` of a lag the skeletons chose measured against poses given beforehand."""

MIN_FIT_COVERAGE = 0.5
"""A lag's skeletons must match at least this fraction of the frames that the best-matched
lag's do for its fit to count (as :mod:`~hiros_calib.sync` keeps a candidate lag only if
its overlap is half the best's)."""

REPEATS_EXACTLY = "the motion may repeat exactly"
"""Part of a pair's flag when a lag other body pairs support fits as well as the chosen one
(see :func:`settle_lag`): nothing in the recording tells the two apart."""

MAX_LAG_FIT = 0.5
"""Largest lag fit residual (m) that counts as the skeletons fitting at all: half a metre,
about a body's width, between the same joints after the best rigid fit means the two cameras'
skeletons at those instants are not one body's (at true lags the simulator's SDKs, the
noisiest included, leave a few tenths of that: docs/calibration-robustness.md, session 30).
Among lags the motion cannot tell apart, the poses choose only a lag that fits: people who
walk one loop side by side correlate alike at lags that pair each person with another, and
the least bad of those is no evidence."""


@dataclass
class LagFit:
    """How well the two cameras' skeletons fit one rigid transform at one clock lag."""

    lag: float
    """``tau = t_a - t_b`` (s)."""
    correlation: float
    """The pooled motion correlation at this lag."""
    frames: dict[tuple[int, int], float] = field(default_factory=dict)
    """Per frame of camera a, keyed by (track index, time in 0.1 ms), the mean joint
    distance after the fit (m), the better of direct and left/right swapped."""
    residual_m: float = math.inf
    """Median of ``frames`` over the frames every candidate lag shares (set by
    :func:`compare_fits`); inf when no person could be matched at this lag."""


def fit_at_lag(
    tracks_a: list[BodyTrack],
    tracks_b: list[BodyTrack],
    lag: float,
    correlation: float,
    params: ExtrinsicsParams,
    *,
    known: RigidTransform | None = None,
) -> LagFit:
    """Camera b's skeletons fitted onto camera a's at clock lag ``lag``, per frame of a.

    ``known`` is camera b's pose in camera a's frame when it is known (from a calibration of
    the same cameras): the skeletons are then measured against it, not fitted.
    """
    clock_a = CameraClock("a", "ok", time_offset=0.0)
    clock_b = CameraClock("b", "ok", time_offset=lag)  # o_b - o_a = tau
    matches = associate(tracks_a, tracks_b, clock_a, clock_b, params)
    found = [
        (i, pair_correspondences(tracks_a[i], tracks_b[j], clock_a, clock_b, params))
        for i, j, _ in matches
    ]
    usable = [(i, c) for i, c in found if c is not None]
    fit = LagFit(lag, correlation)
    if not usable:
        return fit
    joined = Correspondences.concatenate([c for _, c in usable])
    residual = frame_residuals(joined, known) if known is not None else _cross_validated(joined)
    if residual is None:
        return fit
    tracks = np.array([track for track, _ in usable])[joined.bodies]
    keys = np.round(joined.times * 1e4).astype(np.int64)
    seen = np.isfinite(residual)
    fit.frames.update(
        ((int(t), int(k)), float(r))
        for t, k, r in zip(tracks[seen], keys[seen], residual[seen], strict=True)
    )
    return fit


def _cross_validated(joined: Correspondences) -> np.ndarray | None:
    """``(F,)`` per-frame residuals, each after a rigid fit to the other half (None: no fit)."""
    # two-fold cross-validation over alternating blocks of time: each frame's residual comes
    # from a transform fitted without it, so a lag with little common data cannot win by a
    # transform that fits its few frames too closely
    fold = second_half(joined.times)
    if fold.all() or not fold.any():
        return None
    residual = np.full(joined.n_frames, np.nan)
    for held in (fold, ~fold):
        pose = estimate_pair_pose(joined.take(np.flatnonzero(~held)), sampling=QUICK_SAMPLING)
        if not pose.ok:
            return None
        residual[held] = frame_residuals(joined.take(np.flatnonzero(held)), pose.transform)
    return residual


def split_half_spread(correspondences: Correspondences | None) -> tuple[float, float] | None:
    """How far apart (deg, m) the poses fitted to two halves of a pair's frames lie.

    The halves are alternating blocks of time, so each sees the whole recording's variety.
    Each half's pose error is about sqrt(2) times the whole's, and their difference about
    sqrt(2) times a half's: half the spread estimates the error of the pose from all frames
    (the part the noise causes; an error every frame shares stays hidden). None when a half
    gives no pose.
    """
    if correspondences is None or correspondences.n_frames < 2:
        return None
    fold = second_half(correspondences.times)
    poses = []
    for half in (fold, ~fold):
        if not half.any():
            return None
        pose = estimate_pair_pose(
            correspondences.take(np.flatnonzero(half)), sampling=QUICK_SAMPLING
        )
        if not pose.ok:
            return None
        poses.append(pose.transform)
    return relative_error(poses[0], poses[1])


def frame_residuals(c: Correspondences, transform: RigidTransform) -> np.ndarray:
    """``(F,)`` mean joint distance per frame (m), the better of direct and mirrored.

    NaN where a frame has too few joints seen by both cameras.
    """
    moved = transform.apply(c.points_b.reshape(-1, 3)).reshape(c.points_b.shape)
    valid = c.weights > 0
    counts = valid.sum(axis=1)
    direct = np.linalg.norm(moved - c.points_a, axis=2)
    swapped = np.linalg.norm(moved[:, c.mirror] - c.points_a, axis=2)
    both = valid & valid[:, c.mirror]
    with np.errstate(invalid="ignore", divide="ignore"):
        per_frame = np.minimum(
            np.where(valid, direct, 0.0).sum(axis=1) / counts,
            np.where(both, swapped, np.inf).sum(axis=1) / both.sum(axis=1),
        )
    return np.where(counts >= max(3, valid.shape[1] // 3), per_frame, np.nan)


def compare_fits(fits: list[LagFit], min_frames: int = 30) -> None:
    """Set each fit's residual: the mean over the people it matched of their median residual.

    Each person (a track of camera a) counts alike, however long they were seen: at a lag one
    repetition off, the person whose motion repeats with that period fits as well as at the
    true lag, while everyone else is metres off (docs/calibration-robustness.md, session 18);
    a median over all frames would hide them behind the majority. A person's median is taken
    over the frames of theirs that every fit shares, so that a lag which pairs camera a's
    moving stretches with b's still ones, or overlaps less, is not judged on other frames
    than its rivals; a person with fewer than ``min_frames`` shared frames is judged on their
    own frames, and one with fewer than ``min_frames`` in all is left out. A lag whose
    skeletons match fewer than ``MIN_FIT_COVERAGE`` of the frames the best-matched lag does
    (a lag near the recording's length, where the cameras overlap a few seconds) rests on too
    little data to rival the others: its residual is inf.
    """
    matched = [f for f in fits if f.frames]
    shared = set.intersection(*(set(f.frames) for f in matched)) if matched else set()
    most = max((len(f.frames) for f in fits), default=0)
    for fit in fits:
        if len(fit.frames) < MIN_FIT_COVERAGE * most:
            fit.residual_m = math.inf  # too little data to rival the others
            continue
        fit.residual_m = _person_mean(fit.frames, shared, min_frames)


def _person_mean(
    frames: dict[tuple[int, int], float], shared: set[tuple[int, int]], min_frames: int
) -> float:
    """Mean over the tracks of their median frame residual (inf: no track seen enough)."""
    own: dict[int, list[float]] = defaultdict(list)
    common: dict[int, list[float]] = defaultdict(list)
    for key, residual in frames.items():
        own[key[0]].append(residual)
        if key in shared:
            common[key[0]].append(residual)
    medians = [
        float(np.median(common[track] if len(common[track]) >= min_frames else residuals))
        for track, residuals in own.items()
        if len(residuals) >= min_frames
    ]
    return float(np.mean(medians)) if medians else math.inf


def settle_lag(
    pair: PairOffset,
    tracks_a: list[BodyTrack],
    tracks_b: list[BodyTrack],
    params: ExtrinsicsParams,
    repin: Callable[[float], PairOffset],
    *,
    max_ambiguity: float,
    min_lag_margin: float,
    known: RigidTransform | None = None,
) -> PairOffset:
    """The pair with its lag checked (or chosen) by the poses, flagged or refused if need be.

    ``repin(lag)`` re-estimates the pair's offset in the lobe of another candidate lag. The
    motion is ambiguous when the runner-up lag correlates ``max_ambiguity`` as well as the
    best or more; the poses decide when one lag's fit residual is ``MIN_LAG_MARGIN`` times
    smaller than every other's, and only among every lag the motion supports (an ambiguous
    pair with more alike lags than ``MAX_CANDIDATES`` is refused). With ``known`` (camera b's
    pose in camera a's frame, from an earlier calibration) the skeletons are measured against
    that pose instead of a fit of their own, and a lag they choose says so
    (``lag_decided_by: known poses``).
    """
    if not pair.ok or len(pair.candidates) == 0:
        return pair
    fits = [
        fit_at_lag(tracks_a, tracks_b, float(lag), float(corr), params, known=known)
        for lag, corr in pair.candidates
    ]
    compare_fits(fits)
    if "prior_lag" in pair.quality:
        kept = _keep_prior(pair, fits, repin, min_lag_margin)
        if kept is not None:
            return kept
    by_fit = sorted(range(len(fits)), key=lambda k: fits[k].residual_m)
    motion_ratio = float(pair.candidates[1, 1] / pair.candidates[0, 1]) if len(fits) > 1 else 0.0
    ambiguous = motion_ratio >= max_ambiguity and not _motion_decides(pair)
    best = by_fit[0]
    margin = _margin(fits, best)
    chosen, flag = 0, ""
    if ambiguous and (
        pair.quality.get("candidates_left_out", 0) or not fits[best].residual_m <= MAX_LAG_FIT
    ):
        # a motion repeating at more lags than the poses check: the true lag may be one they
        # never saw, and among a looped walk's repetitions the skeletons can fit a wrong lag
        # better than the true one (docs/calibration-robustness.md, session 17); or no lag
        # checked fits at all, so the true one is not among them
        return _undecided(pair, fits, max_ambiguity, min_lag_margin)
    if margin >= min_lag_margin:
        if best == 0 or ambiguous:
            chosen = best
        else:
            flag = (
                f"the motion times {pair.camera_a}-{pair.camera_b} at {fits[0].lag:+.3f} s, but "
                f"the skeletons fit {margin:.2f}x better at {fits[best].lag:+.3f} s"
            )
    elif ambiguous:
        return _undecided(pair, fits, max_ambiguity, min_lag_margin)
    settled = pair if chosen == 0 else repin(fits[chosen].lag)
    if not settled.ok:
        return settled
    settled.candidates = pair.candidates
    settled.quality.update(_quality(pair, fits, chosen, motion_ratio))
    if ambiguous:  # alike lags: the poses chose, whether or not the motion's best
        settled.quality["lag_decided_by"] = "poses"
    if known is not None and settled.quality["lag_decided_by"] == "poses":
        settled.quality["lag_decided_by"] = KNOWN_POSES
    rival = _rival_doubt(
        pair, fits[chosen], (tracks_a, tracks_b), params, min_lag_margin=min_lag_margin, known=known
    )
    flag = "; ".join(text for text in (flag, rival) if text)
    if flag:
        settled.quality["flagged"] = flag
    return settled


def _rival_doubt(
    pair: PairOffset,
    chosen: LagFit,
    tracks: tuple[list[BodyTrack], list[BodyTrack]],
    params: ExtrinsicsParams,
    *,
    min_lag_margin: float,
    known: RigidTransform | None,
) -> str:
    """Why the chosen lag is doubtful when a rival lag fits about as well ("" when none does).

    The rivals (``pair.rivals``) are lags other body pairs support as strongly as the chosen
    lag's, which the candidates missed. They never choose the lag (among a motion repeated
    to the frame, the skeletons fit every repetition alike and a small margin is chance); a
    rival the chosen lag does not beat by ``min_lag_margin`` makes the pair doubtful.
    """
    if len(pair.rivals) == 0 or not math.isfinite(chosen.residual_m):
        return ""
    rivals = [
        fit_at_lag(*tracks, float(lag), float(corr), params, known=known)
        for lag, corr in pair.rivals
    ]
    judged = [LagFit(chosen.lag, chosen.correlation, frames=chosen.frames), *rivals]
    compare_fits(judged)
    own = judged[0].residual_m  # inf: the rivals match over twice the chosen lag's frames
    close = [
        f
        for f in rivals
        if f.residual_m <= MAX_LAG_FIT
        and (f.residual_m < own * min_lag_margin or not math.isfinite(own))
    ]
    if not close:
        return ""
    best = min(close, key=lambda f: f.residual_m)
    chosen_fit = (
        f"{100 * own:.0f} cm" if math.isfinite(own) else "under half as many frames matched"
    )
    return (
        f"the skeletons fit the {pair.camera_a}-{pair.camera_b} pair about as well at "
        f"{best.lag:+.3f} s ({100 * best.residual_m:.0f} cm; the chosen {chosen.lag:+.3f} s: "
        f"{chosen_fit}), a lag other body pairs support as strongly: {REPEATS_EXACTLY}. "
        "Record a stretch of motion that does not repeat"
    )


def _motion_decides(pair: PairOffset) -> bool:
    """Whether the best lag correlates better than every other one window by window.

    See :func:`~hiros_calib.sync.contest_candidates`: the whole-recording correlations of
    two lags may be alike while every window prefers one of them.
    """
    return float(pair.quality.get("motion_window_t", 0.0)) >= CONTEST_DECISIVE_T


def _keep_prior(
    pair: PairOffset,
    fits: list[LagFit],
    repin: Callable[[float], PairOffset],
    min_lag_margin: float,
) -> PairOffset | None:
    """The pair at the arrival times' lag, unless the poses confirm the motion's other lag.

    The motion contradicted the arrival times (a more significant lag elsewhere). Arrival
    times on one receiver are rarely wrong by seconds and a chance correlation often is, so
    the prior's lag stays unless the skeletons fit ``MIN_LAG_MARGIN`` times better at the
    motion's lag. Returns None when they do (the motion's lag then stands).
    """
    prior = pair.quality["prior_lag"]
    index = int(np.argmin([abs(f.lag - prior) for f in fits]))
    if fits[0].residual_m * min_lag_margin <= fits[index].residual_m:
        return None
    kept = repin(fits[index].lag)
    if not kept.ok:
        return None
    kept.candidates = pair.candidates
    kept.quality.update(_quality(pair, fits, index, 0.0))
    kept.quality["arrival_prior"] = (
        f"used: the motion's lag {fits[0].lag:+.3f} s is not confirmed by the poses"
    )
    return kept


def _margin(fits: list[LagFit], chosen: int) -> float:
    """The best other lag's residual over the chosen lag's (inf when there is no other)."""
    others = [f.residual_m for k, f in enumerate(fits) if k != chosen]
    if not others:
        return math.inf
    own = fits[chosen].residual_m
    if not math.isfinite(own):
        return 0.0
    return min(others) / own if own > 0 else math.inf


def _quality(
    pair: PairOffset, fits: list[LagFit], chosen: int, motion_ratio: float
) -> dict[str, object]:
    others = [f for k, f in enumerate(fits) if k != chosen]
    runner_up = min(others, key=lambda f: f.residual_m) if others else None
    quality: dict[str, object] = {
        "lag_decided_by": "poses" if chosen != 0 else "motion",
        # (with a kept arrival-time prior the caller overrides this)
        "lag_fit_residual_m": _rounded(fits[chosen].residual_m),
    }
    if runner_up is not None:
        quality["lag_fit_runner_up_m"] = _rounded(runner_up.residual_m)
        quality["lag_fit_runner_up_lag"] = round(runner_up.lag, 3)
        quality["lag_fit_margin"] = _rounded(_margin(fits, chosen))
        quality["motion_runner_up_ratio"] = round(motion_ratio, 3)
    return quality


def _rounded(value: float) -> float | str:
    return round(value, 4) if math.isfinite(value) else "inf"


def _undecided(
    pair: PairOffset, fits: list[LagFit], max_ambiguity: float, min_lag_margin: float
) -> PairOffset:
    """The pair refused: neither the motion nor the poses single out one lag."""
    listed = ", ".join(
        f"{f.lag:+.2f} s (correlation {f.correlation:.2f}, fit {100 * f.residual_m:.1f} cm)"
        if math.isfinite(f.residual_m)
        else f"{f.lag:+.2f} s (correlation {f.correlation:.2f}, no fit)"
        for f in fits
    )
    lead = pair.quality.get("motion_window_t")
    windows = (
        f", window by window the best leads by only t = {lead:.1f} (need {CONTEST_DECISIVE_T:.0f})"
        if lead is not None
        else ""
    )
    left_out = int(pair.quality.get("candidates_left_out", 0))
    best_fit = min(f.residual_m for f in fits)
    if left_out:
        judged = (
            f"and {left_out} more lags correlate as well: the motion repeats too often for the "
            "skeletons to tell its repetitions apart"
        )
    elif not math.isfinite(best_fit):
        judged = "and at none of them could the two cameras' people be matched"
    elif best_fit > MAX_LAG_FIT:
        judged = (
            "and the skeletons fit at none of them (after the best rigid fit the same joints "
            f"lie {100 * best_fit:.0f} cm apart at best, more than {100 * MAX_LAG_FIT:.0f} cm): "
            "the true lag may not be among these, as when people moving alike are paired "
            "with one another"
        )
    else:
        judged = f"and the skeletons fit none of them {min_lag_margin:.2f}x better than the others"
    reason = (
        f"the lag is ambiguous: the motion repeats, so lags {listed} correlate alike "
        f"(within {max_ambiguity:.0%}){windows}, {judged}. Record a stretch of motion that "
        "does not repeat (walk across the room, turn, move each arm differently), or give "
        "--max-offset to leave the other lags out"
    )
    return PairOffset(
        pair.camera_a,
        pair.camera_b,
        status="refused",
        reason=reason,
        quality={**pair.quality, "candidate_lags": [round(f.lag, 3) for f in fits]},
        candidates=pair.candidates,
    )
