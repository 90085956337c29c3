"""All cameras' clocks: every camera pair's lag, the loop rules, then the global solve."""

from __future__ import annotations

import functools
import math

from scipy.fft import next_fast_len

from hiros_calib.sync.clock import CameraClock, PairOffset, Settle
from hiros_calib.sync.contest import contest_candidates
from hiros_calib.sync.loops import close_loops, overrule_weak_pairs, unless_uncorrelated
from hiros_calib.sync.pair import estimate_pair_offset
from hiros_calib.sync.params import GRID_STEP, SyncParams
from hiros_calib.sync.solve import clock_epochs, solve_clocks
from hiros_calib.sync.work import TrackWork
from hiros_calib.tracks import BodyTrack

__all__ = ["synchronise"]


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
    step = GRID_STEP
    longest = max(
        (math.floor(t.end / step) - math.ceil(t.start / step) + 1 for ts in tracks.values()
         for t in ts),
        default=0,
    )  # fmt: skip
    # one FFT length for every pair, so each track's spectra serve all its camera's pairs
    work = TrackWork(params, next_fast_len(2 * longest))
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
            pairs.append(unless_uncorrelated(pair, params))
            repins.append(repin)
    pairs = close_loops(pairs, repins)
    pairs = overrule_weak_pairs(pairs)
    return solve_clocks(cameras, reference, pairs, clock_epochs(tracks), params), pairs


def _repin(
    tracks_a: list[BodyTrack], tracks_b: list[BodyTrack], pair: PairOffset, work: TrackWork,
    lag: float,
) -> PairOffset:  # fmt: skip
    """The pair re-estimated in the lobe of ``lag``."""
    return estimate_pair_offset(
        tracks_a, tracks_b, work.params, camera_a=pair.camera_a, camera_b=pair.camera_b,
        around=lag, work=work,
    )  # fmt: skip
