"""The rules that check pairs' lags against each other around camera loops.

With three or more cameras the lags around a loop add up to zero: a pair the motion left
ambiguous may be decided by the others, and a chance-level lag the others contradict is
left out.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from hiros_calib.sync.clock import PairOffset, fisher_significance, refused_pair
from hiros_calib.sync.params import CONSENSUS_TOLERANCE, LOOP_OVERRULE_STRENGTH, SyncParams

__all__ = ["close_loops", "overrule_weak_pairs", "unless_uncorrelated"]


def close_loops(
    pairs: list[PairOffset], repins: list[Callable[[float], PairOffset]]
) -> list[PairOffset]:
    """Pairs refused as ambiguous, decided where the other pairs imply one of their lags.

    With three or more cameras, a pair whose motion repeats may still be timed through the
    others: the lags of a-c and c-b add up to the lag of a-b. A refused pair that listed
    candidate lags takes the one within ``CONSENSUS_TOLERANCE`` of that sum (re-estimated
    there by ``repins[k]``), until no more can be decided. Two such pairs of a camera
    triangle whose third pair is timed are decided together when exactly one combination of
    their candidates closes the triangle (:func:`_decide_two_by_triangle`).
    """
    pairs = list(pairs)
    progress = True
    while progress:
        progress = _decide_two_by_triangle(pairs, repins)
        for k, pair in enumerate(pairs):
            if pair.ok or len(pair.candidates) == 0:
                continue
            implied = _implied_lag(pair.camera_a, pair.camera_b, [p for p in pairs if p.ok])
            if implied is None:
                continue
            distance = np.abs(pair.candidates[:, 0] - implied)
            best = int(np.argmin(distance))
            if distance[best] > CONSENSUS_TOLERANCE:
                continue
            decided = repins[k](float(pair.candidates[best, 0]))
            if not decided.ok:
                continue
            decided.candidates = pair.candidates
            decided.quality.update(lag_decided_by="loop", loop_implied_lag=round(implied, 4))
            pairs[k] = decided
            progress = True
    return pairs


def unless_uncorrelated(pair: PairOffset, params: SyncParams) -> PairOffset:
    """The pair, or its refusal when the motion does not correlate at the lag it ended on.

    A lag kept for the arrival times, or chosen by the poses, may sit where the refined
    correlation is below ``min_peak``, the least a usable body pair's peak needs: nothing in
    the motion supports it then. The refusal keeps the candidates, so a loop may decide.
    """
    correlation = pair.quality.get("refined_correlation", 0.0)
    if not pair.ok or correlation >= params.min_peak:
        return pair
    refused = refused_pair(
        pair.camera_a,
        pair.camera_b,
        f"the motion does not correlate at its lag {pair.offset:+.3f} s (correlation "
        f"{correlation:.2f} over {pair.quality.get('overlap_s', 0.0):.0f} s; a usable lag "
        f"needs {params.min_peak})",
    )
    refused.candidates = pair.candidates
    return refused


def _decide_two_by_triangle(
    pairs: list[PairOffset], repins: list[Callable[[float], PairOffset]]
) -> bool:
    """Two ambiguous pairs decided by the timed third side of their triangle (in place).

    Each lists candidate lags; a combination closes the triangle when its lags add up to the
    third pair's within ``CONSENSUS_TOLERANCE``. Only a single closing combination decides:
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
            <= CONSENSUS_TOLERANCE
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


def overrule_weak_pairs(pairs: list[PairOffset]) -> list[PairOffset]:
    """Pairs left out whose chance-level lag the other pairs' loop contradicts.

    With three or more cameras the lags around a loop add up to zero. A pair whose lag is
    more than ``CONSENSUS_TOLERANCE`` from the lag the other pairs imply, and whose refined
    correlation is no more significant than chance gives (``LOOP_OVERRULE_STRENGTH``) while
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
        if implied is None or abs(pair.offset - implied) <= CONSENSUS_TOLERANCE:
            continue
        weakest_other = min(_pair_strength(p) for p in others)
        if not _pair_strength(pair) < LOOP_OVERRULE_STRENGTH <= weakest_other:
            continue
        pairs[k] = refused_pair(
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
        fisher_significance(
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
